/* Geometry shared by every shape plugin. */
#include "shape.h"

#include <stdlib.h>
#include <string.h>

#include "../accel_hit.h"
#include "../scene/loader.h"
#include "../scene/params.h"
#include "shape_internal.h"

/* ---- common properties ------------------------------------------------------ */

rsw_status shape_read_common(loader *ld, node *n, shape *s, bool mesh_like) {
  rsw_status st = ld_transform(ld, n, "to_world", &s->to_world, NULL);
  if (st) return st;
  st = ld_bool(ld, n, "flip_normals", false, &s->flip_normals);
  if (st) return st;
  object *o;
  /* The media first: a wrong object under `interior` / `exterior` is named
   * as such, not counted as a second nested BSDF or emitter. */
  st = ld_child(ld, n, "interior", CLS_MEDIUM, &o);
  if (st) return st;
  s->interior = (struct medium *)o;
  st = ld_child(ld, n, "exterior", CLS_MEDIUM, &o);
  if (st) return st;
  s->exterior = (struct medium *)o;
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
  if (shape_is_mesh(s)) {
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
  if (!shape_is_mesh(s) || s->mesh.n_verts)
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
  tmp.face_cache = NULL; /* not s's: a finalize of tmp must not touch it */
  tmp.face_cache_n = 0;
  tmp.emitter = NULL;
  /* shape_finalize on a copy without its cdf computes only the area. */
  if (shape_is_mesh(s)) {
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
  /* Mitsuba's Shape::traverse names its media so. */
  if (s->interior) pv_object(v, "interior_medium", (object *)s->interior, NAN, NAN);
  if (s->exterior) pv_object(v, "exterior_medium", (object *)s->exterior, NAN, NAN);
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
    shape_face_cache_refresh(s); /* vertices, faces or uv changed */
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
  free(s->face_cache);
  s->face_cache = NULL;
  s->face_cache_n = 0;
  s->face_cache_frames = false;
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

shape *shape_new(const shape_ops *ops) {
  shape *s = calloc(1, sizeof *s);
  if (s) {
    s->ops = ops;
    s->to_world = xf_identity();
  }
  return s;
}

rsw_status shape_finish(loader *ld, node *n, shape *s, object **out) {
  rsw_status st = shape_finalize(s, ld->err, n->loc);
  if (st) {
    shape_release(s);
    free(s);
    return st;
  }
  *out = &s->base;
  return RSW_OK;
}

void shape_box_world_bounds(const shape *s, const xform *t, vec3 *lo, vec3 *hi) {
  vec3 l, h;
  s->ops->bounds(s, &l, &h);
  for (int c = 0; c < 8; c++)
    shape_box_add(lo, hi, xf_point(t, v3(c & 1 ? h.x : l.x, c & 2 ? h.y : l.y, c & 4 ? h.z : l.z)));
}

rsw_status shape_finalize(shape *s, rsw_err *err, const char *where) {
  if (s->emitter) s->emitter->shape = s;
  rsw_status st = s->ops->finalize(s, err, where);
  if (st || (shape_is_mesh(s) && !s->emitter && !s->sampled)) return st;
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

position_sample shape_sample_position(const shape *s, vec2 u) {
  return shape_sample_position_tris(s, u, NULL);
}

position_sample shape_sample_position_tris(const shape *s, vec2 u, const double *tris) {
  position_sample ps;
  memset(&ps, 0, sizeof ps);
  /* Meshes inline (area lights sample them per shadow ray); the analytic
   * shapes through their table, out of line: their transforms inlined
   * here crowd the mesh path's registers (measured: an area-light sample
   * 37 -> 59 ns). */
  if (shape_is_mesh(s))
    mesh_sample_inline(s, u, tris, &ps);
  else
    s->ops->sample_position(s, u, tris, &ps);
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

bool shape_fill_begin(const shape *s, const xform *to_world, const ray3 *r, const accel_hit *h,
                      surface_interaction *si, vec3 *sn_out, vec3 *tangent_out, vec3 *sn_raw,
                      bool *sn_raw_set) {
  si->t = h->t;
  si->shape = s;
  si->prim = h->prim;
  si->p_error = 0; /* hit_fill_interaction adds Embree's rounding */
  vec3 n, sn, tangent = v3(0, 0, 0);
  if (sn_raw_set) *sn_raw_set = false;
  /* Triangles inline (the common hit), other geometry through its table. */
  if (shape_is_mesh(s)) {
    const double *fc = s->face_cache && to_world == &s->to_world
                           ? &s->face_cache[SHAPE_FACE_DOUBLES * (size_t)h->prim]
                           : NULL;
    mesh_fill_inline_raw(s, to_world, r, h, si, &n, &sn, &tangent, fc, sn_raw, sn_raw_set);
    if (fc && s->face_cache_frames) {
      /* The face's frame, made by shape_face_cache_refresh with
       * shape_frame_from_tangent from these n and dp/du: the same bits,
       * without the square roots and the division. */
      const double *f = &fc[SHAPE_FACE_FRAME];
      si->ng = s->flip_normals ? v3_neg(n) : n;
      si->sh.s = v3(f[0], f[1], f[2]);
      si->sh.t = v3(f[3], f[4], f[5]);
      si->sh.n = v3(f[6], f[7], f[8]);
      si->wi = frame_to_local(&si->sh, v3_neg(v3_norm(r->d)));
      return true;
    }
  } else {
    s->ops->fill(s, to_world, r, h, si, &n, &sn, &tangent);
  }
  if (s->flip_normals) {
    /* v3_norm(-x) is -v3_norm(x) bit for bit: a deferred raw normal may
     * be flipped before it is normalised. */
    n = v3_neg(n);
    sn = v3_neg(sn);
    if (sn_raw_set && *sn_raw_set) *sn_raw = v3_neg(*sn_raw);
  }
  si->ng = n;
  *sn_out = sn;
  *tangent_out = tangent;
  return false;
}

void shape_fill_interaction_xf(const shape *s, const xform *to_world, const ray3 *r, const accel_hit *h,
                               surface_interaction *si) {
  vec3 sn, tangent;
  if (shape_fill_begin(s, to_world, r, h, si, &sn, &tangent, NULL, NULL)) return;
  si->sh = shape_frame_from_tangent(sn, tangent);
  si->wi = frame_to_local(&si->sh, v3_neg(v3_norm(r->d)));
}

/* ---- triangle meshes ------------------------------------------------------------------- */

/* Triangle meshes (rectangle, cube, obj, ply; shape groups and instances
 * carry this table with no faces): Embree intersects them as triangles in
 * object space, under to_world as the instance transform. */

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
