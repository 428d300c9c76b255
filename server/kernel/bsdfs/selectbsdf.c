/* `selectbsdf`: one of N >= 2 nested BSDFs, chosen at each point by an
 * index texture (eradiate/mitsuba3 src/eradiate_plugins/bsdfs/selectbsdf.cpp;
 * docs/kernel-conventions.md#selectbsdf).
 *
 * index = (unsigned) indices(si) (the first channel, truncated as
 * Mitsuba's UInt32 cast does); sample / eval / pdf are the chosen BSDF's.
 * An index outside [0, N) (or NaN) selects nothing: black, pdf 0 (Dr.Jit's
 * out-of-range gather; a constant index is checked at load). The nested
 * BSDFs are taken in declaration order and reported as bsdf_0 ...
 * bsdf_{N-1}; `indices` is not differentiable in Eradiate and is a
 * parameter here like any texture. For a bitmap of indices use
 * filter_type "nearest" (and raw), as Eradiate advises. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "../scene/loader.h"
#include "../scene/params.h"
#include "../textures/texture.h"
#include "eo_surfaces.h"
#include "fresnel_pol.h"

typedef struct selectbsdf {
  bsdf base;
  texture *indices;
  size_t n;
  bsdf **kids;
} selectbsdf;

static const bsdf *pick(const selectbsdf *s, const surface_interaction *si) {
  double v = tex_eval(s->indices, si).c[0];
  if (!(v >= 0.0) || !(v < (double)s->n + 1.0)) return NULL;
  size_t i = (size_t)v;
  return i < s->n ? s->kids[i] : NULL;
}

static color sel_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  const bsdf *k = pick((const selectbsdf *)b, si);
  if (!k) return bsdf_fail(bs);
  return k->ops->sample(k, si, u1, u2, bs);
}

static color sel_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const bsdf *k = pick((const selectbsdf *)b, si);
  return k ? k->ops->eval(k, si, wo) : col1(0.0);
}

static double sel_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const bsdf *k = pick((const selectbsdf *)b, si);
  return k ? k->ops->pdf(k, si, wo) : 0.0;
}

/* Polarization (docs/plugins.md#polarization-surfaces): the chosen BSDF's; none
 * chosen (black) depolarizes. */
static void sel_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                             mueller P[3], vec3 *s_in, vec3 *s_out) {
  const bsdf *k = pick((const selectbsdf *)b, si);
  if (k)
    fpol_forward(k, si, wo, lobe, P, s_in, s_out);
  else
    fpol_depolarize(P, wo, si->wi, s_in, s_out);
}

/* A bundle of pages (bsdf_ops.delta_value): the picked BSDF's (sel_pages:
 * every component's delta lobes say their values). */
static color sel_delta_value(const bsdf *b, const surface_interaction *si, unsigned lobe, vec3 wo,
                             double *prob) {
  const bsdf *k = pick((const selectbsdf *)b, si);
  *prob = 0.0;
  return k && k->ops->delta_value ? k->ops->delta_value(k, si, lobe, wo, prob) : col1(0.0);
}

static const bsdf_ops sel_ops = {.sample = sel_sample,
                                 .eval = sel_eval,
                                 .pdf = sel_pdf,
                                 .polarization = sel_polarization,
                                 .delta_value = sel_delta_value};

static void sel_destroy(object *o) {
  if (o) free(((selectbsdf *)o)->kids);
  free(o);
}

static rsw_status sel_create(loader *ld, node *n, object **out) {
  if (!ld_has(n, "indices"))
    return ld_fail(ld, n, "indices", RSW_ERR_MISSING,
                   "selectbsdf needs 'indices' (a texture of BSDF indices)");
  texture *idx;
  rsw_status st = ld_texture(ld, n, "indices", 0.0, 0.0, &idx);
  if (st) return st;
  object **kids = NULL;
  size_t count = 0;
  if ((st = ld_children(ld, n, CLS_BSDF, &kids, &count)) != RSW_OK) return st;
  if (count < 2) {
    free(kids);
    return ld_fail(ld, n, NULL, count == 0 ? RSW_ERR_MISSING : RSW_ERR_INVALID,
                   "selectbsdf '%s': at least two nested BSDFs are needed, got %zu", n->id ? n->id : "",
                   count);
  }
  color c;
  if (uniform_texture_value(idx, &c) && !(c.c[0] >= 0.0 && (size_t)c.c[0] < count)) {
    free(kids);
    return ld_fail(ld, n, "indices", RSW_ERR_RANGE, "selectbsdf: index %g selects none of the %zu BSDFs",
                   c.c[0], count);
  }
  selectbsdf *s = calloc(1, sizeof *s);
  if (!s) {
    free(kids);
    return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "selectbsdf: out of memory");
  }
  s->base.base.plugin = &plugin_selectbsdf;
  s->base.base.id = n->id;
  s->base.ops = &sel_ops;
  s->indices = idx;
  s->n = count;
  s->kids = (bsdf **)kids;
  for (size_t i = 0; i < count; i++) s->base.flags |= s->kids[i]->flags;
  *out = &s->base.base;
  return RSW_OK;
}

static void sel_traverse(object *o, param_visitor *v) {
  selectbsdf *s = (selectbsdf *)o;
  pv_object(v, "indices", &s->indices->base, 0.0, INFINITY);
  for (size_t i = 0; i < s->n; i++) {
    char name[32];
    snprintf(name, sizeof name, "bsdf_%zu", i);
    pv_object(v, name, &s->kids[i]->base, NAN, NAN);
  }
}

/* Whether a bundle of pages can weigh its delta lobes (scene_page_blocker):
 * every component's delta lobes say their values. */
static bool sel_pages(const object *o) {
  const selectbsdf *s = (const selectbsdf *)o;
  for (size_t i = 0; i < s->n; i++)
    if ((s->kids[i]->flags & BSDF_DELTA) && !s->kids[i]->ops->delta_value) return false;
  return true;
}

const plugin plugin_selectbsdf = {
    .name = "selectbsdf",
    .cls = CLS_BSDF,
    .create = sel_create,
    .destroy = sel_destroy,
    .pages = sel_pages,
    .ops = &sel_ops,
    .traverse = sel_traverse,
};
