/* `mpdistant`: Eradiate's multi-pixel distant radiancemeter (eradiate/mitsuba3
 * src/eradiate_plugins/sensors/mpdistant.cpp; docs/kernel-conventions.md#mpdistant).
 *
 * `distant` with a film of any size: every ray travels along
 * d = to_world (0,0,1), and the film position (not the aperture sample)
 * picks where it aims, so pixel (i, j) records the radiance leaving along
 * -d from its own part of the target:
 *   shape:  ps = sample_position(film_u), o = ps.p - offset d, weight 1/(pdf area)
 *           (a rectangle's film maps to its (u, v));
 *   point:  o = p - offset d, or with target_radius >= 0
 *           o = p + target_radius to_world (q, 0) - offset d,
 *           q = square_to_disk_concentric(film_u);
 *   none:   as point with the bounding sphere's centre and radius.
 * ray_offset: distance back along -d (default 2R, R the scene's bounding
 * radius). In a periodic scene the origins are put outside the slab as
 * for `distant` (sensors/sensor_common.h, ray_target_bind). */
#include <math.h>
#include <stdlib.h>

#include "../scene/params.h"
#include "sensor_common.h"

typedef struct mpdistant {
  sensor base;
  ray_target target;
  double target_radius;    /* < 0: the point itself */
  double ray_offset_param; /* as given; < 0: 2R */
  double ray_offset;
  vec3 d; /* unit, into the scene */
  vec3 center;
  double radius;
} mpdistant;

static double mp_sample_ray(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray) {
  (void)aperture_u;
  const mpdistant *m = (const mpdistant *)s;
  vec3 o;
  double w = 1.0;
  if (m->target.kind == RAY_TARGET_POINT && m->target_radius >= 0.0) {
    vec2 q = warp_square_to_disk_concentric(film_u);
    vec3 off = xf_vector(&s->to_world, v3(q.x, q.y, 0.0));
    o = v3_sub(v3_fma(m->target.point, m->target_radius, off), v3_scale(m->d, m->ray_offset));
  } else {
    w = ray_target_origin(&m->target, &s->to_world, m->center, m->radius, m->ray_offset, m->d, film_u, &o);
  }
  ray->o = o;
  ray->d = m->d;
  ray->tmin = 0.0;
  ray->tmax = INFINITY;
  return w;
}

static rsw_status mp_set_scene(sensor *s, const scene *sc, rsw_err *err) {
  mpdistant *m = (mpdistant *)s;
  rsw_status st = ray_target_check(&m->target, s->base.id, err);
  if (st != RSW_OK) return st;
  ray_target_bind(&m->target, sc, m->ray_offset_param >= 0.0);
  m->center = sc->bsphere_center;
  m->radius = sc->bsphere_radius;
  m->ray_offset = m->ray_offset_param >= 0.0 ? m->ray_offset_param : 2.0 * m->radius;
  return RSW_OK;
}

static void mp_pixel_angles(const sensor *s, int W, int H, double *zen_az) {
  vec3 w = v3_neg(((const mpdistant *)s)->d);
  for (size_t i = 0; i < (size_t)W * H; i++) direction_angles(w, &zen_az[2 * i], &zen_az[2 * i + 1]);
}

static void mp_pixel_directions(const sensor *s, int W, int H, double *xyz) {
  vec3 w = v3_neg(((const mpdistant *)s)->d);
  for (size_t i = 0; i < (size_t)W * H; i++) xyz[3 * i] = w.x, xyz[3 * i + 1] = w.y, xyz[3 * i + 2] = w.z;
}

static const sensor_ops mp_ops = {
    .sample_ray = mp_sample_ray,
    .set_scene = mp_set_scene,
    .pixel_angles = mp_pixel_angles,
    .pixel_directions = mp_pixel_directions,
};

static void mp_destroy(object *o) {
  if (o) ray_target_release(&((mpdistant *)o)->target);
  free(o);
}

/* Eradiate's rule for `direction`: look_at(0, normalize(direction), up)
 * with up the second vector of coordinate_system(direction). */
static bool mp_frame(vec3 dir, xform *out) {
  vec3 dn = v3_norm(dir), s_unused, up;
  coordinate_system(dn, &s_unused, &up);
  return xf_look_at(v3(0, 0, 0), dn, up, out);
}

static vec3 mp_get_direction(const object *o) {
  return ((const mpdistant *)o)->d;
}

static void mp_set_direction(object *o, vec3 dir) {
  xform t;
  if (mp_frame(dir, &t)) ((mpdistant *)o)->base.to_world = t;
}

static void mp_changed(object *o) {
  mpdistant *m = (mpdistant *)o;
  m->d = v3_norm(xf_vector(&m->base.to_world, v3(0, 0, 1)));
}

/* As `distant`: to_world and the `direction` convenience key (where the
 * sensor looks), not geometric. */
static void mp_traverse(object *o, param_visitor *v) {
  mpdistant *m = (mpdistant *)o;
  pv_transform(v, "to_world", &m->base.to_world, UPDATE_SPECTRAL, sensor_check_axis_xf);
  pv_vector(v, "direction", mp_get_direction, mp_set_direction, UPDATE_SPECTRAL);
}

static rsw_status mp_read(loader *ld, node *n, mpdistant *m) {
  rsw_status st = sensor_read_base(ld, n, &m->base);
  if (st != RSW_OK) return st;
  if (ld_has(n, "direction") && ld_has(n, "to_world"))
    return ld_fail(ld, n, "direction", RSW_ERR_INVALID,
                   "mpdistant: only one of 'direction' and 'to_world' can be given");
  bool has_dir = false;
  vec3 dir = v3(0, 0, 1);
  if ((st = ld_vec3(ld, n, "direction", dir, &dir, &has_dir)) != RSW_OK) return st;
  if (has_dir) {
    if (!(v3_len(dir) > 0.0))
      return ld_fail(ld, n, "direction", RSW_ERR_INVALID,
                     "mpdistant: 'direction' must not be the zero vector");
    if (!mp_frame(dir, &m->base.to_world))
      return ld_fail(ld, n, "direction", RSW_ERR_INVALID, "mpdistant: cannot build a frame from 'direction'");
  } else if ((st = ld_transform(ld, n, "to_world", &m->base.to_world, NULL)) != RSW_OK) {
    return st;
  }
  vec3 d = xf_vector(&m->base.to_world, v3(0, 0, 1));
  if (!(v3_len(d) > 0.0) || !v3_finite(d))
    return ld_fail(ld, n, "to_world", RSW_ERR_INVALID, "mpdistant: 'to_world' maps +z to a zero vector");
  m->d = v3_norm(d);
  if ((st = ld_float(ld, n, "ray_offset", -1.0, &m->ray_offset_param)) != RSW_OK) return st;
  if ((st = ld_float(ld, n, "target_radius", -1.0, &m->target_radius)) != RSW_OK) return st;
  if (!isfinite(m->ray_offset_param) || !isfinite(m->target_radius))
    return ld_fail(ld, n, NULL, RSW_ERR_INVALID, "mpdistant: ray_offset and target_radius must be finite");
  if ((st = sensor_read_target(ld, n, &m->target)) != RSW_OK) return st;
  if (m->target_radius >= 0.0 && m->target.kind != RAY_TARGET_POINT)
    return ld_fail(ld, n, "target_radius", RSW_ERR_INVALID, "mpdistant: target_radius needs a point target");
  return RSW_OK;
}

static rsw_status mp_create(loader *ld, node *n, object **out);

const plugin plugin_mpdistant = {
    .name = "mpdistant",
    .cls = CLS_SENSOR,
    .create = mp_create,
    .destroy = mp_destroy,
    .ops = &mp_ops,
    .traverse = mp_traverse,
    .parameters_changed = mp_changed,
};

static rsw_status mp_create(loader *ld, node *n, object **out) {
  mpdistant *m = calloc(1, sizeof *m);
  if (!m) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  m->base.base.plugin = &plugin_mpdistant;
  m->base.base.id = n->id;
  m->base.ops = &mp_ops;
  m->base.to_world = xf_identity();
  rsw_status st = mp_read(ld, n, m);
  if (st != RSW_OK) {
    ray_target_release(&m->target);
    free(m);
    return st;
  }
  *out = &m->base.base;
  return RSW_OK;
}
