/* The routes of raysweepd's HTTP API (proto/API-NOTES.md) as one const
 * table, the path matcher and the handlers. A handler translates one
 * request into one service call and its result into an http_resp; generic
 * checks (auth, 404/405, body size, media type, JSON depth) have already
 * run in server.c before any handler, as in redis' processCommand. */
#include "routes.h"

#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <time.h>
#include <unistd.h>

#include <cjson/cJSON.h>

#include "encode.h"
#include "http.h"
#include "ui.h"

/* ---- responses ----------------------------------------------------------- */

void http_resp_clear(http_resp *resp) {
  free(resp->body);
  resp->body = NULL;
  if (resp->has_fd) close(resp->fd);
  resp->has_fd = false;
  resp->len = 0;
  resp->content_type = NULL;
  resp->content_type_full[0] = '\0';
}

/* A problem body could not even be allocated: answer the status bare. */
static void resp_bare(http_req *r, int status) {
  http_resp_clear(&r->resp);
  r->resp.status = status;
}

void http_resp_json(http_req *r, int status, char *json_owned) {
  if (!json_owned) {
    http_resp_problem(r, 500, "RSW_ERR_NOMEM", "the response could not be built (out of memory)");
    return;
  }
  http_resp_clear(&r->resp);
  r->resp.status = status;
  r->resp.content_type = "application/json";
  r->resp.body = json_owned;
  r->resp.len = strlen(json_owned);
}

void http_resp_problem(http_req *r, int status, const char *code, const char *fmt, ...) {
  char detail[1024];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(detail, sizeof detail, fmt, ap);
  va_end(ap);
  char *body = http_problem_json(status, code, detail, NULL, NULL, NULL, 0);
  resp_bare(r, status);
  if (!body) return;
  r->resp.content_type = "application/problem+json";
  r->resp.body = body;
  r->resp.len = strlen(body);
}

void http_resp_svc_error(http_req *r, const svc_error *e) {
  int status = 500;
  char *body = http_problem_from_svc(e, &status);
  resp_bare(r, status);
  if (status == 429) r->resp.retry_after_s = e->retry_after_s > 0 ? e->retry_after_s : 1;
  if (!body) return;
  r->resp.content_type = "application/problem+json";
  r->resp.body = body;
  r->resp.len = strlen(body);
}

/* Answer a service call: its JSON document with ok_status, or its error. */
static void resp_result(http_req *r, rsw_status s, int ok_status, char *json, const svc_error *e) {
  if (s != RSW_OK) {
    free(json);
    http_resp_svc_error(r, e);
    return;
  }
  http_resp_json(r, ok_status, json);
}

static void resp_empty(http_req *r, int status) {
  http_resp_clear(&r->resp);
  r->resp.status = status;
}

static void set_etag(http_req *r, uint64_t revision) {
  snprintf(r->resp.etag, sizeof r->resp.etag, "\"%" PRIu64 "\"", revision);
}

/* Encode a film in the negotiated format and take ownership of nothing:
 * the caller frees f. */
static void resp_film(http_req *r, const svc_film *f, http_film_format fmt) {
  rsw_err err = {0};
  void *bytes = NULL;
  size_t len = 0;
  rsw_status s;
  if (fmt == HTTP_FILM_PNG) {
    png_look look = {.colormap = r->q_colormap};
    if (r->q_exposure) png_exposure_parse(r->q_exposure, &look); /* checked by negotiate_film */
    s = http_film_png(f, &look, &bytes, &len, &err);
    if (s == RSW_ERR_INVALID) { /* colormap for an rgb film, a film with nothing to show */
      char msg[1200];
      http_resp_problem(r, 422, rsw_status_name(s), "%s", rsw_err_format(&err, msg, sizeof msg));
      return;
    }
  } else if (fmt == HTTP_FILM_EXR)
    s = http_film_exr(f, &bytes, &len, &err);
  else if (fmt == HTTP_FILM_NPY)
    s = http_film_npy(f, &bytes, &len, &err);
  else
    s = http_film_json(f, (char **)&bytes, &len, &err);
  if (s != RSW_OK) {
    char msg[1200];
    http_resp_problem(r, 500, rsw_status_name(s), "cannot encode the film: %s",
                      rsw_err_format(&err, msg, sizeof msg));
    return;
  }
  http_resp_clear(&r->resp);
  r->resp.status = 200;
  r->resp.content_type = http_film_content_type(fmt);
  r->resp.body = bytes;
  r->resp.len = len;
}

/* ---- request pieces ------------------------------------------------------- */

/* Negotiate a film format or answer 406; false when answered. The PNG
 * look's query parameters (?exposure=EV&colormap=NAME) are checked here,
 * before any work: 400 when malformed. */
static bool negotiate_film(http_req *r, http_film_format *fmt) {
  *fmt = http_accept_film(r->accept);
  if (*fmt == HTTP_FILM_NONE) {
    http_resp_problem(
        r, 406, NULL,
        "Accept '%s' allows none of application/json, image/x-exr, application/x-npy, image/png", r->accept);
    return false;
  }
  png_look look = {0};
  if (r->q_exposure && !png_exposure_parse(r->q_exposure, &look)) {
    http_resp_problem(r, 400, NULL,
                      "query parameter exposure must be a number of stops, auto, or auto+EV (got '%s')",
                      r->q_exposure);
    return false;
  }
  if (r->q_colormap && !png_colormap_known(r->q_colormap)) {
    http_resp_problem(r, 400, NULL, "query parameter colormap must be one of %s (got '%s')",
                      png_colormap_list(), r->q_colormap);
    return false;
  }
  return true;
}

/* ?force=true|false|1|0 (absent: false); false after answering 400. */
static bool query_bool(http_req *r, const char *name, const char *v, bool *out) {
  *out = false;
  if (!v) return true;
  if (strcmp(v, "true") == 0 || strcmp(v, "1") == 0 || strcmp(v, "") == 0) {
    *out = true;
    return true;
  }
  if (strcmp(v, "false") == 0 || strcmp(v, "0") == 0) return true;
  http_resp_problem(r, 400, NULL, "query parameter %s must be true or false (got '%s')", name, v);
  return false;
}

/* ?name=one|of|these (absent: fine); false after answering 400. */
static bool query_enum(http_req *r, const char *name, const char *v, const char *const *allowed, size_t n) {
  if (!v) return true;
  for (size_t i = 0; i < n; i++)
    if (strcmp(v, allowed[i]) == 0) return true;
  char list[128] = "";
  for (size_t i = 0; i < n; i++) {
    strncat(list, i ? ", " : "", sizeof list - strlen(list) - 1);
    strncat(list, allowed[i], sizeof list - strlen(list) - 1);
  }
  http_resp_problem(r, 400, NULL, "query parameter %s must be one of %s (got '%s')", name, list, v);
  return false;
}

/* Parse an unsigned decimal that fills the whole string. */
static bool parse_u64(const char *s, size_t n, uint64_t *out) {
  if (n == 0 || n > 20) return false;
  uint64_t v = 0;
  for (size_t i = 0; i < n; i++) {
    if (s[i] < '0' || s[i] > '9') return false;
    unsigned d = (unsigned)(s[i] - '0');
    if (v > (UINT64_MAX - d) / 10) return false;
    v = v * 10 + d;
  }
  *out = v;
  return true;
}

/* If-Match: "<revision>" (quoted entity tag; W/ and bare numbers are
 * accepted too) or "*" (any). *out = -1 when absent or "*". False after
 * answering 400 on anything else. */
static bool parse_if_match(http_req *r, int64_t *out) {
  *out = -1;
  const char *v = r->if_match;
  if (!v) return true;
  while (*v == ' ' || *v == '\t') v++;
  size_t n = strlen(v);
  while (n && (v[n - 1] == ' ' || v[n - 1] == '\t')) n--;
  if (n == 1 && v[0] == '*') return true;
  if (n >= 2 && v[0] == 'W' && v[1] == '/') v += 2, n -= 2;
  if (n >= 2 && v[0] == '"' && v[n - 1] == '"') v++, n -= 2;
  uint64_t rev;
  if (!parse_u64(v, n, &rev) || rev > INT64_MAX) {
    http_resp_problem(r, 400, NULL, "If-Match must be a quoted revision number such as \"3\" (got '%s')",
                      r->if_match);
    return false;
  }
  *out = (int64_t)rev;
  return true;
}

/* ---- handlers -------------------------------------------------------------- */

static void h_info(http_req *r) {
  http_resp_json(r, 200, service_info_json(r->svc));
}

static void h_live(http_req *r) {
  http_resp_json(r, 200, strdup("{\"status\":\"live\"}"));
}

static void h_ready(http_req *r) {
  const char *why = NULL;
  if (service_accepts_jobs(r->svc, &why))
    http_resp_json(r, 200, strdup("{\"status\":\"ready\"}"));
  else
    http_resp_problem(r, 503, NULL, "%s", why);
}

static void h_metrics(http_req *r) {
  char *text = service_metrics_text(r->svc);
  if (!text) {
    http_resp_problem(r, 500, "RSW_ERR_NOMEM", "metrics could not be built (out of memory)");
    return;
  }
  http_resp_clear(&r->resp);
  r->resp.status = 200;
  r->resp.content_type = "text/plain; version=0.0.4; charset=utf-8";
  r->resp.body = text;
  r->resp.len = strlen(text);
}

static const char *const variants[] = {"mono", "rgb", "mono_polarized", "rgb_polarized"};

static void h_scene_post(http_req *r) {
  if (!query_enum(r, "variant", r->q_variant, variants, 4)) return;
  if (r->q_name && !service_scene_label_ok(r->q_name)) {
    http_resp_problem(r, 400, NULL,
                      "query parameter name must be a file name (1 to %d bytes, no '/' or control character)",
                      SVC_SCENE_LABEL_MAX);
    return;
  }
  bool is_xml = !http_media_type_is(r->content_type, "application/json");
  svc_error e = {0};
  bool created = false;
  char *id = NULL, *json = NULL;
  /* ?name=: the client's name for the document (raysweep push sends its
   * file's), which messages about its text use. */
  rsw_status s = service_scene_post_named(r->svc, r->body, r->body_len, is_xml, r->q_variant, r->q_name,
                                          &created, &id, &json, &e);
  if (s == RSW_OK && id) snprintf(r->resp.location, sizeof r->resp.location, "/v1/scenes/%s", id);
  if (s == RSW_OK && id && r->q_name) { /* the summary again, with the name */
    free(json);
    json = NULL;
    s = service_scene_label(r->svc, id, r->q_name, &json, &e);
  }
  free(id);
  resp_result(r, s, created ? 201 : 200, json, &e);
}

static void h_scene_reset(http_req *r) {
  svc_error e = {0};
  char *json = NULL;
  rsw_status s = service_scene_reset(r->svc, r->params[0], &json, &e);
  resp_result(r, s, 200, json, &e);
}

static void h_scene_copy(http_req *r) {
  svc_error e = {0};
  char *id = NULL, *json = NULL;
  rsw_status s = service_scene_copy(r->svc, r->params[0], &id, &json, &e);
  if (s == RSW_OK && id) snprintf(r->resp.location, sizeof r->resp.location, "/v1/scenes/%s", id);
  free(id);
  resp_result(r, s, 201, json, &e);
}

static void h_scene_list(http_req *r) {
  svc_error e = {0};
  char *json = NULL;
  rsw_status s = service_scene_list(r->svc, &json, &e);
  resp_result(r, s, 200, json, &e);
}

static void h_scene_get(http_req *r) {
  svc_error e = {0};
  char *json = NULL;
  rsw_status s = service_scene_get(r->svc, r->params[0], &json, &e);
  resp_result(r, s, 200, json, &e);
}

static void h_scene_delete(http_req *r) {
  bool force;
  if (!query_bool(r, "force", r->q_force, &force)) return;
  svc_error e = {0};
  if (service_scene_delete(r->svc, r->params[0], force, &e) != RSW_OK)
    http_resp_svc_error(r, &e);
  else
    resp_empty(r, 204);
}

static const char *const classes[] = {"spectral", "geometric", "none"};

static void h_params_get(http_req *r) {
  if (!query_enum(r, "class", r->q_class, classes, 3)) return;
  bool full;
  if (!query_bool(r, "full", r->q_full, &full)) return;
  svc_error e = {0};
  char *json = NULL;
  uint64_t rev = 0;
  rsw_status s = (full ? service_params_get_full : service_params_get)(
      r->svc, r->params[0], r->q_match ? r->q_match : "*", r->q_class, &json, &rev, &e);
  if (s == RSW_OK) set_etag(r, rev);
  resp_result(r, s, 200, json, &e);
}

static void h_params_patch(http_req *r) {
  int64_t if_match;
  if (!parse_if_match(r, &if_match)) return;
  svc_error e = {0};
  char *json = NULL;
  uint64_t rev = 0;
  rsw_status s = service_params_patch(r->svc, r->params[0], r->body, r->body_len, if_match, &json, &rev, &e);
  if (s == RSW_OK) set_etag(r, rev);
  resp_result(r, s, 200, json, &e);
}

static void h_render(http_req *r) {
  http_film_format fmt;
  if (!negotiate_film(r, &fmt)) return; /* before the work, not after */
  svc_error e = {0};
  svc_film f;
  memset(&f, 0, sizeof f);
  /* A client that hangs up (Ctrl-C on `raysweep render`) cancels the render. */
  const atomic_int *gone = r->watch_client ? r->watch_client(r) : NULL;
  if (service_render(r->svc, r->params[0], r->body, r->body_len, gone, &f, &e) != RSW_OK) {
    http_resp_svc_error(r, &e);
    return;
  }
  resp_film(r, &f, fmt);
  svc_film_free(&f);
}

static void h_directions(http_req *r) {
  svc_error e = {0};
  char *json = NULL;
  rsw_status s = service_directions(r->svc, r->params[0], r->params[1], &json, &e);
  resp_result(r, s, 200, json, &e);
}

static void h_job_submit(http_req *r) {
  if (r->idempotency_key) {
    size_t n = strlen(r->idempotency_key);
    if (n == 0 || n > HTTP_MAX_IDEMPOTENCY_KEY) {
      http_resp_problem(r, 400, NULL, "the Idempotency-Key header must be 1 to %d characters (got %zu)",
                        HTTP_MAX_IDEMPOTENCY_KEY, n);
      return;
    }
  }
  bool dry = false;
  if (!query_bool(r, "dry_run", r->q_dry_run, &dry)) return;
  svc_error e = {0};
  char *job = NULL, *json = NULL;
  if (dry) { /* checked and planned, not queued (an Idempotency-Key records nothing) */
    rsw_status s = service_job_check(r->svc, r->params[0], r->body, r->body_len, &json, &e);
    resp_result(r, s, 200, json, &e);
    return;
  }
  rsw_status s =
      service_job_submit(r->svc, r->params[0], r->body, r->body_len, r->idempotency_key, &job, &json, &e);
  if (s == RSW_OK && job) snprintf(r->resp.location, sizeof r->resp.location, "/v1/jobs/%s", job);
  free(job);
  resp_result(r, s, 202, json, &e);
}

static void h_job_list(http_req *r) {
  svc_error e = {0};
  char *json = NULL;
  rsw_status s = service_job_list(r->svc, &json, &e);
  resp_result(r, s, 200, json, &e);
}

static void h_job_get(http_req *r) {
  svc_error e = {0};
  char *json = NULL;
  rsw_status s = service_job_get(r->svc, r->params[0], &json, &e);
  resp_result(r, s, 200, json, &e);
}

static void h_job_delete(http_req *r) {
  svc_error e = {0};
  if (service_job_delete(r->svc, r->params[0], &e) != RSW_OK)
    http_resp_svc_error(r, &e);
  else
    resp_empty(r, 204);
}

static void h_job_cancel(http_req *r) {
  svc_error e = {0};
  char *json = NULL;
  rsw_status s = service_job_cancel(r->svc, r->params[0], &json, &e);
  resp_result(r, s, 200, json, &e);
}

/* The stream itself is server.c's: here the job must exist (404 before
 * any 200) and Last-Event-ID must be a sequence number. */
static void h_job_events(http_req *r) {
  uint64_t after = 0;
  if (r->last_event_id) {
    const char *v = r->last_event_id;
    while (*v == ' ') v++;
    size_t n = strlen(v);
    while (n && v[n - 1] == ' ') n--;
    if (n && !parse_u64(v, n, &after)) {
      http_resp_problem(r, 400, NULL, "Last-Event-ID must be an event sequence number (got '%s')",
                        r->last_event_id);
      return;
    }
  }
  svc_error e = {0};
  char *json = NULL;
  if (service_job_get(r->svc, r->params[0], &json, &e) != RSW_OK) {
    free(json);
    http_resp_svc_error(r, &e);
    return;
  }
  free(json);
  if (strlen(r->params[0]) >= sizeof r->resp.sse_job) {
    http_resp_problem(r, 404, "RSW_ERR_NOT_FOUND", "no job with an id that long");
    return;
  }
  http_resp_clear(&r->resp);
  r->resp.status = 200;
  r->resp.sse = true;
  snprintf(r->resp.sse_job, sizeof r->resp.sse_job, "%s", r->params[0]);
  r->resp.sse_after = after;
}

static void h_job_results(http_req *r) {
  svc_error e = {0};
  char *json = NULL;
  rsw_status s = service_job_results(r->svc, r->params[0], &json, &e);
  resp_result(r, s, 200, json, &e);
}

static void h_job_result(http_req *r) {
  http_film_format fmt;
  if (!negotiate_film(r, &fmt)) return;
  svc_error e = {0};
  if (r->q_band || r->q_node) { /* a job with bands: a band's film, or a node's */
    svc_film bf;
    memset(&bf, 0, sizeof bf);
    if (service_job_band_result(r->svc, r->params[0], r->params[1], r->params[2], r->q_band, r->q_node, &bf,
                                &e) != RSW_OK) {
      http_resp_svc_error(r, &e);
      return;
    }
    resp_film(r, &bf, fmt);
    svc_film_free(&bf);
    return;
  }
  if (fmt == HTTP_FILM_NPY) { /* a film on disk streams from its file */
    int fd;
    uint64_t len;
    if (service_job_result_npy_fd(r->svc, r->params[0], r->params[1], r->params[2], &fd, &len, &e) !=
        RSW_OK) {
      http_resp_svc_error(r, &e);
      return;
    }
    if (fd >= 0) {
      http_resp_clear(&r->resp);
      r->resp.status = 200;
      r->resp.content_type = http_film_content_type(fmt);
      r->resp.has_fd = true;
      r->resp.fd = fd;
      r->resp.fd_len = len;
      return;
    }
  }
  svc_film f;
  memset(&f, 0, sizeof f);
  if (service_job_result(r->svc, r->params[0], r->params[1], r->params[2], &f, &e) != RSW_OK) {
    http_resp_svc_error(r, &e);
    return;
  }
  resp_film(r, &f, fmt);
  svc_film_free(&f);
}

/* POST /v1/jobs/{id}/results:fetch {"results": [{"context", "sensor"}, ...]}:
 * several films of a job in one answer, multipart/mixed (RFC 2046), each
 * part the bytes GET .../results/{context}/{sensor} answers with the same
 * Accept (EXR or NPY), with its Content-Location and Content-Length. A
 * sweep that fetched its films one request each paid each request's own
 * cost (the balancer's, the daemon's, the client's) once per film. All or
 * nothing: a film that is not there answers as its GET would. */
#define FETCH_MAX_FILMS 256
#define FETCH_MAX_BYTES ((size_t)64 << 20)

/* s percent-encoded as one path segment (RFC 3986 unreserved kept). */
static void buf_segment(http_buf *b, const char *s) {
  for (; *s; s++) {
    unsigned char ch = (unsigned char)*s;
    if ((ch >= 'A' && ch <= 'Z') || (ch >= 'a' && ch <= 'z') || (ch >= '0' && ch <= '9') ||
        strchr("-._~", ch))
      http_buf_append(b, s, 1);
    else
      http_buf_printf(b, "%%%02X", ch);
  }
}
static bool fetch_bad(http_req *r, rsw_status code, const char *ptr, const char *msg) {
  svc_error e = {0};
  rsw_fail(&e.err, code, ptr, "%s", msg);
  http_resp_svc_error(r, &e);
  return false;
}

/* The body's (context, sensor) pairs, borrowed from *doc; false when
 * answered. */
static bool fetch_list(http_req *r, cJSON **doc, const cJSON *pairs[][2], size_t *n) {
  *doc = cJSON_ParseWithLength(r->body, r->body_len);
  if (!cJSON_IsObject(*doc)) return fetch_bad(r, RSW_ERR_PARSE, "", "the body must be a JSON object");
  for (const cJSON *k = (*doc)->child; k; k = k->next)
    if (strcmp(k->string, "results") != 0) {
      char msg[400];
      snprintf(msg, sizeof msg, "unknown field '%.300s' (expected results)", k->string);
      char ptr[310];
      snprintf(ptr, sizeof ptr, "/%.300s", k->string);
      return fetch_bad(r, RSW_ERR_UNUSED_PROPERTY, ptr, msg);
    }
  const cJSON *a = cJSON_GetObjectItemCaseSensitive(*doc, "results");
  int na = cJSON_GetArraySize(a);
  if (!cJSON_IsArray(a) || na < 1 || na > FETCH_MAX_FILMS)
    return fetch_bad(r, RSW_ERR_INVALID, "/results",
                     "results must be an array of 1 to 256 {\"context\", \"sensor\"} objects");
  *n = 0;
  for (const cJSON *x = a->child; x; x = x->next, (*n)++) {
    char ptr[40];
    snprintf(ptr, sizeof ptr, "/results/%zu", *n);
    const cJSON *c = cJSON_GetObjectItemCaseSensitive(x, "context");
    const cJSON *sn = cJSON_GetObjectItemCaseSensitive(x, "sensor");
    if (!cJSON_IsObject(x) || cJSON_GetArraySize(x) != 2 || !cJSON_IsString(c) || !cJSON_IsString(sn))
      return fetch_bad(r, RSW_ERR_INVALID, ptr,
                       "each result is {\"context\": ID, \"sensor\": ID}, nothing else");
    pairs[*n][0] = c, pairs[*n][1] = sn;
  }
  return true;
}

static void h_job_results_fetch(http_req *r) {
  http_film_format fmt = http_accept_film(r->accept);
  if (fmt != HTTP_FILM_EXR && fmt != HTTP_FILM_NPY) {
    http_resp_problem(r, 406, NULL, "Accept '%s' allows neither image/x-exr nor application/x-npy",
                      r->accept);
    return;
  }
  cJSON *doc = NULL;
  const cJSON *pairs[FETCH_MAX_FILMS][2];
  size_t n = 0;
  if (!fetch_list(r, &doc, pairs, &n)) {
    cJSON_Delete(doc);
    return;
  }
  /* The boundary: random, so that no film's bytes hold it (2^-128). */
  char boundary[48];
  unsigned char rnd[16] = {0};
  if (getrandom(rnd, sizeof rnd, 0) != (ssize_t)sizeof rnd) {
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    memcpy(rnd, &ts, sizeof ts < sizeof rnd ? sizeof ts : sizeof rnd);
  }
  int bl = snprintf(boundary, sizeof boundary, "raysweep-");
  for (int i = 0; i < 16; i++) bl += snprintf(boundary + bl, sizeof boundary - (size_t)bl, "%02x", rnd[i]);
  http_buf out = {.max = FETCH_MAX_BYTES};
  for (size_t i = 0; i < n && !out.failed; i++) { /* past the cap: stop encoding */
    svc_error e = {0};
    svc_film f;
    memset(&f, 0, sizeof f);
    const char *ctx = pairs[i][0]->valuestring, *sen = pairs[i][1]->valuestring;
    if (service_job_result(r->svc, r->params[0], ctx, sen, &f, &e) != RSW_OK) {
      http_buf_free(&out);
      cJSON_Delete(doc);
      http_resp_svc_error(r, &e);
      return;
    }
    rsw_err err = {0};
    void *bytes = NULL;
    size_t len = 0;
    rsw_status s =
        fmt == HTTP_FILM_EXR ? http_film_exr(&f, &bytes, &len, &err) : http_film_npy(&f, &bytes, &len, &err);
    svc_film_free(&f);
    if (s != RSW_OK) {
      char msg[1200];
      http_buf_free(&out);
      cJSON_Delete(doc);
      http_resp_problem(r, 500, rsw_status_name(s), "cannot encode the film: %s",
                        rsw_err_format(&err, msg, sizeof msg));
      return;
    }
    http_buf_printf(&out, "--%s\r\nContent-Type: %s\r\nContent-Location: /v1/jobs/%s/results/", boundary,
                    http_film_content_type(fmt), r->params[0]);
    buf_segment(&out, ctx);
    http_buf_puts(&out, "/");
    buf_segment(&out, sen);
    http_buf_printf(&out, "\r\nContent-Length: %zu\r\n\r\n", len);
    http_buf_append(&out, bytes, len);
    http_buf_puts(&out, "\r\n");
    free(bytes);
  }
  cJSON_Delete(doc);
  http_buf_printf(&out, "--%s--\r\n", boundary);
  size_t len = 0;
  char *body = http_buf_take(&out, &len);
  if (!body) {
    http_resp_problem(r, 413, "RSW_ERR_LIMIT",
                      "the films asked for do not fit in one answer (64 MiB): ask for fewer");
    return;
  }
  http_resp_clear(&r->resp);
  r->resp.status = 200;
  snprintf(r->resp.content_type_full, sizeof r->resp.content_type_full, "multipart/mixed; boundary=%s",
           boundary);
  r->resp.content_type = "multipart/mixed";
  r->resp.body = body;
  r->resp.len = len;
}

/* The job as one NetCDF-4 dataset (application/x-netcdf): 409 while it
 * runs unless ?partial=1. */
static void h_job_dataset(http_req *r) {
  bool partial;
  if (!query_bool(r, "partial", r->q_partial, &partial)) return;
  if (!http_accepts(r->accept, "application/x-netcdf")) {
    http_resp_problem(r, 406, NULL, "Accept '%s' does not allow application/x-netcdf", r->accept);
    return;
  }
  svc_error e = {0};
  void *bytes = NULL;
  size_t len = 0;
  int fd;
  uint64_t fd_len = 0;
  if (service_job_dataset_file(r->svc, r->params[0], partial, &fd, &fd_len, &bytes, &len, &e) != RSW_OK) {
    http_resp_svc_error(r, &e);
    return;
  }
  http_resp_clear(&r->resp);
  r->resp.status = 200;
  r->resp.content_type = "application/x-netcdf";
  if (fd >= 0) { /* streamed from its file */
    r->resp.has_fd = true;
    r->resp.fd = fd;
    r->resp.fd_len = fd_len;
    return;
  }
  r->resp.body = bytes;
  r->resp.len = len;
}

static void h_blob_put(http_req *r) {
  svc_error e = {0};
  bool created = false;
  if (service_blob_put(r->svc, r->params[0], r->body, r->body_len, &created, &e) != RSW_OK) {
    http_resp_svc_error(r, &e);
    return;
  }
  resp_empty(r, created ? 201 : 200);
  if (created) snprintf(r->resp.location, sizeof r->resp.location, "/v1/blobs/%s", r->params[0]);
}

static void h_blob_head(http_req *r) {
  if (service_blob_exists(r->svc, r->params[0]))
    resp_empty(r, 200);
  else
    http_resp_problem(r, 404, "RSW_ERR_NOT_FOUND", "no blob %s", r->params[0]);
}

static void h_blobs_missing(http_req *r) {
  svc_error e = {0};
  char *json = NULL;
  rsw_status s = service_blobs_missing(r->svc, r->body, r->body_len, &json, &e);
  resp_result(r, s, 200, json, &e);
}

/* ---- the table ------------------------------------------------------------- */

const http_route http_routes[] = {
    {"GET", "/v1", HTTP_BODY_NONE, false, h_info, false},
    {"GET", "/v1/health/live", HTTP_BODY_NONE, true, h_live, true},
    {"GET", "/v1/health/ready", HTTP_BODY_NONE, true, h_ready, true},
    {"GET", "/metrics", HTTP_BODY_NONE, false, h_metrics, false},
    {"POST", "/v1/scenes", HTTP_BODY_SCENE, false, h_scene_post, false},
    {"GET", "/v1/scenes", HTTP_BODY_NONE, false, h_scene_list, false},
    {"GET", "/v1/scenes/{id}", HTTP_BODY_NONE, false, h_scene_get, false},
    {"DELETE", "/v1/scenes/{id}", HTTP_BODY_NONE, false, h_scene_delete, false},
    {"GET", "/v1/scenes/{id}/params", HTTP_BODY_NONE, false, h_params_get, false},
    {"PATCH", "/v1/scenes/{id}/params", HTTP_BODY_JSON, false, h_params_patch, false},
    {"POST", "/v1/scenes/{id}:render", HTTP_BODY_JSON, false, h_render, false},
    {"POST", "/v1/scenes/{id}:reset", HTTP_BODY_NONE, false, h_scene_reset, false},
    {"POST", "/v1/scenes/{id}:copy", HTTP_BODY_NONE, false, h_scene_copy, false},
    {"GET", "/v1/scenes/{id}/sensors/{sensor}/directions", HTTP_BODY_NONE, false, h_directions, false},
    {"POST", "/v1/scenes/{id}/jobs", HTTP_BODY_JSON, false, h_job_submit, false},
    {"GET", "/v1/jobs", HTTP_BODY_NONE, false, h_job_list, false},
    {"GET", "/v1/jobs/{id}", HTTP_BODY_NONE, false, h_job_get, false},
    {"DELETE", "/v1/jobs/{id}", HTTP_BODY_NONE, false, h_job_delete, false},
    {"POST", "/v1/jobs/{id}:cancel", HTTP_BODY_NONE, false, h_job_cancel, false},
    {"GET", "/v1/jobs/{id}/events", HTTP_BODY_NONE, false, h_job_events, false},
    {"GET", "/v1/jobs/{id}/results", HTTP_BODY_NONE, false, h_job_results, false},
    {"GET", "/v1/jobs/{id}/results/{context}/{sensor}", HTTP_BODY_NONE, false, h_job_result, false},
    {"POST", "/v1/jobs/{id}/results:fetch", HTTP_BODY_JSON, false, h_job_results_fetch, false},
    {"GET", "/v1/jobs/{id}/dataset", HTTP_BODY_NONE, false, h_job_dataset, false},
    {"PUT", "/v1/blobs/{sha256}", HTTP_BODY_RAW, false, h_blob_put, false},
    {"HEAD", "/v1/blobs/{sha256}", HTTP_BODY_NONE, false, h_blob_head, false},
    {"POST", "/v1/blobs:missing", HTTP_BODY_JSON, false, h_blobs_missing, false},
    {"GET", "/", HTTP_BODY_NONE, true, http_root_redirect, true},
    {"GET", "/ui", HTTP_BODY_NONE, true, http_ui_redirect, true},
    {"GET", "/ui/", HTTP_BODY_NONE, true, http_ui_index, true},
    {"GET", "/ui/{file}", HTTP_BODY_NONE, true, http_ui_file, true},
};
const size_t http_n_routes = sizeof http_routes / sizeof http_routes[0];

void http_routes_print(FILE *f) {
  for (size_t i = 0; i < http_n_routes; i++)
    fprintf(f, "%s %s\n", http_routes[i].method, http_routes[i].path);
}

/* ---- matching -------------------------------------------------------------
 * Segment by segment: a literal segment matches itself; "{name}" matches a
 * non-empty segment without ':' (so ".../{id}" never swallows a custom verb
 * like "x:cancel"); "{name}:verb" matches a segment ending in ":verb" with
 * a non-empty, ':'-free prefix. */
bool http_route_match(const char *tmpl, const char *path, char *seg_buf,
                      const char *params[HTTP_MAX_PATH_PARAMS]) {
  size_t plen = strlen(path);
  memcpy(seg_buf, path, plen + 1);
  size_t starts[HTTP_MAX_PATH_PARAMS], lens[HTTP_MAX_PATH_PARAMS];
  int np = 0;
  const char *t = tmpl;
  const char *p = seg_buf;
  while (*t) {
    if (*t != '/' || *p != '/') return false;
    t++, p++;
    size_t tl = strcspn(t, "/"), pl = strcspn(p, "/");
    if (*t == '{') {
      const char *close = memchr(t, '}', tl);
      if (!close || np == HTTP_MAX_PATH_PARAMS) return false;
      const char *verb = close + 1;
      size_t vl = (size_t)(t + tl - verb);
      if (vl && (pl <= vl || memcmp(p + pl - vl, verb, vl) != 0)) return false;
      size_t il = pl - vl;
      if (il == 0 || memchr(p, ':', il)) return false;
      starts[np] = (size_t)(p - seg_buf);
      lens[np] = il;
      np++;
    } else if (tl != pl || memcmp(t, p, tl) != 0) {
      return false;
    }
    t += tl, p += pl;
  }
  if (*p) return false;
  /* Terminate the captures only now: the scan above needed the '/'s. */
  for (int i = 0; i < np; i++) {
    seg_buf[starts[i] + lens[i]] = '\0';
    params[i] = seg_buf + starts[i];
  }
  for (int i = np; i < HTTP_MAX_PATH_PARAMS; i++) params[i] = NULL;
  return true;
}

static void allow_add(char *allow, size_t allow_len, const char *method) {
  if (!allow_len || strstr(allow, method)) return;
  if (allow[0]) strncat(allow, ", ", allow_len - strlen(allow) - 1);
  strncat(allow, method, allow_len - strlen(allow) - 1);
}

const http_route *http_route_find(const char *method, const char *path, char *seg_buf,
                                  const char *params[HTTP_MAX_PATH_PARAMS], bool *path_known, char *allow,
                                  size_t allow_len) {
  *path_known = false;
  if (allow_len) allow[0] = '\0';
  bool head = strcmp(method, "HEAD") == 0;
  const http_route *get = NULL;
  for (size_t i = 0; i < http_n_routes; i++) {
    const http_route *rt = &http_routes[i];
    if (!http_route_match(rt->path, path, seg_buf, params)) continue;
    if (strcmp(rt->method, method) == 0) return rt;
    if (head && !get && strcmp(rt->method, "GET") == 0) get = rt;
    *path_known = true;
    allow_add(allow, allow_len, rt->method);
    if (strcmp(rt->method, "GET") == 0) allow_add(allow, allow_len, "HEAD");
  }
  if (get) { /* match again: a later template may have overwritten seg_buf */
    http_route_match(get->path, path, seg_buf, params);
    *path_known = false;
    if (allow_len) allow[0] = '\0';
  }
  return get;
}
