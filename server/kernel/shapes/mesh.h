/* Triangle meshes' surface data and position sampling, inline: shape.c
 * takes this path without an indirect call (the common case), mesh.c puts
 * the same functions in shape_ops_mesh. */
#ifndef RSW_SHAPES_MESH_H
#define RSW_SHAPES_MESH_H

#include "../accel_hit.h"
#include "shape.h"

static inline vec3 mesh_vertex(const mesh *m, uint32_t i) {
  const float *p = &m->pos[3 * (size_t)i];
  return v3(p[0], p[1], p[2]);
}

/* The world geometric normal of face (p0, p1, p2) under to_world, and
 * its world dp/du from the uv differences (du0, dv0), (du1, dv1) with
 * determinant det != 0: what a hit computes and the face cache holds. */
static inline vec3 mesh_face_normal(const xform *to_world, vec3 dp0, vec3 dp1) {
  /* Face normal = (p1 - p0) x (p2 - p0), as Mitsuba's Mesh. */
  return v3_norm(xf_normal(to_world, v3_cross(dp0, dp1)));
}
static inline vec3 mesh_face_dpdu(const xform *to_world, vec3 dp0, vec3 dp1, double dv0, double dv1,
                                  double det) {
  return xf_vector(to_world, v3_scale(v3_sub(v3_scale(dp0, dv1), v3_scale(dp1, dv0)), 1.0 / det));
}

/* fc: the face's entry in s->face_cache (valid for to_world == &s->to_world
 * only), or NULL to compute it. sn_raw: NULL, or where an interpolated
 * shading normal is left unnormalised (*sn_raw_set true; *sn_out is then
 * n) for the caller to finish as this code does: sn = v3_norm(*sn_raw),
 * n where !(v3_len2(sn) > 0.5). */
static inline void mesh_fill_inline_raw(const shape *s, const xform *to_world, const ray3 *r,
                                        const accel_hit *h, surface_interaction *si, vec3 *n_out,
                                        vec3 *sn_out, vec3 *dpdu, const double *fc, vec3 *sn_raw,
                                        bool *sn_raw_set) {
  const mesh *m = &s->mesh;
  vec3 n, sn;
  if (!m->uv && (!m->nrm || s->face_normals)) {
    /* Nothing to interpolate: the position comes from the ray and the
     * face normal from Embree's hit, which saves fetching three random
     * vertices (a cache miss on large meshes). */
    si->p = v3_fma(r->o, h->t, r->d);
    /* Along the ray, p is off by Embree's error in t (and the ray's own
     * rounding): a few float units of t |d|. */
    si->p_error = 5.0 * RSW_F32_UNIT * h->t * v3_max_abs(r->d);
    n = v3_norm(xf_normal(to_world, h->ng));
    si->uv[0] = h->u;
    si->uv[1] = h->v;
    *n_out = *sn_out = n;
    return;
  }
  const uint32_t *ix = &m->faces[3 * (size_t)h->prim];
  double b1 = h->u, b2 = h->v, b0 = 1.0 - b1 - b2;
  vec3 p0 = mesh_vertex(m, ix[0]), p1 = mesh_vertex(m, ix[1]), p2 = mesh_vertex(m, ix[2]);
  /* Position from barycentrics in object space, then to world: more
   * accurate than o + t d for spawning the next ray. */
  vec3 po = v3_add(v3_add(v3_scale(p0, b0), v3_scale(p1, b1)), v3_scale(p2, b2));
  si->p = xf_point(to_world, po);
  vec3 dp0 = v3_sub(p1, p0), dp1 = v3_sub(p2, p0);
  n = fc ? v3(fc[0], fc[1], fc[2]) : mesh_face_normal(to_world, dp0, dp1);
  if (m->nrm && !s->face_normals) {
    const float *a = &m->nrm[3 * (size_t)ix[0]], *b = &m->nrm[3 * (size_t)ix[1]],
                *c = &m->nrm[3 * (size_t)ix[2]];
    vec3 no = v3(b0 * a[0] + b1 * b[0] + b2 * c[0], b0 * a[1] + b1 * b[1] + b2 * c[1],
                 b0 * a[2] + b1 * b[2] + b2 * c[2]);
    if (sn_raw) {
      *sn_raw = xf_normal(to_world, no);
      *sn_raw_set = true;
      sn = n;
    } else {
      sn = v3_norm(xf_normal(to_world, no));
      if (!(v3_len2(sn) > 0.5)) sn = n;
    }
  } else {
    sn = n;
  }
  if (m->uv) {
    const float *a = &m->uv[2 * (size_t)ix[0]], *b = &m->uv[2 * (size_t)ix[1]],
                *c = &m->uv[2 * (size_t)ix[2]];
    si->uv[0] = b0 * a[0] + b1 * b[0] + b2 * c[0];
    si->uv[1] = b0 * a[1] + b1 * b[1] + b2 * c[1];
    /* dp/du from the uv parameterisation (Mitsuba's Mesh): it orients the
     * shading frame's s axis, which anisotropic BSDFs depend on. */
    double du0 = b[0] - a[0], dv0 = b[1] - a[1], du1 = c[0] - a[0], dv1 = c[1] - a[1];
    double det = du0 * dv1 - dv0 * du1;
    if (det != 0) *dpdu = fc ? v3(fc[3], fc[4], fc[5]) : mesh_face_dpdu(to_world, dp0, dp1, dv0, dv1, det);
  } else {
    si->uv[0] = b1;
    si->uv[1] = b2;
  }
  *n_out = n;
  *sn_out = sn;
}

static inline void mesh_fill_inline(const shape *s, const xform *to_world, const ray3 *r, const accel_hit *h,
                                    surface_interaction *si, vec3 *n_out, vec3 *sn_out, vec3 *dpdu,
                                    const double *fc) {
  mesh_fill_inline_raw(s, to_world, r, h, si, n_out, sn_out, dpdu, fc, NULL, NULL);
}

static inline void mesh_sample_inline(const shape *s, vec2 u, const double *tris, position_sample *ps) {
  const mesh *m = &s->mesh;
  /* Pick a triangle by area (binary search on the cdf), reuse u.x. */
  double target = u.x * s->area;
  uint32_t lo = 0, hi = m->n_faces - 1;
  /* Written for conditional moves: which way a random sample goes is
   * unpredictable, and a mispredicted branch per step costs more than
   * the step. */
  while (lo < hi) {
    uint32_t mid = lo + (hi - lo) / 2;
    bool right = s->tri_cdf[mid] <= target;
    lo = right ? mid + 1 : lo;
    hi = right ? hi : mid;
  }
  uint32_t f = lo;
  double prev = f ? s->tri_cdf[f - 1] : 0.0;
  double w = s->tri_cdf[f] - prev;
  double ux = w > 0 ? (target - prev) / w : 0.5;
  if (ux < 0) ux = 0;
  if (ux >= 1) ux = 0x1.fffffffffffffp-1;
  /* Uniform barycentrics (Mitsuba's square_to_uniform_triangle). */
  double t = sqrt(1.0 - ux);
  double b1 = 1.0 - t, b2 = t * u.y;
  /* The world triangle, precomputed (area lights) or made here by the
   * same code: the same bits either way. */
  double here[SHAPE_TRI_DOUBLES];
  const double *T = tris ? &tris[SHAPE_TRI_DOUBLES * (size_t)f] : here;
  if (!tris) shape_world_triangle(s, f, here);
  vec3 w0 = v3(T[0], T[1], T[2]), e1 = v3(T[3], T[4], T[5]), e2 = v3(T[6], T[7], T[8]);
  ps->p = v3_add(v3_add(w0, v3_scale(e1, b1)), v3_scale(e2, b2));
  ps->n = v3(T[9], T[10], T[11]);
  const uint32_t *ix = &m->faces[3 * (size_t)f];
  if (m->uv) {
    const float *a = &m->uv[2 * (size_t)ix[0]], *b = &m->uv[2 * (size_t)ix[1]],
                *c = &m->uv[2 * (size_t)ix[2]];
    ps->uv[0] = (1 - b1 - b2) * a[0] + b1 * b[0] + b2 * c[0];
    ps->uv[1] = (1 - b1 - b2) * a[1] + b1 * b[1] + b2 * c[1];
  } else {
    ps->uv[0] = b1;
    ps->uv[1] = b2;
  }
}

#endif
