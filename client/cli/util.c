/* raysweep CLI: error reporting, number parsing, files, film output and job
 * progress shared by the commands. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "cli.h"

/* ---- Ctrl-C and SIGTERM ---- */

volatile sig_atomic_t cli_interrupted = 0;
volatile sig_atomic_t cli_signal = 0;

static void on_signal(int sig) {
  cli_signal = sig;
  cli_interrupted = 1; /* nothing else: the wait loops act on it */
}

void cli_catch_interrupt(void) {
  /* SIGTERM too: Slurm's scancel, a notebook kernel's restart and
   * `timeout` send it, and the job should not be left running unseen. */
  static const int sigs[] = {SIGINT, SIGTERM};
  for (size_t i = 0; i < sizeof sigs / sizeof sigs[0]; i++) {
    struct sigaction sa, old;
    /* Ignored at start (`nohup`, a background job of a non-interactive
     * shell): stay ignored, as the convention for SIGINT goes. */
    if (sigaction(sigs[i], NULL, &old) == 0 && old.sa_handler == SIG_IGN) continue;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    /* No SA_RESTART: a blocking call returns EINTR and the loop sees the
     * flag. SA_RESETHAND: a second Ctrl-C (say, while the cancel request
     * hangs) ends the process the usual way. */
    sa.sa_flags = SA_RESETHAND;
    sigaction(sigs[i], &sa, NULL);
  }
}

const char *cli_interrupted_word(void) {
  return cli_signal == SIGTERM ? "terminated (SIGTERM)" : "interrupted";
}

int cli_interrupted_code(void) {
  return cli_signal == SIGTERM ? CLI_TERMINATED : CLI_INTERRUPTED;
}

/* ---- messages and exit codes ---- */

int cli_usage(const cli_ctx *ctx, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, "raysweep%s%s: ", ctx->cmd[0] ? " " : "", ctx->cmd);
  vfprintf(stderr, fmt, ap);
  fputc('\n', stderr);
  va_end(ap);
  return CLI_USAGE;
}

int cli_fail(const cli_ctx *ctx, int code, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, "raysweep%s%s: ", ctx->cmd[0] ? " " : "", ctx->cmd);
  vfprintf(stderr, fmt, ap);
  fputc('\n', stderr);
  va_end(ap);
  return code;
}

/* A response from the server is "the server said no" (1) whatever its
 * code, except a deadline (5). Without a response: a connection failure
 * (RSW_ERR_UNAVAILABLE) is 3, a local file is 6, a deadline is 5. */
int cli_exit_code(rsw_status s, const rsw_error_info *e) {
  if (s == RSW_OK) return CLI_OK;
  if (s == RSW_ERR_TIMEOUT) return CLI_TIMEOUT;
  if (e && e->http_status > 0) return CLI_SERVER;
  switch (s) {
  case RSW_ERR_UNAVAILABLE: return CLI_CONNECT;
  case RSW_ERR_IO: return CLI_IO;
  case RSW_ERR_USAGE: return CLI_USAGE;
  default: return CLI_SERVER;
  }
}

int cli_report(const cli_ctx *ctx, rsw_status s, const char *what) {
  const rsw_error_info *e = ctx->client ? rsw_client_last_error(ctx->client) : NULL;
  int code = cli_exit_code(s, e);
  const char *msg = e && e->message && e->message[0] ? e->message : rsw_strerror(s);
  if (code == CLI_CONNECT) {
    fprintf(stderr,
            "raysweep %s: cannot connect to raysweepd at %s\n"
            "  %s\n"
            "  (start it with `raysweepd serve`, or point --server URL / RAYSWEEP_URL at a running one)\n",
            ctx->cmd, ctx->server_url ? ctx->server_url : "?", msg);
    return code;
  }
  if (!e || e->http_status <= 0) {
    fprintf(stderr, "raysweep %s: %s: %s (%s)\n", ctx->cmd, what, msg, rsw_status_name(s));
    return code;
  }
  const char *name = e->code && e->code[0] ? e->code : rsw_status_name(s);
  fprintf(stderr, "raysweep %s: %s: the server said no (HTTP %d, %s): %s\n", ctx->cmd, what, e->http_status,
          name, msg);
  if (e->pointer && e->pointer[0]) fprintf(stderr, "  at: %s\n", e->pointer);
  if (e->key && e->key[0] && !strstr(msg, e->key)) fprintf(stderr, "  key: %s\n", e->key); /* named once */
  if (e->candidates[0]) {
    fprintf(stderr, "  did you mean: ");
    for (int i = 0; i < 3 && e->candidates[i]; i++) fprintf(stderr, "%s%s", i ? ", " : "", e->candidates[i]);
    fprintf(stderr, "?\n");
  }
  if (e->http_status == 401)
    fprintf(stderr, "  (the daemon wants a bearer token: --token-file F or RAYSWEEP_TOKEN)\n");
  return code;
}

/* ---- numbers ---- */

bool cli_parse_u64(const char *s, unsigned long long max, unsigned long long *out) {
  if (!s || !*s || *s == '-' || *s == '+' || *s == ' ') return false;
  char *end;
  errno = 0;
  unsigned long long v = strtoull(s, &end, 10);
  if (errno || *end || v > max) return false;
  *out = v;
  return true;
}

bool cli_parse_double(const char *s, double *out) {
  if (!s || !*s || *s == ' ') return false;
  char *end;
  errno = 0;
  double v = strtod(s, &end);
  if (errno || *end || !isfinite(v)) return false;
  *out = v;
  return true;
}

void cli_format_double(char *buf, size_t n, double v) {
  for (int prec = 1; prec <= 17; prec++) {
    snprintf(buf, n, "%.*g", prec, v);
    if (strtod(buf, NULL) == v) return;
  }
}

int cli_split_set(const cli_ctx *ctx, const char *opt, const char *kv, char **key_out,
                  const char **value_out) {
  const char *eq = strchr(kv, '=');
  if (!eq || eq == kv) return cli_usage(ctx, "%s needs KEY=VALUE (got '%s')", opt, kv);
  if (!eq[1]) return cli_usage(ctx, "%s %.*s: the value is empty (VALUE is JSON)", opt, (int)(eq - kv), kv);
  *key_out = strndup(kv, (size_t)(eq - kv));
  if (!*key_out) return cli_fail(ctx, CLI_IO, "out of memory");
  *value_out = eq + 1;
  return 0;
}

/* ---- files ---- */

int cli_json_option(const cli_ctx *ctx, const char *opt, const char *arg, cJSON **out) {
  char why[1200];
  *out = rsw_json_arg(opt, arg, why, sizeof why);
  return *out ? 0 : cli_usage(ctx, "%s", why);
}

int cli_write_file_atomic(const char *path, const char *data, size_t len) {
  size_t n = strlen(path) + 32;
  char *tmp = malloc(n);
  if (!tmp) return -1;
  snprintf(tmp, n, "%s.tmp.%ld", path, (long)getpid());
  FILE *f = fopen(tmp, "wb");
  int rc = -1;
  if (f) {
    bool ok = fwrite(data, 1, len, f) == len;
    ok = (fclose(f) == 0) && ok;
    if (ok && rename(tmp, path) == 0) rc = 0;
    if (rc) {
      int e = errno ? errno : EIO;
      unlink(tmp);
      errno = e;
    }
  }
  free(tmp);
  return rc;
}

int cli_mkdirs(const char *path) {
  /* Most calls make one directory in one that exists (a sweep's context
   * directory, once per film): one mkdir then, not one per component. */
  if (mkdir(path, 0777) == 0) return 0;
  if (errno != ENOENT && errno != EEXIST) return -1;
  char *p = strdup(path);
  if (!p) return -1;
  for (char *s = p + 1;; s++) {
    if (*s == '/' || *s == '\0') {
      char c = *s;
      *s = '\0';
      if (mkdir(p, 0777) != 0 && errno != EEXIST) {
        free(p);
        return -1;
      }
      *s = c;
      if (!c) break;
    }
  }
  struct stat st;
  int rc = stat(path, &st) == 0 && S_ISDIR(st.st_mode) ? 0 : -1;
  if (rc && errno == 0) errno = ENOTDIR;
  free(p);
  return rc;
}

bool cli_safe_component(const char *s) {
  if (!s || !*s || strcmp(s, ".") == 0 || strcmp(s, "..") == 0 || strlen(s) > 255) return false;
  for (; *s; s++)
    if (*s == '/' || (unsigned char)*s < 0x20) return false;
  return true;
}

/* ---- films ---- */

cli_format cli_format_from_name(const char *name) {
  if (!name) return CLI_FMT_NONE;
  if (strcmp(name, "exr") == 0) return CLI_FMT_EXR;
  if (strcmp(name, "npy") == 0) return CLI_FMT_NPY;
  if (strcmp(name, "json") == 0) return CLI_FMT_JSON;
  return CLI_FMT_NONE;
}

cli_format cli_format_from_path(const char *path) {
  const char *dot = strrchr(path, '.');
  const char *slash = strrchr(path, '/');
  if (!dot || (slash && dot < slash)) return CLI_FMT_NONE;
  char ext[8];
  size_t n = strlen(dot + 1);
  if (n >= sizeof ext) return CLI_FMT_NONE;
  for (size_t i = 0; i <= n; i++)
    ext[i] = (char)(dot[1 + i] >= 'A' && dot[1 + i] <= 'Z' ? dot[1 + i] + 32 : dot[1 + i]);
  return cli_format_from_name(ext);
}

const char *cli_format_ext(cli_format f) {
  switch (f) {
  case CLI_FMT_EXR: return "exr";
  case CLI_FMT_NPY: return "npy";
  case CLI_FMT_JSON: return "json";
  default: return "";
  }
}

const char *cli_format_media_type(cli_format f) {
  switch (f) {
  case CLI_FMT_EXR: return "image/x-exr";
  case CLI_FMT_NPY: return "application/x-npy";
  default: return NULL;
  }
}

int cli_save_encoded(const cli_ctx *ctx, const void *bytes, size_t len, const char *path) {
  if (cli_write_file_atomic(path, bytes, len))
    return cli_fail(ctx, CLI_IO, "cannot write '%s': %s", path, strerror(errno));
  return CLI_OK;
}

static void put_json_string(FILE *f, const char *s) {
  fputc('"', f);
  for (; *s; s++) {
    unsigned char c = (unsigned char)*s;
    if (c == '"' || c == '\\')
      fprintf(f, "\\%c", c);
    else if (c < 0x20)
      fprintf(f, "\\u%04x", c);
    else
      fputc(c, f);
  }
  fputc('"', f);
}

/* The film as the daemon's application/json representation:
 * {width, height, channels, layout:"HWC", data, meta}. Floats are written
 * with 9 significant digits, which read back as the same float32. */
static char *film_json(const rsw_film *fl, size_t *len) {
  char *buf = NULL;
  FILE *f = open_memstream(&buf, len);
  if (!f) return NULL;
  int w = rsw_film_width(fl), h = rsw_film_height(fl), c = rsw_film_channels(fl);
  fprintf(f, "{\"width\":%d,\"height\":%d,\"channels\":[", w, h);
  for (int i = 0; i < c; i++) {
    if (i) fputc(',', f);
    put_json_string(f, rsw_film_channel_name(fl, i));
  }
  fprintf(f, "],\"layout\":\"HWC\",\"data\":[");
  const float *d = rsw_film_data(fl);
  size_t n = (size_t)w * (size_t)h * (size_t)c;
  for (size_t i = 0; i < n; i++) {
    if (i) fputc(',', f);
    if (isfinite(d[i]))
      fprintf(f, "%.9g", (double)d[i]);
    else
      fputs("null", f);
  }
  const char *meta = rsw_film_meta(fl);
  fprintf(f, "],\"meta\":%s}\n", meta && meta[0] ? meta : "{}");
  if (fclose(f) != 0) {
    free(buf);
    return NULL;
  }
  return buf;
}

int cli_save_film(const cli_ctx *ctx, const rsw_film *f, const char *path, cli_format fmt) {
  rsw_status s = RSW_OK;
  switch (fmt) {
  case CLI_FMT_EXR: s = rsw_film_save_exr(f, path); break;
  case CLI_FMT_NPY: s = rsw_film_save_npy(f, path); break;
  case CLI_FMT_JSON: {
    size_t len = 0;
    char *text = film_json(f, &len);
    if (!text) return cli_fail(ctx, CLI_IO, "cannot format the film as JSON: out of memory");
    int rc = cli_write_file_atomic(path, text, len);
    int e = errno;
    free(text);
    if (rc) return cli_fail(ctx, CLI_IO, "cannot write '%s': %s", path, strerror(e));
    return CLI_OK;
  }
  default: return cli_usage(ctx, "'%s': the output format is chosen by extension: .exr, .npy or .json", path);
  }
  if (s) return cli_fail(ctx, CLI_IO, "cannot write '%s': %s", path, rsw_strerror(s));
  return CLI_OK;
}

/* ---- progress ---- */

double cli_now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

void cli_format_duration(char *buf, size_t n, double s) {
  if (!(s >= 0) || s > 1e7) {
    snprintf(buf, n, "?");
    return;
  }
  long t = (long)(s + 0.5);
  if (t >= 3600)
    snprintf(buf, n, "%ldh%02ldm", t / 3600, t / 60 % 60);
  else if (t >= 60)
    snprintf(buf, n, "%ldm%02lds", t / 60, t % 60);
  else
    snprintf(buf, n, "%lds", t);
}

void cli_progress_init(cli_progress *p, const cli_ctx *ctx) {
  memset(p, 0, sizeof *p);
  p->ctx = ctx;
  p->start = cli_now();
}

static void progress_draw(cli_progress *p, bool final) {
  double el = cli_now() - p->start;
  double rate = el > 0 ? (double)p->done / el : 0;
  char eta[32] = "?";
  if (rate > 0 && p->total >= p->done)
    cli_format_duration(eta, sizeof eta, (double)(p->total - p->done) / rate);
  char failed[48] = "";
  if (p->failed) snprintf(failed, sizeof failed, "  %zu failed", p->failed);
  if (p->ctx->stderr_tty) {
    enum {
      WIDTH = 30
    };
    int fill = p->total ? (int)((double)WIDTH * (double)p->done / (double)p->total) : 0;
    char bar[WIDTH + 1];
    for (int i = 0; i < WIDTH; i++) bar[i] = i < fill ? '#' : '.';
    bar[WIDTH] = '\0';
    fprintf(stderr, "\r[%s] %zu/%zu  %.1f/s  ETA %s%s\033[K", bar, p->done, p->total, rate,
            final ? "0s" : eta, failed);
    if (final) fputc('\n', stderr);
  } else {
    fprintf(stderr, "raysweep %s: %zu/%zu renders done  %.1f/s  ETA %s%s\n", p->ctx->cmd, p->done, p->total,
            rate, final ? "0s" : eta, failed);
  }
  fflush(stderr);
  p->drawn = true;
}

int cli_progress_cb(void *user, const char *context, const char *sensor, size_t done, size_t total,
                    int failed) {
  cli_progress *p = user;
  (void)context, (void)sensor;
  if (done > p->done) p->done = done;
  if (total) p->total = total;
  if (failed && context) p->failed++;
  if (p->ctx->quiet) return 0;
  double now = cli_now();
  /* A TTY bar redraws ten times a second; plain lines once a second, so a
   * log of a long sweep stays readable. */
  double every = p->ctx->stderr_tty ? 0.1 : 1.0;
  if (now - p->last_print >= every && p->done < p->total) {
    p->last_print = now;
    progress_draw(p, false);
  }
  return 0;
}

void cli_progress_finish(cli_progress *p) {
  if (!p->ctx->quiet && (p->drawn || p->total)) progress_draw(p, true);
}

/* Whether text holds line as a whole line. */
static bool has_line(const char *text, const char *line) {
  size_t n = strlen(line);
  for (const char *p = text; p && (p = strstr(p, line)); p++)
    if ((p == text || p[-1] == '\n') && (p[n] == '\n' || p[n] == '\0')) return true;
  return false;
}

void cli_print_warnings(const char *who, const char *subject, const char *text, const char *seen) {
  for (const char *line = text; line && *line;) {
    const char *end = strchr(line, '\n');
    size_t n = end ? (size_t)(end - line) : strlen(line);
    char *one = strndup(line, n);
    if (one && !(seen && has_line(seen, one))) fprintf(stderr, "%s: warning: %s: %s\n", who, subject, one);
    free(one);
    line = end ? end + 1 : NULL;
  }
}

void cli_print_job_warnings(cli_ctx *ctx, const char *who, const char *job_id, char **seen) {
  char *text = NULL;
  if (rsw_job_warnings(ctx->client, job_id, &text) != RSW_OK || !text) return;
  char subject[64];
  snprintf(subject, sizeof subject, "job %s", job_id);
  cli_print_warnings(who, subject, text, seen ? *seen : NULL);
  if (seen) {
    char *all = strdup(text);
    if (all) {
      free(*seen);
      *seen = all;
    }
  }
  rsw_free(text);
}

const char *cli_job_state_name(rsw_job_state s) {
  switch (s) {
  case RSW_JOB_QUEUED: return "queued";
  case RSW_JOB_RUNNING: return "running";
  case RSW_JOB_SUCCEEDED: return "succeeded";
  case RSW_JOB_FAILED: return "failed";
  case RSW_JOB_CANCELLED: return "cancelled";
  }
  return "?";
}

/* Ctrl-C during a wait: the flag is cleared first so that the client can
 * still talk to the daemon (a second Ctrl-C now kills the process). */
static int wait_interrupted(cli_ctx *ctx, const char *job_id, cli_on_interrupt on_int) {
  cli_interrupted = 0;
  if (on_int == CLI_INTERRUPT_DETACH) {
    fprintf(stderr,
            "raysweep %s: %s; job %s keeps running on the daemon "
            "(cancel it with `raysweep job cancel %s`)\n",
            ctx->cmd, cli_interrupted_word(), job_id, job_id);
    return cli_interrupted_code();
  }
  rsw_status s = rsw_job_cancel(ctx->client, job_id);
  rsw_job_status st;
  if (!s) s = rsw_job_get(ctx->client, job_id, &st);
  if (s) {
    cli_report(ctx, s, job_id);
    fprintf(stderr, "raysweep %s: %s; cancelling job %s failed (try `raysweep job cancel %s`)\n", ctx->cmd,
            cli_interrupted_word(), job_id, job_id);
    return cli_interrupted_code();
  }
  fprintf(stderr, "raysweep %s: %s; cancelled job %s on the daemon (%zu of %zu renders were done)\n",
          ctx->cmd, cli_interrupted_word(), job_id, st.renders_done, st.renders_total);
  return cli_interrupted_code();
}

int cli_wait_job(cli_ctx *ctx, const char *job_id, double timeout_s, cli_on_interrupt on_int,
                 rsw_job_status *final_out) {
  cli_progress p;
  cli_progress_init(&p, ctx);
  rsw_job_status st;
  memset(&st, 0, sizeof st);
  /* Joining a running job: its rate counts from when it started on the
   * daemon, not from now (the renders done before joining did not happen
   * in the first instant). */
  if (rsw_job_get(ctx->client, job_id, &st) == RSW_OK && st.seconds > 0) {
    p.start -= st.seconds;
    p.done = st.renders_done, p.total = st.renders_total;
  }
  memset(&st, 0, sizeof st);
  rsw_status s = rsw_job_wait(ctx->client, job_id, cli_progress_cb, &p, timeout_s, &st);
  if (s == RSW_OK && st.state == RSW_JOB_SUCCEEDED) {
    p.done = st.renders_done, p.total = st.renders_total, p.failed = st.renders_failed;
    cli_progress_finish(&p);
  } else if (p.drawn && ctx->stderr_tty) {
    fputc('\n', stderr);
  }
  if (cli_interrupted) return wait_interrupted(ctx, job_id, on_int);
  if (s == RSW_ERR_TIMEOUT) {
    fprintf(stderr,
            "raysweep %s: job %s did not finish within %g s (it keeps running: raysweep job watch %s)\n",
            ctx->cmd, job_id, timeout_s, job_id);
    return CLI_TIMEOUT;
  }
  if (s) return cli_report(ctx, s, job_id);
  if (final_out) *final_out = st;
  if (st.state == RSW_JOB_SUCCEEDED && st.renders_failed == 0) return CLI_OK;
  if (st.state == RSW_JOB_SUCCEEDED)
    fprintf(stderr, "raysweep %s: job %s: %zu of %zu renders failed\n", ctx->cmd, job_id, st.renders_failed,
            st.renders_total);
  else
    fprintf(stderr, "raysweep %s: job %s %s%s%s\n", ctx->cmd, job_id, cli_job_state_name(st.state),
            st.error[0] ? ": " : "", st.error);
  return CLI_JOB;
}

void cli_print_json(cJSON *o) {
  char *t = cJSON_PrintUnformatted(o);
  if (t) printf("%s\n", t);
  free(t);
  cJSON_Delete(o);
}
