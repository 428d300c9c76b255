/* raysweepd serve: parse the command line, start the service and the HTTP
 * server, preload scenes, then wait for SIGTERM/SIGINT in the main thread
 * and shut down in order (service first so blocked renders return, then
 * the HTTP threads, then the service's memory).
 *
 * The signals are blocked before any thread starts so that every thread
 * inherits the mask and only sigwait() here ever receives them: no handler
 * runs on an arbitrary thread and nothing async-signal-unsafe can happen. */
#include "serve.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "cmdline.h"
#include "default_scene.h"
#include "http/http.h"
#include "kernel/core/isa.h"
#include "kernel/extplugin/env_plugin.h"
#include "service/service.h"

#define MAX_SCENES 256
#define MAX_TOKEN  4096

typedef struct serve_args {
  const char *listen, *data_root, *blob_dir, *token_file, *port_file, *plugin_dir, *state_dir;
  const char *scenes[MAX_SCENES];
  size_t n_scenes;
  unsigned long long threads, max_queue, max_body, max_scene_bytes, max_result_bytes, max_connections,
      max_film;
  double result_ttl, header_timeout;
} serve_args;

static int fail_usage(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
static int fail_usage(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, "raysweepd serve: ");
  vfprintf(stderr, fmt, ap);
  fputc('\n', stderr);
  va_end(ap);
  return 2;
}

static bool parse_ull(const char *s, unsigned long long max, unsigned long long *out) {
  if (!s || !*s || *s == '-' || *s == '+') return false;
  char *end;
  errno = 0;
  unsigned long long v = strtoull(s, &end, 10);
  if (errno || *end || v > max) return false;
  *out = v;
  return true;
}

/* BYTES with an optional binary suffix: 1048576, 1024k, 256M, 1G. */
static bool parse_bytes(const char *s, unsigned long long *out) {
  if (!s || !*s || *s == '-' || *s == '+') return false;
  char *end;
  errno = 0;
  unsigned long long v = strtoull(s, &end, 10);
  if (errno || end == s) return false;
  unsigned shift = 0;
  if (*end == 'k' || *end == 'K')
    shift = 10, end++;
  else if (*end == 'm' || *end == 'M')
    shift = 20, end++;
  else if (*end == 'g' || *end == 'G')
    shift = 30, end++;
  if (*end || v > (1ull << 40) >> shift) return false;
  *out = v << shift;
  return *out > 0;
}

/* The options (common/cmdline.h); each takes one value. */
typedef enum opt_id {
  OPT_LISTEN,
  OPT_THREADS,
  OPT_SCENE,
  OPT_DATA_ROOT,
  OPT_BLOB_DIR,
  OPT_TOKEN_FILE,
  OPT_MAX_BODY,
  OPT_MAX_QUEUE,
  OPT_RESULT_TTL,
  OPT_PORT_FILE,
  OPT_PLUGIN_DIR,
  OPT_STATE_DIR,
  OPT_MAX_SCENE_BYTES,
  OPT_MAX_RESULT_BYTES,
  OPT_MAX_CONNECTIONS,
  OPT_HEADER_TIMEOUT,
  OPT_MAX_FILM,
  OPT_ISA,
} opt_id;

static const cmdline_opt options[] = {
    [OPT_LISTEN] = {"--listen", "HOST:PORT"},
    [OPT_THREADS] = {"--threads", "N"},
    [OPT_SCENE] = {"--scene", "FILE", CMDLINE_REPEAT},
    [OPT_DATA_ROOT] = {"--data-root", "DIR"},
    [OPT_BLOB_DIR] = {"--blob-dir", "DIR"},
    [OPT_TOKEN_FILE] = {"--token-file", "F"},
    [OPT_MAX_BODY] = {"--max-body", "BYTES"},
    [OPT_MAX_QUEUE] = {"--max-queue", "N"},
    [OPT_RESULT_TTL] = {"--result-ttl", "S"},
    [OPT_PORT_FILE] = {"--port-file", "F"},
    [OPT_PLUGIN_DIR] = {"--plugin-dir", "DIR"},
    [OPT_STATE_DIR] = {"--state-dir", "DIR"},
    [OPT_MAX_SCENE_BYTES] = {"--max-scene-bytes", "BYTES"},
    [OPT_MAX_RESULT_BYTES] = {"--max-result-bytes", "BYTES"},
    [OPT_MAX_CONNECTIONS] = {"--max-connections", "N"},
    [OPT_HEADER_TIMEOUT] = {"--header-timeout", "S"},
    [OPT_MAX_FILM] = {"--max-film-bytes", "B"},
    [OPT_ISA] = {"--isa", "ISA"},
    {NULL},
};

/* One option's value into *a. */
static int serve_value(serve_args *a, opt_id id, const char *v) {
  switch (id) {
  case OPT_LISTEN: a->listen = v; break;
  case OPT_DATA_ROOT: a->data_root = v; break;
  case OPT_BLOB_DIR: a->blob_dir = v; break;
  case OPT_TOKEN_FILE: a->token_file = v; break;
  case OPT_PORT_FILE: a->port_file = v; break;
  case OPT_PLUGIN_DIR: a->plugin_dir = v; break;
  case OPT_STATE_DIR: a->state_dir = v; break;
  case OPT_MAX_SCENE_BYTES:
    if (!parse_bytes(v, &a->max_scene_bytes))
      return fail_usage("--max-scene-bytes needs a positive byte count such as 1073741824 or 1G (got '%s')",
                        v);
    break;
  case OPT_MAX_RESULT_BYTES:
    if (!parse_bytes(v, &a->max_result_bytes))
      return fail_usage("--max-result-bytes needs a positive byte count such as 1073741824 or 1G (got '%s')",
                        v);
    break;
  case OPT_SCENE:
    if (a->n_scenes == MAX_SCENES) return fail_usage("too many --scene (at most %d)", MAX_SCENES);
    a->scenes[a->n_scenes++] = v;
    break;
  case OPT_THREADS:
    if (!parse_ull(v, 256, &a->threads) || !a->threads)
      return fail_usage("--threads needs an integer in [1, 256] (got '%s')", v);
    break;
  case OPT_ISA: { /* process-wide, set before any thread starts */
    rsw_isa isa;
    rsw_err err = {0};
    if (rsw_isa_parse(v, &isa, &err) != RSW_OK) return fail_usage("%s: %s", err.where, err.msg);
    rsw_isa_set(isa);
    break;
  }
  case OPT_MAX_QUEUE:
    if (!parse_ull(v, 1000000, &a->max_queue) || !a->max_queue)
      return fail_usage("--max-queue needs an integer in [1, 1000000] (got '%s')", v);
    break;
  case OPT_MAX_BODY:
    if (!parse_bytes(v, &a->max_body))
      return fail_usage("--max-body needs a positive byte count such as 268435456 or 256M (got '%s')", v);
    break;
  case OPT_MAX_CONNECTIONS:
    if (!parse_ull(v, 100000, &a->max_connections) || a->max_connections < 8)
      return fail_usage("--max-connections needs an integer in [8, 100000] (got '%s')", v);
    break;
  case OPT_HEADER_TIMEOUT: {
    char *end;
    errno = 0;
    a->header_timeout = strtod(v, &end);
    if (errno || end == v || *end || !(a->header_timeout > 0) || !(a->header_timeout <= 3600))
      return fail_usage("--header-timeout needs a number of seconds in (0, 3600] (got '%s')", v);
    break;
  }
  case OPT_MAX_FILM:
    if (!parse_bytes(v, &a->max_film))
      return fail_usage("--max-film-bytes needs a positive byte count such as 1073741824 or 1G (got '%s')",
                        v);
    break;
  case OPT_RESULT_TTL: {
    char *end;
    errno = 0;
    a->result_ttl = strtod(v, &end);
    if (errno || end == v || *end || !(a->result_ttl > 0) || !isfinite(a->result_ttl))
      return fail_usage("--result-ttl needs a positive number of seconds (got '%s')", v);
    break;
  }
  }
  return 0;
}

/* argv[1..]: every option value through serve_value (in table order);
 * serve takes no positional argument. */
static int parse_args(int argc, char **argv, serve_args *a) {
  cmdline_args args;
  cmdline_error e;
  int rc = 0;
  switch (cmdline_parse(options, argc - 1, argv + 1, &args, &e)) {
  case CMDLINE_OK: break;
  case CMDLINE_UNKNOWN:
  case CMDLINE_NO_VALUE:
    rc = fail_usage("unknown option '%s' (usage: raysweepd %s)", e.word, RSW_SERVE_USAGE);
    break;
  case CMDLINE_NEEDS_VALUE: rc = fail_usage("%s needs a value", e.word); break;
  case CMDLINE_NOMEM: rc = fail_usage("out of memory"); break;
  }
  if (!rc && args.n_pos)
    rc = fail_usage("unknown option '%s' (usage: raysweepd %s)", args.pos[0], RSW_SERVE_USAGE);
  for (size_t i = 0; !rc && i < args.n_opts; i++)
    for (size_t k = 0; !rc && k < args.n_vals[i]; k++) rc = serve_value(a, (opt_id)i, args.vals[i][k]);
  cmdline_free(&args);
  return rc;
}

/* HOST:PORT, :PORT (loopback) or HOST (port 8350). */
static int parse_listen(const char *s, char *host, size_t host_len, int *port) {
  *port = 8350;
  if (s[0] == '[' || (strchr(s, ':') && strchr(s, ':') != strrchr(s, ':')))
    return fail_usage("--listen: IPv6 addresses are not supported (got '%s'); use an IPv4 address such as "
                      "127.0.0.1:8350",
                      s);
  const char *colon = strrchr(s, ':');
  size_t hl = colon ? (size_t)(colon - s) : strlen(s);
  if (hl >= host_len) return fail_usage("--listen: host name too long");
  if (hl == 0)
    snprintf(host, host_len, "127.0.0.1");
  else
    snprintf(host, host_len, "%.*s", (int)hl, s);
  if (colon) {
    unsigned long long p;
    if (!parse_ull(colon + 1, 65535, &p))
      return fail_usage("--listen: port must be an integer in [0, 65535] (got '%s')", colon + 1);
    *port = (int)p;
  }
  return 0;
}

/* The token is the file's content without surrounding whitespace. */
static int read_token(const char *path, char *tok, size_t cap) {
  FILE *f = fopen(path, "rb");
  if (!f) return fail_usage("--token-file %s: %s", path, strerror(errno));
  size_t n = fread(tok, 1, cap - 1, f);
  bool more = fgetc(f) != EOF;
  fclose(f);
  if (more) return fail_usage("--token-file %s: longer than %zu bytes", path, cap - 1);
  tok[n] = '\0';
  size_t b = 0;
  while (b < n && strchr(" \t\r\n", tok[b])) b++;
  while (n > b && strchr(" \t\r\n", tok[n - 1])) n--;
  memmove(tok, tok + b, n - b);
  tok[n - b] = '\0';
  if (!tok[0]) return fail_usage("--token-file %s: the file is empty", path);
  for (const char *p = tok; *p; p++)
    if ((unsigned char)*p < 0x21 || *p == 0x7f)
      return fail_usage("--token-file %s: the token must not contain spaces or control characters", path);
  return 0;
}

static int write_port_file(const char *path, int port) {
  char tmp[4096];
  if (snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid()) >= (int)sizeof tmp) {
    fprintf(stderr, "raysweepd serve: --port-file: path too long\n");
    return 1;
  }
  FILE *f = fopen(tmp, "w");
  if (!f || fprintf(f, "%d\n", port) < 0 || fclose(f) != 0 || rename(tmp, path) != 0) {
    fprintf(stderr, "raysweepd serve: --port-file %s: %s\n", path, strerror(errno));
    unlink(tmp);
    return 1;
  }
  return 0;
}

static void svc_error_print(const char *what, const svc_error *e) {
  char msg[1200];
  fprintf(stderr, "raysweepd serve: %s: %s\n", what, rsw_err_format(&e->err, msg, sizeof msg));
}

static void report_plugin(void *user, const rsw_err *e) {
  (void)user;
  char msg[1200];
  fprintf(stderr, "raysweepd serve: plugin refused: %s\n", rsw_err_format(e, msg, sizeof msg));
}

int cmd_serve(int argc, char **argv) {
  serve_args a = {0};
  int rc = parse_args(argc, argv, &a);
  if (rc) return rc;
  char host[256];
  int port;
  if ((rc = parse_listen(a.listen ? a.listen : "127.0.0.1:8350", host, sizeof host, &port))) return rc;
  char token[MAX_TOKEN] = "";
  if (a.token_file && (rc = read_token(a.token_file, token, sizeof token))) return rc;
  if (!token[0] && !http_host_is_loopback(host))
    return fail_usage("refusing to listen on %s (not a loopback address) without --token-file", host);

  /* Before any thread exists (the service's workers, MHD's threads). */
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, NULL);
  signal(SIGPIPE, SIG_IGN);

  /* Plugins are loaded once, here, before any thread or scene exists;
   * never from a request. */
  if (a.plugin_dir) {
    rsw_err perr = {0};
    char pmsg[1200];
    /* A bad plugin is refused with a message; the good ones load and the
     * service starts (only an unreadable directory stops it). */
    if (plugins_load_dir_lenient(a.plugin_dir, report_plugin, NULL, &perr) == (size_t)-1) {
      fprintf(stderr, "raysweepd serve: %s\n", rsw_err_format(&perr, pmsg, sizeof pmsg));
      return 1;
    }
    for (size_t i = 0; i < plugins_count(); i++) {
      const char *pretty, *file;
      const plugin *p = plugins_at(i, &pretty, &file);
      fprintf(stderr, "raysweepd: plugin emitter '%s' (%s) loaded from %s\n", p->name, pretty, file);
    }
  }

  service *svc = NULL;
  http_server *srv = NULL;
  rc = 1;
  rsw_err err = {0};
  char msg[1200];
  service_opts so = {.size = sizeof so,
                     .render_threads = (int)a.threads,
                     .data_root = a.data_root,
                     .blob_dir = a.blob_dir, /* NULL: under --state-dir, or a temporary
                                                directory the service removes at exit */
                     .state_dir = a.state_dir,
                     .max_scene_bytes = a.max_scene_bytes,
                     .max_result_bytes = a.max_result_bytes,
                     .max_queue = (size_t)a.max_queue,
                     .result_ttl_s = a.result_ttl,
                     .max_body_bytes = a.max_body ? (size_t)a.max_body : HTTP_DEFAULT_MAX_BODY,
                     .max_film_bytes = a.max_film};
  if (service_new(&so, &svc, &err)) {
    fprintf(stderr, "raysweepd serve: %s\n", rsw_err_format(&err, msg, sizeof msg));
    goto out;
  }
  for (size_t i = 0; i < a.n_scenes; i++) {
    svc_error e = {0};
    char *id = NULL;
    char what[4200];
    snprintf(what, sizeof what, "--scene %s", a.scenes[i]);
    if (service_scene_load_file(svc, a.scenes[i], &id, &e)) {
      svc_error_print(what, &e);
      goto out;
    }
    fprintf(stderr, "raysweepd: scene %s loaded from %s\n", id ? id : "?", a.scenes[i]);
    free(id);
  }
  if (!a.n_scenes) {
    svc_error e = {0};
    char *id = NULL;
    if (service_scene_load_text(svc, rsw_default_scene_xml, rsw_default_scene_xml_len, true,
                                "default_scene.xml", &id, &e)) {
      svc_error_print("the embedded default scene", &e);
      goto out;
    }
    fprintf(stderr, "raysweepd: scene %s loaded (embedded default: hdistant seed scene)\n", id ? id : "?");
    free(id);
  }

  /* Jobs in the state directory come back after the startup scenes are
   * loaded (a job on a --scene scene resumes when it is given again). */
  service_restore(svc);

  http_opts ho = {.size = sizeof ho,
                  .host = host,
                  .port = port,
                  .token = token[0] ? token : NULL,
                  .max_body = (size_t)a.max_body,
                  .max_connections = (unsigned)a.max_connections,
                  .header_timeout_s = a.header_timeout};
  rsw_status s = http_server_start(svc, &ho, &srv, &err);
  if (s) {
    fprintf(stderr, "raysweepd serve: %s\n", rsw_err_format(&err, msg, sizeof msg));
    rc = s == RSW_ERR_USAGE || s == RSW_ERR_UNSUPPORTED ? 2 : 1;
    goto out;
  }
  fprintf(stderr, "raysweepd: listening on http://%s:%d\n", host, http_server_port(srv));
  fprintf(stderr, "raysweepd: viewer: http://%s:%d/ui/\n", host, http_server_port(srv));
  if (a.port_file && write_port_file(a.port_file, http_server_port(srv))) goto out;

  int sig = 0;
  while (sigwait(&stop_signals, &sig) != 0) {}
  fprintf(stderr, "raysweepd: %s: shutting down\n", sig == SIGINT ? "SIGINT" : "SIGTERM");
  rc = 0;
out:
  if (svc) service_shutdown(svc); /* ready -> 503, running work cancelled */
  http_server_stop(srv);          /* joins the connection threads */
  service_free(svc);
  plugins_unload(); /* after service_free: no scene uses them any more */
  return rc;
}

int cmd_routes(int argc, char **argv) {
  if (argc > 1) {
    fprintf(stderr, "raysweepd routes: takes no arguments (got '%s')\n", argv[1]);
    return 2;
  }
  http_routes_print(stdout);
  return 0;
}
