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
  free(n->tag);
  free(n->type);
  free(n->id);
  free(n->loc);
  free(n);
}

prop *node_add_prop(node *n, const char *name, prop_kind kind, const char *loc) {
  if (n->n_props >= RSW_MAX_PROPS) return NULL;
  if (n->n_props == n->cap_props) {
    size_t cap = n->cap_props ? 2 * n->cap_props : 8;
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
  if (!p->name || !p->loc) {
    free(p->name);
    free(p->loc);
    return NULL;
  }
  n->n_props++;
  return p;
}

prop *node_find(const node *n, const char *name) {
  for (size_t i = 0; i < n->n_props; i++)
    if (strcmp(n->props[i].name, name) == 0) return &n->props[i];
  return NULL;
}

/* ---- deterministic ids ---------------------------------------------------- */

typedef struct idset {
  char **ids;
  size_t n, cap;
} idset;

static bool idset_has(const idset *s, const char *id) {
  for (size_t i = 0; i < s->n; i++)
    if (strcmp(s->ids[i], id) == 0) return true;
  return false;
}

static bool idset_add(idset *s, const char *id) {
  if (s->n == s->cap) {
    size_t cap = s->cap ? 2 * s->cap : 64;
    char **p = realloc(s->ids, cap * sizeof *p);
    if (!p) return false;
    s->ids = p;
    s->cap = cap;
  }
  s->ids[s->n++] = (char *)id;
  return true;
}

static bool collect_ids(node *n, idset *s) {
  if (n->id && !idset_add(s, n->id)) return false;
  for (size_t i = 0; i < n->n_props; i++)
    if (n->props[i].kind == PROP_NODE && !collect_ids(n->props[i].child, s)) return false;
  return true;
}

static rsw_status assign(node *n, idset *s, bool is_root, rsw_err *err) {
  if (!n->id && !is_root) {
    char buf[RSW_MAX_NAME + 32];
    snprintf(buf, sizeof buf, "%s", n->type ? n->type : "object");
    for (unsigned k = 1; idset_has(s, buf); k++)
      snprintf(buf, sizeof buf, "%s_%u", n->type ? n->type : "object", k);
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
  free(s.ids);
  return st;
}
