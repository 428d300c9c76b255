/* `raysweepd serve` end to end: the real daemon on 127.0.0.1 with an
 * ephemeral port (--listen 127.0.0.1:0 --port-file F), driven over HTTP with
 * libcurl. No mocks: every route of proto/API-NOTES.md with its success
 * status and body shape, every error status with its problem+json body,
 * PATCH-then-render against a fresh load, a spectral job against the
 * closed form rho(lambda) E / pi, split jobs bitwise equal, SSE with resume,
 * cancel, blobs by digest, 8 concurrent clients, paths outside --data-root,
 * and SIGTERM.
 *
 * Three daemons: the main one (most tests), one with --token-file (401),
 * and one with a small --max-body and --max-queue (413, 429, SIGTERM with
 * work running). Scenes are tiny (1x1 and 5x5 films, a few spp) so the
 * binary stays well under 20 s; the "long" jobs are only long enough to be
 * caught running and are always cancelled. */
#include <cjson/cJSON.h>
#include <curl/curl.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <openssl/sha.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "../support/daemon.h"
#include "../support/test.h"
#include "../support/tfile.h"
#include "image_exr.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

/* ---- temp dirs and files ------------------------------------------------------ */

static char tmpdir[64];

static const char *bin_dir(void) {
  const char *e = getenv("RSW_BIN_DIR");
  return e && *e ? e : "build/bin";
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void sleep_ms(int ms) {
  struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
  nanosleep(&ts, NULL);
}

static bool write_bytes(const char *path, const void *data, size_t len) {
  FILE *f = fopen(path, "wb");
  if (!f) return false;
  bool ok = fwrite(data, 1, len, f) == len;
  return fclose(f) == 0 && ok;
}

/* printf into buf, then ' -> " so JSON bodies read without escapes. */
static char *jq(char *buf, size_t n, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static char *jq(char *buf, size_t n, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(buf, n, fmt, ap);
  va_end(ap);
  for (char *p = buf; *p; p++)
    if (*p == '\'') *p = '"';
  return buf;
}

static void sha256_hex(const void *data, size_t len, char out[65]) {
  unsigned char md[SHA256_DIGEST_LENGTH];
  SHA256((const unsigned char *)data, len, md);
  for (int i = 0; i < SHA256_DIGEST_LENGTH; i++) snprintf(out + 2 * i, 3, "%02x", md[i]);
}

/* ---- daemons ----------------------------------------------------------------- */

/* tests/support/daemon.h runs the process; a token rides along. */
typedef struct daemon_proc {
  tdaemon t;      /* pid, port, log */
  char token[64]; /* sent as a bearer token when non-empty */
} daemon_proc;

/* Start `raysweepd serve` on 127.0.0.1:0 with the common options plus
 * extra (NULL-terminated), and wait (up to 20 s: the sanitizer build is
 * slow to start) for the port file. */
static bool daemon_start(daemon_proc *d, const char *name, const char *const *extra) {
  memset(d, 0, sizeof *d);
  char data_root[160], blob_dir[160];
  snprintf(data_root, sizeof data_root, "%s/data", tmpdir);
  snprintf(blob_dir, sizeof blob_dir, "%s/%s-blobs", tmpdir, name);
  const char *argv[64];
  int n = 0;
  argv[n++] = "--data-root";
  argv[n++] = data_root;
  argv[n++] = "--blob-dir";
  argv[n++] = blob_dir;
  for (int i = 0; extra && extra[i] && n < 62; i++) argv[n++] = extra[i];
  argv[n] = NULL;
  return tdaemon_start(&d->t, tmpdir, name, argv, 20.0);
}

/* SIGTERM; wait up to limit_s. Returns the exit status, -1 for a signal,
 * -2 when it had to be killed. *secs: how long it took. */
static int daemon_stop(daemon_proc *d, double limit_s, double *secs) {
  return tdaemon_stop(&d->t, limit_s, secs);
}

/* ---- HTTP -------------------------------------------------------------------- */

typedef struct req {
  const char *method; /* default GET */
  const char *path;
  const char *ctype;  /* Content-Type when there is a body (default application/json) */
  const char *accept; /* NULL: curl's default (Accept: * / *) */
  const char *hdr[6]; /* extra request headers, "Name: value" */
  const void *body;
  size_t len;       /* 0 with body: strlen(body) */
  double timeout_s; /* default 30 */
  bool sse;         /* stop reading after the SSE `end` event */
} req;

typedef struct resp {
  long status; /* 0: transport failure */
  char *body;
  size_t len;
  char *hdrs;
  size_t hlen;
  double secs;
  bool sse;
} resp;

static void resp_free(resp *r) {
  free(r->body);
  free(r->hdrs);
  memset(r, 0, sizeof *r);
}

static void append(char **buf, size_t *len, const char *data, size_t n) {
  char *nb = realloc(*buf, *len + n + 1);
  if (!nb) return;
  memcpy(nb + *len, data, n);
  *len += n;
  nb[*len] = '\0';
  *buf = nb;
}

static size_t on_body(char *data, size_t size, size_t nmemb, void *user) {
  resp *r = user;
  size_t n = size * nmemb;
  append(&r->body, &r->len, data, n);
  if (r->sse && r->body) {
    const char *end = strstr(r->body, "event: end");
    if (end && strstr(end, "\n\n")) return 0; /* stop: the stream is complete */
  }
  return n;
}

static size_t on_header(char *data, size_t size, size_t nmemb, void *user) {
  resp *r = user;
  append(&r->hdrs, &r->hlen, data, size * nmemb);
  return size * nmemb;
}

/* Value of response header `name` (the last one), copied into out. */
static const char *hdr(const resp *r, const char *name, char *out, size_t n) {
  out[0] = '\0';
  size_t nl = strlen(name);
  for (const char *p = r->hdrs; p && *p;) {
    const char *eol = strchr(p, '\n');
    size_t ll = eol ? (size_t)(eol - p) : strlen(p);
    if (ll > nl && strncasecmp(p, name, nl) == 0 && p[nl] == ':') {
      const char *v = p + nl + 1;
      while (*v == ' ' || *v == '\t') v++;
      size_t vl = (size_t)(p + ll - v);
      while (vl && (v[vl - 1] == '\r' || v[vl - 1] == ' ')) vl--;
      if (vl >= n) vl = n - 1;
      memcpy(out, v, vl);
      out[vl] = '\0';
    }
    if (!eol) break;
    p = eol + 1;
  }
  return out;
}

static resp do_req(const daemon_proc *d, req q) {
  resp r = {0};
  r.sse = q.sse;
  CURL *c = curl_easy_init();
  if (!c) return r;
  char url[2048], auth[128], ct[128], acc[128];
  snprintf(url, sizeof url, "%s%s", d->t.base_url, q.path);
  curl_easy_setopt(c, CURLOPT_URL, url);
  curl_easy_setopt(c, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(c, CURLOPT_TIMEOUT_MS, (long)(1000 * (q.timeout_s > 0 ? q.timeout_s : 30)));
  curl_easy_setopt(c, CURLOPT_WRITEFUNCTION, on_body);
  curl_easy_setopt(c, CURLOPT_WRITEDATA, &r);
  curl_easy_setopt(c, CURLOPT_HEADERFUNCTION, on_header);
  curl_easy_setopt(c, CURLOPT_HEADERDATA, &r);
  struct curl_slist *h = NULL;
  h = curl_slist_append(h, "Expect:");
  if (d->token[0]) {
    snprintf(auth, sizeof auth, "Authorization: Bearer %s", d->token);
    h = curl_slist_append(h, auth);
  }
  if (q.accept) {
    snprintf(acc, sizeof acc, "Accept: %s", q.accept);
    h = curl_slist_append(h, acc);
  }
  for (int i = 0; i < 6 && q.hdr[i]; i++) h = curl_slist_append(h, q.hdr[i]);
  const char *method = q.method ? q.method : "GET";
  if (q.body) {
    size_t len = q.len ? q.len : strlen(q.body);
    snprintf(ct, sizeof ct, "Content-Type: %s", q.ctype ? q.ctype : "application/json");
    h = curl_slist_append(h, ct);
    curl_easy_setopt(c, CURLOPT_POSTFIELDSIZE_LARGE, (curl_off_t)len);
    curl_easy_setopt(c, CURLOPT_POSTFIELDS, q.body);
    if (strcmp(method, "POST") != 0) curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, method);
  } else if (strcmp(method, "HEAD") == 0) {
    curl_easy_setopt(c, CURLOPT_NOBODY, 1L);
  } else if (strcmp(method, "POST") == 0) {
    h = curl_slist_append(h, "Content-Type:"); /* no body, no type (curl would say form-urlencoded) */
    curl_easy_setopt(c, CURLOPT_POSTFIELDSIZE_LARGE, (curl_off_t)0);
    curl_easy_setopt(c, CURLOPT_POSTFIELDS, "");
  } else if (strcmp(method, "GET") != 0) {
    curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, method);
  }
  curl_easy_setopt(c, CURLOPT_HTTPHEADER, h);
  double t0 = now_s();
  CURLcode cc = curl_easy_perform(c);
  r.secs = now_s() - t0;
  if (cc == CURLE_OK || (q.sse && cc == CURLE_WRITE_ERROR))
    curl_easy_getinfo(c, CURLINFO_RESPONSE_CODE, &r.status);
  else
    fprintf(stdout, "  %s %s: %s\n", method, q.path, curl_easy_strerror(cc));
  curl_slist_free_all(h);
  curl_easy_cleanup(c);
  if (!r.body) r.body = calloc(1, 1);
  return r;
}

static resp get(const daemon_proc *d, const char *path) {
  return do_req(d, (req){.path = path});
}
static resp post_json(const daemon_proc *d, const char *path, const char *body) {
  return do_req(d, (req){.method = "POST", .path = path, .body = body});
}

static cJSON *jparse(const resp *r) {
  return r->body ? cJSON_ParseWithLength(r->body, r->len) : NULL;
}
static const char *jstr(const cJSON *o, const char *k) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, k);
  return cJSON_IsString(v) ? v->valuestring : NULL;
}
static double jnum(const cJSON *o, const char *k) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, k);
  return cJSON_IsNumber(v) ? v->valuedouble : NAN;
}
static bool jstr_is(const cJSON *o, const char *k, const char *want) {
  const char *s = jstr(o, k);
  return s && strcmp(s, want) == 0;
}
static bool starts_with(const char *s, const char *p) {
  return s && strncmp(s, p, strlen(p)) == 0;
}

/* An RFC 9457 body with the status of the response. */
#define CHECK_PROBLEM(r, want, what)                                                                         \
  do {                                                                                                       \
    char ct_[128];                                                                                           \
    CHECK((r).status == (want), "%s: status %ld, want %d; body %.300s", what, (r).status, want, (r).body);   \
    hdr(&(r), "Content-Type", ct_, sizeof ct_);                                                              \
    CHECK(starts_with(ct_, "application/problem+json"), "%s: Content-Type '%s'", what, ct_);                 \
    cJSON *p_ = jparse(&(r));                                                                                \
    CHECK(p_ &&jnum(p_, "status") == (want), "%s: problem status field: %.300s", what, (r).body);            \
    CHECK(p_ &&jstr(p_, "type") && jstr(p_, "title") && jstr(p_, "detail") && jstr(p_, "code"),              \
          "%s: problem has type, title, detail, code: %.300s", what, (r).body);                              \
    cJSON_Delete(p_);                                                                                        \
  } while (0)

/* ---- scenes and jobs ----------------------------------------------------------------- */

/* The Lambertian plate of the spectral tests: a `distant` 1x1 meter looking
 * down at the plate's centre, a 5x5 hdistant (no target: noisy, so seeds
 * matter), a directional emitter of irradiance 1 at nadir. %s is the plate
 * reflectance (a number), so tests can make documents (scene ids) of their
 * own. */
static const char *PLATE_FMT =
    "{'type': 'scene', 'variant': 'mono',"
    " 'meter': {'type': 'distant', 'direction': [0, 0, -1], 'target': [0, 0, 0],"
    "   'film': {'type': 'hdrfilm', 'width': 1, 'height': 1, 'component_format': 'float32',"
    "     'rfilter': {'type': 'box'}}},"
    " 'hemi': {'type': 'hdistant', 'sampler': {'type': 'independent', 'sample_count': 4},"
    "   'film': {'type': 'hdrfilm', 'width': 5, 'height': 5, 'component_format': 'float32',"
    "     'rfilter': {'type': 'box'}}},"
    " 'sun': {'type': 'directional', 'direction': [0, 0, -1], 'irradiance': 1.0},"
    " 'plate': {'type': 'rectangle', 'bsdf': {'type': 'diffuse', 'reflectance': %s}}}";

static daemon_proc main_d, lim_d;
static bool main_ok;
/* Samples per second of one 5x5 hdistant render of the plate (one render
 * tile, so one thread), measured at start: "long" renders are sized in
 * seconds, the same in the -O2 and the sanitizer builds. */
static double plate_sps = 3e6;

/* POST a scene; 200 or 201; id into id_out (65 bytes). Returns the status. */
static long post_scene(const daemon_proc *d, const char *doc, const char *ctype, char *id_out) {
  resp r = do_req(d, (req){.method = "POST", .path = "/v1/scenes", .body = doc, .ctype = ctype});
  cJSON *j = jparse(&r);
  id_out[0] = '\0';
  if ((r.status == 200 || r.status == 201) && jstr(j, "id"))
    snprintf(id_out, 65, "%s", jstr(j, "id"));
  else
    fprintf(stdout, "  POST /v1/scenes: %ld %.400s\n", r.status, r.body);
  long st = r.status;
  cJSON_Delete(j);
  resp_free(&r);
  return st;
}

static bool plate_scene(const daemon_proc *d, const char *rho, char *id) {
  char doc[4096];
  jq(doc, sizeof doc, PLATE_FMT, rho);
  long st = post_scene(d, doc, NULL, id);
  return (st == 200 || st == 201) && id[0];
}

/* The default scene (the embedded hdistant seed scene): the first listed. */
static bool default_scene(const daemon_proc *d, char *id) {
  resp r = get(d, "/v1/scenes");
  cJSON *j = jparse(&r);
  cJSON *arr = cJSON_GetObjectItemCaseSensitive(j, "scenes");
  id[0] = '\0';
  cJSON *it;
  cJSON_ArrayForEach(it, arr) {
    const cJSON *s = cJSON_GetObjectItemCaseSensitive(it, "sensors");
    const cJSON *s0 = cJSON_GetArrayItem(s, 0);
    if (jstr(it, "id") && cJSON_IsString(s0) && strcmp(s0->valuestring, "hdistant") == 0) {
      snprintf(id, 65, "%s", jstr(it, "id"));
      break;
    }
  }
  cJSON_Delete(j);
  resp_free(&r);
  return id[0] != '\0';
}

/* Submit a job; returns the status; job id into job (128 bytes). */
static long submit_job(const daemon_proc *d, const char *scene, const char *body, const char *idem,
                       char *job) {
  char path[256], ik[160];
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", scene);
  req q = {.method = "POST", .path = path, .body = body};
  if (idem) {
    snprintf(ik, sizeof ik, "Idempotency-Key: %s", idem);
    q.hdr[0] = ik;
  }
  resp r = do_req(d, q);
  cJSON *j = jparse(&r);
  job[0] = '\0';
  if (r.status == 202 && jstr(j, "id"))
    snprintf(job, 128, "%s", jstr(j, "id"));
  else if (r.status != 429 && r.status != 409)
    fprintf(stdout, "  POST %s: %ld %.400s\n", path, r.status, r.body);
  long st = r.status;
  cJSON_Delete(j);
  resp_free(&r);
  return st;
}

static bool terminal(const char *state) {
  return state &&
         (strcmp(state, "succeeded") == 0 || strcmp(state, "failed") == 0 || strcmp(state, "cancelled") == 0);
}

/* Poll GET /v1/jobs/{id} until the state is final (or timeout_s); returns
 * the last Job document (caller frees), NULL if it could not be read. */
static cJSON *wait_job(const daemon_proc *d, const char *job, double timeout_s) {
  char path[256];
  snprintf(path, sizeof path, "/v1/jobs/%s", job);
  double t0 = now_s();
  cJSON *j = NULL;
  for (;;) {
    resp r = get(d, path);
    cJSON_Delete(j);
    j = r.status == 200 ? jparse(&r) : NULL;
    resp_free(&r);
    if (!j || terminal(jstr(j, "state")) || now_s() - t0 > timeout_s) return j;
    sleep_ms(10);
  }
}

/* Wait until a job is running (true) or has ended / timed out (false). */
static bool wait_running(const daemon_proc *d, const char *job, double timeout_s) {
  char path[256];
  snprintf(path, sizeof path, "/v1/jobs/%s", job);
  double t0 = now_s();
  while (now_s() - t0 < timeout_s) {
    resp r = get(d, path);
    cJSON *j = jparse(&r);
    const char *st = jstr(j, "state");
    bool running = st && strcmp(st, "running") == 0, over = !st || terminal(st);
    cJSON_Delete(j);
    resp_free(&r);
    if (running) return true;
    if (over) return false;
    sleep_ms(5);
  }
  return false;
}

/* ---- films ------------------------------------------------------------------- */

typedef struct film {
  int w, h, c;
  double *data; /* HWC */
  cJSON *doc;   /* the JSON film (meta etc.) */
} film;

static void film_free(film *f) {
  free(f->data);
  cJSON_Delete(f->doc);
  memset(f, 0, sizeof *f);
}

/* A JSON film body into f; false (with a message) when the shape is off. */
static bool film_from_json(const resp *r, film *f) {
  memset(f, 0, sizeof *f);
  f->doc = jparse(r);
  if (!f->doc) return false;
  f->w = (int)jnum(f->doc, "width");
  f->h = (int)jnum(f->doc, "height");
  const cJSON *ch = cJSON_GetObjectItemCaseSensitive(f->doc, "channels");
  const cJSON *data = cJSON_GetObjectItemCaseSensitive(f->doc, "data");
  f->c = cJSON_GetArraySize(ch);
  int n = cJSON_GetArraySize(data);
  if (f->w <= 0 || f->h <= 0 || f->c <= 0 || n != f->w * f->h * f->c || !jstr_is(f->doc, "layout", "HWC")) {
    fprintf(stdout, "  bad JSON film: %.300s\n", r->body);
    return false;
  }
  f->data = malloc(sizeof(double) * (size_t)n);
  int i = 0;
  const cJSON *v;
  cJSON_ArrayForEach(v, data) f->data[i++] = cJSON_IsNumber(v) ? v->valuedouble : NAN;
  return true;
}

/* Parse an .npy body: '<f4', C order; shape into sh[3]; *data points into
 * the body. */
static bool npy_parse(const resp *r, int sh[3], const float **data, size_t *n) {
  const unsigned char *b = (const unsigned char *)r->body;
  if (r->len < 12 || memcmp(b, "\x93NUMPY", 6) != 0) return false;
  size_t hl, off;
  if (b[6] == 1) {
    hl = (size_t)b[8] | ((size_t)b[9] << 8);
    off = 10;
  } else {
    hl = (size_t)b[8] | ((size_t)b[9] << 8) | ((size_t)b[10] << 16) | ((size_t)b[11] << 24);
    off = 12;
  }
  if (off + hl > r->len) return false;
  char header[1024];
  size_t cl = hl < sizeof header - 1 ? hl : sizeof header - 1;
  memcpy(header, b + off, cl);
  header[cl] = '\0';
  if (!strstr(header, "'descr': '<f4'") || !strstr(header, "'fortran_order': False")) {
    fprintf(stdout, "  npy header: %s\n", header);
    return false;
  }
  const char *s = strstr(header, "'shape': (");
  if (!s || sscanf(s, "'shape': (%d, %d, %d)", &sh[0], &sh[1], &sh[2]) != 3) {
    fprintf(stdout, "  npy shape: %s\n", header);
    return false;
  }
  if ((off + hl) % 16 != 0) fprintf(stdout, "  npy data offset %zu not 16-aligned\n", off + hl);
  *data = (const float *)(b + off + hl);
  *n = (r->len - off - hl) / 4;
  return *n == (size_t)sh[0] * (size_t)sh[1] * (size_t)sh[2];
}

static resp result(const daemon_proc *d, const char *job, const char *ctx, const char *sensor,
                   const char *accept) {
  char path[512];
  snprintf(path, sizeof path, "/v1/jobs/%s/results/%s/%s", job, ctx, sensor);
  return do_req(d, (req){.path = path, .accept = accept});
}

/* POST .../results:fetch: several films in one multipart/mixed answer,
 * each part byte for byte its GET's answer, in the order asked, with its
 * Content-Location; the refusals. (A job of 2 contexts a, b.2 x 2 sensors
 * hemi and another, finished.) */
static void test_results_fetch(const char *job) {
  static const char *const accepts[] = {"image/x-exr", "application/x-npy"};
  char path[256];
  snprintf(path, sizeof path, "/v1/jobs/%s/results:fetch", job);
  const char *body =
      "{\"results\": [{\"context\": \"b.2\", \"sensor\": \"hemi\"}, "
      "{\"context\": \"a\", \"sensor\": \"hemi\"}, {\"context\": \"b.2\", \"sensor\": \"hemi\"}]}";
  static const char *const order[] = {"b.2", "a", "b.2"};
  for (int k = 0; k < 2; k++) {
    resp r = do_req(&main_d, (req){.method = "POST", .path = path, .accept = accepts[k], .body = body});
    char ct[256];
    hdr(&r, "Content-Type", ct, sizeof ct);
    const char *bp = strstr(ct, "boundary=");
    CHECK(r.status == 200 && starts_with(ct, "multipart/mixed") && bp, "results:fetch %s: %ld %s", accepts[k],
          r.status, ct);
    if (r.status != 200 || !bp) {
      resp_free(&r);
      continue;
    }
    char dash[128];
    int bl = snprintf(dash, sizeof dash, "--%s", bp + 9);
    const char *p = r.body, *end = r.body + r.len;
    for (int i = 0; i < 3; i++) {
      resp one = result(&main_d, job, order[i], "hemi", accepts[k]);
      char want[256], head[600];
      snprintf(want, sizeof want, "Content-Location: /v1/jobs/%s/results/%s/hemi\r\n", job, order[i]);
      const char *hend = (size_t)(end - p) > (size_t)bl ? strstr(p, "\r\n\r\n") : NULL;
      size_t hl = hend ? (size_t)(hend - p) : 0;
      snprintf(head, sizeof head, "%.*s\r\n", (int)(hl < 500 ? hl : 500), p);
      long n = -1;
      const char *cl = strstr(head, "Content-Length: ");
      if (cl) n = strtol(cl + 16, NULL, 10);
      bool same = hend && strncmp(p, dash, (size_t)bl) == 0 && strstr(head, want) && n == (long)one.len &&
                  (size_t)(end - hend - 4) >= one.len + 2 && memcmp(hend + 4, one.body, one.len) == 0 &&
                  memcmp(hend + 4 + one.len, "\r\n", 2) == 0;
      CHECK(same, "results:fetch %s part %d is GET %s/hemi's %zu bytes: %.300s", accepts[k], i, order[i],
            one.len, head);
      resp_free(&one);
      if (!same) break;
      p = hend + 4 + n + 2;
    }
    CHECK((size_t)(end - p) == (size_t)bl + 4 && strncmp(p, dash, (size_t)bl) == 0 &&
              strcmp(p + bl, "--\r\n") == 0,
          "results:fetch %s ends with the closing boundary", accepts[k]);
    resp_free(&r);
  }
  /* Refusals: JSON or PNG asked for, a bad list, a film not there, no such job. */
  resp r = do_req(&main_d, (req){.method = "POST", .path = path, .accept = "application/json", .body = body});
  CHECK_PROBLEM(r, 406, "results:fetch as JSON");
  resp_free(&r);
  static const char *const bad[][2] = {
      {"{\"results\": []}", "/results"},
      {"{\"results\": [{\"context\": \"a\"}]}", "/results/0"},
      {"{\"results\": [{\"context\": \"a\", \"sensor\": \"hemi\", \"x\": 1}]}", "/results/0"},
      {"{\"films\": []}", "/films"},
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    r = do_req(&main_d, (req){.method = "POST", .path = path, .accept = "image/x-exr", .body = bad[i][0]});
    cJSON *j = jparse(&r);
    CHECK(r.status == 422 && jstr_is(j, "pointer", bad[i][1]), "results:fetch %s: %ld %.300s", bad[i][0],
          r.status, r.body);
    cJSON_Delete(j);
    resp_free(&r);
  }
  r = do_req(&main_d, (req){.method = "POST",
                            .path = path,
                            .accept = "image/x-exr",
                            .body = "{\"results\": [{\"context\": \"a\", \"sensor\": \"hemi\"}, "
                                    "{\"context\": \"nosuch\", \"sensor\": \"hemi\"}]}"});
  CHECK_PROBLEM(r, 404, "results:fetch with a context not in the job");
  resp_free(&r);
  r = do_req(&main_d, (req){.method = "POST",
                            .path = "/v1/jobs/no-such-job/results:fetch",
                            .accept = "image/x-exr",
                            .body = "{\"results\": [{\"context\": \"a\", \"sensor\": \"hemi\"}]}"});
  CHECK_PROBLEM(r, 404, "results:fetch of an unknown job");
  resp_free(&r);
}

/* ---- tests: metadata, health, metrics ------------------------------------------- */

static void test_server_info(void) {
  resp r = get(&main_d, "/v1");
  REQUIRE(r.status == 200, "GET /v1: %ld", r.status);
  char ct[128];
  CHECK(starts_with(hdr(&r, "Content-Type", ct, sizeof ct), "application/json"), "Content-Type %s", ct);
  cJSON *j = jparse(&r);
  CHECK(jstr_is(j, "name", "raysweepd"), "name: %.200s", r.body);
  CHECK(jstr(j, "version") && jstr_is(j, "api_version", "v1"), "version, api_version v1");
  CHECK(cJSON_GetObjectItemCaseSensitive(j, "build") != NULL, "build");
  const cJSON *variants = cJSON_GetObjectItemCaseSensitive(j, "variants");
  bool mono = false, rgb = false, hdistant = false;
  const cJSON *it;
  cJSON_ArrayForEach(it, variants) {
    if (cJSON_IsString(it) && strcmp(it->valuestring, "mono") == 0) mono = true;
    if (cJSON_IsString(it) && strcmp(it->valuestring, "rgb") == 0) rgb = true;
  }
  CHECK(mono && rgb, "variants mono and rgb");
  cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(j, "plugins")) {
    if (jstr_is(it, "name", "hdistant") && jstr_is(it, "class", "sensor")) hdistant = true;
  }
  CHECK(hdistant, "plugins lists {name: hdistant, class: sensor}");
  const cJSON *lim = cJSON_GetObjectItemCaseSensitive(j, "limits");
  CHECK(jnum(lim, "max_body_bytes") > 0 && jnum(lim, "max_depth") > 0 && jnum(lim, "max_queue") > 0 &&
            jnum(lim, "max_pixel_samples") > 0 && jnum(lim, "result_ttl_s") > 0,
        "limits: %s", lim ? "incomplete" : "missing");
  cJSON_Delete(j);
  resp_free(&r);
}

static void test_health(void) {
  resp r = get(&main_d, "/v1/health/live");
  cJSON *j = jparse(&r);
  CHECK(r.status == 200 && jstr_is(j, "status", "live"), "live: %ld %s", r.status, r.body);
  cJSON_Delete(j);
  resp_free(&r);
  r = get(&main_d, "/v1/health/ready");
  j = jparse(&r);
  CHECK(r.status == 200 && jstr_is(j, "status", "ready"), "ready: %ld %s", r.status, r.body);
  cJSON_Delete(j);
  resp_free(&r);
}

static void test_metrics(void) {
  resp r = get(&main_d, "/metrics");
  REQUIRE(r.status == 200, "GET /metrics: %ld", r.status);
  char ct[128];
  CHECK(starts_with(hdr(&r, "Content-Type", ct, sizeof ct), "text/plain"), "Content-Type %s", ct);
  CHECK(strstr(ct, "version=0.0.4") != NULL, "text format 0.0.4: %s", ct);
  CHECK(strstr(r.body, "# TYPE ") && strstr(r.body, "# HELP "), "HELP and TYPE lines");
  /* The issue's list: requests by route and status, scenes resident and
   * their bytes, jobs by state, contexts rendered, render seconds, update
   * seconds by class, queue depth. */
  const char *names[] = {"raysweep_http_requests_total",
                         "raysweep_scenes_resident",
                         "raysweep_scene_bytes",
                         "raysweep_jobs",
                         "raysweep_contexts_rendered_total",
                         "raysweep_render_seconds_total",
                         "raysweep_update_seconds_total",
                         "raysweep_queue_depth"};
  for (size_t i = 0; i < sizeof names / sizeof *names; i++)
    CHECK(strstr(r.body, names[i]) != NULL, "metric %s present", names[i]);
  /* Values after the tests before this one: requests counted by route
   * template and status, scenes resident, jobs that succeeded, renders,
   * spectral updates (the PATCHes). */
  CHECK(strstr(r.body, "raysweep_http_requests_total{route=\"") && strstr(r.body, "status=\"200\"}"),
        "requests labelled by route and status");
  CHECK(!strstr(r.body, "route=\"/v1/jobs/job-") && strstr(r.body, "{id}"),
        "routes are templates, not concrete paths");
  double v;
  const char *p = strstr(r.body, "\nraysweep_scenes_resident ");
  CHECK(p && sscanf(p, "\nraysweep_scenes_resident %lf", &v) == 1 && v >= 3, "scenes resident: %s",
        p ? "too few" : "missing");
  p = strstr(r.body, "\nraysweep_contexts_rendered_total ");
  CHECK(p && sscanf(p, "\nraysweep_contexts_rendered_total %lf", &v) == 1 && v >= 40, "contexts rendered");
  p = strstr(r.body, "raysweep_jobs{state=\"succeeded\"} ");
  CHECK(p && sscanf(p, "raysweep_jobs{state=\"succeeded\"} %lf", &v) == 1 && v >= 5, "succeeded jobs");
  p = strstr(r.body, "raysweep_update_seconds_total{class=\"spectral\"} ");
  CHECK(p != NULL, "update seconds by class");
  resp_free(&r);
}

/* ---- tests: scenes, params ------------------------------------------------------ */

static void test_scenes_json(void) {
  char doc[4096], ct[128], loc[256];
  jq(doc, sizeof doc, PLATE_FMT, "0.123");
  resp r = do_req(&main_d, (req){.method = "POST", .path = "/v1/scenes", .body = doc});
  REQUIRE(r.status == 201, "first POST is 201: %ld %.300s", r.status, r.body);
  cJSON *j = jparse(&r);
  const char *id = jstr(j, "id");
  REQUIRE(id && strlen(id) == 64 && strspn(id, "0123456789abcdef") == 64, "id is 64 hex: %s", r.body);
  char sid[65];
  snprintf(sid, sizeof sid, "%s", id);
  CHECK(jstr_is(j, "variant", "mono"), "variant mono");
  CHECK(jnum(j, "revision") == 0, "revision 0");
  const cJSON *s = cJSON_GetObjectItemCaseSensitive(j, "sensors");
  CHECK(cJSON_GetArraySize(s) == 2 && cJSON_IsString(cJSON_GetArrayItem(s, 0)) &&
            strcmp(cJSON_GetArrayItem(s, 0)->valuestring, "meter") == 0 &&
            strcmp(cJSON_GetArrayItem(s, 1)->valuestring, "hemi") == 0,
        "sensors [meter, hemi] in order");
  char want_loc[128];
  snprintf(want_loc, sizeof want_loc, "/v1/scenes/%s", sid);
  hdr(&r, "Location", loc, sizeof loc);
  CHECK(strstr(loc, want_loc) != NULL, "Location %s", loc);
  CHECK(starts_with(hdr(&r, "Content-Type", ct, sizeof ct), "application/json"), "Content-Type %s", ct);
  cJSON_Delete(j);
  resp_free(&r);
  /* Same body: no-op, 200, same id. */
  r = do_req(&main_d, (req){.method = "POST", .path = "/v1/scenes", .body = doc});
  j = jparse(&r);
  CHECK(r.status == 200, "second POST is 200: %ld", r.status);
  CHECK(jstr_is(j, "id", sid), "same id");
  cJSON_Delete(j);
  resp_free(&r);
  /* List and get. */
  r = get(&main_d, "/v1/scenes");
  j = jparse(&r);
  bool listed = false;
  const cJSON *it;
  cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(j, "scenes")) if (jstr_is(it, "id", sid)) listed =
      true;
  CHECK(r.status == 200 && listed, "GET /v1/scenes lists it: %ld", r.status);
  cJSON_Delete(j);
  resp_free(&r);
  r = get(&main_d, want_loc);
  j = jparse(&r);
  CHECK(r.status == 200 && jstr_is(j, "id", sid) && jstr_is(j, "variant", "mono"), "GET scene: %ld",
        r.status);
  CHECK(jnum(j, "shapes") == 1 && jnum(j, "emitters") == 1, "1 shape, 1 emitter: %.300s", r.body);
  CHECK(jnum(j, "params") > 0 && jnum(j, "resident_bytes") > 0 && jnum(j, "load_seconds") >= 0,
        "params, resident_bytes, load_seconds: %.300s", r.body);
  CHECK(jstr(j, "created") && jnum(j, "jobs_active") == 0, "created, jobs_active 0");
  cJSON_Delete(j);
  resp_free(&r);
  /* DELETE: 204, then 404. */
  r = do_req(&main_d, (req){.method = "DELETE", .path = want_loc});
  CHECK(r.status == 204, "DELETE scene: %ld %s", r.status, r.body);
  resp_free(&r);
  r = get(&main_d, want_loc);
  CHECK_PROBLEM(r, 404, "GET deleted scene");
  resp_free(&r);
}

static void test_scenes_xml_seed(void) {
  size_t len;
  char *xml = tfile_read("proto/examples/hdistant_seed.xml", &len);
  REQUIRE(xml, "read proto/examples/hdistant_seed.xml");
  char id1[65], id2[65];
  /* The embedded default is the same scene, so the first POST may be 200. */
  long st1 = post_scene(&main_d, xml, "application/xml", id1);
  long st2 = post_scene(&main_d, xml, "application/xml", id2);
  CHECK(st1 == 201 || st1 == 200, "first POST: %ld", st1);
  CHECK(st2 == 200 && strcmp(id1, id2) == 0, "second POST 200 with the same id: %ld", st2);
  char def[65];
  CHECK(default_scene(&main_d, def), "the default scene is listed");
  CHECK(strcmp(def, id1) == 0, "the embedded default scene has the seed XML's id (%s vs %s)", def, id1);
  /* text/xml is accepted too. */
  char id3[65];
  CHECK(post_scene(&main_d, xml, "text/xml", id3) == 200 && strcmp(id3, id1) == 0, "text/xml");
  /* Render it: rgb, 32x32. */
  char path[256], body[256];
  snprintf(path, sizeof path, "/v1/scenes/%s:render", id1);
  resp r = do_req(&main_d, (req){.method = "POST",
                                 .path = path,
                                 .body = jq(body, sizeof body, "{'spp': 1}"),
                                 .accept = "application/json"});
  film f = {0};
  CHECK(r.status == 200 && film_from_json(&r, &f), "render seed: %ld", r.status);
  if (f.doc) {
    const cJSON *ch = cJSON_GetObjectItemCaseSensitive(f.doc, "channels");
    CHECK(f.w == 32 && f.h == 32 && f.c == 3, "32x32x3, got %dx%dx%d", f.w, f.h, f.c);
    CHECK(cJSON_IsString(cJSON_GetArrayItem(ch, 0)) &&
              strcmp(cJSON_GetArrayItem(ch, 0)->valuestring, "R") == 0,
          "channels R, G, B");
  }
  film_free(&f);
  resp_free(&r);
  free(xml);
}

static void test_params_get_patch(void) {
  char id[65], path[256], ct[128], etag[64], inm[96];
  REQUIRE(plate_scene(&main_d, "0.31", id), "scene");
  snprintf(path, sizeof path, "/v1/scenes/%s/params", id);
  resp r = get(&main_d, path);
  REQUIRE(r.status == 200, "GET params: %ld %s", r.status, r.body);
  CHECK(strcmp(hdr(&r, "ETag", etag, sizeof etag), "\"0\"") == 0, "ETag \"0\", got %s", etag);
  CHECK(starts_with(hdr(&r, "Content-Type", ct, sizeof ct), "application/json"), "Content-Type %s", ct);
  cJSON *j = jparse(&r);
  CHECK(jnum(j, "revision") == 0, "revision 0");
  bool refl = false, xf = false;
  const cJSON *it;
  cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(j, "params")) {
    if (jstr_is(it, "key", "plate.bsdf.reflectance.value")) {
      refl = jstr_is(it, "class", "spectral") && jstr_is(it, "type", "spectrum") &&
             fabs(jnum(it, "value") - 0.31) < 1e-6 && jstr(it, "object_type") &&
             cJSON_IsArray(cJSON_GetObjectItemCaseSensitive(it, "shape")) &&
             cJSON_IsArray(cJSON_GetObjectItemCaseSensitive(it, "aliases"));
    }
    if (jstr_is(it, "key", "plate.to_world"))
      xf = jstr_is(it, "class", "geometric") && jstr_is(it, "type", "transform");
  }
  CHECK(refl, "plate.bsdf.reflectance.value: spectral spectrum 0.31 with shape, aliases: %.600s", r.body);
  CHECK(xf, "plate.to_world: geometric transform");
  cJSON_Delete(j);
  resp_free(&r);
  /* match and class filters. */
  char q[320];
  snprintf(q, sizeof q, "%s?match=plate.*&class=geometric", path);
  r = get(&main_d, q);
  j = jparse(&r);
  int n = 0, bad = 0;
  cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(j, "params")) {
    n++;
    if (!starts_with(jstr(it, "key"), "plate.") || !jstr_is(it, "class", "geometric")) bad++;
  }
  CHECK(r.status == 200 && n >= 1 && bad == 0, "match=plate.*&class=geometric: %ld, %d entries, %d off",
        r.status, n, bad);
  cJSON_Delete(j);
  resp_free(&r);
  /* PATCH with the current revision. */
  char body[256];
  jq(body, sizeof body, "{'plate.bsdf.reflectance.value': 0.62}");
  r = do_req(&main_d, (req){.method = "PATCH", .path = path, .body = body, .hdr = {"If-Match: \"0\""}});
  j = jparse(&r);
  CHECK(r.status == 200, "PATCH: %ld %s", r.status, r.body);
  CHECK(jnum(j, "revision") == 1, "revision 1: %s", r.body);
  const cJSON *cls = cJSON_GetObjectItemCaseSensitive(j, "classes");
  CHECK(cJSON_GetArraySize(cls) == 1 && strcmp(cJSON_GetArrayItem(cls, 0)->valuestring, "spectral") == 0,
        "classes [spectral]");
  CHECK(cJSON_GetObjectItemCaseSensitive(j, "changed") && jnum(j, "seconds") >= 0, "changed, seconds");
  CHECK(strcmp(hdr(&r, "ETag", etag, sizeof etag), "\"1\"") == 0, "new ETag \"1\", got %s", etag);
  cJSON_Delete(j);
  resp_free(&r);
  /* GET reflects it, under the new ETag. */
  snprintf(q, sizeof q, "%s?match=plate.bsdf.*", path);
  r = get(&main_d, q);
  j = jparse(&r);
  const cJSON *p0 = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(j, "params"), 0);
  CHECK(fabs(jnum(p0, "value") - 0.62) < 1e-6, "value after PATCH: %.300s", r.body);
  CHECK(strcmp(hdr(&r, "ETag", etag, sizeof etag), "\"1\"") == 0, "ETag \"1\" on GET, got %s", etag);
  cJSON_Delete(j);
  resp_free(&r);
  /* Stale If-Match: 412, nothing applied. */
  snprintf(inm, sizeof inm, "If-Match: \"0\"");
  jq(body, sizeof body, "{'plate.bsdf.reflectance.value': 0.1}");
  r = do_req(&main_d, (req){.method = "PATCH", .path = path, .body = body, .hdr = {inm}});
  CHECK_PROBLEM(r, 412, "stale If-Match");
  resp_free(&r);
  /* Unknown key: 422 with the key and candidates; nothing applied. */
  jq(body, sizeof body, "{'plate.bsdf.reflectanse.value': 0.1}");
  r = do_req(&main_d, (req){.method = "PATCH", .path = path, .body = body});
  CHECK_PROBLEM(r, 422, "unknown key");
  j = jparse(&r);
  CHECK(jstr_is(j, "key", "plate.bsdf.reflectanse.value"), "problem key: %.300s", r.body);
  bool cand = false;
  cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(j, "candidates")) {
    if (cJSON_IsString(it) && strcmp(it->valuestring, "plate.bsdf.reflectance.value") == 0) cand = true;
  }
  CHECK(cand, "candidates include plate.bsdf.reflectance.value: %.300s", r.body);
  cJSON_Delete(j);
  resp_free(&r);
  r = get(&main_d, path);
  CHECK(strcmp(hdr(&r, "ETag", etag, sizeof etag), "\"1\"") == 0,
        "still revision 1 after the refused PATCHes: %s", etag);
  resp_free(&r);
}

/* ---- tests: renders ------------------------------------------------------------- */

static void test_render_formats(void) {
  char id[65], path[256], body[256], ct[128];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  snprintf(path, sizeof path, "/v1/scenes/%s:render", id);
  jq(body, sizeof body, "{'sensor': 'hemi', 'spp': 2, 'seed': 9, 'wavelength': 600}");
  /* JSON (also the default without Accept). */
  resp r = do_req(&main_d, (req){.method = "POST", .path = path, .body = body, .accept = "application/json"});
  film f = {0};
  REQUIRE(r.status == 200 && film_from_json(&r, &f), "JSON render: %ld %.300s", r.status, r.body);
  CHECK(starts_with(hdr(&r, "Content-Type", ct, sizeof ct), "application/json"), "Content-Type %s", ct);
  CHECK(f.w == 5 && f.h == 5 && f.c == 1, "5x5x1, got %dx%dx%d", f.w, f.h, f.c);
  const cJSON *ch0 = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(f.doc, "channels"), 0);
  CHECK(cJSON_IsString(ch0) && strcmp(ch0->valuestring, "Y") == 0, "mono channel Y");
  const cJSON *meta = cJSON_GetObjectItemCaseSensitive(f.doc, "meta");
  CHECK(jstr_is(meta, "scene", id) && jstr_is(meta, "sensor", "hemi") && jnum(meta, "spp") == 2 &&
            jnum(meta, "seed") == 9 && jnum(meta, "wavelength") == 600 && jnum(meta, "revision") == 0 &&
            cJSON_GetObjectItemCaseSensitive(meta, "context"),
        "meta: %.400s", r.body);
  double sum = 0;
  for (int i = 0; i < 25; i++) sum += f.data[i];
  CHECK(sum > 0, "film is not black");
  resp_free(&r);
  r = do_req(&main_d, (req){.method = "POST", .path = path, .body = body});
  film f2 = {0};
  CHECK(r.status == 200 && film_from_json(&r, &f2), "no Accept gives JSON: %ld", r.status);
  if (f2.data) CHECK(memcmp(f.data, f2.data, 25 * sizeof(double)) == 0, "same request, same film");
  film_free(&f2);
  resp_free(&r);
  /* NPY. */
  r = do_req(&main_d, (req){.method = "POST", .path = path, .body = body, .accept = "application/x-npy"});
  int sh[3] = {0};
  const float *px = NULL;
  size_t n = 0;
  CHECK(r.status == 200, "NPY render: %ld", r.status);
  CHECK(starts_with(hdr(&r, "Content-Type", ct, sizeof ct), "application/x-npy"), "Content-Type %s", ct);
  if (r.status == 200 && npy_parse(&r, sh, &px, &n)) {
    CHECK(sh[0] == 5 && sh[1] == 5 && sh[2] == 1, "shape (5, 5, 1), got (%d, %d, %d)", sh[0], sh[1], sh[2]);
    int off = 0;
    for (int i = 0; i < 25; i++) {
      float v;
      memcpy(&v, px + i, sizeof v);
      if (v != (float)f.data[i]) off++;
    }
    CHECK(off == 0, "NPY equals the JSON film as float32 (%d pixels differ)", off);
  } else {
    CHECK(false, "NPY header and size");
  }
  resp_free(&r);
  /* EXR: magic, then read it back. */
  r = do_req(&main_d, (req){.method = "POST", .path = path, .body = body, .accept = "image/x-exr"});
  CHECK(r.status == 200, "EXR render: %ld", r.status);
  CHECK(starts_with(hdr(&r, "Content-Type", ct, sizeof ct), "image/x-exr"), "Content-Type %s", ct);
  const unsigned char magic[4] = {0x76, 0x2f, 0x31, 0x01};
  CHECK(r.len > 4 && memcmp(r.body, magic, 4) == 0, "EXR magic");
  char exr_path[160];
  snprintf(exr_path, sizeof exr_path, "%s/render.exr", tmpdir);
  if (r.len > 4 && write_bytes(exr_path, r.body, r.len)) {
    exr_image img;
    rsw_err e = {0};
    if (exr_read_image(exr_path, &img, &e) == RSW_OK) {
      CHECK(img.width == 5 && img.height == 5 && img.n_channels == 1, "EXR 5x5x1");
      int off = 0;
      for (int i = 0; i < 25 && img.width * img.height == 25; i++)
        if ((float)img.data[i] != (float)f.data[i]) off++;
      CHECK(off == 0, "EXR equals the JSON film (%d pixels differ)", off);
      exr_image_free(&img);
    } else {
      CHECK(false, "EXR reads back: %s", e.msg);
    }
  }
  resp_free(&r);
  film_free(&f);
  /* The 1x1 meter: rho E / pi exactly (deterministic: the target point
   * always hits the plate and the emitter sample is a delta). */
  jq(body, sizeof body, "{'sensor': 'meter', 'spp': 4}");
  r = do_req(&main_d, (req){.method = "POST", .path = path, .body = body});
  CHECK(r.status == 200 && film_from_json(&r, &f), "meter render: %ld", r.status);
  if (f.data) CHECK_REL(f.data[0], 0.5 / PI, 1e-5);
  film_free(&f);
  resp_free(&r);
  /* Sensor by index. */
  jq(body, sizeof body, "{'sensor': '1', 'spp': 1}");
  r = do_req(&main_d, (req){.method = "POST", .path = path, .body = body});
  CHECK(r.status == 200 && film_from_json(&r, &f) && f.w == 5, "sensor '1' is hemi: %ld", r.status);
  film_free(&f);
  resp_free(&r);
}

static void test_directions(void) {
  char id[65], path[256];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  snprintf(path, sizeof path, "/v1/scenes/%s/sensors/hemi/directions", id);
  resp r = get(&main_d, path);
  REQUIRE(r.status == 200, "directions: %ld %.300s", r.status, r.body);
  cJSON *j = jparse(&r);
  CHECK(jstr_is(j, "sensor", "hemi") && jnum(j, "width") == 5 && jnum(j, "height") == 5 &&
            jstr_is(j, "convention", "east_right"),
        "header fields: %.200s", r.body);
  const cJSON *px = cJSON_GetObjectItemCaseSensitive(j, "pixels");
  REQUIRE(cJSON_GetArraySize(px) == 25, "25 pixels, got %d", cJSON_GetArraySize(px));
  /* Row-major, iy outer. Pixel centre u = ((ix+1/2)/5, (iy+1/2)/5); for
   * hdistant, a = 2u-1, r = max(|a_x|, |a_y|), cos(theta) = 1 - r^2
   * (square_to_uniform_hemisphere through the concentric map); +ix is
   * local +x (azimuth 0, east), +iy local +y (azimuth 90). */
  int order_bad = 0, unit_bad = 0;
  for (int i = 0; i < 25; i++) {
    const cJSON *p = cJSON_GetArrayItem(px, i);
    if (jnum(p, "ix") != i % 5 || jnum(p, "iy") != i / 5) order_bad++;
    double x = jnum(p, "x"), y = jnum(p, "y"), z = jnum(p, "z");
    double zen = jnum(p, "zenith_deg") * PI / 180, az = jnum(p, "azimuth_deg") * PI / 180;
    if (fabs(x * x + y * y + z * z - 1) > 1e-5 || fabs(cos(zen) - z) > 1e-5 ||
        (sin(zen) > 1e-3 && (fabs(sin(zen) * cos(az) - x) > 1e-5 || fabs(sin(zen) * sin(az) - y) > 1e-5)))
      unit_bad++;
  }
  CHECK(order_bad == 0, "row-major, iy outer (%d off)", order_bad);
  CHECK(unit_bad == 0, "unit vectors agreeing with zenith/azimuth (%d off)", unit_bad);
  const cJSON *c = cJSON_GetArrayItem(px, 2 * 5 + 2);
  CHECK(fabs(jnum(c, "zenith_deg")) < 1e-3 && jnum(c, "z") > 0.999999,
        "centre pixel at zenith 0: zenith %g, z %g", jnum(c, "zenith_deg"), jnum(c, "z"));
  struct {
    int ix, iy;
    double az;
  } ring[] = {{4, 2, 0}, {2, 4, 90}, {0, 2, 180}, {2, 0, 270}};
  double zen_ring = acos(1 - 0.8 * 0.8) * 180 / PI;
  for (int k = 0; k < 4; k++) {
    const cJSON *p = cJSON_GetArrayItem(px, ring[k].iy * 5 + ring[k].ix);
    double az = fmod(jnum(p, "azimuth_deg") + 360.0, 360.0);
    double d = fabs(az - ring[k].az);
    if (d > 180) d = 360 - d;
    CHECK(d < 1e-3, "pixel (%d, %d): azimuth %g, want %g (east right)", ring[k].ix, ring[k].iy, az,
          ring[k].az);
    CHECK_ABS(jnum(p, "zenith_deg"), zen_ring, 1e-3);
  }
  cJSON_Delete(j);
  resp_free(&r);
  /* The distant meter: one pixel, looking straight down = exitant zenith 0. */
  snprintf(path, sizeof path, "/v1/scenes/%s/sensors/meter/directions", id);
  r = get(&main_d, path);
  j = jparse(&r);
  const cJSON *p = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(j, "pixels"), 0);
  CHECK(r.status == 200 && jnum(j, "width") == 1 && fabs(jnum(p, "zenith_deg")) < 1e-3,
        "meter: one pixel at zenith 0: %ld %.300s", r.status, r.body);
  cJSON_Delete(j);
  resp_free(&r);
}

/* PATCH then render equals a fresh render of the changed document. */
static void test_patch_equals_reload(void) {
  char a[65], b[65], path[256], body[256];
  REQUIRE(plate_scene(&main_d, "0.47", a), "scene A");
  const char *req_body = jq(body, sizeof body, "{'sensor': 'hemi', 'spp': 3, 'seed': 5, 'wavelength': 550}");
  film before = {0}, after = {0}, fresh = {0};
  snprintf(path, sizeof path, "/v1/scenes/%s:render", a);
  resp r = post_json(&main_d, path, req_body);
  REQUIRE(r.status == 200 && film_from_json(&r, &before), "render A: %ld", r.status);
  resp_free(&r);
  char ppath[256], pbody[128];
  snprintf(ppath, sizeof ppath, "/v1/scenes/%s/params", a);
  r = do_req(&main_d, (req){.method = "PATCH",
                            .path = ppath,
                            .body = jq(pbody, sizeof pbody, "{'plate.bsdf.reflectance.value': 0.21}")});
  CHECK(r.status == 200, "PATCH: %ld %s", r.status, r.body);
  resp_free(&r);
  r = post_json(&main_d, path, req_body);
  CHECK(r.status == 200 && film_from_json(&r, &after), "render A': %ld", r.status);
  resp_free(&r);
  REQUIRE(plate_scene(&main_d, "0.21", b), "scene B");
  CHECK(strcmp(a, b) != 0, "different documents, different ids");
  snprintf(path, sizeof path, "/v1/scenes/%s:render", b);
  r = post_json(&main_d, path, req_body);
  CHECK(r.status == 200 && film_from_json(&r, &fresh), "render B: %ld", r.status);
  resp_free(&r);
  if (after.data && fresh.data && before.data) {
    int diff = 0, changed = 0;
    for (int i = 0; i < 25; i++) {
      if (after.data[i] != fresh.data[i]) diff++;
      if (after.data[i] != before.data[i]) changed++;
    }
    CHECK(diff == 0, "patched render equals the fresh scene's (%d of 25 pixels differ)", diff);
    CHECK(changed > 0, "the PATCH changed the film");
    const cJSON *meta = cJSON_GetObjectItemCaseSensitive(after.doc, "meta");
    CHECK(jnum(meta, "revision") == 1, "meta.revision 1 after the PATCH");
  }
  film_free(&before);
  film_free(&after);
  film_free(&fresh);
}

/* ---- tests: jobs ---------------------------------------------------------------- */

static void test_jobs_routes(void) {
  char id[65], job[128], body[1024], path[512], loc[256];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  jq(body, sizeof body,
     "{'contexts': [{'id': 'a', 'wavelength': 500}, {'id': 'b.2', 'wavelength': 600, 'spp': 3, 'seed': 4}],"
     " 'defaults': {'spp': 2}, 'seed': 1}");
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", id);
  resp r = post_json(&main_d, path, body);
  REQUIRE(r.status == 202, "submit: %ld %.300s", r.status, r.body);
  cJSON *j = jparse(&r);
  REQUIRE(jstr(j, "id"), "job id");
  snprintf(job, sizeof job, "%s", jstr(j, "id"));
  char want[256];
  snprintf(want, sizeof want, "/v1/jobs/%s", job);
  CHECK(strstr(hdr(&r, "Location", loc, sizeof loc), want) != NULL, "Location %s", loc);
  CHECK(jstr_is(j, "scene", id) && jnum(j, "revision") == 0 && jnum(j, "contexts_total") == 2 &&
            jnum(j, "renders_total") == 4 && jstr(j, "created") && jstr(j, "href_results") &&
            jstr(j, "href_events"),
        "Job body: %.500s", r.body);
  const char *st = jstr(j, "state");
  CHECK(st && (strcmp(st, "queued") == 0 || strcmp(st, "running") == 0 || strcmp(st, "succeeded") == 0),
        "state %s", st ? st : "(none)");
  cJSON_Delete(j);
  resp_free(&r);
  j = wait_job(&main_d, job, 10);
  REQUIRE(j, "GET job");
  CHECK(jstr_is(j, "state", "succeeded") && jnum(j, "contexts_done") == 2 && jnum(j, "renders_done") == 4 &&
            jnum(j, "renders_failed") == 0 && jstr(j, "started") && jstr(j, "finished") &&
            jnum(j, "seconds") >= 0,
        "finished job: %s", jstr(j, "state"));
  cJSON_Delete(j);
  /* List. */
  r = get(&main_d, "/v1/jobs");
  j = jparse(&r);
  bool listed = false;
  const cJSON *it;
  cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(j, "jobs")) if (jstr_is(it, "id", job)) listed =
      true;
  CHECK(r.status == 200 && listed, "GET /v1/jobs lists it");
  cJSON_Delete(j);
  resp_free(&r);
  /* Results index. */
  snprintf(path, sizeof path, "/v1/jobs/%s/results", job);
  r = get(&main_d, path);
  j = jparse(&r);
  CHECK(r.status == 200 && jstr_is(j, "job", job), "results: %ld", r.status);
  const cJSON *res = cJSON_GetObjectItemCaseSensitive(j, "results");
  CHECK(cJSON_GetArraySize(res) == 4, "4 results (2 contexts x 2 sensors), got %d", cJSON_GetArraySize(res));
  char href[512] = "";
  cJSON_ArrayForEach(it, res) {
    if (jstr_is(it, "context", "b.2") && jstr_is(it, "sensor", "hemi")) {
      CHECK(jstr_is(it, "state", "succeeded") && jnum(it, "wavelength") == 600 && jnum(it, "spp") == 3 &&
                jnum(it, "seed") == 4 && jnum(it, "width") == 5 && jnum(it, "height") == 5 &&
                cJSON_GetArraySize(cJSON_GetObjectItemCaseSensitive(it, "channels")) == 1,
            "result entry for (b.2, hemi): %.600s", r.body);
      if (jstr(it, "href")) snprintf(href, sizeof href, "%s", jstr(it, "href"));
    }
    if (jstr_is(it, "context", "a")) CHECK(jnum(it, "spp") == 2, "defaults.spp applies to a");
  }
  cJSON_Delete(j);
  resp_free(&r);
  CHECK(strstr(href, "/results/b.2/hemi") != NULL, "href %s", href);
  /* One film by href, in each format; fetching twice keeps it. */
  r = do_req(&main_d, (req){.path = href, .accept = "application/json"});
  film f = {0};
  CHECK(r.status == 200 && film_from_json(&r, &f) && f.w == 5, "result JSON: %ld", r.status);
  const cJSON *meta = f.doc ? cJSON_GetObjectItemCaseSensitive(f.doc, "meta") : NULL;
  CHECK(jstr_is(meta, "context", "b.2") && jstr_is(meta, "sensor", "hemi") && jnum(meta, "seed") == 4,
        "result meta");
  film_free(&f);
  resp_free(&r);
  r = result(&main_d, job, "b.2", "hemi", "application/x-npy");
  int sh[3];
  const float *px;
  size_t n;
  CHECK(r.status == 200 && npy_parse(&r, sh, &px, &n) && sh[0] == 5 && sh[1] == 5 && sh[2] == 1,
        "result NPY: %ld", r.status);
  resp_free(&r);
  r = result(&main_d, job, "b.2", "hemi", "image/x-exr");
  CHECK(r.status == 200 && r.len > 4 && memcmp(r.body, "\x76\x2f\x31\x01", 4) == 0, "result EXR: %ld",
        r.status);
  resp_free(&r);
  r = result(&main_d, job, "b.2", "hemi", "image/png");
  CHECK(r.status == 200 && r.len > 8 && memcmp(r.body, "\x89PNG\r\n\x1a\n", 8) == 0, "result PNG: %ld",
        r.status);
  resp_free(&r);
  r = result(&main_d, job, "b.2", "hemi", "image/tiff");
  CHECK_PROBLEM(r, 406, "result as image/tiff");
  resp_free(&r);
  r = result(&main_d, job, "nosuch", "hemi", NULL);
  CHECK_PROBLEM(r, 404, "result of an unknown context");
  resp_free(&r);
  test_results_fetch(job);
  /* Cancel a finished job: unchanged. */
  snprintf(path, sizeof path, "/v1/jobs/%s:cancel", job);
  r = post_json(&main_d, path, NULL);
  j = jparse(&r);
  CHECK(r.status == 200 && jstr_is(j, "state", "succeeded"), "cancel after the end: %ld %s", r.status,
        jstr(j, "state"));
  cJSON_Delete(j);
  resp_free(&r);
  /* Delete: 204, then 404 for the job and its results. */
  r = do_req(&main_d, (req){.method = "DELETE", .path = want});
  CHECK(r.status == 204, "DELETE job: %ld", r.status);
  resp_free(&r);
  r = get(&main_d, want);
  CHECK_PROBLEM(r, 404, "deleted job");
  resp_free(&r);
  r = result(&main_d, job, "a", "meter", NULL);
  CHECK_PROBLEM(r, 404, "deleted job's result");
  resp_free(&r);
}

/* The spectral loop of the issue: 20 contexts, one tabulated reflectance
 * at job level evaluated at each context's wavelength. Plate rho(w), E = 1
 * at nadir, meter looking straight down: L = rho(w) E cos(0) / pi with
 * rho(w) = 0.2 + 0.6 (w - 400) / 300 (linear between the two nodes). */
static char spectral_job_body[4096];

/* bundle: the job's "bundle" (0: none, the daemon's default, auto). */
static const char *spectral_body_k(int from, int to, int seed, int bundle) {
  char ctx[2048] = "";
  size_t off = 0;
  for (int i = from; i < to; i++)
    off += (size_t)snprintf(ctx + off, sizeof ctx - off, "%s{'id': 'c%02d', 'wavelength': %.17g}",
                            i > from ? ", " : "", i, 400.0 + 300.0 * i / 19.0);
  return jq(spectral_job_body, sizeof spectral_job_body,
            "{'contexts': [%s], 'defaults': {'spp': 2},"
            " 'params': {'plate.bsdf.reflectance.value': {'wavelengths': [400, 700], 'values': [0.2, 0.8]}},"
            " 'seed': %d%s}",
            ctx, seed, bundle == 1 ? ", 'bundle': 1" : "");
}

static const char *spectral_body(int from, int to, int seed) {
  return spectral_body_k(from, to, seed, 0);
}

/* POST .../jobs?dry_run=1: checked and planned as a submission is, nothing
 * queued: 200 with the job's size and its warnings (a coordinate nothing
 * reads), no job listed; a bad request is the submission's 422; a bad
 * value of dry_run is a 400 naming it. */
static void test_jobs_dry_run(void) {
  char id[65], body[1024], path[512];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  resp r = get(&main_d, "/v1/jobs");
  cJSON *j = jparse(&r);
  int before = cJSON_GetArraySize(cJSON_GetObjectItemCaseSensitive(j, "jobs"));
  cJSON_Delete(j);
  resp_free(&r);
  jq(body, sizeof body,
     "{'contexts': [{'id': 'a', 'wavelength': 500, 'coords': {'sza': 0}},"
     " {'id': 'b', 'wavelength': 500, 'coords': {'sza': 30}}], 'defaults': {'spp': 2}}");
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs?dry_run=1", id);
  r = post_json(&main_d, path, body);
  j = jparse(&r);
  const cJSON *w = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(j, "warnings"), 0);
  CHECK(r.status == 200 && cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(j, "dry_run")) &&
            jstr_is(j, "scene", id) && jnum(j, "contexts_total") == 2 && jnum(j, "renders_total") == 4 &&
            !jstr(j, "id") && jstr_is(w, "code", "coordinate_unused") && jstr_is(w, "coordinate", "sza"),
        "dry run: %ld %.600s", r.status, r.body);
  cJSON_Delete(j);
  resp_free(&r);
  r = get(&main_d, "/v1/jobs");
  j = jparse(&r);
  CHECK(cJSON_GetArraySize(cJSON_GetObjectItemCaseSensitive(j, "jobs")) == before,
        "a dry run listed a job: %.300s", r.body);
  cJSON_Delete(j);
  resp_free(&r);
  jq(body, sizeof body, "{'contexts': [{'id': 'a', 'wavelength': -5}]}");
  r = post_json(&main_d, path, body);
  CHECK(r.status == 422 && strstr(r.body, "/contexts/0/wavelength"), "dry run of a bad request: %ld %.300s",
        r.status, r.body);
  resp_free(&r);
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs?dry_run=maybe", id);
  r = post_json(&main_d, path, body);
  CHECK(r.status == 400 && strstr(r.body, "dry_run"), "dry_run=maybe: %ld %.300s", r.status, r.body);
  resp_free(&r);
}

static void test_spectral_job(void) {
  char id[65], job[128];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  REQUIRE(submit_job(&main_d, id, spectral_body(0, 20, 11), NULL, job) == 202, "submit");
  cJSON *j = wait_job(&main_d, job, 15);
  REQUIRE(j && jstr_is(j, "state", "succeeded"), "job succeeded: %s", j ? jstr(j, "state") : "(none)");
  CHECK(jnum(j, "contexts_done") == 20 && jnum(j, "renders_done") == 40, "20 contexts, 40 renders");
  cJSON_Delete(j);
  int bad = 0;
  for (int i = 0; i < 20; i++) {
    char ctx[16];
    snprintf(ctx, sizeof ctx, "c%02d", i);
    double w = 400.0 + 300.0 * i / 19.0, rho = 0.2 + 0.6 * (w - 400.0) / 300.0;
    resp r = result(&main_d, job, ctx, "meter", "application/json");
    film f = {0};
    if (r.status == 200 && film_from_json(&r, &f)) {
      const cJSON *meta = cJSON_GetObjectItemCaseSensitive(f.doc, "meta");
      CHECK(fabs(jnum(meta, "wavelength") - w) < 1e-9 * w, "%s: meta.wavelength %g, want %g", ctx,
            jnum(meta, "wavelength"), w);
      double want = rho * 1.0 / PI;
      if (!(fabs(f.data[0] - want) <= 1e-5 * want)) {
        bad++;
        fprintf(stdout, "  %s (w = %g): %.9g, want rho E / pi = %.9g\n", ctx, w, f.data[0], want);
      }
    } else {
      bad++;
      fprintf(stdout, "  %s: status %ld\n", ctx, r.status);
    }
    film_free(&f);
    resp_free(&r);
  }
  CHECK(bad == 0, "%d of 20 contexts off rho(w) E / pi by more than 1e-5 relative", bad);
  /* The base state is untouched by job-level params. */
  char path[256];
  snprintf(path, sizeof path, "/v1/scenes/%s/params?match=plate.bsdf.*", id);
  resp r = get(&main_d, path);
  j = jparse(&r);
  const cJSON *p0 = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(j, "params"), 0);
  CHECK(fabs(jnum(p0, "value") - 0.5) < 1e-9, "base reflectance still 0.5: %.300s", r.body);
  cJSON_Delete(j);
  resp_free(&r);
}

static void test_split_job_bitwise(void) {
  char id[65], whole[128], lo[128], hi[128], other[128];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  /* One wavelength per path ("bundle": 1): each context's film is its
   * own, whatever the job's other contexts (bundles split along their
   * groups: test_bundle_shards.sh). */
  REQUIRE(submit_job(&main_d, id, spectral_body_k(0, 20, 11, 1), NULL, whole) == 202, "submit whole");
  REQUIRE(submit_job(&main_d, id, spectral_body_k(0, 10, 11, 1), NULL, lo) == 202, "submit 0-9");
  REQUIRE(submit_job(&main_d, id, spectral_body_k(10, 20, 11, 1), NULL, hi) == 202, "submit 10-19");
  REQUIRE(submit_job(&main_d, id, spectral_body_k(0, 20, 12, 1), NULL, other) == 202, "submit another seed");
  const char *jobs[] = {whole, lo, hi, other};
  for (int k = 0; k < 4; k++) {
    cJSON *j = wait_job(&main_d, jobs[k], 15);
    CHECK(j && jstr_is(j, "state", "succeeded"), "job %d: %s", k, j ? jstr(j, "state") : "(none)");
    cJSON_Delete(j);
  }
  int diff = 0, seed_diff = 0, fetched = 0;
  const char *sensors[] = {"meter", "hemi"};
  for (int i = 0; i < 20; i++) {
    char ctx[16];
    snprintf(ctx, sizeof ctx, "c%02d", i);
    for (int s = 0; s < 2; s++) {
      resp a = result(&main_d, whole, ctx, sensors[s], "application/x-npy");
      resp b = result(&main_d, i < 10 ? lo : hi, ctx, sensors[s], "application/x-npy");
      resp c = result(&main_d, other, ctx, sensors[s], "application/x-npy");
      if (a.status == 200 && b.status == 200 && c.status == 200) {
        fetched++;
        if (a.len != b.len || memcmp(a.body, b.body, a.len) != 0) diff++;
        if (s == 1 && (a.len != c.len || memcmp(a.body, c.body, a.len) != 0)) seed_diff++;
      }
      resp_free(&a);
      resp_free(&b);
      resp_free(&c);
    }
  }
  CHECK(fetched == 40, "fetched %d of 40 film triples", fetched);
  CHECK(diff == 0, "%d of 40 films differ between the whole job and its halves", diff);
  /* The comparison means something: the noisy hemi film depends on the seed. */
  CHECK(seed_diff == 20, "another job seed changes the hemi films (%d of 20 differ)", seed_diff);
}

/* Parse an SSE stream into events. */
typedef struct sse_event {
  char type[32];
  long id;
  cJSON *data;
} sse_event;

static int sse_parse(const char *text, sse_event *ev, int max) {
  int n = 0;
  sse_event cur = {.id = -1};
  char data[4096] = "";
  bool any = false;
  for (const char *p = text; p && *p && n < max;) {
    const char *eol = strchr(p, '\n');
    size_t ll = eol ? (size_t)(eol - p) : strlen(p);
    char line[4096];
    if (ll >= sizeof line) ll = sizeof line - 1;
    memcpy(line, p, ll);
    line[ll] = '\0';
    if (ll && line[ll - 1] == '\r') line[--ll] = '\0';
    if (ll == 0) {
      if (any) {
        if (!cur.type[0]) snprintf(cur.type, sizeof cur.type, "message");
        cur.data = cJSON_Parse(data);
        ev[n++] = cur;
      }
      memset(&cur, 0, sizeof cur);
      cur.id = -1;
      data[0] = '\0';
      any = false;
    } else if (line[0] == ':') {
      /* comment (keep-alive) */
    } else if (starts_with(line, "event:")) {
      snprintf(cur.type, sizeof cur.type, "%s", line + 6 + (line[6] == ' '));
      any = true;
    } else if (starts_with(line, "id:")) {
      cur.id = atol(line + 3);
      any = true;
    } else if (starts_with(line, "data:")) {
      size_t dl = strlen(data);
      snprintf(data + dl, sizeof data - dl, "%s%s", dl ? "\n" : "", line + 5 + (line[5] == ' '));
      any = true;
    }
    if (!eol) break;
    p = eol + 1;
  }
  return n;
}

static void sse_free(sse_event *ev, int n) {
  for (int i = 0; i < n; i++) cJSON_Delete(ev[i].data);
}

static void test_events(void) {
  char id[65], job[128], body[1024], path[256], ct[128];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  jq(body, sizeof body,
     "{'contexts': [{'id': 'e0'}, {'id': 'e1'}, {'id': 'e2'}, {'id': 'e3'}, {'id': 'e4'}],"
     " 'defaults': {'sensors': ['meter'], 'spp': 1}}");
  REQUIRE(submit_job(&main_d, id, body, NULL, job) == 202, "submit");
  snprintf(path, sizeof path, "/v1/jobs/%s/events", job);
  resp r = do_req(&main_d, (req){.path = path, .accept = "text/event-stream", .sse = true, .timeout_s = 15});
  REQUIRE(r.status == 200, "events: %ld", r.status);
  CHECK(starts_with(hdr(&r, "Content-Type", ct, sizeof ct), "text/event-stream"), "Content-Type %s", ct);
  sse_event ev[32];
  int n = sse_parse(r.body, ev, 32);
  int seen[5] = {0}, ctx_events = 0, ids_bad = 0;
  for (int i = 0; i < n; i++) {
    if (strcmp(ev[i].type, "context") == 0) {
      ctx_events++;
      if (ev[i].id != ctx_events) ids_bad++;
      const char *c = jstr(ev[i].data, "context");
      if (c && c[0] == 'e' && c[1] >= '0' && c[1] <= '4') seen[c[1] - '0']++;
      CHECK(jstr_is(ev[i].data, "sensor", "meter") && jstr_is(ev[i].data, "state", "succeeded") &&
                jnum(ev[i].data, "done") == ctx_events && jnum(ev[i].data, "total") == 5,
            "context event %d data", ctx_events);
    }
  }
  CHECK(ctx_events == 5, "5 context events, got %d: %.500s", ctx_events, r.body);
  CHECK(ids_bad == 0, "ids 1..5 in order");
  for (int k = 0; k < 5; k++) CHECK(seen[k] == 1, "context e%d seen %d times", k, seen[k]);
  CHECK(n > 0 && strcmp(ev[n - 1].type, "end") == 0 && jstr_is(ev[n - 1].data, "state", "succeeded"),
        "final event end with state succeeded");
  sse_free(ev, n);
  resp_free(&r);
  /* Resume after id 3: only 4, 5 and the end. */
  r = do_req(&main_d, (req){.path = path, .hdr = {"Last-Event-ID: 3"}, .sse = true, .timeout_s = 15});
  n = sse_parse(r.body, ev, 32);
  CHECK(r.status == 200 && n == 3, "resume: %ld, %d events: %.400s", r.status, n, r.body);
  if (n == 3) {
    CHECK(strcmp(ev[0].type, "context") == 0 && ev[0].id == 4 && strcmp(ev[1].type, "context") == 0 &&
              ev[1].id == 5 && strcmp(ev[2].type, "end") == 0,
          "context 4, context 5, end");
  }
  sse_free(ev, n);
  resp_free(&r);
}

/* A job long enough to be caught running: the seed scene (32x32) at many
 * spp per context. */
static const char *long_job_body(char *buf, size_t n, int contexts, int spp) {
  char ctx[4096] = "";
  size_t off = 0;
  for (int i = 0; i < contexts; i++)
    off += (size_t)snprintf(ctx + off, sizeof ctx - off, "%s{'id': 'L%d'}", i ? ", " : "", i);
  return jq(buf, n, "{'contexts': [%s], 'defaults': {'spp': %d}}", ctx, spp);
}

/* spp of a 5x5 hemi render taking about secs seconds. */
static long hemi_spp(double secs) {
  double spp = secs * plate_sps / 25.0;
  return spp < 1 ? 1 : (long)spp;
}

/* A job of n contexts rendering only hemi, each about secs seconds. */
static const char *hemi_job_body(char *buf, size_t n, int contexts, double secs) {
  char ctx[2048] = "";
  size_t off = 0;
  for (int i = 0; i < contexts; i++)
    off += (size_t)snprintf(ctx + off, sizeof ctx - off, "%s{'id': 'H%d'}", i ? ", " : "", i);
  return jq(buf, n, "{'contexts': [%s], 'defaults': {'sensors': ['hemi'], 'spp': %ld}}", ctx, hemi_spp(secs));
}

static void calibrate(void) {
  char id[65], path[256], body[128];
  if (!plate_scene(&main_d, "0.5", id)) return;
  snprintf(path, sizeof path, "/v1/scenes/%s:render", id);
  resp r = post_json(&main_d, path, jq(body, sizeof body, "{'sensor': 'hemi', 'spp': 20000}"));
  if (r.status == 200 && r.secs > 0.005) plate_sps = 25.0 * 20000 / r.secs;
  fprintf(stdout, "  (calibration: %.3g samples/s in one 5x5 render)\n", plate_sps);
  resp_free(&r);
}

/* The issue: cancel "stops between sample passes, not only between
 * contexts". A context of one render tile (5x5 film) and ~60 s of samples
 * (by the calibration): cancelled once running, the job must end with no
 * render finished. That is an order of events, not a latency: a cancel
 * honoured only between contexts would first finish a render (renders_done
 * 1), and the 30 s wait is a limit far below the render's length, not a
 * measurement (a loaded machine, a sanitizer build only make it longer). */
static void test_cancel_between_passes(void) {
  char id[65], job[128], body[4096];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  REQUIRE(submit_job(&main_d, id, hemi_job_body(body, sizeof body, 3, 60.0), NULL, job) == 202, "submit");
  CHECK(wait_running(&main_d, job, 30), "job starts running");
  sleep_ms(100);
  char path[256];
  snprintf(path, sizeof path, "/v1/jobs/%s:cancel", job);
  resp r = post_json(&main_d, path, NULL);
  CHECK(r.status == 200, "cancel: %ld", r.status);
  resp_free(&r);
  cJSON *j = wait_job(&main_d, job, 30);
  CHECK(j && jstr_is(j, "state", "cancelled"), "cancelled, before its first ~60 s render could end: %s",
        j ? jstr(j, "state") : "(none)");
  CHECK(j && jnum(j, "renders_done") == 0, "no render finished: %g (cancel waited for a render to end)",
        j ? jnum(j, "renders_done") : -1);
  cJSON_Delete(j);
}

/* HTTP threads validate while the worker renders: reading a busy scene's
 * parameters and submitting another job to it answer while its render
 * (~60 s by the calibration) is still running. Asserted as an order (the
 * answer, then the job still running with no render done), not a latency. */
static void test_busy_scene_responsive(void) {
  char id[65], job[128], job2[128], body[4096], path[256];
  REQUIRE(plate_scene(&main_d, "0.55", id), "scene");
  REQUIRE(submit_job(&main_d, id, hemi_job_body(body, sizeof body, 1, 60.0), NULL, job) == 202, "submit");
  CHECK(wait_running(&main_d, job, 30), "job starts running");
  long st = submit_job(
      &main_d, id, jq(body, sizeof body, "{'contexts': [{'id': 'q'}], 'defaults': {'spp': 1}}"), NULL, job2);
  snprintf(path, sizeof path, "/v1/jobs/%s", job);
  resp g = get(&main_d, path);
  cJSON *j = jparse(&g);
  CHECK(st == 202 && jstr_is(j, "state", "running") && jnum(j, "renders_done") == 0,
        "submit answered %ld while the render runs (job %s, %g renders done)", st, jstr(j, "state"),
        jnum(j, "renders_done"));
  cJSON_Delete(j);
  resp_free(&g);
  snprintf(path, sizeof path, "/v1/scenes/%s/params", id);
  resp r = get(&main_d, path);
  snprintf(path, sizeof path, "/v1/jobs/%s", job);
  g = get(&main_d, path);
  j = jparse(&g);
  CHECK(r.status == 200 && jstr_is(j, "state", "running") && jnum(j, "renders_done") == 0,
        "GET params answered %ld while the render runs (job %s)", r.status, jstr(j, "state"));
  cJSON_Delete(j);
  resp_free(&g);
  resp_free(&r);
  snprintf(path, sizeof path, "/v1/jobs/%s:cancel", job);
  r = post_json(&main_d, path, NULL);
  resp_free(&r);
  cJSON_Delete(wait_job(&main_d, job, 30));
  if (st == 202) cJSON_Delete(wait_job(&main_d, job2, 30));
}

static void test_cancel(void) {
  char id[65], job[128], body[4096], path[256];
  REQUIRE(default_scene(&main_d, id), "default scene");
  REQUIRE(submit_job(&main_d, id, long_job_body(body, sizeof body, 20, (int)(2.0 * plate_sps / 1024) + 1),
                     NULL, job) == 202,
          "submit");
  CHECK(wait_running(&main_d, job, 10), "job starts running");
  sleep_ms(100);
  snprintf(path, sizeof path, "/v1/jobs/%s:cancel", job);
  resp r = post_json(&main_d, path, NULL);
  cJSON *j = jparse(&r);
  CHECK(r.status == 200 && jstr_is(j, "id", job), "cancel: %ld %.300s", r.status, r.body);
  cJSON_Delete(j);
  resp_free(&r);
  j = wait_job(&main_d, job, 5);
  REQUIRE(j, "job readable");
  CHECK(jstr_is(j, "state", "cancelled"), "state cancelled within 5 s, got %s", jstr(j, "state"));
  CHECK(jnum(j, "renders_done") < jnum(j, "renders_total") && jnum(j, "renders_total") == 20,
        "fewer renders done (%g) than submitted (%g)", jnum(j, "renders_done"), jnum(j, "renders_total"));
  cJSON_Delete(j);
  /* The daemon is free again: a small render answers promptly. */
  snprintf(path, sizeof path, "/v1/scenes/%s:render", id);
  r = do_req(
      &main_d,
      (req){.method = "POST", .path = path, .body = jq(body, sizeof body, "{'spp': 1}"), .timeout_s = 10});
  CHECK(r.status == 200, "render after the cancel: %ld", r.status);
  resp_free(&r);
}

/* ---- tests: blobs and paths ------------------------------------------------------- */

static void test_blobs(void) {
  size_t len;
  char *ply = tfile_read("tests/data/quad_le.ply", &len);
  REQUIRE(ply && len > 100, "read tests/data/quad_le.ply");
  char hex[65], other[65], path[256], body[512];
  sha256_hex(ply, len, hex);
  sha256_hex("not the ply", 11, other);
  snprintf(path, sizeof path, "/v1/blobs/%s", hex);
  resp r = do_req(&main_d, (req){.method = "HEAD", .path = path});
  CHECK(r.status == 404, "HEAD before the upload: %ld", r.status);
  resp_free(&r);
  r = post_json(&main_d, "/v1/blobs:missing", jq(body, sizeof body, "{'digests': ['%s', '%s']}", hex, other));
  cJSON *j = jparse(&r);
  const cJSON *m = cJSON_GetObjectItemCaseSensitive(j, "missing");
  CHECK(r.status == 200 && cJSON_GetArraySize(m) == 2, "both missing: %ld %.300s", r.status, r.body);
  cJSON_Delete(j);
  resp_free(&r);
  r = do_req(
      &main_d,
      (req){.method = "PUT", .path = path, .body = ply, .len = len, .ctype = "application/octet-stream"});
  CHECK(r.status == 201, "PUT: %ld %.300s", r.status, r.body);
  resp_free(&r);
  r = do_req(
      &main_d,
      (req){.method = "PUT", .path = path, .body = ply, .len = len, .ctype = "application/octet-stream"});
  CHECK(r.status == 200, "PUT again: %ld", r.status);
  resp_free(&r);
  r = do_req(&main_d, (req){.method = "HEAD", .path = path});
  CHECK(r.status == 200, "HEAD after the upload: %ld", r.status);
  resp_free(&r);
  r = post_json(&main_d, "/v1/blobs:missing", jq(body, sizeof body, "{'digests': ['%s', '%s']}", hex, other));
  j = jparse(&r);
  m = cJSON_GetObjectItemCaseSensitive(j, "missing");
  CHECK(r.status == 200 && cJSON_GetArraySize(m) == 1 && cJSON_IsString(cJSON_GetArrayItem(m, 0)) &&
            strcmp(cJSON_GetArrayItem(m, 0)->valuestring, other) == 0,
        "only the other one missing: %.300s", r.body);
  cJSON_Delete(j);
  resp_free(&r);
  /* Wrong digest: 422, nothing stored. */
  char wrong[256];
  snprintf(wrong, sizeof wrong, "/v1/blobs/%s", other);
  r = do_req(
      &main_d,
      (req){.method = "PUT", .path = wrong, .body = ply, .len = len, .ctype = "application/octet-stream"});
  CHECK_PROBLEM(r, 422, "PUT with the wrong digest");
  resp_free(&r);
  r = do_req(&main_d, (req){.method = "HEAD", .path = wrong});
  CHECK(r.status == 404, "nothing stored under the wrong digest: %ld", r.status);
  resp_free(&r);
  /* A scene using the mesh by digest renders: Lambertian 0.5 quad, E = 1
   * at nadir, meter looking down at a point of the quad -> 0.5 / pi. */
  const char *fmt =
      "{'type': 'scene', 'variant': 'mono',"
      " 'meter': {'type': 'distant', 'direction': [0, 0, -1], 'target': [0.3, 0.2, 0],"
      "   'film': {'type': 'hdrfilm', 'width': 1, 'height': 1, 'rfilter': {'type': 'box'}}},"
      " 'sun': {'type': 'directional', 'direction': [0, 0, -1]},"
      " 'quad': {'type': 'ply', 'filename': '%s', 'bsdf': {'type': 'diffuse', 'reflectance': 0.5}}}";
  char doc[2048], ref[80], id[65];
  snprintf(ref, sizeof ref, "sha256:%s", hex);
  jq(doc, sizeof doc, fmt, ref);
  REQUIRE(post_scene(&main_d, doc, NULL, id) == 201, "scene with the blob mesh");
  snprintf(path, sizeof path, "/v1/scenes/%s:render", id);
  r = post_json(&main_d, path, jq(body, sizeof body, "{'spp': 2}"));
  film f = {0};
  CHECK(r.status == 200 && film_from_json(&r, &f), "render: %ld %.300s", r.status, r.body);
  if (f.data) CHECK_REL(f.data[0], 0.5 / PI, 1e-5);
  film_free(&f);
  resp_free(&r);
  /* The same mesh by a plain name inside --data-root loads too (a
   * different document, so a different id). */
  char id2[65];
  jq(doc, sizeof doc, fmt, "quad_le.ply");
  CHECK(post_scene(&main_d, doc, NULL, id2) == 201 && strcmp(id, id2) != 0, "plain name inside --data-root");
  /* An unknown digest: 422. */
  snprintf(ref, sizeof ref, "sha256:%s", other);
  jq(doc, sizeof doc, fmt, ref);
  r = post_json(&main_d, "/v1/scenes", doc);
  CHECK_PROBLEM(r, 422, "scene referring to a blob never uploaded");
  resp_free(&r);
  free(ply);
}

static void test_paths_outside_data_root(void) {
  const char *fmt = "{'type': 'scene', 'variant': 'mono',"
                    " 'meter': {'type': 'distant', 'direction': [0, 0, -1],"
                    "   'film': {'type': 'hdrfilm', 'width': 1, 'height': 1}},"
                    " 'm': {'type': 'ply', 'filename': '%s'}}";
  char ply_abs[256];
  /* A real PLY, but outside --data-root (tmpdir/data). */
  snprintf(ply_abs, sizeof ply_abs, "%s/outside.ply", tmpdir);
  size_t len;
  char *ply = tfile_read("tests/data/quad_le.ply", &len);
  if (ply) write_bytes(ply_abs, ply, len);
  free(ply);
  const char *names[] = {"../../etc/passwd", "/etc/passwd", "../outside.ply", ply_abs,
                         "sub/../../outside.ply"};
  for (size_t i = 0; i < sizeof names / sizeof *names; i++) {
    char doc[2048], what[300];
    jq(doc, sizeof doc, fmt, names[i]);
    resp r = post_json(&main_d, "/v1/scenes", doc);
    snprintf(what, sizeof what, "filename %s", names[i]);
    CHECK_PROBLEM(r, 422, what);
    cJSON *j = jparse(&r);
    CHECK(starts_with(jstr(j, "pointer"), "/m"), "%s: pointer names the shape: %.300s", names[i], r.body);
    CHECK(!strstr(r.body, "root:"), "%s: no file content in the answer", names[i]);
    cJSON_Delete(j);
    resp_free(&r);
  }
}

/* ---- tests: concurrency ----------------------------------------------------------- */

typedef struct client_arg {
  const char *scene;
  int k;
  bool ok;
  char why[200];
} client_arg;

static void *client_main(void *p) {
  client_arg *a = p;
  char body[512], job[128];
  jq(body, sizeof body,
     "{'contexts': [{'id': 'k%d-a', 'wavelength': %d}, {'id': 'k%d-b', 'wavelength': %d}],"
     " 'defaults': {'spp': 2}, 'seed': %d}",
     a->k, 450 + a->k, a->k, 500 + a->k, a->k);
  long st = submit_job(&main_d, a->scene, body, NULL, job);
  if (st != 202) {
    snprintf(a->why, sizeof a->why, "submit %ld", st);
    return NULL;
  }
  cJSON *j = wait_job(&main_d, job, 20);
  if (!j || !jstr_is(j, "state", "succeeded") || jnum(j, "renders_done") != 4) {
    snprintf(a->why, sizeof a->why, "job %s ended %s", job, j ? jstr(j, "state") : "(unreadable)");
    cJSON_Delete(j);
    return NULL;
  }
  cJSON_Delete(j);
  char ctx[32];
  snprintf(ctx, sizeof ctx, "k%d-a", a->k);
  resp r = result(&main_d, job, ctx, "meter", "application/json");
  film f = {0};
  if (r.status == 200 && film_from_json(&r, &f) && fabs(f.data[0] - 0.5 / PI) < 1e-5)
    a->ok = true;
  else
    snprintf(a->why, sizeof a->why, "result %ld", r.status);
  film_free(&f);
  resp_free(&r);
  return NULL;
}

static void test_concurrent_clients(void) {
  char id[65];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  pthread_t th[8];
  client_arg args[8];
  for (int k = 0; k < 8; k++) {
    args[k] = (client_arg){.scene = id, .k = k};
    pthread_create(&th[k], NULL, client_main, &args[k]);
  }
  for (int k = 0; k < 8; k++) pthread_join(th[k], NULL);
  for (int k = 0; k < 8; k++) CHECK(args[k].ok, "client %d: %s", k, args[k].why);
}

/* ---- tests: error statuses ---------------------------------------------------------- */

static void test_error_400(void) {
  resp r = post_json(&main_d, "/v1/scenes", "{\"type\": \"scene\", ");
  CHECK_PROBLEM(r, 400, "truncated JSON scene");
  resp_free(&r);
  r = do_req(&main_d, (req){.method = "POST",
                            .path = "/v1/scenes",
                            .body = "<scene version=\"3.0.0\"><shape",
                            .ctype = "application/xml"});
  CHECK_PROBLEM(r, 400, "truncated XML scene");
  resp_free(&r);
  char id[65], path[256];
  if (default_scene(&main_d, id)) {
    snprintf(path, sizeof path, "/v1/scenes/%s/jobs", id);
    r = post_json(&main_d, path, "{\"contexts\": [");
    CHECK_PROBLEM(r, 400, "truncated JSON job");
    resp_free(&r);
  }
}

static void test_error_404(void) {
  const char *paths[] = {"/v1/nothing", "/v2",
                         "/v1/scenes/0000000000000000000000000000000000000000000000000000000000000000",
                         "/v1/jobs/no-such-job", "/v1/jobs/no-such-job/results"};
  for (size_t i = 0; i < sizeof paths / sizeof *paths; i++) {
    resp r = get(&main_d, paths[i]);
    CHECK_PROBLEM(r, 404, paths[i]);
    resp_free(&r);
  }
  char id[65], path[256];
  if (default_scene(&main_d, id)) {
    snprintf(path, sizeof path, "/v1/scenes/%s/sensors/nosuch/directions", id);
    resp r = get(&main_d, path);
    CHECK(r.status == 404 || r.status == 422, "unknown sensor: %ld", r.status);
    resp_free(&r);
  }
}

static void test_error_405(void) {
  char allow[128];
  resp r = do_req(&main_d, (req){.method = "PUT", .path = "/v1/scenes", .body = "{}"});
  CHECK_PROBLEM(r, 405, "PUT /v1/scenes");
  hdr(&r, "Allow", allow, sizeof allow);
  CHECK(strstr(allow, "GET") && strstr(allow, "POST"), "Allow: %s", allow);
  resp_free(&r);
  r = do_req(&main_d, (req){.method = "DELETE", .path = "/v1/health/live"});
  CHECK_PROBLEM(r, 405, "DELETE /v1/health/live");
  CHECK(strstr(hdr(&r, "Allow", allow, sizeof allow), "GET") != NULL, "Allow: %s", allow);
  resp_free(&r);
}

static void test_error_406(void) {
  char id[65], path[256], body[64];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  snprintf(path, sizeof path, "/v1/scenes/%s:render", id);
  resp r = do_req(&main_d, (req){.method = "POST",
                                 .path = path,
                                 .body = jq(body, sizeof body, "{'spp': 1}"),
                                 .accept = "image/tiff"});
  CHECK_PROBLEM(r, 406, "render as image/tiff");
  resp_free(&r);
}

static void test_error_409(void) {
  char id[65], job[128], job2[128], body[4096], body2[1024], path[256], key[64];
  /* A scene of its own with a job running on it. */
  REQUIRE(plate_scene(&main_d, "0.77", id), "scene");
  REQUIRE(submit_job(&main_d, id, hemi_job_body(body, sizeof body, 4, 0.5), NULL, job) == 202, "submit");
  snprintf(path, sizeof path, "/v1/scenes/%s", id);
  resp r = do_req(&main_d, (req){.method = "DELETE", .path = path});
  CHECK_PROBLEM(r, 409, "DELETE a scene with an active job");
  CHECK(r.body && strstr(r.body, job) && strstr(r.body, "force=true"),
        "the 409 names the job and force=true: %.300s", r.body ? r.body : "");
  resp_free(&r);
  r = get(&main_d, path);
  cJSON *j = jparse(&r);
  CHECK(r.status == 200 && jnum(j, "jobs_active") >= 1, "scene still there, jobs_active %g",
        jnum(j, "jobs_active"));
  cJSON_Delete(j);
  resp_free(&r);
  snprintf(path, sizeof path, "/v1/scenes/%s?force=true", id);
  r = do_req(&main_d, (req){.method = "DELETE", .path = path});
  CHECK(r.status == 204, "forced DELETE: %ld %.300s", r.status, r.body);
  resp_free(&r);
  j = wait_job(&main_d, job, 5);
  CHECK(j && jstr_is(j, "state", "cancelled"), "the forced delete cancelled the job: %s",
        j ? jstr(j, "state") : "(gone)");
  cJSON_Delete(j);
  /* Idempotency-Key: same body -> the same job; another body -> 409. */
  REQUIRE(plate_scene(&main_d, "0.5", id), "plate");
  snprintf(key, sizeof key, "itest-%d", (int)getpid());
  jq(body2, sizeof body2, "{'contexts': [{'id': 'i0'}], 'defaults': {'spp': 1}}");
  REQUIRE(submit_job(&main_d, id, body2, key, job) == 202, "first with the key");
  CHECK(submit_job(&main_d, id, body2, key, job2) == 202 && strcmp(job, job2) == 0,
        "same key, same body: same job");
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", id);
  char ik[96];
  snprintf(ik, sizeof ik, "Idempotency-Key: %s", key);
  jq(body2, sizeof body2, "{'contexts': [{'id': 'i1'}], 'defaults': {'spp': 1}}");
  r = do_req(&main_d, (req){.method = "POST", .path = path, .body = body2, .hdr = {ik}});
  CHECK_PROBLEM(r, 409, "same Idempotency-Key, another body");
  resp_free(&r);
  cJSON_Delete(wait_job(&main_d, job, 5));
}

static void test_error_415(void) {
  resp r =
      do_req(&main_d, (req){.method = "POST", .path = "/v1/scenes", .body = "scene", .ctype = "text/plain"});
  CHECK_PROBLEM(r, 415, "text/plain scene");
  resp_free(&r);
}

static void test_error_422(void) {
  /* Well-formed, invalid: an unknown plugin; the pointer names the place. */
  char doc[1024];
  jq(doc, sizeof doc,
     "{'type': 'scene', 'variant': 'mono',"
     " 'meter': {'type': 'distant', 'film': {'type': 'hdrfilm', 'width': 1, 'height': 1}},"
     " 'plate': {'type': 'rectangle', 'bsdf': {'type': 'no_such_bsdf'}}}");
  resp r = post_json(&main_d, "/v1/scenes", doc);
  CHECK_PROBLEM(r, 422, "unknown plugin");
  cJSON *j = jparse(&r);
  CHECK(starts_with(jstr(j, "pointer"), "/plate/bsdf"), "pointer /plate/bsdf...: %.300s", r.body);
  cJSON_Delete(j);
  resp_free(&r);
  /* A bad job: an invalid context id, an unknown param key. */
  char id[65], path[256], body[512];
  REQUIRE(plate_scene(&main_d, "0.5", id), "scene");
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", id);
  r = post_json(&main_d, path, jq(body, sizeof body, "{'contexts': [{'id': 'bad id/x'}]}"));
  CHECK_PROBLEM(r, 422, "context id outside [A-Za-z0-9._-]");
  resp_free(&r);
  r = post_json(&main_d, path, jq(body, sizeof body, "{'contexts': [{'id': 'a'}, {'id': 'a'}]}"));
  CHECK_PROBLEM(r, 422, "duplicate context id");
  resp_free(&r);
  r = post_json(&main_d, path,
                jq(body, sizeof body, "{'contexts': [{'id': 'a', 'params': {'plate.nope': 1}}]}"));
  CHECK_PROBLEM(r, 422, "unknown key in a context");
  j = jparse(&r);
  CHECK(jstr_is(j, "key", "plate.nope"), "problem key: %.300s", r.body);
  cJSON_Delete(j);
  resp_free(&r);
  /* A render with an unknown override key. */
  snprintf(path, sizeof path, "/v1/scenes/%s:render", id);
  r = post_json(&main_d, path, jq(body, sizeof body, "{'params': {'plate.bsdf.reflectance.valu': 0.2}}"));
  CHECK_PROBLEM(r, 422, "render with an unknown override");
  j = jparse(&r);
  bool cand = false;
  const cJSON *it;
  cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(j, "candidates")) {
    if (cJSON_IsString(it) && strcmp(it->valuestring, "plate.bsdf.reflectance.value") == 0) cand = true;
  }
  CHECK(jstr_is(j, "key", "plate.bsdf.reflectance.valu") && cand, "key and candidates: %.300s", r.body);
  cJSON_Delete(j);
  resp_free(&r);
}

static void test_error_504(void) {
  char id[65], path[256], body[256];
  REQUIRE(default_scene(&main_d, id), "default scene");
  snprintf(path, sizeof path, "/v1/scenes/%s:render", id);
  /* 32x32 (16 render tiles) for ~60 s of work (by the calibration): the
   * 504 arriving within the client's 30 s limit shows the work stopped at
   * the deadline (an order: deadline, answer, then nothing left running),
   * with no latency assertion for a loaded machine to break. */
  long spp = 60.0 * plate_sps / 1024.0;
  resp r =
      post_json(&main_d, path, jq(body, sizeof body, "{'spp': %ld, 'timeout_s': 0.05}", spp < 1 ? 1 : spp));
  CHECK_PROBLEM(r, 504, "timeout_s exceeded");
  resp_free(&r);
  /* And the work stopped: a small render on the same scene (which waits
   * for the scene while a render holds it) is served within the limit. */
  r = do_req(&main_d, (req){.method = "POST", .path = path, .body = jq(body, sizeof body, "{'spp': 1}")});
  CHECK(r.status == 200, "render after the 504: %ld", r.status);
  resp_free(&r);
  /* One render tile (5x5) with ~60 s of samples: the deadline still
   * holds (it must not wait for the tile, nor answer 200 after it). */
  REQUIRE(plate_scene(&main_d, "0.5", id), "plate");
  snprintf(path, sizeof path, "/v1/scenes/%s:render", id);
  r = post_json(&main_d, path,
                jq(body, sizeof body, "{'sensor': 'hemi', 'spp': %ld, 'timeout_s': 0.05}", hemi_spp(60.0)));
  CHECK_PROBLEM(r, 504, "timeout_s exceeded on a one-tile render");
  resp_free(&r);
}

/* --token-file: every route but health needs the bearer token. */
static void test_error_401(void) {
  char tok_path[160];
  snprintf(tok_path, sizeof tok_path, "%s/token", tmpdir);
  const char *tok = "itest-secret-7f3a";
  char line[64];
  snprintf(line, sizeof line, "%s\n", tok);
  REQUIRE(write_bytes(tok_path, line, strlen(line)), "token file");
  daemon_proc d;
  const char *extra[] = {"--token-file", tok_path, "--threads", "1", NULL};
  REQUIRE(daemon_start(&d, "token", extra), "daemon with --token-file");
  char www[128];
  resp r = get(&d, "/v1");
  CHECK_PROBLEM(r, 401, "GET /v1 without a token");
  CHECK(starts_with(hdr(&r, "WWW-Authenticate", www, sizeof www), "Bearer"), "WWW-Authenticate: %s", www);
  resp_free(&r);
  r = get(&d, "/v1/scenes");
  CHECK_PROBLEM(r, 401, "GET /v1/scenes without a token");
  /* A missing token and a wrong one are told apart. */
  cJSON *p = jparse(&r);
  CHECK(p && jstr(p, "detail") && strstr(jstr(p, "detail"), "no Authorization header"),
        "missing token: detail says so: %.300s", r.body);
  cJSON_Delete(p);
  resp_free(&r);
  snprintf(d.token, sizeof d.token, "wrong-token");
  r = get(&d, "/v1/scenes");
  CHECK_PROBLEM(r, 401, "GET /v1/scenes with a wrong token");
  p = jparse(&r);
  CHECK(p && jstr(p, "detail") && strstr(jstr(p, "detail"), "Authorization header is wrong") &&
            !strstr(jstr(p, "detail"), "no Authorization header"),
        "wrong token: detail says so: %.300s", r.body);
  cJSON_Delete(p);
  resp_free(&r);
  d.token[0] = '\0';
  /* The root sends a newcomer's browser to the viewer, token or not. */
  r = get(&d, "/");
  CHECK(r.status == 302 && strcmp(hdr(&r, "Location", www, sizeof www), "/ui/") == 0,
        "GET / redirects to /ui/: %ld, Location '%s'", r.status, www);
  resp_free(&r);
  r = do_req(&d, (req){.method = "HEAD", .path = "/"});
  CHECK(r.status == 302 && strcmp(hdr(&r, "Location", www, sizeof www), "/ui/") == 0,
        "HEAD / redirects to /ui/: %ld, Location '%s'", r.status, www);
  resp_free(&r);
  r = get(&d, "/v1/health/live");
  CHECK(r.status == 200, "health/live is open: %ld", r.status);
  resp_free(&r);
  r = get(&d, "/v1/health/ready");
  CHECK(r.status == 200, "health/ready is open: %ld", r.status);
  resp_free(&r);
  snprintf(d.token, sizeof d.token, "%s", tok);
  r = get(&d, "/v1");
  CHECK(r.status == 200, "GET /v1 with the token: %ld", r.status);
  resp_free(&r);
  r = get(&d, "/metrics");
  CHECK(r.status == 200, "GET /metrics with the token: %ld", r.status);
  resp_free(&r);
  double secs;
  int rc = daemon_stop(&d, 5, &secs);
  CHECK(rc == 0, "token daemon exit %d", rc);
}

static void test_error_413(void) {
  REQUIRE(lim_d.t.pid, "limits daemon");
  /* A valid scene padded with whitespace past --max-body 4096. */
  char doc[4096], big[16384];
  jq(doc, sizeof doc, PLATE_FMT, "0.5");
  size_t dl = strlen(doc);
  memset(big, ' ', sizeof big);
  memcpy(big + sizeof big - 1 - dl, doc, dl);
  big[sizeof big - 1] = '\0';
  resp r = post_json(&lim_d, "/v1/scenes", big);
  CHECK_PROBLEM(r, 413, "16 KB body over --max-body 4096");
  resp_free(&r);
  char id[65];
  CHECK(post_scene(&lim_d, doc, NULL, id) == 201, "the same scene unpadded fits");
  resp g = get(&lim_d, "/v1");
  cJSON *j = jparse(&g);
  CHECK(jnum(cJSON_GetObjectItemCaseSensitive(j, "limits"), "max_body_bytes") == 4096 &&
            jnum(cJSON_GetObjectItemCaseSensitive(j, "limits"), "max_queue") == 1,
        "limits reported: %.400s", g.body);
  cJSON_Delete(j);
  resp_free(&g);
}

static void test_error_429(void) {
  REQUIRE(lim_d.t.pid, "limits daemon");
  /* --threads 1 --max-queue 1: one job running (A), one queued (B), the
   * third (C) refused. Three scenes, so that no submission waits on a busy
   * scene. */
  char a[65], b[65], c[65], body[4096], ja[128], jb[128], jc[128], path[256], ra[32];
  REQUIRE(plate_scene(&lim_d, "0.61", a) && plate_scene(&lim_d, "0.62", b) && plate_scene(&lim_d, "0.63", c),
          "scenes");
  /* Long enough (3 x ~60 s) that A is still running for the SIGTERM test. */
  hemi_job_body(body, sizeof body, 3, 60.0);
  REQUIRE(submit_job(&lim_d, a, body, NULL, ja) == 202, "job A");
  CHECK(wait_running(&lim_d, ja, 10), "job A runs");
  CHECK(submit_job(&lim_d, b, body, NULL, jb) == 202, "job B queued");
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", c);
  resp r = post_json(&lim_d, path, body);
  CHECK_PROBLEM(r, 429, "queue full");
  CHECK(atoi(hdr(&r, "Retry-After", ra, sizeof ra)) >= 1, "Retry-After: '%s'", ra);
  resp_free(&r);
  (void)jc;
}

/* SIGTERM with a job running (the limits daemon's job A from the 429 test,
 * ~180 s of renders): exit 0 long before that job could end, so shutdown
 * cancelled it rather than waiting. The 30 s is a limit, not a measurement. */
static void test_sigterm_with_work(void) {
  REQUIRE(lim_d.t.pid, "limits daemon");
  resp r = get(&lim_d, "/metrics");
  CHECK(strstr(r.body, "raysweep_jobs{state=\"running\"} 1"), "a job is running at SIGTERM");
  resp_free(&r);
  double secs = 0;
  int rc = daemon_stop(&lim_d, 30, &secs);
  CHECK(rc == 0, "exit status %d after SIGTERM (%.2f s; -2: still running at the 30 s limit)", rc, secs);
}

static void test_sigterm_main(void) {
  double secs = 0;
  int rc = daemon_stop(&main_d, 30, &secs);
  CHECK(rc == 0, "main daemon exit status %d after SIGTERM (%.2f s)", rc, secs);
  char *log = tfile_read(main_d.t.log, NULL);
  CHECK(log && strstr(log, "raysweepd: listening on http://127.0.0.1:"),
        "stderr announces the address: %.300s", log ? log : "");
  CHECK(log && strstr(log, "raysweepd: viewer: http://127.0.0.1:") && strstr(log, "/ui/\n"),
        "stderr announces the viewer's address: %.300s", log ? log : "");
  free(log);
}

int main(void) {
  signal(SIGPIPE, SIG_IGN);
  snprintf(tmpdir, sizeof tmpdir, "/tmp/rsw-http-XXXXXX");
  if (!mkdtemp(tmpdir)) return 1;
  char data[128], dst[160];
  snprintf(data, sizeof data, "%s/data", tmpdir);
  mkdir(data, 0755);
  size_t len;
  char *ply = tfile_read("tests/data/quad_le.ply", &len);
  snprintf(dst, sizeof dst, "%s/quad_le.ply", data);
  if (ply) write_bytes(dst, ply, len);
  free(ply);
  curl_global_init(CURL_GLOBAL_DEFAULT);

  const char *main_extra[] = {"--threads", "2", NULL};
  main_ok = daemon_start(&main_d, "main", main_extra);
  if (!main_ok) {
    fprintf(stdout, "FAIL could not start %s/raysweepd serve\n", bin_dir());
    rsw_test_failed_++;
  } else {
    calibrate();
    RSW_TEST_RUN(test_server_info);
    RSW_TEST_RUN(test_health);
    RSW_TEST_RUN(test_scenes_json);
    RSW_TEST_RUN(test_scenes_xml_seed);
    RSW_TEST_RUN(test_params_get_patch);
    RSW_TEST_RUN(test_render_formats);
    RSW_TEST_RUN(test_directions);
    RSW_TEST_RUN(test_patch_equals_reload);
    RSW_TEST_RUN(test_jobs_routes);
    RSW_TEST_RUN(test_jobs_dry_run);
    RSW_TEST_RUN(test_spectral_job);
    RSW_TEST_RUN(test_split_job_bitwise);
    RSW_TEST_RUN(test_events);
    RSW_TEST_RUN(test_cancel);
    RSW_TEST_RUN(test_cancel_between_passes);
    RSW_TEST_RUN(test_busy_scene_responsive);
    RSW_TEST_RUN(test_blobs);
    RSW_TEST_RUN(test_paths_outside_data_root);
    RSW_TEST_RUN(test_concurrent_clients);
    RSW_TEST_RUN(test_error_400);
    RSW_TEST_RUN(test_error_404);
    RSW_TEST_RUN(test_error_405);
    RSW_TEST_RUN(test_error_406);
    RSW_TEST_RUN(test_error_409);
    RSW_TEST_RUN(test_error_415);
    RSW_TEST_RUN(test_error_422);
    RSW_TEST_RUN(test_error_504);
    RSW_TEST_RUN(test_metrics);
    RSW_TEST_RUN(test_error_401);
    const char *lim_extra[] = {"--threads", "1", "--max-body", "4096", "--max-queue", "1", NULL};
    if (daemon_start(&lim_d, "limits", lim_extra)) {
      RSW_TEST_RUN(test_error_413);
      RSW_TEST_RUN(test_error_429);
      RSW_TEST_RUN(test_sigterm_with_work);
    } else {
      fprintf(stdout, "FAIL could not start the limits daemon\n");
      rsw_test_failed_++;
    }
    RSW_TEST_RUN(test_sigterm_main);
  }
  if (main_d.t.pid) daemon_stop(&main_d, 5, NULL);
  if (lim_d.t.pid) daemon_stop(&lim_d, 5, NULL);
  curl_global_cleanup();
  char cmd[128];
  snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
  if (getenv("RSW_KEEP_TMP"))
    fprintf(stderr, "kept %s\n", tmpdir);
  else if (system(cmd))
    fprintf(stderr, "could not remove %s\n", tmpdir);
  RSW_TEST_END("test_http");
}
