/* `point`: an isotropic point source (mitsuba3 src/emitters/point.cpp).
 *
 * `intensity` I is radiant intensity, W sr^-1 [nm^-1] (default 1; it must
 * not vary spatially); the source sits at `position` or at to_world's
 * image of the origin (exclusive, as Mitsuba). Next-event estimation is a
 * delta position: from a reference point x at distance r,
 *   ds.d = (p - x) / r, pdf 1 (discrete), value = I / r^2 (irradiance
 *   normal to ds.d, W m^-2 [nm^-1]).
 * Never hit by rays (eval 0, pdf_direction 0).
 * Keys: `intensity.value` and `sampling_weight` (spectral), `position`
 * (spectral: the light is not in the acceleration structure) and
 * `to_world`, each rewriting the other. */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "../textures/texture.h"
#include "delta_position.h"

typedef struct point_light {
  emitter base;
  texture *intensity;
  xform to_world;
  vec3 p; /* to_world (0, 0, 0) */
} point_light;

static color point_sample(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds) {
  const point_light *pl = (const point_light *)e;
  (void)u;
  double inv_r2 = delta_position_sample(pl->p, ref->p, ds);
  if (!(inv_r2 > 0)) return col1(0);
  return col_scale(tex_eval(pl->intensity, ref), inv_r2);
}

static const emitter_ops point_ops = {.sample_direction = point_sample,
                                      .pdf_direction = delta_position_pdf,
                                      .eval = delta_position_eval,
                                      .set_scene = delta_position_set_scene};

static vec3 point_get_position(const object *o) {
  return ((const point_light *)o)->p;
}

static void point_set_position(object *o, vec3 p) {
  point_light *pl = (point_light *)o;
  delta_position_move(&pl->to_world, p);
  pl->p = p;
}

static void point_traverse(object *o, param_visitor *v) {
  point_light *pl = (point_light *)o;
  pv_object(v, "intensity", &pl->intensity->base, 0.0, INFINITY);
  pv_position(v, "position", point_get_position, point_set_position, UPDATE_SPECTRAL);
  pv_transform(v, "to_world", &pl->to_world, UPDATE_SPECTRAL, NULL);
  pv_float(v, "sampling_weight", &pl->base.sampling_weight, UPDATE_SPECTRAL, 0.0, INFINITY);
}

static void point_parameters_changed(object *o) {
  point_light *pl = (point_light *)o;
  pl->p = xf_point(&pl->to_world, v3(0, 0, 0));
}

DEFINE_PLUGIN(point, CLS_EMITTER, .ops = &point_ops, .traverse = point_traverse,
              .parameters_changed = point_parameters_changed);

static rsw_status point_create(loader *ld, node *n, object **out) {
  point_light *pl = PLUGIN_NEW(point_light, point);
  if (!pl) return plugin_created(ld, n, NULL, out);
  pl->base.ops = &point_ops;
  pl->base.flags = EMITTER_DELTA_POSITION;
  rsw_status st = ld_float_range(ld, n, "sampling_weight", 1.0, 0.0, INFINITY, &pl->base.sampling_weight);
  if (!st) st = delta_position_intensity(ld, n, &pl->intensity);
  if (!st) st = delta_position_place(ld, n, true, &pl->to_world);
  if (st) {
    free(pl);
    return st;
  }
  point_parameters_changed(&pl->base.base);
  return plugin_created(ld, n, &pl->base.base, out);
}
