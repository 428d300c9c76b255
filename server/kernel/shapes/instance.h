/* Instancing: `shapegroup` (shapes defined once, not rendered themselves),
 * `instance` (one placement of a group: to_world + the group) and
 * `instancelist` (N placements read from a text file).
 *
 * All three are shapes in scene->shapes so that they take part in loading,
 * parameters and bounds like any shape; accel.c gives each group one
 * Embree scene holding all its members (member to_world baked into the
 * vertices, analytic members transformed in their callbacks, since
 * Debian's Embree allows one instance level) and instances that scene once
 * per placement in the top level.
 *
 * Memory: an `instance` is a full shape object (a few hundred bytes); an
 * `instancelist` stores one compact record per placement, a 3x4 float
 * matrix (48 bytes) and its translation again in double precision (24
 * bytes: placements may be georeferenced, kilometres from the origin),
 * plus what Embree holds per instance. */
#ifndef RSW_SHAPES_INSTANCE_H
#define RSW_SHAPES_INSTANCE_H

#include "shape.h"

extern const plugin plugin_shapegroup, plugin_instance, plugin_instancelist;

typedef struct shape_group {
  shape base;      /* base.to_world unused (identity) */
  shape **members; /* owned array; the shapes are owned by the scene */
  size_t n_members;
  vec3 lo, hi; /* bounds of the members in group space */
} shape_group;

typedef struct instance_shape {
  shape base; /* `instance`: base.to_world is the placement */
  shape_group *group;
  uint32_t n; /* placements: 1 for `instance` */
  float *xf;  /* `instancelist`: n row-major 3x4 matrices; NULL for `instance` */
  double *tr; /* `instancelist`: n translations (x, y, z), exact as read; the
                        float ones in xf are not used for tracing */
} instance_shape;

static inline bool shape_is_group(const shape *s) {
  return s->base.plugin == &plugin_shapegroup;
}
static inline bool shape_is_instancing(const shape *s) {
  return s->base.plugin == &plugin_instance || s->base.plugin == &plugin_instancelist;
}

/* The placement transform of instance k of s (an instancing shape). */
xform instance_transform(const instance_shape *s, uint32_t k);

/* Start fetching placement k's record (what instance_transform reads). */
static inline void instance_prefetch(const instance_shape *s, uint32_t k) {
  if (!s->xf) return;
  const char *m = (const char *)&s->xf[12 * (size_t)k], *t = (const char *)&s->tr[3 * (size_t)k];
  __builtin_prefetch(m);
  __builtin_prefetch(m + 12 * sizeof(float) - 1);
  __builtin_prefetch(t);
  __builtin_prefetch(t + 3 * sizeof(double) - 1);
}

/* Extend [lo, hi] by the world bounds of a group (nothing: not rendered)
 * or of an instancing shape (group box corners under each placement). */
void instance_bbox(const shape *s, vec3 *lo, vec3 *hi);

/* Parse an instance list (one placement per row: 16 numbers, a row-major
 * 4x4 to_world; or 7 numbers "x y z nx ny nz radius", a leaf translated to
 * (x, y, z), its +z turned to the normal and scaled by radius). '#' starts
 * a comment. On success *xf (n x 12 floats, malloc'ed) and *n. Errors
 * name file:line. Exposed for tests. */
rsw_status instance_list_parse(const char *path, float **xf, uint32_t *n, rsw_err *err);

#endif
