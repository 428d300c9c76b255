/* Geometry shared by every shape plugin. */
#include "shape.h"

#include <stdlib.h>
#include <string.h>

#include "../accel.h"
#include "../scene/loader.h"
#include "../scene/params.h"
#include "shape_common.h"

static inline vec3 mesh_vertex(const mesh *m, uint32_t i);

/* ---- common properties ------------------------------------------------------ */

rsw_status shape_read_common(loader *ld, node *n, shape *s, bool mesh_like) {
  rsw_status st = ld_transform(ld, n, "to_world", &s->to_world, NULL);
  if (st) return st;
  st = ld_bool(ld, n, "flip_normals", false, &s->flip_normals);
  if (st) return st;
  object *o;
  st = ld_child(ld, n, NULL, CLS_EMITTER, &o);
  if (st) return st;
  s->emitter = (emitter *)o;
  if (s->emitter && !(s->emitter->flags & EMITTER_SURFACE))
    return ld_fail(ld, n, NULL, RSW_ERR_INVALID, "%s '%s': only an area emitter can be nested in a shape",
                   n->type, n->id);
  st = ld_child(ld, n, NULL, CLS_BSDF, &o);
  if (st) return st;
  if (!o) {
    /* Mitsuba's default: a diffuse BSDF (reflectance 0.5). */
    st = ld_create_default(ld, "diffuse", CLS_BSDF, "diffuse", &o);
    if (st) return st;
  }
  s->bsdf = (bsdf *)o;
  s->mesh_params = mesh_like;
  return ld_float_range(ld, n, "silhouette_sampling_weight", 1.0, 0.0, INFINITY,
                        &s->silhouette_sampling_weight);
}

rsw_status shape_check_traceable(const shape *s, const xform *t, const char *what, rsw_err *err,
                                 const char *where) {
  char msg[512];
  if (!xf_traceable(t->m, what, msg, sizeof msg)) return rsw_fail(err, RSW_ERR_RANGE, where, "%s", msg);
  const double L = RSW_TRACE_MAX_COORD;
  vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
  if (s->geom == GEOM_MESH) {
    const mesh *m = &s->mesh;
    float ext = 0;
    for (size_t i = 0; i < 3 * (size_t)m->n_verts; i++) ext = fmaxf(ext, fabsf(m->pos[i]));
    if (!(ext <= L))
      return rsw_fail(err, RSW_ERR_RANGE, where,
                      "%s: a vertex coordinate of %g exceeds %g, the largest float32 tracing accepts", what,
                      (double)ext, L);
    for (uint32_t k = 0; k < m->n_verts; k++) {
      vec3 w = xf_point(t, mesh_vertex(m, k));
      lo = v3(fmin(lo.x, w.x), fmin(lo.y, w.y), fmin(lo.z, w.z));
      hi = v3(fmax(hi.x, w.x), fmax(hi.y, w.y), fmax(hi.z, w.z));
    }
  } else {
    /* The unit sphere, disk or tube: its box [-1,1]^2 x [-1,1] bounds them all. */
    for (int c = 0; c < 8; c++) {
      vec3 w = xf_point(t, v3(c & 1 ? 1 : -1, c & 2 ? 1 : -1, c & 4 ? 1 : -1));
      lo = v3(fmin(lo.x, w.x), fmin(lo.y, w.y), fmin(lo.z, w.z));
      hi = v3(fmax(hi.x, w.x), fmax(hi.y, w.y), fmax(hi.z, w.z));
    }
  }
  double w = fmax(v3_max_abs(lo), v3_max_abs(hi));
  if (s->geom != GEOM_MESH || s->mesh.n_verts)
    if (!(w <= L))
      return rsw_fail(err, RSW_ERR_RANGE, where,
                      "%s: the shape reaches a world coordinate of %g, beyond %g, the largest float32 "
                      "tracing accepts",
                      what, w, L);
  return RSW_OK;
}

/* What a to_world must satisfy for this shape (as checked at load). */
static rsw_status shape_check_transform(const object *o, const xform *t, const char *key, rsw_err *err) {
  const shape *s = (const shape *)o;
  rsw_status tst = shape_check_traceable(s, t, key, err, key);
  if (tst) return tst;
  shape tmp = *s;
  tmp.to_world = *t;
  tmp.tri_cdf = NULL;
  tmp.tri_cdf_n = 0;
  tmp.tri_cdf_next = NULL;
  tmp.emitter = NULL;
  /* shape_finalize on a copy without its cdf computes only the area. */
  if (s->geom == GEOM_MESH) {
    if (!s->emitter && !s->sampled) return RSW_OK; /* area not needed */
    double area = 0, det = xf_abs_det3(t);
    const mesh *m = &s->mesh;
    for (uint32_t f = 0; f < m->n_faces; f++) {
      const uint32_t *ix = &m->faces[3 * (size_t)f];
      area += tri_world_area(t, det, mesh_vertex(m, ix[0]), mesh_vertex(m, ix[1]), mesh_vertex(m, ix[2]));
    }
    if (!(area > 0) || !isfinite(area))
      return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': the shape would have zero or non-finite area", key);
    return RSW_OK;
  }
  rsw_err local = {0};
  if (shape_finalize(&tmp, &local, key)) return rsw_fail(err, local.code, key, "'%s': %s", key, local.msg);
  return RSW_OK;
}

void shape_traverse(object *o, param_visitor *v) {
  shape *s = (shape *)o;
  /* Every shape, meshes included, exposes to_world: it is the Embree
   * instance transform. Mitsuba bakes it into mesh vertices and does not
   * expose it on meshes; this is a deliberate difference, and
   * vertex_positions are in object space (before to_world). */
  pv_transform(v, "to_world", &s->to_world, UPDATE_GEOMETRIC, shape_check_transform);
  pv_float(v, "silhouette_sampling_weight", &s->silhouette_sampling_weight, UPDATE_NONE, 0, INFINITY);
  if (s->mesh_params) {
    pv_mesh_buffer(v, "faces", s);
    pv_mesh_buffer(v, "vertex_positions", s);
    if (s->mesh.nrm) pv_mesh_buffer(v, "vertex_normals", s);
    if (s->mesh.uv) pv_mesh_buffer(v, "vertex_texcoords", s);
  }
  pv_object(v, "bsdf", &s->bsdf->base, NAN, NAN);
  if (s->emitter) pv_object(v, "emitter", &s->emitter->base, NAN, NAN);
}

void shape_parameters_changed(object *o) {
  shape *s = (shape *)o;
  if (s->cdf_staged) {
    /* The update's validation already computed the new area cdf (the same
     * arithmetic as shape_finalize): swap it in. */
    double *t = s->tri_cdf;
    uint32_t tn = s->tri_cdf_n;
    s->tri_cdf = s->tri_cdf_next;
    s->tri_cdf_n = s->tri_cdf_next_n;
    s->tri_cdf_next = t;
    s->tri_cdf_next_n = tn;
    s->area = s->area_next;
    s->cdf_staged = false;
    if (s->emitter) s->emitter->shape = s;
    return;
  }
  /* Validated before the update was applied: this cannot fail. */
  shape_finalize(s, NULL, "");
}

void shape_release(shape *s) {
  free(s->mesh.pos);
  free(s->mesh.nrm);
  free(s->mesh.uv);
  free(s->mesh.faces);
  free(s->tri_cdf);
  free(s->tri_cdf_next);
  memset(&s->mesh, 0, sizeof s->mesh);
  s->tri_cdf = NULL;
  s->tri_cdf_n = 0;
  s->tri_cdf_next = NULL;
  s->tri_cdf_next_n = 0;
}

void shape_destroy(object *o) {
  shape *s = (shape *)o;
  shape_release(s);
  free(s);
}

static inline vec3 mesh_vertex(const mesh *m, uint32_t i) {
  const float *p = &m->pos[3 * (size_t)i];
  return v3(p[0], p[1], p[2]);
}

rsw_status shape_finalize(shape *s, rsw_err *err, const char *where) {
  if (s->emitter) s->emitter->shape = s;
  switch (s->geom) {
  case GEOM_MESH: {
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
    break;
  }
  case GEOM_SPHERE: {
    rsw_status tst = shape_check_traceable(s, &s->to_world, "to_world", err, where);
    if (tst) return tst;
    double r;
    if (!xf_is_similarity(&s->to_world, &r))
      return rsw_fail(err, RSW_ERR_INVALID, where,
                      "sphere: to_world must be a rotation, uniform scale and translation (no shear or "
                      "non-uniform scale)");
    s->area = 4.0 * RSW_PI * r * r;
    break;
  }
  case GEOM_DISK: {
    rsw_status tst = shape_check_traceable(s, &s->to_world, "to_world", err, where);
    if (tst) return tst;
    /* Area of the image of the unit disk: pi |ex x ey|, exact for any
     * linear map that keeps it an ellipse. Mitsuba rejects non-uniform
     * scale within the plane only through its sampling; we accept ellipses
     * for intersection but require a similarity within the plane so that
     * uniform sampling stays uniform. */
    vec3 ex = xf_vector(&s->to_world, v3(1, 0, 0));
    vec3 ey = xf_vector(&s->to_world, v3(0, 1, 0));
    double lx = v3_len(ex), ly = v3_len(ey);
    if (!(lx > 0) || !(ly > 0) || fabs(lx - ly) > 1e-6 * (lx + ly) || fabs(v3_dot(ex, ey)) > 1e-6 * lx * ly)
      return rsw_fail(err, RSW_ERR_INVALID, where,
                      "disk: to_world must not shear or scale non-uniformly within the disk's plane");
    s->area = RSW_PI * v3_len(v3_cross(ex, ey));
    break;
  }
  case GEOM_CYLINDER: {
    rsw_status tst = shape_check_traceable(s, &s->to_world, "to_world", err, where);
    if (tst) return tst;
    /* Uniform (phi, z) sampling is uniform in area only on a circular,
     * right tube: to_world's x and y columns of equal length, all three
     * orthogonal (Mitsuba warns and drops the shear; we refuse it). */
    vec3 ex = xf_vector(&s->to_world, v3(1, 0, 0));
    vec3 ey = xf_vector(&s->to_world, v3(0, 1, 0));
    vec3 ez = xf_vector(&s->to_world, v3(0, 0, 1));
    double lx = v3_len(ex), ly = v3_len(ey), lz = v3_len(ez);
    if (!(lx > 0) || !(ly > 0) || !(lz > 0) || fabs(lx - ly) > 1e-6 * (lx + ly) ||
        fabs(v3_dot(ex, ey)) > 1e-6 * lx * ly || fabs(v3_dot(ex, ez)) > 1e-6 * lx * lz ||
        fabs(v3_dot(ey, ez)) > 1e-6 * ly * lz)
      return rsw_fail(err, RSW_ERR_INVALID, where,
                      "cylinder: to_world must keep the tube circular and right (no shear, the same "
                      "scale across the axis)");
    s->area = 2.0 * RSW_PI * 0.5 * (lx + ly) * lz;
    break;
  }
  }
  if (!(s->area > 0) || !isfinite(s->area))
    return rsw_fail(err, RSW_ERR_INVALID, where, "%s has zero or non-finite area, but is sampled (%s)",
                    s->base.id ? s->base.id : "shape", s->emitter ? "an area emitter" : "a sensor target");
  return RSW_OK;
}

rsw_status shape_enable_sampling(shape *s, rsw_err *err, const char *where) {
  if (s->sampled) return RSW_OK;
  s->sampled = true;
  return shape_finalize(s, err, where);
}

/* ---- sampling ---------------------------------------------------------------- */

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
  uint32_t nf = s && s->geom == GEOM_MESH && s->tri_cdf ? s->mesh.n_faces : 0;
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

position_sample shape_sample_position(const shape *s, vec2 u) {
  return shape_sample_position_tris(s, u, NULL);
}

/* The analytic shapes, out of line: their transforms inlined into the
 * mesh path crowd its registers (measured: an area-light sample 37 -> 59
 * ns). */
__attribute__((noinline)) static void sample_analytic(const shape *s, vec2 u, position_sample *out) {
  position_sample ps = *out;
  switch (s->geom) {
  case GEOM_SPHERE: {
    vec3 d = warp_square_to_uniform_sphere(u);
    ps.p = xf_point(&s->to_world, d);
    ps.n = v3_norm(xf_normal(&s->to_world, d));
    ps.uv[0] = u.x;
    ps.uv[1] = u.y;
    break;
  }
  case GEOM_CYLINDER: {
    double phi = 2.0 * RSW_PI * u.y;
    double c = cos(phi), sn = sin(phi);
    ps.p = xf_point(&s->to_world, v3(c, sn, u.x));
    ps.n = v3_norm(xf_normal(&s->to_world, v3(c, sn, 0)));
    ps.uv[0] = u.y;
    ps.uv[1] = u.x;
    break;
  }
  case GEOM_DISK: {
    vec2 q = warp_square_to_disk_concentric(u);
    ps.p = xf_point(&s->to_world, v3(q.x, q.y, 0));
    ps.n = v3_norm(xf_normal(&s->to_world, v3(0, 0, 1)));
    ps.uv[0] = u.x;
    ps.uv[1] = u.y;
    break;
  }
  default: break;
  }
  *out = ps;
}

position_sample shape_sample_position_tris(const shape *s, vec2 u, const double *tris) {
  position_sample ps;
  memset(&ps, 0, sizeof ps);
  switch (s->geom) {
  case GEOM_MESH: {
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
    ps.p = v3_add(v3_add(w0, v3_scale(e1, b1)), v3_scale(e2, b2));
    ps.n = v3(T[9], T[10], T[11]);
    const uint32_t *ix = &m->faces[3 * (size_t)f];
    if (m->uv) {
      const float *a = &m->uv[2 * (size_t)ix[0]], *b = &m->uv[2 * (size_t)ix[1]],
                  *c = &m->uv[2 * (size_t)ix[2]];
      ps.uv[0] = (1 - b1 - b2) * a[0] + b1 * b[0] + b2 * c[0];
      ps.uv[1] = (1 - b1 - b2) * a[1] + b1 * b[1] + b2 * c[1];
    } else {
      ps.uv[0] = b1;
      ps.uv[1] = b2;
    }
    break;
  }
  default: sample_analytic(s, u, &ps); break;
  }
  if (s->flip_normals) ps.n = v3_neg(ps.n);
  ps.pdf = 1.0 / s->area;
  return ps;
}

double shape_pdf_position(const shape *s) {
  return 1.0 / s->area;
}

/* ---- hit -> interaction --------------------------------------------------------- */

void shape_fill_interaction(const shape *s, const ray3 *r, const accel_hit *h, surface_interaction *si) {
  shape_fill_interaction_xf(s, &s->to_world, r, h, si);
}

void shape_fill_interaction_xf(const shape *s, const xform *to_world, const ray3 *r, const accel_hit *h,
                               surface_interaction *si) {
  si->t = h->t;
  si->shape = s;
  si->prim = h->prim;
  si->p_error = 0; /* hit_fill_interaction adds Embree's rounding */
  vec3 n, sn, tangent = v3(0, 0, 0);
  switch (s->geom) {
  case GEOM_MESH: {
    const mesh *m = &s->mesh;
    if (!m->uv && (!m->nrm || s->face_normals)) {
      /* Nothing to interpolate: the position comes from the ray and the
       * face normal from Embree's hit, which saves fetching three random
       * vertices (a cache miss on large meshes). */
      si->p = v3_fma(r->o, h->t, r->d);
      /* Along the ray, p is off by Embree's error in t (and the ray's own
       * rounding): a few float units of t |d|. */
      si->p_error = 5.0 * RSW_F32_UNIT * h->t * v3_max_abs(r->d);
      n = sn = v3_norm(xf_normal(to_world, h->ng));
      si->uv[0] = h->u;
      si->uv[1] = h->v;
      break;
    }
    const uint32_t *ix = &m->faces[3 * (size_t)h->prim];
    double b1 = h->u, b2 = h->v, b0 = 1.0 - b1 - b2;
    vec3 p0 = mesh_vertex(m, ix[0]), p1 = mesh_vertex(m, ix[1]), p2 = mesh_vertex(m, ix[2]);
    /* Position from barycentrics in object space, then to world: more
     * accurate than o + t d for spawning the next ray. */
    vec3 po = v3_add(v3_add(v3_scale(p0, b0), v3_scale(p1, b1)), v3_scale(p2, b2));
    si->p = xf_point(to_world, po);
    /* Face normal = (p1 - p0) x (p2 - p0), as Mitsuba's Mesh. */
    n = v3_norm(xf_normal(to_world, v3_cross(v3_sub(p1, p0), v3_sub(p2, p0))));
    if (m->nrm && !s->face_normals) {
      const float *a = &m->nrm[3 * (size_t)ix[0]], *b = &m->nrm[3 * (size_t)ix[1]],
                  *c = &m->nrm[3 * (size_t)ix[2]];
      vec3 no = v3(b0 * a[0] + b1 * b[0] + b2 * c[0], b0 * a[1] + b1 * b[1] + b2 * c[1],
                   b0 * a[2] + b1 * b[2] + b2 * c[2]);
      sn = v3_norm(xf_normal(to_world, no));
      if (!(v3_len2(sn) > 0.5)) sn = n;
    } else {
      sn = n;
    }
    tangent = v3(0, 0, 0);
    if (m->uv) {
      const float *a = &m->uv[2 * (size_t)ix[0]], *b = &m->uv[2 * (size_t)ix[1]],
                  *c = &m->uv[2 * (size_t)ix[2]];
      si->uv[0] = b0 * a[0] + b1 * b[0] + b2 * c[0];
      si->uv[1] = b0 * a[1] + b1 * b[1] + b2 * c[1];
      /* dp/du from the uv parameterisation (Mitsuba's Mesh): it orients the
       * shading frame's s axis, which anisotropic BSDFs depend on. */
      double du0 = b[0] - a[0], dv0 = b[1] - a[1], du1 = c[0] - a[0], dv1 = c[1] - a[1];
      double det = du0 * dv1 - dv0 * du1;
      if (det != 0) {
        vec3 dp0 = v3_sub(p1, p0), dp1 = v3_sub(p2, p0);
        tangent = xf_vector(to_world, v3_scale(v3_sub(v3_scale(dp0, dv1), v3_scale(dp1, dv0)), 1.0 / det));
      }
    } else {
      si->uv[0] = b1;
      si->uv[1] = b2;
    }
    break;
  }
  case GEOM_SPHERE: {
    /* Project the hit onto the unit sphere in object space (removes the
     * float error of the intersection). uv = (phi / 2pi, theta / pi) as
     * Mitsuba's sphere. */
    vec3 pw = v3_fma(r->o, h->t, r->d);
    vec3 po = v3_norm(xf_inv_point(to_world, pw));
    si->p = xf_point(to_world, po);
    n = sn = v3_norm(xf_normal(to_world, po));
    double phi = atan2(po.y, po.x);
    if (phi < 0) phi += 2 * RSW_PI;
    si->uv[0] = phi * RSW_INV_2PI;
    si->uv[1] = acos(fmax(-1.0, fmin(1.0, po.z))) * RSW_INV_PI;
    tangent = xf_vector(to_world, v3(-po.y, po.x, 0));
    break;
  }
  case GEOM_CYLINDER: {
    /* Back onto the unit tube in object space (removes the float error of
     * the intersection, like Mitsuba's normal shift). uv = (phi / 2pi, z)
     * and dp/du along (-y, x, 0), as Mitsuba's cylinder. */
    vec3 pw = v3_fma(r->o, h->t, r->d);
    vec3 po = xf_inv_point(to_world, pw);
    double rr = sqrt(po.x * po.x + po.y * po.y);
    if (rr > 0)
      po.x /= rr, po.y /= rr;
    else
      po.x = 1, po.y = 0;
    po.z = fmin(1.0, fmax(0.0, po.z));
    si->p = xf_point(to_world, po);
    n = sn = v3_norm(xf_normal(to_world, v3(po.x, po.y, 0)));
    double phi = atan2(po.y, po.x);
    if (phi < 0) phi += 2 * RSW_PI;
    si->uv[0] = phi * RSW_INV_2PI;
    si->uv[1] = po.z;
    tangent = xf_vector(to_world, v3(-po.y, po.x, 0));
    break;
  }
  case GEOM_DISK:
  default: {
    vec3 pw = v3_fma(r->o, h->t, r->d);
    vec3 po = xf_inv_point(to_world, pw);
    po.z = 0;
    tangent = v3(0, 0, 0);
    si->p = xf_point(to_world, po);
    n = sn = v3_norm(xf_normal(to_world, v3(0, 0, 1)));
    /* uv = (r, phi / 2pi) as Mitsuba's disk. */
    double phi = atan2(po.y, po.x);
    if (phi < 0) phi += 2 * RSW_PI;
    si->uv[0] = sqrt(po.x * po.x + po.y * po.y);
    si->uv[1] = phi * RSW_INV_2PI;
    break;
  }
  }
  if (s->flip_normals) {
    n = v3_neg(n);
    sn = v3_neg(sn);
  }
  si->ng = n;
  /* Shading frame: s along dp/du made orthogonal to the normal when
   * available, else Mitsuba's coordinate_system(n). */
  vec3 ts = v3_sub(tangent, v3_scale(sn, v3_dot(sn, tangent)));
  double tl = v3_len(ts);
  if (tl > 1e-9 * (v3_len(tangent) + 1e-300)) {
    si->sh.n = sn;
    si->sh.s = v3_scale(ts, 1.0 / tl);
    si->sh.t = v3_cross(sn, si->sh.s);
  } else {
    si->sh = frame_from_normal(sn);
  }
  si->wi = frame_to_local(&si->sh, v3_neg(v3_norm(r->d)));
}
