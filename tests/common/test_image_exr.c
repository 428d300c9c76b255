/* OpenEXR write/read round trips, the temp-file-then-rename contract, and
 * clean failures on bad files. Files go to a fresh mkdtemp() directory. */
#include <dirent.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* Only to write a tiled file, which exr_write_image does not do. */
#include <OpenEXR/openexr.h>

#include "../support/test.h"
#include "image_exr.h"

RSW_TEST_DEFINE_GLOBALS

static char tmpdir[256];

static const char *tpath(const char *name) {
  static char buf[512];
  snprintf(buf, sizeof buf, "%s/%s", tmpdir, name);
  return buf;
}

static int count_dir_entries(const char *dir) {
  DIR *d = opendir(dir);
  if (!d) return -1;
  int n = 0;
  struct dirent *e;
  while ((e = readdir(d)))
    if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) n++;
  closedir(d);
  return n;
}

static bool file_exists(const char *p) {
  struct stat sb;
  return stat(p, &sb) == 0;
}

/* Deterministic test pattern with negatives, fractions and large values. */
static float pattern(int x, int y, int c) {
  return (float)((x + 1) * 0.37 - (y * 1.5) + c * 1000.25 + (x * y % 7) / 3.0);
}

static void test_float_rgb_roundtrip(void) {
  const int w = 37, h = 23; /* several 16-line ZIP chunks, odd sizes */
  float *data = malloc(sizeof(float) * w * h * 3);
  for (int y = 0; y < h; y++)
    for (int x = 0; x < w; x++)
      for (int c = 0; c < 3; c++) data[(y * w + x) * 3 + c] = pattern(x, y, c);
  const char *names[] = {"R", "G", "B"};
  rsw_err err = {0};
  const char *p = tpath("rgb32.exr");
  rsw_status s = exr_write_image(p, w, h, 3, names, data, false, NULL, &err);
  REQUIRE(s == RSW_OK, "write: %s", err.msg);
  exr_image img;
  s = exr_read_image(p, &img, &err);
  REQUIRE(s == RSW_OK, "read: %s: %s", err.where, err.msg);
  CHECK(img.width == w && img.height == h, "size %dx%d", img.width, img.height);
  REQUIRE(img.n_channels == 3, "channels %d", img.n_channels);
  /* EXR stores channels alphabetically: B, G, R. */
  CHECK(strcmp(img.channel_names[0], "B") == 0, "first channel %s", img.channel_names[0]);
  int ir = exr_image_channel(&img, "R"), ig = exr_image_channel(&img, "G"), ib = exr_image_channel(&img, "B");
  REQUIRE(ir >= 0 && ig >= 0 && ib >= 0, "missing channel");
  CHECK(exr_image_channel(&img, "A") == -1, "phantom A channel");
  int bad = 0;
  for (int y = 0; y < h; y++)
    for (int x = 0; x < w; x++) {
      const float *px = img.data + (y * w + x) * 3;
      if (px[ir] != pattern(x, y, 0) || px[ig] != pattern(x, y, 1) || px[ib] != pattern(x, y, 2)) bad++;
    }
  CHECK(bad == 0, "%d pixels differ after a float32 round trip", bad);
  exr_image_free(&img);
  exr_image_free(&img); /* zeroed: second free is a no-op */
  exr_image_free(NULL);
  free(data);
  CHECK(count_dir_entries(tmpdir) == 1, "temp file left behind");
}

static void test_half_y_roundtrip(void) {
  /* Values with known float16 images:
   *   1, 65504 (largest half), -2^-24 (smallest subnormal) exact;
   *   70000 -> +inf (beyond 65520); 1/3 -> nearest half 0x3555;
   *   1 + 2^-11 is a tie between 1 and 1 + 2^-10: rounds to even, 1;
   *   2^-26 -> 0 (below half the smallest subnormal). */
  const float in[8] = {1.0f, 65504.0f, -0x1p-24f, 70000.0f, 1.0f / 3.0f, 1.0f + 0x1p-11f, 0x1p-26f, -0.0f};
  const float want[8] = {1.0f, 65504.0f, -0x1p-24f, INFINITY, 0.333251953125f, 1.0f, 0.0f, -0.0f};
  const char *names[] = {"Y"};
  exr_meta_entry me[] = {{"raysweep_variant", "mono"}, {"comments", "spectral radiance, nm 550"}};
  exr_meta meta = {.entries = me, .count = 2, .uncompressed = true};
  rsw_err err = {0};
  const char *p = tpath("y16.exr");
  rsw_status s = exr_write_image(p, 4, 2, 1, names, in, true, &meta, &err);
  REQUIRE(s == RSW_OK, "write: %s", err.msg);
  exr_image img;
  s = exr_read_image(p, &img, &err);
  REQUIRE(s == RSW_OK, "read: %s", err.msg);
  REQUIRE(img.n_channels == 1 && img.width == 4 && img.height == 2, "shape %d %d %d", img.n_channels,
          img.width, img.height);
  CHECK(strcmp(img.channel_names[0], "Y") == 0, "name %s", img.channel_names[0]);
  for (int i = 0; i < 8; i++)
    CHECK(img.data[i] == want[i], "sample %d: %.9g, want %.9g", i, img.data[i], want[i]);
  CHECK(signbit(img.data[7]), "-0 lost its sign");
  const char *v = exr_image_meta(&img, "raysweep_variant");
  CHECK(v && strcmp(v, "mono") == 0, "metadata variant = %s", v ? v : "NULL");
  v = exr_image_meta(&img, "comments");
  CHECK(v && strcmp(v, "spectral radiance, nm 550") == 0, "comments = %s", v ? v : "NULL");
  CHECK(exr_image_meta(&img, "nope") == NULL, "phantom metadata");
  exr_image_free(&img);
}

static void test_half_rgb_rounding(void) {
  /* A smooth ramp through float16: relative error <= 2^-11 for normals. */
  const int w = 64, h = 20;
  float *data = malloc(sizeof(float) * w * h * 3);
  for (int i = 0; i < w * h * 3; i++) data[i] = 1e-3f * powf(1.013f, (float)i);
  const char *names[] = {"G", "R", "B"}; /* any order is accepted */
  rsw_err err = {0};
  const char *p = tpath("rgb16.exr");
  REQUIRE(exr_write_image(p, w, h, 3, names, data, true, NULL, &err) == RSW_OK, "write: %s", err.msg);
  exr_image img;
  REQUIRE(exr_read_image(p, &img, &err) == RSW_OK, "read: %s", err.msg);
  int map[3] = {exr_image_channel(&img, "G"), exr_image_channel(&img, "R"), exr_image_channel(&img, "B")};
  REQUIRE(map[0] >= 0 && map[1] >= 0 && map[2] >= 0, "channel missing");
  double worst = 0;
  for (int i = 0; i < w * h; i++)
    for (int c = 0; c < 3; c++) {
      double a = data[i * 3 + c], b = img.data[i * 3 + map[c]];
      if (a > 65504.0) continue;
      double rel = fabs(a - b) / a;
      if (rel > worst) worst = rel;
    }
  CHECK(worst <= 0x1p-11, "worst float16 relative error %g", worst);
  exr_image_free(&img);
  free(data);
}

static void test_missing_directory_fails_cleanly(void) {
  const float px[3] = {1, 2, 3};
  const char *names[] = {"R", "G", "B"};
  rsw_err err = {0};
  const char *p = tpath("no/such/dir/out.exr");
  rsw_status s = exr_write_image(p, 1, 1, 3, names, px, false, NULL, &err);
  CHECK(s == RSW_ERR_IO, "status %d", (int)s);
  CHECK(strcmp(err.where, p) == 0, "where = %s", err.where);
  CHECK(!file_exists(p), "file created");
  CHECK(count_dir_entries(tmpdir) >= 0, "tmpdir vanished");
}

static void test_failed_write_keeps_old_file(void) {
  const char *p = tpath("keep.exr");
  FILE *f = fopen(p, "w");
  REQUIRE(f, "fopen");
  fputs("old contents", f);
  fclose(f);
  int before = count_dir_entries(tmpdir);
  /* "channels" is a required attribute of another type: the library
   * refuses it after the temp file exists. */
  exr_meta_entry me[] = {{"channels", "R"}};
  exr_meta meta = {.entries = me, .count = 1};
  const float px[1] = {0.5f};
  const char *names[] = {"Y"};
  rsw_err err = {0};
  rsw_status s = exr_write_image(p, 1, 1, 1, names, px, false, &meta, &err);
  CHECK(s == RSW_ERR_IO, "status %d", (int)s);
  CHECK(strstr(err.msg, "metadata") != NULL, "msg: %s", err.msg);
  CHECK(count_dir_entries(tmpdir) == before, "temp file left behind");
  char buf[64] = {0};
  f = fopen(p, "r");
  REQUIRE(f, "old file gone");
  CHECK(fgets(buf, sizeof buf, f) && strcmp(buf, "old contents") == 0, "old file changed: %s", buf);
  fclose(f);
  /* A good write replaces it. */
  rsw_err_clear(&err);
  REQUIRE(exr_write_image(p, 1, 1, 1, names, px, false, NULL, &err) == RSW_OK, "overwrite: %s", err.msg);
  exr_image img;
  REQUIRE(exr_read_image(p, &img, &err) == RSW_OK, "read: %s", err.msg);
  CHECK(img.data[0] == 0.5f, "value %g", img.data[0]);
  exr_image_free(&img);
  unlink(p);
}

static void test_bad_arguments(void) {
  const float px[2] = {0, 0};
  const char *dup[] = {"R", "R"};
  rsw_err err = {0};
  CHECK(exr_write_image(tpath("a.exr"), 1, 1, 2, dup, px, false, NULL, &err) == RSW_ERR_INVALID,
        "duplicate names accepted");
  CHECK(strstr(err.msg, "twice") != NULL, "msg: %s", err.msg);
  rsw_err_clear(&err);
  const char *one[] = {"Y"};
  CHECK(exr_write_image(tpath("a.exr"), 0, 1, 1, one, px, false, NULL, &err) == RSW_ERR_INVALID,
        "zero width accepted");
  rsw_err_clear(&err);
  CHECK(exr_write_image(tpath("a.exr"), 1 << 20, 1 << 20, 1, one, px, false, NULL, &err) == RSW_ERR_LIMIT,
        "huge image accepted");
  CHECK(!file_exists(tpath("a.exr")), "file created on bad arguments");
}

static void test_corrupt_files(void) {
  rsw_err err = {0};
  exr_image img;
  /* Missing. */
  const char *missing = tpath("missing.exr");
  CHECK(exr_read_image(missing, &img, &err) == RSW_ERR_FILE, "missing");
  CHECK(strcmp(err.where, missing) == 0, "where = %s", err.where);
  /* Not an EXR at all. */
  const char *junk = tpath("junk.exr");
  FILE *f = fopen(junk, "wb");
  REQUIRE(f, "fopen");
  fputs("P6 this is not an OpenEXR file at all\n", f);
  fclose(f);
  rsw_err_clear(&err);
  CHECK(exr_read_image(junk, &img, &err) == RSW_ERR_FILE, "junk accepted");
  CHECK(strcmp(err.where, junk) == 0 && err.msg[0], "where = %s msg = %s", err.where, err.msg);
  /* A valid file cut in half: the header survives, the chunks do not. */
  const int w = 40, h = 40;
  float *data = calloc((size_t)w * h, sizeof(float));
  for (int i = 0; i < w * h; i++) data[i] = (float)i;
  const char *names[] = {"Y"};
  const char *cut = tpath("cut.exr");
  REQUIRE(exr_write_image(cut, w, h, 1, names, data, false, NULL, &err) == RSW_OK, "write: %s", err.msg);
  struct stat sb;
  REQUIRE(stat(cut, &sb) == 0, "stat");
  REQUIRE(truncate(cut, sb.st_size / 2) == 0, "truncate");
  rsw_err_clear(&err);
  CHECK(exr_read_image(cut, &img, &err) == RSW_ERR_FILE, "truncated accepted");
  CHECK(strcmp(err.where, cut) == 0 && err.msg[0], "where = %s msg = %s", err.where, err.msg);
  /* Scribbled chunk data (ZIP stream): an error or some pixels, never a
   * crash (ASan checks the "never"). */
  const char *scr = tpath("scribbled.exr");
  REQUIRE(exr_write_image(scr, w, h, 1, names, data, false, NULL, &err) == RSW_OK, "write");
  REQUIRE(stat(scr, &sb) == 0, "stat");
  f = fopen(scr, "r+b");
  REQUIRE(f, "fopen");
  for (long off = sb.st_size / 2; off < sb.st_size; off += 7) {
    fseek(f, off, SEEK_SET);
    fputc(0xA5, f);
  }
  fclose(f);
  rsw_err_clear(&err);
  rsw_status s = exr_read_image(scr, &img, &err);
  if (s == RSW_OK)
    exr_image_free(&img);
  else
    CHECK(s == RSW_ERR_FILE && strcmp(err.where, scr) == 0, "status %d %s", (int)s, err.where);
  free(data);
  unlink(junk);
  unlink(cut);
  unlink(scr);
}

/* Write a 20 x 13 FLOAT tiled image (8 x 8 tiles, data window offset to
 * (5, -3)) with the core API directly; value = 100 y + x. */
static bool write_tiled(const char *p) {
  exr_context_t ctx = NULL;
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  if (exr_start_write(&ctx, p, EXR_WRITE_FILE_DIRECTLY, &init)) return false;
  int part = 0, W = 20, H = 13;
  exr_attr_box2i_t dw;
  dw.min.x = 5;
  dw.min.y = -3;
  dw.max.x = 5 + W - 1;
  dw.max.y = -3 + H - 1;
  exr_attr_v2f_t swc;
  swc.x = swc.y = 0.f;
  bool ok = !exr_add_part(ctx, NULL, EXR_STORAGE_TILED, &part) &&
            !exr_initialize_required_attr(ctx, part, &dw, &dw, 1.f, &swc, 1.f, EXR_LINEORDER_INCREASING_Y,
                                          EXR_COMPRESSION_NONE) &&
            !exr_set_tile_descriptor(ctx, part, 8, 8, EXR_TILE_ONE_LEVEL, EXR_TILE_ROUND_DOWN) &&
            !exr_add_channel(ctx, part, "Y", EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1) &&
            !exr_write_header(ctx);
  float tile[64];
  for (int ty = 0; ok && ty < 2; ty++)
    for (int tx = 0; ok && tx < 3; tx++) {
      int tw = tx == 2 ? W - 16 : 8, th = ty == 1 ? H - 8 : 8;
      for (int y = 0; y < th; y++)
        for (int x = 0; x < tw; x++) tile[y * tw + x] = (float)(100 * (ty * 8 + y) + tx * 8 + x);
      ok = !exr_write_tile_chunk(ctx, part, tx, ty, 0, 0, tile, sizeof(float) * (uint64_t)(tw * th));
    }
  return !exr_finish(&ctx) && ok;
}

static void test_tiled_read(void) {
  const char *p = tpath("tiled.exr");
  REQUIRE(write_tiled(p), "could not write the tiled fixture");
  exr_image img;
  rsw_err err = {0};
  REQUIRE(exr_read_image(p, &img, &err) == RSW_OK, "read: %s", err.msg);
  CHECK(img.width == 20 && img.height == 13, "size %dx%d", img.width, img.height);
  int bad = 0;
  for (int y = 0; y < img.height; y++)
    for (int x = 0; x < img.width; x++)
      if (img.data[y * img.width + x] != (float)(100 * y + x)) bad++;
  CHECK(bad == 0, "%d tiled pixels wrong", bad);
  exr_image_free(&img);
  unlink(p);
}

/* exr_decode_image: the bytes exr_encode_image made read back as the file
 * exr_read_image reads (pixels, channels, string attributes); every cut of
 * them short of the whole, and no bytes at all, fail as RSW_ERR_FILE. */
static void test_decode_from_memory(void) {
  const int w = 21, h = 19;
  float *data = malloc(sizeof(float) * w * h * 3);
  for (int y = 0; y < h; y++)
    for (int x = 0; x < w; x++)
      for (int c = 0; c < 3; c++) data[(y * w + x) * 3 + c] = pattern(x, y, c);
  const char *names[] = {"R", "G", "B"};
  exr_meta_entry e[] = {{"raysweep:spp", "16"}, {"raysweep:zenith_deg", "1.5,2.25"}};
  exr_meta meta = {.entries = e, .count = 2};
  rsw_err err = {0};
  void *bytes = NULL;
  size_t len = 0;
  REQUIRE(exr_encode_image(w, h, 3, names, data, false, &meta, &bytes, &len, &err) == RSW_OK, "encode: %s",
          err.msg);
  exr_image img;
  REQUIRE(exr_decode_image(bytes, len, NULL, &img, &err) == RSW_OK, "decode: %s", err.msg);
  CHECK(img.width == w && img.height == h && img.n_channels == 3, "%dx%dx%d", img.width, img.height,
        img.n_channels);
  CHECK(img.n_channels == 3 && strcmp(img.channel_names[0], "B") == 0, "channels in the file's order");
  int ir = exr_image_channel(&img, "R"), bad = 0;
  for (int i = 0; ir >= 0 && i < w * h; i++)
    if (img.data[i * 3 + ir] != data[i * 3]) bad++;
  CHECK(ir >= 0 && bad == 0, "%d R samples differ", bad);
  const char *spp = exr_image_meta(&img, "raysweep:spp"), *zen = exr_image_meta(&img, "raysweep:zenith_deg");
  CHECK(spp && strcmp(spp, "16") == 0 && zen && strcmp(zen, "1.5,2.25") == 0, "attributes %s %s",
        spp ? spp : "(none)", zen ? zen : "(none)");
  exr_image_free(&img);
  int accepted = 0;
  for (size_t cut = 0; cut < len; cut += cut < 400 ? 1 : 97) {
    rsw_err e2 = {0};
    rsw_status s = exr_decode_image(bytes, cut, "cut", &img, &e2);
    if (s == RSW_OK) {
      accepted++;
      exr_image_free(&img);
    } else {
      CHECK(s == RSW_ERR_FILE, "cut at %zu: status %d", cut, (int)s);
    }
  }
  CHECK(accepted == 0, "%d cuts short of the whole file decoded", accepted);
  free(bytes);
  free(data);
}

static void cleanup_dir(void) {
  DIR *d = opendir(tmpdir);
  if (!d) return;
  struct dirent *e;
  while ((e = readdir(d)))
    if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) unlink(tpath(e->d_name));
  closedir(d);
  rmdir(tmpdir);
}

int main(void) {
  snprintf(tmpdir, sizeof tmpdir, "/tmp/rsw_test_exr_XXXXXX");
  if (!mkdtemp(tmpdir)) {
    perror("mkdtemp");
    return 1;
  }
  RSW_TEST_RUN(test_float_rgb_roundtrip);
  RSW_TEST_RUN(test_half_y_roundtrip);
  RSW_TEST_RUN(test_half_rgb_rounding);
  RSW_TEST_RUN(test_missing_directory_fails_cleanly);
  RSW_TEST_RUN(test_failed_write_keeps_old_file);
  RSW_TEST_RUN(test_bad_arguments);
  RSW_TEST_RUN(test_corrupt_files);
  RSW_TEST_RUN(test_tiled_read);
  RSW_TEST_RUN(test_decode_from_memory);
  cleanup_dir();
  RSW_TEST_END("test_image_exr");
}
