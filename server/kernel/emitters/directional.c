/* `directional`: a distant source of uniform irradiance from one direction
 * (mitsuba3 src/emitters/directional.cpp; docs/kernel-conventions.md#emitters).
 *
 * `direction` is the direction light travels ((0,0,-1): sun at zenith);
 * or `to_world` (exclusive) maps local +z onto it. `irradiance` is per unit
 * area normal to the beam, W m^-2 [nm^-1], and must not vary spatially.
 * Next-event estimation: a delta direction, pdf 1, value = irradiance.
 * The emitter is infinitely far: ds.dist is INFINITY, so the shadow ray
 * is unbounded (deliberate difference from Mitsuba, whose 2 max(R, |p - c|)
 * is equivalent in a finite scene but cuts the shadow ray in a periodic
 * one, where R is the radius of one column: issue 11). ds.p stays
 * Mitsuba's point 2 max(R, |p - c|) back along the beam (R, c: the
 * scene's bounding sphere). Never hit by BSDF-sampled rays. */
#include <stdlib.h>

#include "../scene/loader.h"
#include "../scene/params.h"
#include "../textures/texture.h"
#include "distant_emitter.h"

typedef struct directional {
  emitter base;
  texture *irradiance;
  xform to_world; /* local +z -> propagation direction */
  vec3 d;         /* unit propagation direction, always to_world (0,0,1) */
  vec3 center;
  double radius;
} directional;

static color dir_sample(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds) {
  const directional *dl = (const directional *)e;
  (void)u;
  double far = 2.0 * fmax(dl->radius, v3_len(v3_sub(ref->p, dl->center)));
  ds->d = v3_neg(dl->d);
  ds->dist = INFINITY;
  ds->p = v3_fma(ref->p, far, ds->d);
  ds->n = dl->d;
  ds->pdf = 1.0;
  ds->delta = true;
  return tex_eval(dl->irradiance, ref);
}

/* The lanes' distances first (their square roots overlap), then the
 * samples; the irradiance is uniform (dir_create refuses a texture that
 * varies), so it is evaluated once: the value every lane's call gives. */
static void dir_sample_batch(const emitter *e, int n, const surface_interaction *const *ref, const vec2 *u,
                             direction_sample *ds, color *value) {
  const directional *dl = (const directional *)e;
  (void)u;
  if (n <= 0) return;
  color v = tex_eval(dl->irradiance, ref[0]);
  vec3 d = v3_neg(dl->d);
  for (int k = 0; k < n; k++) {
    double far = 2.0 * fmax(dl->radius, v3_len(v3_sub(ref[k]->p, dl->center)));
    ds[k].d = d;
    ds[k].dist = INFINITY;
    ds[k].p = v3_fma(ref[k]->p, far, d);
    ds[k].n = dl->d;
    ds[k].pdf = 1.0;
    ds[k].delta = true;
    value[k] = v;
  }
}

static double dir_pdf(const emitter *e, const surface_interaction *ref, const direction_sample *ds) {
  (void)e, (void)ref, (void)ds;
  return 0.0; /* a delta distribution is never hit by chance */
}

static color dir_eval(const emitter *e, const surface_interaction *hit, vec3 d) {
  (void)e, (void)hit, (void)d;
  return col1(0);
}

static void dir_set_scene(emitter *e, const scene *s) {
  directional *dl = (directional *)e;
  dl->center = s->bsphere_center;
  dl->radius = s->bsphere_radius;
}

static const emitter_ops directional_ops = {.sample_direction = dir_sample,
                                            .pdf_direction = dir_pdf,
                                            .eval = dir_eval,
                                            .set_scene = dir_set_scene,
                                            .sample_direction_batch = dir_sample_batch};

static void dir_destroy(object *o) {
  free(o);
}

/* d always comes from to_world, whichever way it was set, so that an
 * update of `direction` or `to_world` equals a reload with it. */
static void derive_direction(directional *dl) {
  dl->d = v3_norm(xf_vector(&dl->to_world, v3(0, 0, 1)));
}

static vec3 dir_get_direction(const object *o) {
  return ((const directional *)o)->d;
}

static void dir_set_direction(object *o, vec3 d) {
  directional *dl = (directional *)o;
  if (distant_look_at(d, &dl->to_world)) derive_direction(dl);
}

static void dir_traverse(object *o, param_visitor *v) {
  directional *dl = (directional *)o;
  pv_object(v, "irradiance", &dl->irradiance->base, 0.0, INFINITY);
  /* Not geometric: the emitter is not in the acceleration structure. */
  pv_transform(v, "to_world", &dl->to_world, UPDATE_SPECTRAL, NULL);
  /* Convenience key: the propagation direction, rewriting to_world. */
  pv_vector(v, "direction", dir_get_direction, dir_set_direction, UPDATE_SPECTRAL);
  pv_float(v, "sampling_weight", &dl->base.sampling_weight, UPDATE_SPECTRAL, 0.0, INFINITY);
}

static void dir_parameters_changed(object *o) {
  derive_direction((directional *)o);
}

static rsw_status dir_create(loader *ld, node *n, object **out) {
  directional *dl = calloc(1, sizeof *dl);
  if (!dl) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  dl->base.ops = &directional_ops;
  dl->base.flags = EMITTER_DELTA_DIRECTION;
  rsw_status st = distant_emitter_read(ld, n, &dl->base, &dl->irradiance, &dl->to_world);
  if (st) {
    free(dl);
    return st;
  }
  derive_direction(dl);
  *out = &dl->base.base;
  return RSW_OK;
}

const plugin plugin_directional = {.name = "directional",
                                   .cls = CLS_EMITTER,
                                   .create = dir_create,
                                   .destroy = dir_destroy,
                                   .ops = &directional_ops,
                                   .traverse = dir_traverse,
                                   .parameters_changed = dir_parameters_changed};
