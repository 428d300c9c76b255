/* Geometry services every shape offers, whatever its plugin: the hit
 * record -> surface interaction, uniform position sampling, area.
 * Shape plugins only differ in how they build the object (mesh from a file,
 * two-triangle rectangle, analytic sphere/disk); the rest is here. */
#ifndef RSW_SHAPES_SHAPE_H
#define RSW_SHAPES_SHAPE_H

#include "../accel_hit.h"
#include "../kernel.h"

/* A sampled point on a shape's surface. */
typedef struct position_sample {
  vec3 p; /* world */
  vec3 n; /* unit world normal (after flip_normals) */
  double uv[2];
  double pdf; /* area density, 1/area for uniform sampling */
} position_sample;

/* ---- one interface per kind of geometry -------------------------------------
 * Each kind of geometry has one table: triangle meshes (rectangle, cube,
 * obj, ply) in shape.c beside what every shape shares (its inline code
 * below), sphere.c, disk.c, cylinder.c. accel.c
 * and the shading code go through the table and never ask which kind a
 * shape is; a new kind of geometry is a new file with its table and its
 * plugin (and the plugin's line in scene/registry.c). */
struct accel_hit;
typedef struct shape_ops {
  const char *kind; /* "mesh", "sphere", "disk", "cylinder" */
  /* Object-space bounds of the geometry, exact: a flat shape has lo = hi
   * on its normal axis (accel.c pads it for Embree). */
  void (*bounds)(const shape *s, vec3 *lo, vec3 *hi);
  /* Widen *lo, *hi by the geometry's bounds under to_world. */
  void (*world_bounds)(const shape *s, const xform *to_world, vec3 *lo, vec3 *hi);
  /* Analytic shapes: the nearest t in (tnear, tfar) where the object-space
   * ray o + t d (d not normalised) meets the surface, and the object-space
   * geometric normal there (not normalised); false if none. Exact in
   * double precision (Embree's user-geometry callbacks call it). NULL for
   * triangle meshes, which Embree intersects itself. */
  bool (*intersect)(const shape *s, const double o[3], const double d[3], double tnear, double tfar,
                    double *t, double n[3]);
  /* Surface data of hit h on ray r, the shape placed by to_world: si->p
   * (and si->p_error beyond 0 when p comes from the ray), si->uv, the unit
   * geometric and shading normals *n, *sn and dp/du *dpdu (world space,
   * before flip_normals; *dpdu is (0, 0, 0) on entry and stays so when the
   * shape has none). */
  void (*fill)(const shape *s, const xform *to_world, const ray3 *r, const struct accel_hit *h,
               surface_interaction *si, vec3 *n, vec3 *sn, vec3 *dpdu);
  /* A uniform position sample in world area measure: ps->p, ps->n (unit,
   * before flip_normals), ps->uv. tris: a mesh's world triangles
   * (shape_sample_position_tris) or NULL. The pdf is 1 / s->area. */
  void (*sample_position)(const shape *s, vec2 u, const double *tris, position_sample *ps);
  /* Check the geometry under s->to_world and compute s->area (a mesh: its
   * area cdf, when sampled). shape_finalize() calls it. */
  rsw_status (*finalize)(shape *s, rsw_err *err, const char *where);
} shape_ops;

extern const shape_ops shape_ops_mesh, shape_ops_sphere, shape_ops_disk, shape_ops_cylinder;

/* A triangle mesh (Embree triangles; shape groups and instances carry the
 * mesh table with no faces). */
static inline bool shape_is_mesh(const shape *s) {
  return s->ops == &shape_ops_mesh;
}

/* Widen *lo, *hi by the eight corners of s's object bounds under t: the
 * world_bounds of every analytic shape but the cylinder. */
void shape_box_world_bounds(const shape *s, const xform *t, vec3 *lo, vec3 *hi);

/* Uniformly sample a point on the shape (world-space area measure):
 * rectangle: to_world (2u.x-1, 2u.y-1, 0); disk: concentric disk;
 * sphere: uniform sphere; cylinder: (cos 2pi u.y, sin 2pi u.y, u.x);
 * mesh: triangle by area then uniform barycentric. */
position_sample shape_sample_position(const shape *s, vec2 u);

/* A mesh's triangle f in world space, as sampling uses it: the first
 * vertex w0 = to_world p0, the edges w1 - w0 and w2 - w0, and the unit
 * normal normalize((w1 - w0) x (w2 - w0)) (before flip_normals), in this
 * order, 3 doubles each. */
#define SHAPE_TRI_DOUBLES 12
void shape_world_triangle(const shape *s, uint32_t f, double out[SHAPE_TRI_DOUBLES]);
/* shape_sample_position() given a mesh's world triangles (n_faces *
 * SHAPE_TRI_DOUBLES doubles from shape_world_triangle(), borrowed; NULL:
 * made as needed). The result is the same, bit for bit, with or without:
 * precomputing them per update saves four transforms and a normalisation
 * per sample. */
position_sample shape_sample_position_tris(const shape *s, vec2 u, const double *tris);
/* Refresh a cache of s's world triangles for shape_sample_position_tris():
 * *tris (owned by the caller, realloc'ed; free() it) and *n, its face
 * count. For a sampled mesh of at most SHAPE_TRIS_MAX faces it is
 * (re)computed; otherwise, or when out of memory, it is freed and left
 * NULL (sampling then makes each triangle itself: the same values). Call
 * it whenever s's to_world or vertices may have changed (the set_scene of
 * emitters and sensors runs after every load and geometric update). */
#define SHAPE_TRIS_MAX (1u << 16) /* 6 MiB of triangles at most */
void shape_world_tris_refresh(const shape *s, double **tris, uint32_t *n);
/* *tris when it was made for s as it is now (face count), else NULL. */
static inline const double *shape_world_tris_for(const shape *s, const double *tris, uint32_t n) {
  return tris && shape_is_mesh(s) && n == s->mesh.n_faces ? tris : NULL;
}
/* Per-face world data of small meshes (shape.face_cache): the geometric
 * normal and dp/du (6 doubles), then, for meshes whose shading normal is
 * the face normal (no vertex normals, or face_normals), the hit's whole
 * shading frame s, t, n after flip_normals (9 doubles; zeros otherwise):
 * SHAPE_FACE_DOUBLES doubles (120 bytes) a face, so only up to this many
 * faces (rectangles, cubes, small meshes: the walls and lights of a
 * room). Each value is computed by the same code a hit runs
 * (shape_frame_from_tangent), so a hit reads the same bits. */
#define SHAPE_FACE_CACHE_MAX (1u << 16)
#define SHAPE_FACE_DOUBLES   15
#define SHAPE_FACE_FRAME     6 /* offset of the frame in an entry */
/* (Re)compute s's face cache, or free it (too large, out of memory, not a
 * mesh): fills then compute the same values per hit. */
void shape_face_cache_refresh(shape *s);
/* The shading frame of a hit with unit shading normal sn and world dp/du
 * `tangent` ((0, 0, 0): none): s along dp/du made orthogonal to sn when
 * available, else Mitsuba's coordinate_system(sn). */
static inline frame shape_frame_from_tangent(vec3 sn, vec3 tangent) {
  /* No dp/du (most meshes, disks): the test below would fail on a zero
   * vector anyway; skip its two square roots. */
  if (tangent.x == 0 && tangent.y == 0 && tangent.z == 0) return frame_from_normal(sn);
  vec3 ts = v3_sub(tangent, v3_scale(sn, v3_dot(sn, tangent)));
  double tl = v3_len(ts);
  if (!(tl > 1e-9 * (v3_len(tangent) + 1e-300))) return frame_from_normal(sn);
  frame f;
  f.n = sn;
  f.s = v3_scale(ts, 1.0 / tl);
  f.t = v3_cross(sn, f.s);
  return f;
}
/* Area pdf of shape_sample_position (1/area). */
double shape_pdf_position(const shape *s);

/* Fill si from a hit (prim, barycentrics u/v for triangles or the object
 * space hit point for analytic shapes) on ray r at distance t. */
struct accel_hit;
void shape_fill_interaction(const shape *s, const ray3 *r, const struct accel_hit *h,
                            surface_interaction *si);
/* The same with to_world given apart from the shape (an instanced member
 * under placement * member.to_world), so no copy of the shape is made. */
void shape_fill_interaction_xf(const shape *s, const xform *to_world, const ray3 *r,
                               const struct accel_hit *h, surface_interaction *si);

/* shape_fill_interaction_xf in two parts, for the batched fill
 * (hit_fill_interaction_batch): shape_fill_begin fills si but for its
 * shading frame and wi, and gives the shading normal *sn (unit, after
 * flip_normals) and dp/du *tangent that make them (shape_frame_from_tangent,
 * then wi = the frame's local -normalize(r->d)); true when it filled the
 * whole si itself (a face frame from the face cache). sn_raw: NULL, or
 * where a mesh's interpolated shading normal is left unnormalised (after
 * flip_normals; *sn_raw_set true, *sn is then the geometric normal): sn is
 * then v3_norm(*sn_raw), or the geometric normal where !(v3_len2(that) >
 * 0.5). */
bool shape_fill_begin(const shape *s, const xform *to_world, const ray3 *r, const struct accel_hit *h,
                      surface_interaction *si, vec3 *sn, vec3 *tangent, vec3 *sn_raw, bool *sn_raw_set);
/* For n lanes, as structures of arrays (component c of lane i at
 * [c stride + i]; stride a multiple of 8, every array readable and
 * writable up to n rounded up to 8): in holds SHAPE_FRAME_IN components,
 * sn xyz, tangent xyz, the ray direction d xyz (as shape_fill_begin leaves
 * them), the raw shading normal xyz and a flag (1: sn is to be made from
 * the raw normal as shape_fill_begin says, with sn as the fallback; 0: sn
 * is final); out receives 12, the frame's s, t, n and wi. Vectorised at
 * the render's ISA (core/isa.h) in double precision with the scalar
 * operations in the scalar order (no FMA contraction), so each lane is
 * bitwise the scalar fill whatever the ISA and n (tests/kernel/integrators/test_wave.c). */
#define SHAPE_FRAME_IN 13
void shape_frames_batch(int n, int stride, const double *in, double *out);

/* The surface data of n hits on one cached mesh (a face_cache, so the
 * hits take mesh_fill_inline_raw's interpolating path), as structures of
 * arrays like shape_frames_batch. k: SHAPE_MH_K constants, the shape's
 * to_world m (4 x 4, row-major) and inv (its upper 3 x 3, row-major),
 * the terms of accel_surface_error that do not depend on the hit (c xyz,
 * tc, ext, S0..S2: accel.h accel_surface_error_terms), then 1 or 0 for
 * interpolated vertex normals (m->nrm && !face_normals), for uv, and for
 * flip_normals. in: SHAPE_MH_IN components, the barycentrics u, v; the
 * face's vertices p0, p1, p2 xyz; its vertex normals na, nb, nc xyz (read
 * only with normals) and uv ua, ub, uc (read only with uv); the face
 * cache's normal n xyz (before flip_normals) and dp/du xyz; the ray
 * direction d xyz. face: NULL, or the face data of every lane (hits on
 * one face), in[2 .. SHAPE_MH_IN_D) as one value each (in then holds only
 * the barycentrics and d). out: SHAPE_MH_OUT, the world position xyz,
 * its error bound (accel_surface_error), uv, the shading frame s, t, n and
 * wi. Each lane bitwise the scalar code (mesh_hit_lanes.h), at every ISA. */
enum {
  SHAPE_MH_M = 0,
  SHAPE_MH_INV = 16,
  SHAPE_MH_C = 25,
  SHAPE_MH_TC = 28,
  SHAPE_MH_EXT = 29,
  SHAPE_MH_S = 30,
  SHAPE_MH_NRM = 33,
  SHAPE_MH_UV = 34,
  SHAPE_MH_FLIP = 35,
  SHAPE_MH_K = 36,
  SHAPE_MH_IN_NA = 11,
  SHAPE_MH_IN_UVA = 20,
  SHAPE_MH_IN_N = 26,
  SHAPE_MH_IN_T = 29,
  SHAPE_MH_IN_D = 32,
  SHAPE_MH_IN = 35,
  SHAPE_MH_OUT = 18
};
void shape_mesh_hits_batch(int n, int stride, const double *k, const double *face, const double *in,
                           double *out);

/* Compute area, triangle cdf; check geometry (degenerate to_world for a
 * disk, non-uniform scale for a sphere, ...). Called by create(). */
rsw_status shape_finalize(shape *s, rsw_err *err, const char *where);

/* |det| of the linear part of t (for triangle areas below). */
static inline double xf_abs_det3(const xform *t) {
  const double(*m)[4] = t->m;
  return fabs(m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
              m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
              m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]));
}

/* World area of an object-space triangle under t without transforming its
 * vertices: with A the linear part, |A e1 x A e2| = |det A| |A^-T (e1 x e2)|,
 * and xf_normal applies A^-T. */
static inline double tri_world_area(const xform *t, double abs_det, vec3 p0, vec3 p1, vec3 p2) {
  return 0.5 * abs_det * v3_len(xf_normal(t, v3_cross(v3_sub(p1, p0), v3_sub(p2, p0))));
}

/* ---- rays leaving a surface ----------------------------------------------------
 * A ray leaving a surface must not hit that surface again through rounding.
 * Mitsuba offsets its origin by (1 + max|p|) RayEpsilon: 2 cm at 250 m from
 * the world origin, 18 cm at 2 km, which skips leaves and shifts the hot
 * spot. Following Waechter and Binder ("A Fast and Robust Method for
 * Avoiding Self-Intersection", Ray Tracing Gems, ch. 6, 2019), the offset is
 * instead proportional to the floating-point error of the hit point, here
 * as Embree sees it: si->p_error (accel_surface_error: a few float32 units
 * of the point's coordinates in Embree's scene-centred frame and of the
 * object's own coordinates) times RSW_SPAWN_ERRORS, along the geometric
 * normal on the side the ray leaves by. Hit points are exact in double (on
 * the surface: barycentrics or re-projection in object space), so the
 * offset only has to cover Embree's float32 rounding; it does not depend on
 * where the scene sits in the world. */
#define RSW_SPAWN_ERRORS 8.0

/* p moved RSW_SPAWN_ERRORS * err along the normal n, on the side of v. */
static inline vec3 offset_on_side(vec3 p, vec3 n, double err, vec3 v) {
  double mag = RSW_SPAWN_ERRORS * err;
  return v3_fma(p, v3_dot(n, v) >= 0 ? mag : -mag, n);
}

/* The ray leaving si along direction d (not necessarily unit). */
static inline ray3 spawn_ray(const surface_interaction *si, vec3 d) {
  ray3 r = {offset_on_side(si->p, si->ng, si->p_error, d), d, 0.0, INFINITY};
  return r;
}

/* The segment from si to point q on another surface (normal nq, error
 * bound q_err): both ends are offset off their surfaces, towards each
 * other, and the segment stops a few float units of its length short of
 * the offset end (Embree's error in t). Unit direction. */
static inline ray3 spawn_ray_between(const surface_interaction *si, vec3 q, vec3 nq, double q_err) {
  vec3 o = offset_on_side(si->p, si->ng, si->p_error, v3_sub(q, si->p));
  vec3 e = offset_on_side(q, nq, q_err, v3_sub(si->p, q));
  vec3 d = v3_sub(e, o);
  double len = v3_len(d);
  ray3 r = {o, len > 0 ? v3_scale(d, 1.0 / len) : d, 0.0, len * (1.0 - RSW_SPAWN_ERRORS * RSW_F32_UNIT)};
  return r;
}

/* Can float32 tracing represent shape s under to_world t (core/transform.h
 * xf_traceable: affine, scales and translation within the limits), with
 * every object-space coordinate of its geometry and every world-space
 * coordinate of its image under t within RSW_TRACE_MAX_COORD? `what`
 * names the property or key in the message (e.g. "to_world" or
 * "rectangle.to_world"); where goes into err. O(vertices) for a mesh. */
rsw_status shape_check_traceable(const shape *s, const xform *t, const char *what, rsw_err *err,
                                 const char *where);

/* Mark a shape as sampled (a sensor target) and compute what sampling
 * needs; fails when it has no area. */
rsw_status shape_enable_sampling(shape *s, rsw_err *err, const char *where);

/* Free a shape's owned geometry (used by every shape plugin's destroy). */
void shape_release(shape *s);

/* ---- triangle meshes ---------------------------------------------------------------- */

/* Triangle meshes' surface data and position sampling, inline: the
 * generic shape code takes this path without an indirect call (the common
 * case), shape_ops_mesh puts the same functions in its table. */

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
