/* Document tree -> object graph: plugin lookup, property getters for
 * plugins, reference resolution, the unused-property check, and the scene
 * plugin itself.
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

#include "../accel.h"
#include "../core/strdist.h"
#include "../media/media.h"
#include "../shapes/instance.h"
#include "../shapes/shape.h"
#include "../textures/texture.h"
#include "loader.h"
#include "params.h"
#include "periodic.h"
#include "plugin_names.h"
#include "rsw_file.h"
#include "scene.h"

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

/* A ref names an explicit id first, then a top-level object's key (the
 * usual load_dict usage), then any object with that (implicit) id. */
static node *resolve_ref(loader *ld, const char *id) {
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

static rsw_status unknown_plugin(loader *ld, node *n) {
  return registry_unknown_type(ld->err, n->loc, n->type, n->tag);
}

static const char *article(const char *word) {
  return word && strchr("aeiou", word[0]) ? "an" : "a";
}

/* Plugin of a node, checking the XML tag agrees with its class. */
static rsw_status node_plugin(loader *ld, node *n, const plugin **out) {
  const plugin *pl = registry_find(n->type);
  /* `periodic` is the one scene-level object that is not the scene. */
  if (!pl || (pl->cls == CLS_SCENE && pl != &plugin_periodic)) return unknown_plugin(ld, n);
  if (n->tag && strcmp(n->tag, obj_class_name(pl->cls)) != 0)
    return rsw_fail(ld->err, RSW_ERR_TYPE, n->loc, "<%s type=\"%s\">: '%s' is %s %s plugin, not %s %s",
                    n->tag, n->type, n->type, article(obj_class_name(pl->cls)), obj_class_name(pl->cls),
                    article(n->tag), n->tag);
  *out = pl;
  return RSW_OK;
}

/* The node a PROP_NODE / PROP_REF property stands for. */
static rsw_status prop_target(loader *ld, node *owner, prop *p, node **out) {
  if (p->kind == PROP_NODE) {
    *out = p->child;
    return RSW_OK;
  }
  node *t = resolve_ref(ld, p->ref);
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

/* Build (or return the already built) object of node n, of class cls
 * (CLS__COUNT for any class). */
static rsw_status ld_build(loader *ld, node *n, obj_class cls, object **out) {
  const plugin *pl;
  rsw_status st = node_plugin(ld, n, &pl);
  if (st) return st;
  if (cls != CLS__COUNT && pl->cls != cls)
    return rsw_fail(ld->err, RSW_ERR_TYPE, n->loc, "expected %s %s here, got the %s plugin '%s'",
                    article(obj_class_name(cls)), obj_class_name(cls), obj_class_name(pl->cls), n->type);
  if (n->build_state == 2) {
    *out = n->built;
    return RSW_OK;
  }
  if (n->build_state == 1)
    return rsw_fail(ld->err, RSW_ERR_CYCLE, n->loc, "'%s' references itself (reference cycle)", n->id);
  n->build_state = 1;
  object *o = NULL;
  st = pl->create(ld, n, &o);
  if (st) {
    if (ld->err && ld->err->code == RSW_OK)
      rsw_fail(ld->err, st, n->loc, "%s '%s': %s", n->type, n->id ? n->id : "", rsw_strerror(st));
    return st;
  }
  if (!o->plugin) o->plugin = pl;
  if (!o->id) o->id = n->id;
  st = ld_adopt(ld, o);
  if (st) return st;
  for (size_t i = 0; i < n->n_props; i++) {
    prop *p = &n->props[i];
    if (!p->used) {
      if (p->kind == PROP_NODE || p->kind == PROP_REF) {
        node *t = p->kind == PROP_NODE ? p->child : resolve_ref(ld, p->ref);
        const plugin *tp = t ? registry_find(t->type) : NULL;
        const char *cname = tp ? obj_class_name(tp->cls) : "object";
        return rsw_fail(ld->err, RSW_ERR_UNUSED_PROPERTY, p->loc,
                        "%s '%s' takes no %s%s%s: %s%s%s is the %s plugin '%s' (unused)", n->type,
                        n->id ? n->id : "", cname, p->name[0] ? " as '" : "", p->name, p->name[0] ? "'" : "",
                        p->kind == PROP_REF ? "the reference resolves to " : "",
                        p->kind == PROP_REF ? p->ref : "it", cname, t ? t->type : "?");
      }
      return rsw_fail(ld->err, RSW_ERR_UNUSED_PROPERTY, p->loc,
                      "%s '%s' has no property '%s' (unused property)", n->type, n->id ? n->id : "", p->name);
    }
  }
  n->build_state = 2;
  n->built = o;
  *out = o;
  return RSW_OK;
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
  texture *t = uniform_texture_new(s, n->id);
  if (!t || (p && !uniform_texture_set_where(t, p->loc))) {
    if (t) t->base.plugin->destroy(&t->base);
    return ld_fail(ld, n, p ? p->name : NULL, RSW_ERR_NOMEM, "out of memory");
  }
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
    node *t;
    st = prop_target(ld, n, p, &t);
    if (st) return st;
    object *o;
    size_t pi = (size_t)(p - n->props);
    st = ld_build(ld, t, CLS_TEXTURE, &o);
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
static rsw_status prop_class(loader *ld, node *owner, prop *p, obj_class *cls, node **target) {
  rsw_status st = prop_target(ld, owner, p, target);
  if (st) return st;
  const plugin *pl;
  st = node_plugin(ld, *target, &pl);
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
    rsw_status st = prop_class(ld, n, p, &c, &t);
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
  rsw_status st = ld_build(ld, target, cls, out);
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
    rsw_status st = prop_class(ld, n, p, &c, &t);
    if (!st && c != cls) continue;
    if (!st) st = ld_build(ld, t, cls, &arr[k]);
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
  const plugin *pl = registry_find(type);
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
  return ld_build(ld, n, cls, out);
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
    double w = rc->wavelength;
    /* Deliberate difference from Mitsuba (which collapses a (wl, v) list to
     * a luminance in mono): the table is evaluated at the render's
     * wavelength by linear interpolation; outside it is an error. */
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
    *out = col1(s->val[lo] + t * (s->val[hi] - s->val[lo]));
    return RSW_OK;
  }
  }
  return rsw_fail(err, RSW_ERR_INVALID, where, "bad spectrum");
}

/* ---- the scene plugin --------------------------------------------------------------- */

static rsw_status push_ptr(void ***arr, size_t *n, void *p) {
  void **a = realloc(*arr, (*n + 1) * sizeof *a);
  if (!a) return RSW_ERR_NOMEM;
  a[(*n)++] = p;
  *arr = a;
  return RSW_OK;
}

static rsw_status add_emitter(loader *ld, scene *s, emitter *e, const char *where) {
  if (e->flags & EMITTER_INFINITE) {
    if (s->environment)
      return rsw_fail(ld->err, RSW_ERR_INVALID, where,
                      "only one environment emitter per scene ('%s' and '%s')", s->environment->base.id,
                      e->base.id);
    s->environment = e;
  }
  if (push_ptr((void ***)&s->emitters, &s->n_emitters, e))
    return rsw_fail(ld->err, RSW_ERR_NOMEM, where, "out of memory");
  return RSW_OK;
}

static rsw_status scene_create(loader *ld, node *n, object **out) {
  scene *s = ld->scene;
  for (size_t i = 0; i < n->n_props; i++) {
    prop *p = &n->props[i];
    if (p->kind != PROP_NODE && p->kind != PROP_REF) continue;
    if (p->used) continue; /* synthetic defaults */
    node *t;
    obj_class c;
    rsw_status st = prop_class(ld, n, p, &c, &t);
    if (st) return st;
    object *o;
    st = ld_build(ld, t, c, &o);
    if (st) return st;
    p = &n->props[i]; /* building may have grown the root's property array */
    p->used = true;
    switch (c) {
    case CLS_SHAPE: {
      shape *sh = (shape *)o;
      if (push_ptr((void ***)&s->shapes, &s->n_shapes, sh))
        return rsw_fail(ld->err, RSW_ERR_NOMEM, p->loc, "out of memory");
      if (sh->emitter) {
        st = add_emitter(ld, s, sh->emitter, p->loc);
        if (st) return st;
      }
      break;
    }
    case CLS_EMITTER:
      if (((emitter *)o)->flags & EMITTER_SURFACE)
        return rsw_fail(ld->err, RSW_ERR_INVALID, p->loc, "an area emitter must be nested in a shape");
      st = add_emitter(ld, s, (emitter *)o, p->loc);
      if (st) return st;
      break;
    case CLS_SENSOR:
      if (push_ptr((void ***)&s->sensors, &s->n_sensors, o))
        return rsw_fail(ld->err, RSW_ERR_NOMEM, p->loc, "out of memory");
      break;
    case CLS_INTEGRATOR:
      if (s->integrator) return rsw_fail(ld->err, RSW_ERR_DUPLICATE, p->loc, "a scene takes one integrator");
      s->integrator = (integrator *)o;
      break;
    case CLS_BSDF:
    case CLS_TEXTURE:
    case CLS_MEDIUM:
    case CLS_PHASE:
    case CLS_VOLUME: break; /* declared at the top level to be referenced */
    case CLS_SCENE:
      if (o->plugin == &plugin_periodic) {
        if (s->periodic.on)
          return rsw_fail(ld->err, RSW_ERR_DUPLICATE, p->loc, "a scene takes one periodic boundary");
        s->periodic = *periodic_of(o);
        break;
      }
      return rsw_fail(ld->err, RSW_ERR_INVALID, p->loc, "a scene cannot be a child of the scene");
    default:
      return rsw_fail(ld->err, RSW_ERR_INVALID, p->loc,
                      "a %s cannot be a child of the scene (nest it in a sensor)", obj_class_name(c));
    }
  }
  *out = &s->base;
  return RSW_OK;
}

const plugin plugin_scene = {.name = "scene", .cls = CLS_SCENE, .create = scene_create};

/* Shapes first, then everything that depends on the scene's bounds
 * (instance_bbox: plain shapes, groups and instances). */

/* Bounds and everything derived from them: the scene's bounding sphere,
 * emitters' and sensors' set_scene. Run at load and after every geometric
 * update, so that an update equals a reload (Mitsuba does not refresh
 * sensors after an update; we do, deliberately). */
rsw_status scene_refresh_bounds(scene *s, rsw_err *err) {
  vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
  for (size_t i = 0; i < s->n_shapes; i++) instance_bbox(s->shapes[i], &lo, &hi);
  if (!(lo.x <= hi.x)) lo = hi = v3(0, 0, 0); /* no rendered geometry */
  if (s->periodic.on) {
    /* The geometry's vertical extent bounds the wrapping; the column's
     * lateral extent gives the bounding sphere. That sphere does not bound
     * the (infinite) scene, so nothing may use it as a bound on ray
     * lengths or to put an origin outside the scene: shadow rays towards
     * infinitely distant emitters are unbounded and distant sensors
     * place their origins outside the slab (scene/periodic.h). */
    s->periodic.zmin = lo.z;
    s->periodic.zmax = hi.z;
    rsw_status zst = periodic_refresh_shapes(s, err);
    if (zst) return zst;
    lo.x = s->periodic.min[0], lo.y = s->periodic.min[1];
    hi.x = s->periodic.max[0], hi.y = s->periodic.max[1];
  }
  s->bbox_min = lo;
  s->bbox_max = hi;
  media_refresh_null_boxes(s);
  s->bsphere_center = v3_scale(v3_add(lo, hi), 0.5);
  double r = v3_len(v3_sub(hi, s->bsphere_center));
  /* Mitsuba's sensors and emitters inflate the bounding sphere:
   * R = max(RayEpsilon, R (1 + RayEpsilon)). */
  s->bsphere_radius = fmax(RSW_RAY_EPSILON, r * (1.0 + RSW_RAY_EPSILON));
  for (size_t i = 0; i < s->n_emitters; i++) {
    emitter *e = s->emitters[i];
    if (e->ops->set_scene) e->ops->set_scene(e, s);
  }
  for (size_t i = 0; i < s->n_sensors; i++) {
    sensor *se = s->sensors[i];
    if (se->ops->set_scene) {
      rsw_status st = se->ops->set_scene(se, s, err);
      if (st) return st;
    }
  }
  return RSW_OK;
}

static rsw_status scene_finalize(loader *ld, scene *s) {
  rsw_status st;
  if (!s->integrator) {
    /* Deliberate difference from Mitsuba 3.7.1 (which refuses to render
     * without one): a scene without an integrator gets `path` with its
     * defaults, like upstream Mitsuba's Scene constructor. */
    object *o;
    st = ld_create_default(ld, "path", CLS_INTEGRATOR, "path", &o);
    if (st) return st;
    s->integrator = (integrator *)o;
  }
  for (size_t i = 0; i < s->n_shapes; i++) s->shapes[i]->index = (unsigned)i;
  st = accel_build(s, ld->err);
  if (st) return st;
  s->emitter_weight_sum = 0;
  if (s->n_emitters) {
    s->emitter_cdf = malloc(s->n_emitters * sizeof(double));
    if (!s->emitter_cdf) return rsw_fail(ld->err, RSW_ERR_NOMEM, "", "out of memory");
    for (size_t i = 0; i < s->n_emitters; i++) {
      s->emitter_weight_sum += s->emitters[i]->sampling_weight;
      s->emitter_cdf[i] = s->emitter_weight_sum;
    }
  }
  st = scene_refresh_bounds(s, ld->err);
  if (st) return st;
  st = scene_check_media(s, ld->root, ld->err);
  if (st) return st;
  return params_build(s, ld->err);
}

static rsw_variant parse_variant(const char *name, bool *ok) {
  const char *v = name;
  *ok = true;
  if (!v || strcmp(v, "rgb") == 0 || strcmp(v, "scalar_rgb") == 0) return VARIANT_RGB;
  if (strcmp(v, "mono") == 0 || strcmp(v, "scalar_mono") == 0 || strcmp(v, "scalar_mono_double") == 0)
    return VARIANT_MONO;
  *ok = false;
  return VARIANT_RGB;
}

rsw_status scene_build(node *root, const char *doc_variant, const scene_load_opts *opts, scene **out,
                       rsw_err *err) {
  const char *vname = opts && opts->variant ? opts->variant : doc_variant;
  bool ok;
  rsw_variant var = parse_variant(vname, &ok);
  if (!ok) {
    rsw_status st = rsw_fail(err, RSW_ERR_INVALID, opts && opts->variant ? "--variant" : root->loc,
                             "unknown variant '%s' (expected \"mono\" or \"rgb\")", vname);
    node_free(root);
    return st;
  }
  scene *s = calloc(1, sizeof *s);
  if (!s) {
    node_free(root);
    return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  }
  s->base.plugin = &plugin_scene;
  s->variant = var;
  s->doc = root;
  loader ld = {.variant = var,
               .err = err,
               .base_dir = opts && opts->base_dir ? opts->base_dir : ".",
               .root = root,
               .scene = s,
               .resolve = opts ? opts->resolve : NULL,
               .resolve_user = opts ? opts->resolve_user : NULL};
  rsw_status st = index_ids(&ld, root);
  if (!st) st = index_refs(&ld);
  if (!st) {
    root->build_state = 1;
    object *o;
    st = scene_create(&ld, root, &o);
  }
  if (!st) {
    for (size_t i = 0; i < root->n_props; i++) {
      prop *p = &root->props[i];
      if (!p->used) {
        st = rsw_fail(err, RSW_ERR_UNUSED_PROPERTY, p->loc,
                      "the scene has no property '%s' (its children must be objects)", p->name);
        break;
      }
    }
  }
  if (!st) st = scene_finalize(&ld, s);
  free(ld.ids);
  free(ld.ref_slots);
  if (st) {
    scene_free(s);
    return st;
  }
  *out = s;
  return RSW_OK;
}

static char *read_all(const char *path, size_t *len, rsw_err *err) {
  FILE *f = rsw_fopen_regular(path, "rb");
  if (!f) {
    rsw_fail(err, RSW_ERR_FILE, path, "cannot open scene file: %s", rsw_open_strerror(errno));
    return NULL;
  }
  const size_t cap_max = (size_t)1 << 30;
  size_t cap = 1 << 16, n = 0;
  char *buf = malloc(cap + 1);
  while (buf) {
    size_t r = fread(buf + n, 1, cap - n, f);
    n += r;
    if (n < cap) break;
    if (cap >= cap_max) {
      free(buf);
      buf = NULL;
      rsw_fail(err, RSW_ERR_LIMIT, path, "scene file larger than 1 GiB");
      break;
    }
    char *nb = realloc(buf, 2 * cap + 1);
    if (!nb) {
      free(buf);
      buf = NULL;
      break;
    }
    buf = nb;
    cap *= 2;
  }
  if (buf && ferror(f)) {
    free(buf);
    buf = NULL;
    rsw_fail(err, RSW_ERR_IO, path, "read error");
  }
  fclose(f);
  if (!buf) {
    rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory reading the scene");
    return NULL;
  }
  buf[n] = '\0';
  *len = n;
  return buf;
}

rsw_status scene_load_memory(const char *text, size_t len, const char *name, bool is_xml,
                             const scene_load_opts *opts, scene **out, rsw_err *err) {
  node *root = NULL;
  char *doc_variant = NULL;
  rsw_status st;
  if (is_xml) {
    st = scene_read_xml(text, len, name, opts ? opts->defines : NULL, opts ? opts->n_defines : 0, &root,
                        &doc_variant, err);
  } else {
    if (opts && opts->n_defines)
      return rsw_fail(err, RSW_ERR_USAGE, "-D", "-D parameters apply to XML scenes only (%s is JSON)", name);
    st = scene_read_json(text, len, name, &root, &doc_variant, err);
  }
  if (st) return st;
  st = scene_build(root, doc_variant, opts, out, err);
  free(doc_variant);
  return st;
}

rsw_status scene_load_file(const char *path, const scene_load_opts *opts, scene **out, rsw_err *err) {
  size_t len;
  char *text = read_all(path, &len, err);
  if (!text) return err ? err->code : RSW_ERR_IO;
  const char *dot = strrchr(path, '.');
  bool is_xml;
  if (dot && strcmp(dot, ".xml") == 0) {
    is_xml = true;
  } else if (dot && strcmp(dot, ".json") == 0) {
    is_xml = false;
  } else {
    const char *c = text;
    while (*c == ' ' || *c == '\t' || *c == '\n' || *c == '\r') c++;
    is_xml = *c == '<';
  }
  scene_load_opts o = {.size = sizeof o};
  if (opts) o = *opts;
  char dir[4096];
  if (!o.base_dir) {
    const char *slash = strrchr(path, '/');
    if (slash) {
      size_t l = (size_t)(slash - path);
      if (l >= sizeof dir) l = sizeof dir - 1;
      memcpy(dir, path, l);
      dir[l] = '\0';
      if (l == 0) strcpy(dir, "/");
      o.base_dir = dir;
    }
  }
  rsw_status st = scene_load_memory(text, len, path, is_xml, &o, out, err);
  free(text);
  return st;
}

rsw_status scene_prepare(scene *s, const render_ctx *rc, rsw_err *err) {
  for (size_t i = 0; i < s->n_objects; i++) {
    object *o = s->objects[i];
    if (o->plugin && o->plugin->prepare) {
      rsw_status st = o->plugin->prepare(o, rc, err);
      if (st) return st;
    }
  }
  return RSW_OK;
}

bool scene_wavelength_dependent(const scene *s) {
  for (size_t i = 0; i < s->n_objects; i++) {
    const object *o = s->objects[i];
    if (o->plugin && o->plugin->spectral && o->plugin->spectral(o)) return true;
  }
  return false;
}

sensor *scene_find_sensor(const scene *s, const char *id, size_t *index_out) {
  for (size_t i = 0; i < s->n_sensors; i++)
    if (strcmp(s->sensors[i]->base.id, id) == 0) {
      if (index_out) *index_out = i;
      return s->sensors[i];
    }
  char *end;
  errno = 0;
  unsigned long k = strtoul(id, &end, 10);
  if (id[0] >= '0' && id[0] <= '9' && !*end && !errno && k < s->n_sensors) {
    if (index_out) *index_out = k;
    return s->sensors[k];
  }
  return NULL;
}

void scene_free(scene *s) {
  if (!s) return;
  accel_free(s->accel);
  params_free(s->params);
  for (size_t i = s->n_objects; i-- > 0;) {
    object *o = s->objects[i];
    if (o == &s->base) continue;
    if (o->plugin && o->plugin->destroy) o->plugin->destroy(o);
  }
  free(s->objects);
  free(s->shapes);
  free(s->emitters);
  free(s->emitter_cdf);
  free(s->sensors);
  free(s->periodic_z);
  node_free(s->doc);
  free(s);
}
