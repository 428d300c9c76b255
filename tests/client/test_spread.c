/* rsw_spread_run's passes while a job runs (client/lib/spread.c,
 * client_early_batch): a job's renders reported one by one, a pass each
 * time the renders since the last one reach the batch (passes taken as
 * instant). A pass is one GET results of the whole job and one fetch, so
 * passes are few (at most an eighth of the job's renders apart, plus a
 * few as the end nears), and the last one leaves few films to the pass
 * after the job ends (the sweep's fixed cost at its end). */
#include <stddef.h>

#include "../../client/lib/internal.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

/* The passes of a job of total renders with passes max_batch apart at
 * most; *left: the renders reported after the last pass; *min_gap: the
 * fewest renders between two passes. */
static size_t simulate(size_t total, size_t max_batch, size_t *left, size_t *min_gap) {
  size_t passes = 0, pending = 0;
  *min_gap = total;
  for (size_t seen = 1; seen <= total; seen++) {
    pending++;
    if (pending >= client_early_batch(max_batch, total, seen, pending)) {
      if (pending < *min_gap) *min_gap = pending;
      passes++;
      pending = 0;
    }
  }
  *left = pending;
  return passes;
}

static void test_passes_few_and_last_close_to_the_end(void) {
  /* (The former schedule, a pass every sixteenth: 16 passes and 8 renders
   * left for 200, 16 and 4 for 100.) */
  const size_t totals[] = {8, 16, 48, 100, 200, 1000, 10000};
  for (size_t i = 0; i < sizeof totals / sizeof totals[0]; i++) {
    size_t n = totals[i], left, min_gap;
    size_t passes = simulate(n, n / 8, &left, &min_gap);
    /* An eighth apart (8), then halving what is left down to the floor:
     * about log2 of an eighth more. */
    size_t most = 8 + 1;
    for (size_t k = n / 8; k > CLIENT_EARLY_MIN_BATCH; k /= 2) most++;
    CHECK(passes >= 1 && passes <= most, "%zu renders: %zu passes (want 1 to %zu)", n, passes, most);
    CHECK(left < CLIENT_EARLY_MIN_BATCH, "%zu renders: %zu left after the last pass (want < %d)", n, left,
          CLIENT_EARLY_MIN_BATCH);
    CHECK(min_gap >= CLIENT_EARLY_MIN_BATCH || n < CLIENT_EARLY_MIN_BATCH,
          "%zu renders: a pass only %zu renders after the one before", n, min_gap);
  }
}

static void test_batch_bounds(void) {
  /* Many left: max_batch; the total not known yet: max_batch too. */
  CHECK(client_early_batch(25, 200, 10, 10) == 25, "200 renders, 10 seen: %zu",
        client_early_batch(25, 200, 10, 10));
  CHECK(client_early_batch(25, 0, 10, 10) == 25, "total unknown: %zu", client_early_batch(25, 0, 10, 10));
  /* 25 left when the last pass started (at 175): the next after 12. */
  CHECK(client_early_batch(25, 200, 180, 5) == 12, "25 left: %zu", client_early_batch(25, 200, 180, 5));
  /* Never under the floor, and a small job's max_batch of 0 is the floor. */
  CHECK(client_early_batch(25, 200, 199, 2) == CLIENT_EARLY_MIN_BATCH, "3 left: %zu",
        client_early_batch(25, 200, 199, 2));
  CHECK(client_early_batch(0, 8, 1, 1) == CLIENT_EARLY_MIN_BATCH, "8 renders: %zu",
        client_early_batch(0, 8, 1, 1));
}

int main(void) {
  RSW_TEST_RUN(test_passes_few_and_last_close_to_the_end);
  RSW_TEST_RUN(test_batch_bounds);
  RSW_TEST_END("test_spread");
}
