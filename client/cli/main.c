/* raysweep: the command-line client of raysweepd.
 *
 * Commands are one const table (redis' command table); the generic checks
 * (global options, --help, option syntax, positional counts, the client
 * connection settings) run in main before any handler, so a handler only
 * sees a well-formed command line. The usage strings and summaries below are
 * what `raysweep --help` and `raysweep COMMAND --help` print; the usage
 * block of docs/client.md and docs/man/raysweep.1 must agree with them
 * (tests/integration/test_usage.sh compares them). */
#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "cli.h"
#include "raysweep/version.h"

#define DEFAULT_URL "http://127.0.0.1:8350"

const cmdline_opt cli_opts_none[] = {{NULL}};

static const cli_command commands[] = {
    {"status", NULL, "", "server version, variants, limits and readiness", cli_opts_none, 0, 0, true,
     cmd_status},
    {"scene", "push", "FILE [--variant mono|rgb|mono_polarized|rgb_polarized]",
     "upload a scene (JSON or Mitsuba XML) and the files it references; prints the scene id",
     cli_opts_scene_push, 1, 1, true, cmd_scene_push},
    {"scene", "ls", "", "list resident scenes", cli_opts_none, 0, 0, true, cmd_scene_ls},
    {"scene", "show", "ID", "one scene's summary", cli_opts_none, 1, 1, true, cmd_scene_show},
    {"scene", "rm", "ID [--force]", "unload a scene (--force cancels its jobs)", cli_opts_scene_rm, 1, 1,
     true, cmd_scene_rm},
    {"scene", "reset", "ID", "set the scene back to its document's state (undo every `set` since)",
     cli_opts_none, 1, 1, true, cmd_scene_reset},
    {"scene", "copy", "ID", "a new scene in ID's current state, yours alone; prints its id", cli_opts_none, 1,
     1, true, cmd_scene_copy},
    {"params", NULL, "ID [--match GLOB] [--class spectral|geometric|none] [--full]",
     "the scene's parameter table", cli_opts_params, 1, 1, true, cmd_params},
    {"set", NULL, "ID KEY=VALUE... [--if-match REV]",
     "update parameters atomically (VALUE is JSON); prints each key's old and new value and the new revision",
     cli_opts_set, 2, (size_t)-1, true, cmd_set},
    {"render", NULL,
     "ID|FILE [--sensor S] [--spp N] [--seed N] [--wavelength NM] [--set KEY=VALUE]... [--coord "
     "NAME=VALUE]... "
     "[--templates FILE.json|-|JSON] [--timeout S] [--quantities LIST] [--variance] [--exposure EV|auto] "
     "[--colormap MAP] -o OUT.exr|.npy|.json|.png",
     "render one context synchronously (format by extension; .json is the film JSON, .png a tone-mapped "
     "quick-look; Ctrl-C stops the render)",
     cli_opts_render, 1, 1, true, cmd_render},
    {"sweep", NULL,
     "ID|FILE (--contexts FILE.jsonl | --grid NAME=START:STOP:STEP|V1,V2,...) [--set KEY=VALUE]... "
     "[--templates FILE.json|JSON] [--sensor S]... [--spp N] [--seed N] [--shard I/N] [--spread K] "
     "[--quantities LIST] [--variance] [--bundle K|auto] "
     "[--format exr|npy|json|nc|dataset] [--layout dirs|flat] [--timeout S] -o DIR [--force]",
     "submit a job over many contexts, show progress, fetch every film into DIR with DIR/index.jsonl and "
     "DIR/sweep.json (Ctrl-C cancels the job)",
     cli_opts_sweep, 1, 1, true, cmd_sweep},
    {"merge", NULL, "DIR... -o DIR [--partial]",
     "join sweep shard directories into one (films hard-linked or copied); fails listing missing contexts",
     cli_opts_merge, 1, (size_t)-1, false, cmd_merge},
    {"job", "submit", "ID|FILE REQUEST.json|-|JSON",
     "submit a job request as the daemon takes it (contexts, defaults, bands, templates, ...); prints its id "
     "(then: job watch ID, fetch ID -o FILE.nc)",
     cli_opts_none, 2, 2, true, cmd_job_submit},
    {"job", "ls", "", "list jobs", cli_opts_none, 0, 0, true, cmd_job_ls},
    {"job", "show", "ID", "one job's state and progress", cli_opts_none, 1, 1, true, cmd_job_show},
    {"job", "watch", "ID [--timeout S]",
     "follow a job's progress until it ends (Ctrl-C stops watching; the job goes on)", cli_opts_job_watch, 1,
     1, true, cmd_job_watch},
    {"job", "cancel", "ID",
     "cancel a job; prints the state it leads to (waits up to 30 s for the job to stop)", cli_opts_none, 1, 1,
     true, cmd_job_cancel},
    {"job", "rm", "ID", "delete a job and its results (cancels it if running)", cli_opts_none, 1, 1, true,
     cmd_job_rm},
    {"fetch", NULL,
     "JOB [CONTEXT SENSOR] [--exposure EV|auto] [--colormap MAP] -o FILE.exr|.npy|.json|.png|.nc "
     "[--format exr|npy|json|nc] [--partial]",
     "download one film of a job, or (.nc) the whole job as one dataset", cli_opts_fetch, 1, 3, true,
     cmd_fetch},
};
#define N_COMMANDS (sizeof commands / sizeof commands[0])

static const char global_help[] =
    "Global options (anywhere on the command line):\n"
    "  --server URL       daemon base URL (env RAYSWEEP_URL; default " DEFAULT_URL ")\n"
    "  --token-file F     bearer token read from F (env RAYSWEEP_TOKEN holds the token itself)\n"
    "  --connect-timeout S  give up connecting after S seconds (env RAYSWEEP_CONNECT_TIMEOUT; default 10)\n"
    "  --stall-timeout S  give up a request that moves no byte for S seconds; 0: never (env\n"
    "                     RAYSWEEP_STALL_TIMEOUT; default 60; a render, scene push, PATCH, job\n"
    "                     submission or dataset waits for its answer to start)\n"
    "  --route KEY        send X-Raysweep-Shard: KEY, so a load balancer routes every request to\n"
    "                     the replica KEY hashes to (env RAYSWEEP_ROUTE; an unfinished --spread\n"
    "                     run's shard keys are in DIR/sweep.spread.jsonl); none: the balancer's\n"
    "                     default replica\n"
    "  --json             machine-readable output on stdout\n"
    "  --quiet, -q        no progress or informational messages on stderr (warnings stay)\n"
    "  --help, -h         this help; `raysweep COMMAND --help` for one command\n"
    "  --version, -V      print the version and exit\n"
    "\n"
    "Exit codes:\n"
    "  0  ok\n"
    "  1  the server said no (its problem is printed: code, message, place, candidates)\n"
    "  2  usage error\n"
    "  3  cannot connect to the daemon (sweep --spread: to the balancer; rerun to resume)\n"
    "  4  job failed or was cancelled (or some of its renders failed)\n"
    "  5  timeout\n"
    "  6  local I/O error (files, directories, inconsistent shard directories)\n"
    "  130 interrupted (Ctrl-C): sweep cancels its job first (with --spread it leaves its jobs for a\n"
    "      rerun to resume), job watch leaves it running\n"
    "  143 terminated (SIGTERM, as Slurm or a notebook restart sends): as Ctrl-C\n";

static void command_name(const cli_command *c, char *buf, size_t n) {
  snprintf(buf, n, "%s%s%s", c->group, c->name ? " " : "", c->name ? c->name : "");
}

static void print_usage(FILE *f, const char *prefix, const char *name, const char *args) {
  cmdline_print_usage(f, prefix, "raysweep", name, args);
}

static void usage_list(FILE *f) {
  fprintf(f, "usage: raysweep [global options] COMMAND [args]\n\nCommands:\n");
  for (size_t i = 0; i < N_COMMANDS; i++) {
    char name[32];
    command_name(&commands[i], name, sizeof name);
    print_usage(f, "  ", name, commands[i].args);
    fprintf(f, "      %s\n", commands[i].summary);
  }
  fputc('\n', f);
  fputs(global_help, f);
}

static void command_help(const cli_command *c) {
  char name[32];
  command_name(c, name, sizeof name);
  print_usage(stdout, "usage: ", name, c->args);
  printf("\n%s\n", c->summary);
  if (c->opts[0].name) {
    printf("\nOptions:\n");
    for (const cmdline_opt *o = c->opts; o->name; o++) {
      char flag[64];
      snprintf(flag, sizeof flag, "%s%s%s", o->name, o->arg ? " " : "", o->arg ? o->arg : "");
      printf("  %-28s %s%s\n", flag, o->help ? o->help : "",
             (o->flags & CMDLINE_REPEAT) ? " (repeatable)" : "");
    }
  }
  printf("\n%s", global_help);
}

/* Parse a command's arguments against its option table (common/cmdline.h)
 * and check the positional count. Returns 0, or a usage exit code after
 * printing. */
static int parse_args(cli_ctx *ctx, const cli_command *c, int argc, char **argv, cmdline_args *a) {
  cmdline_error e;
  switch (cmdline_parse(c->opts, argc, argv, a, &e)) {
  case CMDLINE_OK: break;
  case CMDLINE_UNKNOWN:
    return cli_usage(ctx, "unknown option '%.*s' (see raysweep %s --help)", e.name_len, e.word, ctx->cmd);
  case CMDLINE_NEEDS_VALUE: return cli_usage(ctx, "%s needs a value", e.opt->name);
  case CMDLINE_NO_VALUE: return cli_usage(ctx, "%s takes no value", e.opt->name);
  case CMDLINE_NOMEM: return cli_fail(ctx, CLI_IO, "out of memory");
  }
  if (a->n_pos < c->min_pos)
    return cli_usage(ctx, "missing arguments (usage: raysweep %s %s)", ctx->cmd, c->args);
  if (a->n_pos > c->max_pos)
    return cli_usage(ctx, "unexpected argument '%s' (usage: raysweep %s %s)", a->pos[c->max_pos], ctx->cmd,
                     c->args);
  return 0;
}

/* --connect-timeout / --stall-timeout (or their environment variable):
 * seconds, > 0 (the stall limit also takes 0: none, passed on as -1).
 * *out stays 0 (the library's default) when neither is given. */
static int transfer_limit(cli_ctx *ctx, const char *opt, const char *v, const char *env, bool zero_ok,
                          double *out) {
  const char *from = opt;
  if (!v) {
    v = getenv(env);
    from = env;
    if (!v || !*v) return CLI_OK;
  }
  double d;
  if (!cli_parse_double(v, &d) || !(zero_ok ? d >= 0 : d > 0) || d > 1e6)
    return cli_usage(ctx, "%s needs %s number of seconds (got '%s')", from,
                     zero_ok ? "a non-negative" : "a positive", v);
  *out = d == 0 ? -1 : d;
  return CLI_OK;
}

/* Token: --token-file wins over RAYSWEEP_TOKEN; trailing white space (the
 * newline of `echo secret > F`) is not part of it. */
static int read_token(const cli_ctx *ctx, const char *token_file, char **out) {
  *out = NULL;
  if (token_file) {
    size_t len;
    char *t = rsw_read_file(token_file, &len);
    if (!t) return cli_fail(ctx, CLI_IO, "--token-file: cannot read '%s': %s", token_file, strerror(errno));
    while (len && (t[len - 1] == '\n' || t[len - 1] == '\r' || t[len - 1] == ' ' || t[len - 1] == '\t'))
      t[--len] = '\0';
    if (!len) {
      free(t);
      return cli_fail(ctx, CLI_USAGE, "--token-file: '%s' is empty", token_file);
    }
    *out = t;
    return 0;
  }
  const char *env = getenv("RAYSWEEP_TOKEN");
  if (env && *env && !(*out = strdup(env))) return cli_fail(ctx, CLI_IO, "out of memory");
  return 0;
}

int main(int argc, char **argv) {
  cli_ctx ctx = {.cmd = "", .stderr_tty = isatty(STDERR_FILENO) == 1};
  const char *server = NULL, *token_file = NULL, *connect_to = NULL, *stall_to = NULL, *route = NULL;
  bool help = false, version = false;
  /* Global options anywhere before "--": take them out of argv. */
  char **rest = calloc((size_t)argc + 1, sizeof *rest);
  int n_rest = 0;
  if (!rest) return CLI_IO;
  bool after_dashes = false;
  for (int i = 1; i < argc; i++) {
    const char *arg = argv[i];
    if (after_dashes || strcmp(arg, "--") == 0) {
      after_dashes = true;
      rest[n_rest++] = argv[i];
    } else if (strcmp(arg, "--json") == 0) {
      ctx.json = true;
    } else if (strcmp(arg, "--quiet") == 0 || strcmp(arg, "-q") == 0) {
      ctx.quiet = true;
    } else if (strcmp(arg, "--help") == 0 || strcmp(arg, "-h") == 0) {
      help = true;
    } else if (strcmp(arg, "--version") == 0 || strcmp(arg, "-V") == 0) {
      version = true;
    } else if (strcmp(arg, "--server") == 0 || strcmp(arg, "--token-file") == 0) {
      if (i + 1 >= argc) {
        free(rest);
        return cli_usage(&ctx, "%s needs a value", arg);
      }
      *(arg[2] == 's' ? &server : &token_file) = argv[++i];
    } else if (strcmp(arg, "--connect-timeout") == 0 || strcmp(arg, "--stall-timeout") == 0) {
      if (i + 1 >= argc) {
        free(rest);
        return cli_usage(&ctx, "%s needs a value", arg);
      }
      *(arg[2] == 'c' ? &connect_to : &stall_to) = argv[++i];
    } else if (strncmp(arg, "--connect-timeout=", 18) == 0) {
      connect_to = arg + 18;
    } else if (strncmp(arg, "--stall-timeout=", 16) == 0) {
      stall_to = arg + 16;
    } else if (strcmp(arg, "--route") == 0) {
      if (i + 1 >= argc) {
        free(rest);
        return cli_usage(&ctx, "%s needs a value", arg);
      }
      route = argv[++i];
    } else if (strncmp(arg, "--route=", 8) == 0) {
      route = arg + 8;
    } else if (strncmp(arg, "--server=", 9) == 0) {
      server = arg + 9;
    } else if (strncmp(arg, "--token-file=", 13) == 0) {
      token_file = arg + 13;
    } else {
      rest[n_rest++] = argv[i];
    }
  }
  int rc;
  if (version && !help) {
    printf("raysweep %s\n", RSW_VERSION);
    free(rest);
    return CLI_OK;
  }
  if (n_rest > 0 && strcmp(rest[0], "help") == 0) { /* "raysweep help [CMD]" */
    help = true;
    memmove(rest, rest + 1, (size_t)(n_rest - 1) * sizeof *rest);
    n_rest--;
  }
  if (n_rest == 0) {
    usage_list(help ? stdout : stderr);
    free(rest);
    return help ? CLI_OK : CLI_USAGE;
  }
  /* Look the command up: one word, or group + word. */
  const cli_command *cmd = NULL;
  bool group_known = false;
  for (size_t i = 0; i < N_COMMANDS; i++) {
    if (strcmp(commands[i].group, rest[0]) != 0) continue;
    group_known = true;
    if (!commands[i].name || (n_rest > 1 && strcmp(commands[i].name, rest[1]) == 0)) {
      cmd = &commands[i];
      break;
    }
  }
  if (!cmd) {
    if (group_known && help && n_rest == 1) {
      printf("raysweep %s subcommands:\n", rest[0]);
      for (size_t i = 0; i < N_COMMANDS; i++)
        if (strcmp(commands[i].group, rest[0]) == 0) {
          char sub[32];
          command_name(&commands[i], sub, sizeof sub);
          print_usage(stdout, "  ", sub, commands[i].args);
          printf("      %s\n", commands[i].summary);
        }
      free(rest);
      return CLI_OK;
    }
    if (group_known && n_rest > 1)
      fprintf(stderr, "raysweep %s: unknown subcommand '%s' (see raysweep %s --help)\n", rest[0], rest[1],
              rest[0]);
    else if (group_known)
      fprintf(stderr, "raysweep %s: missing a subcommand (see raysweep %s --help)\n", rest[0], rest[0]);
    else
      fprintf(stderr, "raysweep: unknown command '%s' (see raysweep --help)\n", rest[0]);
    free(rest);
    return CLI_USAGE;
  }
  char name[32];
  command_name(cmd, name, sizeof name);
  ctx.cmd = name;
  if (help) {
    command_help(cmd);
    free(rest);
    return CLI_OK;
  }
  int skip = cmd->name ? 2 : 1;
  cmdline_args args;
  rc = parse_args(&ctx, cmd, n_rest - skip, rest + skip, &args);
  char *token = NULL;
  if (!rc && cmd->needs_client) {
    ctx.server_url = server ? server : getenv("RAYSWEEP_URL");
    if (!ctx.server_url || !*ctx.server_url) ctx.server_url = DEFAULT_URL;
    rc = read_token(&ctx, token_file, &token);
    ctx.token = token;
    double connect_s = 0, stall_s = 0;
    if (!rc)
      rc = transfer_limit(&ctx, "--connect-timeout", connect_to, "RAYSWEEP_CONNECT_TIMEOUT", false,
                          &connect_s);
    if (!rc) rc = transfer_limit(&ctx, "--stall-timeout", stall_to, "RAYSWEEP_STALL_TIMEOUT", true, &stall_s);
    const char *route_opt = route ? "--route" : "RAYSWEEP_ROUTE";
    if (!route) route = getenv("RAYSWEEP_ROUTE");
    if (route && !*route) route = NULL;
    ctx.route = route;
    if (!rc) {
      rsw_client_opts o = {.size = sizeof o,
                           .base_url = ctx.server_url,
                           .token = token,
                           .interrupt = &cli_interrupted,
                           .connect_timeout_s = connect_s,
                           .stall_timeout_s = stall_s};
      rsw_status s = rsw_client_new(&o, &ctx.client);
      if (s)
        rc = cli_fail(&ctx, s == RSW_ERR_INVALID ? CLI_USAGE : CLI_IO, "cannot create a client for '%s': %s",
                      ctx.server_url, rsw_strerror(s));
      /* (the library's rule for a key, and its own error) */
      else if (route && (s = rsw_client_set_route(ctx.client, route)))
        rc = s == RSW_ERR_INVALID
                 ? cli_usage(&ctx, "%s '%s': a routing key is 1 to 64 of A-Z a-z 0-9 . _ -", route_opt, route)
                 : cli_fail(&ctx, CLI_IO, "out of memory");
    }
  }
  if (!rc) rc = cmd->run(&ctx, &args);
  rsw_client_free(ctx.client);
  free(token);
  cmdline_free(&args);
  free(rest);
  return rc;
}
