/* What the integrators' waves share (integrators/path.c, volpath.c): the
 * light samples of many lanes, grouped by emitter so that each emitter
 * samples its lanes in one call (emitter_ops.sample_direction_batch). */
#ifndef RSW_INTEGRATORS_WAVE_H
#define RSW_INTEGRATORS_WAVE_H

#include "../kernel.h"
#include "integrator.h"

/* Scenes with more emitters than this sample lane by lane. */
#define WAVE_EMITTER_GROUPS 64

/* Lanes 0..n) grouped by their emitters ek[] (< sc->n_emitters <=
 * WAVE_EMITTER_GROUPS), a counting sort: emitter e's lanes are
 * ord[start[e]..start[e + 1]), in lane order. */
static inline void wave_group_by_emitter(const scene *sc, const int *ek, int n,
                                         int start[WAVE_EMITTER_GROUPS + 1], int *ord) {
  if (sc->n_emitters == 1) { /* every ek[j] is 0: the count's chain through memory is skipped */
    start[0] = 0, start[1] = n;
    for (int j = 0; j < n; j++) ord[j] = j;
    return;
  }
  int fill[WAVE_EMITTER_GROUPS];
  for (size_t e = 0; e <= sc->n_emitters; e++) start[e] = 0;
  for (int j = 0; j < n; j++) start[ek[j] + 1]++;
  for (size_t e = 0; e < sc->n_emitters; e++) start[e + 1] += start[e];
  for (size_t e = 0; e < sc->n_emitters; e++) fill[e] = start[e];
  for (int j = 0; j < n; j++) ord[fill[ek[j]]++] = j;
}

/* Light samples of n lanes: lane j picks emitter ek[j] with its number
 * u1[j] (pick_emitter_index) and samples it from ref[j] with u2[j] into
 * ds[j], value[j]. The lanes are grouped by emitter (a counting sort, in
 * lane order within each emitter) for one emitter_sample_direction_n call
 * per emitter and chunk of 64; a lane's sample does not depend on its
 * group. ord: n ints of scratch. */
static inline void wave_sample_emitters(const scene *sc, int n, const surface_interaction *const *ref,
                                        const double *u1, const vec2 *u2, int *ek, int *ord,
                                        direction_sample *ds, color *value) {
  enum {
    C = 64
  };
  for (int j = 0; j < n; j++) ek[j] = (int)pick_emitter_index(sc, u1[j]);
  if (sc->n_emitters == 1) { /* one group, in lane order already */
    for (int j0 = 0; j0 < n; j0 += C) {
      int m = n - j0 < C ? n - j0 : C;
      emitter_sample_direction_n(sc->emitters[0], m, ref + j0, u2 + j0, ds + j0, value + j0);
    }
    return;
  }
  if (sc->n_emitters > WAVE_EMITTER_GROUPS) {
    for (int j = 0; j < n; j++) {
      const emitter *e = sc->emitters[ek[j]];
      value[j] = e->ops->sample_direction(e, ref[j], u2[j], &ds[j]);
    }
    return;
  }
  int start[WAVE_EMITTER_GROUPS + 1];
  wave_group_by_emitter(sc, ek, n, start, ord);
  for (size_t e = 0; e < sc->n_emitters; e++) {
    for (int j0 = start[e]; j0 < start[e + 1]; j0 += C) {
      int m = start[e + 1] - j0 < C ? start[e + 1] - j0 : C;
      const surface_interaction *r[C];
      vec2 u[C];
      direction_sample d[C];
      color v[C];
      for (int j = 0; j < m; j++) r[j] = ref[ord[j0 + j]], u[j] = u2[ord[j0 + j]];
      emitter_sample_direction_n(sc->emitters[e], m, r, u, d, v);
      for (int j = 0; j < m; j++) ds[ord[j0 + j]] = d[j], value[ord[j0 + j]] = v[j];
    }
  }
}

#endif
