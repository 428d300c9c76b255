/* The body of pcg_simd.c's batched PCG32 seeding for one ISA: VW 64-bit
 * lanes (VU, with VU32 the same lanes as 32-bit words for the TEA rounds),
 * included once per ISA after PCG_SEED_FN and PCG_ATTR are defined.
 * Integer arithmetic wraps exactly as core/rng.h's scalar code (unsigned,
 * modulo 2^32 or 2^64), so every lane is bitwise the scalar stream. */

/* core/rng.h pcg32_seed(tea64(fold32(key), index, 4), mix64(key + index)),
 * fold32(key) = (uint32_t)(key ^ (key >> 32)). */
PCG_ATTR void PCG_SEED_FN(int n, const uint64_t *key, const uint32_t *index, uint64_t *state, uint64_t *inc) {
  for (int k0 = 0; k0 < n; k0 += VW) {
    int cnt = n - k0 < VW ? n - k0 : VW;
    /* Every lane set, a tail's from its last lane (a variable count of
     * element stores then a vector load would stall on store forwarding). */
    VU kk, ix;
    if (cnt == VW) {
      __builtin_memcpy(&kk, &key[k0], sizeof kk);
      VU32 i32;
      __builtin_memcpy(&i32, &index[k0], sizeof i32);
      ix = __builtin_convertvector(i32, VU);
    } else {
      for (int k = 0; k < VW; k++) {
        int q = k0 + (k < cnt ? k : cnt - 1);
        kk[k] = key[q], ix[k] = index[q];
      }
    }
    VU32 v0 = __builtin_convertvector(kk ^ (kk >> 32), VU32), v1 = __builtin_convertvector(ix, VU32);
    uint32_t sum = 0;
    for (int i = 0; i < 4; i++) {
      sum += 0x9e3779b9u;
      v0 += ((v1 << 4) + 0xa341316cu) ^ (v1 + sum) ^ ((v1 >> 5) + 0xc8013ea4u);
      v1 += ((v0 << 4) + 0xad90777du) ^ (v0 + sum) ^ ((v0 >> 5) + 0x7e95761eu);
    }
    VU initstate = (__builtin_convertvector(v1, VU) << 32) | __builtin_convertvector(v0, VU);
    /* The 64-bit products lane by lane: a scalar multiply is one
     * instruction, a vector one below AVX-512 several (the seed scene's
     * seeding took 2.6% of a render with them in the lanes). */
    for (int k = 0; k < cnt; k++) {
      uint64_t z = mix64(kk[k] + ix[k]), in = (z << 1) | 1u;
      state[k0 + k] = (in + initstate[k]) * PCG32_MULT + in; /* 0 * MULT + inc, then + initstate */
      inc[k0 + k] = in;
    }
  }
}
