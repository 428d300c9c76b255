/* `rtls`: the Ross-Thick Li-Sparse-Reciprocal BRDF (the MODIS BRDF/albedo
 * product's kernel-driven model), one-sided.
 *
 *   f_r = (f_iso + f_vol K_vol + f_geo K_geo) / pi,  eval = f_r cos(theta_o)
 *
 * With both cosines positive, dphi = phi_i - phi_o (0 in the backscatter
 * direction, the hot spot) and the phase angle psi,
 *   cos(psi) = cos(theta_i) cos(theta_o) + sin(theta_i) sin(theta_o) cos(dphi)
 *   K_vol = ((pi/2 - psi) cos(psi) + sin(psi)) / (cos(theta_i) + cos(theta_o)) - pi/4
 * Li-Sparse uses the angles theta' = atan((b/r) tan(theta)) and psi' from
 * them (theta' = theta when b = r):
 *   D     = sqrt(tan^2 theta_i' + tan^2 theta_o' - 2 tan theta_i' tan theta_o' cos(dphi))
 *   cos t = (h/b) sqrt(D^2 + (tan theta_i' tan theta_o' sin(dphi))^2) / (sec theta_i' + sec theta_o'),
 *           clamped to [-1, 1]
 *   O     = (t - sin t cos t) (sec theta_i' + sec theta_o') / pi
 *   K_geo = O - sec theta_i' - sec theta_o' + (1 + cos psi') sec theta_i' sec theta_o' / 2
 * Nothing is clamped: like Eradiate's plugin, a fit may give a negative BRF
 * at grazing angles.
 *
 * Defaults (Eradiate's code; its documentation swaps f_vol and f_geo):
 * f_iso 0.209741, f_vol 0.081384, f_geo 0.004140 (RAMI4ATM, Sentinel-2A
 * MSI band 8A), h = 2, r = 1, b = 1 (MODIS ATBD v5.0). Sampling: cosine
 * hemisphere, weight pi f_r.
 *
 * Sources: Lucht, Schaaf, Strahler (2000), IEEE TGRS 38(2), 977-998,
 * eqs. 37-44; Wanner, Li, Strahler (1995), JGR 100(D10); eradiate/mitsuba3
 * src/eradiate_plugins/bsdfs/rtls.cpp; docs/kernel-conventions.md#rtls. */
#include <math.h>
#include <stdlib.h>

#include "../scene/loader.h"
#include "../scene/params.h"
#include "../textures/texture.h"
#include "eo_surfaces.h"

static void polar(vec3 w, double *sin_t, double *cos_p, double *sin_p) {
  double s = sqrt(w.x * w.x + w.y * w.y);
  *sin_t = s;
  *cos_p = s > 0.0 ? w.x / s : 1.0;
  *sin_p = s > 0.0 ? w.y / s : 0.0;
}

static double clamp1(double x) {
  return x < -1.0 ? -1.0 : x > 1.0 ? 1.0 : x;
}

void rtls_kernels(vec3 wi, vec3 wo, double h, double r, double b, double *k_vol, double *k_geo) {
  double ci = wi.z, co = wo.z, si, cpi, spi, so, cpo, spo;
  polar(wi, &si, &cpi, &spi);
  polar(wo, &so, &cpo, &spo);
  double cos_dphi = cpi * cpo + spi * spo, sin_dphi = spi * cpo - cpi * spo;
  double cos_psi = clamp1(ci * co + si * so * cos_dphi);
  double psi = acos(cos_psi), sin_psi = sqrt(1.0 - cos_psi * cos_psi);
  *k_vol = ((RSW_PI / 2.0 - psi) * cos_psi + sin_psi) / (ci + co) - RSW_PI / 4.0;

  double ti = si / ci, to = so / co;
  double cip = ci, cop = co, sip = si, sop = so;
  if (b != r) { /* theta' = atan((b/r) tan(theta)) */
    ti *= b / r, to *= b / r;
    cip = 1.0 / sqrt(1.0 + ti * ti), cop = 1.0 / sqrt(1.0 + to * to);
    sip = ti * cip, sop = to * cop;
  }
  double cos_psip = clamp1(cip * cop + sip * sop * cos_dphi);
  double sec_i = 1.0 / cip, sec_o = 1.0 / cop, sec_sum = sec_i + sec_o;
  double d2 = fmax(ti * ti + to * to - 2.0 * ti * to * cos_dphi, 0.0);
  double tsp = ti * to * sin_dphi;
  double cos_t = clamp1(h / b * sqrt(d2 + tsp * tsp) / sec_sum);
  double t = acos(cos_t), sin_t = sqrt(1.0 - cos_t * cos_t);
  double o = (t - sin_t * cos_t) * sec_sum / RSW_PI;
  *k_geo = o - sec_sum + 0.5 * (1.0 + cos_psip) * sec_i * sec_o;
}

/* pi f_r per channel (the BRF, also the sampling weight). */
static color rtls_value(const rtls_bsdf *r, const surface_interaction *si, vec3 wo) {
  double kv, kg;
  rtls_kernels(si->wi, wo, r->h, r->r, r->b, &kv, &kg);
  color fi = tex_eval(r->f_iso, si), fv = tex_eval(r->f_vol, si), fg = tex_eval(r->f_geo, si);
  color out;
  for (int i = 0; i < 3; i++) {
    double v = fi.c[i] + fv.c[i] * kv + fg.c[i] * kg;
    out.c[i] = isfinite(v) ? v : 0.0;
  }
  return out;
}

static color rtls_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  (void)u1;
  if (!eo_cosine_sample(si, u2, bs)) return col1(0.0);
  return rtls_value((const rtls_bsdf *)b, si, bs->wo);
}

static color rtls_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return col1(0.0);
  return col_scale(rtls_value((const rtls_bsdf *)b, si, wo), RSW_INV_PI * wo.z);
}

static double rtls_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  return eo_cosine_pdf(si, wo);
}

static const bsdf_ops rtls_ops = {.sample = rtls_sample, .eval = rtls_eval, .pdf = rtls_pdf};

static void rtls_destroy(object *o) {
  free(o);
}

static rsw_status rtls_create(loader *ld, node *n, object **out) {
  texture *fi, *fv, *fg;
  double h, r, b;
  rsw_status st;
  if ((st = ld_texture(ld, n, "f_iso", 0.209741, -INFINITY, &fi)) != RSW_OK) return st;
  if ((st = ld_texture(ld, n, "f_vol", 0.081384, -INFINITY, &fv)) != RSW_OK) return st;
  if ((st = ld_texture(ld, n, "f_geo", 0.004140, -INFINITY, &fg)) != RSW_OK) return st;
  if ((st = ld_float(ld, n, "h", 2.0, &h)) != RSW_OK) return st;
  if ((st = ld_float(ld, n, "r", 1.0, &r)) != RSW_OK) return st;
  if ((st = ld_float(ld, n, "b", 1.0, &b)) != RSW_OK) return st;
  if (!(isfinite(h) && h >= 0.0)) return ld_fail(ld, n, "h", RSW_ERR_INVALID, "h = %g must be >= 0", h);
  if (!(isfinite(r) && r > 0.0)) return ld_fail(ld, n, "r", RSW_ERR_INVALID, "r = %g must be > 0", r);
  if (!(isfinite(b) && b > 0.0)) return ld_fail(ld, n, "b", RSW_ERR_INVALID, "b = %g must be > 0", b);
  bsdf *bb = rtls_new(fi, fv, fg, h, r, b);
  if (!bb) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "rtls: out of memory");
  bb->base.id = n->id;
  *out = &bb->base;
  return RSW_OK;
}

/* Eradiate exposes the three kernel weights only; h, r and b are fixed at
 * load. */
static void rtls_traverse(object *o, param_visitor *v) {
  rtls_bsdf *r = (rtls_bsdf *)o;
  pv_object(v, "f_iso", &r->f_iso->base, -INFINITY, INFINITY);
  pv_object(v, "f_vol", &r->f_vol->base, -INFINITY, INFINITY);
  pv_object(v, "f_geo", &r->f_geo->base, -INFINITY, INFINITY);
}

const plugin plugin_rtls = {
    .name = "rtls",
    .cls = CLS_BSDF,
    .create = rtls_create,
    .destroy = rtls_destroy,
    .ops = &rtls_ops,
    .traverse = rtls_traverse,
};

bsdf *rtls_new(texture *f_iso, texture *f_vol, texture *f_geo, double h, double r, double b) {
  rtls_bsdf *p = calloc(1, sizeof *p);
  if (!p) return NULL;
  p->base.base.plugin = &plugin_rtls;
  p->base.ops = &rtls_ops;
  p->base.flags = BSDF_GLOSSY_REFLECTION;
  p->f_iso = f_iso, p->f_vol = f_vol, p->f_geo = f_geo;
  p->h = h, p->r = r, p->b = b;
  return &p->base;
}
