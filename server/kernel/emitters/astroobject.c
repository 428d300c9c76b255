/* `astroobject`: a distant object of finite angular size, Eradiate's sun
 * (eradiate/mitsuba3 src/eradiate_plugins/emitters/astroobject.cpp;
 * docs/kernel-conventions.md#emitters).
 *
 * A disc of angular diameter `angular_diameter` (degrees, in (0, 180);
 * default 0.5358, the Sun's mean apparent size) around the axis
 * to_world (0,0,1), which points from the scene TOWARDS the object (the
 * opposite of `directional`'s `direction`). Its radiance is uniform:
 *   L = E / Omega inside the cone, Omega = 2 pi (1 - cos r), r = diameter / 2,
 * so the irradiance on a plane normal to the axis is E (1 + cos r) / 2
 * (E (1 - 5.5e-6) for the Sun). An environment emitter: rays that escape
 * inside the disc see L; next-event estimation samples the cone
 * uniformly (pdf 1 / Omega, weight E). The shadow ray is unbounded
 * (ds.dist INFINITY), as for `directional`. The cone is taken about the
 * unit axis alone (a twist or scale in to_world does not matter). */
#include <math.h>
#include <stdlib.h>

#include "../scene/loader.h"
#include "../scene/params.h"
#include "../textures/texture.h"
#include "distant_emitter.h"

typedef struct astro {
  emitter base;
  texture *irradiance;
  xform to_world;
  double angular_diameter; /* degrees */
  /* derived (astro_derive) */
  frame f; /* f.n: unit axis towards the object */
  double cos_r, omega;
  vec3 center;
  double radius;
} astro;

static void astro_derive(astro *a) {
  vec3 d = v3_norm(xf_vector(&a->to_world, v3(0, 0, 1)));
  a->f = frame_from_normal(d);
  double r = 0.5 * a->angular_diameter * RSW_PI / 180.0;
  a->cos_r = cos(r);
  a->omega = 2.0 * RSW_PI * (1.0 - a->cos_r);
}

static color astro_sample(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds) {
  const astro *a = (const astro *)e;
  vec3 local = warp_square_to_uniform_cone(u, a->cos_r);
  ds->d = v3_norm(frame_to_world(&a->f, local));
  ds->pdf = warp_square_to_uniform_cone_pdf(local, a->cos_r);
  double far = 2.0 * fmax(a->radius, v3_len(v3_sub(ref->p, a->center)));
  ds->p = v3_fma(ref->p, far, ds->d);
  ds->n = v3_neg(ds->d);
  ds->dist = INFINITY;
  ds->delta = false;
  if (!(ds->pdf > 0.0)) return col1(0.0);
  return col_scale(tex_eval(a->irradiance, ref), 1.0 / (a->omega * ds->pdf));
}

static double astro_pdf(const emitter *e, const surface_interaction *ref, const direction_sample *ds) {
  const astro *a = (const astro *)e;
  (void)ref;
  return v3_dot(ds->d, a->f.n) >= a->cos_r ? 1.0 / a->omega : 0.0;
}

static color astro_eval(const emitter *e, const surface_interaction *hit, vec3 d) {
  const astro *a = (const astro *)e;
  if (!(v3_dot(v3_norm(d), a->f.n) > a->cos_r)) return col1(0.0);
  surface_interaction si = {0};
  return col_scale(tex_eval(a->irradiance, hit ? hit : &si), 1.0 / a->omega);
}

static void astro_set_scene(emitter *e, const scene *s) {
  astro *a = (astro *)e;
  a->center = s->bsphere_center;
  a->radius = s->bsphere_radius;
}

static const emitter_ops astro_ops = {.sample_direction = astro_sample,
                                      .pdf_direction = astro_pdf,
                                      .eval = astro_eval,
                                      .set_scene = astro_set_scene};

static void astro_destroy(object *o) {
  free(o);
}

static vec3 astro_get_direction(const object *o) {
  return ((const astro *)o)->f.n;
}

static void astro_set_direction(object *o, vec3 d) {
  astro *a = (astro *)o;
  if (distant_look_at(d, &a->to_world)) astro_derive(a);
}

static void astro_traverse(object *o, param_visitor *v) {
  astro *a = (astro *)o;
  pv_object(v, "irradiance", &a->irradiance->base, 0.0, INFINITY);
  pv_transform(v, "to_world", &a->to_world, UPDATE_SPECTRAL, NULL);
  pv_vector(v, "direction", astro_get_direction, astro_set_direction, UPDATE_SPECTRAL);
  pv_float(v, "angular_diameter", &a->angular_diameter, UPDATE_SPECTRAL, nextafter(0.0, 1.0),
           nextafter(180.0, 0.0));
  pv_float(v, "sampling_weight", &a->base.sampling_weight, UPDATE_SPECTRAL, 0.0, INFINITY);
}

static void astro_changed(object *o) {
  astro_derive((astro *)o);
}

static rsw_status astro_create(loader *ld, node *n, object **out) {
  astro *a = calloc(1, sizeof *a);
  if (!a) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  a->base.ops = &astro_ops;
  a->base.flags = EMITTER_INFINITE;
  rsw_status st = distant_emitter_read(ld, n, &a->base, &a->irradiance, &a->to_world);
  if (!st) st = ld_float(ld, n, "angular_diameter", 0.5358, &a->angular_diameter);
  if (!st && !(a->angular_diameter > 0.0 && a->angular_diameter < 180.0))
    st = ld_fail(ld, n, "angular_diameter", RSW_ERR_RANGE,
                 "angular_diameter = %g must lie in (0, 180) degrees", a->angular_diameter);
  if (st) {
    free(a);
    return st;
  }
  astro_derive(a);
  *out = &a->base.base;
  return RSW_OK;
}

const plugin plugin_astroobject = {.name = "astroobject",
                                   .cls = CLS_EMITTER,
                                   .create = astro_create,
                                   .destroy = astro_destroy,
                                   .ops = &astro_ops,
                                   .traverse = astro_traverse,
                                   .parameters_changed = astro_changed};
