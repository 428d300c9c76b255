/* The service layer: resident scenes, blobs, parameters, synchronous
 * renders (see service.h). Jobs are in jobs.c. */
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <openssl/evp.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../kernel/accel.h"
#include "../kernel/core/warp.h"
#include "../kernel/plugins/env_plugin.h"
#include "../kernel/scene/loader.h"
#include "raysweep/version.h"
#include "service_internal.h"

/* ---- small helpers ------------------------------------------------------------- */

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

rsw_status svc_fail(svc_error *e, rsw_status code, int http, const char *where, const char *fmt, ...) {
  if (!e) return code;
  if (e->err.code != RSW_OK) return code;
  char msg[768];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  rsw_fail(&e->err, code, where, "%s", msg);
  e->http_status = http;
  return code;
}

static char *print_json(cJSON *o) {
  char *s = cJSON_PrintUnformatted(o);
  cJSON_Delete(o);
  return s;
}

static void hex(const unsigned char *d, size_t n, char *out) {
  static const char digits[] = "0123456789abcdef";
  for (size_t i = 0; i < n; i++) {
    out[2 * i] = digits[d[i] >> 4];
    out[2 * i + 1] = digits[d[i] & 15];
  }
  out[2 * n] = '\0';
}

static bool is_hex64(const char *s) {
  if (!s || strlen(s) != 64) return false;
  for (int i = 0; i < 64; i++)
    if (!((s[i] >= '0' && s[i] <= '9') || (s[i] >= 'a' && s[i] <= 'f'))) return false;
  return true;
}

/* SHA-256 through OpenSSL's EVP interface. */
typedef struct sha_ctx {
  EVP_MD_CTX *md;
} sha_ctx;

static bool sha_begin(sha_ctx *c) {
  c->md = EVP_MD_CTX_new();
  return c->md && EVP_DigestInit_ex(c->md, EVP_sha256(), NULL) == 1;
}
static void sha_update(sha_ctx *c, const void *d, size_t n) {
  EVP_DigestUpdate(c->md, d, n);
}
static void sha_end(sha_ctx *c, unsigned char out[32]) {
  unsigned int len = 32;
  EVP_DigestFinal_ex(c->md, out, &len);
  EVP_MD_CTX_free(c->md);
  c->md = NULL;
}
static bool sha256(const void *d, size_t n, unsigned char out[32]) {
  sha_ctx c;
  if (!sha_begin(&c)) {
    EVP_MD_CTX_free(c.md);
    return false;
  }
  sha_update(&c, d, n);
  sha_end(&c, out);
  return true;
}

static bool sha256_file(const char *path, unsigned char out[32]) {
  FILE *f = fopen(path, "rb");
  if (!f) return false;
  sha_ctx c;
  if (!sha_begin(&c)) {
    EVP_MD_CTX_free(c.md);
    fclose(f);
    return false;
  }
  char buf[1 << 16];
  size_t r;
  while ((r = fread(buf, 1, sizeof buf, f)) > 0) sha_update(&c, buf, r);
  bool ok = !ferror(f);
  fclose(f);
  sha_end(&c, out);
  return ok;
}

/* ---- life cycle ---------------------------------------------------------------- */

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

/* ---- info and metrics ------------------------------------------------------------ */

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
  return print_json(o);
}

void service_count_request(service *svc, const char *route, int status) {
  pthread_mutex_lock(&svc->lock);
  size_t i = 0;
  for (; i < svc->n_reqs; i++)
    if (svc->reqs[i].status == status && strcmp(svc->reqs[i].route, route) == 0) break;
  if (i == svc->n_reqs) {
    if (svc->n_reqs == svc->cap_reqs) {
      size_t cap = svc->cap_reqs ? 2 * svc->cap_reqs : 32;
      void *p = realloc(svc->reqs, cap * sizeof *svc->reqs);
      if (!p) {
        pthread_mutex_unlock(&svc->lock);
        return;
      }
      svc->reqs = p;
      svc->cap_reqs = cap;
    }
    snprintf(svc->reqs[i].route, sizeof svc->reqs[i].route, "%s", route);
    svc->reqs[i].status = status;
    svc->reqs[i].n = 0;
    svc->n_reqs++;
  }
  svc->reqs[i].n++;
  pthread_mutex_unlock(&svc->lock);
}

static size_t scene_bytes(const scene *sc) {
  size_t b = accel_memory(sc->accel);
  for (size_t i = 0; i < sc->n_shapes; i++) {
    const mesh *m = &sc->shapes[i]->mesh;
    b += (size_t)m->n_verts * (12 + (m->nrm ? 12 : 0) + (m->uv ? 8 : 0)) + (size_t)m->n_faces * 12;
    if (sc->shapes[i]->tri_cdf) b += (size_t)sc->shapes[i]->tri_cdf_n * 8;
  }
  return b;
}

typedef struct mbuf {
  char *p;
  size_t n, cap;
} mbuf;

static void mb_printf(mbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void mb_printf(mbuf *b, const char *fmt, ...) {
  for (;;) {
    va_list ap;
    va_start(ap, fmt);
    int w = vsnprintf(b->p ? b->p + b->n : NULL, b->p ? b->cap - b->n : 0, fmt, ap);
    va_end(ap);
    if (w < 0) return;
    if (b->p && b->n + (size_t)w < b->cap) {
      b->n += (size_t)w;
      return;
    }
    size_t cap = b->cap ? 2 * b->cap : 4096;
    while (cap <= b->n + (size_t)w) cap *= 2;
    char *np = realloc(b->p, cap);
    if (!np) return;
    b->p = np;
    b->cap = cap;
  }
}

char *service_metrics_text(service *svc) {
  mbuf b = {0};
  pthread_mutex_lock(&svc->lock);
  mb_printf(&b, "# HELP raysweep_http_requests_total HTTP requests by route template and status.\n");
  mb_printf(&b, "# TYPE raysweep_http_requests_total counter\n");
  for (size_t i = 0; i < svc->n_reqs; i++)
    mb_printf(&b, "raysweep_http_requests_total{route=\"%s\",status=\"%d\"} %llu\n", svc->reqs[i].route,
              svc->reqs[i].status, (unsigned long long)svc->reqs[i].n);
  size_t bytes = 0;
  for (size_t i = 0; i < svc->n_scenes; i++) bytes += scene_bytes(svc->scenes[i]->sc);
  mb_printf(
      &b, "# HELP raysweep_scenes_resident Scenes held in memory.\n# TYPE raysweep_scenes_resident gauge\n");
  mb_printf(&b, "raysweep_scenes_resident %zu\n", svc->n_scenes);
  mb_printf(&b, "# HELP raysweep_scene_bytes Bytes held by resident scenes' geometry.\n# TYPE "
                "raysweep_scene_bytes gauge\n");
  mb_printf(&b, "raysweep_scene_bytes %zu\n", bytes);
  static const char *const states[] = {"queued", "running", "succeeded", "failed", "cancelled"};
  size_t by_state[5] = {0};
  for (size_t i = 0; i < svc->n_jobs; i++) by_state[svc->jobs[i]->state]++;
  mb_printf(&b, "# HELP raysweep_jobs Jobs by state.\n# TYPE raysweep_jobs gauge\n");
  for (int s = 0; s < 5; s++) mb_printf(&b, "raysweep_jobs{state=\"%s\"} %zu\n", states[s], by_state[s]);
  mb_printf(&b,
            "# HELP raysweep_queue_depth Jobs waiting for the worker.\n# TYPE raysweep_queue_depth gauge\n");
  mb_printf(&b, "raysweep_queue_depth %zu\n", svc->n_queue);
  mb_printf(&b, "# HELP raysweep_sync_renders Synchronous renders (POST :render) in progress.\n");
  mb_printf(&b, "# TYPE raysweep_sync_renders gauge\nraysweep_sync_renders %zu\n", svc->sync_renders);
  mb_printf(&b, "# HELP raysweep_contexts_rendered_total Renders of (context, sensor) completed.\n");
  mb_printf(&b, "# TYPE raysweep_contexts_rendered_total counter\nraysweep_contexts_rendered_total %llu\n",
            (unsigned long long)svc->contexts_rendered);
  mb_printf(&b, "# HELP raysweep_renders_failed_total Renders that failed.\n");
  mb_printf(&b, "# TYPE raysweep_renders_failed_total counter\nraysweep_renders_failed_total %llu\n",
            (unsigned long long)svc->renders_failed);
  mb_printf(&b, "# HELP raysweep_render_seconds_total Wall time spent rendering.\n");
  mb_printf(&b, "# TYPE raysweep_render_seconds_total counter\nraysweep_render_seconds_total %.6f\n",
            svc->render_seconds);
  mb_printf(&b, "# HELP raysweep_unresolved_rays_total Rays a periodic boundary could not resolve (counted "
                "as blocked).\n");
  mb_printf(&b, "# TYPE raysweep_unresolved_rays_total counter\nraysweep_unresolved_rays_total %llu\n",
            (unsigned long long)svc->unresolved_rays);
  static const char *const classes[] = {"none", "spectral", "geometric"};
  mb_printf(&b, "# HELP raysweep_update_seconds_total Time spent applying parameter updates, by the "
                "costliest class touched.\n");
  mb_printf(&b, "# TYPE raysweep_update_seconds_total counter\n");
  for (int c = 0; c < 3; c++)
    mb_printf(&b, "raysweep_update_seconds_total{class=\"%s\"} %.6f\n", classes[c], svc->update_seconds[c]);
  mb_printf(&b, "# HELP raysweep_updates_total Parameter updates applied, by the costliest class touched.\n");
  mb_printf(&b, "# TYPE raysweep_updates_total counter\n");
  for (int c = 0; c < 3; c++)
    mb_printf(&b, "raysweep_updates_total{class=\"%s\"} %llu\n", classes[c],
              (unsigned long long)svc->updates[c]);
  mb_printf(&b, "# HELP raysweep_ready Whether the server accepts work.\n# TYPE raysweep_ready gauge\n");
  mb_printf(&b, "raysweep_ready %d\n", atomic_load(&svc->ready) ? 1 : 0);
  pthread_mutex_unlock(&svc->lock);
  return b.p;
}

static void count_update(service *svc, const update_report *rep) {
  int c = (rep->classes & UPDATE_GEOMETRIC) ? 2 : (rep->classes & UPDATE_SPECTRAL) ? 1 : 0;
  pthread_mutex_lock(&svc->lock);
  svc->update_seconds[c] += rep->seconds;
  svc->updates[c]++;
  pthread_mutex_unlock(&svc->lock);
}

/* ---- scenes ---------------------------------------------------------------------- */

static void refresh_param_cache(resident *r);

/* File references while loading: blobs by digest, plain names inside the
 * data root; every digest goes into the scene id. */
typedef struct load_ctx {
  service *svc;
  sha_ctx *files; /* digests of referenced files, in reference order */
} load_ctx;

static rsw_status resolve_file(void *user, const char *name, char **path_out, rsw_err *err) {
  load_ctx *lc = user;
  service *svc = lc->svc;
  char path[8192];
  unsigned char d[32];
  char dh[65];
  if (strncmp(name, "sha256:", 7) == 0) {
    if (!is_hex64(name + 7))
      return rsw_fail(err, RSW_ERR_INVALID, name, "'%s' is not sha256:<64 lowercase hex digits>", name);
    snprintf(path, sizeof path, "%s/%s", svc->blob_dir, name + 7);
    struct stat sb;
    if (stat(path, &sb) != 0)
      return rsw_fail(err, RSW_ERR_FILE, name, "blob %s has not been uploaded (PUT /v1/blobs/%s)", name + 7,
                      name + 7);
    snprintf(dh, sizeof dh, "%s", name + 7);
  } else {
    if (!svc->data_root[0])
      return rsw_fail(
          err, RSW_ERR_FILE, name,
          "file '%s': this daemon has no --data-root; upload it as a blob and refer to it as sha256:<hex>",
          name);
    if (name[0] == '/')
      snprintf(path, sizeof path, "%s", name);
    else
      snprintf(path, sizeof path, "%s/%s", svc->data_root, name);
    char *rp = realpath(path, NULL);
    if (!rp) return rsw_fail(err, RSW_ERR_FILE, name, "file '%s' not found under the data root", name);
    size_t lr = strlen(svc->data_root);
    bool inside = strncmp(rp, svc->data_root, lr) == 0 && rp[lr] == '/';
    if (!inside) {
      free(rp);
      return rsw_fail(err, RSW_ERR_FILE, name, "file '%s' lies outside the data root", name);
    }
    snprintf(path, sizeof path, "%s", rp);
    free(rp);
    if (!sha256_file(path, d)) return rsw_fail(err, RSW_ERR_FILE, name, "cannot read '%s'", name);
    hex(d, 32, dh);
  }
  if (lc->files) {
    sha_update(lc->files, "file ", 5);
    sha_update(lc->files, dh, 64);
    sha_update(lc->files, "\n", 1);
  }
  *path_out = strdup(path);
  return *path_out ? RSW_OK : rsw_fail(err, RSW_ERR_NOMEM, name, "out of memory");
}

/* The canonical document: JSON re-printed without whitespace (keys in
 * document order, numbers as cJSON prints them), or the XML text as is. */
static char *canonical_text(const char *body, size_t len, bool is_xml) {
  if (is_xml) {
    char *c = malloc(len + 1);
    if (c) {
      memcpy(c, body, len);
      c[len] = '\0';
    }
    return c;
  }
  cJSON *j = cJSON_ParseWithLength(body, len);
  if (!j) return NULL;
  char *c = cJSON_PrintUnformatted(j);
  cJSON_Delete(j);
  return c;
}

static resident *find_scene_locked(service *svc, const char *id) {
  for (size_t i = 0; i < svc->n_scenes; i++)
    if (strcmp(svc->scenes[i]->id, id) == 0) return svc->scenes[i];
  return NULL;
}

resident *svc_scene_acquire(service *svc, const char *id) {
  pthread_mutex_lock(&svc->lock);
  resident *r = find_scene_locked(svc, id);
  if (r) r->refs++;
  pthread_mutex_unlock(&svc->lock);
  return r;
}

void svc_scene_release(service *svc, resident *r) {
  if (!r) return;
  pthread_mutex_lock(&svc->lock);
  bool free_it = --r->refs == 0 && r->deleted;
  pthread_mutex_unlock(&svc->lock);
  if (free_it) svc_resident_free(r);
}

void svc_scene_summary(const resident *r, cJSON *o) {
  cJSON_AddStringToObject(o, "id", r->id);
  cJSON_AddStringToObject(o, "variant", r->sc->variant == VARIANT_MONO ? "mono" : "rgb");
  cJSON *s = cJSON_AddArrayToObject(o, "sensors");
  for (size_t i = 0; i < r->sc->n_sensors; i++)
    cJSON_AddItemToArray(s, cJSON_CreateString(r->sc->sensors[i]->base.id));
  cJSON_AddNumberToObject(o, "revision", (double)r->revision);
}

static void scene_error(svc_error *e, const rsw_err *err) {
  e->err = *err;
  e->http_status = err->code == RSW_ERR_PARSE ? 400 : err->code == RSW_ERR_NOMEM ? 500 : 422;
}

/* Load, compute the id, register (or find the existing one). */
static rsw_status scene_post(service *svc, const char *body, size_t len, bool is_xml, const char *variant,
                             const char *name, bool *created, resident **out, svc_error *e) {
  if (variant && strcmp(variant, "mono") != 0 && strcmp(variant, "rgb") != 0)
    return svc_fail(e, RSW_ERR_INVALID, 400, "variant", "variant must be mono or rgb (got '%s')", variant);
  /* Same text and variant as an earlier post: the same scene (cheap path;
   * files it references are content-addressed or re-hashed on a load). */
  unsigned char raw[32];
  {
    sha_ctx c;
    if (!sha_begin(&c)) return svc_fail(e, RSW_ERR_NOMEM, 500, "scene", "out of memory");
    sha_update(&c, is_xml ? "xml\n" : "json\n", is_xml ? 4 : 5);
    sha_update(&c, variant ? variant : "-", variant ? strlen(variant) : 1);
    sha_update(&c, "\n", 1);
    sha_update(&c, body, len);
    sha_end(&c, raw);
  }
  bool has_files = memmem(body, len, "filename", 8) != NULL;
  if (!has_files) {
    pthread_mutex_lock(&svc->lock);
    for (size_t i = 0; i < svc->n_raw; i++)
      if (memcmp(svc->raw[i].digest, raw, 32) == 0) {
        resident *r = find_scene_locked(svc, svc->raw[i].id);
        if (r) {
          r->refs++;
          pthread_mutex_unlock(&svc->lock);
          *created = false;
          *out = r;
          return RSW_OK;
        }
      }
    pthread_mutex_unlock(&svc->lock);
  }
  char *canon = canonical_text(body, len, is_xml);
  /* A body that does not even parse is reported by the reader below. */
  sha_ctx files;
  if (!sha_begin(&files)) {
    free(canon);
    return svc_fail(e, RSW_ERR_NOMEM, 500, "scene", "out of memory");
  }
  load_ctx lc = {.svc = svc, .files = &files};
  scene_load_opts lo = {.size = sizeof lo, .variant = variant, .resolve = resolve_file, .resolve_user = &lc};
  rsw_err err = {0};
  scene *sc = NULL;
  double t0 = svc_now();
  rsw_status st = scene_load_memory(body, len, name, is_xml, &lo, &sc, &err);
  double load_s = svc_now() - t0;
  unsigned char fd[32];
  sha_end(&files, fd);
  if (st) {
    free(canon);
    scene_error(e, &err);
    return st;
  }
  /* id = SHA-256("raysweep-scene-v1\n" format \n variant \n canonical \n
   * SHA-256 of the referenced files' digests). */
  unsigned char d[32];
  sha_ctx c;
  if (!canon || !sha_begin(&c)) {
    free(canon);
    scene_free(sc);
    return svc_fail(e, RSW_ERR_NOMEM, 500, "scene", "out of memory");
  }
  const char *vname = sc->variant == VARIANT_MONO ? "mono" : "rgb";
  sha_update(&c, "raysweep-scene-v1\n", 18);
  sha_update(&c, is_xml ? "xml\n" : "json\n", is_xml ? 4 : 5);
  sha_update(&c, vname, strlen(vname));
  sha_update(&c, "\n", 1);
  sha_update(&c, canon, strlen(canon));
  sha_update(&c, "\n", 1);
  sha_update(&c, fd, 32);
  sha_end(&c, d);
  free(canon);
  char id[65];
  hex(d, 32, id);
  pthread_mutex_lock(&svc->lock);
  resident *r = find_scene_locked(svc, id);
  if (r) {
    r->refs++;
    pthread_mutex_unlock(&svc->lock);
    scene_free(sc);
    *created = false;
    *out = r;
    return RSW_OK;
  }
  r = calloc(1, sizeof *r);
  bool ok = r && (svc->n_scenes < svc->cap_scenes ||
                  (svc->scenes =
                       realloc(svc->scenes, (svc->cap_scenes = svc->cap_scenes ? 2 * svc->cap_scenes : 8) *
                                                sizeof *svc->scenes)) != NULL);
  if (!ok) {
    pthread_mutex_unlock(&svc->lock);
    free(r);
    scene_free(sc);
    return svc_fail(e, RSW_ERR_NOMEM, 500, "scene", "out of memory");
  }
  memcpy(r->id, id, 65);
  r->sc = sc;
  r->load_s = load_s;
  r->created = time(NULL);
  pthread_mutex_init(&r->lock, NULL);
  pthread_mutex_init(&r->cache_lock, NULL);
  refresh_param_cache(r);
  r->refs = 1;
  svc->scenes[svc->n_scenes++] = r;
  if (!has_files && (svc->n_raw < svc->cap_raw ||
                     (svc->raw = realloc(svc->raw, (svc->cap_raw = svc->cap_raw ? 2 * svc->cap_raw : 8) *
                                                       sizeof *svc->raw)) != NULL)) {
    memcpy(svc->raw[svc->n_raw].digest, raw, 32);
    memcpy(svc->raw[svc->n_raw].id, id, 65);
    svc->n_raw++;
  }
  pthread_mutex_unlock(&svc->lock);
  *created = true;
  *out = r;
  return RSW_OK;
}

rsw_status service_scene_post(service *svc, const char *body, size_t len, bool is_xml, const char *variant,
                              bool *created, char **id_out, char **json_out, svc_error *e) {
  if (!service_ready(svc)) return svc_fail(e, RSW_ERR_UNAVAILABLE, 503, "", "the server is shutting down");
  resident *r;
  rsw_status st =
      scene_post(svc, body, len, is_xml, variant, is_xml ? "scene.xml" : "scene.json", created, &r, e);
  if (st) return st;
  cJSON *o = cJSON_CreateObject();
  svc_scene_summary(r, o);
  *id_out = strdup(r->id);
  *json_out = print_json(o);
  svc_scene_release(svc, r);
  return RSW_OK;
}

rsw_status service_scene_load_text(service *svc, const char *text, size_t len, bool is_xml, const char *name,
                                   char **id_out, svc_error *e) {
  bool created;
  resident *r;
  rsw_status st = scene_post(svc, text, len, is_xml, NULL, name, &created, &r, e);
  if (st) return st;
  if (id_out) *id_out = strdup(r->id);
  svc_scene_release(svc, r);
  return RSW_OK;
}

rsw_status service_scene_load_file(service *svc, const char *path, char **id_out, svc_error *e) {
  FILE *f = fopen(path, "rb");
  if (!f) return svc_fail(e, RSW_ERR_FILE, 422, path, "cannot open scene file: %s", strerror(errno));
  char *buf = NULL;
  size_t n = 0, cap = 0;
  for (;;) {
    if (n + 65536 > cap) {
      cap = cap ? 2 * cap : 1 << 17;
      char *p = realloc(buf, cap);
      if (!p) {
        free(buf);
        fclose(f);
        return svc_fail(e, RSW_ERR_NOMEM, 500, path, "out of memory");
      }
      buf = p;
    }
    size_t r = fread(buf + n, 1, cap - n, f);
    n += r;
    if (r == 0) break;
  }
  fclose(f);
  const char *dot = strrchr(path, '.');
  bool is_xml = dot ? strcmp(dot, ".xml") == 0 : (n && buf[0] == '<');
  /* Startup scenes may name files relative to their own directory: the
   * data root rule still applies when one is set; without one, load as the
   * CLI does. */
  rsw_status st;
  if (!svc->data_root[0]) {
    bool created;
    resident *r;
    /* Temporarily resolve relative to the file's directory. */
    char dir[4096];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (slash)
      *slash = '\0';
    else
      snprintf(dir, sizeof dir, ".");
    char *rp = realpath(dir, NULL);
    if (rp) {
      snprintf(svc->data_root, sizeof svc->data_root, "%s", rp);
      free(rp);
    }
    st = scene_post(svc, buf, n, is_xml, NULL, path, &created, &r, e);
    svc->data_root[0] = '\0';
    if (!st) {
      if (id_out) *id_out = strdup(r->id);
      svc_scene_release(svc, r);
    }
  } else {
    st = service_scene_load_text(svc, buf, n, is_xml, path, id_out, e);
  }
  free(buf);
  return st;
}

static cJSON *scene_info(service *svc, resident *r) {
  cJSON *o = cJSON_CreateObject();
  svc_scene_summary(r, o);
  cJSON_AddNumberToObject(o, "shapes", (double)r->sc->n_shapes);
  cJSON_AddNumberToObject(o, "emitters", (double)r->sc->n_emitters);
  cJSON_AddNumberToObject(o, "params", (double)params_count(r->sc));
  cJSON_AddNumberToObject(o, "resident_bytes", (double)scene_bytes(r->sc));
  cJSON_AddNumberToObject(o, "load_seconds", r->load_s);
  char iso[32];
  svc_iso_time(r->created, iso);
  cJSON_AddStringToObject(o, "created", iso);
  cJSON_AddNumberToObject(o, "jobs_active", r->active_jobs);
  (void)svc;
  return o;
}

rsw_status service_scene_list(service *svc, char **json_out, svc_error *e) {
  (void)e;
  cJSON *o = cJSON_CreateObject();
  cJSON *a = cJSON_AddArrayToObject(o, "scenes");
  pthread_mutex_lock(&svc->lock);
  for (size_t i = 0; i < svc->n_scenes; i++) cJSON_AddItemToArray(a, scene_info(svc, svc->scenes[i]));
  pthread_mutex_unlock(&svc->lock);
  *json_out = print_json(o);
  return RSW_OK;
}

static rsw_status no_scene(svc_error *e, const char *id) {
  return svc_fail(e, RSW_ERR_NOT_FOUND, 404, id, "no resident scene '%s'", id);
}

rsw_status service_scene_get(service *svc, const char *id, char **json_out, svc_error *e) {
  pthread_mutex_lock(&svc->lock);
  resident *r = find_scene_locked(svc, id);
  cJSON *o = r ? scene_info(svc, r) : NULL;
  pthread_mutex_unlock(&svc->lock);
  if (!o) return no_scene(e, id);
  *json_out = print_json(o);
  return RSW_OK;
}

rsw_status service_scene_delete(service *svc, const char *id, bool force, svc_error *e) {
  pthread_mutex_lock(&svc->lock);
  resident *r = find_scene_locked(svc, id);
  if (!r) {
    pthread_mutex_unlock(&svc->lock);
    return no_scene(e, id);
  }
  if (r->active_jobs && !force) {
    /* Name the jobs (the first few), so the answer says what to cancel. */
    char ids[160] = "";
    size_t used = 0, named = 0;
    for (size_t i = 0; i < svc->n_jobs && named < 3; i++) {
      const job *j = svc->jobs[i];
      if (j->deleted || j->res != r || (j->state != JOB_QUEUED && j->state != JOB_RUNNING)) continue;
      int k = snprintf(ids + used, sizeof ids - used, "%s%s", named ? ", " : "", j->id);
      if (k < 0 || (size_t)k >= sizeof ids - used) break;
      used += (size_t)k, named++;
    }
    int n = r->active_jobs;
    pthread_mutex_unlock(&svc->lock);
    return svc_fail(e, RSW_ERR_CONFLICT, 409, id,
                    "scene '%s' is in use by %d queued or running job(s) (%s%s); cancel them "
                    "(POST /v1/jobs/{id}:cancel) or delete with ?force=true, which cancels them first",
                    id, n, ids, n > (int)named ? ", ..." : "");
  }
  for (size_t i = 0; i < svc->n_jobs; i++)
    if (svc->jobs[i]->res == r && (svc->jobs[i]->state == JOB_QUEUED || svc->jobs[i]->state == JOB_RUNNING))
      atomic_store(&svc->jobs[i]->cancel, 1);
  for (size_t i = 0; i < svc->n_scenes; i++)
    if (svc->scenes[i] == r) {
      svc->scenes[i] = svc->scenes[--svc->n_scenes];
      break;
    }
  for (size_t i = 0; i < svc->n_raw;)
    if (strcmp(svc->raw[i].id, id) == 0)
      svc->raw[i] = svc->raw[--svc->n_raw];
    else
      i++;
  r->deleted = true;
  bool free_now = r->refs == 0;
  pthread_cond_broadcast(&svc->cond);
  pthread_mutex_unlock(&svc->lock);
  if (free_now) svc_resident_free(r);
  return RSW_OK;
}

/* ---- parameters ------------------------------------------------------------------ */

static cJSON *param_entry_json(const scene *sc, size_t i) {
  param_info pi;
  if (!params_info(sc, i, &pi)) return NULL;
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "key", pi.key);
  cJSON_AddStringToObject(o, "type", param_type_name(pi.type));
  cJSON_AddStringToObject(o, "class", update_class_name(pi.cls));
  cJSON *sh = cJSON_AddArrayToObject(o, "shape");
  cJSON_AddItemToArray(sh, cJSON_CreateNumber((double)pi.shape[0]));
  if (pi.shape[1]) cJSON_AddItemToArray(sh, cJSON_CreateNumber((double)pi.shape[1]));
  cJSON_AddStringToObject(o, "object_type", pi.object_type);
  cJSON_AddStringToObject(o, "object_class", pi.object_class);
  cJSON_AddStringToObject(o, "object_id", pi.object_id);
  char *v = params_value_json(sc, i, 16);
  cJSON *val = v ? cJSON_Parse(v) : NULL;
  free(v);
  cJSON_AddItemToObject(o, "value", val ? val : cJSON_CreateNull());
  cJSON *al = cJSON_AddArrayToObject(o, "aliases");
  for (size_t a = 0; a < pi.n_aliases; a++) cJSON_AddItemToArray(al, cJSON_CreateString(pi.aliases[a]));
  return o;
}

/* Rebuild the base-state cache; r->lock held (no overrides applied). */
static void refresh_param_cache(resident *r) {
  cJSON *a = cJSON_CreateArray();
  size_t n = params_count(r->sc);
  for (size_t i = 0; a && i < n; i++) {
    cJSON *p = param_entry_json(r->sc, i);
    cJSON_AddItemToArray(a, p ? p : cJSON_CreateNull());
  }
  pthread_mutex_lock(&r->cache_lock);
  cJSON_Delete(r->base_params);
  r->base_params = a;
  r->cache_revision = r->revision;
  pthread_mutex_unlock(&r->cache_lock);
}

/* An unknown-key error with the closest keys, for problem+json. */
static rsw_status key_error(svc_error *e, const scene *sc, const char *key, const rsw_err *err) {
  e->err = *err;
  e->http_status = err->code == RSW_ERR_NOMEM ? 500 : 422;
  snprintf(e->key, sizeof e->key, "%s", key);
  if (err->code == RSW_ERR_NOT_FOUND) {
    const char *c[3];
    size_t n = params_closest(sc, key, c);
    for (size_t i = 0; i < n; i++) snprintf(e->candidates[i], sizeof e->candidates[i], "%s", c[i]);
  }
  return err->code;
}

rsw_status service_params_get(service *svc, const char *id, const char *match, const char *cls,
                              char **json_out, uint64_t *revision_out, svc_error *e) {
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return no_scene(e, id);
  unsigned mask = UPDATE_SPECTRAL | UPDATE_GEOMETRIC;
  bool none = true;
  if (cls && *cls) {
    update_class c;
    if (!update_class_parse(cls, &c)) {
      svc_scene_release(svc, r);
      return svc_fail(e, RSW_ERR_INVALID, 400, "class",
                      "class must be spectral, geometric or none (got '%s')", cls);
    }
    mask = c == UPDATE_NONE ? 0 : (unsigned)c;
    none = c == UPDATE_NONE;
  }
  /* Matching reads only the table's keys and classes (fixed at load);
   * values come from the base-state cache, so this never waits for a
   * render. */
  size_t *idx = NULL, n = 0;
  rsw_err err = {0};
  rsw_status st = params_match(r->sc, match && *match ? match : "*", mask, none, &idx, &n, &err);
  cJSON *o = NULL;
  pthread_mutex_lock(&r->cache_lock);
  uint64_t rev = r->cache_revision;
  if (st == RSW_OK) {
    o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "revision", (double)rev);
    cJSON *a = cJSON_AddArrayToObject(o, "params");
    for (size_t k = 0; k < n; k++) {
      cJSON *p = cJSON_GetArrayItem(r->base_params, (int)idx[k]);
      if (p) cJSON_AddItemToArray(a, cJSON_Duplicate(p, 1));
    }
  } else if (st == RSW_ERR_NOT_FOUND && !strchr(match, ':')) {
    /* A glob matching nothing is an empty table, not an error, over HTTP. */
    o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "revision", (double)rev);
    cJSON_AddArrayToObject(o, "params");
    st = RSW_OK;
  } else {
    key_error(e, r->sc, match, &err);
  }
  pthread_mutex_unlock(&r->cache_lock);
  *revision_out = rev;
  free(idx);
  svc_scene_release(svc, r);
  if (st) return st;
  *json_out = print_json(o);
  return RSW_OK;
}

/* Parse a JSON object {key: value} into updates. Keys borrowed from j. */
static rsw_status map_to_updates(const cJSON *j, const scene *sc, const char *where, param_update **out,
                                 size_t *n, svc_error *e) {
  *out = NULL;
  *n = 0;
  if (!cJSON_IsObject(j))
    return svc_fail(e, RSW_ERR_TYPE, 422, where, "%s must be an object {key: value}", where);
  size_t cnt = 0;
  for (const cJSON *k = j->child; k; k = k->next) cnt++;
  param_update *u = calloc(cnt ? cnt : 1, sizeof *u);
  if (!u) return svc_fail(e, RSW_ERR_NOMEM, 500, where, "out of memory");
  size_t i = 0;
  for (const cJSON *k = j->child; k; k = k->next, i++) {
    u[i].key = k->string;
    char *txt = cJSON_PrintUnformatted(k);
    rsw_err err = {0};
    rsw_status st = txt ? param_value_parse(txt, k->string, &u[i].value, &err) : RSW_ERR_NOMEM;
    free(txt);
    if (st) {
      for (size_t q = 0; q < i; q++) param_value_free(&u[q].value);
      free(u);
      key_error(e, sc, k->string, &err);
      if (e->err.code == RSW_ERR_NOT_FOUND) e->candidates[0][0] = '\0';
      return st;
    }
  }
  *out = u;
  *n = cnt;
  return RSW_OK;
}

static void free_updates(param_update *u, size_t n) {
  for (size_t i = 0; i < n; i++) param_value_free(&u[i].value);
  free(u);
}

static rsw_status update_error(svc_error *e, const scene *sc, const param_update *u, size_t n,
                               const rsw_err *err) {
  /* Name the key the kernel complained about (err->where is the key). */
  const char *key = err->where;
  for (size_t i = 0; i < n; i++)
    if (strcmp(u[i].key, err->where) == 0) key = u[i].key;
  return key_error(e, sc, key, err);
}

rsw_status service_params_patch(service *svc, const char *id, const char *body, size_t len, int64_t if_match,
                                char **json_out, uint64_t *revision_out, svc_error *e) {
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return no_scene(e, id);
  cJSON *j = cJSON_ParseWithLength(body, len);
  if (!j) {
    svc_scene_release(svc, r);
    return svc_fail(e, RSW_ERR_PARSE, 400, "", "the body is not valid JSON");
  }
  pthread_mutex_lock(&r->lock);
  rsw_status st = RSW_OK;
  param_update *u = NULL;
  size_t n = 0;
  update_report rep = {0};
  if (if_match >= 0 && (uint64_t)if_match != r->revision)
    st = svc_fail(e, RSW_ERR_PRECONDITION, 412, "If-Match",
                  "revision %lld is stale: the scene is at revision %llu", (long long)if_match,
                  (unsigned long long)r->revision);
  if (!st) st = map_to_updates(j, r->sc, "body", &u, &n, e);
  if (!st) {
    rsw_err err = {0};
    st = scene_update(r->sc, u, n, &rep, &err);
    if (st) update_error(e, r->sc, u, n, &err);
  }
  if (!st && rep.changed) {
    r->revision++;
    refresh_param_cache(r);
  }
  *revision_out = r->revision;
  cJSON *o = NULL;
  if (!st) {
    o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "revision", (double)r->revision);
    cJSON_AddNumberToObject(o, "changed", (double)rep.changed);
    cJSON *c = cJSON_AddArrayToObject(o, "classes");
    if (rep.classes & UPDATE_SPECTRAL) cJSON_AddItemToArray(c, cJSON_CreateString("spectral"));
    if (rep.classes & UPDATE_GEOMETRIC) cJSON_AddItemToArray(c, cJSON_CreateString("geometric"));
    cJSON_AddNumberToObject(o, "seconds", rep.seconds);
  }
  pthread_mutex_unlock(&r->lock);
  if (!st) count_update(svc, &rep);
  free_updates(u, n);
  cJSON_Delete(j);
  svc_scene_release(svc, r);
  if (st) return st;
  *json_out = print_json(o);
  return RSW_OK;
}

/* ---- rendering ------------------------------------------------------------------- */

bool svc_find_sensor(const scene *sc, const char *name, size_t *index) {
  return scene_find_sensor(sc, name, index) != NULL;
}

void svc_film_free(svc_film *f) {
  if (f) film_image_free(&f->img);
}

/* The current values of the overridden keys, to restore the base state
 * after a render (values round-trip exactly through their JSON text). */
static rsw_status snapshot(const scene *sc, const param_update *u, size_t n, param_update **out,
                           rsw_err *err) {
  param_update *s = calloc(n ? n : 1, sizeof *s);
  if (!s) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  for (size_t i = 0; i < n; i++) {
    size_t idx;
    rsw_status st = params_lookup(sc, u[i].key, &idx, err);
    char *txt = st ? NULL : params_value_json(sc, idx, 0);
    if (!st && !txt) st = rsw_fail(err, RSW_ERR_NOMEM, u[i].key, "out of memory");
    if (!st) {
      s[i].key = u[i].key;
      st = param_value_parse(txt, u[i].key, &s[i].value, err);
    }
    free(txt);
    if (st) {
      for (size_t q = 0; q < i; q++) param_value_free(&s[q].value);
      free(s);
      return st;
    }
  }
  *out = s;
  return RSW_OK;
}

rsw_status svc_render_locked(service *svc, resident *r, const render_spec *rs, svc_film *out, svc_error *e) {
  scene *sc = r->sc;
  param_update *u = NULL, *restore = NULL;
  size_t n = 0;
  rsw_status st = RSW_OK;
  rsw_err err = {0};
  pthread_mutex_lock(&r->lock);
  if (rs->overrides) st = map_to_updates(rs->overrides, sc, "params", &u, &n, e);
  if (!st && n) {
    st = snapshot(sc, u, n, &restore, &err);
    if (st) update_error(e, sc, u, n, &err);
  }
  if (!st && n) {
    update_report rep;
    st = scene_update(sc, u, n, &rep, &err);
    if (st)
      update_error(e, sc, u, n, &err);
    else
      count_update(svc, &rep);
  }
  if (!st) {
    render_opts ro = {.size = sizeof ro,
                      .sensor = rs->sensor_index,
                      .spp = rs->spp,
                      .seed = rs->seed,
                      .wavelength = rs->wavelength,
                      .threads = svc->opts.render_threads,
                      .cancel = rs->cancel,
                      .deadline = rs->deadline};
    render_result_stats stats;
    rsw_err rerr = {0};
    st = render_sensor(sc, &ro, &out->img, &stats, &rerr);
    if (st) {
      e->err = rerr;
      e->http_status = st == RSW_ERR_TIMEOUT     ? 504
                       : st == RSW_ERR_CANCELLED ? 409
                       : st == RSW_ERR_NOMEM     ? 500
                                                 : 422;
    } else {
      pthread_mutex_lock(&svc->lock);
      svc->render_seconds += stats.wall_s;
      svc->unresolved_rays += stats.rays.unresolved;
      pthread_mutex_unlock(&svc->lock);
      memcpy(out->scene, r->id, 65);
      out->revision = r->revision;
      snprintf(out->sensor, sizeof out->sensor, "%s", sc->sensors[rs->sensor_index]->base.id);
    }
  }
  if (restore) {
    /* Back to the base state: the same values, so bitwise the base. */
    rsw_err rerr = {0};
    if (scene_update(sc, restore, n, NULL, &rerr) != RSW_OK && !st)
      st = svc_fail(e, rerr.code, 500, rerr.where, "restoring the base state failed: %s", rerr.msg);
    for (size_t i = 0; i < n; i++) param_value_free(&restore[i].value);
    free(restore);
  }
  pthread_mutex_unlock(&r->lock);
  free_updates(u, n);
  return st;
}

rsw_status service_render(service *svc, const char *id, const char *body, size_t len,
                          const atomic_int *cancel, svc_film *out, svc_error *e) {
  if (!service_ready(svc)) return svc_fail(e, RSW_ERR_UNAVAILABLE, 503, "", "the server is shutting down");
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return no_scene(e, id);
  memset(out, 0, sizeof *out);
  cJSON *j = len ? cJSON_ParseWithLength(body, len) : cJSON_CreateObject();
  rsw_status st = RSW_OK;
  render_spec rs = {.seed = 0, .cancel = cancel};
  if (!j)
    st = svc_fail(e, RSW_ERR_PARSE, 400, "", "the body is not valid JSON");
  else if (!cJSON_IsObject(j))
    st = svc_fail(e, RSW_ERR_TYPE, 422, "", "the body must be a JSON object");
  for (const cJSON *k = j && !st ? j->child : NULL; k && !st; k = k->next) {
    char ptr[300];
    snprintf(ptr, sizeof ptr, "/%s", k->string);
    if (strcmp(k->string, "sensor") == 0) {
      char buf[32];
      const char *name = cJSON_IsString(k) ? k->valuestring : NULL;
      if (cJSON_IsNumber(k) && k->valuedouble >= 0 && k->valuedouble == floor(k->valuedouble)) {
        snprintf(buf, sizeof buf, "%.0f", k->valuedouble);
        name = buf;
      }
      if (!name || !svc_find_sensor(r->sc, name, &rs.sensor_index))
        st = svc_fail(e, RSW_ERR_NOT_FOUND, 422, ptr, "no sensor '%s' in the scene", name ? name : "?");
    } else if (strcmp(k->string, "spp") == 0) {
      if (!cJSON_IsNumber(k) || k->valuedouble < 1 || k->valuedouble > 4294967295.0 ||
          k->valuedouble != floor(k->valuedouble))
        st = svc_fail(e, RSW_ERR_INVALID, 422, ptr, "spp must be a positive integer");
      else
        rs.spp = (uint32_t)k->valuedouble;
    } else if (strcmp(k->string, "seed") == 0) {
      if (!cJSON_IsNumber(k) || k->valuedouble < 0 || k->valuedouble > 9007199254740991.0 ||
          k->valuedouble != floor(k->valuedouble))
        st = svc_fail(e, RSW_ERR_INVALID, 422, ptr, "seed must be a non-negative integer");
      else
        rs.seed = (uint64_t)k->valuedouble;
    } else if (strcmp(k->string, "wavelength") == 0) {
      if (!cJSON_IsNumber(k) || !(k->valuedouble > 0) || !isfinite(k->valuedouble))
        st = svc_fail(e, RSW_ERR_INVALID, 422, ptr, "wavelength must be a positive number of nm");
      else
        rs.wavelength = k->valuedouble;
    } else if (strcmp(k->string, "params") == 0) {
      if (!cJSON_IsObject(k))
        st = svc_fail(e, RSW_ERR_TYPE, 422, ptr, "params must be an object {key: value}");
      else
        rs.overrides = k;
    } else if (strcmp(k->string, "timeout_s") == 0) {
      if (!cJSON_IsNumber(k) || !(k->valuedouble > 0))
        st = svc_fail(e, RSW_ERR_INVALID, 422, ptr, "timeout_s must be a positive number");
      else
        rs.deadline = svc_now() + k->valuedouble;
    } else {
      st = svc_fail(e, RSW_ERR_UNUSED_PROPERTY, 422, ptr,
                    "unknown field '%s' (expected sensor, spp, seed, wavelength, params, timeout_s)",
                    k->string);
    }
  }
  if (!st && rs.wavelength > 0 && r->sc->variant != VARIANT_MONO)
    st = svc_fail(e, RSW_ERR_INVALID, 422, "/wavelength",
                  "wavelength applies to mono scenes; this scene is rgb");
  if (!st && r->sc->n_sensors == 0)
    st = svc_fail(e, RSW_ERR_INVALID, 422, "/sensor", "the scene has no sensor");
  if (!st) {
    const sensor *se = r->sc->sensors[rs.sensor_index];
    uint64_t spp = rs.spp ? rs.spp : se->sampler->sample_count;
    uint64_t ps = (uint64_t)se->film->width * (uint64_t)se->film->height * spp;
    if (ps > svc->opts.max_pixel_samples)
      st = svc_fail(e, RSW_ERR_LIMIT, 422, "/spp", "%llu pixel samples exceed this server's limit of %llu",
                    (unsigned long long)ps, (unsigned long long)svc->opts.max_pixel_samples);
  }
  if (!st) {
    pthread_mutex_lock(&svc->lock);
    svc->sync_renders++;
    pthread_mutex_unlock(&svc->lock);
    st = svc_render_locked(svc, r, &rs, out, e);
    pthread_mutex_lock(&svc->lock);
    svc->sync_renders--;
    if (!st) svc->contexts_rendered++;
    pthread_mutex_unlock(&svc->lock);
    if (!st) snprintf(out->context, sizeof out->context, "render");
  }
  cJSON_Delete(j);
  svc_scene_release(svc, r);
  return st;
}

rsw_status service_directions(service *svc, const char *id, const char *sensor_name, char **json_out,
                              svc_error *e) {
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return no_scene(e, id);
  size_t si;
  rsw_status st = RSW_OK;
  if (!svc_find_sensor(r->sc, sensor_name, &si)) {
    svc_scene_release(svc, r);
    return svc_fail(e, RSW_ERR_NOT_FOUND, 404, sensor_name, "no sensor '%s' in scene %s", sensor_name, id);
  }
  pthread_mutex_lock(&r->lock);
  const sensor *se = r->sc->sensors[si];
  const char *type = se->base.plugin->name;
  cJSON *o = NULL;
  if (strcmp(type, "hdistant") != 0 && strcmp(type, "distant") != 0) {
    st = svc_fail(
        e, RSW_ERR_UNSUPPORTED, 422, sensor_name,
        "sensor '%s' is a %s; per-pixel directions exist for distant-family sensors (hdistant, distant)",
        sensor_name, type);
  } else {
    int W = se->film->width, H = se->film->height;
    o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "sensor", se->base.id);
    cJSON_AddNumberToObject(o, "width", W);
    cJSON_AddNumberToObject(o, "height", H);
    cJSON_AddStringToObject(o, "convention", "east_right");
    cJSON *px = cJSON_AddArrayToObject(o, "pixels");
    for (int iy = 0; iy < H; iy++)
      for (int ix = 0; ix < W; ix++) {
        /* hdistant: omega = to_world H(u) at the pixel centre
         * (kernel-behavior.md §1.2); angles from the local vector, as
         * Eradiate's post-processing (theta = acos z, phi = atan2(y, x),
         * east-right). distant: omega = -(to_world z). */
        vec3 local, w;
        if (strcmp(type, "hdistant") == 0) {
          local = warp_square_to_uniform_hemisphere(v2((ix + 0.5) / W, (iy + 0.5) / H));
          w = v3_norm(xf_vector(&se->to_world, local));
        } else {
          local = v3(0, 0, 1);
          w = v3_neg(v3_norm(xf_vector(&se->to_world, v3(0, 0, 1))));
          local = w;
        }
        double zen = acos(fmax(-1.0, fmin(1.0, local.z))) * 180.0 / RSW_PI;
        double az = atan2(local.y, local.x) * 180.0 / RSW_PI;
        if (az < 0) az += 360.0;
        cJSON *p = cJSON_CreateObject();
        cJSON_AddNumberToObject(p, "ix", ix);
        cJSON_AddNumberToObject(p, "iy", iy);
        cJSON_AddNumberToObject(p, "x", w.x);
        cJSON_AddNumberToObject(p, "y", w.y);
        cJSON_AddNumberToObject(p, "z", w.z);
        cJSON_AddNumberToObject(p, "zenith_deg", zen);
        cJSON_AddNumberToObject(p, "azimuth_deg", az);
        cJSON_AddItemToArray(px, p);
      }
  }
  pthread_mutex_unlock(&r->lock);
  svc_scene_release(svc, r);
  if (st) return st;
  *json_out = print_json(o);
  return RSW_OK;
}

/* ---- blobs ----------------------------------------------------------------------- */

rsw_status service_blob_put(service *svc, const char *h, const void *data, size_t len, bool *created,
                            svc_error *e) {
  if (!is_hex64(h))
    return svc_fail(e, RSW_ERR_INVALID, 400, h, "a blob is named by its SHA-256: 64 lowercase hex digits");
  unsigned char d[32];
  char dh[65];
  if (!sha256(data, len, d)) return svc_fail(e, RSW_ERR_NOMEM, 500, h, "hashing failed");
  hex(d, 32, dh);
  if (strcmp(dh, h) != 0)
    return svc_fail(e, RSW_ERR_INVALID, 422, h, "the body's SHA-256 is %s, not %s", dh, h);
  char path[8192], tmp[8300];
  snprintf(path, sizeof path, "%s/%s", svc->blob_dir, h);
  struct stat sb;
  if (stat(path, &sb) == 0) {
    *created = false;
    return RSW_OK;
  }
  snprintf(tmp, sizeof tmp, "%s.tmp.%ld.%lu", path, (long)getpid(), (unsigned long)pthread_self());
  FILE *f = fopen(tmp, "wb");
  if (!f) return svc_fail(e, RSW_ERR_IO, 500, h, "cannot store the blob: %s", strerror(errno));
  bool ok = fwrite(data, 1, len, f) == len;
  ok = fclose(f) == 0 && ok;
  if (!ok || rename(tmp, path) != 0) {
    remove(tmp);
    return svc_fail(e, RSW_ERR_IO, 500, h, "cannot store the blob");
  }
  *created = true;
  return RSW_OK;
}

long long service_blob_size(service *svc, const char *h) {
  if (!is_hex64(h)) return -1;
  char path[8192];
  snprintf(path, sizeof path, "%s/%s", svc->blob_dir, h);
  struct stat sb;
  return stat(path, &sb) == 0 ? (long long)sb.st_size : -1;
}

bool service_blob_exists(service *svc, const char *h) {
  if (!is_hex64(h)) return false;
  char path[8192];
  snprintf(path, sizeof path, "%s/%s", svc->blob_dir, h);
  struct stat sb;
  return stat(path, &sb) == 0;
}

rsw_status service_blobs_missing(service *svc, const char *body, size_t len, char **json_out, svc_error *e) {
  cJSON *j = cJSON_ParseWithLength(body, len);
  if (!j) return svc_fail(e, RSW_ERR_PARSE, 400, "", "the body is not valid JSON");
  const cJSON *d = cJSON_GetObjectItemCaseSensitive(j, "digests");
  if (!cJSON_IsArray(d)) {
    cJSON_Delete(j);
    return svc_fail(e, RSW_ERR_TYPE, 422, "/digests", "expected {\"digests\": [sha256 hex, ...]}");
  }
  cJSON *o = cJSON_CreateObject();
  cJSON *m = cJSON_AddArrayToObject(o, "missing");
  int i = 0;
  for (const cJSON *x = d->child; x; x = x->next, i++) {
    if (!cJSON_IsString(x) || !is_hex64(x->valuestring)) {
      cJSON_Delete(o);
      cJSON_Delete(j);
      char ptr[32];
      snprintf(ptr, sizeof ptr, "/digests/%d", i);
      return svc_fail(e, RSW_ERR_INVALID, 422, ptr, "not a SHA-256 hex digest");
    }
    if (!service_blob_exists(svc, x->valuestring))
      cJSON_AddItemToArray(m, cJSON_CreateString(x->valuestring));
  }
  cJSON_Delete(j);
  *json_out = print_json(o);
  return RSW_OK;
}
