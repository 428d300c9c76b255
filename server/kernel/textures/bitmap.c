/* `bitmap` (mitsuba3 src/textures/bitmap.cpp): an OpenEXR, PNG or JPEG
 * image (told apart by the file's first bytes) looked up at
 * uv' = to_uv (u, v). Parameters: filename, filter_type (bilinear |
 * nearest), wrap_mode (repeat | mirror | clamp), raw (PNG and JPEG values
 * are sRGB-decoded unless raw is true, as Mitsuba does for 8-bit images;
 * EXR data is linear already and raw has no effect there), to_uv. Image row 0 is the top, so v = 0 maps to the
 * bottom row, as Mitsuba (which flips v on lookup). In mono an RGB image
 * gives its luminance (as Mitsuba's mono conversion); a one-channel (Y)
 * image is used as is. */
#include <stdlib.h>
#include <string.h>

#include "../image_ldr.h"
#include "../scene/plugin_def.h"
#include "image_exr.h"

typedef enum wrap_mode {
  WRAP_REPEAT,
  WRAP_MIRROR,
  WRAP_CLAMP
} wrap_mode;

typedef struct bitmap_tex {
  texture base;
  int w, h;
  float *rgb; /* w*h*3 */
  bool bilinear;
  wrap_mode wrap;
  xform to_uv;
  bool mono;
  color mean;
} bitmap_tex;

static int wrap_index(int i, int n, wrap_mode m) {
  switch (m) {
  case WRAP_CLAMP: return i < 0 ? 0 : (i >= n ? n - 1 : i);
  case WRAP_MIRROR: {
    int p = ((i % (2 * n)) + 2 * n) % (2 * n);
    return p < n ? p : 2 * n - 1 - p;
  }
  case WRAP_REPEAT:
  default: return ((i % n) + n) % n;
  }
}

static color texel(const bitmap_tex *b, int x, int y) {
  x = wrap_index(x, b->w, b->wrap);
  y = wrap_index(y, b->h, b->wrap);
  const float *p = &b->rgb[3 * ((size_t)y * b->w + x)];
  color c = col(p[0], p[1], p[2]);
  return b->mono ? col1(col_luminance(c)) : c;
}

static color bm_eval(const texture *t, const surface_interaction *si) {
  const bitmap_tex *b = (const bitmap_tex *)t;
  vec3 uv = xf_point(&b->to_uv, v3(si->uv[0], si->uv[1], 0));
  /* Continuous pixel coordinates, v flipped so that v = 0 is the bottom. */
  double x = uv.x * b->w - 0.5, y = (1.0 - uv.y) * b->h - 0.5;
  if (!b->bilinear) return texel(b, (int)floor(x + 0.5), (int)floor(y + 0.5));
  int x0 = (int)floor(x), y0 = (int)floor(y);
  double fx = x - x0, fy = y - y0;
  color c00 = texel(b, x0, y0), c10 = texel(b, x0 + 1, y0), c01 = texel(b, x0, y0 + 1),
        c11 = texel(b, x0 + 1, y0 + 1);
  return col_add(col_add(col_scale(c00, (1 - fx) * (1 - fy)), col_scale(c10, fx * (1 - fy))),
                 col_add(col_scale(c01, (1 - fx) * fy), col_scale(c11, fx * fy)));
}

static color bm_mean(const texture *t) {
  return ((const bitmap_tex *)t)->mean;
}

static const texture_ops bitmap_ops = {.eval = bm_eval, .mean = bm_mean};

static void bm_destroy(object *o) {
  bitmap_tex *b = (bitmap_tex *)o;
  free(b->rgb);
  free(b);
}

static rsw_status bm_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  (void)err;
  ((bitmap_tex *)o)->mono = rc->variant == VARIANT_MONO;
  return RSW_OK;
}

/* A PNG or JPEG: sRGB-decoded unless raw (Mitsuba's bitmap treats 8-bit
 * images as sRGB-encoded; `raw` keeps the stored values), grey replicated
 * into the three channels. */
static rsw_status read_ldr(loader *ld, node *n, const char *path, bool raw, bitmap_tex *b) {
  ldr_image img;
  rsw_status st = ldr_read_image(path, &img, ld->err);
  if (st) return st;
  b->w = img.width;
  b->h = img.height;
  b->rgb = malloc((size_t)b->w * b->h * 3 * sizeof(float));
  if (!b->rgb) {
    ldr_image_free(&img);
    return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  }
  double sum[3] = {0, 0, 0};
  for (size_t i = 0; i < (size_t)b->w * b->h; i++)
    for (int k = 0; k < 3; k++) {
      double v = img.data[i * img.n_channels + (img.n_channels == 3 ? k : 0)];
      if (!raw) v = srgb_to_linear(v);
      b->rgb[3 * i + k] = (float)v;
      sum[k] += (float)v;
    }
  double inv = 1.0 / ((double)b->w * b->h);
  b->mean = col(sum[0] * inv, sum[1] * inv, sum[2] * inv);
  ldr_image_free(&img);
  return RSW_OK;
}

static void bm_traverse(object *o, param_visitor *v) {
  pv_transform(v, "to_uv", &((bitmap_tex *)o)->to_uv, UPDATE_SPECTRAL, NULL);
}

DEFINE_PLUGIN(bitmap, CLS_TEXTURE, .destroy = bm_destroy, .prepare = bm_prepare, .pages = plugin_pages_any,
              .ops = &bitmap_ops, .traverse = bm_traverse);

static rsw_status bitmap_create(loader *ld, node *n, object **out) {
  bitmap_tex *b = PLUGIN_NEW(bitmap_tex, bitmap);
  if (!b) return plugin_created(ld, n, NULL, out);
  b->base.ops = &bitmap_ops;
  char *path = NULL;
  const char *filter, *wrap;
  bool raw;
  exr_image img = {0};
  bool have_img = false;
  rsw_status st = ld_path(ld, n, "filename", &path);
  if (!st) st = ld_string(ld, n, "filter_type", "bilinear", &filter);
  if (!st) st = ld_string(ld, n, "wrap_mode", "repeat", &wrap);
  if (!st) st = ld_bool(ld, n, "raw", false, &raw);
  if (!st) st = ld_transform(ld, n, "to_uv", &b->to_uv, NULL);
  if (!st) {
    if (strcmp(filter, "bilinear") == 0)
      b->bilinear = true;
    else if (strcmp(filter, "nearest") == 0)
      b->bilinear = false;
    else
      st = ld_fail(ld, n, "filter_type", RSW_ERR_INVALID,
                   "filter_type must be \"bilinear\" or \"nearest\" (got \"%s\")", filter);
  }
  if (!st) {
    if (strcmp(wrap, "repeat") == 0)
      b->wrap = WRAP_REPEAT;
    else if (strcmp(wrap, "mirror") == 0)
      b->wrap = WRAP_MIRROR;
    else if (strcmp(wrap, "clamp") == 0)
      b->wrap = WRAP_CLAMP;
    else
      st = ld_fail(ld, n, "wrap_mode", RSW_ERR_INVALID,
                   "wrap_mode must be \"repeat\", \"mirror\" or \"clamp\" (got \"%s\")", wrap);
  }
  ldr_format fmt = st ? LDR_NONE : ldr_sniff(path);
  if (!st && fmt != LDR_NONE) {
    st = read_ldr(ld, n, path, raw, b);
  } else if (!st) {
    st = exr_read_image(path, &img, ld->err);
    have_img = !st;
  }
  if (have_img) {
    int r = exr_image_channel(&img, "R"), g = exr_image_channel(&img, "G"), bl = exr_image_channel(&img, "B");
    int y = exr_image_channel(&img, "Y");
    if (!(r >= 0 && g >= 0 && bl >= 0) && y < 0)
      st = ld_fail(ld, n, "filename", RSW_ERR_INVALID, "bitmap '%s' has neither R,G,B nor Y channels", path);
    if (!st) {
      b->w = img.width;
      b->h = img.height;
      b->rgb = malloc((size_t)b->w * b->h * 3 * sizeof(float));
      if (!b->rgb) st = ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
    }
    if (!st) {
      double sum[3] = {0, 0, 0};
      for (size_t i = 0; i < (size_t)b->w * b->h; i++) {
        const float *px = &img.data[i * img.n_channels];
        float v[3];
        if (r >= 0 && g >= 0 && bl >= 0)
          v[0] = px[r], v[1] = px[g], v[2] = px[bl];
        else
          v[0] = v[1] = v[2] = px[y];
        for (int k = 0; k < 3; k++) {
          if (!isfinite(v[k])) {
            st = ld_fail(ld, n, "filename", RSW_ERR_INVALID, "bitmap '%s' has a non-finite pixel", path);
            break;
          }
          b->rgb[3 * i + k] = v[k];
          sum[k] += v[k];
        }
        if (st) break;
      }
      double inv = 1.0 / ((double)b->w * b->h);
      b->mean = col(sum[0] * inv, sum[1] * inv, sum[2] * inv);
    }
  }
  if (have_img) exr_image_free(&img);
  free(path);
  if (st) {
    bm_destroy(&b->base.base);
    return st;
  }
  return plugin_created(ld, n, &b->base.base, out);
}
