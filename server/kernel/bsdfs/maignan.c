/* `maignan`: the polarized-reflectance model of Maignan et al. (2009) for
 * bare soil and vegetation, unpolarized part (the Fresnel matrix's M00),
 * one-sided.
 *
 * With both cosines positive and cos(Theta) = wi . wo (Theta: the angle
 * between the two directions, twice the facet incidence angle alpha):
 *   tan(alpha) = sqrt((1 - cos Theta) / (1 + cos Theta)),
 *   cos(alpha) = sqrt((1 + cos Theta) / 2)
 *   value = C exp(-tan alpha) exp(-ndvi) F(alpha) / (4 (cos theta_i + cos theta_o))
 * F: the unpolarized Fresnel reflectance of the interface from ext_ior to
 * refr_re + i refr_im (bsdfs/fresnel.h, relative index refr / ext_ior).
 * Maignan et al. eq. 21. `value` is what Eradiate's eval() returns (its
 * cosine-weighted BRDF, as for every Mitsuba eval); raysweep's eval is the
 * same number. Sampling: cosine hemisphere, pdf cos(theta_o)/pi, weight
 * eval / pdf. (Eradiate's sample() returns `value` itself as the weight;
 * raysweep keeps weight = eval / pdf, so BSDF- and emitter-sampled
 * estimates agree: with a directional sun only the latter is used, and
 * the two codes agree.)
 *
 * Defaults (Eradiate's code; its documentation gives C 5, ndvi 0.8):
 * C 0.1, ndvi 0, refr_re 1.5, refr_im 0, ext_ior 1.000277 (air).
 *
 * Sources: Maignan, Breon, Fedele, Bouvier (2009), Remote Sens. Environ.
 * 113, 2642-2650, eq. 21; eradiate/mitsuba3
 * src/eradiate_plugins/bsdfs/maignan.cpp; docs/kernel-conventions.md#maignan. */
#include <math.h>
#include <stdlib.h>

#include "../scene/loader.h"
#include "../scene/params.h"
#include "../textures/texture.h"
#include "eo_surfaces.h"
#include "fresnel.h"
#include "fresnel_pol.h"

double maignan_value(double C, double ndvi, double refr_re, double refr_im, double ext_ior, vec3 wi,
                     vec3 wo) {
  double cos_big = wi.x * wo.x + wi.y * wo.y + wi.z * wo.z;
  cos_big = cos_big < -1.0 ? -1.0 : cos_big > 1.0 ? 1.0 : cos_big;
  double tan_a = sqrt((1.0 - cos_big) / (1.0 + cos_big));
  double cos_a = sqrt(0.5 * (1.0 + cos_big));
  double c = C * exp(-tan_a) * exp(-ndvi) / (4.0 * (wi.z + wo.z));
  double f = fresnel_conductor(cos_a, refr_re / ext_ior, refr_im / ext_ior);
  double v = c * f;
  return isfinite(v) ? v : 0.0;
}

static color maignan_col(const maignan_bsdf *m, const surface_interaction *si, vec3 wo) {
  color C = tex_eval(m->C, si), nd = tex_eval(m->ndvi, si), re = tex_eval(m->refr_re, si);
  color im = tex_eval(m->refr_im, si), ext = tex_eval(m->ext_ior, si);
  color out;
  for (int i = 0; i < 3; i++)
    out.c[i] = maignan_value(C.c[i], nd.c[i], re.c[i], im.c[i], ext.c[i], si->wi, wo);
  return out;
}

static color maignan_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2,
                            bsdf_sample *bs) {
  (void)u1;
  if (!eo_cosine_sample(si, u2, bs)) return col1(0.0);
  return col_scale(maignan_col((const maignan_bsdf *)b, si, bs->wo), 1.0 / bs->pdf);
}

static color maignan_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return col1(0.0);
  return maignan_col((const maignan_bsdf *)b, si, wo);
}

static double maignan_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  return eo_cosine_pdf(si, wo);
}

/* Polarization (docs/plugins.md#polarization-surfaces): Maignan et al.'s model is
 * the Fresnel matrix of the facet reflecting -wo into wi (eq. 21, the
 * interface from ext_ior to refr_re + i refr_im at the facet angle alpha),
 * as eradiate/mitsuba3 maignan.cpp (its fresnel_sunglint_polarized: that
 * matrix rotated to the meridian planes; here in the facet's s-axis
 * bases), per channel. */
static void maignan_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                                 mueller P[3], vec3 *s_in, vec3 *s_out) {
  (void)lobe;
  const maignan_bsdf *m = (const maignan_bsdf *)b;
  color re = tex_eval(m->refr_re, si), im = tex_eval(m->refr_im, si), ext = tex_eval(m->ext_ior, si);
  double cos_big = fmin(1.0, fmax(-1.0, v3_dot(si->wi, wo)));
  for (int c = 0; c < 3; c++) re.c[c] /= ext.c[c], im.c[c] /= ext.c[c];
  fpol_reflection(P, sqrt(0.5 * (1.0 + cos_big)), re, im);
  *s_in = *s_out = fpol_s_axis(wo, si->wi);
}

static const bsdf_ops maignan_ops = {
    .sample = maignan_sample, .eval = maignan_eval, .pdf = maignan_pdf, .polarization = maignan_polarization};

static void maignan_destroy(object *o) {
  free(o);
}

/* Ranges as Eradiate documents them: C >= 0, 0 <= ndvi <= 1 (loaded as
 * [-1, 1], NDVI's own range), refr_re >= 1, refr_im >= 0, ext_ior > 0. */
static rsw_status maignan_create(loader *ld, node *n, object **out) {
  texture *C, *nd, *re, *im, *ext;
  rsw_status st;
  if ((st = ld_texture(ld, n, "C", 0.1, 0.0, &C)) != RSW_OK) return st;
  if ((st = ld_texture(ld, n, "ndvi", 0.0, -1.0, &nd)) != RSW_OK) return st;
  if ((st = ld_texture(ld, n, "refr_re", 1.5, 0.0, &re)) != RSW_OK) return st;
  if ((st = ld_texture(ld, n, "refr_im", 0.0, 0.0, &im)) != RSW_OK) return st;
  if ((st = ld_texture(ld, n, "ext_ior", 1.000277, 0.0, &ext)) != RSW_OK) return st;
  if ((st = bsdf_check_const_range(ld, n, "ndvi", nd, -1.0, false, 1.0, false)) != RSW_OK) return st;
  if ((st = bsdf_check_const_range(ld, n, "refr_re", re, 1.0, false, INFINITY, true)) != RSW_OK) return st;
  if ((st = bsdf_check_const_range(ld, n, "ext_ior", ext, 0.0, true, INFINITY, true)) != RSW_OK) return st;
  bsdf *b = maignan_new(C, nd, re, im, ext);
  if (!b) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "maignan: out of memory");
  b->base.id = n->id;
  *out = &b->base;
  return RSW_OK;
}

static void maignan_traverse(object *o, param_visitor *v) {
  maignan_bsdf *m = (maignan_bsdf *)o;
  pv_object(v, "C", &m->C->base, 0.0, INFINITY);
  pv_object(v, "ndvi", &m->ndvi->base, -1.0, 1.0);
  pv_object(v, "refr_re", &m->refr_re->base, 1.0, INFINITY);
  pv_object(v, "refr_im", &m->refr_im->base, 0.0, INFINITY);
  pv_object(v, "ext_ior", &m->ext_ior->base, nextafter(0.0, 1.0), INFINITY);
}

const plugin plugin_maignan = {
    .name = "maignan",
    .cls = CLS_BSDF,
    .create = maignan_create,
    .destroy = maignan_destroy,
    .ops = &maignan_ops,
    .traverse = maignan_traverse,
};

bsdf *maignan_new(texture *C, texture *ndvi, texture *refr_re, texture *refr_im, texture *ext_ior) {
  maignan_bsdf *m = calloc(1, sizeof *m);
  if (!m) return NULL;
  m->base.base.plugin = &plugin_maignan;
  m->base.ops = &maignan_ops;
  m->base.flags = BSDF_GLOSSY_REFLECTION;
  m->C = C, m->ndvi = ndvi, m->refr_re = refr_re, m->refr_im = refr_im, m->ext_ior = ext_ior;
  return &m->base;
}
