/* Geometry services every shape offers, whatever its plugin: the hit
 * record -> surface interaction, uniform position sampling, area.
 * Shape plugins only differ in how they build the object (mesh from a file,
 * two-triangle rectangle, analytic sphere/disk); the rest is here. */
#ifndef RSW_SHAPES_SHAPE_H
#define RSW_SHAPES_SHAPE_H

#include "../kernel.h"

/* A sampled point on a shape's surface. */
typedef struct position_sample {
  vec3 p;      /* world */
  vec3 n;      /* unit world normal (after flip_normals) */
  double uv[2];
  double pdf;  /* area density, 1/area for uniform sampling */
} position_sample;

/* Uniformly sample a point on the shape (world-space area measure):
 * rectangle: to_world (2u.x-1, 2u.y-1, 0); disk: concentric disk;
 * sphere: uniform sphere; cylinder: (cos 2pi u.y, sin 2pi u.y, u.x);
 * mesh: triangle by area then uniform barycentric. */
position_sample shape_sample_position(const shape *s, vec2 u);
/* Area pdf of shape_sample_position (1/area). */
double shape_pdf_position(const shape *s);

/* Fill si from a hit (prim, barycentrics u/v for triangles or the object
 * space hit point for analytic shapes) on ray r at distance t. */
struct accel_hit;
void shape_fill_interaction(const shape *s, const ray3 *r, const struct accel_hit *h,
                            surface_interaction *si);

/* Compute area, triangle cdf; check geometry (degenerate to_world for a
 * disk, non-uniform scale for a sphere, ...). Called by create(). */
rsw_status shape_finalize(shape *s, rsw_err *err, const char *where);

/* |det| of the linear part of t (for triangle areas below). */
static inline double xf_abs_det3(const xform *t) {
  const double(*m)[4] = t->m;
  return fabs(m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
              m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]));
}

/* World area of an object-space triangle under t without transforming its
 * vertices: with A the linear part, |A e1 x A e2| = |det A| |A^-T (e1 x e2)|,
 * and xf_normal applies A^-T. */
static inline double tri_world_area(const xform *t, double abs_det, vec3 p0, vec3 p1, vec3 p2) {
  return 0.5 * abs_det * v3_len(xf_normal(t, v3_cross(v3_sub(p1, p0), v3_sub(p2, p0))));
}

/* Mark a shape as sampled (a sensor target) and compute what sampling
 * needs; fails when it has no area. */
rsw_status shape_enable_sampling(shape *s, rsw_err *err, const char *where);

/* Free a shape's owned geometry (used by every shape plugin's destroy). */
void shape_release(shape *s);

#endif
