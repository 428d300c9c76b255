/* raysweep status, scene push|ls|show|rm, params, set. */
#include <cjson/cJSON.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"

const cmdline_opt cli_opts_scene_push[] = {
    {"--variant", "mono|rgb|mono_polarized", false,
     "mono, rgb or mono_polarized (overrides the scene's own)"},
    {NULL},
};
const cmdline_opt cli_opts_scene_rm[] = {
    {"--force", NULL, false, "also cancel the scene's queued and running jobs"},
    {NULL},
};
const cmdline_opt cli_opts_params[] = {
    {"--match", "GLOB", false, "glob over keys (e.g. '*.reflectance.value') or TYPE:ID:PATH"},
    {"--class", "C", false, "spectral, geometric or none"},
    {"--full", NULL, false,
     "every buffer's values (else one longer than 16 numbers shows as {\"length\": N})"},
    {NULL},
};
const cmdline_opt cli_opts_set[] = {
    {"--if-match", "REV", false, "apply only if the scene is still at revision REV"},
    {NULL},
};

/* Print JSON text the server sent, as is, with one newline. */
static void print_raw(const char *json) {
  size_t n = strlen(json);
  fwrite(json, 1, n, stdout);
  if (!n || json[n - 1] != '\n') putchar('\n');
}

static const char *jstr(const cJSON *o, const char *k) {
  const char *s = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, k));
  return s ? s : "";
}

static double jnum(const cJSON *o, const char *k) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, k);
  return cJSON_IsNumber(v) ? v->valuedouble : 0;
}

/* Strings of a JSON array joined by sep into buf. */
static void join_strings(const cJSON *arr, const char *sep, char *buf, size_t n) {
  size_t used = 0;
  buf[0] = '\0';
  const cJSON *it;
  cJSON_ArrayForEach(it, arr) {
    const char *s = cJSON_GetStringValue(it);
    if (!s) continue;
    int w = snprintf(buf + used, n - used, "%s%s", used ? sep : "", s);
    if (w < 0 || (size_t)w >= n - used) break;
    used += (size_t)w;
  }
}

static int parse_or_fail(const cli_ctx *ctx, const char *text, cJSON **out) {
  *out = cJSON_Parse(text);
  if (!*out) return cli_fail(ctx, CLI_SERVER, "the server's answer is not JSON");
  return 0;
}

int cmd_status(cli_ctx *ctx, const cmdline_args *a) {
  (void)a;
  char *info = NULL;
  rsw_status s = rsw_server_info(ctx->client, &info);
  if (s) return cli_report(ctx, s, "GET /v1");
  rsw_status ready = rsw_server_ready(ctx->client);
  int rc = CLI_OK;
  if (ctx->json) {
    print_raw(info);
  } else {
    cJSON *j;
    if ((rc = parse_or_fail(ctx, info, &j))) goto out;
    char variants[128];
    join_strings(cJSON_GetObjectItemCaseSensitive(j, "variants"), ", ", variants, sizeof variants);
    const cJSON *lim = cJSON_GetObjectItemCaseSensitive(j, "limits");
    printf("server:    %s\n", ctx->server_url);
    printf("daemon:    %s %s (%s)\n", jstr(j, "name"), jstr(j, "version"), jstr(j, "build"));
    printf("api:       %s\n", jstr(j, "api_version"));
    printf("variants:  %s\n", variants);
    printf("plugins:   %d\n", cJSON_GetArraySize(cJSON_GetObjectItemCaseSensitive(j, "plugins")));
    printf("ready:     %s\n", ready == RSW_OK ? "yes" : "no");
    if (lim)
      printf("limits:    body %.0f B, queue %.0f jobs, %.0f pixel samples, results kept %.0f s\n",
             jnum(lim, "max_body_bytes"), jnum(lim, "max_queue"), jnum(lim, "max_pixel_samples"),
             jnum(lim, "result_ttl_s"));
    cJSON_Delete(j);
  }
  /* The daemon answered GET /v1 but is not ready (shutting down): say so. */
  if (ready != RSW_OK && !ctx->json) rc = cli_report(ctx, ready, "GET /v1/health/ready");
out:
  rsw_free(info);
  return rc;
}

int cmd_scene_push(cli_ctx *ctx, const cmdline_args *a) {
  const char *variant = cmdline_get(a, "--variant");
  static const char *const known[] = {"mono", "rgb", "mono_polarized", "rgb_polarized"};
  bool ok = !variant;
  for (size_t i = 0; variant && i < sizeof known / sizeof known[0]; i++) ok |= strcmp(variant, known[i]) == 0;
  if (!ok)
    return cli_usage(ctx, "--variant needs mono, rgb, mono_polarized or rgb_polarized (got '%s')", variant);
  char id[65];
  int created = 0;
  rsw_status s = rsw_scene_push_file(ctx->client, a->pos[0], variant, id, &created);
  if (s) return cli_report(ctx, s, a->pos[0]);
  if (ctx->json)
    printf("{\"id\":\"%s\",\"created\":%s}\n", id, created ? "true" : "false");
  else
    printf("%s\n", id);
  if (!ctx->quiet && !ctx->json)
    fprintf(stderr, "raysweep scene push: %s %s\n", a->pos[0], created ? "loaded" : "was already resident");
  return CLI_OK;
}

int cmd_scene_ls(cli_ctx *ctx, const cmdline_args *a) {
  (void)a;
  char *text = NULL;
  rsw_status s = rsw_scene_list(ctx->client, &text);
  if (s) return cli_report(ctx, s, "GET /v1/scenes");
  int rc = CLI_OK;
  if (ctx->json) {
    print_raw(text);
  } else {
    cJSON *j;
    if (!(rc = parse_or_fail(ctx, text, &j))) {
      const cJSON *sc;
      cJSON_ArrayForEach(sc, cJSON_GetObjectItemCaseSensitive(j, "scenes")) {
        char sensors[256];
        join_strings(cJSON_GetObjectItemCaseSensitive(sc, "sensors"), ",", sensors, sizeof sensors);
        printf("%s  %-4s  rev %-4.0f  params %-5.0f  jobs %-3.0f  sensors %s\n", jstr(sc, "id"),
               jstr(sc, "variant"), jnum(sc, "revision"), jnum(sc, "params"), jnum(sc, "jobs_active"),
               sensors);
      }
      cJSON_Delete(j);
    }
  }
  rsw_free(text);
  return rc;
}

int cmd_scene_show(cli_ctx *ctx, const cmdline_args *a) {
  char *text = NULL;
  rsw_status s = rsw_scene_info(ctx->client, a->pos[0], &text);
  if (s) return cli_report(ctx, s, a->pos[0]);
  int rc = CLI_OK;
  if (ctx->json) {
    print_raw(text);
  } else {
    cJSON *j;
    if (!(rc = parse_or_fail(ctx, text, &j))) {
      char sensors[512];
      join_strings(cJSON_GetObjectItemCaseSensitive(j, "sensors"), ", ", sensors, sizeof sensors);
      printf("id:             %s\n", jstr(j, "id"));
      printf("variant:        %s\n", jstr(j, "variant"));
      printf("revision:       %.0f\n", jnum(j, "revision"));
      printf("sensors:        %s\n", sensors);
      printf("shapes:         %.0f\n", jnum(j, "shapes"));
      printf("emitters:       %.0f\n", jnum(j, "emitters"));
      printf("params:         %.0f\n", jnum(j, "params"));
      printf("resident bytes: %.0f\n", jnum(j, "resident_bytes"));
      printf("load seconds:   %.4f\n", jnum(j, "load_seconds"));
      printf("created:        %s\n", jstr(j, "created"));
      printf("active jobs:    %.0f\n", jnum(j, "jobs_active"));
      cJSON_Delete(j);
    }
  }
  rsw_free(text);
  return rc;
}

int cmd_scene_rm(cli_ctx *ctx, const cmdline_args *a) {
  rsw_status s = rsw_scene_delete(ctx->client, a->pos[0], cmdline_has(a, "--force"));
  if (s) {
    int rc = cli_report(ctx, s, a->pos[0]);
    const rsw_error_info *e = rsw_client_last_error(ctx->client);
    /* The daemon's hint names its API (?force=true); say it in CLI terms. */
    if (e && e->http_status == 409)
      fprintf(stderr,
              "  (cancel those jobs with `raysweep job cancel JOB` (see `raysweep job ls`), or unload "
              "anyway with `raysweep scene rm %s --force`, which cancels them first)\n",
              a->pos[0]);
    return rc;
  }
  if (ctx->json)
    printf("{\"deleted\":\"%s\"}\n", a->pos[0]);
  else if (!ctx->quiet)
    fprintf(stderr, "raysweep scene rm: %s unloaded\n", a->pos[0]);
  return CLI_OK;
}

int cmd_scene_reset(cli_ctx *ctx, const cmdline_args *a) {
  char *text = NULL;
  rsw_status s = rsw_scene_reset(ctx->client, a->pos[0], &text);
  if (s) return cli_report(ctx, s, a->pos[0]);
  int rc = CLI_OK;
  cJSON *j;
  if (ctx->json) {
    print_raw(text);
  } else if (!(rc = parse_or_fail(ctx, text, &j))) {
    char keys[1024];
    join_strings(cJSON_GetObjectItemCaseSensitive(j, "keys"), ", ", keys, sizeof keys);
    printf("%s: %s, revision %.0f\n", jstr(j, "id"), keys[0] ? keys : "already in its document's state",
           jnum(j, "revision"));
    if (!ctx->quiet && keys[0])
      fprintf(stderr, "raysweep scene reset: %s is back to its document's state (the keys above)\n",
              a->pos[0]);
    cJSON_Delete(j);
  }
  rsw_free(text);
  return rc;
}

int cmd_scene_copy(cli_ctx *ctx, const cmdline_args *a) {
  char id[65];
  char *text = NULL;
  rsw_status s = rsw_scene_copy(ctx->client, a->pos[0], id, &text);
  if (s) return cli_report(ctx, s, a->pos[0]);
  if (ctx->json)
    print_raw(text);
  else
    printf("%s\n", id);
  if (!ctx->quiet && !ctx->json) fprintf(stderr, "raysweep scene copy: %s copied to %s\n", a->pos[0], id);
  rsw_free(text);
  return CLI_OK;
}

int cmd_params(cli_ctx *ctx, const cmdline_args *a) {
  const char *cls = cmdline_get(a, "--class");
  if (cls && strcmp(cls, "spectral") != 0 && strcmp(cls, "geometric") != 0 && strcmp(cls, "none") != 0)
    return cli_usage(ctx, "--class needs spectral, geometric or none (got '%s')", cls);
  char *text = NULL;
  uint64_t rev = 0;
  rsw_status s = (cmdline_has(a, "--full") ? rsw_params_get_full : rsw_params_get)(
      ctx->client, a->pos[0], cmdline_get(a, "--match"), cls, &text, &rev);
  if (s) return cli_report(ctx, s, a->pos[0]);
  int rc = CLI_OK;
  if (ctx->json) {
    print_raw(text);
  } else {
    cJSON *j;
    if (!(rc = parse_or_fail(ctx, text, &j))) {
      const cJSON *p;
      cJSON_ArrayForEach(p, cJSON_GetObjectItemCaseSensitive(j, "params")) {
        char shape[48] = "", aliases[256];
        const cJSON *d;
        size_t used = 0;
        cJSON_ArrayForEach(d, cJSON_GetObjectItemCaseSensitive(p, "shape")) {
          used += (size_t)snprintf(shape + used, sizeof shape - used, "%s%d", used ? "x" : "", d->valueint);
          if (used >= sizeof shape) break;
        }
        join_strings(cJSON_GetObjectItemCaseSensitive(p, "aliases"), ", ", aliases, sizeof aliases);
        char *value = cJSON_PrintUnformatted(cJSON_GetObjectItemCaseSensitive(p, "value"));
        printf("%-48s %-9s %-9s %-7s %s%s%s%s\n", jstr(p, "key"), jstr(p, "type"), jstr(p, "class"), shape,
               value ? value : "?", aliases[0] ? "  (alias: " : "", aliases, aliases[0] ? ")" : "");
        free(value);
      }
      if (!ctx->quiet) fprintf(stderr, "raysweep params: revision %" PRIu64 "\n", rev);
      cJSON_Delete(j);
    }
  }
  rsw_free(text);
  return rc;
}

int cli_build_param_map(const cli_ctx *ctx, const char *opt, const char *const *sets, size_t n, cJSON **out) {
  cJSON *map = cJSON_CreateObject();
  if (!map) return cli_fail(ctx, CLI_IO, "out of memory");
  for (size_t i = 0; i < n; i++) {
    char *key;
    const char *val;
    int rc = cli_split_set(ctx, opt, sets[i], &key, &val);
    if (rc) {
      cJSON_Delete(map);
      return rc;
    }
    cJSON *v = cJSON_Parse(val);
    if (!v) {
      rc = cli_usage(ctx, "%s %s: the value '%s' is not JSON (quote strings: '\"text\"')", opt, key, val);
    } else if (cJSON_GetObjectItemCaseSensitive(map, key)) {
      cJSON_Delete(v);
      rc = cli_usage(ctx, "%s: '%s' is set twice", opt, key);
    } else {
      cJSON_AddItemToObject(map, key, v);
    }
    free(key);
    if (rc) {
      cJSON_Delete(map);
      return rc;
    }
  }
  *out = map;
  return 0;
}

/* The value of key before the update, as compact JSON (owned: free), or
 * NULL when it cannot be read (the PATCH then reports why). */
static char *param_value_now(cli_ctx *ctx, const char *id, const char *key) {
  char *json = NULL;
  if (rsw_params_get(ctx->client, id, key, NULL, &json, NULL)) return NULL;
  cJSON *doc = cJSON_Parse(json);
  rsw_free(json);
  char *text = NULL;
  const cJSON *p;
  cJSON_ArrayForEach(p, cJSON_GetObjectItemCaseSensitive(doc, "params")) {
    const cJSON *k = cJSON_GetObjectItemCaseSensitive(p, "key");
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(p, "value");
    if (cJSON_IsString(k) && strcmp(k->valuestring, key) == 0 && v) {
      text = cJSON_PrintUnformatted(v);
      break;
    }
  }
  cJSON_Delete(doc);
  return text;
}

/* A value for a line of `set`'s report: long ones (meshes) are cut. */
static void print_value(const char *text) {
  enum {
    MAX = 80
  };
  if (!text)
    fputs("?", stdout);
  else if (strlen(text) > MAX)
    printf("%.*s...", MAX, text);
  else
    fputs(text, stdout);
}

/* Prints each key with its value before and after, then the revision
 * ("revision N"); --json: {"revision": N, "changes": [{key, old, new}]}. */
int cmd_set(cli_ctx *ctx, const cmdline_args *a) {
  int64_t if_match = -1;
  const char *im = cmdline_get(a, "--if-match");
  if (im) {
    unsigned long long v;
    if (!cli_parse_u64(im, INT64_MAX, &v))
      return cli_usage(ctx, "--if-match needs a revision number (got '%s')", im);
    if_match = (int64_t)v;
  }
  cJSON *map;
  int rc = cli_build_param_map(ctx, "set", a->pos + 1, a->n_pos - 1, &map);
  if (rc) return rc;
  int n = cJSON_GetArraySize(map);
  char **old = calloc((size_t)n + 1, sizeof *old);
  char *text = old ? cJSON_PrintUnformatted(map) : NULL;
  if (!text) {
    free(old);
    cJSON_Delete(map);
    return cli_fail(ctx, CLI_IO, "out of memory");
  }
  int i = 0;
  const cJSON *e;
  cJSON_ArrayForEach(e, map) old[i++] = param_value_now(ctx, a->pos[0], e->string);
  uint64_t rev = 0;
  rsw_status s = rsw_params_update(ctx->client, a->pos[0], text, if_match, &rev);
  free(text);
  if (s) {
    rc = cli_report(ctx, s, a->pos[0]);
  } else if (ctx->json) {
    printf("{\"revision\":%" PRIu64 ",\"changes\":[", rev);
    i = 0;
    cJSON_ArrayForEach(e, map) {
      char *nv = cJSON_PrintUnformatted(e);
      cJSON *ks = cJSON_CreateString(e->string);
      char *k = ks ? cJSON_PrintUnformatted(ks) : NULL; /* quoted, escaped */
      cJSON_Delete(ks);
      printf("%s{\"key\":%s,\"old\":%s,\"new\":%s}", i ? "," : "", k ? k : "null", old[i] ? old[i] : "null",
             nv ? nv : "null");
      free(nv);
      free(k);
      i++;
    }
    printf("]}\n");
    rc = CLI_OK;
  } else {
    i = 0;
    cJSON_ArrayForEach(e, map) {
      char *nv = cJSON_PrintUnformatted(e);
      printf("%s: ", e->string);
      print_value(old[i]);
      fputs(" -> ", stdout);
      print_value(nv);
      putchar('\n');
      free(nv);
      i++;
    }
    printf("revision %" PRIu64 "\n", rev);
    rc = CLI_OK;
  }
  for (i = 0; i < n; i++) free(old[i]);
  free(old);
  cJSON_Delete(map);
  return rc;
}
