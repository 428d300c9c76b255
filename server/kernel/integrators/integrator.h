/* What the path tracers share (integrators/path.c, volpath.c): the
 * power-heuristic MIS weight and the emitter selection by
 * sampling_weight (Mitsuba 3's, docs/kernel-conventions.md#path). */
#ifndef RSW_INTEGRATORS_INTEGRATOR_H
#define RSW_INTEGRATORS_INTEGRATOR_H

#include <math.h>

#include "../kernel.h"

/* Power heuristic w(a, b) = a^2 / (a^2 + b^2); 0 where it is not finite. */
static inline double mis_weight(double a, double b) {
  a *= a;
  b *= b;
  double w = a / (a + b);
  return isfinite(w) ? w : 0.0;
}

/* The emitter that u in [0, 1) picks, proportionally to sampling_weight.
 * The search is written for conditional moves (which way a random number
 * goes is unpredictable). */
static inline size_t pick_emitter_index(const scene *sc, double u) {
  double t = u * sc->emitter_weight_sum;
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

#endif
