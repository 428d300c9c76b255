/* `spot`: a point source lit only inside a cone (mitsuba3
 * src/emitters/spot.cpp). At the origin of to_world, pointing along its
 * +z. `intensity` I (W sr^-1 [nm^-1], default 1, constant) is the radiant
 * intensity on the axis; `cutoff_angle` (degrees, default 20) bounds the
 * cone and `beam_width` (degrees, default 3/4 of cutoff_angle) its fully
 * lit core. Mitsuba's falloff at angle theta from the axis:
 *   f(theta) = 1                                     theta <= beam_width,
 *            = (cutoff - theta) / (cutoff - beam)    beam_width < theta < cutoff,
 *            = 0                                     theta >= cutoff_angle
 * (in Mitsuba's branches: cos theta >= cos beam gives 1, cos theta <=
 * cos cutoff gives 0). Next-event estimation as `point`: from x at
 * distance r, pdf 1, value = I f(theta) / r^2, W m^-2 [nm^-1].
 * An optional `texture` (spatially varying, as Mitsuba requires) is
 * projected along the beam: the value is multiplied by it at
 *   uv = (1/2 + x / (2 z tan(cutoff)), 1/2 + y / (2 z tan(cutoff)))
 * for the local direction (x, y, z) towards the lit point (Mitsuba's
 * direction_to_uv), so the cone's cross-section spans [0, 1]^2.
 * Keys: `intensity.value`, `texture.…`, `to_world` and `sampling_weight`, spectral;
 * the angles are fixed at load, as Mitsuba traverses neither. */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "../textures/texture.h"
#include "delta_position.h"

typedef struct spot_light {
  emitter base;
  texture *intensity;
  texture *texture; /* projected along the beam, or NULL */
  double uv_factor; /* tan(cutoff) */
  xform to_world;
  vec3 p;              /* to_world (0, 0, 0) */
  double cutoff, beam; /* radians */
  double cos_cutoff, cos_beam, inv_transition;
} spot_light;

static color spot_sample(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds) {
  const spot_light *sl = (const spot_light *)e;
  (void)u;
  double inv_r2 = delta_position_sample(sl->p, ref->p, ds);
  if (!(inv_r2 > 0)) return col1(0);
  vec3 local = v3_norm(xf_inv_vector(&sl->to_world, v3_neg(ds->d)));
  double cos_theta = local.z, f;
  if (!(cos_theta > sl->cos_cutoff))
    f = 0.0;
  else if (cos_theta >= sl->cos_beam)
    f = 1.0;
  else
    f = (sl->cutoff - acos(fmin(1.0, cos_theta))) * sl->inv_transition;
  if (!(f > 0)) {
    ds->pdf = 0;
    return col1(0);
  }
  color v = col_scale(tex_eval(sl->intensity, ref), f * inv_r2);
  if (sl->texture) {
    surface_interaction at = {.p = sl->p};
    at.uv[0] = 0.5 + 0.5 * local.x / (local.z * sl->uv_factor);
    at.uv[1] = 0.5 + 0.5 * local.y / (local.z * sl->uv_factor);
    v = col_mul(v, tex_eval(sl->texture, &at));
  }
  return v;
}

static const emitter_ops spot_ops = {.sample_direction = spot_sample,
                                     .pdf_direction = delta_position_pdf,
                                     .eval = delta_position_eval,
                                     .set_scene = delta_position_set_scene};

static void spot_parameters_changed(object *o) {
  spot_light *sl = (spot_light *)o;
  sl->p = xf_point(&sl->to_world, v3(0, 0, 0));
}

static void spot_traverse(object *o, param_visitor *v) {
  spot_light *sl = (spot_light *)o;
  pv_object(v, "intensity", &sl->intensity->base, 0.0, INFINITY);
  if (sl->texture) pv_object(v, "texture", &sl->texture->base, 0.0, INFINITY);
  pv_transform(v, "to_world", &sl->to_world, UPDATE_SPECTRAL, NULL);
  pv_float(v, "sampling_weight", &sl->base.sampling_weight, UPDATE_SPECTRAL, 0.0, INFINITY);
}

DEFINE_PLUGIN(spot, CLS_EMITTER, .ops = &spot_ops, .traverse = spot_traverse,
              .parameters_changed = spot_parameters_changed);

static rsw_status spot_create(loader *ld, node *n, object **out) {
  spot_light *sl = PLUGIN_NEW(spot_light, spot);
  if (!sl) return plugin_created(ld, n, NULL, out);
  sl->base.ops = &spot_ops;
  sl->base.flags = EMITTER_DELTA_POSITION;
  double cutoff = 20.0, beam = 15.0;
  rsw_status st = ld_float_range(ld, n, "sampling_weight", 1.0, 0.0, INFINITY, &sl->base.sampling_weight);
  if (!st) st = delta_position_intensity(ld, n, &sl->intensity);
  if (!st) st = delta_position_place(ld, n, false, &sl->to_world);
  if (!st) st = ld_float(ld, n, "cutoff_angle", 20.0, &cutoff);
  if (!st && !(cutoff > 0 && cutoff < 180))
    st = ld_fail(ld, n, "cutoff_angle", RSW_ERR_RANGE, "cutoff_angle must lie in (0, 180) degrees");
  if (!st) st = ld_float(ld, n, "beam_width", cutoff * 3.0 / 4.0, &beam);
  if (!st && !(beam >= 0 && beam <= cutoff))
    st = ld_fail(ld, n, "beam_width", RSW_ERR_RANGE, "beam_width must lie in [0, cutoff_angle] degrees");
  if (!st) st = ld_texture_opt(ld, n, "texture", 0.0, &sl->texture);
  color c;
  if (!st && sl->texture && uniform_texture_value(sl->texture, &c))
    st = ld_fail(ld, n, "texture", RSW_ERR_INVALID,
                 "the projected texture must vary spatially (e.g. a bitmap); scale 'intensity' instead");
  if (!st && sl->texture && !(cutoff < 90))
    st = ld_fail(ld, n, "cutoff_angle", RSW_ERR_RANGE,
                 "a projected texture needs a cutoff_angle below 90 degrees");
  if (st) {
    free(sl);
    return st;
  }
  sl->cutoff = cutoff * RSW_PI / 180.0;
  sl->beam = beam * RSW_PI / 180.0;
  sl->cos_cutoff = cos(sl->cutoff);
  sl->cos_beam = cos(sl->beam);
  sl->uv_factor = tan(sl->cutoff);
  sl->inv_transition = sl->cutoff > sl->beam ? 1.0 / (sl->cutoff - sl->beam) : 0.0;
  spot_parameters_changed(&sl->base.base);
  return plugin_created(ld, n, &sl->base.base, out);
}
