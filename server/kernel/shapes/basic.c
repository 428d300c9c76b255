/* Built-in analytic and procedural shapes: rectangle, cube (triangle
 * meshes, as in Mitsuba 3.7.1), sphere and disk (analytic, intersected
 * exactly by accel.c's user geometry). Canonical geometry before to_world:
 * kernel-behavior.md §2.3. */
#include <stdlib.h>
#include <string.h>

#include "shape_common.h"

static shape *shape_alloc(geom_kind g) {
  shape *s = calloc(1, sizeof *s);
  if (s) {
    s->geom = g;
    s->to_world = xf_identity();
  }
  return s;
}

static rsw_status mesh_alloc(mesh *m, uint32_t nv, uint32_t nf, bool normals, bool uvs) {
  m->n_verts = nv;
  m->n_faces = nf;
  m->pos = malloc(3 * (size_t)nv * sizeof(float));
  m->faces = malloc(3 * (size_t)nf * sizeof(uint32_t));
  m->nrm = normals ? malloc(3 * (size_t)nv * sizeof(float)) : NULL;
  m->uv = uvs ? malloc(2 * (size_t)nv * sizeof(float)) : NULL;
  if (!m->pos || !m->faces || (normals && !m->nrm) || (uvs && !m->uv)) return RSW_ERR_NOMEM;
  return RSW_OK;
}

static rsw_status finish(loader *ld, node *n, shape *s, object **out) {
  rsw_status st = shape_finalize(s, ld->err, n->loc);
  if (st) {
    shape_release(s);
    free(s);
    return st;
  }
  *out = &s->base;
  return RSW_OK;
}

/* rectangle: [-1,1]^2 at z = 0, normal +z; vertices (-1,-1,0), (1,-1,0),
 * (-1,1,0), (1,1,0); triangles (1,2,0), (1,3,2) (mitsuba3
 * src/shapes/rectangle.cpp, 3.7.1 mesh form); uv = ((x+1)/2, (y+1)/2). */
static rsw_status rectangle_create(loader *ld, node *n, object **out) {
  shape *s = shape_alloc(GEOM_MESH);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  rsw_status st = shape_read_common(ld, n, s, false);
  if (!st && mesh_alloc(&s->mesh, 4, 2, true, true))
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
  return finish(ld, n, s, out);
}

/* cube: [-1,1]^3, 24 vertices (4 per face, per-face normals), 12
 * triangles, each face's uv in [0,1]^2 (mitsuba3 src/shapes/cube.cpp). */
static rsw_status cube_create(loader *ld, node *n, object **out) {
  shape *s = shape_alloc(GEOM_MESH);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  rsw_status st = shape_read_common(ld, n, s, true);
  if (!st && mesh_alloc(&s->mesh, 24, 12, true, true))
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
  return finish(ld, n, s, out);
}

/* sphere: unit sphere at the origin, normals outward; `center` and `radius`
 * fold into to_world as to_world * T(center) * S(radius)
 * (mitsuba3 src/shapes/sphere.cpp). */
static rsw_status sphere_create(loader *ld, node *n, object **out) {
  shape *s = shape_alloc(GEOM_SPHERE);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  vec3 c;
  double r;
  rsw_status st = shape_read_common(ld, n, s, false);
  if (!st) st = ld_vec3(ld, n, "center", v3(0, 0, 0), &c, NULL);
  if (!st) st = ld_float(ld, n, "radius", 1.0, &r);
  if (!st && !(r > 0)) st = ld_fail(ld, n, "radius", RSW_ERR_RANGE, "radius must be > 0 (got %g)", r);
  if (!st && !(r >= RSW_TRACE_MIN_SCALE && r <= RSW_TRACE_MAX_SCALE))
    st = ld_fail(ld, n, "radius", RSW_ERR_RANGE,
                 "radius %g is outside [%g, %g], what float32 tracing can represent", r, RSW_TRACE_MIN_SCALE,
                 RSW_TRACE_MAX_SCALE);
  if (!st && !(v3_max_abs(c) <= RSW_TRACE_MAX_COORD))
    st = ld_fail(ld, n, "center", RSW_ERR_RANGE,
                 "center coordinate %g exceeds %g, the largest float32 tracing accepts", v3_max_abs(c),
                 RSW_TRACE_MAX_COORD);
  if (st) {
    free(s);
    return st;
  }
  xform t = xf_translate(c), sc = xf_scale(v3(r, r, r));
  xform ts = xf_mul(&t, &sc);
  s->to_world = xf_mul(&s->to_world, &ts);
  return finish(ld, n, s, out);
}

/* disk: unit disk at the origin in z = 0, normal +z
 * (mitsuba3 src/shapes/disk.cpp). */
static rsw_status disk_create(loader *ld, node *n, object **out) {
  shape *s = shape_alloc(GEOM_DISK);
  if (!s) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  rsw_status st = shape_read_common(ld, n, s, false);
  if (st) {
    free(s);
    return st;
  }
  return finish(ld, n, s, out);
}

const plugin plugin_rectangle = {.name = "rectangle",
                                 .cls = CLS_SHAPE,
                                 .create = rectangle_create,
                                 .destroy = shape_destroy,
                                 .traverse = shape_traverse,
                                 .parameters_changed = shape_parameters_changed};
const plugin plugin_cube = {.name = "cube",
                            .cls = CLS_SHAPE,
                            .create = cube_create,
                            .destroy = shape_destroy,
                            .traverse = shape_traverse,
                            .parameters_changed = shape_parameters_changed};
const plugin plugin_sphere = {.name = "sphere",
                              .cls = CLS_SHAPE,
                              .create = sphere_create,
                              .destroy = shape_destroy,
                              .traverse = shape_traverse,
                              .parameters_changed = shape_parameters_changed};
const plugin plugin_disk = {.name = "disk",
                            .cls = CLS_SHAPE,
                            .create = disk_create,
                            .destroy = shape_destroy,
                            .traverse = shape_traverse,
                            .parameters_changed = shape_parameters_changed};
