/* `blendbsdf`: two BSDFs mixed by a weight texture w in [0, 1] (mitsuba3
 * src/bsdfs/blendbsdf.cpp; 0: the first only, 1: the second only):
 *   f = (1 - w) f_0 + w f_1,   pdf = (1 - w) pdf_0 + w pdf_1.
 * w is the texture's value at the shading point (the mean of its
 * channels), clamped to [0, 1] as Mitsuba does; a constant must lie in
 * [0, 1]. Sampling picks bsdf_1 when u1 <= w (reusing u1 / w), else
 * bsdf_0 (reusing (u1 - w) / (1 - w)), as Mitsuba. A smooth sample then
 * reports the mixture's pdf and the weight f / pdf (Mitsuba reports the
 * picked component's own, as its blendphase does; the mixture's is what
 * pdf() gives, so MIS and the chi-square test see one density, as our
 * blendphase); a delta sample its pick probability times its own pdf,
 * and its own weight. Components are ordered by their property names
 * (Mitsuba: alphanumeric, the usual `bsdf_0`, `bsdf_1`); `weight` is
 * required. Keys: `weight` (its texture's), `bsdf_0`, `bsdf_1`. */
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "bsdfs_internal.h"
#include "fresnel_pol.h"

typedef struct blend_bsdf {
  bsdf base;
  texture *weight;
  bsdf *c[2];
} blend_bsdf;

static double weight_at(const blend_bsdf *b, const surface_interaction *si) {
  double w = col_mean(tex_eval(b->weight, si));
  return w < 0 ? 0 : w > 1 ? 1 : w;
}

static color blend_eval(const bsdf *bb, const surface_interaction *si, vec3 wo) {
  const blend_bsdf *b = (const blend_bsdf *)bb;
  double w = weight_at(b, si);
  color f0 = w < 1 ? b->c[0]->ops->eval(b->c[0], si, wo) : col1(0);
  color f1 = w > 0 ? b->c[1]->ops->eval(b->c[1], si, wo) : col1(0);
  return col_add(col_scale(f0, 1 - w), col_scale(f1, w));
}

static double blend_pdf(const bsdf *bb, const surface_interaction *si, vec3 wo) {
  const blend_bsdf *b = (const blend_bsdf *)bb;
  double w = weight_at(b, si);
  double p0 = w < 1 ? b->c[0]->ops->pdf(b->c[0], si, wo) : 0;
  double p1 = w > 0 ? b->c[1]->ops->pdf(b->c[1], si, wo) : 0;
  return (1 - w) * p0 + w * p1;
}

static color blend_sample(const bsdf *bb, const surface_interaction *si, double u1, vec2 u2,
                          bsdf_sample *bs) {
  const blend_bsdf *b = (const blend_bsdf *)bb;
  double w = weight_at(b, si);
  int k = u1 <= w && w > 0 ? 1 : 0;
  double pk = k ? w : 1 - w;
  double uk = k ? u1 / w : (u1 - w) / (1 - w);
  color v = b->c[k]->ops->sample(b->c[k], si, fmin(uk, 0x1.fffffffffffffp-1), u2, bs);
  if (!(bs->pdf > 0) || col_is_black(v)) return bsdf_fail(bs);
  if (bs->sampled_type & BSDF_DELTA) {
    bs->pdf *= pk;
    return v;
  }
  bs->pdf = blend_pdf(bb, si, bs->wo);
  if (!(bs->pdf > 0)) return bsdf_fail(bs);
  return col_scale(blend_eval(bb, si, bs->wo), 1.0 / bs->pdf);
}

/* Polarization (docs/plugins.md#polarization-surfaces). Smooth lobes (eval, and
 * a smooth sample, whose weight is the mixture's eval over its pdf): the
 * components' matrices weighted by their shares of f, per channel,
 * P = ((1 - w) f_0 P_0 + w f_1 P_1) / f, in common bases (the s axis of
 * wo and wi). A delta lobe: the matrix of the component that has it; when
 * both have it (which one was drawn is not known here) their mixture by
 * the pick probabilities 1 - w and w, an approximation. */
static void blend_polarization(const bsdf *bb, const surface_interaction *si, vec3 wo, unsigned lobe,
                               mueller P[3], vec3 *s_in, vec3 *s_out) {
  const blend_bsdf *b = (const blend_bsdf *)bb;
  double w = weight_at(b, si);
  color f[2];
  unsigned delta = lobe & BSDF_DELTA;
  if (delta) {
    bool has0 = w < 1 && (b->c[0]->flags & delta), has1 = w > 0 && (b->c[1]->flags & delta);
    if (has0 != has1) {
      fpol_forward(b->c[has1 ? 1 : 0], si, wo, lobe, P, s_in, s_out);
      return;
    }
    f[0] = col1(1 - w), f[1] = col1(w);
  } else {
    f[0] = col_scale(w < 1 ? b->c[0]->ops->eval(b->c[0], si, wo) : col1(0), 1 - w);
    f[1] = col_scale(w > 0 ? b->c[1]->ops->eval(b->c[1], si, wo) : col1(0), w);
  }
  *s_in = *s_out = fpol_s_axis(wo, si->wi);
  mueller acc[3] = {mu_zero(), mu_zero(), mu_zero()}, Pk[3];
  double sum[3] = {0, 0, 0};
  for (int k = 0; k < 2; k++) {
    if (col_is_black(f[k])) continue;
    fpol_child(b->c[k], si, wo, lobe, Pk, *s_in, *s_out);
    fpol_mix_add(acc, sum, f[k], Pk);
  }
  fpol_mix_end(acc, sum);
  for (int c = 0; c < 3; c++) P[c] = acc[c];
}

/* A bundle of pages (bsdf_ops.delta_value): lobe `lobe` towards wo at
 * the page rsw_page names, the components' values and probabilities mixed
 * by their pick probabilities 1 - w and w (each counts only where its own
 * lobe leads to wo: two delta transmissions may refract apart). */
static color blend_delta_value(const bsdf *bb, const surface_interaction *si, unsigned lobe, vec3 wo,
                               double *prob) {
  const blend_bsdf *b = (const blend_bsdf *)bb;
  double w = weight_at(b, si), pk[2] = {1.0 - w, w};
  color v = col1(0.0);
  *prob = 0.0;
  for (int k = 0; k < 2; k++) {
    const bsdf *c = b->c[k];
    double p = 0.0;
    if (!(pk[k] > 0) || !c->ops->delta_value) continue;
    v = col_add(v, col_scale(c->ops->delta_value(c, si, lobe, wo, &p), pk[k]));
    *prob += pk[k] * p;
  }
  return v;
}

static const bsdf_ops blend_ops = {.sample = blend_sample,
                                   .eval = blend_eval,
                                   .pdf = blend_pdf,
                                   .polarization = blend_polarization,
                                   .delta_value = blend_delta_value};

/* Whether a bundle of pages can weigh its delta lobes (scene_page_blocker):
 * each component's delta lobes say their values. */
static bool blend_pages(const object *o) {
  const blend_bsdf *b = (const blend_bsdf *)o;
  for (int k = 0; k < 2; k++) {
    const bsdf *c = b->c[k];
    if ((c->flags & BSDF_DELTA) && !c->ops->delta_value) return false;
  }
  return true;
}

static void blend_traverse(object *o, param_visitor *v) {
  blend_bsdf *b = (blend_bsdf *)o;
  pv_object(v, "weight", &b->weight->base, 0.0, 1.0);
  pv_object(v, "bsdf_0", &b->c[0]->base, NAN, NAN);
  pv_object(v, "bsdf_1", &b->c[1]->base, NAN, NAN);
}

DEFINE_PLUGIN(blendbsdf, CLS_BSDF, .ops = &blend_ops, .traverse = blend_traverse, .pages = blend_pages);

static rsw_status blendbsdf_create(loader *ld, node *n, object **out) {
  object **kids;
  size_t count;
  rsw_status st = ld_children(ld, n, CLS_BSDF, &kids, &count);
  if (st) return st;
  if (count != 2) {
    free(kids);
    return ld_fail(ld, n, NULL, RSW_ERR_INVALID, "blendbsdf '%s': takes exactly two nested BSDFs, got %zu",
                   n->id ? n->id : "", count);
  }
  /* Their property names, in the order ld_children marked them used
   * (before `weight` is read), as blendphase orders its components. */
  const char *names[2] = {"", ""};
  for (size_t i = 0, k = 0; i < n->n_props && k < 2; i++)
    if (n->props[i].used && (n->props[i].kind == PROP_NODE || n->props[i].kind == PROP_REF))
      names[k++] = n->props[i].name;
  bool swap = names[0][0] && names[1][0] && strcmp(names[0], names[1]) > 0;
  bsdf *c0 = (bsdf *)kids[swap ? 1 : 0], *c1 = (bsdf *)kids[swap ? 0 : 1];
  free(kids);
  if (!ld_has(n, "weight"))
    return ld_fail(ld, n, "weight", RSW_ERR_MISSING, "blendbsdf: 'weight' is required");
  texture *w;
  if ((st = ld_texture(ld, n, "weight", 0.5, 0.0, &w))) return st;
  if ((st = bsdf_check_const_range(ld, n, "weight", w, 0.0, false, 1.0, false))) return st;
  blend_bsdf *b = BSDF_NEW(blend_bsdf, blendbsdf, c0->flags | c1->flags);
  if (!b) return plugin_created(ld, n, NULL, out);
  b->weight = w;
  b->c[0] = c0, b->c[1] = c1;
  return plugin_created(ld, n, &b->base.base, out);
}
