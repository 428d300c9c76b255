/* Allocation-failure testing (issue 13), as curl's and redis's suites do:
 * every operation below runs once with allocation n failing, for
 * n = 1, 2, 3, ... until a run completes without reaching allocation n
 * (tests/support/failmalloc.c: a malloc hook linked into this binary,
 * armed only around the operation). Every run must end either in a clean
 * error (a non-OK status with a message, state left as it was) or, when
 * the failure was absorbed on the way (a retry, an optional cache), in the
 * exact result of the run without a failure; never a crash, an abort, a
 * hang (each run has a 30 s alarm) or, in the SAN build, an invalid
 * access.
 *
 * Sampling (run time): every n up to FULL_N, then every STRIDE-th; the
 * figures printed for each operation say how many allocations it makes
 * and how many runs were made.
 *
 * The daemon (service and HTTP server in this process) is driven through
 * libraysweep (scene push with mesh blobs, PATCH, render with an override,
 * a two-context job followed over server-sent events, a film saved as
 * EXR by the client) and through libcurl (a render answered as
 * image/x-exr: the in-memory EXR encoder).
 *
 * Kernel operations: scene load from JSON (with an OBJ and a PLY mesh file) and
 * from XML; a parameter update (a spectrum, a mesh's transform, a
 * direction, a mesh's vertex positions: Embree instance update and refit);
 * a render on 2 threads; the film's EXR written to a file and encoded in
 * memory (a distant sensor's film, with its per-pixel angle metadata).
 *
 * Debugging: OOM_ONLY=name,name runs those operations alone; OOM_SIDE=
 * client|server fails only the test thread's allocations or only the
 * daemon threads'; FAILMALLOC_JITTER_US=N makes one allocation in 4 sleep
 * up to N us first (other interleavings of the threads). A run that hangs
 * prints where the failed allocation was. */
#include <curl/curl.h>
#include <dlfcn.h>
#include <errno.h>
#include <sched.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "../support/failmalloc.h"
#include "../support/test.h"
#include "film_io.h"
#include "http/http.h"
#include "image_exr.h"
#include "kernel/accel.h"
#include "kernel/render.h"
#include "kernel/scene/params.h"
#include "kernel/scene/scene.h"
#include "kernel/scene/update.h"
#include "raysweep/client.h"
#include "service/service.h"

RSW_TEST_DEFINE_GLOBALS

/* Every allocation up to FULL_N is failed in turn, then every STRIDE-th. */
#define FULL_N      3000
#define STRIDE      7
#define RUN_LIMIT_S 30
/* A run that takes longer than this is a hang cut short by a client
 * timeout (normal runs take milliseconds). */
#define SLOW_S      5.0

static char tmpdir[256];
static char data_dir[512];

/* ---- what a crash or a hang names ------------------------------------------------------ */

static volatile sig_atomic_t cur_n;
static const char *volatile cur_op = "";

static void put(const char *s) {
  ssize_t w = write(2, s, strlen(s));
  (void)w;
}

static void on_fatal(int sig) {
  char num[24];
  int k = 0;
  long n = cur_n;
  char d[24];
  do d[k++] = (char)('0' + n % 10), n /= 10;
  while (n);
  int j = 0;
  while (k) num[j++] = d[--k];
  num[j] = '\0';
  put("\ntest_oom: ");
  put(sig == SIGALRM ? "HANG (30 s)" : "CRASH");
  put(" in operation ");
  put((const char *)cur_op);
  put(" with allocation ");
  put(num);
  put(" failing\n");
  signal(sig, SIG_DFL);
  signal(SIGABRT, SIG_DFL);
  raise(sig == SIGALRM ? SIGABRT : sig);
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- the scenes ------------------------------------------------------------------------- */

#define JSON_SCENE                                                                                           \
  "{\"type\": \"scene\", \"variant\": \"mono\","                                                             \
  " \"meter\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\"},"                              \
  "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"                                        \
  "   \"film\": {\"type\": \"hdrfilm\", \"width\": 6, \"height\": 5, \"rfilter\": {\"type\": \"box\"}}},"    \
  " \"integrator\": {\"type\": \"path\", \"max_depth\": 3},"                                                 \
  " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0.1, -0.866],"                                 \
  "   \"irradiance\": {\"type\": \"spectrum\", \"wavelengths\": [400, 500, 600, 700],"                       \
  "                    \"values\": [1.6, 1.9, 1.8, 1.4]}},"                                                  \
  " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"                          \
  "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": {\"type\": \"spectrum\","                           \
  "              \"value\": [[400, 0.05], [550, 0.1], [700, 0.45]]}}},"                                      \
  " \"quad\": {\"type\": \"obj\", \"filename\": \"quad.obj\", \"to_world\": [{\"translate\": [0, 0, 0.5]}]," \
  "   \"bsdf\": {\"type\": \"roughconductor\"}},"                                                            \
  " \"tri\": {\"type\": \"ply\", \"filename\": \"quad_le.ply\","                                             \
  "   \"to_world\": [{\"translate\": [1, 1, 0.2]}, {\"scale\": 0.5}]},"                                      \
  " \"ball\": {\"type\": \"sphere\", \"center\": [0, 0, 1], \"radius\": 0.3,"                                \
  "   \"bsdf\": {\"type\": \"dielectric\"}}}"

static const char *XML_SCENE =
    "<scene version=\"3.0.0\">\n"
    "  <default name=\"spp\" value=\"4\"/>\n"
    "  <sensor type=\"hdistant\" id=\"meter\">\n"
    "    <sampler type=\"independent\"><integer name=\"sample_count\" value=\"$spp\"/></sampler>\n"
    "    <film type=\"hdrfilm\"><integer name=\"width\" value=\"3\"/><integer name=\"height\" value=\"2\"/>\n"
    "      <rfilter type=\"box\"/></film>\n"
    "  </sensor>\n"
    "  <integrator type=\"path\"><integer name=\"max_depth\" value=\"2\"/></integrator>\n"
    "  <emitter type=\"directional\"><vector name=\"direction\" x=\"1\" y=\"0\" z=\"-1\"/>\n"
    "    <rgb name=\"irradiance\" value=\"1, 0.5, 0.25\"/></emitter>\n"
    "  <shape type=\"rectangle\" id=\"plate\">\n"
    "    <transform name=\"to_world\"><scale value=\"5\"/></transform>\n"
    "    <bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.2, 0.3, 0.4\"/></bsdf>\n"
    "  </shape>\n"
    "  <shape type=\"obj\" id=\"quad\"><string name=\"filename\" value=\"quad.obj\"/>\n"
    "    <transform name=\"to_world\"><translate z=\"0.5\"/></transform></shape>\n"
    "</scene>\n";

static scene *load(const char *text, bool xml, rsw_err *err) {
  scene_load_opts o = {.size = sizeof o, .base_dir = data_dir};
  scene *s = NULL;
  if (scene_load_memory(text, strlen(text), xml ? "oom.xml" : "oom.json", xml, &o, &s, err) != RSW_OK)
    return NULL;
  return s;
}

/* Runs in which Embree ran out of memory, over all operations (main
 * checks that some did), and whether a stuck Embree was played once. */
static long embree_oom_runs;
static bool stuck_played;
static unsigned long long ooms_seen; /* Embree's failures counted so far */
static char d_url[64];
static service *d_svc;

/* A probe build that does not finish within the probe's 3 s: what a lock
 * left held by a failure inside Embree's build tasks does. */
static _Atomic int stalled_policy = -1; /* the stalled probe's, as it ends */

static void probe_stalls(void) {
  sleep(4);
  atomic_store(&stalled_policy, sched_getscheduler(0));
}

static void check_embree_stuck(const char *op, long n);

/* Disarmed, after a run in which Embree ran out of memory. */
static void check_embree_oom(const char *op, long n) {
  embree_oom_runs++;
  char *m = d_svc ? service_metrics_text(d_svc) : NULL;
  const char *g = m ? strstr(m, "\nraysweep_embree_out_of_memory_total ") : NULL;
  CHECK(!d_svc || (g && atoll(g + 37) > 0),
        "%s: allocation %ld: Embree ran out of memory, but /metrics says %.60s", op, n,
        g ? g + 1 : "nothing");
  free(m);
  /* Once, with the daemon up: a probe that stalls. Then loads are refused
   * (RSW_ERR_UNAVAILABLE, saying why) instead of waiting forever, the
   * daemon is not ready, scene posts answer 503, and /metrics says when. */
  if (!stuck_played && d_url[0]) {
    stuck_played = true;
    check_embree_stuck(op, n);
    return;
  }
  /* The failure was outside Embree's build tasks (failmalloc leaves those
   * alone): no lock is held, the probe's build finishes, and a load builds
   * as before. */
  rsw_err err = {0};
  scene *s = load(JSON_SCENE, false, &err);
  CHECK(s && !accel_embree_stuck(NULL, NULL, false),
        "%s: allocation %ld: Embree ran out of memory, then a load: %s", op, n, s ? "stuck" : err.msg);
  scene_free(s);
}

static void check_embree_stuck(const char *op, long n) {
  char *m;
  const char *g;
  scene *s;
  accel_set_probe_hook(probe_stalls);
  rsw_err e2 = {0};
  s = load(JSON_SCENE, false, &e2);
  CHECK(!s && e2.code == RSW_ERR_UNAVAILABLE && strstr(e2.msg, "Embree cannot build any more"),
        "%s: allocation %ld, a probe that stalls, then a load: %s (code %d)", op, n, s ? "built" : e2.msg,
        (int)e2.code);
  scene_free(s);
  m = service_metrics_text(d_svc);
  g = m ? strstr(m, "\nraysweep_embree_stuck_since ") : NULL;
  CHECK(g && atoll(g + 29) > 0, "%s: Embree stuck, /metrics says %.60s", op, g ? g + 1 : "nothing");
  free(m);
  rsw_client_opts o = {.size = sizeof o, .base_url = d_url, .timeout_s = 10, .max_retries = -1};
  rsw_client *c = NULL;
  REQUIRE(rsw_client_new(&o, &c) == RSW_OK, "a client");
  rsw_status st = rsw_server_ready(c);
  const rsw_error_info *ei = rsw_client_last_error(c);
  CHECK(st != RSW_OK && ei->http_status == 503 && strstr(ei->message, "Embree cannot build any more"),
        "%s: Embree stuck, then /v1/health/ready: HTTP %d %s", op, ei->http_status, ei->message);
  /* A new scene (no mesh: nothing to upload first) */
  static const char *plate = "{\"type\": \"scene\", \"p\": {\"type\": \"rectangle\"}, \"s\": "
                             "{\"type\": \"perspective\"}, \"oom_check\": {\"type\": \"constant\"}}";
  char id[65] = "";
  int created = 0;
  st = rsw_scene_push_buffer(c, plate, strlen(plate), data_dir, NULL, id, &created);
  ei = rsw_client_last_error(c);
  CHECK(st != RSW_OK && ei->http_status == 503 && strstr(ei->message, "Embree cannot build any more"),
        "%s: Embree stuck, then POST /v1/scenes: HTTP %d %s", op, ei->http_status, ei->message);
  /* The stalled probe's thread was demoted: stuck on a spin lock, it
   * would take only the cores nothing else wants. */
  for (int i = 0; i < 300 && atomic_load(&stalled_policy) < 0; i++) usleep(10000);
  CHECK(atomic_load(&stalled_policy) == SCHED_IDLE,
        "%s: the stalled probe's thread runs under policy %d, not SCHED_IDLE", op,
        atomic_load(&stalled_policy));
  accel_set_probe_hook(NULL);
  accel_clear_embree_stuck();
  CHECK(rsw_server_ready(c) == RSW_OK, "%s: ready again once the test forgot it", op);
  rsw_client_free(c);
  printf("    (a stalled probe, after allocation %ld of %s: loads refused, the daemon not ready)\n", n, op);
}

static rsw_status render(scene *s, film_image *out, rsw_err *err) {
  render_opts o = {.size = sizeof o, .spp = 4, .seed = 7, .threads = 2, .wavelength = 550};
  return render_sensor(s, &o, out, NULL, err);
}

static bool same_film(const film_image *a, const film_image *b) {
  return a->data && b->data && a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, sizeof(float) * (size_t)a->width * a->height * a->channels) == 0;
}

/* ---- the sweep ----------------------------------------------------------------------------- */

/* One operation: setup and teardown run disarmed, run() armed. After a
 * failed run, failed_ok() checks that the state is as before (NULL: no
 * check); after an OK run that absorbed the failure, same() checks the
 * result is the one of a clean run. */
typedef struct oom_op {
  const char *name;
  void *(*setup)(void);
  rsw_status (*run)(void *st, rsw_err *err);
  bool (*failed_ok)(void *st);
  bool (*same)(void *st);
  void (*teardown)(void *st);
  /* The API returns a status only (rsw_film_save_exr: no client to carry
   * a message): a non-OK status is the whole clean error. */
  bool status_only;
  /* Optional: called after the clean run, to keep its result as the
   * reference (one that depends on the daemon's state, e.g. a revision). */
  void (*capture)(void *st);
  /* Failures inside Embree move to the next allocation (Embree 3.13 does
   * not survive one in a re-commit: failmalloc_skip_embree). */
  bool skip_embree;
} oom_op;

/* Where the allocation made to fail was (a run that hung says nothing
 * else): its stack as failmalloc took it, then the frames in this
 * executable as functions and lines (addr2line, from binutils, when it is
 * there). */
static void print_failure_place(void) {
  fflush(stdout);
  failmalloc_print_failure(STDOUT_FILENO);
  void *st[48];
  int n = failmalloc_failure_stack(st, 48);
  Dl_info self;
  if (n <= 0 || !dladdr((void *)print_failure_place, &self) || !self.dli_fbase) return;
  char cmd[2048];
  int len = snprintf(cmd, sizeof cmd, "addr2line -f -i -p -e /proc/%ld/exe", (long)getpid());
  int any = 0;
  for (int i = 0; i < n && len < (int)sizeof cmd - 24; i++) {
    Dl_info di;
    if (dladdr(st[i], &di) && di.dli_fbase == self.dli_fbase) {
      /* (a return address: the call is the byte before it) */
      len += snprintf(cmd + len, sizeof cmd - (size_t)len, " %#lx",
                      (unsigned long)((char *)st[i] - (char *)self.dli_fbase - 1));
      any = 1;
    }
  }
  if (!any) return;
  snprintf(cmd + len, sizeof cmd - (size_t)len, " 2>/dev/null | sed 's/^/    /'");
  printf("  its frames in %s:\n", self.dli_fname);
  fflush(stdout);
  if (system(cmd) != 0) printf("    (addr2line failed)\n");
}

static void sweep(const oom_op *op) {
  /* OOM_SIDE=client|server: only the allocations of the test's own
   * thread (the client library, libcurl), or only the others' (the
   * daemon's threads): each side's in an order that the other's timing
   * does not shift (debugging a failure seen once under load). */
  const char *side = getenv("OOM_SIDE");
  failmalloc_side(side && strcmp(side, "client") == 0 ? 1 : side && strcmp(side, "server") == 0 ? 2 : 0);
  /* OOM_ONLY=name,name: only those operations (debugging). */
  const char *only = getenv("OOM_ONLY");
  if (only && *only) {
    size_t len = strlen(op->name);
    const char *p = only;
    while ((p = strstr(p, op->name)) && ((p != only && p[-1] != ',') || (p[len] && p[len] != ','))) p += len;
    if (!p) return;
  }
  cur_op = op->name;
  cur_n = 0;
  /* A clean run: the allocation count. */
  void *st = op->setup();
  REQUIRE(st, "%s: setup", op->name);
  rsw_err err = {0};
  failmalloc_arm(0);
  rsw_status s = op->run(st, &err);
  long total = failmalloc_disarm();
  if (s == RSW_OK && op->capture) op->capture(st);
  op->teardown(st);
  char buf[1100];
  REQUIRE(s == RSW_OK, "%s: clean run: %s", op->name, rsw_err_format(&err, buf, sizeof buf));

  long runs = 0, errors = 0, absorbed = 0, bad = 0, embree_oom = 0;
  failmalloc_skip_embree(op->skip_embree);
  for (long n = 1;; n = n < FULL_N ? n + 1 : n + STRIDE) {
    cur_n = n;
    st = op->setup();
    REQUIRE(st, "%s: setup for n = %ld", op->name, n);
    rsw_err_clear(&err);
    alarm(RUN_LIMIT_S);
    double t0 = now_s();
    failmalloc_arm(n);
    s = op->run(st, &err);
    failmalloc_disarm();
    double secs = now_s() - t0;
    alarm(0);
    if (secs > SLOW_S) { /* e.g. a request that timed out on a hung server thread */
      op->teardown(st);
      CHECK(false, "%s: allocation %ld failing: the call took %.1f s (a hang cut short by a timeout)",
            op->name, n, secs);
      print_failure_place();
      break;
    }
    bool injected = failmalloc_failed() > 0;
    /* Embree reported running out of memory (check_embree_oom). */
    unsigned long long ooms;
    (void)accel_embree_stuck(NULL, &ooms, false);
    if (ooms > ooms_seen) {
      ooms_seen = ooms;
      embree_oom++;
      check_embree_oom(op->name, n);
    }
    if (!injected) { /* ran to completion before allocation n */
      op->teardown(st);
      CHECK(s == RSW_OK, "%s: n = %ld, no failure injected but: %s", op->name, n,
            rsw_err_format(&err, buf, sizeof buf));
      break;
    }
    runs++;
    if (s != RSW_OK) {
      errors++;
      if (!op->status_only && (!err.msg[0] || err.code != s)) {
        bad++;
        CHECK(false, "%s: allocation %ld failing: status %d without a message (code %d)", op->name, n, (int)s,
              (int)err.code);
      } else if (op->failed_ok && !op->failed_ok(st)) {
        bad++;
        CHECK(false, "%s: allocation %ld failing: state changed by the failed call (%s)", op->name, n,
              rsw_err_format(&err, buf, sizeof buf));
      }
    } else {
      absorbed++;
      if (op->same && !op->same(st)) {
        bad++;
        CHECK(false, "%s: allocation %ld failing: reported success with a different result", op->name, n);
      }
    }
    op->teardown(st);
    if (bad > 5) {
      CHECK(false, "%s: stopping after 5 bad runs", op->name);
      break;
    }
  }
  failmalloc_skip_embree(false);
  printf(
      "    %-14s %6ld allocations (clean run); %ld runs (each of 1..%d, then every %d-th): %ld clean errors, "
      "%ld absorbed (result identical); Embree out of memory in %ld\n",
      op->name, total, runs, FULL_N, STRIDE, errors, absorbed, embree_oom);
}

/* ---- kernel operations ------------------------------------------------------------------ */

typedef struct kstate {
  scene *s;
  film_image film;
  void *bytes;
  size_t len;
  char path[600];
} kstate;

static film_image ref_json, ref_json_updated, ref_xml;
static void *ref_exr;
static size_t ref_exr_len;

static void *setup_empty(void) {
  return calloc(1, sizeof(kstate));
}

static void teardown(void *p) {
  kstate *k = p;
  scene_free(k->s);
  film_image_free(&k->film);
  free(k->bytes);
  if (k->path[0]) unlink(k->path);
  free(k);
}

static rsw_status run_load_json(void *p, rsw_err *err) {
  kstate *k = p;
  k->s = load(JSON_SCENE, false, err);
  return k->s ? RSW_OK : err->code;
}

static rsw_status run_load_xml(void *p, rsw_err *err) {
  kstate *k = p;
  k->s = load(XML_SCENE, true, err);
  return k->s ? RSW_OK : err->code;
}

/* An absorbed failure must still load the same scene: it renders the
 * same film. */
static bool same_json_render(void *p) {
  kstate *k = p;
  rsw_err err = {0};
  film_image f = {0};
  bool ok = k->s && render(k->s, &f, &err) == RSW_OK && same_film(&f, &ref_json);
  film_image_free(&f);
  return ok;
}

static bool same_xml_render(void *p) {
  kstate *k = p;
  rsw_err err = {0};
  film_image f = {0};
  bool ok = k->s && render(k->s, &f, &err) == RSW_OK && same_film(&f, &ref_xml);
  film_image_free(&f);
  return ok;
}

static void *setup_scene(void) {
  kstate *k = calloc(1, sizeof *k);
  rsw_err err = {0};
  if (k) k->s = load(JSON_SCENE, false, &err);
  if (!k || !k->s) {
    free(k);
    return NULL;
  }
  return k;
}

/* Three entries of three update classes: spectral (a reflectance),
 * geometric (a mesh's transform: an Embree instance update) and the
 * sun's direction. */
static rsw_status run_update(void *p, rsw_err *err) {
  kstate *k = p;
  static const char *keys[] = {"plate.bsdf.reflectance.value", "quad.to_world", "sun.direction",
                               "tri.vertex_positions"};
  static const char *vals[] = {"0.3", "[1,0,0,0.1, 0,1,0,0, 0,0,1,0.6, 0,0,0,1]", "[0.3, 0, -1]",
                               "[-1,-1,0, 1,-1,0.1, 1,1,0, -1,1,0.2]"};
  enum {
    N_UPD = sizeof keys / sizeof *keys
  };
  param_update items[N_UPD];
  size_t n = 0;
  rsw_status s = RSW_OK;
  for (; n < N_UPD; n++) {
    items[n].key = keys[n];
    s = param_value_parse(vals[n], keys[n], &items[n].value, err);
    if (s != RSW_OK) break;
  }
  if (s == RSW_OK) s = scene_update(k->s, items, N_UPD, NULL, err);
  for (size_t i = 0; i < n; i++) param_value_free(&items[i].value);
  return s;
}

/* A failed update changes nothing: the scene renders as before. */
static bool update_left_scene_alone(void *p) {
  kstate *k = p;
  rsw_err err = {0};
  film_image f = {0};
  bool ok = render(k->s, &f, &err) == RSW_OK && same_film(&f, &ref_json);
  film_image_free(&f);
  return ok;
}

static bool update_applied(void *p) {
  kstate *k = p;
  rsw_err err = {0};
  film_image f = {0};
  bool ok = render(k->s, &f, &err) == RSW_OK && same_film(&f, &ref_json_updated);
  film_image_free(&f);
  return ok;
}

static rsw_status run_render(void *p, rsw_err *err) {
  kstate *k = p;
  return render(k->s, &k->film, err);
}

static bool render_same(void *p) {
  kstate *k = p;
  return same_film(&k->film, &ref_json);
}

/* A failed render leaves the scene usable. */
static bool render_failed_ok(void *p) {
  return update_left_scene_alone(p);
}

static void *setup_film(void) {
  kstate *k = setup_scene();
  rsw_err err = {0};
  if (k && render(k->s, &k->film, &err) != RSW_OK) {
    teardown(k);
    return NULL;
  }
  if (k) snprintf(k->path, sizeof k->path, "%s/film.exr", tmpdir);
  return k;
}

static rsw_status run_exr_file(void *p, rsw_err *err) {
  kstate *k = p;
  return film_image_write_exr(&k->film, k->path, "meter", err);
}

static bool slurp(const char *path, void **bytes, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return false;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  *bytes = malloc(n > 0 ? (size_t)n : 1);
  *len = *bytes && n >= 0 && fread(*bytes, 1, (size_t)n, f) == (size_t)n ? (size_t)n : 0;
  fclose(f);
  return *len > 0;
}

/* No file (and no temp file) after a failed write. */
static bool exr_file_absent(void *p) {
  kstate *k = p;
  struct stat sb;
  char tmp[700];
  snprintf(tmp, sizeof tmp, "%s.tmp.%ld", k->path, (long)getpid());
  return stat(k->path, &sb) != 0 && stat(tmp, &sb) != 0;
}

static bool exr_file_same(void *p) {
  kstate *k = p;
  void *b = NULL;
  size_t n = 0;
  bool ok = slurp(k->path, &b, &n) && n == ref_exr_len && memcmp(b, ref_exr, n) == 0;
  free(b);
  return ok;
}

static rsw_status run_exr_mem(void *p, rsw_err *err) {
  kstate *k = p;
  film_exr_info info = film_image_exr_info(&k->film, "meter");
  return film_exr_encode(k->film.width, k->film.height, k->film.channels, k->film.channel_names, k->film.data,
                         k->film.half, &info, &k->bytes, &k->len, err);
}

static bool exr_mem_same(void *p) {
  kstate *k = p;
  return k->bytes && k->len == ref_exr_len && memcmp(k->bytes, ref_exr, k->len) == 0;
}

static bool make_references(void) {
  rsw_err err = {0};
  char buf[1100];
  scene *s = load(JSON_SCENE, false, &err);
  if (!s || render(s, &ref_json, &err) != RSW_OK) goto fail;
  kstate k = {.s = s};
  if (run_update(&k, &err) != RSW_OK || render(s, &ref_json_updated, &err) != RSW_OK) goto fail;
  scene_free(s);
  s = load(XML_SCENE, true, &err);
  if (!s || render(s, &ref_xml, &err) != RSW_OK) goto fail;
  scene_free(s);
  film_exr_info info = film_image_exr_info(&ref_json, "meter");
  if (film_exr_encode(ref_json.width, ref_json.height, ref_json.channels, ref_json.channel_names,
                      ref_json.data, ref_json.half, &info, &ref_exr, &ref_exr_len, &err) != RSW_OK)
    goto fail;
  if (!ref_json.angles) {
    printf("  the JSON scene's film has no per-pixel angles\n");
    return false;
  }
  return true;
fail:
  printf("  references: %s\n", rsw_err_format(&err, buf, sizeof buf));
  scene_free(s);
  return false;
}

static void test_kernel_load(void) {
  static const oom_op json = {"load_json", setup_empty, run_load_json, NULL, same_json_render,
                              teardown,    false,       NULL,          false};
  static const oom_op xml = {"load_xml", setup_empty, run_load_xml, NULL, same_xml_render,
                             teardown,   false,       NULL,         false};
  sweep(&json);
  sweep(&xml);
}

static void test_kernel_update(void) {
  static const oom_op op = {"update",       setup_scene, run_update, update_left_scene_alone,
                            update_applied, teardown,    false,      NULL,
                            false};
  sweep(&op);
}

static void test_kernel_render(void) {
  static const oom_op op = {"render", setup_scene, run_render, render_failed_ok, render_same, teardown,
                            false,    NULL,        false};
  sweep(&op);
}

static void test_exr_encode(void) {
  static const oom_op file = {"exr_file", setup_film, run_exr_file, exr_file_absent, exr_file_same, teardown,
                              false,      NULL,       false};
  static const oom_op mem = {"exr_memory", setup_film, run_exr_mem, NULL, exr_mem_same,
                             teardown,     false,      NULL,        false};
  sweep(&file);
  sweep(&mem);
}

/* ---- the daemon in process, driven by the client library ------------------------------------ *
 * One service and HTTP server (server/service, server/http on
 * 127.0.0.1, an ephemeral port) and libraysweep calls against it: a failed
 * allocation may fall in the client (libraysweep, libcurl), in the
 * connection thread (libmicrohttpd, request parsing, the service), in a
 * render or job worker, or in the kernel. The client's error must be a
 * clean one (a status and a message), and the daemon must still answer
 * afterwards (checked disarmed after every run). */

static http_server *d_srv;
static char d_blobs[300];
static char d_scene_id[65];

/* The JSON scene with its mesh files: pushed by the client, which uploads
 * the meshes as blobs and rewrites the references. */
static const char *SCENE_TEXT = JSON_SCENE;

static rsw_client *client_new(void) {
  rsw_client_opts o = {.size = sizeof o, .base_url = d_url, .timeout_s = 10, .max_retries = -1};
  rsw_client *c = NULL;
  return rsw_client_new(&o, &c) == RSW_OK ? c : NULL;
}

typedef struct cstate {
  rsw_client *c;
  rsw_film *film;
  char id[65];
  char job[40];
  char *json;
  uint64_t rev;
} cstate;

static rsw_film *ref_c_render, *ref_c_job;
static char *ref_c_params;

static void *c_setup(void) {
  cstate *k = calloc(1, sizeof *k);
  if (k && !(k->c = client_new())) {
    free(k);
    return NULL;
  }
  return k;
}

/* Disarmed: the daemon answers and the base scene is there. */
static bool daemon_alive(rsw_client *c) {
  char *json = NULL;
  bool ok = rsw_server_ready(c) == RSW_OK && rsw_scene_info(c, d_scene_id, &json) == RSW_OK;
  rsw_free(json);
  return ok;
}

static void c_teardown(void *p) {
  cstate *k = p;
  bool alive = daemon_alive(k->c);
  CHECK(alive, "%s: allocation %ld failing: the daemon does not answer any more", cur_op, (long)cur_n);
  if (k->job[0]) rsw_job_delete(k->c, k->job);
  rsw_film_free(k->film);
  rsw_free(k->json);
  rsw_client_free(k->c);
  free(k);
}

static rsw_status c_status(cstate *k, rsw_status s, rsw_err *err) {
  if (s != RSW_OK) {
    const rsw_error_info *ei = rsw_client_last_error(k->c);
    rsw_fail(err, s, ei->pointer, "%s%s(HTTP %d)", ei->message, ei->message[0] ? " " : "", ei->http_status);
    if (!ei->message[0]) err->msg[0] = '\0'; /* no message: the sweep reports it */
  }
  return s;
}

/* Push: each run loads a scene anew (the base scene with another
 * max_depth, so another id; deleted again in teardown). */
static char push_text[4096];

static rsw_status c_run_push(void *p, rsw_err *err) {
  cstate *k = p;
  int created = 0;
  return c_status(
      k, rsw_scene_push_buffer(k->c, push_text, strlen(push_text), data_dir, NULL, k->id, &created), err);
}

static void c_teardown_push(void *p) {
  cstate *k = p;
  if (k->id[0]) rsw_scene_delete(k->c, k->id, 1);
  c_teardown(p);
}

/* A spectrum (tabulated) and a mesh's transform; PATCH_BACK writes the
 * scene's own values again (same table, same matrix). */
static const char *PATCH =
    "{\"plate.bsdf.reflectance.value\": {\"wavelengths\": [400, 700], \"values\": [0.2, 0.3]},"
    " \"quad.to_world\": [1,0,0,0.1, 0,1,0,0, 0,0,1,0.6, 0,0,0,1]}";
static const char *PATCH_BACK =
    "{\"plate.bsdf.reflectance.value\": {\"wavelengths\": [400, 550, 700],"
    " \"values\": [0.05, 0.1, 0.45]}, \"quad.to_world\": [1,0,0,0, 0,1,0,0, 0,0,1,0.5, 0,0,0,1]}";

/* The table's values (not its revision) as text, to compare. */
static char *params_values(rsw_client *c) {
  char *json = NULL;
  uint64_t rev = 0;
  if (rsw_params_get(c, d_scene_id, NULL, NULL, &json, &rev) != RSW_OK) return NULL;
  return json;
}

static rsw_status c_run_patch(void *p, rsw_err *err) {
  cstate *k = p;
  return c_status(k, rsw_params_update(k->c, d_scene_id, PATCH, -1, &k->rev), err);
}

static bool strip_revision_equal(const char *a, const char *b) {
  /* {"revision": N, ...}: compare what follows the first comma. */
  const char *ca = a ? strchr(a, ',') : NULL, *cb = b ? strchr(b, ',') : NULL;
  return ca && cb && strcmp(ca, cb) == 0;
}

static char *ref_c_params_patched;

/* All or nothing: the table is the base one, or (when the failure hit the
 * answer after the update was applied: a 500 "the response could not be
 * built", a reply the client could not read) the patched one; never a
 * mix. */
static bool c_patch_unchanged(void *p) {
  cstate *k = p;
  char *now = params_values(k->c);
  bool ok = strip_revision_equal(now, ref_c_params) || strip_revision_equal(now, ref_c_params_patched);
  if (!ok && getenv("OOM_DEBUG")) {
    FILE *f = fopen("/tmp/oom_now.json", "w");
    if (f) fprintf(f, "%s\n%s\n", now ? now : "(null)", ref_c_params);
    if (f) fclose(f);
  }
  rsw_free(now);
  return ok;
}

static bool c_patch_applied(void *p) {
  cstate *k = p;
  char *now = params_values(k->c);
  bool ok = strip_revision_equal(now, ref_c_params_patched);
  if (!ok && getenv("OOM_DEBUG")) {
    FILE *f = fopen("/tmp/oom_now.json", "w");
    if (f) fprintf(f, "%s\n%s\n", now ? now : "(null)", ref_c_params_patched);
    if (f) fclose(f);
  }
  rsw_free(now);
  return ok;
}

static void c_teardown_patch(void *p) {
  cstate *k = p;
  rsw_params_update(k->c, d_scene_id, PATCH_BACK, -1, NULL);
  c_teardown(p);
}

static const char *RENDER_REQ =
    "{\"spp\": 4, \"seed\": 7, \"params\": {\"plate.bsdf.reflectance.value\": 0.25}}";

static rsw_status c_run_render(void *p, rsw_err *err) {
  cstate *k = p;
  return c_status(k, rsw_render(k->c, d_scene_id, RENDER_REQ, &k->film), err);
}

static bool same_rsw_film(const rsw_film *a, const rsw_film *b) {
  if (!a || !b) return false;
  int w = rsw_film_width(a), h = rsw_film_height(a), c = rsw_film_channels(a);
  return w == rsw_film_width(b) && h == rsw_film_height(b) && c == rsw_film_channels(b) &&
         memcmp(rsw_film_data(a), rsw_film_data(b), sizeof(float) * (size_t)w * h * c) == 0;
}

static bool c_render_same(void *p) {
  cstate *k = p;
  return same_rsw_film(k->film, ref_c_render);
}

/* A failed render with an override leaves the base values alone. */
static bool c_render_base_intact(void *p) {
  cstate *k = p;
  char *now = params_values(k->c);
  bool ok = strip_revision_equal(now, ref_c_params);
  rsw_free(now);
  return ok;
}

static rsw_status c_run_job(void *p, rsw_err *err) {
  cstate *k = p;
  rsw_contexts *x = NULL;
  rsw_status s = rsw_contexts_new(&x);
  size_t i0 = 0, i1 = 0;
  if (s == RSW_OK) s = rsw_contexts_add(x, "a", 500, &i0);
  if (s == RSW_OK) s = rsw_contexts_add(x, "b", 650, &i1);
  if (s == RSW_OK) s = rsw_contexts_set_param(x, i1, "plate.bsdf.reflectance.value", "0.4");
  if (s == RSW_OK) s = rsw_contexts_set_default_spp(x, 4);
  if (s == RSW_OK) s = rsw_contexts_set_job_seed(x, 3);
  if (s != RSW_OK) {
    rsw_contexts_free(x);
    return rsw_fail(err, s, "contexts", "building the contexts failed");
  }
  s = rsw_job_submit(k->c, d_scene_id, x, NULL, k->job);
  rsw_contexts_free(x);
  if (s != RSW_OK) return c_status(k, s, err);
  rsw_job_status js;
  s = rsw_job_wait(k->c, k->job, NULL, NULL, 10, &js);
  if (s != RSW_OK) return c_status(k, s, err);
  if (js.state != RSW_JOB_SUCCEEDED)
    return rsw_fail(err, RSW_ERR_RENDER, k->job, "job ended %d: %s", (int)js.state,
                    js.error[0] ? js.error : "");
  return c_status(k, rsw_job_fetch(k->c, k->job, "b", "meter", &k->film), err);
}

static bool c_job_same(void *p) {
  cstate *k = p;
  return same_rsw_film(k->film, ref_c_job);
}

static rsw_status c_run_save(void *p, rsw_err *err) {
  cstate *k = p;
  char path[600];
  snprintf(path, sizeof path, "%s/client.exr", tmpdir);
  rsw_status s = rsw_film_save_exr(ref_c_render, path);
  unlink(path);
  return c_status(k, s, err);
}

/* POST :render with Accept: image/x-exr, through libcurl: the daemon's
 * in-memory EXR encoder (film_exr_encode) behind HTTP. The answer is the
 * reference EXR, or an error status with a problem+json body, or a
 * transport error (a connection the daemon had to drop). */
typedef struct rawbuf {
  char *p;
  size_t n;
  bool oom;
} rawbuf;

static size_t raw_write(char *data, size_t size, size_t nmemb, void *user) {
  rawbuf *b = user;
  size_t add = size * nmemb;
  char *q = realloc(b->p, b->n + add + 1);
  if (!q) {
    b->oom = true;
    return 0;
  }
  b->p = q;
  memcpy(b->p + b->n, data, add);
  b->n += add;
  b->p[b->n] = '\0';
  return add;
}

static rawbuf ref_exr_body;

static rsw_status exr_request(rawbuf *out, long *http, rsw_err *err) {
  char url[400];
  snprintf(url, sizeof url, "%s/v1/scenes/%s:render", d_url, d_scene_id);
  CURL *h = curl_easy_init();
  if (!h) return rsw_fail(err, RSW_ERR_NOMEM, "curl", "curl_easy_init failed");
  struct curl_slist *hd = curl_slist_append(NULL, "Accept: image/x-exr");
  struct curl_slist *hd2 = hd ? curl_slist_append(hd, "Content-Type: application/json") : NULL;
  if (!hd2) {
    curl_slist_free_all(hd);
    curl_easy_cleanup(h);
    return rsw_fail(err, RSW_ERR_NOMEM, "curl", "curl_slist_append failed");
  }
  hd = hd2;
  curl_easy_setopt(h, CURLOPT_URL, url);
  curl_easy_setopt(h, CURLOPT_HTTPHEADER, hd);
  curl_easy_setopt(h, CURLOPT_POSTFIELDS, RENDER_REQ);
  curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, raw_write);
  curl_easy_setopt(h, CURLOPT_WRITEDATA, out);
  curl_easy_setopt(h, CURLOPT_TIMEOUT, 10L);
  curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);
  CURLcode rc = curl_easy_perform(h);
  *http = 0;
  curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, http);
  char ctype[128] = "";
  char *ct = NULL;
  if (rc == CURLE_OK && curl_easy_getinfo(h, CURLINFO_CONTENT_TYPE, &ct) == CURLE_OK && ct)
    snprintf(ctype, sizeof ctype, "%s", ct);
  curl_slist_free_all(hd);
  curl_easy_cleanup(h);
  if (rc != CURLE_OK)
    return rsw_fail(err, RSW_ERR_UNAVAILABLE, "curl", "transport error: %s", curl_easy_strerror(rc));
  if (*http == 200) return RSW_OK;
  if (*http >= 400 && strstr(ctype, "problem+json") && out->p && strstr(out->p, "\"detail\""))
    return rsw_fail(err, RSW_ERR_RENDER, "http", "HTTP %ld: %.200s", *http, out->p);
  return rsw_fail(err, RSW_ERR_PARSE, "http", "HTTP %ld without a problem+json body (%s)", *http, ctype);
}

typedef struct estate {
  cstate c;
  rawbuf body;
} estate;

static void *e_setup(void) {
  estate *k = calloc(1, sizeof *k);
  if (k && !(k->c.c = client_new())) {
    free(k);
    return NULL;
  }
  return k;
}

static rsw_status e_run(void *p, rsw_err *err) {
  estate *k = p;
  long http = 0;
  rsw_status s = exr_request(&k->body, &http, err);
  /* An error status must be a problem+json; anything else is not clean. */
  if (s == RSW_ERR_PARSE) err->msg[0] = '\0';
  return s;
}

static void e_capture(void *p) {
  estate *k = p;
  free(ref_exr_body.p);
  ref_exr_body = k->body;
  k->body = (rawbuf){0};
}

static bool e_same(void *p) {
  estate *k = p;
  return k->body.n == ref_exr_body.n && k->body.p && memcmp(k->body.p, ref_exr_body.p, k->body.n) == 0;
}

static bool c_render_base_intact_e(void *p) {
  estate *k = p;
  return c_render_base_intact(&k->c);
}

static void e_teardown(void *p) {
  estate *k = p;
  free(k->body.p);
  k->body.p = NULL;
  rsw_client *c = k->c.c;
  free(k);
  cstate *cs = calloc(1, sizeof *cs);
  if (!cs) {
    rsw_client_free(c);
    return;
  }
  cs->c = c;
  c_teardown(cs);
}

static bool daemon_start(void) {
  snprintf(d_blobs, sizeof d_blobs, "%s/blobs", tmpdir);
  snprintf(push_text, sizeof push_text, "%s", SCENE_TEXT);
  char *md = strstr(push_text, "\"max_depth\": 3");
  if (md) md[strlen("\"max_depth\": ")] = '4';
  service_opts so = {.size = sizeof so, .render_threads = 2, .blob_dir = d_blobs};
  rsw_err err = {0};
  char buf[1100];
  if (service_new(&so, &d_svc, &err) != RSW_OK) {
    printf("  service_new: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  http_opts ho = {.size = sizeof ho, .host = "127.0.0.1", .port = 0};
  if (http_server_start(d_svc, &ho, &d_srv, &err) != RSW_OK) {
    printf("  http_server_start: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  snprintf(d_url, sizeof d_url, "http://127.0.0.1:%d", http_server_port(d_srv));
  rsw_client *c = client_new();
  int created = 0;
  const char *step = "client";
  bool ok = c != NULL;
  if (ok) {
    step = "push";
    ok = rsw_scene_push_buffer(c, SCENE_TEXT, strlen(SCENE_TEXT), data_dir, NULL, d_scene_id, &created) ==
         RSW_OK;
  }
  if (ok) {
    step = "render";
    ok = rsw_render(c, d_scene_id, RENDER_REQ, &ref_c_render) == RSW_OK;
  }
  if (ok) {
    step = "params";
    ok = (ref_c_params = params_values(c)) != NULL;
  }
  if (ok) {
    step = "patch";
    ok = rsw_params_update(c, d_scene_id, PATCH, -1, NULL) == RSW_OK &&
         (ref_c_params_patched = params_values(c)) != NULL &&
         rsw_params_update(c, d_scene_id, PATCH_BACK, -1, NULL) == RSW_OK;
    char *back = ok ? params_values(c) : NULL;
    if (ok && !strip_revision_equal(back, ref_c_params)) {
      printf("  PATCH_BACK does not restore the scene's values\n");
      ok = false;
    }
    rsw_free(back);
  }
  if (ok) {
    step = "job";
    cstate k = {.c = c};
    ok = c_run_job(&k, &err) == RSW_OK;
    ref_c_job = k.film;
    if (k.job[0]) rsw_job_delete(c, k.job);
  }
  if (ok) {
    step = "render as EXR";
    long http = 0;
    ok = exr_request(&ref_exr_body, &http, &err) == RSW_OK && ref_exr_body.n > 4 &&
         memcmp(ref_exr_body.p, "\x76\x2f\x31\x01", 4) == 0;
  }
  if (!ok)
    printf("  daemon references: %s: %s %s\n", step, c ? rsw_client_last_error(c)->message : "", err.msg);
  rsw_client_free(c);
  return ok;
}

static void daemon_stop(void) {
  if (d_svc) service_shutdown(d_svc);
  http_server_stop(d_srv);
  service_free(d_svc);
  rsw_film_free(ref_c_render);
  rsw_film_free(ref_c_job);
  rsw_free(ref_c_params);
  rsw_free(ref_c_params_patched);
  free(ref_exr_body.p);
}

static void test_daemon(void) {
  REQUIRE(daemon_start(), "the in-process daemon");
  static const oom_op push = {"d_scene_push",  c_setup, c_run_push, NULL, NULL,
                              c_teardown_push, false,   NULL,       false};
  static const oom_op patch = {"d_params_patch", c_setup, c_run_patch, c_patch_unchanged,  c_patch_applied,
                               c_teardown_patch, false,   NULL,        .skip_embree = true};
  static const oom_op render = {
      "d_render", c_setup, c_run_render, c_render_base_intact, c_render_same, c_teardown, false, NULL, false};
  static const oom_op job = {"d_job", c_setup, c_run_job, c_render_base_intact, c_job_same, c_teardown,
                             false,   NULL,    false};
  static const oom_op exr = {"d_render_exr", e_setup,   e_run, c_render_base_intact_e, e_same, e_teardown,
                             false,          e_capture, false};
  static const oom_op save = {"c_film_save", c_setup,    c_run_save,          NULL,
                              NULL,          c_teardown, .status_only = true, NULL};
  sweep(&push);
  sweep(&patch);
  sweep(&render);
  sweep(&job);
  sweep(&exr);
  sweep(&save);
}

/* The loads, pushes and renders fail allocations inside Embree too
 * (outside its build tasks), so some runs must have checked what follows
 * Embree running out of memory (check_embree_oom). */
static void test_embree_oom_seen(void) {
  printf("  Embree out of memory in %ld runs: each time the probe's build finished and loads went on\n",
         embree_oom_runs);
  CHECK(embree_oom_runs > 0, "no run made Embree run out of memory");
  CHECK(stuck_played, "no stalled probe was played");
}

int main(void) {
  setvbuf(stdout, NULL, _IOLBF, 0);
  signal(SIGALRM, on_fatal);
  signal(SIGSEGV, on_fatal);
  signal(SIGBUS, on_fatal);
  signal(SIGABRT, on_fatal);
  const char *td = getenv("RSW_TEST_DIR");
  snprintf(data_dir, sizeof data_dir, "%s/data", td && *td ? td : "tests");
  snprintf(tmpdir, sizeof tmpdir, "%s/rsw_oom_XXXXXX", getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp");
  if (!mkdtemp(tmpdir)) {
    perror("mkdtemp");
    return 1;
  }
  if (!make_references()) {
    printf("FAIL references\ntest_oom: 0 passed, 1 failed\n");
    return 1;
  }
  RSW_TEST_RUN(test_kernel_load);
  RSW_TEST_RUN(test_kernel_update);
  RSW_TEST_RUN(test_kernel_render);
  RSW_TEST_RUN(test_exr_encode);
  RSW_TEST_RUN(test_daemon);
  const char *only = getenv("OOM_ONLY");
  if (!only || !*only) RSW_TEST_RUN(test_embree_oom_seen);
  cur_op = "stopping the daemon";
  cur_n = 0;
  alarm(RUN_LIMIT_S); /* a server thread stuck for good would hang the join */
  daemon_stop();
  alarm(0);
  char cmd[300];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
  if (system(cmd) != 0) printf("could not remove %s\n", tmpdir);
  film_image_free(&ref_json);
  film_image_free(&ref_json_updated);
  film_image_free(&ref_xml);
  free(ref_exr);
  RSW_TEST_END("test_oom");
}
