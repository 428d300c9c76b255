/* `independent` sampler (mitsuba3 src/samplers/independent.cpp): every
 * dimension of every sample is an independent uniform draw from the
 * sample's own PCG32 stream (seeded by sampler_seed_stream()).
 * Parameters: sample_count (4), seed (0, added to the render's seed). */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "sampler_common.h"

static void independent_start(const sampler *s, sampler_state *st, uint64_t seed, uint64_t pixel,
                              uint32_t sample_index, uint32_t spp) {
  sampler_seed_stream(s, st, seed, pixel, sample_index, spp);
}

static double independent_next_1d(sampler_state *st) {
  st->dim++;
  return pcg32_next_double(&st->rng);
}

static vec2 independent_next_2d(sampler_state *st) {
  st->dim++;
  double x = pcg32_next_double(&st->rng);
  double y = pcg32_next_double(&st->rng);
  return v2(x, y);
}

static void independent_start_batch(const sampler *s, sampler_state *st, int n, uint64_t seed,
                                    const uint64_t *pixel, const uint32_t *sample_index, uint32_t spp) {
  sampler_seed_streams(s, st, n, seed, pixel, sample_index, spp, NULL, NULL);
}

/* start_batch then next_2d_2d_batch (idx NULL), the first four numbers
 * of each stream drawn as it is seeded, vectorised (sampler_seed_streams). */
static void independent_start_2d_2d_batch(const sampler *s, sampler_state *st, int n, uint64_t seed,
                                          const uint64_t *pixel, const uint32_t *sample_index, uint32_t spp,
                                          vec2 *out1, vec2 *out2) {
  sampler_seed_streams(s, st, n, seed, pixel, sample_index, spp, out1, out2);
}

/* The lanes' draws in one loop: each lane's PCG32 step is a serial chain,
 * but the lanes' chains are independent, so the loop overlaps them (the
 * per-lane calls could not, each behind an indirect call); bitwise each
 * lane's own next_1d()/next_2d(). */
static void independent_next_1d_batch(sampler_state *st, const int *idx, int n, double *out) {
  for (int k = 0; k < n; k++) out[k] = independent_next_1d(&st[idx ? idx[k] : k]);
}

static void independent_next_2d_batch(sampler_state *st, const int *idx, int n, vec2 *out) {
  for (int k = 0; k < n; k++) out[k] = independent_next_2d(&st[idx ? idx[k] : k]);
}

static void independent_next_1d_2d_batch(sampler_state *st, const int *idx, int n, double *out1, vec2 *out2) {
  if (idx)
    for (int k = 0; k < n; k++) {
      sampler_state *q = &st[idx[k]];
      out1[k] = independent_next_1d(q);
      out2[k] = independent_next_2d(q);
    }
  else
    for (int k = 0; k < n; k++) {
      out1[k] = independent_next_1d(&st[k]);
      out2[k] = independent_next_2d(&st[k]);
    }
}

static void independent_next_2d_2d_batch(sampler_state *st, const int *idx, int n, vec2 *out1, vec2 *out2) {
  if (idx)
    for (int k = 0; k < n; k++) {
      sampler_state *q = &st[idx[k]];
      out1[k] = independent_next_2d(q);
      out2[k] = independent_next_2d(q);
    }
  else
    for (int k = 0; k < n; k++) {
      out1[k] = independent_next_2d(&st[k]);
      out2[k] = independent_next_2d(&st[k]);
    }
}

/* Any count works; 0 means "the scene's sample_count". */
static uint32_t independent_adjust_spp(const sampler *s, uint32_t spp) {
  return spp ? spp : s->sample_count;
}

static const sampler_ops independent_ops = {
    .start = independent_start,
    .next_1d = independent_next_1d,
    .next_2d = independent_next_2d,
    .adjust_spp = independent_adjust_spp,
    .start_batch = independent_start_batch,
    .next_1d_batch = independent_next_1d_batch,
    .next_2d_batch = independent_next_2d_batch,
    .next_1d_2d_batch = independent_next_1d_2d_batch,
    .next_2d_2d_batch = independent_next_2d_2d_batch,
    .start_2d_2d_batch = independent_start_2d_2d_batch,
};

DEFINE_PLUGIN(independent, CLS_SAMPLER, .ops = &independent_ops);

static rsw_status independent_create(loader *ld, node *n, object **out) {
  long long count = 0, seed = 0;
  rsw_status st = ld_int(ld, n, "sample_count", 4, 1, SAMPLER_MAX_SPP, &count);
  if (st == RSW_OK) st = ld_int(ld, n, "seed", 0, 0, UINT32_MAX, &seed);
  if (st != RSW_OK) return st;
  sampler *s = PLUGIN_NEW(sampler, independent);
  if (!s) return plugin_created(ld, n, NULL, out);
  s->ops = &independent_ops;
  s->sample_count = (uint32_t)count;
  s->seed = (uint64_t)seed;
  s->jitter = true;
  return plugin_created(ld, n, &s->base, out);
}
