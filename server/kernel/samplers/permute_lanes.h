/* Kensler 2013, "Correlated Multi-Jittered Sampling" (Pixar technical memo
 * 13-01), listing 3: a hash-based permutation of [0, l) indexed by the
 * seed p, written once for the stratified sampler's scalar permute() and
 * its lanes (samplers/stratified.c). Each round is invertible on the bits
 * selected by the mask w (the smallest all-ones mask >= l - 1); results >=
 * l are re-hashed (cycle walking), which keeps the map a bijection on
 * [0, l). Integer arithmetic: the lanes are bitwise the scalar. */
#ifndef RSW_SAMPLERS_PERMUTE_LANES_H
#define RSW_SAMPLERS_PERMUTE_LANES_H

#include <stdint.h>

static inline uint32_t permute_mask(uint32_t l) {
  uint32_t w = l - 1;
  w |= w >> 1;
  w |= w >> 2;
  w |= w >> 4;
  w |= w >> 8;
  w |= w >> 16;
  return w;
}

/* One hash of i (a uint32_t, or a vector of them with p alike) under seed
 * p and mask w. */
#define PERMUTE_HASH(i, p, w)                                                                                \
  do {                                                                                                       \
    (i) ^= (p);                                                                                              \
    (i) *= 0xe170893du;                                                                                      \
    (i) ^= (p) >> 16;                                                                                        \
    (i) ^= ((i) & (w)) >> 4;                                                                                 \
    (i) ^= (p) >> 8;                                                                                         \
    (i) *= 0x0929eb3fu;                                                                                      \
    (i) ^= (p) >> 23;                                                                                        \
    (i) ^= ((i) & (w)) >> 1;                                                                                 \
    (i) *= 1u | (p) >> 27;                                                                                   \
    (i) *= 0x6935fa69u;                                                                                      \
    (i) ^= ((i) & (w)) >> 11;                                                                                \
    (i) *= 0x74dcb303u;                                                                                      \
    (i) ^= ((i) & (w)) >> 2;                                                                                 \
    (i) *= 0x9e501cc3u;                                                                                      \
    (i) ^= ((i) & (w)) >> 2;                                                                                 \
    (i) *= 0xc860a3dfu;                                                                                      \
    (i) &= (w);                                                                                              \
    (i) ^= (i) >> 5;                                                                                         \
  } while (0)

#endif

/* The permutation of VW lanes at once in 32-bit integer lanes (VU32),
 * instantiated per ISA by stratified.c after it defined PERM_FN and
 * PERM_ATTR: each lane runs the scalar rounds; cycle walking continues,
 * masked, until every lane has landed in [0, l). When l is a power of two
 * (l = w + 1, every square sample count 4^k) the first round lands every
 * lane (it ends masked to w, and i ^ i >> 5 keeps those bits) and
 * (i + p) mod l is (i + p) & w: one round, no walking, no division. */
#ifdef PERM_FN
PERM_ATTR void PERM_FN(int n, const uint32_t *in, uint32_t l, const uint32_t *seed, uint32_t *out) {
  uint32_t w = permute_mask(l);
  if (w == l - 1) {
    int k0 = 0;
    for (; k0 + VW <= n; k0 += VW) {
      VU32 i, p;
      __builtin_memcpy(&i, &in[k0], sizeof i);
      __builtin_memcpy(&p, &seed[k0], sizeof p);
      PERMUTE_HASH(i, p, w);
      i = (i + p) & w;
      __builtin_memcpy(&out[k0], &i, sizeof i);
    }
    for (; k0 < n; k0++) {
      uint32_t i = in[k0], p = seed[k0];
      PERMUTE_HASH(i, p, w);
      out[k0] = (i + p) & w;
    }
    return;
  }
  for (int k0 = 0; k0 < n; k0 += VW) {
    int cnt = n - k0 < VW ? n - k0 : VW;
    VU32 i, p;
    if (cnt == VW) {
      __builtin_memcpy(&i, &in[k0], sizeof i);
      __builtin_memcpy(&p, &seed[k0], sizeof p);
    } else {
      for (int k = 0; k < VW; k++) {
        int q = k0 + (k < cnt ? k : cnt - 1);
        i[k] = in[q], p[k] = seed[q];
      }
    }
    VU32 res = i, active = (VU32){0} + 0xffffffffu;
    for (;;) {
      PERMUTE_HASH(i, p, w);
      VU32 landed = active & (VU32)(i < l);
      res = (landed & i) | (~landed & res);
      active &= ~landed;
      uint32_t any = 0;
      for (int k = 0; k < VW; k++) any |= active[k];
      if (!any) break;
    }
    for (int k = 0; k < cnt; k++) out[k0 + k] = (res[k] + p[k]) % l;
  }
}
#endif
