/* The malformed-scene corpus (tests/corpus/bad/bad_*.json, bad_*.xml): every
 * file must fail to load with a clear error and never crash.
 *
 * Each file is checked twice:
 *  - in process, with scene_load_file(): a non-OK status, no scene, a
 *    non-empty message and a non-empty place (err.where) that names the
 *    scene file or the mesh file it references; in the SAN build ASan/LSan
 *    also catch any leak or bad access on the error paths;
 *  - through the daemon, `raysweepd render FILE -o OUT` spawned as a child
 *    (RSW_BIN_DIR, default build/bin): it must exit normally (not by a
 *    signal) with a non-zero status, print a line starting
 *    "raysweepd render: ", print no sanitizer report, and write no image.
 *
 * The directory is read at run time, so a new corpus file is covered
 * without touching this test. Bad command lines are checked the same way,
 * next to a positive control (a good scene renders and writes its image)
 * that shows the "no image written" checks can fail. */
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <spawn.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../../../server/kernel/scene/scene.h"
#include "../../support/test.h"

RSW_TEST_DEFINE_GLOBALS

extern char **environ;

#define MAX_FILES 512
#define PATH_LEN  1024

/* Fewer than this many corpus scenes means the directory was not found or
 * the corpus lost files (the issue asks for at least 30). */
#define MIN_CORPUS 30

typedef struct corpus {
  char dir[PATH_LEN];
  char *names[MAX_FILES];
  int n;
  int n_json, n_xml;
} corpus;

/* Per-run scratch paths under a private temporary directory. */
typedef struct scratch {
  char dir[PATH_LEN];
  char out[PATH_LEN + 32];  /* the image a render must not write */
  char err[PATH_LEN + 32];  /* the child's captured stderr */
  char good[PATH_LEN + 32]; /* a valid JSON scene for the command-line tests */
  char bin[PATH_LEN];       /* raysweepd */
} scratch;

static corpus g_corpus;
static scratch g_scratch;

/* The child's outcome. */
typedef struct child_result {
  bool spawned;
  bool exited; /* ended through exit(), not a signal */
  int status;  /* exit status, or the signal number */
  char text[8192];
} child_result;

static bool ends_with(const char *s, const char *suffix) {
  size_t ls = strlen(s), lx = strlen(suffix);
  return ls >= lx && strcmp(s + ls - lx, suffix) == 0;
}

static int cmp_names(const void *a, const void *b) {
  return strcmp(*(char *const *)a, *(char *const *)b);
}

static bool file_exists(const char *path) {
  struct stat sb;
  return stat(path, &sb) == 0;
}

/* Read the corpus directory: <RSW_TEST_DIR or "tests">/corpus/bad. */
static void corpus_read(corpus *c) {
  const char *tests = getenv("RSW_TEST_DIR");
  snprintf(c->dir, sizeof c->dir, "%s/corpus/bad", tests && *tests ? tests : "tests");
  DIR *d = opendir(c->dir);
  if (!d) return;
  struct dirent *e;
  while ((e = readdir(d)) != NULL && c->n < MAX_FILES) {
    if (strncmp(e->d_name, "bad_", 4) != 0) continue;
    bool json = ends_with(e->d_name, ".json"), xml = ends_with(e->d_name, ".xml");
    if (!json && !xml) continue;
    char *name = strdup(e->d_name);
    if (!name) break;
    c->names[c->n++] = name;
    c->n_json += json;
    c->n_xml += xml;
  }
  closedir(d);
  qsort(c->names, (size_t)c->n, sizeof c->names[0], cmp_names);
}

static void corpus_free(corpus *c) {
  for (int i = 0; i < c->n; i++) free(c->names[i]);
  c->n = 0;
}

static bool write_text(const char *path, const char *text) {
  FILE *f = fopen(path, "w");
  if (!f) return false;
  bool ok = fputs(text, f) >= 0;
  return fclose(f) == 0 && ok;
}

/* A small valid scene: the command-line tests need one that loads, so that
 * each failure is the flag's, not the scene's. */
static const char good_scene[] =
    "{\"type\": \"scene\",\n"
    " \"cam\": {\"type\": \"perspective\",\n"
    "   \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}],\n"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4},\n"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 2}},\n"
    " \"integrator\": {\"type\": \"path\"},\n"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.0},\n"
    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}\n";

static bool scratch_init(scratch *s) {
  snprintf(s->dir, sizeof s->dir, "/tmp/rsw_corpus_XXXXXX");
  if (!mkdtemp(s->dir)) return false;
  snprintf(s->out, sizeof s->out, "%s/out.exr", s->dir);
  snprintf(s->err, sizeof s->err, "%s/stderr.txt", s->dir);
  snprintf(s->good, sizeof s->good, "%s/good.json", s->dir);
  const char *bin = getenv("RSW_BIN_DIR");
  snprintf(s->bin, sizeof s->bin, "%s/raysweepd", bin && *bin ? bin : "build/bin");
  return write_text(s->good, good_scene);
}

static void scratch_free(scratch *s) {
  unlink(s->out);
  unlink(s->err);
  unlink(s->good);
  rmdir(s->dir);
}

/* Run raysweepd with argv (argv[0] is filled in), stdout to /dev/null and
 * stderr captured into r->text. */
static void run_daemon(char **argv, child_result *r) {
  memset(r, 0, sizeof *r);
  argv[0] = g_scratch.bin;
  unlink(g_scratch.out);
  posix_spawn_file_actions_t fa;
  if (posix_spawn_file_actions_init(&fa)) return;
  posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 2, g_scratch.err, O_WRONLY | O_CREAT | O_TRUNC, 0600);
  pid_t pid;
  int rc = posix_spawn(&pid, g_scratch.bin, &fa, NULL, argv, environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) return;
  r->spawned = true;
  int ws;
  while (waitpid(pid, &ws, 0) < 0)
    if (errno != EINTR) return;
  r->exited = WIFEXITED(ws);
  r->status = r->exited ? WEXITSTATUS(ws) : (WIFSIGNALED(ws) ? WTERMSIG(ws) : -1);
  FILE *f = fopen(g_scratch.err, "rb");
  if (f) {
    size_t n = fread(r->text, 1, sizeof r->text - 1, f);
    r->text[n] = '\0';
    fclose(f);
  }
}

/* Does any line of text start with prefix? */
static bool has_line_starting(const char *text, const char *prefix) {
  size_t lp = strlen(prefix);
  for (const char *l = text; l && *l; l = strchr(l, '\n') ? strchr(l, '\n') + 1 : NULL)
    if (strncmp(l, prefix, lp) == 0) return true;
  return false;
}

/* A sanitizer report in the child's stderr ("ERROR: AddressSanitizer",
 * "ERROR: LeakSanitizer", UBSan's "runtime error:"). */
static bool has_sanitizer_report(const char *text) {
  return strstr(text, "Sanitizer") != NULL || strstr(text, "runtime error:") != NULL;
}

/* First line of text, for failure messages. */
static const char *first_line(const char *text, char *buf, size_t len) {
  size_t n = strcspn(text, "\n");
  if (n >= len) n = len - 1;
  memcpy(buf, text, n);
  buf[n] = '\0';
  return buf;
}

/* ---- the corpus ------------------------------------------------------------------ */

static void test_corpus_size(void) {
  REQUIRE(g_corpus.n > 0, "no corpus files found in %s (run from the repository root or set RSW_TEST_DIR)",
          g_corpus.dir);
  CHECK(g_corpus.n >= MIN_CORPUS, "%d corpus scenes in %s, expected at least %d", g_corpus.n, g_corpus.dir,
        MIN_CORPUS);
  CHECK(g_corpus.n_json >= MIN_CORPUS, "%d bad JSON scenes, expected at least %d", g_corpus.n_json,
        MIN_CORPUS);
  CHECK(g_corpus.n_xml >= MIN_CORPUS, "%d bad XML scenes, expected at least %d", g_corpus.n_xml, MIN_CORPUS);
}

/* Messages that must say something specific (the rest only need to be
 * non-empty and placed). */
typedef struct expect_msg {
  const char *file;
  const char *needle; /* in err.msg */
} expect_msg;

static const expect_msg expected_messages[] = {
    {"bad_json_misspelt_plugin.json", "did you mean 'diffuse'"},
    {"bad_scene_misspelt_plugin.xml", "did you mean 'roughconductor'"},
    {"bad_json_unknown_plugin.json", "teapot"},
    {"bad_json_dangling_ref.json", "nowhere"},
    {"bad_scene_dangling_ref.xml", "gold"},
    {"bad_json_ref_cycle.json", "cycle"},
    {"bad_scene_ref_cycle.xml", "cycle"},
    {"bad_json_unused_property.json", "reflectence"},
    {"bad_scene_unused_property.xml", "radus"},
    {"bad_json_duplicate_key.json", "duplicate"},
    {"bad_json_nested_too_deep.json", "64"},
    {"bad_json_unknown_variant.json", "spectral"},
    {"bad_json_two_environments.json", "environment"},
    {"bad_json_area_top_level.json", "area"},
    {"bad_json_missing_mesh.json", "no_such_mesh.ply"},
    {"bad_json_truncated_ply.json", "truncated"},
    {"bad_scene_truncated_ply.xml", "truncated"},
    {"bad_json_conductor_unknown_material.json", "Unobtainium"},
    {"bad_json_tabulated_in_rgb.json", "mono"},
    {"bad_json_trailing_garbage.json", "after the JSON document"},
    {"bad_json_list_id_clash.json", "already names"},
    {"bad_json_nul_in_filename.json", "'filename': a string contains \\u0000"},
};

static const char *expected_needle(const char *file) {
  for (size_t i = 0; i < sizeof expected_messages / sizeof expected_messages[0]; i++)
    if (strcmp(expected_messages[i].file, file) == 0) return expected_messages[i].needle;
  return NULL;
}

static void test_corpus_in_process(void) {
  REQUIRE(g_corpus.n > 0, "no corpus files");
  for (int i = 0; i < g_corpus.n; i++) {
    const char *name = g_corpus.names[i];
    char path[PATH_LEN * 2];
    snprintf(path, sizeof path, "%s/%s", g_corpus.dir, name);
    rsw_err err = {0};
    scene *sc = NULL;
    scene_load_opts lo = {.size = sizeof lo};
    rsw_status st = scene_load_file(path, &lo, &sc, &err);
    CHECK(st != RSW_OK, "%s: loaded, expected an error", name);
    CHECK(sc == NULL, "%s: a scene was returned with the error", name);
    CHECK(err.code == st, "%s: err.code %d differs from the status %d", name, (int)err.code, (int)st);
    CHECK(err.msg[0] != '\0', "%s: empty error message", name);
    CHECK(err.where[0] != '\0', "%s: error without a place (message: %s)", name, err.msg);
    /* The place names the scene (file#/pointer, file:line) or, for mesh
     * errors, the mesh file the scene references. */
    CHECK(strstr(err.where, name) != NULL || strstr(err.where, "/meshes/") != NULL,
          "%s: error place '%s' names neither the scene nor a mesh file", name, err.where);
    const char *needle = expected_needle(name);
    if (needle) CHECK(strstr(err.msg, needle) != NULL, "%s: message '%s' lacks '%s'", name, err.msg, needle);
    scene_free(sc); /* NULL here; LSan checks nothing of the failed load leaked */
  }
}

static void test_corpus_daemon(void) {
  REQUIRE(g_corpus.n > 0, "no corpus files");
  REQUIRE(file_exists(g_scratch.bin), "%s not found (build it, or set RSW_BIN_DIR)", g_scratch.bin);
  for (int i = 0; i < g_corpus.n; i++) {
    const char *name = g_corpus.names[i];
    char path[PATH_LEN * 2];
    snprintf(path, sizeof path, "%s/%s", g_corpus.dir, name);
    char *argv[] = {NULL, "render", path, "-o", g_scratch.out, NULL};
    child_result r;
    run_daemon(argv, &r);
    char line[300];
    REQUIRE(r.spawned, "%s: could not spawn %s", name, g_scratch.bin);
    CHECK(r.exited, "%s: raysweepd killed by signal %d", name, r.status);
    CHECK(!r.exited || r.status != 0, "%s: raysweepd exited 0", name);
    CHECK(has_line_starting(r.text, "raysweepd render: "), "%s: no 'raysweepd render: ' line on stderr: %s",
          name, first_line(r.text, line, sizeof line));
    CHECK(!has_sanitizer_report(r.text), "%s: sanitizer report from raysweepd:\n%s", name, r.text);
    CHECK(!file_exists(g_scratch.out), "%s: an output image was written", name);
  }
}

/* Every proper prefix of a good scene (a file cut short anywhere) must fail
 * with a placed message: truncation is the commonest corruption, and each
 * cut lands the parsers in a different state. */
static const char good_xml_scene[] =
    "<scene version=\"3.0.0\">\n"
    "  <sensor type=\"perspective\">\n"
    "    <transform name=\"to_world\"><lookat origin=\"0, 0, 5\" target=\"0, 0, 0\" up=\"0, 1, "
    "0\"/></transform>\n"
    "    <film type=\"hdrfilm\"><integer name=\"width\" value=\"4\"/><integer name=\"height\" "
    "value=\"4\"/></film>\n"
    "  </sensor>\n"
    "  <emitter type=\"directional\"><vector name=\"direction\" x=\"0\" y=\"0\" z=\"-1\"/></emitter>\n"
    "  <shape type=\"rectangle\"><bsdf type=\"diffuse\"><rgb name=\"reflectance\" "
    "value=\"0.5\"/></bsdf></shape>\n"
    "</scene>\n";

static void check_prefixes(const char *text, bool is_xml) {
  size_t len = strlen(text);
  /* The whole scene loads: otherwise the prefixes prove nothing. */
  rsw_err err = {0};
  scene *sc = NULL;
  rsw_status st = scene_load_memory(text, len, "good", is_xml, NULL, &sc, &err);
  REQUIRE(st == RSW_OK && sc, "the complete %s scene fails: %s: %s", is_xml ? "XML" : "JSON", err.where,
          err.msg);
  scene_free(sc);
  int bad = 0;
  for (size_t n = 0; n < len; n++) {
    /* A prefix that ends in whitespace after the root's close is complete. */
    bool complete = strspn(text + n, " \t\r\n") == len - n;
    memset(&err, 0, sizeof err);
    sc = NULL;
    /* An exact-size copy without a terminator: ASan then catches any read
     * past `len`, which the API's length argument promises not to do. */
    char *cut = malloc(n ? n : 1);
    REQUIRE(cut, "out of memory");
    memcpy(cut, text, n);
    st = scene_load_memory(cut, n, "cut", is_xml, NULL, &sc, &err);
    free(cut);
    scene_free(sc);
    if (complete) continue;
    if (st == RSW_OK || !err.msg[0] || !err.where[0]) {
      if (bad++ < 5)
        CHECK(false, "%s scene cut to %zu of %zu bytes: status %d, where '%s', message '%s'",
              is_xml ? "XML" : "JSON", n, len, (int)st, err.where, err.msg);
    }
  }
  CHECK(bad == 0, "%d truncated %s scenes loaded or failed without a placed message", bad,
        is_xml ? "XML" : "JSON");
}

static void test_truncated_prefixes(void) {
  check_prefixes(good_scene, false);
  check_prefixes(good_xml_scene, true);
}

/* ---- command lines ----------------------------------------------------------------- */

/* Run a command line and check: normal exit with `want` (1 or 2), a
 * "raysweepd" message on stderr, no sanitizer report, no image. */
static void check_bad_cmdline(const char *what, char **argv, int want) {
  child_result r;
  run_daemon(argv, &r);
  char line[300];
  REQUIRE(r.spawned, "%s: could not spawn %s", what, g_scratch.bin);
  CHECK(r.exited, "%s: raysweepd killed by signal %d", what, r.status);
  CHECK(!r.exited || r.status == want, "%s: exit status %d, expected %d (%s)", what, r.status, want,
        first_line(r.text, line, sizeof line));
  CHECK(strncmp(r.text, "raysweepd", 9) == 0 || strncmp(r.text, "usage:", 6) == 0,
        "%s: stderr does not start with a raysweepd message: '%s'", what,
        first_line(r.text, line, sizeof line));
  CHECK(!has_sanitizer_report(r.text), "%s: sanitizer report from raysweepd:\n%s", what, r.text);
  CHECK(!file_exists(g_scratch.out), "%s: an output image was written", what);
}

/* The positive control: without it every "no image written" check above
 * could pass for a wrong output path. */
static void test_good_scene_renders(void) {
  REQUIRE(file_exists(g_scratch.bin), "%s not found", g_scratch.bin);
  char *argv[] = {NULL, "render", g_scratch.good, "--spp", "1", "-o", g_scratch.out, NULL};
  child_result r;
  run_daemon(argv, &r);
  REQUIRE(r.spawned, "could not spawn %s", g_scratch.bin);
  CHECK(r.exited && r.status == 0, "good scene: exited=%d status %d: %s", r.exited, r.status, r.text);
  CHECK(file_exists(g_scratch.out), "good scene: no image written to %s", g_scratch.out);
  CHECK(has_line_starting(r.text, "raysweepd render: wrote "), "good scene: no 'wrote' line: %s", r.text);
  unlink(g_scratch.out);
}

static void test_bad_command_lines(void) {
  REQUIRE(file_exists(g_scratch.bin), "%s not found", g_scratch.bin);
  char *good = g_scratch.good, *out = g_scratch.out;
  char missing[PATH_LEN + 32];
  snprintf(missing, sizeof missing, "%s/no_such_scene.json", g_scratch.dir);
  struct {
    const char *what;
    char *argv[12];
    int want;
  } cases[] = {
      {"no subcommand", {NULL, NULL}, 2},
      {"unknown subcommand", {NULL, "rendr", good, "-o", out, NULL}, 2},
      {"unknown option", {NULL, "render", good, "--bogus", "-o", out, NULL}, 2},
      {"--spp 0", {NULL, "render", good, "--spp", "0", "-o", out, NULL}, 2},
      {"--spp abc", {NULL, "render", good, "--spp", "abc", "-o", out, NULL}, 2},
      {"--spp -3", {NULL, "render", good, "--spp", "-3", "-o", out, NULL}, 2},
      {"--spp without a value", {NULL, "render", good, "-o", out, "--spp", NULL}, 2},
      {"--threads 0", {NULL, "render", good, "--threads", "0", "-o", out, NULL}, 2},
      {"--threads 100000", {NULL, "render", good, "--threads", "100000", "-o", out, NULL}, 2},
      {"--seed -1", {NULL, "render", good, "--seed", "-1", "-o", out, NULL}, 2},
      {"--wavelength -5", {NULL, "render", good, "--wavelength", "-5", "-o", out, NULL}, 2},
      {"--wavelength nan", {NULL, "render", good, "--wavelength", "nan", "-o", out, NULL}, 2},
      {"missing -o", {NULL, "render", good, NULL}, 2},
      {"-o without a file", {NULL, "render", good, "-o", NULL}, 2},
      {"missing scene file", {NULL, "render", "-o", out, NULL}, 2},
      {"two scene files", {NULL, "render", good, good, "-o", out, NULL}, 2},
      {"-D without '='", {NULL, "render", good, "-Dfoo", "-o", out, NULL}, 2},
      /* A usage error after a -D: the definitions parsed so far must still
       * be freed (LSan in the SAN build). */
      {"-D then an unknown option", {NULL, "render", good, "-Dfoo=1", "--bogus", "-o", out, NULL}, 2},
      {"-D then -o without a file", {NULL, "render", good, "-D", "foo=1", "-o", NULL}, 2},
      {"nonexistent scene file", {NULL, "render", missing, "-o", out, NULL}, 1},
      {"scene file is a directory", {NULL, "render", g_scratch.dir, "-o", out, NULL}, 1},
      {"-D on a JSON scene", {NULL, "render", good, "-Dradius=2", "-o", out, NULL}, 1},
      {"--sensor naming no sensor", {NULL, "render", good, "--sensor", "nosuch", "-o", out, NULL}, 1},
      {"--sensor index out of range", {NULL, "render", good, "--sensor", "5", "-o", out, NULL}, 1},
      {"--variant spectral", {NULL, "render", good, "--variant", "spectral", "-o", out, NULL}, 1},
      {"output in a missing directory",
       {NULL, "render", good, "--spp", "1", "-o", "/nonexistent_rsw_dir/out.exr", NULL},
       1},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
    check_bad_cmdline(cases[i].what, cases[i].argv, cases[i].want);

  /* More -D definitions than the daemon holds (256). */
  enum {
    N_DEFS = 300
  };
  static char defs[N_DEFS][32];
  char *argv[N_DEFS + 8];
  int k = 0;
  argv[k++] = NULL;
  argv[k++] = "render";
  argv[k++] = good;
  for (int i = 0; i < N_DEFS; i++) {
    snprintf(defs[i], sizeof defs[i], "-Dp%d=1", i);
    argv[k++] = defs[i];
  }
  argv[k++] = "-o";
  argv[k++] = out;
  argv[k] = NULL;
  check_bad_cmdline("300 -D definitions", argv, 2);
}

int main(void) {
  corpus_read(&g_corpus);
  if (!scratch_init(&g_scratch)) {
    fprintf(stdout, "FAIL cannot create a scratch directory under /tmp\n");
    rsw_test_failed_++;
    corpus_free(&g_corpus);
    RSW_TEST_END("test_corpus");
  }
  RSW_TEST_RUN(test_corpus_size);
  RSW_TEST_RUN(test_corpus_in_process);
  RSW_TEST_RUN(test_truncated_prefixes);
  RSW_TEST_RUN(test_good_scene_renders);
  RSW_TEST_RUN(test_corpus_daemon);
  RSW_TEST_RUN(test_bad_command_lines);
  scratch_free(&g_scratch);
  corpus_free(&g_corpus);
  RSW_TEST_END("test_corpus");
}
