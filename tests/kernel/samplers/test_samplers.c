/* `independent` and `stratified` samplers (mitsuba3
 * src/samplers/independent.cpp, src/samplers/stratified.cpp), built through
 * their plugins' create(). */
#include "../../support/test.h"
RSW_TEST_DEFINE_GLOBALS

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "kernel/core/isa.h"
#include "kernel/core/rng.h"
#include "kernel/samplers/pcg_simd.h"
#include "kernel/scene/loader.h"
#include "kernel/shapes/shape.h"

typedef struct harness {
  scene sc;
  rsw_err err;
  loader ld;
  node *doc;
  sampler *s;
} harness;

/* Build `type` with optional sample_count (0: absent), seed (< 0: absent)
 * and jitter (-1: absent). */
static rsw_status build(harness *h, const char *type, int spp, long seed, int jitter) {
  memset(h, 0, sizeof *h);
  h->doc = node_new(NULL, type, type);
  if (spp) {
    prop *p = node_add_prop(h->doc, "sample_count", PROP_NUMBER, "sample_count");
    p->num = spp;
    p->is_int = true;
  }
  if (seed >= 0) {
    prop *p = node_add_prop(h->doc, "seed", PROP_NUMBER, "seed");
    p->num = (double)seed;
    p->is_int = true;
  }
  if (jitter >= 0) node_add_prop(h->doc, "jitter", PROP_BOOL, "jitter")->b = jitter != 0;
  h->ld.variant = VARIANT_MONO;
  h->ld.err = &h->err;
  h->ld.root = h->doc;
  h->ld.scene = &h->sc;
  h->ld.hooks = &scene_build_hooks;
  object *o = NULL;
  rsw_status st = registry_find(type)->create(&h->ld, h->doc, &o);
  if (st == RSW_OK) h->s = (sampler *)o;
  return st;
}

static void h_free(harness *h) {
  if (h->s) h->s->base.plugin->destroy(&h->s->base);
  free(h->sc.objects);
  node_free(h->doc);
}

/* Draw n values (alternating 1-D and 2-D) of one sample. */
static void draw(const sampler *s, uint64_t seed, uint64_t pixel, uint32_t idx, uint32_t spp, double *out,
                 int n) {
  sampler_state st;
  s->ops->start(s, &st, seed, pixel, idx, spp);
  for (int i = 0; i < n;) {
    if (i % 3 == 0) {
      out[i++] = s->ops->next_1d(&st);
    } else {
      vec2 v = s->ops->next_2d(&st);
      out[i++] = v.x;
      if (i < n) out[i++] = v.y;
    }
  }
}

static bool same(const double *a, const double *b, int n) {
  return memcmp(a, b, (size_t)n * sizeof *a) == 0;
}

static void check_determinism(const sampler *s, uint32_t spp) {
  enum {
    N = 12
  };
  double a[N], b[N];
  draw(s, 7, 1234, 3, spp, a, N);
  draw(s, 7, 1234, 3, spp, b, N);
  CHECK(same(a, b, N), "same inputs gave different numbers");
  for (int i = 0; i < N; i++) CHECK(a[i] >= 0.0 && a[i] < 1.0, "value %g outside [0,1)", a[i]);
  draw(s, 7, 1234, 4, spp, b, N);
  CHECK(!same(a, b, N), "another sample index gave the same numbers");
  draw(s, 7, 1235, 3, spp, b, N);
  CHECK(!same(a, b, N), "another pixel gave the same numbers");
  draw(s, 8, 1234, 3, spp, b, N);
  CHECK(!same(a, b, N), "another seed gave the same numbers");
  /* Interleaving other samples' streams changes nothing (no hidden state). */
  sampler_state st1, st2;
  s->ops->start(s, &st1, 7, 1234, 3, spp);
  s->ops->start(s, &st2, 7, 99, 0, spp);
  s->ops->next_2d(&st2);
  CHECK(s->ops->next_1d(&st1) == a[0], "stream depends on another sample's state");
}

static void test_independent_determinism(void) {
  harness h;
  REQUIRE(build(&h, "independent", 0, -1, -1) == RSW_OK, "%s", h.err.msg);
  CHECK(h.s->sample_count == 4 && h.s->seed == 0, "defaults %u %llu", h.s->sample_count,
        (unsigned long long)h.s->seed);
  check_determinism(h.s, 4);

  /* The sampler's seed is added to the render's seed. */
  harness h2;
  REQUIRE(build(&h2, "independent", 16, 5, -1) == RSW_OK, "%s", h2.err.msg);
  CHECK(h2.s->sample_count == 16, "sample_count");
  double a[6], b[6];
  draw(h2.s, 2, 10, 1, 16, a, 6);
  draw(h.s, 7, 10, 1, 16, b, 6);
  CHECK(same(a, b, 6), "seed + sampler seed is not what matters");
  CHECK(h.s->ops->adjust_spp(h.s, 10) == 10 && h.s->ops->adjust_spp(h.s, 0) == 4, "adjust_spp");
  h_free(&h);
  h_free(&h2);
}

/* Mean and variance of the first three dimensions over many pixels and
 * sample indices: U[0,1) has mean 1/2 and variance 1/12; each mean must lie
 * within 3 standard errors sqrt(1/12/N) (fixed seed, deterministic). */
static void check_uniform(const sampler *s, uint32_t spp) {
  enum {
    PIXELS = 4096
  };
  double sum[3] = {0}, sum2[3] = {0};
  long n = 0;
  for (uint64_t px = 0; px < PIXELS; px++)
    for (uint32_t i = 0; i < spp; i++) {
      sampler_state st;
      s->ops->start(s, &st, 42, px, i, spp);
      double x = s->ops->next_1d(&st);
      vec2 y = s->ops->next_2d(&st);
      double v[3] = {x, y.x, y.y};
      for (int k = 0; k < 3; k++) {
        sum[k] += v[k];
        sum2[k] += v[k] * v[k];
      }
      n++;
    }
  double se = sqrt(1.0 / 12.0 / (double)n);
  for (int k = 0; k < 3; k++) {
    double mean = sum[k] / (double)n, var = sum2[k] / (double)n - mean * mean;
    CHECK(fabs(mean - 0.5) < 3 * se, "dim %d: mean %.6f outside 0.5 +- %.6f", k, mean, 3 * se);
    CHECK(fabs(var - 1.0 / 12.0) < 0.01, "dim %d: variance %.6f", k, var);
  }
}

static void test_independent_uniform(void) {
  harness h;
  REQUIRE(build(&h, "independent", 0, -1, -1) == RSW_OK, "%s", h.err.msg);
  check_uniform(h.s, 8);
  /* 2-D uniformity: 8x8 histogram of next_2d, chi-square against uniform
   * with 63 d.o.f.; 110 is above the 0.9999 quantile (~104.2). */
  enum {
    N = 64000
  };
  int cell[64] = {0};
  for (uint32_t i = 0; i < N; i++) {
    sampler_state st;
    h.s->ops->start(h.s, &st, 1, i / 16, i % 16, 16);
    vec2 v = h.s->ops->next_2d(&st);
    cell[(int)(v.x * 8) + 8 * (int)(v.y * 8)]++;
  }
  double chi2 = 0, e = N / 64.0;
  for (int c = 0; c < 64; c++) chi2 += (cell[c] - e) * (cell[c] - e) / e;
  CHECK(chi2 < 110.0, "chi2 = %g", chi2);
  h_free(&h);
}

static void test_stratified_adjust_spp(void) {
  harness h;
  /* Mitsuba rounds up to the next square (stratified.cpp:
   * while (res^2 < spp) res++). */
  REQUIRE(build(&h, "stratified", 10, -1, -1) == RSW_OK, "%s", h.err.msg);
  CHECK(h.s->sample_count == 16, "sample_count 10 -> %u", h.s->sample_count);
  const sampler_ops *o = h.s->ops;
  CHECK(o->adjust_spp(h.s, 10) == 16, "adjust_spp(10) = %u", o->adjust_spp(h.s, 10));
  CHECK(o->adjust_spp(h.s, 9) == 9, "adjust_spp(9)");
  CHECK(o->adjust_spp(h.s, 16) == 16, "adjust_spp(16)");
  CHECK(o->adjust_spp(h.s, 1) == 1, "adjust_spp(1)");
  CHECK(o->adjust_spp(h.s, 17) == 25, "adjust_spp(17)");
  CHECK(o->adjust_spp(h.s, 0) == 16, "adjust_spp(0) = sample_count");
  CHECK(h.s->jitter, "jitter default");
  h_free(&h);
}

static void test_stratified_strata(void) {
  harness h;
  REQUIRE(build(&h, "stratified", 16, -1, -1) == RSW_OK, "%s", h.err.msg);
  const sampler *s = h.s;
  int differing = 0;
  for (uint64_t px = 0; px < 50; px++) {
    int hit2[4][16] = {{0}}, hit1[16] = {0};
    int order[2][16];
    for (uint32_t i = 0; i < 16; i++) {
      sampler_state st;
      s->ops->start(s, &st, 3, px, i, 16);
      for (int d = 0; d < 4; d++) {
        vec2 v = s->ops->next_2d(&st);
        int cx = (int)(v.x * 4), cy = (int)(v.y * 4);
        REQUIRE(cx >= 0 && cx < 4 && cy >= 0 && cy < 4, "value outside [0,1)^2");
        hit2[d][cx + 4 * cy]++;
        if (d < 2) order[d][i] = cx + 4 * cy;
      }
      double x = s->ops->next_1d(&st);
      hit1[(int)(x * 16)]++;
    }
    for (int d = 0; d < 4; d++)
      for (int c = 0; c < 16; c++)
        CHECK(hit2[d][c] == 1, "pixel %llu dim %d: cell %d has %d samples", (unsigned long long)px, d, c,
              hit2[d][c]);
    for (int c = 0; c < 16; c++)
      CHECK(hit1[c] == 1, "pixel %llu 1-D stratum %d has %d samples", (unsigned long long)px, c, hit1[c]);
    if (memcmp(order[0], order[1], sizeof order[0]) != 0) differing++;
  }
  /* Dimensions use independent permutations (else dimensions correlate). */
  CHECK(differing >= 45, "only %d of 50 pixels permute dimensions differently", differing);
  check_determinism(s, 16);
  check_uniform(s, 16);
  h_free(&h);
}

static void test_stratified_no_jitter(void) {
  harness h;
  REQUIRE(build(&h, "stratified", 4, -1, 0) == RSW_OK, "%s", h.err.msg);
  CHECK(!h.s->jitter, "jitter false");
  for (uint32_t i = 0; i < 4; i++) {
    sampler_state st;
    h.s->ops->start(h.s, &st, 0, 17, i, 4);
    vec2 v = h.s->ops->next_2d(&st);
    double x = h.s->ops->next_1d(&st);
    /* Stratum centres: (k + 0.5) / 2 in 2-D, (k + 0.5) / 4 in 1-D. */
    CHECK(fabs(v.x * 2 - 0.5 - floor(v.x * 2)) < 1e-15, "x %g not a centre", v.x);
    CHECK(fabs(v.y * 2 - 0.5 - floor(v.y * 2)) < 1e-15, "y %g not a centre", v.y);
    CHECK(fabs(x * 4 - 0.5 - floor(x * 4)) < 1e-15, "1-D %g not a centre", x);
  }
  h_free(&h);
}

static void test_sampler_bad_input(void) {
  harness h;
  CHECK(build(&h, "independent", -3, -1, -1) == RSW_ERR_RANGE, "negative sample_count");
  h_free(&h);
  CHECK(build(&h, "stratified", 0, -2, -1) == RSW_OK, "defaults");
  CHECK(h.s->sample_count == 4, "stratified default 4");
  h_free(&h);
}

/* sampler_pcg_seed_batch (samplers/pcg_simd.h) seeds every lane as
 * core/rng.h's pcg32_seed(tea64(fold32(key), index, 4), mix64(key +
 * index)) does, at every ISA and every count from 1 to 70 (whole steps of
 * the lanes and every kind of tail), keys changing every few lanes. */
static void test_pcg_seed_batch(void) {
  enum {
    N = 70
  };
  uint64_t key[N], state[N], inc[N];
  uint32_t index[N];
  for (int i = 0; i < N; i++) key[i] = mix64(1000 + (uint64_t)(i / 5)), index[i] = (uint32_t)(i * 37 % 101);
  int bad = 0, runs = 0;
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    for (int n = 1; n <= N; n++) {
      for (int i = 0; i < N; i++) state[i] = inc[i] = 0x5555;
      sampler_pcg_seed_batch(n, key, index, state, inc);
      for (int i = 0; i < N; i++) {
        pcg32 r = {0x5555, 0x5555};
        if (i < n) {
          uint32_t fold = (uint32_t)(key[i] ^ (key[i] >> 32));
          pcg32_seed(&r, tea64(fold, index[i], 4), mix64(key[i] + index[i]));
        }
        bad += r.state != state[i] || r.inc != inc[i]; /* lanes past n untouched */
      }
      runs++;
    }
  }
  rsw_isa_set(rsw_isa_best());
  CHECK(runs >= N, "ran at some ISA (%d runs)", runs);
  CHECK(bad == 0, "%d seeded lanes differ from pcg32_seed's (or lanes past n written)", bad);
}

/* sampler_pcg_draw_batch (samplers/pcg_simd.h) draws, for every stream,
 * the numbers of core/rng.h's pcg32_next_double in turn and leaves the
 * stream past them, at every ISA, for 1 to 4 draws and every count from 1
 * to 70 (whole vectors and every kind of tail); nothing past n written. */
static void test_pcg_draw_batch(void) {
  enum {
    N = 70,
    D = 4
  };
  uint64_t state0[N], inc[N], state[N];
  double out[D * N];
  for (int i = 0; i < N; i++) state0[i] = mix64(77 + (uint64_t)i), inc[i] = mix64(5000 + (uint64_t)i) | 1u;
  int bad = 0, runs = 0;
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    for (int draws = 1; draws <= D; draws++)
      for (int n = 1; n <= N; n++) {
        memcpy(state, state0, sizeof state);
        for (int i = 0; i < D * N; i++) out[i] = -1.0;
        sampler_pcg_draw_batch(n, state, inc, draws, out);
        for (int i = 0; i < N; i++) {
          pcg32 r = {state0[i], inc[i]};
          for (int d = 0; d < draws && i < n; d++) {
            double x = pcg32_next_double(&r);
            bad += memcmp(&x, &out[d * n + i], sizeof x) != 0;
          }
          bad += r.state != state[i]; /* streams past n untouched */
        }
        for (int i = draws * n; i < D * N; i++) bad += out[i] != -1.0;
        runs++;
      }
  }
  rsw_isa_set(rsw_isa_best());
  CHECK(runs >= D * N, "ran at some ISA (%d runs)", runs);
  CHECK(bad == 0, "%d draws or states differ from pcg32_next_double's (or written past n)", bad);
}

/* The independent sampler's start_2d_2d_batch gives every sample the
 * numbers and the state of start() then next_2d() twice, at every ISA,
 * for waves that span pixels and end in every kind of tail. */
static void test_start_2d_2d_batch(void) {
  enum {
    N = 75
  };
  harness h;
  CHECK(build(&h, "independent", 16, 3, -1) == RSW_OK, "built");
  const sampler_ops *ops = h.s->ops;
  CHECK(ops->start_2d_2d_batch != NULL, "independent has start_2d_2d_batch");
  uint64_t pixel[N];
  uint32_t index[N];
  for (int i = 0; i < N; i++) pixel[i] = 40 + (uint64_t)(i / 16), index[i] = (uint32_t)(i % 16);
  int bad = 0, runs = 0;
  for (int isa = 0; isa < RSW_ISA__COUNT && ops->start_2d_2d_batch; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    for (int n = 1; n <= N; n += 7) {
      sampler_state st[N], ref;
      vec2 a[N], b[N];
      ops->start_2d_2d_batch(h.s, st, n, 11, pixel, index, 16, a, b);
      for (int i = 0; i < n; i++) {
        ops->start(h.s, &ref, 11, pixel[i], index[i], 16);
        vec2 ra = ops->next_2d(&ref), rb = ops->next_2d(&ref);
        bad += ra.x != a[i].x || ra.y != a[i].y || rb.x != b[i].x || rb.y != b[i].y;
        bad += ref.rng.state != st[i].rng.state || ref.rng.inc != st[i].rng.inc || ref.dim != st[i].dim;
        bad += ops->next_1d(&ref) != ops->next_1d(&st[i]); /* the streams go on alike */
      }
      runs++;
    }
  }
  rsw_isa_set(rsw_isa_best());
  CHECK(runs > 0, "ran at some ISA");
  CHECK(bad == 0, "%d samples differ from start() then next_2d() twice", bad);
  h_free(&h);
}

int main(void) {
  RSW_TEST_RUN(test_independent_determinism);
  RSW_TEST_RUN(test_independent_uniform);
  RSW_TEST_RUN(test_stratified_adjust_spp);
  RSW_TEST_RUN(test_stratified_strata);
  RSW_TEST_RUN(test_stratified_no_jitter);
  RSW_TEST_RUN(test_sampler_bad_input);
  RSW_TEST_RUN(test_pcg_seed_batch);
  RSW_TEST_RUN(test_pcg_draw_batch);
  RSW_TEST_RUN(test_start_2d_2d_batch);
  RSW_TEST_END("test_samplers");
}
