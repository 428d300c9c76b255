/* `roughconductor`: the two ways of measuring a directional-hemispherical
 * albedo agree (issue 11, item 4).
 *
 *   sky: BSDF sampling, the mean of sample()'s weight (what a constant
 *        emitter seen through BSDF sampling converges to, by reciprocity
 *        the radiance of the plate seen under a uniform sky);
 *   sun: eval(wi, wo) (which includes cos theta_o) integrated over the
 *        hemisphere with a deterministic quadrature (what emitter sampling
 *        converges to under a directional emitter).
 *
 * They can only agree when sample()'s directions are distributed with the
 * density pdf() reports and the weight is eval/pdf. Before the fix, the
 * Beckmann visible-normal sampler drew exact Beckmann-Smith visible
 * normals while the pdf and weight used the rational G1 fit
 * (docs/kernel-conventions.md#where-raysweep-differs): at alpha 1, 80 deg the sky
 * albedo was 0.880118 +- 2.1e-4 against 0.882550 (-0.28 %, 11.6 sigma),
 * and 6 of the 15 Beckmann visible-normal cases below failed (up to
 * 7.7 sigma, +0.34 % at alpha 0.3, 80 deg).
 *
 * The quadrature runs over the half vector h (wo = 2 (wi.h) h - wi,
 * dwo = 4 (wo.h) dh, h restricted to wi.h > 0 so that each wo is counted
 * once) with h = (sin t cos p, sin t sin p, cos t), p = 2 pi w and
 * tan t = alpha s(v): s = sqrt(-log(1 - v)) for Beckmann and
 * sqrt(v / (1 - v)) for GGX, so the grid follows the lobe at any alpha.
 * The Jacobian dh / (dv dw) = 2 pi sin t (dt/dv) is written out below;
 * nothing of the kernel's microfacet code is used for it. Its accuracy is
 * estimated by the difference between an N and an N/2 grid and added to
 * the tolerance.
 *
 * Tolerance: |sky - sun| <= 3 sigma(sky) + |Q_N - Q_N/2|, fixed seeds.
 * The sample weight is also checked to equal eval/pdf to 1e-6 relative at
 * random incident directions for every microfacet configuration. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "../../support/bsdf_test.h"
#include "../../support/test.h"
#include "kernel/bsdfs/bsdfs_internal.h"
#include "kernel/bsdfs/microfacet.h"
#include "kernel/core/rng.h"
#include "kernel/core/warp.h"
#include "kernel/textures/texture.h"

RSW_TEST_DEFINE_GLOBALS

/* Mean of sample()'s weight (channel 0) and its standard error. */
static void sky_albedo(const bsdf *b, vec3 wi, int n, uint64_t seed, double *mean, double *se) {
  surface_interaction si = tb_si_with(wi);
  pcg32 rng;
  pcg32_seed(&rng, seed, 54);
  double sum = 0.0, sum2 = 0.0;
  for (int i = 0; i < n; i++) {
    bsdf_sample bs;
    double u1 = pcg32_next_double(&rng);
    vec2 u2;
    u2.x = pcg32_next_double(&rng);
    u2.y = pcg32_next_double(&rng);
    double w = b->ops->sample(b, &si, u1, u2, &bs).c[0];
    sum += w;
    sum2 += w * w;
  }
  *mean = sum / n;
  *se = sqrt(fmax(0.0, sum2 / n - *mean * *mean) / (n - 1));
}

/* Midpoint rule on an nx x nw grid over (x, w) with v = 1 - (1 - x)^2
 * (see the file comment). The substitution keeps the integrand bounded as
 * v -> 1: there h approaches the horizon and the integrand in v grows like
 * (1 - v)^-1/2 for GGX (like sqrt(-log(1 - v)) for Beckmann). */
static double sun_albedo(const bsdf *b, mf_type type, double alpha, vec3 wi, int nx, int nw) {
  surface_interaction si = tb_si_with(wi);
  double sum = 0.0;
  for (int i = 0; i < nx; i++) {
    double x = (i + 0.5) / nx, y = 1.0 - x; /* 1 - v = y^2 */
    /* s(v) and s ds/dv dv/dx, with dv/dx = 2 y. */
    double s, ss_dx;
    if (type == MF_BECKMANN) {
      s = sqrt(-2.0 * log(y)); /* s^2 = -log(1 - v) */
      ss_dx = 1.0 / y;         /* 1 / (2 (1 - v)) * 2 y */
    } else {
      s = sqrt(x * (2.0 - x)) / y; /* s^2 = v / (1 - v) */
      ss_dx = 1.0 / (y * y * y);   /* 1 / (2 (1 - v)^2) * 2 y */
    }
    double as = alpha * s, q = 1.0 + as * as;
    double cos_t = 1.0 / sqrt(q), sin_t = as / sqrt(q);
    /* sin t dt/dx = alpha^2 s s' / q^(3/2); times 2 pi from p = 2 pi w. */
    double jac = 2.0 * RSW_PI * alpha * alpha * ss_dx / (q * sqrt(q));
    double row = 0.0;
    for (int j = 0; j < nw; j++) {
      double p = 2.0 * RSW_PI * (j + 0.5) / nw;
      vec3 h = v3(sin_t * cos(p), sin_t * sin(p), cos_t);
      double wi_h = v3_dot(wi, h);
      if (!(wi_h > 0.0)) continue;
      vec3 wo = v3_sub(v3_scale(h, 2.0 * wi_h), wi);
      if (!(wo.z > 0.0)) continue;
      row += b->ops->eval(b, &si, wo).c[0] * 4.0 * wi_h;
    }
    sum += row * jac;
  }
  return sum / ((double)nx * nw);
}

/* Sample counts per configuration: visible normals, D(m) cos sampling. */
#define SKY_VISIBLE 300000
#define SKY_DCOS    100000

static void test_sky_equals_sun(void) {
  const mf_type types[2] = {MF_BECKMANN, MF_GGX};
  const double alphas[3] = {0.05, 0.3, 1.0};
  const double thetas[5] = {0.0, 30.0, 60.0, 80.0, 89.0};
  int worst_t = 0, worst_a = 0, worst_i = 0, worst_v = 0;
  double worst = 0.0;
  for (int t = 0; t < 2; t++)
    for (int a = 0; a < 3; a++)
      for (int i = 0; i < 5; i++) {
        /* F = 1 (eta = 0, k = 1): the albedo is the microfacet model's. */
        rough_case rv = rough_make(types[t], alphas[a], alphas[a], true, 0.0, 1.0);
        rough_case rn = rough_make(types[t], alphas[a], alphas[a], false, 0.0, 1.0);
        REQUIRE(rv.b && rn.b, "allocation");
        vec3 wi = tb_dir_deg(thetas[i], 25.0);
        double q = sun_albedo(rv.b, types[t], alphas[a], wi, 800, 800);
        double q_half = sun_albedo(rv.b, types[t], alphas[a], wi, 400, 400);
        double quad_err = fabs(q - q_half);
        /* Worst case GGX alpha 0.05, 89 deg: 2.5e-4 (Q_N itself is within
         * ~5e-5 of a 2400 x 2400 grid there). */
        CHECK(quad_err < 5e-4, "%s alpha %g theta %g: quadrature not converged (%.3g)",
              mf_type_name(types[t]), alphas[a], thetas[i], quad_err);
        for (int v = 0; v < 2; v++) {
          double m, se;
          sky_albedo(v == 0 ? rv.b : rn.b, wi, v == 0 ? SKY_VISIBLE : SKY_DCOS, 1000 + 100 * t + 10 * a + i,
                     &m, &se);
          double z = fabs(m - q) / (se + quad_err / 3.0 + 1e-300);
          if (getenv("RSW_ALBEDO_VERBOSE"))
            printf("  %-8s alpha %-4g theta %-2g visible %d: sky %.6f +- %.1e  sun %.6f (quad %.1e)"
                   "  %+.2f %%  z %.2f\n",
                   mf_type_name(types[t]), alphas[a], thetas[i], v == 0, m, se, q, quad_err,
                   100.0 * (m - q) / q, z);
          if (z > worst) {
            worst = z;
            worst_t = t, worst_a = a, worst_i = i, worst_v = v;
          }
          CHECK(fabs(m - q) <= 3.0 * se + quad_err,
                "%s alpha %g theta %g sample_visible %d: sky albedo %.6f +- %.1e vs sun %.6f "
                "(quadrature %.1e): %+.3f %%",
                mf_type_name(types[t]), alphas[a], thetas[i], v == 0, m, se, q, quad_err,
                100.0 * (m - q) / q);
          /* Visible normals (the default, and the sampler at issue): small
           * enough that a 0.3 % bias shows at about 3 sigma (worst se
           * 7.6e-4, Beckmann alpha 1 at normal incidence; the precise test
           * above resolves the grazing case to 2e-4). D cos sampling, a
           * control, has a larger variance. */
          if (v == 0) CHECK(se < 1e-3, "standard error %.2g too large", se);
        }
        rough_free(&rv);
        rough_free(&rn);
      }
  printf("  worst: %s alpha %g theta %g visible %d at %.2f (sigma + quad/3)\n", mf_type_name(types[worst_t]),
         alphas[worst_a], thetas[worst_i], worst_v == 0, worst);
}

/* The case from issue 11 with more samples: Beckmann, alpha 1, 80 deg. */
static void test_beckmann_grazing_precise(void) {
  rough_case r = rough_make(MF_BECKMANN, 1.0, 1.0, true, 0.0, 1.0);
  REQUIRE(r.b, "allocation");
  vec3 wi = tb_dir_deg(80.0, 0.0);
  double q = sun_albedo(r.b, MF_BECKMANN, 1.0, wi, 1000, 1000);
  double quad_err = fabs(q - sun_albedo(r.b, MF_BECKMANN, 1.0, wi, 500, 500));
  double m, se;
  sky_albedo(r.b, wi, 1000000, 99, &m, &se);
  printf("  beckmann alpha 1 theta 80: sky %.6f +- %.1e, sun %.6f (quadrature %.1e), %+.3f %%\n", m, se, q,
         quad_err, 100.0 * (m - q) / q);
  CHECK(fabs(m - q) <= 3.0 * se + quad_err, "sky %.6f +- %.1e vs sun %.6f", m, se, q);
  rough_free(&r);
}

/* sample()'s weight is eval/pdf (and its pdf is pdf()) at random incident
 * directions, for GGX/Beckmann, sample_visible on/off, isotropic and
 * anisotropic roughness, with a non-trivial Fresnel term. */
static void test_weight_is_eval_over_pdf(void) {
  const mf_type types[2] = {MF_BECKMANN, MF_GGX};
  const double alphas[5][2] = {{0.05, 0.05}, {0.3, 0.3}, {1.0, 1.0}, {0.1, 0.5}, {1.0, 0.05}};
  pcg32 rng;
  pcg32_seed(&rng, 31, 37);
  for (int t = 0; t < 2; t++)
    for (int a = 0; a < 5; a++)
      for (int v = 0; v < 2; v++) {
        rough_case r = rough_make(types[t], alphas[a][0], alphas[a][1], v == 0, 0.2, 3.0);
        REQUIRE(r.b, "allocation");
        int ok = 0, bad = 0;
        for (int n = 0; n < 5000; n++) {
          vec3 wi = warp_square_to_uniform_hemisphere(v2(pcg32_next_double(&rng), pcg32_next_double(&rng)));
          surface_interaction si = tb_si_with(wi);
          bsdf_sample bs;
          double u1 = pcg32_next_double(&rng);
          vec2 u2;
          u2.x = pcg32_next_double(&rng);
          u2.y = pcg32_next_double(&rng);
          color w = r.b->ops->sample(r.b, &si, u1, u2, &bs);
          if (!(bs.pdf > 0.0)) continue;
          double pdf = r.b->ops->pdf(r.b, &si, bs.wo);
          double f = r.b->ops->eval(r.b, &si, bs.wo).c[0];
          double expect = f / pdf;
          if (!(fabs(w.c[0] - expect) <= 1e-6 * fabs(expect)) || !(fabs(pdf - bs.pdf) <= 1e-6 * pdf)) {
            if (bad++ == 0)
              CHECK(false,
                    "%s alpha (%g, %g) visible %d, wi (%.4f, %.4f, %.4f): weight %.9g vs "
                    "eval/pdf %.9g, pdf %.9g vs pdf() %.9g",
                    mf_type_name(types[t]), alphas[a][0], alphas[a][1], v == 0, wi.x, wi.y, wi.z, w.c[0],
                    expect, bs.pdf, pdf);
          }
          ok++;
        }
        CHECK(bad == 0, "%s alpha (%g, %g) visible %d: %d inconsistent samples", mf_type_name(types[t]),
              alphas[a][0], alphas[a][1], v == 0, bad);
        CHECK(ok > 2500, "%s alpha (%g, %g) visible %d: only %d successful samples", mf_type_name(types[t]),
              alphas[a][0], alphas[a][1], v == 0, ok);
        rough_free(&r);
      }
}

int main(void) {
  RSW_TEST_RUN(test_weight_is_eval_over_pdf);
  RSW_TEST_RUN(test_beckmann_grazing_precise);
  RSW_TEST_RUN(test_sky_equals_sun);
  RSW_TEST_END("test_microfacet_albedo");
}
