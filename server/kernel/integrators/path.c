/* `path`: unidirectional path tracer with next-event estimation and
 * multiple importance sampling, following Mitsuba 3's path integrator loop
 * (mitsuba3 src/integrators/path.cpp; docs/kernel-conventions.md#path).
 *
 * Estimator: L = sum over path vertices of T * (Le w_bsdf + NEE w_em), with
 * T the product of BSDF sample weights f |cos| / pdf, power-heuristic MIS
 * weights w(a, b) = a^2 / (a^2 + b^2) between emitter sampling (solid-angle
 * pdf times the emitter selection probability) and BSDF sampling. Delta
 * emitters and delta BSDF lobes take weight 1 on their only strategy.
 * Russian roulette from depth rr_depth with survival probability
 * q = min(max(T) eta^2, 0.95). */
#include <stdlib.h>
#include <time.h>

#include "../accel.h"
#include "../hit.h"
#include "../samplers/sampler_batch.h"
#include "../scene/periodic.h"
#include "../scene/plugin_def.h"
#include "../shapes/instance.h"
#include "../shapes/shape.h"
#include "cull.h"
#include "cull_lanes.h"
#include "integrator.h"
#include "pages.h"
#include "polarization.h"
#include "wave.h"

/* Shadow ray from si towards the emitter sample ds. Spawned rays are
 * offset by the hit point's float error, not by Mitsuba's (1 + max|p|)
 * RayEpsilon (shapes/shape.h spawn_ray). A point on a surface emitter gets
 * the same treatment at the light's end (spawn_ray_between); for other
 * emitters the ray stops short of ds.dist by ShadowEpsilon (relative), as
 * Mitsuba. */
static inline void spawn_ray_to_far(const surface_interaction *si, const direction_sample *ds, ray3 *r) {
  r->o = offset_on_side(si->p, si->ng, si->p_error, ds->d);
  r->d = ds->d;
  r->tmin = 0.0;
  r->tmax = isfinite(ds->dist) ? ds->dist * (1.0 - RSW_SHADOW_EPSILON) : INFINITY;
}

static inline void spawn_ray_to_in(const scene *sc, const surface_interaction *si, const emitter *e,
                                   const direction_sample *ds, ray3 *r) {
  if ((e->flags & EMITTER_SURFACE) && e->shape) {
    const shape *ls = e->shape;
    *r = spawn_ray_between(si, ds->p, ds->n,
                           accel_surface_error(sc->accel, ls->index, &ls->to_world, ds->p, ds->n));
    return;
  }
  spawn_ray_to_far(si, ds, r);
}

ray3 spawn_ray_to(const scene *sc, const surface_interaction *si, const emitter *e,
                  const direction_sample *ds) {
  ray3 r;
  spawn_ray_to_in(sc, si, e, ds, &r);
  return r;
}

/* p lies in the periodic column (walls included). */
static inline bool in_column(const periodic_bounds *b, vec3 p) {
  return p.x >= b->min[0] && p.x <= b->max[0] && p.y >= b->min[1] && p.y <= b->max[1];
}

/* Stokes films of the unpolarized variants (mono, pixel_format "stokes"):
 * only an environment that reports polarisation carries Q, U, V; they are
 * scaled by the path throughput's intensity (BSDFs are treated as
 * non-polarising and the frame is not rotated along the path). The
 * polarized variants do it properly (integrators/polarization.h). */
static void add_polarization(double *quv, const emitter *e, vec3 d, double scale) {
  if (!quv || !e->ops->eval_polarization || scale == 0) return;
  double q[3] = {0, 0, 0};
  e->ops->eval_polarization(e, d, q);
  for (int k = 0; k < 3; k++) quv[k] += scale * q[k];
}

/* ---- the wave ------------------------------------------------------------
 *
 * Paths advance together, bounce by bounce (a wavefront): every live path's
 * ray is traced (as Embree packets of neighbouring paths, accel.h, or one
 * by one through the periodic boundary), then every hit is shaded and its
 * next-event shadow ray emitted, the shadow rays are traced together, then
 * each path finishes its light sample, samples its BSDF and emits its
 * continuation ray; paths that ended drop out of the live list (kept in
 * lane order). Each path draws its random numbers from its own sampler
 * state in exactly the order of the one-path loop (light pick, light
 * sample, BSDF lobe, BSDF direction, roulette), and the shading arithmetic
 * is the same per lane, so a path's value does not depend on its batch;
 * Li is the wave of one path.
 *
 * BSDF values and pdfs towards the light samples, then BSDF samples, are
 * taken for all live lanes together, grouped by BSDF, through
 * bsdf_ops.eval_pdf_batch and sample_batch where a BSDF has them (vectorised at the
 * render's ISA, core/isa.h; roughconductor), after every lane has drawn
 * its numbers; a lane's value still depends on its own state only.
 *
 * Precision: shading stays in double (the plugins' scalar ops, and the
 * batched samplers' pdfs and weights); the batched samplers place a sample
 * in single precision, and roughconductor's batched eval/pdf towards a
 * light sample is single precision up to Fresnel (bsdfs/microfacet_lanes.h
 * says why both are safe); the path throughput and L stay double; Embree
 * traces in float32 behind fill_ray (accel.c). Contributions are summed
 * per path in double, in bounce order. */

typedef struct lane {
  /* What every bounce reads and writes first (wave_run's start and end
   * touch these alone): together, so a lane's pass over them touches few
   * cache lines; the BSDF sample and the previous vertex, which the seed
   * scene's paths rarely reach, last. */
  ray3 ray;
  color T, L;
  double eta, prev_pdf;
  /* wrapped: the hit was reached through the periodic boundary (a copy of
   * the shape in another cell). */
  bool prev_delta, wrapped;
  int depth;
  trace_result hit;
  /* Next-event estimation between the shading and the shading's end. */
  bool nee;
  trace_result occ;
  surface_interaction si;
  accel_hit h; /* the hit, between the packet queries and the surface data */
  const emitter *ne;
  double pe;
  color value;
  direction_sample ds;
  /* The light sample's BSDF value and pdf (wave_eval_bsdfs). */
  vec3 nwo;
  color nf;
  double npdf;
  ray3 sray;
  /* The BSDF sample: its random numbers, then its result. */
  double u1;
  vec2 u2;
  bsdf_sample bs;
  color weight;
  surface_interaction prev_si;
} lane;

/* A bundle of pages (render_ctx.bundle > 3, docs/experiments.md#spectral-bundles):
 * a lane's throughput and radiance at pages 1.. (page 0's are the lane's
 * T and L) and what its vertex computes for them. The path is sampled
 * once for all pages: the BSDF direction from one page picked by the lobe
 * number (one-sample spectral MIS, Wilkie et al. 2014: every page's value
 * over the pages' mean pdf, so a direction any page can sample is
 * counted), the light sample and the roulette shared; an object answers
 * for page p while rsw_page = p. */
typedef struct page_lane {
  color T[RENDER_MAX_PAGES - 1], L[RENDER_MAX_PAGES - 1];
  color value[RENDER_MAX_PAGES - 1];  /* the light sample's emitted value */
  color nf[RENDER_MAX_PAGES - 1];     /* the BSDF towards the light sample */
  color weight[RENDER_MAX_PAGES - 1]; /* the BSDF sample's weight */
} page_lane;

static double clock_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* Trace the rays of the live lanes idx[0..n): packets of consecutive live
 * lanes, or one by one under a periodic boundary (scene_trace walks the
 * walls per ray). */
/* Rays that cannot meet the scene's geometry need no query: a continuation
 * or shadow ray leaving the top of an Earth-observation scene for the sky
 * (the seed scene's every ray but the camera's). The test is a slab test
 * in double against the scene's bounding box padded by `pad` (scene_pad):
 * more than Embree's float32 placement of the geometry can move it, and
 * less than the RSW_SPAWN_ERRORS surface errors a spawned ray starts off
 * its surface (shapes/shape.h spawn_ray), so a ray leaving a face of the
 * box outwards is culled and one that Embree could see hit something never
 * is. Not under a periodic boundary (copies of the scene beyond the box).
 * Measured: a full slab test (three divisions per ray) cost more than the
 * queries it saved on the seed scene. */
static double scene_pad(const scene *sc) {
  vec3 lo = sc->bbox_min, hi = sc->bbox_max;
  double m = fmax(v3_max_abs(lo), v3_max_abs(hi)), e = v3_max_abs(v3_sub(hi, lo));
  return 4.0 * RSW_F32_UNIT * (m + e);
}

void rays_traced_batch(rsw_isa isa, int n, const double *const *o, const double *const *d, const pad_box *pb,
                       const accel_box *box, unsigned char *out) {
  SIMD_DISPATCH(isa, rays_traced, n, o, d, pb->lo, pb->hi, box ? box->lo : NULL, box ? box->hi : NULL, out);
}

/* Whether the continuation of a path at si cannot meet anything, for
 * any direction its BSDF samples: then, without an environment to see,
 * the next bounce would only find a miss that adds nothing, and the path
 * ends after its light sample (wave_run). It holds for a one-sided
 * reflecting BSDF, whose valid samples have wo.z >= 0 in the shading
 * frame (tests/kernel/integrators/test_wave.c checks every such plugin),
 * at a point whose geometric and shading normals point along one axis
 * (the other two vectors of the shading frame without a component along
 * it), outwards from a face of the padded box that the spawned origin
 * lies beyond: every direction then has a component >= 0 along the
 * normal, spawn_ray offsets the origin along it, and ray_may_hit's test for
 * that face culls the ray, in the same arithmetic as below. The seed
 * scene's every hit (a flat surface under directional suns). */
static bool continuation_escapes(const scene *sc, const surface_interaction *si, double pad) {
  const unsigned reflect = BSDF_DIFFUSE_REFLECTION | BSDF_GLOSSY_REFLECTION | BSDF_DELTA_REFLECTION;
  if (si->shape->bsdf->flags & ~reflect) return false;
  const double ng[3] = {si->ng.x, si->ng.y, si->ng.z}, n[3] = {si->sh.n.x, si->sh.n.y, si->sh.n.z};
  const double s[3] = {si->sh.s.x, si->sh.s.y, si->sh.s.z}, t[3] = {si->sh.t.x, si->sh.t.y, si->sh.t.z};
  const double p[3] = {si->p.x, si->p.y, si->p.z};
  const double lo[3] = {sc->bbox_min.x, sc->bbox_min.y, sc->bbox_min.z};
  const double hi[3] = {sc->bbox_max.x, sc->bbox_max.y, sc->bbox_max.z};
  const double mag = RSW_SPAWN_ERRORS * si->p_error; /* offset_on_side, ng . d >= 0 */
  for (int a = 0; a < 3; a++) {
    int b = (a + 1) % 3, c = (a + 2) % 3;
    if (ng[b] != 0 || ng[c] != 0 || s[a] != 0 || t[a] != 0) continue;
    double o = p[a] + mag * ng[a];
    if (ng[a] > 0 && n[a] > 0 && o > hi[a] + pad) return true;
    if (ng[a] < 0 && n[a] < 0 && o < lo[a] - pad) return true;
  }
  return false;
}

/* Lanes idx[0..n) go to hit[0..*n_hit) (the ones whose ray hit, in the
 * order of idx) and the others to other[0..*n_other), without a branch
 * on the outcome (a camera ray's is unpredictable). */
static void wave_trace(const scene *sc, lane *ln, const int *idx, int n, render_stats *stats, bool coherent,
                       bool timed, int *hit, int *n_hit, int *other, int *n_other) {
  int nh = 0, no = 0;
  if (sc->periodic.on) { /* the hit fill is counted as tracing here */
    double t0 = timed ? clock_s() : 0;
    /* C rays walked one by one (scene_trace), then their hits' surface
     * data together: each hit's placement record is fetched
     * (hit_prefetch) while the next rays are traced, not waited for at
     * once, and the frames are vectorised. Each si is what intersect()
     * gives: hit_fill_interaction_batch is bitwise hit_fill_interaction.
     * TRACE_UNRESOLVED (scene/periodic.h): the ray neither hit nor
     * escaped; the path ends there, without environment light. */
    enum {
      C = 64
    };
    ray3 seg[C];
    double off[C];
    int at[C];
    const ray3 *rr[C];
    const accel_hit *hh[C];
    surface_interaction *ss[C];
    for (int k0 = 0; k0 < n; k0 += C) {
      int m = n - k0 < C ? n - k0 : C, nm = 0;
      for (int j = 0; j < m; j++) {
        lane *l = &ln[idx[k0 + j]];
        seg[nm] = l->ray;
        l->hit = scene_trace(sc, &seg[nm], &l->h, &off[nm]);
        bool h = l->hit == TRACE_HIT;
        stats->unresolved += l->hit == TRACE_UNRESOLVED;
        if (h) hit_prefetch(sc, &l->h);
        at[nm] = hit[nh] = other[no] = idx[k0 + j];
        nh += h, no += !h, nm += h;
      }
      for (int j = 0; j < nm; j++) rr[j] = &seg[j], hh[j] = &ln[at[j]].h, ss[j] = &ln[at[j]].si;
      hit_fill_interaction_batch(sc, nm, rr, hh, ss);
      for (int j = 0; j < nm; j++) {
        lane *l = &ln[at[j]];
        l->si.t += off[j]; /* distance along the whole (possibly wrapped) ray */
        l->wrapped = off[j] > 0;
      }
    }
    stats->rays += (uint64_t)n;
    if (timed) stats->trace_s += clock_s() - t0;
    *n_hit = nh, *n_other = no;
    return;
  }
  enum {
    P = 16
  };
  /* All packets first (timed as one), then every hit's surface data. */
  double t0 = timed ? clock_s() : 0;
  const pad_box pb = pad_box_of(sc, scene_pad(sc));
  accel_box box;
  const bool cull = coherent && accel_cull_box(sc->accel, &box);
  /* Which rays to trace, V at a time (rays_traced_batch, vectorised):
   * ray_may_hit, and camera rays also by a full slab test with a clear
   * margin (accel_misses_bounds): those that pass the scene by (a third
   * of the seed scene's) need no query either. */
  enum {
    V = 64
  };
  unsigned char go[V];
  int q[P], nq = 0;
  for (int k = 0; k <= n; k++) {
    if (k < n) {
      if (k % V == 0) {
        int m = n - k < V ? n - k : V;
        double c[6][V];
        for (int j = 0; j < m; j++) {
          const ray3 *r = &ln[idx[k + j]].ray;
          c[0][j] = r->o.x, c[1][j] = r->o.y, c[2][j] = r->o.z;
          c[3][j] = r->d.x, c[4][j] = r->d.y, c[5][j] = r->d.z;
        }
        const double *o[3] = {c[0], c[1], c[2]}, *d[3] = {c[3], c[4], c[5]};
        rays_traced_batch(rsw_isa_get(), m, o, d, &pb, cull ? &box : NULL, go);
      }
      int i = idx[k];
      lane *l = &ln[i];
      l->hit = TRACE_MISS;
      l->wrapped = false;
      bool m = go[k % V];
      q[nq] = other[no] = i;
      nq += m, no += !m;
      if (nq < P) continue;
    }
    if (!nq) continue;
    const ray3 *rp[P];
    accel_hit *hp[P];
    bool h[P];
    for (int j = 0; j < nq; j++) rp[j] = &ln[q[j]].ray, hp[j] = &ln[q[j]].h;
    accel_intersect_packet(sc->accel, rp, nq, hp, h, coherent);
    for (int j = 0; j < nq; j++) {
      ln[q[j]].hit = h[j] ? TRACE_HIT : TRACE_MISS;
      hit[nh] = other[no] = q[j];
      nh += h[j], no += !h[j];
    }
    nq = 0;
  }
  if (timed) stats->trace_s += clock_s() - t0;
  stats->rays += (uint64_t)n;
  *n_hit = nh, *n_other = no;
  /* The hits' surface data together (their frames vectorised), 256 at
   * a time (hit.c HIT_BATCH). */
  enum {
    C = 256
  };
  const ray3 *rr[C];
  const accel_hit *hh[C];
  surface_interaction *ss[C];
  for (int k0 = 0; k0 < nh; k0 += C) {
    int m = nh - k0 < C ? nh - k0 : C;
    for (int j = 0; j < m; j++) {
      lane *l = &ln[hit[k0 + j]];
      rr[j] = &l->ray, hh[j] = &l->h, ss[j] = &l->si;
    }
    hit_fill_interaction_batch(sc, m, rr, hh, ss);
  }
}

/* Trace the shadow rays of lanes idx[0..n) (each has nee set). */
static void wave_occluded(const scene *sc, lane *ln, const int *idx, int n, render_stats *stats, bool timed) {
  stats->shadow_rays += (uint64_t)n;
  double t0 = timed ? clock_s() : 0;
  if (sc->periodic.on) {
    for (int k = 0; k < n; k++) {
      lane *l = &ln[idx[k]];
      /* Infinitely distant emitters give dist = INFINITY: the shadow ray
       * is unbounded (in a periodic scene, cut only by leaving the slab).
       * An unresolved one counts as blocked, never as lit. */
      l->occ = scene_occluded(sc, &l->sray);
      if (l->occ == TRACE_UNRESOLVED) stats->unresolved++;
    }
    if (timed) stats->trace_s += clock_s() - t0;
    return;
  }
  enum {
    P = 16
  };
  const pad_box pb = pad_box_of(sc, scene_pad(sc));
  int q[P], nq = 0;
  for (int k = 0; k <= n; k++) {
    if (k < n) {
      lane *l = &ln[idx[k]];
      if (!ray_may_hit(&pb, &l->sray)) {
        l->occ = TRACE_MISS;
        continue;
      }
      q[nq++] = idx[k];
      if (nq < P) continue;
    }
    if (!nq) continue;
    const ray3 *rp[P];
    bool occ[P];
    for (int j = 0; j < nq; j++) rp[j] = &ln[q[j]].sray;
    accel_occluded_packet(sc->accel, rp, nq, occ);
    for (int j = 0; j < nq; j++) ln[q[j]].occ = occ[j] ? TRACE_HIT : TRACE_MISS;
    nq = 0;
  }
  if (timed) stats->trace_s += clock_s() - t0;
}

/* Emitted radiance at pages 1.. (page 0's is the caller's), weighted by
 * w, into the lane's pages (pg NULL: none). */
static void pages_add_emission(const scene *sc, page_lane *pg, const emitter *e,
                               const surface_interaction *si, vec3 d, double w) {
  if (!pg) return;
  for (int p = 1; p < sc->pages; p++) {
    rsw_page = p;
    color Le = e->ops->eval(e, si, d);
    pg->L[p - 1] = col_add(pg->L[p - 1], col_scale(col_mul(pg->T[p - 1], Le), w));
  }
  rsw_page = 0;
}

/* Emission seen by lane l's ray; l->nee: the vertex takes a light sample
 * (its random numbers and the sample itself come from wave_light_samples,
 * for the lanes together). False: the path ends here. */
static bool shade_emit(const integrator *it, const scene *sc, lane *l, double *quv, pol_lane *pl,
                       page_lane *pg) {
  l->nee = false;
  /* Emission seen by this ray (area light or the environment). */
  bool visible_emitter = !(it->hide_emitters && l->depth == 0);
  if (l->hit != TRACE_HIT) {
    const emitter *env = sc->environment;
    if (env && visible_emitter && l->hit == TRACE_MISS) {
      double em_pdf = 0.0;
      if (!l->prev_delta) {
        direction_sample ds = {.d = v3_norm(l->ray.d), .dist = INFINITY};
        em_pdf = env->ops->pdf_direction(env, &l->prev_si, &ds) * emitter_prob(sc, env);
      }
      color Le = env->ops->eval(env, NULL, l->ray.d);
      double w = mis_weight(l->prev_pdf, em_pdf);
      l->L = col_add(l->L, col_scale(col_mul(l->T, Le), w));
      pages_add_emission(sc, pg, env, NULL, l->ray.d, w);
      if (pl) {
        pol_add_env(pl, env, l->ray.d, Le, col_scale(col_mul(l->T, Le), w), pol_channels(sc));
      } else {
        add_polarization(quv, env, v3_norm(l->ray.d), l->T.c[0] * w);
      }
    }
    return false;
  }
  const surface_interaction *si = &l->si;
  const emitter *em = si->shape->emitter;
  if (em && visible_emitter) {
    color Le = em->ops->eval(em, si, l->ray.d);
    if (!col_is_black(Le) || pg) {
      double em_pdf = 0.0;
      /* Next-event estimation samples the emitter in the column only,
       * along a segment that never wraps: a copy reached through the
       * periodic boundary is BSDF sampling's alone (weight 1). */
      if (!l->prev_delta && !l->wrapped) {
        direction_sample ds = {
            .p = si->p, .n = si->ng, .d = v3_norm(l->ray.d), .dist = si->t * v3_len(l->ray.d)};
        em_pdf = em->ops->pdf_direction(em, &l->prev_si, &ds) * emitter_prob(sc, em);
      }
      double w = mis_weight(l->prev_pdf, em_pdf);
      color v = col_scale(col_mul(l->T, Le), w);
      l->L = col_add(l->L, v);
      if (pl) pol_add(pl, v, pol_channels(sc));
      pages_add_emission(sc, pg, em, si, l->ray.d, w);
    }
  }
  if (!(it->max_depth < 0 || l->depth + 1 < it->max_depth)) return false;
  /* Next-event estimation towards one emitter. */
  l->nee = (si->shape->bsdf->flags & BSDF_SMOOTH) && sc->n_emitters > 0;
  return true;
}

/* The shadow rays of spawn_ray_between for up to SPAWN_C lanes, in
 * structure-of-arrays lanes: the lane's surface point p (normal ng, error
 * err) and the point q on the light (normal nq, error qerr) in, the ray's
 * origin o, unit direction d and tmax out. The loop is compiled per ISA
 * (core/isa.h) and vectorised, each lane making spawn_ray_between's
 * operations in its order (no contraction in ISO C mode): the same bits.
 * A lane's square root and division no longer wait on the lane before. */
enum {
  SPAWN_C = 64
};
typedef struct spawn_lanes {
  double p[3][SPAWN_C], ng[3][SPAWN_C], err[SPAWN_C];
  double q[3][SPAWN_C], nq[3][SPAWN_C], qerr[SPAWN_C];
  double o[3][SPAWN_C], d[3][SPAWN_C], tmax[SPAWN_C];
} spawn_lanes;

static inline __attribute__((always_inline)) void spawn_between_body(spawn_lanes *S, int n) {
  const double shorten = 1.0 - RSW_SPAWN_ERRORS * RSW_F32_UNIT;
  for (int i = 0; i < n; i++) {
    const double px = S->p[0][i], py = S->p[1][i], pz = S->p[2][i];
    const double qx = S->q[0][i], qy = S->q[1][i], qz = S->q[2][i];
    const double gx = S->ng[0][i], gy = S->ng[1][i], gz = S->ng[2][i];
    const double nx = S->nq[0][i], ny = S->nq[1][i], nz = S->nq[2][i];
    /* offset_on_side(p, ng, err, q - p) */
    double vx = qx - px, vy = qy - py, vz = qz - pz;
    double mo = RSW_SPAWN_ERRORS * S->err[i];
    double so = gx * vx + gy * vy + gz * vz >= 0 ? mo : -mo;
    double ox = px + so * gx, oy = py + so * gy, oz = pz + so * gz;
    /* offset_on_side(q, nq, qerr, p - q) */
    double wx = px - qx, wy = py - qy, wz = pz - qz;
    double me = RSW_SPAWN_ERRORS * S->qerr[i];
    double se = nx * wx + ny * wy + nz * wz >= 0 ? me : -me;
    double ex = qx + se * nx, ey = qy + se * ny, ez = qz + se * nz;
    double dx = ex - ox, dy = ey - oy, dz = ez - oz;
    double len = sqrt(dx * dx + dy * dy + dz * dz);
    double inv = 1.0 / len;
    S->o[0][i] = ox, S->o[1][i] = oy, S->o[2][i] = oz;
    S->d[0][i] = len > 0 ? dx * inv : dx;
    S->d[1][i] = len > 0 ? dy * inv : dy;
    S->d[2][i] = len > 0 ? dz * inv : dz;
    S->tmax[i] = len * shorten;
  }
}

#if defined(__x86_64__) || defined(__i386__)
static __attribute__((target("avx512f,avx512vl,avx512dq"))) void spawn_between_avx512(spawn_lanes *S, int n) {
  spawn_between_body(S, n);
}
static __attribute__((target("avx2,fma"))) void spawn_between_avx2(spawn_lanes *S, int n) {
  spawn_between_body(S, n);
}
#endif
static void spawn_between_base(spawn_lanes *S, int n) {
  spawn_between_body(S, n);
}

static void spawn_between_run(rsw_isa isa, spawn_lanes *S, int n) {
#if defined(__x86_64__) || defined(__i386__)
  switch (isa) {
  case RSW_ISA_AVX512: spawn_between_avx512(S, n); return;
  case RSW_ISA_AVX2: spawn_between_avx2(S, n); return;
  default: break;
  }
#else
  (void)isa;
#endif
  spawn_between_base(S, n);
}

/* Ray j of S's outputs. */
static inline ray3 spawn_lane_out(const spawn_lanes *S, int j) {
  ray3 r = {v3(S->o[0][j], S->o[1][j], S->o[2][j]), v3(S->d[0][j], S->d[1][j], S->d[2][j]), 0.0, S->tmax[j]};
  return r;
}

/* Lane j of S: from si towards the point q (normal nq) on a surface. */
static inline void spawn_lane_in(spawn_lanes *S, int j, const surface_interaction *si, vec3 q, vec3 nq) {
  S->p[0][j] = si->p.x, S->p[1][j] = si->p.y, S->p[2][j] = si->p.z;
  S->ng[0][j] = si->ng.x, S->ng[1][j] = si->ng.y, S->ng[2][j] = si->ng.z;
  S->err[j] = si->p_error;
  S->q[0][j] = q.x, S->q[1][j] = q.y, S->q[2][j] = q.z;
  S->nq[0][j] = nq.x, S->nq[1][j] = nq.y, S->nq[2][j] = nq.z;
}

/* Lanes ln[sl[0..n)]'s shadow rays from S's inputs 0..n), towards the
 * surface of shape ls: the light's end's error bounds from the shape's
 * accel_surface_error_terms t (accel_surface_error_at_n), then the rays. */
static void spawn_between_lanes(const shape *ls, const double t[8], lane *ln, spawn_lanes *S, const int *sl,
                                int n) {
  if (n == 0) return;
  const double *q[3] = {S->q[0], S->q[1], S->q[2]}, *nq[3] = {S->nq[0], S->nq[1], S->nq[2]};
  accel_surface_error_at_n(t, &ls->to_world, n, q, nq, S->qerr);
  spawn_between_run(rsw_isa_get(), S, n);
  for (int j = 0; j < n; j++) ln[sl[j]].sray = spawn_lane_out(S, j);
}

void spawn_rays_between_batch(rsw_isa isa, int n, const surface_interaction *const *si, const vec3 *q,
                              const vec3 *nq, const double *qerr, ray3 *r) {
  spawn_lanes S;
  for (int k0 = 0; k0 < n; k0 += SPAWN_C) {
    int m = n - k0 < SPAWN_C ? n - k0 : SPAWN_C;
    for (int j = 0; j < m; j++) {
      spawn_lane_in(&S, j, si[k0 + j], q[k0 + j], nq[k0 + j]);
      S.qerr[j] = qerr[k0 + j];
    }
    spawn_between_run(isa, &S, m);
    for (int j = 0; j < m; j++) r[k0 + j] = spawn_lane_out(&S, j);
  }
}

/* Next-event estimation for lanes g[0..n) (each has nee set): the light
 * pick and light sample numbers of every lane (in the one-path order:
 * pick, then sample), then the samples grouped by emitter
 * (emitter_ops.sample_direction_batch where the emitter has it), then the
 * shadow rays. A lane whose sample counts zero drops its nee; the lanes
 * that keep it and whose shadow ray needs a query are left in
 * g[0..*n_sh), in order; *n_clear counts those whose ray ray_may_hit
 * culled (occ TRACE_MISS already, no sray). d1, d2, ek, ord: n entries of
 * scratch each. */
#define EMITTER_GROUPS WAVE_EMITTER_GROUPS

/* What a lane's light sample asks of the shadow rays (light_far). */
enum {
  LIGHT_NONE,    /* the sample counts zero: no shadow ray */
  LIGHT_CLEAR,   /* its ray cannot meet the scene: clear, not traced */
  LIGHT_QUERY,   /* its ray l->sray is traced (wave_occluded) */
  LIGHT_SURFACE, /* towards a surface emitter: left to the spawn pass */
};

/* Lane l's light sample ds (value v) from an emitter that is not a
 * surface, outside a periodic boundary: nee, and the shadow ray's
 * verdict as wave_light_samples' spawn pass and wave_occluded's culling
 * would give them (the same ray, the same test). */
/* Lane l's shadow ray towards its far (not surface) light sample ds:
 * wave_occluded's first test made here, while the lane is in cache
 * (cull: outside a periodic boundary), so that a ray that cannot meet
 * the scene (a sun's, leaving an Earth-observation scene) is clear
 * without being stored. */
static inline int far_shadow_ray(lane *l, const direction_sample *ds, const pad_box *pb, bool cull) {
  ray3 r;
  spawn_ray_to_far(&l->si, ds, &r);
  if (cull && !ray_may_hit(pb, &r)) {
    l->occ = TRACE_MISS;
    return LIGHT_CLEAR;
  }
  l->sray = r;
  return LIGHT_QUERY;
}

static inline int light_far(lane *l, const direction_sample *ds, color v, const pad_box *pb) {
  l->nee = ds->pdf > 0 && !col_is_black(v);
  return l->nee ? far_shadow_ray(l, ds, pb, true) : LIGHT_NONE;
}
static void wave_light_samples(const scene *sc, sampler_state *st, lane *ln, page_lane *pgs, int *g, int n,
                               int *n_sh, int *n_clear, double *d1, vec2 *d2, int *ek, int *ord) {
  enum {
    C = 64
  };
  *n_sh = *n_clear = 0;
  if (n == 0) return;
  const sampler *smp = st[g[0]].s;
  sampler_next_1d_2d_batch(smp, st, g, n, d1, d2);
  for (int k = 0; k < n; k++) ek[k] = (int)pick_emitter_index(sc, d1[k]);
  /* Without pages or a periodic boundary, a lane of an emitter that is not
   * a surface takes its shadow ray's verdict (light_far) as its sample is
   * stored, while the lane is in cache; the others, below. verdict[k]:
   * lane g[k]'s, in ek (free once the lanes are grouped). */
  const bool cull = !sc->periodic.on, fast = !pgs && cull && sc->n_emitters <= EMITTER_GROUPS;
  const pad_box pb = pad_box_of(sc, scene_pad(sc));
  int *verdict = ek;
  /* The lanes grouped by emitter (a counting sort, in lane order within
   * each emitter) for one batched call per emitter and chunk; a lane's
   * sample does not depend on its group. Scenes with many emitters sample
   * lane by lane. */
  if (sc->n_emitters > EMITTER_GROUPS) {
    for (int k = 0; k < n; k++) {
      lane *l = &ln[g[k]];
      l->pe = pick_probability(sc, (size_t)ek[k]);
      l->ne = sc->emitters[ek[k]];
      l->value = l->ne->ops->sample_direction(l->ne, &l->si, d2[k], &l->ds);
    }
  } else {
    int start[EMITTER_GROUPS + 1];
    wave_group_by_emitter(sc, ek, n, start, ord);
    for (int k = 0; fast && k < n; k++) verdict[k] = LIGHT_SURFACE;
    for (size_t e_i = 0; e_i < sc->n_emitters; e_i++) {
      const emitter *e = sc->emitters[e_i];
      const bool far = fast && !((e->flags & EMITTER_SURFACE) && e->shape);
      double pe = pick_probability(sc, e_i); /* every lane's own quotient */
      for (int j0 = start[e_i]; j0 < start[e_i + 1]; j0 += C) {
        int m = start[e_i + 1] - j0 < C ? start[e_i + 1] - j0 : C;
        const surface_interaction *ref[C];
        vec2 u[C];
        direction_sample ds[C];
        color val[C];
        for (int j = 0; j < m; j++) {
          ref[j] = &ln[g[ord[j0 + j]]].si;
          u[j] = d2[ord[j0 + j]];
        }
        emitter_sample_direction_n(e, m, ref, u, ds, val);
        for (int j = 0; j < m; j++) {
          lane *l = &ln[g[ord[j0 + j]]];
          l->pe = pe;
          l->ne = e;
          l->ds = ds[j];
          l->value = val[j];
          if (far) verdict[ord[j0 + j]] = light_far(l, &ds[j], val[j], &pb);
        }
      }
    }
  }
  /* Pages 1..: the same sample's value at each (the same numbers give the
   * same direction: every emitter samples positions and directions
   * without its spectrum, environment plugins included, whose sample()
   * takes no wavelength). */
  for (int k = 0; pgs && k < n; k++) {
    lane *l = &ln[g[k]];
    for (int p = 1; p < sc->pages; p++) {
      direction_sample ds;
      rsw_page = p;
      color v = l->ne->ops->sample_direction(l->ne, &l->si, d2[k], &ds);
      pgs[g[k]].value[p - 1] = v;
    }
    rsw_page = 0;
  }
  /* The light's end of a shadow ray towards a surface emitter is offset
   * by accel_surface_error; its shape's terms are taken once per run of
   * lanes of one emitter (accel_surface_error_at: the same bits). */
  const emitter *te = NULL;
  double terms[8];
  spawn_lanes S;
  int sl[SPAWN_C], ns = 0, nq = 0, nc = 0; /* the counts in registers, not behind the pointers */
  for (int k = 0; k < n; k++) {
    if (fast && verdict[k] != LIGHT_SURFACE) { /* its verdict taken already (light_far) */
      g[nq] = g[k];
      nq += verdict[k] == LIGHT_QUERY;
      nc += verdict[k] == LIGHT_CLEAR;
      continue;
    }
    lane *l = &ln[g[k]];
    const emitter *e = l->ne;
    l->nee = false;
    /* Under `periodic`, the part of a surface emitter outside the column
     * is not in the scene (scene/periodic.h): a light sample there counts
     * zero. The in-column part keeps its density 1/area, which is what
     * pdf_direction gives an unwrapped emitter hit; its copies beyond the
     * walls are reached by BSDF sampling alone (weight 1). */
    if (sc->periodic.on && (e->flags & EMITTER_SURFACE) && !in_column(&sc->periodic, l->ds.p)) l->ds.pdf = 0;
    bool lit = !col_is_black(l->value);
    for (int p = 1; pgs && p < sc->pages; p++) lit |= !col_is_black(pgs[g[k]].value[p - 1]);
    if (l->ds.pdf > 0 && lit) {
      if ((e->flags & EMITTER_SURFACE) && e->shape) {
        const shape *ls = e->shape;
        if (e != te) {
          if (te) spawn_between_lanes(te->shape, terms, ln, &S, sl, ns), ns = 0;
          accel_surface_error_terms(sc->accel, ls->index, &ls->to_world, terms);
          te = e;
        }
        spawn_lane_in(&S, ns, &l->si, l->ds.p, l->ds.n);
        sl[ns++] = g[k];
        if (ns == SPAWN_C) spawn_between_lanes(ls, terms, ln, &S, sl, ns), ns = 0;
      } else if (far_shadow_ray(l, &l->ds, &pb, cull) == LIGHT_CLEAR) {
        l->nee = true;
        nc++;
        continue;
      }
      l->nee = true;
      g[nq++] = g[k];
    }
  }
  if (te) spawn_between_lanes(te->shape, terms, ln, &S, sl, ns);
  *n_sh = nq, *n_clear = nc;
}

/* Lanes g[0..*left), of BSDFs gb[], wait for batched BSDF calls: move
 * all of those whose BSDF is gb[0] into take[] (in lane order), keep the
 * rest in g and gb (in order), and return how many were taken; *b is
 * their BSDF. The BSDFs from gb, not the lanes: a wave's every group is
 * one pass over a dense array (a scan of the lanes per call of 64 read
 * each lane's line again and again). Without a branch on the BSDF. */
static int take_bsdf_group(int *g, const bsdf **gb, int *left, int *take, const bsdf **b) {
  *b = gb[0];
  int m = 0, rest = 0;
  for (int k = 0; k < *left; k++) {
    bool on = gb[k] == *b;
    take[m] = g[rest] = g[k];
    gb[rest] = gb[k];
    m += on, rest += !on;
  }
  *left = rest;
  return m;
}

/* The batched BSDF calls of the lanes waiting in g, gb (take_bsdf_group;
 * take: as many ints of scratch): each call's BSDF *b and lanes t[0..*m),
 * at most BSDF_BATCH of them. False: none left. */
enum {
  BSDF_BATCH = 64
};
typedef struct bsdf_batches {
  int *g, left, *take, taken, done;
  const bsdf **gb, *b;
} bsdf_batches;

static bool next_bsdf_batch(bsdf_batches *q, const bsdf **b, const int **t, int *m) {
  if (q->done == q->taken) {
    if (q->left == 0) return false;
    q->taken = take_bsdf_group(q->g, q->gb, &q->left, q->take, &q->b), q->done = 0;
  }
  *b = q->b, *t = q->take + q->done;
  *m = q->taken - q->done < BSDF_BATCH ? q->taken - q->done : BSDF_BATCH;
  q->done += *m;
  return true;
}

/* The second half of lane l's vertex, first part: the light sample's
 * contribution if its shadow ray was clear (its BSDF value and pdf from
 * wave_eval_bsdfs, which calls it). The BSDF sample's random numbers are drawn next, for
 * the lanes together (wave_run), in the one-path order; the sample itself
 * is taken by wave_sample_bsdfs. */
static void shade_light(const scene *sc, lane *l, double *quv, pol_lane *pl, page_lane *pg) {
  if (l->nee && l->occ == TRACE_MISS) {
    const direction_sample *ds = &l->ds;
    const emitter *e = l->ne;
    color f = l->nf;
    double w = ds->delta ? 1.0 : mis_weight(ds->pdf * l->pe, l->npdf);
    for (int p = 1; pg && p < sc->pages; p++) {
      color v = col_mul(pg->T[p - 1], col_mul(pg->nf[p - 1], pg->value[p - 1]));
      pg->L[p - 1] = col_add(pg->L[p - 1], col_scale(v, w / l->pe));
    }
    if (!col_is_black(f)) {
      color v = col_scale(col_mul(l->T, col_mul(f, l->value)), w / l->pe);
      l->L = col_add(l->L, v);
      if (pl)
        pol_collect_light(pl, &l->si, l->nwo, 0, e, ds->d, v3_neg(v3_norm(l->ray.d)), v, pol_channels(sc));
      else if (quv && (e->flags & EMITTER_INFINITE))
        add_polarization(quv, e, ds->d, l->T.c[0] * f.c[0] * w / (l->pe * ds->pdf));
    }
  }
}

/* The light samples of lanes idx[0..n) whose shadow ray was clear: the
 * BSDF's value and pdf towards each (l->nf, l->npdf), grouped by BSDF
 * through bsdf_ops.eval_pdf_batch where a BSDF has it, else per lane (a
 * bundle of pages: lane by lane, every page's value and the pages' mean
 * pdf), and at once the sample's contribution (shade_light), while the
 * lane is in cache. A lane's values depend on its own state only, so
 * the order its group puts it in changes nothing. quv (qs values a lane),
 * pol: as wave_run's. g: n ints of scratch. */
static void wave_eval_bsdfs(const scene *sc, lane *ln, page_lane *pgs, const int *idx, int n, int *g,
                            const bsdf **gb, int *take, double *quv, int qs, pol_lane *pol) {
  enum {
    C = BSDF_BATCH
  };
  int left = 0;
  for (int k = 0; k < n; k++) {
    lane *l = &ln[idx[k]];
    if (!(l->nee && l->occ == TRACE_MISS)) continue;
    const surface_interaction *si = &l->si;
    const bsdf *b = si->shape->bsdf;
    l->nwo = frame_to_local(&si->sh, l->ds.d);
    if (pgs) { /* every page's value, and the pages' mean pdf (one-sample MIS), lane by lane */
      color f[RENDER_MAX_PAGES];
      l->npdf = bsdf_eval_pages(b, si, sc->pages, l->nwo, !l->ds.delta, f);
      l->nf = f[0];
      for (int p = 1; p < sc->pages; p++) pgs[idx[k]].nf[p - 1] = f[p];
    } else if (b->ops->eval_pdf_batch) {
      gb[left] = b;
      g[left++] = idx[k];
      continue;
    } else {
      l->nf = b->ops->eval(b, si, l->nwo);
      l->npdf = col_is_black(l->nf) || l->ds.delta ? 0.0 : b->ops->pdf(b, si, l->nwo);
    }
    int i = idx[k];
    shade_light(sc, l, quv ? &quv[qs * i] : NULL, pol ? &pol[i] : NULL, pgs ? &pgs[i] : NULL);
  }
  bsdf_batches q = {.g = g, .gb = gb, .left = left, .take = take};
  const bsdf *b;
  const int *t;
  int m;
  while (next_bsdf_batch(&q, &b, &t, &m)) {
    const surface_interaction *si[C];
    vec3 wo[C];
    color f[C];
    double pdf[C];
    for (int k = 0; k < m; k++) si[k] = &ln[t[k]].si, wo[k] = ln[t[k]].nwo;
    b->ops->eval_pdf_batch(b, m, si, wo, f, pdf);
    for (int k = 0; k < m; k++) {
      int i = t[k];
      ln[i].nf = f[k];
      ln[i].npdf = pdf[k];
      shade_light(sc, &ln[i], quv ? &quv[qs * i] : NULL, pol ? &pol[i] : NULL, NULL);
    }
  }
}

/* BSDF samples of the lanes idx[0..n): lanes whose BSDF has a batched
 * sample op are grouped by BSDF (one call per BSDF, vectorised at the
 * render's ISA); the others sample one by one. The grouping does not
 * change a lane's value (bsdf_ops.sample_batch). A bundle of pages
 * samples lane by lane for every page (integrators/pages.h). g: n ints of
 * scratch. */
static void wave_sample_bsdfs(const scene *sc, lane *ln, page_lane *pgs, const int *idx, int n, int *g,
                              const bsdf **gb, int *take) {
  enum {
    C = BSDF_BATCH
  };
  if (pgs) {
    for (int k = 0; k < n; k++) {
      lane *l = &ln[idx[k]];
      color w[RENDER_MAX_PAGES];
      bsdf_sample_pages(l->si.shape->bsdf, &l->si, sc->pages, l->u1, l->u2, &l->bs, w);
      l->weight = w[0];
      for (int p = 1; p < sc->pages; p++) pgs[idx[k]].weight[p - 1] = w[p];
    }
    return;
  }
  int left = 0;
  for (int k = 0; k < n; k++) {
    lane *l = &ln[idx[k]];
    const bsdf *b = l->si.shape->bsdf;
    if (b->ops->sample_batch)
      gb[left] = b, g[left++] = idx[k];
    else
      l->weight = b->ops->sample(b, &l->si, l->u1, l->u2, &l->bs);
  }
  bsdf_batches q = {.g = g, .gb = gb, .left = left, .take = take};
  const bsdf *b;
  const int *t;
  int m;
  while (next_bsdf_batch(&q, &b, &t, &m)) {
    const surface_interaction *si[C];
    double u1[C];
    vec2 u2[C];
    bsdf_sample bs[C];
    color w[C];
    for (int k = 0; k < m; k++) si[k] = &ln[t[k]].si, u1[k] = ln[t[k]].u1, u2[k] = ln[t[k]].u2;
    b->ops->sample_batch(b, m, si, u1, u2, bs, w);
    for (int k = 0; k < m; k++) ln[t[k]].bs = bs[k], ln[t[k]].weight = w[k];
  }
}

/* The end of lane l's vertex: the continuation ray from its BSDF sample
 * and the roulette. False: the path ends here. */
static bool shade_continue(const integrator *it, const scene *sc, sampler_state *st, lane *l, pol_lane *pl,
                           page_lane *pg) {
  const sampler_ops *sops = st->s->ops;
  const surface_interaction *si = &l->si;
  const bsdf_sample *bs = &l->bs;
  color weight = l->weight;
  bool lit = !col_is_black(weight);
  for (int p = 1; pg && p < sc->pages; p++) lit |= !col_is_black(pg->weight[p - 1]);
  if (!(bs->pdf > 0) || !lit) return false;
  vec3 wo_world = frame_to_world(&si->sh, bs->wo);
  if (pl) {
    mueller P[3];
    vec3 b_in = {0}, b_out = {0};
    const mueller *pp = pol_bsdf(si->shape->bsdf, si, bs->wo, bs->sampled_type, P, &b_in, &b_out);
    pol_scatter(pl, v3_neg(v3_norm(l->ray.d)), b_out, pp, b_in, pol_channels(sc));
  }
  l->ray = spawn_ray(si, wo_world);
  l->T = col_mul(l->T, weight);
  /* A bundle of pages: the roulette on the largest throughput of any page. */
  double tmax = col_max(l->T);
  for (int p = 1; pg && p < sc->pages; p++) {
    pg->T[p - 1] = col_mul(pg->T[p - 1], pg->weight[p - 1]);
    tmax = fmax(tmax, col_max(pg->T[p - 1]));
  }
  l->eta *= bs->eta;
  l->prev_si = *si;
  l->prev_pdf = bs->pdf;
  l->prev_delta = (bs->sampled_type & BSDF_DELTA) != 0;
  l->depth++;
  if (l->depth >= it->rr_depth) {
    double q = fmin(tmax * l->eta * l->eta, 0.95);
    if (!(sops->next_1d(st) < q)) return false;
    l->T = col_scale(l->T, 1.0 / q);
    for (int p = 1; pg && p < sc->pages; p++) pg->T[p - 1] = col_scale(pg->T[p - 1], 1.0 / q);
    tmax /= q;
  }
  return tmax > 0;
}

/* Scratch for a wave of n lanes: the lanes, two index lists and the
 * batched draws. */
typedef struct wave_scratch {
  lane *ln;
  pol_lane *pol; /* the polarized variants' payload, per lane (else NULL) */
  page_lane *pg; /* a bundle of pages: pages 1.., per lane (else NULL) */
  int *idx, *sh, *ek, *ord, *cont, *take;
  const bsdf **gb; /* the BSDFs of lanes waiting for a batch (take_bsdf_group) */
  double *d1;
  vec2 *d2;
} wave_scratch;

/* Run the wave over n lanes. */
static void wave_run(const integrator *it, const scene *sc, sampler_state *st, const ray3 *rays, int n,
                     render_stats *stats, color *L, double *quv, const wave_scratch *ws) {
  lane *ln = ws->ln;
  pol_lane *pol = ws->pol;
  page_lane *pgs = ws->pg;
  int *idx = ws->idx, *sh = ws->sh, *cont = ws->cont;
  const int qs = scene_extra_stride(sc);
  if (quv)
    for (int i = 0; i < qs * n; i++) quv[i] = 0;
  double *pages_out = pgs ? quv : NULL; /* a bundle's pages 1.. go there, not Stokes values */
  if (pgs) quv = NULL;
  for (int i = 0; pgs && i < n; i++)
    for (int p = 1; p < sc->pages; p++) {
      pgs[i].T[p - 1] = col1(1);
      pgs[i].L[p - 1] = col1(0);
    }
  if (pol)
    for (int i = 0; i < n; i++) pol_start(&pol[i], rays[i].d, pol_channels(sc));
  for (int i = 0; i < n; i++) {
    lane *l = &ln[i];
    l->ray = rays[i];
    l->T = col1(1);
    l->L = col1(0);
    l->eta = 1.0;
    l->prev_pdf = 1.0;
    l->prev_delta = true;
    l->wrapped = false;
    l->depth = 0;
    idx[i] = i;
  }
  int live = it->max_depth == 0 ? 0 : n;
  bool timed = n > 1; /* Li's one-path waves are not timed (two clock reads per query) */
  bool camera = true;
  const sampler *smp = n > 0 ? st[0].s : NULL;
  const bool escape_test = !sc->periodic.on && !sc->environment && !pol;
  const double pad = scene_pad(sc);
  for (unsigned bounce = 1; live > 0; bounce++) {
    if (bounce % WAVE_STOP_EVERY == 0 && render_stop_requested()) break; /* (discarded) */
    /* The lanes whose ray hit (in order) and the others, in ws->ord and
     * ws->ek (wave_light_samples' scratch, free until then). */
    int *hits = ws->ord, *other = ws->ek, n_hit, n_other;
    wave_trace(sc, ln, idx, live, stats, camera, timed, hits, &n_hit, other, &n_other);
    camera = false;
    for (int k = 0; k < n_other; k++) { /* the environment's light; these paths end */
      int i = other[k];
      shade_emit(it, sc, &ln[i], quv ? &quv[qs * i] : NULL, pol ? &pol[i] : NULL, pgs ? &pgs[i] : NULL);
    }
    /* The hits' emission, and (in the same pass, while the lane is in
     * cache) whether the path ends after its light sample: paths whose
     * continuation cannot meet anything (continuation_escapes) take no
     * BSDF sample, no roulette, nothing else drawn from their streams
     * (cont: the others, in order). Not under a periodic boundary, with
     * an environment, or in the polarized variants (their payload). */
    int next = 0, n_nee = 0, n_sh = 0, n_clear = 0, n_cont = 0;
    for (int k = 0; k < n_hit; k++) {
      int i = hits[k];
      bool keep =
          shade_emit(it, sc, &ln[i], quv ? &quv[qs * i] : NULL, pol ? &pol[i] : NULL, pgs ? &pgs[i] : NULL);
      idx[next] = sh[n_nee] = cont[n_cont] = i;
      next += keep, n_nee += keep & ln[i].nee;
      n_cont += keep && !(escape_test && continuation_escapes(sc, &ln[i].si, pad));
    }
    live = next;
    wave_light_samples(sc, st, ln, pgs, sh, n_nee, &n_sh, &n_clear, ws->d1, ws->d2, ws->ek, ws->ord);
    stats->shadow_rays += (uint64_t)n_clear;
    if (n_sh) wave_occluded(sc, ln, sh, n_sh, stats, timed);
    /* Each lane's light sample. */
    wave_eval_bsdfs(sc, ln, pgs, idx, live, sh, ws->gb, ws->take, quv, qs, pol);
    for (int k = 0; k < n_cont; k++) idx[k] = cont[k];
    live = n_cont;
    /* The BSDF samples' numbers, lobe then direction, for every lane. */
    if (live) {
      sampler_next_1d_2d_batch(smp, st, idx, live, ws->d1, ws->d2);
      for (int k = 0; k < live; k++) {
        ln[idx[k]].u1 = ws->d1[k];
        ln[idx[k]].u2 = ws->d2[k];
      }
    }
    wave_sample_bsdfs(sc, ln, pgs, idx, live, sh, ws->gb, ws->take);
    next = 0;
    for (int k = 0; k < live; k++) { /* whether a BSDF sample failed is unpredictable: no branch */
      int i = idx[k];
      bool keep = shade_continue(it, sc, &st[i], &ln[i], pol ? &pol[i] : NULL, pgs ? &pgs[i] : NULL);
      idx[next] = i;
      next += keep;
    }
    live = next;
  }
  for (int i = 0; i < n; i++) L[i] = ln[i].L;
  for (int i = 0; pages_out && i < n; i++)
    for (int p = 1; p < sc->pages; p++)
      for (int c = 0; c < 3; c++) pages_out[qs * i + 3 * (p - 1) + c] = pgs[i].L[p - 1].c[c];
  if (pol)
    for (int i = 0; i < n; i++) pol_result(&pol[i], pol_channels(sc), &L[i], quv ? &quv[qs * i] : NULL);
}

static bool path_Li_batch(const integrator *it, const scene *sc, sampler_state *st, const ray3 *rays, int n,
                          render_stats *stats, color *L, double *quv) {
  if (n <= 0) return true;
  wave_scratch ws = {.ln = malloc((size_t)n * sizeof *ws.ln),
                     .idx = malloc(6 * (size_t)n * sizeof *ws.idx),
                     .gb = malloc((size_t)n * sizeof *ws.gb),
                     .d1 = malloc((size_t)n * sizeof *ws.d1),
                     .d2 = malloc((size_t)n * sizeof *ws.d2),
                     .pol = sc->polarized ? pol_alloc(n, pol_channels(sc)) : NULL,
                     .pg = sc->pages > 1 ? malloc((size_t)n * sizeof *ws.pg) : NULL};
  bool ok =
      ws.ln && ws.idx && ws.gb && ws.d1 && ws.d2 && (ws.pol || !sc->polarized) && (ws.pg || sc->pages <= 1);
  if (ok) {
    ws.sh = ws.idx + n;
    ws.ek = ws.idx + 2 * (size_t)n;
    ws.ord = ws.idx + 3 * (size_t)n;
    ws.cont = ws.idx + 4 * (size_t)n;
    ws.take = ws.idx + 5 * (size_t)n;
    wave_run(it, sc, st, rays, n, stats, L, quv, &ws);
  }
  free(ws.ln);
  free(ws.idx);
  free(ws.gb);
  free(ws.d1);
  free(ws.d2);
  free(ws.pg);
  pol_free(ws.pol);
  return ok;
}

static color path_Li(const integrator *it, const scene *sc, sampler_state *st, ray3 ray, render_stats *stats,
                     double *quv) {
  lane ln;
  int idx[6];
  const bsdf *gb[1];
  double d1[1];
  vec2 d2[1];
  mueller pm[3];
  pol_lane pl = {.M = pm};
  page_lane pg;
  wave_scratch ws = {.ln = &ln,
                     .idx = idx,
                     .sh = idx + 1,
                     .ek = idx + 2,
                     .ord = idx + 3,
                     .cont = idx + 4,
                     .take = idx + 5,
                     .gb = gb,
                     .d1 = d1,
                     .d2 = d2,
                     .pol = sc->polarized ? &pl : NULL,
                     .pg = sc->pages > 1 ? &pg : NULL};
  color L;
  double q[SCENE_QUV_MAX > SCENE_EXTRA_MAX ? SCENE_QUV_MAX : SCENE_EXTRA_MAX];
  wave_run(it, sc, st, &ray, 1, stats, &L, quv ? q : NULL, &ws);
  if (quv) /* (a bundle's pages: Li_batch alone gives them) */
    for (int k = 0; k < scene_quv_stride(sc) && sc->pages <= 1; k++) quv[k] += q[k];
  return L;
}

static const integrator_ops path_ops = {.Li = path_Li, .Li_batch = path_Li_batch};

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
  it->pages = true;
  /* Waves of 1024 samples (render.c): on the AVX-512 machine of
   * docs/performance.md 512 took 0.96x (the seed scene) and 0.98x (the
   * Cornell box) the CPU time of 256 (the per-wave work, grouping by
   * emitter and BSDF, the packets' tails, over more lanes), and 1024
   * 0.98x and 0.99x that of 512; 2048 took 1.03x (the seed scene: the
   * lanes no longer stay in the core's cache). */
  it->wave = 1024;
  *out = &it->base;
  return RSW_OK;
}

DEFINE_PLUGIN(path, CLS_INTEGRATOR, .ops = &path_ops);
