/* shapegroup, instance and instancelist (see instance.h). */
#include "instance.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../accel_hit.h"
#include "../scene/plugin_def.h"
#include "rsw_file.h"
#include "shape_internal.h"

/* ---- shapegroup ------------------------------------------------------------ */

/* World (here: group-space) bounds of a plain shape. */
static void member_bbox(const shape *sh, vec3 *lo, vec3 *hi) {
  sh->ops->world_bounds(sh, &sh->to_world, lo, hi);
}

static void group_destroy(object *o) {
  shape_group *g = (shape_group *)o;
  free(g->members);
  free(g);
}

/* Members' BSDFs stay reachable as parameters (<group>.<member>.bsdf...);
 * their to_world is baked into the group's Embree scene, so it is not a
 * parameter. */
static void group_traverse(object *o, param_visitor *v) {
  shape_group *g = (shape_group *)o;
  for (size_t i = 0; i < g->n_members; i++) {
    shape *m = g->members[i];
    char key[256];
    snprintf(key, sizeof key, "%s.bsdf", m->base.id ? m->base.id : "member");
    pv_object(v, key, &m->bsdf->base, NAN, NAN);
  }
}

DEFINE_PLUGIN(shapegroup, CLS_SHAPE, .destroy = group_destroy, .traverse = group_traverse);

static rsw_status shapegroup_create(loader *ld, node *n, object **out) {
  shape_group *g = PLUGIN_NEW(shape_group, shapegroup);
  if (!g) return plugin_created(ld, n, NULL, out);
  g->base.ops = &shape_ops_mesh; /* no geometry of its own */
  g->base.to_world = xf_identity();
  object **arr = NULL;
  size_t cnt = 0;
  rsw_status st = ld_children(ld, n, CLS_SHAPE, &arr, &cnt);
  if (st) {
    free(g);
    return st;
  }
  g->members = (shape **)arr;
  g->n_members = cnt;
  g->lo = v3(INFINITY, INFINITY, INFINITY);
  g->hi = v3(-INFINITY, -INFINITY, -INFINITY);
  for (size_t i = 0; i < cnt && !st; i++) {
    shape *m = g->members[i];
    if (shape_is_group(m) || shape_is_instancing(m))
      st = ld_fail(
          ld, n, NULL, RSW_ERR_UNSUPPORTED,
          "shapegroup '%s': member '%s' is a %s; groups do not nest (Embree allows one instance level)",
          n->id, m->base.id, m->base.plugin->name);
    else if (m->emitter)
      st = ld_fail(
          ld, n, NULL, RSW_ERR_UNSUPPORTED,
          "shapegroup '%s': member '%s' carries an area emitter; instanced emitters are not supported", n->id,
          m->base.id);
    else
      member_bbox(m, &g->lo, &g->hi);
  }
  if (!st && cnt == 0) st = ld_fail(ld, n, NULL, RSW_ERR_INVALID, "shapegroup '%s' has no shapes", n->id);
  if (st) {
    group_destroy(&g->base.base);
    return st;
  }
  return plugin_created(ld, n, &g->base.base, out);
}

/* ---- instance -------------------------------------------------------------------------- */

static void instance_destroy(object *o) {
  instance_shape *s = (instance_shape *)o;
  free(s->xf);
  free(s->tr);
  free(s);
}

static rsw_status read_group(loader *ld, node *n, shape_group **out) {
  object *o;
  rsw_status st = ld_child(ld, n, "shapegroup", CLS_SHAPE, &o);
  if (st) return st;
  if (!o)
    return ld_fail(ld, n, NULL, RSW_ERR_MISSING, "%s '%s': missing property 'shapegroup'", n->type, n->id);
  if (!shape_is_group((shape *)o))
    return ld_fail(ld, n, "shapegroup", RSW_ERR_TYPE, "property 'shapegroup' must be a shapegroup, got '%s'",
                   o->plugin->name);
  *out = (shape_group *)o;
  return RSW_OK;
}

static rsw_status placement_check(const shape_group *g, const xform *t, const char *what, rsw_err *err,
                                  const char *where);

/* A placement float32 tracing can represent (core/transform.h): affine,
 * scales and translation within the limits, and the group's box placed
 * within RSW_TRACE_MAX_COORD. */
static rsw_status placement_check(const shape_group *g, const xform *t, const char *what, rsw_err *err,
                                  const char *where) {
  char msg[512];
  if (!xf_traceable(t->m, what, msg, sizeof msg)) return rsw_fail(err, RSW_ERR_RANGE, where, "%s", msg);
  double w = 0;
  for (int c = 0; c < 8; c++)
    w = fmax(w, v3_max_abs(xf_point(
                    t, v3(c & 1 ? g->hi.x : g->lo.x, c & 2 ? g->hi.y : g->lo.y, c & 4 ? g->hi.z : g->lo.z))));
  if (!(w <= RSW_TRACE_MAX_COORD))
    return rsw_fail(err, RSW_ERR_RANGE, where,
                    "%s: the placed group reaches a world coordinate of %g, beyond %g, the largest float32 "
                    "tracing accepts",
                    what, w, RSW_TRACE_MAX_COORD);
  return RSW_OK;
}

static rsw_status instance_check_transform(const object *o, const xform *t, const char *key, rsw_err *err) {
  return placement_check(((const instance_shape *)o)->group, t, key, err, key);
}

/* to_world is geometric: the instance transform and one top-level commit
 * (accel_update_transform), the group's BVH is untouched. */
static void instance_traverse(object *o, param_visitor *v) {
  instance_shape *s = (instance_shape *)o;
  pv_transform(v, "to_world", &s->base.to_world, UPDATE_GEOMETRIC, instance_check_transform);
}

static void instance_parameters_changed(object *o) {
  (void)o;
}

DEFINE_PLUGIN(instance, CLS_SHAPE, .destroy = instance_destroy, .traverse = instance_traverse,
              .parameters_changed = instance_parameters_changed);

static rsw_status instance_create(loader *ld, node *n, object **out) {
  instance_shape *s = PLUGIN_NEW(instance_shape, instance);
  if (!s) return plugin_created(ld, n, NULL, out);
  s->base.ops = &shape_ops_mesh; /* no geometry of its own */
  s->n = 1;
  rsw_status st = ld_transform(ld, n, "to_world", &s->base.to_world, NULL);
  if (!st) st = read_group(ld, n, &s->group);
  if (!st) st = placement_check(s->group, &s->base.to_world, "to_world", ld->err, n->loc);
  if (st) {
    free(s);
    return st;
  }
  return plugin_created(ld, n, &s->base.base, out);
}

/* ---- instancelist ---------------------------------------------------------------------- */

/* Row-major 3x4 of a leaf placement: T(x, y, z) R S(r), R's columns the
 * frame (s, t, n) of the unit normal (Mitsuba's coordinate_system), so
 * that the leaf's +z turns to n. */
static void leaf_matrix(const double v[7], float out[12], double tr[3]) {
  vec3 n = v3_norm(v3(v[3], v[4], v[5]));
  frame f = frame_from_normal(n);
  double r = v[6];
  const vec3 cols[3] = {f.s, f.t, f.n};
  for (int c = 0; c < 3; c++) {
    out[0 * 4 + c] = (float)(r * cols[c].x);
    out[1 * 4 + c] = (float)(r * cols[c].y);
    out[2 * 4 + c] = (float)(r * cols[c].z);
  }
  out[3] = (float)v[0], out[7] = (float)v[1], out[11] = (float)v[2];
  tr[0] = v[0], tr[1] = v[1], tr[2] = v[2];
}

/* The parser behind instance_list_parse: also returns the translations in
 * double precision (n x 3, malloc'ed): a float keeps only ~7 digits, 8 mm
 * steps at 100 km, so placements in georeferenced coordinates would move. */
static rsw_status list_parse(const char *path, float **xf_out, double **tr_out, uint32_t *n_out,
                             rsw_err *err) {
  *xf_out = NULL;
  *tr_out = NULL;
  *n_out = 0;
  FILE *f = rsw_fopen_regular(path, "r");
  if (!f)
    return rsw_fail(err, RSW_ERR_FILE, path, "cannot open instance list '%s': %s", path,
                    rsw_open_strerror(errno));
  size_t cap = 1024, n = 0;
  float *xf = malloc(cap * 12 * sizeof(float));
  double *tr = malloc(cap * 3 * sizeof(double));
  rsw_status st = xf && tr ? RSW_OK : rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory");
  char line[4096];
  char where[300];
  unsigned long lineno = 0;
  while (!st && fgets(line, sizeof line, f)) {
    lineno++;
    snprintf(where, sizeof where, "%s:%lu", path, lineno);
    size_t len = strlen(line);
    if (len == sizeof line - 1 && line[len - 1] != '\n' && !feof(f)) {
      st = rsw_fail(err, RSW_ERR_PARSE, where, "line longer than %zu characters", sizeof line - 2);
      break;
    }
    char *hash = strchr(line, '#');
    if (hash) *hash = '\0';
    double v[17];
    int k = 0;
    char *p = line;
    for (;;) {
      while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n') p++;
      if (!*p) break;
      char *end;
      errno = 0;
      double x = strtod(p, &end);
      if (end == p || (*end && *end != ' ' && *end != '\t' && *end != '\r' && *end != '\n')) {
        st = rsw_fail(err, RSW_ERR_PARSE, where, "'%.*s' is not a number", (int)strcspn(p, " \t\r\n"), p);
        break;
      }
      if (!isfinite(x)) {
        st = rsw_fail(err, RSW_ERR_PARSE, where, "non-finite number");
        break;
      }
      if (k < 17) v[k] = x;
      k++;
      p = end;
    }
    if (st || k == 0) continue;
    if (k != 16 && k != 7) {
      st = rsw_fail(err, RSW_ERR_PARSE, where,
                    "a row has 16 numbers (a 4x4 to_world) or 7 (x y z nx ny nz radius), got %d", k);
      break;
    }
    if (n == cap) {
      float *g = realloc(xf, 2 * cap * 12 * sizeof(float));
      if (g) xf = g;
      double *gt = g ? realloc(tr, 2 * cap * 3 * sizeof(double)) : NULL;
      if (gt) tr = gt;
      if (!g || !gt) {
        st = rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory");
        break;
      }
      cap *= 2;
    }
    float *m = &xf[12 * n];
    double *tn = &tr[3 * n];
    if (k == 16) {
      if (v[12] != 0 || v[13] != 0 || v[14] != 0 || v[15] != 1) {
        st = rsw_fail(err, RSW_ERR_INVALID, where, "the last row of a to_world must be 0 0 0 1");
        break;
      }
      double mm[4][4];
      for (int i = 0; i < 16; i++) mm[i / 4][i % 4] = v[i];
      xform t;
      if (!xf_from_matrix(mm, &t)) {
        st = rsw_fail(err, RSW_ERR_INVALID, where, "singular to_world");
        break;
      }
      char msg[512];
      if (!xf_traceable(mm, "to_world", msg, sizeof msg)) {
        st = rsw_fail(err, RSW_ERR_RANGE, where, "%s", msg);
        break;
      }
      for (int i = 0; i < 12; i++) m[i] = (float)v[i];
      tn[0] = v[3], tn[1] = v[7], tn[2] = v[11];
    } else {
      if (!(v[6] > 0)) {
        st = rsw_fail(err, RSW_ERR_INVALID, where, "radius must be > 0 (got %g)", v[6]);
        break;
      }
      if (!(v[6] >= RSW_TRACE_MIN_SCALE && v[6] <= RSW_TRACE_MAX_SCALE)) {
        st = rsw_fail(err, RSW_ERR_RANGE, where,
                      "radius %g is outside [%g, %g], what float32 tracing can represent", v[6],
                      RSW_TRACE_MIN_SCALE, RSW_TRACE_MAX_SCALE);
        break;
      }
      if (!(fabs(v[0]) <= RSW_TRACE_MAX_COORD && fabs(v[1]) <= RSW_TRACE_MAX_COORD &&
            fabs(v[2]) <= RSW_TRACE_MAX_COORD)) {
        st = rsw_fail(err, RSW_ERR_RANGE, where,
                      "a position coordinate exceeds %g, the largest float32 tracing accepts",
                      RSW_TRACE_MAX_COORD);
        break;
      }
      if (!(v[3] * v[3] + v[4] * v[4] + v[5] * v[5] > 0)) {
        st = rsw_fail(err, RSW_ERR_INVALID, where, "the normal must not be zero");
        break;
      }
      leaf_matrix(v, m, tn);
    }
    n++;
    if (n > 0xFFFFFFF0u) st = rsw_fail(err, RSW_ERR_RANGE, where, "too many instances");
  }
  if (!st && ferror(f)) st = rsw_fail(err, RSW_ERR_FILE, path, "read error");
  fclose(f);
  if (!st && n == 0) st = rsw_fail(err, RSW_ERR_INVALID, path, "instance list '%s' has no rows", path);
  if (st) {
    free(xf);
    free(tr);
    return st;
  }
  float *shrunk = realloc(xf, n * 12 * sizeof(float));
  *xf_out = shrunk ? shrunk : xf;
  double *tshrunk = realloc(tr, n * 3 * sizeof(double));
  *tr_out = tshrunk ? tshrunk : tr;
  *n_out = (uint32_t)n;
  return RSW_OK;
}

rsw_status instance_list_parse(const char *path, float **xf_out, uint32_t *n_out, rsw_err *err) {
  double *tr = NULL;
  rsw_status st = list_parse(path, xf_out, &tr, n_out, err);
  free(tr);
  return st;
}

DEFINE_PLUGIN(instancelist, CLS_SHAPE, .destroy = instance_destroy);

static rsw_status instancelist_create(loader *ld, node *n, object **out) {
  instance_shape *s = PLUGIN_NEW(instance_shape, instancelist);
  if (!s) return plugin_created(ld, n, NULL, out);
  s->base.ops = &shape_ops_mesh; /* no geometry of its own */
  s->base.to_world = xf_identity();
  char *path = NULL;
  rsw_status st = read_group(ld, n, &s->group);
  if (!st) st = ld_path(ld, n, "filename", &path);
  if (!st) st = list_parse(path, &s->xf, &s->tr, &s->n, ld->err);
  free(path);
  if (st) {
    free(s);
    return st;
  }
  return plugin_created(ld, n, &s->base.base, out);
}

/* ---- shared ------------------------------------------------------------------------------ */

xform instance_transform(const instance_shape *s, uint32_t k) {
  if (!s->xf) return s->base.to_world;
  const float *m = &s->xf[12 * (size_t)k];
  const double *tr = &s->tr[3 * (size_t)k];
  /* Called for every hit on a placement: the inverse of the affine map
   * [A | t] in closed form, A^-1 = adj(A) / det(A) and -A^-1 t, not a
   * pivoting 4x4 inversion; list_parse() checked at load that A is
   * invertible (xf_from_matrix). Nothing is stored per placement (its
   * record stays 72 bytes). */
  double a00 = m[0], a01 = m[1], a02 = m[2], a10 = m[4], a11 = m[5], a12 = m[6], a20 = m[8], a21 = m[9],
         a22 = m[10];
  double c00 = a11 * a22 - a12 * a21, c01 = a02 * a21 - a01 * a22, c02 = a01 * a12 - a02 * a11;
  double c10 = a12 * a20 - a10 * a22, c11 = a00 * a22 - a02 * a20, c12 = a02 * a10 - a00 * a12;
  double c20 = a10 * a21 - a11 * a20, c21 = a01 * a20 - a00 * a21, c22 = a00 * a11 - a01 * a10;
  double id = 1.0 / (a00 * c00 + a01 * c10 + a02 * c20);
  xform t = {.m = {{a00, a01, a02, tr[0]}, {a10, a11, a12, tr[1]}, {a20, a21, a22, tr[2]}, {0, 0, 0, 1}},
             .inv = {{c00 * id, c01 * id, c02 * id, 0},
                     {c10 * id, c11 * id, c12 * id, 0},
                     {c20 * id, c21 * id, c22 * id, 0},
                     {0, 0, 0, 1}}};
  for (int i = 0; i < 3; i++)
    t.inv[i][3] = -(t.inv[i][0] * tr[0] + t.inv[i][1] * tr[1] + t.inv[i][2] * tr[2]);
  return t;
}

void instance_bbox(const shape *sh, vec3 *lo, vec3 *hi) {
  if (shape_is_group(sh)) return;
  if (!shape_is_instancing(sh)) {
    member_bbox(sh, lo, hi);
    return;
  }
  const instance_shape *s = (const instance_shape *)sh;
  const shape_group *g = s->group;
  if (!s->xf) {
    for (int c = 0; c < 8; c++)
      shape_box_add(lo, hi,
                    xf_point(&sh->to_world, v3(c & 1 ? g->hi.x : g->lo.x, c & 2 ? g->hi.y : g->lo.y,
                                               c & 4 ? g->hi.z : g->lo.z)));
    return;
  }
  /* Placements applied directly (instance_transform would also invert
   * each matrix). */
  for (uint32_t k = 0; k < s->n; k++) {
    const float *m = &s->xf[12 * (size_t)k];
    const double *t = &s->tr[3 * (size_t)k];
    for (int c = 0; c < 8; c++) {
      double q[3] = {c & 1 ? g->hi.x : g->lo.x, c & 2 ? g->hi.y : g->lo.y, c & 4 ? g->hi.z : g->lo.z};
      shape_box_add(lo, hi,
                    v3((double)m[0] * q[0] + (double)m[1] * q[1] + (double)m[2] * q[2] + t[0],
                       (double)m[4] * q[0] + (double)m[5] * q[1] + (double)m[6] * q[2] + t[1],
                       (double)m[8] * q[0] + (double)m[9] * q[1] + (double)m[10] * q[2] + t[2]));
    }
  }
}
