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

#endif
