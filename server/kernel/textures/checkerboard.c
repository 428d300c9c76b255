/* `checkerboard` (mitsuba3 src/textures/checkerboard.cpp): color0 (0.4) and
 * color1 (0.2), both spectral textures, and `to_uv` (an affine map of the
 * texture coordinates, identity by default). With uv' = to_uv (u, v),
 * color0 where [frac(u') > 0.5] == [frac(v') > 0.5], else color1. */
#include <stdlib.h>

#include "../scene/plugin_def.h"

typedef struct checkerboard {
  texture base;
  texture *c0, *c1;
  xform to_uv;
} checkerboard;

static double frac(double x) {
  return x - floor(x);
}

static color cb_eval(const texture *t, const surface_interaction *si) {
  const checkerboard *c = (const checkerboard *)t;
  vec3 uv = xf_point(&c->to_uv, v3(si->uv[0], si->uv[1], 0));
  bool mu = frac(uv.x) > 0.5, mv = frac(uv.y) > 0.5;
  return mu == mv ? tex_eval(c->c0, si) : tex_eval(c->c1, si);
}

static color cb_mean(const texture *t) {
  const checkerboard *c = (const checkerboard *)t;
  return col_scale(col_add(c->c0->ops->mean(c->c0), c->c1->ops->mean(c->c1)), 0.5);
}

static const texture_ops checkerboard_ops = {.eval = cb_eval, .mean = cb_mean};

static rsw_status checkerboard_create(loader *ld, node *n, object **out) {
  checkerboard *c = calloc(1, sizeof *c);
  if (!c) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  c->base.ops = &checkerboard_ops;
  rsw_status st = ld_texture(ld, n, "color0", 0.4, -INFINITY, &c->c0);
  if (!st) st = ld_texture(ld, n, "color1", 0.2, -INFINITY, &c->c1);
  if (!st) st = ld_transform(ld, n, "to_uv", &c->to_uv, NULL);
  if (st) {
    free(c);
    return st;
  }
  *out = &c->base.base;
  return RSW_OK;
}

static void cb_traverse(object *o, param_visitor *v) {
  checkerboard *c = (checkerboard *)o;
  pv_object(v, "color0", &c->c0->base, NAN, NAN);
  pv_object(v, "color1", &c->c1->base, NAN, NAN);
  pv_transform(v, "to_uv", &c->to_uv, UPDATE_SPECTRAL, NULL);
}

DEFINE_PLUGIN(checkerboard, CLS_TEXTURE, .ops = &checkerboard_ops, .traverse = cb_traverse);
