/* Test-only stand-ins for modules that other branches provide (the scene
 * builder's ld_* getters, the warps, shape position sampling), so that
 * test_sensors and test_samplers link and run before those land.
 *
 * Every definition is weak: once the real loader.c / warp.c / shape.c are
 * in the kernel library (linked --whole-archive), their strong symbols
 * replace these and the tests exercise the real modules unchanged.
 *
 * The loader stand-in follows loader.h: getters mark properties used,
 * check the type, return the default when absent; nested objects are built
 * through the registry and adopted by ld->scene. A nested shape whose
 * plugin is not linked yet (e.g. "disk") is built as a unit disk so the
 * shape-target tests can run. Include this header in one file per test
 * binary. */
#ifndef RSW_TEST_SENSOR_SHIMS_H
#define RSW_TEST_SENSOR_SHIMS_H

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kernel/scene/loader.h"
#include "kernel/shapes/shape.h"

#define SHIM_ __attribute__((weak))

SHIM_ rsw_status ld_fail(loader *ld, node *n, const char *name, rsw_status code, const char *fmt, ...) {
  char msg[512];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  const char *where = n ? n->loc : "";
  prop *p = (n && name) ? node_find(n, name) : NULL;
  if (p) where = p->loc;
  return rsw_fail(ld->err, code, where, "%s", msg);
}

SHIM_ bool ld_has(const node *n, const char *name) {
  return node_find(n, name) != NULL;
}

static prop *shim_get_(loader *ld, node *n, const char *name, prop_kind kind, rsw_status *st) {
  prop *p = node_find(n, name);
  *st = RSW_OK;
  if (!p) return NULL;
  p->used = true;
  if (p->kind != kind) {
    *st = ld_fail(ld, n, name, RSW_ERR_TYPE, "'%s' has the wrong type", name);
    return NULL;
  }
  return p;
}

SHIM_ rsw_status ld_float(loader *ld, node *n, const char *name, double def, double *out) {
  rsw_status st;
  prop *p = shim_get_(ld, n, name, PROP_NUMBER, &st);
  if (st != RSW_OK) return st;
  double v = p ? p->num : def;
  if (!isfinite(v)) return ld_fail(ld, n, name, RSW_ERR_INVALID, "'%s' is not finite", name);
  *out = v;
  return RSW_OK;
}

SHIM_ rsw_status ld_float_range(loader *ld, node *n, const char *name, double def, double lo, double hi,
                                double *out) {
  double v = 0;
  rsw_status st = ld_float(ld, n, name, def, &v);
  if (st != RSW_OK) return st;
  if (v < lo || v > hi) return ld_fail(ld, n, name, RSW_ERR_RANGE, "'%s' out of range", name);
  *out = v;
  return RSW_OK;
}

SHIM_ rsw_status ld_int(loader *ld, node *n, const char *name, long long def, long long lo, long long hi,
                        long long *out) {
  rsw_status st;
  prop *p = shim_get_(ld, n, name, PROP_NUMBER, &st);
  if (st != RSW_OK) return st;
  if (p && p->num != floor(p->num))
    return ld_fail(ld, n, name, RSW_ERR_TYPE, "'%s' must be an integer", name);
  if (p && (p->num < (double)lo || p->num > (double)hi))
    return ld_fail(ld, n, name, RSW_ERR_RANGE, "'%s' out of range", name);
  *out = p ? (long long)p->num : def;
  return RSW_OK;
}

SHIM_ rsw_status ld_bool(loader *ld, node *n, const char *name, bool def, bool *out) {
  rsw_status st;
  prop *p = shim_get_(ld, n, name, PROP_BOOL, &st);
  if (st != RSW_OK) return st;
  *out = p ? p->b : def;
  return RSW_OK;
}

SHIM_ rsw_status ld_string(loader *ld, node *n, const char *name, const char *def, const char **out) {
  rsw_status st;
  prop *p = shim_get_(ld, n, name, PROP_STRING, &st);
  if (st != RSW_OK) return st;
  *out = p ? p->str : def;
  return RSW_OK;
}

SHIM_ rsw_status ld_vec3(loader *ld, node *n, const char *name, vec3 def, vec3 *out, bool *present) {
  rsw_status st;
  prop *p = shim_get_(ld, n, name, PROP_VEC3, &st);
  if (st != RSW_OK) return st;
  *out = p ? p->vec : def;
  if (present) *present = p != NULL;
  return RSW_OK;
}

SHIM_ rsw_status ld_transform(loader *ld, node *n, const char *name, xform *out, bool *present) {
  rsw_status st;
  prop *p = shim_get_(ld, n, name, PROP_TRANSFORM, &st);
  if (st != RSW_OK) return st;
  *out = p ? p->xf : xf_identity();
  if (present) *present = p != NULL;
  return RSW_OK;
}

SHIM_ rsw_status ld_path(loader *ld, node *n, const char *name, char **out) {
  (void)out;
  return ld_fail(ld, n, name, RSW_ERR_UNSUPPORTED, "test loader: no files");
}

SHIM_ rsw_status ld_texture(loader *ld, node *n, const char *name, double def, double lo, texture **out) {
  (void)def, (void)lo, (void)out;
  return ld_fail(ld, n, name, RSW_ERR_UNSUPPORTED, "test loader: no textures");
}

SHIM_ rsw_status ld_texture_opt(loader *ld, node *n, const char *name, double lo, texture **out) {
  (void)lo, (void)out;
  return ld_fail(ld, n, name, RSW_ERR_UNSUPPORTED, "test loader: no textures");
}

SHIM_ rsw_status ld_adopt(loader *ld, object *o) {
  scene *sc = ld->scene;
  if (sc->n_objects == sc->cap_objects) {
    size_t cap = sc->cap_objects ? 2 * sc->cap_objects : 8;
    object **a = realloc(sc->objects, cap * sizeof *a);
    if (!a) return rsw_fail(ld->err, RSW_ERR_NOMEM, "", "out of memory");
    sc->objects = a;
    sc->cap_objects = cap;
  }
  sc->objects[sc->n_objects++] = o;
  return RSW_OK;
}

/* Stand-in geometry for a shape plugin that is not linked yet: the unit
 * disk at the origin (area pi, normal +z). */
static void shim_shape_destroy_(object *o) {
  free(o);
}
static const plugin shim_shape_plugin_ = {
    .name = "shim-disk", .cls = CLS_SHAPE, .destroy = shim_shape_destroy_};

static rsw_status shim_build_(loader *ld, node *c, obj_class cls, object **out) {
  const plugin *pl = registry_find(c->type);
  object *o = NULL;
  if (!pl && cls == CLS_SHAPE) {
    shape *s = calloc(1, sizeof *s);
    if (!s) return rsw_fail(ld->err, RSW_ERR_NOMEM, "", "out of memory");
    s->base.plugin = &shim_shape_plugin_;
    s->base.id = c->id;
    s->geom = GEOM_DISK;
    s->to_world = xf_identity();
    s->area = RSW_PI;
    o = &s->base;
  } else {
    if (!pl) return ld_fail(ld, c, NULL, RSW_ERR_UNKNOWN_PLUGIN, "unknown plugin '%s'", c->type);
    if (pl->cls != cls)
      return ld_fail(ld, c, NULL, RSW_ERR_TYPE, "'%s' is not a %s", c->type, obj_class_name(cls));
    rsw_status st = pl->create(ld, c, &o);
    if (st != RSW_OK) return st;
  }
  rsw_status st = ld_adopt(ld, o);
  if (st != RSW_OK) {
    o->plugin->destroy(o);
    return st;
  }
  c->built = o;
  *out = o;
  return RSW_OK;
}

static obj_class shim_class_of_(const node *c) {
  const plugin *pl = registry_find(c->type);
  return pl ? pl->cls : CLS_SHAPE;
}

SHIM_ rsw_status ld_child(loader *ld, node *n, const char *name, obj_class cls, object **out) {
  *out = NULL;
  if (name) {
    prop *p = node_find(n, name);
    if (!p) return RSW_OK;
    p->used = true;
    if (p->kind != PROP_NODE)
      return ld_fail(ld, n, name, RSW_ERR_UNSUPPORTED, "test loader: only nested objects");
    return shim_build_(ld, p->child, cls, out);
  }
  prop *found = NULL;
  for (size_t i = 0; i < n->n_props; i++) {
    prop *p = &n->props[i];
    if (p->kind != PROP_NODE || shim_class_of_(p->child) != cls) continue;
    if (found) return ld_fail(ld, n, p->name, RSW_ERR_DUPLICATE, "more than one %s", obj_class_name(cls));
    found = p;
  }
  if (!found) return RSW_OK;
  found->used = true;
  return shim_build_(ld, found->child, cls, out);
}

SHIM_ rsw_status ld_children(loader *ld, node *n, obj_class cls, object ***out, size_t *count) {
  (void)cls, (void)out, (void)count;
  return ld_fail(ld, n, NULL, RSW_ERR_UNSUPPORTED, "test loader: no child lists");
}

SHIM_ rsw_status ld_create_default(loader *ld, const char *type, obj_class cls, const char *id,
                                   object **out) {
  node *tmp = node_new(NULL, type, "<default>");
  if (!tmp) return rsw_fail(ld->err, RSW_ERR_NOMEM, "", "out of memory");
  object *o = NULL;
  rsw_status st = shim_build_(ld, tmp, cls, &o);
  node_free(tmp);
  if (st != RSW_OK) return st;
  o->id = id;
  *out = o;
  return RSW_OK;
}

SHIM_ rsw_status spectrum_eval(const spectrum *s, const render_ctx *rc, color *out, rsw_err *err,
                               const char *where) {
  (void)s, (void)rc, (void)out;
  return rsw_fail(err, RSW_ERR_UNSUPPORTED, where, "test loader: no spectra");
}

/* kernel-behavior.md §5.1: Shirley-Chiu concentric map, branch-reduced. */
SHIM_ vec2 warp_square_to_disk_concentric(vec2 u) {
  double a = 2.0 * u.x - 1.0, b = 2.0 * u.y - 1.0;
  if (a == 0.0 && b == 0.0) return v2(0.0, 0.0);
  double r, phi;
  if (fabs(a) < fabs(b)) {
    r = b;
    phi = 0.5 * RSW_PI - 0.25 * RSW_PI * (a / b);
  } else {
    r = a;
    phi = 0.25 * RSW_PI * (b / a);
  }
  return v2(r * cos(phi), r * sin(phi));
}

/* §5.2: z = 1 - |p|^2, (x, y) = p sqrt(z + 1). */
SHIM_ vec3 warp_square_to_uniform_hemisphere(vec2 u) {
  vec2 p = warp_square_to_disk_concentric(u);
  double z = 1.0 - (p.x * p.x + p.y * p.y);
  double s = sqrt(z + 1.0);
  return v3(p.x * s, p.y * s, z);
}

/* Disks only (the stand-in shape above): concentric disk through
 * to_world, pdf 1/area. */
SHIM_ position_sample shape_sample_position(const shape *s, vec2 u) {
  position_sample ps;
  memset(&ps, 0, sizeof ps);
  vec2 q = warp_square_to_disk_concentric(u);
  ps.p = xf_point(&s->to_world, v3(q.x, q.y, 0.0));
  ps.n = v3_norm(xf_normal(&s->to_world, v3(0, 0, 1)));
  ps.pdf = 1.0 / s->area;
  return ps;
}

SHIM_ double shape_pdf_position(const shape *s) {
  return 1.0 / s->area;
}

#undef SHIM_

#endif
