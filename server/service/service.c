/* The service layer's life cycle, GET /v1 and the helpers every part
 * shares (service_internal.h). Resources have their own files: scenes.c,
 * params.c, renders.c, blobs.c, jobs.c, metrics.c. */
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "../kernel/core/isa.h"
#include "../kernel/extplugin/env_plugin.h"
#include "../kernel/kapi.h"
#include "../kernel/scene/loader.h"
#include "buf.h"
#include "raysweep/version.h"
#include "rsw_sha256.h"
#include "service_internal.h"

double svc_now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

void svc_iso_time(time_t t, char out[32]) {
  struct tm tm;
  gmtime_r(&t, &tm);
  strftime(out, 32, "%Y-%m-%dT%H:%M:%SZ", &tm);
}

rsw_status svc_fail(svc_error *e, rsw_status code, const char *where, const char *fmt, ...) {
  if (!e) return code;
  if (e->err.code != RSW_OK) return code;
  char msg[768];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  rsw_fail(&e->err, code, where, "%s", msg);
  return code;
}

rsw_status svc_request_code(rsw_status kernel_code) {
  switch (kernel_code) {
  case RSW_ERR_NOT_FOUND: return RSW_ERR_UNKNOWN_NAME;
  case RSW_ERR_PARSE: return RSW_ERR_INVALID;
  default: return kernel_code;
  }
}

/* ---- JSON documents when memory runs out ------------------------------------------------
 * cJSON_Add*, cJSON_Create* and cJSON_Duplicate report an allocation
 * failure only by a NULL that the add functions then ignore, so a document
 * built under memory pressure silently lacks a field or an entry (test_oom
 * found parameter entries without "type" in GET params and job overrides
 * dropped from a job). Rather than checking every call, the service gives
 * cJSON an allocator that counts failures per thread, and a document is
 * checked once where it is printed or kept: no failure since the mark taken
 * before building it. (The hooks are process-wide; the count is per
 * thread, so other cJSON users are unaffected.) */
static _Thread_local unsigned t_json_failures;

static void *json_malloc(size_t n) {
  void *p = malloc(n);
  if (!p) t_json_failures++;
  return p;
}

static pthread_once_t g_json_once = PTHREAD_ONCE_INIT;

static void json_hooks_install(void) {
  cJSON_Hooks h = {.malloc_fn = json_malloc, .free_fn = free};
  cJSON_InitHooks(&h);
}

unsigned svc_json_mark(void) {
  pthread_once(&g_json_once, json_hooks_install);
  return t_json_failures;
}

bool svc_json_ok(unsigned mark) {
  return t_json_failures == mark;
}

char *svc_print_json(cJSON *o, unsigned mark) {
  char *s = o && svc_json_ok(mark) ? cJSON_PrintUnformatted(o) : NULL;
  cJSON_Delete(o);
  return s;
}

/* 16 hex digits from /dev/urandom (the clock and the pid when it cannot
 * be read): tells replicas apart, nothing more. */
static void random_instance(char out[17]) {
  unsigned char b[8] = {0};
  int fd = open("/dev/urandom", O_RDONLY | O_CLOEXEC);
  if (fd < 0 || read(fd, b, sizeof b) != (ssize_t)sizeof b) {
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    uint64_t v = ((uint64_t)ts.tv_sec * 1000000007ull) ^ (uint64_t)ts.tv_nsec ^ ((uint64_t)getpid() << 40);
    memcpy(b, &v, sizeof b);
  }
  if (fd >= 0) close(fd);
  for (int i = 0; i < 8; i++) snprintf(out + 2 * i, 3, "%02x", b[i]);
}

void svc_json_push(cJSON *array, cJSON *item) {
  if (!cJSON_AddItemToArray(array, item)) cJSON_Delete(item);
}

void svc_json_put(cJSON *obj, const char *key, cJSON *item) {
  if (!cJSON_AddItemToObject(obj, key, item)) cJSON_Delete(item);
}

rsw_status svc_json_out(char **json_out, cJSON *o, unsigned mark, svc_error *e) {
  *json_out = svc_print_json(o, mark);
  if (*json_out) return RSW_OK;
  return svc_fail(e, RSW_ERR_NOMEM, "", "out of memory while building the answer");
}

rsw_status service_new(const service_opts *opts, service **out, rsw_err *err) {
  (void)svc_json_mark(); /* installs the counting allocator before any thread starts */
  service *svc = calloc(1, sizeof *svc);
  if (!svc) return rsw_fail(err, RSW_ERR_NOMEM, "service", "out of memory");
  if (opts) svc->opts = *opts;
  if (!svc->opts.max_queue) svc->opts.max_queue = 64;
  if (!(svc->opts.result_ttl_s > 0)) svc->opts.result_ttl_s = 3600;
  if (!svc->opts.max_pixel_samples) svc->opts.max_pixel_samples = (uint64_t)1 << 32;
  if (!svc->opts.max_film_bytes) svc->opts.max_film_bytes = (uint64_t)1 << 30;
  if (svc->opts.data_root) {
    char *rp = realpath(svc->opts.data_root, NULL);
    if (!rp) {
      free(svc);
      return rsw_fail(err, RSW_ERR_FILE, "--data-root", "cannot use data root '%s': %s", opts->data_root,
                      strerror(errno));
    }
    snprintf(svc->data_root, sizeof svc->data_root, "%s", rp);
    free(rp);
  }
  svc->state_lock_fd = -1;
  if (svc->opts.state_dir && strlen(svc->opts.state_dir) > 3000) {
    free(svc);
    return rsw_fail(err, RSW_ERR_USAGE, "--state-dir", "the state directory's path is too long");
  }
  if (svc->opts.state_dir) {
    snprintf(svc->state_dir, sizeof svc->state_dir, "%s", svc->opts.state_dir);
    rsw_status sst = svc_state_open(svc, err);
    if (sst) {
      if (svc->state_lock_fd >= 0) close(svc->state_lock_fd);
      free(svc);
      return sst;
    }
    svc->opts.state_dir = svc->state_dir;
  }
  if (svc->opts.blob_dir || svc->state_dir[0]) {
    if (svc->opts.blob_dir)
      snprintf(svc->blob_dir, sizeof svc->blob_dir, "%s", svc->opts.blob_dir);
    else
      snprintf(svc->blob_dir, sizeof svc->blob_dir, "%.3000s/blobs", svc->state_dir);
    if (mkdir(svc->blob_dir, 0700) != 0 && errno != EEXIST) {
      if (svc->state_lock_fd >= 0) close(svc->state_lock_fd);
      free(svc);
      return rsw_fail(err, RSW_ERR_IO, "--blob-dir", "cannot create blob directory '%s': %s", opts->blob_dir,
                      strerror(errno));
    }
  } else {
    snprintf(svc->blob_dir, sizeof svc->blob_dir, "/tmp/raysweepd-blobs-XXXXXX");
    if (!mkdtemp(svc->blob_dir)) {
      free(svc);
      return rsw_fail(err, RSW_ERR_IO, "--blob-dir", "cannot create a blob directory: %s", strerror(errno));
    }
    svc->blob_dir_temp = true; /* removed by service_free */
  }
  svc->opts.blob_dir = svc->blob_dir;
  svc->opts.data_root = svc->data_root[0] ? svc->data_root : NULL;
  pthread_mutex_init(&svc->lock, NULL);
  pthread_mutex_init(&svc->probe_lock, NULL);
  pthread_cond_init(&svc->cond, NULL);
  random_instance(svc->instance);
  pthread_cond_init(&svc->work_cond, NULL);
  atomic_store(&svc->ready, true);
  /* Job workers: one job each at a time, so jobs (of one scene or of
   * several) run concurrently; their renders share the kernel's worker
   * pool tile by tile (render.c), and a job of 1x1 contexts keeps a core
   * busy per worker. As many as render threads: --threads 1 means one
   * core's worth of jobs. */
  long nw = svc->opts.render_threads > 0 ? svc->opts.render_threads : sysconf(_SC_NPROCESSORS_ONLN);
  if (nw < 1) nw = 1;
  if (nw > 64) nw = 64;
  svc->workers = calloc((size_t)nw, sizeof *svc->workers);
  for (long i = 0; svc->workers && i < nw; i++) {
    if (pthread_create(&svc->workers[i], NULL, svc_worker_main, svc) != 0) break;
    svc->n_workers++;
  }
  if (svc->n_workers == 0) {
    service_free(svc);
    return rsw_fail(err, RSW_ERR_NOMEM, "service", "cannot start the worker threads");
  }
  *out = svc;
  return RSW_OK;
}

void service_shutdown(service *svc) {
  if (!svc) return;
  atomic_store(&svc->ready, false);
  pthread_mutex_lock(&svc->lock);
  svc->stopping = true;
  for (size_t i = 0; i < svc->n_jobs; i++) atomic_store(&svc->jobs[i]->cancel, 1);
  pthread_cond_broadcast(&svc->cond);
  pthread_cond_broadcast(&svc->work_cond);
  pthread_mutex_unlock(&svc->lock);
}

bool service_ready(const service *svc) {
  return svc && atomic_load(&svc->ready);
}

bool service_accepts_jobs(service *svc, const char **why_out) {
  const char *why = NULL;
  if (!service_ready(svc)) {
    why = "the server is shutting down";
  } else {
    pthread_mutex_lock(&svc->lock);
    if (svc->n_queue >= svc->opts.max_queue) why = "the job queue is full (--max-queue)";
    pthread_mutex_unlock(&svc->lock);
    /* Embree ran out of memory and a test build did not finish: none
     * will (accel.h), so this daemon must be restarted. */
    if (!why && kapi_embree_stuck(NULL, NULL, true))
      why = "Embree cannot build any more in this daemon (after it ran out of memory, a test build did not "
            "finish): scenes, geometry updates and new views are refused; restart it (docs/robustness.md)";
    /* A state directory that cannot take writes: PATCHes, scene posts and
     * jobs would answer 507 (a probe write, at most once a second). */
    if (!why) svc_state_writable(svc, &why);
  }
  if (why_out) *why_out = why;
  return !why;
}

void svc_resident_free(resident *r) {
  if (!r) return;
  svc_views_free(r);
  scene_free(r->sc);
  cJSON_Delete(r->base_params);
  cJSON_Delete(r->patches);
  cJSON_Delete(r->templates);
  free(r->src);
  free(r->src_root);
  pthread_cond_destroy(&r->cond);
  pthread_mutex_destroy(&r->lock);
  pthread_mutex_destroy(&r->cache_lock);
  free(r);
}

static int remove_entry(const char *path, const struct stat *sb, int flag, struct FTW *ftw) {
  (void)sb, (void)flag, (void)ftw;
  remove(path);
  return 0;
}

void service_restore(service *svc) {
  if (svc) svc_state_restore(svc);
}

void service_free(service *svc) {
  if (!svc) return;
  service_shutdown(svc);
  for (int i = 0; i < svc->n_workers; i++) pthread_join(svc->workers[i], NULL);
  free(svc->workers);
  svc_jobs_free(svc);
  for (size_t i = 0; i < svc->n_scenes; i++) svc_resident_free(svc->scenes[i]);
  free(svc->scenes);
  free(svc->raw);
  free(svc->reqs);
  free(svc->evicted);
  if (svc->blob_dir_temp) nftw(svc->blob_dir, remove_entry, 16, FTW_DEPTH | FTW_PHYS);
  if (svc->state_lock_fd >= 0) close(svc->state_lock_fd);
  pthread_mutex_destroy(&svc->lock);
  pthread_mutex_destroy(&svc->probe_lock);
  pthread_cond_destroy(&svc->cond);
  pthread_cond_destroy(&svc->work_cond);
  free(svc);
}

char *service_info_json(service *svc) {
  unsigned jm = svc_json_mark();
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "name", "raysweepd");
  cJSON_AddStringToObject(o, "version", RSW_VERSION);
  cJSON_AddStringToObject(o, "build", __DATE__ " " __TIME__);
  cJSON_AddStringToObject(o, "api_version", "v1");
  cJSON_AddStringToObject(o, "isa", rsw_isa_name(rsw_isa_get()));
  cJSON_AddStringToObject(o, "instance", svc->instance);
  cJSON *v = cJSON_AddArrayToObject(o, "variants");
  svc_json_push(v, cJSON_CreateString("mono"));
  svc_json_push(v, cJSON_CreateString("rgb"));
  svc_json_push(v, cJSON_CreateString("mono_polarized"));
  svc_json_push(v, cJSON_CreateString("rgb_polarized"));
  cJSON *pl = cJSON_AddArrayToObject(o, "plugins");
  for (size_t i = 0; rsw_plugins[i]; i++) {
    const plugin *p = rsw_plugins[i];
    if (p->cls == CLS_SCENE) continue;
    cJSON *e = cJSON_CreateObject();
    cJSON_AddStringToObject(e, "name", p->name);
    cJSON_AddStringToObject(e, "class", obj_class_name(p->cls));
    svc_json_push(pl, e);
  }
  for (size_t i = 0; i < plugins_count(); i++) { /* --plugin-dir environment plugins */
    const char *pretty = NULL;
    const plugin *p = plugins_at(i, &pretty, NULL);
    cJSON *e = cJSON_CreateObject();
    cJSON_AddStringToObject(e, "name", p->name);
    cJSON_AddStringToObject(e, "class", obj_class_name(p->cls));
    cJSON_AddStringToObject(e, "pretty_name", pretty);
    cJSON_AddBoolToObject(e, "external", 1);
    svc_json_push(pl, e);
  }
  cJSON *lim = cJSON_AddObjectToObject(o, "limits");
  if (svc->opts.max_body_bytes)
    cJSON_AddNumberToObject(lim, "max_body_bytes", (double)svc->opts.max_body_bytes);
  cJSON_AddNumberToObject(lim, "max_depth", RSW_MAX_DEPTH);
  cJSON_AddNumberToObject(lim, "max_queue", (double)svc->opts.max_queue);
  cJSON_AddNumberToObject(lim, "max_pixel_samples", (double)svc->opts.max_pixel_samples);
  cJSON_AddNumberToObject(lim, "max_film_bytes", (double)svc->opts.max_film_bytes);
  cJSON_AddNumberToObject(lim, "max_job_contexts", SVC_MAX_JOB_CONTEXTS);
  cJSON_AddNumberToObject(lim, "max_job_renders", SVC_MAX_JOB_RENDERS);
  cJSON_AddNumberToObject(lim, "max_direction_pixels", SVC_MAX_DIRECTION_PIXELS);
  cJSON_AddNumberToObject(lim, "max_bundle", RENDER_MAX_BUNDLE); /* a job's "bundle" K */
  cJSON_AddNumberToObject(lim, "result_ttl_s", svc->opts.result_ttl_s);
  /* 0: no budget / no cap. */
  cJSON_AddNumberToObject(lim, "max_scene_bytes", (double)svc->opts.max_scene_bytes);
  cJSON_AddNumberToObject(lim, "max_result_bytes", (double)svc->opts.max_result_bytes);
  cJSON_AddBoolToObject(lim, "state_dir", svc->state_dir[0] != 0);
  return svc_print_json(o, jm);
}
