/* Stokes vectors and Mueller matrices (the polarized variants,
 * docs/polarization.md).
 *
 * A Stokes vector (I, Q, U, V) is stated in a basis: the direction d the
 * light travels and a unit vector x perpendicular to it; y = d x x. Then
 * Q = I_x - I_y, U = I_{+45} - I_{-45} (+45: (x + y) / sqrt 2) and V the
 * circular part. A basis is defined up to the sign of x (turning x by 180
 * degrees leaves a Stokes vector unchanged). Turning x by phi about d
 * (right-handed, counter-clockwise when looking into the beam) changes the
 * vector by the rotator
 *
 *   R(phi) = [1 0 0 0; 0 cos 2phi sin 2phi 0; 0 -sin 2phi cos 2phi 0; 0 0 0 1]
 *
 * (Chandrasekhar 1960, Radiative Transfer, eq. I.185; Mitsuba 3's
 * mueller.h rotator uses the same matrix). A Mueller matrix maps the
 * Stokes vector of incident light (its basis) to that of the scattered
 * light (its own basis); chains multiply from the camera's end.
 *
 * The path tracers carry, per colour channel, the scalar throughput they
 * carry in every variant times a matrix M of polarization factors: each
 * scattering contributes P = F / F00, F its Mueller matrix, so that the
 * unpolarized arithmetic is untouched and M00 holds what polarization
 * changes in the intensity (docs/polarization.md#the-payload). */
#ifndef RSW_CORE_MUELLER_H
#define RSW_CORE_MUELLER_H

#include <complex.h>
#include <math.h>
#include <string.h>

#include "vec.h"

typedef struct mueller {
  double m[4][4];
} mueller;

static inline mueller mu_zero(void) {
  mueller r;
  memset(&r, 0, sizeof r);
  return r;
}
static inline mueller mu_identity(void) {
  mueller r = mu_zero();
  r.m[0][0] = r.m[1][1] = r.m[2][2] = r.m[3][3] = 1.0;
  return r;
}
/* What a non-polarizing interaction contributes: only I passes (and is
 * scaled by the scalar throughput). */
static inline mueller mu_depolarizer(void) {
  mueller r = mu_zero();
  r.m[0][0] = 1.0;
  return r;
}
static inline mueller mu_mul(const mueller *a, const mueller *b) {
  mueller r;
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++)
      r.m[i][j] = a->m[i][0] * b->m[0][j] + a->m[i][1] * b->m[1][j] + a->m[i][2] * b->m[2][j] +
                  a->m[i][3] * b->m[3][j];
  return r;
}
static inline void mu_apply(const mueller *a, const double s[4], double out[4]) {
  for (int i = 0; i < 4; i++)
    out[i] = a->m[i][0] * s[0] + a->m[i][1] * s[1] + a->m[i][2] * s[2] + a->m[i][3] * s[3];
}
/* a with every element divided by a->m[0][0] (identity-free: a matrix
 * whose I -> I element is 0 gives the depolarizer). */
static inline mueller mu_normalized(mueller a) {
  if (!(a.m[0][0] != 0.0) || !isfinite(a.m[0][0])) return mu_depolarizer();
  double k = 1.0 / a.m[0][0];
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++) a.m[i][j] *= k;
  a.m[0][0] = 1.0;
  return a;
}

/* The rotator R(phi) above, from cos 2phi and sin 2phi. */
static inline mueller mu_rotator_cs(double c2, double s2) {
  mueller r = mu_identity();
  r.m[1][1] = c2, r.m[1][2] = s2;
  r.m[2][1] = -s2, r.m[2][2] = c2;
  return r;
}

/* Stokes vector in basis `from` -> the same light in basis `to`; both unit
 * and perpendicular to the travel direction d. */
static inline mueller mu_basis_change(vec3 d, vec3 from, vec3 to) {
  double c = v3_dot(from, to), s = v3_dot(v3_cross(from, to), d);
  double n = c * c + s * s; /* |from||to| squared, 1 up to rounding */
  if (!(n > 0)) return mu_identity();
  return mu_rotator_cs((c * c - s * s) / n, 2.0 * c * s / n);
}

/* The basis vector a direction gets when nothing else names one: the
 * first tangent of core/vec.h coordinate_system (Mitsuba's stokes_basis). */
static inline vec3 stokes_basis(vec3 d) {
  vec3 s, t;
  coordinate_system(d, &s, &t);
  return s;
}

/* A unit vector perpendicular to both a and b (the normal of the plane
 * they span); when they are parallel, stokes_basis(a). */
static inline vec3 plane_normal(vec3 a, vec3 b) {
  vec3 n = v3_cross(a, b);
  double l = v3_len(n);
  return l > 1e-12 ? v3_scale(n, 1.0 / l) : stokes_basis(a);
}

/* ---- Fresnel (Born & Wolf, Principles of Optics, sect. 1.5.2 and 14.2;
 * the Mueller form as in Collett, Field Guide to Polarization, and
 * Mitsuba 3's mueller.h specular_reflection / specular_transmission) ---- */

/* Amplitude coefficients of an interface of relative index eta (complex
 * for conductors), for incidence cosine cos_i > 0 on the side the normal
 * points to: r_s = (cos_i - eta cos_t) / (cos_i + eta cos_t),
 * r_p = (eta cos_i - cos_t) / (eta cos_i + cos_t), cos_t = sqrt(1 -
 * (1 - cos_i^2) / eta^2) (principal root: total internal reflection when
 * eta < 1 gives |r_s| = |r_p| = 1 with their phases). */
static inline void fresnel_amplitudes(double cos_i, double complex eta, double complex *rs,
                                      double complex *rp, double complex *ts, double complex *tp) {
  double ci = fabs(cos_i);
  double complex ct = csqrt(1.0 - (1.0 - ci * ci) / (eta * eta));
  *rs = (ci - eta * ct) / (ci + eta * ct);
  *rp = (eta * ci - ct) / (eta * ci + ct);
  if (ts) *ts = 2.0 * ci / (ci + eta * ct);
  if (tp) *tp = 2.0 * ci / (eta * ci + ct);
}

/* Mueller matrix of specular reflection, in the bases whose x is the
 * s-direction (perpendicular to the plane of incidence) for the incident
 * and the reflected beam. */
static inline mueller mu_fresnel_reflection(double cos_i, double complex eta) {
  double complex rs, rp;
  fresnel_amplitudes(cos_i, eta, &rs, &rp, NULL, NULL);
  double as = creal(rs * conj(rs)), ap = creal(rp * conj(rp));
  double complex x = rs * conj(rp);
  double a = 0.5 * (as + ap), b = 0.5 * (as - ap), c = creal(x), d = cimag(x);
  mueller r = mu_zero();
  r.m[0][0] = r.m[1][1] = a;
  r.m[0][1] = r.m[1][0] = b;
  r.m[2][2] = r.m[3][3] = c;
  r.m[2][3] = d;
  r.m[3][2] = -d;
  return r;
}

/* Mueller matrix of specular transmission through a dielectric interface
 * of real relative index eta (no total internal reflection), s-direction
 * bases, up to the factor eta cos_t / cos_i that only scales the
 * intensity (the callers normalize it away). */
static inline mueller mu_fresnel_transmission(double cos_i, double eta) {
  double complex rs, rp, ts, tp;
  fresnel_amplitudes(cos_i, eta, &rs, &rp, &ts, &tp);
  double s = creal(ts * conj(ts)), p = creal(tp * conj(tp)), x = creal(ts * conj(tp));
  mueller r = mu_zero();
  r.m[0][0] = r.m[1][1] = 0.5 * (s + p);
  r.m[0][1] = r.m[1][0] = 0.5 * (s - p);
  r.m[2][2] = r.m[3][3] = x;
  return r;
}

/* ---- Rayleigh scattering --------------------------------------------------
 * The phase matrix of anisotropic molecules with depolarization factor rho
 * (Hansen & Travis 1974, Space Sci. Rev. 16, eq. 2.15-2.16): with
 * Delta = (1 - rho) / (1 + rho / 2), Delta' = (1 - 2 rho) / (1 - rho) and
 * mu = cos Theta,
 *   F11 = F22 / ... : F11 = 3/4 Delta (1 + mu^2) + (1 - Delta),
 *   F12 = F21 = -3/4 Delta (1 - mu^2), F22 = 3/4 Delta (1 + mu^2),
 *   F33 = 3/2 Delta mu, F44 = 3/2 Delta Delta' mu,
 * stated for Q = I_l - I_r (l in the scattering plane). Here the bases'
 * x is the scattering plane's normal (Q = I_r - I_l), which flips the sign
 * of F12 and F21. */
static inline mueller mu_rayleigh(double mu, double rho) {
  double D = (1.0 - rho) / (1.0 + 0.5 * rho), Dp = (1.0 - 2.0 * rho) / (1.0 - rho);
  mueller r = mu_zero();
  r.m[0][0] = 0.75 * D * (1.0 + mu * mu) + (1.0 - D);
  r.m[0][1] = r.m[1][0] = 0.75 * D * (1.0 - mu * mu);
  r.m[1][1] = 0.75 * D * (1.0 + mu * mu);
  r.m[2][2] = 1.5 * D * mu;
  r.m[3][3] = 1.5 * D * Dp * mu;
  return r;
}

#endif
