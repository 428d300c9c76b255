/* mpdistant (server/kernel/sensors/mpdistant.c,
 * docs/kernel-conventions.md#mpdistant), a plate under a directional sun
 * (one bounce, a delta light: every pixel is exact):
 *  - a 2 x 2 film looking down at a checkerboard plate through a disc
 *    target (a point and target_radius): each pixel sees one check,
 *    rho_k E cos(theta_s) / pi (to float precision), the diagonal pixels
 *    alike;
 *  - a uniform plate seen by a 4 x 3 mpdistant: every pixel equals the
 *    1 x 1 `distant` sensor's value in the same direction, for a shape
 *    target, a point target with target_radius, and no target;
 *  - JSON and XML; target_radius without a point target is refused; the
 *    pixel directions are the sensor's; the parameters are to_world and
 *    direction. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../support/test.h"
#include "../../support/tsup.h"
#include "kernel/scene/param_table.h"
#include "kernel/scene/params.h"
#include "kernel/scene/scene.h"
#include "kernel/scene/update.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

static const double E = 1.6, TS = 25; /* sun irradiance, zenith (degrees) */

static scene *load(const char *bsdf_json, const char *sensor_json) {
  char buf[4096];
  snprintf(buf, sizeof buf,
           "{\"type\": \"scene\", \"sun\": {\"type\": \"directional\", \"irradiance\": %g,"
           " \"direction\": [%.17g, 0, %.17g]},"
           " \"plate\": {\"type\": \"rectangle\", \"id\": \"plate\", \"to_world\": [{\"scale\": 2}], "
           "\"bsdf\": %s},"
           " \"sensor\": %s}",
           E, -sin(TS * PI / 180), -cos(TS * PI / 180), bsdf_json, sensor_json);
  return tsup_load(buf, "mono");
}

static void test_checkerboard(void) {
  /* Nadir view, a disc of radius 1.5 around the plate's centre: the
   * concentric map keeps the film's quadrants in the disc's quadrants,
   * which the checks (boundaries at x = 0 and y = 0 of the 4 x 4 plate)
   * follow. */
  const char *sensor_json =
      "{\"type\": \"mpdistant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0], \"target_radius\": 1.5,"
      " \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
      " \"film\": {\"type\": \"hdrfilm\", \"width\": 2, \"height\": 2, \"rfilter\": {\"type\": \"box\"}}}";
  scene *s = load("{\"type\": \"diffuse\", \"reflectance\": {\"type\": \"checkerboard\", \"color0\": 0.7, "
                  "\"color1\": 0.1}}",
                  sensor_json);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 5, 1, &img), "render");
  REQUIRE(img.width == 2 && img.height == 2, "2 x 2 film");
  double c = E * cos(TS * PI / 180) / PI;
  double p00 = img.data[0], p10 = img.data[1], p01 = img.data[2], p11 = img.data[3];
  printf("  pixels %.7g %.7g / %.7g %.7g; checks %.7g and %.7g\n", p00, p10, p01, p11, 0.7 * c, 0.1 * c);
  CHECK(p00 == p11 && p10 == p01, "the diagonals agree");
  bool a = fabs(p00 - 0.7 * c) <= 1e-6 * c && fabs(p10 - 0.1 * c) <= 1e-6 * c;
  bool b = fabs(p00 - 0.1 * c) <= 1e-6 * c && fabs(p10 - 0.7 * c) <= 1e-6 * c;
  CHECK(a || b, "each pixel sees one check");
  film_image_free(&img);
  scene_free(s);
}

static double distant_value(const char *dir) {
  char sensor_json[512];
  snprintf(sensor_json, sizeof sensor_json,
           "{\"type\": \"distant\", \"direction\": %s, \"target\": [0.3, 0.2, 0],"
           " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}",
           dir);
  scene *s = load("{\"type\": \"diffuse\", \"reflectance\": 0.35}", sensor_json);
  film_image img;
  double v = NAN;
  if (s && tsup_render(s, 0, 1, 1, &img)) {
    v = img.data[0];
    film_image_free(&img);
  }
  if (s) scene_free(s);
  return v;
}

static void test_matches_distant(void) {
  const char *dir = "[0.4, -0.3, -0.8]";
  double want = distant_value(dir);
  CHECK_REL(want, 0.35 * E * cos(TS * PI / 180) / PI, 1e-6);
  const char *targets[3] = {"\"target\": {\"type\": \"ref\", \"id\": \"plate\"},",
                            "\"target\": [0.1, 0, 0], \"target_radius\": 0.5,", ""};
  for (int k = 0; k < 3; k++) {
    char sensor_json[1024];
    snprintf(sensor_json, sizeof sensor_json,
             "{\"type\": \"mpdistant\", \"id\": \"mp\", \"direction\": %s, %s"
             " \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 3}}",
             dir, targets[k]);
    scene *s = load("{\"type\": \"diffuse\", \"reflectance\": 0.35}", sensor_json);
    REQUIRE(s, "scene %d", k);
    film_image img;
    REQUIRE(tsup_render(s, 0, 2, 1, &img), "render");
    int bad = 0;
    for (int i = 0; i < 12; i++) /* Without a target, rays that miss the 4 x 4 plate see nothing. */
      if (k < 2 ? fabs(img.data[i] - want) > 1e-6 * want
                : !(img.data[i] >= 0 && img.data[i] <= want * 1.000001))
        bad++;
    CHECK(bad == 0, "target %d: %d of 12 pixels differ from distant's %g", k, bad, want);
    if (k == 0) {
      size_t idx;
      rsw_err err = {0};
      CHECK(params_lookup(s, "mp.direction", &idx, &err) == RSW_OK, "%s", err.msg);
      CHECK(params_lookup(s, "mp.to_world", &idx, &err) == RSW_OK, "%s", err.msg);
    }
    film_image_free(&img);
    scene_free(s);
  }
}

static void test_xml_and_errors(void) {
  const char *xml =
      "<scene version=\"3.0.0\"><emitter type=\"directional\"><vector name=\"direction\" x=\"0\" y=\"0\" "
      "z=\"-1\"/></emitter><shape type=\"rectangle\" id=\"plate\"><bsdf type=\"diffuse\"><float "
      "name=\"reflectance\" value=\"0.5\"/></bsdf></shape><sensor type=\"mpdistant\"><vector "
      "name=\"direction\" "
      "x=\"0\" y=\"0\" z=\"-1\"/><ref name=\"target\" id=\"plate\"/><film type=\"hdrfilm\"><integer "
      "name=\"width\" value=\"3\"/><integer name=\"height\" value=\"2\"/></film></sensor></scene>";
  scene *s = tsup_load(xml, "mono");
  REQUIRE(s, "XML scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 2, 1, &img), "render");
  for (int i = 0; i < 6; i++) CHECK_REL(img.data[i], 0.5 / PI, 1e-6);
  film_image_free(&img);
  scene_free(s);
  s = load("{\"type\": \"diffuse\"}", "{\"type\": \"mpdistant\", \"target_radius\": 1}");
  CHECK(s == NULL, "target_radius without a point target is refused");
  if (s) scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_checkerboard);
  RSW_TEST_RUN(test_matches_distant);
  RSW_TEST_RUN(test_xml_and_errors);
  RSW_TEST_END("test_mpdistant");
}
