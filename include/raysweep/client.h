/* libraysweep: a C client for raysweepd.
 *
 * Life cycle, as curl and Embree: opaque handles with _new/_free pairs
 * (_free(NULL) is a no-op); every call returns an rsw_status (status.h;
 * RSW_OK = 0, rsw_strerror() for a message); out-parameters are written
 * only on success; details of the last failure (including the server's
 * problem+json) are kept per client handle.
 *
 * Ownership is stated on every prototype: "borrowed" arguments are read
 * during the call only; results marked "owned" belong to the caller and
 * are freed as stated.
 *
 * Thread safety: one rsw_client may be used by one thread at a time;
 * several clients may be used in parallel. rsw_film, rsw_contexts and
 * rsw_job_status objects are plain data: use each from one thread at a
 * time. rsw_strerror is thread-safe.
 *
 * This header depends on no other library's headers and compiles as C11
 * and as C++. */
#ifndef RAYSWEEP_CLIENT_H
#define RAYSWEEP_CLIENT_H

#include <signal.h>
#include <stddef.h>
#include <stdint.h>

#include "status.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Errors this library adds to status.h's list are reported with these
 * codes (already in status.h): RSW_ERR_IO (local files), RSW_ERR_UNAVAILABLE
 * (cannot connect, or 503 after retries), RSW_ERR_TIMEOUT, RSW_ERR_PARSE
 * (a response that is not what the API promises). A server error keeps the
 * server's code (rsw_status from the problem's "code" when it names one,
 * else the HTTP status mapped to the closest code). */

typedef struct rsw_client rsw_client;

/* Options for rsw_client_new. Zero-initialise, set `size`, fill what you
 * need: the struct may grow (OpenEXR Core's convention). */
typedef struct rsw_client_opts {
  size_t size;                            /* sizeof(rsw_client_opts) */
  const char *base_url;                   /* "http://127.0.0.1:8350" when NULL */
  const char *token;                      /* bearer token, or NULL */
  double connect_timeout_s;               /* 0: 10 s */
  double timeout_s;                       /* whole request; 0: none */
  int max_retries;                        /* on connection errors, 429 and 503; 0: 3;
                                negative: no retries */
  double retry_backoff_s;                 /* first backoff, doubled each retry; 0: 0.2 s;
                                Retry-After wins when the server sends it */
  const volatile sig_atomic_t *interrupt; /* borrowed, may be NULL: once
                                *interrupt is non-zero, a call in progress
                                (a request, a stream, a wait, a retry pause)
                                stops within about a second and returns
                                RSW_ERR_CANCELLED, and later calls fail the
                                same way until it is zero again. A signal
                                handler may set it (the CLI's Ctrl-C). */
  const char *route_key;                  /* or NULL: sent as the X-Raysweep-Shard header on
                                every request: the key a load balancer in front
                                of several replicas hashes (docker/haproxy,
                                docker/nginx) so that all requests of one shard
                                reach the same replica; [A-Za-z0-9._-]{1,64} */
  double stall_timeout_s;                 /* the low-speed limit: a request that sends
                                and receives nothing for this long fails with
                                RSW_ERR_TIMEOUT and a message naming its URL.
                                0: 60 s; negative: none. A render, a scene
                                push and a dataset, whose answers the daemon
                                computes first, are exempt until their answer
                                starts (a render's own timeout_s bounds it:
                                see rsw_render); TCP keep-alive probes still
                                notice a peer that went away. */
} rsw_client_opts;

/* Create a client. Borrows opts (strings are copied). *out is owned: free
 * with rsw_client_free. Thread-safe. */
rsw_status rsw_client_new(const rsw_client_opts *opts, rsw_client **out);
/* Free a client; NULL is a no-op. */
void rsw_client_free(rsw_client *c);
/* Change the routing key (X-Raysweep-Shard) of later requests; NULL: send
 * none. RSW_ERR_INVALID unless [A-Za-z0-9._-]{1,64}. Job ids are local to a
 * replica: the requests that follow a job (events, results, films) must
 * carry the key its submission carried. */
rsw_status rsw_client_set_route(rsw_client *c, const char *key);

/* The last error of this client, valid until its next call. All strings
 * are borrowed from the client ("" when absent). */
typedef struct rsw_error_info {
  rsw_status status;
  int http_status;           /* 0 when no HTTP response */
  const char *code;          /* the server's machine code, e.g. "RSW_ERR_NOT_FOUND" */
  const char *message;       /* human-readable detail */
  const char *pointer;       /* JSON pointer or file:line, or "" */
  const char *key;           /* parameter key, or "" */
  const char *candidates[3]; /* closest keys for an unknown key, or NULL */
} rsw_error_info;
const rsw_error_info *rsw_client_last_error(const rsw_client *c);

/* ---- server ---------------------------------------------------------------- */

/* GET /v1 as JSON text. *json_out is owned: free with rsw_free. */
rsw_status rsw_server_info(rsw_client *c, char **json_out);
/* GET /v1/health/ready: RSW_OK when ready. */
rsw_status rsw_server_ready(rsw_client *c);

/* Free memory returned by this library (strings, arrays). NULL ok. */
void rsw_free(void *p);

/* ---- scenes ------------------------------------------------------------------ */

/* Push a scene file (JSON or Mitsuba XML, by extension or content).
 * Every file the scene references (`filename` properties, resolved
 * against the scene file's directory) is hashed; the server is asked which
 * digests it lacks, only those are uploaded, and the references are
 * rewritten to "sha256:<hex>" before the scene is posted. variant may be
 * NULL. The file's name (without its directory) goes along as the scene's
 * label (?name=, the viewer's name for it). id_out: 65 bytes (64 hex +
 * NUL). created_out (may be NULL): 1 when the server loaded it, 0 when it
 * was already resident. */
rsw_status rsw_scene_push_file(rsw_client *c, const char *path, const char *variant, char id_out[65],
                               int *created_out);
/* (The file's name goes with it, ?name=, so the daemon's messages about
 * its text name it: `mine.xml:6: ...`.) */
/* Same from memory; base_dir resolves relative file names (NULL: "."). */
rsw_status rsw_scene_push_buffer(rsw_client *c, const char *text, size_t len, const char *base_dir,
                                 const char *variant, char id_out[65], int *created_out);
/* GET /v1/scenes, /v1/scenes/{id} as JSON text (owned: rsw_free). */
rsw_status rsw_scene_list(rsw_client *c, char **json_out);
rsw_status rsw_scene_info(rsw_client *c, const char *id, char **json_out);
/* DELETE /v1/scenes/{id}; force cancels its jobs. */
rsw_status rsw_scene_delete(rsw_client *c, const char *id, int force);
/* POST /v1/scenes/{id}:reset: the scene back to its document's state
 * (the keys PATCHed since get the document's values; the revision moves
 * when one changed). json_out (may be NULL; owned: rsw_free): the answer,
 * the scene's summary with "changed" and "keys". */
rsw_status rsw_scene_reset(rsw_client *c, const char *id, char **json_out);
/* POST /v1/scenes/{id}:copy: a new scene in id's current state, a private
 * one (a push of the document is never handed it). id_out: 65 bytes;
 * json_out (may be NULL; owned): its summary. */
rsw_status rsw_scene_copy(rsw_client *c, const char *id, char id_out[65], char **json_out);

/* ---- parameters ---------------------------------------------------------------- */

/* The parameter table as JSON text ({revision, params:[...]}); match and
 * class_name may be NULL. *revision_out (may be NULL) is the base
 * revision. */
rsw_status rsw_params_get(rsw_client *c, const char *id, const char *match, const char *class_name,
                          char **json_out, uint64_t *revision_out);
/* As rsw_params_get, with every buffer's values however long (GET
 * ...?full=1; the table otherwise gives a buffer longer than 16 numbers
 * as {"length": n}). The daemon waits for a running render of the scene. */
rsw_status rsw_params_get_full(rsw_client *c, const char *id, const char *match, const char *class_name,
                               char **json_out, uint64_t *revision_out);
/* Apply a parameter map atomically. map_json is a JSON object text
 * {"key": value, ...} (borrowed). if_match < 0: unconditional; otherwise
 * RSW_ERR_PRECONDITION when the base revision moved. *revision_out (may be
 * NULL) gets the new revision. */
rsw_status rsw_params_update(rsw_client *c, const char *id, const char *map_json, int64_t if_match,
                             uint64_t *revision_out);

/* ---- films ----------------------------------------------------------------------- */

typedef struct rsw_film rsw_film;
/* Accessors; pointers are borrowed from the film. data is H*W*C float32,
 * row-major (row 0 = top), channels interleaved. */
int rsw_film_width(const rsw_film *f);
int rsw_film_height(const rsw_film *f);
int rsw_film_channels(const rsw_film *f);
const char *rsw_film_channel_name(const rsw_film *f, int i);
const float *rsw_film_data(const rsw_film *f);
/* Metadata the server attached (JSON object text, borrowed; may be "{}"). */
const char *rsw_film_meta(const rsw_film *f);
/* Write as float32 OpenEXR (through a temp file renamed on success) or as
 * NumPy .npy (<f4, shape (H, W, C)). Borrow everything. The EXR carries the
 * meta as the string attributes raysweepd writes ("raysweep:scene",
 * "raysweep:revision", "raysweep:context", "raysweep:sensor",
 * "raysweep:spp", "raysweep:seed", "raysweep:variant",
 * "raysweep:wavelength_nm", and "raysweep:zenith_deg" /
 * "raysweep:azimuth_deg" as comma-separated lists); RSW_ERR_PARSE when a
 * meta member has the wrong type or an angle list the wrong length. */
rsw_status rsw_film_save_exr(const rsw_film *f, const char *path);
rsw_status rsw_film_save_npy(const rsw_film *f, const char *path);
/* A film asked for with "quantities" or "variance" has more channels after
 * its radiance ones, "<plane>.<channel>" ("brf.Y", "radiance_stderr.R"),
 * and its meta lists "planes" (and "irradiance" with brdf/brf); both
 * savers keep them (EXR channels, the .npy's last axis) and the EXR adds
 * "raysweep:irradiance". */
/* A tone-mapped 8-bit sRGB PNG quick-look of the film's radiance (R, G, B;
 * else Y; else S0) through a temp file renamed on success, as Mitsuba
 * converts a film to 8-bit sRGB: linear values times 2^exposure, clamped
 * to [0, 1], sRGB-encoded (docs/viewer.md "Tone mapping"). exposure is
 * NULL (0 stops) or text as in the HTTP ?exposure=: a number of stops,
 * "auto" (the film's 99.5th percentile maps to white, not its maximum) or
 * "auto+EV" / "auto-EV". A one-channel film may use colormap "gray" (NULL:
 * the default), "viridis" or "inferno". RSW_ERR_INVALID for an unknown
 * colormap, a colormap on an RGB film or a malformed exposure; RSW_ERR_IO
 * when the file cannot be written. Borrows everything. */
rsw_status rsw_film_save_png(const rsw_film *f, const char *path, const char *exposure, const char *colormap);
void rsw_film_free(rsw_film *f);

/* One synchronous render. request_json is a RenderRequest text
 * ({"sensor", "spp", "seed", "wavelength", "params", "timeout_s"}) or NULL
 * for the defaults. *film_out is owned: rsw_film_free. With a timeout_s
 * of T the whole exchange is also bounded here, at T + 2 s + T/10 (the
 * daemon stops at T and answers; RSW_ERR_TIMEOUT naming the URL past it). */
rsw_status rsw_render(rsw_client *c, const char *id, const char *request_json, rsw_film **film_out);

/* ---- jobs ------------------------------------------------------------------------ */

/* A list of kernel contexts being built. */
typedef struct rsw_contexts rsw_contexts;
rsw_status rsw_contexts_new(rsw_contexts **out);
void rsw_contexts_free(rsw_contexts *x);
/* Append a context with id ([A-Za-z0-9._-]{1,64}); wavelength <= 0: none.
 * Returns its index through *index (may be NULL). */
rsw_status rsw_contexts_add(rsw_contexts *x, const char *id, double wavelength, size_t *index);
/* Per-context settings (index from rsw_contexts_add). value_json is JSON
 * text (borrowed). spp/seed < 0: unset. set_coord labels the context in
 * the job's dataset: name [A-Za-z][A-Za-z0-9_]{0,63}, value_json a JSON
 * number or string (the daemon checks that every context names the same
 * coords, each of one type). */
rsw_status rsw_contexts_set_param(rsw_contexts *x, size_t index, const char *key, const char *value_json);
rsw_status rsw_contexts_set_coord(rsw_contexts *x, size_t index, const char *name, const char *value_json);
rsw_status rsw_contexts_add_sensor(rsw_contexts *x, size_t index, const char *sensor);
rsw_status rsw_contexts_set_spp(rsw_contexts *x, size_t index, long long spp);
rsw_status rsw_contexts_set_seed(rsw_contexts *x, size_t index, long long seed);
/* Job-level settings: overrides for every context, default sensors and
 * spp, and the job seed. */
rsw_status rsw_contexts_set_job_param(rsw_contexts *x, const char *key, const char *value_json);
rsw_status rsw_contexts_add_default_sensor(rsw_contexts *x, const char *sensor);
rsw_status rsw_contexts_set_default_spp(rsw_contexts *x, long long spp);
rsw_status rsw_contexts_set_job_seed(rsw_contexts *x, long long seed);
/* Film planes for every render of the job: "quantities" (names borrowed:
 * "radiance", "brdf", "brf"; n 0 removes it) and "variance" (on != 0: the
 * radiance_stderr plane). The server checks them at submission. */
rsw_status rsw_contexts_set_quantities(rsw_contexts *x, const char *const *names, size_t n);
rsw_status rsw_contexts_set_variance(rsw_contexts *x, int on);
/* The job's "bundle": wavelengths carried per path (1..RSW_BUNDLE_MAX; 1:
 * one per path, as before bundles; RSW_BUNDLE_AUTO: "auto", the most the
 * daemon allows for the scene, what a job that names no bundle gets;
 * docs/experiments.md#spectral-bundles). The server checks the scene. */
#define RSW_BUNDLE_AUTO (-1)
/* The most wavelengths per path the API allows ("bundle" 1..RSW_BUNDLE_MAX). */
#define RSW_BUNDLE_MAX  16
rsw_status rsw_contexts_set_bundle(rsw_contexts *x, int k);
/* Context index's "bundle_group" (group < 0 removes it): renders of
 * contexts in different groups never share a bundle. What keeps a sweep's
 * bundles the same in every shard (docs/cluster.md#shards-and-spectral-bundles);
 * rsw_spread_run sets it from the daemon's rule where a context has none. */
rsw_status rsw_contexts_set_bundle_group(rsw_contexts *x, size_t index, long long group);
/* The job's parameter-map templates (docs/experiments.md#templates):
 * templates_json is the text of a JSON object {KEY: template} (borrowed);
 * NULL or "" removes them. RSW_ERR_PARSE when it is not JSON,
 * RSW_ERR_TYPE when not an object; the server checks the keys and forms. */
rsw_status rsw_contexts_set_templates(rsw_contexts *x, const char *templates_json);
size_t rsw_contexts_count(const rsw_contexts *x);

/* Submit a job. idempotency_key may be NULL. job_id_out: 40 bytes. */
rsw_status rsw_job_submit(rsw_client *c, const char *scene_id, const rsw_contexts *x,
                          const char *idempotency_key, char job_id_out[40]);
/* Submit a JobRequest given as JSON text (borrowed), sent as it is: any
 * member the daemon takes (contexts, defaults, params, templates, bands,
 * quantities, ...; docs/daemon.md). RSW_ERR_PARSE when it is not a JSON
 * object; the daemon checks the rest. */
rsw_status rsw_job_submit_json(rsw_client *c, const char *scene_id, const char *request_json,
                               const char *idempotency_key, char job_id_out[40]);

typedef enum rsw_job_state {
  RSW_JOB_QUEUED,
  RSW_JOB_RUNNING,
  RSW_JOB_SUCCEEDED,
  RSW_JOB_FAILED,
  RSW_JOB_CANCELLED
} rsw_job_state;

typedef struct rsw_job_status {
  rsw_job_state state;
  size_t contexts_total, contexts_done;
  size_t renders_total, renders_done, renders_failed;
  double seconds;  /* elapsed since start (0 when queued) */
  char error[512]; /* "" unless failed */
} rsw_job_status;

rsw_status rsw_job_get(rsw_client *c, const char *job_id, rsw_job_status *out);
/* The job's warnings (a sweep that changes nothing along a coordinate or
 * the wavelength: docs/experiments.md "Templates"), one "code
 * (coordinate): detail" a line; *text_out is NULL when there are none,
 * else owned: rsw_free. */
rsw_status rsw_job_warnings(rsw_client *c, const char *job_id, char **text_out);
/* A dry run of rsw_job_submit (POST .../jobs?dry_run=1): the request is
 * checked and planned as a submission is and nothing is queued; the
 * submission's error, or *renders_out (may be NULL) the renders it would
 * run and *warnings_out (may be NULL; owned: rsw_free) its warnings as
 * rsw_job_warnings gives them. RSW_ERR_UNSUPPORTED from a daemon without
 * dry runs (the job it queued is deleted). */
rsw_status rsw_job_check(rsw_client *c, const char *scene_id, const rsw_contexts *x, size_t *renders_out,
                         char **warnings_out);
/* Progress callback: one call per finished (context, sensor) and once at
 * the end. Return non-zero to stop waiting (the job keeps running). */
typedef int (*rsw_progress_fn)(void *user, const char *context, const char *sensor, size_t done, size_t total,
                               int failed);
/* Wait until the job ends, following its server-sent events (reconnecting
 * with Last-Event-ID when the stream drops). timeout_s <= 0: no limit
 * (RSW_ERR_TIMEOUT otherwise). *final_out (may be NULL) gets the end
 * state. */
rsw_status rsw_job_wait(rsw_client *c, const char *job_id, rsw_progress_fn progress, void *user,
                        double timeout_s, rsw_job_status *final_out);
rsw_status rsw_job_cancel(rsw_client *c, const char *job_id);
rsw_status rsw_job_delete(rsw_client *c, const char *job_id);
/* GET /v1/jobs and /v1/jobs/{id}/results as JSON text (owned: rsw_free). */
rsw_status rsw_job_list(rsw_client *c, char **json_out);
rsw_status rsw_job_results(rsw_client *c, const char *job_id, char **json_out);
/* One film of a job. *film_out is owned: rsw_film_free. */
rsw_status rsw_job_fetch(rsw_client *c, const char *job_id, const char *context, const char *sensor,
                         rsw_film **film_out);
/* The same film as the daemon encodes it, its bytes untouched: media_type
 * "image/x-exr", "application/x-npy", "image/png" or "application/json".
 * Nothing is parsed or formatted on the client, so this is the cheap way
 * to store films: the EXR and the .npy are byte for byte the files
 * rsw_film_save_exr and rsw_film_save_npy write of rsw_job_fetch's film
 * (but for non-finite samples, which the JSON detour makes NaN and these
 * keep as the daemon has them). *bytes_out owned: rsw_free; *len_out its
 * length. RSW_ERR_PARSE when the answer is of another type or does not
 * start as one. */
rsw_status rsw_job_fetch_encoded(rsw_client *c, const char *job_id, const char *context, const char *sensor,
                                 const char *media_type, void **bytes_out, size_t *len_out);

/* ---- sweep datasets ------------------------------------------------------------------ */

/* A job's films as one NetCDF-4 dataset (CF conventions; xarray opens it
 * with xarray.open_dataset(path) and no options): GET
 * /v1/jobs/{id}/dataset written to path (through a temp file renamed on
 * success). RSW_ERR_CONFLICT while the job is queued or running, unless
 * partial is non-zero (films not rendered yet are NaN). Borrows
 * everything. */
rsw_status rsw_job_fetch_dataset(rsw_client *c, const char *job_id, int partial, const char *path);

/* The same dataset built on the client from films it holds (a sweep spread
 * over several jobs, shards merged): contexts in order, then films, then
 * rsw_dataset_write. The file is the one raysweepd serves for the same
 * contexts and films, written by the same code. Not thread-safe per
 * handle; handles are independent. */
typedef struct rsw_dataset rsw_dataset;
/* *out owned: rsw_dataset_free. */
rsw_status rsw_dataset_new(rsw_dataset **out);
void rsw_dataset_free(rsw_dataset *d);
/* Add a context: id (distinct, 1 to 64 characters), wavelength in nm
 * (<= 0: none; a film's meta fills it in), coords_json a JSON object text
 * {name: number or string} or NULL (the Context's "coords"). Borrows. */
rsw_status rsw_dataset_add_context(rsw_dataset *d, const char *id, double wavelength,
                                   const char *coords_json);
/* The job seed (a global attribute); seed >= 0. */
rsw_status rsw_dataset_set_seed(rsw_dataset *d, long long seed);
/* Add the film of (context, sensor), copied: its pixels are the radiance;
 * its meta gives scene, revision and variant (the same for every film:
 * RSW_ERR_INVALID otherwise), spp, seed, the pixel angles and the plugin
 * failures (plugin_failures, plugin_failure; absent: 0). Borrows. */
rsw_status rsw_dataset_add_film(rsw_dataset *d, const char *context, const char *sensor,
                                const rsw_film *film);
/* The same from a film saved as JSON (`raysweep fetch -o F.json`,
 * `raysweep sweep --format json|nc`). */
rsw_status rsw_dataset_add_film_file(rsw_dataset *d, const char *context, const char *sensor,
                                     const char *path);
/* The same from the film's EXR as the daemon encodes it (image/x-exr,
 * rsw_job_fetch_encoded; bytes borrowed, len of them): its pixels and its
 * "raysweep:" attributes, angles included, with nothing formatted or
 * parsed as JSON, so the cheap way to build a sweep's dataset. channels:
 * the film's channel order (the job result's "channels"; the EXR's own is
 * alphabetical), n_channels of them, or NULL for the file's order.
 * Non-finite samples become NaN, as the JSON film has them, so the
 * dataset is the one the JSON films give, byte for byte. */
rsw_status rsw_dataset_add_film_exr(rsw_dataset *d, const char *context, const char *sensor,
                                    const void *bytes, size_t len, const char *const *channels,
                                    int n_channels);
/* Keep the films' pixels and angles past memory_bytes of them in a file
 * without a name in dir (mapped: the kernel writes such pages back and
 * drops them as memory runs short), so that a sweep's dataset of any size
 * is built in bounded memory; the file takes their size on the disk until
 * rsw_dataset_free. Without it every film is held on the heap. Call once,
 * before the films. Errors: RSW_ERR_IO (no file can be made in dir); a
 * film that the file cannot take (a full disk) is RSW_ERR_IO from the
 * call that adds it, naming the film, dir and the cause. */
rsw_status rsw_dataset_set_store(rsw_dataset *d, const char *dir, size_t memory_bytes);
/* Write the dataset (through a temp file renamed on success). Errors: the
 * contexts' coords (RSW_ERR_TYPE, RSW_ERR_INVALID, RSW_ERR_MISSING,
 * RSW_ERR_LIMIT, naming "/contexts/<i>/coords/<name>", i in the order
 * added), films of one sensor with different shapes, RSW_ERR_IO. */
rsw_status rsw_dataset_write(rsw_dataset *d, const char *path);
/* What the last failing call of d said ("" when none; borrowed). */
const char *rsw_dataset_last_error(const rsw_dataset *d);

/* ---- one job spread over several replicas ------------------------------------------ */

/* rsw_spread_run cuts a context list into `shards` shards (context k goes
 * to shard k mod shards, as `raysweep sweep --shard`), gives each shard its
 * own routing key ("<prefix>-<shard>", then "<prefix>-<shard>.r<n>" for
 * the n-th resubmission) and runs them concurrently, one client per shard,
 * through one base URL: a load balancer that hashes X-Raysweep-Shard
 * consistently sends every request of a shard to one replica. Films are
 * the same as the unsharded job's: seeds derive from (job seed, context id,
 * sensor) on the daemon.
 *
 * A shard whose replica is lost (its job answers 404, 502, 503 or 504, or
 * ended cancelled because the replica shut down) is resubmitted, without
 * the contexts already delivered, under its next routing key, so the
 * balancer places it elsewhere. When the base URL cannot be reached at
 * all (connection refused: the balancer is gone) the run stops with
 * RSW_ERR_UNAVAILABLE; with a state file the same call later resumes: the
 * jobs it names are followed again (through their keys) and only contexts
 * that were not delivered are rendered. */

/* Called once per (context, sensor) of the list, serialised (never two at
 * once), in no particular order, a context's films together once all its
 * renders are over: mostly while its job still runs (a second connection
 * per shard hands finished contexts over as the job goes), the rest when
 * the job ends. result_json: the job's result object
 * ({context, sensor, state, wavelength?, seed?, error?}). film: the film
 * when state is "succeeded", else NULL; also NULL with resumed = 1 for a
 * film an earlier run with the same state file delivered (the caller kept
 * it then). Return non-zero to stop the run (RSW_ERR_CANCELLED). */
typedef int (*rsw_spread_film_fn)(void *user, const char *context, const char *sensor,
                                  const char *result_json, const rsw_film *film, int resumed);

/* The same with the film as the daemon encoded it (rsw_spread_opts
 * .film_media_type; rsw_job_fetch_encoded): bytes (borrowed for the call)
 * and len, NULL and 0 when the render did not succeed or resumed is 1. */
typedef int (*rsw_spread_encoded_fn)(void *user, const char *context, const char *sensor,
                                     const char *result_json, const void *bytes, size_t len, int resumed);

typedef struct rsw_spread_opts {
  size_t size;              /* sizeof(rsw_spread_opts) */
  int shards;               /* K >= 1 */
  const char *scene_file;   /* pushed through every routing key before its job (blobs as in
                                 rsw_scene_push_file); NULL: scene_id must be resident on every
                                 replica */
  const char *variant;      /* for scene_file; may be NULL */
  const char *route_prefix; /* NULL: "rs" + 12 random hex digits (kept in the state file) */
  const char *state_path;   /* NULL: no resume; otherwise a journal (JSON lines) written as the
                                 run goes and read first when it exists */
  int max_resubmits;        /* per shard; 0: 8 */
  double timeout_s;         /* whole run; <= 0: none */
  rsw_progress_fn progress; /* may be NULL; done/total over every shard, serialised */
  void *progress_user;
  rsw_spread_film_fn on_film; /* required, unless film_media_type and on_film_encoded are given */
  void *film_user;
  /* NULL: films reach on_film decoded. A media type rsw_job_fetch_encoded
   * takes ("image/x-exr", "application/x-npy", ...): films are fetched so,
   * undecoded, and reach on_film_encoded (with film_user) instead. */
  const char *film_media_type;
  rsw_spread_encoded_fn on_film_encoded;
  /* NULL: not asked. Else the whole sweep is dry-run once (rsw_job_check,
   * through shard 0's key) before any shard runs, so a request the daemon
   * refuses fails at once, and this is called with its warnings (text
   * borrowed for the call) when it has some: a shard alone may not differ
   * along the coordinate a warning names. A daemon without dry runs is
   * skipped. */
  void (*on_warnings)(void *user, const char *text);
  void *warnings_user;
} rsw_spread_opts;

typedef struct rsw_spread_result {
  size_t films;       /* delivered by this run (state succeeded) */
  size_t failed;      /* renders that did not succeed (delivered with film NULL) */
  size_t resumed;     /* delivered by an earlier run (from the state file) */
  size_t resubmitted; /* shard resubmissions after a lost replica */
  size_t contexts_resubmitted;
  char scene_id[65]; /* the scene the jobs used */
  char route_prefix[32];
} rsw_spread_result;

/* copts: how to reach the balancer (base_url, token, ...; route_key is
 * ignored). scene_id: the scene, or NULL with opts->scene_file. x: the
 * contexts and job settings (borrowed). *out (may be NULL) is filled also
 * on failure. Thread-safe; starts opts->shards threads. */
rsw_status rsw_spread_run(const rsw_client_opts *copts, const char *scene_id, const rsw_contexts *x,
                          const rsw_spread_opts *opts, rsw_spread_result *out);
/* The message of the last rsw_spread_run failure of this thread ("" when
 * none). */
const char *rsw_spread_last_error(void);

#ifdef __cplusplus
}
#endif
#endif
