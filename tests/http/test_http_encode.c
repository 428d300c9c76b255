/* Encoders of the HTTP layer (server/http/encode.c): film JSON, NPY and
 * in-memory EXR (exr_encode_image, decoded back through exr_read_image),
 * problem+json, Accept negotiation and the JSON depth scan. */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../support/test.h"
#include "http/encode.h"
#include "image_exr.h"
#include <png.h>

RSW_TEST_DEFINE_GLOBALS

/* A 3 x 2 RGB film whose samples are distinct and not exactly representable
 * in few digits, with one NaN (JSON must print it as null). */
static svc_film make_film(float *data) {
  svc_film f;
  memset(&f, 0, sizeof f);
  f.img.width = 3;
  f.img.height = 2;
  f.img.channels = 3;
  f.img.channel_names[0] = "R";
  f.img.channel_names[1] = "G";
  f.img.channel_names[2] = "B";
  for (int i = 0; i < 18; i++) data[i] = (float)(i + 1) / 7.0f - 0.5f;
  f.img.data = data;
  f.img.spp = 16;
  f.img.seed = 42;
  f.img.wavelength = 550;
  f.img.variant = VARIANT_RGB;
  snprintf(f.scene, sizeof f.scene, "%064d", 7);
  f.revision = 3;
  snprintf(f.context, sizeof f.context, "ctx-1");
  snprintf(f.sensor, sizeof f.sensor, "cam \"a\"");
  return f;
}

static void test_film_json(void) {
  float data[18];
  svc_film f = make_film(data);
  data[4] = NAN;
  char *text = NULL;
  size_t len = 0;
  rsw_err err = {0};
  REQUIRE(http_film_json(&f, &text, &len, &err) == RSW_OK, "film json: %s", err.msg);
  CHECK(strlen(text) == len, "length %zu vs strlen %zu", len, strlen(text));
  cJSON *j = cJSON_Parse(text);
  REQUIRE(j, "film JSON does not parse: %.200s", text);
  CHECK(cJSON_GetObjectItem(j, "width")->valueint == 3, "width");
  CHECK(cJSON_GetObjectItem(j, "height")->valueint == 2, "height");
  CHECK(strcmp(cJSON_GetObjectItem(j, "layout")->valuestring, "HWC") == 0, "layout");
  cJSON *ch = cJSON_GetObjectItem(j, "channels");
  CHECK(cJSON_GetArraySize(ch) == 3 && strcmp(cJSON_GetArrayItem(ch, 2)->valuestring, "B") == 0, "channels");
  cJSON *d = cJSON_GetObjectItem(j, "data");
  REQUIRE(cJSON_GetArraySize(d) == 18, "data has %d numbers", cJSON_GetArraySize(d));
  for (int i = 0; i < 18; i++) {
    cJSON *v = cJSON_GetArrayItem(d, i);
    if (i == 4) {
      CHECK(cJSON_IsNull(v), "NaN sample should be null");
      continue;
    }
    /* 9 significant digits round-trip float32 exactly */
    CHECK(cJSON_IsNumber(v) && (float)v->valuedouble == data[i], "sample %d: %.9g vs %.9g", i, v->valuedouble,
          (double)data[i]);
  }
  cJSON *m = cJSON_GetObjectItem(j, "meta");
  REQUIRE(m, "no meta");
  CHECK(strcmp(cJSON_GetObjectItem(m, "sensor")->valuestring, "cam \"a\"") == 0, "sensor escaped");
  CHECK(strcmp(cJSON_GetObjectItem(m, "context")->valuestring, "ctx-1") == 0, "context");
  CHECK(cJSON_GetObjectItem(m, "revision")->valueint == 3, "revision");
  CHECK(cJSON_GetObjectItem(m, "spp")->valueint == 16, "spp");
  CHECK(cJSON_GetObjectItem(m, "seed")->valueint == 42, "seed");
  CHECK(cJSON_IsNull(cJSON_GetObjectItem(m, "wavelength")), "rgb film: wavelength null");
  CHECK(!cJSON_GetObjectItem(m, "unresolved_rays"), "no unresolved rays: no unresolved_rays key");
  cJSON_Delete(j);
  free(text);

  /* Non-finite values (issue 22): the NaN above and an inf, flagged in the
   * meta with their count; a finite film has no such key. */
  data[7] = INFINITY;
  CHECK(film_image_nonfinite(&f.img) == 2, "film_image_nonfinite %llu, wanted 2",
        (unsigned long long)film_image_nonfinite(&f.img));
  REQUIRE(http_film_json(&f, &text, &len, &err) == RSW_OK, "film json: %s", err.msg);
  j = cJSON_Parse(text);
  REQUIRE(j, "does not parse");
  cJSON *nf = cJSON_GetObjectItem(cJSON_GetObjectItem(j, "meta"), "nonfinite");
  CHECK(cJSON_IsNumber(nf) && nf->valueint == 2, "meta.nonfinite %s, wanted 2",
        nf ? cJSON_PrintUnformatted(nf) : "(none)");
  CHECK(cJSON_IsNull(cJSON_GetArrayItem(cJSON_GetObjectItem(j, "data"), 7)), "inf sample should be null");
  cJSON_Delete(j);
  free(text);
  data[4] = 0.25f, data[7] = 0.5f;
  CHECK(film_image_nonfinite(&f.img) == 0, "a finite film counts 0");
  REQUIRE(http_film_json(&f, &text, &len, &err) == RSW_OK, "film json: %s", err.msg);
  CHECK(!strstr(text, "nonfinite"), "a finite film has no nonfinite key");
  free(text);
  data[4] = NAN;

  /* Unresolved periodic rays: the count, an integer, in the meta. */
  f.img.unresolved_rays = 12345678901ULL;
  REQUIRE(http_film_json(&f, &text, &len, &err) == RSW_OK, "film json: %s", err.msg);
  j = cJSON_Parse(text);
  REQUIRE(j, "does not parse");
  cJSON *u = cJSON_GetObjectItem(cJSON_GetObjectItem(j, "meta"), "unresolved_rays");
  CHECK(cJSON_IsNumber(u) && u->valuedouble == 12345678901.0, "unresolved_rays %s",
        u ? cJSON_PrintUnformatted(u) : "(none)");
  const char *ur = strstr(text, "\"unresolved_rays\":12345678901");
  CHECK(ur && (ur[29] == '}' || ur[29] == ','), "unresolved_rays printed as an integer");
  cJSON_Delete(j);
  free(text);
  f.img.unresolved_rays = 0;

  /* A synchronous render has no context: null. */
  f.context[0] = '\0';
  REQUIRE(http_film_json(&f, &text, &len, &err) == RSW_OK, "film json: %s", err.msg);
  j = cJSON_Parse(text);
  REQUIRE(j, "does not parse");
  CHECK(cJSON_IsNull(cJSON_GetObjectItem(cJSON_GetObjectItem(j, "meta"), "context")), "context null");
  cJSON_Delete(j);
  free(text);
}

static void test_film_npy(void) {
  float data[18];
  svc_film f = make_film(data);
  void *bytes = NULL;
  size_t len = 0;
  rsw_err err = {0};
  REQUIRE(http_film_npy(&f, &bytes, &len, &err) == RSW_OK, "npy: %s", err.msg);
  const uint8_t *p = bytes;
  CHECK(memcmp(p, "\x93NUMPY\x01\x00", 8) == 0, "magic and version 1.0");
  size_t hlen = (size_t)p[8] | (size_t)p[9] << 8;
  size_t start = 10 + hlen;
  CHECK(start % 64 == 0, "data starts at %zu, not a multiple of 64", start);
  CHECK(len == start + 18 * 4, "length %zu", len);
  CHECK(p[start - 1] == '\n', "header ends with a newline");
  char header[256] = {0};
  memcpy(header, p + 10, hlen < 255 ? hlen : 255);
  CHECK(strstr(header, "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 3), }") == header,
        "header dict: %s", header);
  for (size_t i = strlen("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 3), }"); i + 1 < hlen; i++)
    CHECK(header[i] == ' ', "padding byte %zu is 0x%02x", i, (unsigned char)header[i]);
  for (int i = 0; i < 18; i++) {
    const uint8_t *q = p + start + 4 * i;
    uint32_t u = (uint32_t)q[0] | (uint32_t)q[1] << 8 | (uint32_t)q[2] << 16 | (uint32_t)q[3] << 24;
    float v;
    memcpy(&v, &u, 4);
    CHECK(v == data[i], "sample %d: %g vs %g", i, (double)v, (double)data[i]);
  }
  free(bytes);
}

/* exr_encode_image's bytes written to a file read back through
 * exr_read_image: same pixels (float32, exact), same metadata. */
static void test_exr_round_trip(void) {
  float data[18];
  svc_film f = make_film(data);
  void *bytes = NULL;
  size_t len = 0;
  rsw_err err = {0};
  REQUIRE(http_film_exr(&f, &bytes, &len, &err) == RSW_OK, "exr: %s", err.msg);
  CHECK(len > 100 && memcmp(bytes, "\x76\x2f\x31\x01", 4) == 0, "EXR magic, %zu bytes", len);
  char path[] = "/tmp/test_http_encode_XXXXXX";
  int fd = mkstemp(path);
  REQUIRE(fd >= 0, "mkstemp");
  CHECK(write(fd, bytes, len) == (ssize_t)len, "write");
  close(fd);
  free(bytes);
  exr_image img = {0};
  rsw_status s = exr_read_image(path, &img, &err);
  unlink(path);
  REQUIRE(s == RSW_OK, "read back: %s", err.msg);
  CHECK(img.width == 3 && img.height == 2 && img.n_channels == 3, "size %dx%dx%d", img.width, img.height,
        img.n_channels);
  const char *names[3] = {"R", "G", "B"};
  for (int c = 0; c < 3; c++) {
    int k = exr_image_channel(&img, names[c]);
    REQUIRE(k >= 0, "channel %s missing", names[c]);
    for (int i = 0; i < 6; i++)
      CHECK(img.data[i * 3 + k] == data[i * 3 + c], "pixel %d %s: %g vs %g", i, names[c],
            (double)img.data[i * 3 + k], (double)data[i * 3 + c]);
  }
  const char *sensor_meta = exr_image_meta(&img, "raysweep:sensor");
  CHECK(sensor_meta && strcmp(sensor_meta, "cam \"a\"") == 0, "sensor meta %s",
        sensor_meta ? sensor_meta : "(none)");
  const char *rev = exr_image_meta(&img, "raysweep:revision");
  CHECK(rev && strcmp(rev, "3") == 0, "revision meta");
  CHECK(!exr_image_meta(&img, "raysweep:unresolved_rays"), "no unresolved rays: no attribute");
  exr_image_free(&img);

  /* Unresolved periodic rays: the count as an attribute. */
  f.img.unresolved_rays = 7;
  REQUIRE(http_film_exr(&f, &bytes, &len, &err) == RSW_OK, "exr: %s", err.msg);
  snprintf(path, sizeof path, "/tmp/test_http_encode_XXXXXX");
  fd = mkstemp(path);
  REQUIRE(fd >= 0, "mkstemp");
  CHECK(write(fd, bytes, len) == (ssize_t)len, "write");
  close(fd);
  free(bytes);
  s = exr_read_image(path, &img, &err);
  unlink(path);
  REQUIRE(s == RSW_OK, "read back: %s", err.msg);
  const char *unres = exr_image_meta(&img, "raysweep:unresolved_rays");
  CHECK(unres && strcmp(unres, "7") == 0, "unresolved_rays attribute %s", unres ? unres : "(none)");
  exr_image_free(&img);

  /* Bad arguments fail with a message and leave the outputs alone. */
  bytes = (void *)&len;
  err = (rsw_err){0};
  CHECK(exr_encode_image(0, 1, 1, names, data, false, NULL, &bytes, &len, &err) == RSW_ERR_INVALID,
        "0 width");
  CHECK(bytes == (void *)&len && err.msg[0], "outputs untouched, message set");
}

/* A larger half-float image takes several chunks and many buffer doublings. */
static void test_exr_half_large(void) {
  int w = 300, h = 200;
  float *px = malloc(sizeof(float) * (size_t)w * (size_t)h);
  REQUIRE(px, "alloc");
  for (int i = 0; i < w * h; i++) px[i] = (float)(i % 1024); /* exact in half */
  const char *names[1] = {"Y"};
  void *bytes = NULL;
  size_t len = 0;
  rsw_err err = {0};
  rsw_status s = exr_encode_image(w, h, 1, names, px, true, NULL, &bytes, &len, &err);
  REQUIRE(s == RSW_OK, "encode: %s", err.msg);
  char path[] = "/tmp/test_http_encode_XXXXXX";
  int fd = mkstemp(path);
  REQUIRE(fd >= 0, "mkstemp");
  CHECK(write(fd, bytes, len) == (ssize_t)len, "write");
  close(fd);
  free(bytes);
  exr_image img = {0};
  s = exr_read_image(path, &img, &err);
  unlink(path);
  REQUIRE(s == RSW_OK, "read back: %s", err.msg);
  int bad = 0;
  for (int i = 0; i < w * h; i++) bad += img.data[i] != px[i];
  CHECK(img.width == w && img.height == h && bad == 0, "%d of %d samples differ", bad, w * h);
  exr_image_free(&img);
  free(px);
}

/* A film with planes (brf, radiance_stderr): JSON lists their channels
 * after the radiance's with the meta's planes and irradiance; the .npy's
 * last axis and the EXR's channels hold the same values. */
static void test_film_planes(void) {
  float data[18], brf[18], se[18];
  svc_film f = make_film(data);
  for (int i = 0; i < 18; i++) brf[i] = 10.0f + (float)i, se[i] = 100.0f + (float)i;
  film_plane_init(&f.img, "brf", &f.img.planes[0]);
  film_plane_init(&f.img, "radiance_stderr", &f.img.planes[1]);
  f.img.planes[0].data = brf;
  f.img.planes[1].data = se;
  f.img.n_planes = 2;
  f.img.has_irradiance = true;
  f.img.irradiance[0] = 1.5, f.img.irradiance[1] = 2.5, f.img.irradiance[2] = 3.5;
  char *text = NULL;
  size_t len = 0;
  rsw_err err = {0};
  REQUIRE(http_film_json(&f, &text, &len, &err) == RSW_OK, "film json: %s", err.msg);
  cJSON *j = cJSON_Parse(text);
  REQUIRE(j, "does not parse");
  const char *want[9] = {"R",
                         "G",
                         "B",
                         "brf.R",
                         "brf.G",
                         "brf.B",
                         "radiance_stderr.R",
                         "radiance_stderr.G",
                         "radiance_stderr.B"};
  cJSON *ch = cJSON_GetObjectItem(j, "channels");
  REQUIRE(cJSON_GetArraySize(ch) == 9, "%d channels", cJSON_GetArraySize(ch));
  for (int c = 0; c < 9; c++)
    CHECK(strcmp(cJSON_GetArrayItem(ch, c)->valuestring, want[c]) == 0, "channel %d: %s", c,
          cJSON_GetArrayItem(ch, c)->valuestring);
  cJSON *d = cJSON_GetObjectItem(j, "data");
  REQUIRE(cJSON_GetArraySize(d) == 54, "%d samples", cJSON_GetArraySize(d));
  for (int px = 0; px < 6; px++)
    for (int c = 0; c < 3; c++) {
      CHECK((float)cJSON_GetArrayItem(d, px * 9 + c)->valuedouble == data[px * 3 + c], "radiance");
      CHECK((float)cJSON_GetArrayItem(d, px * 9 + 3 + c)->valuedouble == brf[px * 3 + c], "brf");
      CHECK((float)cJSON_GetArrayItem(d, px * 9 + 6 + c)->valuedouble == se[px * 3 + c], "stderr");
    }
  cJSON *m = cJSON_GetObjectItem(j, "meta");
  cJSON *pl = cJSON_GetObjectItem(m, "planes");
  CHECK(cJSON_GetArraySize(pl) == 2 &&
            strcmp(cJSON_GetObjectItem(cJSON_GetArrayItem(pl, 0), "name")->valuestring, "brf") == 0 &&
            strcmp(cJSON_GetObjectItem(cJSON_GetArrayItem(pl, 0), "units")->valuestring, "1") == 0,
        "meta planes");
  cJSON *ir = cJSON_GetObjectItem(m, "irradiance");
  CHECK(cJSON_GetArraySize(ir) == 3 && cJSON_GetArrayItem(ir, 2)->valuedouble == 3.5, "meta irradiance");
  cJSON_Delete(j);
  free(text);

  void *bytes = NULL;
  REQUIRE(http_film_npy(&f, &bytes, &len, &err) == RSW_OK, "npy: %s", err.msg);
  const uint8_t *p = bytes;
  size_t start = 10 + ((size_t)p[8] | (size_t)p[9] << 8);
  CHECK(strstr((const char *)p + 10, "'shape': (2, 3, 9)") != NULL, "npy shape (H, W, 9)");
  CHECK(len == start + 54 * 4, "npy length");
  float v;
  memcpy(&v, p + start + 4 * (9 * 5 + 7), 4); /* pixel 5, radiance_stderr.G (little-endian host) */
  CHECK(v == se[5 * 3 + 1], "npy stderr sample %g", (double)v);
  free(bytes);

  REQUIRE(http_film_exr(&f, &bytes, &len, &err) == RSW_OK, "exr: %s", err.msg);
  char path[] = "/tmp/rsw_planes_XXXXXX";
  int fd = mkstemp(path);
  REQUIRE(fd >= 0, "temp file");
  CHECK(write(fd, bytes, len) == (ssize_t)len, "write");
  close(fd);
  free(bytes);
  exr_image im;
  REQUIRE(exr_read_image(path, &im, &err) == RSW_OK, "read back: %s", err.msg);
  unlink(path);
  CHECK(im.n_channels == 9, "exr channels %d", im.n_channels);
  int kb = exr_image_channel(&im, "brf.G"), ks = exr_image_channel(&im, "radiance_stderr.B");
  REQUIRE(kb >= 0 && ks >= 0, "exr has brf.G and radiance_stderr.B");
  CHECK(im.data[4 * 9 + kb] == brf[4 * 3 + 1] && im.data[4 * 9 + ks] == se[4 * 3 + 2], "exr plane values");
  const char *irr = exr_image_meta(&im, "raysweep:irradiance");
  CHECK(irr && strcmp(irr, "1.5,2.5,3.5") == 0, "raysweep:irradiance '%s'", irr ? irr : "(none)");
  exr_image_free(&im);
}

/* The quick-look decodes (libpng) to the film's size, 8-bit, and its
 * brightest pixel is where the film's brightest value is (the only white
 * one when that value alone reaches 1 after the exposure). */
static void check_png(const void *bytes, size_t len, int W, int H, int want_channels, int bright_x,
                      int bright_y) {
  png_image im;
  memset(&im, 0, sizeof im);
  im.version = PNG_IMAGE_VERSION;
  REQUIRE(png_image_begin_read_from_memory(&im, bytes, len), "png does not decode: %s", im.message);
  CHECK((int)im.width == W && (int)im.height == H, "png is %ux%u, want %dx%d", im.width, im.height, W, H);
  CHECK((int)PNG_IMAGE_SAMPLE_CHANNELS(im.format) == want_channels, "png has %d channels, want %d",
        (int)PNG_IMAGE_SAMPLE_CHANNELS(im.format), want_channels);
  im.format = PNG_FORMAT_GRAY;
  unsigned char *px = malloc(PNG_IMAGE_SIZE(im));
  REQUIRE(px && png_image_finish_read(&im, NULL, px, 0, NULL), "png pixels: %s", im.message);
  int best = -1, at = -1, n_best = 0;
  for (int i = 0; i < W * H; i++) {
    if (px[i] > best) best = px[i], at = i, n_best = 0;
    if (px[i] == best) n_best++;
  }
  CHECK(at == bright_y * W + bright_x && n_best == 1, "brightest png pixel %d (x %d) of %d, want (%d, %d)",
        at, n_best, best, bright_x, bright_y);
  free(px);
}

/* A grey PNG's 8-bit values (n of them); false when it does not decode. */
static bool gray_pixels(const void *bytes, size_t len, unsigned char *out, int n) {
  png_image im;
  memset(&im, 0, sizeof im);
  im.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&im, bytes, len)) return false;
  im.format = PNG_FORMAT_GRAY;
  if ((int)PNG_IMAGE_SIZE(im) != n) {
    png_image_free(&im);
    return false;
  }
  return png_image_finish_read(&im, NULL, out, 0, NULL) != 0;
}

/* The sRGB transfer curve (IEC 61966-2-1) of v in [0, 1], to 8 bits. */
static int srgb8_of(double v) {
  return (int)lrint(255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1 / 2.4) - 0.055));
}

/* "auto" exposure: the 99.5th percentile (nearest rank) of the values > 0
 * maps to white, not the maximum. 1000 pixels 1..1000 (x 1e-3) and a lamp
 * of 1e6: the 995th value (0.995) is white and 0.4975 is sRGB 188; with
 * the maximum as white (the old auto) the whole ramp was black but the
 * lamp. Then the exposure's text forms. */
static void test_png_auto_exposure(void) {
  enum {
    N = 1001
  };
  float v[N];
  for (int i = 0; i < N - 1; i++) v[i] = 1e-3f * (float)(i + 1);
  v[N - 1] = 1e6f;
  svc_film f;
  memset(&f, 0, sizeof f);
  f.img.width = N, f.img.height = 1, f.img.channels = 1;
  f.img.channel_names[0] = "Y";
  f.img.data = v;
  f.img.variant = VARIANT_MONO;
  png_look look = {0};
  CHECK(png_exposure_parse("auto", &look) && look.auto_exposure && look.exposure == 0, "parse auto");
  void *bytes = NULL;
  size_t len = 0;
  rsw_err err = {0};
  REQUIRE(http_film_png(&f, &look, &bytes, &len, &err) == RSW_OK, "auto png: %s", err.msg);
  unsigned char g[N];
  REQUIRE(gray_pixels(bytes, len, g, N), "grey pixels");
  free(bytes);
  /* pixel 994 holds 0.995 (white), pixel 899 0.9 and 496 0.497 (each its
   * sRGB value over white), the lamp clips. */
  CHECK(g[994] == 255 && g[899] == srgb8_of(0.9 / 0.995) && g[496] == srgb8_of(0.497 / 0.995) &&
            g[496] > 150 && g[N - 1] == 255,
        "auto: 0.995 -> %d (255), 0.9 -> %d (%d), 0.497 -> %d (%d), lamp -> %d", g[994], g[899],
        srgb8_of(0.9 / 0.995), g[496], srgb8_of(0.497 / 0.995), g[N - 1]);
  CHECK(png_exposure_parse("auto+1", &look) && look.auto_exposure && look.exposure == 1, "parse auto+1");
  REQUIRE(http_film_png(&f, &look, &bytes, &len, &err) == RSW_OK, "auto+1 png: %s", err.msg);
  REQUIRE(gray_pixels(bytes, len, g, N), "grey pixels");
  free(bytes);
  CHECK(g[496] == 255 && g[247] == srgb8_of(2 * 0.248 / 0.995), "auto+1: 0.497 -> %d (255), 0.248 -> %d (%d)",
        g[496], g[247], srgb8_of(2 * 0.248 / 0.995));
  CHECK(png_exposure_parse("auto-0.5", &look) && look.auto_exposure && look.exposure == -0.5, "auto-0.5");
  CHECK(png_exposure_parse("-2.5", &look) && !look.auto_exposure && look.exposure == -2.5, "-2.5");
  const char *bad[] = {"", "autox", "auto+", "auto1", "nan", "inf", "1e9", "1 ", "auto+1e9", NULL};
  for (int i = 0; bad[i]; i++) {
    png_look l = {.exposure = 7};
    CHECK(!png_exposure_parse(bad[i], &l) && l.exposure == 7, "'%s' is refused and changes nothing", bad[i]);
  }
  CHECK(!png_exposure_parse(NULL, &look), "NULL refused");
}

static void test_film_png(void) {
  enum {
    W = 7,
    H = 5
  };
  float y[W * H];
  for (int i = 0; i < W * H; i++) y[i] = 0.01f * (float)((i * 7) % 13);
  y[3 * W + 5] = 2.0f; /* the brightest value, at (5, 3) */
  y[1] = NAN;
  svc_film f;
  memset(&f, 0, sizeof f);
  f.img.width = W, f.img.height = H, f.img.channels = 1;
  f.img.channel_names[0] = "Y";
  f.img.data = y;
  f.img.variant = VARIANT_MONO;
  void *bytes = NULL;
  size_t len = 0;
  rsw_err err = {0};
  REQUIRE(http_film_png(&f, NULL, &bytes, &len, &err) == RSW_OK, "png: %s", err.msg);
  check_png(bytes, len, W, H, 1, 5, 3);
  free(bytes);
  /* Mitsuba's mapping: linear values clamped to [0, 1], sRGB-encoded; 0.5
   * is sRGB 188 whatever the brightest value (it was 137, 0.5 / 2.0, when
   * the maximum mapped to white). */
  y[0] = 0.5f;
  REQUIRE(http_film_png(&f, NULL, &bytes, &len, &err) == RSW_OK, "png: %s", err.msg);
  unsigned char g[W * H];
  REQUIRE(gray_pixels(bytes, len, g, W * H), "grey pixels");
  CHECK(g[0] == 188 && g[3 * W + 5] == 255 && g[1] == 0,
        "0.5 -> %d (want 188), 2.0 -> %d (255), NaN -> %d (0)", g[0], g[3 * W + 5], g[1]);
  free(bytes);
  png_look minus1 = {.exposure = -1};
  REQUIRE(http_film_png(&f, &minus1, &bytes, &len, &err) == RSW_OK, "png: %s", err.msg);
  REQUIRE(gray_pixels(bytes, len, g, W * H), "grey pixels");
  CHECK(g[0] == 137 && g[3 * W + 5] == 255, "exposure -1: 0.5 -> %d (want 137 = sRGB of 0.25), 2.0 -> %d",
        g[0], g[3 * W + 5]);
  free(bytes);
  png_look look = {.exposure = -1, .colormap = "viridis"};
  REQUIRE(http_film_png(&f, &look, &bytes, &len, &err) == RSW_OK, "viridis png: %s", err.msg);
  check_png(bytes, len, W, H, 3, 5, 3);
  free(bytes);
  /* RGB: the brightest pixel of the three channels. */
  float rgb[18];
  svc_film c = make_film(rgb);
  rgb[3 * 4 + 1] = 9.0f;                       /* pixel 4 = (1, 1), G */
  png_look autolook = {.auto_exposure = true}; /* 18 values: the 99.5th percentile is the largest */
  REQUIRE(http_film_png(&c, &autolook, &bytes, &len, &err) == RSW_OK, "rgb png: %s", err.msg);
  check_png(bytes, len, 3, 2, 3, 1, 1);
  free(bytes);
  err = (rsw_err){0};
  CHECK(http_film_png(&c, &look, &bytes, &len, &err) == RSW_ERR_INVALID && strstr(err.msg, "one-channel"),
        "a colormap on an rgb film is refused: %s", err.msg);
  err = (rsw_err){0};
  png_look bad = {.colormap = "jet"};
  CHECK(http_film_png(&f, &bad, &bytes, &len, &err) == RSW_ERR_INVALID && strstr(err.msg, "jet"),
        "unknown colormap refused: %s", err.msg);
}

static void test_problem(void) {
  const char *cands[3] = {"a.value", "", "b.value"};
  char *t = http_problem_json(422, "RSW_ERR_INVALID", "bad \"x\"", "/shapes/0", "x.value", cands, 3);
  REQUIRE(t, "problem");
  cJSON *j = cJSON_Parse(t);
  REQUIRE(j, "problem does not parse: %s", t);
  CHECK(strcmp(cJSON_GetObjectItem(j, "type")->valuestring,
               "https://raysweep.dev/problems/RSW_ERR_INVALID") == 0,
        "type");
  CHECK(strcmp(cJSON_GetObjectItem(j, "title")->valuestring, "Unprocessable Content") == 0, "title");
  CHECK(cJSON_GetObjectItem(j, "status")->valueint == 422, "status");
  CHECK(strcmp(cJSON_GetObjectItem(j, "detail")->valuestring, "bad \"x\"") == 0, "detail");
  CHECK(strcmp(cJSON_GetObjectItem(j, "pointer")->valuestring, "/shapes/0") == 0, "pointer");
  CHECK(strcmp(cJSON_GetObjectItem(j, "key")->valuestring, "x.value") == 0, "key");
  cJSON *c = cJSON_GetObjectItem(j, "candidates");
  CHECK(cJSON_GetArraySize(c) == 2, "two non-empty candidates");
  cJSON_Delete(j);
  free(t);

  svc_error e;
  memset(&e, 0, sizeof e);
  rsw_fail(&e.err, RSW_ERR_NOT_FOUND, "", "no scene 'abc'");
  int status = 0;
  t = http_problem_from_svc(&e, &status);
  REQUIRE(t, "from svc");
  j = cJSON_Parse(t);
  REQUIRE(j, "does not parse");
  CHECK(status == 404 && cJSON_GetObjectItem(j, "status")->valueint == 404, "404 from the code");
  CHECK(strcmp(cJSON_GetObjectItem(j, "code")->valuestring, "RSW_ERR_NOT_FOUND") == 0, "code");
  CHECK(strcmp(cJSON_GetObjectItem(j, "title")->valuestring, "not found") == 0,
        "title is the code's message");
  CHECK(!cJSON_GetObjectItem(j, "pointer") && !cJSON_GetObjectItem(j, "key"), "no pointer, no key");
  cJSON_Delete(j);
  free(t);

  /* The status follows from the code alone (no service-chosen status). */
  memset(&e, 0, sizeof e);
  rsw_fail(&e.err, RSW_ERR_UNKNOWN_NAME, "/sensor", "no sensor 'x'");
  t = http_problem_from_svc(&e, &status);
  CHECK(t && status == 422, "unknown name: %d", status);
  free(t);

  /* file:line is a place (pointer); a digest in where is not. */
  memset(&e, 0, sizeof e);
  rsw_fail(&e.err, RSW_ERR_PARSE, "scene.xml:12", "bad tag");
  t = http_problem_from_svc(&e, &status);
  j = t ? cJSON_Parse(t) : NULL;
  REQUIRE(j, "does not parse");
  cJSON *ptr = cJSON_GetObjectItem(j, "pointer");
  CHECK(status == 400 && ptr && strcmp(ptr->valuestring, "scene.xml:12") == 0, "file:line pointer");
  CHECK(strcmp(cJSON_GetObjectItem(j, "detail")->valuestring, "scene.xml:12: bad tag") == 0, "detail");
  cJSON_Delete(j);
  free(t);
  /* A message that names its key already: the detail names it once
   * (issue 24: errors repeated the key three times). */
  memset(&e, 0, sizeof e);
  rsw_fail(&e.err, RSW_ERR_RANGE, "s.bsdf.alpha.value", "'s.bsdf.alpha.value': value -3 must be >= 0.0001");
  t = http_problem_from_svc(&e, &status);
  j = t ? cJSON_Parse(t) : NULL;
  REQUIRE(j, "does not parse");
  const char *det = cJSON_GetObjectItem(j, "detail")->valuestring;
  const char *first = strstr(det, "s.bsdf.alpha.value");
  CHECK(first && !strstr(first + 1, "s.bsdf.alpha.value"), "the key once in the detail: %s", det);
  cJSON_Delete(j);
  free(t);
  memset(&e, 0, sizeof e);
  rsw_fail(&e.err, RSW_ERR_INVALID, "ab12", "digest mismatch");
  t = http_problem_from_svc(&e, &status);
  j = t ? cJSON_Parse(t) : NULL;
  REQUIRE(j, "does not parse");
  CHECK(!cJSON_GetObjectItem(j, "pointer"), "a digest is not a pointer");
  cJSON_Delete(j);
  free(t);

  /* HTTP-layer problems: code NULL gives the status name. */
  t = http_problem_json(413, NULL, "too big", NULL, NULL, NULL, 0);
  j = t ? cJSON_Parse(t) : NULL;
  REQUIRE(j, "does not parse");
  CHECK(strcmp(cJSON_GetObjectItem(j, "code")->valuestring, "CONTENT_TOO_LARGE") == 0, "code from status");
  CHECK(strcmp(cJSON_GetObjectItem(j, "type")->valuestring,
               "https://raysweep.dev/problems/CONTENT_TOO_LARGE") == 0,
        "type from status");
  cJSON_Delete(j);
  free(t);
}

/* Strict UTF-8 check (RFC 3629), written independently of encode.c's. */
static bool valid_utf8(const unsigned char *s, size_t n) {
  for (size_t i = 0; i < n;) {
    uint32_t cp;
    size_t k;
    if (s[i] < 0x80) {
      i++;
      continue;
    } else if ((s[i] & 0xE0) == 0xC0)
      k = 2, cp = s[i] & 0x1F;
    else if ((s[i] & 0xF0) == 0xE0)
      k = 3, cp = s[i] & 0x0F;
    else if ((s[i] & 0xF8) == 0xF0)
      k = 4, cp = s[i] & 0x07;
    else
      return false;
    if (i + k > n) return false;
    for (size_t j = 1; j < k; j++) {
      if ((s[i + j] & 0xC0) != 0x80) return false;
      cp = cp << 6 | (s[i + j] & 0x3F);
    }
    static const uint32_t min_cp[5] = {0, 0, 0x80, 0x800, 0x10000};
    if (cp < min_cp[k] || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return false;
    i += k;
  }
  return true;
}

/* A key with invalid UTF-8 (a lone continuation byte, a truncated
 * sequence, an overlong '/', a surrogate, a code point past U+10FFFF) is
 * echoed in detail and key: the body must stay valid UTF-8 JSON, with the
 * bad bytes replaced and the good ones (e-acute, a 4-byte emoji) kept. */
static void test_problem_utf8(void) {
  const char *bad = "k\x80"
                    "a\xc3"
                    "b\xc0\xaf"
                    "c\xed\xa0\x80"
                    "d\xf4\x90\x80\x80"
                    "e\xc3\xa9"
                    "f\xf0\x9f\x98\x80"
                    "\xff";
  char detail[256];
  snprintf(detail, sizeof detail, "unknown key '%s'", bad);
  char *t = http_problem_json(422, "RSW_ERR_INVALID", detail, "/params/x", bad, NULL, 0);
  REQUIRE(t, "problem");
  CHECK(valid_utf8((const unsigned char *)t, strlen(t)), "body is not valid UTF-8: %s", t);
  cJSON *j = cJSON_Parse(t);
  REQUIRE(j, "problem does not parse: %s", t);
  const char *key = cJSON_GetObjectItem(j, "key")->valuestring;
  CHECK(strstr(key, "e\xc3\xa9"
                    "f\xf0\x9f\x98\x80") != NULL,
        "good UTF-8 kept: %s", key);
  CHECK(strncmp(key,
                "k\xef\xbf\xbd"
                "a\xef\xbf\xbd"
                "b",
                9) == 0,
        "bad bytes become U+FFFD: %s", key);
  cJSON_Delete(j);
  free(t);
  /* The same through the service path (detail = "where: message"). */
  svc_error e;
  memset(&e, 0, sizeof e);
  rsw_fail(&e.err, RSW_ERR_NOT_FOUND, bad, "no key '%s'", bad);
  int status = 0;
  t = http_problem_from_svc(&e, &status);
  REQUIRE(t, "from svc");
  CHECK(valid_utf8((const unsigned char *)t, strlen(t)), "svc body is not valid UTF-8: %s", t);
  j = cJSON_Parse(t);
  CHECK(j != NULL, "svc problem does not parse");
  cJSON_Delete(j);
  free(t);
}

static void test_accept(void) {
  CHECK(http_accept_film(NULL) == HTTP_FILM_JSON, "missing");
  CHECK(http_accept_film("") == HTTP_FILM_JSON, "empty");
  CHECK(http_accept_film("*/*") == HTTP_FILM_JSON, "*/*");
  CHECK(http_accept_film("image/x-exr") == HTTP_FILM_EXR, "exr");
  CHECK(http_accept_film("Application/X-NPY") == HTTP_FILM_NPY, "npy, case");
  CHECK(http_accept_film("text/html, application/x-npy;q=0.5") == HTTP_FILM_NPY, "npy second");
  CHECK(http_accept_film("*/*;q=0.1, image/x-exr") == HTTP_FILM_EXR, "exact beats wildcard");
  CHECK(http_accept_film("image/*") == HTTP_FILM_EXR, "image/*");
  CHECK(http_accept_film("application/*") == HTTP_FILM_JSON, "application/*");
  CHECK(http_accept_film("*/*, application/json;q=0") == HTTP_FILM_EXR, "json excluded");
  CHECK(http_accept_film("image/x-exr;q=0, image/*") == HTTP_FILM_PNG, "exr excluded under image/*: png");
  CHECK(http_accept_film("image/x-exr;q=0, image/png;q=0, image/*") == HTTP_FILM_NONE, "both excluded");
  CHECK(http_accept_film("image/png") == HTTP_FILM_PNG, "png");
  CHECK(strcmp(http_film_content_type(HTTP_FILM_PNG), "image/png") == 0, "png content type");
  CHECK(http_accept_film("text/html") == HTTP_FILM_NONE, "406");
  CHECK(http_accept_film("application/json;q=0") == HTTP_FILM_NONE, "only json, excluded");
  CHECK(http_accept_film("application/json; charset=\"utf-8,x\"; q=1") == HTTP_FILM_JSON, "quoted param");
}

static void test_depth_and_media(void) {
  char deep[200];
  memset(deep, '[', 65);
  memset(deep + 65, ']', 65);
  CHECK(!http_json_depth_ok(deep, 130, 64), "65 deep rejected");
  CHECK(http_json_depth_ok(deep + 1, 128, 64), "64 deep accepted");
  const char *s = "{\"a\": \"[[[[[[[[[[\\\"[[[[\", \"b\": [1, {\"c\": 2}]}";
  CHECK(http_json_depth_ok(s, strlen(s), 3), "brackets in strings do not count");
  CHECK(!http_json_depth_ok(s, strlen(s), 2), "depth 3 over a limit of 2");
  CHECK(http_media_type_is("application/json; charset=utf-8", "application/json"), "params");
  CHECK(http_media_type_is(" Application/JSON", "application/json"), "case");
  CHECK(!http_media_type_is("application/jsonx", "application/json"), "prefix only");
  CHECK(!http_media_type_is(NULL, "application/json"), "missing");
}

/* One media type against Accept (the dataset route): listed, wildcards,
 * q=0 exclusions; media types are case-insensitive. */
static void test_accepts(void) {
  const char *nc = "application/x-netcdf";
  CHECK(http_accepts(NULL, nc) && http_accepts("", nc) && http_accepts("  ", nc), "no Accept: anything");
  CHECK(http_accepts("application/x-netcdf", nc), "exact");
  CHECK(http_accepts("Application/X-NetCDF", nc), "case");
  CHECK(http_accepts("*/*", nc) && http_accepts("application/*", nc), "wildcards");
  CHECK(http_accepts("application/json, application/x-netcdf;q=0.5", nc), "in a list");
  CHECK(!http_accepts("application/json", nc), "another type");
  CHECK(!http_accepts("image/*", nc), "another major type's wildcard");
  CHECK(!http_accepts("*/*, application/x-netcdf;q=0", nc), "excluded by q=0");
}

int main(void) {
  RSW_TEST_RUN(test_accepts);
  RSW_TEST_RUN(test_film_json);
  RSW_TEST_RUN(test_film_npy);
  RSW_TEST_RUN(test_exr_round_trip);
  RSW_TEST_RUN(test_exr_half_large);
  RSW_TEST_RUN(test_film_planes);
  RSW_TEST_RUN(test_film_png);
  RSW_TEST_RUN(test_png_auto_exposure);
  RSW_TEST_RUN(test_problem);
  RSW_TEST_RUN(test_problem_utf8);
  RSW_TEST_RUN(test_accept);
  RSW_TEST_RUN(test_depth_and_media);
  RSW_TEST_END("test_http_encode");
}
