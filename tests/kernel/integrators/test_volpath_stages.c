/* volpath's and piecewise_volpath's waves by stages (integrators/volpath.c
 * wave_events) against the same waves lane by lane (lane_event, forced by
 * volpath_set_stages(false)): the films must be bitwise the same, since
 * each lane draws the same numbers in the same order and computes the same
 * values either way. The scenes reach every branch of the stages: the
 * layered atmosphere example (analytic flights, a null box crossed
 * analytically, RPV, a directional sun), and small scenes with delta
 * tracking, a null sphere crossed by queries, two emitters (a sun and an
 * area light: the light samples grouped by emitter, emission hits), a
 * dielectric (no light sample), an environment (escapes), a medium that
 * takes no light samples, hidden emitters, max_depth and an early
 * roulette; with 1 and 2 threads; and layers in a null cube, whose
 * flights and shadow rays the stages take a short way (one_box_of), lane
 * by lane the general walk; and the same short ways for a bundle's pages
 * (lane by lane) against the general walk (the stages switched off). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/integrators/integrator.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

/* Renders s by stages and lane by lane, requires bitwise-equal films with
 * some light in them. */
static void check_same(scene *s, uint32_t spp, int threads, const char *what) {
  film_image a, b;
  volpath_set_stages(true);
  bool ok_a = tsup_render(s, spp, 7, threads, &a);
  volpath_set_stages(false);
  bool ok_b = tsup_render(s, spp, 7, threads, &b);
  volpath_set_stages(true);
  REQUIRE(ok_a && ok_b, "%s: render", what);
  size_t n = (size_t)a.width * a.height * a.channels, same = 0;
  double sum = 0;
  bool dims = a.width == b.width && a.height == b.height && a.channels == b.channels;
  for (size_t i = 0; dims && i < n; i++) {
    same += memcmp(&a.data[i], &b.data[i], sizeof(float)) == 0;
    sum += a.data[i];
  }
  printf("  %s: %zu of %zu values bitwise equal, mean %.6g\n", what, same, n, sum / (double)n);
  CHECK(dims && same == n, "%s: stages and lane by lane differ (%zu of %zu equal)", what, same, n);
  CHECK(sum > 0 && isfinite(sum), "%s: an empty film (%g)", what, sum);
  film_image_free(&a);
  film_image_free(&b);
}

static void test_atmosphere_example(void) {
  static const char *variants[] = {"mono", "rgb"};
  for (int v = 0; v < 2; v++) {
    scene *s = tsup_load_file("proto/examples/atmosphere.xml", variants[v]);
    REQUIRE(s, "atmosphere.xml");
    char what[64];
    snprintf(what, sizeof what, "atmosphere.xml %s", variants[v]);
    check_same(s, 8, 1, what);
    check_same(s, 8, 2, what);
    scene_free(s);
  }
}

/* A layered atmosphere in a null cube (volpath.c one_box_of: the short
 * ways of the flights and shadow rays, staged; lane by lane the general
 * walk): the medium's box equal to the cube (cube_z0 0) or inside it
 * (cube_z0 < 0), a sky or none (escapes: a passed flight's exp skipped),
 * a camera above the cube (rays enter it) or inside it. */
static scene *layered_scene(double cube_z0, bool sky, bool inside) {
  char doc[4096];
  const char *grid = "\"shape\": [6, 1, 1], \"filter_type\": \"nearest\","
                     " \"to_world\": [{\"scale\": [20, 20, 6]}, {\"translate\": [-10, -10, 0]}]";
  snprintf(doc, sizeof doc,
           "{\"type\": \"scene\", \"integrator\": {\"type\": \"piecewise_volpath\"},"
           " \"cam\": {\"type\": \"perspective\", \"fov\": 60,"
           "   \"to_world\": [{\"lookat\": {\"origin\": [0.5, -1, %s], \"target\": [0, 0, 0], \"up\": [0, 0, "
           "1]}}],"
           "   \"film\": {\"type\": \"hdrfilm\", \"width\": 12, \"height\": 10}},"
           " \"air\": {\"type\": \"piecewise\","
           "   \"sigma_t\": {\"type\": \"gridvolume\", \"data\": [0.5, 0.3, 0.2, 0.1, 0.05, 0.02], %s},"
           "   \"albedo\": {\"type\": \"gridvolume\", \"data\": [0.9, 0.9, 0.8, 0.95, 0.9, 0.9], %s},"
           "   \"phase\": {\"type\": \"hg\", \"g\": 0.6}},"
           " \"box\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
           "   \"to_world\": [{\"scale\": [10, 10, %.17g]}, {\"translate\": [0, 0, %.17g]}],"
           "   \"interior\": {\"type\": \"ref\", \"id\": \"air\"}},"
           " \"ground\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 10}],"
           "   \"bsdf\": {\"type\": \"rpv\", \"rho_0\": 0.2, \"k\": 0.8, \"g\": -0.1}},"
           " \"sun\": {\"type\": \"directional\", \"direction\": [0.3, 0.2, -1], \"irradiance\": 2}%s}",
           inside ? "3" : "9", grid, grid, (6.0 - cube_z0) / 2, (6.0 + cube_z0) / 2,
           sky ? ", \"sky\": {\"type\": \"constant\", \"radiance\": 0.3}" : "");
  return tsup_load(doc, "mono");
}

static void test_one_box(void) {
  for (int v = 0; v < 8; v++) {
    double z0 = v & 1 ? -0.5 : 0.0;
    bool sky = v & 2, inside = v & 4;
    scene *s = layered_scene(z0, sky, inside);
    REQUIRE(s, "layered scene %d", v);
    char what[128];
    snprintf(what, sizeof what, "layers in a null cube (cube z0 %g, sky %d, camera inside %d)", z0, sky,
             inside);
    check_same(s, 16, 2, what);
    scene_free(s);
  }
}

/* A bundle of k wavelengths 400, 410, ... nm (pages of three, lane by
 * lane), rendered with the stages on (one_box_of's short ways for the
 * pages too) and off (the general walk): every film bitwise equal. */
static void check_same_bundle(scene *s, int k, uint32_t spp, int threads, const char *what) {
  render_opts o = {.size = sizeof o, .spp = spp, .seed = 7, .threads = threads, .bundle = k};
  for (int i = 0; i < RENDER_MAX_BUNDLE; i++) o.bundle_wl[i] = 400.0 + 10.0 * (i < k ? i : k - 1);
  film_image a[RENDER_MAX_BUNDLE], b[RENDER_MAX_BUNDLE];
  rsw_err err = {0};
  volpath_set_stages(true);
  bool ok_a = render_sensor_bundle(s, &o, a, NULL, &err) == RSW_OK;
  volpath_set_stages(false);
  bool ok_b = render_sensor_bundle(s, &o, b, NULL, &err) == RSW_OK;
  volpath_set_stages(true);
  REQUIRE(ok_a && ok_b, "%s: bundle render: %s", what, err.msg);
  size_t same = 0, n = 0;
  double sum = 0;
  for (int f = 0; f < k; f++) {
    size_t m = (size_t)a[f].width * a[f].height * a[f].channels;
    bool dims = a[f].width == b[f].width && a[f].height == b[f].height && a[f].channels == b[f].channels;
    for (size_t i = 0; dims && i < m; i++) {
      same += memcmp(&a[f].data[i], &b[f].data[i], sizeof(float)) == 0;
      sum += a[f].data[i];
    }
    n += m;
    film_image_free(&a[f]);
    film_image_free(&b[f]);
  }
  printf("  %s, bundle of %d: %zu of %zu values bitwise equal, mean %.6g\n", what, k, same, n,
         sum / (double)n);
  CHECK(same == n, "%s, bundle of %d: stages on and off differ (%zu of %zu equal)", what, k, same, n);
  CHECK(sum > 0 && isfinite(sum), "%s, bundle of %d: empty films (%g)", what, k, sum);
}

/* The one-box short ways for a bundle's pages: the molecular atmosphere
 * example (2,400 layers, spectral) and the layered cubes above. */
static void test_one_box_pages(void) {
  scene *s = tsup_load_file("proto/examples/atmosphere_molecular.json", "mono");
  REQUIRE(s, "atmosphere_molecular.json");
  check_same_bundle(s, 16, 4, 2, "atmosphere_molecular.json");
  check_same_bundle(s, 7, 4, 1, "atmosphere_molecular.json");
  scene_free(s);
  for (int v = 0; v < 8; v++) {
    double z0 = v & 1 ? -0.5 : 0.0;
    bool sky = v & 2, inside = v & 4;
    s = layered_scene(z0, sky, inside);
    REQUIRE(s, "layered scene %d", v);
    char what[128];
    snprintf(what, sizeof what, "layers in a null cube (cube z0 %g, sky %d, camera inside %d)", z0, sky,
             inside);
    check_same_bundle(s, 16, 16, 2, what);
    scene_free(s);
  }
}

/* Medium med in a null sphere over a ground, a glass ball, an area
 * light and a sun under a sky, rendered by integrator integ. */
static scene *mixed_scene(const char *integ, const char *med) {
  char doc[4096];
  snprintf(
      doc, sizeof doc,
      "{\"type\": \"scene\", \"integrator\": %s,"
      " \"cam\": {\"type\": \"perspective\", \"fov\": 50,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [0, -6, 3], \"target\": [0, 0, 0.5], \"up\": [0, 0, 1]}}],"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 12, \"height\": 10}},"
      " \"haze\": {\"type\": \"sphere\", \"radius\": 1.5, \"center\": [0, 0, 1], \"bsdf\": {\"type\": "
      "\"null\"},"
      "   \"interior\": %s},"
      " \"ground\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 6}],"
      "   \"bsdf\": {\"type\": \"rpv\", \"rho_0\": 0.2, \"k\": 0.8, \"g\": -0.1}},"
      " \"glass\": {\"type\": \"sphere\", \"radius\": 0.4, \"center\": [1.8, 0.5, 0.4],"
      "   \"bsdf\": {\"type\": \"dielectric\"}},"
      " \"lamp\": {\"type\": \"rectangle\","
      "   \"to_world\": [{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}}, {\"translate\": [-1.5, 1, 3]}],"
      "   \"emitter\": {\"type\": \"area\", \"radiance\": 4}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0.3, 0.2, -1], \"irradiance\": 2},"
      " \"sky\": {\"type\": \"constant\", \"radiance\": 0.3}}",
      integ, med);
  return tsup_load(doc, "mono");
}

static void test_mixed_scenes(void) {
  static const char *integ[] = {
      "{\"type\": \"volpath\"}",
      "{\"type\": \"piecewise_volpath\"}",
      "{\"type\": \"volpath\", \"rr_depth\": 1, \"hide_emitters\": true}",
      "{\"type\": \"piecewise_volpath\", \"max_depth\": 3}",
      "{\"type\": \"volpath\", \"rr_depth\": 2, \"rr_rule\": \"mitsuba\"}",
  };
  static const char *media[] = {
      "{\"type\": \"homogeneous\", \"sigma_t\": 1.2, \"albedo\": 0.9, \"phase\": {\"type\": \"hg\", \"g\": "
      "0.4}}",
      "{\"type\": \"homogeneous\", \"sigma_t\": 1.2, \"albedo\": 0.9, \"sample_emitters\": false}",
      "{\"type\": \"homogeneous\", \"sigma_t\": 0.8, \"albedo\": 0}",
      "{\"type\": \"heterogeneous\", \"albedo\": 0.8, \"sigma_t\": {\"type\": \"constvolume\", \"value\": "
      "1.1,"
      " \"to_world\": [{\"translate\": [-0.5, -0.5, -0.5]}, {\"scale\": 3}, {\"translate\": [0, 0, 1]}]}}",
  };
  for (size_t i = 0; i < sizeof integ / sizeof *integ; i++)
    for (size_t m = 0; m < sizeof media / sizeof *media; m++) {
      scene *s = mixed_scene(integ[i], media[m]);
      REQUIRE(s, "scene %zu %zu", i, m);
      char what[512];
      snprintf(what, sizeof what, "%s in %s", integ[i], media[m]);
      check_same(s, 16, 2, what);
      scene_free(s);
    }
}

int main(void) {
  RSW_TEST_RUN(test_atmosphere_example);
  RSW_TEST_RUN(test_mixed_scenes);
  RSW_TEST_RUN(test_one_box);
  RSW_TEST_RUN(test_one_box_pages);
  RSW_TEST_END("test_volpath_stages");
}
