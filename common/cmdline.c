/* Command lines against option tables (cmdline.h). */
#include "cmdline.h"

#include <stdlib.h>
#include <string.h>

/* The option named word[0..len), or the attached short option word starts
 * with; -1 when none. *attached: the value follows the name in the word.
 * An alias gives the entry it names. */
static int find_opt(const cmdline_opt *opts, size_t n, const char *word, size_t len, bool *attached) {
  *attached = false;
  int k = -1;
  for (size_t j = 0; j < n && k < 0; j++)
    if (strlen(opts[j].name) == len && strncmp(opts[j].name, word, len) == 0) k = (int)j;
  for (size_t j = 0; j < n && k < 0; j++) {
    size_t nl = strlen(opts[j].name);
    if ((opts[j].flags & CMDLINE_ATTACHED) && opts[j].arg && strlen(word) > nl &&
        strncmp(opts[j].name, word, nl) == 0) {
      *attached = true;
      k = (int)j;
    }
  }
  while (k > 0 && (opts[k].flags & CMDLINE_ALIAS)) k--;
  return k;
}

cmdline_status cmdline_parse(const cmdline_opt *opts, int argc, char **argv, cmdline_args *a,
                             cmdline_error *err) {
  memset(a, 0, sizeof *a);
  memset(err, 0, sizeof *err);
  a->opts = opts;
  while (opts[a->n_opts].name && a->n_opts < CMDLINE_MAX_OPTS) a->n_opts++;
  /* Every values array holds at most argc entries, so it is sized once. */
  a->pos = calloc((size_t)argc + 1, sizeof *a->pos);
  if (!a->pos) return CMDLINE_NOMEM;
  for (size_t i = 0; i < a->n_opts; i++)
    if (!(a->vals[i] = calloc((size_t)argc + 1, sizeof(char *)))) return CMDLINE_NOMEM;
  bool only_pos = false;
  for (int i = 0; i < argc; i++) {
    const char *arg = argv[i];
    if (!only_pos && strcmp(arg, "--") == 0) {
      only_pos = true;
      continue;
    }
    if (only_pos || arg[0] != '-' || arg[1] == '\0') {
      a->pos[a->n_pos++] = arg;
      continue;
    }
    const char *eq = strchr(arg, '=');
    size_t len = eq && strncmp(arg, "--", 2) == 0 ? (size_t)(eq - arg) : strlen(arg);
    bool attached;
    int k = find_opt(opts, a->n_opts, arg, len, &attached);
    err->word = arg;
    err->name_len = (int)len;
    if (k < 0) return CMDLINE_UNKNOWN;
    const cmdline_opt *o = &opts[k];
    err->opt = o;
    const char *val = "";
    if (attached) {
      val = arg + strlen(o->name);
    } else if (o->arg) {
      if (len < strlen(arg))
        val = arg + len + 1;
      else if (i + 1 < argc)
        val = argv[++i];
      else
        return CMDLINE_NEEDS_VALUE;
    } else if (len < strlen(arg)) {
      return CMDLINE_NO_VALUE;
    }
    if (!(o->flags & CMDLINE_REPEAT)) a->n_vals[k] = 0;
    a->vals[k][a->n_vals[k]++] = val;
  }
  memset(err, 0, sizeof *err);
  return CMDLINE_OK;
}

void cmdline_free(cmdline_args *a) {
  free(a->pos);
  for (size_t i = 0; i < a->n_opts; i++) free(a->vals[i]);
  memset(a, 0, sizeof *a);
}

static int opt_index(const cmdline_args *a, const char *name) {
  int k = -1;
  for (size_t i = 0; i < a->n_opts && k < 0; i++)
    if (strcmp(a->opts[i].name, name) == 0) k = (int)i;
  while (k > 0 && (a->opts[k].flags & CMDLINE_ALIAS)) k--;
  return k;
}

const char *cmdline_get(const cmdline_args *a, const char *name) {
  int i = opt_index(a, name);
  if (i < 0 || a->n_vals[i] == 0) return NULL;
  return a->vals[i][a->n_vals[i] - 1];
}

const char *const *cmdline_get_all(const cmdline_args *a, const char *name, size_t *n) {
  int i = opt_index(a, name);
  *n = i < 0 ? 0 : a->n_vals[i];
  return i < 0 ? NULL : a->vals[i];
}

bool cmdline_has(const cmdline_args *a, const char *name) {
  return cmdline_get(a, name) != NULL;
}

void cmdline_print_usage(FILE *f, const char *prefix, const char *program, const char *name, const char *args) {
  int indent = (int)strlen(prefix) + (int)strlen(program) + 1 + (int)strlen(name) + 1;
  int col = fprintf(f, "%s%s %s", prefix, program, name);
  const char *p = args;
  while (*p) {
    while (*p == ' ') p++;
    const char *q = p; /* the next word: up to a space at depth 0 */
    int depth = 0;
    bool joined = false;
    while (*q && (*q != ' ' || depth > 0)) {
      if (*q == '[' || *q == '(') depth++;
      if ((*q == ']' || *q == ')') && depth > 0) depth--;
      q++;
      /* A flag and its value stay together ("-o OUT.exr"). */
      if (*q == ' ' && depth == 0 && *p == '-' && !joined && q[1] && !strchr("-[(", q[1])) q++, joined = true;
    }
    if (q == p) break;
    if (col + 1 + (q - p) > 100)
      col = fprintf(f, "\n%*s", indent, "") - 1;
    else
      col += fprintf(f, " ");
    col += fprintf(f, "%.*s", (int)(q - p), p);
    p = q;
  }
  fputc('\n', f);
}
