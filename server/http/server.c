/* libmicrohttpd glue: with sse.c, the only file of raysweepd that
 * includes microhttpd.h. It owns the listening socket, the connection limits, body
 * accumulation, the generic checks that run before any handler (auth,
 * 404/405, 413, 414, 415, JSON depth), the translation of an http_resp
 * into an MHD response (server-sent events: sse.c).
 *
 * Threads. MHD runs a small pool of event-loop threads (thread-pool mode,
 * epoll): a connection costs a socket and its memory pool, not a thread,
 * so a client that trickles its headers one byte a second holds nothing
 * that other clients need. The cost of that mode is that a handler which
 * blocks stalls every connection of its event-loop thread, and most
 * handlers can block (a synchronous render for minutes, a scene load or a
 * PATCH commit for seconds, any service call waiting on a lock that a long
 * job submission holds). So only the two health routes run on the event
 * loop (they read one atomic and take no lock: a probe is answered however
 * busy the service is), and so do the web viewer's files (copied from
 * memory, no service call); every other handler runs on a thread of its own
 * while its connection is suspended (MHD_suspend_connection), and the
 * connection is resumed when the answer is ready. An event stream likewise
 * has a thread that waits for the job's events and resumes the connection
 * when it has text to send; its content reader never blocks. Thread
 * creation (tens of microseconds) is small next to any handler that needs
 * the service, and a fixed handler pool would be starved by long renders.
 *
 * Limits, so that no client can lock the others out:
 *   - at most max_connections open connections (MHD refuses more);
 *   - above max_connections - HTTP_RESERVED_CONNECTIONS, every request but
 *     the health probes is answered 503 with Retry-After at once, which
 *     leaves room for the probes;
 *   - a connection must complete its request headers within
 *     header_timeout_s of connecting (or of the end of its previous
 *     request): a reaper thread shuts down the socket of any that does
 *     not, which ends slow-loris clients, garbage that MHD keeps reading
 *     (blank or NUL-led request lines) and idle keep-alive connections;
 *   - request targets of at most HTTP_MAX_URI bytes and HTTP_MAX_QUERY
 *     query parameters (414 otherwise).
 *
 * Per-request state lives in a struct conn hung on MHD's per-request
 * pointer (created by the URI log callback, which also keeps the raw,
 * still percent-encoded path to route on) and freed in the completion
 * callback; per-connection state (for the header deadline) in a
 * conn_track on MHD's socket context. The server has no global state. */
#include "http.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <cjson/cJSON.h>
#include <microhttpd.h>

#include "encode.h"
#include "routes.h"
#include "sse.h"

/* On shutdown, event streams go on this long for their jobs' final
 * `end` event (the service cancels running jobs), and answers already
 * made go on being sent, before every socket is cut. */
#define SSE_GRACE_MS         3000
/* Most body memory reserved from Content-Length before the bytes arrive. */
#define PREALLOC_MAX         ((size_t)16 << 20)
/* A connection with no traffic at all closes after this (seconds); the
 * header deadline (http_opts.header_timeout_s) is usually shorter. */
#define CONNECTION_TIMEOUT_S 60
/* MHD's per-connection memory pool: request line, headers, parsed query
 * arguments and the write buffer. Large enough for HTTP_MAX_QUERY_PARAMS
 * (and many more, so that a long query reaches our 414 instead of MHD's
 * own answer); beyond it MHD answers 431 itself. */
#define CONNECTION_MEMORY    ((size_t)256 << 10)
/* Event-loop threads (they only parse, route and copy bytes). */
#define EVENT_THREADS        2
/* How long an idle handler thread waits for the next task. */
#define HANDLER_IDLE_MS      2000
/* How often the reaper looks for connections past their header deadline. */
#define REAPER_PERIOD_MS     200

/* One open connection (MHD's socket context), for the header deadline. */
typedef struct conn_track {
  struct conn_track *prev, *next;
  int fd;
  int64_t since_ms; /* accepted, or the previous request ended */
  bool in_request;  /* headers complete: the deadline no longer applies */
  bool cut;         /* the reaper shut the socket down already */
} conn_track;

struct http_server {
  service *svc;
  struct MHD_Daemon *mhd;
  char *token; /* NULL: no auth */
  size_t token_len;
  size_t max_body;
  int port;
  unsigned max_connections;
  int64_t header_timeout_ms;
  atomic_bool stopping;
  _Atomic int64_t stop_deadline_ms; /* monotonic ms; streams end after it */
  /* Written once when stopping, never read: readable from then on, so
   * every poll() that includes it (render watches, the reaper) wakes. */
  int stop_pipe[2];
  pthread_t reaper;
  bool reaper_started;
  /* Client watches (see client_watch): an epoll set, its thread, and the
   * watches in it (guarded by lock). */
  int watch_ep;
  pthread_t watcher;
  bool watcher_started;
  bool watch_closed; /* stopping: new watches are cancelled at once */
  uint64_t watch_seq;
  struct client_watch *watches;
  /* Guards what follows; cond is broadcast whenever a count drops. */
  pthread_mutex_t lock;
  pthread_cond_t cond;
  int n_streams; /* event streams not yet freed */
  int n_tasks;   /* handlers whose connection has not resumed yet */
  /* Handler threads: one finished with its task waits up to
   * HANDLER_IDLE_MS for another before it exits, so a busy server does
   * not create a thread per request; a task with no waiting thread gets a
   * new one. Not a fixed pool: a render holds its thread for as long as
   * it runs, and a fixed pool would let long renders starve short
   * requests. */
  pthread_cond_t task_cond;
  struct task *queue; /* handed over, not yet taken (FIFO) */
  struct task **queue_tail;
  int n_queued;
  int n_idle;         /* threads waiting on task_cond */
  int n_threads;      /* handler threads alive */
  int n_inflight;     /* requests between their URI and their completion */
  unsigned n_open;    /* open connections */
  conn_track *tracks; /* every open connection */
};

/* One request in flight. */
typedef struct conn {
  http_server *srv;
  const http_route *route; /* NULL when answered at the first call */
  const char *params[HTTP_MAX_PATH_PARAMS];
  char *raw_path; /* the path as sent, percent-encoding intact */
  size_t uri_len; /* the whole request target, in bytes */
  size_t n_query; /* query parameters in it */
  char *seg_buf;  /* owns the strings params point into */
  char *body;
  size_t len, cap;
  bool too_large;  /* body passed max_body: read and dropped, then 413 */
  bool answered;   /* a response is queued already */
  bool seen_first; /* the first call (headers only) is over */
  bool has_early;  /* early holds a problem to send at the last call */
  bool task_done;  /* the handler thread finished: resp is ready */
  bool task_started;
  bool close_after; /* answered while full: close the connection */
  http_resp early;
  http_resp resp; /* the handler thread's answer */
} conn;

static int64_t now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

/* ---- responses ------------------------------------------------------------ */

static void count(http_server *srv, const http_route *rt, int status) {
  service_count_request(srv->svc, rt ? rt->path : "unmatched", status);
}

static void add_headers(struct MHD_Response *mr, const http_resp *resp) {
  if (resp->content_type)
    MHD_add_response_header(mr, MHD_HTTP_HEADER_CONTENT_TYPE,
                            resp->content_type_full[0] ? resp->content_type_full : resp->content_type);
  if (resp->location[0]) MHD_add_response_header(mr, MHD_HTTP_HEADER_LOCATION, resp->location);
  if (resp->etag[0]) MHD_add_response_header(mr, MHD_HTTP_HEADER_ETAG, resp->etag);
  if (resp->allow[0]) MHD_add_response_header(mr, MHD_HTTP_HEADER_ALLOW, resp->allow);
  if (resp->www_authenticate)
    MHD_add_response_header(mr, MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"raysweepd\"");
  if (resp->cache_control) MHD_add_response_header(mr, MHD_HTTP_HEADER_CACHE_CONTROL, resp->cache_control);
  if (resp->csp) {
    MHD_add_response_header(mr, "Content-Security-Policy", resp->csp);
    MHD_add_response_header(mr, "X-Content-Type-Options", "nosniff");
  }
  if (resp->retry_after_s > 0) {
    char v[16];
    snprintf(v, sizeof v, "%d", resp->retry_after_s);
    MHD_add_response_header(mr, MHD_HTTP_HEADER_RETRY_AFTER, v);
  }
}

/* The event streams' side of the server (sse.h): shutdown past the grace
 * period ends them, and http_server_stop waits for them. */
static bool streams_must_end(void *ctx) {
  http_server *srv = ctx;
  return atomic_load(&srv->stopping) && now_ms() >= atomic_load(&srv->stop_deadline_ms);
}

static void stream_count(void *ctx, int delta) {
  http_server *srv = ctx;
  pthread_mutex_lock(&srv->lock);
  srv->n_streams += delta;
  if (delta < 0) pthread_cond_broadcast(&srv->cond);
  pthread_mutex_unlock(&srv->lock);
}

/* Queue resp on the connection (taking its body) and count it. */
static enum MHD_Result send_http_resp(struct MHD_Connection *c, conn *cn, http_resp *resp) {
  struct MHD_Response *mr = NULL;
  if (resp->sse) {
    sse_host h = {.svc = cn->srv->svc, .ctx = cn->srv, .must_end = streams_must_end, .count = stream_count};
    mr = sse_response(&h, c, resp->sse_job, resp->sse_after);
  } else if (resp->has_fd) {
    mr = MHD_create_response_from_fd64(resp->fd_len, resp->fd);
    if (mr) {
      resp->has_fd = false; /* microhttpd closes it */
      add_headers(mr, resp);
      if (cn->close_after) MHD_add_response_header(mr, MHD_HTTP_HEADER_CONNECTION, "close");
    }
  } else {
    mr = resp->len ? MHD_create_response_from_buffer(resp->len, resp->body, MHD_RESPMEM_MUST_FREE)
                   : MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT);
    if (mr && resp->len) resp->body = NULL; /* MHD frees it with free() */
    if (mr) add_headers(mr, resp);
    if (mr && cn->close_after) MHD_add_response_header(mr, MHD_HTTP_HEADER_CONNECTION, "close");
  }
  http_resp_clear(resp);
  cn->answered = true;
  if (!mr) {
    count(cn->srv, cn->route, 500);
    return MHD_NO; /* out of memory: MHD closes the connection */
  }
  enum MHD_Result ret = MHD_queue_response(c, (unsigned)resp->status, mr);
  MHD_destroy_response(mr);
  count(cn->srv, cn->route, resp->status);
  return ret;
}

/* Does the request announce a body? */
static bool has_body(struct MHD_Connection *c) {
  const char *cl = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_CONTENT_LENGTH);
  if (MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_TRANSFER_ENCODING)) return true;
  return cl && strtoull(cl, NULL, 10) != 0;
}

/* Answer with a problem. At the first call of a request that announces a
 * body, the answer goes out at once and MHD closes the connection without
 * reading the body; without a body it waits for the request's last call
 * (cn->early), so the connection stays open for the next request. */
static enum MHD_Result send_problem_ra(struct MHD_Connection *c, conn *cn, int status, const char *code,
                                       const char *detail, const char *allow, bool www_auth,
                                       int retry_after_s) {
  http_req r = {.svc = cn->srv->svc};
  http_resp_problem(&r, status, code, "%s", detail);
  if (allow) snprintf(r.resp.allow, sizeof r.resp.allow, "%s", allow);
  r.resp.www_authenticate = www_auth;
  r.resp.retry_after_s = retry_after_s;
  if (!cn->seen_first && !has_body(c)) {
    cn->early = r.resp;
    cn->has_early = true;
    return MHD_YES;
  }
  return send_http_resp(c, cn, &r.resp);
}

static enum MHD_Result send_problem(struct MHD_Connection *c, conn *cn, int status, const char *code,
                                    const char *detail, const char *allow, bool www_auth) {
  return send_problem_ra(c, cn, status, code, detail, allow, www_auth, 0);
}

/* ---- connections ---------------------------------------------------------------- */

static void on_connection(void *cls, struct MHD_Connection *c, void **socket_context,
                          enum MHD_ConnectionNotificationCode code) {
  http_server *srv = cls;
  if (code == MHD_CONNECTION_NOTIFY_STARTED) {
    conn_track *t = calloc(1, sizeof *t);
    if (t) {
      const union MHD_ConnectionInfo *ci = MHD_get_connection_info(c, MHD_CONNECTION_INFO_CONNECTION_FD);
      t->fd = ci ? ci->connect_fd : -1;
      t->since_ms = now_ms();
    }
    pthread_mutex_lock(&srv->lock);
    srv->n_open++;
    if (t) {
      t->next = srv->tracks;
      if (srv->tracks) srv->tracks->prev = t;
      srv->tracks = t;
    }
    pthread_mutex_unlock(&srv->lock);
    *socket_context = t;
  } else if (code == MHD_CONNECTION_NOTIFY_CLOSED) {
    /* MHD calls this before it closes the socket, so the reaper never
     * shuts down a descriptor that was reused by another connection. */
    conn_track *t = *socket_context;
    pthread_mutex_lock(&srv->lock);
    srv->n_open--;
    if (t) {
      if (t->prev)
        t->prev->next = t->next;
      else
        srv->tracks = t->next;
      if (t->next) t->next->prev = t->prev;
    }
    pthread_mutex_unlock(&srv->lock);
    free(t);
    *socket_context = NULL;
  }
}

static conn_track *track_of(struct MHD_Connection *c) {
  const union MHD_ConnectionInfo *ci = MHD_get_connection_info(c, MHD_CONNECTION_INFO_SOCKET_CONTEXT);
  return ci ? ci->socket_context : NULL;
}

/* The header deadline: shut down the socket of every connection that did
 * not complete its request headers in time. MHD then sees the end of the
 * stream and closes the connection itself (we never close its socket). */
static void *reaper_main(void *arg) {
  http_server *srv = arg;
  for (;;) {
    struct pollfd p = {.fd = srv->stop_pipe[0], .events = POLLIN};
    int n = poll(&p, 1, REAPER_PERIOD_MS);
    if (n > 0) break;
    int64_t now = now_ms();
    pthread_mutex_lock(&srv->lock);
    for (conn_track *t = srv->tracks; t; t = t->next)
      if (!t->in_request && !t->cut && t->fd >= 0 && now - t->since_ms > srv->header_timeout_ms) {
        shutdown(t->fd, SHUT_RDWR);
        t->cut = true;
      }
    pthread_mutex_unlock(&srv->lock);
  }
  return NULL;
}

/* ---- generic checks ----------------------------------------------------------- */

/* Compare without an early exit, so the time does not tell how much of a
 * guessed token was right. */
static bool token_equal(const char *a, size_t alen, const char *b, size_t blen) {
  size_t n = alen > blen ? alen : blen;
  unsigned char d = alen != blen;
  for (size_t i = 0; i < n; i++) d |= (unsigned char)((i < alen ? a[i] : 0) ^ (i < blen ? b[i] : 0));
  return d == 0;
}

/* NULL when the request may pass; otherwise why not, so that a client
 * without a token and one with a wrong token are told apart (neither
 * learns anything about the token itself). */
static const char *unauthorized(const http_server *srv, struct MHD_Connection *c) {
  if (!srv->token) return NULL;
  const char *h = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_AUTHORIZATION);
  if (!h)
    return "this server requires Authorization: Bearer <token>, and the request has no Authorization header";
  while (*h == ' ') h++;
  if (strncasecmp(h, "Bearer", 6) != 0 || (h[6] != ' ' && h[6] != '\t'))
    return "the Authorization header is not of the form 'Bearer <token>'";
  h += 6;
  while (*h == ' ' || *h == '\t') h++;
  size_t n = strlen(h);
  while (n && (h[n - 1] == ' ' || h[n - 1] == '\t')) n--;
  if (!token_equal(h, n, srv->token, srv->token_len))
    return "the bearer token of the Authorization header is wrong (it does not match the daemon's "
           "--token-file)";
  return NULL;
}

static const char *header(struct MHD_Connection *c, const char *name) {
  return MHD_lookup_connection_value(c, MHD_HEADER_KIND, name);
}

/* Does a declared Content-Type fit the route? (Absence is judged once the
 * body is in: an empty body needs no type.) */
static bool media_fits(http_body_kind kind, const char *ct) {
  switch (kind) {
  case HTTP_BODY_JSON: return http_media_type_is(ct, "application/json");
  case HTTP_BODY_SCENE:
    return http_media_type_is(ct, "application/json") || http_media_type_is(ct, "application/xml") ||
           http_media_type_is(ct, "text/xml");
  case HTTP_BODY_RAW: return http_media_type_is(ct, "application/octet-stream");
  default: return true;
  }
}

static const char *media_expected(http_body_kind kind) {
  switch (kind) {
  case HTTP_BODY_SCENE: return "application/json, application/xml or text/xml";
  case HTTP_BODY_RAW: return "application/octet-stream";
  default: return "application/json";
  }
}

static int hex_digit(char ch) {
  if (ch >= '0' && ch <= '9') return ch - '0';
  if (ch >= 'a' && ch <= 'f') return ch - 'a' + 10;
  if (ch >= 'A' && ch <= 'F') return ch - 'A' + 10;
  return -1;
}

/* Percent-decode a path segment in place. False on a malformed escape or
 * an encoded NUL (which no identifier may hold). */
static bool pct_decode(char *s) {
  char *o = s;
  for (const char *p = s; *p; p++) {
    if (*p != '%') {
      *o++ = *p;
      continue;
    }
    int hi = hex_digit(p[1]), lo = hi < 0 ? -1 : hex_digit(p[2]);
    if (lo < 0 || (hi == 0 && lo == 0)) return false;
    *o++ = (char)(hi * 16 + lo);
    p += 2;
  }
  *o = '\0';
  return true;
}

/* Reserve connections for the health probes: above this many open
 * connections, other requests get 503 at once. */
static unsigned soft_limit(const http_server *srv) {
  unsigned reserve = srv->max_connections / 4;
  if (reserve > HTTP_RESERVED_CONNECTIONS) reserve = HTTP_RESERVED_CONNECTIONS;
  return srv->max_connections - reserve;
}

/* First call for a request: headers are in, the body is not. Answers
 * at once what needs no body; returns false when it did. The route is
 * found on the path as sent (cn->raw_path), so that "%2F" inside an id
 * cannot split it into two segments; the {placeholders} are decoded after
 * matching. */
/* Every Content-Length header of a request (MHD_get_connection_values). */
typedef struct cl_scan {
  unsigned n;
  const char *first;
  bool differ;
} cl_scan;

static enum MHD_Result cl_visit(void *cls, enum MHD_ValueKind kind, const char *key, const char *value) {
  (void)kind;
  cl_scan *cs = cls;
  if (!key || strcasecmp(key, MHD_HTTP_HEADER_CONTENT_LENGTH) != 0) return MHD_YES;
  if (cs->n++ == 0)
    cs->first = value ? value : "";
  else if (strcmp(cs->first, value ? value : "") != 0)
    cs->differ = true;
  return MHD_YES;
}

/* Every request header field (MHD_get_connection_values): how many, and
 * the first whose name holds a blank. libmicrohttpd 0.9.75 keeps
 * "Content-Length : 60" as a field named "Content-Length " (it cuts the
 * name at the colon only), so such a field frames nothing and its body
 * would be read as the next request. */
typedef struct field_scan {
  unsigned n;
  const char *blank_name; /* NULL: none */
} field_scan;

static enum MHD_Result field_visit(void *cls, enum MHD_ValueKind kind, const char *key, const char *value) {
  (void)kind, (void)value;
  field_scan *fs = cls;
  fs->n++;
  if (!fs->blank_name && key && key[strcspn(key, " \t")]) fs->blank_name = key;
  return MHD_YES;
}

/* Answer a problem now and close the connection after it, whether or not
 * the request announced a body: what follows on the connection cannot be
 * trusted to start a request. */
static enum MHD_Result send_problem_close(struct MHD_Connection *c, conn *cn, int status,
                                          const char *detail) {
  http_req r = {.svc = cn->srv->svc};
  http_resp_problem(&r, status, NULL, "%s", detail);
  cn->close_after = true;
  return send_http_resp(c, cn, &r.resp);
}

static bool first_checks(struct MHD_Connection *c, conn *cn, const char *method, enum MHD_Result *ret) {
  http_server *srv = cn->srv;
  char allow[64];
  bool path_known = false;
  const char *path = cn->raw_path;
  char detail[600];
  /* Framing first (RFC 9112 5.1): no whitespace between a field name and
   * its colon; a 400 and the connection closed. */
  field_scan fs = {0};
  MHD_get_connection_values(c, MHD_HEADER_KIND, field_visit, &fs);
  if (fs.blank_name) {
    snprintf(detail, sizeof detail,
             "header field '%.100s' has whitespace before its colon, which HTTP/1.1 forbids (RFC 9112 "
             "section 5.1); the connection is closed",
             fs.blank_name);
    *ret = send_problem_close(c, cn, 400, detail);
    return false;
  }
  if (fs.n > HTTP_MAX_HEADER_FIELDS) {
    snprintf(detail, sizeof detail, "the request has %u header fields (at most %d)", fs.n,
             HTTP_MAX_HEADER_FIELDS);
    *ret = send_problem(c, cn, 431, NULL, detail, NULL, false);
    return false;
  }
  if (cn->uri_len > HTTP_MAX_URI || cn->n_query > HTTP_MAX_QUERY_PARAMS) {
    snprintf(detail, sizeof detail,
             "the request target has %zu bytes and %zu query parameters (at most %d and %d)", cn->uri_len,
             cn->n_query, HTTP_MAX_URI, HTTP_MAX_QUERY_PARAMS);
    *ret = send_problem(c, cn, 414, NULL, detail, NULL, false);
    return false;
  }
  cn->seg_buf = malloc(strlen(path) + 1);
  if (!cn->seg_buf) {
    *ret = MHD_NO;
    return false;
  }
  const http_route *rt =
      http_route_find(method, path, cn->seg_buf, cn->params, &path_known, allow, sizeof allow);
  /* Health stays open to probes; everything else, known path or not, asks
   * for the token first so that unauthenticated clients learn nothing. */
  const char *why = rt && rt->public_route ? NULL : unauthorized(srv, c);
  if (why) {
    cn->route = rt;
    *ret = send_problem(c, cn, 401, NULL, why, NULL, true);
    return false;
  }
  if (!rt) {
    if (path_known) {
      snprintf(detail, sizeof detail, "%s is not allowed on %.400s (allowed: %s)", method, path, allow);
      *ret = send_problem(c, cn, 405, NULL, detail, allow, false);
    } else {
      snprintf(detail, sizeof detail, "no route %.400s (see GET /v1 and proto/openapi.yaml)", path);
      *ret = send_problem(c, cn, 404, NULL, detail, NULL, false);
    }
    return false;
  }
  cn->route = rt;
  for (int i = 0; i < HTTP_MAX_PATH_PARAMS; i++)
    if (cn->params[i] && !pct_decode((char *)cn->params[i])) {
      snprintf(detail, sizeof detail, "malformed percent-encoding in the path %.400s", path);
      *ret = send_problem(c, cn, 400, NULL, detail, NULL, false);
      return false;
    }
  /* Nearly full: keep the last connections for the health probes (not
   * for the viewer's files, which are public too). */
  if (strncmp(rt->path, "/v1/health/", 11) != 0) {
    pthread_mutex_lock(&srv->lock);
    bool full = srv->n_open > soft_limit(srv) || srv->n_tasks >= (int)srv->max_connections;
    unsigned open = srv->n_open;
    pthread_mutex_unlock(&srv->lock);
    if (full) {
      snprintf(detail, sizeof detail,
               "the server has %u open connections (at most %u, --max-connections); retry shortly", open,
               srv->max_connections);
      cn->close_after = true;
      *ret = send_problem_ra(c, cn, 503, NULL, detail, NULL, false, 1);
      return false;
    }
  }
  const char *ct = header(c, MHD_HTTP_HEADER_CONTENT_TYPE);
  if (ct && !media_fits(rt->body, ct)) {
    snprintf(detail, sizeof detail, "Content-Type '%.200s' is not accepted here (send %s)", ct,
             media_expected(rt->body));
    *ret = send_problem(c, cn, 415, NULL, detail, NULL, false);
    return false;
  }
  /* Body framing must be unambiguous (RFC 9112 6.3): a Content-Length
   * repeated with different values, or one beside Transfer-Encoding, is
   * how requests are smuggled past a proxy that reads the other framing.
   * libmicrohttpd would take one of them; refuse both and close. */
  cl_scan cs = {0};
  MHD_get_connection_values(c, MHD_HEADER_KIND, cl_visit, &cs);
  if (cs.differ || (cs.n > 0 && header(c, MHD_HTTP_HEADER_TRANSFER_ENCODING))) {
    snprintf(detail, sizeof detail,
             cs.differ
                 ? "Content-Length is given %u times with different values: the body's length is ambiguous"
                 : "Content-Length and Transfer-Encoding are both given (%u): the body's length is ambiguous",
             cs.n);
    cn->close_after = true;
    *ret = send_problem(c, cn, 400, NULL, detail, NULL, false);
    return false;
  }
  const char *cl = header(c, MHD_HTTP_HEADER_CONTENT_LENGTH);
  if (cl) {
    char *end;
    errno = 0;
    unsigned long long n = strtoull(cl, &end, 10);
    if (!errno && end != cl && n > srv->max_body) {
      snprintf(detail, sizeof detail, "request body of %llu bytes exceeds the limit of %zu (--max-body)", n,
               srv->max_body);
      *ret = send_problem(c, cn, 413, NULL, detail, NULL, false);
      return false;
    }
    /* Reserve the announced length once instead of growing by doubling,
     * up to a point: an announcement alone must not pin much memory. */
    if (!errno && end != cl && n > 0 && rt->body != HTTP_BODY_NONE) {
      size_t want = (size_t)n + 1 < PREALLOC_MAX ? (size_t)n + 1 : PREALLOC_MAX;
      cn->body = malloc(want);
      if (cn->body) cn->cap = want;
    }
  }
  return true;
}

static void take_body(conn *cn, const char *data, size_t n) {
  if (cn->too_large || cn->route->body == HTTP_BODY_NONE) return;
  if (n > cn->srv->max_body - cn->len) {
    cn->too_large = true;
    free(cn->body);
    cn->body = NULL;
    cn->len = cn->cap = 0;
    return;
  }
  if (cn->len + n + 1 > cn->cap) {
    size_t cap = cn->cap ? cn->cap : 4096;
    while (cap < cn->len + n + 1) cap *= 2;
    if (cap > cn->srv->max_body + 1) cap = cn->srv->max_body + 1;
    char *q = realloc(cn->body, cap);
    if (!q) { /* treat as too large: the client gets a clear answer */
      cn->too_large = true;
      return;
    }
    cn->body = q;
    cn->cap = cap;
  }
  memcpy(cn->body + cn->len, data, n);
  cn->len += n;
  cn->body[cn->len] = '\0';
}

/* ---- clients that hang up, and shutdown ---------------------------------------- */

/* While a long handler (a synchronous render) runs, nobody reads its
 * socket (the connection is suspended, and MHD does not notice a
 * suspended connection's client leaving): the server's watcher thread
 * holds the socket in an epoll set for EPOLLRDHUP (the client's FIN) and
 * HUP/ERR (reset), and sets the watch's `gone` when one comes, so the
 * render stops instead of finishing for nobody. The request body is fully
 * read by then, and HTTP clients do not half-close, so an end of stream
 * here means the client went away. The same thread watches the server's
 * stop pipe: on SIGTERM every watched request is cancelled too
 * (`by_shutdown`), and its client is answered 503. One thread for all
 * watches, not one per render: a thread start and join per request would
 * cost more than a small render.
 *
 * Watches are found by id, not by pointer, in the watcher thread: an event
 * fetched before watch_stop removed its watch (which lives on the handler
 * thread's stack) finds no id and is dropped. */
typedef struct client_watch {
  struct client_watch *next;
  http_server *srv;
  struct MHD_Connection *conn;
  uint64_t id;
  bool registered;
  atomic_int gone;
  atomic_int by_shutdown;
} client_watch;

/* srv->lock held: take w out of the epoll set and the list. */
static void watch_unlink_locked(http_server *srv, client_watch *w, int fd) {
  if (!w->registered) return;
  epoll_ctl(srv->watch_ep, EPOLL_CTL_DEL, fd, NULL);
  for (client_watch **pp = &srv->watches; *pp; pp = &(*pp)->next)
    if (*pp == w) {
      *pp = w->next;
      break;
    }
  w->registered = false;
}

static int watch_fd(const client_watch *w) {
  const union MHD_ConnectionInfo *ci = MHD_get_connection_info(w->conn, MHD_CONNECTION_INFO_CONNECTION_FD);
  return ci ? ci->connect_fd : -1;
}

static void *watcher_main(void *arg) {
  http_server *srv = arg;
  struct epoll_event evs[64];
  for (;;) {
    int n = epoll_wait(srv->watch_ep, evs, 64, -1);
    if (n < 0 && errno == EINTR) continue;
    bool stop = n < 0;
    pthread_mutex_lock(&srv->lock);
    for (int i = 0; i < n; i++) {
      if (evs[i].data.u64 == 0) { /* the stop pipe */
        stop = true;
        continue;
      }
      for (client_watch *w = srv->watches; w; w = w->next)
        if (w->id == evs[i].data.u64) {
          atomic_store(&w->gone, 1);
          watch_unlink_locked(srv, w, watch_fd(w));
          break;
        }
    }
    if (stop) { /* cancel every watched request; later ones are cancelled at once */
      srv->watch_closed = true;
      while (srv->watches) {
        client_watch *w = srv->watches;
        atomic_store(&w->by_shutdown, 1);
        atomic_store(&w->gone, 1);
        watch_unlink_locked(srv, w, watch_fd(w));
      }
    }
    pthread_mutex_unlock(&srv->lock);
    if (stop) return NULL;
  }
}

/* http_req.watch_client: start the watch once per request. */
static const atomic_int *watch_start(http_req *r) {
  client_watch *w = r->watch_ctx;
  http_server *srv = w->srv;
  if (w->registered || atomic_load(&w->gone)) return &w->gone;
  int fd = watch_fd(w);
  if (fd < 0) return NULL;
  pthread_mutex_lock(&srv->lock);
  if (srv->watch_closed) {
    atomic_store(&w->by_shutdown, 1);
    atomic_store(&w->gone, 1);
  } else {
    w->id = ++srv->watch_seq;
    struct epoll_event ev = {.events = EPOLLRDHUP, .data.u64 = w->id};
    if (epoll_ctl(srv->watch_ep, EPOLL_CTL_ADD, fd, &ev) == 0) {
      w->registered = true;
      w->next = srv->watches;
      srv->watches = w;
    }
  }
  bool ok = w->registered || atomic_load(&w->gone);
  pthread_mutex_unlock(&srv->lock);
  return ok ? &w->gone : NULL;
}

static void watch_stop(client_watch *w) {
  http_server *srv = w->srv;
  pthread_mutex_lock(&srv->lock);
  if (w->registered) watch_unlink_locked(srv, w, watch_fd(w));
  pthread_mutex_unlock(&srv->lock);
}

/* Run the route's handler with a client watch; a request cancelled by the
 * server's shutdown is answered 503 whatever the handler made of it. */
static void run_handler(http_server *srv, struct MHD_Connection *c, const http_route *rt, http_req *r) {
  client_watch w = {.srv = srv, .conn = c, .registered = false};
  atomic_init(&w.gone, 0);
  atomic_init(&w.by_shutdown, 0);
  r->watch_client = watch_start;
  r->watch_ctx = &w;
  rt->handler(r);
  watch_stop(&w);
  r->watch_ctx = NULL;
  if (atomic_load(&w.by_shutdown) && (r->resp.status < 200 || r->resp.status >= 300)) {
    http_resp_problem(r, 503, "RSW_ERR_UNAVAILABLE",
                      "the server is shutting down (SIGTERM): the request was cancelled; retry it on a "
                      "running server");
    r->resp.retry_after_s = 1;
  }
}

/* A handler on its own thread, its connection suspended meanwhile. */
typedef struct task {
  struct task *next;
  conn *cn;
  struct MHD_Connection *c;
  http_req r;
} task;

static void task_run(task *t) {
  conn *cn = t->cn;
  http_server *srv = cn->srv;
  struct MHD_Connection *c = t->c;
  run_handler(srv, c, cn->route, &t->r);
  cn->resp = t->r.resp;
  cn->task_done = true;
  free(t);
  /* From here on cn may be gone (MHD answers and completes the request). */
  MHD_resume_connection(c);
  pthread_mutex_lock(&srv->lock);
  srv->n_tasks--;
  pthread_cond_broadcast(&srv->cond);
  pthread_mutex_unlock(&srv->lock);
}

static void *handler_main(void *arg) {
  task *t = arg;
  http_server *srv = t->cn->srv;
  for (;;) {
    task_run(t);
    t = NULL;
    pthread_mutex_lock(&srv->lock);
    srv->n_idle++;
    int64_t until = now_ms() + HANDLER_IDLE_MS;
    struct timespec ts = {.tv_sec = (time_t)(until / 1000), .tv_nsec = (long)(until % 1000) * 1000000L};
    while (!srv->queue && !atomic_load(&srv->stopping))
      if (pthread_cond_timedwait(&srv->task_cond, &srv->lock, &ts) == ETIMEDOUT) break;
    srv->n_idle--;
    if (srv->queue) {
      t = srv->queue;
      srv->queue = t->next;
      if (!srv->queue) srv->queue_tail = &srv->queue;
      srv->n_queued--;
    }
    if (!t) {
      srv->n_threads--;
      pthread_cond_broadcast(&srv->cond);
    }
    pthread_mutex_unlock(&srv->lock);
    if (!t) return NULL;
  }
}

/* Hand t to a waiting thread or a new one. False when no thread could be
 * had (then t is not taken). */
static bool task_start(http_server *srv, task *t) {
  t->next = NULL;
  pthread_mutex_lock(&srv->lock);
  if (srv->n_idle > srv->n_queued) {
    *srv->queue_tail = t;
    srv->queue_tail = &t->next;
    srv->n_queued++;
    pthread_cond_signal(&srv->task_cond);
    pthread_mutex_unlock(&srv->lock);
    return true;
  }
  srv->n_threads++;
  pthread_mutex_unlock(&srv->lock);
  pthread_t th;
  pthread_attr_t at;
  pthread_attr_init(&at);
  pthread_attr_setdetachstate(&at, PTHREAD_CREATE_DETACHED);
  bool ok = pthread_create(&th, &at, handler_main, t) == 0;
  pthread_attr_destroy(&at);
  if (!ok) {
    pthread_mutex_lock(&srv->lock);
    srv->n_threads--;
    pthread_cond_broadcast(&srv->cond);
    pthread_mutex_unlock(&srv->lock);
  }
  return ok;
}

/* The whole request is in: last checks, then the handler (on the event
 * loop for the health routes, on a thread of its own otherwise). */
static enum MHD_Result dispatch(struct MHD_Connection *c, conn *cn, const char *url, const char *method) {
  const http_route *rt = cn->route;
  http_server *srv = cn->srv;
  if (cn->too_large) {
    char detail[200];
    snprintf(detail, sizeof detail, "request body exceeds the limit of %zu bytes (--max-body)",
             srv->max_body);
    return send_problem(c, cn, 413, NULL, detail, NULL, false);
  }
  const char *ct = header(c, MHD_HTTP_HEADER_CONTENT_TYPE);
  const char *body = cn->body ? cn->body : "";
  size_t len = cn->len;
  bool json = rt->body == HTTP_BODY_JSON ||
              (rt->body == HTTP_BODY_SCENE && http_media_type_is(ct, "application/json"));
  if ((rt->body == HTTP_BODY_JSON || rt->body == HTTP_BODY_SCENE) && !ct && len) {
    char detail[200];
    snprintf(detail, sizeof detail, "a request body needs a Content-Type (%s)", media_expected(rt->body));
    return send_problem(c, cn, 415, NULL, detail, NULL, false);
  }
  if (json && !http_json_depth_ok(body, len, HTTP_MAX_JSON_DEPTH)) {
    char detail[120];
    snprintf(detail, sizeof detail, "JSON body nests deeper than %d levels", HTTP_MAX_JSON_DEPTH);
    return send_problem(c, cn, 400, NULL, detail, NULL, false);
  }
  /* Every field of a JSON request is optional somewhere (a render with all
   * defaults): an empty body means an empty object. */
  if (rt->body == HTTP_BODY_JSON && len == 0) body = "{}", len = 2;

  http_req r = {
      .svc = srv->svc,
      .method = method,
      .path = url,
      .params = {cn->params[0], cn->params[1], cn->params[2]},
      .q_match = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "match"),
      .q_class = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "class"),
      .q_full = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "full"),
      .q_force = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "force"),
      .q_variant = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "variant"),
      .q_name = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "name"),
      .q_partial = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "partial"),
      .q_exposure = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "exposure"),
      .q_colormap = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "colormap"),
      .q_band = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "band"),
      .q_node = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "node"),
      .q_dry_run = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "dry_run"),
      .content_type = ct,
      .accept = header(c, MHD_HTTP_HEADER_ACCEPT),
      .if_match = header(c, MHD_HTTP_HEADER_IF_MATCH),
      .idempotency_key = header(c, "Idempotency-Key"),
      .last_event_id = header(c, MHD_HTTP_HEADER_LAST_EVENT_ID),
      .if_none_match = header(c, MHD_HTTP_HEADER_IF_NONE_MATCH),
      .body = body,
      .body_len = len,
      .resp = {.status = 500},
  };
  if (rt->quick) {
    run_handler(srv, c, rt, &r);
    return send_http_resp(c, cn, &r.resp);
  }
  task *t = malloc(sizeof *t);
  if (!t) return send_problem(c, cn, 500, "RSW_ERR_NOMEM", "out of memory", NULL, false);
  t->cn = cn;
  t->c = c;
  t->r = r;
  /* Counted under the lock with the stopping check, so that stopping
   * (which sets the flag, then waits for the count) never misses one. */
  pthread_mutex_lock(&srv->lock);
  bool stopping = atomic_load(&srv->stopping);
  if (!stopping) srv->n_tasks++;
  pthread_mutex_unlock(&srv->lock);
  if (stopping) {
    free(t);
    return send_problem_ra(c, cn, 503, "RSW_ERR_UNAVAILABLE", "the server is shutting down", NULL, false, 1);
  }
  cn->task_started = true;
  MHD_suspend_connection(c);
  if (!task_start(srv, t)) { /* answer 503 on the next call */
    free(t);
    http_req q = {.svc = srv->svc};
    http_resp_problem(&q, 503, NULL, "the server cannot start a thread for this request; retry shortly");
    q.resp.retry_after_s = 1;
    cn->resp = q.resp;
    cn->task_done = true;
    MHD_resume_connection(c);
    pthread_mutex_lock(&srv->lock);
    srv->n_tasks--;
    pthread_cond_broadcast(&srv->cond);
    pthread_mutex_unlock(&srv->lock);
  }
  return MHD_YES;
}

/* MHD_OPTION_URI_LOG_CALLBACK: the first thing MHD reports of a request,
 * with the request target exactly as sent. Its result becomes the
 * per-request pointer. */
static void *on_uri(void *cls, const char *uri, struct MHD_Connection *c) {
  (void)c;
  http_server *srv = cls;
  conn *cn = calloc(1, sizeof *cn);
  if (!cn) return NULL;
  cn->srv = srv;
  cn->uri_len = strlen(uri);
  size_t n = strcspn(uri, "?");
  if (uri[n] == '?') {
    cn->n_query = 1;
    for (const char *q = uri + n + 1; *q; q++) cn->n_query += *q == '&';
  }
  /* Too many query parameters: answered 414 at the first call (which
   * needs none of them). libmicrohttpd calls this before it splits the
   * query into parameters in its per-connection memory pool, from the
   * same writable buffer, and 5,000 of them exhaust that pool: it then
   * closes the connection without an answer. An empty query costs it
   * nothing, so the query is emptied here (the byte after '?'). */
  if (cn->n_query > HTTP_MAX_QUERY_PARAMS) ((char *)uri)[n + 1] = '\0';
  cn->raw_path = strndup(uri, n);
  if (!cn->raw_path) {
    free(cn);
    return NULL;
  }
  pthread_mutex_lock(&srv->lock);
  srv->n_inflight++;
  pthread_mutex_unlock(&srv->lock);
  return cn;
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url, const char *method,
                                  const char *version, const char *upload_data, size_t *upload_data_size,
                                  void **con_cls) {
  (void)version, (void)cls;
  conn *cn = *con_cls;
  if (!cn) return MHD_NO; /* on_uri ran out of memory: close */
  if (!cn->seen_first) {
    conn_track *t = track_of(c);
    if (t) {
      pthread_mutex_lock(&cn->srv->lock);
      t->in_request = true;
      pthread_mutex_unlock(&cn->srv->lock);
    }
    enum MHD_Result ret = MHD_YES;
    first_checks(c, cn, method, &ret);
    cn->seen_first = true;
    return ret;
  }
  if (cn->task_started) { /* resumed: the handler thread's answer */
    if (!cn->task_done) return MHD_YES;
    cn->task_started = false;
    return send_http_resp(c, cn, &cn->resp);
  }
  if (cn->answered || cn->has_early) { /* answered already: drop any body */
    if (*upload_data_size) {
      *upload_data_size = 0;
      return MHD_YES;
    }
    if (cn->answered) return MHD_YES;
    cn->has_early = false;
    return send_http_resp(c, cn, &cn->early);
  }
  if (*upload_data_size) {
    take_body(cn, upload_data, *upload_data_size);
    *upload_data_size = 0;
    return MHD_YES;
  }
  return dispatch(c, cn, url, method);
}

static void on_completed(void *cls, struct MHD_Connection *c, void **con_cls,
                         enum MHD_RequestTerminationCode toe) {
  (void)toe;
  http_server *srv = cls;
  conn *cn = *con_cls;
  conn_track *t = track_of(c);
  pthread_mutex_lock(&srv->lock);
  if (t) { /* the next request's headers have their own deadline */
    t->in_request = false;
    t->since_ms = now_ms();
  }
  if (cn) srv->n_inflight--;
  pthread_cond_broadcast(&srv->cond);
  pthread_mutex_unlock(&srv->lock);
  if (!cn) return;
  /* A handler thread's answer that never went out: libmicrohttpd, resuming
   * the connection, found its client gone before asking on_request for
   * the answer (a synchronous render whose client hung up: the render
   * stopped and answered 409). It is counted as answered, as it is when
   * libmicrohttpd asks first; which comes first is a race. */
  if (cn->task_started && cn->task_done) count(srv, cn->route, cn->resp.status);
  if (cn->has_early) http_resp_clear(&cn->early);
  http_resp_clear(&cn->resp);
  free(cn->raw_path);
  free(cn->seg_buf);
  free(cn->body);
  free(cn);
  *con_cls = NULL;
}

static void on_log(void *cls, const char *fmt, va_list ap) {
  (void)cls;
  char msg[512];
  vsnprintf(msg, sizeof msg, fmt, ap);
  size_t n = strlen(msg);
  while (n && msg[n - 1] == '\n') msg[--n] = '\0';
  fprintf(stderr, "raysweepd: http: %s\n", msg);
}

/* ---- life cycle ----------------------------------------------------------------- */

bool http_host_is_loopback(const char *host) {
  if (!host) return false;
  if (strcasecmp(host, "localhost") == 0) return true;
  struct in_addr a;
  if (inet_pton(AF_INET, host, &a) != 1) return false;
  return (ntohl(a.s_addr) >> 24) == 127;
}

static rsw_status resolve(const char *host, int port, struct sockaddr_in *sin, rsw_err *err) {
  if (strchr(host, ':') || host[0] == '[')
    return rsw_fail(err, RSW_ERR_UNSUPPORTED, "--listen",
                    "IPv6 addresses are not supported (got '%s'); use an IPv4 address such as 127.0.0.1",
                    host);
  memset(sin, 0, sizeof *sin);
  sin->sin_family = AF_INET;
  sin->sin_port = htons((uint16_t)port);
  if (inet_pton(AF_INET, host, &sin->sin_addr) == 1) return RSW_OK;
  struct addrinfo hints = {.ai_family = AF_INET, .ai_socktype = SOCK_STREAM}, *res = NULL;
  int rc = getaddrinfo(host, NULL, &hints, &res);
  if (rc != 0 || !res)
    return rsw_fail(err, RSW_ERR_IO, "--listen", "cannot resolve '%s' to an IPv4 address: %s", host,
                    rc ? gai_strerror(rc) : "no address");
  sin->sin_addr = ((const struct sockaddr_in *)res->ai_addr)->sin_addr;
  freeaddrinfo(res);
  return RSW_OK;
}

rsw_status http_server_start(service *svc, const http_opts *opts, http_server **out, rsw_err *err) {
  if (!svc || !opts || opts->size < sizeof *opts || !out)
    return rsw_fail(err, RSW_ERR_INVALID, "http_server_start", "missing service or options");
  const char *host = opts->host ? opts->host : "127.0.0.1";
  if (opts->port < 0 || opts->port > 65535)
    return rsw_fail(err, RSW_ERR_USAGE, "--listen", "port %d outside [0, 65535]", opts->port);
  struct sockaddr_in sin;
  rsw_status s = resolve(host, opts->port, &sin, err);
  if (s) return s;
  bool has_token = opts->token && opts->token[0];
  if ((ntohl(sin.sin_addr.s_addr) >> 24) != 127 && !has_token)
    return rsw_fail(err, RSW_ERR_USAGE, "--listen",
                    "refusing to listen on %s (not a loopback address) without --token-file", host);

  http_server *srv = calloc(1, sizeof *srv);
  if (!srv) return rsw_fail(err, RSW_ERR_NOMEM, "http_server_start", "out of memory");
  srv->svc = svc;
  srv->max_body = opts->max_body ? opts->max_body : HTTP_DEFAULT_MAX_BODY;
  srv->max_connections = opts->max_connections ? opts->max_connections : HTTP_DEFAULT_MAX_CONNECTIONS;
  srv->header_timeout_ms = (int64_t)(1000.0 * (opts->header_timeout_s > 0 ? opts->header_timeout_s
                                                                          : HTTP_DEFAULT_HEADER_TIMEOUT_S));
  srv->stop_pipe[0] = srv->stop_pipe[1] = -1;
  atomic_init(&srv->stopping, false);
  atomic_init(&srv->stop_deadline_ms, 0);
  srv->watch_ep = -1;
  if (pipe2(srv->stop_pipe, O_CLOEXEC) != 0) {
    free(srv);
    return rsw_fail(err, RSW_ERR_IO, "http_server_start", "cannot create a pipe: %s", strerror(errno));
  }
  srv->watch_ep = epoll_create1(EPOLL_CLOEXEC);
  struct epoll_event stop_ev = {.events = EPOLLIN, .data.u64 = 0};
  if (srv->watch_ep < 0 || epoll_ctl(srv->watch_ep, EPOLL_CTL_ADD, srv->stop_pipe[0], &stop_ev) != 0) {
    int e = errno;
    if (srv->watch_ep >= 0) close(srv->watch_ep);
    close(srv->stop_pipe[0]);
    close(srv->stop_pipe[1]);
    free(srv);
    return rsw_fail(err, RSW_ERR_IO, "http_server_start", "cannot create an epoll set: %s", strerror(e));
  }
  if (has_token) {
    srv->token = strdup(opts->token);
    if (!srv->token) {
      free(srv);
      return rsw_fail(err, RSW_ERR_NOMEM, "http_server_start", "out of memory");
    }
    srv->token_len = strlen(srv->token);
  }

  /* Our own socket, so that a bind failure is reported with its errno. */
  int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  int one = 1;
  if (fd < 0 || setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) != 0 ||
      bind(fd, (const struct sockaddr *)&sin, sizeof sin) != 0 || listen(fd, 128) != 0) {
    int e = errno;
    if (fd >= 0) close(fd);
    close(srv->watch_ep);
    close(srv->stop_pipe[0]);
    close(srv->stop_pipe[1]);
    free(srv->token);
    free(srv);
    return rsw_fail(
        err, RSW_ERR_IO, "--listen", "cannot listen on %s:%d: %s%s", host, opts->port, strerror(e),
        e == EADDRINUSE ? " (another process, perhaps another raysweepd, has this port: stop it, or give "
                          "another port, e.g. --listen 127.0.0.1:0 for any free one)"
                        : "");
  }

  unsigned flags =
      MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_EPOLL | MHD_ALLOW_SUSPEND_RESUME | MHD_USE_ERROR_LOG;
  pthread_condattr_t ca;
  pthread_condattr_init(&ca);
  pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
  pthread_mutex_init(&srv->lock, NULL);
  pthread_cond_init(&srv->cond, &ca);
  pthread_cond_init(&srv->task_cond, &ca);
  pthread_condattr_destroy(&ca);
  srv->queue_tail = &srv->queue;
  /* The logger goes first so that it sees the other options' messages. */
  srv->mhd = MHD_start_daemon(
      flags, 0, NULL, NULL, on_request, srv, MHD_OPTION_EXTERNAL_LOGGER, on_log, NULL,
      MHD_OPTION_LISTEN_SOCKET, fd, MHD_OPTION_THREAD_POOL_SIZE, (unsigned)EVENT_THREADS,
      MHD_OPTION_URI_LOG_CALLBACK, on_uri, srv, MHD_OPTION_NOTIFY_COMPLETED, on_completed, srv,
      MHD_OPTION_NOTIFY_CONNECTION, on_connection, srv, MHD_OPTION_CONNECTION_LIMIT, srv->max_connections,
      MHD_OPTION_PER_IP_CONNECTION_LIMIT, opts->max_connections_per_ip, MHD_OPTION_CONNECTION_TIMEOUT,
      (unsigned)CONNECTION_TIMEOUT_S, MHD_OPTION_CONNECTION_MEMORY_LIMIT, CONNECTION_MEMORY,
      MHD_OPTION_LISTEN_BACKLOG_SIZE, 512u, MHD_OPTION_END);
  if (srv->mhd) srv->reaper_started = pthread_create(&srv->reaper, NULL, reaper_main, srv) == 0;
  if (srv->reaper_started) srv->watcher_started = pthread_create(&srv->watcher, NULL, watcher_main, srv) == 0;
  if (!srv->mhd || !srv->reaper_started || !srv->watcher_started) {
    if (srv->reaper_started || srv->watcher_started) {
      char wake = 1;
      while (write(srv->stop_pipe[1], &wake, 1) < 0 && errno == EINTR) {}
    }
    if (srv->reaper_started) pthread_join(srv->reaper, NULL);
    if (srv->watcher_started) pthread_join(srv->watcher, NULL);
    if (srv->mhd) MHD_stop_daemon(srv->mhd);
    pthread_cond_destroy(&srv->task_cond);
    pthread_cond_destroy(&srv->cond);
    pthread_mutex_destroy(&srv->lock);
    close(fd);
    close(srv->watch_ep);
    close(srv->stop_pipe[0]);
    close(srv->stop_pipe[1]);
    free(srv->token);
    free(srv);
    return rsw_fail(err, RSW_ERR_IO, "--listen", "libmicrohttpd could not start on %s:%d", host, opts->port);
  }
  const union MHD_DaemonInfo *info = MHD_get_daemon_info(srv->mhd, MHD_DAEMON_INFO_BIND_PORT);
  srv->port = info && info->port ? info->port : opts->port;
  if (!srv->port) { /* older libraries: ask the socket */
    struct sockaddr_in got;
    socklen_t gl = sizeof got;
    if (getsockname(fd, (struct sockaddr *)&got, &gl) == 0) srv->port = ntohs(got.sin_port);
  }
  *out = srv;
  return RSW_OK;
}

int http_server_port(const http_server *srv) {
  return srv ? srv->port : 0;
}

/* Wait (srv->lock held) until *count is 0 or the monotonic deadline. */
static void wait_zero(http_server *srv, const int *count, int64_t deadline_ms) {
  while (*count > 0) {
    if (deadline_ms < 0) {
      pthread_cond_wait(&srv->cond, &srv->lock);
      continue;
    }
    struct timespec until = {.tv_sec = (time_t)(deadline_ms / 1000),
                             .tv_nsec = (long)(deadline_ms % 1000) * 1000000L};
    if (pthread_cond_timedwait(&srv->cond, &srv->lock, &until) == ETIMEDOUT) break;
  }
}

void http_server_stop(http_server *srv) {
  if (!srv) return;
  int64_t deadline = now_ms() + SSE_GRACE_MS;
  atomic_store(&srv->stop_deadline_ms, deadline);
  atomic_store(&srv->stopping, true);
  /* Wake the render watches (their renders are cancelled and answered
   * 503) and the reaper. */
  char one = 1;
  while (write(srv->stop_pipe[1], &one, 1) < 0 && errno == EINTR) {}
  if (srv->reaper_started) pthread_join(srv->reaper, NULL);
  if (srv->watcher_started) pthread_join(srv->watcher, NULL);
  pthread_mutex_lock(&srv->lock);
  /* Handler threads hold suspended connections: every one must have
   * resumed before MHD may free its connections. Renders stop within a
   * moment of the stop pipe; other handlers finish their short work. */
  wait_zero(srv, &srv->n_tasks, -1);
  /* Idle handler threads leave now (stopping is set). */
  pthread_cond_broadcast(&srv->task_cond);
  wait_zero(srv, &srv->n_threads, -1);
  /* Event streams end with their job's `end` event (the service cancelled
   * the jobs) or at the deadline, and answers made go on being sent until
   * then: MHD's stop cuts every socket. */
  wait_zero(srv, &srv->n_streams, deadline + SSE_POLL_MS);
  wait_zero(srv, &srv->n_inflight, deadline + SSE_POLL_MS);
  pthread_mutex_unlock(&srv->lock);
  MHD_stop_daemon(srv->mhd);
  /* Stream threads let go of their stream within one poll. */
  pthread_mutex_lock(&srv->lock);
  wait_zero(srv, &srv->n_streams, -1);
  pthread_mutex_unlock(&srv->lock);
  pthread_cond_destroy(&srv->task_cond);
  pthread_cond_destroy(&srv->cond);
  pthread_mutex_destroy(&srv->lock);
  close(srv->watch_ep);
  close(srv->stop_pipe[0]);
  close(srv->stop_pipe[1]);
  free(srv->token);
  free(srv);
}
