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

/* Upper bound on sample_count (keeps ceil(sqrt(spp))^2 within 32 bits). */
#define SAMPLER_MAX_SPP (1LL << 30)

static inline uint64_t sampler_pixel_key(uint64_t seed, uint64_t pixel) {
  return mix64(mix64(seed) ^ pixel);
}

static inline void sampler_seed_stream(const sampler *s, sampler_state *st, uint64_t seed, uint64_t pixel,
                                       uint32_t sample_index, uint32_t spp) {
  st->s = s;
  st->pixel_key = sampler_pixel_key(seed + s->seed, pixel);
  st->sample_index = sample_index;
  st->spp = spp;
  st->dim = 0;
  uint32_t fold = (uint32_t)(st->pixel_key ^ (st->pixel_key >> 32));
  pcg32_seed(&st->rng, tea64(fold, sample_index, 4), mix64(st->pixel_key + sample_index));
}

#endif
