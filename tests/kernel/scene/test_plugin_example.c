/* The worked example of docs/adding-a-plugin.md compiles and works: the
 * `lommel` BSDF (docs/examples/lommel.c, included here as it is), added
 * to the registry at run time (registry_add, the test's stand-in for the
 * walk-through's line in scene/registry.c):
 *  - registry_add accepts it once, refuses its name again and a built-in
 *    name;
 *  - the record DEFINE_PLUGIN made (name from the token, class, create,
 *    the default destroy);
 *  - chi-square of its sampling against pdf() at 0, 45 and 75 degrees
 *    (200,000 samples, the suite's significance 0.01 over 3 tests) and
 *    weight = eval / pdf;
 *  - a scene with it: the plate of docs/examples/plate.json (sun at the
 *    zenith, E = 1, a distant sensor looking down) gives the closed form
 *    L = E f_r = w / (8 pi) to 1e-6 relative (float32 film), for the
 *    default w = 0.5, for w = 0.8, and after a PATCH of `albedo` to 0.2
 *    (traverse reports it);
 *  - a constant albedo above 1 is refused naming the property. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../../docs/examples/lommel.c"
#include "../../support/bsdf_test.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"
#include "kernel/core/rng.h"
#include "kernel/scene/param_table.h"
#include "kernel/scene/params.h"
#include "kernel/scene/scene.h"
#include "kernel/scene/update.h"
#include "kernel/textures/texture.h"

RSW_TEST_DEFINE_GLOBALS

static void test_registry(void) {
  CHECK(strcmp(plugin_lommel.name, "lommel") == 0 && plugin_lommel.cls == CLS_BSDF, "record: name, class");
  CHECK(plugin_lommel.create == lommel_create && plugin_lommel.destroy == plugin_free_object &&
            plugin_lommel.ops == &lommel_ops && plugin_lommel.traverse == lommel_traverse,
        "record: create, default destroy, ops, traverse");
  CHECK(registry_find("lommel") == NULL, "not known before registry_add");
  CHECK(registry_add(&plugin_lommel), "registry_add");
  CHECK(registry_find("lommel") == &plugin_lommel, "found after registry_add");
  CHECK(!registry_add(&plugin_lommel), "the same name twice is refused");
  plugin clash = plugin_lommel;
  clash.name = "diffuse";
  CHECK(!registry_add(&clash), "a built-in name is refused");
  CHECK(registry_find("diffuse") != &clash, "diffuse is still the built-in");
}

static void test_sampling(void) {
  texture *w = uniform_texture_const(0.7, "w");
  REQUIRE(w, "texture");
  lommel_bsdf *l = BSDF_NEW(lommel_bsdf, lommel, BSDF_GLOSSY_REFLECTION);
  REQUIRE(l, "allocation");
  l->albedo = w;
  const double deg[3] = {0.0, 45.0, 75.0};
  for (int k = 0; k < 3; k++) {
    vec3 wi = tb_dir_deg(deg[k], 30.0);
    chi2_bsdf c = {&l->base, tb_si_with(wi)};
    chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
    cfg.sample_count = 200000;
    cfg.test_count = 3;
    chi2_result r = chi2_run(&cfg, chi2_bsdf_sample, chi2_bsdf_pdf, &c);
    CHECK(r.passed, "chi2 at %g degrees: p = %g: %s", deg[k], r.p_value, r.reason);
    pcg32 rng;
    pcg32_seed(&rng, 11, (uint64_t)k);
    int bad = 0;
    for (int s = 0; s < 500; s++) {
      bsdf_sample bs;
      vec2 u2 = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
      color wt = l->base.ops->sample(&l->base, &c.si, 0.5, u2, &bs);
      if (!(bs.pdf > 0.0)) continue;
      color f = l->base.ops->eval(&l->base, &c.si, bs.wo);
      double p = l->base.ops->pdf(&l->base, &c.si, bs.wo);
      double want = 0.7 / (4.0 * RSW_PI) / (wi.z + bs.wo.z) * bs.wo.z;
      bad += fabs(f.c[0] - want) > 1e-14 || fabs(p - bs.pdf) > 1e-14 * p ||
             fabs(wt.c[0] - f.c[0] / p) > 1e-12 * wt.c[0];
    }
    CHECK(bad == 0, "%d samples: eval, pdf or weight differ from the closed form at %g degrees", bad, deg[k]);
  }
  plugin_lommel.destroy(&l->base.base);
  tb_free_tex(w);
}

static const char *plate(const char *bsdf_json) {
  static char buf[1024];
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"camera\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
      "  \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
      "  \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"component_format\": \"float32\","
      "   \"rfilter\": {\"type\": \"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": %s}}",
      bsdf_json);
  return buf;
}

static double render_value(scene *s) {
  film_image img;
  if (!tsup_render(s, 4, 1, 1, &img)) return NAN;
  double mean, sem;
  tsup_stats(&img, 0, &mean, &sem);
  film_image_free(&img);
  return mean;
}

static void test_scene(void) {
  scene *s = tsup_load(plate("{\"type\": \"lommel\"}"), NULL);
  REQUIRE(s, "a scene with the example BSDF loads");
  CHECK_REL(render_value(s), 0.5 / (8.0 * RSW_PI), 1e-6);
  scene_free(s);

  s = tsup_load(plate("{\"type\": \"lommel\", \"id\": \"soil\", \"albedo\": 0.8}"), NULL);
  REQUIRE(s, "albedo 0.8");
  CHECK_REL(render_value(s), 0.8 / (8.0 * RSW_PI), 1e-6);
  size_t idx;
  rsw_err err = {0};
  rsw_status st = params_lookup(s, "bsdf:soil:albedo.value", &idx, &err);
  CHECK(st == RSW_OK, "traverse reports albedo: %s", err.msg);
  param_update up = {.key = "bsdf:soil:albedo.value"};
  st = param_value_parse("0.2", "albedo", &up.value, &err);
  if (st == RSW_OK) st = scene_update(s, &up, 1, NULL, &err);
  param_value_free(&up.value);
  CHECK(st == RSW_OK, "PATCH albedo: %s", err.msg);
  CHECK_REL(render_value(s), 0.2 / (8.0 * RSW_PI), 1e-6);
  scene_free(s);

  rsw_err e2 = {0};
  const char *bad = plate("{\"type\": \"lommel\", \"albedo\": 1.5}");
  scene *b = NULL;
  st = scene_load_memory(bad, strlen(bad), "bad", false, NULL, &b, &e2);
  CHECK(st != RSW_OK && strstr(e2.msg, "albedo"), "albedo 1.5 is refused naming it (got '%s')", e2.msg);
  if (b) scene_free(b);
}

int main(void) {
  RSW_TEST_RUN(test_registry);
  RSW_TEST_RUN(test_sampling);
  RSW_TEST_RUN(test_scene);
  RSW_TEST_END("test_plugin_example");
}
