/* `point` and `spot` emitters (emitters/point.c, spot.c) in closed form.
 *
 * A Lambertian plate (rho = 0.5, z = 0) lit by a point source of
 * intensity I at height h: a radiancemeter looking straight down at
 * (x, 0, 0) sees
 *   L = rho / pi * I f(theta) cos(theta) / d^2,  d^2 = x^2 + h^2,
 *   cos(theta) = h / d,
 * with f = 1 for `point` and Mitsuba's linear falloff for `spot`
 * (beam_width < theta < cutoff_angle: (cutoff - theta) / (cutoff - beam)).
 * Under the light (x = 0): rho I / (pi h^2). The estimate has no variance
 * (one delta light, a diffuse plate, max_depth 2), so it is checked to
 * 1e-5 relative (float32 film). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "../../../server/kernel/scene/param_table.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define RHO 0.5
#define H   2.0
#define I0  3.0

static double radiance_xy(const char *integ, const char *light_json, double x, double y) {
  char buf[4096];
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\","
      " \"sensor\": {\"type\": \"radiancemeter\", \"origin\": [%.17g, %.17g, 0.5], \"direction\": [0, 0, -1],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": %s,"
      " \"light\": %s,"
      " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": %g}}}",
      x, y, integ, light_json, RHO);
  scene *s = tsup_load(buf, "mono");
  if (!s) return NAN;
  film_image img;
  double v = NAN;
  if (tsup_render(s, 0, 1, 1, &img)) {
    v = img.data[0];
    film_image_free(&img);
  }
  scene_free(s);
  return v;
}

static double radiance_with(const char *integ, const char *light_json, double x) {
  return radiance_xy(integ, light_json, x, 0.0);
}

static double radiance_probe(const char *light_json, double x, double y) {
  return radiance_xy("{\"type\": \"path\", \"max_depth\": 2}", light_json, x, y);
}

static double radiance_at(const char *light_json, double x) {
  return radiance_with("{\"type\": \"path\", \"max_depth\": 2}", light_json, x);
}

static double expected(double x, double falloff) {
  double d2 = x * x + H * H;
  return RHO / RSW_PI * I0 * falloff * (H / sqrt(d2)) / d2;
}

static void test_point_under_light(void) {
  char light[256];
  snprintf(light, sizeof light, "{\"type\": \"point\", \"position\": [0, 0, %g], \"intensity\": %g}", H, I0);
  double l0 = radiance_at(light, 0.0);
  CHECK_REL(l0, RHO * I0 / (RSW_PI * H * H), 1e-5);
  for (double x = 0.5; x < 4; x += 1.1) CHECK_REL(radiance_at(light, x), expected(x, 1.0), 1e-5);
  /* The same light placed by to_world. */
  snprintf(light, sizeof light,
           "{\"type\": \"point\", \"to_world\": [{\"translate\": [0, 0, %g]}], \"intensity\": %g}", H, I0);
  CHECK_REL(radiance_at(light, 1.3), expected(1.3, 1.0), 1e-5);
  /* The volumetric integrators sample them alike (no medium here). */
  CHECK_REL(radiance_with("{\"type\": \"volpath\", \"max_depth\": 2}", light, 1.3), expected(1.3, 1.0), 1e-5);
  CHECK_REL(radiance_with("{\"type\": \"direct\"}", light, 1.3), expected(1.3, 1.0), 1e-5);
}

static void test_point_xml(void) {
  char buf[4096];
  snprintf(
      buf, sizeof buf,
      "<scene version=\"3.0.0\">"
      " <sensor type=\"radiancemeter\"><point name=\"origin\" value=\"0, 0, 0.5\"/>"
      "  <vector name=\"direction\" value=\"0, 0, -1\"/>"
      "  <film type=\"hdrfilm\"><integer name=\"width\" value=\"1\"/><integer name=\"height\" value=\"1\"/>"
      "   <rfilter type=\"box\"/></film></sensor>"
      " <integrator type=\"path\"><integer name=\"max_depth\" value=\"2\"/></integrator>"
      " <emitter type=\"point\"><point name=\"position\" value=\"0, 0, %g\"/>"
      "  <float name=\"intensity\" value=\"%g\"/></emitter>"
      " <emitter type=\"spot\"><transform name=\"to_world\"><lookat origin=\"0, 0, %g\" target=\"0, 0, 0\""
      "   up=\"0, 1, 0\"/></transform><float name=\"intensity\" value=\"%g\"/>"
      "  <float name=\"cutoff_angle\" value=\"30\"/></emitter>"
      " <shape type=\"rectangle\"><bsdf type=\"diffuse\"/></shape>"
      "</scene>",
      H, I0, H, I0);
  scene *s = tsup_load(buf, "mono");
  REQUIRE(s, "XML scene");
  film_image img;
  REQUIRE(tsup_render(s, 4, 1, 1, &img), "render");
  /* Both lights straight above: twice rho I / (pi h^2). */
  CHECK_REL(img.data[0], 2 * RHO * I0 / (RSW_PI * H * H), 1e-5);
  film_image_free(&img);
  scene_free(s);
}

static void test_spot_falloff(void) {
  const double cutoff = 40, beam = 20;
  char light[512];
  snprintf(
      light, sizeof light,
      "{\"type\": \"spot\", \"intensity\": %g, \"cutoff_angle\": %g, \"beam_width\": %g,"
      " \"to_world\": [{\"lookat\": {\"origin\": [0, 0, %g], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}]}",
      I0, cutoff, beam, H);
  CHECK_REL(radiance_at(light, 0.0), RHO * I0 / (RSW_PI * H * H), 1e-5);
  /* Inside the beam, across the ramp, and beyond the cutoff. */
  const double angles[] = {10, 19.5, 22, 25, 30, 35, 39, 41, 60};
  for (size_t i = 0; i < sizeof angles / sizeof angles[0]; i++) {
    double th = angles[i], x = H * tan(th * RSW_PI / 180);
    double f = th <= beam ? 1.0 : th >= cutoff ? 0.0 : (cutoff - th) / (cutoff - beam);
    double got = radiance_at(light, x), want = expected(x, f);
    if (f == 0)
      CHECK(got == 0, "theta %g: beyond the cutoff the plate is dark, got %g", th, got);
    else
      CHECK(fabs(got - want) <= 1e-5 * want, "theta %g: L %.9g, expected %.9g (falloff %g)", th, got, want,
            f);
  }
  /* Defaults: cutoff 20, beam 15 (3/4 of the cutoff). */
  snprintf(
      light, sizeof light,
      "{\"type\": \"spot\", \"intensity\": %g,"
      " \"to_world\": [{\"lookat\": {\"origin\": [0, 0, %g], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}]}",
      I0, H);
  double x = H * tan(17.5 * RSW_PI / 180);
  CHECK_REL(radiance_at(light, x), expected(x, 0.5), 1e-5);
}

/* A projected checkerboard (color0 0.8, color1 0.2): the spot, looking
 * down from (0, 0, h) with up +y, has its local x along world -x, so a
 * point at (x < 0, y > 0) sees uv > 1/2 in both (color0) and (x < 0, y < 0)
 * u > 1/2 > v (color1). */
static void test_spot_texture(void) {
  char light[512];
  snprintf(
      light, sizeof light,
      "{\"type\": \"spot\", \"intensity\": %g, \"cutoff_angle\": 40, \"beam_width\": 30,"
      " \"texture\": {\"type\": \"checkerboard\", \"color0\": 0.8, \"color1\": 0.2},"
      " \"to_world\": [{\"lookat\": {\"origin\": [0, 0, %g], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}]}",
      I0, H);
  const double x = -0.4, y = 0.3;
  double d2 = x * x + y * y + H * H, want = RHO / RSW_PI * I0 * (H / sqrt(d2)) / d2;
  CHECK_REL(radiance_probe(light, x, y), 0.8 * want, 1e-5);
  CHECK_REL(radiance_probe(light, x, -y), 0.2 * want, 1e-5);
  CHECK_REL(radiance_probe(light, -x, -y), 0.8 * want, 1e-5);
}

static void test_bad_input(void) {
  const char *bad[] = {
      "{\"type\": \"point\", \"position\": [0, 0, 1], \"to_world\": [{\"translate\": [0, 0, 1]}]}",
      "{\"type\": \"spot\", \"cutoff_angle\": 20, \"beam_width\": 30}",
      "{\"type\": \"spot\", \"cutoff_angle\": -1}",
      "{\"type\": \"spot\", \"position\": [0, 0, 1]}",
      "{\"type\": \"point\", \"intensity\": -1}",
      "{\"type\": \"point\", \"intensity\": {\"type\": \"checkerboard\"}}",
      "{\"type\": \"spot\", \"texture\": 0.5}",
      "{\"type\": \"spot\", \"cutoff_angle\": 100, \"texture\": {\"type\": \"checkerboard\"}}",
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
    CHECK(tsup_refused("{\"type\": \"scene\", \"light\": %s}", bad[i]), "refused: %s", bad[i]);
}

/* Moving the light by its `position` key equals loading it there. */
static void test_position_update_equals_reload(void) {
  const char *fmt =
      "{\"type\": \"scene\","
      " \"sensor\": {\"type\": \"perspective\", \"fov\": 60,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [0, -3, 3], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16}},"
      " \"light\": {\"type\": \"point\", \"position\": %s, \"intensity\": 3},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\"}}}";
  char a[2048], b[2048];
  snprintf(a, sizeof a, fmt, "[0, 0, 2]");
  snprintf(b, sizeof b, fmt, "[0.5, -0.25, 1.5]");
  scene *s = tsup_load(a, NULL), *s2 = tsup_load(b, NULL);
  REQUIRE(s && s2, "scenes");
  param_update u = {.key = "light.position"};
  rsw_err err = {0};
  REQUIRE(param_value_parse("[0.5, -0.25, 1.5]", "light.position", &u.value, &err) == RSW_OK, "parse");
  update_report rep = {0};
  CHECK(scene_update(s, &u, 1, &rep, &err) == RSW_OK, "update");
  CHECK(rep.classes == UPDATE_SPECTRAL, "spectral update, got %u", rep.classes);
  param_value_free(&u.value);
  film_image f1, f2;
  REQUIRE(tsup_render(s, 0, 7, 2, &f1) && tsup_render(s2, 0, 7, 1, &f2), "renders");
  size_t n = (size_t)f1.width * f1.height * f1.channels, diff = 0;
  for (size_t i = 0; i < n; i++) diff += f1.data[i] != f2.data[i];
  CHECK(diff == 0, "%zu values differ between the update and the reload", diff);
  film_image_free(&f1);
  film_image_free(&f2);
  scene_free(s);
  scene_free(s2);
}

int main(void) {
  RSW_TEST_RUN(test_point_under_light);
  RSW_TEST_RUN(test_point_xml);
  RSW_TEST_RUN(test_spot_falloff);
  RSW_TEST_RUN(test_spot_texture);
  RSW_TEST_RUN(test_bad_input);
  RSW_TEST_RUN(test_position_update_equals_reload);
  RSW_TEST_END("test_point_spot");
}
