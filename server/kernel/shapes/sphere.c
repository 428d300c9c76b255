/* sphere: the unit sphere at the origin, normals outward; `center` and
 * `radius` fold into to_world as to_world * T(center) * S(radius)
 * (mitsuba3 src/shapes/sphere.cpp). Intersected exactly in double
 * precision in object space (Embree user geometry). */
#include <stdlib.h>

#include "../accel_hit.h"
#include "../scene/plugin_def.h"
#include "shape_internal.h"

static void sphere_bounds(const shape *s, vec3 *lo, vec3 *hi) {
  *lo = v3(-1, -1, -1), *hi = v3(1, 1, 1);
}

/* |o + t d|^2 = 1: a t^2 + 2 b t + c = 0, solved stably; the nearer root
 * in (tnear, tfar), else the farther. */
static bool sphere_intersect(const shape *s, const double o[3], const double d[3], double tnear, double tfar,
                             double *t_out, double n_out[3]) {
  double a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  double b = o[0] * d[0] + o[1] * d[1] + o[2] * d[2];
  double c = o[0] * o[0] + o[1] * o[1] + o[2] * o[2] - 1.0;
  double disc = b * b - a * c;
  if (disc < 0 || a == 0) return false;
  double sq = sqrt(disc);
  double q = b < 0 ? -b + sq : -b - sq; /* q = -(b + sign(b) sq) */
  double t0 = q / a, t1 = q != 0 ? c / q : t0;
  if (t0 > t1) {
    double tmp = t0;
    t0 = t1;
    t1 = tmp;
  }
  double t = t0 > tnear ? t0 : t1;
  if (!(t > tnear && t < tfar)) return false;
  *t_out = t;
  for (int i = 0; i < 3; i++) n_out[i] = o[i] + t * d[i];
  return true;
}

/* The hit projected onto the unit sphere in object space (removes the
 * float error of the intersection). uv = (phi / 2pi, theta / pi) as
 * Mitsuba's sphere. */
static void sphere_fill(const shape *s, const xform *to_world, const ray3 *r, const accel_hit *h,
                        surface_interaction *si, vec3 *n, vec3 *sn, vec3 *dpdu) {
  vec3 pw = v3_fma(r->o, h->t, r->d);
  vec3 po = v3_norm(xf_inv_point(to_world, pw));
  si->p = xf_point(to_world, po);
  *n = *sn = v3_norm(xf_normal(to_world, po));
  double phi = atan2(po.y, po.x);
  if (phi < 0) phi += 2 * RSW_PI;
  si->uv[0] = phi * RSW_INV_2PI;
  si->uv[1] = acos(fmax(-1.0, fmin(1.0, po.z))) * RSW_INV_PI;
  *dpdu = xf_vector(to_world, v3(-po.y, po.x, 0));
}

static void sphere_sample(const shape *s, vec2 u, const double *tris, position_sample *ps) {
  vec3 d = warp_square_to_uniform_sphere(u);
  ps->p = xf_point(&s->to_world, d);
  ps->n = v3_norm(xf_normal(&s->to_world, d));
  ps->uv[0] = u.x;
  ps->uv[1] = u.y;
}

static rsw_status sphere_finalize(shape *s, rsw_err *err, const char *where) {
  rsw_status tst = shape_check_traceable(s, &s->to_world, "to_world", err, where);
  if (tst) return tst;
  double r;
  if (!xf_is_similarity(&s->to_world, &r))
    return rsw_fail(err, RSW_ERR_INVALID, where,
                    "sphere: to_world must be a rotation, uniform scale and translation (no shear or "
                    "non-uniform scale)");
  s->area = 4.0 * RSW_PI * r * r;
  return RSW_OK;
}

const shape_ops shape_ops_sphere = {.kind = "sphere",
                                    .bounds = sphere_bounds,
                                    .world_bounds = shape_box_world_bounds,
                                    .intersect = sphere_intersect,
                                    .fill = sphere_fill,
                                    .sample_position = sphere_sample,
                                    .finalize = sphere_finalize};

static rsw_status sphere_create(loader *ld, node *n, object **out) {
  shape *s = shape_new(&shape_ops_sphere);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  vec3 c;
  double r;
  rsw_status st = shape_read_common(ld, n, s, false);
  if (!st) st = ld_vec3(ld, n, "center", v3(0, 0, 0), &c, NULL);
  if (!st) st = ld_float(ld, n, "radius", 1.0, &r);
  if (!st && !(r > 0)) st = ld_fail(ld, n, "radius", RSW_ERR_RANGE, "radius must be > 0 (got %g)", r);
  if (!st && !(r >= RSW_TRACE_MIN_SCALE && r <= RSW_TRACE_MAX_SCALE))
    st = ld_fail(ld, n, "radius", RSW_ERR_RANGE,
                 "radius %g is outside [%g, %g], what float32 tracing can represent", r, RSW_TRACE_MIN_SCALE,
                 RSW_TRACE_MAX_SCALE);
  if (!st && !(v3_max_abs(c) <= RSW_TRACE_MAX_COORD))
    st = ld_fail(ld, n, "center", RSW_ERR_RANGE,
                 "center coordinate %g exceeds %g, the largest float32 tracing accepts", v3_max_abs(c),
                 RSW_TRACE_MAX_COORD);
  if (st) {
    free(s);
    return st;
  }
  xform t = xf_translate(c), sc = xf_scale(v3(r, r, r));
  xform ts = xf_mul(&t, &sc);
  s->to_world = xf_mul(&s->to_world, &ts);
  return shape_finish(ld, n, s, out);
}

DEFINE_PLUGIN(sphere, CLS_SHAPE, .destroy = shape_destroy, .traverse = shape_traverse,
              .parameters_changed = shape_parameters_changed);
