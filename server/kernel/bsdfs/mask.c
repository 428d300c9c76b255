/* `mask`: a nested BSDF made partly transparent by an opacity texture
 * alpha in [0, 1] (mitsuba3 src/bsdfs/mask.cpp; clamped where a texture
 * strays, as Mitsuba): with probability 1 - alpha light passes the surface
 * unchanged, else it meets the nested BSDF.
 *   eval = alpha f_nested,  pdf = alpha pdf_nested (the smooth part);
 *   sample: u1 > alpha -> the pass-through wo = -wi, a delta transmission
 *   of pdf 1 - alpha and weight 1; else the nested sample with u1 / alpha,
 *   its pdf times alpha, its weight unchanged (Mitsuba's).
 * `opacity` (0.5, texture; the mean of its channels), one nested BSDF.
 * Shadow rays stop at the surface whatever alpha is (as `path` treats
 * `null`; Mitsuba's path does the same: only its volumetric integrators
 * weigh shadow rays by 1 - alpha). Keys: `opacity.…`, `nested_bsdf.…`. */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "bsdfs_internal.h"
#include "fresnel_pol.h"

typedef struct mask_bsdf {
  bsdf base;
  texture *opacity;
  bsdf *nested;
} mask_bsdf;

static double opacity_at(const mask_bsdf *m, const surface_interaction *si) {
  double a = col_mean(tex_eval(m->opacity, si));
  return a < 0 ? 0 : a > 1 ? 1 : a;
}

static color mask_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  const mask_bsdf *m = (const mask_bsdf *)b;
  double a = opacity_at(m, si);
  if (u1 >= a) {
    bs->wo = v3_neg(si->wi);
    bs->pdf = 1.0 - a;
    bs->eta = 1.0;
    bs->sampled_type = BSDF_DELTA_TRANSMISSION;
    return col1(1.0);
  }
  color v = m->nested->ops->sample(m->nested, si, u1 / a, u2, bs);
  bs->pdf *= a;
  return v;
}

static color mask_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const mask_bsdf *m = (const mask_bsdf *)b;
  return col_scale(m->nested->ops->eval(m->nested, si, wo), opacity_at(m, si));
}

static double mask_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const mask_bsdf *m = (const mask_bsdf *)b;
  return opacity_at(m, si) * m->nested->ops->pdf(m->nested, si, wo);
}

/* Polarization (docs/plugins.md#polarization-surfaces): the pass-through
 * (wo = -wi, a delta transmission) leaves the light as it is (the
 * identity); everything else is the nested BSDF's (eval = alpha f_nested
 * has its matrix). A nested delta transmission straight through (a
 * dielectric at normal incidence) is the identity too, so the two need
 * not be told apart. */
static void mask_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                              mueller P[3], vec3 *s_in, vec3 *s_out) {
  const mask_bsdf *m = (const mask_bsdf *)b;
  vec3 wi = si->wi;
  if ((lobe & BSDF_DELTA_TRANSMISSION) && wo.x == -wi.x && wo.y == -wi.y && wo.z == -wi.z) {
    P[0] = P[1] = P[2] = mu_identity();
    *s_in = *s_out = stokes_basis(wo);
    return;
  }
  fpol_forward(m->nested, si, wo, lobe, P, s_in, s_out);
}

/* A bundle of pages (bsdf_ops.delta_value): lobe `lobe` towards wo at the
 * page rsw_page names, the pass-through's (1 - alpha, weight 1, where wo
 * = -wi) plus alpha times the nested BSDF's (where its lobe leads to wo:
 * a nested delta transmission refracts elsewhere). */
static color mask_delta_value(const bsdf *b, const surface_interaction *si, unsigned lobe, vec3 wo,
                              double *prob) {
  const mask_bsdf *m = (const mask_bsdf *)b;
  double a = opacity_at(m, si), pn = 0.0;
  color v = col1(0.0);
  if (m->nested->ops->delta_value)
    v = col_scale(m->nested->ops->delta_value(m->nested, si, lobe, wo, &pn), a);
  double pass = lobe == BSDF_DELTA_TRANSMISSION && delta_same_direction(wo, v3_neg(si->wi)) ? 1.0 - a : 0.0;
  *prob = pass + a * pn;
  return col_add(v, col1(pass));
}

static const bsdf_ops mask_ops = {.sample = mask_sample,
                                  .eval = mask_eval,
                                  .pdf = mask_pdf,
                                  .polarization = mask_polarization,
                                  .delta_value = mask_delta_value};

/* Whether a bundle of pages can weigh its delta lobes (scene_page_blocker):
 * the nested BSDF's delta lobes say their values. */
static bool mask_pages(const object *o) {
  const bsdf *n = ((const mask_bsdf *)o)->nested;
  return !(n->flags & BSDF_DELTA) || n->ops->delta_value;
}

static void mask_traverse(object *o, param_visitor *v) {
  mask_bsdf *m = (mask_bsdf *)o;
  pv_object(v, "opacity", &m->opacity->base, 0.0, 1.0);
  pv_object(v, "nested_bsdf", &m->nested->base, NAN, NAN);
}

DEFINE_PLUGIN(mask, CLS_BSDF, .ops = &mask_ops, .traverse = mask_traverse, .pages = mask_pages);

static rsw_status mask_create(loader *ld, node *n, object **out) {
  object *nested;
  rsw_status st = ld_child(ld, n, NULL, CLS_BSDF, &nested);
  if (st) return st;
  if (!nested) return ld_fail(ld, n, NULL, RSW_ERR_MISSING, "mask: a nested BSDF is required");
  texture *op;
  if ((st = ld_texture(ld, n, "opacity", 0.5, 0.0, &op))) return st;
  if ((st = bsdf_check_const_range(ld, n, "opacity", op, 0.0, false, 1.0, false))) return st;
  mask_bsdf *m = BSDF_NEW(mask_bsdf, mask, ((bsdf *)nested)->flags | BSDF_DELTA_TRANSMISSION);
  if (!m) return plugin_created(ld, n, NULL, out);
  m->nested = (bsdf *)nested;
  m->opacity = op;
  return plugin_created(ld, n, &m->base.base, out);
}
