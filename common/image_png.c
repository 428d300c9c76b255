/* Film quick-looks as 8-bit PNGs (see image_png.h). The only file that
 * includes png.h. */
#include "image_png.h"

#include <math.h>
#include <png.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "rsw_file.h"

/* matplotlib's viridis and inferno at t = 0, 1/8, ..., 1 (8-bit sRGB). */
static const unsigned char viridis[9][3] = {{68, 1, 84},    {71, 44, 122},  {59, 81, 139},
                                            {44, 113, 142}, {33, 144, 141}, {39, 173, 129},
                                            {92, 200, 99},  {170, 220, 50}, {253, 231, 37}};
static const unsigned char inferno[9][3] = {{0, 0, 4},      {31, 12, 72},   {85, 15, 109},
                                            {136, 34, 106}, {186, 54, 85},  {227, 89, 51},
                                            {249, 140, 10}, {249, 201, 50}, {252, 255, 164}};

static const struct {
  const char *name;
  const unsigned char (*table)[3]; /* NULL: grey */
} colormaps[] = {{"gray", NULL}, {"viridis", viridis}, {"inferno", inferno}};

bool png_colormap_known(const char *name) {
  if (!name) return true;
  for (size_t i = 0; i < sizeof colormaps / sizeof colormaps[0]; i++)
    if (strcmp(colormaps[i].name, name) == 0) return true;
  return false;
}

const char *png_colormap_list(void) {
  return "gray, viridis, inferno";
}

/* sRGB transfer curve of a linear value in [0, 1], to 8 bits. */
static unsigned char srgb8(double v) {
  double s = v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
  return (unsigned char)lrint(fmin(fmax(s, 0.0), 1.0) * 255.0);
}

bool png_exposure_parse(const char *text, png_look *look) {
  if (!text) return false;
  bool is_auto = strncmp(text, "auto", 4) == 0;
  const char *num = is_auto ? text + 4 : text;
  double ev = 0;
  if (!is_auto || *num) {
    if (is_auto && *num != '+' && *num != '-') return false;
    char *end = NULL;
    ev = strtod(num, &end);
    if (end == num || *end || !isfinite(ev) || fabs(ev) > 1000) return false;
  }
  look->exposure = ev;
  look->auto_exposure = is_auto;
  return true;
}

static int cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* The PNG_AUTO_PERCENTILE-th percentile (nearest rank) of the finite
 * values > 0 of channels ch[0..count) of n pixels; 0 when there are none,
 * -1 when out of memory. */
static double auto_white(const float *data, size_t n, int n_channels, const int *ch, int count) {
  double *v = malloc((n * (size_t)count + 1) * sizeof *v);
  if (!v) return -1;
  size_t m = 0;
  for (size_t i = 0; i < n; i++)
    for (int k = 0; k < count; k++) {
      double x = data[i * (size_t)n_channels + (size_t)ch[k]];
      if (isfinite(x) && x > 0) v[m++] = x;
    }
  double white = 0;
  if (m) {
    qsort(v, m, sizeof *v, cmp_double);
    size_t rank = (size_t)ceil(PNG_AUTO_PERCENTILE / 100.0 * (double)m); /* 1-based */
    white = v[(rank < 1 ? 1 : rank > m ? m : rank) - 1];
  }
  free(v);
  return white;
}

static double shown(float v, double scale) {
  double x = (double)v * scale;
  return isfinite(x) && x > 0 ? fmin(x, 1.0) : 0.0;
}

/* The pixels as 8-bit rows (malloc'ed) and the PNG colour type. */
static rsw_status tonemap(int width, int height, int n_channels, const char *const *names, const float *data,
                          const png_look *look, const char *where, unsigned char **rows_out, int *color_type,
                          int *bpp, rsw_err *err) {
  png_look dflt = {0};
  if (!look) look = &dflt;
  if (width < 1 || height < 1 || n_channels < 1 || !data || !names)
    return rsw_fail(err, RSW_ERR_INVALID, where, "film has no pixels");
  if (!isfinite(look->exposure) || fabs(look->exposure) > 1000)
    return rsw_fail(err, RSW_ERR_INVALID, where, "exposure must be a finite number of stops");
  const unsigned char(*table)[3] = NULL;
  bool known = false;
  for (size_t i = 0; i < sizeof colormaps / sizeof colormaps[0]; i++)
    if (!look->colormap || strcmp(colormaps[i].name, look->colormap) == 0) {
      table = colormaps[i].table;
      known = true;
      break;
    }
  if (!known)
    return rsw_fail(err, RSW_ERR_INVALID, where, "unknown colormap '%s' (one of %s)", look->colormap,
                    png_colormap_list());
  /* A Stokes film shows its S0 (stokes.h): S0, S0.Y, or S0.R S0.G S0.B. */
  int idx[3] = {-1, -1, -1}, sidx[3] = {-1, -1, -1}, y = -1, s0 = -1;
  for (int c = 0; c < n_channels; c++) {
    const char *n = names[c] ? names[c] : "";
    if (strcmp(n, "R") == 0) idx[0] = c;
    if (strcmp(n, "G") == 0) idx[1] = c;
    if (strcmp(n, "B") == 0) idx[2] = c;
    if (strcmp(n, "Y") == 0) y = c;
    if (strcmp(n, "S0") == 0 || strcmp(n, "S0.Y") == 0) s0 = c;
    if (strcmp(n, "S0.R") == 0) sidx[0] = c;
    if (strcmp(n, "S0.G") == 0) sidx[1] = c;
    if (strcmp(n, "S0.B") == 0) sidx[2] = c;
  }
  if (idx[0] < 0 && sidx[0] >= 0) memcpy(idx, sidx, sizeof idx);
  bool rgb = idx[0] >= 0 && idx[1] >= 0 && idx[2] >= 0;
  int one = y >= 0 ? y : s0;
  if (!rgb && one < 0)
    return rsw_fail(err, RSW_ERR_INVALID, where, "the film has no R, G, B, Y or S0 (S0.Y) channel to show");
  if (rgb && look->colormap && table)
    return rsw_fail(err, RSW_ERR_INVALID, where,
                    "colormap '%s' is for one-channel films; this film has R, G, B", look->colormap);
  size_t px = (size_t)width * (size_t)height;
  double scale = exp2(look->exposure);
  if (look->auto_exposure) {
    double white = auto_white(data, px, n_channels, rgb ? idx : &one, rgb ? 3 : 1);
    if (white < 0) return rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory for a %dx%d PNG", width, height);
    if (white > 0) scale /= white;
  }
  *bpp = rgb || table ? 3 : 1;
  *color_type = *bpp == 3 ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_GRAY;
  unsigned char *rows = malloc(px * (size_t)*bpp);
  if (!rows) return rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory for a %dx%d PNG", width, height);
  for (size_t i = 0; i < px; i++) {
    const float *p = &data[i * (size_t)n_channels];
    unsigned char *o = &rows[i * (size_t)*bpp];
    if (rgb) {
      for (int k = 0; k < 3; k++) o[k] = srgb8(shown(p[idx[k]], scale));
    } else if (!table) {
      o[0] = srgb8(shown(p[one], scale));
    } else {
      double t = shown(p[one], scale) * 8;
      int j = t >= 8 ? 7 : (int)t;
      double f = t - j;
      for (int k = 0; k < 3; k++) o[k] = (unsigned char)lrint(table[j][k] + f * (table[j + 1][k] - table[j][k]));
    }
  }
  *rows_out = rows;
  return RSW_OK;
}

typedef struct membuf {
  unsigned char *p;
  size_t len, cap;
  bool failed;
} membuf;

static void mem_write(png_structp png, png_bytep data, png_size_t n) {
  membuf *m = png_get_io_ptr(png);
  if (m->failed) return;
  if (m->len + n > m->cap) {
    size_t cap = m->cap ? m->cap : 4096;
    while (cap < m->len + n) cap *= 2;
    unsigned char *q = realloc(m->p, cap);
    if (!q) {
      m->failed = true;
      return;
    }
    m->p = q, m->cap = cap;
  }
  memcpy(m->p + m->len, data, n);
  m->len += n;
}

static void mem_flush(png_structp png) {
  (void)png;
}

/* Encode 8-bit rows into m. false on a libpng error or out of memory. */
static bool encode(membuf *m, int width, int height, int color_type, int bpp, unsigned char *rows) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
  png_infop info = png ? png_create_info_struct(png) : NULL;
  if (!info) {
    png_destroy_write_struct(&png, NULL);
    return false;
  }
  /* libpng reports errors by longjmp; nothing here needs unwinding but
   * the structs, freed below. */
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_set_write_fn(png, m, mem_write, mem_flush);
  png_set_IHDR(png, info, (png_uint_32)width, (png_uint_32)height, 8, color_type, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_sRGB_gAMA_and_cHRM(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
  png_write_info(png, info);
  for (int r = 0; r < height; r++) png_write_row(png, rows + (size_t)r * (size_t)width * (size_t)bpp);
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  return !m->failed;
}

rsw_status png_encode_film(int width, int height, int n_channels, const char *const *channel_names,
                           const float *data, const png_look *look, void **bytes_out, size_t *len_out,
                           rsw_err *err) {
  const char *where = "(PNG in memory)";
  unsigned char *rows = NULL;
  int ct = 0, bpp = 0;
  rsw_status st = tonemap(width, height, n_channels, channel_names, data, look, where, &rows, &ct, &bpp, err);
  if (st) return st;
  membuf m = {0};
  bool ok = encode(&m, width, height, ct, bpp, rows);
  free(rows);
  if (!ok) {
    free(m.p);
    return rsw_fail(err, RSW_ERR_NOMEM, where, "cannot encode a %dx%d PNG", width, height);
  }
  *bytes_out = m.p;
  *len_out = m.len;
  return RSW_OK;
}

rsw_status png_write_film(const char *path, int width, int height, int n_channels,
                          const char *const *channel_names, const float *data, const png_look *look,
                          rsw_err *err) {
  void *bytes = NULL;
  size_t len = 0;
  rsw_status st = png_encode_film(width, height, n_channels, channel_names, data, look, &bytes, &len, err);
  if (st) {
    if (err) snprintf(err->where, sizeof err->where, "%s", path);
    return st;
  }
  bool ok = rsw_write_replace(path, bytes, len);
  free(bytes);
  return ok ? RSW_OK : rsw_fail(err, RSW_ERR_IO, path, "cannot write the PNG");
}
