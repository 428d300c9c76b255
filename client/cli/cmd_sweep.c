/* raysweep sweep: one job over many kernel contexts, films into a
 * directory with an index (the directory's files: sweep.h; --spread:
 * sweep_spread.c; raysweep merge: cmd_merge.c).
 *
 * Reproducibility across shards: context ids are numbered over the whole
 * unsharded list, and no per-context seed is sent, so the server derives
 * each (context, sensor) seed from fnv1a64(job seed, context id, sensor id)
 * (proto/API-NOTES.md, Context). A context therefore renders the same film
 * whichever shard submits it, and the union of the shards' films equals
 * the unsharded sweep bit for bit. */
#include <cjson/cJSON.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "bundle_plan.h"
#include "sweep.h"

const cmdline_opt cli_opts_sweep[] = {
    {"--contexts", "FILE.jsonl", false, "one Context object per line (id optional)"},
    {"--grid", "NAME=START:STOP:STEP|V1,V2,...", true,
     "a range (end included) or a list of values; NAME is wavelength, a parameter key (it holds a '.' or "
     "':'), or a coordinate that the scene's templates read (sza); several form a product (each also a "
     "coord of the contexts: wavelength, the key's last name before .value, or NAME)"},
    {"--set", "KEY=VALUE", true, "job-level parameter for every context (VALUE is JSON)"},
    {"--templates", "FILE.json|JSON", false,
     "the job's parameter-map templates, {KEY: template}: a file, or the JSON itself; each context's "
     "coords render them, e.g. {\"sun.direction\": {\"sun\": {\"zenith\": \"sza\", \"azimuth\": 0}}} "
     "with --grid sza=0,30,60 (docs/experiments.md#templates; a key the scene's templates also have: the "
     "job's wins)"},
    {"--sensor", "S", true, "sensor to render (default: every sensor)"},
    {"--spp", "N", false, "samples per pixel"},
    {"--seed", "N", false, "job seed (default 0)"},
    {"--shard", "I/N", false,
     "keep contexts I, I+N, I+2N, ... (ids unchanged; unless --bundle 1, whole bundle groups: those whose "
     "first context is one of them)"},
    {"--spread", "K", false,
     "run K shards at once through one load balancer (--server), each routed to its own replica by "
     "X-Raysweep-Shard; a scene FILE is pushed to every replica; a balancer that went away: rerun to resume"},
    {"--quantities", "LIST", false,
     "comma-separated, of radiance, brdf, brf: films add brdf and brf channels"},
    {"--variance", NULL, false, "films add radiance_stderr channels (standard error of each pixel's mean)"},
    {"--bundle", "K|auto", false,
     "carry K (1-16) wavelengths per path: each render with the next ones that differ only in wavelength; "
     "auto (the default): the most the daemon allows for the scene, 1 where it allows none; 1: one "
     "wavelength per path (docs/experiments.md#spectral-bundles)"},
    {"--format", "exr|npy|json|nc|dataset", false,
     "film files: exr (default), npy or json; nc: json films plus DIR/dataset.nc, the sweep as one "
     "NetCDF-4 dataset (xarray.open_dataset); dataset: DIR/dataset.nc alone, no file per film (the same "
     "dataset; not with --shard or --layout)"},
    {"--layout", "dirs|flat", false,
     "where the films go: dirs (default): DIR/CONTEXT/SENSOR.EXT; flat: DIR/CONTEXT.SENSOR.EXT, no directory "
     "per context (faster to write; '%' and '.' in CONTEXT written %25 and %2E); index.jsonl names each "
     "file"},
    {"--timeout", "S", false, "stop waiting after S seconds (exit 5; the job keeps running)"},
    {"-o", "DIR", false, "output directory: new or empty (see --force)"},
    {"--force", NULL, false,
     "DIR holds an earlier sweep: delete that sweep's films, index.jsonl and sweep.json first "
     "(other files are kept; a DIR with no sweep in it is still refused)"},
    {NULL},
};

/* The unsharded list may be longer than one job allows (the point of
 * --shard), so the local cap is larger than the server's 100000. */
#define MAX_CONTEXTS 10000000ull
#define MAX_GRIDS    16

typedef struct grid_axis {
  char *name;     /* owned */
  char coord[72]; /* the coord it fills: wavelength, the key's last name, or the name */
  bool is_wavelength;
  bool is_key; /* a parameter key (holds '.' or ':'); else wavelength or a coordinate alone */
  double start, step;
  double *values; /* a list (owned), or NULL: the range start + k step */
  size_t n;
} grid_axis;

static double axis_value(const grid_axis *g, size_t k) {
  return g->values ? g->values[k] : g->start + (double)k * g->step;
}

static void items_free(sweep_list *l) {
  for (size_t i = 0; i < l->n; i++) {
    cJSON_Delete(l->items[i].params);
    cJSON_Delete(l->items[i].sensors);
    cJSON_Delete(l->items[i].coords);
  }
  free(l->items);
  if (l->all_ids)
    for (size_t i = 0; i < l->total; i++) free(l->all_ids[i]);
  free(l->all_ids);
  free(l->leads);
  free(l->keys);
}

static sweep_item *items_push(sweep_list *l) {
  if (l->n == l->cap) {
    size_t cap = l->cap ? l->cap * 2 : 64;
    sweep_item *ni = realloc(l->items, cap * sizeof *ni);
    if (!ni) return NULL;
    l->items = ni, l->cap = cap;
  }
  sweep_item *it = &l->items[l->n++];
  memset(it, 0, sizeof *it);
  it->spp = it->seed = it->group = -1;
  return it;
}

/* A name a coordinate alone may have (the daemon's and the dataset's
 * rule): a letter, then up to 63 letters, digits or '_'. */
static bool coord_name_ok(const char *name, size_t len) {
  if (len == 0 || len > 64 || !((name[0] >= 'A' && name[0] <= 'Z') || (name[0] >= 'a' && name[0] <= 'z')))
    return false;
  for (size_t i = 1; i < len; i++) {
    char c = name[i];
    if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_'))
      return false;
  }
  return true;
}

/* V1,V2,... (at least one number) into g->values. */
static int parse_grid_list(const cli_ctx *ctx, const char *spec, const char *list, grid_axis *g) {
  size_t n = 1;
  for (const char *p = list; *p; p++) n += *p == ',';
  if (n > MAX_CONTEXTS) return cli_usage(ctx, "--grid %s: %zu values (at most %llu)", spec, n, MAX_CONTEXTS);
  char *copy = strdup(list);
  g->values = malloc(n * sizeof *g->values);
  if (!copy || !g->values) {
    free(copy);
    return cli_fail(ctx, CLI_IO, "out of memory");
  }
  int rc = 0;
  char *item = copy;
  for (size_t k = 0; k < n && !rc; k++) {
    char *comma = strchr(item, ',');
    if (comma) *comma = '\0';
    if (!cli_parse_double(item, &g->values[k]))
      rc = cli_usage(ctx,
                     "--grid %s: value %zu ('%s') is not a number (a list is V1,V2,...; a range "
                     "START:STOP:STEP)",
                     spec, k + 1, item);
    item = comma ? comma + 1 : item;
  }
  free(copy);
  g->n = n;
  return rc;
}

/* NAME=START:STOP:STEP or NAME=V1,V2,... The count of a range uses integer
 * steps so 400:700:10 has 31 values whatever the rounding of
 * (stop - start) / step:
 *   n = floor((stop - start) / step + 1e-9) + 1,  value_k = start + k step.
 * NAME is wavelength, a parameter key (it holds '.' or ':', an Eradiate
 * search TYPE:ID:PATH too), or a coordinate alone, which the scene's
 * templates read (docs/experiments.md#templates), as the Python client's
 * grid takes it. */
static int parse_grid(const cli_ctx *ctx, const char *spec, grid_axis *g) {
  const char *eq = strchr(spec, '=');
  if (!eq || eq == spec)
    return cli_usage(ctx, "--grid needs NAME=START:STOP:STEP or NAME=V1,V2,... (got '%s')", spec);
  size_t name_len = (size_t)(eq - spec);
  bool is_key = memchr(spec, '.', name_len) || memchr(spec, ':', name_len);
  bool is_wavelength = name_len == 10 && strncmp(spec, "wavelength", 10) == 0;
  if (!is_key && !is_wavelength && !coord_name_ok(spec, name_len))
    return cli_usage(ctx,
                     "--grid %.*s: neither wavelength, a parameter key (with a '.'), nor a coordinate name "
                     "(a letter, then letters, digits or '_')",
                     (int)name_len, spec);
  const char *vals = eq + 1;
  int rc = 0;
  if (!strchr(vals, ':')) {
    rc = parse_grid_list(ctx, spec, vals, g);
  } else {
    char *nums = strdup(vals);
    if (!nums) return cli_fail(ctx, CLI_IO, "out of memory");
    char *p1 = strchr(nums, ':'), *p2 = strchr(p1 + 1, ':');
    double start, stop, step;
    if (!p2) {
      rc = cli_usage(ctx, "--grid %s: the range needs START:STOP:STEP", spec);
    } else {
      *p1 = *p2 = '\0';
      if (!cli_parse_double(nums, &start) || !cli_parse_double(p1 + 1, &stop) ||
          !cli_parse_double(p2 + 1, &step))
        rc = cli_usage(ctx, "--grid %s: START, STOP and STEP must be numbers", spec);
      else if (!(step > 0))
        rc = cli_usage(ctx, "--grid %s: STEP must be positive", spec);
      else if (stop < start)
        rc = cli_usage(ctx, "--grid %s: STOP is below START", spec);
    }
    free(nums);
    if (rc) return rc;
    double n = floor((stop - start) / step + 1e-9) + 1;
    if (!(n <= (double)MAX_CONTEXTS))
      return cli_usage(ctx, "--grid %s: %.0f values (at most %llu)", spec, n, MAX_CONTEXTS);
    g->start = start, g->step = step, g->n = (size_t)n;
  }
  if (rc) return rc;
  g->name = strndup(spec, name_len);
  if (!g->name) return cli_fail(ctx, CLI_IO, "out of memory");
  g->is_wavelength = is_wavelength;
  g->is_key = is_key;
  for (size_t k = 0; is_wavelength && k < g->n; k++)
    if (!(axis_value(g, k) > 0)) return cli_usage(ctx, "--grid %s: wavelengths must be positive (nm)", spec);
  return 0;
}

/* The coord an axis fills: "wavelength", or a parameter key's last
 * dot-separated name that is not "value" ("plate.bsdf.reflectance.value"
 * -> "reflectance"), characters other than [A-Za-z0-9_] made '_'; when two
 * axes would share one, each of those takes its whole key so. */
static void axis_coords(grid_axis *g, size_t n) {
  for (size_t a = 0; a < n; a++) {
    const char *name = g[a].name;
    size_t len = strlen(name);
    if (len > 6 && strcmp(name + len - 6, ".value") == 0) len -= 6;
    const char *start = name + len;
    while (start > name && start[-1] != '.') start--;
    snprintf(g[a].coord, sizeof g[a].coord, "%.*s", (int)(name + len - start), start);
  }
  for (size_t a = 0; a < n; a++)
    for (size_t b = 0; b < n; b++)
      if (a != b && strcmp(g[a].coord, g[b].coord) == 0 && strchr(g[a].name, '.'))
        snprintf(g[a].coord, sizeof g[a].coord, "%.64s", g[a].name);
  for (size_t a = 0; a < n; a++) {
    char *c = g[a].coord;
    for (char *p = c; *p; p++)
      if (!((*p >= 'A' && *p <= 'Z') || (*p >= 'a' && *p <= 'z') || (*p >= '0' && *p <= '9') || *p == '_'))
        *p = '_';
    if (!((c[0] >= 'A' && c[0] <= 'Z') || (c[0] >= 'a' && c[0] <= 'z'))) {
      memmove(c + 1, c, strnlen(c, sizeof g[a].coord - 2) + 1);
      c[0] = 'p';
    }
  }
}

/* A grid's bundle groups (bundle > 1 and a wavelength axis; otherwise
 * l->leads stays NULL): the daemon's rule (common/bundle_plan.h) over the
 * contexts, whose key is their index with the wavelength axis's digit
 * taken out (the contexts that differ only in the wavelength). */
static int grid_leads(const cli_ctx *ctx, const grid_axis *g, size_t n_axes, int bundle, sweep_list *l) {
  size_t wa = n_axes, stride = 1;
  for (size_t a = 0; a < n_axes; a++)
    if (g[a].is_wavelength) wa = a;
  if (bundle <= 1 || wa == n_axes) return 0;
  for (size_t a = wa + 1; a < n_axes; a++) stride *= g[a].n;
  size_t n = l->total, nw = g[wa].n;
  uint64_t *key = malloc(n * sizeof *key);
  double *wl = malloc(n * sizeof *wl);
  l->leads = malloc(n * sizeof *l->leads);
  int rc = key && wl && l->leads ? 0 : -1;
  for (size_t i = 0; i < n && !rc; i++) {
    size_t lo = i % stride, kw = i / stride % nw, hi = i / stride / nw;
    key[i] = (uint64_t)(hi * stride + lo);
    wl[i] = axis_value(&g[wa], kw);
  }
  if (!rc) rc = rsw_bundle_runs(n, key, wl, bundle, l->leads);
  if (!rc) rc = (l->keys = malloc(n * sizeof *l->keys)) ? 0 : -1;
  if (!rc) rsw_bundle_shard_keys(n, l->leads, l->keys);
  free(key);
  free(wl);
  return rc ? cli_fail(ctx, CLI_IO, "out of memory") : 0;
}

/* The Cartesian product of the axes, first axis slowest; only the indices
 * this shard keeps are materialised (sweep_shard_of: with bundles, whole
 * bundle groups). */
static int build_grid(const cli_ctx *ctx, const grid_axis *g, size_t n_axes, size_t shard_i, size_t shard_n,
                      int bundle, sweep_list *l) {
  unsigned long long total = 1;
  for (size_t a = 0; a < n_axes; a++) {
    total *= g[a].n;
    if (total > MAX_CONTEXTS)
      return cli_usage(ctx, "--grid: the product has more than %llu contexts", MAX_CONTEXTS);
  }
  l->total = (size_t)total;
  int w = l->id_width = sweep_id_width(l->total);
  int rc = grid_leads(ctx, g, n_axes, bundle, l);
  if (rc) return rc;
  for (size_t i = l->leads ? 0 : shard_i; i < l->total; i += l->leads ? 1 : shard_n) {
    if (l->leads && sweep_shard_of(l->keys, i, shard_n) != shard_i) continue;
    sweep_item *it = items_push(l);
    if (!it) return cli_fail(ctx, CLI_IO, "out of memory");
    sweep_make_id(it->id, w, i);
    if (bundle > 1) it->group = (long long)(l->leads ? l->leads[i] : i);
    size_t rest = i, ks[MAX_GRIDS];
    for (size_t a = n_axes; a-- > 0;) {
      ks[a] = rest % g[a].n;
      rest /= g[a].n;
    }
    /* The coords in axis order (the dataset's dimensions follow it). */
    if (n_axes && !(it->coords = cJSON_CreateObject())) return cli_fail(ctx, CLI_IO, "out of memory");
    for (size_t a = 0; a < n_axes; a++)
      if (!cJSON_AddNumberToObject(it->coords, g[a].coord, axis_value(&g[a], ks[a])))
        return cli_fail(ctx, CLI_IO, "out of memory");
    for (size_t a = n_axes; a-- > 0;) {
      double v = axis_value(&g[a], ks[a]);
      if (g[a].is_wavelength) {
        it->has_wl = true, it->wl = v;
      } else if (g[a].is_key) {
        if (!it->params && !(it->params = cJSON_CreateObject()))
          return cli_fail(ctx, CLI_IO, "out of memory");
        cJSON_AddNumberToObject(it->params, g[a].name, v);
      }
    }
  }
  return 0;
}

typedef struct text_key {
  char *text;
  size_t index;
} text_key;

static int cmp_text_key(const void *a, const void *b) {
  const text_key *x = a, *y = b;
  int c = strcmp(x->text, y->text);
  return c ? c : (x->index > y->index) - (x->index < y->index);
}

/* A contexts file's bundle groups (bundle > 1): the daemon's rule
 * (common/bundle_plan.h) over every line, keyed by
 * rsw_bundle_context_text (a line that is not an object, or has a seed or
 * no wavelength, is a group of its own). text: the file, its lines
 * NUL-free; total lines that are not blank. */
static int file_leads(const cli_ctx *ctx, const char *text, size_t total, int bundle, sweep_list *l) {
  if (bundle <= 1 || !total) return 0;
  uint64_t *key = malloc(total * sizeof *key);
  double *wl = calloc(total, sizeof *wl);
  text_key *tk = calloc(total, sizeof *tk);
  l->leads = malloc(total * sizeof *l->leads);
  int rc = key && wl && tk && l->leads ? 0 : -1;
  size_t i = 0, nt = 0;
  for (const char *s = text; *s && !rc && i < total;) {
    const char *nl = strchr(s, '\n');
    size_t n = nl ? (size_t)(nl - s) : strlen(s);
    cJSON *o = cJSON_ParseWithLength(s, n);
    bool blank = true;
    for (size_t k = 0; k < n; k++) blank = blank && (s[k] == ' ' || s[k] == '\t' || s[k] == '\r');
    if (!blank) {
      const cJSON *w = cJSON_GetObjectItemCaseSensitive(o, "wavelength");
      wl[i] = cJSON_IsNumber(w) ? w->valuedouble : 0;
      key[i] = RSW_BUNDLE_ALONE;
      char *t = rsw_bundle_context_text(o);
      if (t) tk[nt++] = (text_key){t, i};
      i++;
    }
    cJSON_Delete(o);
    s += n + (nl ? 1 : 0);
  }
  if (!rc) {
    qsort(tk, nt, sizeof *tk, cmp_text_key);
    for (size_t a = 0, id = 0; a < nt; a++) {
      if (a && strcmp(tk[a].text, tk[a - 1].text) != 0) id++;
      key[tk[a].index] = id;
    }
    rc = rsw_bundle_runs(total, key, wl, bundle, l->leads);
    if (!rc) rc = (l->keys = malloc(total * sizeof *l->keys)) ? 0 : -1;
    if (!rc) rsw_bundle_shard_keys(total, l->leads, l->keys);
  }
  for (size_t a = 0; tk && a < nt; a++) free(tk[a].text);
  free(tk);
  free(key);
  free(wl);
  return rc ? cli_fail(ctx, CLI_IO, "out of memory") : 0;
}

/* One Context per non-blank line: {id?, wavelength?, params?, sensors?,
 * spp?, seed?}; a missing id is numbered like a grid's. This shard keeps
 * the lines sweep_shard_of gives it (with bundles, whole bundle groups). */
static int read_contexts(const cli_ctx *ctx, const char *path, size_t shard_i, size_t shard_n, int bundle,
                         sweep_list *l) {
  size_t len;
  char *text = rsw_read_file(path, &len);
  if (!text) return cli_fail(ctx, CLI_IO, "--contexts: cannot read '%s': %s", path, strerror(errno));
  int rc = 0;
  /* First pass: count the contexts so generated ids have their width. */
  size_t total = 0;
  for (char *s = text; *s;) {
    char *nl = strchr(s, '\n');
    size_t n = nl ? (size_t)(nl - s) : strlen(s);
    for (size_t k = 0; k < n; k++)
      if (s[k] != ' ' && s[k] != '\t' && s[k] != '\r') {
        total++;
        break;
      }
    s += n + (nl ? 1 : 0);
  }
  l->total = total;
  int w = l->id_width = sweep_id_width(total);
  if (strstr(text, "\"id\"") && total && !(l->all_ids = calloc(total, sizeof *l->all_ids))) {
    free(text);
    return cli_fail(ctx, CLI_IO, "out of memory");
  }
  int lrc = file_leads(ctx, text, total, bundle, l);
  if (lrc) {
    free(text);
    return lrc;
  }
  size_t line = 0, index = 0;
  for (char *s = text; *s && !rc;) {
    char *nl = strchr(s, '\n');
    if (nl) *nl = '\0';
    line++;
    char *next = nl ? nl + 1 : s + strlen(s);
    bool blank = true;
    for (char *k = s; *k; k++)
      if (*k != ' ' && *k != '\t' && *k != '\r') blank = false;
    if (blank) {
      s = next;
      continue;
    }
    size_t my = index++;
    if (sweep_shard_of(l->keys, my, shard_n) != shard_i) {
      if (l->all_ids) { /* another shard's line: only its id (that shard checks the rest) */
        cJSON *o = cJSON_Parse(s);
        const char *id = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "id"));
        if (id && *id && strlen(id) <= 64) l->all_ids[my] = strdup(id);
        cJSON_Delete(o);
      }
      s = next;
      continue;
    }
    cJSON *o = cJSON_Parse(s);
    if (!cJSON_IsObject(o)) {
      cJSON_Delete(o);
      rc = cli_usage(ctx, "%s:%zu: not a JSON object", path, line);
      break;
    }
    sweep_item *it = items_push(l);
    if (!it) {
      cJSON_Delete(o);
      rc = cli_fail(ctx, CLI_IO, "out of memory");
      break;
    }
    sweep_make_id(it->id, w, my);
    if (bundle > 1) it->group = (long long)(l->leads ? l->leads[my] : my);
    cJSON *f;
    cJSON_ArrayForEach(f, o) {
      const char *k = f->string;
      if (strcmp(k, "id") == 0) {
        const char *id = cJSON_GetStringValue(f);
        if (!id || !*id || strlen(id) > 64) {
          rc = cli_usage(ctx, "%s:%zu: id must be a string of 1 to 64 characters", path, line);
          break;
        }
        snprintf(it->id, sizeof it->id, "%s", id);
      } else if (strcmp(k, "wavelength") == 0) {
        if (!cJSON_IsNumber(f) || !(f->valuedouble > 0)) {
          rc = cli_usage(ctx, "%s:%zu: wavelength must be a positive number (nm)", path, line);
          break;
        }
        it->has_wl = true, it->wl = f->valuedouble;
      } else if (strcmp(k, "params") == 0) {
        if (!cJSON_IsObject(f)) {
          rc = cli_usage(ctx, "%s:%zu: params must be an object {key: value}", path, line);
          break;
        }
        it->params = cJSON_Duplicate(f, 1);
      } else if (strcmp(k, "sensors") == 0) {
        const cJSON *sv;
        bool ok = cJSON_IsArray(f);
        cJSON_ArrayForEach(sv, f) ok = ok && cJSON_IsString(sv);
        if (!ok) {
          rc = cli_usage(ctx, "%s:%zu: sensors must be an array of sensor ids", path, line);
          break;
        }
        it->sensors = cJSON_Duplicate(f, 1);
      } else if (strcmp(k, "coords") == 0) {
        if (!cJSON_IsObject(f)) {
          rc = cli_usage(ctx, "%s:%zu: coords must be an object {name: number or string}", path, line);
          break;
        }
        it->coords = cJSON_Duplicate(f, 1);
      } else if (strcmp(k, "spp") == 0) {
        if (!sweep_json_is_int(f, 1)) {
          rc = cli_usage(ctx, "%s:%zu: spp must be a positive integer", path, line);
          break;
        }
        it->spp = (long long)f->valuedouble;
      } else if (strcmp(k, "seed") == 0) {
        if (!sweep_json_is_int(f, 0)) {
          rc = cli_usage(ctx, "%s:%zu: seed must be a non-negative integer", path, line);
          break;
        }
        it->seed = (long long)f->valuedouble;
      } else {
        rc = cli_usage(
            ctx,
            "%s:%zu: unknown field '%s' (a Context has id, wavelength, params, sensors, spp, seed, coords)",
            path, line, k);
        break;
      }
    }
    cJSON_Delete(o);
    if (!rc && l->all_ids && !(l->all_ids[my] = strdup(it->id))) rc = cli_fail(ctx, CLI_IO, "out of memory");
    s = next;
  }
  free(text);
  return rc;
}

/* Feed the builder. Errors here are about the contexts the user described:
 * usage (2). */
static int build_contexts(const cli_ctx *ctx, const cmdline_args *a, const sweep_item *items, size_t n,
                          const cJSON *job_params, const char *tmpl, long long spp, long long seed,
                          int bundle, rsw_contexts **out) {
  rsw_contexts *x = NULL;
  rsw_status s = rsw_contexts_new(&x);
  if (s) return cli_fail(ctx, CLI_IO, "cannot start a context list: %s", rsw_strerror(s));
  int rc = 0;
  char what[160] = "";
  for (size_t i = 0; i < n && !s; i++) {
    const sweep_item *it = &items[i];
    size_t idx;
    snprintf(what, sizeof what, "context '%s'", it->id);
    if ((s = rsw_contexts_add(x, it->id, it->has_wl ? it->wl : 0, &idx))) break;
    const cJSON *p;
    cJSON_ArrayForEach(p, it->params) {
      char *v = cJSON_PrintUnformatted(p);
      s = v ? rsw_contexts_set_param(x, idx, p->string, v) : RSW_ERR_NOMEM;
      free(v);
      if (s) break;
    }
    cJSON_ArrayForEach(p, it->coords) {
      if (s) break;
      snprintf(what, sizeof what, "context '%s' coord '%s'", it->id, p->string);
      char *v = cJSON_PrintUnformatted(p);
      s = v ? rsw_contexts_set_coord(x, idx, p->string, v) : RSW_ERR_NOMEM;
      free(v);
    }
    cJSON_ArrayForEach(p, it->sensors) if (!s) s = rsw_contexts_add_sensor(x, idx, p->valuestring);
    if (!s && it->spp >= 0) s = rsw_contexts_set_spp(x, idx, it->spp);
    if (!s && it->seed >= 0) s = rsw_contexts_set_seed(x, idx, it->seed);
    if (!s && it->group >= 0) s = rsw_contexts_set_bundle_group(x, idx, it->group);
  }
  if (!s) {
    snprintf(what, sizeof what, "--set");
    const cJSON *p;
    cJSON_ArrayForEach(p, job_params) {
      char *v = cJSON_PrintUnformatted(p);
      s = v ? rsw_contexts_set_job_param(x, p->string, v) : RSW_ERR_NOMEM;
      free(v);
      if (s) break;
    }
  }
  size_t n_sensors;
  const char *const *sensors = cmdline_get_all(a, "--sensor", &n_sensors);
  for (size_t i = 0; i < n_sensors && !s; i++) {
    snprintf(what, sizeof what, "--sensor '%s'", sensors[i]);
    s = rsw_contexts_add_default_sensor(x, sensors[i]);
  }
  if (!s && spp > 0) snprintf(what, sizeof what, "--spp"), s = rsw_contexts_set_default_spp(x, spp);
  if (!s) snprintf(what, sizeof what, "--seed"), s = rsw_contexts_set_job_seed(x, seed);
  const char *qv = cmdline_get(a, "--quantities");
  if (!s && qv) {
    char list[256];
    const char *names[8];
    size_t nq = 0;
    snprintf(list, sizeof list, "%s", qv);
    snprintf(what, sizeof what, "--quantities '%s'", qv);
    for (char *save = NULL, *t = strtok_r(list, ",", &save); t && !s; t = strtok_r(NULL, ",", &save)) {
      if ((strcmp(t, "radiance") && strcmp(t, "brdf") && strcmp(t, "brf")) || nq == 8) {
        rsw_contexts_free(x);
        return cli_usage(ctx, "--quantities: unknown quantity '%s' (one of radiance, brdf, brf)", t);
      }
      names[nq++] = t;
    }
    if (!nq) s = RSW_ERR_INVALID;
    if (!s) s = rsw_contexts_set_quantities(x, names, nq);
  }
  if (!s && cmdline_get(a, "--variance"))
    snprintf(what, sizeof what, "--variance"), s = rsw_contexts_set_variance(x, 1);
  if (!s && tmpl) snprintf(what, sizeof what, "--templates"), s = rsw_contexts_set_templates(x, tmpl);
  if (!s && cmdline_get(a, "--bundle"))
    snprintf(what, sizeof what, "--bundle %s", cmdline_get(a, "--bundle")),
        s = rsw_contexts_set_bundle(x, bundle);
  if (s) {
    rc = s == RSW_ERR_NOMEM ? cli_fail(ctx, CLI_IO, "out of memory")
                            : cli_usage(ctx, "%s: %s", what, rsw_strerror(s));
    rsw_contexts_free(x);
    return rc;
  }
  *out = x;
  return 0;
}

/* Films of a finished job into dir (sweep_film_file), one index entry
 * each. Failed renders are reported and counted. */
static int fetch_all(cli_ctx *ctx, const char *job, const char *dir, sweep_layout layout, cli_format fmt,
                     sweep_item **sorted, size_t n, const cJSON *job_params, cJSON *incomplete,
                     film_pack *pack, index_entry **entries_out, size_t *n_out, size_t *failed_out) {
  char *text = NULL;
  rsw_status s = rsw_job_results(ctx->client, job, &text);
  if (s) return cli_report(ctx, s, job);
  cJSON *res = cJSON_Parse(text);
  rsw_free(text);
  const cJSON *list = cJSON_GetObjectItemCaseSensitive(res, "results");
  if (!cJSON_IsArray(list)) {
    cJSON_Delete(res);
    return cli_fail(ctx, CLI_SERVER, "%s: the results answer has no results list", job);
  }
  size_t cap = (size_t)cJSON_GetArraySize(list);
  index_entry *e = calloc(cap ? cap : 1, sizeof *e);
  size_t ne = 0, failed = 0;
  int rc = e ? 0 : cli_fail(ctx, CLI_IO, "out of memory");
  const cJSON *r;
  cJSON_ArrayForEach(r, list) {
    if (rc) break;
    const char *c = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "context"));
    const char *sn = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "sensor"));
    const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "state"));
    if (!c || !sn || !state) {
      rc = cli_fail(ctx, CLI_SERVER, "%s: a result without context, sensor or state", job);
      break;
    }
    if (strcmp(state, "succeeded") != 0) {
      const char *err = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(r, "error"));
      fprintf(stderr, "raysweep %s: %s/%s %s%s%s\n", ctx->cmd, c, sn, state, err ? ": " : "", err ? err : "");
      failed++;
      const char *last =
          cJSON_GetStringValue(cJSON_GetArrayItem(incomplete, cJSON_GetArraySize(incomplete) - 1));
      if (!last || strcmp(last, c) != 0) cJSON_AddItemToArray(incomplete, cJSON_CreateString(c));
      continue;
    }
    char rel[1100], path[4096];
    if (!pack &&
        (rc = sweep_film_file(ctx, dir, layout, c, sn, fmt, true, rel, sizeof rel, path, sizeof path)))
      break;
    /* EXR and NPY: the daemon's encoding is the file (or, --format dataset,
     * kept for the dataset); JSON: decoded. */
    rsw_film *film = NULL;
    void *bytes = NULL;
    size_t len = 0;
    const char *media = cli_format_media_type(fmt);
    if ((s = media ? rsw_job_fetch_encoded(ctx->client, job, c, sn, media, &bytes, &len)
                   : rsw_job_fetch(ctx->client, job, c, sn, &film))) {
      char what[300];
      snprintf(what, sizeof what, "%s %s/%s", job, c, sn);
      rc = cli_report(ctx, s, what);
      break;
    }
    if (pack)
      rc = pack_add(ctx, pack, c, sn, cJSON_GetObjectItemCaseSensitive(r, "channels"), bytes, len);
    else
      rc = film ? cli_save_film(ctx, film, path, fmt) : cli_save_encoded(ctx, bytes, len, path);
    rsw_film_free(film);
    rsw_free(bytes);
    if (rc) break;
    cJSON *line = sweep_index_line(r, c, sn, pack ? NULL : rel, sorted, n, job_params);
    e[ne].line = line;
    e[ne].context = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(line, "context"));
    e[ne].sensor = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(line, "sensor"));
    e[ne].order = ne;
    ne++;
  }
  cJSON_Delete(res);
  if (rc) {
    sweep_entries_free(e, ne);
    return rc;
  }
  *entries_out = e, *n_out = ne, *failed_out = failed;
  return 0;
}

/* The sweep's options, checked (usage errors name the option). */
typedef struct sweep_opts {
  const char *dir, *contexts_file;
  const char *const *grids;
  size_t n_grids;
  cli_format fmt;
  bool want_nc;   /* --format nc: JSON films and DIR/dataset.nc */
  bool want_pack; /* --format dataset: DIR/dataset.nc alone, built from the daemon's EXRs */
  sweep_layout layout;
  unsigned long long spp, seed, shard_i, shard_n, spread;
  double timeout;
  int bundle;      /* --bundle: 1..RSW_BUNDLE_MAX or RSW_BUNDLE_AUTO (auto when absent) */
  int bundle_plan; /* the K its groups are planned with: RSW_BUNDLE_MAX for auto */
  char *templates; /* --templates as compact JSON text (owned), or NULL */
} sweep_opts;

static int read_sweep_options(const cli_ctx *ctx, const cmdline_args *a, sweep_opts *o) {
  *o = (sweep_opts){.fmt = CLI_FMT_EXR, .shard_n = 1};
  o->dir = cmdline_get(a, "-o");
  o->contexts_file = cmdline_get(a, "--contexts");
  o->grids = cmdline_get_all(a, "--grid", &o->n_grids);
  if (!o->dir) return cli_usage(ctx, "missing -o DIR");
  if (!o->contexts_file == !o->n_grids)
    return cli_usage(ctx,
                     "give either --contexts FILE.jsonl or --grid NAME=START:STOP:STEP (or NAME=V1,V2,...)");
  if (o->n_grids > MAX_GRIDS) return cli_usage(ctx, "at most %d --grid axes", MAX_GRIDS);
  const char *v;
  o->want_nc = (v = cmdline_get(a, "--format")) && strcmp(v, "nc") == 0;
  o->want_pack = v && strcmp(v, "dataset") == 0;
  if (o->want_nc)
    o->fmt = CLI_FMT_JSON; /* the films the dataset is built from (and merge rebuilds it from) */
  else if (o->want_pack)
    o->fmt = CLI_FMT_EXR; /* as the daemon encodes them: pixels and angles binary, nothing parsed as JSON */
  else if (v && (o->fmt = cli_format_from_name(v)) == CLI_FMT_NONE)
    return cli_usage(ctx, "--format needs exr, npy, json, nc or dataset (got '%s')", v);
  unsigned long long mem;
  if ((o->want_nc || o->want_pack) && sweep_dataset_memory(ctx, &mem)) return CLI_USAGE;
  /* One dataset of the whole sweep: shards could not be merged (merge joins
   * film files), and there are no film files to lay out. */
  if (o->want_pack && cmdline_has(a, "--shard"))
    return cli_usage(ctx,
                     "--shard: --format dataset writes the sweep as one dataset, which merge cannot join; "
                     "use --spread K (its shards at once, one dataset), or --format nc to merge shards");
  if (o->want_pack && cmdline_has(a, "--layout"))
    return cli_usage(ctx, "--layout: --format dataset writes no film files (the films are in DIR/%s)",
                     DATASET_NAME);
  if ((v = cmdline_get(a, "--spp")) && (!cli_parse_u64(v, 1ull << 31, &o->spp) || o->spp == 0))
    return cli_usage(ctx, "--spp needs a positive integer (got '%s')", v);
  if ((v = cmdline_get(a, "--seed")) && !cli_parse_u64(v, (1ull << 53) - 1, &o->seed))
    return cli_usage(ctx, "--seed needs an integer in [0, 2^53) (got '%s')", v);
  if ((v = cmdline_get(a, "--shard"))) {
    const char *slash = strchr(v, '/');
    char ib[32];
    if (!slash || (size_t)(slash - v) >= sizeof ib) return cli_usage(ctx, "--shard needs I/N (got '%s')", v);
    memcpy(ib, v, (size_t)(slash - v));
    ib[slash - v] = '\0';
    if (!cli_parse_u64(ib, MAX_CONTEXTS, &o->shard_i) ||
        !cli_parse_u64(slash + 1, MAX_CONTEXTS, &o->shard_n) || o->shard_n == 0 || o->shard_i >= o->shard_n)
      return cli_usage(ctx, "--shard needs I/N with 0 <= I < N (got '%s')", v);
  }
  if ((v = cmdline_get(a, "--spread")) && (!cli_parse_u64(v, 4096, &o->spread) || o->spread == 0))
    return cli_usage(ctx, "--spread needs a number of shards from 1 to 4096 (got '%s')", v);
  if (o->spread && ctx->route)
    return cli_usage(ctx,
                     "--route %s: sweep --spread gives each shard a key of its own; drop --route (or "
                     "RAYSWEEP_ROUTE) to spread, or --spread to send the whole sweep with this key",
                     ctx->route);
  o->bundle = RSW_BUNDLE_AUTO, o->bundle_plan = RSW_BUNDLE_MAX; /* the daemon's default */
  if ((v = cmdline_get(a, "--bundle"))) {
    unsigned long long k;
    if (strcmp(v, "auto") == 0)
      o->bundle = RSW_BUNDLE_AUTO, o->bundle_plan = RSW_BUNDLE_MAX;
    else if (cli_parse_u64(v, RSW_BUNDLE_MAX, &k) && k >= 1)
      o->bundle = o->bundle_plan = (int)k;
    else
      return cli_usage(ctx,
                       "--bundle needs a number of wavelengths per path from 1 to %d, or auto (got '%s')",
                       RSW_BUNDLE_MAX, v);
  }
  if ((v = cmdline_get(a, "--layout")) && !sweep_layout_from_name(v, &o->layout))
    return cli_usage(ctx, "--layout needs dirs or flat (got '%s')", v);
  if ((v = cmdline_get(a, "--timeout")) && (!cli_parse_double(v, &o->timeout) || !(o->timeout > 0)))
    return cli_usage(ctx, "--timeout needs a positive number of seconds (got '%s')", v);
  if ((v = cmdline_get(a, "--templates"))) {
    cJSON *t;
    int rc = cli_json_option(ctx, "--templates", v, &t);
    if (!rc && !cJSON_IsObject(t))
      rc =
          cli_usage(ctx, "--templates: a JSON object {KEY: template} (docs/experiments.md#templates), not %s",
                    cJSON_IsArray(t) ? "an array" : "a single value");
    if (!rc && !(o->templates = cJSON_PrintUnformatted(t))) rc = cli_fail(ctx, CLI_IO, "out of memory");
    cJSON_Delete(t);
    if (rc) return rc;
  }
  return 0;
}

/* This shard's contexts (*l, from --contexts or the --grid axes), and
 * *sorted: pointers to them by id, every id usable as a file name (not
 * "." or "..": the daemon's URLs could not name them either) and given
 * once. */
static int build_list(const cli_ctx *ctx, const sweep_opts *o, grid_axis *axes, sweep_list *l,
                      sweep_item ***sorted) {
  int rc = 0;
  if (o->contexts_file) {
    rc = read_contexts(ctx, o->contexts_file, o->shard_i, o->shard_n, o->bundle_plan, l);
  } else {
    for (size_t i = 0; i < o->n_grids && !rc; i++) {
      rc = parse_grid(ctx, o->grids[i], &axes[i]);
      for (size_t k = 0; k < i && !rc; k++)
        if (strcmp(axes[k].name, axes[i].name) == 0)
          rc = cli_usage(ctx, "--grid %s given twice", axes[i].name);
    }
    if (!rc) axis_coords(axes, o->n_grids);
    if (!rc) rc = build_grid(ctx, axes, o->n_grids, o->shard_i, o->shard_n, o->bundle_plan, l);
  }
  if (rc) return rc;
  sweep_item **s = *sorted = malloc((l->n ? l->n : 1) * sizeof *s);
  if (!s) return cli_fail(ctx, CLI_IO, "out of memory");
  for (size_t i = 0; i < l->n; i++) s[i] = &l->items[i];
  qsort(s, l->n, sizeof *s, sweep_cmp_item_id);
  for (size_t i = 0; i < l->n; i++) {
    if (!cli_safe_component(s[i]->id)) return cli_usage(ctx, "context id '%s' cannot name a file", s[i]->id);
    if (i && strcmp(s[i]->id, s[i - 1]->id) == 0)
      return cli_usage(ctx, "context id '%s' appears twice", s[i]->id);
  }
  return 0;
}

/* One job for this shard's contexts x on `scene` (an id): submit, record
 * it in DIR/sweep.json, wait (Ctrl-C cancels it), fetch every film, write
 * the index, the dataset and the finished manifest. */
static int run_job(cli_ctx *ctx, const sweep_opts *o, const sweep_list *l, sweep_item **sorted,
                   const cJSON *job_params, const rsw_contexts *x, const char *scene, const char *fingerprint,
                   char *warned_whole) {
  const char *dir = o->dir;
  char job[40] = "";
  index_entry *entries = NULL;
  size_t n_entries = 0, failed = 0;
  cJSON *incomplete = NULL;
  /* the warnings printed: the whole sweep's (--shard; taken over), then the job's */
  char *warned = warned_whole;
  film_pack pack = {.fd = -1};
  int rc;
  cli_catch_interrupt();
  rsw_status s = rsw_job_submit(ctx->client, scene, x, NULL, job);
  if (s && cli_interrupted)
    return cli_fail(ctx, cli_interrupted_code(),
                    "%s while submitting the job (if the daemon got it, `raysweep job ls` shows it)",
                    cli_interrupted_word());
  if (s) return cli_report(ctx, s, scene);
  if (!ctx->quiet)
    fprintf(stderr, "raysweep sweep: job %s: %zu contexts%s\n", job, l->n,
            o->shard_n > 1 ? " (one shard)" : "");
  cli_print_job_warnings(ctx, "raysweep sweep", job, &warned);
  /* Written before any film, so a sweep that dies half-way leaves a
   * directory that says so (merge lists its contexts as missing; --force
   * knows what to clean). */
  if ((rc = manifest_write(ctx, dir, fingerprint, scene, o->shard_i, o->shard_n, l, job, false, NULL))) {
    free(warned);
    return rc;
  }
  rsw_job_status st;
  /* Ctrl-C cancels the job (this command submitted it) and writes no films. */
  rc = cli_wait_job(ctx, job, o->timeout, CLI_INTERRUPT_CANCEL, &st);
  if (rc != CLI_OK && rc != CLI_JOB) {
    free(warned);
    return rc;
  }
  int job_rc = rc;
  /* What the renders added (plugin_failures). */
  cli_print_job_warnings(ctx, "raysweep sweep", job, &warned);
  free(warned);
  warned = NULL;
  if (!(incomplete = cJSON_CreateArray())) return cli_fail(ctx, CLI_IO, "out of memory");
  if (l->pack && (rc = pack_open(ctx, &pack, dir, false, false, sorted, l->n))) goto out;
  if ((rc = fetch_all(ctx, job, dir, l->layout, o->fmt, sorted, l->n, job_params, incomplete,
                      l->pack ? &pack : NULL, &entries, &n_entries, &failed))) {
    if (cli_interrupted)
      rc = cli_fail(ctx, cli_interrupted_code(),
                    "%s while fetching films; job %s is over and keeps its results on the daemon "
                    "(`raysweep fetch %s CONTEXT SENSOR`, or sweep again)",
                    cli_interrupted_word(), job, job);
    goto out;
  }
  if ((rc = sweep_write_index(ctx, dir, entries, n_entries))) goto out;
  if ((o->want_nc || l->pack) &&
      (rc = sweep_write_dataset(ctx, dir, entries, n_entries, true, l->seed, l->pack ? &pack : NULL)))
    goto out;
  if ((rc = manifest_write(ctx, dir, fingerprint, scene, o->shard_i, o->shard_n, l, job, true, incomplete)))
    goto out;
  rc = job_rc;
  if (ctx->json) {
    cJSON *j = cJSON_CreateObject();
    cJSON_AddStringToObject(j, "job", job);
    cJSON_AddStringToObject(j, "state", cli_job_state_name(st.state));
    cJSON_AddStringToObject(j, "dir", dir);
    cJSON_AddNumberToObject(j, "contexts", (double)l->n);
    cJSON_AddNumberToObject(j, "films", (double)n_entries);
    cJSON_AddNumberToObject(j, "failed", (double)failed);
    cli_print_json(j);
  } else if (!ctx->quiet) {
    fprintf(stderr, "raysweep sweep: %zu films in %s%s\n", n_entries, dir,
            failed ? " (some renders failed)" : "");
  }
out:
  cJSON_Delete(incomplete);
  sweep_entries_free(entries, n_entries);
  pack_close(&pack, false);
  return rc;
}

/* --shard I/N: the whole sweep's dry run (POST .../jobs?dry_run=1, nothing
 * queued) on this shard's daemon, whose warnings no shard's own job may
 * show (a coordinate that changes nothing, one value a shard): printed as
 * --spread prints them, and returned (malloc'd lines, or NULL) so that the
 * shard's job does not print them again. A daemon without dry runs, or a
 * refusal (the shard's own job then says why), prints nothing. */
static char *warn_whole_sweep(cli_ctx *ctx, const cmdline_args *a, const sweep_opts *o,
                              const cJSON *job_params, const char *scene) {
  sweep_opts whole = *o;
  whole.shard_i = 0, whole.shard_n = 1;
  sweep_list l = {.seed = (long long)o->seed};
  grid_axis axes[MAX_GRIDS] = {{0}};
  sweep_item **sorted = NULL;
  rsw_contexts *x = NULL;
  char *w = NULL, *out = NULL;
  if (!build_list(ctx, &whole, axes, &l, &sorted) &&
      !build_contexts(ctx, a, l.items, l.n, job_params, o->templates, (long long)o->spp, (long long)o->seed,
                      o->bundle, &x) &&
      rsw_job_check(ctx->client, scene, x, NULL, &w) == RSW_OK && w) {
    cli_print_warnings("raysweep sweep", "the sweep", w, NULL);
    out = strdup(w);
  }
  rsw_free(w);
  rsw_contexts_free(x);
  free(sorted);
  items_free(&l);
  for (size_t i = 0; i < MAX_GRIDS; i++) free(axes[i].name), free(axes[i].values);
  return out;
}

int cmd_sweep(cli_ctx *ctx, const cmdline_args *a) {
  const char *scene = a->pos[0];
  sweep_opts o;
  int rc = read_sweep_options(ctx, a, &o);
  if (rc) return rc;
  const char *dir = o.dir;
  size_t n_sets;
  const char *const *sets = cmdline_get_all(a, "--set", &n_sets);
  cJSON *job_params = NULL;
  rc = cli_build_param_map(ctx, "--set", sets, n_sets, &job_params);
  if (rc) {
    free(o.templates);
    return rc;
  }

  sweep_list l = {.seed = (long long)o.seed, .dataset = o.want_nc, .pack = o.want_pack, .layout = o.layout};
  grid_axis axes[MAX_GRIDS] = {{0}};
  sweep_item **sorted = NULL;
  rsw_contexts *x = NULL;
  char fingerprint[17] = "", scene_id[65] = "";
  if ((rc = build_list(ctx, &o, axes, &l, &sorted))) goto out;
  /* A key both swept and --set: every context sets its own value, so the
   * --set would change nothing. */
  for (size_t i = 0; i < o.n_grids && !o.contexts_file; i++)
    if (axes[i].name && cJSON_GetObjectItemCaseSensitive(job_params, axes[i].name)) {
      rc =
          cli_usage(ctx, "--set %s: also a --grid axis, whose values every context sets; give one of the two",
                    axes[i].name);
      goto out;
    }
  /* Everything the user described is checked: now the directory. */
  l.templates = o.templates;
  sweep_fingerprint(a, scene, l.templates, fingerprint);
  sweep_layout was = SWEEP_LAYOUT_DIRS;
  bool resume = o.spread && !cmdline_has(a, "--force") && sweep_spread_resumable(dir, fingerprint, &was);
  if (resume && was != o.layout) {
    rc = cli_usage(ctx,
                   "--layout %s: -o %s holds an unfinished --spread run of this sweep with --layout %s; "
                   "rerun with --layout %s to resume it, or add --force to start over",
                   sweep_layout_name(o.layout), dir, sweep_layout_name(was), sweep_layout_name(was));
    goto out;
  }
  if (!resume && (rc = sweep_prepare_output(ctx, dir, cmdline_has(a, "--force")))) goto out;
  /* The job lists the contexts in the order the user described them (an empty
   * shard's too: its options are checked before the scene is pushed). */
  if ((rc = build_contexts(ctx, a, l.items, l.n, job_params, o.templates, (long long)o.spp, (long long)o.seed,
                           o.bundle, &x)))
    goto out;
  struct stat sst;
  if (!o.spread && stat(scene, &sst) == 0 && S_ISREG(sst.st_mode)) {
    /* A scene FILE: push it (blobs it references too) and sweep its id
     * (an empty shard too: its sweep.json must name the sweep its other
     * shards name, for merge). */
    int created = 0;
    rsw_status ps = rsw_scene_push_file(ctx->client, scene, NULL, scene_id, &created);
    if (ps) {
      rc = cli_report(ctx, ps, scene);
      goto out;
    }
    scene = scene_id;
    sweep_fingerprint(a, scene, l.templates, fingerprint);
  }
  if (l.n == 0) {
    /* A shard past the end of a short list: nothing to submit, an empty
     * index keeps `merge` simple. */
    if (!ctx->quiet)
      fprintf(stderr, "raysweep sweep: shard %llu/%llu has no contexts\n", o.shard_i, o.shard_n);
    rc = sweep_write_index(ctx, dir, NULL, 0);
    if (!rc) rc = manifest_write(ctx, dir, fingerprint, scene, o.shard_i, o.shard_n, &l, NULL, true, NULL);
    goto out;
  }
  if (o.spread)
    rc = sweep_run_spread(ctx, a, (int)o.spread, resume, o.fmt, o.timeout, &l, sorted, job_params, x,
                          fingerprint, (size_t)o.shard_i, (size_t)o.shard_n);
  else
    rc = run_job(ctx, &o, &l, sorted, job_params, x, scene, fingerprint,
                 o.shard_n > 1 ? warn_whole_sweep(ctx, a, &o, job_params, scene) : NULL);
out:
  rsw_contexts_free(x);
  free(sorted);
  items_free(&l);
  for (size_t i = 0; i < MAX_GRIDS; i++) free(axes[i].name), free(axes[i].values);
  free(o.templates);
  cJSON_Delete(job_params);
  return rc;
}
