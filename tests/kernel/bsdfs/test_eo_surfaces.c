/* Earth-observation surfaces in closed-form scenes (docs/kernel-conventions.md
 * #rpv, #bilambertian):
 *  - rpv with k = 1, g = 0, rho_c = 1 is Lambertian: the same film, bit
 *    for bit, as `diffuse` (same scene, same seed);
 *  - a bilambertian sheet (r, t) alone under a constant environment L
 *    leaves radiance (r + t) L on either side (reflected L from its own
 *    side plus transmitted L from the other);
 *  - a leaf sheet (r, t) one unit above a Lambertian soil rho_s, under a
 *    sun at nadir: BRF = pi L / E = r + t^2 rho_s / (1 - r rho_s) (the
 *    geometric series of sheet-soil inter-reflections; every surface is
 *    Lambertian so the radiance above is isotropic). The 100 x 100 sheet
 *    stands in for an infinite one: the edge loss seen from the central
 *    target is ~1e-4.
 * Monte Carlo checks are 3 standard errors of the film mean over pixels,
 * fixed seeds. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../support/test.h"
#include "../../support/tsup.h"
#include "image_exr.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

static void check_mean_3sigma(const film_image *img, double expect, const char *what) {
  for (int c = 0; c < img->channels; c++) {
    double m, sem;
    tsup_stats(img, c, &m, &sem);
    CHECK(fabs(m - expect) <= 3 * sem + 1e-12, "%s: channel %d mean %.6g vs expected %.6g (3 sigma = %.3g)",
          what, c, m, expect, 3 * sem);
    CHECK(sem < 0.02 * expect, "%s: standard error %.3g too large for a meaningful test", what, sem);
  }
}

static scene *plate(const char *bsdf_json) {
  char buf[4096];
  snprintf(buf, sizeof buf,
           "{\"type\": \"scene\","
           " \"sensor\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\"},"
           "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
           "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16,"
           "     \"rfilter\": {\"type\": \"box\"}}},"
           " \"integrator\": {\"type\": \"path\"},"
           " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0.2, -0.8], \"irradiance\": 1.3},"
           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": %s},"
           " \"ball\": {\"type\": \"sphere\", \"radius\": 0.3, \"center\": [0.2, 0.1, 0.3],"
           "   \"bsdf\": %s}}",
           bsdf_json, bsdf_json);
  return tsup_load(buf, NULL);
}

static void test_rpv_lambertian_bitwise(void) {
  scene *a = plate("{\"type\": \"diffuse\", \"reflectance\": 0.37}");
  scene *b = plate("{\"type\": \"rpv\", \"rho_0\": 0.37, \"k\": 1, \"g\": 0, \"rho_c\": 1}");
  REQUIRE(a && b, "scenes");
  film_image ia, ib;
  REQUIRE(tsup_render(a, 0, 42, 1, &ia), "render diffuse");
  REQUIRE(tsup_render(b, 0, 42, 1, &ib), "render rpv");
  REQUIRE(ia.width == ib.width && ia.height == ib.height && ia.channels == ib.channels, "shapes");
  size_t n = (size_t)ia.width * ia.height * ia.channels;
  CHECK(memcmp(ia.data, ib.data, n * sizeof ia.data[0]) == 0,
        "rpv(k=1, g=0, rho_c=1) film differs from diffuse");
  double sum = 0;
  for (size_t i = 0; i < n; i++) sum += ia.data[i];
  CHECK(sum > 0, "the films are not black");
  film_image_free(&ia);
  film_image_free(&ib);
  scene_free(a);
  scene_free(b);
}

/* Sheet of `r`, `t` (normal +z, or -z when flipped) under constant L = 2,
 * seen from above by an hdistant sensor targeting its middle. */
static void sheet_alone(bool flipped) {
  const double r = 0.3, t = 0.5, L = 2.0;
  char buf[4096];
  snprintf(buf, sizeof buf,
           "{\"type\": \"scene\","
           " \"sensor\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\","
           "     \"to_world\": [{\"scale\": 0.5}]},"
           "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 64},"
           "   \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8,"
           "     \"rfilter\": {\"type\": \"box\"}}},"
           " \"integrator\": {\"type\": \"path\"},"
           " \"env\": {\"type\": \"constant\", \"radiance\": %g},"
           " \"sheet\": {\"type\": \"rectangle\", \"to_world\": [%s],"
           "   \"bsdf\": {\"type\": \"bilambertian\", \"reflectance\": %g, \"transmittance\": %g}}}",
           L, flipped ? "{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}}" : "{\"scale\": 1}", r, t);
  scene *s = tsup_load(buf, "mono");
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, flipped ? 8 : 7, 1, &img), "render");
  check_mean_3sigma(&img, (r + t) * L, flipped ? "sheet seen from its back" : "sheet seen from its front");
  film_image_free(&img);
  scene_free(s);
}

static void test_bilambertian_sheet_both_sides(void) {
  sheet_alone(false);
  sheet_alone(true);
}

static void test_leaf_over_soil_brf(void) {
  const double r = 0.45, t = 0.4, rho_s = 0.3, E = 1.0;
  char buf[4096];
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\","
      " \"sensor\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\","
      "     \"to_world\": [{\"scale\": 0.1}, {\"translate\": [0, 0, 1]}]},"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 256},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8,"
      "     \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\"},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": %g},"
      " \"sheet\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 50}, {\"translate\": [0, 0, 1]}],"
      "   \"bsdf\": {\"type\": \"bilambertian\", \"reflectance\": %g, \"transmittance\": %g}},"
      " \"soil\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 50}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": %g}}}",
      E, r, t, rho_s);
  scene *s = tsup_load(buf, "mono");
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 9, 1, &img), "render");
  /* Radiance L = BRF E / pi. */
  double brf = r + t * t * rho_s / (1.0 - r * rho_s);
  check_mean_3sigma(&img, brf * E / PI, "leaf over soil");
  film_image_free(&img);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_rpv_lambertian_bitwise);
  RSW_TEST_RUN(test_bilambertian_sheet_both_sides);
  RSW_TEST_RUN(test_leaf_over_soil_brf);
  RSW_TEST_END("test_eo_surfaces");
}
