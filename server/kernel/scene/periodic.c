/* The periodic lateral boundary (see periodic.h). */
#include "periodic.h"

#include <stdlib.h>

#include "../shapes/instance.h"
#include "plugin_def.h"

/* The plugin only carries the box; scene_create copies it into
 * scene->periodic. */
typedef struct periodic_obj {
  object base;
  periodic_bounds b;
} periodic_obj;

static rsw_status read_xy(loader *ld, node *n, const char *name, double out[2]) {
  prop *p = node_find(n, name);
  if (!p)
    return ld_fail(ld, n, NULL, RSW_ERR_MISSING, "%s '%s': missing property '%s'", n->type, n->id, name);
  if (p->kind != PROP_NUMBERS || p->n_nums != 2)
    return ld_fail(ld, n, name, RSW_ERR_TYPE, "property '%s' must be a list of 2 numbers [x, y]", name);
  out[0] = p->nums[0];
  out[1] = p->nums[1];
  p->used = true;
  return RSW_OK;
}

DEFINE_PLUGIN(periodic, CLS_SCENE);

static rsw_status periodic_create(loader *ld, node *n, object **out) {
  periodic_obj *o = PLUGIN_NEW(periodic_obj, periodic);
  if (!o) return plugin_created(ld, n, NULL, out);
  rsw_status st = read_xy(ld, n, "min", o->b.min);
  if (!st) st = read_xy(ld, n, "max", o->b.max);
  if (!st && !(o->b.max[0] > o->b.min[0] && o->b.max[1] > o->b.min[1] &&
               isfinite(o->b.max[0] - o->b.min[0]) && isfinite(o->b.max[1] - o->b.min[1])))
    st =
        ld_fail(ld, n, "max", RSW_ERR_RANGE, "periodic '%s': max must exceed min in x and y (finite)", n->id);
  if (st) {
    free(o);
    return st;
  }
  o->b.on = true;
  return plugin_created(ld, n, &o->base, out);
}

const periodic_bounds *periodic_of(const object *o) {
  return &((const periodic_obj *)o)->b;
}

/* x brought into [lo, hi) modulo the period. */
static double wrap(double x, double lo, double hi) {
  if (x >= lo && x < hi) return x;
  double L = hi - lo, r = fmod(x - lo, L);
  if (r < 0) r += L;
  double w = lo + r;
  return w < hi ? w : lo;
}

vec3 periodic_wrap_point(const periodic_bounds *b, vec3 p) {
  if (!b->on) return p;
  p.x = wrap(p.x, b->min[0], b->max[0]);
  p.y = wrap(p.y, b->min[1], b->max[1]);
  return p;
}

/* A margin around the geometry's slab [zmin, zmax] inside which nothing
 * lies either (it covers the float rounding of Embree's vertices), so that
 * cutting a ray at the margin is exact. */
static double slab_margin(const periodic_bounds *b) {
  return 1e-4 * (b->zmax - b->zmin) + 1e-6 * (1.0 + fmax(fabs(b->zmin), fabs(b->zmax)));
}

double periodic_slab_offset(const periodic_bounds *b, vec3 p, vec3 d) {
  if (!b->on) return 0.0;
  double m = slab_margin(b);
  double t = d.z < 0 ? (b->zmax + m - p.z) / -d.z : d.z > 0 ? (p.z - (b->zmin - m)) / d.z : 0.0;
  return t > 0 && isfinite(t) ? t : 0.0;
}

/* Distance along r to the side wall it leaves the column through, and
 * which walls (bit 0: x, bit 1: y). */
static double side_exit(const periodic_bounds *b, const ray3 *r, int *walls) {
  double tx = r->d.x > 0   ? (b->max[0] - r->o.x) / r->d.x
              : r->d.x < 0 ? (b->min[0] - r->o.x) / r->d.x
                           : INFINITY;
  double ty = r->d.y > 0   ? (b->max[1] - r->o.y) / r->d.y
              : r->d.y < 0 ? (b->min[1] - r->o.y) / r->d.y
                           : INFINITY;
  tx = fmax(tx, 0.0), ty = fmax(ty, 0.0);
  *walls = (tx <= ty ? 1 : 0) | (ty <= tx ? 2 : 0);
  return fmin(tx, ty);
}

/* Move the origin of q by ts along it (ts < q->tmax), wrapped into the
 * column; *off accumulates the distance. */
static void move_origin(const periodic_bounds *b, ray3 *q, double ts, double *off) {
  vec3 p = v3_fma(q->o, ts, q->d);
  p.x = wrap(p.x, b->min[0], b->max[0]);
  p.y = wrap(p.y, b->min[1], b->max[1]);
  q->o = p;
  q->tmin = fmax(0.0, q->tmin - ts);
  q->tmax -= ts;
  *off += ts;
}

/* A ray whose origin lies outside the slab (plus margin) and heads
 * towards it is moved, exactly, to the slab's margin plane (nothing lies
 * between). False when it can hit nothing: it heads away or its segment
 * ends before the slab. */
static bool enter_slab(const periodic_bounds *b, ray3 *q, double *off) {
  double m = slab_margin(b), top = b->zmax + m, bot = b->zmin - m, t;
  if (q->o.z > top) {
    if (!(q->d.z < 0)) return false;
    t = (top - q->o.z) / q->d.z;
  } else if (q->o.z < bot) {
    if (!(q->d.z > 0)) return false;
    t = (bot - q->o.z) / q->d.z;
  } else {
    return true;
  }
  if (!(t < q->tmax)) return false;
  move_origin(b, q, t, off);
  return true;
}

/* Re-enter through the opposite wall(s) at distance ts; false when the ray
 * has left the geometry's slab for good (above going up, below going
 * down, or level outside it) or its segment ends before the wall. */
static bool advance(const periodic_bounds *b, ray3 *q, double ts, int walls) {
  if (!(ts < q->tmax) || !isfinite(ts)) return false;
  vec3 p = v3_fma(q->o, ts, q->d);
  double m = slab_margin(b);
  if ((q->d.z >= 0 && p.z > b->zmax + m) || (q->d.z <= 0 && p.z < b->zmin - m)) return false;
  if (walls & 1) p.x = q->d.x > 0 ? b->min[0] : b->max[0];
  if (walls & 2) p.y = q->d.y > 0 ? b->min[1] : b->max[1];
  q->o = p;
  q->tmin = fmax(0.0, q->tmin - ts);
  q->tmax -= ts;
  return true;
}

/* The walk ends exactly when the ray leaves the slab (or its segment
 * ends), however many walls that takes: a ray with d.z != 0 always leaves
 * it. Only a ray within about (zmax - zmin) / (PERIODIC_MAX_WALLS * cell)
 * radians of horizontal, inside the slab, can run into this guard; such a
 * ray is reported as unresolved (see periodic.h), never as escaped. */
enum {
  PERIODIC_MAX_WALLS = 1 << 16
};

rsw_status periodic_refresh_shapes(scene *s, rsw_err *err) {
  size_t n = s->n_shapes ? s->n_shapes : 1;
  double *z = realloc(s->periodic_z, 2 * n * sizeof *z);
  if (!z) return rsw_fail(err, RSW_ERR_NOMEM, "periodic", "out of memory");
  s->periodic_z = z;
  for (size_t i = 0; i < s->n_shapes; i++) {
    vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
    instance_bbox(s->shapes[i], &lo, &hi); /* nothing (not rendered): lo > hi, never in the way */
    z[2 * i] = lo.z, z[2 * i + 1] = hi.z;
  }
  return RSW_OK;
}

/* The early decision (issue: a horizontal sun cost 65,536 queries per
 * shadow ray). q: the ray as the walk starts (origin wrapped, inside the
 * slab). True only when the walk below would provably end in
 * TRACE_UNRESOLVED, decided without tracing:
 *
 * 1. It cannot end by leaving the slab or at tmax. The side walls of the
 *    axis with the shortest crossing distance c = min(Lx / |dx|,
 *    Ly / |dy|) are crossed at most c apart from the start (the origin is
 *    inside the column), and every crossing is one step of the walk, so
 *    the walk's PERIODIC_MAX_WALLS steps end within D = MAX * c. If the
 *    ray (exact arithmetic) stays inside the slab's margin planes, with
 *    half the margin to spare, up to D (1 + 1e-6) (only the plane it
 *    heads for counts, as in advance()), and tmax exceeds that,
 *    every step of the walk advances: the float drift of the walk's
 *    positions over 65,536 steps (~1e-11 |z|) is far below the spare
 *    half margin (>= 5e-7 (1 + |z|)), and the 1e-6 covers its drift in
 *    distance. Otherwise (a ray that may leave the slab within the limit,
 *    including every boundary case) the walk decides, as before.
 * 2. It can hit nothing on the way: the z-range it sweeps over [0, D]
 *    misses every shape's world z-range (scene->periodic_z, the shapes'
 *    bounding boxes). A shape behind the origin (entirely below it for a
 *    ray going up or level, above it for a ray going down or level) is
 *    compared strictly: a ray spawned off a flat surface (a soil, a leaf
 *    sheet) lies beyond it by the spawn offset and moves away or level. A
 *    shape ahead must lie beyond the swept range by the slab margin.
 *    Otherwise (a ray that sweeps through a layer of geometry) the walk
 *    decides, as before: it usually hits something within a few walls.
 *
 * So the decision is the walk's in exact arithmetic. In float it can only
 * differ for a ray passing level within Embree's float error of a shape's
 * bounding box (where the walk's own answer is rounding noise), never for
 * one spawned off a surface. test_periodic_sun compares both (with the
 * decision switched off) for directions around the threshold. */
static bool early_out = true;
static _Thread_local unsigned long n_queries;

void periodic_set_early_out(bool on) {
  early_out = on;
}

unsigned long periodic_query_count(void) {
  return n_queries;
}

static bool never_resolves(const scene *s, const ray3 *q) {
  const periodic_bounds *b = &s->periodic;
  double cx = q->d.x != 0 ? (b->max[0] - b->min[0]) / fabs(q->d.x) : INFINITY;
  double cy = q->d.y != 0 ? (b->max[1] - b->min[1]) / fabs(q->d.y) : INFINITY;
  double D = (double)PERIODIC_MAX_WALLS * fmin(cx, cy) * (1.0 + 1e-6);
  if (!early_out || !isfinite(D) || !(q->tmax > D) || isnan(q->d.z) || isnan(q->o.z)) return false;
  double m = slab_margin(b), z0 = q->o.z, dz = q->d.z, z1 = z0 + D * dz;
  /* advance() stops a ray going up above zmax + m, one going down below
   * zmin - m, a level one at neither (its z never changes, and
   * enter_slab() put it inside). */
  if (dz > 0 ? !(z1 < b->zmax + 0.5 * m) : dz < 0 ? !(z1 > b->zmin - 0.5 * m) : false) return false;
  const double *z = s->periodic_z;
  for (size_t i = 0; i < s->n_shapes; i++) {
    double lo = z[2 * i], hi = z[2 * i + 1];
    bool clear =
        (dz >= 0 && hi < z0) || (dz <= 0 && lo > z0) || (dz > 0 && lo > z1 + m) || (dz < 0 && hi < z1 - m);
    if (!clear) return false;
  }
  return true;
}

trace_result scene_trace(const scene *s, ray3 *r, accel_hit *h, double *t_offset) {
  *t_offset = 0;
  const periodic_bounds *b = &s->periodic;
  if (!b->on) return accel_intersect(s->accel, r, h) ? TRACE_HIT : TRACE_MISS;
  ray3 q = *r;
  q.o.x = wrap(q.o.x, b->min[0], b->max[0]);
  q.o.y = wrap(q.o.y, b->min[1], b->max[1]);
  double off = 0;
  if (!enter_slab(b, &q, &off)) return TRACE_MISS;
  if (never_resolves(s, &q)) return TRACE_UNRESOLVED;
  for (int k = 0; k < PERIODIC_MAX_WALLS; k++) {
    int walls;
    double ts = side_exit(b, &q, &walls);
    ray3 seg = q;
    seg.tmax = fmin(q.tmax, ts);
    if (seg.tmax >= seg.tmin) {
      n_queries++;
      if (accel_intersect(s->accel, &seg, h)) {
        *r = q;
        *t_offset = off;
        return TRACE_HIT;
      }
    }
    if (!advance(b, &q, ts, walls)) return TRACE_MISS;
    off += ts;
  }
  return TRACE_UNRESOLVED;
}

trace_result scene_occluded(const scene *s, const ray3 *r) {
  const periodic_bounds *b = &s->periodic;
  if (!b->on) return accel_occluded(s->accel, r) ? TRACE_HIT : TRACE_MISS;
  ray3 q = *r;
  q.o.x = wrap(q.o.x, b->min[0], b->max[0]);
  q.o.y = wrap(q.o.y, b->min[1], b->max[1]);
  double off = 0;
  if (!enter_slab(b, &q, &off)) return TRACE_MISS;
  if (never_resolves(s, &q)) return TRACE_UNRESOLVED;
  for (int k = 0; k < PERIODIC_MAX_WALLS; k++) {
    int walls;
    double ts = side_exit(b, &q, &walls);
    ray3 seg = q;
    seg.tmax = fmin(q.tmax, ts);
    if (seg.tmax >= seg.tmin) {
      n_queries++;
      if (accel_occluded(s->accel, &seg)) return TRACE_HIT;
    }
    if (!advance(b, &q, ts, walls)) return TRACE_MISS;
  }
  return TRACE_UNRESOLVED;
}
