/* `thinlens`: a perspective camera with a thin lens (mitsuba3
 * src/sensors/thinlens.cpp): depth of field. Its field of view as
 * `perspective` (fov / fov_axis / focal_length), to_world rigid,
 * near_clip and far_clip, `aperture_radius` (scene units, required and
 * > 0, as Mitsuba reads it without a default) and `focus_distance` (the
 * distance along the axis that is in focus; default far_clip).
 *
 * With t = tan(fov_x / 2), a = W / H and the film sample s, the point
 * on the focal plane is F v, v = ((1 - 2 s.x) t, (1 - 2 s.y) t / a, 1)
 * (the pinhole direction of `perspective`), the lens point
 * l = R square_to_disk_concentric(aperture sample), and the ray starts at
 * l towards F v: d = normalize(F v - l), clipped to z in [near, far]
 * (tmin = near / d.z, tmax = far / d.z; Mitsuba moves the origin to the
 * near plane instead: the same segment). Weight 1. A point at depth Z is
 * spread on the film (in units of t) over a disk of radius
 * R |1/F - 1/Z|: the circle of confusion.
 * Keys: to_world, x_fov (degrees), aperture_radius, focus_distance, all
 * spectral (Mitsuba lists none but to_world). */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "projective.h"

typedef struct thinlens {
  sensor base;
  projective proj;
  double x_fov, tan_half_fov_x;
  double aperture_radius;
} thinlens;

#define DEG2RAD (RSW_PI / 180.0)

static double thinlens_sample_ray(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray) {
  const thinlens *c = (const thinlens *)s;
  double t = c->tan_half_fov_x, F = c->proj.focus_distance;
  vec3 focus = v3(F * (1.0 - 2.0 * film_u.x) * t, F * (1.0 - 2.0 * film_u.y) * t / c->proj.aspect, F);
  vec2 q = warp_square_to_disk_concentric(aperture_u);
  vec3 lens = v3(c->aperture_radius * q.x, c->aperture_radius * q.y, 0.0);
  vec3 d = v3_norm(v3_sub(focus, lens));
  ray->o = xf_point(&s->to_world, lens);
  ray->d = xf_vector(&s->to_world, d);
  double inv_z = 1.0 / d.z;
  ray->tmin = c->proj.near_clip * inv_z;
  ray->tmax = c->proj.far_clip * inv_z;
  return 1.0;
}

static rsw_status thinlens_set_scene(sensor *s, const scene *sc, rsw_err *err) {
  (void)s, (void)sc, (void)err;
  return RSW_OK;
}

static const sensor_ops thinlens_ops = {.sample_ray = thinlens_sample_ray, .set_scene = thinlens_set_scene};

static void thinlens_parameters_changed(object *o) {
  thinlens *c = (thinlens *)o;
  c->tan_half_fov_x = tan(0.5 * c->x_fov * DEG2RAD);
}

static void thinlens_traverse(object *o, param_visitor *v) {
  thinlens *c = (thinlens *)o;
  pv_transform(v, "to_world", &c->base.to_world, UPDATE_SPECTRAL, projective_check_rigid);
  pv_float(v, "x_fov", &c->x_fov, UPDATE_SPECTRAL, X_FOV_MIN, X_FOV_MAX);
  pv_float(v, "aperture_radius", &c->aperture_radius, UPDATE_SPECTRAL, 1e-12, INFINITY);
  pv_float(v, "focus_distance", &c->proj.focus_distance, UPDATE_SPECTRAL, 1e-12, INFINITY);
}

DEFINE_PLUGIN(thinlens, CLS_SENSOR, .ops = &thinlens_ops, .traverse = thinlens_traverse,
              .parameters_changed = thinlens_parameters_changed);

static rsw_status thinlens_create(loader *ld, node *n, object **out) {
  thinlens *c = PLUGIN_NEW(thinlens, thinlens);
  if (!c) return plugin_created(ld, n, NULL, out);
  c->base.ops = &thinlens_ops;
  rsw_status st = sensor_read_base(ld, n, &c->base);
  if (!st) st = projective_read(ld, n, &c->base, &c->proj);
  if (!st) st = perspective_parse_fov(ld, n, c->proj.aspect, &c->x_fov);
  if (!st) st = projective_read_rigid(ld, n, &c->base.to_world);
  if (!st && !ld_has(n, "aperture_radius"))
    st = ld_fail(ld, n, "aperture_radius", RSW_ERR_MISSING, "thinlens: 'aperture_radius' is required");
  if (!st) st = ld_float(ld, n, "aperture_radius", 0.0, &c->aperture_radius);
  if (!st && !(c->aperture_radius > 0.0))
    st = ld_fail(ld, n, "aperture_radius", RSW_ERR_RANGE,
                 "'aperture_radius' must be > 0 (use perspective for a pinhole)");
  if (!st && !(c->proj.focus_distance > 0.0))
    st = ld_fail(ld, n, "focus_distance", RSW_ERR_RANGE, "'focus_distance' must be > 0");
  if (st) {
    free(c);
    return st;
  }
  thinlens_parameters_changed(&c->base.base);
  return plugin_created(ld, n, &c->base.base, out);
}
