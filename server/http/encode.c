/* Encoders of the HTTP layer (see encode.h). No microhttpd here: these are
 * plain functions over bytes so a unit test can exercise them directly. */
#include "encode.h"

#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "film_io.h"
#include "image_png.h"

/* ---- growable text buffer ------------------------------------------------ */

static bool buf_reserve(http_buf *b, size_t extra) {
  if (b->failed) return false;
  size_t max = b->max ? b->max : HTTP_BUF_MAX;
  if (extra > max || b->len + 1 > max - extra) {
    b->failed = true;
    return false;
  }
  size_t need = b->len + extra + 1;
  if (need <= b->cap) return true;
  size_t cap = b->cap ? b->cap : 256;
  while (cap < need) cap = cap > max / 2 ? max : cap * 2;
  char *q = realloc(b->p, cap);
  if (!q) {
    b->failed = true;
    return false;
  }
  b->p = q;
  b->cap = cap;
  return true;
}

void http_buf_append(http_buf *b, const char *s, size_t n) {
  if (!buf_reserve(b, n)) return;
  memcpy(b->p + b->len, s, n);
  b->len += n;
  b->p[b->len] = '\0';
}

void http_buf_puts(http_buf *b, const char *s) {
  http_buf_append(b, s, strlen(s));
}

void http_buf_printf(http_buf *b, const char *fmt, ...) {
  char small[256];
  va_list ap;
  va_start(ap, fmt);
  int n = vsnprintf(small, sizeof small, fmt, ap);
  va_end(ap);
  if (n < 0) {
    b->failed = true;
    return;
  }
  if ((size_t)n < sizeof small) {
    http_buf_append(b, small, (size_t)n);
    return;
  }
  if (!buf_reserve(b, (size_t)n)) return;
  va_start(ap, fmt);
  vsnprintf(b->p + b->len, (size_t)n + 1, fmt, ap);
  va_end(ap);
  b->len += (size_t)n;
}

/* Length of the well-formed UTF-8 sequence at s (RFC 3629: no overlong
 * forms, no surrogates, nothing above U+10FFFF), or 0 when it is not one. */
static size_t utf8_seq_len(const unsigned char *s) {
  unsigned char c = s[0];
  size_t n;
  unsigned lo = 0x80, hi = 0xBF; /* allowed range of the second byte */
  if (c >= 0xC2 && c <= 0xDF)
    n = 2;
  else if (c >= 0xE0 && c <= 0xEF) {
    n = 3;
    if (c == 0xE0) lo = 0xA0;
    if (c == 0xED) hi = 0x9F;
  } else if (c >= 0xF0 && c <= 0xF4) {
    n = 4;
    if (c == 0xF0) lo = 0x90;
    if (c == 0xF4) hi = 0x8F;
  } else
    return 0;
  if (s[1] < lo || s[1] > hi) return 0;
  for (size_t i = 2; i < n; i++)
    if (s[i] < 0x80 || s[i] > 0xBF) return 0;
  return n;
}

void http_buf_json_string(http_buf *b, const char *s) {
  http_buf_append(b, "\"", 1);
  const char *run = s;
  while (*s) {
    unsigned char ch = (unsigned char)*s;
    if (ch >= 0x20 && ch < 0x80 && ch != '"' && ch != '\\') {
      s++;
      continue;
    }
    if (ch >= 0x80) {
      size_t n = utf8_seq_len((const unsigned char *)s);
      if (n) {
        s += n;
        continue;
      }
    }
    http_buf_append(b, run, (size_t)(s - run));
    char esc[8];
    switch (ch) {
    case '"': http_buf_append(b, "\\\"", 2); break;
    case '\\': http_buf_append(b, "\\\\", 2); break;
    case '\n': http_buf_append(b, "\\n", 2); break;
    case '\r': http_buf_append(b, "\\r", 2); break;
    case '\t': http_buf_append(b, "\\t", 2); break;
    default:
      /* A control character, or a byte that starts no well-formed UTF-8
       * sequence (a client's raw key echoed in a detail): U+FFFD, so the
       * body stays valid UTF-8 JSON whatever the input was. */
      if (ch >= 0x80)
        http_buf_append(b, "\\ufffd", 6);
      else {
        snprintf(esc, sizeof esc, "\\u%04x", ch);
        http_buf_append(b, esc, 6);
      }
    }
    s++;
    run = s;
  }
  http_buf_append(b, run, (size_t)(s - run));
  http_buf_append(b, "\"", 1);
}

char *http_buf_take(http_buf *b, size_t *len_out) {
  if (b->failed || (!b->p && !buf_reserve(b, 0))) {
    http_buf_free(b);
    return NULL;
  }
  char *p = b->p;
  if (len_out) *len_out = b->len;
  b->p = NULL;
  b->len = b->cap = 0;
  return p;
}

void http_buf_free(http_buf *b) {
  free(b->p);
  b->p = NULL;
  b->len = b->cap = 0;
  b->failed = false;
}

/* ---- films ----------------------------------------------------------------- */

static rsw_status check_film(const svc_film *f, const char *what, rsw_err *err) {
  const film_image *im = f ? &f->img : NULL;
  if (!im || im->width < 1 || im->height < 1 || im->channels < 1 || im->channels > FILM_MAX_CHANNELS ||
      !im->data)
    return rsw_fail(err, RSW_ERR_INVALID, what, "film has no pixels");
  for (int c = 0; c < im->channels; c++)
    if (!im->channel_names[c]) return rsw_fail(err, RSW_ERR_INVALID, what, "film channel %d has no name", c);
  return RSW_OK;
}

/* Every channel of the film: radiance, then the planes' (render.h). */
static size_t film_samples(const film_image *im) {
  return (size_t)im->width * (size_t)im->height * (size_t)im->channels * (size_t)(1 + im->n_planes);
}

/* The film's samples, all channels interleaved (film_image_all_channels's
 * order): the film's own data when it has no planes (*owned NULL), else a
 * malloc'ed copy in *owned. NULL when out of memory. */
static const float *film_all(const film_image *im, float **owned) {
  *owned = NULL;
  if (!im->n_planes) return im->data;
  *owned = film_image_interleaved(im);
  return *owned;
}

rsw_status http_film_json(const svc_film *f, char **bytes_out, size_t *len_out, rsw_err *err) {
  rsw_status s = check_film(f, "film JSON", err);
  if (s) return s;
  const film_image *im = &f->img;
  float *owned;
  const float *all = film_all(im, &owned);
  size_t n = film_samples(im);
  if (!all) return rsw_fail(err, RSW_ERR_NOMEM, "film JSON", "no memory for %zu samples", n);
  const char *names[FILM_MAX_CHANNELS * (1 + FILM_MAX_PLANES)];
  int nc = film_image_all_channels(im, names);
  http_buf b = {0};
  http_buf_printf(&b, "{\"width\":%d,\"height\":%d,\"channels\":[", im->width, im->height);
  for (int c = 0; c < nc; c++) {
    if (c) http_buf_append(&b, ",", 1);
    http_buf_json_string(&b, names[c]);
  }
  http_buf_puts(&b, "],\"layout\":\"HWC\",\"data\":[");
  /* Reserve roughly what the samples take, so the loop rarely reallocates. */
  uint64_t nonfinite = 0; /* written as null, and counted in the meta */
  if (buf_reserve(&b, n * 12)) {
    for (size_t i = 0; i < n && !b.failed; i++) {
      float v = all[i];
      char num[32];
      nonfinite += !isfinite(v);
      int k = isfinite(v) ? snprintf(num, sizeof num, "%.9g", (double)v) : snprintf(num, sizeof num, "null");
      if (i) http_buf_append(&b, ",", 1);
      http_buf_append(&b, num, (size_t)k);
    }
  }
  http_buf_puts(&b, "],\"meta\":{\"scene\":");
  http_buf_json_string(&b, f->scene);
  http_buf_printf(&b, ",\"revision\":%llu,\"context\":", (unsigned long long)f->revision);
  if (f->context[0])
    http_buf_json_string(&b, f->context);
  else
    http_buf_puts(&b, "null");
  http_buf_puts(&b, ",\"sensor\":");
  http_buf_json_string(&b, f->sensor);
  http_buf_printf(&b, ",\"variant\":\"%s\",\"wavelength\":", variant_name(im->variant, im->polarized));
  if (im->variant == VARIANT_MONO && isfinite(im->wavelength))
    http_buf_printf(&b, "%.17g", im->wavelength);
  else
    http_buf_puts(&b, "null");
  http_buf_printf(&b, ",\"spp\":%u,\"seed\":%llu", im->spp, (unsigned long long)im->seed);
  if (im->angles) {
    /* Distant-family films: each pixel's viewing zenith and azimuth in
     * degrees (Eradiate's east-right convention), row-major. */
    size_t np = (size_t)im->width * (size_t)im->height;
    for (int k = 0; k < 2 && !b.failed; k++) {
      http_buf_puts(&b, k ? "],\"azimuth_deg\":[" : ",\"zenith_deg\":[");
      size_t len = 0;
      char *list = film_angle_list(im->angles, np, k, &len); /* the EXR's list, "%.9g" joined by ',' */
      if (list)
        http_buf_append(&b, list, len);
      else
        b.failed = true;
      free(list);
    }
    http_buf_puts(&b, "]");
  }
  /* Only when non-zero: rays that could not be resolved (UNRESOLVED_WHY). */
  if (im->unresolved_rays)
    http_buf_printf(&b, ",\"unresolved_rays\":%llu", (unsigned long long)im->unresolved_rays);
  /* Only when non-zero: environment plugin answers replaced by black, and
   * the first one's message. */
  if (im->plugin_failures) {
    http_buf_printf(&b,
                    ",\"plugin_failures\":%llu,\"plugin_failure\":", (unsigned long long)im->plugin_failures);
    http_buf_json_string(&b, im->plugin_failure);
  }
  /* Only when non-zero: values that are inf or NaN (null in "data"). */
  if (nonfinite) http_buf_printf(&b, ",\"nonfinite\":%llu", (unsigned long long)nonfinite);
  /* The instruction set the batched shading ran (core/isa.h), when known. */
  if (im->isa) http_buf_printf(&b, ",\"isa\":\"%s\"", im->isa);
  /* Films with planes: what each is (its channels are "<name>.<channel>"),
   * and for brdf / brf the horizontal irradiance they divide by. */
  if (im->n_planes) {
    http_buf_puts(&b, ",\"planes\":[");
    for (int p = 0; p < im->n_planes; p++) {
      http_buf_printf(&b, "%s{\"name\":", p ? "," : "");
      http_buf_json_string(&b, im->planes[p].name);
      http_buf_puts(&b, ",\"units\":");
      http_buf_json_string(&b, im->planes[p].units);
      http_buf_puts(&b, ",\"long_name\":");
      http_buf_json_string(&b, im->planes[p].long_name);
      http_buf_puts(&b, "}");
    }
    http_buf_puts(&b, "]");
  }
  if (im->has_irradiance) {
    http_buf_puts(&b, ",\"irradiance\":[");
    for (int c = 0; c < im->channels; c++) http_buf_printf(&b, "%s%.17g", c ? "," : "", im->irradiance[c]);
    http_buf_puts(&b, "]");
  }
  /* One directional emitter: its zenith and azimuth (Eradiate's
   * convention), the dataset's sza and saa. */
  if (im->has_sun)
    http_buf_printf(&b, ",\"sun_zenith_deg\":%.9g,\"sun_azimuth_deg\":%.9g", im->sun_zenith, im->sun_azimuth);
  http_buf_puts(&b, "}}");
  free(owned);
  size_t len = 0;
  char *text = http_buf_take(&b, &len);
  if (!text) return rsw_fail(err, RSW_ERR_NOMEM, "film JSON", "no memory for %zu samples as JSON", n);
  *bytes_out = text;
  *len_out = len;
  return RSW_OK;
}

rsw_status http_film_npy(const svc_film *f, void **bytes_out, size_t *len_out, rsw_err *err) {
  rsw_status s = check_film(f, "film NPY", err);
  if (s) return s;
  const film_image *im = &f->img;
  char dict[128];
  int dn = snprintf(dict, sizeof dict, "{'descr': '<f4', 'fortran_order': False, 'shape': (%d, %d, %d), }",
                    im->height, im->width, im->channels * (1 + im->n_planes));
  /* 10 bytes of preamble (magic 6, version 2, header length 2), then the
   * dict, spaces, '\n', to a multiple of 64 (numpy's ARRAY_ALIGN). */
  size_t header = 10 + (size_t)dn + 1;
  header = (header + 63) / 64 * 64;
  size_t n = film_samples(im);
  size_t len = header + n * 4;
  float *owned;
  const float *all = film_all(im, &owned);
  uint8_t *p = all ? malloc(len) : NULL;
  if (!p) {
    free(owned);
    return rsw_fail(err, RSW_ERR_NOMEM, "film NPY", "no memory for %zu bytes", len);
  }
  memcpy(p, "\x93NUMPY\x01\x00", 8);
  size_t hlen = header - 10;
  p[8] = (uint8_t)(hlen & 0xff);
  p[9] = (uint8_t)(hlen >> 8);
  memcpy(p + 10, dict, (size_t)dn);
  memset(p + 10 + dn, ' ', header - 10 - (size_t)dn - 1);
  p[header - 1] = '\n';
  uint8_t *d = p + header;
  for (size_t i = 0; i < n; i++) { /* little-endian whatever the host */
    uint32_t u;
    memcpy(&u, &all[i], 4);
    d[4 * i + 0] = (uint8_t)u;
    d[4 * i + 1] = (uint8_t)(u >> 8);
    d[4 * i + 2] = (uint8_t)(u >> 16);
    d[4 * i + 3] = (uint8_t)(u >> 24);
  }
  free(owned);
  *bytes_out = p;
  *len_out = len;
  return RSW_OK;
}

rsw_status http_film_exr(const svc_film *f, void **bytes_out, size_t *len_out, rsw_err *err) {
  rsw_status s = check_film(f, "film EXR", err);
  if (s) return s;
  const film_image *im = &f->img;
  /* The attributes raysweepd render writes, plus what the JSON meta adds. */
  film_exr_info info = film_image_exr_info(im, f->sensor);
  info.scene = f->scene;
  info.has_revision = true;
  info.revision = f->revision;
  info.context = f->context;
  info.has_sun = im->has_sun; /* the meta's sun_zenith_deg, sun_azimuth_deg */
  info.sun_zenith = im->sun_zenith, info.sun_azimuth = im->sun_azimuth;
  float *owned;
  const float *all = film_all(im, &owned);
  if (!all) return rsw_fail(err, RSW_ERR_NOMEM, "film EXR", "out of memory");
  const char *names[FILM_MAX_CHANNELS * (1 + FILM_MAX_PLANES)];
  int nc = film_image_all_channels(im, names);
  s = film_exr_encode(im->width, im->height, nc, names, all, false, &info, bytes_out, len_out, err);
  free(owned);
  return s;
}

rsw_status http_film_png(const svc_film *f, const png_look *look, void **bytes_out, size_t *len_out,
                         rsw_err *err) {
  rsw_status s = check_film(f, "film PNG", err);
  if (s) return s;
  const film_image *im = &f->img;
  return png_encode_film(im->width, im->height, im->channels, im->channel_names, im->data, look, bytes_out,
                         len_out, err);
}

/* ---- problem+json ---------------------------------------------------------- */

/* Reason phrases (RFC 9110) and the machine codes the HTTP layer uses for
 * errors of its own: the phrase in upper snake case. */
static const struct {
  int status;
  const char *reason, *code;
} statuses[] = {
    {200, "OK", "OK"},
    {201, "Created", "CREATED"},
    {202, "Accepted", "ACCEPTED"},
    {204, "No Content", "NO_CONTENT"},
    {400, "Bad Request", "BAD_REQUEST"},
    {401, "Unauthorized", "UNAUTHORIZED"},
    {403, "Forbidden", "FORBIDDEN"},
    {404, "Not Found", "NOT_FOUND"},
    {405, "Method Not Allowed", "METHOD_NOT_ALLOWED"},
    {406, "Not Acceptable", "NOT_ACCEPTABLE"},
    {409, "Conflict", "CONFLICT"},
    {410, "Gone", "GONE"},
    {412, "Precondition Failed", "PRECONDITION_FAILED"},
    {413, "Content Too Large", "CONTENT_TOO_LARGE"},
    {414, "URI Too Long", "URI_TOO_LONG"},
    {415, "Unsupported Media Type", "UNSUPPORTED_MEDIA_TYPE"},
    {422, "Unprocessable Content", "UNPROCESSABLE_CONTENT"},
    {429, "Too Many Requests", "TOO_MANY_REQUESTS"},
    {431, "Request Header Fields Too Large", "REQUEST_HEADER_FIELDS_TOO_LARGE"},
    {500, "Internal Server Error", "INTERNAL_SERVER_ERROR"},
    {501, "Not Implemented", "NOT_IMPLEMENTED"},
    {503, "Service Unavailable", "SERVICE_UNAVAILABLE"},
    {504, "Gateway Timeout", "GATEWAY_TIMEOUT"},
    {507, "Insufficient Storage", "INSUFFICIENT_STORAGE"},
};

const char *http_reason(int status) {
  for (size_t i = 0; i < sizeof statuses / sizeof statuses[0]; i++)
    if (statuses[i].status == status) return statuses[i].reason;
  return "Error";
}

const char *http_status_code(int status) {
  for (size_t i = 0; i < sizeof statuses / sizeof statuses[0]; i++)
    if (statuses[i].status == status) return statuses[i].code;
  return "ERROR";
}

static char *problem_json(int status, const char *code, const char *title, const char *detail,
                          const char *pointer, const char *key, const char *const *candidates,
                          size_t n_candidates) {
  http_buf b = {0};
  if (!code) code = http_status_code(status);
  http_buf_puts(&b, "{\"type\":\"https://raysweep.dev/problems/");
  /* code is an identifier ([A-Z0-9_]); escape anyway, minus the quotes */
  http_buf tmp = {0};
  http_buf_json_string(&tmp, code);
  if (tmp.p) http_buf_append(&b, tmp.p + 1, tmp.len - 2);
  http_buf_free(&tmp);
  http_buf_puts(&b, "\",\"title\":");
  http_buf_json_string(&b, title);
  http_buf_printf(&b, ",\"status\":%d,\"detail\":", status);
  http_buf_json_string(&b, detail ? detail : "");
  http_buf_puts(&b, ",\"code\":");
  http_buf_json_string(&b, code);
  if (pointer && pointer[0]) {
    http_buf_puts(&b, ",\"pointer\":");
    http_buf_json_string(&b, pointer);
  }
  if (key && key[0]) {
    http_buf_puts(&b, ",\"key\":");
    http_buf_json_string(&b, key);
  }
  bool any = false;
  for (size_t i = 0; candidates && i < n_candidates; i++) {
    if (!candidates[i] || !candidates[i][0]) continue;
    http_buf_puts(&b, any ? "," : ",\"candidates\":[");
    http_buf_json_string(&b, candidates[i]);
    any = true;
  }
  if (any) http_buf_puts(&b, "]");
  http_buf_puts(&b, "}");
  return http_buf_take(&b, NULL);
}

char *http_problem_json(int status, const char *code, const char *detail, const char *pointer,
                        const char *key, const char *const *candidates, size_t n_candidates) {
  return problem_json(status, code, http_reason(status), detail, pointer, key, candidates, n_candidates);
}

/* Is where a place in a document: a JSON pointer ("/shapes/0") or
 * "file:line[:column]"? (Other where strings, such as a digest or a key,
 * stay in the detail only.) */
static bool is_place(const char *where) {
  if (where[0] == '/') return true;
  const char *colon = strchr(where, ':');
  return colon && colon != where && colon[1] >= '0' && colon[1] <= '9';
}

char *http_problem_from_svc(const svc_error *e, int *status_out) {
  int status = rsw_status_http(e->err.code);
  if (status < 400 || status > 599) status = 500; /* an error must not read as success */
  char detail[1200];
  if (e->err.msg[0])
    rsw_err_format(&e->err, detail, sizeof detail);
  else
    snprintf(detail, sizeof detail, "%s", rsw_strerror(e->err.code));
  /* Scene errors come as "scene.json#/a/b": the pointer is after '#'. */
  const char *hash = strchr(e->err.where, '#');
  const char *pointer = hash && hash[1] == '/' ? hash + 1 : is_place(e->err.where) ? e->err.where : NULL;
  const char *cands[3] = {e->candidates[0], e->candidates[1], e->candidates[2]};
  *status_out = status;
  /* The title belongs to the problem type (the code), not to the case. */
  return problem_json(status, rsw_status_name(e->err.code), rsw_strerror(e->err.code), detail, pointer,
                      e->key, cands, 3);
}

/* ---- request helpers ------------------------------------------------------- */

const char *http_film_content_type(http_film_format f) {
  switch (f) {
  case HTTP_FILM_EXR: return "image/x-exr";
  case HTTP_FILM_NPY: return "application/x-npy";
  case HTTP_FILM_PNG: return "image/png";
  case HTTP_FILM_JSON: return "application/json";
  default: return NULL;
  }
}

/* One media range of an Accept header: type/subtype (lower-cased, at most
 * 63 bytes) and whether a q=0 parameter excludes it. */
typedef struct media_range {
  char type[64];
  bool excluded;
} media_range;

/* Parse the range starting at *s (up to the next ',' outside quotes); moves
 * *s past it. */
static void next_range(const char **s, media_range *r) {
  const char *p = *s;
  size_t n = 0;
  while (*p == ' ' || *p == '\t') p++;
  while (*p && *p != ',' && *p != ';' && *p != ' ' && *p != '\t') {
    if (n + 1 < sizeof r->type) r->type[n++] = (char)((*p >= 'A' && *p <= 'Z') ? *p + 32 : *p);
    p++;
  }
  r->type[n] = '\0';
  r->excluded = false;
  while (*p && *p != ',') { /* parameters: look for q */
    if (*p == ';') {
      p++;
      while (*p == ' ' || *p == '\t') p++;
      if ((p[0] == 'q' || p[0] == 'Q') && p[1] == '=') {
        char *end;
        double q = strtod(p + 2, &end);
        if (end != p + 2 && q <= 0) r->excluded = true;
        p = end != p + 2 ? end : p + 2;
      }
      continue;
    }
    if (*p == '"') { /* quoted parameter value: skip to its end */
      for (p++; *p && *p != '"'; p++)
        if (*p == '\\' && p[1]) p++;
      if (*p) p++;
      continue;
    }
    p++;
  }
  if (*p == ',') p++;
  *s = p;
}

bool http_accepts(const char *accept, const char *type) {
  if (!accept) return true;
  const char *p = accept;
  while (*p == ' ' || *p == '\t') p++;
  if (!*p) return true;
  char major[64];
  size_t ml = strcspn(type, "/");
  snprintf(major, sizeof major, "%.*s/*", (int)ml, type);
  bool exact = false, exact_excluded = false, wild = false;
  for (int guard = 0; *p && guard < 256; guard++) {
    media_range r;
    next_range(&p, &r);
    if (!r.type[0]) continue;
    if (strcmp(r.type, type) == 0) {
      if (r.excluded)
        exact_excluded = true;
      else
        exact = true;
    } else if (!r.excluded && (strcmp(r.type, "*/*") == 0 || strcmp(r.type, major) == 0)) {
      wild = true;
    }
  }
  return !exact_excluded && (exact || wild);
}

http_film_format http_accept_film(const char *accept) {
  static const struct {
    const char *type;
    http_film_format fmt;
  } exact[] = {
      {"application/json", HTTP_FILM_JSON},
      {"image/x-exr", HTTP_FILM_EXR},
      {"application/x-npy", HTTP_FILM_NPY},
      {"image/png", HTTP_FILM_PNG},
  };
  enum {
    N_EXACT = sizeof exact / sizeof exact[0]
  };
  if (!accept) return HTTP_FILM_JSON;
  const char *p = accept;
  while (*p == ' ' || *p == '\t') p++;
  if (!*p) return HTTP_FILM_JSON;

  bool excluded[N_EXACT] = {false};
  http_film_format first_exact = HTTP_FILM_NONE;
  bool any_wild = false, app_wild = false, image_wild = false;
  for (int guard = 0; *p && guard < 256; guard++) {
    media_range r;
    next_range(&p, &r);
    if (!r.type[0]) continue;
    for (size_t i = 0; i < N_EXACT; i++)
      if (strcmp(r.type, exact[i].type) == 0) {
        if (r.excluded)
          excluded[i] = true;
        else if (first_exact == HTTP_FILM_NONE)
          first_exact = exact[i].fmt;
      }
    if (r.excluded) continue;
    if (strcmp(r.type, "*/*") == 0) any_wild = true;
    if (strcmp(r.type, "application/*") == 0) app_wild = true;
    if (strcmp(r.type, "image/*") == 0) image_wild = true;
  }
  /* A later "type;q=0" may exclude an earlier exact listing of the same type. */
  for (size_t i = 0; i < N_EXACT; i++)
    if (first_exact == exact[i].fmt && excluded[i]) first_exact = HTTP_FILM_NONE;
  if (first_exact != HTTP_FILM_NONE) return first_exact;
  for (size_t i = 0; i < N_EXACT; i++) {
    if (excluded[i]) continue;
    bool is_app = strncmp(exact[i].type, "application/", 12) == 0;
    if (any_wild || (app_wild && is_app) || (image_wild && !is_app)) return exact[i].fmt;
  }
  return HTTP_FILM_NONE;
}

bool http_json_depth_ok(const char *body, size_t len, int max_depth) {
  int depth = 0;
  bool in_string = false;
  for (size_t i = 0; i < len; i++) {
    char c = body[i];
    if (in_string) {
      if (c == '\\')
        i++; /* the escaped character cannot end the string */
      else if (c == '"')
        in_string = false;
      continue;
    }
    if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > max_depth) return false;
    } else if ((c == ']' || c == '}') && depth > 0) {
      depth--;
    }
  }
  return true;
}

bool http_media_type_is(const char *content_type, const char *type) {
  if (!content_type) return false;
  while (*content_type == ' ' || *content_type == '\t') content_type++;
  size_t n = strlen(type);
  if (strncasecmp(content_type, type, n) != 0) return false;
  const char *rest = content_type + n;
  while (*rest == ' ' || *rest == '\t') rest++;
  return *rest == '\0' || *rest == ';';
}
