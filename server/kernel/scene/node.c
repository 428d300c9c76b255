#include "node.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

char *rsw_strdup(const char *s) {
  if (!s) return NULL;
  size_t n = strlen(s) + 1;
  char *r = malloc(n);
  if (r) memcpy(r, s, n);
  return r;
}

node *node_new(const char *tag, const char *type, const char *loc) {
  node *n = calloc(1, sizeof *n);
  if (!n) return NULL;
  n->tag = rsw_strdup(tag);
  n->type = rsw_strdup(type);
  n->loc = rsw_strdup(loc ? loc : "");
  if ((tag && !n->tag) || (type && !n->type) || !n->loc) {
    node_free(n);
    return NULL;
  }
  return n;
}

void spectrum_free(spectrum *s) {
  if (!s) return;
  free(s->wl);
  free(s->val);
  s->wl = s->val = NULL;
  s->n = 0;
}

static void prop_release(prop *p) {
  free(p->name);
  free(p->loc);
  free(p->str);
  free(p->nums);
  free(p->ref);
  spectrum_free(&p->spec);
  node_free(p->child);
}

void node_free(node *n) {
  if (!n) return;
  for (size_t i = 0; i < n->n_props; i++) prop_release(&n->props[i]);
  free(n->props);
  free(n->name_index);
  free(n->tag);
  free(n->type);
  free(n->id);
  free(n->loc);
  free(n);
}

const scene_limits scene_limits_default = {.max_props = RSW_MAX_PROPS, .max_tree_bytes = RSW_MAX_TREE_BYTES};

bool node_type_is_container(const char *type) {
  return type && (strcmp(type, "scene") == 0 || strcmp(type, "shapegroup") == 0);
}

/* Below this many properties a linear scan is as fast as hashing. */
#define NODE_INDEX_MIN 16

static size_t name_hash(const char *s) { /* FNV-1a */
  unsigned long long h = 1469598103934665603ull;
  for (; *s; s++) h = (h ^ (unsigned char)*s) * 1099511628211ull;
  return (size_t)h;
}

/* Slot of `name` in the index: the one holding it, or the empty one where
 * it would go. */
static size_t index_slot(const node *n, const size_t *idx, size_t cap, const char *name) {
  size_t i = name_hash(name) & (cap - 1);
  while (idx[i] && strcmp(n->props[idx[i] - 1].name, name) != 0) i = (i + 1) & (cap - 1);
  return i;
}

/* Record property k (already counted in n_props) in the index, first
 * occurrence of a name winning as in the linear scan; (re)builds the
 * table at half load. */
static bool index_add(node *n, size_t k) {
  if (2 * n->n_props > n->index_cap) {
    size_t cap = n->index_cap ? 2 * n->index_cap : 64;
    while (cap < 2 * n->n_props) cap *= 2;
    size_t *idx = calloc(cap, sizeof *idx);
    if (!idx) return false;
    for (size_t j = 0; j < n->n_props; j++)
      if (j != k) {
        size_t s = index_slot(n, idx, cap, n->props[j].name);
        if (!idx[s]) idx[s] = j + 1;
      }
    free(n->name_index);
    n->name_index = idx;
    n->index_cap = cap;
  }
  size_t s = index_slot(n, n->name_index, n->index_cap, n->props[k].name);
  if (!n->name_index[s]) n->name_index[s] = k + 1;
  return true;
}

prop *node_add_prop(node *n, const char *name, prop_kind kind, const char *loc) {
  if (n->n_props >= RSW_MAX_NODES) return NULL;
  if (n->n_props == n->cap_props) {
    /* small first: most objects have a handful of properties, and a
     * 100,000-member group is 100,000 such objects (each prop is ~400 B) */
    size_t cap = n->cap_props ? 2 * n->cap_props : 2;
    prop *p = realloc(n->props, cap * sizeof *p);
    if (!p) return NULL;
    n->props = p;
    n->cap_props = cap;
  }
  prop *p = &n->props[n->n_props];
  memset(p, 0, sizeof *p);
  p->name = rsw_strdup(name ? name : "");
  p->loc = rsw_strdup(loc ? loc : "");
  p->kind = kind;
  n->n_props++;
  if (!p->name || !p->loc ||
      ((n->name_index || n->n_props >= NODE_INDEX_MIN) && !index_add(n, n->n_props - 1))) {
    n->n_props--;
    free(p->name);
    free(p->loc);
    return NULL;
  }
  return p;
}

prop *node_find(const node *n, const char *name) {
  if (n->name_index) {
    size_t s = index_slot(n, n->name_index, n->index_cap, name);
    return n->name_index[s] ? &n->props[n->name_index[s] - 1] : NULL;
  }
  for (size_t i = 0; i < n->n_props; i++)
    if (strcmp(n->props[i].name, name) == 0) return &n->props[i];
  return NULL;
}

static size_t str_mem(const char *s) {
  return s ? strlen(s) + 1 : 0;
}

size_t node_mem_self(const node *n) {
  return sizeof *n + str_mem(n->tag) + str_mem(n->type) + str_mem(n->id) + str_mem(n->loc);
}

size_t node_mem_arrays(const node *n) {
  return n->cap_props * sizeof *n->props + n->index_cap * sizeof *n->name_index;
}

size_t node_mem_prop(const prop *p) {
  return str_mem(p->name) + str_mem(p->loc) + str_mem(p->str) + str_mem(p->ref) + p->n_nums * sizeof(double) +
         2 * p->spec.n * sizeof(double);
}

/* ---- deterministic ids ---------------------------------------------------- */

/* Ids taken so far, hashed (open addressing; keys borrowed from nodes), and
 * per plugin type the next suffix to try. A linear set made generation
 * cubic in the number of same-type objects (k-th object: k probes, each a
 * scan); with the hash and the per-type counter it is linear. The counter
 * is exact: every candidate below it is already taken, and ids are only
 * ever added. */
typedef struct idset {
  const char **slots;
  size_t n, cap; /* cap: 0 or a power of two */
  const char **types;
  unsigned *next;
  size_t n_types, cap_types;
} idset;

static size_t id_hash(const char *s) { /* FNV-1a */
  unsigned long long h = 1469598103934665603ull;
  for (; *s; s++) h = (h ^ (unsigned char)*s) * 1099511628211ull;
  return (size_t)h;
}

static size_t idset_slot(const char **slots, size_t cap, const char *id) {
  size_t i = id_hash(id) & (cap - 1);
  while (slots[i] && strcmp(slots[i], id) != 0) i = (i + 1) & (cap - 1);
  return i;
}

static bool idset_has(const idset *s, const char *id) {
  return s->cap && s->slots[idset_slot(s->slots, s->cap, id)];
}

static bool idset_add(idset *s, const char *id) {
  if (2 * (s->n + 1) > s->cap) {
    size_t cap = s->cap ? 2 * s->cap : 64;
    const char **slots = calloc(cap, sizeof *slots);
    if (!slots) return false;
    for (size_t i = 0; i < s->cap; i++)
      if (s->slots[i]) slots[idset_slot(slots, cap, s->slots[i])] = s->slots[i];
    free(s->slots);
    s->slots = slots;
    s->cap = cap;
  }
  size_t i = idset_slot(s->slots, s->cap, id);
  if (!s->slots[i]) {
    s->slots[i] = id;
    s->n++;
  }
  return true;
}

/* Slot of the suffix counter for `type` (hashed like the id set); NULL on
 * OOM. New counters start at 0 (= the bare type name). */
static unsigned *idset_counter(idset *s, const char *type) {
  if (2 * (s->n_types + 1) > s->cap_types) {
    size_t cap = s->cap_types ? 2 * s->cap_types : 16;
    const char **types = calloc(cap, sizeof *types);
    unsigned *next = calloc(cap, sizeof *next);
    if (!types || !next) {
      free(types);
      free(next);
      return NULL;
    }
    for (size_t i = 0; i < s->cap_types; i++)
      if (s->types[i]) {
        size_t j = idset_slot(types, cap, s->types[i]);
        types[j] = s->types[i];
        next[j] = s->next[i];
      }
    free(s->types);
    free(s->next);
    s->types = types;
    s->next = next;
    s->cap_types = cap;
  }
  size_t i = idset_slot(s->types, s->cap_types, type);
  if (!s->types[i]) {
    s->types[i] = type;
    s->n_types++;
  }
  return &s->next[i];
}

static bool collect_ids(node *n, idset *s) {
  if (n->id && !idset_add(s, n->id)) return false;
  for (size_t i = 0; i < n->n_props; i++)
    if (n->props[i].kind == PROP_NODE && !collect_ids(n->props[i].child, s)) return false;
  return true;
}

static rsw_status assign(node *n, idset *s, bool is_root, rsw_err *err) {
  if (!n->id && !is_root) {
    const char *type = n->type ? n->type : "object";
    unsigned *k = idset_counter(s, type);
    if (!k) return rsw_fail(err, RSW_ERR_NOMEM, n->loc, "out of memory assigning ids");
    char buf[RSW_MAX_NAME + 32];
    for (;; ++*k) {
      if (*k == 0)
        snprintf(buf, sizeof buf, "%s", type);
      else
        snprintf(buf, sizeof buf, "%s_%u", type, *k);
      if (!idset_has(s, buf)) break;
    }
    ++*k;
    n->id = rsw_strdup(buf);
    if (!n->id || !idset_add(s, n->id))
      return rsw_fail(err, RSW_ERR_NOMEM, n->loc, "out of memory assigning ids");
  }
  for (size_t i = 0; i < n->n_props; i++)
    if (n->props[i].kind == PROP_NODE) {
      rsw_status st = assign(n->props[i].child, s, false, err);
      if (st) return st;
    }
  return RSW_OK;
}

rsw_status node_assign_ids(node *root, rsw_err *err) {
  idset s = {0};
  rsw_status st = RSW_OK;
  if (!collect_ids(root, &s))
    st = rsw_fail(err, RSW_ERR_NOMEM, root->loc, "out of memory assigning ids");
  else
    st = assign(root, &s, true, err);
  free(s.slots);
  free(s.types);
  free(s.next);
  return st;
}
