/* The Embree ceilings make bench measures (bench_kernel, bench_canopy):
 * Embree alone, with no shading, on a scene's own acceleration structure
 * (server/kernel/accel_internal.h). Measurement only: nothing in the daemon
 * calls these. */
#ifndef RSW_BENCH_ACCEL_BENCH_H
#define RSW_BENCH_ACCEL_BENCH_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../../server/kernel/scene/scene.h"

/* Rays per second of random incoherent rtcIntersect1 queries against the
 * scene's geometry on `threads` threads: origins uniform inside the
 * scene's bounding ball, directions uniform on the sphere (the "Embree
 * ceiling"). With flat = true the same
 * triangles are put in a single-level Embree scene (vertices transformed to
 * world space, analytic shapes skipped) to measure what the two-level
 * layout costs. Returns 0 on failure. */
double accel_ceiling_rays_per_s(const scene *s, bool flat, uint64_t n_rays, int threads, uint64_t seed);

/* The replay ceiling: a render's own queries recorded once, as Embree saw
 * them (float rays in its frame, each query's packet width and kind), then
 * traced again by Embree alone with no shading, in the recorded packets and
 * order, split into contiguous shares over `threads` threads. Recording is
 * process-wide (one log at a time) and meant for one-thread renders (queries
 * of concurrent threads would interleave); queries past max_rays are not
 * recorded. Off (the default), each query pays one relaxed atomic load. */
typedef struct accel_ray_log accel_ray_log;
accel_ray_log *accel_record_begin(size_t max_rays); /* NULL: out of memory */
void accel_record_end(void);
size_t accel_ray_log_count(const accel_ray_log *lg);
void accel_ray_log_free(accel_ray_log *lg);
/* Recorded rays per second on s's structure; 0 on failure or an empty log.
 * flat: on a single-level copy of s's triangles instead (world space,
 * analytic shapes and instances left out, as accel_ceiling_rays_per_s):
 * what a flat BVH would give on the render's own rays. */
double accel_replay_rays_per_s(const scene *s, const accel_ray_log *lg, int threads, bool flat);

#endif
