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

vec3 xf_point(const xform *t, vec3 p);
vec3 xf_vector(const xform *t, vec3 v);
vec3 xf_normal(const xform *t, vec3 n); /* inverse transpose, not normalised */
vec3 xf_inv_point(const xform *t, vec3 p);
vec3 xf_inv_vector(const xform *t, vec3 v);
bool xf_is_identity(const xform *t);
/* True when the upper 3x3 is a rotation times a uniform scale (within a
 * relative tolerance); *scale gets that scale. */
bool xf_is_similarity(const xform *t, double *scale);

#endif
