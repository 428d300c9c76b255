/* `molecular_atmosphere` against published values and closed forms
 * (docs/atmosphere.md):
 *  - Rayleigh cross section vs Bodhaine et al. (1999) eq. (29) (0.05 %),
 *    Rayleigh optical thickness of the US standard atmosphere at 550 nm vs
 *    their 0.0973 at 1013.25 hPa (1 %: the AFGL column is the table's, not
 *    the hydrostatic one);
 *  - the US standard O3 column vs 345 DU (1 %), column independent of the
 *    levels (1e-12);
 *  - direct transmittance through the atmosphere = exp(-tau / mu) at
 *    several wavelengths and zeniths (albedo 0: exact up to float32 films,
 *    2e-6), and the medium's transmittance op along slant rays with
 *    scattering on (1e-12);
 *  - a wavelength sweep of molecular_atmosphere equals the same layers
 *    given to piecewise + blendphase, bitwise (same seed, 2 threads), in
 *    mono and in mono_polarized (S0..S3: the two phase matrices);
 *  - particle layers: tau at w_ref = tau_ref (1e-12) for every
 *    distribution, the Angstrom law at another wavelength, an extinction
 *    spectrum's ratio;
 *  - the Thuillier solar spectrum as a directional irradiance;
 *  - every refusal names the property. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/media/atmo_data.h"
#include "../../../server/kernel/media/molecular_atmosphere.h"
#include "../../../server/kernel/render.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/scene.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define TOP 120e3
#define W   1e6

/* The variant atmo_scene loads in (test_sweep_equals_piecewise sets
 * mono_polarized too). */
static const char *atmo_variant = "mono";

static void levels(sbuf *b, int n) {
  sb_printf(b, "[");
  for (int k = 0; k <= n; k++) sb_printf(b, "%s%.17g", k ? ", " : "", TOP * k / n);
  sb_printf(b, "]");
}

/* An atmosphere medium (JSON) in a null cube 100 m deeper than it, a
 * constant sky of radiance 1 (or a sun), a meter or an hdistant. */
static scene *atmo_scene(const char *med, const char *light, const char *sens, const char *ground) {
  sbuf b = {0};
  double half = (TOP + 100) / 2;
  sb_printf(&b,
            "{\"type\": \"scene\", \"integrator\": {\"type\": \"piecewise_volpath\"},"
            " \"medium_atmosphere\": %s,"
            " \"shape_atmosphere\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
            "   \"interior\": {\"type\": \"ref\", \"id\": \"medium_atmosphere\"},"
            "   \"to_world\": [{\"scale\": [%.17g, %.17g, %.17g]}, {\"translate\": [0, 0, %.17g]}]},"
            " \"illumination\": %s, \"measure\": %s",
            med, W / 2, W / 2, half, TOP - half, light, sens);
  if (ground) sb_printf(&b, ", \"surface\": %s", ground);
  sb_printf(&b, "}");
  scene *s = tsup_load(b.p, atmo_variant);
  free(b.p);
  return s;
}

static const medium *find_medium(const scene *s) {
  for (size_t i = 0; i < s->n_objects; i++)
    if (s->objects[i]->plugin && strcmp(s->objects[i]->plugin->name, "molecular_atmosphere") == 0)
      return (const medium *)s->objects[i];
  return NULL;
}

static bool render_at(scene *s, double wl, uint32_t spp, uint64_t seed, film_image *out) {
  rsw_err err = {0};
  render_opts o = {.size = sizeof o, .spp = spp, .seed = seed, .threads = 2, .wavelength = wl};
  if (render_sensor(s, &o, out, NULL, &err)) {
    char buf[1200];
    printf("  render failed: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  return true;
}

/* sum sigma_t dz of the medium's layers at wl. */
static double medium_tau(const medium *m, double wl) {
  const double *z, *st, *al, *w;
  uint32_t n;
  size_t np;
  if (!molecular_atmosphere_layers(m, wl, &z, &n, &st, &al, &w, &np)) return NAN;
  double tau = 0;
  for (uint32_t k = 0; k < n; k++) tau += st[k] * (z[k + 1] - z[k]);
  return tau;
}

static char *us_standard(int n, const char *extra) {
  sbuf b = {0};
  sb_printf(
      &b, "{\"type\": \"molecular_atmosphere\", \"thermoprops\": {\"identifier\": \"afgl_1986-us_standard\", "
          "\"z\": ");
  levels(&b, n);
  sb_printf(&b, "}%s%s}", extra[0] ? ", " : "", extra);
  return b.p;
}

static const char *METER_UP =
    "{\"type\": \"radiancemeter\", \"origin\": [0, 0, -500], \"direction\": [0, 0, 1],"
    " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1,"
    " \"rfilter\": {\"type\": \"box\"}}}";

/* ---- Rayleigh and ozone --------------------------------------------------- */

static void test_rayleigh_bodhaine(void) {
  /* Bodhaine et al. (1999) eq. (29): their fit to eqs. (16)-(23) at 360 ppm
   * CO2, 1e-28 cm^2, lambda in micrometres. */
  const double wls[] = {350, 450, 550, 700, 1000};
  for (size_t i = 0; i < sizeof wls / sizeof wls[0]; i++) {
    double l = wls[i] * 1e-3, l2 = l * l;
    double fit = (1.0455996 - 341.29061 / l2 - 0.90230850 * l2) / (1 + 0.0027059889 / l2 - 85.968563 * l2);
    double s = atmo_rayleigh_cross_section(wls[i]) * 1e4 / 1e-28;
    CHECK(fabs(s / fit - 1) < 5e-4, "sigma_R(%g nm) = %.6g e-28 cm^2 vs Bodhaine eq. 29 %.6g", wls[i], s,
          fit);
  }
  char *med = us_standard(120, "\"has_absorption\": false");
  scene *s = atmo_scene(med, "{\"type\": \"constant\"}", METER_UP, NULL);
  free(med);
  REQUIRE(s, "scene");
  double tau = medium_tau(find_medium(s), 550);
  CHECK(fabs(tau - 0.0973) < 0.01 * 0.0973, "Rayleigh tau(550 nm) = %.5f vs Bodhaine 1999 0.0973 (1 %%)",
        tau);
  printf("  Rayleigh optical thickness, US standard, 550 nm: %.5f\n", tau);
  /* lambda^-4-ish: tau(450) / tau(550) */
  double r = medium_tau(find_medium(s), 450) / tau;
  CHECK(r > pow(550.0 / 450, 4.0) && r < pow(550.0 / 450, 4.2), "tau ratio 450/550 = %.4f", r);
  scene_free(s);
}

static void test_ozone_column(void) {
  /* The cross section at the 253.65 nm mercury line, room temperature:
   * 1.147e-17 cm^2 (Hearn 1961), 1.137e-17 (Molina and Molina 1986); 3 %. */
  double c[3];
  REQUIRE(atmo_o3_coefficients(253.65, c), "253.65 nm in the table");
  double sig = (c[0] + c[1] * 20 + c[2] * 400) * 1e-20;
  CHECK(fabs(sig - 1.14e-17) < 0.03 * 1.14e-17, "sigma_O3(253.65 nm, 293 K) = %.4g cm^2 vs 1.14e-17", sig);
  CHECK(!atmo_o3_coefficients(229.9, c), "below the table must be refused");
  CHECK(atmo_o3_coefficients(1200, c) && c[0] == 0, "above the table: 0");
  double cols[2];
  const int ns[2] = {120, 7};
  for (int i = 0; i < 2; i++) {
    sbuf b = {0};
    sb_printf(&b, "{\"type\": \"molecular_atmosphere\", \"thermoprops\": {\"identifier\": "
                  "\"afgl_1986-us_standard\", \"z\": ");
    if (i == 0)
      levels(&b, ns[0]);
    else
      sb_printf(&b, "[0, 1000, 2500, 10000, 22000, 47000, 80000, 120000]");
    sb_printf(&b, "}}");
    scene *s = atmo_scene(b.p, "{\"type\": \"constant\"}", METER_UP, NULL);
    free(b.p);
    REQUIRE(s, "scene");
    double air, o3;
    REQUIRE(molecular_atmosphere_columns(find_medium(s), &air, &o3), "columns");
    cols[i] = o3 / 2.6867e20; /* 1 DU = 2.6867e16 cm^-2 */
    scene_free(s);
  }
  CHECK(fabs(cols[0] - 345) < 0.01 * 345, "US standard O3 column %.2f DU vs 345 DU (1 %%)", cols[0]);
  CHECK(fabs(cols[1] / cols[0] - 1) < 1e-12, "O3 column depends on the levels: %.12g vs %.12g DU", cols[1],
        cols[0]);
  printf("  US standard O3 column: %.2f DU\n", cols[0]);
}

/* ---- direct transmittance ------------------------------------------------- */

static void test_direct_transmittance(void) {
  /* Absorption only (O3 + a user sigma_a + an absorbing aerosol): a meter
   * under the atmosphere looking up at a sky of radiance 1 sees
   * exp(-tau / mu) exactly; unequal layers. */
  const char *med =
      "{\"type\": \"molecular_atmosphere\", \"has_scattering\": false,"
      " \"thermoprops\": {\"identifier\": \"afgl_1986-midlatitude_summer\","
      "   \"z\": [0, 500, 1500, 3000, 8000, 15000, 30000, 60000, 120000]},"
      " \"sigma_a\": {\"type\": \"spectrum\", \"wavelengths\": [300, 1000], \"values\": [2e-6, 1e-6]},"
      " \"particle_layers\": [{\"bottom\": 0, \"top\": 2000, \"tau_ref\": 0.1, \"albedo\": 0,"
      "   \"angstrom\": 1.2}]}";
  const double wls[] = {320, 450, 600, 900}, ths[] = {0, 30, 60};
  for (int j = 0; j < 3; j++) {
    double th = ths[j] * M_PI / 180, mu = cos(th);
    char meter[512];
    snprintf(
        meter, sizeof meter,
        "{\"type\": \"radiancemeter\", \"origin\": [%.17g, 0, -500], \"direction\": [%.17g, 0, %.17g],"
        " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}}",
        -500 * tan(th), sin(th), mu);
    scene *s = atmo_scene(med, "{\"type\": \"constant\", \"radiance\": 1}", meter, NULL);
    REQUIRE(s, "scene");
    for (size_t i = 0; i < sizeof wls / sizeof wls[0]; i++) {
      film_image img;
      REQUIRE(render_at(s, wls[i], 4, 1, &img), "render");
      double tau = medium_tau(find_medium(s), wls[i]), expect = exp(-tau / mu);
      CHECK(fabs(img.data[0] - expect) <= 2e-6 * expect,
            "%g nm, %g deg: L = %.9g vs exp(-tau/mu) = %.9g (tau %.6g)", wls[i], ths[j], img.data[0], expect,
            tau);
      CHECK(tau > 0.1, "%g nm: tau %.4g suspiciously small", wls[i], tau);
      film_image_free(&img);
    }
    scene_free(s);
  }
  /* With scattering: the medium's own transmittance along slant rays from
   * the ground to the top (the direct beam) is exp(-tau / mu). */
  char *m2 = us_standard(240, "\"particle_layers\": [{\"bottom\": 0, \"top\": 3000, \"tau_ref\": 0.3, "
                              "\"distribution\": {\"type\": \"exponential\", \"scale_height\": 1000}}]");
  scene *s = atmo_scene(m2, "{\"type\": \"constant\"}", METER_UP, NULL);
  free(m2);
  REQUIRE(s, "scene");
  const medium *m = find_medium(s);
  for (size_t i = 0; i < sizeof wls / sizeof wls[0]; i++) {
    rsw_err err = {0};
    render_ctx rc = {.variant = VARIANT_MONO, .wavelength = wls[i]};
    REQUIRE(scene_prepare(s, &rc, &err) == RSW_OK, "prepare");
    double tau = medium_tau(m, wls[i]);
    for (int j = 0; j < 3; j++) {
      double th = ths[j] * M_PI / 180, mu = cos(th);
      ray3 r = {.o = v3(0, 0, 0), .d = v3(sin(th), 0, mu), .tmin = 0, .tmax = INFINITY};
      double t0, t1;
      REQUIRE(m->ops->intersect_aabb(m, &r, &t0, &t1), "box");
      double tr = m->ops->transmittance(m, &r, t0, t1).c[0], expect = exp(-tau / mu);
      CHECK(fabs(tr - expect) <= 1e-12, "transmittance %g nm %g deg: %.15g vs %.15g", wls[i], ths[j], tr,
            expect);
    }
  }
  scene_free(s);
}

/* ---- the same layers through piecewise, bitwise ----------------------------- */

static void sweep_equals_piecewise(void) {
  const int n = 60;
  char *mol = us_standard(n, "\"width\": 1000000, \"particle_layers\": [{\"bottom\": 0, \"top\": 4000, "
                             "\"tau_ref\": 0.2, \"angstrom\": 1.3, \"albedo\": 0.9, "
                             "\"phase\": {\"type\": \"hg\", \"g\": 0.7}}]");
  const char *sun =
      "{\"type\": \"directional\", \"direction\": [-0.5, 0, -0.8660254037844386], \"irradiance\": 1}";
  const char *hd = "{\"type\": \"hdistant\", \"target\": [0, 0, 0], \"film\": {\"type\": \"hdrfilm\", "
                   "\"width\": 6, \"height\": 6, \"rfilter\": {\"type\": \"box\"}}}";
  const char *ground = "{\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.3},"
                       " \"to_world\": {\"scale\": [500000, 500000, 1]}}";
  scene *a = atmo_scene(mol, sun, hd, ground);
  free(mol);
  REQUIRE(a, "scene");
  const double wls[] = {400, 550, 800};
  for (size_t i = 0; i < 3; i++) {
    film_image fa, fb;
    REQUIRE(render_at(a, wls[i], 16, 7, &fa), "render molecular");
    const double *z, *st, *al, *w;
    uint32_t nl;
    size_t np;
    REQUIRE(molecular_atmosphere_layers(find_medium(a), wls[i], &z, &nl, &st, &al, &w, &np), "layers");
    sbuf b = {0};
    const char *grid =
        "\"shape\": [%u, 1, 1], \"filter_type\": \"nearest\", \"to_world\": [{\"scale\": [%.17g, "
        "%.17g, %.17g]}, {\"translate\": [%.17g, %.17g, 0]}]";
    const double *arr[3] = {st, al, w};
    const char *names[3] = {"sigma_t", "albedo", "weight"};
    sb_printf(&b, "{\"type\": \"piecewise\", ");
    for (int g = 0; g < 3; g++) {
      if (g == 2)
        sb_printf(&b, "\"phase\": {\"type\": \"blendphase\", \"phase_0\": {\"type\": \"rayleigh\"}, "
                      "\"phase_1\": {\"type\": \"hg\", \"g\": 0.7}, ");
      sb_printf(&b, "\"%s\": {\"type\": \"gridvolume\", \"data\": [", names[g]);
      for (uint32_t k = 0; k < nl; k++) sb_printf(&b, "%s%.17g", k ? ", " : "", arr[g][k]);
      sb_printf(&b, "], ");
      sb_printf(&b, grid, nl, W, W, TOP, -W / 2, -W / 2);
      sb_printf(&b, "}%s", g < 1 ? ", " : g == 1 ? ", " : "}}");
    }
    scene *pb = atmo_scene(b.p, sun, hd, ground);
    free(b.p);
    REQUIRE(pb, "piecewise scene");
    REQUIRE(render_at(pb, wls[i], 16, 7, &fb), "render piecewise");
    size_t bytes = (size_t)fa.width * fa.height * fa.channels * sizeof(float);
    CHECK(fa.width == fb.width && memcmp(fa.data, fb.data, bytes) == 0,
          "%g nm: molecular_atmosphere and the same layers as piecewise differ (pixel 0: %.9g vs %.9g)",
          wls[i], fa.data[0], fb.data[0]);
    double mean = 0, q = 0;
    for (int p = 0; p < fa.width * fa.height; p++) {
      mean += fa.data[p * fa.channels];
      if (fa.channels == 4) q += fabs(fa.data[p * 4 + 1]);
    }
    CHECK(mean > 0, "%g nm: black film", wls[i]);
    CHECK(fa.channels != 4 || q > 1e-3 * mean, "%g nm: no polarization (sum |S1| %g, S0 %g)", wls[i], q,
          mean);
    film_image_free(&fa);
    film_image_free(&fb);
    scene_free(pb);
  }
  scene_free(a);
}

/* In mono, and in mono_polarized (the phase matrices: molecular_atmosphere's
 * mixture against blendphase's, S0..S3 bit for bit). */
static void test_sweep_equals_piecewise(void) {
  sweep_equals_piecewise();
  atmo_variant = "mono_polarized";
  sweep_equals_piecewise();
  atmo_variant = "mono";
}

/* ---- particle layers ---------------------------------------------------------- */

static void test_particle_tau(void) {
  const char *dists[] = {"\"uniform\"", "{\"type\": \"exponential\", \"rate\": 3}",
                         "{\"type\": \"exponential\", \"scale_height\": 700}",
                         "{\"type\": \"gaussian\", \"mean\": 0.3, \"std\": 0.1}"};
  for (size_t d = 0; d < 4; d++) {
    char extra[512];
    snprintf(extra, sizeof extra,
             "\"has_absorption\": false, \"has_scattering\": false, \"particle_layers\": [{\"bottom\": 1000, "
             "\"top\": 5000, \"tau_ref\": 0.35, \"w_ref\": 500, \"angstrom\": 1.4, \"distribution\": %s}]",
             dists[d]);
    char *med = us_standard(97, extra); /* layers that do not line up with bottom and top */
    scene *s = atmo_scene(med, "{\"type\": \"constant\"}", METER_UP, NULL);
    free(med);
    REQUIRE(s, "scene %zu", d);
    const medium *m = find_medium(s);
    double t500 = medium_tau(m, 500), t1000 = medium_tau(m, 1000);
    CHECK(fabs(t500 - 0.35) < 1e-12, "%s: tau(w_ref) = %.15g vs tau_ref 0.35", dists[d], t500);
    CHECK(fabs(t1000 - 0.35 * pow(2.0, -1.4)) < 1e-12, "%s: tau(1000) = %.15g vs Angstrom %.15g", dists[d],
          t1000, 0.35 * pow(2.0, -1.4));
    scene_free(s);
  }
  /* an extinction spectrum instead of the Angstrom law; two layers add */
  char *med = us_standard(120, "\"has_absorption\": false, \"has_scattering\": false, \"particle_layers\": ["
                               "{\"bottom\": 0, \"top\": 2000, \"tau_ref\": 0.2, \"extinction\": {\"type\": "
                               "\"spectrum\", \"wavelengths\": [400, 550, 1000], \"values\": [2, 1.5, 0.5]}},"
                               "{\"bottom\": 10000, \"top\": 12000, \"tau_ref\": 0.05}]");
  scene *s = atmo_scene(med, "{\"type\": \"constant\"}", METER_UP, NULL);
  free(med);
  REQUIRE(s, "scene");
  double t = medium_tau(find_medium(s), 400);
  CHECK(fabs(t - (0.2 * 2 / 1.5 + 0.05)) < 1e-12, "extinction spectrum: tau(400) = %.15g vs %.15g", t,
        0.2 * 2 / 1.5 + 0.05);
  scene_free(s);
}

/* ---- parameters: tau_ref per context ------------------------------------------ */

static void test_parameter_update(void) {
  char *med = us_standard(120, "\"has_absorption\": false, \"has_scattering\": false, \"particle_layers\": "
                               "[{\"bottom\": 0, \"top\": 2000, \"tau_ref\": 0.2, \"albedo\": 0}]");
  scene *s = atmo_scene(med, "{\"type\": \"constant\"}", METER_UP, NULL);
  free(med);
  REQUIRE(s, "scene");
  rsw_err err = {0};
  film_image img0;
  REQUIRE(render_at(s, 550, 4, 1, &img0), "render");
  CHECK(fabs(img0.data[0] - exp(-0.2)) < 2e-6, "tau_ref 0.2: L = %.9g vs %.9g", img0.data[0], exp(-0.2));
  film_image_free(&img0);
  param_update up = {.key = "medium_atmosphere.particle_layer_0.tau_ref",
                     .value = {.kind = PV_NUMBER, .num = 0.5}};
  rsw_status st = scene_update(s, &up, 1, NULL, &err);
  CHECK(st == RSW_OK, "update: %s", err.msg);
  film_image img;
  REQUIRE(render_at(s, 550, 4, 1, &img), "render");
  CHECK(fabs(img.data[0] - exp(-0.5)) < 2e-6, "after tau_ref = 0.5: L = %.9g vs %.9g", img.data[0],
        exp(-0.5));
  film_image_free(&img);
  scene_free(s);
}

/* ---- solar spectrum ------------------------------------------------------------ */

static void test_solar_irradiance(void) {
  const char *sun = "{\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": {\"type\": "
                    "\"solar_irradiance\", \"dataset\": \"thuillier_2003\", \"earth_sun_distance\": 1.01}}";
  char *med = us_standard(12, "");
  scene *s = atmo_scene(med, sun, METER_UP, NULL);
  free(med);
  REQUIRE(s, "scene");
  const atmo_solar_table *t = &atmo_solar_thuillier_2003;
  int i = 1000;
  rsw_err err = {0};
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = t->wl[i]};
  REQUIRE(scene_prepare(s, &rc, &err) == RSW_OK, "prepare: %s", err.msg);
  color e;
  REQUIRE(render_horizontal_irradiance(s, &e, &err) == RSW_OK, "E_h: %s", err.msg);
  double expect = t->mw[i] * 1e-3 / (1.01 * 1.01);
  CHECK(fabs(e.c[0] - expect) < 1e-12 * expect, "solar E(%g nm) = %.12g vs %.12g W/m2/nm", t->wl[i], e.c[0],
        expect);
  CHECK(fabs(t->wl[0] - 199.12) < 1e-9 && t->n > 8000, "Thuillier table starts at %g nm, %d values", t->wl[0],
        t->n);
  scene_free(s);
}

/* ---- refusals ------------------------------------------------------------------- */

static void expect_error(const char *med, const char *variant, const char *needle, const char *loc) {
  sbuf b = {0};
  sb_printf(
      &b,
      "{\"type\": \"scene\", \"medium_atmosphere\": %s, \"shape_atmosphere\": {\"type\": \"cube\", "
      "\"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": \"ref\", \"id\": \"medium_atmosphere\"}}}",
      med);
  rsw_err err = {0};
  scene *s = NULL;
  scene_load_opts o = {.variant = variant};
  rsw_status st = scene_load_memory(b.p, strlen(b.p), NULL, false, &o, &s, &err);
  free(b.p);
  CHECK(st != RSW_OK, "loaded a scene that should fail (%s)", needle);
  if (st == RSW_OK) {
    scene_free(s);
    return;
  }
  CHECK(strstr(err.msg, needle) != NULL, "error '%s' lacks '%s'", err.msg, needle);
  size_t lw = strlen(err.where), ll = strlen(loc);
  CHECK(lw >= ll && strcmp(err.where + lw - ll, loc) == 0, "error at '%s', expected '...%s'", err.where, loc);
}

#define MA(tp, rest) "{\"type\": \"molecular_atmosphere\", \"thermoprops\": " tp rest "}"
#define US(z)        "{\"identifier\": \"afgl_1986-us_standard\", \"z\": " z "}"

static void test_refusals(void) {
  expect_error(MA("{\"identifier\": \"afgl_1986-us_standrd\", \"z\": [0, 1000]}", ""), "mono",
               "afgl_1986-us_standard, afgl_1986-tropical, afgl_1986-midlatitude_summer, "
               "afgl_1986-midlatitude_winter, afgl_1986-subarctic_summer, afgl_1986-subarctic_winter",
               "/thermoprops/identifier");
  expect_error(MA(US("[100, 1000]"), ""), "mono", "must start at 0", "/thermoprops/z");
  expect_error(MA(US("[0, 1000, 1000, 2000]"), ""), "mono", "increase strictly", "/thermoprops/z");
  expect_error(MA(US("[0, 2000, 1000]"), ""), "mono", "increase strictly", "/thermoprops/z");
  expect_error(MA(US("[0, 1e999]"), ""), "mono", "finite", "/thermoprops/z");
  expect_error(MA(US("[0, 130000]"), ""), "mono", "above the AFGL", "/thermoprops/z");
  expect_error(MA("{\"z\": [0, 1000]}", ""), "mono", "needs 'p'", "/thermoprops");
  expect_error(MA("{\"z\": [0, 1000], \"p\": [1e5, 9e4], \"t\": [288, 280], \"n_air\": [2.5e25, -1], "
                  "\"n_o3\": [0, 0]}",
                  ""),
               "mono", "n_air[1] = -1", "/thermoprops/n_air");
  expect_error(MA("{\"z\": [0, 1000], \"p\": [1e5, 9e4], \"t\": [288], \"n_air\": [2.5e25, 2e25], "
                  "\"n_o3\": [0, 0]}",
                  ""),
               "mono", "one per level", "/thermoprops/t");
  expect_error(MA(US("[0, 1000]"), ", \"thermoprop_typo\": 1"), "mono", "thermoprop_typo",
               "/thermoprop_typo");
  expect_error(MA("{\"identifier\": \"afgl_1986-tropical\", \"z\": [0, 1000], \"zz\": 1}", ""), "mono",
               "'zz'", "/thermoprops/zz");
  expect_error("{\"type\": \"molecular_atmosphere\"}", "mono", "needs \"thermoprops\"", "/medium_atmosphere");
  expect_error(MA(US("[0, 1000, 5000]"), ", \"particle_layers\": [{\"bottom\": 3000, \"top\": 2000}]"),
               "mono", "must lie below top", "/particle_layers/0/top");
  expect_error(MA(US("[0, 1000, 5000]"), ", \"particle_layers\": [{\"bottom\": 3000, \"top\": 9000}]"),
               "mono", "above the atmosphere's top", "/particle_layers/0/top");
  expect_error(
      MA(US("[0, 1000, 5000]"), ", \"particle_layers\": [{\"top\": 2000, \"distribution\": \"lognormal\"}]"),
      "mono", "unknown distribution 'lognormal'", "/particle_layers/0/distribution");
  expect_error(MA(US("[0, 1000, 5000]"),
                  ", \"particle_layers\": [{\"top\": 2000, \"distribution\": {\"type\": \"cauchy\"}}]"),
               "mono", "unknown distribution 'cauchy'", "/particle_layers/0/distribution");
  expect_error(MA(US("[0, 1000, 5000]"), ", \"particle_layers\": [{\"top\": 2000, \"distribution\": "
                                         "{\"type\": \"gaussian\", \"mean\": 40, \"std\": 0.01}}]"),
               "mono", "no mass", "/particle_layers/0/distribution/mean");
  expect_error(MA(US("[0, 1000, 5000]"), ", \"particle_layers\": [{\"top\": 2000, \"tau_ref\": -1}]"), "mono",
               "tau_ref", "/particle_layers/0/tau_ref");
  expect_error(MA(US("[0, 1000, 5000]"), ", \"particle_layers\": [{\"top\": 2000, \"albedo\": 1.5}]"), "mono",
               "albedo", "/particle_layers/0/albedo");
  expect_error(MA(US("[0, 1000, 5000]"),
                  ", \"particle_layers\": [{\"top\": 2000, \"angstrom\": 1, \"extinction\": "
                  "{\"type\": \"spectrum\", \"value\": [[400, 1], [800, 0.5]]}}]"),
               "mono", "not both", "/particle_layers/0/angstrom");
  expect_error(MA(US("[0, 1000, 5000]"), ", \"sigma_a\": {\"type\": \"gridvolume\", \"data\": [1, 2, 3], "
                                         "\"shape\": [3, 1, 1]}"),
               "mono", "one value per layer", "/sigma_a");
  expect_error(MA(US("[0, 1000, 5000]"), ", \"sigma_a\": -1"), "mono", "", "/sigma_a");
  expect_error(MA(US("[0, 1000]"), ""), "rgb", "mono variant", "/medium_atmosphere");
  /* the solar spectrum */
  const char *bad_sun[][2] = {
      {"{\"type\": \"solar_irradiance\", \"dataset\": \"kurucz\"}", "/dataset"},
      {"{\"type\": \"solar_irradiance\", \"earth_sun_distance\": 0}", "/earth_sun_distance"},
      {"{\"type\": \"solar_irradiance\", \"scael\": 2}", "/scael"},
  };
  for (size_t i = 0; i < 3; i++) {
    sbuf b = {0};
    sb_printf(&b, "{\"type\": \"scene\", \"sun\": {\"type\": \"directional\", \"irradiance\": %s}}",
              bad_sun[i][0]);
    rsw_err err = {0};
    scene *s = NULL;
    scene_load_opts o = {.variant = "mono"};
    rsw_status st = scene_load_memory(b.p, strlen(b.p), NULL, false, &o, &s, &err);
    free(b.p);
    CHECK(st != RSW_OK, "solar: loaded %s", bad_sun[i][0]);
    if (st == RSW_OK) scene_free(s);
    size_t lw = strlen(err.where), ll = strlen(bad_sun[i][1]);
    CHECK(st != RSW_OK && lw >= ll && strcmp(err.where + lw - ll, bad_sun[i][1]) == 0,
          "solar error at '%s' (%s)", err.where, err.msg);
  }
  /* below the ozone table: refused at render, naming the range */
  char *med = us_standard(12, "");
  scene *s = atmo_scene(med, "{\"type\": \"constant\"}", METER_UP, NULL);
  free(med);
  REQUIRE(s, "scene");
  rsw_err err = {0};
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 220};
  CHECK(scene_prepare(s, &rc, &err) != RSW_OK && strstr(err.msg, "230-1066.2 nm"), "220 nm: %s", err.msg);
  scene_free(s);
}

/* ---- XML ----------------------------------------------------------------------- */

static const char *XML_ATMO =
    "<scene version=\"3.0.0\">\n"
    "  <medium type=\"molecular_atmosphere\" id=\"medium_atmosphere\">\n"
    "    <thermoprops>\n"
    "      <string name=\"identifier\" value=\"%s\"/>\n"
    "      <string name=\"z\" value=\"0, 1000, 2000, 5000, 10000, 30000, 120000\"/>\n"
    "    </thermoprops>\n"
    "    <particle_layer>\n"
    "      <float name=\"top\" value=\"3000\"/> <float name=\"tau_ref\" value=\"0.3\"/>\n"
    "      <float name=\"angstrom\" value=\"1\"/>\n"
    "      <distribution type=\"exponential\"><float name=\"rate\" value=\"2\"/></distribution>\n"
    "      <phase type=\"hg\" name=\"phase\"><float name=\"g\" value=\"0.6\"/></phase>\n"
    "    </particle_layer>\n"
    "    <particle_layer>\n"
    "      <float name=\"bottom\" value=\"8000\"/> <float name=\"top\" value=\"9000\"/>\n"
    "      <float name=\"tau_ref\" value=\"0.05\"/>\n"
    "    </particle_layer>\n"
    "  </medium>\n"
    "  <shape type=\"cube\"><bsdf type=\"null\"/><ref name=\"interior\" id=\"medium_atmosphere\"/></shape>\n"
    "</scene>\n";

static void test_xml(void) {
  char xml[4096];
  snprintf(xml, sizeof xml, XML_ATMO, "afgl_1986-tropical");
  rsw_err err = {0};
  scene *x = NULL;
  scene_load_opts o = {.variant = "mono"};
  rsw_status st = scene_load_memory(xml, strlen(xml), NULL, true, &o, &x, &err);
  REQUIRE(st == RSW_OK, "XML: %s at %s", err.msg, err.where);
  const char *js =
      "{\"type\": \"molecular_atmosphere\", \"thermoprops\": {\"identifier\": \"afgl_1986-tropical\","
      " \"z\": [0, 1000, 2000, 5000, 10000, 30000, 120000]}, \"particle_layers\": ["
      "{\"top\": 3000, \"tau_ref\": 0.3, \"angstrom\": 1, \"distribution\": {\"type\": \"exponential\","
      " \"rate\": 2}, \"phase\": {\"type\": \"hg\", \"g\": 0.6}},"
      "{\"bottom\": 8000, \"top\": 9000, \"tau_ref\": 0.05}]}";
  scene *j = atmo_scene(js, "{\"type\": \"constant\"}", METER_UP, NULL);
  REQUIRE(j, "JSON twin");
  const double *z1, *s1, *a1, *w1, *z2, *s2, *a2, *w2;
  uint32_t n1, n2;
  size_t p1, p2;
  REQUIRE(molecular_atmosphere_layers(find_medium(x), 500, &z1, &n1, &s1, &a1, &w1, &p1), "XML layers");
  REQUIRE(molecular_atmosphere_layers(find_medium(j), 500, &z2, &n2, &s2, &a2, &w2, &p2), "JSON layers");
  CHECK(n1 == 6 && n2 == 6 && p1 == 2 && p2 == 2, "layers %u/%u, particle layers %zu/%zu", n1, n2, p1, p2);
  CHECK(memcmp(s1, s2, 6 * sizeof *s1) == 0 && memcmp(a1, a2, 6 * sizeof *a1) == 0 &&
            memcmp(w1, w2, 12 * sizeof *w1) == 0,
        "XML and JSON give different layers");
  scene_free(x);
  scene_free(j);
  snprintf(xml, sizeof xml, XML_ATMO, "afgl_1986-tropics");
  err = (rsw_err){0};
  st = scene_load_memory(xml, strlen(xml), NULL, true, &o, &x, &err);
  CHECK(st != RSW_OK && strstr(err.msg, "afgl_1986-subarctic_winter") && strstr(err.where, ":4"),
        "XML unknown identifier: %s at %s", err.msg, err.where);
  if (st == RSW_OK) scene_free(x);
  /* NaN in a list of levels */
  snprintf(xml, sizeof xml, XML_ATMO, "afgl_1986-tropical");
  char *z = strstr(xml, "5000, 10000");
  REQUIRE(z, "template");
  memcpy(z, " nan,", 5);
  err = (rsw_err){0};
  st = scene_load_memory(xml, strlen(xml), NULL, true, &o, &x, &err);
  CHECK(st != RSW_OK && strstr(err.where, ":5"), "XML NaN level: %s at %s", err.msg, err.where);
  if (st == RSW_OK) scene_free(x);
}

/* ---- the no-op sweep warning: the scene says whether it depends on wavelength */

static void test_wavelength_dependent(void) {
  static const struct {
    const char *extra;
    bool spectral;
  } cases[] = {
      {"", true},
      {"\"has_absorption\": false", true},
      {"\"has_scattering\": false", true},
      {"\"has_absorption\": false, \"has_scattering\": false, \"particle_layers\": [{\"bottom\": 0, "
       "\"top\": 2000, \"tau_ref\": 0.2, \"angstrom\": 1.3}]",
       true},
      {"\"has_absorption\": false, \"has_scattering\": false, \"particle_layers\": [{\"bottom\": 0, "
       "\"top\": 2000, \"tau_ref\": 0.2, \"angstrom\": 0}]",
       false},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    char *med = us_standard(12, cases[i].extra);
    scene *s = atmo_scene(med, "{\"type\": \"constant\"}", METER_UP, NULL);
    free(med);
    REQUIRE(s, "case %zu", i);
    CHECK(scene_wavelength_dependent(s) == cases[i].spectral,
          "case %zu (%s): wavelength dependent %d, want %d", i, cases[i].extra, scene_wavelength_dependent(s),
          cases[i].spectral);
    scene_free(s);
  }
}

int main(void) {
  RSW_TEST_RUN(test_rayleigh_bodhaine);
  RSW_TEST_RUN(test_ozone_column);
  RSW_TEST_RUN(test_direct_transmittance);
  RSW_TEST_RUN(test_sweep_equals_piecewise);
  RSW_TEST_RUN(test_particle_tau);
  RSW_TEST_RUN(test_parameter_update);
  RSW_TEST_RUN(test_solar_irradiance);
  RSW_TEST_RUN(test_refusals);
  RSW_TEST_RUN(test_xml);
  RSW_TEST_RUN(test_wavelength_dependent);
  RSW_TEST_END("test_molecular_atmosphere");
}
