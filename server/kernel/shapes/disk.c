/* disk: the unit disk at the origin in z = 0, normal +z
 * (mitsuba3 src/shapes/disk.cpp). Intersected exactly in double precision
 * in object space (Embree user geometry). */
#include <stdlib.h>

#include "../accel_hit.h"
#include "../scene/plugin_def.h"
#include "shape_internal.h"

/* Flat: z in [-0, 0] (accel.c pads it for Embree's box). */
static void disk_bounds(const shape *s, vec3 *lo, vec3 *hi) {
  double z = 0.0;
  *lo = v3(-1, -1, -z), *hi = v3(1, 1, z);
}

static bool disk_intersect(const shape *s, const double o[3], const double d[3], double tnear, double tfar,
                           double *t_out, double n_out[3]) {
  if (d[2] == 0) return false;
  double t = -o[2] / d[2];
  if (!(t > tnear && t < tfar)) return false;
  double x = o[0] + t * d[0], y = o[1] + t * d[1];
  if (x * x + y * y > 1.0) return false;
  *t_out = t;
  n_out[0] = 0, n_out[1] = 0, n_out[2] = 1;
  return true;
}

/* The hit put back in the plane z = 0 in object space; uv = (r, phi / 2pi)
 * as Mitsuba's disk; no dp/du (the shading frame is Mitsuba's
 * coordinate_system(n)). */
static void disk_fill(const shape *s, const xform *to_world, const ray3 *r, const accel_hit *h,
                      surface_interaction *si, vec3 *n, vec3 *sn, vec3 *dpdu) {
  vec3 pw = v3_fma(r->o, h->t, r->d);
  vec3 po = xf_inv_point(to_world, pw);
  po.z = 0;
  si->p = xf_point(to_world, po);
  *n = *sn = v3_norm(xf_normal(to_world, v3(0, 0, 1)));
  double phi = atan2(po.y, po.x);
  if (phi < 0) phi += 2 * RSW_PI;
  si->uv[0] = sqrt(po.x * po.x + po.y * po.y);
  si->uv[1] = phi * RSW_INV_2PI;
}

static void disk_sample(const shape *s, vec2 u, const double *tris, position_sample *ps) {
  vec2 q = warp_square_to_disk_concentric(u);
  ps->p = xf_point(&s->to_world, v3(q.x, q.y, 0));
  ps->n = v3_norm(xf_normal(&s->to_world, v3(0, 0, 1)));
  ps->uv[0] = u.x;
  ps->uv[1] = u.y;
}

static rsw_status disk_finalize(shape *s, rsw_err *err, const char *where) {
  rsw_status tst = shape_check_traceable(s, &s->to_world, "to_world", err, where);
  if (tst) return tst;
  /* Area of the image of the unit disk: pi |ex x ey|, exact for any
   * linear map that keeps it an ellipse. Mitsuba rejects non-uniform
   * scale within the plane only through its sampling; we accept ellipses
   * for intersection but require a similarity within the plane so that
   * uniform sampling stays uniform. */
  vec3 ex = xf_vector(&s->to_world, v3(1, 0, 0));
  vec3 ey = xf_vector(&s->to_world, v3(0, 1, 0));
  double lx = v3_len(ex), ly = v3_len(ey);
  if (!(lx > 0) || !(ly > 0) || fabs(lx - ly) > 1e-6 * (lx + ly) || fabs(v3_dot(ex, ey)) > 1e-6 * lx * ly)
    return rsw_fail(err, RSW_ERR_INVALID, where,
                    "disk: to_world must not shear or scale non-uniformly within the disk's plane");
  s->area = RSW_PI * v3_len(v3_cross(ex, ey));
  return RSW_OK;
}

const shape_ops shape_ops_disk = {.kind = "disk",
                                  .bounds = disk_bounds,
                                  .world_bounds = shape_box_world_bounds,
                                  .intersect = disk_intersect,
                                  .fill = disk_fill,
                                  .sample_position = disk_sample,
                                  .finalize = disk_finalize};

static rsw_status disk_create(loader *ld, node *n, object **out) {
  shape *s = shape_new(&shape_ops_disk);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  rsw_status st = shape_read_common(ld, n, s, false);
  if (st) {
    free(s);
    return st;
  }
  return shape_finish(ld, n, s, out);
}

DEFINE_PLUGIN(disk, CLS_SHAPE, .destroy = shape_destroy, .traverse = shape_traverse,
              .parameters_changed = shape_parameters_changed);
