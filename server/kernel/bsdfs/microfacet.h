/* Beckmann and GGX (Trowbridge-Reitz) microfacet distributions, anisotropic,
 * with Smith shadowing-masking and two sampling strategies: the
 * distribution of visible normals (default) and D(m) cos(theta_m).
 *
 * Sources: mitsuba3 include/mitsuba/render/microfacet.h; Walter et al.
 * 2007 "Microfacet models for refraction through rough surfaces"; Heitz
 * 2018 "Sampling the GGX distribution of visible normals" (JCGT 7(4));
 * Jakob 2014 "An improved visible normal sampling routine for the
 * Beckmann distribution"; docs/kernel-conventions.md#rough-conductors.
 *
 * All vectors are in the local shading frame (n = +z). */
#ifndef RSW_BSDFS_MICROFACET_H
#define RSW_BSDFS_MICROFACET_H

#include <stdbool.h>

#include "../core/isa.h"
#include "../core/vec.h"
#include "../core/warp.h"

typedef enum mf_type {
  MF_BECKMANN,
  MF_GGX
} mf_type;

typedef struct mf_distr {
  mf_type type;
  double alpha_u, alpha_v; /* roughness along the tangent / bitangent */
  bool sample_visible;     /* sample visible normals (Heitz & d'Eon) */
} mf_distr;

/* A distribution; alphas are clamped to >= 1e-4 as Mitsuba's configure()
 * does (zero roughness belongs to the smooth models). */
mf_distr mf_make(mf_type type, double alpha_u, double alpha_v, bool sample_visible);

/* D(m), the normal distribution (per unit projected area):
 *   Beckmann: exp(-(mx^2/au^2 + my^2/av^2) / cos^2) / (pi au av cos^4)
 *   GGX:      1 / (pi au av (mx^2/au^2 + my^2/av^2 + mz^2)^2)
 * set to 0 where D cos(theta_m) <= 1e-20 (Mitsuba, to avoid numerical
 * trouble downstream) and for m.z <= 0. */
double mf_D(const mf_distr *d, vec3 m);

/* Smith's G1(v, m), with t = (au^2 vx^2 + av^2 vy^2) / vz^2:
 *   Beckmann: a = 1/sqrt(t); 1 if a >= 1.6, else the rational fit
 *             (3.535 a + 2.181 a^2) / (1 + 2.276 a + 2.577 a^2)
 *             (< 0.35 % error, Walter et al. 2007 eq. 27);
 *   GGX:      2 / (1 + sqrt(1 + t)).
 * 1 when t = 0 (normal incidence); 0 when (v.m) v.z <= 0 (the back of a
 * microfacet cannot be seen from the front and vice versa). */
double mf_smith_g1(const mf_distr *d, vec3 v, vec3 m);

/* The exact Smith G1 of the distribution, the normalisation of its
 * distribution of visible normals (what mf_sample() draws):
 *   Beckmann: 2 / (1 + erf(a) + exp(-a^2) / (a sqrt(pi))) (Walter et al.
 *             2007 eq. 25; Heitz 2014 "Understanding the masking-shadowing
 *             function", §5.1);
 *   GGX:      mf_smith_g1() (its closed form is exact).
 * Same conventions as mf_smith_g1() at t = 0 and for back-facing m.
 *
 * The model (issue 11 item 4; docs/kernel-conventions.md#where-raysweep-differs):
 * eval() keeps Mitsuba's values, i.e. G = mf_smith_g1() products with the
 * Beckmann rational fit (mitsuba3 include/mitsuba/render/microfacet.h,
 * smith_g1()); sampling draws exact Beckmann-Smith visible normals as
 * Mitsuba's sample_visible_11() does; mf_pdf() is the density of what is
 * drawn, with this exact G1, and sample weights are eval/pdf. Mitsuba uses
 * the fit in pdf() as well, which is not the density its sampler draws,
 * so its BSDF-sampled and emitter-sampled estimates differ by up to
 * 0.3 % at grazing incidence. */
double mf_visible_g1(const mf_distr *d, vec3 v, vec3 m);

/* Separable shadowing-masking G1(wi, m) G1(wo, m). */
double mf_G(const mf_distr *d, vec3 wi, vec3 wo, vec3 m);

/* Sample a microfacet normal m for incident direction wi (wi.z > 0) and
 * write its solid-angle density in *pdf (see mf_pdf). The placement of m
 * is computed in single precision (error budget in microfacet.c); *pdf is
 * evaluated in double from the m returned, by mf_pdf()'s code. */
vec3 mf_sample(const mf_distr *d, vec3 wi, vec2 u, double *pdf);
/* The same, also writing the G1vis(wi, m) factor of the pdf (1 when not
 * sampling visible normals) so that a sample weight can reuse it. */
vec3 mf_sample_g1(const mf_distr *d, vec3 wi, vec2 u, double *pdf, double *g1vis);

/* Density of mf_sample() producing m (solid angle, over m):
 *   visible:     D_wi(m) = G1vis(wi, m) |wi.m| D(m) / wi.z, with the
 *                exact G1vis = mf_visible_g1() (not Mitsuba's fit);
 *   not visible: D(m) cos(theta_m). */
double mf_pdf(const mf_distr *d, vec3 wi, vec3 m);
/* mf_pdf() that also writes its G1vis(wi, m) factor (1 when not visible). */
double mf_pdf_g1(const mf_distr *d, vec3 wi, vec3 m, double *g1vis);

/* Inverse error function on (-1, 1), in single precision (Giles 2010, as
 * Mitsuba's): erf(mf_erfinvf(x)) is within 2e-7 of x (tested over the
 * domain); +-inf at +-1, NaN outside. mf_erfinv() is the same value for a
 * double argument. */
float mf_erfinvf(float x);
double mf_erfinv(double x);

/* Error function in single precision (Abramowitz & Stegun 7.1.28, no
 * exp): absolute error below 4e-7 on the whole real line (tested against
 * libm's erf). For sampling only; densities use libm's double erf. */
float mf_erff(float x);

/* Batched visible-normal samples and eval/pdf, single precision, at
 * `isa` (supported; rsw_isa_get() for the render's): the float lanes of
 * bsdfs/microfacet_lanes.h, whose declarations say the in/out layouts. */
void mf_sample_visible_batch(rsw_isa isa, int ggx, int n, const float *const *in, float *const *out);
void mf_eval_batch(rsw_isa isa, int ggx, int visible, int n, const float *const *in, float *const *out);

#endif
