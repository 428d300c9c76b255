/* `raysweepd render` end to end: the real binary, real files. Checks the
 * film that comes out (size, channels, metadata), the command-line
 * overrides (-D, --variant, --wavelength, --sensor, --spp, --seed), and
 * that a failed render leaves no output file. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../support/daemon.h"
#include "../support/test.h"
#include "image_exr.h"

RSW_TEST_DEFINE_GLOBALS

static char tmpdir[64];
/* Run raysweepd with args (NULL-terminated); returns the exit status, or
 * -1 on a signal. stderr goes to errbuf. */
static int run(char *errbuf, size_t len, const char *const *args) {
  return tdaemon_run(args, errbuf, len);
}

static bool exists(const char *p) {
  struct stat sb;
  return stat(p, &sb) == 0;
}

static void write_file(const char *path, const char *text) {
  FILE *f = fopen(path, "w");
  if (f) {
    fputs(text, f);
    fclose(f);
  }
}

static void test_render_seed_exr(void) {
  char out[128], err[4096];
  snprintf(out, sizeof out, "%s/seed.exr", tmpdir);
  const char *args[] = {"render", "proto/examples/hdistant_seed.xml", "--spp", "16", "--seed", "3", "-o", out,
                        NULL};
  int rc = run(err, sizeof err, args);
  REQUIRE(rc == 0, "exit %d: %s", rc, err);
  exr_image img;
  rsw_err e = {0};
  REQUIRE(exr_read_image(out, &img, &e) == RSW_OK, "read back: %s", e.msg);
  CHECK(img.width == 32 && img.height == 32, "32x32, got %dx%d", img.width, img.height);
  CHECK(img.n_channels == 3 && exr_image_channel(&img, "R") >= 0 && exr_image_channel(&img, "B") >= 0,
        "RGB film");
  const char *spp = exr_image_meta(&img, "raysweep:spp"), *sensor = exr_image_meta(&img, "raysweep:sensor");
  CHECK(spp && strcmp(spp, "16") == 0, "spp metadata: %s", spp ? spp : "(none)");
  CHECK(sensor && strcmp(sensor, "hdistant") == 0, "sensor metadata: %s", sensor ? sensor : "(none)");
  double sum = 0;
  for (int i = 0; i < img.width * img.height * img.n_channels; i++) sum += img.data[i];
  CHECK(sum > 0, "film is not black");
  exr_image_free(&img);
}

static char *slurp(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  char *b = calloc(1, 1 << 20);
  *len = b ? fread(b, 1, (1 << 20) - 1, f) : 0;
  fclose(f);
  return b;
}

/* -o picks the encoding from the name: .npy and .json as the HTTP API
 * sends them; a name it cannot write is refused before rendering. */
static void test_output_formats(void) {
  char out[128], err[4096];
  size_t len = 0;
  snprintf(out, sizeof out, "%s/film.npy", tmpdir);
  const char *a1[] = {"render", "proto/examples/hdistant_seed.xml", "--spp", "4", "-o", out, NULL};
  int rc = run(err, sizeof err, a1);
  REQUIRE(rc == 0, "-o .npy: exit %d: %s", rc, err);
  char *b = slurp(out, &len);
  CHECK(b && len == 128 + 32 * 32 * 3 * 4 && memcmp(b, "\x93NUMPY\x01\x00", 8) == 0 &&
            strstr(b + 10, "'descr': '<f4'") && strstr(b + 10, "'shape': (32, 32, 3)"),
        "-o film.npy is a (32, 32, 3) float32 .npy: %zu bytes, header %.80s", len, b ? b + 10 : "");
  free(b);
  snprintf(out, sizeof out, "%s/film.json", tmpdir);
  const char *a2[] = {"render", "proto/examples/hdistant_seed.xml", "--spp", "4", "-o", out, NULL};
  rc = run(err, sizeof err, a2);
  REQUIRE(rc == 0, "-o .json: exit %d: %s", rc, err);
  b = slurp(out, &len);
  CHECK(b && b[0] == '{' && strstr(b, "\"width\":32") && strstr(b, "\"layout\":\"HWC\"") &&
            strstr(b, "\"sensor\":\"hdistant\""),
        "-o film.json is the film as JSON: %.200s", b ? b : "");
  free(b);
  snprintf(out, sizeof out, "%s/film.tiff", tmpdir);
  const char *a3[] = {"render", "proto/examples/hdistant_seed.xml", "--spp", "4", "-o", out, NULL};
  rc = run(err, sizeof err, a3);
  CHECK(rc == 2, "-o .tiff: exit %d, want 2 (usage)", rc);
  CHECK(strstr(err, "film.tiff") && strstr(err, ".npy"),
        "-o .tiff: the error names the file and what can be written: %s", err);
  CHECK(!exists(out), "-o .tiff: no file written");
}

static void test_variant_and_wavelength(void) {
  char out[128], err[4096];
  snprintf(out, sizeof out, "%s/mono.exr", tmpdir);
  const char *args[] = {"render",
                        "proto/examples/hdistant_seed.xml",
                        "--variant",
                        "mono",
                        "--wavelength",
                        "600",
                        "--spp",
                        "4",
                        "--threads",
                        "1",
                        "-o",
                        out,
                        NULL};
  int rc = run(err, sizeof err, args);
  REQUIRE(rc == 0, "exit %d: %s", rc, err);
  exr_image img;
  rsw_err e = {0};
  REQUIRE(exr_read_image(out, &img, &e) == RSW_OK, "read back: %s", e.msg);
  CHECK(img.n_channels == 1 && exr_image_channel(&img, "Y") == 0, "mono film has one channel Y");
  const char *wl = exr_image_meta(&img, "raysweep:wavelength_nm");
  CHECK(wl && atof(wl) == 600.0, "wavelength metadata: %s", wl ? wl : "(none)");
  exr_image_free(&img);
}

/* --isa: each ISA the CPU has (generic, the portable kernels, on every
 * CPU) renders and says so in raysweep:isa; auto picks one of them; an unknown name is a usage error (exit 2) naming
 * --isa. (An ISA the CPU lacks is refused the same way: core/isa.c,
 * tests/kernel/simd/test_simd.c.) */
static void test_isa(void) {
  char out[128], err[4096];
  snprintf(out, sizeof out, "%s/isa.exr", tmpdir);
  const char *names[] = {"sse2", "avx2", "avx512", "generic", "auto"};
  int rendered = 0;
  for (int k = 0; k < 5; k++) {
    const char *args[] = {
        "render", "proto/examples/hdistant_seed.xml", "--spp", "2", "--isa", names[k], "-o", out, NULL};
    int rc = run(err, sizeof err, args);
    if (rc == 2 && strstr(err, "lacks")) continue; /* not on this CPU */
    REQUIRE(rc == 0, "--isa %s: exit %d: %s", names[k], rc, err);
    exr_image img;
    rsw_err e = {0};
    REQUIRE(exr_read_image(out, &img, &e) == RSW_OK, "read back: %s", e.msg);
    const char *isa = exr_image_meta(&img, "raysweep:isa");
    bool named =
        isa && (k == 4 ? strcmp(isa, "sse2") == 0 || strcmp(isa, "avx2") == 0 || strcmp(isa, "avx512") == 0
                       : strcmp(isa, names[k]) == 0);
    CHECK(named, "--isa %s: raysweep:isa = %s", names[k], isa ? isa : "(none)");
    exr_image_free(&img);
    rendered++;
  }
  CHECK(rendered >= 2, "generic (every CPU) and auto render");
  const char *bad[] = {"render", "proto/examples/hdistant_seed.xml", "--isa", "avx9", "-o", out, NULL};
  int rc = run(err, sizeof err, bad);
  CHECK(rc == 2 && strstr(err, "--isa") && strstr(err, "avx9"), "--isa avx9: exit %d: %s", rc, err);
}

static void test_defines_and_sensor(void) {
  char scene[128], out[128], err[4096];
  snprintf(scene, sizeof scene, "%s/params.xml", tmpdir);
  snprintf(out, sizeof out, "%s/params.exr", tmpdir);
  write_file(scene,
             "<scene version=\"3.0.0\">\n"
             "  <default name=\"res\" value=\"4\"/>\n"
             "  <sensor type=\"radiancemeter\" id=\"meter\">\n"
             "    <point name=\"origin\" value=\"0, 0, 1\"/><vector name=\"direction\" value=\"0, 0, -1\"/>\n"
             "    <film type=\"hdrfilm\"><integer name=\"width\" value=\"1\"/><integer name=\"height\" "
             "value=\"1\"/>\n"
             "      <string name=\"component_format\" value=\"float32\"/>\n"
             "      <rfilter type=\"box\"/></film>\n"
             "  </sensor>\n"
             "  <sensor type=\"hdistant\" id=\"hemi\">\n"
             "    <film type=\"hdrfilm\"><integer name=\"width\" value=\"$res\"/><integer name=\"height\" "
             "value=\"$res\"/>\n"
             "      <rfilter type=\"box\"/></film>\n"
             "  </sensor>\n"
             "  <emitter type=\"directional\"><vector name=\"direction\" value=\"0, 0, -1\"/></emitter>\n"
             "  <shape type=\"rectangle\"/>\n"
             "</scene>\n");
  const char *args[] = {"render", scene, "-D", "res=6", "--sensor", "hemi", "--spp", "2", "-o", out, NULL};
  int rc = run(err, sizeof err, args);
  REQUIRE(rc == 0, "exit %d: %s", rc, err);
  exr_image img;
  rsw_err e = {0};
  REQUIRE(exr_read_image(out, &img, &e) == RSW_OK, "read back: %s", e.msg);
  CHECK(img.width == 6 && img.height == 6, "-D res=6 overrides the default 4: got %dx%d", img.width,
        img.height);
  exr_image_free(&img);
  /* By index, and the first sensor by default. */
  const char *args2[] = {"render", scene, "--sensor", "0", "--spp", "2", "-o", out, NULL};
  rc = run(err, sizeof err, args2);
  REQUIRE(rc == 0, "exit %d: %s", rc, err);
  REQUIRE(exr_read_image(out, &img, &e) == RSW_OK, "read back: %s", e.msg);
  CHECK(img.width == 1 && img.height == 1, "sensor 0 is the 1x1 radiancemeter");
  /* Lambertian 0.5 plate, E = 1 at normal incidence: 0.5/pi exactly. */
  CHECK(fabs(img.data[0] - 0.5 / 3.14159265358979323846) < 1e-6, "meter reads %g", img.data[0]);
  exr_image_free(&img);
}

/* --coord NAME=VALUE (and --templates): the scene's templates and the
 * option's render the overrides, as the daemon does for a render's coords;
 * the plate under a sun at zenith 60 reads 0.5 cos 60 / pi. */
static void test_coords(void) {
  char scene[128], out[128], err[4096];
  snprintf(scene, sizeof scene, "%s/sun.json", tmpdir);
  snprintf(out, sizeof out, "%s/sun.exr", tmpdir);
  write_file(
      scene,
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"templates\": {\"sun.direction\": {\"sun\": {\"zenith\": \"sza\", \"azimuth\": 0}}},"
      " \"s\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"component_format\": \"float32\"}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1]},"
      " \"p\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}");
  const double want = 0.5 * 0.5 / 3.14159265358979323846;
  exr_image img;
  rsw_err e = {0};
  const char *a1[] = {"render", scene, "--coord", "sza=60", "--spp", "4", "-o", out, NULL};
  int rc = run(err, sizeof err, a1);
  REQUIRE(rc == 0, "exit %d: %s", rc, err);
  REQUIRE(exr_read_image(out, &img, &e) == RSW_OK, "read back: %s", e.msg);
  CHECK(fabs(img.data[0] - want) < 1e-6, "--coord sza=60 reads %g, want %g", img.data[0], want);
  exr_image_free(&img);
  /* --templates of the render's own (a key of the scene's replaced). */
  const char *a2[] = {"render",      scene,
                      "--coord",     "sza=0",
                      "--coord",     "vza=60",
                      "--spp",       "4",
                      "--templates", "{\"sun.direction\": {\"sun\": {\"zenith\": \"vza\", \"azimuth\": 0}}}",
                      "-o",          out,
                      NULL};
  rc = run(err, sizeof err, a2);
  REQUIRE(rc == 0, "exit %d: %s", rc, err);
  REQUIRE(exr_read_image(out, &img, &e) == RSW_OK, "read back: %s", e.msg);
  CHECK(fabs(img.data[0] - want) < 1e-6, "--templates on vza=60 reads %g, want %g", img.data[0], want);
  exr_image_free(&img);
  struct {
    const char *coord, *says;
  } bad[] = {{"sz=60", "--coord sz: no template reads it"},
             {"sza=200", "--coord sza: 200 degrees lies outside [0, 180]"},
             {"sza=high", "--coord needs NAME=NUMBER"}};
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    char never[160];
    snprintf(never, sizeof never, "%s/never%zu.exr", tmpdir, i);
    const char *a[] = {"render", scene, "--coord", bad[i].coord, "-o", never, NULL};
    rc = run(err, sizeof err, a);
    CHECK(rc != 0 && strstr(err, bad[i].says) && !exists(never), "--coord %s: exit %d: %s", bad[i].coord, rc,
          err);
  }
}

static void test_failure_leaves_no_file(void) {
  char scene[128], out[128], err[4096];
  snprintf(scene, sizeof scene, "%s/oob.json", tmpdir);
  snprintf(out, sizeof out, "%s/never.exr", tmpdir);
  /* Loads, but the render fails: the wavelength lies outside the table. */
  write_file(scene, "{\"type\": \"scene\", \"variant\": \"mono\","
                    " \"s\": {\"type\": \"radiancemeter\", \"origin\": [0, 0, 1], \"direction\": [0, 0, -1],"
                    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
                    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1]},"
                    " \"p\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\","
                    "   \"reflectance\": {\"type\": \"spectrum\", \"value\": [[500, 0.1], [600, 0.2]]}}}}");
  const char *args[] = {"render", scene, "--wavelength", "700", "-o", out, NULL};
  int rc = run(err, sizeof err, args);
  CHECK(rc == 1, "exit %d", rc);
  CHECK(strstr(err, "700") && strstr(err, "/p/bsdf/reflectance"),
        "error names the wavelength and the property: %s", err);
  CHECK(!exists(out), "no output file after a failed render");
  /* An unwritable output: clear error, nothing left behind. */
  char bad[160];
  snprintf(bad, sizeof bad, "%s/no/such/dir/x.exr", tmpdir);
  const char *args2[] = {"render", "proto/examples/hdistant_seed.xml", "--spp", "1", "-o", bad, NULL};
  rc = run(err, sizeof err, args2);
  CHECK(rc == 1, "exit %d", rc);
  CHECK(strstr(err, "x.exr") != NULL, "error names the output file: %s", err);
}

int main(void) {
  snprintf(tmpdir, sizeof tmpdir, "/tmp/rsw-cli-XXXXXX");
  if (!mkdtemp(tmpdir)) return 1;
  RSW_TEST_RUN(test_render_seed_exr);
  RSW_TEST_RUN(test_output_formats);
  RSW_TEST_RUN(test_variant_and_wavelength);
  RSW_TEST_RUN(test_defines_and_sensor);
  RSW_TEST_RUN(test_isa);
  RSW_TEST_RUN(test_failure_leaves_no_file);
  RSW_TEST_RUN(test_coords);
  char cmd[128];
  snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
  if (system(cmd)) fprintf(stderr, "could not remove %s\n", tmpdir);
  RSW_TEST_END("test_cli");
}
