/* JSON scene dictionaries -> document tree, with Mitsuba 3's load_dict
 * grammar (docs/kernel-conventions.md#scene-dictionaries; mitsuba3 src/core/python/parser.cpp):
 *
 *  - a dict is one object: "type" names the plugin (root: "scene" or absent),
 *    every other key is a property; keys may not contain '.';
 *  - nested dicts with "type" are child objects whose id is "id" if given,
 *    else the key;
 *  - {"type":"ref","id":X} references an object; {"type":"rgb","value":v},
 *    {"type":"uniform","value":x}, {"type":"spectrum","value":x or
 *    [[wl,v],...]} and {"type":"spectrum","wavelengths":[..],"values":[..]}
 *    are spectra;
 *  - numbers, booleans, strings and 3-vectors are plain properties;
 *  - transforms have no encoding in Mitsuba's dicts; ours (DESIGN.md) is a
 *    4x4 row-major matrix given as 4 rows of 4, or a list of operations
 *    applied in order like XML ({"translate":..}, {"rotate":{"axis","angle"}},
 *    {"scale":..}, {"lookat":{"origin","target","up"}}, {"matrix":[16]}),
 *    each left-multiplied onto the accumulated transform. A flat list of 16
 *    numbers is kept as a number list, which ld_transform() accepts too.
 *
 * Deliberate strictness beyond cJSON: duplicate keys in one object are an
 * error (cJSON keeps them silently), nesting is limited to RSW_MAX_DEPTH,
 * an ordinary object to max_props keys (containers to the tree's memory
 * cap), and integers are exact only below 2^53 (is_int is false above). */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../core/jsonscan.h"
#include "../media/atmo_data.h"
#include "node.h"
#include "rsw_file.h"

#define TWO_POW_53 9007199254740992.0

typedef struct jctx {
  const char *source;
  rsw_err *err;
  size_t n_nodes;
  const scene_limits *lim;
  size_t bytes; /* document tree memory so far (node_mem_*) */
} jctx;

/* JSON pointer of `key` under `base` (RFC 6901 escaping), prefixed by the
 * source name: "scene.json#/shape/bsdf". */
static void ptr_join(char *out, size_t len, const char *base, const char *key) {
  size_t n = (size_t)snprintf(out, len, "%s/", base);
  for (const char *c = key; *c && n + 3 < len; c++) {
    if (*c == '~') {
      out[n++] = '~';
      out[n++] = '0';
    } else if (*c == '/') {
      out[n++] = '~';
      out[n++] = '1';
    } else {
      out[n++] = *c;
    }
  }
  out[n < len ? n : len - 1] = '\0';
}

static void ptr_index(char *out, size_t len, const char *base, int i) {
  char idx[16];
  snprintf(idx, sizeof idx, "%d", i);
  ptr_join(out, len, base, idx);
}

static rsw_status fail(jctx *c, rsw_status code, const char *where, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static rsw_status fail(jctx *c, rsw_status code, const char *where, const char *fmt, ...) {
  char msg[600];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  return rsw_fail(c->err, code, where, "%s", msg);
}

static int array_size(const cJSON *a) {
  int n = 0;
  for (const cJSON *e = a->child; e; e = e->next) n++;
  return n;
}

static bool all_numbers(const cJSON *a) {
  for (const cJSON *e = a->child; e; e = e->next)
    if (!cJSON_IsNumber(e)) return false;
  return true;
}

static rsw_status read_vec3(jctx *c, const cJSON *v, const char *where, vec3 *out) {
  if (!cJSON_IsArray(v) || array_size(v) != 3 || !all_numbers(v))
    return fail(c, RSW_ERR_TYPE, where, "expected an array of 3 numbers");
  const cJSON *e = v->child;
  out->x = e->valuedouble;
  out->y = e->next->valuedouble;
  out->z = e->next->next->valuedouble;
  return RSW_OK;
}

/* 16 numbers, or 4 rows of 4 numbers. */
static rsw_status read_matrix(jctx *c, const cJSON *v, const char *where, xform *out) {
  double m[4][4];
  if (cJSON_IsArray(v) && array_size(v) == 16 && all_numbers(v)) {
    int i = 0;
    for (const cJSON *e = v->child; e; e = e->next, i++) m[i / 4][i % 4] = e->valuedouble;
  } else if (cJSON_IsArray(v) && array_size(v) == 4) {
    int r = 0;
    for (const cJSON *row = v->child; row; row = row->next, r++) {
      if (!cJSON_IsArray(row) || array_size(row) != 4 || !all_numbers(row))
        return fail(c, RSW_ERR_TYPE, where, "a 4x4 matrix needs 4 rows of 4 numbers");
      int k = 0;
      for (const cJSON *e = row->child; e; e = e->next, k++) m[r][k] = e->valuedouble;
    }
  } else {
    return fail(c, RSW_ERR_TYPE, where,
                "expected a 4x4 matrix: 16 numbers or 4 rows of 4 numbers (row-major)");
  }
  if (!xf_from_matrix(m, out)) return fail(c, RSW_ERR_INVALID, where, "matrix is singular");
  return RSW_OK;
}

static bool is_transform_op(const cJSON *o) {
  static const char *const ops[] = {"translate", "rotate", "scale", "lookat", "matrix"};
  if (!cJSON_IsObject(o) || !o->child || o->child->next) return false;
  for (size_t i = 0; i < sizeof ops / sizeof ops[0]; i++)
    if (o->child->string && strcmp(o->child->string, ops[i]) == 0) return true;
  return false;
}

/* One op object {"name": args}; returns the op's matrix. */
static rsw_status read_op(jctx *c, const cJSON *o, const char *where, xform *out) {
  const cJSON *a = o->child;
  const char *name = a->string;
  char w[512];
  ptr_join(w, sizeof w, where, name);
  if (strcmp(name, "translate") == 0) {
    vec3 t = {0, 0, 0};
    rsw_status st = read_vec3(c, a, w, &t);
    if (st) return st;
    *out = xf_translate(t);
  } else if (strcmp(name, "scale") == 0) {
    vec3 s = {0, 0, 0};
    if (cJSON_IsNumber(a)) {
      s = v3(a->valuedouble, a->valuedouble, a->valuedouble);
    } else {
      rsw_status st = read_vec3(c, a, w, &s);
      if (st) return fail(c, RSW_ERR_TYPE, w, "scale: expected a number or 3 numbers");
    }
    if (s.x == 0 || s.y == 0 || s.z == 0)
      return fail(c, RSW_ERR_INVALID, w, "scale factors must be non-zero");
    *out = xf_scale(s);
  } else if (strcmp(name, "rotate") == 0) {
    if (!cJSON_IsObject(a))
      return fail(c, RSW_ERR_TYPE, w, "rotate: expected {\"axis\": [x,y,z], \"angle\": degrees}");
    const cJSON *axis = NULL, *angle = NULL;
    for (const cJSON *k = a->child; k; k = k->next) {
      if (strcmp(k->string, "axis") == 0 && !axis)
        axis = k;
      else if (strcmp(k->string, "angle") == 0 && !angle)
        angle = k;
      else {
        char wk[600];
        ptr_join(wk, sizeof wk, w, k->string);
        return fail(c, RSW_ERR_INVALID, wk, "rotate: unexpected key '%s' (expected axis, angle)", k->string);
      }
    }
    if (!axis || !angle) return fail(c, RSW_ERR_MISSING, w, "rotate: needs both 'axis' and 'angle'");
    char wa[600];
    ptr_join(wa, sizeof wa, w, "axis");
    vec3 ax;
    rsw_status st = read_vec3(c, axis, wa, &ax);
    if (st) return st;
    if (!(v3_len(ax) > 0)) return fail(c, RSW_ERR_INVALID, wa, "rotate: axis must be non-zero");
    if (!cJSON_IsNumber(angle)) {
      ptr_join(wa, sizeof wa, w, "angle");
      return fail(c, RSW_ERR_TYPE, wa, "rotate: angle must be a number (degrees)");
    }
    *out = xf_rotate(ax, angle->valuedouble);
  } else if (strcmp(name, "lookat") == 0) {
    if (!cJSON_IsObject(a))
      return fail(c, RSW_ERR_TYPE, w, "lookat: expected {\"origin\", \"target\", \"up\"}");
    vec3 v[3];
    bool got[3] = {false, false, false};
    static const char *const keys[3] = {"origin", "target", "up"};
    for (const cJSON *k = a->child; k; k = k->next) {
      int idx = -1;
      for (int i = 0; i < 3; i++)
        if (strcmp(k->string, keys[i]) == 0) idx = i;
      char wk[600];
      ptr_join(wk, sizeof wk, w, k->string);
      if (idx < 0 || got[idx])
        return fail(c, RSW_ERR_INVALID, wk, "lookat: unexpected or repeated key '%s'", k->string);
      rsw_status st = read_vec3(c, k, wk, &v[idx]);
      if (st) return st;
      got[idx] = true;
    }
    if (!got[0] || !got[1]) return fail(c, RSW_ERR_MISSING, w, "lookat: needs 'origin' and 'target'");
    if (!got[2]) {
      /* As Mitsuba's XML parser: without `up`, take coordinate_system's
       * first vector of the viewing direction. */
      vec3 s, t;
      coordinate_system(v3_norm(v3_sub(v[1], v[0])), &s, &t);
      v[2] = s;
    }
    if (!xf_look_at(v[0], v[1], v[2], out))
      return fail(c, RSW_ERR_INVALID, w, "lookat: degenerate (origin == target or up parallel to the view)");
  } else { /* matrix */
    return read_matrix(c, a, w, out);
  }
  return RSW_OK;
}

/* A list of op objects (or a single op object) -> accumulated transform. */
static rsw_status read_ops(jctx *c, const cJSON *v, const char *where, xform *out) {
  xform acc = xf_identity();
  if (is_transform_op(v)) return read_op(c, v, where, out);
  int i = 0;
  for (const cJSON *e = v->child; e; e = e->next, i++) {
    char w[512];
    ptr_index(w, sizeof w, where, i);
    if (!is_transform_op(e))
      return fail(c, RSW_ERR_TYPE, w,
                  "expected a transform operation: one of {\"translate\"}, {\"rotate\"}, "
                  "{\"scale\"}, {\"lookat\"}, {\"matrix\"}");
    xform op;
    rsw_status st = read_op(c, e, w, &op);
    if (st) return st;
    acc = xf_mul(&op, &acc); /* left-multiply: later ops apply after */
  }
  *out = acc;
  return RSW_OK;
}

/* Keys of one object: duplicates are an error, and an ordinary object
 * takes at most lim->max_props keys (a safety cap: no plugin has more
 * than a few dozen properties). Containers (the scene, a shapegroup) take
 * any number, bounded by the tree's memory cap. Large objects are checked
 * with a hash set of the keys, small ones pairwise. */
static rsw_status check_keys(jctx *c, const cJSON *obj, const char *type, const char *where) {
  size_t n = 0;
  for (const cJSON *a = obj->child; a; a = a->next) n++;
  bool container = node_type_is_container(type);
  if (!container && n > c->lim->max_props)
    return fail(c, RSW_ERR_LIMIT, where,
                "object '%s' (type '%s') has %zu keys, more than the %zu an object may have "
                "(only the scene and shapegroups take more)",
                where, type, n, c->lim->max_props);
  if (n <= 32) {
    for (const cJSON *a = obj->child; a; a = a->next)
      for (const cJSON *b = a->next; b; b = b->next)
        if (strcmp(a->string, b->string) == 0) {
          char w[512];
          ptr_join(w, sizeof w, where, a->string);
          return fail(c, RSW_ERR_DUPLICATE, w, "duplicate key '%s'", a->string);
        }
    return RSW_OK;
  }
  size_t cap = 64;
  while (cap < 2 * n) cap *= 2;
  const char **set = calloc(cap, sizeof *set);
  if (!set) return fail(c, RSW_ERR_NOMEM, where, "out of memory");
  rsw_status st = RSW_OK;
  for (const cJSON *a = obj->child; a && !st; a = a->next) {
    unsigned long long h = 1469598103934665603ull; /* FNV-1a */
    for (const char *k = a->string; *k; k++) h = (h ^ (unsigned char)*k) * 1099511628211ull;
    size_t i = (size_t)h & (cap - 1);
    while (set[i] && strcmp(set[i], a->string) != 0) i = (i + 1) & (cap - 1);
    if (set[i]) {
      char w[512];
      ptr_join(w, sizeof w, where, a->string);
      st = fail(c, RSW_ERR_DUPLICATE, w, "duplicate key '%s'", a->string);
    }
    set[i] = a->string;
  }
  free(set);
  return st;
}

/* Count `bytes` of document tree against the memory cap; `where` is the
 * key being read when it runs out. */
static rsw_status account(jctx *c, size_t bytes, const char *where) {
  c->bytes += bytes;
  if (c->bytes > c->lim->max_tree_bytes)
    return fail(c, RSW_ERR_LIMIT, where,
                "the scene document needs more than its memory cap of %zu bytes (%.0f MiB) at '%s'; "
                "split the scene or raise the cap",
                c->lim->max_tree_bytes, c->lim->max_tree_bytes / 1048576.0, where);
  return RSW_OK;
}

/* {"type":"spectrum", ...} / rgb / uniform -> spectrum. */
/* {"type": "solar_irradiance", "dataset": "thuillier_2003", "scale": s,
 * "earth_sun_distance": d}: the Thuillier et al. (2003) spectrum at 1 AU
 * (data/solar, compiled into media/atmo_data.c) in W m^-2 nm^-1, times
 * s / d^2 (d in astronomical units, default 1; Eradiate's
 * SolarIrradianceSpectrum). docs/atmosphere.md. */
static rsw_status read_solar(jctx *c, const cJSON *o, const char *where, spectrum *out) {
  memset(out, 0, sizeof *out);
  double scale = 1.0, d = 1.0;
  for (const cJSON *k = o->child; k; k = k->next) {
    if (strcmp(k->string, "type") == 0) continue;
    char w[512];
    ptr_join(w, sizeof w, where, k->string);
    if (strcmp(k->string, "dataset") == 0) {
      if (!cJSON_IsString(k) || strcmp(k->valuestring, "thuillier_2003") != 0)
        return fail(c, RSW_ERR_INVALID, w, "solar_irradiance: unknown dataset (known: thuillier_2003)");
    } else if (strcmp(k->string, "scale") == 0 || strcmp(k->string, "earth_sun_distance") == 0) {
      bool is_scale = k->string[0] == 's';
      if (!cJSON_IsNumber(k) || !isfinite(k->valuedouble) ||
          !(is_scale ? k->valuedouble >= 0 : k->valuedouble > 0))
        return fail(c, RSW_ERR_RANGE, w, "solar_irradiance: '%s' must be a finite number %s", k->string,
                    is_scale ? ">= 0" : "> 0 (astronomical units)");
      *(is_scale ? &scale : &d) = k->valuedouble;
    } else {
      return fail(c, RSW_ERR_INVALID, w,
                  "solar_irradiance: unexpected key '%s' (dataset, scale, earth_sun_distance)", k->string);
    }
  }
  const atmo_solar_table *t = &atmo_solar_thuillier_2003;
  out->kind = SPEC_TABLE;
  out->n = (size_t)t->n;
  out->wl = malloc(out->n * sizeof(double));
  out->val = malloc(out->n * sizeof(double));
  if (!out->wl || !out->val) {
    spectrum_free(out);
    return fail(c, RSW_ERR_NOMEM, where, "out of memory");
  }
  double f = 1e-3 * scale / (d * d); /* mW -> W, 1 / d^2 */
  for (size_t i = 0; i < out->n; i++) out->wl[i] = t->wl[i], out->val[i] = t->mw[i] * f;
  return RSW_OK;
}

static rsw_status read_spectrum(jctx *c, const cJSON *o, const char *type, const char *where, spectrum *out) {
  memset(out, 0, sizeof *out);
  const cJSON *value = NULL, *wls = NULL, *vals = NULL;
  for (const cJSON *k = o->child; k; k = k->next) {
    if (strcmp(k->string, "type") == 0) continue;
    char w[512];
    ptr_join(w, sizeof w, where, k->string);
    if (strcmp(k->string, "value") == 0)
      value = k;
    else if (strcmp(type, "spectrum") == 0 && strcmp(k->string, "wavelengths") == 0)
      wls = k;
    else if (strcmp(type, "spectrum") == 0 && strcmp(k->string, "values") == 0)
      vals = k;
    else if (strcmp(k->string, "filename") == 0)
      return fail(c, RSW_ERR_UNSUPPORTED, w, "spectrum files are not supported: give the values inline");
    else
      return fail(c, RSW_ERR_INVALID, w, "unexpected key '%s' in a '%s' value", k->string, type);
  }
  char w[512];
  if (strcmp(type, "rgb") == 0) {
    ptr_join(w, sizeof w, where, "value");
    if (!value) return fail(c, RSW_ERR_MISSING, where, "rgb: missing 'value'");
    out->kind = SPEC_RGB;
    if (cJSON_IsNumber(value)) {
      out->rgb[0] = out->rgb[1] = out->rgb[2] = value->valuedouble;
    } else {
      vec3 v = {0, 0, 0};
      rsw_status st = read_vec3(c, value, w, &v);
      if (st) return fail(c, RSW_ERR_TYPE, w, "rgb: 'value' must be a number or 3 numbers");
      out->rgb[0] = v.x;
      out->rgb[1] = v.y;
      out->rgb[2] = v.z;
    }
    return RSW_OK;
  }
  if (strcmp(type, "uniform") == 0 || (value && cJSON_IsNumber(value))) {
    ptr_join(w, sizeof w, where, "value");
    if (!value) return fail(c, RSW_ERR_MISSING, where, "%s: missing 'value'", type);
    if (!cJSON_IsNumber(value)) return fail(c, RSW_ERR_TYPE, w, "%s: 'value' must be a number", type);
    if (wls || vals)
      return fail(c, RSW_ERR_INVALID, where, "spectrum: give either 'value' or 'wavelengths'+'values'");
    out->kind = SPEC_UNIFORM;
    out->value = value->valuedouble;
    return RSW_OK;
  }
  /* Tabulated: value = [[wl, v], ...] or wavelengths + values. */
  size_t n = 0;
  if (value) {
    if (wls || vals)
      return fail(c, RSW_ERR_INVALID, where, "spectrum: give either 'value' or 'wavelengths'+'values'");
    ptr_join(w, sizeof w, where, "value");
    if (!cJSON_IsArray(value))
      return fail(c, RSW_ERR_TYPE, w,
                  "spectrum: 'value' must be a number or a list of [wavelength, value] pairs");
    n = (size_t)array_size(value);
  } else {
    if (!wls || !vals)
      return fail(c, RSW_ERR_MISSING, where, "spectrum: needs 'value', or 'wavelengths' and 'values'");
    ptr_join(w, sizeof w, where, "wavelengths");
    if (!cJSON_IsArray(wls) || !all_numbers(wls))
      return fail(c, RSW_ERR_TYPE, w, "spectrum: 'wavelengths' must be a list of numbers");
    ptr_join(w, sizeof w, where, "values");
    if (!cJSON_IsArray(vals) || !all_numbers(vals))
      return fail(c, RSW_ERR_TYPE, w, "spectrum: 'values' must be a list of numbers");
    n = (size_t)array_size(wls);
    if ((size_t)array_size(vals) != n)
      return fail(c, RSW_ERR_INVALID, where, "spectrum: 'wavelengths' has %zu entries but 'values' has %d", n,
                  array_size(vals));
  }
  if (n < 2) return fail(c, RSW_ERR_INVALID, where, "spectrum: a table needs at least 2 samples");
  if (n > RSW_MAX_SPECTRUM)
    return fail(c, RSW_ERR_LIMIT, where, "spectrum: more than %d samples", RSW_MAX_SPECTRUM);
  out->kind = SPEC_TABLE;
  out->n = n;
  out->wl = malloc(n * sizeof(double));
  out->val = malloc(n * sizeof(double));
  if (!out->wl || !out->val) {
    spectrum_free(out);
    return fail(c, RSW_ERR_NOMEM, where, "out of memory");
  }
  if (value) {
    size_t i = 0;
    for (const cJSON *e = value->child; e; e = e->next, i++) {
      ptr_index(w, sizeof w, where, (int)i);
      if (!cJSON_IsArray(e) || array_size(e) != 2 || !all_numbers(e)) {
        spectrum_free(out);
        return fail(c, RSW_ERR_TYPE, w, "spectrum: each entry must be [wavelength_nm, value]");
      }
      out->wl[i] = e->child->valuedouble;
      out->val[i] = e->child->next->valuedouble;
    }
  } else {
    size_t i = 0;
    for (const cJSON *e = wls->child; e; e = e->next, i++) out->wl[i] = e->valuedouble;
    i = 0;
    for (const cJSON *e = vals->child; e; e = e->next, i++) out->val[i] = e->valuedouble;
  }
  for (size_t i = 0; i < n; i++) {
    if (!(out->wl[i] > 0) || (i > 0 && !(out->wl[i] > out->wl[i - 1]))) {
      spectrum_free(out);
      return fail(c, RSW_ERR_INVALID, where,
                  "spectrum: wavelengths must be positive and strictly increasing (entry %zu)", i);
    }
  }
  return RSW_OK;
}

static rsw_status read_object(jctx *c, const cJSON *obj, const char *key, const char *where, int depth,
                              node **out);

static rsw_status read_value(jctx *c, node *n, const cJSON *v, const char *key, const char *where, int depth);

/* A JSON array of objects with a "type": a list of container members. */
static bool is_list(const cJSON *v) {
  return cJSON_IsArray(v) && v->child && cJSON_IsObject(v->child) &&
         cJSON_GetObjectItemCaseSensitive(v->child, "type");
}

/* Read v as a nested object and append it to n as the property `key`. */
static rsw_status add_child(jctx *c, node *n, const cJSON *v, const char *key, const char *where, int depth) {
  node *child = NULL;
  rsw_status st = read_object(c, v, key, where, depth + 1, &child);
  if (st) return st;
  prop *p = node_add_prop(n, key, PROP_NODE, where);
  if (!p) {
    node_free(child);
    return fail(c, RSW_ERR_NOMEM, where, "out of memory");
  }
  p->child = child;
  return RSW_OK;
}

/* Property groups of `molecular_atmosphere` (docs/atmosphere.md): nested
 * dicts that name no plugin, read by their owner as a group of
 * properties. The type they get ("thermoprops", "particle_layer"); NULL
 * for any other key. */
static const char *group_type(const char *key) {
  if (!key) return NULL;
  if (strcmp(key, "thermoprops") == 0) return "thermoprops";
  if (strcmp(key, "particle_layers") == 0) return "particle_layer";
  if (strcmp(key, "distribution") == 0) return "uniform";
  return NULL;
}

/* "particle_layers": [{...}, ...]: one group per element, each a property
 * named particle_layers, in order. */
static rsw_status read_groups(jctx *c, node *n, const cJSON *v, const char *key, const char *where,
                              int depth) {
  int i = 0;
  for (const cJSON *e = v->child; e; e = e->next, i++) {
    char w[512];
    ptr_index(w, sizeof w, where, i);
    if (!cJSON_IsObject(e)) return fail(c, RSW_ERR_TYPE, w, "'%s' is a list of objects", key);
    rsw_status st = check_keys(c, e, group_type(key), w);
    if (st) return st;
    size_t arrays = node_mem_arrays(n);
    st = add_child(c, n, e, key, w, depth);
    if (st) return st;
    st = account(c, node_mem_arrays(n) - arrays + node_mem_prop(&n->props[n->n_props - 1]), w);
    if (st) return st;
  }
  return RSW_OK;
}

/* A list of objects in a container (the scene, a shapegroup):
 * "members": [{"type": "disk", ...}, {"type": "ref", "id": "x"}, ...] adds
 * one child per element, as if each had its own key; an element without
 * an explicit "id" gets the id "<key>_<index>". Saves inventing 100,000
 * keys. */
static rsw_status read_list(jctx *c, node *n, const cJSON *v, const char *key, const char *where, int depth) {
  if (!node_type_is_container(n->type))
    return fail(c, RSW_ERR_TYPE, where,
                "a list of objects is accepted only in the scene and in shapegroups ('%s' is a %s)", key,
                n->type);
  int i = 0;
  for (const cJSON *e = v->child; e; e = e->next, i++) {
    char w[512];
    ptr_index(w, sizeof w, where, i);
    const cJSON *type = cJSON_IsObject(e) ? cJSON_GetObjectItemCaseSensitive(e, "type") : NULL;
    if (!type || !cJSON_IsString(type))
      return fail(c, RSW_ERR_TYPE, w, "'%s' is a list of objects: every element needs a \"type\"", key);
    size_t before = n->n_props, arrays = node_mem_arrays(n);
    rsw_status st = read_value(c, n, e, key, w, depth + 1);
    if (st) return st;
    prop *p = n->n_props > before ? &n->props[n->n_props - 1] : NULL;
    if (p && p->kind == PROP_NODE && !p->child->id_explicit) {
      char id[RSW_MAX_NAME + 16];
      snprintf(id, sizeof id, "%s_%d", key, i);
      char *dup = rsw_strdup(id);
      if (!dup) return fail(c, RSW_ERR_NOMEM, w, "out of memory");
      free(p->child->id);
      p->child->id = dup;
    }
    if (p && p->kind != PROP_NODE && p->kind != PROP_REF)
      return fail(c, RSW_ERR_TYPE, w, "'%s' is a list of objects: a %s value is not an object", key,
                  type->valuestring);
    if (p) {
      st = account(c, node_mem_arrays(n) - arrays + node_mem_prop(p), w);
      if (st) return st;
    }
  }
  return RSW_OK;
}

/* Convert one property value and append it to n. */
static rsw_status read_value(jctx *c, node *n, const cJSON *v, const char *key, const char *where,
                             int depth) {
  if (depth > RSW_MAX_DEPTH)
    return fail(c, RSW_ERR_LIMIT, where, "nesting deeper than %d levels", RSW_MAX_DEPTH);
  if (strchr(key, '.'))
    return fail(c, RSW_ERR_INVALID, where,
                "key '%s' contains '.', which separates parameter paths (nest the dict instead)", key);
  if (strlen(key) >= RSW_MAX_NAME)
    return fail(c, RSW_ERR_LIMIT, where, "key longer than %d characters", RSW_MAX_NAME - 1);
  prop *p;
#define ADD_(kind)                                                                                           \
  do {                                                                                                       \
    p = node_add_prop(n, key, kind, where);                                                                  \
    if (!p && n->n_props >= RSW_MAX_NODES)                                                                   \
      return fail(c, RSW_ERR_LIMIT, where, "more than %d properties in one object", RSW_MAX_NODES);          \
    if (!p) return fail(c, RSW_ERR_NOMEM, where, "out of memory");                                           \
  } while (0)
  if (cJSON_IsBool(v)) {
    ADD_(PROP_BOOL);
    p->b = cJSON_IsTrue(v);
  } else if (cJSON_IsNumber(v)) {
    ADD_(PROP_NUMBER);
    p->num = v->valuedouble;
    p->is_int = (p->num == floor(p->num) && fabs(p->num) < TWO_POW_53);
  } else if (cJSON_IsString(v)) {
    ADD_(PROP_STRING);
    p->str = rsw_strdup(v->valuestring);
    if (!p->str) return fail(c, RSW_ERR_NOMEM, where, "out of memory");
  } else if (cJSON_IsNull(v)) {
    return fail(c, RSW_ERR_TYPE, where, "null is not a valid property value");
  } else if (cJSON_IsArray(v)) {
    int len = array_size(v);
    if (len == 3 && all_numbers(v)) {
      vec3 x = {0, 0, 0};
      rsw_status st = read_vec3(c, v, where, &x);
      if (st) return st;
      ADD_(PROP_VEC3);
      p->vec = x;
    } else if (all_numbers(v)) {
      ADD_(PROP_NUMBERS);
      p->n_nums = (size_t)len;
      p->nums = malloc((len ? (size_t)len : 1) * sizeof(double));
      if (!p->nums) return fail(c, RSW_ERR_NOMEM, where, "out of memory");
      int i = 0;
      for (const cJSON *e = v->child; e; e = e->next) p->nums[i++] = e->valuedouble;
    } else if (len == 4 && cJSON_IsArray(v->child)) {
      xform xf;
      rsw_status st = read_matrix(c, v, where, &xf);
      if (st) return st;
      ADD_(PROP_TRANSFORM);
      p->xf = xf;
    } else if (group_type(key) && strcmp(key, "particle_layers") == 0 &&
               (len == 0 || cJSON_IsObject(v->child))) {
      return read_groups(c, n, v, key, where, depth);
    } else if (is_list(v)) {
      return read_list(c, n, v, key, where, depth);
    } else if (len > 0 && cJSON_IsObject(v->child)) {
      xform xf;
      rsw_status st = read_ops(c, v, where, &xf);
      if (st) return st;
      ADD_(PROP_TRANSFORM);
      p->xf = xf;
    } else {
      return fail(c, RSW_ERR_TYPE, where,
                  "unsupported array: expected numbers, a 4x4 matrix or a list of transform operations");
    }
  } else if (cJSON_IsObject(v)) {
    const cJSON *type = cJSON_GetObjectItemCaseSensitive(v, "type");
    if (!type) {
      if (is_transform_op(v)) {
        xform xf;
        rsw_status st = read_ops(c, v, where, &xf);
        if (st) return st;
        ADD_(PROP_TRANSFORM);
        p->xf = xf;
        return RSW_OK;
      }
      if (group_type(key)) {
        rsw_status st = check_keys(c, v, group_type(key), where);
        return st ? st : add_child(c, n, v, key, where, depth);
      }
      return fail(c, RSW_ERR_MISSING, where, "object has no \"type\" (every nested object names its plugin)");
    }
    char wt[512];
    ptr_join(wt, sizeof wt, where, "type");
    if (!cJSON_IsString(type)) return fail(c, RSW_ERR_TYPE, wt, "\"type\" must be a string");
    const char *t = type->valuestring;
    rsw_status st = check_keys(c, v, t, where);
    if (st) return st;
    if (strcmp(t, "ref") == 0) {
      const cJSON *id = NULL;
      for (const cJSON *k = v->child; k; k = k->next) {
        if (strcmp(k->string, "type") == 0) continue;
        char wk[600];
        ptr_join(wk, sizeof wk, where, k->string);
        if (strcmp(k->string, "id") != 0)
          return fail(c, RSW_ERR_INVALID, wk, "ref: unexpected key '%s' (a ref has only \"type\" and \"id\")",
                      k->string);
        id = k;
      }
      if (!id || !cJSON_IsString(id) || !id->valuestring[0])
        return fail(c, RSW_ERR_MISSING, where, "ref: needs a non-empty string \"id\"");
      ADD_(PROP_REF);
      p->ref = rsw_strdup(id->valuestring);
      if (!p->ref) return fail(c, RSW_ERR_NOMEM, where, "out of memory");
    } else if ((strcmp(t, "rgb") == 0 || strcmp(t, "spectrum") == 0 || strcmp(t, "uniform") == 0 ||
                strcmp(t, "solar_irradiance") == 0) &&
               !(strcmp(key, "distribution") == 0)) {
      spectrum s;
      st = strcmp(t, "solar_irradiance") == 0 ? read_solar(c, v, where, &s)
                                              : read_spectrum(c, v, t, where, &s);
      if (st) return st;
      p = node_add_prop(n, key, PROP_SPECTRUM, where);
      if (!p) {
        spectrum_free(&s);
        return fail(c, RSW_ERR_NOMEM, where, "out of memory");
      }
      p->spec = s;
    } else {
      st = add_child(c, n, v, key, where, depth);
      if (st) return st;
    }
  } else {
    return fail(c, RSW_ERR_TYPE, where, "unsupported JSON value");
  }
#undef ADD_
  return RSW_OK;
}

/* A list element's generated id "<key>_<index>" must not be a key of the
 * same container too (the two objects would share an id, and one of them
 * would silently be renamed in the parameter table). Checked once the
 * whole container is read, since the key may come after the list. */
static rsw_status check_list_ids(jctx *c, const node *n) {
  for (size_t i = 0; i < n->n_props; i++) {
    const prop *p = &n->props[i];
    if (p->kind != PROP_NODE || p->child->id_explicit || !p->child->id || strcmp(p->child->id, p->name) == 0)
      continue;
    const prop *q = node_find(n, p->child->id);
    if (q)
      return fail(c, RSW_ERR_INVALID, p->loc,
                  "this element of the list '%s' gets the id '%s', which the key '%s' already names: "
                  "give the element an \"id\" (or rename the key)",
                  p->name, p->child->id, q->name);
  }
  return RSW_OK;
}

static rsw_status read_object(jctx *c, const cJSON *obj, const char *key, const char *where, int depth,
                              node **out) {
  if (depth > RSW_MAX_DEPTH)
    return fail(c, RSW_ERR_LIMIT, where, "nesting deeper than %d levels", RSW_MAX_DEPTH);
  if (++c->n_nodes > RSW_MAX_NODES)
    return fail(c, RSW_ERR_LIMIT, where, "more than %d objects", RSW_MAX_NODES);
  const cJSON *type = cJSON_GetObjectItemCaseSensitive(obj, "type");
  const char *tname = type && cJSON_IsString(type) ? type->valuestring
                      : group_type(key)            ? group_type(key)
                                                   : "scene";
  if (strlen(tname) >= RSW_MAX_NAME) return fail(c, RSW_ERR_LIMIT, where, "type name too long");
  node *n = node_new(NULL, tname, where);
  if (!n) return fail(c, RSW_ERR_NOMEM, where, "out of memory");
  rsw_status st = RSW_OK;
  const cJSON *id = cJSON_GetObjectItemCaseSensitive(obj, "id");
  if (id) {
    char w[512];
    ptr_join(w, sizeof w, where, "id");
    if (!cJSON_IsString(id) || !id->valuestring[0] || strlen(id->valuestring) >= RSW_MAX_NAME) {
      st = fail(c, RSW_ERR_TYPE, w, "\"id\" must be a non-empty string");
      goto done;
    }
    n->id = rsw_strdup(id->valuestring);
    n->id_explicit = true;
  } else if (key) {
    n->id = rsw_strdup(key);
  }
  if ((id || key) && !n->id) {
    st = fail(c, RSW_ERR_NOMEM, where, "out of memory");
    goto done;
  }
  st = account(c, node_mem_self(n), where);
  for (const cJSON *k = obj->child; k && !st; k = k->next) {
    if (strcmp(k->string, "type") == 0 || strcmp(k->string, "id") == 0) continue;
    char w[512];
    ptr_join(w, sizeof w, where, k->string);
    size_t before = n->n_props, arrays = node_mem_arrays(n);
    st = read_value(c, n, k, k->string, w, depth);
    /* (a list accounts for its elements itself) */
    if (!st && !is_list(k) && n->n_props == before + 1)
      st = account(c, node_mem_arrays(n) - arrays + node_mem_prop(&n->props[n->n_props - 1]), w);
  }
  if (!st && node_type_is_container(n->type)) st = check_list_ids(c, n);
done:
  if (st) {
    node_free(n);
    return st;
  }
  *out = n;
  return RSW_OK;
}

rsw_status scene_read_json(const char *text, size_t len, const char *source_name, node **root_out,
                           char **variant_out, rsw_err *err) {
  return scene_read_json_limited(text, len, source_name, NULL, root_out, variant_out, err);
}

rsw_status scene_read_json_limited(const char *text, size_t len, const char *source_name,
                                   const scene_limits *lim, node **root_out, char **variant_out,
                                   rsw_err *err) {
  jctx c = {.source = source_name ? source_name : "scene.json",
            .err = err,
            .lim = lim ? lim : &scene_limits_default};
  char where[512];
  snprintf(where, sizeof where, "%s#", c.source);
  if (variant_out) *variant_out = NULL;
  if (len == 0) return fail(&c, RSW_ERR_PARSE, where, "empty document");
  const char *end = NULL;
  cJSON *doc = cJSON_ParseWithLengthOpts(text, len, &end, 0);
  if (!doc) {
    size_t off = end && end >= text && end <= text + len ? (size_t)(end - text) : 0;
    size_t line, colno;
    rsw_line_col(text, off, &line, &colno);
    char w[600];
    snprintf(w, sizeof w, "%s:%zu:%zu", c.source, line, colno);
    return fail(&c, RSW_ERR_PARSE, w, "malformed JSON near line %zu, column %zu", line, colno);
  }
  /* Trailing garbage after the document. */
  if (end) {
    const char *e = end;
    while (e < text + len && (*e == ' ' || *e == '\t' || *e == '\n' || *e == '\r' || *e == '\0')) e++;
    if (e < text + len) {
      size_t line, colno;
      rsw_line_col(text, (size_t)(e - text), &line, &colno);
      char w[600];
      snprintf(w, sizeof w, "%s:%zu:%zu", c.source, line, colno);
      cJSON_Delete(doc);
      return fail(&c, RSW_ERR_PARSE, w, "unexpected content after the JSON document");
    }
  }
  /* A NUL in a string would cut it short (a file name, an id). */
  char member[128];
  long nul = json_find_nul_escape(text, len, member, sizeof member);
  if (nul >= 0) {
    size_t line, colno;
    rsw_line_col(text, (size_t)nul, &line, &colno);
    char w[600];
    snprintf(w, sizeof w, "%s:%zu:%zu", c.source, line, colno);
    cJSON_Delete(doc);
    return fail(&c, RSW_ERR_INVALID, w,
                "%s%s%sa string contains \\u0000 (NUL), which no name, id or value may hold",
                member[0] ? "'" : "", member, member[0] ? "': " : "");
  }
  rsw_status st = RSW_OK;
  node *root = NULL;
  char *variant = NULL;
  if (!cJSON_IsObject(doc)) {
    st = fail(&c, RSW_ERR_TYPE, where, "the document must be a JSON object (a scene dictionary)");
    goto out;
  }
  st = check_keys(&c, doc, "scene", where);
  if (st) goto out;
  const cJSON *type = cJSON_GetObjectItemCaseSensitive(doc, "type");
  if (type && (!cJSON_IsString(type) || strcmp(type->valuestring, "scene") != 0)) {
    char w[600];
    ptr_join(w, sizeof w, where, "type");
    st = fail(&c, RSW_ERR_INVALID, w, "the root object must have \"type\": \"scene\"");
    goto out;
  }
  const cJSON *var = cJSON_GetObjectItemCaseSensitive(doc, "variant");
  if (var) {
    char w[600];
    ptr_join(w, sizeof w, where, "variant");
    if (!cJSON_IsString(var)) {
      st = fail(&c, RSW_ERR_TYPE, w, "\"variant\" must be a string (\"mono\" or \"rgb\")");
      goto out;
    }
    /* Unchecked, a failed copy read as "no variant": the scene loaded
     * as rgb (test_oom_cli). */
    if (!(variant = rsw_strdup(var->valuestring))) {
      st = fail(&c, RSW_ERR_NOMEM, w, "out of memory");
      goto out;
    }
  }
  /* "templates" (parameter-map templates, docs/experiments.md) belong to
   * the service that renders them per context, not to the scene graph:
   * an object, read by the daemon from the document itself. */
  const cJSON *tmpl = cJSON_GetObjectItemCaseSensitive(doc, "templates");
  if (tmpl && !cJSON_IsObject(tmpl)) {
    char w[600];
    ptr_join(w, sizeof w, where, "templates");
    st = fail(&c, RSW_ERR_TYPE, w, "\"templates\" must be an object {parameter key: template}");
    goto out;
  }
  cJSON *detached_tmpl = tmpl ? cJSON_DetachItemViaPointer(doc, (cJSON *)tmpl) : NULL;
  /* Build the root without the "variant" key: detach it temporarily. */
  cJSON *detached = var ? cJSON_DetachItemViaPointer(doc, (cJSON *)var) : NULL;
  if (cJSON_GetObjectItemCaseSensitive(doc, "id")) {
    char w[600];
    ptr_join(w, sizeof w, where, "id");
    st = fail(&c, RSW_ERR_INVALID, w, "the root scene takes no \"id\"");
  } else {
    st = read_object(&c, doc, NULL, where, 0, &root);
  }
  cJSON_Delete(detached);
  cJSON_Delete(detached_tmpl);
  if (st) goto out;
  free(root->id);
  root->id = NULL;
  st = node_assign_ids(root, err);
out:
  cJSON_Delete(doc);
  if (st) {
    node_free(root);
    free(variant);
    return st;
  }
  *root_out = root;
  if (variant_out)
    *variant_out = variant;
  else
    free(variant);
  return RSW_OK;
}
