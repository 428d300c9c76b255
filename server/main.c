/* raysweepd: the radiometric computation daemon.
 *
 *   raysweepd render | params | serve | routes | version   (see `commands`)
 *
 * Subcommands are a const table (redis' command table); each row holds its
 * usage line and help text, which `raysweepd COMMAND --help`, the usage
 * blocks of the docs/ pages and docs/man/raysweepd.1 must agree with
 * (tests/integration/test_usage.sh compares them). Bad input exits
 * non-zero with a message naming the flag, file or document place. */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "cmdline.h"
#include "film_io.h"
#include "http/encode.h"
#include "image_exr.h"
#include "image_png.h"
#include "kernel/core/isa.h"
#include "kernel/extplugin/env_plugin.h"
#include "kernel/render.h"
#include "kernel/scene/param_table.h"
#include "kernel/scene/params.h"
#include "kernel/scene/scene.h"
#include "kernel/scene/update.h"
#include "raysweep/status.h"
#include "raysweep/version.h"
#include "rsw_file.h"
#include "serve.h"
#include "service/templates.h"

#define MAX_DEFINES 256
#define MAX_SETS    1024

typedef struct command {
  const char *name;
  const char *usage;   /* after "raysweepd ", one line (wrapped when printed) */
  const char *summary; /* one line */
  const char *help;    /* the options, one "  FLAG  what" per line, or "" */
  int (*run)(int argc, char **argv);
} command;

static int usage_error(const char *cmd, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static int usage_error(const char *cmd, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, "raysweepd %s: ", cmd);
  vfprintf(stderr, fmt, ap);
  fputc('\n', stderr);
  va_end(ap);
  return 2;
}

static bool parse_u64(const char *s, unsigned long long max, unsigned long long *out) {
  if (!s || !*s || *s == '-' || *s == '+') return false;
  char *end;
  errno = 0;
  unsigned long long v = strtoull(s, &end, 10);
  if (errno || *end || v > max) return false;
  *out = v;
  return true;
}

static bool parse_pos_double(const char *s, double *out) {
  if (!s || !*s) return false;
  char *end;
  errno = 0;
  double v = strtod(s, &end);
  if (errno || *end || !(v > 0) || !isfinite(v)) return false;
  *out = v;
  return true;
}

/* A finite number, the whole of s. */
static bool parse_double(const char *s, double *out) {
  if (!s || !*s) return false;
  char *end;
  errno = 0;
  double v = strtod(s, &end);
  if (errno || *end || !isfinite(v)) return false;
  *out = v;
  return true;
}

static int apply_sets(const char *cmd, const char *what, scene *sc, const char *const *sets, size_t n);
struct render_req;
static int apply_coords(const struct render_req *r, const char *scene_path, scene *sc);

/* A command's option values, one at a time, in table order: o is the
 * option, typed the name as the user wrote it, val its value (NULL: the
 * command line ended before it). Returns 0, or the exit status after the
 * message. */
typedef int (*opt_value_fn)(void *req, const cmdline_opt *o, const char *typed, const char *val);

/* argv[1..] against opts (common/cmdline.h, as the client reads its
 * command lines): positionals into a->pos, every option value through
 * value(). Returns 0, or the exit status after the message. */
static int parse_command(const char *cmd, const cmdline_opt *opts, int argc, char **argv, cmdline_args *a,
                         opt_value_fn value, void *req) {
  cmdline_error e;
  switch (cmdline_parse(opts, argc - 1, argv + 1, a, &e)) {
  case CMDLINE_OK: break;
  case CMDLINE_UNKNOWN:
  case CMDLINE_NO_VALUE: return usage_error(cmd, "unknown option '%s'", e.word);
  case CMDLINE_NEEDS_VALUE: {
    int rc = value(req, e.opt, e.word, NULL);
    return rc ? rc : usage_error(cmd, "%s needs a value", e.word);
  }
  case CMDLINE_NOMEM: fprintf(stderr, "raysweepd %s: out of memory\n", cmd); return 1;
  }
  for (size_t i = 0; i < a->n_opts; i++)
    for (size_t k = 0; k < a->n_vals[i]; k++) {
      int rc = value(req, &opts[i], opts[i].name, a->vals[i][k]);
      if (rc) return rc;
    }
  return 0;
}

/* -D name=value: append to defines (the name is malloc'ed). Returns NULL,
 * or why it was refused. */
static const char *add_define(scene_define *defines, size_t *n, const char *def) {
  const char *eq = def ? strchr(def, '=') : NULL;
  if (!def || !eq || eq == def) return "-D needs name=value";
  if (*n == MAX_DEFINES) return "too many -D definitions";
  char *name = strndup(def, (size_t)(eq - def));
  if (!name) return "out of memory";
  defines[*n].name = name;
  defines[*n].value = eq + 1;
  (*n)++;
  return NULL;
}

/* What -o writes, from its name's ending (any case). */
typedef enum {
  OUT_UNKNOWN,
  OUT_EXR,
  OUT_PNG,
  OUT_NPY,
  OUT_JSON
} out_format;

static out_format out_format_of(const char *path) {
  static const struct {
    const char *ext;
    out_format fmt;
  } exts[] = {{".exr", OUT_EXR}, {".png", OUT_PNG}, {".npy", OUT_NPY}, {".json", OUT_JSON}};
  size_t n = strlen(path);
  for (size_t i = 0; i < sizeof exts / sizeof exts[0]; i++) {
    size_t el = strlen(exts[i].ext);
    if (n > el && strcasecmp(path + n - el, exts[i].ext) == 0) return exts[i].fmt;
  }
  return OUT_UNKNOWN;
}

/* The film as .npy or JSON, in the encodings of the HTTP API (http/encode.h:
 * the same bytes a render over the daemon returns, with an empty scene id,
 * revision 0 and no context, as no resident scene made it). */
static rsw_status write_film_encoded(out_format fmt, const film_image *img, const char *sensor_name,
                                     const char *path, rsw_err *err) {
  svc_film f = {.img = *img}; /* borrowed: never svc_film_free'd */
  snprintf(f.sensor, sizeof f.sensor, "%s", sensor_name);
  void *bytes = NULL;
  size_t len = 0;
  rsw_status s =
      fmt == OUT_NPY ? http_film_npy(&f, &bytes, &len, err) : http_film_json(&f, (char **)&bytes, &len, err);
  if (s) return s;
  bool ok = rsw_write_replace(path, bytes, len);
  int e = errno;
  free(bytes);
  return ok ? RSW_OK : rsw_fail(err, RSW_ERR_IO, path, "cannot write the film: %s", strerror(e));
}

/* raysweepd render's options (the help text: `commands` below). */
enum {
  R_OUT,
  R_OUTPUT,
  R_SENSOR,
  R_SPP,
  R_SEED,
  R_THREADS,
  R_ISA,
  R_WAVELENGTH,
  R_QUANTITIES,
  R_VARIANCE,
  R_EXPOSURE,
  R_COLORMAP,
  R_VARIANT,
  R_SET,
  R_PLUGIN_DIR,
  R_STATS,
  R_DEFINE,
  R_COORD,
  R_TEMPLATES
};
static const cmdline_opt render_cmd_opts[] = {
    [R_OUT] = {"-o", "OUT"},
    [R_OUTPUT] = {"--output", "OUT", CMDLINE_ALIAS},
    [R_SENSOR] = {"--sensor", "ID"},
    [R_SPP] = {"--spp", "N"},
    [R_SEED] = {"--seed", "S"},
    [R_THREADS] = {"--threads", "N"},
    [R_ISA] = {"--isa", "ISA"},
    [R_WAVELENGTH] = {"--wavelength", "NM"},
    [R_QUANTITIES] = {"--quantities", "LIST"},
    [R_VARIANCE] = {"--variance"},
    [R_EXPOSURE] = {"--exposure", "EV|auto[+-EV]"},
    [R_COLORMAP] = {"--colormap", "MAP"},
    [R_VARIANT] = {"--variant", "mono|rgb|mono_polarized|rgb_polarized"},
    [R_SET] = {"--set", "KEY=VALUE", CMDLINE_REPEAT},
    [R_PLUGIN_DIR] = {"--plugin-dir", "DIR"},
    [R_STATS] = {"--stats"},
    [R_DEFINE] = {"-D", "name=value", CMDLINE_REPEAT | CMDLINE_ATTACHED},
    [R_COORD] = {"--coord", "NAME=VALUE", CMDLINE_REPEAT},
    [R_TEMPLATES] = {"--templates", "FILE.json|-|JSON"},
    {NULL},
};

/* What raysweepd render was asked. */
typedef struct render_req render_req;
struct render_req {
  const char *out_path, *sensor_id, *variant_name, *plugin_dir;
  scene_define defines[MAX_DEFINES];
  size_t n_defines;
  const char *sets[MAX_SETS];
  size_t n_sets;
  const char *coords[MAX_SETS]; /* --coord NAME=VALUE */
  size_t n_coords;
  const char *templates; /* --templates: a file, - or the JSON */
  unsigned long long spp, seed, threads;
  double wavelength;
  unsigned quantities;
  bool variance, stats;
  png_look look;
};

static int render_value(void *req, const cmdline_opt *o, const char *typed, const char *val) {
  render_req *r = req;
  const char *v = val ? val : "";
  switch ((int)(o - render_cmd_opts)) {
  case R_OUT:
    if (!val) return usage_error("render", "%s needs a file name", typed);
    r->out_path = val;
    break;
  case R_SENSOR:
    if (!val) return usage_error("render", "%s needs a sensor id or index", typed);
    r->sensor_id = val;
    break;
  case R_SPP:
    if (!parse_u64(val, 1ull << 31, &r->spp) || r->spp == 0)
      return usage_error("render", "--spp needs a positive integer (got '%s')", v);
    break;
  case R_SEED:
    if (!parse_u64(val, ULLONG_MAX, &r->seed))
      return usage_error("render", "--seed needs a non-negative integer (got '%s')", v);
    break;
  case R_THREADS:
    if (!parse_u64(val, 256, &r->threads) || r->threads == 0)
      return usage_error("render", "--threads needs an integer in [1, 256] (got '%s')", v);
    break;
  case R_ISA: {
    rsw_isa isa;
    rsw_err ierr = {0};
    if (rsw_isa_parse(val, &isa, &ierr) != RSW_OK)
      return usage_error("render", "%s: %s", ierr.where, ierr.msg);
    rsw_isa_set(isa);
    break;
  }
  case R_WAVELENGTH:
    if (!parse_pos_double(val, &r->wavelength))
      return usage_error("render", "--wavelength needs a positive number of nm (got '%s')", v);
    break;
  case R_QUANTITIES: {
    if (!val || !*val)
      return usage_error("render", "--quantities needs a comma-separated list of %s", RENDER_QUANTITY_NAMES);
    char list[256];
    snprintf(list, sizeof list, "%s", val);
    for (char *save = NULL, *q = strtok_r(list, ",", &save); q; q = strtok_r(NULL, ",", &save)) {
      unsigned bit;
      if (!render_quantity_bit(q, &bit))
        return usage_error("render", "--quantities: unknown quantity '%s' (one of %s)", q,
                           RENDER_QUANTITY_NAMES);
      r->quantities |= bit;
    }
    break;
  }
  case R_VARIANCE: r->variance = true; break;
  case R_EXPOSURE:
    if (!png_exposure_parse(val, &r->look))
      return usage_error("render", "--exposure needs a number of stops, auto, or auto+EV (got '%s')", v);
    break;
  case R_COLORMAP:
    if (!val || !png_colormap_known(val))
      return usage_error("render", "--colormap needs one of %s (got '%s')", png_colormap_list(), v);
    r->look.colormap = val;
    break;
  case R_VARIANT:
    if (!val) return usage_error("render", "%s needs mono or rgb", typed);
    r->variant_name = val;
    break;
  case R_SET:
    if (!val || !strchr(val, '=') || val[0] == '=')
      return usage_error("render", "--set needs KEY=VALUE (got '%s')", v);
    if (r->n_sets == MAX_SETS) return usage_error("render", "too many --set (at most %d)", MAX_SETS);
    r->sets[r->n_sets++] = val;
    break;
  case R_COORD: {
    const char *eq = val ? strchr(val, '=') : NULL;
    double d;
    if (!eq || eq == val || !parse_double(eq + 1, &d))
      return usage_error("render", "--coord needs NAME=NUMBER (got '%s')", v);
    if (r->n_coords == MAX_SETS) return usage_error("render", "too many --coord (at most %d)", MAX_SETS);
    r->coords[r->n_coords++] = val;
    break;
  }
  case R_TEMPLATES:
    if (!val) return usage_error("render", "%s needs a file, - or the JSON", typed);
    r->templates = val;
    break;
  case R_PLUGIN_DIR:
    if (!val) return usage_error("render", "%s needs a directory", typed);
    r->plugin_dir = val;
    break;
  case R_STATS: r->stats = true; break;
  case R_DEFINE: {
    const char *why = add_define(r->defines, &r->n_defines, val);
    if (why) return usage_error("render", "%s (got '%s')", why, v);
    break;
  }
  }
  return 0;
}

static int cmd_render(int argc, char **argv) {
  render_req r = {0};
  cmdline_args args;
  int rc = 1;
  scene *sc = NULL;
  film_image img = {0};
  const char *scene_path = NULL;
  if ((rc = parse_command("render", render_cmd_opts, argc, argv, &args, render_value, &r))) goto out;
  rc = 1;
  if (args.n_pos > 1) {
    rc = usage_error("render", "unexpected argument '%s' (one scene file per render)", args.pos[1]);
    goto out;
  }
  scene_path = args.n_pos ? args.pos[0] : NULL;
  const char *out_path = r.out_path, *sensor_id = r.sensor_id;
  png_look look = r.look;
  if (!scene_path) {
    rc = usage_error("render", "missing the scene file%s", "");
    goto out;
  }
  if (!out_path) {
    rc = usage_error("render", "missing -o OUT.exr|OUT.npy|OUT.json|OUT.png%s", "");
    goto out;
  }
  out_format fmt = out_format_of(out_path);
  if (fmt == OUT_UNKNOWN) {
    rc = usage_error("render",
                     "-o %s: cannot write that kind of file (the name must end in .exr, .npy, .json or .png)",
                     out_path);
    goto out;
  }
  bool is_png = fmt == OUT_PNG;
  if (!is_png && (look.exposure != 0 || look.auto_exposure || look.colormap)) {
    rc = usage_error("render", "--exposure and --colormap are for a PNG output (-o OUT.png)%s", "");
    goto out;
  }
  rsw_err err = {0};
  char msg[1200];
  if (r.plugin_dir && plugins_load_dir(r.plugin_dir, &err)) {
    fprintf(stderr, "raysweepd render: %s\n", rsw_err_format(&err, msg, sizeof msg));
    goto out;
  }
  scene_load_opts lo = {
      .size = sizeof lo, .variant = r.variant_name, .defines = r.defines, .n_defines = r.n_defines};
  if (scene_load_file(scene_path, &lo, &sc, &err)) {
    fprintf(stderr, "raysweepd render: %s\n", rsw_err_format(&err, msg, sizeof msg));
    goto out;
  }
  if (r.n_sets && apply_sets("render", "--set", sc, r.sets, r.n_sets)) goto out;
  if ((r.n_coords || r.templates) && apply_coords(&r, scene_path, sc)) goto out;
  size_t sensor_index = 0;
  if (sensor_id) {
    if (!scene_find_sensor(sc, sensor_id, &sensor_index)) {
      fprintf(stderr, "raysweepd render: --sensor: no sensor '%s' in %s (", sensor_id, scene_path);
      for (size_t i = 0; i < sc->n_sensors; i++)
        fprintf(stderr, "%s%s", i ? ", " : "sensors: ", sc->sensors[i]->base.id);
      fprintf(stderr, "%s)\n", sc->n_sensors ? "" : "the scene has none");
      goto out;
    }
  }
  render_opts ro = {.size = sizeof ro,
                    .sensor = sensor_index,
                    .spp = (uint32_t)r.spp,
                    .seed = r.seed,
                    .wavelength = r.wavelength,
                    .threads = (int)r.threads,
                    .quantities = r.quantities,
                    .variance = r.variance};
  render_result_stats rs;
  if (render_sensor(sc, &ro, &img, &rs, &err)) {
    fprintf(stderr, "raysweepd render: %s\n", rsw_err_format(&err, msg, sizeof msg));
    goto out;
  }
  if (r.stats) {
    char line[600];
    render_stats_line(&rs, line, sizeof line);
    fprintf(stderr, "raysweepd render: stats: %s\n", line);
  }
  if (rs.invalid_samples)
    fprintf(stderr, "raysweepd render: warning: %llu samples were NaN or infinite and were dropped\n",
            (unsigned long long)rs.invalid_samples);
  if (rs.rays.unresolved)
    fprintf(stderr, "raysweepd render: warning: %llu rays " UNRESOLVED_WHY "\n",
            (unsigned long long)rs.rays.unresolved);
  if (img.plugin_failures)
    fprintf(stderr,
            "raysweepd render: warning: %llu environment plugin failures were replaced by black; first: %s\n",
            (unsigned long long)img.plugin_failures, img.plugin_failure);
  rsw_status ws;
  if (fmt == OUT_PNG)
    ws = png_write_film(out_path, img.width, img.height, img.channels, img.channel_names, img.data, &look,
                        &err);
  else if (fmt == OUT_EXR)
    ws = film_image_write_exr(&img, out_path, sc->sensors[sensor_index]->base.id, &err);
  else
    ws = write_film_encoded(fmt, &img, sc->sensors[sensor_index]->base.id, out_path, &err);
  if (ws) {
    fprintf(stderr, "raysweepd render: %s\n", rsw_err_format(&err, msg, sizeof msg));
    goto out;
  }
  fprintf(stderr, "raysweepd render: wrote %s (%dx%d, %u spp, %.3f s, %d threads)\n", out_path, img.width,
          img.height, img.spp, rs.wall_s, rs.threads);
  rc = 0;
out:
  film_image_free(&img);
  scene_free(sc);
  plugins_unload(); /* after the scene: its plugin emitters call into them */
  for (size_t i = 0; i < r.n_defines; i++) free((char *)r.defines[i].name);
  cmdline_free(&args);
  return rc;
}

/* Apply --set KEY=VALUE updates (VALUE is JSON) as one atomic update.
 * Returns non-zero after printing the error. */
static int apply_sets(const char *cmd, const char *what, scene *sc, const char *const *sets, size_t n) {
  param_update *items = calloc(n, sizeof *items);
  char **keys = calloc(n, sizeof *keys);
  rsw_err err = {0};
  char msg[1200];
  int rc = 0;
  if (!items || !keys) {
    fprintf(stderr, "raysweepd %s: out of memory\n", cmd);
    rc = 1;
  }
  size_t parsed = 0;
  for (size_t i = 0; i < n && !rc; i++) {
    const char *eq = strchr(sets[i], '=');
    keys[i] = strndup(sets[i], (size_t)(eq - sets[i]));
    if (!keys[i]) {
      rc = 1;
      break;
    }
    items[i].key = keys[i];
    if (param_value_parse(eq + 1, keys[i], &items[i].value, &err)) {
      fprintf(stderr, "raysweepd %s: %s %s\n", cmd, what, rsw_err_format(&err, msg, sizeof msg));
      rc = 1;
      break;
    }
    parsed = i + 1;
  }
  if (!rc && scene_update(sc, items, n, NULL, &err)) {
    fprintf(stderr, "raysweepd %s: %s: %s\n", cmd, what, rsw_err_format(&err, msg, sizeof msg));
    rc = 1;
  }
  for (size_t i = 0; i < parsed; i++) param_value_free(&items[i].value);
  for (size_t i = 0; keys && i < n; i++) free(keys[i]);
  free(keys);
  free(items);
  return rc;
}

/* --coord and --templates: the document's templates (a JSON scene's
 * top-level "templates") and --templates' rendered from the coords into
 * overrides, as the daemon does for a render's coords
 * (docs/experiments.md#templates); --set keys win (a scene template on one
 * is dropped, a --templates one refused). Every coordinate must be read by
 * a template. Returns 0, or 1 after the message. */
static int apply_coords(const render_req *r, const char *scene_path, scene *sc) {
  int rc = 1;
  cJSON *coords = cJSON_CreateObject(), *sets = cJSON_CreateObject(), *req = NULL, *doc = NULL, *out = NULL;
  tmpl_set *ts = NULL;
  svc_error e = {0};
  char **lines = NULL;
  size_t n = 0;
  if (!coords || !sets) goto oom;
  for (size_t i = 0; i < r->n_coords; i++) {
    const char *eq = strchr(r->coords[i], '=');
    char name[80];
    snprintf(name, sizeof name, "%.*s", (int)(eq - r->coords[i] < 72 ? eq - r->coords[i] : 72), r->coords[i]);
    double d = 0;
    parse_double(eq + 1, &d); /* (checked when read) */
    if (cJSON_GetObjectItemCaseSensitive(coords, name)) {
      fprintf(stderr, "raysweepd render: --coord %s given twice\n", name);
      goto done;
    }
    if (!cJSON_AddNumberToObject(coords, name, d)) goto oom;
  }
  for (size_t i = 0; i < r->n_sets; i++) {
    char key[512];
    snprintf(key, sizeof key, "%.*s", (int)(strchr(r->sets[i], '=') - r->sets[i]), r->sets[i]);
    if (!cJSON_GetObjectItemCaseSensitive(sets, key) && !cJSON_AddNullToObject(sets, key)) goto oom;
  }
  if (r->templates) {
    char why[1200];
    if (!(req = rsw_json_arg("--templates", r->templates, why, sizeof why))) {
      fprintf(stderr, "raysweepd render: %s\n", why);
      goto done;
    }
    if (!cJSON_IsObject(req)) {
      fprintf(stderr, "raysweepd render: --templates: a JSON object {KEY: template}\n");
      goto done;
    }
  }
  /* A JSON scene's own templates (an XML scene has none). */
  char *text = rsw_read_file(scene_path, NULL);
  if (text) {
    doc = cJSON_Parse(text);
    free(text);
  }
  const cJSON *doc_tmpl = cJSON_IsObject(doc) ? cJSON_GetObjectItemCaseSensitive(doc, "templates") : NULL;
  char ptr[600];
  snprintf(ptr, sizeof ptr, "%.500s#/templates", scene_path);
  rsw_status st = tmpl_compile(sc, doc_tmpl, ptr, req, sets, &ts, &e);
  const cJSON *cw = cJSON_GetObjectItemCaseSensitive(coords, "wavelength");
  if (!st && cw && r->wavelength > 0 && cw->valuedouble != r->wavelength) {
    fprintf(stderr, "raysweepd render: --coord wavelength=%g differs from --wavelength %g\n", cw->valuedouble,
            r->wavelength);
    goto done;
  }
  for (const cJSON *c = coords->child; !st && c; c = c->next)
    if (strcmp(c->string, "wavelength") != 0 && (!ts || !tmpl_uses_coord(ts, c->string))) {
      fprintf(stderr,
              "raysweepd render: --coord %s: no template reads it (%s): the render would not depend on it\n",
              c->string,
              doc_tmpl || req ? "the templates read other coordinates, or --set gives their value"
                              : "the scene has no templates, and --templates gives none");
      goto done;
    }
  double wl = sc->variant != VARIANT_MONO ? 0
              : cw                        ? cw->valuedouble
              : r->wavelength > 0         ? r->wavelength
                                          : 550;
  if (!st && ts && !(out = cJSON_CreateObject())) goto oom;
  if (!st && ts) st = tmpl_render(ts, sc, coords, wl, out, "", &e);
  if (st) {
    const char *w = e.err.where;
    bool coord = strncmp(w, "/coords/", 8) == 0;
    fprintf(stderr, "raysweepd render: %s%s: %s\n", coord ? "--coord " : "",
            coord  ? w + 8
            : w[0] ? w
                   : "--coord",
            e.err.msg);
    goto done;
  }
  /* The rendered overrides as KEY=JSON, applied as --set's are. */
  n = (size_t)cJSON_GetArraySize(out);
  lines = calloc(n ? n : 1, sizeof *lines);
  if (!lines) goto oom;
  size_t k = 0;
  for (const cJSON *v = out ? out->child : NULL; v; v = v->next, k++) {
    char *val = cJSON_PrintUnformatted(v);
    size_t sz = strlen(v->string) + (val ? strlen(val) : 0) + 2;
    lines[k] = val ? malloc(sz) : NULL;
    if (!lines[k]) {
      free(val);
      goto oom;
    }
    snprintf(lines[k], sz, "%s=%s", v->string, val);
    free(val);
  }
  rc = n ? apply_sets("render", "--coord (a template's value)", sc, (const char *const *)lines, n) : 0;
  goto done;
oom:
  fprintf(stderr, "raysweepd render: out of memory\n");
done:
  for (size_t i = 0; lines && i < n; i++) free(lines[i]);
  free(lines);
  tmpl_free(ts);
  cJSON_Delete(coords);
  cJSON_Delete(sets);
  cJSON_Delete(req);
  cJSON_Delete(doc);
  cJSON_Delete(out);
  return rc;
}

/* JSON string literal (keys and ids are plain, but escape anyway). */
static void print_json_string(const char *s) {
  putchar('"');
  for (; *s; s++) {
    if (*s == '"' || *s == '\\')
      printf("\\%c", *s);
    else if ((unsigned char)*s < 0x20)
      printf("\\u%04x", *s);
    else
      putchar(*s);
  }
  putchar('"');
}

/* raysweepd params's options. */
enum {
  P_MATCH,
  P_CLASS,
  P_JSON,
  P_VARIANT,
  P_DEFINE
};
static const cmdline_opt params_cmd_opts[] = {
    [P_MATCH] = {"--match", "PATTERN"},
    [P_CLASS] = {"--class", "CLASS"},
    [P_JSON] = {"--json"},
    [P_VARIANT] = {"--variant", "mono|rgb|mono_polarized|rgb_polarized"},
    [P_DEFINE] = {"-D", "name=value", CMDLINE_REPEAT | CMDLINE_ATTACHED},
    {NULL},
};

/* What raysweepd params was asked. */
typedef struct params_req {
  const char *match, *variant_name;
  unsigned mask;
  bool include_none, json;
  scene_define defines[MAX_DEFINES];
  size_t n_defines;
} params_req;

static int params_value(void *req, const cmdline_opt *o, const char *typed, const char *val) {
  params_req *r = req;
  switch ((int)(o - params_cmd_opts)) {
  case P_MATCH:
    if (!val)
      return usage_error("params", "%s needs a glob (e.g. '*.reflectance.value') or TYPE:ID:PATH", typed);
    r->match = val;
    break;
  case P_CLASS: {
    update_class c;
    if (!val || !update_class_parse(val, &c))
      return usage_error("params", "--class needs spectral, geometric or none (got '%s')", val ? val : "");
    r->mask = c == UPDATE_NONE ? 0 : (unsigned)c;
    r->include_none = c == UPDATE_NONE;
    break;
  }
  case P_JSON: r->json = true; break;
  case P_VARIANT:
    if (!val) return usage_error("params", "%s needs mono or rgb", typed);
    r->variant_name = val;
    break;
  case P_DEFINE: {
    const char *why = add_define(r->defines, &r->n_defines, val);
    if (why) return usage_error("params", "%s (got '%s')", why, val ? val : "");
    break;
  }
  }
  return 0;
}

static int cmd_params(int argc, char **argv) {
  params_req r = {.match = "*", .mask = UPDATE_SPECTRAL | UPDATE_GEOMETRIC, .include_none = true};
  cmdline_args args;
  int rc = 1;
  scene *sc = NULL;
  size_t *idx = NULL, count = 0;
  const char *scene_path = NULL;
  if ((rc = parse_command("params", params_cmd_opts, argc, argv, &args, params_value, &r))) goto out;
  rc = 1;
  if (args.n_pos > 1) {
    rc = usage_error("params", "unexpected argument '%s'", args.pos[1]);
    goto out;
  }
  scene_path = args.n_pos ? args.pos[0] : NULL;
  const char *match = r.match;
  unsigned mask = r.mask;
  bool include_none = r.include_none, json = r.json;
  if (!scene_path) {
    rc = usage_error("params", "missing the scene file%s", "");
    goto out;
  }
  rsw_err err = {0};
  char msg[1200];
  scene_load_opts lo = {
      .size = sizeof lo, .variant = r.variant_name, .defines = r.defines, .n_defines = r.n_defines};
  if (scene_load_file(scene_path, &lo, &sc, &err)) {
    fprintf(stderr, "raysweepd params: %s\n", rsw_err_format(&err, msg, sizeof msg));
    goto out;
  }
  if (params_match(sc, match, mask, include_none, &idx, &count, &err)) {
    fprintf(stderr, "raysweepd params: --match: %s\n", rsw_err_format(&err, msg, sizeof msg));
    goto out;
  }
  if (json) printf("[\n");
  for (size_t k = 0; k < count; k++) {
    param_info pi;
    params_info(sc, idx[k], &pi);
    char *value = params_value_json(sc, idx[k], 16);
    if (json) {
      printf("  {\"key\": ");
      print_json_string(pi.key);
      printf(", \"type\": \"%s\", \"class\": \"%s\", \"shape\": [%zu", param_type_name(pi.type),
             update_class_name(pi.cls), pi.shape[0]);
      if (pi.shape[1]) printf(", %zu", pi.shape[1]);
      printf("], \"object_type\": ");
      print_json_string(pi.object_type);
      printf(", \"object_class\": ");
      print_json_string(pi.object_class);
      printf(", \"object_id\": ");
      print_json_string(pi.object_id);
      printf(", \"value\": %s, \"aliases\": [", value ? value : "null");
      for (size_t a = 0; a < pi.n_aliases; a++) {
        if (a) printf(", ");
        print_json_string(pi.aliases[a]);
      }
      printf("]}%s\n", k + 1 < count ? "," : "");
    } else {
      char dims[48];
      if (pi.shape[1])
        snprintf(dims, sizeof dims, "%zux%zu", pi.shape[0], pi.shape[1]);
      else
        snprintf(dims, sizeof dims, "%zu", pi.shape[0]);
      printf("%-48s %-9s %-9s %-7s %s", pi.key, param_type_name(pi.type), update_class_name(pi.cls), dims,
             value ? value : "?");
      for (size_t a = 0; a < pi.n_aliases; a++) printf("%s%s", a ? ", " : "  (alias: ", pi.aliases[a]);
      printf("%s\n", pi.n_aliases ? ")" : "");
    }
    free(value);
  }
  if (json) printf("]\n");
  rc = 0;
out:
  free(idx);
  scene_free(sc);
  for (size_t i = 0; i < r.n_defines; i++) free((char *)r.defines[i].name);
  cmdline_free(&args);
  return rc;
}

static int cmd_version(int argc, char **argv) {
  if (argc > 1) return usage_error("version", "takes no arguments (got '%s')", argv[1]);
  printf("raysweepd %s (variants: mono, rgb, mono_polarized, rgb_polarized)\n", RSW_VERSION);
  return 0;
}

static const command commands[] = {
    {"render",
     "render SCENE [-D name=value]... [--set KEY=VALUE]... [--coord NAME=VALUE]... [--templates "
     "FILE.json|-|JSON] "
     "[--sensor ID] [--spp N] [--seed S] "
     "[--wavelength NM] [--threads N] [--isa auto|avx512|avx2|sse2|generic] [--variant "
     "mono|rgb|mono_polarized|rgb_polarized] "
     "[--plugin-dir DIR] "
     "[--quantities LIST] "
     "[--variance] [--exposure EV|auto] [--colormap MAP] [--stats] -o OUT.exr|OUT.npy|OUT.json|OUT.png",
     "load a scene, apply parameter updates, render one sensor to OpenEXR, NumPy, JSON or a PNG quick-look",
     "  SCENE               a .xml (Mitsuba XML) or .json scene file\n"
     "  -o, --output OUT    the film; written next to it and renamed once complete; the name's ending\n"
     "                      picks the kind: .exr OpenEXR, .npy NumPy and .json JSON (as the HTTP API\n"
     "                      sends them), .png a tone-mapped 8-bit quick-look; any other is refused\n"
     "  -D name=value       sets an XML $name parameter (not for JSON scenes)\n"
     "  --set KEY=VALUE     a parameter update after loading; VALUE is JSON (all --set form one update)\n"
     "  --coord NAME=VALUE  a coordinate the scene's templates (a JSON scene's \"templates\") and\n"
     "                      --templates' render overrides from, as the daemon's render coords\n"
     "  --templates T       templates for this render, {KEY: template}: a file, - or the JSON\n"
     "  --sensor ID         a sensor id or index (default: the first sensor)\n"
     "  --spp N             samples per pixel (default: the sensor's sampler sample_count)\n"
     "  --seed S            an integer >= 0, added to the sampler's seed (default 0)\n"
     "  --wavelength NM     the render wavelength in nm, mono variant (default 550)\n"
     "  --threads N         1 to 256 (default: every online core; the film does not depend on N)\n"
     "  --isa ISA           auto (default: the widest the CPU has), avx512, avx2, sse2 or generic "
     "(portable,\n"
     "                      every CPU): the instruction set of the vectorised shading; films agree across\n"
     "                      ISAs statistically, not bitwise; refused when the CPU lacks it\n"
     "  --variant V         mono, rgb, mono_polarized or rgb_polarized (Stokes films S0..S3):\n"
     "                      overrides the document's variant (default rgb)\n"
     "  --plugin-dir DIR    load every *.so in DIR as an environment plugin first\n"
     "  --quantities LIST   comma-separated, of radiance, brdf, brf: adds brdf = L/E_h and brf = pi L/E_h\n"
     "                      channels (E_h: horizontal irradiance of the directional emitters)\n"
     "  --variance          adds radiance_stderr channels, the standard error of each pixel's mean\n"
     "                      (box rfilter, spp >= 2)\n"
     "  --exposure EV       PNG only, as Mitsuba's 8-bit sRGB: linear radiance times 2^EV, clamped to\n"
     "                      [0, 1], sRGB curve (default 0); auto: the film's 99.5th percentile maps to\n"
     "                      white (not its maximum); auto+EV, auto-EV: then EV stops more or less\n"
     "  --colormap MAP      PNG only, one-channel films: gray (default), viridis or inferno\n"
     "  --stats             one summary line on stderr: samples/s, rays by kind, time tracing vs shading\n"
     "Exit status: 0 ok, 1 the scene failed to load or render, 2 command-line mistake.\n",
     cmd_render},
    {"params",
     "params SCENE [-D name=value]... [--match GLOB|TYPE:ID:PATH] [--class spectral|geometric|none] "
     "[--variant mono|rgb|mono_polarized|rgb_polarized] [--json]",
     "print a scene's parameter table (key, type, class, shape, value, aliases)",
     "  SCENE               a .xml (Mitsuba XML) or .json scene file\n"
     "  -D name=value       sets an XML $name parameter (not for JSON scenes)\n"
     "  --match PATTERN     a glob over keys ('*' also matches dots) or an Eradiate search TYPE:ID:PATH\n"
     "  --class CLASS       only keys of this update class: spectral, geometric or none\n"
     "  --variant V         mono, rgb, mono_polarized or rgb_polarized (Stokes films S0..S3):\n"
     "                      overrides the document's variant (default rgb)\n"
     "  --json              a JSON array instead of the table\n",
     cmd_params},
    {"serve", RSW_SERVE_USAGE, "the HTTP/JSON daemon (contract: proto/openapi.yaml)",
     "  --listen HOST:PORT  default 127.0.0.1:8350; port 0 picks a free one (see --port-file)\n"
     "  --threads N         threads per render and jobs run at once, 1 to 256 (default: every online core)\n"
     "  --scene FILE        preload a scene (repeatable; default: the embedded default scene)\n"
     "  --data-root DIR     plain file names in scenes resolve inside DIR (default: none, blobs only)\n"
     "  --blob-dir DIR      where uploaded blobs are kept (default: DIR/blobs of --state-dir, else a\n"
     "                      temporary directory removed at exit)\n"
     "  --token-file F      require 'Authorization: Bearer <token>' (needed off loopback)\n"
     "  --max-body BYTES    largest request body, e.g. 1048576 or 1024k (default 256M)\n"
     "  --max-queue N       most queued jobs before 429 (default 64)\n"
     "  --result-ttl S      seconds job results are kept (default 3600)\n"
     "  --port-file F       write the port listened on to F once listening\n"
     "  --plugin-dir DIR    load every *.so in DIR as an environment plugin at start\n"
     "  --state-dir DIR     keep blobs, scenes, job records and finished films in DIR (fsync'ed), so a\n"
     "                      restart, crash or SIGKILL loses nothing; interrupted jobs resume (default:\n"
     "                      all in memory)\n"
     "  --max-scene-bytes BYTES  evict idle scenes, least recently used, beyond BYTES (default: no budget)\n"
     "  --max-result-bytes BYTES  films kept in memory; beyond, on disk (--state-dir) or 507 (default: no "
     "cap)\n"
     "  --max-connections N open connections at most, 8 to 100000 (default 1024); near the\n"
     "                      limit requests other than the health probes get 503 + Retry-After\n"
     "  --header-timeout S  seconds a connection may take to send a request's headers\n"
     "                      (default 10); slower ones are closed\n"
     "  --max-film-bytes B  film memory one render may take (default 1G); larger films get 422\n"
     "  --isa ISA           auto (default: the widest the CPU has), avx512, avx2, sse2 or generic "
     "(portable,\n"
     "                      every CPU): the instruction set of the vectorised shading (GET /v1 says\n"
     "                      which); refused when the CPU lacks it\n"
     "Stops on SIGTERM or SIGINT.\n",
     cmd_serve},
    {"routes", "routes", "print the routes the daemon serves, one \"METHOD PATH\" per line", "", cmd_routes},
    {"version", "version", "print the version (also raysweepd --version)", "", cmd_version},
};
#define N_COMMANDS (sizeof commands / sizeof commands[0])

/* Print "PREFIX raysweepd USAGE" (common/cmdline.h: wrapped as the
 * client's usage lines are). */
static void print_usage_line(FILE *f, const char *prefix, const char *usage) {
  const char *sp = strchr(usage, ' ');
  char name[32];
  snprintf(name, sizeof name, "%.*s", sp ? (int)(sp - usage) : (int)strlen(usage), usage);
  cmdline_print_usage(f, prefix, "raysweepd", name, sp ? sp + 1 : "");
}

static void usage(FILE *f) {
  fprintf(f, "usage:\n");
  for (size_t i = 0; i < N_COMMANDS; i++) print_usage_line(f, "  ", commands[i].usage);
  fprintf(f, "  raysweepd --help | COMMAND --help | --version\n");
}

static void command_help(const command *c) {
  print_usage_line(stdout, "usage: ", c->usage);
  printf("\n%s\n", c->summary);
  if (c->help[0]) printf("\n%s", c->help);
}

static bool is_help(const char *a) {
  return strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    usage(stderr);
    return 2;
  }
  if (strcmp(argv[1], "--version") == 0 || strcmp(argv[1], "-V") == 0) return cmd_version(1, argv + 1);
  bool help = is_help(argv[1]) || strcmp(argv[1], "help") == 0;
  const char *name = help ? (argc > 2 ? argv[2] : NULL) : argv[1];
  if (help && !name) {
    usage(stdout);
    return 0;
  }
  for (size_t i = 0; i < N_COMMANDS; i++) {
    if (strcmp(name, commands[i].name) != 0) continue;
    /* `raysweepd help CMD`, or --help / -h anywhere after the command. */
    for (int k = 2; !help && k < argc; k++) help = is_help(argv[k]);
    if (help) {
      command_help(&commands[i]);
      return 0;
    }
    return commands[i].run(argc - 1, argv + 1);
  }
  fprintf(stderr, "raysweepd: unknown command '%s'\n", name);
  usage(stderr);
  return 2;
}
