/* Non-blocking, regular-file-only opens (rsw_file.h). */
#include "rsw_file.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <stdio.h>
#include <fcntl.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

int rsw_open_regular(const char *path, bool nofollow) {
  int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC | (nofollow ? O_NOFOLLOW : 0));
  if (fd < 0) return -1;
  struct stat sb;
  int err = fstat(fd, &sb) != 0 ? errno : !S_ISREG(sb.st_mode) ? EINVAL : 0;
  if (err) {
    close(fd);
    errno = err;
    return -1;
  }
  int fl = fcntl(fd, F_GETFL);
  if (fl >= 0) fcntl(fd, F_SETFL, fl & ~O_NONBLOCK);
  return fd;
}

FILE *rsw_fopen_regular(const char *path, const char *mode) {
  int fd = rsw_open_regular(path, false);
  if (fd < 0) return NULL;
  FILE *f = fdopen(fd, mode);
  if (!f) {
    int err = errno;
    close(fd);
    errno = err;
  }
  return f;
}

const char *rsw_open_strerror(int err) {
  return err == EINVAL ? "not a regular file (a FIFO, socket, device or directory)" : strerror(err);
}

bool rsw_write_replace(const char *path, const void *data, size_t len) {
  size_t tl = strlen(path) + 32;
  char *tmp = malloc(tl);
  if (!tmp) return false;
  snprintf(tmp, tl, "%s.tmp.%ld", path, (long)getpid());
  FILE *f = fopen(tmp, "wb");
  bool ok = f && fwrite(data, 1, len, f) == len;
  if (f) ok = fclose(f) == 0 && ok;
  ok = ok && rename(tmp, path) == 0;
  if (!ok) {
    int e = errno;
    unlink(tmp);
    errno = e;
  }
  free(tmp);
  return ok;
}

char *rsw_read_file(const char *path, size_t *len_out) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  size_t cap = 4096, len = 0;
  char *buf = malloc(cap);
  while (buf) {
    if (len + 1 >= cap) {
      char *nb = realloc(buf, cap * 2);
      if (!nb) {
        free(buf);
        buf = NULL;
        errno = ENOMEM;
        break;
      }
      buf = nb, cap *= 2;
    }
    size_t got = fread(buf + len, 1, cap - len - 1, f);
    len += got;
    if (got == 0) {
      if (ferror(f)) {
        free(buf);
        buf = NULL;
        errno = EIO;
      }
      break;
    }
  }
  fclose(f);
  if (!buf) return NULL;
  buf[len] = '\0';
  if (len_out) *len_out = len;
  return buf;
}

void rsw_line_col(const char *text, size_t off, size_t *line, size_t *col) {
  size_t l = 1, c = 1;
  for (size_t i = 0; i < off; i++) {
    if (text[i] == '\n')
      l++, c = 1;
    else
      c++;
  }
  *line = l, *col = c;
}

cJSON *rsw_json_arg(const char *opt, const char *arg, char *why, size_t cap) {
  const char *p = arg;
  while (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r') p++;
  const bool inline_text = *p == '{' || *p == '[', std_in = strcmp(arg, "-") == 0;
  const char *name = std_in ? "stdin" : arg;
  char *file = NULL;
  if (!inline_text && !(file = rsw_read_file(std_in ? "/dev/stdin" : arg, NULL))) {
    snprintf(why, cap, "%s %s: cannot read it (%s); give a file, - (the standard input) or the JSON itself",
             opt, name, strerror(errno));
    return NULL;
  }
  const char *text = inline_text ? arg : file, *end = NULL;
  cJSON *j = cJSON_ParseWithOpts(text, &end, true);
  if (!j) { /* cJSON stops at the byte it could not take */
    size_t line, col;
    const char *at = end ? end : cJSON_GetErrorPtr();
    rsw_line_col(text, at ? (size_t)(at - text) : 0, &line, &col);
    if (inline_text)
      snprintf(why, cap, "%s: malformed JSON at line %zu, column %zu", opt, line, col);
    else
      snprintf(why, cap, "%s %s:%zu:%zu: malformed JSON", opt, name, line, col);
  }
  free(file);
  return j;
}
