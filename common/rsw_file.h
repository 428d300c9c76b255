/* Opening files that a scene or the state directory names, without ever
 * blocking: a FIFO, socket or device in place of a file must be refused
 * at once, not hang the reader (and the thread, and a SIGTERM behind it).
 * Shared by the kernel's file readers and the daemon. */
#ifndef RSW_COMMON_FILE_H
#define RSW_COMMON_FILE_H

#include <stdbool.h>
#include <stdio.h>

/* open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC [| O_NOFOLLOW]), then fstat:
 * the descriptor of a regular file (O_NONBLOCK cleared again), or -1 with
 * errno set; a file that is not a regular one (FIFO, socket, device,
 * directory) gives -1 with errno EINVAL. nofollow: a symbolic link as the
 * last component is refused (ELOOP). */
int rsw_open_regular(const char *path, bool nofollow);
/* The same as a read-only stdio stream ("r" or "rb"); NULL with errno. */
FILE *rsw_fopen_regular(const char *path, const char *mode);
/* A sentence for an errno of the two above ("not a regular file" for
 * EINVAL, strerror otherwise). */
const char *rsw_open_strerror(int err);

/* Write len bytes to "<path>.tmp.<pid>" and rename it over path, so that a
 * reader never sees a partial file and a failure leaves none behind (the
 * temporary file is removed). false with errno set. */
bool rsw_write_replace(const char *path, const void *data, size_t len);

/* A whole file into memory, NUL-terminated (*len_out, may be NULL: its
 * length); NULL with errno set. Plain fopen: "/dev/stdin" reads the
 * standard input. */
char *rsw_read_file(const char *path, size_t *len_out);

/* Line and column (1-based) of byte offset off (at most text's length) of text. */
void rsw_line_col(const char *text, size_t off, size_t *line, size_t *col);

struct cJSON;
/* The JSON value of a command-line option: the text itself when it starts
 * with '{' or '[', the standard input for "-", else the file it names.
 * NULL with why[] saying what went wrong, opt and the file (or stdin) and
 * the line and column of malformed JSON named. Owned: cJSON_Delete. */
struct cJSON *rsw_json_arg(const char *opt, const char *arg, char *why, size_t cap);

#endif
