/* Warps from the unit square to disks, hemispheres, spheres and cones, as
 * sample / pdf / inverse triplets. Formulas follow Mitsuba 3's
 * include/mitsuba/core/warp.h (docs/kernel-conventions.md#warps); the pdfs are
 * Mitsuba's "checking" variants (TestDomain = true): they return 0 for a
 * point outside the warp's domain, so a chi-square test can detect a
 * sampler that leaves it. */
#include "warp.h"

#include <math.h>

/* Directions are accepted as unit when | |v|^2 - 1 | <= RayEpsilon, the
 * tolerance Mitsuba's checking pdfs use. */
static int off_unit_sphere(vec3 v) {
  return !(fabs(v3_len2(v) - 1.0) <= RSW_RAY_EPSILON);
}

/* atan2(y, x) / (2 pi) wrapped into [0, 1). */
static double angle_fraction(double y, double x) {
  double t = atan2(y, x) * RSW_INV_2PI;
  if (t < 0.0) t += 1.0;
  return t < 1.0 ? t : 0.0;
}

/* sin and cos of (pi/4) t for t in [-1, 1], in double precision: Taylor
 * polynomials in x^2 up to x^15 (sin) and x^16 (cos), whose first omitted
 * terms at |x| = pi/4 are 5e-17 and 2e-18, below half an ulp of the
 * results (tested against libm to 2 ulp, tests/kernel/core/test_warp.c). Cheaper
 * than libm's sincos (no range reduction, no call) and as accurate, so the
 * warps keep double precision everywhere: a float angle would move
 * directions near the poles by ~1e-7 rad relative to their tiny radius,
 * and the hemisphere pdfs and their inverses are tested in double. */
static inline void sincos_quarter(double t, double *s, double *c) {
  double x = 0.78539816339744830962 * t, x2 = x * x;
  double ps = -1.0 / 1307674368000.0;
  ps = 1.0 / 6227020800.0 + ps * x2;
  ps = -1.0 / 39916800.0 + ps * x2;
  ps = 1.0 / 362880.0 + ps * x2;
  ps = -1.0 / 5040.0 + ps * x2;
  ps = 1.0 / 120.0 + ps * x2;
  ps = -1.0 / 6.0 + ps * x2;
  double pc = 1.0 / 20922789888000.0;
  pc = -1.0 / 87178291200.0 + pc * x2;
  pc = 1.0 / 479001600.0 + pc * x2;
  pc = -1.0 / 3628800.0 + pc * x2;
  pc = 1.0 / 40320.0 + pc * x2;
  pc = -1.0 / 720.0 + pc * x2;
  pc = 1.0 / 24.0 + pc * x2;
  pc = -0.5 + pc * x2;
  *s = x + x * x2 * ps;
  *c = 1.0 + x2 * pc;
}

/* sin and cos of 2 pi u for u in [0, 1]: the nearest quarter turn q is
 * taken out exactly (4u - q is exact), the rest is +-pi/4 at most. */
static inline void sincos_2pi(double u, double *s, double *c) {
  double q = floor(4.0 * u + 0.5);
  double ss, cc;
  sincos_quarter(2.0 * (4.0 * u - q), &ss, &cc);
  /* A NaN u gives NaN below; the cast must not see it (undefined). */
  switch (q >= 0.0 && q <= 4.0 ? (int)q & 3 : 0) {
  case 0: *s = ss, *c = cc; break;
  case 1: *s = cc, *c = -ss; break;
  case 2: *s = -ss, *c = -cc; break;
  default: *s = -cc, *c = ss; break;
  }
}

/* --- planar ------------------------------------------------------------ */

/* Shirley & Chiu 1997, "A low distortion map between disk and square", in
 * Mitsuba's branch-reduced form (square_to_uniform_disk_concentric):
 *   a = 2 u.x - 1, b = 2 u.y - 1;
 *   |a| < |b|: r = b, phi = pi/2 - (pi/4)(a/b);  else r = a, phi = (pi/4)(b/a)
 *   p = (r cos phi, r sin phi)   (negative r rotates the point by pi).
 * Area is preserved up to the factor pi/4: pdf 1/pi on the unit disk. */
vec2 warp_square_to_disk_concentric(vec2 u) {
  double a = 2.0 * u.x - 1.0, b = 2.0 * u.y - 1.0;
  if (a == 0.0 && b == 0.0) return v2(0.0, 0.0);
  /* cos and sin of pi/2 - (pi/4) t are sin and cos of (pi/4) t. */
  double s, c;
  if (fabs(a) < fabs(b)) {
    sincos_quarter(a / b, &s, &c);
    return v2(b * s, b * c);
  }
  sincos_quarter(b / a, &s, &c);
  return v2(a * c, a * s);
}

/* Inverse of the above (Mitsuba's uniform_disk_to_square_concentric):
 *   m = |x| > |y|, rs = m ? x : y, r = copysign(|p|, rs),
 *   phi = atan2(y sgn rs, x sgn rs) in [-pi/4, pi/4] or [pi/4, 3pi/4],
 *   t = (4/pi) phi, t = (m ? t : 2 - t) r,
 *   (a, b) = m ? (r, t) : (t, r), u = ((a + 1)/2, (b + 1)/2),
 * with sgn(0) = +1. */
vec2 warp_disk_to_square_concentric(vec2 p) {
  int m = fabs(p.x) > fabs(p.y);
  double rs = m ? p.x : p.y;
  double sgn = copysign(1.0, rs);
  /* copysign of a signed zero would give -1 for -0.0: treat 0 as +. */
  if (rs == 0.0) sgn = 1.0;
  double r = sgn * sqrt(p.x * p.x + p.y * p.y);
  double phi = atan2(p.y * sgn, p.x * sgn);
  double t = (4.0 / RSW_PI) * phi;
  t = (m ? t : 2.0 - t) * r;
  double a = m ? r : t, b = m ? t : r;
  return v2(0.5 * (a + 1.0), 0.5 * (b + 1.0));
}

double warp_square_to_disk_concentric_pdf(vec2 p) {
  return p.x * p.x + p.y * p.y > 1.0 ? 0.0 : RSW_INV_PI;
}

/* Polar map (Mitsuba square_to_uniform_disk): r = sqrt(u.y), phi = 2 pi u.x.
 * The area element r dr dphi = (1/2) du.y (2 pi du.x) = pi du, so pdf 1/pi. */
vec2 warp_square_to_uniform_disk(vec2 u) {
  double r = sqrt(u.y), s, c; /* phi = 2 pi u.x */
  sincos_2pi(u.x, &s, &c);
  return v2(r * c, r * s);
}

/* Inverse: u = (phi / (2 pi) in [0, 1), r^2). */
vec2 warp_uniform_disk_to_square(vec2 p) {
  return v2(angle_fraction(p.y, p.x), p.x * p.x + p.y * p.y);
}

double warp_square_to_uniform_disk_pdf(vec2 p) {
  return p.x * p.x + p.y * p.y > 1.0 ? 0.0 : RSW_INV_PI;
}

/* --- hemisphere / sphere / cone ----------------------------------------- */

/* Uniform hemisphere through the concentric disk (Mitsuba
 * square_to_uniform_hemisphere): p = concentric(u), z = 1 - |p|^2,
 * (x, y) = p sqrt(z + 1). Since |(x,y)|^2 = |p|^2 (2 - |p|^2) = 1 - z^2 the
 * result is unit; z is uniform in [0, 1] (Archimedes), so pdf 1/(2 pi). */
vec3 warp_square_to_uniform_hemisphere(vec2 u) {
  vec2 p = warp_square_to_disk_concentric(u);
  double z = 1.0 - (p.x * p.x + p.y * p.y);
  double s = sqrt(fmax(0.0, z + 1.0));
  return v3(p.x * s, p.y * s, z);
}

/* Inverse: concentric-inverse of (x, y) / sqrt(z + 1). */
vec2 warp_uniform_hemisphere_to_square(vec3 v) {
  double s = v.z + 1.0 > 0.0 ? 1.0 / sqrt(v.z + 1.0) : 0.0;
  return warp_disk_to_square_concentric(v2(v.x * s, v.y * s));
}

double warp_square_to_uniform_hemisphere_pdf(vec3 v) {
  return (off_unit_sphere(v) || v.z < 0.0) ? 0.0 : RSW_INV_2PI;
}

/* Malley's method (Mitsuba square_to_cosine_hemisphere): a uniform disk
 * point p projected up, z = sqrt(1 - |p|^2). Projection divides the area
 * density 1/pi by the Jacobian d(area)/d(omega) = cos theta: pdf
 * cos(theta) / pi. */
vec3 warp_square_to_cosine_hemisphere(vec2 u) {
  vec2 p = warp_square_to_disk_concentric(u);
  double z = sqrt(fmax(0.0, 1.0 - (p.x * p.x + p.y * p.y)));
  return v3(p.x, p.y, z);
}

vec2 warp_cosine_hemisphere_to_square(vec3 v) {
  return warp_disk_to_square_concentric(v2(v.x, v.y));
}

double warp_square_to_cosine_hemisphere_pdf(vec3 v) {
  return (off_unit_sphere(v) || v.z < 0.0) ? 0.0 : RSW_INV_PI * v.z;
}

/* Cosine-power lobe p(omega) = (n+1) cos^n(theta) / (2 pi) (Global
 * Illumination Compendium (36); Castle's RandomHemispherePointCosThetaExp).
 * Marginal in mu = cos theta: (n+1) mu^n on [0, 1], CDF mu^(n+1), so
 * mu = u.y^(1/(n+1)); phi = 2 pi u.x. */
vec3 warp_square_to_cosine_power_hemisphere(vec2 u, double n) {
  double cos_theta = pow(u.y, 1.0 / (n + 1.0));
  double sin_theta = sqrt(fmax(0.0, 1.0 - cos_theta * cos_theta));
  double phi = 2.0 * RSW_PI * u.x;
  return v3(sin_theta * cos(phi), sin_theta * sin(phi), cos_theta);
}

/* Inverse: u = (phi / (2 pi) in [0, 1), cos(theta)^(n+1)). */
vec2 warp_cosine_power_hemisphere_to_square(vec3 v, double n) {
  double mu = fmin(fmax(v.z, 0.0), 1.0);
  return v2(angle_fraction(v.y, v.x), pow(mu, n + 1.0));
}

double warp_square_to_cosine_power_hemisphere_pdf(vec3 v, double n) {
  if (off_unit_sphere(v) || v.z < 0.0) return 0.0;
  return (n + 1.0) * pow(v.z, n) * RSW_INV_2PI;
}

/* Uniform sphere (Mitsuba square_to_uniform_sphere): z = 1 - 2 u.y is
 * uniform in [-1, 1] (Archimedes), phi = 2 pi u.x; pdf 1/(4 pi). */
vec3 warp_square_to_uniform_sphere(vec2 u) {
  double z = 1.0 - 2.0 * u.y;
  double r = sqrt(fmax(0.0, 1.0 - z * z)), s, c; /* phi = 2 pi u.x */
  sincos_2pi(u.x, &s, &c);
  return v3(r * c, r * s, z);
}

/* Inverse: u = (phi / (2 pi) in [0, 1), (1 - z) / 2). */
vec2 warp_uniform_sphere_to_square(vec3 v) {
  return v2(angle_fraction(v.y, v.x), 0.5 * (1.0 - v.z));
}

double warp_square_to_uniform_sphere_pdf(vec3 v) {
  return off_unit_sphere(v) ? 0.0 : RSW_INV_4PI;
}

/* Uniform cone through the concentric disk (Mitsuba square_to_uniform_cone,
 * its low-distortion "approach 2"): with c = cos_cutoff, p = concentric(u),
 *   z = c + (1 - c)(1 - |p|^2),  (x, y) = p sqrt((1 - c)(2 - (1 - c) |p|^2)),
 * so |(x,y)|^2 = 1 - z^2 and z is uniform in [c, 1]: the solid angle of
 * the cone is 2 pi (1 - c) and the pdf its inverse. */
vec3 warp_square_to_uniform_cone(vec2 u, double cos_cutoff) {
  double k = 1.0 - cos_cutoff;
  vec2 p = warp_square_to_disk_concentric(u);
  double pn = p.x * p.x + p.y * p.y;
  double z = cos_cutoff + k * (1.0 - pn);
  double s = sqrt(fmax(0.0, k * (2.0 - k * pn)));
  return v3(p.x * s, p.y * s, z);
}

/* Inverse (Mitsuba uniform_cone_to_square): the disk point has
 * |p|^2 = (1 - z) / (1 - c) and the direction of (x, y). */
vec2 warp_uniform_cone_to_square(vec3 v, double cos_cutoff) {
  double xy2 = v.x * v.x + v.y * v.y;
  double k = 1.0 - cos_cutoff;
  double s = (xy2 > 0.0 && k > 0.0) ? sqrt(fmax(0.0, (1.0 - v.z) / (xy2 * k))) : 0.0;
  return warp_disk_to_square_concentric(v2(v.x * s, v.y * s));
}

double warp_square_to_uniform_cone_pdf(vec3 v, double cos_cutoff) {
  if (off_unit_sphere(v) || v.z < cos_cutoff) return 0.0;
  return RSW_INV_2PI / (1.0 - cos_cutoff);
}

/* --- angles (CastleSphereSampling representation) ----------------------- */

/* Castle's PhiThetaToXYZ(PhiTheta, SphereTheta0): theta = 0 lies on the
 * pole `axis`, whose length is the radius; the phi = 0 meridian is fixed
 * by the axis alone, here the first vector s of coordinate_system(n) (so
 * for n = +z, phi = 0 is +x and phi = pi/2 is +y, Castle's local frame):
 *   v = |axis| (sin theta cos phi s + sin theta sin phi t + cos theta n).
 * A zero axis has no pole: the result is the zero vector. */
vec3 warp_phi_theta_to_xyz(vec2 phi_theta, vec3 axis) {
  double radius = v3_len(axis);
  if (!(radius > 0.0)) return v3(0.0, 0.0, 0.0);
  vec3 n = v3_scale(axis, 1.0 / radius), s, t;
  coordinate_system(n, &s, &t);
  double sin_theta = sin(phi_theta.y), cos_theta = cos(phi_theta.y);
  vec3 local = v3(sin_theta * cos(phi_theta.x), sin_theta * sin(phi_theta.x), cos_theta);
  vec3 dir = v3_add(v3_add(v3_scale(s, local.x), v3_scale(t, local.y)), v3_scale(n, local.z));
  return v3_scale(dir, radius);
}

/* Inverse, in the same frame: phi = atan2(v.t, v.s) in [0, 2 pi),
 * theta = atan2(|v x n|, v.n) in [0, pi] (atan2 rather than acos keeps
 * precision near the poles). The length of v is ignored. */
vec2 warp_xyz_to_phi_theta(vec3 v, vec3 axis) {
  double len = v3_len(axis);
  if (!(len > 0.0)) return v2(0.0, 0.0);
  vec3 n = v3_scale(axis, 1.0 / len), s, t;
  coordinate_system(n, &s, &t);
  double ls = v3_dot(v, s), lt = v3_dot(v, t), ln = v3_dot(v, n);
  double phi = 2.0 * RSW_PI * angle_fraction(lt, ls);
  double theta = atan2(sqrt(ls * ls + lt * lt), ln);
  return v2(phi, theta);
}
