/* A wave's sampler draws (kernel.h sampler_ops start_batch, next_1d_batch,
 * next_2d_batch), or the per-lane ops in a loop for a sampler without
 * them: either way each lane gets exactly the numbers of its own per-lane
 * calls. All lanes share the sampler s (one sensor's). */
#ifndef RSW_SAMPLERS_SAMPLER_BATCH_H
#define RSW_SAMPLERS_SAMPLER_BATCH_H

#include "../kernel.h"

static inline void sampler_start_batch(const sampler *s, sampler_state *st, int n, uint64_t seed,
                                       const uint64_t *pixel, const uint32_t *sample_index, uint32_t spp) {
  if (s->ops->start_batch) {
    s->ops->start_batch(s, st, n, seed, pixel, sample_index, spp);
    return;
  }
  for (int k = 0; k < n; k++) s->ops->start(s, &st[k], seed, pixel[k], sample_index[k], spp);
}

static inline void sampler_next_1d_batch(const sampler *s, sampler_state *st, const int *idx, int n,
                                         double *out) {
  if (s->ops->next_1d_batch) {
    s->ops->next_1d_batch(st, idx, n, out);
    return;
  }
  for (int k = 0; k < n; k++) out[k] = s->ops->next_1d(&st[idx ? idx[k] : k]);
}

static inline void sampler_next_2d_batch(const sampler *s, sampler_state *st, const int *idx, int n,
                                         vec2 *out) {
  if (s->ops->next_2d_batch) {
    s->ops->next_2d_batch(st, idx, n, out);
    return;
  }
  for (int k = 0; k < n; k++) out[k] = s->ops->next_2d(&st[idx ? idx[k] : k]);
}

/* A 1-D then a 2-D number per lane (next_1d_2d_batch, or the two batches
 * above: the same numbers). */
static inline void sampler_next_1d_2d_batch(const sampler *s, sampler_state *st, const int *idx, int n,
                                            double *out1, vec2 *out2) {
  if (s->ops->next_1d_2d_batch) {
    s->ops->next_1d_2d_batch(st, idx, n, out1, out2);
    return;
  }
  sampler_next_1d_batch(s, st, idx, n, out1);
  sampler_next_2d_batch(s, st, idx, n, out2);
}

/* Two 2-D numbers per lane (next_2d_2d_batch, or next_2d_batch twice:
 * the same numbers). */
static inline void sampler_next_2d_2d_batch(const sampler *s, sampler_state *st, const int *idx, int n,
                                            vec2 *out1, vec2 *out2) {
  if (s->ops->next_2d_2d_batch) {
    s->ops->next_2d_2d_batch(st, idx, n, out1, out2);
    return;
  }
  sampler_next_2d_batch(s, st, idx, n, out1);
  sampler_next_2d_batch(s, st, idx, n, out2);
}

/* sampler_start_batch, then two 2-D numbers per sample (out1[k],
 * out2[k]): start_2d_2d_batch, or the two calls (the same numbers). */
static inline void sampler_start_2d_2d_batch(const sampler *s, sampler_state *st, int n, uint64_t seed,
                                             const uint64_t *pixel, const uint32_t *sample_index,
                                             uint32_t spp, vec2 *out1, vec2 *out2) {
  if (s->ops->start_2d_2d_batch) {
    s->ops->start_2d_2d_batch(s, st, n, seed, pixel, sample_index, spp, out1, out2);
    return;
  }
  sampler_start_batch(s, st, n, seed, pixel, sample_index, spp);
  sampler_next_2d_2d_batch(s, st, NULL, n, out1, out2);
}

#endif
