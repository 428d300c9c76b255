/* What the path tracers share (integrators/path.c, volpath.c): the
 * power-heuristic MIS weight and the emitter selection by
 * sampling_weight (Mitsuba 3's, docs/kernel-conventions.md#path). */
#ifndef RSW_INTEGRATORS_INTEGRATOR_H
#define RSW_INTEGRATORS_INTEGRATOR_H

#include <math.h>

#include "../core/isa.h"
#include "../kernel.h"

/* Power heuristic w(a, b) = a^2 / (a^2 + b^2); 0 where it is not finite. */
static inline double mis_weight(double a, double b) {
  a *= a;
  b *= b;
  double w = a / (a + b);
  return isfinite(w) ? w : 0.0;
}

/* The emitter that u in [0, 1) picks, proportionally to sampling_weight:
 * the first k < n - 1 with cdf[k] > t = u * sum, else n - 1. The cdf
 * never decreases (weights >= 0), so the cdf[k] <= t form a prefix and
 * the pick is their count over k < n - 1 (a NaN t counts none, as the
 * search goes left): a few emitters are counted in a loop of fixed
 * length, more are searched, written for conditional moves (which way a
 * random number goes is unpredictable; the search's length varies with
 * it, the count's does not). */
#define PICK_COUNT_MAX 8
static inline size_t pick_emitter_index(const scene *sc, double u) {
  double t = u * sc->emitter_weight_sum;
  if (sc->n_emitters <= PICK_COUNT_MAX) {
    size_t k = 0;
    for (size_t i = 0; i + 1 < sc->n_emitters; i++) k += sc->emitter_cdf[i] <= t;
    return k;
  }
  size_t lo = 0, hi = sc->n_emitters - 1;
  while (lo < hi) {
    size_t mid = (lo + hi) / 2;
    bool right = sc->emitter_cdf[mid] <= t;
    lo = right ? mid + 1 : lo;
    hi = right ? hi : mid;
  }
  return lo;
}

/* The probability that emitter k is picked. */
static inline double pick_probability(const scene *sc, size_t k) {
  return sc->emitters[k]->sampling_weight / sc->emitter_weight_sum;
}

/* The same for an emitter given by pointer (0 when no emitter has weight). */
static inline double emitter_prob(const scene *sc, const emitter *e) {
  return sc->emitter_weight_sum > 0 ? e->sampling_weight / sc->emitter_weight_sum : 0.0;
}

/* The shadow ray from si towards the light sample ds of emitter e
 * (integrators/path.c says how it is offset at both ends). */
ray3 spawn_ray_to(const scene *sc, const surface_interaction *si, const emitter *e,
                  const direction_sample *ds);
/* spawn_ray_between(si[j], q[j], nq[j], qerr[j]) into r[j] for j < n, in
 * structure-of-arrays lanes at ISA isa: path's shadow rays towards surface
 * emitters, bitwise the scalar function at every ISA (test_wave). */
void spawn_rays_between_batch(rsw_isa isa, int n, const surface_interaction *const *si, const vec3 *q,
                              const vec3 *nq, const double *qerr, ray3 *r);

/* volpath's and piecewise_volpath's waves: by stages over the lanes (on,
 * the default) or lane by lane (off), for the whole process; the films
 * are bitwise the same either way (for the tests that check it). */
void volpath_set_stages(bool on);

#endif
