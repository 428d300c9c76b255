/* `plastic`: a smooth dielectric coating over a diffuse base (mitsuba3
 * src/bsdfs/plastic.cpp; the layer model in bsdfs/plastic_layer.h).
 * One-sided (black from the back). With F(c) the coating's Fresnel
 * reflectance at incidence cosine c:
 *   specular: a delta reflection of weight F(cos_i) s;
 *   diffuse:  f cos_o = rho' cos_o / pi  (1 - F(cos_i)) (1 - F(cos_o)) / eta^2,
 *             rho' = rho / (1 - Fdr_int), Fdr_int = fresnel_diffuse_reflectance(1 / eta).
 * Sampling (Mitsuba's): the specular lobe with probability
 *   P_s = F_i w / (F_i w + (1 - F_i)(1 - w)),  w = s / (s + rho) (means),
 * else a cosine-weighted direction (pdf (1 - P_s) cos_o / pi). */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "fresnel.h"
#include "fresnel_pol.h"
#include "plastic_layer.h"

typedef struct plastic_bsdf {
  bsdf base;
  plastic_layer layer;
  double fdr_int; /* derived from layer.eta */
} plastic_bsdf;

static double prob_specular(const plastic_bsdf *p, double f_i) {
  double w = plastic_specular_weight(&p->layer);
  double ps = f_i * w, pd = (1.0 - f_i) * (1.0 - w);
  return ps + pd > 0 ? ps / (ps + pd) : 0.0;
}

static color diffuse_value(const plastic_bsdf *p, const surface_interaction *si, double f_i, double cos_o) {
  double f_o = fresnel_dielectric(cos_o, p->layer.eta, NULL, NULL, NULL);
  double k = (1.0 - f_i) * (1.0 - f_o) / (p->layer.eta * p->layer.eta);
  return col_scale(plastic_diffuse(&p->layer, si, p->fdr_int), k);
}

static color plastic_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2,
                            bsdf_sample *bs) {
  const plastic_bsdf *p = (const plastic_bsdf *)b;
  double cos_i = si->wi.z;
  if (!(cos_i > 0.0)) return bsdf_fail(bs);
  double f_i = fresnel_dielectric(cos_i, p->layer.eta, NULL, NULL, NULL);
  double ps = prob_specular(p, f_i);
  bs->eta = 1.0;
  if (u1 < ps) {
    bs->wo = reflect_local(si->wi);
    bs->pdf = ps;
    bs->sampled_type = BSDF_DELTA_REFLECTION;
    return col_scale(bsdf_factor(p->layer.specular, si), f_i / ps);
  }
  double pd = 1.0 - ps;
  bs->wo = warp_square_to_cosine_hemisphere(u2);
  bs->pdf = pd * warp_square_to_cosine_hemisphere_pdf(bs->wo);
  bs->sampled_type = BSDF_DIFFUSE_REFLECTION;
  if (!(bs->pdf > 0.0) || !(bs->wo.z > 0.0)) return bsdf_fail(bs);
  return col_scale(diffuse_value(p, si, f_i, bs->wo.z), 1.0 / pd);
}

/* The specular lobe's value F(cos_i) s and its probability P_s at the
 * page rsw_page names, wo being its mirror direction (bsdf_ops.delta_value). */
static color plastic_delta_value(const bsdf *b, const surface_interaction *si, unsigned lobe, vec3 wo,
                                 double *prob) {
  const plastic_bsdf *p = (const plastic_bsdf *)b;
  double cos_i = si->wi.z;
  *prob = 0.0;
  if (!(cos_i > 0.0) || lobe != BSDF_DELTA_REFLECTION || !delta_same_direction(wo, reflect_local(si->wi)))
    return col1(0.0);
  double f_i = fresnel_dielectric(cos_i, p->layer.eta, NULL, NULL, NULL);
  *prob = prob_specular(p, f_i);
  return col_scale(bsdf_factor(p->layer.specular, si), f_i);
}

static color plastic_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const plastic_bsdf *p = (const plastic_bsdf *)b;
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return col1(0.0);
  double f_i = fresnel_dielectric(si->wi.z, p->layer.eta, NULL, NULL, NULL);
  return col_scale(diffuse_value(p, si, f_i, wo.z), warp_square_to_cosine_hemisphere_pdf(wo));
}

static double plastic_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const plastic_bsdf *p = (const plastic_bsdf *)b;
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return 0.0;
  double f_i = fresnel_dielectric(si->wi.z, p->layer.eta, NULL, NULL, NULL);
  return (1.0 - prob_specular(p, f_i)) * warp_square_to_cosine_hemisphere_pdf(wo);
}

/* Polarization (docs/plugins.md#polarization-surfaces): the specular lobe is the
 * coating's Fresnel reflection matrix at the light's incidence cosine
 * (s-axis bases, as `dielectric`); the diffuse base depolarizes, and it
 * is eval's only lobe (lobe 0). Mitsuba 3's plastic depolarizes both
 * lobes; its pplastic and our `dielectric` polarize a smooth coating's
 * reflection as here. */
static void plastic_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                                 mueller P[3], vec3 *s_in, vec3 *s_out) {
  fpol_depolarize(P, wo, si->wi, s_in, s_out);
  if (lobe & BSDF_DELTA_REFLECTION)
    P[0] = P[1] = P[2] = mu_normalized(mu_fresnel_reflection(wo.z, ((const plastic_bsdf *)b)->layer.eta));
}

static const bsdf_ops plastic_ops = {.sample = plastic_sample,
                                     .eval = plastic_eval,
                                     .pdf = plastic_pdf,
                                     .polarization = plastic_polarization,
                                     .delta_value = plastic_delta_value};

static void plastic_parameters_changed(object *o) {
  plastic_bsdf *p = (plastic_bsdf *)o;
  p->fdr_int = fresnel_diffuse_reflectance(1.0 / p->layer.eta);
}

static void plastic_traverse(object *o, param_visitor *v) {
  plastic_layer_traverse(&((plastic_bsdf *)o)->layer, v);
}

DEFINE_PLUGIN(plastic, CLS_BSDF, .ops = &plastic_ops, .traverse = plastic_traverse,
              .parameters_changed = plastic_parameters_changed);

static rsw_status plastic_create(loader *ld, node *n, object **out) {
  plastic_layer layer;
  rsw_status st = plastic_layer_load(ld, n, &layer);
  if (st) return st;
  plastic_bsdf *p = BSDF_NEW(plastic_bsdf, plastic, BSDF_DELTA_REFLECTION | BSDF_DIFFUSE_REFLECTION);
  if (!p) return plugin_created(ld, n, NULL, out);
  p->layer = layer;
  plastic_parameters_changed(&p->base.base);
  return plugin_created(ld, n, &p->base.base, out);
}
