/* `path`: unidirectional path tracer with next-event estimation and
 * multiple importance sampling, following Mitsuba 3's path integrator loop
 * (mitsuba3 src/integrators/path.cpp; kernel-behavior.md §2.4).
 *
 * Estimator: L = sum over path vertices of T * (Le w_bsdf + NEE w_em), with
 * T the product of BSDF sample weights f |cos| / pdf, power-heuristic MIS
 * weights w(a, b) = a^2 / (a^2 + b^2) between emitter sampling (solid-angle
 * pdf times the emitter selection probability) and BSDF sampling. Delta
 * emitters and delta BSDF lobes take weight 1 on their only strategy.
 * Russian roulette from depth rr_depth with survival probability
 * q = min(max(T) eta^2, 0.95). */
#include <stdlib.h>

#include "../accel.h"
#include "../scene/loader.h"
#include "../scene/periodic.h"
#include "../shapes/instance.h"
#include "../shapes/shape.h"

static inline double mis_weight(double a, double b) {
  a *= a;
  b *= b;
  double w = a / (a + b);
  return isfinite(w) ? w : 0.0;
}

/* Shadow ray from si towards the emitter sample ds. Spawned rays are
 * offset by the hit point's float error, not by Mitsuba's (1 + max|p|)
 * RayEpsilon (shapes/shape.h spawn_ray). A point on a surface emitter gets
 * the same treatment at the light's end (spawn_ray_between); for other
 * emitters the ray stops short of ds.dist by ShadowEpsilon (relative), as
 * Mitsuba. */
static ray3 spawn_ray_to(const scene *sc, const surface_interaction *si, const emitter *e,
                         const direction_sample *ds) {
  if ((e->flags & EMITTER_SURFACE) && e->shape) {
    const shape *ls = e->shape;
    return spawn_ray_between(si, ds->p, ds->n,
                             accel_surface_error(sc->accel, ls->index, &ls->to_world, ds->p, ds->n));
  }
  ray3 r = spawn_ray(si, ds->d);
  r.tmax = isfinite(ds->dist) ? ds->dist * (1.0 - RSW_SHADOW_EPSILON) : INFINITY;
  return r;
}

/* p lies in the periodic column (walls included). */
static inline bool in_column(const periodic_bounds *b, vec3 p) {
  return p.x >= b->min[0] && p.x <= b->max[0] && p.y >= b->min[1] && p.y <= b->max[1];
}

/* TRACE_UNRESOLVED (periodic scenes, scene/periodic.h): the ray neither
 * hit nor escaped; the path ends there, without environment light.
 * *wrapped: the hit was reached through the periodic boundary (a copy of
 * the shape in another cell). */
static trace_result intersect(const scene *sc, const ray3 *r, surface_interaction *si, render_stats *stats,
                              bool *wrapped) {
  accel_hit h;
  stats->rays++;
  ray3 seg = *r;
  double off;
  trace_result tr = scene_trace(sc, &seg, &h, &off);
  if (tr != TRACE_HIT) {
    if (tr == TRACE_UNRESOLVED) stats->unresolved++;
    return tr;
  }
  hit_fill_interaction(sc, &seg, &h, si);
  si->t += off; /* distance along the whole (possibly wrapped) ray */
  *wrapped = off > 0;
  return TRACE_HIT;
}

/* Pick an emitter proportionally to sampling_weight; returns its index and
 * the selection probability. */
static size_t pick_emitter(const scene *sc, double u, double *prob) {
  double t = u * sc->emitter_weight_sum;
  size_t lo = 0, hi = sc->n_emitters - 1;
  while (lo < hi) {
    size_t mid = (lo + hi) / 2;
    if (sc->emitter_cdf[mid] <= t)
      lo = mid + 1;
    else
      hi = mid;
  }
  *prob = sc->emitters[lo]->sampling_weight / sc->emitter_weight_sum;
  return lo;
}

static double emitter_prob(const scene *sc, const emitter *e) {
  return sc->emitter_weight_sum > 0 ? e->sampling_weight / sc->emitter_weight_sum : 0.0;
}

/* Stokes films: only an environment that reports polarisation carries Q,
 * U, V; they are scaled by the path throughput's intensity (BSDFs are
 * treated as non-polarising and the frame is not rotated along the path —
 * a stated simplification until a polarised integrator exists). */
static void add_polarization(double *quv, const emitter *e, vec3 d, double scale) {
  if (!quv || !e->ops->eval_polarization || scale == 0) return;
  double q[3] = {0, 0, 0};
  e->ops->eval_polarization(e, d, q);
  for (int k = 0; k < 3; k++) quv[k] += scale * q[k];
}

static color path_Li(const integrator *it, const scene *sc, sampler_state *st, ray3 ray, render_stats *stats,
                     double *quv) {
  const sampler_ops *sops = st->s->ops;
  color L = col1(0), T = col1(1);
  if (it->max_depth == 0) return L;
  double eta = 1.0, prev_pdf = 1.0;
  bool prev_delta = true;
  surface_interaction si, prev_si;
  int depth = 0;
  bool wrapped = false;
  trace_result hit = intersect(sc, &ray, &si, stats, &wrapped);
  for (;;) {
    /* Emission seen by this ray (area light or the environment). */
    bool visible_emitter = !(it->hide_emitters && depth == 0);
    if (hit != TRACE_HIT) {
      const emitter *env = sc->environment;
      if (env && visible_emitter && hit == TRACE_MISS) {
        double em_pdf = 0.0;
        if (!prev_delta) {
          direction_sample ds = {.d = v3_norm(ray.d), .dist = INFINITY};
          em_pdf = env->ops->pdf_direction(env, &prev_si, &ds) * emitter_prob(sc, env);
        }
        color Le = env->ops->eval(env, NULL, ray.d);
        double w = mis_weight(prev_pdf, em_pdf);
        L = col_add(L, col_scale(col_mul(T, Le), w));
        add_polarization(quv, env, v3_norm(ray.d), T.c[0] * w);
      }
      break;
    }
    const emitter *em = si.shape->emitter;
    if (em && visible_emitter) {
      color Le = em->ops->eval(em, &si, ray.d);
      if (!col_is_black(Le)) {
        double em_pdf = 0.0;
        /* Next-event estimation samples the emitter in the column only,
         * along a segment that never wraps: a copy reached through the
         * periodic boundary is BSDF sampling's alone (weight 1). */
        if (!prev_delta && !wrapped) {
          direction_sample ds = {.p = si.p, .n = si.ng, .d = v3_norm(ray.d), .dist = si.t * v3_len(ray.d)};
          em_pdf = em->ops->pdf_direction(em, &prev_si, &ds) * emitter_prob(sc, em);
        }
        L = col_add(L, col_scale(col_mul(T, Le), mis_weight(prev_pdf, em_pdf)));
      }
    }
    if (!(it->max_depth < 0 || depth + 1 < it->max_depth)) break;
    const bsdf *b = si.shape->bsdf;

    /* Next-event estimation towards one emitter. */
    if ((b->flags & BSDF_SMOOTH) && sc->n_emitters > 0) {
      double pe;
      size_t k = pick_emitter(sc, sops->next_1d(st), &pe);
      const emitter *e = sc->emitters[k];
      direction_sample ds;
      color value = e->ops->sample_direction(e, &si, sops->next_2d(st), &ds);
      /* Under `periodic`, the part of a surface emitter outside the column
       * is not in the scene (scene/periodic.h): a light sample there
       * counts zero. The in-column part keeps its density 1/area, which
       * is what pdf_direction gives an unwrapped emitter hit; its copies
       * beyond the walls are reached by BSDF sampling alone (weight 1). */
      if (sc->periodic.on && (e->flags & EMITTER_SURFACE) && !in_column(&sc->periodic, ds.p)) ds.pdf = 0;
      if (ds.pdf > 0 && !col_is_black(value)) {
        ray3 sr = spawn_ray_to(sc, &si, e, &ds);
        stats->shadow_rays++;
        /* Infinitely distant emitters give dist = INFINITY: the shadow ray
         * is unbounded (in a periodic scene, cut only by leaving the
         * slab). An unresolved one counts as blocked, never as lit. */
        trace_result occ = scene_occluded(sc, &sr);
        if (occ == TRACE_UNRESOLVED) stats->unresolved++;
        if (occ == TRACE_MISS) {
          vec3 wo = frame_to_local(&si.sh, ds.d);
          color f = b->ops->eval(b, &si, wo);
          if (!col_is_black(f)) {
            double w = ds.delta ? 1.0 : mis_weight(ds.pdf * pe, b->ops->pdf(b, &si, wo));
            L = col_add(L, col_scale(col_mul(T, col_mul(f, value)), w / pe));
            if (quv && (e->flags & EMITTER_INFINITE))
              add_polarization(quv, e, ds.d, T.c[0] * f.c[0] * w / (pe * ds.pdf));
          }
        }
      }
    }

    /* Continue the path by sampling the BSDF. */
    bsdf_sample bs;
    double u1 = sops->next_1d(st);
    vec2 u2 = sops->next_2d(st);
    color weight = b->ops->sample(b, &si, u1, u2, &bs);
    if (!(bs.pdf > 0) || col_is_black(weight)) break;
    vec3 wo_world = frame_to_world(&si.sh, bs.wo);
    ray = spawn_ray(&si, wo_world);
    T = col_mul(T, weight);
    eta *= bs.eta;
    prev_si = si;
    prev_pdf = bs.pdf;
    prev_delta = (bs.sampled_type & BSDF_DELTA) != 0;
    depth++;
    if (depth >= it->rr_depth) {
      double q = fmin(col_max(T) * eta * eta, 0.95);
      if (!(sops->next_1d(st) < q)) break;
      T = col_scale(T, 1.0 / q);
    }
    if (!(col_max(T) > 0)) break;
    hit = intersect(sc, &ray, &si, stats, &wrapped);
  }
  return L;
}

static const integrator_ops path_ops = {.Li = path_Li};

static void path_destroy(object *o) {
  free(o);
}

static rsw_status path_create(loader *ld, node *n, object **out) {
  integrator *it = calloc(1, sizeof *it);
  if (!it) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  it->ops = &path_ops;
  long long md, rr;
  rsw_status st = ld_int(ld, n, "max_depth", -1, -1, 1 << 30, &md);
  if (!st) st = ld_int(ld, n, "rr_depth", 5, 1, 1 << 30, &rr);
  if (!st) st = ld_bool(ld, n, "hide_emitters", false, &it->hide_emitters);
  if (st) {
    free(it);
    return st;
  }
  it->max_depth = (int)md;
  it->rr_depth = (int)rr;
  *out = &it->base;
  return RSW_OK;
}

const plugin plugin_path = {
    .name = "path", .cls = CLS_INTEGRATOR, .create = path_create, .destroy = path_destroy, .ops = &path_ops};
