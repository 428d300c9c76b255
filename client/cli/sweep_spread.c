/* raysweep sweep --spread K: the shards of one sweep at once, through a
 * load balancer (rsw_spread_run), and resuming a run that was cut off: its
 * journal (SPREAD_STATE) names the films saved, so a rerun fetches only
 * the rest. */
#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "sweep.h"

/* DIR holds an unfinished --spread run of this very sweep: rerunning the
 * command resumes it instead of refusing a non-empty directory. */
bool sweep_spread_resumable(const char *dir, const char *fingerprint, sweep_layout *layout) {
  char *state = sweep_dir_file(dir, SPREAD_STATE);
  bool has = state && sweep_is_regular(state);
  free(state);
  if (!has) return false;
  sweep_manifest m;
  cli_ctx quiet = {.cmd = "sweep", .quiet = true};
  if (manifest_read(&quiet, dir, &m) != 0) return false;
  bool same = strcmp(m.sweep, fingerprint) == 0 && !m.finished;
  *layout = m.layout;
  manifest_free(&m);
  return same;
}

typedef struct spread_sink {
  cli_ctx *ctx;
  const char *dir;
  sweep_layout layout;
  cli_format fmt;
  sweep_item **sorted;
  size_t n;
  const cJSON *job_params;
  index_entry *e;
  size_t ne, cap;
  cJSON *incomplete; /* context ids, may repeat */
  size_t failed;
  int rc;
  cli_progress *progress;
  film_pack *pack; /* --format dataset: the films kept (and spooled), no file each */
} spread_sink;

/* Save the film (decoded, or the daemon's bytes; or, resumed, find the one
 * an earlier run saved) and keep its index line. */
static int spread_save(spread_sink *k, const char *c, const char *sn, const char *result_json,
                       const rsw_film *film, const void *bytes, size_t len, int resumed) {
  if (k->rc) return 1;
  cJSON *r = cJSON_Parse(result_json);
  const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "state"));
  if (!state || strcmp(state, "succeeded") != 0) {
    const char *err = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "error"));
    if (k->progress && k->progress->drawn && k->ctx->stderr_tty) fputc('\n', stderr);
    fprintf(stderr, "raysweep sweep: %s/%s %s%s%s\n", c, sn, state ? state : "lost", err ? ": " : "",
            err ? err : "");
    k->failed++;
    cJSON_AddItemToArray(k->incomplete, cJSON_CreateString(c));
    cJSON_Delete(r);
    return 0;
  }
  char rel[1100], path[4096];
  if (k->pack) {
    if (bytes)
      k->rc = pack_add(k->ctx, k->pack, c, sn, cJSON_GetObjectItemCaseSensitive(r, "channels"), bytes, len);
    else if (resumed && !pack_find(k->pack, c, sn))
      k->rc = cli_fail(k->ctx, CLI_IO,
                       "%s/%s: %s says an earlier run saved it, but %s/%s does not hold it (start over "
                       "with --force)",
                       c, sn, SPREAD_STATE, k->dir, FILM_SPOOL);
  } else {
    k->rc = sweep_film_file(k->ctx, k->dir, k->layout, c, sn, k->fmt, film || bytes, rel, sizeof rel, path,
                            sizeof path);
    if (!k->rc && (film || bytes))
      k->rc = film ? cli_save_film(k->ctx, film, path, k->fmt) : cli_save_encoded(k->ctx, bytes, len, path);
    else if (!k->rc && resumed && !sweep_is_regular(path))
      k->rc = cli_fail(k->ctx, CLI_IO,
                       "%s: %s says an earlier run saved it, but it is not there (start over with --force)",
                       path, SPREAD_STATE);
  }
  if (k->rc) {
    cJSON_Delete(r);
    return 1;
  }
  if (k->ne == k->cap) {
    size_t nc = k->cap ? 2 * k->cap : 64;
    index_entry *ne = realloc(k->e, nc * sizeof *ne);
    if (!ne) {
      k->rc = cli_fail(k->ctx, CLI_IO, "out of memory");
      cJSON_Delete(r);
      return 1;
    }
    k->e = ne, k->cap = nc;
  }
  cJSON *line = sweep_index_line(r, c, sn, k->pack ? NULL : rel, k->sorted, k->n, k->job_params);
  cJSON_Delete(r);
  index_entry *e = &k->e[k->ne];
  memset(e, 0, sizeof *e);
  e->line = line;
  e->context = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(line, "context"));
  e->sensor = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(line, "sensor"));
  e->order = k->ne++;
  return 0;
}

/* rsw_spread_film_fn (films decoded: JSON) and rsw_spread_encoded_fn
 * (EXR and NPY, as the daemon encoded them). */
static int spread_film(void *user, const char *c, const char *sn, const char *result_json,
                       const rsw_film *film, int resumed) {
  return spread_save(user, c, sn, result_json, film, NULL, 0, resumed);
}

static int spread_film_encoded(void *user, const char *c, const char *sn, const char *result_json,
                               const void *bytes, size_t len, int resumed) {
  return spread_save(user, c, sn, result_json, NULL, bytes, len, resumed);
}

/* The whole sweep's warnings (its dry run: rsw_spread_opts.on_warnings), a
 * line each, as the unsharded sweep prints its job's (even with -q). */
static void spread_warnings(void *user, const char *text) {
  (void)user;
  cli_print_warnings("raysweep sweep", "the sweep", text, NULL);
}

int sweep_run_spread(cli_ctx *ctx, const cmdline_args *a, int k_shards, bool resume, cli_format fmt,
                     double timeout, const sweep_list *l, sweep_item **sorted, const cJSON *job_params,
                     const rsw_contexts *x, const char *fingerprint, size_t shard_i, size_t shard_n) {
  const char *scene = a->pos[0], *dir = cmdline_get(a, "-o");
  struct stat sst;
  bool scene_is_file = stat(scene, &sst) == 0 && S_ISREG(sst.st_mode);
  char *state = sweep_dir_file(dir, SPREAD_STATE);
  cli_progress p;
  cli_progress_init(&p, ctx);
  film_pack pack = {.fd = -1};
  bool done = false;
  spread_sink sink = {.ctx = ctx,
                      .dir = dir,
                      .layout = l->layout,
                      .fmt = fmt,
                      .sorted = sorted,
                      .n = l->n,
                      .job_params = job_params,
                      .incomplete = cJSON_CreateArray(),
                      .progress = &p,
                      .pack = l->pack ? &pack : NULL};
  int rc = 0;
  if (!state || !sink.incomplete) {
    rc = cli_fail(ctx, CLI_IO, "out of memory");
    goto out;
  }
  /* --format dataset: the films delivered, spooled for a rerun (resumed:
   * those of the run before, read back). */
  if (l->pack && (rc = pack_open(ctx, &pack, dir, true, resume, sorted, l->n))) goto out;
  /* Written before any film: an interrupted sweep says so (merge lists it
   * as unfinished; a rerun of the command resumes it). */
  if (!resume && (rc = manifest_write(ctx, dir, fingerprint, scene, shard_i, shard_n, l, NULL, false, NULL)))
    goto out;
  if (!ctx->quiet)
    fprintf(stderr, "raysweep sweep: %s%zu contexts in %d shards through %s\n", resume ? "resuming: " : "",
            l->n, k_shards, ctx->server_url);
  rsw_client_opts co = {
      .size = sizeof co, .base_url = ctx->server_url, .token = ctx->token, .interrupt = &cli_interrupted};
  rsw_spread_opts so = {.size = sizeof so,
                        .on_warnings = spread_warnings,
                        .shards = k_shards,
                        .scene_file = scene_is_file ? scene : NULL,
                        .state_path = state,
                        .timeout_s = timeout,
                        .progress = ctx->quiet ? NULL : cli_progress_cb,
                        .progress_user = &p,
                        .on_film = spread_film,
                        .film_user = &sink,
                        .film_media_type = cli_format_media_type(fmt),
                        .on_film_encoded = spread_film_encoded};
  rsw_spread_result res;
  cli_catch_interrupt();
  rsw_status s = rsw_spread_run(&co, scene_is_file ? NULL : scene, x, &so, &res);
  if (p.drawn && ctx->stderr_tty && s) fputc('\n', stderr);
  if (sink.rc) {
    rc = sink.rc;
    goto out;
  }
  if (s) {
    const char *why = rsw_spread_last_error();
    if (s == RSW_ERR_CANCELLED && cli_interrupted)
      rc = cli_fail(ctx, cli_interrupted_code(),
                    "%s; the shards' jobs keep running on the replicas: rerun the same command to "
                    "fetch what finished and render only the rest (state in %s)",
                    cli_interrupted_word(), state);
    else if (s == RSW_ERR_UNAVAILABLE)
      rc = cli_fail(ctx, CLI_CONNECT,
                    "%s; %zu films saved so far; rerun the same command to resume (state in %s)", why,
                    sink.ne, state);
    else if (s == RSW_ERR_TIMEOUT)
      rc = cli_fail(ctx, CLI_TIMEOUT, "%s; rerun the same command to resume (state in %s)", why, state);
    else if (s == RSW_ERR_PRECONDITION)
      rc = cli_usage(ctx, "%s: resume with the same --spread, or start over with --force", why);
    else
      rc = cli_fail(ctx, s == RSW_ERR_NOMEM || s == RSW_ERR_IO ? CLI_IO : CLI_SERVER, "%s", why);
    goto out;
  }
  p.done = p.total = res.films + res.failed + res.resumed;
  p.failed = res.failed;
  if (!ctx->quiet) cli_progress_finish(&p);
  /* The same directory an unsharded sweep of the scene id writes: index
   * sorted by context and sensor, sweep.json with that sweep's
   * fingerprint. */
  char fp2[17];
  sweep_fingerprint(a, res.scene_id, l->templates, fp2);
  if ((rc = sweep_write_index(ctx, dir, sink.e, sink.ne))) goto out;
  if ((l->dataset || l->pack) &&
      (rc = sweep_write_dataset(ctx, dir, sink.e, sink.ne, true, l->seed, l->pack ? &pack : NULL)))
    goto out;
  cJSON *inc = cJSON_CreateArray();
  const char *prev = NULL;
  /* incomplete ids sorted, each once */
  size_t ni = (size_t)cJSON_GetArraySize(sink.incomplete);
  const char **ids = malloc((ni ? ni : 1) * sizeof *ids);
  size_t m = 0;
  const cJSON *it;
  cJSON_ArrayForEach(it, sink.incomplete) if (ids) ids[m++] = it->valuestring;
  if (ids && m) qsort(ids, m, sizeof *ids, sweep_cmp_str);
  for (size_t i = 0; ids && i < m; i++)
    if (!prev || strcmp(prev, ids[i]) != 0) cJSON_AddItemToArray(inc, cJSON_CreateString(prev = ids[i]));
  free(ids);
  rc = manifest_write(ctx, dir, fp2, res.scene_id, shard_i, shard_n, l, NULL, true, inc);
  cJSON_Delete(inc);
  if (rc) goto out;
  unlink(state);
  done = true; /* the spool goes with the journal */
  rc = res.failed ? CLI_JOB : CLI_OK;
  if (ctx->json) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "scene", res.scene_id);
    cJSON_AddStringToObject(o, "dir", dir);
    cJSON_AddNumberToObject(o, "contexts", (double)l->n);
    cJSON_AddNumberToObject(o, "films", (double)sink.ne);
    cJSON_AddNumberToObject(o, "failed", (double)res.failed);
    cJSON_AddNumberToObject(o, "shards", k_shards);
    cJSON_AddNumberToObject(o, "resubmitted", (double)res.resubmitted);
    cJSON_AddNumberToObject(o, "contexts_resubmitted", (double)res.contexts_resubmitted);
    cJSON_AddNumberToObject(o, "resumed", (double)res.resumed);
    cli_print_json(o);
  } else if (!ctx->quiet) {
    fprintf(
        stderr,
        "raysweep sweep: %zu films in %s%s (%d shards; %zu resubmission%s of %zu contexts; %zu films from an "
        "earlier run)\n",
        sink.ne, dir, res.failed ? " (some renders failed)" : "", k_shards, res.resubmitted,
        res.resubmitted == 1 ? "" : "s", res.contexts_resubmitted, res.resumed);
  }
out:
  pack_close(&pack, done);
  sweep_entries_free(sink.e, sink.ne);
  cJSON_Delete(sink.incomplete);
  free(state);
  return rc;
}
