/* Small file helpers for tests that link no test support objects
 * (tests/client, the benchmarks): header-only. */
#ifndef RSW_TEST_TFILE_H
#define RSW_TEST_TFILE_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A whole file, NUL-terminated (malloc'ed; *len its length, may be NULL),
 * or NULL when it cannot be read. */
static inline char *tfile_read(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  char *buf = malloc((size_t)(n > 0 ? n : 0) + 1);
  size_t got = buf && n > 0 ? fread(buf, 1, (size_t)n, f) : 0;
  fclose(f);
  if (!buf || (n > 0 && got != (size_t)n)) {
    free(buf);
    return NULL;
  }
  buf[got] = '\0';
  if (len) *len = got;
  return buf;
}

/* A "<field>: N kB" line of /proc/self/status (VmRSS, VmHWM, RssAnon...)
 * in bytes; 0 when there is none. */
static inline size_t tfile_proc_status_bytes(const char *field) {
  FILE *f = fopen("/proc/self/status", "r");
  size_t kb = 0, n = strlen(field);
  char line[256];
  while (f && fgets(line, sizeof line, f))
    if (strncmp(line, field, n) == 0 && line[n] == ':') {
      kb = (size_t)strtoull(line + n + 1, NULL, 10);
      break;
    }
  if (f) fclose(f);
  return kb * 1024;
}

#endif
