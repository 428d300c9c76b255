/* `envmap`: an environment of radiance read from a latitude-longitude
 * OpenEXR image (mitsuba3 src/emitters/envmap.cpp). Parameters: filename
 * (RGB or Y channels), scale (default 1), to_world (default identity),
 * sampling_weight (default 1).
 *
 * Orientation, as Mitsuba's direction_to_uv / uv_to_direction (envmap.cpp),
 * with +y up in the emitter's local frame, d_local = to_world^-1 d:
 *     u = atan2(d.x, -d.z) / (2 pi)        (in [-1/2, 1/2], wrapped to [0,1))
 *     v = acos(d.y) / pi                   (0: +y, 1: -y)
 *     d = (sin phi sin theta, cos theta, -cos phi sin theta),
 *         phi = 2 pi u, theta = pi v.
 * Texels, as Mitsuba's eval_spectrum: the W x H image is a grid of samples
 * bilinearly interpolated, periodic in u (column W repeats column 0).
 * Column i sits at u = (i + 1/2) / W (Mitsuba's half-texel shift), row j at
 * v = j / (H - 1): row 0 is the +y pole, row H-1 the -y pole. So the
 * centre of column 0 looks along -z, u = 1/4 along +x.
 *
 * Radiance (W m^-2 sr^-1 [nm^-1]) = bilinear(image)(u, v) * scale; in mono
 * an RGB image gives its luminance (as Mitsuba's mono conversion, and as
 * `bitmap`), a Y image its value.
 *
 * Sampling. Mitsuba warps with a piecewise-bilinear Hierarchical2D over the
 * grid; we use a piecewise-constant distribution (core/distr2d.h) over the
 * W x (H-1) cells between grid samples (cell (i, j): columns i, i+1, rows
 * j, j+1), with weight
 *     w_ij = mean luminance of the four corners * sin(theta_c),
 *     theta_c = pi (j + 1/2) / (H - 1)  (the cell's centre row),
 * the sin theta being the solid-angle Jacobian. Any cell where the radiance
 * is non-zero has w_ij > 0, so the estimator is unbiased; only the variance
 * differs from Mitsuba's. A sample s in [0,1)^2 of the distribution maps
 * to u = s.x + 1/(2W), v = s.y (a shift: Jacobian 1), and since
 * dω = sin theta dtheta dphi = 2 pi^2 sin theta du dv,
 *     pdf_omega = pdf_uv / (2 pi^2 sin theta),
 * 0 where sin theta = 0 (the poles, a set of measure zero).
 *
 * to_world must be a rotation times a uniform scale (directions are
 * normalised after it), so that the solid-angle pdf is unchanged by it. */
#include <stdlib.h>

#include "../core/distr2d.h"
#include "../scene/plugin_def.h"
#include "image_exr.h"

typedef struct envmap {
  emitter base;
  int w, h;   /* image size: w >= 2, h >= 3 (as Mitsuba) */
  float *rgb; /* w*h*3, row 0 = v 0 (the +y pole) */
  double scale;
  xform to_world; /* local (+y up) -> world */
  distr2d distr;  /* over w x (h-1) cells; unused when black */
  bool black;     /* every texel is zero: nothing to sample */
  bool mono;
} envmap;

static vec2 direction_to_uv(vec3 d) {
  double cy = d.y < -1 ? -1 : (d.y > 1 ? 1 : d.y);
  return v2(atan2(d.x, -d.z) * RSW_INV_2PI, acos(cy) * RSW_INV_PI);
}

/* Local direction of (u, v); *sin_theta gets sin(pi v). */
static vec3 uv_to_direction(vec2 uv, double *sin_theta) {
  double theta = uv.y * RSW_PI, phi = uv.x * 2.0 * RSW_PI;
  double st = sin(theta);
  *sin_theta = st;
  return v3(sin(phi) * st, cos(theta), -cos(phi) * st);
}

static double half_texel(const envmap *m) {
  return 0.5 / m->w;
}

static color texel(const envmap *m, int x, int y) {
  x %= m->w;
  const float *p = &m->rgb[3 * ((size_t)y * m->w + x)];
  return col(p[0], p[1], p[2]);
}

/* Bilinear lookup of the image at (u, v), times scale (Mitsuba's
 * eval_spectrum): x = (u - 1/(2W)) mod 1 * W, y = v (H - 1). */
static color lookup(const envmap *m, vec2 uv) {
  double u = uv.x - half_texel(m);
  u -= floor(u);
  double x = u * m->w, y = uv.y * (m->h - 1);
  int px = (int)x, py = (int)y;
  if (px > m->w - 1) px = m->w - 1;
  if (px < 0) px = 0;
  if (py > m->h - 2) py = m->h - 2;
  if (py < 0) py = 0;
  double fx = x - px, fy = y - py;
  color c0 = col_add(col_scale(texel(m, px, py), 1 - fx), col_scale(texel(m, px + 1, py), fx));
  color c1 = col_add(col_scale(texel(m, px, py + 1), 1 - fx), col_scale(texel(m, px + 1, py + 1), fx));
  color c = col_scale(col_add(col_scale(c0, 1 - fy), col_scale(c1, fy)), m->scale);
  /* Luminance is linear: the luminance of the interpolated triple is the
   * interpolation of the texels' luminances, as Mitsuba's mono data. */
  return m->mono ? col1(col_luminance(c)) : c;
}

static vec3 local_direction(const envmap *m, vec3 d) {
  return v3_norm(xf_inv_vector(&m->to_world, d));
}

static color env_eval(const emitter *e, const surface_interaction *hit, vec3 d) {
  const envmap *m = (const envmap *)e;
  (void)hit;
  return lookup(m, direction_to_uv(local_direction(m, d)));
}

static color env_sample(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds) {
  const envmap *m = (const envmap *)e;
  (void)ref;
  *ds = (direction_sample){.dist = INFINITY, .pdf = 0, .delta = false};
  if (m->black) return col1(0);
  double pdf_uv;
  vec2 s = distr2d_sample(&m->distr, u, &pdf_uv);
  vec2 uv = v2(s.x + half_texel(m), s.y);
  double sin_theta;
  vec3 dl = uv_to_direction(uv, &sin_theta);
  if (!(sin_theta > 0) || !(pdf_uv > 0)) return col1(0);
  ds->d = v3_norm(xf_vector(&m->to_world, dl));
  ds->p = ds->d;
  ds->n = v3_neg(ds->d);
  ds->pdf = pdf_uv / (2.0 * RSW_PI * RSW_PI * sin_theta);
  return col_scale(lookup(m, uv), 1.0 / ds->pdf);
}

static double env_pdf(const emitter *e, const surface_interaction *ref, const direction_sample *ds) {
  const envmap *m = (const envmap *)e;
  (void)ref;
  if (m->black) return 0.0;
  vec3 d = local_direction(m, ds->d);
  double sin_theta = sqrt(d.x * d.x + d.z * d.z);
  if (!(sin_theta > 0)) return 0.0;
  vec2 uv = direction_to_uv(d);
  double x = uv.x - half_texel(m);
  x -= floor(x);
  if (x >= 1.0) x = 0.0; /* -tiny - floor(-tiny) rounds to 1 */
  return distr2d_pdf(&m->distr, v2(x, uv.y)) / (2.0 * RSW_PI * RSW_PI * sin_theta);
}

static const emitter_ops envmap_ops = {
    .sample_direction = env_sample, .pdf_direction = env_pdf, .eval = env_eval};

static void env_destroy(object *o) {
  envmap *m = (envmap *)o;
  distr2d_free(&m->distr);
  free(m->rgb);
  free(m);
}

/* In mono the map's radiance is its luminance at every wavelength: each
 * page of a bundle takes the same value. */
static rsw_status env_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  (void)err;
  ((envmap *)o)->mono = rc->variant == VARIANT_MONO;
  return RSW_OK;
}

/* Directions are normalised after to_world: the solid-angle pdf survives
 * a rotation times a uniform scale only. */
static rsw_status env_check_xf(const object *o, const xform *t, const char *key, rsw_err *err) {
  (void)o;
  double scale;
  if (!xf_is_similarity(t, &scale) || !(scale > 0))
    return rsw_fail(err, RSW_ERR_INVALID, key,
                    "'%s': an envmap's to_world must be a rotation (times a uniform scale)", key);
  return RSW_OK;
}

/* Copy the image's R,G,B (or Y) into m->rgb; every value finite and >= 0. */
static rsw_status load_pixels(loader *ld, node *n, envmap *m, const exr_image *img, const char *path) {
  int r = exr_image_channel(img, "R"), g = exr_image_channel(img, "G"), b = exr_image_channel(img, "B");
  int y = exr_image_channel(img, "Y");
  bool rgb = r >= 0 && g >= 0 && b >= 0;
  if (!rgb && y < 0)
    return ld_fail(ld, n, "filename", RSW_ERR_INVALID, "'%s' has neither R,G,B nor Y channels", path);
  if (img->width < 2 || img->height < 3)
    return ld_fail(ld, n, "filename", RSW_ERR_INVALID,
                   "'%s' is %dx%d; an environment map must be at least 2x3 pixels", path, img->width,
                   img->height);
  m->w = img->width;
  m->h = img->height;
  m->rgb = malloc((size_t)m->w * m->h * 3 * sizeof(float));
  if (!m->rgb) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  for (size_t i = 0; i < (size_t)m->w * m->h; i++) {
    const float *px = &img->data[i * img->n_channels];
    float v[3];
    if (rgb)
      v[0] = px[r], v[1] = px[g], v[2] = px[b];
    else
      v[0] = v[1] = v[2] = px[y];
    for (int k = 0; k < 3; k++) {
      if (!isfinite(v[k]) || v[k] < 0)
        return ld_fail(ld, n, "filename", RSW_ERR_INVALID,
                       "'%s': pixel (%zu, %zu) is negative or not finite (radiance must be >= 0)", path,
                       i % (size_t)m->w, i / (size_t)m->w);
      m->rgb[3 * i + k] = v[k];
    }
  }
  return RSW_OK;
}

/* The sampling distribution over the w x (h-1) cells (see the top). */
static rsw_status build_distribution(loader *ld, node *n, envmap *m) {
  int cw = m->w, ch = m->h - 1;
  double *wts = malloc((size_t)cw * ch * sizeof(double));
  if (!wts) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  double sum = 0;
  for (int j = 0; j < ch; j++) {
    double sin_theta = sin(RSW_PI * (j + 0.5) / ch);
    for (int i = 0; i < cw; i++) {
      double lum = 0.25 * (col_luminance(texel(m, i, j)) + col_luminance(texel(m, i + 1, j)) +
                           col_luminance(texel(m, i, j + 1)) + col_luminance(texel(m, i + 1, j + 1)));
      wts[(size_t)j * cw + i] = lum * sin_theta;
      sum += lum;
    }
  }
  rsw_status st = RSW_OK;
  /* An all-black map emits nothing: nothing to sample (pdf 0 everywhere). */
  m->black = !(sum > 0);
  if (!m->black) {
    rsw_err tmp = {0};
    st = distr2d_init(&m->distr, wts, cw, ch, "filename", &tmp);
    if (st) st = ld_fail(ld, n, "filename", st, "envmap sampling distribution: %s", tmp.msg);
  }
  free(wts);
  return st;
}

static rsw_status envmap_create(loader *ld, node *n, object **out) {
  envmap *m = calloc(1, sizeof *m);
  if (!m) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  m->base.ops = &envmap_ops;
  m->base.flags = EMITTER_INFINITE;
  char *path = NULL;
  exr_image img = {0};
  bool have_img = false;
  rsw_status st = ld_float_range(ld, n, "sampling_weight", 1.0, 0.0, INFINITY, &m->base.sampling_weight);
  if (!st) st = ld_float_range(ld, n, "scale", 1.0, 0.0, INFINITY, &m->scale);
  if (!st) st = ld_transform(ld, n, "to_world", &m->to_world, NULL);
  if (!st) {
    double s;
    if (!xf_is_similarity(&m->to_world, &s) || !(s > 0))
      st = ld_fail(ld, n, "to_world", RSW_ERR_INVALID,
                   "an envmap's to_world must be a rotation (times a uniform scale)");
  }
  if (!st) st = ld_path(ld, n, "filename", &path);
  if (!st) {
    st = exr_read_image(path, &img, ld->err);
    have_img = !st;
  }
  if (!st) st = load_pixels(ld, n, m, &img, path);
  if (!st) st = build_distribution(ld, n, m);
  if (have_img) exr_image_free(&img);
  free(path);
  if (st) {
    env_destroy(&m->base.base);
    return st;
  }
  *out = &m->base.base;
  return RSW_OK;
}

static void env_traverse(object *o, param_visitor *v) {
  envmap *m = (envmap *)o;
  pv_float(v, "scale", &m->scale, UPDATE_SPECTRAL, 0.0, INFINITY);
  /* Not geometric: the emitter is not in the acceleration structure. */
  pv_transform(v, "to_world", &m->to_world, UPDATE_SPECTRAL, env_check_xf);
  pv_float(v, "sampling_weight", &m->base.sampling_weight, UPDATE_SPECTRAL, 0.0, INFINITY);
}

DEFINE_PLUGIN(envmap, CLS_EMITTER, .destroy = env_destroy, .prepare = env_prepare, .ops = &envmap_ops,
              .traverse = env_traverse, .pages = plugin_pages_any);
