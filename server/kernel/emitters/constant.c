/* `constant`: an environment of uniform radiance from every direction
 * (mitsuba3 src/emitters/constant.cpp). Rays that escape the scene see
 * `radiance` (W m^-2 sr^-1 [nm^-1]); next-event estimation samples the
 * uniform sphere, pdf 1/(4 pi). */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "../textures/texture.h"

typedef struct constant_env {
  emitter base;
  texture *radiance;
} constant_env;

static color const_sample(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds) {
  const constant_env *c = (const constant_env *)e;
  ds->d = warp_square_to_uniform_sphere(u);
  ds->dist = INFINITY;
  ds->p = ds->d;
  ds->n = v3_neg(ds->d);
  ds->pdf = RSW_INV_4PI;
  ds->delta = false;
  return col_scale(tex_eval(c->radiance, ref), 4.0 * RSW_PI);
}

static double const_pdf(const emitter *e, const surface_interaction *ref, const direction_sample *ds) {
  (void)e, (void)ref, (void)ds;
  return RSW_INV_4PI;
}

static color const_eval(const emitter *e, const surface_interaction *hit, vec3 d) {
  const constant_env *c = (const constant_env *)e;
  (void)d;
  return tex_eval(c->radiance, hit);
}

static const emitter_ops constant_ops = {
    .sample_direction = const_sample, .pdf_direction = const_pdf, .eval = const_eval};

static rsw_status constant_create(loader *ld, node *n, object **out) {
  constant_env *c = calloc(1, sizeof *c);
  if (!c) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  c->base.ops = &constant_ops;
  c->base.flags = EMITTER_INFINITE;
  rsw_status st = ld_float_range(ld, n, "sampling_weight", 1.0, 0.0, INFINITY, &c->base.sampling_weight);
  if (!st) st = ld_texture(ld, n, "radiance", 1.0, 0.0, &c->radiance);
  color tmp;
  if (!st && !uniform_texture_value(c->radiance, &tmp))
    st = ld_fail(ld, n, "radiance", RSW_ERR_INVALID, "radiance must be a constant (number, rgb or spectrum)");
  if (st) {
    free(c);
    return st;
  }
  *out = &c->base.base;
  return RSW_OK;
}

static void const_traverse(object *o, param_visitor *v) {
  constant_env *c = (constant_env *)o;
  pv_object(v, "radiance", &c->radiance->base, 0.0, INFINITY);
  pv_float(v, "sampling_weight", &c->base.sampling_weight, UPDATE_SPECTRAL, 0.0, INFINITY);
}

DEFINE_PLUGIN(constant, CLS_EMITTER, .ops = &constant_ops, .traverse = const_traverse);
