/* rtls (server/kernel/bsdfs/rtls.c, docs/kernel-conventions.md#rtls):
 *  - the BRF (pi eval / cos theta_o) equals f_iso + f_vol K_vol + f_geo K_geo
 *    with the kernels of Lucht, Schaaf and Strahler (2000), eqs. 37-44,
 *    written here from angles (theta, phi), at 100 random direction pairs
 *    for the MODIS shape (h/b = 2, b/r = 1) and 100 for b/r = 2.5, to
 *    1e-9 absolute (both sides compute in double; float precision would
 *    be 1e-6);
 *  - both kernels vanish with sun and view at nadir (BRF = f_iso), the
 *    model is reciprocal, one-sided;
 *  - chi-square of sample() against pdf() (tests/support/chi2.h,
 *    200,000 samples, alpha 0.01 Sidak-corrected over 4 runs), weight =
 *    eval / pdf;
 *  - a scene (JSON and XML): a plate under a directional sun seen by a
 *    `distant` sensor reads L = E cos(theta_s) f_r exactly (one bounce,
 *    delta light), and its parameter table holds f_iso, f_vol, f_geo.
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
#include "kernel/core/rng.h"
#include "kernel/scene/param_table.h"
#include "kernel/scene/params.h"
#include "kernel/scene/scene.h"
#include "kernel/scene/update.h"
#include "kernel/textures/texture.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

/* Ross-Thick (Lucht et al. 2000, eq. 38) with phase angle xi. */
static double ref_kvol(double ti, double tv, double phi) {
  double cxi = cos(ti) * cos(tv) + sin(ti) * sin(tv) * cos(phi);
  if (cxi > 1) cxi = 1;
  double xi = acos(cxi);
  return ((PI / 2 - xi) * cos(xi) + sin(xi)) / (cos(ti) + cos(tv)) - PI / 4;
}

/* Li-Sparse Reciprocal (eqs. 39-44) with the primed angles of eq. 44. */
static double ref_kgeo(double ti, double tv, double phi, double h_b, double b_r) {
  double tip = atan(b_r * tan(ti)), tvp = atan(b_r * tan(tv));
  double cxip = cos(tip) * cos(tvp) + sin(tip) * sin(tvp) * cos(phi);
  double D = sqrt(fmax(0, tan(tip) * tan(tip) + tan(tvp) * tan(tvp) - 2 * tan(tip) * tan(tvp) * cos(phi)));
  double secs = 1 / cos(tip) + 1 / cos(tvp);
  double cost = h_b * sqrt(D * D + pow(tan(tip) * tan(tvp) * sin(phi), 2)) / secs;
  if (cost > 1) cost = 1;
  double t = acos(cost);
  double O = (t - sin(t) * cos(t)) * secs / PI;
  return O - secs + 0.5 * (1 + cxip) / cos(tip) / cos(tvp);
}

typedef struct rtls_case {
  texture *t[3];
  bsdf *b;
} rtls_case;

static rtls_case make(double fi, double fv, double fg, double h, double r, double b) {
  rtls_case c;
  c.t[0] = uniform_texture_const(fi, NULL);
  c.t[1] = uniform_texture_const(fv, NULL);
  c.t[2] = uniform_texture_const(fg, NULL);
  c.b = rtls_new(c.t[0], c.t[1], c.t[2], h, r, b);
  return c;
}
static void release(rtls_case *c) {
  tb_free_bsdf(c->b);
  for (int k = 0; k < 3; k++) tb_free_tex(c->t[k]);
}

static void test_closed_form(void) {
  pcg32 rng;
  pcg32_seed(&rng, 25, 1);
  const double shapes[2][3] = {{2.0, 1.0, 1.0}, {2.0, 1.0, 2.5}}; /* h, r, b */
  double worst = 0;
  for (int sh = 0; sh < 2; sh++) {
    double h = shapes[sh][0], r = shapes[sh][1], b = shapes[sh][2];
    for (int s = 0; s < 100; s++) {
      double fi = pcg32_next_double(&rng), fv = 0.3 * pcg32_next_double(&rng),
             fg = 0.1 * pcg32_next_double(&rng);
      double ti = 1.45 * pcg32_next_double(&rng), tv = 1.45 * pcg32_next_double(&rng);
      double pi_ = 2 * PI * pcg32_next_double(&rng), pv = 2 * PI * pcg32_next_double(&rng);
      vec3 wi = v3(sin(ti) * cos(pi_), sin(ti) * sin(pi_), cos(ti));
      vec3 wo = v3(sin(tv) * cos(pv), sin(tv) * sin(pv), cos(tv));
      rtls_case c = make(fi, fv, fg, h, r, b);
      surface_interaction si = tb_si_with(wi);
      double brf = c.b->ops->eval(c.b, &si, wo).c[0] * PI / wo.z;
      double want = fi + fv * ref_kvol(ti, tv, pi_ - pv) + fg * ref_kgeo(ti, tv, pi_ - pv, h / b, b / r);
      double err = fabs(brf - want);
      worst = fmax(worst, err);
      CHECK(err <= 1e-9, "shape %d pair %d: BRF %.12g vs Lucht %.12g", sh, s, brf, want);
      release(&c);
    }
  }
  printf("  rtls vs Lucht et al. (2000): worst |dBRF| %.3g over 200 pairs\n", worst);
  /* Sun and view at nadir: K_vol = K_geo = 0. */
  rtls_case c = make(0.3, 0.2, 0.1, 2, 1, 1);
  surface_interaction si = tb_si_with(v3(0, 0, 1));
  CHECK_REL(c.b->ops->eval(c.b, &si, v3(0, 0, 1)).c[0], 0.3 / PI, 1e-14);
  CHECK(c.b->ops->eval(c.b, &si, tb_dir_deg(120, 0)).c[0] == 0.0, "one-sided");
  surface_interaction below = tb_si_with(tb_dir_deg(120, 0));
  CHECK(c.b->ops->eval(c.b, &below, v3(0, 0, 1)).c[0] == 0.0, "black from below");
  /* Reciprocity. */
  for (int s = 0; s < 20; s++) {
    vec3 a = tb_dir_deg(80 * pcg32_next_double(&rng), 360 * pcg32_next_double(&rng));
    vec3 d = tb_dir_deg(80 * pcg32_next_double(&rng), 360 * pcg32_next_double(&rng));
    surface_interaction sa = tb_si_with(a), sd = tb_si_with(d);
    CHECK_REL(c.b->ops->eval(c.b, &sa, d).c[0] / d.z, c.b->ops->eval(c.b, &sd, a).c[0] / a.z, 1e-12);
  }
  release(&c);
}

static void run_chi2(const bsdf *b, vec3 wi, const char *what) {
  chi2_bsdf c = {b, tb_si_with(wi)};
  chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
  cfg.sample_count = 200000;
  cfg.test_count = 4;
  cfg.ires = 8;
  chi2_result r = chi2_run(&cfg, chi2_bsdf_sample, chi2_bsdf_pdf, &c);
  CHECK(r.passed, "chi2 %s: p = %g, chi2 = %g, dof = %d: %s", what, r.p_value, r.chi2, r.dof, r.reason);
}

static void test_sampling(void) {
  rtls_case c = make(0.209741, 0.081384, 0.004140, 2, 1, 1);
  pcg32 rng;
  pcg32_seed(&rng, 4, 4);
  for (int i = 0; i < 2; i++) {
    vec3 wi = tb_dir_deg(i ? 65.0 : 15.0, 40.0);
    run_chi2(c.b, wi, i ? "rtls at 65 deg" : "rtls at 15 deg");
    surface_interaction si = tb_si_with(wi);
    int bad = 0;
    for (int s = 0; s < 200; s++) {
      bsdf_sample bs;
      color w = c.b->ops->sample(c.b, &si, 0.5, v2(pcg32_next_double(&rng), pcg32_next_double(&rng)), &bs);
      if (!(bs.pdf > 0)) continue;
      double p = c.b->ops->pdf(c.b, &si, bs.wo), e = c.b->ops->eval(c.b, &si, bs.wo).c[0];
      if (fabs(p - bs.pdf) > 1e-12 * p || fabs(w.c[0] - e / p) > 1e-12 * fmax(1, fabs(w.c[0]))) bad++;
    }
    CHECK(bad == 0, "%d weight/pdf mismatches", bad);
  }
  release(&c);
}

/* Plate under a sun at (30 deg, azimuth 0), sensor at (40 deg, azimuth
 * 150): L = E cos(30 deg) f_r. */
static const char *json_scene =
    "{\"type\": \"scene\","
    " \"sensor\": {\"type\": \"distant\", \"direction\": [%.17g, %.17g, %.17g],"
    "   \"target\": [0, 0, 0],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
    " \"integrator\": {\"type\": \"path\"},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [%.17g, %.17g, %.17g], \"irradiance\": 1.7},"
    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"rtls\", \"id\": \"soil\","
    "   \"f_iso\": 0.25, \"f_vol\": 0.12, \"f_geo\": 0.03}}}";

static const char *xml_scene =
    "<scene version=\"3.0.0\">"
    " <sensor type=\"distant\"><vector name=\"direction\" x=\"%.17g\" y=\"%.17g\" z=\"%.17g\"/>"
    "  <point name=\"target\" x=\"0\" y=\"0\" z=\"0\"/>"
    "  <sampler type=\"independent\"><integer name=\"sample_count\" value=\"4\"/></sampler>"
    "  <film type=\"hdrfilm\"><integer name=\"width\" value=\"1\"/><integer name=\"height\" value=\"1\"/>"
    "   <rfilter type=\"box\"/></film></sensor>"
    " <integrator type=\"path\"/>"
    " <emitter type=\"directional\"><vector name=\"direction\" x=\"%.17g\" y=\"%.17g\" z=\"%.17g\"/>"
    "  <float name=\"irradiance\" value=\"1.7\"/></emitter>"
    " <shape type=\"rectangle\"><bsdf type=\"rtls\" id=\"soil\"><float name=\"f_iso\" value=\"0.25\"/>"
    "  <float name=\"f_vol\" value=\"0.12\"/><float name=\"f_geo\" value=\"0.03\"/></bsdf></shape>"
    "</scene>";

static void test_scene(void) {
  vec3 view = tb_dir_deg(40, 150), sun = tb_dir_deg(30, 0);
  rtls_case c = make(0.25, 0.12, 0.03, 2, 1, 1);
  surface_interaction si = tb_si_with(view);
  double want = 1.7 * c.b->ops->eval(c.b, &si, sun).c[0];
  release(&c);
  for (int x = 0; x < 2; x++) {
    char buf[4096];
    snprintf(buf, sizeof buf, x ? xml_scene : json_scene, -view.x, -view.y, -view.z, -sun.x, -sun.y, -sun.z);
    scene *s = tsup_load(buf, "mono");
    REQUIRE(s, "%s scene loads", x ? "XML" : "JSON");
    film_image img;
    REQUIRE(tsup_render(s, 0, 3, 1, &img), "render");
    CHECK_REL(img.data[0], want, 1e-5);
    const char *keys[3] = {"rtls:soil:f_iso.value", "rtls:soil:f_vol.value", "rtls:soil:f_geo.value"};
    for (int k = 0; k < 3; k++) {
      size_t idx;
      rsw_err err = {0};
      CHECK(params_lookup(s, keys[k], &idx, &err) == RSW_OK, "%s: %s", keys[k], err.msg);
    }
    size_t idx;
    rsw_err err = {0};
    CHECK(params_lookup(s, "rtls:soil:h", &idx, &err) != RSW_OK, "h is not a parameter (as in Eradiate)");
    film_image_free(&img);
    scene_free(s);
  }
  /* Bad shape parameters are refused, naming the key. */
  scene *s = tsup_load("{\"type\": \"scene\", \"a\": {\"type\": \"rtls\", \"b\": 0}}", "mono");
  CHECK(s == NULL, "b = 0 refused");
  if (s) scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_closed_form);
  RSW_TEST_RUN(test_sampling);
  RSW_TEST_RUN(test_scene);
  RSW_TEST_END("test_rtls");
}
