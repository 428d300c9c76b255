/* `orthographic`: parallel rays along the camera's +z (mitsuba3
 * src/sensors/orthographic.cpp). The film covers local x in [-1, 1] and
 * y in [-1/a, 1/a] (a = W / H), so to_world's scale sets the size of the
 * view (a scale is allowed here, unlike the perspective cameras). The film
 * sample s gives the local point p = (1 - 2 s.x, (1 - 2 s.y) / a, near)
 * (film x to the left of the camera frame, as `perspective`); the ray
 * starts at to_world p along normalize(to_world (0, 0, 1)) for far - near
 * (Mitsuba's maxt). Weight 1. Keys: to_world (spectral; an invertible
 * transform). */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "projective.h"

typedef struct orthographic {
  sensor base;
  projective proj;
} orthographic;

static double ortho_sample_ray(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray) {
  (void)aperture_u;
  const orthographic *c = (const orthographic *)s;
  vec3 p = v3(1.0 - 2.0 * film_u.x, (1.0 - 2.0 * film_u.y) / c->proj.aspect, c->proj.near_clip);
  ray->o = xf_point(&s->to_world, p);
  ray->d = v3_norm(xf_vector(&s->to_world, v3(0, 0, 1)));
  ray->tmin = 0.0;
  ray->tmax = c->proj.far_clip - c->proj.near_clip;
  return 1.0;
}

static rsw_status ortho_set_scene(sensor *s, const scene *sc, rsw_err *err) {
  (void)s, (void)sc, (void)err;
  return RSW_OK;
}

static const sensor_ops ortho_ops = {.sample_ray = ortho_sample_ray, .set_scene = ortho_set_scene};

static void ortho_traverse(object *o, param_visitor *v) {
  pv_transform(v, "to_world", &((sensor *)o)->to_world, UPDATE_SPECTRAL, NULL);
}

DEFINE_PLUGIN(orthographic, CLS_SENSOR, .ops = &ortho_ops, .traverse = ortho_traverse);

static rsw_status orthographic_create(loader *ld, node *n, object **out) {
  orthographic *c = PLUGIN_NEW(orthographic, orthographic);
  if (!c) return plugin_created(ld, n, NULL, out);
  c->base.ops = &ortho_ops;
  rsw_status st = sensor_read_base(ld, n, &c->base);
  if (!st) st = projective_read(ld, n, &c->base, &c->proj);
  if (!st) st = ld_transform(ld, n, "to_world", &c->base.to_world, NULL);
  if (st) {
    free(c);
    return st;
  }
  return plugin_created(ld, n, &c->base.base, out);
}
