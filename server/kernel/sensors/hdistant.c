/* `hdistant`: hemispherical distant radiancemeter (Eradiate plugin,
 * eradiate/mitsuba3 src/eradiate_plugins/sensors/hdistant.cpp;
 * docs/kernel-conventions.md#hdistant).
 *
 * Each film sample u maps to one exitant direction of the hemisphere around
 * the sensor axis to_world (0,0,1):
 *   v_local = square_to_uniform_hemisphere(u)   (concentric based)
 *   omega   = to_world v_local,   ray.d = -omega
 * The map preserves area, so every pixel subtends 2 pi / (W H) sr and the
 * film records, per pixel, the mean over samples of weight * L(o, d): the
 * radiance leaving the target along omega (W m^-2 sr^-1 [nm^-1]).
 *
 * Ray origins follow the target strategy (sensor_common.h) with the
 * distance `ray_offset` back along -d; a negative ray_offset (default -1)
 * is resolved in set_scene() to R without a target and 2R with one, R
 * being the inflated bounding-sphere radius. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "sensor_common.h"

typedef struct hdistant {
  sensor base;
  ray_target target;
  double ray_offset_param; /* as given; < 0: resolve from the scene */
  double ray_offset;       /* in use (resolved by set_scene) */
  vec3 center;             /* scene bounding sphere */
  double radius;
} hdistant;

/* The film mapping (docs/kernel-conventions.md#hdistant): film sample u in
 * [0,1)^2 sees the radiance leaving along omega = to_world H(u), H the
 * concentric uniform-hemisphere map. Normalised so that a to_world with a
 * scale still gives a unit ray direction (Mitsuba leaves it scaled; the
 * integrators assume |d| = 1). */
static vec3 hdistant_omega(const sensor *s, vec2 film_u) {
  return v3_norm(xf_vector(&s->to_world, warp_square_to_uniform_hemisphere(film_u)));
}

static double hdistant_sample_ray(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray) {
  const hdistant *h = (const hdistant *)s;
  vec3 omega = hdistant_omega(s, film_u);
  vec3 d = v3_neg(omega);
  vec3 o;
  double w =
      ray_target_origin(&h->target, &s->to_world, h->center, h->radius, h->ray_offset, d, aperture_u, &o);
  ray->o = o;
  ray->d = d;
  ray->tmin = 0.0;
  ray->tmax = INFINITY;
  return w;
}

/* Batched rays (sensor_ops.sample_ray_batch): the double-precision lanes
 * of sensors/sensor_common_lanes.h, which give hdistant_sample_ray()'s
 * rays bit for bit without a target or a periodic slab; with one, their
 * directions (hdistant_omega's, negated: the same bits) and the origins
 * and weights of ray_target_origin() (ray_target_origins), as sample_ray
 * takes them. */
static void hdistant_sample_ray_batch(const sensor *s, int n, const vec2 *film_u, const vec2 *aperture_u,
                                      ray3 *rays, double *w) {
  const hdistant *h = (const hdistant *)s;
  hemisphere_rays_batch(s, h->center, h->radius, h->ray_offset, n, film_u, aperture_u, rays);
  if (h->target.kind != RAY_TARGET_NONE || h->target.slab.on) {
    ray_target_origins(&h->target, &s->to_world, h->center, h->radius, h->ray_offset, n, aperture_u, rays, w);
    return;
  }
  for (int i = 0; i < n; i++) w[i] = 1.0;
}

static rsw_status hdistant_set_scene(sensor *s, const scene *sc, rsw_err *err) {
  hdistant *h = (hdistant *)s;
  rsw_status st = ray_target_check(&h->target, s->base.id, err);
  if (st != RSW_OK) return st;
  ray_target_bind(&h->target, sc, h->ray_offset_param >= 0.0);
  /* scene->bsphere_radius is already inflated as Mitsuba's set_scene does:
   * R = max(RayEpsilon, r (1 + RayEpsilon)). */
  h->center = sc->bsphere_center;
  h->radius = sc->bsphere_radius;
  h->ray_offset = sensor_ray_offset(&h->target, h->ray_offset_param, h->radius);
  return RSW_OK;
}

static void hdistant_pixel_angles(const sensor *s, int W, int H, double *zen_az) {
  (void)s;
  hemisphere_pixel_angles(W, H, zen_az);
}

/* omega = to_world H(u) at the pixel centre, as sample_ray maps it. */
static void hdistant_pixel_directions(const sensor *s, int W, int H, double *xyz) {
  for (int iy = 0; iy < H; iy++)
    for (int ix = 0; ix < W; ix++) {
      vec3 v = warp_square_to_uniform_hemisphere(v2((ix + 0.5) / W, (iy + 0.5) / H));
      vec3 w = v3_norm(xf_vector(&s->to_world, v));
      double *o = &xyz[3 * ((size_t)iy * W + (size_t)ix)];
      o[0] = w.x, o[1] = w.y, o[2] = w.z;
    }
}

static const sensor_ops hdistant_ops = {
    .sample_ray = hdistant_sample_ray,
    .set_scene = hdistant_set_scene,
    .pixel_angles = hdistant_pixel_angles,
    .pixel_directions = hdistant_pixel_directions,
    .sample_ray_batch = hdistant_sample_ray_batch,
};

static void hdistant_destroy(object *o) {
  if (o) ray_target_release(&((hdistant *)o)->target);
  free(o);
}

/* to_world and the `direction` key: sensor_traverse_axis (sensor_common.h). */
DEFINE_PLUGIN(hdistant, CLS_SENSOR, .destroy = hdistant_destroy, .traverse = sensor_traverse_axis,
              .ops = &hdistant_ops);

static rsw_status hdistant_create(loader *ld, node *n, object **out) {
  hdistant *h = PLUGIN_NEW(hdistant, hdistant);
  if (!h) return plugin_created(ld, n, NULL, out);
  h->base.ops = &hdistant_ops;
  h->base.to_world = xf_identity();
  h->base.stokes_pole = true;

  rsw_status st = sensor_read_base(ld, n, &h->base);
  if (st == RSW_OK) st = ld_transform(ld, n, "to_world", &h->base.to_world, NULL);
  if (st == RSW_OK) st = sensor_read_target(ld, n, &h->target);
  if (st == RSW_OK) st = ld_float(ld, n, "ray_offset", -1.0, &h->ray_offset_param);
  if (st != RSW_OK) {
    free(h);
    return st;
  }
  h->ray_offset = h->ray_offset_param;
  return plugin_created(ld, n, &h->base.base, out);
}
