/* Private helpers for shape plugins. */
#ifndef RSW_SHAPES_SHAPE_COMMON_H
#define RSW_SHAPES_SHAPE_COMMON_H

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

#endif
