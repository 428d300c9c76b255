/* `roughplastic`: a rough dielectric coating (Beckmann or GGX, isotropic
 * `alpha`) over a diffuse base (mitsuba3 src/bsdfs/roughplastic.cpp; the
 * layer model in bsdfs/plastic_layer.h). One-sided. With H the half
 * vector, F the coating's Fresnel reflectance, D and G the microfacet
 * terms (bsdfs/microfacet.h):
 *   specular: f cos_o = s F(wi.H) D(H) G(wi, wo, H) / (4 cos_i);
 *   diffuse:  f cos_o = rho' cos_o / pi  T(cos_i) T(cos_o) / eta^2,
 *             rho' = rho / (1 - R_int)   (rho / (1 - rho R_int) if nonlinear),
 * where T(mu) = 1 - R(mu, eta) is the coating's transmittance and R_int
 * its internal diffuse reflectance, from the rough interface's directional
 * albedo R(mu, eta) = E_m[F(wi.m) G1(wo, m)] (m from the visible normals
 * of wi, wo = reflect(wi, m); Mitsuba's eval_reflectance). As Mitsuba:
 * T is tabulated at 64 cosines mu_k = max(1e-6, k / 63) and read by
 * linear interpolation, and R_int = 2 mean_k(R(mu_k, 1/eta) mu_k). Mitsuba
 * integrates R by Gauss-Lobatto quadrature; here a 32 x 32 midpoint rule
 * on the visible-normal sample square (the same integral; differences
 * ~1e-3). Sampling: the specular lobe (visible normals) with probability
 * P_s = (1 - T_i) w / ((1 - T_i) w + T_i (1 - w)), w = s / (s + rho), else
 * cosine-weighted; pdf the mixture, weight eval / pdf.
 * Keys: `alpha` and `eta` (spectral; the tables are recomputed),
 * `diffuse_reflectance`, `specular_reflectance`. */
#include <stdlib.h>
#include <strings.h>

#include "../scene/plugin_def.h"
#include "fresnel.h"
#include "fresnel_pol.h"
#include "plastic_layer.h"

enum {
  RP_RES = 64, /* Mitsuba's MI_ROUGH_TRANSMITTANCE_RES */
  RP_QUAD = 32
};

typedef struct roughplastic_bsdf {
  bsdf base;
  plastic_layer layer;
  mf_type type;
  double alpha;
  bool sample_visible;
  double ext_transmittance[RP_RES]; /* T(mu_k) */
  double int_reflectance;           /* R_int */
} roughplastic_bsdf;

/* R(mu, eta) (see the top of the file). */
static double rough_albedo(const mf_distr *vis, double mu, double eta) {
  vec3 wi = v3(sqrt(fmax(0.0, 1.0 - mu * mu)), 0.0, mu);
  double sum = 0.0;
  for (int i = 0; i < RP_QUAD; i++)
    for (int j = 0; j < RP_QUAD; j++) {
      double pdf;
      vec3 m = mf_sample(vis, wi, v2((i + 0.5) / RP_QUAD, (j + 0.5) / RP_QUAD), &pdf);
      if (!(pdf > 0.0)) continue;
      vec3 wo = reflect_about(wi, m);
      if (!(wo.z > 0.0)) continue;
      sum += fresnel_dielectric(v3_dot(wi, m), eta, NULL, NULL, NULL) * mf_smith_g1(vis, wo, m);
    }
  return sum / (RP_QUAD * RP_QUAD);
}

static void rp_parameters_changed(object *o) {
  roughplastic_bsdf *r = (roughplastic_bsdf *)o;
  mf_distr vis = mf_make(r->type, r->alpha, r->alpha, true);
  double acc = 0.0;
  for (int k = 0; k < RP_RES; k++) {
    double mu = fmax(1e-6, (double)k / (RP_RES - 1));
    r->ext_transmittance[k] = 1.0 - rough_albedo(&vis, mu, r->layer.eta);
    acc += rough_albedo(&vis, mu, 1.0 / r->layer.eta) * mu;
  }
  r->int_reflectance = 2.0 * acc / RP_RES;
}

/* Mitsuba's lerp_gather over the table. */
static double transmittance(const roughplastic_bsdf *r, double mu) {
  double x = mu * (RP_RES - 1);
  int k = x < RP_RES - 2 ? (int)x : RP_RES - 2;
  double w1 = x - k;
  return (1.0 - w1) * r->ext_transmittance[k] + w1 * r->ext_transmittance[k + 1];
}

static double prob_specular(const roughplastic_bsdf *r, double t_i) {
  double w = plastic_specular_weight(&r->layer);
  double ps = (1.0 - t_i) * w, pd = t_i * (1.0 - w);
  return ps + pd > 0 ? ps / (ps + pd) : 0.0;
}

/* eval's two lobes: *fs the specular, *fd the diffuse (both cosine
 * weighted); false (both 0) outside the upper hemisphere. */
static bool rp_lobes(const roughplastic_bsdf *r, const surface_interaction *si, vec3 wo, color *fs,
                     color *fd) {
  vec3 wi = si->wi;
  if (!(wi.z > 0.0) || !(wo.z > 0.0)) {
    *fs = *fd = col1(0.0);
    return false;
  }
  mf_distr d = mf_make(r->type, r->alpha, r->alpha, r->sample_visible);
  vec3 h = v3_norm(v3_add(wi, wo));
  double spec = 0.0, D = mf_D(&d, h);
  if (D > 0.0)
    spec = fresnel_dielectric(v3_dot(wi, h), r->layer.eta, NULL, NULL, NULL) * D * mf_G(&d, wi, wo, h) /
           (4.0 * wi.z);
  *fs = col_scale(bsdf_factor(r->layer.specular, si), spec);
  double t =
      transmittance(r, wi.z) * transmittance(r, wo.z) * wo.z * RSW_INV_PI / (r->layer.eta * r->layer.eta);
  *fd = col_scale(plastic_diffuse(&r->layer, si, r->int_reflectance), t);
  return true;
}

static color rp_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  color fs, fd;
  if (!rp_lobes((const roughplastic_bsdf *)b, si, wo, &fs, &fd)) return col1(0.0);
  return col_add(fs, fd);
}

/* Polarization (docs/plugins.md#polarization-surfaces): the coating's microfacet
 * Fresnel matrix at wo . h for the specular lobe (s-axis bases, as
 * `roughconductor`), the diffuse base depolarizing; mixed by the lobes'
 * values, per channel, P = (f_s F / F00 + f_d D) / (f_s + f_d). A
 * sample's weight is eval / pdf of both lobes whichever was drawn, so
 * every lobe gets this mixture. (Mitsuba 3's roughplastic depolarizes
 * both lobes.) */
static void rp_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                            mueller P[3], vec3 *s_in, vec3 *s_out) {
  (void)lobe;
  const roughplastic_bsdf *r = (const roughplastic_bsdf *)b;
  color fs, fd;
  fpol_depolarize(P, wo, si->wi, s_in, s_out);
  if (!rp_lobes(r, si, wo, &fs, &fd)) return;
  vec3 h = v3_norm(v3_add(si->wi, wo));
  mueller F[3];
  F[0] = F[1] = F[2] = mu_normalized(mu_fresnel_reflection(v3_dot(wo, h), r->layer.eta));
  fpol_with_diffuse(P, F, fs, fd);
}

static double rp_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const roughplastic_bsdf *r = (const roughplastic_bsdf *)b;
  vec3 wi = si->wi;
  if (!(wi.z > 0.0) || !(wo.z > 0.0)) return 0.0;
  double ps = prob_specular(r, transmittance(r, wi.z));
  vec3 h = v3_norm(v3_add(wi, wo));
  double wo_h = v3_dot(wo, h), spec = 0.0;
  if (v3_dot(wi, h) > 0.0 && wo_h > 0.0) {
    mf_distr d = mf_make(r->type, r->alpha, r->alpha, r->sample_visible);
    spec = mf_pdf(&d, wi, h) / (4.0 * wo_h);
  }
  return ps * spec + (1.0 - ps) * warp_square_to_cosine_hemisphere_pdf(wo);
}

static color rp_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  const roughplastic_bsdf *r = (const roughplastic_bsdf *)b;
  vec3 wi = si->wi;
  if (!(wi.z > 0.0)) return bsdf_fail(bs);
  double ps = prob_specular(r, transmittance(r, wi.z));
  if (u1 < ps) {
    mf_distr d = mf_make(r->type, r->alpha, r->alpha, r->sample_visible);
    double mpdf;
    vec3 m = mf_sample(&d, wi, u2, &mpdf);
    if (!(mpdf > 0.0)) return bsdf_fail(bs);
    bs->wo = reflect_about(wi, m);
    bs->sampled_type = BSDF_GLOSSY_REFLECTION;
  } else {
    bs->wo = warp_square_to_cosine_hemisphere(u2);
    bs->sampled_type = BSDF_DIFFUSE_REFLECTION;
  }
  bs->eta = 1.0;
  if (!(bs->wo.z > 0.0)) return bsdf_fail(bs);
  bs->pdf = rp_pdf(b, si, bs->wo);
  if (!(bs->pdf > 0.0)) return bsdf_fail(bs);
  return col_scale(rp_eval(b, si, bs->wo), 1.0 / bs->pdf);
}

static const bsdf_ops roughplastic_ops = {
    .sample = rp_sample, .eval = rp_eval, .pdf = rp_pdf, .polarization = rp_polarization};

static void rp_traverse(object *o, param_visitor *v) {
  roughplastic_bsdf *r = (roughplastic_bsdf *)o;
  pv_float(v, "alpha", &r->alpha, UPDATE_SPECTRAL, 1e-4, 1e4);
  plastic_layer_traverse(&r->layer, v);
}

DEFINE_PLUGIN(roughplastic, CLS_BSDF, .ops = &roughplastic_ops, .traverse = rp_traverse,
              .parameters_changed = rp_parameters_changed);

static rsw_status roughplastic_create(loader *ld, node *n, object **out) {
  const char *dist;
  rsw_status st = ld_string(ld, n, "distribution", "beckmann", &dist);
  if (st) return st;
  mf_type type;
  if (strcasecmp(dist, "beckmann") == 0)
    type = MF_BECKMANN;
  else if (strcasecmp(dist, "ggx") == 0)
    type = MF_GGX;
  else
    return ld_fail(ld, n, "distribution", RSW_ERR_INVALID,
                   "unknown distribution '%s' (expected \"beckmann\" or \"ggx\")", dist);
  if (ld_has(n, "alpha_u") || ld_has(n, "alpha_v"))
    return ld_fail(ld, n, ld_has(n, "alpha_u") ? "alpha_u" : "alpha_v", RSW_ERR_INVALID,
                   "roughplastic is isotropic (as Mitsuba's): give 'alpha'");
  double alpha;
  bool visible;
  plastic_layer layer;
  /* alpha is a number, not a texture: the tables depend on it. */
  if ((st = ld_float_range(ld, n, "alpha", 0.1, 1e-4, 1e4, &alpha))) return st;
  if ((st = ld_bool(ld, n, "sample_visible", true, &visible))) return st;
  if ((st = plastic_layer_load(ld, n, &layer))) return st;
  if (layer.eta == 1.0)
    return ld_fail(ld, n, "int_ior", RSW_ERR_INVALID, "int_ior and ext_ior must differ (as in Mitsuba)");
  roughplastic_bsdf *r =
      BSDF_NEW(roughplastic_bsdf, roughplastic, BSDF_GLOSSY_REFLECTION | BSDF_DIFFUSE_REFLECTION);
  if (!r) return plugin_created(ld, n, NULL, out);
  r->layer = layer;
  r->type = type;
  r->alpha = alpha;
  r->sample_visible = visible;
  rp_parameters_changed(&r->base.base);
  return plugin_created(ld, n, &r->base.base, out);
}
