/* raysweep status codes: the one list shared by the kernel, the daemon and
 * libraysweep.
 *
 * Generated from a single X-macro list so that the enum, the message table and
 * the HTTP mapping can never drift apart. The list is append-only: a code's
 * number never changes and is never reused. RSW_OK is 0.
 *
 * This header depends on nothing and compiles as C11 and as C++. */
#ifndef RAYSWEEP_STATUS_H
#define RAYSWEEP_STATUS_H

#ifdef __cplusplus
extern "C" {
#endif

/* X(name, message, http_status) */
#define RSW_STATUS_LIST(X)                                                                                   \
  X(RSW_OK, "success", 200)                                                                                  \
  X(RSW_ERR_NOMEM, "out of memory", 500)                                                                     \
  X(RSW_ERR_IO, "input/output error", 500)                                                                   \
  X(RSW_ERR_PARSE, "malformed document", 400)                                                                \
  X(RSW_ERR_INVALID, "invalid value", 422)                                                                   \
  X(RSW_ERR_UNKNOWN_PLUGIN, "unknown plugin", 422)                                                           \
  X(RSW_ERR_UNUSED_PROPERTY, "unused property", 422)                                                         \
  X(RSW_ERR_TYPE, "wrong property type", 422)                                                                \
  X(RSW_ERR_MISSING, "missing required property", 422)                                                       \
  X(RSW_ERR_DANGLING_REF, "reference to an unknown id", 422)                                                 \
  X(RSW_ERR_DUPLICATE, "duplicate key or id", 422)                                                           \
  X(RSW_ERR_NOT_FOUND, "not found", 404)                                                                     \
  X(RSW_ERR_FILE, "cannot read referenced file", 422)                                                        \
  X(RSW_ERR_UNSUPPORTED, "unsupported feature", 422)                                                         \
  X(RSW_ERR_LIMIT, "limit exceeded", 422)                                                                    \
  X(RSW_ERR_EMBREE, "ray-tracing backend error", 500)                                                        \
  X(RSW_ERR_RENDER, "render failed", 500)                                                                    \
  X(RSW_ERR_USAGE, "invalid command-line usage", 400)                                                        \
  X(RSW_ERR_CYCLE, "reference cycle", 422)                                                                   \
  X(RSW_ERR_RANGE, "value out of range", 422)                                                                \
  X(RSW_ERR_TIMEOUT, "deadline exceeded", 504)                                                               \
  X(RSW_ERR_CANCELLED, "cancelled", 409)                                                                     \
  X(RSW_ERR_CONFLICT, "conflict with the current state", 409)                                                \
  X(RSW_ERR_PRECONDITION, "precondition failed (stale revision)", 412)                                       \
  X(RSW_ERR_BUSY, "too many queued jobs", 429)                                                               \
  X(RSW_ERR_UNAVAILABLE, "service unavailable", 503)                                                         \
  X(RSW_ERR_MEDIA_TYPE, "unsupported media type", 415)                                                       \
  X(RSW_ERR_NOT_ACCEPTABLE, "no acceptable representation", 406)                                             \
  X(RSW_ERR_UNAUTHORIZED, "authentication required", 401)                                                    \
  X(RSW_ERR_METHOD, "method not allowed", 405)                                                               \
  X(RSW_ERR_TOO_LARGE, "request body too large", 413)                                                        \
  X(RSW_ERR_UNKNOWN_NAME, "names nothing in the scene", 422)                                                 \
  X(RSW_ERR_BAD_REQUEST, "invalid request parameter", 400)                                                   \
  X(RSW_ERR_EVICTED, "scene evicted from memory; post it again", 404)                                        \
  X(RSW_ERR_STORAGE, "result storage full", 507)                                                             \
  X(RSW_ERR_STATE_DIR, "the state directory cannot take writes", 507)

typedef enum rsw_status {
#define RSW_STATUS_ENUM_(name, msg, http) name,
  RSW_STATUS_LIST(RSW_STATUS_ENUM_)
#undef RSW_STATUS_ENUM_
  RSW_STATUS_COUNT_
} rsw_status;

/* Static English message for a status; never NULL (unknown codes give
 * "unknown status"). Thread-safe. */
const char *rsw_strerror(rsw_status status);

/* Symbolic name ("RSW_ERR_PARSE") of a status; never NULL. Thread-safe. */
const char *rsw_status_name(rsw_status status);

/* HTTP status that a daemon answers with for this status. Thread-safe. */
int rsw_status_http(rsw_status status);

#ifdef __cplusplus
}
#endif
#endif
