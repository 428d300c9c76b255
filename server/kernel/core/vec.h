/* Double-precision 3-vectors, orthonormal frames and colours.
 * Everything here is header-only and static inline: these are the hot-path
 * building blocks of shading. */
#ifndef RSW_CORE_VEC_H
#define RSW_CORE_VEC_H

#include <math.h>
#include <stdbool.h>

#define RSW_PI      3.14159265358979323846
#define RSW_INV_PI  0.31830988618379067154
#define RSW_INV_2PI 0.15915494309189533577
#define RSW_INV_4PI 0.07957747154594766788

/* The float32 rounding unit 2^-24 (half an ulp at 1): Embree traces in
 * single precision. */
#define RSW_F32_UNIT 5.9604644775390625e-08

/* Mitsuba's RayEpsilon = 1500 * 2^-24 (float epsilon, Embree traces in
 * single precision); ShadowEpsilon = 10 * RayEpsilon.
 * Source: mitsuba3 include/mitsuba/core/math.h. Kept where Mitsuba's
 * semantics use them as constants (bounding-sphere inflation, the
 * radiancemeter's nudge, unit-vector tolerances). Spawned rays do NOT use
 * Mitsuba's (1 + max|p|) RayEpsilon offset, which grows with the distance
 * from the world origin: see spawn_ray in shapes/shape.h. */
#define RSW_RAY_EPSILON    (1500.0 * RSW_F32_UNIT)
#define RSW_SHADOW_EPSILON (10.0 * RSW_RAY_EPSILON)

typedef struct vec3 {
  double x, y, z;
} vec3;

static inline vec3 v3(double x, double y, double z) {
  vec3 r = {x, y, z};
  return r;
}
static inline vec3 v3_add(vec3 a, vec3 b) {
  return v3(a.x + b.x, a.y + b.y, a.z + b.z);
}
static inline vec3 v3_sub(vec3 a, vec3 b) {
  return v3(a.x - b.x, a.y - b.y, a.z - b.z);
}
static inline vec3 v3_mul(vec3 a, vec3 b) {
  return v3(a.x * b.x, a.y * b.y, a.z * b.z);
}
static inline vec3 v3_scale(vec3 a, double s) {
  return v3(a.x * s, a.y * s, a.z * s);
}
static inline vec3 v3_neg(vec3 a) {
  return v3(-a.x, -a.y, -a.z);
}
static inline vec3 v3_fma(vec3 a, double s, vec3 b) { /* a + s*b */
  return v3(a.x + s * b.x, a.y + s * b.y, a.z + s * b.z);
}
static inline double v3_dot(vec3 a, vec3 b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
static inline vec3 v3_cross(vec3 a, vec3 b) {
  return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline double v3_len2(vec3 a) {
  return v3_dot(a, a);
}
static inline double v3_len(vec3 a) {
  return sqrt(v3_dot(a, a));
}
static inline vec3 v3_norm(vec3 a) {
  double l = v3_len(a);
  return l > 0 ? v3_scale(a, 1.0 / l) : a;
}
static inline double v3_max_abs(vec3 a) {
  double m = fabs(a.x);
  if (fabs(a.y) > m) m = fabs(a.y);
  if (fabs(a.z) > m) m = fabs(a.z);
  return m;
}
static inline bool v3_finite(vec3 a) {
  return isfinite(a.x) && isfinite(a.y) && isfinite(a.z);
}

/* Orthonormal basis (s, t, n). */
typedef struct frame {
  vec3 s, t, n;
} frame;

/* Duff et al. 2017 "Building an orthonormal basis, revisited", exactly as
 * Mitsuba's coordinate_system(): s = sign(n.z), a = -1/(s + n.z),
 * b = n.x n.y a; first = (n.x^2 a s + 1, b s, -n.x s),
 * second = (b, s + n.y^2 a, -n.y). For n = +z: (1,0,0), (0,1,0). */
static inline void coordinate_system(vec3 n, vec3 *s_out, vec3 *t_out) {
  double s = copysign(1.0, n.z);
  double a = -1.0 / (s + n.z);
  double b = n.x * n.y * a;
  *s_out = v3(n.x * n.x * a * s + 1.0, b * s, -n.x * s);
  *t_out = v3(b, s + n.y * n.y * a, -n.y);
}

static inline frame frame_from_normal(vec3 n) {
  frame f;
  f.n = n;
  coordinate_system(n, &f.s, &f.t);
  return f;
}
static inline vec3 frame_to_local(const frame *f, vec3 v) {
  return v3(v3_dot(v, f->s), v3_dot(v, f->t), v3_dot(v, f->n));
}
static inline vec3 frame_to_world(const frame *f, vec3 v) {
  return v3_add(v3_add(v3_scale(f->s, v.x), v3_scale(f->t, v.y)), v3_scale(f->n, v.z));
}

/* A colour / spectral value. In the rgb variant the three channels are
 * linear sRGB; in the mono variant all three hold the same value (the
 * quantity at the render's wavelength), so luminance == that value and the
 * same shading code serves both variants. */
typedef struct color {
  double c[3];
} color;

static inline color col(double r, double g, double b) {
  color x = {{r, g, b}};
  return x;
}
static inline color col1(double v) {
  return col(v, v, v);
}
static inline color col_add(color a, color b) {
  return col(a.c[0] + b.c[0], a.c[1] + b.c[1], a.c[2] + b.c[2]);
}
static inline color col_mul(color a, color b) {
  return col(a.c[0] * b.c[0], a.c[1] * b.c[1], a.c[2] * b.c[2]);
}
static inline color col_scale(color a, double s) {
  return col(a.c[0] * s, a.c[1] * s, a.c[2] * s);
}
static inline double col_max(color a) {
  double m = a.c[0];
  if (a.c[1] > m) m = a.c[1];
  if (a.c[2] > m) m = a.c[2];
  return m;
}
static inline bool col_is_black(color a) {
  return a.c[0] == 0.0 && a.c[1] == 0.0 && a.c[2] == 0.0;
}
static inline double col_mean(color a) {
  return (a.c[0] + a.c[1] + a.c[2]) / 3.0;
}
/* Rec. 709 / sRGB luminance weights, as Mitsuba's luminance(). */
static inline double col_luminance(color a) {
  return 0.212671 * a.c[0] + 0.715160 * a.c[1] + 0.072169 * a.c[2];
}

/* A ray: origin, direction (not necessarily unit), [tmin, tmax]. */
typedef struct ray3 {
  vec3 o, d;
  double tmin, tmax;
} ray3;

#endif
