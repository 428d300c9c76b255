/* BSDF plugins (server/kernel/bsdfs): chi-square tests of sample() against
 * pdf() (Mitsuba's procedure, tests/support/chi2.h), consistency of the
 * sampling weight with eval/pdf, reciprocity, energy (white furnace),
 * Fresnel values, Snell's law, and the conductor preset tables.
 *
 * BSDFs are built with the direct constructors of bsdfs_internal.h and
 * constant textures, without the scene loader.
 *
 * Sample counts: the chi-square runs use 200,000 samples each (Mitsuba
 * uses 1,000,000) to keep the binary short, also under ASan; the
 * significance level is Mitsuba's 0.01 with the Sidak correction over all
 * chi-square runs in this file. All random streams have fixed seeds. */
#include <complex.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../support/bsdf_test.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "kernel/bsdfs/bsdfs_internal.h"
#include "kernel/bsdfs/fresnel.h"
#include "kernel/bsdfs/ior_data.h"
#include "kernel/bsdfs/microfacet.h"
#include "kernel/core/rng.h"
#include "kernel/scene/scene.h"
#include "kernel/textures/texture.h"

RSW_TEST_DEFINE_GLOBALS

#define CHI2_SAMPLES 200000
/* Number of chi2_run calls in this file (for the Sidak correction):
 * diffuse 3 + isotropic rough 2x3x2x3 = 36 + anisotropic 2x2x3 = 12 +
 * twosided 2. */
#define CHI2_TESTS   53

static const double incidence_deg[3] = {0.0, 60.0, 85.0};

/* ires: trapezoid points per cell axis when integrating the pdf. Mitsuba's
 * 4 is too coarse for lobes much narrower than a cell (alpha 0.05 puts a
 * normal-incidence lobe inside the first row of cells, where the pdf
 * falls by e^-4 across a cell): the expected counts are then off by more
 * than the statistical noise. 8 suffices for alpha >= 0.1, 32 for 0.05. */
static void run_chi2(const bsdf *b, vec3 wi, const char *what, int ires) {
  chi2_bsdf c = {b, tb_si_with(wi)};
  chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
  cfg.sample_count = CHI2_SAMPLES;
  cfg.test_count = CHI2_TESTS;
  cfg.ires = ires;
  chi2_result r = chi2_run(&cfg, chi2_bsdf_sample, chi2_bsdf_pdf, &c);
  CHECK(r.passed, "chi2 %s, wi = (%.4f, %.4f, %.4f): p = %g, chi2 = %g, dof = %d: %s", what, wi.x, wi.y, wi.z,
        r.p_value, r.chi2, r.dof, r.reason);
}

/* ---- Fresnel ------------------------------------------------------------------ */

/* Independent reference: complex arithmetic, n = eta + i k, with
 * c_t = sqrt(n^2 - s^2) / n the (complex) transmitted cosine:
 *   r_s = (c - n c_t) / (c + n c_t),  r_p = (n c - c_t) / (n c + c_t). */
static double fresnel_complex_ref(double c, double eta, double k) {
  double complex n = eta + k * I;
  double s2 = 1.0 - c * c;
  double complex nct = csqrt(n * n - s2); /* n cos_t */
  double complex ct = nct / n;
  double complex rs = (c - nct) / (c + nct);
  double complex rp = (n * c - ct) / (n * c + ct);
  double as = cabs(rs), ap = cabs(rp);
  return 0.5 * (as * as + ap * ap);
}

static void test_fresnel_conductor(void) {
  /* eta = 0 + 1i: a perfect reflector at every angle. */
  for (double c = 0.0; c <= 1.0; c += 0.05) CHECK_REL(fresnel_conductor(c, 0.0, 1.0), 1.0, 1e-12);
  /* Normal incidence: ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2). */
  double n = 0.2, k = 3.0;
  CHECK_REL(fresnel_conductor(1.0, n, k), ((n - 1) * (n - 1) + k * k) / ((n + 1) * (n + 1) + k * k), 1e-12);
  /* General angles and indices against complex arithmetic. */
  const double etas[] = {0.2, 0.5, 1.3, 2.5}, ks[] = {0.01, 1.0, 3.0, 7.0};
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++)
      for (double c = 0.02; c <= 1.0; c += 0.07)
        CHECK_REL(fresnel_conductor(c, etas[i], ks[j]), fresnel_complex_ref(c, etas[i], ks[j]), 1e-9);
  /* Per channel. */
  color f = fresnel_conductor_col(0.5, col(0.2, 0.0, 1.3), col(3.0, 1.0, 1.0));
  CHECK_REL(f.c[0], fresnel_conductor(0.5, 0.2, 3.0), 1e-15);
  CHECK_REL(f.c[1], 1.0, 1e-12);
}

static void test_fresnel_dielectric(void) {
  double eta = 1.5;
  /* Normal incidence: ((eta - 1) / (eta + 1))^2 from either side. */
  double r0 = (eta - 1) * (eta - 1) / ((eta + 1) * (eta + 1));
  double ct, eit, eti;
  CHECK_REL(fresnel_dielectric(1.0, eta, &ct, &eit, &eti), r0, 1e-12);
  CHECK_REL(ct, -1.0, 1e-12);
  CHECK_REL(eit, eta, 0);
  CHECK_REL(eti, 1.0 / eta, 0);
  CHECK_REL(fresnel_dielectric(-1.0, eta, &ct, &eit, &eti), r0, 1e-12);
  CHECK_REL(ct, 1.0, 1e-12);
  CHECK_REL(eit, 1.0 / eta, 0);
  /* Brewster angle tan(theta_B) = eta: r_p = 0, R = r_s^2 / 2. */
  double tb = atan(eta), ci = cos(tb), si_ = sin(tb);
  double ctb = sqrt(1.0 - si_ * si_ / (eta * eta));
  double rs = (ci - eta * ctb) / (ci + eta * ctb);
  CHECK_REL(fresnel_dielectric(ci, eta, NULL, NULL, NULL), 0.5 * rs * rs, 1e-12);
  /* Total internal reflection from inside beyond the critical angle. */
  double crit = asin(1.0 / eta);
  CHECK(fresnel_dielectric(-cos(crit + 0.01), eta, &ct, NULL, NULL) == 1.0, "TIR gives R = 1");
  CHECK(ct == 0.0, "TIR: cos_t = 0");
  /* Index-matched: no reflection. */
  CHECK(fresnel_dielectric(0.3, 1.0, NULL, NULL, NULL) == 0.0, "eta = 1 gives R = 0");
  /* The conductor formula with k = 0 is the dielectric one from outside. */
  for (double c = 0.05; c <= 1.0; c += 0.1)
    CHECK_REL(fresnel_conductor(c, eta, 0.0), fresnel_dielectric(c, eta, NULL, NULL, NULL), 1e-9);
}

/* ---- microfacet building blocks ------------------------------------------------- */

static void test_erfinv(void) {
  /* Giles' single-precision approximation, as Mitsuba: ~1e-7 relative in
   * erfinv, so erf(erfinv(x)) is within 2e-7 of x (abs). */
  for (double x = -0.999999; x < 1.0; x += 0.0123) CHECK_ABS(erf(mf_erfinv(x)), x, 2e-7);
  CHECK(mf_erfinv(0.0) == 0.0, "erfinv(0) = 0");
  CHECK(isinf(mf_erfinv(1.0)), "erfinv(1) = inf");
  /* The float version over the whole domain, densely (2e6 points; both
   * branches of Giles' fit: |x| > 0.9966 is the tail branch), and near +-1
   * where the tail branch takes over. */
  double worst = 0.0;
  for (int i = 1; i < 2000000; i++) {
    float x = (float)(-1.0 + i * 1e-6);
    worst = fmax(worst, fabs(erf(mf_erfinvf(x)) - x));
  }
  for (int k = 1; k <= 7; k++) {
    float x = (float)(1.0 - pow(10.0, -k));
    worst = fmax(worst, fabs(erf(mf_erfinvf(x)) - x));
    worst = fmax(worst, fabs(erf(mf_erfinvf(-x)) + x));
  }
  CHECK(worst <= 2e-7, "erfinvf: max |erf(erfinvf(x)) - x| = %g > 2e-7", worst);
  CHECK(isinf(mf_erfinvf(-1.0f)) && mf_erfinvf(-1.0f) < 0, "erfinvf(-1) = -inf");
  CHECK(isnan(mf_erfinvf(1.5f)), "erfinvf outside [-1, 1] is NaN");
}

/* The polynomial erf of the samplers (A&S 7.1.28) against libm's erf on
 * [-8, 8] (beyond, both are +-1 in float): 1.6e6 points. */
static void test_erff(void) {
  double worst = 0.0;
  for (int i = 0; i <= 1600000; i++) {
    float x = (float)(-8.0 + i * 1e-5);
    worst = fmax(worst, fabs((double)mf_erff(x) - erf(x)));
  }
  CHECK(worst <= 4e-7, "erff: max abs error %g > 4e-7", worst);
  CHECK(mf_erff(0.0f) == 0.0f, "erff(0) = 0");
  CHECK(mf_erff(INFINITY) == 1.0f && mf_erff(-INFINITY) == -1.0f, "erff(+-inf) = +-1");
  CHECK(isnan(mf_erff(NAN)), "erff(NaN) = NaN");
  CHECK(mf_erff(-0.3f) == -mf_erff(0.3f), "erff is odd");
}

/* Midpoint quadrature over the upper hemisphere in (cos theta, phi):
 * integral of f(m) d(omega). The grid is fine enough for alpha >= 0.3. */
typedef double (*hemi_fn)(const mf_distr *d, vec3 wi, vec3 m);
static double hemi_integral(const mf_distr *d, vec3 wi, hemi_fn f) {
  const int nz = 1200, np = 400;
  double sum = 0.0;
  for (int i = 0; i < nz; i++) {
    double z = (i + 0.5) / nz, s = sqrt(1.0 - z * z);
    for (int j = 0; j < np; j++) {
      double p = 2.0 * RSW_PI * (j + 0.5) / np;
      sum += f(d, wi, v3(s * cos(p), s * sin(p), z));
    }
  }
  return sum * (1.0 / nz) * (2.0 * RSW_PI / np);
}
static double f_d_cos(const mf_distr *d, vec3 wi, vec3 m) {
  (void)wi;
  return mf_D(d, m) * m.z;
}
static double f_visible(const mf_distr *d, vec3 wi, vec3 m) {
  return mf_smith_g1(d, wi, m) * fmax(0.0, v3_dot(wi, m)) * mf_D(d, m);
}

static double f_pdf(const mf_distr *d, vec3 wi, vec3 m) {
  return mf_pdf(d, wi, m);
}

static void test_microfacet_normalisation(void) {
  /* Projected microfacet area is one: int D(m) cos(theta_m) dm = 1, and
   * the visible projected area equals the macro-surface's:
   * int G1(wi, m) max(0, wi.m) D(m) dm = cos(theta_i) (exact for GGX's
   * Smith G1; within the rational fit's 0.35 % for Beckmann). The density
   * of visible normals, which uses the exact G1 (mf_visible_g1), integrates
   * to one also for Beckmann, at grazing incidence too. */
  const mf_type types[2] = {MF_BECKMANN, MF_GGX};
  const double alphas[3][2] = {{0.3, 0.3}, {0.8, 0.8}, {0.3, 0.6}};
  for (int t = 0; t < 2; t++)
    for (int a = 0; a < 3; a++) {
      mf_distr d = mf_make(types[t], alphas[a][0], alphas[a][1], true);
      CHECK_REL(hemi_integral(&d, v3(0, 0, 1), f_d_cos), 1.0, types[t] == MF_GGX ? 5e-3 : 1e-3);
      vec3 wi = tb_dir_deg(60.0, 30.0);
      CHECK_REL(hemi_integral(&d, wi, f_visible), wi.z, types[t] == MF_GGX ? 5e-3 : 5e-3);
      for (int i = 0; i < 2; i++) {
        vec3 wv = tb_dir_deg(i == 0 ? 60.0 : 80.0, 30.0);
        CHECK_REL(hemi_integral(&d, wv, f_pdf), 1.0, 1e-4);
      }
    }
  /* D is zeroed where D cos <= 1e-20 and below the horizon. */
  mf_distr d = mf_make(MF_BECKMANN, 0.05, 0.05, true);
  CHECK(mf_D(&d, tb_dir_deg(80.0, 0.0)) == 0.0, "Beckmann tail underflows to 0");
  CHECK(mf_D(&d, v3(0, 0, -1)) == 0.0, "D = 0 below the horizon");
  /* G1 = 1 at normal incidence, 0 for a back-facing microfacet. */
  CHECK(mf_smith_g1(&d, v3(0, 0, 1), v3(0, 0, 1)) == 1.0, "G1(n, n) = 1");
  CHECK(mf_smith_g1(&d, tb_dir_deg(80.0, 0.0), tb_dir_deg(-15.0, 0.0)) == 0.0, "G1 back-facing = 0");
  CHECK(mf_visible_g1(&d, v3(0, 0, 1), v3(0, 0, 1)) == 1.0, "exact G1(n, n) = 1");
  CHECK(mf_visible_g1(&d, tb_dir_deg(80.0, 0.0), tb_dir_deg(-15.0, 0.0)) == 0.0, "exact G1 back-facing = 0");
  CHECK(mf_visible_g1(&d, v3(1, 0, 0), v3(0, 0, 1)) == 0.0, "exact G1 at the horizon = 0");
  /* Exact Beckmann G1 = 2 / (1 + erf(a) + exp(-a^2) / (a sqrt(pi))) with
   * a = 1 / (alpha tan theta): at a = 1, 2 / (1 + erf(1) + 1 / (e sqrt(pi))),
   * with alpha_u, alpha_v stretching the slope (here along y). The
   * rational fit stays within its documented 0.35 % of it (Mitsuba). */
  mf_distr da = mf_make(MF_BECKMANN, 0.2, 0.5, true);
  vec3 v = v3_norm(v3(0.0, 2.0, 1.0)); /* alpha_v tan theta = 1 */
  CHECK_REL(mf_visible_g1(&da, v, v3(0, 0, 1)), 2.0 / (1.0 + erf(1.0) + exp(-1.0) / sqrt(RSW_PI)), 1e-14);
  for (double a = 0.01; a < 3.0; a *= 1.05) {
    vec3 w = v3_norm(v3(0.0, 1.0 / (0.5 * a), 1.0));
    double exact = mf_visible_g1(&da, w, v3(0, 0, 1)), fit = mf_smith_g1(&da, w, v3(0, 0, 1));
    CHECK(fabs(fit / exact - 1.0) < 3.5e-3, "a = %g: fit %.6f vs exact %.6f", a, fit, exact);
  }
  /* GGX: the closed form is exact; both are the same function. */
  mf_distr dg = mf_make(MF_GGX, 0.2, 0.5, true);
  CHECK(mf_visible_g1(&dg, v, v3(0, 0, 1)) == mf_smith_g1(&dg, v, v3(0, 0, 1)), "GGX G1");
}

/* ---- diffuse ------------------------------------------------------------------------ */

static void test_diffuse(void) {
  texture *rho = uniform_texture_const(0.7, "rho");
  bsdf *b = diffuse_new(rho);
  REQUIRE(b && rho, "allocation");
  CHECK(b->flags == BSDF_DIFFUSE_REFLECTION, "flags");
  for (int a = 0; a < 3; a++) run_chi2(b, tb_dir_deg(incidence_deg[a], 20.0), "diffuse", 8);
  surface_interaction si = tb_si_with(tb_dir_deg(30.0, 0.0));
  vec3 wo = tb_dir_deg(50.0, 120.0);
  CHECK_REL(b->ops->eval(b, &si, wo).c[0], 0.7 / RSW_PI * wo.z, 1e-14);
  CHECK_REL(b->ops->pdf(b, &si, wo), wo.z / RSW_PI, 1e-14);
  /* One-sided: black from the back and towards the back. */
  CHECK(b->ops->eval(b, &si, v3(0, 0.6, -0.8)).c[0] == 0.0, "eval below the horizon");
  surface_interaction back = tb_si_with(v3(0, 0.6, -0.8));
  CHECK(b->ops->eval(b, &back, wo).c[0] == 0.0, "eval from the back");
  bsdf_sample bs;
  color w = b->ops->sample(b, &back, 0.5, v2(0.3, 0.3), &bs);
  CHECK(col_is_black(w) && bs.pdf == 0.0, "sample from the back fails");
  w = b->ops->sample(b, &si, 0.5, v2(0.3, 0.7), &bs);
  CHECK_REL(w.c[0], 0.7, 1e-15);
  CHECK(bs.sampled_type == BSDF_DIFFUSE_REFLECTION && bs.eta == 1.0, "sample record");
  tb_free_bsdf(b);
  tb_free_tex(rho);
}

/* ---- rough conductor ------------------------------------------------------------------ */

static void test_roughconductor_chi2_isotropic(void) {
  const mf_type types[2] = {MF_BECKMANN, MF_GGX};
  const double alphas[3] = {0.05, 0.3, 0.8};
  for (int t = 0; t < 2; t++)
    for (int a = 0; a < 3; a++)
      for (int v = 0; v < 2; v++) {
        rough_case r = rough_make(types[t], alphas[a], alphas[a], v == 0, 0.0, 1.0);
        REQUIRE(r.b, "allocation");
        char what[96];
        snprintf(what, sizeof what, "roughconductor %s alpha %g sample_visible %d", mf_type_name(types[t]),
                 alphas[a], v == 0);
        for (int i = 0; i < 3; i++)
          run_chi2(r.b, tb_dir_deg(incidence_deg[i], 40.0), what, alphas[a] < 0.1 ? 32 : 8);
        rough_free(&r);
      }
}

static void test_roughconductor_chi2_anisotropic(void) {
  const mf_type types[2] = {MF_BECKMANN, MF_GGX};
  for (int t = 0; t < 2; t++)
    for (int v = 0; v < 2; v++) {
      rough_case r = rough_make(types[t], 0.1, 0.5, v == 0, 0.0, 1.0);
      REQUIRE(r.b, "allocation");
      char what[96];
      snprintf(what, sizeof what, "roughconductor %s alpha (0.1, 0.5) sample_visible %d",
               mf_type_name(types[t]), v == 0);
      for (int i = 0; i < 3; i++) run_chi2(r.b, tb_dir_deg(incidence_deg[i], 40.0), what, 8);
      rough_free(&r);
    }
}

/* sample()'s weight equals eval/pdf and its pdf equals pdf(), for the
 * smooth lobes, over many samples. */
static void check_weight_consistency(const bsdf *b, vec3 wi, const char *what) {
  surface_interaction si = tb_si_with(wi);
  pcg32 rng;
  pcg32_seed(&rng, 7, 11);
  int bad = 0, ok = 0;
  for (int i = 0; i < 20000; i++) {
    bsdf_sample bs;
    double u1 = pcg32_next_double(&rng);
    vec2 u2 = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
    color w = b->ops->sample(b, &si, u1, u2, &bs);
    if (!(bs.pdf > 0.0)) continue;
    double pdf = b->ops->pdf(b, &si, bs.wo);
    color f = b->ops->eval(b, &si, bs.wo);
    for (int c = 0; c < 3; c++) {
      double expect = f.c[c] / pdf;
      if (!(fabs(w.c[c] - expect) <= 1e-9 * fmax(fabs(expect), 1e-300)) ||
          !(fabs(pdf - bs.pdf) <= 1e-9 * pdf)) {
        if (bad++ == 0)
          CHECK(false, "%s: weight %.17g vs eval/pdf %.17g, pdf %.17g vs %.17g", what, w.c[c], expect, bs.pdf,
                pdf);
      }
    }
    ok++;
  }
  CHECK(bad == 0, "%s: %d inconsistent samples", what, bad);
  CHECK(ok > 1000, "%s: only %d successful samples", what, ok);
}

static void test_weight_is_eval_over_pdf(void) {
  texture *rho = uniform_texture_const(0.6, "rho");
  bsdf *d = diffuse_new(rho);
  REQUIRE(d, "allocation");
  for (int i = 0; i < 3; i++) check_weight_consistency(d, tb_dir_deg(incidence_deg[i], 10.0), "diffuse");
  tb_free_bsdf(d);
  tb_free_tex(rho);
  const mf_type types[2] = {MF_BECKMANN, MF_GGX};
  for (int t = 0; t < 2; t++)
    for (int v = 0; v < 2; v++) {
      /* A coloured conductor (rgb-like eta/k differ per channel is covered
       * by fresnel tests; here a single gold-like index). */
      rough_case r = rough_make(types[t], 0.3, 0.3, v == 0, 0.2, 3.0);
      rough_case ra = rough_make(types[t], 0.1, 0.5, v == 0, 1.3, 2.0);
      REQUIRE(r.b && ra.b, "allocation");
      for (int i = 0; i < 3; i++) {
        check_weight_consistency(r.b, tb_dir_deg(incidence_deg[i], 10.0), "roughconductor");
        check_weight_consistency(ra.b, tb_dir_deg(incidence_deg[i], 70.0), "roughconductor aniso");
      }
      rough_free(&r);
      rough_free(&ra);
    }
}

static void test_reciprocity(void) {
  texture *rho = uniform_texture_const(0.6, "rho");
  bsdf *d = diffuse_new(rho);
  rough_case r1 = rough_make(MF_BECKMANN, 0.3, 0.3, true, 0.2, 3.0);
  rough_case r2 = rough_make(MF_GGX, 0.1, 0.5, true, 1.3, 2.0);
  REQUIRE(d && r1.b && r2.b, "allocation");
  const bsdf *bs[3] = {d, r1.b, r2.b};
  pcg32 rng;
  pcg32_seed(&rng, 3, 5);
  for (int n = 0; n < 3; n++)
    for (int i = 0; i < 2000; i++) {
      vec3 a = warp_square_to_uniform_hemisphere(v2(pcg32_next_double(&rng), pcg32_next_double(&rng)));
      vec3 b = warp_square_to_uniform_hemisphere(v2(pcg32_next_double(&rng), pcg32_next_double(&rng)));
      if (a.z < 1e-3 || b.z < 1e-3) continue;
      surface_interaction sa = tb_si_with(a), sb = tb_si_with(b);
      double fab = bs[n]->ops->eval(bs[n], &sa, b).c[0] / b.z;
      double fba = bs[n]->ops->eval(bs[n], &sb, a).c[0] / a.z;
      CHECK(fabs(fab - fba) <= 1e-10 * fmax(fab, fba), "reciprocity of %s: %g vs %g",
            bs[n]->base.plugin->name, fab, fba);
    }
  tb_free_bsdf(d);
  tb_free_tex(rho);
  rough_free(&r1);
  rough_free(&r2);
}

/* White furnace: with F = 1 (eta = 0, k = 1) the directional albedo
 * int f_r cos dwo = E[weight] can only lose energy (single scattering
 * with Smith masking) and loses almost none at low roughness. 200,000
 * samples; the bound allows 4 standard errors. */
static void test_white_furnace(void) {
  const mf_type types[2] = {MF_BECKMANN, MF_GGX};
  const double alphas[3] = {0.05, 0.3, 0.8};
  for (int t = 0; t < 2; t++)
    for (int a = 0; a < 3; a++)
      for (int v = 0; v < 2; v++) {
        rough_case r = rough_make(types[t], alphas[a], alphas[a], v == 0, 0.0, 1.0);
        REQUIRE(r.b, "allocation");
        for (int i = 0; i < 2; i++) {
          surface_interaction si = tb_si_with(tb_dir_deg(incidence_deg[i], 0.0));
          pcg32 rng;
          pcg32_seed(&rng, 17, 23);
          const int n = 200000;
          double sum = 0.0, sum2 = 0.0;
          for (int s = 0; s < n; s++) {
            bsdf_sample bs;
            color w = r.b->ops->sample(r.b, &si, pcg32_next_double(&rng),
                                       v2(pcg32_next_double(&rng), pcg32_next_double(&rng)), &bs);
            sum += w.c[0];
            sum2 += w.c[0] * w.c[0];
          }
          double mean = sum / n, se = sqrt(fmax(0.0, sum2 / n - mean * mean) / n);
          CHECK(mean <= 1.0 + 4.0 * se + 1e-12, "%s alpha %g visible %d theta %g: albedo %g > 1",
                mf_type_name(types[t]), alphas[a], v == 0, incidence_deg[i], mean);
          if (alphas[a] <= 0.05)
            CHECK(mean >= 0.99, "%s alpha %g visible %d theta %g: albedo %g not close to 1",
                  mf_type_name(types[t]), alphas[a], v == 0, incidence_deg[i], mean);
        }
        rough_free(&r);
      }
}

static void test_roughconductor_edges(void) {
  rough_case r = rough_make(MF_GGX, 0.3, 0.3, true, 0.0, 1.0);
  REQUIRE(r.b, "allocation");
  CHECK(r.b->flags == BSDF_GLOSSY_REFLECTION, "flags");
  surface_interaction back = tb_si_with(v3(0, 0.6, -0.8));
  bsdf_sample bs;
  color w = r.b->ops->sample(r.b, &back, 0.5, v2(0.4, 0.4), &bs);
  CHECK(col_is_black(w) && bs.pdf == 0.0, "sample from the back fails");
  CHECK(r.b->ops->eval(r.b, &back, v3(0, 0, 1)).c[0] == 0.0, "eval from the back");
  surface_interaction si = tb_si_with(tb_dir_deg(30.0, 0.0));
  CHECK(r.b->ops->eval(r.b, &si, v3(0, 0.6, -0.8)).c[0] == 0.0, "eval below the horizon");
  CHECK(r.b->ops->pdf(r.b, &si, v3(0, 0.6, -0.8)) == 0.0, "pdf below the horizon");
  /* The eval formula at one point, written out: F D G / (4 cos_i). */
  vec3 wi = tb_dir_deg(30.0, 0.0), wo = tb_dir_deg(45.0, 160.0), h = v3_norm(v3_add(wi, wo));
  double a = 0.3, c = h.z, t2 = (h.x * h.x + h.y * h.y) / (c * c);
  double D = 1.0 / (RSW_PI * a * a * c * c * c * c * (1 + t2 / (a * a)) * (1 + t2 / (a * a)));
  double ti = (a * a) * (wi.x * wi.x + wi.y * wi.y) / (wi.z * wi.z);
  double to = (a * a) * (wo.x * wo.x + wo.y * wo.y) / (wo.z * wo.z);
  double G = 2.0 / (1.0 + sqrt(1.0 + ti)) * 2.0 / (1.0 + sqrt(1.0 + to));
  CHECK_REL(r.b->ops->eval(r.b, &si, wo).c[0], D * G / (4.0 * wi.z), 1e-12);
  rough_free(&r);
}

/* ---- smooth conductor and presets ---------------------------------------------------- */

static void test_conductor_smooth(void) {
  texture *eta = uniform_texture_const(0.0, "eta"), *k = uniform_texture_const(1.0, "k");
  texture *spec = uniform_texture_const(0.8, "spec");
  bsdf *mirror = conductor_new(eta, k, NULL, NULL, NULL);
  bsdf *tinted = conductor_new(eta, k, NULL, spec, NULL);
  REQUIRE(mirror && tinted, "allocation");
  CHECK(mirror->flags == BSDF_DELTA_REFLECTION, "flags");
  for (int i = 0; i < 3; i++) {
    vec3 wi = tb_dir_deg(incidence_deg[i], 33.0);
    surface_interaction si = tb_si_with(wi);
    bsdf_sample bs;
    color w = mirror->ops->sample(mirror, &si, 0.3, v2(0.2, 0.9), &bs);
    CHECK_REL(w.c[0], 1.0, 1e-12);
    CHECK_ABS(bs.wo.x, -wi.x, 1e-15);
    CHECK_ABS(bs.wo.y, -wi.y, 1e-15);
    CHECK_ABS(bs.wo.z, wi.z, 1e-15);
    CHECK(bs.pdf == 1.0 && bs.sampled_type == BSDF_DELTA_REFLECTION, "delta sample record");
    CHECK(mirror->ops->eval(mirror, &si, bs.wo).c[0] == 0.0, "delta eval is 0");
    CHECK(mirror->ops->pdf(mirror, &si, bs.wo) == 0.0, "delta pdf is 0");
    w = tinted->ops->sample(tinted, &si, 0.3, v2(0.2, 0.9), &bs);
    CHECK_REL(w.c[1], 0.8, 1e-12);
  }
  tb_free_bsdf(mirror);
  tb_free_bsdf(tinted);
  tb_free_tex(eta);
  tb_free_tex(k);
  tb_free_tex(spec);
}

static void test_conductor_presets(void) {
  /* Rows of Mitsuba's data/ios/Au.{eta,k}.spd around 550 nm:
   *   539.061646  eta 0.402000  k 2.540000
   *   551.040771  eta 0.345500  k 2.730625 */
  const ior_conductor *au = ior_conductor_lookup("Au");
  REQUIRE(au, "Au preset exists");
  double t = (550.0 - 539.061646) / (551.040771 - 539.061646);
  double eta_ref = 0.402 + t * (0.3455 - 0.402), k_ref = 2.54 + t * (2.730625 - 2.54);
  double eta, k;
  CHECK(ior_conductor_eval(au, 550.0, &eta, &k), "550 nm inside the Au table");
  CHECK_REL(eta, eta_ref, 1e-12);
  CHECK_REL(k, k_ref, 1e-12);
  /* A table node: Cu at 551.040771 nm is (0.950375, 2.576500). */
  const ior_conductor *cu = ior_conductor_lookup("Cu");
  REQUIRE(cu, "Cu preset exists");
  CHECK(ior_conductor_eval(cu, 551.040771, &eta, &k), "node inside");
  CHECK_REL(eta, 0.950375, 1e-12);
  CHECK_REL(k, 2.5765, 1e-12);
  CHECK(ior_conductor_lookup("Al") && ior_conductor_lookup("Ag") && ior_conductor_lookup("Cr"),
        "Al, Ag, Cr presets exist");
  CHECK(!ior_conductor_lookup("none") && !ior_conductor_lookup("Xx"), "unknown presets");

  /* Mono render context at 550 nm: the BSDF uses the interpolated index. */
  render_ctx mono = {.variant = VARIANT_MONO, .wavelength = 550.0};
  bsdf *b = conductor_new(NULL, NULL, au, NULL, &mono);
  REQUIRE(b, "allocation");
  surface_interaction si = tb_si_with(v3(0, 0, 1));
  bsdf_sample bs;
  color w = b->ops->sample(b, &si, 0.5, v2(0.5, 0.5), &bs);
  double r0 =
      ((eta_ref - 1) * (eta_ref - 1) + k_ref * k_ref) / ((eta_ref + 1) * (eta_ref + 1) + k_ref * k_ref);
  CHECK_REL(w.c[0], r0, 1e-12);
  CHECK(w.c[0] == w.c[1] && w.c[1] == w.c[2], "mono: equal channels");

  /* prepare() re-evaluates for a new wavelength; outside the table is an
   * error that names the material. */
  rsw_err err;
  rsw_err_clear(&err);
  render_ctx far = {.variant = VARIANT_MONO, .wavelength = 1000.0};
  CHECK(plugin_conductor.prepare(&b->base, &far, &err) == RSW_ERR_RANGE, "1000 nm rejected");
  CHECK(strstr(err.msg, "Au") != NULL, "error names the material: %s", err.msg);
  rsw_err_clear(&err);
  render_ctx at_node = {.variant = VARIANT_MONO, .wavelength = 539.061646};
  CHECK(plugin_conductor.prepare(&b->base, &at_node, &err) == RSW_OK, "539 nm accepted");
  w = b->ops->sample(b, &si, 0.5, v2(0.5, 0.5), &bs);
  CHECK_REL(w.c[0], ((0.402 - 1) * (0.402 - 1) + 2.54 * 2.54) / ((1.402) * (1.402) + 2.54 * 2.54), 1e-9);

  /* rgb: the table at 645, 526, 444 nm per channel. */
  render_ctx rgb = {.variant = VARIANT_RGB, .wavelength = 550.0};
  CHECK(plugin_conductor.prepare(&b->base, &rgb, &err) == RSW_OK, "rgb prepare");
  w = b->ops->sample(b, &si, 0.5, v2(0.5, 0.5), &bs);
  const double wl[3] = {645.0, 526.0, 444.0};
  for (int c = 0; c < 3; c++) {
    REQUIRE(ior_conductor_eval(au, wl[c], &eta, &k), "rgb wavelengths inside");
    CHECK_REL(w.c[c], fresnel_conductor(1.0, eta, k), 1e-12);
  }
  CHECK(w.c[0] > w.c[2], "gold reflects more red than blue");
  tb_free_bsdf(b);
}

/* ---- dielectric ----------------------------------------------------------------------- */

static void test_dielectric(void) {
  double ior;
  CHECK(ior_dielectric_lookup("bk7", &ior) && ior == 1.5046, "bk7");
  CHECK(ior_dielectric_lookup("Air", &ior) && ior == 1.000277, "air (case-insensitive)");
  CHECK(ior_dielectric_lookup("water", &ior) && ior == 1.3330, "water");
  CHECK(ior_dielectric_lookup("fused quartz", &ior) && ior == 1.458, "fused quartz");
  CHECK(ior_dielectric_lookup("polypropylene", &ior) && ior == 1.49, "polypropylene");
  CHECK(ior_dielectric_lookup("diamond", &ior) && ior == 2.419, "diamond");
  CHECK(ior_dielectric_lookup("vacuum", &ior) && ior == 1.0, "vacuum");
  CHECK(!ior_dielectric_lookup("unobtainium", &ior), "unknown name");

  bsdf *b = dielectric_new(1.5046, 1.000277, NULL, NULL);
  REQUIRE(b, "allocation");
  double eta = 1.5046 / 1.000277;
  CHECK(b->flags & BSDF_DELTA_TRANSMISSION, "flags");
  const double thetas[] = {0.0, 20.0, 45.0, 60.0, 85.0};
  for (int side = 0; side < 2; side++)
    for (int i = 0; i < 5; i++) {
      vec3 wi = tb_dir_deg(thetas[i], 25.0);
      if (side) wi.z = -wi.z;
      surface_interaction si = tb_si_with(wi);
      bsdf_sample br, bt;
      color wr = b->ops->sample(b, &si, 0.0, v2(0.5, 0.5), &br);
      color wt = b->ops->sample(b, &si, 0.999999, v2(0.5, 0.5), &bt);
      double r = fresnel_dielectric(wi.z, eta, NULL, NULL, NULL);
      CHECK(br.sampled_type == BSDF_DELTA_REFLECTION, "reflection chosen for u1 = 0");
      CHECK_REL(br.pdf, r, 1e-12);
      CHECK_REL(wr.c[0], 1.0, 1e-12);
      CHECK_ABS(br.wo.z, wi.z, 1e-15);
      if (r == 1.0) {
        /* Total internal reflection: only reflection, with probability 1. */
        CHECK(side == 1 && bt.sampled_type == BSDF_DELTA_REFLECTION && bt.pdf == 1.0,
              "TIR only from inside, reflecting");
        continue;
      }
      CHECK(bt.sampled_type == BSDF_DELTA_TRANSMISSION, "transmission chosen for u1 ~ 1");
      /* R + T = 1. */
      CHECK_REL(br.pdf + bt.pdf, 1.0, 1e-12);
      /* Snell: eta_i sin_i = eta_t sin_t, on the other side, opposite
       * azimuth, unit length. */
      double eta_i = side ? eta : 1.0, eta_t = side ? 1.0 : eta;
      double sin_i = sqrt(wi.x * wi.x + wi.y * wi.y);
      double sin_t = sqrt(bt.wo.x * bt.wo.x + bt.wo.y * bt.wo.y);
      CHECK_ABS(eta_i * sin_i, eta_t * sin_t, 1e-12);
      CHECK(bt.wo.z * wi.z < 0.0, "transmitted direction on the other side");
      CHECK_REL(v3_len(bt.wo), 1.0, 1e-12);
      if (sin_i > 0) CHECK(bt.wo.x * wi.x <= 0 && bt.wo.y * wi.y <= 0, "opposite azimuth");
      /* Radiance weight (eta_t / eta_i)^-2 and the sample's eta. */
      CHECK_REL(wt.c[0], (eta_i / eta_t) * (eta_i / eta_t), 1e-12);
      CHECK_REL(bt.eta, eta_t / eta_i, 1e-12);
      CHECK(b->ops->eval(b, &si, bt.wo).c[0] == 0.0 && b->ops->pdf(b, &si, bt.wo) == 0.0,
            "delta: eval = pdf = 0");
    }
  /* Total internal reflection from inside at 60 degrees (critical ~41.7). */
  vec3 wi = tb_dir_deg(60.0, 0.0);
  wi.z = -wi.z;
  surface_interaction si = tb_si_with(wi);
  bsdf_sample bs;
  color w = b->ops->sample(b, &si, 0.999999, v2(0.5, 0.5), &bs);
  CHECK(bs.sampled_type == BSDF_DELTA_REFLECTION && bs.pdf == 1.0 && w.c[0] == 1.0,
        "TIR reflects with probability 1");
  tb_free_bsdf(b);
}

/* ---- twosided --------------------------------------------------------------------------- */

static void test_twosided(void) {
  texture *rho = uniform_texture_const(0.4, "rho");
  bsdf *front = diffuse_new(rho);
  rough_case back = rough_make(MF_GGX, 0.3, 0.3, true, 0.0, 1.0);
  REQUIRE(front && back.b, "allocation");
  bsdf *one = twosided_new(front, NULL);
  bsdf *two = twosided_new(front, back.b);
  REQUIRE(one && two, "allocation");
  CHECK(one->flags & BSDF_TWO_SIDED, "flags");
  vec3 wi_back = tb_dir_deg(120.0, 30.0); /* 60 degrees from the back */
  run_chi2(one, wi_back, "twosided(diffuse) from the back", 8);
  run_chi2(two, wi_back, "twosided(diffuse, roughconductor ggx 0.3) from the back", 8);
  /* Back side = the nested BSDF with both directions mirrored. */
  surface_interaction sb = tb_si_with(wi_back), sf = tb_si_with(v3(wi_back.x, wi_back.y, -wi_back.z));
  vec3 wo = tb_dir_deg(130.0, 200.0), wo_m = v3(wo.x, wo.y, -wo.z);
  CHECK_REL(two->ops->eval(two, &sb, wo).c[0], back.b->ops->eval(back.b, &sf, wo_m).c[0], 1e-15);
  CHECK_REL(two->ops->pdf(two, &sb, wo), back.b->ops->pdf(back.b, &sf, wo_m), 1e-15);
  CHECK_REL(one->ops->eval(one, &sb, wo).c[0], 0.4 / RSW_PI * fabs(wo.z), 1e-14);
  /* Front side is the front BSDF; wo on the other side is black. */
  CHECK_REL(two->ops->eval(two, &sf, wo_m).c[0], 0.4 / RSW_PI * wo_m.z, 1e-14);
  CHECK(two->ops->eval(two, &sb, wo_m).c[0] == 0.0, "no transmission through twosided");
  bsdf_sample bs;
  two->ops->sample(two, &sb, 0.5, v2(0.3, 0.6), &bs);
  CHECK(bs.pdf > 0 && bs.wo.z < 0.0, "back-side sample stays on the back");
  check_weight_consistency(two, wi_back, "twosided back");
  tb_free_bsdf(one);
  tb_free_bsdf(two);
  tb_free_bsdf(front);
  rough_free(&back);
  tb_free_tex(rho);
}

/* ---- the plugins through the scene loader ------------------------------------------- */

/* Load a JSON document in `variant`; returns the status (and the scene on
 * success, else NULL) with err filled. */
static rsw_status load_json(const char *text, const char *variant, scene **out, rsw_err *err) {
  scene_load_opts o = {.size = sizeof o, .variant = variant};
  rsw_err_clear(err);
  *out = NULL;
  return scene_load_memory(text, strlen(text), "test_bsdf", false, &o, out, err);
}

/* The BSDF with that id (textures made from its properties may carry the
 * same id). */
static object *find_object(const scene *s, const char *id) {
  for (size_t i = 0; i < s->n_objects; i++)
    if (s->objects[i]->id && strcmp(s->objects[i]->id, id) == 0 && s->objects[i]->plugin->cls == CLS_BSDF)
      return s->objects[i];
  return NULL;
}

static double tex_value(const texture *t) {
  color c = col1(NAN);
  if (!t || !uniform_texture_value(t, &c)) return NAN;
  return c.c[0];
}

static void test_loader_defaults(void) {
  const char *doc =
      "{\"type\": \"scene\","
      " \"d\": {\"type\": \"diffuse\"},"
      " \"c\": {\"type\": \"conductor\"},"
      " \"r\": {\"type\": \"roughconductor\"},"
      " \"g\": {\"type\": \"dielectric\"},"
      " \"t\": {\"type\": \"twosided\", \"inner\": {\"type\": \"diffuse\", \"reflectance\": 0.25}}}";
  scene *s;
  rsw_err err;
  rsw_status st = load_json(doc, "mono", &s, &err);
  REQUIRE(st == RSW_OK, "load: %s: %s", err.where, err.msg);
  diffuse_bsdf *d = (diffuse_bsdf *)find_object(s, "d");
  conductor_bsdf *c = (conductor_bsdf *)find_object(s, "c");
  roughconductor_bsdf *r = (roughconductor_bsdf *)find_object(s, "r");
  dielectric_bsdf *g = (dielectric_bsdf *)find_object(s, "g");
  twosided_bsdf *t = (twosided_bsdf *)find_object(s, "t");
  REQUIRE(d && c && r && g && t, "all five BSDFs built");
  CHECK(tex_value(d->reflectance) == 0.5, "diffuse reflectance 0.5");
  CHECK(!c->ior.material && tex_value(c->ior.eta) == 0.0 && tex_value(c->ior.k) == 1.0,
        "conductor eta 0, k 1");
  CHECK(tex_value(c->specular_reflectance) == 1.0, "conductor specular_reflectance 1");
  CHECK(r->type == MF_BECKMANN && r->sample_visible && r->alpha_u == r->alpha_v &&
            tex_value(r->alpha_u) == 0.1 && !r->specular_reflectance,
        "roughconductor: beckmann, alpha 0.1, sample_visible, no specular_reflectance");
  CHECK_REL(g->eta, 1.5046 / 1.000277, 1e-15);
  CHECK(t->brdf[0] == t->brdf[1] && t->brdf[0]->base.plugin == &plugin_diffuse, "twosided: back = front");
  CHECK(t->base.flags == (BSDF_DIFFUSE_REFLECTION | BSDF_TWO_SIDED), "twosided flags");
  scene_free(s);
}

static void test_loader_options(void) {
  const char *doc = "{\"type\": \"scene\","
                    " \"r\": {\"type\": \"roughconductor\", \"distribution\": \"GGX\", \"alpha_u\": 0.1,"
                    "        \"alpha_v\": 0.4, \"sample_visible\": false, \"eta\": 0.2, \"k\": 3.0,"
                    "        \"specular_reflectance\": 0.9},"
                    " \"a\": {\"type\": \"conductor\", \"material\": \"Au\"},"
                    " \"g\": {\"type\": \"dielectric\", \"int_ior\": \"water\", \"ext_ior\": 1.0},"
                    " \"t\": {\"type\": \"twosided\", \"f\": {\"type\": \"diffuse\"},"
                    "        \"b\": {\"type\": \"conductor\"}}}";
  scene *s;
  rsw_err err;
  rsw_status st = load_json(doc, "mono", &s, &err);
  REQUIRE(st == RSW_OK, "load: %s: %s", err.where, err.msg);
  roughconductor_bsdf *r = (roughconductor_bsdf *)find_object(s, "r");
  conductor_bsdf *a = (conductor_bsdf *)find_object(s, "a");
  dielectric_bsdf *g = (dielectric_bsdf *)find_object(s, "g");
  twosided_bsdf *t = (twosided_bsdf *)find_object(s, "t");
  REQUIRE(r && a && g && t, "built");
  CHECK(r->type == MF_GGX && !r->sample_visible, "ggx, sample_visible false");
  CHECK(tex_value(r->alpha_u) == 0.1 && tex_value(r->alpha_v) == 0.4, "alpha_u/alpha_v");
  CHECK(tex_value(r->ior.eta) == 0.2 && tex_value(r->ior.k) == 3.0, "eta/k");
  CHECK(tex_value(r->specular_reflectance) == 0.9, "specular_reflectance");
  CHECK(a->ior.material && strcmp(a->ior.material->name, "Au") == 0, "Au preset");
  CHECK_REL(g->eta, 1.3330, 1e-15);
  CHECK(t->brdf[0]->base.plugin == &plugin_diffuse && t->brdf[1]->base.plugin == &plugin_conductor,
        "twosided front/back in declaration order");

  /* A render at 550 nm and one outside the Au table. */
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 550.0};
  rsw_err_clear(&err);
  CHECK(scene_prepare(s, &rc, &err) == RSW_OK, "prepare at 550 nm: %s", err.msg);
  rc.wavelength = 2000.0;
  rsw_err_clear(&err);
  CHECK(scene_prepare(s, &rc, &err) == RSW_ERR_RANGE, "prepare at 2000 nm fails");
  CHECK(strstr(err.msg, "Au") != NULL, "the error names the material: %s", err.msg);
  scene_free(s);
}

static void test_loader_errors(void) {
  static const struct {
    const char *doc;
    rsw_status code;
  } cases[] = {
      {"{\"type\": \"scene\", \"c\": {\"type\": \"conductor\", \"material\": \"Au\", \"eta\": 0.2}}",
       RSW_ERR_INVALID},
      {"{\"type\": \"scene\", \"c\": {\"type\": \"conductor\", \"material\": \"Xx\"}}", RSW_ERR_INVALID},
      {"{\"type\": \"scene\", \"c\": {\"type\": \"conductor\", \"material\": \"Au\", \"k\": 2}}",
       RSW_ERR_UNUSED_PROPERTY},
      {"{\"type\": \"scene\", \"r\": {\"type\": \"roughconductor\", \"material\": \"Cu\", \"eta\": 1}}",
       RSW_ERR_INVALID},
      {"{\"type\": \"scene\", \"r\": {\"type\": \"roughconductor\", \"alpha\": 0.1, \"alpha_u\": 0.2,"
       " \"alpha_v\": 0.3}}",
       RSW_ERR_INVALID},
      {"{\"type\": \"scene\", \"r\": {\"type\": \"roughconductor\", \"alpha_u\": 0.2}}", RSW_ERR_MISSING},
      {"{\"type\": \"scene\", \"r\": {\"type\": \"roughconductor\", \"distribution\": \"phong\"}}",
       RSW_ERR_INVALID},
      {"{\"type\": \"scene\", \"g\": {\"type\": \"dielectric\", \"int_ior\": \"unobtainium\"}}",
       RSW_ERR_INVALID},
      {"{\"type\": \"scene\", \"g\": {\"type\": \"dielectric\", \"ext_ior\": -1.0}}", RSW_ERR_RANGE},
      {"{\"type\": \"scene\", \"t\": {\"type\": \"twosided\"}}", RSW_ERR_MISSING},
      {"{\"type\": \"scene\", \"t\": {\"type\": \"twosided\", \"a\": {\"type\": \"dielectric\"}}}",
       RSW_ERR_INVALID},
      {"{\"type\": \"scene\", \"t\": {\"type\": \"twosided\", \"a\": {\"type\": \"diffuse\"},"
       " \"b\": {\"type\": \"diffuse\"}, \"c\": {\"type\": \"diffuse\"}}}",
       RSW_ERR_INVALID},
      {"{\"type\": \"scene\", \"d\": {\"type\": \"diffuse\", \"reflectance\": -0.5}}", RSW_ERR_RANGE},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    scene *s;
    rsw_err err;
    rsw_status st = load_json(cases[i].doc, "mono", &s, &err);
    CHECK(st == cases[i].code, "case %zu: got %s (%s: %s), expected %s", i, rsw_status_name(st), err.where,
          err.msg, rsw_status_name(cases[i].code));
    CHECK(st == RSW_OK || err.where[0] != '\0', "case %zu: the error names a place", i);
    scene_free(s);
  }
}

int main(void) {
  RSW_TEST_RUN(test_fresnel_conductor);
  RSW_TEST_RUN(test_fresnel_dielectric);
  RSW_TEST_RUN(test_erfinv);
  RSW_TEST_RUN(test_erff);
  RSW_TEST_RUN(test_microfacet_normalisation);
  RSW_TEST_RUN(test_diffuse);
  RSW_TEST_RUN(test_roughconductor_edges);
  RSW_TEST_RUN(test_weight_is_eval_over_pdf);
  RSW_TEST_RUN(test_reciprocity);
  RSW_TEST_RUN(test_white_furnace);
  RSW_TEST_RUN(test_conductor_smooth);
  RSW_TEST_RUN(test_conductor_presets);
  RSW_TEST_RUN(test_dielectric);
  RSW_TEST_RUN(test_twosided);
  RSW_TEST_RUN(test_loader_defaults);
  RSW_TEST_RUN(test_loader_options);
  RSW_TEST_RUN(test_loader_errors);
  RSW_TEST_RUN(test_roughconductor_chi2_isotropic);
  RSW_TEST_RUN(test_roughconductor_chi2_anisotropic);
  RSW_TEST_END("test_bsdf");
}
