/* Stokes results outside the kernel, in process (no HTTP), on a mono
 * `pixel_format: "stokes"` film fed by an environment plugin compiled at
 * test time ("polvar": a constant (i, q, u, v) in every direction, each an
 * updatable parameter), so every camera ray that escapes sees exactly
 * that vector:
 *   - jobs and templates: a job whose template makes q linear in the
 *     wavelength keeps S0..S3 (and brf.S0.., radiance_stderr.S0..) in every
 *     result, each context's q the template's;
 * *   - its dataset: radiance, brf, radiance_stderr over (context, y, x,
 *     stokes), labels S0..S3, and dolp / aolp against the closed forms
 *     sqrt(q^2 + u^2) / i and 0.5 atan2(u, q);
 *   - bands: a uniform band over [450, 550] nm with q(λ) = 0.8 (λ - 500) /
 *     50 and u = 0.5: the band's Stokes vector is (1, 0, 0.5, v) (the
 *     Gauss rule is exact for a linear q), so dolp_srf = 0.5 and aolp_srf
 *     = 45 degrees, while the nodes' own DoLPs are all above 0.5 (their
 *     mean is what integrating DoLP would give: refused by construction). */
#include <math.h>
#include <netcdf.h>
#include <netcdf_mem.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../server/kernel/extplugin/env_plugin.h"
#include "../../server/service/service.h"
#include "../support/svc_job.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static const char *PLUGIN =
    "#include <raysweep/plugin.h>\n"
    "#include <stdlib.h>\n"
    "#include <string.h>\n"
    "static const rsw_plugin_host *H;\n"
    "static const rsw_plugin_param P[4] = {{.name = \"i\", .default_value = {1}}, {.name = \"q\"},\n"
    "  {.name = \"u\", .default_value = {0.5}}, {.name = \"v\", .default_value = {0.125}}};\n"
    "static int idx(const char *n) { for (int k = 0; k < 4; k++) if (!strcmp(P[k].name, n)) return k; return "
    "-1; }\n"
    "static int create(const double *const *p, void **inst, char *e, size_t n) {\n"
    "  (void)e, (void)n; double *s = malloc(4 * sizeof *s); if (!s) return 1;\n"
    "  for (int k = 0; k < 4; k++) { s[k] = p[k][0]; }\n"
    "  *inst = s; return 0; }\n"
    "static void destroy(void *i) { free(i); }\n"
    "static int clone(const void *i, void **o, char *e, size_t n) {\n"
    "  (void)e, (void)n; double *s = malloc(4 * sizeof *s); if (!s) return 1;\n"
    "  memcpy(s, i, 4 * sizeof *s);\n  *o = s; return 0; }\n"
    "static int set(void *i, const char *n, const double *v, char *e, size_t l) {\n"
    "  (void)e, (void)l; int k = idx(n); if (k < 0) return 1; ((double *)i)[k] = v[0]; return 0; }\n"
    "static int get(const void *i, const char *n, double *v) {\n"
    "  int k = idx(n); if (k < 0) return 1; v[0] = ((const double *)i)[k]; return 0; }\n"
    "static int prep(void *i, const rsw_prepare_context *c, char *e, size_t n) {\n"
    "  (void)i, (void)c, (void)e, (void)n; return 0; }\n"
    "static void add(const void *i, rsw_stokes_context *c, const double d[3]) {\n"
    "  (void)d; const double *s = i;\n"
    "  for (size_t k = 0; k < c->count; k++)\n"
    "    for (int j = 0; j < 4; j++) c->stokes[j][k] += s[j]; }\n"
    "static double sample(const void *i, const double u[2], double d[3]) {\n"
    "  (void)i; H->square_to_uniform_sphere(u, d); return H->uniform_sphere_pdf(); }\n"
    "static double pdf(const void *i, const double d[3]) { (void)i, (void)d; return H->uniform_sphere_pdf(); "
    "}\n"
    "static const rsw_env_plugin T = {.abi_version = RSW_PLUGIN_ABI_VERSION, .type_name = \"polvar\",\n"
    "  .pretty_name = \"Polarised constant\", .params = P, .n_params = 4, .create = create, .destroy = "
    "destroy,\n"
    "  .clone = clone, .set_param = set, .get_param = get, .prepare = prep, .add_radiance = add,\n"
    "  .sample = sample, .pdf = pdf};\n"
    "RSW_PLUGIN_EXPORT const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *h) { H = h; return "
    "&T; }\n";

/* A 2x2 camera whose rays all escape, under a sun (for brf: E_h = 2 cos 0). */
static const char *SCENE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"cam\": {\"type\": \"perspective\", \"fov\": 20,"
    "   \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 2, \"height\": 2, \"pixel_format\": \"stokes\","
    "     \"component_format\": \"float32\", \"rfilter\": {\"type\": \"box\"}}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 2.0},"
    " \"sky\": {\"type\": \"polvar\"}}";

static char dir[64];
static service *svc;
static char *g_scene;

/* Submit and wait for the end; the job id (free), or NULL. */
static char *run_job(const char *body) {
  return svc_test_run_job(svc, g_scene, body);
}

/* The dataset of job jid, open in memory (-1 on failure; *bytes to free). */
static int open_dataset(const char *jid, void **bytes) {
  size_t len = 0;
  svc_error e = {0};
  if (service_job_dataset(svc, jid, false, bytes, &len, &e) != RSW_OK) {
    printf("  dataset: %s\n", e.err.msg);
    return -1;
  }
  int nc;
  return nc_open_mem("stokes.nc", NC_NOWRITE, len, *bytes, &nc) == NC_NOERR ? nc : -1;
}

/* Variable name's values (n floats) and its dimension names joined by ','. */
static bool get_var(int nc, const char *name, float *v, char *dims, size_t cap) {
  int var, nd, ids[16];
  if (nc_inq_varid(nc, name, &var) != NC_NOERR || nc_inq_varndims(nc, var, &nd) != NC_NOERR) return false;
  nc_inq_vardimid(nc, var, ids);
  dims[0] = '\0';
  for (int k = 0; k < nd; k++) {
    char dn[NC_MAX_NAME + 1];
    nc_inq_dimname(nc, ids[k], dn);
    snprintf(dims + strlen(dims), cap - strlen(dims), "%s%s", k ? "," : "", dn);
  }
  return nc_get_var_float(nc, var, v) == NC_NOERR;
}

static void test_job_with_templates(void) {
  /* q = 0.8 (λ - 500) / 50: -0.8, 0, 0.8 at 450, 500, 550 nm. */
  const char *body =
      "{\"seed\": 1, \"quantities\": [\"brf\"], \"variance\": true,"
      " \"templates\": {\"sky.q\": {\"coord\": \"wavelength\", \"x\": [450, 550], \"y\": [-0.8, 0.8]}},"
      " \"contexts\": [{\"id\": \"w450\", \"wavelength\": 450}, {\"id\": \"w500\", \"wavelength\": 500},"
      "   {\"id\": \"w550\", \"wavelength\": 550}]}";
  char *jid = run_job(body);
  REQUIRE(jid, "job");
  static const char *const ctx[3] = {"w450", "w500", "w550"};
  const double q[3] = {-0.8, 0, 0.8};
  for (int c = 0; c < 3; c++) {
    svc_film f;
    svc_error e = {0};
    REQUIRE(service_job_result(svc, jid, ctx[c], "cam", &f, &e) == RSW_OK, "result %s: %s", ctx[c],
            e.err.msg);
    const char *names[16];
    int n = film_image_all_channels(&f.img, names);
    CHECK(n == 12 && strcmp(names[0], "S0") == 0 && strcmp(names[3], "S3") == 0 &&
              strcmp(names[4], "brf.S0") == 0 && strcmp(names[11], "radiance_stderr.S3") == 0,
          "%s: the result keeps S0..S3 and its planes' (%d channels)", ctx[c], n);
    for (int p = 0; p < 4 && f.img.channels == 4; p++) {
      CHECK_ABS(f.img.data[4 * p], 1.0, 1e-6);
      CHECK_ABS(f.img.data[4 * p + 1], q[c], 1e-6);
      CHECK_ABS(f.img.data[4 * p + 2], 0.5, 1e-6);
      CHECK_ABS(f.img.data[4 * p + 3], 0.125, 1e-6);
    }
    svc_film_free(&f);
  }
  void *bytes = NULL;
  int nc = open_dataset(jid, &bytes);
  REQUIRE(nc >= 0, "dataset");
  float r[3 * 4 * 4], brf[3 * 4 * 4], dolp[12], aolp[12];
  char dims[256];
  REQUIRE(get_var(nc, "radiance", r, dims, sizeof dims), "radiance");
  CHECK(strcmp(dims, "context,y,x,stokes") == 0, "radiance over %s", dims);
  REQUIRE(get_var(nc, "brf", brf, dims, sizeof dims), "brf");
  CHECK(strcmp(dims, "context,y,x,stokes") == 0, "brf over %s", dims);
  float se[48];
  CHECK(get_var(nc, "radiance_stderr", se, dims, sizeof dims) && strcmp(dims, "context,y,x,stokes") == 0,
        "radiance_stderr over %s", dims);
  CHECK(get_var(nc, "brf_stderr", se, dims, sizeof dims) && strcmp(dims, "context,y,x,stokes") == 0,
        "brf_stderr over %s", dims);
  REQUIRE(get_var(nc, "dolp", dolp, dims, sizeof dims), "dolp");
  CHECK(strcmp(dims, "context,y,x") == 0, "dolp over %s", dims);
  REQUIRE(get_var(nc, "aolp", aolp, dims, sizeof dims), "aolp");
  int var;
  CHECK(nc_inq_varid(nc, "brf_dolp", &var) != NC_NOERR && nc_inq_varid(nc, "dolp_srf", &var) != NC_NOERR,
        "one dolp: brf's is radiance's");
  for (int c = 0; c < 3; c++)
    for (int p = 0; p < 4; p++) {
      size_t i = (size_t)(4 * c + p);
      CHECK_ABS(r[4 * i + 1], q[c], 1e-6);
      CHECK_ABS(brf[4 * i + 2], M_PI * 0.5 / 2.0, 1e-6); /* pi U / E_h */
      CHECK_ABS(dolp[i], sqrt(q[c] * q[c] + 0.25), 1e-6);
      CHECK_ABS(aolp[i], 0.5 * atan2(0.5, q[c]) * 180 / M_PI, 1e-4);
    }
  nc_close(nc);
  free(bytes);
  free(jid);
}

static void test_band_integrates_stokes(void) {
  const char *body =
      "{\"seed\": 2, \"quantities\": [\"brf\"],"
      " \"templates\": {\"sky.q\": {\"coord\": \"wavelength\", \"x\": [450, 550], \"y\": [-0.8, 0.8]}},"
      " \"bands\": [{\"id\": \"b\", \"srf\": {\"type\": \"uniform\", \"wmin\": 450, \"wmax\": 550}}],"
      " \"contexts\": [{\"id\": \"k\"}]}";
  char *jid = run_job(body);
  REQUIRE(jid, "job");
  svc_film f;
  svc_error e = {0};
  REQUIRE(service_job_band_result(svc, jid, "k", "cam", "b", NULL, &f, &e) == RSW_OK, "band film: %s",
          e.err.msg);
  REQUIRE(f.img.channels == 4 && strcmp(f.img.channel_names[2], "S2") == 0, "the band film keeps S0..S3");
  const float want[4] = {1.0f, 0.0f, 0.5f, 0.125f};
  for (int p = 0; p < 4; p++)
    for (int k = 0; k < 4; k++) CHECK_ABS(f.img.data[4 * p + k], want[k], 1e-6);
  const film_plane *brf = film_image_plane(&f.img, "brf");
  REQUIRE(brf, "band film has brf");
  for (int k = 0; k < 4; k++) CHECK_ABS(brf->data[k], M_PI * want[k] / 2.0, 1e-6);
  svc_film_free(&f);
  void *bytes = NULL;
  int nc = open_dataset(jid, &bytes);
  REQUIRE(nc >= 0, "dataset");
  float dolp_srf[4], aolp_srf[4], dolp[64], rs[16];
  char dims[256];
  REQUIRE(get_var(nc, "radiance_srf", rs, dims, sizeof dims), "radiance_srf");
  CHECK(strcmp(dims, "context,band,y,x,stokes") == 0, "radiance_srf over %s", dims);
  REQUIRE(get_var(nc, "dolp_srf", dolp_srf, dims, sizeof dims), "dolp_srf");
  CHECK(strcmp(dims, "context,band,y,x") == 0, "dolp_srf over %s", dims);
  REQUIRE(get_var(nc, "aolp_srf", aolp_srf, dims, sizeof dims), "aolp_srf");
  for (int p = 0; p < 4; p++) {
    CHECK_ABS(dolp_srf[p], 0.5, 1e-6);
    CHECK_ABS(aolp_srf[p], 45.0, 1e-4);
  }
  /* The nodes' own DoLPs (dolp over the node wavelengths): all above 0.5,
   * their SRF-weighted mean well above. */
  int dim;
  size_t n_nodes = 0;
  REQUIRE(nc_inq_dimid(nc, "wavelength", &dim) == NC_NOERR && nc_inq_dimlen(nc, dim, &n_nodes) == NC_NOERR &&
              n_nodes >= 2 && n_nodes <= 16,
          "node wavelengths");
  REQUIRE(get_var(nc, "dolp", dolp, dims, sizeof dims), "node dolp");
  CHECK(strcmp(dims, "context,wavelength,y,x") == 0, "node dolp over %s", dims);
  double mean = 0;
  for (size_t i = 0; i < n_nodes; i++) {
    CHECK(dolp[4 * i] > 0.5, "node %zu: dolp %g > 0.5", i, dolp[4 * i]);
    mean += dolp[4 * i] / (double)n_nodes;
  }
  CHECK(mean > 0.6, "the nodes' mean DoLP %g is not the band's 0.5", mean);
  nc_close(nc);
  free(bytes);
  free(jid);
}

int main(void) {
  if (!tsup_build_plugin(PLUGIN, "polvar", dir)) return 1;
  rsw_err err = {0};
  if (plugins_load_dir(dir, &err)) {
    printf("load: %s\n", err.msg);
    return 1;
  }
  if (!svc_test_start(&svc, SCENE, &g_scene)) return 1;
  if (g_scene) {
    RSW_TEST_RUN(test_job_with_templates);
    RSW_TEST_RUN(test_band_integrates_stokes);
  } else {
    CHECK(false, "the polvar scene loads");
  }
  free(g_scene);
  service_free(svc);
  plugins_unload();
  tsup_remove_dir(dir);
  RSW_TEST_END("test_stokes_results");
}
