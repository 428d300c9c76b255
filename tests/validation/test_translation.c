/* Results must not depend on where a scene sits (issue 11, item 3).
 *
 * Each scene is rendered as written and translated by D along a fixed
 * oblique unit vector u (so that x, y and z all grow), D = 1 km, 10 km and
 * 100 km (and 2 km for the hot spot). Every shape's to_world, the sensors'
 * targets and cameras and the instance placements move; directions do not.
 *
 *  - plate: a Lambertian rectangle under a directional sun, hdistant with a
 *    flat shape target: a zero-variance estimator, so every pixel must
 *    equal the closed form rho E cos(theta_s) / pi to 1e-5 relative.
 *  - cornell: a closed box (six inward walls, an area light, an analytic
 *    sphere and disk) seen by a perspective camera inside it. The film mean
 *    must agree with the untranslated one within 3 sigma, sigma the
 *    standard deviation of the difference of two independent renders
 *    (estimated from K independent seeds of the untranslated scene; the
 *    translated render reuses seed 1, which only makes the difference
 *    smaller, so the bound is conservative).
 *  - radiancemeters: six meters of an mradiancemeter lying on the box's
 *    tilted disk, looking at the light's centre, emission only: each sees
 *    exactly the light's radiance (a meter whose origin rounds below the
 *    disk sees the disk's black back instead).
 *  - canopy: a plot of 8,000 instanced discs of radius 5 cm (one shapegroup
 *    holding a unit disk, one instancelist) over a soil, lit by a sun at 30
 *    degrees and seen by mdistant in five directions of the principal plane
 *    around the backscattering direction: the exact hot spot (view
 *    direction = sun direction) and +-3, +-6 degrees. The hot-spot BRF
 *    (pi L / (E cos theta_s)) must match the untranslated one within 0.5%,
 *    every direction within 3 sigma as above (per pixel).
 *
 *  - an update that moves the soil 2 km away (and so Embree's frame, and
 *    every instance transform with it) equals a reload, bit for bit.
 *
 * Fixed seeds; two threads. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../server/kernel/accel.h"
#include "../../server/kernel/core/rng.h"
#include "../../server/kernel/core/transform.h"
#include "../../server/kernel/scene/params.h"
#include "../../server/kernel/scene/update.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define PI      3.14159265358979323846
#define THREADS 2
#define K_SEEDS 6

/* The translation direction (unit). */
static const double U[3] = {0.6, 0.48, 0.64};
static const double SHIFTS[] = {0.0, 1e3, 1e4, 1e5};
#define N_SHIFTS (sizeof SHIFTS / sizeof SHIFTS[0])

/* ", {"translate": base + D u}" to append to a to_world operation list. */
static void sb_shift_from(sbuf *b, const double base[3], double D) {
  sb_printf(b, ", {\"translate\": [%.17g, %.17g, %.17g]}", base[0] + D * U[0], base[1] + D * U[1],
            base[2] + D * U[2]);
}
static const double ZERO[3] = {0, 0, 0};
static void sb_shift(sbuf *b, double D) {
  sb_shift_from(b, ZERO, D);
}

/* The box sits off the grid (its floor at z = -0.69), so that its
 * coordinates are not exact in float32 at any shift. */
static const double BOX[3] = {0.137, -0.071, 0.31};

static double film_mean(const film_image *f) {
  double s = 0;
  size_t n = (size_t)f->width * f->height;
  for (size_t i = 0; i < n; i++) s += f->data[i * f->channels];
  return s / (double)n;
}

/* ---- plate -------------------------------------------------------------------- */

static char *plate_scene(double D) {
  sbuf b = {0};
  sb_printf(&b, "{\"type\": \"scene\", \"variant\": \"mono\",\n"
                "\"cam\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\", \"to_world\": "
                "[{\"scale\": [5, 5, 1]}");
  sb_shift(&b, D);
  sb_printf(
      &b,
      "]}, \"sampler\": {\"type\": \"independent\", \"sample_count\": 8}, "
      "\"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"box\"}}},\n"
      "\"sun\": {\"type\": \"directional\", \"direction\": [0.3, 0.2, -0.9], \"irradiance\": 2.0},\n"
      "\"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}, "
      "\"to_world\": [{\"scale\": [20, 20, 1]}");
  sb_shift(&b, D);
  sb_printf(&b, "]}}\n");
  return b.p;
}

static void test_plate(void) {
  double cos_s = 0.9 / sqrt(0.09 + 0.04 + 0.81);
  double expect = 0.5 * 2.0 * cos_s / PI;
  for (size_t k = 0; k < N_SHIFTS; k++) {
    char *txt = plate_scene(SHIFTS[k]);
    scene *s = tsup_load(txt, NULL);
    free(txt);
    REQUIRE(s, "plate scene at %g m", SHIFTS[k]);
    film_image img;
    bool ok = tsup_render(s, 0, 1, THREADS, &img);
    scene_free(s);
    REQUIRE(ok, "render");
    double worst = 0;
    for (int i = 0; i < img.width * img.height; i++)
      worst = fmax(worst, fabs(img.data[(size_t)i * img.channels] - expect) / expect);
    printf("  plate shift %6.0f m: worst pixel rel. error %.3g\n", SHIFTS[k], worst);
    CHECK(worst <= 1e-5, "plate shifted by %g m: a pixel is %.3g off the closed form %.9g", SHIFTS[k], worst,
          expect);
    film_image_free(&img);
  }
}

/* ---- cornell-like closed box -------------------------------------------------- */

/* A wall: the unit rectangle turned so that its normal points into the
 * box, moved to its side; `rot` is a rotate operation or "". */
static void sb_wall(sbuf *b, const char *name, const char *rot, double tx, double ty, double tz, double rho,
                    double D) {
  sb_printf(b,
            ",\n\"%s\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": %g}, "
            "\"to_world\": [%s%s{\"translate\": [%g, %g, %g]}",
            name, rho, rot, *rot ? ", " : "", tx, ty, tz);
  sb_shift_from(b, BOX, D);
  sb_printf(b, "]}");
}

/* meters: instead of the camera, an mradiancemeter whose N_METER meters
 * lie on the tilted disk (the plaque) looking at the light's centre, with
 * max_depth 1 (emission only): every pixel is the light's radiance. */
#define N_METER 6
static void meter_ray(double D, int i, vec3 *o, vec3 *d) {
  xform T = xf_translate(v3(BOX[0] - 0.5 + D * U[0], BOX[1] + 0.4 + D * U[1], BOX[2] - 0.3 + D * U[2]));
  xform R = xf_rotate(v3(1, -1, 0), 60), S = xf_scale(v3(0.3, 0.3, 1));
  xform RS = xf_mul(&R, &S), P = xf_mul(&T, &RS);
  double a = 2 * PI * i / N_METER, r = 0.2 + 0.1 * (i % 3);
  *o = xf_point(&P, v3(r * cos(a), r * sin(a), 0));
  vec3 light = v3(BOX[0] + D * U[0], BOX[1] + 0.1 + D * U[1], BOX[2] + 0.98 + D * U[2]);
  *d = v3_sub(light, *o);
}

static char *cornell_scene(double D, bool meters) {
  sbuf b = {0};
  sb_printf(&b,
            "{\"type\": \"scene\", \"variant\": \"mono\",\n"
            "\"integrator\": {\"type\": \"path\", \"max_depth\": %d},\n",
            meters ? 1 : 6);
  if (meters) {
    vec3 o[N_METER], d[N_METER];
    for (int i = 0; i < N_METER; i++) meter_ray(D, i, &o[i], &d[i]);
    sb_printf(&b, "\"cam\": {\"type\": \"mradiancemeter\", \"origins\": \"");
    for (int i = 0; i < N_METER; i++)
      sb_printf(&b, "%s%.17g %.17g %.17g", i ? ", " : "", o[i].x, o[i].y, o[i].z);
    sb_printf(&b, "\", \"directions\": \"");
    for (int i = 0; i < N_METER; i++)
      sb_printf(&b, "%s%.17g %.17g %.17g", i ? ", " : "", d[i].x, d[i].y, d[i].z);
    sb_printf(&b,
              "\", \"sampler\": {\"type\": \"independent\", \"sample_count\": 1}, "
              "\"film\": {\"type\": \"hdrfilm\", \"width\": %d, \"height\": 1, "
              "\"rfilter\": {\"type\": \"box\"}}}",
              N_METER);
  } else {
    sb_printf(&b,
              "\"cam\": {\"type\": \"perspective\", \"fov\": 70, \"to_world\": [{\"lookat\": {\"origin\": "
              "[0, -0.9, 0.1], \"target\": [0, 1, 0], \"up\": [0, 0, 1]}}");
    sb_shift_from(&b, BOX, D);
    sb_printf(
        &b,
        "], \"sampler\": {\"type\": \"independent\", \"sample_count\": 48}, "
        "\"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"box\"}}}");
  }
  sb_wall(&b, "floor", "", 0, 0, -1, 0.6, D);
  sb_wall(&b, "ceiling", "{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}}", 0, 0, 1, 0.6, D);
  sb_wall(&b, "left", "{\"rotate\": {\"axis\": [0, 1, 0], \"angle\": 90}}", -1, 0, 0, 0.3, D);
  sb_wall(&b, "right", "{\"rotate\": {\"axis\": [0, 1, 0], \"angle\": -90}}", 1, 0, 0, 0.8, D);
  sb_wall(&b, "back", "{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 90}}", 0, 1, 0, 0.6, D);
  sb_wall(&b, "front", "{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": -90}}", 0, -1, 0, 0.6, D);
  sb_printf(&b,
            ",\n\"light\": {\"type\": \"rectangle\", \"emitter\": {\"type\": \"area\", \"radiance\": 8}, "
            "\"to_world\": [{\"scale\": [0.3, 0.3, 1]}, {\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}}, "
            "{\"translate\": [0, 0.1, 0.98]}");
  sb_shift_from(&b, BOX, D);
  sb_printf(&b, "]},\n\"ball\": {\"type\": \"sphere\", \"radius\": 0.35, \"bsdf\": {\"type\": \"diffuse\", "
                "\"reflectance\": 0.7}, \"to_world\": [{\"translate\": [0.35, 0.3, -0.65]}");
  sb_shift_from(&b, BOX, D);
  sb_printf(&b,
            "]},\n\"plaque\": {\"type\": \"disk\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.7}, "
            "\"to_world\": [{\"scale\": [0.3, 0.3, 1]}, {\"rotate\": {\"axis\": [1, -1, 0], \"angle\": 60}}, "
            "{\"translate\": [-0.5, 0.4, -0.3]}");
  sb_shift_from(&b, BOX, D);
  sb_printf(&b, "]}}\n");
  return b.p;
}

static bool render_mean(const char *txt, uint64_t seed, double *mean) {
  scene *s = tsup_load(txt, NULL);
  if (!s) return false;
  film_image img;
  bool ok = tsup_render(s, 0, seed, THREADS, &img);
  scene_free(s);
  if (!ok) return false;
  *mean = film_mean(&img);
  film_image_free(&img);
  return true;
}

static void test_cornell(void) {
  /* Sigma of one render's film mean from K independent seeds. */
  char *txt = cornell_scene(0, false);
  double m[K_SEEDS], s1 = 0, s2 = 0;
  for (int k = 0; k < K_SEEDS; k++) {
    REQUIRE(render_mean(txt, 1 + (uint64_t)k, &m[k]), "cornell render");
    s1 += m[k];
    s2 += m[k] * m[k];
  }
  free(txt);
  double sd = sqrt(fmax(0.0, (s2 - s1 * s1 / K_SEEDS) / (K_SEEDS - 1)));
  double tol = 3.0 * sqrt(2.0) * sd;
  printf("  cornell shift      0 m: film mean %.6f (sigma of one render %.2g)\n", m[0], sd);
  REQUIRE(sd > 0 && sd < 0.05 * m[0], "cornell: sigma %.3g of mean %.3g is not a usable yardstick", sd, m[0]);
  for (size_t k = 1; k < N_SHIFTS; k++) {
    txt = cornell_scene(SHIFTS[k], false);
    double mk;
    bool ok = render_mean(txt, 1, &mk);
    free(txt);
    REQUIRE(ok, "cornell render at %g m", SHIFTS[k]);
    printf("  cornell shift %6.0f m: film mean %.6f (%+.2f sigma)\n", SHIFTS[k], mk,
           (mk - m[0]) / (sqrt(2.0) * sd));
    CHECK(fabs(mk - m[0]) <= tol, "cornell box shifted by %g m: film mean %.6f vs %.6f (3 sigma = %.3g)",
          SHIFTS[k], mk, m[0], tol);
  }
}

/* Radiancemeters lying on the tilted disk see the light (radiance 8) at
 * every shift, not the disk's back. */
static void test_radiancemeters_on_surface(void) {
  for (size_t k = 0; k < N_SHIFTS; k++) {
    char *txt = cornell_scene(SHIFTS[k], true);
    scene *s = tsup_load(txt, NULL);
    free(txt);
    REQUIRE(s, "meter scene at %g m", SHIFTS[k]);
    film_image img;
    bool ok = tsup_render(s, 0, 1, THREADS, &img);
    scene_free(s);
    REQUIRE(ok, "render");
    int wrong = 0;
    for (int i = 0; i < N_METER; i++) wrong += !(fabs(img.data[(size_t)i * img.channels] - 8.0) <= 1e-6);
    printf("  radiancemeters on a surface, shift %6.0f m: %d of %d do not see the light\n", SHIFTS[k], wrong,
           N_METER);
    CHECK(wrong == 0, "shifted by %g m: %d of %d radiancemeters on a surface miss the light", SHIFTS[k],
          wrong, N_METER);
    film_image_free(&img);
  }
}

/* ---- disc canopy hot spot ----------------------------------------------------- */

#define N_LEAF 8000
#define N_DIR  5
static const double VIEW_ZEN[N_DIR] = {24, 27, 30, 33, 36}; /* degrees, sun side; 30 = hot spot */
#define SUN_ZEN 30.0

/* Leaf placements (x y z and a random upward normal; radius 5 cm) as
 * 4x4 rows of an instancelist, translated by D u, written to `path`. */
static bool write_leaves(const char *path, double D) {
  FILE *f = fopen(path, "w");
  if (!f) return false;
  pcg32 g;
  pcg32_seed(&g, 2024, 11);
  for (int i = 0; i < N_LEAF; i++) {
    double x = -3 + 6 * pcg32_next_double(&g), y = -3 + 6 * pcg32_next_double(&g);
    double z = 0.3 + 1.2 * pcg32_next_double(&g);
    /* Uniform on the upper hemisphere. */
    double cz = pcg32_next_double(&g), ph = 2 * PI * pcg32_next_double(&g), sz = sqrt(1 - cz * cz);
    vec3 n = v3(sz * cos(ph), sz * sin(ph), cz);
    frame fr = frame_from_normal(n);
    const double r = 0.05;
    vec3 c[3] = {fr.s, fr.t, fr.n};
    double t[3] = {x + D * U[0], y + D * U[1], z + D * U[2]};
    double rows[3][3] = {{c[0].x, c[1].x, c[2].x}, {c[0].y, c[1].y, c[2].y}, {c[0].z, c[1].z, c[2].z}};
    for (int rr = 0; rr < 3; rr++)
      fprintf(f, "%.9g %.9g %.9g %.17g ", r * rows[rr][0], r * rows[rr][1], r * rows[rr][2], t[rr]);
    fprintf(f, "0 0 0 1\n");
  }
  return fclose(f) == 0;
}

static char *canopy_scene(double D, const char *list, double soil_x) {
  sbuf b = {0};
  double ss = sin(SUN_ZEN * PI / 180), cs = cos(SUN_ZEN * PI / 180);
  sb_printf(&b, "{\"type\": \"scene\", \"variant\": \"mono\",\n"
                "\"integrator\": {\"type\": \"path\", \"max_depth\": 3},\n"
                "\"cam\": {\"type\": \"mdistant\", \"directions\": \"");
  for (int i = 0; i < N_DIR; i++) {
    double z = VIEW_ZEN[i] * PI / 180;
    sb_printf(&b, "%s%.17g 0 %.17g", i ? ", " : "", sin(z), -cos(z));
  }
  sb_printf(&b, "\", \"target\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [1, 1, 1]}");
  sb_shift(&b, D);
  sb_printf(
      &b,
      "]}, \"sampler\": {\"type\": \"independent\", \"sample_count\": 16000}, "
      "\"film\": {\"type\": \"hdrfilm\", \"width\": %d, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},\n"
      "\"sun\": {\"type\": \"directional\", \"direction\": [%.17g, 0, %.17g], \"irradiance\": 1.0},\n"
      "\"soil\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.15}, "
      "\"to_world\": [{\"scale\": [4, 4, 1]}, {\"translate\": [%.17g, 0, 0]}",
      N_DIR, ss, -cs, soil_x);
  sb_shift(&b, D);
  sb_printf(&b,
            "]},\n\"leaf\": {\"type\": \"shapegroup\", \"d\": {\"type\": \"disk\", \"bsdf\": "
            "{\"type\": \"diffuse\", \"reflectance\": 0.45}}},\n"
            "\"canopy\": {\"type\": \"instancelist\", \"filename\": \"%s\", "
            "\"shapegroup\": {\"type\": \"ref\", \"id\": \"leaf\"}}}\n",
            list);
  return b.p;
}

/* BRF per direction: pi L / (E cos theta_s), E = 1. */
static bool canopy_brf(double D, uint64_t seed, double brf[N_DIR]) {
  char path[] = "/tmp/rsw_translation_XXXXXX";
  int fd = mkstemp(path);
  if (fd < 0) return false;
  close(fd);
  bool ok = write_leaves(path, D);
  char *txt = ok ? canopy_scene(D, path, 0) : NULL;
  scene *s = txt ? tsup_load(txt, NULL) : NULL;
  free(txt);
  remove(path);
  if (!s) return false;
  film_image img;
  ok = tsup_render(s, 0, seed, THREADS, &img);
  scene_free(s);
  if (!ok) return false;
  for (int i = 0; i < N_DIR; i++) brf[i] = PI * img.data[(size_t)i * img.channels] / cos(SUN_ZEN * PI / 180);
  film_image_free(&img);
  return true;
}

static void test_canopy_hot_spot(void) {
  /* Per-direction sigma of one render from K independent seeds. */
  double ref[K_SEEDS][N_DIR];
  for (int k = 0; k < K_SEEDS; k++) REQUIRE(canopy_brf(0, 1 + (uint64_t)k, ref[k]), "canopy render");
  double sd[N_DIR];
  for (int i = 0; i < N_DIR; i++) {
    double s1 = 0, s2 = 0;
    for (int k = 0; k < K_SEEDS; k++) s1 += ref[k][i], s2 += ref[k][i] * ref[k][i];
    sd[i] = sqrt(fmax(0.0, (s2 - s1 * s1 / K_SEEDS) / (K_SEEDS - 1)));
  }
  printf("  canopy BRF at view zenith");
  for (int i = 0; i < N_DIR; i++) printf(" %5.0f", VIEW_ZEN[i]);
  printf("  (sun at %g; sigma of one render:", SUN_ZEN);
  for (int i = 0; i < N_DIR; i++) printf(" %.2g", sd[i]);
  printf(")\n  shift      0 m:          ");
  for (int i = 0; i < N_DIR; i++) printf(" %.4f", ref[0][i]);
  printf("\n");
  const double shifts[] = {1e3, 2e3, 1e4, 1e5};
  for (size_t k = 0; k < sizeof shifts / sizeof shifts[0]; k++) {
    double b[N_DIR];
    REQUIRE(canopy_brf(shifts[k], 1, b), "canopy render at %g m", shifts[k]);
    printf("  shift %6.0f m:          ", shifts[k]);
    for (int i = 0; i < N_DIR; i++) printf(" %.4f", b[i]);
    printf("   hot spot %+.3f%%\n", 100 * (b[2] - ref[0][2]) / ref[0][2]);
    CHECK(fabs(b[2] - ref[0][2]) <= 0.005 * ref[0][2], "hot-spot BRF shifted by %g m: %.5f vs %.5f (> 0.5%%)",
          shifts[k], b[2], ref[0][2]);
    for (int i = 0; i < N_DIR; i++)
      CHECK(fabs(b[i] - ref[0][i]) <= 3 * sqrt(2.0) * sd[i],
            "BRF at view zenith %g shifted by %g m: %.5f vs %.5f (3 sigma = %.3g)", VIEW_ZEN[i], shifts[k],
            b[i], ref[0][i], 3 * sqrt(2.0) * sd[i]);
  }
}

static bool same_film(const film_image *a, const film_image *b) {
  return a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, sizeof(float) * (size_t)a->width * a->height * a->channels) == 0;
}

/* Moving the soil 2 km away moves Embree's frame (accel_origin) and so
 * rewrites every instance transform, the instancelist's included: the
 * update must still equal a reload, bit for bit. */
static void test_update_moves_frame(void) {
  char path[] = "/tmp/rsw_translation_XXXXXX";
  int fd = mkstemp(path);
  REQUIRE(fd >= 0, "mkstemp");
  close(fd);
  REQUIRE(write_leaves(path, 0), "leaves");
  char *t0 = canopy_scene(0, path, 0), *t1 = canopy_scene(0, path, 2000);
  scene *s = tsup_load(t0, NULL), *r = tsup_load(t1, NULL);
  free(t0), free(t1);
  REQUIRE(s && r, "scenes load");
  film_image before = {0}, after = {0}, ref = {0};
  REQUIRE(tsup_render(s, 2000, 3, THREADS, &before), "render");
  vec3 o0 = accel_origin(s->accel);
  accel_counters c0, c1;
  accel_get_counters(s->accel, &c0);
  rsw_err err = {0};
  param_update u = {.key = "soil.to_world"};
  REQUIRE(param_value_parse("[[4, 0, 0, 2000], [0, 4, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]", "soil.to_world",
                            &u.value, &err) == RSW_OK,
          "parse: %s", err.msg);
  rsw_status st = scene_update(s, &u, 1, NULL, &err);
  param_value_free(&u.value);
  REQUIRE(st == RSW_OK, "update: %s", err.msg);
  accel_get_counters(s->accel, &c1);
  vec3 o1 = accel_origin(s->accel), oref = accel_origin(r->accel);
  CHECK(c1.origin_moves == c0.origin_moves + 1 && fabs(o1.x - o0.x) > 900,
        "the update moves the frame (x %.3f -> %.3f, moves %lu -> %lu)", o0.x, o1.x, c0.origin_moves,
        c1.origin_moves);
  CHECK(memcmp(&o1, &oref, sizeof o1) == 0, "frame after the update equals the reload's");
  REQUIRE(tsup_render(s, 2000, 3, THREADS, &after) && tsup_render(r, 2000, 3, THREADS, &ref), "renders");
  CHECK(same_film(&after, &ref), "update equals reload");
  CHECK(!same_film(&before, &after), "the update changed the film");
  film_image_free(&before), film_image_free(&after), film_image_free(&ref);
  scene_free(s), scene_free(r);
  remove(path);
}

int main(void) {
  RSW_TEST_RUN(test_plate);
  RSW_TEST_RUN(test_cornell);
  RSW_TEST_RUN(test_radiancemeters_on_surface);
  RSW_TEST_RUN(test_canopy_hot_spot);
  RSW_TEST_RUN(test_update_moves_frame);
  RSW_TEST_END("test_translation");
}
