/* Command lines read against option tables: the raysweep client
 * (client/cli/main.c) and the daemon (server/main.c, server/serve.c) parse
 * argv the same way, and print usage lines the same way.
 *
 * Syntax: options and positionals in any order; an option with a value
 * takes the next word (`--spp 64`) or, for a long option, `--spp=64`; an
 * `attached` short option also `-Dname=value`; after `--` every word is a
 * positional; a lone "-" is a positional. A repeatable option keeps every
 * value in order, any other the last one given. */
#ifndef RSW_COMMON_CMDLINE_H
#define RSW_COMMON_CMDLINE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>

/* cmdline_opt.flags */
enum {
  CMDLINE_REPEAT = 1,   /* may be given several times (otherwise the last wins); `true` reads as it */
  CMDLINE_ATTACHED = 2, /* a short option whose value may follow it in the same word */
  CMDLINE_ALIAS = 4     /* another name of the entry before it ("--output" after "-o") */
};

/* One option a command accepts. arg: the value's placeholder for help (the
 * option takes a value), NULL for a flag. */
typedef struct cmdline_opt {
  const char *name; /* "--spp", "-o" */
  const char *arg;
  unsigned flags;   /* CMDLINE_* */
  const char *help; /* one line for generated help, or NULL */
} cmdline_opt;

#define CMDLINE_MAX_OPTS 24

/* A parsed command line: positionals, and the values of each option in the
 * order given (index = the option's index in its table; a flag's value is
 * ""). */
typedef struct cmdline_args {
  const char **pos;
  size_t n_pos;
  const cmdline_opt *opts;
  size_t n_opts;
  const char **vals[CMDLINE_MAX_OPTS];
  size_t n_vals[CMDLINE_MAX_OPTS];
} cmdline_args;

typedef enum cmdline_status {
  CMDLINE_OK = 0,
  CMDLINE_UNKNOWN,     /* a word that looks like an option is none of the table's */
  CMDLINE_NEEDS_VALUE, /* an option that takes a value ends the command line */
  CMDLINE_NO_VALUE,    /* a flag given a value (--flag=x) */
  CMDLINE_NOMEM
} cmdline_status;

/* What cmdline_parse refused: the word as given, the length of its option
 * name (up to an '='), and the option (NEEDS_VALUE, NO_VALUE). */
typedef struct cmdline_error {
  const char *word;
  int name_len;
  const cmdline_opt *opt;
} cmdline_error;

/* Parse argv[0..argc) against opts (terminated by a {NULL} entry, at most
 * CMDLINE_MAX_OPTS). *a is filled (and must be freed with cmdline_free)
 * whatever the outcome; *err on a refusal. */
cmdline_status cmdline_parse(const cmdline_opt *opts, int argc, char **argv, cmdline_args *a,
                             cmdline_error *err);
void cmdline_free(cmdline_args *a);

/* Last value of option `name`, or NULL when absent. */
const char *cmdline_get(const cmdline_args *a, const char *name);
/* All values of option `name` (borrowed), count through *n. */
const char *const *cmdline_get_all(const cmdline_args *a, const char *name, size_t *n);
bool cmdline_has(const cmdline_args *a, const char *name);

/* Print "PREFIX PROGRAM NAME ARGS", wrapped before column 100 at spaces
 * outside brackets and parentheses (a flag keeps its value: "-o DIR"),
 * continuation lines aligned after "PROGRAM NAME ". */
void cmdline_print_usage(FILE *f, const char *prefix, const char *program, const char *name, const char *args);

#endif
