/* Phase functions in the polarized variant (mono_polarized): Rayleigh
 * single scattering of sunlight rendered through a thin layer, whose
 * degree of linear polarization has a closed form at every scattering
 * angle Theta (mu = cos Theta). From core/mueller.h mu_rayleigh (Hansen &
 * Travis 1974, eq. 2.15), unpolarized light scattered once leaves with
 * Stokes vector F[., 0] = (F11, F21, 0, 0), so
 *
 *   DoLP = |F21| / F11 = 3/4 D (1 - mu^2) / (3/4 D (1 + mu^2) + 1 - D)
 *        = (1 - mu^2) / ((1 + mu^2) + 2 rho / (1 - rho)),
 *
 * with D = (1 - rho) / (1 + rho / 2), since 4 (1 - D) / (3 D) =
 * 2 rho / (1 - rho); rho = 0 gives sin^2 Theta / (1 + cos^2 Theta). Every
 * single-scattered sample of a view direction has the same scattering
 * angle, hence the same DoLP: the film's DoLP is exact (tolerance 1e-5,
 * float32 films). Its intensity S0 is the single-scattering radiance of a
 * layer of optical thickness tau over a black ground,
 *
 *   L = E p(Theta) mu0 / (mu0 + mu_v) (1 - exp(-tau (1 / mu0 + 1 / mu_v))),
 *
 * (albedo 1, E the sun's irradiance normal to its beam; Chandrasekhar
 * 1960, Radiative Transfer, sect. 1.3), checked within 4 standard errors.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/films/film_planes.h"
#include "../../../server/kernel/phase/phase.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define SUN_ZENITH 40.0 /* degrees, azimuth 0 */
#define TAU        0.01
#define SPP        1024

/* View zenith, azimuth (degrees) of the mdistant's pixels: azimuths 0
 * and 180 lie in the principal plane (Theta from 10 to 170 degrees),
 * (50, 180) at Theta = 90. */
static const double views[][2] = {{0.5, 0},  {30, 0},  {70, 0},   {20, 180}, {50, 180},
                                  {75, 180}, {50, 90}, {20, 135}, {65, 45},  {35, 300}};
#define NV (sizeof views / sizeof views[0])

static vec3 view_vector(int i) {
  double th = views[i][0] * RSW_PI / 180.0, ph = views[i][1] * RSW_PI / 180.0;
  return v3(sin(th) * cos(ph), sin(th) * sin(ph), cos(th));
}

static vec3 sun_vector(void) {
  double th = SUN_ZENITH * RSW_PI / 180.0;
  return v3(sin(th), 0.0, cos(th));
}

/* The layer z in [0, 1] of sigma_t TAU holding phase `phase_json` over a
 * black ground, under a sun of irradiance 1, seen by an mdistant along
 * -view for every view. */
static scene *layer_scene(const char *phase_json) {
  sbuf b = {0};
  vec3 s = sun_vector();
  sb_printf(
      &b,
      "{\"type\": \"scene\", \"variant\": \"mono_polarized\","
      " \"med\": {\"type\": \"homogeneous\", \"sigma_t\": %.17g, \"albedo\": 1.0, \"phase\": %s},"
      " \"atmo\": {\"type\": \"cube\", \"to_world\": [{\"scale\": [1e5, 1e5, 0.5]},"
      " {\"translate\": [0, 0, 0.5]}], \"bsdf\": {\"type\": \"null\"},"
      " \"interior\": {\"type\": \"ref\", \"id\": \"med\"}},"
      " \"ground\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [1e5, 1e5, 1]}],"
      " \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.0}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [%.17g, %.17g, %.17g], \"irradiance\": 1.0},"
      " \"integrator\": {\"type\": \"volpath\", \"max_depth\": 2},"
      " \"measure\": {\"type\": \"mdistant\", \"directions\": \"",
      TAU, phase_json, -s.x, -s.y, -s.z);
  for (size_t i = 0; i < NV; i++) {
    vec3 v = view_vector((int)i);
    sb_printf(&b, "%s%.17g %.17g %.17g", i ? " " : "", -v.x, -v.y, -v.z);
  }
  sb_printf(&b,
            "\", \"target\": {\"type\": \"rectangle\", \"to_world\": [{\"translate\": [0, 0, 1]}]},"
            " \"sampler\": {\"type\": \"independent\", \"sample_count\": %d},"
            " \"film\": {\"type\": \"hdrfilm\", \"width\": %zu, \"height\": 1, \"component_format\": "
            "\"float32\", \"rfilter\": {\"type\": \"box\"}}}}",
            SPP, NV);
  scene *sc = tsup_load(b.p, "mono_polarized");
  free(b.p);
  return sc;
}

static bool render_var(scene *sc, film_image *img) {
  rsw_err err = {0};
  render_opts o = {.size = sizeof o, .spp = SPP, .seed = 7, .threads = 2, .variance = true};
  if (render_sensor(sc, &o, img, NULL, &err)) {
    char buf[1200];
    printf("  render failed: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  return true;
}

/* The layer with Rayleigh phase `phase_json` of depolarization rho: DoLP
 * and S0 of every view against the closed forms above. */
static void check_rayleigh_layer(const char *phase_json, double rho, film_image *keep) {
  scene *sc = layer_scene(phase_json);
  REQUIRE(sc, "load %s", phase_json);
  film_image img = {0};
  REQUIRE(render_var(sc, &img), "render %s", phase_json);
  REQUIRE(img.polarized && img.channels == 4, "a Stokes film (%d channels)", img.channels);
  CHECK(strcmp(img.channel_names[1], "S1.Y") == 0, "channel 1 is %s", img.channel_names[1]);
  const film_plane *se = film_image_plane(&img, "radiance_stderr");
  REQUIRE(se, "radiance_stderr plane");
  vec3 s = sun_vector();
  double mu0 = s.z, worst = 0.0, zmax = 0.0;
  for (size_t i = 0; i < NV; i++) {
    vec3 v = view_vector((int)i);
    double mu = -v3_dot(s, v), muv = v.z; /* scattering cosine: from -s into v */
    const float *px = img.data + 4 * i;
    double s0 = px[0], s1 = px[1], s2 = px[2], s3 = px[3];
    double dolp = sqrt(s1 * s1 + s2 * s2) / s0;
    double want = (1.0 - mu * mu) / ((1.0 + mu * mu) + 2.0 * rho / (1.0 - rho));
    CHECK(fabs(dolp - want) <= 1e-5, "rho %g view (%g, %g), Theta %.2f deg: DoLP %.7f, want %.7f", rho,
          views[i][0], views[i][1], acos(mu) * 180.0 / RSW_PI, dolp, want);
    worst = fmax(worst, fabs(dolp - want));
    CHECK(fabs(s3) <= 1e-6 * s0, "view %zu: no circular part (S3 / S0 = %g)", i, s3 / s0);
    /* The angle of linear polarization: across the scattering plane
     * (along e = s x v), measured in the film's basis for light arriving
     * along v: x horizontal (z x v, render.c film_stokes_x), y = v x x. */
    vec3 x = v3_norm(v3_cross(v3(0, 0, 1), v)), y = v3_cross(v, x), e = v3_cross(s, v);
    double psi = atan2(v3_dot(e, y), v3_dot(e, x)), lp = sqrt(s1 * s1 + s2 * s2);
    if (want > 1e-3) {
      CHECK(fabs(s1 - lp * cos(2 * psi)) <= 1e-5 * s0 && fabs(s2 - lp * sin(2 * psi)) <= 1e-5 * s0,
            "rho %g view (%g, %g): (S1, S2) / S0 = (%.6f, %.6f), across the scattering plane (%.6f, %.6f)",
            rho, views[i][0], views[i][1], s1 / s0, s2 / s0, lp / s0 * cos(2 * psi), lp / s0 * sin(2 * psi));
    }
    double p = 3.0 / (8.0 * RSW_PI * (2.0 + rho)) * ((1.0 + rho) + (1.0 - rho) * mu * mu);
    double L = p * mu0 / (mu0 + muv) * (1.0 - exp(-TAU * (1.0 / mu0 + 1.0 / muv)));
    double z = (s0 - L) / se->data[4 * i];
    CHECK(fabs(z) < 4.0, "rho %g view %zu: S0 %.6g, single scattering %.6g, z = %.2f", rho, i, s0, L, z);
    zmax = fmax(zmax, fabs(z));
  }
  printf("  %.48s: max |DoLP - closed form| = %.2g, max |z| of S0 = %.2f\n", phase_json, worst, zmax);
  if (keep)
    *keep = img;
  else
    film_image_free(&img);
  scene_free(sc);
}

/* The phase function with this id. */
static const phase *find_phase(const scene *s, const char *id) {
  for (size_t i = 0; i < s->n_objects; i++) {
    object *o = s->objects[i];
    if (o->id && strcmp(o->id, id) == 0 && o->plugin && o->plugin->cls == CLS_PHASE) return (const phase *)o;
  }
  return NULL;
}

/* The Rayleigh phase matrix in Eradiate's bases (Q = I_l - I_r: m12 < 0),
 * tabulated at n nodes (irregular when `irregular`: denser near mu = 0),
 * as a tabphase_polarized object's JSON. malloc'ed. */
static char *rayleigh_table(int n, bool irregular) {
  sbuf b = {0};
  const char *keys[7] = {"nodes", "m11", "m12", "m22", "m33", "m34", "m44"};
  sb_printf(&b, "{\"type\": \"tabphase_polarized\"");
  for (int k = irregular ? 0 : 1; k < 7; k++) {
    sb_printf(&b, ", \"%s\": [", keys[k]);
    for (int i = 0; i < n; i++) {
      double x = -1.0 + 2.0 * i / (n - 1), mu = irregular ? sin(x * RSW_PI / 2) : x;
      if (i == 0) mu = -1.0;
      if (i == n - 1) mu = 1.0;
      double v[7] = {
          mu, 0.75 * (1 + mu * mu), -0.75 * (1 - mu * mu), 0.75 * (1 + mu * mu), 1.5 * mu, 0.0, 1.5 * mu};
      sb_printf(&b, "%s%.17g", i ? ", " : "", v[k]);
    }
    sb_printf(&b, "]");
  }
  sb_printf(&b, "}");
  return b.p;
}

/* tabphase_polarized holding Rayleigh's matrix (in Eradiate's bases): its
 * factors are mu_rayleigh's (the kernel's bases) to the interpolation's
 * accuracy, and it renders the layer as `rayleigh` does (the closed
 * forms, and rayleigh's film within 4 combined standard errors). */
static void test_tabphase_polarized_rayleigh(void) {
  medium_interaction mi = {0};
  mi.wi = v3_norm(v3(0.3, -0.5, -0.8));
  mueller P[3];
  double pdf;
  /* Rayleigh's matrix tabulated in Eradiate's bases gives mu_rayleigh's
   * factors (the kernel's bases) to the interpolation's accuracy:
   * |error| <= h^2 / 8 max |F''| / F11 ~ 1e-6 for 2001 nodes. */
  for (int irr = 0; irr < 2; irr++) {
    char *tab = rayleigh_table(2001, irr);
    sbuf b = {0};
    sb_printf(&b, "{\"type\": \"scene\", \"r\": %s}", tab);
    scene *sr = tsup_load(b.p, "mono");
    free(b.p), free(tab);
    REQUIRE(sr, "load the Rayleigh table");
    const phase *r = find_phase(sr, "r");
    REQUIRE(r, "phase r");
    double worst = 0.0;
    for (int i = 0; i < 400; i++) {
      double mu = -1.0 + 2.0 * (i + 0.37) / 400.0; /* between nodes */
      vec3 wo = phase_direction(&mi, mu, 0.3);
      mueller want = mu_normalized(mu_rayleigh(phase_mu(&mi, wo), 0.0));
      r->ops->polarization(r, &mi, wo, P);
      for (int a = 0; a < 4; a++)
        for (int c = 0; c < 4; c++) worst = fmax(worst, fabs(P[0].m[a][c] - want.m[a][c]));
      CHECK_REL(r->ops->eval_pdf(r, &mi, wo, &pdf), 3.0 / (16 * RSW_PI) * (1 + mu * mu), 1e-5);
    }
    CHECK(worst < 2e-6, "%s Rayleigh table: max |P - mu_rayleigh's| = %g", irr ? "irregular" : "regular",
          worst);
    printf("  Rayleigh table (2001 %s nodes): max |P - mu_rayleigh's| = %.2g\n",
           irr ? "irregular" : "regular", worst);
    scene_free(sr);
  }
  film_image ray = {0};
  check_rayleigh_layer("{\"type\": \"rayleigh\"}", 0.0, &ray);
  for (int irr = 0; irr < 2; irr++) {
    char *tab = rayleigh_table(2001, irr);
    film_image img = {0};
    check_rayleigh_layer(tab, 0.0, &img);
    const film_plane *e0 = film_image_plane(&ray, "radiance_stderr"),
                     *e1 = film_image_plane(&img, "radiance_stderr");
    double zmax = 0.0;
    for (size_t i = 0; i < 4 * NV && e0 && e1 && img.data; i++) {
      double sd = hypot(e0->data[i], e1->data[i]);
      if (sd > 0.0) zmax = fmax(zmax, fabs(img.data[i] - ray.data[i]) / sd);
    }
    CHECK(e0 && e1 && zmax < 4.0, "%s table vs rayleigh: max |z| over S0..S3 = %.2f",
          irr ? "irregular" : "regular", zmax);
    printf("  table (%s nodes) vs rayleigh films: max |z| = %.2f\n", irr ? "irregular" : "regular", zmax);
    film_image_free(&img);
    free(tab);
  }
  film_image_free(&ray);
}

static void test_rayleigh_single_scattering(void) {
  check_rayleigh_layer("{\"type\": \"rayleigh\"}", 0.0, NULL);
  check_rayleigh_layer("{\"type\": \"rayleigh\", \"depolarization\": 0.0279}", 0.0279, NULL);
  check_rayleigh_layer("{\"type\": \"rayleigh_polarized\", \"depolarization\": 0.3}", 0.3, NULL);
}

int main(void) {
  RSW_TEST_RUN(test_rayleigh_single_scattering);
  RSW_TEST_RUN(test_tabphase_polarized_rayleigh);
  RSW_TEST_END("test_phase_polarized");
}
