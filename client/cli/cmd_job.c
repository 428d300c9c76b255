/* raysweep job submit | ls | show | watch | cancel | rm. */
#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "cli.h"

const cmdline_opt cli_opts_job_watch[] = {
    {"--timeout", "S", false, "stop waiting after S seconds (exit 5; the job keeps running)"},
    {NULL},
};

static void print_status_json(const char *id, const rsw_job_status *st) {
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "id", id);
  cJSON_AddStringToObject(o, "state", cli_job_state_name(st->state));
  cJSON_AddNumberToObject(o, "contexts_total", (double)st->contexts_total);
  cJSON_AddNumberToObject(o, "contexts_done", (double)st->contexts_done);
  cJSON_AddNumberToObject(o, "renders_total", (double)st->renders_total);
  cJSON_AddNumberToObject(o, "renders_done", (double)st->renders_done);
  cJSON_AddNumberToObject(o, "renders_failed", (double)st->renders_failed);
  cJSON_AddNumberToObject(o, "seconds", st->seconds);
  if (st->error[0]) cJSON_AddStringToObject(o, "error", st->error);
  cli_print_json(o);
}

/* job submit ID|FILE REQUEST: a JobRequest as the daemon takes it (a file
 * or the JSON itself), sent as it is: what sweep's options do not carry
 * (bands, per-job defaults, a context list with templates) from a shell.
 * Prints the job id; job watch and fetch -o FILE.nc follow. */
int cmd_job_submit(cli_ctx *ctx, const cmdline_args *a) {
  const char *scene = a->pos[0];
  cJSON *req = NULL;
  int rc = cli_json_option(ctx, "REQUEST", a->pos[1], &req);
  if (!rc && !cJSON_IsObject(req))
    rc = cli_usage(ctx, "REQUEST: a JSON object (a JobRequest: contexts, defaults, bands, templates, ...)");
  char *body = rc ? NULL : cJSON_PrintUnformatted(req);
  cJSON_Delete(req);
  if (rc) return rc;
  if (!body) return cli_fail(ctx, CLI_IO, "out of memory");
  char scene_id[65] = "", job[40] = "";
  struct stat sst;
  rsw_status s = RSW_OK;
  if (stat(scene, &sst) == 0 && S_ISREG(sst.st_mode)) { /* a scene FILE, pushed first, as sweep does */
    int created = 0;
    s = rsw_scene_push_file(ctx->client, scene, NULL, scene_id, &created);
    if (s) {
      free(body);
      return cli_report(ctx, s, scene);
    }
    scene = scene_id;
  }
  s = rsw_job_submit_json(ctx->client, scene, body, NULL, job);
  free(body);
  if (s) return cli_report(ctx, s, scene);
  cli_print_job_warnings(ctx, "raysweep job submit", job, NULL);
  if (ctx->json) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "id", job);
    cJSON_AddStringToObject(o, "scene", scene);
    cli_print_json(o);
  } else {
    printf("%s\n", job);
  }
  return CLI_OK;
}

/* What a job's failed renders say, not only how many there were: the
 * first one's context, sensor and error on stderr ("and N more" when
 * there are others; `fetch` or GET results list them all). Nothing when
 * the results cannot be read. */
static void print_first_failure(const cli_ctx *ctx, const char *id) {
  char *text = NULL;
  if (rsw_job_results(ctx->client, id, &text) != RSW_OK) return;
  cJSON *res = cJSON_Parse(text);
  rsw_free(text);
  const cJSON *r, *first = NULL;
  size_t n = 0;
  cJSON_ArrayForEach(r, cJSON_GetObjectItemCaseSensitive(res, "results")) {
    const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "state"));
    if (!state || strcmp(state, "failed") != 0) continue;
    if (!n++) first = r;
  }
  if (first) {
    const char *c = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(first, "context"));
    const char *s = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(first, "sensor"));
    const char *e = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(first, "error"));
    fprintf(stderr, "raysweep %s: %s/%s failed: %s", ctx->cmd, c ? c : "?", s ? s : "?",
            e ? e : "no reason given");
    if (n > 1) fprintf(stderr, " (and %zu more)", n - 1);
    fputc('\n', stderr);
  }
  cJSON_Delete(res);
}

int cmd_job_ls(cli_ctx *ctx, const cmdline_args *a) {
  (void)a;
  char *text = NULL;
  rsw_status s = rsw_job_list(ctx->client, &text);
  if (s) return cli_report(ctx, s, "GET /v1/jobs");
  int rc = CLI_OK;
  if (ctx->json) {
    fputs(text, stdout);
    if (!*text || text[strlen(text) - 1] != '\n') putchar('\n');
  } else {
    cJSON *j = cJSON_Parse(text);
    if (!j) {
      rc = cli_fail(ctx, CLI_SERVER, "the server's answer is not JSON");
    } else {
      const cJSON *job;
      cJSON_ArrayForEach(job, cJSON_GetObjectItemCaseSensitive(j, "jobs")) {
        const char *id = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(job, "id"));
        const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(job, "state"));
        const char *scene = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(job, "scene"));
        const char *created = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(job, "created"));
        char progress[64];
        snprintf(progress, sizeof progress, "%.0f/%.0f",
                 cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(job, "renders_done")),
                 cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(job, "renders_total")));
        printf("%-14s %-9s %13s renders  %4.0f failed  scene %.12s  %s\n", id ? id : "?", state ? state : "?",
               progress, cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(job, "renders_failed")),
               scene ? scene : "?", created ? created : "");
      }
      cJSON_Delete(j);
    }
  }
  rsw_free(text);
  return rc;
}

/* The Job object as the server sends it, picked out of GET /v1/jobs (the
 * library gives one job as a struct). NULL when not listed. Owned. */
static char *job_json(cli_ctx *ctx, const char *id) {
  char *text = NULL, *out = NULL;
  if (rsw_job_list(ctx->client, &text)) return NULL;
  cJSON *j = cJSON_Parse(text);
  const cJSON *job;
  cJSON_ArrayForEach(job, cJSON_GetObjectItemCaseSensitive(j, "jobs")) {
    const char *jid = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(job, "id"));
    if (jid && strcmp(jid, id) == 0) {
      out = cJSON_PrintUnformatted(job);
      break;
    }
  }
  cJSON_Delete(j);
  rsw_free(text);
  return out;
}

int cmd_job_show(cli_ctx *ctx, const cmdline_args *a) {
  const char *id = a->pos[0];
  rsw_job_status st;
  rsw_status s = rsw_job_get(ctx->client, id, &st);
  if (s) return cli_report(ctx, s, id);
  if (ctx->json) {
    char *t = job_json(ctx, id);
    if (t)
      printf("%s\n", t);
    else
      print_status_json(id, &st);
    free(t);
    return CLI_OK;
  }
  cli_print_job_warnings(ctx, "raysweep job", id, NULL);
  printf("id:        %s\n", id);
  printf("state:     %s\n", cli_job_state_name(st.state));
  printf("contexts:  %zu/%zu\n", st.contexts_done, st.contexts_total);
  printf("renders:   %zu/%zu (%zu failed)\n", st.renders_done, st.renders_total, st.renders_failed);
  char el[32];
  cli_format_duration(el, sizeof el, st.seconds);
  if (st.state == RSW_JOB_QUEUED)
    printf("elapsed:   - (queued, not started)\n");
  else if (st.state == RSW_JOB_RUNNING)
    printf("elapsed:   %s so far (%.3f s)\n", el, st.seconds);
  else
    printf("elapsed:   %s (%.3f s)\n", el, st.seconds);
  if (st.state == RSW_JOB_RUNNING && st.seconds > 0 && st.renders_done > 0) {
    /* The job's mean rate since it started, and the time left at it. */
    double rate = (double)st.renders_done / st.seconds;
    char eta[32];
    cli_format_duration(eta, sizeof eta, (double)(st.renders_total - st.renders_done) / rate);
    printf("rate:      %.2f renders/s  ETA %s\n", rate, eta);
  }
  if (st.error[0]) printf("error:     %s\n", st.error);
  if (st.renders_failed) print_first_failure(ctx, id);
  return CLI_OK;
}

int cmd_job_watch(cli_ctx *ctx, const cmdline_args *a) {
  const char *id = a->pos[0];
  double timeout = 0;
  const char *v = cmdline_get(a, "--timeout");
  if (v && (!cli_parse_double(v, &timeout) || !(timeout > 0)))
    return cli_usage(ctx, "--timeout needs a positive number of seconds (got '%s')", v);
  rsw_job_status st;
  memset(&st, 0, sizeof st);
  /* Ctrl-C stops watching and leaves the job alone: the watcher is often
   * not the one who submitted it (a sweep in another terminal, a script),
   * and cancelling is one explicit command away, which the message names. */
  cli_catch_interrupt();
  int rc = cli_wait_job(ctx, id, timeout, CLI_INTERRUPT_DETACH, &st);
  if (rc != CLI_OK && rc != CLI_JOB) return rc;
  if (st.renders_failed) print_first_failure(ctx, id);
  if (ctx->json)
    print_status_json(id, &st);
  else
    printf("%s %s: %zu/%zu renders, %zu failed, %.3f s\n", id, cli_job_state_name(st.state), st.renders_done,
           st.renders_total, st.renders_failed, st.seconds);
  return rc;
}

enum {
  CANCEL_WAIT_S = 30
};

int cmd_job_cancel(cli_ctx *ctx, const cmdline_args *a) {
  const char *id = a->pos[0];
  rsw_status s = rsw_job_cancel(ctx->client, id);
  if (s) return cli_report(ctx, s, id);
  /* The cancel is asynchronous: the job stops at its renders' next check.
   * Wait for that (a bounded wait), so that what is printed is the state
   * the cancel led to, not the one it found. */
  rsw_job_status st;
  (void)rsw_job_wait(ctx->client, id, NULL, NULL, CANCEL_WAIT_S, NULL); /* a failure: the GET reports it */
  s = rsw_job_get(ctx->client, id, &st);
  if (s) return cli_report(ctx, s, id);
  if (ctx->json)
    print_status_json(id, &st);
  else if (st.state == RSW_JOB_QUEUED || st.state == RSW_JOB_RUNNING)
    printf("%s %s (cancel requested; still %s after %d s)\n", id, cli_job_state_name(st.state),
           cli_job_state_name(st.state), CANCEL_WAIT_S);
  else
    printf("%s %s\n", id, cli_job_state_name(st.state));
  return CLI_OK;
}

int cmd_job_rm(cli_ctx *ctx, const cmdline_args *a) {
  rsw_status s = rsw_job_delete(ctx->client, a->pos[0]);
  if (s) return cli_report(ctx, s, a->pos[0]);
  if (ctx->json)
    printf("{\"deleted\":\"%s\"}\n", a->pos[0]);
  else if (!ctx->quiet)
    fprintf(stderr, "raysweep job rm: %s deleted\n", a->pos[0]);
  return CLI_OK;
}
