/* Internal to server/http: the routes table and the request/response
 * records its handlers work on. No microhttpd types: server.c (the one
 * file, with sse.c, that includes microhttpd.h) fills an http_req from the connection,
 * runs the route's handler and turns the http_resp into a response. */
#ifndef RSW_HTTP_ROUTES_H
#define RSW_HTTP_ROUTES_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "../service/service.h"

#define HTTP_MAX_PATH_PARAMS     3
#define HTTP_MAX_JSON_DEPTH      64
/* Request targets longer than this, or with more query parameters, get
 * 414 (the API's routes take at most three parameters). */
#define HTTP_MAX_URI             8192
#define HTTP_MAX_QUERY_PARAMS    32
/* Request header fields beyond this many get 431 (a client of this API
 * sends about ten; browsers about twenty). */
#define HTTP_MAX_HEADER_FIELDS   100
/* Idempotency-Key length (proto/openapi.yaml). */
#define HTTP_MAX_IDEMPOTENCY_KEY 255

/* What a route's body must be (checked before the handler runs). */
typedef enum http_body_kind {
  HTTP_BODY_NONE,  /* any body is read and ignored */
  HTTP_BODY_JSON,  /* application/json (or an empty body) */
  HTTP_BODY_SCENE, /* application/json, application/xml or text/xml */
  HTTP_BODY_RAW,   /* bytes: application/octet-stream or no type (blobs) */
} http_body_kind;

/* The response a handler builds. body is malloc'ed (freed by the caller);
 * header values are copied into the fixed fields. */
typedef struct http_resp {
  int status;
  const char *content_type; /* static string; NULL with no body */
  /* When not empty, the Content-Type sent instead: a value with
   * parameters (multipart/mixed; boundary=...), kept here since the
   * response is copied between threads. http_resp_clear empties it. */
  char content_type_full[96];
  void *body;
  size_t len;
  char location[512];
  char etag[32];
  int retry_after_s;     /* > 0: Retry-After */
  bool www_authenticate; /* WWW-Authenticate: Bearer */
  char allow[64];        /* for 405 */
  /* Static strings or NULL: Cache-Control, and Content-Security-Policy
   * (sent with X-Content-Type-Options: nosniff). */
  const char *cache_control;
  const char *csp;
  /* Server-sent events instead of a body: server.c streams
   * service_job_next_event for sse_job after sse_after. */
  bool sse;
  char sse_job[128];
  uint64_t sse_after;
  /* A body streamed from a file instead (a film on disk): fd_len bytes
   * from offset 0; server.c hands the descriptor to microhttpd, which
   * closes it. */
  bool has_fd;
  int fd;
  uint64_t fd_len;
} http_resp;

/* One request, as the handler sees it: everything server.c looked up from
 * the connection (NULL when absent), the path's {placeholders} in order,
 * and the whole body. */
typedef struct http_req http_req;
struct http_req {
  service *svc;
  const char *method, *path;
  const char *params[HTTP_MAX_PATH_PARAMS];
  /* query */
  const char *q_match, *q_class, *q_force, *q_variant, *q_partial, *q_full;
  const char *q_name;                  /* POST /v1/scenes: a label, e.g. the pushed file's name */
  const char *q_exposure, *q_colormap; /* PNG films (image/png) */
  const char *q_band, *q_node;         /* job results of a job with bands */
  const char *q_dry_run;               /* POST .../jobs?dry_run=1 */
  /* headers */
  const char *content_type, *accept, *if_match, *idempotency_key, *last_event_id, *if_none_match;
  const char *body;
  size_t body_len;
  /* For a long handler (a synchronous render): start watching the
   * connection; the flag returned becomes 1 when the client hangs up and
   * stays valid until the handler returns (the watch ends then). NULL when
   * it cannot watch. watch_ctx belongs to server.c. */
  const atomic_int *(*watch_client)(struct http_req *r);
  void *watch_ctx;
  http_resp resp;
};

typedef void (*http_handler)(http_req *r);

typedef struct http_route {
  const char *method;
  const char *path; /* template: literal segments, "{name}", "{name}:verb" */
  http_body_kind body;
  bool public_route; /* no token needed (health, the viewer's files) */
  http_handler handler;
  bool quick; /* never blocks (no service lock): runs on MHD's event loop */
} http_route;

/* The table, in the order `raysweepd routes` prints it. */
extern const http_route http_routes[];
extern const size_t http_n_routes;

/* Match path against a template; on success fill params (borrowed
 * pointers into seg_buf, which must hold strlen(path) + 1 bytes). */
bool http_route_match(const char *tmpl, const char *path, char *seg_buf,
                      const char *params[HTTP_MAX_PATH_PARAMS]);

/* Find the route for (method, path). HEAD finds the GET route of a path
 * without a HEAD route of its own (the server sends the headers only).
 * Returns it, or NULL with *path_known telling whether another method
 * would match (then allow receives the comma-separated methods, HEAD
 * included where GET is, for a 405). */
const http_route *http_route_find(const char *method, const char *path, char *seg_buf,
                                  const char *params[HTTP_MAX_PATH_PARAMS], bool *path_known, char *allow,
                                  size_t allow_len);

/* Response helpers for handlers and server.c. They replace any previous
 * body. http_resp_problem formats detail; its code NULL means the HTTP
 * status name (http_status_code). http_resp_svc_error answers from an
 * svc_error (status, Retry-After for 429). */
void http_resp_json(http_req *r, int status, char *json_owned);
void http_resp_problem(http_req *r, int status, const char *code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
void http_resp_svc_error(http_req *r, const svc_error *e);
void http_resp_clear(http_resp *resp);

#endif
