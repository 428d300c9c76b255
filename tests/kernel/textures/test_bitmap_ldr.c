/* `bitmap` textures from PNG and JPEG files (textures/bitmap.c,
 * image_ldr.c): a texture's texel values read back through a render.
 *
 * A rectangle ([-1, 1]^2, uv (0, 0) at (-1, -1)) with a diffuse BSDF whose
 * reflectance is the bitmap, under a sun of irradiance 1 at the zenith, is
 * seen by four radiancemeters (an mradiancemeter) looking straight down at
 * the centres of its quadrants: pixel k gives rho_k / pi with no variance.
 * Image row 0 is the top (v = 1), so texel (i, j) is the quadrant centred
 * at (-0.5 + i, 0.5 - j). Expected rho: the stored value c / 255
 * sRGB-decoded (IEC 61966-2-1), or c / 255 itself with raw = true.
 * PNG: to 1e-6 relative (float32 film); JPEG (lossy, quality 100, no
 * chroma subsampling, uniform 8 x 8 blocks): within 2 / 255 of the stored
 * code value. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include <jpeglib.h>
#include <png.h>

#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

/* The four texels (row-major, row 0 = top), RGB 8-bit. */
static const unsigned char TEX[4][3] = {{255, 0, 30}, {10, 128, 200}, {64, 64, 64}, {230, 180, 2}};

static double srgb_decode(double c) {
  return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

static bool write_png(const char *path, int gray, int bits) {
  FILE *f = fopen(path, "wb");
  if (!f) return false;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
  png_infop info = png_create_info_struct(png);
  if (setjmp(png_jmpbuf(png))) {
    fclose(f);
    return false;
  }
  png_init_io(png, f);
  int ch = gray ? 1 : 3;
  png_set_IHDR(png, info, 2, 2, bits, gray ? PNG_COLOR_TYPE_GRAY : PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < 2; y++) {
    unsigned char row[2 * 3 * 2];
    for (int x = 0; x < 2; x++)
      for (int c = 0; c < ch; c++) {
        unsigned v = TEX[2 * y + x][c];
        if (bits == 16) {
          unsigned v16 = v * 257; /* the same fraction of full scale */
          row[2 * (x * ch + c)] = (unsigned char)(v16 >> 8), row[2 * (x * ch + c) + 1] = (unsigned char)v16;
        } else {
          row[x * ch + c] = (unsigned char)v;
        }
      }
    png_write_row(png, row);
  }
  png_write_end(png, NULL);
  png_destroy_write_struct(&png, &info);
  return fclose(f) == 0;
}

/* A 16 x 16 JPEG: each 8 x 8 block one texel of TEX. */
static bool write_jpeg(const char *path) {
  FILE *f = fopen(path, "wb");
  if (!f) return false;
  struct jpeg_compress_struct c;
  struct jpeg_error_mgr jerr;
  c.err = jpeg_std_error(&jerr);
  jpeg_create_compress(&c);
  jpeg_stdio_dest(&c, f);
  c.image_width = 16, c.image_height = 16, c.input_components = 3, c.in_color_space = JCS_RGB;
  jpeg_set_defaults(&c);
  jpeg_set_quality(&c, 100, TRUE);
  for (int k = 0; k < c.num_components; k++) c.comp_info[k].h_samp_factor = c.comp_info[k].v_samp_factor = 1;
  jpeg_start_compress(&c, TRUE);
  for (int y = 0; y < 16; y++) {
    unsigned char row[16 * 3];
    for (int x = 0; x < 16; x++)
      for (int ch = 0; ch < 3; ch++) row[3 * x + ch] = TEX[2 * (y / 8) + x / 8][ch];
    JSAMPROW rp = row;
    jpeg_write_scanlines(&c, &rp, 1);
  }
  jpeg_finish_compress(&c);
  jpeg_destroy_compress(&c);
  return fclose(f) == 0;
}

/* Renders the plate with the bitmap (extra: more bitmap properties, JSON
 * or XML) and writes the four quadrants' rho (pixel value times pi). */
static bool quadrants(const char *path, const char *extra_json, const char *variant, bool xml,
                      double rho[4][3], int *channels) {
  char buf[4096];
  if (!xml)
    snprintf(
        buf, sizeof buf,
        "{\"type\": \"scene\","
        " \"sensor\": {\"type\": \"mradiancemeter\","
        "   \"origins\": \"-0.5 0.5 1 0.5 0.5 1 -0.5 -0.5 1 0.5 -0.5 1\","
        "   \"directions\": \"0 0 -1 0 0 -1 0 0 -1 0 0 -1\","
        "   \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 1, \"rfilter\": {\"type\": "
        "\"box\"}}},"
        " \"integrator\": {\"type\": \"path\", \"max_depth\": 2},"
        " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1},"
        " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\","
        "   \"reflectance\": {\"type\": \"bitmap\", \"filename\": \"%s\", \"filter_type\": \"nearest\"%s}}}}",
        path, extra_json);
  else
    snprintf(
        buf, sizeof buf,
        "<scene version=\"3.0.0\">"
        " <sensor type=\"mradiancemeter\">"
        "  <string name=\"origins\" value=\"-0.5 0.5 1 0.5 0.5 1 -0.5 -0.5 1 0.5 -0.5 1\"/>"
        "  <string name=\"directions\" value=\"0 0 -1 0 0 -1 0 0 -1 0 0 -1\"/>"
        "  <film type=\"hdrfilm\"><integer name=\"width\" value=\"4\"/><integer name=\"height\" value=\"1\"/>"
        "   <rfilter type=\"box\"/></film></sensor>"
        " <integrator type=\"path\"><integer name=\"max_depth\" value=\"2\"/></integrator>"
        " <emitter type=\"directional\"><vector name=\"direction\" value=\"0, 0, -1\"/></emitter>"
        " <shape type=\"rectangle\"><bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\">"
        "  <string name=\"filename\" value=\"%s\"/><string name=\"filter_type\" value=\"nearest\"/>%s"
        " </texture></bsdf></shape></scene>",
        path, extra_json);
  scene *s = tsup_load(buf, variant);
  if (!s) return false;
  film_image img;
  bool ok = tsup_render(s, 4, 1, 1, &img);
  if (ok) {
    *channels = img.channels;
    for (int k = 0; k < 4; k++)
      for (int c = 0; c < 3; c++)
        rho[k][c] = RSW_PI * img.data[k * img.channels + (img.channels == 3 ? c : 0)];
    film_image_free(&img);
  }
  scene_free(s);
  return ok;
}

static void check_rgb(const double rho[4][3], bool raw, double tol_code, const char *what) {
  for (int k = 0; k < 4; k++)
    for (int c = 0; c < 3; c++) {
      double code = TEX[k][c] / 255.0;
      double want = raw ? code : srgb_decode(code);
      if (tol_code == 0) {
        CHECK(fabs(rho[k][c] - want) <= 1e-6 * fmax(want, 1e-3),
              "%s texel %d channel %d: %.8g, expected %.8g", what, k, c, rho[k][c], want);
      } else {
        /* Back to a code value and compare there. */
        double got =
            raw ? rho[k][c]
                : (rho[k][c] <= 0.0031308 ? 12.92 * rho[k][c] : 1.055 * pow(rho[k][c], 1 / 2.4) - 0.055);
        CHECK(fabs(got - code) <= tol_code, "%s texel %d channel %d: code %.2f, expected %d", what, k, c,
              got * 255, TEX[k][c]);
      }
    }
}

static void test_png_texels(void) {
  char path[] = "/tmp/rsw_bitmap_XXXXXX.png";
  int fd = mkstemps(path, 4);
  REQUIRE(fd >= 0, "temp file");
  close(fd);
  REQUIRE(write_png(path, 0, 8), "write PNG");
  double rho[4][3];
  int ch;
  REQUIRE(quadrants(path, "", NULL, false, rho, &ch), "render");
  check_rgb(rho, false, 0, "PNG sRGB");
  REQUIRE(quadrants(path, ", \"raw\": true", NULL, false, rho, &ch), "render raw");
  check_rgb(rho, true, 0, "PNG raw");
  REQUIRE(quadrants(path, "<boolean name=\"raw\" value=\"true\"/>", NULL, true, rho, &ch), "render XML");
  check_rgb(rho, true, 0, "PNG raw (XML)");
  /* mono: the luminance of the decoded linear RGB. */
  REQUIRE(quadrants(path, "", "mono", false, rho, &ch), "render mono");
  CHECK(ch == 1, "mono film has one channel");
  for (int k = 0; k < 4; k++) {
    double l[3];
    for (int c = 0; c < 3; c++) l[c] = srgb_decode(TEX[k][c] / 255.0);
    double y = 0.212671 * l[0] + 0.715160 * l[1] + 0.072169 * l[2];
    CHECK(fabs(rho[k][0] - y) <= 2e-6, "mono texel %d: %.8g, expected %.8g", k, rho[k][0], y);
  }
  /* 16-bit: v * 257 / 65535 is v / 255 exactly. */
  REQUIRE(write_png(path, 0, 16), "write 16-bit PNG");
  REQUIRE(quadrants(path, "", NULL, false, rho, &ch), "render 16-bit");
  check_rgb(rho, false, 0, "PNG 16-bit");
  remove(path);
}

static void test_jpeg_texels(void) {
  char path[] = "/tmp/rsw_bitmap_XXXXXX.jpg";
  int fd = mkstemps(path, 4);
  REQUIRE(fd >= 0, "temp file");
  close(fd);
  REQUIRE(write_jpeg(path), "write JPEG");
  double rho[4][3];
  int ch;
  REQUIRE(quadrants(path, "", NULL, false, rho, &ch), "render");
  check_rgb(rho, false, 2.0 / 255, "JPEG sRGB");
  REQUIRE(quadrants(path, ", \"raw\": true", NULL, false, rho, &ch), "render raw");
  check_rgb(rho, true, 2.0 / 255, "JPEG raw");
  remove(path);
}

static void test_bad_files(void) {
  char path[] = "/tmp/rsw_bitmap_XXXXXX.png";
  int fd = mkstemps(path, 4);
  REQUIRE(fd >= 0, "temp file");
  close(fd);
  REQUIRE(write_png(path, 0, 8), "write PNG");
  /* Truncated after the header: refused, naming the file. */
  REQUIRE(truncate(path, 40) == 0, "truncate");
  char buf[1024];
  snprintf(buf, sizeof buf, "{\"type\": \"scene\", \"t\": {\"type\": \"bitmap\", \"filename\": \"%s\"}}",
           path);
  rsw_err err = {0};
  scene *s = NULL;
  CHECK(scene_load_memory(buf, strlen(buf), "bad.json", false, NULL, &s, &err) != RSW_OK && !s,
        "truncated PNG");
  char msg[1200];
  CHECK(strstr(rsw_err_format(&err, msg, sizeof msg), path) != NULL, "the error names the file: %s", msg);
  FILE *f = fopen(path, "wb");
  REQUIRE(f, "rewrite");
  fputs("\xff\xd8\xff garbage", f);
  fclose(f);
  err = (rsw_err){0};
  CHECK(scene_load_memory(buf, strlen(buf), "bad.json", false, NULL, &s, &err) != RSW_OK && !s,
        "corrupt JPEG");
  remove(path);
}

int main(void) {
  RSW_TEST_RUN(test_png_texels);
  RSW_TEST_RUN(test_jpeg_texels);
  RSW_TEST_RUN(test_bad_files);
  RSW_TEST_END("test_bitmap_ldr");
}
