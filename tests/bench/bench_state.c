/* make bench: the daemon's restart with a state directory, one JSON line:
 *   {"bench": "state", "restart_s", "restart_s_empty", "restore_s", "results", "reps",
 *    "job_us_per_context"}
 * restart_s: from exec of `raysweepd serve --state-dir DIR` to
 * /v1/health/ready answering 200, with DIR holding one finished job of
 * 1,000 contexts (1x1 film, 1 spp: 1,000 finished results, their films on
 * disk), median of 5 starts; restart_s_empty the same with an empty state
 * directory (the process's own start: loading the default scene, binding);
 * restore_s the daemon's own figure for reading the state directory
 * (raysweep_restore_seconds). Each start also fetches one result, so a
 * restart that lost them fails the bench. job_us_per_context: the
 * 1,000-context job's wall time per context with the state directory
 * (each film written and fdatasync'ed before it counts). */
#include "bench.h"
#include <curl/curl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static const char *SCENE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 1},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"component_format\": \"float32\"}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1]},"
    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";

#define N_CONTEXTS 1000
#define REPS       5

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

static int port;

static long request(CURL *c, const char *method, const char *path, const char *body, buf *out) {
  char url[512];
  snprintf(url, sizeof url, "http://127.0.0.1:%d%s", port, path);
  out->n = 0;
  if (out->p) out->p[0] = '\0';
  struct curl_slist *h = curl_slist_append(NULL, "Content-Type: application/json");
  curl_easy_reset(c);
  curl_easy_setopt(c, CURLOPT_URL, url);
  if (body) {
    curl_easy_setopt(c, CURLOPT_POSTFIELDSIZE, (long)strlen(body));
    curl_easy_setopt(c, CURLOPT_POSTFIELDS, body);
  }
  curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, method);
  curl_easy_setopt(c, CURLOPT_HTTPHEADER, h);
  curl_easy_setopt(c, CURLOPT_WRITEFUNCTION, on_data);
  curl_easy_setopt(c, CURLOPT_WRITEDATA, out);
  long status = 0;
  if (curl_easy_perform(c) == CURLE_OK) curl_easy_getinfo(c, CURLINFO_RESPONSE_CODE, &status);
  curl_slist_free_all(h);
  return status;
}

static pid_t start(const char *state_dir, const char *portfile) {
  const char *bd = getenv("RSW_BIN_DIR");
  char exe[512];
  snprintf(exe, sizeof exe, "%s/raysweepd", bd && *bd ? bd : "build/bin");
  remove(portfile);
  pid_t pid = fork();
  if (pid == 0) {
    if (!freopen("/dev/null", "w", stderr)) _exit(127);
    execl(exe, exe, "serve", "--listen", "127.0.0.1:0", "--port-file", portfile, "--state-dir", state_dir,
          (char *)NULL);
    _exit(127);
  }
  return pid;
}

/* Wait for the port file, then for ready; seconds since t0, or -1. */
static double wait_ready(CURL *c, const char *portfile, double t0) {
  port = 0;
  buf b = {0};
  for (int i = 0; i < 20000; i++) {
    if (!port) {
      FILE *f = fopen(portfile, "r");
      if (f) {
        if (fscanf(f, "%d", &port) != 1) port = 0;
        fclose(f);
      }
    }
    if (port && request(c, "GET", "/v1/health/ready", NULL, &b) == 200) {
      free(b.p);
      return bench_wall_s() - t0;
    }
    usleep(500);
  }
  free(b.p);
  return -1;
}

static void stop(pid_t pid) {
  kill(pid, SIGTERM);
  waitpid(pid, NULL, 0);
}

int main(void) {
  curl_global_init(CURL_GLOBAL_DEFAULT);
  CURL *c = curl_easy_init();
  char dir[] = "/tmp/rsw-bench-state-XXXXXX", empty[] = "/tmp/rsw-bench-state0-XXXXXX";
  char portfile[128];
  if (!mkdtemp(dir) || !mkdtemp(empty)) return 1;
  snprintf(portfile, sizeof portfile, "%s.port", dir);
  buf b = {0};
  /* Fill the state directory: one job of 1,000 contexts. */
  pid_t pid = start(dir, portfile);
  if (wait_ready(c, portfile, bench_wall_s()) < 0) {
    fprintf(stderr, "bench_state: the daemon did not start\n");
    return 1;
  }
  if (request(c, "POST", "/v1/scenes", SCENE, &b) / 100 != 2) return 1;
  char id[65] = "";
  const char *p = strstr(b.p, "\"id\":\"");
  if (p) snprintf(id, sizeof id, "%.64s", p + 6);
  size_t cap = (size_t)N_CONTEXTS * 40 + 64;
  char *body = malloc(cap);
  size_t n = (size_t)snprintf(body, cap, "{\"contexts\":[");
  for (int i = 0; i < N_CONTEXTS; i++)
    n += (size_t)snprintf(body + n, cap - n, "%s{\"id\":\"c%d\",\"wavelength\":%d}", i ? "," : "", i,
                          400 + i % 500);
  snprintf(body + n, cap - n, "]}");
  char path[256];
  snprintf(path, sizeof path, "/v1/scenes/%s/jobs", id);
  double t_submit = bench_wall_s();
  if (request(c, "POST", path, body, &b) != 202) {
    fprintf(stderr, "bench_state: job refused: %s\n", b.p);
    return 1;
  }
  free(body);
  char job[64] = "";
  p = strstr(b.p, "\"id\":\"");
  if (p) sscanf(p + 6, "%63[^\"]", job);
  snprintf(path, sizeof path, "/v1/jobs/%s", job);
  for (int i = 0; i < 60000; i++) {
    request(c, "GET", path, NULL, &b);
    if (strstr(b.p, "\"state\":\"succeeded\"")) break;
    usleep(2000);
  }
  if (!strstr(b.p, "\"state\":\"succeeded\"")) {
    fprintf(stderr, "bench_state: the job did not finish: %s\n", b.p);
    return 1;
  }
  double job_us = (bench_wall_s() - t_submit) / N_CONTEXTS * 1e6;
  stop(pid);
  double t[REPS], t0s[REPS], restore = 0;
  for (int r = 0; r < REPS; r++) {
    double t0 = bench_wall_s();
    pid = start(dir, portfile);
    t[r] = wait_ready(c, portfile, t0);
    snprintf(path, sizeof path, "/v1/jobs/%s/results/c%d/meter", job, N_CONTEXTS - 1);
    long st = request(c, "GET", path, NULL, &b);
    request(c, "GET", "/metrics", NULL, &b);
    const char *m = b.p ? strstr(b.p, "\nraysweep_restore_seconds ") : NULL;
    if (m) restore = atof(m + 26);
    stop(pid);
    if (t[r] < 0 || st != 200) {
      fprintf(stderr, "bench_state: restart %d: ready %.3f s, result %ld\n", r, t[r], st);
      return 1;
    }
    t0 = bench_wall_s();
    pid = start(empty, portfile);
    t0s[r] = wait_ready(c, portfile, t0);
    stop(pid);
  }
  printf("{\"bench\": \"state\", \"restart_s\": %.4f, \"restart_s_empty\": %.4f, \"restore_s\": %.4f, "
         "\"results\": %d, \"reps\": %d, \"job_us_per_context\": %.0f}\n",
         bench_median(t, REPS), bench_median(t0s, REPS), restore, N_CONTEXTS, REPS, job_us);
  free(b.p);
  char cmd[256];
  snprintf(cmd, sizeof cmd, "rm -rf '%s' '%s' '%s'", dir, empty, portfile);
  if (system(cmd) != 0) return 1;
  curl_easy_cleanup(c);
  curl_global_cleanup();
  return 0;
}
