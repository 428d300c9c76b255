/* `distant`: single-direction distant radiancemeter (mitsuba3
 * src/sensors/distant.cpp; docs/kernel-conventions.md#distant).
 *
 * Every ray travels along d = to_world (0,0,1) (the direction the sensor
 * looks, into the scene); the one pixel records the radiance leaving the
 * scene along -d (W m^-2 sr^-1 [nm^-1]), averaged over the target.
 * Origins: point target o = p - 2R d; shape target o = ps.p - 2R d with
 * weight 1/(pdf area); no target: a disk of radius R around the bounding
 * sphere centre, orthogonal to d (to_world's z), shifted back by R.
 * There is no ray_offset parameter. */
#include <math.h>
#include <stdlib.h>

#include "../scene/params.h"
#include "../scene/plugin_def.h"
#include "sensor_common.h"

typedef struct distant {
  sensor base;
  ray_target target;
  vec3 d;      /* unit, into the scene */
  vec3 center; /* scene bounding sphere */
  double radius;
} distant;

static double distant_sample_ray(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray) {
  (void)film_u;
  const distant *ds = (const distant *)s;
  /* Point/shape targets start 2R away (the sphere's diameter: the origin is
   * outside the scene whatever the target); the no-target disk goes
   * through the centre, so R suffices. */
  double offset = ds->target.kind == RAY_TARGET_NONE ? ds->radius : 2.0 * ds->radius;
  vec3 o;
  double w =
      ray_target_origin(&ds->target, &s->to_world, ds->center, ds->radius, offset, ds->d, aperture_u, &o);
  ray->o = o;
  ray->d = ds->d;
  ray->tmin = 0.0;
  ray->tmax = INFINITY;
  return w;
}

/* Batched rays (sensor_ops.sample_ray_batch): without a target or a
 * periodic slab, the origins on the bounding disk in double lanes
 * (sensors/sensor_common_lanes.h disk_origins, the same operations as
 * ray_target_origin()), so bit for bit distant_sample_ray()'s rays; the
 * direction is the sensor's. Otherwise one by one. */
static void distant_sample_ray_batch(const sensor *s, int n, const vec2 *film_u, const vec2 *aperture_u,
                                     ray3 *rays, double *w) {
  const distant *ds = (const distant *)s;
  if (ds->target.kind != RAY_TARGET_NONE || ds->target.slab.on) {
    for (int i = 0; i < n; i++) w[i] = distant_sample_ray(s, film_u[i], aperture_u[i], &rays[i]);
    return;
  }
  enum {
    C = 64
  };
  const double(*m)[4] = s->to_world.m;
  double m9[9] = {m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2]};
  double d[3] = {ds->d.x, ds->d.y, ds->d.z}, c[3] = {ds->center.x, ds->center.y, ds->center.z};
  double ap[2 * C], out[3 * C];
  rsw_isa isa = rsw_isa_get();
  for (int i0 = 0; i0 < n; i0 += C) {
    int cnt = n - i0 < C ? n - i0 : C;
    for (int k = 0; k < cnt; k++) ap[2 * k] = aperture_u[i0 + k].x, ap[2 * k + 1] = aperture_u[i0 + k].y;
    disk_origins_batch(isa, cnt, m9, 0, d, 0, ap, c, ds->radius, ds->radius, out);
    for (int k = 0; k < cnt; k++) {
      ray3 *r = &rays[i0 + k];
      r->o = v3(out[3 * k], out[3 * k + 1], out[3 * k + 2]);
      r->d = ds->d;
      r->tmin = 0.0;
      r->tmax = INFINITY;
      w[i0 + k] = 1.0;
    }
  }
}

static rsw_status distant_set_scene(sensor *s, const scene *sc, rsw_err *err) {
  distant *ds = (distant *)s;
  rsw_status st = ray_target_check(&ds->target, s->base.id, err);
  if (st != RSW_OK) return st;
  ray_target_bind(&ds->target, sc, false);
  ds->center = sc->bsphere_center; /* radius already inflated (kernel.h) */
  ds->radius = sc->bsphere_radius;
  return RSW_OK;
}

/* The one pixel sees the radiance leaving along -d. */
static void distant_pixel_angles(const sensor *s, int W, int H, double *zen_az) {
  vec3 w = v3_neg(((const distant *)s)->d);
  for (size_t i = 0; i < (size_t)W * H; i++) direction_angles(w, &zen_az[2 * i], &zen_az[2 * i + 1]);
}

static void distant_pixel_directions(const sensor *s, int W, int H, double *xyz) {
  vec3 w = v3_neg(((const distant *)s)->d);
  for (size_t i = 0; i < (size_t)W * H; i++) xyz[3 * i] = w.x, xyz[3 * i + 1] = w.y, xyz[3 * i + 2] = w.z;
}

static const sensor_ops distant_ops = {
    .sample_ray = distant_sample_ray,
    .set_scene = distant_set_scene,
    .pixel_angles = distant_pixel_angles,
    .pixel_directions = distant_pixel_directions,
    .sample_ray_batch = distant_sample_ray_batch,
};

static void distant_destroy(object *o) {
  if (o) ray_target_release(&((distant *)o)->target);
  free(o);
}

/* Mitsuba's rule for `direction`: look_at(0, normalize(direction), up)
 * with up the second vector of coordinate_system(direction). */
static bool distant_frame(vec3 dir, xform *out) {
  vec3 dn = v3_norm(dir), s_unused, up;
  coordinate_system(dn, &s_unused, &up);
  return xf_look_at(v3(0, 0, 0), dn, up, out);
}

static vec3 distant_get_direction(const object *o) {
  return ((const distant *)o)->d;
}

static void distant_set_direction(object *o, vec3 dir) {
  distant *ds = (distant *)o;
  xform t;
  if (distant_frame(dir, &t)) ds->base.to_world = t;
}

static void distant_parameters_changed(object *o) {
  distant *ds = (distant *)o;
  ds->d = v3_norm(xf_vector(&ds->base.to_world, v3(0, 0, 1)));
}

/* Mitsuba does not expose a distant sensor's transform; we do, with the
 * `direction` convenience key (the direction the sensor looks, into the
 * scene), since viewing angles are what sweeps vary most. Neither is
 * geometric. */
static void distant_traverse(object *o, param_visitor *v) {
  distant *ds = (distant *)o;
  pv_transform(v, "to_world", &ds->base.to_world, UPDATE_SPECTRAL, sensor_check_axis_xf);
  pv_vector(v, "direction", distant_get_direction, distant_set_direction, UPDATE_SPECTRAL);
}

DEFINE_PLUGIN(distant, CLS_SENSOR, .destroy = distant_destroy, .traverse = distant_traverse,
              .parameters_changed = distant_parameters_changed, .ops = &distant_ops);

static rsw_status distant_read(loader *ld, node *n, distant *ds) {
  rsw_status st = sensor_read_base(ld, n, &ds->base);
  if (st != RSW_OK) return st;
  st = sensor_require_1x1_film(ld, n, &ds->base);
  if (st != RSW_OK) return st;

  if (ld_has(n, "direction") && ld_has(n, "to_world"))
    return ld_fail(ld, n, "direction", RSW_ERR_INVALID,
                   "distant: only one of 'direction' and 'to_world' can be given");
  bool has_dir = false;
  vec3 dir = v3(0, 0, 1);
  st = ld_vec3(ld, n, "direction", dir, &dir, &has_dir);
  if (st != RSW_OK) return st;
  if (has_dir) {
    if (!(v3_len(dir) > 0.0))
      return ld_fail(ld, n, "direction", RSW_ERR_INVALID, "distant: 'direction' must not be the zero vector");
    /* Mitsuba: to_world = look_at(0, normalize(direction), up) with up the
     * second vector of coordinate_system(direction). */
    if (!distant_frame(dir, &ds->base.to_world))
      return ld_fail(ld, n, "direction", RSW_ERR_INVALID, "distant: cannot build a frame from 'direction'");
  } else {
    st = ld_transform(ld, n, "to_world", &ds->base.to_world, NULL);
    if (st != RSW_OK) return st;
  }
  /* Mitsuba leaves the direction scaled with to_world; the integrators
   * expect a unit ray direction. */
  vec3 d = xf_vector(&ds->base.to_world, v3(0, 0, 1));
  if (!(v3_len(d) > 0.0) || !v3_finite(d))
    return ld_fail(ld, n, "to_world", RSW_ERR_INVALID, "distant: 'to_world' maps +z to a zero vector");
  ds->d = v3_norm(d);
  return sensor_read_target(ld, n, &ds->target);
}

static rsw_status distant_create(loader *ld, node *n, object **out) {
  distant *ds = PLUGIN_NEW(distant, distant);
  if (!ds) return plugin_created(ld, n, NULL, out);
  ds->base.ops = &distant_ops;
  ds->base.to_world = xf_identity();
  rsw_status st = distant_read(ld, n, ds);
  if (st != RSW_OK) {
    free(ds);
    return st;
  }
  return plugin_created(ld, n, &ds->base.base, out);
}
