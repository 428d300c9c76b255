/* The scene parameter table: traversal, lookup, updates (see params.h). */
#include "params.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../accel.h"
#include "../core/strdist.h"
#include "../media/media.h"
#include "../shapes/mesh_io.h"
#include "../shapes/shape.h"
#include "../textures/texture.h"
#include "scene.h"

/* ---- entries and the table ------------------------------------------------------ */

typedef enum entry_kind {
  EK_FLOAT,
  EK_BOOL,
  EK_TRANSFORM,
  EK_VECTOR,
  EK_SPECTRUM,
  EK_MESHBUF,
  EK_DBUF /* pv_buffer: a plugin's array of doubles, fixed length */
} entry_kind;
typedef enum mesh_buf {
  MB_POSITIONS,
  MB_FACES,
  MB_NORMALS,
  MB_TEXCOORDS
} mesh_buf;

typedef struct entry {
  char *key;
  entry_kind kind;
  update_class cls;
  object *owner;
  double lo, hi;
  double *fptr;
  bool bval;
  xform *xptr;
  xform_check_fn check;
  vec_get_fn vget;
  vec_set_fn vset;
  texture *tex;
  shape *sh;
  mesh_buf buf;
  double *dptr; /* EK_DBUF */
  size_t dn;
  buffer_check_fn dcheck;
  char **aliases;
  size_t n_aliases;
} entry;

typedef struct objrec {
  object *o;
  char *path;
  size_t e_begin, e_end; /* entries added while it was traversed */
} objrec;

struct param_table {
  entry *e;
  size_t n, cap;
  objrec *objs; /* first path of every object reached */
  size_t n_objs, cap_objs;
  objrec *alias; /* further paths of shared objects */
  size_t n_alias, cap_alias;
  /* objs by object pointer and by path: index + 1 (0 = empty), open
   * addressing, so that traversing 100,000 group members stays linear. */
  size_t *by_obj, *by_path;
  size_t ocap;
  /* Open-addressing hash: key or alias -> entry index + 1 (0 = empty). */
  const char **hkey;
  size_t *hval;
  size_t hcap;
};

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

static bool grow(void **arr, size_t *cap, size_t n, size_t elem) {
  if (n < *cap) return true;
  size_t c = *cap ? 2 * *cap : 32;
  void *p = realloc(*arr, c * elem);
  if (!p) return false;
  *arr = p;
  *cap = c;
  return true;
}

static uint64_t hash_str(const char *s) {
  uint64_t h = 1469598103934665603ULL;
  for (; *s; s++) h = (h ^ (unsigned char)*s) * 1099511628211ULL;
  return h;
}

static size_t hash_find(const param_table *t, const char *key) {
  if (!t->hcap) return 0;
  size_t m = t->hcap - 1;
  for (size_t i = hash_str(key) & m;; i = (i + 1) & m) {
    if (!t->hval[i]) return 0;
    if (strcmp(t->hkey[i], key) == 0) return t->hval[i];
  }
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

/* ---- traversal -------------------------------------------------------------------- */

struct param_visitor {
  param_table *t;
  rsw_status st;
  rsw_err *err;
  object *cur;
  const char *prefix; /* path of cur ("" at the root) */
  double lo, hi;      /* constraint for a uniform texture reached here */
};

static char *join(const char *prefix, const char *name) {
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

static entry *add_entry(param_visitor *v, const char *name, entry_kind kind, update_class cls) {
  if (v->st) return NULL;
  param_table *t = v->t;
  if (!grow((void **)&t->e, &t->cap, t->n, sizeof *t->e)) {
    v->st = rsw_fail(v->err, RSW_ERR_NOMEM, "params", "out of memory");
    return NULL;
  }
  entry *e = &t->e[t->n];
  memset(e, 0, sizeof *e);
  e->key = join(v->prefix, name);
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

void pv_vector(param_visitor *v, const char *name, vec_get_fn get, vec_set_fn set, update_class cls) {
  entry *e = add_entry(v, name, EK_VECTOR, cls);
  if (!e) return;
  e->vget = get;
  e->vset = set;
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
  char *path = join(v->prefix, name);
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
      char *al = join(t->alias[a].path, e->key + lp + 1);
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

/* ---- lookup --------------------------------------------------------------------- */

size_t params_count(const scene *s) {
  return s->params ? s->params->n : 0;
}

static void entry_shape(const entry *e, size_t dims[2]) {
  dims[0] = 1;
  dims[1] = 0;
  switch (e->kind) {
  case EK_TRANSFORM: dims[0] = 4, dims[1] = 4; break;
  case EK_VECTOR: dims[0] = 3; break;
  case EK_SPECTRUM: {
    const spectrum *sp = uniform_texture_spectrum(e->tex);
    if (sp && sp->kind == SPEC_TABLE)
      dims[0] = sp->n, dims[1] = 2;
    else if (sp && sp->kind == SPEC_RGB)
      dims[0] = 3;
    break;
  }
  case EK_MESHBUF: {
    const mesh *m = &e->sh->mesh;
    dims[0] = e->buf == MB_FACES       ? 3 * (size_t)m->n_faces
              : e->buf == MB_TEXCOORDS ? 2 * (size_t)m->n_verts
                                       : 3 * (size_t)m->n_verts;
    break;
  }
  case EK_DBUF: dims[0] = e->dn; break;
  default: break;
  }
}

static param_type entry_type(const scene *s, const entry *e) {
  switch (e->kind) {
  case EK_FLOAT: return PARAM_FLOAT;
  case EK_BOOL: return PARAM_BOOL;
  case EK_TRANSFORM: return PARAM_TRANSFORM;
  case EK_VECTOR: return PARAM_VECTOR;
  case EK_SPECTRUM: return s->variant == VARIANT_MONO ? PARAM_SPECTRUM : PARAM_RGB;
  case EK_MESHBUF:
  case EK_DBUF: return PARAM_BUFFER;
  }
  return PARAM_FLOAT;
}

bool params_info(const scene *s, size_t i, param_info *out) {
  if (!s->params || i >= s->params->n) return false;
  const entry *e = &s->params->e[i];
  memset(out, 0, sizeof *out);
  out->key = e->key;
  out->type = entry_type(s, e);
  out->cls = e->cls;
  entry_shape(e, out->shape);
  out->object_type = e->owner->plugin ? e->owner->plugin->name : "scene";
  out->object_class = e->owner->plugin ? obj_class_name(e->owner->plugin->cls) : "scene";
  out->object_id = e->owner->id ? e->owner->id : "";
  out->aliases = (const char *const *)e->aliases;
  out->n_aliases = e->n_aliases;
  return true;
}

size_t params_closest(const scene *s, const char *key, const char *out[3]) {
  const param_table *t = s->params;
  size_t bd[3] = {(size_t)-1, (size_t)-1, (size_t)-1};
  out[0] = out[1] = out[2] = NULL;
  for (size_t i = 0; t && i < t->n; i++) {
    size_t d = rsw_edit_distance(key, t->e[i].key);
    for (int k = 0; k < 3; k++)
      if (d < bd[k]) {
        for (int j = 2; j > k; j--) bd[j] = bd[j - 1], out[j] = out[j - 1];
        bd[k] = d;
        out[k] = t->e[i].key;
        break;
      }
  }
  return out[2] ? 3 : out[1] ? 2 : out[0] ? 1 : 0;
}

static rsw_status not_found(const scene *s, const char *key, rsw_err *err) {
  const param_table *t = s->params;
  const char *best[3] = {NULL, NULL, NULL};
  size_t bd[3] = {(size_t)-1, (size_t)-1, (size_t)-1};
  for (size_t i = 0; t && i < t->n; i++) {
    size_t d = rsw_edit_distance(key, t->e[i].key);
    for (int k = 0; k < 3; k++)
      if (d < bd[k]) {
        for (int j = 2; j > k; j--) bd[j] = bd[j - 1], best[j] = best[j - 1];
        bd[k] = d;
        best[k] = t->e[i].key;
        break;
      }
  }
  /* Mitsuba silently ignores unknown keys; an unknown key here is an error
   * so that a misspelt update cannot go unnoticed. */
  if (!best[0])
    return rsw_fail(err, RSW_ERR_NOT_FOUND, key, "unknown parameter '%s' (the scene has none)", key);
  return rsw_fail(err, RSW_ERR_NOT_FOUND, key, "unknown parameter '%s'; closest: %s%s%s%s%s", key, best[0],
                  best[1] ? ", " : "", best[1] ? best[1] : "", best[2] ? ", " : "", best[2] ? best[2] : "");
}

/* TYPE:ID:PATH -> the key of PATH under the object of class or plugin TYPE
 * and id ID (Eradiate's SearchSceneParameter). */
static rsw_status resolve_search(const scene *s, const char *spec, char **key_out, rsw_err *err) {
  const char *c1 = strchr(spec, ':');
  const char *c2 = c1 ? strchr(c1 + 1, ':') : NULL;
  if (!c1 || !c2 || c1 == spec || c2 == c1 + 1 || !c2[1])
    return rsw_fail(err, RSW_ERR_INVALID, spec,
                    "a search is written TYPE:ID:PATH (e.g. bsdf:surface_bsdf:reflectance.value)");
  size_t lt = (size_t)(c1 - spec), li = (size_t)(c2 - c1 - 1);
  const param_table *t = s->params;
  for (size_t i = 0; t && i < t->n_objs; i++) {
    const object *o = t->objs[i].o;
    if (!o->id || strlen(o->id) != li || strncmp(o->id, c1 + 1, li) != 0) continue;
    const char *cls = o->plugin ? obj_class_name(o->plugin->cls) : "scene";
    const char *pname = o->plugin ? o->plugin->name : "scene";
    if ((strlen(cls) == lt && strncmp(cls, spec, lt) == 0) ||
        (strlen(pname) == lt && strncmp(pname, spec, lt) == 0)) {
      *key_out = join(t->objs[i].path, c2 + 1);
      return *key_out ? RSW_OK : rsw_fail(err, RSW_ERR_NOMEM, spec, "out of memory");
    }
  }
  return rsw_fail(err, RSW_ERR_NOT_FOUND, spec, "no %.*s with id '%.*s' in the scene", (int)lt, spec, (int)li,
                  c1 + 1);
}

rsw_status params_lookup(const scene *s, const char *key, size_t *index, rsw_err *err) {
  if (!s->params) return rsw_fail(err, RSW_ERR_NOT_FOUND, key, "the scene has no parameter table");
  size_t h = hash_find(s->params, key);
  if (h) {
    *index = h - 1;
    return RSW_OK;
  }
  if (strchr(key, ':')) {
    char *k = NULL;
    rsw_status st = resolve_search(s, key, &k, err);
    if (st) return st;
    h = hash_find(s->params, k);
    if (!h) {
      rsw_fail(err, RSW_ERR_NOT_FOUND, key, "'%s' resolves to '%s', which is not a parameter", key, k);
      free(k);
      return RSW_ERR_NOT_FOUND;
    }
    free(k);
    *index = h - 1;
    return RSW_OK;
  }
  return not_found(s, key, err);
}

rsw_status params_match(const scene *s, const char *glob, unsigned class_mask, bool include_none,
                        size_t **out, size_t *count, rsw_err *err) {
  *out = NULL;
  *count = 0;
  const param_table *t = s->params;
  size_t n = t ? t->n : 0;
  size_t *res = malloc((n ? n : 1) * sizeof *res);
  if (!res) return rsw_fail(err, RSW_ERR_NOMEM, glob, "out of memory");
  size_t k = 0;
  if (strchr(glob, ':')) {
    size_t i;
    rsw_status st = params_lookup(s, glob, &i, err);
    if (st) {
      free(res);
      return st;
    }
    const entry *e = &t->e[i];
    if ((e->cls & class_mask) || (e->cls == UPDATE_NONE && include_none)) res[k++] = i;
  } else {
    for (size_t i = 0; i < n; i++) {
      const entry *e = &t->e[i];
      if (!((e->cls & class_mask) || (e->cls == UPDATE_NONE && include_none))) continue;
      bool m = rsw_glob_match(glob, e->key);
      for (size_t a = 0; !m && a < e->n_aliases; a++) m = rsw_glob_match(glob, e->aliases[a]);
      if (m) res[k++] = i;
    }
  }
  if (!k) {
    free(res);
    return rsw_fail(err, RSW_ERR_NOT_FOUND, glob, "no parameter matches '%s'", glob);
  }
  *out = res;
  *count = k;
  return RSW_OK;
}

/* ---- values as JSON ---------------------------------------------------------------- */

typedef struct sbuf {
  char *p;
  size_t n, cap;
  bool oom;
} sbuf;

static void sb_printf(sbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void sb_printf(sbuf *b, const char *fmt, ...) {
  if (b->oom) return;
  for (;;) {
    va_list ap;
    va_start(ap, fmt);
    int w = vsnprintf(b->p ? b->p + b->n : NULL, b->p ? b->cap - b->n : 0, fmt, ap);
    va_end(ap);
    if (w < 0) {
      b->oom = true;
      return;
    }
    if (b->p && b->n + (size_t)w < b->cap) {
      b->n += (size_t)w;
      return;
    }
    size_t cap = b->cap ? b->cap : 64;
    while (cap <= b->n + (size_t)w) cap *= 2;
    char *np = realloc(b->p, cap);
    if (!np) {
      b->oom = true;
      return;
    }
    b->p = np;
    b->cap = cap;
  }
}

static void sb_num(sbuf *b, double v) {
  if (v == floor(v) && fabs(v) < 1e15)
    sb_printf(b, "%.0f", v);
  else
    sb_printf(b, "%.17g", v);
}

static void sb_nums(sbuf *b, const double *v, size_t n) {
  sb_printf(b, "[");
  for (size_t i = 0; i < n; i++) {
    if (i) sb_printf(b, ", ");
    sb_num(b, v[i]);
  }
  sb_printf(b, "]");
}

char *params_value_json(const scene *s, size_t i, size_t max_items) {
  if (!s->params || i >= s->params->n) return NULL;
  const entry *e = &s->params->e[i];
  sbuf b = {0};
  switch (e->kind) {
  case EK_FLOAT: sb_num(&b, *e->fptr); break;
  case EK_BOOL: sb_printf(&b, "%s", e->bval ? "true" : "false"); break;
  case EK_TRANSFORM:
    sb_printf(&b, "[");
    for (int r = 0; r < 4; r++) {
      if (r) sb_printf(&b, ", ");
      sb_nums(&b, e->xptr->m[r], 4);
    }
    sb_printf(&b, "]");
    break;
  case EK_VECTOR: {
    vec3 v = e->vget(e->owner);
    double a[3] = {v.x, v.y, v.z};
    sb_nums(&b, a, 3);
    break;
  }
  case EK_SPECTRUM: {
    const spectrum *sp = uniform_texture_spectrum(e->tex);
    if (!sp) break;
    if (sp->kind == SPEC_UNIFORM) {
      sb_num(&b, sp->value);
    } else if (sp->kind == SPEC_RGB) {
      sb_nums(&b, sp->rgb, 3);
    } else {
      sb_printf(&b, "{\"wavelengths\": ");
      sb_nums(&b, sp->wl, sp->n);
      sb_printf(&b, ", \"values\": ");
      sb_nums(&b, sp->val, sp->n);
      sb_printf(&b, "}");
    }
    break;
  }
  case EK_MESHBUF: {
    size_t dims[2];
    entry_shape(e, dims);
    size_t n = dims[0];
    if (max_items && n > max_items) {
      sb_printf(&b, "{\"length\": %zu}", n);
      break;
    }
    const mesh *m = &e->sh->mesh;
    sb_printf(&b, "[");
    for (size_t k = 0; k < n; k++) {
      if (k) sb_printf(&b, ", ");
      if (e->buf == MB_FACES)
        sb_printf(&b, "%u", m->faces[k]);
      else
        sb_printf(&b, "%.9g",
                  (double)(e->buf == MB_POSITIONS ? m->pos[k]
                           : e->buf == MB_NORMALS ? m->nrm[k]
                                                  : m->uv[k]));
    }
    sb_printf(&b, "]");
    break;
  }
  case EK_DBUF:
    if (max_items && e->dn > max_items)
      sb_printf(&b, "{\"length\": %zu}", e->dn);
    else
      sb_nums(&b, e->dptr, e->dn);
    break;
  }
  if (b.oom) {
    free(b.p);
    return NULL;
  }
  return b.p;
}

/* ---- parsing values --------------------------------------------------------------- */

void param_value_free(param_value *v) {
  if (!v) return;
  free(v->arr);
  spectrum_free(&v->table);
  memset(v, 0, sizeof *v);
}

static bool json_numbers(const cJSON *a, double *out, size_t *n) {
  size_t k = 0;
  for (const cJSON *x = a->child; x; x = x->next) {
    if (!cJSON_IsNumber(x)) return false;
    if (out) out[k] = x->valuedouble;
    k++;
  }
  *n = k;
  return true;
}

static rsw_status parse_table(const cJSON *o, const char *where, spectrum *out, rsw_err *err) {
  const cJSON *wl = cJSON_GetObjectItemCaseSensitive(o, "wavelengths");
  const cJSON *vals = cJSON_GetObjectItemCaseSensitive(o, "values");
  const cJSON *value = cJSON_GetObjectItemCaseSensitive(o, "value");
  memset(out, 0, sizeof *out);
  out->kind = SPEC_TABLE;
  size_t n = 0;
  if (wl && vals) {
    size_t n2;
    if (!cJSON_IsArray(wl) || !cJSON_IsArray(vals) || !json_numbers(wl, NULL, &n) ||
        !json_numbers(vals, NULL, &n2) || n != n2)
      return rsw_fail(err, RSW_ERR_TYPE, where,
                      "a tabulated spectrum needs \"wavelengths\" and \"values\": two lists of numbers of "
                      "the same length");
  } else if (value && cJSON_IsArray(value)) {
    for (const cJSON *x = value->child; x; x = x->next) {
      size_t k;
      if (!cJSON_IsArray(x) || !json_numbers(x, NULL, &k) || k != 2)
        return rsw_fail(err, RSW_ERR_TYPE, where,
                        "a spectrum \"value\" list holds [wavelength_nm, value] pairs");
      n++;
    }
  } else {
    return rsw_fail(err, RSW_ERR_TYPE, where,
                    "expected {\"wavelengths\": [...], \"values\": [...]} or {\"type\": \"spectrum\", "
                    "\"value\": [[wl, v], ...]}");
  }
  if (n < 2 || n > RSW_MAX_SPECTRUM)
    return rsw_fail(err, RSW_ERR_INVALID, where, "a tabulated spectrum needs between 2 and %d samples",
                    RSW_MAX_SPECTRUM);
  out->n = n;
  out->wl = malloc(n * sizeof(double));
  out->val = malloc(n * sizeof(double));
  if (!out->wl || !out->val) {
    spectrum_free(out);
    return rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory");
  }
  if (wl && vals) {
    size_t k;
    json_numbers(wl, out->wl, &k);
    json_numbers(vals, out->val, &k);
  } else {
    size_t i = 0;
    for (const cJSON *x = value->child; x; x = x->next, i++) {
      out->wl[i] = x->child->valuedouble;
      out->val[i] = x->child->next->valuedouble;
    }
  }
  for (size_t i = 0; i < n; i++)
    if (!(out->wl[i] > 0) || (i && !(out->wl[i] > out->wl[i - 1]))) {
      spectrum_free(out);
      return rsw_fail(err, RSW_ERR_INVALID, where,
                      "spectrum wavelengths must be positive and strictly increasing");
    }
  return RSW_OK;
}

rsw_status param_value_parse(const char *json, const char *where, param_value *out, rsw_err *err) {
  memset(out, 0, sizeof *out);
  if (!json || !*json) return rsw_fail(err, RSW_ERR_PARSE, where, "empty value");
  const char *end = NULL;
  cJSON *j = cJSON_ParseWithOpts(json, &end, 1);
  if (!j) return rsw_fail(err, RSW_ERR_PARSE, where, "value is not valid JSON: '%s'", json);
  rsw_status st = RSW_OK;
  if (cJSON_IsNumber(j)) {
    out->kind = PV_NUMBER;
    out->num = j->valuedouble;
  } else if (cJSON_IsBool(j)) {
    out->kind = PV_BOOL;
    out->b = cJSON_IsTrue(j);
  } else if (cJSON_IsArray(j)) {
    out->kind = PV_ARRAY;
    size_t n = 0;
    if (json_numbers(j, NULL, &n)) {
      out->arr = malloc((n ? n : 1) * sizeof(double));
      if (!out->arr)
        st = rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory");
      else
        json_numbers(j, out->arr, &out->n);
    } else {
      /* Nested rows of equal length (a 4x4 matrix). */
      size_t rows = 0, cols = 0, total = 0;
      for (const cJSON *r = j->child; r && !st; r = r->next, rows++) {
        size_t k = 0;
        if (!cJSON_IsArray(r) || !json_numbers(r, NULL, &k) || (rows && k != cols))
          st = rsw_fail(err, RSW_ERR_TYPE, where, "expected numbers, or rows of numbers of equal length");
        cols = k;
        total += k;
      }
      if (!st) {
        out->arr = malloc((total ? total : 1) * sizeof(double));
        if (!out->arr) st = rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory");
      }
      if (!st) {
        size_t k = 0;
        for (const cJSON *r = j->child; r; r = r->next) {
          size_t m = 0;
          json_numbers(r, out->arr + k, &m);
          k += m;
        }
        out->n = total;
        out->rows = rows;
      }
    }
  } else if (cJSON_IsObject(j)) {
    const cJSON *type = cJSON_GetObjectItemCaseSensitive(j, "type");
    const cJSON *value = cJSON_GetObjectItemCaseSensitive(j, "value");
    if (type && cJSON_IsString(type) &&
        (strcmp(type->valuestring, "rgb") == 0 || strcmp(type->valuestring, "uniform") == 0)) {
      /* {"type": "rgb", "value": [r, g, b]} / {"type": "uniform", "value": x} */
      if (value && cJSON_IsNumber(value)) {
        out->kind = PV_NUMBER;
        out->num = value->valuedouble;
      } else if (value && cJSON_IsArray(value) && strcmp(type->valuestring, "rgb") == 0) {
        size_t n;
        out->kind = PV_ARRAY;
        out->arr = malloc(3 * sizeof(double));
        if (!out->arr || !json_numbers(value, NULL, &n) || n != 3)
          st = rsw_fail(err, RSW_ERR_TYPE, where, "rgb: \"value\" must be 3 numbers");
        else
          json_numbers(value, out->arr, &out->n);
      } else {
        st = rsw_fail(err, RSW_ERR_TYPE, where, "%s: missing or bad \"value\"", type->valuestring);
      }
    } else if (type && cJSON_IsString(type) && strcmp(type->valuestring, "spectrum") == 0 && value &&
               cJSON_IsNumber(value)) {
      out->kind = PV_NUMBER;
      out->num = value->valuedouble;
    } else {
      out->kind = PV_TABLE;
      st = parse_table(j, where, &out->table, err);
    }
  } else {
    st = rsw_fail(err, RSW_ERR_TYPE, where, "expected a number, a list of numbers or a spectrum object");
  }
  cJSON_Delete(j);
  if (st) param_value_free(out);
  return st;
}

/* ---- updates -------------------------------------------------------------------- */

static const char *kind_expect(const scene *s, const entry *e) {
  switch (e->kind) {
  case EK_FLOAT: return "a number";
  case EK_BOOL: return "a boolean";
  case EK_TRANSFORM: return "a 4x4 matrix (16 numbers, row-major, or 4 rows of 4)";
  case EK_VECTOR: return "3 numbers";
  case EK_SPECTRUM:
    return s->variant == VARIANT_MONO ? "a number, an [r, g, b] triple or a tabulated spectrum"
                                      : "a number or an [r, g, b] triple";
  case EK_MESHBUF: return "a flat list of numbers";
  case EK_DBUF: return "a flat list of numbers";
  }
  return "a value";
}

/* A range bound as text: %g when that reads back exactly, else all 17
 * digits (an open interval's bound, e.g. hg's g < 1, is the closed one
 * just inside it, which %g would print as the excluded 1). */
static const char *bound_text(double b, char buf[32]) {
  snprintf(buf, 32, "%g", b);
  if (strtod(buf, NULL) != b) snprintf(buf, 32, "%.17g", b);
  return buf;
}

static rsw_status check_range(const entry *e, const char *key, double x, rsw_err *err) {
  if (!isfinite(x)) return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': value must be finite", key);
  if (fabs(x) > RSW_MAX_MAGNITUDE)
    return rsw_fail(err, RSW_ERR_RANGE, key,
                    "'%s': value %g exceeds the largest magnitude a value may have (%g)", key, x,
                    RSW_MAX_MAGNITUDE);
  if (x < e->lo || x > e->hi) {
    char lo[32], hi[32];
    if (isinf(e->hi))
      return rsw_fail(err, RSW_ERR_RANGE, key, "'%s': value %g must be >= %s", key, x, bound_text(e->lo, lo));
    return rsw_fail(err, RSW_ERR_RANGE, key, "'%s': value %g must lie in [%s, %s]", key, x,
                    bound_text(e->lo, lo), bound_text(e->hi, hi));
  }
  return RSW_OK;
}

/* A staged update: what validation decided, applied afterwards. */
typedef struct staged {
  size_t index;
  const param_update *item;
  xform xf;
  spectrum spec; /* borrowed from the item (copied on apply) */
  vec3 vec;
  float *fpos; /* vertex_positions converted to float (owned until applied) */
  bool changed;
  /* Prepared before anything is written (prepare()), so that applying
   * cannot fail; and what applying replaced, so that a failure after it
   * (Embree, the scene-wide float32 check, a sensor) puts it all back. */
  spectrum new_spec; /* owned copy of the new spectrum; after apply: the old one */
  bool spec_ready;
  void *buf; /* faces (uint32), normals or texcoords (float), owned */
  bool applied;
  double old_f;
  xform old_xf;
  vec3 old_vec;
  void *old_buf;      /* the mesh buffer replaced (positions, faces, normals, uvs) */
  uint32_t old_count; /* n_verts (positions) or n_faces (faces) before */
} staged;

static bool spectrum_equal(const spectrum *a, const spectrum *b) {
  if (a->kind != b->kind) return false;
  switch (a->kind) {
  case SPEC_UNIFORM: return a->value == b->value;
  case SPEC_RGB: return memcmp(a->rgb, b->rgb, sizeof a->rgb) == 0;
  case SPEC_TABLE:
    return a->n == b->n && memcmp(a->wl, b->wl, a->n * sizeof(double)) == 0 &&
           memcmp(a->val, b->val, a->n * sizeof(double)) == 0;
  }
  return false;
}

/* Vertex count the mesh will have after this map (positions may change it
 * only together with faces). */
static rsw_status validate(const scene *s, staged *sg, const staged *all, size_t n_all, rsw_err *err) {
  const entry *e = &s->params->e[sg->index];
  const param_value *v = &sg->item->value;
  const char *key = sg->item->key;
  if (e->cls == UPDATE_NONE) return rsw_fail(err, RSW_ERR_INVALID, key, "'%s' is read-only", e->key);
  switch (e->kind) {
  case EK_FLOAT: {
    if (v->kind != PV_NUMBER)
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes %s", key, kind_expect(s, e));
    rsw_status st = check_range(e, key, v->num, err);
    if (st) return st;
    sg->changed = *e->fptr != v->num;
    return RSW_OK;
  }
  case EK_TRANSFORM: {
    if (v->kind != PV_ARRAY || v->n != 16 || (v->rows && v->rows != 4))
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes %s", key, kind_expect(s, e));
    double m[4][4];
    for (int i = 0; i < 16; i++) {
      if (!isfinite(v->arr[i]))
        return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': matrix entries must be finite", key);
      m[i / 4][i % 4] = v->arr[i];
    }
    /* A shape's transform (the geometric ones) must be one float32 tracing
     * can represent: checked on the matrix itself first, so that a tiny
     * scale is reported as such rather than as "singular". */
    char msg[512];
    if (e->cls == UPDATE_GEOMETRIC && !xf_traceable(m, key, msg, sizeof msg))
      return rsw_fail(err, RSW_ERR_RANGE, key, "%s", msg);
    if (!xf_from_matrix(m, &sg->xf))
      return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': matrix is singular", key);
    if (e->check) {
      rsw_status st = e->check(e->owner, &sg->xf, key, err);
      if (st) return st;
    }
    sg->changed = memcmp(e->xptr->m, sg->xf.m, sizeof sg->xf.m) != 0;
    return RSW_OK;
  }
  case EK_VECTOR: {
    if (v->kind != PV_ARRAY || v->n != 3 || v->rows)
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes %s", key, kind_expect(s, e));
    sg->vec = v3(v->arr[0], v->arr[1], v->arr[2]);
    if (!v3_finite(sg->vec) || !(v3_len(sg->vec) > 0))
      return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': a direction must be finite and non-zero", key);
    vec3 cur = e->vget(e->owner);
    sg->changed = cur.x != sg->vec.x || cur.y != sg->vec.y || cur.z != sg->vec.z;
    return RSW_OK;
  }
  case EK_SPECTRUM: {
    spectrum sp = {.kind = SPEC_UNIFORM};
    if (v->kind == PV_NUMBER) {
      sp.value = v->num;
      rsw_status st = check_range(e, key, v->num, err);
      if (st) return st;
    } else if (v->kind == PV_ARRAY && v->n == 3 && !v->rows) {
      sp.kind = SPEC_RGB;
      for (int i = 0; i < 3; i++) {
        sp.rgb[i] = v->arr[i];
        rsw_status st = check_range(e, key, v->arr[i], err);
        if (st) return st;
      }
    } else if (v->kind == PV_TABLE) {
      if (s->variant != VARIANT_MONO)
        return rsw_fail(err, RSW_ERR_UNSUPPORTED, key,
                        "'%s': a tabulated spectrum needs the mono variant (this scene is rgb)", key);
      sp = v->table;
      for (size_t i = 0; i < sp.n; i++) {
        rsw_status st = check_range(e, key, sp.val[i], err);
        if (st) return st;
      }
    } else {
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes %s", key, kind_expect(s, e));
    }
    sg->spec = sp;
    const spectrum *cur = uniform_texture_spectrum(e->tex);
    sg->changed = !cur || !spectrum_equal(cur, &sp);
    return RSW_OK;
  }
  case EK_MESHBUF: {
    if (v->kind != PV_ARRAY || v->rows)
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes %s", key, kind_expect(s, e));
    const mesh *m = &e->sh->mesh;
    /* Other buffers of the same mesh in this map decide the new counts. */
    const param_value *pos = NULL, *faces = NULL;
    for (size_t k = 0; k < n_all; k++) {
      const entry *o = &s->params->e[all[k].index];
      if (o->kind != EK_MESHBUF || o->sh != e->sh) continue;
      if (o->buf == MB_POSITIONS) pos = &all[k].item->value;
      if (o->buf == MB_FACES) faces = &all[k].item->value;
    }
    size_t nv = pos && pos->kind == PV_ARRAY ? pos->n / 3 : m->n_verts;
    switch (e->buf) {
    case MB_POSITIONS:
      if (v->n % 3 || !v->n || (v->n != 3 * (size_t)m->n_verts && !faces))
        return rsw_fail(err, RSW_ERR_INVALID, key,
                        "'%s' takes %u numbers (3 per vertex); changing the vertex count needs 'faces' in "
                        "the same update",
                        key, 3 * m->n_verts);
      if (v->n / 3 > MESH_MAX_ELEMENTS)
        return rsw_fail(err, RSW_ERR_LIMIT, key, "'%s': too many vertices", key);
      {
        /* Branch-free scan first (vectorises), then locate the culprit. */
        int bad = 0;
        for (size_t i = 0; i < v->n; i++) bad |= !(fabs(v->arr[i]) <= RSW_TRACE_MAX_COORD);
        for (size_t i = 0; bad && i < v->n; i++)
          if (!(fabs(v->arr[i]) <= RSW_TRACE_MAX_COORD))
            return rsw_fail(err, isfinite(v->arr[i]) ? RSW_ERR_RANGE : RSW_ERR_INVALID, key,
                            "'%s': coordinate %zu (%g) is not finite or exceeds %g, the largest float32 "
                            "tracing accepts",
                            key, i, v->arr[i], RSW_TRACE_MAX_COORD);
        /* Their image under the shape's to_world (core/transform.h). */
        const xform *t = &e->sh->to_world;
        double w = 0;
        for (size_t i = 0; i + 2 < v->n; i += 3)
          w = fmax(w, v3_max_abs(xf_point(t, v3(v->arr[i], v->arr[i + 1], v->arr[i + 2]))));
        if (!(w <= RSW_TRACE_MAX_COORD))
          return rsw_fail(
              err, RSW_ERR_RANGE, key,
              "'%s': the mesh would reach a world coordinate of %g, beyond %g, the largest float32 "
              "tracing accepts",
              key, w, RSW_TRACE_MAX_COORD);
      }
      break;
    case MB_FACES:
      if (!v->n || v->n % 3 || v->n / 3 > MESH_MAX_ELEMENTS)
        return rsw_fail(err, RSW_ERR_INVALID, key,
                        "'%s' takes a non-empty list of vertex indices, 3 per face", key);
      for (size_t i = 0; i < v->n; i++)
        if (!(v->arr[i] >= 0 && v->arr[i] < (double)nv && v->arr[i] == floor(v->arr[i])))
          return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': index %zu (%g) is not a vertex index below %zu",
                          key, i, v->arr[i], nv);
      break;
    case MB_NORMALS:
    case MB_TEXCOORDS: {
      size_t per = e->buf == MB_NORMALS ? 3 : 2;
      if (v->n != per * nv)
        return rsw_fail(err, RSW_ERR_INVALID, key, "'%s' takes %zu numbers (%zu per vertex)", key, per * nv,
                        per);
      for (size_t i = 0; i < v->n; i++)
        if (!isfinite(v->arr[i]))
          return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': values must be finite", key);
      break;
    }
    }
    sg->changed = true;
    if (e->buf == MB_POSITIONS && v->n == 3 * (size_t)m->n_verts) {
      int diff = 0;
      for (size_t i = 0; i < v->n; i++) diff |= (float)v->arr[i] != m->pos[i];
      sg->changed = diff != 0;
    } else if (e->buf == MB_FACES && v->n == 3 * (size_t)m->n_faces) {
      sg->changed = false;
      for (size_t i = 0; i < v->n && !sg->changed; i++) sg->changed = (uint32_t)v->arr[i] != m->faces[i];
    }
    return RSW_OK;
  }
  case EK_DBUF: {
    const double *x = v->kind == PV_NUMBER ? &v->num : v->arr;
    size_t n = v->kind == PV_NUMBER ? 1 : v->n;
    if (v->kind != PV_NUMBER && v->kind != PV_ARRAY)
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes a flat list of %zu numbers", key, e->dn);
    if (n != e->dn)
      return rsw_fail(err, RSW_ERR_INVALID, key, "'%s' takes %zu numbers (its shape is fixed), got %zu", key,
                      e->dn, n);
    for (size_t i = 0; i < n; i++) {
      if (!isfinite(x[i]))
        return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': value at index %zu must be finite", key, i);
      if (x[i] < e->lo || x[i] > e->hi) {
        if (isinf(e->hi))
          return rsw_fail(err, RSW_ERR_RANGE, key, "'%s': value %g at index %zu must be >= %g", key, x[i], i,
                          e->lo);
        if (isinf(e->lo))
          return rsw_fail(err, RSW_ERR_RANGE, key, "'%s': value %g at index %zu must be <= %g", key, x[i], i,
                          e->hi);
        return rsw_fail(err, RSW_ERR_RANGE, key, "'%s': value %g at index %zu must lie in [%g, %g]", key,
                        x[i], i, e->lo, e->hi);
      }
    }
    if (e->dcheck) {
      rsw_status st = e->dcheck(e->owner, x, n, key, err);
      if (st) return st;
    }
    sg->changed = memcmp(x, e->dptr, n * sizeof(double)) != 0;
    return RSW_OK;
  }
  case EK_BOOL: break;
  }
  return rsw_fail(err, RSW_ERR_INVALID, key, "'%s' is read-only", e->key);
}

/* Everything applying needs that could fail (allocations), done before
 * anything is written. */
static rsw_status prepare(staged *sg, const entry *e, rsw_err *err) {
  const param_value *v = &sg->item->value;
  if (e->kind == EK_SPECTRUM) {
    if (!uniform_spectrum_copy(&sg->new_spec, &sg->spec))
      return rsw_fail(err, RSW_ERR_NOMEM, e->key, "out of memory");
    sg->spec_ready = true;
    return RSW_OK;
  }
  if (e->kind == EK_DBUF) {
    /* The values it replaces, for undo_one. */
    sg->old_buf = malloc(e->dn * sizeof(double));
    if (!sg->old_buf) return rsw_fail(err, RSW_ERR_NOMEM, e->key, "out of memory");
    return RSW_OK;
  }
  if (e->kind != EK_MESHBUF) return RSW_OK;
  switch (e->buf) {
  case MB_POSITIONS:
    if (!sg->fpos) {
      sg->fpos = malloc((v->n ? v->n : 1) * sizeof(float));
      if (!sg->fpos) return rsw_fail(err, RSW_ERR_NOMEM, e->key, "out of memory");
      for (size_t q = 0; q < v->n; q++) sg->fpos[q] = (float)v->arr[q];
    }
    break;
  case MB_FACES: {
    uint32_t *f = malloc((v->n ? v->n : 1) * sizeof(uint32_t));
    if (!f) return rsw_fail(err, RSW_ERR_NOMEM, e->key, "out of memory");
    for (size_t i = 0; i < v->n; i++) f[i] = (uint32_t)v->arr[i];
    sg->buf = f;
    break;
  }
  case MB_NORMALS:
  case MB_TEXCOORDS: {
    float *f = malloc((v->n ? v->n : 1) * sizeof(float));
    if (!f) return rsw_fail(err, RSW_ERR_NOMEM, e->key, "out of memory");
    for (size_t i = 0; i < v->n; i++) f[i] = (float)v->arr[i];
    sg->buf = f;
    break;
  }
  }
  return RSW_OK;
}

/* Write one prepared value, remembering what it replaced. Cannot fail. */
static void apply_one(staged *sg, const entry *e) {
  switch (e->kind) {
  case EK_FLOAT:
    sg->old_f = *e->fptr;
    *e->fptr = sg->item->value.num;
    break;
  case EK_TRANSFORM:
    sg->old_xf = *e->xptr;
    *e->xptr = sg->xf;
    break;
  case EK_VECTOR:
    sg->old_vec = e->vget(e->owner);
    e->vset(e->owner, sg->vec);
    break;
  case EK_SPECTRUM: uniform_texture_swap_spectrum(e->tex, &sg->new_spec); break;
  case EK_MESHBUF: {
    mesh *m = &e->sh->mesh;
    size_t n = sg->item->value.n;
    switch (e->buf) {
    case MB_POSITIONS:
      sg->old_buf = m->pos, sg->old_count = m->n_verts;
      m->pos = sg->fpos, m->n_verts = (uint32_t)(n / 3);
      sg->fpos = NULL;
      break;
    case MB_FACES:
      sg->old_buf = m->faces, sg->old_count = m->n_faces;
      m->faces = sg->buf, m->n_faces = (uint32_t)(n / 3);
      sg->buf = NULL;
      break;
    case MB_NORMALS:
      sg->old_buf = m->nrm;
      m->nrm = sg->buf;
      sg->buf = NULL;
      break;
    case MB_TEXCOORDS:
      sg->old_buf = m->uv;
      m->uv = sg->buf;
      sg->buf = NULL;
      break;
    }
    break;
  }
  case EK_DBUF: {
    const param_value *v = &sg->item->value;
    memcpy(sg->old_buf, e->dptr, e->dn * sizeof(double));
    memcpy(e->dptr, v->kind == PV_NUMBER ? &v->num : v->arr, e->dn * sizeof(double));
    break;
  }
  case EK_BOOL: break;
  }
  sg->applied = true;
}

/* Put back what apply_one replaced (the new value is freed). */
static void undo_one(staged *sg, const entry *e) {
  if (!sg->applied) return;
  switch (e->kind) {
  case EK_FLOAT: *e->fptr = sg->old_f; break;
  case EK_TRANSFORM: *e->xptr = sg->old_xf; break;
  case EK_VECTOR: e->vset(e->owner, sg->old_vec); break;
  case EK_SPECTRUM: uniform_texture_swap_spectrum(e->tex, &sg->new_spec); break;
  case EK_MESHBUF: {
    mesh *m = &e->sh->mesh;
    void *cur = NULL;
    switch (e->buf) {
    case MB_POSITIONS: cur = m->pos, m->pos = sg->old_buf, m->n_verts = sg->old_count; break;
    case MB_FACES: cur = m->faces, m->faces = sg->old_buf, m->n_faces = sg->old_count; break;
    case MB_NORMALS: cur = m->nrm, m->nrm = sg->old_buf; break;
    case MB_TEXCOORDS: cur = m->uv, m->uv = sg->old_buf; break;
    }
    free(cur);
    sg->old_buf = NULL;
    break;
  }
  case EK_DBUF: memcpy(e->dptr, sg->old_buf, e->dn * sizeof(double)); break;
  case EK_BOOL: break;
  }
  sg->applied = false;
}

/* Free what the staged entries still own: prepared values not applied,
 * values replaced by a successful update. */
static void staged_free(staged *sg, size_t n) {
  for (size_t i = 0; i < n; i++) {
    free(sg[i].fpos);
    free(sg[i].buf);
    free(sg[i].old_buf);
    if (sg[i].spec_ready) spectrum_free(&sg[i].new_spec);
  }
  free(sg);
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* The acceleration structure and the scene's bounds after the values of
 * sg were written (restore = false) or put back (restore = true: every
 * touched mesh is rebuilt, whatever its update was). */
static rsw_status update_geometry(scene *s, staged *sg, size_t n, bool restore, rsw_err *err) {
  rsw_status st = RSW_OK;
  for (size_t i = 0; i < n && !st; i++) {
    if (!sg[i].changed) continue;
    const entry *e = &s->params->e[sg[i].index];
    if (e->cls != UPDATE_GEOMETRIC) continue;
    const shape *sh = (const shape *)e->owner;
    if (e->kind == EK_TRANSFORM) {
      accel_update_transform(s->accel, sh);
    } else if (e->kind == EK_MESHBUF) {
      bool topology = restore;
      for (size_t k = 0; k < n; k++) {
        const entry *o = &s->params->e[sg[k].index];
        if (sg[k].changed && o->kind == EK_MESHBUF && o->sh == e->sh && o->buf == MB_FACES) topology = true;
      }
      if (restore) {
        /* Once per mesh: at its first changed buffer. */
        bool first = true;
        for (size_t k = 0; k < i && first; k++) {
          const entry *o = &s->params->e[sg[k].index];
          first = !(sg[k].changed && o->kind == EK_MESHBUF && o->sh == e->sh);
        }
        if (first) st = accel_rebuild_shape(s->accel, sh, err);
      } else if (e->buf == MB_FACES || (topology && e->buf == MB_POSITIONS)) {
        if (e->buf == MB_FACES) st = accel_rebuild_shape(s->accel, sh, err);
      } else if (e->buf == MB_POSITIONS) {
        st = accel_update_vertices(s->accel, sh, err);
      }
    }
  }
  if (!st) st = accel_commit(s->accel, err);
  /* Bounds, emitters and sensors: the same code as a load, so that an
   * update equals a reload. */
  if (!st) st = scene_refresh_bounds(s, err);
  return st;
}

rsw_status scene_update(scene *s, const param_update *items, size_t n, update_report *report, rsw_err *err) {
  double t0 = now_s();
  if (report) memset(report, 0, sizeof *report);
  if (!s->params) return rsw_fail(err, RSW_ERR_NOT_FOUND, "params", "the scene has no parameter table");
  staged *sg = calloc(n ? n : 1, sizeof *sg);
  if (!sg) return rsw_fail(err, RSW_ERR_NOMEM, "params", "out of memory");
  rsw_status st = RSW_OK;
  /* 1. Resolve every key; a key (or two names of it) given twice is an
   *    error, since the result would depend on the order. */
  for (size_t i = 0; i < n && !st; i++) {
    sg[i].item = &items[i];
    st = params_lookup(s, items[i].key, &sg[i].index, err);
    for (size_t k = 0; k < i && !st; k++)
      if (sg[k].index == sg[i].index)
        st = rsw_fail(err, RSW_ERR_DUPLICATE, items[i].key,
                      "'%s' is given twice in one update (also as '%s')", items[i].key, items[k].key);
  }
  /* 2. Validate everything before writing anything. */
  for (size_t i = 0; i < n && !st; i++) st = validate(s, &sg[i], sg, n, err);
  if (st) {
    free(sg);
    return st;
  }
  /* Geometry checks that need the new values together: a mesh's new
   * vertices (with its faces and transform, new or current) must keep a
   * positive area, or sampling it would divide by zero. */
  for (size_t i = 0; i < n && !st; i++) {
    const entry *e = &s->params->e[sg[i].index];
    if (!sg[i].changed || e->kind != EK_MESHBUF || (e->buf != MB_POSITIONS && e->buf != MB_FACES)) continue;
    const shape *sh = e->sh;
    if (!sh->emitter && !sh->sampled) continue; /* nothing samples it: no area needed */
    const double *fc = NULL;
    size_t nf = sh->mesh.n_faces;
    const xform *xf = &sh->to_world;
    const float *fpos = NULL;
    for (size_t k = 0; k < n; k++) {
      const entry *o = &s->params->e[sg[k].index];
      if (o->owner != e->owner) continue;
      if (o->kind == EK_MESHBUF && o->buf == MB_POSITIONS && sg[k].changed) {
        /* Convert once (a sequential pass); the area loop then gathers
         * floats, and applying the update swaps this buffer in. */
        const param_value *pv = &sg[k].item->value;
        if (!sg[k].fpos) {
          sg[k].fpos = malloc(pv->n * sizeof(float));
          if (!sg[k].fpos) {
            st = rsw_fail(err, RSW_ERR_NOMEM, sg[k].item->key, "out of memory");
            break;
          }
          for (size_t q = 0; q < pv->n; q++) sg[k].fpos[q] = (float)pv->arr[q];
        }
        fpos = sg[k].fpos;
      }
      if (o->kind == EK_MESHBUF && o->buf == MB_FACES)
        fc = sg[k].item->value.arr, nf = sg[k].item->value.n / 3;
      if (o->kind == EK_TRANSFORM) xf = &sg[k].xf;
    }
    if (st) break;
    /* The new area cdf, computed once here and installed by the shape's
     * parameters_changed (same arithmetic as shape_finalize, so the result
     * equals a reload's). Only the transform changing is left to
     * shape_finalize. */
    shape *msh = e->sh;
    if (msh->tri_cdf_next_n < nf) {
      double *c = realloc(msh->tri_cdf_next, nf * sizeof(double));
      if (!c) {
        st = rsw_fail(err, RSW_ERR_NOMEM, sg[i].item->key, "out of memory");
        break;
      }
      msh->tri_cdf_next = c;
      msh->tri_cdf_next_n = (uint32_t)nf;
    }
    double area = 0, det = xf_abs_det3(xf);
    for (size_t f = 0; f < nf; f++) {
      vec3 p[3];
      for (int c = 0; c < 3; c++) {
        size_t vi = fc ? (size_t)fc[3 * f + c] : sh->mesh.faces[3 * f + c];
        const float *q = fpos ? &fpos[3 * vi] : &sh->mesh.pos[3 * vi];
        p[c] = v3(q[0], q[1], q[2]);
      }
      area += tri_world_area(xf, det, p[0], p[1], p[2]);
      msh->tri_cdf_next[f] = area;
    }
    if (!(area > 0) || !isfinite(area)) {
      st = rsw_fail(err, RSW_ERR_INVALID, sg[i].item->key,
                    "'%s': the mesh would have zero or non-finite area", sg[i].item->key);
    } else {
      msh->area_next = area;
      msh->tri_cdf_next_n = (uint32_t)nf; /* entries valid (buffer may be larger) */
      msh->cdf_staged = true;
    }
  }
  /* Prepare every value that needs memory, still before writing. */
  for (size_t i = 0; i < n && !st; i++)
    if (sg[i].changed) st = prepare(&sg[i], &s->params->e[sg[i].index], err);
  if (st) {
    for (size_t i = 0; i < n; i++) {
      const entry *e = &s->params->e[sg[i].index];
      if (e->kind == EK_MESHBUF) e->sh->cdf_staged = false;
    }
    staged_free(sg, n);
    return st;
  }
  accel_counters before;
  accel_get_counters(s->accel, &before);
  /* 3. Apply: nothing here can fail. */
  unsigned classes = 0;
  size_t changed = 0;
  bool geometry = false;
  for (size_t i = 0; i < n; i++) {
    if (!sg[i].changed) continue;
    const entry *e = &s->params->e[sg[i].index];
    changed++;
    classes |= e->cls;
    apply_one(&sg[i], e);
    if (e->cls == UPDATE_GEOMETRIC) geometry = true;
  }
  /* 4. Derived state, each touched object once. */
  for (size_t i = 0; i < n; i++) {
    if (!sg[i].changed) continue;
    object *o = s->params->e[sg[i].index].owner;
    bool seen = false;
    for (size_t k = 0; k < i && !seen; k++) seen = sg[k].changed && s->params->e[sg[k].index].owner == o;
    if (seen) continue;
    if (o->plugin && o->plugin->parameters_changed) o->plugin->parameters_changed(o);
  }
  /* Embree: instance transforms, refits and rebuilds, then one commit.
   * These can still fail (Embree, accel.c's scene-wide float32 check, a
   * sensor refusing the new bounds): then every value goes back, and the
   * structure is brought back to it, so that a failed update changes
   * nothing. */
  if (geometry) st = update_geometry(s, sg, n, false, err);
  /* A sensor inside a medium must still be inside it (a moved boundary or
   * sensor): the load-time check again, undone like the rest. */
  if (!st && changed && scene_has_sensor_media(s)) {
    st = scene_check_media(s, NULL, err);
    if (st && err) {
      static const char pre[] = "after the update, ";
      size_t pl = sizeof pre - 1, len = strlen(err->msg);
      if (len + pl >= sizeof err->msg) len = sizeof err->msg - pl - 1;
      memmove(err->msg + pl, err->msg, len);
      memcpy(err->msg, pre, pl);
      err->msg[pl + len] = '\0';
    }
  }
  if (st) {
    for (size_t i = 0; i < n; i++) undo_one(&sg[i], &s->params->e[sg[i].index]);
    for (size_t i = 0; i < n; i++) {
      const entry *e = &s->params->e[sg[i].index];
      if (e->kind == EK_MESHBUF) e->sh->cdf_staged = false;
    }
    for (size_t i = 0; i < n; i++) {
      if (!sg[i].changed) continue;
      object *o = s->params->e[sg[i].index].owner;
      bool seen = false;
      for (size_t k = 0; k < i && !seen; k++) seen = sg[k].changed && s->params->e[sg[k].index].owner == o;
      if (!seen && o->plugin && o->plugin->parameters_changed) o->plugin->parameters_changed(o);
    }
    if (geometry) {
      rsw_err again = {0};
      if (update_geometry(s, sg, n, true, &again) && err) {
        size_t used = strlen(err->msg);
        snprintf(err->msg + used, sizeof err->msg - used, " (and restoring the previous state failed: %s)",
                 again.msg);
      }
    }
  }
  /* Emitter selection by sampling_weight (cheap: one pass). */
  if (!st && changed) {
    double sum = 0;
    for (size_t i = 0; i < s->n_emitters; i++) {
      sum += s->emitters[i]->sampling_weight;
      if (s->emitter_cdf) s->emitter_cdf[i] = sum;
    }
    s->emitter_weight_sum = sum;
  }
  staged_free(sg, n);
  if (report) {
    accel_counters after;
    accel_get_counters(s->accel, &after);
    report->classes = classes;
    report->changed = changed;
    report->refits = (unsigned)(after.refits - before.refits);
    report->rebuilds = (unsigned)(after.rebuilds - before.rebuilds);
    report->instance_updates = (unsigned)(after.instance_updates - before.instance_updates);
    report->seconds = now_s() - t0;
  }
  return st;
}

rsw_status scene_update_check(const scene *s, const param_update *items, size_t n, rsw_err *err) {
  if (!s->params) return rsw_fail(err, RSW_ERR_NOT_FOUND, "params", "the scene has no parameter table");
  staged *sg = calloc(n ? n : 1, sizeof *sg);
  if (!sg) return rsw_fail(err, RSW_ERR_NOMEM, "params", "out of memory");
  rsw_status st = RSW_OK;
  for (size_t i = 0; i < n && !st; i++) {
    sg[i].item = &items[i];
    st = params_lookup(s, items[i].key, &sg[i].index, err);
    for (size_t k = 0; k < i && !st; k++)
      if (sg[k].index == sg[i].index)
        st = rsw_fail(err, RSW_ERR_DUPLICATE, items[i].key,
                      "'%s' is given twice in one update (also as '%s')", items[i].key, items[k].key);
  }
  for (size_t i = 0; i < n && !st; i++) st = validate(s, &sg[i], sg, n, err);
  free(sg);
  return st;
}
