/* Microfacet distributions (formulas and sources in microfacet.h). */
#include "microfacet.h"
#include "microfacet_lanes.h"

#define INV_SQRT_PI 0.56418958354775628695

mf_distr mf_make(mf_type type, double alpha_u, double alpha_v, bool sample_visible) {
  mf_distr d;
  d.type = type;
  d.alpha_u = alpha_u > 1e-4 ? alpha_u : 1e-4;
  d.alpha_v = alpha_v > 1e-4 ? alpha_v : 1e-4;
  d.sample_visible = sample_visible;
  return d;
}

double mf_D(const mf_distr *d, vec3 m) {
  double c = m.z;
  if (!(c > 0.0)) return 0.0;
  double c2 = c * c;
  double xu = m.x / d->alpha_u, yv = m.y / d->alpha_v;
  double result;
  if (d->type == MF_BECKMANN) {
    result = exp(-(xu * xu + yv * yv) / c2) / (RSW_PI * d->alpha_u * d->alpha_v * c2 * c2);
  } else {
    double t = xu * xu + yv * yv + c2;
    result = 1.0 / (RSW_PI * d->alpha_u * d->alpha_v * t * t);
  }
  /* Written so that a NaN also lands on 0. */
  return result * c > 1e-20 ? result : 0.0;
}

double mf_smith_g1(const mf_distr *d, vec3 v, vec3 m) {
  /* Consistent orientation first: a back-facing microfacet is invisible. */
  if (v3_dot(v, m) * v.z <= 0.0) return 0.0;
  double ax = d->alpha_u * v.x, ay = d->alpha_v * v.y;
  double xy_alpha_2 = ax * ax + ay * ay;
  if (xy_alpha_2 == 0.0) return 1.0;
  double t = xy_alpha_2 / (v.z * v.z);
  if (d->type == MF_BECKMANN) {
    double a = 1.0 / sqrt(t), a2 = a * a;
    if (a >= 1.6) return 1.0;
    return (3.535 * a + 2.181 * a2) / (1.0 + 2.276 * a + 2.577 * a2);
  }
  return 2.0 / (1.0 + sqrt(1.0 + t));
}

double mf_visible_g1(const mf_distr *d, vec3 v, vec3 m) {
  if (d->type == MF_GGX) return mf_smith_g1(d, v, m); /* GGX's G1 is exact */
  if (v3_dot(v, m) * v.z <= 0.0) return 0.0;
  double ax = d->alpha_u * v.x, ay = d->alpha_v * v.y;
  double xy_alpha_2 = ax * ax + ay * ay;
  if (xy_alpha_2 == 0.0) return 1.0;
  /* G1 = 1 / (1 + Lambda(a)), Lambda(a) = (erf(a) - 1) / 2 +
   * exp(-a^2) / (2 a sqrt(pi)), a = 1 / sqrt(t) = v.z / sqrt(xy_alpha_2).
   * Written as a sum of non-negative terms: no cancellation; a = 0
   * (grazing) gives 2 / inf = 0. */
  double a = fabs(v.z) / sqrt(xy_alpha_2);
  return 2.0 / (1.0 + erf(a) + INV_SQRT_PI * exp(-a * a) / a);
}

double mf_G(const mf_distr *d, vec3 wi, vec3 wo, vec3 m) {
  return mf_smith_g1(d, wi, m) * mf_smith_g1(d, wo, m);
}

static inline double pdf_g1(const mf_distr *d, vec3 wi, vec3 m, double *g1vis) {
  *g1vis = 1.0;
  double D = mf_D(d, m);
  if (D == 0.0) return 0.0;
  if (d->sample_visible) {
    if (!(wi.z > 0.0)) return 0.0;
    /* The exact Smith G1: the visible-normal samplers below draw this
     * density exactly (Beckmann's rational fit would be off by up to
     * 0.35 %, see microfacet.h). */
    double g = mf_visible_g1(d, wi, m);
    *g1vis = g;
    return D * g * fabs(v3_dot(wi, m)) / wi.z;
  }
  return D * m.z;
}

double mf_pdf_g1(const mf_distr *d, vec3 wi, vec3 m, double *g1vis) {
  return pdf_g1(d, wi, m, g1vis);
}

double mf_pdf(const mf_distr *d, vec3 wi, vec3 m) {
  double g1vis;
  return pdf_g1(d, wi, m, &g1vis);
}

/* ---- single-precision sampling helpers -----------------------------------
 *
 * Error budget. The values below only decide *where* a microfacet normal
 * lands; the pdf and the weight of a sample are evaluated afterwards in
 * double precision from the normal actually drawn (mf_sample_g1()). An
 * error e in the sampled CDF therefore moves probability mass by at most e
 * (here ~1e-6): the estimator's bias is of that relative order, far below
 * the Monte Carlo noise of any render (1e-3 at thousands of spp) and below
 * what the chi-square tests resolve (they stay at 3 sigma, fixed seeds).
 * Mitsuba's scalar variants sample in single precision as well. */

/* erf(x) in single precision: Abramowitz & Stegun 7.1.28,
 *   erf(x) = 1 - (1 + a1 x + ... + a6 x^6)^-16 for x >= 0, odd in x,
 * polynomial only (no exp). Max absolute error 3e-7 (A&S); with the
 * rounding to float, below 4e-7 over the real line (tested against libm's
 * erf, tests/kernel/bsdfs/test_bsdf.c). */
float mf_erff(float x) {
  float ax = fabsf(x);
  if (!(ax < 6.0f)) return x != x ? x : copysignf(1.0f, x); /* erf = 1 in float; NaN passes */
  /* The polynomial and its 16th power in double: in float, 1 - p^-16
   * loses ~3e-6 to rounding near x = 0.1 (16 roundings of p compounded);
   * in double only the approximation's own 3e-7 remains. */
  double a = ax, a2 = a * a, a4 = a2 * a2;
  double p = (1.0 + 0.0705230784 * a) + (0.0422820123 + 0.0092705272 * a) * a2 +
             ((0.0001520143 + 0.0002765672 * a) + 0.0000430638 * a2) * a4;
  double p2 = p * p, p4 = p2 * p2, p8 = p4 * p4, p16 = p8 * p8;
  return copysignf((float)(1.0 - 1.0 / p16), x);
}

float mf_erfinvf(float xf) {
  if (!(xf > -1.0f)) return xf == -1.0f ? -INFINITY : NAN;
  if (!(xf < 1.0f)) return xf == 1.0f ? INFINITY : NAN;
  /* Giles, "Approximating the erfinv function" (GPU Computing Gems, 2010),
   * single-precision branch: relative error ~1e-7 (erf of the result is
   * within 2e-7 of x, tested). The polynomials are evaluated in Estrin's
   * form (pairs, then w^2 and w^4 steps) rather than Horner's: the same
   * terms, a third of the dependent latency (the Newton chain of the
   * Beckmann sampler is latency-bound). */
  float w = -logf((1.0f - xf) * (1.0f + xf)), p;
  if (w < 5.0f) {
    w -= 2.5f;
    float w2 = w * w, w4 = w2 * w2;
    float q01 = 1.50140941f + 0.246640727f * w, q23 = -0.00417768164f + -0.00125372503f * w;
    float q45 = 0.00021858087f + -4.39150654e-06f * w, q67 = -3.5233877e-06f + 3.43273939e-07f * w;
    float r03 = q01 + q23 * w2, r47 = q45 + q67 * w2;
    p = r03 + (r47 + 2.81022636e-08f * w4) * w4;
  } else {
    w = sqrtf(w) - 3.0f;
    float w2 = w * w, w4 = w2 * w2;
    float q01 = 2.83297682f + 1.00167406f * w, q23 = 0.00943887047f + -0.0076224613f * w;
    float q45 = 0.00573950773f + -0.00367342844f * w, q67 = 0.00134934322f + 0.000100950558f * w;
    float r03 = q01 + q23 * w2, r47 = q45 + q67 * w2;
    p = r03 + (r47 + -0.000200214257f * w4) * w4;
  }
  return p * xf;
}

double mf_erfinv(double x) {
  if (!(x > -1.0)) return x == -1.0 ? -INFINITY : NAN;
  if (!(x < 1.0)) return x == 1.0 ? INFINITY : NAN;
  return (double)mf_erfinvf((float)x);
}

/* Branch-free in practice (fmin/fmax are libm calls at -O2 because of
 * their NaN rules; these are not, and NaN goes to the bound or 0). */
static inline float clampf(float v, float lo, float hi) {
  return v > lo ? (v < hi ? v : hi) : lo;
}
static inline float maxf0(float v) {
  return v > 0.0f ? v : 0.0f;
}
static inline double clampd(double v, double lo, double hi) {
  return v > lo ? (v < hi ? v : hi) : lo;
}
static inline double maxd0(double v) {
  return v > 0.0 ? v : 0.0;
}

/* Slopes of a visible-normal sample of the Beckmann distribution with
 * alpha = 1 for incidence cosine cos_i (Jakob 2014), in single precision
 * (see the error budget above). The marginal CDF in the erf() domain
 * x = erf(slope_x) is, up to normalisation,
 *   C(x) = 1 + x + tan(theta_i) exp(-erfinv(x)^2) / sqrt(pi),
 * normalised by C(erf(cot theta_i)); it is inverted with three Newton steps
 * from the analytic solution for theta_i = pi/2. The slope along y is
 * Gaussian: erfinv(2 u.y - 1). Mitsuba uses the same scheme because the
 * original 2014 inversion (Heitz & d'Eon) has discontinuities. */
static vec2 beckmann_visible_11(double cos_i, vec2 u) {
  const float inv_sqrt_pi = 0.564189584f;
  float ci = (float)cos_i;
  float sin_i = sqrtf(maxf0(1.0f - ci * ci));
  float tan_i = sin_i / ci, cot_i = ci / sin_i; /* cot = inf at normal incidence */
  float maxval = mf_erff(cot_i);
  float ux0 = clampf((float)u.x, 1e-6f, 1.0f - 1e-6f);
  float uy0 = clampf((float)u.y, 1e-6f, 1.0f - 1e-6f);
  float x = maxval - (maxval + 1.0f) * mf_erff(sqrtf(-logf(ux0)));
  /* tan_i * exp(-cot_i^2) is 0 at normal incidence (tan_i = 0), and below
   * float resolution for cot_i > 9 (also keeps expf off its slow
   * underflow path). */
  float tail = tan_i > 0.0f && cot_i < 9.0f ? inv_sqrt_pi * tan_i * expf(-cot_i * cot_i) : 0.0f;
  float ux = ux0 * (1.0f + maxval + tail);
  /* Newton steps stop once the residual C(x) - ux is at float resolution
   * (4e-7 ux): the sample's CDF is then off by at most that, and further
   * steps only reshuffle rounding. The residual, not the step in x, is
   * what bounds the error of the distribution drawn. */
  float slope = 0.0f;
  bool converged = false;
  for (int i = 0; i < 3; i++) {
    slope = mf_erfinvf(x);
    float value = 1.0f + x + inv_sqrt_pi * tan_i * expf(-slope * slope) - ux;
    if (fabsf(value) <= 4e-7f * ux) {
      converged = true;
      break;
    }
    float deriv = 1.0f - slope * tan_i;
    x -= value / deriv;
  }
  float sy = mf_erfinvf(2.0f * uy0 - 1.0f);
  if (!converged) {
    /* Keep x inside erfinv's domain after the Newton steps. */
    x = clampf(x, -1.0f + 6e-8f, 1.0f - 6e-8f);
    slope = mf_erfinvf(x);
  }
  return v2(slope, sy);
}

/* Beckmann visible normals: stretch wi to the alpha = 1 configuration,
 * sample slopes there, rotate back to wi's azimuth and unstretch
 * (Heitz & d'Eon 2014, §4). */
static vec3 beckmann_sample_visible(const mf_distr *d, vec3 wi, vec2 u) {
  vec3 wi_p = v3_norm(v3(d->alpha_u * wi.x, d->alpha_v * wi.y, wi.z));
  double sin_t = sqrt(maxd0(1.0 - wi_p.z * wi_p.z));
  double cos_phi = 1.0, sin_phi = 0.0;
  if (sin_t > 0.0) {
    cos_phi = clampd(wi_p.x / sin_t, -1.0, 1.0);
    sin_phi = clampd(wi_p.y / sin_t, -1.0, 1.0);
  }
  vec2 s = beckmann_visible_11(wi_p.z, u);
  double sx = (cos_phi * s.x - sin_phi * s.y) * d->alpha_u;
  double sy = (sin_phi * s.x + cos_phi * s.y) * d->alpha_v;
  return v3_norm(v3(-sx, -sy, 1.0));
}

/* GGX visible normals, Heitz 2018: stretch wi to the hemisphere
 * configuration Vh, sample the projected area of the unit hemisphere seen
 * from Vh (a disk whose far half is squashed by (1 + Vh.z)/2), lift the
 * point onto the hemisphere and unstretch the normal. */
static vec3 ggx_sample_visible(const mf_distr *d, vec3 wi, vec2 u) {
  vec3 vh = v3_norm(v3(d->alpha_u * wi.x, d->alpha_v * wi.y, wi.z));
  double lensq = vh.x * vh.x + vh.y * vh.y;
  vec3 t1 = lensq > 0.0 ? v3_scale(v3(-vh.y, vh.x, 0.0), 1.0 / sqrt(lensq)) : v3(1.0, 0.0, 0.0);
  vec3 t2 = v3_cross(vh, t1);
  /* The azimuth of the disk point in single precision: it only places the
   * sample (error budget above; the pdf is evaluated from the m drawn). */
  float cf, sf;
  sincosf(2.0f * (float)RSW_PI * (float)u.y, &sf, &cf);
  double r = sqrt(u.x);
  double p1 = r * cf, p2 = r * sf;
  double s = 0.5 * (1.0 + vh.z);
  p2 = (1.0 - s) * sqrt(maxd0(1.0 - p1 * p1)) + s * p2;
  double pz = sqrt(maxd0(1.0 - p1 * p1 - p2 * p2));
  vec3 nh = v3_add(v3_add(v3_scale(t1, p1), v3_scale(t2, p2)), v3_scale(vh, pz));
  return v3_norm(v3(d->alpha_u * nh.x, d->alpha_v * nh.y, maxd0(nh.z)));
}

/* Sampling D(m) cos(theta_m) directly (Walter et al. 2007 with Mitsuba's
 * anisotropic azimuth): phi from tan(phi) = (av/au) tan(2 pi u.y) placed in
 * the quadrant of 2 pi u.y, the effective alpha^2 = 1 / (cos^2 phi / au^2 +
 * sin^2 phi / av^2), then
 *   Beckmann: tan^2 theta = -alpha^2 log(1 - u.x)
 *   GGX:      tan^2 theta = alpha^2 u.x / (1 - u.x). */
static vec3 sample_all_normals(const mf_distr *d, vec2 u) {
  double sin_phi, cos_phi, alpha2;
  if (d->alpha_u == d->alpha_v) {
    sin_phi = sin(2.0 * RSW_PI * u.y);
    cos_phi = cos(2.0 * RSW_PI * u.y);
    alpha2 = d->alpha_u * d->alpha_u;
  } else {
    double tmp = d->alpha_v / d->alpha_u * tan(2.0 * RSW_PI * u.y);
    cos_phi = 1.0 / sqrt(tmp * tmp + 1.0);
    /* cos(phi) < 0 for u.y in (1/4, 3/4): the second and third quadrants. */
    cos_phi = copysign(cos_phi, fabs(u.y - 0.5) - 0.25);
    sin_phi = cos_phi * tmp;
    double cu = cos_phi / d->alpha_u, sv = sin_phi / d->alpha_v;
    alpha2 = 1.0 / (cu * cu + sv * sv);
  }
  double tan2;
  if (d->type == MF_BECKMANN)
    tan2 = -alpha2 * log(1.0 - u.x);
  else
    tan2 = alpha2 * u.x / (1.0 - u.x);
  double cos_t = 1.0 / sqrt(1.0 + tan2);
  double sin_t = sqrt(maxd0(1.0 - cos_t * cos_t));
  return v3(cos_phi * sin_t, sin_phi * sin_t, cos_t);
}

vec3 mf_sample_g1(const mf_distr *d, vec3 wi, vec2 u, double *pdf, double *g1vis) {
  vec3 m;
  if (!d->sample_visible)
    m = sample_all_normals(d, u);
  else if (d->type == MF_GGX)
    m = ggx_sample_visible(d, wi, u);
  else
    m = beckmann_sample_visible(d, wi, u);
  /* The density is evaluated by the same code as mf_pdf() so that sample
   * and pdf agree to the last bit (Mitsuba computes the D cos form in
   * closed form; it is the same quantity). */
  *pdf = pdf_g1(d, wi, m, g1vis);
  return m;
}

vec3 mf_sample(const mf_distr *d, vec3 wi, vec2 u, double *pdf) {
  double g1vis;
  return mf_sample_g1(d, wi, u, pdf, &g1vis);
}

void mf_sample_visible_batch(rsw_isa isa, int ggx, int n, const float *const *in, float *const *out) {
  SIMD_DISPATCH(isa, mf_sample_visible, ggx, n, in, out);
}

void mf_eval_batch(rsw_isa isa, int ggx, int visible, int n, const float *const *in, float *const *out) {
  SIMD_DISPATCH(isa, mf_eval, ggx, visible, n, in, out);
}
