/* raysweep render (one synchronous render, of a resident scene or a scene
 * file pushed first) and fetch (one film of a job). */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#include "cli.h"
#include "film_io.h"

const cmdline_opt cli_opts_render[] = {
    {"--sensor", "S", false, "sensor id or index (default: the first)"},
    {"--spp", "N", false, "samples per pixel (default: the scene's sampler)"},
    {"--seed", "N", false, "sampler seed (default 0)"},
    {"--wavelength", "NM", false, "wavelength in nm (mono variant; default 550)"},
    {"--set", "KEY=VALUE", true, "parameter override for this render only (VALUE is JSON)"},
    {"--coord", "NAME=VALUE", true,
     "a coordinate the scene's (or --templates') templates render this render's overrides from, e.g. "
     "--coord sza=30 (docs/experiments.md#templates)"},
    {"--templates", "FILE.json|-|JSON", false,
     "templates for this render, {KEY: template}: a file, - or the JSON"},
    {"--timeout", "S", false, "seconds the server may spend (exit 5 past it)"},
    {"--quantities", "LIST", false, "comma-separated, of radiance, brdf, brf: adds brdf and brf channels"},
    {"--variance", NULL, false, "adds radiance_stderr channels (standard error of each pixel's mean)"},
    {"--exposure", "EV|auto[+-EV]", false,
     "PNG: linear radiance times 2^EV, clamped to [0,1], sRGB (default 0); auto: the 99.5th percentile to "
     "white"},
    {"--colormap", "MAP", false, "PNG of a one-channel film: gray (default), viridis or inferno"},
    {"-o", "FILE", false, "output file: .exr, .npy, .json (the film JSON) or .png (a quick-look)"},
    {NULL},
};
const cmdline_opt cli_opts_fetch[] = {
    {"--exposure", "EV|auto[+-EV]", false,
     "PNG: linear radiance times 2^EV, clamped to [0,1], sRGB (default 0); auto: the 99.5th percentile to "
     "white"},
    {"--colormap", "MAP", false, "PNG of a one-channel film: gray (default), viridis or inferno"},
    {"-o", "FILE", false,
     "output file: .exr, .npy, .json (the film JSON) or .png (a quick-look); .nc: the whole job as one "
     "NetCDF-4 dataset (give JOB alone)"},
    {"--format", "exr|npy|json|nc", false, "the format, whatever FILE's extension"},
    {"--partial", NULL, false, "nc: the dataset of a job still running (films not there yet are NaN)"},
    {NULL},
};

/* The PNG quick-look's options (-o OUT.png), or a usage error. */
typedef struct png_out {
  bool png;
  const char *exposure; /* as given: checked by png_exposure_parse's rules */
  const char *colormap;
} png_out;

static bool ends_png(const char *path) {
  size_t n = strlen(path);
  return n > 4 && strcasecmp(path + n - 4, ".png") == 0;
}

static int output_format(const cli_ctx *ctx, const cmdline_args *a, const char *out, cli_format *fmt,
                         png_out *po) {
  if (!out) return cli_usage(ctx, "missing -o OUT.exr|.npy|.json|.png");
  memset(po, 0, sizeof *po);
  po->png = ends_png(out);
  const char *v;
  if ((v = cmdline_get(a, "--exposure"))) {
    double ev = 0;
    const char *num = strncmp(v, "auto", 4) == 0 && (v[4] == '+' || v[4] == '-') ? v + 4 : v;
    if (strcmp(v, "auto") != 0 && (!cli_parse_double(num, &ev) || fabs(ev) > 1000))
      return cli_usage(ctx, "--exposure needs a number of stops, auto, or auto+EV (got '%s')", v);
    po->exposure = v;
  }
  if ((v = cmdline_get(a, "--colormap"))) {
    if (strcmp(v, "gray") && strcmp(v, "viridis") && strcmp(v, "inferno"))
      return cli_usage(ctx, "--colormap needs gray, viridis or inferno (got '%s')", v);
    po->colormap = v;
  }
  if (!po->png && (cmdline_get(a, "--exposure") || cmdline_get(a, "--colormap")))
    return cli_usage(ctx, "--exposure and --colormap are for a PNG output (-o OUT.png)");
  if (po->png) {
    *fmt = CLI_FMT_NONE;
    return 0;
  }
  *fmt = cli_format_from_path(out);
  if (*fmt == CLI_FMT_NONE)
    return cli_usage(ctx, "-o '%s': the format is chosen by extension: .exr, .npy, .json or .png", out);
  return 0;
}

static int save(const cli_ctx *ctx, const rsw_film *f, const char *out, cli_format fmt, const png_out *po) {
  if (!po->png) return cli_save_film(ctx, f, out, fmt);
  rsw_status s = rsw_film_save_png(f, out, po->exposure, po->colormap);
  if (s == RSW_ERR_INVALID)
    return cli_usage(ctx,
                     "cannot make a PNG of this film: --colormap is for one-channel films (this one has %d)",
                     rsw_film_channels(f));
  if (s) return cli_fail(ctx, CLI_IO, "cannot write '%s': %s", out, rsw_strerror(s));
  return CLI_OK;
}

static void report_written(const cli_ctx *ctx, const rsw_film *f, const char *path, double seconds) {
  /* A warning, not progress: printed even with --quiet. */
  cJSON *m = cJSON_Parse(rsw_film_meta(f));
  const cJSON *u = cJSON_GetObjectItemCaseSensitive(m, "unresolved_rays");
  if (cJSON_IsNumber(u) && u->valuedouble > 0)
    fprintf(stderr, "raysweep %s: warning: %.0f rays of %s " UNRESOLVED_WHY "\n", ctx->cmd, u->valuedouble,
            path);
  const cJSON *pf = cJSON_GetObjectItemCaseSensitive(m, "plugin_failures");
  const cJSON *pm = cJSON_GetObjectItemCaseSensitive(m, "plugin_failure");
  if (cJSON_IsNumber(pf) && pf->valuedouble > 0)
    fprintf(stderr,
            "raysweep %s: warning: %.0f environment plugin answers in %s were replaced by black; first: %s\n",
            ctx->cmd, pf->valuedouble, path, cJSON_IsString(pm) ? pm->valuestring : "(no message)");
  cJSON_Delete(m);
  if (ctx->json) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "file", path);
    cJSON_AddNumberToObject(o, "width", rsw_film_width(f));
    cJSON_AddNumberToObject(o, "height", rsw_film_height(f));
    cJSON *ch = cJSON_AddArrayToObject(o, "channels");
    for (int i = 0; i < rsw_film_channels(f); i++)
      cJSON_AddItemToArray(ch, cJSON_CreateString(rsw_film_channel_name(f, i)));
    cJSON *meta = cJSON_Parse(rsw_film_meta(f));
    if (meta) cJSON_AddItemToObject(o, "meta", meta);
    cJSON_AddNumberToObject(o, "seconds", seconds);
    cli_print_json(o);
  } else if (!ctx->quiet) {
    fprintf(stderr, "raysweep %s: wrote %s (%dx%d, %d channel%s, %.3f s)\n", ctx->cmd, path,
            rsw_film_width(f), rsw_film_height(f), rsw_film_channels(f), rsw_film_channels(f) == 1 ? "" : "s",
            seconds);
  }
}

int cmd_render(cli_ctx *ctx, const cmdline_args *a) {
  const char *out = cmdline_get(a, "-o");
  cli_format fmt;
  png_out po;
  int rc = output_format(ctx, a, out, &fmt, &po);
  if (rc) return rc;
  cJSON *req = cJSON_CreateObject();
  if (!req) return cli_fail(ctx, CLI_IO, "out of memory");
  const char *v;
  unsigned long long u;
  double d;
  if ((v = cmdline_get(a, "--sensor"))) {
    if (!*v) {
      rc = cli_usage(ctx, "--sensor needs a sensor id or index");
      goto out;
    }
    cJSON_AddStringToObject(req, "sensor", v);
  }
  if ((v = cmdline_get(a, "--spp"))) {
    if (!cli_parse_u64(v, 1ull << 31, &u) || u == 0) {
      rc = cli_usage(ctx, "--spp needs a positive integer (got '%s')", v);
      goto out;
    }
    cJSON_AddNumberToObject(req, "spp", (double)u);
  }
  if ((v = cmdline_get(a, "--seed"))) {
    /* JSON numbers are doubles on the wire: seeds stay below 2^53. */
    if (!cli_parse_u64(v, (1ull << 53) - 1, &u)) {
      rc = cli_usage(ctx, "--seed needs an integer in [0, 2^53) (got '%s')", v);
      goto out;
    }
    cJSON_AddNumberToObject(req, "seed", (double)u);
  }
  if ((v = cmdline_get(a, "--wavelength"))) {
    if (!cli_parse_double(v, &d) || !(d > 0)) {
      rc = cli_usage(ctx, "--wavelength needs a positive number of nm (got '%s')", v);
      goto out;
    }
    cJSON_AddNumberToObject(req, "wavelength", d);
  }
  if ((v = cmdline_get(a, "--timeout"))) {
    if (!cli_parse_double(v, &d) || !(d > 0)) {
      rc = cli_usage(ctx, "--timeout needs a positive number of seconds (got '%s')", v);
      goto out;
    }
    cJSON_AddNumberToObject(req, "timeout_s", d);
  }
  if ((v = cmdline_get(a, "--quantities"))) {
    cJSON *q = cJSON_AddArrayToObject(req, "quantities");
    char list[256];
    snprintf(list, sizeof list, "%s", v);
    for (char *save = NULL, *t = strtok_r(list, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
      if (strcmp(t, "radiance") && strcmp(t, "brdf") && strcmp(t, "brf")) {
        rc = cli_usage(ctx, "--quantities: unknown quantity '%s' (one of radiance, brdf, brf)", t);
        goto out;
      }
      cJSON_AddItemToArray(q, cJSON_CreateString(t));
    }
    if (!q->child) {
      rc = cli_usage(ctx, "--quantities needs a comma-separated list of radiance, brdf, brf");
      goto out;
    }
  }
  if (cmdline_get(a, "--variance")) cJSON_AddBoolToObject(req, "variance", true);
  size_t n_sets;
  const char *const *sets = cmdline_get_all(a, "--set", &n_sets);
  if (n_sets) {
    cJSON *map;
    if ((rc = cli_build_param_map(ctx, "--set", sets, n_sets, &map))) goto out;
    cJSON_AddItemToObject(req, "params", map);
  }
  size_t n_coords;
  const char *const *coords = cmdline_get_all(a, "--coord", &n_coords);
  cJSON *co = n_coords ? cJSON_AddObjectToObject(req, "coords") : NULL;
  for (size_t i = 0; i < n_coords; i++) {
    const char *eq = strchr(coords[i], '=');
    if (!eq || eq == coords[i] || !cli_parse_double(eq + 1, &d)) {
      rc = cli_usage(ctx, "--coord needs NAME=NUMBER (got '%s')", coords[i]);
      goto out;
    }
    char name[72];
    snprintf(name, sizeof name, "%.*s", (int)(eq - coords[i] < 64 ? eq - coords[i] : 64), coords[i]);
    if (cJSON_GetObjectItemCaseSensitive(co, name)) {
      rc = cli_usage(ctx, "--coord %s given twice", name);
      goto out;
    }
    cJSON_AddNumberToObject(co, name, d);
  }
  if ((v = cmdline_get(a, "--templates"))) {
    cJSON *t;
    if ((rc = cli_json_option(ctx, "--templates", v, &t))) goto out;
    if (!cJSON_IsObject(t)) {
      cJSON_Delete(t);
      rc = cli_usage(ctx, "--templates: a JSON object {KEY: template} (docs/experiments.md#templates)");
      goto out;
    }
    cJSON_AddItemToObject(req, "templates", t);
  }
  char *text = cJSON_PrintUnformatted(req);
  if (!text) {
    rc = cli_fail(ctx, CLI_IO, "out of memory");
    goto out;
  }
  /* A scene FILE: pushed (with the files it references), then rendered by
   * its id, as sweep does. */
  const char *scene = a->pos[0];
  char scene_id[65] = "";
  struct stat sst;
  if (stat(scene, &sst) == 0 && S_ISREG(sst.st_mode)) {
    int created = 0;
    rsw_status ps = rsw_scene_push_file(ctx->client, scene, NULL, scene_id, &created);
    if (ps) {
      free(text);
      rc = cli_report(ctx, ps, scene);
      goto out;
    }
    scene = scene_id;
  }
  rsw_film *film = NULL;
  double t0 = cli_now();
  cli_catch_interrupt();
  rsw_status s = rsw_render(ctx->client, scene, text, &film);
  double seconds = cli_now() - t0;
  free(text);
  if (s && cli_interrupted) {
    /* The request is dropped, which closes the connection: the daemon
     * stops a synchronous render whose client went away. */
    rc = cli_fail(ctx, cli_interrupted_code(),
                  "%s; the render request was dropped and the daemon stops the render",
                  cli_interrupted_word());
    goto out;
  }
  if (s) {
    rc = cli_report(ctx, s, a->pos[0]);
    goto out;
  }
  rc = save(ctx, film, out, fmt, &po);
  if (!rc) report_written(ctx, film, out, seconds);
  rsw_film_free(film);
out:
  cJSON_Delete(req);
  return rc;
}

/* fetch JOB -o F.nc: the job's dataset (GET /v1/jobs/{id}/dataset). */
static int fetch_dataset(cli_ctx *ctx, const cmdline_args *a, const char *out) {
  if (a->n_pos != 1)
    return cli_usage(ctx, "a dataset (.nc) is the whole job: give JOB alone, without CONTEXT SENSOR");
  rsw_status s = rsw_job_fetch_dataset(ctx->client, a->pos[0], cmdline_has(a, "--partial"), out);
  if (s) return cli_report(ctx, s, a->pos[0]);
  if (ctx->json) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "file", out);
    cJSON_AddStringToObject(o, "job", a->pos[0]);
    cli_print_json(o);
  } else if (!ctx->quiet)
    fprintf(stderr, "raysweep fetch: dataset of %s written to %s\n", a->pos[0], out);
  return CLI_OK;
}

int cmd_fetch(cli_ctx *ctx, const cmdline_args *a) {
  const char *out = cmdline_get(a, "-o"), *v = cmdline_get(a, "--format");
  if (!out) return cli_usage(ctx, "missing -o FILE.exr|.npy|.json|.png|.nc");
  cli_format fmt;
  png_out po;
  memset(&po, 0, sizeof po);
  int rc = 0;
  if (v) {
    if (strcmp(v, "nc") == 0) return fetch_dataset(ctx, a, out);
    if ((fmt = cli_format_from_name(v)) == CLI_FMT_NONE)
      return cli_usage(ctx, "--format needs exr, npy, json or nc (got '%s')", v);
    if (cmdline_get(a, "--exposure") || cmdline_get(a, "--colormap"))
      return cli_usage(ctx, "--exposure and --colormap are for a PNG output (-o OUT.png, no --format)");
  } else {
    const char *dot = strrchr(out, '.');
    if (dot && strcmp(dot, ".nc") == 0 && !strchr(dot, '/')) return fetch_dataset(ctx, a, out);
    if ((rc = output_format(ctx, a, out, &fmt, &po))) return rc;
  }
  if (cmdline_has(a, "--partial")) return cli_usage(ctx, "--partial applies to a dataset (-o FILE.nc)");
  if (a->n_pos != 3)
    return cli_usage(ctx, "one film needs JOB CONTEXT SENSOR (or -o FILE.nc for the dataset)");
  rsw_film *film = NULL;
  double t0 = cli_now();
  rsw_status s = rsw_job_fetch(ctx->client, a->pos[0], a->pos[1], a->pos[2], &film);
  if (s) {
    char what[256];
    snprintf(what, sizeof what, "%s %s %s", a->pos[0], a->pos[1], a->pos[2]);
    return cli_report(ctx, s, what);
  }
  rc = save(ctx, film, out, fmt, &po);
  if (!rc) report_written(ctx, film, out, cli_now() - t0);
  rsw_film_free(film);
  return rc;
}
