/* Resident scenes: load from a body or a file (blobs and data-root
 * files resolved, every referenced file's digest in the scene id), the
 * registry, summaries, deletion, reset and copy.
 *
 * A document yields its own state (docs/daemon.md#a-document-yields-its-own-state):
 * a push is handed the document's resident scene (its twin, id = the
 * document's digest) only while the twin is in the document's state (no
 * PATCH recorded since its load or its last reset). Once the twin has
 * changed, a push gets a fork: a scene of its own, loaded from the
 * document, with a fresh id and `doc` naming the document, handed to later
 * pushes in turn while it is unchanged. A copy (POST :copy) is loaded the
 * same way with its source's PATCHes and is never handed to a pusher. */
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../kernel/scene/loader.h"
#include "buf.h"
#include "rsw_file.h"
#include "rsw_sha256.h"
#include "service_internal.h"
#include "templates.h"

/* File references while loading: blobs by digest, plain names inside the
 * data root; every digest goes into the scene id. */
typedef struct load_ctx {
  service *svc;
  rsw_sha256_ctx *files; /* digests of referenced files, in reference order */
  const char *root;      /* the data root (NULL: svc->data_root) */
} load_ctx;

static rsw_status resolve_file(void *user, const char *name, char **path_out, rsw_err *err) {
  load_ctx *lc = user;
  service *svc = lc->svc;
  const char *data_root = lc->root ? lc->root : svc->data_root;
  char path[8192];
  unsigned char d[32];
  char dh[65];
  if (strncmp(name, "sha256:", 7) == 0) {
    if (!rsw_is_sha256_hex(name + 7))
      return rsw_fail(err, RSW_ERR_INVALID, name, "'%s' is not sha256:<64 lowercase hex digits>", name);
    snprintf(path, sizeof path, "%s/%s", svc->blob_dir, name + 7);
    /* Opened as the kernel will read it (no symbolic link, no FIFO), and
     * checked against its name: a blob is what its digest says. */
    int fd = rsw_open_regular(path, true);
    if (fd < 0 && errno == ENOENT)
      return rsw_fail(err, RSW_ERR_FILE, name, "blob %s has not been uploaded (PUT /v1/blobs/%s)", name + 7,
                      name + 7);
    bool same = fd >= 0 && rsw_sha256_fd(fd, d) && (rsw_hex(d, 32, dh), strcmp(dh, name + 7) == 0);
    if (fd >= 0) close(fd);
    if (!same)
      return rsw_fail(err, RSW_ERR_FILE, name, "blob %s cannot be read on the server (upload it again)",
                      name + 7);
  } else {
    if (!data_root[0])
      return rsw_fail(
          err, RSW_ERR_FILE, name,
          "file '%s': this daemon has no --data-root; upload it as a blob and refer to it as sha256:<hex>",
          name);
    if (name[0] == '/')
      snprintf(path, sizeof path, "%s", name);
    else
      snprintf(path, sizeof path, "%s/%s", data_root, name);
    /* Symbolic links are followed only while they stay inside the root. */
    char *rp = realpath(path, NULL);
    if (!rp) return rsw_fail(err, RSW_ERR_FILE, name, "file '%s' not found under the data root", name);
    size_t lr = strlen(data_root);
    bool inside = strncmp(rp, data_root, lr) == 0 && rp[lr] == '/';
    if (!inside) {
      free(rp);
      return rsw_fail(err, RSW_ERR_FILE, name, "file '%s' lies outside the data root", name);
    }
    snprintf(path, sizeof path, "%s", rp);
    free(rp);
    /* The resolved path has no link left: O_NOFOLLOW refuses one planted
     * since; O_NONBLOCK and fstat refuse a FIFO or device (never a hang). */
    int fd = rsw_open_regular(path, true);
    if (fd < 0)
      return rsw_fail(err, RSW_ERR_FILE, name, "cannot read '%s': %s", name, rsw_open_strerror(errno));
    bool hashed = rsw_sha256_fd(fd, d);
    close(fd);
    if (!hashed) return rsw_fail(err, RSW_ERR_FILE, name, "cannot read '%s'", name);
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

/* The bytes a resident scene counts against --max-scene-bytes: its
 * geometry and acceleration structures (svc_scene_bytes) plus what the
 * object graph, the parameter table and Embree's per-scene objects take,
 * which svc_scene_bytes does not see: measured as resident-set growth over
 * 200-300 distinct loads (2026-11-23), 47 KB for a one-rectangle scene and
 * 103 KB for a five-rectangle one, i.e. about 33 KB a scene and 14 KB a
 * shape; rounded up. */
#define SCENE_OVERHEAD_BYTES ((size_t)36 << 10)
#define SHAPE_OVERHEAD_BYTES ((size_t)16 << 10)

static size_t budget_bytes(const scene *sc) {
  return svc_scene_bytes(sc) + SCENE_OVERHEAD_BYTES + SHAPE_OVERHEAD_BYTES * sc->n_shapes;
}

/* Whether this thread's last svc_scene_acquire missed a scene that was
 * evicted (and could not be reloaded): svc_no_scene, which every caller
 * answers a miss with, then says so (RSW_ERR_EVICTED). */
static _Thread_local bool last_miss_evicted;

static rsw_status scene_post(service *svc, const char *body, size_t len, bool is_xml, const char *variant,
                             const char *name, const struct post_extra *x, bool *created, resident **out,
                             svc_error *e);

/* Reload a scene from the state directory by id: its posted text and the
 * parameters PATCHed since, at its revision. */
static resident *scene_reload(service *svc, const char *id) {
  char *body;
  size_t len;
  bool is_xml;
  char variant[32];
  cJSON *patched;
  uint64_t revision;
  char doc[65];
  bool copy;
  if (!svc_state_scene_read(svc, id, &body, &len, &is_xml, variant, &patched, &revision, doc, &copy))
    return NULL;
  struct post_extra x = {
      .expect_id = id, .doc = doc[0] ? doc : NULL, .copy = copy, .patched = patched, .revision = revision};
  svc_error e = {0};
  bool created;
  resident *r = NULL;
  if (scene_post(svc, body, len, is_xml, variant[0] ? variant : NULL, is_xml ? "scene.xml" : "scene.json", &x,
                 &created, &r, &e) != RSW_OK) {
    char msg[1200];
    fprintf(stderr, "raysweepd: state: cannot reload scene %s: %s\n", id,
            rsw_err_format(&e.err, msg, sizeof msg));
    r = NULL;
  } else if (created) {
    pthread_mutex_lock(&svc->lock);
    svc->scenes_reloaded++;
    pthread_mutex_unlock(&svc->lock);
  }
  cJSON_Delete(patched);
  free(body);
  return r;
}

resident *svc_scene_acquire(service *svc, const char *id) {
  pthread_mutex_lock(&svc->lock);
  resident *r = svc_find_scene_locked(svc, id);
  if (r) {
    r->refs++;
    r->last_used = ++svc->use_clock;
  }
  bool evicted = !r && svc_was_evicted_locked(svc, id);
  pthread_mutex_unlock(&svc->lock);
  if (!r) r = scene_reload(svc, id); /* NULL without a state directory */
  last_miss_evicted = !r && evicted;
  return r;
}

bool svc_was_evicted_locked(service *svc, const char *id) {
  for (size_t i = 0; i < svc->n_evicted; i++)
    if (strcmp(svc->evicted[i], id) == 0) return true;
  return false;
}

void svc_forget_evicted_locked(service *svc, const char *id) {
  for (size_t i = 0; i < svc->n_evicted; i++)
    if (strcmp(svc->evicted[i], id) == 0) svc->evicted[i][0] = '\0';
}

/* The ids of evicted scenes, remembered so a request for one says why it
 * is gone: a ring of the last EVICTED_MEMORY evictions. */
#define EVICTED_MEMORY 4096

static void remember_evicted_locked(service *svc, const char *id) {
  if (!svc->evicted) {
    svc->evicted = calloc(EVICTED_MEMORY, sizeof *svc->evicted);
    if (!svc->evicted) return;
  }
  memcpy(svc->evicted[svc->evicted_next], id, 65);
  svc->evicted_next = (svc->evicted_next + 1) % EVICTED_MEMORY;
  if (svc->n_evicted < EVICTED_MEMORY) svc->n_evicted++;
}

/* Remove r from the registry (svc->lock held); the caller frees it when
 * no one holds it. */
static void unregister_locked(service *svc, resident *r) {
  for (size_t i = 0; i < svc->n_scenes; i++)
    if (svc->scenes[i] == r) {
      svc->scenes[i] = svc->scenes[--svc->n_scenes];
      break;
    }
  for (size_t i = 0; i < svc->n_raw;)
    if (strcmp(svc->raw[i].id, r->id) == 0)
      svc->raw[i] = svc->raw[--svc->n_raw];
    else
      i++;
  svc->scene_bytes -= r->bytes;
  r->deleted = true;
}

resident **svc_evict_locked(service *svc, const resident *keep) {
  uint64_t budget = svc->opts.max_scene_bytes;
  resident **ev = NULL;
  size_t n = 0, cap = 0;
  while (budget && svc->scene_bytes > budget) {
    resident *lru = NULL;
    for (size_t i = 0; i < svc->n_scenes; i++) {
      resident *c = svc->scenes[i];
      if (c == keep || c->pinned || c->refs || c->active_jobs) continue;
      if (!lru || c->last_used < lru->last_used) lru = c;
    }
    if (!lru || !svc_grow((void **)&ev, &cap, n + 2, sizeof *ev, 0)) break;
    unregister_locked(svc, lru);
    remember_evicted_locked(svc, lru->id);
    svc->scenes_evicted++;
    ev[n++] = lru;
    ev[n] = NULL;
  }
  return ev;
}

void svc_free_evicted(resident **ev) {
  for (size_t i = 0; ev && ev[i]; i++) svc_resident_free(ev[i]);
  free(ev);
}

rsw_status svc_scene_patched(service *svc, resident *r, svc_error *e) {
  rsw_status st = svc_state_scene_patched(svc, r, e);
  if (st) return st;
  size_t b = budget_bytes(r->sc);
  pthread_mutex_lock(&svc->lock);
  svc->scene_bytes += b - r->bytes;
  r->bytes = b;
  pthread_mutex_unlock(&svc->lock);
  return RSW_OK;
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
  cJSON_AddStringToObject(o, "document", r->doc);
  cJSON_AddBoolToObject(o, "copy", r->copy);
  cJSON_AddStringToObject(o, "variant", variant_name(r->sc->variant, r->sc->polarized));
  cJSON *s = cJSON_AddArrayToObject(o, "sensors");
  for (size_t i = 0; i < r->sc->n_sensors; i++)
    svc_json_push(s, cJSON_CreateString(r->sc->sensors[i]->base.id));
  cJSON_AddNumberToObject(o, "revision", (double)r->revision);
  if (r->label[0]) cJSON_AddStringToObject(o, "name", r->label);
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

/* A new id for a fork or copy of document doc: not its content's digest
 * (that is doc) but unique: SHA-256 of doc and 32 random bytes. */
static bool fresh_id(const char *doc, char out[65]) {
  unsigned char rnd[32], d[32];
  rsw_sha256_ctx c;
  if (getrandom(rnd, sizeof rnd, 0) != (ssize_t)sizeof rnd || !rsw_sha256_begin(&c)) return false;
  rsw_sha256_update(&c, "raysweep-scene-fork-v1\n", 23);
  rsw_sha256_update(&c, doc, 64);
  rsw_sha256_update(&c, rnd, sizeof rnd);
  rsw_sha256_end(&c, d);
  rsw_hex(d, 32, out);
  return true;
}

/* Whether r is in its document's state: no PATCH recorded since its load
 * or its last reset (r->patches NULL: unknown, so no). */
static bool in_document_state(resident *r) {
  pthread_mutex_lock(&r->lock);
  bool same = r->patches && !r->patches->child && !r->broken;
  pthread_mutex_unlock(&r->lock);
  return same;
}

/* A resident scene of document doc in the document's state that a push
 * may be handed, with a ref: the twin first, else a fork; never a copy.
 * NULL when there is none. svc->lock not held (r->lock is taken after it
 * is released: a PATCH holds r->lock, then svc->lock). */
static resident *twin_acquire(service *svc, const char *doc) {
  resident **c = NULL;
  size_t n = 0, cap = 0;
  pthread_mutex_lock(&svc->lock);
  for (size_t i = 0; i < svc->n_scenes; i++) {
    resident *r = svc->scenes[i];
    if (r->copy || strcmp(r->doc, doc) != 0) continue;
    if (!svc_grow((void **)&c, &cap, n + 1, sizeof *c, 0)) break;
    r->refs++;
    c[n++] = r;
  }
  pthread_mutex_unlock(&svc->lock);
  resident *found = NULL;
  for (int twin = 1; twin >= 0 && !found; twin--)
    for (size_t i = 0; i < n && !found; i++)
      if ((strcmp(c[i]->id, doc) == 0) == twin && in_document_state(c[i])) found = c[i];
  for (size_t i = 0; i < n; i++)
    if (c[i] != found) svc_scene_release(svc, c[i]);
  free(c);
  if (found) {
    pthread_mutex_lock(&svc->lock);
    found->last_used = ++svc->use_clock;
    pthread_mutex_unlock(&svc->lock);
  }
  return found;
}

/* A new resident scene holding sc and templates, not registered yet; NULL
 * when out of memory (sc and templates then stay the caller's). */
static resident *resident_alloc(scene *sc, cJSON *templates, const char *id, const char *doc, size_t bytes) {
  resident *r = calloc(1, sizeof *r);
  if (!r) return NULL;
  memcpy(r->id, id, 65);
  memcpy(r->doc, doc, 65);
  r->sc = sc;
  r->templates = templates;
  r->bytes = bytes;
  r->created = time(NULL);
  pthread_mutex_init(&r->lock, NULL);
  pthread_cond_init(&r->cond, NULL);
  pthread_mutex_init(&r->cache_lock, NULL);
  return r;
}

/* Register r (svc->lock held, room made in svc->scenes) with one ref for
 * the caller; returns the scenes the budget evicts for it
 * (svc_free_evicted, after the lock). */
static resident **add_locked(service *svc, resident *r) {
  r->refs = 1;
  r->last_used = ++svc->use_clock;
  svc->scenes[svc->n_scenes++] = r;
  svc->scene_bytes += r->bytes;
  svc_forget_evicted_locked(svc, r->id);
  return svc_evict_locked(svc, r);
}

/* Load, compute the id, register (or find the existing one). x (may be
 * NULL): a startup scene (pinned, not stored) or a reload from the state
 * directory (the id it must have, the parameters to apply first). */
static rsw_status scene_post(service *svc, const char *body, size_t len, bool is_xml, const char *variant,
                             const char *name, const struct post_extra *x, bool *created, resident **out,
                             svc_error *e) {
  rsw_variant v_parsed;
  bool v_pol;
  if (variant &&
      (strlen(variant) >= sizeof((resident *)0)->src_variant || !variant_parse(variant, &v_parsed, &v_pol)))
    return svc_fail(e, RSW_ERR_BAD_REQUEST, "variant",
                    "variant must be mono, rgb, mono_polarized or rgb_polarized (got '%s')", variant);
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
  if (!has_files && !x) {
    char doc[65] = "";
    pthread_mutex_lock(&svc->lock);
    for (size_t i = 0; i < svc->n_raw && !doc[0]; i++)
      if (memcmp(svc->raw[i].digest, raw, 32) == 0) memcpy(doc, svc->raw[i].id, 65);
    pthread_mutex_unlock(&svc->lock);
    resident *r = doc[0] ? twin_acquire(svc, doc) : NULL;
    if (r) {
      *created = false;
      *out = r;
      return RSW_OK;
    }
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
  /* The document's parameter-map templates: every form and key checked
   * now (422 naming /templates/KEY), rendered per context by jobs. They
   * are part of the canonical text, hence of the id. */
  cJSON *templates = NULL;
  if (!is_xml && memmem(body, len, "\"templates\"", 11)) {
    cJSON *doc = cJSON_ParseWithLength(body, len); /* parsed once already: NULL is out of memory */
    templates = doc ? cJSON_DetachItemFromObjectCaseSensitive(doc, "templates") : NULL;
    cJSON_Delete(doc);
    tmpl_set *ts = NULL;
    char tp[300];
    snprintf(tp, sizeof tp, "%s#/templates", name ? name : "scene.json");
    st = doc ? tmpl_compile(sc, templates, tp, NULL, NULL, &ts, e)
             : svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
    tmpl_free(ts);
    if (st) {
      cJSON_Delete(templates);
      free(canon);
      scene_free(sc);
      return st;
    }
  }
  /* id = SHA-256("raysweep-scene-v1\n" format \n variant \n canonical \n
   * SHA-256 of the referenced files' digests). */
  unsigned char d[32];
  rsw_sha256_ctx c;
  if (!canon || !rsw_sha256_begin(&c)) {
    free(canon);
    scene_free(sc);
    cJSON_Delete(templates);
    return svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
  }
  const char *vname = variant_name(sc->variant, sc->polarized);
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
  const char *expect_doc = x && x->doc ? x->doc : x ? x->expect_id : NULL;
  if (expect_doc && strcmp(id, expect_doc) != 0) {
    scene_free(sc);
    cJSON_Delete(templates);
    return svc_fail(e, RSW_ERR_FILE, x->expect_id,
                    "the files scene %s refers to changed since it was stored (it now loads as %s)",
                    x->expect_id, id);
  }
  /* The id it is registered under: the document's own, a reload's, or a
   * fresh one for a fork (a push while the document's twin has changed,
   * resident or stored). */
  char reg[65];
  memcpy(reg, x && x->expect_id ? x->expect_id : id, 65);
  uint64_t revision = x && x->patched ? x->revision : 0;
  bool fork = false;
  if (!x) {
    resident *t = twin_acquire(svc, id);
    if (t) {
      scene_free(sc);
      cJSON_Delete(templates);
      *created = false;
      *out = t;
      return RSW_OK;
    }
    pthread_mutex_lock(&svc->lock);
    fork = svc_find_scene_locked(svc, id) != NULL;
    pthread_mutex_unlock(&svc->lock);
    cJSON *sp = NULL;
    uint64_t srev = 0;
    if (!fork && svc_state_scene_params(svc, id, &sp, &srev)) {
      fork = sp->child != NULL;
      revision = srev; /* the twin as stored: its revision, no PATCH standing */
    }
    cJSON_Delete(sp);
    if (fork && !fresh_id(id, reg)) {
      scene_free(sc);
      cJSON_Delete(templates);
      return svc_fail(e, RSW_ERR_NOMEM, "scene", "cannot draw a new scene id (getrandom failed)");
    }
    if (fork) revision = 0;
  }
  if (x && x->patched) { /* a reload: its base state at its revision */
    param_update *u = NULL;
    size_t nu = 0;
    rsw_status pst = svc_map_to_updates(x->patched, sc, "params", &u, &nu, e);
    if (!pst && nu) {
      rsw_err uerr = {0};
      pst = scene_update(sc, u, nu, NULL, &uerr);
      if (pst) pst = svc_update_error(e, sc, u, nu, &uerr);
    }
    svc_free_updates(u, nu);
    if (pst) {
      scene_free(sc);
      cJSON_Delete(templates);
      return pst;
    }
  }
  if (!x) { /* posted: stored before it is answered */
    rsw_status sst = svc_state_scene_save(svc, reg, id, false, is_xml, variant, body, len, e);
    if (sst) {
      scene_free(sc);
      cJSON_Delete(templates);
      return sst;
    }
  }
  size_t bytes = budget_bytes(sc);
  pthread_mutex_lock(&svc->lock);
  resident *r = svc_find_scene_locked(svc, reg);
  if (r) {
    r->refs++;
    r->last_used = ++svc->use_clock;
    pthread_mutex_unlock(&svc->lock);
    scene_free(sc);
    cJSON_Delete(templates);
    *created = false;
    *out = r;
    return RSW_OK;
  }
  r = resident_alloc(sc, templates, reg, id, bytes);
  bool ok = r && svc_grow((void **)&svc->scenes, &svc->cap_scenes, svc->n_scenes + 1, sizeof *svc->scenes, 0);
  if (!ok) {
    pthread_mutex_unlock(&svc->lock);
    if (r)
      svc_resident_free(r);
    else
      scene_free(sc), cJSON_Delete(templates);
    return svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
  }
  r->copy = x && x->copy;
  r->pinned = x && x->pinned;
  r->revision = revision;
  r->load_s = load_s;
  memcpy(r->src_files, fd, 32);
  /* a reload: its views replay the stored PATCHes too */
  if (!svc_keep_source(svc, r, body, len, is_xml) || (x && x->patched && !svc_keep_patch(r, x->patched)) ||
      !svc_refresh_param_cache(r)) {
    pthread_mutex_unlock(&svc->lock);
    svc_resident_free(r);
    return svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
  }
  if (!has_files && !x && !fork &&
      svc_grow((void **)&svc->raw, &svc->cap_raw, svc->n_raw + 1, sizeof *svc->raw, 0)) {
    memcpy(svc->raw[svc->n_raw].digest, raw, 32);
    memcpy(svc->raw[svc->n_raw].id, id, 65);
    svc->n_raw++;
  }
  resident **ev = add_locked(svc, r);
  pthread_mutex_unlock(&svc->lock);
  svc_free_evicted(ev);
  *created = true;
  *out = r;
  return RSW_OK;
}

/* The answer to a post or copy: r's id and summary; r's ref released. */
static rsw_status summary_answer(service *svc, resident *r, char **id_out, char **json_out, svc_error *e) {
  unsigned jm = svc_json_mark();
  cJSON *o = cJSON_CreateObject();
  svc_scene_summary(r, o);
  *id_out = strdup(r->id);
  rsw_status st = svc_json_out(json_out, o, jm, e);
  if (!st && !*id_out) st = svc_fail(e, RSW_ERR_NOMEM, "", "out of memory while building the answer");
  if (st) {
    free(*id_out);
    free(*json_out);
    *id_out = *json_out = NULL;
  }
  svc_scene_release(svc, r);
  return st;
}

rsw_status service_scene_post(service *svc, const char *body, size_t len, bool is_xml, const char *variant,
                              bool *created, char **id_out, char **json_out, svc_error *e) {
  return service_scene_post_named(svc, body, len, is_xml, variant, NULL, created, id_out, json_out, e);
}

rsw_status service_scene_post_named(service *svc, const char *body, size_t len, bool is_xml,
                                    const char *variant, const char *name, bool *created, char **id_out,
                                    char **json_out, svc_error *e) {
  if (!service_ready(svc)) return svc_fail(e, RSW_ERR_UNAVAILABLE, "", "the server is shutting down");
  /* What the client calls the document (its file's name): the scene's
   * label and the name its messages use. */
  if (name && !service_scene_label_ok(name))
    return svc_fail(e, RSW_ERR_BAD_REQUEST, "name",
                    "name must be a file name (1 to %d bytes, no '/' or control character)",
                    SVC_SCENE_LABEL_MAX);
  resident *r;
  rsw_status st = scene_post(svc, body, len, is_xml, variant,
                             name     ? name
                             : is_xml ? "scene.xml"
                                      : "scene.json",
                             NULL, created, &r, e);
  if (st) return st;
  return summary_answer(svc, r, id_out, json_out, e);
}

rsw_status service_scene_load_text(service *svc, const char *text, size_t len, bool is_xml, const char *name,
                                   char **id_out, svc_error *e) {
  bool created;
  resident *r;
  struct post_extra x = {.pinned = true}; /* startup scenes: never evicted */
  rsw_status st = scene_post(svc, text, len, is_xml, NULL, name, &x, &created, &r, e);
  if (st) return st;
  if (name) { /* a startup scene's label: its file's name */
    const char *base = strrchr(name, '/') ? strrchr(name, '/') + 1 : name;
    pthread_mutex_lock(&svc->lock);
    if (!r->label[0] && service_scene_label_ok(base)) snprintf(r->label, sizeof r->label, "%s", base);
    pthread_mutex_unlock(&svc->lock);
  }
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
    struct post_extra x = {.pinned = true};
    st = scene_post(svc, buf, n, is_xml, NULL, path, &x, &created, &r, e);
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
  unsigned jm = svc_json_mark();
  cJSON *o = cJSON_CreateObject();
  cJSON *a = cJSON_AddArrayToObject(o, "scenes");
  pthread_mutex_lock(&svc->lock);
  for (size_t i = 0; i < svc->n_scenes; i++) svc_json_push(a, scene_info(svc, svc->scenes[i]));
  pthread_mutex_unlock(&svc->lock);
  return svc_json_out(json_out, o, jm, e);
}

rsw_status svc_no_scene(svc_error *e, const char *id) {
  if (last_miss_evicted)
    return svc_fail(e, RSW_ERR_EVICTED, id,
                    "scene '%s' was evicted from memory (the server's --max-scene-bytes budget); post it "
                    "again",
                    id);
  return svc_fail(e, RSW_ERR_NOT_FOUND, id, "no resident scene '%s'", id);
}

rsw_status service_scene_get(service *svc, const char *id, char **json_out, svc_error *e) {
  svc_scene_release(svc, svc_scene_acquire(svc, id)); /* reloads an evicted or stored one */
  unsigned jm = svc_json_mark();
  pthread_mutex_lock(&svc->lock);
  resident *r = svc_find_scene_locked(svc, id);
  cJSON *o = r ? scene_info(svc, r) : NULL;
  pthread_mutex_unlock(&svc->lock);
  if (!o) return svc_no_scene(e, id);
  return svc_json_out(json_out, o, jm, e);
}

rsw_status service_scene_delete(service *svc, const char *id, bool force, svc_error *e) {
  pthread_mutex_lock(&svc->lock);
  resident *r = svc_find_scene_locked(svc, id);
  if (!r) {
    bool evicted = svc_was_evicted_locked(svc, id);
    svc_forget_evicted_locked(svc, id);
    pthread_mutex_unlock(&svc->lock);
    char *b = NULL;
    size_t bl;
    bool xml;
    char v[32];
    cJSON *pp = NULL;
    uint64_t rev;
    bool stored = svc_state_scene_read(svc, id, &b, &bl, &xml, v, &pp, &rev, NULL, NULL);
    free(b);
    cJSON_Delete(pp);
    if (stored || evicted) { /* not resident: forgetting it is all there is to do */
      svc_state_scene_remove(svc, id);
      return RSW_OK;
    }
    last_miss_evicted = false;
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
  unregister_locked(svc, r);
  bool free_now = r->refs == 0;
  svc_state_scene_remove(svc, id);
  pthread_cond_broadcast(&svc->cond);
  pthread_mutex_unlock(&svc->lock);
  if (free_now) svc_resident_free(r);
  return RSW_OK;
}

/* ---- what render views are built from (renders.c) ---------------------------- */

bool svc_keep_source(service *svc, resident *r, const char *text, size_t len, bool is_xml) {
  r->src = malloc(len + 1);
  r->patches = cJSON_CreateObject();
  r->src_root = svc->data_root[0] ? strdup(svc->data_root) : NULL;
  if (!r->src || !r->patches || (svc->data_root[0] && !r->src_root)) return false;
  memcpy(r->src, text, len);
  r->src[len] = '\0';
  r->src_len = len;
  r->src_xml = is_xml;
  snprintf(r->src_variant, sizeof r->src_variant, "%s", variant_name(r->sc->variant, r->sc->polarized));
  return true;
}

rsw_status svc_scene_reload(service *svc, const resident *r, scene **out, rsw_err *err) {
  /* A blob deleted since fails here as it would on a fresh load; a file
   * under the data root that changed since is refused (its digest is part
   * of the scene's id, so the view would not be this scene). r->src_root
   * keeps a start-up scene's own directory (service_scene_load_file). */
  rsw_sha256_ctx files;
  if (!rsw_sha256_begin(&files)) return rsw_fail(err, RSW_ERR_NOMEM, "scene", "out of memory");
  load_ctx lc = {.svc = svc, .files = &files, .root = r->src_root ? r->src_root : ""};
  scene_load_opts lo = {
      .size = sizeof lo, .variant = r->src_variant, .resolve = resolve_file, .resolve_user = &lc};
  scene *sc = NULL;
  rsw_status st = scene_load_memory(r->src, r->src_len, r->id, r->src_xml, &lo, &sc, err);
  unsigned char fd[32];
  rsw_sha256_end(&files, fd);
  if (!st && memcmp(fd, r->src_files, 32) != 0) {
    scene_free(sc);
    return rsw_fail(err, RSW_ERR_FILE, "scene", "a file the scene names changed since it was loaded");
  }
  if (!st) *out = sc;
  return st;
}

bool service_scene_label_ok(const char *label) {
  size_t n = label ? strlen(label) : 0;
  if (n < 1 || n > SVC_SCENE_LABEL_MAX) return false;
  for (size_t i = 0; i < n; i++)
    if ((unsigned char)label[i] < 0x20 || label[i] == 0x7f || label[i] == '/') return false;
  return true;
}

rsw_status service_scene_label(service *svc, const char *id, const char *label, char **json_out,
                               svc_error *e) {
  if (!service_scene_label_ok(label))
    return svc_fail(e, RSW_ERR_BAD_REQUEST, "name", "a scene's name must be 1 to %d bytes of text",
                    SVC_SCENE_LABEL_MAX);
  unsigned jm = svc_json_mark();
  pthread_mutex_lock(&svc->lock);
  resident *r = svc_find_scene_locked(svc, id);
  if (!r) {
    pthread_mutex_unlock(&svc->lock);
    return svc_fail(e, RSW_ERR_NOT_FOUND, id, "no scene '%s'", id);
  }
  if (!r->label[0]) snprintf(r->label, sizeof r->label, "%s", label);
  cJSON *o = cJSON_CreateObject();
  svc_scene_summary(r, o);
  pthread_mutex_unlock(&svc->lock);
  return svc_json_out(json_out, o, jm, e);
}
rsw_status svc_scene_build_at(service *svc, const resident *r, const cJSON *patches, scene **out,
                              svc_error *e) {
  rsw_err err = {0};
  scene *sc = NULL;
  rsw_status st = svc_scene_reload(svc, r, &sc, &err);
  if (st) {
    scene_error(e, svc, &err);
    return e->err.code;
  }
  if (patches && patches->child) {
    param_update *u = NULL;
    size_t n = 0;
    st = svc_map_to_updates(patches, sc, "params", &u, &n, e);
    if (!st && scene_update(sc, u, n, NULL, &err) != RSW_OK)
      st = svc_fail(e, RSW_ERR_RENDER, err.where, "cannot replay the scene's updates: %s", err.msg);
    svc_free_updates(u, n);
  }
  if (st) {
    scene_free(sc);
    return st;
  }
  *out = sc;
  return RSW_OK;
}

/* ---- reset and copy -------------------------------------------------------------- */

/* A scene marked broken (service_internal.h) is refused: 503. */
static rsw_status broken_error(svc_error *e, const char *id) {
  return svc_fail(e, RSW_ERR_UNAVAILABLE, id,
                  "the scene's base state was lost (restoring it after a render ran out of memory): delete "
                  "the scene and post it again");
}

rsw_status service_scene_reset(service *svc, const char *id, char **json_out, svc_error *e) {
  unsigned jm = svc_json_mark();
  resident *r = svc_scene_acquire(svc, id);
  if (!r) return svc_no_scene(e, id);
  /* The document's values of the keys PATCHed since (from the document
   * loaded again), set as one update: the same path as a PATCH, so renders
   * and views follow the revision; then no PATCH stands. */
  scene *doc = NULL;
  rsw_err err = {0};
  rsw_status st = svc_scene_reload(svc, r, &doc, &err);
  if (st) {
    scene_error(e, svc, &err);
    svc_scene_release(svc, r);
    return e->err.code;
  }
  pthread_mutex_lock(&r->lock);
  while (r->base_busy) pthread_cond_wait(&r->cond, &r->lock);
  param_update *keys = NULL, *docv = NULL, *before = NULL;
  size_t n = 0;
  update_report rep = {0};
  cJSON *empty = NULL, *old_patches = NULL; /* keys[].key points into the latter */
  if (r->broken)
    st = broken_error(e, r->id);
  else if (!r->patches || !(empty = cJSON_CreateObject()))
    st = svc_fail(e, RSW_ERR_NOMEM, r->id, "out of memory: the scene's PATCHes were not recorded");
  if (!st) {
    for (const cJSON *k = r->patches->child; k; k = k->next) n++;
    keys = calloc(n ? n : 1, sizeof *keys);
    if (!keys) st = svc_fail(e, RSW_ERR_NOMEM, r->id, "out of memory");
    size_t i = 0;
    for (const cJSON *k = r->patches->child; keys && k; k = k->next) keys[i++].key = k->string;
  }
  if (!st && n) {
    st = svc_param_snapshot(doc, keys, n, &docv, &err);
    if (!st) st = svc_param_snapshot(r->sc, keys, n, &before, &err);
    if (!st) st = scene_update(r->sc, docv, n, &rep, &err);
    if (st) st = svc_update_error(e, r->sc, keys, n, &err);
  }
  if (!st && n) {
    uint64_t old_revision = r->revision;
    old_patches = r->patches;
    if (rep.changed) r->revision++;
    r->patches = empty;
    empty = NULL;
    st = svc_scene_patched(svc, r, e);
    if (st) { /* not stored: back as it was (the same values, so bitwise) */
      rsw_err uerr = {0};
      svc_error ignored = {0};
      empty = r->patches;
      r->patches = old_patches;
      old_patches = NULL;
      r->revision = old_revision;
      if (scene_update(r->sc, before, n, NULL, &uerr) != RSW_OK) r->broken = true;
      (void)svc_state_scene_patched(svc, r, &ignored);
    }
    (void)svc_refresh_param_cache(r);
    svc_views_free(r);
  }
  cJSON *o = NULL;
  if (!st) {
    o = cJSON_CreateObject();
    svc_scene_summary(r, o);
    cJSON_AddNumberToObject(o, "changed", (double)rep.changed);
    cJSON *ks = cJSON_AddArrayToObject(o, "keys");
    for (size_t i = 0; i < n; i++) svc_json_push(ks, cJSON_CreateString(keys[i].key));
  }
  pthread_mutex_unlock(&r->lock);
  if (!st && n) svc_count_update(svc, &rep);
  for (size_t i = 0; docv && i < n; i++) param_value_free(&docv[i].value);
  for (size_t i = 0; before && i < n; i++) param_value_free(&before[i].value);
  free(docv), free(before), free(keys);
  cJSON_Delete(empty);
  cJSON_Delete(old_patches);
  scene_free(doc);
  svc_scene_release(svc, r);
  if (st) {
    cJSON_Delete(o);
    return st;
  }
  return svc_json_out(json_out, o, jm, e);
}

rsw_status service_scene_copy(service *svc, const char *id, char **id_out, char **json_out, svc_error *e) {
  if (!service_ready(svc)) return svc_fail(e, RSW_ERR_UNAVAILABLE, "", "the server is shutting down");
  resident *src = svc_scene_acquire(svc, id);
  if (!src) return svc_no_scene(e, id);
  /* The source's state: its PATCHes at its revision, replayed on the
   * document loaded again (a view's recipe); its text, variant, root and
   * templates are fixed at its load. */
  pthread_mutex_lock(&src->lock);
  bool broken = src->broken;
  cJSON *patches = src->patches ? cJSON_Duplicate(src->patches, true) : NULL;
  pthread_mutex_unlock(&src->lock);
  rsw_status st = RSW_OK;
  scene *sc = NULL;
  resident *r = NULL;
  char nid[65];
  if (broken)
    st = broken_error(e, src->id);
  else if (!patches)
    st = svc_fail(e, RSW_ERR_NOMEM, src->id, "out of memory: the scene's PATCHes were not recorded");
  else if (!fresh_id(src->doc, nid))
    st = svc_fail(e, RSW_ERR_NOMEM, "scene", "cannot draw a new scene id (getrandom failed)");
  if (!st) {
    double t0 = svc_now();
    st = svc_scene_build_at(svc, src, patches, &sc, e);
    if (!st) {
      cJSON *tm = src->templates ? cJSON_Duplicate(src->templates, true) : NULL;
      r = (!src->templates || tm) ? resident_alloc(sc, tm, nid, src->doc, budget_bytes(sc)) : NULL;
      if (!r) {
        scene_free(sc), cJSON_Delete(tm);
        st = svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
      } else {
        r->load_s = svc_now() - t0;
      }
    }
  }
  if (!st) {
    r->copy = true;
    /* A copy of a start-up scene is not stored either (its files resolve
     * in the start-up file's directory, which a reload does not know) and
     * never evicted. */
    r->pinned = src->pinned;
    memcpy(r->src_files, src->src_files, 32);
    snprintf(r->src_variant, sizeof r->src_variant, "%s", src->src_variant);
    r->src_xml = src->src_xml;
    r->src_len = src->src_len;
    r->src = malloc(src->src_len + 1);
    r->src_root = src->src_root ? strdup(src->src_root) : NULL;
    r->patches = patches;
    patches = NULL;
    if (!r->src || (src->src_root && !r->src_root) || !svc_refresh_param_cache(r)) {
      st = svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
    } else {
      memcpy(r->src, src->src, src->src_len + 1);
    }
  }
  /* Stored before it is answered: its PATCHes first, then the document
   * that makes it a scene (a crash between leaves an unused record). */
  if (!st && !r->pinned) {
    st = svc_state_scene_patched(svc, r, e);
    if (!st)
      st = svc_state_scene_save(svc, r->id, r->doc, true, r->src_xml, r->src_variant, r->src, r->src_len, e);
    if (st) svc_state_scene_remove(svc, r->id);
  }
  resident **ev = NULL;
  if (!st) {
    pthread_mutex_lock(&svc->lock);
    if (svc_grow((void **)&svc->scenes, &svc->cap_scenes, svc->n_scenes + 1, sizeof *svc->scenes, 0))
      ev = add_locked(svc, r);
    else
      st = svc_fail(e, RSW_ERR_NOMEM, "scene", "out of memory");
    pthread_mutex_unlock(&svc->lock);
    svc_free_evicted(ev);
    if (st) svc_state_scene_remove(svc, r->id);
  }
  cJSON_Delete(patches);
  svc_scene_release(svc, src);
  if (st) {
    svc_resident_free(r);
    return st;
  }
  return summary_answer(svc, r, id_out, json_out, e);
}
