/* The service's growable memory: one byte buffer with a cap (documents it
 * builds: metrics text, event payloads) and one array-growth helper that
 * never loses the array when an allocation fails (the `p = realloc(p, n)`
 * mistake). */
#ifndef RSW_SERVICE_BUF_H
#define RSW_SERVICE_BUF_H

#include <stdbool.h>
#include <stddef.h>

typedef struct svc_buf {
  char *p;      /* NUL-terminated when n > 0 */
  size_t n;     /* bytes used, without the NUL */
  size_t cap;   /* bytes allocated */
  size_t limit; /* most bytes it may hold (0: SIZE_MAX / 2) */
  bool failed;  /* an append was refused (out of memory or over limit);
                   sticky: later appends are no-ops */
} svc_buf;

/* An empty buffer that may grow to limit bytes (0: no cap of its own). */
svc_buf svc_buf_make(size_t limit);
bool svc_buf_append(svc_buf *b, const void *data, size_t len);
bool svc_buf_printf(svc_buf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* The contents as a malloc'ed NUL-terminated string, handed to the caller
 * (the buffer is left empty); NULL when any append failed (the memory is
 * freed then). */
char *svc_buf_take(svc_buf *b);
void svc_buf_free(svc_buf *b);

/* Make room for `need` elements of `elem` bytes in *arr (capacity *cap,
 * doubled as needed; at most `limit` elements, 0: no cap). On failure the
 * array and *cap are unchanged and false is returned. */
bool svc_grow(void **arr, size_t *cap, size_t need, size_t elem, size_t limit);

#endif
