/* The body of pcg_simd.c's batched PCG32 seeding and draws for one ISA:
 * VW 64-bit lanes (VU, with VU32 the same lanes as 32-bit words for the
 * TEA rounds, VD as doubles), included once per ISA after PCG_SEED_FN,
 * PCG_DRAW_FN (or PCG_NO_DRAW) and PCG_ATTR are defined. Integer arithmetic wraps exactly
 * as core/rng.h's scalar code (unsigned, modulo 2^32 or 2^64), and the
 * conversion of a 32-bit draw to double is exact, so every lane is
 * bitwise the scalar stream. */

/* core/rng.h pcg32_seed(tea64(fold32(key), index, 4), mix64(key + index)),
 * fold32(key) = (uint32_t)(key ^ (key >> 32)). */
PCG_ATTR void PCG_SEED_FN(int n, const uint64_t *key, const uint32_t *index, uint64_t *state, uint64_t *inc) {
  for (int k0 = 0; k0 < n; k0 += VW) {
    int cnt = n - k0 < VW ? n - k0 : VW;
    VU kk = {0}, ix = {0};
    for (int k = 0; k < cnt; k++) kk[k] = key[k0 + k], ix[k] = index[k0 + k];
    VU32 v0 = __builtin_convertvector(kk ^ (kk >> 32), VU32), v1 = __builtin_convertvector(ix, VU32);
    uint32_t sum = 0;
    for (int i = 0; i < 4; i++) {
      sum += 0x9e3779b9u;
      v0 += ((v1 << 4) + 0xa341316cu) ^ (v1 + sum) ^ ((v1 >> 5) + 0xc8013ea4u);
      v1 += ((v0 << 4) + 0xad90777du) ^ (v0 + sum) ^ ((v0 >> 5) + 0x7e95761eu);
    }
    VU initstate = (__builtin_convertvector(v1, VU) << 32) | __builtin_convertvector(v0, VU);
    VU z = kk + ix; /* mix64 */
    z += 0x9e3779b97f4a7c15ULL;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    z = z ^ (z >> 31);
    VU in = (z << 1) | 1u;
    VU s = in + initstate; /* 0 * MULT + inc, then + initstate */
    s = s * PCG32_MULT + in;
    for (int k = 0; k < cnt; k++) state[k0 + k] = s[k], inc[k0 + k] = in[k];
  }
}

#ifndef PCG_NO_DRAW
/* `draws` pcg32_next_double() per lane st[idx[k]] (idx NULL: st[k]), in
 * order, into out[draws k + j]; the states advance. */
PCG_ATTR void PCG_DRAW_FN(sampler_state *st, const int *idx, int n, int draws, double *out) {
  for (int k0 = 0; k0 < n; k0 += VW) {
    int cnt = n - k0 < VW ? n - k0 : VW;
    VU s = {0}, in = {0};
    for (int k = 0; k < cnt; k++) {
      const pcg32 *r = &st[idx ? idx[k0 + k] : k0 + k].rng;
      s[k] = r->state, in[k] = r->inc;
    }
    for (int j = 0; j < draws; j++) {
      VU old = s;
      s = old * PCG32_MULT + in;
      VU xs = (((old >> 18u) ^ old) >> 27u) & 0xffffffffu;
      VU rot = old >> 59u;
      VU r = ((xs >> rot) | (xs << ((-rot) & 31u))) & 0xffffffffu;
      /* r < 2^32 as a double, exactly: the bits of 2^52 + r, minus 2^52. */
      VD d = ((VD)(r | 0x4330000000000000ULL) - 4503599627370496.0) * (1.0 / 4294967296.0);
      for (int k = 0; k < cnt; k++) out[draws * (k0 + k) + j] = d[k];
    }
    for (int k = 0; k < cnt; k++) st[idx ? idx[k0 + k] : k0 + k].rng.state = s[k];
  }
}
#endif
