/* Earth-observation BSDFs (server/kernel/bsdfs/{rpv,bilambertian,hapke}.c):
 * chi-square tests of sample() against pdf() (Mitsuba's procedure,
 * tests/support/chi2.h; 200,000 samples, alpha 0.01 with the Sidak
 * correction over the runs of this file), sampling weight = eval / pdf,
 * RPV reciprocity and its closed form against an independent evaluation
 * from angles (docs/kernel-conventions.md#rpv), bilambertian's two sides, and
 * Hapke's energy bound and h = 0 guard. Fixed seeds throughout. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../support/bsdf_test.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "kernel/bsdfs/bsdfs_internal.h"
#include "kernel/core/rng.h"
#include "kernel/scene/scene.h"
#include "kernel/textures/texture.h"

RSW_TEST_DEFINE_GLOBALS

#define CHI2_SAMPLES 200000
/* rpv 2 sets x 2 incidences + bilambertian 4 + hapke 2 sets x 2 = 12. */
#define CHI2_TESTS   12

static void run_chi2(const bsdf *b, vec3 wi, const char *what) {
  chi2_bsdf c = {b, tb_si_with(wi)};
  chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
  cfg.sample_count = CHI2_SAMPLES;
  cfg.test_count = CHI2_TESTS;
  cfg.ires = 8;
  chi2_result r = chi2_run(&cfg, chi2_bsdf_sample, chi2_bsdf_pdf, &c);
  CHECK(r.passed, "chi2 %s, wi = (%.4f, %.4f, %.4f): p = %g, chi2 = %g, dof = %d: %s", what, wi.x, wi.y, wi.z,
        r.p_value, r.chi2, r.dof, r.reason);
}

/* Sampling weight equals eval / pdf and pdf matches, at 200 samples. */
static void check_weights(const bsdf *b, vec3 wi, const char *what) {
  surface_interaction si = tb_si_with(wi);
  pcg32 rng;
  pcg32_seed(&rng, 7, 3);
  int bad = 0;
  for (int s = 0; s < 200; s++) {
    bsdf_sample bs;
    double u1 = pcg32_next_double(&rng);
    vec2 u2 = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
    color w = b->ops->sample(b, &si, u1, u2, &bs);
    if (!(bs.pdf > 0.0)) continue;
    color e = b->ops->eval(b, &si, bs.wo);
    double p = b->ops->pdf(b, &si, bs.wo);
    if (fabs(p - bs.pdf) > 1e-12 * p) bad++;
    for (int k = 0; k < 3; k++)
      if (fabs(w.c[k] - e.c[k] / p) > 1e-10 * fmax(1.0, fabs(w.c[k]))) bad++;
  }
  CHECK(bad == 0, "%s: %d weight/pdf mismatches", what, bad);
}

/* ---- rpv ------------------------------------------------------------------ */

typedef struct rpv_case {
  texture *rho_0, *k, *g, *rho_c;
  bsdf *b;
} rpv_case;

static rpv_case rpv_make(double rho_0, double k, double g, double rho_c) {
  rpv_case r;
  r.rho_0 = uniform_texture_const(rho_0, NULL);
  r.k = uniform_texture_const(k, NULL);
  r.g = uniform_texture_const(g, NULL);
  r.rho_c = rho_c < 0.0 ? NULL : uniform_texture_const(rho_c, NULL);
  r.b = rpv_new(r.rho_0, r.k, r.g, r.rho_c);
  return r;
}
static void rpv_free(rpv_case *r) {
  tb_free_bsdf(r->b);
  tb_free_tex(r->rho_0);
  tb_free_tex(r->k);
  tb_free_tex(r->g);
  tb_free_tex(r->rho_c);
}

static void test_rpv_chi2(void) {
  rpv_case a = rpv_make(0.1, 0.1, 0.0, -1.0); /* the defaults, rho_c shared */
  rpv_case b = rpv_make(0.183, 0.78, -0.1, 0.3);
  REQUIRE(a.b && b.b, "rpv_new");
  CHECK(((rpv_bsdf *)a.b)->rho_c == a.rho_0, "rho_c defaults to rho_0's object");
  for (int i = 0; i < 2; i++) {
    vec3 wi = tb_dir_deg(i ? 60.0 : 10.0, 30.0);
    run_chi2(a.b, wi, "rpv defaults");
    run_chi2(b.b, wi, "rpv (0.183, 0.78, -0.1, 0.3)");
    check_weights(a.b, wi, "rpv defaults");
    check_weights(b.b, wi, "rpv eradiate");
  }
  rpv_free(&a);
  rpv_free(&b);
}

static vec3 random_up(pcg32 *rng) {
  vec3 w = warp_square_to_cosine_hemisphere(v2(pcg32_next_double(rng), pcg32_next_double(rng)));
  return w;
}

static void test_rpv_reciprocity(void) {
  rpv_case r = rpv_make(0.25, 0.6, -0.3, 0.8);
  pcg32 rng;
  pcg32_seed(&rng, 11, 1);
  for (int s = 0; s < 50; s++) {
    vec3 wi = random_up(&rng), wo = random_up(&rng);
    surface_interaction a = tb_si_with(wi), b = tb_si_with(wo);
    double f1 = r.b->ops->eval(r.b, &a, wo).c[0] / fabs(wo.z);
    double f2 = r.b->ops->eval(r.b, &b, wi).c[0] / fabs(wi.z);
    CHECK(f1 > 0.0, "rpv eval positive");
    CHECK_REL(f1, f2, 1e-12);
  }
  rpv_free(&r);
}

/* RPV (docs/kernel-conventions.md#rpv) written with angles: theta, phi of each direction (phi from atan2,
 * which is 0 at the pole as the spec requires), tangents from tan(). */
static double rpv_ref(double rho_0, double k, double g, double rho_c, double ti, double pi_, double to,
                      double po) {
  double dphi = pi_ - po;
  double cos_big = cos(ti) * cos(to) + sin(ti) * sin(to) * cos(dphi);
  double F = (1 - g * g) / pow(1 + g * g + 2 * g * cos_big, 1.5);
  double G2 = tan(ti) * tan(ti) + tan(to) * tan(to) - 2 * tan(ti) * tan(to) * cos(dphi);
  double G = sqrt(G2 > 0 ? G2 : 0);
  double H = 1 + (1 - rho_c) / (1 + G);
  double M = pow(cos(ti) * cos(to) * (cos(ti) + cos(to)), k - 1);
  return rho_0 * M * F * H / RSW_PI;
}

static void test_rpv_closed_form(void) {
  pcg32 rng;
  pcg32_seed(&rng, 5, 9);
  for (int s = 0; s < 50; s++) {
    double rho_0 = 0.05 + 0.5 * pcg32_next_double(&rng), k = 0.2 + 1.3 * pcg32_next_double(&rng);
    double g = -0.8 + 1.6 * pcg32_next_double(&rng), rho_c = 1.5 * pcg32_next_double(&rng);
    double ti = 1.4 * pcg32_next_double(&rng), to = 1.4 * pcg32_next_double(&rng);
    double pi_ = 2 * RSW_PI * pcg32_next_double(&rng), po = 2 * RSW_PI * pcg32_next_double(&rng);
    if (s == 0) ti = 0.0; /* the pole */
    vec3 wi = v3(sin(ti) * cos(pi_), sin(ti) * sin(pi_), cos(ti));
    vec3 wo = v3(sin(to) * cos(po), sin(to) * sin(po), cos(to));
    rpv_case r = rpv_make(rho_0, k, g, rho_c);
    surface_interaction si = tb_si_with(wi);
    double got = r.b->ops->eval(r.b, &si, wo).c[0];
    double want = rpv_ref(rho_0, k, g, rho_c, ti, s == 0 ? 0.0 : pi_, to, po) * cos(to);
    CHECK_REL(got, want, 1e-9);
    rpv_free(&r);
  }
  /* k = 1, g = 0, rho_c = 1 is Lambertian rho_0 / pi. */
  rpv_case l = rpv_make(0.3, 1.0, 0.0, 1.0);
  surface_interaction si = tb_si_with(tb_dir_deg(40, 10));
  CHECK_REL(l.b->ops->eval(l.b, &si, tb_dir_deg(20, 200)).c[0], 0.3 / RSW_PI * cos(20 * RSW_PI / 180), 1e-14);
  CHECK(l.b->ops->eval(l.b, &si, tb_dir_deg(120, 0)).c[0] == 0.0, "rpv is one-sided");
  rpv_free(&l);
}

/* rpv.c keeps the thread's last geometry and grey value (a bundle's pages
 * ask at the same directions): interleaved evaluations of BSDFs with other
 * parameters (grey and coloured) at the same and other directions must
 * each give the bits of an evaluation after an unrelated one (a value
 * kept for other parameters, or a geometry for other directions, fails). */
static void test_rpv_last_value(void) {
  rpv_case a = rpv_make(0.183, 0.78, -0.1, -1.0), b = rpv_make(0.183, 0.9, -0.1, -1.0);
  rpv_case c = rpv_make(0.2, 0.78, 0.3, 0.5);
  spectrum s3 = {.kind = SPEC_RGB, .rgb = {0.05, 0.1, 0.3}};
  texture *r3 = uniform_texture_new(&s3, "t");
  bsdf *col3 = rpv_new(r3, a.k, a.g, NULL);
  REQUIRE(a.b && b.b && c.b && r3 && col3, "rpv_new");
  const bsdf *bs[4] = {a.b, b.b, c.b, col3};
  vec3 wi[2] = {tb_dir_deg(30, 0), tb_dir_deg(55, 120)};
  vec3 wo[2] = {tb_dir_deg(40, 200), tb_dir_deg(10, 80)};
  color want[4][2][2];
  surface_interaction far = tb_si_with(tb_dir_deg(70, 300));
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 2; j++)
      for (int k = 0; k < 2; k++) {
        bs[i]->ops->eval(bs[i], &far, tb_dir_deg(5, 5)); /* (another geometry first) */
        surface_interaction si = tb_si_with(wi[j]);
        want[i][j][k] = bs[i]->ops->eval(bs[i], &si, wo[k]);
      }
  pcg32 rng;
  pcg32_seed(&rng, 7, 3);
  int same = 0;
  for (int n = 0; n < 400; n++) {
    int i = (int)(pcg32_next_double(&rng) * 4), j = (int)(pcg32_next_double(&rng) * 2);
    int k = (int)(pcg32_next_double(&rng) * 2);
    surface_interaction si = tb_si_with(wi[j]);
    color got = bs[i]->ops->eval(bs[i], &si, wo[k]);
    for (int ch = 0; ch < 3; ch++) same += memcmp(&got.c[ch], &want[i][j][k].c[ch], sizeof(double)) == 0;
  }
  CHECK(same == 1200, "rpv: every interleaved evaluation bit for bit a fresh one's (%d of 1200)", same);
  CHECK(want[0][0][0].c[0] != want[1][0][0].c[0], "rpv: k 0.78 and 0.9 differ");
  tb_free_bsdf(col3);
  tb_free_tex(r3);
  rpv_free(&a);
  rpv_free(&b);
  rpv_free(&c);
}

/* F's x^1.5 is x sqrt(x) in rpv.c (a sixth of pow's time): with wi at the
 * pole, cos(Theta) = cos(theta_o) exactly and k = 1, rho_c = 1 make M = H =
 * 1, so rpv_fr is rho_0 F / pi; F must stay within 4 ulp of the pow form
 * over a dense sweep of g and theta_o (measured worst: 3 ulp, of which 1 on x^1.5,
 * plus the division's and 1/pi's roundings). */
static void test_rpv_phase_term_ulp(void) {
  double worst = 0.0;
  for (int ig = 0; ig <= 40; ig++) {
    double g = -0.95 + 1.9 * ig / 40.0;
    for (int it = 0; it < 20000; it++) {
      double t = 1.5 * it / 20000.0;
      vec3 wo = v3(sin(t), 0.0, cos(t));
      double want = (1.0 - g * g) / pow(1.0 + g * g + 2.0 * g * wo.z, 1.5) * RSW_INV_PI;
      double got = rpv_fr(1.0, 1.0, g, 1.0, v3(0.0, 0.0, 1.0), wo);
      double ulps = fabs(got - want) / (nextafter(want, INFINITY) - want);
      if (ulps > worst) worst = ulps;
    }
  }
  CHECK(worst <= 4.0, "rpv F within 4 ulp of the pow form (worst %.1f)", worst);
}

/* ---- bilambertian --------------------------------------------------------- */

static void test_bilambertian(void) {
  texture *r = uniform_texture_const(0.3, NULL), *t = uniform_texture_const(0.6, NULL);
  bsdf *b = bilambertian_new(r, t);
  REQUIRE(b, "bilambertian_new");
  CHECK(b->flags == (BSDF_DIFFUSE_REFLECTION | BSDF_DIFFUSE_TRANSMISSION), "flags");
  vec3 up = tb_dir_deg(30, 10), down = tb_dir_deg(150, 70);
  run_chi2(b, up, "bilambertian (0.3, 0.6) from above");
  run_chi2(b, down, "bilambertian (0.3, 0.6) from below");
  check_weights(b, up, "bilambertian above");
  check_weights(b, down, "bilambertian below");
  /* eval on both sides. */
  vec3 wo_up = tb_dir_deg(50, 0), wo_dn = tb_dir_deg(130, 0);
  double c = cos(50 * RSW_PI / 180);
  surface_interaction su = tb_si_with(up), sd = tb_si_with(down);
  CHECK_REL(b->ops->eval(b, &su, wo_up).c[0], 0.3 / RSW_PI * c, 1e-14);
  CHECK_REL(b->ops->eval(b, &su, wo_dn).c[0], 0.6 / RSW_PI * c, 1e-14);
  CHECK_REL(b->ops->eval(b, &sd, wo_dn).c[0], 0.3 / RSW_PI * c, 1e-14);
  CHECK_REL(b->ops->eval(b, &sd, wo_up).c[0], 0.6 / RSW_PI * c, 1e-14);
  /* p_R = 1/3: the pdf splits accordingly. */
  CHECK_REL(b->ops->pdf(b, &su, wo_up), c / RSW_PI / 3.0, 1e-14);
  CHECK_REL(b->ops->pdf(b, &sd, wo_up), c / RSW_PI * 2.0 / 3.0, 1e-14);
  /* Sample weights: R / p_R and T / (1 - p_R). */
  bsdf_sample bs;
  color w = b->ops->sample(b, &sd, 0.1, v2(0.3, 0.4), &bs);
  CHECK(bs.wo.z < 0.0 && bs.sampled_type == BSDF_DIFFUSE_REFLECTION, "reflection stays below");
  CHECK_REL(w.c[0], 0.9, 1e-14);
  w = b->ops->sample(b, &sd, 0.9, v2(0.3, 0.4), &bs);
  CHECK(bs.wo.z > 0.0 && bs.sampled_type == BSDF_DIFFUSE_TRANSMISSION, "transmission crosses");
  CHECK_REL(w.c[0], 0.9, 1e-14);
  tb_free_bsdf(b);
  tb_free_tex(r);
  tb_free_tex(t);
  /* R + T = 0: p_R is NaN -> 0, no NaN anywhere. */
  texture *z = uniform_texture_const(0.0, NULL);
  b = bilambertian_new(z, z);
  w = b->ops->sample(b, &su, 0.5, v2(0.3, 0.4), &bs);
  CHECK(w.c[0] == 0.0 && !isnan(bs.pdf), "black bilambertian: weight 0, no NaN");
  tb_free_bsdf(b);
  /* Pure reflector from below: transmission pdf is 0. */
  texture *one = uniform_texture_const(1.0, NULL);
  b = bilambertian_new(one, z);
  run_chi2(b, down, "bilambertian (1, 0) from below");
  tb_free_bsdf(b);
  b = bilambertian_new(z, one);
  run_chi2(b, up, "bilambertian (0, 1) from above");
  tb_free_bsdf(b);
  tb_free_tex(z);
  tb_free_tex(one);
}

/* ---- hapke ------------------------------------------------------------------ */

typedef struct hapke_case {
  texture *t[6];
  bsdf *b;
} hapke_case;

static hapke_case hapke_make(double w, double b, double c, double theta, double B_0, double h) {
  hapke_case r;
  double v[6] = {w, b, c, theta, B_0, h};
  for (int k = 0; k < 6; k++) r.t[k] = uniform_texture_const(v[k], NULL);
  r.b = hapke_new(r.t[0], r.t[1], r.t[2], r.t[3], r.t[4], r.t[5]);
  return r;
}
static void hapke_free(hapke_case *r) {
  tb_free_bsdf(r->b);
  for (int k = 0; k < 6; k++) tb_free_tex(r->t[k]);
}

static void test_hapke_chi2(void) {
  hapke_case a = hapke_make(0.5, 0.2, 0.5, 30.0, 0.0, 0.0); /* defaults */
  /* Eradiate's regolith example (Nguyen 2025 fit): */
  hapke_case b = hapke_make(0.52, 0.17, 0.62, 15.0, 0.9, 0.06);
  for (int i = 0; i < 2; i++) {
    vec3 wi = tb_dir_deg(i ? 65.0 : 20.0, 45.0);
    run_chi2(a.b, wi, "hapke defaults");
    run_chi2(b.b, wi, "hapke (0.52, 0.17, 0.62, 15, 0.9, 0.06)");
    check_weights(a.b, wi, "hapke defaults");
    check_weights(b.b, wi, "hapke regolith");
  }
  hapke_free(&a);
  hapke_free(&b);
}

/* Directional-hemispherical albedo (the mean of cosine-sampled weights)
 * stays <= 1; the h = 0 guard: wi == wo (phase angle 0) and the pole give
 * finite values. */
static void test_hapke_energy_and_guard(void) {
  const double params[3][6] = {
      {0.5, 0.2, 0.5, 30.0, 0.0, 0.0}, {0.9, 0.3, 0.3, 20.0, 1.0, 0.05}, {0.52, 0.17, 0.62, 15.0, 0.9, 0.06}};
  for (int p = 0; p < 3; p++) {
    hapke_case hc =
        hapke_make(params[p][0], params[p][1], params[p][2], params[p][3], params[p][4], params[p][5]);
    for (double ti = 0.0; ti < 85.0; ti += 20.0) {
      surface_interaction si = tb_si_with(tb_dir_deg(ti, 0));
      pcg32 rng;
      pcg32_seed(&rng, 3, 4);
      const int n = 20000;
      double sum = 0.0, sum2 = 0.0;
      for (int s = 0; s < n; s++) {
        bsdf_sample bs;
        color w =
            hc.b->ops->sample(hc.b, &si, 0.5, v2(pcg32_next_double(&rng), pcg32_next_double(&rng)), &bs);
        sum += w.c[0];
        sum2 += w.c[0] * w.c[0];
      }
      double mean = sum / n, sd = sqrt((sum2 / n - mean * mean) / n);
      CHECK(mean > 0.0 && mean <= 1.0 + 3.0 * sd, "hapke set %d at %g deg: albedo %g (+- %g)", p, ti, mean,
            sd);
    }
    hapke_free(&hc);
  }
  /* h = 0 with B_0 > 0: no NaN at g = 0 (wi == wo), including the pole. */
  hapke_case g0 = hapke_make(0.5, 0.2, 0.5, 30.0, 1.0, 0.0);
  const double th[4] = {0.0, 10.0, 45.0, 80.0};
  for (int k = 0; k < 4; k++) {
    vec3 w = tb_dir_deg(th[k], 33.0);
    surface_interaction si = tb_si_with(w);
    double v = g0.b->ops->eval(g0.b, &si, w).c[0];
    CHECK(isfinite(v) && v > 0.0, "hapke h = 0 at g = 0, theta %g: %g", th[k], v);
    /* g = 0 gets the full surge B_0: (1 + B) with B = B_0 = 1 vs B = 0. */
    double v_ref = hapke_fr(0.5, 0.2, 0.5, 30.0, 0.0, 0.0, w, w) * w.z;
    CHECK(v > v_ref, "surge at g = 0: %g > %g", v, v_ref);
    /* Away from g = 0 with h = 0 the surge vanishes. */
    vec3 wo = tb_dir_deg(th[k] + 5.0, 33.0);
    CHECK_REL(g0.b->ops->eval(g0.b, &si, wo).c[0], hapke_fr(0.5, 0.2, 0.5, 30.0, 0.0, 0.0, w, wo) * wo.z,
              1e-14);
  }
  /* theta = 0 (smooth): E1 = E2 = 0, S = 1; finite everywhere. */
  CHECK(isfinite(hapke_fr(0.5, 0.2, 0.5, 0.0, 0.0, 0.0, tb_dir_deg(0, 0), tb_dir_deg(0, 0))), "theta 0");
  CHECK(hapke_fr(0.5, 0.2, 0.5, 30.0, 0.0, 0.0, tb_dir_deg(30, 0), tb_dir_deg(100, 0)) == 0.0,
        "hapke is one-sided");
  hapke_free(&g0);
}

/* ---- loader ------------------------------------------------------------------ */

static rsw_status load_json(const char *text, scene **out, rsw_err *err) {
  scene_load_opts o = {.size = sizeof o, .variant = "mono"};
  rsw_err_clear(err);
  *out = NULL;
  return scene_load_memory(text, strlen(text), "test_eo_bsdf", false, &o, out, err);
}

static void test_loader(void) {
  scene *s = NULL;
  rsw_err err = {0};
  rsw_status st = load_json("{\"type\": \"scene\", \"a\": {\"type\": \"rpv\", \"id\": \"a\"},"
                            " \"b\": {\"type\": \"bilambertian\", \"id\": \"b\"},"
                            " \"c\": {\"type\": \"hapke\", \"id\": \"c\"}}",
                            &s, &err);
  CHECK(st == RSW_OK, "defaults load: %s", err.msg);
  if (s) scene_free(s);
  const char *bad[] = {
      "{\"type\": \"scene\", \"a\": {\"type\": \"rpv\", \"g\": 1.0}}",
      "{\"type\": \"scene\", \"a\": {\"type\": \"rpv\", \"k\": -0.5}}",
      "{\"type\": \"scene\", \"a\": {\"type\": \"bilambertian\", \"reflectance\": 0.6, "
      "\"transmittance\": 0.5}}",
      "{\"type\": \"scene\", \"a\": {\"type\": \"hapke\", \"w\": 1.2}}",
      "{\"type\": \"scene\", \"a\": {\"type\": \"hapke\", \"b\": 1.0}}",
      "{\"type\": \"scene\", \"a\": {\"type\": \"hapke\", \"theta\": 90}}",
      "{\"type\": \"scene\", \"a\": {\"type\": \"hapke\", \"h\": -1}}",
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    s = NULL;
    memset(&err, 0, sizeof err);
    st = load_json(bad[i], &s, &err);
    CHECK(st != RSW_OK, "refused: %s", bad[i]);
    if (s) scene_free(s);
  }
}

int main(void) {
  RSW_TEST_RUN(test_rpv_chi2);
  RSW_TEST_RUN(test_rpv_reciprocity);
  RSW_TEST_RUN(test_rpv_closed_form);
  RSW_TEST_RUN(test_rpv_last_value);
  RSW_TEST_RUN(test_rpv_phase_term_ulp);
  RSW_TEST_RUN(test_bilambertian);
  RSW_TEST_RUN(test_hapke_chi2);
  RSW_TEST_RUN(test_hapke_energy_and_guard);
  RSW_TEST_RUN(test_loader);
  RSW_TEST_END("test_eo_bsdf");
}
