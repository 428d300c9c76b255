/* Spectral bundles' one rule (docs/experiments.md#spectral-bundles),
 * shared by the daemon, which forms a job's bundles from its renders, and
 * the client, which keeps a sweep's bundle groups whole across shards
 * (docs/cluster.md#shards-and-spectral-bundles): units with the same key,
 * taken in their order, are cut into runs of at most k from the first;
 * a wavelength already in the run starts the next one. */
#ifndef RSW_COMMON_BUNDLE_PLAN_H
#define RSW_COMMON_BUNDLE_PLAN_H

#include <stddef.h>
#include <stdint.h>

/* A unit that never shares a run (a render with a seed of its own). */
#define RSW_BUNDLE_ALONE UINT64_MAX
/* The most wavelengths one run may hold (k is clamped to it). */
#define RSW_BUNDLE_MAX_RUN 64

/* lead[i]: the index of the first unit of unit i's run (lead[i] <= i;
 * lead[i] == i for every i when k <= 1). key[i]: equal keys may share a
 * run; wl[i]: unit i's wavelength. 0, or -1 out of memory (lead as for
 * k = 1). */
int rsw_bundle_runs(size_t n, const uint64_t *key, const double *wl, int k, size_t *lead);

/* Which shard of n holds unit i: key[i] mod n, key[i] the rank of unit
 * i's run among the runs in the order of their first units (the number of
 * leads below lead[i]; i itself without runs). So a run stays whole and
 * the runs are dealt out in turn: by lead[i] mod n, runs of 16 would all
 * fall on shard 0 whenever n divides 16. */
void rsw_bundle_shard_keys(size_t n, const size_t *lead, size_t *key);

struct cJSON;
/* The client's key for a context (a JobRequest Context object): its JSON
 * less what may differ within a bundle (id, wavelength, coords,
 * bundle_group), malloc'd; NULL for a context that shares no bundle (a
 * seed of its own, no wavelength: a band's nodes bundle within their
 * context) or out of memory. Contexts with equal texts may share runs. */
char *rsw_bundle_context_text(const struct cJSON *c);

#endif
