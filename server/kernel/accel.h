/* Ray queries on the two-level acceleration structure. accel.c is the only
 * kernel file that includes Embree (measurement code reaches Embree through
 * accel_internal.h).
 *
 * Layout (decided once, relied on by parameter updates): every shape is its
 * own Embree scene holding one geometry in object space, instanced into the
 * top-level scene with the shape's to_world as instance transform (instance
 * id = shape index). Debian's Embree 3.13 allows one instance level and only
 * honours per-geometry refit inside such a two-level scene; so a rigid
 * to_world change is a top-level rebuild, a vertex move a refit of that
 * mesh's own BVH.
 *
 * Instancing (shapes/instance.h): each shapegroup is one Embree scene with
 * its members (geomID = member index); an `instance` is attached at its
 * shape index like any shape, an `instancelist`'s placements at ids after
 * all shapes (a 2 x 4-byte map gives shape and placement back).
 *
 * Precision: Embree traces in float32. Everything it holds (instance
 * translations, ray origins, the ceiling's flat copy) is expressed relative
 * to accel_origin(), the centre of the geometry's bounds, which is
 * recomputed (and every instance transform rewritten) whenever a commit
 * moves it. So float rounding depends on distances within the scene, not on
 * where the scene sits in the world: a canopy at 100 km from the world
 * origin traces like the same canopy at the origin. accel_surface_error()
 * bounds what that rounding can still do, for the offsets of spawned rays
 * (shapes/shape.h spawn_ray). */
#ifndef RSW_ACCEL_H
#define RSW_ACCEL_H

#include <time.h>

#include "accel_hit.h"
#include <math.h>

#include "kernel.h"

typedef struct accel accel;

/* Build for all shapes of s (s->accel is set). Thread count for the
 * Embree build is Embree's default. */
rsw_status accel_build(scene *s, rsw_err *err);
void accel_free(accel *a);

/* Closest hit on [r->tmin, r->tmax]; false if none. Thread-safe. */
bool accel_intersect(const accel *a, const ray3 *r, accel_hit *h);
/* Any hit on [r->tmin, r->tmax]. Thread-safe. */
bool accel_occluded(const accel *a, const ray3 *r);

/* Packet queries (the wavefront integrator, integrators/path.c): n rays
 * traced together, up to 16 at a time, as Embree packets of 4, 8 or 16 lanes (the
 * widest the CPU and Embree support, or accel_set_packet_width's pin);
 * the rays should belong together (same bounce of neighbouring paths).
 * Per ray the same queries as accel_intersect / accel_occluded (fill_ray's
 * rules, same hit record); Embree's packet kernels may round a hit
 * distance differently from its single-ray kernel, so results agree with
 * the single-ray calls to float precision, not bitwise. hit[i] / occ[i]:
 * ray i hit something (*h[i] filled, and a miss's *h[i] overwritten; h[i]
 * in the _mask variant below, a miss's left as it was) / is blocked. coherent: the rays share an origin region and nearly a
 * direction (camera rays), an Embree hint. */
void accel_intersect_packet(const accel *a, const ray3 *const *r, int n, accel_hit *const *h, bool *hit,
                            bool coherent);
void accel_occluded_packet(const accel *a, const ray3 *const *r, int n, bool *occ);

/* True when ray r (any tmin, tmax) passes the scene's bounding box
 * (scene.h bbox_min/max) by a clear margin, 2^-14 clip_r (clip_r being
 * 64 times the bounds' half diagonal): far beyond where Embree's float32
 * copy of the ray (its origin within clip_r of accel_origin, rounded to
 * 2^-24 relative, its direction likewise: a lateral error below
 * 2^-24 * 130 clip_r / 64) or of the geometry can stray, so no query of
 * r can hit anything: a caller may count it a miss without one. A slab
 * test in double; false for a ray starting inside the padded box, one
 * with a NaN, or a NULL structure. Not for periodic scenes (the box is
 * one cell's). */
bool accel_misses_bounds(const accel *a, const ray3 *r);

/* The same test inline, for many rays: the padded box once
 * (accel_cull_box; false for a NULL structure, where nothing may be
 * culled), then accel_box_misses per ray. */
typedef struct accel_box {
  double lo[3], hi[3];
} accel_box;
bool accel_cull_box(const accel *a, accel_box *b);

/* The line from t = 0 on meets slab k over [tn_k, tf_k] = [A_k, B_k] /
 * |d_k| (A_k, B_k: the signed distances to the slab's near and far planes
 * along d_k's sign); it misses the box when some tf_k < 0 or some tn_i >
 * tf_j, i.e. A_i |d_j| > B_j |d_i|: products, no division (their rounding
 * is nothing next to the margin). A slab the direction lies in (d_k = 0)
 * culls when the origin is outside it, else takes no part (A = -1, B = 1
 * make its comparisons false). A NaN makes a comparison false: less
 * culled, never more. Without branches. */
static inline bool accel_box_misses(const accel_box *b, const ray3 *r) {
  const double o[3] = {r->o.x, r->o.y, r->o.z}, d[3] = {r->d.x, r->d.y, r->d.z};
  double A[3], B[3], ad[3];
  bool out = false;
  for (int k = 0; k < 3; k++) {
    bool zero = d[k] == 0.0, pos = d[k] > 0.0;
    out |= zero & ((o[k] < b->lo[k]) | (o[k] > b->hi[k]));
    double near = pos ? b->lo[k] - o[k] : o[k] - b->hi[k], far = pos ? b->hi[k] - o[k] : o[k] - b->lo[k];
    A[k] = zero ? -1.0 : near;
    B[k] = zero ? 1.0 : far;
    ad[k] = fabs(d[k]);
    out |= B[k] < 0.0;
  }
  out |= A[0] * ad[1] > B[1] * ad[0];
  out |= A[0] * ad[2] > B[2] * ad[0];
  out |= A[1] * ad[0] > B[0] * ad[1];
  out |= A[1] * ad[2] > B[2] * ad[1];
  out |= A[2] * ad[0] > B[0] * ad[2];
  out |= A[2] * ad[1] > B[1] * ad[2];
  return out;
}

/* ---- ray masks: null boxes the volumetric integrators cross analytically --
 * A top-level shape that may be a box with the `null` BSDF
 * (accel_null_box_candidate: index-matched BSDF, no emitter, a triangle
 * mesh of 12 faces) gets the instance mask ACCEL_MASK_NULL_BOX when the
 * device supports ray masks (accel_null_box_masked). Every query above
 * uses the full mask and sees it as always; the _mask variants with
 * ACCEL_RAYS_NO_NULL_BOX do not (integrators/volpath.c, with
 * media_refresh_null_boxes deciding whether that is exact). */
#define ACCEL_MASK_NULL_BOX    0x2u
#define ACCEL_RAYS_NO_NULL_BOX (~ACCEL_MASK_NULL_BOX)
bool accel_null_box_candidate(const shape *sh);
bool accel_null_box_masked(const accel *a, uint32_t index);
/* Test hook: structures built after accel_set_null_box_masks(false) mask
 * nothing (every null box is traced as before); true restores the default. */
void accel_set_null_box_masks(bool on);
bool accel_intersect_mask(const accel *a, const ray3 *r, accel_hit *h, unsigned mask);
void accel_intersect_packet_mask(const accel *a, const ray3 *const *r, int n, accel_hit *h, bool *hit,
                                 bool coherent, unsigned mask);
/* Lanes of the packets those calls trace (16, 8, 4, or 1 without packet
 * support), and a pin to a narrower width for the process (1, 4, 8 or 16;
 * anything else: back to the widest). */
int accel_packet_width(void);
void accel_set_packet_width(int w);

/* ---- float32 error bounds ---------------------------------------------------- */

/* The world point Embree's frame is centred on (see above; the origin
 * (0,0,0) for a NULL structure). */
vec3 accel_origin(const accel *a);

/* Bound (world units), along the surface's unit normal n, on the distance
 * between a point p on the surface of top-level shape `index` (into
 * scene->shapes), computed in double precision, and that surface as Embree
 * intersects rays starting near p in float32. X is the instance transform
 * Embree applies, (A, t): the shape's to_world, or the placement of the
 * instance that was hit. With u = 2^-24, c = accel_origin(), B = A^-1 and
 * ext the largest |coordinate| of the shape's geometry in instance space:
 *   u [ |n|_1 |p - c| + sum_k |(A^T n)_k| |B_k|_1 (|p - c| + |t - c|)
 *       + |A^T n|_1 ext ]                      (|.| of points: max-abs)
 * the ray origin's rounding in Embree's frame, its float transform into
 * instance space, and the intersection arithmetic there. It does not
 * depend on a translation of the whole scene. */
double accel_surface_error(const accel *a, uint32_t index, const xform *X, vec3 p, vec3 n);
/* The terms of that bound that depend on the shape and X only, for
 * batched fills (hit.c): t[0..2] = c, t[3] = |t - c|, t[4] = ext, t[5..7]
 * = |B_k|_1; the bound is then u [ |n|_1 pc + w (pc + t[3]) + a t[4] ]
 * with pc = |p - c|, a = sum_k |(A^T n)_k| and w = sum_k |(A^T n)_k|
 * t[5 + k], each sum taken in k order (accel_surface_error's bits). */
void accel_surface_error_terms(const accel *a, uint32_t index, const xform *X, double t[8]);
/* accel_surface_error from those terms (bit for bit): a shape's many hits
 * take the terms once. */
double accel_surface_error_at(const double t[8], const xform *X, vec3 p, vec3 n);
/* The same for m points (p[0][j], p[1][j], p[2][j]) with unit normals
 * n[.][j], into out[j], j < m: one call for a batch. */
void accel_surface_error_at_n(const double t[8], const xform *X, int m, const double *const p[3],
                              const double *const n[3], double *out);

/* ---- updates (scene/update.c) -------------------------------------------------
 * Each call stages work on one shape; accel_commit() then commits the
 * top-level scene once if anything changed. */

/* New to_world of shape sh: the instance transform only. */
void accel_update_transform(accel *a, const shape *sh);
/* sh's vertex positions changed (same count): copy them and refit that
 * shape's BVH (RTC_BUILD_QUALITY_REFIT). */
rsw_status accel_update_vertices(accel *a, const shape *sh, rsw_err *err);
/* sh's topology changed (faces, vertex count): rebuild that shape's BVH. */
rsw_status accel_rebuild_shape(accel *a, const shape *sh, rsw_err *err);
/* Commit the top level if any update was staged (and, after a failed
 * update, every shape scene again). */
rsw_status accel_commit(accel *a, rsw_err *err);
/* False while staged updates are uncommitted or a failed one left the
 * structure incomplete (tracing it then is not safe): renders refuse. */
bool accel_ready(const accel *a);

/* Counters of Embree work since the structure was built (test hook and
 * update reports). */
typedef struct accel_counters {
  unsigned long top_commits;      /* rtcCommitScene on the top level */
  unsigned long instance_updates; /* instance transforms written */
  unsigned long refits;           /* shape BVHs refitted */
  unsigned long rebuilds;         /* shape BVHs rebuilt */
  unsigned long origin_moves;     /* commits that moved accel_origin() (every
                                     instance transform rewritten) */
} accel_counters;
void accel_get_counters(const accel *a, accel_counters *out);

/* Bytes held by Embree buffers we allocated (for reporting). */
size_t accel_memory(const accel *a);

/* Bytes Embree's device holds now, process-wide, from its device memory
 * monitor (rtcSetDeviceMemoryMonitorFunction): every scene, BVH and
 * geometry of the shared device. */
size_t accel_embree_bytes(void);

/* Whether Embree is stuck in this process. A failure for want of memory
 * inside one of Embree's parallel build tasks can leave a lock of Embree's
 * held, and every later build then waits on it forever
 * (docs/robustness.md#when-memory-runs-out). So after Embree reports
 * RTC_ERROR_OUT_OF_MEMORY, the next call builds a one-triangle scene on a
 * thread of its own and waits up to 3 s for it; one that does not finish
 * marks Embree stuck for good. From then on this is true (*since: when it
 * was found), and accel_build, accel_rebuild_shape, accel_update_vertices
 * and accel_commit (when it has something to commit), which call it first,
 * refuse with RSW_ERR_UNAVAILABLE and a message that says why, instead of
 * waiting forever; structures built before still trace. *oom_count (unless
 * NULL): Embree's out-of-memory failures so far. probe false: what is
 * known, without probing (for reports). Thread-safe. */
bool accel_embree_stuck(time_t *since, unsigned long long *oom_count, bool probe);
/* Test hooks: the probe runs hook instead of its build (NULL: the build);
 * forget that Embree was found stuck. */
void accel_set_probe_hook(void (*hook)(void));
void accel_clear_embree_stuck(void);

/* The ceilings make bench measures (Embree alone on the same structure)
 * live with the benchmarks, tests/bench/accel_bench.h, on accel_internal.h. */

#endif
