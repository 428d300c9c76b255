/* `direct`: direct illumination only, as Mitsuba 3's direct integrator
 * (mitsuba3 src/integrators/direct.cpp). At the camera ray's first hit x:
 *   L = Le(x) + (1/n_e) sum_{k<n_e} w_e f Le / p_e  +  (1/n_b) sum_{k<n_b} w_b f Le / p_b,
 * n_e = emitter_samples light samples (pdf p_e: solid angle times the
 * emitter pick probability) and n_b = bsdf_samples BSDF samples whose ray
 * reaches an emitter (an area light, or the environment on a miss), with
 * Mitsuba's power-heuristic weights over the sample fractions
 *   w_e = w(p_e n_e / n, p_b n_b / n),  w_b = w(p_b n_b / n, p_e n_e / n),
 * n = n_e + n_b (w(a, b) = a^2 / (a^2 + b^2), integrators/integrator.h).
 * Delta lights and delta lobes have only one strategy: weight 1 (Mitsuba
 * gives a delta light weight 1 on each of its n_e samples without the
 * 1/n_e; here each takes 1/n_e, so the estimate does not grow with n_e).
 * `shading_samples` sets both counts (exclusive with them, default 1);
 * their sum must be positive. `hide_emitters` hides the emission seen by
 * the camera ray. Media are ignored (as Mitsuba's); Stokes films of the
 * unpolarized variants get no Q, U, V, the polarized variants carry the
 * BSDF's Mueller factors (integrators/polarization.h). */
#include <stdlib.h>

#include "../accel.h"
#include "../hit.h"
#include "../scene/periodic.h"
#include "../scene/plugin_def.h"
#include "../shapes/instance.h"
#include "../shapes/shape.h"
#include "integrator.h"
#include "pages.h"
#include "polarization.h"

typedef struct direct_integrator {
  integrator base;
  long long emitter_samples, bsdf_samples;
  double frac_e, frac_b; /* n_e / n, n_b / n */
} direct_integrator;

static trace_result trace(const scene *sc, const ray3 *r, surface_interaction *si, render_stats *stats) {
  accel_hit h;
  stats->rays++;
  ray3 seg = *r;
  double off;
  trace_result tr = scene_trace(sc, &seg, &h, &off);
  if (tr == TRACE_UNRESOLVED) stats->unresolved++;
  if (tr != TRACE_HIT) return tr;
  hit_fill_interaction(sc, &seg, &h, si);
  si->t += off;
  return TRACE_HIT;
}

/* One light sample at si: its numbers drawn (the pick, then u2), the
 * emitter *e picked with probability *pe, its direction sample *ds and its
 * value. *pe is 0 where the sample counts for nothing: a zero pdf, or a
 * surface emitter's point outside the periodic column (not in the scene,
 * as path.c). */
static color light_sample(const scene *sc, sampler_state *st, const surface_interaction *si,
                          const emitter **e, double *pe, vec2 *u2, direction_sample *ds) {
  const sampler_ops *sops = st->s->ops;
  double u = sops->next_1d(st);
  *u2 = sops->next_2d(st);
  size_t ei = pick_emitter_index(sc, u);
  *e = sc->emitters[ei];
  *pe = pick_probability(sc, ei);
  color value = (*e)->ops->sample_direction(*e, si, *u2, ds);
  const periodic_bounds *pb = &sc->periodic;
  if (!(ds->pdf > 0) ||
      (pb->on && ((*e)->flags & EMITTER_SURFACE) &&
       !(ds->p.x >= pb->min[0] && ds->p.x <= pb->max[0] && ds->p.y >= pb->min[1] && ds->p.y <= pb->max[1])))
    *pe = 0.0;
  return value;
}

/* Light samples: sum of w_e f Le / p_e over n_e samples, divided by n_e. */
static color light_samples(const direct_integrator *d, const scene *sc, sampler_state *st,
                           const surface_interaction *si, render_stats *stats, pol_lane *pl, vec3 pd) {
  const bsdf *b = si->shape->bsdf;
  color sum = col1(0);
  for (long long k = 0; k < d->emitter_samples; k++) {
    const emitter *e;
    double pe;
    vec2 u2;
    direction_sample ds;
    color value = light_sample(sc, st, si, &e, &pe, &u2, &ds);
    if (!(pe > 0) || col_is_black(value)) continue;
    vec3 wo = frame_to_local(&si->sh, ds.d);
    color f = b->ops->eval(b, si, wo);
    if (col_is_black(f)) continue;
    ray3 sray = spawn_ray_to(sc, si, e, &ds);
    stats->shadow_rays++;
    if (scene_occluded(sc, &sray) != TRACE_MISS) continue;
    double w = ds.delta ? 1.0 : mis_weight(ds.pdf * pe * d->frac_e, b->ops->pdf(b, si, wo) * d->frac_b);
    color v = col_scale(col_mul(f, value), w / pe);
    sum = col_add(sum, v);
    if (pl)
      pol_collect_light(pl, si, wo, 0, e, ds.d, pd, col_scale(v, 1.0 / (double)d->emitter_samples),
                        pol_channels(sc));
  }
  return col_scale(sum, 1.0 / (double)d->emitter_samples);
}

/* BSDF samples: sum of w_b f Le / p_b over n_b samples, divided by n_b. */
static color bsdf_samples(const direct_integrator *d, const scene *sc, sampler_state *st,
                          const surface_interaction *si, render_stats *stats, pol_lane *pl, vec3 pd) {
  const sampler_ops *sops = st->s->ops;
  const bsdf *b = si->shape->bsdf;
  color sum = col1(0);
  for (long long k = 0; k < d->bsdf_samples; k++) {
    double u1 = sops->next_1d(st);
    vec2 u2 = sops->next_2d(st);
    bsdf_sample bs;
    color weight = b->ops->sample(b, si, u1, u2, &bs);
    if (!(bs.pdf > 0) || col_is_black(weight)) continue;
    ray3 r = spawn_ray(si, frame_to_world(&si->sh, bs.wo));
    surface_interaction hit;
    trace_result tr = trace(sc, &r, &hit, stats);
    const emitter *e = NULL;
    direction_sample ds = {.d = v3_norm(r.d), .dist = INFINITY};
    color Le = col1(0);
    if (tr == TRACE_HIT && hit.shape->emitter) {
      e = hit.shape->emitter;
      Le = e->ops->eval(e, &hit, r.d);
      ds.p = hit.p, ds.n = hit.ng, ds.dist = hit.t * v3_len(r.d);
    } else if (tr == TRACE_MISS && sc->environment) {
      e = sc->environment;
      Le = e->ops->eval(e, NULL, r.d);
    }
    if (!e || col_is_black(Le)) continue;
    double pe =
        (bs.sampled_type & BSDF_DELTA) ? 0.0 : e->ops->pdf_direction(e, si, &ds) * emitter_prob(sc, e);
    double w = mis_weight(bs.pdf * d->frac_b, pe * d->frac_e);
    color v = col_scale(col_mul(weight, Le), w);
    sum = col_add(sum, v);
    if (pl)
      pol_collect_light(pl, si, bs.wo, bs.sampled_type, e, ds.d, pd,
                        col_scale(v, 1.0 / (double)d->bsdf_samples), pol_channels(sc));
  }
  return col_scale(sum, 1.0 / (double)d->bsdf_samples);
}

/* The unpolarized estimate (pl NULL), or also the Stokes vectors into
 * *pl (the polarized variants). */
static color direct_L(const direct_integrator *d, const scene *sc, sampler_state *st, ray3 ray,
                      render_stats *stats, pol_lane *pl) {
  const integrator *it = &d->base;
  surface_interaction si;
  trace_result tr = trace(sc, &ray, &si, stats);
  if (tr != TRACE_HIT) {
    if (tr == TRACE_MISS && sc->environment && !it->hide_emitters) {
      color Le = sc->environment->ops->eval(sc->environment, NULL, ray.d);
      if (pl) pol_add_env(pl, sc->environment, ray.d, Le, Le, pol_channels(sc));
      return Le;
    }
    return col1(0);
  }
  color L = col1(0);
  const emitter *em = si.shape->emitter;
  if (em && !it->hide_emitters) L = em->ops->eval(em, &si, ray.d);
  if (pl) pol_add(pl, L, pol_channels(sc));
  vec3 pd = v3_neg(v3_norm(ray.d));
  if (d->emitter_samples > 0 && sc->n_emitters > 0 && (si.shape->bsdf->flags & BSDF_SMOOTH))
    L = col_add(L, light_samples(d, sc, st, &si, stats, pl, pd));
  if (d->bsdf_samples > 0) L = col_add(L, bsdf_samples(d, sc, st, &si, stats, pl, pd));
  return L;
}

/* Each page's value of emitter e (seen along d at si, or sampled with u2
 * at the shading point si: sample) into v[1..pages), page 0's given. */
static void emitter_pages(const scene *sc, const emitter *e, const surface_interaction *si, vec3 d,
                          bool sample, vec2 u2, color *v) {
  for (int p = 1; p < sc->pages; p++) {
    rsw_page = p;
    direction_sample ds;
    v[p] = sample ? e->ops->sample_direction(e, si, u2, &ds) : e->ops->eval(e, si, d);
  }
  rsw_page = 0;
}

/* A bundle of pages (render_ctx.bundle > 3, docs/experiments.md#spectral-bundles):
 * the estimate at every page into Lp[0..pages), one path for all. The
 * light samples' picks and directions are drawn once and each page takes
 * its emitter's and BSDF's values there; the BSDF samples are drawn from
 * one page and every page weighted by its own value over the pages' mean
 * pdf (integrators/pages.h); both strategies' MIS weights use that mean
 * pdf, the same at every page, so that they sum to 1 for any direction.
 * The numbers are drawn in the order of direct_L. */
static void direct_pages(const direct_integrator *d, const scene *sc, sampler_state *st, ray3 ray,
                         render_stats *stats, color *Lp) {
  const int NP = sc->pages;
  const integrator *it = &d->base;
  const sampler_ops *sops = st->s->ops;
  color v[RENDER_MAX_PAGES], f[RENDER_MAX_PAGES], sum[RENDER_MAX_PAGES];
  for (int p = 0; p < NP; p++) Lp[p] = col1(0);
  surface_interaction si;
  trace_result tr = trace(sc, &ray, &si, stats);
  if (tr != TRACE_HIT) {
    if (tr == TRACE_MISS && sc->environment && !it->hide_emitters) {
      Lp[0] = sc->environment->ops->eval(sc->environment, NULL, ray.d);
      emitter_pages(sc, sc->environment, NULL, ray.d, false, v2(0, 0), Lp);
    }
    return;
  }
  const emitter *em = si.shape->emitter;
  if (em && !it->hide_emitters) {
    Lp[0] = em->ops->eval(em, &si, ray.d);
    emitter_pages(sc, em, &si, ray.d, false, v2(0, 0), Lp);
  }
  const bsdf *b = si.shape->bsdf;
  if (d->emitter_samples > 0 && sc->n_emitters > 0 && (b->flags & BSDF_SMOOTH)) {
    for (int p = 0; p < NP; p++) sum[p] = col1(0);
    for (long long k = 0; k < d->emitter_samples; k++) {
      const emitter *e;
      double pe;
      vec2 u2;
      direction_sample ds;
      v[0] = light_sample(sc, st, &si, &e, &pe, &u2, &ds);
      if (!(pe > 0)) continue;
      emitter_pages(sc, e, &si, ds.d, true, u2, v);
      vec3 wo = frame_to_local(&si.sh, ds.d);
      double pdf = bsdf_eval_pages(b, &si, NP, wo, !ds.delta, f);
      bool lit = false;
      for (int p = 0; p < NP; p++) lit |= !col_is_black(col_mul(f[p], v[p]));
      if (!lit) continue;
      ray3 sray = spawn_ray_to(sc, &si, e, &ds);
      stats->shadow_rays++;
      if (scene_occluded(sc, &sray) != TRACE_MISS) continue;
      double w = ds.delta ? 1.0 : mis_weight(ds.pdf * pe * d->frac_e, pdf * d->frac_b);
      for (int p = 0; p < NP; p++) sum[p] = col_add(sum[p], col_scale(col_mul(f[p], v[p]), w / pe));
    }
    for (int p = 0; p < NP; p++) Lp[p] = col_add(Lp[p], col_scale(sum[p], 1.0 / (double)d->emitter_samples));
  }
  if (d->bsdf_samples > 0) {
    for (int p = 0; p < NP; p++) sum[p] = col1(0);
    for (long long k = 0; k < d->bsdf_samples; k++) {
      double u1 = sops->next_1d(st);
      vec2 u2 = sops->next_2d(st);
      bsdf_sample bs;
      bsdf_sample_pages(b, &si, NP, u1, u2, &bs, f);
      if (!(bs.pdf > 0)) continue;
      ray3 r = spawn_ray(&si, frame_to_world(&si.sh, bs.wo));
      surface_interaction hit;
      trace_result th = trace(sc, &r, &hit, stats);
      const emitter *e = NULL;
      direction_sample ds = {.d = v3_norm(r.d), .dist = INFINITY};
      if (th == TRACE_HIT && hit.shape->emitter) {
        e = hit.shape->emitter;
        v[0] = e->ops->eval(e, &hit, r.d);
        ds.p = hit.p, ds.n = hit.ng, ds.dist = hit.t * v3_len(r.d);
      } else if (th == TRACE_MISS && sc->environment) {
        e = sc->environment;
        v[0] = e->ops->eval(e, NULL, r.d);
      }
      if (!e) continue;
      emitter_pages(sc, e, th == TRACE_HIT ? &hit : NULL, r.d, false, v2(0, 0), v);
      double pe =
          (bs.sampled_type & BSDF_DELTA) ? 0.0 : e->ops->pdf_direction(e, &si, &ds) * emitter_prob(sc, e);
      double w = mis_weight(bs.pdf * d->frac_b, pe * d->frac_e);
      for (int p = 0; p < NP; p++) sum[p] = col_add(sum[p], col_scale(col_mul(f[p], v[p]), w));
    }
    for (int p = 0; p < NP; p++) Lp[p] = col_add(Lp[p], col_scale(sum[p], 1.0 / (double)d->bsdf_samples));
  }
}

static color direct_Li(const integrator *it, const scene *sc, sampler_state *st, ray3 ray,
                       render_stats *stats, double *quv) {
  const direct_integrator *d = (const direct_integrator *)it;
  if (sc->pages > 1 && !sc->polarized) { /* pages 1.. into quv (scene_extra_stride) */
    color Lp[RENDER_MAX_PAGES];
    direct_pages(d, sc, st, ray, stats, Lp);
    for (int p = 1; quv && p < sc->pages; p++)
      for (int c = 0; c < 3; c++) quv[3 * (p - 1) + c] += Lp[p].c[c];
    return Lp[0];
  }
  if (!sc->polarized) return direct_L(d, sc, st, ray, stats, NULL);
  mueller pm[3];
  pol_lane pl = {.M = pm};
  int nch = pol_channels(sc);
  pol_start(&pl, ray.d, nch);
  (void)direct_L(d, sc, st, ray, stats, &pl);
  color S0;
  double q[SCENE_QUV_MAX];
  pol_result(&pl, nch, &S0, q);
  if (quv)
    for (int k = 0; k < scene_quv_stride(sc); k++) quv[k] += q[k];
  return S0;
}

static const integrator_ops direct_ops = {.Li = direct_Li};

DEFINE_PLUGIN(direct, CLS_INTEGRATOR, .ops = &direct_ops);

static rsw_status direct_create(loader *ld, node *n, object **out) {
  if (ld_has(n, "shading_samples") && (ld_has(n, "emitter_samples") || ld_has(n, "bsdf_samples")))
    return ld_fail(ld, n, "shading_samples", RSW_ERR_INVALID,
                   "give either 'shading_samples' or 'emitter_samples' / 'bsdf_samples', not both");
  long long shading, ne, nb;
  bool hide;
  rsw_status st = ld_int(ld, n, "shading_samples", 1, 0, 1 << 20, &shading);
  if (!st) st = ld_int(ld, n, "emitter_samples", shading, 0, 1 << 20, &ne);
  if (!st) st = ld_int(ld, n, "bsdf_samples", shading, 0, 1 << 20, &nb);
  if (!st) st = ld_bool(ld, n, "hide_emitters", false, &hide);
  if (st) return st;
  if (ne + nb == 0)
    return ld_fail(ld, n, "emitter_samples", RSW_ERR_INVALID,
                   "emitter_samples + bsdf_samples must be at least 1");
  direct_integrator *d = PLUGIN_NEW(direct_integrator, direct);
  if (!d) return plugin_created(ld, n, NULL, out);
  d->base.ops = &direct_ops;
  d->base.max_depth = 2;
  d->base.rr_depth = 1 << 30;
  d->base.hide_emitters = hide;
  d->base.pages = true; /* (direct_pages) */
  d->emitter_samples = ne;
  d->bsdf_samples = nb;
  d->frac_e = (double)ne / (double)(ne + nb);
  d->frac_b = (double)nb / (double)(ne + nb);
  return plugin_created(ld, n, &d->base.base, out);
}
