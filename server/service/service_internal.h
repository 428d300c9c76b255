/* Private state of the service layer, shared by its files (one per
 * resource: service.c, scenes.c, params.c, renders.c, blobs.c, jobs.c,
 * metrics.c). */
#ifndef RSW_SERVICE_INTERNAL_H
#define RSW_SERVICE_INTERNAL_H

#include <pthread.h>
#include <time.h>

#include <cjson/cJSON.h>

#include "../kernel/scene/params.h"
#include "../kernel/scene/scene.h"
#include "service.h"

/* A resident scene. `lock` serialises everything that touches the scene's
 * parameter state: renders (which apply per-context overrides and restore
 * the base state), PATCHes. */
typedef struct resident {
  char id[65];
  scene *sc;
  uint64_t revision; /* base revision, +1 per PATCH that changed something */
  double load_s;
  time_t created;
  pthread_mutex_t lock;
  /* The parameter table's entries at the base state (JSON, table order)
   * and their revision, so GET params answers without waiting for a
   * render that holds `lock` (renders apply per-context overrides). */
  pthread_mutex_t cache_lock;
  cJSON *base_params;
  uint64_t cache_revision;
  int active_jobs; /* queued or running jobs on this scene (svc->lock) */
  int refs;        /* holders outside svc->lock (svc->lock) */
  bool deleted;    /* removed from the registry; freed at refs == 0 */
} resident;

/* One render of a job: a (context, sensor) pair. */
typedef enum job_state {
  JOB_QUEUED,
  JOB_RUNNING,
  JOB_SUCCEEDED,
  JOB_FAILED,
  JOB_CANCELLED
} job_state;

typedef struct render_item {
  char context[72];
  size_t context_index;
  char sensor[256];
  size_t sensor_index;
  double wavelength;
  uint32_t spp;
  uint64_t seed;
  cJSON *params; /* merged overrides (job-level, then context-level), owned */
  job_state state;
  svc_film film;
  bool has_film;
  char error[600];
} render_item;

typedef struct job_event {
  uint64_t seq;
  char *json;
  bool end;
} job_event;

typedef struct job {
  char id[40];
  resident *res; /* holds a ref */
  char scene_id[65];
  uint64_t revision;
  job_state state;
  time_t created;
  double t_created, t_started, t_finished; /* monotonic */
  char created_iso[32], started_iso[32], finished_iso[32];
  render_item *items;
  size_t n_items, items_done, items_failed;
  size_t n_contexts;
  size_t *context_remaining; /* renders left per context */
  size_t contexts_done;
  atomic_int cancel;
  job_event *events;
  size_t n_events, cap_events;
  char *idem_key;
  unsigned char body_digest[32];
  char error[600];
  bool deleted;
} job;

struct service {
  service_opts opts;
  char blob_dir[4096];
  char data_root[4096]; /* realpath, "" when none */
  pthread_mutex_t lock;
  pthread_cond_t cond; /* queue and job events */
  resident **scenes;
  size_t n_scenes, cap_scenes;
  /* body digest -> scene id, so reposting the same text skips a load */
  struct raw_index {
    unsigned char digest[32];
    char id[65];
  } * raw;
  size_t n_raw, cap_raw;
  job **jobs;
  size_t n_jobs, cap_jobs;
  job **queue;
  size_t n_queue, cap_queue;
  uint64_t next_job;
  pthread_t worker;
  bool worker_started;
  bool stopping;
  atomic_bool ready;
  /* metrics */
  struct req_count {
    char route[96];
    int status;
    uint64_t n;
  } * reqs;
  size_t n_reqs, cap_reqs;
  uint64_t contexts_rendered, renders_failed;
  size_t sync_renders; /* synchronous renders (POST :render) in progress */
  double render_seconds;
  uint64_t unresolved_rays; /* render_stats.unresolved over all renders */
  double update_seconds[3]; /* none(+unchanged), spectral, geometric */
  uint64_t updates[3];
};

/* Helpers shared by the service files. */
double svc_now(void);
void svc_iso_time(time_t t, char out[32]);
/* Record an error (the first one wins) and return its code. The HTTP
 * status follows from the code alone (rsw_status_http, status.h): pick the
 * code that says what went wrong; never a status. */
rsw_status svc_fail(svc_error *e, rsw_status code, const char *where, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/* A request body read strictly as one JSON document: empty bodies,
 * malformed JSON and anything but blanks after the document are
 * RSW_ERR_PARSE; a \u0000 (or raw NUL) in any string is RSW_ERR_INVALID
 * naming the member (cJSON would cut the string at the NUL). *out (free
 * with cJSON_Delete) only on success. */
rsw_status svc_parse_body(const char *body, size_t len, cJSON **out, svc_error *e);
/* The same checks on a body parsed elsewhere (body.c). */
rsw_status svc_check_body(const char *body, size_t len, svc_error *e);
/* The code for a kernel error about something a request named: an
 * unknown key or sensor (kernel NOT_FOUND) is RSW_ERR_UNKNOWN_NAME, a
 * value that does not parse is RSW_ERR_INVALID; others are kept. */
rsw_status svc_request_code(rsw_status kernel_code);
/* Print and free a JSON document (NULL when out of memory). */
char *svc_print_json(cJSON *o);
/* Metrics (metrics.c): an applied parameter update. */
struct update_report;
void svc_count_update(service *svc, const struct update_report *rep);
/* Parameters (params.c). */
void svc_refresh_param_cache(resident *r);
rsw_status svc_no_scene(svc_error *e, const char *id);
rsw_status svc_map_to_updates(const cJSON *j, const scene *sc, const char *where, param_update **out,
                              size_t *n, svc_error *e);
void svc_free_updates(param_update *u, size_t n);
rsw_status svc_update_error(svc_error *e, const scene *sc, const param_update *u, size_t n,
                            const rsw_err *err);
/* The bytes a resident scene holds (metrics.c). */
size_t svc_scene_bytes(const scene *sc);
resident *svc_find_scene_locked(service *svc, const char *id); /* svc->lock held */
/* Find a resident scene and take a ref (svc->lock must NOT be held). */
resident *svc_scene_acquire(service *svc, const char *id);
void svc_scene_release(service *svc, resident *r);
/* Free a resident scene (no refs left). */
void svc_resident_free(resident *r);
/* Render one context on a resident scene: apply `overrides` (a JSON
 * object {key: value}, may be NULL) on top of the base state, render,
 * restore the base state. Takes r->lock. */
typedef struct render_spec {
  size_t sensor_index;
  uint32_t spp;
  uint64_t seed;
  double wavelength;
  const cJSON *overrides;
  const atomic_int *cancel;
  double deadline;
} render_spec;
rsw_status svc_render_locked(service *svc, resident *r, const render_spec *rs, svc_film *out, svc_error *e);
/* Resolve a sensor given by id or decimal index. */
bool svc_find_sensor(const scene *sc, const char *name, size_t *index);
/* Fill a JSON object with a scene's summary (id, variant, sensors, revision). */
void svc_scene_summary(const resident *r, cJSON *o);
/* Jobs (jobs.c). */
void *svc_worker_main(void *arg);
void svc_jobs_free(service *svc);
void svc_jobs_expire(service *svc); /* svc->lock held */

#endif
