/* The periodic boundary at low sun and grazing view (issue 11, item 2).
 *
 *  - A leaf sheet (bilambertian r, t) at height h over a Lambertian soil
 *    rho_s, both exactly covering a periodic cell of a x b: an infinite
 *    sheet over an infinite soil, so BRF = r + t^2 rho_s / (1 - r rho_s)
 *    at every sun zenith (all surfaces Lambertian: the radiance above is
 *    isotropic, L = BRF E cos(theta_s) / pi). Checked within 3 standard
 *    errors at sun zeniths 0 ... 85 degrees in cells of several aspect
 *    ratios (hdistant, target = the cell's top). Before the fix the sun's
 *    shadow ray stopped after 2 max(R, |p - c|) with R the radius of one
 *    column, so the soil was lit through the sheet as soon as the
 *    soil-to-sheet path exceeded 2R (2x2x1 cell: from 70.5 degrees).
 *  - The same scene seen by distant sensors without a target (and with a
 *    point target on the soil) at grazing view: their origins must lie
 *    outside the geometry's slab, not only outside one column's bounding
 *    sphere.
 *  - A plot with leaves under the periodic boundary equals the plot with
 *    its explicit copies around it at sun zeniths 80 and 85 degrees
 *    (distant sensor at nadir, target = the central plot), within 3 sigma.
 *  - Area lamps under the periodic boundary equal their explicit copies
 *    (multiple importance sampling of copies reached through the boundary).
 *  - The tracer: a nearly horizontal ray inside the slab ends by leaving
 *    it (exact) after many walls; one within the guard's reach of
 *    horizontal is unresolved (never "unoccluded").
 * Fixed seeds; a few seconds in all. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../server/kernel/core/rng.h"
#include "../../../server/kernel/core/transform.h"
#include "../../../server/kernel/scene/periodic.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define PI     3.14159265358979323846
#define R_LEAF 0.45
#define T_LEAF 0.4
#define RHO_S  0.3

static double closed_form(void) {
  return R_LEAF + T_LEAF * T_LEAF * RHO_S / (1.0 - R_LEAF * RHO_S);
}

/* The sun (propagation direction) at zenith th (degrees), azimuth 30. */
static vec3 sun_dir(double th) {
  double t = th * PI / 180.0, p = 30.0 * PI / 180.0;
  return v3(-sin(t) * cos(p), -sin(t) * sin(p), -cos(t));
}

/* Leaf sheet at z = h over soil at z = 0, both covering the cell
 * [-a, a] x [-b, b], under the periodic boundary; `sens` is the sensor's
 * JSON. */
static scene *sheet_scene(double a, double b, double h, double sun_zen, const char *sens) {
  char buf[4096];
  vec3 d = sun_dir(sun_zen);
  snprintf(buf, sizeof buf,
           "{\"type\": \"scene\", \"variant\": \"mono\","
           " \"sensor\": %s,"
           " \"integrator\": {\"type\": \"path\"},"
           " \"sun\": {\"type\": \"directional\", \"direction\": [%.17g, %.17g, %.17g], \"irradiance\": 1},"
           " \"sheet\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [%g, %g, 1]}, {\"translate\": "
           "[0, 0, %g]}],"
           "   \"bsdf\": {\"type\": \"bilambertian\", \"reflectance\": %g, \"transmittance\": %g}},"
           " \"soil\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [%g, %g, 1]}],"
           "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": %g}},"
           " \"cell\": {\"type\": \"periodic\", \"min\": [%g, %g], \"max\": [%g, %g]}}",
           sens, d.x, d.y, d.z, a, b, h, R_LEAF, T_LEAF, a, b, RHO_S, -a, -b, a, b);
  return tsup_load(buf, NULL);
}

/* BRF from a film of radiance (mean and sem over pixels). */
static bool film_brf(scene *s, uint32_t spp, uint64_t seed, double sun_zen, double *brf, double *sig,
                     uint64_t *unresolved) {
  film_image img = {0};
  rsw_err err = {0};
  render_opts o = {.size = sizeof o, .spp = spp, .seed = seed, .threads = 2};
  render_result_stats st = {0};
  if (render_sensor(s, &o, &img, &st, &err)) return false;
  double m, sem;
  tsup_stats(&img, 0, &m, &sem);
  double k = PI / cos(sun_zen * PI / 180.0); /* E = 1 */
  *brf = m * k, *sig = sem * k;
  if (unresolved) *unresolved = st.rays.unresolved;
  film_image_free(&img);
  return true;
}

static void check_brf(const char *what, double brf, double sig) {
  double want = closed_form();
  CHECK(fabs(brf - want) <= 3 * sig, "%s: BRF %.5f vs closed form %.5f (3 sigma = %.5f)", what, brf, want,
        3 * sig);
  CHECK(sig < 0.01 * want, "%s: sigma %.3g too large for a meaningful test", what, sig);
}

static void test_sheet_over_soil_low_sun(void) {
  const double cells[][3] = {{1, 1, 1}, {5, 5, 1}, {0.5, 0.5, 5}, {2, 0.5, 2}}; /* half-widths, height */
  const double zen[] = {0, 30, 60, 70, 75, 80, 85};
  for (size_t c = 0; c < sizeof cells / sizeof cells[0]; c++) {
    double a = cells[c][0], b = cells[c][1], h = cells[c][2];
    char sens[1024];
    /* The target is the cell's top: origins 2R above it, outside the slab. */
    snprintf(
        sens, sizeof sens,
        "{\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\","
        " \"to_world\": [{\"scale\": [%g, %g, 1]}, {\"translate\": [0, 0, %g]}]},"
        " \"sampler\": {\"type\": \"independent\", \"sample_count\": 128},"
        " \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"box\"}}}",
        a, b, h);
    for (size_t k = 0; k < sizeof zen / sizeof zen[0]; k++) {
      scene *s = sheet_scene(a, b, h, zen[k], sens);
      REQUIRE(s, "scene loads");
      double brf, sig;
      uint64_t unres;
      REQUIRE(film_brf(s, 0, 100 + k, zen[k], &brf, &sig, &unres), "renders");
      char what[128];
      snprintf(what, sizeof what, "cell %gx%gx%g, sun %g deg", 2 * a, 2 * b, h, zen[k]);
      if (c == 0 && (zen[k] == 70 || zen[k] == 80))
        printf("  %s: BRF %.5f +- %.5f (closed form %.5f)\n", what, brf, sig, closed_form());
      check_brf(what, brf, sig);
      CHECK(unres == 0, "%s: %llu unresolved rays", what, (unsigned long long)unres);
      scene_free(s);
    }
  }
}

/* Distant sensors in a periodic scene: no target (the cell is sampled)
 * and a point target on the soil, at grazing view. */
static void test_distant_sensors_grazing_view(void) {
  const double a = 1, b = 1, h = 1, zen = 40;
  char sens[1024];
  /* hdistant without a target: every viewing direction of the hemisphere. */
  snprintf(
      sens, sizeof sens,
      "{\"type\": \"hdistant\", \"sampler\": {\"type\": \"independent\", \"sample_count\": 128},"
      " \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"box\"}}}");
  scene *s = sheet_scene(a, b, h, zen, sens);
  REQUIRE(s, "scene loads");
  double brf, sig;
  REQUIRE(film_brf(s, 0, 31, zen, &brf, &sig, NULL), "renders");
  printf("  hdistant, no target: BRF %.5f +- %.5f\n", brf, sig);
  check_brf("hdistant without target", brf, sig);
  scene_free(s);

  /* distant (one pixel) at 80 degrees view, without a target and with a
   * point target on the soil: mean and sem over seeds. */
  const char *targets[2] = {"", ", \"target\": [0.3, -0.2, 0]"};
  for (int t = 0; t < 2; t++) {
    double v = 80 * PI / 180;
    snprintf(
        sens, sizeof sens,
        "{\"type\": \"distant\", \"direction\": [%.17g, 0.1, %.17g]%s,"
        " \"sampler\": {\"type\": \"independent\", \"sample_count\": 256},"
        " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}}",
        -sin(v), -cos(v), targets[t]);
    s = sheet_scene(a, b, h, zen, sens);
    REQUIRE(s, "scene loads");
    enum {
      NS = 12
    };
    double sum = 0, sum2 = 0;
    for (int k = 0; k < NS; k++) {
      double x, e;
      REQUIRE(film_brf(s, 0, 500 + k, zen, &x, &e, NULL), "renders");
      sum += x, sum2 += x * x;
    }
    double m = sum / NS, sd = sqrt(fmax(0, (sum2 - sum * sum / NS) / (NS - 1)) / NS);
    printf("  distant at 80 deg, %s: BRF %.5f +- %.5f\n", t ? "point target on the soil" : "no target", m,
           sd);
    check_brf(t ? "distant, point target on the soil" : "distant, no target", m, sd);
    scene_free(s);
  }
}

/* ---- a plot with leaves: periodic vs explicit copies --------------------- */

#define PLOT  2.0 /* the plot is [-2, 2]^2 */
#define NLEAF 24

/* K: copies on each side (0 = the plot alone). */
static void write_plot_list(const char *path, int K) {
  static double m[NLEAF][16];
  tsup_random_leaves(m, NLEAF, 11, 5, 1.7, 0.3, 1.0, 0.3);
  FILE *f = fopen(path, "w");
  for (int cx = -K; cx <= K; cx++)
    for (int cy = -K; cy <= K; cy++)
      for (int i = 0; i < NLEAF; i++) {
        double q[16];
        memcpy(q, m[i], sizeof q);
        q[3] += 2 * PLOT * cx, q[7] += 2 * PLOT * cy;
        for (int k = 0; k < 16; k++) fprintf(f, "%s%.17g", k ? " " : "", q[k]);
        fprintf(f, "\n");
      }
  fclose(f);
}

static scene *plot_scene(int K, bool periodic, double sun_zen, const char *list) {
  char buf[4096];
  vec3 d = sun_dir(sun_zen);
  double half = PLOT * (2 * K + 1);
  int n = snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"cam\": {\"type\": \"distant\", \"direction\": [0, 0, -1],"
      "   \"target\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [%g, %g, 1]}]},"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 512},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [%.17g, %.17g, %.17g], \"irradiance\": 1},"
      " \"soil\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [%g, %g, 1]}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.3}},"
      " \"leaf\": {\"type\": \"shapegroup\", \"d\": {\"type\": \"disk\","
      "   \"bsdf\": {\"type\": \"bilambertian\", \"reflectance\": 0.45, \"transmittance\": 0.4}}},"
      " \"canopy\": {\"type\": \"instancelist\", \"filename\": \"%s\","
      "   \"shapegroup\": {\"type\": \"ref\", \"id\": \"leaf\"}}",
      PLOT, PLOT, d.x, d.y, d.z, half, half, list);
  if (periodic)
    n += snprintf(buf + n, sizeof buf - n,
                  ", \"cell\": {\"type\": \"periodic\", \"min\": [%g, %g], \"max\": [%g, %g]}", -PLOT, -PLOT,
                  PLOT, PLOT);
  snprintf(buf + n, sizeof buf - n, "}");
  return tsup_load(buf, NULL);
}

#define NSEEDS 10
static bool seed_stats(scene *s, uint64_t seed0, double *mean, double *sem) {
  double sum = 0, sum2 = 0;
  for (int k = 0; k < NSEEDS; k++) {
    film_image img = {0};
    if (!tsup_render(s, 0, seed0 + k, 2, &img)) return false;
    sum += img.data[0], sum2 += (double)img.data[0] * img.data[0];
    film_image_free(&img);
  }
  *mean = sum / NSEEDS;
  *sem = sqrt(fmax(0, (sum2 - sum * sum / NSEEDS) / (NSEEDS - 1)) / NSEEDS);
  return true;
}

static void test_periodic_equals_copies_low_sun(void) {
  char p1[] = "/tmp/rsw_psun1_XXXXXX", pk[] = "/tmp/rsw_psunk_XXXXXX";
  int f1 = mkstemp(p1), fk = mkstemp(pk);
  REQUIRE(f1 >= 0 && fk >= 0, "mkstemp");
  close(f1), close(fk);
  /* Leaves reach z = 1.6: at 85 degrees a sun ray from the soil climbs
   * out of the canopy within 1.6 tan(85) = 18.3 m, inside 5 copies on
   * each side of the 4 m plot. */
  const int K = 5;
  write_plot_list(p1, 0);
  write_plot_list(pk, K);
  const double zen[2] = {80, 85};
  for (int a = 0; a < 2; a++) {
    scene *sp = plot_scene(0, true, zen[a], p1), *sc = plot_scene(K, false, zen[a], pk);
    REQUIRE(sp && sc, "plot scenes load");
    double mp, ep, mc, ec;
    REQUIRE(seed_stats(sp, 1000, &mp, &ep) && seed_stats(sc, 2000, &mc, &ec), "renders");
    double sig = sqrt(ep * ep + ec * ec);
    printf("  sun %2.0f deg: periodic %.6f +- %.6f, %dx%d copies %.6f +- %.6f\n", zen[a], mp, ep, 2 * K + 1,
           2 * K + 1, mc, ec);
    CHECK(mc > 0.001, "the plot is lit (%g)", mc);
    CHECK(fabs(mp - mc) <= 3 * sig, "sun %.0f deg: periodic %.6f vs copies %.6f (3 sigma = %.6f)", zen[a], mp,
          mc, 3 * sig);
    CHECK(sig < 0.03 * mc, "sun %.0f deg: sigma %.3g too large", zen[a], sig);
    scene_free(sp), scene_free(sc);
  }
  unlink(p1), unlink(pk);
}

/* ---- an area emitter under the periodic boundary ---------------------------
 * Small down-facing lamps (0.8 m squares at z = 0.5, one per 2 m cell) over
 * a Lambertian soil, seen from above at nadir: the periodic cell against
 * 13 x 13 explicit lamps (the lamps beyond add < 0.1%). Next-event
 * estimation samples only the lamp in the cell; a BSDF-sampled ray that
 * reaches a neighbour's copy through the boundary used to get the MIS
 * weight of a strategy that never samples it (the cell was 27% dark). */
static scene *lamp_scene(bool periodic, int K) {
  static char buf[100000];
  int n = snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"sensor\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": {\"type\": \"rectangle\"},"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 8192},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\", \"max_depth\": 3},"
      " \"soil\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [%d, %d, 1]}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}",
      2 * K + 1, 2 * K + 1);
  for (int i = -K; i <= K; i++)
    for (int j = -K; j <= K; j++)
      n += snprintf(buf + n, sizeof buf - n,
                    ", \"lamp_%d_%d\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 0.4},"
                    " {\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}}, {\"translate\": [%d, %d, 0.5]}],"
                    " \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0}, \"emitter\": {\"type\": "
                    "\"area\", \"radiance\": 1}}",
                    i + K, j + K, 2 * i, 2 * j);
  if (periodic)
    n += snprintf(buf + n, sizeof buf - n,
                  ", \"cell\": {\"type\": \"periodic\", \"min\": [-1, -1], \"max\": [1, 1]}");
  snprintf(buf + n, sizeof buf - n, "}");
  return tsup_load(buf, NULL);
}

static void test_area_emitter_equals_copies(void) {
  scene *sp = lamp_scene(true, 0), *sc = lamp_scene(false, 6);
  REQUIRE(sp && sc, "lamp scenes load");
  double mp, ep, mc, ec;
  REQUIRE(seed_stats(sp, 3000, &mp, &ep) && seed_stats(sc, 4000, &mc, &ec), "renders");
  double sig = sqrt(ep * ep + ec * ec);
  printf("  area lamps: periodic %.5f +- %.5f, 13x13 lamps %.5f +- %.5f\n", mp, ep, mc, ec);
  CHECK(fabs(mp - mc) <= 3 * sig, "area lamps: periodic %.5f vs copies %.5f (3 sigma = %.5f)", mp, mc,
        3 * sig);
  CHECK(sig < 0.02 * mc, "area lamps: sigma %.3g too large", sig);
  scene_free(sp), scene_free(sc);
}

/* ---- the early decision: rays that can neither leave the slab nor hit ----
 * A horizontal sun's shadow rays (and a distant sensor looking
 * horizontally) used to walk all 65,536 walls, one Embree query each,
 * before being reported unresolved. Now a ray that provably can neither
 * leave the slab nor hit a shape within the wall limit is classified at
 * once (scene/periodic.c never_resolves). Checked: the query count of
 * such rays (before: 65,536 each), and that the classification (and any
 * hit) equals the walk's (the decision switched off) for directions
 * swept across the threshold, from origins on and between the surfaces,
 * in the sheet scene and in a canopy of leaves (where a level ray hits a
 * leaf and must still do so). */
static int cmp_walk(scene *s, vec3 o, vec3 d, unsigned long *q_on, unsigned long *q_off) {
  trace_result occ[2], tr[2];
  double dist[2] = {0, 0};
  for (int k = 0; k < 2; k++) {
    periodic_set_early_out(k == 0);
    unsigned long q0 = periodic_query_count();
    ray3 r = {o, d, 0, INFINITY};
    occ[k] = scene_occluded(s, &r);
    accel_hit h;
    double off;
    tr[k] = scene_trace(s, &r, &h, &off);
    if (tr[k] == TRACE_HIT) dist[k] = off + h.t;
    *(k == 0 ? q_on : q_off) += periodic_query_count() - q0;
  }
  periodic_set_early_out(true);
  CHECK(occ[0] == occ[1] && tr[0] == tr[1] && dist[0] == dist[1],
        "o (%g, %g, %.9g) d (%g, %g, %.6g): early decision occluded %d trace %d (%.9g) vs walk %d %d (%.9g)",
        o.x, o.y, o.z, d.x, d.y, d.z, occ[0], tr[0], dist[0], occ[1], tr[1], dist[1]);
  return tr[1];
}

static void test_early_unresolved(void) {
  const char *sens =
      "{\"type\": \"distant\", \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}";
  scene *s = sheet_scene(1, 1, 1, 0, sens); /* cell [-1, 1]^2, sheet at z = 1, soil at z = 0 */
  REQUIRE(s, "scene loads");
  /* Query counts of level and nearly level shadow rays off the soil, off
   * either side of the sheet (origins as spawn_ray puts them: 1e-6 off
   * the surface, moving away or level) and mid-way. */
  const struct {
    vec3 o, d;
  } lv[] = {
      {{0.1, 0.2, 1e-6}, {1, 0, 0}},
      {{0.1, 0.2, 1e-6}, {-1, 0, 1e-7}},
      {{0.1, 0.2, 1e-6}, {0.6, 0.8, 0}},
      {{0.1, 0.2, 1 + 1e-6}, {1, 0, 0}},
      {{0.1, 0.2, 1 + 1e-6}, {0.6, 0.8, 0}},
      {{0.1, 0.2, 1 - 1e-6}, {0, -1, 0}},
      {{0.1, 0.2, 1 - 1e-6}, {0.6, -0.8, -1e-9}},
      {{-0.7, 0.9, 0.5}, {1, 0, 0}},
      {{-0.7, 0.9, 0.5}, {-0.6, 0.8, 1e-9}},
      {{-0.7, 0.9, 0.5}, {0.8, 0.6, -1e-9}},
  };
  unsigned long q_on = 0, q_off = 0;
  for (size_t i = 0; i < sizeof lv / sizeof lv[0]; i++) {
    unsigned long a = 0, b = 0;
    int t = cmp_walk(s, lv[i].o, lv[i].d, &a, &b);
    CHECK(t == TRACE_UNRESOLVED, "o z %.9g d (%g, %g, %g): unresolved (%d)", lv[i].o.z, lv[i].d.x, lv[i].d.y,
          lv[i].d.z, t);
    CHECK(a == 0, "o z %.9g d (%g, %g, %g): %lu Embree queries with the early decision (want 0)", lv[i].o.z,
          lv[i].d.x, lv[i].d.y, lv[i].d.z, a);
    CHECK(b == 2ul * 65536, "walk: %lu queries (want 2 x 65536)", b);
    q_on += a, q_off += b;
  }
  printf("  level rays: %lu Embree queries (walk: %lu)\n", q_on, q_off);

  /* Directions swept across the threshold: elevation e * e0 where e0 is
   * where the exact ray meets the plane it heads for after 65,536
   * crossings of the nearest wall (a hit on the sheet or soil, or leaving
   * the slab). */
  struct {
    vec3 o;
    double dz_sign, gap;
  } starts[] = {
      {v3(0.1, 0.2, 1e-6), 1, 1 - 1e-6},            /* off the soil, up to the sheet */
      {v3(0.3, -0.4, 0.5), 1, 0.5},                 /* mid-way, up to the sheet */
      {v3(0.3, -0.4, 0.5), -1, 0.5},                /* mid-way, down to the soil */
      {v3(-0.2, 0.1, 1 + 1e-6), 1, 1.02e-4 - 1e-6}, /* off the sheet, up out of the slab (margin 1.02e-4) */
      {v3(-0.2, 0.1, -1e-6), -1, 1.02e-4 - 1e-6},   /* under the soil, down out of the slab */
  };
  const double az[] = {0, 37, 90};
  const double fac[] = {0, 0.3, 0.49, 0.51, 0.9, 0.999, 1, 1.001, 1.1, 2};
  int n_unres = 0, n_other = 0, n_early = 0;
  q_on = q_off = 0;
  for (size_t i = 0; i < sizeof starts / sizeof starts[0]; i++)
    for (size_t a = 0; a < sizeof az / sizeof az[0]; a++)
      for (size_t f = 0; f < sizeof fac / sizeof fac[0]; f++) {
        double p = az[a] * PI / 180, cx = cos(p), cy = sin(p);
        double c = fmin(fabs(cx) > 0 ? 2 / fabs(cx) : INFINITY, fabs(cy) > 1e-12 ? 2 / fabs(cy) : INFINITY);
        double e = starts[i].gap / (65536.0 * c) * fac[f];
        vec3 d = v3(cx, fabs(cy) > 1e-12 ? cy : 0, starts[i].dz_sign * e);
        unsigned long q = q_on;
        int t = cmp_walk(s, starts[i].o, d, &q_on, &q_off);
        n_early += q_on == q;
        if (t == TRACE_UNRESOLVED)
          n_unres++;
        else
          n_other++;
      }
  printf("  threshold sweep: %d unresolved (%d decided early), %d hit or left the slab; %lu queries (walk: "
         "%lu)\n",
         n_unres, n_early, n_other, q_on, q_off);
  CHECK(n_unres > 30 && n_other > 30 && n_early > 30, "the sweep straddles the threshold (%d, %d, %d early)",
        n_unres, n_other, n_early);
  scene_free(s);

  /* Inside a canopy (the leaves plot): a level ray through the leaf layer
   * is not decided early; it hits a leaf, as the walk does. */
  char p1[] = "/tmp/rsw_pearly_XXXXXX";
  int f1 = mkstemp(p1);
  REQUIRE(f1 >= 0, "mkstemp");
  close(f1);
  write_plot_list(p1, 0);
  scene *sp = plot_scene(0, true, 30, p1);
  REQUIRE(sp, "plot scene loads");
  int hits = 0;
  q_on = q_off = 0;
  for (int k = 0; k < 8; k++) {
    double p = (10 + 40 * k) * PI / 180;
    int t = cmp_walk(sp, v3(0.1 * k - 0.3, 0.2, 0.5 + 0.1 * k), v3(cos(p), sin(p), 0), &q_on, &q_off);
    hits += t == TRACE_HIT;
  }
  /* Level rays off the soil, under the lowest leaf: decided early (the
   * soil lies behind them, the leaves above their level); both agree. */
  for (int k = 0; k < 4; k++) {
    double p = (20 + 90 * k) * PI / 180;
    cmp_walk(sp, v3(0.5, -0.5, 1e-6), v3(cos(p), sin(p), 0), &q_on, &q_off);
  }
  printf("  canopy: %d of 8 level rays hit a leaf; %lu queries (walk: %lu)\n", hits, q_on, q_off);
  CHECK(hits >= 6, "level rays through the canopy hit leaves (%d of 8)", hits);
  scene_free(sp);
  unlink(p1);
}

/* ---- a radiancemeter far outside the column ---------------------------------
 * Column [-1, 1]^2, Lambertian soil (rho 0.5) at z = 0 under an overhead
 * sun of irradiance 1: L = rho E / pi everywhere above the soil. A meter
 * 1 cm above the soil looking down at x = 0.3 and at x = 200000.3 (the
 * same point modulo the period) must read the same. Before the fix its
 * nudge along the view direction was sized by the unwrapped origin
 * (4.8 cm at 2e5 m from the frame origin), which put the origin under the
 * soil: 0 instead of 0.159155. */
static void test_radiancemeter_outside_column(void) {
  const double xs[] = {0.3, 200000.3, -199999.7, 0.3};
  const double ys[] = {0.0, 0.0, 0.0, -300000.0};
  const char *kinds[] = {"radiancemeter", "mradiancemeter"};
  for (int k = 0; k < 2; k++)
    for (size_t i = 0; i < sizeof xs / sizeof xs[0]; i++) {
      char buf[2048], sens[512];
      if (k == 0)
        snprintf(sens, sizeof sens,
                 "{\"type\": \"radiancemeter\", \"origin\": [%.17g, %.17g, 0.01], \"direction\": [0, 0, -1],"
                 " \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
                 " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}",
                 xs[i], ys[i]);
      else
        snprintf(
            sens, sizeof sens,
            "{\"type\": \"mradiancemeter\", \"origins\": \"%.17g, %.17g, 0.01\", \"directions\": \"0, 0, "
            "-1\", \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
            " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}",
            xs[i], ys[i]);
      snprintf(
          buf, sizeof buf,
          "{\"type\": \"scene\", \"variant\": \"mono\", \"sensor\": %s,"
          " \"integrator\": {\"type\": \"path\"},"
          " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1},"
          " \"soil\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}},"
          " \"cell\": {\"type\": \"periodic\", \"min\": [-1, -1], \"max\": [1, 1]}}",
          sens);
      scene *s = tsup_load(buf, NULL);
      REQUIRE(s, "%s scene loads", kinds[k]);
      film_image img = {0};
      REQUIRE(tsup_render(s, 4, 7, 1, &img), "renders");
      double want = 0.5 / PI;
      CHECK(fabs(img.data[0] - want) <= 1e-5, "%s at (%.1f, %.1f, 0.01): L %.6f vs rho E / pi = %.6f",
            kinds[k], xs[i], ys[i], img.data[0], want);
      film_image_free(&img);
      scene_free(s);
    }
}

/* ---- the tracer ------------------------------------------------------------ */

static void test_tracer_grazing(void) {
  const char *sens =
      "{\"type\": \"distant\", \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}";
  scene *s = sheet_scene(1, 1, 1, 0, sens);
  REQUIRE(s, "scene loads");
  /* From just above the soil, 89.9 degrees from the zenith: ~573 m and
   * ~1000 walls to the sheet, which blocks it. */
  double t = 89.9 * PI / 180;
  ray3 up = {v3(0.1, 0.2, 1e-3), v3(sin(t) * 0.6, sin(t) * 0.8, cos(t)), 0, INFINITY};
  CHECK(scene_occluded(s, &up) == TRACE_HIT, "grazing ray under the sheet is blocked by it");
  accel_hit h;
  double off;
  ray3 r = up;
  CHECK(scene_trace(s, &r, &h, &off) == TRACE_HIT, "grazing ray under the sheet hits it");
  CHECK(fabs(off + h.t - (1 - 1e-3) / cos(t)) < 1e-6 * (1 / cos(t)), "hit distance %.9g vs %.9g", off + h.t,
        (1 - 1e-3) / cos(t));
  /* Just above the sheet going up: escapes after a few walls. */
  ray3 above = {v3(0.1, 0.2, 1.001), up.d, 0, INFINITY};
  CHECK(scene_occluded(s, &above) == TRACE_MISS, "ray above the sheet escapes");
  /* Origin far above, grazing down: moved to the slab, then hits the
   * sheet; the distance is along the original ray. */
  ray3 down = {v3(0.3, -0.4, 50.0), v3(0.6 * sin(t), 0.8 * sin(t), -cos(t)), 0, INFINITY};
  r = down;
  CHECK(scene_trace(s, &r, &h, &off) == TRACE_HIT, "ray from far above hits the sheet");
  CHECK(fabs(off + h.t - 49.0 / cos(t)) < 1e-6 * (49.0 / cos(t)), "distance %.9g vs %.9g", off + h.t,
        49.0 / cos(t));
  /* A segment that ends before the slab hits nothing. */
  down.tmax = 40.0 / cos(t);
  CHECK(scene_occluded(s, &down) == TRACE_MISS, "short segment above the slab");
  /* 1e-9 rad from horizontal between soil and sheet: it would take ~1e9
   * walls to leave the slab; the guard reports it unresolved. */
  ray3 flat = {v3(0.1, 0.2, 0.5), v3(0.6, 0.8, 1e-9), 0, INFINITY};
  CHECK(scene_occluded(s, &flat) == TRACE_UNRESOLVED, "nearly horizontal ray is unresolved, not unoccluded");
  r = flat;
  CHECK(scene_trace(s, &r, &h, &off) == TRACE_UNRESOLVED, "nearly horizontal ray is unresolved, not a miss");
  /* The slab offset puts a point on the soil outside the slab. */
  vec3 d = v3(0.6 * sin(t), 0.8 * sin(t), -cos(t));
  double o = periodic_slab_offset(&s->periodic, v3(0, 0, 0), d);
  CHECK(o * cos(t) > 1.0 && o * cos(t) < 1.01, "slab offset %.6g", o);
  scene_free(s);

  /* Rendered: a distant sensor looking exactly horizontally at a point
   * between soil and sheet, under a constant sky. Its rays never leave the
   * slab: they are counted as unresolved and see no sky (before, they
   * escaped after 100,000 walls and saw it). */
  scene *hs =
      tsup_load("{\"type\": \"scene\", \"variant\": \"mono\","
                " \"cam\": {\"type\": \"distant\", \"direction\": [0.6, 0.8, 0], \"target\": [0, 0, 0.5],"
                "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 2},"
                "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
                " \"sky\": {\"type\": \"constant\", \"radiance\": 1},"
                " \"sheet\": {\"type\": \"rectangle\", \"to_world\": [{\"translate\": [0, 0, 1]}], \"bsdf\": "
                "{\"type\": \"diffuse\"}},"
                " \"soil\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\"}},"
                " \"cell\": {\"type\": \"periodic\", \"min\": [-1, -1], \"max\": [1, 1]}}",
                NULL);
  REQUIRE(hs, "horizontal scene loads");
  film_image img = {0};
  rsw_err err = {0};
  render_opts ro = {.size = sizeof ro, .seed = 3, .threads = 1};
  render_result_stats st = {0};
  REQUIRE(render_sensor(hs, &ro, &img, &st, &err) == RSW_OK, "renders");
  CHECK(st.rays.unresolved == 2, "unresolved camera rays: %llu (want 2)",
        (unsigned long long)st.rays.unresolved);
  CHECK(img.data[0] == 0.0f, "an unresolved ray sees no sky (film %g)", img.data[0]);
  /* The film says so: its metadata (EXR attribute, JSON meta) carries the count. */
  CHECK(img.unresolved_rays == 2, "film unresolved_rays %llu (want 2)",
        (unsigned long long)img.unresolved_rays);
  film_exr_info info = film_image_exr_info(&img, "cam");
  CHECK(info.unresolved_rays == 2, "EXR info unresolved_rays %llu (want 2)",
        (unsigned long long)info.unresolved_rays);
  film_image_free(&img);
  scene_free(hs);
}

int main(void) {
  RSW_TEST_RUN(test_sheet_over_soil_low_sun);
  RSW_TEST_RUN(test_distant_sensors_grazing_view);
  RSW_TEST_RUN(test_periodic_equals_copies_low_sun);
  RSW_TEST_RUN(test_area_emitter_equals_copies);
  RSW_TEST_RUN(test_tracer_grazing);
  RSW_TEST_RUN(test_radiancemeter_outside_column);
  RSW_TEST_RUN(test_early_unresolved);
  RSW_TEST_END("test_periodic_sun");
}
