/* `volpath` and `piecewise_volpath`: volumetric path tracers (Mitsuba 3's
 * volpath, mitsuba3 src/integrators/volpath.cpp; Eradiate's
 * piecewise_volpath, eradiate/mitsuba3
 * src/eradiate_plugins/integrators/piecewise_volpath.cpp;
 * docs/kernel-conventions.md#volumetric-path-tracing). Surfaces behave as in `path` (NEE towards one
 * emitter, MIS with BSDF sampling, power heuristic); inside a medium a
 * path also scatters, with NEE and MIS against phase sampling.
 *
 * Media. A path starts in its sensor's medium and changes medium where it
 * crosses a shape whose interior and exterior differ (Mitsuba's
 * is_medium_transition): it goes into the exterior when it leaves along
 * the normal, else into the interior. A `null` BSDF (BSDF_INDEX_MATCHED)
 * is crossed without a bounce, by camera, scattered and shadow rays.
 * Null boxes (a `null` cube, or any 12-triangle mesh that is exactly a
 * box, scene->null_boxes, media/media.h) are crossed analytically
 * instead: the queries leave them out (an Embree ray mask, accel.h) and
 * each segment between two hits is cut where it enters or leaves a box
 * (a slab test in double), the medium changing there as at a traced
 * crossing, with the same draws in the same order; rays that cannot meet
 * the rest of the geometry are not traced at all (may_hit). An
 * atmosphere's cube then costs no query: a path through it is its camera
 * ray, and its shadow and escaping rays none. `path` and every other
 * integrator trace the boxes as before.
 *
 * Free flight along a segment [0, t_s] (t_s: the next surface), with
 * unit directions so that t is a length:
 *  - tracking (volpath, media whose coefficients vary): delta tracking
 *    against the scalar majorant mu (the largest over the channels):
 *    tentative collisions t ~ mu e^{-mu t}, each real with probability
 *    P = mean_c sigma_t,c / mu (then T *= sigma_s / (mu P): the albedo in
 *    mono) and null otherwise (T *= sigma_n / (mu (1 - P)): 1 in mono).
 *    Mitsuba decides with one channel's sigma_t,c / mu instead, which
 *    never takes a null collision where sigma_t,c = mu although other
 *    channels have sigma_n > 0 (biased for chromatic extinction); the
 *    channel mean (Kutz et al. 2017, spectral tracking) covers them all.
 *  - analytic (homogeneous media in both integrators, every medium with
 *    medium_ops.sample_real in piecewise_volpath): t is drawn by
 *    inverting the optical thickness in a channel c (uniform over the
 *    three when sigma_t differs between them, else 0), and with pdf the
 *    mean of the channels' densities (the density t was drawn with),
 *    T *= tr sigma_s / pdf at a collision (the albedo in mono) and
 *    tr / pdf when the flight passes t_s (1 in mono).
 *  - a medium with no scattering (medium.absorbing_only) is not sampled:
 *    T *= transmittance over the segment, exact in analytic media (the
 *    Beer-Lambert tests are noise-free) and ratio-tracked otherwise.
 * Transmittance along shadow rays: exact in analytic media, ratio tracking
 * (T *= sigma_n / mu per tentative collision, with Russian roulette once
 * the estimate falls below 0.1) otherwise; null surfaces are crossed, any
 * other surface blocks. Stokes films of the unpolarized variants get Q =
 * U = V = 0 (no polarisation through media); the polarized variants carry
 * Mueller factors (integrators/polarization.h).
 *
 * Estimator: L = sum over vertices of T (Le w_bsdf + NEE w_em); at a
 * medium vertex, NEE = p(wi, wo) Le tr / (pdf_em p_pick) with MIS weight
 * w(pdf_em p_pick, pdf_phase) and phase sampling weight p / pdf (1 for
 * exact sampling). A bounce is a surface or medium scattering event (null
 * surfaces and null collisions are not); max_depth counts as in `path`
 * (2: single scattering). Russian roulette from rr_depth, only while
 * w = max(T) eta^2 < 1, with survival q = min(w, 0.95); from
 * RR_BACKSTOP_DEPTH bounces on at every bounce (docs/media.md#dense-media-the-roulette-and-the-segment-lengths:
 * Mitsuba's rule, q = min(w, 0.95) at every bounce, starves dense
 * conservative media, where T stays 1 over the ~tau^2 scatterings a path
 * needs to cross them; rr_rule "mitsuba" keeps it). Emitting media are
 * not supported (none of the media plugins emits).
 *
 * The sensor's medium: Li does not receive the sensor, so the path's first
 * medium is that of the sensor whose sampler drives it (st->s); sensors
 * sharing a sampler must share a medium (scene_check_media says so).
 *
 * The paths run as a wave (below): in stages over its lanes where the
 * scene has neither pages nor polarization (wave_events), so that each
 * stage can call the batched ops for all its lanes (the samplers' draws,
 * the emitters' light samples; per lane still: free flights, phase
 * functions and BSDFs), else lane by lane (lane_event); the same film bit
 * for bit either way (tests/kernel/integrators/test_volpath_stages.c). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../accel.h"
#include "../hit.h"
#include "../media/layered.h"
#include "../media/majorant_grid.h"
#include "../phase/phase.h"
#include "../samplers/sampler_batch.h"
#include "../scene/periodic.h"
#include "../scene/plugin_def.h"
#include "../shapes/instance.h"
#include "../shapes/shape.h"
#include "integrator.h"
#include "pages.h"
#include "polarization.h"
#include "wave.h"

typedef struct volpath_integrator {
  integrator base;
  bool analytic;   /* piecewise_volpath */
  bool rr_mitsuba; /* rr_rule "mitsuba": the roulette at every bounce from rr_depth */
} volpath_integrator;

enum {
  MAX_CROSSINGS = 1024, /* null surfaces crossed by one ray before it counts as lost */
  /* From this many bounces on, the roulette runs whatever the throughput
   * (survival min(max T eta^2, 0.95), Mitsuba's), so that a path in a
   * lossless medium with no way out (an unbounded albedo-1 medium) ends.
   * A conservative slab of optical thickness tau holds a path beyond n
   * scatterings with probability ~ exp(-n pi^2 / (3 tau^2)) (diffusion's
   * slowest mode): about e^-21 at n = 65536 for tau = 100, so the paths
   * it reaches carry a negligible share of the flux. */
  RR_BACKSTOP_DEPTH = 1 << 16
};

/* The emitter u picks and its selection probability. */
static size_t pick_emitter(const scene *sc, double u, double *prob) {
  size_t k = pick_emitter_index(sc, u);
  *prob = pick_probability(sc, k);
  return k;
}

/* Can ray r meet the scene's bounding box on [tmin, tmax]? A ray that has
 * left it (through an atmosphere's top, say) can hit nothing more, so
 * it needs no query. Not under a periodic boundary (copies beyond the
 * column). */
typedef struct hit_bounds {
  int fixed;           /* -1: decide per ray; 0 or 1: every ray's answer */
  double lo[3], hi[3]; /* the bounds */
  double pl[3], ph[3]; /* the same, padded */
} hit_bounds;

/* What may_hit needs of the scene, worked out once per wave. */
static void hit_bounds_init(const scene *sc, hit_bounds *b) {
  b->fixed = -1;
  if (sc->periodic.on) {
    b->fixed = 1;
    return;
  }
  /* With null boxes crossed analytically, the queries leave them out:
   * the bounds of the rest decide. */
  vec3 bl = sc->null_boxes.on ? sc->null_boxes.rest_min : sc->bbox_min;
  vec3 bh = sc->null_boxes.on ? sc->null_boxes.rest_max : sc->bbox_max;
  if (!(bl.x <= bh.x)) {
    b->fixed = !sc->null_boxes.on; /* nothing else to hit */
    return;
  }
  const double lo[3] = {bl.x, bl.y, bl.z};
  const double hi[3] = {bh.x, bh.y, bh.z};
  for (int a = 0; a < 3; a++) {
    double pad = 1e-9 * (fabs(lo[a]) + fabs(hi[a]) + 1.0);
    b->lo[a] = lo[a], b->hi[a] = hi[a];
    b->pl[a] = lo[a] - pad, b->ph[a] = hi[a] + pad;
  }
}

/* Can ray r meet the scene's bounding box on [tmin, tmax]? A ray that has
 * left it (through an atmosphere's top, say) can hit nothing more, so
 * it needs no query. Not under a periodic boundary (copies beyond the
 * column). b: hit_bounds_init's. */
static bool may_hit_in(const hit_bounds *b, const ray3 *r) {
  if (b->fixed >= 0) return b->fixed;
  const double *lo = b->lo, *hi = b->hi, *pl = b->pl, *ph = b->ph;
  const double o[3] = {r->o.x, r->o.y, r->o.z}, d[3] = {r->d.x, r->d.y, r->d.z};
  if (o[0] >= lo[0] && o[0] <= hi[0] && o[1] >= lo[1] && o[1] <= hi[1] && o[2] >= lo[2] && o[2] <= hi[2])
    return true; /* most rays start inside */
  for (int a = 0; a < 3; a++) {
    /* Outside a slab and moving away from it (a ray leaving the ground
     * upwards, say): no division needed. */
    if ((o[a] < pl[a] && !(d[a] > 0)) || (o[a] > ph[a] && !(d[a] < 0))) return false;
  }
  double t0 = r->tmin, t1 = r->tmax;
  for (int a = 0; a < 3; a++) {
    double l = pl[a], h = ph[a];
    if (d[a] == 0.0) continue; /* inside that slab (above) */
    double inv = 1.0 / d[a];   /* (the padding covers the rounding) */
    double tl = (l - o[a]) * inv, th = (h - o[a]) * inv;
    double ta = rsw_sel_min(th, tl), tb = rsw_sel_max(tl, th); /* (tl > th ? th : tl, tl > th ? tl : th) */
    t0 = ta > t0 ? ta : t0; /* (no fmin/fmax calls: a NaN never gets here) */
    t1 = tb < t1 ? tb : t1;
    if (t0 > t1) return false;
  }
  return true;
}

static bool may_hit(const scene *sc, const ray3 *r) {
  hit_bounds b;
  hit_bounds_init(sc, &b);
  return may_hit_in(&b, r);
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

/* Null boxes crossed analytically (scene->null_boxes.on; the queries
 * leave them out). box_walk_start: the slab test of o + t d (unit d)
 * against every box, in double (in world coordinates for a box under a
 * scale and translation, else in its object space). box_walk_next: the
 * next crossing after the last one (t > tc, or t == tc and a later
 * crossing index: crossings at one t are taken in a fixed order) and
 * before tend, and the medium beyond it (*m); false when there is none.
 * Entering a box leads into its inside medium, leaving it into the
 * outside one, as the hit's normal would say (a box with one medium on
 * both sides changes nothing). */
typedef struct box_walk {
  double inv[3];                      /* 1 / d per world axis (where d != 0): media_clip shares it */
  double t[2 * SCENE_NULL_BOXES_MAX]; /* per box: entry, exit (or +inf: missed) */
  double tc;                          /* the last crossing taken */
  int ic;
} box_walk;

static inline __attribute__((always_inline)) void box_walk_start(const scene *sc, vec3 o, vec3 d,
                                                                 box_walk *w) {
  w->tc = 0.0;
  w->ic = -1;
  const double dw[3] = {d.x, d.y, d.z};
  for (int a = 0; a < 3; a++) w->inv[a] = dw[a] != 0.0 ? 1.0 / dw[a] : 0.0;
  for (unsigned i = 0; i < sc->null_boxes.n; i++) {
    const struct scene_null_box *b = &sc->null_boxes.box[i];
    double oo[3], dd[3];
    const double *lo = b->wlo, *hi = b->whi;
    if (b->aligned) {
      oo[0] = o.x, oo[1] = o.y, oo[2] = o.z;
      dd[0] = d.x, dd[1] = d.y, dd[2] = d.z;
    } else {
      vec3 ol = xf_inv_point(&b->sh->to_world, o), dl = xf_inv_vector(&b->sh->to_world, d);
      oo[0] = ol.x, oo[1] = ol.y, oo[2] = ol.z;
      dd[0] = dl.x, dd[1] = dl.y, dd[2] = dl.z;
      lo = b->lo, hi = b->hi;
    }
    double tn = -INFINITY, tf = INFINITY;
    for (int a = 0; a < 3; a++) {
      if (dd[a] == 0.0) {
        if (oo[a] < lo[a] || oo[a] > hi[a]) tn = INFINITY;
        continue;
      }
      double inv = b->aligned ? w->inv[a] : 1.0 / dd[a]; /* (the same quotient) */
      double ta = (lo[a] - oo[a]) * inv, tb = (hi[a] - oo[a]) * inv;
      double t0 = rsw_sel_min(tb, ta), t1 = rsw_sel_max(ta, tb); /* (ta > tb ? tb : ta, ta > tb ? ta : tb) */
      tn = t0 > tn ? t0 : tn;
      tf = t1 < tf ? t1 : tf;
    }
    bool met = tn <= tf;
    w->t[2 * i] = met ? tn : INFINITY;
    w->t[2 * i + 1] = met ? tf : INFINITY;
  }
}

static inline bool box_walk_next(const scene *sc, box_walk *w, double tend, const medium **m) {
  double best = INFINITY;
  int bi = -1;
  for (int id = 0; id < 2 * (int)sc->null_boxes.n; id++) {
    double t = w->t[id];
    bool after = t > w->tc || (t == w->tc && id > w->ic);
    if (after && t < tend && t < best) best = t, bi = id;
  }
  if (bi < 0) return false;
  const struct scene_null_box *b = &sc->null_boxes.box[bi / 2];
  if (b->sh->interior != b->sh->exterior) *m = (bi & 1) ? b->out : b->in;
  w->tc = best;
  w->ic = bi;
  return true;
}

/* The null box whose world bounds are, bit for bit, those of layered
 * medium m's box, both aligned (an atmosphere's cube); -1: none. */
static inline int media_null_box(const scene *sc, const medium *m) {
  const media_box *mb = &((const layered_medium *)m)->L.box;
  if (!mb->aligned) return -1;
  for (unsigned i = 0; i < sc->null_boxes.n; i++) {
    const struct scene_null_box *b = &sc->null_boxes.box[i];
    if (b->aligned && memcmp(b->wlo, mb->lo, sizeof mb->lo) == 0 &&
        memcmp(b->whi, mb->hi, sizeof mb->hi) == 0)
      return (int)i;
  }
  return -1;
}

/* m's part of segment r: intersect_aabb, or for a layered medium its box
 * clipped with w's 1 / d (box_walk's, for r's direction and origin; NULL:
 * none), the same bit for bit. Where that box is one of the null boxes
 * the walk has met already (media_null_box), its slab interval is
 * [tn, tf] = [max over the axes of the entries, min of the exits] (both
 * +inf when missed), and the clip is [max(tmin, tn), min(tmax, tf)]:
 * the same maximum and minimum of the same numbers as the slab test
 * below (ties keep the earlier operand, tmin or tmax, in both). */
static inline bool media_clip_at(const scene *sc, const medium *m, const ray3 *r, const box_walk *w, int i,
                                 double *mint, double *maxt) {
  if (w && m->ops == &layered_medium_ops) {
    if (i >= 0) {
      double tn = w->t[2 * i], tf = w->t[2 * i + 1];
      double lo = tn > r->tmin ? tn : r->tmin, hi = tf < r->tmax ? tf : r->tmax;
      if (!(lo < hi)) return false;
      *mint = lo;
      *maxt = hi;
      return true;
    }
    const media_box *b = &((const layered_medium *)m)->L.box;
    if (b->aligned) return media_box_clip_aligned(b, r->o, r->d, r->tmin, r->tmax, w->inv, mint, maxt);
  }
  return m->ops->intersect_aabb(m, r, mint, maxt);
}

/* media_clip_at with i = media_null_box(sc, m) (looked up only for a
 * layered medium under a box walk). */
static inline bool media_clip(const scene *sc, const medium *m, const ray3 *r, const box_walk *w,
                              double *mint, double *maxt) {
  int i = w && m->ops == &layered_medium_ops ? media_null_box(sc, m) : -1;
  return media_clip_at(sc, m, r, w, i, mint, maxt);
}

/* The atmosphere's case, worked out once per wave: the scene's only null
 * box holds a layered medium (m), sampled analytically, with no medium
 * outside the box; nbi: media_null_box(sc, m). m NULL: not so. The walks
 * of rays that start inside the box (its entry behind them, its exit
 * ahead) then take a short way (shadow_step) with the walk's numbers. */
typedef struct one_box {
  const medium *m;
  int nbi;
} one_box;

static one_box one_box_of(const volpath_integrator *vp, const scene *sc) {
  one_box ob = {NULL, -1};
  if (!sc->null_boxes.on || sc->null_boxes.n != 1 || !vp->analytic) return ob;
  const struct scene_null_box *b = &sc->null_boxes.box[0];
  const medium *m = b->in;
  if (b->sh->interior == b->sh->exterior || b->out || !m || m->ops != &layered_medium_ops ||
      m->absorbing_only)
    return ob;
  ob.m = m;
  ob.nbi = media_null_box(sc, m);
  return ob;
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

/* Whether segment_tr is exact in m (else it tracks). */
static bool exact_in(const volpath_integrator *vp, const medium *m) {
  return (m->ops == &layered_medium_ops && vp->analytic) ||
         (m->ops->transmittance && (analytic_in(vp, m) || m->is_homogeneous));
}

/* A bundle of pages: the majorant over every page's channels at mi (a
 * tracked medium's free flights and ratio tracks serve all pages at once). */
static double majorant_pages(const medium *m, const medium_interaction *mi, int pages) {
  double mu = 0.0;
  for (int p = 0; p < pages; p++) {
    rsw_page = p;
    mu = fmax(mu, col_max(m->ops->majorant(m, mi)));
  }
  rsw_page = 0;
  return mu;
}

/* A bundle of pages: the coefficients of m at mi (t, p set) at every page
 * against the shared majorant mu (sigma_n = mu - sigma_t per channel); mi
 * keeps page 0's. Returns the mean of the 3 pages channels' sigma_t. */
static double coefficients_pages(const medium *m, medium_interaction *mi, double mu, int pages, color *ss,
                                 color *sn) {
  double mean = 0.0;
  medium_interaction q = *mi;
  for (int p = pages - 1; p >= 0; p--) {
    rsw_page = p;
    q.majorant = col1(mu);
    m->ops->coefficients(m, &q);
    ss[p] = q.sigma_s;
    for (int c = 0; c < 3; c++) sn[p].c[c] = fmax(mu - q.sigma_t.c[c], 0.0);
    mean += col_mean(q.sigma_t);
  }
  rsw_page = 0;
  *mi = q; /* (page 0's, the last) */
  mi->sigma_n = sn[0];
  return mean / pages;
}

/* A tracking loop's guard (docs/media.md#tracks-given-up). A track is
 * given up, and its path counted as unresolved (render_stats.unresolved),
 * after TRACK_MAX_STEPS tentative collisions, or after TRACK_MAX_STUCK in
 * a row that no longer move t: a majorant whose mean free path is below
 * the resolution of t (1e91 per metre at t = 1 takes steps of 1e-91,
 * which t + dt rounds away) would otherwise loop for ever, and a
 * majorant millions of times the density it bounds for the life of the
 * render (a deadline or a cancel is asked between bounces, not within a
 * track). A track given up scatters nothing and transmits nothing: its
 * path ends there. */
#define TRACK_MAX_STEPS (1u << 20)
#define TRACK_MAX_STUCK 64u

typedef struct track_guard {
  unsigned steps, stuck;
} track_guard;

/* t advanced by dt (a free flight's step); false: give the track up. */
static inline bool track_step(track_guard *g, double *t, double dt) {
  double tn = *t + dt;
  g->stuck = tn > *t ? 0 : g->stuck + 1;
  *t = tn;
  return ++g->steps <= TRACK_MAX_STEPS && g->stuck <= TRACK_MAX_STUCK;
}

/* The walk of a track of m along r over [mint, maxt] (media/majorant_grid.h):
 * m's local majorants where it has them, else one piece at mu, the
 * majorant that the track would take without them. rrt (a transmittance's
 * track where m->use_rrt): each piece's control is its minorant (the
 * cell's, else the medium's), else 0. */
static inline void track_walk_start(const medium *m, const ray3 *r, double mint, double maxt, double mu,
                                    bool rrt, track_walk *w) {
  if (!m->ops->majorant_walk || !m->ops->majorant_walk(m, r, mint, maxt, rrt, w))
    track_walk_global(w, mu, rrt && m->ops->minorant ? m->ops->minorant(m) : 0.0);
}

/* Does the walk take tentative collisions at all from where it is (a
 * piece ahead, or a residual majorant on the last)? */
static inline bool track_walk_live(const track_walk *w) {
  return w->mu - w->ctl > 0 || w->b < INFINITY;
}

/* A track's next tentative collision from *t: optical thickness tau (in
 * units of the residual majorant mu - ctl, -ln(1 - u)) spent over the
 * walk's pieces, those of residual 0 crossed for free; *ctl_tau gains the
 * control's optical thickness over the way travelled (residual ratio
 * tracking, Novak et al. 2014; 0 without a control). 1: a collision at
 * *t < maxt, at majorant w->mu; 0: the track passes maxt; -1: given up
 * (track_step). With one piece and no control this is t + tau / mu, the
 * global majorant's step, bit for bit. */
static inline int walk_step(track_walk *w, track_guard *g, double *t, double tau, double maxt,
                            double *ctl_tau) {
  while (w->b < INFINITY) {
    double len = w->b - *t;
    if (len > 0) {
      double res = w->mu - w->ctl;
      if (res > 0 && tau < res * len) break;
      tau -= res * len;
      *ctl_tau += w->ctl * len;
      *t = w->b;
    }
    track_walk_next(w);
  }
  double res = w->mu - w->ctl, t0 = *t;
  if (!(res > 0)) {
    *ctl_tau += w->ctl * (maxt - t0);
    return 0;
  }
  if (!track_step(g, t, tau / res)) return -1;
  bool in = *t < maxt;
  *ctl_tau += w->ctl * ((in ? *t : maxt) - t0);
  return in;
}

/* The transmittance of a tracked medium m along r over [tstart, tend] at
 * pages 0..pages-1 into tr[p] (one page: segment_tr's), by one ratio track
 * for all: each page's sigma_n over the majorant of every page's channels,
 * so that each page's estimate is unbiased, and a roulette on the largest
 * page's weight below 0.1 that keeps long tracks bounded (unbiased).
 * False: the track was given up (track_step), tr is 0. */
static __attribute__((noinline)) bool segment_tr_pages(const scene *sc, const medium *m, const ray3 *r,
                                                       double tstart, double tend, const box_walk *w,
                                                       sampler_state *st, int pages, color *tr) {
  for (int p = 0; p < pages; p++) tr[p] = col1(1.0);
  ray3 seg = *r;
  seg.tmin = tstart;
  seg.tmax = tend;
  double mint, maxt;
  if (!media_clip(sc, m, &seg, w, &mint, &maxt)) return true;
  const sampler_ops *sops = st->s->ops;
  medium_interaction mi = {.medium = m, .wi = v3_neg(r->d)};
  mi.p = v3_fma(r->o, mint, r->d);
  track_walk tw;
  track_walk_start(m, r, mint, maxt, majorant_pages(m, &mi, pages), m->use_rrt, &tw);
  double ctl_tau = 0.0; /* (residual ratio tracking: the control's part, exact) */
  if (!track_walk_live(&tw)) {
    if (tw.ctl > 0)
      for (int p = 0; p < pages; p++) tr[p] = col1(exp(-tw.ctl * (maxt - mint)));
    return true;
  }
  color ss[RENDER_MAX_PAGES], sn[RENDER_MAX_PAGES];
  double t = mint;
  track_guard g = {0, 0};
  for (;;) {
    int ev = walk_step(&tw, &g, &t, -log1p(-sops->next_1d(st)), maxt, &ctl_tau);
    if (ev < 0) {
      for (int p = 0; p < pages; p++) tr[p] = col1(0.0);
      return false;
    }
    if (ev == 0) break;
    double mu = tw.mu;
    mi.t = t;
    mi.p = v3_fma(r->o, t, r->d);
    coefficients_pages(m, &mi, mu, pages, ss, sn);
    double q = 0.0, k = 1.0 / (mu - tw.ctl); /* (sigma_n over the residual majorant) */
    for (int p = 0; p < pages; p++) {
      tr[p] = col_mul(tr[p], col_scale(sn[p], k));
      q = fmax(q, col_max(tr[p]));
    }
    if (q <= 0) break;
    if (q < 0.1) { /* (segment_tr's roulette, on the largest page) */
      bool live = sops->next_1d(st) < q;
      for (int p = 0; p < pages; p++) tr[p] = live ? col_scale(tr[p], 1.0 / q) : col1(0.0);
      if (!live) break;
    }
  }
  if (ctl_tau > 0) {
    double c = exp(-ctl_tau);
    for (int p = 0; p < pages; p++) tr[p] = col_scale(tr[p], c);
  }
  return true;
}

/* Transmittance of m along r over [tstart, tend] (a shadow ray's segment):
 * exact where analytic, else ratio tracking (segment_tr_pages' one page;
 * a track given up sets *unres and transmits nothing). */
static color segment_tr(const volpath_integrator *vp, const scene *sc, const medium *m, const ray3 *r,
                        double tstart, double tend, const box_walk *w, sampler_state *st, bool *unres) {
  ray3 seg = *r;
  seg.tmin = tstart;
  seg.tmax = tend;
  double mint, maxt;
  if (!media_clip(sc, m, &seg, w, &mint, &maxt)) return col1(1.0);
  if (m->ops == &layered_medium_ops && vp->analytic) /* (inline: the same code as its op) */
    return media_layers_transmittance(layered_layers(m), &seg, mint, maxt);
  if (m->ops->transmittance && (analytic_in(vp, m) || m->is_homogeneous))
    return m->ops->transmittance(m, &seg, mint, maxt);
  color tr;
  if (!segment_tr_pages(sc, m, r, tstart, tend, w, st, 1, &tr)) *unres = true;
  return tr;
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
    ray3 r = {p, len > 0 ? v3_scale(d, 1.0 / len) : ds->d, 0.0,
              len * (1.0 - RSW_SPAWN_ERRORS * RSW_F32_UNIT)};
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

/* ---- the wave -------------------------------------------------------------
 *
 * Paths advance together, event by event (as `path`'s wave): the rays of
 * the live lanes are traced as Embree packets (one by one under a
 * periodic boundary; a ray that has left the scene's bounds is not traced
 * at all) and their hits filled together (hit_fill_interaction_batch),
 * then the lanes handle their segments: the free flight through the
 * medium, then the scattering event, the surface, the null surface
 * crossed or the escape, which sets up the shadow ray (next-event
 * estimation) and the next ray. Without pages or polarization this goes
 * in stages over the lanes (wave_events: the flights, the surfaces, the
 * scatterings, the roulette, each stage drawing its numbers for all its
 * lanes at once), else lane by lane (lane_event); both are made of the
 * same pieces and give the same film bit for bit. The shadow rays are
 * then traced together, round after round while some cross null
 * surfaces, each lane accumulating its transmittance. A lane draws from
 * its own sampler state only, always in the same order (free flight,
 * light sample, phase or BSDF sample, roulette, then the shadow ray's
 * ratio tracking), so its value does not depend on its batch (up to
 * Embree's packet rounding, accel.h); Li is the wave of one path. */

typedef struct vlane {
  ray3 ray;   /* the ray to trace (its origin offset off the surface it leaves) */
  vec3 seg_o; /* where the ray really starts: media integrate from here */
  const medium *m;
  color T, L;
  double eta, prev_pdf;
  bool prev_delta;
  surface_interaction prev; /* the last scattering vertex (its p), for MIS */
  int depth, crossings;
  bool hit;   /* (its hit record stays in wave_run's array) */
  bool unres; /* a track given up (track_step): counted in render_stats.unresolved */
  /* The shadow ray of this event, while it is being traced. */
  bool sh;
  ray3 sray;
  vec3 sp0, send; /* its exact start, its end (sfinite) */
  bool sfinite;
  const medium *sm;
  color sval; /* the contribution if unoccluded: T f Le w / pe */
  color str;  /* transmittance so far */
  int scross;
} vlane;

/* A bundle of pages (render_ctx.bundle > 3, piecewise_volpath;
 * docs/experiments.md#pages-more-than-three-wavelengths-per-path): a lane's
 * throughput, radiance, shadow contribution and shadow transmittance at
 * pages 1.. (page 0's are the lane's). The path is sampled once for all
 * pages: a free flight inverts one channel of the 3 P the bundle carries,
 * picked at random, and every page is weighted by its own transmittance
 * (and scattering coefficient) over the mean of the 3 P channels'
 * densities, as a bundle of three does with its three; the phase
 * direction is drawn with page 0's mixture and each page weighted by its
 * own value over that density; surfaces as `path` (integrators/pages.h);
 * the roulette on the largest throughput of any page. */
typedef struct vpage {
  color T[RENDER_MAX_PAGES - 1], L[RENDER_MAX_PAGES - 1];
  color sval[RENDER_MAX_PAGES - 1], str[RENDER_MAX_PAGES - 1];
  /* The path's hero channel for its free flights (-1: none drawn yet)
   * and the weights of the 3 P channels given the flights so far
   * (draw_hero, flight_pages, track_pages: path-level spectral MIS). */
  int hero;
  double post[3 * RENDER_MAX_PAGES];
} vpage;

/* The largest value of x (page 0's) and of pages 1.. of a (pg NULL: x's). */
static inline double pages_max(color x, const vpage *pg, const color *a, int pages) {
  double m = col_max(x);
  for (int p = 1; pg && p < pages; p++) m = fmax(m, col_max(a[p - 1]));
  return m;
}

/* Fill the pending hits' interactions (hit_fill_interaction_batch:
 * bitwise hit_fill_interaction's, the frames vectorised). */
static void fill_hits(const scene *sc, int n, const ray3 *const *r, const accel_hit *h,
                      surface_interaction *si, const int *k) {
  enum {
    C = 64
  };
  const accel_hit *hp[C];
  surface_interaction *sp[C];
  for (int j = 0; j < n; j++) hp[j] = &h[j], sp[j] = &si[k[j]];
  hit_fill_interaction_batch(sc, n, r, hp, sp);
}

/* Trace lanes idx[0..n) (rays in ln[i].ray for shadow == false, ln[i].sray
 * else): hit flags into hit[k], hits into si[k]. The packets' hits wait in
 * a buffer of C and are filled together (fill_hits). */
static void wave_trace(const scene *sc, const hit_bounds *hb, vlane *ln, const int *idx, int n, bool shadow,
                       bool coherent, bool *hit, surface_interaction *si, render_stats *stats) {
  enum {
    P = 16,
    C = 64 /* (a multiple of P) */
  };
  int q[P], nq = 0;
  const ray3 *fr[C];
  accel_hit fh[C];
  int fk[C], nf = 0;
  for (int k = 0; k <= n; k++) {
    if (k < n) {
      vlane *l = &ln[idx[k]];
      const ray3 *r = shadow ? &l->sray : &l->ray;
      hit[k] = false;
      bool go = may_hit_in(hb, r);
      if (sc->periodic.on) { /* scene_trace walks the walls per ray (go: always) */
        uint64_t before = stats->rays;
        hit[k] = go && intersect(sc, r, &si[k], stats); /* counts itself in stats->rays */
        if (shadow) {
          stats->shadow_rays += stats->rays - before;
          stats->rays = before;
        }
        continue;
      }
      q[nq] = k; /* (no branch on go) */
      nq += go;
      if (nq < P) continue;
    }
    if (nq == 0) continue;
    const ray3 *rp[P];
    accel_hit h[P];
    bool ok[P];
    for (int j = 0; j < nq; j++) rp[j] = shadow ? &ln[idx[q[j]]].sray : &ln[idx[q[j]]].ray;
    accel_intersect_packet_mask(sc->accel, rp, nq, h, ok, coherent,
                                sc->null_boxes.on ? ACCEL_RAYS_NO_NULL_BOX : 0xFFFFFFFFu);
    *(shadow ? &stats->shadow_rays : &stats->rays) += (uint64_t)nq;
    if (nf + nq > C) {
      fill_hits(sc, nf, fr, fh, si, fk);
      nf = 0;
    }
    for (int j = 0; j < nq; j++) {
      hit[q[j]] = ok[j];
      fr[nf] = rp[j], fh[nf] = h[j], fk[nf] = q[j];
      nf += ok[j];
    }
    nq = 0;
  }
  if (nf > 0) fill_hits(sc, nf, fr, fh, si, fk);
}

/* The length from the exact start o0 of ray r's segment (unit direction)
 * to its hit si: from the hit point, or, under a periodic boundary (si->p
 * wrapped into the column), from the hit distance. Where a medium lies
 * along or beyond the segment (media: Beer-Lambert needs the length to
 * the surface as the scene describes it), a hit on a triangle of a
 * top-level mesh is moved onto the triangle's plane along the ray, in
 * double from o0 and the face's vertices under to_world: Embree's float32
 * hit distance (or barycentrics) are off by a few float units of the
 * coordinates, 2e-4 at 3 km, which a dense medium far from the origin
 * turns into a transmittance error (docs/media.md#dense-media-the-roulette-and-the-segment-lengths). A
 * grazing hit keeps Embree's point. The planes of the last two faces met
 * are kept (fp[0], fp[1]: a ground of two triangles, hit at random, needs
 * no more). */
typedef struct face_plane {
  const shape *sh; /* NULL: empty */
  uint32_t prim;
  bool ok; /* a non-degenerate face: a (its first vertex), n (unit normal) */
  vec3 a, n;
} face_plane;

static double seg_end(const scene *sc, const ray3 *r, vec3 o0, surface_interaction *si, bool media,
                      face_plane *fp) {
  if (sc->periodic.on) return si->t + v3_dot(v3_sub(r->o, o0), r->d);
  double t = v3_dot(v3_sub(si->p, o0), r->d);
  const shape *sh = si->shape;
  if (!media || !shape_is_mesh(sh) || sh->index >= sc->n_shapes || sc->shapes[sh->index] != sh ||
      si->prim >= sh->mesh.n_faces)
    return t; /* (an instance's member: its placement is not at hand) */
  if (fp[1].sh == sh && fp[1].prim == si->prim) {
    fp = &fp[1];
  } else if (fp->sh != sh || fp->prim != si->prim) {
    fp[1] = fp[0];
    const uint32_t *ix = &sh->mesh.faces[3 * (size_t)si->prim];
    vec3 a = xf_point(&sh->to_world, mesh_vertex(&sh->mesh, ix[0]));
    vec3 b = xf_point(&sh->to_world, mesh_vertex(&sh->mesh, ix[1]));
    vec3 c = xf_point(&sh->to_world, mesh_vertex(&sh->mesh, ix[2]));
    vec3 n = v3_cross(v3_sub(b, a), v3_sub(c, a));
    double len = v3_len(n);
    *fp = (face_plane){.sh = sh, .prim = si->prim, .ok = len > 0, .a = a};
    if (fp->ok) fp->n = v3_scale(n, 1.0 / len);
  }
  if (!fp->ok) return t;
  vec3 a = fp->a, n = fp->n;
  double cos_n = v3_dot(r->d, n);
  if (!(fabs(cos_n) > 1e-3)) return t;
  double te = v3_dot(v3_sub(a, o0), n) / cos_n;
  /* Embree works in float relative to the ray's origin: its point is off
   * the plane by a few float units of the coordinates and of t (p_error),
   * and along it by as much again; a move beyond 1e-5 of them (about 170
   * float units) would not be a rounding's. */
  double scale = fabs(t) + v3_max_abs(o0) + v3_max_abs(a);
  if (!(fabs((te - t) * cos_n) <= 1e-5 * scale + 4.0 * si->p_error)) return t;
  si->p = v3_fma(o0, te, r->d);
  return te;
}

/* Does a medium lie along a segment in medium m that ends on si, or
 * beyond it? */
static bool media_at(const medium *m, const surface_interaction *si) {
  return m || si->shape->interior || si->shape->exterior;
}

/* Layered medium m's layers at page 0: layered_layers(m) wherever rsw_page
 * is 0, as it is outside the loops over a bundle's pages (each sets it back
 * to 0), without reading the thread-local page. */
static inline const media_layers *layers_page0(const medium *m) {
  return &((const layered_medium *)m)->L;
}

/* Start lane l's shadow ray towards ds from a surface vertex si (or the
 * medium point p when si is NULL) in medium sm, worth val if clear. */
static void start_shadow(const scene *sc, vlane *l, const surface_interaction *si, vec3 p, const emitter *e,
                         const direction_sample *ds, const medium *sm, color val) {
  l->sray = shadow_ray(sc, si, p, e, ds);
  l->sp0 = p;
  l->sfinite = isfinite(l->sray.tmax);
  l->send = l->sfinite ? v3_fma(l->sray.o, l->sray.tmax, l->sray.d) : p;
  l->sm = sm;
  l->sval = val;
  l->str = col1(1.0);
  l->scross = 0;
  l->sh = true;
}

/* A bundle of pages: medium m's transmittance along r over [mint, maxt]
 * at pages p0..pages-1 but page skip (-1: none; tr[skip] left as it was)
 * into tr[p]. A layered medium works out the levels
 * (and so the layers crossed) once for every page; another answers its
 * transmittance op at each page (rsw_page). */
static __attribute__((noinline)) void tr_pages(const medium *m, const ray3 *r, double mint, double maxt,
                                               int p0, int pages, int skip, color *tr) {
  if (m->ops == &layered_medium_ops) {
    layered_transmittance_pages((const layered_medium *)m, r, mint, maxt, p0, pages, skip, tr);
    return;
  }
  for (int p = p0; p < pages; p++) {
    if (p == skip) continue;
    rsw_page = p;
    tr[p] = m->ops->transmittance(m, r, mint, maxt);
  }
  rsw_page = 0;
}

/* One round of lane l's shadow ray after its query (hit at si): the
 * segment's transmittance, then done (false) or a null surface crossed
 * (true: trace again). */
/* Lane l's shadow ray (no polarization; pg: a bundle's pages 1.., or
 * NULL) when it hit nothing (its query's answer, or no query: may_hit_in)
 * in the one-box case (one_box_of) from inside the box (tn < 0 < tf), its
 * end at infinity: shadow_step's walk has one piece, [0, tf] in the box's
 * medium, and no medium beyond the exit. Its transmittances (the pages'
 * exact, one_box_of's medium being analytic) and contributions as
 * shadow_step's, the ray done (true); false: not that case. */
static inline bool shadow_one_box(const scene *sc, const one_box *ob, vlane *l, vpage *pg) {
  if (l->sm != ob->m || !ob->m || l->sfinite) return false;
  box_walk bw;
  box_walk_start(sc, l->sp0, l->sray.d, &bw);
  double tn = bw.t[0], tf = bw.t[1];
  if (!(tn < 0.0 && tf > 0.0 && tf < INFINITY)) return false;
  ray3 seg = {l->sp0, l->sray.d, 0.0, tf};
  double mint, maxt;
  bool in = media_clip_at(sc, ob->m, &seg, &bw, ob->nbi, &mint, &maxt);
  color trp[RENDER_MAX_PAGES];
  const int NP = sc->pages;
  if (pg && in) /* (every page's in one batch, page 0's too: shadow_step's) */
    tr_pages(ob->m, &seg, mint, maxt, 0, NP, -1, trp);
  else
    trp[0] = in ? media_layers_transmittance(layers_page0(ob->m), &seg, mint, maxt) : col1(1.0);
  l->str = col_mul(l->str, trp[0]);
  l->L = col_add(l->L, col_mul(l->sval, l->str));
  if (pg) {
    for (int p = 1; in && p < NP; p++) pg->str[p - 1] = col_mul(pg->str[p - 1], trp[p]);
    for (int p = 1; p < NP; p++)
      pg->L[p - 1] = col_add(pg->L[p - 1], col_mul(pg->sval[p - 1], pg->str[p - 1]));
  }
  l->sh = false;
  return true;
}

/* A staged lane's shadow ray just started (l->sh), settled at once where
 * it needs no query (may_hit_in) and shadow_one_box takes it: the lane
 * is in cache, and the shadow rounds skip it. Its contribution is added
 * where the rounds would add it (nothing else adds to l->L between the
 * light sample and the rounds). */
static inline void shadow_now(const scene *sc, const hit_bounds *hb, const one_box *ob, vlane *l) {
  if (l->sh && ob->m && l->sm == ob->m && !may_hit_in(hb, &l->sray)) shadow_one_box(sc, ob, l, NULL);
}

static bool shadow_step(const volpath_integrator *vp, const scene *sc, vlane *l, pol_lane *vq, vpage *pg,
                        bool hit, surface_interaction *si, sampler_state *st, face_plane *fp,
                        const one_box *ob) {
  const int NP = sc->pages;
  if (!hit && !vq && shadow_one_box(sc, ob, l, pg)) return false;
  if (hit && !(l->sm || sc->null_boxes.on) && media_at(NULL, si))
    seg_end(sc, &l->sray, l->sp0, si, true, fp); /* the next segment's start (si->p) */
  if (l->sm || sc->null_boxes.on) {
    double tend = hit          ? seg_end(sc, &l->sray, l->sp0, si, media_at(l->sm, si), fp)
                  : l->sfinite ? v3_dot(v3_sub(l->send, l->sp0), l->sray.d)
                               : INFINITY;
    ray3 mr = {l->sp0, l->sray.d, 0.0, tend};
    double t0 = 0.0;
    box_walk bw;
    if (sc->null_boxes.on) box_walk_start(sc, mr.o, mr.d, &bw);
    for (;;) { /* the segment piece by piece between null boxes' sides */
      const medium *next = l->sm;
      bool cross = sc->null_boxes.on && box_walk_next(sc, &bw, tend, &next);
      double t1 = cross ? bw.tc : tend;
      const box_walk *w = sc->null_boxes.on ? &bw : NULL;
      /* A bundle through a layered medium: page 0's transmittance in the
       * pages' batch below (shadow_one_box's numbers). */
      bool batch0 = pg && l->sm && t1 > t0 && vp->analytic && l->sm->ops == &layered_medium_ops;
      if (pg && l->sm && t1 > t0 && !exact_in(vp, l->sm)) { /* every page tracked at once */
        color tr[RENDER_MAX_PAGES];
        if (!segment_tr_pages(sc, l->sm, &mr, t0, t1, w, st, NP, tr)) l->unres = true;
        l->str = col_mul(l->str, tr[0]);
        for (int p = 1; p < NP; p++) pg->str[p - 1] = col_mul(pg->str[p - 1], tr[p]);
      } else if (l->sm && t1 > t0 && vp->analytic && l->sm->ops == &layered_medium_ops && !batch0) {
        /* segment_tr's exact case, inline */
        ray3 seg = {mr.o, mr.d, t0, t1};
        double mint, maxt;
        color tr = media_clip(sc, l->sm, &seg, w, &mint, &maxt)
                       ? media_layers_transmittance(layers_page0(l->sm), &seg, mint, maxt)
                       : col1(1.0);
        l->str = col_mul(l->str, tr);
      } else if (l->sm && t1 > t0 && !batch0) {
        l->str = col_mul(l->str, segment_tr(vp, sc, l->sm, &mr, t0, t1, w, st, &l->unres));
      }
      if (pg && l->sm && t1 > t0 && exact_in(vp, l->sm)) { /* pages 1.. (exact; 0.. with batch0) */
        ray3 seg = {mr.o, mr.d, t0, t1};
        double mint, maxt;
        color tr[RENDER_MAX_PAGES];
        if (media_clip(sc, l->sm, &seg, w, &mint, &maxt)) {
          tr_pages(l->sm, &seg, mint, maxt, batch0 ? 0 : 1, NP, -1, tr);
          if (batch0) l->str = col_mul(l->str, tr[0]);
          for (int p = 1; p < NP; p++) pg->str[p - 1] = col_mul(pg->str[p - 1], tr[p]);
        }
      }
      if (!cross || !(pages_max(l->str, pg, pg ? pg->str : NULL, NP) > 0)) break;
      l->sm = next;
      t0 = t1;
    }
  }
  bool more = hit && pages_max(l->str, pg, pg ? pg->str : NULL, NP) > 0;
  bool block = more && !(si->shape->bsdf->flags & BSDF_INDEX_MATCHED);
  if (more) { /* a null surface crossed: on to the next segment (or blocked) */
    double left = l->sray.tmax - si->t;
    block |= ++l->scross >= MAX_CROSSINGS;
    more = !block;
    if (block) {
      l->str = col1(0.0);
      for (int p = 1; pg && p < NP; p++) pg->str[p - 1] = col1(0.0);
    }
    more = more && left > 0;
    if (more) {
      l->sm = medium_after(si, l->sray.d, l->sm);
      l->sray = spawn_ray(si, l->sray.d);
      l->sray.tmax = left;
      l->sp0 = si->p;
      return true;
    }
  }
  l->L = col_add(l->L, col_mul(l->sval, l->str));
  for (int p = 1; pg && p < NP; p++)
    pg->L[p - 1] = col_add(pg->L[p - 1], col_mul(pg->sval[p - 1], pg->str[p - 1]));
  if (vq) pol_collect(vq, vq->pend, col_mul(l->sval, l->str), pol_channels(sc));
  l->sh = false;
  return false;
}

/* A bundle's free flights: path-level spectral MIS (the hero wavelength
 * of Wilkie et al. 2014, "Hero Wavelength Spectral Sampling", over the
 * bundle's 3 P channels). A path draws its hero channel j once, with
 * prior probability w_j, at its first flight through a medium whose
 * extinction depends on the wavelength, and every later such flight
 * inverts the hero's optical thickness. The path's density is then the
 * mixture sum_j w_j prod_e p_j(e) over its flights e (p_j: the flight's
 * outcome's density had channel j drawn it: the transmittance to a pass,
 * transmittance times sigma_t at a collision), and channel c's estimate
 * is its own prod_e f_c(e) over that sum (the balance heuristic, Veach
 * 1997, sec. 9.2.4: unbiased for any prior). Flight by flight: with
 * post_j = w_j prod p_j / sum_k w_k prod p_k (the channels' weights given
 * the flights so far; w before the first), a flight divides every
 * channel's throughput by pc = sum_j post_j p_j(e) and then post_j *=
 * p_j(e) / pc. Drawing a new channel at every flight instead (the mixture
 * per flight, what bundles did before) lets a wavelength's mismatch
 * compound over the bounces: through a slab of optical thickness 4 at 400
 * nm to 1 at 700 the 400 nm film was 14.5 times noisier than unbundled at
 * equal spp, 1.6 with the hero (docs/experiments.md#spectral-bundles).
 * The prior puts FLIGHT_W_THICK on the bundle's thickest channel,
 * FLIGHT_W_THIN on its thinnest (a layered medium's whole column, a
 * homogeneous one's sigma_t: medium_extremes) and spreads the rest alike:
 * a wavelength at either end of the range then gets paths drawn near its
 * own density. */
#define FLIGHT_W_THICK 0.4
#define FLIGHT_W_THIN  0.4

/* Lane pg's hero among the nch channels, drawn with number u0 from the
 * prior above (m: the medium of the path's first chromatic flight), and
 * its channels' weights set to that prior. */
static void draw_hero(const medium *m, int nch, double u0, vpage *pg) {
  double *post = pg->post;
  int thick = m->thick_channel, thin = m->thin_channel;
  bool ends = m->extinction_spread > 1.0 && thick != thin && thick < nch && thin < nch;
  for (int k = 0; k < nch; k++) post[k] = (ends ? 1.0 - FLIGHT_W_THICK - FLIGHT_W_THIN : 1.0) / nch;
  if (ends) post[thick] += FLIGHT_W_THICK, post[thin] += FLIGHT_W_THIN;
  double cdf = 0.0;
  int k = 0;
  for (; k < nch - 1; k++) {
    cdf += post[k];
    if (u0 < cdf) break;
  }
  pg->hero = k;
}

/* A free flight over [mint, maxt] of seg in analytic medium m for a
 * bundle of pages (vpage): the collision (or the pass) drawn by inverting
 * the path's hero channel (drawn here at its first chromatic flight),
 * each page weighted by its own transmittance (and sigma_s at a
 * collision) over the path-level mixture above. True: a collision, at
 * mi. */
static __attribute__((noinline)) bool flight_pages(const scene *sc, const medium *m, const ray3 *seg,
                                                   double mint, double maxt, sampler_state *st, vlane *l,
                                                   vpage *pg, medium_interaction *mi) {
  const sampler_ops *sops = st->s->ops;
  const int NP = sc->pages, nch = 3 * NP;
  const bool chromatic = m->has_spectral_extinction;
  double *post = pg->post;
  if (chromatic && pg->hero < 0) draw_hero(m, nch, sops->next_1d(st), pg);
  int c = chromatic ? pg->hero : 0;
  double u = sops->next_1d(st);
  int h = c / 3;
  color tr[RENDER_MAX_PAGES], pdf[RENDER_MAX_PAGES], ss[RENDER_MAX_PAGES];
  rsw_page = h;
  m->ops->sample_real(m, seg, mint, maxt, u, c % 3, mi, &tr[h], &pdf[h]);
  ss[h] = mi->sigma_s;
  bool scattered = isfinite(mi->t);
  double tend = scattered ? mi->t : maxt, pc = 0.0;
  rsw_page = 0;
  tr_pages(m, seg, mint, tend, 0, NP, h, tr); /* (the hero page's, sample_real's) */
  const layered_medium *lm = m->ops == &layered_medium_ops ? (const layered_medium *)m : NULL;
  int k = scattered && lm ? media_layer_of(&lm->L, media_layers_z(&lm->L, mi->p)) : 0;
  for (int p = 0; p < NP; p++) {
    if (p != h) {
      pdf[p] = tr[p];
      if (scattered && lm) { /* (the page's layer's coefficients alone) */
        color sgt;
        media_layers_sigmas(p ? &lm->Lp[p - 1] : &lm->L, k, &sgt, &ss[p]);
        pdf[p] = col_mul(sgt, tr[p]);
      } else if (scattered) {
        medium_interaction mp = *mi;
        rsw_page = p;
        m->ops->coefficients(m, &mp);
        rsw_page = 0;
        ss[p] = mp.sigma_s;
        pdf[p] = col_mul(mp.sigma_t, tr[p]);
      }
    }
    for (int j = 0; chromatic && j < 3; j++) pc += post[3 * p + j] * pdf[p].c[j];
  }
  if (!chromatic) pc = pdf[0].c[0];
  if (chromatic && pc > 0) {
    for (int p = 0; p < NP; p++)
      for (int j = 0; j < 3; j++) post[3 * p + j] *= pdf[p].c[j] / pc;
  }
  for (int p = 0; p < NP; p++) {
    color f = scattered ? col_mul(tr[p], ss[p]) : tr[p];
    color *T = p ? &pg->T[p - 1] : &l->T;
    *T = pc > 0 ? col_scale(col_mul(*T, f), 1.0 / pc) : col1(0.0);
  }
  return scattered;
}

/* A free flight over [mint, maxt] of seg in tracked medium m for a bundle
 * of pages: delta tracking against the majorant of every page's channels,
 * each page weighted by its own sigma_s (real) or sigma_n (null) over the
 * probability of the outcome, so that each page's estimate is unbiased
 * (Kutz et al. 2017, "Spectral and decomposition tracking for rendering
 * heterogeneous volumes"). Where the extinction depends on the wavelength,
 * a tentative collision is real with the path's hero channel's
 * probability sigma_t / mu and weighted over the path-level mixture
 * (draw_hero, flight_pages: the tentative collisions' distances do not
 * depend on the channel, the real-or-null choices do); else with the
 * mean of the 3 P channels' (the channel-mean tracking volpath uses for
 * rgb). 1: a collision, at mi; 0: the flight passed maxt; -1: every
 * page's throughput is 0. */
static __attribute__((noinline)) int track_pages(const scene *sc, const medium *m, const ray3 *seg,
                                                 double mint, double maxt, sampler_state *st, vlane *l,
                                                 vpage *pg, medium_interaction *mi) {
  const sampler_ops *sops = st->s->ops;
  const int NP = sc->pages, nch = 3 * NP;
  const bool chromatic = m->has_spectral_extinction;
  double *post = pg->post;
  if (chromatic && pg->hero < 0) draw_hero(m, nch, sops->next_1d(st), pg);
  *mi = (medium_interaction){.medium = m, .wi = v3_neg(seg->d), .mint = mint};
  mi->p = v3_fma(seg->o, mint, seg->d);
  track_walk tw;
  track_walk_start(m, seg, mint, maxt, majorant_pages(m, mi, NP), false, &tw);
  double ctl_tau = 0.0; /* (no control: a free flight samples sigma_t itself) */
  color ss[RENDER_MAX_PAGES], sn[RENDER_MAX_PAGES];
  double t = mint;
  track_guard g = {0, 0};
  while (track_walk_live(&tw)) {
    int ev = walk_step(&tw, &g, &t, -log1p(-sops->next_1d(st)), maxt, &ctl_tau);
    if (ev < 0) {
      l->unres = true;
      return -1;
    }
    if (ev == 0) break;
    double mu = tw.mu;
    mi->t = t;
    mi->p = v3_fma(seg->o, t, seg->d);
    double p_real = coefficients_pages(m, mi, mu, NP, ss, sn) / mu;
    if (chromatic) p_real = 1.0 - sn[pg->hero / 3].c[pg->hero % 3] / mu;
    mi->majorant = col1(mu);
    bool real = sops->next_1d(st) < p_real;
    double pc = real ? p_real : 1.0 - p_real;
    if (chromatic) { /* the mixture's probability of the outcome; the weights given it */
      pc = 0.0;
      for (int j = 0; j < nch; j++) {
        double q = sn[j / 3].c[j % 3] / mu;
        pc += post[j] * (real ? 1.0 - q : q);
      }
      for (int j = 0; j < nch && pc > 0; j++) {
        double q = sn[j / 3].c[j % 3] / mu;
        post[j] *= (real ? 1.0 - q : q) / pc;
      }
    }
    double k = pc > 0 ? 1.0 / (mu * pc) : 0.0;
    for (int p = 0; p < NP; p++) {
      color *T = p ? &pg->T[p - 1] : &l->T;
      *T = col_scale(col_mul(*T, real ? ss[p] : sn[p]), k);
    }
    if (real) return 1;
    if (!(pages_max(l->T, pg, pg->T, NP) > 0)) return -1;
  }
  mi->t = INFINITY;
  return 0;
}

/* ---- a lane's event, in pieces --------------------------------------------
 *
 * Lane l's event after its query: the medium along the segment
 * (lane_flight), then the scattering event (scatter_*), or the surface,
 * null surface or escape (surface_*), then the roulette (roulette). Each
 * piece takes the random numbers it uses as arguments where a wave's
 * stages (wave_events) draw them for many lanes at once; lane_event calls
 * the same pieces for one lane, drawing as it goes (the bundles of pages
 * and the polarized variants always go that way). Either way a lane draws
 * from its own sampler state in the same order: the free flight, the
 * light pick and light sample, the phase or BSDF sample, the roulette.
 * The pieces are inlined into both callers (as calls, the staged wave
 * measured 4% slower than the lane-by-lane one it replaces). */
#define PIECE static inline __attribute__((always_inline))

enum lane_outcome {
  EV_END,     /* the path ends (a pending shadow ray still counts) */
  EV_SCATTER, /* lane_flight: a collision in the medium */
  EV_SURFACE, /* lane_flight: the segment's end reached (its surface, or the escape) */
  EV_CROSS,   /* surface_emit: a null surface crossed (no bounce, no roulette) */
  EV_BOUNCE   /* surface_emit: a surface to scatter from */
};

/* Does lane l's path end, whatever its throughput, if its flight through
 * the piece of its segment that the box walk bw is at passes (cross: a
 * null box's side ends the piece, into medium next)? Its ray hits nothing
 * (surface_emit: the path ends there), no environment sees it, and
 * nothing beyond the piece can scatter it: the piece runs to the ray's
 * end, or to the exit of the scene's only null box into no medium (the
 * last crossing). Then a pass's weight (its exp) is not needed, and the
 * film is the same bit for bit. Not with pages (each page's weight). */
static inline bool escapes_after(const scene *sc, const vlane *l, const vpage *pg, bool cross,
                                 const box_walk *bw, const medium *next) {
  return !l->hit && !sc->environment && !pg &&
         (!cross || (sc->null_boxes.n == 1 && (bw->ic & 1) && next == NULL));
}

/* An analytic free flight of lane l in medium m over [mint, maxt] of seg
 * (no pages): its draws, the throughput, and at a collision (true) its
 * point *mi. escapes: escapes_after's answer. */
PIECE bool flight_analytic(const scene *sc, sampler_state *st, vlane *l, const medium *m, const ray3 *seg,
                           double mint, double maxt, bool escapes, medium_interaction *mi) {
  int c = pick_channel(m, st);
  color tr, pdf;
  double u = st->s->ops->next_1d(st);
  if (m->ops == &layered_medium_ops) /* (inline: the same code as its op) */
    media_layers_sample_real_w(layers_page0(m), m, seg, mint, maxt, u, c, !escapes, mi, &tr, &pdf);
  else
    m->ops->sample_real(m, seg, mint, maxt, u, c, mi, &tr, &pdf);
  double pc = col_mean(pdf);
  bool scattered = isfinite(mi->t);
  color f = scattered ? col_mul(tr, mi->sigma_s) : tr;
  l->T = pc > 0 ? col_scale(col_mul(l->T, f), 1.0 / pc) : col1(0.0);
  return scattered;
}

/* The medium along lane l's segment, piece by piece between null boxes'
 * sides: the free flight's draws, the throughput, and at a collision
 * (EV_SCATTER) its point *mi. si: the query's hit (when l->hit), whose
 * point seg_end may move onto its face's plane. */
PIECE enum lane_outcome lane_flight(const volpath_integrator *vp, const scene *sc, sampler_state *st,
                                    vlane *l, surface_interaction *si, vpage *pg, face_plane *fp,
                                    const one_box *ob, medium_interaction *mi) {
  const int NP = sc->pages;
  const sampler_ops *sops = st->s->ops;
  bool hit = l->hit;
  const medium *m = l->m;
  bool scattered = false;
  double tend = hit ? seg_end(sc, &l->ray, l->seg_o, si, media_at(m, si), fp) : l->ray.tmax, t0 = 0.0;
  box_walk bw;
  if (sc->null_boxes.on) box_walk_start(sc, l->seg_o, l->ray.d, &bw);
  if (ob && ob->m && (m == ob->m || !m)) {
    /* one_box_of's box, from inside it (tn < 0 < tf) or entered from
     * before it (0 <= tn < tend): the walk's one piece in the medium,
     * from 0 or tn to tf or tend, the exit at tf (when tf < tend) into no
     * medium */
    double tn = bw.t[0], tf = bw.t[1];
    bool inside = m && tn < 0.0 && tf > 0.0, enters = !m && tn >= 0.0 && tn < tend;
    if ((inside || enters) && tf < INFINITY) {
      if (enters) {
        if (!(pages_max(l->T, pg, pg ? pg->T : NULL, NP) > 0)) return EV_END;
        m = l->m = ob->m;
        t0 = tn;
      }
      bool cross = tf < tend;
      ray3 seg = {l->seg_o, l->ray.d, t0, cross ? tf : tend};
      double mint, maxt;
      if (seg.tmax > seg.tmin && media_clip_at(sc, m, &seg, &bw, ob->nbi, &mint, &maxt))
        scattered = pg ? flight_pages(sc, m, &seg, mint, maxt, st, l, pg, mi)
                       : flight_analytic(sc, st, l, m, &seg, mint, maxt, !l->hit && !sc->environment, mi);
      bool live = pages_max(l->T, pg, pg ? pg->T : NULL, NP) > 0;
      if (!scattered && cross && live) l->m = NULL;
      return !live ? EV_END : scattered ? EV_SCATTER : EV_SURFACE;
    }
  }
  for (;;) { /* the segment piece by piece between null boxes' sides */
    const medium *next = m;
    bool cross = sc->null_boxes.on && box_walk_next(sc, &bw, tend, &next);
    ray3 seg = {l->seg_o, l->ray.d, t0, cross ? bw.tc : tend};
    double mint, maxt;
    const box_walk *w = sc->null_boxes.on ? &bw : NULL;
    if (m && seg.tmax > seg.tmin && media_clip(sc, m, &seg, w, &mint, &maxt)) {
      if (m->absorbing_only && pg && !exact_in(vp, m)) { /* every page tracked at once */
        color tr[RENDER_MAX_PAGES];
        if (!segment_tr_pages(sc, m, &seg, seg.tmin, seg.tmax, w, st, NP, tr)) l->unres = true;
        l->T = col_mul(l->T, tr[0]);
        for (int p = 1; p < NP; p++) pg->T[p - 1] = col_mul(pg->T[p - 1], tr[p]);
      } else if (m->absorbing_only) {
        l->T = col_mul(l->T, segment_tr(vp, sc, m, &seg, seg.tmin, seg.tmax, w, st, &l->unres));
        if (pg) { /* pages 1.. (exact) */
          color tr[RENDER_MAX_PAGES];
          tr_pages(m, &seg, mint, maxt, 1, NP, -1, tr);
          for (int p = 1; p < NP; p++) pg->T[p - 1] = col_mul(pg->T[p - 1], tr[p]);
        }
      } else if (pg && analytic_in(vp, m)) {
        scattered = flight_pages(sc, m, &seg, mint, maxt, st, l, pg, mi);
      } else if (pg) {
        int ev = track_pages(sc, m, &seg, mint, maxt, st, l, pg, mi);
        if (ev < 0) return EV_END;
        scattered = ev > 0;
      } else if (analytic_in(vp, m)) {
        scattered =
            flight_analytic(sc, st, l, m, &seg, mint, maxt, escapes_after(sc, l, pg, cross, &bw, next), mi);
      } else {
        *mi = (medium_interaction){.medium = m, .wi = v3_neg(l->ray.d), .mint = mint};
        mi->p = v3_fma(seg.o, mint, seg.d);
        track_walk tw;
        track_walk_start(m, &seg, mint, maxt, col_max(m->ops->majorant(m, mi)), false, &tw);
        double ctl_tau = 0.0; /* (no control: a free flight samples sigma_t itself) */
        double t = mint;
        track_guard g = {0, 0};
        while (track_walk_live(&tw)) {
          int ev = walk_step(&tw, &g, &t, -log1p(-sops->next_1d(st)), maxt, &ctl_tau);
          if (ev < 0) {
            l->unres = true;
            return EV_END;
          }
          if (ev == 0) break;
          double mu = tw.mu;
          mi->t = t;
          mi->p = v3_fma(seg.o, t, seg.d);
          mi->majorant = col1(mu);
          m->ops->coefficients(m, mi);
          double p_real = col_mean(mi->sigma_t) / mu;
          if (sops->next_1d(st) < p_real) {
            l->T = col_scale(col_mul(l->T, mi->sigma_s), 1.0 / (mu * p_real));
            scattered = true;
            break;
          }
          l->T = col_scale(col_mul(l->T, mi->sigma_n), 1.0 / (mu * (1.0 - p_real)));
          if (col_max(l->T) <= 0) return EV_END;
        }
      }
    }
    if (scattered || !cross || !(pages_max(l->T, pg, pg ? pg->T : NULL, NP) > 0)) break;
    m = l->m = next; /* a null box's side crossed without a query */
    t0 = bw.tc;
  }
  if (!(pages_max(l->T, pg, pg ? pg->T : NULL, NP) > 0)) return EV_END;
  return scattered ? EV_SCATTER : EV_SURFACE;
}

/* A collision at mi in lane l's medium, before its draws: whether the
 * path may scatter once more (max_depth), the point's phase looked up
 * once (phase_bind), and the vertex that MIS weighs later hits against
 * and the light sample starts from (l->prev: only its p and t, written in
 * place: the last surface record is not needed past this point). */
PIECE bool scatter_begin(const volpath_integrator *vp, vlane *l, medium_interaction *mi) {
  const integrator *it = &vp->base;
  if (!(it->max_depth < 0 || l->depth + 1 < it->max_depth)) return false;
  phase_bind(l->m->phase, mi);
  l->prev = (surface_interaction){.p = mi->p, .t = mi->t};
  return true;
}

/* Does a collision in medium m take a light sample? */
static bool scatter_nee(const scene *sc, const medium *m) {
  return m->sample_emitters && sc->n_emitters > 0;
}

/* The light sample at lane l's collision mi: emitter e (picked with
 * probability pe) sampled with u2 into ds, worth value; its shadow ray
 * is started where the phase function and the sample count. */
PIECE void scatter_light(const scene *sc, vlane *l, const medium_interaction *mi, const emitter *e, double pe,
                         vec2 u2, const direction_sample *ds, color value, pol_lane *vq, vpage *pg) {
  const int NP = sc->pages;
  const medium *m = l->m;
  const phase *ph = m->phase;
  if (!(ds->pdf > 0) || (col_is_black(value) && !pg)) return;
  double ppdf;
  double pval = ph->ops->eval_pdf(ph, mi, ds->d, &ppdf);
  if (!(pval > 0)) return;
  double w = ds->delta ? 1.0 : mis_weight(ds->pdf * pe, ppdf);
  /* A chromatic phase (a spectral bundle's aerosol mixture): each
   * channel's own value. */
  color c = col_mul(l->T, value);
  c = ph->chromatic ? col_scale(col_mul(c, ph->ops->eval_channels(ph, mi, ds->d)), w / pe)
                    : col_scale(c, pval * w / pe);
  start_shadow(sc, l, NULL, mi->p, e, ds, m, c);
  color pv[RENDER_MAX_PAGES];
  if (pg && ph->chromatic) phase_pages(ph, mi, ds->d, 1, NP, pv);
  for (int p = 1; pg && p < NP; p++) { /* each page's light and phase value */
    direction_sample dp;
    rsw_page = p;
    color v = col_mul(pg->T[p - 1], e->ops->sample_direction(e, &l->prev, u2, &dp));
    v = ph->chromatic ? col_mul(v, pv[p]) : col_scale(v, pval);
    pg->sval[p - 1] = col_scale(v, w / pe);
    pg->str[p - 1] = col1(1.0);
  }
  rsw_page = 0;
  if (vq) {
    mueller P[3];
    vec3 bp = {0};
    const mueller *pp = pol_phase(ph, mi, ds->d, P, &bp);
    pol_through_light(vq, e, ds->d, mi->wi, bp, bp, pp, pol_channels(sc), vq->pend);
  }
}

/* The phase sample at lane l's collision mi (numbers u1, u2) and the
 * continuation ray. False: the sample failed and the path ends. */
PIECE bool scatter_phase(const scene *sc, vlane *l, const medium_interaction *mi, double u1, vec2 u2,
                         pol_lane *vq, vpage *pg) {
  const int NP = sc->pages;
  const medium *m = l->m;
  const phase *ph = m->phase;
  vec3 wo;
  double ppdf;
  double pw = ph->ops->sample(ph, mi, u1, u2, &wo, &ppdf);
  if (!(ppdf > 0) || !(pw > 0)) return false;
  /* A chromatic phase: wo drawn with channel 0's mixture, each channel
   * weighted by its own value over that density (unbiased: every
   * component covers the sphere). */
  l->T = ph->chromatic ? col_mul(l->T, col_scale(ph->ops->eval_channels(ph, mi, wo), 1.0 / ppdf))
                       : col_scale(l->T, pw);
  color pv[RENDER_MAX_PAGES];
  if (pg && ph->chromatic) phase_pages(ph, mi, wo, 1, NP, pv);
  for (int p = 1; pg && p < NP; p++)
    pg->T[p - 1] =
        ph->chromatic ? col_mul(pg->T[p - 1], col_scale(pv[p], 1.0 / ppdf)) : col_scale(pg->T[p - 1], pw);
  if (vq) {
    mueller P[3];
    vec3 bp = {0};
    const mueller *pp = pol_phase(ph, mi, wo, P, &bp);
    pol_scatter(vq, mi->wi, bp, pp, bp, pol_channels(sc));
  }
  l->ray = (ray3){mi->p, wo, 0.0, INFINITY};
  l->seg_o = mi->p;
  l->prev_pdf = ppdf;
  l->prev_delta = !m->sample_emitters; /* no light sample taken here: phase sampling's hits count fully */
  l->crossings = 0;
  return true;
}

/* Emission Le of e seen by lane l's ray (at si, or escaped: si NULL),
 * MIS weight w: added to l->L and every page's L; returns page 0's part. */
static color emission_add(const scene *sc, vlane *l, const emitter *e, const surface_interaction *si,
                          color Le, double w, vpage *pg) {
  color v = col_scale(col_mul(l->T, Le), w);
  l->L = col_add(l->L, v);
  for (int p = 1; pg && p < sc->pages; p++) {
    rsw_page = p;
    pg->L[p - 1] = col_add(pg->L[p - 1], col_scale(col_mul(pg->T[p - 1], e->ops->eval(e, si, l->ray.d)), w));
  }
  rsw_page = 0;
  return v;
}

/* The end of lane l's segment (its surface si when l->hit, else the
 * escape): the emission its ray sees (weighted against the last vertex's
 * light sample), then a null surface crossed (EV_CROSS: on into the
 * medium beyond, no bounce), the end of the path (EV_END: an escape, or
 * max_depth), or a surface to scatter from (EV_BOUNCE). */
PIECE enum lane_outcome surface_emit(const volpath_integrator *vp, const scene *sc, vlane *l,
                                     surface_interaction *si, pol_lane *vq, vpage *pg) {
  const integrator *it = &vp->base;
  bool visible = !(it->hide_emitters && l->depth == 0);
  if (!l->hit) {
    const emitter *env = sc->environment;
    if (env && visible) {
      double em_pdf = 0.0;
      if (!l->prev_delta) {
        direction_sample ds = {.d = l->ray.d, .dist = INFINITY};
        em_pdf = env->ops->pdf_direction(env, &l->prev, &ds) * emitter_prob(sc, env);
      }
      color Le = env->ops->eval(env, NULL, l->ray.d);
      color v = emission_add(sc, l, env, NULL, Le, mis_weight(l->prev_pdf, em_pdf), pg);
      if (vq) pol_add_env(vq, env, l->ray.d, Le, v, pol_channels(sc));
    }
    return EV_END;
  }
  const emitter *em = si->shape->emitter;
  if (em && visible) {
    color Le = em->ops->eval(em, si, l->ray.d);
    if (!col_is_black(Le) || pg) {
      double em_pdf = 0.0;
      if (!l->prev_delta) {
        direction_sample ds = {
            .p = si->p, .n = si->ng, .d = l->ray.d, .dist = v3_len(v3_sub(si->p, l->prev.p))};
        em_pdf = em->ops->pdf_direction(em, &l->prev, &ds) * emitter_prob(sc, em);
      }
      color v = emission_add(sc, l, em, si, Le, mis_weight(l->prev_pdf, em_pdf), pg);
      if (vq) pol_add(vq, v, pol_channels(sc));
    }
  }
  const bsdf *b = si->shape->bsdf;
  if (b->flags & BSDF_INDEX_MATCHED) { /* crossed without a bounce */
    if (++l->crossings > MAX_CROSSINGS) return EV_END;
    l->m = medium_after(si, l->ray.d, l->m);
    l->ray = spawn_ray(si, l->ray.d);
    l->seg_o = si->p;
    return EV_CROSS;
  }
  if (!(it->max_depth < 0 || l->depth + 1 < it->max_depth)) return EV_END;
  return EV_BOUNCE;
}

/* Does a bounce at si take a light sample? */
static bool surface_nee(const scene *sc, const surface_interaction *si) {
  return (si->shape->bsdf->flags & BSDF_SMOOTH) && sc->n_emitters > 0;
}

/* Does the light sample ds of value `value` need the BSDF's value? */
static inline bool surface_light_lit(const direction_sample *ds, color value) {
  return ds->pdf > 0 && !col_is_black(value);
}

/* surface_light past the BSDF: its value f (not black) and pdf bpdf (0
 * for a delta light) towards the light sample (local wo). */
PIECE void surface_light_at(const scene *sc, vlane *l, const surface_interaction *si, const emitter *e,
                            double pe, const direction_sample *ds, color value, vec3 wo, color f, double bpdf,
                            pol_lane *vq) {
  const bsdf *b = si->shape->bsdf;
  double w = ds->delta ? 1.0 : mis_weight(ds->pdf * pe, bpdf);
  start_shadow(sc, l, si, si->p, e, ds, medium_after(si, ds->d, l->m),
               col_scale(col_mul(l->T, col_mul(f, value)), w / pe));
  if (vq) {
    mueller P[3];
    vec3 b_in = {0}, b_out = {0};
    const mueller *pp = pol_bsdf(b, si, wo, 0, P, &b_in, &b_out);
    pol_through_light(vq, e, ds->d, v3_neg(l->ray.d), b_in, b_out, pp, pol_channels(sc), vq->pend);
  }
}

/* The light sample at lane l's surface si (no pages: lane_surface does
 * theirs): emitter e (picked with probability pe) sampled into ds, worth
 * value; its shadow ray is started where the BSDF and the sample count. */
PIECE void surface_light(const scene *sc, vlane *l, const surface_interaction *si, const emitter *e,
                         double pe, const direction_sample *ds, color value, pol_lane *vq) {
  if (!surface_light_lit(ds, value)) return;
  const bsdf *b = si->shape->bsdf;
  vec3 wo = frame_to_local(&si->sh, ds->d);
  color f = b->ops->eval(b, si, wo);
  if (col_is_black(f)) return;
  surface_light_at(sc, l, si, e, pe, ds, value, wo, f, ds->delta ? 0.0 : b->ops->pdf(b, si, wo), vq);
}

/* Lane l's BSDF sample bs at si, of weight `weight` (page 0's; a bundle's
 * pages have theirs in pg->T already): the continuation ray. False: the
 * sample failed and the path ends. */
PIECE bool surface_continue(const scene *sc, vlane *l, const surface_interaction *si, const bsdf_sample *bs,
                            color weight, pol_lane *vq, vpage *pg) {
  if (!(bs->pdf > 0) || (col_is_black(weight) && !pg)) return false;
  vec3 wo = frame_to_world(&si->sh, bs->wo);
  if (vq) {
    mueller P[3];
    vec3 b_in = {0}, b_out = {0};
    const mueller *pp = pol_bsdf(si->shape->bsdf, si, bs->wo, bs->sampled_type, P, &b_in, &b_out);
    pol_scatter(vq, v3_neg(l->ray.d), b_out, pp, b_in, pol_channels(sc));
  }
  l->T = col_mul(l->T, weight);
  l->eta *= bs->eta;
  l->m = medium_after(si, wo, l->m);
  l->ray = spawn_ray(si, wo);
  l->seg_o = si->p;
  l->prev = *si;
  l->prev_pdf = bs->pdf;
  l->prev_delta = (bs->sampled_type & BSDF_DELTA) != 0;
  l->crossings = 0;
  return true;
}

/* Does lane l draw a roulette number after this bounce (l->depth counts
 * it already)? Drawn whether used or not: later draws keep their places. */
static bool roulette_draws(const volpath_integrator *vp, const vlane *l) {
  return l->depth >= vp->base.rr_depth;
}

/* The roulette after lane l's bounce (docs/media.md#dense-media-the-roulette-and-the-segment-lengths),
 * with number u where roulette_draws. False: the path ends. */
PIECE bool roulette(const volpath_integrator *vp, const scene *sc, vlane *l, vpage *pg, double u) {
  const int NP = sc->pages;
  if (roulette_draws(vp, l)) {
    double w = pages_max(l->T, pg, pg ? pg->T : NULL, NP) * l->eta * l->eta;
    if (w < 1.0 || l->depth >= RR_BACKSTOP_DEPTH || vp->rr_mitsuba) {
      double q = fmin(w, 0.95);
      if (!(u < q)) return false;
      l->T = col_scale(l->T, 1.0 / q);
      for (int p = 1; pg && p < NP; p++) pg->T[p - 1] = col_scale(pg->T[p - 1], 1.0 / q);
    }
  }
  return pages_max(l->T, pg, pg ? pg->T : NULL, NP) > 0;
}

/* A phase or BSDF sample's numbers u1 (the lobe or component) and u2
 * (the direction): drawn u2 first, u1 second, the order lane_event has
 * always drawn them in (the films depend on it), but for a bundle's BSDF
 * samples (pages: u1 first). */
static void draw_sample_numbers(sampler_state *st, bool pages, double *u1, vec2 *u2) {
  const sampler_ops *sops = st->s->ops;
  if (pages) {
    *u1 = sops->next_1d(st);
    *u2 = sops->next_2d(st);
  } else {
    *u2 = sops->next_2d(st);
    *u1 = sops->next_1d(st);
  }
}

/* Lane l's surface bounce at si, drawing as it goes: the light sample
 * (every page's BSDF and light value with a bundle of pages), the BSDF
 * sample (one direction for every page, integrators/pages.h). False: the
 * path ends. */
static bool lane_surface(const scene *sc, sampler_state *st, vlane *l, surface_interaction *si, pol_lane *vq,
                         vpage *pg) {
  const int NP = sc->pages;
  const sampler_ops *sops = st->s->ops;
  const bsdf *b = si->shape->bsdf;
  if (surface_nee(sc, si)) {
    double pe;
    size_t k = pick_emitter(sc, sops->next_1d(st), &pe);
    const emitter *e = sc->emitters[k];
    direction_sample ds;
    vec2 u2 = sops->next_2d(st);
    color value = e->ops->sample_direction(e, si, u2, &ds);
    if (pg && ds.pdf > 0) { /* every page's BSDF and light value, the pages' mean pdf */
      vec3 wo = frame_to_local(&si->sh, ds.d);
      color f[RENDER_MAX_PAGES];
      double bpdf = bsdf_eval_pages(b, si, NP, wo, !ds.delta, f);
      double w = ds.delta ? 1.0 : mis_weight(ds.pdf * pe, bpdf);
      start_shadow(sc, l, si, si->p, e, &ds, medium_after(si, ds.d, l->m),
                   col_scale(col_mul(l->T, col_mul(f[0], value)), w / pe));
      for (int p = 1; p < NP; p++) {
        direction_sample dp;
        rsw_page = p;
        color v = e->ops->sample_direction(e, si, u2, &dp);
        pg->sval[p - 1] = col_scale(col_mul(pg->T[p - 1], col_mul(f[p], v)), w / pe);
        pg->str[p - 1] = col1(1.0);
      }
      rsw_page = 0;
    } else if (!pg) {
      surface_light(sc, l, si, e, pe, &ds, value, vq);
    }
  }
  bsdf_sample bs;
  color weight;
  double u1;
  vec2 u2;
  draw_sample_numbers(st, pg != NULL, &u1, &u2);
  if (pg) { /* one direction for every page (integrators/pages.h) */
    color w[RENDER_MAX_PAGES] = {{{0}}};
    bsdf_sample_pages(b, si, NP, u1, u2, &bs, w);
    weight = w[0];
    for (int p = 1; p < NP; p++) pg->T[p - 1] = col_mul(pg->T[p - 1], w[p]);
    if (!(bs.pdf > 0) || !(pages_max(weight, pg, pg->T, NP) > 0)) return false;
  } else {
    weight = b->ops->sample(b, si, u1, u2, &bs);
  }
  return surface_continue(sc, l, si, &bs, weight, vq, pg);
}

/* Lane l's event after its query, drawing as it goes: the pieces above
 * for one lane. Sets up the shadow ray (l->sh) and the next ray. False:
 * the path ends (a pending shadow ray still counts). */
static bool lane_event(const volpath_integrator *vp, const scene *sc, sampler_state *st, vlane *l,
                       surface_interaction *si, pol_lane *vq, vpage *pg, face_plane *fp, const one_box *ob) {
  const sampler_ops *sops = st->s->ops;
  l->sh = false;
  medium_interaction mi;
  enum lane_outcome ev = lane_flight(vp, sc, st, l, si, pg, fp, ob, &mi);
  if (ev == EV_END) return false;
  if (ev == EV_SCATTER) {
    if (!scatter_begin(vp, l, &mi)) return false;
    if (scatter_nee(sc, l->m)) {
      double pe;
      size_t k = pick_emitter(sc, sops->next_1d(st), &pe);
      const emitter *e = sc->emitters[k];
      direction_sample ds;
      vec2 u2 = sops->next_2d(st);
      color value = e->ops->sample_direction(e, &l->prev, u2, &ds);
      scatter_light(sc, l, &mi, e, pe, u2, &ds, value, vq, pg);
    }
    double u1;
    vec2 u2;
    draw_sample_numbers(st, false, &u1, &u2);
    if (!scatter_phase(sc, l, &mi, u1, u2, vq, pg)) return false;
  } else {
    ev = surface_emit(vp, sc, l, si, vq, pg);
    if (ev != EV_BOUNCE) return ev == EV_CROSS;
    if (!lane_surface(sc, st, l, si, vq, pg)) return false;
  }
  l->depth++;
  return roulette(vp, sc, l, pg, roulette_draws(vp, l) ? sops->next_1d(st) : 0.0);
}

/* ---- the wave's stages ----------------------------------------------------
 *
 * Without pages or polarization (the common case), a wave's events go in
 * stages over its lanes rather than lane by lane (wave_events): every
 * lane's free flight and what needs no draw after it (the emission its
 * ray sees, a null surface crossed); then the lanes that bounce off a
 * surface (light samples, BSDF samples); then the lanes that scatter in
 * the medium (light samples, phase samples); each of the last two ending
 * with the roulette. Each stage draws its numbers for all its lanes at
 * once (samplers/sampler_batch.h) and groups the light samples by emitter
 * (integrators/wave.h); every lane still draws from its own state in
 * lane_event's order and computes the same values, so the staged and the
 * lane-by-lane events give bitwise the same film
 * (tests/kernel/integrators/test_volpath_stages.c). The BSDFs with exact
 * batches (bsdf_ops.sample_batch_exact, eval_pdf_batch_exact: rpv's
 * double lanes, the scalar ops' bits) are called for a chunk of lanes at
 * once in stage (b); their other batched ops compute in single precision
 * (bsdfs/rpv.c), which would move the films. The free flights and the
 * phase functions are still called per lane (their batches, wired into
 * stage_segments and stage_scatters, measured slower:
 * docs/performance.md). */

/* Whether wave_run goes by stages where it can (volpath_set_stages). */
static _Atomic bool g_stages = true;

void volpath_set_stages(bool on) {
  g_stages = on;
}

/* The stages' scratch for a wave of n lanes: per live lane k, its
 * collision and its outcome; lists of n lanes and the batched draws and
 * light samples of a list. */
typedef struct vstage {
  medium_interaction *mi;
  unsigned char *ev; /* enum lane_outcome */
  int *ks, *sub, *lid, *ek, *ord;
  const surface_interaction **ref;
  double *d1;
  vec2 *d2;
  direction_sample *ds;
  color *val;
} vstage;

/* Lanes idx[ks[j]] of list ks[0..n) into lid[j], for the sampler's
 * batched draws. */
static void stage_lanes(const int *idx, const int *ks, int n, int *lid) {
  for (int j = 0; j < n; j++) lid[j] = idx[ks[j]];
}

/* The phase or BSDF samples' numbers of lanes lid[0..n) into vs->d1
 * (u1) and vs->d2 (u2), in draw_sample_numbers' order. */
static void stage_sample_numbers(const sampler *smp, sampler_state *st, const int *lid, int n,
                                 const vstage *vs) {
  sampler_next_2d_batch(smp, st, lid, n, vs->d2);
  sampler_next_1d_batch(smp, st, lid, n, vs->d1);
}

/* Stage (a): every live lane's segment, up to its first draw past the
 * free flight: the flight (lane_flight), then at a collision
 * scatter_begin, at a surface or an escape surface_emit. ev[k]:
 * EV_SCATTER (on to stage (c)), EV_BOUNCE (on to stage (b)), EV_CROSS (a
 * null surface crossed: goes on as it is) or EV_END. */
static void stage_segments(const volpath_integrator *vp, const scene *sc, sampler_state *st, vlane *ln,
                           const int *idx, int live, const bool *hit, surface_interaction *si, face_plane *fp,
                           const one_box *ob, const vstage *vs) {
  for (int k = 0; k < live; k++) {
    vlane *l = &ln[idx[k]];
    l->hit = hit[k];
    l->sh = false;
    enum lane_outcome ev = lane_flight(vp, sc, &st[idx[k]], l, &si[k], NULL, fp, ob, &vs->mi[k]);
    if (ev == EV_SCATTER)
      ev = scatter_begin(vp, l, &vs->mi[k]) ? EV_SCATTER : EV_END;
    else if (ev == EV_SURFACE)
      ev = surface_emit(vp, sc, l, &si[k], NULL, NULL);
    vs->ev[k] = (unsigned char)ev;
  }
}

/* Stage (d), for the lanes ks[0..n) that bounced or scattered: their
 * depth counted, then the roulette, the numbers of the lanes that draw
 * one drawn together. ev[k] = EV_END where the path ends. */
static void stage_roulette(const volpath_integrator *vp, const scene *sc, sampler_state *st, vlane *ln,
                           const int *idx, const int *ks, int n, const vstage *vs) {
  int nd = 0;
  for (int j = 0; j < n; j++) {
    vlane *l = &ln[idx[ks[j]]];
    l->depth++;
    vs->lid[nd] = idx[ks[j]];
    nd += roulette_draws(vp, l);
  }
  if (nd > 0) sampler_next_1d_batch(st[vs->lid[0]].s, st, vs->lid, nd, vs->d1);
  for (int j = 0, r = 0; j < n; j++) {
    vlane *l = &ln[idx[ks[j]]];
    double u = roulette_draws(vp, l) ? vs->d1[r++] : 0.0;
    if (!roulette(vp, sc, l, NULL, u)) vs->ev[ks[j]] = EV_END;
  }
}

/* Light samples for lanes idx[g[j]], j < n, from ref[j] (vs->ref): the
 * picks' and samples' numbers drawn together, the samples grouped by
 * emitter (wave_sample_emitters), into vs->ek, vs->ds, vs->val. */
static void stage_light_samples(const scene *sc, sampler_state *st, const int *idx, const int *g, int n,
                                const vstage *vs) {
  stage_lanes(idx, g, n, vs->lid);
  sampler_next_1d_2d_batch(st[vs->lid[0]].s, st, vs->lid, n, vs->d1, vs->d2);
  wave_sample_emitters(sc, n, vs->ref, vs->d1, vs->d2, vs->ek, vs->ord, vs->ds, vs->val);
}

/* The BSDF calls of stage (b) go in chunks of BSDF_C lanes, their results
 * on the stack (the stages' scratch is allocated per wave, and more of it
 * costs page faults: see vstage_alloc's caller). A chunk whose lanes share
 * a BSDF with exact batches (bsdf_ops.sample_batch_exact,
 * eval_pdf_batch_exact: the scalar ops' bits) takes one call; any other
 * chunk the scalar ops lane by lane, the same numbers. */
enum {
  BSDF_C = 64
};

/* The BSDF of the surfaces vs->ref[j0..j0 + c) where they all have the
 * same, else NULL. */
static const bsdf *chunk_bsdf(const vstage *vs, int j0, int c) {
  const bsdf *b = vs->ref[j0]->shape->bsdf;
  bool same = true;
  for (int j = j0; j < j0 + c; j++) same &= vs->ref[j]->shape->bsdf == b;
  return same ? b : NULL;
}

/* The BSDFs' values and pdfs towards the light samples of the surfaces
 * vs->ref[j0..j0 + c) (c <= BSDF_C) into f[j - j0], pdf[j - j0], their
 * local directions into wo[j - j0], where a lane needs them
 * (surface_light_lit; an exact batch computes every lane's, the others
 * unused), as surface_light computes them. */
static void stage_bsdf_evals(int j0, int c, const vstage *vs, vec3 *wo, color *f, double *pdf) {
  const bsdf *b = chunk_bsdf(vs, j0, c);
  if (b && b->ops->eval_pdf_batch_exact) {
    for (int i = 0; i < c; i++) wo[i] = frame_to_local(&vs->ref[j0 + i]->sh, vs->ds[j0 + i].d);
    b->ops->eval_pdf_batch_exact(b, c, vs->ref + j0, wo, f, pdf);
    return;
  }
  for (int i = 0; i < c; i++) {
    const surface_interaction *si = vs->ref[j0 + i];
    const direction_sample *ds = &vs->ds[j0 + i];
    if (!surface_light_lit(ds, vs->val[j0 + i])) continue;
    const bsdf *bi = si->shape->bsdf;
    wo[i] = frame_to_local(&si->sh, ds->d);
    f[i] = bi->ops->eval(bi, si, wo[i]);
    pdf[i] = col_is_black(f[i]) || ds->delta ? 0.0 : bi->ops->pdf(bi, si, wo[i]);
  }
}

/* The BSDF samples of the surfaces vs->ref[j0..j0 + c) (c <= BSDF_C) with
 * numbers vs->d1, vs->d2 into bs[j - j0], their weights into w[j - j0]. */
static void stage_bsdf_samples(int j0, int c, const vstage *vs, bsdf_sample *bs, color *w) {
  const bsdf *b = chunk_bsdf(vs, j0, c);
  if (b && b->ops->sample_batch_exact) {
    b->ops->sample_batch_exact(b, c, vs->ref + j0, vs->d1 + j0, vs->d2 + j0, bs, w);
    return;
  }
  for (int i = 0; i < c; i++) {
    const surface_interaction *si = vs->ref[j0 + i];
    const bsdf *bi = si->shape->bsdf;
    w[i] = bi->ops->sample(bi, si, vs->d1[j0 + i], vs->d2[j0 + i], &bs[i]);
  }
}

/* Stage (b): the lanes ks[0..n) that bounce off a surface: the light
 * samples of those whose BSDF takes one and the BSDF's value towards
 * them (stage_bsdf_evals, surface_light_at), then the BSDF samples'
 * numbers (together), the samples (stage_bsdf_samples) and the
 * continuation rays (surface_continue), then the roulette. ev[k]:
 * EV_BOUNCE (goes on) or EV_END. ks is reordered. */
static void stage_surfaces(const volpath_integrator *vp, const scene *sc, sampler_state *st, vlane *ln,
                           const int *idx, int *ks, int n, surface_interaction *si, const hit_bounds *hb,
                           const one_box *ob, const vstage *vs) {
  if (n == 0) return;
  int *g = vs->sub, ng = 0;
  for (int j = 0; j < n; j++) {
    g[ng] = ks[j];
    vs->ref[ng] = &si[ks[j]];
    ng += surface_nee(sc, &si[ks[j]]);
  }
  if (ng > 0) stage_light_samples(sc, st, idx, g, ng, vs);
  for (int j0 = 0; j0 < ng; j0 += BSDF_C) {
    int c = ng - j0 < BSDF_C ? ng - j0 : BSDF_C;
    vec3 wo[BSDF_C];
    color f[BSDF_C];
    double pdf[BSDF_C];
    stage_bsdf_evals(j0, c, vs, wo, f, pdf);
    for (int i = 0; i < c; i++) {
      int j = j0 + i;
      if (surface_light_lit(&vs->ds[j], vs->val[j]) && !col_is_black(f[i])) {
        surface_light_at(sc, &ln[idx[g[j]]], &si[g[j]], sc->emitters[vs->ek[j]],
                         pick_probability(sc, vs->ek[j]), &vs->ds[j], vs->val[j], wo[i], f[i],
                         vs->ds[j].delta ? 0.0 : pdf[i], NULL);
        shadow_now(sc, hb, ob, &ln[idx[g[j]]]);
      }
    }
  }
  stage_lanes(idx, ks, n, vs->lid);
  stage_sample_numbers(st[vs->lid[0]].s, st, vs->lid, n, vs);
  for (int j = 0; j < n; j++) vs->ref[j] = &si[ks[j]];
  int m = 0;
  for (int j0 = 0; j0 < n; j0 += BSDF_C) {
    int c = n - j0 < BSDF_C ? n - j0 : BSDF_C;
    bsdf_sample bs[BSDF_C];
    color w[BSDF_C];
    stage_bsdf_samples(j0, c, vs, bs, w);
    for (int i = 0; i < c; i++) {
      int k = ks[j0 + i];
      bool on = surface_continue(sc, &ln[idx[k]], &si[k], &bs[i], w[i], NULL, NULL);
      vs->ev[k] = (unsigned char)(on ? EV_BOUNCE : EV_END);
      ks[m] = k;
      m += on;
    }
  }
  stage_roulette(vp, sc, st, ln, idx, ks, m, vs);
}

/* Stage (c): the lanes ks[0..n) that scatter in their medium: the light
 * samples of those whose medium takes one and the phase function's value
 * towards them (scatter_light), then the phase samples' numbers
 * (together), the samples and the continuation rays (scatter_phase), then
 * the roulette. ev[k]: EV_SCATTER (goes on) or EV_END. ks is reordered. */
static void stage_scatters(const volpath_integrator *vp, const scene *sc, sampler_state *st, vlane *ln,
                           const int *idx, int *ks, int n, const hit_bounds *hb, const one_box *ob,
                           const vstage *vs) {
  if (n == 0) return;
  int *g = vs->sub, ng = 0;
  for (int j = 0; j < n; j++) {
    g[ng] = ks[j];
    vs->ref[ng] = &ln[idx[ks[j]]].prev;
    ng += scatter_nee(sc, ln[idx[ks[j]]].m);
  }
  if (ng > 0) {
    stage_light_samples(sc, st, idx, g, ng, vs);
    for (int j = 0; j < ng; j++) {
      scatter_light(sc, &ln[idx[g[j]]], &vs->mi[g[j]], sc->emitters[vs->ek[j]],
                    pick_probability(sc, vs->ek[j]), vs->d2[j], &vs->ds[j], vs->val[j], NULL, NULL);
      shadow_now(sc, hb, ob, &ln[idx[g[j]]]);
    }
  }
  stage_lanes(idx, ks, n, vs->lid);
  stage_sample_numbers(st[vs->lid[0]].s, st, vs->lid, n, vs);
  int m = 0;
  for (int j = 0; j < n; j++) {
    int k = ks[j];
    bool on = scatter_phase(sc, &ln[idx[k]], &vs->mi[k], vs->d1[j], vs->d2[j], NULL, NULL);
    vs->ev[k] = (unsigned char)(on ? EV_SCATTER : EV_END);
    ks[m] = k;
    m += on;
  }
  stage_roulette(vp, sc, st, ln, idx, ks, m, vs);
}

/* The events of the live lanes idx[0..live) after their query (hit[k],
 * si[k]) by stages: (a) the segments, (b) the surfaces, (c) the
 * scatterings in the media, each of (b) and (c) ending with (d) the
 * roulette. ev[k] != EV_END: lane idx[k] goes on; ln[i].sh: it has a
 * shadow ray to trace. */
static void wave_events(const volpath_integrator *vp, const scene *sc, sampler_state *st, vlane *ln,
                        const int *idx, int live, const bool *hit, surface_interaction *si, face_plane *fp,
                        const hit_bounds *hb, const one_box *ob, const vstage *vs) {
  stage_segments(vp, sc, st, ln, idx, live, hit, si, fp, ob, vs);
  int n = 0;
  for (int k = 0; k < live; k++) {
    vs->ks[n] = k;
    n += vs->ev[k] == EV_BOUNCE;
  }
  stage_surfaces(vp, sc, st, ln, idx, vs->ks, n, si, hb, ob, vs);
  n = 0;
  for (int k = 0; k < live; k++) {
    vs->ks[n] = k;
    n += vs->ev[k] == EV_SCATTER;
  }
  stage_scatters(vp, sc, st, ln, idx, vs->ks, n, hb, ob, vs);
}

/* Run the wave over n lanes; scratch: ln (n lanes), idx and sh (n ints
 * each), hit (n), si (n), vs (the stages', for n lanes). */
static void wave_run(const volpath_integrator *vp, const scene *sc, sampler_state *st, const ray3 *rays,
                     int n, render_stats *stats, color *L, double *quv, vlane *ln, pol_lane *vq, vpage *pgs,
                     int *idx, int *sh, bool *hit, surface_interaction *si, const vstage *vs) {
  int live = 0;
  for (int i = 0; pgs && i < n; i++) {
    pgs[i].hero = -1;
    for (int p = 1; p < sc->pages; p++) {
      pgs[i].T[p - 1] = col1(1.0);
      pgs[i].L[p - 1] = col1(0.0);
    }
  }
  if (vq)
    for (int i = 0; i < n; i++) pol_start(&vq[i], rays[i].d, pol_channels(sc));
  for (int i = 0; i < n; i++) {
    vlane *l = &ln[i];
    /* Every field but the surface record prev (192 bytes that are written
     * before they are read) and the shadow ray's (start_shadow sets them). */
    l->m = NULL;
    l->T = col1(1.0);
    l->L = col1(0.0);
    l->eta = 1.0;
    l->prev_pdf = 1.0;
    l->prev_delta = true;
    l->depth = l->crossings = 0;
    l->hit = l->sh = l->unres = false;
    ray3 r = rays[i];
    double len = v3_len(r.d);
    if (!(len > 0) || vp->base.max_depth == 0) continue;
    r.d = v3_scale(r.d, 1.0 / len);
    r.tmin *= len;
    r.tmax *= len;
    l->ray = r;
    l->seg_o = r.o;
    l->m = start_medium(sc, &st[i]);
    idx[live++] = i;
  }
  bool camera = true;
  hit_bounds hb;
  hit_bounds_init(sc, &hb);
  face_plane fp[2] = {{.sh = NULL}, {.sh = NULL}};
  /* (the pieces' pages and polarization: lane by lane; vs has no scratch
   * where the caller saw the stages switched off) */
  const bool staged = !vq && !pgs && vs->mi;
  /* The short ways of one_box_of: by stages, and lane by lane for a
   * bundle's pages; with the stages switched off (volpath_set_stages)
   * every walk goes the general way, which test_volpath_stages compares
   * them with. Not with polarization. */
  const one_box ob = !vq && g_stages ? one_box_of(vp, sc) : (one_box){NULL, -1};
  for (unsigned bounce = 1; live > 0; bounce++) {
    if (bounce % WAVE_STOP_EVERY == 0 && render_stop_requested()) break; /* (discarded) */
    wave_trace(sc, &hb, ln, idx, live, false, camera, hit, si, stats);
    camera = false;
    int next = 0, n_sh = 0;
    if (staged) {
      wave_events(vp, sc, st, ln, idx, live, hit, si, fp, &hb, &ob, vs); /* (si[k]: in place) */
      for (int k = 0; k < live; k++) {                                   /* (no branch on the outcomes) */
        int i = idx[k];
        sh[n_sh] = idx[next] = i;
        n_sh += ln[i].sh;
        next += vs->ev[k] != EV_END;
      }
    } else {
      for (int k = 0; k < live; k++) {
        int i = idx[k];
        ln[i].hit = hit[k];
        bool alive = lane_event(vp, sc, &st[i], &ln[i], &si[k], vq ? &vq[i] : NULL, pgs ? &pgs[i] : NULL, fp,
                                &ob); /* (si[k]: in place) */
        if (ln[i].sh) sh[n_sh++] = i;
        if (alive) idx[next++] = i;
      }
    }
    live = next;
    while (n_sh > 0) {
      wave_trace(sc, &hb, ln, sh, n_sh, true, false, hit, si, stats);
      int more = 0;
      for (int k = 0; k < n_sh; k++) {
        int i = sh[k];
        if (shadow_step(vp, sc, &ln[i], vq ? &vq[i] : NULL, pgs ? &pgs[i] : NULL, hit[k], &si[k], &st[i], fp,
                        &ob))
          sh[more++] = i;
      }
      n_sh = more;
    }
  }
  for (int i = 0; i < n; i++) {
    L[i] = ln[i].L;
    stats->unresolved += ln[i].unres;
  }
  const int qs = scene_extra_stride(sc);
  if (quv)
    for (int i = 0; i < qs * n; i++) quv[i] = 0; /* unpolarized variants: no polarisation through media */
  for (int i = 0; pgs && quv && i < n; i++)      /* a bundle's pages 1.. */
    for (int p = 1; p < sc->pages; p++)
      for (int c = 0; c < 3; c++) quv[qs * i + 3 * (p - 1) + c] = pgs[i].L[p - 1].c[c];
  if (vq)
    for (int i = 0; i < n; i++) pol_result(&vq[i], pol_channels(sc), &L[i], quv ? &quv[qs * i] : NULL);
}

/* The stages' scratch for n lanes (vstage_free frees it); false: out of
 * memory. */
static bool vstage_alloc(vstage *vs, int n) {
  size_t m = (size_t)n;
  *vs = (vstage){.mi = malloc(m * sizeof *vs->mi),
                 .ev = malloc(m),
                 .ks = malloc(5 * m * sizeof *vs->ks),
                 .ref = malloc(m * sizeof *vs->ref),
                 .d1 = malloc(m * sizeof *vs->d1),
                 .d2 = malloc(m * sizeof *vs->d2),
                 .ds = malloc(m * sizeof *vs->ds),
                 .val = malloc(m * sizeof *vs->val)};
  if (vs->ks)
    vs->sub = vs->ks + m, vs->lid = vs->ks + 2 * m, vs->ek = vs->ks + 3 * m, vs->ord = vs->ks + 4 * m;
  return vs->mi && vs->ev && vs->ks && vs->ref && vs->d1 && vs->d2 && vs->ds && vs->val;
}

static void vstage_free(vstage *vs) {
  free(vs->mi);
  free(vs->ev);
  free(vs->ks);
  free((void *)vs->ref);
  free(vs->d1);
  free(vs->d2);
  free(vs->ds);
  free(vs->val);
}

static bool volpath_Li_batch(const integrator *it, const scene *sc, sampler_state *st, const ray3 *rays,
                             int n, render_stats *stats, color *L, double *quv) {
  if (n <= 0) return true;
  /* The stages' scratch only where they run: allocated for nothing, it
   * cost the polarized slab 12 % (glibc returned it to the kernel at each
   * free, and the next wave faulted it in again). */
  vstage vs = {0};
  bool staged = !sc->polarized && sc->pages <= 1 && g_stages;
  vlane *ln = malloc((size_t)n * sizeof *ln);
  int *idx = malloc(2 * (size_t)n * sizeof *idx);
  bool *hit = malloc((size_t)n * sizeof *hit);
  surface_interaction *si = malloc((size_t)n * sizeof *si);
  pol_lane *vq = sc->polarized ? pol_alloc(n, pol_channels(sc)) : NULL;
  vpage *pg = sc->pages > 1 ? malloc((size_t)n * sizeof *pg) : NULL;
  bool ok = (!staged || vstage_alloc(&vs, n)) && ln && idx && hit && si && (vq || !sc->polarized) &&
            (pg || sc->pages <= 1);
  if (ok)
    wave_run((const volpath_integrator *)it, sc, st, rays, n, stats, L, quv, ln, vq, pg, idx, idx + n, hit,
             si, &vs);
  vstage_free(&vs);
  pol_free(vq);
  free(pg);
  free(ln);
  free(idx);
  free(hit);
  free(si);
  return ok;
}

static color volpath_Li(const integrator *it, const scene *sc, sampler_state *st, ray3 ray,
                        render_stats *stats, double *quv) {
  vlane ln;
  mueller pm[3];
  pol_lane vq = {.M = pm};
  int idx[2];
  bool hit;
  surface_interaction si;
  color L;
  vpage pg;
  medium_interaction mi;
  unsigned char ev;
  int ks[5];
  const surface_interaction *ref;
  double d1;
  vec2 d2;
  direction_sample ds;
  color val;
  const vstage vs = {.mi = g_stages ? &mi : NULL, /* (NULL: lane by lane, wave_run) */
                     .ev = &ev,
                     .ks = ks,
                     .sub = ks + 1,
                     .lid = ks + 2,
                     .ek = ks + 3,
                     .ord = ks + 4,
                     .ref = &ref,
                     .d1 = &d1,
                     .d2 = &d2,
                     .ds = &ds,
                     .val = &val};
  double q[SCENE_QUV_MAX > SCENE_EXTRA_MAX ? SCENE_QUV_MAX : SCENE_EXTRA_MAX];
  wave_run((const volpath_integrator *)it, sc, st, &ray, 1, stats, &L, quv ? q : NULL, &ln,
           sc->polarized ? &vq : NULL, sc->pages > 1 ? &pg : NULL, idx, idx + 1, &hit, &si, &vs);
  if (quv) /* (a bundle's pages: Li_batch alone gives them) */
    for (int k = 0; k < scene_quv_stride(sc) && sc->pages <= 1; k++) quv[k] += q[k];
  return L;
}

static const integrator_ops volpath_ops = {.Li = volpath_Li, .Li_batch = volpath_Li_batch};

static rsw_status create_common(loader *ld, node *n, object **out, bool analytic) {
  volpath_integrator *vp = calloc(1, sizeof *vp);
  if (!vp) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  vp->base.ops = &volpath_ops;
  vp->analytic = analytic;
  long long md, rr;
  rsw_status st = ld_int(ld, n, "max_depth", -1, -1, 1 << 30, &md);
  if (!st) st = ld_int(ld, n, "rr_depth", 5, 1, 1 << 30, &rr);
  if (!st) st = ld_bool(ld, n, "hide_emitters", false, &vp->base.hide_emitters);
  const char *rule = NULL;
  if (!st) st = ld_string(ld, n, "rr_rule", "throughput", &rule);
  if (!st && strcmp(rule, "mitsuba") == 0)
    vp->rr_mitsuba = true;
  else if (!st && strcmp(rule, "throughput") != 0)
    st = ld_fail(ld, n, "rr_rule", RSW_ERR_INVALID,
                 "%s: unknown rr_rule '%s' (expected throughput or mitsuba)",
                 analytic ? "piecewise_volpath" : "volpath", rule);
  if (st) {
    free(vp);
    return st;
  }
  vp->base.max_depth = (int)md;
  vp->base.rr_depth = (int)rr;
  /* Pages: exact free flights weight every page by its own transmittance
   * (flight_pages), tracked ones track every page at once (track_pages,
   * segment_tr_pages). */
  vp->base.pages = true;
  *out = &vp->base.base;
  return RSW_OK;
}

static rsw_status volpath_create(loader *ld, node *n, object **out) {
  return create_common(ld, n, out, false);
}

static rsw_status piecewise_volpath_create(loader *ld, node *n, object **out) {
  return create_common(ld, n, out, true);
}

DEFINE_PLUGIN(volpath, CLS_INTEGRATOR, .ops = &volpath_ops);
DEFINE_PLUGIN(piecewise_volpath, CLS_INTEGRATOR, .ops = &volpath_ops);
