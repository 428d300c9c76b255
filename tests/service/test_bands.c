/* Spectral response functions (bands) in jobs, in process (no HTTP):
 *   - the quadrature: each SRF's n-node rule integrates S·p exactly for
 *     polynomials p of degree 2n-1 (uniform, tabulated, gaussian against
 *     a fine trapezoid), and a smooth spectrum to a stated tolerance;
 *   - a Lambertian plate whose reflectance is linear in λ (a tabulated
 *     spectrum) under a uniform SRF: brf_srf is the band mean, to float
 *     rounding (2e-7);
 *   - a gaussian SRF over a sinusoidal reflectance against a fine
 *     quadrature of the same SRF (relative 2e-5);
 *   - radiance_srf_stderr against the scatter of 48 replicates (fixed
 *     seeds): the ratio of the replicates' variance to the mean predicted
 *     variance within [0.75, 1.33] for nodes rendered alone ("bundle": 1),
 *     within [0.6, 1.33] for nodes in one bundle (a bound: never below);
 *   - the dataset (read back with libnetcdf): band and wavelength
 *     dimensions, radiance_srf, brf_srf and their _stderr, irradiance,
 *     irradiance_srf, brf_stderr, and sza, saa, vza, vaa as coordinates;
 *   - every refusal: 422 with the JSON pointer, and no job made. */
#include <math.h>
#include <netcdf.h>
#include <netcdf_mem.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../server/service/bands.h"
#include "../../server/service/service.h"
#include "../support/svc_job.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

/* A plate under one sun (zenith 30°, azimuth 45°: the light travels along
 * -(sin30 cos45, sin30 sin45, cos30)), seen by a 2x2 hdistant. */
static const char *PLATE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 2, \"height\": 2, \"component_format\": \"float32\","
    "     \"rfilter\": {\"type\": \"box\"}}},"
    " \"integrator\": {\"type\": \"path\", \"max_depth\": -1},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [-0.35355339059327373, -0.35355339059327373, "
    "-0.8660254037844386], \"irradiance\": 1.5},"
    " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"
    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";

/* A plate under a uniform sky: noisy samples, for the standard errors. */
static const char *SKY =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4, \"component_format\": \"float32\","
    "     \"rfilter\": {\"type\": \"box\"}}},"
    " \"integrator\": {\"type\": \"path\", \"max_depth\": -1},"
    " \"sky\": {\"type\": \"constant\", \"radiance\": 1.0},"
    " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"
    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";

static service *svc;

static char *post(const char *doc) {
  return svc_test_post(svc, doc);
}

/* Submit and wait for the end; the job id (free), or NULL. */
static char *run_job(const char *scene_id, const char *body) {
  return svc_test_run_job(svc, scene_id, body);
}

static bool parse_bands(const char *json, band_plan **p) {
  cJSON *v = cJSON_Parse(json);
  svc_error e = {0};
  rsw_status st = bands_parse(v, "/bands", p, &e);
  if (st) printf("  bands_parse: %s (%s)\n", e.err.msg, e.err.where);
  cJSON_Delete(v);
  return st == RSW_OK;
}

/* ---- the quadrature ------------------------------------------------------------- */

static double tri(double x) { /* the tabulated test SRF: 0 at 500, 1 at 530, 0.5 at 560, 0 at 600 */
  if (x <= 500 || x >= 600) return 0;
  if (x < 530) return (x - 500) / 30;
  if (x < 560) return 1 - 0.5 * (x - 530) / 30;
  return 0.5 * (600 - x) / 40;
}
static double gauss665(double x) {
  double s = 30 / (2 * sqrt(2 * log(2.0))), u = (x - 665) / s;
  return fabs(x - 665) <= BAND_GAUSS_SIGMAS * s ? exp(-0.5 * u * u) : 0;
}

/* ∫ S(x) f(x) dx by the trapezoid rule with 2e5 steps over [a, b]. */
static double fine(double (*S)(double), double (*f)(double), double a, double b) {
  int n = 200000;
  double h = (b - a) / n, s = 0;
  for (int i = 0; i <= n; i++) {
    double x = a + h * i;
    s += (i == 0 || i == n ? 0.5 : 1) * S(x) * f(x);
  }
  return s * h;
}

static double g_pow;
static double mono(double x) {
  return pow((x - 560) / 50, g_pow);
}
static double smooth(double x) { /* a smooth spectrum: two bumps and a slope */
  return 1 + 0.3 * sin(x / 23) + 0.001 * x + 0.2 * exp(-(x - 540) * (x - 540) / 800);
}
static double one(double x) {
  (void)x;
  return 1;
}

static void test_quadrature(void) {
  band_plan *p = NULL;
  REQUIRE(
      parse_bands(
          "[{\"id\": \"u\", \"srf\": {\"type\": \"uniform\", \"wmin\": 500, \"wmax\": 600}, "
          "\"nodes\": 5},"
          " {\"id\": \"t\", \"srf\": {\"type\": \"tabulated\", \"wavelengths\": [450, 500, 530, 560, 600,"
          " 700], \"values\": [0, 0, 1, 0.5, 0, 0]}, \"nodes\": 5},"
          " {\"id\": \"g\", \"srf\": {\"type\": \"gaussian\", \"mean\": 665, \"fwhm\": 30}, \"nodes\": 5}]",
          &p),
      "parse");
  double (*S[3])(double) = {NULL, tri, gauss665};
  double lo[3] = {500, 500, 665 - 4 * 30 / (2 * sqrt(2 * log(2.0)))};
  double hi[3] = {600, 600, 665 + 4 * 30 / (2 * sqrt(2 * log(2.0)))};
  for (int b = 0; b < 3; b++) {
    const band *bd = &p->b[b];
    CHECK(bd->n_nodes == 5, "band %s: 5 nodes (%zu)", bd->id, bd->n_nodes);
    CHECK(bd->wl[0] > lo[b] && bd->wl[4] < hi[b], "band %s: nodes inside the support", bd->id);
    for (int k = 0; k <= 9; k++) { /* exact to degree 2n-1 = 9 */
      g_pow = k;
      double q = 0;
      for (size_t i = 0; i < bd->n_nodes; i++) q += bd->w[i] * mono(bd->wl[i]);
      double ref = b == 0 ? fine(one, mono, 500, 600) : fine(S[b], mono, lo[b], hi[b]);
      CHECK(fabs(q - ref) <= 1e-6 * (fabs(ref) + 1), "band %s: degree %d: %.12g vs %.12g", bd->id, k, q, ref);
    }
  }
  CHECK_REL(p->b[0].integral, 100, 1e-12);
  CHECK_REL(p->b[1].integral, 0.5 * 30 + 0.75 * 30 + 0.25 * 40, 1e-9);
  bands_free(p);
  /* The default node counts on a smooth spectrum: relative error of the
   * band mean against the fine trapezoid (docs/experiments.md#spectral-response-functions-bands). */
  REQUIRE(parse_bands(
              "[{\"id\": \"u\", \"srf\": {\"type\": \"uniform\", \"wmin\": 500, \"wmax\": 600}},"
              " {\"id\": \"t\", \"srf\": {\"type\": \"tabulated\", \"wavelengths\": [450, 500, 530, 560, 600,"
              " 700], \"values\": [0, 0, 1, 0.5, 0, 0]}},"
              " {\"id\": \"g\", \"srf\": {\"type\": \"gaussian\", \"mean\": 665, \"fwhm\": 30}}]",
              &p),
          "parse defaults");
  for (int b = 0; b < 3; b++) {
    const band *bd = &p->b[b];
    double q = 0;
    for (size_t i = 0; i < bd->n_nodes; i++) q += bd->w[i] * smooth(bd->wl[i]);
    q /= bd->integral;
    double num = b == 0 ? fine(one, smooth, 500, 600) : fine(S[b], smooth, lo[b], hi[b]);
    double den = b == 0 ? 100 : fine(S[b], one, lo[b], hi[b]);
    printf("  band %s: %zu nodes, smooth spectrum: relative error %.2e\n", bd->id, bd->n_nodes,
           fabs(q / (num / den) - 1));
    CHECK(fabs(q / (num / den) - 1) < 1e-5, "band %s: smooth spectrum within 1e-5 (%g)", bd->id,
          fabs(q / (num / den) - 1));
  }
  bands_free(p);
}

/* ---- band values ------------------------------------------------------------------ */

static char *g_plate;

static void test_linear_uniform(void) {
  /* ρ(λ) = 0.1 + 0.4 (λ - 400) / 400: the mean over [500, 600] is 0.25. */
  const char *body =
      "{\"seed\": 1, \"quantities\": [\"brf\"], \"variance\": true,"
      " \"params\": {\"plate.bsdf.reflectance.value\": {\"wavelengths\": [400, 800], \"values\": [0.1, "
      "0.5]}},"
      " \"bands\": [{\"id\": \"b4\", \"srf\": {\"type\": \"uniform\", \"wmin\": 500, \"wmax\": 600}},"
      "   {\"id\": \"b5\", \"srf\": {\"type\": \"gaussian\", \"mean\": 665, \"fwhm\": 30}}],"
      " \"contexts\": [{\"id\": \"c0\"}, {\"id\": \"c1\", \"params\": {\"sun.irradiance.value\": 2.0}}]}";
  char *jid = run_job(g_plate, body);
  REQUIRE(jid, "job");
  svc_film f;
  svc_error e = {0};
  REQUIRE(service_job_band_result(svc, jid, "c0", "meter", "b4", NULL, &f, &e) == RSW_OK, "band film: %s",
          e.err.msg);
  const film_plane *brf = film_image_plane(&f.img, "brf");
  REQUIRE(brf, "band film has brf");
  for (int p = 0; p < 4; p++) CHECK_ABS(brf->data[p], 0.25, 2e-7);
  CHECK(isnan(f.img.wavelength), "a band film has no wavelength");
  CHECK(f.img.has_irradiance && fabs(f.img.irradiance[0] - 1.5 * cos(M_PI / 6)) < 1e-12,
        "irradiance_srf = E cos(sza) (%g)", f.img.irradiance[0]);
  svc_film_free(&f);
  /* Linear reflectance, symmetric gaussian: brf_srf = ρ(665) = 0.365. */
  REQUIRE(service_job_band_result(svc, jid, "c1", "meter", "b5", NULL, &f, &e) == RSW_OK, "band b5: %s",
          e.err.msg);
  brf = film_image_plane(&f.img, "brf");
  for (int p = 0; brf && p < 4; p++) CHECK_ABS(brf->data[p], 0.365, 2e-7);
  svc_film_free(&f);
  /* A node's film, and the plain address refused for a job with bands. */
  REQUIRE(service_job_band_result(svc, jid, "c0", "meter", NULL, "0", &f, &e) == RSW_OK, "node 0: %s",
          e.err.msg);
  CHECK(f.img.wavelength > 500 && f.img.wavelength < 510, "node 0 is the first uniform node (%g)",
        f.img.wavelength);
  CHECK(f.img.has_sun && fabs(f.img.sun_zenith - 30) < 1e-9 && fabs(f.img.sun_azimuth - 45) < 1e-9,
        "sun angles 30, 45 (%g, %g)", f.img.sun_zenith, f.img.sun_azimuth);
  svc_film_free(&f);
  svc_error e2 = {0};
  CHECK(service_job_result(svc, jid, "c0", "meter", &f, &e2) != RSW_OK && rsw_status_http(e2.err.code) == 422,
        "a band job's plain result is refused (%s)", e2.err.msg);
  svc_error e3 = {0};
  CHECK(service_job_band_result(svc, jid, "c0", "meter", "nope", NULL, &f, &e3) == RSW_ERR_NOT_FOUND,
        "unknown band: 404");

  /* The dataset. */
  void *bytes = NULL;
  size_t len = 0;
  REQUIRE(service_job_dataset(svc, jid, false, &bytes, &len, &e) == RSW_OK, "dataset: %s", e.err.msg);
  int nc;
  REQUIRE(nc_open_mem("bands.nc", NC_NOWRITE, len, bytes, &nc) == NC_NOERR, "open the dataset");
  int dim, var;
  size_t n;
  CHECK(nc_inq_dimid(nc, "band", &dim) == NC_NOERR && nc_inq_dimlen(nc, dim, &n) == NC_NOERR && n == 2,
        "band dimension of 2");
  CHECK(nc_inq_dimid(nc, "wavelength", &dim) == NC_NOERR && nc_inq_dimlen(nc, dim, &n) == NC_NOERR && n > 2,
        "wavelength dimension (the nodes)");
  static const char *const vars[] = {"radiance",
                                     "brf",
                                     "radiance_stderr",
                                     "brf_stderr",
                                     "irradiance",
                                     "radiance_srf",
                                     "brf_srf",
                                     "radiance_srf_stderr",
                                     "brf_srf_stderr",
                                     "irradiance_srf",
                                     "sza",
                                     "saa",
                                     "vza",
                                     "vaa",
                                     "band",
                                     "wavelength"};
  for (size_t i = 0; i < sizeof vars / sizeof vars[0]; i++)
    CHECK(nc_inq_varid(nc, vars[i], &var) == NC_NOERR, "variable %s", vars[i]);
  char coords[1024] = "";
  if (nc_inq_varid(nc, "brf_srf", &var) == NC_NOERR) {
    size_t al = 0;
    if (nc_inq_attlen(nc, var, "coordinates", &al) == NC_NOERR && al < sizeof coords)
      nc_get_att_text(nc, var, "coordinates", coords);
    int nd, dims[8];
    nc_inq_varndims(nc, var, &nd);
    nc_inq_vardimid(nc, var, dims);
    char dn[NC_MAX_NAME + 1] = "";
    nc_inq_dimname(nc, dims[1], dn);
    CHECK(nd == 4 && strcmp(dn, "band") == 0, "brf_srf over (context, band, y, x): %d dims, 2nd %s", nd, dn);
    float v[2][2][2][2];
    nc_get_var_float(nc, var, &v[0][0][0][0]);
    CHECK_ABS(v[0][0][0][0], 0.25, 2e-7);
    CHECK_ABS(v[1][1][1][1], 0.365, 2e-7);
  }
  CHECK(strstr(coords, "sza") && strstr(coords, "saa") && strstr(coords, "vza") && strstr(coords, "vaa"),
        "sza saa vza vaa are coordinates: '%s'", coords);
  double sza[2] = {0, 0}, saa[2] = {0, 0};
  if (nc_inq_varid(nc, "sza", &var) == NC_NOERR) nc_get_var_double(nc, var, sza);
  if (nc_inq_varid(nc, "saa", &var) == NC_NOERR) nc_get_var_double(nc, var, saa);
  CHECK_ABS(sza[0], 30, 1e-6);
  CHECK_ABS(saa[1], 45, 1e-6);
  double irr[2][2];
  if (nc_inq_varid(nc, "irradiance_srf", &var) == NC_NOERR) nc_get_var_double(nc, var, &irr[0][0]);
  CHECK_ABS(irr[1][0], 2.0 * cos(M_PI / 6), 1e-9);
  nc_close(nc);
  free(bytes);
  free(jid);
}

/* A gaussian SRF over ρ(λ) = 0.3 + 0.2 sin(λ / 40), tabulated every 2 nm:
 * brf_srf against the fine trapezoid of the same piecewise-linear table. */
static double g_tab[201];
static double rho_tab(double x) {
  double u = (x - 400) / 2;
  int i = (int)u;
  if (i >= 200) return g_tab[200];
  return g_tab[i] + (u - i) * (g_tab[i + 1] - g_tab[i]);
}

static void test_gaussian_fine(void) {
  char *body = malloc(16384);
  REQUIRE(body, "memory");
  size_t n = (size_t)snprintf(body, 16384,
                              "{\"quantities\": [\"brf\"], \"bands\": [{\"id\": \"g\", \"srf\": {\"type\": "
                              "\"gaussian\", \"mean\": 620, \"fwhm\": 40}}],"
                              " \"params\": {\"plate.bsdf.reflectance.value\": {\"wavelengths\": [");
  for (int i = 0; i <= 200; i++)
    n += (size_t)snprintf(body + n, 16384 - n, "%s%d", i ? "," : "", 400 + 2 * i);
  n += (size_t)snprintf(body + n, 16384 - n, "], \"values\": [");
  for (int i = 0; i <= 200; i++) {
    g_tab[i] = 0.3 + 0.2 * sin((400 + 2 * i) / 40.0);
    n += (size_t)snprintf(body + n, 16384 - n, "%s%.17g", i ? "," : "", g_tab[i]);
  }
  snprintf(body + n, 16384 - n, "]}}, \"contexts\": [{\"id\": \"c\"}]}");
  char *jid = run_job(g_plate, body);
  free(body);
  REQUIRE(jid, "job");
  svc_film f;
  svc_error e = {0};
  REQUIRE(service_job_band_result(svc, jid, "c", "meter", "g", NULL, &f, &e) == RSW_OK, "band: %s",
          e.err.msg);
  double s = 40 / (2 * sqrt(2 * log(2.0)));
  double a = 620 - 4 * s, b = 620 + 4 * s, num = 0, den = 0;
  int steps = 400000;
  for (int i = 0; i <= steps; i++) {
    double x = a + (b - a) * i / steps, u = (x - 620) / s,
           g = exp(-0.5 * u * u) * (i == 0 || i == steps ? 0.5 : 1);
    num += g * rho_tab(x), den += g;
  }
  const film_plane *brf = film_image_plane(&f.img, "brf");
  REQUIRE(brf, "brf plane");
  printf("  gaussian band over a sinusoidal table: brf_srf %.9g, fine %.9g (relative %.2e)\n", brf->data[0],
         num / den, fabs(brf->data[0] / (num / den) - 1));
  CHECK_REL(brf->data[0], num / den, 2e-5);
  svc_film_free(&f);
  free(jid);
}

/* radiance_srf_stderr predicts the scatter of the band value. */
/* The replicates' variance over the mean predicted one, the band's 4
 * nodes rendered with `bundle` ("1": alone, each its own seed; "\"auto\"":
 * in one bundle, on the same paths). */
static double replicates_ratio(const char *bundle) {
  char *sky = post(SKY);
  if (!sky) return NAN;
  enum {
    R = 48,
    P = 16
  };
  char body[8192];
  size_t n =
      (size_t)snprintf(body, sizeof body,
                       "{\"seed\": 7, \"bundle\": %s, \"variance\": true, \"bands\": [{\"id\": \"u\", "
                       "\"srf\": {\"type\": \"uniform\", \"wmin\": 500, \"wmax\": 600}, \"nodes\": 4}], "
                       "\"contexts\": [",
                       bundle);
  for (int r = 0; r < R; r++)
    n += (size_t)snprintf(body + n, sizeof body - n, "%s{\"id\": \"r%d\"}", r ? "," : "", r);
  snprintf(body + n, sizeof body - n, "]}");
  char *jid = run_job(sky, body);
  if (!jid) {
    free(sky);
    return NAN;
  }
  static double L[R][P], S2[R][P];
  for (int r = 0; r < R; r++) {
    char ctx[16];
    snprintf(ctx, sizeof ctx, "r%d", r);
    svc_film f;
    svc_error e = {0};
    const film_plane *sd = NULL;
    if (service_job_band_result(svc, jid, ctx, "meter", "u", NULL, &f, &e) != RSW_OK ||
        !(sd = film_image_plane(&f.img, "radiance_stderr"))) {
      printf("  %s: %s\n", ctx, sd ? e.err.msg : "no stderr plane");
      free(jid);
      free(sky);
      return NAN;
    }
    for (int p = 0; p < P; p++) L[r][p] = f.img.data[p], S2[r][p] = (double)sd->data[p] * sd->data[p];
    svc_film_free(&f);
  }
  double scatter = 0, predicted = 0;
  for (int p = 0; p < P; p++) {
    double m = 0;
    for (int r = 0; r < R; r++) m += L[r][p];
    m /= R;
    for (int r = 0; r < R; r++) scatter += (L[r][p] - m) * (L[r][p] - m) / (R - 1), predicted += S2[r][p] / R;
  }
  double ratio = scatter / predicted;
  printf("  replicates, bundle %s: scatter / predicted variance = %.3f\n", bundle, ratio);
  free(jid);
  free(sky);
  return ratio;
}

/* Nodes rendered alone are independent: the stderr predicts the scatter.
 * Nodes of one bundle are correlated: the stderr bounds it (Cauchy-Schwarz
 * within a bundle), never below it, and close (neighbouring wavelengths
 * on the same paths are nearly fully correlated). The formula for
 * independent nodes gave 3.6 there: its stderr too small by 1.9x. */
static void test_stderr_replicates(void) {
  double alone = replicates_ratio("1"), bundled = replicates_ratio("\"auto\"");
  CHECK(alone > 0.75 && alone < 1.33, "alone: stderr predicts the scatter: ratio %.3f", alone);
  CHECK(bundled > 0.6 && bundled < 1.33, "bundled: stderr bounds the scatter closely: ratio %.3f", bundled);
}

/* ---- refusals ---------------------------------------------------------------------- */

static void refused(const char *label, const char *body, const char *where) {
  char *jid = NULL, *json = NULL;
  svc_error e = {0};
  rsw_status st = service_job_submit(svc, g_plate, body, strlen(body), NULL, &jid, &json, &e);
  CHECK(st != RSW_OK && rsw_status_http(st) == 422 && strcmp(e.err.where, where) == 0,
        "%s: 422 at %s (got %d at '%s': %s)", label, where, rsw_status_http(st), e.err.where, e.err.msg);
  CHECK(!jid, "%s: no job", label);
  free(jid), free(json);
}

static void test_refusals(void) {
#define CTX "\"contexts\": [{\"id\": \"c\"}]"
  refused("zero integral",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"tabulated\", \"wavelengths\": [500, 600],"
          " \"values\": [0, 0]}}], " CTX "}",
          "/bands/0/srf/values");
  refused(
      "empty uniform",
      "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"uniform\", \"wmin\": 600, \"wmax\": 600}}], " CTX
      "}",
      "/bands/0/srf/wmax");
  refused("wavelengths not increasing",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"tabulated\", \"wavelengths\": [500, 500, 600],"
          " \"values\": [0, 1, 0]}}], " CTX "}",
          "/bands/0/srf/wavelengths/1");
  refused("negative value",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"tabulated\", \"wavelengths\": [500, 550, 600],"
          " \"values\": [0, -1, 0]}}], " CTX "}",
          "/bands/0/srf/values/1");
  refused(
      "infinite mean",
      "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"gaussian\", \"mean\": 1e999, \"fwhm\": 30}}], " CTX
      "}",
      "/bands/0/srf/mean");
  refused("infinite table value",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"tabulated\", \"wavelengths\": [500, 550, 600],"
          " \"values\": [0, 1e999, 0]}}], " CTX "}",
          "/bands/0/srf/values/1");
  refused("fwhm 0",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"gaussian\", \"mean\": 600, \"fwhm\": 0}}], " CTX
          "}",
          "/bands/0/srf/fwhm");
  refused(
      "fwhm negative",
      "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"gaussian\", \"mean\": 600, \"fwhm\": -3}}], " CTX
      "}",
      "/bands/0/srf/fwhm");
  refused("band id twice",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"uniform\", \"wmin\": 500, \"wmax\": 600}},"
          " {\"id\": \"b\", \"srf\": {\"type\": \"uniform\", \"wmin\": 600, \"wmax\": 700}}], " CTX "}",
          "/bands/1/id");
  refused("context wavelength",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"uniform\", \"wmin\": 500, \"wmax\": 600}}],"
          " \"contexts\": [{\"id\": \"c\", \"wavelength\": 550}]}",
          "/contexts/0/wavelength");
  refused("coord wavelength",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"uniform\", \"wmin\": 500, \"wmax\": 600}}],"
          " \"contexts\": [{\"id\": \"c\", \"coords\": {\"wavelength\": 550}}]}",
          "/contexts/0/coords/wavelength");
  refused("coord band",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"uniform\", \"wmin\": 500, \"wmax\": 600}}],"
          " \"contexts\": [{\"id\": \"c\", \"coords\": {\"band\": 1}}]}",
          "/contexts/0/coords/band");
  refused("default wavelength",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"uniform\", \"wmin\": 500, \"wmax\": 600}}],"
          " \"defaults\": {\"wavelength\": 550}, " CTX "}",
          "/defaults/wavelength");
  refused(
      "outside a tabulated spectrum",
      "{\"params\": {\"plate.bsdf.reflectance.value\": {\"wavelengths\": [400, 700], \"values\": [0.1, "
      "0.5]}},"
      " \"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"uniform\", \"wmin\": 650, \"wmax\": 750}}], " CTX
      "}",
      "/bands/0/srf");
  refused("unknown SRF type", "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"box\"}}], " CTX "}",
          "/bands/0/srf/type");
  refused("unknown member",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"uniform\", \"wmin\": 500, \"wmax\": 600, "
          "\"w\": 1}}], " CTX "}",
          "/bands/0/srf/w");
  refused("gaussian below 0 nm",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"gaussian\", \"mean\": 20, \"fwhm\": 30}}], " CTX
          "}",
          "/bands/0/srf/fwhm");
  refused("lengths differ",
          "{\"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"tabulated\", \"wavelengths\": [500, 550, 600],"
          " \"values\": [0, 1]}}], " CTX "}",
          "/bands/0/srf/values");
  refused("nodes 0",
          "{\"bands\": [{\"id\": \"b\", \"nodes\": 0, \"srf\": {\"type\": \"uniform\", \"wmin\": 500, "
          "\"wmax\": 600}}], " CTX "}",
          "/bands/0/nodes");
  refused("bands not a list", "{\"bands\": {}, " CTX "}", "/bands");
#undef CTX
}

/* Templates under bands: a template over the coordinate `wavelength` is
 * rendered at each node's wavelength (not once per context), so a
 * reflectance given as a template, linear in λ, gives the band mean
 * ρ(650) = 0.35 (once per context, at the default 550 nm, it would give
 * 0.25); and a sun template sets the angles. */
static void test_templates_per_node(void) {
  const char *body =
      "{\"seed\": 1, \"quantities\": [\"brf\"],"
      " \"templates\": {\"plate.bsdf.reflectance.value\": {\"coord\": \"wavelength\", \"x\": [400, 800],"
      "   \"y\": [0.1, 0.5]}, \"sun.direction\": {\"sun\": {\"zenith\": \"sza\", \"azimuth\": 0}}},"
      " \"bands\": [{\"id\": \"b4\", \"srf\": {\"type\": \"uniform\", \"wmin\": 600, \"wmax\": 700}}],"
      " \"contexts\": [{\"id\": \"s0\", \"coords\": {\"sza\": 0}}, {\"id\": \"s60\", \"coords\": {\"sza\": "
      "60}}]}";
  char *jid = run_job(g_plate, body);
  REQUIRE(jid, "job");
  static const char *const ctx[] = {"s0", "s60"};
  static const double zen[] = {0, 60};
  for (int c = 0; c < 2; c++) {
    svc_film f;
    svc_error e = {0};
    REQUIRE(service_job_band_result(svc, jid, ctx[c], "meter", "b4", NULL, &f, &e) == RSW_OK,
            "band film %s: %s", ctx[c], e.err.msg);
    const film_plane *brf = film_image_plane(&f.img, "brf");
    REQUIRE(brf, "band film has brf");
    for (int p = 0; p < 4; p++) CHECK_ABS(brf->data[p], 0.35, 2e-7);
    CHECK(f.img.has_irradiance && fabs(f.img.irradiance[0] - 1.5 * cos(zen[c] * M_PI / 180)) < 1e-9,
          "%s: irradiance_srf = E cos(sza) (%g)", ctx[c], f.img.irradiance[0]);
    svc_film_free(&f);
  }
  free(jid);
}

int main(void) {
  service_opts o = {.size = sizeof o, .render_threads = 2};
  rsw_err err = {0};
  if (service_new(&o, &svc, &err)) {
    printf("service_new: %s\n", err.msg);
    return 1;
  }
  g_plate = post(PLATE);
  RSW_TEST_RUN(test_quadrature);
  if (g_plate) {
    RSW_TEST_RUN(test_linear_uniform);
    RSW_TEST_RUN(test_gaussian_fine);
    RSW_TEST_RUN(test_templates_per_node);
    RSW_TEST_RUN(test_stderr_replicates);
    RSW_TEST_RUN(test_refusals);
  } else {
    CHECK(false, "the plate scene loads");
  }
  free(g_plate);
  service_free(svc);
  RSW_TEST_END("test_bands");
}
