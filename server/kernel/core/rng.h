/* PCG32 (O'Neill 2014, pcg32 "XSH RR" with 64-bit state) and the TEA hash
 * Mitsuba uses to seed per-sample streams (sample_tea_32/64).
 * Determinism: a render derives every stream from (seed, pixel, sample
 * index) through these functions only. */
#ifndef RSW_CORE_RNG_H
#define RSW_CORE_RNG_H

#include <stdint.h>

#define PCG32_DEFAULT_STATE  0x853c49e6748fea9bULL
#define PCG32_DEFAULT_STREAM 0xda3e39cb94b95bdbULL
#define PCG32_MULT           0x5851f42d4c957f2dULL

typedef struct pcg32 {
  uint64_t state, inc;
} pcg32;

static inline uint32_t pcg32_next(pcg32 *r) {
  uint64_t old = r->state;
  r->state = old * PCG32_MULT + r->inc;
  uint32_t xorshifted = (uint32_t)(((old >> 18u) ^ old) >> 27u);
  uint32_t rot = (uint32_t)(old >> 59u);
  return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31));
}

static inline void pcg32_seed(pcg32 *r, uint64_t initstate, uint64_t initseq) {
  r->state = 0u;
  r->inc = (initseq << 1u) | 1u;
  pcg32_next(r);
  r->state += initstate;
  pcg32_next(r);
}

/* Uniform double in [0, 1) with 32 random bits (exactly representable). */
static inline double pcg32_next_double(pcg32 *r) {
  return (double)pcg32_next(r) * (1.0 / 4294967296.0);
}

/* Tiny Encryption Algorithm as a hash of two 32-bit words (Zafar et al.
 * 2010, "GPU random numbers via the tiny encryption algorithm"); Mitsuba's
 * sample_tea_32 with 4 rounds by default. */
static inline uint64_t tea64(uint32_t v0, uint32_t v1, int rounds) {
  uint32_t sum = 0;
  for (int i = 0; i < rounds; i++) {
    sum += 0x9e3779b9u;
    v0 += ((v1 << 4) + 0xa341316cu) ^ (v1 + sum) ^ ((v1 >> 5) + 0xc8013ea4u);
    v1 += ((v0 << 4) + 0xad90777du) ^ (v0 + sum) ^ ((v0 >> 5) + 0x7e95761eu);
  }
  return ((uint64_t)v1 << 32) | v0;
}

/* 64-bit finaliser (splitmix64), used to mix seeds before TEA. */
static inline uint64_t mix64(uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

#endif
