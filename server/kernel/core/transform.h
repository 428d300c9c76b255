/* 4x4 affine/projective transforms, stored with their inverse.
 * Names read target_from_source; xf_mul(a, b) applies b first, then a. */
#ifndef RSW_CORE_TRANSFORM_H
#define RSW_CORE_TRANSFORM_H

#include "vec.h"
#include <stdbool.h>

typedef struct xform {
  double m[4][4]; /* row-major: p' = m p (column vectors) */
  double inv[4][4];
} xform;

xform xf_identity(void);
/* Build from a row-major matrix. Returns false when it is singular or not
 * finite (the inverse cannot be formed). */
bool xf_from_matrix(const double m[4][4], xform *out);
xform xf_mul(const xform *a, const xform *b); /* a * b */
xform xf_inverse(const xform *a);
xform xf_translate(vec3 t);
xform xf_scale(vec3 s);                       /* caller checks no zero factor */
xform xf_rotate(vec3 axis, double angle_deg); /* counter-clockwise, as Mitsuba */
/* Mitsuba's look_at: columns (left, new_up, dir, origin) with
 * dir = normalize(target - origin), left = normalize(cross(up, dir)),
 * new_up = cross(dir, left). Returns false when degenerate. */
bool xf_look_at(vec3 origin, vec3 target, vec3 up, xform *out);

/* Applying a transform: inline, as every sample and hit does it several
 * times (the same arithmetic as a call, so the same bits). */
static inline vec3 mat_point(const double (*m)[4], vec3 p) {
  double x = m[0][0] * p.x + m[0][1] * p.y + m[0][2] * p.z + m[0][3];
  double y = m[1][0] * p.x + m[1][1] * p.y + m[1][2] * p.z + m[1][3];
  double z = m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3];
  double w = m[3][0] * p.x + m[3][1] * p.y + m[3][2] * p.z + m[3][3];
  if (w != 1.0) return v3(x / w, y / w, z / w);
  return v3(x, y, z);
}
static inline vec3 mat_vector(const double (*m)[4], vec3 v) {
  return v3(m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z, m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
            m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z);
}
static inline vec3 xf_point(const xform *t, vec3 p) {
  return mat_point(t->m, p);
}
static inline vec3 xf_vector(const xform *t, vec3 v) {
  return mat_vector(t->m, v);
}
/* Inverse transpose, not normalised. */
static inline vec3 xf_normal(const xform *t, vec3 n) {
  const double(*m)[4] = t->inv;
  return v3(m[0][0] * n.x + m[1][0] * n.y + m[2][0] * n.z, m[0][1] * n.x + m[1][1] * n.y + m[2][1] * n.z,
            m[0][2] * n.x + m[1][2] * n.y + m[2][2] * n.z);
}
/* By the stored inverse (the same bits as xf_point of xf_inverse(t)). */
static inline vec3 xf_inv_point(const xform *t, vec3 p) {
  return mat_point(t->inv, p);
}
static inline vec3 xf_inv_vector(const xform *t, vec3 v) {
  return mat_vector(t->inv, v);
}
bool xf_is_identity(const xform *t);
/* True when the upper 3x3 is a rotation times a uniform scale (within a
 * relative tolerance); *scale gets that scale. */
bool xf_is_similarity(const xform *t, double *scale);

/* ---- what float32 tracing can represent ----------------------------------------
 * Embree traces in single precision and asserts (aborts the process) on a
 * ray whose origin or direction has a coordinate beyond FLT_LARGE =
 * 1.844e18 (embree common/sys/platform.h; RayK<1>::valid()), and drops
 * geometry beyond it. Every instance transform (A, t) maps the ray into
 * object space as A^-1 (o - t), A^-1 d, in float, so a tiny scale turns an
 * ordinary ray into an invalid one (a scale of 1e-20 makes a unit direction
 * 1e20 long), and a projective matrix, which Embree cannot express, is
 * silently cut down to its affine part. A shape's to_world (and an
 * instance placement) is therefore held to these limits, at load, at
 * PATCH and at per-render override time; accel.c checks the exact
 * condition for the whole scene once more before any commit.
 *
 * The limits leave the realistic range of radiative-transfer scenes (a
 * 1 um detail, a 1,000,000 km extent) inside and keep every float Embree
 * computes orders of magnitude below FLT_LARGE: with world coordinates
 * below RSW_TRACE_MAX_COORD and scales above RSW_TRACE_MIN_SCALE, an
 * object-space ray coordinate stays below about 1e16. */
#define RSW_TRACE_MAX_COORD 1e9  /* |world|, |object| coordinates, |translation| */
#define RSW_TRACE_MIN_SCALE 1e-6 /* smallest scale of a linear part */
#define RSW_TRACE_MAX_SCALE 1e9  /* largest scale of a linear part */
/* Largest condition number (largest over smallest scale) of a nearly
 * singular matrix: beyond it the float inverse Embree forms can be off by
 * more than half the smallest dimension (2^-24 times 1e7 = 0.6). */
#define RSW_TRACE_MAX_COND  1e7

/* Check the 4x4 row-major matrix m as a shape's to_world for float32
 * tracing: finite, affine (last row exactly 0 0 0 1), translation within
 * RSW_TRACE_MAX_COORD, the linear part's scales within [MIN_SCALE,
 * MAX_SCALE] and its condition within MAX_COND (scales estimated from
 * Frobenius norms: sqrt(3)/|A^-1|_F and |A|_F/sqrt(3), exact for a rotation
 * times a uniform scale). On failure writes a message that starts with
 * `what` (the key or property name) into buf and returns false. */
bool xf_traceable(const double m[4][4], const char *what, char *buf, unsigned long len);

#endif
