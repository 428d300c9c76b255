/* common/dataset_nc: the contexts' coords (validation and the errors'
 * JSON pointers), grid detection (a complete grid gives one dimension per
 * coord, anything else one "context" dimension), film values placed in
 * their grid cell whatever the order of the contexts, missing films NaN,
 * and bad films refused. Datasets are encoded in memory and read back with
 * libnetcdf. */
#include <cjson/cJSON.h>
#include <math.h>
#include <netcdf.h>
#include <netcdf_mem.h>
#include <stdlib.h>
#include <string.h>

#include "../support/test.h"
#include "dataset_nc.h"
#include "stokes.h"

RSW_TEST_DEFINE_GLOBALS

/* Build coords from a JSON array of the contexts' coords objects (null:
 * none); returns the status, err filled. */
static rsw_status coords_of(const char *json, nc_coords *out, rsw_err *err) {
  cJSON *a = cJSON_Parse(json);
  size_t n = (size_t)cJSON_GetArraySize(a);
  const void *p[16] = {0};
  size_t i = 0;
  for (const cJSON *c = a ? a->child : NULL; c && i < 16; c = c->next, i++) p[i] = cJSON_IsNull(c) ? NULL : c;
  memset(err, 0, sizeof *err);
  rsw_status st = nc_coords_build(p, n, "/contexts", out, err);
  cJSON_Delete(a);
  return st;
}

static void test_coords_errors(void) {
  static const struct {
    const char *json;
    rsw_status code;
    const char *where;
  } cases[] = {
      {"[[1]]", RSW_ERR_TYPE, "/contexts/0/coords"},
      {"[{\"k\": true}]", RSW_ERR_TYPE, "/contexts/0/coords/k"},
      {"[{\"k\": 1}, {\"k\": \"s\"}]", RSW_ERR_TYPE, "/contexts/1/coords/k"},
      {"[{\"k\": \"s\"}, {\"k\": 2}]", RSW_ERR_TYPE, "/contexts/1/coords/k"},
      {"[{\"k\": 1}, null]", RSW_ERR_MISSING, "/contexts/1"},
      {"[{\"k\": 1}, {}]", RSW_ERR_MISSING, "/contexts/1/coords"},
      {"[{\"k\": 1, \"m\": 2}, {\"k\": 2}]", RSW_ERR_MISSING, "/contexts/1/coords/m"},
      {"[{\"k\": 1}, {\"k\": 2, \"m\": 3}]", RSW_ERR_INVALID, "/contexts/1/coords/m"},
      {"[{\"y\": 1}]", RSW_ERR_INVALID, "/contexts/0/coords/y"},
      {"[{\"radiance\": 1}]", RSW_ERR_INVALID, "/contexts/0/coords/radiance"},
      {"[{\"9a\": 1}]", RSW_ERR_INVALID, "/contexts/0/coords/9a"},
      {"[{\"a-b\": 1}]", RSW_ERR_INVALID, "/contexts/0/coords/a-b"},
      {"[{\"k\": \"\"}]", RSW_ERR_INVALID, "/contexts/0/coords/k"},
      {"[{\"k\": \"a\\nb\"}]", RSW_ERR_INVALID, "/contexts/0/coords/k"},
      {"[{\"a\":1,\"b\":1,\"c\":1,\"d\":1,\"e\":1,\"f\":1,\"g\":1,\"h\":1,\"i\":1}]", RSW_ERR_LIMIT,
       "/contexts/0/coords"},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    nc_coords c = {0};
    rsw_err err;
    rsw_status st = coords_of(cases[i].json, &c, &err);
    CHECK(st == cases[i].code, "%s: status %d, wanted %d (%s)", cases[i].json, st, cases[i].code, err.msg);
    CHECK(strcmp(err.where, cases[i].where) == 0, "%s: where '%s', wanted '%s'", cases[i].json, err.where,
          cases[i].where);
    nc_coords_free(&c);
  }
  nc_coords c = {0};
  rsw_err err;
  CHECK(coords_of("[null, null]", &c, &err) == RSW_OK && c.n == 0, "no coords at all is fine");
  nc_coords_free(&c);
  CHECK(coords_of("[{}, {}]", &c, &err) == RSW_OK && c.n == 0, "empty coords everywhere is fine");
  nc_coords_free(&c);
  REQUIRE(coords_of("[{\"wavelength\": 550, \"s\": \"a\"}, {\"wavelength\": 600, \"s\": \"b\"}]", &c, &err) ==
              RSW_OK,
          "%s", err.msg);
  CHECK(c.n == 2 && !c.c[0].is_string && c.c[1].is_string && c.c[0].num[1] == 600 &&
            strcmp(c.c[1].str[0], "a") == 0,
        "columns built");
  nc_coords copy;
  REQUIRE(nc_coords_copy(&c, &copy, &err) == RSW_OK, "copy");
  CHECK(copy.n == 2 && copy.c[0].num[0] == 550 && strcmp(copy.c[1].str[1], "b") == 0,
        "copy holds the values");
  nc_coords_free(&copy);
  nc_coords_free(&c);
}

/* A 1x2-pixel one-channel film per context whose values encode it. */
typedef struct fixture {
  const char *ids[8];
  float data[8][2];
  nc_var vars[8];
  nc_film films[8];
  const char *ch[1];
} fixture;

static void make_films(fixture *fx, size_t n, const size_t *skip, size_t n_skip, size_t *n_films) {
  fx->ch[0] = "Y";
  size_t k = 0;
  for (size_t i = 0; i < n; i++) {
    bool skipped = false;
    for (size_t s = 0; s < n_skip; s++) skipped |= skip[s] == i;
    fx->data[i][0] = (float)i + 0.25f;
    fx->data[i][1] = (float)i + 0.5f;
    if (skipped) continue;
    fx->vars[k] = (nc_var){"radiance", fx->data[i]};
    fx->films[k] = (nc_film){.context = i,
                             .sensor = "cam",
                             .width = 2,
                             .height = 1,
                             .channels = 1,
                             .channel_names = fx->ch,
                             .spp = 4,
                             .seed = 100 + i,
                             .vars = &fx->vars[k],
                             .n_vars = 1};
    k++;
  }
  *n_films = k;
}

/* Encode, open in memory; -1 on failure. */
static int encode_open(const nc_dataset *d, void **bytes, rsw_err *err) {
  size_t len;
  if (nc_dataset_encode(d, bytes, &len, err) != RSW_OK) return -1;
  int ncid;
  if (nc_open_mem("t.nc", NC_NOWRITE, len, *bytes, &ncid) != NC_NOERR) return -1;
  return ncid;
}

/* A mono dataset of scene "s" over n contexts (ids, coords c) holding
 * nf films of fx, encoded and opened as encode_open does. */
static int encode_fixture(const fixture *fx, size_t nf, size_t n, const char *const *ids, const nc_coords *c,
                          void **bytes, rsw_err *err) {
  nc_dataset d = {.size = sizeof d,
                  .scene = "s",
                  .variant = "mono",
                  .n_contexts = n,
                  .context_ids = ids,
                  .coords = c,
                  .films = fx->films,
                  .n_films = nf};
  return encode_open(&d, bytes, err);
}

static void test_grid_any_order(void) {
  /* 2 x 3 over (a, b), listed out of order: b descending, a mixed. */
  const char *json = "[{\"a\": 2, \"b\": \"z\"}, {\"a\": 1, \"b\": \"z\"}, {\"a\": 2, \"b\": \"x\"},"
                     " {\"a\": 1, \"b\": \"y\"}, {\"a\": 1, \"b\": \"x\"}, {\"a\": 2, \"b\": \"y\"}]";
  nc_coords c;
  rsw_err err;
  REQUIRE(coords_of(json, &c, &err) == RSW_OK, "%s", err.msg);
  fixture fx;
  const char *ids[6] = {"c0", "c1", "c2", "c3", "c4", "c5"};
  size_t nf;
  make_films(&fx, 6, NULL, 0, &nf);
  void *bytes = NULL;
  int ncid = encode_fixture(&fx, nf, 6, ids, &c, &bytes, &err);
  REQUIRE(ncid >= 0, "encode: %s", err.msg);
  int dim_a, dim_b, dim_ctx, var;
  size_t na = 0, nb = 0;
  CHECK(nc_inq_dimid(ncid, "a", &dim_a) == NC_NOERR && nc_inq_dimlen(ncid, dim_a, &na) == NC_NOERR && na == 2,
        "dimension a of 2");
  CHECK(nc_inq_dimid(ncid, "b", &dim_b) == NC_NOERR && nc_inq_dimlen(ncid, dim_b, &nb) == NC_NOERR && nb == 3,
        "dimension b of 3");
  CHECK(nc_inq_dimid(ncid, "context", &dim_ctx) != NC_NOERR, "no context dimension in a grid");
  double av[2];
  CHECK(nc_inq_varid(ncid, "a", &var) == NC_NOERR && nc_get_var_double(ncid, var, av) == NC_NOERR &&
            av[0] == 1 && av[1] == 2,
        "a sorted: %g %g", av[0], av[1]);
  char *bv[3] = {0};
  CHECK(nc_inq_varid(ncid, "b", &var) == NC_NOERR && nc_get_var_string(ncid, var, bv) == NC_NOERR &&
            strcmp(bv[0], "x") == 0 && strcmp(bv[2], "z") == 0,
        "b sorted bytewise");
  nc_free_string(3, bv);
  float r[2][3][1][2];
  REQUIRE(nc_inq_varid(ncid, "radiance", &var) == NC_NOERR &&
              nc_get_var_float(ncid, var, &r[0][0][0][0]) == NC_NOERR,
          "radiance");
  /* Context i holds i + 0.25: (a=2,b=z) is c0, (a=1,b=x) is c4. */
  CHECK(r[1][2][0][0] == 0.25f && r[0][0][0][0] == 4.25f && r[0][1][0][1] == 3.5f, "values in their cells");
  unsigned long long seeds[2][3];
  CHECK(nc_inq_varid(ncid, "seed", &var) == NC_NOERR &&
            nc_get_var_ulonglong(ncid, var, &seeds[0][0]) == NC_NOERR && seeds[1][2] == 100 &&
            seeds[0][0] == 104,
        "seeds in their cells");
  unsigned spp = 0;
  CHECK(nc_get_att_uint(ncid, NC_GLOBAL, "spp", &spp) == NC_NOERR && spp == 4, "spp attribute");
  nc_close(ncid);
  free(bytes);
  nc_coords_free(&c);
}

static void dims_of(const char *json, size_t n, const size_t *skip, size_t n_skip, bool *grid, float *first,
                    float *missing) {
  nc_coords c;
  rsw_err err;
  *grid = false;
  if (coords_of(json, &c, &err) != RSW_OK) return;
  fixture fx;
  const char *ids[8] = {"c0", "c1", "c2", "c3", "c4", "c5", "c6", "c7"};
  size_t nf;
  make_films(&fx, n, skip, n_skip, &nf);
  nc_dataset d = {
      .size = sizeof d, .n_contexts = n, .context_ids = ids, .coords = &c, .films = fx.films, .n_films = nf};
  void *bytes = NULL;
  int ncid = encode_open(&d, &bytes, &err);
  if (ncid >= 0) {
    int dim, var;
    *grid = nc_inq_dimid(ncid, "context", &dim) != NC_NOERR;
    float v[16];
    if (nc_inq_varid(ncid, "radiance", &var) == NC_NOERR && nc_get_var_float(ncid, var, v) == NC_NOERR) {
      *first = v[0];
      if (missing) *missing = v[2 * skip[0]];
    }
    nc_close(ncid);
  }
  free(bytes);
  nc_coords_free(&c);
}

static void test_not_a_grid(void) {
  bool grid;
  float first = 0, missing = 0;
  /* A combination twice and one missing: 4 contexts, 2 x 2 values. */
  dims_of("[{\"a\":1,\"b\":1},{\"a\":1,\"b\":2},{\"a\":2,\"b\":1},{\"a\":1,\"b\":1}]", 4, NULL, 0, &grid,
          &first, NULL);
  CHECK(!grid, "a repeated combination is not a grid");
  dims_of("[{\"a\":1,\"b\":1},{\"a\":1,\"b\":2},{\"a\":2,\"b\":1}]", 3, NULL, 0, &grid, &first, NULL);
  CHECK(!grid && first == 0.25f, "an incomplete grid: context dimension in context order");
  dims_of("[null, null]", 2, NULL, 0, &grid, &first, NULL);
  CHECK(!grid, "no coords: context dimension");
  dims_of("[{\"a\":3},{\"a\":1}]", 2, NULL, 0, &grid, &first, NULL);
  CHECK(grid && first == 1.25f, "one coord of distinct values is a 1-D grid, sorted");
  size_t skip[1] = {1};
  dims_of("[{\"a\":1},{\"a\":2},{\"a\":3}]", 3, skip, 1, &grid, &first, &missing);
  CHECK(grid && isnan(missing), "a missing film is NaN");
}

static void test_bad_films(void) {
  fixture fx;
  const char *ids[2] = {"c0", "c1"};
  size_t nf;
  make_films(&fx, 2, NULL, 0, &nf);
  nc_dataset d = {.size = sizeof d, .n_contexts = 2, .context_ids = ids, .films = fx.films, .n_films = nf};
  void *bytes = NULL;
  size_t len;
  rsw_err err = {0};
  fx.films[1].width = 3;
  CHECK(nc_dataset_encode(&d, &bytes, &len, &err) == RSW_ERR_INVALID, "films of one sensor with two shapes");
  fx.films[1].width = 2;
  fx.films[1].context = 0;
  memset(&err, 0, sizeof err);
  CHECK(nc_dataset_encode(&d, &bytes, &len, &err) == RSW_ERR_INVALID, "two films of one context and sensor");
  fx.films[1].context = 7;
  memset(&err, 0, sizeof err);
  CHECK(nc_dataset_encode(&d, &bytes, &len, &err) == RSW_ERR_INVALID, "a context out of range");
  fx.films[1].context = 1;
  fx.vars[1].name = "temperature";
  memset(&err, 0, sizeof err);
  CHECK(nc_dataset_encode(&d, &bytes, &len, &err) == RSW_ERR_INVALID && strstr(err.msg, "temperature"),
        "an unknown quantity: %s", err.msg);
  fx.vars[1].name = "brf";
  memset(&err, 0, sizeof err);
  REQUIRE(nc_dataset_encode(&d, &bytes, &len, &err) == RSW_OK, "radiance and brf: %s", err.msg);
  free(bytes);
  CHECK(nc_quantity_find("radiance_stderr") && nc_quantity_find("brdf") && !nc_quantity_find("x"),
        "the quantity table");
}

/* Plugin failures (nc_film.plugin_failures, plugin_failure): a uint64
 * and a string variable per film, always there (0 and "" for clean
 * films); a missing film's count is the variable's _FillValue, not 0.
 * The contexts are out of grid order: c0 (a=2), c1 (a=3), c2 (a=1) sit in
 * cells 1, 2, 0; c1 has failures, c2 is missing in the second round. */
static void test_plugin_failures(void) {
  nc_coords c;
  rsw_err err;
  REQUIRE(coords_of("[{\"a\": 2}, {\"a\": 3}, {\"a\": 1}]", &c, &err) == RSW_OK, "%s", err.msg);
  const char *ids[3] = {"c0", "c1", "c2"};
  for (int with_missing = 0; with_missing < 2; with_missing++) {
    fixture fx;
    size_t skip[1] = {2}, nf;
    make_films(&fx, 3, skip, with_missing ? 1 : 0, &nf);
    fx.films[1].plugin_failures = 7;
    fx.films[1].plugin_failure = "emitter 'sky' (plugin type 'nan_sky'): add_radiance returned I = nan";
    fx.films[0].plugin_failure = "ignored: no failures"; /* a message without a count is not written */
    void *bytes = NULL;
    int ncid = encode_fixture(&fx, nf, 3, ids, &c, &bytes, &err);
    REQUIRE(ncid >= 0, "encode: %s", err.msg);
    int var, msg_var;
    unsigned long long n[3] = {1, 1, 1}, fill = 0;
    CHECK(nc_inq_varid(ncid, "plugin_failures", &var) == NC_NOERR &&
              nc_get_var_ulonglong(ncid, var, n) == NC_NOERR && n[1] == 0 && n[2] == 7,
          "missing=%d: counts %llu %llu", with_missing, n[1], n[2]);
    nc_type type = NC_NAT;
    CHECK(nc_inq_vartype(ncid, var, &type) == NC_NOERR && type == NC_UINT64, "plugin_failures is uint64");
    char text[200] = "";
    CHECK(nc_get_att_text(ncid, var, "comment", text) == NC_NOERR && strstr(text, "replaced by black"),
          "plugin_failures has a comment naming what it counts");
    bool has_fill = nc_get_att_ulonglong(ncid, var, "_FillValue", &fill) == NC_NOERR;
    if (with_missing)
      CHECK(has_fill && fill == NC_FILL_UINT64 && n[0] == fill, "a missing film's count is the fill: %llu",
            n[0]);
    else
      CHECK(!has_fill && n[0] == 0, "no fill when every film is there; the clean film reads 0");
    char *msg[3] = {0};
    CHECK(nc_inq_varid(ncid, "plugin_failure", &msg_var) == NC_NOERR &&
              nc_get_var_string(ncid, msg_var, msg) == NC_NOERR && msg[0] && strcmp(msg[0], "") == 0 &&
              msg[1] && strcmp(msg[1], "") == 0 && msg[2] && strstr(msg[2], "add_radiance returned I = nan"),
          "messages: '%s' '%s' '%s'", msg[0] ? msg[0] : "(null)", msg[1] ? msg[1] : "(null)",
          msg[2] ? msg[2] : "(null)");
    nc_free_string(3, msg);
    nc_close(ncid);
    free(bytes);
  }
  nc_coords_free(&c);
  /* A coord may not take the names. */
  nc_coords r = {0};
  CHECK(coords_of("[{\"plugin_failures\": 1}]", &r, &err) == RSW_ERR_INVALID, "plugin_failures is reserved");
  nc_coords_free(&r);
}

/* Stokes films (common/stokes.h): a stokes dimension S0..S3 (channel over
 * the colours where there are several), and dolp / aolp from the Stokes
 * vector, for the three channel namings. One context, 2x1 pixels; pixel 0
 * of colour c is (1, 0.5, -0.25, 0.125) scaled by c + 1, pixel 1 is
 * unpolarized (2, 0, 0, 0) but for colour 1 with S0 = 0 (dolp 0 by
 * definition). Closed forms: dolp = sqrt(0.5^2 + 0.25^2) = 0.559017,
 * aolp = 0.5 atan2(-0.25, 0.5) = -13.2825 degrees. */
static void stokes_case(const char *variant, const char *const *names, int nch, int n_col) {
  float data[2 * 12], brf[2 * 12];
  const float pol[4] = {1.0f, 0.5f, -0.25f, 0.125f};
  for (int c = 0; c < n_col; c++)
    for (int k = 0; k < 4; k++) {
      data[k * n_col + c] = pol[k] * (float)(c + 1);
      data[nch + k * n_col + c] = k == 0 && c != 1 ? 2.0f : 0.0f;
    }
  for (int i = 0; i < 2 * nch; i++) brf[i] = data[i] * 0.5f;
  nc_var vars[2] = {{"radiance", data}, {"brf", brf}};
  const char *ids[1] = {"k0"};
  nc_film film = {.context = 0,
                  .sensor = "cam",
                  .width = 2,
                  .height = 1,
                  .channels = nch,
                  .channel_names = names,
                  .spp = 4,
                  .vars = vars,
                  .n_vars = 2,
                  .has_irradiance = true,
                  .irradiance = {2, 2, 2, 2}};
  nc_dataset d = {.size = sizeof d,
                  .variant = variant,
                  .n_contexts = 1,
                  .context_ids = ids,
                  .films = &film,
                  .n_films = 1};
  void *bytes = NULL;
  rsw_err err = {0};
  int ncid = encode_open(&d, &bytes, &err);
  REQUIRE(ncid >= 0, "%s: encode: %s", names[0], err.msg);
  int dim, var, nd = 0, dims[8];
  size_t len = 0;
  CHECK(nc_inq_dimid(ncid, "stokes", &dim) == NC_NOERR && nc_inq_dimlen(ncid, dim, &len) == NC_NOERR &&
            len == 4,
        "%s: a stokes dimension of 4", names[0]);
  char *lab[4] = {0};
  CHECK(nc_inq_varid(ncid, "stokes", &var) == NC_NOERR && nc_get_var_string(ncid, var, lab) == NC_NOERR &&
            lab[0] && strcmp(lab[0], "S0") == 0 && strcmp(lab[3], "S3") == 0,
        "%s: stokes labels S0..S3", names[0]);
  nc_free_string(4, lab);
  bool has_ch = nc_inq_dimid(ncid, "channel", &dim) == NC_NOERR;
  CHECK(has_ch == (n_col > 1), "%s: a channel dimension only for several colours", names[0]);
  if (has_ch) {
    char *cl[3] = {0};
    CHECK(nc_inq_dimlen(ncid, dim, &len) == NC_NOERR && len == (size_t)n_col, "channel of n_col");
    CHECK(nc_inq_varid(ncid, "channel", &var) == NC_NOERR && nc_get_var_string(ncid, var, cl) == NC_NOERR &&
              cl[0] && strcmp(cl[0], "R") == 0 && strcmp(cl[2], "B") == 0,
          "channel labels R G B");
    nc_free_string(3, cl);
  }
  /* radiance over (context, y, x, stokes[, channel]), the film's values. */
  float r[24];
  REQUIRE(nc_inq_varid(ncid, "radiance", &var) == NC_NOERR && nc_inq_varndims(ncid, var, &nd) == NC_NOERR &&
              nd == (has_ch ? 5 : 4) && nc_get_var_float(ncid, var, r) == NC_NOERR,
          "%s: radiance over %d dims", names[0], nd);
  CHECK(memcmp(r, data, sizeof(float) * 2 * (size_t)nch) == 0, "%s: radiance holds the film's values",
        names[0]);
  nc_inq_vardimid(ncid, var, dims);
  char dn[NC_MAX_NAME + 1];
  nc_inq_dimname(ncid, dims[3], dn);
  CHECK(strcmp(dn, "stokes") == 0, "%s: radiance's 4th dimension is stokes (%s)", names[0], dn);
  float dolp[6], aolp[6];
  REQUIRE(nc_inq_varid(ncid, "dolp", &var) == NC_NOERR && nc_inq_varndims(ncid, var, &nd) == NC_NOERR &&
              nd == (has_ch ? 4 : 3) && nc_get_var_float(ncid, var, dolp) == NC_NOERR,
          "%s: dolp over (context, y, x[, channel])", names[0]);
  char units[32] = {0};
  CHECK(nc_get_att_text(ncid, var, "units", units) == NC_NOERR && strcmp(units, "1") == 0, "dolp units");
  REQUIRE(nc_inq_varid(ncid, "aolp", &var) == NC_NOERR && nc_get_var_float(ncid, var, aolp) == NC_NOERR,
          "%s: aolp", names[0]);
  memset(units, 0, sizeof units);
  CHECK(nc_get_att_text(ncid, var, "units", units) == NC_NOERR && strcmp(units, "degree") == 0, "aolp units");
  size_t clen = 0;
  CHECK(nc_inq_attlen(ncid, var, "comment", &clen) == NC_NOERR && clen > 20, "aolp states its convention");
  for (int c = 0; c < n_col; c++) {
    CHECK(fabsf(dolp[c] - 0.559017f) < 1e-5f, "%s: dolp %g, wanted 0.559017", names[0], dolp[c]);
    CHECK(fabsf(aolp[c] - -13.28252f) < 1e-4f, "%s: aolp %g, wanted -13.28252", names[0], aolp[c]);
    CHECK(dolp[n_col + c] == 0.0f && aolp[n_col + c] == 0.0f, "%s: unpolarized and S0 = 0: dolp 0, aolp 0",
          names[0]);
  }
  CHECK(nc_inq_varid(ncid, "brf_dolp", &var) != NC_NOERR, "no second dolp for brf");
  /* irradiance per colour, not per Stokes component. */
  CHECK(nc_inq_varid(ncid, "irradiance", &var) == NC_NOERR && nc_inq_varndims(ncid, var, &nd) == NC_NOERR &&
            nd == (has_ch ? 2 : 1),
        "%s: irradiance over (context[, channel])", names[0]);
  nc_close(ncid);
  free(bytes);
}

static void test_stokes_films(void) {
  static const char *const bare[4] = {"S0", "S1", "S2", "S3"};
  static const char *const mono[4] = {"S0.Y", "S1.Y", "S2.Y", "S3.Y"};
  static const char *const rgb[12] = {"S0.R", "S0.G", "S0.B", "S1.R", "S1.G", "S1.B",
                                      "S2.R", "S2.G", "S2.B", "S3.R", "S3.G", "S3.B"};
  stokes_case("mono", bare, 4, 1);
  stokes_case("mono_polarized", mono, 4, 1);
  stokes_case("rgb_polarized", rgb, 12, 3);
  /* Not Stokes: a plain rgb film keeps its channel dimension, labelled. */
  static const char *const plain[3] = {"R", "G", "B"};
  float data[6] = {1, 2, 3, 4, 5, 6};
  nc_var var = {"radiance", data};
  const char *ids[1] = {"k0"};
  nc_film film = {.sensor = "cam",
                  .width = 2,
                  .height = 1,
                  .channels = 3,
                  .channel_names = plain,
                  .vars = &var,
                  .n_vars = 1};
  nc_dataset d = {
      .size = sizeof d, .variant = "rgb", .n_contexts = 1, .context_ids = ids, .films = &film, .n_films = 1};
  void *bytes = NULL;
  rsw_err err = {0};
  int ncid = encode_open(&d, &bytes, &err);
  REQUIRE(ncid >= 0, "rgb encode: %s", err.msg);
  int dim, v;
  char *cl[3] = {0};
  CHECK(nc_inq_dimid(ncid, "stokes", &dim) != NC_NOERR && nc_inq_varid(ncid, "dolp", &v) != NC_NOERR,
        "an rgb film has no stokes dimension and no dolp");
  CHECK(nc_inq_varid(ncid, "channel", &v) == NC_NOERR && nc_get_var_string(ncid, v, cl) == NC_NOERR &&
            cl[1] && strcmp(cl[1], "G") == 0,
        "the channel coordinate holds the channel names");
  nc_free_string(3, cl);
  nc_close(ncid);
  free(bytes);
  /* dolp is derived, never handed in. */
  var.name = "dolp";
  size_t len;
  CHECK(nc_dataset_encode(&d, &bytes, &len, &err) == RSW_ERR_INVALID, "a film's own dolp is refused");
}

/* stokes.h's closed forms and layouts. */
static void test_stokes_helpers(void) {
  CHECK(stokes_dolp(0, 0, 0) == 0 && stokes_dolp(0, 1, 1) == 0, "dolp 0 where S0 = 0");
  CHECK(fabs(stokes_dolp(2, 1, -1) - sqrt(2) / 2) < 1e-15, "dolp sqrt(S1^2 + S2^2) / S0");
  CHECK(isnan(stokes_dolp(NAN, 0, 0)), "dolp NaN in, NaN out");
  CHECK(stokes_aolp_deg(1, 0) == 0 && fabs(stokes_aolp_deg(0, 1) - 45) < 1e-12 &&
            fabs(stokes_aolp_deg(0, -1) + 45) < 1e-12,
        "aolp 0, 45, -45");
  CHECK(stokes_aolp_deg(-1, 0) == 90 && stokes_aolp_deg(-1, -0.0) == 90,
        "aolp 90 (not -90) for S1 < 0, S2 = -0");
  CHECK(stokes_aolp_deg(0, 0) == 0 && stokes_aolp_deg(-0.0, -0.0) == 0, "aolp 0 where S1 = S2 = 0");
  stokes_layout l;
  const char *ok3[12] = {"S0.R", "S0.G", "S0.B", "S1.R", "S1.G", "S1.B",
                         "S2.R", "S2.G", "S2.B", "S3.R", "S3.G", "S3.B"};
  CHECK(stokes_layout_of(ok3, 12, &l) && l.n_color == 3 && strcmp(l.color[2], "B") == 0, "rgb layout");
  const char *bad1[4] = {"S0", "S1", "S3", "S2"};
  const char *bad2[4] = {"S0.Y", "S1.Y", "S2.X", "S3.Y"};
  const char *bad3[4] = {"Y", "brf.Y", "brdf.Y", "radiance_stderr.Y"};
  const char *bad4[8] = {"S0", "S0", "S1", "S1", "S2", "S2", "S3", "S3"};
  CHECK(!stokes_layout_of(bad1, 4, &l) && !stokes_layout_of(bad2, 4, &l) && !stokes_layout_of(bad3, 4, &l) &&
            !stokes_layout_of(bad4, 8, &l) && !stokes_layout_of(ok3, 3, &l),
        "not Stokes layouts");
  CHECK(stokes_component("S2.Y") == 2 && stokes_component("S2") == 2 && stokes_component("S4") == -1 &&
            stokes_component("S0Y") == -1 && stokes_component("brf.S0.Y") == -1,
        "stokes_component");
}

/* A data variable over its slab budget goes in slabs of whole images
 * (nc_dataset.slab_bytes): a 3 x 2 x 4 grid of 2 x 3 films, listed out of
 * order with two missing, and two quantities; and a 5-context list with
 * node films. Every budget, from one image a call to a slab over the
 * grid's first dimension, gives the file of one call, byte for byte, with
 * every film in its cell and NaN where one is missing. */
#define SLAB_N 24
/* A 3 x 2 film of "cam" for context ctx, one channel "Y", 4 spp. */
static nc_film slab_film(size_t ctx, const char *const *ch, const nc_var *vars, size_t n_vars) {
  return (nc_film){.context = ctx,
                   .sensor = "cam",
                   .width = 3,
                   .height = 2,
                   .channels = 1,
                   .channel_names = ch,
                   .spp = 4,
                   .vars = vars,
                   .n_vars = n_vars};
}

static void test_slabs(void) {
  cJSON *co[SLAB_N];
  const char *ids[SLAB_N];
  char idbuf[SLAB_N][8];
  static float data[SLAB_N][2][6];
  nc_var vars[SLAB_N][2];
  nc_film films[SLAB_N];
  const char *ch[1] = {"Y"};
  size_t nf = 0;
  for (size_t i = 0; i < SLAB_N; i++) {
    size_t k = (i * 7) % SLAB_N; /* context i holds grid position k */
    co[i] = cJSON_CreateObject();
    cJSON_AddNumberToObject(co[i], "a", (double)(k / 8));
    cJSON_AddStringToObject(co[i], "b", k / 4 % 2 ? "y" : "x");
    cJSON_AddNumberToObject(co[i], "c", 0.5 + (double)(k % 4));
    snprintf(idbuf[i], sizeof idbuf[i], "c%zu", i);
    ids[i] = idbuf[i];
    for (int q = 0; q < 2; q++)
      for (int p = 0; p < 6; p++) data[i][q][p] = (float)(1000 * q + 10 * k + (size_t)p);
    if (i == 3 || i == 17) continue;
    vars[nf][0] = (nc_var){"radiance", data[i][0]};
    vars[nf][1] = (nc_var){"radiance_stderr", data[i][1]};
    films[nf] = slab_film(i, ch, vars[nf], 2);
    films[nf].seed = i;
    nf++;
  }
  nc_coords c;
  rsw_err err = {0};
  REQUIRE(nc_coords_build((const void *const *)co, SLAB_N, "/contexts", &c, &err) == RSW_OK, "%s", err.msg);
  for (size_t i = 0; i < SLAB_N; i++) cJSON_Delete(co[i]);
  nc_dataset d = {.size = sizeof d,
                  .scene = "s",
                  .variant = "mono",
                  .n_contexts = SLAB_N,
                  .context_ids = ids,
                  .coords = &c,
                  .films = films,
                  .n_films = nf};
  void *one = NULL;
  size_t one_len = 0;
  REQUIRE(nc_dataset_encode(&d, &one, &one_len, &err) == RSW_OK, "one call: %s", err.msg);
  /* budgets in images: 1, 2 (c by 2), 5 (b by 1: 4 images), 17 (a by 2,
   * then 1), 23 (a by 2: 16, then 8) */
  const size_t imgs[] = {1, 2, 5, 17, 23};
  for (size_t t = 0; t < sizeof imgs / sizeof *imgs; t++) {
    d.slab_bytes = imgs[t] * 6 * sizeof(float);
    void *b = NULL;
    size_t len = 0;
    REQUIRE(nc_dataset_encode(&d, &b, &len, &err) == RSW_OK, "slabs of %zu: %s", imgs[t], err.msg);
    CHECK(len == one_len && memcmp(b, one, len) == 0,
          "slabs of %zu images: the one-call file (%zu, %zu bytes)", imgs[t], len, one_len);
    int ncid, var;
    float r[3][2][4][2][3];
    REQUIRE(nc_open_mem("t.nc", NC_NOWRITE, len, b, &ncid) == NC_NOERR, "open");
    REQUIRE(nc_inq_varid(ncid, "radiance_stderr", &var) == NC_NOERR &&
                nc_get_var_float(ncid, var, &r[0][0][0][0][0]) == NC_NOERR,
            "radiance_stderr");
    int wrong = 0;
    for (size_t k = 0; k < SLAB_N; k++)
      for (int p = 0; p < 6; p++) {
        float v = r[k / 8][k / 4 % 2][k % 4][p / 3][p % 3];
        bool missing = k == (3 * 7) % SLAB_N || k == (17 * 7) % SLAB_N;
        wrong += missing ? !isnan(v) : v != (float)(1000 + 10 * k + (size_t)p);
      }
    CHECK(wrong == 0, "slabs of %zu: %d values out of their cells", imgs[t], wrong);
    nc_close(ncid);
    free(b);
  }
  free(one);
  nc_coords_free(&c);

  /* Node films: contexts x wavelength nodes, a list (no coords). */
  const double nodes[3] = {500, 550, 600};
  nc_film nfilm[15];
  nc_var nv[15];
  static float nd[15][6];
  size_t nn = 0;
  for (size_t i = 0; i < 5; i++)
    for (size_t w = 0; w < 3; w++) {
      for (int p = 0; p < 6; p++) nd[nn][p] = (float)(100 * i + 10 * w + (size_t)p);
      nv[nn] = (nc_var){"radiance", nd[nn]};
      nfilm[nn] = slab_film(i, ch, &nv[nn], 1);
      nfilm[nn].node = w + 1;
      nn++;
    }
  const char *band_ids[1] = {"b1"};
  nc_dataset e = {.size = sizeof e,
                  .scene = "s",
                  .variant = "mono",
                  .n_contexts = 5,
                  .context_ids = ids,
                  .films = nfilm,
                  .n_films = nn,
                  .n_nodes = 3,
                  .nodes = nodes,
                  .n_bands = 1,
                  .band_ids = band_ids};
  REQUIRE(nc_dataset_encode(&e, &one, &one_len, &err) == RSW_OK, "nodes, one call: %s", err.msg);
  const size_t nimgs[] = {1, 2, 4, 7};
  for (size_t t = 0; t < sizeof nimgs / sizeof *nimgs; t++) {
    e.slab_bytes = nimgs[t] * 6 * sizeof(float);
    void *b = NULL;
    size_t len = 0;
    REQUIRE(nc_dataset_encode(&e, &b, &len, &err) == RSW_OK, "nodes, slabs of %zu: %s", nimgs[t], err.msg);
    CHECK(len == one_len && memcmp(b, one, len) == 0, "nodes, slabs of %zu images: the one-call file",
          nimgs[t]);
    free(b);
  }
  free(one);
}

int main(void) {
  RSW_TEST_RUN(test_coords_errors);
  RSW_TEST_RUN(test_grid_any_order);
  RSW_TEST_RUN(test_not_a_grid);
  RSW_TEST_RUN(test_bad_films);
  RSW_TEST_RUN(test_plugin_failures);
  RSW_TEST_RUN(test_stokes_helpers);
  RSW_TEST_RUN(test_stokes_films);
  RSW_TEST_RUN(test_slabs);
  RSW_TEST_END("test_dataset_nc");
}
