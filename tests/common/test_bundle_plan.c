/* Spectral bundles' one rule (common/bundle_plan.c), which the daemon's job
 * planning and the client's shards share: runs of equal keys in order, at
 * most k long, a repeated wavelength starting the next run, lone units;
 * the shard keys that deal the runs out in turn (rsw_bundle_shard_keys);
 * and the client's context key (rsw_bundle_context_text). */
#include <cjson/cJSON.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../support/test.h"
#include "bundle_plan.h"

RSW_TEST_DEFINE_GLOBALS

static void check_leads(const char *what, size_t n, const uint64_t *key, const double *wl, int k,
                        const size_t *want) {
  size_t lead[32];
  REQUIRE(n <= 32, "n");
  REQUIRE(rsw_bundle_runs(n, key, wl, k, lead) == 0, "%s: out of memory", what);
  for (size_t i = 0; i < n; i++)
    CHECK(lead[i] == want[i], "%s: lead[%zu] = %zu, want %zu", what, i, lead[i], want[i]);
}

static void test_runs(void) {
  /* Two keys interleaved (a grid with the wavelength slowest): each key's
   * units in order, cut into threes. */
  uint64_t key[] = {0, 1, 0, 1, 0, 1, 0, 1};
  double wl[] = {400, 400, 410, 410, 420, 420, 430, 430};
  check_leads("interleaved, k 3", 8, key, wl, 3, (size_t[]){0, 1, 0, 1, 0, 1, 6, 7});
  check_leads("interleaved, k 2", 8, key, wl, 2, (size_t[]){0, 1, 0, 1, 4, 5, 4, 5});
  check_leads("k 1: each alone", 8, key, wl, 1, (size_t[]){0, 1, 2, 3, 4, 5, 6, 7});
  /* A wavelength already in the run starts the next one. */
  uint64_t k0[] = {0, 0, 0, 0, 0};
  double dup[] = {400, 410, 400, 420, 430};
  check_leads("a repeated wavelength", 5, k0, dup, 3, (size_t[]){0, 0, 2, 2, 2});
  /* A lone unit (a seed of its own) breaks nothing and joins nothing. */
  uint64_t lone[] = {0, RSW_BUNDLE_ALONE, 0, RSW_BUNDLE_ALONE, 0};
  double w5[] = {400, 410, 420, 430, 440};
  check_leads("lone units", 5, lone, w5, 3, (size_t[]){0, 1, 0, 3, 0});
  /* k above RSW_BUNDLE_MAX_RUN is clamped, n < 2 and n = 0 are fine. */
  size_t one = 7;
  CHECK(rsw_bundle_runs(1, k0, w5, 3, &one) == 0 && one == 0, "one unit: lead %zu", one);
  CHECK(rsw_bundle_runs(0, NULL, NULL, 3, NULL) == 0, "no units");
}

/* Shards deal the runs out in turn: a 40-wavelength sweep in runs of 16
 * (leads 0, 16, 32) over 4 shards puts one run on each of shards 0, 1, 2
 * (by lead mod 4 all three fell on shard 0); runs of interleaved groups
 * are ranked by their first units; without runs, unit i is its own. */
static void test_shard_keys(void) {
  enum {
    N = 40
  };
  uint64_t key[N];
  double wl[N];
  size_t lead[N], sk[N];
  for (size_t i = 0; i < N; i++) key[i] = 0, wl[i] = 400.0 + (double)i;
  REQUIRE(rsw_bundle_runs(N, key, wl, 16, lead) == 0, "runs");
  rsw_bundle_shard_keys(N, lead, sk);
  size_t per[4] = {0};
  for (size_t i = 0; i < N; i++) per[sk[i] % 4]++;
  CHECK(sk[0] == 0 && sk[15] == 0 && sk[16] == 1 && sk[31] == 1 && sk[32] == 2 && sk[39] == 2,
        "runs ranked 0, 1, 2: %zu %zu %zu", sk[0], sk[16], sk[32]);
  CHECK(per[0] == 16 && per[1] == 16 && per[2] == 8 && per[3] == 0, "shards of 4 hold %zu %zu %zu %zu",
        per[0], per[1], per[2], per[3]);
  /* Two interleaved groups (keys 0 1 0 1 ...) in runs of 3: leads 0 1 0 1 0 1 6 7 6 7 ... */
  for (size_t i = 0; i < N; i++) key[i] = i % 2, wl[i] = 400.0 + (double)(i / 2);
  REQUIRE(rsw_bundle_runs(N, key, wl, 3, lead) == 0, "interleaved runs");
  rsw_bundle_shard_keys(N, lead, sk);
  CHECK(lead[7] == 7 && sk[6] == 2 && sk[7] == 3 && sk[9] == 3 && sk[8] == 2,
        "interleaved runs ranked by their first units: lead[7] %zu, keys %zu %zu", lead[7], sk[6], sk[7]);
  for (size_t i = 0; i < N; i++) lead[i] = i;
  rsw_bundle_shard_keys(N, lead, sk);
  bool own = true;
  for (size_t i = 0; i < N; i++) own = own && sk[i] == i;
  CHECK(own, "without runs every unit is its own key");
}

static void test_context_text(void) {
  const char *base =
      "{\"id\":\"a\",\"wavelength\":400,\"coords\":{\"r\":1},\"params\":{\"k\":0.2},\"spp\":8}";
  const char *same = "{\"id\":\"b\",\"wavelength\":410,\"coords\":{\"r\":2},\"params\":{\"k\":0.2},\"spp\":8,"
                     "\"bundle_group\":4}";
  const char *other = "{\"id\":\"c\",\"wavelength\":400,\"params\":{\"k\":0.3},\"spp\":8}";
  const char *seeded = "{\"id\":\"d\",\"wavelength\":400,\"seed\":1}";
  const char *no_wl = "{\"id\":\"e\",\"params\":{\"k\":0.2}}";
  cJSON *c[5] = {cJSON_Parse(base), cJSON_Parse(same), cJSON_Parse(other), cJSON_Parse(seeded),
                 cJSON_Parse(no_wl)};
  char *t[5];
  for (int i = 0; i < 5; i++) t[i] = rsw_bundle_context_text(c[i]);
  REQUIRE(t[0] && t[1] && t[2], "texts");
  CHECK(strcmp(t[0], t[1]) == 0, "id, wavelength, coords and bundle_group differ only: '%s' vs '%s'", t[0],
        t[1]);
  CHECK(strcmp(t[0], t[2]) != 0, "other params, same text '%s'", t[2]);
  CHECK(!t[3], "a seed of its own shares no bundle");
  CHECK(!t[4], "no wavelength shares no bundle");
  CHECK(!rsw_bundle_context_text(NULL), "NULL");
  for (int i = 0; i < 5; i++) {
    free(t[i]);
    cJSON_Delete(c[i]);
  }
}

int main(void) {
  RSW_TEST_RUN(test_runs);
  RSW_TEST_RUN(test_shard_keys);
  RSW_TEST_RUN(test_context_text);
  RSW_TEST_END("test_bundle_plan");
}
