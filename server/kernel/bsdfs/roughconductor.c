/* `roughconductor`: a rough metal, the Torrance-Sparrow microfacet BRDF
 * with a Beckmann (default) or GGX distribution.
 *
 *   h = normalize(wi + wo),
 *   f_r cos(theta_o) = F(wi.h; eta, k) D(h) G(wi, wo, h) / (4 cos(theta_i))
 *                      * specular_reflectance,
 * zero unless cos(theta_i) > 0 and cos(theta_o) > 0.
 *
 * Sampling draws a microfacet normal m (visible normals by default, or
 * D(m) cos(theta_m)) and reflects wi about it: wo = 2 (wi.m) m - wi, with
 * the Jacobian dwo/dm = 1 / (4 |wo.m|), so
 *   pdf(wo) = pdf_m(m) / (4 wo.m),
 *   weight  = eval / pdf
 *           = F G1(wo, m) G1(wi, m) / G1vis(wi, m)  (visible normals,
 *             since wi.m = wo.m and pdf_m = G1vis(wi) (wi.m) D / wi.z)
 *           = F G(wi, wo, m) (wi.m) / (cos(theta_i) cos(theta_m))
 *                                                   (D cos sampling).
 * G1 is Mitsuba's (for Beckmann the rational fit, which eval uses, so
 * eval keeps Mitsuba's values); G1vis is the exact Smith G1 that
 * normalises the visible normals actually drawn (mf_visible_g1()). For GGX
 * the two are the same and the weight is Mitsuba's F G1(wo, m). Mitsuba's
 * Beckmann weight F G1(wo, m) is not eval/pdf of its own sampler: its
 * sky (BSDF-sampled) albedo misses its sun (emitter-sampled) one by up to
 * 0.3 % at grazing incidence (issue 11 item 4).
 *
 * Source: mitsuba3 src/bsdfs/roughconductor.cpp and
 * include/mitsuba/render/microfacet.h; docs/kernel-conventions.md#rough-conductors
 * and #where-raysweep-differs. */
#include <ctype.h>
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "../textures/texture.h"
#include "bsdfs_internal.h"
#include "fresnel.h"
#include "fresnel_pol.h"

/* Scalar roughness from a texture: luminance, which is the value itself
 * for a uniform (mono or grey) input, as Mitsuba's eval_1(). */
static mf_distr distr_at(const roughconductor_bsdf *r, const surface_interaction *si) {
  double au = col_luminance(tex_eval(r->alpha_u, si));
  double av = r->alpha_v == r->alpha_u ? au : col_luminance(tex_eval(r->alpha_v, si));
  return mf_make(r->type, au, av, r->sample_visible);
}

static color rough_finish(const roughconductor_bsdf *r, const mf_distr *d, const surface_interaction *si,
                          vec3 m, double pdf_m, double g1vis, bsdf_sample *bs);

/* Not a batch of one: the batched ops place m and evaluate D G in float
 * lanes (bsdfs/microfacet_lanes.h), this scalar op in double (its
 * placement in float too, by mf_sample's own code); both keep pdf and
 * weight consistent, but their bits differ. */
static color rough_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  (void)u1;
  const roughconductor_bsdf *r = (const roughconductor_bsdf *)b;
  vec3 wi = si->wi;
  if (!(wi.z > 0.0)) return bsdf_fail(bs);
  mf_distr d = distr_at(r, si);
  /* D and G1vis(wi, m) are computed once, for the pdf, and the weight
   * reuses G1vis (it is the same factor). */
  double pdf_m, g1vis;
  vec3 m = mf_sample_g1(&d, wi, u2, &pdf_m, &g1vis);
  return rough_finish(r, &d, si, m, pdf_m, g1vis, bs);
}

/* The double-precision end of a visible-normal sample, shared by the
 * scalar and the batched paths: from the microfacet normal m drawn, the
 * reflected direction, its pdf (D and G1vis computed once) and the weight
 * eval / pdf with Fresnel. */
static color rough_finish(const roughconductor_bsdf *r, const mf_distr *d, const surface_interaction *si,
                          vec3 m, double pdf_m, double g1vis, bsdf_sample *bs) {
  vec3 wi = si->wi;
  vec3 wo = reflect_about(wi, m);
  double wo_m = v3_dot(wo, m);
  if (!(pdf_m > 0.0) || !(wo.z > 0.0) || !(wo_m > 0.0)) return bsdf_fail(bs);
  bs->wo = wo;
  bs->pdf = pdf_m / (4.0 * wo_m);
  bs->eta = 1.0;
  bs->sampled_type = BSDF_GLOSSY_REFLECTION;
  double weight;
  if (d->sample_visible)
    weight = mf_smith_g1(d, wo, m) * (mf_smith_g1(d, wi, m) / g1vis);
  else
    weight = mf_G(d, wi, wo, m) * v3_dot(wi, m) / (wi.z * m.z);
  color eta, k;
  conductor_ior_eval(&r->ior, si, &eta, &k);
  color f = fresnel_conductor_col(v3_dot(wi, m), eta, k);
  return col_mul(col_scale(f, weight), bsdf_factor(r->specular_reflectance, si));
}

/* What every lane of a batch shares when the textures involved are
 * uniform (a uniform texture's eval ignores si, so one evaluation gives
 * each lane's own bits): the distribution, the conductor's indices with
 * whether Fresnel is 1 (`material: none`, eta 0 and k 1:
 * fresnel_conductor_col returns col1(1) there whatever the angle), and the
 * specular factor. si0: any lane's interaction. */
typedef struct rough_shared {
  bool distr, ior, f_one, factor;
  mf_distr d;
  color eta, k, fac;
} rough_shared;

static void rough_shared_at(const roughconductor_bsdf *r, const surface_interaction *si0, rough_shared *c) {
  color v;
  c->distr = uniform_texture_value(r->alpha_u, &v) &&
             (r->alpha_v == r->alpha_u || uniform_texture_value(r->alpha_v, &v));
  if (c->distr) c->d = distr_at(r, si0);
  c->ior = r->ior.material || (uniform_texture_value(r->ior.eta, &v) && uniform_texture_value(r->ior.k, &v));
  c->f_one = false;
  if (c->ior) {
    conductor_ior_eval(&r->ior, si0, &c->eta, &c->k);
    c->f_one = c->eta.c[0] == 0.0 && c->eta.c[1] == 0.0 && c->eta.c[2] == 0.0 && c->k.c[0] == 1.0 &&
               c->k.c[1] == 1.0 && c->k.c[2] == 1.0;
  }
  c->factor = !r->specular_reflectance || uniform_texture_value(r->specular_reflectance, &v);
  if (c->factor) c->fac = bsdf_factor(r->specular_reflectance, si0);
}

/* Fresnel at cos_i times the specular factor, for lane si: the shared
 * values where there are some, else the per-lane evaluations. */
static inline color rough_fresnel_factor(const roughconductor_bsdf *r, const rough_shared *c,
                                         const surface_interaction *si, double cos_i, double value) {
  color f;
  if (c->f_one) {
    f = col1(1.0);
  } else {
    color eta = c->eta, k = c->k;
    if (!c->ior) conductor_ior_eval(&r->ior, si, &eta, &k);
    f = fresnel_conductor_col(cos_i, eta, k);
  }
  return col_mul(col_scale(f, value), c->factor ? c->fac : bsdf_factor(r->specular_reflectance, si));
}

/* Batched sampling (bsdf_ops.sample_batch): the visible-normal samples of
 * up to 64 lanes at a time, with their pdf and weight (without Fresnel),
 * by the per-ISA single-precision kernels (bsdfs/microfacet_lanes.h: for
 * Beckmann the Newton inversion runs across the lanes instead of one chain
 * per sample; the tail says why float is safe there); then Fresnel at wi.m
 * and the specular factor per lane in double, and wo renormalised in
 * double. D cos sampling (sample_visible false) takes the scalar path. */
static void rough_sample_batch(const bsdf *b, int n, const surface_interaction *const *si, const double *u1,
                               const vec2 *u2, bsdf_sample *bs, color *weight) {
  const roughconductor_bsdf *r = (const roughconductor_bsdf *)b;
  if (!r->sample_visible) {
    for (int i = 0; i < n; i++) weight[i] = rough_sample(b, si[i], u1[i], u2[i], &bs[i]);
    return;
  }
  enum {
    C = 64
  };
  rsw_isa isa = rsw_isa_get();
  rough_shared sh;
  if (n <= 0) return;
  rough_shared_at(r, si[0], &sh);
  float in[7][C], out[6][C];
  if (sh.distr) /* the lanes' roughness, converted once */
    for (int j = 0; j < C; j++) in[3][j] = (float)sh.d.alpha_u, in[4][j] = (float)sh.d.alpha_v;
  for (int i0 = 0; i0 < n; i0 += C) {
    int m = n - i0 < C ? n - i0 : C;
    int lane[C], k = 0;
    for (int j = 0; j < m; j++) {
      const surface_interaction *s = si[i0 + j];
      if (!(s->wi.z > 0.0)) {
        weight[i0 + j] = bsdf_fail(&bs[i0 + j]);
        continue;
      }
      in[0][k] = (float)s->wi.x, in[1][k] = (float)s->wi.y, in[2][k] = (float)s->wi.z;
      if (!sh.distr) {
        mf_distr d = distr_at(r, s);
        in[3][k] = (float)d.alpha_u, in[4][k] = (float)d.alpha_v;
      }
      in[5][k] = (float)u2[i0 + j].x, in[6][k] = (float)u2[i0 + j].y;
      lane[k++] = i0 + j;
    }
    const float *ip[7] = {in[0], in[1], in[2], in[3], in[4], in[5], in[6]};
    float *op[6] = {out[0], out[1], out[2], out[3], out[4], out[5]};
    mf_sample_visible_batch(isa, r->type == MF_GGX, k, ip, op);
    for (int j = 0; j < k; j++) {
      int i = lane[j];
      if (!(out[3][j] > 0.0f)) {
        weight[i] = bsdf_fail(&bs[i]);
        continue;
      }
      bs[i].wo = v3_norm(v3(out[0][j], out[1][j], out[2][j]));
      bs[i].pdf = out[3][j];
      bs[i].eta = 1.0;
      bs[i].sampled_type = BSDF_GLOSSY_REFLECTION;
      weight[i] = rough_fresnel_factor(r, &sh, si[i], out[5][j], out[4][j]);
    }
  }
}

static color rough_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const roughconductor_bsdf *r = (const roughconductor_bsdf *)b;
  vec3 wi = si->wi;
  if (!(wi.z > 0.0) || !(wo.z > 0.0)) return col1(0.0);
  vec3 h = v3_norm(v3_add(wi, wo));
  mf_distr d = distr_at(r, si);
  double D = mf_D(&d, h);
  if (D == 0.0) return col1(0.0);
  double value = D * mf_G(&d, wi, wo, h) / (4.0 * wi.z);
  color eta, k;
  conductor_ior_eval(&r->ior, si, &eta, &k);
  color f = fresnel_conductor_col(v3_dot(wi, h), eta, k);
  return col_mul(col_scale(f, value), bsdf_factor(r->specular_reflectance, si));
}

static double rough_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const roughconductor_bsdf *r = (const roughconductor_bsdf *)b;
  vec3 wi = si->wi;
  if (!(wi.z > 0.0) || !(wo.z > 0.0)) return 0.0;
  vec3 h = v3_norm(v3_add(wi, wo));
  double wi_h = v3_dot(wi, h), wo_h = v3_dot(wo, h);
  if (!(wi_h > 0.0) || !(wo_h > 0.0)) return 0.0;
  mf_distr d = distr_at(r, si);
  return mf_pdf(&d, wi, h) / (4.0 * wo_h);
}

/* Batched eval and pdf (bsdf_ops.eval_pdf_batch): D, the G1 products, the
 * visible G1 and the pdf of up to 64 lanes at a time in single precision
 * (bsdfs/microfacet_lanes.h mf_eval_lanes says why that is safe), then
 * Fresnel and the specular factor per lane in double, as rough_eval(). */
static void rough_eval_pdf_batch(const bsdf *b, int n, const surface_interaction *const *si, const vec3 *wo,
                                 color *f, double *pdf) {
  const roughconductor_bsdf *r = (const roughconductor_bsdf *)b;
  enum {
    C = 64
  };
  rsw_isa isa = rsw_isa_get();
  rough_shared sh;
  if (n <= 0) return;
  rough_shared_at(r, si[0], &sh);
  float in[8][C], out[3][C];
  if (sh.distr) /* the lanes' roughness, converted once */
    for (int j = 0; j < C; j++) in[6][j] = (float)sh.d.alpha_u, in[7][j] = (float)sh.d.alpha_v;
  for (int i0 = 0; i0 < n; i0 += C) {
    int m = n - i0 < C ? n - i0 : C;
    int lane[C], k = 0;
    for (int j = 0; j < m; j++) {
      const surface_interaction *s = si[i0 + j];
      vec3 o = wo[i0 + j];
      f[i0 + j] = col1(0.0);
      pdf[i0 + j] = 0.0;
      if (!(s->wi.z > 0.0) || !(o.z > 0.0)) continue;
      in[0][k] = (float)s->wi.x, in[1][k] = (float)s->wi.y, in[2][k] = (float)s->wi.z;
      in[3][k] = (float)o.x, in[4][k] = (float)o.y, in[5][k] = (float)o.z;
      if (!sh.distr) {
        mf_distr d = distr_at(r, s);
        in[6][k] = (float)d.alpha_u, in[7][k] = (float)d.alpha_v;
      }
      lane[k++] = i0 + j;
    }
    const float *ip[8] = {in[0], in[1], in[2], in[3], in[4], in[5], in[6], in[7]};
    float *op[3] = {out[0], out[1], out[2]};
    mf_eval_batch(isa, r->type == MF_GGX, r->sample_visible, k, ip, op);
    for (int j = 0; j < k; j++) {
      int i = lane[j];
      pdf[i] = out[1][j];
      if (!(out[0][j] > 0.0f)) continue;
      f[i] = rough_fresnel_factor(r, &sh, si[i], out[2][j], out[0][j]);
    }
  }
}

/* Polarization (docs/plugins.md#polarization-surfaces): the Fresnel matrix of
 * the microfacet that reflects -wo into wi, at wo . h (h the half
 * vector), in the bases of its plane of incidence, which holds wo, wi and
 * h (mitsuba3 src/bsdfs/roughconductor.cpp). One lobe: eval's and a
 * sample's matrix are the same. */
static void rough_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                               mueller P[3], vec3 *s_in, vec3 *s_out) {
  (void)lobe;
  const roughconductor_bsdf *r = (const roughconductor_bsdf *)b;
  color eta, k;
  conductor_ior_eval(&r->ior, si, &eta, &k);
  vec3 h = v3_add(si->wi, wo);
  double l = v3_len(h);
  fpol_reflection(P, l > 0.0 ? v3_dot(wo, h) / l : 1.0, eta, k);
  *s_in = *s_out = fpol_s_axis(wo, si->wi);
}

static const bsdf_ops rough_ops = {.sample = rough_sample,
                                   .eval = rough_eval,
                                   .pdf = rough_pdf,
                                   .sample_batch = rough_sample_batch,
                                   .eval_pdf_batch = rough_eval_pdf_batch,
                                   .polarization = rough_polarization};

static rsw_status rough_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  return conductor_ior_prepare(&((roughconductor_bsdf *)o)->ior, rc, err, o->id);
}

static bool equal_nocase(const char *a, const char *b) {
  for (; *a && *b; a++, b++)
    if (tolower((unsigned char)*a) != tolower((unsigned char)*b)) return false;
  return *a == *b;
}

/* Distribution and roughness as Mitsuba's MicrofacetDistribution(props):
 * `distribution` "beckmann" (default) or "ggx" (case-insensitive);
 * either `alpha` (default 0.1) or both `alpha_u` and `alpha_v`;
 * `sample_visible` (default true). */
static rsw_status roughconductor_create(loader *ld, node *n, object **out) {
  const char *dist;
  rsw_status st = ld_string(ld, n, "distribution", "beckmann", &dist);
  if (st != RSW_OK) return st;
  mf_type type;
  if (equal_nocase(dist, "beckmann"))
    type = MF_BECKMANN;
  else if (equal_nocase(dist, "ggx"))
    type = MF_GGX;
  else
    return ld_fail(ld, n, "distribution", RSW_ERR_INVALID,
                   "unknown distribution '%s' (expected "
                   "\"beckmann\" or \"ggx\")",
                   dist);

  /* Roughness must be positive: Mitsuba silently clamps alpha to 1e-4;
   * we refuse smaller values (use `conductor` for a perfect mirror). */
  const double alpha_min = 1e-4;
  texture *au, *av;
  bool has_u = ld_has(n, "alpha_u"), has_v = ld_has(n, "alpha_v");
  if (ld_has(n, "alpha")) {
    if (has_u || has_v)
      return ld_fail(ld, n, has_u ? "alpha_u" : "alpha_v", RSW_ERR_INVALID,
                     "give either 'alpha' or 'alpha_u' and "
                     "'alpha_v', not both");
    if ((st = ld_texture(ld, n, "alpha", 0.1, alpha_min, &au)) != RSW_OK) return st;
    av = au;
  } else if (has_u || has_v) {
    if (!(has_u && has_v))
      return ld_fail(ld, n, has_u ? "alpha_v" : "alpha_u", RSW_ERR_MISSING,
                     "'alpha_u' and 'alpha_v' must be given "
                     "together");
    if ((st = ld_texture(ld, n, "alpha_u", 0.1, alpha_min, &au)) != RSW_OK) return st;
    if ((st = ld_texture(ld, n, "alpha_v", 0.1, alpha_min, &av)) != RSW_OK) return st;
  } else {
    if ((st = ld_texture(ld, n, "alpha", 0.1, alpha_min, &au)) != RSW_OK) return st;
    av = au;
  }

  bool sample_visible;
  if ((st = ld_bool(ld, n, "sample_visible", true, &sample_visible)) != RSW_OK) return st;
  conductor_ior ior;
  if ((st = conductor_ior_load(ld, n, &ior)) != RSW_OK) return st;
  texture *spec;
  if ((st = ld_texture_opt(ld, n, "specular_reflectance", 0.0, &spec)) != RSW_OK) return st;

  roughconductor_bsdf *r = BSDF_NEW(roughconductor_bsdf, roughconductor, BSDF_GLOSSY_REFLECTION);
  if (r) {
    r->ior = ior;
    r->specular_reflectance = spec;
    r->type = type;
    r->alpha_u = au;
    r->alpha_v = av;
    r->sample_visible = sample_visible;
  }
  return plugin_created(ld, n, (object *)r, out);
}

static void rough_traverse(object *o, param_visitor *v) {
  roughconductor_bsdf *r = (roughconductor_bsdf *)o;
  /* Mitsuba: `alpha` when isotropic, else `alpha_u` and `alpha_v`. */
  if (r->alpha_u == r->alpha_v) {
    pv_object(v, "alpha", &r->alpha_u->base, 1e-4, INFINITY);
  } else {
    pv_object(v, "alpha_u", &r->alpha_u->base, 1e-4, INFINITY);
    pv_object(v, "alpha_v", &r->alpha_v->base, 1e-4, INFINITY);
  }
  conductor_ior_traverse(&r->ior, v);
  if (r->specular_reflectance)
    pv_object(v, "specular_reflectance", &r->specular_reflectance->base, 0.0, INFINITY);
}

DEFINE_PLUGIN(roughconductor, CLS_BSDF, .prepare = rough_prepare, .ops = &rough_ops,
              .traverse = rough_traverse, .pages = plugin_pages_any);

bsdf *roughconductor_new(mf_type type, texture *alpha_u, texture *alpha_v, bool sample_visible, texture *eta,
                         texture *k, const ior_conductor *material, texture *specular_reflectance,
                         const render_ctx *rc) {
  roughconductor_bsdf *r = BSDF_NEW(roughconductor_bsdf, roughconductor, BSDF_GLOSSY_REFLECTION);
  if (!r) return NULL;
  r->ior.eta = eta;
  r->ior.k = k;
  r->ior.material = material;
  r->specular_reflectance = specular_reflectance;
  r->type = type;
  r->alpha_u = alpha_u;
  r->alpha_v = alpha_v ? alpha_v : alpha_u;
  r->sample_visible = sample_visible;
  render_ctx def = {.variant = VARIANT_MONO, .wavelength = 550.0};
  if (conductor_ior_prepare(&r->ior, rc ? rc : &def, NULL, NULL) != RSW_OK) {
    free(r);
    return NULL;
  }
  return &r->base;
}
