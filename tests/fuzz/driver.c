/* Replays inputs through one fuzz harness without libFuzzer, so that the
 * checked-in corpus and every past crash input run in `make test` (normal
 * and SAN builds, any C compiler).
 *
 *   fuzz_NAME [FILE|DIR]...
 *
 * Without arguments it replays $RSW_TEST_DIR/fuzz/corpus/NAME and
 * $RSW_TEST_DIR/fuzz/crashes/NAME (RSW_TEST_DIR defaults to "tests"), NAME
 * being this program's name less "fuzz_" (with FUZZ_PENDING=1 also
 * $RSW_TEST_DIR/fuzz/pending/NAME). Each input that returns counts as
 * passed; a crash or an abort ends the program (tests/run.sh counts that as
 * a failure). Closing line: "fuzz_NAME: N passed, 0 failed". */
#include <dirent.h>
#include <libgen.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "fuzz.h"

__attribute__((weak)) int LLVMFuzzerInitialize(int *argc, char ***argv) {
  (void)argc;
  (void)argv;
  return 0;
}

static int n_pass, n_fail;

static void run_file(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    fprintf(stderr, "FAIL cannot open %s\n", path);
    n_fail++;
    return;
  }
  size_t cap = 4096, len = 0;
  uint8_t *buf = malloc(cap);
  size_t got;
  while (buf && (got = fread(buf + len, 1, cap - len, f)) > 0) {
    len += got;
    if (len == cap) {
      uint8_t *nb = realloc(buf, cap * 2);
      if (!nb) {
        free(buf);
        buf = NULL;
        break;
      }
      buf = nb;
      cap *= 2;
    }
  }
  fclose(f);
  if (!buf) {
    fprintf(stderr, "FAIL out of memory reading %s\n", path);
    n_fail++;
    return;
  }
  /* Exactly len bytes, like libFuzzer (ASan sees reads past the end). */
  uint8_t *exact = malloc(len ? len : 1);
  if (exact && len) memcpy(exact, buf, len);
  free(buf);
  if (!exact) {
    n_fail++;
    return;
  }
  if (getenv("FUZZ_VERBOSE")) fprintf(stderr, "input %s (%zu bytes)\n", path, len);
  LLVMFuzzerTestOneInput(exact, len);
  free(exact);
  n_pass++;
}

static int cmp_str(const void *a, const void *b) {
  return strcmp(*(char *const *)a, *(char *const *)b);
}

/* Every regular file of a directory (not recursive), in name order. A
 * missing directory is fine (no crash inputs yet). */
static void run_dir(const char *dir, bool must_exist) {
  DIR *d = opendir(dir);
  if (!d) {
    if (must_exist) {
      fprintf(stderr, "FAIL no directory %s\n", dir);
      n_fail++;
    }
    return;
  }
  char **names = NULL;
  size_t n = 0, cap = 0;
  struct dirent *e;
  while ((e = readdir(d))) {
    if (e->d_name[0] == '.') continue;
    if (n == cap) {
      cap = cap ? cap * 2 : 64;
      char **nn = realloc(names, cap * sizeof *names);
      if (!nn) break;
      names = nn;
    }
    size_t l = strlen(dir) + strlen(e->d_name) + 2;
    names[n] = malloc(l);
    if (!names[n]) break;
    snprintf(names[n], l, "%s/%s", dir, e->d_name);
    n++;
  }
  closedir(d);
  if (n) qsort(names, n, sizeof *names, cmp_str);
  for (size_t i = 0; i < n; i++) {
    struct stat st;
    if (stat(names[i], &st) == 0 && S_ISREG(st.st_mode)) run_file(names[i]);
    free(names[i]);
  }
  free(names);
}

int main(int argc, char **argv) {
  char prog[256];
  snprintf(prog, sizeof prog, "%s", argv[0]);
  const char *name = basename(prog);
  LLVMFuzzerInitialize(&argc, &argv);
  if (argc > 1) {
    for (int i = 1; i < argc; i++) {
      struct stat st;
      if (stat(argv[i], &st) == 0 && S_ISDIR(st.st_mode))
        run_dir(argv[i], true);
      else
        run_file(argv[i]);
    }
  } else {
    const char *td = getenv("RSW_TEST_DIR");
    if (!td || !*td) td = "tests";
    const char *h = strncmp(name, "fuzz_", 5) == 0 ? name + 5 : name;
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/fuzz/corpus/%s", td, h);
    run_dir(dir, true);
    snprintf(dir, sizeof dir, "%s/fuzz/crashes/%s", td, h);
    run_dir(dir, false);
    /* Crash inputs whose fix is on another branch (tests/fuzz/README.md). */
    const char *pend = getenv("FUZZ_PENDING");
    if (pend && *pend && strcmp(pend, "0") != 0) {
      snprintf(dir, sizeof dir, "%s/fuzz/pending/%s", td, h);
      run_dir(dir, false);
    }
  }
  if (n_pass == 0 && n_fail == 0) {
    fprintf(stderr, "FAIL %s: no inputs\n", name);
    n_fail = 1;
  }
  printf("%s: %d passed, %d failed\n", name, n_pass, n_fail);
  return n_fail ? 1 : 0;
}
