/* Jobs of kernel contexts: validation, the queue, the worker that renders
 * them, results, and the event log behind server-sent events.
 *
 * Several workers (service.c) each run one job at a time, one (context,
 * sensor) after another; the renders of concurrent jobs share the kernel's
 * worker pool, and each renders on the base or a private view of its
 * scene (renders.c), so jobs never share parameter state. A job's results are a pure function of the request
 * and the base revision: each (context, sensor) seed defaults to a hash of
 * (job seed, context id, sensor id), never of the call order, so a sweep
 * split into several jobs gives bitwise the films of one job. */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <time.h>
#include <unistd.h>

#include "buf.h"
#include "bundle_plan.h"
#include "rsw_sha256.h"
#include "service_internal.h"
#include "templates.h"

static const char *const state_names[] = {"queued", "running", "succeeded", "failed", "cancelled"};

/* FNV-1a 64 over (job seed, context id, sensor id), folded to 32 bits. */
static uint64_t default_seed(uint64_t job_seed, const char *ctx, const char *sensor_id) {
  uint64_t h = 1469598103934665603ULL;
  for (int i = 0; i < 8; i++) h = (h ^ ((job_seed >> (8 * i)) & 0xff)) * 1099511628211ULL;
  for (const char *c = ctx; *c; c++) h = (h ^ (unsigned char)*c) * 1099511628211ULL;
  h = (h ^ 0xff) * 1099511628211ULL; /* separator */
  for (const char *c = sensor_id; *c; c++) h = (h ^ (unsigned char)*c) * 1099511628211ULL;
  return (h ^ (h >> 32)) & 0xffffffffULL;
}

/* ---- a set of context ids ------------------------------------------------------------
 * Duplicate context ids are found with a hash set, so that a job's
 * validation is linear in its contexts (a pairwise scan took 153 s for
 * 100,000). The hash is SipHash-2-4 (Aumasson and Bernstein, "SipHash: a
 * fast short-input PRF", 2012) under a key drawn at random once per
 * process, so that a client cannot choose ids that all collide. */
static uint8_t g_sip_key[16];
static pthread_once_t g_sip_once = PTHREAD_ONCE_INIT;

static void sip_key_init(void) {
  if (getrandom(g_sip_key, sizeof g_sip_key, 0) != (ssize_t)sizeof g_sip_key) {
    /* No entropy source: the clock and the pid still differ per process. */
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    uint64_t a = (uint64_t)ts.tv_nsec * 0x9E3779B97F4A7C15ULL ^ (uint64_t)ts.tv_sec;
    uint64_t b = (uint64_t)getpid() * 0xC2B2AE3D27D4EB4FULL ^ (uint64_t)(uintptr_t)&ts;
    memcpy(g_sip_key, &a, 8);
    memcpy(g_sip_key + 8, &b, 8);
  }
}

static uint64_t rotl64(uint64_t x, int b) {
  return (x << b) | (x >> (64 - b));
}

static uint64_t load_le64(const uint8_t *p) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; i--) v = (v << 8) | p[i];
  return v;
}

#define SIPROUND                                                                                             \
  do {                                                                                                       \
    v0 += v1, v1 = rotl64(v1, 13), v1 ^= v0, v0 = rotl64(v0, 32);                                            \
    v2 += v3, v3 = rotl64(v3, 16), v3 ^= v2;                                                                 \
    v0 += v3, v3 = rotl64(v3, 21), v3 ^= v0;                                                                 \
    v2 += v1, v1 = rotl64(v1, 17), v1 ^= v2, v2 = rotl64(v2, 32);                                            \
  } while (0)

static uint64_t siphash24(const char *s, size_t len) {
  pthread_once(&g_sip_once, sip_key_init);
  uint64_t k0 = load_le64(g_sip_key), k1 = load_le64(g_sip_key + 8);
  uint64_t v0 = k0 ^ 0x736f6d6570736575ULL, v1 = k1 ^ 0x646f72616e646f6dULL;
  uint64_t v2 = k0 ^ 0x6c7967656e657261ULL, v3 = k1 ^ 0x7465646279746573ULL;
  const uint8_t *p = (const uint8_t *)s;
  size_t full = len & ~(size_t)7;
  for (size_t i = 0; i < full; i += 8) {
    uint64_t m = load_le64(p + i);
    v3 ^= m;
    SIPROUND;
    SIPROUND;
    v0 ^= m;
  }
  uint64_t b = (uint64_t)len << 56;
  for (size_t i = 0; i < (len & 7); i++) b |= (uint64_t)p[full + i] << (8 * i);
  v3 ^= b;
  SIPROUND;
  SIPROUND;
  v0 ^= b;
  v2 ^= 0xff;
  SIPROUND;
  SIPROUND;
  SIPROUND;
  SIPROUND;
  return v0 ^ v1 ^ v2 ^ v3;
}

/* Open addressing over borrowed strings; capacity a power of two at least
 * twice the entries. */
typedef struct id_set {
  const char **slot;
  size_t mask;
} id_set;

static bool id_set_init(id_set *set, size_t n) {
  size_t cap = 16;
  while (cap < 2 * n) cap *= 2;
  set->slot = calloc(cap, sizeof *set->slot);
  set->mask = cap - 1;
  return set->slot != NULL;
}

/* Adds s; false when it was already there. */
static bool id_set_add(id_set *set, const char *s) {
  size_t i = (size_t)siphash24(s, strlen(s)) & set->mask;
  while (set->slot[i]) {
    if (strcmp(set->slot[i], s) == 0) return false;
    i = (i + 1) & set->mask;
  }
  set->slot[i] = s;
  return true;
}

bool svc_valid_id(const char *s) {
  size_t n = strlen(s);
  if (n < 1 || n > 64) return false;
  for (size_t i = 0; i < n; i++) {
    char c = s[i];
    if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '.' ||
          c == '_' || c == '-'))
      return false;
  }
  return true;
}

static void job_free(job *j) {
  if (!j) return;
  for (size_t i = 0; i < j->n_items; i++) {
    cJSON_Delete(j->items[i].params);
    free(j->items[i].result_json);
    if (j->items[i].has_film) svc_film_free(&j->items[i].film);
  }
  for (size_t i = 0; i < j->n_events; i++) free(j->events[i].json);
  free(j->events);
  free(j->items);
  free(j->by_name);
  free(j->context_remaining);
  free(j->idem_key);
  nc_coords_free(&j->coords);
  cJSON_Delete(j->warnings);
  bands_free(j->bands);
  for (size_t s = 0; s < j->n_angle_slots; s++) film_angles_unref(j->angle_slots[s].block);
  free(j->angle_slots);
  free(j);
}

/* svc->lock held; takes txt (printed event data, NULL when out of
 * memory). Out of memory, a progress event is dropped, but the end event
 * never is: a progress event is stored only when the array also has room
 * for the end event after it, and the end event's payload falls back to a
 * fixed text; a stream that never got its end event would never close. */
static void push_event_text(service *svc, job *j, char *txt, bool end) {
  if (!end &&
      (!txt || !svc_grow((void **)&j->events, &j->cap_events, j->n_events + 2, sizeof *j->events, 0))) {
    free(txt);
    return;
  }
  if (end && !svc_grow((void **)&j->events, &j->cap_events, j->n_events + 1, sizeof *j->events, 0)) {
    free(txt); /* cannot happen: the slot was kept free (or is the first) */
    return;
  }
  if (end && !txt) {
    char fb[160];
    snprintf(fb, sizeof fb, "{\"job\":\"%s\",\"state\":\"%s\"}", j->id, state_names[j->state]);
    txt = strdup(fb); /* NULL: next_event answers "{}" */
  }
  job_event *ev = &j->events[j->n_events];
  ev->seq = j->n_events + 1;
  ev->json = txt;
  ev->end = end;
  j->n_events++;
  pthread_cond_broadcast(&svc->cond);
}

/* svc->lock held; takes data. */
static void push_event(service *svc, job *j, cJSON *data, bool end, unsigned jm) {
  push_event_text(svc, j, svc_print_json(data, jm), end);
}

/* svc->lock held. */

static cJSON *job_json(const job *j) {
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "id", j->id);
  cJSON_AddStringToObject(o, "scene", j->scene_id);
  cJSON_AddNumberToObject(o, "revision", (double)j->revision);
  cJSON_AddStringToObject(o, "state", state_names[j->state]);
  cJSON_AddNumberToObject(o, "contexts_total", (double)j->n_contexts);
  cJSON_AddNumberToObject(o, "contexts_done", (double)j->contexts_done);
  cJSON_AddNumberToObject(o, "renders_total", (double)j->n_items);
  cJSON_AddNumberToObject(o, "renders_done", (double)j->items_done);
  cJSON_AddNumberToObject(o, "renders_failed", (double)j->items_failed);
  cJSON_AddStringToObject(o, "created", j->created_iso);
  if (j->started_iso[0]) cJSON_AddStringToObject(o, "started", j->started_iso);
  if (j->finished_iso[0]) cJSON_AddStringToObject(o, "finished", j->finished_iso);
  /* Running time: so far while running, final once finished, 0 for a job
   * that never started (cancelled while queued). A client that joins a
   * running job divides renders_done by it for an honest rate. */
  double seconds = 0;
  if (j->started_iso[0]) seconds = (j->finished_iso[0] ? j->t_finished : svc_now()) - j->t_started;
  if (j->started_iso[0] || j->finished_iso[0])
    cJSON_AddNumberToObject(o, "seconds", seconds > 0 ? seconds : 0);
  if (j->error[0]) cJSON_AddStringToObject(o, "error", j->error);
  if (j->state == JOB_RUNNING && j->current < j->n_items) {
    /* Progress within the render under way (samples traced so far). */
    const render_item *it = &j->items[j->current];
    cJSON *cur = cJSON_AddObjectToObject(o, "render");
    cJSON_AddStringToObject(cur, "context", it->context);
    cJSON_AddStringToObject(cur, "sensor", it->sensor);
    cJSON_AddNumberToObject(cur, "samples_done", (double)atomic_load(&j->current_samples.done));
    cJSON_AddNumberToObject(cur, "samples_total", (double)atomic_load(&j->current_samples.total));
  }
  if (j->warnings) svc_json_put(o, "warnings", cJSON_Duplicate(j->warnings, 1));
  if (j->bundle_asked) { /* what "bundle" came to ("auto": and why 1) */
    cJSON_AddNumberToObject(o, "bundle", j->bundle);
    if (j->bundle_why[0]) cJSON_AddStringToObject(o, "bundle_why", j->bundle_why);
  }
  char href[128];
  snprintf(href, sizeof href, "/v1/jobs/%s/results", j->id);
  cJSON_AddStringToObject(o, "href_results", href);
  snprintf(href, sizeof href, "/v1/jobs/%s/events", j->id);
  cJSON_AddStringToObject(o, "href_events", href);
  return o;
}

static job *find_job_locked(service *svc, const char *id) {
  for (size_t i = 0; i < svc->n_jobs; i++)
    if (!svc->jobs[i]->deleted && strcmp(svc->jobs[i]->id, id) == 0) return svc->jobs[i];
  return NULL;
}

static rsw_status no_job(svc_error *e, const char *id) {
  return svc_fail(e, RSW_ERR_NOT_FOUND, id, "no job '%s' (unknown, deleted or expired)", id);
}

/* Merge job-level and context-level overrides: context keys win. */
/* NULL when out of memory (an override silently missing would render the
 * context with the base value and report success). */
static cJSON *merge_params(const cJSON *job_params, const cJSON *ctx_params) {
  unsigned jm = svc_json_mark();
  cJSON *m = cJSON_CreateObject();
  if (!m) return NULL;
  for (const cJSON *k = job_params ? job_params->child : NULL; k; k = k->next)
    if (!ctx_params || !cJSON_GetObjectItemCaseSensitive(ctx_params, k->string))
      svc_json_put(m, k->string, cJSON_Duplicate(k, 1));
  for (const cJSON *k = ctx_params ? ctx_params->child : NULL; k; k = k->next)
    svc_json_put(m, k->string, cJSON_Duplicate(k, 1));
  if (!svc_json_ok(jm)) {
    cJSON_Delete(m);
    return NULL;
  }
  return m;
}

/* Keys of an override map must exist and their values parse (their legal
 * values: check_values, with the job-level map under each context's). */
static rsw_status check_params(const scene *sc, const cJSON *p, const char *ptr, svc_error *e) {
  if (!p) return RSW_OK;
  if (!cJSON_IsObject(p)) return svc_fail(e, RSW_ERR_TYPE, ptr, "params must be an object {key: value}");
  for (const cJSON *k = p->child; k; k = k->next) {
    size_t idx;
    rsw_err err = {0};
    if (params_lookup(sc, k->string, &idx, &err) != RSW_OK) {
      e->err = err;
      e->err.code = svc_request_code(err.code);
      snprintf(e->err.where, sizeof e->err.where, "%s/%s", ptr, k->string);
      snprintf(e->key, sizeof e->key, "%s", k->string);
      const char *c[3];
      size_t n = params_closest(sc, k->string, c);
      for (size_t i = 0; i < n; i++) snprintf(e->candidates[i], sizeof e->candidates[i], "%s", c[i]);
      return e->err.code;
    }
    param_value v;
    rsw_status st = param_value_from_json(k, k->string, &v, &err);
    if (st) {
      char w[512];
      snprintf(w, sizeof w, "%s/%s", ptr, k->string);
      return svc_fail(e, svc_request_code(st), w, "%s", err.msg);
    }
    param_value_free(&v);
  }
  return RSW_OK;
}

/* The overrides a context renders with (m: job-level, its own (cp) over
 * them, then templates of ts for the keys neither gives) against the scene
 * (scene_update_check): an illegal value is refused at submit, named by
 * its pointer (/params/KEY, CTX/params/KEY, or the template's
 * /templates/KEY with the context in the message). */
static rsw_status check_merged(const scene *sc, const cJSON *m, const cJSON *cp, const tmpl_set *ts,
                               const char *ctx_ptr, svc_error *e) {
  param_update *u = NULL;
  size_t n = 0;
  rsw_status st = svc_map_to_updates(m, sc, "params", &u, &n, e);
  if (!st) {
    rsw_err err = {0};
    st = scene_update_check(sc, u, n, &err);
    if (st) st = svc_update_error(e, sc, u, n, &err);
  }
  if (st) {
    bool own = cp && cJSON_GetObjectItemCaseSensitive(cp, e->key);
    if (own)
      snprintf(e->err.where, sizeof e->err.where, "%.64s/params/%.180s", ctx_ptr, e->key);
    else if (!tmpl_blame(ts, ctx_ptr, e))
      snprintf(e->err.where, sizeof e->err.where, "/params/%.240s", e->key);
  }
  svc_free_updates(u, n);
  return st;
}

static rsw_status check_values(const scene *sc, const cJSON *jp, const cJSON *cp, const char *ctx_ptr,
                               svc_error *e) {
  cJSON *m = merge_params(jp, cp);
  if (!m) return svc_fail(e, RSW_ERR_NOMEM, ctx_ptr, "out of memory");
  rsw_status st = check_merged(sc, m, cp, NULL, ctx_ptr, e);
  cJSON_Delete(m);
  return st;
}

/* Whether an override map holds a tabulated spectrum (read at the
 * render's wavelength). */
static bool has_table(const cJSON *map);

static bool table_range(const cJSON *v, double *lo, double *hi);

static bool has_table(const cJSON *map) {
  double lo, hi;
  for (const cJSON *k = cJSON_IsObject(map) ? map->child : NULL; k; k = k->next)
    if (table_range(k, &lo, &hi)) return true;
  return false;
}

/* A tabulated spectrum's range (nm), in the two forms a value takes
 * (param_value_from_json): {"wavelengths": [...], "values": [...]} or
 * {"type": "spectrum", "value": [[wl, value], ...]}, increasing. False for
 * anything else: a bare list of rows is a matrix (a transform's 4 rows of
 * 4), never a table. */
static bool table_range(const cJSON *v, double *lo, double *hi) {
  const cJSON *first = NULL, *last = NULL;
  const cJSON *wl = cJSON_IsObject(v) ? cJSON_GetObjectItemCaseSensitive(v, "wavelengths") : NULL;
  const cJSON *pairs = cJSON_IsObject(v) ? cJSON_GetObjectItemCaseSensitive(v, "value") : NULL;
  if (cJSON_IsArray(wl) && wl->child) {
    first = wl->child;
    for (last = first; last->next; last = last->next) {}
  } else if (cJSON_IsArray(pairs) && cJSON_IsArray(pairs->child)) {
    const cJSON *fp = pairs->child, *lp = fp;
    while (lp->next) lp = lp->next;
    first = fp->child, last = cJSON_IsArray(lp) ? lp->child : NULL;
  }
  if (!cJSON_IsNumber(first) || !cJSON_IsNumber(last)) return false;
  *lo = first->valuedouble, *hi = last->valuedouble;
  return true;
}

/* The tabulated spectra of the scene's base state (from the parameter
 * cache, so no render is waited for): index, range and key. */
typedef struct spec_range {
  size_t index;
  double lo, hi;
  char key[200];
} spec_range;

static spec_range *base_ranges(resident *r, size_t *n_out) {
  spec_range *out = NULL;
  size_t n = 0, cap = 0;
  pthread_mutex_lock(&r->cache_lock);
  size_t i = 0;
  for (const cJSON *p = r->base_params ? r->base_params->child : NULL; p; p = p->next, i++) {
    const cJSON *type = cJSON_GetObjectItemCaseSensitive(p, "type");
    const cJSON *key = cJSON_GetObjectItemCaseSensitive(p, "key");
    double lo, hi;
    if (!cJSON_IsString(type) || strcmp(type->valuestring, "spectrum") != 0 || !cJSON_IsString(key) ||
        !table_range(cJSON_GetObjectItemCaseSensitive(p, "value"), &lo, &hi))
      continue;
    if (n == cap) {
      size_t nc = cap ? 2 * cap : 8;
      spec_range *g = realloc(out, nc * sizeof *g);
      if (!g) break;
      out = g, cap = nc;
    }
    out[n] = (spec_range){.index = i, .lo = lo, .hi = hi};
    snprintf(out[n].key, sizeof out[n].key, "%s", key->valuestring);
    n++;
  }
  pthread_mutex_unlock(&r->cache_lock);
  *n_out = n;
  return out;
}

/* A context's wavelength against every tabulated spectrum it renders
 * with: the base state's, less those its overrides replace, and the
 * overrides' own tables (context keys over job-level keys). Out of range
 * failed only when the context rendered. */
static rsw_status check_wavelength(const scene *sc, const spec_range *br, size_t nbr, const cJSON *jp,
                                   const cJSON *cp, double wl, const char *wptr, svc_error *e) {
  const cJSON *maps[2] = {cp, jp};
  for (size_t b = 0; b < nbr; b++) {
    bool replaced = false;
    for (int m = 0; m < 2 && !replaced; m++)
      for (const cJSON *k = cJSON_IsObject(maps[m]) ? maps[m]->child : NULL; k && !replaced; k = k->next) {
        size_t idx;
        rsw_err err = {0};
        replaced = params_lookup(sc, k->string, &idx, &err) == RSW_OK && idx == br[b].index;
      }
    if (!replaced && !(wl >= br[b].lo && wl <= br[b].hi))
      return svc_fail(e, RSW_ERR_RANGE, wptr, "wavelength %g nm lies outside the table of '%s' [%g, %g] nm",
                      wl, br[b].key, br[b].lo, br[b].hi);
  }
  for (int m = 0; m < 2; m++)
    for (const cJSON *k = cJSON_IsObject(maps[m]) ? maps[m]->child : NULL; k; k = k->next) {
      if (m == 1 && cJSON_IsObject(cp) && cJSON_GetObjectItemCaseSensitive(cp, k->string)) continue;
      double lo, hi;
      if (table_range(k, &lo, &hi) && !(wl >= lo && wl <= hi))
        return svc_fail(e, RSW_ERR_RANGE, wptr, "wavelength %g nm lies outside the table of '%s' [%g, %g] nm",
                        wl, k->string, lo, hi);
    }
  return RSW_OK;
}

static bool get_uint(const cJSON *o, const char *name, double max, uint64_t *out, bool *present,
                     const char *ptr, svc_error *e, rsw_status *st) {
  const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, name);
  *present = x != NULL;
  if (!x) return true;
  if (!cJSON_IsNumber(x) || x->valuedouble < 0 || x->valuedouble > max ||
      x->valuedouble != floor(x->valuedouble)) {
    char w[300];
    snprintf(w, sizeof w, "%s/%s", ptr, name);
    *st = svc_fail(e, RSW_ERR_INVALID, w, "%s must be a non-negative integer", name);
    return false;
  }
  *out = (uint64_t)x->valuedouble;
  return true;
}

/* ---- submitting a job ---------------------------------------------------------------------
 * service_job_submit runs four stages, each of which answers the first
 * problem it meets (its pointer and message) and leaves nothing behind:
 *   parse_request     the body's fields (no scene needed);
 *   validate_request  everything against the scene, context by context
 *                     (check_context), before anything is accepted;
 *   plan_job          the job's renders, their seeds and overrides;
 *   enqueue_job       an id, the state directory, the queue and the answer.
 * A replayed Idempotency-Key (submit_replay) answers before any of them. */

/* A job request as parsed from its body (stage 1); the cJSON pointers
 * point into req. */
typedef struct job_req {
  cJSON *req;
  const cJSON *contexts, *defaults, *params, *templates;
  uint64_t seed;       /* the job's seed ("seed"; 0 when absent) */
  unsigned quantities; /* RENDER_Q_* */
  bool variance;
  band_plan *bands;  /* NULL: no bands (bands.c); the job takes it (plan_job) */
  size_t n_contexts; /* entries of "contexts" */
  /* "defaults", read by validate_request (0 / NULL: not given). */
  uint64_t d_spp;
  double d_wl;
  const cJSON *d_sensors;
  int bundle; /* "bundle" (0 when absent: auto, plan_job; JOB_BUNDLE_AUTO for "auto") */
} job_req;

/* "bundle": "auto": the most the job's sensors allow (plan_job). */
#define JOB_BUNDLE_AUTO (-1)

/* What validation learned (stage 2) for planning. */
typedef struct job_check {
  tmpl_set *ts;       /* the templates (the scene's under the job's), NULL: none */
  size_t n_nodes;     /* renders per context and sensor: the bands' nodes, or 1 */
  cJSON **ctx_params; /* with templates: per context and node (context-major), the overrides rendered */
  size_t n_items;     /* renders */
  cJSON *warnings;    /* the no-op sweep warnings (NULL: none); the job takes them */
  nc_coords coords;   /* the contexts' coords; the job takes them */
} job_check;

static void job_req_free(job_req *q) {
  cJSON_Delete(q->req);
  bands_free(q->bands);
}

static void job_check_free(job_check *k, size_t n_contexts) {
  for (size_t i = 0; k->ctx_params && i < n_contexts * k->n_nodes; i++) cJSON_Delete(k->ctx_params[i]);
  free(k->ctx_params);
  tmpl_free(k->ts);
  cJSON_Delete(k->warnings);
  nc_coords_free(&k->coords);
}

/* A request whose Idempotency-Key this scene's jobs already hold (*found):
 * the same body answers with that job, another body is a conflict. */
static rsw_status submit_replay(service *svc, const char *scene_id, const char *idem_key,
                                const unsigned char digest[32], unsigned jm, char **job_id_out,
                                char **json_out, bool *found, svc_error *e) {
  *found = false;
  pthread_mutex_lock(&svc->lock);
  for (size_t i = 0; i < svc->n_jobs; i++) {
    job *j = svc->jobs[i];
    if (j->deleted || !j->idem_key || strcmp(j->idem_key, idem_key) != 0 ||
        strcmp(j->scene_id, scene_id) != 0)
      continue;
    *found = true;
    if (memcmp(j->body_digest, digest, 32) != 0) {
      pthread_mutex_unlock(&svc->lock);
      return svc_fail(e, RSW_ERR_CONFLICT, "Idempotency-Key",
                      "Idempotency-Key '%s' was used for another request body", idem_key);
    }
    rsw_status st = svc_json_out(json_out, job_json(j), jm, e);
    *job_id_out = st ? NULL : strdup(j->id);
    pthread_mutex_unlock(&svc->lock);
    if (!st && !*job_id_out) {
      free(*json_out);
      *json_out = NULL;
      st = svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
    }
    return st;
  }
  pthread_mutex_unlock(&svc->lock);
  return RSW_OK;
}

/* Stage 1: the body as JSON, its known fields, a non-empty context list
 * within SVC_MAX_JOB_CONTEXTS (the caps before any context is read: a
 * request over them costs one pass over the list). */
static rsw_status parse_request(const char *body, size_t len, job_req *q, svc_error *e) {
  q->req = cJSON_ParseWithLength(body, len);
  if (!q->req) return svc_fail(e, RSW_ERR_PARSE, "", "the body is not valid JSON");
  if (svc_check_body(body, len, e) != RSW_OK) return e->err.code;
  if (!cJSON_IsObject(q->req)) return svc_fail(e, RSW_ERR_TYPE, "", "the body must be a JSON object");
  rsw_status st = RSW_OK;
  for (const cJSON *k = q->req->child; k && !st; k = k->next) {
    if (strcmp(k->string, "contexts") == 0)
      q->contexts = k;
    else if (strcmp(k->string, "defaults") == 0)
      q->defaults = k;
    else if (strcmp(k->string, "params") == 0)
      q->params = k;
    else if (strcmp(k->string, "templates") == 0)
      q->templates = k;
    else if (strcmp(k->string, "seed") == 0) {
      bool present;
      get_uint(q->req, "seed", 9007199254740991.0, &q->seed, &present, "", e, &st);
    } else if (strcmp(k->string, "quantities") == 0) {
      st = svc_parse_quantities(k, "/quantities", &q->quantities, e);
    } else if (strcmp(k->string, "variance") == 0) {
      st = svc_parse_variance(k, "/variance", &q->variance, e);
    } else if (strcmp(k->string, "bands") == 0) {
      st = bands_parse(k, "/bands", &q->bands, e);
    } else if (strcmp(k->string, "bundle") == 0) {
      /* (its range against the scene: render_check_bundle, at planning) */
      if (cJSON_IsString(k) && strcmp(k->valuestring, "auto") == 0)
        q->bundle = JOB_BUNDLE_AUTO;
      else if (!cJSON_IsNumber(k) || k->valuedouble != floor(k->valuedouble) || k->valuedouble < 1 ||
               k->valuedouble > 1e6)
        st = svc_fail(e, RSW_ERR_INVALID, "/bundle",
                      "bundle must be \"auto\" (the most the scene allows) or an integer from 1 (one "
                      "wavelength per path) to %d (the wavelengths a path carries)",
                      RENDER_MAX_BUNDLE);
      else
        q->bundle = (int)k->valuedouble;
    } else {
      char w[300];
      snprintf(w, sizeof w, "/%s", k->string);
      st = svc_fail(e, RSW_ERR_UNUSED_PROPERTY, w,
                    "unknown field '%s' (expected contexts, defaults, params, templates, seed, quantities, "
                    "variance, bands, bundle)",
                    k->string);
    }
  }
  if (st) return st;
  if (!cJSON_IsArray(q->contexts) || !q->contexts->child)
    return svc_fail(e, RSW_ERR_MISSING, "/contexts", "a job needs a non-empty \"contexts\" list");
  for (const cJSON *c = q->contexts->child; c; c = c->next) q->n_contexts++;
  if (q->n_contexts > SVC_MAX_JOB_CONTEXTS)
    return svc_fail(e, RSW_ERR_LIMIT, "/contexts", "%zu contexts; a job may have at most %d", q->n_contexts,
                    SVC_MAX_JOB_CONTEXTS);
  if (q->defaults && !cJSON_IsObject(q->defaults))
    return svc_fail(e, RSW_ERR_TYPE, "/defaults", "defaults must be an object");
  return RSW_OK;
}

/* The "defaults" object's spp, wavelength and sensors. */
static rsw_status read_defaults(job_req *q, svc_error *e) {
  const cJSON *defaults = q->defaults;
  rsw_status st = RSW_OK;
  if (!defaults) return RSW_OK;
  bool present;
  get_uint(defaults, "spp", 4294967295.0, &q->d_spp, &present, "/defaults", e, &st);
  if (!st && present && q->d_spp == 0)
    st = svc_fail(e, RSW_ERR_INVALID, "/defaults/spp", "spp must be at least 1");
  const cJSON *w = cJSON_GetObjectItemCaseSensitive(defaults, "wavelength");
  if (!st && w) {
    if (!cJSON_IsNumber(w) || !(w->valuedouble > 0) || !isfinite(w->valuedouble))
      st =
          svc_fail(e, RSW_ERR_INVALID, "/defaults/wavelength", "wavelength must be a positive finite number");
    else
      q->d_wl = w->valuedouble;
    if (!st && q->bands)
      st = svc_fail(e, RSW_ERR_INVALID, "/defaults/wavelength",
                    "a job with bands renders each band's wavelengths: it takes no wavelength");
  }
  q->d_sensors = cJSON_GetObjectItemCaseSensitive(defaults, "sensors");
  for (const cJSON *k = defaults->child; k && !st; k = k->next)
    if (strcmp(k->string, "spp") && strcmp(k->string, "wavelength") && strcmp(k->string, "sensors")) {
      char w2[300];
      snprintf(w2, sizeof w2, "/defaults/%s", k->string);
      st = svc_fail(e, RSW_ERR_UNUSED_PROPERTY, w2, "unknown field '%s' in defaults", k->string);
    }
  return st;
}

/* What checking the contexts carries from one context to the next. */
typedef struct ctx_scan {
  service *svc;
  const scene *sc;
  const job_req *q;
  job_check *k;
  id_set ids;         /* the context ids met */
  size_t *seen;       /* per sensor: 1 + the context that last named it (once per context) */
  bool *film_ok;      /* per sensor: its film passed the film limits (checked once) */
  spec_range *ranges; /* mono: the base state's tabulated spectra */
  size_t n_ranges;
  bool spectral;      /* what the contexts render with depends on the wavelength */
  bool any_table;     /* some context's overrides hold a table */
  bool job_params_ok; /* the job-level overrides were checked on their own */
  tmpl_ctx_sig *sigs; /* per context: the fingerprint for the no-op sweep check */
} ctx_scan;

/* A context's fields: an object with a fresh id, known keys, a valid
 * wavelength (*w, NULL when absent) and only on a mono scene. */
static rsw_status check_context_fields(ctx_scan *cs, const cJSON *c, const char *ptr, const cJSON **w,
                                       svc_error *e) {
  if (!cJSON_IsObject(c)) return svc_fail(e, RSW_ERR_TYPE, ptr, "a context must be an object");
  const cJSON *id = cJSON_GetObjectItemCaseSensitive(c, "id");
  if (!cJSON_IsString(id) || !svc_valid_id(id->valuestring))
    return svc_fail(e, RSW_ERR_INVALID, ptr, "context \"id\" must match [A-Za-z0-9._-]{1,64}");
  if (!id_set_add(&cs->ids, id->valuestring))
    return svc_fail(e, RSW_ERR_DUPLICATE, ptr, "context id '%s' appears twice", id->valuestring);
  for (const cJSON *k = c->child; k; k = k->next)
    if (strcmp(k->string, "id") && strcmp(k->string, "wavelength") && strcmp(k->string, "params") &&
        strcmp(k->string, "sensors") && strcmp(k->string, "spp") && strcmp(k->string, "seed") &&
        strcmp(k->string, "coords") && strcmp(k->string, "bundle_group")) {
      char p[300];
      snprintf(p, sizeof p, "%s/%s", ptr, k->string);
      return svc_fail(e, RSW_ERR_UNUSED_PROPERTY, p, "unknown field '%s' in a context", k->string);
    }
  *w = cJSON_GetObjectItemCaseSensitive(c, "wavelength");
  if (*w && (!cJSON_IsNumber(*w) || !((*w)->valuedouble > 0) || !isfinite((*w)->valuedouble))) {
    char p2[80];
    snprintf(p2, sizeof p2, "%s/wavelength", ptr);
    return svc_fail(e, RSW_ERR_INVALID, p2, "wavelength must be a positive finite number of nm");
  }
  if ((*w || cs->q->d_wl > 0) && cs->sc->variant != VARIANT_MONO)
    return svc_fail(e, RSW_ERR_INVALID, ptr, "wavelength applies to mono scenes; this scene is rgb");
  return RSW_OK;
}

/* The wavelengths a mono context renders at (wl, or with bands every
 * band's support) against the tables it renders with (mine: its
 * overrides; the job-level ones too without templates). */
static rsw_status check_context_wavelengths(ctx_scan *cs, const cJSON *c, const cJSON *w, const cJSON *cw,
                                            double wl, const cJSON *mine, const char *ptr, svc_error *e) {
  const scene *sc = cs->sc;
  const cJSON *jp = cs->k->ts ? NULL : cs->q->params;
  const band_plan *bands = cs->q->bands;
  if (bands) {
    /* No wavelength of its own, and the scene's tables must cover
     * every band's support. */
    rsw_status st = svc_bands_check_context(bands, c, ptr, e);
    for (size_t b = 0; !st && b < bands->n; b++) {
      char p6[80];
      snprintf(p6, sizeof p6, "/bands/%zu/srf", b);
      st = check_wavelength(sc, cs->ranges, cs->n_ranges, jp, mine, bands->b[b].lo, p6, e);
      if (!st) st = check_wavelength(sc, cs->ranges, cs->n_ranges, jp, mine, bands->b[b].hi, p6, e);
    }
    return st;
  }
  if (sc->variant != VARIANT_MONO) return RSW_OK;
  char p5[96];
  snprintf(p5, sizeof p5,
           w                 ? "%s/wavelength"
           : cw              ? "%s/coords/wavelength"
           : cs->q->d_wl > 0 ? "/defaults/wavelength"
                             : "%s",
           ptr);
  return check_wavelength(sc, cs->ranges, cs->n_ranges, jp, mine, wl, p5, e);
}

/* The values context i renders with must be legal now, not only when it
 * renders: job-level overrides under its own (checked once for all
 * contexts that have none of their own), what its templates render, and
 * its wavelengths against the tables. Records its sweep fingerprint. */
static rsw_status check_context_values(ctx_scan *cs, const cJSON *c, size_t i, const cJSON *w,
                                       const char *ptr, svc_error *e) {
  const scene *sc = cs->sc;
  const job_req *q = cs->q;
  job_check *k = cs->k;
  char pp[80];
  snprintf(pp, sizeof pp, "%s/params", ptr);
  const cJSON *cparams = cJSON_GetObjectItemCaseSensitive(c, "params");
  rsw_status st = check_params(sc, cparams, pp, e);
  if (st) return st;
  const cJSON *coords = cJSON_GetObjectItemCaseSensitive(c, "coords");
  const cJSON *cw = cJSON_IsObject(coords) ? cJSON_GetObjectItemCaseSensitive(coords, "wavelength") : NULL;
  if (cw && (st = tmpl_check_coord_wavelength(sc, w, cw, ptr, e))) return st;
  double wl = sc->variant != VARIANT_MONO ? 0
              : w                         ? w->valuedouble
              : cw                        ? cw->valuedouble
              : q->d_wl > 0               ? q->d_wl
                                          : 550;
  const cJSON *mine = cparams;
  if (k->ts) {
    /* With bands, once per node wavelength: a template may read it. */
    for (size_t nk = 0; nk < k->n_nodes; nk++) {
      cJSON *m = merge_params(q->params, cparams);
      if (!m) return svc_fail(e, RSW_ERR_NOMEM, ptr, "out of memory");
      k->ctx_params[i * k->n_nodes + nk] = m;
      st = tmpl_render(k->ts, sc, coords, q->bands ? q->bands->wl[nk] : wl, m, ptr, e);
      if (!st) st = check_merged(sc, m, cparams, k->ts, ptr, e);
      if (st) return st;
    }
    mine = k->ctx_params[i * k->n_nodes];
  } else if (cparams || (q->params && !cs->job_params_ok)) {
    st = check_values(sc, q->params, cparams, ptr, e);
    if (st) return st;
    if (!cparams) cs->job_params_ok = true;
  }
  st = check_context_wavelengths(cs, c, w, cw, wl, mine, ptr, e);
  if (st) return st;
  bool own_table = sc->variant == VARIANT_MONO && has_table(mine);
  cs->any_table = cs->any_table || own_table;
  tmpl_ctx_sig *sig = &cs->sigs[i];
  sig->coords = cJSON_IsObject(coords) ? coords : NULL;
  sig->wavelength = wl;
  if (sig->coords) tmpl_ctx_digest(mine, wl, cs->spectral || own_table, c, q->d_sensors, sig->digest);
  return RSW_OK;
}

/* A context's spp (at least 1) and seed. */
static rsw_status check_context_spp_seed(const cJSON *c, const char *ptr, svc_error *e) {
  rsw_status st = RSW_OK;
  uint64_t dummy;
  bool present;
  get_uint(c, "spp", 4294967295.0, &dummy, &present, ptr, e, &st);
  if (!st && present && dummy == 0) {
    char p3[80];
    snprintf(p3, sizeof p3, "%s/spp", ptr);
    st = svc_fail(e, RSW_ERR_INVALID, p3, "spp must be at least 1");
  }
  if (!st) get_uint(c, "seed", 9007199254740991.0, &dummy, &present, ptr, e, &st);
  if (!st) get_uint(c, "bundle_group", 9007199254740991.0, &dummy, &present, ptr, e, &st);
  return st;
}

/* Context i's sensors (its own list, the defaults' or every sensor of the
 * scene): known, once each, films within the limits; counts its renders
 * into k->n_items, at most SVC_MAX_JOB_RENDERS in all. */
static rsw_status check_context_sensors(ctx_scan *cs, const cJSON *c, size_t i, const char *ptr,
                                        svc_error *e) {
  const scene *sc = cs->sc;
  const job_req *q = cs->q;
  job_check *k = cs->k;
  rsw_status st = RSW_OK;
  const cJSON *sens = cJSON_GetObjectItemCaseSensitive(c, "sensors");
  const char *sens_ptr = ptr;
  char sp[80];
  if (sens) {
    snprintf(sp, sizeof sp, "%s/sensors", ptr);
    sens_ptr = sp;
  } else if (q->d_sensors) {
    sens = q->d_sensors;
    sens_ptr = "/defaults/sensors";
  }
  if (sens) {
    if (!cJSON_IsArray(sens) || !sens->child)
      return svc_fail(e, RSW_ERR_TYPE, sens_ptr, "sensors must be a non-empty list of sensor ids");
    size_t n = 0;
    for (const cJSON *s = sens->child; s && !st; s = s->next, n++) {
      size_t si;
      char ep[120];
      snprintf(ep, sizeof ep, "%s/%zu", sens_ptr, n);
      if (!cJSON_IsString(s) || !svc_find_sensor(sc, s->valuestring, &si)) {
        st = svc_no_sensor(e, sc, ep, cJSON_IsString(s) ? s->valuestring : NULL);
        break;
      }
      if (cs->seen[si] == i + 1) {
        st = svc_fail(e, RSW_ERR_DUPLICATE, ep, "sensor '%s' appears twice in one context", s->valuestring);
        break;
      }
      cs->seen[si] = i + 1;
      if (!cs->film_ok[si]) {
        st = svc_check_film(cs->svc, sc, si, q->quantities, q->variance, ep, e);
        cs->film_ok[si] = !st;
      }
      k->n_items += k->n_nodes;
    }
  } else {
    if (!sc->n_sensors) st = svc_fail(e, RSW_ERR_INVALID, ptr, "the scene has no sensor");
    for (size_t si = 0; si < sc->n_sensors && !st; si++)
      if (!cs->film_ok[si]) {
        st = svc_check_film(cs->svc, sc, si, q->quantities, q->variance, ptr, e);
        cs->film_ok[si] = !st;
      }
    k->n_items += sc->n_sensors * k->n_nodes;
  }
  if (!st && k->n_items > SVC_MAX_JOB_RENDERS)
    st = svc_fail(e, RSW_ERR_LIMIT, ptr, "the job's renders (contexts times sensors) exceed %d",
                  SVC_MAX_JOB_RENDERS);
  return st;
}

/* Context i (at /contexts/i), in full. */
static rsw_status check_context(ctx_scan *cs, const cJSON *c, size_t i, svc_error *e) {
  char ptr[64];
  snprintf(ptr, sizeof ptr, "/contexts/%zu", i);
  const cJSON *w = NULL;
  rsw_status st = check_context_fields(cs, c, ptr, &w, e);
  if (!st) st = check_context_values(cs, c, i, w, ptr, e);
  if (!st) st = check_context_spp_seed(c, ptr, e);
  if (!st) st = check_context_sensors(cs, c, i, ptr, e);
  return st;
}

/* The contexts' coords (labels for the dataset): the same names in every
 * context, one type per name (nc_coords_build). */
static rsw_status context_coords(const job_req *q, nc_coords *out, svc_error *e) {
  const void **cj = malloc(q->n_contexts * sizeof *cj);
  if (!cj) return svc_fail(e, RSW_ERR_NOMEM, "/contexts", "out of memory");
  size_t i = 0;
  for (const cJSON *c = q->contexts->child; c; c = c->next, i++)
    cj[i] = cJSON_GetObjectItemCaseSensitive(c, "coords");
  rsw_err cerr = {0};
  rsw_status st = RSW_OK;
  if (nc_coords_build(cj, q->n_contexts, "/contexts", out, &cerr) != RSW_OK)
    st = svc_fail(e, cerr.code, cerr.where, "%s", cerr.msg);
  free(cj);
  return st;
}

/* Stage 2: the request against the scene (r), every context before any is
 * accepted. Validation reads the parameter table's keys, the sensors' ids
 * and films: all fixed at load, so no scene lock is needed (a running
 * render holds it for its whole duration). */
static rsw_status validate_request(service *svc, resident *r, job_req *q, job_check *k, svc_error *e) {
  scene *sc = r->sc;
  rsw_status st = check_params(sc, q->params, "/params", e);
  if (!st && q->bands && sc->variant != VARIANT_MONO)
    st = svc_fail(e, RSW_ERR_INVALID, "/bands", "bands apply to mono scenes; this scene is rgb");
  k->n_nodes = q->bands ? q->bands->n_wl : 1;
  /* Templates (the scene's under the job's), rendered for each context
   * into the overrides it renders with. */
  if (!st) st = tmpl_compile(sc, r->templates, "/scene/templates", q->templates, q->params, &k->ts, e);
  if (st) return st;
  ctx_scan cs = {.svc = svc, .sc = sc, .q = q, .k = k};
  /* Whether what the contexts render with depends on the wavelength: the
   * scene (under r->lock: a PATCH may be changing a table), a template
   * or a job-level table. Contexts' own tables are added as met. */
  if (sc->variant == VARIANT_MONO) {
    pthread_mutex_lock(&r->lock);
    cs.spectral = scene_wavelength_dependent(sc);
    pthread_mutex_unlock(&r->lock);
    cs.spectral = cs.spectral || tmpl_uses_coord(k->ts, "wavelength") || has_table(q->params);
  }
  size_t n_sensors = sc->n_sensors ? sc->n_sensors : 1;
  if ((k->ts && !(k->ctx_params = calloc(q->n_contexts * k->n_nodes, sizeof *k->ctx_params))) ||
      !(cs.sigs = calloc(q->n_contexts, sizeof *cs.sigs)) || !id_set_init(&cs.ids, q->n_contexts) ||
      !(cs.seen = calloc(n_sensors, sizeof *cs.seen)) ||
      !(cs.film_ok = calloc(n_sensors, sizeof *cs.film_ok)))
    st = svc_fail(e, RSW_ERR_NOMEM, "/contexts", "out of memory");
  if (!st) st = read_defaults(q, e);
  if (!st && sc->variant == VARIANT_MONO) cs.ranges = base_ranges(r, &cs.n_ranges);
  size_t i = 0;
  for (const cJSON *c = !st ? q->contexts->child : NULL; c && !st; c = c->next, i++)
    st = check_context(&cs, c, i, e);
  free(cs.ids.slot);
  free(cs.seen);
  free(cs.film_ok);
  free(cs.ranges);
  /* A sweep that changes nothing it renders is flagged (not refused:
   * replicates differing by seed alone are legitimate). */
  if (!st && q->n_contexts > 1)
    k->warnings = tmpl_sweep_warnings(cs.sigs, q->n_contexts, cs.spectral || cs.any_table);
  free(cs.sigs);
  if (!st) st = context_coords(q, &k->coords, e);
  return st;
}

/* The renders of context ci (c), from items[*next] on: one per sensor and
 * band node (node-major), with its seed and overrides. */
static rsw_status plan_context(service *svc, const scene *sc, const job_req *q, const job_check *k, job *jb,
                               const cJSON *c, size_t ci, size_t *next, svc_error *e) {
  const band_plan *bands = jb->bands;
  size_t n_nodes = k->n_nodes;
  rsw_status st = RSW_OK;
  const cJSON *id = cJSON_GetObjectItemCaseSensitive(c, "id");
  const cJSON *w = cJSON_GetObjectItemCaseSensitive(c, "wavelength");
  const cJSON *sens = cJSON_GetObjectItemCaseSensitive(c, "sensors");
  if (!sens) sens = q->d_sensors;
  uint64_t spp = q->d_spp, seed = 0;
  bool has_spp, has_seed;
  get_uint(c, "spp", 4294967295.0, &spp, &has_spp, "", e, &st);
  if (!has_spp) spp = q->d_spp;
  get_uint(c, "seed", 9007199254740991.0, &seed, &has_seed, "", e, &st);
  uint64_t group = 0;
  bool has_group;
  get_uint(c, "bundle_group", 9007199254740991.0, &group, &has_group, "", e, &st);
  size_t ns = sens ? (size_t)cJSON_GetArraySize(sens) : sc->n_sensors;
  jb->context_remaining[ci] = ns * n_nodes;
  for (size_t s = 0; s < ns * n_nodes && !st; s++, (*next)++) {
    render_item *it = &jb->items[*next];
    size_t nk = s / ns; /* node-major within the context */
    snprintf(it->context, sizeof it->context, "%s", id->valuestring);
    it->context_index = ci;
    const char *sname =
        sens ? cJSON_GetArrayItem(sens, (int)(s % ns))->valuestring : sc->sensors[s % ns]->base.id;
    svc_find_sensor(sc, sname, &it->sensor_index);
    snprintf(it->sensor, sizeof it->sensor, "%s", sc->sensors[it->sensor_index]->base.id);
    it->film_w = sc->sensors[it->sensor_index]->film->width;
    it->film_h = sc->sensors[it->sensor_index]->film->height;
    const cJSON *cc = cJSON_GetObjectItemCaseSensitive(c, "coords");
    const cJSON *cw = cJSON_IsObject(cc) ? cJSON_GetObjectItemCaseSensitive(cc, "wavelength") : NULL;
    it->wavelength = w ? w->valuedouble : cw ? cw->valuedouble : q->d_wl;
    it->spp = (uint32_t)spp;
    it->seed = has_seed ? seed : default_seed(q->seed, it->context, it->sensor);
    it->own_seed = has_seed;
    it->bundle_group = has_group ? group + 1 : 0;
    if (bands) { /* node renders: independent, each its own seed */
      it->node = nk + 1;
      it->wavelength = bands->wl[nk];
      it->seed = bands_node_seed(it->seed, it->wavelength);
    }
    it->quantities = q->quantities;
    it->variance = q->variance;
    /* Refused up front (the message names the sensor and spp) rather
     * than failing render by render. */
    if ((q->quantities || q->variance) && svc_check_planes(sc, it->sensor_index, it->spp, q->quantities,
                                                           q->variance, "/quantities", "/variance", e))
      st = e->err.code;
    it->params = k->ctx_params ? cJSON_Duplicate(k->ctx_params[ci * n_nodes + nk], 1)
                               : merge_params(q->params, cJSON_GetObjectItemCaseSensitive(c, "params"));
    if (!it->params) {
      st = svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
      break;
    }
    const sensor *se = sc->sensors[it->sensor_index];
    uint64_t eff = spp ? spp : se->sampler->sample_count;
    uint64_t ps = (uint64_t)se->film->width * (uint64_t)se->film->height * eff;
    if (ps > svc->opts.max_pixel_samples) {
      char p2[80];
      snprintf(p2, sizeof p2, "/contexts/%zu", ci);
      st = svc_fail(e, RSW_ERR_LIMIT, p2, "%llu pixel samples exceed this server's limit of %llu",
                    (unsigned long long)ps, (unsigned long long)svc->opts.max_pixel_samples);
    }
  }
  return st;
}

/* Whether every sensor the job renders takes a bundle of k
 * (render_check_bundle); the first refusal in *err. */
static rsw_status sensors_take_bundle(const scene *sc, const job *jb, int k, rsw_err *err) {
  for (size_t si = 0; si < sc->n_sensors; si++) {
    bool used = false;
    for (size_t i = 0; i < jb->n_items && !used; i++) used = jb->items[i].sensor_index == si;
    rsw_status st = used ? render_check_bundle(sc, si, k, err) : RSW_OK;
    if (st) return st;
  }
  return RSW_OK;
}

/* A job's "bundle" against every sensor it renders: K > 1 that a sensor
 * cannot take is a 422 naming /bundle and what stands in the way; "auto"
 * takes RENDER_MAX_BUNDLE where every one can (pages: surfaces and the
 * path integrator), else 3 (the colour's channels), else 1, the reason it
 * stopped short in jb->bundle_why (never refused). */
static rsw_status check_bundle(const scene *sc, job *jb, svc_error *e) {
  bool autok = jb->bundle == JOB_BUNDLE_AUTO;
  jb->bundle_unit = autok ? RENDER_MAX_BUNDLE : jb->bundle;
  if (!autok) {
    rsw_err err = {0};
    rsw_status st = jb->bundle > 1 ? sensors_take_bundle(sc, jb, jb->bundle, &err) : RSW_OK;
    return st ? svc_fail(e, st, "/bundle", "%s", err.msg) : RSW_OK;
  }
  static const int tries[] = {RENDER_MAX_BUNDLE, 3};
  jb->bundle = 1;
  for (size_t t = 0; t < sizeof tries / sizeof tries[0]; t++) {
    rsw_err err = {0};
    if (sensors_take_bundle(sc, jb, tries[t], &err) == RSW_OK) {
      jb->bundle = tries[t];
      break;
    }
    if (!jb->bundle_why[0]) snprintf(jb->bundle_why, sizeof jb->bundle_why, "%s", err.msg);
  }
  return RSW_OK;
}

/* A render's bundle key (plan_bundles): what must be the same for two
 * renders to share a bundle; params is its printed overrides ("" when
 * none). */
typedef struct bundle_key {
  const render_item *it;
  const char *params;
  size_t index;
} bundle_key;

static int bundle_key_cmp(const void *pa, const void *pb) {
  const render_item *a = ((const bundle_key *)pa)->it, *b = ((const bundle_key *)pb)->it;
  if (a->sensor_index != b->sensor_index) return a->sensor_index < b->sensor_index ? -1 : 1;
  if (a->spp != b->spp) return a->spp < b->spp ? -1 : 1;
  if (a->quantities != b->quantities) return a->quantities < b->quantities ? -1 : 1;
  if (a->variance != b->variance) return a->variance < b->variance ? -1 : 1;
  if (a->bundle_group != b->bundle_group) return a->bundle_group < b->bundle_group ? -1 : 1;
  return strcmp(((const bundle_key *)pa)->params, ((const bundle_key *)pb)->params);
}

/* A job's spectral bundles ("bundle" K > 1, mono): the renders that may
 * share a bundle (the same sensor, spp, planes, "bundle_group" and
 * overrides, no seed of their own: a wavelength sweep at one set of
 * overrides, whatever the axes' order; a context's band nodes) are cut by
 * rsw_bundle_runs, the rule the client's shards follow too
 * (common/bundle_plan.h): in the job's order, into bundles of K from the
 * first (a wavelength already in the bundle starts the next one); the
 * last may be smaller. So a job's bundles depend only on its renders and
 * their order (docs/experiments.md#spectral-bundles). False: out of
 * memory. */
static bool plan_bundles(job *jb) {
  size_t n = jb->n_items;
  for (size_t i = 0; i < n; i++) jb->items[i].bundle[0] = i, jb->items[i].bundle_n = 1;
  if (jb->bundle <= 1 || jb->variant != VARIANT_MONO || n < 2) return true;
  bundle_key *k = calloc(n, sizeof *k);
  char **printed = calloc(n, sizeof *printed);
  uint64_t *key = calloc(n, sizeof *key);
  double *wl = calloc(n, sizeof *wl);
  size_t *lead = calloc(n, sizeof *lead);
  bool ok = k && printed && key && wl && lead;
  for (size_t i = 0; i < n && ok; i++) {
    printed[i] = jb->items[i].params ? cJSON_PrintUnformatted(jb->items[i].params) : NULL;
    ok = !jb->items[i].params || printed[i];
    k[i] = (bundle_key){&jb->items[i], printed[i] ? printed[i] : "", i};
    wl[i] = jb->items[i].wavelength;
  }
  /* Equal keys, numbered in sorted order; a render with its own seed alone. */
  if (ok) qsort(k, n, sizeof *k, bundle_key_cmp);
  for (size_t i = 0, id = 0; i < n && ok; i++) {
    if (i && bundle_key_cmp(&k[i - 1], &k[i]) != 0) id++;
    key[k[i].index] = k[i].it->own_seed ? RSW_BUNDLE_ALONE : id;
  }
  ok = ok &&
       rsw_bundle_runs(n, key, wl, jb->bundle_unit > jb->bundle ? jb->bundle_unit : jb->bundle, lead) == 0;
  /* "auto" that came to fewer than its unit: each group, in order, cut
   * into bundles of jb->bundle (so a shard's groups still render as the
   * whole sweep's do). */
  size_t *count = ok && jb->bundle_unit > jb->bundle ? calloc(n, sizeof *count) : NULL;
  size_t *cur = count ? calloc(n, sizeof *cur) : NULL;
  if (count && !cur) ok = false;
  for (size_t i = 0; cur && i < n; i++) {
    size_t g = lead[i]; /* g <= i: its group's first, already numbered */
    if (count[g] % (size_t)jb->bundle == 0) cur[g] = i;
    count[g]++;
    lead[i] = cur[g];
  }
  free(count);
  free(cur);
  for (size_t i = 0; i < n && ok; i++) { /* a leader holds the list, in order; a mate points to it */
    if (lead[i] == i) continue;
    render_item *l = &jb->items[lead[i]];
    l->bundle[l->bundle_n++] = i;
    jb->items[i].bundle[0] = lead[i];
    jb->items[i].bundle_n = 0;
  }
  for (size_t i = 0; printed && i < n; i++) cJSON_free(printed[i]);
  free(printed);
  free(k);
  free(key);
  free(wl);
  free(lead);
  return ok;
}

/* Whether every key of a that sets a parameter of the sensor whose id is
 * id (its key, aliases resolved, starts with "id.") is in b, with the same
 * value. */
static bool same_sensor_params(const scene *sc, const char *id, const cJSON *a, const cJSON *b) {
  size_t n = strlen(id);
  for (const cJSON *k = a ? a->child : NULL; k; k = k->next) {
    size_t idx;
    param_info pi;
    rsw_err err = {0};
    if (params_lookup(sc, k->string, &idx, &err) || !params_info(sc, idx, &pi)) return false;
    if (strncmp(pi.key, id, n) != 0 || pi.key[n] != '.') continue;
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(b, k->string);
    if (!v || !cJSON_Compare(k, v, true)) return false;
  }
  return true;
}

/* Whether the job renders sensor si and its contexts all give it the
 * same parameters, so that its films' pixel angles are the same: held once
 * (share_angles), and reserved once for --max-result-bytes. A parameter
 * named two ways (a key and its alias) counts as different. */
static bool sensor_still(const scene *sc, const job *jb, size_t si) {
  const char *id = sc->sensors[si]->base.id;
  if (!id || !*id) return false;
  const render_item *first = NULL;
  for (size_t i = 0; i < jb->n_items; i++) {
    const render_item *it = &jb->items[i];
    if (it->sensor_index != si) continue;
    if (!first) {
      first = it;
      continue;
    }
    if (!same_sensor_params(sc, id, first->params, it->params) ||
        !same_sensor_params(sc, id, it->params, first->params))
      return false;
  }
  return first != NULL;
}

/* Stage 3: the job (*out) with its renders in context order, taking the
 * bands, coords and warnings; *reserve: the bytes its films will hold,
 * for --max-result-bytes. */
static rsw_status plan_job(service *svc, const scene *sc, job_req *q, job_check *k, job **out,
                           uint64_t *reserve, svc_error *e) {
  job *jb = calloc(1, sizeof *jb);
  if (!jb) return svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
  jb->coords = k->coords;
  k->coords = (nc_coords){0};
  jb->seed = q->seed;
  jb->variant = sc->variant;
  jb->warnings = k->warnings;
  k->warnings = NULL;
  jb->bands = q->bands;
  q->bands = NULL;
  /* No "bundle": "auto", the daemon's choice (docs/experiments.md#spectral-bundles);
   * 1 for a job restored from a record older than that default. */
  bool old_default = svc->restore_id && svc->restore_bundle_default;
  jb->bundle_asked = q->bundle != 0 || !old_default;
  if (q->bundle == 0) q->bundle = old_default ? 1 : JOB_BUNDLE_AUTO;
  jb->bundle = q->bundle == JOB_BUNDLE_AUTO ? JOB_BUNDLE_AUTO : q->bundle > 1 ? q->bundle : 1;
  jb->items = calloc(k->n_items, sizeof *jb->items);
  jb->context_remaining = calloc(q->n_contexts, sizeof *jb->context_remaining);
  rsw_status st = RSW_OK;
  if (!jb->items || !jb->context_remaining) st = svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
  size_t next = 0, ci = 0;
  for (const cJSON *c = !st ? q->contexts->child : NULL; c && !st; c = c->next, ci++)
    st = plan_context(svc, sc, q, k, jb, c, ci, &next, e);
  /* Items exist only if their array was allocated (job_free walks
   * n_items of them). */
  jb->n_items = jb->items ? k->n_items : 0;
  if (!st) st = check_bundle(sc, jb, e);
  if (!st && !plan_bundles(jb)) st = svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
  if (st) {
    job_free(jb);
    return st;
  }
  jb->n_contexts = q->n_contexts;
  jb->angle_slots = calloc(sc->n_sensors, sizeof *jb->angle_slots);
  if (!jb->angle_slots) {
    job_free(jb);
    return svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
  }
  jb->n_angle_slots = sc->n_sensors;
  uint64_t planes =
      (uint64_t)((q->quantities & RENDER_Q_BRDF) != 0) + ((q->quantities & RENDER_Q_BRF) != 0) + q->variance;
  *reserve = 0;
  for (size_t si = 0; si < sc->n_sensors; si++) {
    jb->angle_slots[si].once = sensor_still(sc, jb, si);
    if (jb->angle_slots[si].once) *reserve += svc_film_angle_bytes(sc, si);
  }
  /* Each plane as large as the film; the angles once a film, or once for
   * a sensor no context moves. */
  for (size_t i = 0; i < jb->n_items; i++) {
    size_t si = jb->items[i].sensor_index;
    uint64_t angles = svc_film_angle_bytes(sc, si);
    *reserve += (svc_film_bytes(sc, si) - angles) * (1 + planes) + (jb->angle_slots[si].once ? 0 : angles);
  }
  *out = jb;
  return RSW_OK;
}

/* svc->lock held: room for a job whose films take reserve bytes. Without
 * a state directory films live in memory: a job whose films cannot fit
 * under --max-result-bytes is refused now, not after rendering (with one,
 * films beyond the cap go to disk). And the queue must be below its
 * limit (a job being restored always has room). */
static rsw_status check_room_locked(service *svc, uint64_t reserve, svc_error *e) {
  uint64_t cap = svc->opts.max_result_bytes;
  if (cap && !svc_state_on(svc) &&
      reserve > cap - (svc->result_committed < cap ? svc->result_committed : cap))
    return svc_fail(
        e, RSW_ERR_STORAGE, "/contexts",
        "the job's films take %llu bytes; %llu of this server's %llu bytes of result storage "
        "(--max-result-bytes) are held by other jobs: fetch and delete finished jobs, or retry later",
        (unsigned long long)reserve, (unsigned long long)svc->result_committed, (unsigned long long)cap);
  if (svc->n_queue >= svc->opts.max_queue && !svc->restore_id) {
    rsw_status st =
        svc_fail(e, RSW_ERR_BUSY, "", "%zu jobs are already queued (the limit); retry later", svc->n_queue);
    e->retry_after_s = 1;
    return st;
  }
  return RSW_OK;
}

/* Stage 4: accept the job (taking it and the reference on r) or refuse it
 * and free both: room for it (check_room_locked), its id, its request
 * stored (with a state directory), then queued; the answer is built
 * before it is queued. */
static rsw_status enqueue_job(service *svc, resident *r, job *jb, uint64_t reserve, const char *idem_key,
                              const unsigned char digest[32], const char *body, size_t len, unsigned jm,
                              char **job_id_out, char **json_out, svc_error *e) {
  jb->res = r; /* keeps the ref taken by service_job_submit */
  memcpy(jb->scene_id, r->id, 65);
  memcpy(jb->body_digest, digest, 32);
  if (idem_key && !(jb->idem_key = strdup(idem_key))) {
    job_free(jb);
    svc_scene_release(svc, r);
    return svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
  }
  jb->created = time(NULL);
  jb->t_created = svc_now();
  svc_iso_time(jb->created, jb->created_iso);
  jb->state = JOB_QUEUED;
  pthread_mutex_lock(&svc->lock);
  rsw_status st = check_room_locked(svc, reserve, e);
  if (st) {
    pthread_mutex_unlock(&svc->lock);
    job_free(jb);
    svc_scene_release(svc, r);
    return st;
  }
  if (svc->restore_id) {
    snprintf(jb->id, sizeof jb->id, "%s", svc->restore_id);
    svc_state_resume_items(svc, jb);
  } else {
    /* The process's instance in the id: replicas behind one balancer never
     * hand out the same job id, so a request rerouted to another replica
     * (its own replica lost) gets 404, not somebody else's job. */
    snprintf(jb->id, sizeof jb->id, "job-%.8s-%06llu", svc->instance, (unsigned long long)++svc->next_job);
  }
  jb->revision = r->revision;
  bool ok = svc_grow((void **)&svc->jobs, &svc->cap_jobs, svc->n_jobs + 1, sizeof *svc->jobs, 0) &&
            svc_grow((void **)&svc->queue, &svc->cap_queue, svc->n_queue + 1, sizeof *svc->queue, 0);
  /* The answer is built before the job is queued: a job must not run
   * behind an error answer (the client would submit it again). */
  char *id_copy = ok ? strdup(jb->id) : NULL;
  char *answer = id_copy ? svc_print_json(job_json(jb), jm) : NULL;
  /* Durable before it is accepted: a job whose request cannot be stored
   * is refused (507), never acknowledged and then lost by a restart. */
  rsw_status sst = answer ? svc_state_job_saved(svc, jb, body, len, e) : RSW_OK;
  if (!answer || sst) {
    pthread_mutex_unlock(&svc->lock);
    free(answer);
    free(id_copy);
    job_free(jb);
    svc_scene_release(svc, r);
    return answer ? sst : svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
  }
  svc->jobs[svc->n_jobs++] = jb;
  svc->queue[svc->n_queue++] = jb;
  r->active_jobs++;
  if (!svc_state_on(svc)) {
    jb->result_reserve = reserve;
    svc->result_committed += reserve;
  }
  *job_id_out = id_copy;
  *json_out = answer;
  pthread_cond_broadcast(&svc->cond);
  pthread_cond_signal(&svc->work_cond);
  pthread_mutex_unlock(&svc->lock);
  return RSW_OK;
}

/* A request's parse, checks and plan on resident r: the job in *jb_out
 * (not queued) and the result memory it reserves. */
static rsw_status plan_request(service *svc, resident *r, const char *body, size_t len, job **jb_out,
                               uint64_t *reserve, svc_error *e) {
  job_req q = {0};
  job_check k = {0};
  rsw_status st = parse_request(body, len, &q, e);
  if (!st) st = validate_request(svc, r, &q, &k, e);
  if (!st) st = plan_job(svc, r->sc, &q, &k, jb_out, reserve, e);
  job_check_free(&k, q.n_contexts);
  job_req_free(&q);
  return st;
}

rsw_status service_job_submit(service *svc, const char *scene_id, const char *body, size_t len,
                              const char *idem_key, char **job_id_out, char **json_out, svc_error *e) {
  if (!service_ready(svc)) return svc_fail(e, RSW_ERR_UNAVAILABLE, "", "the server is shutting down");
  unsigned jm = svc_json_mark();
  unsigned char digest[32];
  if (!rsw_sha256(body, len, digest)) return svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
  if (idem_key) {
    bool found;
    rsw_status st = submit_replay(svc, scene_id, idem_key, digest, jm, job_id_out, json_out, &found, e);
    if (found) return st;
  }
  resident *r = svc_scene_acquire(svc, scene_id);
  if (!r) return svc_no_scene(e, scene_id);
  job *jb = NULL;
  uint64_t reserve = 0;
  rsw_status st = plan_request(svc, r, body, len, &jb, &reserve, e);
  if (st) {
    svc_scene_release(svc, r);
    return st;
  }
  return enqueue_job(svc, r, jb, reserve, idem_key, digest, body, len, jm, job_id_out, json_out, e);
}

/* A dry run: the submission's stages (room for it now included) but the
 * queue. */
rsw_status service_job_check(service *svc, const char *scene_id, const char *body, size_t len,
                             char **json_out, svc_error *e) {
  if (!service_ready(svc)) return svc_fail(e, RSW_ERR_UNAVAILABLE, "", "the server is shutting down");
  resident *r = svc_scene_acquire(svc, scene_id);
  if (!r) return svc_no_scene(e, scene_id);
  unsigned jm = svc_json_mark();
  job *jb = NULL;
  uint64_t reserve = 0;
  rsw_status st = plan_request(svc, r, body, len, &jb, &reserve, e);
  if (!st) { /* room for it now (result storage, the queue), as a submission would find */
    pthread_mutex_lock(&svc->lock);
    st = check_room_locked(svc, reserve, e);
    pthread_mutex_unlock(&svc->lock);
    if (st) job_free(jb);
  }
  if (!st) {
    /* What the job would be: its size, what "bundle" comes to, its warnings. */
    cJSON *o = cJSON_CreateObject();
    cJSON_AddBoolToObject(o, "dry_run", true);
    cJSON_AddStringToObject(o, "scene", r->id);
    cJSON_AddNumberToObject(o, "revision", (double)r->revision);
    cJSON_AddNumberToObject(o, "contexts_total", (double)jb->n_contexts);
    cJSON_AddNumberToObject(o, "renders_total", (double)jb->n_items);
    if (jb->bundle_asked) {
      cJSON_AddNumberToObject(o, "bundle", jb->bundle);
      if (jb->bundle_why[0]) cJSON_AddStringToObject(o, "bundle_why", jb->bundle_why);
    }
    cJSON_AddNumberToObject(o, "result_bytes", (double)reserve);
    if (jb->warnings) svc_json_put(o, "warnings", cJSON_Duplicate(jb->warnings, 1));
    if (!(*json_out = svc_print_json(o, jm))) st = svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
    job_free(jb);
  }
  svc_scene_release(svc, r);
  return st;
}

/* ---- the worker ------------------------------------------------------------------ */

static void finish_job(service *svc, job *j) {
  /* svc->lock held */
  if (atomic_load(&j->cancel))
    j->state = JOB_CANCELLED;
  else if (j->items_failed) {
    j->state = JOB_FAILED;
    if (!j->error[0])
      snprintf(j->error, sizeof j->error, "%zu of %zu renders failed", j->items_failed, j->n_items);
  } else
    j->state = JOB_SUCCEEDED;
  j->t_finished = svc_now();
  svc_iso_time(time(NULL), j->finished_iso);
  /* A finished job no longer holds its scene (it may be evicted). */
  resident *r = j->res;
  j->res = NULL;
  r->active_jobs--;
  if (--r->refs == 0 && r->deleted) svc_resident_free(r);
  svc_free_evicted(svc_evict_locked(svc, NULL));
  svc_state_job_finished(svc, j);
  unsigned jm = svc_json_mark();
  cJSON *d = cJSON_CreateObject();
  cJSON_AddStringToObject(d, "state", state_names[j->state]);
  cJSON_AddNumberToObject(d, "done", (double)j->items_done);
  cJSON_AddNumberToObject(d, "total", (double)j->n_items);
  push_event(svc, j, d, true, jm);
}

/* Item k's render ended with st (its film in *film when st is OK; e the
 * error otherwise): the film stored, counters, and its event. Called
 * without svc->lock; returns holding it. */
/* The first film of job j whose render replaced environment plugin
 * answers by black (film_image.plugin_failures) adds a warning to the
 * job (`raysweep sweep` prints the job's warnings, its dataset keeps
 * them); every such film says so in its own meta and result. svc->lock
 * held. */
static void note_plugin_failures(job *j, const render_item *it) {
  for (const cJSON *w = j->warnings ? j->warnings->child : NULL; w; w = w->next) {
    const cJSON *c = cJSON_GetObjectItemCaseSensitive(w, "code");
    if (cJSON_IsString(c) && strcmp(c->valuestring, "plugin_failures") == 0) return;
  }
  if (!j->warnings && !(j->warnings = cJSON_CreateArray())) return;
  char detail[1024];
  snprintf(detail, sizeof detail,
           "context '%s' (sensor '%s'): %llu environment plugin answers were replaced by black (first: %s); "
           "each film with such answers says how many in its plugin_failures",
           it->context, it->sensor, (unsigned long long)it->film.img.plugin_failures,
           it->film.img.plugin_failure);
  cJSON *w = cJSON_CreateObject();
  if (!w) return;
  cJSON_AddStringToObject(w, "code", "plugin_failures");
  cJSON_AddStringToObject(w, "coordinate", "");
  cJSON_AddStringToObject(w, "detail", detail);
  cJSON_AddItemToArray(j->warnings, w);
}

/* Sensor s's slot of job j's pixel angles (job.angle_slots, one a
 * sensor of its scene, made by plan_job), or NULL (then nothing is
 * shared). */
static struct job_angles *angle_slot(job *j, size_t s) {
  return s < j->n_angle_slots ? &j->angle_slots[s] : NULL;
}

/* Film im's pixel angles as its sensor's block (slot) where they are the
 * same as that sensor's last film's, else its own, kept for the next. */
static void share_angles(struct job_angles *slot, film_image *im) {
  size_t n = (size_t)im->width * (size_t)im->height * 2;
  if (!slot || !im->angles || im->angles == slot->block) return;
  if (slot->block && slot->n == n && memcmp(slot->block, im->angles, n * sizeof(double)) == 0) {
    film_angles_unref(im->angles);
    im->angles = film_angles_ref(slot->block);
    return;
  }
  film_angles_unref(slot->block);
  slot->block = film_angles_ref(im->angles);
  slot->n = n;
}

static void item_done(service *svc, job *j, size_t k, rsw_status st, svc_film *out, svc_error *e) {
  render_item *it = &j->items[k];
  size_t done = j->items_done + 1; /* only this worker writes it */
  struct job_angles *slot = NULL;
  if (!st) {
    slot = angle_slot(j, it->sensor_index);
    share_angles(slot, &out->img);
    it->film = *out;
    /* The seed the film was rendered with: its bundle's (its leader's),
     * which GET .../results, the job's record and its dataset name. */
    it->seed = out->img.seed;
    /* With a state directory every film goes to disk first. */
    snprintf(it->film.context, sizeof it->film.context, "%s", it->context);
    st = svc_state_film_write(svc, j, k, &it->film, e);
    if (st) svc_film_free(&it->film);
    it->on_disk = !st && svc_state_on(svc);
  }
  /* The event is built before taking svc->lock (only this worker
   * writes the job's counters), so a job of tiny renders holds the
   * lock for moments and requests are not starved of it. */
  if (st) rsw_err_format(&e->err, it->error, sizeof it->error);
  unsigned jm = svc_json_mark();
  cJSON *d = cJSON_CreateObject();
  cJSON_AddStringToObject(d, "context", it->context);
  cJSON_AddStringToObject(d, "sensor", it->sensor);
  if (it->node) cJSON_AddNumberToObject(d, "node", (double)(it->node - 1)); /* jobs with bands */
  cJSON_AddStringToObject(d, "state", st ? "failed" : "succeeded");
  if (st) cJSON_AddStringToObject(d, "error", it->error);
  cJSON_AddNumberToObject(d, "done", (double)done);
  cJSON_AddNumberToObject(d, "total", (double)j->n_items);
  char *ev = svc_print_json(d, jm);
  pthread_mutex_lock(&svc->lock);
  if (st) {
    it->state = JOB_FAILED;
    j->items_failed++;
    svc->renders_failed++;
  } else {
    it->state = JOB_SUCCEEDED;
    it->has_film = true;
    /* In memory: the film's pixels, and its angles unless it holds the
     * block counted with an earlier film of the job (share_angles). */
    const film_image *im = &it->film.img;
    uint64_t angles = im->angles ? (uint64_t)im->width * (uint64_t)im->height * 16 : 0;
    uint64_t mem = svc_film_mem(&it->film), cap = svc->opts.max_result_bytes;
    uint64_t held = mem - (slot && im->angles && im->angles == slot->counted ? angles : 0);
    if (it->on_disk) {
      svc->result_disk_bytes += mem;
      svc->results_on_disk++;
    }
    if (it->on_disk && cap && svc->result_bytes + held > cap) {
      /* Beyond the memory cap: served from disk only. */
      film_image_free(&it->film.img);
      it->has_film = false;
    } else {
      svc->result_bytes += held;
      it->mem_held = held;
      if (slot && im->angles) slot->counted = im->angles;
    }
    svc->contexts_rendered++;
    if (it->film.img.plugin_failures) note_plugin_failures(j, it);
  }
  j->items_done++;
  j->current = SIZE_MAX;
  if (--j->context_remaining[it->context_index] == 0) j->contexts_done++;
  push_event_text(svc, j, ev, false);
}

void *svc_worker_main(void *arg) {
  service *svc = arg;
  pthread_mutex_lock(&svc->lock);
  for (;;) {
    while (!svc->n_queue && !svc->stopping) {
      struct timespec ts;
      clock_gettime(CLOCK_REALTIME, &ts);
      ts.tv_sec += 5;
      pthread_cond_timedwait(&svc->work_cond, &svc->lock, &ts);
      svc_jobs_expire(svc);
    }
    if (svc->stopping) {
      /* Queued jobs end cancelled. */
      for (size_t i = 0; i < svc->n_queue; i++) {
        atomic_store(&svc->queue[i]->cancel, 1);
        finish_job(svc, svc->queue[i]);
      }
      svc->n_queue = 0;
      break;
    }
    job *j = svc->queue[0];
    memmove(svc->queue, svc->queue + 1, (svc->n_queue - 1) * sizeof *svc->queue);
    svc->n_queue--;
    j->state = JOB_RUNNING;
    j->t_started = svc_now();
    svc_iso_time(time(NULL), j->started_iso);
    for (size_t i = 0; i < j->n_items; i++) {
      if (atomic_load(&j->cancel) || svc->stopping) break;
      render_item *it = &j->items[i];
      if (it->state != JOB_QUEUED) continue; /* done before a restart */
      /* Its bundle (plan_bundles), whose members still queued take their
       * films from this render (after a restart some may be done: they
       * are rendered again, the same bits, and not stored twice). */
      size_t lead = it->bundle_n > 0 ? i : it->bundle[0];
      const size_t *mates = &i;
      int nb = 1;
      if (lead < j->n_items && j->items[lead].bundle_n > 0)
        mates = j->items[lead].bundle, nb = j->items[lead].bundle_n;
      it = &j->items[mates[0]];
      j->current = i;
      atomic_store(&j->current_samples.done, 0);
      atomic_store(&j->current_samples.total, 0);
      pthread_mutex_unlock(&svc->lock);
      svc_error e = {0};
      render_spec rs = {.sensor_index = it->sensor_index,
                        .spp = it->spp,
                        .seed = it->seed,
                        .wavelength = it->wavelength,
                        .overrides = it->params,
                        .cancel = &j->cancel,
                        .quantities = it->quantities,
                        .variance = it->variance,
                        .samples = &j->current_samples,
                        .bundle = nb > 1 ? nb : 0};
      for (int b = 0; b < nb && nb > 1; b++) {
        double w = j->items[mates[b]].wavelength;
        rs.bundle_wl[b] = w > 0 ? w : 550.0;
      }
      svc_film films[RENDER_MAX_BUNDLE];
      memset(films, 0, sizeof films);
      rsw_status st = svc_render_locked(svc, j->res, &rs, films, &e);
      if (st && st != RSW_ERR_CANCELLED && nb > 1) {
        /* A bundle that failed: each render alone, so that a failure
         * (its message naming a wavelength, say) is its own. */
        bool locked = false;
        for (int b = 0; b < nb && st != RSW_ERR_CANCELLED; b++) {
          render_item *m = &j->items[mates[b]];
          if (m->state != JOB_QUEUED) continue;
          if (locked) pthread_mutex_unlock(&svc->lock);
          locked = false;
          svc_error e1 = {0};
          render_spec r1 = rs;
          r1.seed = m->seed, r1.wavelength = m->wavelength, r1.overrides = m->params, r1.bundle = 0;
          svc_film f1;
          memset(&f1, 0, sizeof f1);
          st = svc_render_locked(svc, j->res, &r1, &f1, &e1);
          if (st == RSW_ERR_CANCELLED) break;
          item_done(svc, j, mates[b], st, &f1, &e1);
          locked = true;
        }
        if (!locked) pthread_mutex_lock(&svc->lock);
        if (st == RSW_ERR_CANCELLED) break;
        continue;
      }
      if (st == RSW_ERR_CANCELLED) {
        pthread_mutex_lock(&svc->lock);
        break;
      }
      bool locked = false;
      for (int b = 0; b < nb; b++) {
        if (j->items[mates[b]].state != JOB_QUEUED) {
          if (!st) svc_film_free(&films[b]);
          continue;
        }
        if (locked) pthread_mutex_unlock(&svc->lock);
        item_done(svc, j, mates[b], st, &films[b], &e);
        locked = true;
      }
      if (!locked) pthread_mutex_lock(&svc->lock);
    }
    finish_job(svc, j);
  }
  pthread_mutex_unlock(&svc->lock);
  return NULL;
}

/* Drop finished jobs older than the results TTL. svc->lock held. */
void svc_jobs_expire(service *svc) {
  double now = svc_now();
  for (size_t i = 0; i < svc->n_jobs;) {
    job *j = svc->jobs[i];
    bool done = j->state != JOB_QUEUED && j->state != JOB_RUNNING;
    if (done && now - j->t_finished > svc->opts.result_ttl_s) j->deleted = true;
    if (j->deleted && done) {
      svc->jobs[i] = svc->jobs[--svc->n_jobs];
      resident *r = j->res; /* NULL once finished */
      bool free_scene = r && --r->refs == 0 && r->deleted;
      for (size_t k = 0; k < j->n_items; k++)
        if (j->items[k].has_film) svc->result_bytes -= j->items[k].mem_held;
      svc->result_committed -= j->result_reserve;
      svc_state_job_remove(svc, j);
      job_free(j);
      if (free_scene) svc_resident_free(r);
      continue;
    }
    i++;
  }
}

void svc_jobs_free(service *svc) {
  for (size_t i = 0; i < svc->n_jobs; i++) {
    resident *r = svc->jobs[i]->res;
    job_free(svc->jobs[i]);
    if (r && --r->refs == 0 && r->deleted) {
      /* Deleted while its jobs still held it: no longer in svc->scenes. */
      svc_resident_free(r);
    }
  }
  free(svc->jobs);
  free(svc->queue);
  svc->jobs = NULL;
  svc->queue = NULL;
  svc->n_jobs = svc->n_queue = 0;
}

/* ---- queries --------------------------------------------------------------------- */

rsw_status service_job_list(service *svc, char **json_out, svc_error *e) {
  unsigned jm = svc_json_mark();
  cJSON *o = cJSON_CreateObject();
  cJSON *a = cJSON_AddArrayToObject(o, "jobs");
  pthread_mutex_lock(&svc->lock);
  svc_jobs_expire(svc);
  for (size_t i = 0; i < svc->n_jobs; i++)
    if (!svc->jobs[i]->deleted) svc_json_push(a, job_json(svc->jobs[i]));
  pthread_mutex_unlock(&svc->lock);
  return svc_json_out(json_out, o, jm, e);
}

rsw_status service_job_get(service *svc, const char *id, char **json_out, svc_error *e) {
  unsigned jm = svc_json_mark();
  pthread_mutex_lock(&svc->lock);
  job *j = find_job_locked(svc, id);
  cJSON *o = j ? job_json(j) : NULL;
  pthread_mutex_unlock(&svc->lock);
  if (!o) return no_job(e, id);
  return svc_json_out(json_out, o, jm, e);
}

/* Cancel: a queued job leaves the queue and ends now; a running one stops
 * at its render's next pixel. svc->lock held. */
static void stop_job(service *svc, job *j) {
  if (j->state == JOB_QUEUED) {
    for (size_t i = 0; i < svc->n_queue; i++)
      if (svc->queue[i] == j) {
        memmove(svc->queue + i, svc->queue + i + 1, (svc->n_queue - i - 1) * sizeof *svc->queue);
        svc->n_queue--;
        break;
      }
    atomic_store(&j->cancel, 1);
    finish_job(svc, j);
  } else if (j->state == JOB_RUNNING) {
    atomic_store(&j->cancel, 1);
  }
}

rsw_status service_job_cancel(service *svc, const char *id, char **json_out, svc_error *e) {
  unsigned jm = svc_json_mark();
  pthread_mutex_lock(&svc->lock);
  job *j = find_job_locked(svc, id);
  if (!j) {
    pthread_mutex_unlock(&svc->lock);
    return no_job(e, id);
  }
  stop_job(svc, j);
  cJSON *o = job_json(j);
  pthread_mutex_unlock(&svc->lock);
  return svc_json_out(json_out, o, jm, e);
}

rsw_status service_job_delete(service *svc, const char *id, svc_error *e) {
  pthread_mutex_lock(&svc->lock);
  job *j = find_job_locked(svc, id);
  if (!j) {
    pthread_mutex_unlock(&svc->lock);
    return no_job(e, id);
  }
  stop_job(svc, j);
  /* Freed by the next expiry pass once it has stopped. */
  j->deleted = true;
  pthread_cond_broadcast(&svc->cond);
  if (j->state != JOB_RUNNING) svc_jobs_expire(svc);
  pthread_mutex_unlock(&svc->lock);
  return RSW_OK;
}

/* One result of GET results: its object, printed. */
static char *result_text(const job *j, const render_item *it, unsigned jm) {
  cJSON *x = cJSON_CreateObject();
  cJSON_AddStringToObject(x, "context", it->context);
  cJSON_AddStringToObject(x, "sensor", it->sensor);
  cJSON_AddStringToObject(x, "state", state_names[it->state]);
  if (it->wavelength > 0) cJSON_AddNumberToObject(x, "wavelength", it->wavelength);
  if (it->node) cJSON_AddNumberToObject(x, "node", (double)(it->node - 1));
  cJSON_AddNumberToObject(x, "seed", (double)it->seed);
  if (j->coords.n) { /* the context's coords, for plots across the job (the viewer's sweep view) */
    cJSON *co = cJSON_AddObjectToObject(x, "coords");
    for (size_t k = 0; k < j->coords.n; k++) {
      const nc_coord *c = &j->coords.c[k];
      if (c->is_string)
        cJSON_AddStringToObject(co, c->name, c->str[it->context_index]);
      else
        cJSON_AddNumberToObject(co, c->name, c->num[it->context_index]);
    }
  }
  if (it->has_film || it->on_disk) {
    cJSON_AddNumberToObject(x, "spp", it->film.img.spp);
    cJSON_AddNumberToObject(x, "width", it->film.img.width);
    cJSON_AddNumberToObject(x, "height", it->film.img.height);
    cJSON *ch = cJSON_AddArrayToObject(x, "channels");
    const char *names[FILM_MAX_CHANNELS * (1 + FILM_MAX_PLANES)];
    int nc = film_image_all_channels(&it->film.img, names);
    for (int c = 0; c < nc; c++) svc_json_push(ch, cJSON_CreateString(names[c]));
    char href[512];
    if (it->node)
      snprintf(href, sizeof href, "/v1/jobs/%s/results/%s/%s?node=%zu", j->id, it->context, it->sensor,
               it->node - 1);
    else
      snprintf(href, sizeof href, "/v1/jobs/%s/results/%s/%s", j->id, it->context, it->sensor);
    cJSON_AddStringToObject(x, "href", href);
    if (it->film.img.unresolved_rays)
      cJSON_AddNumberToObject(x, "unresolved_rays", (double)it->film.img.unresolved_rays);
    if (it->film.img.plugin_failures) {
      cJSON_AddNumberToObject(x, "plugin_failures", (double)it->film.img.plugin_failures);
      cJSON_AddStringToObject(x, "plugin_failure", it->film.img.plugin_failure);
    }
  }
  if (it->error[0]) cJSON_AddStringToObject(x, "error", it->error);
  return svc_print_json(x, jm);
}

/* The text of item it's result, printed once and kept until it changes:
 * only its state and whether a film is there can change what it says (the
 * key), so a client that polls GET results while a job runs (`raysweep
 * sweep --spread` does, about 16 times a job) costs a copy per result, not
 * a cJSON object built and printed each time, nor svc->lock held that
 * long against the render thread's item_done. svc->lock held; NULL when
 * out of memory. */
static const char *result_text_kept(const job *j, render_item *it, unsigned jm) {
  unsigned key = (unsigned)it->state << 1 | (it->has_film || it->on_disk);
  if (it->result_json && it->result_key == key) return it->result_json;
  char *t = result_text(j, it, jm);
  if (!t) return NULL;
  free(it->result_json);
  it->result_json = t;
  it->result_key = key;
  return t;
}

/* GET results: {"job", "state", "results": [...], and with bands "bands"
 * and "band_results"}, the same text cJSON would print for the whole
 * object, put together from the results' texts. */
rsw_status service_job_results(service *svc, const char *id, char **json_out, svc_error *e) {
  unsigned jm = svc_json_mark();
  pthread_mutex_lock(&svc->lock);
  job *j = find_job_locked(svc, id);
  if (!j) {
    pthread_mutex_unlock(&svc->lock);
    return no_job(e, id);
  }
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "job", j->id);
  cJSON_AddStringToObject(o, "state", state_names[j->state]);
  char *head = svc_print_json(o, jm), *tail = NULL;
  if (j->bands) {
    cJSON *b = cJSON_CreateObject();
    svc_bands_results_json(j, b);
    tail = svc_print_json(b, jm);
  }
  svc_buf out = svc_buf_make(0);
  if (!head || (j->bands && !tail)) out.failed = true;
  if (head) svc_buf_append(&out, head, strlen(head) - 1); /* without its '}' */
  svc_buf_append(&out, ",\"results\":[", 12);
  for (size_t i = 0; i < j->n_items && !out.failed; i++) {
    const char *t = result_text_kept(j, &j->items[i], jm);
    if (!t) out.failed = true;
    if (i) svc_buf_append(&out, ",", 1);
    if (t) svc_buf_append(&out, t, strlen(t));
  }
  svc_buf_append(&out, "]", 1);
  if (tail) { /* ,"bands":[...],"band_results":[...]} */
    svc_buf_append(&out, ",", 1);
    svc_buf_append(&out, tail + 1, strlen(tail + 1));
  } else {
    svc_buf_append(&out, "}", 1);
  }
  pthread_mutex_unlock(&svc->lock);
  free(head);
  free(tail);
  *json_out = svc_buf_take(&out);
  if (*json_out) return RSW_OK;
  return svc_fail(e, RSW_ERR_NOMEM, "", "out of memory while building the answer");
}

/* Item order for find_item_locked: by context, sensor, then job order. */
static int item_name_cmp(const void *pa, const void *pb, void *arg) {
  const render_item *items = arg;
  size_t a = *(const size_t *)pa, b = *(const size_t *)pb;
  int c = strcmp(items[a].context, items[b].context);
  if (!c) c = strcmp(items[a].sensor, items[b].sensor);
  return c ? c : (a > b) - (a < b);
}

/* The index in j->items of the first render (in the job's order) of
 * context and sensor, or SIZE_MAX. A sorted index of the items is built at
 * the first lookup (items never change their names after planning), so
 * fetching every film of a job of n renders costs n log n string
 * compares, not n^2 / 2. Without memory for it, a linear scan. svc->lock
 * held. */
static size_t find_item_locked(job *j, const char *context, const char *sensor_id) {
  if (!j->by_name && j->n_items > 8 && (j->by_name = malloc(j->n_items * sizeof *j->by_name))) {
    for (size_t i = 0; i < j->n_items; i++) j->by_name[i] = i;
    qsort_r(j->by_name, j->n_items, sizeof *j->by_name, item_name_cmp, j->items);
  }
  if (!j->by_name) {
    for (size_t i = 0; i < j->n_items; i++)
      if (strcmp(j->items[i].context, context) == 0 && strcmp(j->items[i].sensor, sensor_id) == 0) return i;
    return SIZE_MAX;
  }
  size_t lo = 0, hi = j->n_items; /* first entry not below (context, sensor) */
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    const render_item *it = &j->items[j->by_name[mid]];
    int c = strcmp(it->context, context);
    if (!c) c = strcmp(it->sensor, sensor_id);
    if (c < 0)
      lo = mid + 1;
    else
      hi = mid;
  }
  if (lo == j->n_items) return SIZE_MAX;
  const render_item *it = &j->items[j->by_name[lo]];
  return strcmp(it->context, context) == 0 && strcmp(it->sensor, sensor_id) == 0 ? j->by_name[lo] : SIZE_MAX;
}

rsw_status service_job_result(service *svc, const char *id, const char *context, const char *sensor_id,
                              svc_film *out, svc_error *e) {
  const char *sensor_name = sensor_id;
  pthread_mutex_lock(&svc->lock);
  job *j = find_job_locked(svc, id);
  if (!j) {
    pthread_mutex_unlock(&svc->lock);
    return no_job(e, id);
  }
  if (j->bands) {
    pthread_mutex_unlock(&svc->lock);
    snprintf(e->key, sizeof e->key, "band"); /* the query parameter the problem names */
    return svc_fail(e, RSW_ERR_INVALID, "band",
                    "job %s has bands: ask for a band's film (?band=ID) or a node's (?node=K); its results "
                    "list both",
                    id);
  }
  size_t i = find_item_locked(j, context, sensor_name);
  if (i != SIZE_MAX) {
    const render_item *it = &j->items[i];
    if (!it->has_film && it->on_disk) {
      /* Beyond the memory cap or restored: read from the state directory. */
      svc_film_ref ref;
      svc_film_ref_set(&ref, j, i);
      pthread_mutex_unlock(&svc->lock);
      return svc_state_film_read(svc, &ref, out, e);
    }
    if (!it->has_film) {
      pthread_mutex_unlock(&svc->lock);
      if (it->state == JOB_FAILED)
        return svc_fail(e, RSW_ERR_NOT_FOUND, context, "context '%s' sensor '%s' has no film: it failed: %s",
                        context, sensor_name, it->error);
      return svc_fail(e, RSW_ERR_NOT_FOUND, context, "context '%s' sensor '%s' has no film yet (%s)", context,
                      sensor_name, state_names[it->state]);
    }
    /* The film, held (its pixels, angles and planes: one more reference
     * each): the job may be deleted while the response is written. */
    *out = it->film;
    film_image_share(&it->film.img, &out->img);
    pthread_mutex_unlock(&svc->lock);
    return RSW_OK;
  }
  pthread_mutex_unlock(&svc->lock);
  return svc_fail(e, RSW_ERR_NOT_FOUND, context, "job %s has no result for context '%s' and sensor '%s'", id,
                  context, sensor_name);
}

rsw_status service_job_next_event(service *svc, const char *id, uint64_t after, int timeout_ms,
                                  uint64_t *seq_out, char **json_out, bool *is_end, svc_error *e) {
  *json_out = NULL;
  *is_end = false;
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  ts.tv_sec += timeout_ms / 1000;
  ts.tv_nsec += (long)(timeout_ms % 1000) * 1000000L;
  if (ts.tv_nsec >= 1000000000L) ts.tv_sec++, ts.tv_nsec -= 1000000000L;
  pthread_mutex_lock(&svc->lock);
  for (;;) {
    job *j = find_job_locked(svc, id);
    if (!j) {
      pthread_mutex_unlock(&svc->lock);
      return no_job(e, id);
    }
    if (j->n_events > after) {
      job_event *ev = &j->events[after];
      *seq_out = ev->seq;
      *json_out = strdup(ev->json ? ev->json : "{}");
      *is_end = ev->end;
      pthread_mutex_unlock(&svc->lock);
      return RSW_OK;
    }
    if (pthread_cond_timedwait(&svc->cond, &svc->lock, &ts) != 0) break;
  }
  pthread_mutex_unlock(&svc->lock);
  return RSW_OK;
}

rsw_status service_job_result_npy_fd(service *svc, const char *id, const char *context, const char *sensor_id,
                                     int *fd_out, uint64_t *len_out, svc_error *e) {
  *fd_out = -1;
  *len_out = 0;
  if (!svc_state_on(svc)) return RSW_OK;
  pthread_mutex_lock(&svc->lock);
  job *j = find_job_locked(svc, id);
  if (!j) {
    pthread_mutex_unlock(&svc->lock);
    return no_job(e, id);
  }
  svc_film_ref ref;
  size_t k = SIZE_MAX;
  size_t i =
      j->bands ? SIZE_MAX : find_item_locked(j, context, sensor_id); /* bands: service_job_band_result */
  if (i != SIZE_MAX && j->items[i].on_disk) k = i;
  if (k != SIZE_MAX) svc_film_ref_set(&ref, j, k);
  pthread_mutex_unlock(&svc->lock);
  /* Deleted meanwhile: -1, and the in-memory path answers. */
  if (k != SIZE_MAX) *fd_out = svc_state_film_npy_fd(svc, &ref, len_out);
  return RSW_OK;
}

uint64_t svc_film_mem(const svc_film *f) {
  const film_image *im = &f->img;
  uint64_t px = (uint64_t)im->width * (uint64_t)im->height;
  return px * (uint64_t)im->channels * 4 * (uint64_t)(1 + im->n_planes) + (im->angles ? px * 16 : 0);
}

void svc_job_free(job *j) {
  job_free(j);
}

void svc_job_push_event(service *svc, job *j, cJSON *data, bool end) {
  push_event(svc, j, data, end, svc_json_mark());
}

job *svc_find_job_locked(service *svc, const char *id) {
  return find_job_locked(svc, id);
}
