/* Encoders and request-header helpers of the HTTP layer that need no
 * microhttpd types, so tests/http/test_http_encode.c can check them alone:
 * a growable text buffer with a hard cap, JSON string escaping, films as
 * JSON / NPY / EXR, problem+json bodies, Accept negotiation and the JSON
 * nesting-depth scan. Every function is thread-safe (no shared state). */
#ifndef RSW_HTTP_ENCODE_H
#define RSW_HTTP_ENCODE_H

#include <stdbool.h>
#include <stddef.h>

#include "../service/service.h"
#include "image_png.h"
#include "rsw_error.h"

/* ---- growable text buffer ------------------------------------------------
 * Always NUL-terminated once anything is appended; on allocation failure or
 * when the cap would be passed it sets failed and ignores further appends,
 * so callers check once at the end. */
typedef struct http_buf {
  char *p;
  size_t len, cap;
  size_t max; /* hard cap in bytes (0: HTTP_BUF_MAX) */
  bool failed;
} http_buf;

#define HTTP_BUF_MAX ((size_t)1 << 31)

void http_buf_append(http_buf *b, const char *s, size_t n);
void http_buf_puts(http_buf *b, const char *s);
void http_buf_printf(http_buf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* A JSON string literal (quotes included) of s: escapes '"', '\\' and
 * control characters; well-formed UTF-8 passes through and every byte that
 * starts no well-formed sequence becomes \ufffd, so the result is valid
 * UTF-8 JSON for any input. */
void http_buf_json_string(http_buf *b, const char *s);
/* Hand the text over (malloc'ed, NUL-terminated; caller frees) and reset b;
 * NULL when the buffer failed (then its memory is released). */
char *http_buf_take(http_buf *b, size_t *len_out);
void http_buf_free(http_buf *b);

/* ---- films ----------------------------------------------------------------
 * All three borrow f and return malloc'ed bytes (*bytes_out, free()) and
 * their length; outputs are written only on success. */

/* {"width", "height", "channels": [...], "layout": "HWC", "data": [...],
 *  "meta": {scene, revision, context, sensor, wavelength, spp, seed}}.
 * A film with planes (render.h) lists their channels after the radiance
 * ones ("brf.Y", "radiance_stderr.Y") and its meta adds "planes" ([{name,
 * units, long_name}]) and, with brdf or brf, "irradiance" (E_h per
 * radiance channel); the .npy and EXR encodings carry the same channels
 * in the same order.
 * Samples print with 9 significant digits (round-trips float32); NaN and
 * infinities, which JSON cannot hold, print as null. context is null for a
 * synchronous render (empty f->context). */
rsw_status http_film_json(const svc_film *f, char **bytes_out, size_t *len_out, rsw_err *err);

/* NumPy .npy format 1.0: magic "\x93NUMPY", version 1.0, a little-endian
 * uint16 header length, then the header dict
 *   {'descr': '<f4', 'fortran_order': False, 'shape': (H, W, C), }
 * padded with spaces and ended by '\n' so that the data starts at a
 * multiple of 64 bytes (as numpy.lib.format writes it), then H*W*C
 * little-endian float32 in C order (HWC). */
rsw_status http_film_npy(const svc_film *f, void **bytes_out, size_t *len_out, rsw_err *err);

/* Float32 OpenEXR (always float32, whatever the film asked for) with the
 * film's context as the "raysweep:" string attributes of film_io.h (scene,
 * revision, context, sensor, spp, seed, variant, wavelength_nm in mono,
 * zenith_deg and azimuth_deg for distant-family sensors): those of
 * raysweepd render -o plus scene, revision and context. */
rsw_status http_film_exr(const svc_film *f, void **bytes_out, size_t *len_out, rsw_err *err);

/* A tone-mapped 8-bit quick-look of the film's radiance (image_png.h;
 * look may be NULL: exposure 0, grey). */
rsw_status http_film_png(const svc_film *f, const png_look *look, void **bytes_out, size_t *len_out,
                         rsw_err *err);

/* ---- problem+json ----------------------------------------------------------
 * RFC 9457 body: {"type": "https://raysweep.dev/problems/<code>", "title":
 * the status's reason phrase, "status", "detail", "code" (NULL: the status's
 * http_status_code), and when given
 * "pointer", "key", "candidates"}. pointer, key may be NULL or "";
 * candidates is NULL or n_candidates strings (empty ones skipped).
 * Returns malloc'ed text or NULL when out of memory. */
char *http_problem_json(int status, const char *code, const char *detail, const char *pointer,
                        const char *key, const char *const *candidates, size_t n_candidates);
/* The same from a service error: status is rsw_status_http(e->err.code)
 * (the status table decides, include/raysweep/status.h); code is the status name (RSW_ERR_...)
 * and title its message (rsw_strerror: "unknown plugin");
 * detail is "where: message"; pointer is err.where when it names a place
 * in the document (a JSON pointer "/..." or "file:line"). *status_out
 * receives the status. */
char *http_problem_from_svc(const svc_error *e, int *status_out);
/* Reason phrase of an HTTP status ("Not Found"); "Error" when unknown. */
const char *http_reason(int status);
/* The machine code of an HTTP-layer error: the reason phrase in upper
 * snake case ("NOT_FOUND", "CONTENT_TOO_LARGE"); "ERROR" when unknown. */
const char *http_status_code(int status);

/* ---- request helpers ------------------------------------------------------- */

typedef enum http_film_format {
  HTTP_FILM_NONE = 0, /* nothing acceptable: 406 */
  HTTP_FILM_JSON,
  HTTP_FILM_EXR,
  HTTP_FILM_NPY,
  HTTP_FILM_PNG,
} http_film_format;

/* Pick a film representation from an Accept header value (NULL or empty:
 * JSON). Exact media types are preferred over ranges in the client's
 * order; "*" + "/" + "*" and "application/" + "*" give JSON (or the first of
 * JSON, EXR, NPY, PNG not excluded), "image/" + "*" gives EXR. q-values are
 * ignored except q=0, which excludes a type. */
http_film_format http_accept_film(const char *accept);
/* Whether an Accept header value (NULL or empty: anything) allows the one
 * media type `type` ("application/x-netcdf"): listed, or matched by
 * "*" + "/" + "*" or its major type's wildcard, and not excluded by q=0. */
bool http_accepts(const char *accept, const char *type);
const char *http_film_content_type(http_film_format f);

/* True when the JSON text nests arrays/objects at most max_depth deep
 * (brackets inside strings do not count). Does not validate the JSON. */
bool http_json_depth_ok(const char *body, size_t len, int max_depth);

/* Media type of a Content-Type value without parameters, compared
 * case-insensitively with type ("application/json; charset=utf-8"
 * matches "application/json"). */
bool http_media_type_is(const char *content_type, const char *type);

#endif
