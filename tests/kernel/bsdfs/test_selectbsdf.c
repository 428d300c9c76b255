/* selectbsdf (server/kernel/bsdfs/selectbsdf.c,
 * docs/kernel-conventions.md#selectbsdf):
 *  - picks by texture: a plate whose indices are a checkerboard of 0 and
 *    1 over diffuse 0.2 and diffuse 0.8, under a sun, seen by a 2 x 2
 *    mpdistant through a disc target at nadir: each pixel is exactly
 *    rho_k E cos(theta_s) / pi of its quadrant's BSDF (JSON and XML);
 *    indices of 5 on the odd checks make those pixels black;
 *  - chi-square of sample() against pdf() where it selects a
 *    roughconductor (200,000 samples, alpha 0.01, 2 runs): selection
 *    hands sampling to the chosen BSDF;
 *  - a constant index outside [0, N) and fewer than two BSDFs are
 *    refused; the parameters are indices and bsdf_0, bsdf_1. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../support/bsdf_test.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"
#include "kernel/scene/param_table.h"
#include "kernel/scene/params.h"
#include "kernel/scene/scene.h"
#include "kernel/scene/update.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

static const char *sensor_json =
    "\"sensor\": {\"type\": \"mpdistant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0], "
    "\"target_radius\": 1.5,"
    " \"film\": {\"type\": \"hdrfilm\", \"width\": 2, \"height\": 2, \"rfilter\": {\"type\": \"box\"}}}";

static scene *plate(const char *bsdf_json) {
  char buf[4096];
  snprintf(buf, sizeof buf,
           "{\"type\": \"scene\", \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0, -1]},"
           " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 2}], \"bsdf\": %s}, %s}",
           bsdf_json, sensor_json);
  return tsup_load(buf, "mono");
}

static void check_quadrants(scene *s, double r0, double r1, const char *what) {
  film_image img;
  REQUIRE(tsup_render(s, 0, 3, 1, &img), "render");
  double c = cos(atan(0.5)) / PI; /* E = 1, sun at atan(0.5) from zenith */
  /* Film quadrants follow the disc's; the checks put color0 (index 0) on
   * the diagonal x y > 0. */
  double d0 = img.data[0], d1 = img.data[1];
  printf("  %s: pixels %.7g %.7g / %.7g %.7g\n", what, img.data[0], img.data[1], img.data[2], img.data[3]);
  CHECK(img.data[3] == d0 && img.data[2] == d1, "%s: diagonals agree", what);
  bool a = fabs(d0 - r0 * c) <= 1e-6 * c && fabs(d1 - r1 * c) <= 1e-6 * c;
  bool b = fabs(d0 - r1 * c) <= 1e-6 * c && fabs(d1 - r0 * c) <= 1e-6 * c;
  CHECK(a || b, "%s: each pixel sees its quadrant's BSDF (%g, %g)", what, r0 * c, r1 * c);
  film_image_free(&img);
}

static void test_picks_by_texture(void) {
  scene *s = plate("{\"type\": \"selectbsdf\", \"id\": \"sel\", \"indices\": {\"type\": \"checkerboard\","
                   " \"color0\": 0, \"color1\": 1}, \"a\": {\"type\": \"diffuse\", \"reflectance\": 0.2},"
                   " \"b\": {\"type\": \"diffuse\", \"reflectance\": 0.8}}");
  REQUIRE(s, "JSON scene");
  check_quadrants(s, 0.2, 0.8, "JSON");
  const char *keys[3] = {"selectbsdf:sel:indices.color0.value", "selectbsdf:sel:bsdf_0.reflectance.value",
                         "selectbsdf:sel:bsdf_1.reflectance.value"};
  for (int k = 0; k < 3; k++) {
    size_t idx;
    rsw_err err = {0};
    CHECK(params_lookup(s, keys[k], &idx, &err) == RSW_OK, "%s: %s", keys[k], err.msg);
  }
  scene_free(s);
  s = plate(
      "{\"type\": \"selectbsdf\", \"indices\": {\"type\": \"checkerboard\", \"color0\": 0, \"color1\": 5},"
      " \"a\": {\"type\": \"diffuse\", \"reflectance\": 0.2}, \"b\": {\"type\": \"diffuse\"}}");
  REQUIRE(s, "out-of-range scene");
  check_quadrants(s, 0.2, 0.0, "index 5 is black");
  scene_free(s);
  const char *xml =
      "<scene version=\"3.0.0\"><emitter type=\"directional\"><vector name=\"direction\" x=\"0.5\" y=\"0\" "
      "z=\"-1\"/></emitter><shape type=\"rectangle\"><transform name=\"to_world\"><scale value=\"2\"/>"
      "</transform><bsdf type=\"selectbsdf\"><texture type=\"checkerboard\" name=\"indices\"><float "
      "name=\"color0\" value=\"0\"/><float name=\"color1\" value=\"1\"/></texture><bsdf type=\"diffuse\">"
      "<float name=\"reflectance\" value=\"0.2\"/></bsdf><bsdf type=\"diffuse\"><float name=\"reflectance\" "
      "value=\"0.8\"/></bsdf></bsdf></shape><sensor type=\"mpdistant\"><vector name=\"direction\" x=\"0\" "
      "y=\"0\" z=\"-1\"/><point name=\"target\" x=\"0\" y=\"0\" z=\"0\"/><float name=\"target_radius\" "
      "value=\"1.5\"/><film type=\"hdrfilm\"><integer name=\"width\" value=\"2\"/><integer name=\"height\" "
      "value=\"2\"/><rfilter type=\"box\"/></film></sensor></scene>";
  s = tsup_load(xml, "mono");
  REQUIRE(s, "XML scene");
  check_quadrants(s, 0.2, 0.8, "XML");
  scene_free(s);
}

static const bsdf *find_bsdf(const scene *s, const char *id) {
  for (size_t i = 0; i < s->n_objects; i++) {
    const object *o = s->objects[i];
    if (o->plugin && o->plugin->cls == CLS_BSDF && o->id && strcmp(o->id, id) == 0) return (const bsdf *)o;
  }
  return NULL;
}

static void test_chi2(void) {
  scene *s = plate("{\"type\": \"selectbsdf\", \"id\": \"sel\", \"indices\": 1,"
                   " \"a\": {\"type\": \"diffuse\"}, \"b\": {\"type\": \"roughconductor\", \"alpha\": 0.3}}");
  REQUIRE(s, "scene");
  const bsdf *b = find_bsdf(s, "sel");
  REQUIRE(b, "the selectbsdf object");
  for (int i = 0; i < 2; i++) {
    chi2_bsdf c = {b, tb_si_with(tb_dir_deg(i ? 60 : 20, 30))};
    chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
    cfg.sample_count = 200000;
    cfg.test_count = 2;
    chi2_result r = chi2_run(&cfg, chi2_bsdf_sample, chi2_bsdf_pdf, &c);
    CHECK(r.passed, "chi2 %d: p = %g, chi2 = %g: %s", i, r.p_value, r.chi2, r.reason);
  }
  scene_free(s);
}

static void test_refused(void) {
  const char *bad[3] = {
      "{\"type\": \"selectbsdf\", \"indices\": 2, \"a\": {\"type\": \"diffuse\"},"
      " \"b\": {\"type\": \"diffuse\"}}",
      "{\"type\": \"selectbsdf\", \"indices\": 0, \"a\": {\"type\": \"diffuse\"}}",
      "{\"type\": \"selectbsdf\", \"a\": {\"type\": \"diffuse\"}, \"b\": {\"type\": \"diffuse\"}}"};
  for (int k = 0; k < 3; k++) {
    scene *s = plate(bad[k]);
    CHECK(s == NULL, "refused: %s", bad[k]);
    if (s) scene_free(s);
  }
}

int main(void) {
  RSW_TEST_RUN(test_picks_by_texture);
  RSW_TEST_RUN(test_chi2);
  RSW_TEST_RUN(test_refused);
  RSW_TEST_END("test_selectbsdf");
}
