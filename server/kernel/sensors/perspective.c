/* `perspective`: pinhole camera (mitsuba3 src/sensors/perspective.cpp,
 * include/mitsuba/render/sensor.h parse_fov / perspective_projection).
 *
 * Camera frame (to_world, usually look_at): the camera looks along local
 * +z; film x increasing goes towards local -x (image right = -left of
 * look_at), film y increasing (rows going down) towards local -y. With
 * a = W/H and t = tan(fov_x / 2), the film sample s in [0,1)^2 (plus the
 * principal point offset) maps to the camera-space direction
 *   v = ((1 - 2 s.x) t, (1 - 2 s.y) t / a, 1),   d = v / |v|,
 * which is what Mitsuba's camera_to_sample = scale(-1/2, -a/2, 1)
 * translate(-1, -1/a, 0) perspective(fov_x, near, far) inverts to.
 * The ray starts at the camera position and is clipped to the near/far
 * planes: tmin = near_clip / d.z, tmax = far_clip / d.z. Weight 1. */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "../scene/plugin_def.h"
#include "perspective_lanes.h"
#include "sensor_common.h"

typedef struct perspective {
  sensor base;
  double x_fov;          /* horizontal field of view, degrees (key `x_fov`) */
  double tan_half_fov_x; /* tan(fov_x / 2) */
  double aspect;         /* film width / height */
  double near_clip, far_clip;
  double pp_offset_x, pp_offset_y; /* principal point offset (film units) */
} perspective;

static double perspective_sample_ray(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray) {
  (void)aperture_u;
  const perspective *p = (const perspective *)s;
  double sx = film_u.x + p->pp_offset_x, sy = film_u.y + p->pp_offset_y;
  double t = p->tan_half_fov_x;
  vec3 d = v3_norm(v3((1.0 - 2.0 * sx) * t, (1.0 - 2.0 * sy) * t / p->aspect, 1.0));
  /* to_world is a rigid motion (checked in create): d stays unit and the
   * origin is the translation column. */
  ray->o = v3(s->to_world.m[0][3], s->to_world.m[1][3], s->to_world.m[2][3]);
  ray->d = xf_vector(&s->to_world, d);
  double inv_z = 1.0 / d.z;
  ray->tmin = p->near_clip * inv_z;
  ray->tmax = p->far_clip * inv_z;
  return 1.0;
}

/* Batched rays (sensor_ops.sample_ray_batch): perspective_sample_ray()'s
 * operations in double lanes (sensors/perspective_lanes.h,
 * written straight into the rays: 8 doubles each), so bit for bit its
 * rays. */
_Static_assert(sizeof(ray3) == 8 * sizeof(double) && offsetof(ray3, d) == 3 * sizeof(double) &&
                   offsetof(ray3, tmin) == 6 * sizeof(double) && offsetof(ray3, tmax) == 7 * sizeof(double),
               "perspective_rays writes a ray3 as 8 doubles (o, d, tmin, tmax)");
static void perspective_rays_batch(rsw_isa isa, int n, const double (*m)[4], const double *pp, double t,
                                   double aspect, double near_clip, double far_clip, const double *fu,
                                   double *out) {
  SIMD_DISPATCH(isa, perspective_rays, n, m, pp, t, aspect, near_clip, far_clip, fu, out);
}

static void perspective_sample_ray_batch(const sensor *s, int n, const vec2 *film_u, const vec2 *aperture_u,
                                         ray3 *rays, double *w) {
  (void)aperture_u;
  const perspective *p = (const perspective *)s;
  _Static_assert(sizeof(vec2) == 2 * sizeof(double), "film samples are (x, y) pairs of doubles");
  double pp[2] = {p->pp_offset_x, p->pp_offset_y};
  perspective_rays_batch(rsw_isa_get(), n, (const double(*)[4])s->to_world.m, pp, p->tan_half_fov_x,
                         p->aspect, p->near_clip, p->far_clip, (const double *)film_u, (double *)rays);
  for (int i = 0; i < n; i++) w[i] = 1.0;
}

static rsw_status perspective_set_scene(sensor *s, const scene *sc, rsw_err *err) {
  (void)s;
  (void)sc;
  (void)err;
  return RSW_OK;
}

static const sensor_ops perspective_ops = {
    .sample_ray = perspective_sample_ray,
    .set_scene = perspective_set_scene,
    .sample_ray_batch = perspective_sample_ray_batch,
};

/* The camera transform must stay a rigid motion (as checked at load). */
static rsw_status perspective_check_xf(const object *o, const xform *t, const char *key, rsw_err *err) {
  (void)o;
  double scale;
  if (!xf_is_similarity(t, &scale) || fabs(scale - 1.0) > 1e-4)
    return rsw_fail(err, RSW_ERR_INVALID, key,
                    "'%s': a perspective camera's to_world must be a rotation and translation", key);
  return RSW_OK;
}

#define DEG2RAD (RSW_PI / 180.0)

/* Mitsuba's keys: to_world and x_fov (degrees, in (0, 180)). */
static void perspective_traverse(object *o, param_visitor *v) {
  pv_transform(v, "to_world", &((sensor *)o)->to_world, UPDATE_SPECTRAL, perspective_check_xf);
  pv_float(v, "x_fov", &((perspective *)o)->x_fov, UPDATE_SPECTRAL, X_FOV_MIN, X_FOV_MAX);
}

static void perspective_parameters_changed(object *o) {
  perspective *p = (perspective *)o;
  p->tan_half_fov_x = tan(0.5 * p->x_fov * DEG2RAD);
}

DEFINE_PLUGIN(perspective, CLS_SENSOR, .traverse = perspective_traverse,
              .parameters_changed = perspective_parameters_changed, .ops = &perspective_ops);

/* Focal length of a 35 mm film camera: "50mm", "50" or a number (mm). */
static rsw_status read_focal_length(loader *ld, node *n, double *mm) {
  prop *p = node_find(n, "focal_length");
  if (p && p->kind == PROP_NUMBER) return ld_float(ld, n, "focal_length", 50.0, mm);
  const char *str = NULL;
  rsw_status st = ld_string(ld, n, "focal_length", "50mm", &str);
  if (st != RSW_OK) return st;
  char buf[64];
  size_t len = strlen(str);
  if (len >= 2 && strcasecmp(str + len - 2, "mm") == 0) len -= 2;
  char *end = NULL;
  double v = 0;
  if (len > 0 && len < sizeof buf) {
    memcpy(buf, str, len);
    buf[len] = '\0';
    v = strtod(buf, &end);
  }
  if (!end || *end != '\0' || end == buf || !(v > 0.0) || !isfinite(v))
    return ld_fail(ld, n, "focal_length", RSW_ERR_INVALID,
                   "perspective: cannot parse the focal length '%s' (expected <x>mm, x > 0)", str);
  *mm = v;
  return RSW_OK;
}

/* Horizontal field of view in degrees from fov / fov_axis / focal_length
 * (mitsuba3 parse_fov):
 *  - fov and focal_length are exclusive;
 *  - fov with fov_axis x (default), y, diagonal, smaller, larger
 *    (smaller/larger pick y or x by the aspect a = W/H);
 *  - otherwise focal_length f (default 50mm) on a 36 x 24 mm film:
 *    fov = 2 atan(sqrt(36^2 + 24^2) / (2 f)) along the diagonal;
 *  - axis y:        fov_x = 2 atan(tan(fov/2) a)
 *    axis diagonal: w = 2 tan(fov/2) / sqrt(1 + 1/a^2), fov_x = 2 atan(w/2);
 *  - the result must lie in (0, 180). */
rsw_status perspective_parse_fov(loader *ld, node *n, double aspect, double *fov_x) {
  if (ld_has(n, "fov") && ld_has(n, "focal_length"))
    return ld_fail(ld, n, "fov", RSW_ERR_INVALID,
                   "perspective: give either a focal length ('focal_length') or a "
                   "field of view ('fov'), not both");
  double fov = 0;
  const char *axis = "x";
  rsw_status st;
  if (ld_has(n, "fov")) {
    st = ld_float(ld, n, "fov", 0.0, &fov);
    if (st != RSW_OK) return st;
    st = ld_string(ld, n, "fov_axis", "x", &axis);
    if (st != RSW_OK) return st;
    if (strcasecmp(axis, "smaller") == 0)
      axis = aspect > 1 ? "y" : "x";
    else if (strcasecmp(axis, "larger") == 0)
      axis = aspect > 1 ? "x" : "y";
  } else {
    double f = 50.0;
    st = read_focal_length(ld, n, &f);
    if (st != RSW_OK) return st;
    fov = 2.0 * atan(sqrt(36.0 * 36.0 + 24.0 * 24.0) / (2.0 * f)) / DEG2RAD;
    /* Mitsuba does not read fov_axis here: given alone it is left unused,
     * which the builder reports. */
    axis = "diagonal";
  }
  double result;
  if (strcasecmp(axis, "x") == 0) {
    result = fov;
  } else if (strcasecmp(axis, "y") == 0) {
    result = 2.0 * atan(tan(0.5 * fov * DEG2RAD) * aspect) / DEG2RAD;
  } else if (strcasecmp(axis, "diagonal") == 0) {
    double diagonal = 2.0 * tan(0.5 * fov * DEG2RAD);
    double width = diagonal / sqrt(1.0 + 1.0 / (aspect * aspect));
    result = 2.0 * atan(0.5 * width) / DEG2RAD;
  } else {
    return ld_fail(ld, n, "fov_axis", RSW_ERR_INVALID,
                   "perspective: 'fov_axis' must be one of 'smaller', 'larger', "
                   "'diagonal', 'x' or 'y' (got '%s')",
                   axis);
  }
  if (!(result > 0.0 && result < 180.0))
    return ld_fail(ld, n, ld_has(n, "fov") ? "fov" : "focal_length", RSW_ERR_RANGE,
                   "perspective: the horizontal field of view must lie in (0, 180) "
                   "degrees (got %g)",
                   result);
  *fov_x = result;
  return RSW_OK;
}

static rsw_status perspective_read(loader *ld, node *n, perspective *p) {
  rsw_status st = sensor_read_base(ld, n, &p->base);
  if (st != RSW_OK) return st;
  p->aspect = (double)p->base.film->width / (double)p->base.film->height;

  double fov_x = 0;
  st = perspective_parse_fov(ld, n, p->aspect, &fov_x);
  if (st != RSW_OK) return st;
  p->x_fov = fov_x;
  p->tan_half_fov_x = tan(0.5 * fov_x * DEG2RAD);

  st = ld_transform(ld, n, "to_world", &p->base.to_world, NULL);
  if (st != RSW_OK) return st;
  /* Mitsuba: "Scale factors in the camera-to-world transformation are not
   * allowed!" */
  double scale = 0;
  if (!xf_is_similarity(&p->base.to_world, &scale) || fabs(scale - 1.0) > 1e-4)
    return ld_fail(ld, n, "to_world", RSW_ERR_INVALID,
                   "perspective: scale factors in 'to_world' are not allowed");

  /* ProjectiveCamera: near_clip 1e-2, far_clip 1e4, focus_distance
   * (default far_clip; no effect on a pinhole camera). */
  st = ld_float(ld, n, "near_clip", 1e-2, &p->near_clip);
  if (st == RSW_OK) st = ld_float(ld, n, "far_clip", 1e4, &p->far_clip);
  if (st != RSW_OK) return st;
  if (!(p->near_clip > 0.0))
    return ld_fail(ld, n, "near_clip", RSW_ERR_RANGE, "perspective: 'near_clip' must be greater than zero");
  if (!(p->near_clip < p->far_clip))
    return ld_fail(ld, n, "near_clip", RSW_ERR_RANGE,
                   "perspective: 'near_clip' must be smaller than 'far_clip'");
  double focus = 0;
  st = ld_float(ld, n, "focus_distance", p->far_clip, &focus);
  if (st == RSW_OK) st = ld_float(ld, n, "principal_point_offset_x", 0.0, &p->pp_offset_x);
  if (st == RSW_OK) st = ld_float(ld, n, "principal_point_offset_y", 0.0, &p->pp_offset_y);
  return st;
}

static rsw_status perspective_create(loader *ld, node *n, object **out) {
  perspective *p = PLUGIN_NEW(perspective, perspective);
  if (!p) return plugin_created(ld, n, NULL, out);
  p->base.ops = &perspective_ops;
  p->base.to_world = xf_identity();
  rsw_status st = perspective_read(ld, n, p);
  if (st != RSW_OK) {
    free(p);
    return st;
  }
  return plugin_created(ld, n, &p->base.base, out);
}
