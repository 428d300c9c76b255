/* The service's view of the kernel (kapi.h). */
#include "kapi.h"
#include <stdlib.h>

#include "accel.h"
#include "scene/scene.h"

bool kapi_is_mono(const scene *sc) {
  return sc->variant == VARIANT_MONO;
}

size_t kapi_sensor_count(const scene *sc) {
  return sc->n_sensors;
}

const char *kapi_sensor_id(const scene *sc, size_t i) {
  return i < sc->n_sensors ? sc->sensors[i]->base.id : NULL;
}

const char *kapi_sensor_type(const scene *sc, size_t i) {
  return i < sc->n_sensors ? sc->sensors[i]->base.plugin->name : NULL;
}

bool kapi_find_sensor(const scene *sc, const char *name, size_t *index) {
  return scene_find_sensor(sc, name, index) != NULL;
}

void kapi_film_size(const scene *sc, size_t i, int *width, int *height) {
  const film *f = i < sc->n_sensors ? sc->sensors[i]->film : NULL;
  *width = f ? f->width : 0;
  *height = f ? f->height : 0;
}

uint32_t kapi_sensor_spp(const scene *sc, size_t i) {
  return i < sc->n_sensors ? sc->sensors[i]->sampler->sample_count : 0;
}

size_t kapi_scene_bytes(const scene *sc) {
  size_t b = accel_memory(sc->accel);
  for (size_t i = 0; i < sc->n_shapes; i++) {
    const mesh *m = &sc->shapes[i]->mesh;
    b += (size_t)m->n_verts * (12 + (m->nrm ? 12 : 0) + (m->uv ? 8 : 0)) + (size_t)m->n_faces * 12;
    if (sc->shapes[i]->tri_cdf) b += (size_t)sc->shapes[i]->tri_cdf_n * 8;
  }
  return b;
}

bool kapi_has_directions(const scene *sc, size_t i) {
  return i < sc->n_sensors && sc->sensors[i]->ops->pixel_directions && sc->sensors[i]->ops->pixel_angles;
}

rsw_status kapi_pixel_directions(const scene *sc, size_t i, double *out, rsw_err *err) {
  if (!kapi_has_directions(sc, i))
    return rsw_fail(err, RSW_ERR_UNSUPPORTED, i < sc->n_sensors ? sc->sensors[i]->base.id : "sensor",
                    "this sensor has no per-pixel directions");
  const sensor *se = sc->sensors[i];
  int W = se->film->width, H = se->film->height;
  size_t n = (size_t)W * (size_t)H;
  double *xyz = malloc(3 * n * sizeof *xyz);
  if (!xyz) return rsw_fail(err, RSW_ERR_NOMEM, se->base.id, "out of memory");
  double *za = out + 3 * n; /* 2 per pixel, read before pixel p's 5 slots reach them */
  se->ops->pixel_angles(se, W, H, za);
  se->ops->pixel_directions(se, W, H, xyz);
  for (size_t p = 0; p < n; p++) {
    double zen = za[2 * p], az = za[2 * p + 1];
    double *o = out + 5 * p;
    o[0] = xyz[3 * p], o[1] = xyz[3 * p + 1], o[2] = xyz[3 * p + 2], o[3] = zen, o[4] = az;
  }
  free(xyz);
  return RSW_OK;
}

bool kapi_embree_stuck(long long *since, unsigned long long *oom_count, bool probe) {
  time_t t = 0;
  bool stuck = accel_embree_stuck(&t, oom_count, probe);
  if (since) *since = (long long)t;
  return stuck;
}
