/* `sphericalcoordsvolume` (volumes/sphericalcoords.c; docs/plugins.md):
 *
 *  - Mapping: a nearest [phi, theta, r] grid of distinct values under a
 *    scaled, translated sphere, with rmin, rmax and both fills: at 20,000
 *    random points the value is the cell that the spherical coordinates
 *    name (Eradiate's convention), exactly.
 *  - A shell of uniform sigma_t (rmin 0.5, rmax 1) in a heterogeneous
 *    medium, seen through along parallel rays at impact parameters 0.3 and
 *    0.7: T = exp(-sigma L), L the chord through the shell (closed form),
 *    within 4 standard errors (24 renders of 1024 samples, fixed seeds).
 *  - A radial profile of 4 shells seen through the centre: tau is twice
 *    the sum of sigma_i times the shells' thickness.
 *  - An update of the nested grid's data renders the new transmittance,
 *    and a negative value is refused (the medium's sigma_t range reaches
 *    the nested grid).
 *  - Refused: rmin >= rmax, a negative rmin, and the volume where a slot
 *    reads box cells (piecewise, homogeneous), naming the key.
 *  - extremum_spherical: along 400 random rays through a shell of random
 *    radial, polar and azimuthal values (trilinear), the radial walk's
 *    pieces tile the segment in order, and sigma_t at 64 points of each
 *    lies between the piece's minorant and majorant; with it, the shell
 *    and the radial profile above keep their closed forms; refused on a
 *    box grid, extremum_grid refused on a sphericalcoordsvolume, a
 *    resolution other than [n, 1, 1], an rmin not the volume's.
 *  - docs/examples/spherical_shell.json (a Rayleigh atmosphere of 120
 *    exponential layers around a planet of 6,371 km, sun and view at
 *    zenith) against the same layers in a plane-parallel box over a plane:
 *    at nadir under a zenith sun the Earth's curvature changes the
 *    radiance by far less than 0.5%, so the two agree within 0.5% plus 4
 *    standard errors of the difference (8 renders each, fixed seeds). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/media/majorant_grid.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/scene.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

static uint64_t rng = 0x2545f4914f6cdd1dull;
static double urand(void) {
  rng ^= rng << 13, rng ^= rng >> 7, rng ^= rng << 17;
  return (double)(rng >> 11) * 0x1p-53;
}

static object *find_obj(const scene *s, const char *id) {
  for (size_t i = 0; i < s->n_objects; i++)
    if (s->objects[i]->id && strcmp(s->objects[i]->id, id) == 0) return s->objects[i];
  return NULL;
}

static void test_mapping(void) {
  enum {
    NR = 3,
    NT = 2,
    NP = 2
  };
  const double rmin = 0.4, rmax = 1.0, fmin_ = 7, fmax_ = 9;
  sbuf d = {0};
  for (int z = 0; z < NP; z++)
    for (int y = 0; y < NT; y++)
      for (int x = 0; x < NR; x++) sb_printf(&d, "%s%d", d.n ? ", " : "", 100 * z + 10 * y + x + 1);
  sbuf b = {0};
  sb_printf(&b,
            "{\"type\": \"scene\", \"v\": {\"type\": \"sphericalcoordsvolume\", \"rmin\": %g, \"rmax\": %g,"
            " \"fillmin\": %g, \"fillmax\": %g, \"to_world\": [{\"scale\": 2}, {\"translate\": [1, 2, 3]}],"
            " \"volume\": {\"type\": \"gridvolume\", \"filter_type\": \"nearest\", \"shape\": [%d, %d, %d],"
            " \"data\": [%s]}}}",
            rmin, rmax, fmin_, fmax_, NP, NT, NR, d.p);
  free(d.p);
  scene *s = tsup_load(b.p, "mono");
  free(b.p);
  REQUIRE(s, "scene");
  const volume *v = (const volume *)find_obj(s, "v");
  REQUIRE(v && v->base.plugin->cls == CLS_VOLUME, "the volume");
  long bad = 0, inside = 0;
  for (int k = 0; k < 20000; k++) {
    vec3 q = v3(2.4 * urand() - 1.2, 2.4 * urand() - 1.2, 2.4 * urand() - 1.2);
    double r = v3_len(q), want;
    if (r < rmin)
      want = fmin_;
    else if (r > rmax)
      want = fmax_;
    else {
      int ix = (int)floor((r - rmin) / (rmax - rmin) * NR), iy = (int)floor(acos(q.z / r) / PI * NT),
          iz = (int)floor((atan2(q.y, q.x) / (2 * PI) + 0.5) * NP);
      ix = ix > NR - 1 ? NR - 1 : ix, iy = iy > NT - 1 ? NT - 1 : iy, iz = iz > NP - 1 ? NP - 1 : iz;
      want = 100 * iz + 10 * iy + ix + 1;
      inside++;
    }
    vec3 p = v3(2 * q.x + 1, 2 * q.y + 2, 2 * q.z + 3);
    double got = v->ops->eval(v, p).c[0];
    if (got != want && bad++ < 5)
      printf("  q (%.6f, %.6f, %.6f) r %.6f: %g, want %g\n", q.x, q.y, q.z, r, got, want);
  }
  printf("  20000 points, %ld in the shell: %ld wrong\n", inside, bad);
  CHECK(bad == 0 && inside > 5000, "%ld points wrong (%ld in the shell)", bad, inside);
  CHECK(v->max == 113 && v->box_grid == false, "max %g (want 113, the largest cell)", v->max);
  /* the box: [-1, 1]^3 of the sphere's frame */
  CHECK(fabs(v->bbox_min.x - -1) < 1e-12 && fabs(v->bbox_max.z - 5) < 1e-12, "box (%g..%g, .., ..%g)",
        v->bbox_min.x, v->bbox_max.x, v->bbox_max.z);
  scene_free(s);
}

/* A heterogeneous medium inside the unit sphere, sigma_t a
 * sphericalcoordsvolume (shell rmin..1, nested `inner`), absorbing, seen
 * straight down at (b, 0) against a uniform sky. */
static char *shell_scene(double rmin, const char *inner, double b) {
  sbuf s = {0};
  sb_printf(
      &s,
      "{\"type\": \"scene\", \"integrator\": {\"type\": \"volpath\", \"max_depth\": -1},"
      " \"s\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [%.17g, 0, 0],"
      "  \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"sky\": {\"type\": \"constant\", \"radiance\": 1},"
      " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": \"ref\", "
      "\"id\": \"m\"}},"
      " \"m\": {\"type\": \"heterogeneous\", \"albedo\": 0,"
      "  \"sigma_t\": {\"type\": \"sphericalcoordsvolume\", \"rmin\": %.17g, \"rmax\": 1, \"volume\": %s}}}",
      b, rmin, inner);
  return s.p;
}

static void check_t(const char *what, scene *s, double want) {
  double m, se;
  REQUIRE(tsup_pixel_estimate(s, 1024, 24, &m, &se), "renders");
  printf("  %s: T %.5f +- %.5f, exact %.5f\n", what, m, se, want);
  /* (+ 1e-6: the sphere's boundary comes from Embree's single-precision
   * hit, and a shell's residual ratio tracking with a control equal to its
   * sigma_t is exact, standard error 0) */
  CHECK(fabs(m - want) <= 4 * se + 1e-6, "%s: T %.6g vs exact %.6g beyond 4 sigma (%.3g)", what, m, want,
        4 * se);
  CHECK(se < 0.03 * want, "%s: standard error %.3g too large for a meaningful test", what, se);
}

/* The chord through the shell rmin < r < 1 at impact parameter b. */
static double chord(double rmin, double b) {
  return 2 * (sqrt(1 - b * b) - (b < rmin ? sqrt(rmin * rmin - b * b) : 0.0));
}

static void test_shell_transmittance(void) {
  const double sig = 0.5;
  for (int k = 0; k < 2; k++) {
    double b = k ? 0.7 : 0.3;
    char *text = shell_scene(0.5, "{\"type\": \"gridvolume\", \"shape\": [1, 1, 1], \"data\": [0.5]}", b);
    scene *s = tsup_load(text, "mono");
    free(text);
    REQUIRE(s, "scene");
    char what[64];
    snprintf(what, sizeof what, "uniform shell, b %.1f", b);
    check_t(what, s, exp(-sig * chord(0.5, b)));
    scene_free(s);
  }
}

static void test_radial_profile(void) {
  static const double sig[4] = {0.2, 0.6, 1.0, 1.4};
  char *text = shell_scene(0.2,
                           "{\"type\": \"gridvolume\", \"filter_type\": \"nearest\", \"shape\": [1, 1, 4],"
                           " \"data\": [0.2, 0.6, 1.0, 1.4]}",
                           0.0);
  scene *s = tsup_load(text, "mono");
  free(text);
  REQUIRE(s, "scene");
  double tau = 0;
  for (int i = 0; i < 4; i++) tau += 2 * sig[i] * 0.2;
  check_t("4 shells through the centre", s, exp(-tau));
  scene_free(s);
}

static void test_update(void) {
  char *text = shell_scene(0.5, "{\"type\": \"gridvolume\", \"shape\": [1, 1, 1], \"data\": [0.5]}", 0.3);
  scene *s = tsup_load(text, "mono");
  free(text);
  REQUIRE(s, "scene");
  rsw_err e = {0};
  param_update u = {.key = "m.sigma_t.volume.data"};
  REQUIRE(param_value_parse("[1.5]", "test", &u.value, &e) == RSW_OK, "parse: %s", e.msg);
  rsw_err err = {0};
  rsw_status st = scene_update(s, &u, 1, NULL, &err);
  param_value_free(&u.value);
  char buf[1400];
  CHECK(st == RSW_OK, "the update: %s", rsw_err_format(&err, buf, sizeof buf));
  check_t("after m.sigma_t.volume.data = [1.5]", s, exp(-1.5 * chord(0.5, 0.3)));
  REQUIRE(param_value_parse("[-1]", "test", &u.value, &e) == RSW_OK, "parse: %s", e.msg);
  err = (rsw_err){0};
  st = scene_update(s, &u, 1, NULL, &err);
  param_value_free(&u.value);
  rsw_err_format(&err, buf, sizeof buf);
  printf("  [-1]: %s\n", buf);
  CHECK(st != RSW_OK && strstr(buf, "m.sigma_t.volume.data"), "a negative sigma_t was taken: %s", buf);
  scene_free(s);
}

static void test_refusals(void) {
  const char *inner = "{\"type\": \"gridvolume\", \"shape\": [1, 1, 1], \"data\": [0.5]}";
  char bad[512];
  snprintf(bad, sizeof bad,
           "{\"type\": \"sphericalcoordsvolume\", \"rmin\": 1, \"rmax\": 0.5, \"volume\": %s}", inner);
  const char *fmt = "{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"},"
                    " \"interior\": {\"type\": \"heterogeneous\", \"sigma_t\": %s}}}";
  CHECK(tsup_refused(fmt, bad), "rmin > rmax taken");
  snprintf(bad, sizeof bad, "{\"type\": \"sphericalcoordsvolume\", \"rmin\": -0.1, \"volume\": %s}", inner);
  CHECK(tsup_refused(fmt, bad), "a negative rmin taken");
  snprintf(bad, sizeof bad, "{\"type\": \"sphericalcoordsvolume\", \"volume\": %s}", inner);
  CHECK(!tsup_refused(fmt, bad), "the good volume refused");
  snprintf(
      bad, sizeof bad,
      "{\"type\": \"sphericalcoordsvolume\", \"volume\": {\"type\": \"gridvolume\", \"shape\": [1, 1, 2],"
      " \"data\": [0.5, -1]}}");
  CHECK(tsup_refused(fmt, bad), "negative nested values taken as sigma_t");
  /* slots that read box cells */
  static const char *const slots[] = {
      "{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"},"
      " \"interior\": {\"type\": \"piecewise\", \"sigma_t\": %s}}}",
      "{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"},"
      " \"interior\": {\"type\": \"homogeneous\", \"sigma_t\": %s}}}",
  };
  snprintf(bad, sizeof bad, "{\"type\": \"sphericalcoordsvolume\", \"volume\": %s}", inner);
  for (size_t i = 0; i < sizeof slots / sizeof slots[0]; i++) {
    char text[2048];
    snprintf(text, sizeof text, slots[i], bad);
    rsw_err err = {0};
    scene *s = NULL;
    rsw_status st = scene_load_memory(text, strlen(text), "bad.json", false, NULL, &s, &err);
    char buf[1200];
    rsw_err_format(&err, buf, sizeof buf);
    printf("  %s\n", buf);
    CHECK(st != RSW_OK && strstr(buf, "/ball/interior/sigma_t") && strstr(buf, "grid over a box"),
          "slot %zu: %s", i, buf);
    scene_free(s);
  }
}

/* ---- extremum_spherical ------------------------------------------------------- */

static void radial_bounds(const char *res) {
  enum {
    NR = 6,
    NT = 3,
    NP = 4
  };
  sbuf d = {0};
  for (int i = 0; i < NR * NT * NP; i++) sb_printf(&d, "%s%.17g", i ? ", " : "", 0.1 + 2.0 * urand());
  sbuf b = {0};
  sb_printf(
      &b,
      "{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"radius\": 3, \"center\": [1, 0, 0],"
      " \"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": \"ref\", \"id\": \"m\"}},"
      " \"m\": {\"type\": \"heterogeneous\", \"ex\": {\"type\": \"extremum_spherical\"%s%s},"
      "  \"sigma_t\": {\"type\": \"sphericalcoordsvolume\", \"rmin\": 0.3, \"rmax\": 0.9, \"fillmin\": 0.05,"
      "   \"fillmax\": 0.0, \"to_world\": [{\"scale\": 3}, {\"translate\": [1, 0, 0]}],"
      "   \"volume\": {\"type\": \"gridvolume\", \"shape\": [%d, %d, %d], \"data\": [%s]}}}}",
      res ? ", \"resolution\": " : "", res ? res : "", NP, NT, NR, d.p);
  free(d.p);
  scene *s = tsup_load(b.p, "mono");
  free(b.p);
  REQUIRE(s, "scene");
  const medium *m = NULL;
  for (size_t i = 0; i < s->n_objects && !m; i++)
    if (s->objects[i]->plugin && s->objects[i]->plugin->cls == CLS_MEDIUM) m = (const medium *)s->objects[i];
  REQUIRE(m && m->ops->majorant_walk, "the medium");
  /* the grid is built by prepare(); a scene without a sensor renders
   * nothing, so prepare the medium as a render would */
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 550};
  rsw_err err = {0};
  REQUIRE(scene_prepare(s, &rc, &err) == RSW_OK, "prepare");
  tsup_walk_stats w;
  tsup_walk_check(m, v3(-2.5, -3.5, -3.5), v3(4.5, 3.5, 3.5), 400, &rng, &w);
  long bad = w.bad, pieces = w.pieces, rays = w.rays, order = w.order;
  CHECK(w.radial == w.rays, "%ld of %ld walks radial", w.radial, w.rays);
  printf("  extremum_spherical %s: %ld rays, %ld pieces\n", res ? res : "auto", rays, pieces);
  CHECK(rays > 100 && pieces > 2 * rays, "too few rays (%ld) or pieces (%ld)", rays, pieces);
  CHECK(bad == 0, "%s: %ld points outside their piece's minorant and majorant", res ? res : "auto", bad);
  CHECK(order == 0, "%s: %ld pieces out of order", res ? res : "auto", order);
  scene_free(s);
}

static void test_extremum_spherical(void) {
  radial_bounds("[1, 1, 1]");
  radial_bounds("[3, 1, 1]");
  radial_bounds("[6, 1, 1]");
  radial_bounds("[17, 1, 1]");
  radial_bounds(NULL);
  /* closed forms with it */
  char *text = shell_scene(0.5, "{\"type\": \"gridvolume\", \"shape\": [1, 1, 1], \"data\": [0.5]}", 0.3);
  char *ex = NULL;
  {
    sbuf b = {0};
    const char *at = strstr(text, "\"albedo\": 0,");
    REQUIRE(at, "the medium");
    sb_printf(&b,
              "%.*s\"albedo\": 0, \"ex\": {\"type\": \"extremum_spherical\", \"resolution\": [4, 1, 1]},%s",
              (int)(at - text), text, at + strlen("\"albedo\": 0,"));
    ex = b.p;
  }
  free(text);
  scene *s = tsup_load(ex, "mono");
  free(ex);
  REQUIRE(s, "scene");
  check_t("uniform shell, b 0.3, extremum_spherical [4, 1, 1]", s, exp(-0.5 * chord(0.5, 0.3)));
  scene_free(s);
  /* refusals */
  const char *grid =
      "{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"},"
      " \"interior\": {\"type\": \"heterogeneous\", \"ex\": %s, \"sigma_t\": {\"type\": \"gridvolume\","
      " \"shape\": [1, 1, 2], \"data\": [1, 2]}}}}";
  const char *sph = "{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"},"
                    " \"interior\": {\"type\": \"heterogeneous\", \"ex\": %s, \"sigma_t\": {\"type\":"
                    " \"sphericalcoordsvolume\", \"rmin\": 0.5, \"volume\": 1}}}}";
  CHECK(tsup_refused(grid, "{\"type\": \"extremum_spherical\"}"), "extremum_spherical over a box grid taken");
  CHECK(tsup_refused(sph, "{\"type\": \"extremum_grid\"}"),
        "extremum_grid over a sphericalcoordsvolume taken");
  CHECK(tsup_refused(sph, "{\"type\": \"extremum_spherical\", \"resolution\": [4, 2, 1]}"),
        "[4, 2, 1] taken");
  CHECK(tsup_refused(sph, "{\"type\": \"extremum_spherical\", \"rmin\": 0.4}"), "a foreign rmin taken");
  CHECK(!tsup_refused(sph, "{\"type\": \"extremum_spherical\", \"rmin\": 0.5, \"rmax\": 1}"),
        "the volume's own rmin and rmax refused");
  CHECK(!tsup_refused(grid, "{\"type\": \"extremum_grid\"}"), "extremum_grid over a box grid refused");
}

/* The docs' spherical shell against its plane-parallel twin. */
static void test_shell_vs_plane_parallel(void) {
  enum {
    REPS = 8,
    N = 120
  };
  scene *sh = tsup_load_file("docs/examples/spherical_shell.json", NULL);
  REQUIRE(sh, "docs/examples/spherical_shell.json");
  sbuf d = {0};
  for (int i = 0; i < N; i++)
    sb_printf(&d, "%s%.6g", i ? ", " : "", 0.012 * 8 * (exp(-i / 8.0) - exp(-(i + 1) / 8.0)));
  sbuf b = {0};
  sb_printf(
      &b,
      "{\"type\": \"scene\", \"variant\": \"mono\", \"integrator\": {\"type\": \"volpath\", \"max_depth\": "
      "-1},"
      " \"toa\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
      "  \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1},"
      " \"ground\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 4000}],"
      "  \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.3}},"
      " \"box\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
      "  \"to_world\": [{\"scale\": [4000, 4000, 60]}, {\"translate\": [0, 0, 60]}],"
      "  \"interior\": {\"type\": \"heterogeneous\", \"albedo\": 1, \"phase\": {\"type\": \"rayleigh\"},"
      "   \"sigma_t\": {\"type\": \"gridvolume\", \"filter_type\": \"nearest\", \"shape\": [%d, 1, 1],"
      "    \"data\": [%s], \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [8000, 8000, "
      "120]}]}}}}",
      N, d.p);
  free(d.p);
  scene *pp = tsup_load(b.p, "mono");
  free(b.p);
  REQUIRE(pp, "the plane-parallel scene");
  double m[2], se[2];
  scene *sc[2] = {sh, pp};
  for (int k = 0; k < 2; k++) REQUIRE(tsup_pixel_estimate(sc[k], 16384, REPS, &m[k], &se[k]), "renders");
  double diff = m[0] - m[1], tol = 4 * sqrt(se[0] * se[0] + se[1] * se[1]) + 0.005 * m[1];
  printf("  nadir radiance: spherical shell %.6f +- %.6f, plane-parallel %.6f +- %.6f (%+.2f%%)\n", m[0],
         se[0], m[1], se[1], 100 * diff / m[1]);
  CHECK(fabs(diff) <= tol, "spherical %.6g vs plane-parallel %.6g: beyond %.3g", m[0], m[1], tol);
  CHECK(se[1] < 0.002 * m[1], "standard error %.3g too large for a meaningful test", se[1]);
  scene_free(sh);
  scene_free(pp);
}

int main(void) {
  RSW_TEST_RUN(test_mapping);
  RSW_TEST_RUN(test_shell_transmittance);
  RSW_TEST_RUN(test_radial_profile);
  RSW_TEST_RUN(test_update);
  RSW_TEST_RUN(test_refusals);
  RSW_TEST_RUN(test_extremum_spherical);
  RSW_TEST_RUN(test_shell_vs_plane_parallel);
  RSW_TEST_END("test_sphericalcoords");
}
