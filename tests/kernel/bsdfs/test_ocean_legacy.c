/* ocean_legacy (server/kernel/bsdfs/ocean_legacy.c,
 * docs/kernel-conventions.md#ocean_legacy):
 *  - data: the water index at 550 nm with chlorinity 19 (Hale and Querry
 *    + Friedman-Sverdrup), Monahan's coverage and the whitecap reflectance
 *    at 10 m/s, r_omega inside (0, 0.1), underlight 0 outside 400-700 nm;
 *  - the glint term equals Cox and Munk's (1954) reflectance written in
 *    slope space, pi p(z_u, z_c) F / (4 mu_s mu_v cos^4 beta) with the
 *    Gram-Charlier p, at 200 random pairs (1e-9 relative);
 *  - glint position and width, for wind speeds 3 and 12 m/s, sun at 10
 *    degrees, principal plane along the wind: the BRF peaks within 0.25
 *    degrees of the closed form's peak and its half-maximum view angles
 *    agree to 0.05 degrees; the slope distribution it implies (the BRF
 *    over pi F / (4 mu_s mu_v cos^4 beta)) has its mode within
 *    sigma_u / 2 of slope 0 (the mirror direction) and a half-maximum
 *    half-width of sqrt(2 ln 2) sigma_u within 25 % (the Gram-Charlier
 *    terms depart from a Gaussian), in the ratio sqrt(12 / 3) = 2 (25 %);
 *  - energy: the directional albedo (mean sample weight, 40,000 samples)
 *    is <= 1 + 3 sigma for 4 incidences x 3 wind speeds;
 *  - the tables' 32-point quadrature is within 2e-3 of Eradiate's 64 up
 *    to 54 degrees (beyond, neither has converged: at 86 degrees 32, 64
 *    and 128 points give 0.93, 0.77, 0.61);
 *  - chi-square of sample() against pdf() (200,000 samples, alpha 0.01
 *    Sidak-corrected over 4 runs), weight = eval / pdf;
 *  - JSON and XML scenes load; a PATCH of wind_speed updates the derived
 *    coverage; a missing wavelength, wind_speed 40 and a wavelength
 *    string other than "render" are refused;
 *  - "wavelength": "render": the ocean at 450 and 650 nm is bit for bit
 *    the ocean given those wavelengths (value and pdf), has no wavelength
 *    parameter, is spectral, and refuses a render at 5000 nm;
 *  - the tables (one index's, a bundle of 5's) are the same bits on 1 and
 *    5 threads and at every ISA (the lanes against the scalar path).
 * Fixed seeds throughout. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../support/bsdf_test.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"
#include "kernel/bsdfs/eo_surfaces.h"
#include "kernel/core/isa.h"
#include "kernel/core/rng.h"
#include "kernel/scene/param_table.h"
#include "kernel/scene/params.h"
#include "kernel/scene/scene.h"
#include "kernel/scene/update.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

static void test_data(void) {
  bsdf *b = ocean_legacy_new(550, 10, 0, 19, 0.3, true, 0);
  REQUIRE(b, "ocean_legacy_new");
  ocean_bsdf *o = (ocean_bsdf *)b;
  CHECK_REL(o->n_re, 1.333 + 0.00017492711 * (0.03 + 1.805 * 19), 1e-12);
  CHECK_REL(o->n_im, 1.96e-9, 1e-9);
  CHECK_REL(o->coverage, 2.95e-6 * pow(10, 3.52), 1e-12);
  CHECK_REL(o->whitecap, 0.22 * 2.95e-6 * pow(10, 3.52), 1e-12);
  CHECK(o->r_omega > 0 && o->r_omega < 0.1, "r_omega %g", o->r_omega);
  /* The wind at North 0 (from the north, North Left) points to -y ... the
   * local azimuth is 90 degrees. */
  CHECK_REL(o->phi_w, PI / 2, 1e-12);
  /* Underlight only in 400-700 nm: component 3 at 800 nm is 0. */
  bsdf *b8 = ocean_legacy_new(800, 10, 0, 19, 0.3, true, 3);
  ocean_tables((ocean_bsdf *)b8);
  surface_interaction si = tb_si_with(tb_dir_deg(20, 0));
  CHECK(b8->ops->eval(b8, &si, tb_dir_deg(40, 100)).c[0] == 0.0, "no underlight at 800 nm");
  bsdf *b5 = ocean_legacy_new(500, 10, 0, 19, 0.3, true, 3);
  CHECK(b5->ops->eval(b5, &si, tb_dir_deg(40, 100)).c[0] == 0.0, "no underlight before the tables");
  ocean_tables((ocean_bsdf *)b5);
  double u5 = b5->ops->eval(b5, &si, tb_dir_deg(40, 100)).c[0];
  CHECK(u5 > 0.001 && u5 < 0.1, "underlight at 500 nm: %g", u5);
  tb_free_bsdf(b);
  tb_free_bsdf(b8);
  tb_free_bsdf(b5);
}

/* Cox-Munk glint BRF in slope space, wind along +x (phi_w = 0, i.e.
 * wind_direction 90): slopes z = -h_xy / h_z of the facet normal h; Eradiate
 * (and 6S) take xn = h_x / (sigma_u h_z), the opposite sign, in the odd
 * Gram-Charlier terms; written here the same way. */
static double cm_glint(double ws, double nre, double nim, vec3 sun, vec3 view) {
  double su = sqrt(0.00316 * ws), sc = sqrt(0.003 + 0.00192 * ws);
  vec3 h = v3_norm(v3_add(sun, view));
  double xn = h.x / (h.z * su), xe = h.y / (h.z * sc);
  double c21 = 0.01 - 0.0086 * ws, c03 = 0.04 - 0.033 * ws;
  double gc = 1 - c21 / 2 * (xe * xe - 1) * xn - c03 / 6 * (xn * xn - 3) * xn +
              0.40 / 24 * (pow(xe, 4) - 6 * xe * xe + 3) + 0.23 / 24 * (pow(xn, 4) - 6 * xn * xn + 3) +
              0.12 / 4 * (xe * xe - 1) * (xn * xn - 1);
  double p = gc * exp(-0.5 * (xn * xn + xe * xe)) / (2 * PI * su * sc);
  double cchi = v3_dot(view, h);
  double F = ocean_fresnel_6s(nre, nim, cchi, sqrt(1 - cchi * cchi));
  return PI * p * F / (4 * sun.z * view.z * pow(h.z, 4));
}

static void test_glint_closed_form(void) {
  pcg32 rng;
  pcg32_seed(&rng, 25, 6);
  for (int s = 0; s < 200; s++) {
    double ws = 1 + 15 * pcg32_next_double(&rng);
    bsdf *b = ocean_legacy_new(440 + 200 * pcg32_next_double(&rng), ws, 90, 19, 0.3, false, 2);
    ocean_bsdf *o = (ocean_bsdf *)b;
    vec3 view = tb_dir_deg(75 * pcg32_next_double(&rng), 360 * pcg32_next_double(&rng));
    vec3 sun = tb_dir_deg(75 * pcg32_next_double(&rng), 360 * pcg32_next_double(&rng));
    surface_interaction si = tb_si_with(view);
    double got = b->ops->eval(b, &si, sun).c[0] / (1 - o->coverage);
    double want = cm_glint(ws, o->n_re, o->n_im, sun, view);
    /* Absolute 1e-15 as well: the Beckmann D is set to 0 where D cos is
     * below 1e-20 (bsdfs/microfacet.h). */
    CHECK(fabs(got - want) <= 1e-9 * fabs(want) + 1e-15, "pair %d: %.12g vs %.12g", s, got, want);
    tb_free_bsdf(b);
  }
}

typedef struct lobe {
  double peak, lo, hi;
} lobe;

/* Peak by a 0.01-degree scan over [-60, 80], half-maximum angles by
 * bisection. */
static lobe find_lobe(double (*f)(const void *, double), const void *ctx) {
  lobe l = {0};
  double best = -1;
  for (double t = -60; t <= 80; t += 0.01) {
    double v = f(ctx, t);
    if (v > best) best = v, l.peak = t;
  }
  for (int side = 0; side < 2; side++) {
    double a = l.peak, b = side ? 80.0 : -60.0;
    for (int it = 0; it < 60; it++) {
      double m = 0.5 * (a + b);
      if (f(ctx, m) > best / 2)
        a = m;
      else
        b = m;
    }
    if (side)
      l.hi = a;
    else
      l.lo = a;
  }
  return l;
}

typedef struct gctx {
  const bsdf *b;
  double ws;
  vec3 sun;
  bool slope_pdf; /* divide out F / (4 mu_s mu_v h_z^4) / pi: the slope pdf */
} gctx;

static vec3 plane_view(double t) {
  return t >= 0 ? tb_dir_deg(t, 180) : tb_dir_deg(-t, 0);
}
static double to_slope_pdf(const gctx *g, double v, double t) {
  if (!g->slope_pdf) return v;
  const ocean_bsdf *o = (const ocean_bsdf *)g->b;
  vec3 view = plane_view(t), h = v3_norm(v3_add(g->sun, view));
  double cchi = v3_dot(view, h);
  double F = ocean_fresnel_6s(o->n_re, o->n_im, cchi, sqrt(1 - cchi * cchi));
  return v * 4 * g->sun.z * view.z * pow(h.z, 4) / (PI * F);
}
static double f_plugin(const void *c, double t) {
  const gctx *g = c;
  surface_interaction si = tb_si_with(plane_view(t));
  return to_slope_pdf(g, g->b->ops->eval(g->b, &si, g->sun).c[0], t);
}
static double f_cm(const void *c, double t) {
  const gctx *g = c;
  const ocean_bsdf *o = (const ocean_bsdf *)g->b;
  return to_slope_pdf(g, (1 - o->coverage) * cm_glint(g->ws, o->n_re, o->n_im, g->sun, plane_view(t)), t);
}

/* The facet slope along the wind that reflects the sun into view t. */
static double slope_at(vec3 sun, double t) {
  vec3 h = v3_norm(v3_add(sun, plane_view(t)));
  return h.x / h.z;
}

static void test_glint_position_width(void) {
  vec3 sun = tb_dir_deg(10, 0);
  double width[2];
  const double wss[2] = {3, 12};
  for (int k = 0; k < 2; k++) {
    double ws = wss[k], su = sqrt(0.00316 * ws);
    bsdf *b = ocean_legacy_new(550, ws, 90, 19, 0.3, false, 2);
    /* The BRF lobe against Cox-Munk's. */
    gctx g = {b, ws, sun, false};
    lobe lp = find_lobe(f_plugin, &g), lc = find_lobe(f_cm, &g);
    printf("  ws %g: BRF peak %.3f deg (Cox-Munk %.3f), half max [%.3f, %.3f] (Cox-Munk [%.3f, %.3f])\n", ws,
           lp.peak, lc.peak, lp.lo, lp.hi, lc.lo, lc.hi);
    CHECK(fabs(lp.peak - lc.peak) <= 0.25, "ws %g: peak %g vs Cox-Munk %g", ws, lp.peak, lc.peak);
    CHECK(fabs(lp.lo - lc.lo) <= 0.05 && fabs(lp.hi - lc.hi) <= 0.05, "ws %g: half-max angles differ", ws);
    /* The slope distribution it implies: mode near slope 0 (the mirror
     * direction; the Gram-Charlier skewness moves it), half-maximum
     * half-width sqrt(2 ln 2) sigma_u within 25 % (its kurtosis). */
    gctx gs = {b, ws, sun, true};
    lobe ls = find_lobe(f_plugin, &gs);
    double z0 = slope_at(sun, ls.peak);
    double half = 0.5 * fabs(slope_at(sun, ls.hi) - slope_at(sun, ls.lo));
    double want = sqrt(2 * log(2.0)) * su;
    printf("  ws %g: slope mode %.4f (sigma_u %.4f), half-max half-width %.4f, Gaussian %.4f\n", ws, z0, su,
           half, want);
    CHECK(fabs(z0) <= 0.5 * su, "ws %g: slope mode %g", ws, z0);
    CHECK(fabs(half - want) <= 0.25 * want, "ws %g: slope half-width %g vs %g", ws, half, want);
    width[k] = half;
    tb_free_bsdf(b);
  }
  CHECK(fabs(width[1] / width[0] - 2.0) <= 0.25 * 2.0, "width ratio %g for sqrt(12/3) = 2",
        width[1] / width[0]);
}

static void test_energy(void) {
  const double wss[3] = {1, 5, 15};
  for (int k = 0; k < 3; k++) {
    bsdf *b = ocean_legacy_new(550, wss[k], 30, 19, 0.3, true, 0);
    ocean_tables((ocean_bsdf *)b);
    for (double ti = 0; ti < 85; ti += 25) {
      surface_interaction si = tb_si_with(tb_dir_deg(ti, 10));
      pcg32 rng;
      pcg32_seed(&rng, 8, (uint64_t)ti);
      const int n = 40000;
      double sum = 0, sum2 = 0;
      for (int s = 0; s < n; s++) {
        bsdf_sample bs;
        double u1 = pcg32_next_double(&rng);
        vec2 u2 = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
        double w = b->ops->sample(b, &si, u1, u2, &bs).c[0];
        sum += w, sum2 += w * w;
      }
      double m = sum / n, sd = sqrt(fmax(sum2 / n - m * m, 0) / n);
      CHECK(m > 0 && m <= 1 + 3 * sd, "ws %g, theta %g: albedo %g +- %g", wss[k], ti, m, sd);
    }
    tb_free_bsdf(b);
  }
}

static void test_quadrature(void) {
  bsdf *b = ocean_legacy_new(550, 7, 0, 19, 0.3, true, 0);
  const ocean_bsdf *o = (const ocean_bsdf *)b;
  double worst = 0;
  for (int up = 0; up < 2; up++)
    for (double th = 0; th < 0.95; th += 0.15)
      for (double ph = 0; ph < 6.2; ph += 1.5) {
        double a = ocean_transmittance(o, th, ph, up, 32), c = ocean_transmittance(o, th, ph, up, 64);
        worst = fmax(worst, fabs(a - c));
        CHECK(a > 0.5 && a <= 1.0, "transmittance %g", a);
      }
  printf("  tables: 32- vs 64-point quadrature, worst difference %.3g\n", worst);
  CHECK(worst <= 2e-3, "32-point quadrature off by %g", worst);
  tb_free_bsdf(b);
}

static void test_sampling(void) {
  const double wss[2] = {5, 12};
  pcg32 rng;
  pcg32_seed(&rng, 1, 2);
  for (int k = 0; k < 2; k++) {
    bsdf *b = ocean_legacy_new(550, wss[k], 30, 19, 0.3, true, 0);
    ocean_tables((ocean_bsdf *)b);
    for (int i = 0; i < 2; i++) {
      vec3 wi = tb_dir_deg(i ? 70 : 30, 20);
      chi2_bsdf c = {b, tb_si_with(wi)};
      chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
      cfg.sample_count = 200000;
      cfg.test_count = 4;
      chi2_result r = chi2_run(&cfg, chi2_bsdf_sample, chi2_bsdf_pdf, &c);
      CHECK(r.passed, "chi2 ws %g at %d: p = %g, chi2 = %g: %s", wss[k], i, r.p_value, r.chi2, r.reason);
      int bad = 0;
      for (int s = 0; s < 200; s++) {
        bsdf_sample bs;
        double u1 = pcg32_next_double(&rng);
        color w = b->ops->sample(b, &c.si, u1, v2(pcg32_next_double(&rng), pcg32_next_double(&rng)), &bs);
        if (!(bs.pdf > 0)) continue;
        double p = b->ops->pdf(b, &c.si, bs.wo), e = b->ops->eval(b, &c.si, bs.wo).c[0];
        if (fabs(p - bs.pdf) > 1e-12 * p || fabs(w.c[0] - e / p) > 1e-10 * fmax(1, fabs(w.c[0]))) bad++;
      }
      CHECK(bad == 0, "%d weight/pdf mismatches", bad);
    }
    tb_free_bsdf(b);
  }
}

static void test_scene(void) {
  const char *docs[2] = {
      "{\"type\": \"scene\", \"sea\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"ocean_legacy\", "
      "\"id\": "
      "\"o\", \"wavelength\": 550, \"wind_speed\": 5, \"wind_direction\": 30}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0.3, 0, -1]},"
      " \"sensor\": {\"type\": \"distant\", \"direction\": [0.3, 0, -1], \"target\": [0, 0, 0],"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}",
      "<scene version=\"3.0.0\"><shape type=\"rectangle\"><bsdf type=\"ocean_legacy\" id=\"o\">"
      "<float name=\"wavelength\" value=\"550\"/><float name=\"wind_speed\" value=\"5\"/>"
      "<float name=\"wind_direction\" value=\"30\"/><boolean name=\"shadowing\" "
      "value=\"true\"/></bsdf></shape>"
      "<emitter type=\"directional\"><vector name=\"direction\" x=\"0.3\" y=\"0\" z=\"-1\"/></emitter>"
      "<sensor type=\"distant\"><vector name=\"direction\" x=\"0.3\" y=\"0\" z=\"-1\"/>"
      "<point name=\"target\" x=\"0\" y=\"0\" z=\"0\"/><film type=\"hdrfilm\"><integer name=\"width\" "
      "value=\"1\"/><integer name=\"height\" value=\"1\"/></film></sensor></scene>"};
  for (int x = 0; x < 2; x++) {
    scene *s = tsup_load(docs[x], "mono");
    REQUIRE(s, "%s scene", x ? "XML" : "JSON");
    film_image img;
    REQUIRE(tsup_render(s, 0, 1, 1, &img), "render");
    CHECK(img.data[0] > 0 && isfinite(img.data[0]), "radiance %g", img.data[0]);
    film_image_free(&img);
    size_t idx;
    rsw_err err = {0};
    const char *keys[6] = {"wavelength", "wind_speed",   "wind_direction",
                           "chlorinity", "pigmentation", "coverage"};
    for (int k = 0; k < 6; k++) {
      char key[96];
      snprintf(key, sizeof key, "ocean_legacy:o:%s", keys[k]);
      CHECK(params_lookup(s, key, &idx, &err) == RSW_OK, "%s: %s", key, err.msg);
    }
    param_update u = {.key = "ocean_legacy:o:wind_speed"};
    REQUIRE(param_value_parse("12", "wind_speed", &u.value, &err) == RSW_OK, "parse");
    update_report rep;
    CHECK(scene_update(s, &u, 1, &rep, &err) == RSW_OK, "update: %s", err.msg);
    param_value_free(&u.value);
    params_lookup(s, "ocean_legacy:o:coverage", &idx, &err);
    char *v = params_value_json(s, idx, 0);
    CHECK(v && fabs(atof(v) - 2.95e-6 * pow(12, 3.52)) < 1e-12, "coverage after the update: %s", v ? v : "?");
    free(v);
    param_update c = {.key = "ocean_legacy:o:coverage"};
    param_value_parse("0.5", "coverage", &c.value, &err);
    CHECK(scene_update(s, &c, 1, &rep, &err) != RSW_OK, "coverage is read-only");
    param_value_free(&c.value);
    scene_free(s);
  }
  const char *bad[3] = {
      "{\"type\": \"scene\", \"a\": {\"type\": \"ocean_legacy\"}}",
      "{\"type\": \"scene\", \"a\": {\"type\": \"ocean_legacy\", \"wavelength\": 550, "
      "\"wind_speed\": 40}}",
      "{\"type\": \"scene\", \"a\": {\"type\": \"ocean_legacy\", \"wavelength\": \"sensor\"}}"};
  for (int k = 0; k < 3; k++) {
    scene *s = tsup_load(bad[k], "mono");
    CHECK(s == NULL, "refused: %s", bad[k]);
    if (s) scene_free(s);
  }
}

/* "wavelength": "render": the ocean at each render's wavelength, bit for
 * bit the ocean given that wavelength (its index, whitecaps, underlight
 * and tables); no `wavelength` parameter of its own; spectral (a
 * wavelength sweep changes it); a render outside 200-4000 nm refused. */
static void test_follow(void) {
  scene *s = tsup_load("{\"type\": \"scene\", \"a\": {\"type\": \"ocean_legacy\", \"id\": \"o\", "
                       "\"wavelength\": \"render\", \"wind_speed\": 7, \"component\": 4}}",
                       "mono");
  REQUIRE(s, "an ocean that follows the render loads");
  CHECK(scene_wavelength_dependent(s), "a wavelength sweep changes it");
  const bsdf *b = NULL;
  for (size_t i = 0; i < s->n_objects && !b; i++)
    if (s->objects[i]->plugin == &plugin_ocean_legacy) b = (const bsdf *)s->objects[i];
  REQUIRE(b, "the ocean");
  rsw_err err = {0};
  size_t idx;
  CHECK(params_lookup(s, "ocean_legacy:o:wavelength", &idx, &err) != RSW_OK, "no wavelength parameter");
  err = (rsw_err){0};
  surface_interaction si = tb_si_with(tb_dir_deg(30, 10));
  vec3 wo = tb_dir_deg(40, 200);
  double prev = -1;
  for (int k = 0; k < 2; k++) {
    double wl = k ? 650.0 : 450.0;
    render_ctx rc = {.variant = VARIANT_MONO, .wavelength = wl};
    REQUIRE(scene_prepare(s, &rc, &err) == RSW_OK, "prepare at %g: %s", wl, err.msg);
    bsdf *f = ocean_legacy_new(wl, 7, 0, 19, 0.3, true, 4);
    REQUIRE(f, "fixed");
    ocean_tables((ocean_bsdf *)f);
    color a = b->ops->eval(b, &si, wo), e = f->ops->eval(f, &si, wo);
    CHECK(a.c[0] == e.c[0] && a.c[1] == e.c[0] && a.c[2] == e.c[0], "at %g nm: %g, fixed %g", wl, a.c[0],
          e.c[0]);
    CHECK(b->ops->pdf(b, &si, wo) == f->ops->pdf(f, &si, wo), "pdf at %g nm", wl);
    CHECK(a.c[0] != prev, "450 and 650 nm differ");
    prev = a.c[0];
    free(f);
  }
  render_ctx far = {.variant = VARIANT_MONO, .wavelength = 5000};
  err = (rsw_err){0};
  CHECK(scene_prepare(s, &far, &err) != RSW_OK && strstr(err.msg, "5000"), "5000 nm refused: %s", err.msg);
  scene_free(s);
}

/* One build of the tables on `isa` with `threads` into out: a fixed
 * ocean's pair (2 tables), or (follow) the 6 pairs of the channels of a
 * bundle of 5 wavelengths (its downwelling tables 5 indices at once; the
 * last channel a copy). */
enum {
  TBL = OCEAN_T_RES * OCEAN_T_RES
};
static void build_tables_at(rsw_isa isa, int threads, bool follow, float *out) {
  REQUIRE(rsw_isa_set(isa), "the ISA %s", rsw_isa_name(isa));
  bsdf *b = ocean_legacy_new(550, 7, 30, 19, 0.3, true, 0);
  REQUIRE(b, "ocean");
  ocean_bsdf *o = (ocean_bsdf *)b;
  o->follow = follow;
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 550, .threads = threads};
  if (follow) {
    rc.bundle = 5;
    for (int c = 0; c < RENDER_MAX_BUNDLE; c++) rc.wl[c] = 400.0 + 50.0 * (c < 5 ? c : 4);
    rc.wavelength = rc.wl[0];
  }
  rsw_err err = {0};
  REQUIRE(plugin_ocean_legacy.prepare(&b->base, &rc, &err) == RSW_OK, "prepare: %s", err.msg);
  if (!follow) {
    memcpy(out, o->t_down, sizeof o->t_down);
    memcpy(out + TBL, o->t_up, sizeof o->t_up);
  }
  for (int k = 0; follow && k < 6; k++) {
    const ocean_wl *w = &o->pg[k / 3][k % 3];
    REQUIRE(w->t_down && w->t_up, "channel %d's tables", k);
    memcpy(out + 2 * k * TBL, w->t_down, TBL * sizeof *out);
    memcpy(out + (2 * k + 1) * TBL, w->t_up, TBL * sizeof *out);
  }
  plugin_ocean_legacy.destroy(&b->base);
  rsw_isa_set(rsw_isa_best());
}

/* The tables are the same bits whatever the threads that build them
 * (render_ctx.threads: 1 and 5) and the ISA (ocean_lanes.h's lanes on
 * sse2, avx2 and avx512 against the scalar path, the generic ISA's), for
 * one index and for a bundle's; they vary over the cells and between
 * wavelengths (the comparison compares something). */
static void test_tables_threads_isa(void) {
  float *ref = malloc(12 * TBL * sizeof *ref), *got = malloc(12 * TBL * sizeof *got);
  REQUIRE(ref && got, "memory");
  for (int follow = 0; follow < 2; follow++) {
    size_t n = (follow ? 12 : 2) * (size_t)TBL;
    build_tables_at(RSW_ISA_GENERIC, 1, follow, ref);
    CHECK(ref[0] != ref[TBL - 1] && ref[5 * OCEAN_T_RES + 40] != ref[40 * OCEAN_T_RES + 5],
          "the tables vary over the cells");
    if (follow) CHECK(memcmp(ref, ref + 2 * TBL, TBL * sizeof *ref) != 0, "400 and 450 nm differ");
    if (follow)
      CHECK(memcmp(ref + 8 * TBL, ref + 10 * TBL, 2 * TBL * sizeof *ref) == 0, "the copied channel");
    for (int isa = 0; isa < RSW_ISA__COUNT; isa++)
      for (int threads = 1; threads <= 5; threads += 4) {
        if (isa == RSW_ISA_GENERIC && threads == 1) continue;
        if (!rsw_isa_supported((rsw_isa)isa)) continue;
        build_tables_at((rsw_isa)isa, threads, follow, got);
        size_t diff = 0;
        for (size_t i = 0; i < n; i++) diff += memcmp(&ref[i], &got[i], sizeof *ref) != 0;
        CHECK(diff == 0, "%s, %d threads, %s: %zu of %zu entries differ from the generic ISA's on 1 thread",
              rsw_isa_name((rsw_isa)isa), threads, follow ? "a bundle of 5" : "one index", diff, n);
      }
  }
  free(ref), free(got);
  /* The sums before the tables' rounding to float: ocean_transmittance,
   * down and up, 32 and 7 points (49: the lanes and the scalar tail). */
  bsdf *b = ocean_legacy_new(550, 7, 30, 19, 0.3, true, 0);
  REQUIRE(b, "ocean");
  const ocean_bsdf *o = (const ocean_bsdf *)b;
  for (int k = 0; k < 40; k++) {
    double th = 1.55 * k / 39.0, ph = 0.7 + 0.37 * k;
    bool up = k % 2;
    int nq = k % 4 < 2 ? 32 : 7;
    REQUIRE(rsw_isa_set(RSW_ISA_GENERIC), "generic");
    double t0 = ocean_transmittance(o, th, ph, up, nq);
    for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
      if (!rsw_isa_set((rsw_isa)isa)) continue;
      double t = ocean_transmittance(o, th, ph, up, nq);
      CHECK(memcmp(&t, &t0, sizeof t) == 0, "%s at theta %g, phi %g, %s, %d points: %.17g, scalar %.17g",
            rsw_isa_name((rsw_isa)isa), th, ph, up ? "up" : "down", nq, t, t0);
    }
  }
  rsw_isa_set(rsw_isa_best());
  free(b);
}

int main(void) {
  RSW_TEST_RUN(test_data);
  RSW_TEST_RUN(test_glint_closed_form);
  RSW_TEST_RUN(test_glint_position_width);
  RSW_TEST_RUN(test_energy);
  RSW_TEST_RUN(test_quadrature);
  RSW_TEST_RUN(test_sampling);
  RSW_TEST_RUN(test_scene);
  RSW_TEST_RUN(test_follow);
  RSW_TEST_RUN(test_tables_threads_isa);
  RSW_TEST_END("test_ocean_legacy");
}
