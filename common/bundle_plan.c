/* Spectral bundles' one rule: bundle_plan.h. */
#include "bundle_plan.h"

#include <cjson/cJSON.h>
#include <stdlib.h>
#include <string.h>

typedef struct unit {
  uint64_t key;
  size_t index;
} unit;

static int unit_cmp(const void *pa, const void *pb) {
  const unit *a = pa, *b = pb;
  if (a->key != b->key) return a->key < b->key ? -1 : 1;
  return a->index < b->index ? -1 : a->index > b->index;
}

int rsw_bundle_runs(size_t n, const uint64_t *key, const double *wl, int k, size_t *lead) {
  for (size_t i = 0; i < n; i++) lead[i] = i;
  if (k <= 1 || n < 2) return 0;
  if (k > RSW_BUNDLE_MAX_RUN) k = RSW_BUNDLE_MAX_RUN;
  unit *u = malloc(n * sizeof *u);
  if (!u) return -1;
  for (size_t i = 0; i < n; i++) u[i] = (unit){key[i], i};
  /* Each key's units in their order (a stable order: by key, then index). */
  qsort(u, n, sizeof *u, unit_cmp);
  for (size_t g = 0; g < n;) { /* a run's first unit, then its mates among the next ones */
    size_t e = g + 1;
    if (u[g].key != RSW_BUNDLE_ALONE)
      while (e < n && e - g < (size_t)k && u[e].key == u[g].key) {
        int dup = 0;
        for (size_t m = g; m < e && !dup; m++) dup = wl[u[m].index] == wl[u[e].index];
        if (dup) break;
        lead[u[e].index] = u[g].index;
        e++;
      }
    g = e;
  }
  free(u);
  return 0;
}

char *rsw_bundle_context_text(const cJSON *c) {
  if (!cJSON_IsObject(c) || cJSON_GetObjectItemCaseSensitive(c, "seed") ||
      !cJSON_IsNumber(cJSON_GetObjectItemCaseSensitive(c, "wavelength")))
    return NULL;
  cJSON *d = cJSON_Duplicate(c, 1);
  if (!d) return NULL;
  static const char *const within[] = {"id", "wavelength", "coords", "bundle_group"};
  for (size_t i = 0; i < sizeof within / sizeof within[0]; i++)
    cJSON_DeleteItemFromObjectCaseSensitive(d, within[i]);
  char *t = cJSON_PrintUnformatted(d);
  cJSON_Delete(d);
  if (!t) return NULL;
  char *out = strdup(t); /* malloc'd, whatever cJSON's allocator */
  cJSON_free(t);
  return out;
}

void rsw_bundle_shard_keys(size_t n, const size_t *lead, size_t *key) {
  /* key[i] = #{j < lead[i] : lead[j] == j}: leads counted in one pass
   * (lead[i] <= i, so the count up to lead[i] is known when i comes). */
  size_t below = 0; /* leads among 0..i-1 */
  for (size_t i = 0; i < n; i++) {
    size_t l = lead[i] <= i ? lead[i] : i;
    /* the count below l: l == i gives `below`; l < i was a lead whose
     * key is that count */
    key[i] = l == i ? below : key[l];
    if (lead[i] == i) below++;
  }
}
