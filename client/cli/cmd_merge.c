/* raysweep merge: join the directories of a sweep's shards (or of several
 * sweeps) into one; sweep.json tells which contexts must be there. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "sweep.h"

const cmdline_opt cli_opts_merge[] = {
    {"-o", "DIR", false,
     "output directory (with DIR/dataset.nc when the shards were swept with --format nc)"},
    {"--partial", NULL, false, "merge even when contexts are missing (they are listed; exit 0)"},
    {NULL},
};

static bool same_bytes(const char *a, const char *b) {
  size_t la, lb;
  char *x = rsw_read_file(a, &la), *y = rsw_read_file(b, &lb);
  bool same = x && y && la == lb && memcmp(x, y, la) == 0;
  free(x);
  free(y);
  return same;
}

/* Hard link when the file system allows it, else copy through a temp
 * file. dst must not be src. */
static int link_or_copy(const char *src, const char *dst) {
  unlink(dst);
  if (link(src, dst) == 0) return 0;
  size_t len;
  char *data = rsw_read_file(src, &len);
  if (!data) return -1;
  int rc = cli_write_file_atomic(dst, data, len);
  free(data);
  return rc;
}

/* ---- merge: are all the contexts there? ---- */

typedef struct merge_input {
  const char *dir;
  bool has_manifest, has_index;
  sweep_manifest m;
} merge_input;

/* Films of `context` from an input without sweep.json (e sorted by context). */
static bool legacy_has(const index_entry *e, size_t n, const merge_input *in, const char *context) {
  size_t lo = 0, hi = n;
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    if (strcmp(e[mid].context, context) < 0)
      lo = mid + 1;
    else
      hi = mid;
  }
  for (size_t i = lo; i < n && strcmp(e[i].context, context) == 0; i++)
    if (!in[e[i].input].has_manifest) return true;
  return false;
}

/* For each sweep the inputs' manifests name, the contexts no input
 * supplies in full: a context is covered by an input whose shard holds it,
 * whose sweep finished (index written) and that does not list it as
 * incomplete, or by films of an input without a manifest. Prints what is
 * missing; *missing_out (owned) gets every missing id when there is one
 * sweep. Returns the number of missing contexts. */
static size_t merge_missing(const cli_ctx *ctx, const merge_input *in, size_t n_in, const index_entry *e,
                            size_t n, bool partial, size_t *n_sweeps, cJSON **missing_out) {
  size_t total_missing = 0;
  *n_sweeps = 0;
  *missing_out = cJSON_CreateArray();
  for (size_t g = 0; g < n_in; g++) {
    const sweep_manifest *m0 = &in[g].m;
    bool first = in[g].has_manifest;
    for (size_t k = 0; k < g && first; k++)
      if (in[k].has_manifest && strcmp(in[k].m.sweep, m0->sweep) == 0) first = false;
    if (!first) continue; /* this sweep was checked with its first input */
    (*n_sweeps)++;
    size_t shard_n = m0->shard_n, missing = 0;
    bool same_n = true;
    for (size_t j = g; j < n_in; j++)
      if (in[j].has_manifest && strcmp(in[j].m.sweep, m0->sweep) == 0 && in[j].m.shard_n != shard_n)
        same_n = false;
    char buf[72], list[400] = "";
    size_t used = 0;
    for (size_t k = 0; k < m0->total; k++) {
      const char *id = manifest_id(m0, k, buf);
      bool covered = false;
      for (size_t j = g; j < n_in && !covered; j++) {
        const sweep_manifest *m = &in[j].m;
        if (!in[j].has_manifest || strcmp(m->sweep, m0->sweep) != 0) continue;
        covered = in[j].has_index && m->finished && sweep_shard_of(m->keys, k, m->shard_n) == m->shard_i &&
                  !manifest_incomplete(m, id);
      }
      if (!covered) covered = legacy_has(e, n, in, id);
      if (covered) continue;
      missing++;
      cJSON_AddItemToArray(*missing_out, cJSON_CreateString(id));
      if (missing <= 12) {
        int w = snprintf(list + used, sizeof list - used, "%s%s", missing > 1 ? ", " : "", id);
        if (w > 0 && (size_t)w < sizeof list - used) used += (size_t)w;
      }
    }
    if (!missing) continue;
    total_missing += missing;
    fprintf(stderr, "raysweep %s: %s%zu of %zu contexts of sweep %s (scene %.12s) are missing: %s%s\n",
            ctx->cmd, partial ? "warning: " : "", missing, m0->total, m0->sweep,
            cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(m0->root, "scene")), list,
            missing > 12 ? ", ..." : "");
    if (same_n) {
      /* Name the shards that were not given (or did not finish). */
      char shards[200] = "";
      size_t su = 0, count = 0;
      for (size_t i = 0; i < shard_n && count < 8; i++) {
        bool given = false;
        for (size_t j = g; j < n_in; j++)
          if (in[j].has_manifest && strcmp(in[j].m.sweep, m0->sweep) == 0 && in[j].m.shard_i == i &&
              in[j].m.finished && in[j].has_index)
            given = true;
        if (given) continue;
        int w = snprintf(shards + su, sizeof shards - su, "%s%zu/%zu", count ? ", " : "", i, shard_n);
        if (w > 0 && (size_t)w < sizeof shards - su) su += (size_t)w;
        count++;
      }
      if (count)
        fprintf(stderr,
                "  shard%s not given or not finished: %s (run `raysweep sweep ... --shard I/N` for %s)\n",
                count == 1 ? "" : "s", shards, count == 1 ? "it" : "them");
      else
        fprintf(stderr,
                "  every shard is there: the missing contexts had renders that failed (see the shards' "
                "sweep.json \"incomplete\")\n");
    }
  }
  return total_missing;
}

/* Each input's sweep.json and index.jsonl: the entries of every input
 * whose sweep finished (an unfinished one contributes nothing: its
 * contexts are missing), appended to *e. */
static int merge_read_inputs(const cli_ctx *ctx, const cmdline_args *a, merge_input *in, index_entry **e,
                             size_t *n) {
  size_t cap = 0;
  int rc = 0;
  for (size_t i = 0; i < a->n_pos && !rc; i++) {
    in[i].dir = a->pos[i];
    int mrc = manifest_read(ctx, a->pos[i], &in[i].m);
    if (mrc > 0) return mrc;
    in[i].has_manifest = mrc == 0;
    if (in[i].has_manifest && in[i].m.pack)
      return cli_usage(ctx,
                       "%s was swept with --format dataset: its films are in %s alone, and merge joins film "
                       "files; sweep the whole list in one run (--spread K runs its shards at once), or "
                       "sweep the shards with --format nc to merge them",
                       a->pos[i], DATASET_NAME);
    char *index = sweep_dir_file(a->pos[i], "index.jsonl");
    in[i].has_index = index && sweep_is_regular(index);
    free(index);
    if (in[i].has_manifest && !in[i].has_index) {
      /* A sweep that was interrupted or failed: its contexts are missing. */
      if (!ctx->quiet)
        fprintf(stderr,
                "raysweep merge: %s: the sweep did not finish (no index.jsonl); its films are not used\n",
                a->pos[i]);
      continue;
    }
    if (!in[i].has_manifest && !ctx->quiet)
      fprintf(stderr,
              "raysweep merge: %s has no %s (an older raysweep wrote it): its contexts are merged, "
              "but what is missing from its sweep cannot be told\n",
              a->pos[i], MANIFEST_NAME);
    rc = sweep_read_index(ctx, a->pos[i], i, e, n, &cap);
  }
  return rc;
}

/* Sort the entries and drop duplicates (a shard given twice, overlapping
 * shards): the same film is kept once (*dups counts the others);
 * different films for one (context, sensor) are refused. *n: the entries
 * kept (every other one is freed). */
static int merge_dedupe(const cli_ctx *ctx, index_entry *e, size_t *n, size_t *dups) {
  if (*n) qsort(e, *n, sizeof *e, sweep_cmp_entry);
  size_t kept = 0;
  for (size_t i = 0; i < *n; i++) {
    if (kept && strcmp(e[kept - 1].context, e[i].context) == 0 &&
        strcmp(e[kept - 1].sensor, e[i].sensor) == 0) {
      if (!same_bytes(e[kept - 1].src, e[i].src)) {
        int rc = cli_fail(ctx, CLI_IO, "%s/%s is in two inputs with different films: %s and %s", e[i].context,
                          e[i].sensor, e[kept - 1].src, e[i].src);
        sweep_entries_free_range(e, i, *n);
        *n = kept;
        return rc;
      }
      (*dups)++;
      sweep_entries_free_range(e, i, i + 1);
      continue;
    }
    e[kept++] = e[i];
  }
  *n = kept;
  return 0;
}

/* Each kept film into out (its path in the index, relative): hard-linked
 * or copied; already in place when out is one of the inputs. */
static int merge_copy_films(const cli_ctx *ctx, const char *out, const index_entry *e, size_t n) {
  if (cli_mkdirs(out)) return cli_fail(ctx, CLI_IO, "cannot create '%s': %s", out, strerror(errno));
  int rc = 0;
  for (size_t i = 0; i < n && !rc; i++) {
    const char *file = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(e[i].line, "file"));
    size_t dl = strlen(out) + strlen(file) + 2;
    char *dst = malloc(dl);
    if (!dst) return cli_fail(ctx, CLI_IO, "out of memory");
    snprintf(dst, dl, "%s/%s", out, file);
    char *slash = strrchr(dst, '/');
    *slash = '\0';
    if (cli_mkdirs(dst)) rc = cli_fail(ctx, CLI_IO, "cannot create '%s': %s", dst, strerror(errno));
    *slash = '/';
    struct stat ss, ds;
    if (!rc && stat(e[i].src, &ss) != 0)
      rc = cli_fail(ctx, CLI_IO, "cannot read '%s': %s", e[i].src, strerror(errno));
    /* Merging into one of the inputs: the film is already in place. */
    bool in_place = !rc && stat(dst, &ds) == 0 && ds.st_dev == ss.st_dev && ds.st_ino == ss.st_ino;
    if (!rc && !in_place && link_or_copy(e[i].src, dst))
      rc = cli_fail(ctx, CLI_IO, "cannot copy '%s' to '%s': %s", e[i].src, dst, strerror(errno));
    free(dst);
  }
  return rc;
}

/* Inputs swept with --format nc: the merged dataset, rebuilt from the
 * films (bitwise the unsharded sweep's data). An input without films (a
 * shard whose contexts all went to others, as spectral bundles send them)
 * has no dataset and does not say how it was swept. */
static int merge_dataset(const cli_ctx *ctx, const cmdline_args *a, const merge_input *in, const char *out,
                         const index_entry *e, size_t n) {
  bool any = false, all_nc = true;
  for (size_t i = 0; i < a->n_pos && all_nc; i++) {
    bool films = false;
    for (size_t k = 0; k < n && !films; k++) films = e[k].input == i;
    if (!films) continue;
    char *p = sweep_dir_file(a->pos[i], DATASET_NAME);
    any = true;
    all_nc = p && sweep_is_regular(p);
    free(p);
  }
  if (!any || !all_nc) return 0;
  const cJSON *seed = NULL;
  for (size_t i = 0; i < a->n_pos && !seed; i++)
    if (in[i].has_manifest) seed = cJSON_GetObjectItemCaseSensitive(in[i].m.root, "seed");
  return sweep_write_dataset(ctx, out, e, n, sweep_json_is_int(seed, 0),
                             sweep_json_is_int(seed, 0) ? (long long)seed->valuedouble : 0, NULL);
}

/* out/sweep.json when the inputs are the shards of one sweep: that sweep
 * unsharded (as complete as the inputs: what is missing is listed as
 * incomplete). */
static int merge_manifest(const cli_ctx *ctx, const merge_input *in, size_t n_in, const char *out,
                          const cJSON *missing_ids) {
  const sweep_manifest *m0 = NULL;
  for (size_t i = 0; i < n_in && !m0; i++) m0 = in[i].has_manifest ? &in[i].m : NULL;
  cJSON *o = cJSON_Duplicate(m0->root, 1);
  cJSON *sh = cJSON_CreateArray();
  cJSON_AddItemToArray(sh, cJSON_CreateNumber(0));
  cJSON_AddItemToArray(sh, cJSON_CreateNumber(1));
  cJSON_ReplaceItemInObjectCaseSensitive(o, "shard", sh);
  cJSON_ReplaceItemInObjectCaseSensitive(o, "job", cJSON_CreateNull());
  cJSON_ReplaceItemInObjectCaseSensitive(o, "finished", cJSON_CreateTrue());
  cJSON_ReplaceItemInObjectCaseSensitive(o, "incomplete", cJSON_Duplicate(missing_ids, 1));
  char *text = cJSON_PrintUnformatted(o);
  char *path = sweep_dir_file(out, MANIFEST_NAME);
  int rc = 0;
  if (!text || !path) {
    rc = cli_fail(ctx, CLI_IO, "out of memory");
  } else {
    size_t len = strlen(text);
    text[len] = '\n';
    if (cli_write_file_atomic(path, text, len + 1))
      rc = cli_fail(ctx, CLI_IO, "cannot write '%s': %s", path, strerror(errno));
  }
  free(text);
  free(path);
  cJSON_Delete(o);
  return rc;
}

int cmd_merge(cli_ctx *ctx, const cmdline_args *a) {
  const char *out = cmdline_get(a, "-o");
  if (!out) return cli_usage(ctx, "missing -o DIR");
  bool partial = cmdline_has(a, "--partial");
  index_entry *e = NULL;
  size_t n = 0, dups = 0, n_sweeps = 0, missing = 0;
  cJSON *missing_ids = NULL;
  merge_input *in = calloc(a->n_pos, sizeof *in);
  if (!in) return cli_fail(ctx, CLI_IO, "out of memory");
  int rc = merge_read_inputs(ctx, a, in, &e, &n);
  if (!rc) rc = merge_dedupe(ctx, e, &n, &dups);
  if (rc) goto done;
  /* Nothing is written before the inputs are known to be complete. */
  missing = merge_missing(ctx, in, a->n_pos, e, n, partial, &n_sweeps, &missing_ids);
  if (missing && !partial) {
    rc = cli_fail(ctx, CLI_IO,
                  "%zu context%s missing: nothing was written (give the missing shards, or "
                  "--partial to merge what is there)",
                  missing, missing == 1 ? " is" : "s are");
    goto done;
  }
  rc = merge_copy_films(ctx, out, e, n);
  if (!rc) rc = sweep_write_index(ctx, out, e, n);
  if (!rc) rc = merge_dataset(ctx, a, in, out, e, n);
  bool legacy = false;
  for (size_t i = 0; i < a->n_pos; i++) legacy = legacy || !in[i].has_manifest;
  if (!rc && n_sweeps == 1 && !legacy) rc = merge_manifest(ctx, in, a->n_pos, out, missing_ids);
  if (!rc) {
    if (ctx->json) {
      cJSON *o = cJSON_CreateObject();
      cJSON_AddStringToObject(o, "dir", out);
      cJSON_AddNumberToObject(o, "films", (double)n);
      cJSON_AddNumberToObject(o, "duplicates", (double)dups);
      cli_print_json(o);
    } else if (!ctx->quiet)
      fprintf(stderr, "raysweep merge: %zu films in %s%s\n", n, out,
              dups ? " (identical duplicates kept once)" : "");
  }
done:
  sweep_entries_free(e, n);
  for (size_t i = 0; i < a->n_pos; i++) manifest_free(&in[i].m);
  free(in);
  cJSON_Delete(missing_ids);
  return rc;
}
