/* Common medium code: properties, box clipping, scene-level checks. */
#include <math.h>
#include <stdlib.h>

#include "../accel.h"
#include "../hit.h"
#include "../scene/loader.h"
#include "../scene/params.h"
#include "../scene/periodic.h"
#include "../shapes/instance.h"
#include "media.h"

rsw_status medium_read_common(loader *ld, node *n, medium *m) {
  object *o = NULL;
  rsw_status st = ld_child(ld, n, NULL, CLS_PHASE, &o);
  if (st) return st;
  if (!o) {
    st = ld_create_default(ld, "isotropic", CLS_PHASE, NULL, &o);
    if (st) return st;
  }
  m->phase = (phase *)o;
  st = ld_float_range(ld, n, "scale", 1.0, 0.0, INFINITY, &m->scale);
  if (st) return st;
  st = ld_bool(ld, n, "sample_emitters", true, &m->sample_emitters);
  if (st) return st;
  return ld_bool(ld, n, "use_rrt", true, &m->use_rrt);
}

void medium_traverse_common(medium *m, param_visitor *v) {
  pv_float(v, "scale", &m->scale, UPDATE_SPECTRAL, 0.0, INFINITY);
  pv_object(v, "phase_function", &m->phase->base, NAN, NAN);
}

void media_box_init(media_box *b, const xform *to_world) {
  const double(*m)[4] = to_world->m;
  b->to_world = to_world;
  b->aligned = m[0][1] == 0 && m[0][2] == 0 && m[1][0] == 0 && m[1][2] == 0 && m[2][0] == 0 && m[2][1] == 0 &&
               m[0][0] != 0 && m[1][1] != 0 && m[2][2] != 0;
  for (int a = 0; a < 3; a++) {
    double b0 = m[a][3], b1 = m[a][3] + m[a][a];
    bool swap = b0 > b1;
    b->lo[a] = swap ? b1 : b0;
    b->hi[a] = swap ? b0 : b1;
  }
}

bool media_box_clip_at(const media_box *b, const ray3 *r, double *mint, double *maxt) {
  if (b->aligned) {
    /* Axis-aligned box (scale and translation): the slab test in world
     * coordinates, one division per axis. */
    double inv[3] = {0.0, 0.0, 0.0};
    if (r->d.x != 0.0) inv[0] = 1.0 / r->d.x;
    if (r->d.y != 0.0) inv[1] = 1.0 / r->d.y;
    if (r->d.z != 0.0) inv[2] = 1.0 / r->d.z;
    return media_box_clip_aligned(b, r->o, r->d, r->tmin, r->tmax, inv, mint, maxt);
  }
  double lo = r->tmin, hi = r->tmax;
  vec3 o = xf_inv_point(b->to_world, r->o), d = xf_inv_vector(b->to_world, r->d);
  const double oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z};
  for (int a = 0; a < 3; a++) {
    if (dd[a] == 0.0) {
      if (oo[a] < 0.0 || oo[a] > 1.0) return false;
      continue;
    }
    double inv = 1.0 / dd[a];
    double t0 = (0.0 - oo[a]) * inv, t1 = (1.0 - oo[a]) * inv;
    if (t0 > t1) {
      double tmp = t0;
      t0 = t1;
      t1 = tmp;
    }
    if (t0 > lo) lo = t0;
    if (t1 < hi) hi = t1;
  }
  if (!(lo < hi)) return false;
  *mint = lo;
  *maxt = hi;
  return true;
}

bool media_box_clip(const xform *to_world, const ray3 *r, double *mint, double *maxt) {
  media_box b;
  media_box_init(&b, to_world);
  return media_box_clip_at(&b, r, mint, maxt);
}

/* ---- scene-level checks ---------------------------------------------------- */

/* The document node an object was built from (depth-first), or NULL. */
static node *node_of(node *n, const void *o, int depth) {
  if (n->built == o) return n;
  if (depth > RSW_MAX_DEPTH) return NULL;
  for (size_t i = 0; i < n->n_props; i++)
    if (n->props[i].kind == PROP_NODE) {
      node *r = node_of(n->props[i].child, o, depth + 1);
      if (r) return r;
    }
  return NULL;
}

static const char *loc_of(node *root, const void *o) {
  node *n = root ? node_of(root, o, 0) : NULL;
  return n ? n->loc : "";
}

/* Does any shape (or sensor) use medium m? */
static bool bounded(const scene *s, const medium *m) {
  for (size_t i = 0; i < s->n_shapes; i++)
    if (s->shapes[i]->interior == m || s->shapes[i]->exterior == m) return true;
  return false;
}

static bool held_by_sensor(const scene *s, const medium *m) {
  for (size_t i = 0; i < s->n_sensors; i++)
    if (s->sensors[i]->medium == m) return true;
  return false;
}

bool scene_has_sensor_media(const scene *s) {
  for (size_t i = 0; i < s->n_sensors; i++)
    if (s->sensors[i]->medium) return true;
  return false;
}

rsw_status scene_check_media(const scene *s, node *root, rsw_err *err) {
  for (size_t i = 0; i < s->n_objects; i++) {
    const object *o = s->objects[i];
    if (!o->plugin || o->plugin->cls != CLS_MEDIUM) continue;
    const medium *m = (const medium *)o;
    if (!bounded(s, m) && !held_by_sensor(s, m))
      return rsw_fail(err, RSW_ERR_INVALID, loc_of(root, o),
                      "medium '%s' has no boundary: no shape has it as its interior or exterior and no "
                      "sensor sits in it, so no ray can enter it",
                      o->id ? o->id : "");
  }
  /* volpath finds a path's sensor by its sampler (integrators/volpath.c). */
  for (size_t i = 0; i < s->n_sensors; i++)
    for (size_t j = 0; j < i; j++)
      if (s->sensors[i]->sampler == s->sensors[j]->sampler && s->sensors[i]->medium != s->sensors[j]->medium)
        return rsw_fail(
            err, RSW_ERR_INVALID, loc_of(root, s->sensors[i]),
            "sensor '%s' shares its sampler with sensor '%s' but sits in another medium: give each "
            "its own sampler",
            s->sensors[i]->base.id ? s->sensors[i]->base.id : "",
            s->sensors[j]->base.id ? s->sensors[j]->base.id : "");
  for (size_t i = 0; i < s->n_sensors; i++) {
    const sensor *se = s->sensors[i];
    if (!se->medium || !bounded(s, se->medium)) continue; /* an unbounded medium fills all space */
    ray3 r;
    if (!(se->ops->sample_ray(se, v2(0.5, 0.5), v2(0.5, 0.5), &r) > 0)) continue;
    double len = v3_len(r.d);
    if (!(len > 0)) continue;
    r.d = v3_scale(r.d, 1.0 / len);
    r.tmin = 0;
    r.tmax = INFINITY;
    /* Walk the ray to the first surface that bounds a medium. */
    const medium *here = NULL;
    bool found = false;
    for (int k = 0; k < 4096 && !found; k++) {
      ray3 seg = r;
      accel_hit h;
      double off;
      if (scene_trace(s, &seg, &h, &off) != TRACE_HIT) break;
      surface_interaction si;
      hit_fill_interaction(s, &seg, &h, &si);
      const shape *sh = si.shape;
      if (sh->interior || sh->exterior) {
        here = v3_dot(r.d, si.ng) > 0 ? sh->interior : sh->exterior;
        found = true;
        break;
      }
      r.o = v3_fma(r.o, si.t + off, r.d);
      r.o = v3_fma(r.o, 8 * si.p_error + 1e-9 * (1 + v3_len(r.o)), r.d);
    }
    if (here != se->medium) {
      const char *mid = se->medium->base.id ? se->medium->base.id : "";
      return rsw_fail(
          err, RSW_ERR_INVALID, loc_of(root, se), "sensor '%s' does not sit inside its medium '%s': %s",
          se->base.id ? se->base.id : "", mid,
          found ? (here ? "its rays start in another medium" : "its rays start outside the medium")
                : "its rays start outside every shape that bounds a medium");
    }
  }
  return RSW_OK;
}

/* ---- null boxes crossed analytically ----------------------------------------- */

/* Is sh (a masked candidate) exactly the surface of its object-space
 * bounds [lo, hi], 12 triangles, two per side covering it along a
 * diagonal, all facing out, under a to_world that keeps orientation? Then
 * a slab test finds every crossing of it exactly as Embree would (up to
 * its float rounding), and which way a ray crosses (into the box or out)
 * gives the media as the hit's normal does. */
static bool null_box_shape(const shape *sh, double lo[3], double hi[3]) {
  const mesh *me = &sh->mesh;
  if (me->n_faces != 12 || !me->pos || !me->faces) return false;
  const double(*m)[4] = sh->to_world.m;
  double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
               m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
               m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  if (!(det > 0) || !isfinite(det)) return false;
  for (int a = 0; a < 3; a++) lo[a] = INFINITY, hi[a] = -INFINITY;
  for (uint32_t f = 0; f < 36; f++) {
    uint32_t v = me->faces[f];
    if (v >= me->n_verts) return false;
    for (int a = 0; a < 3; a++) {
      double x = me->pos[3 * (size_t)v + a];
      lo[a] = fmin(lo[a], x);
      hi[a] = fmax(hi[a], x);
    }
  }
  for (int a = 0; a < 3; a++)
    if (!(lo[a] < hi[a]) || !isfinite(lo[a]) || !isfinite(hi[a])) return false;
  /* Per side (axis a, hi or lo: index 2 a + s), the corner sets (bits of
   * an 8-corner code) of its triangles. */
  unsigned sets[6][2], count[6] = {0};
  for (uint32_t f = 0; f < 12; f++) {
    unsigned code[3];
    double p[3][3];
    for (int k = 0; k < 3; k++) {
      uint32_t v = me->faces[3 * f + k];
      code[k] = 0;
      for (int a = 0; a < 3; a++) {
        double x = me->pos[3 * (size_t)v + a];
        p[k][a] = x;
        if (x == hi[a])
          code[k] |= 1u << a;
        else if (x != lo[a])
          return false; /* not a corner */
      }
    }
    if (code[0] == code[1] || code[1] == code[2] || code[0] == code[2]) return false;
    int side = -1;
    for (int a = 0; a < 3 && side < 0; a++) {
      unsigned b = 1u << a;
      if ((code[0] & b) == (code[1] & b) && (code[1] & b) == (code[2] & b))
        side = 2 * a + ((code[0] & b) ? 1 : 0);
    }
    if (side < 0 || count[side] >= 2) return false;
    int a = side / 2, a1 = (a + 1) % 3, a2 = (a + 2) % 3;
    double e1[3], e2[3];
    for (int c = 0; c < 3; c++) e1[c] = p[1][c] - p[0][c], e2[c] = p[2][c] - p[0][c];
    double n_a = e1[a1] * e2[a2] - e1[a2] * e2[a1];      /* (e1 x e2)_a */
    if (!((side & 1) ? n_a > 0 : n_a < 0)) return false; /* facing in */
    sets[side][count[side]++] = (1u << code[0]) | (1u << code[1]) | (1u << code[2]);
  }
  for (int side = 0; side < 6; side++) {
    if (count[side] != 2) return false;
    unsigned both = sets[side][0] & sets[side][1], all = sets[side][0] | sets[side][1];
    if (__builtin_popcount(all) != 4 || __builtin_popcount(both) != 2) return false;
    unsigned c0 = (unsigned)__builtin_ctz(both), c1 = 31u - (unsigned)__builtin_clz(both);
    if (__builtin_popcount(c0 ^ c1) != 2) return false; /* they share an edge, not the diagonal */
  }
  return true;
}

void media_refresh_null_boxes(scene *s) {
  s->null_boxes.on = false;
  s->null_boxes.n = 0;
  vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
  bool ok = !s->periodic.on;
  for (size_t i = 0; i < s->n_shapes; i++) {
    const shape *sh = s->shapes[i];
    if (!accel_null_box_masked(s->accel, (uint32_t)i)) {
      instance_bbox(sh, &lo, &hi);
      continue;
    }
    struct scene_null_box *b =
        &s->null_boxes.box[s->null_boxes.n < SCENE_NULL_BOXES_MAX ? s->null_boxes.n : 0];
    if (!ok || s->null_boxes.n >= SCENE_NULL_BOXES_MAX || !null_box_shape(sh, b->lo, b->hi)) {
      ok = false;
      continue;
    }
    b->sh = sh;
    const double(*m)[4] = sh->to_world.m;
    b->aligned = m[0][1] == 0 && m[0][2] == 0 && m[1][0] == 0 && m[1][2] == 0 && m[2][0] == 0 &&
                 m[2][1] == 0 && m[3][0] == 0 && m[3][1] == 0 && m[3][2] == 0 && m[3][3] == 1;
    for (int a = 0; a < 3; a++) {
      double x0 = m[a][a] * b->lo[a] + m[a][3], x1 = m[a][a] * b->hi[a] + m[a][3];
      b->wlo[a] = x0 < x1 ? x0 : x1;
      b->whi[a] = x0 < x1 ? x1 : x0;
    }
    /* Interior: the side the normal points away from (inside, for
     * outward triangles), the other way round under flip_normals. */
    b->in = sh->flip_normals ? sh->exterior : sh->interior;
    b->out = sh->flip_normals ? sh->interior : sh->exterior;
    s->null_boxes.n++;
  }
  s->null_boxes.rest_min = lo;
  s->null_boxes.rest_max = hi;
  s->null_boxes.on = ok && s->null_boxes.n > 0;
  if (!s->null_boxes.on) s->null_boxes.n = 0;
}
