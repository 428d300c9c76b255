/* DIR/sweep.json, the manifest of a sweep directory (its format: sweep.h),
 * and --force: removing exactly what an earlier sweep wrote. */
#include <cjson/cJSON.h>
#include <dirent.h>
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "bundle_plan.h"
#include "sweep.h"

static uint64_t fnv1a(uint64_t h, const char *s, size_t n) {
  for (size_t i = 0; i < n; i++) h = (h ^ (unsigned char)s[i]) * 0x100000001b3ull;
  return (h ^ 0xff) * 0x100000001b3ull; /* a separator, so "ab","c" != "a","bc" */
}

static uint64_t fnv1a_str(uint64_t h, const char *s) {
  return fnv1a(h, s ? s : "", s ? strlen(s) : 0);
}

void sweep_fingerprint(const cmdline_args *a, const char *scene, const char *templates, char out[17]) {
  uint64_t h = 0xcbf29ce484222325ull;
  h = fnv1a_str(h, MANIFEST_FORMAT);
  h = fnv1a_str(h, scene);
  const char *file = cmdline_get(a, "--contexts");
  if (file) {
    size_t len = 0;
    char *text = rsw_read_file(file, &len);
    h = fnv1a(h, text ? text : "", text ? len : 0);
    free(text);
  }
  static const char *const keyed[] = {"--grid", "--set",    "--sensor",     "--spp",
                                      "--seed", "--format", "--quantities", "--variance"};
  for (size_t k = 0; k < sizeof keyed / sizeof keyed[0]; k++) {
    size_t n;
    const char *const *v = cmdline_get_all(a, keyed[k], &n);
    h = fnv1a_str(h, keyed[k]);
    for (size_t i = 0; i < n; i++) h = fnv1a_str(h, v[i]);
  }
  /* (only when it bundles: --bundle 1 keeps the value sweeps had before
   * --bundle existed; none is auto, the daemon's default, so that a sweep
   * begun when none meant 1 is not resumed with bundles) */
  const char *bundle = cmdline_get(a, "--bundle");
  if (!bundle) bundle = "auto";
  if (strcmp(bundle, "1") != 0) h = fnv1a_str(fnv1a_str(h, "--bundle"), bundle);
  /* --templates by their JSON, not the argument (a file or stdin); only
   * when given, so that sweeps without them keep their fingerprints */
  if (templates) h = fnv1a_str(fnv1a_str(h, "--templates"), templates);
  snprintf(out, 17, "%016llx", (unsigned long long)h);
}

void manifest_free(sweep_manifest *m) {
  cJSON_Delete(m->root);
  free(m->ids);
  free(m->leads);
  free(m->keys);
  free(m->incomplete);
  memset(m, 0, sizeof *m);
}

/* The id of context k of the unsharded list a manifest describes. */
const char *manifest_id(const sweep_manifest *m, size_t k, char buf[72]) {
  if (m->ids) return m->ids[k];
  sweep_make_id(buf, m->id_width, k);
  return buf;
}

int sweep_cmp_str(const void *a, const void *b) {
  return strcmp(*(const char *const *)a, *(const char *const *)b);
}

bool manifest_incomplete(const sweep_manifest *m, const char *id) {
  return m->n_incomplete &&
         bsearch(&id, m->incomplete, m->n_incomplete, sizeof *m->incomplete, sweep_cmp_str);
}

/* Read and check DIR/sweep.json. 0, or -1 when absent (errno ENOENT), or a
 * CLI exit code after printing. */
int manifest_read(const cli_ctx *ctx, const char *dir, sweep_manifest *m) {
  memset(m, 0, sizeof *m);
  char *path = sweep_dir_file(dir, MANIFEST_NAME);
  if (!path) return cli_fail(ctx, CLI_IO, "out of memory");
  size_t len;
  char *text = rsw_read_file(path, &len);
  if (!text) {
    int e = errno;
    int rc = e == ENOENT ? -1 : cli_fail(ctx, CLI_IO, "cannot read '%s': %s", path, strerror(e));
    free(path);
    errno = e;
    return rc;
  }
  m->root = cJSON_ParseWithLength(text, len);
  free(text);
  const cJSON *r = m->root;
  const cJSON *shard = cJSON_GetObjectItemCaseSensitive(r, "shard");
  const cJSON *total = cJSON_GetObjectItemCaseSensitive(r, "contexts_total");
  const cJSON *width = cJSON_GetObjectItemCaseSensitive(r, "id_width");
  m->sweep = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "sweep"));
  const cJSON *ids = cJSON_GetObjectItemCaseSensitive(r, "ids");
  const cJSON *inc = cJSON_GetObjectItemCaseSensitive(r, "incomplete");
  const cJSON *leads = cJSON_GetObjectItemCaseSensitive(r, "bundle_leads");
  m->finished = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(r, "finished"));
  const cJSON *layout = cJSON_GetObjectItemCaseSensitive(r, "layout");
  const cJSON *output = cJSON_GetObjectItemCaseSensitive(r, "output");
  m->pack = output && cJSON_IsString(output) && strcmp(output->valuestring, "dataset") == 0;
  bool ok = (!layout || sweep_layout_from_name(cJSON_GetStringValue(layout), &m->layout)) &&
            (!output || m->pack) && m->sweep && cJSON_IsArray(shard) && cJSON_GetArraySize(shard) == 2 &&
            sweep_json_is_int(total, 0) && (ids ? cJSON_IsArray(ids) : sweep_json_is_int(width, 1)) &&
            (!inc || cJSON_IsArray(inc)) && (!leads || cJSON_IsArray(leads));
  if (ok) {
    const cJSON *si = cJSON_GetArrayItem(shard, 0), *sn = cJSON_GetArrayItem(shard, 1);
    ok = sweep_json_is_int(si, 0) && sweep_json_is_int(sn, 1) && si->valuedouble < sn->valuedouble;
    if (ok) m->shard_i = (size_t)si->valuedouble, m->shard_n = (size_t)sn->valuedouble;
    m->total = (size_t)total->valuedouble;
    m->id_width = ids ? 0 : (int)width->valuedouble;
  }
  /* Arrays for O(1) ids and O(log n) "incomplete?" (cJSON arrays are lists). */
  if (ok && ids) {
    m->ids = malloc((m->total ? m->total : 1) * sizeof *m->ids);
    size_t k = 0;
    const cJSON *v;
    cJSON_ArrayForEach(v, ids) {
      if (!m->ids || k >= m->total || !cJSON_IsString(v)) break;
      m->ids[k++] = v->valuestring;
    }
    ok = m->ids && k == m->total && !v; /* every element a string, no more and no fewer */
  }
  if (ok && leads) { /* total of them, each at most its own index */
    m->leads = malloc((m->total ? m->total : 1) * sizeof *m->leads);
    size_t k = 0;
    const cJSON *v;
    cJSON_ArrayForEach(v, leads) {
      if (!m->leads || k >= m->total || !sweep_json_is_int(v, 0) || v->valuedouble > (double)k) break;
      m->leads[k] = (size_t)v->valuedouble;
      k++;
    }
    ok = m->leads && k == m->total && !v;
    if (ok) ok = (m->keys = malloc((m->total ? m->total : 1) * sizeof *m->keys)) != NULL;
    /* How its groups were dealt: "rank" (group g to shard g mod N), or,
     * absent, by the group's first context mod N, as clients before the
     * rank rule did, so that their shards still merge and --force still
     * finds their films. */
    const cJSON *rule = cJSON_GetObjectItemCaseSensitive(r, "bundle_shards");
    const char *rs = cJSON_GetStringValue(rule);
    if (ok && rule && !(rs && strcmp(rs, "rank") == 0)) {
      int rc =
          cli_fail(ctx, CLI_IO, "%s: \"bundle_shards\" is not \"rank\" (written by a newer raysweep?)", path);
      manifest_free(m);
      free(path);
      return rc;
    }
    if (ok && rule)
      rsw_bundle_shard_keys(m->total, m->leads, m->keys);
    else if (ok)
      memcpy(m->keys, m->leads, m->total * sizeof *m->keys);
  }
  if (ok && inc) {
    size_t n = (size_t)cJSON_GetArraySize(inc);
    m->incomplete = malloc((n ? n : 1) * sizeof *m->incomplete);
    const cJSON *v;
    cJSON_ArrayForEach(v, inc) {
      if (!m->incomplete || !cJSON_IsString(v)) break;
      m->incomplete[m->n_incomplete++] = v->valuestring;
    }
    ok = m->incomplete && m->n_incomplete == n;
    if (ok && n) qsort(m->incomplete, n, sizeof *m->incomplete, sweep_cmp_str);
  }
  if (!ok) {
    int rc = cli_fail(ctx, CLI_IO, "%s: not a sweep manifest (%s)", path, MANIFEST_FORMAT);
    manifest_free(m);
    free(path);
    return rc;
  }
  free(path);
  return 0;
}

/* Write DIR/sweep.json for this shard. incomplete may be NULL ([]). */
int manifest_write(const cli_ctx *ctx, const char *dir, const char *fingerprint, const char *scene,
                   size_t shard_i, size_t shard_n, const sweep_list *l, const char *job, bool finished,
                   const cJSON *incomplete) {
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "format", MANIFEST_FORMAT);
  cJSON_AddStringToObject(o, "sweep", fingerprint);
  cJSON_AddStringToObject(o, "scene", scene);
  cJSON *sh = cJSON_AddArrayToObject(o, "shard");
  cJSON_AddItemToArray(sh, cJSON_CreateNumber((double)shard_i));
  cJSON_AddItemToArray(sh, cJSON_CreateNumber((double)shard_n));
  cJSON_AddNumberToObject(o, "contexts_total", (double)l->total);
  cJSON_AddNumberToObject(o, "seed", (double)l->seed);
  if (l->all_ids) {
    cJSON *ids = cJSON_AddArrayToObject(o, "ids");
    char buf[72];
    for (size_t k = 0; k < l->total; k++) {
      if (!l->all_ids[k]) sweep_make_id(buf, l->id_width, k);
      cJSON_AddItemToArray(ids, cJSON_CreateString(l->all_ids[k] ? l->all_ids[k] : buf));
    }
  } else {
    cJSON_AddNumberToObject(o, "id_width", l->id_width);
  }
  bool grouped = false;
  for (size_t k = 0; l->leads && k < l->total && !grouped; k++) grouped = l->leads[k] != k;
  if (grouped) {
    cJSON *leads = cJSON_AddArrayToObject(o, "bundle_leads");
    for (size_t k = 0; k < l->total; k++)
      cJSON_AddItemToArray(leads, cJSON_CreateNumber((double)l->leads[k]));
    cJSON_AddStringToObject(o, "bundle_shards", "rank"); /* how the groups are dealt (manifest_read) */
  }
  if (l->layout != SWEEP_LAYOUT_DIRS) /* absent for the default: manifests as before --layout */
    cJSON_AddStringToObject(o, "layout", sweep_layout_name(l->layout));
  if (l->pack) cJSON_AddStringToObject(o, "output", "dataset"); /* absent: a file per film */
  if (job && *job)
    cJSON_AddStringToObject(o, "job", job);
  else
    cJSON_AddNullToObject(o, "job");
  cJSON_AddBoolToObject(o, "finished", finished);
  cJSON_AddItemToObject(o, "incomplete", incomplete ? cJSON_Duplicate(incomplete, 1) : cJSON_CreateArray());
  char *text = cJSON_PrintUnformatted(o);
  cJSON_Delete(o);
  char *path = sweep_dir_file(dir, MANIFEST_NAME);
  int rc = CLI_OK;
  if (!text || !path) {
    rc = cli_fail(ctx, CLI_IO, "out of memory");
  } else {
    size_t n = strlen(text);
    text[n] = '\n'; /* the NUL goes: write n + 1 bytes of "...}\n" */
    if (cli_write_file_atomic(path, text, n + 1))
      rc = cli_fail(ctx, CLI_IO, "cannot write '%s': %s", path, strerror(errno));
  }
  free(text);
  free(path);
  return rc;
}

/* What a sweep writes into DIR/<context>/: <sensor>.exr|.npy|.json and
 * the temp files of an interrupted write (<name>.tmp.<pid>). */
static bool sweep_file_name(const char *name) {
  if (strstr(name, ".tmp.")) return true;
  const char *dot = strrchr(name, '.');
  return dot && (strcmp(dot, ".exr") == 0 || strcmp(dot, ".npy") == 0 || strcmp(dot, ".json") == 0);
}

/* Remove DIR/<context>/'s sweep files and the directory when that empties
 * it. Symbolic links are not followed. Returns the files removed. */
static size_t remove_context_dir(const char *dir, const char *context) {
  if (!cli_safe_component(context)) return 0;
  char *cdir = sweep_dir_file(dir, context);
  struct stat st;
  size_t removed = 0;
  if (cdir && lstat(cdir, &st) == 0 && S_ISDIR(st.st_mode)) {
    DIR *d = opendir(cdir);
    struct dirent *e;
    while (d && (e = readdir(d))) {
      if (!sweep_file_name(e->d_name)) continue;
      char *f = sweep_dir_file(cdir, e->d_name);
      if (f && sweep_is_regular(f) && unlink(f) == 0) removed++;
      free(f);
    }
    if (d) closedir(d);
    rmdir(cdir); /* fails, as it should, when something else is left */
  }
  free(cdir);
  return removed;
}

/* The contexts an earlier sweep in DIR wrote, for its flat films. */
typedef struct context_set {
  char **ids;
  size_t n, cap;
  bool flat; /* films in DIR itself: the manifest says so, or index.jsonl names one */
} context_set;

static void context_set_add(context_set *s, const char *id) {
  if (s->n == s->cap) {
    size_t cap = s->cap ? 2 * s->cap : 64;
    char **ni = realloc(s->ids, cap * sizeof *ni);
    if (!ni) return; /* out of memory: those films stay, and are named as kept */
    s->ids = ni, s->cap = cap;
  }
  if ((s->ids[s->n] = strdup(id))) s->n++;
}

/* Remove DIR's flat films (and their temp files) of the contexts in s.
 * Returns the files removed. */
static size_t remove_flat_films(const char *dir, context_set *s) {
  if (!s->flat || !s->n) return 0;
  qsort(s->ids, s->n, sizeof *s->ids, sweep_cmp_str);
  DIR *d = opendir(dir);
  struct dirent *e;
  size_t removed = 0;
  while (d && (e = readdir(d))) {
    char id[256];
    const char *key = id;
    if (!sweep_flat_context(e->d_name, id) || !bsearch(&key, s->ids, s->n, sizeof *s->ids, sweep_cmp_str))
      continue;
    char *f = sweep_dir_file(dir, e->d_name);
    if (f && sweep_is_regular(f) && unlink(f) == 0) removed++;
    free(f);
  }
  if (d) closedir(d);
  return removed;
}

/* Make -o DIR ready: create it when absent; an empty one is fine. A
 * non-empty one is refused unless --force and it holds an earlier sweep
 * (sweep.json or index.jsonl): then exactly what that sweep wrote goes
 * (its films, the temp files of an interrupted write, emptied context
 * directories, index.jsonl, sweep.json) and anything else stays. A
 * directory holding no sweep is never emptied: a mistyped -o must not
 * cost someone their files. */
int sweep_prepare_output(const cli_ctx *ctx, const char *dir, bool force) {
  char first[256];
  DIR *d = opendir(dir);
  if (!d) {
    if (errno == ENOENT) {
      if (cli_mkdirs(dir)) return cli_fail(ctx, CLI_IO, "cannot create '%s': %s", dir, strerror(errno));
      return 0;
    }
    return cli_fail(ctx, CLI_IO, "-o %s: %s", dir, strerror(errno));
  }
  size_t n = sweep_dir_entries(d, first, sizeof first);
  closedir(d);
  if (n == 0) return 0;
  if (!force)
    return cli_usage(ctx,
                     "-o %s: the directory is not empty (%zu entr%s, e.g. '%s'); give a new or empty "
                     "directory, or add --force to replace the earlier sweep in it",
                     dir, n, n == 1 ? "y" : "ies", first);
  char *index = sweep_dir_file(dir, "index.jsonl"), *manifest = sweep_dir_file(dir, MANIFEST_NAME);
  if (!index || !manifest) {
    free(index), free(manifest);
    return cli_fail(ctx, CLI_IO, "out of memory");
  }
  bool has_index = sweep_is_regular(index), has_manifest = sweep_is_regular(manifest);
  char *state = sweep_dir_file(dir, SPREAD_STATE);
  if (state && sweep_is_regular(state)) unlink(state); /* the journal of an earlier --spread */
  free(state);
  char *spool = sweep_dir_file(dir, FILM_SPOOL); /* and its films, with --format dataset */
  if (spool && sweep_is_regular(spool)) unlink(spool);
  free(spool);
  if (!has_index && !has_manifest) {
    free(index), free(manifest);
    return cli_usage(ctx,
                     "-o %s: --force replaces an earlier sweep, but this non-empty directory holds none "
                     "(no %s or index.jsonl); nothing was deleted: give a new or empty directory",
                     dir, MANIFEST_NAME);
  }
  size_t removed = 0;
  context_set flat = {0};
  if (has_index) { /* every context the index names */
    char *text = rsw_read_file(index, NULL);
    for (char *s = text, *nl; s && *s; s = nl ? nl + 1 : s + strlen(s)) {
      nl = strchr(s, '\n');
      if (nl) *nl = '\0';
      cJSON *o = cJSON_Parse(s);
      const char *c = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "context"));
      const char *file = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "file"));
      if (c) removed += remove_context_dir(dir, c);
      if (c) context_set_add(&flat, c);
      if (file && !strchr(file, '/')) flat.flat = true;
      cJSON_Delete(o);
    }
    free(text);
  }
  sweep_manifest m;
  int mrc = has_manifest ? manifest_read(ctx, dir, &m) : -1;
  if (mrc > 0) {
    for (size_t i = 0; i < flat.n; i++) free(flat.ids[i]);
    free(flat.ids);
    free(index), free(manifest);
    return mrc;
  }
  if (mrc == 0) { /* every context of its shard (an interrupted sweep has no index yet) */
    char buf[72];
    flat.flat = flat.flat || m.layout == SWEEP_LAYOUT_FLAT;
    for (size_t k = 0; k < m.total; k++)
      if (sweep_shard_of(m.keys, k, m.shard_n) == m.shard_i) {
        removed += remove_context_dir(dir, manifest_id(&m, k, buf));
        if (flat.flat) context_set_add(&flat, manifest_id(&m, k, buf));
      }
    manifest_free(&m);
  }
  removed += remove_flat_films(dir, &flat);
  for (size_t i = 0; i < flat.n; i++) free(flat.ids[i]);
  free(flat.ids);
  char *dataset = sweep_dir_file(dir, DATASET_NAME);
  if (dataset && sweep_is_regular(dataset)) unlink(dataset);
  free(dataset);
  if (has_index && unlink(index) != 0 && errno != ENOENT) {
    int rc = cli_fail(ctx, CLI_IO, "cannot remove '%s': %s", index, strerror(errno));
    free(index), free(manifest);
    return rc;
  }
  if (has_manifest && unlink(manifest) != 0 && errno != ENOENT) {
    int rc = cli_fail(ctx, CLI_IO, "cannot remove '%s': %s", manifest, strerror(errno));
    free(index), free(manifest);
    return rc;
  }
  free(index), free(manifest);
  d = opendir(dir);
  size_t left = d ? sweep_dir_entries(d, first, sizeof first) : 0;
  if (d) closedir(d);
  if (!ctx->quiet) {
    fprintf(stderr, "raysweep %s: --force: removed the earlier sweep in %s (%zu film%s)\n", ctx->cmd, dir,
            removed, removed == 1 ? "" : "s");
    if (left)
      fprintf(stderr, "raysweep %s: kept %zu entr%s no sweep wrote (e.g. '%s')\n", ctx->cmd, left,
              left == 1 ? "y" : "ies", first);
  }
  return 0;
}
