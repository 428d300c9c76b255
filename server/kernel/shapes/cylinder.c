/* cylinder: an open tube without caps (mitsuba3 src/shapes/cylinder.cpp).
 *
 * Properties as Mitsuba's: `p0` ((0, 0, 0)) and `p1` ((0, 0, 1)), the ends
 * of the axis; `radius` (1); `flip_normals` (false: normals point away
 * from the axis); `to_world`. Mitsuba builds
 *
 *     to_world * T(p0) * to_frame(Frame(d / |d|)) * S(radius, radius, |d|),
 *     d = p1 - p0,
 *
 * where to_frame's columns are coordinate_system(d / |d|) and the axis
 * itself; we keep that composite as the shape's to_world, so the object
 * space is the unit tube x^2 + y^2 = 1, 0 <= z <= 1 (as the sphere here
 * keeps center and radius folded into its to_world). Mitsuba strips the
 * scale again and keeps radius and length apart, so its *exposed*
 * to_world is rigid; ours is the composite, which reads back and writes
 * back unchanged. Writing a to_world means the same in both: its x (= y)
 * scale is the radius and its z scale the length.
 *
 * Geometry (object space, p(u, v) = (cos 2 pi u, sin 2 pi u, v)):
 *   uv = (phi / 2 pi, z), phi = atan2(y, x) in [0, 2 pi)   (Mitsuba's)
 *   n  = (x, y, 0) outward = dp/du x dp/dv
 *   area = 2 pi r L  (r = |A e_x| = |A e_y|, L = |A e_z|, A the linear part
 *          of to_world, which must keep the tube circular and right:
 *          checked in shape_finalize)
 *   sampling: u -> (cos 2 pi u.y, sin 2 pi u.y, u.x), uniform in area
 *          (dA = r L dphi dz is constant in (phi, z)), pdf = 1 / area. */
#include <stdlib.h>
#include <string.h>

#include "../accel_hit.h"
#include "../scene/plugin_def.h"
#include "shape_internal.h"

static void cylinder_bounds(const shape *s, vec3 *lo, vec3 *hi) {
  *lo = v3(-1, -1, 0), *hi = v3(1, 1, 1); /* the unit tube, 0 <= z <= 1 */
}

/* The two end circles bound the tube: centre c, axes a = A e_x and
 * b = A e_y, so coordinate k spans c_k +- sqrt(a_k^2 + b_k^2). */
static void cylinder_world_bounds(const shape *s, const xform *t, vec3 *lo, vec3 *hi) {
  vec3 a = xf_vector(t, v3(1, 0, 0)), b = xf_vector(t, v3(0, 1, 0));
  vec3 x = v3(sqrt(a.x * a.x + b.x * b.x), sqrt(a.y * a.y + b.y * b.y), sqrt(a.z * a.z + b.z * b.z));
  for (int e = 0; e < 2; e++) {
    vec3 c = xf_point(t, v3(0, 0, e));
    shape_box_add(lo, hi, v3_sub(c, x));
    shape_box_add(lo, hi, v3_add(c, x));
  }
}

/* Unit tube x^2 + y^2 = 1, 0 <= z <= 1 (open, no caps): the nearer root
 * within (tnear, tfar) whose z lies on the tube, else the farther one
 * (mitsuba3 src/shapes/cylinder.cpp). A ray parallel to the axis never
 * meets the open tube. */
static bool cylinder_intersect(const shape *s, const double o[3], const double d[3], double tnear,
                               double tfar, double *t_out, double n_out[3]) {
  double a = d[0] * d[0] + d[1] * d[1];
  double b = o[0] * d[0] + o[1] * d[1];
  double c = o[0] * o[0] + o[1] * o[1] - 1.0;
  double disc = b * b - a * c;
  if (!(a > 0) || disc < 0) return false;
  double sq = sqrt(disc);
  double q = b < 0 ? -b + sq : -b - sq;
  double t0 = q / a, t1 = q != 0 ? c / q : t0;
  if (t0 > t1) {
    double tmp = t0;
    t0 = t1;
    t1 = tmp;
  }
  for (int k = 0; k < 2; k++) {
    double t = k ? t1 : t0;
    if (!(t > tnear && t < tfar)) continue;
    double z = o[2] + t * d[2];
    if (!(z >= 0.0 && z <= 1.0)) continue;
    *t_out = t;
    n_out[0] = o[0] + t * d[0], n_out[1] = o[1] + t * d[1], n_out[2] = 0;
    return true;
  }
  return false;
}

/* Back onto the unit tube in object space (removes the float error of
 * the intersection, like Mitsuba's normal shift). uv = (phi / 2pi, z)
 * and dp/du along (-y, x, 0), as Mitsuba's cylinder. */
static void cylinder_fill(const shape *s, const xform *to_world, const ray3 *r, const accel_hit *h,
                          surface_interaction *si, vec3 *n, vec3 *sn, vec3 *dpdu) {
  vec3 pw = v3_fma(r->o, h->t, r->d);
  vec3 po = xf_inv_point(to_world, pw);
  double rr = sqrt(po.x * po.x + po.y * po.y);
  if (rr > 0)
    po.x /= rr, po.y /= rr;
  else
    po.x = 1, po.y = 0;
  po.z = fmin(1.0, fmax(0.0, po.z));
  si->p = xf_point(to_world, po);
  *n = *sn = v3_norm(xf_normal(to_world, v3(po.x, po.y, 0)));
  double phi = atan2(po.y, po.x);
  if (phi < 0) phi += 2 * RSW_PI;
  si->uv[0] = phi * RSW_INV_2PI;
  si->uv[1] = po.z;
  *dpdu = xf_vector(to_world, v3(-po.y, po.x, 0));
}

static void cylinder_sample(const shape *s, vec2 u, const double *tris, position_sample *ps) {
  double phi = 2.0 * RSW_PI * u.y;
  double c = cos(phi), sn = sin(phi);
  ps->p = xf_point(&s->to_world, v3(c, sn, u.x));
  ps->n = v3_norm(xf_normal(&s->to_world, v3(c, sn, 0)));
  ps->uv[0] = u.y;
  ps->uv[1] = u.x;
}

static rsw_status cylinder_finalize(shape *s, rsw_err *err, const char *where) {
  rsw_status tst = shape_check_traceable(s, &s->to_world, "to_world", err, where);
  if (tst) return tst;
  /* Uniform (phi, z) sampling is uniform in area only on a circular,
   * right tube: to_world's x and y columns of equal length, all three
   * orthogonal (Mitsuba warns and drops the shear; we refuse it). */
  vec3 ex = xf_vector(&s->to_world, v3(1, 0, 0));
  vec3 ey = xf_vector(&s->to_world, v3(0, 1, 0));
  vec3 ez = xf_vector(&s->to_world, v3(0, 0, 1));
  double lx = v3_len(ex), ly = v3_len(ey), lz = v3_len(ez);
  if (!(lx > 0) || !(ly > 0) || !(lz > 0) || fabs(lx - ly) > 1e-6 * (lx + ly) ||
      fabs(v3_dot(ex, ey)) > 1e-6 * lx * ly || fabs(v3_dot(ex, ez)) > 1e-6 * lx * lz ||
      fabs(v3_dot(ey, ez)) > 1e-6 * ly * lz)
    return rsw_fail(err, RSW_ERR_INVALID, where,
                    "cylinder: to_world must keep the tube circular and right (no shear, the same "
                    "scale across the axis)");
  s->area = 2.0 * RSW_PI * 0.5 * (lx + ly) * lz;
  return RSW_OK;
}

const shape_ops shape_ops_cylinder = {.kind = "cylinder",
                                      .bounds = cylinder_bounds,
                                      .world_bounds = cylinder_world_bounds,
                                      .intersect = cylinder_intersect,
                                      .fill = cylinder_fill,
                                      .sample_position = cylinder_sample,
                                      .finalize = cylinder_finalize};

static rsw_status cylinder_create(loader *ld, node *n, object **out) {
  shape *s = shape_new(&shape_ops_cylinder);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  vec3 p0, p1;
  double r;
  rsw_status st = shape_read_common(ld, n, s, false);
  if (!st) st = ld_vec3(ld, n, "p0", v3(0, 0, 0), &p0, NULL);
  if (!st) st = ld_vec3(ld, n, "p1", v3(0, 0, 1), &p1, NULL);
  if (!st) st = ld_float(ld, n, "radius", 1.0, &r);
  if (!st && !(r > 0)) st = ld_fail(ld, n, "radius", RSW_ERR_RANGE, "radius must be > 0 (got %g)", r);
  if (!st && !(r >= RSW_TRACE_MIN_SCALE && r <= RSW_TRACE_MAX_SCALE))
    st = ld_fail(ld, n, "radius", RSW_ERR_RANGE,
                 "radius %g is outside [%g, %g], what float32 tracing can represent", r, RSW_TRACE_MIN_SCALE,
                 RSW_TRACE_MAX_SCALE);
  vec3 d = v3_sub(p1, p0);
  double len = v3_len(d);
  if (!st && !(len > 0))
    st = ld_fail(ld, n, ld_has(n, "p1") ? "p1" : "p0", RSW_ERR_INVALID,
                 "p0 and p1 must differ: the cylinder's axis has zero length");
  if (!st && !isfinite(len))
    st = ld_fail(ld, n, "p1", RSW_ERR_INVALID, "the cylinder's axis length is not finite");
  if (st) {
    free(s);
    return st;
  }
  frame f = frame_from_normal(v3_scale(d, 1.0 / len));
  const double m[4][4] = {{r * f.s.x, r * f.t.x, len * f.n.x, p0.x},
                          {r * f.s.y, r * f.t.y, len * f.n.y, p0.y},
                          {r * f.s.z, r * f.t.z, len * f.n.z, p0.z},
                          {0, 0, 0, 1}};
  xform local;
  if (!xf_from_matrix(m, &local)) {
    free(s);
    return ld_fail(ld, n, "radius", RSW_ERR_INVALID, "radius and axis give a singular transform");
  }
  s->to_world = xf_mul(&s->to_world, &local);
  st = shape_finalize(s, ld->err, n->loc);
  if (st) {
    free(s);
    return st;
  }
  return plugin_created(ld, n, &s->base, out);
}

DEFINE_PLUGIN(cylinder, CLS_SHAPE, .destroy = shape_destroy, .traverse = shape_traverse,
              .parameters_changed = shape_parameters_changed);
