/* Local majorants (docs/media.md#local-majorants): a `heterogeneous`
 * medium with a nested extremum_grid.
 *
 *  - Bounds: for grids of random values (1 and 3 channels, nearest and
 *    trilinear lookups, clamp, repeat and mirror wraps, coarser, equal and
 *    finer cell counts than voxels, automatic), along 400 random rays
 *    through the box, the walk's pieces tile [mint, maxt] in order and the
 *    extinction at 64 random points of each piece is at most the piece's
 *    majorant. A failure means a biased film.
 *  - Transmittance: an absorbing grid (ratio tracking) seen against a
 *    uniform sky gives exp(-tau) of the column the sensor looks through,
 *    tau summed exactly from the grid, within 4 standard errors (24
 *    renders, fixed seeds), with and without the grid.
 *  - Scattering: a scattering grid (delta tracking, ratio-tracked shadow
 *    rays) renders the same film mean with extremum_grid as with the
 *    global majorant, within 4 standard errors of the difference (mono,
 *    rgb, and a bundle of 4 wavelengths of a tabulated grid: the pages'
 *    tracks).
 *  - A grid with one cell of 1e12 beside 0.001, whose tracks the global
 *    majorant gives up (docs/media.md#tracks-given-up), renders with none
 *    given up and the exact transmittance where its rays miss the dense
 *    cell.
 *  - A grid of zeros with one dense corner: the extremum grid takes fewer
 *    tentative collisions (the render is faster: reported, not asserted).
 *  - Bad resolutions are refused naming the key; an extremum on a
 *    homogeneous medium is refused. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../../server/kernel/media/majorant_grid.h"
#include "../../../server/kernel/scene/scene.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static uint64_t rng = 0x9e3779b97f4a7c15ull;
static double urand(void) {
  rng ^= rng << 13, rng ^= rng >> 7, rng ^= rng << 17;
  return (double)(rng >> 11) * 0x1p-53;
}

static object *find_cls(const scene *s, const char *id, obj_class cls) {
  for (size_t i = 0; i < s->n_objects; i++) {
    object *o = s->objects[i];
    if (o->id && strcmp(o->id, id) == 0 && o->plugin && o->plugin->cls == cls) return o;
  }
  return NULL;
}

/* A scene: a heterogeneous medium "m" (albedo alb; sigma_t a gridvolume of
 * [nz, ny, nx(, ch)] values `data` with filter and wrap; `extra`: more of
 * the medium's members, e.g. an extremum) filling the cube [-1, 1]^3,
 * seen straight down by a one-pixel `distant` sensor aimed at (tx, ty, 0)
 * against a uniform sky of radiance 1 (nothing else). */
static char *grid_scene(const char *variant_json, int nx, int ny, int nz, int ch, const char *data,
                        const char *filter, const char *wrap, const char *extra, double alb, double tx,
                        double ty, const char *vol_extra) {
  sbuf b = {0};
  sb_printf(
      &b,
      "{\"type\": \"scene\",%s \"integrator\": {\"type\": \"volpath\", \"max_depth\": -1},"
      " \"s\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [%.17g, %.17g, 0],"
      "  \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"sky\": {\"type\": \"constant\", \"radiance\": 1},"
      " \"box\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": \"ref\", "
      "\"id\": \"m\"}},"
      " \"m\": {\"type\": \"heterogeneous\", \"albedo\": %.17g, %s"
      "  \"sigma_t\": {\"type\": \"gridvolume\", \"shape\": [%d, %d, %d%s], \"data\": [%s],"
      "   \"filter_type\": \"%s\", \"wrap_mode\": \"%s\", %s"
      "   \"to_world\": [{\"translate\": [-0.5, -0.5, -0.5]}, {\"scale\": 2}]}}}",
      variant_json, tx, ty, alb, extra, nz, ny, nx, ch == 3 ? ", 3" : "", data, filter, wrap, vol_extra);
  return b.p;
}

static char *random_values(size_t n, double lo, double hi) {
  sbuf b = {0};
  for (size_t i = 0; i < n; i++) sb_printf(&b, "%s%.17g", i ? ", " : "", lo + (hi - lo) * urand());
  return b.p;
}

static bool prepare(scene *s) {
  film_image img;
  if (!tsup_render(s, 1, 1, 1, &img)) return false;
  film_image_free(&img);
  return true;
}

/* ---- bounds -------------------------------------------------------------------- */

static void bounds_case(int nx, int ny, int nz, int ch, const char *filter, const char *wrap,
                        const char *res) {
  char *vals = random_values((size_t)nx * ny * nz * ch, 0.0, 5.0);
  char extra[160];
  snprintf(extra, sizeof extra, "\"ex\": {\"type\": \"extremum_grid\"%s%s},", res ? ", \"resolution\": " : "",
           res ? res : "");
  char *text = grid_scene(ch == 3 ? " \"variant\": \"rgb\"," : "", nx, ny, nz, ch, vals, filter, wrap, extra,
                          0.5, 0, 0, "");
  free(vals);
  scene *s = tsup_load(text, ch == 3 ? "rgb" : "mono");
  free(text);
  REQUIRE(s, "scene");
  REQUIRE(prepare(s), "render");
  const medium *m = (const medium *)find_cls(s, "m", CLS_MEDIUM);
  REQUIRE(m && m->ops->majorant_walk, "the medium and its walk");
  tsup_walk_stats w;
  tsup_walk_check(m, v3(-1.5, -1.5, -1.5), v3(1.5, 1.5, 1.5), 400, &rng, &w);
  long bad = w.bad, pieces = w.pieces, rays = w.rays, order = w.order;
  printf("  %dx%dx%d x%d %s %s res %s: %ld rays, %ld pieces\n", nx, ny, nz, ch, filter, wrap,
         res ? res : "auto", rays, pieces);
  CHECK(rays > 100 && pieces > rays, "too few rays (%ld) or pieces (%ld) to test", rays, pieces);
  CHECK(bad == 0, "%s %s res %s: %ld points with sigma_t above their piece's majorant or below its minorant",
        filter, wrap, res ? res : "auto", bad);
  CHECK(order == 0, "%s %s res %s: %ld pieces out of order", filter, wrap, res ? res : "auto", order);
  scene_free(s);
}

static void test_cells_bound_the_extinction(void) {
  static const char *const filters[] = {"nearest", "trilinear"}, *const wraps[] = {"clamp", "repeat",
                                                                                   "mirror"};
  static const char *const res[] = {"[1, 1, 1]", "[2, 3, 2]", "[5, 7, 4]", "[9, 11, 6]", NULL};
  for (int f = 0; f < 2; f++)
    for (int w = 0; w < 3; w++)
      for (int r = 0; r < 5; r++) bounds_case(5, 7, 4, 1, filters[f], wraps[w], res[r]);
  bounds_case(6, 5, 3, 3, "trilinear", "clamp", "[3, 2, 2]");
  bounds_case(40, 1, 1, 1, "nearest", "clamp", NULL); /* (automatic: 16 x 1 x 1) */
}

/* ---- estimates ------------------------------------------------------------------ */

/* An absorbing 4 x 3 x 6 nearest grid: the column under (tx, ty) is
 * voxel (ix, iy); straight down through the cube (length 2), tau is the
 * sum of its 6 values times 2/6. */
static void test_transmittance_exact(void) {
  enum {
    NX = 4,
    NY = 3,
    NZ = 6,
    REPS = 24
  };
  double v[NZ][NY][NX];
  sbuf d = {0};
  for (int z = 0; z < NZ; z++)
    for (int y = 0; y < NY; y++)
      for (int x = 0; x < NX; x++) {
        v[z][y][x] = (x + y) % 3 == 0 ? 0.0 : 0.2 + 1.3 * urand();
        sb_printf(&d, "%s%.17g", d.n ? ", " : "", v[z][y][x]);
      }
  const double tx = -0.6, ty = 0.1; /* local x 0.2 (ix 0), y 0.55 (iy 1) */
  double tau = 0;
  for (int z = 0; z < NZ; z++) tau += v[z][1][0] * 2.0 / NZ;
  const double want = exp(-tau);
  static const char *const extra[3] = {
      "", "\"ex\": {\"type\": \"extremum_grid\", \"resolution\": [2, 3, 3]}, \"use_rrt\": false,",
      "\"ex\": {\"type\": \"extremum_grid\", \"resolution\": [2, 3, 3]},"};
  static const char *const what[3] = {"global", "extremum_grid, ratio tracking", "extremum_grid, residual"};
  double se_k[3];
  for (int k = 0; k < 3; k++) {
    char *text = grid_scene("", NX, NY, NZ, 1, d.p, "nearest", "clamp", extra[k], 0.0, tx, ty, "");
    scene *s = tsup_load(text, "mono");
    free(text);
    REQUIRE(s, "scene");
    double m = 0, se = 0;
    REQUIRE(tsup_pixel_estimate(s, 64, REPS, &m, &se), "renders");
    printf("  absorbing grid, %s: T %.6f +- %.6f, exact %.6f (tau %.4f)\n", what[k], m, se, want, tau);
    CHECK(fabs(m - want) <= 4 * se + 1e-12, "%s: T %.6g vs exact %.6g beyond 4 sigma (%.3g)", what[k], m,
          want, 4 * se);
    CHECK(se < 0.05 * want, "standard error %.3g too large for a meaningful test", se);
    se_k[k] = se;
    scene_free(s);
  }
  /* the column's cells have a positive minorant: most of tau is the
   * control's, exact */
  CHECK(se_k[2] < 0.75 * se_k[1],
        "residual ratio tracking's error %.3g is not below 3/4 of ratio tracking's %.3g", se_k[2], se_k[1]);
  free(d.p);
}

/* Residual ratio tracking with the medium's global minorant (no extremum):
 * a grid of values in [0.5, 1.5] seen through, against exp(-tau), with
 * use_rrt true (the default) and false. */
static void test_residual_global(void) {
  enum {
    N = 4,
    REPS = 24
  };
  double v[N][N][N];
  sbuf d = {0};
  for (int z = 0; z < N; z++)
    for (int y = 0; y < N; y++)
      for (int x = 0; x < N; x++) {
        v[z][y][x] = 0.5 + urand();
        sb_printf(&d, "%s%.17g", d.n ? ", " : "", v[z][y][x]);
      }
  double tau = 0; /* the column under (0.3, -0.3): local (0.65, 0.35), voxel (2, 1) */
  for (int z = 0; z < N; z++) tau += v[z][1][2] * 2.0 / N;
  const double want = exp(-tau);
  double se_k[2];
  for (int k = 0; k < 2; k++) {
    char *text = grid_scene("", N, N, N, 1, d.p, "nearest", "clamp", k ? "" : "\"use_rrt\": false,", 0.0, 0.3,
                            -0.3, "");
    scene *s = tsup_load(text, "mono");
    free(text);
    REQUIRE(s, "scene");
    double m = 0, se = 0;
    REQUIRE(tsup_pixel_estimate(s, 64, REPS, &m, &se), "renders");
    printf("  grid in [0.5, 1.5], %s: T %.6f +- %.6f, exact %.6f\n",
           k ? "residual (global minorant)" : "ratio", m, se, want);
    CHECK(fabs(m - want) <= 4 * se + 1e-12, "T %.6g vs exact %.6g beyond 4 sigma (%.3g)", m, want, 4 * se);
    se_k[k] = se;
    scene_free(s);
  }
  CHECK(se_k[1] < se_k[0], "residual ratio tracking's error %.3g is not below ratio tracking's %.3g", se_k[1],
        se_k[0]);
  free(d.p);
}

/* A scattering grid's film mean, global against extremum_grid. */
static void scatter_case(const char *what, const char *variant, const char *variant_json, int ch,
                         const char *data, int nx, int ny, int nz, const char *vol_extra, int bundle) {
  enum {
    REPS = 24
  };
  double m[2], se[2];
  for (int k = 0; k < 2; k++) {
    char extra[400];
    snprintf(extra, sizeof extra, "%s",
             k ? "\"ex\": {\"type\": \"extremum_grid\", \"resolution\": [3, 2, 4]}," : "");
    char *text = grid_scene(variant_json, nx, ny, nz, ch, data, "trilinear", "clamp", extra, 0.8, 0.2, -0.3,
                            vol_extra);
    scene *s = tsup_load(text, variant);
    free(text);
    REQUIRE(s, "scene");
    double sum = 0, sum2 = 0;
    for (int r = 1; r <= REPS; r++) {
      render_opts o = {.size = sizeof o, .spp = 256, .seed = (uint64_t)r, .threads = 0, .wavelength = 550};
      film_image img[4];
      rsw_err err = {0};
      if (bundle) {
        o.bundle = bundle;
        for (int b = 0; b < bundle; b++) o.bundle_wl[b] = 500 + 25 * b;
      }
      REQUIRE(render_sensor_bundle(s, &o, img, NULL, &err) == RSW_OK, "render");
      double v = 0;
      for (int b = 0; b < (bundle ? bundle : 1); b++) {
        v += img[b].data[0];
        film_image_free(&img[b]);
      }
      sum += v, sum2 += v * v;
    }
    m[k] = sum / REPS;
    se[k] = sqrt(fmax(sum2 / REPS - m[k] * m[k], 0) / (REPS - 1));
    scene_free(s);
  }
  double z = (m[1] - m[0]) / sqrt(se[0] * se[0] + se[1] * se[1]);
  printf("  %s: global %.5f +- %.5f, extremum_grid %.5f +- %.5f (%.2f sigma)\n", what, m[0], se[0], m[1],
         se[1], z);
  CHECK(fabs(z) <= 4, "%s: film means differ by %.2f standard errors", what, z);
  CHECK(se[0] < 0.02 * m[0], "%s: standard error %.3g too large for a meaningful test", what, se[0]);
}

static void test_scattering_agrees(void) {
  char *v1 = random_values(5 * 4 * 6, 0.0, 3.0), *v3 = random_values(5 * 4 * 6 * 3, 0.0, 3.0);
  scatter_case("mono, scattering grid", "mono", "", 1, v1, 5, 4, 6, "", 0);
  scatter_case("rgb, 3-channel grid", "rgb", " \"variant\": \"rgb\",", 3, v3, 5, 4, 6, "", 0);
  free(v1), free(v3);
  /* A tabulated grid (a value per cell at 450 and 650 nm): a bundle's
   * pages differ, and the pages' tracks share one walk. */
  sbuf d = {0};
  for (int i = 0; i < 5 * 4 * 6; i++) {
    double a = 3.0 * urand();
    sb_printf(&d, "%s%.17g, %.17g", i ? ", " : "", a, 0.4 * a);
  }
  scatter_case("mono bundle of 4, tabulated grid", "mono", "", 1, d.p, 5, 4, 6,
               "\"wavelengths\": [450, 650],", 4);
  free(d.p);
}

/* ---- a dense cell ---------------------------------------------------------------- */

/* sigma_t 1e12, 0.001, 0.001 along x (nearest), absorbing: the sensor
 * looks down the third column (local x 0.9), tau 0.002. The global
 * majorant (1e12) gives its tracks up (test_dense_media.c); with a cell
 * per voxel, none is, and T is exp(-0.002). */
static void test_dense_cell_resolved(void) {
  char *text =
      grid_scene("", 3, 1, 1, 1, "1e12, 0.001, 0.001", "nearest", "clamp",
                 "\"ex\": {\"type\": \"extremum_grid\", \"resolution\": [3, 1, 1]},", 0.0, 0.8, 0.0, "");
  scene *s = tsup_load(text, "mono");
  free(text);
  REQUIRE(s, "scene");
  render_opts o = {.size = sizeof o, .spp = 4096, .seed = 1, .threads = 0};
  film_image img;
  render_result_stats rs = {0};
  rsw_err err = {0};
  REQUIRE(render_sensor(s, &o, &img, &rs, &err) == RSW_OK, "render");
  double v = img.data[0], want = exp(-0.002);
  printf("  T %.9f (exact %.9f), %llu unresolved\n", v, want, (unsigned long long)rs.rays.unresolved);
  CHECK(rs.rays.unresolved == 0, "%llu tracks given up (want none)", (unsigned long long)rs.rays.unresolved);
  /* (ratio tracking at a majorant equal to sigma_t: a path's T is 1, or
   * about 2^-40 when it takes a tentative collision (probability 1 - T):
   * standard error sqrt(T (1 - T) / spp); residual ratio tracking, the
   * default, with a control equal to sigma_t: exact) */
  double se = sqrt(want * (1 - want) / 4096);
  CHECK(fabs(v - want) <= 4 * se, "T %.9g vs exact %.9g beyond 4 sigma (%.3g)", v, want, 4 * se);
  film_image_free(&img);
  scene_free(s);
}

/* ---- a cloud ---------------------------------------------------------------------- */

/* tsup_cloud_scene at 24^3: the film mean with extremum_grid [8, 8, 8]
 * equals the global majorant's within 4 standard errors (16 renders
 * each); the time of each is printed (the speed is `make bench`'s
 * media_cloud, not asserted here). */
static void test_cloud_agrees(void) {
  enum {
    REPS = 16
  };
  const char *ex[2] = {"", "\"ex\": {\"type\": \"extremum_grid\", \"resolution\": [8, 8, 8]},"};
  double m[2], se[2], secs[2];
  for (int k = 0; k < 2; k++) {
    char *text = tsup_cloud_scene(24, ex[k], 16);
    scene *s = tsup_load(text, "mono");
    free(text);
    REQUIRE(s, "scene");
    double sum = 0, sum2 = 0;
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (int r = 1; r <= REPS; r++) {
      film_image img;
      REQUIRE(tsup_render(s, 16, (uint64_t)r, 0, &img), "render");
      double mean, sem;
      tsup_stats(&img, 0, &mean, &sem);
      film_image_free(&img);
      sum += mean, sum2 += mean * mean;
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    secs[k] = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    m[k] = sum / REPS;
    se[k] = sqrt(fmax(sum2 / REPS - m[k] * m[k], 0) / (REPS - 1));
    scene_free(s);
  }
  double z = (m[1] - m[0]) / sqrt(se[0] * se[0] + se[1] * se[1]);
  printf("  cloud 24^3: global %.5f +- %.5f in %.2f s, extremum_grid %.5f +- %.5f in %.2f s (%.2f sigma)\n",
         m[0], se[0], secs[0], m[1], se[1], secs[1], z);
  CHECK(fabs(z) <= 4, "cloud: film means differ by %.2f standard errors", z);
  CHECK(se[0] < 0.02 * m[0], "cloud: standard error %.3g too large for a meaningful test", se[0]);
}

/* ---- refusals --------------------------------------------------------------------- */

static void test_refusals(void) {
  static const char *const bad[] = {
      "{\"type\": \"extremum_grid\", \"resolution\": [0, 4, 4]}",
      "{\"type\": \"extremum_grid\", \"resolution\": [2.5, 4, 4]}",
      "{\"type\": \"extremum_grid\", \"resolution\": [-1, 4, 4]}",
      "{\"type\": \"extremum_grid\", \"resolution\": [5000, 4, 4]}",
      "{\"type\": \"extremum_grid\", \"resolution\": [4, 4, 4], \"volume\": 1}",
      "{\"type\": \"extremum_gird\"}",
  };
  /* (a whole scene but for the extremum: a refusal is the extremum's) */
  char *fmt =
      grid_scene("", 2, 2, 2, 1, "1, 2, 3, 4, 5, 6, 7, 8", "nearest", "clamp", "\"ex\": %s,", 0.5, 0, 0, "");
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
    CHECK(tsup_refused(fmt, bad[i]), "refused: %s", bad[i]);
  /* the message names the key */
  char text[1024];
  snprintf(text, sizeof text, fmt, bad[0]);
  rsw_err err = {0};
  scene *s = NULL;
  CHECK(scene_load_memory(text, strlen(text), "bad.json", false, NULL, &s, &err) != RSW_OK,
        "[0, 4, 4] taken");
  char buf[1200];
  rsw_err_format(&err, buf, sizeof buf);
  printf("  %s\n", buf);
  CHECK(strstr(buf, "/m/ex/resolution") && strstr(buf, "1 to 4096"), "the error names the key and range: %s",
        buf);
  scene_free(s);
  /* an extremum on a medium that takes none (the same scene with a
   * homogeneous medium loads) */
  const char *hom = "{\"type\": \"scene\", \"box\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
                    " \"interior\": {\"type\": \"homogeneous\"%s}}}";
  CHECK(!tsup_refused(hom, ""), "the homogeneous scene is refused");
  CHECK(tsup_refused(hom, ", \"ex\": {\"type\": \"extremum_grid\"}"),
        "an extremum_grid on a homogeneous medium was taken");
  /* and the two accepted forms */
  CHECK(!tsup_refused(fmt, "{\"type\": \"extremum_grid\"}"), "extremum_grid without resolution refused");
  CHECK(!tsup_refused(fmt, "{\"type\": \"extremum_global\"}"), "extremum_global refused");
  CHECK(!tsup_refused(fmt, "{\"type\": \"extremum_grid\", \"resolution\": [0, 0, 0]}"), "[0, 0, 0] refused");
  free(fmt);
}

int main(void) {
  RSW_TEST_RUN(test_cells_bound_the_extinction);
  RSW_TEST_RUN(test_transmittance_exact);
  RSW_TEST_RUN(test_residual_global);
  RSW_TEST_RUN(test_scattering_agrees);
  RSW_TEST_RUN(test_dense_cell_resolved);
  RSW_TEST_RUN(test_cloud_agrees);
  RSW_TEST_RUN(test_refusals);
  RSW_TEST_END("test_majorant_grid");
}
