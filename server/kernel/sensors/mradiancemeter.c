/* `mradiancemeter`: N radiancemeters in one sensor (Eradiate plugin,
 * eradiate/mitsuba3 src/eradiate_plugins/sensors/mradiancemeter.cpp;
 * docs/kernel-conventions.md#mdistant-and-mradiancemeter).
 *
 * `origins` and `directions` are strings of 3N numbers each (commas and/or
 * white space); the film is N x 1 and pixel i = floor(u.x N) is the
 * radiancemeter at origin_i looking along normalize(direction_i): the
 * radiance arriving at origin_i from that direction, weight 1. As for
 * radiancemeter the origin is nudged by RayEpsilon along d
 * (radiancemeter_ray_origin). */
#include <math.h>
#include <stdlib.h>

#include "../accel.h"
#include "../scene/plugin_def.h"
#include "sensor_common.h"

typedef struct mradiancemeter {
  sensor base;
  size_t n;
  vec3 *o, *d;       /* n each; d unit */
  meter_frame frame; /* set_scene */
} mradiancemeter;

static double mradiancemeter_sample_ray(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray) {
  (void)aperture_u;
  const mradiancemeter *m = (const mradiancemeter *)s;
  double f = floor(film_u.x * (double)m->n);
  size_t i = !(f >= 0.0) ? 0 : (f >= (double)m->n ? m->n - 1 : (size_t)f);
  ray->o = radiancemeter_ray_origin(m->o[i], m->d[i], &m->frame);
  ray->d = m->d[i];
  ray->tmin = 0.0;
  ray->tmax = INFINITY;
  return 1.0;
}

static rsw_status mradiancemeter_set_scene(sensor *s, const scene *sc, rsw_err *err) {
  (void)err;
  meter_frame_bind(&((mradiancemeter *)s)->frame, sc);
  return RSW_OK;
}

static const sensor_ops mradiancemeter_ops = {
    .sample_ray = mradiancemeter_sample_ray,
    .set_scene = mradiancemeter_set_scene,
};

static void mradiancemeter_destroy(object *o) {
  mradiancemeter *m = (mradiancemeter *)o;
  if (!m) return;
  free(m->o);
  free(m->d);
  free(m);
}

DEFINE_PLUGIN(mradiancemeter, CLS_SENSOR, .destroy = mradiancemeter_destroy, .ops = &mradiancemeter_ops);

static rsw_status mradiancemeter_read(loader *ld, node *n, mradiancemeter *m) {
  rsw_status st = sensor_read_base(ld, n, &m->base);
  if (st != RSW_OK) return st;
  size_t n_o = 0;
  st = sensor_read_vec3_list(ld, n, "origins", &m->o, &n_o);
  if (st != RSW_OK) return st;
  st = sensor_read_vec3_list(ld, n, "directions", &m->d, &m->n);
  if (st != RSW_OK) return st;
  if (n_o != m->n)
    return ld_fail(ld, n, "directions", RSW_ERR_INVALID,
                   "mradiancemeter: %zu origins but %zu directions (they must pair up)", n_o, m->n);
  if (m->base.film->width < 0 || (size_t)m->base.film->width != m->n || m->base.film->height != 1)
    return ld_fail(ld, n, "film", RSW_ERR_INVALID,
                   "mradiancemeter: the film must be %zu x 1 pixels, one per radiancemeter (got %dx%d)", m->n,
                   m->base.film->width, m->base.film->height);
  for (size_t i = 0; i < m->n; i++) {
    if (!(v3_len(m->d[i]) > 0.0))
      return ld_fail(ld, n, "directions", RSW_ERR_INVALID, "mradiancemeter: direction %zu is the zero vector",
                     i);
    m->d[i] = v3_norm(m->d[i]);
  }
  return RSW_OK;
}

static rsw_status mradiancemeter_create(loader *ld, node *n, object **out) {
  mradiancemeter *m = PLUGIN_NEW(mradiancemeter, mradiancemeter);
  if (!m) return plugin_created(ld, n, NULL, out);
  m->base.ops = &mradiancemeter_ops;
  m->base.to_world = xf_identity();
  rsw_status st = mradiancemeter_read(ld, n, m);
  if (st != RSW_OK) {
    mradiancemeter_destroy(&m->base.base);
    return st;
  }
  return plugin_created(ld, n, &m->base.base, out);
}
