/* Parameter-map templates: compile, render per context, and the check
 * that a sweep is not a silent no-op (templates.h; docs/experiments.md
 * "Templates"). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../kernel/scene/param_table.h"
#include "../kernel/scene/params.h"
#include "buf.h"
#include "rsw_sha256.h"
#include "service_internal.h"
#include "templates.h"

#define DEG (3.14159265358979323846 / 180.0)

/* A number given as a constant or read from a coordinate. */
typedef struct operand {
  int coord; /* index into the set's coordinate names; -1: constant */
  double v;
} operand;

typedef enum form_kind {
  FORM_VALUE,  /* {"value": V} */
  FORM_COORD,  /* {"coord": NAME} */
  FORM_TABLE,  /* {"coord": NAME, "x": [...], "y": [...]} */
  FORM_SUN,    /* {"sun": {zenith, azimuth}} */
  FORM_VIEW,   /* {"view": {zenith, azimuth}} */
  FORM_HPLANE, /* {"view": {construct: hplane, zeniths, azimuth}} */
  FORM_ANGLES, /* {"view": {construct: from_angles, angles}} */
} form_kind;

typedef struct tmpl {
  char *key;
  size_t index;  /* in the scene's parameter table */
  char ptr[300]; /* "/templates/KEY" (the job's) or the scene's pointer */
  form_kind kind;
  cJSON *value;    /* FORM_VALUE (owned) */
  int coord;       /* FORM_COORD, FORM_TABLE */
  size_t n;        /* FORM_TABLE: points; FORM_HPLANE, FORM_ANGLES: directions */
  size_t len;      /* FORM_TABLE: 0 for numbers, else the arrays' length */
  double *x, *y;   /* FORM_TABLE: n, n * max(len, 1) */
  operand zen, az; /* FORM_SUN, FORM_VIEW, FORM_HPLANE (azimuth) */
  operand *ops;    /* FORM_HPLANE: n zeniths; FORM_ANGLES: 2 n (zenith, azimuth) */
} tmpl;

struct tmpl_set {
  tmpl *t;
  size_t n;
  char **coords; /* names the templates read */
  size_t n_coords;
};

/* ---- compiling ------------------------------------------------------------------- */

static int coord_index(tmpl_set *s, const char *name, svc_error *e, const char *ptr) {
  for (size_t i = 0; i < s->n_coords; i++)
    if (strcmp(s->coords[i], name) == 0) return (int)i;
  char **g = realloc(s->coords, (s->n_coords + 1) * sizeof *g);
  char *c = g ? strdup(name) : NULL;
  if (g) s->coords = g;
  if (!c) {
    svc_fail(e, RSW_ERR_NOMEM, ptr, "out of memory");
    return -1;
  }
  s->coords[s->n_coords] = c;
  return (int)s->n_coords++;
}

/* A coordinate name: what a context's coords may hold. */
static bool coord_name_ok(const char *s) {
  size_t n = strlen(s);
  if (n < 1 || n > 64 || !((s[0] >= 'A' && s[0] <= 'Z') || (s[0] >= 'a' && s[0] <= 'z'))) return false;
  for (size_t i = 1; i < n; i++)
    if (!((s[i] >= 'A' && s[i] <= 'Z') || (s[i] >= 'a' && s[i] <= 'z') || (s[i] >= '0' && s[i] <= '9') ||
          s[i] == '_'))
      return false;
  return true;
}

static rsw_status read_coord_name(tmpl_set *s, const cJSON *v, const char *ptr, int *out, svc_error *e) {
  if (!cJSON_IsString(v) || !coord_name_ok(v->valuestring))
    return svc_fail(e, RSW_ERR_INVALID, ptr, "a coordinate name ([A-Za-z][A-Za-z0-9_]{0,63}) is expected");
  int i = coord_index(s, v->valuestring, e, ptr);
  if (i < 0) return e->err.code;
  *out = i;
  return RSW_OK;
}

/* An angle operand: a coordinate's name, or a finite number of degrees in
 * [lo, hi] (a coordinate's value is checked when rendered). */
static rsw_status read_operand(tmpl_set *s, const cJSON *v, const char *ptr, double lo, double hi,
                               operand *out, svc_error *e) {
  if (cJSON_IsString(v)) {
    out->v = 0;
    return read_coord_name(s, v, ptr, &out->coord, e);
  }
  if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble))
    return svc_fail(e, RSW_ERR_TYPE, ptr, "an angle is a coordinate's name or a finite number of degrees");
  if (!(v->valuedouble >= lo && v->valuedouble <= hi))
    return svc_fail(e, RSW_ERR_RANGE, ptr, "%g degrees lies outside [%g, %g]", v->valuedouble, lo, hi);
  out->coord = -1;
  out->v = v->valuedouble;
  return RSW_OK;
}

/* Members of o other than those listed are an error naming the first. */
static rsw_status only_members(const cJSON *o, const char *const *names, const char *ptr, const char *what,
                               svc_error *e) {
  for (const cJSON *k = o->child; k; k = k->next) {
    bool ok = false;
    for (const char *const *n = names; *n && !ok; n++) ok = strcmp(*n, k->string) == 0;
    if (!ok) {
      char w[400];
      snprintf(w, sizeof w, "%s/%s", ptr, k->string);
      return svc_fail(e, RSW_ERR_UNUSED_PROPERTY, w, "unknown member '%s' in %s", k->string, what);
    }
  }
  return RSW_OK;
}

static rsw_status read_numbers(const cJSON *a, const char *ptr, double *out, size_t n, svc_error *e) {
  size_t i = 0;
  for (const cJSON *v = a->child; v; v = v->next, i++) {
    if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble)) {
      char w[400];
      snprintf(w, sizeof w, "%s/%zu", ptr, i);
      return svc_fail(e, RSW_ERR_INVALID, w, "a finite number is expected");
    }
    if (i < n) out[i] = v->valuedouble;
  }
  return RSW_OK;
}

static rsw_status compile_table(tmpl_set *s, tmpl *t, const cJSON *o, svc_error *e) {
  static const char *const members[] = {"coord", "x", "y", NULL};
  char w[400];
  rsw_status st = only_members(o, members, t->ptr, "a table template (coord, x, y)", e);
  snprintf(w, sizeof w, "%s/coord", t->ptr);
  if (!st) st = read_coord_name(s, cJSON_GetObjectItemCaseSensitive(o, "coord"), w, &t->coord, e);
  if (st) return st;
  const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, "x"), *y = cJSON_GetObjectItemCaseSensitive(o, "y");
  snprintf(w, sizeof w, "%s/%s", t->ptr, cJSON_IsArray(x) ? "y" : "x");
  if (!cJSON_IsArray(x) || !cJSON_IsArray(y))
    return svc_fail(e, RSW_ERR_TYPE, w, "a table template needs arrays \"x\" and \"y\"");
  size_t n = (size_t)cJSON_GetArraySize(x);
  snprintf(w, sizeof w, "%s/x", t->ptr);
  if (n < 2) return svc_fail(e, RSW_ERR_INVALID, w, "x needs at least 2 points");
  if ((size_t)cJSON_GetArraySize(y) != n) {
    snprintf(w, sizeof w, "%s/y", t->ptr);
    return svc_fail(e, RSW_ERR_INVALID, w, "y has %d entries; x has %zu", cJSON_GetArraySize(y), n);
  }
  t->n = n;
  t->kind = FORM_TABLE;
  t->len = cJSON_IsArray(y->child) ? (size_t)cJSON_GetArraySize(y->child) : 0;
  size_t stride = t->len ? t->len : 1;
  if (t->len && n > SIZE_MAX / sizeof(double) / t->len) return svc_fail(e, RSW_ERR_LIMIT, w, "too large");
  t->x = malloc(n * sizeof *t->x);
  t->y = malloc(n * stride * sizeof *t->y);
  if (!t->x || !t->y) return svc_fail(e, RSW_ERR_NOMEM, t->ptr, "out of memory");
  if ((st = read_numbers(x, w, t->x, n, e))) return st;
  for (size_t i = 1; i < n; i++)
    if (!(t->x[i] > t->x[i - 1])) {
      snprintf(w, sizeof w, "%s/x/%zu", t->ptr, i);
      return svc_fail(e, RSW_ERR_INVALID, w, "x must increase strictly (%g after %g)", t->x[i], t->x[i - 1]);
    }
  size_t i = 0;
  for (const cJSON *v = y->child; v; v = v->next, i++) {
    snprintf(w, sizeof w, "%s/y/%zu", t->ptr, i);
    if (t->len == 0) {
      if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble))
        return svc_fail(e, RSW_ERR_INVALID, w, "y holds finite numbers (as its first entry does)");
      t->y[i] = v->valuedouble;
    } else {
      if (!cJSON_IsArray(v) || (size_t)cJSON_GetArraySize(v) != t->len)
        return svc_fail(e, RSW_ERR_INVALID, w, "y holds arrays of %zu numbers (as its first entry does)",
                        t->len);
      if ((st = read_numbers(v, w, t->y + i * t->len, t->len, e))) return st;
    }
  }
  if (t->len == 0 && !cJSON_IsNumber(y->child)) {
    snprintf(w, sizeof w, "%s/y/0", t->ptr);
    return svc_fail(e, RSW_ERR_INVALID, w, "y holds numbers or non-empty arrays of numbers");
  }
  return RSW_OK;
}

static rsw_status compile_angles(tmpl_set *s, tmpl *t, const cJSON *o, bool sun, svc_error *e) {
  char w[400];
  snprintf(w, sizeof w, "%s/%s", t->ptr, sun ? "sun" : "view");
  if (!cJSON_IsObject(o)) return svc_fail(e, RSW_ERR_TYPE, w, "an object of angles is expected");
  const cJSON *construct = cJSON_GetObjectItemCaseSensitive(o, "construct");
  const cJSON *zeniths = cJSON_GetObjectItemCaseSensitive(o, "zeniths");
  const cJSON *angles = cJSON_GetObjectItemCaseSensitive(o, "angles");
  const char *how = cJSON_IsString(construct) ? construct->valuestring
                    : zeniths                 ? "hplane"
                    : angles                  ? "from_angles"
                                              : "";
  rsw_status st;
  char m[460];
  if (construct && (sun || !cJSON_IsString(construct) ||
                    (strcmp(how, "hplane") != 0 && strcmp(how, "from_angles") != 0))) {
    snprintf(m, sizeof m, "%s/construct", w);
    return svc_fail(e, RSW_ERR_INVALID, m, "%s",
                    sun ? "a sun takes zenith and azimuth only"
                        : "construct is \"hplane\" or \"from_angles\"");
  }
  if (strcmp(how, "hplane") == 0) {
    static const char *const members[] = {"construct", "zeniths", "azimuth", NULL};
    if ((st = only_members(o, members, w, "an hplane view (zeniths, azimuth)", e))) return st;
    snprintf(m, sizeof m, "%s/zeniths", w);
    if (!cJSON_IsArray(zeniths) || !zeniths->child)
      return svc_fail(e, RSW_ERR_TYPE, m, "zeniths is a non-empty list of angles");
    t->n = (size_t)cJSON_GetArraySize(zeniths);
    if (!(t->ops = calloc(t->n, sizeof *t->ops))) return svc_fail(e, RSW_ERR_NOMEM, m, "out of memory");
    size_t i = 0;
    for (const cJSON *z = zeniths->child; z; z = z->next, i++) {
      char zi[480];
      snprintf(zi, sizeof zi, "%s/%zu", m, i);
      if ((st = read_operand(s, z, zi, -180, 180, &t->ops[i], e))) return st;
    }
    snprintf(m, sizeof m, "%s/azimuth", w);
    t->kind = FORM_HPLANE;
    return read_operand(s, cJSON_GetObjectItemCaseSensitive(o, "azimuth"), m, -INFINITY, INFINITY, &t->az, e);
  }
  if (strcmp(how, "from_angles") == 0) {
    static const char *const members[] = {"construct", "angles", NULL};
    if ((st = only_members(o, members, w, "a from_angles view (angles)", e))) return st;
    snprintf(m, sizeof m, "%s/angles", w);
    if (!cJSON_IsArray(angles) || !angles->child)
      return svc_fail(e, RSW_ERR_TYPE, m, "angles is a non-empty list of [zenith, azimuth] pairs");
    t->n = (size_t)cJSON_GetArraySize(angles);
    if (!(t->ops = calloc(2 * t->n, sizeof *t->ops))) return svc_fail(e, RSW_ERR_NOMEM, m, "out of memory");
    size_t i = 0;
    for (const cJSON *p = angles->child; p; p = p->next, i++) {
      char pi[480];
      snprintf(pi, sizeof pi, "%s/%zu", m, i);
      if (!cJSON_IsArray(p) || cJSON_GetArraySize(p) != 2)
        return svc_fail(e, RSW_ERR_TYPE, pi, "an angle pair is [zenith, azimuth]");
      char q[500];
      snprintf(q, sizeof q, "%s/0", pi);
      if ((st = read_operand(s, p->child, q, 0, 180, &t->ops[2 * i], e))) return st;
      snprintf(q, sizeof q, "%s/1", pi);
      if ((st = read_operand(s, p->child->next, q, -INFINITY, INFINITY, &t->ops[2 * i + 1], e))) return st;
    }
    t->kind = FORM_ANGLES;
    return RSW_OK;
  }
  static const char *const members[] = {"zenith", "azimuth", NULL};
  if ((st = only_members(o, members, w, sun ? "a sun (zenith, azimuth)" : "a view (zenith, azimuth)", e)))
    return st;
  snprintf(m, sizeof m, "%s/zenith", w);
  if ((st = read_operand(s, cJSON_GetObjectItemCaseSensitive(o, "zenith"), m, 0, 180, &t->zen, e))) return st;
  snprintf(m, sizeof m, "%s/azimuth", w);
  t->kind = sun ? FORM_SUN : FORM_VIEW;
  return read_operand(s, cJSON_GetObjectItemCaseSensitive(o, "azimuth"), m, -INFINITY, INFINITY, &t->az, e);
}

/* One template's form, by its distinguishing member. */
static rsw_status compile_form(tmpl_set *s, tmpl *t, const cJSON *v, svc_error *e) {
  if (!cJSON_IsObject(v))
    return svc_fail(
        e, RSW_ERR_TYPE, t->ptr,
        "a template is an object: {\"value\"}, {\"coord\"[, \"x\", \"y\"]}, {\"sun\"} or {\"view\"}");
  const cJSON *val = cJSON_GetObjectItemCaseSensitive(v, "value");
  const cJSON *coord = cJSON_GetObjectItemCaseSensitive(v, "coord");
  const cJSON *sun = cJSON_GetObjectItemCaseSensitive(v, "sun");
  const cJSON *view = cJSON_GetObjectItemCaseSensitive(v, "view");
  rsw_status st;
  if (val) {
    static const char *const members[] = {"value", NULL};
    if ((st = only_members(v, members, t->ptr, "a constant template (value)", e))) return st;
    t->kind = FORM_VALUE;
    if (!(t->value = cJSON_Duplicate(val, 1))) return svc_fail(e, RSW_ERR_NOMEM, t->ptr, "out of memory");
    return RSW_OK;
  }
  if (coord && !cJSON_GetObjectItemCaseSensitive(v, "x") && !cJSON_GetObjectItemCaseSensitive(v, "y")) {
    static const char *const members[] = {"coord", NULL};
    if ((st = only_members(v, members, t->ptr, "a coordinate template (coord)", e))) return st;
    char w[400];
    snprintf(w, sizeof w, "%s/coord", t->ptr);
    t->kind = FORM_COORD;
    return read_coord_name(s, coord, w, &t->coord, e);
  }
  if (coord) return compile_table(s, t, v, e);
  if (sun || view) {
    static const char *const members[] = {"sun", "view", NULL};
    if ((st = only_members(v, members, t->ptr, "an angle template", e))) return st;
    if (sun && view) return svc_fail(e, RSW_ERR_INVALID, t->ptr, "a template is a sun or a view, not both");
    return compile_angles(s, t, sun ? sun : view, sun != NULL, e);
  }
  return svc_fail(e, RSW_ERR_INVALID, t->ptr,
                  "unknown template form (expected a member \"value\", \"coord\", \"sun\" or \"view\")");
}

static void tmpl_clear(tmpl *t) {
  free(t->key);
  cJSON_Delete(t->value);
  free(t->x);
  free(t->y);
  free(t->ops);
  memset(t, 0, sizeof *t);
}

void tmpl_free(tmpl_set *s) {
  if (!s) return;
  for (size_t i = 0; i < s->n; i++) tmpl_clear(&s->t[i]);
  for (size_t i = 0; i < s->n_coords; i++) free(s->coords[i]);
  free(s->coords);
  free(s->t);
  free(s);
}

/* The table index of key, or an unknown-key error at ptr (closest keys). */
static rsw_status lookup_key(const scene *sc, const char *key, const char *ptr, size_t *idx, svc_error *e) {
  rsw_err err = {0};
  if (params_lookup(sc, key, idx, &err) == RSW_OK) return RSW_OK;
  svc_key_error(e, sc, key, &err);
  snprintf(e->err.where, sizeof e->err.where, "%.250s", ptr);
  return e->err.code;
}

/* Whether map (a JSON object of overrides, may be NULL) names parameter idx. */
static bool map_names(const scene *sc, const cJSON *map, size_t idx) {
  for (const cJSON *k = cJSON_IsObject(map) ? map->child : NULL; k; k = k->next) {
    size_t j;
    rsw_err err = {0};
    if (params_lookup(sc, k->string, &j, &err) == RSW_OK && j == idx) return true;
  }
  return false;
}

static rsw_status add_templates(tmpl_set *s, const scene *sc, const cJSON *map, const char *base, bool of_job,
                                const cJSON *job_params, svc_error *e) {
  if (!map) return RSW_OK;
  if (!cJSON_IsObject(map))
    return svc_fail(e, RSW_ERR_TYPE, base, "templates must be an object {parameter key: template}");
  for (const cJSON *k = map->child; k; k = k->next) {
    char ptr[300];
    snprintf(ptr, sizeof ptr, "%.40s/%.250s", base, k->string);
    size_t idx;
    rsw_status st = lookup_key(sc, k->string, ptr, &idx, e);
    if (st) return st;
    if (map_names(sc, job_params, idx)) {
      if (of_job)
        return svc_fail(e, RSW_ERR_DUPLICATE, ptr,
                        "'%s' is given both as a template and in the job's params: keep one", k->string);
      continue; /* the job's explicit value wins over the scene's template */
    }
    size_t slot = s->n;
    for (size_t i = 0; i < s->n; i++)
      if (s->t[i].index == idx) {
        if (!of_job)
          return svc_fail(e, RSW_ERR_DUPLICATE, ptr, "'%s' names a parameter another template sets",
                          k->string);
        slot = i; /* the job's template replaces the scene's */
        tmpl_clear(&s->t[i]);
      }
    if (slot == s->n) {
      tmpl *g = realloc(s->t, (s->n + 1) * sizeof *g);
      if (!g) return svc_fail(e, RSW_ERR_NOMEM, ptr, "out of memory");
      s->t = g;
      memset(&s->t[s->n++], 0, sizeof *s->t);
    }
    tmpl *t = &s->t[slot];
    t->index = idx;
    snprintf(t->ptr, sizeof t->ptr, "%s", ptr);
    if (!(t->key = strdup(k->string))) return svc_fail(e, RSW_ERR_NOMEM, ptr, "out of memory");
    if ((st = compile_form(s, t, k, e))) return st;
  }
  return RSW_OK;
}

rsw_status tmpl_compile(const scene *sc, const cJSON *scene_tmpl, const char *scene_ptr,
                        const cJSON *job_tmpl, const cJSON *job_params, tmpl_set **out, svc_error *e) {
  *out = NULL;
  if (!scene_tmpl && !job_tmpl) return RSW_OK;
  tmpl_set *s = calloc(1, sizeof *s);
  if (!s) return svc_fail(e, RSW_ERR_NOMEM, "/templates", "out of memory");
  rsw_status st = add_templates(s, sc, scene_tmpl, scene_ptr, false, job_params, e);
  if (!st) st = add_templates(s, sc, job_tmpl, "/templates", true, job_params, e);
  if (st || !s->n) {
    tmpl_free(s);
    return st;
  }
  *out = s;
  return RSW_OK;
}

bool tmpl_uses_coord(const tmpl_set *s, const char *name) {
  for (size_t i = 0; s && i < s->n_coords; i++)
    if (strcmp(s->coords[i], name) == 0) return true;
  return false;
}

bool tmpl_origin(const tmpl_set *s, const char *key, char *ptr, size_t cap) {
  for (size_t i = 0; s && i < s->n; i++)
    if (strcmp(s->t[i].key, key) == 0) {
      snprintf(ptr, cap, "%s", s->t[i].ptr);
      return true;
    }
  return false;
}

/* ---- rendering --------------------------------------------------------------------- */

/* Coordinate values of one context, in the set's order; NAN until read. */
typedef struct coord_vals {
  const tmpl_set *s;
  const cJSON *coords;
  double wavelength;
  const char *ctx_ptr;
  double v[NC_MAX_COORDS * 4];
  bool have[NC_MAX_COORDS * 4];
} coord_vals;

static rsw_status coord_value(coord_vals *cv, int i, const tmpl *t, double *out, svc_error *e) {
  if ((size_t)i < sizeof cv->v / sizeof cv->v[0] && cv->have[i]) {
    *out = cv->v[i];
    return RSW_OK;
  }
  const char *name = cv->s->coords[i];
  char w[300];
  snprintf(w, sizeof w, "%.64s/coords/%.64s", cv->ctx_ptr, name);
  const cJSON *c = cJSON_GetObjectItemCaseSensitive(cv->coords, name);
  double v;
  if (strcmp(name, "wavelength") == 0 && !c) {
    if (!(cv->wavelength > 0))
      return svc_fail(e, RSW_ERR_MISSING, w, "template %s reads the wavelength; this context has none",
                      t->ptr);
    v = cv->wavelength;
  } else if (!c) {
    return svc_fail(e, RSW_ERR_MISSING, w, "the context has no coordinate '%s' (template %s reads it)", name,
                    t->ptr);
  } else if (!cJSON_IsNumber(c) || !isfinite(c->valuedouble)) {
    return svc_fail(e, RSW_ERR_INVALID, w, "coordinate '%s' must be a finite number (template %s reads it)",
                    name, t->ptr);
  } else {
    v = c->valuedouble;
  }
  if ((size_t)i < sizeof cv->v / sizeof cv->v[0]) {
    cv->v[i] = v;
    cv->have[i] = true;
  }
  *out = v;
  return RSW_OK;
}

static rsw_status operand_value(coord_vals *cv, const operand *o, const tmpl *t, double lo, double hi,
                                double *out, svc_error *e) {
  if (o->coord < 0) {
    *out = o->v;
    return RSW_OK;
  }
  rsw_status st = coord_value(cv, o->coord, t, out, e);
  if (!st && !(*out >= lo && *out <= hi)) {
    char w[300];
    snprintf(w, sizeof w, "%.64s/coords/%.64s", cv->ctx_ptr, cv->s->coords[o->coord]);
    return svc_fail(e, RSW_ERR_RANGE, w, "%g degrees lies outside [%g, %g] (template %s)", *out, lo, hi,
                    t->ptr);
  }
  return st;
}

/* -(sin z cos a, sin z sin a, cos z): the direction light from (z, a)
 * travels, and where a distant sensor at (z, a) looks (Eradiate's
 * angles_to_direction, negated). Degrees. */
static void toward(double zen_deg, double az_deg, double *d) {
  double z = zen_deg * DEG, a = az_deg * DEG, sz = sin(z);
  d[0] = -(sz * cos(a));
  d[1] = -(sz * sin(a));
  d[2] = -cos(z);
}

/* Linear interpolation at c, exact at the points: (1 - f) y_i + f y_i+1. */
static rsw_status render_table(coord_vals *cv, const tmpl *t, cJSON **out, svc_error *e) {
  double c;
  rsw_status st = coord_value(cv, t->coord, t, &c, e);
  if (st) return st;
  if (!(c >= t->x[0] && c <= t->x[t->n - 1])) {
    char w[300];
    snprintf(w, sizeof w, "%.64s/coords/%.64s", cv->ctx_ptr, cv->s->coords[t->coord]);
    return svc_fail(e, RSW_ERR_RANGE, w, "%s = %g lies outside the table of template %s [%g, %g]",
                    cv->s->coords[t->coord], c, t->ptr, t->x[0], t->x[t->n - 1]);
  }
  size_t lo = 0, hi = t->n - 1; /* x[lo] <= c <= x[hi] */
  while (hi - lo > 1) {
    size_t mid = lo + (hi - lo) / 2;
    if (t->x[mid] <= c)
      lo = mid;
    else
      hi = mid;
  }
  double f = (c - t->x[lo]) / (t->x[hi] - t->x[lo]);
  size_t len = t->len ? t->len : 1;
  const double *a = t->y + lo * len, *b = t->y + hi * len;
  if (!t->len) {
    *out = cJSON_CreateNumber(f == 0 ? a[0] : f == 1 ? b[0] : (1 - f) * a[0] + f * b[0]);
    return RSW_OK;
  }
  *out = cJSON_CreateArray();
  for (size_t k = 0; *out && k < len; k++) {
    double v = f == 0 ? a[k] : f == 1 ? b[k] : (1 - f) * a[k] + f * b[k];
    cJSON *n = cJSON_CreateNumber(v);
    if (!n || !cJSON_AddItemToArray(*out, n)) {
      cJSON_Delete(n);
      cJSON_Delete(*out);
      *out = NULL;
    }
  }
  return RSW_OK;
}

static cJSON *vector_json(const double *d, size_t n) {
  cJSON *a = cJSON_CreateArray();
  for (size_t k = 0; a && k < n; k++) {
    cJSON *x = cJSON_CreateNumber(d[k]);
    if (!x || !cJSON_AddItemToArray(a, x)) {
      cJSON_Delete(x);
      cJSON_Delete(a);
      a = NULL;
    }
  }
  return a;
}

static rsw_status render_one(coord_vals *cv, const tmpl *t, cJSON **out, svc_error *e) {
  double z, a, d[3];
  rsw_status st = RSW_OK;
  *out = NULL;
  switch (t->kind) {
  case FORM_VALUE: *out = cJSON_Duplicate(t->value, 1); break;
  case FORM_COORD:
    if (!(st = coord_value(cv, t->coord, t, &z, e))) *out = cJSON_CreateNumber(z);
    break;
  case FORM_TABLE: st = render_table(cv, t, out, e); break;
  case FORM_SUN:
  case FORM_VIEW:
    st = operand_value(cv, &t->zen, t, 0, 180, &z, e);
    if (!st) st = operand_value(cv, &t->az, t, -INFINITY, INFINITY, &a, e);
    if (!st) {
      toward(z, a, d);
      *out = vector_json(d, 3);
    }
    break;
  case FORM_HPLANE:
  case FORM_ANGLES: {
    double *v = malloc(3 * t->n * sizeof *v);
    if (!v) return svc_fail(e, RSW_ERR_NOMEM, t->ptr, "out of memory");
    if (t->kind == FORM_HPLANE) st = operand_value(cv, &t->az, t, -INFINITY, INFINITY, &a, e);
    for (size_t i = 0; !st && i < t->n; i++) {
      if (t->kind == FORM_HPLANE) {
        st = operand_value(cv, &t->ops[i], t, -180, 180, &z, e);
      } else {
        st = operand_value(cv, &t->ops[2 * i], t, 0, 180, &z, e);
        if (!st) st = operand_value(cv, &t->ops[2 * i + 1], t, -INFINITY, INFINITY, &a, e);
      }
      if (!st) toward(z, a, v + 3 * i);
    }
    if (!st) *out = vector_json(v, 3 * t->n);
    free(v);
    break;
  }
  }
  if (!st && !*out) st = svc_fail(e, RSW_ERR_NOMEM, t->ptr, "out of memory");
  return st;
}

rsw_status tmpl_render(const tmpl_set *s, const scene *sc, const cJSON *coords, double wavelength, cJSON *out,
                       const char *ctx_ptr, svc_error *e) {
  if (!s) return RSW_OK;
  coord_vals cv = {.s = s, .coords = coords, .wavelength = wavelength, .ctx_ptr = ctx_ptr};
  for (size_t i = 0; i < s->n; i++) {
    const tmpl *t = &s->t[i];
    if (out->child && map_names(sc, out, t->index)) continue; /* explicit values win */
    cJSON *v;
    rsw_status st = render_one(&cv, t, &v, e);
    if (st) return st;
    if (!cJSON_AddItemToObject(out, t->key, v)) {
      cJSON_Delete(v);
      return svc_fail(e, RSW_ERR_NOMEM, t->ptr, "out of memory");
    }
  }
  return RSW_OK;
}

/* ---- the silent no-op sweep ------------------------------------------------------ */

/* The coordinate `wavelength` sets the context's wavelength: a positive
 * finite number of nm, in a mono scene, equal to the context's
 * "wavelength" when both are given. */
rsw_status tmpl_check_coord_wavelength(const scene *sc, const cJSON *w, const cJSON *cw, const char *ptr,
                                       svc_error *e) {
  char p[96];
  snprintf(p, sizeof p, "%s/coords/wavelength", ptr);
  if (!cJSON_IsNumber(cw) || !(cw->valuedouble > 0) || !isfinite(cw->valuedouble))
    return svc_fail(e, RSW_ERR_INVALID, p,
                    "the coordinate wavelength (the context's wavelength) must be a "
                    "positive finite number of nm");
  if (sc->variant != VARIANT_MONO)
    return svc_fail(e, RSW_ERR_INVALID, p, "wavelength applies to mono scenes; this scene is rgb");
  if (w && w->valuedouble != cw->valuedouble)
    return svc_fail(e, RSW_ERR_INVALID, p,
                    "the coordinate wavelength (%.17g) differs from %s/wavelength (%.17g)", cw->valuedouble,
                    ptr, w->valuedouble);
  return RSW_OK;
}

/* A context's fingerprint for the no-op sweep check (templates.h): what
 * it renders with besides a seed it did not choose. Common parts (the
 * job-level overrides) may be left out: only differences matter. */
void tmpl_ctx_digest(const cJSON *params, double wl, bool spectral, const cJSON *c, const cJSON *d_sensors,
                     unsigned char out[32]) {
  rsw_sha256_ctx h;
  memset(out, 0, 32);
  if (!rsw_sha256_begin(&h)) return;
  char *txt = params ? cJSON_PrintUnformatted(params) : NULL;
  if (txt) rsw_sha256_update(&h, txt, strlen(txt));
  free(txt);
  char buf[160];
  snprintf(buf, sizeof buf, "\n%.17g", spectral ? wl : 0.0);
  rsw_sha256_update(&h, buf, strlen(buf));
  static const char *const own[] = {"spp", "seed", "sensors"};
  for (int i = 0; i < 3; i++) {
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(c, own[i]);
    if (!v && i == 2) v = d_sensors;
    char *t = v ? cJSON_PrintUnformatted(v) : NULL;
    rsw_sha256_update(&h, "\n", 1);
    if (t) rsw_sha256_update(&h, t, strlen(t));
    free(t);
  }
  rsw_sha256_end(&h, out);
}

typedef struct sort_row {
  const tmpl_ctx_sig *c;
  char *others; /* the other coordinates' values, printed */
  const cJSON *mine;
} sort_row;

static int cmp_rows(const void *pa, const void *pb) {
  const sort_row *a = pa, *b = pb;
  return strcmp(a->others, b->others);
}

static bool same_value(const cJSON *a, const cJSON *b) {
  if (!a || !b) return a == b;
  if (cJSON_IsNumber(a) && cJSON_IsNumber(b)) return a->valuedouble == b->valuedouble;
  return cJSON_IsString(a) && cJSON_IsString(b) && strcmp(a->valuestring, b->valuestring) == 0;
}

/* The other coordinates of a context as one string (numbers to 17
 * digits: distinct doubles print distinctly). */
static char *others_key(const cJSON *coords, const char *skip) {
  svc_buf b = svc_buf_make(1 << 16);
  for (const cJSON *k = cJSON_IsObject(coords) ? coords->child : NULL; k; k = k->next) {
    if (strcmp(k->string, skip) == 0) continue;
    if (cJSON_IsNumber(k))
      svc_buf_printf(&b, "%s=%.17g\x1f", k->string, k->valuedouble);
    else if (cJSON_IsString(k))
      svc_buf_printf(&b, "%s=\"%s\x1f", k->string, k->valuestring);
  }
  if (!b.n) {
    svc_buf_free(&b);
    return strdup("");
  }
  return svc_buf_take(&b);
}

static void add_warning(cJSON *a, const char *code, const char *coord, const char *detail) {
  cJSON *w = cJSON_CreateObject();
  cJSON_AddStringToObject(w, "code", code);
  cJSON_AddStringToObject(w, "coordinate", coord);
  cJSON_AddStringToObject(w, "detail", detail);
  svc_json_push(a, w);
}

/* Coordinate `name` is unused when contexts equal in every other
 * coordinate differ in it somewhere, and never differ in what they render
 * where they differ in it. */
static int coordinate_unused(const tmpl_ctx_sig *ctx, size_t n, const char *name) {
  sort_row *r = calloc(n, sizeof *r);
  if (!r) return -1;
  int verdict = 0;
  for (size_t i = 0; i < n; i++) {
    r[i].c = &ctx[i];
    r[i].mine = cJSON_GetObjectItemCaseSensitive(ctx[i].coords, name);
    if (!(r[i].others = others_key(ctx[i].coords, name))) verdict = -1;
  }
  if (verdict == 0) {
    qsort(r, n, sizeof *r, cmp_rows);
    bool differs = false, used = false;
    for (size_t i = 0; i < n && !used;) {
      size_t j = i + 1;
      while (j < n && strcmp(r[j].others, r[i].others) == 0) j++;
      bool vary = false, rendered = false;
      for (size_t k = i + 1; k < j; k++) {
        vary |= !same_value(r[k].mine, r[i].mine);
        rendered |= memcmp(r[k].c->digest, r[i].c->digest, 32) != 0;
      }
      differs |= vary;
      used |= vary && rendered;
      i = j;
    }
    verdict = differs && !used;
  }
  for (size_t i = 0; i < n; i++) free(r[i].others);
  free(r);
  return verdict;
}

cJSON *tmpl_sweep_warnings(const tmpl_ctx_sig *ctx, size_t n, bool spectral) {
  unsigned jm = svc_json_mark();
  cJSON *a = cJSON_CreateArray();
  if (!a || n < 2) {
    cJSON_Delete(a);
    return NULL;
  }
  bool wl_varies = false;
  for (size_t i = 1; i < n && !wl_varies; i++) wl_varies = ctx[i].wavelength != ctx[0].wavelength;
  if (wl_varies && !spectral)
    add_warning(a, "wavelength_unused", "wavelength",
                "the contexts differ in wavelength but nothing they render depends on it (no tabulated "
                "spectrum, spectral grid or template reads the wavelength): every wavelength gives the same "
                "result");
  for (const cJSON *k = cJSON_IsObject(ctx[0].coords) ? ctx[0].coords->child : NULL; k; k = k->next) {
    if (strcmp(k->string, "wavelength") == 0 && wl_varies && !spectral) continue; /* said above */
    if (coordinate_unused(ctx, n, k->string) != 1) continue;
    char d[400];
    snprintf(d, sizeof d,
             "the contexts differ in coordinate '%s' but render the same thing wherever they do: no template "
             "reads it and no override, wavelength, sensor, spp or explicit seed changes with it",
             k->string);
    add_warning(a, "coordinate_unused", k->string, d);
  }
  if (!svc_json_ok(jm) || !a->child) {
    cJSON_Delete(a);
    return NULL;
  }
  return a;
}

bool tmpl_blame(const tmpl_set *t, const char *ctx, svc_error *e) {
  char tp[300];
  if (!t || !e->key[0] || !tmpl_origin(t, e->key, tp, sizeof tp)) return false;
  char msg[sizeof e->err.msg];
  memcpy(msg, e->err.msg, sizeof msg);
  snprintf(e->err.where, sizeof e->err.where, "%.250s", tp);
  snprintf(e->err.msg, sizeof e->err.msg, "rendered for %.64s: %.660s", ctx, msg);
  return true;
}
