/* libraysweep internals shared by the files of client/lib/. Not installed.
 *
 * Layering: http.c is the one file that talks to libcurl (it sees CURL
 * only through the opaque `void *curl` below); client.c holds the handle's
 * life cycle, the last-error slot and the small GET/DELETE wrappers;
 * scene.c, film.c and jobs.c build requests and decode answers with cJSON. */
#ifndef RSW_CLIENT_INTERNAL_H
#define RSW_CLIENT_INTERNAL_H

#include <signal.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>

#include "raysweep/client.h"

/* Caps on what the client accepts, so a confused server cannot make it
 * allocate without bound. */
#define CLIENT_MAX_BODY        ((size_t)1 << 31) /* one response body: 2 GiB */
#define CLIENT_MAX_SSE_EVENT   ((size_t)1 << 20) /* one server-sent event: 1 MiB */
/* Defaults of the transfer limits (rsw_client_opts; docs/robustness.md). */
#define CLIENT_STALL_TIMEOUT_S 60.0
/* A render with a timeout_s of T is given up client-side at
 * T + CLIENT_RENDER_GRACE_S + T / 10: the daemon stops at T and answers. */
#define CLIENT_RENDER_GRACE_S  2.0

struct rsw_client {
  char *base_url; /* without a trailing '/' */
  char *token;    /* NULL: no Authorization header */
  char *route;    /* X-Raysweep-Shard routing key, or NULL: none */
  double connect_timeout_s, timeout_s;
  double stall_timeout_s; /* <= 0: none (rsw_client_opts.stall_timeout_s) */
  int max_retries;        /* >= 0 after rsw_client_new */
  double retry_backoff_s;
  void *curl;                             /* CURL *: one easy handle, so connections are kept alive */
  const volatile sig_atomic_t *interrupt; /* borrowed; NULL: none */

  /* The last error: info points into the buffers below. */
  rsw_error_info info;
  char code[64];
  char message[1024];
  char pointer[256];
  char key[256];
  char candidates[3][256];
};

/* ---- the last-error slot (client.c) ---------------------------------------- */

/* Reset to "no error". */
void client_clear_error(rsw_client *c);
/* Record a local failure (no HTTP answer) and return s: "report and return"
 * in one statement. */
rsw_status client_fail(rsw_client *c, rsw_status s, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
/* Record an HTTP error answer (problem+json when body parses as one, else
 * the HTTP status alone); what names the request ("GET /v1/scenes/x").
 * Returns the mapped status. */
rsw_status client_fail_http(rsw_client *c, long http_status, const char *body, size_t len, const char *what);
/* Status for an HTTP error status without a usable problem code. */
rsw_status client_status_for_http(long http_status);

/* A media type rsw_job_fetch_encoded takes (jobs.c). */
bool client_film_media_type_known(const char *media_type);
/* Several films of a job in one request (POST /v1/jobs/{id}/results:fetch,
 * multipart/mixed): bytes_out[i] and len_out[i] for (contexts[i],
 * sensors[i]), each what rsw_job_fetch_encoded returns, borrowed from
 * *answer_out (the whole answer, owned: free(); the films are not copied
 * out of it); media_type image/x-exr or application/x-npy; 1 <= n <=
 * CLIENT_FETCH_MAX. All or nothing (on failure *answer_out and every
 * bytes_out[i] are NULL). jobs.c. */
#define CLIENT_FETCH_MAX   32
#define CLIENT_FETCH_BYTES (16.0 * 1024 * 1024) /* a batch's films, about (the daemon takes 64 MiB) */
rsw_status client_job_fetch_encoded_many(rsw_client *c, const char *job_id, size_t n,
                                         const char *const *contexts, const char *const *sensors,
                                         const char *media_type, char **answer_out, const void **bytes_out,
                                         size_t *len_out);

/* rsw_spread_run's passes while a job runs (spread.c): the renders the
 * next pass waits for, of a job of total renders (0: not known yet), seen
 * reported so far, pending of them since the last pass: max_batch while
 * many are left, then half of those left when the last pass started, and
 * never fewer than CLIENT_EARLY_MIN_BATCH. */
#define CLIENT_EARLY_MIN_BATCH 4
size_t client_early_batch(size_t max_batch, size_t total, size_t seen, size_t pending);

/* ---- HTTP (http.c) ---------------------------------------------------------- */

typedef struct http_req {
  const char *method;       /* "GET", "POST", "PUT", "PATCH", "DELETE", "HEAD" */
  const char *path;         /* appended to base_url; already percent-encoded */
  const char *content_type; /* of body; NULL when there is none */
  const void *body;
  size_t body_len;
  const char *accept;          /* NULL: application/json */
  const char *if_match;        /* If-Match value, or NULL */
  const char *idempotency_key; /* or NULL */
  const char *last_event_id;   /* or NULL */
  /* The daemon computes the answer before its first byte (a render, a
   * scene load, a dataset): the stall limit waits for the answer to start. */
  bool computed;
  /* > 0: the whole exchange ends after this many seconds (RSW_ERR_TIMEOUT),
   * whichever of it and the client's timeout_s comes first. */
  double deadline_s;
} http_req;

typedef struct http_resp {
  long status;
  char *body; /* NUL-terminated (owned; http_resp_free); may be empty */
  size_t len;
  char etag[80];
  char content_type[128]; /* the answer's Content-Type, as sent ("" when none) */
} http_resp;

/* One request with the client's retry policy: retried with exponential
 * backoff on connection errors, 429 and 503 (Retry-After wins). RSW_OK
 * with *r filled on a 2xx answer; otherwise the last error is set (from
 * the problem+json body) and *r is left empty. */
rsw_status http_request(rsw_client *c, const http_req *q, http_resp *r);
void http_resp_free(http_resp *r);

/* Server-sent events: on_line gets each line of a 2xx text/event-stream
 * body without its end of line; returning non-zero stops the stream.
 * timeout_s <= 0: none. Returns RSW_OK when the server ended the stream or
 * on_line stopped it (*stopped tells which), RSW_ERR_UNAVAILABLE when the
 * connection dropped or could not be made, RSW_ERR_TIMEOUT, or the mapped
 * status of an HTTP error answer (last error set). *not_a_stream is set
 * when a 2xx answer was not text/event-stream (nothing passed to on_line).
 * No retries here: the caller reconnects with Last-Event-ID. */
typedef int (*http_line_fn)(void *user, const char *line, size_t len);
rsw_status http_stream(rsw_client *c, const http_req *q, double timeout_s, http_line_fn on_line, void *user,
                       bool *stopped, bool *not_a_stream);

/* Create / destroy the easy handle of a client (curl's global init is done
 * once per process, thread-safely). */
rsw_status http_client_init(rsw_client *c);
void http_client_cleanup(rsw_client *c);

/* ---- helpers (client.c) ---------------------------------------------------- */

/* Percent-encode s (everything outside A-Z a-z 0-9 - . _ ~) into out;
 * false when it does not fit. */
bool client_escape(const char *s, char *out, size_t cap);
/* A routing key: [A-Za-z0-9._-]{1,64}. */
bool client_valid_route(const char *key);
/* GET path and hand back the body as an owned string (rsw_free). */
rsw_status client_get_text(rsw_client *c, const char *path, char **json_out);
/* rsw_scene_push_file, also giving the scene's document id (doc_out, may
 * be NULL): the same on every replica for the same file, where the scene's
 * id is not once a replica's twin has changed (docs/daemon.md). */
rsw_status client_scene_push_file(rsw_client *c, const char *path, const char *variant, char id_out[65],
                                  char doc_out[65], int *created_out);
/* Monotonic seconds. */
double client_now_s(void);
/* Sleep s seconds (interrupted sleeps resume, unless the client's
 * interrupt flag is set: then it returns early). c may be NULL. */
void client_sleep_s(const rsw_client *c, double s);
/* True when the client's interrupt flag (rsw_client_opts.interrupt) is set. */
bool client_interrupted(const rsw_client *c);
/* Record "interrupted" (RSW_ERR_CANCELLED) and return it. */
rsw_status client_fail_interrupted(rsw_client *c, const char *what);

/* ---- contexts (jobs.c), for spread.c ----------------------------------------- */

/* The id of context i (borrowed), or NULL. */
const char *client_contexts_id(const rsw_contexts *x, size_t i);
/* Context i's object (borrowed), or NULL. */
struct cJSON *client_contexts_item(const rsw_contexts *x, size_t i);
/* The whole JobRequest as JSON text (owned: free). */
char *client_contexts_print(const rsw_contexts *x);
/* A new list with the job settings of x and its contexts idx[0..n). */
rsw_status client_contexts_subset(const rsw_contexts *x, const size_t *idx, size_t n, rsw_contexts **out);
/* The job's "bundle" as the client plans with it: K, RSW_BUNDLE_MAX for
 * "auto", 1 when absent. */
int client_contexts_bundle(const rsw_contexts *x);
/* lead[i] (n = the contexts of x): the index of the first context of
 * context i's bundle group, so that shards keep groups whole
 * (docs/cluster.md#shards-and-spectral-bundles): contexts with the same
 * "bundle_group" form one; the others are cut by the daemon's rule
 * (common/bundle_plan.h) over their JSON less id, wavelength and coords.
 * lead[i] == i for every i when the bundle is 1. */
rsw_status client_contexts_bundle_leads(const rsw_contexts *x, size_t *lead);

/* ---- films (film.c) -------------------------------------------------------- */

/* Decode a JSON film answer ({width, height, channels, layout, data,
 * meta}); what names the request in errors. */
rsw_status film_from_json(rsw_client *c, const char *text, size_t len, const char *what, rsw_film **out);

#endif
