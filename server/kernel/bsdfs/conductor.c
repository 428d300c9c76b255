/* `conductor`: a smooth metal, a perfect specular reflector weighted by
 * the conductor Fresnel term of the complex index eta + i k.
 *
 *   sample: wo = reflect(wi) (delta), pdf 1,
 *           weight = F(cos theta_i; eta, k) * specular_reflectance;
 *   eval = pdf = 0 (a delta lobe cannot be evaluated).
 * With the defaults eta = 0, k = 1, F = 1: a perfect mirror.
 *
 * Also holds the complex-index plumbing (material presets or eta/k
 * textures) shared with roughconductor.c.
 *
 * Source: mitsuba3 src/bsdfs/conductor.cpp; docs/kernel-conventions.md#conductors-and-fresnel. */
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "bsdfs_internal.h"
#include "fresnel.h"
#include "fresnel_pol.h"

/* ---- complex index of refraction ---------------------------------------- */

void conductor_ior_eval(const conductor_ior *c, const surface_interaction *si, color *eta, color *k) {
  if (c->material) {
    int p = rsw_page;
    *eta = p ? c->page_eta[p - 1] : c->mat_eta;
    *k = p ? c->page_k[p - 1] : c->mat_k;
  } else {
    *eta = tex_eval(c->eta, si);
    *k = tex_eval(c->k, si);
  }
}

rsw_status conductor_ior_prepare(conductor_ior *c, const render_ctx *rc, rsw_err *err, const char *where) {
  if (!c->material) return RSW_OK;
  render_ctx pc = rc_page(rc, 0);
  rsw_status st = ior_conductor_for_ctx(c->material, &pc, &c->mat_eta, &c->mat_k, err, where);
  for (int p = 1; p < rc_pages(rc) && !st; p++) {
    pc = rc_page(rc, p);
    st = ior_conductor_for_ctx(c->material, &pc, &c->page_eta[p - 1], &c->page_k[p - 1], err, where);
  }
  return st;
}

rsw_status conductor_ior_load(loader *ld, node *n, conductor_ior *out) {
  conductor_ior c = {0};
  const char *material;
  rsw_status st = ld_string(ld, n, "material", "none", &material);
  if (st != RSW_OK) return st;
  if (strcmp(material, "none") != 0) {
    if (ld_has(n, "eta"))
      return ld_fail(ld, n, "eta", RSW_ERR_INVALID, "give either 'material' or 'eta'/'k', not both");
    c.material = ior_conductor_lookup(material);
    if (!c.material)
      return ld_fail(ld, n, "material", RSW_ERR_INVALID, "unknown material '%s' (known: %s)", material,
                     ior_conductor_names());
    /* Initial values for this variant (mono at the default 550 nm);
     * prepare() re-evaluates them for each render. */
    render_ctx rc = {.variant = ld->variant, .wavelength = 550.0};
    st = conductor_ior_prepare(&c, &rc, ld->err, n->loc);
    if (st != RSW_OK) return st;
  } else {
    if ((st = ld_texture(ld, n, "eta", 0.0, 0.0, &c.eta)) != RSW_OK) return st;
    if ((st = ld_texture(ld, n, "k", 1.0, 0.0, &c.k)) != RSW_OK) return st;
  }
  *out = c;
  return RSW_OK;
}

/* ---- the smooth conductor ------------------------------------------------ */

static color conductor_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  (void)si;
  (void)wo;
  return col1(0.0);
}

static double conductor_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  (void)si;
  (void)wo;
  return 0.0;
}

/* Sampling (bsdf_ops.sample_batch): the mirror direction per lane, the
 * Fresnel terms of up to 64 lanes (three per lane for a coloured index,
 * none for eta = 0, k = 1: F = 1 exactly, as fresnel_conductor_col()) in
 * double lanes (bsdfs/fresnel_lanes.h, bitwise fresnel_conductor()),
 * times specular_reflectance. */
static void conductor_sample_batch(const bsdf *b, int n, const surface_interaction *const *si,
                                   const double *u1, const vec2 *u2, bsdf_sample *bs, color *weight) {
  (void)u1;
  (void)u2;
  const conductor_bsdf *c = (const conductor_bsdf *)b;
  enum {
    C = 64
  };
  rsw_isa isa = rsw_isa_get();
  for (int i0 = 0; i0 < n; i0 += C) {
    int m = n - i0 < C ? n - i0 : C;
    double ci[3 * C], et[3 * C], kk[3 * C], fr[3 * C];
    int first[C], nch[C], q = 0; /* lane j's terms: fr[first[j] .. first[j] + nch[j]) */
    for (int j = 0; j < m; j++) {
      const surface_interaction *s = si[i0 + j];
      nch[j] = -1;
      if (!(s->wi.z > 0.0)) continue;
      color eta, k;
      conductor_ior_eval(&c->ior, s, &eta, &k);
      bool grey = eta.c[0] == eta.c[1] && eta.c[0] == eta.c[2] && k.c[0] == k.c[1] && k.c[0] == k.c[2];
      first[j] = q;
      nch[j] = grey ? (eta.c[0] == 0.0 && k.c[0] == 1.0 ? 0 : 1) : 3;
      for (int ch = 0; ch < nch[j]; ch++, q++) ci[q] = s->wi.z, et[q] = eta.c[ch], kk[q] = k.c[ch];
    }
    fresnel_conductor_batch(isa, q, ci, et, kk, fr);
    for (int j = 0; j < m; j++) {
      int i = i0 + j;
      if (nch[j] < 0) {
        weight[i] = bsdf_fail(&bs[i]);
        continue;
      }
      bs[i].wo = reflect_local(si[i]->wi);
      bs[i].pdf = 1.0;
      bs[i].eta = 1.0;
      bs[i].sampled_type = BSDF_DELTA_REFLECTION;
      const double *f = &fr[first[j]];
      color F = nch[j] == 0 ? col1(1.0) : nch[j] == 1 ? col1(f[0]) : col(f[0], f[1], f[2]);
      weight[i] = col_mul(F, bsdf_factor(c->specular_reflectance, si[i]));
    }
  }
}

/* The scalar op is the batch of one (the lanes are bitwise the scalar
 * Fresnel term: tests/unit/test_simd.c). */
static color conductor_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2,
                              bsdf_sample *bs) {
  color w;
  conductor_sample_batch(b, 1, &si, &u1, &u2, bs, &w);
  return w;
}

/* A bundle of pages (bsdf_ops.delta_value): the mirror lobe at the page
 * rsw_page names, drawn with probability 1 (0 below the surface, or for
 * a wo that is not the mirror direction): its
 * value is sample()'s weight, bit for bit. What a composition over a
 * conductor (twosided) asks for. */
static color conductor_delta_value(const bsdf *b, const surface_interaction *si, unsigned lobe, vec3 wo,
                                   double *prob) {
  bsdf_sample bs;
  double u1 = 0.0;
  vec2 u2 = v2(0.0, 0.0);
  color w;
  conductor_sample_batch(b, 1, &si, &u1, &u2, &bs, &w);
  *prob = bs.pdf > 0.0 && lobe == BSDF_DELTA_REFLECTION && delta_same_direction(wo, bs.wo) ? 1.0 : 0.0;
  return *prob > 0.0 ? w : col1(0.0);
}

/* Polarization (docs/plugins.md#polarization-surfaces): the Fresnel matrix of
 * the complex index eta + i k per channel at the light's incidence
 * cosine, s-axis bases (mitsuba3 src/bsdfs/conductor.cpp; the default
 * eta 0, k 1 is a mirror that keeps the intensity but retards p against
 * s, as there). specular_reflectance scales F00 alone. */
static void conductor_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                                   mueller P[3], vec3 *s_in, vec3 *s_out) {
  (void)lobe;
  const conductor_bsdf *c = (const conductor_bsdf *)b;
  color eta, k;
  conductor_ior_eval(&c->ior, si, &eta, &k);
  fpol_reflection(P, wo.z, eta, k);
  *s_in = *s_out = fpol_s_axis(wo, si->wi);
}

static const bsdf_ops conductor_ops = {.sample = conductor_sample,
                                       .eval = conductor_eval,
                                       .pdf = conductor_pdf,
                                       .sample_batch = conductor_sample_batch,
                                       .polarization = conductor_polarization,
                                       .delta_value = conductor_delta_value};

static rsw_status conductor_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  return conductor_ior_prepare(&((conductor_bsdf *)o)->ior, rc, err, o->id);
}

static rsw_status conductor_create(loader *ld, node *n, object **out) {
  conductor_ior ior;
  texture *spec;
  rsw_status st = conductor_ior_load(ld, n, &ior);
  if (st != RSW_OK) return st;
  if ((st = ld_texture(ld, n, "specular_reflectance", 1.0, 0.0, &spec)) != RSW_OK) return st;
  conductor_bsdf *c = BSDF_NEW(conductor_bsdf, conductor, BSDF_DELTA_REFLECTION);
  if (c) c->ior = ior, c->specular_reflectance = spec;
  return plugin_created(ld, n, (object *)c, out);
}

/* eta/k are reported only without a material preset (a preset has no
 * texture to update); specular_reflectance always. */
void conductor_ior_traverse(conductor_ior *c, param_visitor *v) {
  if (c->material) return;
  pv_object(v, "eta", &c->eta->base, 0.0, INFINITY);
  pv_object(v, "k", &c->k->base, 0.0, INFINITY);
}

static void conductor_traverse(object *o, param_visitor *v) {
  conductor_bsdf *c = (conductor_bsdf *)o;
  conductor_ior_traverse(&c->ior, v);
  if (c->specular_reflectance)
    pv_object(v, "specular_reflectance", &c->specular_reflectance->base, 0.0, INFINITY);
}

DEFINE_PLUGIN(conductor, CLS_BSDF, .prepare = conductor_prepare, .ops = &conductor_ops,
              .traverse = conductor_traverse, .pages = plugin_pages_any);

bsdf *conductor_new(texture *eta, texture *k, const ior_conductor *material, texture *specular_reflectance,
                    const render_ctx *rc) {
  conductor_bsdf *c = BSDF_NEW(conductor_bsdf, conductor, BSDF_DELTA_REFLECTION);
  if (!c) return NULL;
  c->ior.eta = eta;
  c->ior.k = k;
  c->ior.material = material;
  c->specular_reflectance = specular_reflectance;
  render_ctx def = {.variant = VARIANT_MONO, .wavelength = 550.0};
  if (conductor_ior_prepare(&c->ior, rc ? rc : &def, NULL, NULL) != RSW_OK) {
    free(c);
    return NULL;
  }
  return &c->base;
}
