/* `homogeneous`: a medium with constant coefficients (Mitsuba's
 * homogeneous): sigma_t = scale * sigma_t (default 1, per scene length),
 * sigma_s = albedo sigma_t (albedo default 0.75), the nested phase
 * function (default isotropic). It fills whatever its boundary shapes
 * enclose (or all space around a sensor that sits in it).
 *
 *   free flight: t ~ sigma_t exp(-sigma_t t) (in `channel`), exact;
 *   transmittance over a length l: exp(-sigma_t l).
 *
 * sigma_t and albedo are constant volumes (a number, an rgb or a spectrum,
 * or a constvolume), read at the render's wavelength by prepare(); for a
 * bundle of pages (render_ctx.bundle > 3) at each page's wavelengths, and
 * the ops answer at the page rsw_page names (docs/experiments.md#pages-more-than-three-wavelengths-per-path).
 * Source: mitsuba3 src/media/homogeneous.cpp. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "media.h"

typedef struct homogeneous_medium {
  medium base;
  volume *sigma_t, *albedo;
  /* sigma_t (scaled) and albedo at the render's wavelength, or at page p's
   * of a bundle of pages (pages of them, set by prepare) */
  color sig[RENDER_MAX_PAGES], alb[RENDER_MAX_PAGES];
  int pages;
} homogeneous_medium;

static bool hom_intersect_aabb(const medium *m, const ray3 *r, double *mint, double *maxt) {
  (void)m;
  *mint = r->tmin;
  *maxt = r->tmax;
  return r->tmin < r->tmax;
}

static color hom_majorant(const medium *m, const medium_interaction *mi) {
  (void)mi;
  return ((const homogeneous_medium *)m)->sig[rsw_page];
}

static void hom_coefficients(const medium *m, medium_interaction *mi) {
  const homogeneous_medium *h = (const homogeneous_medium *)m;
  int p = rsw_page;
  mi->sigma_t = h->sig[p];
  mi->sigma_s = col_mul(h->sig[p], h->alb[p]);
  mi->sigma_n = col1(0.0);
}

static color tr_over(color sig, double len) {
  return col(exp(-sig.c[0] * len), exp(-sig.c[1] * len), exp(-sig.c[2] * len));
}

static void hom_sample_real(const medium *m, const ray3 *r, double mint, double maxt, double u, int channel,
                            medium_interaction *mi, color *tr, color *pdf) {
  const homogeneous_medium *h = (const homogeneous_medium *)m;
  color sig = h->sig[rsw_page];
  double s = sig.c[channel];
  double t = s > 0 ? mint - log1p(-u) / s : INFINITY;
  mi->medium = m;
  mi->mint = mint;
  mi->wi = v3_neg(r->d);
  if (t < maxt) {
    mi->t = t;
    mi->p = v3_fma(r->o, t, r->d);
    mi->majorant = sig;
    hom_coefficients(m, mi);
    *tr = tr_over(sig, t - mint);
    *pdf = col_mul(*tr, sig);
  } else {
    mi->t = INFINITY;
    *tr = tr_over(sig, maxt - mint);
    *pdf = *tr;
  }
}

static color hom_transmittance(const medium *m, const ray3 *r, double mint, double maxt) {
  (void)r;
  return tr_over(((const homogeneous_medium *)m)->sig[rsw_page], maxt - mint);
}

static const medium_ops hom_ops = {.intersect_aabb = hom_intersect_aabb,
                                   .majorant = hom_majorant,
                                   .coefficients = hom_coefficients,
                                   .sample_real = hom_sample_real,
                                   .transmittance = hom_transmittance};

/* The coefficients at each of h->pages pages (the volumes' textures
 * answer at the page rsw_page names). has_spectral_extinction: sigma_t
 * differs between any two of the pages' channels (a bundle's free flight
 * then picks one of them, volpath); absorbing_only: no albedo at any. */
static void hom_refresh(homogeneous_medium *h) {
  vec3 o = v3(0, 0, 0);
  bool spectral = false;
  double alb_max = 0.0;
  for (int p = 0; p < h->pages; p++) {
    rsw_page = p;
    h->sig[p] = col_scale(h->sigma_t->ops->eval(h->sigma_t, o), h->base.scale);
    h->alb[p] = h->albedo->ops->eval(h->albedo, o);
    rsw_page = 0;
    for (int c = 0; c < 3; c++) spectral |= h->sig[p].c[c] != h->sig[0].c[0];
    alb_max = fmax(alb_max, col_max(h->alb[p]));
  }
  h->base.has_spectral_extinction = spectral;
  h->base.absorbing_only = alb_max == 0.0;
  double ext[3 * RENDER_MAX_PAGES] = {0};
  for (int k = 0; k < 3 * h->pages; k++) ext[k] = h->sig[k / 3].c[k % 3];
  medium_extremes(&h->base, ext, 3 * h->pages);
}

static rsw_status hom_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  (void)err;
  homogeneous_medium *h = (homogeneous_medium *)o;
  h->pages = rc_pages(rc);
  hom_refresh(h);
  return RSW_OK;
}

static void hom_parameters_changed(object *o) {
  hom_refresh((homogeneous_medium *)o);
}

static rsw_status constant_only(loader *ld, node *n, const char *name, const volume *v) {
  if (v->res[0] * v->res[1] * v->res[2] != 1)
    return ld_fail(
        ld, n, name, RSW_ERR_INVALID,
        "homogeneous: '%s' must be constant (a number, a spectrum or a constvolume), got a %ux%ux%u "
        "grid (use the heterogeneous or piecewise medium for grids)",
        name, v->res[0], v->res[1], v->res[2]);
  return RSW_OK;
}

static rsw_status homogeneous_create(loader *ld, node *n, object **out) {
  homogeneous_medium *h = calloc(1, sizeof *h);
  if (!h) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "homogeneous: out of memory");
  h->base.ops = &hom_ops;
  h->base.is_homogeneous = true;
  h->pages = 1;
  rsw_status st = medium_read_common(ld, n, &h->base);
  if (!st) st = ld_volume(ld, n, "sigma_t", 1.0, 0.0, INFINITY, &h->sigma_t);
  if (!st) st = ld_volume(ld, n, "albedo", 0.75, 0.0, 1.0, &h->albedo);
  if (!st) st = constant_only(ld, n, "sigma_t", h->sigma_t);
  if (!st) st = constant_only(ld, n, "albedo", h->albedo);
  if (st) {
    free(h);
    return st;
  }
  *out = &h->base.base;
  return RSW_OK;
}

static void hom_traverse(object *o, param_visitor *v) {
  homogeneous_medium *h = (homogeneous_medium *)o;
  medium_traverse_common(&h->base, v);
  pv_object(v, "sigma_t", &h->sigma_t->base, 0.0, INFINITY);
  pv_object(v, "albedo", &h->albedo->base, 0.0, 1.0);
}

DEFINE_PLUGIN(homogeneous, CLS_MEDIUM, .prepare = hom_prepare, .ops = &hom_ops, .traverse = hom_traverse,
              .parameters_changed = hom_parameters_changed, .pages = plugin_pages_any);
