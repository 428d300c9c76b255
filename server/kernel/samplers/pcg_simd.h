/* The PCG32 seeding of many sample streams at once (pcg_simd.c), which
 * sampler_common.h's sampler_seed_streams calls. */
#ifndef RSW_SAMPLERS_PCG_SIMD_H
#define RSW_SAMPLERS_PCG_SIMD_H

#include "../kernel.h"

/* For n lanes (pcg_simd.c, vectorised at the render's ISA; bitwise the
 * scalar code): the PCG32 state and increment that sampler_seed_stream_key
 * gives pixel key key[k] and sample index[k]. */
void sampler_pcg_seed_batch(int n, const uint64_t *key, const uint32_t *index, uint64_t *state,
                            uint64_t *inc);

/* For n streams (state[k], inc[k]; pcg_simd.c, vectorised at the render's
 * ISA, bitwise the scalar code): `draws` numbers of each as core/rng.h's
 * pcg32_next_double gives them in turn, out[d * n + k], and state[k]
 * advanced past them. */
void sampler_pcg_draw_batch(int n, uint64_t *state, const uint64_t *inc, int draws, double *out);

#endif
