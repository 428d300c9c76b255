/* Private state of the service layer, shared by its files (one per
 * resource: service.c, scenes.c, params.c, renders.c, blobs.c, jobs.c,
 * metrics.c). */
#ifndef RSW_SERVICE_INTERNAL_H
#define RSW_SERVICE_INTERNAL_H

#include <pthread.h>
#include <time.h>

#include <cjson/cJSON.h>

#include "../kernel/scene/param_table.h"
#include "../kernel/scene/params.h"
#include "../kernel/scene/scene.h"
#include "../kernel/scene/update.h"
#include "bands.h"
#include "dataset_nc.h"
#include "service.h"

/* A private copy of a resident scene for one render at a time
 * (renders.c). */
typedef struct svc_view {
  scene *sc;
  uint64_t revision; /* the base revision it reproduces */
  struct svc_view *next;
} svc_view;

/* A resident scene. The base scene `sc` is written only by PATCH (under
 * `lock`, once no render borrows it). A render never writes the base's
 * parameters: it borrows the base when it has no overrides and no other
 * render holds it (base_busy; a render still writes the base's
 * wavelength-dependent state), else takes a private view (renders.c), so
 * renders of one scene, with or without overrides, run concurrently.
 * `lock` guards base_busy, the views and the base's parameters; `cond`
 * says the base or a view came back. */
typedef struct resident {
  char id[65];
  char label[SVC_SCENE_LABEL_MAX + 1]; /* "" or the name it was pushed under (svc->lock) */
  /* The document it was loaded from: the id a push of that text gets.
   * Equal to id for the document's own scene (its twin); another scene of
   * the same document has an id of its own: a push while the twin had
   * changed (a fork) or a POST :copy (`copy`, never handed to a pusher).
   * A push is handed a twin or fork only in the document's state
   * (scenes.c, docs/daemon.md#a-document-yields-its-own-state). Fixed. */
  char doc[65];
  bool copy;
  scene *sc;
  uint64_t revision; /* base revision, +1 per PATCH that changed something */
  double load_s;
  time_t created;
  pthread_mutex_t lock;
  pthread_cond_t cond;
  bool base_busy;
  svc_view *views; /* idle views */
  int n_views;     /* views alive, idle or rendering */
  /* What a view is built from: the scene's text as posted, its variant,
   * the data root its file names resolved in, and every PATCH since the
   * load merged into one {key: value} object (a later value of a key
   * replaces the earlier, moved to the end). The one record of the
   * scene's PATCHes: views replay it, --state-dir stores it with the
   * revision and a reload applies it. NULL: out of memory while recording
   * a PATCH (no views; the stored record stays at the older revision).
   * Written under r->lock. */
  char *src;
  size_t src_len;
  bool src_xml;
  char src_variant[32];
  char *src_root;              /* NULL: the daemon's data root */
  unsigned char src_files[32]; /* digest of the referenced files' digests */
  cJSON *patches;
  /* The parameter table's entries at the base state (JSON, table order)
   * and their revision, so GET params answers without waiting for a
   * render that holds `lock` (renders apply per-context overrides). */
  pthread_mutex_t cache_lock;
  cJSON *base_params;
  uint64_t cache_revision;
  /* The last rebuild failed (out of memory): base_params is older than
   * the scene's values; GET params rebuilds it first (or fails). */
  bool cache_stale;
  int active_jobs; /* queued or running jobs on this scene (svc->lock) */
  int refs;        /* holders outside svc->lock (svc->lock) */
  bool deleted;    /* removed from the registry; freed at refs == 0 */
  /* Memory budget and durable state (state.c). */
  size_t bytes;       /* svc_scene_bytes at load and after each PATCH */
  uint64_t last_used; /* svc->use_clock at the last acquire (LRU) */
  bool pinned;        /* loaded at startup (--scene): never evicted */
  /* A render's overrides could not be undone (out of memory, every
   * retry): the scene's values are no longer its base state, so renders
   * and updates of it are refused until it is deleted and posted again
   * (r->lock). */
  bool broken;
  /* The JSON document's top-level "templates" (parameter-map templates,
   * templates.h), checked at load; NULL when none. Fixed at load. */
  cJSON *templates;
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
  /* The size of its sensor's film (plan_context; a restored job's record):
   * a stored film of another size is not this render's (film_open_ref). */
  int film_w, film_h;
  double wavelength;
  size_t node; /* jobs with bands: 1 + the index of wavelength in job.bands->wl; 0 otherwise */
  uint32_t spp;
  uint64_t seed;
  bool own_seed; /* the context gave its "seed" (never bundled: docs/experiments.md#spectral-bundles) */
  /* Its spectral bundle (job.bundle > 1; plan_bundles): the renders, its
   * leader first (the bundle's seed), as indices into job.items. A
   * bundle of one: bundle[0] is the item itself. */
  size_t bundle[RENDER_MAX_BUNDLE];
  int bundle_n;
  /* The context's "bundle_group" + 1 (0: none): renders of other groups
   * never share a bundle (docs/cluster.md#shards-and-spectral-bundles). */
  uint64_t bundle_group;
  unsigned quantities; /* RENDER_Q_*: the job's "quantities" */
  bool variance;       /* the job's "variance" */
  cJSON *params;       /* merged overrides (job-level, then context-level), owned */
  job_state state;
  svc_film film;
  bool has_film;
  uint64_t mem_held; /* what svc->result_bytes counts for its film while has_film (item_done) */
  bool on_disk;      /* the film's files are in the state directory; when
                      !has_film, film.img holds its header (no data) */
  char error[600];
  char *result_json;   /* its result's text in GET results, kept (jobs.c result_text_kept) */
  unsigned result_key; /* what that text was printed from: state, film there */
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
  size_t *by_name; /* items sorted by context and sensor, built at the first lookup (jobs.c) */
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
  uint64_t result_reserve; /* bytes counted in svc->result_committed */
  /* For the dataset (dataset.c): the contexts' coords (columns, n == 0
   * when none), the job seed, the scene's variant. */
  nc_coords coords;
  uint64_t seed;
  rsw_variant variant;
  /* The sweep's warnings (templates.h tmpl_sweep_warnings: a coordinate
   * or the wavelength that nothing depends on), a JSON array; NULL when
   * none. In the job's answers, its record and its dataset. */
  cJSON *warnings;
  /* The job's bands (bands.c), NULL without: each context renders once
   * per node wavelength, items context-major then node then sensor. */
  band_plan *bands;
  /* Per sensor (by sensor index; n_angle_slots of them, one a sensor of
   * the scene, made by plan_job), the pixel angles of its last film with
   * angles (a counted block, film_angles_ref; n doubles): the sensor's
   * next films whose angles are the same share it (item_done), so a sweep
   * holds one block a sensor, not one a film, however its sensors' films
   * interleave; and the block whose bytes svc->result_bytes counts
   * (compared, not held: a film of the job holds it). Written by the
   * job's worker alone. once:
   * the job's contexts all give the sensor the same parameters, so its
   * films' angles are the same (the job renders at its scene's revision:
   * nothing else moves the sensor), and were reserved once (plan_job). */
  struct job_angles {
    double *block;
    size_t n;
    const double *counted;
    bool once;
  } * angle_slots;
  size_t n_angle_slots;
  /* The render in progress (an index into items, SIZE_MAX when none) and
   * its samples, for the job's answers ("render"). */
  size_t current;
  render_progress current_samples;
  /* "bundle": wavelengths per path (render_opts.bundle), 1: none;
   * bundle_asked: the answers say what it came to (every job but one
   * restored from a record older than the "auto" default); bundle_why: why "auto" came to less than RENDER_MAX_BUNDLE ("" otherwise);
   * bundle_unit: the groups the bundles are cut from (plan_bundles), K, or
   * RENDER_MAX_BUNDLE for "auto", as the client's shards plan them. */
  int bundle;
  int bundle_unit;
  bool bundle_asked;
  char bundle_why[768];
} job;

struct service {
  service_opts opts;
  char blob_dir[4096];
  char data_root[4096]; /* realpath, "" when none */
  pthread_mutex_t lock;
  pthread_cond_t cond;      /* job events */
  pthread_cond_t work_cond; /* a job was queued, or shutdown (job workers wait on it
                               alone, so events do not wake idle workers) */
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
  pthread_t *workers; /* job workers: jobs run concurrently, one per worker */
  int n_workers;
  bool stopping;
  atomic_bool ready;
  char instance[17]; /* random per process: GET /v1 "instance" (which replica a balancer key reaches) */
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
  uint64_t films_nonfinite; /* films rendered with an inf or NaN value */
  double update_seconds[3]; /* none(+unchanged), spectral, geometric */
  uint64_t updates[3];
  /* Memory budget and durable state (state.c). */
  char state_dir[4096]; /* "" without --state-dir */
  int state_lock_fd;    /* flock'ed DIR/lock (-1: none) */
  bool blob_dir_temp;   /* blob_dir is a temporary directory: removed */
  uint64_t use_clock;   /* LRU clock (svc->lock) */
  size_t scene_bytes;   /* sum of resident scenes' bytes (svc->lock) */
  uint64_t scenes_evicted, scenes_reloaded;
  char (*evicted)[65]; /* ids evicted from memory, a ring (svc->lock) */
  size_t n_evicted, evicted_next;
  uint64_t result_bytes;                       /* films held in memory (svc->lock) */
  uint64_t result_committed;                   /* estimates reserved by live jobs, no state dir */
  uint64_t result_disk_bytes, results_on_disk; /* films written to disk */
  const char *restore_id;                      /* while restoring: the id a submission takes */
  int restore_bundle_default; /* while restoring: what no "bundle" means (1: a record from before "auto"; 0: auto) */
  uint64_t jobs_resumed, jobs_failed_on_restore;
  double restore_s;
  /* Trust and durability of the state directory (state.c). */
  bool state_legacy;               /* no DIR/format yet: records of the previous
                                      version are upgraded by the restore */
  atomic_bool state_unwritable;    /* the last write or probe failed: not ready */
  pthread_mutex_t probe_lock;      /* one readiness probe at a time */
  double state_probe_t;            /* when the last probe ran (svc_now) */
  atomic_ullong state_quarantined; /* files moved to DIR/quarantine */
  atomic_ullong state_write_failures;
};

/* Request limits besides the options (GET /v1 reports them). A job's
 * contexts are counted before any is read; a context id or a sensor may
 * appear once; the directions route answers for films of at most
 * SVC_MAX_DIRECTION_PIXELS pixels (~150 bytes of JSON each). */
#define SVC_MAX_JOB_CONTEXTS     100000
#define SVC_MAX_JOB_RENDERS      1000000
#define SVC_MAX_DIRECTION_PIXELS (1024 * 1024)

/* RSW_ERR_LIMIT when rendering sensor si of sc would take more film memory
 * than the server allows (--max-film-bytes); `where` is the request field
 * that chose the sensor. */
rsw_status svc_check_film(const service *svc, const scene *sc, size_t si, unsigned quantities, bool variance,
                          const char *where, svc_error *e);

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
/* Documents built under memory pressure (service.c): take a mark before
 * building, then print (o is deleted; NULL when any cJSON allocation of
 * this thread failed since the mark, or printing failed), or check it. */
unsigned svc_json_mark(void);
bool svc_json_ok(unsigned mark);
char *svc_print_json(cJSON *o, unsigned mark);
/* cJSON_AddItemToArray / cJSON_AddItemToObject that free the item when
 * the add fails (a NULL array or object, no memory for the key): the
 * plain calls leak it then. */
void svc_json_push(cJSON *array, cJSON *item);
void svc_json_put(cJSON *obj, const char *key, cJSON *item);
/* *json_out = svc_print_json(o, mark); RSW_OK, or RSW_ERR_NOMEM (set in e). */
rsw_status svc_json_out(char **json_out, cJSON *o, unsigned mark, svc_error *e);
/* Metrics (metrics.c): an applied parameter update. */
struct update_report;
void svc_count_update(service *svc, const struct update_report *rep);
/* Parameters (params.c). */
/* False when out of memory: the old cache stays, marked stale. */
bool svc_refresh_param_cache(resident *r);
rsw_status svc_no_scene(svc_error *e, const char *id);
rsw_status svc_map_to_updates(const cJSON *j, const scene *sc, const char *where, param_update **out,
                              size_t *n, svc_error *e);
void svc_free_updates(param_update *u, size_t n);
rsw_status svc_update_error(svc_error *e, const scene *sc, const param_update *u, size_t n,
                            const rsw_err *err);
/* err (from params_lookup and the like) about key into e, with the
 * closest keys when it is unknown (did-you-mean); returns the code. */
rsw_status svc_key_error(svc_error *e, const scene *sc, const char *key, const rsw_err *err);
/* The bytes a resident scene holds (metrics.c). */
size_t svc_scene_bytes(const scene *sc);
resident *svc_find_scene_locked(service *svc, const char *id); /* svc->lock held */
/* Find a resident scene and take a ref (svc->lock must NOT be held). */
resident *svc_scene_acquire(service *svc, const char *id);
void svc_scene_release(service *svc, resident *r);
/* Free a resident scene (no refs left). */
void svc_resident_free(resident *r);
/* Keep what a view of r is built from (scenes.c; false: out of memory). */
bool svc_keep_source(service *svc, resident *r, const char *text, size_t len, bool is_xml);
/* Load the scene r was loaded from again (scenes.c). */
rsw_status svc_scene_reload(service *svc, const resident *r, scene **out, rsw_err *err);
/* r's document loaded again with the PATCHes `patches` (NULL or {}: none)
 * applied: r's state at the revision they make (scenes.c; renders.c's
 * views, POST :copy). */
rsw_status svc_scene_build_at(service *svc, const resident *r, const cJSON *patches, scene **out,
                              svc_error *e);
/* Free r's idle views (renders.c; r->lock held or r unreachable). */
void svc_views_free(resident *r);
/* A copy of `old` (NULL: none) with the keys of a PATCH body set to its
 * values, each recorded under its canonical path in sc (a search key or an
 * alias replaces the entry's earlier value under any name, so that a view's
 * replay, and a render's override by path, never name one entry twice);
 * NULL when out of memory (built before the update, so that a PATCH that
 * cannot record itself changes nothing). */
cJSON *svc_patch_merged(const cJSON *old, const cJSON *body, const scene *sc);
/* Merge body's values into r->patches (false, r->patches unchanged, when
 * out of memory or when r has no record). */
bool svc_keep_patch(resident *r, const cJSON *body);
/* Render one context on a resident scene with `overrides` (a JSON object
 * {key: value}, may be NULL) on top of the base state, on the base or a
 * private view (the base state is never written). */
typedef struct render_spec {
  size_t sensor_index;
  uint32_t spp;
  uint64_t seed;
  double wavelength;
  const cJSON *overrides;
  const atomic_int *cancel;
  double deadline;
  unsigned quantities; /* RENDER_Q_* */
  bool variance;
  render_progress *samples; /* optional: the render's progress (render_opts.samples) */
  /* A spectral bundle (render_opts.bundle): 2..RENDER_MAX_BUNDLE films, at
   * bundle_wl[b], into out[b]; 0 or 1: one film at `wavelength`. */
  int bundle;
  double bundle_wl[RENDER_MAX_BUNDLE];
} render_spec;
/* A request's "quantities" (a list of "radiance", "brdf", "brf") into
 * RENDER_Q_* bits, or its "variance" (a boolean); ptr is the member's JSON
 * pointer for errors. */
rsw_status svc_parse_quantities(const cJSON *v, const char *ptr, unsigned *out, svc_error *e);
rsw_status svc_parse_variance(const cJSON *v, const char *ptr, bool *out, svc_error *e);
/* render_check_planes for sensor si with the request's pointers: ptr_q
 * ("/quantities") and ptr_v ("/variance") name the field at fault. */
rsw_status svc_check_planes(const scene *sc, size_t si, uint32_t spp, unsigned quantities, bool variance,
                            const char *ptr_q, const char *ptr_v, svc_error *e);
/* out: max(rs->bundle, 1) films. */
rsw_status svc_render_locked(service *svc, resident *r, const render_spec *rs, svc_film *out, svc_error *e);
/* Resolve a sensor given by id or decimal index. */
bool svc_find_sensor(const scene *sc, const char *name, size_t *index);
/* RSW_ERR_UNKNOWN_NAME at where for a sensor name that names nothing: the
 * closest id and the scene's sensors in the message, the closest in
 * e->candidates. */
rsw_status svc_no_sensor(svc_error *e, const scene *sc, const char *where, const char *name);
/* Fill a JSON object with a scene's summary (id, variant, sensors, revision). */
void svc_scene_summary(const resident *r, cJSON *o);
/* Memory budget (scenes.c): the resident scene's bytes changed or a
 * scene arrived; evict idle scenes least recently used while over
 * --max-scene-bytes (never `keep`, a pinned one, one with refs or active
 * jobs). svc->lock held. Returns the evicted residents, for the caller to
 * free after unlocking (NULL-terminated, malloc'ed; NULL when none). */
resident **svc_evict_locked(service *svc, const resident *keep);
/* A PATCH changed r's base state (r->lock held; r->patches already holds
 * every PATCHed value, svc_patch_merged): store it with --state-dir,
 * fsync'ed, and recount its bytes; RSW_ERR_STATE_DIR (507) when it cannot
 * be stored (the caller undoes the PATCH, and its bytes are not recounted). */
rsw_status svc_scene_patched(service *svc, resident *r, svc_error *e);
/* The scene's current values of the keys u names (values round-trip
 * exactly through their JSON text: applying them restores the scene
 * bitwise). renders.c */
rsw_status svc_param_snapshot(const scene *sc, const param_update *u, size_t n, param_update **out,
                              rsw_err *err);
/* How a scene is loaded besides a plain POST (scenes.c). */
struct post_extra {
  bool pinned;           /* a startup scene: never evicted, not stored */
  const char *expect_id; /* a reload: the id it must get */
  const char *doc;       /* a reload of a fork or copy: its document's id (NULL: expect_id) */
  bool copy;             /* a reload of a copy */
  const cJSON *patched;  /* a reload: parameters to apply first */
  uint64_t revision;     /* a reload: the revision they make */
};
void svc_free_evicted(resident **ev);
bool svc_was_evicted_locked(service *svc, const char *id);
void svc_forget_evicted_locked(service *svc, const char *id);
/* A finished job restored from the state directory (its submission body):
 * the contexts' coords, the job seed and its bands, which its dataset needs
 * (dataset.c; left empty when the body does not give them). */
void svc_job_restore_labels(job *j, const char *body, size_t len);
/* Durable state (state.c); every function is a no-op without a state
 * directory. */
rsw_status svc_state_open(service *svc, rsw_err *err);
bool svc_state_on(const service *svc);
/* A scene's document: id, or for a fork or copy its own id with doc (its
 * document's id) and copy in the header line. */
rsw_status svc_state_scene_save(service *svc, const char *id, const char *doc, bool copy, bool is_xml,
                                const char *variant, const char *body, size_t len, svc_error *e);
/* doc (may be NULL) receives the document's id ("" when it is id itself),
 * copy (may be NULL) whether it is a copy. */
bool svc_state_scene_read(service *svc, const char *id, char **body, size_t *len, bool *is_xml,
                          char variant[32], cJSON **patched, uint64_t *revision, char doc[65], bool *copy);
/* Whether scene id has a parameter record: its PATCHed keys (*patched,
 * the caller deletes it) at *revision. */
bool svc_state_scene_params(service *svc, const char *id, cJSON **patched, uint64_t *revision);
/* Store r's PATCHed parameters at its revision, fsync'ed; RSW_ERR_STATE_DIR
 * (507) when they cannot be (the caller undoes the PATCH). r->lock held. */
rsw_status svc_state_scene_patched(service *svc, resident *r, svc_error *e);
void svc_state_scene_remove(service *svc, const char *id);
/* Store job j's request, fsync'ed, before it is accepted; RSW_ERR_STATE_DIR
 * (507) when it cannot be. svc->lock held. */
rsw_status svc_state_job_saved(service *svc, const job *j, const char *body, size_t len, svc_error *e);
void svc_state_job_finished(service *svc, const job *j); /* svc->lock held */
void svc_state_job_remove(service *svc, const job *j);
/* Write item k's film (svc->lock NOT held). */
rsw_status svc_state_film_write(service *svc, const job *j, size_t k, const svc_film *f, svc_error *e);
/* Which stored film a reader wants: its address (job, item k) and the
 * identity it must carry (scene, context, sensor); a film whose checksum
 * or identity does not match is quarantined, never served. */
typedef struct svc_film_ref {
  char job[40];
  size_t k;
  char scene[65];
  char context[72];
  char sensor[256];
  int width, height; /* the render's film size; 0: not known */
} svc_film_ref;
void svc_film_ref_set(svc_film_ref *ref, const job *j, size_t k); /* svc->lock held */
rsw_status svc_state_film_read(service *svc, const svc_film_ref *ref, svc_film *out, svc_error *e);
bool svc_state_film_header(service *svc, const svc_film_ref *ref, svc_film *out);
/* Item k's film as .npy: a descriptor at offset 0 and the length to
 * send; -1 when not on disk (or quarantined). */
int svc_state_film_npy_fd(service *svc, const svc_film_ref *ref, uint64_t *len);
/* Whether the state directory takes writes now (a probe write, at most
 * once a second); false with *why set when it does not. */
bool svc_state_writable(service *svc, const char **why);
/* Test hook: when set, every state-directory write first asks it; a
 * non-zero answer is the errno the write fails with (ENOSPC: a full disk). */
extern int (*svc_state_fault_hook)(const char *path);
/* Store a file atomically (temporary file created O_EXCL|O_NOFOLLOW with a
 * random suffix in the same directory, fsync, rename, fsync of the
 * directory). false with errno set. (blobs.c) */
bool svc_write_file(const char *path, const void *data, size_t len);
void svc_state_restore(service *svc);
/* A job being resumed (svc->restore_id): its renders whose film is on
 * disk count done. svc->lock held, before it is queued. */
void svc_state_resume_items(service *svc, job *j);
/* Bytes a film of this sensor takes in memory (data and angles). */
uint64_t svc_film_bytes(const scene *sc, size_t sensor_index);
/* Of those, the pixel angles' (16 bytes a pixel; 0 for a sensor without). */
uint64_t svc_film_angle_bytes(const scene *sc, size_t sensor_index);
/* Jobs (jobs.c). */
void *svc_worker_main(void *arg);
void svc_jobs_free(service *svc);
void svc_jobs_expire(service *svc); /* svc->lock held */
void svc_job_free(job *j);
void svc_job_push_event(service *svc, job *j, cJSON *data, bool end); /* svc->lock held */
job *svc_find_job_locked(service *svc, const char *id);
/* Bytes a film holds in memory (data and angles). */
uint64_t svc_film_mem(const svc_film *f);
/* An id of a context or a band: [A-Za-z0-9._-]{1,64} (jobs.c). */
bool svc_valid_id(const char *s);
/* Bands in jobs (bands.c): the checks of a job with bands at submission
 * of context c at ptr: it may carry no wavelength, in itself or as a
 * coord. */
rsw_status svc_bands_check_context(const band_plan *p, const cJSON *c, const char *ptr, svc_error *e);
/* The "bands" member of a band job's results (svc->lock held). */
void svc_bands_results_json(const job *j, cJSON *o);

#endif
