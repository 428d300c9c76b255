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

#include "shape_common.h"

static rsw_status cylinder_create(loader *ld, node *n, object **out) {
  shape *s = calloc(1, sizeof *s);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  s->geom = GEOM_CYLINDER;
  s->to_world = xf_identity();
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
  *out = &s->base;
  return RSW_OK;
}

const plugin plugin_cylinder = {.name = "cylinder",
                                .cls = CLS_SHAPE,
                                .create = cylinder_create,
                                .destroy = shape_destroy,
                                .traverse = shape_traverse,
                                .parameters_changed = shape_parameters_changed};
