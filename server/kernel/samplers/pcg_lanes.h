/* The body of pcg_simd.c's batched PCG32 seeding for one ISA: VW 64-bit
 * lanes (VU, with VU32 the same lanes as 32-bit words for the TEA rounds),
 * included once per ISA after PCG_SEED_FN and PCG_ATTR are defined.
 * Integer arithmetic wraps exactly as core/rng.h's scalar code (unsigned,
 * modulo 2^32 or 2^64), so every lane is bitwise the scalar stream. */

/* core/rng.h pcg32_seed(tea64(fold32(key), index, 4), mix64(key + index)),
 * fold32(key) = (uint32_t)(key ^ (key >> 32)). */
PCG_ATTR void PCG_SEED_FN(int n, const uint64_t *key, const uint32_t *index, uint64_t *state, uint64_t *inc) {
  /* PCG_IL vectors of lanes per step, their TEA rounds interleaved: one
   * vector's rounds are a chain of dependent operations, several give the
   * core independent work to overlap. */
  for (int k0 = 0; k0 < n; k0 += PCG_IL * VW) {
    int cnt = n - k0 < PCG_IL * VW ? n - k0 : PCG_IL * VW;
    /* Every lane set, a tail's from its last lane (a variable count of
     * element stores then a vector load would stall on store forwarding). */
    VU kk[PCG_IL] = {{0}}, ix[PCG_IL] = {{0}};
    for (int h = 0; h < PCG_IL; h++) {
      if (cnt == PCG_IL * VW) {
        __builtin_memcpy(&kk[h], &key[k0 + h * VW], sizeof kk[h]);
        VU32 i32;
        __builtin_memcpy(&i32, &index[k0 + h * VW], sizeof i32);
        ix[h] = __builtin_convertvector(i32, VU);
      } else {
        for (int k = 0; k < VW; k++) {
          int j = h * VW + k, q = k0 + (j < cnt ? j : cnt - 1);
          kk[h][k] = key[q], ix[h][k] = index[q];
        }
      }
    }
    VU32 v0[PCG_IL], v1[PCG_IL];
    for (int h = 0; h < PCG_IL; h++)
      v0[h] = __builtin_convertvector(kk[h] ^ (kk[h] >> 32), VU32),
      v1[h] = __builtin_convertvector(ix[h], VU32);
    uint32_t sum = 0;
    for (int i = 0; i < 4; i++) {
      sum += 0x9e3779b9u;
      for (int h = 0; h < PCG_IL; h++)
        v0[h] += ((v1[h] << 4) + 0xa341316cu) ^ (v1[h] + sum) ^ ((v1[h] >> 5) + 0xc8013ea4u);
      for (int h = 0; h < PCG_IL; h++)
        v1[h] += ((v0[h] << 4) + 0xad90777du) ^ (v0[h] + sum) ^ ((v0[h] >> 5) + 0x7e95761eu);
    }
    /* The 64-bit products lane by lane below AVX-512 (PCG_VMUL 0): a
     * scalar multiply is one instruction, a vector one there several (the
     * seed scene's seeding took 2.6% of a render with them in the lanes);
     * at AVX-512 (one instruction) in the lanes, whole vectors stored. */
    for (int h = 0; h < PCG_IL; h++) {
      VU initstate = (__builtin_convertvector(v1[h], VU) << 32) | __builtin_convertvector(v0[h], VU);
      if (PCG_VMUL && cnt == PCG_IL * VW) {
        VU z = kk[h] + ix[h] + 0x9e3779b97f4a7c15ULL; /* mix64 */
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
        z ^= z >> 31;
        VU in = (z << 1) | 1u, st = (in + initstate) * PCG32_MULT + in;
        __builtin_memcpy(&state[k0 + h * VW], &st, sizeof st);
        __builtin_memcpy(&inc[k0 + h * VW], &in, sizeof in);
        continue;
      }
      for (int k = 0; k < VW && h * VW + k < cnt; k++) {
        int j = k0 + h * VW + k;
        uint64_t z = mix64(kk[h][k] + ix[h][k]), in = (z << 1) | 1u;
        state[j] = (in + initstate[k]) * PCG32_MULT + in; /* 0 * MULT + inc, then + initstate */
        inc[j] = in;
      }
    }
  }
}

/* core/rng.h pcg32_next_double `draws` times per stream, VW streams a
 * step (VI, VD: the lanes as int64 and double): out[d * n + j] is stream
 * j's d-th number, and state[j] is left past them. The step's 64-bit
 * product and the output permutation wrap and shift as the scalar code
 * does (the 32-bit rotation in 64-bit lanes, masked), and a 32-bit value
 * converts to double exactly, times 2^-32 exactly: every lane is bitwise
 * the scalar stream. */
PCG_ATTR void PCG_DRAW_FN(int n, uint64_t *state, const uint64_t *inc, int draws, double *out) {
  for (int k0 = 0; k0 < n; k0 += VW) {
    int cnt = n - k0 < VW ? n - k0 : VW;
    VU s = {0}, in = {0};
    if (cnt == VW) {
      __builtin_memcpy(&s, &state[k0], sizeof s);
      __builtin_memcpy(&in, &inc[k0], sizeof in);
    } else { /* a tail: its last lane repeated */
      for (int k = 0; k < VW; k++) {
        int q = k0 + (k < cnt ? k : cnt - 1);
        s[k] = state[q], in[k] = inc[q];
      }
    }
    for (int d = 0; d < draws; d++) {
      VU old = s;
      s = old * PCG32_MULT + in;
      VU xs = (((old >> 18) ^ old) >> 27) & 0xffffffffu, rot = old >> 59;
      VU r = ((xs >> rot) | (xs << ((32 - rot) & 31))) & 0xffffffffu;
      VD x = __builtin_convertvector((VI)r, VD) * (1.0 / 4294967296.0);
      if (cnt == VW)
        __builtin_memcpy(&out[(size_t)d * n + k0], &x, sizeof x);
      else
        for (int k = 0; k < cnt; k++) out[(size_t)d * n + k0 + k] = x[k];
    }
    if (cnt == VW)
      __builtin_memcpy(&state[k0], &s, sizeof s);
    else
      for (int k = 0; k < cnt; k++) state[k0 + k] = s[k];
  }
}
