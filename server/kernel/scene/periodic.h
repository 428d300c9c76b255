/* The periodic lateral boundary: a scene-level object
 *
 *   "periodic": {"type": "periodic", "min": [x0, y0], "max": [x1, y1]}
 *
 * (a top-level child of the scene; at most one). The scene then stands for
 * an infinite canopy: the content of the column [x0, x1] x [y0, y1] repeated
 * sideways. Geometry outside the column is not seen. Rays are traced inside
 * the column; a ray that leaves through a side wall re-enters through the
 * opposite wall with the same direction; rays leaving through the top or
 * bottom (above or below all geometry) continue normally. An origin outside
 * the column is first brought into it (modulo the period), which is exact
 * for the infinite canopy.
 *
 * Nothing lies outside the geometry's slab [zmin, zmax] (the vertical
 * extent of all shapes, set with the bounds), so a ray ends exactly when
 * it leaves the slab, however many walls it crosses first: a ray whose
 * direction is not horizontal always does. A ray starting outside the
 * slab is first moved along itself to the slab (exact). Shadow rays
 * towards infinitely distant emitters (directional, constant, envmap,
 * environment plugins) have no length limit (direction_sample.dist is
 * INFINITY), so a wrapped shadow ray is cut by the slab only. The
 * scene's bounding sphere covers one column; distant sensors put their
 * ray origins outside the slab (sensor_common.c), so nothing that uses
 * the sphere assumes the scene is finite. */
#ifndef RSW_SCENE_PERIODIC_H
#define RSW_SCENE_PERIODIC_H

#include "../accel.h"

extern const plugin plugin_periodic;
/* The box a `periodic` object carries (scene_create copies it). */
const periodic_bounds *periodic_of(const object *o);

/* What a traced ray did. A periodic ray that stays inside the slab for
 * 65536 walls (only a ray within about (zmax - zmin) / (65536 * cell
 * width) radians of horizontal can) is UNRESOLVED: it neither hit nor
 * escaped. It is never counted as escaped: scene_occluded's callers treat
 * it as blocked (it is non-zero) and the path tracer ends the path there
 * without environment light, and counts it (render_stats.unresolved).
 * A ray that provably can neither leave the slab nor hit a shape within
 * the limit (a level shadow ray between a soil and a leaf sheet) is
 * classified so at once, without walking (periodic.c never_resolves). */
typedef enum trace_result {
  TRACE_MISS = 0,
  TRACE_HIT = 1,
  TRACE_UNRESOLVED = 2
} trace_result;

/* Each shape's world z-range into scene->periodic_z (scene_refresh_bounds,
 * with zmin/zmax): what lets a ray that can neither leave the slab nor hit
 * anything within the wall limit be classified UNRESOLVED at once, without
 * walking the 65536 walls (a horizontal sun's shadow rays, a distant
 * sensor looking horizontally). */
rsw_status periodic_refresh_shapes(scene *s, rsw_err *err);

/* Closest hit honouring the periodic boundary (plain accel_intersect
 * without one). On a hit, *r is the ray segment that hit (its origin
 * wrapped; h->t is along it) and *t_offset the distance travelled before
 * that segment (so the hit lies at t_offset + h->t along the original
 * ray). */
trace_result scene_trace(const scene *s, ray3 *r, accel_hit *h, double *t_offset);
/* Any hit on [tmin, tmax] honouring the boundary (TRACE_HIT: occluded). */
trace_result scene_occluded(const scene *s, const ray3 *r);

/* The distance t >= 0 to move back along -d from p so that p - t d lies
 * outside the slab on the side the direction d comes from (above it for
 * d.z < 0, below for d.z > 0; 0 when already there, when d is horizontal
 * or without a periodic boundary). Exact: nothing lies there. */
double periodic_slab_offset(const periodic_bounds *b, vec3 p, vec3 d);

/* p brought into the column (x, y modulo the period, into [min, max));
 * p unchanged without a periodic boundary or when already inside. This is
 * what scene_trace and scene_occluded do to a ray's origin first. */
vec3 periodic_wrap_point(const periodic_bounds *b, vec3 p);

/* Test hooks: Embree queries made by scene_trace/scene_occluded on the
 * calling thread (a running count), and the early decision on or off
 * (on by default; off: every ray walks, as before it existed). */
unsigned long periodic_query_count(void);
void periodic_set_early_out(bool on);

#endif
