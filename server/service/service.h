/* The service layer of raysweepd: resident scenes, blobs, parameter
 * updates, synchronous renders and jobs of kernel contexts. No HTTP types:
 * server/http/ translates requests into these calls and their results and
 * errors into responses (see proto/openapi.yaml, docs/daemon.md).
 *
 * Every function is thread-safe unless noted. Errors come back as an
 * rsw_status with an svc_error naming the place (JSON pointer, parameter
 * key) and, for unknown keys, candidate keys. The HTTP status follows
 * from the code alone (rsw_status_http): server/http decides it, never the
 * service. */
#ifndef RSW_SERVICE_H
#define RSW_SERVICE_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../kernel/render.h"
#include "rsw_error.h"

typedef struct service service;

typedef struct svc_error {
  rsw_err err;             /* code, where (pointer or key), message */
  char key[256];           /* parameter key when the error is about one */
  char candidates[3][256]; /* closest keys for an unknown key ("" unused) */
  int retry_after_s;       /* for 429 */
} svc_error;

typedef struct service_opts {
  size_t size;                /* sizeof(service_opts) */
  int render_threads;         /* 0: all cores */
  const char *data_root;      /* plain file names in scenes resolve only
                                  inside it (NULL: none allowed) */
  const char *blob_dir;       /* where blobs are stored (created) */
  size_t max_queue;           /* queued jobs before 429 (default 64) */
  double result_ttl_s;        /* finished jobs' results live this long
                                  (default 3600) */
  uint64_t max_pixel_samples; /* width*height*spp*sensors per request
                                  (default 2^32) */
  size_t max_body_bytes;      /* reported in GET /v1 (the HTTP layer
                                  enforces it) */
  uint64_t max_film_bytes;    /* memory one render's film may take
                                  (sensor_film_bytes), checked before
                                  anything is allocated (default 1 GiB) */
  /* Durable state (state.c): blobs (unless blob_dir is given), scene
   * documents, job records and finished films live under it, written
   * through a temporary file, fsync and rename; a restart restores them.
   * NULL: everything in memory (blob_dir NULL then means a temporary
   * directory removed by service_free). */
  const char *state_dir;
  /* Resident scenes' bytes (geometry and acceleration) beyond which idle
   * scenes are evicted least recently used (0: no budget). */
  uint64_t max_scene_bytes;
  /* Finished films held in memory, in bytes (0: no cap). Beyond it films
   * live on disk only (with state_dir) or a job whose films cannot fit is
   * refused up front (RSW_ERR_STORAGE, 507). */
  uint64_t max_result_bytes;
} service_opts;

rsw_status service_new(const service_opts *opts, service **out, rsw_err *err);
/* Cancels running work, joins the workers, frees everything. NULL ok. */
void service_free(service *svc);
/* Stop accepting work (ready goes false); running jobs are cancelled. */
void service_shutdown(service *svc);
bool service_ready(const service *svc);
/* GET /v1/health/ready: ready, and room in the job queue (--max-queue), so
 * that a load balancer's health check takes a full replica out of its ring
 * until it has room again. *why_out (may be NULL) says which is missing. */
bool service_accepts_jobs(service *svc, const char **why_out);
/* With a state directory: restore its jobs (finished ones fetchable,
 * interrupted ones resumed or failed with the reason). Call once, after
 * the startup scenes are loaded and before serving requests. */
void service_restore(service *svc);

/* ---- JSON documents ---------------------------------------------------------
 * Results that are JSON documents come back as malloc'ed, NUL-terminated
 * strings (*json_out, free()). */

/* GET /v1 body. */
char *service_info_json(service *svc);
/* GET /metrics body (Prometheus text). http_requests is maintained by the
 * HTTP layer through service_count_request. */
char *service_metrics_text(service *svc);
void service_count_request(service *svc, const char *route, int status);

/* ---- scenes ------------------------------------------------------------------ */

/* Load a scene from a request body; is_xml picks the reader. variant may be
 * NULL. On success *created tells whether it is new (201) or was already
 * resident (200, no work done) and *json_out is the SceneSummary. */
rsw_status service_scene_post(service *svc, const char *body, size_t len, bool is_xml, const char *variant,
                              bool *created, char **id_out, char **json_out, svc_error *e);
/* Load a scene file at startup (--scene) or the embedded default. */
rsw_status service_scene_load_file(service *svc, const char *path, char **id_out, svc_error *e);
rsw_status service_scene_load_text(service *svc, const char *text, size_t len, bool is_xml, const char *name,
                                   char **id_out, svc_error *e);
rsw_status service_scene_list(service *svc, char **json_out, svc_error *e);
/* A scene's label (the name it was pushed under: SceneSummary "name"),
 * set by the first push that gives one; *json_out is the SceneSummary.
 * service_scene_label_ok: a file name, 1 to SVC_SCENE_LABEL_MAX bytes, no
 * '/' or control character. */
#define SVC_SCENE_LABEL_MAX 255
bool service_scene_label_ok(const char *label);
rsw_status service_scene_label(service *svc, const char *id, const char *label, char **json_out,
                               svc_error *e);
rsw_status service_scene_get(service *svc, const char *id, char **json_out, svc_error *e);
rsw_status service_scene_delete(service *svc, const char *id, bool force, svc_error *e);
/* service_scene_post with the client's name for the document (its file's
 * name, NULL: scene.json or scene.xml), which messages about its text use
 * (`a.xml:6: ...`); not part of the id. */
rsw_status service_scene_post_named(service *svc, const char *body, size_t len, bool is_xml,
                                    const char *variant, const char *name, bool *created, char **id_out,
                                    char **json_out, svc_error *e);
/* POST :reset: the scene back to its document's state (the values of the
 * keys PATCHed since, from the document); +1 revision when a value
 * changed. *json_out: the SceneSummary with "changed" and "keys". */
rsw_status service_scene_reset(service *svc, const char *id, char **json_out, svc_error *e);
/* POST :copy: a new scene (a fresh id) in scene id's current state, never
 * handed to a pusher of the document; *json_out: its SceneSummary. */
rsw_status service_scene_copy(service *svc, const char *id, char **id_out, char **json_out, svc_error *e);

/* GET params: *revision_out is the base revision (the ETag). */
rsw_status service_params_get(service *svc, const char *id, const char *match, const char *cls,
                              char **json_out, uint64_t *revision_out, svc_error *e);
/* As service_params_get, with every buffer's values however long (the
 * table above gives a buffer longer than 16 numbers as {"length": n}).
 * Reading them waits for a running render of the scene. */
rsw_status service_params_get_full(service *svc, const char *id, const char *match, const char *cls,
                                   char **json_out, uint64_t *revision_out, svc_error *e);
/* PATCH params: body is a JSON object {key: value}. if_match < 0: none. */
rsw_status service_params_patch(service *svc, const char *id, const char *body, size_t len, int64_t if_match,
                                char **json_out, uint64_t *revision_out, svc_error *e);

/* A film produced by a render, with its context. */
typedef struct svc_film {
  film_image img;
  char scene[65];
  uint64_t revision;
  char context[72];
  char sensor[256];
} svc_film;
void svc_film_free(svc_film *f);

/* POST :render (body: RenderRequest). Blocks until done or timeout_s, or
 * until *cancel (borrowed, may be NULL) becomes non-zero: RSW_ERR_CANCELLED
 * (the HTTP layer sets it when the client hangs up). */
rsw_status service_render(service *svc, const char *id, const char *body, size_t len,
                          const atomic_int *cancel, svc_film *out, svc_error *e);

/* GET sensors/{sensor}/directions. */
rsw_status service_directions(service *svc, const char *id, const char *sensor, char **json_out,
                              svc_error *e);

/* ---- blobs ------------------------------------------------------------------- */
/* created: false when it existed already. 422 on a digest mismatch. */
rsw_status service_blob_put(service *svc, const char *sha256_hex, const void *data, size_t len, bool *created,
                            svc_error *e);
bool service_blob_exists(service *svc, const char *sha256_hex);
/* Size in bytes of a stored blob, or -1 when absent. */
long long service_blob_size(service *svc, const char *sha256_hex);
/* body {digests:[...]} -> {missing:[...]} */
rsw_status service_blobs_missing(service *svc, const char *body, size_t len, char **json_out, svc_error *e);

/* ---- jobs -------------------------------------------------------------------- */
/* idem_key may be NULL. *job_id_out (malloc'ed) for the Location header. */
rsw_status service_job_submit(service *svc, const char *scene_id, const char *body, size_t len,
                              const char *idem_key, char **job_id_out, char **json_out, svc_error *e);
/* POST .../jobs?dry_run=1: the request checked and planned as a submission
 * is, nothing queued; *json_out {dry_run, scene, revision, contexts_total,
 * renders_total, bundle, bundle_why, result_bytes, warnings}. */
rsw_status service_job_check(service *svc, const char *scene_id, const char *body, size_t len,
                             char **json_out, svc_error *e);
rsw_status service_job_list(service *svc, char **json_out, svc_error *e);
rsw_status service_job_get(service *svc, const char *job_id, char **json_out, svc_error *e);
rsw_status service_job_cancel(service *svc, const char *job_id, char **json_out, svc_error *e);
rsw_status service_job_delete(service *svc, const char *job_id, svc_error *e);
rsw_status service_job_results(service *svc, const char *job_id, char **json_out, svc_error *e);
/* GET /v1/jobs/{id}/dataset: the job's films as one NetCDF-4 dataset
 * (common/dataset_nc.h), *bytes_out owned (free()). RSW_ERR_CONFLICT while
 * the job is queued or running, unless partial (films not there are NaN). */
rsw_status service_job_dataset(service *svc, const char *job_id, bool partial, void **bytes_out,
                               size_t *len_out, svc_error *e);
/* The same written to a file in the blob directory, unlinked once open:
 * *fd_out (>= 0: read it from the start, *fd_len bytes; the caller closes
 * it), so that the whole file is not held in memory beside the films; or,
 * where that directory takes no file, in memory (*fd_out -1, *bytes_out
 * as above). */
rsw_status service_job_dataset_file(service *svc, const char *job_id, bool partial, int *fd_out,
                                    uint64_t *fd_len, void **bytes_out, size_t *len_out, svc_error *e);
rsw_status service_job_result(service *svc, const char *job_id, const char *context, const char *sensor_id,
                              svc_film *out, svc_error *e);
/* Jobs with bands (docs/experiments.md#spectral-response-functions-bands): the film of band `band`
 * (its radiance_srf, brf_srf, radiance_srf_stderr as the radiance, brf
 * and radiance_stderr planes; wavelength NaN), combined from the node
 * films on each call, or with `node` (decimal, an index into the job's
 * node wavelengths) that node's film. Exactly one of band and node.
 * RSW_ERR_NOT_FOUND (no such job, context, sensor, band or node; a node
 * film missing), RSW_ERR_INVALID (a job without bands; both or neither
 * given), RSW_ERR_NOMEM. */
rsw_status service_job_band_result(service *svc, const char *job_id, const char *context,
                                   const char *sensor_id, const char *band, const char *node, svc_film *out,
                                   svc_error *e);
/* The same result as a NumPy .npy file on disk (state directory), for
 * streaming: *fd_out (the caller closes it) reads *len_out bytes from
 * offset 0, exactly what http_film_npy would encode. RSW_OK with
 * *fd_out = -1 when the film is not on disk (use service_job_result). */
rsw_status service_job_result_npy_fd(service *svc, const char *job_id, const char *context,
                                     const char *sensor_id, int *fd_out, uint64_t *len_out, svc_error *e);

/* Server-sent events: wait until the job has an event with sequence number
 * > after (or has ended), up to timeout_ms. Fills *json_out with the next
 * event's data and *seq_out with its number, *is_end when it is the final
 * `end` event. Returns RSW_OK with *json_out NULL on a timeout (the HTTP
 * layer then sends a keep-alive comment). */
rsw_status service_job_next_event(service *svc, const char *job_id, uint64_t after, int timeout_ms,
                                  uint64_t *seq_out, char **json_out, bool *is_end, svc_error *e);

#endif
