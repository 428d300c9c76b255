/* `distantflux`: hemispherical exitant flux density (Eradiate plugin,
 * eradiate/mitsuba3 src/eradiate_plugins/sensors/distantflux.cpp;
 * docs/kernel-conventions.md#distantflux).
 *
 * Directions, targets and ray_offset exactly as hdistant:
 *   v_local = square_to_uniform_hemisphere(u), omega = to_world v_local,
 *   ray.d = -omega.
 * Each sample is weighted by cos theta / (p_H N_pix) with p_H = 1 / (2 pi)
 * the hemisphere's sampling density and N_pix = W H:
 *   w = 2 pi (omega . n_ref) / (W H),   n_ref = to_world (0,0,1),
 * times the target weight. A pixel holds (2 pi / N_pix) E_pixel[L cos theta],
 * so the SUM over all pixels is the radiosity
 *   J = int_hemisphere L cos theta d omega   (W m^-2 [nm^-1]).
 * n_ref is read from the current to_world at each sample, so updating the
 * `to_world` / `direction` parameters moves the reference normal too. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "sensor_common.h"

typedef struct distantflux {
  sensor base;
  ray_target target;
  double ray_offset_param; /* as given; < 0: resolve from the scene */
  double ray_offset;
  vec3 center;
  double radius;
} distantflux;

static double distantflux_sample_ray(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray) {
  const distantflux *f = (const distantflux *)s;
  vec3 v_local = warp_square_to_uniform_hemisphere(film_u);
  vec3 omega = v3_norm(xf_vector(&s->to_world, v_local));
  vec3 n_ref = v3_norm(xf_vector(&s->to_world, v3(0, 0, 1)));
  vec3 d = v3_neg(omega);
  vec3 o;
  double w =
      ray_target_origin(&f->target, &s->to_world, f->center, f->radius, f->ray_offset, d, aperture_u, &o);
  double n_pix = (double)s->film->width * (double)s->film->height;
  w *= 2.0 * 3.14159265358979323846 * v3_dot(omega, n_ref) / n_pix;
  ray->o = o;
  ray->d = d;
  ray->tmin = 0.0;
  ray->tmax = INFINITY;
  return w;
}

/* Batched rays (sensor_ops.sample_ray_batch): without a target or a
 * periodic slab, hdistant's double lanes (sensors/sensor_common_lanes.h: the same
 * directions and origins, bit for bit), omega = -d (exact), and the
 * weight per lane with distantflux_sample_ray()'s operations: bit for bit
 * its rays and weights. Otherwise one by one. */
static void distantflux_sample_ray_batch(const sensor *s, int n, const vec2 *film_u, const vec2 *aperture_u,
                                         ray3 *rays, double *w) {
  const distantflux *f = (const distantflux *)s;
  if (f->target.kind != RAY_TARGET_NONE || f->target.slab.on) {
    for (int i = 0; i < n; i++) w[i] = distantflux_sample_ray(s, film_u[i], aperture_u[i], &rays[i]);
    return;
  }
  hemisphere_rays_batch(s, f->center, f->radius, f->ray_offset, n, film_u, aperture_u, rays);
  vec3 n_ref = v3_norm(xf_vector(&s->to_world, v3(0, 0, 1)));
  double n_pix = (double)s->film->width * (double)s->film->height;
  for (int i = 0; i < n; i++) {
    vec3 omega = v3_neg(rays[i].d);
    double wk = 1.0;
    wk *= 2.0 * 3.14159265358979323846 * v3_dot(omega, n_ref) / n_pix;
    w[i] = wk;
  }
}

static rsw_status distantflux_set_scene(sensor *s, const scene *sc, rsw_err *err) {
  distantflux *f = (distantflux *)s;
  rsw_status st = ray_target_check(&f->target, s->base.id, err);
  if (st != RSW_OK) return st;
  ray_target_bind(&f->target, sc, f->ray_offset_param >= 0.0);
  f->center = sc->bsphere_center; /* radius already inflated (kernel.h) */
  f->radius = sc->bsphere_radius;
  f->ray_offset = sensor_ray_offset(&f->target, f->ray_offset_param, f->radius);
  return RSW_OK;
}

static void distantflux_pixel_angles(const sensor *s, int W, int H, double *zen_az) {
  (void)s;
  hemisphere_pixel_angles(W, H, zen_az);
}

static const sensor_ops distantflux_ops = {
    .sample_ray = distantflux_sample_ray,
    .set_scene = distantflux_set_scene,
    .pixel_angles = distantflux_pixel_angles,
    .sample_ray_batch = distantflux_sample_ray_batch,
};

static void distantflux_destroy(object *o) {
  if (o) ray_target_release(&((distantflux *)o)->target);
  free(o);
}

/* to_world and the `direction` key: sensor_traverse_axis (sensor_common.h). */
DEFINE_PLUGIN(distantflux, CLS_SENSOR, .destroy = distantflux_destroy, .traverse = sensor_traverse_axis,
              .ops = &distantflux_ops);

static rsw_status distantflux_create(loader *ld, node *n, object **out) {
  distantflux *f = PLUGIN_NEW(distantflux, distantflux);
  if (!f) return plugin_created(ld, n, NULL, out);
  f->base.ops = &distantflux_ops;
  f->base.to_world = xf_identity();
  f->base.stokes_pole = true;

  rsw_status st = sensor_read_base(ld, n, &f->base);
  if (st == RSW_OK) st = ld_transform(ld, n, "to_world", &f->base.to_world, NULL);
  if (st == RSW_OK) {
    vec3 d = xf_vector(&f->base.to_world, v3(0, 0, 1));
    if (!(v3_len(d) > 0.0) || !v3_finite(d))
      st = ld_fail(ld, n, "to_world", RSW_ERR_INVALID, "distantflux: 'to_world' maps +z to a zero vector");
  }
  if (st == RSW_OK) st = sensor_read_target(ld, n, &f->target);
  if (st == RSW_OK) st = ld_float(ld, n, "ray_offset", -1.0, &f->ray_offset_param);
  if (st != RSW_OK) {
    free(f);
    return st;
  }
  f->ray_offset = f->ray_offset_param;
  return plugin_created(ld, n, &f->base.base, out);
}
