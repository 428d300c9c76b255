/* Growable buffers of the service layer (buf.h). */
#include "buf.h"

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

svc_buf svc_buf_make(size_t limit) {
  return (svc_buf){.limit = limit ? limit : SIZE_MAX / 2};
}

/* Room for `extra` more bytes and a NUL. */
static bool reserve(svc_buf *b, size_t extra) {
  if (b->failed) return false;
  if (!b->limit) b->limit = SIZE_MAX / 2;
  if (extra > b->limit - b->n) {
    b->failed = true;
    return false;
  }
  size_t need = b->n + extra + 1;
  if (need <= b->cap) return true;
  size_t cap = b->cap ? b->cap : 256;
  while (cap < need) cap = cap > SIZE_MAX / 4 ? need : 2 * cap;
  char *p = realloc(b->p, cap);
  if (!p) {
    b->failed = true;
    return false;
  }
  b->p = p;
  b->cap = cap;
  return true;
}

bool svc_buf_append(svc_buf *b, const void *data, size_t len) {
  if (!reserve(b, len)) return false;
  if (len) memcpy(b->p + b->n, data, len);
  b->n += len;
  b->p[b->n] = '\0';
  return true;
}

bool svc_buf_printf(svc_buf *b, const char *fmt, ...) {
  if (b->failed) return false;
  va_list ap;
  va_start(ap, fmt);
  int w = vsnprintf(b->p ? b->p + b->n : NULL, b->p ? b->cap - b->n : 0, fmt, ap);
  va_end(ap);
  if (w < 0) {
    b->failed = true;
    return false;
  }
  if (b->p && (size_t)w < b->cap - b->n) {
    if ((size_t)w > b->limit - b->n) {
      b->p[b->n] = '\0';
      b->failed = true;
      return false;
    }
    b->n += (size_t)w;
    return true;
  }
  if (!reserve(b, (size_t)w)) return false;
  va_start(ap, fmt);
  vsnprintf(b->p + b->n, b->cap - b->n, fmt, ap);
  va_end(ap);
  b->n += (size_t)w;
  return true;
}

char *svc_buf_take(svc_buf *b) {
  char *p = NULL;
  if (!b->failed)
    p = b->p ? b->p : calloc(1, 1);
  else
    free(b->p);
  size_t limit = b->limit;
  *b = (svc_buf){.limit = limit};
  return p;
}

void svc_buf_free(svc_buf *b) {
  free(b->p);
  size_t limit = b->limit;
  *b = (svc_buf){.limit = limit};
}

bool svc_grow(void **arr, size_t *cap, size_t need, size_t elem, size_t limit) {
  if (need <= *cap) return true;
  if (limit && need > limit) return false;
  size_t c = *cap ? *cap : 8;
  while (c < need) c *= 2;
  if (limit && c > limit) c = limit;
  if (c > SIZE_MAX / elem) return false;
  void *p = realloc(*arr, c * elem);
  if (!p) return false;
  *arr = p;
  *cap = c;
  return true;
}
