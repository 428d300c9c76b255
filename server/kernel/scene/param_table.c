/* The parameter table read: lookup by key, alias, glob or Eradiate's
 * TYPE:ID:PATH search, and the entries' values as JSON (param_table.h). */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../core/strdist.h"
#include "../shapes/shape.h"
#include "../textures/texture.h"
#include "param_table.h"
#include "params_internal.h"
#include "scene.h"

static size_t hash_find(const param_table *t, const char *key) {
  if (!t->hcap) return 0;
  size_t m = t->hcap - 1;
  for (size_t i = hash_str(key) & m;; i = (i + 1) & m) {
    if (!t->hval[i]) return 0;
    if (strcmp(t->hkey[i], key) == 0) return t->hval[i];
  }
}

/* ---- lookup --------------------------------------------------------------------- */

size_t params_count(const scene *s) {
  return s->params ? s->params->n : 0;
}

static void entry_shape(const entry *e, size_t dims[2]) {
  dims[0] = 1;
  dims[1] = 0;
  switch (e->kind) {
  case EK_TRANSFORM: dims[0] = 4, dims[1] = 4; break;
  case EK_VECTOR: dims[0] = 3; break;
  case EK_SPECTRUM: {
    const spectrum *sp = uniform_texture_spectrum(e->tex);
    if (sp && sp->kind == SPEC_TABLE)
      dims[0] = sp->n, dims[1] = 2;
    else if (sp && sp->kind == SPEC_RGB)
      dims[0] = 3;
    break;
  }
  case EK_MESHBUF: {
    const mesh *m = &e->sh->mesh;
    dims[0] = e->buf == MB_FACES       ? 3 * (size_t)m->n_faces
              : e->buf == MB_TEXCOORDS ? 2 * (size_t)m->n_verts
                                       : 3 * (size_t)m->n_verts;
    break;
  }
  case EK_DBUF: dims[0] = e->dn; break;
  default: break;
  }
}

static param_type entry_type(const scene *s, const entry *e) {
  switch (e->kind) {
  case EK_FLOAT: return PARAM_FLOAT;
  case EK_BOOL: return PARAM_BOOL;
  case EK_TRANSFORM: return PARAM_TRANSFORM;
  case EK_VECTOR: return PARAM_VECTOR;
  case EK_SPECTRUM: return s->variant == VARIANT_MONO ? PARAM_SPECTRUM : PARAM_RGB;
  case EK_MESHBUF:
  case EK_DBUF: return PARAM_BUFFER;
  }
  return PARAM_FLOAT;
}

bool params_info(const scene *s, size_t i, param_info *out) {
  if (!s->params || i >= s->params->n) return false;
  const entry *e = &s->params->e[i];
  memset(out, 0, sizeof *out);
  out->key = e->key;
  out->type = entry_type(s, e);
  out->cls = e->cls;
  entry_shape(e, out->shape);
  out->object_type = e->owner->plugin ? e->owner->plugin->name : "scene";
  out->object_class = e->owner->plugin ? obj_class_name(e->owner->plugin->cls) : "scene";
  out->object_id = e->owner->id ? e->owner->id : "";
  out->aliases = (const char *const *)e->aliases;
  out->n_aliases = e->n_aliases;
  return true;
}

size_t params_closest(const scene *s, const char *key, const char *out[3]) {
  const param_table *t = s->params;
  size_t bd[3] = {(size_t)-1, (size_t)-1, (size_t)-1};
  out[0] = out[1] = out[2] = NULL;
  for (size_t i = 0; t && i < t->n; i++) {
    size_t d = rsw_edit_distance(key, t->e[i].key);
    for (int k = 0; k < 3; k++)
      if (d < bd[k]) {
        for (int j = 2; j > k; j--) bd[j] = bd[j - 1], out[j] = out[j - 1];
        bd[k] = d;
        out[k] = t->e[i].key;
        break;
      }
  }
  return out[2] ? 3 : out[1] ? 2 : out[0] ? 1 : 0;
}

static rsw_status not_found(const scene *s, const char *key, rsw_err *err) {
  const param_table *t = s->params;
  const char *best[3] = {NULL, NULL, NULL};
  size_t bd[3] = {(size_t)-1, (size_t)-1, (size_t)-1};
  for (size_t i = 0; t && i < t->n; i++) {
    size_t d = rsw_edit_distance(key, t->e[i].key);
    for (int k = 0; k < 3; k++)
      if (d < bd[k]) {
        for (int j = 2; j > k; j--) bd[j] = bd[j - 1], best[j] = best[j - 1];
        bd[k] = d;
        best[k] = t->e[i].key;
        break;
      }
  }
  /* Mitsuba silently ignores unknown keys; an unknown key here is an error
   * so that a misspelt update cannot go unnoticed. */
  if (!best[0])
    return rsw_fail(err, RSW_ERR_NOT_FOUND, key, "unknown parameter '%s' (the scene has none)", key);
  return rsw_fail(err, RSW_ERR_NOT_FOUND, key, "unknown parameter '%s'; closest: %s%s%s%s%s", key, best[0],
                  best[1] ? ", " : "", best[1] ? best[1] : "", best[2] ? ", " : "", best[2] ? best[2] : "");
}

/* TYPE:ID:PATH -> the key of PATH under the object of class or plugin TYPE
 * and id ID (Eradiate's SearchSceneParameter). */
static rsw_status resolve_search(const scene *s, const char *spec, char **key_out, rsw_err *err) {
  const char *c1 = strchr(spec, ':');
  const char *c2 = c1 ? strchr(c1 + 1, ':') : NULL;
  if (!c1 || !c2 || c1 == spec || c2 == c1 + 1 || !c2[1])
    return rsw_fail(err, RSW_ERR_INVALID, spec,
                    "a search is written TYPE:ID:PATH (e.g. bsdf:surface_bsdf:reflectance.value)");
  size_t lt = (size_t)(c1 - spec), li = (size_t)(c2 - c1 - 1);
  const param_table *t = s->params;
  for (size_t i = 0; t && i < t->n_objs; i++) {
    const object *o = t->objs[i].o;
    if (!o->id || strlen(o->id) != li || strncmp(o->id, c1 + 1, li) != 0) continue;
    const char *cls = o->plugin ? obj_class_name(o->plugin->cls) : "scene";
    const char *pname = o->plugin ? o->plugin->name : "scene";
    if ((strlen(cls) == lt && strncmp(cls, spec, lt) == 0) ||
        (strlen(pname) == lt && strncmp(pname, spec, lt) == 0)) {
      *key_out = params_join(t->objs[i].path, c2 + 1);
      return *key_out ? RSW_OK : rsw_fail(err, RSW_ERR_NOMEM, spec, "out of memory");
    }
  }
  return rsw_fail(err, RSW_ERR_NOT_FOUND, spec, "no %.*s with id '%.*s' in the scene", (int)lt, spec, (int)li,
                  c1 + 1);
}

rsw_status params_lookup(const scene *s, const char *key, size_t *index, rsw_err *err) {
  if (!s->params) return rsw_fail(err, RSW_ERR_NOT_FOUND, key, "the scene has no parameter table");
  size_t h = hash_find(s->params, key);
  if (h) {
    *index = h - 1;
    return RSW_OK;
  }
  if (strchr(key, ':')) {
    char *k = NULL;
    rsw_status st = resolve_search(s, key, &k, err);
    if (st) return st;
    h = hash_find(s->params, k);
    if (!h) {
      rsw_fail(err, RSW_ERR_NOT_FOUND, key, "'%s' resolves to '%s', which is not a parameter", key, k);
      free(k);
      return RSW_ERR_NOT_FOUND;
    }
    free(k);
    *index = h - 1;
    return RSW_OK;
  }
  return not_found(s, key, err);
}

rsw_status params_match(const scene *s, const char *glob, unsigned class_mask, bool include_none,
                        size_t **out, size_t *count, rsw_err *err) {
  *out = NULL;
  *count = 0;
  const param_table *t = s->params;
  size_t n = t ? t->n : 0;
  size_t *res = malloc((n ? n : 1) * sizeof *res);
  if (!res) return rsw_fail(err, RSW_ERR_NOMEM, glob, "out of memory");
  size_t k = 0;
  if (strchr(glob, ':')) {
    size_t i;
    rsw_status st = params_lookup(s, glob, &i, err);
    if (st) {
      free(res);
      return st;
    }
    const entry *e = &t->e[i];
    if ((e->cls & class_mask) || (e->cls == UPDATE_NONE && include_none)) res[k++] = i;
  } else {
    for (size_t i = 0; i < n; i++) {
      const entry *e = &t->e[i];
      if (!((e->cls & class_mask) || (e->cls == UPDATE_NONE && include_none))) continue;
      bool m = rsw_glob_match(glob, e->key);
      for (size_t a = 0; !m && a < e->n_aliases; a++) m = rsw_glob_match(glob, e->aliases[a]);
      if (m) res[k++] = i;
    }
  }
  if (!k) {
    free(res);
    return rsw_fail(err, RSW_ERR_NOT_FOUND, glob, "no parameter matches '%s'", glob);
  }
  *out = res;
  *count = k;
  return RSW_OK;
}

/* ---- values as JSON ---------------------------------------------------------------- */

typedef struct sbuf {
  char *p;
  size_t n, cap;
  bool oom;
} sbuf;

static void sb_printf(sbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void sb_printf(sbuf *b, const char *fmt, ...) {
  if (b->oom) return;
  for (;;) {
    va_list ap;
    va_start(ap, fmt);
    int w = vsnprintf(b->p ? b->p + b->n : NULL, b->p ? b->cap - b->n : 0, fmt, ap);
    va_end(ap);
    if (w < 0) {
      b->oom = true;
      return;
    }
    if (b->p && b->n + (size_t)w < b->cap) {
      b->n += (size_t)w;
      return;
    }
    size_t cap = b->cap ? b->cap : 64;
    while (cap <= b->n + (size_t)w) cap *= 2;
    char *np = realloc(b->p, cap);
    if (!np) {
      b->oom = true;
      return;
    }
    b->p = np;
    b->cap = cap;
  }
}

static void sb_num(sbuf *b, double v) {
  if (v == floor(v) && fabs(v) < 1e15)
    sb_printf(b, "%.0f", v);
  else
    sb_printf(b, "%.17g", v);
}

static void sb_nums(sbuf *b, const double *v, size_t n) {
  sb_printf(b, "[");
  for (size_t i = 0; i < n; i++) {
    if (i) sb_printf(b, ", ");
    sb_num(b, v[i]);
  }
  sb_printf(b, "]");
}

char *params_value_json(const scene *s, size_t i, size_t max_items) {
  if (!s->params || i >= s->params->n) return NULL;
  const entry *e = &s->params->e[i];
  sbuf b = {0};
  switch (e->kind) {
  case EK_FLOAT: sb_num(&b, *e->fptr); break;
  case EK_BOOL: sb_printf(&b, "%s", e->bval ? "true" : "false"); break;
  case EK_TRANSFORM:
    sb_printf(&b, "[");
    for (int r = 0; r < 4; r++) {
      if (r) sb_printf(&b, ", ");
      sb_nums(&b, e->xptr->m[r], 4);
    }
    sb_printf(&b, "]");
    break;
  case EK_VECTOR: {
    vec3 v = e->vget(e->owner);
    double a[3] = {v.x, v.y, v.z};
    sb_nums(&b, a, 3);
    break;
  }
  case EK_SPECTRUM: {
    const spectrum *sp = uniform_texture_spectrum(e->tex);
    if (!sp) break;
    if (sp->kind == SPEC_UNIFORM) {
      sb_num(&b, sp->value);
    } else if (sp->kind == SPEC_RGB) {
      sb_nums(&b, sp->rgb, 3);
    } else {
      sb_printf(&b, "{\"wavelengths\": ");
      sb_nums(&b, sp->wl, sp->n);
      sb_printf(&b, ", \"values\": ");
      sb_nums(&b, sp->val, sp->n);
      sb_printf(&b, "}");
    }
    break;
  }
  case EK_MESHBUF: {
    size_t dims[2];
    entry_shape(e, dims);
    size_t n = dims[0];
    if (max_items && n > max_items) {
      sb_printf(&b, "{\"length\": %zu}", n);
      break;
    }
    const mesh *m = &e->sh->mesh;
    sb_printf(&b, "[");
    for (size_t k = 0; k < n; k++) {
      if (k) sb_printf(&b, ", ");
      if (e->buf == MB_FACES)
        sb_printf(&b, "%u", m->faces[k]);
      else
        sb_printf(&b, "%.9g",
                  (double)(e->buf == MB_POSITIONS ? m->pos[k]
                           : e->buf == MB_NORMALS ? m->nrm[k]
                                                  : m->uv[k]));
    }
    sb_printf(&b, "]");
    break;
  }
  case EK_DBUF:
    if (max_items && e->dn > max_items)
      sb_printf(&b, "{\"length\": %zu}", e->dn);
    else
      sb_nums(&b, e->dptr, e->dn);
    break;
  }
  if (b.oom) {
    free(b.p);
    return NULL;
  }
  return b.p;
}
