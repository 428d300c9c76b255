/* `obj` and `ply`: triangle meshes read from files (mitsuba3
 * src/shapes/obj.cpp, ply.cpp). Parameters: filename, face_normals (false:
 * use the file's vertex normals when present), flip_tex_coords (obj: true,
 * ply: false), flip_normals, to_world, nested bsdf and area emitter.
 *
 * Deliberate difference: Mitsuba bakes to_world into the vertices; here the
 * vertices stay in object space and to_world is the Embree instance
 * transform (accel.h), so moving a mesh never touches its BVH. */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "mesh_io.h"
#include "shape_internal.h"

static rsw_status meshfile_create(loader *ld, node *n, object **out, bool is_obj) {
  shape *s = shape_new(&shape_ops_mesh);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  char *path = NULL;
  bool flip_tc;
  rsw_status st = shape_read_common(ld, n, s, true);
  if (!st) st = ld_bool(ld, n, "face_normals", false, &s->face_normals);
  if (!st) st = ld_bool(ld, n, "flip_tex_coords", is_obj, &flip_tc);
  if (!st) st = ld_path(ld, n, "filename", &path);
  if (!st) {
    st = is_obj ? mesh_load_obj(path, flip_tc, &s->mesh, ld->err) : mesh_load_ply(path, &s->mesh, ld->err);
    if (!st && !is_obj && flip_tc && s->mesh.uv)
      for (uint32_t i = 0; i < s->mesh.n_verts; i++) s->mesh.uv[2 * i + 1] = 1.0f - s->mesh.uv[2 * i + 1];
  }
  if (!st) st = shape_finalize(s, ld->err, n->loc);
  free(path);
  if (st) {
    shape_release(s);
    free(s);
    return st;
  }
  *out = &s->base;
  return RSW_OK;
}

static rsw_status obj_create(loader *ld, node *n, object **out) {
  return meshfile_create(ld, n, out, true);
}
static rsw_status ply_create(loader *ld, node *n, object **out) {
  return meshfile_create(ld, n, out, false);
}

DEFINE_PLUGIN(obj, CLS_SHAPE, .destroy = shape_destroy, .traverse = shape_traverse,
              .parameters_changed = shape_parameters_changed);
DEFINE_PLUGIN(ply, CLS_SHAPE, .destroy = shape_destroy, .traverse = shape_traverse,
              .parameters_changed = shape_parameters_changed);
