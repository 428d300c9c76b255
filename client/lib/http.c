/* HTTP transport of libraysweep: the one file of the client that includes
 * curl/curl.h.
 *
 * Each rsw_client owns one easy handle. curl_easy_reset() between requests
 * clears the options but keeps the connection cache, so consecutive calls
 * reuse one keep-alive connection to the daemon. */
#include <curl/curl.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>

#include "internal.h"
#include "raysweep/version.h"

/* curl_global_init once per process: it is not thread-safe on every curl
 * build, and rsw_client_new promises to be. */
static pthread_once_t global_once = PTHREAD_ONCE_INIT;
static CURLcode global_rc = CURLE_OK;
static void global_init(void) {
  global_rc = curl_global_init(CURL_GLOBAL_DEFAULT);
}

rsw_status http_client_init(rsw_client *c) {
  pthread_once(&global_once, global_init);
  if (global_rc != CURLE_OK)
    return client_fail(c, RSW_ERR_UNAVAILABLE, "libcurl initialisation failed: %s",
                       curl_easy_strerror(global_rc));
  c->curl = curl_easy_init();
  if (!c->curl) return client_fail(c, RSW_ERR_NOMEM, "libcurl: cannot create an easy handle");
  return RSW_OK;
}

void http_client_cleanup(rsw_client *c) {
  if (c->curl) curl_easy_cleanup(c->curl);
  c->curl = NULL;
}

void http_resp_free(http_resp *r) {
  free(r->body);
  memset(r, 0, sizeof *r);
}

/* ---- buffers and callbacks --------------------------------------------------- */

typedef struct body_buf {
  char *p;
  size_t len, cap;
  bool too_big;
} body_buf;

static bool buf_append(body_buf *b, const char *data, size_t n) {
  if (b->len + n + 1 > CLIENT_MAX_BODY) {
    b->too_big = true;
    return false;
  }
  if (b->len + n + 1 > b->cap) {
    size_t cap = b->cap ? b->cap : 4096;
    while (cap < b->len + n + 1) cap *= 2;
    char *p = realloc(b->p, cap);
    if (!p) return false;
    b->p = p;
    b->cap = cap;
  }
  memcpy(b->p + b->len, data, n);
  b->len += n;
  b->p[b->len] = '\0';
  return true;
}

static size_t on_body(char *data, size_t size, size_t nmemb, void *user) {
  size_t n = size * nmemb;
  return buf_append(user, data, n) ? n : 0;
}

typedef struct hdr_state {
  char etag[80];
  char content_type[128];
  size_t bytes; /* header bytes received (progress for the stall limit) */
} hdr_state;

/* Copy the value of "Name: value\r\n" into out when the name matches. */
static void header_value(const char *line, size_t n, const char *name, char *out, size_t cap) {
  size_t k = strlen(name);
  if (n <= k + 1 || strncasecmp(line, name, k) != 0 || line[k] != ':') return;
  const char *v = line + k + 1;
  const char *end = line + n;
  while (v < end && (*v == ' ' || *v == '\t')) v++;
  while (end > v && (end[-1] == '\r' || end[-1] == '\n' || end[-1] == ' ')) end--;
  size_t len = (size_t)(end - v);
  if (len >= cap) len = cap - 1;
  memcpy(out, v, len);
  out[len] = '\0';
}

static size_t on_header(char *data, size_t size, size_t nmemb, void *user) {
  size_t n = size * nmemb;
  hdr_state *h = user;
  size_t seen = h->bytes + n;
  /* A new status line (after a 100 Continue or a redirect) starts afresh. */
  if (n >= 5 && strncmp(data, "HTTP/", 5) == 0) memset(h, 0, sizeof *h);
  h->bytes = seen;
  header_value(data, n, "ETag", h->etag, sizeof h->etag);
  header_value(data, n, "Content-Type", h->content_type, sizeof h->content_type);
  return n;
}

/* ---- one exchange ------------------------------------------------------------ */

/* The low-speed limit: progress is any byte sent or received (headers
 * included); none for stall_s seconds aborts the transfer. */
typedef struct stall_watch {
  rsw_client *c;
  double stall_s; /* <= 0: no limit */
  bool computed;  /* exempt until the answer starts (http_req.computed) */
  const hdr_state *hdr;
  curl_off_t last; /* bytes moved at the last progress */
  double last_t;   /* when */
  bool stalled;    /* aborted by the limit */
} stall_watch;

typedef struct exchange {
  struct curl_slist *headers;
  char errbuf[CURL_ERROR_SIZE];
  hdr_state hdr;
  stall_watch watch;
} exchange;

static double mono_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static bool add_header(exchange *x, const char *fmt, const char *value) {
  char line[1200];
  int n = snprintf(line, sizeof line, fmt, value);
  if (n < 0 || (size_t)n >= sizeof line) return false;
  struct curl_slist *l = curl_slist_append(x->headers, line);
  if (!l) return false;
  x->headers = l;
  return true;
}

/* libcurl calls this often during a transfer and about once a second while
 * idle: a non-zero answer aborts the transfer (CURLE_ABORTED_BY_CALLBACK). */
static int on_xferinfo(void *user, curl_off_t dltotal, curl_off_t dlnow, curl_off_t ultotal,
                       curl_off_t ulnow) {
  (void)dltotal, (void)ultotal;
  stall_watch *w = user;
  if (client_interrupted(w->c)) return 1;
  if (w->stall_s <= 0) return 0;
  double now = mono_s();
  curl_off_t moved = dlnow + ulnow + (curl_off_t)w->hdr->bytes;
  if (moved != w->last || w->last_t == 0) {
    w->last = moved;
    w->last_t = now;
    return 0;
  }
  /* A computed answer: the daemon works before it sends a byte. */
  if (w->computed && w->hdr->bytes == 0 && dlnow == 0) {
    w->last_t = now;
    return 0;
  }
  if (now - w->last_t < w->stall_s) return 0;
  w->stalled = true;
  return 1;
}

/* Set every option of one request on the (reset) handle. */
static rsw_status setup(rsw_client *c, const http_req *q, exchange *x, char *url, size_t url_cap) {
  CURL *h = c->curl;
  curl_easy_reset(h);
  int n = snprintf(url, url_cap, "%s%s", c->base_url, q->path);
  if (n < 0 || (size_t)n >= url_cap)
    return client_fail(c, RSW_ERR_INVALID, "URL too long: %s%s", c->base_url, q->path);
  bool ok = add_header(x, "Accept: %s", q->accept ? q->accept : "application/json");
  if (c->token) ok = ok && add_header(x, "Authorization: Bearer %s", c->token);
  /* The balancer's consistent-hash key (docker/haproxy, docker/nginx). */
  if (c->route) ok = ok && add_header(x, "X-Raysweep-Shard: %s", c->route);
  if (q->content_type) ok = ok && add_header(x, "Content-Type: %s", q->content_type);
  if (q->if_match) ok = ok && add_header(x, "If-Match: %s", q->if_match);
  if (q->idempotency_key) ok = ok && add_header(x, "Idempotency-Key: %s", q->idempotency_key);
  if (q->last_event_id) ok = ok && add_header(x, "Last-Event-ID: %s", q->last_event_id);
  /* No "Expect: 100-continue" round trip before large uploads. */
  ok = ok && add_header(x, "Expect:%s", "");
  if (!ok)
    return client_fail(c, RSW_ERR_NOMEM, "cannot build the request headers of %s %s", q->method, q->path);

  curl_easy_setopt(h, CURLOPT_URL, url);
  curl_easy_setopt(h, CURLOPT_HTTPHEADER, x->headers);
  curl_easy_setopt(h, CURLOPT_ERRORBUFFER, x->errbuf);
  curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(h, CURLOPT_USERAGENT, "libraysweep/" RSW_VERSION);
  curl_easy_setopt(h, CURLOPT_CONNECTTIMEOUT_MS, (long)(c->connect_timeout_s * 1000.0));
  curl_easy_setopt(h, CURLOPT_HEADERFUNCTION, on_header);
  curl_easy_setopt(h, CURLOPT_HEADERDATA, &x->hdr);
  /* Interruption and the low-speed limit (stall_watch). */
  x->watch = (stall_watch){.c = c, .stall_s = c->stall_timeout_s, .computed = q->computed, .hdr = &x->hdr};
  curl_easy_setopt(h, CURLOPT_XFERINFOFUNCTION, on_xferinfo);
  curl_easy_setopt(h, CURLOPT_XFERINFODATA, &x->watch);
  curl_easy_setopt(h, CURLOPT_NOPROGRESS, 0L);
  /* A peer that went away without a word (a dead host, a dropped route)
   * is noticed by keep-alive probes within about a minute, also while a
   * computed answer is exempt from the stall limit. */
  curl_easy_setopt(h, CURLOPT_TCP_KEEPALIVE, 1L);
  curl_easy_setopt(h, CURLOPT_TCP_KEEPIDLE, 30L);
  curl_easy_setopt(h, CURLOPT_TCP_KEEPINTVL, 10L);
  /* The daemon's routes are plain http on a known host: no proxy from the
   * environment should sit between a client and its local daemon. Users
   * with a proxy set it explicitly in the base URL's host. */
  curl_easy_setopt(h, CURLOPT_NOPROXY, "127.0.0.1,localhost,::1");
  if (strcmp(q->method, "HEAD") == 0) {
    curl_easy_setopt(h, CURLOPT_NOBODY, 1L);
  } else if (strcmp(q->method, "GET") != 0) {
    if (strcmp(q->method, "POST") != 0) curl_easy_setopt(h, CURLOPT_CUSTOMREQUEST, q->method);
    if (q->body || strcmp(q->method, "POST") == 0 || strcmp(q->method, "PUT") == 0 ||
        strcmp(q->method, "PATCH") == 0) {
      curl_easy_setopt(h, CURLOPT_POSTFIELDSIZE_LARGE, (curl_off_t)q->body_len);
      curl_easy_setopt(h, CURLOPT_POSTFIELDS, q->body ? (const char *)q->body : "");
    }
  }
  return RSW_OK;
}

/* Connection-level failures that are worth another try: nothing reached
 * the server's handlers (or the answer never came back). */
static bool retryable_curl(CURLcode rc) {
  return rc == CURLE_COULDNT_CONNECT || rc == CURLE_COULDNT_RESOLVE_HOST || rc == CURLE_GOT_NOTHING ||
         rc == CURLE_SEND_ERROR || rc == CURLE_RECV_ERROR;
}

static rsw_status curl_failure(rsw_client *c, CURLcode rc, const exchange *x, const char *url,
                               const http_req *q) {
  const char *detail = x->errbuf[0] ? x->errbuf : curl_easy_strerror(rc);
  if (rc == CURLE_OPERATION_TIMEDOUT)
    return client_fail(c, RSW_ERR_TIMEOUT, "%s %s: no complete answer in time (%s)", q->method, url, detail);
  if (rc == CURLE_COULDNT_CONNECT || rc == CURLE_COULDNT_RESOLVE_HOST)
    return client_fail(c, RSW_ERR_UNAVAILABLE,
                       "cannot connect to raysweepd at %s (%s); is the daemon running?", c->base_url, detail);
  if (rc == CURLE_OUT_OF_MEMORY) return client_fail(c, RSW_ERR_NOMEM, "%s %s: out of memory", q->method, url);
  if (rc == CURLE_URL_MALFORMAT || rc == CURLE_UNSUPPORTED_PROTOCOL)
    return client_fail(c, RSW_ERR_INVALID, "bad server URL %s (%s)", url, detail);
  return client_fail(c, RSW_ERR_UNAVAILABLE, "%s %s: connection failed (%s)", q->method, url, detail);
}

rsw_status http_request(rsw_client *c, const http_req *q, http_resp *r) {
  client_clear_error(c);
  memset(r, 0, sizeof *r);
  double backoff = c->retry_backoff_s;
  for (int attempt = 0;; attempt++) {
    if (client_interrupted(c)) return client_fail_interrupted(c, q->path);
    exchange x = {0};
    char url[2048];
    body_buf b = {0};
    rsw_status s = setup(c, q, &x, url, sizeof url);
    if (s) {
      curl_slist_free_all(x.headers);
      return s;
    }
    curl_easy_setopt(c->curl, CURLOPT_WRITEFUNCTION, on_body);
    curl_easy_setopt(c->curl, CURLOPT_WRITEDATA, &b);
    double whole = c->timeout_s;
    if (q->deadline_s > 0 && (whole <= 0 || q->deadline_s < whole)) whole = q->deadline_s;
    if (whole > 0) curl_easy_setopt(c->curl, CURLOPT_TIMEOUT_MS, (long)(whole * 1000.0));
    CURLcode rc = curl_easy_perform(c->curl);
    curl_slist_free_all(x.headers);
    long status = 0;
    curl_off_t retry_after = -1;
    if (rc == CURLE_OK) {
      curl_easy_getinfo(c->curl, CURLINFO_RESPONSE_CODE, &status);
      curl_easy_getinfo(c->curl, CURLINFO_RETRY_AFTER, &retry_after);
    }
    bool again =
        attempt < c->max_retries && (rc == CURLE_OK ? (status == 429 || status == 503) : retryable_curl(rc));
    if (again) {
      free(b.p);
      /* Retry-After (seconds) wins over our own schedule; capped so a
       * confused server cannot park the client for hours. */
      double wait = retry_after > 0 ? (double)retry_after : backoff;
      if (wait > 60.0) wait = 60.0;
      client_sleep_s(c, wait);
      backoff *= 2.0;
      continue;
    }
    if (rc != CURLE_OK) {
      free(b.p);
      if (rc == CURLE_ABORTED_BY_CALLBACK && x.watch.stalled)
        return client_fail(c, RSW_ERR_TIMEOUT,
                           "%s %s: no progress for %g s: the server stalled (the low-speed limit, "
                           "RAYSWEEP_STALL_TIMEOUT / rsw_client_opts.stall_timeout_s)",
                           q->method, url, x.watch.stall_s);
      if (rc == CURLE_ABORTED_BY_CALLBACK) return client_fail_interrupted(c, q->path);
      if (rc == CURLE_OPERATION_TIMEDOUT && whole > 0)
        return client_fail(c, RSW_ERR_TIMEOUT, "%s %s: no complete answer within %g s (%s)", q->method, url,
                           whole, x.errbuf[0] ? x.errbuf : curl_easy_strerror(rc));
      if (rc == CURLE_WRITE_ERROR && b.too_big)
        return client_fail(c, RSW_ERR_LIMIT, "%s %s: answer larger than %zu bytes", q->method, url,
                           (size_t)CLIENT_MAX_BODY);
      return curl_failure(c, rc, &x, url, q);
    }
    if (status < 200 || status > 299) {
      char what[2200];
      snprintf(what, sizeof what, "%s %s", q->method, url);
      s = client_fail_http(c, status, b.p ? b.p : "", b.len, what);
      free(b.p);
      return s;
    }
    if (!b.p) { /* an empty body: still a string */
      b.p = calloc(1, 1);
      if (!b.p) return client_fail(c, RSW_ERR_NOMEM, "out of memory");
    }
    r->status = status;
    r->body = b.p;
    r->len = b.len;
    snprintf(r->etag, sizeof r->etag, "%s", x.hdr.etag);
    snprintf(r->content_type, sizeof r->content_type, "%s", x.hdr.content_type);
    return RSW_OK;
  }
}

/* ---- server-sent events -------------------------------------------------------- */

typedef struct stream_state {
  rsw_client *c;
  long status; /* 0 until known */
  bool is_stream;
  body_buf err_body; /* the body of an error answer */
  body_buf line;     /* the line being assembled */
  http_line_fn on_line;
  void *user;
  bool stopped;
  bool overflow;
} stream_state;

static size_t on_stream(char *data, size_t size, size_t nmemb, void *user) {
  size_t n = size * nmemb;
  stream_state *st = user;
  if (!st->status) {
    curl_easy_getinfo(st->c->curl, CURLINFO_RESPONSE_CODE, &st->status);
    const char *ct = NULL;
    curl_easy_getinfo(st->c->curl, CURLINFO_CONTENT_TYPE, &ct);
    st->is_stream = ct && strncasecmp(ct, "text/event-stream", 17) == 0;
  }
  if (st->status < 200 || st->status > 299 || !st->is_stream) {
    /* An error answer (kept for its problem) or not a stream at all. */
    if (st->status >= 200 && st->status <= 299) return 0;
    return buf_append(&st->err_body, data, n) ? n : 0;
  }
  for (size_t i = 0; i < n; i++) {
    char ch = data[i];
    if (ch == '\n') {
      size_t len = st->line.len;
      if (len && st->line.p[len - 1] == '\r') len--;
      int stop = st->on_line(st->user, st->line.p ? st->line.p : "", len);
      st->line.len = 0;
      if (st->line.p) st->line.p[0] = '\0';
      if (stop) {
        st->stopped = true;
        return 0; /* CURLE_WRITE_ERROR ends the transfer */
      }
    } else if (st->line.len >= CLIENT_MAX_SSE_EVENT || !buf_append(&st->line, &ch, 1)) {
      st->overflow = true;
      return 0;
    }
  }
  return n;
}

rsw_status http_stream(rsw_client *c, const http_req *q, double timeout_s, http_line_fn on_line, void *user,
                       bool *stopped, bool *not_a_stream) {
  client_clear_error(c);
  *stopped = false;
  *not_a_stream = false;
  if (client_interrupted(c)) return client_fail_interrupted(c, q->path);
  exchange x = {0};
  char url[2048];
  rsw_status s = setup(c, q, &x, url, sizeof url);
  if (s) {
    curl_slist_free_all(x.headers);
    return s;
  }
  x.watch.stall_s = 0; /* the low-speed check below instead */
  stream_state st = {.c = c, .on_line = on_line, .user = user};
  curl_easy_setopt(c->curl, CURLOPT_WRITEFUNCTION, on_stream);
  curl_easy_setopt(c->curl, CURLOPT_WRITEDATA, &st);
  /* The client's whole-request timeout does not apply to a stream that
   * lives as long as the job; the caller's wait limit does. The daemon
   * sends a ": ping" comment every 15 s, so 45 s without a byte means the
   * connection is dead: drop it and let the caller reconnect. */
  if (timeout_s > 0) curl_easy_setopt(c->curl, CURLOPT_TIMEOUT_MS, (long)(timeout_s * 1000.0) + 1);
  curl_easy_setopt(c->curl, CURLOPT_LOW_SPEED_LIMIT, 1L);
  curl_easy_setopt(c->curl, CURLOPT_LOW_SPEED_TIME, 45L);
  CURLcode rc = curl_easy_perform(c->curl);
  curl_slist_free_all(x.headers);
  free(st.line.p);
  if (st.stopped) {
    free(st.err_body.p);
    *stopped = true;
    return RSW_OK;
  }
  long status = st.status;
  if (!status && rc == CURLE_OK) curl_easy_getinfo(c->curl, CURLINFO_RESPONSE_CODE, &status);
  if (status && (status < 200 || status > 299)) {
    s = client_fail_http(c, status, st.err_body.p ? st.err_body.p : "", st.err_body.len, url);
    free(st.err_body.p);
    return s;
  }
  free(st.err_body.p);
  if (status && !st.is_stream) {
    *not_a_stream = true;
    return client_fail(c, RSW_ERR_PARSE, "GET %s: the answer is not text/event-stream", url);
  }
  if (st.overflow)
    return client_fail(c, RSW_ERR_LIMIT, "GET %s: an event line over %zu bytes", url,
                       (size_t)CLIENT_MAX_SSE_EVENT);
  if (rc == CURLE_OK) return RSW_OK;
  if (rc == CURLE_ABORTED_BY_CALLBACK) return client_fail_interrupted(c, q->path);
  if (rc == CURLE_OPERATION_TIMEDOUT && timeout_s > 0)
    return client_fail(c, RSW_ERR_TIMEOUT, "GET %s: wait limit of %.3g s reached", url, timeout_s);
  return curl_failure(c, rc == CURLE_OPERATION_TIMEDOUT ? CURLE_RECV_ERROR : rc, &x, url, q);
}
