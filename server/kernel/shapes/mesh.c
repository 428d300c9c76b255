/* Triangle meshes (rectangle, cube, obj, ply; shape groups and instances
 * carry this table with no faces): Embree intersects them as triangles in
 * object space, under to_world as the instance transform. */
#include "mesh.h"

#include <stdlib.h>
#include <string.h>

#include "shape_common.h"

/* The vertices' box; (0, 0, 0) for a mesh without vertices. */
static void mesh_bounds(const shape *s, vec3 *lo, vec3 *hi) {
  vec3 l = v3(INFINITY, INFINITY, INFINITY), h = v3(-INFINITY, -INFINITY, -INFINITY);
  for (uint32_t k = 0; k < s->mesh.n_verts; k++) shape_box_add(&l, &h, mesh_vertex(&s->mesh, k));
  if (!(l.x <= h.x)) l = h = v3(0, 0, 0);
  *lo = l, *hi = h;
}

static void mesh_world_bounds(const shape *s, const xform *t, vec3 *lo, vec3 *hi) {
  for (uint32_t i = 0; i < s->mesh.n_verts; i++) shape_box_add(lo, hi, xf_point(t, mesh_vertex(&s->mesh, i)));
}

static void mesh_fill(const shape *s, const xform *to_world, const ray3 *r, const accel_hit *h,
                      surface_interaction *si, vec3 *n, vec3 *sn, vec3 *dpdu) {
  const double *fc =
      s->face_cache && to_world == &s->to_world ? &s->face_cache[SHAPE_FACE_DOUBLES * (size_t)h->prim] : NULL;
  mesh_fill_inline(s, to_world, r, h, si, n, sn, dpdu, fc);
}

static void mesh_sample(const shape *s, vec2 u, const double *tris, position_sample *ps) {
  mesh_sample_inline(s, u, tris, ps);
}

static rsw_status mesh_finalize(shape *s, rsw_err *err, const char *where) {
  const mesh *m = &s->mesh;
  if (m->n_faces == 0) return rsw_fail(err, RSW_ERR_INVALID, where, "mesh has no faces");
  /* Indices and coordinates are checked whatever happens next: Embree
   * would read out of bounds. */
  uint32_t worst = 0;
  for (size_t i = 0; i < 3 * (size_t)m->n_faces; i++) worst = m->faces[i] > worst ? m->faces[i] : worst;
  if (worst >= m->n_verts)
    return rsw_fail(err, RSW_ERR_INVALID, where, "a face references vertex %u of %u", worst, m->n_verts);
  int bad = 0;
  for (size_t i = 0; i < 3 * (size_t)m->n_verts; i++) bad |= !(fabsf(m->pos[i]) <= 3.0e38f);
  if (bad) return rsw_fail(err, RSW_ERR_INVALID, where, "mesh has a non-finite vertex");
  rsw_status tst = shape_check_traceable(s, &s->to_world, "to_world", err, where);
  if (tst) return tst;
  shape_face_cache_refresh(s);
  if (!s->emitter && !s->sampled) {
    s->area = 0;
    return RSW_OK;
  }
  if (!s->tri_cdf || s->tri_cdf_n != m->n_faces) {
    /* Reused when the face count is unchanged (vertex updates): a fresh
     * buffer would page-fault in on every update. */
    double *cdf = realloc(s->tri_cdf, (size_t)m->n_faces * sizeof(double));
    if (!cdf) return rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory");
    s->tri_cdf = cdf;
    s->tri_cdf_n = m->n_faces;
  }
  double acc = 0, det = xf_abs_det3(&s->to_world);
  for (uint32_t f = 0; f < m->n_faces; f++) {
    const uint32_t *ix = &m->faces[3 * (size_t)f];
    acc += tri_world_area(&s->to_world, det, mesh_vertex(m, ix[0]), mesh_vertex(m, ix[1]),
                          mesh_vertex(m, ix[2]));
    s->tri_cdf[f] = acc;
  }
  s->area = acc;
  return RSW_OK;
}

const shape_ops shape_ops_mesh = {.kind = "mesh",
                                  .bounds = mesh_bounds,
                                  .world_bounds = mesh_world_bounds,
                                  .intersect = NULL, /* Embree's triangles */
                                  .fill = mesh_fill,
                                  .sample_position = mesh_sample,
                                  .finalize = mesh_finalize};

void shape_face_cache_refresh(shape *s) {
  const mesh *m = &s->mesh;
  /* Only meshes whose hits take the interpolating path (uv or vertex
   * normals; the other path reads Embree's normal). */
  bool used = m->uv || (m->nrm && !s->face_normals);
  uint32_t nf = shape_is_mesh(s) && m->faces && used ? m->n_faces : 0;
  if (nf == 0 || nf > SHAPE_FACE_CACHE_MAX) {
    free(s->face_cache);
    s->face_cache = NULL;
    s->face_cache_n = 0;
    s->face_cache_frames = false;
    return;
  }
  if (s->face_cache_n != nf || !s->face_cache) {
    double *c = realloc(s->face_cache, (size_t)nf * SHAPE_FACE_DOUBLES * sizeof(double));
    if (!c) {
      free(s->face_cache);
      s->face_cache = NULL;
      s->face_cache_n = 0;
      s->face_cache_frames = false;
      return;
    }
    s->face_cache = c;
    s->face_cache_n = nf;
  }
  /* The shading normal is the face normal: the whole frame is the face's. */
  bool frames = !(m->nrm && !s->face_normals);
  for (uint32_t f = 0; f < nf; f++) {
    const uint32_t *ix = &m->faces[3 * (size_t)f];
    vec3 p0 = mesh_vertex(m, ix[0]), p1 = mesh_vertex(m, ix[1]), p2 = mesh_vertex(m, ix[2]);
    vec3 dp0 = v3_sub(p1, p0), dp1 = v3_sub(p2, p0);
    vec3 n = mesh_face_normal(&s->to_world, dp0, dp1), t = v3(0, 0, 0);
    if (m->uv) {
      const float *a = &m->uv[2 * (size_t)ix[0]], *b = &m->uv[2 * (size_t)ix[1]],
                  *c = &m->uv[2 * (size_t)ix[2]];
      double du0 = b[0] - a[0], dv0 = b[1] - a[1], du1 = c[0] - a[0], dv1 = c[1] - a[1];
      double det = du0 * dv1 - dv0 * du1;
      if (det != 0) t = mesh_face_dpdu(&s->to_world, dp0, dp1, dv0, dv1, det);
    }
    double *o = &s->face_cache[SHAPE_FACE_DOUBLES * (size_t)f];
    o[0] = n.x, o[1] = n.y, o[2] = n.z, o[3] = t.x, o[4] = t.y, o[5] = t.z;
    /* The frame a hit makes (shape_fill_interaction_xf) when its shading
     * normal is this face normal. */
    frame fr = {v3(0, 0, 0), v3(0, 0, 0), v3(0, 0, 0)};
    if (frames) fr = shape_frame_from_tangent(s->flip_normals ? v3_neg(n) : n, t);
    const double fv[9] = {fr.s.x, fr.s.y, fr.s.z, fr.t.x, fr.t.y, fr.t.z, fr.n.x, fr.n.y, fr.n.z};
    memcpy(&o[SHAPE_FACE_FRAME], fv, sizeof fv);
  }
  s->face_cache_frames = frames;
}

void shape_world_triangle(const shape *s, uint32_t f, double out[SHAPE_TRI_DOUBLES]) {
  const mesh *m = &s->mesh;
  const uint32_t *ix = &m->faces[3 * (size_t)f];
  vec3 w0 = xf_point(&s->to_world, mesh_vertex(m, ix[0]));
  vec3 e1 = v3_sub(xf_point(&s->to_world, mesh_vertex(m, ix[1])), w0);
  vec3 e2 = v3_sub(xf_point(&s->to_world, mesh_vertex(m, ix[2])), w0);
  vec3 n = v3_norm(v3_cross(e1, e2));
  const double v[SHAPE_TRI_DOUBLES] = {w0.x, w0.y, w0.z, e1.x, e1.y, e1.z, e2.x, e2.y, e2.z, n.x, n.y, n.z};
  memcpy(out, v, sizeof v);
}

void shape_world_tris_refresh(const shape *s, double **tris, uint32_t *n) {
  uint32_t nf = s && shape_is_mesh(s) && s->tri_cdf ? s->mesh.n_faces : 0;
  if (nf == 0 || nf > SHAPE_TRIS_MAX) {
    free(*tris);
    *tris = NULL;
    *n = 0;
    return;
  }
  if (*n != nf || !*tris) {
    double *t = realloc(*tris, (size_t)nf * SHAPE_TRI_DOUBLES * sizeof(double));
    if (!t) {
      free(*tris);
      *tris = NULL;
      *n = 0;
      return;
    }
    *tris = t;
    *n = nf;
  }
  for (uint32_t f = 0; f < nf; f++) shape_world_triangle(s, f, &(*tris)[SHAPE_TRI_DOUBLES * (size_t)f]);
}

rsw_status shape_mesh_alloc(mesh *m, uint32_t nv, uint32_t nf, bool normals, bool uvs) {
  m->n_verts = nv;
  m->n_faces = nf;
  m->pos = malloc(3 * (size_t)nv * sizeof(float));
  m->faces = malloc(3 * (size_t)nf * sizeof(uint32_t));
  m->nrm = normals ? malloc(3 * (size_t)nv * sizeof(float)) : NULL;
  m->uv = uvs ? malloc(2 * (size_t)nv * sizeof(float)) : NULL;
  if (!m->pos || !m->faces || (normals && !m->nrm) || (uvs && !m->uv)) return RSW_ERR_NOMEM;
  return RSW_OK;
}
