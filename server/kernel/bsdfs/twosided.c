/* `twosided`: makes one-sided reflection models reflect from both sides.
 * One or two nested BSDFs (front, back; back defaults to front). When the
 * incident direction lies on the back (wi.z < 0), both directions are
 * mirrored through the surface (z -> -z) and the back BSDF is used:
 *   eval(wi, wo) = back.eval((wi.x, wi.y, -wi.z), (wo.x, wo.y, -wo.z)),
 * and a sampled wo is mirrored back. wi.z == 0 gives 0.
 *
 * Nested BSDFs with a transmission lobe are rejected (Mitsuba's default,
 * allow_transmission = false, is the only mode here).
 *
 * Source: mitsuba3 src/bsdfs/twosided.cpp; docs/kernel-conventions.md#diffuse-and-twosided. */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "bsdfs_internal.h"
#include "fresnel_pol.h"

#define TRANSMISSION_LOBES (BSDF_DIFFUSE_TRANSMISSION | BSDF_GLOSSY_TRANSMISSION | BSDF_DELTA_TRANSMISSION)

static vec3 flip_z(vec3 v) {
  return v3(v.x, v.y, -v.z);
}

/* The scalar ops pick a side and call the nested BSDF's scalar op; the
 * batched ones split a chunk by side and call the nested batched ops
 * (bsdf_sample_n), so each lane gets the same value either way. */
static color twosided_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2,
                             bsdf_sample *bs) {
  const twosided_bsdf *t = (const twosided_bsdf *)b;
  if (si->wi.z > 0.0) return t->brdf[0]->ops->sample(t->brdf[0], si, u1, u2, bs);
  if (!(si->wi.z < 0.0)) return bsdf_fail(bs);
  surface_interaction s = *si;
  s.wi = flip_z(si->wi);
  color w = t->brdf[1]->ops->sample(t->brdf[1], &s, u1, u2, bs);
  bs->wo = flip_z(bs->wo);
  return w;
}

static color twosided_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const twosided_bsdf *t = (const twosided_bsdf *)b;
  if (si->wi.z > 0.0) return t->brdf[0]->ops->eval(t->brdf[0], si, wo);
  if (!(si->wi.z < 0.0)) return col1(0.0);
  surface_interaction s = *si;
  s.wi = flip_z(si->wi);
  return t->brdf[1]->ops->eval(t->brdf[1], &s, flip_z(wo));
}

static double twosided_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const twosided_bsdf *t = (const twosided_bsdf *)b;
  if (si->wi.z > 0.0) return t->brdf[0]->ops->pdf(t->brdf[0], si, wo);
  if (!(si->wi.z < 0.0)) return 0.0;
  surface_interaction s = *si;
  s.wi = flip_z(si->wi);
  return t->brdf[1]->ops->pdf(t->brdf[1], &s, flip_z(wo));
}

/* ---- batched ops: each side's lanes through that side's batched op ------
 * Lanes with wi.z > 0 go to the front BSDF as they are; lanes with
 * wi.z < 0 to the back one with wi (and wo) mirrored, as the scalar ops
 * do; wi.z == 0 (or NaN) fails. A side without a batched op runs its
 * scalar op per lane. A lane's result is then its side's batched result,
 * which depends on that lane alone. */
enum {
  TS_C = 64
};

/* Up to TS_C lanes split by side: lane[s][j] the lane index of side s's
 * j-th entry, sp[s] its interactions (the back side's are copies in buf
 * with wi mirrored); cnt[2] the counts. Lanes with wi.z == 0 (or NaN) are
 * in neither. */
static void split_sides(int m, const surface_interaction *const *si, surface_interaction *buf,
                        const surface_interaction *sp[2][TS_C], int lane[2][TS_C], int cnt[2]) {
  cnt[0] = cnt[1] = 0;
  for (int j = 0; j < m; j++) {
    const surface_interaction *s = si[j];
    if (s->wi.z > 0.0) {
      lane[0][cnt[0]] = j;
      sp[0][cnt[0]++] = s;
    } else if (s->wi.z < 0.0) {
      surface_interaction *b = &buf[cnt[1]];
      *b = *s;
      b->wi = flip_z(s->wi);
      lane[1][cnt[1]] = j;
      sp[1][cnt[1]++] = b;
    }
  }
}

static void twosided_sample_batch(const bsdf *b, int n, const surface_interaction *const *si,
                                  const double *u1, const vec2 *u2, bsdf_sample *bs, color *weight) {
  const twosided_bsdf *t = (const twosided_bsdf *)b;
  for (int i0 = 0; i0 < n; i0 += TS_C) {
    int m = n - i0 < TS_C ? n - i0 : TS_C;
    surface_interaction buf[TS_C];
    const surface_interaction *sp[2][TS_C];
    int lane[2][TS_C], cnt[2];
    split_sides(m, si + i0, buf, sp, lane, cnt);
    for (int j = 0; j < m; j++) weight[i0 + j] = bsdf_fail(&bs[i0 + j]); /* wi.z == 0 lanes keep this */
    for (int s = 0; s < 2; s++) {
      double v1[TS_C];
      vec2 v2[TS_C];
      bsdf_sample out[TS_C];
      color w[TS_C];
      for (int j = 0; j < cnt[s]; j++) v1[j] = u1[i0 + lane[s][j]], v2[j] = u2[i0 + lane[s][j]];
      if (cnt[s] > 0) bsdf_sample_n(t->brdf[s], cnt[s], sp[s], v1, v2, out, w);
      for (int j = 0; j < cnt[s]; j++) {
        int i = i0 + lane[s][j];
        bs[i] = out[j];
        if (s == 1) bs[i].wo = flip_z(out[j].wo);
        weight[i] = w[j];
      }
    }
  }
}

static void twosided_eval_pdf_batch(const bsdf *b, int n, const surface_interaction *const *si,
                                    const vec3 *wo, color *f, double *pdf) {
  const twosided_bsdf *t = (const twosided_bsdf *)b;
  for (int i0 = 0; i0 < n; i0 += TS_C) {
    int m = n - i0 < TS_C ? n - i0 : TS_C;
    surface_interaction buf[TS_C];
    const surface_interaction *sp[2][TS_C];
    int lane[2][TS_C], cnt[2];
    split_sides(m, si + i0, buf, sp, lane, cnt);
    for (int j = 0; j < m; j++) f[i0 + j] = col1(0.0), pdf[i0 + j] = 0.0;
    for (int s = 0; s < 2; s++) {
      vec3 o[TS_C];
      color fo[TS_C];
      double po[TS_C];
      for (int j = 0; j < cnt[s]; j++) o[j] = s == 1 ? flip_z(wo[i0 + lane[s][j]]) : wo[i0 + lane[s][j]];
      if (cnt[s] > 0) bsdf_eval_pdf_n(t->brdf[s], cnt[s], sp[s], o, fo, po);
      for (int j = 0; j < cnt[s]; j++) f[i0 + lane[s][j]] = fo[j], pdf[i0 + lane[s][j]] = po[j];
    }
  }
}

/* Polarization (docs/plugins.md#polarization-surfaces): the side's BSDF, with the
 * back side's geometry mirrored as for its values. A mirror reverses the
 * handedness of a Stokes basis (y = d x x), so U and V change sign on
 * both sides of the back BSDF's matrix: P = D P_back D, D = diag(1, 1, -1, -1). */
static void twosided_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                                  mueller P[3], vec3 *s_in, vec3 *s_out) {
  const twosided_bsdf *t = (const twosided_bsdf *)b;
  if (si->wi.z > 0.0) {
    fpol_forward(t->brdf[0], si, wo, lobe, P, s_in, s_out);
    return;
  }
  if (!(si->wi.z < 0.0)) {
    fpol_depolarize(P, wo, si->wi, s_in, s_out);
    return;
  }
  surface_interaction s = *si;
  s.wi = flip_z(si->wi);
  fpol_forward(t->brdf[1], &s, flip_z(wo), lobe, P, s_in, s_out);
  *s_in = flip_z(*s_in);
  *s_out = flip_z(*s_out);
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < 4; i++)
      for (int j = 0; j < 4; j++)
        if ((i >= 2) != (j >= 2)) P[c].m[i][j] = -P[c].m[i][j];
}

/* A bundle of pages (bsdf_ops.delta_value): the side's BSDF's delta lobe
 * at the page rsw_page names, the back side's wi and wo mirrored as for its
 * values (a mirrored direction has the same cosines, so the lobe's value
 * and probability are the back BSDF's). A side whose BSDF has no
 * delta_value has no delta lobe it could have drawn: nested delta lobes
 * say their value (conductor, plastic; scene_page_blocker refuses the
 * others, and twosided refuses transmission). */
static color twosided_delta_value(const bsdf *b, const surface_interaction *si, unsigned lobe, vec3 wo,
                                  double *prob) {
  const twosided_bsdf *t = (const twosided_bsdf *)b;
  *prob = 0.0;
  if (!(si->wi.z != 0.0)) return col1(0.0);
  int side = si->wi.z < 0.0;
  const bsdf *n = t->brdf[side];
  if (!n->ops->delta_value) return col1(0.0);
  if (!side) return n->ops->delta_value(n, si, lobe, wo, prob);
  surface_interaction s = *si;
  s.wi = flip_z(si->wi);
  return n->ops->delta_value(n, &s, lobe, flip_z(wo), prob);
}

static const bsdf_ops twosided_ops = {.polarization = twosided_polarization,
                                      .delta_value = twosided_delta_value,
                                      .sample = twosided_sample,
                                      .eval = twosided_eval,
                                      .pdf = twosided_pdf,
                                      .sample_batch = twosided_sample_batch,
                                      .eval_pdf_batch = twosided_eval_pdf_batch};

static rsw_status twosided_create(loader *ld, node *n, object **out) {
  object **kids = NULL;
  size_t count = 0;
  rsw_status st = ld_children(ld, n, CLS_BSDF, &kids, &count);
  if (st != RSW_OK) return st;
  if (count == 0 || count > 2) {
    free(kids);
    return ld_fail(ld, n, NULL, count == 0 ? RSW_ERR_MISSING : RSW_ERR_INVALID,
                   "twosided '%s': expected one or two nested BSDFs, got %zu", n->id ? n->id : "", count);
  }
  bsdf *front = (bsdf *)kids[0];
  bsdf *back = count == 2 ? (bsdf *)kids[1] : front;
  free(kids);
  for (int i = 0; i < 2; i++) {
    const bsdf *c = i == 0 ? front : back;
    if (c->flags & TRANSMISSION_LOBES)
      return ld_fail(ld, n, NULL, RSW_ERR_INVALID,
                     "twosided '%s': nested BSDF '%s' (%s) has a transmission "
                     "component; only reflection models can be nested",
                     n->id ? n->id : "", c->base.id ? c->base.id : "?", c->base.plugin->name);
  }
  return plugin_created(ld, n, (object *)twosided_new(front, back), out);
}

static void twosided_traverse(object *o, param_visitor *v) {
  twosided_bsdf *t = (twosided_bsdf *)o;
  /* Mitsuba reports both slots; when the back is the front's object,
   * `brdf_1...` keys are aliases of the `brdf_0...` ones. */
  pv_object(v, "brdf_0", &t->brdf[0]->base, NAN, NAN);
  pv_object(v, "brdf_1", &t->brdf[1]->base, NAN, NAN);
}

DEFINE_PLUGIN(twosided, CLS_BSDF, .ops = &twosided_ops, .traverse = twosided_traverse);

bsdf *twosided_new(bsdf *front, bsdf *back) {
  if (!back) back = front;
  twosided_bsdf *t = BSDF_NEW(twosided_bsdf, twosided, front->flags | back->flags | BSDF_TWO_SIDED);
  if (!t) return NULL;
  t->brdf[0] = front;
  t->brdf[1] = back;
  return &t->base;
}
