/* `volpath` and `piecewise_volpath`: volumetric path tracers (Mitsuba 3's
 * volpath, mitsuba3 src/integrators/volpath.cpp; Eradiate's
 * piecewise_volpath, eradiate/mitsuba3
 * src/eradiate_plugins/integrators/piecewise_volpath.cpp;
 * kernel-behavior.md §4.5). Surfaces behave as in `path` (NEE towards one
 * emitter, MIS with BSDF sampling, power heuristic); inside a medium a
 * path also scatters, with NEE and MIS against phase sampling.
 *
 * Media. A path starts in its sensor's medium and changes medium where it
 * crosses a shape whose interior and exterior differ (Mitsuba's
 * is_medium_transition): it goes into the exterior when it leaves along
 * the normal, else into the interior. A `null` BSDF (BSDF_INDEX_MATCHED)
 * is crossed without a bounce, by camera, scattered and shadow rays.
 *
 * Free flight along a segment [0, t_s] (t_s: the next surface), with
 * unit directions so that t is a length:
 *  - tracking (volpath, media whose coefficients vary): delta tracking
 *    against the scalar majorant mu: tentative collisions t ~ mu e^{-mu t};
 *    with channel c (uniform over the three when sigma_t differs between
 *    them, else 0) a collision is real with probability sigma_t,c / mu
 *    (then T *= sigma_s / sigma_t,c: the albedo in mono) and null
 *    otherwise (T *= sigma_n / (mu - sigma_t,c): 1 in mono); Mitsuba's
 *    weights with tr / tr_pdf = 1 / mu.
 *  - analytic (homogeneous media in both integrators, every medium with
 *    medium_ops.sample_real in piecewise_volpath): t is drawn by
 *    inverting the optical thickness in channel c and T *= tr sigma_s /
 *    pdf_c at a collision (the albedo in mono), tr / pdf_c when the flight
 *    passes t_s (1 in mono).
 *  - a medium with no scattering (medium.absorbing_only) is not sampled:
 *    T *= transmittance over the segment, exact in analytic media (the
 *    Beer-Lambert tests are noise-free) and ratio-tracked otherwise.
 * Transmittance along shadow rays: exact in analytic media, ratio tracking
 * (T *= sigma_n / mu per tentative collision) otherwise; null surfaces are
 * crossed, any other surface blocks.
 *
 * Estimator: L = sum over vertices of T (Le w_bsdf + NEE w_em); at a
 * medium vertex, NEE = p(wi, wo) Le tr / (pdf_em p_pick) with MIS weight
 * w(pdf_em p_pick, pdf_phase) and phase sampling weight p / pdf (1 for
 * exact sampling). A bounce is a surface or medium scattering event (null
 * surfaces and null collisions are not); max_depth counts as in `path`
 * (2: single scattering). Russian roulette from rr_depth, survival
 * q = min(max(T) eta^2, 0.95). Emitting media are not supported (none of
 * the media plugins emits).
 *
 * The sensor's medium: Li does not receive the sensor, so the path's first
 * medium is that of the sensor whose sampler drives it (st->s); sensors
 * sharing a sampler must share a medium (scene_check_media says so). One
 * path at a time (no Li_batch). */
#include <math.h>
#include <stdlib.h>

#include "../accel.h"
#include "../scene/loader.h"
#include "../scene/periodic.h"
#include "../shapes/instance.h"
#include "../shapes/shape.h"

typedef struct volpath_integrator {
  integrator base;
  bool analytic; /* piecewise_volpath */
} volpath_integrator;

enum {
  MAX_CROSSINGS = 1024 /* null surfaces crossed by one ray before it counts as lost */
};

static inline double mis_weight(double a, double b) {
  a *= a;
  b *= b;
  double w = a / (a + b);
  return isfinite(w) ? w : 0.0;
}

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

/* Can ray r meet the scene's bounding box on [tmin, tmax]? A ray that has
 * left it (through an atmosphere's top, say) can hit nothing more, so
 * it needs no query. Not under a periodic boundary (copies beyond the
 * column). */
static bool may_hit(const scene *sc, const ray3 *r) {
  if (sc->periodic.on) return true;
  const double lo[3] = {sc->bbox_min.x, sc->bbox_min.y, sc->bbox_min.z};
  const double hi[3] = {sc->bbox_max.x, sc->bbox_max.y, sc->bbox_max.z};
  const double o[3] = {r->o.x, r->o.y, r->o.z}, d[3] = {r->d.x, r->d.y, r->d.z};
  double t0 = r->tmin, t1 = r->tmax;
  for (int a = 0; a < 3; a++) {
    double pad = 1e-9 * (fabs(lo[a]) + fabs(hi[a]) + 1.0);
    double l = lo[a] - pad, h = hi[a] + pad;
    if (d[a] == 0.0) {
      if (o[a] < l || o[a] > h) return false;
      continue;
    }
    double ta = (l - o[a]) / d[a], tb = (h - o[a]) / d[a];
    if (ta > tb) {
      double x = ta;
      ta = tb;
      tb = x;
    }
    t0 = fmax(t0, ta);
    t1 = fmin(t1, tb);
    if (t0 > t1) return false;
  }
  return true;
}

static bool intersect(const scene *sc, const ray3 *r, surface_interaction *si, render_stats *stats) {
  if (!may_hit(sc, r)) return false;
  accel_hit h;
  stats->rays++;
  ray3 seg = *r;
  double off;
  trace_result tr = scene_trace(sc, &seg, &h, &off);
  if (tr != TRACE_HIT) {
    if (tr == TRACE_UNRESOLVED) stats->unresolved++;
    return false;
  }
  hit_fill_interaction(sc, &seg, &h, si);
  si->t += off;
  return true;
}

/* The medium on the far side of si for a ray leaving along world d. */
static const medium *medium_after(const surface_interaction *si, vec3 d, const medium *current) {
  const shape *sh = si->shape;
  if (sh->interior == sh->exterior) return current;
  return v3_dot(d, si->ng) > 0 ? sh->exterior : sh->interior;
}

static int pick_channel(const medium *m, sampler_state *st) {
  if (!m->has_spectral_extinction) return 0;
  int c = (int)(st->s->ops->next_1d(st) * 3.0);
  return c > 2 ? 2 : c;
}

/* Does this integrator sample m analytically? */
static bool analytic_in(const volpath_integrator *vp, const medium *m) {
  return m->ops->sample_real && m->ops->transmittance && (vp->analytic || m->is_homogeneous);
}

/* Transmittance of m along r over [0, tend] (a shadow ray's segment):
 * exact where analytic, else ratio tracking. */
static color segment_tr(const volpath_integrator *vp, const medium *m, const ray3 *r, double tend,
                        sampler_state *st) {
  ray3 seg = *r;
  seg.tmin = 0;
  seg.tmax = tend;
  double mint, maxt;
  if (!m->ops->intersect_aabb(m, &seg, &mint, &maxt)) return col1(1.0);
  if (m->ops->transmittance && (analytic_in(vp, m) || m->is_homogeneous))
    return m->ops->transmittance(m, &seg, mint, maxt);
  const sampler_ops *sops = st->s->ops;
  color tr = col1(1.0);
  medium_interaction mi = {.medium = m, .wi = v3_neg(r->d)};
  mi.p = v3_fma(r->o, mint, r->d);
  double mu = col_max(m->ops->majorant(m, &mi));
  if (!(mu > 0)) return tr;
  double t = mint;
  for (;;) {
    t -= log1p(-sops->next_1d(st)) / mu;
    if (!(t < maxt)) break;
    mi.t = t;
    mi.p = v3_fma(r->o, t, r->d);
    mi.majorant = col1(mu);
    m->ops->coefficients(m, &mi);
    tr = col_mul(tr, col_scale(mi.sigma_n, 1.0 / mu));
    if (col_max(tr) <= 0) return col1(0.0);
    /* Roulette on low weights keeps long tracks bounded (unbiased). */
    if (col_max(tr) < 0.1) {
      double q = col_max(tr);
      if (!(sops->next_1d(st) < q)) return col1(0.0);
      tr = col_scale(tr, 1.0 / q);
    }
  }
  return tr;
}

/* Transmittance along the shadow ray r (unit d, r.tmax its length) from a
 * vertex at p0 in medium m, crossing null surfaces; 0 when blocked. The
 * media see the exact segments between surface points (p0, the hits),
 * not the traced rays' offset origins. */
static color shadow_tr(const volpath_integrator *vp, const scene *sc, ray3 r, vec3 p0, const medium *m,
                       sampler_state *st, render_stats *stats) {
  color tr = col1(1.0);
  vec3 end = v3_fma(r.o, r.tmax, r.d);
  bool finite = isfinite(r.tmax);
  for (int k = 0; k < MAX_CROSSINGS; k++) {
    surface_interaction si;
    uint64_t before = stats->rays;
    bool hit = intersect(sc, &r, &si, stats);
    stats->shadow_rays += stats->rays - before; /* counted as shadow rays */
    stats->rays = before;
    if (m) {
      vec3 q = hit ? si.p : end;
      ray3 mr = {p0, r.d, 0.0, (hit || finite) ? v3_dot(v3_sub(q, p0), r.d) : INFINITY};
      tr = col_mul(tr, segment_tr(vp, m, &mr, mr.tmax, st));
      if (col_is_black(tr)) return tr;
    }
    if (!hit) return tr;
    if (!(si.shape->bsdf->flags & BSDF_INDEX_MATCHED)) return col1(0.0);
    m = medium_after(&si, r.d, m);
    double left = r.tmax - si.t;
    r = spawn_ray(&si, r.d);
    r.tmax = left;
    p0 = si.p;
    if (!(left > 0)) return tr;
  }
  return col1(0.0);
}

/* The shadow ray from a surface vertex si (or a medium point p when si is
 * NULL) towards emitter sample ds (unit direction ds->d). */
static ray3 shadow_ray(const scene *sc, const surface_interaction *si, vec3 p, const emitter *e,
                       const direction_sample *ds) {
  if ((e->flags & EMITTER_SURFACE) && e->shape) {
    const shape *ls = e->shape;
    double err = accel_surface_error(sc->accel, ls->index, &ls->to_world, ds->p, ds->n);
    if (si) return spawn_ray_between(si, ds->p, ds->n, err);
    vec3 q = offset_on_side(ds->p, ds->n, err, v3_sub(p, ds->p));
    vec3 d = v3_sub(q, p);
    double len = v3_len(d);
    ray3 r = {p, len > 0 ? v3_scale(d, 1.0 / len) : ds->d, 0.0, len * (1.0 - RSW_SPAWN_ERRORS * RSW_F32_UNIT)};
    return r;
  }
  ray3 r = si ? spawn_ray(si, ds->d) : (ray3){p, ds->d, 0.0, INFINITY};
  r.tmax = isfinite(ds->dist) ? ds->dist * (1.0 - RSW_SHADOW_EPSILON) : INFINITY;
  return r;
}

/* The medium the path of sampler state st starts in: its sensor's. */
static const medium *start_medium(const scene *sc, const sampler_state *st) {
  for (size_t i = 0; i < sc->n_sensors; i++)
    if (sc->sensors[i]->sampler == st->s) return sc->sensors[i]->medium;
  return NULL;
}

static color volpath_Li(const integrator *it, const scene *sc, sampler_state *st, ray3 ray, render_stats *stats,
                        double *quv) {
  (void)quv; /* no polarisation through media */
  const volpath_integrator *vp = (const volpath_integrator *)it;
  const sampler_ops *sops = st->s->ops;
  color L = col1(0.0), T = col1(1.0);
  double len = v3_len(ray.d);
  if (!(len > 0)) return L;
  ray.d = v3_scale(ray.d, 1.0 / len);
  ray.tmin *= len;
  ray.tmax *= len;
  const medium *m = start_medium(sc, st);
  int depth = 0, crossings = 0;
  double eta = 1.0;
  /* The last scattering vertex, for MIS at emitters found by sampling. */
  surface_interaction prev = {0};
  double prev_pdf = 1.0;
  bool prev_delta = true;
  /* Where the current ray really starts (the traced ray's origin is
   * offset off surfaces): media integrate from here to the exact hit. */
  vec3 seg_o = ray.o;
  if (it->max_depth == 0) return L;
  for (;;) {
    surface_interaction si;
    bool hit = intersect(sc, &ray, &si, stats);
    double tsurf = hit ? si.t : ray.tmax;

    /* ---- the medium along [0, tsurf] ---- */
    medium_interaction mi;
    bool scattered = false;
    if (m) {
      ray3 seg = {seg_o, ray.d, 0.0, hit ? v3_dot(v3_sub(si.p, seg_o), ray.d) : tsurf};
      double mint, maxt;
      if (m->ops->intersect_aabb(m, &seg, &mint, &maxt)) {
        if (m->absorbing_only) {
          T = col_mul(T, segment_tr(vp, m, &seg, seg.tmax, st));
        } else if (analytic_in(vp, m)) {
          int c = pick_channel(m, st);
          color tr, pdf;
          m->ops->sample_real(m, &seg, mint, maxt, sops->next_1d(st), c, &mi, &tr, &pdf);
          double pc = col_mean(pdf);
          if (isfinite(mi.t)) {
            scattered = true;
            T = pc > 0 ? col_scale(col_mul(T, col_mul(tr, mi.sigma_s)), 1.0 / pc) : col1(0.0);
          } else {
            T = pc > 0 ? col_scale(col_mul(T, tr), 1.0 / pc) : col1(0.0);
          }
        } else {
          mi = (medium_interaction){.medium = m, .wi = v3_neg(ray.d), .mint = mint};
          mi.p = v3_fma(seg.o, mint, ray.d);
          double mu = col_max(m->ops->majorant(m, &mi));
          double t = mint;
          while (mu > 0) {
            t -= log1p(-sops->next_1d(st)) / mu;
            if (!(t < maxt)) break;
            mi.t = t;
            mi.p = v3_fma(seg.o, t, ray.d);
            mi.majorant = col1(mu);
            m->ops->coefficients(m, &mi);
            int c = pick_channel(m, st);
            double p_real = mi.sigma_t.c[c] / mu;
            if (sops->next_1d(st) < p_real) {
              T = col_scale(col_mul(T, mi.sigma_s), 1.0 / mi.sigma_t.c[c]);
              scattered = true;
              break;
            }
            T = col_scale(col_mul(T, mi.sigma_n), 1.0 / (mu - mi.sigma_t.c[c]));
            if (col_max(T) <= 0) return L;
          }
        }
      }
    }
    if (col_max(T) <= 0) return L;

    if (scattered) {
      /* ---- a scattering event in the medium ---- */
      if (!(it->max_depth < 0 || depth + 1 < it->max_depth)) return L;
      const phase *ph = m->phase;
      surface_interaction ref = {.p = mi.p, .t = mi.t};
      if (m->sample_emitters && sc->n_emitters > 0) {
        double pe;
        size_t k = pick_emitter(sc, sops->next_1d(st), &pe);
        const emitter *e = sc->emitters[k];
        direction_sample ds;
        color value = e->ops->sample_direction(e, &ref, sops->next_2d(st), &ds);
        if (ds.pdf > 0 && !col_is_black(value)) {
          double ppdf;
          double pval = ph->ops->eval_pdf(ph, &mi, ds.d, &ppdf);
          if (pval > 0) {
            color tr = shadow_tr(vp, sc, shadow_ray(sc, NULL, mi.p, e, &ds), mi.p, m, st, stats);
            double w = ds.delta ? 1.0 : mis_weight(ds.pdf * pe, ppdf);
            L = col_add(L, col_scale(col_mul(T, col_mul(value, tr)), pval * w / pe));
          }
        }
      }
      vec3 wo;
      double ppdf;
      double pw = ph->ops->sample(ph, &mi, sops->next_1d(st), sops->next_2d(st), &wo, &ppdf);
      if (!(ppdf > 0) || !(pw > 0)) return L;
      T = col_scale(T, pw);
      ray = (ray3){mi.p, wo, 0.0, INFINITY};
      seg_o = mi.p;
      prev = ref;
      prev_pdf = ppdf;
      prev_delta = false;
      crossings = 0;
    } else {
      /* ---- the surface (or the escape) ---- */
      bool visible = !(it->hide_emitters && depth == 0);
      if (!hit) {
        const emitter *env = sc->environment;
        if (env && visible) {
          double em_pdf = 0.0;
          if (!prev_delta) {
            direction_sample ds = {.d = ray.d, .dist = INFINITY};
            em_pdf = env->ops->pdf_direction(env, &prev, &ds) * emitter_prob(sc, env);
          }
          L = col_add(L, col_scale(col_mul(T, env->ops->eval(env, NULL, ray.d)), mis_weight(prev_pdf, em_pdf)));
        }
        return L;
      }
      const emitter *em = si.shape->emitter;
      if (em && visible) {
        color Le = em->ops->eval(em, &si, ray.d);
        if (!col_is_black(Le)) {
          double em_pdf = 0.0;
          if (!prev_delta) {
            direction_sample ds = {.p = si.p, .n = si.ng, .d = ray.d, .dist = v3_len(v3_sub(si.p, prev.p))};
            em_pdf = em->ops->pdf_direction(em, &prev, &ds) * emitter_prob(sc, em);
          }
          L = col_add(L, col_scale(col_mul(T, Le), mis_weight(prev_pdf, em_pdf)));
        }
      }
      const bsdf *b = si.shape->bsdf;
      if (b->flags & BSDF_INDEX_MATCHED) { /* crossed without a bounce */
        if (++crossings > MAX_CROSSINGS) return L;
        m = medium_after(&si, ray.d, m);
        ray = spawn_ray(&si, ray.d);
        seg_o = si.p;
        continue;
      }
      if (!(it->max_depth < 0 || depth + 1 < it->max_depth)) return L;
      if ((b->flags & BSDF_SMOOTH) && sc->n_emitters > 0) {
        double pe;
        size_t k = pick_emitter(sc, sops->next_1d(st), &pe);
        const emitter *e = sc->emitters[k];
        direction_sample ds;
        color value = e->ops->sample_direction(e, &si, sops->next_2d(st), &ds);
        if (ds.pdf > 0 && !col_is_black(value)) {
          vec3 wo = frame_to_local(&si.sh, ds.d);
          color f = b->ops->eval(b, &si, wo);
          if (!col_is_black(f)) {
            color tr = shadow_tr(vp, sc, shadow_ray(sc, &si, si.p, e, &ds), si.p, medium_after(&si, ds.d, m), st,
                                 stats);
            double bpdf = ds.delta ? 0.0 : b->ops->pdf(b, &si, wo);
            double w = ds.delta ? 1.0 : mis_weight(ds.pdf * pe, bpdf);
            L = col_add(L, col_scale(col_mul(T, col_mul(f, col_mul(value, tr))), w / pe));
          }
        }
      }
      bsdf_sample bs;
      color weight = b->ops->sample(b, &si, sops->next_1d(st), sops->next_2d(st), &bs);
      if (!(bs.pdf > 0) || col_is_black(weight)) return L;
      vec3 wo = frame_to_world(&si.sh, bs.wo);
      T = col_mul(T, weight);
      eta *= bs.eta;
      m = medium_after(&si, wo, m);
      ray = spawn_ray(&si, wo);
      seg_o = si.p;
      prev = si;
      prev_pdf = bs.pdf;
      prev_delta = (bs.sampled_type & BSDF_DELTA) != 0;
      crossings = 0;
    }
    depth++;
    if (depth >= it->rr_depth) {
      double q = fmin(col_max(T) * eta * eta, 0.95);
      if (!(sops->next_1d(st) < q)) return L;
      T = col_scale(T, 1.0 / q);
    }
    if (!(col_max(T) > 0)) return L;
  }
}

static const integrator_ops volpath_ops = {.Li = volpath_Li};

static void volpath_destroy(object *o) {
  free(o);
}

static rsw_status create_common(loader *ld, node *n, object **out, bool analytic) {
  volpath_integrator *vp = calloc(1, sizeof *vp);
  if (!vp) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  vp->base.ops = &volpath_ops;
  vp->analytic = analytic;
  long long md, rr;
  rsw_status st = ld_int(ld, n, "max_depth", -1, -1, 1 << 30, &md);
  if (!st) st = ld_int(ld, n, "rr_depth", 5, 1, 1 << 30, &rr);
  if (!st) st = ld_bool(ld, n, "hide_emitters", false, &vp->base.hide_emitters);
  if (st) {
    free(vp);
    return st;
  }
  vp->base.max_depth = (int)md;
  vp->base.rr_depth = (int)rr;
  *out = &vp->base.base;
  return RSW_OK;
}

static rsw_status volpath_create(loader *ld, node *n, object **out) {
  return create_common(ld, n, out, false);
}

static rsw_status piecewise_volpath_create(loader *ld, node *n, object **out) {
  return create_common(ld, n, out, true);
}

const plugin plugin_volpath = {.name = "volpath",
                               .cls = CLS_INTEGRATOR,
                               .create = volpath_create,
                               .destroy = volpath_destroy,
                               .ops = &volpath_ops};

const plugin plugin_piecewise_volpath = {.name = "piecewise_volpath",
                                         .cls = CLS_INTEGRATOR,
                                         .create = piecewise_volpath_create,
                                         .destroy = volpath_destroy,
                                         .ops = &volpath_ops};
