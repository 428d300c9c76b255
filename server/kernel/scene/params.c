/* The parameter table's making: the visitor every plugin's traverse()
 * reports into (pv_*, Mitsuba's traverse()), which names the entries and
 * their aliases, and the table's type names. Lookup and values:
 * param_table.c; updates: update.c. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "params.h"
#include "params_internal.h"

const char *param_type_name(param_type t) {
  static const char *const names[] = {"float", "spectrum", "rgb", "vector", "transform", "buffer", "bool"};
  return (unsigned)t < sizeof names / sizeof names[0] ? names[t] : "?";
}

const char *update_class_name(update_class c) {
  return c == UPDATE_GEOMETRIC ? "geometric" : c == UPDATE_SPECTRAL ? "spectral" : "none";
}

bool update_class_parse(const char *s, update_class *out) {
  if (strcmp(s, "none") == 0)
    *out = UPDATE_NONE;
  else if (strcmp(s, "spectral") == 0)
    *out = UPDATE_SPECTRAL;
  else if (strcmp(s, "geometric") == 0)
    *out = UPDATE_GEOMETRIC;
  else
    return false;
  return true;
}

static bool hash_put(param_table *t, const char *key, size_t idx) {
  size_t m = t->hcap - 1;
  for (size_t i = hash_str(key) & m;; i = (i + 1) & m) {
    if (!t->hval[i]) {
      t->hkey[i] = key;
      t->hval[i] = idx + 1;
      return true;
    }
    if (strcmp(t->hkey[i], key) == 0) return true; /* first wins */
  }
}

void params_free(param_table *t) {
  if (!t) return;
  for (size_t i = 0; i < t->n; i++) {
    free(t->e[i].key);
    for (size_t k = 0; k < t->e[i].n_aliases; k++) free(t->e[i].aliases[k]);
    free(t->e[i].aliases);
  }
  for (size_t i = 0; i < t->n_objs; i++) free(t->objs[i].path);
  for (size_t i = 0; i < t->n_alias; i++) free(t->alias[i].path);
  free(t->e);
  free(t->objs);
  free(t->alias);
  free(t->by_obj);
  free(t->by_path);
  free(t->hkey);
  free(t->hval);
  free(t);
}

char *params_join(const char *prefix, const char *name) {
  size_t lp = strlen(prefix), ln = strlen(name);
  char *k = malloc(lp + ln + 2);
  if (!k) return NULL;
  if (lp) {
    memcpy(k, prefix, lp);
    k[lp] = '.';
    memcpy(k + lp + 1, name, ln + 1);
  } else {
    memcpy(k, name, ln + 1);
  }
  return k;
}

/* ---- traversal -------------------------------------------------------------------- */

struct param_visitor {
  param_table *t;
  rsw_status st;
  rsw_err *err;
  object *cur;
  const char *prefix; /* path of cur ("" at the root) */
  double lo, hi;      /* constraint for a uniform texture reached here */
};

static entry *add_entry(param_visitor *v, const char *name, entry_kind kind, update_class cls) {
  if (v->st) return NULL;
  param_table *t = v->t;
  if (!grow((void **)&t->e, &t->cap, t->n, sizeof *t->e)) {
    v->st = rsw_fail(v->err, RSW_ERR_NOMEM, "params", "out of memory");
    return NULL;
  }
  entry *e = &t->e[t->n];
  memset(e, 0, sizeof *e);
  e->key = params_join(v->prefix, name);
  if (!e->key) {
    v->st = rsw_fail(v->err, RSW_ERR_NOMEM, "params", "out of memory");
    return NULL;
  }
  e->kind = kind;
  e->cls = cls;
  e->owner = v->cur;
  e->lo = -INFINITY;
  e->hi = INFINITY;
  t->n++;
  return e;
}

void pv_float(param_visitor *v, const char *name, double *ptr, update_class cls, double lo, double hi) {
  entry *e = add_entry(v, name, EK_FLOAT, cls);
  if (!e) return;
  e->fptr = ptr;
  e->lo = lo;
  e->hi = hi;
}

void pv_bool_ro(param_visitor *v, const char *name, bool value) {
  entry *e = add_entry(v, name, EK_BOOL, UPDATE_NONE);
  if (e) e->bval = value;
}

void pv_transform(param_visitor *v, const char *name, xform *ptr, update_class cls, xform_check_fn check) {
  entry *e = add_entry(v, name, EK_TRANSFORM, cls);
  if (!e) return;
  e->xptr = ptr;
  e->check = check;
}

static void add_vector(param_visitor *v, const char *name, vec_get_fn get, vec_set_fn set, update_class cls,
                       bool position) {
  entry *e = add_entry(v, name, EK_VECTOR, cls);
  if (!e) return;
  e->vget = get;
  e->vset = set;
  e->position = position;
}

void pv_vector(param_visitor *v, const char *name, vec_get_fn get, vec_set_fn set, update_class cls) {
  add_vector(v, name, get, set, cls, false);
}

void pv_position(param_visitor *v, const char *name, vec_get_fn get, vec_set_fn set, update_class cls) {
  add_vector(v, name, get, set, cls, true);
}

void pv_spectrum(param_visitor *v, const char *name, texture *t) {
  entry *e = add_entry(v, name, EK_SPECTRUM, UPDATE_SPECTRAL);
  if (!e) return;
  e->tex = t;
  e->lo = isnan(v->lo) ? -INFINITY : v->lo;
  e->hi = isnan(v->hi) ? INFINITY : v->hi;
}

void pv_mesh_buffer(param_visitor *v, const char *name, shape *sh) {
  mesh_buf b;
  update_class cls = UPDATE_GEOMETRIC;
  if (strcmp(name, "vertex_positions") == 0)
    b = MB_POSITIONS;
  else if (strcmp(name, "faces") == 0)
    b = MB_FACES;
  else if (strcmp(name, "vertex_normals") == 0)
    b = MB_NORMALS, cls = UPDATE_SPECTRAL;
  else if (strcmp(name, "vertex_texcoords") == 0)
    b = MB_TEXCOORDS, cls = UPDATE_SPECTRAL;
  else
    return;
  entry *e = add_entry(v, name, EK_MESHBUF, cls);
  if (!e) return;
  e->sh = sh;
  e->buf = b;
}

void pv_buffer(param_visitor *v, const char *name, double *data, size_t n, update_class cls, double lo,
               double hi, buffer_check_fn check) {
  entry *e = add_entry(v, name, EK_DBUF, cls);
  if (!e) return;
  e->dptr = data;
  e->dn = n;
  e->lo = lo;
  e->hi = hi;
  e->dcheck = check;
}

static size_t obj_slot(const param_table *t, const size_t *tab, size_t cap, const object *o) {
  uint64_t h = (uint64_t)(uintptr_t)o * 0x9E3779B97F4A7C15ULL;
  size_t i = (size_t)(h >> 20) & (cap - 1);
  while (tab[i] && t->objs[tab[i] - 1].o != o) i = (i + 1) & (cap - 1);
  return i;
}

static size_t path_slot(const param_table *t, const size_t *tab, size_t cap, const char *path) {
  size_t i = hash_str(path) & (cap - 1);
  while (tab[i] && strcmp(t->objs[tab[i] - 1].path, path) != 0) i = (i + 1) & (cap - 1);
  return i;
}

/* Index objs[k] (just appended); rebuilds both tables at half load. */
static bool objs_index(param_table *t, size_t k) {
  if (2 * t->n_objs > t->ocap) {
    size_t cap = t->ocap ? 2 * t->ocap : 64;
    size_t *bo = calloc(cap, sizeof *bo), *bp = calloc(cap, sizeof *bp);
    if (!bo || !bp) {
      free(bo);
      free(bp);
      return false;
    }
    for (size_t j = 0; j < t->n_objs; j++) {
      if (j == k) continue;
      size_t s = obj_slot(t, bo, cap, t->objs[j].o);
      if (!bo[s]) bo[s] = j + 1;
      s = path_slot(t, bp, cap, t->objs[j].path);
      if (!bp[s]) bp[s] = j + 1;
    }
    free(t->by_obj);
    free(t->by_path);
    t->by_obj = bo;
    t->by_path = bp;
    t->ocap = cap;
  }
  size_t s = obj_slot(t, t->by_obj, t->ocap, t->objs[k].o);
  if (!t->by_obj[s]) t->by_obj[s] = k + 1;
  s = path_slot(t, t->by_path, t->ocap, t->objs[k].path);
  if (!t->by_path[s]) t->by_path[s] = k + 1;
  return true;
}

static objrec *find_obj(const param_table *t, const object *o) {
  if (!t->ocap) return NULL;
  size_t s = obj_slot(t, t->by_obj, t->ocap, o);
  return t->by_obj[s] ? &t->objs[t->by_obj[s] - 1] : NULL;
}

static bool path_taken(const param_table *t, const char *path) {
  return t->ocap && t->by_path[path_slot(t, t->by_path, t->ocap, path)];
}

static void visit(param_visitor *v, object *o, char *path, double lo, double hi) {
  param_table *t = v->t;
  if (find_obj(t, o)) {
    /* Shared through a ref: listed once, this path becomes an alias. */
    if (!grow((void **)&t->alias, &t->cap_alias, t->n_alias, sizeof *t->alias)) {
      free(path);
      v->st = rsw_fail(v->err, RSW_ERR_NOMEM, "params", "out of memory");
      return;
    }
    t->alias[t->n_alias++] = (objrec){o, path, 0, 0};
    return;
  }
  if (!grow((void **)&t->objs, &t->cap_objs, t->n_objs, sizeof *t->objs)) {
    free(path);
    v->st = rsw_fail(v->err, RSW_ERR_NOMEM, "params", "out of memory");
    return;
  }
  size_t k = t->n_objs++;
  t->objs[k] = (objrec){o, path, t->n, t->n};
  if (!objs_index(t, k)) {
    v->st = rsw_fail(v->err, RSW_ERR_NOMEM, "params", "out of memory");
    return;
  }
  /* A sensor's medium (Mitsuba's Endpoint traverses it as "medium"),
   * whatever the sensor plugin. */
  object *sensor_medium = o->plugin && o->plugin->cls == CLS_SENSOR ? (object *)((sensor *)o)->medium : NULL;
  if (!o->plugin || (!o->plugin->traverse && !sensor_medium)) return;
  param_visitor saved = *v;
  v->cur = o;
  v->prefix = path;
  v->lo = lo;
  v->hi = hi;
  if (o->plugin->traverse) o->plugin->traverse(o, v);
  if (sensor_medium) pv_object(v, "medium", sensor_medium, NAN, NAN);
  saved.st = v->st;
  *v = saved;
  t->objs[k].e_end = t->n;
}

void pv_object(param_visitor *v, const char *name, object *child, double lo, double hi) {
  if (!child || v->st) return;
  char *path = params_join(v->prefix, name);
  if (!path) {
    v->st = rsw_fail(v->err, RSW_ERR_NOMEM, "params", "out of memory");
    return;
  }
  if (!find_obj(v->t, child) && path_taken(v->t, path)) {
    /* Name clash: Mitsuba appends _1, _2, ... */
    char *base = path;
    for (unsigned k = 1;; k++) {
      char buf[32];
      snprintf(buf, sizeof buf, "_%u", k);
      path = malloc(strlen(base) + strlen(buf) + 1);
      if (!path) break;
      strcpy(path, base);
      strcat(path, buf);
      if (!path_taken(v->t, path)) break;
      free(path);
    }
    free(base);
    if (!path) {
      v->st = rsw_fail(v->err, RSW_ERR_NOMEM, "params", "out of memory");
      return;
    }
  }
  visit(v, child, path, lo, hi);
}

/* Aliases: for every other path A of a shared object O, each entry whose
 * key lies under O's first path P gets the alias A + key[len(P):]. Those
 * entries were added while O was traversed (keys are built from the
 * traversal prefix), so only that range is scanned: a BSDF shared by
 * 100,000 group members costs 100,000 x its own entries, not x all. */
static rsw_status build_aliases(param_table *t, rsw_err *err) {
  for (size_t a = 0; a < t->n_alias; a++) {
    const objrec *first = find_obj(t, t->alias[a].o);
    if (!first) continue;
    size_t lp = strlen(first->path);
    for (size_t i = first->e_begin; i < first->e_end; i++) {
      entry *e = &t->e[i];
      if (strncmp(e->key, first->path, lp) != 0 || e->key[lp] != '.') continue;
      char *al = params_join(t->alias[a].path, e->key + lp + 1);
      char **arr = e->aliases;
      /* Capacity doubles at powers of two (implicit in n_aliases). */
      if (al && (e->n_aliases & (e->n_aliases - 1)) == 0)
        arr = realloc(e->aliases, (e->n_aliases ? 2 * e->n_aliases : 1) * sizeof *arr);
      if (!al || !arr) {
        free(al);
        return rsw_fail(err, RSW_ERR_NOMEM, "params", "out of memory");
      }
      e->aliases = arr;
      e->aliases[e->n_aliases++] = al;
    }
  }
  return RSW_OK;
}

static rsw_status build_hash(param_table *t, rsw_err *err) {
  size_t count = t->n;
  for (size_t i = 0; i < t->n; i++) count += t->e[i].n_aliases;
  size_t cap = 64;
  while (cap < 2 * count + 1) cap *= 2;
  t->hkey = calloc(cap, sizeof *t->hkey);
  t->hval = calloc(cap, sizeof *t->hval);
  if (!t->hkey || !t->hval) return rsw_fail(err, RSW_ERR_NOMEM, "params", "out of memory");
  t->hcap = cap;
  for (size_t i = 0; i < t->n; i++) hash_put(t, t->e[i].key, i);
  for (size_t i = 0; i < t->n; i++)
    for (size_t k = 0; k < t->e[i].n_aliases; k++) hash_put(t, t->e[i].aliases[k], i);
  return RSW_OK;
}

rsw_status params_build(scene *s, rsw_err *err) {
  params_free(s->params);
  s->params = NULL;
  param_table *t = calloc(1, sizeof *t);
  if (!t) return rsw_fail(err, RSW_ERR_NOMEM, "params", "out of memory");
  param_visitor v = {.t = t, .err = err, .cur = &s->base, .prefix = "", .lo = NAN, .hi = NAN};
  /* Mitsuba's Scene::traverse reports this flag first. We do not reorder
   * threads, so it is read-only here. */
  pv_bool_ro(&v, "allow_thread_reordering", true);
  /* Scene children by id, in declaration order. */
  node *root = s->doc;
  for (size_t i = 0; root && i < root->n_props && !v.st; i++) {
    prop *p = &root->props[i];
    if (p->kind != PROP_NODE || !p->child->built) continue;
    if (strcmp(p->child->loc, "(default)") == 0) continue; /* synthetic defaults */
    object *o = p->child->built;
    pv_object(&v, o->id, o, NAN, NAN);
  }
  rsw_status st = v.st;
  if (!st) st = build_aliases(t, err);
  if (!st) st = build_hash(t, err);
  if (st) {
    params_free(t);
    return st;
  }
  s->params = t;
  return RSW_OK;
}
