/* Resident scenes: load from a body or a file (blobs and data-root
 * files resolved, every referenced file's digest in the scene id), the
 * registry, summaries, deletion. */
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../kernel/scene/loader.h"
#include "buf.h"
#include "rsw_sha256.h"
#include "service_internal.h"

/* File references while loading: blobs by digest, plain names inside the
 * data root; every digest goes into the scene id. */
typedef struct load_ctx {
  service *svc;
  rsw_sha256_ctx *files; /* digests of referenced files, in reference order */
} load_ctx;

static rsw_status resolve_file(void *user, const char *name, char **path_out, rsw_err *err) {
  load_ctx *lc = user;
  service *svc = lc->svc;
  char path[8192];
  unsigned char d[32];
  char dh[65];
  if (strncmp(name, "sha256:", 7) == 0) {
    if (!rsw_is_sha256_hex(name + 7))
      return rsw_fail(err, RSW_ERR_INVALID, name, "'%s' is not sha256:<64 lowercase hex digits>", name);
    snprintf(path, sizeof path, "%s/%s", svc->blob_dir, name + 7);
    struct stat sb;
    if (stat(path, &sb) != 0)
      return rsw_fail(err, RSW_ERR_FILE, name, "blob %s has not been uploaded (PUT /v1/blobs/%s)", name + 7,
                      name + 7);
    if (!S_ISREG(sb.st_mode) || access(path, R_OK) != 0)
      return rsw_fail(err, RSW_ERR_FILE, name, "blob %s cannot be read on the server (upload it again)",
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
    if (!rsw_sha256_file(path, d)) return rsw_fail(err, RSW_ERR_FILE, name, "cannot read '%s'", name);
    rsw_hex(d, 32, dh);
  }
  if (lc->files) {
    rsw_sha256_update(lc->files, "file ", 5);
    rsw_sha256_update(lc->files, dh, 64);
    rsw_sha256_update(lc->files, "\n", 1);
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

resident *svc_find_scene_locked(service *svc, const char *id) {
  for (size_t i = 0; i < svc->n_scenes; i++)
    if (strcmp(svc->scenes[i]->id, id) == 0) return svc->scenes[i];
  return NULL;
}

resident *svc_scene_acquire(service *svc, const char *id) {
  pthread_mutex_lock(&svc->lock);
  resident *r = svc_find_scene_locked(svc, id);
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

/* Replace every "prefix/" in s (a string in cap bytes) by repl, cutting
 * the end if it no longer fits. */
static void scrub(char *s, size_t cap, const char *prefix, const char *repl) {
  size_t lp = strlen(prefix), lr = strlen(repl);
  if (!lp || !cap) return;
  char *p = s;
  while ((p = strstr(p, prefix)) && p[lp] == '/') {
    size_t at = (size_t)(p - s);
    if (at + lr >= cap) {
      *p = '\0';
      return;
    }
    size_t tail = strlen(p + lp + 1);
    if (at + lr + tail >= cap) tail = cap - 1 - at - lr;
    memmove(p + lr, p + lp + 1, tail);
    memcpy(p, repl, lr);
    p[lr + tail] = '\0';
    p += lr;
  }
}

static void scene_error(svc_error *e, const service *svc, const rsw_err *err) {
  e->err = *err;
  /* A file the scene names that cannot be found or read is the request's
   * fault (422), not the server's. */
  if (err->code == RSW_ERR_IO || err->code == RSW_ERR_NOT_FOUND) e->err.code = RSW_ERR_FILE;
  /* Errors about a file name its path as the reader opened it: say it the
   * way the scene did (sha256:<hex>, a name under the data root), never
   * the server's own directories. */
  scrub(e->err.where, sizeof e->err.where, svc->blob_dir, "sha256:");
  scrub(e->err.msg, sizeof e->err.msg, svc->blob_dir, "sha256:");
  scrub(e->err.where, sizeof e->err.where, svc->data_root, "");
  scrub(e->err.msg, sizeof e->err.msg, svc->data_root, "");
}

/* Load, compute the id, register (or find the existing one). */
static rsw_status scene_post(service *svc, const char *body, size_t len, bool is_xml, const char *variant,
                             const char *name, bool *created, resident **out, svc_error *e) {
  if (variant && strcmp(variant, "mono") != 0 && strcmp(variant, "rgb") != 0)
    return svc_fail(e, RSW_ERR_BAD_REQUEST, "variant", "variant must be mono or rgb (got '%s')", variant);
  /* Same text and variant as an earlier post: the same scene (cheap path;
   * files it references are content-addressed or re-hashed on a load). */
  unsigned char raw[32];
  {
    rsw_sha256_ctx c;
    if (!rsw_sha256_begin(&c)) return svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
    rsw_sha256_update(&c, is_xml ? "xml\n" : "json\n", is_xml ? 4 : 5);
    rsw_sha256_update(&c, variant ? variant : "-", variant ? strlen(variant) : 1);
    rsw_sha256_update(&c, "\n", 1);
    rsw_sha256_update(&c, body, len);
    rsw_sha256_end(&c, raw);
  }
  bool has_files = memmem(body, len, "filename", 8) != NULL;
  if (!has_files) {
    pthread_mutex_lock(&svc->lock);
    for (size_t i = 0; i < svc->n_raw; i++)
      if (memcmp(svc->raw[i].digest, raw, 32) == 0) {
        resident *r = svc_find_scene_locked(svc, svc->raw[i].id);
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
  rsw_sha256_ctx files;
  if (!rsw_sha256_begin(&files)) {
    free(canon);
    return svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
  }
  load_ctx lc = {.svc = svc, .files = &files};
  scene_load_opts lo = {.size = sizeof lo, .variant = variant, .resolve = resolve_file, .resolve_user = &lc};
  rsw_err err = {0};
  scene *sc = NULL;
  double t0 = svc_now();
  rsw_status st = scene_load_memory(body, len, name, is_xml, &lo, &sc, &err);
  double load_s = svc_now() - t0;
  unsigned char fd[32];
  rsw_sha256_end(&files, fd);
  if (st) {
    free(canon);
    scene_error(e, svc, &err);
    return e->err.code;
  }
  /* id = SHA-256("raysweep-scene-v1\n" format \n variant \n canonical \n
   * SHA-256 of the referenced files' digests). */
  unsigned char d[32];
  rsw_sha256_ctx c;
  if (!canon || !rsw_sha256_begin(&c)) {
    free(canon);
    scene_free(sc);
    return svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
  }
  const char *vname = sc->variant == VARIANT_MONO ? "mono" : "rgb";
  rsw_sha256_update(&c, "raysweep-scene-v1\n", 18);
  rsw_sha256_update(&c, is_xml ? "xml\n" : "json\n", is_xml ? 4 : 5);
  rsw_sha256_update(&c, vname, strlen(vname));
  rsw_sha256_update(&c, "\n", 1);
  rsw_sha256_update(&c, canon, strlen(canon));
  rsw_sha256_update(&c, "\n", 1);
  rsw_sha256_update(&c, fd, 32);
  rsw_sha256_end(&c, d);
  free(canon);
  char id[65];
  rsw_hex(d, 32, id);
  pthread_mutex_lock(&svc->lock);
  resident *r = svc_find_scene_locked(svc, id);
  if (r) {
    r->refs++;
    pthread_mutex_unlock(&svc->lock);
    scene_free(sc);
    *created = false;
    *out = r;
    return RSW_OK;
  }
  r = calloc(1, sizeof *r);
  bool ok = r && svc_grow((void **)&svc->scenes, &svc->cap_scenes, svc->n_scenes + 1, sizeof *svc->scenes, 0);
  if (!ok) {
    pthread_mutex_unlock(&svc->lock);
    free(r);
    scene_free(sc);
    return svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
  }
  memcpy(r->id, id, 65);
  r->sc = sc;
  r->load_s = load_s;
  r->created = time(NULL);
  pthread_mutex_init(&r->lock, NULL);
  pthread_mutex_init(&r->cache_lock, NULL);
  svc_refresh_param_cache(r);
  r->refs = 1;
  svc->scenes[svc->n_scenes++] = r;
  if (!has_files && svc_grow((void **)&svc->raw, &svc->cap_raw, svc->n_raw + 1, sizeof *svc->raw, 0)) {
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
  if (!service_ready(svc)) return svc_fail(e, RSW_ERR_UNAVAILABLE, "", "the server is shutting down");
  resident *r;
  rsw_status st =
      scene_post(svc, body, len, is_xml, variant, is_xml ? "scene.xml" : "scene.json", created, &r, e);
  if (st) return st;
  cJSON *o = cJSON_CreateObject();
  svc_scene_summary(r, o);
  *id_out = strdup(r->id);
  *json_out = svc_print_json(o);
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
  if (!f) return svc_fail(e, RSW_ERR_FILE, path, "cannot open scene file: %s", strerror(errno));
  char *buf = NULL;
  size_t n = 0, cap = 0;
  for (;;) {
    if (n + 65536 > cap) {
      cap = cap ? 2 * cap : 1 << 17;
      char *p = realloc(buf, cap);
      if (!p) {
        free(buf);
        fclose(f);
        return svc_fail(e, RSW_ERR_NOMEM, path, "out of memory");
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
  cJSON_AddNumberToObject(o, "resident_bytes", (double)svc_scene_bytes(r->sc));
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
  *json_out = svc_print_json(o);
  return RSW_OK;
}

rsw_status svc_no_scene(svc_error *e, const char *id) {
  return svc_fail(e, RSW_ERR_NOT_FOUND, id, "no resident scene '%s'", id);
}

rsw_status service_scene_get(service *svc, const char *id, char **json_out, svc_error *e) {
  pthread_mutex_lock(&svc->lock);
  resident *r = svc_find_scene_locked(svc, id);
  cJSON *o = r ? scene_info(svc, r) : NULL;
  pthread_mutex_unlock(&svc->lock);
  if (!o) return svc_no_scene(e, id);
  *json_out = svc_print_json(o);
  return RSW_OK;
}

rsw_status service_scene_delete(service *svc, const char *id, bool force, svc_error *e) {
  pthread_mutex_lock(&svc->lock);
  resident *r = svc_find_scene_locked(svc, id);
  if (!r) {
    pthread_mutex_unlock(&svc->lock);
    return svc_no_scene(e, id);
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
    return svc_fail(e, RSW_ERR_CONFLICT, id,
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
