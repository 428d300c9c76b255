/* Parameter updates: values parsed from JSON, and the resolve, validate,
 * stage, apply (or undo) of scene_update; scene_update_check is the same
 * run that stops after validating (update.h). */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../accel.h"
#include "../media/media.h"
#include "../shapes/mesh_io.h"
#include "../shapes/shape.h"
#include "../textures/texture.h"
#include "param_table.h"
#include "params_internal.h"
#include "scene.h"
#include "update.h"

/* ---- parsing values --------------------------------------------------------------- */

void param_value_free(param_value *v) {
  if (!v) return;
  free(v->arr);
  spectrum_free(&v->table);
  memset(v, 0, sizeof *v);
}

static bool json_numbers(const cJSON *a, double *out, size_t *n) {
  size_t k = 0;
  for (const cJSON *x = a->child; x; x = x->next) {
    if (!cJSON_IsNumber(x)) return false;
    if (out) out[k] = x->valuedouble;
    k++;
  }
  *n = k;
  return true;
}

static rsw_status parse_table(const cJSON *o, const char *where, spectrum *out, rsw_err *err) {
  const cJSON *wl = cJSON_GetObjectItemCaseSensitive(o, "wavelengths");
  const cJSON *vals = cJSON_GetObjectItemCaseSensitive(o, "values");
  const cJSON *value = cJSON_GetObjectItemCaseSensitive(o, "value");
  memset(out, 0, sizeof *out);
  out->kind = SPEC_TABLE;
  size_t n = 0;
  if (wl && vals) {
    size_t n2;
    if (!cJSON_IsArray(wl) || !cJSON_IsArray(vals) || !json_numbers(wl, NULL, &n) ||
        !json_numbers(vals, NULL, &n2) || n != n2)
      return rsw_fail(err, RSW_ERR_TYPE, where,
                      "a tabulated spectrum needs \"wavelengths\" and \"values\": two lists of numbers of "
                      "the same length");
  } else if (value && cJSON_IsArray(value)) {
    for (const cJSON *x = value->child; x; x = x->next) {
      size_t k;
      if (!cJSON_IsArray(x) || !json_numbers(x, NULL, &k) || k != 2)
        return rsw_fail(err, RSW_ERR_TYPE, where,
                        "a spectrum \"value\" list holds [wavelength_nm, value] pairs");
      n++;
    }
  } else {
    return rsw_fail(err, RSW_ERR_TYPE, where,
                    "expected {\"wavelengths\": [...], \"values\": [...]} or {\"type\": \"spectrum\", "
                    "\"value\": [[wl, v], ...]}");
  }
  if (n < 2 || n > RSW_MAX_SPECTRUM)
    return rsw_fail(err, RSW_ERR_INVALID, where, "a tabulated spectrum needs between 2 and %d samples",
                    RSW_MAX_SPECTRUM);
  out->n = n;
  out->wl = malloc(n * sizeof(double));
  out->val = malloc(n * sizeof(double));
  if (!out->wl || !out->val) {
    spectrum_free(out);
    return rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory");
  }
  if (wl && vals) {
    size_t k;
    json_numbers(wl, out->wl, &k);
    json_numbers(vals, out->val, &k);
  } else {
    size_t i = 0;
    for (const cJSON *x = value->child; x; x = x->next, i++) {
      out->wl[i] = x->child->valuedouble;
      out->val[i] = x->child->next->valuedouble;
    }
  }
  for (size_t i = 0; i < n; i++)
    if (!(out->wl[i] > 0) || (i && !(out->wl[i] > out->wl[i - 1]))) {
      spectrum_free(out);
      return rsw_fail(err, RSW_ERR_INVALID, where,
                      "spectrum wavelengths must be positive and strictly increasing");
    }
  return RSW_OK;
}

rsw_status param_value_from_json(const cJSON *j, const char *where, param_value *out, rsw_err *err) {
  memset(out, 0, sizeof *out);
  rsw_status st = RSW_OK;
  if (cJSON_IsNumber(j)) {
    out->kind = PV_NUMBER;
    out->num = j->valuedouble;
  } else if (cJSON_IsBool(j)) {
    out->kind = PV_BOOL;
    out->b = cJSON_IsTrue(j);
  } else if (cJSON_IsArray(j)) {
    out->kind = PV_ARRAY;
    size_t n = 0;
    if (json_numbers(j, NULL, &n)) {
      out->arr = malloc((n ? n : 1) * sizeof(double));
      if (!out->arr)
        st = rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory");
      else
        json_numbers(j, out->arr, &out->n);
    } else {
      /* Nested rows of equal length (a 4x4 matrix). */
      size_t rows = 0, cols = 0, total = 0;
      for (const cJSON *r = j->child; r && !st; r = r->next, rows++) {
        size_t k = 0;
        if (!cJSON_IsArray(r) || !json_numbers(r, NULL, &k) || (rows && k != cols))
          st = rsw_fail(err, RSW_ERR_TYPE, where, "expected numbers, or rows of numbers of equal length");
        cols = k;
        total += k;
      }
      if (!st) {
        out->arr = malloc((total ? total : 1) * sizeof(double));
        if (!out->arr) st = rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory");
      }
      if (!st) {
        size_t k = 0;
        for (const cJSON *r = j->child; r; r = r->next) {
          size_t m = 0;
          json_numbers(r, out->arr + k, &m);
          k += m;
        }
        out->n = total;
        out->rows = rows;
      }
    }
  } else if (cJSON_IsObject(j)) {
    const cJSON *type = cJSON_GetObjectItemCaseSensitive(j, "type");
    const cJSON *value = cJSON_GetObjectItemCaseSensitive(j, "value");
    if (type && cJSON_IsString(type) &&
        (strcmp(type->valuestring, "rgb") == 0 || strcmp(type->valuestring, "uniform") == 0)) {
      /* {"type": "rgb", "value": [r, g, b]} / {"type": "uniform", "value": x} */
      if (value && cJSON_IsNumber(value)) {
        out->kind = PV_NUMBER;
        out->num = value->valuedouble;
      } else if (value && cJSON_IsArray(value) && strcmp(type->valuestring, "rgb") == 0) {
        size_t n;
        out->kind = PV_ARRAY;
        out->arr = malloc(3 * sizeof(double));
        if (!out->arr || !json_numbers(value, NULL, &n) || n != 3)
          st = rsw_fail(err, RSW_ERR_TYPE, where, "rgb: \"value\" must be 3 numbers");
        else
          json_numbers(value, out->arr, &out->n);
      } else {
        st = rsw_fail(err, RSW_ERR_TYPE, where, "%s: missing or bad \"value\"", type->valuestring);
      }
    } else if (type && cJSON_IsString(type) && strcmp(type->valuestring, "spectrum") == 0 && value &&
               cJSON_IsNumber(value)) {
      out->kind = PV_NUMBER;
      out->num = value->valuedouble;
    } else {
      out->kind = PV_TABLE;
      st = parse_table(j, where, &out->table, err);
    }
  } else {
    st = rsw_fail(err, RSW_ERR_TYPE, where, "expected a number, a list of numbers or a spectrum object");
  }
  if (st) param_value_free(out);
  return st;
}

rsw_status param_value_parse(const char *json, const char *where, param_value *out, rsw_err *err) {
  memset(out, 0, sizeof *out);
  if (!json || !*json) return rsw_fail(err, RSW_ERR_PARSE, where, "empty value");
  const char *end = NULL;
  cJSON *j = cJSON_ParseWithOpts(json, &end, 1);
  if (!j) return rsw_fail(err, RSW_ERR_PARSE, where, "value is not valid JSON: '%s'", json);
  rsw_status st = param_value_from_json(j, where, out, err);
  cJSON_Delete(j);
  return st;
}

/* ---- updates -------------------------------------------------------------------- */

static const char *kind_expect(const scene *s, const entry *e) {
  switch (e->kind) {
  case EK_FLOAT: return "a number";
  case EK_BOOL: return "a boolean";
  case EK_TRANSFORM: return "a 4x4 matrix (16 numbers, row-major, or 4 rows of 4)";
  case EK_VECTOR: return "3 numbers";
  case EK_SPECTRUM:
    return s->variant == VARIANT_MONO ? "a number, an [r, g, b] triple or a tabulated spectrum"
                                      : "a number or an [r, g, b] triple";
  case EK_MESHBUF: return "a flat list of numbers";
  case EK_DBUF: return "a flat list of numbers";
  }
  return "a value";
}

/* A range bound as text: %g when that reads back exactly, else all 17
 * digits (an open interval's bound, e.g. hg's g < 1, is the closed one
 * just inside it, which %g would print as the excluded 1). */
static const char *bound_text(double b, char buf[32]) {
  snprintf(buf, 32, "%g", b);
  if (strtod(buf, NULL) != b) snprintf(buf, 32, "%.17g", b);
  return buf;
}

static rsw_status check_range(const entry *e, const char *key, double x, rsw_err *err) {
  if (!isfinite(x)) return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': value must be finite", key);
  if (fabs(x) > RSW_MAX_MAGNITUDE)
    return rsw_fail(err, RSW_ERR_RANGE, key,
                    "'%s': value %g exceeds the largest magnitude a value may have (%g)", key, x,
                    RSW_MAX_MAGNITUDE);
  if (x < e->lo || x > e->hi) {
    char lo[32], hi[32];
    if (isinf(e->hi))
      return rsw_fail(err, RSW_ERR_RANGE, key, "'%s': value %g must be >= %s", key, x, bound_text(e->lo, lo));
    return rsw_fail(err, RSW_ERR_RANGE, key, "'%s': value %g must lie in [%s, %s]", key, x,
                    bound_text(e->lo, lo), bound_text(e->hi, hi));
  }
  return RSW_OK;
}

/* A staged update: what validation decided, applied afterwards. */
typedef struct staged {
  size_t index;
  const param_update *item;
  xform xf;
  spectrum spec; /* borrowed from the item (copied on apply) */
  vec3 vec;
  float *fpos; /* vertex_positions converted to float (owned until applied) */
  bool changed;
  /* Prepared before anything is written (prepare()), so that applying
   * cannot fail; and what applying replaced, so that a failure after it
   * (Embree, the scene-wide float32 check, a sensor) puts it all back. */
  spectrum new_spec; /* owned copy of the new spectrum; after apply: the old one */
  bool spec_ready;
  void *buf; /* faces (uint32), normals or texcoords (float), owned */
  bool applied;
  double old_f;
  xform old_xf;
  vec3 old_vec;
  void *old_buf;      /* the mesh buffer replaced (positions, faces, normals, uvs) */
  uint32_t old_count; /* n_verts (positions) or n_faces (faces) before */
} staged;

static bool spectrum_equal(const spectrum *a, const spectrum *b) {
  if (a->kind != b->kind) return false;
  switch (a->kind) {
  case SPEC_UNIFORM: return a->value == b->value;
  case SPEC_RGB: return memcmp(a->rgb, b->rgb, sizeof a->rgb) == 0;
  case SPEC_TABLE:
    return a->n == b->n && memcmp(a->wl, b->wl, a->n * sizeof(double)) == 0 &&
           memcmp(a->val, b->val, a->n * sizeof(double)) == 0;
  }
  return false;
}

/* Vertex count the mesh will have after this map (positions may change it
 * only together with faces). */
static rsw_status validate(const scene *s, staged *sg, const staged *all, size_t n_all, rsw_err *err) {
  const entry *e = &s->params->e[sg->index];
  const param_value *v = &sg->item->value;
  const char *key = sg->item->key;
  if (e->cls == UPDATE_NONE) return rsw_fail(err, RSW_ERR_INVALID, key, "'%s' is read-only", e->key);
  switch (e->kind) {
  case EK_FLOAT: {
    if (v->kind != PV_NUMBER)
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes %s", key, kind_expect(s, e));
    rsw_status st = check_range(e, key, v->num, err);
    if (st) return st;
    sg->changed = *e->fptr != v->num;
    return RSW_OK;
  }
  case EK_TRANSFORM: {
    if (v->kind != PV_ARRAY || v->n != 16 || (v->rows && v->rows != 4))
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes %s", key, kind_expect(s, e));
    double m[4][4];
    for (int i = 0; i < 16; i++) {
      if (!isfinite(v->arr[i]))
        return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': matrix entries must be finite", key);
      m[i / 4][i % 4] = v->arr[i];
    }
    /* A shape's transform (the geometric ones) must be one float32 tracing
     * can represent: checked on the matrix itself first, so that a tiny
     * scale is reported as such rather than as "singular". */
    char msg[512];
    if (e->cls == UPDATE_GEOMETRIC && !xf_traceable(m, key, msg, sizeof msg))
      return rsw_fail(err, RSW_ERR_RANGE, key, "%s", msg);
    if (!xf_from_matrix(m, &sg->xf))
      return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': matrix is singular", key);
    if (e->check) {
      rsw_status st = e->check(e->owner, &sg->xf, key, err);
      if (st) return st;
    }
    sg->changed = memcmp(e->xptr->m, sg->xf.m, sizeof sg->xf.m) != 0;
    return RSW_OK;
  }
  case EK_VECTOR: {
    if (v->kind != PV_ARRAY || v->n != 3 || v->rows)
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes %s", key, kind_expect(s, e));
    sg->vec = v3(v->arr[0], v->arr[1], v->arr[2]);
    if (!v3_finite(sg->vec))
      return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': a vector's components must be finite", key);
    if (!e->position && !(v3_len(sg->vec) > 0))
      return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': a direction must be non-zero", key);
    vec3 cur = e->vget(e->owner);
    sg->changed = cur.x != sg->vec.x || cur.y != sg->vec.y || cur.z != sg->vec.z;
    return RSW_OK;
  }
  case EK_SPECTRUM: {
    spectrum sp = {.kind = SPEC_UNIFORM};
    if (v->kind == PV_NUMBER) {
      sp.value = v->num;
      rsw_status st = check_range(e, key, v->num, err);
      if (st) return st;
    } else if (v->kind == PV_ARRAY && v->n == 3 && !v->rows) {
      sp.kind = SPEC_RGB;
      for (int i = 0; i < 3; i++) {
        sp.rgb[i] = v->arr[i];
        rsw_status st = check_range(e, key, v->arr[i], err);
        if (st) return st;
      }
    } else if (v->kind == PV_TABLE) {
      if (s->variant != VARIANT_MONO)
        return rsw_fail(err, RSW_ERR_UNSUPPORTED, key,
                        "'%s': a tabulated spectrum needs the mono variant (this scene is rgb)", key);
      sp = v->table;
      for (size_t i = 0; i < sp.n; i++) {
        rsw_status st = check_range(e, key, sp.val[i], err);
        if (st) return st;
      }
    } else {
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes %s", key, kind_expect(s, e));
    }
    sg->spec = sp;
    const spectrum *cur = uniform_texture_spectrum(e->tex);
    sg->changed = !cur || !spectrum_equal(cur, &sp);
    return RSW_OK;
  }
  case EK_MESHBUF: {
    if (v->kind != PV_ARRAY || v->rows)
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes %s", key, kind_expect(s, e));
    const mesh *m = &e->sh->mesh;
    /* Other buffers of the same mesh in this map decide the new counts. */
    const param_value *pos = NULL, *faces = NULL;
    for (size_t k = 0; k < n_all; k++) {
      const entry *o = &s->params->e[all[k].index];
      if (o->kind != EK_MESHBUF || o->sh != e->sh) continue;
      if (o->buf == MB_POSITIONS) pos = &all[k].item->value;
      if (o->buf == MB_FACES) faces = &all[k].item->value;
    }
    size_t nv = pos && pos->kind == PV_ARRAY ? pos->n / 3 : m->n_verts;
    switch (e->buf) {
    case MB_POSITIONS:
      if (v->n % 3 || !v->n || (v->n != 3 * (size_t)m->n_verts && !faces))
        return rsw_fail(err, RSW_ERR_INVALID, key,
                        "'%s' takes %u numbers (3 per vertex); changing the vertex count needs 'faces' in "
                        "the same update",
                        key, 3 * m->n_verts);
      if (v->n / 3 > MESH_MAX_ELEMENTS)
        return rsw_fail(err, RSW_ERR_LIMIT, key, "'%s': too many vertices", key);
      {
        /* Branch-free scan first (vectorises), then locate the culprit. */
        int bad = 0;
        for (size_t i = 0; i < v->n; i++) bad |= !(fabs(v->arr[i]) <= RSW_TRACE_MAX_COORD);
        for (size_t i = 0; bad && i < v->n; i++)
          if (!(fabs(v->arr[i]) <= RSW_TRACE_MAX_COORD))
            return rsw_fail(err, isfinite(v->arr[i]) ? RSW_ERR_RANGE : RSW_ERR_INVALID, key,
                            "'%s': coordinate %zu (%g) is not finite or exceeds %g, the largest float32 "
                            "tracing accepts",
                            key, i, v->arr[i], RSW_TRACE_MAX_COORD);
        /* Their image under the shape's to_world (core/transform.h). */
        const xform *t = &e->sh->to_world;
        double w = 0;
        for (size_t i = 0; i + 2 < v->n; i += 3)
          w = fmax(w, v3_max_abs(xf_point(t, v3(v->arr[i], v->arr[i + 1], v->arr[i + 2]))));
        if (!(w <= RSW_TRACE_MAX_COORD))
          return rsw_fail(
              err, RSW_ERR_RANGE, key,
              "'%s': the mesh would reach a world coordinate of %g, beyond %g, the largest float32 "
              "tracing accepts",
              key, w, RSW_TRACE_MAX_COORD);
      }
      break;
    case MB_FACES:
      if (!v->n || v->n % 3 || v->n / 3 > MESH_MAX_ELEMENTS)
        return rsw_fail(err, RSW_ERR_INVALID, key,
                        "'%s' takes a non-empty list of vertex indices, 3 per face", key);
      for (size_t i = 0; i < v->n; i++)
        if (!(v->arr[i] >= 0 && v->arr[i] < (double)nv && v->arr[i] == floor(v->arr[i])))
          return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': index %zu (%g) is not a vertex index below %zu",
                          key, i, v->arr[i], nv);
      break;
    case MB_NORMALS:
    case MB_TEXCOORDS: {
      size_t per = e->buf == MB_NORMALS ? 3 : 2;
      if (v->n != per * nv)
        return rsw_fail(err, RSW_ERR_INVALID, key, "'%s' takes %zu numbers (%zu per vertex)", key, per * nv,
                        per);
      for (size_t i = 0; i < v->n; i++)
        if (!isfinite(v->arr[i]))
          return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': values must be finite", key);
      break;
    }
    }
    sg->changed = true;
    if (e->buf == MB_POSITIONS && v->n == 3 * (size_t)m->n_verts) {
      int diff = 0;
      for (size_t i = 0; i < v->n; i++) diff |= (float)v->arr[i] != m->pos[i];
      sg->changed = diff != 0;
    } else if (e->buf == MB_FACES && v->n == 3 * (size_t)m->n_faces) {
      sg->changed = false;
      for (size_t i = 0; i < v->n && !sg->changed; i++) sg->changed = (uint32_t)v->arr[i] != m->faces[i];
    }
    return RSW_OK;
  }
  case EK_DBUF: {
    const double *x = v->kind == PV_NUMBER ? &v->num : v->arr;
    size_t n = v->kind == PV_NUMBER ? 1 : v->n;
    if (v->kind != PV_NUMBER && v->kind != PV_ARRAY)
      return rsw_fail(err, RSW_ERR_TYPE, key, "'%s' takes a flat list of %zu numbers", key, e->dn);
    if (n != e->dn)
      return rsw_fail(err, RSW_ERR_INVALID, key, "'%s' takes %zu numbers (its shape is fixed), got %zu", key,
                      e->dn, n);
    for (size_t i = 0; i < n; i++) {
      if (!isfinite(x[i]))
        return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': value at index %zu must be finite", key, i);
      if (x[i] < e->lo || x[i] > e->hi) {
        if (isinf(e->hi))
          return rsw_fail(err, RSW_ERR_RANGE, key, "'%s': value %g at index %zu must be >= %g", key, x[i], i,
                          e->lo);
        if (isinf(e->lo))
          return rsw_fail(err, RSW_ERR_RANGE, key, "'%s': value %g at index %zu must be <= %g", key, x[i], i,
                          e->hi);
        return rsw_fail(err, RSW_ERR_RANGE, key, "'%s': value %g at index %zu must lie in [%g, %g]", key,
                        x[i], i, e->lo, e->hi);
      }
    }
    if (e->dcheck) {
      rsw_status st = e->dcheck(e->owner, x, n, key, err);
      if (st) return st;
    }
    sg->changed = memcmp(x, e->dptr, n * sizeof(double)) != 0;
    return RSW_OK;
  }
  case EK_BOOL: break;
  }
  return rsw_fail(err, RSW_ERR_INVALID, key, "'%s' is read-only", e->key);
}

/* Everything applying needs that could fail (allocations), done before
 * anything is written. */
static rsw_status prepare(staged *sg, const entry *e, rsw_err *err) {
  const param_value *v = &sg->item->value;
  if (e->kind == EK_SPECTRUM) {
    if (!uniform_spectrum_copy(&sg->new_spec, &sg->spec))
      return rsw_fail(err, RSW_ERR_NOMEM, e->key, "out of memory");
    sg->spec_ready = true;
    return RSW_OK;
  }
  if (e->kind == EK_DBUF) {
    /* The values it replaces, for undo_one. */
    sg->old_buf = malloc(e->dn * sizeof(double));
    if (!sg->old_buf) return rsw_fail(err, RSW_ERR_NOMEM, e->key, "out of memory");
    return RSW_OK;
  }
  if (e->kind != EK_MESHBUF) return RSW_OK;
  switch (e->buf) {
  case MB_POSITIONS:
    if (!sg->fpos) {
      sg->fpos = malloc((v->n ? v->n : 1) * sizeof(float));
      if (!sg->fpos) return rsw_fail(err, RSW_ERR_NOMEM, e->key, "out of memory");
      for (size_t q = 0; q < v->n; q++) sg->fpos[q] = (float)v->arr[q];
    }
    break;
  case MB_FACES: {
    uint32_t *f = malloc((v->n ? v->n : 1) * sizeof(uint32_t));
    if (!f) return rsw_fail(err, RSW_ERR_NOMEM, e->key, "out of memory");
    for (size_t i = 0; i < v->n; i++) f[i] = (uint32_t)v->arr[i];
    sg->buf = f;
    break;
  }
  case MB_NORMALS:
  case MB_TEXCOORDS: {
    float *f = malloc((v->n ? v->n : 1) * sizeof(float));
    if (!f) return rsw_fail(err, RSW_ERR_NOMEM, e->key, "out of memory");
    for (size_t i = 0; i < v->n; i++) f[i] = (float)v->arr[i];
    sg->buf = f;
    break;
  }
  }
  return RSW_OK;
}

/* Write one prepared value, remembering what it replaced. Cannot fail. */
static void apply_one(staged *sg, const entry *e) {
  switch (e->kind) {
  case EK_FLOAT:
    sg->old_f = *e->fptr;
    *e->fptr = sg->item->value.num;
    break;
  case EK_TRANSFORM:
    sg->old_xf = *e->xptr;
    *e->xptr = sg->xf;
    break;
  case EK_VECTOR:
    sg->old_vec = e->vget(e->owner);
    e->vset(e->owner, sg->vec);
    break;
  case EK_SPECTRUM: uniform_texture_swap_spectrum(e->tex, &sg->new_spec); break;
  case EK_MESHBUF: {
    mesh *m = &e->sh->mesh;
    size_t n = sg->item->value.n;
    switch (e->buf) {
    case MB_POSITIONS:
      sg->old_buf = m->pos, sg->old_count = m->n_verts;
      m->pos = sg->fpos, m->n_verts = (uint32_t)(n / 3);
      sg->fpos = NULL;
      break;
    case MB_FACES:
      sg->old_buf = m->faces, sg->old_count = m->n_faces;
      m->faces = sg->buf, m->n_faces = (uint32_t)(n / 3);
      sg->buf = NULL;
      break;
    case MB_NORMALS:
      sg->old_buf = m->nrm;
      m->nrm = sg->buf;
      sg->buf = NULL;
      break;
    case MB_TEXCOORDS:
      sg->old_buf = m->uv;
      m->uv = sg->buf;
      sg->buf = NULL;
      break;
    }
    break;
  }
  case EK_DBUF: {
    const param_value *v = &sg->item->value;
    memcpy(sg->old_buf, e->dptr, e->dn * sizeof(double));
    memcpy(e->dptr, v->kind == PV_NUMBER ? &v->num : v->arr, e->dn * sizeof(double));
    break;
  }
  case EK_BOOL: break;
  }
  sg->applied = true;
}

/* Put back what apply_one replaced (the new value is freed). */
static void undo_one(staged *sg, const entry *e) {
  if (!sg->applied) return;
  switch (e->kind) {
  case EK_FLOAT: *e->fptr = sg->old_f; break;
  case EK_TRANSFORM: *e->xptr = sg->old_xf; break;
  case EK_VECTOR: e->vset(e->owner, sg->old_vec); break;
  case EK_SPECTRUM: uniform_texture_swap_spectrum(e->tex, &sg->new_spec); break;
  case EK_MESHBUF: {
    mesh *m = &e->sh->mesh;
    void *cur = NULL;
    switch (e->buf) {
    case MB_POSITIONS: cur = m->pos, m->pos = sg->old_buf, m->n_verts = sg->old_count; break;
    case MB_FACES: cur = m->faces, m->faces = sg->old_buf, m->n_faces = sg->old_count; break;
    case MB_NORMALS: cur = m->nrm, m->nrm = sg->old_buf; break;
    case MB_TEXCOORDS: cur = m->uv, m->uv = sg->old_buf; break;
    }
    free(cur);
    sg->old_buf = NULL;
    break;
  }
  case EK_DBUF: memcpy(e->dptr, sg->old_buf, e->dn * sizeof(double)); break;
  case EK_BOOL: break;
  }
  sg->applied = false;
}

/* Free what the staged entries still own: prepared values not applied,
 * values replaced by a successful update. */
static void staged_free(staged *sg, size_t n) {
  for (size_t i = 0; i < n; i++) {
    free(sg[i].fpos);
    free(sg[i].buf);
    free(sg[i].old_buf);
    if (sg[i].spec_ready) spectrum_free(&sg[i].new_spec);
  }
  free(sg);
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* The acceleration structure and the scene's bounds after the values of
 * sg were written (restore = false) or put back (restore = true: every
 * touched mesh is rebuilt, whatever its update was). */
static rsw_status update_geometry(scene *s, staged *sg, size_t n, bool restore, rsw_err *err) {
  rsw_status st = RSW_OK;
  for (size_t i = 0; i < n && !st; i++) {
    if (!sg[i].changed) continue;
    const entry *e = &s->params->e[sg[i].index];
    if (e->cls != UPDATE_GEOMETRIC) continue;
    const shape *sh = (const shape *)e->owner;
    if (e->kind == EK_TRANSFORM) {
      accel_update_transform(s->accel, sh);
    } else if (e->kind == EK_MESHBUF) {
      bool topology = restore;
      for (size_t k = 0; k < n; k++) {
        const entry *o = &s->params->e[sg[k].index];
        if (sg[k].changed && o->kind == EK_MESHBUF && o->sh == e->sh && o->buf == MB_FACES) topology = true;
      }
      if (restore) {
        /* Once per mesh: at its first changed buffer. */
        bool first = true;
        for (size_t k = 0; k < i && first; k++) {
          const entry *o = &s->params->e[sg[k].index];
          first = !(sg[k].changed && o->kind == EK_MESHBUF && o->sh == e->sh);
        }
        if (first) st = accel_rebuild_shape(s->accel, sh, err);
      } else if (e->buf == MB_FACES || (topology && e->buf == MB_POSITIONS)) {
        if (e->buf == MB_FACES) st = accel_rebuild_shape(s->accel, sh, err);
      } else if (e->buf == MB_POSITIONS) {
        st = accel_update_vertices(s->accel, sh, err);
      }
    }
  }
  if (!st) st = accel_commit(s->accel, err);
  /* Bounds, emitters and sensors: the same code as a load, so that an
   * update equals a reload. */
  if (!st) st = scene_refresh_bounds(s, err);
  return st;
}

/* One update, or with dry_run its checks alone: every key resolves (no
 * entry twice) and every value validates, then a dry run stops, having
 * written nothing (not even staging: s is only read); a real one goes on
 * to stage, apply and refresh. */
static rsw_status update_run(scene *s, const param_update *items, size_t n, bool dry_run,
                             update_report *report, rsw_err *err) {
  double t0 = now_s();
  if (report) memset(report, 0, sizeof *report);
  if (!s->params) return rsw_fail(err, RSW_ERR_NOT_FOUND, "params", "the scene has no parameter table");
  staged *sg = calloc(n ? n : 1, sizeof *sg);
  if (!sg) return rsw_fail(err, RSW_ERR_NOMEM, "params", "out of memory");
  rsw_status st = RSW_OK;
  /* 1. Resolve every key; a key (or two names of it) given twice is an
   *    error, since the result would depend on the order. */
  for (size_t i = 0; i < n && !st; i++) {
    sg[i].item = &items[i];
    st = params_lookup(s, items[i].key, &sg[i].index, err);
    for (size_t k = 0; k < i && !st; k++)
      if (sg[k].index == sg[i].index)
        st = rsw_fail(err, RSW_ERR_DUPLICATE, items[i].key,
                      "'%s' is given twice in one update (also as '%s')", items[i].key, items[k].key);
  }
  /* 2. Validate everything before writing anything. */
  for (size_t i = 0; i < n && !st; i++) st = validate(s, &sg[i], sg, n, err);
  if (st || dry_run) {
    free(sg);
    return st;
  }
  /* Geometry checks that need the new values together: a mesh's new
   * vertices (with its faces and transform, new or current) must keep a
   * positive area, or sampling it would divide by zero. */
  for (size_t i = 0; i < n && !st; i++) {
    const entry *e = &s->params->e[sg[i].index];
    if (!sg[i].changed || e->kind != EK_MESHBUF || (e->buf != MB_POSITIONS && e->buf != MB_FACES)) continue;
    const shape *sh = e->sh;
    if (!sh->emitter && !sh->sampled) continue; /* nothing samples it: no area needed */
    const double *fc = NULL;
    size_t nf = sh->mesh.n_faces;
    const xform *xf = &sh->to_world;
    const float *fpos = NULL;
    for (size_t k = 0; k < n; k++) {
      const entry *o = &s->params->e[sg[k].index];
      if (o->owner != e->owner) continue;
      if (o->kind == EK_MESHBUF && o->buf == MB_POSITIONS && sg[k].changed) {
        /* Convert once (a sequential pass); the area loop then gathers
         * floats, and applying the update swaps this buffer in. */
        const param_value *pv = &sg[k].item->value;
        if (!sg[k].fpos) {
          sg[k].fpos = malloc(pv->n * sizeof(float));
          if (!sg[k].fpos) {
            st = rsw_fail(err, RSW_ERR_NOMEM, sg[k].item->key, "out of memory");
            break;
          }
          for (size_t q = 0; q < pv->n; q++) sg[k].fpos[q] = (float)pv->arr[q];
        }
        fpos = sg[k].fpos;
      }
      if (o->kind == EK_MESHBUF && o->buf == MB_FACES)
        fc = sg[k].item->value.arr, nf = sg[k].item->value.n / 3;
      if (o->kind == EK_TRANSFORM) xf = &sg[k].xf;
    }
    if (st) break;
    /* The new area cdf, computed once here and installed by the shape's
     * parameters_changed (same arithmetic as shape_finalize, so the result
     * equals a reload's). Only the transform changing is left to
     * shape_finalize. */
    shape *msh = e->sh;
    if (msh->tri_cdf_next_n < nf) {
      double *c = realloc(msh->tri_cdf_next, nf * sizeof(double));
      if (!c) {
        st = rsw_fail(err, RSW_ERR_NOMEM, sg[i].item->key, "out of memory");
        break;
      }
      msh->tri_cdf_next = c;
      msh->tri_cdf_next_n = (uint32_t)nf;
    }
    double area = 0, det = xf_abs_det3(xf);
    for (size_t f = 0; f < nf; f++) {
      vec3 p[3];
      for (int c = 0; c < 3; c++) {
        size_t vi = fc ? (size_t)fc[3 * f + c] : sh->mesh.faces[3 * f + c];
        const float *q = fpos ? &fpos[3 * vi] : &sh->mesh.pos[3 * vi];
        p[c] = v3(q[0], q[1], q[2]);
      }
      area += tri_world_area(xf, det, p[0], p[1], p[2]);
      msh->tri_cdf_next[f] = area;
    }
    if (!(area > 0) || !isfinite(area)) {
      st = rsw_fail(err, RSW_ERR_INVALID, sg[i].item->key,
                    "'%s': the mesh would have zero or non-finite area", sg[i].item->key);
    } else {
      msh->area_next = area;
      msh->tri_cdf_next_n = (uint32_t)nf; /* entries valid (buffer may be larger) */
      msh->cdf_staged = true;
    }
  }
  /* Prepare every value that needs memory, still before writing. */
  for (size_t i = 0; i < n && !st; i++)
    if (sg[i].changed) st = prepare(&sg[i], &s->params->e[sg[i].index], err);
  if (st) {
    for (size_t i = 0; i < n; i++) {
      const entry *e = &s->params->e[sg[i].index];
      if (e->kind == EK_MESHBUF) e->sh->cdf_staged = false;
    }
    staged_free(sg, n);
    return st;
  }
  accel_counters before;
  accel_get_counters(s->accel, &before);
  /* 3. Apply: nothing here can fail. */
  unsigned classes = 0;
  size_t changed = 0;
  bool geometry = false;
  for (size_t i = 0; i < n; i++) {
    if (!sg[i].changed) continue;
    const entry *e = &s->params->e[sg[i].index];
    changed++;
    classes |= e->cls;
    apply_one(&sg[i], e);
    if (e->cls == UPDATE_GEOMETRIC) geometry = true;
  }
  /* 4. Derived state, each touched object once. */
  for (size_t i = 0; i < n; i++) {
    if (!sg[i].changed) continue;
    object *o = s->params->e[sg[i].index].owner;
    bool seen = false;
    for (size_t k = 0; k < i && !seen; k++) seen = sg[k].changed && s->params->e[sg[k].index].owner == o;
    if (seen) continue;
    if (o->plugin && o->plugin->parameters_changed) o->plugin->parameters_changed(o);
  }
  /* Embree: instance transforms, refits and rebuilds, then one commit.
   * These can still fail (Embree, accel.c's scene-wide float32 check, a
   * sensor refusing the new bounds): then every value goes back, and the
   * structure is brought back to it, so that a failed update changes
   * nothing. */
  if (geometry) st = update_geometry(s, sg, n, false, err);
  /* A sensor inside a medium must still be inside it (a moved boundary or
   * sensor): the load-time check again, undone like the rest. */
  if (!st && changed && scene_has_sensor_media(s)) {
    st = scene_check_media(s, NULL, err);
    if (st && err) {
      static const char pre[] = "after the update, ";
      size_t pl = sizeof pre - 1, len = strlen(err->msg);
      if (len + pl >= sizeof err->msg) len = sizeof err->msg - pl - 1;
      memmove(err->msg + pl, err->msg, len);
      memcpy(err->msg, pre, pl);
      err->msg[pl + len] = '\0';
    }
  }
  if (st) {
    for (size_t i = 0; i < n; i++) undo_one(&sg[i], &s->params->e[sg[i].index]);
    for (size_t i = 0; i < n; i++) {
      const entry *e = &s->params->e[sg[i].index];
      if (e->kind == EK_MESHBUF) e->sh->cdf_staged = false;
    }
    for (size_t i = 0; i < n; i++) {
      if (!sg[i].changed) continue;
      object *o = s->params->e[sg[i].index].owner;
      bool seen = false;
      for (size_t k = 0; k < i && !seen; k++) seen = sg[k].changed && s->params->e[sg[k].index].owner == o;
      if (!seen && o->plugin && o->plugin->parameters_changed) o->plugin->parameters_changed(o);
    }
    if (geometry) {
      rsw_err again = {0};
      if (update_geometry(s, sg, n, true, &again) && err) {
        size_t used = strlen(err->msg);
        snprintf(err->msg + used, sizeof err->msg - used, " (and restoring the previous state failed: %s)",
                 again.msg);
      }
    }
  }
  /* Emitter selection by sampling_weight (cheap: one pass). */
  if (!st && changed) {
    double sum = 0;
    for (size_t i = 0; i < s->n_emitters; i++) {
      sum += s->emitters[i]->sampling_weight;
      if (s->emitter_cdf) s->emitter_cdf[i] = sum;
    }
    s->emitter_weight_sum = sum;
  }
  staged_free(sg, n);
  if (report) {
    accel_counters after;
    accel_get_counters(s->accel, &after);
    report->classes = classes;
    report->changed = changed;
    report->refits = (unsigned)(after.refits - before.refits);
    report->rebuilds = (unsigned)(after.rebuilds - before.rebuilds);
    report->instance_updates = (unsigned)(after.instance_updates - before.instance_updates);
    report->seconds = now_s() - t0;
  }
  return st;
}

rsw_status scene_update(scene *s, const param_update *items, size_t n, update_report *report, rsw_err *err) {
  return update_run(s, items, n, false, report, err);
}

rsw_status scene_update_check(const scene *s, const param_update *items, size_t n, rsw_err *err) {
  /* A dry run only reads the scene (update_run stops before staging). */
  return update_run((scene *)s, items, n, true, NULL, err);
}
