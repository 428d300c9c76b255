/* The Fresnel Mueller matrices (core/mueller.h states the conventions).
 * Apart from mueller.h because it needs <complex.h>, whose macro `I` the
 * rest of the kernel must not see: include it only where the Fresnel
 * matrices are needed. */
#ifndef RSW_CORE_MUELLER_FRESNEL_H
#define RSW_CORE_MUELLER_FRESNEL_H

#include <complex.h>

#include "mueller.h"

/* re + i im, as C11's CMPLX (which glibc's header leaves undefined for
 * clang, the fuzzers' compiler): a complex has the representation of an
 * array of two doubles (C11 6.2.5p13). */
static inline double complex mu_cmplx(double re, double im) {
  union {
    double complex z;
    double d[2];
  } u = {.d = {re, im}};
  return u.z;
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

#endif
