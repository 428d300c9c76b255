/* The parameter path of participating media through the real daemon
 * (issue 14): the example atmosphere (proto/examples/atmosphere.json,
 * 2,400 layers) is pushed to `raysweepd serve` on an ephemeral loopback
 * port, and
 *  - GET params lists its three per-layer arrays (sigma_t.data,
 *    albedo.data, the blendphase weight grid) as spectral, shape [2400];
 *  - a PATCH of a 2,400-layer sigma_t.data answers 200 and moves the
 *    revision (ETag) by one;
 *  - a refused PATCH (a good albedo beside a sigma_t of 2,399 values, a
 *    negative coefficient, an albedo above 1) is a 422 problem naming the
 *    key, the revision does not move and a render is bitwise the one
 *    before: the map is atomic;
 *  - per-context overrides in a job: the context that overrides the
 *    three arrays renders bitwise what a synchronous render with the same
 *    overrides gives, and what a render after a PATCH of the same values
 *    gives (an override equals an update); a context without overrides
 *    renders the base state;
 *  - a job whose context override is bad (negative, wrong length, albedo
 *    1.5) is refused at submit with the pointer
 *    /contexts/N/params/KEY, and a bad job-level value with /params/KEY;
 *  - the daemon exits cleanly on SIGTERM, with no sanitizer report in its
 *    log (SAN=1).
 * Films are compared as .npy bodies (float32, bitwise). */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../support/daemon.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define LAYERS   2400
#define MEDIUM   "medium_atmosphere"
#define K_SIGMA  MEDIUM ".sigma_t.data"
#define K_ALBEDO MEDIUM ".albedo.data"
#define K_WEIGHT MEDIUM ".phase_function.weight.data"

static tdaemon d;
static char dir[] = "/tmp/rsw_media_http_XXXXXX";
static char scene_id[80];

/* tools/make_atmosphere.py's profiles at wl nm. */
static void profiles(double wl, double *sigma_t, double *albedo, double *weight) {
  const double top = 120e3, h = 8e3, dz = top / LAYERS;
  double bm = 1.2e-5 * pow(550.0 / wl, 4.05), ba = 0.2 / 2e3 * pow(550.0 / wl, 1.3);
  for (int i = 0; i < LAYERS; i++) {
    double z0 = i * dz, z1 = (i + 1) * dz;
    double sm = bm * h * (exp(-z0 / h) - exp(-z1 / h)) / dz;
    double frac = fmin(fmax((2e3 - z0) / dz, 0.0), 1.0);
    double sa = ba * frac, ss = sm + 0.9 * sa;
    sigma_t[i] = sm + sa;
    albedo[i] = ss / (sm + sa);
    weight[i] = 0.9 * sa / ss;
  }
}

/* A growing string. */
typedef struct str {
  char *p;
  size_t n, cap;
} str;

static void put(str *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void put(str *s, const char *fmt, ...) {
  for (;;) {
    va_list ap;
    va_start(ap, fmt);
    int k = vsnprintf(s->p ? s->p + s->n : NULL, s->p ? s->cap - s->n : 0, fmt, ap);
    va_end(ap);
    if (k >= 0 && s->p && s->n + (size_t)k < s->cap) {
      s->n += (size_t)k;
      return;
    }
    size_t nc = (s->cap + (size_t)k + 1) * 2;
    char *q = realloc(s->p, nc);
    if (!q) abort();
    s->p = q, s->cap = nc;
  }
}

static void put_array(str *s, const double *v, int n) {
  put(s, "[");
  for (int i = 0; i < n; i++) put(s, "%s%.17g", i ? "," : "", v[i]);
  put(s, "]");
}

static thttp_resp call(const char *method, const char *path, const char *body, const char *accept) {
  char acc[96];
  snprintf(acc, sizeof acc, "Accept: %s", accept ? accept : "application/json");
  const char *hdr[] = {"Content-Type: application/json", acc, NULL};
  thttp_resp r = {0};
  tdaemon_http(&d, method, path, hdr, body, body ? strlen(body) : 0, 300, &r);
  return r;
}

static long etag(void) {
  char path[160], v[64] = "";
  snprintf(path, sizeof path, "/v1/scenes/%s/params?match=" MEDIUM ".sigma_t.data", scene_id);
  thttp_resp r = call("GET", path, NULL, NULL);
  long rev = -1;
  if (r.status == 200 && thttp_header(&r, "ETag", v, sizeof v)) rev = strtol(v + (v[0] == '"'), NULL, 10);
  thttp_resp_free(&r);
  return rev;
}

/* A synchronous render as .npy (malloc'ed body, *len); params: a JSON
 * object text or NULL. */
static char *render(const char *params, uint64_t seed, size_t *len) {
  char path[160];
  snprintf(path, sizeof path, "/v1/scenes/%s:render", scene_id);
  str b = {0};
  put(&b, "{\"spp\": 2, \"seed\": %llu, \"wavelength\": 550%s%s}", (unsigned long long)seed,
      params ? ", \"params\": " : "", params ? params : "");
  thttp_resp r = call("POST", path, b.p, "application/x-npy");
  free(b.p);
  char *out = NULL;
  if (r.status == 200) {
    out = r.body, *len = r.len;
    r.body = NULL;
  } else {
    printf("  render: %d %.300s\n", r.status, r.body ? r.body : "");
  }
  thttp_resp_free(&r);
  return out;
}

static bool same(const char *a, size_t na, const char *b, size_t nb) {
  return a && b && na == nb && memcmp(a, b, na) == 0;
}

/* {K_SIGMA: ..., K_ALBEDO: ..., K_WEIGHT: ...} at wl (malloc'ed). */
static char *three_arrays(double wl) {
  double *v = malloc(3 * LAYERS * sizeof *v);
  if (!v) abort();
  profiles(wl, v, v + LAYERS, v + 2 * LAYERS);
  str s = {0};
  put(&s, "{\"" K_SIGMA "\": ");
  put_array(&s, v, LAYERS);
  put(&s, ", \"" K_ALBEDO "\": ");
  put_array(&s, v + LAYERS, LAYERS);
  put(&s, ", \"" K_WEIGHT "\": ");
  put_array(&s, v + 2 * LAYERS, LAYERS);
  put(&s, "}");
  free(v);
  return s.p;
}

static void test_push_and_list(void) {
  size_t len = 0;
  char *text = tsup_read_file("proto/examples/atmosphere.json", &len);
  REQUIRE(text, "read proto/examples/atmosphere.json");
  thttp_resp r = call("POST", "/v1/scenes", text, NULL);
  free(text);
  REQUIRE(r.status == 201 || r.status == 200, "POST /v1/scenes: %d %.500s", r.status, r.body ? r.body : "");
  const char *p = strstr(r.body, "\"id\":\"");
  if (p) sscanf(p + 6, "%64[0-9a-f]", scene_id);
  thttp_resp_free(&r);
  REQUIRE(strlen(scene_id) == 64, "no scene id");
  char path[200];
  snprintf(path, sizeof path, "/v1/scenes/%s/params?match=" MEDIUM ".*", scene_id);
  r = call("GET", path, NULL, NULL);
  CHECK(r.status == 200, "GET params: %d", r.status);
  const char *keys[] = {K_SIGMA, K_ALBEDO, K_WEIGHT};
  for (int k = 0; k < 3 && r.body; k++) {
    char pat[200];
    snprintf(pat, sizeof pat, "\"key\":\"%s\"", keys[k]);
    const char *e = strstr(r.body, pat);
    CHECK(e, "GET params does not list %s", keys[k]);
    CHECK(e && strstr(e, "\"class\":\"spectral\"") && strstr(e, "\"shape\":[2400]"),
          "%s: not spectral with shape [2400]: %.300s", keys[k], e ? e : "");
  }
  thttp_resp_free(&r);
}

static void test_patch_2400(void) {
  REQUIRE(*scene_id, "no scene");
  long rev0 = etag();
  char path[160];
  snprintf(path, sizeof path, "/v1/scenes/%s/params", scene_id);
  double *v = malloc(3 * LAYERS * sizeof *v);
  REQUIRE(v, "out of memory");
  profiles(650, v, v + LAYERS, v + 2 * LAYERS);
  str b = {0};
  put(&b, "{\"" K_SIGMA "\": ");
  put_array(&b, v, LAYERS);
  put(&b, "}");
  thttp_resp r = call("PATCH", path, b.p, NULL);
  CHECK(r.status == 200, "PATCH sigma_t.data: %d %.400s", r.status, r.body ? r.body : "");
  thttp_resp_free(&r);
  CHECK(etag() == rev0 + 1, "the revision did not move by one: %ld -> %ld", rev0, etag());
  /* Back to 550 nm for the tests after this one. */
  profiles(550, v, v + LAYERS, v + 2 * LAYERS);
  b.n = 0;
  put(&b, "{\"" K_SIGMA "\": ");
  put_array(&b, v, LAYERS);
  put(&b, "}");
  r = call("PATCH", path, b.p, NULL);
  CHECK(r.status == 200, "PATCH sigma_t.data back: %d", r.status);
  thttp_resp_free(&r);
  free(b.p);
  free(v);
}

/* A PATCH that must be refused: 422, the key named, revision and film
 * unchanged. */
static void refused_patch(const char *what, const char *body, const char *key) {
  char path[160];
  snprintf(path, sizeof path, "/v1/scenes/%s/params", scene_id);
  long rev0 = etag();
  size_t n0 = 0, n1 = 0;
  char *f0 = render(NULL, 7, &n0);
  thttp_resp r = call("PATCH", path, body, NULL);
  CHECK(r.status == 422, "%s: PATCH answered %d, expected 422: %.300s", what, r.status, r.body ? r.body : "");
  CHECK(r.body && strstr(r.body, key), "%s: the problem does not name %s: %.400s", what, key,
        r.body ? r.body : "");
  thttp_resp_free(&r);
  CHECK(etag() == rev0, "%s: the revision moved (%ld -> %ld)", what, rev0, etag());
  char *f1 = render(NULL, 7, &n1);
  CHECK(same(f0, n0, f1, n1), "%s: the film changed although the PATCH was refused", what);
  free(f0);
  free(f1);
}

static void test_patch_refused_atomic(void) {
  REQUIRE(*scene_id, "no scene");
  double v[LAYERS];
  for (int i = 0; i < LAYERS; i++) v[i] = 0.5;
  str b = {0};
  /* A good albedo first, then a sigma_t one value short. */
  put(&b, "{\"" K_ALBEDO "\": ");
  put_array(&b, v, LAYERS);
  put(&b, ", \"" K_SIGMA "\": ");
  put_array(&b, v, LAYERS - 1);
  put(&b, "}");
  refused_patch("sigma_t of 2,399 values", b.p, K_SIGMA);
  b.n = 0;
  v[100] = -1e-6;
  put(&b, "{\"" K_SIGMA "\": ");
  put_array(&b, v, LAYERS);
  put(&b, "}");
  refused_patch("negative sigma_t", b.p, K_SIGMA);
  b.n = 0;
  v[100] = 1.5;
  put(&b, "{\"" K_SIGMA "\": ");
  put_array(&b, v + 1, LAYERS - 1);
  put(&b, ", \"" K_ALBEDO "\": ");
  put_array(&b, v, LAYERS);
  put(&b, "}");
  refused_patch("albedo 1.5 (and a short sigma_t)", b.p, MEDIUM);
  free(b.p);
}

/* Wait for a job; its state text. */
static bool wait_job(const char *job) {
  char path[160];
  snprintf(path, sizeof path, "/v1/jobs/%s", job);
  for (int i = 0; i < 6000; i++) {
    thttp_resp r = call("GET", path, NULL, NULL);
    bool done = r.status == 200 && !strstr(r.body, "\"state\":\"queued\"") &&
                !strstr(r.body, "\"state\":\"running\"");
    bool ok = done && strstr(r.body, "\"state\":\"succeeded\"");
    if (done && !ok) printf("  job: %.600s\n", r.body);
    thttp_resp_free(&r);
    if (done) return ok;
    usleep(20000);
  }
  return false;
}

static char *result(const char *job, const char *ctx, size_t *len) {
  char path[200];
  snprintf(path, sizeof path, "/v1/jobs/%s/results/%s/measure", job, ctx);
  thttp_resp r = call("GET", path, NULL, "application/x-npy");
  char *out = NULL;
  if (r.status == 200) {
    out = r.body, *len = r.len;
    r.body = NULL;
  } else {
    printf("  result %s: %d %.300s\n", ctx, r.status, r.body ? r.body : "");
  }
  thttp_resp_free(&r);
  return out;
}

static void test_job_overrides(void) {
  REQUIRE(*scene_id, "no scene");
  char *over = three_arrays(650);
  str b = {0};
  put(&b,
      "{\"defaults\": {\"spp\": 2, \"wavelength\": 550}, \"contexts\": ["
      "{\"id\": \"red\", \"seed\": 11, \"params\": %s}, {\"id\": \"base\", \"seed\": 12}]}",
      over);
  char path[160], job[80] = "";
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", scene_id);
  thttp_resp r = call("POST", path, b.p, NULL);
  free(b.p);
  CHECK(r.status == 202, "POST jobs: %d %.400s", r.status, r.body ? r.body : "");
  const char *p = r.body ? strstr(r.body, "\"id\":\"") : NULL;
  if (p) sscanf(p + 6, "%70[A-Za-z0-9_-]", job);
  thttp_resp_free(&r);
  REQUIRE(*job && wait_job(job), "the job did not succeed");
  size_t nr = 0, nb = 0, ns = 0, n0 = 0, np = 0;
  char *red = result(job, "red", &nr), *base = result(job, "base", &nb);
  char *sync_over = render(over, 11, &ns), *sync_base = render(NULL, 12, &n0);
  CHECK(same(red, nr, sync_over, ns), "the overriding context differs from a render with the same overrides");
  CHECK(same(base, nb, sync_base, n0), "the context without overrides differs from a render of the base");
  CHECK(!same(red, nr, base, nb) || nr == 0, "the overrides did not change the film");
  /* An override equals an update: PATCH the base to the same values. */
  snprintf(path, sizeof path, "/v1/scenes/%s/params", scene_id);
  r = call("PATCH", path, over, NULL);
  CHECK(r.status == 200, "PATCH the three arrays: %d %.300s", r.status, r.body ? r.body : "");
  thttp_resp_free(&r);
  char *patched = render(NULL, 11, &np);
  CHECK(same(red, nr, patched, np), "a render after the PATCH differs from the overriding context");
  free(patched);
  /* Back to the base values. */
  char *back = three_arrays(550);
  r = call("PATCH", path, back, NULL);
  CHECK(r.status == 200, "PATCH back: %d", r.status);
  thttp_resp_free(&r);
  free(back);
  free(red), free(base), free(sync_over), free(sync_base), free(over);
}

static void refused_job(const char *what, const char *body, const char *pointer) {
  char path[160];
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", scene_id);
  thttp_resp r = call("POST", path, body, NULL);
  CHECK(r.status == 422, "%s: POST jobs answered %d, expected 422: %.300s", what, r.status,
        r.body ? r.body : "");
  CHECK(r.body && strstr(r.body, pointer), "%s: the problem does not name %s: %.400s", what, pointer,
        r.body ? r.body : "");
  thttp_resp_free(&r);
}

static void test_job_refused(void) {
  REQUIRE(*scene_id, "no scene");
  double v[LAYERS];
  for (int i = 0; i < LAYERS; i++) v[i] = 1e-5;
  str b = {0}, ok = {0};
  put(&ok, "{\"id\": \"a\", \"params\": {\"" K_SIGMA "\": ");
  put_array(&ok, v, LAYERS);
  put(&ok, "}}");
  v[7] = -1;
  put(&b,
      "{\"defaults\": {\"spp\": 1}, \"contexts\": [%s, {\"id\": \"b\", \"params\": {\"" K_SIGMA "\": ", ok.p);
  put_array(&b, v, LAYERS);
  put(&b, "}}]}");
  refused_job("negative sigma_t in context 1", b.p, "/contexts/1/params/" K_SIGMA);
  b.n = 0;
  v[7] = 0.3;
  put(&b,
      "{\"defaults\": {\"spp\": 1}, \"contexts\": [%s, {\"id\": \"b\", \"params\": {\"" K_SIGMA "\": ", ok.p);
  put_array(&b, v, 24);
  put(&b, "}}]}");
  refused_job("sigma_t of 24 values in context 1", b.p, "/contexts/1/params/" K_SIGMA);
  b.n = 0;
  for (int i = 0; i < LAYERS; i++) v[i] = 0.5;
  v[2399] = 1.5;
  put(&b, "{\"params\": {\"" K_ALBEDO "\": ");
  put_array(&b, v, LAYERS);
  put(&b, "}, \"defaults\": {\"spp\": 1}, \"contexts\": [{\"id\": \"a\"}]}");
  refused_job("job-level albedo 1.5", b.p, "/params/" K_ALBEDO);
  free(b.p);
  free(ok.p);
}

int main(void) {
  if (!mkdtemp(dir)) return 1;
  const char *extra[] = {"--threads", "2", "--data-root", ".", NULL};
  if (!tdaemon_start(&d, dir, "media", extra, 0)) {
    printf("FAIL start the daemon\ntest_media_http: 0 passed, 1 failed\n");
    return 1;
  }
  RSW_TEST_RUN(test_push_and_list);
  RSW_TEST_RUN(test_patch_2400);
  RSW_TEST_RUN(test_patch_refused_atomic);
  RSW_TEST_RUN(test_job_overrides);
  RSW_TEST_RUN(test_job_refused);
  int rc = tdaemon_stop(&d, 10, NULL);
  /* The daemon exits cleanly, and (SAN=1) with no sanitizer report. */
  char *log = tdaemon_log(&d);
  bool clean = rc == 0 && !(log && (strstr(log, "Sanitizer") || strstr(log, "runtime error")));
  if (!clean) printf("  FAIL the daemon: exit %d, log:\n%.2000s\n", rc, log ? log : "");
  free(log);
  if (clean)
    rsw_test_passed_++;
  else
    rsw_test_failed_++;
  char p[128];
  snprintf(p, sizeof p, "%s/media.log", dir);
  unlink(p);
  snprintf(p, sizeof p, "%s/media.port", dir);
  unlink(p);
  rmdir(dir);
  RSW_TEST_END("test_media_http");
}
