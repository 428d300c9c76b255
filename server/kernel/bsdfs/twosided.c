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
 * Source: mitsuba3 src/bsdfs/twosided.cpp; kernel-behavior.md §2.3. */
#include <stdlib.h>

#include "../scene/loader.h"
#include "../scene/params.h"
#include "bsdfs_internal.h"

#define TRANSMISSION_LOBES (BSDF_DIFFUSE_TRANSMISSION | BSDF_GLOSSY_TRANSMISSION | BSDF_DELTA_TRANSMISSION)

static vec3 flip_z(vec3 v) {
  return v3(v.x, v.y, -v.z);
}

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

static const bsdf_ops twosided_ops = {.sample = twosided_sample, .eval = twosided_eval, .pdf = twosided_pdf};

static void twosided_destroy(object *o) {
  free(o);
}

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
  bsdf *b = twosided_new(front, back);
  if (!b) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "twosided: out of memory");
  b->base.id = n->id;
  *out = &b->base;
  return RSW_OK;
}

static void twosided_traverse(object *o, param_visitor *v) {
  twosided_bsdf *t = (twosided_bsdf *)o;
  /* Mitsuba reports both slots; when the back is the front's object,
   * `brdf_1...` keys are aliases of the `brdf_0...` ones. */
  pv_object(v, "brdf_0", &t->brdf[0]->base, NAN, NAN);
  pv_object(v, "brdf_1", &t->brdf[1]->base, NAN, NAN);
}

const plugin plugin_twosided = {
    .name = "twosided",
    .cls = CLS_BSDF,
    .create = twosided_create,
    .destroy = twosided_destroy,
    .ops = &twosided_ops,
    .traverse = twosided_traverse,
};

bsdf *twosided_new(bsdf *front, bsdf *back) {
  twosided_bsdf *t = calloc(1, sizeof *t);
  if (!t) return NULL;
  t->base.base.plugin = &plugin_twosided;
  t->base.ops = &twosided_ops;
  t->brdf[0] = front;
  t->brdf[1] = back ? back : front;
  t->base.flags = t->brdf[0]->flags | t->brdf[1]->flags | BSDF_TWO_SIDED;
  return &t->base;
}
