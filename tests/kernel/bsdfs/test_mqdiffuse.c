/* mqdiffuse (server/kernel/bsdfs/mqdiffuse.c,
 * docs/kernel-conventions.md#mqdiffuse):
 *  - it reproduces its grid: with random values on a 5 (cos_o) x 8 (phi_d)
 *    x 4 (cos_i) grid, eval / cos(theta_o) at every node direction with
 *    0 < cos < 1 is that node's value; with values linear in the three
 *    coordinates (which trilinear interpolation reproduces exactly),
 *    eval / cos(theta_o) at 100 random direction pairs is the linear
 *    function (1e-12 relative both); one-sided;
 *  - chi-square of sample() against pdf() (cosine hemisphere; 200,000
 *    samples, alpha 0.01, 2 runs), weight = eval / pdf;
 *  - a plate under a sun seen by `distant` reads E cos(theta_s) g (JSON
 *    with inline data; XML with a .vol file);
 *  - a missing grid is refused. Fixed seeds. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../support/bsdf_test.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"
#include "kernel/core/rng.h"
#include "kernel/scene/scene.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846
enum {
  NX = 5, /* cos_o */
  NY = 8, /* phi_d / 2 pi */
  NZ = 4  /* cos_i */
};

static double lin(double x, double y, double z) {
  return 0.1 + 0.2 * x + 0.05 * y + 0.3 * z;
}

/* A scene with the plate's BSDF on `vals` (z, y, x order) seen along
 * `view` under a sun towards `sun` (both local directions up). */
static scene *plate(const double *vals, vec3 view, vec3 sun) {
  size_t cap = 64 * NX * NY * NZ + 4096, k = 0;
  char *buf = malloc(cap);
  k += (size_t)snprintf(
      buf + k, cap - k,
      "{\"type\": \"scene\", \"sun\": {\"type\": \"directional\", \"direction\": [%.17g, %.17g, "
      "%.17g], \"irradiance\": 1.3},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"mqdiffuse\", \"id\": \"mq\","
      " \"grid\": {\"type\": \"gridvolume\", \"shape\": [%d, %d, %d], \"data\": [",
      -sun.x, -sun.y, -sun.z, NZ, NY, NX);
  for (int i = 0; i < NX * NY * NZ; i++)
    k += (size_t)snprintf(buf + k, cap - k, "%s%.17g", i ? ", " : "", vals[i]);
  snprintf(
      buf + k, cap - k,
      "]}}}, \"sensor\": {\"type\": \"distant\", \"direction\": [%.17g, %.17g, %.17g], \"target\": [0, 0, 0],"
      " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}",
      -view.x, -view.y, -view.z);
  scene *s = tsup_load(buf, "mono");
  free(buf);
  return s;
}

static const bsdf *find_bsdf(const scene *s) {
  for (size_t i = 0; i < s->n_objects; i++) {
    const object *o = s->objects[i];
    if (o->plugin && o->plugin->cls == CLS_BSDF && o->id && strcmp(o->id, "mq") == 0) return (const bsdf *)o;
  }
  return NULL;
}

static void test_reproduces_grid(void) {
  double vals[NX * NY * NZ];
  pcg32 rng;
  pcg32_seed(&rng, 12, 25);
  for (int i = 0; i < NX * NY * NZ; i++) vals[i] = 0.05 + 0.4 * pcg32_next_double(&rng);
  scene *s = plate(vals, v3(0, 0, 1), v3(0, 0, 1));
  REQUIRE(s, "scene");
  const bsdf *b = find_bsdf(s);
  REQUIRE(b, "mqdiffuse object");
  int checked = 0;
  /* cos = 1 has no azimuth (phi_d is then not the node's): not node tests. */
  for (int z = 1; z < NZ - 1; z++)
    for (int y = 0; y < NY - 1; y++)
      for (int x = 1; x < NX - 1; x++) {
        double ci = (double)z / (NZ - 1), co = (double)x / (NX - 1), phi = 2 * PI * y / (NY - 1);
        double si_ = sqrt(1 - ci * ci), so = sqrt(1 - co * co), a = 0.3;
        vec3 wi = v3(si_ * cos(a), si_ * sin(a), ci), wo = v3(so * cos(a + phi), so * sin(a + phi), co);
        surface_interaction si = tb_si_with(wi);
        double got = b->ops->eval(b, &si, wo).c[0] / co;
        double want = vals[(z * NY + y) * NX + x];
        /* phi_d of exactly 0 may come out as 2 pi - tiny: the y = NY - 1
         * node holds another value, so skip where rounding picked it. */
        if (y == 0 && fabs(got - want) > 1e-9) continue;
        CHECK(fabs(got - want) <= 1e-12 * want, "node (%d, %d, %d): %.15g vs %.15g", x, y, z, got, want);
        checked++;
      }
  CHECK(checked >= (NX - 2) * (NY - 2) * (NZ - 2), "nodes checked: %d", checked);
  surface_interaction si = tb_si_with(tb_dir_deg(30, 0));
  CHECK(b->ops->eval(b, &si, tb_dir_deg(120, 0)).c[0] == 0.0, "one-sided");
  scene_free(s);
  /* Linear values: exact everywhere. */
  for (int z = 0; z < NZ; z++)
    for (int y = 0; y < NY; y++)
      for (int x = 0; x < NX; x++)
        vals[(z * NY + y) * NX + x] = lin((double)x / (NX - 1), (double)y / (NY - 1), (double)z / (NZ - 1));
  s = plate(vals, v3(0, 0, 1), v3(0, 0, 1));
  b = find_bsdf(s);
  REQUIRE(b, "linear scene");
  for (int k = 0; k < 100; k++) {
    vec3 wi = tb_dir_deg(85 * pcg32_next_double(&rng), 360 * pcg32_next_double(&rng));
    vec3 wo = tb_dir_deg(85 * pcg32_next_double(&rng), 360 * pcg32_next_double(&rng));
    double phi = fmod(atan2(wo.y, wo.x) - atan2(wi.y, wi.x), 2 * PI);
    if (phi < 0) phi += 2 * PI;
    surface_interaction sk = tb_si_with(wi);
    double got = b->ops->eval(b, &sk, wo).c[0] / wo.z, want = lin(wo.z, phi / (2 * PI), wi.z);
    CHECK(fabs(got - want) <= 1e-12 * want, "pair %d: %.15g vs %.15g", k, got, want);
  }
  /* Sampling. */
  for (int i = 0; i < 2; i++) {
    chi2_bsdf c = {b, tb_si_with(tb_dir_deg(i ? 70 : 20, 40))};
    chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
    cfg.sample_count = 200000;
    cfg.test_count = 2;
    chi2_result r = chi2_run(&cfg, chi2_bsdf_sample, chi2_bsdf_pdf, &c);
    CHECK(r.passed, "chi2 %d: p = %g: %s", i, r.p_value, r.reason);
    int bad = 0;
    for (int q = 0; q < 200; q++) {
      bsdf_sample bs;
      color w = b->ops->sample(b, &c.si, 0.5, v2(pcg32_next_double(&rng), pcg32_next_double(&rng)), &bs);
      if (!(bs.pdf > 0)) continue;
      double p = b->ops->pdf(b, &c.si, bs.wo), e = b->ops->eval(b, &c.si, bs.wo).c[0];
      if (fabs(p - bs.pdf) > 1e-12 * p || fabs(w.c[0] - e / p) > 1e-12 * fmax(1, w.c[0])) bad++;
    }
    CHECK(bad == 0, "%d weight/pdf mismatches", bad);
  }
  scene_free(s);
}

static void put_u32(FILE *f, unsigned v) {
  fwrite(&v, 4, 1, f);
}
static void put_f32(FILE *f, double v) {
  float x = (float)v;
  fwrite(&x, 4, 1, f);
}

static void test_scene(void) {
  vec3 view = tb_dir_deg(40, 200), sun = tb_dir_deg(30, 10);
  double vals[NX * NY * NZ];
  for (int z = 0; z < NZ; z++)
    for (int y = 0; y < NY; y++)
      for (int x = 0; x < NX; x++)
        vals[(z * NY + y) * NX + x] = lin((double)x / (NX - 1), (double)y / (NY - 1), (double)z / (NZ - 1));
  /* eval(wi = view, wo = sun) = g cos(theta_sun). */
  double phi = fmod(atan2(sun.y, sun.x) - atan2(view.y, view.x), 2 * PI);
  if (phi < 0) phi += 2 * PI;
  double want = 1.3 * sun.z * lin(sun.z, phi / (2 * PI), view.z);
  scene *s = plate(vals, view, sun);
  REQUIRE(s, "JSON scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 1, 1, &img), "render");
  CHECK_REL(img.data[0], want, 1e-6);
  film_image_free(&img);
  scene_free(s);
  /* XML with a .vol file (float32 values: 1e-6). */
  char path[] = "/tmp/test_mqdiffuse_XXXXXX.vol";
  int fd = mkstemps(path, 4);
  REQUIRE(fd >= 0, "temp file");
  FILE *f = fdopen(fd, "wb");
  fwrite("VOL\x03", 1, 4, f);
  put_u32(f, 1);
  put_u32(f, NX), put_u32(f, NY), put_u32(f, NZ), put_u32(f, 1);
  for (int k = 0; k < 6; k++) put_f32(f, k < 3 ? 0 : 1);
  for (int i = 0; i < NX * NY * NZ; i++) put_f32(f, vals[i]);
  fclose(f);
  char xml[4096];
  snprintf(xml, sizeof xml,
           "<scene version=\"3.0.0\"><emitter type=\"directional\"><vector name=\"direction\" x=\"%.17g\" "
           "y=\"%.17g\" z=\"%.17g\"/><float name=\"irradiance\" value=\"1.3\"/></emitter><shape "
           "type=\"rectangle\"><bsdf type=\"mqdiffuse\"><volume type=\"gridvolume\" name=\"grid\"><string "
           "name=\"filename\" value=\"%s\"/></volume></bsdf></shape><sensor type=\"distant\"><vector "
           "name=\"direction\" x=\"%.17g\" y=\"%.17g\" z=\"%.17g\"/><point name=\"target\" x=\"0\" y=\"0\" "
           "z=\"0\"/><film type=\"hdrfilm\"><integer name=\"width\" value=\"1\"/><integer name=\"height\" "
           "value=\"1\"/></film></sensor></scene>",
           -sun.x, -sun.y, -sun.z, path, -view.x, -view.y, -view.z);
  s = tsup_load(xml, "mono");
  unlink(path);
  REQUIRE(s, "XML scene");
  REQUIRE(tsup_render(s, 0, 1, 1, &img), "render");
  CHECK_REL(img.data[0], want, 1e-6);
  film_image_free(&img);
  scene_free(s);
  s = tsup_load("{\"type\": \"scene\", \"a\": {\"type\": \"mqdiffuse\"}}", "mono");
  CHECK(s == NULL, "a missing grid is refused");
  if (s) scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_reproduces_grid);
  RSW_TEST_RUN(test_scene);
  RSW_TEST_END("test_mqdiffuse");
}
