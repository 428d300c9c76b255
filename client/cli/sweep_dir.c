/* The sweep directory's shared pieces (sweep.h): index.jsonl, dataset.nc,
 * context ids and file helpers, for sweep, --spread and merge. */
#include <cjson/cJSON.h>
#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "sweep.h"

char *sweep_dir_file(const char *dir, const char *name) {
  size_t n = strlen(dir) + strlen(name) + 2;
  char *p = malloc(n);
  if (p) snprintf(p, n, "%s/%s", dir, name);
  return p;
}

/* Entries of a directory other than "." and "..": count, and the first. */
size_t sweep_dir_entries(DIR *d, char *first, size_t cap) {
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

bool sweep_is_regular(const char *path) {
  struct stat st;
  return lstat(path, &st) == 0 && S_ISREG(st.st_mode);
}

bool sweep_json_is_int(const cJSON *v, double lo) {
  return cJSON_IsNumber(v) && v->valuedouble >= lo && v->valuedouble == floor(v->valuedouble) &&
         v->valuedouble < 9007199254740992.0;
}

/* A relative path inside a sweep directory: no leading '/', no "..". */
bool sweep_safe_relative(const char *p) {
  if (!p || !*p || p[0] == '/') return false;
  for (const char *s = p; *s;) {
    const char *e = strchr(s, '/');
    size_t n = e ? (size_t)(e - s) : strlen(s);
    if (n == 0 || (n == 2 && s[0] == '.' && s[1] == '.')) return false;
    s += n + (e ? 1 : 0);
  }
  return true;
}

bool sweep_layout_from_name(const char *name, sweep_layout *out) {
  if (name && strcmp(name, "dirs") == 0) return *out = SWEEP_LAYOUT_DIRS, true;
  if (name && strcmp(name, "flat") == 0) return *out = SWEEP_LAYOUT_FLAT, true;
  return false;
}

const char *sweep_layout_name(sweep_layout l) {
  return l == SWEEP_LAYOUT_FLAT ? "flat" : "dirs";
}

int sweep_film_file(const cli_ctx *ctx, const char *dir, sweep_layout layout, const char *c, const char *sn,
                    cli_format fmt, bool mkdir, char *rel, size_t rel_cap, char *path, size_t path_cap) {
  if (!cli_safe_component(c) || !cli_safe_component(sn))
    return cli_fail(ctx, CLI_IO, "%s/%s: not usable as a file name", c, sn);
  const char *ext = cli_format_ext(fmt);
  int n;
  if (layout == SWEEP_LAYOUT_FLAT) {
    char esc[3 * 256 + 1];
    size_t k = 0;
    const char *p = c;
    for (; *p && k + 4 <= sizeof esc; p++) {
      if (*p == '%' || *p == '.') {
        memcpy(esc + k, *p == '%' ? "%25" : "%2E", 3);
        k += 3;
      } else {
        esc[k++] = *p;
      }
    }
    esc[k] = '\0';
    n = snprintf(rel, rel_cap, "%s.%s.%s", esc, sn, ext);
    /* one name in DIR: at most 255 bytes (NAME_MAX) */
    if (*p || n < 0 || (size_t)n >= rel_cap || !cli_safe_component(rel))
      return cli_fail(ctx, CLI_IO, "%s/%s: too long for one file name with --layout flat (at most 255 bytes)",
                      c, sn);
  } else {
    n = snprintf(path, path_cap, "%s/%s", dir, c);
    if (n < 0 || (size_t)n >= path_cap) return cli_fail(ctx, CLI_IO, "%s/%s: path too long", dir, c);
    if (mkdir && cli_mkdirs(path))
      return cli_fail(ctx, CLI_IO, "cannot create '%s': %s", path, strerror(errno));
    n = snprintf(rel, rel_cap, "%s/%s.%s", c, sn, ext);
    if (n < 0 || (size_t)n >= rel_cap)
      return cli_fail(ctx, CLI_IO, "%s/%s: not usable as a file name", c, sn);
  }
  n = snprintf(path, path_cap, "%s/%s", dir, rel);
  if (n < 0 || (size_t)n >= path_cap) return cli_fail(ctx, CLI_IO, "%s/%s: path too long", dir, rel);
  return 0;
}

bool sweep_flat_context(const char *name, char *out) {
  const char *dot = strchr(name, '.');
  if (!dot || dot == name) return false;
  size_t k = 0;
  for (const char *p = name; p < dot; p++) {
    if (*p != '%') {
      out[k++] = *p;
    } else if (p + 2 < dot && p[1] == '2' && (p[2] == '5' || p[2] == 'E')) {
      out[k++] = p[2] == '5' ? '%' : '.';
      p += 2;
    } else {
      return false;
    }
  }
  out[k] = '\0';
  /* the rest: SENSOR.EXT, or its temp file SENSOR.EXT.tmp.PID */
  const char *rest = dot + 1, *tmp = NULL;
  for (const char *t = strstr(rest, ".tmp."); t; t = strstr(t + 1, ".tmp.")) tmp = t; /* the last */
  if (tmp && !tmp[5]) tmp = NULL;
  for (const char *p = tmp ? tmp + 5 : ""; *p; p++)
    if (*p < '0' || *p > '9') tmp = NULL;
  size_t len = tmp ? (size_t)(tmp - rest) : strlen(rest);
  static const char *const exts[] = {".exr", ".npy", ".json"};
  for (size_t i = 0; i < 3; i++) {
    size_t el = strlen(exts[i]);
    if (len > el && strncmp(rest + len - el, exts[i], el) == 0) return true;
  }
  return false;
}

/* "c" + index zero-padded to at least 5 digits; the width is that of the
 * largest index, so every id of one sweep has the same width and ids sort
 * in list order. */
int sweep_id_width(size_t total) {
  int w = 1;
  for (size_t m = total > 0 ? total - 1 : 0; m >= 10; m /= 10) w++;
  return w < 5 ? 5 : w;
}

void sweep_make_id(char out[72], int width, size_t index) {
  char digits[24];
  int len = snprintf(digits, sizeof digits, "%zu", index);
  int pad = width > len ? width - len : 0;
  out[0] = 'c';
  memset(out + 1, '0', (size_t)pad);
  memcpy(out + 1 + pad, digits, (size_t)len + 1);
}

int sweep_cmp_item_id(const void *a, const void *b) {
  return strcmp((*(const sweep_item *const *)a)->id, (*(const sweep_item *const *)b)->id);
}

int sweep_cmp_entry(const void *a, const void *b) {
  const index_entry *x = a, *y = b;
  int c = strcmp(x->context, y->context);
  if (!c) c = strcmp(x->sensor, y->sensor);
  if (!c) c = x->order < y->order ? -1 : x->order > y->order;
  return c;
}

/* index.jsonl: one line per film, sorted by context then sensor, so a
 * merged directory's index equals the unsharded one byte for byte. */
int sweep_write_index(const cli_ctx *ctx, const char *dir, index_entry *e, size_t n) {
  if (n) qsort(e, n, sizeof *e, sweep_cmp_entry);
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

void sweep_entries_free_range(index_entry *e, size_t from, size_t to) {
  for (size_t i = from; i < to; i++) {
    cJSON_Delete(e[i].line);
    free(e[i].src);
  }
}

void sweep_entries_free(index_entry *e, size_t n) {
  sweep_entries_free_range(e, 0, n);
  free(e);
}

int sweep_read_index(const cli_ctx *ctx, const char *dir, size_t input, index_entry **e, size_t *n,
                     size_t *cap) {
  size_t pn = strlen(dir) + 16;
  char *path = malloc(pn);
  if (!path) return cli_fail(ctx, CLI_IO, "out of memory");
  snprintf(path, pn, "%s/index.jsonl", dir);
  char *text = rsw_read_file(path, NULL);
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
    if (!c || !sn || !sweep_safe_relative(file)) {
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

/* One index.jsonl line for result r (the job's result object) of film
 * rel: wavelength and seed as the server used them; params the effective
 * overrides (job-level, then the context's own). */
cJSON *sweep_index_line(const cJSON *r, const char *c, const char *sn, const char *rel, sweep_item **sorted,
                        size_t n, const cJSON *job_params) {
  cJSON *line = cJSON_CreateObject();
  cJSON_AddStringToObject(line, "context", c);
  cJSON_AddStringToObject(line, "sensor", sn);
  const cJSON *wl = cJSON_GetObjectItemCaseSensitive(r, "wavelength");
  sweep_item key, *kp = &key;
  snprintf(key.id, sizeof key.id, "%s", c);
  sweep_item **found = bsearch(&kp, sorted, n, sizeof *sorted, sweep_cmp_item_id);
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
  if (rel)
    cJSON_AddStringToObject(line, "file", rel);
  else
    cJSON_AddStringToObject(line, "dataset", DATASET_NAME);
  return line;
}

/* DIR/dataset.nc: the films of index entries e (sorted: write_index) as
 * one NetCDF-4 dataset, built by libraysweep from the JSON films (or, for
 * --format dataset, the daemon's EXRs in pack: the same dataset, byte for
 * byte), so the dataset of merged shards is the unsharded one's. Contexts
 * come in index order with the wavelength and coords of their index lines;
 * a context without any film is not in it. */
int sweep_dataset_memory(const cli_ctx *ctx, unsigned long long *out) {
  *out = SWEEP_DATASET_MEMORY;
  const char *v = getenv("RAYSWEEP_DATASET_MEMORY");
  if (v && *v && !cli_parse_u64(v, 1ULL << 50, out))
    return cli_usage(ctx, "RAYSWEEP_DATASET_MEMORY needs a number of bytes (got '%s')", v);
  return CLI_OK;
}

int sweep_dataset_store(const cli_ctx *ctx, rsw_dataset *d, const char *dir) {
  unsigned long long mem;
  int rc = sweep_dataset_memory(ctx, &mem);
  if (rc) return rc;
  if (rsw_dataset_set_store(d, dir, (size_t)mem))
    return cli_fail(ctx, CLI_IO, "%s", rsw_dataset_last_error(d));
  return CLI_OK;
}

int sweep_write_dataset(const cli_ctx *ctx, const char *dir, const index_entry *e, size_t n, bool has_seed,
                        long long seed, film_pack *pack) {
  /* --format dataset: the films went in as they arrived (sweep_pack.c) */
  rsw_dataset *live = pack ? pack_live(pack, e, n) : NULL, *d = live;
  if (!d) {
    if (rsw_dataset_new(&d)) return cli_fail(ctx, CLI_IO, "out of memory");
    int rc = sweep_dataset_store(ctx, d, dir);
    if (rc) {
      rsw_dataset_free(d);
      return rc;
    }
  }
  char *out = sweep_dir_file(dir, DATASET_NAME);
  rsw_status s = out ? RSW_OK : RSW_ERR_NOMEM;
  if (!s && has_seed) s = rsw_dataset_set_seed(d, seed);
  const char *prev = NULL;
  char where[4200] = "";
  for (size_t i = 0; !s && !live && i < n; i++) {
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
    if (!s && pack) {
      const pack_film *f = pack_find(pack, c, sn);
      snprintf(where, sizeof where, "film %s/%s", c, sn);
      s = f ? pack_film_add_to(pack, d, f) : RSW_ERR_INVALID;
    } else if (!s) {
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
  if (!live) rsw_dataset_free(d); /* (the live one is the pack's) */
  return rc;
}
