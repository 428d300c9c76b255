/* make bench: the daemon's overheads, one JSON line:
 *   {"bench": "http", "job_overhead_us_per_context", "sync_roundtrip_ms_p50",
 *    "sync_roundtrip_ms_p99", "cancel_latency_ms", ...}
 * Per-context overhead: a 1000-context job of a 1x1 `distant` film at 1 spp
 * through the daemon, against the same 1000 renders in process.
 * Round trip: synchronous 1x1 renders over loopback (keep-alive).
 * Cancel latency: from POST :cancel to the job reporting `cancelled`, on a
 * job of long renders. Deadline latency: from a long synchronous render
 * with timeout_s 0.05 to its 504. (Latencies live here; the tests assert
 * the order of events only.) Targets: <= 150 us per context, <= 1 ms per round
 * trip. */
#include <curl/curl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "../support/daemon.h"
#include "../../server/kernel/render.h"
#include "../../server/kernel/scene/scene.h"

static const char *SCENE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 1},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"component_format\": \"float32\"}},"
    " \"big\": {\"type\": \"hdistant\", \"film\": {\"type\": \"hdrfilm\", \"width\": 256, \"height\": 256}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1]},"
    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

typedef struct buf {
  char *p;
  size_t n;
} buf;

static size_t on_data(char *d, size_t sz, size_t nm, void *u) {
  buf *b = u;
  size_t n = sz * nm;
  char *p = realloc(b->p, b->n + n + 1);
  if (!p) return 0;
  memcpy(p + b->n, d, n);
  b->p = p;
  b->n += n;
  b->p[b->n] = '\0';
  return n;
}

static char base[64];

/* One request on a reused handle; returns the status, body in *out. */
static long request(CURL *c, const char *method, const char *path, const char *body, buf *out) {
  char url[512];
  snprintf(url, sizeof url, "%s%s", base, path);
  out->n = 0;
  if (out->p) out->p[0] = '\0';
  struct curl_slist *h = curl_slist_append(NULL, "Content-Type: application/json");
  curl_easy_setopt(c, CURLOPT_URL, url);
  if (body) {
    curl_easy_setopt(c, CURLOPT_POSTFIELDSIZE, (long)strlen(body));
    curl_easy_setopt(c, CURLOPT_POSTFIELDS, body);
    curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, method);
  } else {
    curl_easy_setopt(c, CURLOPT_POSTFIELDSIZE, -1L);
    curl_easy_setopt(c, CURLOPT_POSTFIELDS, NULL);
    curl_easy_setopt(c, CURLOPT_HTTPGET, 1L);
    curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, strcmp(method, "GET") ? method : NULL);
  }
  curl_easy_setopt(c, CURLOPT_HTTPHEADER, h);
  curl_easy_setopt(c, CURLOPT_WRITEFUNCTION, on_data);
  curl_easy_setopt(c, CURLOPT_WRITEDATA, out);
  long status = 0;
  if (curl_easy_perform(c) == CURLE_OK) curl_easy_getinfo(c, CURLINFO_RESPONSE_CODE, &status);
  curl_slist_free_all(h);
  return status;
}

static int cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return x < y ? -1 : x > y;
}

/* Poll a job until it leaves queued/running; returns seconds. */
static double wait_job(CURL *c, const char *job, const char *want, buf *b) {
  char path[128];
  snprintf(path, sizeof path, "/v1/jobs/%s", job);
  double t0 = now_s();
  for (int i = 0; i < 200000; i++) {
    if (request(c, "GET", path, NULL, b) != 200) {
      usleep(1000);
      continue;
    }
    if (b->p && !strstr(b->p, "\"state\":\"queued\"") && !strstr(b->p, "\"state\":\"running\"")) break;
    if (want && b->p && strstr(b->p, want)) break;
    usleep(200);
  }
  return now_s() - t0;
}

static bool json_string(const char *json, const char *key, char *out, size_t len) {
  char pat[64];
  snprintf(pat, sizeof pat, "\"%s\":\"", key);
  const char *p = json ? strstr(json, pat) : NULL;
  if (!p) return false;
  p += strlen(pat);
  size_t i = 0;
  while (*p && *p != '"' && i + 1 < len) out[i++] = *p++;
  out[i] = '\0';
  return true;
}

/* The same renders in process, for the per-context overhead. Run before
 * the daemon starts, so nothing else competes for the cores. */
static double in_process_seconds(int n_ctx) {
  rsw_err err = {0};
  scene *sc = NULL;
  scene_load_opts lo = {.size = sizeof lo};
  double s = 0;
  if (scene_load_memory(SCENE, strlen(SCENE), "bench", false, &lo, &sc, &err) == RSW_OK) {
    size_t si = 0;
    scene_find_sensor(sc, "meter", &si);
    double t0 = now_s();
    for (int i = 0; i < n_ctx; i++) {
      render_opts o = {
          .size = sizeof o, .sensor = si, .spp = 1, .seed = (uint64_t)i, .wavelength = 400 + i % 300};
      film_image img;
      if (render_sensor(sc, &o, &img, NULL, &err) == RSW_OK) film_image_free(&img);
    }
    s = now_s() - t0;
    scene_free(sc);
  }
  return s;
}

int main(void) {
  double inproc_s = in_process_seconds(1000);
  char dir[] = "/tmp/rsw-bench-XXXXXX";
  if (!mkdtemp(dir)) return 1;
  tdaemon d;
  const char *extra[] = {"--max-queue", "16", NULL};
  if (!tdaemon_start(&d, dir, "bench", extra, 5.0)) {
    fprintf(stderr, "bench http: the daemon did not start\n");
    rmdir(dir);
    return 1;
  }
  int port = d.port;
  snprintf(base, sizeof base, "http://127.0.0.1:%d", port);
  curl_global_init(CURL_GLOBAL_DEFAULT);
  CURL *c = curl_easy_init();
  buf b = {0};
  int rc = 0;
  long st = request(c, "POST", "/v1/scenes", SCENE, &b);
  char id[80] = "";
  if ((st != 201 && st != 200) || !json_string(b.p, "id", id, sizeof id)) {
    fprintf(stderr, "bench http: scene post failed (%ld): %s\n", st, b.p ? b.p : "");
    rc = 1;
    goto out;
  }
  char path[256];
  /* Synchronous round trips. */
  enum {
    N_SYNC = 400
  };
  double rt[N_SYNC];
  snprintf(path, sizeof path, "/v1/scenes/%s:render", id);
  for (int i = 0; i < 20; i++) request(c, "POST", path, "{\"sensor\": \"meter\", \"spp\": 1}", &b);
  for (int i = 0; i < N_SYNC; i++) {
    double t0 = now_s();
    st = request(c, "POST", path, "{\"sensor\": \"meter\", \"spp\": 1}", &b);
    rt[i] = (now_s() - t0) * 1e3;
    if (st != 200) {
      fprintf(stderr, "bench http: render failed (%ld): %s\n", st, b.p);
      rc = 1;
      goto out;
    }
  }
  qsort(rt, N_SYNC, sizeof *rt, cmp_double);
  /* A 1000-context job vs the same renders in process. */
  enum {
    N_CTX = 1000
  };
  size_t cap = 64 * N_CTX + 256, n = 0;
  char *job = malloc(cap);
  n += (size_t)snprintf(job + n, cap - n,
                        "{\"defaults\": {\"sensors\": [\"meter\"], \"spp\": 1}, \"contexts\": [");
  for (int i = 0; i < N_CTX; i++)
    n += (size_t)snprintf(job + n, cap - n, "%s{\"id\": \"c%d\", \"wavelength\": %d}", i ? ", " : "", i,
                          400 + i % 300);
  snprintf(job + n, cap - n, "]}");
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", id);
  double t0 = now_s();
  st = request(c, "POST", path, job, &b);
  char jid[64] = "";
  if (st != 202 || !json_string(b.p, "id", jid, sizeof jid)) {
    fprintf(stderr, "bench http: job submit failed (%ld): %s\n", st, b.p);
    rc = 1;
    free(job);
    goto out;
  }
  wait_job(c, jid, NULL, &b);
  double daemon_s = now_s() - t0;
  free(job);
  /* Cancel latency: a job of long renders. */
  char big[512];
  snprintf(big, sizeof big,
           "{\"defaults\": {\"sensors\": [\"big\"], \"spp\": 4096}, \"contexts\": [{\"id\": \"a\"}, {\"id\": "
           "\"b\"}]}");
  st = request(c, "POST", path, big, &b);
  char cid[64] = "";
  double cancel_ms = -1;
  if (st == 202 && json_string(b.p, "id", cid, sizeof cid)) {
    char jp[128];
    snprintf(jp, sizeof jp, "/v1/jobs/%s", cid);
    for (int i = 0; i < 2000; i++) { /* wait until it runs */
      request(c, "GET", jp, NULL, &b);
      if (b.p && strstr(b.p, "\"state\":\"running\"")) break;
      usleep(1000);
    }
    usleep(100000);
    char cp[128];
    snprintf(cp, sizeof cp, "/v1/jobs/%s:cancel", cid);
    t0 = now_s();
    request(c, "POST", cp, "", &b);
    wait_job(c, cid, "\"state\":\"cancelled\"", &b);
    cancel_ms = (now_s() - t0) * 1e3;
  }
  /* Deadline latency: the long render stops at timeout_s (504). */
  double deadline_ms = -1;
  {
    char rp[256];
    snprintf(rp, sizeof rp, "/v1/scenes/%s:render", id);
    t0 = now_s();
    long rs = request(c, "POST", rp, "{\"sensor\": \"big\", \"spp\": 4096, \"timeout_s\": 0.05}", &b);
    if (rs == 504) deadline_ms = (now_s() - t0) * 1e3;
  }
  double per_ctx_us = (daemon_s - inproc_s) / N_CTX * 1e6;
  printf(
      "{\"bench\": \"http\", \"job_overhead_us_per_context\": %.1f, \"job_s\": %.4f, \"in_process_s\": %.4f, "
      "\"sync_roundtrip_ms_p50\": %.3f, \"sync_roundtrip_ms_p99\": %.3f, \"cancel_latency_ms\": %.1f, "
      "\"deadline_latency_ms\": %.1f, "
      "\"contexts\": %d, \"target_us_per_context\": 150, \"target_roundtrip_ms\": 1, \"meets_target\": %s}\n",
      per_ctx_us, daemon_s, inproc_s, rt[N_SYNC / 2], rt[(N_SYNC * 99) / 100], cancel_ms, deadline_ms, N_CTX,
      per_ctx_us <= 150 && rt[N_SYNC / 2] <= 1.0 ? "true" : "false");
out:
  free(b.p);
  curl_easy_cleanup(c);
  curl_global_cleanup();
  tdaemon_stop(&d, 30.0, NULL);
  char file[300];
  snprintf(file, sizeof file, "%s/bench.log", dir);
  remove(file);
  snprintf(file, sizeof file, "%s/bench.port", dir);
  remove(file);
  rmdir(dir);
  return rc;
}
