/* `radiancemeter`: radiance along one ray (mitsuba3
 * src/sensors/radiancemeter.cpp).
 *
 * The ray starts at to_world (0,0,0) and travels along to_world (0,0,1);
 * the one pixel records the radiance arriving at the origin from that
 * direction (W m^-2 sr^-1 [nm^-1]), weight 1. Either `to_world`, or both
 * `origin` and `direction` (to_world = look_at(origin, origin + direction,
 * up), up the first vector of coordinate_system(direction)); when
 * to_world is given it wins and origin/direction are ignored, as in
 * Mitsuba. Like Mitsuba, the origin is nudged by RayEpsilon along d (more
 * in a scene so large that Embree's float32 frame is coarser there:
 * radiancemeter_ray_origin). */
#include <math.h>
#include <stdlib.h>

#include "../accel.h"
#include "../scene/plugin_def.h"
#include "sensor_common.h"

typedef struct radiancemeter {
  sensor base;
  vec3 o, d;         /* d unit */
  meter_frame frame; /* set_scene */
} radiancemeter;

static double radiancemeter_sample_ray(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray) {
  (void)film_u;
  (void)aperture_u;
  const radiancemeter *r = (const radiancemeter *)s;
  ray->o = radiancemeter_ray_origin(r->o, r->d, &r->frame);
  ray->d = r->d;
  ray->tmin = 0.0;
  ray->tmax = INFINITY;
  return 1.0;
}

/* Batched rays (sensor_ops.sample_ray_batch): every sample's ray is the
 * same (it depends on neither sample), so one scalar ray is made and
 * copied: nothing to vectorise, bit for bit the scalar rays. */
static void radiancemeter_sample_ray_batch(const sensor *s, int n, const vec2 *film_u, const vec2 *aperture_u,
                                           ray3 *rays, double *w) {
  if (n <= 0) return;
  ray3 r;
  double w0 = radiancemeter_sample_ray(s, film_u[0], aperture_u[0], &r);
  for (int i = 0; i < n; i++) rays[i] = r, w[i] = w0;
}

static rsw_status radiancemeter_set_scene(sensor *s, const scene *sc, rsw_err *err) {
  (void)err;
  meter_frame_bind(&((radiancemeter *)s)->frame, sc);
  return RSW_OK;
}

static const sensor_ops radiancemeter_ops = {
    .sample_ray = radiancemeter_sample_ray,
    .set_scene = radiancemeter_set_scene,
    .sample_ray_batch = radiancemeter_sample_ray_batch,
};

DEFINE_PLUGIN(radiancemeter, CLS_SENSOR, .ops = &radiancemeter_ops);

static rsw_status radiancemeter_read(loader *ld, node *n, radiancemeter *r) {
  rsw_status st = sensor_read_base(ld, n, &r->base);
  if (st != RSW_OK) return st;
  st = sensor_require_1x1_film(ld, n, &r->base);
  if (st != RSW_OK) return st;

  bool has_xf = ld_has(n, "to_world");
  bool has_o = false, has_d = false;
  vec3 origin = v3(0, 0, 0), dir = v3(0, 0, 1);
  /* Read (and so mark used) origin/direction even when to_world overrides
   * them, as Mitsuba marks them queried. */
  st = ld_vec3(ld, n, "origin", origin, &origin, &has_o);
  if (st != RSW_OK) return st;
  st = ld_vec3(ld, n, "direction", dir, &dir, &has_d);
  if (st != RSW_OK) return st;
  if (has_xf) {
    st = ld_transform(ld, n, "to_world", &r->base.to_world, NULL);
    if (st != RSW_OK) return st;
  } else if (has_o != has_d) {
    return ld_fail(ld, n, has_o ? "origin" : "direction", RSW_ERR_MISSING,
                   "radiancemeter: 'origin' and 'direction' must be given together");
  } else if (has_d) {
    if (!(v3_len(dir) > 0.0))
      return ld_fail(ld, n, "direction", RSW_ERR_INVALID,
                     "radiancemeter: 'direction' must not be the zero vector");
    vec3 dn = v3_norm(dir), up, t_unused;
    coordinate_system(dn, &up, &t_unused);
    if (!xf_look_at(origin, v3_add(origin, dir), up, &r->base.to_world))
      return ld_fail(ld, n, "direction", RSW_ERR_INVALID,
                     "radiancemeter: cannot build a frame from 'direction'");
  }
  vec3 d = xf_vector(&r->base.to_world, v3(0, 0, 1));
  if (!(v3_len(d) > 0.0) || !v3_finite(d))
    return ld_fail(ld, n, "to_world", RSW_ERR_INVALID, "radiancemeter: 'to_world' maps +z to a zero vector");
  r->d = v3_norm(d);
  r->o = xf_point(&r->base.to_world, v3(0, 0, 0));
  return RSW_OK;
}

static rsw_status radiancemeter_create(loader *ld, node *n, object **out) {
  radiancemeter *r = PLUGIN_NEW(radiancemeter, radiancemeter);
  if (!r) return plugin_created(ld, n, NULL, out);
  r->base.ops = &radiancemeter_ops;
  r->base.to_world = xf_identity();
  rsw_status st = radiancemeter_read(ld, n, r);
  if (st != RSW_OK) {
    free(r);
    return st;
  }
  return plugin_created(ld, n, &r->base.base, out);
}
