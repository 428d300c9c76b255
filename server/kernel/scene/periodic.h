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
 * for the infinite canopy. The sensors' bounding sphere uses the column's
 * lateral extent. */
#ifndef RSW_SCENE_PERIODIC_H
#define RSW_SCENE_PERIODIC_H

#include "../accel.h"

extern const plugin plugin_periodic;
/* The box a `periodic` object carries (scene_create copies it). */
const periodic_bounds *periodic_of(const object *o);

/* Closest hit honouring the periodic boundary (plain accel_intersect
 * without one). On a hit, *r is the ray segment that hit (its origin
 * wrapped; h->t is along it) and *t_offset the distance travelled before
 * that segment (so the hit lies at t_offset + h->t along the original
 * ray). */
bool scene_trace(const scene *s, ray3 *r, accel_hit *h, double *t_offset);
/* Any hit on [tmin, tmax] honouring the boundary. */
bool scene_occluded(const scene *s, const ray3 *r);

#endif
