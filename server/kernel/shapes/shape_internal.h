/* Private helpers for shape plugins. */
#ifndef RSW_SHAPES_SHAPE_INTERNAL_H
#define RSW_SHAPES_SHAPE_INTERNAL_H

#include "../scene/loader.h"
#include "shape.h"

/* Read to_world, flip_normals, the nested bsdf (default diffuse) and an
 * optional nested area emitter. */
rsw_status shape_read_common(loader *ld, node *n, shape *s, bool mesh_like);
/* plugin.destroy for every shape. */
void shape_destroy(object *o);
/* plugin.traverse / parameters_changed for every shape. */
void shape_traverse(object *o, struct param_visitor *v);
void shape_parameters_changed(object *o);

/* A new shape with the given geometry table and to_world the identity
 * (calloc'ed; NULL when out of memory). */
shape *shape_new(const shape_ops *ops);
/* shape_finalize(), then *out = s; on failure s is released and freed. */
rsw_status shape_finish(loader *ld, node *n, shape *s, object **out);
/* Allocate a mesh's buffers (RSW_ERR_NOMEM when any is missing). */
rsw_status shape_mesh_alloc(mesh *m, uint32_t nv, uint32_t nf, bool normals, bool uvs);
/* Widen the box [*lo, *hi] by p. */
static inline void shape_box_add(vec3 *lo, vec3 *hi, vec3 p) {
  lo->x = fmin(lo->x, p.x), lo->y = fmin(lo->y, p.y), lo->z = fmin(lo->z, p.z);
  hi->x = fmax(hi->x, p.x), hi->y = fmax(hi->y, p.y), hi->z = fmax(hi->z, p.z);
}

#endif
