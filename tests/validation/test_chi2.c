/* Tests of the chi-square test library itself (tests/support/chi2.c): the
 * regularised incomplete gamma function against closed forms and table
 * values, and chi2_run on self-contained samplers (a correct one must
 * pass, a wrong pdf and an out-of-domain sampler must fail). */
#include <math.h>
#include <stdint.h>

#include "../support/chi2.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

/* P(n, x) for integer n: 1 - e^-x sum_{k<n} x^k / k! (Poisson tail). */
static double gamma_p_integer(int n, double x) {
  double term = exp(-x), sum = 0.0;
  for (int k = 0; k < n; k++) {
    sum += term;
    term *= x / (k + 1);
  }
  return 1.0 - sum;
}

static void test_gamma_p_closed_forms(void) {
  /* a = 1: P = 1 - e^-x; a = 1/2: P = erf(sqrt x). Both branches (series
   * for x < a + 1, continued fraction above) are exercised. */
  const double xs[] = {1e-3, 0.1, 0.5, 1.0, 1.9, 2.1, 5.0, 20.0};
  for (size_t i = 0; i < sizeof xs / sizeof xs[0]; i++) {
    double x = xs[i];
    CHECK_REL(chi2_gamma_p(1.0, x), 1.0 - exp(-x), 1e-12);
    CHECK_REL(chi2_gamma_p(0.5, x), erf(sqrt(x)), 1e-12);
    /* Recurrence P(a+1, x) = P(a, x) - x^a e^-x / Gamma(a+1) at a = 1/2. */
    double p15 = erf(sqrt(x)) - sqrt(x) * exp(-x) / tgamma(1.5);
    CHECK_ABS(chi2_gamma_p(1.5, x), p15, 1e-13);
  }
  const int ns[] = {2, 5, 10, 50};
  const double fr[] = {0.3, 0.9, 1.0, 1.1, 2.0};
  for (size_t i = 0; i < sizeof ns / sizeof ns[0]; i++)
    for (size_t j = 0; j < sizeof fr / sizeof fr[0]; j++) {
      double x = fr[j] * ns[i];
      CHECK_ABS(chi2_gamma_p(ns[i], x), gamma_p_integer(ns[i], x), 1e-12);
    }
}

static void test_gamma_p_table_values(void) {
  /* Chi-square quantiles from standard tables (e.g. NIST/SEMATECH
   * e-Handbook 1.3.6.7.4): CDF_k(q) = P(k/2, q/2). Table values carry 6
   * significant digits, hence the tolerance. */
  CHECK_ABS(chi2_gamma_p(0.5, 3.841459 / 2), 0.95, 1e-6);
  CHECK_ABS(chi2_gamma_p(1.0, 5.991465 / 2), 0.95, 1e-6);
  CHECK_ABS(chi2_gamma_p(5.0, 18.307038 / 2), 0.95, 1e-6);
  CHECK_ABS(chi2_gamma_p(5.0, 23.209251 / 2), 0.99, 1e-6);
  CHECK_ABS(chi2_gamma_p(50.0, 124.342113 / 2), 0.95, 1e-6);
  CHECK_ABS(chi2_gamma_p(50.0, 135.806723 / 2), 0.99, 1e-6);
  CHECK_ABS(chi2_gamma_p(50.0, 77.929465 / 2), 0.05, 1e-6);
  /* Large a, as for ~5000 cells: the median of Gamma(a) is close to
   * a - 1/3 (Choi 1994), so P(a, a - 1/3) ~ 1/2 within O(1/a). */
  CHECK_ABS(chi2_gamma_p(2500.0, 2500.0 - 1.0 / 3.0), 0.5, 1e-4);
  /* Edges and bad input. */
  CHECK(chi2_gamma_p(3.0, 0.0) == 0.0, "P(a, 0) = 0");
  CHECK_ABS(chi2_gamma_p(3.0, 1e3), 1.0, 1e-15);
  CHECK(isnan(chi2_gamma_p(0.0, 1.0)), "a = 0 is not defined");
  CHECK(isnan(chi2_gamma_p(1.0, -1.0)), "x < 0 is not defined");
}

/* Uniform sphere drawn inline (z = 1 - 2 u1, phi = 2 pi u0), so this test
 * does not depend on warp.c. */
static bool sample_sphere(void *user, const double *u, vec3 *out, double *w) {
  (void)user;
  double z = 1.0 - 2.0 * u[1], r = sqrt(fmax(0.0, 1.0 - z * z));
  double phi = 2.0 * RSW_PI * u[0];
  *out = v3(r * cos(phi), r * sin(phi), z);
  *w = 1.0;
  return true;
}
static double pdf_sphere(void *user, vec3 v) {
  (void)user;
  (void)v;
  return RSW_INV_4PI;
}
/* A density that integrates to 1 but does not match the sampler. */
static double pdf_sphere_tilted(void *user, vec3 v) {
  (void)user;
  return RSW_INV_4PI * (1.0 + 0.1 * v.z);
}
static bool sample_off_sphere(void *user, const double *u, vec3 *out, double *w) {
  sample_sphere(user, u, out, w);
  *out = v3_scale(*out, 1.01);
  return true;
}
/* Polar disk drawn inline: r = sqrt(u1), phi = 2 pi u0. */
static bool sample_disk(void *user, const double *u, vec3 *out, double *w) {
  (void)user;
  double r = sqrt(u[1]), phi = 2.0 * RSW_PI * u[0];
  *out = v3(r * cos(phi), r * sin(phi), 0.0);
  *w = 1.0;
  return true;
}
static double pdf_disk(void *user, vec3 p) {
  (void)user;
  return p.x * p.x + p.y * p.y <= 1.0 ? RSW_INV_PI : 0.0;
}

static void test_chi2_accepts_correct_sampler(void) {
  /* alpha = 0.01, fixed seed 0: a correct sampler passes. */
  chi2_config c = chi2_defaults(CHI2_SPHERE, 2);
  c.sample_count = 200000;
  chi2_result r = chi2_run(&c, sample_sphere, pdf_sphere, NULL);
  CHECK(r.passed, "uniform sphere: %s (p = %g)", r.reason, r.p_value);
  /* 50 x 101 cells, all with expected ~39.6 >= 5: dof = 5049. */
  CHECK(r.dof == 50 * 101 - 1, "dof = %d", r.dof);

  chi2_config d = chi2_defaults(CHI2_DISK, 2);
  d.sample_count = 200000;
  r = chi2_run(&d, sample_disk, pdf_disk, NULL);
  CHECK(r.passed, "polar disk: %s (p = %g)", r.reason, r.p_value);
}

static void test_chi2_rejects_wrong_pdf(void) {
  chi2_config c = chi2_defaults(CHI2_SPHERE, 2);
  c.sample_count = 200000;
  chi2_result r = chi2_run(&c, sample_sphere, pdf_sphere_tilted, NULL);
  CHECK(!r.passed, "a 10%% tilt must be detected (p = %g)", r.p_value);
  CHECK(r.p_value < 1e-6, "p = %g", r.p_value);
  CHECK(r.reason[0] != '\0', "a reason is given");
}

static void test_chi2_rejects_outside_domain(void) {
  chi2_config c = chi2_defaults(CHI2_SPHERE, 2);
  c.sample_count = 10000;
  chi2_result r = chi2_run(&c, sample_off_sphere, pdf_sphere, NULL);
  CHECK(!r.passed, "samples off the unit sphere must fail");
  CHECK(strstr(r.reason, "outside the domain") != NULL, "reason: %s", r.reason);
}

static void test_chi2_rejects_bad_config(void) {
  chi2_config c = chi2_defaults(CHI2_SPHERE, 2);
  c.res = 1;
  chi2_result r = chi2_run(&c, sample_sphere, pdf_sphere, NULL);
  CHECK(!r.passed && strstr(r.reason, "res") != NULL, "reason: %s", r.reason);
  c = chi2_defaults(CHI2_SPHERE, 0);
  r = chi2_run(&c, sample_sphere, pdf_sphere, NULL);
  CHECK(!r.passed && strstr(r.reason, "sample_dim") != NULL, "reason: %s", r.reason);
}

int main(void) {
  RSW_TEST_RUN(test_gamma_p_closed_forms);
  RSW_TEST_RUN(test_gamma_p_table_values);
  RSW_TEST_RUN(test_chi2_accepts_correct_sampler);
  RSW_TEST_RUN(test_chi2_rejects_wrong_pdf);
  RSW_TEST_RUN(test_chi2_rejects_outside_domain);
  RSW_TEST_RUN(test_chi2_rejects_bad_config);
  RSW_TEST_END("test_chi2");
}
