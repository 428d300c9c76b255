/* raysweepd under hostile and careless clients (issue 13): the real daemon
 * on 127.0.0.1, raw HTTP over sockets (tests/support/daemon.h).
 *
 *   - slow-loris: 300 connections trickling a header byte a second (more
 *     than the 256 connections the thread-per-connection server had) while
 *     a normal client gets /v1/health/ready and a small render within
 *     100 ms each;
 *   - a nearly full server answers 503 + Retry-After, the probes still 200;
 *   - the header deadline cuts slow and garbage connections;
 *   - the wire: HEAD on GET routes, %2F does not split a path segment,
 *     2,000 query parameters get a 414 problem, Idempotency-Key of length
 *     0 or 300 is a 400 naming the header, invalid UTF-8 in an echoed key
 *     still gives a valid UTF-8 JSON problem;
 *   - hangs: an event stream resumed at or past a finished job's end closes
 *     at once; a sync render whose client hung up stops (the scene is free
 *     again within 2 s); SIGTERM cancels a running sync render and answers
 *     it 503 within a few seconds. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "../support/daemon.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

static char tmpdir[64];
static tdaemon main_d;
static bool main_ok;
static char plate_id[65];
/* Samples per second of a 5x5 hdistant render of the plate (calibrated). */
static double plate_sps = 3e6;

static void sleep_ms(int ms) {
  struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
  nanosleep(&ts, NULL);
}

/* The plate of test_http.c: a 1x1 `distant` meter and a 5x5 hdistant. */
static const char *PLATE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"component_format\": \"float32\","
    "     \"rfilter\": {\"type\": \"box\"}}},"
    " \"hemi\": {\"type\": \"hdistant\", \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 5, \"height\": 5, \"component_format\": \"float32\","
    "     \"rfilter\": {\"type\": \"box\"}}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.0},"
    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";

static const char *const JSON_CT[] = {"Content-Type: application/json", NULL};

static bool req(const tdaemon *d, const char *method, const char *path, const char *body, thttp_resp *r) {
  return tdaemon_http(d, method, path, body ? JSON_CT : NULL, body, body ? strlen(body) : 0, 10.0, r);
}

static bool is_problem(const thttp_resp *r, int status) {
  char ct[128];
  if (r->status != status) return false;
  if (!thttp_header(r, "Content-Type", ct, sizeof ct) || strncmp(ct, "application/problem+json", 24) != 0)
    return false;
  cJSON *j = cJSON_Parse(r->body);
  const cJSON *s = cJSON_GetObjectItemCaseSensitive(j, "status");
  bool ok = cJSON_IsNumber(s) && s->valueint == status;
  cJSON_Delete(j);
  return ok;
}

static long hemi_spp(double secs) {
  double spp = plate_sps * secs / 25.0;
  return spp < 1 ? 1 : (long)spp;
}

/* ---- slow clients ----------------------------------------------------------- */

typedef struct slow_set {
  int fd[400];
  int n;
} slow_set;

/* Open n connections and send each the first byte of a request. */
static void slow_open(const tdaemon *d, slow_set *s, int n) {
  s->n = 0;
  for (int i = 0; i < n && i < 400; i++) {
    int fd = tdaemon_connect(d);
    if (fd < 0) break;
    send(fd, "G", 1, MSG_NOSIGNAL);
    s->fd[s->n++] = fd;
  }
}

/* One more header byte on every connection (the slow-loris tick). */
static void slow_tick(slow_set *s, int k) {
  static const char hdr[] =
      "ET /v1/health/live HTTP/1.1\r\nHost: x\r\nX-Slow: aaaaaaaaaaaaaaaaaaaaaaaaaaaaaa";
  char ch = hdr[k % (int)(sizeof hdr - 1)];
  for (int i = 0; i < s->n; i++) send(s->fd[i], &ch, 1, MSG_NOSIGNAL);
}

static void slow_close(slow_set *s) {
  for (int i = 0; i < s->n; i++) close(s->fd[i]);
  s->n = 0;
}

static void test_slow_loris(void) {
  REQUIRE(main_ok, "main daemon");
  static slow_set s;
  slow_open(&main_d, &s, 300);
  CHECK(s.n == 300, "opened %d of 300 slow connections", s.n);
  char path[160];
  snprintf(path, sizeof path, "/v1/scenes/%s:render", plate_id);
  double worst_ready = 0, worst_render = 0;
  int bad = 0;
  /* Four seconds of ticks, a byte a second, with the normal client's
   * requests in between. */
  for (int k = 0; k < 4; k++) {
    slow_tick(&s, k);
    for (int i = 0; i < 5; i++) {
      thttp_resp r;
      tdaemon_http(&main_d, "GET", "/v1/health/ready", NULL, NULL, 0, 3.0, &r);
      if (r.status != 200) bad++;
      if (r.secs > worst_ready) worst_ready = r.secs;
      thttp_resp_free(&r);
      req(&main_d, "POST", path, "{\"sensor\": \"meter\", \"spp\": 1}", &r);
      if (r.status != 200) bad++;
      if (r.secs > worst_render) worst_render = r.secs;
      thttp_resp_free(&r);
      sleep_ms(150);
    }
  }
  fprintf(stdout, "  300 slow connections: slowest ready %.1f ms, slowest 1x1 render %.1f ms, %d failed\n",
          1e3 * worst_ready, 1e3 * worst_render, bad);
  CHECK(bad == 0, "%d of 40 requests failed under 300 slow connections", bad);
  CHECK(worst_ready < 0.1, "ready took %.1f ms (limit 100)", 1e3 * worst_ready);
  CHECK(worst_render < 0.1, "render took %.1f ms (limit 100)", 1e3 * worst_render);
  slow_close(&s);
}

/* --max-connections 24: 6 reserved for the probes (a quarter, at most 16),
 * so with 20 slow connections open every other request gets 503 with
 * Retry-After, and the probes still 200. */
static void test_nearly_full(void) {
  tdaemon d;
  const char *extra[] = {"--max-connections", "24", NULL};
  REQUIRE(tdaemon_start(&d, tmpdir, "full", extra, 0), "daemon");
  static slow_set s;
  slow_open(&d, &s, 20);
  sleep_ms(100);
  thttp_resp r;
  tdaemon_http(&d, "GET", "/v1", NULL, NULL, 0, 3.0, &r);
  char ra[32];
  CHECK(is_problem(&r, 503), "GET /v1 while nearly full: %d %.200s", r.status, r.body);
  CHECK(thttp_header(&r, "Retry-After", ra, sizeof ra) && atoi(ra) >= 1, "Retry-After: %s",
        thttp_header(&r, "Retry-After", ra, sizeof ra) ? ra : "(none)");
  thttp_resp_free(&r);
  tdaemon_http(&d, "GET", "/v1/health/ready", NULL, NULL, 0, 3.0, &r);
  CHECK(r.status == 200, "ready while nearly full: %d", r.status);
  thttp_resp_free(&r);
  tdaemon_http(&d, "GET", "/v1/health/live", NULL, NULL, 0, 3.0, &r);
  CHECK(r.status == 200, "live while nearly full: %d", r.status);
  thttp_resp_free(&r);
  slow_close(&s);
  sleep_ms(200);
  tdaemon_http(&d, "GET", "/v1", NULL, NULL, 0, 3.0, &r);
  CHECK(r.status == 200, "GET /v1 once the slow clients left: %d", r.status);
  thttp_resp_free(&r);
  CHECK(tdaemon_stop(&d, 10, NULL) == 0, "exit 0");
}

/* Seconds until the server closes fd (reads and drops anything). */
static double secs_until_closed(int fd, double limit) {
  double t0 = tdaemon_now();
  char buf[512];
  while (tdaemon_now() - t0 < limit) {
    struct pollfd p = {.fd = fd, .events = POLLIN};
    if (poll(&p, 1, 50) > 0) {
      ssize_t k = recv(fd, buf, sizeof buf, 0);
      if (k <= 0) return tdaemon_now() - t0;
    }
  }
  return -1;
}

/* --header-timeout 1: a connection that trickles its headers, one that
 * sends only blank lines (which MHD skips forever) and one led by NUL
 * bytes are all closed about a second after they connected. */
static void test_header_deadline(void) {
  tdaemon d;
  const char *extra[] = {"--header-timeout", "1", NULL};
  REQUIRE(tdaemon_start(&d, tmpdir, "deadline", extra, 0), "daemon");
  int slow = tdaemon_connect(&d), blank = tdaemon_connect(&d), nul = tdaemon_connect(&d);
  REQUIRE(slow >= 0 && blank >= 0 && nul >= 0, "connect");
  send(blank, "\r\n\r\n\r\n", 6, MSG_NOSIGNAL);
  send(nul, "\0\1\2\3\r\n", 6, MSG_NOSIGNAL);
  double t0 = tdaemon_now(), closed_slow = -1;
  for (int k = 0; k < 30 && closed_slow < 0; k++) { /* a byte every 100 ms */
    static const char line[] = "GET /v1 HTTP/1.1\r\nX: aaaaaaaaaaaaaaaaaaaaaaaaaaaa";
    send(slow, &line[k % (int)(sizeof line - 1)], 1, MSG_NOSIGNAL);
    double c = secs_until_closed(slow, 0.1);
    if (c >= 0) closed_slow = tdaemon_now() - t0;
  }
  double closed_blank = secs_until_closed(blank, 3.0);
  double closed_nul = secs_until_closed(nul, 3.0);
  if (closed_blank >= 0) closed_blank = tdaemon_now() - t0;
  if (closed_nul >= 0) closed_nul = tdaemon_now() - t0;
  fprintf(stdout, "  closed after: trickling %.2f s, blank lines %.2f s, NUL-led %.2f s\n", closed_slow,
          closed_blank, closed_nul);
  CHECK(closed_slow > 0.5 && closed_slow < 2.0, "trickling client closed after %.2f s", closed_slow);
  CHECK(closed_blank > 0 && closed_blank < 2.0, "blank-line client closed after %.2f s", closed_blank);
  CHECK(closed_nul > 0 && closed_nul < 2.0, "NUL-led client closed after %.2f s", closed_nul);
  close(slow);
  close(blank);
  close(nul);
  /* A normal request right after is fine. */
  thttp_resp r;
  tdaemon_http(&d, "GET", "/v1/health/ready", NULL, NULL, 0, 3.0, &r);
  CHECK(r.status == 200, "ready: %d", r.status);
  thttp_resp_free(&r);
  CHECK(tdaemon_stop(&d, 10, NULL) == 0, "exit 0");
}

/* ---- the wire ------------------------------------------------------------------- */

static void test_head(void) {
  REQUIRE(main_ok, "main daemon");
  const char *paths[] = {"/v1/health/live", "/v1/health/ready", "/v1", "/v1/scenes"};
  for (size_t i = 0; i < sizeof paths / sizeof paths[0]; i++) {
    thttp_resp g, h;
    req(&main_d, "GET", paths[i], NULL, &g);
    req(&main_d, "HEAD", paths[i], NULL, &h);
    char cl[32] = "";
    thttp_header(&h, "Content-Length", cl, sizeof cl);
    CHECK(h.status == 200 && g.status == 200, "HEAD %s: %d (GET %d)", paths[i], h.status, g.status);
    CHECK(h.len == 0, "HEAD %s sent a body of %zu bytes", paths[i], h.len);
    CHECK((size_t)atol(cl) == g.len, "HEAD %s Content-Length %s, GET body %zu", paths[i], cl, g.len);
    thttp_resp_free(&g);
    thttp_resp_free(&h);
  }
  thttp_resp r;
  req(&main_d, "DELETE", "/v1/health/live", NULL, &r);
  char allow[64] = "";
  thttp_header(&r, "Allow", allow, sizeof allow);
  CHECK(is_problem(&r, 405) && strstr(allow, "GET") && strstr(allow, "HEAD"), "405 Allow '%s'", allow);
  thttp_resp_free(&r);
}

static void test_raw_path(void) {
  REQUIRE(main_ok, "main daemon");
  char path[256];
  thttp_resp r;
  snprintf(path, sizeof path, "/v1/scenes/%s%%2Fparams", plate_id);
  req(&main_d, "GET", path, NULL, &r);
  CHECK(is_problem(&r, 404), "GET %s: %d (a decoded %%2F must not reach the params route) %.200s", path,
        r.status, r.body);
  thttp_resp_free(&r);
  /* Encoded characters inside a segment are still decoded: the scene id
   * with its first hex digit percent-encoded finds the scene. */
  snprintf(path, sizeof path, "/v1/scenes/%%%02X%s", (unsigned char)plate_id[0], plate_id + 1);
  req(&main_d, "GET", path, NULL, &r);
  CHECK(r.status == 200, "GET %s: %d", path, r.status);
  thttp_resp_free(&r);
  snprintf(path, sizeof path, "/v1/scenes/%%zz");
  req(&main_d, "GET", path, NULL, &r);
  CHECK(is_problem(&r, 400), "malformed escape: %d %.200s", r.status, r.body);
  thttp_resp_free(&r);
}

static void test_many_query_params(void) {
  REQUIRE(main_ok, "main daemon");
  size_t cap = 2000 * 12 + 64, n = 0;
  char *path = malloc(cap);
  REQUIRE(path, "memory");
  n += (size_t)snprintf(path + n, cap - n, "/v1/scenes?");
  for (int i = 0; i < 2000; i++) n += (size_t)snprintf(path + n, cap - n, "%sa%d=1", i ? "&" : "", i);
  thttp_resp r;
  bool got = tdaemon_http(&main_d, "GET", path, NULL, NULL, 0, 3.0, &r);
  CHECK(got && is_problem(&r, 414), "2,000 query parameters: %d after %.2f s: %.200s", r.status, r.secs,
        r.body ? r.body : "");
  thttp_resp_free(&r);
  free(path);
}

static void test_idempotency_key_length(void) {
  REQUIRE(main_ok, "main daemon");
  char path[160], key[400];
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", plate_id);
  const char *body =
      "{\"contexts\": [{\"id\": \"k\"}], \"defaults\": {\"sensors\": [\"meter\"], \"spp\": 1}}";
  for (int len = 0; len <= 300; len += 300) {
    memset(key, 'k', (size_t)len);
    key[len] = '\0';
    char hdr[420];
    snprintf(hdr, sizeof hdr, "Idempotency-Key: %s", key);
    const char *h[] = {"Content-Type: application/json", hdr, NULL};
    thttp_resp r;
    tdaemon_http(&main_d, "POST", path, h, body, strlen(body), 10.0, &r);
    CHECK(is_problem(&r, 400) && strstr(r.body, "Idempotency-Key"), "key of %d characters: %d %.300s", len,
          r.status, r.body);
    thttp_resp_free(&r);
  }
  /* 255 is fine. */
  memset(key, 'k', 255);
  key[255] = '\0';
  char hdr[420];
  snprintf(hdr, sizeof hdr, "Idempotency-Key: %s", key);
  const char *h[] = {"Content-Type: application/json", hdr, NULL};
  thttp_resp r;
  tdaemon_http(&main_d, "POST", path, h, body, strlen(body), 10.0, &r);
  CHECK(r.status == 202, "key of 255 characters: %d %.300s", r.status, r.body);
  thttp_resp_free(&r);
}

/* Strict UTF-8 check (RFC 3629). */
static bool valid_utf8(const unsigned char *s, size_t n) {
  for (size_t i = 0; i < n;) {
    uint32_t cp;
    size_t k;
    if (s[i] < 0x80) {
      i++;
      continue;
    } else if ((s[i] & 0xE0) == 0xC0)
      k = 2, cp = s[i] & 0x1F;
    else if ((s[i] & 0xF0) == 0xE0)
      k = 3, cp = s[i] & 0x0F;
    else if ((s[i] & 0xF8) == 0xF0)
      k = 4, cp = s[i] & 0x07;
    else
      return false;
    if (i + k > n) return false;
    for (size_t j = 1; j < k; j++) {
      if ((s[i + j] & 0xC0) != 0x80) return false;
      cp = cp << 6 | (s[i + j] & 0x3F);
    }
    static const uint32_t min_cp[5] = {0, 0, 0x80, 0x800, 0x10000};
    if (cp < min_cp[k] || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return false;
    i += k;
  }
  return true;
}

static void test_invalid_utf8_key(void) {
  REQUIRE(main_ok, "main daemon");
  char path[160];
  snprintf(path, sizeof path, "/v1/scenes/%s/params", plate_id);
  const char *body = "{\"plate.bsdf.\xff\xfe\xc3.value\": 0.3}";
  thttp_resp r;
  req(&main_d, "PATCH", path, body, &r);
  CHECK(r.status >= 400 && r.status < 500, "PATCH with a bad key: %d", r.status);
  CHECK(valid_utf8((const unsigned char *)r.body, r.len), "problem body is not valid UTF-8: %.300s", r.body);
  cJSON *j = cJSON_Parse(r.body);
  CHECK(j != NULL, "problem body is not JSON: %.300s", r.body);
  cJSON_Delete(j);
  thttp_resp_free(&r);
  /* The same key in a render override. */
  snprintf(path, sizeof path, "/v1/scenes/%s:render", plate_id);
  req(&main_d, "POST", path, "{\"sensor\": \"meter\", \"params\": {\"\xc0\xaf\": 1}}", &r);
  CHECK(r.status >= 400 && r.status < 500, "render with a bad key: %d", r.status);
  CHECK(valid_utf8((const unsigned char *)r.body, r.len), "render problem is not valid UTF-8: %.300s",
        r.body);
  thttp_resp_free(&r);
}

/* ---- hangs ---------------------------------------------------------------------- */

static void test_sse_resume_past_end(void) {
  REQUIRE(main_ok, "main daemon");
  char path[160];
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", plate_id);
  const char *body = "{\"contexts\": [{\"id\": \"a\"}, {\"id\": \"b\"}], \"defaults\": {\"sensors\": "
                     "[\"meter\"], \"spp\": 1}}";
  thttp_resp r;
  req(&main_d, "POST", path, body, &r);
  REQUIRE(r.status == 202, "submit: %d %.200s", r.status, r.body);
  cJSON *j = cJSON_Parse(r.body);
  char job[128] = "";
  const cJSON *id = cJSON_GetObjectItemCaseSensitive(j, "id");
  if (cJSON_IsString(id)) snprintf(job, sizeof job, "%s", id->valuestring);
  cJSON_Delete(j);
  thttp_resp_free(&r);
  REQUIRE(job[0], "job id");
  snprintf(path, sizeof path, "/v1/jobs/%s/events", job);
  /* From the start: two contexts and the end (ids 1, 2, 3). The stream
   * ends after `end`. */
  tdaemon_http(&main_d, "GET", path, NULL, NULL, 0, 10.0, &r);
  CHECK(r.status == 200 && strstr(r.body, "event: end") && strstr(r.body, "id: 3"), "full stream: %d %.300s",
        r.status, r.body);
  thttp_resp_free(&r);
  /* Resumed at the end's id and past it: the job is over, the client has
   * the end: the stream closes at once, empty. */
  const char *ids[] = {"Last-Event-ID: 3", "Last-Event-ID: 999"};
  for (int i = 0; i < 2; i++) {
    const char *h[] = {ids[i], NULL};
    bool got = tdaemon_http(&main_d, "GET", path, h, NULL, 0, 3.0, &r);
    CHECK(got && r.status == 200 && r.secs < 1.0, "%s: %d after %.2f s", ids[i], r.status, r.secs);
    CHECK(!r.body || !strstr(r.body, "event: context"), "%s re-sent a context: %.200s", ids[i], r.body);
    thttp_resp_free(&r);
  }
  /* Resumed before the end: the end is sent, then it closes. */
  const char *h[] = {"Last-Event-ID: 2", NULL};
  tdaemon_http(&main_d, "GET", path, h, NULL, 0, 3.0, &r);
  CHECK(r.status == 200 && strstr(r.body, "event: end") && !strstr(r.body, "event: context") && r.secs < 1.0,
        "Last-Event-ID 2: %d after %.2f s: %.200s", r.status, r.secs, r.body);
  thttp_resp_free(&r);
}

typedef struct render_call {
  const tdaemon *d;
  char path[160];
  char body[160];
  thttp_resp r;
  double t_end;
} render_call;

static void *render_thread(void *arg) {
  render_call *c = arg;
  req(c->d, "POST", c->path, c->body, &c->r);
  c->t_end = tdaemon_now();
  return NULL;
}

/* A client that hangs up on a long sync render frees the scene: the next
 * render on it answers within 2 s (the hung-up one would run ~6 s). */
static void test_render_client_gone(void) {
  REQUIRE(main_ok, "main daemon");
  char path[160], body[160], head[512];
  snprintf(path, sizeof path, "/v1/scenes/%s:render", plate_id);
  snprintf(body, sizeof body, "{\"sensor\": \"hemi\", \"spp\": %ld}", hemi_spp(6.0));
  int fd = tdaemon_connect(&main_d);
  REQUIRE(fd >= 0, "connect");
  int n = snprintf(
      head, sizeof head,
      "POST %s HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: %zu\r\n\r\n%s", path,
      strlen(body), body);
  send(fd, head, (size_t)n, MSG_NOSIGNAL);
  sleep_ms(300);
  close(fd);
  double t0 = tdaemon_now();
  thttp_resp r;
  req(&main_d, "POST", path, "{\"sensor\": \"meter\", \"spp\": 1}", &r);
  double dt = tdaemon_now() - t0;
  fprintf(stdout, "  render after a client hung up on a 6 s render: %d in %.2f s\n", r.status, dt);
  CHECK(r.status == 200 && dt < 2.0, "next render: %d after %.2f s", r.status, dt);
  thttp_resp_free(&r);
  /* And nothing is left rendering within 2 s of the hang-up (renders with
   * overrides or on views run beside each other, so the next render did
   * not have to wait for the cancelled one to wind down). */
  bool idle = false;
  for (int i = 0; i < 20 && !idle; i++) {
    req(&main_d, "GET", "/metrics", NULL, &r);
    idle = r.status == 200 && r.body && strstr(r.body, "\nraysweep_sync_renders 0\n");
    if (!idle) {
      thttp_resp_free(&r);
      sleep_ms(100);
    }
  }
  CHECK(idle, "sync renders still running 2 s after the client hung up: %.120s",
        r.body && strstr(r.body, "\nraysweep_sync_renders ") ? strstr(r.body, "\nraysweep_sync_renders ") + 1
                                                             : "?");
  thttp_resp_free(&r);
}

/* The value of the metric line that starts with `key ` in /metrics (0
 * when absent), or -1 when /metrics did not answer. */
static long metric_of(const char *key) {
  thttp_resp r;
  req(&main_d, "GET", "/metrics", NULL, &r);
  long v = r.status == 200 ? 0 : -1;
  size_t n = strlen(key);
  for (const char *p = r.body; v == 0 && p && *p; p = strchr(p, '\n') ? strchr(p, '\n') + 1 : NULL)
    if (strncmp(p, key, n) == 0 && p[n] == ' ') v = strtol(p + n + 1, NULL, 10);
  thttp_resp_free(&r);
  return v;
}

/* A sync render whose client hung up is answered 409 and counted so in
 * /metrics, every time. libmicrohttpd, resuming the connection, sometimes
 * found the client gone before asking for the answer, and the request
 * went uncounted (2 of 40 hang-ups on the development machine; the CLI
 * test's Ctrl-C check failed that way once). HANGUPS hang-ups, each
 * waited on until its render stopped. */
static void test_render_client_gone_counted(void) {
  REQUIRE(main_ok, "main daemon");
  enum {
    HANGUPS = 150
  };
  char path[160], body[160], head[512], key[256];
  snprintf(path, sizeof path, "/v1/scenes/%s:render", plate_id);
  snprintf(body, sizeof body, "{\"sensor\": \"hemi\", \"spp\": %ld}", hemi_spp(6.0));
  snprintf(key, sizeof key, "raysweep_http_requests_total{route=\"/v1/scenes/{id}:render\",status=\"409\"}");
  long before = metric_of(key);
  REQUIRE(before >= 0, "/metrics");
  int done = 0;
  for (; done < HANGUPS; done++) {
    int fd = tdaemon_connect(&main_d);
    if (fd < 0) break;
    int n = snprintf(
        head, sizeof head,
        "POST %s HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: %zu\r\n\r\n%s",
        path, strlen(body), body);
    send(fd, head, (size_t)n, MSG_NOSIGNAL);
    bool started = false, stopped = false;
    for (int i = 0; i < 2000 && !started; i++) started = metric_of("raysweep_sync_renders") > 0;
    close(fd);
    for (int i = 0; i < 500 && started && !stopped; i++) {
      stopped = metric_of("raysweep_sync_renders") == 0;
      if (!stopped) sleep_ms(2);
    }
    if (!started || !stopped) {
      CHECK(false, "hang-up %d: the render %s", done, started ? "did not stop within 1 s" : "never started");
      break;
    }
  }
  /* The counter is written as the request completes, after the render's
   * end: a moment for the last one. */
  long after = metric_of(key);
  for (int i = 0; i < 100 && after - before < done; i++) {
    sleep_ms(10);
    after = metric_of(key);
  }
  fprintf(stdout, "  %d hung-up renders: %ld counted 409\n", done, after - before);
  CHECK(done == HANGUPS && after - before == done, "%d hung-up renders, %ld counted 409", done,
        after - before);
}

/* SIGTERM during a 20 s sync render: the render is cancelled, its client
 * gets a 503 problem, and the daemon exits 0, all within a few seconds. */
static void test_sigterm_sync_render(void) {
  tdaemon d;
  REQUIRE(tdaemon_start(&d, tmpdir, "term", NULL, 0), "daemon");
  thttp_resp r;
  tdaemon_http(&d, "POST", "/v1/scenes", JSON_CT, PLATE, strlen(PLATE), 10.0, &r);
  cJSON *j = cJSON_Parse(r.body);
  const cJSON *id = cJSON_GetObjectItemCaseSensitive(j, "id");
  render_call c = {.d = &d};
  if (cJSON_IsString(id)) snprintf(c.path, sizeof c.path, "/v1/scenes/%s:render", id->valuestring);
  cJSON_Delete(j);
  thttp_resp_free(&r);
  REQUIRE(c.path[0], "scene");
  snprintf(c.body, sizeof c.body, "{\"sensor\": \"hemi\", \"spp\": %ld}", hemi_spp(20.0));
  pthread_t t;
  REQUIRE(pthread_create(&t, NULL, render_thread, &c) == 0, "thread");
  sleep_ms(500);
  double secs = 0, t0 = tdaemon_now();
  int rc = tdaemon_stop(&d, 15, &secs);
  pthread_join(t, NULL);
  fprintf(stdout, "  SIGTERM during a sync render: exit %d after %.2f s; render answered %d after %.2f s\n",
          rc, secs, c.r.status, c.t_end - t0);
  CHECK(rc == 0 && secs < 5.0, "exit %d after %.2f s", rc, secs);
  CHECK(is_problem(&c.r, 503), "the render's answer: %d %.300s", c.r.status, c.r.body ? c.r.body : "");
  CHECK(c.t_end - t0 < 5.0, "answered %.2f s after SIGTERM", c.t_end - t0);
  thttp_resp_free(&c.r);
}

/* ---- setup ---------------------------------------------------------------------- */

static void calibrate(void) {
  char path[160], body[64];
  snprintf(path, sizeof path, "/v1/scenes/%s:render", plate_id);
  snprintf(body, sizeof body, "{\"sensor\": \"hemi\", \"spp\": 20000}");
  thttp_resp r;
  req(&main_d, "POST", path, body, &r);
  if (r.status == 200 && r.secs > 0.005) plate_sps = 25.0 * 20000 / r.secs;
  fprintf(stdout, "  (calibration: %.3g samples/s in one 5x5 render)\n", plate_sps);
  thttp_resp_free(&r);
}

int main(void) {
  signal(SIGPIPE, SIG_IGN);
  struct rlimit rl;
  if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur < 1024 && rl.rlim_max >= 1024) {
    rl.rlim_cur = 1024;
    setrlimit(RLIMIT_NOFILE, &rl);
  }
  snprintf(tmpdir, sizeof tmpdir, "/tmp/rsw-http-limits-XXXXXX");
  if (!mkdtemp(tmpdir)) {
    perror("mkdtemp");
    return 1;
  }
  main_ok = tdaemon_start(&main_d, tmpdir, "main", NULL, 0);
  if (main_ok) {
    thttp_resp r;
    req(&main_d, "POST", "/v1/scenes", PLATE, &r);
    cJSON *j = cJSON_Parse(r.body);
    const cJSON *id = cJSON_GetObjectItemCaseSensitive(j, "id");
    if (cJSON_IsString(id)) snprintf(plate_id, sizeof plate_id, "%s", id->valuestring);
    cJSON_Delete(j);
    thttp_resp_free(&r);
    main_ok = plate_id[0] != '\0';
    if (main_ok) calibrate();
  }
  RSW_TEST_RUN(test_slow_loris);
  RSW_TEST_RUN(test_head);
  RSW_TEST_RUN(test_raw_path);
  RSW_TEST_RUN(test_many_query_params);
  RSW_TEST_RUN(test_idempotency_key_length);
  RSW_TEST_RUN(test_invalid_utf8_key);
  RSW_TEST_RUN(test_sse_resume_past_end);
  RSW_TEST_RUN(test_render_client_gone);
  RSW_TEST_RUN(test_render_client_gone_counted);
  RSW_TEST_RUN(test_nearly_full);
  RSW_TEST_RUN(test_header_deadline);
  RSW_TEST_RUN(test_sigterm_sync_render);
  if (main_ok) CHECK(tdaemon_stop(&main_d, 15, NULL) == 0, "main daemon exit 0");
  char cmd[128];
  snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
  if (system(cmd) != 0) fprintf(stdout, "  could not remove %s\n", tmpdir);
  RSW_TEST_END("test_http_limits");
}
