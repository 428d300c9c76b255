/* libmicrohttpd glue: the one file of raysweepd that includes
 * microhttpd.h. It owns the listening socket, one thread per connection
 * (MHD_USE_THREAD_PER_CONNECTION: a synchronous render or an event stream
 * blocks only its own connection), body accumulation, the generic checks
 * that run before any handler (auth, 404/405, 413, 415, JSON depth), the
 * translation of an http_resp into an MHD response, and server-sent events.
 *
 * Per-request state lives in a struct conn hung on MHD's per-request
 * pointer and freed in the completion callback; the server has no global
 * state. */
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
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <microhttpd.h>

#include "encode.h"
#include "routes.h"

/* Event streams poll the service this often for shutdown, and send a
 * keep-alive comment after this long without an event (proxies drop
 * silent connections; it also reveals clients that went away). */
#define SSE_POLL_MS          500
#define SSE_PING_MS          15000
/* On shutdown, event streams go on this long for their jobs' final
 * `end` event (the service cancels running jobs) before they are cut. */
#define SSE_GRACE_MS         3000
/* Most body memory reserved from Content-Length before the bytes arrive. */
#define PREALLOC_MAX         ((size_t)16 << 20)
/* Idle connections close after this (seconds). */
#define CONNECTION_TIMEOUT_S 120

struct http_server {
  service *svc;
  struct MHD_Daemon *mhd;
  char *token; /* NULL: no auth */
  size_t token_len;
  size_t max_body;
  int port;
  atomic_bool stopping;
  _Atomic int64_t stop_deadline_ms; /* monotonic ms; streams end after it */
  /* Open event streams, so that stopping can wait for them to send their
   * jobs' `end` before MHD closes every socket. */
  pthread_mutex_t lock;
  pthread_cond_t streams_done;
  int n_streams;
};

/* One request in flight. */
typedef struct conn {
  http_server *srv;
  const http_route *route; /* NULL when answered at the first call */
  const char *params[HTTP_MAX_PATH_PARAMS];
  char *seg_buf; /* owns the strings params point into */
  char *body;
  size_t len, cap;
  bool too_large;  /* body passed max_body: read and dropped, then 413 */
  bool answered;   /* a response is queued already */
  bool seen_first; /* the first call (headers only) is over */
  bool has_early;  /* early holds a problem to send at the last call */
  http_resp early;
} conn;

/* ---- responses ------------------------------------------------------------ */

static void count(http_server *srv, const http_route *rt, int status) {
  service_count_request(srv->svc, rt ? rt->path : "unmatched", status);
}

typedef struct sse_stream {
  http_server *srv;
  char job[128];
  uint64_t after;
  http_buf out; /* formatted and not yet handed to MHD */
  size_t out_off;
  bool ended;
} sse_stream;

static ssize_t sse_read(void *cls, uint64_t pos, char *buf, size_t max);
static void sse_free(void *cls);

static void add_headers(struct MHD_Response *mr, const http_resp *resp) {
  if (resp->content_type) MHD_add_response_header(mr, MHD_HTTP_HEADER_CONTENT_TYPE, resp->content_type);
  if (resp->location[0]) MHD_add_response_header(mr, MHD_HTTP_HEADER_LOCATION, resp->location);
  if (resp->etag[0]) MHD_add_response_header(mr, MHD_HTTP_HEADER_ETAG, resp->etag);
  if (resp->allow[0]) MHD_add_response_header(mr, MHD_HTTP_HEADER_ALLOW, resp->allow);
  if (resp->www_authenticate)
    MHD_add_response_header(mr, MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"raysweepd\"");
  if (resp->retry_after_s > 0) {
    char v[16];
    snprintf(v, sizeof v, "%d", resp->retry_after_s);
    MHD_add_response_header(mr, MHD_HTTP_HEADER_RETRY_AFTER, v);
  }
}

/* Queue r->resp on the connection (taking its body) and count it. */
static enum MHD_Result send_resp(struct MHD_Connection *c, conn *cn, http_req *r) {
  http_resp *resp = &r->resp;
  struct MHD_Response *mr = NULL;
  if (resp->sse) {
    sse_stream *st = calloc(1, sizeof *st);
    if (st) {
      st->srv = cn->srv;
      snprintf(st->job, sizeof st->job, "%s", resp->sse_job);
      st->after = resp->sse_after;
      mr = MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 4096, sse_read, st, sse_free);
      if (!mr) {
        free(st);
      } else {
        pthread_mutex_lock(&cn->srv->lock);
        cn->srv->n_streams++;
        pthread_mutex_unlock(&cn->srv->lock);
      }
    }
    if (mr) {
      MHD_add_response_header(mr, MHD_HTTP_HEADER_CONTENT_TYPE, "text/event-stream");
      MHD_add_response_header(mr, MHD_HTTP_HEADER_CACHE_CONTROL, "no-cache");
    }
  } else if (resp->has_fd) {
    mr = MHD_create_response_from_fd64(resp->fd_len, resp->fd);
    if (mr) {
      resp->has_fd = false; /* microhttpd closes it */
      add_headers(mr, resp);
    }
  } else {
    mr = resp->len ? MHD_create_response_from_buffer(resp->len, resp->body, MHD_RESPMEM_MUST_FREE)
                   : MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT);
    if (mr && resp->len) resp->body = NULL; /* MHD frees it with free() */
    if (mr) add_headers(mr, resp);
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
static enum MHD_Result send_problem(struct MHD_Connection *c, conn *cn, int status, const char *code,
                                    const char *detail, const char *allow, bool www_auth) {
  http_req r = {.svc = cn->srv->svc};
  http_resp_problem(&r, status, code, "%s", detail);
  if (allow) snprintf(r.resp.allow, sizeof r.resp.allow, "%s", allow);
  r.resp.www_authenticate = www_auth;
  if (!cn->seen_first && !has_body(c)) {
    cn->early = r.resp;
    cn->has_early = true;
    return MHD_YES;
  }
  return send_resp(c, cn, &r);
}

static int64_t now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

static bool streams_must_end(http_server *srv) {
  return atomic_load(&srv->stopping) && now_ms() >= atomic_load(&srv->stop_deadline_ms);
}

/* ---- server-sent events ------------------------------------------------------
 * event: context | end
 * id: <sequence>
 * data: <json>            (one data: line per line of the JSON)
 * <blank line> */

static void sse_format(http_buf *b, const char *event, uint64_t id, const char *data) {
  http_buf_printf(b, "event: %s\n", event);
  if (id) http_buf_printf(b, "id: %llu\n", (unsigned long long)id);
  for (const char *line = data;;) {
    size_t n = strcspn(line, "\r\n");
    http_buf_puts(b, "data: ");
    http_buf_append(b, line, n);
    http_buf_puts(b, "\n");
    line += n;
    if (*line == '\r' && line[1] == '\n') line++;
    if (!*line || !*++line) break;
  }
  http_buf_puts(b, "\n");
}

/* Block (this connection's own thread) until there is something to send:
 * the next event, a keep-alive comment, or the end of the stream. */
static ssize_t sse_read(void *cls, uint64_t pos, char *buf, size_t max) {
  sse_stream *st = cls;
  (void)pos;
  int waited_ms = 0;
  while (st->out_off >= st->out.len) {
    http_buf_free(&st->out);
    st->out_off = 0;
    if (st->ended || streams_must_end(st->srv)) return MHD_CONTENT_READER_END_OF_STREAM;
    uint64_t seq = 0;
    char *json = NULL;
    bool is_end = false;
    svc_error e = {0};
    rsw_status s =
        service_job_next_event(st->srv->svc, st->job, st->after, SSE_POLL_MS, &seq, &json, &is_end, &e);
    if (s != RSW_OK) { /* the job went away (deleted): say why, then end */
      int status;
      char *problem = http_problem_from_svc(&e, &status);
      sse_format(&st->out, "error", 0, problem ? problem : "{}");
      free(problem);
      st->ended = true;
    } else if (json) {
      sse_format(&st->out, is_end ? "end" : "context", seq, json);
      free(json);
      if (seq > st->after) st->after = seq;
      st->ended = is_end;
    } else if ((waited_ms += SSE_POLL_MS) >= SSE_PING_MS) {
      http_buf_puts(&st->out, ": ping\n\n");
      waited_ms = 0;
    }
    if (st->out.failed) return MHD_CONTENT_READER_END_WITH_ERROR;
  }
  size_t n = st->out.len - st->out_off;
  if (n > max) n = max;
  memcpy(buf, st->out.p + st->out_off, n);
  st->out_off += n;
  return (ssize_t)n;
}

static void sse_free(void *cls) {
  sse_stream *st = cls;
  http_server *srv = st->srv;
  http_buf_free(&st->out);
  free(st);
  pthread_mutex_lock(&srv->lock);
  if (--srv->n_streams == 0) pthread_cond_broadcast(&srv->streams_done);
  pthread_mutex_unlock(&srv->lock);
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

static bool authorized(const http_server *srv, struct MHD_Connection *c) {
  if (!srv->token) return true;
  const char *h = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_AUTHORIZATION);
  if (!h) return false;
  while (*h == ' ') h++;
  if (strncasecmp(h, "Bearer", 6) != 0 || (h[6] != ' ' && h[6] != '\t')) return false;
  h += 6;
  while (*h == ' ' || *h == '\t') h++;
  size_t n = strlen(h);
  while (n && (h[n - 1] == ' ' || h[n - 1] == '\t')) n--;
  return token_equal(h, n, srv->token, srv->token_len);
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

/* First call for a request: headers are in, the body is not. Answers
 * at once what needs no body; returns false when it did. */
static bool first_checks(struct MHD_Connection *c, conn *cn, const char *url, const char *method,
                         enum MHD_Result *ret) {
  http_server *srv = cn->srv;
  char allow[64];
  bool path_known = false;
  cn->seg_buf = malloc(strlen(url) + 1);
  if (!cn->seg_buf) {
    *ret = MHD_NO;
    return false;
  }
  const http_route *rt =
      http_route_find(method, url, cn->seg_buf, cn->params, &path_known, allow, sizeof allow);
  /* Health stays open to probes; everything else, known path or not, asks
   * for the token first so that unauthenticated clients learn nothing. */
  if (!(rt && rt->public_route) && !authorized(srv, c)) {
    cn->route = rt;
    *ret = send_problem(c, cn, 401, NULL, "this server requires Authorization: Bearer <token>", NULL, true);
    return false;
  }
  if (!rt) {
    char detail[600];
    if (path_known) {
      snprintf(detail, sizeof detail, "%s is not allowed on %.400s (allowed: %s)", method, url, allow);
      *ret = send_problem(c, cn, 405, NULL, detail, allow, false);
    } else {
      snprintf(detail, sizeof detail, "no route %.400s (see GET /v1 and proto/openapi.yaml)", url);
      *ret = send_problem(c, cn, 404, NULL, detail, NULL, false);
    }
    return false;
  }
  cn->route = rt;
  const char *ct = header(c, MHD_HTTP_HEADER_CONTENT_TYPE);
  if (ct && !media_fits(rt->body, ct)) {
    char detail[400];
    snprintf(detail, sizeof detail, "Content-Type '%.200s' is not accepted here (send %s)", ct,
             media_expected(rt->body));
    *ret = send_problem(c, cn, 415, NULL, detail, NULL, false);
    return false;
  }
  const char *cl = header(c, MHD_HTTP_HEADER_CONTENT_LENGTH);
  if (cl) {
    char *end;
    errno = 0;
    unsigned long long n = strtoull(cl, &end, 10);
    if (!errno && end != cl && n > srv->max_body) {
      char detail[200];
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

/* The whole request is in: last checks, then the handler. */
/* ---- clients that hang up ---------------------------------------------------- */

/* While a long handler (a synchronous render) runs on a connection's
 * thread, nobody reads its socket: a small thread polls it and sets `gone`
 * when the peer closed it (POLLRDHUP: the client's FIN; HUP/ERR: reset), so
 * the render stops instead of finishing for nobody. The request body is
 * fully read by then, and HTTP clients do not half-close, so an end of
 * stream here means the client went away. */
typedef struct client_watch {
  struct MHD_Connection *conn;
  int fd;
  int wake[2]; /* a pipe: watch_stop writes, so the watcher leaves poll at once */
  bool running;
  atomic_int gone;
  pthread_t thread;
} client_watch;

static void *watch_main(void *arg) {
  client_watch *w = arg;
  for (;;) {
    struct pollfd p[2] = {{.fd = w->fd, .events = POLLRDHUP}, {.fd = w->wake[0], .events = POLLIN}};
    int n = poll(p, 2, -1);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 || p[1].revents) break; /* stopped: the handler is done */
    if (p[0].revents & (POLLRDHUP | POLLHUP | POLLERR | POLLNVAL)) {
      atomic_store(&w->gone, 1);
      break;
    }
  }
  return NULL;
}

/* http_req.watch_client: start the watch once per request. */
static const atomic_int *watch_start(http_req *r) {
  client_watch *w = r->watch_ctx;
  if (w->running) return &w->gone;
  const union MHD_ConnectionInfo *ci = MHD_get_connection_info(w->conn, MHD_CONNECTION_INFO_CONNECTION_FD);
  if (!ci) return NULL;
  w->fd = ci->connect_fd;
  atomic_init(&w->gone, 0);
  if (pipe2(w->wake, O_CLOEXEC) != 0) return NULL;
  w->running = pthread_create(&w->thread, NULL, watch_main, w) == 0;
  if (!w->running) {
    close(w->wake[0]);
    close(w->wake[1]);
    return NULL;
  }
  return &w->gone;
}

static void watch_stop(client_watch *w) {
  if (!w->running) return;
  char c = 1;
  while (write(w->wake[1], &c, 1) < 0 && errno == EINTR) {}
  pthread_join(w->thread, NULL);
  close(w->wake[0]);
  close(w->wake[1]);
  w->running = false;
}

static enum MHD_Result dispatch(struct MHD_Connection *c, conn *cn, const char *url, const char *method) {
  const http_route *rt = cn->route;
  if (cn->too_large) {
    char detail[200];
    snprintf(detail, sizeof detail, "request body exceeds the limit of %zu bytes (--max-body)",
             cn->srv->max_body);
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
      .svc = cn->srv->svc,
      .method = method,
      .path = url,
      .params = {cn->params[0], cn->params[1], cn->params[2]},
      .q_match = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "match"),
      .q_class = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "class"),
      .q_force = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "force"),
      .q_variant = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "variant"),
      .content_type = ct,
      .accept = header(c, MHD_HTTP_HEADER_ACCEPT),
      .if_match = header(c, MHD_HTTP_HEADER_IF_MATCH),
      .idempotency_key = header(c, "Idempotency-Key"),
      .last_event_id = header(c, MHD_HTTP_HEADER_LAST_EVENT_ID),
      .body = body,
      .body_len = len,
      .resp = {.status = 500},
  };
  client_watch w = {.conn = c};
  r.watch_client = watch_start;
  r.watch_ctx = &w;
  rt->handler(&r);
  watch_stop(&w);
  return send_resp(c, cn, &r);
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url, const char *method,
                                  const char *version, const char *upload_data, size_t *upload_data_size,
                                  void **con_cls) {
  (void)version;
  http_server *srv = cls;
  conn *cn = *con_cls;
  if (!cn) {
    cn = calloc(1, sizeof *cn);
    if (!cn) return MHD_NO;
    cn->srv = srv;
    *con_cls = cn;
    enum MHD_Result ret = MHD_YES;
    first_checks(c, cn, url, method, &ret);
    cn->seen_first = true;
    return ret;
  }
  if (cn->answered || cn->has_early) { /* answered already: drop any body */
    if (*upload_data_size) {
      *upload_data_size = 0;
      return MHD_YES;
    }
    if (cn->answered) return MHD_YES;
    http_req r = {.svc = srv->svc, .resp = cn->early};
    cn->has_early = false;
    return send_resp(c, cn, &r);
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
  (void)cls, (void)c, (void)toe;
  conn *cn = *con_cls;
  if (!cn) return;
  if (cn->has_early) http_resp_clear(&cn->early);
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
  atomic_init(&srv->stopping, false);
  atomic_init(&srv->stop_deadline_ms, 0);
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
    free(srv->token);
    free(srv);
    return rsw_fail(
        err, RSW_ERR_IO, "--listen", "cannot listen on %s:%d: %s%s", host, opts->port, strerror(e),
        e == EADDRINUSE ? " (another process, perhaps another raysweepd, has this port: stop it, or give "
                          "another port, e.g. --listen 127.0.0.1:0 for any free one)"
                        : "");
  }

  unsigned flags =
      MHD_USE_THREAD_PER_CONNECTION | MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_POLL | MHD_USE_ERROR_LOG;
  pthread_condattr_t ca;
  pthread_condattr_init(&ca);
  pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
  pthread_mutex_init(&srv->lock, NULL);
  pthread_cond_init(&srv->streams_done, &ca);
  pthread_condattr_destroy(&ca);
  /* The logger goes first so that it sees the other options' messages. */
  srv->mhd =
      MHD_start_daemon(flags, 0, NULL, NULL, on_request, srv, MHD_OPTION_EXTERNAL_LOGGER, on_log, NULL,
                       MHD_OPTION_LISTEN_SOCKET, fd, MHD_OPTION_NOTIFY_COMPLETED, on_completed, srv,
                       MHD_OPTION_CONNECTION_LIMIT, opts->max_connections ? opts->max_connections : 256u,
                       MHD_OPTION_CONNECTION_TIMEOUT, (unsigned)CONNECTION_TIMEOUT_S, MHD_OPTION_END);
  if (!srv->mhd) {
    pthread_cond_destroy(&srv->streams_done);
    pthread_mutex_destroy(&srv->lock);
    close(fd);
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

void http_server_stop(http_server *srv) {
  if (!srv) return;
  int64_t deadline = now_ms() + SSE_GRACE_MS;
  atomic_store(&srv->stop_deadline_ms, deadline);
  atomic_store(&srv->stopping, true);
  /* Event streams end with their job's `end` event (the service cancelled
   * the jobs) or at the deadline (their next poll). Wait for them before
   * MHD shuts every socket down, or clients would lose the `end`. */
  struct timespec until = {.tv_sec = (time_t)((deadline + SSE_POLL_MS) / 1000),
                           .tv_nsec = (long)((deadline + SSE_POLL_MS) % 1000) * 1000000L};
  pthread_mutex_lock(&srv->lock);
  while (srv->n_streams > 0)
    if (pthread_cond_timedwait(&srv->streams_done, &srv->lock, &until) == ETIMEDOUT) break;
  pthread_mutex_unlock(&srv->lock);
  /* Joins every connection thread; renders return once the service was
   * shut down. */
  MHD_stop_daemon(srv->mhd);
  pthread_cond_destroy(&srv->streams_done);
  pthread_mutex_destroy(&srv->lock);
  free(srv->token);
  free(srv);
}
