/* raysweep CLI: shared declarations.
 *
 * The CLI talks to raysweepd only through the public libraysweep API
 * (include/raysweep/client.h); cJSON (a system library) reads and writes
 * the JSON documents the API hands around as text. */
#ifndef RSW_CLI_H
#define RSW_CLI_H

#include <signal.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>

#include "cmdline.h"
#include "raysweep/client.h"
#include "rsw_file.h"

/* Exit codes, documented in `raysweep --help`. */
enum {
  CLI_OK = 0,
  CLI_SERVER = 1,        /* the server answered with a problem */
  CLI_USAGE = 2,         /* bad command line or bad local input description */
  CLI_CONNECT = 3,       /* cannot connect to the daemon */
  CLI_JOB = 4,           /* job (or one of its renders) failed or was cancelled */
  CLI_TIMEOUT = 5,       /* a deadline passed */
  CLI_IO = 6,            /* local files */
  CLI_INTERRUPTED = 130, /* Ctrl-C (SIGINT): 128 + 2, the shells' convention */
  CLI_TERMINATED = 143   /* SIGTERM: 128 + 15, handled as Ctrl-C */
};

/* Set by the SIGINT handler (cli_catch_interrupt); the client's transfers
 * watch it (rsw_client_opts.interrupt) and stop within about a second. */
extern volatile sig_atomic_t cli_interrupted;
/* The signal that set it (SIGINT or SIGTERM), 0 before any. */
extern volatile sig_atomic_t cli_signal;
/* Catch the first SIGINT or SIGTERM in cli_interrupted (the handler only
 * sets the flags); a second one kills the process as usual (SA_RESETHAND).
 * For the commands that wait on the daemon: sweep, render, job watch. */
void cli_catch_interrupt(void);
/* "interrupted", or "terminated (SIGTERM)", for the messages. */
const char *cli_interrupted_word(void);
/* CLI_INTERRUPTED, or CLI_TERMINATED after SIGTERM. */
int cli_interrupted_code(void);

/* What every command handler gets. */
typedef struct cli_ctx {
  const char *cmd;        /* "scene push", for messages */
  const char *server_url; /* effective base URL */
  const char *token;      /* bearer token or NULL (for extra clients: sweep --spread) */
  const char *route;      /* --route / RAYSWEEP_ROUTE: the requests' routing key, or NULL */
  bool json, quiet;
  bool stderr_tty;
  rsw_client *client; /* created before the handler when the command needs it */
} cli_ctx;

struct cli_command;
typedef int (*cli_run_fn)(cli_ctx *ctx, const cmdline_args *a);

typedef struct cli_command {
  const char *group; /* first word */
  const char *name;  /* second word, or NULL */
  const char *args;  /* positional synopsis and options, for usage lines */
  const char *summary;
  const cmdline_opt *opts; /* terminated by a {NULL} entry */
  size_t min_pos, max_pos;
  bool needs_client;
  cli_run_fn run;
} cli_command;

/* Options: cmdline_get, cmdline_get_all, cmdline_has (common/cmdline.h). */

/* ---- util.c ---- */
int cli_usage(const cli_ctx *ctx, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Print a local failure ("raysweep CMD: ...") and return code. */
int cli_fail(const cli_ctx *ctx, int code, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* Report a failed library call on ctx->client (what the server said, or why
 * the call did not reach it) and return the exit code for it. */
int cli_report(const cli_ctx *ctx, rsw_status s, const char *what);
/* Exit code for a status and the client's error info (NULL when none). */
int cli_exit_code(rsw_status s, const rsw_error_info *e);

bool cli_parse_u64(const char *s, unsigned long long max, unsigned long long *out);
bool cli_parse_double(const char *s, double *out);
/* Shortest "%.*g" that reads back as v exactly. buf >= 32 bytes. */
void cli_format_double(char *buf, size_t n, double v);

/* Split KEY=VALUE: VALUE is JSON; a value that is not JSON is an error
 * (quote strings). On success *key_out is owned (free). */
int cli_split_set(const cli_ctx *ctx, const char *opt, const char *kv, char **key_out,
                  const char **value_out);

struct cJSON;
/* --json output: o on one line of stdout, then freed. */
void cli_print_json(struct cJSON *o);

/* Build {"key": value, ...} from KEY=VALUE words (VALUE is JSON text;
 * opt names the flag in messages). Returns 0 with *out owned
 * (cJSON_Delete), or an exit code after printing. */
int cli_build_param_map(const cli_ctx *ctx, const char *opt, const char *const *sets, size_t n,
                        struct cJSON **out);

/* Film file formats, chosen by extension. */
typedef enum cli_format {
  CLI_FMT_NONE,
  CLI_FMT_EXR,
  CLI_FMT_NPY,
  CLI_FMT_JSON
} cli_format;
cli_format cli_format_from_path(const char *path);
cli_format cli_format_from_name(const char *name);
const char *cli_format_ext(cli_format f);
/* Write a film in a format; returns a CLI exit code after printing. */
int cli_save_film(const cli_ctx *ctx, const rsw_film *f, const char *path, cli_format fmt);
/* The media type in which the daemon's own encoding of a film is the file
 * cli_save_film writes (rsw_job_fetch_encoded): EXR and NPY; NULL for
 * JSON, whose meta the client prints itself. */
const char *cli_format_media_type(cli_format f);
/* Write a film's bytes as fetched (through a temp file renamed on
 * success); returns a CLI exit code after printing. */
int cli_save_encoded(const cli_ctx *ctx, const void *bytes, size_t len, const char *path);

/* An option whose value is JSON given inline (it starts with '{' or '['),
 * as a file, or "-" for the standard input: parsed into *out (owned). A usage error (exit 2) names
 * the option, the file and the line and column of malformed JSON. */
int cli_json_option(const cli_ctx *ctx, const char *opt, const char *arg, struct cJSON **out);
/* Write text through a temp file renamed on success. 0 or -1 (errno). */
int cli_write_file_atomic(const char *path, const char *data, size_t len);
/* mkdir -p. 0 or -1 (errno). */
int cli_mkdirs(const char *path);
/* A name that is safe as one path component. */
bool cli_safe_component(const char *s);

/* Progress of a job on stderr: a bar on a TTY, plain lines otherwise,
 * nothing with --quiet. Pass cli_progress_cb and a cli_progress as user. */
typedef struct cli_progress {
  const cli_ctx *ctx;
  double start; /* when the job started running (cli_now's clock): the
                   rate is done / (now - start), also for a client that
                   joins a running job (start = now - the job's seconds) */
  double last_print;
  size_t done, total, failed;
  bool drawn;
} cli_progress;
void cli_progress_init(cli_progress *p, const cli_ctx *ctx);
int cli_progress_cb(void *user, const char *context, const char *sensor, size_t done, size_t total,
                    int failed);
void cli_progress_finish(cli_progress *p);
double cli_now(void);

/* What cli_wait_job does on Ctrl-C: cancel the job on the daemon (the
 * command owns it: sweep), or leave it running and say how to cancel it
 * (the command only watches it: job watch). */
typedef enum cli_on_interrupt {
  CLI_INTERRUPT_CANCEL,
  CLI_INTERRUPT_DETACH
} cli_on_interrupt;

/* Wait for a job with progress; prints the end state. Returns a CLI exit
 * code: 0 succeeded (no failed renders), 4 failed/cancelled/renders failed,
 * 5 timeout, 130 interrupted (after cancelling or detaching, as `on_int`
 * says, and saying so on stderr), or the code of a transport failure. */
int cli_wait_job(cli_ctx *ctx, const char *job_id, double timeout_s, cli_on_interrupt on_int,
                 rsw_job_status *final_out);
/* "12s", "3m05s", "1h02m"; "?" for a negative or absurd value. */
void cli_format_duration(char *buf, size_t n, double s);
const char *cli_job_state_name(rsw_job_state s);
/* The job's warnings (a sweep that changes nothing along a coordinate or
 * the wavelength, renders that replaced environment plugin answers by
 * black) on stderr, "<who>: warning: job ID: ..." a line, even with
 * --quiet; nothing when there are none or they cannot be read. seen (or
 * NULL): the lines printed before, skipped, and replaced by the job's
 * whole text now (the caller frees it with free). */
void cli_print_job_warnings(cli_ctx *ctx, const char *who, const char *job_id, char **seen);
/* Warnings text (rsw_job_warnings' lines) on stderr, "WHO: warning: SUBJECT:
 * LINE" each, but the lines seen (may be NULL) already holds. */
void cli_print_warnings(const char *who, const char *subject, const char *text, const char *seen);

/* ---- handlers ---- */
int cmd_status(cli_ctx *ctx, const cmdline_args *a);
int cmd_scene_push(cli_ctx *ctx, const cmdline_args *a);
int cmd_scene_ls(cli_ctx *ctx, const cmdline_args *a);
int cmd_scene_show(cli_ctx *ctx, const cmdline_args *a);
int cmd_scene_rm(cli_ctx *ctx, const cmdline_args *a);
int cmd_scene_reset(cli_ctx *ctx, const cmdline_args *a);
int cmd_scene_copy(cli_ctx *ctx, const cmdline_args *a);
int cmd_params(cli_ctx *ctx, const cmdline_args *a);
int cmd_set(cli_ctx *ctx, const cmdline_args *a);
int cmd_render(cli_ctx *ctx, const cmdline_args *a);
int cmd_fetch(cli_ctx *ctx, const cmdline_args *a);
int cmd_sweep(cli_ctx *ctx, const cmdline_args *a);
int cmd_merge(cli_ctx *ctx, const cmdline_args *a);
int cmd_job_ls(cli_ctx *ctx, const cmdline_args *a);
int cmd_job_show(cli_ctx *ctx, const cmdline_args *a);
int cmd_job_watch(cli_ctx *ctx, const cmdline_args *a);
int cmd_job_submit(cli_ctx *ctx, const cmdline_args *a);
int cmd_job_cancel(cli_ctx *ctx, const cmdline_args *a);
int cmd_job_rm(cli_ctx *ctx, const cmdline_args *a);

/* Option tables, defined beside their handlers. */
extern const cmdline_opt cli_opts_none[];
extern const cmdline_opt cli_opts_scene_push[];
extern const cmdline_opt cli_opts_scene_rm[];
extern const cmdline_opt cli_opts_params[];
extern const cmdline_opt cli_opts_set[];
extern const cmdline_opt cli_opts_render[];
extern const cmdline_opt cli_opts_fetch[];
extern const cmdline_opt cli_opts_sweep[];
extern const cmdline_opt cli_opts_merge[];
extern const cmdline_opt cli_opts_job_watch[];

#endif
