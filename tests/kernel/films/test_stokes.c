/* Stokes films (hdrfilm pixel_format "stokes", mono): channels S0..S3 carry
 * the environment plugin's (I, Q, U, V). A plugin with a constant,
 * partially polarised radiance is compiled at test time:
 *  - camera rays that escape see exactly (I, Q, U, V);
 *  - light reflected by a diffuse sphere keeps Q/I, U/I, V/I (throughput is
 *    applied to the whole vector; BSDFs are treated as non-polarising);
 *  - rgb scenes refuse "stokes". */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../server/kernel/extplugin/env_plugin.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static const char *PLUGIN =
    "#include <raysweep/plugin.h>\n"
    "#include <stdlib.h>\n"
    "static const rsw_plugin_host *H;\n"
    "static int create(const double *const *p, void **inst, char *e, size_t n) {\n"
    "  (void)p, (void)e, (void)n; *inst = malloc(1); return *inst ? 0 : 1; }\n"
    "static void destroy(void *i) { free(i); }\n"
    "static void add(const void *i, rsw_stokes_context *c, const double d[3]) {\n"
    "  (void)i, (void)d;\n"
    "  for (size_t k = 0; k < c->count; k++) {\n"
    "    c->stokes[0][k] += 1.0; c->stokes[1][k] += 0.5; c->stokes[2][k] += -0.25; c->stokes[3][k] += 0.125; "
    "} }\n"
    "static double sample(const void *i, const double u[2], double d[3]) {\n"
    "  (void)i; H->square_to_uniform_sphere(u, d); return H->uniform_sphere_pdf(); }\n"
    "static double pdf(const void *i, const double d[3]) { (void)i, (void)d; return H->uniform_sphere_pdf(); "
    "}\n"
    "static const rsw_env_plugin T = {.abi_version = RSW_PLUGIN_ABI_VERSION, .type_name = \"polsky\",\n"
    "  .pretty_name = \"Polarised sky\", .create = create, .destroy = destroy, .add_radiance = add,\n"
    "  .sample = sample, .pdf = pdf};\n"
    "RSW_PLUGIN_EXPORT const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *h) { H = h; return "
    "&T; }\n";

static char dir[64];

static bool build(void) {
  snprintf(dir, sizeof dir, "/tmp/rsw-stokes-XXXXXX");
  if (!mkdtemp(dir)) return false;
  char src[128], cmd[1024];
  snprintf(src, sizeof src, "%s/polsky.c", dir);
  FILE *f = fopen(src, "w");
  if (!f) return false;
  fputs(PLUGIN, f);
  fclose(f);
  const char *td = getenv("RSW_TEST_DIR");
  char inc[512];
  snprintf(inc, sizeof inc, "%s/../include", td && *td ? td : "tests");
  snprintf(cmd, sizeof cmd, "cc -std=c11 -Wall -Wextra -Werror -shared -fPIC -I '%s' -o '%s/polsky.so' '%s'",
           inc, dir, src);
  return system(cmd) == 0;
}

static const char *SCENE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"cam\": {\"type\": \"perspective\", \"fov\": 30,"
    "   \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 8},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"pixel_format\": \"stokes\","
    "     \"component_format\": \"float32\", \"rfilter\": {\"type\": \"box\"}}},"
    " \"sky\": {\"type\": \"polsky\"}%s}";

static void test_escaped_rays_carry_the_stokes_vector(void) {
  char sc[2048];
  snprintf(sc, sizeof sc, SCENE, "");
  scene *s = tsup_load(sc, NULL);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 1, 1, &img), "render");
  REQUIRE(img.channels == 4 && strcmp(img.channel_names[0], "S0") == 0 &&
              strcmp(img.channel_names[3], "S3") == 0,
          "S0..S3 channels");
  const double want[4] = {1.0, 0.5, -0.25, 0.125};
  for (int i = 0; i < img.width * img.height; i++)
    for (int k = 0; k < 4; k++)
      CHECK(img.data[4 * i + k] == (float)want[k], "pixel %d S%d = %g", i, k, img.data[4 * i + k]);
  film_image_free(&img);
  scene_free(s);
}

static void test_reflected_light_keeps_the_ratios(void) {
  char sc[2048];
  snprintf(sc, sizeof sc, SCENE,
           ", \"ball\": {\"type\": \"sphere\", \"radius\": 1.5, \"bsdf\": {\"type\": \"diffuse\", "
           "\"reflectance\": 0.5}}");
  scene *s = tsup_load(sc, NULL);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 2, 2, &img), "render");
  int lit = 0;
  for (int i = 0; i < img.width * img.height; i++) {
    double s0 = img.data[4 * i];
    if (s0 <= 0) continue;
    lit++;
    CHECK_REL(img.data[4 * i + 1], 0.5 * s0, 1e-5);
    CHECK_REL(img.data[4 * i + 2], -0.25 * s0, 1e-5);
    CHECK_REL(img.data[4 * i + 3], 0.125 * s0, 1e-5);
  }
  CHECK(lit == img.width * img.height, "every pixel sees light (%d)", lit);
  film_image_free(&img);
  scene_free(s);
}

static void test_rgb_refuses_stokes(void) {
  const char *sc =
      "{\"type\": \"scene\", \"cam\": {\"type\": \"perspective\","
      " \"film\": {\"type\": \"hdrfilm\", \"width\": 2, \"height\": 2, \"pixel_format\": \"stokes\"}}}";
  scene *s = tsup_load(sc, "rgb");
  CHECK(s == NULL, "an rgb scene with a stokes film must be refused");
  scene_free(s);
}

int main(void) {
  if (!build()) {
    printf("could not build the test plugin\n");
    return 1;
  }
  rsw_err err = {0};
  if (plugins_load_dir(dir, &err)) {
    printf("load: %s\n", err.msg);
    return 1;
  }
  RSW_TEST_RUN(test_escaped_rays_carry_the_stokes_vector);
  RSW_TEST_RUN(test_reflected_light_keeps_the_ratios);
  RSW_TEST_RUN(test_rgb_refuses_stokes);
  plugins_unload();
  char cmd[128];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  if (system(cmd)) fprintf(stderr, "could not remove %s\n", dir);
  RSW_TEST_END("test_stokes");
}
