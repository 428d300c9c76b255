/* `stratified` sampler (mitsuba3 src/samplers/stratified.cpp).
 *
 * sample_count is rounded up to a square n^2 (Mitsuba: the smallest
 * n with n^2 >= spp, so 10 -> 16). For each dimension d, sample s of a
 * pixel takes stratum
 *   p = permute(s, n^2, hash(seed, pixel, d))
 * a bijection of [0, n^2), so the n^2 samples of a pixel fill every
 * stratum exactly once, in a different order per dimension:
 *   next_1d: (p + j) / n^2                       (n^2 strata of [0,1))
 *   next_2d: ((p mod n) + jx, (p div n) + jy) / n (n x n cells)
 * j ~ U[0,1) from the sample's PCG32 stream when jitter is on (default),
 * 0.5 (stratum centre) otherwise. Parameters: sample_count (4), seed (0),
 * jitter (true). */
#include <math.h>
#include <stdlib.h>

#include "../core/isa.h"
#include "../scene/plugin_def.h"
#include "permute_lanes.h"
#include "sampler_common.h"

/* Kensler's permutation of [0, l) (samplers/permute_lanes.h). */
static uint32_t permute(uint32_t i, uint32_t l, uint32_t p) {
  uint32_t w = permute_mask(l);
  do {
    PERMUTE_HASH(i, p, w);
  } while (i >= l);
  return (i + p) % l;
}

/* Smallest n with n^2 >= spp. Called for every draw: counting up is
 * cheapest for the usual few dozen samples; from 1024 on, the double
 * square root (exact for the perfect squares adjust_spp hands the render,
 * within one otherwise, which the loops correct) is. */
static uint32_t ceil_sqrt(uint32_t spp) {
  uint32_t n = 1;
  if (spp > 1024) {
    n = (uint32_t)sqrt((double)spp);
    while ((uint64_t)(n - 1) * (n - 1) >= spp) n--;
  }
  while ((uint64_t)n * n < spp) n++;
  return n;
}

static uint32_t stratified_adjust_spp(const sampler *s, uint32_t spp) {
  if (spp == 0) spp = s->sample_count;
  uint32_t n = ceil_sqrt(spp);
  return n * n;
}

/* Permutation seed of dimension d: a 32-bit hash of (seed, pixel, d). */
static uint32_t dim_seed(const sampler_state *st) {
  return (uint32_t)(mix64(st->pixel_key ^ (0x9e3779b97f4a7c15ULL * ((uint64_t)st->dim + 1))) >> 32);
}

/* Stratum of the current sample in the current dimension, in [0, n^2). */
static uint32_t stratum(const sampler_state *st, uint32_t n2) {
  return permute(st->sample_index % n2, n2, dim_seed(st));
}

static double jitter(sampler_state *st) {
  return st->s->jitter ? pcg32_next_double(&st->rng) : 0.5;
}

static void stratified_start(const sampler *s, sampler_state *st, uint64_t seed, uint64_t pixel,
                             uint32_t sample_index, uint32_t spp) {
  sampler_seed_stream(s, st, seed, pixel, sample_index, spp);
}

static double stratified_next_1d(sampler_state *st) {
  uint32_t n = ceil_sqrt(st->spp ? st->spp : 1), n2 = n * n;
  uint32_t p = stratum(st, n2);
  double j = jitter(st);
  st->dim++;
  return ((double)p + j) / (double)n2;
}

static vec2 stratified_next_2d(sampler_state *st) {
  uint32_t n = ceil_sqrt(st->spp ? st->spp : 1), n2 = n * n;
  uint32_t p = stratum(st, n2);
  uint32_t y = p / n, x = p - y * n;
  double jx = jitter(st);
  double jy = jitter(st);
  st->dim++;
  return v2(((double)x + jx) / (double)n, ((double)y + jy) / (double)n);
}

static void stratified_start_batch(const sampler *s, sampler_state *st, int n, uint64_t seed,
                                   const uint64_t *pixel, const uint32_t *sample_index, uint32_t spp) {
  sampler_seed_streams(s, st, n, seed, pixel, sample_index, spp, NULL, NULL);
}

/* The batches: each lane's stratum by the vectorised permutation
 * (stratified_permute_batch, bitwise permute()), C lanes at a time, then
 * its jitter and dimension as next_1d()/next_2d() do; ceil_sqrt(spp) once
 * per chunk (a render's lanes share its spp; a chunk whose lanes do not
 * takes the per-lane path). */
enum {
  STRAT_C = 64
};

/* out[k] = permute(in[k], l, seed[k]) for k < n, l >= 1: the lanes of
 * samplers/permute_lanes.h, 32-bit integer lanes (16 avx512, 8 avx2, 4
 * sse2 and generic) picked at the render's ISA (core/isa.h); bitwise the
 * scalar permutation at every ISA. */
#if defined(__x86_64__) || defined(__i386__)
typedef uint32_t vp_16 __attribute__((vector_size(64)));
typedef uint32_t vp_8 __attribute__((vector_size(32)));

#define VW        16
#define VU32      vp_16
#define PERM_FN   permute_avx512
#define PERM_ATTR static __attribute__((target("avx512f,avx512vl,avx512dq")))
#include "permute_lanes.h"
#undef VW
#undef VU32
#undef PERM_FN
#undef PERM_ATTR

#define VW        8
#define VU32      vp_8
#define PERM_FN   permute_avx2
#define PERM_ATTR static __attribute__((target("avx2,fma")))
#include "permute_lanes.h"
#undef VW
#undef VU32
#undef PERM_FN
#undef PERM_ATTR

#define VW 4
#else
#define VW 1
#endif
typedef uint32_t vp_p __attribute__((vector_size(4 * VW)));
#define VU32      vp_p
#define PERM_FN   permute_plain
#define PERM_ATTR static
#include "permute_lanes.h"

static void stratified_permute_batch(int n, const uint32_t *in, uint32_t l, const uint32_t *seed,
                                     uint32_t *out) {
#if defined(__x86_64__) || defined(__i386__)
  switch (rsw_isa_get()) {
  case RSW_ISA_AVX512: permute_avx512(n, in, l, seed, out); return;
  case RSW_ISA_AVX2: permute_avx2(n, in, l, seed, out); return;
  default: break;
  }
#endif
  permute_plain(n, in, l, seed, out);
}

/* Strata of lanes q[0..m) in their current dimension (p0) and, when p1
 * is not NULL, the next (p1); false when their spp differ (nothing
 * written). One pass over the lanes' states: the spp compared as the
 * indices and seeds are gathered (with the first lane's n^2, discarded
 * when one differs). */
static bool strata_batch(sampler_state *const *q, int m, uint32_t *sq, uint32_t *p0, uint32_t *p1) {
  uint32_t spp = q[0]->spp, in[STRAT_C], seed0[STRAT_C], seed1[STRAT_C];
  uint32_t n = ceil_sqrt(spp ? spp : 1), n2 = n * n;
  /* A wave holds runs of samples of one pixel at one dimension: their
   * seeds are hashed once per run; an index below n^2 (every sample of a
   * render) needs no division. */
  uint64_t key = 0;
  uint32_t dim = 0, h0 = 0, h1 = 0;
  bool same = true;
  for (int k = 0; k < m; k++) {
    uint32_t si = q[k]->sample_index;
    same &= q[k]->spp == spp;
    in[k] = si < n2 ? si : si % n2;
    if (k == 0 || q[k]->pixel_key != key || q[k]->dim != dim) {
      key = q[k]->pixel_key, dim = q[k]->dim;
      h0 = dim_seed(q[k]);
      if (p1) h1 = (uint32_t)(mix64(key ^ (0x9e3779b97f4a7c15ULL * ((uint64_t)dim + 2))) >> 32);
    }
    seed0[k] = h0, seed1[k] = h1;
  }
  if (!same) return false;
  stratified_permute_batch(m, in, n2, seed0, p0);
  if (p1) stratified_permute_batch(m, in, n2, seed1, p1);
  *sq = n;
  return true;
}

/* Stratum p of n^2 (n = sq) with jitter j as next_1d(). Apart from the
 * streams: the divisions in vector lanes (IEEE division, the scalar's
 * bits); by a power of two (spp 4^k) a product with its reciprocal, which
 * is exact: the same bits. */
static void strata_line(int m, uint32_t sq, const uint32_t *p, const double *j, double *out) {
  double n2 = (double)(sq * sq);
  if ((sq & (sq - 1)) == 0) {
    const double inv = 1.0 / n2;
    for (int k = 0; k < m; k++) out[k] = ((double)p[k] + j[k]) * inv;
    return;
  }
  for (int k = 0; k < m; k++) out[k] = ((double)p[k] + j[k]) / n2;
}

/* Stratum p of a side-sq grid as a 2-D number with jitters (jx, jy), as
 * next_2d(): the cell by a shift and mask and the division by the side a
 * product with its reciprocal (exact) for a power-of-two side. */
static void strata_cells(int m, uint32_t sq, const uint32_t *p, const double *jx, const double *jy,
                         vec2 *out) {
  double side = (double)sq;
  if ((sq & (sq - 1)) == 0) {
    int sh = __builtin_ctz(sq);
    const double inv = 1.0 / side;
    for (int k = 0; k < m; k++)
      out[k] = v2(((double)(p[k] & (sq - 1)) + jx[k]) * inv, ((double)(p[k] >> sh) + jy[k]) * inv);
    return;
  }
  for (int k = 0; k < m; k++) {
    uint32_t y = p[k] / sq;
    out[k] = v2(((double)(p[k] - y * sq) + jx[k]) / side, ((double)y + jy[k]) / side);
  }
}

static void stratified_next_1d_batch(sampler_state *st, const int *idx, int n, double *out) {
  for (int k0 = 0; k0 < n; k0 += STRAT_C) {
    int m = n - k0 < STRAT_C ? n - k0 : STRAT_C;
    sampler_state *q[STRAT_C];
    uint32_t p[STRAT_C], sq;
    for (int k = 0; k < m; k++) q[k] = &st[idx ? idx[k0 + k] : k0 + k];
    if (!strata_batch(q, m, &sq, p, NULL)) {
      for (int k = 0; k < m; k++) out[k0 + k] = stratified_next_1d(q[k]);
      continue;
    }
    double j[STRAT_C];
    for (int k = 0; k < m; k++) {
      j[k] = jitter(q[k]);
      q[k]->dim++;
    }
    strata_line(m, sq, p, j, out + k0);
  }
}

static void stratified_next_2d_batch(sampler_state *st, const int *idx, int n, vec2 *out) {
  for (int k0 = 0; k0 < n; k0 += STRAT_C) {
    int m = n - k0 < STRAT_C ? n - k0 : STRAT_C;
    sampler_state *q[STRAT_C];
    uint32_t p[STRAT_C], sq;
    for (int k = 0; k < m; k++) q[k] = &st[idx ? idx[k0 + k] : k0 + k];
    if (!strata_batch(q, m, &sq, p, NULL)) {
      for (int k = 0; k < m; k++) out[k0 + k] = stratified_next_2d(q[k]);
      continue;
    }
    double jx[STRAT_C], jy[STRAT_C];
    for (int k = 0; k < m; k++) {
      jx[k] = jitter(q[k]);
      jy[k] = jitter(q[k]);
      q[k]->dim++;
    }
    strata_cells(m, sq, p, jx, jy, out + k0);
  }
}

/* Two draws per lane in one pass over the lanes' states: a 1-D number
 * into first1 (non-NULL) or a 2-D one into first2, then a 2-D number into
 * second; each lane's jitters in its per-lane order. */
static void stratified_pair_batch(sampler_state *st, const int *idx, int n, double *first1, vec2 *first2,
                                  vec2 *second) {
  for (int k0 = 0; k0 < n; k0 += STRAT_C) {
    int m = n - k0 < STRAT_C ? n - k0 : STRAT_C;
    sampler_state *q[STRAT_C];
    uint32_t p0[STRAT_C], p1[STRAT_C], sq;
    for (int k = 0; k < m; k++) q[k] = &st[idx ? idx[k0 + k] : k0 + k];
    if (!strata_batch(q, m, &sq, p0, p1)) {
      for (int k = 0; k < m; k++) {
        if (first1)
          first1[k0 + k] = stratified_next_1d(q[k]);
        else
          first2[k0 + k] = stratified_next_2d(q[k]);
        second[k0 + k] = stratified_next_2d(q[k]);
      }
      continue;
    }
    double ax[STRAT_C], ay[STRAT_C], bx[STRAT_C], by[STRAT_C];
    for (int k = 0; k < m; k++) {
      ax[k] = jitter(q[k]);
      if (!first1) ay[k] = jitter(q[k]);
      bx[k] = jitter(q[k]);
      by[k] = jitter(q[k]);
      q[k]->dim += 2;
    }
    if (first1)
      strata_line(m, sq, p0, ax, first1 + k0);
    else
      strata_cells(m, sq, p0, ax, ay, first2 + k0);
    strata_cells(m, sq, p1, bx, by, second + k0);
  }
}

static void stratified_next_1d_2d_batch(sampler_state *st, const int *idx, int n, double *out1, vec2 *out2) {
  stratified_pair_batch(st, idx, n, out1, NULL, out2);
}

static void stratified_next_2d_2d_batch(sampler_state *st, const int *idx, int n, vec2 *out1, vec2 *out2) {
  stratified_pair_batch(st, idx, n, NULL, out1, out2);
}

static const sampler_ops stratified_ops = {
    .start = stratified_start,
    .next_1d = stratified_next_1d,
    .next_2d = stratified_next_2d,
    .adjust_spp = stratified_adjust_spp,
    .start_batch = stratified_start_batch,
    .next_1d_batch = stratified_next_1d_batch,
    .next_2d_batch = stratified_next_2d_batch,
    .next_1d_2d_batch = stratified_next_1d_2d_batch,
    .next_2d_2d_batch = stratified_next_2d_2d_batch,
};

DEFINE_PLUGIN(stratified, CLS_SAMPLER, .ops = &stratified_ops);

static rsw_status stratified_create(loader *ld, node *n, object **out) {
  long long count = 0, seed = 0;
  bool jit = true;
  rsw_status st = ld_int(ld, n, "sample_count", 4, 1, SAMPLER_MAX_SPP, &count);
  if (st == RSW_OK) st = ld_int(ld, n, "seed", 0, 0, UINT32_MAX, &seed);
  if (st == RSW_OK) st = ld_bool(ld, n, "jitter", true, &jit);
  if (st != RSW_OK) return st;
  sampler *s = PLUGIN_NEW(sampler, stratified);
  if (!s) return plugin_created(ld, n, NULL, out);
  s->ops = &stratified_ops;
  s->seed = (uint64_t)seed;
  s->jitter = jit;
  s->sample_count = stratified_adjust_spp(s, (uint32_t)count);
  return plugin_created(ld, n, &s->base, out);
}
