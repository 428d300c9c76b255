/* The command-line tables the client and the daemon share
 * (common/cmdline.c): values by name and alias, last-wins and repeatable
 * options, --name=value, attached short options, "--", and what is refused
 * (unknown options, a missing value, a flag given a value); and the usage
 * lines' wrapping at column 100. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../support/test.h"
#include "cmdline.h"

RSW_TEST_DEFINE_GLOBALS

static const cmdline_opt opts[] = {
    {"-o", "OUT", 0, NULL},
    {"--output", "OUT", CMDLINE_ALIAS, NULL},
    {"--spp", "N", 0, NULL},
    {"--set", "KEY=VALUE", CMDLINE_REPEAT, NULL},
    {"-D", "name=value", CMDLINE_REPEAT | CMDLINE_ATTACHED, NULL},
    {"--stats", NULL, 0, NULL},
    {NULL},
};

static cmdline_status parse(cmdline_args *a, cmdline_error *e, char **argv) {
  int argc = 0;
  while (argv[argc]) argc++;
  return cmdline_parse(opts, argc, argv, a, e);
}

static void test_values(void) {
  char *argv[] = {"scene.xml", "--spp", "4",  "--output", "a.exr",   "--set",   "k=1", "-o", "b.exr",
                  "--set=j=2", "-Dx=1", "-D", "y=2",      "--spp=8", "--stats", "--",  "-o", NULL};
  cmdline_args a;
  cmdline_error e;
  REQUIRE(parse(&a, &e, argv) == CMDLINE_OK, "parse failed at '%s'", e.word ? e.word : "?");
  CHECK(a.n_pos == 2 && strcmp(a.pos[0], "scene.xml") == 0 && strcmp(a.pos[1], "-o") == 0,
        "positionals: %zu (after -- a word is positional)", a.n_pos);
  CHECK(strcmp(cmdline_get(&a, "-o"), "b.exr") == 0, "-o: last of -o/--output wins, got %s",
        cmdline_get(&a, "-o"));
  CHECK(strcmp(cmdline_get(&a, "--output"), "b.exr") == 0, "--output reads as -o");
  CHECK(strcmp(cmdline_get(&a, "--spp"), "8") == 0, "--spp=8 (last) got %s", cmdline_get(&a, "--spp"));
  size_t n;
  const char *const *sets = cmdline_get_all(&a, "--set", &n);
  CHECK(n == 2 && strcmp(sets[0], "k=1") == 0 && strcmp(sets[1], "j=2") == 0, "--set values: %zu", n);
  const char *const *defs = cmdline_get_all(&a, "-D", &n);
  CHECK(n == 2 && strcmp(defs[0], "x=1") == 0 && strcmp(defs[1], "y=2") == 0, "-D values: %zu", n);
  CHECK(cmdline_has(&a, "--stats") && strcmp(cmdline_get(&a, "--stats"), "") == 0, "--stats flag");
  CHECK(!cmdline_has(&a, "--nope") && !cmdline_get(&a, "--nope"), "an unknown name is absent");
  cmdline_free(&a);
}

static void test_refusals(void) {
  struct {
    char *argv[4];
    cmdline_status want;
    const char *word;
    int name_len;
  } cases[] = {
      {{"--bogus=3", NULL}, CMDLINE_UNKNOWN, "--bogus=3", 7},
      {{"-x", NULL}, CMDLINE_UNKNOWN, "-x", 2},
      {{"-oFILE", NULL}, CMDLINE_UNKNOWN, "-oFILE", 6}, /* only -D takes an attached value */
      {{"-o=FILE", NULL}, CMDLINE_UNKNOWN, "-o=FILE", 7},
      {{"a", "--spp", NULL}, CMDLINE_NEEDS_VALUE, "--spp", 5},
      {{"--output", NULL}, CMDLINE_NEEDS_VALUE, "--output", 8},
      {{"--stats=1", NULL}, CMDLINE_NO_VALUE, "--stats=1", 7},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    cmdline_args a;
    cmdline_error e;
    cmdline_status s = parse(&a, &e, cases[i].argv);
    CHECK(s == cases[i].want, "case %zu: status %d, want %d", i, (int)s, (int)cases[i].want);
    CHECK(e.word && strcmp(e.word, cases[i].word) == 0 && e.name_len == cases[i].name_len,
          "case %zu: word '%s' (%d)", i, e.word ? e.word : "(null)", e.name_len);
    if (s == CMDLINE_NEEDS_VALUE) CHECK(e.opt == &opts[0] || e.opt == &opts[2], "case %zu: the option", i);
    cmdline_free(&a);
  }
  /* Lone "-" is a positional (stdin by convention). */
  char *argv[] = {"-", NULL};
  cmdline_args a;
  cmdline_error e;
  CHECK(parse(&a, &e, argv) == CMDLINE_OK && a.n_pos == 1, "'-' is a positional");
  cmdline_free(&a);
}

static void test_usage_wrap(void) {
  char *buf = NULL;
  size_t len = 0;
  FILE *f = open_memstream(&buf, &len);
  REQUIRE(f, "open_memstream");
  cmdline_print_usage(f, "usage: ", "prog", "cmd",
                      "SCENE [--aaaaaaaaaa N] [--bbbbbbbbbb N] [--cccccccccc N] [--dddddddddd N] "
                      "[--eeeeeeeeee N] -o OUT.exr|OUT.npy");
  fclose(f);
  /* Every line within 100 columns, continuation lines indented under the
   * arguments, "-o OUT..." kept on one line. */
  const char *want =
      "usage: prog cmd SCENE [--aaaaaaaaaa N] [--bbbbbbbbbb N] [--cccccccccc N] [--dddddddddd N]\n"
      "                [--eeeeeeeeee N] -o OUT.exr|OUT.npy\n";
  CHECK(strcmp(buf, want) == 0, "got:\n%s", buf);
  free(buf);
}

int main(void) {
  RSW_TEST_RUN(test_values);
  RSW_TEST_RUN(test_refusals);
  RSW_TEST_RUN(test_usage_wrap);
  RSW_TEST_END("test_cmdline");
}
