/* `hdrfilm`: the film description of a sensor (mitsuba3
 * src/films/hdrfilm.cpp, src/render/film.cpp; docs/kernel-conventions.md#films-and-samplers).
 *
 * Only the description lives here: size, pixel and component format, the
 * reconstruction filter. The renderer owns the pixel buffer and writes
 * OpenEXR through image_exr; this film writes nothing itself.
 *
 * Defaults: width 768, height 576, file_format "openexr", pixel_format
 * "rgb" (forced to "luminance" in mono, as Mitsuba does, with no error),
 * component_format "float16", crop = the whole film, sample_border false,
 * rfilter `gaussian`. What Mitsuba accepts but this kernel does not
 * produce (alpha / XYZ pixel formats, uint32 components, RGBE / PFM files,
 * partial crop windows, border sampling) is RSW_ERR_UNSUPPORTED. */
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include <math.h>

#include "../scene/plugin_def.h"
#include "film_planes.h"

/* Bounds that keep a hostile document from asking for a huge buffer. */
#define HDRFILM_MAX_DIM    65536
#define HDRFILM_MAX_PIXELS (1LL << 26)

typedef struct hdrfilm {
  film base;
  pixel_format requested; /* what the document asked for (before mono) */
} hdrfilm;

/* The variant is known per render: mono forces one luminance channel. */
static rsw_status hdrfilm_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  (void)err;
  hdrfilm *f = (hdrfilm *)o;
  f->base.pixel_format = rc->polarized                                                  ? PIXFMT_STOKES
                         : rc->variant == VARIANT_MONO && f->requested != PIXFMT_STOKES ? PIXFMT_LUMINANCE
                                                                                        : f->requested;
  return RSW_OK;
}

/* Develop: normalise by the filter weights; mono films hold one
 * luminance channel Y (Mitsuba forces it), rgb films R, G, B or Y, Stokes
 * films S0..S3. Then the planes, in the order brdf, brf, radiance_stderr.
 * The BRDF is L / E_h and the BRF pi L / E_h per developed channel
 * (Eradiate's compute_bidirectional_reflectance); the standard error of a
 * pixel's mean of n samples is sqrt((sum d^2 - (sum d)^2 / n) / (n (n -
 * 1))), d = x - K (the unbiased sample variance over n). */
static rsw_status hdrfilm_develop(const film *fm, const film_sums *s, film_image *out, rsw_err *err) {
  bool lum = s->lum;
  film_image img;
  memset(&img, 0, sizeof img);
  img.width = s->width;
  img.height = s->height;
  /* Stokes films: nc colour channels per component, in the order S0.R
   * S0.G S0.B S1.R ... (rgb_polarized) or S0..S3 / S0.Y..S3.Y. */
  int nc = s->stokes && s->polarized && s->variant == VARIANT_RGB ? 3 : 1;
  if (s->stokes) {
    static const char *const plain[4] = {"S0", "S1", "S2", "S3"}, *const pol[4] = {"S0.Y", "S1.Y", "S2.Y",
                                                                                   "S3.Y"};
    static const char *const rgb[12] = {"S0.R", "S0.G", "S0.B", "S1.R", "S1.G", "S1.B",
                                        "S2.R", "S2.G", "S2.B", "S3.R", "S3.G", "S3.B"};
    img.channels = 4 * nc;
    for (int k = 0; k < img.channels; k++)
      img.channel_names[k] = nc == 3 ? rgb[k] : s->polarized ? pol[k] : plain[k];
  } else if (lum) {
    img.channels = 1;
    img.channel_names[0] = "Y";
  } else {
    img.channels = 3;
    img.channel_names[0] = "R";
    img.channel_names[1] = "G";
    img.channel_names[2] = "B";
  }
  img.half = fm->component_format == COMPFMT_FLOAT16;
  img.spp = s->spp;
  img.seed = s->seed;
  img.wavelength = s->wavelength;
  img.variant = s->variant;
  img.polarized = s->polarized;
  size_t np = (size_t)s->width * s->height;
  img.data = film_pixels_new(np * img.channels);
  if (!img.data) return rsw_fail(err, RSW_ERR_NOMEM, "film", "out of memory");
  for (size_t i = 0; i < np; i++) {
    const double *a = &s->acc[(size_t)s->stride * i];
    double inv = a[3] != 0 ? 1.0 / a[3] : 0.0;
    color c = col(a[0] * inv, a[1] * inv, a[2] * inv);
    if (s->stokes) {
      float *o = &img.data[(size_t)img.channels * i];
      for (int ch = 0; ch < nc; ch++) {
        o[ch] = (float)c.c[ch];
        for (int k = 0; k < 3; k++) o[nc * (k + 1) + ch] = (float)(a[4 + 3 * ch + k] * inv);
      }
    } else if (lum) {
      img.data[i] = (float)(s->variant == VARIANT_MONO ? c.c[0] : col_luminance(c));
    } else {
      img.data[3 * i] = (float)c.c[0];
      img.data[3 * i + 1] = (float)c.c[1];
      img.data[3 * i + 2] = (float)c.c[2];
    }
  }
  double eh[FILM_MAX_CHANNELS] = {0}; /* per developed channel, as the radiance maps colours */
  for (int c = 0; c < img.channels; c++)
    eh[c] = s->stokes                    ? s->e_h.c[nc == 3 ? c % 3 : 0]
            : s->variant == VARIANT_MONO ? s->e_h.c[0]
            : lum                        ? col_luminance(s->e_h)
                                         : s->e_h.c[c];
  const char *want[FILM_MAX_PLANES];
  int n_want = 0;
  if (s->quantities & RENDER_Q_BRDF) want[n_want++] = "brdf";
  if (s->quantities & RENDER_Q_BRF) want[n_want++] = "brf";
  if (s->variance) want[n_want++] = "radiance_stderr";
  size_t nv = np * img.channels;
  for (int p = 0; p < n_want; p++) {
    film_plane *pl = &img.planes[p];
    film_plane_init(&img, want[p], pl);
    pl->data = film_pixels_new(nv);
    img.n_planes = p + 1;
    if (!pl->data) {
      film_image_free(&img);
      return rsw_fail(err, RSW_ERR_NOMEM, "film", "out of memory");
    }
    bool is_stderr = strcmp(want[p], "radiance_stderr") == 0;
    double scale = strcmp(want[p], "brf") == 0 ? M_PI : 1.0; /* over E_h */
    for (size_t i = 0; i < np; i++) {
      const double *a = &s->acc[(size_t)s->stride * i];
      for (int c = 0; c < img.channels; c++) {
        size_t q = i * (size_t)img.channels + (size_t)c;
        if (!is_stderr) {
          pl->data[q] = (float)(scale / eh[c] * (double)img.data[q]);
          continue;
        }
        const double *m = &a[s->m_off + FILM_ACC_MOMENT * c];
        double n = a[3], var = n > 1 ? (m[2] - m[1] * m[1] / n) / (n - 1) : 0;
        pl->data[q] = (float)(var > 0 ? sqrt(var / n) : 0.0);
      }
    }
  }
  if (n_want && (s->quantities & (RENDER_Q_BRDF | RENDER_Q_BRF))) {
    img.has_irradiance = true;
    for (int c = 0; c < FILM_MAX_CHANNELS; c++) img.irradiance[c] = eh[c];
  }
  *out = img;
  return RSW_OK;
}

static const film_ops hdrfilm_ops = {.develop = hdrfilm_develop};

DEFINE_PLUGIN(hdrfilm, CLS_FILM, .prepare = hdrfilm_prepare, .pages = plugin_pages_any, .ops = &hdrfilm_ops);

typedef struct name_code {
  const char *name;
  int code; /* >= 0: value; -1: known to Mitsuba but unsupported here */
} name_code;

/* The entry named `value` (case-insensitive, as Mitsuba lower-cases these
 * strings), or NULL. */
static const name_code *find_name(const char *value, const name_code *table, size_t count) {
  for (size_t i = 0; i < count; i++)
    if (strcasecmp(value, table[i].name) == 0) return &table[i];
  return NULL;
}

/* Look `value` up: unknown names are invalid, names Mitsuba knows but this
 * kernel does not produce are unsupported. */
static rsw_status lookup(loader *ld, node *n, const char *key, const char *value, const name_code *table,
                         size_t count, const char *valid, int *out) {
  const name_code *e = find_name(value, table, count);
  if (!e)
    return ld_fail(ld, n, key, RSW_ERR_INVALID, "hdrfilm: unknown %s '%s' (supported: %s)", key, value,
                   valid);
  if (e->code < 0)
    return ld_fail(ld, n, key, RSW_ERR_UNSUPPORTED, "hdrfilm: %s '%s' is not supported (supported: %s)", key,
                   value, valid);
  *out = e->code;
  return RSW_OK;
}

static const name_code file_formats[] = {{"openexr", 0}, {"exr", 0}, {"rgbe", -1}, {"pfm", -1}};
static const name_code pixel_formats[] = {
    {"rgb", PIXFMT_RGB}, {"luminance", PIXFMT_LUMINANCE}, {"stokes", PIXFMT_STOKES},
    {"rgba", -1},        {"luminance_alpha", -1},         {"xyz", -1},
    {"xyza", -1}};
static const name_code component_formats[] = {
    {"float16", COMPFMT_FLOAT16}, {"float32", COMPFMT_FLOAT32}, {"uint32", -1}};
#define COUNT(a) (sizeof(a) / sizeof((a)[0]))

static rsw_status hdrfilm_read(loader *ld, node *n, hdrfilm *f) {
  long long w = 0, h = 0;
  rsw_status st = ld_int(ld, n, "width", 768, 1, HDRFILM_MAX_DIM, &w);
  if (st == RSW_OK) st = ld_int(ld, n, "height", 576, 1, HDRFILM_MAX_DIM, &h);
  if (st != RSW_OK) return st;
  if (w * h > HDRFILM_MAX_PIXELS)
    return ld_fail(ld, n, NULL, RSW_ERR_LIMIT, "hdrfilm: %lldx%lld pixels exceed the limit of %lld", w, h,
                   HDRFILM_MAX_PIXELS);
  f->base.width = (int)w;
  f->base.height = (int)h;

  /* Crop window (film.cpp): must lie inside the film; only the full film is
   * rendered here. */
  long long cx = 0, cy = 0, cw = 0, ch = 0;
  st = ld_int(ld, n, "crop_offset_x", 0, 0, HDRFILM_MAX_DIM, &cx);
  if (st == RSW_OK) st = ld_int(ld, n, "crop_offset_y", 0, 0, HDRFILM_MAX_DIM, &cy);
  if (st == RSW_OK) st = ld_int(ld, n, "crop_width", w, 1, HDRFILM_MAX_DIM, &cw);
  if (st == RSW_OK) st = ld_int(ld, n, "crop_height", h, 1, HDRFILM_MAX_DIM, &ch);
  if (st != RSW_OK) return st;
  if (cx + cw > w || cy + ch > h)
    return ld_fail(ld, n, NULL, RSW_ERR_INVALID,
                   "hdrfilm: invalid crop window (offset %lld,%lld size %lldx%lld on a "
                   "%lldx%lld film)",
                   cx, cy, cw, ch, w, h);
  if (cx != 0 || cy != 0 || cw != w || ch != h)
    return ld_fail(ld, n, NULL, RSW_ERR_UNSUPPORTED,
                   "hdrfilm: crop windows other than the whole film are not supported");

  bool flag = false;
  st = ld_bool(ld, n, "sample_border", false, &flag);
  if (st != RSW_OK) return st;
  if (flag)
    return ld_fail(ld, n, "sample_border", RSW_ERR_UNSUPPORTED,
                   "hdrfilm: sample_border = true is not supported");
  /* compensate (Kahan summation) changes nothing when the renderer
   * accumulates in double; banner is accepted and ignored as in Mitsuba. */
  st = ld_bool(ld, n, "compensate", false, &flag);
  if (st == RSW_OK) st = ld_bool(ld, n, "banner", false, &flag);
  if (st != RSW_OK) return st;

  const char *s = NULL;
  int code = 0;
  st = ld_string(ld, n, "file_format", "openexr", &s);
  if (st == RSW_OK) st = lookup(ld, n, "file_format", s, file_formats, COUNT(file_formats), "openexr", &code);
  if (st != RSW_OK) return st;

  st = ld_string(ld, n, "pixel_format", "rgb", &s);
  if (st != RSW_OK) return st;
  if (ld->variant == VARIANT_MONO) {
    /* Mitsuba forces Y in monochrome variants whatever was asked (with a
     * warning); a name Mitsuba does not know is still an error here. */
    if (!find_name(s, pixel_formats, COUNT(pixel_formats)))
      return ld_fail(ld, n, "pixel_format", RSW_ERR_INVALID, "hdrfilm: unknown pixel_format '%s'", s);
    /* "stokes": channels S0..S3 (I, Q, U, V) — kept in mono. */
    code = strcmp(s, "stokes") == 0 ? PIXFMT_STOKES : PIXFMT_LUMINANCE;
  } else if (strcmp(s, "stokes") == 0 && !ld->polarized) {
    return ld_fail(
        ld, n, "pixel_format", RSW_ERR_UNSUPPORTED,
        "hdrfilm: pixel_format 'stokes' needs the mono variant (Stokes vectors are per wavelength)");
  } else {
    st = lookup(ld, n, "pixel_format", s, pixel_formats, COUNT(pixel_formats), "rgb, luminance", &code);
    if (st != RSW_OK) return st;
  }
  f->requested = (pixel_format)code;
  /* The polarized variants' films are Stokes films whatever was asked
   * (Mitsuba's `stokes` integrator gives them S0..S3 channels). */
  f->base.pixel_format = ld->polarized                                                  ? PIXFMT_STOKES
                         : ld->variant == VARIANT_MONO && f->requested != PIXFMT_STOKES ? PIXFMT_LUMINANCE
                                                                                        : f->requested;

  st = ld_string(ld, n, "component_format", "float16", &s);
  if (st == RSW_OK)
    st = lookup(ld, n, "component_format", s, component_formats, COUNT(component_formats), "float16, float32",
                &code);
  if (st != RSW_OK) return st;
  f->base.component_format = (component_format)code;

  object *o = NULL;
  st = ld_child(ld, n, NULL, CLS_RFILTER, &o);
  if (st != RSW_OK) return st;
  if (!o) {
    st = ld_create_default(ld, "gaussian", CLS_RFILTER, "rfilter", &o);
    if (st != RSW_OK) return st;
  }
  f->base.filter = (rfilter *)o;
  return RSW_OK;
}

static rsw_status hdrfilm_create(loader *ld, node *n, object **out) {
  hdrfilm *f = PLUGIN_NEW(hdrfilm, hdrfilm);
  if (!f) return plugin_created(ld, n, NULL, out);
  f->base.ops = &hdrfilm_ops;
  rsw_status st = hdrfilm_read(ld, n, f);
  if (st != RSW_OK) {
    free(f);
    return st;
  }
  return plugin_created(ld, n, &f->base.base, out);
}
