/* The service layer's life cycle, GET /v1 and the helpers every part
 * shares (service_internal.h). Resources have their own files: scenes.c,
 * params.c, renders.c, blobs.c, jobs.c, metrics.c. */
#include <errno.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../kernel/plugins/env_plugin.h"
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

char *svc_print_json(cJSON *o) {
  char *s = cJSON_PrintUnformatted(o);
  cJSON_Delete(o);
  return s;
}

rsw_status service_new(const service_opts *opts, service **out, rsw_err *err) {
  service *svc = calloc(1, sizeof *svc);
  if (!svc) return rsw_fail(err, RSW_ERR_NOMEM, "service", "out of memory");
  if (opts) svc->opts = *opts;
  if (!svc->opts.max_queue) svc->opts.max_queue = 64;
  if (!(svc->opts.result_ttl_s > 0)) svc->opts.result_ttl_s = 3600;
  if (!svc->opts.max_pixel_samples) svc->opts.max_pixel_samples = (uint64_t)1 << 32;
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
  if (svc->opts.blob_dir) {
    snprintf(svc->blob_dir, sizeof svc->blob_dir, "%s", svc->opts.blob_dir);
    if (mkdir(svc->blob_dir, 0700) != 0 && errno != EEXIST) {
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
  }
  svc->opts.blob_dir = svc->blob_dir;
  svc->opts.data_root = svc->data_root[0] ? svc->data_root : NULL;
  pthread_mutex_init(&svc->lock, NULL);
  pthread_cond_init(&svc->cond, NULL);
  atomic_store(&svc->ready, true);
  if (pthread_create(&svc->worker, NULL, svc_worker_main, svc) != 0) {
    service_free(svc);
    return rsw_fail(err, RSW_ERR_NOMEM, "service", "cannot start the worker thread");
  }
  svc->worker_started = true;
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
  pthread_mutex_unlock(&svc->lock);
}

bool service_ready(const service *svc) {
  return svc && atomic_load(&svc->ready);
}

void svc_resident_free(resident *r) {
  if (!r) return;
  scene_free(r->sc);
  cJSON_Delete(r->base_params);
  pthread_mutex_destroy(&r->lock);
  pthread_mutex_destroy(&r->cache_lock);
  free(r);
}

void service_free(service *svc) {
  if (!svc) return;
  service_shutdown(svc);
  if (svc->worker_started) pthread_join(svc->worker, NULL);
  svc_jobs_free(svc);
  for (size_t i = 0; i < svc->n_scenes; i++) svc_resident_free(svc->scenes[i]);
  free(svc->scenes);
  free(svc->raw);
  free(svc->reqs);
  pthread_mutex_destroy(&svc->lock);
  pthread_cond_destroy(&svc->cond);
  free(svc);
}

char *service_info_json(service *svc) {
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "name", "raysweepd");
  cJSON_AddStringToObject(o, "version", RSW_VERSION);
  cJSON_AddStringToObject(o, "build", __DATE__ " " __TIME__);
  cJSON_AddStringToObject(o, "api_version", "v1");
  cJSON *v = cJSON_AddArrayToObject(o, "variants");
  cJSON_AddItemToArray(v, cJSON_CreateString("mono"));
  cJSON_AddItemToArray(v, cJSON_CreateString("rgb"));
  cJSON *pl = cJSON_AddArrayToObject(o, "plugins");
  for (size_t i = 0; rsw_plugins[i] || i == 0; i++) {
    const plugin *p = rsw_plugins[i];
    if (!p) break;
    if (p->cls == CLS_SCENE) continue;
    cJSON *e = cJSON_CreateObject();
    cJSON_AddStringToObject(e, "name", p->name);
    cJSON_AddStringToObject(e, "class", obj_class_name(p->cls));
    cJSON_AddItemToArray(pl, e);
  }
  for (size_t i = 0; i < plugins_count(); i++) { /* --plugin-dir environment plugins */
    const char *pretty = NULL;
    const plugin *p = plugins_at(i, &pretty, NULL);
    cJSON *e = cJSON_CreateObject();
    cJSON_AddStringToObject(e, "name", p->name);
    cJSON_AddStringToObject(e, "class", obj_class_name(p->cls));
    cJSON_AddStringToObject(e, "pretty_name", pretty);
    cJSON_AddBoolToObject(e, "external", 1);
    cJSON_AddItemToArray(pl, e);
  }
  cJSON *lim = cJSON_AddObjectToObject(o, "limits");
  if (svc->opts.max_body_bytes)
    cJSON_AddNumberToObject(lim, "max_body_bytes", (double)svc->opts.max_body_bytes);
  cJSON_AddNumberToObject(lim, "max_depth", RSW_MAX_DEPTH);
  cJSON_AddNumberToObject(lim, "max_queue", (double)svc->opts.max_queue);
  cJSON_AddNumberToObject(lim, "max_pixel_samples", (double)svc->opts.max_pixel_samples);
  cJSON_AddNumberToObject(lim, "result_ttl_s", svc->opts.result_ttl_s);
  return svc_print_json(o);
}
