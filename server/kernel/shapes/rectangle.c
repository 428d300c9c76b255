/* `rectangle`: a two-triangle mesh (Mitsuba 3.7.1's form; shape.c has
 * its geometry's ops). */
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "shape_internal.h"

/* rectangle: [-1,1]^2 at z = 0, normal +z; vertices (-1,-1,0), (1,-1,0),
 * (-1,1,0), (1,1,0); triangles (1,2,0), (1,3,2) (mitsuba3
 * src/shapes/rectangle.cpp, 3.7.1 mesh form); uv = ((x+1)/2, (y+1)/2). */
static rsw_status rectangle_create(loader *ld, node *n, object **out) {
  shape *s = shape_new(&shape_ops_mesh);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  rsw_status st = shape_read_common(ld, n, s, false);
  if (!st && shape_mesh_alloc(&s->mesh, 4, 2, true, true))
    st = ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  if (st) {
    shape_release(s);
    free(s);
    return st;
  }
  static const float P[12] = {-1, -1, 0, 1, -1, 0, -1, 1, 0, 1, 1, 0};
  static const uint32_t F[6] = {1, 2, 0, 1, 3, 2};
  memcpy(s->mesh.pos, P, sizeof P);
  memcpy(s->mesh.faces, F, sizeof F);
  for (int i = 0; i < 4; i++) {
    s->mesh.nrm[3 * i] = 0;
    s->mesh.nrm[3 * i + 1] = 0;
    s->mesh.nrm[3 * i + 2] = 1;
    s->mesh.uv[2 * i] = (P[3 * i] + 1) * 0.5f;
    s->mesh.uv[2 * i + 1] = (P[3 * i + 1] + 1) * 0.5f;
  }
  return shape_finish(ld, n, s, out);
}

DEFINE_PLUGIN(rectangle, CLS_SHAPE, .destroy = shape_destroy, .traverse = shape_traverse,
              .parameters_changed = shape_parameters_changed);
