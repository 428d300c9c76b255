/* The one daemon harness of the C tests and benchmarks: start
 * `raysweepd serve` on 127.0.0.1 with an ephemeral port (--listen
 * 127.0.0.1:0 --port-file F), wait until it listens, talk to it with a tiny
 * blocking HTTP/1.1 client over a socket, stop it with SIGTERM and wait,
 * and read what it wrote on stderr.
 *
 * Nothing here is thread-safe except tdaemon_http (any number of threads
 * may use one started daemon). */
#ifndef RSW_TESTS_DAEMON_H
#define RSW_TESTS_DAEMON_H

#include <stdbool.h>
#include <stddef.h>
#include <sys/types.h>

typedef struct tdaemon {
  pid_t pid; /* 0 when not running */
  int port;
  char name[32];
  char log[256];     /* stdout and stderr of the daemon */
  char base_url[64]; /* "http://127.0.0.1:PORT" */
} tdaemon;

/* The directory of raysweepd: $RSW_BIN_DIR, else build/bin. */
const char *tdaemon_bin_dir(void);

/* Start `raysweepd serve --listen 127.0.0.1:0 --port-file DIR/NAME.port`
 * followed by extra (NULL-terminated, may be NULL), with stdout and stderr
 * to DIR/NAME.log, and wait up to timeout_s (0: 20 s, the sanitizer build
 * is slow to start) until it listens. False (with the log printed) when it
 * exits first or never listens; then *d is not running. */
bool tdaemon_start(tdaemon *d, const char *dir, const char *name, const char *const *extra, double timeout_s);

/* SIGTERM, wait up to limit_s. Returns the exit status, -1 for a signal,
 * -2 when it had to be killed (SIGKILL), -3 when it was not running.
 * *secs (may be NULL): how long it took. */
int tdaemon_stop(tdaemon *d, double limit_s, double *secs);

/* The daemon's log so far (malloc'ed, NUL-terminated; NULL when none). */
char *tdaemon_log(const tdaemon *d);

/* Run raysweepd once (not serve: render, routes, ...) with args
 * (NULL-terminated, without argv[0]) and wait. Its stderr goes to errbuf
 * (len bytes, NUL-terminated; stdout is inherited). Returns the exit
 * status, -1 on a signal, -2 when it could not be started. */
int tdaemon_run(const char *const *args, char *errbuf, size_t len);

/* ---- a blocking HTTP/1.1 client (one connection per request) ------------- */

typedef struct thttp_resp {
  int status;    /* 0: no answer (connection failed, closed or timed out) */
  char *headers; /* the header block as received, NUL-terminated */
  char *body;    /* NUL-terminated (len excludes the NUL) */
  size_t len;
  double secs; /* from connect to the end of the answer */
} thttp_resp;

/* Send METHOD PATH with the extra header lines (each "Name: value", NULL-
 * terminated, may be NULL) and body (len bytes; Content-Length is added
 * when body is not NULL), with Connection: close, and read the answer
 * until the server closes or timeout_s passes. A HEAD answer has no body.
 * Returns false with r->status 0 on a transport failure or timeout. */
bool tdaemon_http(const tdaemon *d, const char *method, const char *path, const char *const *headers,
                  const void *body, size_t len, double timeout_s, thttp_resp *r);

/* Value of a response header (case-insensitive name) into out; NULL when
 * absent. */
const char *thttp_header(const thttp_resp *r, const char *name, char *out, size_t n);

void thttp_resp_free(thttp_resp *r);

/* A connected socket to the daemon (-1 on failure), for raw tests. */
int tdaemon_connect(const tdaemon *d);

/* Monotonic seconds. */
double tdaemon_now(void);

#endif
