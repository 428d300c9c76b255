/* Triangle meshes from Wavefront OBJ and Stanford PLY files, into the
 * kernel's object-space `mesh` (kernel.h). Used by the obj and ply shape
 * plugins; knows nothing of the scene document.
 *
 * Both loaders read the whole file, fan-triangulate polygons (v0, vi,
 * vi+1), and give per-vertex attributes. Every error names the place:
 * "file:line" for OBJ and ASCII PLY, the byte offset and element index for
 * binary PLY. Bad input is an error, never a crash or a silent default.
 * Limits: at most MESH_MAX_ELEMENTS vertices and triangles; counts that a
 * file declares are checked against the bytes that follow before anything
 * is allocated. */
#ifndef RSW_SHAPES_MESH_IO_H
#define RSW_SHAPES_MESH_IO_H

#include <stdbool.h>

#include "../kernel.h"

/* Most vertices (and most triangles) a loaded mesh may have: 2^31. */
#define MESH_MAX_ELEMENTS ((uint32_t)1 << 31)

/* Load an OBJ file: `v` (x y z [w], w ignored), `vt` (u [v [w]]), `vn`,
 * `f` with v, v/vt, v//vn or v/vt/vn corners, 1-based or negative
 * (relative to the end so far) indices. Corners are deduplicated per
 * (v, vt, vn) triple, so each output vertex has one position, uv and
 * normal. uvs are present if any corner names a vt (others get (0, 0));
 * normals only if every corner names a vn. flip_tex_coords maps v -> 1 - v
 * (Mitsuba's obj default is true). Comments, o, g, s, usemtl, mtllib and
 * other statements (l, p, vp, ...) are ignored.
 * Writes *out only on success (owned: release with mesh_free).
 * Errors: RSW_ERR_FILE (cannot read, or bad content), RSW_ERR_LIMIT,
 * RSW_ERR_NOMEM. Thread-safe. */
rsw_status mesh_load_obj(const char *path, bool flip_tex_coords, mesh *out, rsw_err *err);

/* Load a PLY 1.0 file, ascii or binary_little_endian (binary_big_endian is
 * RSW_ERR_UNSUPPORTED). Element `vertex`: x, y, z (any scalar type),
 * optional nx, ny, nz and u, v / s, t / texture_u, texture_v /
 * texture_s, texture_t. Element `face`: list property vertex_indices or
 * vertex_index (integer count and index types). Other elements and
 * properties, lists included, are skipped.
 * Writes *out only on success (owned: release with mesh_free).
 * Errors: RSW_ERR_FILE, RSW_ERR_UNSUPPORTED, RSW_ERR_LIMIT, RSW_ERR_NOMEM.
 * Thread-safe. */
rsw_status mesh_load_ply(const char *path, mesh *out, rsw_err *err);

/* Free the mesh's arrays and zero it; NULL is a no-op. */
void mesh_free(mesh *m);

#endif
