/* Tests of server/kernel/core/distr2d.c and server/kernel/emitters/envmap.c:
 * the distribution's pdf and sampling, the envmap's orientation (Mitsuba's
 * lat-long convention), a chi-square test of its sample_direction against
 * its pdf_direction (alpha 0.01), a constant map against `constant`
 * (white furnace, 3 sigma, background pixels equal), a bright polar cap
 * against the equivalent `directional` emitter (3 sigma), and mono. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"
#include "image_exr.h"
#include "kernel/core/distr2d.h"
#include "kernel/scene/param_table.h"
#include "kernel/scene/params.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

/* Write a w x h EXR (channels R,G,B when nc = 3, Y when 1) to a temp file;
 * path must hold 32 characters. */
static bool write_map(char *path, int w, int h, int nc, const float *px) {
  strcpy(path, "/tmp/rsw-envmap-XXXXXX.exr");
  int fd = mkstemps(path, 4);
  if (fd < 0) return false;
  close(fd);
  const char *rgb[3] = {"R", "G", "B"}, *y[1] = {"Y"};
  rsw_err err = {0};
  rsw_status st = exr_write_image(path, w, h, nc, nc == 3 ? rgb : y, px, false, NULL, &err);
  if (st) printf("  write %s: %s\n", path, err.msg);
  return st == RSW_OK;
}

/* --- distr2d ---------------------------------------------------------------- */

static void test_distr2d(void) {
  /* 5 x 3 weights with a zero cell and a zero row. */
  const double w[15] = {1, 2, 0, 4, 1, 0, 0, 0, 0, 0, 3, 1, 1, 2, 0.5};
  distr2d d;
  rsw_err err = {0};
  REQUIRE(distr2d_init(&d, w, 5, 3, "w", &err) == RSW_OK, "init: %s", err.msg);
  double total = 0;
  for (int k = 0; k < 15; k++) total += w[k];
  /* The pdf integrates to 1 (it is constant per cell: the midpoint sum is
   * exact) and equals w W H / total in each cell. */
  double integral = 0;
  for (int j = 0; j < 3; j++)
    for (int i = 0; i < 5; i++) {
      double p = distr2d_pdf(&d, v2((i + 0.5) / 5, (j + 0.5) / 3));
      CHECK_REL(p + 1e-300, w[j * 5 + i] * 15 / total + 1e-300, 1e-12);
      integral += p / 15;
    }
  CHECK_REL(integral, 1.0, 1e-12);
  CHECK(distr2d_pdf(&d, v2(1.0, 0.5)) == 0 && distr2d_pdf(&d, v2(-0.1, 0.5)) == 0, "pdf outside the square");
  /* Sampling: the returned pdf equals pdf() at the point, never lands in a
   * zero cell, and cell frequencies match w / total (n = 200000: each
   * frequency within 5 binomial sigma). */
  const int n = 200000;
  int count[15] = {0};
  int bad = 0;
  pcg32 rng;
  pcg32_seed(&rng, 3, 1);
  for (int k = 0; k < n; k++) {
    vec2 u = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
    double pdf;
    vec2 p = distr2d_sample(&d, u, &pdf);
    if (!(p.x >= 0 && p.x < 1 && p.y >= 0 && p.y < 1) || !(pdf > 0) ||
        fabs(pdf - distr2d_pdf(&d, p)) > 1e-12 * pdf)
      bad++;
    else
      count[(int)(p.y * 3) * 5 + (int)(p.x * 5)]++;
  }
  CHECK(bad == 0, "%d samples outside, in a zero cell, or with an inconsistent pdf", bad);
  for (int k = 0; k < 15; k++) {
    double pk = w[k] / total, sigma = sqrt(n * pk * (1 - pk));
    CHECK(fabs(count[k] - n * pk) <= 5 * sigma + 1e-9, "cell %d: %d samples, expected %.1f", k, count[k],
          n * pk);
  }
  /* Corners of the sample square stay in [0,1)^2. */
  vec2 c = distr2d_sample(&d, v2(0.9999999999999999, 0.9999999999999999), NULL);
  CHECK(c.x < 1 && c.y < 1, "u -> 1 gave (%g, %g)", c.x, c.y);
  distr2d_free(&d);
  distr2d_free(&d); /* zeroed: no-op */
  /* Bad input. */
  const double neg[2] = {1, -1}, zero[2] = {0, 0};
  CHECK(distr2d_init(&d, neg, 2, 1, "w", &err) == RSW_ERR_INVALID, "negative weight accepted");
  rsw_err_clear(&err);
  CHECK(distr2d_init(&d, zero, 2, 1, "w", &err) == RSW_ERR_INVALID, "all-zero weights accepted");
  CHECK(strstr(err.msg, "zero") != NULL, "message: %s", err.msg);
}

/* --- loading ------------------------------------------------------------------ */

static scene *env_scene(const char *env_json, const char *variant) {
  char sc[2048];
  snprintf(
      sc, sizeof sc,
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"perspective\", \"fov\": 30,"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4, \"rfilter\": {\"type\": \"box\"}}},"
      " \"env\": %s}",
      env_json);
  return tsup_load(sc, variant);
}

/* 16 x 8 RGB map: a gradient in u and v plus a bright spot. */
static void gradient_map(float *px) {
  for (int y = 0; y < 8; y++)
    for (int x = 0; x < 16; x++) {
      float *p = &px[3 * (y * 16 + x)];
      p[0] = 0.1f + 0.05f * x;
      p[1] = 0.2f + 0.1f * y;
      p[2] = 0.05f * (float)((x + y) % 4);
    }
  float *s = &px[3 * (3 * 16 + 11)];
  s[0] = 40, s[1] = 60, s[2] = 20;
}

typedef struct env_ctx {
  const emitter *e;
  surface_interaction ref;
} env_ctx;

/* Through the wave's call (kernel.h emitter_sample_direction_n: the
 * batched op or its fallback), one lane at a time; test_sampling_chi2 checks it against
 * sample_direction bit for bit. */
static bool s_env(void *user, const double *u, vec3 *out, double *weight) {
  env_ctx *c = user;
  direction_sample ds;
  const surface_interaction *ref = &c->ref;
  vec2 uu = v2(u[0], u[1]);
  color v;
  emitter_sample_direction_n(c->e, 1, &ref, &uu, &ds, &v);
  if (!(ds.pdf > 0) || col_is_black(v)) return false;
  *out = ds.d;
  *weight = 1.0;
  return true;
}

static double p_env(void *user, vec3 d) {
  env_ctx *c = user;
  direction_sample ds = {.d = d, .dist = INFINITY};
  return c->e->ops->pdf_direction(c->e, &c->ref, &ds);
}

/* Negative control: the pdf of the map turned by one column (2 pi / 16
 * about the local +y axis); the test must reject it. */
static double p_env_turned(void *user, vec3 d) {
  double a = 2 * PI / 16, c = cos(a), s = sin(a);
  return p_env(user, v3(c * d.x + s * d.z, d.y, -s * d.x + c * d.z));
}

static void test_sampling_chi2(void) {
  float px[16 * 8 * 3];
  gradient_map(px);
  char path[32];
  REQUIRE(write_map(path, 16, 8, 3, px), "write");
  /* Identity, and a rotation so that to_world is exercised. */
  const char *xf[2] = {"", ", \"to_world\": [{\"rotate\": {\"axis\": [1, 2, 0.5], \"angle\": 37}}]"};
  for (int k = 0; k < 2; k++) {
    char env[512];
    snprintf(env, sizeof env, "{\"type\": \"envmap\", \"filename\": \"%s\", \"scale\": 1.5%s}", path, xf[k]);
    scene *s = env_scene(env, NULL);
    REQUIRE(s && s->environment, "scene");
    env_ctx c = {.e = s->environment};
    chi2_config cfg = chi2_defaults(CHI2_SPHERE, 2);
    cfg.sample_count = 400000;
    cfg.test_count = 2;
    /* The pdf is piecewise constant with jumps inside the test's cells;
     * Mitsuba's ires = 4 Simpson integration of it is off by more than the
     * statistical noise of 400k samples, so integrate finer. */
    cfg.ires = 32;
    chi2_result r = chi2_run(&cfg, s_env, p_env, &c);
    CHECK(r.passed, "to_world %d: %s (chi2 %g, dof %d, p %g)", k, r.reason, r.chi2, r.dof, r.p_value);
    if (k == 0) {
      chi2_result bad_r = chi2_run(&cfg, s_env, p_env_turned, &c);
      CHECK(!bad_r.passed && bad_r.p_value < 1e-12, "a pdf turned by one column was accepted (p = %g)",
            bad_r.p_value);
    }
    /* sample's value is eval / pdf, and its pdf is pdf_direction's. */
    pcg32 rng;
    pcg32_seed(&rng, 11, 2);
    int bad = 0;
    for (int i = 0; i < 2000; i++) {
      direction_sample ds;
      vec2 u = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
      color v = c.e->ops->sample_direction(c.e, &c.ref, u, &ds);
      if (!(ds.pdf > 0)) continue;
      double p = p_env(&c, ds.d);
      color le = c.e->ops->eval(c.e, NULL, ds.d);
      if (fabs(p - ds.pdf) > 1e-6 * ds.pdf || ds.delta || !isinf(ds.dist)) bad++;
      for (int ch = 0; ch < 3; ch++)
        if (fabs(v.c[ch] * ds.pdf - le.c[ch]) > 1e-6 * (le.c[ch] + 1e-3)) bad++;
    }
    CHECK(bad == 0, "to_world %d: %d inconsistent samples", k, bad);
    /* The batched op: each lane bitwise sample_direction's. */
    enum {
      N = 40
    };
    const surface_interaction *refs[N];
    vec2 us[N];
    direction_sample dss[N];
    color vs[N];
    for (int i = 0; i < N; i++)
      refs[i] = &c.ref, us[i] = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
    emitter_sample_direction_n(c.e, N, refs, us, dss, vs);
    for (int i = 0; i < N; i++) {
      direction_sample ds;
      color v = c.e->ops->sample_direction(c.e, &c.ref, us[i], &ds);
      bad += memcmp(&v, &vs[i], sizeof v) != 0 || memcmp(&ds.d, &dss[i].d, sizeof ds.d) != 0 ||
             memcmp(&ds.pdf, &dss[i].pdf, sizeof ds.pdf) != 0;
    }
    CHECK(bad == 0, "to_world %d: %d batched samples differ from sample_direction", k, bad);
    scene_free(s);
  }
  remove(path);
}

/* --- orientation --------------------------------------------------------------- */

static void test_orientation(void) {
  /* 4 x 3 Y map: row 0 (the +y pole) all 7, row 2 (-y) all 9, the equator
   * row 1, 2, 3, 4. Column i lies at phi = 2 pi (i + 1/2) / 4 with
   * d = (sin phi, 0, -cos phi) on the equator (Mitsuba's uv_to_direction). */
  const float px[12] = {7, 7, 7, 7, 1, 2, 3, 4, 9, 9, 9, 9};
  char path[32];
  REQUIRE(write_map(path, 4, 3, 1, px), "write");
  char env[256];
  snprintf(env, sizeof env, "{\"type\": \"envmap\", \"filename\": \"%s\", \"scale\": 2}", path);
  scene *s = env_scene(env, NULL);
  REQUIRE(s && s->environment, "scene");
  const emitter *e = s->environment;
  CHECK(e->flags == EMITTER_INFINITE, "flags %u", e->flags);
  /* traverse(): scale, to_world, sampling_weight in the parameter table. */
  const char *keys[3] = {"env.scale", "env.to_world", "env.sampling_weight"};
  for (int k = 0; k < 3; k++) {
    size_t idx;
    rsw_err perr = {0};
    CHECK(params_lookup(s, keys[k], &idx, &perr) == RSW_OK, "%s: %s", keys[k], perr.msg);
  }
  for (int i = 0; i < 4; i++) {
    double phi = 2 * PI * (i + 0.5) / 4;
    color c = e->ops->eval(e, NULL, v3(sin(phi), 0, -cos(phi)));
    CHECK_REL(c.c[0], 2.0 * px[4 + i], 1e-9);
    /* Half way between columns i and i+1: their mean (periodic in u). */
    double phi2 = 2 * PI * (i + 1.0) / 4;
    color c2 = e->ops->eval(e, NULL, v3_scale(v3(sin(phi2), 0, -cos(phi2)), 3.0)); /* not unit: normalised */
    CHECK_REL(c2.c[1], (px[4 + i] + px[4 + (i + 1) % 4]), 1e-9);
  }
  CHECK_REL(e->ops->eval(e, NULL, v3(0, 1, 0)).c[0], 14.0, 1e-9);
  CHECK_REL(e->ops->eval(e, NULL, v3(0, -1, 0)).c[2], 18.0, 1e-9);
  /* Half way from the equator to the pole along column 0: bilinear in v. */
  double phi = 2 * PI * 0.5 / 4;
  color c = e->ops->eval(e, NULL, v3(sin(phi) * sin(PI / 4), cos(PI / 4), -cos(phi) * sin(PI / 4)));
  CHECK_REL(c.c[0], 2.0 * 0.5 * (7 + 1), 1e-9);
  scene_free(s);
  /* A rotation of 90 degrees about x takes local +y to world +z. */
  snprintf(env, sizeof env,
           "{\"type\": \"envmap\", \"filename\": \"%s\", \"to_world\": [{\"rotate\": {\"axis\": [1, 0, 0], "
           "\"angle\": 90}}]}",
           path);
  s = env_scene(env, NULL);
  REQUIRE(s && s->environment, "scene");
  CHECK_REL(s->environment->ops->eval(s->environment, NULL, v3(0, 0, 1)).c[0], 7.0, 1e-9);
  CHECK_REL(s->environment->ops->eval(s->environment, NULL, v3(0, 0, -1)).c[0], 9.0, 1e-9);
  scene_free(s);
  remove(path);
}

static void test_load_errors(void) {
  float px[12] = {1, 1, 1, 1, 1, 1, 1, -1, 1, 1, 1, 1};
  char path[32], small[32];
  REQUIRE(write_map(path, 4, 3, 1, px), "write");
  REQUIRE(write_map(small, 2, 2, 1, px), "write");
  char env[512];
  snprintf(env, sizeof env, "{\"type\": \"envmap\", \"filename\": \"%s\"}", path);
  CHECK(env_scene(env, NULL) == NULL, "negative pixel accepted");
  snprintf(env, sizeof env, "{\"type\": \"envmap\", \"filename\": \"%s\"}", small);
  CHECK(env_scene(env, NULL) == NULL, "2x2 map accepted");
  CHECK(env_scene("{\"type\": \"envmap\"}", NULL) == NULL, "missing filename accepted");
  px[7] = 1;
  REQUIRE(write_map(path, 4, 3, 1, px), "write");
  snprintf(env, sizeof env,
           "{\"type\": \"envmap\", \"filename\": \"%s\", \"to_world\": [{\"scale\": [1, 2, 1]}]}", path);
  CHECK(env_scene(env, NULL) == NULL, "non-uniform scale accepted");
  snprintf(env, sizeof env, "{\"type\": \"envmap\", \"filename\": \"%s\", \"scale\": -1}", path);
  CHECK(env_scene(env, NULL) == NULL, "negative scale accepted");
  /* An all-black map loads and emits nothing. */
  memset(px, 0, sizeof px);
  REQUIRE(write_map(path, 4, 3, 1, px), "write");
  snprintf(env, sizeof env, "{\"type\": \"envmap\", \"filename\": \"%s\"}", path);
  scene *s = env_scene(env, NULL);
  REQUIRE(s && s->environment, "black map refused");
  direction_sample ds;
  surface_interaction ref = {0};
  color v = s->environment->ops->sample_direction(s->environment, &ref, v2(0.3, 0.6), &ds);
  CHECK(col_is_black(v) && ds.pdf == 0, "black map sampled");
  scene_free(s);
  remove(path);
  remove(small);
}

/* --- renders -------------------------------------------------------------------- */

/* Paired comparison of two films rendered with the same seed: the mean of
 * the per-pixel differences is within 3 standard errors of 0. */
static void check_same_3sigma(const film_image *a, const film_image *b, const char *what) {
  size_t n = (size_t)a->width * a->height;
  for (int c = 0; c < a->channels; c++) {
    double s = 0, s2 = 0;
    for (size_t i = 0; i < n; i++) {
      double d = a->data[i * a->channels + c] - b->data[i * b->channels + c];
      s += d;
      s2 += d * d;
    }
    double m = s / n, sem = sqrt(fmax((s2 - s * s / n) / (n - 1), 0) / n);
    CHECK(fabs(m) <= 3 * sem + 1e-9, "%s channel %d: mean difference %.4g, 3 sigma %.4g", what, c, m,
          3 * sem);
  }
}

static void test_constant_map_equals_constant(void) {
  /* White furnace: a diffuse sphere of reflectance 1 in an environment of
   * radiance L = (0.5, 1, 2) everywhere; every pixel's expectation is L.
   * The envmap's film equals constant's within 3 sigma (paired), and its
   * mean is L within 3 sigma; background pixels (those where constant
   * gives exactly L) are exactly L in the envmap film too. */
  float px[8 * 4 * 3];
  for (int i = 0; i < 32; i++) px[3 * i] = 0.5f, px[3 * i + 1] = 1.0f, px[3 * i + 2] = 2.0f;
  char path[32];
  REQUIRE(write_map(path, 8, 4, 3, px), "write");
  const char *fmt =
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"perspective\", \"fov\": 30,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16, \"rfilter\": {\"type\": "
      "\"box\"}}},"
      " \"integrator\": {\"type\": \"path\", \"rr_depth\": 5},"
      " \"env\": %s,"
      " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 1.0}}}";
  char env[512], sc[2048];
  film_image img[2];
  for (int k = 0; k < 2; k++) {
    if (k == 0)
      snprintf(env, sizeof env, "{\"type\": \"constant\", \"radiance\": [0.5, 1, 2]}");
    else
      snprintf(env, sizeof env,
               "{\"type\": \"envmap\", \"filename\": \"%s\", \"to_world\": [{\"rotate\": {\"axis\": [0, 0, "
               "1], \"angle\": 20}}]}",
               path);
    snprintf(sc, sizeof sc, fmt, env);
    scene *s = tsup_load(sc, NULL);
    REQUIRE(s, "scene %d", k);
    REQUIRE(tsup_render(s, 0, 5, 0, &img[k]), "render %d", k);
    scene_free(s);
  }
  REQUIRE(img[0].channels == 3 && img[1].channels == 3, "rgb films");
  check_same_3sigma(&img[1], &img[0], "envmap - constant");
  const double L[3] = {0.5, 1, 2};
  for (int c = 0; c < 3; c++) {
    double m, sem;
    tsup_stats(&img[1], c, &m, &sem);
    CHECK(fabs(m - L[c]) <= 3 * sem + 1e-9, "channel %d: mean %.5g vs L %.5g (3 sigma %.3g)", c, m, L[c],
          3 * sem);
  }
  int background = 0, bad = 0;
  for (int i = 0; i < img[0].width * img[0].height; i++) {
    bool bg = true;
    for (int c = 0; c < 3; c++) bg = bg && fabs(img[0].data[3 * i + c] - L[c]) <= 1e-6 * L[c];
    if (!bg) continue;
    background++;
    for (int c = 0; c < 3; c++)
      if (fabs(img[1].data[3 * i + c] - img[0].data[3 * i + c]) > 1e-6 * L[c]) bad++;
  }
  CHECK(background >= 40, "only %d background pixels", background);
  CHECK(bad == 0, "%d background values differ between envmap and constant", bad);
  film_image_free(&img[0]);
  film_image_free(&img[1]);
  remove(path);
}

static void test_bright_pole_equals_directional(void) {
  /* An 8 x 33 map, zero but for row 0 (the +y pole, where all of row 0's
   * samples sit) of radiance Lb. Bilinear interpolation makes a polar cap
   * of radiance Lb (1 - theta / D), D = pi / 32. Its radiance integrated
   * over solid angle (the irradiance of the equivalent directional
   * emitter) is
   *     Omega Lb = 2 pi Lb int_0^D (1 - t/D) sin t dt = 2 pi Lb (1 - sin D / D),
   * and the exact irradiance on a plane facing +y
   *     E = 2 pi Lb int_0^D (1 - t/D) sin t cos t dt
   *       = 2 pi Lb (sin^2 D / 2 + cos 2D / 4 - sin 2D / (8 D)),
   * which differs from Omega Lb by |E - Omega Lb| (~0.1%), allowed on top
   * of 3 sigma. A Lambertian plate (rho 0.5) facing the cap has radiance
   * rho E / pi. Case 0: identity to_world, plate turned to face +y, sun
   * travelling along -y; case 1: to_world turns +y to +z, plate facing +z,
   * sun travelling along -z. */
  const int W = 8, H = 33;
  const double Lb = 50.0, rho = 0.5, D = PI / (H - 1);
  float *px = calloc((size_t)W * H * 3, sizeof(float));
  REQUIRE(px, "alloc");
  for (int i = 0; i < 3 * W; i++) px[i] = (float)Lb;
  char path[32];
  REQUIRE(write_map(path, W, H, 3, px), "write");
  free(px);
  double omega = 2 * PI * (1 - sin(D) / D);
  double E = 2 * PI * Lb * (sin(D) * sin(D) / 2 + cos(2 * D) / 4 - sin(2 * D) / (8 * D));
  const char *fmt = "{\"type\": \"scene\","
                    " \"cam\": {\"type\": \"perspective\", \"fov\": 8,"
                    "   \"to_world\": [{\"lookat\": {\"origin\": %s, \"target\": [0, 0, 0], \"up\": %s}}],"
                    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
                    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16, \"rfilter\": "
                    "{\"type\": \"box\"}}},"
                    " \"integrator\": {\"type\": \"path\"},"
                    " \"light\": %s,"
                    " \"plate\": {\"type\": \"rectangle\"%s,"
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";
  for (int k = 0; k < 2; k++) {
    const char *origin = k ? "[0, 0, 5]" : "[0, 5, 0]", *up = k ? "[0, 1, 0]" : "[0, 0, 1]";
    const char *plate_xf = k ? "" : ", \"to_world\": [{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": -90}}]";
    const char *env_xf = k ? ", \"to_world\": [{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 90}}]" : "";
    char light[512], sc[2048];
    film_image img[2];
    for (int e = 0; e < 2; e++) {
      if (e == 0)
        snprintf(light, sizeof light, "{\"type\": \"directional\", \"direction\": %s, \"irradiance\": %.17g}",
                 k ? "[0, 0, -1]" : "[0, -1, 0]", Lb * omega);
      else
        snprintf(light, sizeof light, "{\"type\": \"envmap\", \"filename\": \"%s\"%s}", path, env_xf);
      snprintf(sc, sizeof sc, fmt, origin, up, light, plate_xf);
      scene *s = tsup_load(sc, NULL);
      REQUIRE(s, "scene %d %d", k, e);
      REQUIRE(tsup_render(s, 0, 9, 0, &img[e]), "render");
      scene_free(s);
    }
    double directional = rho * Lb * omega / PI, bias = rho * fabs(E - Lb * omega) / PI;
    double m0, sem0;
    tsup_stats(&img[0], 0, &m0, &sem0);
    CHECK_REL(m0, directional, 1e-5); /* the directional plate is exact */
    for (int c = 0; c < 3; c++) {
      double m, sem;
      tsup_stats(&img[1], c, &m, &sem);
      CHECK(fabs(m - directional) <= 3 * sem + bias,
            "case %d channel %d: envmap %.6g vs directional %.6g (3 sigma %.3g, bias %.3g)", k, c, m,
            directional, 3 * sem, bias);
      CHECK(fabs(m - rho * E / PI) <= 3 * sem, "case %d channel %d: envmap %.6g vs exact %.6g (3 sigma %.3g)",
            k, c, m, rho * E / PI, 3 * sem);
      CHECK(sem < 0.02 * m, "case %d: standard error %.3g too large for a meaningful test", k, sem);
    }
    film_image_free(&img[0]);
    film_image_free(&img[1]);
  }
  remove(path);
}

static void test_mono(void) {
  /* An RGB map in mono gives its luminance (times scale); in rgb the
   * triple; a Y map its value in both. The camera sees only background. */
  float px[4 * 3 * 3];
  for (int i = 0; i < 12; i++) px[3 * i] = 0.2f, px[3 * i + 1] = 0.5f, px[3 * i + 2] = 0.9f;
  float py[12];
  for (int i = 0; i < 12; i++) py[i] = 0.7f;
  char prgb[32], pyy[32];
  REQUIRE(write_map(prgb, 4, 3, 3, px), "write");
  REQUIRE(write_map(pyy, 4, 3, 1, py), "write");
  const double lum = 0.212671 * 0.2f + 0.715160 * 0.5f + 0.072169 * 0.9f;
  for (int v = 0; v < 2; v++)
    for (int m = 0; m < 2; m++) {
      char env[256];
      snprintf(env, sizeof env, "{\"type\": \"envmap\", \"filename\": \"%s\", \"scale\": 2}", m ? pyy : prgb);
      scene *s = env_scene(env, v ? "mono" : "rgb");
      REQUIRE(s, "scene");
      film_image img;
      REQUIRE(tsup_render(s, 2, 1, 1, &img), "render");
      CHECK(img.channels == (v ? 1 : 3), "channels %d", img.channels);
      int bad = 0;
      for (int i = 0; i < img.width * img.height; i++)
        for (int c = 0; c < img.channels; c++) {
          double want = 2.0 * (m ? 0.7f : (v ? lum : (double)px[c]));
          if (fabs(img.data[i * img.channels + c] - want) > 1e-6 * want) bad++;
        }
      CHECK(bad == 0, "variant %s, %s map: %d wrong values (first %.7g)", v ? "mono" : "rgb", m ? "Y" : "RGB",
            bad, img.data[0]);
      film_image_free(&img);
      scene_free(s);
    }
  remove(prgb);
  remove(pyy);
}

int main(void) {
  RSW_TEST_RUN(test_distr2d);
  RSW_TEST_RUN(test_orientation);
  RSW_TEST_RUN(test_load_errors);
  RSW_TEST_RUN(test_sampling_chi2);
  RSW_TEST_RUN(test_constant_map_equals_constant);
  RSW_TEST_RUN(test_bright_pole_equals_directional);
  RSW_TEST_RUN(test_mono);
  RSW_TEST_END("test_envmap");
}
