/* Participating media against closed forms (issue 14): Beer-Lambert
 * through absorbing slabs (exact: albedo 0 needs no sampling), single
 * scattering in a thin slab under a sun (3 sigma), furnaces (an albedo-1
 * medium under a constant sky gives the sky back), piecewise against
 * homogeneous and piecewise_volpath against volpath (3 sigma), and the
 * scene-level media errors.
 *
 * Monte Carlo estimates: REPS independent renders (seeds 1..REPS) of a
 * one-pixel radiancemeter; mean and standard error over the renders;
 * tolerance 3 standard errors (fixed seeds: deterministic outcome). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/accel.h"
#include "../../../server/kernel/media/layered.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/test.h"
#include "../../support/tsup.h"
#include "image_exr.h"

RSW_TEST_DEFINE_GLOBALS

#define PI   3.14159265358979323846
#define REPS 24

/* A slab z in [0, h], 40 x 40 wide, bounded by a null cube holding
 * `medium` (JSON), over an optional ground at z = -0.5. */
static scene *slab_scene(const char *integ, const char *med, double h, const char *light, const char *ground,
                         vec3 origin, vec3 dir) {
  sbuf b = {0};
  sb_printf(&b,
            "{\"type\": \"scene\", \"integrator\": %s,"
            " \"slab\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"}, \"interior\": %s,"
            "   \"to_world\": [{\"scale\": [20, 20, %.17g]}, {\"translate\": [0, 0, %.17g]}]},"
            " \"light\": %s,",
            integ, med, 0.5 * h, 0.5 * h, light);
  if (ground)
    sb_printf(&b,
              " \"ground\": {\"type\": \"rectangle\", \"bsdf\": %s,"
              "   \"to_world\": [{\"scale\": 40}, {\"translate\": [0, 0, -0.5]}]},",
              ground);
  sb_printf(
      &b,
      " \"meter\": {\"type\": \"radiancemeter\", \"origin\": [%.17g, %.17g, %.17g],"
      "   \"direction\": [%.17g, %.17g, %.17g],"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}}}",
      origin.x, origin.y, origin.z, dir.x, dir.y, dir.z);
  scene *s = tsup_load(b.p, "mono");
  free(b.p);
  return s;
}

static double render1(scene *s, uint32_t spp, uint64_t seed) {
  film_image img;
  if (!tsup_render(s, spp, seed, 2, &img)) return NAN;
  double v = img.data[0];
  film_image_free(&img);
  return v;
}

static void estimate(scene *s, uint32_t spp, double *mean, double *sem) {
  double sum = 0, sum2 = 0;
  for (int r = 1; r <= REPS; r++) {
    double v = render1(s, spp, (uint64_t)r);
    sum += v;
    sum2 += v * v;
  }
  *mean = sum / REPS;
  *sem = sqrt(fmax(sum2 / REPS - *mean * *mean, 0.0) / (REPS - 1));
}

static void check_3sigma(const char *what, double m, double sem, double expect) {
  CHECK(fabs(m - expect) <= 3 * sem + 1e-12, "%s: %.6g vs expected %.6g (3 sigma = %.3g)", what, m, expect,
        3 * sem);
  CHECK(sem < 0.05 * fabs(expect) + 1e-9, "%s: standard error %.3g too large for a meaningful test", what,
        sem);
}

/* ---- Beer-Lambert ---------------------------------------------------------- */

/* A meter under the slab looks up through it at zenith angle th; the sky
 * has radiance 1: L = exp(-tau / mu). Exact (no sampling with albedo 0),
 * up to the boundary's hit points: Embree places them in float32, 1e-6
 * of the 40-unit-wide slab's coordinates, so 1e-5 relative. */
static void beer_lambert(const char *integ, const char *med, double h, double tau, double th_deg) {
  double th = th_deg * PI / 180, mu = cos(th);
  scene *s = slab_scene(integ, med, h, "{\"type\": \"constant\", \"radiance\": 1}", NULL,
                        v3(-2 * tan(th), 0, -2), v3(sin(th), 0, mu));
  REQUIRE(s, "scene");
  double expect = exp(-tau / mu);
  for (uint64_t seed = 0; seed < 2; seed++) {
    double v = render1(s, 4, seed);
    CHECK(fabs(v - expect) <= 1e-5 * expect, "%s %s at %g deg: %.9g vs exp(-tau/mu) = %.9g", integ, med,
          th_deg, v, expect);
  }
  scene_free(s);
}

static void test_beer_lambert_homogeneous(void) {
  const char *med = "{\"type\": \"homogeneous\", \"sigma_t\": 0.7, \"albedo\": 0}";
  for (int i = 0; i < 3; i++) {
    double th = 25.0 * i;
    beer_lambert("{\"type\": \"volpath\"}", med, 1.0, 0.7, th);
    beer_lambert("{\"type\": \"piecewise_volpath\"}", med, 1.0, 0.7, th);
  }
}

static void test_beer_lambert_heterogeneous_constant(void) {
  /* A constant grid over the slab's box (the unit cube under to_world). */
  const char *med = "{\"type\": \"heterogeneous\", \"albedo\": 0,"
                    " \"sigma_t\": {\"type\": \"constvolume\", \"value\": 1.3,"
                    "   \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [40, 40, 2]}]}}";
  for (int i = 0; i < 3; i++) {
    beer_lambert("{\"type\": \"volpath\"}", med, 2.0, 2.6, 25.0 * i);
    beer_lambert("{\"type\": \"piecewise_volpath\"}", med, 2.0, 2.6, 25.0 * i);
  }
}

static void test_beer_lambert_piecewise_one_layer(void) {
  const char *med = "{\"type\": \"piecewise\", \"albedo\": 0,"
                    " \"sigma_t\": {\"type\": \"constvolume\", \"value\": 0.4,"
                    "   \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [40, 40, 3]}]}}";
  for (int i = 0; i < 3; i++) beer_lambert("{\"type\": \"piecewise_volpath\"}", med, 3.0, 1.2, 25.0 * i);
}

/* ---- single scattering ------------------------------------------------------ */

/* A slab of optical thickness tau and albedo w over a black ground under a
 * sun of irradiance 1 from zenith th0 (azimuth 0), seen from zenith thv at
 * azimuth phv (degrees); max_depth 2 (single scattering):
 *   L = w p(Theta) mu0 / (mu0 + muv) (1 - exp(-tau (1/mu0 + 1/muv))),
 * Theta between the sun's propagation and the view direction. */
typedef double (*phase_fn)(double cos_theta, double g);

static double p_iso(double c, double g) {
  (void)c, (void)g;
  return 1.0 / (4 * PI);
}
static double p_hg(double c, double g) {
  return (1 - g * g) / (4 * PI * pow(1 + g * g - 2 * g * c, 1.5));
}

static double p_rayleigh(double c, double g) {
  (void)g;
  return 3.0 / (16 * PI) * (1 + c * c);
}

static void single_scattering(const char *integ, const char *phase_json, phase_fn p, double g, double thv_deg,
                              double phv_deg) {
  const double tau = 0.2, w = 0.8, h = 1.0;
  const double th0 = 30 * PI / 180, thv = thv_deg * PI / 180, phv = phv_deg * PI / 180;
  vec3 sun = v3(-sin(th0), 0, -cos(th0)); /* propagation */
  vec3 to_view = v3(sin(thv) * cos(phv), sin(thv) * sin(phv), cos(thv));
  char med[512], emit[256];
  snprintf(med, sizeof med,
           "{\"type\": \"homogeneous\", \"sigma_t\": %.17g, \"albedo\": %.17g, \"phase\": %s}", tau / h, w,
           phase_json);
  snprintf(emit, sizeof emit,
           "{\"type\": \"directional\", \"direction\": [%.17g, 0, %.17g], \"irradiance\": 1}", sun.x, sun.z);
  vec3 origin = v3_scale(to_view, 3.0);
  scene *s =
      slab_scene(integ, med, h, emit, "{\"type\": \"diffuse\", \"reflectance\": 0}", origin, v3_neg(to_view));
  REQUIRE(s, "scene");
  double mu0 = cos(th0), muv = cos(thv);
  double expect = w * p(v3_dot(sun, to_view), g) * mu0 / (mu0 + muv) * (1 - exp(-tau * (1 / mu0 + 1 / muv)));
  double m, sem;
  estimate(s, 4096, &m, &sem);
  char what[256];
  snprintf(what, sizeof what, "single scattering %s %s view (%g, %g)", integ, phase_json, thv_deg, phv_deg);
  check_3sigma(what, m, sem, expect);
  scene_free(s);
}

static void test_single_scattering(void) {
  const char *integ[] = {"{\"type\": \"volpath\", \"max_depth\": 2}",
                         "{\"type\": \"piecewise_volpath\", \"max_depth\": 2}"};
  const double views[][2] = {{0, 0}, {40, 0}, {40, 180}, {65, 90}};
  for (int i = 0; i < 2; i++)
    for (int v = 0; v < 4; v++) {
      single_scattering(integ[i], "{\"type\": \"isotropic\"}", p_iso, 0, views[v][0], views[v][1]);
      single_scattering(integ[i], "{\"type\": \"hg\", \"g\": 0.7}", p_hg, 0.7, views[v][0], views[v][1]);
      single_scattering(integ[i], "{\"type\": \"hg\", \"g\": -0.7}", p_hg, -0.7, views[v][0], views[v][1]);
      single_scattering(integ[i], "{\"type\": \"rayleigh\"}", p_rayleigh, 0, views[v][0], views[v][1]);
    }
}

/* ---- furnaces --------------------------------------------------------------- */

static void test_furnace_sphere(void) {
  /* An albedo-1 medium in a null sphere under a sky of radiance 1: every
   * path ends in the sky with weight 1 (roulette aside). */
  const char *integ[] = {"{\"type\": \"volpath\"}", "{\"type\": \"piecewise_volpath\"}"};
  /* The third: no light samples from the medium (sample_emitters false),
   * so the sky seen after scattering must count fully (no MIS). */
  for (int i = 0; i < 3; i++) {
    sbuf b = {0};
    sb_printf(&b,
              "{\"type\": \"scene\", \"integrator\": %s,"
              " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"},"
              "   \"interior\": {\"type\": \"homogeneous\", \"sigma_t\": 3, \"albedo\": 1,"
              "                  \"sample_emitters\": %s, \"phase\": {\"type\": \"hg\", \"g\": 0.5}}},"
              " \"sky\": {\"type\": \"constant\", \"radiance\": 1},"
              " \"meter\": {\"type\": \"radiancemeter\", \"origin\": [0, 0, 5], \"direction\": [0, 0.1, -1],"
              "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}",
              integ[i % 2], i == 2 ? "false" : "true");
    scene *s = tsup_load(b.p, "mono");
    free(b.p);
    REQUIRE(s, "scene");
    double m, sem;
    estimate(s, 1024, &m, &sem);
    CHECK(fabs(m - 1) <= 3 * sem + 1e-9 && sem < 0.01, "furnace %s (case %d): %.6g +- %.3g vs 1",
          integ[i % 2], i, m, sem);
    scene_free(s);
  }
}

static void test_furnace_atmosphere_white_ground(void) {
  /* A non-absorbing slab over a white Lambertian ground under a sky of
   * radiance 1: the sky's radiance upwards at every angle. */
  for (int a = 0; a < 3; a++) {
    double th = 30.0 * a * PI / 180;
    vec3 to_view = v3(sin(th), 0, cos(th));
    scene *s =
        slab_scene("{\"type\": \"volpath\"}",
                   "{\"type\": \"homogeneous\", \"sigma_t\": 0.5, \"albedo\": 1,"
                   " \"phase\": {\"type\": \"hg\", \"g\": 0.3}}",
                   1.0, "{\"type\": \"constant\", \"radiance\": 1}",
                   "{\"type\": \"diffuse\", \"reflectance\": 1}", v3_scale(to_view, 3), v3_neg(to_view));
    REQUIRE(s, "scene");
    double m, sem;
    estimate(s, 1024, &m, &sem);
    CHECK(fabs(m - 1) <= 3 * sem + 1e-9 && sem < 0.01, "white furnace at %g deg: %.6g +- %.3g vs 1", 30.0 * a,
          m, sem);
    scene_free(s);
  }
}

/* ---- integrators and media agree -------------------------------------------- */

/* Multiple scattering over a grey ground under a sun: volpath and
 * piecewise_volpath, homogeneous and one-layer piecewise media. */
static void test_integrators_agree(void) {
  const char *media[] = {
      "{\"type\": \"homogeneous\", \"sigma_t\": 0.8, \"albedo\": 0.9,"
      " \"phase\": {\"type\": \"hg\", \"g\": 0.6}}",
      "{\"type\": \"piecewise\", \"albedo\": 0.9, \"phase\": {\"type\": \"hg\", \"g\": 0.6},"
      " \"sigma_t\": {\"type\": \"constvolume\", \"value\": 0.8,"
      "   \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [40, 40, 1]}]}}"};
  const char *integ[] = {"{\"type\": \"volpath\"}", "{\"type\": \"piecewise_volpath\"}"};
  double m[4], se[4];
  for (int k = 0; k < 4; k++) {
    vec3 to_view = v3(0.5, 0.2, 0.8427);
    scene *s =
        slab_scene(integ[k & 1], media[k >> 1], 1.0,
                   "{\"type\": \"directional\", \"direction\": [-0.5, 0, -0.8660254], \"irradiance\": 2}",
                   "{\"type\": \"diffuse\", \"reflectance\": 0.3}", v3_scale(to_view, 3), v3_neg(to_view));
    REQUIRE(s, "scene");
    estimate(s, 2048, &m[k], &se[k]);
    scene_free(s);
  }
  for (int k = 1; k < 4; k++)
    CHECK(fabs(m[k] - m[0]) <= 3 * sqrt(se[k] * se[k] + se[0] * se[0]),
          "case %d: %.6g +- %.3g vs volpath homogeneous %.6g +- %.3g", k, m[k], se[k], m[0], se[0]);
}

/* ---- layered media ------------------------------------------------------------ */

/* A [N, 1, 1] gridvolume over the slab's box (z in [0, h]) as JSON. */
static void layers_json(sbuf *b, const double *v, int n, double h, const char *extra) {
  sb_printf(b, "{\"type\": \"gridvolume\", \"shape\": [%d, 1, 1], %s \"data\": [", n, extra);
  for (int i = 0; i < n; i++) sb_printf(b, "%s%.17g", i ? ", " : "", v[i]);
  sb_printf(b, "], \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [40, 40, %.17g]}]}", h);
}

/* N unequal layers: exp(-sum sigma_i dz / mu), exact for piecewise (both
 * integrators), 3 sigma for heterogeneous (nearest filter: ratio
 * tracking). Also N equal layers. */
static void test_beer_lambert_layers(void) {
  enum {
    N = 37
  };
  double sig[N], eq[N], tau = 0, h = 3.0;
  for (int i = 0; i < N; i++) {
    sig[i] = 0.05 + 0.9 * fabs(sin(1.7 * i)) * exp(-i / 15.0);
    eq[i] = 0.35;
    tau += sig[i] * h / N;
  }
  for (int which = 0; which < 2; which++) {
    const double *v = which ? eq : sig;
    double t = which ? 0.35 * h : tau;
    sbuf b = {0};
    sb_printf(&b, "{\"type\": \"piecewise\", \"albedo\": 0, \"sigma_t\": ");
    layers_json(&b, v, N, h, "");
    sb_printf(&b, "}");
    for (int i = 0; i < 3; i++) beer_lambert("{\"type\": \"piecewise_volpath\"}", b.p, h, t, 25.0 * i);
    /* volpath ratio-tracks the same layers: 3 sigma. */
    double th = 35 * PI / 180;
    scene *s = slab_scene("{\"type\": \"volpath\"}", b.p, h, "{\"type\": \"constant\", \"radiance\": 1}",
                          NULL, v3(-2 * tan(th), 0, -2), v3(sin(th), 0, cos(th)));
    free(b.p);
    REQUIRE(s, "scene");
    double m, sem;
    estimate(s, 1024, &m, &sem);
    check_3sigma(which ? "volpath, equal layers" : "volpath, unequal layers", m, sem, exp(-t / cos(th)));
    scene_free(s);
  }
  /* Heterogeneous, nearest cells: ratio tracking against the exact value. */
  sbuf b = {0};
  sb_printf(&b, "{\"type\": \"heterogeneous\", \"albedo\": 0, \"sigma_t\": ");
  layers_json(&b, sig, N, h, "\"filter_type\": \"nearest\",");
  sb_printf(&b, "}");
  double th = 35 * PI / 180;
  scene *s = slab_scene("{\"type\": \"volpath\"}", b.p, h, "{\"type\": \"constant\", \"radiance\": 1}", NULL,
                        v3(-2 * tan(th), 0, -2), v3(sin(th), 0, cos(th)));
  free(b.p);
  REQUIRE(s, "scene");
  double m, sem;
  estimate(s, 1024, &m, &sem);
  check_3sigma("heterogeneous layers, ratio tracking", m, sem, exp(-tau / cos(th)));
  scene_free(s);
}

/* Scattering: piecewise with N identical layers == homogeneous, and
 * piecewise_volpath == volpath on unequal layers (3 sigma). */
static void test_piecewise_agrees(void) {
  enum {
    N = 24
  };
  double eq[N], sig[N], alb[N];
  for (int i = 0; i < N; i++) {
    eq[i] = 0.6;
    sig[i] = 1.2 * exp(-i / 6.0);
    alb[i] = 0.5 + 0.45 * (i % 3) / 2.0;
  }
  vec3 to_view = v3(0.3, -0.4, 0.866);
  const char *sun = "{\"type\": \"directional\", \"direction\": [-0.5, 0.1, -0.86], \"irradiance\": 2}";
  const char *gnd = "{\"type\": \"diffuse\", \"reflectance\": 0.25}";
  double m[5], se[5];
  for (int k = 0; k < 5; k++) {
    sbuf b = {0};
    const char *integ = "{\"type\": \"volpath\"}";
    if (k == 0) {
      sb_printf(&b, "{\"type\": \"homogeneous\", \"sigma_t\": 0.6, \"albedo\": 0.8,"
                    " \"phase\": {\"type\": \"hg\", \"g\": 0.5}}");
    } else {
      sb_printf(&b, "{\"type\": \"piecewise\", \"phase\": {\"type\": \"hg\", \"g\": 0.5}, \"sigma_t\": ");
      bool equal = k == 1 || k == 2;
      layers_json(&b, equal ? eq : sig, N, 2.0, "");
      if (equal)
        sb_printf(&b, ", \"albedo\": 0.8}");
      else {
        sb_printf(&b, ", \"albedo\": ");
        layers_json(&b, alb, N, 2.0, "");
        sb_printf(&b, "}");
      }
      if (k == 2 || k == 4) integ = "{\"type\": \"piecewise_volpath\"}";
    }
    scene *s = slab_scene(integ, b.p, 2.0, sun, gnd, v3_scale(to_view, 4), v3_neg(to_view));
    free(b.p);
    REQUIRE(s, "scene %d", k);
    estimate(s, 2048, &m[k], &se[k]);
    scene_free(s);
  }
  /* 0 homogeneous, 1 piecewise equal (volpath), 2 equal (piecewise_volpath),
   * 3 unequal (volpath), 4 unequal (piecewise_volpath). */
  const int pairs[][2] = {{0, 1}, {0, 2}, {3, 4}};
  for (int i = 0; i < 3; i++) {
    int a = pairs[i][0], c = pairs[i][1];
    CHECK(fabs(m[a] - m[c]) <= 3 * sqrt(se[a] * se[a] + se[c] * se[c]),
          "case %d %.6g +- %.3g vs case %d %.6g +- %.3g", c, m[c], se[c], a, m[a], se[a]);
    CHECK(se[c] < 0.02 * m[c], "case %d: standard error %.3g too large", c, se[c]);
  }
}

/* ---- piecewise optical thickness, directly ----------------------------------- */

/* tau along o + t d over [t0, t1] summed layer by layer (each layer's
 * slab cut by the segment), independent of the medium's cumulative sums.
 * The box is z in [zb, zb + h] (axis-aligned, so local z = (z - zb) / h). */
static double tau_layers(const double *sig, int n, double zb, double h, vec3 o, vec3 d, double t0,
                         double t1) {
  double za = o.z + t0 * d.z, zc = o.z + t1 * d.z;
  if (fabs(d.z) < 1e-300) {
    int k = (int)floor((za - zb) / h * n);
    return sig[k < 0 ? 0 : k >= n ? n - 1 : k] * (t1 - t0);
  }
  double lo = fmin(za, zc), hi = fmax(za, zc), tau = 0;
  for (int k = 0; k < n; k++) {
    double a = fmax(lo, zb + h * k / n), b = fmin(hi, zb + h * (k + 1) / n);
    if (b > a) tau += sig[k] * (b - a) / fabs(d.z);
  }
  return tau;
}

static void test_piecewise_exact_ops(void) {
  enum {
    N = 53
  };
  double sig[N], h = 7.0, zb = -1.0;
  for (int i = 0; i < N; i++) sig[i] = (i % 7 == 3) ? 0.0 : 0.02 + 0.5 * fabs(cos(0.9 * i));
  sbuf b = {0};
  sb_printf(
      &b,
      "{\"type\": \"scene\", \"box\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
      " \"to_world\": [{\"scale\": [5, 5, %.17g]}, {\"translate\": [0, 0, %.17g]}],"
      " \"interior\": {\"type\": \"piecewise\", \"albedo\": 0.5, \"sigma_t\": {\"type\": \"gridvolume\","
      " \"shape\": [%d, 1, 1], \"data\": [",
      h / 2, zb + h / 2, N);
  for (int i = 0; i < N; i++) sb_printf(&b, "%s%.17g", i ? ", " : "", sig[i]);
  sb_printf(&b,
            "], \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [10, 10, %.17g]},"
            " {\"translate\": [0, 0, %.17g]}]}}}}",
            h, zb);
  scene *s = tsup_load(b.p, "mono");
  free(b.p);
  REQUIRE(s, "scene");
  const medium *m = s->shapes[0]->interior;
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 550};
  rsw_err err = {0};
  REQUIRE(scene_prepare(s, &rc, &err) == RSW_OK, "prepare: %s", err.msg);
  pcg32 rng;
  pcg32_seed(&rng, 7, 1);
  int bad_tr = 0, bad_inv = 0, n_coll = 0;
  double worst = 0;
  for (int k = 0; k < 400; k++) {
    vec3 o = v3(4 * pcg32_next_double(&rng) - 2, 4 * pcg32_next_double(&rng) - 2,
                zb + h * pcg32_next_double(&rng));
    double ct = 2 * pcg32_next_double(&rng) - 1, ph = 2 * PI * pcg32_next_double(&rng);
    if (k % 50 == 0) ct = 0; /* level rays */
    if (k % 50 == 1) ct = 1e-9;
    double st = sqrt(1 - ct * ct);
    vec3 d = v3(st * cos(ph), st * sin(ph), ct);
    ray3 r = {o, d, 0, INFINITY};
    double mint, maxt;
    REQUIRE(m->ops->intersect_aabb(m, &r, &mint, &maxt), "ray %d meets the box", k);
    double tau = tau_layers(sig, N, zb, h, o, d, mint, maxt);
    double tr = m->ops->transmittance(m, &r, mint, maxt).c[0];
    double e = fabs(tr - exp(-tau));
    /* Conditioning: a layer boundary's crossing is known to a few ulps of
     * z over |d.z| in t, which a nearly level ray turns into a large
     * error in tau (for the reference as much as for the medium). */
    double cond = d.z != 0 ? 16 * 2.2e-16 * (fabs(o.z) + fabs(zb) + h) * 0.52 / fabs(d.z) : 0;
    if (e > 1e-12 + 1e-10 * exp(-tau) + cond) bad_tr++;
    worst = fmax(worst, e);
    /* Free flights: the collision t at u must satisfy 1 - exp(-tau(mint, t)) = u. */
    for (int j = 0; j < 8; j++) {
      double u = pcg32_next_double(&rng);
      medium_interaction mi;
      color trc, pdf;
      m->ops->sample_real(m, &r, mint, maxt, u, 0, &mi, &trc, &pdf);
      if (!isfinite(mi.t)) {
        if (!(u >= 1 - exp(-tau) - 1e-12)) bad_inv++;
        continue;
      }
      n_coll++;
      double tt = tau_layers(sig, N, zb, h, o, d, mint, mi.t);
      if (fabs((1 - exp(-tt)) - u) > 1e-9 + cond || !(mi.t >= mint && mi.t <= maxt) || !(mi.sigma_t.c[0] > 0))
        bad_inv++;
    }
  }
  CHECK(bad_tr == 0, "%d transmittances differ from the layer-by-layer product (worst %g)", bad_tr, worst);
  CHECK(bad_inv == 0, "%d free flights do not invert the optical thickness", bad_inv);
  CHECK(n_coll > 1000, "only %d collisions sampled", n_coll);
  scene_free(s);
}

/* ---- rgb, determinism, updates ------------------------------------------------ */

/* rgb: a chromatic absorbing slab gives exp(-tau_c / mu) per channel
 * (homogeneous, and piecewise with a 3-channel grid); a chromatic
 * scattering slab agrees between volpath and piecewise_volpath. */
/* The free flights' index over C (media/layered.h) brackets the binary
 * search only where C says the bracket holds: with it and without it
 * (bk_scale -1: the full search), every flight lands in the same layer at
 * the same t, bit for bit. Profiles with runs of empty layers (flat C, so
 * that buckets hold many equal entries), a dynamic range of 1e8 (an
 * atmosphere's thin top in one bucket) and three channels (rgb, chromatic:
 * one index per channel); rays up and down, nearly level and vertical. */
static void test_layer_index_search(void) {
  enum {
    N = 517
  };
  for (int prof = 0; prof < 3; prof++) {
    bool rgb = prof == 2;
    sbuf b = {0};
    sb_printf(
        &b,
        "{\"type\": \"scene\", \"box\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
        " \"to_world\": [{\"scale\": [5, 5, 3]}, {\"translate\": [0, 0, 2]}],"
        " \"interior\": {\"type\": \"piecewise\", \"albedo\": 0.5, \"sigma_t\": {\"type\": \"gridvolume\","
        " \"shape\": [%d, 1, 1%s], \"data\": [",
        N, rgb ? ", 3" : "");
    for (int i = 0; i < N; i++)
      for (int c = 0; c < (rgb ? 3 : 1); c++) {
        double v = prof == 0 ? ((i / 9) % 3 == 1 ? 0.0 : 0.3 + 0.2 * sin(0.37 * i))
                             : 2.0 * exp(-i / (N / 18.0)) * (1 + c);
        if (prof == 2 && i % 11 == c) v = 0;
        sb_printf(&b, "%s%.17g", i || c ? ", " : "", v);
      }
    sb_printf(&b, "], \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [10, 10, 6]},"
                  " {\"translate\": [0, 0, -1]}]}}}}");
    scene *s = tsup_load(b.p, rgb ? "rgb" : "mono");
    free(b.p);
    REQUIRE(s, "scene %d", prof);
    medium *m = s->shapes[0]->interior;
    render_ctx rc = {.variant = rgb ? VARIANT_RGB : VARIANT_MONO, .wavelength = 550};
    rsw_err err = {0};
    REQUIRE(scene_prepare(s, &rc, &err) == RSW_OK, "prepare: %s", err.msg);
    media_layers *L = &((layered_medium *)m)->L;
    int nc = rgb ? 3 : 1;
    for (int c = 0; c < nc; c++) CHECK(L->bk_scale[c] > 0, "profile %d channel %d has its index", prof, c);
    double keep[3] = {L->bk_scale[0], L->bk_scale[1], L->bk_scale[2]};
    pcg32 rng;
    pcg32_seed(&rng, 11, (uint64_t)prof);
    int differ = 0, coll = 0;
    for (int k = 0; k < 3000; k++) {
      vec3 o = v3(2 * pcg32_next_double(&rng) - 1, 2 * pcg32_next_double(&rng) - 1,
                  -1 + 6 * pcg32_next_double(&rng));
      double ct = 2 * pcg32_next_double(&rng) - 1, ph = 2 * PI * pcg32_next_double(&rng);
      if (k % 100 == 0) ct = 1e-7;
      if (k % 100 == 1) ct = -1;
      double st = sqrt(1 - ct * ct);
      ray3 r = {o, v3(st * cos(ph), st * sin(ph), ct), 0, INFINITY};
      double mint, maxt;
      if (!m->ops->intersect_aabb(m, &r, &mint, &maxt)) continue;
      double u = pcg32_next_double(&rng);
      if (k % 7 == 0) u = 1 - 1e-12;
      int ch = (int)(pcg32_next_double(&rng) * nc);
      medium_interaction mi[2];
      color tr[2], pdf[2];
      for (int w = 0; w < 2; w++) {
        for (int c = 0; c < 3; c++) L->bk_scale[c] = w ? -1.0 : keep[c];
        memset(&mi[w], 0, sizeof mi[w]);
        m->ops->sample_real(m, &r, mint, maxt, u, ch, &mi[w], &tr[w], &pdf[w]);
      }
      coll += isfinite(mi[0].t);
      if (memcmp(&mi[0].t, &mi[1].t, sizeof mi[0].t) || memcmp(&tr[0], &tr[1], sizeof tr[0]) ||
          memcmp(&pdf[0], &pdf[1], sizeof pdf[0]) || memcmp(&mi[0].sigma_t, &mi[1].sigma_t, sizeof(color)))
        differ++;
    }
    for (int c = 0; c < 3; c++) L->bk_scale[c] = keep[c];
    printf("  profile %d: %d collisions of 3000 flights, %d differ\n", prof, coll, differ);
    CHECK(coll > 500, "profile %d: flights collide (%d)", prof, coll);
    CHECK(differ == 0, "profile %d: %d flights differ with the index", prof, differ);
    scene_free(s);
  }
}

/* A flight decides that it passes the box without the log when u >= total
 * (1 + 2^-40) (media_layers_sample_real): the decision must be the log's,
 * !(-log1p(-u) < total) as rsw_neg_log1m computes it, for every u. Flights
 * through thin (totals down to 1e-12, where tau* is u to an ulp or two)
 * and thick layers, u at the margin and up to 64 ulp either side of it and
 * of total itself, and at random. */
static void test_flight_pass_margin(void) {
  enum {
    N = 240
  };
  sbuf b = {0};
  sb_printf(
      &b,
      "{\"type\": \"scene\", \"box\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
      " \"interior\": {\"type\": \"piecewise\", \"albedo\": 0.5, \"sigma_t\": {\"type\": \"gridvolume\","
      " \"shape\": [%d, 1, 1], \"data\": [",
      N);
  for (int i = 0; i < N; i++) sb_printf(&b, "%s%.17g", i ? ", " : "", 3.0 * exp(-i / 8.0));
  sb_printf(&b, "], \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [2, 2, 2]},"
                " {\"translate\": [0, 0, -1]}]}}}}");
  scene *s = tsup_load(b.p, "mono");
  free(b.p);
  REQUIRE(s, "scene");
  medium *m = s->shapes[0]->interior;
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 550};
  rsw_err err = {0};
  REQUIRE(scene_prepare(s, &rc, &err) == RSW_OK, "prepare: %s", err.msg);
  const media_layers *L = &((layered_medium *)m)->L;
  pcg32 rng;
  pcg32_seed(&rng, 5, 3);
  long flights = 0, fast = 0, near = 0, differ = 0;
  double tmin_seen = INFINITY;
  for (int k = 0; k < 4000; k++) {
    /* From inside the box, mostly upwards into the thin top. */
    vec3 o =
        v3(0.5 * pcg32_next_double(&rng), 0.5 * pcg32_next_double(&rng), -1 + 2 * pcg32_next_double(&rng));
    double ct = 2 * pcg32_next_double(&rng) - 1, ph = 2 * PI * pcg32_next_double(&rng);
    if (k % 2) ct = 0.2 + 0.8 * pcg32_next_double(&rng);
    double st = sqrt(1 - ct * ct);
    ray3 r = {o, v3(st * cos(ph), st * sin(ph), ct), 0, INFINITY};
    double mint, maxt;
    if (!m->ops->intersect_aabb(m, &r, &mint, &maxt)) continue;
    if (k % 3 == 0) mint = maxt - (maxt - mint) * pow(10, -12 * pcg32_next_double(&rng)); /* short ones */
    double oz = media_layers_z(L, r.o), dz = media_layers_dz(L, r.d);
    double z0 = oz + mint * dz, z1 = oz + maxt * dz;
    double total =
        media_layers_tau(L, 0, z0, z1, media_layer_of(L, z0), media_layer_of(L, z1), dz, maxt - mint);
    if (!(total > 0) || !(total < 1)) continue;
    tmin_seen = fmin(tmin_seen, total);
    double edge = total * MEDIA_LAYERS_PASS_MARGIN;
    for (int j = -66; j <= 66; j++) {
      double base = j < -33 ? total : j > 33 ? edge : 0, u;
      int step = j < -33 ? j + 50 : j > 33 ? j - 50 : 0;
      if (base > 0) {
        u = base;
        for (int q = 0; q < (step < 0 ? -step : step); q++) u = nextafter(u, step < 0 ? 0.0 : 1.0);
      } else {
        u = pcg32_next_double(&rng);
      }
      if (!(u >= 0 && u < 1)) continue;
      medium_interaction mi;
      color tr, pdf;
      memset(&mi, 0, sizeof mi);
      media_layers_sample_real(L, m, &r, mint, maxt, u, 0, &mi, &tr, &pdf);
      bool passed = !isfinite(mi.t);
      bool want = !(rsw_neg_log1m(u) < total);
      flights++;
      fast += u >= edge;
      near += base > 0;
      differ += passed != want;
    }
  }
  printf("  %ld flights (%ld near the margin or total, %ld decided without the log), smallest total %.3g, "
         "%ld differ\n",
         flights, near, fast, tmin_seen, differ);
  CHECK(flights > 100000 && fast > 20000, "enough flights (%ld, %ld without the log)", flights, fast);
  CHECK(tmin_seen < 1e-10, "thin flights (smallest total %g)", tmin_seen);
  CHECK(differ == 0, "%ld flights decided otherwise than the log", differ);
  scene_free(s);
}

/* media_box_clip_aligned with the caller's 1 / d (volpath shares its null
 * boxes') against the slab test as media_box_clip_at did it before (one
 * division per axis inside the loop, written out here): bit for bit, for
 * 40,000 random rays from inside, outside and on the box, directions with
 * zero components among them, over random [tmin, tmax]. */
static bool ref_clip(const media_box *b, const ray3 *r, double *mint, double *maxt) {
  double lo = r->tmin, hi = r->tmax;
  const double o3[3] = {r->o.x, r->o.y, r->o.z}, d3[3] = {r->d.x, r->d.y, r->d.z};
  for (int a = 0; a < 3; a++) {
    double b0 = b->lo[a], b1 = b->hi[a];
    if (d3[a] == 0.0) {
      if (o3[a] < b0 || o3[a] > b1) return false;
      continue;
    }
    double inv = 1.0 / d3[a];
    double ta = (b0 - o3[a]) * inv, tb = (b1 - o3[a]) * inv;
    double t0 = ta > tb ? tb : ta, t1 = ta > tb ? ta : tb;
    lo = t0 > lo ? t0 : lo;
    hi = t1 < hi ? t1 : hi;
  }
  if (!(lo < hi)) return false;
  *mint = lo;
  *maxt = hi;
  return true;
}

static void test_box_clip_shared_inverse(void) {
  xform xf;
  const double mat[4][4] = {{1e6, 0, 0, -5e5}, {0, 3.5, 0, 2}, {0, 0, 120e3, 0}, {0, 0, 0, 1}};
  REQUIRE(xf_from_matrix(mat, &xf), "to_world");
  media_box b;
  media_box_init(&b, &xf);
  REQUIRE(b.aligned, "a scale and translation is aligned");
  pcg32 rng;
  pcg32_seed(&rng, 5, 26);
  int differ = 0, met = 0;
  for (int k = 0; k < 40000; k++) {
    vec3 o = v3(b.lo[0] + (b.hi[0] - b.lo[0]) * (2 * pcg32_next_double(&rng) - 0.5),
                b.lo[1] + (b.hi[1] - b.lo[1]) * (2 * pcg32_next_double(&rng) - 0.5),
                b.lo[2] + (b.hi[2] - b.lo[2]) * (2 * pcg32_next_double(&rng) - 0.5));
    if (k % 17 == 0) o.z = b.hi[2]; /* on the top */
    double ct = 2 * pcg32_next_double(&rng) - 1, ph = 2 * PI * pcg32_next_double(&rng),
           st = sqrt(1 - ct * ct);
    vec3 d = v3(st * cos(ph), st * sin(ph), ct);
    if (k % 5 == 0) d.x = 0;
    if (k % 7 == 0) d.y = 0;
    if (k % 11 == 0) d = v3(0, 0, k % 2 ? 1 : -1); /* hdistant's nadir rays */
    ray3 r = {o, d, k % 3 ? 0.0 : 1e4 * pcg32_next_double(&rng),
              k % 4 ? INFINITY : 1e6 * pcg32_next_double(&rng)};
    double inv[3] = {d.x != 0 ? 1.0 / d.x : 0.0, d.y != 0 ? 1.0 / d.y : 0.0, d.z != 0 ? 1.0 / d.z : 0.0};
    double m0 = 0, M0 = 0, m1 = 0, M1 = 0, m2 = 0, M2 = 0;
    bool a = ref_clip(&b, &r, &m0, &M0);
    bool c = media_box_clip_aligned(&b, r.o, r.d, r.tmin, r.tmax, inv, &m1, &M1);
    bool e = media_box_clip_at(&b, &r, &m2, &M2);
    met += a;
    if (a != c || a != e || memcmp(&m0, &m1, sizeof m0) || memcmp(&M0, &M1, sizeof M0) ||
        memcmp(&m0, &m2, sizeof m0) || memcmp(&M0, &M2, sizeof M0))
      differ++;
  }
  printf("  %d of 40000 rays meet the box, %d differ\n", met, differ);
  CHECK(met > 2000 && met < 38000, "rays both meet and miss the box (%d)", met);
  CHECK(differ == 0, "%d clips differ from the slab test", differ);
}

static void test_rgb_chromatic(void) {
  const char *meds[] = {"{\"type\": \"homogeneous\", \"albedo\": 0, \"sigma_t\": [0.2, 0.5, 1.0]}",
                        "{\"type\": \"piecewise\", \"albedo\": 0, \"sigma_t\": {\"type\": \"gridvolume\","
                        " \"shape\": [2, 1, 1, 3], \"data\": [0.1, 0.4, 1.0, 0.3, 0.6, 1.0],"
                        " \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [40, 40, 1]}]}}"};
  double th = 30 * PI / 180;
  for (int k = 0; k < 2; k++) {
    sbuf b = {0};
    sb_printf(&b,
              "{\"type\": \"scene\", \"integrator\": {\"type\": \"piecewise_volpath\"},"
              " \"slab\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"}, \"interior\": %s,"
              "   \"to_world\": [{\"scale\": [20, 20, 0.5]}, {\"translate\": [0, 0, 0.5]}]},"
              " \"sky\": {\"type\": \"constant\", \"radiance\": 1},"
              " \"meter\": {\"type\": \"radiancemeter\", \"origin\": [%.17g, 0, -2], \"direction\": [%.17g, "
              "0, %.17g],"
              "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}",
              meds[k], -2 * tan(th), sin(th), cos(th));
    scene *s = tsup_load(b.p, "rgb");
    free(b.p);
    REQUIRE(s, "scene");
    film_image img;
    REQUIRE(tsup_render(s, 4, 0, 1, &img), "render");
    const double tau[2][3] = {{0.2, 0.5, 1.0}, {0.2, 0.5, 1.0}};
    for (int c = 0; c < 3 && c < img.channels; c++) {
      double expect = exp(-tau[k][c] / cos(th));
      CHECK(fabs(img.data[c] - expect) <= 1e-5 * expect, "medium %d channel %d: %.9g vs %.9g", k, c,
            img.data[c], expect);
    }
    film_image_free(&img);
    scene_free(s);
  }
  /* Scattering with chromatic extinction (the channel is picked per flight). */
  double m[2][3], se[2][3];
  for (int k = 0; k < 2; k++) {
    vec3 to_view = v3(0.4, 0, 0.9165);
    sbuf b = {0};
    sb_printf(
        &b,
        "{\"type\": \"scene\", \"integrator\": {\"type\": \"%s\"},"
        " \"slab\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
        "   \"interior\": {\"type\": \"piecewise\", \"albedo\": [0.9, 0.7, 0.5], \"sigma_t\": {\"type\": "
        "\"gridvolume\", \"shape\": [2, 1, 1, 3], \"data\": [0.1, 0.4, 1.0, 0.3, 0.6, 1.0],"
        "   \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [40, 40, 1]}]}},"
        "   \"to_world\": [{\"scale\": [20, 20, 0.5]}, {\"translate\": [0, 0, 0.5]}]},"
        " \"sun\": {\"type\": \"directional\", \"direction\": [-0.5, 0, -0.866], \"irradiance\": 1},"
        " \"meter\": {\"type\": \"radiancemeter\", \"origin\": [%.17g, 0, %.17g], \"direction\": [%.17g, 0, "
        "%.17g],"
        "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}",
        k ? "piecewise_volpath" : "volpath", 3 * to_view.x, 3 * to_view.z, -to_view.x, -to_view.z);
    scene *s = tsup_load(b.p, "rgb");
    free(b.p);
    REQUIRE(s, "scene");
    double sum[3] = {0}, sum2[3] = {0};
    for (int r = 1; r <= REPS; r++) {
      film_image img;
      REQUIRE(tsup_render(s, 2048, (uint64_t)r, 2, &img), "render");
      for (int c = 0; c < 3; c++) {
        sum[c] += img.data[c];
        sum2[c] += img.data[c] * img.data[c];
      }
      film_image_free(&img);
    }
    for (int c = 0; c < 3; c++) {
      m[k][c] = sum[c] / REPS;
      se[k][c] = sqrt(fmax(sum2[c] / REPS - m[k][c] * m[k][c], 0) / (REPS - 1));
    }
    scene_free(s);
  }
  for (int c = 0; c < 3; c++)
    CHECK(fabs(m[0][c] - m[1][c]) <= 3 * sqrt(se[0][c] * se[0][c] + se[1][c] * se[1][c]) && m[0][c] > 0,
          "channel %d: volpath %.6g +- %.3g vs piecewise_volpath %.6g +- %.3g", c, m[0][c], se[0][c], m[1][c],
          se[1][c]);
}

/* The same film, bit for bit, with 1 and 3 threads (a hdistant view of the
 * slab over a ground, both integrators). */
static void test_determinism(void) {
  const char *integ[] = {"volpath", "piecewise_volpath"};
  for (int k = 0; k < 2; k++) {
    sbuf b = {0};
    sb_printf(
        &b,
        "{\"type\": \"scene\", \"integrator\": {\"type\": \"%s\"},"
        " \"slab\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
        "   \"interior\": {\"type\": \"heterogeneous\", \"albedo\": 0.8, \"phase\": {\"type\": \"hg\", "
        "\"g\": 0.4},"
        "     \"sigma_t\": {\"type\": \"gridvolume\", \"shape\": [3, 2, 2], \"data\": [0.1, 0.5, 0.9, 0.3, "
        "1.1, 0.2,"
        "       0.7, 0.4, 0.6, 0.8, 0.05, 1.3], \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": "
        "[4, 4, 1]}]}},"
        "   \"to_world\": [{\"scale\": [2, 2, 0.5]}, {\"translate\": [0, 0, 0.5]}]},"
        " \"ground\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 3}, {\"translate\": [0, 0, "
        "-0.2]}]},"
        " \"sun\": {\"type\": \"directional\", \"direction\": [-0.5, 0.2, -0.84], \"irradiance\": 1},"
        " \"sky\": {\"type\": \"constant\", \"radiance\": 0.3},"
        " \"cam\": {\"type\": \"hdistant\", \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
        "   \"film\": {\"type\": \"hdrfilm\", \"width\": 24, \"height\": 24}}}",
        integ[k]);
    scene *s = tsup_load(b.p, "mono");
    free(b.p);
    REQUIRE(s, "scene");
    film_image a, c;
    REQUIRE(tsup_render(s, 0, 5, 1, &a), "render 1 thread");
    REQUIRE(tsup_render(s, 0, 5, 3, &c), "render 3 threads");
    size_t n = (size_t)a.width * a.height * a.channels;
    CHECK(memcmp(a.data, c.data, n * sizeof *a.data) == 0, "%s: films differ between 1 and 3 threads",
          integ[k]);
    double sum = 0;
    for (size_t i = 0; i < n; i++) sum += a.data[i];
    CHECK(sum > 0, "%s: black film", integ[k]);
    film_image_free(&a);
    film_image_free(&c);
    scene_free(s);
  }
}

/* Update equals reload, bitwise: sigma_t.data, albedo.data and scale of a
 * piecewise medium (its cumulative thickness is refreshed), g of its
 * phase function, at two wavelengths. */
static char *layered_scene(const double *sig, const double *alb, double scale, double g) {
  enum {
    N = 6
  };
  sbuf b = {0};
  sb_printf(&b,
            "{\"type\": \"scene\", \"integrator\": {\"type\": \"piecewise_volpath\"},"
            " \"atmo\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
            "   \"to_world\": [{\"scale\": [2, 2, 0.5]}, {\"translate\": [0, 0, 0.5]}],"
            "   \"interior\": {\"type\": \"piecewise\", \"scale\": %.17g, \"phase\": {\"type\": \"hg\", "
            "\"g\": %.17g},"
            "     \"sigma_t\": ",
            scale, g);
  layers_json(&b, sig, N, 1.0, "");
  sb_printf(&b, ", \"albedo\": ");
  layers_json(&b, alb, N, 1.0, "");
  sb_printf(
      &b, "}}, \"ground\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 2}]},"
          " \"sun\": {\"type\": \"directional\", \"direction\": [-0.3, 0, -0.95], \"irradiance\": 1},"
          " \"cam\": {\"type\": \"hdistant\", \"sampler\": {\"type\": \"independent\", \"sample_count\": 8},"
          "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16}}}");
  return b.p;
}

static void test_update_equals_reload(void) {
  /* layers_json's box spans 40 units; the cube bounds it laterally. */
  const double sig0[6] = {0.5, 0.4, 0.3, 0.2, 0.1, 0.05}, sig1[6] = {1.5, 0.2, 0.9, 0.0, 0.3, 0.7};
  const double alb0[6] = {0.9, 0.9, 0.8, 0.8, 0.7, 0.7}, alb1[6] = {0.3, 1.0, 0.5, 0.95, 0.0, 0.6};
  char *t0 = layered_scene(sig0, alb0, 1.0, 0.2), *t1 = layered_scene(sig1, alb1, 2.5, -0.4);
  scene *a = tsup_load(t0, "mono"), *b = tsup_load(t1, "mono");
  free(t0);
  free(t1);
  REQUIRE(a && b, "scenes");
  char v_sig[256], v_alb[256];
  snprintf(v_sig, sizeof v_sig, "[%.17g, %.17g, %.17g, %.17g, %.17g, %.17g]", sig1[0], sig1[1], sig1[2],
           sig1[3], sig1[4], sig1[5]);
  snprintf(v_alb, sizeof v_alb, "[%.17g, %.17g, %.17g, %.17g, %.17g, %.17g]", alb1[0], alb1[1], alb1[2],
           alb1[3], alb1[4], alb1[5]);
  const char *keys[4] = {"atmo.interior_medium.sigma_t.data", "atmo.interior_medium.albedo.data",
                         "atmo.interior_medium.scale", "atmo.interior_medium.phase_function.g"};
  const char *vals[4] = {v_sig, v_alb, "2.5", "-0.4"};
  param_update items[4];
  rsw_err err = {0};
  for (int i = 0; i < 4; i++) {
    items[i].key = keys[i];
    REQUIRE(param_value_parse(vals[i], keys[i], &items[i].value, &err) == RSW_OK, "parse %s: %s", keys[i],
            err.msg);
  }
  /* Render a first (derived data computed for the old values), update it. */
  film_image x;
  REQUIRE(tsup_render(a, 0, 3, 2, &x), "render");
  film_image_free(&x);
  CHECK(scene_update(a, items, 4, NULL, &err) == RSW_OK, "update: %s", err.msg);
  for (int i = 0; i < 4; i++) param_value_free(&items[i].value);
  const double wl[2] = {450, 700};
  for (int w = 0; w < 2; w++) {
    film_image fa, fb;
    rsw_err e2 = {0};
    render_opts o = {.size = sizeof o, .spp = 0, .seed = 9, .threads = 2, .wavelength = wl[w]};
    REQUIRE(render_sensor(a, &o, &fa, NULL, &e2) == RSW_OK, "render a: %s", e2.msg);
    REQUIRE(render_sensor(b, &o, &fb, NULL, &e2) == RSW_OK, "render b: %s", e2.msg);
    size_t n = (size_t)fa.width * fa.height * fa.channels;
    CHECK(fa.width == fb.width && memcmp(fa.data, fb.data, n * sizeof *fa.data) == 0,
          "update != reload at %g nm", wl[w]);
    film_image_free(&fa);
    film_image_free(&fb);
  }
  scene_free(a);
  scene_free(b);
}

/* Null boxes crossed analytically (accel.h ray masks, media.h
 * media_refresh_null_boxes): the layered scene's cube is one, and a
 * render with it analytic matches the same render with it traced (the
 * same draws in the same order: only the crossing points' rounding
 * differs, float32 hits against a double slab test); a to_world update
 * (scale and translation, then a rotation: the object-space path) equals
 * a reload bitwise; 1 vs 3 threads bitwise; a vertex update that bends
 * the cube turns the analytic crossing off. */
static void render_both(scene *s, uint64_t seed, film_image *one, film_image *three) {
  REQUIRE(tsup_render(s, 0, seed, 1, one), "render 1 thread");
  REQUIRE(tsup_render(s, 0, seed, 3, three), "render 3 threads");
}

static bool same_film(const film_image *a, const film_image *b) {
  size_t n = (size_t)a->width * a->height * a->channels;
  return a->width == b->width && a->height == b->height && memcmp(a->data, b->data, n * sizeof *a->data) == 0;
}

static void test_null_box_analytic(void) {
  const double sig[6] = {0.5, 0.4, 0.3, 0.2, 0.1, 0.05}, alb[6] = {0.9, 0.9, 0.8, 0.8, 0.7, 0.7};
  /* The cube reaches below the ground (as Eradiate's atmospheres do): a
   * side on the ground would make the order of the two hits a tie. */
  char *text0 = layered_scene(sig, alb, 1.0, 0.3);
  const char *from = "[{\"scale\": [2, 2, 0.5]}, {\"translate\": [0, 0, 0.5]}]";
  const char *box = "[{\"scale\": [2, 2, 0.55]}, {\"translate\": [0, 0, 0.45]}]";
  char *p0 = strstr(text0, from);
  REQUIRE(p0, "the cube's to_world in the scene text");
  sbuf b0 = {0};
  sb_printf(&b0, "%.*s%s%s", (int)(p0 - text0), text0, box, p0 + strlen(from));
  free(text0);
  char *text = b0.p;
  scene *a = tsup_load(text, "mono");
  accel_set_null_box_masks(false);
  scene *t = tsup_load(text, "mono");
  accel_set_null_box_masks(true);
  REQUIRE(a && t, "scenes");
  CHECK(a->null_boxes.on && a->null_boxes.n == 1, "the cube is crossed analytically");
  CHECK(!t->null_boxes.on, "without masks the cube is traced");
  film_image fa, fa3, ft, ft3;
  render_both(a, 4, &fa, &fa3);
  render_both(t, 4, &ft, &ft3);
  CHECK(same_film(&fa, &fa3) && same_film(&ft, &ft3), "1 vs 3 threads");
  size_t n = (size_t)fa.width * fa.height * fa.channels, close = 0;
  double sa = 0, st = 0;
  for (size_t i = 0; i < n; i++) {
    sa += fa.data[i], st += ft.data[i];
    close += fabs(fa.data[i] - ft.data[i]) <= 1e-4 * fabs(ft.data[i]) + 1e-9;
  }
  CHECK(sa > 0 && fabs(sa - st) <= 1e-3 * st, "analytic %.9g vs traced %.9g", sa, st);
  CHECK(close >= n - n / 50, "%zu of %zu pixels agree to 1e-4", close, n);
  film_image_free(&fa3);
  film_image_free(&ft);
  film_image_free(&ft3);
  scene_free(t);

  /* flip_normals with the medium as exterior: the same media on the same
   * sides, so the same film, bitwise. */
  {
    const char *in = "\"interior\": {\"type\": \"piecewise\"";
    char *p = strstr(text, in);
    REQUIRE(p, "the cube's interior in the scene text");
    sbuf b = {0};
    sb_printf(&b, "%.*s\"flip_normals\": true, \"exterior\": {\"type\": \"piecewise\"%s", (int)(p - text),
              text, p + strlen(in));
    scene *f = tsup_load(b.p, "mono");
    free(b.p);
    REQUIRE(f, "flipped scene");
    CHECK(f->null_boxes.on, "the flipped cube is crossed analytically");
    film_image ff;
    REQUIRE(tsup_render(f, 0, 4, 1, &ff), "render flipped");
    CHECK(same_film(&ff, &fa), "flip_normals + exterior differs from interior");
    film_image_free(&ff);
    scene_free(f);
  }

  /* to_world updates against reloads. */
  const char *xf[2] = {"[[3, 0, 0, 0.25], [0, 2.5, 0, -0.5], [0, 0, 0.75, 0.6], [0, 0, 0, 1]]",
                       "[[1.7320508075688772, -1, 0, 0], [1, 1.7320508075688772, 0, 0], [0, 0, 0.55, 0.45], "
                       "[0, 0, 0, 1]]"};
  const char *xf_load[2] = {"[{\"matrix\": [3, 0, 0, 0.25, 0, 2.5, 0, -0.5, 0, 0, 0.75, 0.6, 0, 0, 0, 1]}]",
                            "[{\"matrix\": [1.7320508075688772, -1, 0, 0, 1, 1.7320508075688772, 0, 0, 0, 0, "
                            "0.55, 0.45, 0, 0, 0, 1]}]"};
  for (int k = 0; k < 2; k++) {
    param_update u = {.key = "atmo.to_world"};
    rsw_err err = {0};
    REQUIRE(param_value_parse(xf[k], u.key, &u.value, &err) == RSW_OK, "parse: %s", err.msg);
    CHECK(scene_update(a, &u, 1, NULL, &err) == RSW_OK, "update: %s", err.msg);
    param_value_free(&u.value);
    CHECK(a->null_boxes.on, "still analytic after a to_world update");
    char *p = strstr(text, box);
    sbuf b = {0};
    sb_printf(&b, "%.*s%s%s", (int)(p - text), text, xf_load[k], p + strlen(box));
    scene *r = tsup_load(b.p, "mono");
    free(b.p);
    REQUIRE(r && r->null_boxes.on, "reload");
    film_image fu, fu3, fr, fr3;
    render_both(a, 6, &fu, &fu3);
    render_both(r, 6, &fr, &fr3);
    CHECK(same_film(&fu, &fr), "to_world update %d != reload", k);
    CHECK(same_film(&fu, &fu3) && same_film(&fr, &fr3), "to_world %d: 1 vs 3 threads", k);
    CHECK(!same_film(&fu, &fa), "to_world %d: the film did not change", k);
    film_image_free(&fu);
    film_image_free(&fu3);
    film_image_free(&fr);
    film_image_free(&fr3);
    scene_free(r);
  }
  film_image_free(&fa);

  /* A vertex moved off the box: no longer a box, traced again. */
  {
    param_update u = {.key = "atmo.vertex_positions"};
    rsw_err err = {0};
    sbuf b = {0};
    sb_printf(&b, "[");
    const shape *cube = a->null_boxes.box[0].sh;
    for (uint32_t v = 0; v < cube->mesh.n_verts; v++)
      for (int c = 0; c < 3; c++) {
        double x = cube->mesh.pos[3 * v + c];
        if (v == 0 && c == 0) x *= 1.25;
        sb_printf(&b, "%s%.9g", v + c ? ", " : "", x);
      }
    sb_printf(&b, "]");
    REQUIRE(param_value_parse(b.p, u.key, &u.value, &err) == RSW_OK, "parse: %s", err.msg);
    free(b.p);
    CHECK(scene_update(a, &u, 1, NULL, &err) == RSW_OK, "vertex update: %s", err.msg);
    param_value_free(&u.value);
    CHECK(!a->null_boxes.on, "a bent box is not crossed analytically");
    film_image fv;
    REQUIRE(tsup_render(a, 0, 2, 2, &fv), "render after the vertex update");
    double sum = 0;
    for (size_t i = 0; i < n; i++) sum += fv.data[i];
    CHECK(sum > 0 && isfinite(sum), "renders");
    film_image_free(&fv);
  }
  free(text);
  scene_free(a);
}

/* A slab in a periodic plot: a slanted ray leaves the cell through its
 * side walls (null faces) and re-enters through the opposite ones, so its
 * path of length 2 through the slab crosses four boundaries; exact. */
static void test_periodic_slab(void) {
  const char *text = "{\"type\": \"scene\", \"integrator\": {\"type\": \"piecewise_volpath\"},"
                     " \"plot\": {\"type\": \"periodic\", \"min\": [-1, -1], \"max\": [1, 1]},"
                     " \"slab\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
                     "   \"interior\": {\"type\": \"homogeneous\", \"sigma_t\": 0.7, \"albedo\": 0},"
                     "   \"to_world\": [{\"scale\": [1, 1, 0.5]}, {\"translate\": [0, 0, 0.5]}]},"
                     " \"sky\": {\"type\": \"constant\", \"radiance\": 1},"
                     " \"m\": {\"type\": \"radiancemeter\", \"origin\": [0.3, 0.2, -0.5],"
                     "   \"direction\": [0.8660254037844386, 0, 0.5],"
                     "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}";
  scene *s = tsup_load(text, "mono");
  REQUIRE(s, "scene");
  double v = render1(s, 4, 1), expect = exp(-0.7 / 0.5);
  CHECK(fabs(v - expect) <= 1e-5 * expect, "periodic slab: %.9g vs %.9g", v, expect);
  scene_free(s);
}

/* ---- scene-level errors ------------------------------------------------------ */

static void expect_error(const char *text, const char *needle, const char *loc) {
  rsw_err err = {0};
  scene *s = NULL;
  scene_load_opts o = {.variant = "mono"};
  rsw_status st = scene_load_memory(text, strlen(text), NULL, text[0] == '<', &o, &s, &err);
  CHECK(st != RSW_OK, "loaded a scene that should fail (%s)", needle);
  if (st == RSW_OK) {
    scene_free(s);
    return;
  }
  CHECK(strstr(err.msg, needle) != NULL, "error '%s' lacks '%s'", err.msg, needle);
  size_t lw = strlen(err.where), ll = loc ? strlen(loc) : 0;
  if (loc)
    CHECK(lw >= ll && strcmp(err.where + lw - ll, loc) == 0, "error at '%s', expected '...%s'", err.where,
          loc);
}

static void test_media_errors(void) {
  expect_error("{\"type\": \"scene\", \"fog\": {\"type\": \"homogeneous\"},"
               " \"s\": {\"type\": \"radiancemeter\", \"origin\": [0,0,0], \"direction\": [0,0,1],"
               "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}",
               "has no boundary", "/fog");
  expect_error(
      "{\"type\": \"scene\", \"fog\": {\"type\": \"homogeneous\"},"
      " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": \"ref\", "
      "\"id\": \"fog\"}},"
      " \"s\": {\"type\": \"radiancemeter\", \"origin\": [0,0,5], \"direction\": [0,0,1],"
      "   \"medium\": {\"type\": \"ref\", \"id\": \"fog\"},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}",
      "does not sit inside its medium", "/s");
  /* XML: the error names the medium's line. */
  expect_error("<scene version=\"3.0.0\">\n"
               "  <emitter type=\"constant\"/>\n"
               "  <medium type=\"homogeneous\" id=\"fog\"><float name=\"sigma_t\" value=\"0.5\"/></medium>\n"
               "</scene>\n",
               "medium 'fog' has no boundary", ":3");
  /* The same scene with a null sphere around the medium renders. */
  const char *xml =
      "<scene version=\"3.0.0\">\n"
      "  <integrator type=\"volpath\"/>\n"
      "  <emitter type=\"constant\"/>\n"
      "  <medium type=\"homogeneous\" id=\"fog\"><float name=\"sigma_t\" value=\"0.5\"/>\n"
      "    <float name=\"albedo\" value=\"1\"/><phase type=\"hg\"><float name=\"g\" value=\"0.7\"/></phase>\n"
      "  </medium>\n"
      "  <shape type=\"sphere\"><bsdf type=\"null\"/><ref name=\"interior\" id=\"fog\"/></shape>\n"
      "  <sensor type=\"radiancemeter\"><point name=\"origin\" x=\"0\" y=\"0\" z=\"3\"/>\n"
      "    <vector name=\"direction\" x=\"0\" y=\"0\" z=\"-1\"/>\n"
      "    <film type=\"hdrfilm\"><integer name=\"width\" value=\"1\"/><integer name=\"height\" "
      "value=\"1\"/></film>\n"
      "  </sensor>\n"
      "</scene>\n";
  scene *sx = tsup_load(xml, "mono");
  CHECK(sx != NULL, "the XML medium scene loads");
  if (sx) {
    double v = render1(sx, 256, 1);
    CHECK(fabs(v - 1) < 0.05, "XML furnace: %.6g vs 1", v);
    scene_free(sx);
  }
  /* The same sensor inside the ball loads. */
  const char *ok =
      "{\"type\": \"scene\", \"fog\": {\"type\": \"homogeneous\"},"
      " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": "
      "\"ref\", \"id\": \"fog\"}},"
      " \"s\": {\"type\": \"radiancemeter\", \"origin\": [0,0,0.5], \"direction\": [0,0,1],"
      "   \"medium\": {\"type\": \"ref\", \"id\": \"fog\"},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}";
  scene *s = tsup_load(ok, "mono");
  CHECK(s != NULL, "a sensor inside its medium loads");
  scene_free(s);
  expect_error("{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"},"
               " \"interior\": {\"type\": \"piecewise\", \"sigma_t\": {\"type\": \"gridvolume\","
               " \"shape\": [2, 1, 2], \"data\": [1, 2, 3, 4]}}}}",
               "[1, 1, N] grid", "/ball/interior/sigma_t");
  expect_error("{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"null\"},"
               " \"interior\": {\"type\": \"piecewise\", \"sigma_t\": {\"type\": \"gridvolume\","
               " \"shape\": [3, 1, 1], \"data\": [1, 2, 3]}, \"albedo\": {\"type\": \"gridvolume\","
               " \"shape\": [2, 1, 1], \"data\": [0.5, 0.5]}}}}",
               "albedo must be constant or a [1, 1, 3] grid", "/ball/interior/albedo");
  expect_error(
      "{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"interior\": {\"type\": \"homogeneous\","
      " \"albedo\": 1.5}}}",
      "albedo", NULL);
  expect_error(
      "{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"interior\": {\"type\": \"homogeneous\","
      " \"sigma_t\": -1}}}",
      "sigma_t", NULL);
  expect_error(
      "{\"type\": \"scene\", \"ball\": {\"type\": \"sphere\", \"interior\": {\"type\": \"homogeneous\","
      " \"phase\": {\"type\": \"nosuchphase\"}}}}",
      "nosuchphase", NULL);
}

/* A sensor inside an infinite (unbounded) absorbing medium, looking at a
 * lit plate: the plate's radiance times exp(-sigma_t d). Exact. */
static void test_sensor_in_medium(void) {
  const char *text =
      "{\"type\": \"scene\", \"integrator\": {\"type\": \"volpath\"},"
      " \"fog\": {\"type\": \"homogeneous\", \"sigma_t\": 0.25, \"albedo\": 0},"
      " \"lamp\": {\"type\": \"rectangle\", \"emitter\": {\"type\": \"area\", \"radiance\": 2}},"
      " \"s\": {\"type\": \"radiancemeter\", \"origin\": [0, 0, 3], \"direction\": [0, 0, -1],"
      "   \"medium\": {\"type\": \"ref\", \"id\": \"fog\"},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}";
  scene *s = tsup_load(text, "mono");
  REQUIRE(s, "scene");
  /* The meter's origin is nudged along its direction by Mitsuba's
   * RayEpsilon (1500 float32 units: 9e-5 here), so 1e-4 relative. */
  double v = render1(s, 4, 0), expect = 2 * exp(-0.75);
  CHECK(fabs(v - expect) <= 1e-4 * expect, "sensor in fog: %.9g vs %.9g", v, expect);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_piecewise_exact_ops);
  RSW_TEST_RUN(test_layer_index_search);
  RSW_TEST_RUN(test_flight_pass_margin);
  RSW_TEST_RUN(test_box_clip_shared_inverse);
  RSW_TEST_RUN(test_beer_lambert_homogeneous);
  RSW_TEST_RUN(test_beer_lambert_heterogeneous_constant);
  RSW_TEST_RUN(test_beer_lambert_piecewise_one_layer);
  RSW_TEST_RUN(test_sensor_in_medium);
  RSW_TEST_RUN(test_media_errors);
  RSW_TEST_RUN(test_single_scattering);
  RSW_TEST_RUN(test_furnace_sphere);
  RSW_TEST_RUN(test_furnace_atmosphere_white_ground);
  RSW_TEST_RUN(test_integrators_agree);
  RSW_TEST_RUN(test_beer_lambert_layers);
  RSW_TEST_RUN(test_piecewise_agrees);
  RSW_TEST_RUN(test_rgb_chromatic);
  RSW_TEST_RUN(test_determinism);
  RSW_TEST_RUN(test_update_equals_reload);
  RSW_TEST_RUN(test_periodic_slab);
  RSW_TEST_RUN(test_null_box_analytic);
  RSW_TEST_END("test_media");
}
