/* accel.c's Embree side, for code that measures Embree alone (the
 * ceilings of make bench, tests/bench/accel_bench.c): the structure's
 * Embree device and top-level scene, the C layout of Embree's ray packets,
 * and a hook that sees every query as Embree receives it. Only accel.c and
 * measurement code include this header (it includes Embree; accel.h does
 * not). */
#ifndef RSW_ACCEL_INTERNAL_H
#define RSW_ACCEL_INTERNAL_H

#include <stdbool.h>

#include <embree3/rtcore.h>

#include "accel.h"

/* Embree's RTCRayN/RTCHitN accessors are C++ only; in C the SOA layout is
 * addressed directly: RTCRayN is 12 arrays of N 32-bit fields (org_x,
 * org_y, org_z, tnear, dir_x, dir_y, dir_z, time, tfar, mask, id, flags),
 * RTCHitN follows it (Ng_x, Ng_y, Ng_z, u, v, primID, geomID, instID[0]). */
enum {
  RAY_ORG = 0,
  RAY_TNEAR = 3,
  RAY_DIR = 4,
  RAY_TFAR = 8,
  RAY_FIELDS = 12
};
enum {
  HIT_NG = 0,
  HIT_U = 3,
  HIT_V = 4,
  HIT_PRIM = 5,
  HIT_GEOM = 6,
  HIT_INST = 7
};
#define RAYN_F(p, N, f, i) (((float *)(p))[(size_t)(f) * (N) + (i)])
#define HITN_F(p, N, f, i) (((float *)(p))[(size_t)(f) * (N) + (i)])
#define HITN_U(p, N, f, i) (((unsigned *)(p))[(size_t)(f) * (N) + (i)])

/* One SOA packet of up to 16 rays with their hits (RTCRayHit16's layout,
 * addressed through RAYN_F/HITN_*: the same memory serves N = 4, 8, 16). */
typedef struct packet_buf {
  _Alignas(64) float f[(RAY_FIELDS + HIT_INST + 1) * 16];
  _Alignas(64) int valid[16];
  double t0[16], ts[16];
} packet_buf;

/* The process-wide device and the two-level scene that accel_intersect and
 * accel_occluded trace (rays in its frame: world minus accel_origin). */
RTCDevice accel_embree_device(const accel *a);
RTCScene accel_embree_top(const accel *a);

/* Called with every query's rays after fill_ray (float, in Embree's frame),
 * from every thread, before Embree traces them: k valid lanes of a packet
 * of `width` (1: rtcIntersect1/rtcOccluded1), occluded for an occlusion
 * query. NULL (the default): no hook, and each query pays one relaxed
 * atomic load. Process-wide: one hook at a time. */
typedef void accel_query_hook(const struct RTCRay *const *rays, unsigned k, unsigned width, bool occluded);
void accel_set_query_hook(accel_query_hook *fn);

#endif
