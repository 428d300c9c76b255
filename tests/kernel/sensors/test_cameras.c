/* `thinlens`, `orthographic`, and perspective's `fov_axis` and `x_fov`
 * (sensors/thinlens.c, orthographic.c, perspective.c): geometry checked
 * by what a camera sees of an emitting rectangle (radiance 1, black
 * elsewhere), through a box filter, so a pixel's value is the fraction of
 * its footprint that sees the rectangle.
 *
 * - perspective: a rectangle of half-width w at distance D fills the
 *   fraction w / (D tan(fov_x / 2)) of each row (fov_axis x), and its
 *   half-height h the fraction h / (D tan(fov_y / 2)) of each column
 *   (fov_axis y); after an update of `x_fov` the new fraction (and the
 *   film equals a reload with that fov, bitwise);
 * - orthographic: the view spans [-s, s] x [-s/a, s/a] for a to_world
 *   scale s: the fractions w / s and h a / s;
 * - thinlens: a half-plane edge at the focus distance renders sharp (each
 *   pixel 0 or 1); at depth Z it is blurred by the circle of confusion of
 *   radius c = R |1/F - 1/Z| (film units of tan): the expected pixel value
 *   is the mean over the pixel of the disk's marginal CDF
 *   G(u) = 1/2 + (u sqrt(1 - u^2) + asin u) / pi, u = x / c.
 * Tolerances: fractions to 2e-3 (the edge pixels' sampling noise); the
 * blurred profile per column to 0.025 (>= 4 standard errors at 8192
 * samples per column). Fixed seeds. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "../../../server/kernel/scene/param_table.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

/* An emitter rectangle facing the camera (which looks along +z from the
 * origin): x in [x0, x1], y in [y0, y1] at depth z. */
static void lamp(char *buf, size_t len, double x0, double x1, double y0, double y1, double z) {
  snprintf(buf, len,
           "{\"type\": \"rectangle\", \"to_world\": [{\"scale\": [%.17g, %.17g, 1]},"
           " {\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}}, {\"translate\": [%.17g, %.17g, %.17g]}],"
           " \"emitter\": {\"type\": \"area\", \"radiance\": 1}}",
           (x1 - x0) / 2, (y1 - y0) / 2, (x0 + x1) / 2, (y0 + y1) / 2, z);
}

static scene *camera_scene(const char *sensor_body, int w, int h, int spp, const char *lamp_json) {
  char buf[4096];
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\", \"integrator\": {\"type\": \"path\"},"
      " \"sensor\": {%s, \"sampler\": {\"type\": \"independent\", \"sample_count\": %d},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": %d, \"height\": %d, \"pixel_format\": \"luminance\","
      "     \"rfilter\": {\"type\": \"box\"}}},"
      " \"lamp\": %s}",
      sensor_body, spp, w, h, lamp_json);
  return tsup_load(buf, "mono");
}

static double film_mean(scene *s, uint64_t seed) {
  film_image img;
  if (!tsup_render(s, 0, seed, 2, &img)) return NAN;
  double m, sem;
  tsup_stats(&img, 0, &m, &sem);
  film_image_free(&img);
  return m;
}

static void test_perspective_fov_axis_and_x_fov(void) {
  const double D = 3, w = 0.8, fov = 50;
  char l[512];
  lamp(l, sizeof l, -w, w, -50, 50, D);
  scene *s = camera_scene("\"type\": \"perspective\", \"fov\": 50", 64, 16, 64, l);
  REQUIRE(s, "scene");
  double t = tan(fov / 2 * RSW_PI / 180);
  CHECK_ABS(film_mean(s, 1), w / (D * t), 2e-3);
  /* x_fov read back, updated, and equal to a reload. */
  size_t i;
  rsw_err err = {0};
  REQUIRE(params_lookup(s, "sensor.x_fov", &i, &err) == RSW_OK, "key sensor.x_fov");
  char *v = params_value_json(s, i, 0);
  CHECK(v && fabs(atof(v) - fov) < 1e-9, "x_fov reads %s", v ? v : "(null)");
  free(v);
  param_update u = {.key = "sensor.x_fov"};
  REQUIRE(param_value_parse("70", "x_fov", &u.value, &err) == RSW_OK, "parse");
  CHECK(scene_update(s, &u, 1, NULL, &err) == RSW_OK, "update x_fov");
  param_value_free(&u.value);
  CHECK_ABS(film_mean(s, 1), w / (D * tan(35 * RSW_PI / 180)), 2e-3);
  scene *s2 = camera_scene("\"type\": \"perspective\", \"fov\": 70", 64, 16, 64, l);
  REQUIRE(s2, "reload");
  film_image a, b;
  REQUIRE(tsup_render(s, 0, 9, 1, &a) && tsup_render(s2, 0, 9, 2, &b), "renders");
  size_t diff = 0;
  for (int k = 0; k < a.width * a.height; k++) diff += a.data[k] != b.data[k];
  CHECK(diff == 0, "%zu pixels differ between the x_fov update and the reload", diff);
  film_image_free(&a);
  film_image_free(&b);
  u.key = "sensor.x_fov";
  REQUIRE(param_value_parse("180", "x_fov", &u.value, &err) == RSW_OK, "parse");
  CHECK(scene_update(s, &u, 1, NULL, &err) != RSW_OK, "x_fov 180 refused");
  param_value_free(&u.value);
  scene_free(s);
  scene_free(s2);
  /* fov_axis y: 50 degrees vertically; a horizontal band of half-height h. */
  const double h = 0.6;
  lamp(l, sizeof l, -50, 50, -h, h, D);
  s = camera_scene("\"type\": \"perspective\", \"fov\": 50, \"fov_axis\": \"y\"", 32, 64, 64, l);
  REQUIRE(s, "scene");
  CHECK_ABS(film_mean(s, 2), h / (D * t), 2e-3);
  scene_free(s);
}

static void test_orthographic(void) {
  const double sc = 2.5, w = 1.0, h = 0.4;
  char l[512], body[512];
  lamp(l, sizeof l, -w, w, -50, 50, 4);
  snprintf(body, sizeof body, "\"type\": \"orthographic\", \"to_world\": [{\"scale\": [%g, %g, 1]}]", sc, sc);
  scene *s = camera_scene(body, 64, 32, 16, l);
  REQUIRE(s, "scene");
  CHECK_ABS(film_mean(s, 1), w / sc, 2e-3);
  scene_free(s);
  /* a = 2: y spans [-s/2, s/2]. */
  lamp(l, sizeof l, -50, 50, -h, h, 4);
  s = camera_scene(body, 64, 32, 16, l);
  REQUIRE(s, "scene");
  CHECK_ABS(film_mean(s, 1), h * 2 / sc, 2e-3);
  scene_free(s);
  /* The rays are parallel: a lamp twice as far covers the same. */
  lamp(l, sizeof l, -50, 50, -h, h, 400);
  s = camera_scene(body, 64, 32, 16, l);
  REQUIRE(s, "scene");
  CHECK_ABS(film_mean(s, 1), h * 2 / sc, 2e-3);
  scene_free(s);
}

/* The disk's marginal CDF (see the top of the file). */
static double disk_cdf(double u) {
  if (u <= -1) return 0;
  if (u >= 1) return 1;
  return 0.5 + (u * sqrt(1 - u * u) + asin(u)) / RSW_PI;
}

static void test_thinlens_focus_and_blur(void) {
  enum {
    W = 64,
    H = 8
  };
  const double fov = 40, R = 0.1, F = 4, t = tan(fov / 2 * RSW_PI / 180);
  char body[512], l[512];
  snprintf(body, sizeof body,
           "\"type\": \"thinlens\", \"fov\": %g, \"aperture_radius\": %g, \"focus_distance\": %g", fov, R, F);
  /* In focus: the edge x = 0 is sharp. */
  lamp(l, sizeof l, 0, 100, -100, 100, F);
  scene *s = camera_scene(body, W, H, 64, l);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 3, 2, &img), "render");
  int bad = 0;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      double want = x < W / 2 ? 1.0 : 0.0; /* film x runs to the camera's -x */
      bad += fabs(img.data[y * W + x] - want) > 1e-6;
    }
  CHECK(bad == 0, "in focus: %d pixels are neither fully lit nor dark as expected", bad);
  film_image_free(&img);
  scene_free(s);
  /* At Z = 1: c = R |1/F - 1/Z| (6.6 pixels). */
  const double Z = 1, c = R * fabs(1 / F - 1 / Z);
  lamp(l, sizeof l, 0, 100, -100, 100, Z);
  s = camera_scene(body, W, H, 1024, l);
  REQUIRE(s, "scene");
  REQUIRE(tsup_render(s, 0, 4, 2, &img), "render");
  double worst = 0;
  int blurred = 0;
  for (int x = 0; x < W; x++) {
    double got = 0, want = 0;
    for (int y = 0; y < H; y++) got += img.data[y * W + x] / H;
    for (int k = 0; k < 200; k++) {
      double sx = (x + (k + 0.5) / 200) / W;
      want += disk_cdf((1 - 2 * sx) * t / c) / 200;
    }
    worst = fmax(worst, fabs(got - want));
    blurred += got > 0.02 && got < 0.98;
  }
  CHECK(worst < 0.025, "out of focus: the edge profile differs from the circle of confusion by %.3g", worst);
  /* 2 c spans 2 c / (2 t / W) pixels: about 13. */
  CHECK(blurred >= 10 && blurred <= 15, "%d blurred columns, expected about %g", blurred, c * W / t);
  film_image_free(&img);
  scene_free(s);
}

static void test_xml_and_bad_input(void) {
  const char *xml =
      "<scene version=\"3.0.0\">"
      " <sensor type=\"thinlens\"><float name=\"fov\" value=\"30\"/>"
      "  <float name=\"aperture_radius\" value=\"0.05\"/><float name=\"focus_distance\" value=\"3\"/>"
      "  <film type=\"hdrfilm\"><integer name=\"width\" value=\"8\"/>"
      "   <integer name=\"height\" value=\"8\"/></film></sensor>"
      " <sensor type=\"orthographic\"><transform name=\"to_world\"><scale value=\"2\"/></transform>"
      "  <film type=\"hdrfilm\"><integer name=\"width\" value=\"8\"/>"
      "   <integer name=\"height\" value=\"8\"/></film></sensor>"
      " <shape type=\"rectangle\"/></scene>";
  scene *s = tsup_load(xml, NULL);
  CHECK(s && s->n_sensors == 2, "XML thinlens and orthographic");
  scene_free(s);
  const char *bad[] = {
      "{\"type\": \"thinlens\"}",
      "{\"type\": \"thinlens\", \"aperture_radius\": 0}",
      "{\"type\": \"thinlens\", \"aperture_radius\": 0.1, \"focus_distance\": -1}",
      "{\"type\": \"thinlens\", \"aperture_radius\": 0.1, \"to_world\": [{\"scale\": 2}]}",
      "{\"type\": \"orthographic\", \"near_clip\": 5, \"far_clip\": 1}",
      "{\"type\": \"perspective\", \"fov\": 40, \"fov_axis\": \"z\"}",
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
    CHECK(tsup_refused("{\"type\": \"scene\", \"sensor\": %s}", bad[i]), "refused: %s", bad[i]);
}

int main(void) {
  RSW_TEST_RUN(test_perspective_fov_axis_and_x_fov);
  RSW_TEST_RUN(test_orthographic);
  RSW_TEST_RUN(test_thinlens_focus_and_blur);
  RSW_TEST_RUN(test_xml_and_bad_input);
  RSW_TEST_END("test_cameras");
}
