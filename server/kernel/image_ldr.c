/* PNG and JPEG decoding for bitmap textures (image_ldr.h). */
#include "image_ldr.h"

#include <math.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <jpeglib.h>
#include <png.h>

#define LDR_MAX_SAMPLES ((size_t)1 << 28)

double srgb_to_linear(double c) {
  return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

ldr_format ldr_sniff(const char *path) {
  unsigned char m[8] = {0};
  FILE *f = fopen(path, "rb");
  if (!f) return LDR_NONE;
  size_t n = fread(m, 1, sizeof m, f);
  fclose(f);
  if (n >= 8 && png_sig_cmp(m, 0, 8) == 0) return LDR_PNG;
  if (n >= 3 && m[0] == 0xFF && m[1] == 0xD8 && m[2] == 0xFF) return LDR_JPEG;
  return LDR_NONE;
}

void ldr_image_free(ldr_image *img) {
  if (!img) return;
  free(img->data);
  memset(img, 0, sizeof *img);
}

/* Room for w x h x c floats, or an error naming path. */
static rsw_status alloc_pixels(const char *path, size_t w, size_t h, int c, float **out, rsw_err *err) {
  if (w == 0 || h == 0 || w > LDR_MAX_SAMPLES / h || w * h > LDR_MAX_SAMPLES / (size_t)c)
    return rsw_fail(err, RSW_ERR_LIMIT, path, "image '%s' is %zu x %zu: larger than %zu samples", path, w, h,
                    LDR_MAX_SAMPLES);
  *out = malloc(w * h * (size_t)c * sizeof(float));
  return *out ? RSW_OK : rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory reading '%s'", path);
}

/* ---- PNG ---------------------------------------------------------------- */

typedef struct png_ctx {
  char msg[200];
} png_ctx;

static void png_on_error(png_structp png, png_const_charp msg) {
  png_ctx *c = png_get_error_ptr(png);
  snprintf(c->msg, sizeof c->msg, "%s", msg);
  png_longjmp(png, 1);
}

static void png_on_warning(png_structp png, png_const_charp msg) {
  (void)png, (void)msg;
}

static rsw_status read_png(const char *path, FILE *f, ldr_image *out, rsw_err *err) {
  png_ctx ctx = {{0}};
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &ctx, png_on_error, png_on_warning);
  png_infop info = png ? png_create_info_struct(png) : NULL;
  if (!info) {
    png_destroy_read_struct(&png, NULL, NULL);
    return rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory reading '%s'", path);
  }
  /* Set before setjmp and read after a longjmp: volatile. */
  float *volatile data = NULL;
  unsigned char *volatile row = NULL;
  volatile rsw_status st = RSW_OK;
  if (setjmp(png_jmpbuf(png))) {
    free(data);
    free(row);
    png_destroy_read_struct(&png, &info, NULL);
    if (st != RSW_OK) return st;
    return rsw_fail(err, RSW_ERR_FILE, path, "PNG '%s' is corrupt or truncated: %s", path, ctx.msg);
  }
  png_init_io(png, f);
  png_read_info(png, info);
  png_uint_32 w = png_get_image_width(png, info), h = png_get_image_height(png, info);
  int depth = png_get_bit_depth(png, info), type = png_get_color_type(png, info);
  if (type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (type == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (type & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  int ch = png_get_channels(png, info), bits = png_get_bit_depth(png, info);
  int out_ch = ch >= 3 ? 3 : 1;
  float *px = NULL;
  st = alloc_pixels(path, w, h, out_ch, &px, err);
  data = px;
  size_t rowbytes = png_get_rowbytes(png, info);
  if (st == RSW_OK) {
    /* Interlaced images need every row at once; read one row at a time
     * otherwise. */
    row = malloc(rowbytes * (png_get_interlace_type(png, info) == PNG_INTERLACE_NONE ? 1 : h));
    if (!row) st = rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory reading '%s'", path);
  }
  if (st != RSW_OK) png_longjmp(png, 1);
  bool whole = png_get_interlace_type(png, info) != PNG_INTERLACE_NONE;
  if (whole) {
    png_bytep *rows = malloc(h * sizeof *rows);
    if (!rows) {
      st = rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory reading '%s'", path);
      png_longjmp(png, 1);
    }
    for (png_uint_32 y = 0; y < h; y++) rows[y] = row + y * rowbytes;
    png_read_image(png, rows);
    free(rows);
  }
  double scale = bits == 16 ? 1.0 / 65535.0 : 1.0 / 255.0;
  for (png_uint_32 y = 0; y < h; y++) {
    const unsigned char *r = whole ? row + y * rowbytes : row;
    if (!whole) png_read_row(png, row, NULL);
    for (png_uint_32 x = 0; x < w; x++)
      for (int c = 0; c < out_ch; c++) {
        size_t k = (size_t)x * ch + c;
        unsigned v = bits == 16 ? ((unsigned)r[2 * k] << 8 | r[2 * k + 1]) : r[k];
        data[((size_t)y * w + x) * out_ch + c] = (float)(v * scale);
      }
  }
  png_read_end(png, NULL);
  free(row);
  png_destroy_read_struct(&png, &info, NULL);
  out->width = (int)w, out->height = (int)h, out->n_channels = out_ch, out->data = data;
  return RSW_OK;
}

/* ---- JPEG --------------------------------------------------------------- */

typedef struct jpeg_err {
  struct jpeg_error_mgr mgr;
  jmp_buf jump;
} jpeg_err;

static void jpeg_on_error(j_common_ptr cinfo) {
  longjmp(((jpeg_err *)cinfo->err)->jump, 1);
}

static void jpeg_on_message(j_common_ptr cinfo) {
  (void)cinfo;
}

static rsw_status read_jpeg(const char *path, FILE *f, ldr_image *out, rsw_err *err) {
  struct jpeg_decompress_struct cinfo;
  jpeg_err je;
  cinfo.err = jpeg_std_error(&je.mgr);
  je.mgr.error_exit = jpeg_on_error;
  je.mgr.output_message = jpeg_on_message;
  float *volatile data = NULL;
  unsigned char *volatile row = NULL;
  if (setjmp(je.jump)) {
    char msg[JMSG_LENGTH_MAX];
    je.mgr.format_message((j_common_ptr)&cinfo, msg);
    jpeg_destroy_decompress(&cinfo);
    free(data);
    free(row);
    return rsw_fail(err, RSW_ERR_FILE, path, "JPEG '%s' is corrupt or truncated: %s", path, msg);
  }
  jpeg_create_decompress(&cinfo);
  jpeg_stdio_src(&cinfo, f);
  jpeg_read_header(&cinfo, TRUE);
  /* Grey stays grey; YCbCr, CMYK and the rest become RGB. */
  cinfo.out_color_space = cinfo.jpeg_color_space == JCS_GRAYSCALE ? JCS_GRAYSCALE : JCS_RGB;
  jpeg_start_decompress(&cinfo);
  int ch = cinfo.output_components;
  size_t w = cinfo.output_width, h = cinfo.output_height;
  float *px = NULL;
  rsw_status st = alloc_pixels(path, w, h, ch, &px, err);
  data = px;
  if (st == RSW_OK) {
    row = malloc(w * (size_t)ch);
    if (!row) st = rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory reading '%s'", path);
  }
  if (st != RSW_OK) {
    jpeg_destroy_decompress(&cinfo);
    free(data);
    return st;
  }
  while (cinfo.output_scanline < cinfo.output_height) {
    size_t y = cinfo.output_scanline;
    JSAMPROW rp = row;
    jpeg_read_scanlines(&cinfo, &rp, 1);
    for (size_t i = 0; i < w * (size_t)ch; i++) data[y * w * ch + i] = (float)(row[i] / 255.0);
  }
  jpeg_finish_decompress(&cinfo);
  jpeg_destroy_decompress(&cinfo);
  free(row);
  out->width = (int)w, out->height = (int)h, out->n_channels = ch, out->data = data;
  return RSW_OK;
}

rsw_status ldr_read_image(const char *path, ldr_image *out, rsw_err *err) {
  ldr_format fmt = ldr_sniff(path);
  if (fmt == LDR_NONE)
    return rsw_fail(err, RSW_ERR_FILE, path, "'%s' is neither a PNG nor a JPEG file", path);
  FILE *f = fopen(path, "rb");
  if (!f) return rsw_fail(err, RSW_ERR_FILE, path, "cannot open '%s'", path);
  ldr_image img = {0};
  rsw_status st = fmt == LDR_PNG ? read_png(path, f, &img, err) : read_jpeg(path, f, &img, err);
  fclose(f);
  if (st == RSW_OK) *out = img;
  return st;
}
