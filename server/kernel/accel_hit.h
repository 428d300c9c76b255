/* What a ray query of the acceleration structure (accel.h) answers: the
 * hit record shapes turn into an interaction (shapes/shape.h). Its own
 * header so that shapes, which accel.c builds on, need not include
 * accel.h (tools/check-layers.py). */
#ifndef RSW_ACCEL_HIT_H
#define RSW_ACCEL_HIT_H

#include "kernel.h"

typedef struct accel_hit {
  double t;        /* distance along the (unnormalised) ray direction */
  uint32_t shape;  /* index into scene->shapes */
  uint32_t member; /* instanced hits: the member of the group (its geomID in the group) */
  uint32_t sub;    /* instanced hits: the placement within an instancelist (0 for `instance`) */
  uint32_t prim;   /* triangle index (meshes), 0 for analytic shapes */
  double u, v;     /* barycentrics for triangles (p = (1-u-v) p0 + u p1 + v p2) */
  vec3 ng;         /* unnormalised geometric normal in object space, oriented
                       as (p1 - p0) x (p2 - p0) for triangles */
} accel_hit;

#endif
