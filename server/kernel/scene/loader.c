/* The builder's property getters (scene/loader.h): what plugins call from
 * their create() to read their properties, the document's id and ref
 * tables, and the class names. Building a nested object goes through
 * ld->hooks (set by the scene assembly, scene/build.c, which sits above
 * the plugins), so that these getters stay below every plugin
 * (tools/check-layers.py).
 *
 * Ownership: the scene owns every object (scene->objects) and the document
 * (scene->doc); objects reference each other by pointer and never free
 * their children, so an object shared through `ref` is freed exactly once. */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "loader.h"

#define TWO_POW_53 9007199254740992.0

/* ---- errors ----------------------------------------------------------------- */

rsw_status ld_fail(loader *ld, node *n, const char *name, rsw_status code, const char *fmt, ...) {
  const char *where = n ? n->loc : "";
  if (n && name) {
    prop *p = node_find(n, name);
    if (p) where = p->loc;
  }
  char msg[700];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  if (n && n->id && name) return rsw_fail(ld->err, code, where, "%s '%s': %s", n->type, n->id, msg);
  return rsw_fail(ld->err, code, where, "%s", msg);
}

static const char *prop_kind_name(prop_kind k) {
  switch (k) {
  case PROP_BOOL: return "a boolean";
  case PROP_NUMBER: return "a number";
  case PROP_STRING: return "a string";
  case PROP_VEC3: return "a 3-vector";
  case PROP_SPECTRUM: return "a spectrum";
  case PROP_TRANSFORM: return "a transform";
  case PROP_NUMBERS: return "a list of numbers";
  case PROP_NODE: return "an object";
  case PROP_REF: return "a reference";
  }
  return "a value";
}

static rsw_status wrong_type(loader *ld, node *n, prop *p, const char *expected) {
  return ld_fail(ld, n, p->name, RSW_ERR_TYPE, "property '%s' must be %s, got %s", p->name, expected,
                 prop_kind_name(p->kind));
}

/* ---- id table and plugin lookup ----------------------------------------------- */

static rsw_status index_ids(loader *ld, node *n) {
  if (n->id && n != ld->root) {
    if (ld->n_ids == ld->cap_ids) {
      size_t cap = ld->cap_ids ? 2 * ld->cap_ids : 64;
      node **p = realloc(ld->ids, cap * sizeof *p);
      if (!p) return rsw_fail(ld->err, RSW_ERR_NOMEM, n->loc, "out of memory");
      ld->ids = p;
      ld->cap_ids = cap;
    }
    ld->ids[ld->n_ids++] = n;
  }
  for (size_t i = 0; i < n->n_props; i++)
    if (n->props[i].kind == PROP_NODE) {
      rsw_status st = index_ids(ld, n->props[i].child);
      if (st) return st;
    }
  return RSW_OK;
}

static size_t ref_slot(const loader *ld, const char *id) {
  unsigned long long h = 1469598103934665603ull; /* FNV-1a */
  for (const char *c = id; *c; c++) h = (h ^ (unsigned char)*c) * 1099511628211ull;
  size_t i = (size_t)h & (ld->ref_cap - 1);
  while (ld->ref_slots[i] && strcmp(ld->ref_slots[i]->id, id) != 0) i = (i + 1) & (ld->ref_cap - 1);
  return i;
}

/* The ref table, filled in priority order (a later candidate never
 * replaces an earlier one): explicit ids (which must be unique), then the
 * top-level objects' keys in order, then any object's (implicit) id in
 * document order. */
static rsw_status index_refs(loader *ld) {
  size_t cap = 64;
  while (cap < 2 * (ld->n_ids + 1)) cap *= 2;
  ld->ref_slots = calloc(cap, sizeof *ld->ref_slots);
  if (!ld->ref_slots) return rsw_fail(ld->err, RSW_ERR_NOMEM, "", "out of memory");
  ld->ref_cap = cap;
  for (size_t i = 0; i < ld->n_ids; i++) {
    node *n = ld->ids[i];
    if (!n->id_explicit) continue;
    size_t k = ref_slot(ld, n->id);
    if (ld->ref_slots[k])
      return rsw_fail(ld->err, RSW_ERR_DUPLICATE, n->loc, "duplicate id '%s' (also used at %s)", n->id,
                      ld->ref_slots[k]->loc);
    ld->ref_slots[k] = n;
  }
  for (size_t i = 0; i < ld->root->n_props; i++) {
    prop *p = &ld->root->props[i];
    if (p->kind != PROP_NODE || !p->child->id) continue;
    size_t k = ref_slot(ld, p->child->id);
    if (!ld->ref_slots[k]) ld->ref_slots[k] = p->child;
  }
  for (size_t i = 0; i < ld->n_ids; i++) {
    size_t k = ref_slot(ld, ld->ids[i]->id);
    if (!ld->ref_slots[k]) ld->ref_slots[k] = ld->ids[i];
  }
  return RSW_OK;
}

rsw_status ld_index(loader *ld) {
  rsw_status st = index_ids(ld, ld->root);
  return st ? st : index_refs(ld);
}

/* A ref names an explicit id first, then a top-level object's key (the
 * usual load_dict usage), then any object with that (implicit) id. */
node *ld_resolve_ref(loader *ld, const char *id) {
  if (ld->ref_cap) {
    node *t = ld->ref_slots[ref_slot(ld, id)];
    if (t) return t;
  }
  /* Objects created since indexing (defaults attached to the root). */
  for (size_t i = 0; i < ld->root->n_props; i++) {
    prop *p = &ld->root->props[i];
    if (p->kind == PROP_NODE && p->child->id && strcmp(p->child->id, id) == 0) return p->child;
  }
  return NULL;
}

/* The node a PROP_NODE / PROP_REF property stands for. */
static rsw_status prop_target(loader *ld, node *owner, prop *p, node **out) {
  if (p->kind == PROP_NODE) {
    *out = p->child;
    return RSW_OK;
  }
  node *t = ld_resolve_ref(ld, p->ref);
  if (!t)
    return ld_fail(ld, owner, p->name[0] ? p->name : NULL, RSW_ERR_DANGLING_REF,
                   "reference to unknown id '%s'", p->ref);
  *out = t;
  return RSW_OK;
}

static rsw_status scene_add_object(scene *s, object *o, rsw_err *err) {
  if (s->n_objects == s->cap_objects) {
    size_t cap = s->cap_objects ? 2 * s->cap_objects : 64;
    object **p = realloc(s->objects, cap * sizeof *p);
    if (!p) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
    s->objects = p;
    s->cap_objects = cap;
  }
  s->objects[s->n_objects++] = o;
  return RSW_OK;
}

rsw_status ld_adopt(loader *ld, object *o) {
  rsw_status st = scene_add_object(ld->scene, o, ld->err);
  if (st && o->plugin && o->plugin->destroy) o->plugin->destroy(o);
  return st;
}

/* ---- property getters ------------------------------------------------------------ */

bool ld_has(const node *n, const char *name) {
  return node_find(n, name) != NULL;
}

rsw_status ld_float(loader *ld, node *n, const char *name, double def, double *out) {
  prop *p = node_find(n, name);
  if (!p) {
    *out = def;
    return RSW_OK;
  }
  if (p->kind != PROP_NUMBER) return wrong_type(ld, n, p, "a number");
  if (!isfinite(p->num)) return ld_fail(ld, n, name, RSW_ERR_INVALID, "property '%s' must be finite", name);
  p->used = true;
  *out = p->num;
  return RSW_OK;
}

rsw_status ld_float_range(loader *ld, node *n, const char *name, double def, double lo, double hi,
                          double *out) {
  double v;
  rsw_status st = ld_float(ld, n, name, def, &v);
  if (st) return st;
  if (!(v >= lo && v <= hi)) {
    if (isinf(hi))
      return ld_fail(ld, n, name, RSW_ERR_RANGE, "property '%s' = %g must be >= %g", name, v, lo);
    return ld_fail(ld, n, name, RSW_ERR_RANGE, "property '%s' = %g must lie in [%g, %g]", name, v, lo, hi);
  }
  *out = v;
  return RSW_OK;
}

rsw_status ld_int(loader *ld, node *n, const char *name, long long def, long long lo, long long hi,
                  long long *out) {
  prop *p = node_find(n, name);
  if (!p) {
    *out = def;
    return RSW_OK;
  }
  if (p->kind != PROP_NUMBER) return wrong_type(ld, n, p, "an integer");
  if (!(p->num == floor(p->num)) || !(fabs(p->num) < TWO_POW_53))
    return ld_fail(ld, n, name, RSW_ERR_TYPE, "property '%s' must be an integer (|x| < 2^53), got %g", name,
                   p->num);
  long long v = (long long)p->num;
  if (v < lo || v > hi)
    return ld_fail(ld, n, name, RSW_ERR_RANGE, "property '%s' = %lld must lie in [%lld, %lld]", name, v, lo,
                   hi);
  p->used = true;
  *out = v;
  return RSW_OK;
}

rsw_status ld_bool(loader *ld, node *n, const char *name, bool def, bool *out) {
  prop *p = node_find(n, name);
  if (!p) {
    *out = def;
    return RSW_OK;
  }
  if (p->kind != PROP_BOOL) return wrong_type(ld, n, p, "a boolean");
  p->used = true;
  *out = p->b;
  return RSW_OK;
}

rsw_status ld_string(loader *ld, node *n, const char *name, const char *def, const char **out) {
  prop *p = node_find(n, name);
  if (!p) {
    *out = def;
    return RSW_OK;
  }
  if (p->kind != PROP_STRING) return wrong_type(ld, n, p, "a string");
  p->used = true;
  *out = p->str;
  return RSW_OK;
}

rsw_status ld_vec3(loader *ld, node *n, const char *name, vec3 def, vec3 *out, bool *present) {
  prop *p = node_find(n, name);
  if (present) *present = p != NULL;
  if (!p) {
    *out = def;
    return RSW_OK;
  }
  if (p->kind != PROP_VEC3) return wrong_type(ld, n, p, "a 3-vector");
  if (!v3_finite(p->vec)) return ld_fail(ld, n, name, RSW_ERR_INVALID, "property '%s' must be finite", name);
  p->used = true;
  *out = p->vec;
  return RSW_OK;
}

rsw_status ld_transform(loader *ld, node *n, const char *name, xform *out, bool *present) {
  prop *p = node_find(n, name);
  if (present) *present = p != NULL;
  if (!p) {
    *out = xf_identity();
    return RSW_OK;
  }
  if (p->kind == PROP_NUMBERS && p->n_nums == 16) {
    double m[4][4];
    for (int i = 0; i < 16; i++) m[i / 4][i % 4] = p->nums[i];
    if (!xf_from_matrix(m, out))
      return ld_fail(ld, n, name, RSW_ERR_INVALID, "transform '%s' is singular or not finite", name);
    p->used = true;
    return RSW_OK;
  }
  if (p->kind != PROP_TRANSFORM)
    return wrong_type(ld, n, p, "a transform (4x4 matrix or a list of operations)");
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++)
      if (!isfinite(p->xf.m[i][j]) || !isfinite(p->xf.inv[i][j]))
        return ld_fail(ld, n, name, RSW_ERR_INVALID, "transform '%s' is not finite", name);
  p->used = true;
  *out = p->xf;
  return RSW_OK;
}

rsw_status ld_path(loader *ld, node *n, const char *name, char **out) {
  const char *f;
  rsw_status st = ld_string(ld, n, name, NULL, &f);
  if (st) return st;
  if (!f)
    return ld_fail(ld, n, NULL, RSW_ERR_MISSING, "%s '%s': missing property '%s'", n->type, n->id, name);
  if (!f[0]) return ld_fail(ld, n, name, RSW_ERR_INVALID, "property '%s' is empty", name);
  if (ld->resolve) {
    rsw_err local = {0};
    char *path = NULL;
    st = ld->resolve(ld->resolve_user, f, &path, &local);
    if (st) return ld_fail(ld, n, name, st, "property '%s': %s", name, local.msg);
    *out = path;
    return RSW_OK;
  }
  size_t len = strlen(f) + strlen(ld->base_dir) + 2;
  char *path = malloc(len);
  if (!path) return ld_fail(ld, n, name, RSW_ERR_NOMEM, "out of memory");
  if (f[0] == '/')
    snprintf(path, len, "%s", f);
  else
    snprintf(path, len, "%s/%s", ld->base_dir, f);
  struct stat sb;
  if (stat(path, &sb) != 0 || !S_ISREG(sb.st_mode)) {
    if (stat(path, &sb) == 0)
      st = ld_fail(ld, n, name, RSW_ERR_FILE, "'%s' is not a regular file (resolved to '%s')", f, path);
    else
      st = ld_fail(ld, n, name, RSW_ERR_FILE, "file '%s' not found (resolved to '%s')", f, path);
    free(path);
    return st;
  }
  *out = path;
  return RSW_OK;
}

static rsw_status too_large(loader *ld, node *n, const char *name, double x) {
  return ld_fail(ld, n, name, RSW_ERR_RANGE,
                 "property '%s': value %g exceeds the largest magnitude a value may have (%g)", name, x,
                 RSW_MAX_MAGNITUDE);
}

static rsw_status check_spectrum(loader *ld, node *n, prop *p, double lo) {
  const spectrum *s = &p->spec;
  if (s->kind == SPEC_TABLE && ld->variant == VARIANT_RGB)
    return ld_fail(ld, n, p->name, RSW_ERR_UNSUPPORTED,
                   "property '%s': a tabulated spectrum needs the mono variant (the rgb variant takes "
                   "rgb or uniform values)",
                   p->name);
  double vals[3];
  size_t cnt = 0;
  const double *arr = vals;
  if (s->kind == SPEC_UNIFORM) {
    vals[0] = s->value;
    cnt = 1;
  } else if (s->kind == SPEC_RGB) {
    memcpy(vals, s->rgb, sizeof vals);
    cnt = 3;
  } else {
    arr = s->val;
    cnt = s->n;
  }
  for (size_t i = 0; i < cnt; i++) {
    if (!isfinite(arr[i]))
      return ld_fail(ld, n, p->name, RSW_ERR_INVALID, "property '%s' must be finite", p->name);
    if (fabs(arr[i]) > RSW_MAX_MAGNITUDE) return too_large(ld, n, p->name, arr[i]);
    if (arr[i] < lo)
      return ld_fail(ld, n, p->name, RSW_ERR_RANGE, "property '%s' must be >= %g (got %g)", p->name, lo,
                     arr[i]);
  }
  return RSW_OK;
}

static rsw_status make_uniform(loader *ld, node *n, prop *p, const spectrum *s, texture **out) {
  texture *t = ld->hooks->uniform_texture(s, n->id, p ? p->loc : NULL);
  if (!t) return ld_fail(ld, n, p ? p->name : NULL, RSW_ERR_NOMEM, "out of memory");
  rsw_status st = ld_adopt(ld, &t->base);
  if (st) return st;
  *out = t;
  return RSW_OK;
}

rsw_status ld_texture_opt(loader *ld, node *n, const char *name, double lo, texture **out) {
  prop *p = node_find(n, name);
  if (!p) {
    *out = NULL;
    return RSW_OK;
  }
  spectrum s = {.kind = SPEC_UNIFORM};
  rsw_status st;
  switch (p->kind) {
  case PROP_NUMBER:
    if (!isfinite(p->num)) return ld_fail(ld, n, name, RSW_ERR_INVALID, "property '%s' must be finite", name);
    if (fabs(p->num) > RSW_MAX_MAGNITUDE) return too_large(ld, n, name, p->num);
    if (p->num < lo)
      return ld_fail(ld, n, name, RSW_ERR_RANGE, "property '%s' must be >= %g (got %g)", name, lo, p->num);
    s.value = p->num;
    break;
  case PROP_VEC3:
    s.kind = SPEC_RGB;
    s.rgb[0] = p->vec.x;
    s.rgb[1] = p->vec.y;
    s.rgb[2] = p->vec.z;
    for (int i = 0; i < 3; i++) {
      if (!isfinite(s.rgb[i]))
        return ld_fail(ld, n, name, RSW_ERR_INVALID, "property '%s' must be finite", name);
      if (fabs(s.rgb[i]) > RSW_MAX_MAGNITUDE) return too_large(ld, n, name, s.rgb[i]);
      if (s.rgb[i] < lo)
        return ld_fail(ld, n, name, RSW_ERR_RANGE, "property '%s' must be >= %g (got %g)", name, lo,
                       s.rgb[i]);
    }
    break;
  case PROP_SPECTRUM:
    st = check_spectrum(ld, n, p, lo);
    if (st) return st;
    s = p->spec;
    break;
  case PROP_NODE:
  case PROP_REF: {
    node *t = NULL;
    st = prop_target(ld, n, p, &t);
    if (st) return st;
    object *o;
    size_t pi = (size_t)(p - n->props);
    st = ld->hooks->build(ld, t, CLS_TEXTURE, &o);
    if (st) return st;
    n->props[pi].used = true; /* (building may grow the root's property array) */
    *out = (texture *)o;
    return RSW_OK;
  }
  default: return wrong_type(ld, n, p, "a spectrum (number, rgb, spectrum) or a texture");
  }
  st = make_uniform(ld, n, p, &s, out);
  if (st) return st;
  p->used = true;
  return RSW_OK;
}

rsw_status ld_texture(loader *ld, node *n, const char *name, double def, double lo, texture **out) {
  if (node_find(n, name)) return ld_texture_opt(ld, n, name, lo, out);
  spectrum s = {.kind = SPEC_UNIFORM, .value = def};
  return make_uniform(ld, n, NULL, &s, out);
}

/* Class of the object a node/ref property stands for (without building). */
rsw_status ld_prop_class(loader *ld, node *owner, prop *p, obj_class *cls, node **target) {
  rsw_status st = prop_target(ld, owner, p, target);
  if (st) return st;
  const plugin *pl;
  st = ld->hooks->node_plugin(ld, *target, &pl);
  if (st) return st;
  *cls = pl->cls;
  return RSW_OK;
}

rsw_status ld_child(loader *ld, node *n, const char *name, obj_class cls, object **out) {
  *out = NULL;
  prop *found = NULL;
  node *target = NULL;
  for (size_t i = 0; i < n->n_props; i++) {
    prop *p = &n->props[i];
    if (p->kind != PROP_NODE && p->kind != PROP_REF) continue;
    if (name && strcmp(p->name, name) != 0) continue;
    obj_class c;
    node *t;
    rsw_status st = ld_prop_class(ld, n, p, &c, &t);
    if (st) return st;
    if (c != cls) {
      if (name)
        return ld_fail(ld, n, name, RSW_ERR_TYPE, "property '%s' must be a %s, got the %s plugin '%s'", name,
                       obj_class_name(cls), obj_class_name(c), t->type);
      continue;
    }
    if (found)
      return rsw_fail(ld->err, RSW_ERR_DUPLICATE, p->loc, "%s '%s' takes one nested %s, got several", n->type,
                      n->id ? n->id : "", obj_class_name(cls));
    found = p;
    target = t;
  }
  if (name && !found) {
    prop *p = node_find(n, name);
    if (p) return wrong_type(ld, n, p, "an object");
  }
  if (!found) return RSW_OK;
  size_t fi = (size_t)(found - n->props);
  rsw_status st = ld->hooks->build(ld, target, cls, out);
  if (st) return st;
  n->props[fi].used = true; /* building may grow the root's property array (defaults) */
  return RSW_OK;
}

rsw_status ld_children(loader *ld, node *n, obj_class cls, object ***out, size_t *count) {
  *out = NULL;
  *count = 0;
  size_t cnt = 0;
  for (size_t i = 0; i < n->n_props; i++)
    if (n->props[i].kind == PROP_NODE || n->props[i].kind == PROP_REF) cnt++;
  if (!cnt) return RSW_OK;
  object **arr = malloc(cnt * sizeof *arr);
  if (!arr) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  size_t k = 0;
  for (size_t i = 0; i < n->n_props; i++) {
    prop *p = &n->props[i];
    if (p->kind != PROP_NODE && p->kind != PROP_REF) continue;
    obj_class c;
    node *t;
    rsw_status st = ld_prop_class(ld, n, p, &c, &t);
    if (!st && c != cls) continue;
    if (!st) st = ld->hooks->build(ld, t, cls, &arr[k]);
    if (st) {
      free(arr);
      return st;
    }
    n->props[i].used = true; /* (building may grow the root's property array) */
    k++;
  }
  *out = arr;
  *count = k;
  return RSW_OK;
}

rsw_status ld_create_default(loader *ld, const char *type, obj_class cls, const char *id, object **out) {
  const plugin *pl = ld->hooks->find(type);
  if (!pl || pl->cls != cls)
    return rsw_fail(ld->err, RSW_ERR_UNKNOWN_PLUGIN, "", "internal: no default %s plugin '%s'",
                    obj_class_name(cls), type);
  /* A synthetic node keeps the id string alive for the scene's lifetime. */
  node *n = node_new(NULL, type, "(default)");
  if (!n) return rsw_fail(ld->err, RSW_ERR_NOMEM, "", "out of memory");
  n->id = rsw_strdup(id ? id : type);
  prop *holder = n->id ? node_add_prop(ld->root, "", PROP_NODE, "(default)") : NULL;
  if (!holder) {
    node_free(n);
    return rsw_fail(ld->err, RSW_ERR_NOMEM, "", "out of memory");
  }
  /* Attached to the root as an already-used, unnamed child so it is freed
   * with the document; flagged so traversal can skip defaults. */
  holder->child = n;
  holder->used = true;
  return ld->hooks->build(ld, n, cls, out);
}

/* ---- spectra ----------------------------------------------------------------------- */

rsw_status spectrum_eval(const spectrum *s, const render_ctx *rc, color *out, rsw_err *err,
                         const char *where) {
  switch (s->kind) {
  case SPEC_UNIFORM: *out = col1(s->value); return RSW_OK;
  case SPEC_RGB:
    /* Mono: Mitsuba converts an rgb value to its luminance
     * (docs/kernel-conventions.md#spectra-and-textures). */
    if (rc->variant == VARIANT_MONO)
      *out = col1(col_luminance(col(s->rgb[0], s->rgb[1], s->rgb[2])));
    else
      *out = col(s->rgb[0], s->rgb[1], s->rgb[2]);
    return RSW_OK;
  case SPEC_TABLE: {
    if (rc->variant != VARIANT_MONO)
      return rsw_fail(err, RSW_ERR_UNSUPPORTED, where, "tabulated spectrum in the rgb variant");
    /* Deliberate difference from Mitsuba (which collapses a (wl, v) list to
     * a luminance in mono): the table is evaluated at the render's
     * wavelength by linear interpolation; outside it is an error. A
     * spectral bundle evaluates each channel at its own wavelength. */
    int nch = rc->bundle > 1 ? 3 : 1;
    for (int c = 0; c < nch; c++) {
      double w = rc_channel_wavelength(rc, c);
      if (!(w >= s->wl[0] && w <= s->wl[s->n - 1]))
        return rsw_fail(err, RSW_ERR_RANGE, where,
                        "wavelength %g nm lies outside the spectrum's table [%g, %g] nm", w, s->wl[0],
                        s->wl[s->n - 1]);
      size_t lo = 0, hi = s->n - 1;
      while (hi - lo > 1) {
        size_t mid = (lo + hi) / 2;
        if (s->wl[mid] <= w)
          lo = mid;
        else
          hi = mid;
      }
      double t = (w - s->wl[lo]) / (s->wl[hi] - s->wl[lo]);
      out->c[c] = s->val[lo] + t * (s->val[hi] - s->val[lo]);
    }
    if (nch == 1) out->c[1] = out->c[2] = out->c[0];
    return RSW_OK;
  }
  }
  return rsw_fail(err, RSW_ERR_INVALID, where, "bad spectrum");
}

const plugin *ld_find_plugin(loader *ld, const char *type) {
  return ld->hooks->find(type);
}

/* ---- class names ------------------------------------------------------------------ */

static const char *const class_names[CLS__COUNT] = {
    [CLS_SCENE] = "scene",     [CLS_SHAPE] = "shape",       [CLS_BSDF] = "bsdf",
    [CLS_EMITTER] = "emitter", [CLS_SENSOR] = "sensor",     [CLS_FILM] = "film",
    [CLS_SAMPLER] = "sampler", [CLS_RFILTER] = "rfilter",   [CLS_INTEGRATOR] = "integrator",
    [CLS_TEXTURE] = "texture", [CLS_MEDIUM] = "medium",     [CLS_PHASE] = "phase",
    [CLS_VOLUME] = "volume",   [CLS_EXTREMUM] = "extremum",
};

const char *variant_name(rsw_variant v, bool polarized) {
  if (v == VARIANT_MONO) return polarized ? "mono_polarized" : "mono";
  return polarized ? "rgb_polarized" : "rgb";
}

bool variant_parse(const char *name, rsw_variant *v, bool *polarized) {
  static const struct {
    const char *name;
    rsw_variant v;
    bool pol;
  } names[] = {
      {"rgb", VARIANT_RGB, false},
      {"scalar_rgb", VARIANT_RGB, false},
      {"mono", VARIANT_MONO, false},
      {"scalar_mono", VARIANT_MONO, false},
      {"scalar_mono_double", VARIANT_MONO, false},
      {"mono_polarized", VARIANT_MONO, true},
      {"scalar_mono_polarized", VARIANT_MONO, true},
      {"scalar_mono_polarized_double", VARIANT_MONO, true},
      {"rgb_polarized", VARIANT_RGB, true},
      {"scalar_rgb_polarized", VARIANT_RGB, true},
  };
  for (size_t i = 0; name && i < sizeof names / sizeof names[0]; i++)
    if (strcmp(name, names[i].name) == 0) {
      *v = names[i].v;
      *polarized = names[i].pol;
      return true;
    }
  return false;
}

const char *obj_class_name(obj_class c) {
  return (unsigned)c < CLS__COUNT ? class_names[c] : "object";
}
