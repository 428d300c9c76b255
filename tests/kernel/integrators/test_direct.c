/* The `direct` integrator (integrators/direct.c) against `path` with
 * max_depth 2, which estimates the same direct illumination.
 *
 * An mradiancemeter of N identical rays (one per pixel) gives N
 * independent estimates of one radiance, so the film's mean and its
 * standard error are the estimate and its error. The two integrators'
 * means must agree within 3 combined standard errors (fixed seeds), for a
 * diffuse and a rough floor lit by an area light, an environment and a
 * point light, partly shadowed by a sphere, with several emitter/BSDF
 * sample counts. A point light alone gives rho I / (pi h^2) exactly
 * whatever emitter_samples is. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

enum {
  NPIX = 400
};

static char *scene_text(const char *integ, const char *floor_bsdf, const char *bulb) {
  sbuf b = {0};
  sb_printf(&b, "{\"type\": \"scene\", \"sensor\": {\"type\": \"mradiancemeter\", \"origins\": \"");
  for (int i = 0; i < NPIX; i++) sb_printf(&b, "%s0.3 -0.6 1.5", i ? " " : "");
  sb_printf(&b, "\", \"directions\": \"");
  for (int i = 0; i < NPIX; i++) sb_printf(&b, "%s-0.2 0.4 -1", i ? " " : "");
  sb_printf(
      &b,
      "\", \"sampler\": {\"type\": \"independent\", \"sample_count\": 64},"
      " \"film\": {\"type\": \"hdrfilm\", \"width\": %d, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": %s,"
      " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [4, 4, 1]}], \"bsdf\": %s},"
      " \"ball\": {\"type\": \"sphere\", \"center\": [0.4, 0.3, 0.6], \"radius\": 0.35,"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.2}},"
      " \"lamp\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [0.5, 0.5, 1]},"
      "   {\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 160}}, {\"translate\": [0.5, 0.8, 2]}],"
      "   \"emitter\": {\"type\": \"area\", \"radiance\": 6}},"
      " \"sky\": {\"type\": \"constant\", \"radiance\": 0.4}%s%s}",
      NPIX, integ, floor_bsdf, bulb ? "," : "", bulb ? bulb : "");
  return b.p;
}

static void estimate(const char *integ, const char *floor_bsdf, const char *bulb, uint64_t seed, double *mean,
                     double *sem) {
  char *t = scene_text(integ, floor_bsdf, bulb);
  scene *s = tsup_load(t, "mono");
  free(t);
  *mean = NAN, *sem = NAN;
  if (!s) return;
  film_image img;
  if (tsup_render(s, 0, seed, 2, &img)) {
    tsup_stats(&img, 0, mean, sem);
    film_image_free(&img);
  }
  scene_free(s);
}

static void compare(const char *floor_bsdf, const char *bulb, const char *direct_json) {
  double mp, sp, md, sd;
  estimate("{\"type\": \"path\", \"max_depth\": 2}", floor_bsdf, bulb, 3, &mp, &sp);
  estimate(direct_json, floor_bsdf, bulb, 5, &md, &sd);
  double tol = 3 * sqrt(sp * sp + sd * sd);
  CHECK(fabs(mp - md) <= tol, "%s with %s: path %.6g +- %.2g, direct %.6g +- %.2g (3 sigma %.3g)",
        direct_json, floor_bsdf, mp, sp, md, sd, tol);
  CHECK(sp < 0.01 * mp && sd < 0.01 * md, "errors too large for a meaningful test: %.3g, %.3g", sp, sd);
}

#define BULB "\"bulb\": {\"type\": \"point\", \"position\": [-0.5, 0.2, 1.2], \"intensity\": 0.8}"

static void test_direct_equals_path_diffuse(void) {
  const char *floor = "{\"type\": \"diffuse\", \"reflectance\": 0.6}";
  compare(floor, BULB, "{\"type\": \"direct\"}");
  compare(floor, BULB, "{\"type\": \"direct\", \"emitter_samples\": 3, \"bsdf_samples\": 1}");
  /* BSDF samples alone never reach a point light: without it. */
  compare(floor, NULL, "{\"type\": \"direct\", \"emitter_samples\": 0, \"bsdf_samples\": 2}");
}

static void test_direct_equals_path_rough(void) {
  const char *floor = "{\"type\": \"roughplastic\", \"alpha\": 0.15, \"diffuse_reflectance\": 0.3}";
  compare(floor, BULB, "{\"type\": \"direct\", \"shading_samples\": 2}");
  compare(floor, BULB, "{\"type\": \"direct\", \"emitter_samples\": 1, \"bsdf_samples\": 4}");
}

/* A point light over a diffuse floor: L = rho I / (pi h^2) with no
 * variance, for any number of light samples; BSDF samples see nothing. */
static void test_point_light_exact(void) {
  const int counts[3] = {1, 2, 5};
  for (int k = 0; k < 3; k++) {
    char buf[2048];
    snprintf(
        buf, sizeof buf,
        "<scene version=\"3.0.0\">"
        " <integrator type=\"direct\"><integer name=\"emitter_samples\" value=\"%d\"/></integrator>"
        " <sensor type=\"radiancemeter\"><point name=\"origin\" value=\"0, 0, 1\"/>"
        "  <vector name=\"direction\" value=\"0, 0, -1\"/>"
        "  <film type=\"hdrfilm\"><integer name=\"width\" value=\"1\"/><integer name=\"height\" value=\"1\"/>"
        "   <rfilter type=\"box\"/></film></sensor>"
        " <emitter type=\"point\"><point name=\"position\" value=\"0, 0, 2\"/>"
        "  <float name=\"intensity\" value=\"3\"/></emitter>"
        " <shape type=\"rectangle\"><bsdf type=\"diffuse\"/></shape>"
        "</scene>",
        counts[k]);
    scene *s = tsup_load(buf, "mono");
    REQUIRE(s, "scene");
    film_image img;
    REQUIRE(tsup_render(s, 4, 1, 1, &img), "render");
    CHECK_REL(img.data[0], 0.5 * 3 / (RSW_PI * 4), 1e-5);
    film_image_free(&img);
    scene_free(s);
  }
}

static void test_bad_input(void) {
  const char *bad[] = {
      "{\"type\": \"direct\", \"emitter_samples\": 0, \"bsdf_samples\": 0}",
      "{\"type\": \"direct\", \"shading_samples\": 2, \"bsdf_samples\": 1}",
      "{\"type\": \"direct\", \"emitter_samples\": -1}",
      "{\"type\": \"direct\", \"max_depth\": 3}",
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
    CHECK(tsup_refused("{\"type\": \"scene\", \"integrator\": %s}", bad[i]), "refused: %s", bad[i]);
}

int main(void) {
  RSW_TEST_RUN(test_point_light_exact);
  RSW_TEST_RUN(test_direct_equals_path_diffuse);
  RSW_TEST_RUN(test_direct_equals_path_rough);
  RSW_TEST_RUN(test_bad_input);
  RSW_TEST_END("test_direct");
}
