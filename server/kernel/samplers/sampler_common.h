/* Per-sample stream seeding shared by the sampler plugins (private to
 * samplers/). Determinism (DESIGN.md): every value a sample draws is a
 * function of (render seed + sampler seed, pixel, sample index) only, so
 * any split of the film over threads gives bitwise-identical results.
 *
 *   pixel_key = mix64(mix64(seed + sampler seed) ^ pixel)
 *   pcg32 initstate = tea64(fold32(pixel_key), sample_index)   (Mitsuba
 *                     seeds its PCG32 streams with sample_tea_32 of the
 *                     seed and the sample index, src/render/sampler.cpp)
 *   pcg32 initseq   = mix64(pixel_key + sample_index)
 * so two samples differ in both the PCG state and the stream. */
#ifndef RSW_SAMPLERS_SAMPLER_COMMON_H
#define RSW_SAMPLERS_SAMPLER_COMMON_H

#include "../kernel.h"
#include "pcg_simd.h"

/* Upper bound on sample_count (keeps ceil(sqrt(spp))^2 within 32 bits). */
#define SAMPLER_MAX_SPP (1LL << 30)

static inline uint64_t sampler_pixel_key(uint64_t seed, uint64_t pixel) {
  return mix64(mix64(seed) ^ pixel);
}

/* sampler_seed_stream given the pixel's key (sampler_pixel_key(seed +
 * s->seed, pixel)), which the samples of one pixel share. */
static inline void sampler_seed_stream_key(const sampler *s, sampler_state *st, uint64_t key,
                                           uint32_t sample_index, uint32_t spp) {
  st->s = s;
  st->pixel_key = key;
  st->sample_index = sample_index;
  st->spp = spp;
  st->dim = 0;
  uint32_t fold = (uint32_t)(st->pixel_key ^ (st->pixel_key >> 32));
  pcg32_seed(&st->rng, tea64(fold, sample_index, 4), mix64(st->pixel_key + sample_index));
}

static inline void sampler_seed_stream(const sampler *s, sampler_state *st, uint64_t seed, uint64_t pixel,
                                       uint32_t sample_index, uint32_t spp) {
  sampler_seed_stream_key(s, st, sampler_pixel_key(seed + s->seed, pixel), sample_index, spp);
}

/* start_batch of both samplers: the pixel's key once per run of samples
 * of the same pixel (a wave holds consecutive samples of few pixels), the
 * streams seeded together. out1, out2 (NULL: none): the independent
 * sampler's first two next_2d() of each stream, out1[k] then out2[k],
 * drawn while the streams are at hand (the state left past them). */
static inline void sampler_seed_streams(const sampler *s, sampler_state *st, int n, uint64_t seed,
                                        const uint64_t *pixel, const uint32_t *sample_index, uint32_t spp,
                                        vec2 *out1, vec2 *out2) {
  enum {
    C = 64
  };
  uint64_t key[C], state[C], inc[C], last = 0;
  double u[4 * C];
  for (int k0 = 0; k0 < n; k0 += C) {
    int m = n - k0 < C ? n - k0 : C;
    for (int k = 0; k < m; k++) {
      int i = k0 + k;
      if (i == 0 || pixel[i] != pixel[i - 1]) last = sampler_pixel_key(seed + s->seed, pixel[i]);
      key[k] = last;
    }
    sampler_pcg_seed_batch(m, key, sample_index + k0, state, inc);
    if (out1) {
      sampler_pcg_draw_batch(m, state, inc, 4, u);
      for (int k = 0; k < m; k++)
        out1[k0 + k] = v2(u[k], u[m + k]), out2[k0 + k] = v2(u[2 * m + k], u[3 * m + k]);
    }
    for (int k = 0; k < m; k++) {
      sampler_state *q = &st[k0 + k];
      q->s = s;
      q->pixel_key = key[k];
      q->sample_index = sample_index[k0 + k];
      q->spp = spp;
      q->dim = out1 ? 2 : 0;
      q->rng.state = state[k];
      q->rng.inc = inc[k];
    }
  }
}

#endif
