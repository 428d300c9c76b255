/* raysweep sweep (one job over many kernel contexts, films into a
 * directory with an index) and raysweep merge (join shard directories).
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

#include "cli.h"

const cli_opt cli_opts_sweep[] = {
    {"--contexts", "FILE.jsonl", false, "one Context object per line (id optional)"},
    {"--grid", "NAME=START:STOP:STEP", true,
     "a range, end included; NAME is wavelength or a parameter key; several form a product (each also "
     "a coord of the contexts: wavelength, or the key's last name before .value)"},
    {"--set", "KEY=VALUE", true, "job-level parameter for every context (VALUE is JSON)"},
    {"--sensor", "S", true, "sensor to render (default: every sensor)"},
    {"--spp", "N", false, "samples per pixel"},
    {"--seed", "N", false, "job seed (default 0)"},
    {"--shard", "I/N", false, "keep contexts I, I+N, I+2N, ... (ids unchanged)"},
    {"--spread", "K", false,
     "run K shards at once through one load balancer (--server), each routed to its own replica by "
     "X-Raysweep-Shard; a scene FILE is pushed to every replica; a balancer that went away: rerun to resume"},
    {"--quantities", "LIST", false,
     "comma-separated, of radiance, brdf, brf: films add brdf and brf channels"},
    {"--variance", NULL, false, "films add radiance_stderr channels (standard error of each pixel's mean)"},
    {"--format", "exr|npy|json|nc", false,
     "film files: exr (default), npy or json; nc: json films plus DIR/dataset.nc, the sweep as one "
     "NetCDF-4 dataset (xarray.open_dataset)"},
    {"--timeout", "S", false, "stop waiting after S seconds (exit 5; the job keeps running)"},
    {"-o", "DIR", false, "output directory: new or empty (see --force)"},
    {"--force", NULL, false,
     "DIR holds an earlier sweep: delete that sweep's films, index.jsonl and sweep.json first "
     "(other files are kept; a DIR with no sweep in it is still refused)"},
    {NULL},
};
const cli_opt cli_opts_merge[] = {
    {"-o", "DIR", false,
     "output directory (with DIR/dataset.nc when the shards were swept with --format nc)"},
    {"--partial", NULL, false, "merge even when contexts are missing (they are listed; exit 0)"},
    {NULL},
};

/* The unsharded list may be longer than one job allows (the point of
 * --shard), so the local cap is larger than the server's 100000. */
#define MAX_CONTEXTS 10000000ull
#define MAX_GRIDS    16

typedef struct sweep_item {
  char id[72];
  bool has_wl;
  double wl;
  cJSON *params;       /* object or NULL, owned */
  cJSON *sensors;      /* array of strings or NULL, owned */
  cJSON *coords;       /* object or NULL, owned: the context's coords */
  long long spp, seed; /* -1: unset */
} sweep_item;

typedef struct grid_axis {
  char *name;     /* owned */
  char coord[72]; /* the coord it fills: wavelength, or the key's last name */
  bool is_wavelength;
  double start, step;
  size_t n;
} grid_axis;

typedef struct sweep_list {
  sweep_item *items;
  size_t n, cap;
  size_t total; /* unsharded count */
  /* --contexts with ids in the file: the id of every context of the
   * unsharded list (NULL: numbered), so sweep.json can name the contexts
   * of the other shards. NULL when every id is numbered. */
  char **all_ids;
  int id_width;
  long long seed; /* --seed (0 by default): the job seed, in sweep.json */
  bool dataset;   /* --format nc: DIR/dataset.nc besides the (JSON) films */
} sweep_list;

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
  it->spp = it->seed = -1;
  return it;
}

/* "c" + index zero-padded to at least 5 digits; the width is that of the
 * largest index, so every id of one sweep has the same width and ids sort
 * in list order. */
static int id_width(size_t total) {
  int w = 1;
  for (size_t m = total > 0 ? total - 1 : 0; m >= 10; m /= 10) w++;
  return w < 5 ? 5 : w;
}

static void make_id(char out[72], int width, size_t index) {
  char digits[24];
  int len = snprintf(digits, sizeof digits, "%zu", index);
  int pad = width > len ? width - len : 0;
  out[0] = 'c';
  memset(out + 1, '0', (size_t)pad);
  memcpy(out + 1 + pad, digits, (size_t)len + 1);
}

/* NAME=START:STOP:STEP. The count uses integer steps so 400:700:10 has 31
 * values whatever the rounding of (stop - start) / step:
 *   n = floor((stop - start) / step + 1e-9) + 1,  value_k = start + k step. */
static int parse_grid(const cli_ctx *ctx, const char *spec, grid_axis *g) {
  const char *eq = strchr(spec, '=');
  if (!eq || eq == spec) return cli_usage(ctx, "--grid needs NAME=START:STOP:STEP (got '%s')", spec);
  char *nums = strdup(eq + 1);
  if (!nums) return cli_fail(ctx, CLI_IO, "out of memory");
  char *p1 = strchr(nums, ':'), *p2 = p1 ? strchr(p1 + 1, ':') : NULL;
  double start, stop, step;
  int rc = 0;
  if (!p1 || !p2) {
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
  g->name = strndup(spec, (size_t)(eq - spec));
  if (!g->name) return cli_fail(ctx, CLI_IO, "out of memory");
  g->is_wavelength = strcmp(g->name, "wavelength") == 0;
  g->start = start, g->step = step, g->n = (size_t)n;
  if (g->is_wavelength && !(start > 0))
    return cli_usage(ctx, "--grid %s: wavelengths must be positive (nm)", spec);
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

/* The Cartesian product of the axes, first axis slowest; only the indices
 * this shard keeps are materialised. */
static int build_grid(const cli_ctx *ctx, const grid_axis *g, size_t n_axes, size_t shard_i, size_t shard_n,
                      sweep_list *l) {
  unsigned long long total = 1;
  for (size_t a = 0; a < n_axes; a++) {
    total *= g[a].n;
    if (total > MAX_CONTEXTS)
      return cli_usage(ctx, "--grid: the product has more than %llu contexts", MAX_CONTEXTS);
  }
  l->total = (size_t)total;
  int w = l->id_width = id_width(l->total);
  for (size_t i = shard_i; i < l->total; i += shard_n) {
    sweep_item *it = items_push(l);
    if (!it) return cli_fail(ctx, CLI_IO, "out of memory");
    make_id(it->id, w, i);
    size_t rest = i, ks[MAX_GRIDS];
    for (size_t a = n_axes; a-- > 0;) {
      ks[a] = rest % g[a].n;
      rest /= g[a].n;
    }
    /* The coords in axis order (the dataset's dimensions follow it). */
    if (n_axes && !(it->coords = cJSON_CreateObject())) return cli_fail(ctx, CLI_IO, "out of memory");
    for (size_t a = 0; a < n_axes; a++)
      if (!cJSON_AddNumberToObject(it->coords, g[a].coord, g[a].start + (double)ks[a] * g[a].step))
        return cli_fail(ctx, CLI_IO, "out of memory");
    for (size_t a = n_axes; a-- > 0;) {
      double v = g[a].start + (double)ks[a] * g[a].step;
      if (g[a].is_wavelength) {
        it->has_wl = true, it->wl = v;
      } else {
        if (!it->params && !(it->params = cJSON_CreateObject()))
          return cli_fail(ctx, CLI_IO, "out of memory");
        cJSON_AddNumberToObject(it->params, g[a].name, v);
      }
    }
  }
  return 0;
}

static bool json_is_int(const cJSON *v, double lo) {
  return cJSON_IsNumber(v) && v->valuedouble >= lo && v->valuedouble == floor(v->valuedouble) &&
         v->valuedouble < 9007199254740992.0;
}

/* One Context per non-blank line: {id?, wavelength?, params?, sensors?,
 * spp?, seed?}; a missing id is numbered like a grid's. */
static int read_contexts(const cli_ctx *ctx, const char *path, size_t shard_i, size_t shard_n,
                         sweep_list *l) {
  size_t len;
  char *text = cli_read_file(path, &len);
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
  int w = l->id_width = id_width(total);
  if (strstr(text, "\"id\"") && total && !(l->all_ids = calloc(total, sizeof *l->all_ids))) {
    free(text);
    return cli_fail(ctx, CLI_IO, "out of memory");
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
    if (my % shard_n != shard_i) {
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
    make_id(it->id, w, my);
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
        if (!json_is_int(f, 1)) {
          rc = cli_usage(ctx, "%s:%zu: spp must be a positive integer", path, line);
          break;
        }
        it->spp = (long long)f->valuedouble;
      } else if (strcmp(k, "seed") == 0) {
        if (!json_is_int(f, 0)) {
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

static int cmp_item_id(const void *a, const void *b) {
  return strcmp((*(const sweep_item *const *)a)->id, (*(const sweep_item *const *)b)->id);
}

/* One film of the index: its line (owned) and, for merge, the source. */
typedef struct index_entry {
  const char *context, *sensor; /* borrowed from line */
  cJSON *line;
  char *src; /* owned, merge only */
  size_t order;
  size_t input; /* merge: which input directory */
} index_entry;

static int cmp_entry(const void *a, const void *b) {
  const index_entry *x = a, *y = b;
  int c = strcmp(x->context, y->context);
  if (!c) c = strcmp(x->sensor, y->sensor);
  if (!c) c = x->order < y->order ? -1 : x->order > y->order;
  return c;
}

/* index.jsonl: one line per film, sorted by context then sensor, so a
 * merged directory's index equals the unsharded one byte for byte. */
static int write_index(const cli_ctx *ctx, const char *dir, index_entry *e, size_t n) {
  if (n) qsort(e, n, sizeof *e, cmp_entry);
  char *buf = NULL;
  size_t len = 0;
  FILE *f = open_memstream(&buf, &len);
  if (!f) return cli_fail(ctx, CLI_IO, "out of memory");
  for (size_t i = 0; i < n; i++) {
    char *t = cJSON_PrintUnformatted(e[i].line);
    if (t) fprintf(f, "%s\n", t);
    free(t);
  }
  fclose(f);
  size_t pn = strlen(dir) + 16;
  char *path = malloc(pn);
  int rc = CLI_OK;
  if (!buf || !path) {
    rc = cli_fail(ctx, CLI_IO, "out of memory");
  } else {
    snprintf(path, pn, "%s/index.jsonl", dir);
    if (cli_write_file_atomic(path, buf, len))
      rc = cli_fail(ctx, CLI_IO, "cannot write '%s': %s", path, strerror(errno));
  }
  free(path);
  free(buf);
  return rc;
}

static void entries_free(index_entry *e, size_t n) {
  for (size_t i = 0; i < n; i++) {
    cJSON_Delete(e[i].line);
    free(e[i].src);
  }
  free(e);
}

/* Feed the builder. Errors here are about the contexts the user described:
 * usage (2). */
static int build_contexts(const cli_ctx *ctx, const cli_args *a, const sweep_item *items, size_t n,
                          const cJSON *job_params, long long spp, long long seed, rsw_contexts **out) {
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
  const char *const *sensors = cli_get_all(a, "--sensor", &n_sensors);
  for (size_t i = 0; i < n_sensors && !s; i++) {
    snprintf(what, sizeof what, "--sensor '%s'", sensors[i]);
    s = rsw_contexts_add_default_sensor(x, sensors[i]);
  }
  if (!s && spp > 0) snprintf(what, sizeof what, "--spp"), s = rsw_contexts_set_default_spp(x, spp);
  if (!s) snprintf(what, sizeof what, "--seed"), s = rsw_contexts_set_job_seed(x, seed);
  const char *qv = cli_get(a, "--quantities");
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
  if (!s && cli_get(a, "--variance"))
    snprintf(what, sizeof what, "--variance"), s = rsw_contexts_set_variance(x, 1);
  if (s) {
    rc = s == RSW_ERR_NOMEM ? cli_fail(ctx, CLI_IO, "out of memory")
                            : cli_usage(ctx, "%s: %s", what, rsw_strerror(s));
    rsw_contexts_free(x);
    return rc;
  }
  *out = x;
  return 0;
}

/* One index.jsonl line for result r (the job's result object) of film
 * rel: wavelength and seed as the server used them; params the effective
 * overrides (job-level, then the context's own). */
static cJSON *index_line(const cJSON *r, const char *c, const char *sn, const char *rel, sweep_item **sorted,
                         size_t n, const cJSON *job_params) {
  cJSON *line = cJSON_CreateObject();
  cJSON_AddStringToObject(line, "context", c);
  cJSON_AddStringToObject(line, "sensor", sn);
  const cJSON *wl = cJSON_GetObjectItemCaseSensitive(r, "wavelength");
  sweep_item key, *kp = &key;
  snprintf(key.id, sizeof key.id, "%s", c);
  sweep_item **found = bsearch(&kp, sorted, n, sizeof *sorted, cmp_item_id);
  if (cJSON_IsNumber(wl))
    cJSON_AddNumberToObject(line, "wavelength", wl->valuedouble);
  else if (found && (*found)->has_wl)
    cJSON_AddNumberToObject(line, "wavelength", (*found)->wl);
  else
    cJSON_AddNullToObject(line, "wavelength");
  cJSON *params = job_params ? cJSON_Duplicate(job_params, 1) : cJSON_CreateObject();
  const cJSON *p;
  if (found) cJSON_ArrayForEach(p, (*found)->params) {
      cJSON_DeleteItemFromObjectCaseSensitive(params, p->string);
      cJSON_AddItemToObject(params, p->string, cJSON_Duplicate(p, 1));
    }
  cJSON_AddItemToObject(line, "params", params);
  if (found && (*found)->coords) cJSON_AddItemToObject(line, "coords", cJSON_Duplicate((*found)->coords, 1));
  const cJSON *seed = cJSON_GetObjectItemCaseSensitive(r, "seed");
  if (cJSON_IsNumber(seed))
    cJSON_AddNumberToObject(line, "seed", seed->valuedouble);
  else
    cJSON_AddNullToObject(line, "seed");
  cJSON_AddStringToObject(line, "file", rel);
  return line;
}

/* Films of a finished job into dir/<context>/<sensor>.<ext>, one index
 * entry each. Failed renders are reported and counted. */
static int fetch_all(cli_ctx *ctx, const char *job, const char *dir, cli_format fmt, sweep_item **sorted,
                     size_t n, const cJSON *job_params, cJSON *incomplete, index_entry **entries_out,
                     size_t *n_out, size_t *failed_out) {
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
    if (!cli_safe_component(c) || !cli_safe_component(sn)) {
      rc = cli_fail(ctx, CLI_IO, "%s/%s: not usable as a file name", c, sn);
      break;
    }
    char rel[600], path[4096];
    snprintf(rel, sizeof rel, "%s", c);
    snprintf(path, sizeof path, "%s/%s", dir, rel);
    if (cli_mkdirs(path)) {
      rc = cli_fail(ctx, CLI_IO, "cannot create '%s': %s", path, strerror(errno));
      break;
    }
    snprintf(rel, sizeof rel, "%s/%s.%s", c, sn, cli_format_ext(fmt));
    snprintf(path, sizeof path, "%s/%s", dir, rel);
    rsw_film *film = NULL;
    if ((s = rsw_job_fetch(ctx->client, job, c, sn, &film))) {
      char what[300];
      snprintf(what, sizeof what, "%s %s/%s", job, c, sn);
      rc = cli_report(ctx, s, what);
      break;
    }
    rc = cli_save_film(ctx, film, path, fmt);
    rsw_film_free(film);
    if (rc) break;
    cJSON *line = index_line(r, c, sn, rel, sorted, n, job_params);
    e[ne].line = line;
    e[ne].context = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(line, "context"));
    e[ne].sensor = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(line, "sensor"));
    e[ne].order = ne;
    ne++;
  }
  cJSON_Delete(res);
  if (rc) {
    entries_free(e, ne);
    return rc;
  }
  *entries_out = e, *n_out = ne, *failed_out = failed;
  return 0;
}

/* ---- sweep.json: what a sweep directory is meant to hold ---- */

/* DIR/sweep.json, written before the job is submitted and again when the
 * sweep ends:
 *   {"format": "raysweep-sweep/1", "sweep": FINGERPRINT, "scene": ID,
 *    "shard": [I, N], "contexts_total": T,
 *    "id_width": W | "ids": [every context id of the unsharded list],
 *    "job": JOB | null, "finished": BOOL, "incomplete": [context ids]}
 * FINGERPRINT is FNV-1a 64 over everything that defines the unsharded
 * sweep (scene, contexts file or grid, --set, --sensor, --spp, --seed,
 * --format, --quantities, --variance) and not over --shard, so every shard of one sweep carries the
 * same value. `merge` uses it to know which contexts a set of shard
 * directories must cover; `sweep --force` to know what an earlier sweep
 * wrote. "incomplete" lists contexts with a render that did not succeed. */
#define MANIFEST_NAME   "sweep.json"
#define DATASET_NAME    "dataset.nc"
/* The journal of a --spread sweep (rsw_spread_opts.state_path): there
 * while the sweep is unfinished, removed when it completes. */
#define SPREAD_STATE    "sweep.spread.jsonl"
#define MANIFEST_FORMAT "raysweep-sweep/1"

static uint64_t fnv1a(uint64_t h, const char *s, size_t n) {
  for (size_t i = 0; i < n; i++) h = (h ^ (unsigned char)s[i]) * 0x100000001b3ull;
  return (h ^ 0xff) * 0x100000001b3ull; /* a separator, so "ab","c" != "a","bc" */
}

static uint64_t fnv1a_str(uint64_t h, const char *s) {
  return fnv1a(h, s ? s : "", s ? strlen(s) : 0);
}

static void sweep_fingerprint(const cli_args *a, const char *scene, char out[17]) {
  uint64_t h = 0xcbf29ce484222325ull;
  h = fnv1a_str(h, MANIFEST_FORMAT);
  h = fnv1a_str(h, scene);
  const char *file = cli_get(a, "--contexts");
  if (file) {
    size_t len = 0;
    char *text = cli_read_file(file, &len);
    h = fnv1a(h, text ? text : "", text ? len : 0);
    free(text);
  }
  static const char *const keyed[] = {"--grid", "--set",    "--sensor",     "--spp",
                                      "--seed", "--format", "--quantities", "--variance"};
  for (size_t k = 0; k < sizeof keyed / sizeof keyed[0]; k++) {
    size_t n;
    const char *const *v = cli_get_all(a, keyed[k], &n);
    h = fnv1a_str(h, keyed[k]);
    for (size_t i = 0; i < n; i++) h = fnv1a_str(h, v[i]);
  }
  snprintf(out, 17, "%016llx", (unsigned long long)h);
}

static char *dir_file(const char *dir, const char *name) {
  size_t n = strlen(dir) + strlen(name) + 2;
  char *p = malloc(n);
  if (p) snprintf(p, n, "%s/%s", dir, name);
  return p;
}

typedef struct sweep_manifest {
  cJSON *root; /* owned */
  const char *sweep;
  size_t shard_i, shard_n, total;
  int id_width;
  const char **ids;        /* owned array of total ids (borrowed strings), or NULL: numbered */
  const char **incomplete; /* owned, sorted (strings borrowed from root) */
  size_t n_incomplete;
  bool finished;
} sweep_manifest;

static void manifest_free(sweep_manifest *m) {
  cJSON_Delete(m->root);
  free(m->ids);
  free(m->incomplete);
  memset(m, 0, sizeof *m);
}

/* The id of context k of the unsharded list a manifest describes. */
static const char *manifest_id(const sweep_manifest *m, size_t k, char buf[72]) {
  if (m->ids) return m->ids[k];
  make_id(buf, m->id_width, k);
  return buf;
}

static int cmp_str(const void *a, const void *b) {
  return strcmp(*(const char *const *)a, *(const char *const *)b);
}

static bool manifest_incomplete(const sweep_manifest *m, const char *id) {
  return m->n_incomplete && bsearch(&id, m->incomplete, m->n_incomplete, sizeof *m->incomplete, cmp_str);
}

/* Read and check DIR/sweep.json. 0, or -1 when absent (errno ENOENT), or a
 * CLI exit code after printing. */
static int manifest_read(const cli_ctx *ctx, const char *dir, sweep_manifest *m) {
  memset(m, 0, sizeof *m);
  char *path = dir_file(dir, MANIFEST_NAME);
  if (!path) return cli_fail(ctx, CLI_IO, "out of memory");
  size_t len;
  char *text = cli_read_file(path, &len);
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
  m->finished = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(r, "finished"));
  bool ok = m->sweep && cJSON_IsArray(shard) && cJSON_GetArraySize(shard) == 2 && json_is_int(total, 0) &&
            (ids ? cJSON_IsArray(ids) : json_is_int(width, 1)) && (!inc || cJSON_IsArray(inc));
  if (ok) {
    const cJSON *si = cJSON_GetArrayItem(shard, 0), *sn = cJSON_GetArrayItem(shard, 1);
    ok = json_is_int(si, 0) && json_is_int(sn, 1) && si->valuedouble < sn->valuedouble;
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
  if (ok && inc) {
    size_t n = (size_t)cJSON_GetArraySize(inc);
    m->incomplete = malloc((n ? n : 1) * sizeof *m->incomplete);
    const cJSON *v;
    cJSON_ArrayForEach(v, inc) {
      if (!m->incomplete || !cJSON_IsString(v)) break;
      m->incomplete[m->n_incomplete++] = v->valuestring;
    }
    ok = m->incomplete && m->n_incomplete == n;
    if (ok && n) qsort(m->incomplete, n, sizeof *m->incomplete, cmp_str);
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
static int manifest_write(const cli_ctx *ctx, const char *dir, const char *fingerprint, const char *scene,
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
      if (!l->all_ids[k]) make_id(buf, l->id_width, k);
      cJSON_AddItemToArray(ids, cJSON_CreateString(l->all_ids[k] ? l->all_ids[k] : buf));
    }
  } else {
    cJSON_AddNumberToObject(o, "id_width", l->id_width);
  }
  if (job && *job)
    cJSON_AddStringToObject(o, "job", job);
  else
    cJSON_AddNullToObject(o, "job");
  cJSON_AddBoolToObject(o, "finished", finished);
  cJSON_AddItemToObject(o, "incomplete", incomplete ? cJSON_Duplicate(incomplete, 1) : cJSON_CreateArray());
  char *text = cJSON_PrintUnformatted(o);
  cJSON_Delete(o);
  char *path = dir_file(dir, MANIFEST_NAME);
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

/* Entries of a directory other than "." and "..": count, and the first. */
static size_t dir_entries(DIR *d, char *first, size_t cap) {
  size_t n = 0;
  struct dirent *e;
  if (cap) first[0] = '\0';
  while ((e = readdir(d))) {
    if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0) continue;
    if (!n && cap) snprintf(first, cap, "%s", e->d_name);
    n++;
  }
  return n;
}

static bool is_regular(const char *path) {
  struct stat st;
  return lstat(path, &st) == 0 && S_ISREG(st.st_mode);
}

/* What a sweep writes into DIR/<context>/: <sensor>.exr|.npy|.json and
 * the temp files of an interrupted write (<name>.tmp.<pid>). */
static bool sweep_file_name(const char *name) {
  if (strstr(name, ".tmp.")) return true;
  const char *dot = strrchr(name, '.');
  return dot && (strcmp(dot, ".exr") == 0 || strcmp(dot, ".npy") == 0 || strcmp(dot, ".json") == 0);
}

/* DIR/dataset.nc: the films of index entries e (sorted: write_index) as
 * one NetCDF-4 dataset, built by libraysweep from the JSON films, so the
 * dataset of merged shards is the unsharded one's. Contexts come in index
 * order with the wavelength and coords of their index lines; a context
 * without any film is not in it. */
static int write_dataset(const cli_ctx *ctx, const char *dir, const index_entry *e, size_t n, bool has_seed,
                         long long seed) {
  rsw_dataset *d = NULL;
  if (rsw_dataset_new(&d)) return cli_fail(ctx, CLI_IO, "out of memory");
  char *out = dir_file(dir, DATASET_NAME);
  rsw_status s = out ? RSW_OK : RSW_ERR_NOMEM;
  if (!s && has_seed) s = rsw_dataset_set_seed(d, seed);
  const char *prev = NULL;
  char where[4200] = "";
  for (size_t i = 0; !s && i < n; i++) {
    const cJSON *line = e[i].line;
    const char *c = e[i].context, *sn = e[i].sensor;
    const char *file = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(line, "file"));
    if (!prev || strcmp(prev, c) != 0) {
      const cJSON *wl = cJSON_GetObjectItemCaseSensitive(line, "wavelength");
      const cJSON *co = cJSON_GetObjectItemCaseSensitive(line, "coords");
      char *ctext = co ? cJSON_PrintUnformatted(co) : NULL;
      snprintf(where, sizeof where, "index.jsonl context '%s'", c);
      s = co && !ctext ? RSW_ERR_NOMEM
                       : rsw_dataset_add_context(d, c, cJSON_IsNumber(wl) ? wl->valuedouble : 0, ctext);
      free(ctext);
      prev = c;
    }
    if (!s) {
      snprintf(where, sizeof where, "%s/%s", dir, file ? file : "?");
      s = file ? rsw_dataset_add_film_file(d, c, sn, where) : RSW_ERR_INVALID;
    }
  }
  if (!s) {
    snprintf(where, sizeof where, "%s", out);
    s = rsw_dataset_write(d, out);
  }
  int rc = CLI_OK;
  if (s)
    rc = cli_fail(ctx, s == RSW_ERR_IO ? CLI_IO : CLI_USAGE, "%s: %s", where,
                  rsw_dataset_last_error(d)[0] ? rsw_dataset_last_error(d) : rsw_strerror(s));
  else if (!ctx->quiet)
    fprintf(stderr, "raysweep %s: dataset %s\n", ctx->cmd, out);
  free(out);
  rsw_dataset_free(d);
  return rc;
}

/* Remove DIR/<context>/'s sweep files and the directory when that empties
 * it. Symbolic links are not followed. Returns the files removed. */
static size_t remove_context_dir(const char *dir, const char *context) {
  if (!cli_safe_component(context)) return 0;
  char *cdir = dir_file(dir, context);
  struct stat st;
  size_t removed = 0;
  if (cdir && lstat(cdir, &st) == 0 && S_ISDIR(st.st_mode)) {
    DIR *d = opendir(cdir);
    struct dirent *e;
    while (d && (e = readdir(d))) {
      if (!sweep_file_name(e->d_name)) continue;
      char *f = dir_file(cdir, e->d_name);
      if (f && is_regular(f) && unlink(f) == 0) removed++;
      free(f);
    }
    if (d) closedir(d);
    rmdir(cdir); /* fails, as it should, when something else is left */
  }
  free(cdir);
  return removed;
}

/* Make -o DIR ready: create it when absent; an empty one is fine. A
 * non-empty one is refused unless --force and it holds an earlier sweep
 * (sweep.json or index.jsonl): then exactly what that sweep wrote goes
 * (its films, the temp files of an interrupted write, emptied context
 * directories, index.jsonl, sweep.json) and anything else stays. A
 * directory holding no sweep is never emptied: a mistyped -o must not
 * cost someone their files. */
static int prepare_output(const cli_ctx *ctx, const char *dir, bool force) {
  char first[256];
  DIR *d = opendir(dir);
  if (!d) {
    if (errno == ENOENT) {
      if (cli_mkdirs(dir)) return cli_fail(ctx, CLI_IO, "cannot create '%s': %s", dir, strerror(errno));
      return 0;
    }
    return cli_fail(ctx, CLI_IO, "-o %s: %s", dir, strerror(errno));
  }
  size_t n = dir_entries(d, first, sizeof first);
  closedir(d);
  if (n == 0) return 0;
  if (!force)
    return cli_usage(ctx,
                     "-o %s: the directory is not empty (%zu entr%s, e.g. '%s'); give a new or empty "
                     "directory, or add --force to replace the earlier sweep in it",
                     dir, n, n == 1 ? "y" : "ies", first);
  char *index = dir_file(dir, "index.jsonl"), *manifest = dir_file(dir, MANIFEST_NAME);
  if (!index || !manifest) {
    free(index), free(manifest);
    return cli_fail(ctx, CLI_IO, "out of memory");
  }
  bool has_index = is_regular(index), has_manifest = is_regular(manifest);
  char *state = dir_file(dir, SPREAD_STATE);
  if (state && is_regular(state)) unlink(state); /* the journal of an earlier --spread */
  free(state);
  if (!has_index && !has_manifest) {
    free(index), free(manifest);
    return cli_usage(ctx,
                     "-o %s: --force replaces an earlier sweep, but this non-empty directory holds none "
                     "(no %s or index.jsonl); nothing was deleted: give a new or empty directory",
                     dir, MANIFEST_NAME);
  }
  size_t removed = 0;
  if (has_index) { /* every context the index names */
    char *text = cli_read_file(index, NULL);
    for (char *s = text, *nl; s && *s; s = nl ? nl + 1 : s + strlen(s)) {
      nl = strchr(s, '\n');
      if (nl) *nl = '\0';
      cJSON *o = cJSON_Parse(s);
      const char *c = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "context"));
      if (c) removed += remove_context_dir(dir, c);
      cJSON_Delete(o);
    }
    free(text);
  }
  sweep_manifest m;
  int mrc = has_manifest ? manifest_read(ctx, dir, &m) : -1;
  if (mrc > 0) {
    free(index), free(manifest);
    return mrc;
  }
  if (mrc == 0) { /* every context of its shard (an interrupted sweep has no index yet) */
    char buf[72];
    for (size_t k = m.shard_i; k < m.total; k += m.shard_n)
      removed += remove_context_dir(dir, manifest_id(&m, k, buf));
    manifest_free(&m);
  }
  char *dataset = dir_file(dir, DATASET_NAME);
  if (dataset && is_regular(dataset)) unlink(dataset);
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
  size_t left = d ? dir_entries(d, first, sizeof first) : 0;
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

/* ---- --spread K: the shards of one sweep at once, through a balancer ---- */

/* DIR holds an unfinished --spread run of this very sweep: rerunning the
 * command resumes it instead of refusing a non-empty directory. */
static bool spread_resumable(const char *dir, const char *fingerprint) {
  char *state = dir_file(dir, SPREAD_STATE);
  bool has = state && is_regular(state);
  free(state);
  if (!has) return false;
  sweep_manifest m;
  cli_ctx quiet = {.cmd = "sweep", .quiet = true};
  if (manifest_read(&quiet, dir, &m) != 0) return false;
  bool same = strcmp(m.sweep, fingerprint) == 0 && !m.finished;
  manifest_free(&m);
  return same;
}

typedef struct spread_sink {
  cli_ctx *ctx;
  const char *dir;
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
} spread_sink;

/* rsw_spread_film_fn: save the film (or, resumed, find the one an earlier
 * run saved) and keep its index line. */
static int spread_film(void *user, const char *c, const char *sn, const char *result_json,
                       const rsw_film *film, int resumed) {
  spread_sink *k = user;
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
  if (!cli_safe_component(c) || !cli_safe_component(sn)) {
    k->rc = cli_fail(k->ctx, CLI_IO, "%s/%s: not usable as a file name", c, sn);
    cJSON_Delete(r);
    return 1;
  }
  char rel[600], path[4096];
  snprintf(path, sizeof path, "%s/%s", k->dir, c);
  snprintf(rel, sizeof rel, "%s/%s.%s", c, sn, cli_format_ext(k->fmt));
  if (film) {
    if (cli_mkdirs(path)) {
      k->rc = cli_fail(k->ctx, CLI_IO, "cannot create '%s': %s", path, strerror(errno));
    } else {
      snprintf(path, sizeof path, "%s/%s", k->dir, rel);
      k->rc = cli_save_film(k->ctx, film, path, k->fmt);
    }
  } else if (resumed) {
    snprintf(path, sizeof path, "%s/%s", k->dir, rel);
    if (!is_regular(path))
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
  cJSON *line = index_line(r, c, sn, rel, k->sorted, k->n, k->job_params);
  cJSON_Delete(r);
  index_entry *e = &k->e[k->ne];
  memset(e, 0, sizeof *e);
  e->line = line;
  e->context = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(line, "context"));
  e->sensor = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(line, "sensor"));
  e->order = k->ne++;
  return 0;
}

static int run_spread(cli_ctx *ctx, const cli_args *a, int k_shards, bool resume, cli_format fmt,
                      double timeout, const sweep_list *l, sweep_item **sorted, const cJSON *job_params,
                      const rsw_contexts *x, const char *fingerprint, size_t shard_i, size_t shard_n) {
  const char *scene = a->pos[0], *dir = cli_get(a, "-o");
  struct stat sst;
  bool scene_is_file = stat(scene, &sst) == 0 && S_ISREG(sst.st_mode);
  char *state = dir_file(dir, SPREAD_STATE);
  cli_progress p;
  cli_progress_init(&p, ctx);
  spread_sink sink = {.ctx = ctx,
                      .dir = dir,
                      .fmt = fmt,
                      .sorted = sorted,
                      .n = l->n,
                      .job_params = job_params,
                      .incomplete = cJSON_CreateArray(),
                      .progress = &p};
  int rc = 0;
  if (!state || !sink.incomplete) {
    rc = cli_fail(ctx, CLI_IO, "out of memory");
    goto out;
  }
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
                        .shards = k_shards,
                        .scene_file = scene_is_file ? scene : NULL,
                        .state_path = state,
                        .timeout_s = timeout,
                        .progress = ctx->quiet ? NULL : cli_progress_cb,
                        .progress_user = &p,
                        .on_film = spread_film,
                        .film_user = &sink};
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
  sweep_fingerprint(a, res.scene_id, fp2);
  if ((rc = write_index(ctx, dir, sink.e, sink.ne))) goto out;
  if (l->dataset && (rc = write_dataset(ctx, dir, sink.e, sink.ne, true, l->seed))) goto out;
  cJSON *inc = cJSON_CreateArray();
  const char *prev = NULL;
  /* incomplete ids sorted, each once */
  size_t ni = (size_t)cJSON_GetArraySize(sink.incomplete);
  const char **ids = malloc((ni ? ni : 1) * sizeof *ids);
  size_t m = 0;
  const cJSON *it;
  cJSON_ArrayForEach(it, sink.incomplete) if (ids) ids[m++] = it->valuestring;
  if (ids && m) qsort(ids, m, sizeof *ids, cmp_str);
  for (size_t i = 0; ids && i < m; i++)
    if (!prev || strcmp(prev, ids[i]) != 0) cJSON_AddItemToArray(inc, cJSON_CreateString(prev = ids[i]));
  free(ids);
  rc = manifest_write(ctx, dir, fp2, res.scene_id, shard_i, shard_n, l, NULL, true, inc);
  cJSON_Delete(inc);
  if (rc) goto out;
  unlink(state);
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
    char *t = cJSON_PrintUnformatted(o);
    if (t) printf("%s\n", t);
    free(t);
    cJSON_Delete(o);
  } else if (!ctx->quiet) {
    fprintf(
        stderr,
        "raysweep sweep: %zu films in %s%s (%d shards; %zu resubmission%s of %zu contexts; %zu films from an "
        "earlier run)\n",
        sink.ne, dir, res.failed ? " (some renders failed)" : "", k_shards, res.resubmitted,
        res.resubmitted == 1 ? "" : "s", res.contexts_resubmitted, res.resumed);
  }
out:
  entries_free(sink.e, sink.ne);
  cJSON_Delete(sink.incomplete);
  free(state);
  return rc;
}

int cmd_sweep(cli_ctx *ctx, const cli_args *a) {
  const char *scene = a->pos[0], *dir = cli_get(a, "-o"), *contexts_file = cli_get(a, "--contexts");
  size_t n_grids;
  const char *const *grids = cli_get_all(a, "--grid", &n_grids);
  if (!dir) return cli_usage(ctx, "missing -o DIR");
  if (!contexts_file == !n_grids)
    return cli_usage(ctx, "give either --contexts FILE.jsonl or --grid NAME=START:STOP:STEP");
  if (n_grids > MAX_GRIDS) return cli_usage(ctx, "at most %d --grid axes", MAX_GRIDS);
  const char *v;
  cli_format fmt = CLI_FMT_EXR;
  bool want_nc = (v = cli_get(a, "--format")) && strcmp(v, "nc") == 0;
  if (want_nc)
    fmt = CLI_FMT_JSON; /* the films the dataset is built from (and merge rebuilds it from) */
  else if (v && (fmt = cli_format_from_name(v)) == CLI_FMT_NONE)
    return cli_usage(ctx, "--format needs exr, npy, json or nc (got '%s')", v);
  unsigned long long spp = 0, seed = 0, shard_i = 0, shard_n = 1;
  if ((v = cli_get(a, "--spp")) && (!cli_parse_u64(v, 1ull << 31, &spp) || spp == 0))
    return cli_usage(ctx, "--spp needs a positive integer (got '%s')", v);
  if ((v = cli_get(a, "--seed")) && !cli_parse_u64(v, (1ull << 53) - 1, &seed))
    return cli_usage(ctx, "--seed needs an integer in [0, 2^53) (got '%s')", v);
  if ((v = cli_get(a, "--shard"))) {
    const char *slash = strchr(v, '/');
    char ib[32];
    if (!slash || (size_t)(slash - v) >= sizeof ib) return cli_usage(ctx, "--shard needs I/N (got '%s')", v);
    memcpy(ib, v, (size_t)(slash - v));
    ib[slash - v] = '\0';
    if (!cli_parse_u64(ib, MAX_CONTEXTS, &shard_i) || !cli_parse_u64(slash + 1, MAX_CONTEXTS, &shard_n) ||
        shard_n == 0 || shard_i >= shard_n)
      return cli_usage(ctx, "--shard needs I/N with 0 <= I < N (got '%s')", v);
  }
  unsigned long long spread = 0;
  if ((v = cli_get(a, "--spread")) && (!cli_parse_u64(v, 4096, &spread) || spread == 0))
    return cli_usage(ctx, "--spread needs a number of shards from 1 to 4096 (got '%s')", v);
  double timeout = 0;
  if ((v = cli_get(a, "--timeout")) && (!cli_parse_double(v, &timeout) || !(timeout > 0)))
    return cli_usage(ctx, "--timeout needs a positive number of seconds (got '%s')", v);
  size_t n_sets;
  const char *const *sets = cli_get_all(a, "--set", &n_sets);
  cJSON *job_params = NULL;
  int rc = cli_build_param_map(ctx, "--set", sets, n_sets, &job_params);
  if (rc) return rc;

  sweep_list l = {.seed = (long long)seed, .dataset = want_nc};
  grid_axis axes[MAX_GRIDS] = {{0}};
  sweep_item **sorted = NULL;
  rsw_contexts *x = NULL;
  index_entry *entries = NULL;
  size_t n_entries = 0, failed = 0;
  char job[40] = "", fingerprint[17] = "", scene_id[65] = "";
  cJSON *incomplete = NULL;
  if (contexts_file) {
    rc = read_contexts(ctx, contexts_file, shard_i, shard_n, &l);
  } else {
    for (size_t i = 0; i < n_grids && !rc; i++) {
      rc = parse_grid(ctx, grids[i], &axes[i]);
      for (size_t k = 0; k < i && !rc; k++)
        if (strcmp(axes[k].name, axes[i].name) == 0)
          rc = cli_usage(ctx, "--grid %s given twice", axes[i].name);
    }
    if (!rc) axis_coords(axes, n_grids);
    if (!rc) rc = build_grid(ctx, axes, n_grids, shard_i, shard_n, &l);
  }
  if (rc) goto out;
  sorted = malloc((l.n ? l.n : 1) * sizeof *sorted);
  if (!sorted) {
    rc = cli_fail(ctx, CLI_IO, "out of memory");
    goto out;
  }
  for (size_t i = 0; i < l.n; i++) sorted[i] = &l.items[i];
  qsort(sorted, l.n, sizeof *sorted, cmp_item_id);
  for (size_t i = 0; i < l.n; i++) {
    if (!cli_safe_component(sorted[i]->id)) {
      rc = cli_usage(ctx, "context id '%s' cannot name a directory", sorted[i]->id);
      goto out;
    }
    if (i && strcmp(sorted[i]->id, sorted[i - 1]->id) == 0) {
      rc = cli_usage(ctx, "context id '%s' appears twice", sorted[i]->id);
      goto out;
    }
  }
  /* Everything the user described is checked: now the directory. */
  sweep_fingerprint(a, scene, fingerprint);
  bool resume = spread && !cli_has(a, "--force") && spread_resumable(dir, fingerprint);
  if (!resume && (rc = prepare_output(ctx, dir, cli_has(a, "--force")))) goto out;
  if (l.n == 0) {
    /* A shard past the end of a short list: nothing to submit, an empty
     * index keeps `merge` simple. */
    if (!ctx->quiet) fprintf(stderr, "raysweep sweep: shard %llu/%llu has no contexts\n", shard_i, shard_n);
    rc = write_index(ctx, dir, NULL, 0);
    if (!rc) rc = manifest_write(ctx, dir, fingerprint, scene, shard_i, shard_n, &l, NULL, true, NULL);
    goto out;
  }
  /* The job lists the contexts in the order the user described them. */
  if ((rc = build_contexts(ctx, a, l.items, l.n, job_params, (long long)spp, (long long)seed, &x))) goto out;
  struct stat sst;
  if (!spread && stat(scene, &sst) == 0 && S_ISREG(sst.st_mode)) {
    /* A scene FILE: push it (blobs it references too) and sweep its id. */
    int created = 0;
    rsw_status ps = rsw_scene_push_file(ctx->client, scene, NULL, scene_id, &created);
    if (ps) {
      rc = cli_report(ctx, ps, scene);
      goto out;
    }
    scene = scene_id;
    sweep_fingerprint(a, scene, fingerprint);
  }
  if (spread) {
    rc = run_spread(ctx, a, (int)spread, resume, fmt, timeout, &l, sorted, job_params, x, fingerprint,
                    (size_t)shard_i, (size_t)shard_n);
    goto out;
  }
  cli_catch_interrupt();
  rsw_status s = rsw_job_submit(ctx->client, scene, x, NULL, job);
  if (s && cli_interrupted) {
    rc = cli_fail(ctx, cli_interrupted_code(),
                  "%s while submitting the job (if the daemon got it, `raysweep job ls` shows it)",
                  cli_interrupted_word());
    goto out;
  }
  if (s) {
    rc = cli_report(ctx, s, scene);
    goto out;
  }
  if (!ctx->quiet)
    fprintf(stderr, "raysweep sweep: job %s: %zu contexts%s\n", job, l.n, shard_n > 1 ? " (one shard)" : "");
  cli_print_job_warnings(ctx, "raysweep sweep", job);
  /* Written before any film, so a sweep that dies half-way leaves a
   * directory that says so (merge lists its contexts as missing; --force
   * knows what to clean). */
  if ((rc = manifest_write(ctx, dir, fingerprint, scene, shard_i, shard_n, &l, job, false, NULL))) goto out;
  rsw_job_status st;
  /* Ctrl-C cancels the job (this command submitted it) and writes no films. */
  rc = cli_wait_job(ctx, job, timeout, CLI_INTERRUPT_CANCEL, &st);
  if (rc != CLI_OK && rc != CLI_JOB) goto out;
  int job_rc = rc;
  if (!(incomplete = cJSON_CreateArray())) {
    rc = cli_fail(ctx, CLI_IO, "out of memory");
    goto out;
  }
  if ((rc = fetch_all(ctx, job, dir, fmt, sorted, l.n, job_params, incomplete, &entries, &n_entries,
                      &failed))) {
    if (cli_interrupted)
      rc = cli_fail(ctx, cli_interrupted_code(),
                    "%s while fetching films; job %s is over and keeps its results on the daemon "
                    "(`raysweep fetch %s CONTEXT SENSOR`, or sweep again)",
                    cli_interrupted_word(), job, job);
    goto out;
  }
  if ((rc = write_index(ctx, dir, entries, n_entries))) goto out;
  if (want_nc && (rc = write_dataset(ctx, dir, entries, n_entries, true, l.seed))) goto out;
  if ((rc = manifest_write(ctx, dir, fingerprint, scene, shard_i, shard_n, &l, job, true, incomplete)))
    goto out;
  rc = job_rc;
  if (ctx->json) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "job", job);
    cJSON_AddStringToObject(o, "state", cli_job_state_name(st.state));
    cJSON_AddStringToObject(o, "dir", dir);
    cJSON_AddNumberToObject(o, "contexts", (double)l.n);
    cJSON_AddNumberToObject(o, "films", (double)n_entries);
    cJSON_AddNumberToObject(o, "failed", (double)failed);
    char *t = cJSON_PrintUnformatted(o);
    if (t) printf("%s\n", t);
    free(t);
    cJSON_Delete(o);
  } else if (!ctx->quiet) {
    fprintf(stderr, "raysweep sweep: %zu films in %s%s\n", n_entries, dir,
            failed ? " (some renders failed)" : "");
  }
out:
  cJSON_Delete(incomplete);
  entries_free(entries, n_entries);
  rsw_contexts_free(x);
  free(sorted);
  items_free(&l);
  for (size_t i = 0; i < MAX_GRIDS; i++) free(axes[i].name);
  cJSON_Delete(job_params);
  return rc;
}

/* ---- merge ---- */

/* A relative path inside a sweep directory: no leading '/', no "..". */
static bool safe_relative(const char *p) {
  if (!p || !*p || p[0] == '/') return false;
  for (const char *s = p; *s;) {
    const char *e = strchr(s, '/');
    size_t n = e ? (size_t)(e - s) : strlen(s);
    if (n == 0 || (n == 2 && s[0] == '.' && s[1] == '.')) return false;
    s += n + (e ? 1 : 0);
  }
  return true;
}

static bool same_bytes(const char *a, const char *b) {
  size_t la, lb;
  char *x = cli_read_file(a, &la), *y = cli_read_file(b, &lb);
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
  char *data = cli_read_file(src, &len);
  if (!data) return -1;
  int rc = cli_write_file_atomic(dst, data, len);
  free(data);
  return rc;
}

static int read_index(const cli_ctx *ctx, const char *dir, size_t input, index_entry **e, size_t *n,
                      size_t *cap) {
  size_t pn = strlen(dir) + 16;
  char *path = malloc(pn);
  if (!path) return cli_fail(ctx, CLI_IO, "out of memory");
  snprintf(path, pn, "%s/index.jsonl", dir);
  char *text = cli_read_file(path, NULL);
  if (!text) {
    int rc = cli_fail(ctx, CLI_IO, "cannot read '%s': %s", path, strerror(errno));
    free(path);
    return rc;
  }
  int rc = 0;
  size_t line = 0;
  for (char *s = text, *nl; *s && !rc; s = nl ? nl + 1 : s + strlen(s)) {
    nl = strchr(s, '\n');
    if (nl) *nl = '\0';
    line++;
    if (!*s) continue;
    cJSON *o = cJSON_Parse(s);
    const char *c = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "context"));
    const char *sn = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "sensor"));
    const char *file = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "file"));
    if (!c || !sn || !safe_relative(file)) {
      cJSON_Delete(o);
      rc = cli_fail(ctx, CLI_IO, "%s:%zu: not an index line (context, sensor and a relative file)", path,
                    line);
      break;
    }
    if (*n == *cap) {
      size_t nc = *cap ? *cap * 2 : 64;
      index_entry *ne = realloc(*e, nc * sizeof *ne);
      if (!ne) {
        cJSON_Delete(o);
        rc = cli_fail(ctx, CLI_IO, "out of memory");
        break;
      }
      *e = ne, *cap = nc;
    }
    index_entry *it = &(*e)[*n];
    size_t sl = strlen(dir) + strlen(file) + 2;
    it->src = malloc(sl);
    if (!it->src) {
      cJSON_Delete(o);
      rc = cli_fail(ctx, CLI_IO, "out of memory");
      break;
    }
    snprintf(it->src, sl, "%s/%s", dir, file);
    it->line = o, it->context = c, it->sensor = sn, it->order = *n, it->input = input;
    (*n)++;
  }
  free(text);
  free(path);
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
        covered =
            in[j].has_index && m->finished && k % m->shard_n == m->shard_i && !manifest_incomplete(m, id);
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

int cmd_merge(cli_ctx *ctx, const cli_args *a) {
  const char *out = cli_get(a, "-o");
  if (!out) return cli_usage(ctx, "missing -o DIR");
  bool partial = cli_has(a, "--partial");
  index_entry *e = NULL;
  size_t n = 0, cap = 0, dups = 0, n_sweeps = 0, missing = 0;
  cJSON *missing_ids = NULL;
  int rc = 0;
  merge_input *in = calloc(a->n_pos, sizeof *in);
  if (!in) return cli_fail(ctx, CLI_IO, "out of memory");
  for (size_t i = 0; i < a->n_pos && !rc; i++) {
    in[i].dir = a->pos[i];
    int mrc = manifest_read(ctx, a->pos[i], &in[i].m);
    if (mrc > 0) {
      rc = mrc;
      break;
    }
    in[i].has_manifest = mrc == 0;
    char *index = dir_file(a->pos[i], "index.jsonl");
    in[i].has_index = index && is_regular(index);
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
    rc = read_index(ctx, a->pos[i], i, &e, &n, &cap);
  }
  if (rc) goto done;
  if (n) qsort(e, n, sizeof *e, cmp_entry);
  /* Duplicates (a shard given twice, overlapping shards): the same film is
   * kept once; different films for one (context, sensor) are refused. */
  size_t kept = 0;
  for (size_t i = 0; i < n; i++) {
    if (kept && strcmp(e[kept - 1].context, e[i].context) == 0 &&
        strcmp(e[kept - 1].sensor, e[i].sensor) == 0) {
      if (!same_bytes(e[kept - 1].src, e[i].src)) {
        rc = cli_fail(ctx, CLI_IO, "%s/%s is in two inputs with different films: %s and %s", e[i].context,
                      e[i].sensor, e[kept - 1].src, e[i].src);
        for (size_t k = i; k < n; k++) {
          cJSON_Delete(e[k].line);
          free(e[k].src);
        }
        n = kept;
        goto done;
      }
      dups++;
      cJSON_Delete(e[i].line);
      free(e[i].src);
      continue;
    }
    e[kept++] = e[i];
  }
  n = kept;
  /* Nothing is written before the inputs are known to be complete. */
  missing = merge_missing(ctx, in, a->n_pos, e, n, partial, &n_sweeps, &missing_ids);
  if (missing && !partial) {
    rc = cli_fail(ctx, CLI_IO,
                  "%zu context%s missing: nothing was written (give the missing shards, or "
                  "--partial to merge what is there)",
                  missing, missing == 1 ? " is" : "s are");
    goto done;
  }
  if (cli_mkdirs(out)) {
    rc = cli_fail(ctx, CLI_IO, "cannot create '%s': %s", out, strerror(errno));
    goto done;
  }
  for (size_t i = 0; i < n && !rc; i++) {
    const char *file = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(e[i].line, "file"));
    size_t dl = strlen(out) + strlen(file) + 2;
    char *dst = malloc(dl);
    if (!dst) {
      rc = cli_fail(ctx, CLI_IO, "out of memory");
      break;
    }
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
  if (!rc) rc = write_index(ctx, out, e, n);
  /* Inputs swept with --format nc: the merged dataset, rebuilt from the
   * films (bitwise the unsharded sweep's data). */
  bool all_nc = a->n_pos > 0;
  for (size_t i = 0; i < a->n_pos && all_nc; i++) {
    char *p = dir_file(a->pos[i], DATASET_NAME);
    all_nc = p && is_regular(p);
    free(p);
  }
  if (!rc && all_nc) {
    const cJSON *seed = NULL;
    for (size_t i = 0; i < a->n_pos && !seed; i++)
      if (in[i].has_manifest) seed = cJSON_GetObjectItemCaseSensitive(in[i].m.root, "seed");
    rc = write_dataset(ctx, out, e, n, json_is_int(seed, 0),
                       json_is_int(seed, 0) ? (long long)seed->valuedouble : 0);
  }
  bool legacy = false;
  for (size_t i = 0; i < a->n_pos; i++) legacy = legacy || !in[i].has_manifest;
  if (!rc && n_sweeps == 1 && !legacy) {
    /* The merged directory is that sweep unsharded (as complete as the
     * inputs: what is missing is listed as incomplete). */
    const sweep_manifest *m0 = NULL;
    for (size_t i = 0; i < a->n_pos && !m0; i++) m0 = in[i].has_manifest ? &in[i].m : NULL;
    cJSON *o = cJSON_Duplicate(m0->root, 1);
    cJSON *sh = cJSON_CreateArray();
    cJSON_AddItemToArray(sh, cJSON_CreateNumber(0));
    cJSON_AddItemToArray(sh, cJSON_CreateNumber(1));
    cJSON_ReplaceItemInObjectCaseSensitive(o, "shard", sh);
    cJSON_ReplaceItemInObjectCaseSensitive(o, "job", cJSON_CreateNull());
    cJSON_ReplaceItemInObjectCaseSensitive(o, "finished", cJSON_CreateTrue());
    cJSON_ReplaceItemInObjectCaseSensitive(o, "incomplete", cJSON_Duplicate(missing_ids, 1));
    char *text = cJSON_PrintUnformatted(o);
    char *path = dir_file(out, MANIFEST_NAME);
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
  }
  if (!rc) {
    if (ctx->json) {
      cJSON *o = cJSON_CreateObject();
      cJSON_AddStringToObject(o, "dir", out);
      cJSON_AddNumberToObject(o, "films", (double)n);
      cJSON_AddNumberToObject(o, "duplicates", (double)dups);
      char *t = cJSON_PrintUnformatted(o);
      if (t) printf("%s\n", t);
      free(t);
      cJSON_Delete(o);
    } else if (!ctx->quiet)
      fprintf(stderr, "raysweep merge: %zu films in %s%s\n", n, out,
              dups ? " (identical duplicates kept once)" : "");
  }
done:
  entries_free(e, n);
  for (size_t i = 0; i < a->n_pos; i++) manifest_free(&in[i].m);
  free(in);
  cJSON_Delete(missing_ids);
  return rc;
}
