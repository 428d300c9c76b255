/* `cube`: a 24-vertex, 12-triangle mesh (mitsuba3 src/shapes/cube.cpp;
 * shape.c has its geometry's ops). */
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "shape_internal.h"

/* cube: [-1,1]^3, 24 vertices (4 per face, per-face normals), 12
 * triangles, each face's uv in [0,1]^2 (mitsuba3 src/shapes/cube.cpp). */
static rsw_status cube_create(loader *ld, node *n, object **out) {
  shape *s = shape_new(&shape_ops_mesh);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  rsw_status st = shape_read_common(ld, n, s, true);
  if (!st && shape_mesh_alloc(&s->mesh, 24, 12, true, true))
    st = ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  if (st) {
    shape_release(s);
    free(s);
    return st;
  }
  /* For each face: normal axis a with sign sg; the face's own (u, v) axes
   * are chosen so that (u x v) = normal, which makes the triangles
   * (0,1,2), (0,2,3) wind counter-clockwise seen from outside. */
  for (int f = 0; f < 6; f++) {
    int a = f / 2;
    float sg = (f % 2) ? -1.0f : 1.0f;
    int ua = (a + 1) % 3, va = (a + 2) % 3;
    float nrm[3] = {0, 0, 0};
    nrm[a] = sg;
    static const float cu[4] = {-1, 1, 1, -1}, cv[4] = {-1, -1, 1, 1};
    for (int k = 0; k < 4; k++) {
      float p[3];
      p[a] = sg;
      /* Flip u on negative faces to keep the winding outward. */
      p[ua] = cu[k] * sg;
      p[va] = cv[k];
      int vi = 4 * f + k;
      memcpy(&s->mesh.pos[3 * vi], p, sizeof p);
      memcpy(&s->mesh.nrm[3 * vi], nrm, sizeof nrm);
      s->mesh.uv[2 * vi] = (cu[k] + 1) * 0.5f;
      s->mesh.uv[2 * vi + 1] = (cv[k] + 1) * 0.5f;
    }
    uint32_t b = 4u * (uint32_t)f;
    uint32_t tri[6] = {b, b + 1, b + 2, b, b + 2, b + 3};
    memcpy(&s->mesh.faces[6 * f], tri, sizeof tri);
  }
  return shape_finish(ld, n, s, out);
}

DEFINE_PLUGIN(cube, CLS_SHAPE, .destroy = shape_destroy, .traverse = shape_traverse,
              .parameters_changed = shape_parameters_changed);
