/* libraysweep: the client handle, its last-error slot, server info and
 * health, and the small helpers the other files share. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "internal.h"

#define DEFAULT_URL "http://127.0.0.1:8350"

/* ---- helpers ------------------------------------------------------------------- */

double client_now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

bool client_interrupted(const rsw_client *c) {
  return c && c->interrupt && *c->interrupt;
}

rsw_status client_fail_interrupted(rsw_client *c, const char *what) {
  return client_fail(c, RSW_ERR_CANCELLED, "%s: interrupted", what);
}

void client_sleep_s(const rsw_client *c, double s) {
  if (!(s > 0)) return;
  struct timespec ts = {.tv_sec = (time_t)s, .tv_nsec = (long)((s - (double)(time_t)s) * 1e9)};
  /* A signal that sets the interrupt flag also ends nanosleep with EINTR. */
  while (nanosleep(&ts, &ts) != 0 && errno == EINTR)
    if (client_interrupted(c)) return;
}

bool client_escape(const char *s, char *out, size_t cap) {
  static const char hex[] = "0123456789ABCDEF";
  size_t o = 0;
  for (const unsigned char *p = (const unsigned char *)s; *p; p++) {
    bool plain = (*p >= 'A' && *p <= 'Z') || (*p >= 'a' && *p <= 'z') || (*p >= '0' && *p <= '9') ||
                 *p == '-' || *p == '.' || *p == '_' || *p == '~';
    if (o + (plain ? 1 : 3) >= cap) return false;
    if (plain) {
      out[o++] = (char)*p;
    } else {
      out[o++] = '%';
      out[o++] = hex[*p >> 4];
      out[o++] = hex[*p & 15];
    }
  }
  if (o >= cap) return false;
  out[o] = '\0';
  return true;
}

static char *dup_str(const char *s) {
  size_t n = strlen(s) + 1;
  char *p = malloc(n);
  if (p) memcpy(p, s, n);
  return p;
}

/* ---- life cycle ------------------------------------------------------------------ */

rsw_status rsw_client_new(const rsw_client_opts *opts, rsw_client **out) {
  if (!out) return RSW_ERR_INVALID;
  /* Read only the fields the caller's struct has (it may be an older,
   * smaller version of rsw_client_opts). */
  rsw_client_opts o = {0};
  if (opts) {
    size_t n = opts->size ? opts->size : sizeof o;
    if (n > sizeof o) n = sizeof o;
    memcpy(&o, opts, n);
  }
  rsw_client *c = calloc(1, sizeof *c);
  if (!c) return RSW_ERR_NOMEM;
  client_clear_error(c);
  const char *url = o.base_url && *o.base_url ? o.base_url : DEFAULT_URL;
  c->base_url = dup_str(url);
  c->token = o.token && *o.token ? dup_str(o.token) : NULL;
  if (!c->base_url || (o.token && *o.token && !c->token)) {
    rsw_client_free(c);
    return RSW_ERR_NOMEM;
  }
  size_t n = strlen(c->base_url);
  while (n && c->base_url[n - 1] == '/') c->base_url[--n] = '\0';
  if (strncmp(c->base_url, "http://", 7) != 0 && strncmp(c->base_url, "https://", 8) != 0) {
    rsw_client_free(c);
    return RSW_ERR_INVALID;
  }
  c->connect_timeout_s = o.connect_timeout_s > 0 ? o.connect_timeout_s : 10.0;
  c->timeout_s = o.timeout_s > 0 ? o.timeout_s : 0.0;
  c->stall_timeout_s = o.stall_timeout_s == 0 ? CLIENT_STALL_TIMEOUT_S : o.stall_timeout_s;
  c->max_retries = o.max_retries == 0 ? 3 : o.max_retries < 0 ? 0 : o.max_retries;
  c->retry_backoff_s = o.retry_backoff_s > 0 ? o.retry_backoff_s : 0.2;
  c->interrupt = o.interrupt;
  if (o.route_key && rsw_client_set_route(c, o.route_key)) {
    rsw_client_free(c);
    return RSW_ERR_INVALID;
  }
  rsw_status s = http_client_init(c);
  if (s) {
    rsw_client_free(c);
    return s;
  }
  *out = c;
  return RSW_OK;
}

void rsw_client_free(rsw_client *c) {
  if (!c) return;
  http_client_cleanup(c);
  free(c->base_url);
  free(c->token);
  free(c->route);
  free(c);
}

bool client_valid_route(const char *key) {
  size_t n = 0;
  for (const char *p = key; *p; p++, n++) {
    bool ok = (*p >= 'A' && *p <= 'Z') || (*p >= 'a' && *p <= 'z') || (*p >= '0' && *p <= '9') || *p == '.' ||
              *p == '_' || *p == '-';
    if (!ok) return false;
  }
  return n >= 1 && n <= 64;
}

rsw_status rsw_client_set_route(rsw_client *c, const char *key) {
  if (!c) return RSW_ERR_INVALID;
  if (key && !client_valid_route(key)) return RSW_ERR_INVALID;
  char *k = key ? dup_str(key) : NULL;
  if (key && !k) return RSW_ERR_NOMEM;
  free(c->route);
  c->route = k;
  return RSW_OK;
}

void rsw_free(void *p) {
  free(p);
}

/* ---- the last error ---------------------------------------------------------------- */

const rsw_error_info *rsw_client_last_error(const rsw_client *c) {
  static const rsw_error_info none = {.status = RSW_ERR_INVALID,
                                      .code = "RSW_ERR_INVALID",
                                      .message = "no client (NULL handle)",
                                      .pointer = "",
                                      .key = ""};
  return c ? &c->info : &none;
}

void client_clear_error(rsw_client *c) {
  c->code[0] = c->message[0] = c->pointer[0] = c->key[0] = '\0';
  for (int i = 0; i < 3; i++) c->candidates[i][0] = '\0';
  c->info = (rsw_error_info){.status = RSW_OK,
                             .http_status = 0,
                             .code = c->code,
                             .message = c->message,
                             .pointer = c->pointer,
                             .key = c->key};
}

rsw_status client_fail(rsw_client *c, rsw_status s, const char *fmt, ...) {
  client_clear_error(c);
  c->info.status = s;
  snprintf(c->code, sizeof c->code, "%s", rsw_status_name(s));
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(c->message, sizeof c->message, fmt, ap);
  va_end(ap);
  return s;
}

/* The closest status for an HTTP error whose problem names no RSW code. */
static const struct {
  long http;
  rsw_status status;
} http_map[] = {
    {400, RSW_ERR_PARSE},        {401, RSW_ERR_UNAUTHORIZED},   {404, RSW_ERR_NOT_FOUND},
    {405, RSW_ERR_METHOD},       {406, RSW_ERR_NOT_ACCEPTABLE}, {409, RSW_ERR_CONFLICT},
    {412, RSW_ERR_PRECONDITION}, {413, RSW_ERR_TOO_LARGE},      {415, RSW_ERR_MEDIA_TYPE},
    {422, RSW_ERR_INVALID},      {429, RSW_ERR_BUSY},           {503, RSW_ERR_UNAVAILABLE},
    {504, RSW_ERR_TIMEOUT},
};

rsw_status client_status_for_http(long http_status) {
  for (size_t i = 0; i < sizeof http_map / sizeof http_map[0]; i++)
    if (http_map[i].http == http_status) return http_map[i].status;
  if (http_status >= 500) return RSW_ERR_UNAVAILABLE;
  return RSW_ERR_INVALID;
}

/* rsw_status whose name is code ("RSW_ERR_NOT_FOUND"), or RSW_OK when none. */
static rsw_status status_from_name(const char *code) {
  for (int s = 1; s < RSW_STATUS_COUNT_; s++)
    if (strcmp(rsw_status_name((rsw_status)s), code) == 0) return (rsw_status)s;
  return RSW_OK;
}

static void copy_member(const cJSON *o, const char *name, char *out, size_t cap) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, name);
  if (cJSON_IsString(v)) snprintf(out, cap, "%s", v->valuestring);
}

rsw_status client_fail_http(rsw_client *c, long http_status, const char *body, size_t len, const char *what) {
  rsw_status s = client_status_for_http(http_status);
  client_clear_error(c);
  cJSON *p = len ? cJSON_ParseWithLength(body, len) : NULL;
  if (cJSON_IsObject(p)) {
    copy_member(p, "code", c->code, sizeof c->code);
    copy_member(p, "detail", c->message, sizeof c->message);
    if (!c->message[0]) copy_member(p, "title", c->message, sizeof c->message);
    copy_member(p, "pointer", c->pointer, sizeof c->pointer);
    copy_member(p, "key", c->key, sizeof c->key);
    const cJSON *cand = cJSON_GetObjectItemCaseSensitive(p, "candidates");
    int k = 0;
    const cJSON *it;
    cJSON_ArrayForEach(it, cand) {
      if (k >= 3) break;
      if (cJSON_IsString(it)) snprintf(c->candidates[k++], sizeof c->candidates[0], "%s", it->valuestring);
    }
    for (int i = 0; i < k; i++) c->info.candidates[i] = c->candidates[i];
    rsw_status named = c->code[0] ? status_from_name(c->code) : RSW_OK;
    if (named != RSW_OK) s = named;
  }
  cJSON_Delete(p);
  if (!c->code[0]) snprintf(c->code, sizeof c->code, "%s", rsw_status_name(s));
  if (!c->message[0]) {
    /* Not a problem document: keep the start of whatever came back. */
    int n = len > 200 ? 200 : (int)len;
    snprintf(c->message, sizeof c->message, "%s: HTTP %ld%s%.*s", what, http_status, n ? ": " : "", n, body);
  }
  c->info.status = s;
  c->info.http_status = (int)http_status;
  return s;
}

/* ---- plain GETs ------------------------------------------------------------------------ */

rsw_status client_get_text(rsw_client *c, const char *path, char **json_out) {
  if (!json_out) return client_fail(c, RSW_ERR_INVALID, "GET %s: json_out is NULL", path);
  http_resp r;
  rsw_status s = http_request(c, &(http_req){.method = "GET", .path = path}, &r);
  if (s) return s;
  *json_out = r.body; /* ownership moves to the caller */
  return RSW_OK;
}

rsw_status rsw_server_info(rsw_client *c, char **json_out) {
  if (!c) return RSW_ERR_INVALID;
  return client_get_text(c, "/v1", json_out);
}

rsw_status rsw_server_ready(rsw_client *c) {
  if (!c) return RSW_ERR_INVALID;
  http_resp r;
  rsw_status s = http_request(c, &(http_req){.method = "GET", .path = "/v1/health/ready"}, &r);
  if (s == RSW_OK) http_resp_free(&r);
  return s;
}
