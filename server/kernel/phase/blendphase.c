/* `blendphase`: two phase functions mixed by a weight volume w(p) in
 * [0, 1] (0: the first only, 1: the second only), so that molecules and
 * aerosols mix per layer:
 *
 *   p(wi, wo) = (1 - w) p_0(wi, wo) + w p_1(wi, wo).
 *
 * Sampling picks phase_1 when u1 <= w (reusing u1 / w), else phase_0
 * (reusing (u1 - w) / (1 - w)), then returns the mixture's pdf and the
 * weight p / pdf. Mitsuba returns the picked component's own pdf and
 * weight instead; we return the mixture's (what eval_pdf reports too), so
 * that MIS and the chi-square test see one density. Components are
 * ordered by their property names (Mitsuba: alphanumeric order, the
 * usual `phase_0`, `phase_1`); `weight` defaults to 0.5. Polarized
 * variants: the mixture's phase matrix, F = (1 - w) F_0 + w F_1, i.e. the
 * components' factors weighted by their shares of p (a component without
 * a phase matrix counts as a depolarizer).
 *
 * Source: mitsuba3 src/phase/blendphase.cpp. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../core/fastmath.h"
#include "../scene/plugin_def.h"
#include "../volumes/volume.h"
#include "phase.h"

typedef struct blendphase {
  phase base;
  volume *weight;
  phase *ph[2];
} blendphase;

static double blend_lookup(const blendphase *b, vec3 p) {
  double w = volume_eval_1(b->weight, p);
  /* clamped to [0, 1] (NaN: 0), no libm calls and no branch (the layers
   * with aerosols and without alternate): w > 1 ? 1 : w > 0 ? w : 0 */
  return rsw_sel_min(1.0, rsw_sel_max(w, 0.0));
}

/* The weight at mi->p: looked up once per scattering when bound (the
 * volumetric integrators' NEE and phase sampling share it). */
static double blend_weight(const blendphase *b, const medium_interaction *mi) {
  return mi->bound == &b->base ? mi->bound_w : blend_lookup(b, mi->p);
}

static void blend_bind(const phase *ph, medium_interaction *mi) {
  mi->bound_w = blend_lookup((const blendphase *)ph, mi->p);
  mi->bound = ph;
}

/* The mixture at weight w from its components' values and pdfs at wo
 * (those of a component whose share is 0 taken as 0, not evaluated). */
static double blend_sum(double w, double v0, double p0, double v1, double p1, double *pdf) {
  *pdf = (1.0 - w) * p0 + w * p1;
  return (1.0 - w) * v0 + w * v1;
}

/* The mixture at weight w. */
static double blend_mix(const blendphase *b, double w, const medium_interaction *mi, vec3 wo, double *pdf) {
  double p0 = 0, p1 = 0, v0 = 0, v1 = 0;
  if (w < 1.0) v0 = b->ph[0]->ops->eval_pdf(b->ph[0], mi, wo, &p0);
  if (w > 0.0) v1 = b->ph[1]->ops->eval_pdf(b->ph[1], mi, wo, &p1);
  return blend_sum(w, v0, p0, v1, p1, pdf);
}

static double blend_eval_pdf(const phase *ph, const medium_interaction *mi, vec3 wo, double *pdf) {
  const blendphase *b = (const blendphase *)ph;
  return blend_mix(b, blend_weight(b, mi), mi, wo, pdf);
}

/* The component a sample at weight w draws from with u1 (phase_1 when
 * u1 <= w), and *u1 rescaled for it (at most 1). */
static int blend_pick(double w, double *u1) {
  int k;
  double u = *u1;
  if (w >= 1.0 || (w > 0.0 && u <= w)) {
    k = 1;
    u = w >= 1.0 ? u : u / w;
  } else {
    k = 0;
    u = w <= 0.0 ? u : (u - w) / (1.0 - w);
  }
  *u1 = u < 1.0 ? u : 1.0;
  return k;
}

/* The weight value / pdf of a sample whose mixture at wo is val, *pdf. */
static double blend_weigh(double val, double *pdf) {
  if (!(*pdf > 0.0)) return phase_fail(pdf);
  return val / *pdf;
}

static double blend_sample(const phase *ph, const medium_interaction *mi, double u1, vec2 u2, vec3 *wo,
                           double *pdf) {
  const blendphase *b = (const blendphase *)ph;
  double w = blend_weight(b, mi), cpdf;
  int k = blend_pick(w, &u1);
  double cw = b->ph[k]->ops->sample(b->ph[k], mi, u1, u2, wo, &cpdf);
  if (!(cpdf > 0.0) || !(cw > 0.0)) return phase_fail(pdf);
  double val = blend_mix(b, w, mi, *wo, pdf); /* (the weight looked up once) */
  return blend_weigh(val, pdf);
}

/* ---- batches: lane i is blend_eval_pdf's / blend_sample's, bit for bit:
 * the weights looked up (or bound) per lane, the components evaluated by
 * their own batches over the lanes, a component's values taken as 0 where
 * its share is. */

#define BLEND_CHUNK 64

/* n <= BLEND_CHUNK lanes at weights w. */
static void blend_mix_lanes(const blendphase *b, int n, const medium_interaction *mi, const vec3 *wo,
                            const double *w, double *val, double *pdf) {
  double v0[BLEND_CHUNK], p0[BLEND_CHUNK], v1[BLEND_CHUNK], p1[BLEND_CHUNK];
  phase_eval_pdf_batch(b->ph[0], n, mi, wo, v0, p0);
  phase_eval_pdf_batch(b->ph[1], n, mi, wo, v1, p1);
  for (int i = 0; i < n; i++) {
    bool a0 = w[i] < 1.0;
    bool a1 = w[i] > 0.0;
    val[i] = blend_sum(w[i], a0 ? v0[i] : 0.0, a0 ? p0[i] : 0.0, a1 ? v1[i] : 0.0, a1 ? p1[i] : 0.0, &pdf[i]);
  }
}

static void blend_eval_pdf_batch(const phase *ph, int n, const medium_interaction *mi, const vec3 *wo,
                                 double *val, double *pdf) {
  const blendphase *b = (const blendphase *)ph;
  for (int i0 = 0; i0 < n; i0 += BLEND_CHUNK) {
    int cnt = n - i0 < BLEND_CHUNK ? n - i0 : BLEND_CHUNK;
    double w[BLEND_CHUNK];
    for (int i = 0; i < cnt; i++) w[i] = blend_weight(b, &mi[i0 + i]);
    blend_mix_lanes(b, cnt, mi + i0, wo + i0, w, val + i0, pdf + i0);
  }
}

static void blend_sample_batch(const phase *ph, int n, const medium_interaction *mi, const double *u1,
                               const vec2 *u2, vec3 *wo, double *pdf, double *weight) {
  const blendphase *b = (const blendphase *)ph;
  for (int i0 = 0; i0 < n; i0 += BLEND_CHUNK) {
    int cnt = n - i0 < BLEND_CHUNK ? n - i0 : BLEND_CHUNK;
    double w[BLEND_CHUNK], val[BLEND_CHUNK];
    bool ok[BLEND_CHUNK];
    vec3 at[BLEND_CHUNK]; /* where the mixture is evaluated (failed lanes: any unit direction) */
    for (int i = 0; i < cnt; i++) {
      int j = i0 + i;
      w[i] = blend_weight(b, &mi[j]);
      double u = u1[j], cpdf;
      int k = blend_pick(w[i], &u);
      double cw = b->ph[k]->ops->sample(b->ph[k], &mi[j], u, u2[j], &wo[j], &cpdf);
      ok[i] = cpdf > 0.0 && cw > 0.0;
      at[i] = ok[i] ? wo[j] : v3_neg(mi[j].wi);
    }
    blend_mix_lanes(b, cnt, mi + i0, at, w, val, pdf + i0);
    for (int i = 0; i < cnt; i++)
      weight[i0 + i] = ok[i] ? blend_weigh(val[i], &pdf[i0 + i]) : phase_fail(&pdf[i0 + i]);
  }
}

/* Polarized variants: the components' factors weighted by (1 - w) p_0 and
 * w p_1 (phase.h phase_mix_add). */
static void blend_polarization(const phase *ph, const medium_interaction *mi, vec3 wo, mueller P[3]) {
  const blendphase *b = (const blendphase *)ph;
  double w = blend_weight(b, mi), pdf;
  mueller acc[3] = {mu_zero(), mu_zero(), mu_zero()};
  if (w < 1.0)
    phase_mix_add(b->ph[0], mi, wo, (1.0 - w) * b->ph[0]->ops->eval_pdf(b->ph[0], mi, wo, &pdf), acc);
  if (w > 0.0) phase_mix_add(b->ph[1], mi, wo, w * b->ph[1]->ops->eval_pdf(b->ph[1], mi, wo, &pdf), acc);
  for (int c = 0; c < 3; c++) P[c] = mu_normalized(acc[c]);
}

/* A component's value per channel: its own channels where it is
 * chromatic (a nested blendphase whose weight depends on the
 * wavelength), else its one value in all three. */
static color component_channels(const phase *ph, const medium_interaction *mi, vec3 wo) {
  if (ph->chromatic && ph->ops->eval_channels) return ph->ops->eval_channels(ph, mi, wo);
  double pdf;
  return col1(ph->ops->eval_pdf(ph, mi, wo, &pdf));
}

/* A spectral bundle whose weight, or a component's, depends on the
 * wavelength (phase.chromatic, set by prepare): each channel's mixture at
 * its own weight of its components' own values, the weight volume read
 * per channel (and at the page rsw_page names); sample() and eval_pdf()
 * stay channel 0's. */
static color blend_eval_channels(const phase *ph, const medium_interaction *mi, vec3 wo) {
  const blendphase *b = (const blendphase *)ph;
  color w = volume_eval(b->weight, mi->p);
  color v0 = component_channels(b->ph[0], mi, wo), v1 = component_channels(b->ph[1], mi, wo);
  color r;
  for (int c = 0; c < 3; c++) {
    double wc = w.c[c] > 1.0 ? 1.0 : w.c[c] > 0.0 ? w.c[c] : 0.0;
    r.c[c] = (1.0 - wc) * v0.c[c] + wc * v1.c[c];
  }
  return r;
}

static const phase_ops blendphase_ops = {.sample = blend_sample,
                                         .eval_pdf = blend_eval_pdf,
                                         .bind = blend_bind,
                                         .polarization = blend_polarization,
                                         .sample_batch = blend_sample_batch,
                                         .eval_pdf_batch = blend_eval_pdf_batch,
                                         .eval_channels = blend_eval_channels};

static rsw_status blendphase_create(loader *ld, node *n, object **out) {
  object **kids;
  size_t count;
  rsw_status st = ld_children(ld, n, CLS_PHASE, &kids, &count);
  if (st) return st;
  if (count != 2) {
    free(kids);
    return ld_fail(ld, n, NULL, RSW_ERR_INVALID,
                   "blendphase '%s': takes exactly two nested phase functions, got %zu", n->id ? n->id : "",
                   count);
  }
  /* Their property names, in the order ld_children marked them used
   * (before `weight`, the only other object property, is read). */
  const char *names[2] = {"", ""};
  for (size_t i = 0, k = 0; i < n->n_props && k < 2; i++)
    if (n->props[i].used && (n->props[i].kind == PROP_NODE || n->props[i].kind == PROP_REF))
      names[k++] = n->props[i].name;
  bool swap = names[0][0] && names[1][0] && strcmp(names[0], names[1]) > 0;
  blendphase *b = calloc(1, sizeof *b);
  if (!b) {
    free(kids);
    return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "blendphase: out of memory");
  }
  b->ph[0] = (phase *)kids[swap ? 1 : 0];
  b->ph[1] = (phase *)kids[swap ? 0 : 1];
  free(kids);
  st = ld_volume_mapped(ld, n, "weight", 0.5, 0.0, 1.0, &b->weight);
  if (st) {
    free(b);
    return st;
  }
  b->base.ops = &blendphase_ops;
  b->base.base.id = n->id;
  *out = &b->base.base;
  return RSW_OK;
}

/* Mitsuba's keys: weight, phase_0, phase_1 (the weight of a constant is
 * `weight.value.value`, of a grid `weight.data`). */
static void blendphase_traverse(object *o, param_visitor *v) {
  blendphase *b = (blendphase *)o;
  pv_object(v, "weight", &b->weight->base, NAN, NAN);
  pv_object(v, "phase_0", &b->ph[0]->base, NAN, NAN);
  pv_object(v, "phase_1", &b->ph[1]->base, NAN, NAN);
}

/* Whether ph's value depends on the wavelength through a blendphase's
 * weight (its own or a component's). */
static bool blend_spectral(const phase *ph) {
  if (ph->ops != &blendphase_ops) return false;
  const blendphase *b = (const blendphase *)ph;
  return volume_spectral(b->weight) || blend_spectral(b->ph[0]) || blend_spectral(b->ph[1]);
}

/* A spectral bundle with a weight that depends on the wavelength (its own
 * or a nested blendphase's) renders chromatic (blend_eval_channels), each
 * page at its own weights. */
static rsw_status blendphase_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  (void)err;
  blendphase *b = (blendphase *)o;
  b->base.chromatic = rc->bundle > 1 && blend_spectral(&b->base);
  return RSW_OK;
}

DEFINE_PLUGIN(blendphase, CLS_PHASE, .ops = &blendphase_ops, .traverse = blendphase_traverse,
              .prepare = blendphase_prepare, .pages = plugin_pages_any);
