/* Rendering one sensor of a scene into a film buffer.
 *
 * Determinism: every sample's random numbers come from the sampler seeded
 * by (seed, pixel index, sample index) only; pixels are accumulated in a
 * fixed order inside fixed 8x8 tiles, and tiles are merged into the film
 * in tile order; so 1 thread and N threads give bitwise-identical films.
 * Within a tile, samples are traced in waves of up to 256 (integrator_ops
 * Li_batch: the paths advance bounce by bounce together, their rays traced
 * as Embree packets) and splatted in sample order afterwards. */
#ifndef RSW_RENDER_H
#define RSW_RENDER_H

#include <stdatomic.h>

#include "films/film_exr.h"
#include "films/film_planes.h"
#include "kernel.h"

/* A render's progress in samples, for another thread to read (relaxed
 * atomics): total (width x height x spp) is set when tracing starts, done
 * grows after each wave of samples. */
typedef struct render_progress {
  _Atomic uint64_t done, total;
} render_progress;

typedef struct render_opts {
  size_t size;   /* sizeof(render_opts) */
  size_t sensor; /* index into scene->sensors */
  uint32_t spp;  /* 0: the sensor sampler's sample_count */
  uint64_t seed;
  double wavelength; /* nm, mono only; 0 means 550 */
  /* Mono: a spectral bundle, `bundle` (2..RENDER_MAX_BUNDLE) wavelengths
   * carried by every path, one per colour channel
   * (docs/experiments.md#spectral-bundles); `wavelength` is then ignored and the render gives
   * one film per wavelength (render_sensor_bundle). 0 or 1: none. */
  int bundle;
  double bundle_wl[RENDER_MAX_BUNDLE];
  int threads;              /* 0: all cores */
  const atomic_int *cancel; /* optional: non-zero stops the render
                               (checked before each wave of 256
                               samples): RSW_ERR_CANCELLED */
  double deadline;          /* optional: CLOCK_MONOTONIC seconds after which
                               the render stops: RSW_ERR_TIMEOUT (0: none) */
  /* Optional progress callback: tiles done of total (called from worker
   * threads, serialised). */
  void (*progress)(void *user, size_t done, size_t total);
  void *progress_user;
  /* Planes beyond radiance (film_image.planes), RENDER_Q_* bits. brdf and
   * brf need a directional emitter (see render_horizontal_irradiance). */
  unsigned quantities;
  /* Add the radiance_stderr plane: each pixel's standard error of the
   * mean from its samples' second moment. Needs the box filter (radius
   * 0.5) and spp >= 2 (RSW_ERR_INVALID "variance" otherwise). */
  bool variance;
  /* Optional: kept up to date while the render runs (a job's progress
   * within its current render). Does not change the film. */
  render_progress *samples;
} render_opts;

typedef struct render_result_stats {
  render_stats rays; /* rays.unresolved: see film_image.unresolved_rays */
  uint64_t samples;
  uint64_t invalid_samples; /* NaN/inf contributions dropped */
  double wall_s;
  int threads;
  /* Thread time spent on tiles, summed over threads; rays.trace_s of it
   * in ray queries (the rest: camera rays, shading, splatting). */
  double busy_s;
  int packet_width; /* lanes of the Embree packets the wave traced (accel_packet_width) */
} render_result_stats;

/* One line summing up a render (raysweepd render --stats): samples and
 * samples/s, rays by kind (camera, continuation, shadow) and rays/s, time
 * tracing vs the rest. Written into buf (NUL-terminated). */
void render_stats_line(const render_result_stats *st, char *buf, size_t size);

rsw_status render_sensor(scene *s, const render_opts *opts, film_image *out, render_result_stats *stats,
                         rsw_err *err);

/* Whether sensor sensor_index of sc can render a bundle of `bundle`
 * wavelengths (1 always can): 2..RENDER_MAX_BUNDLE, a mono scene, a film
 * without Stokes components, and for more than three, a scene that can
 * carry pages (scene_page_blocker). The message names what stands in the
 * way. */
rsw_status render_check_bundle(const scene *sc, size_t sensor_index, int bundle, rsw_err *err);

/* A bundle's render: out[b] is the film at opts->bundle_wl[b], for b <
 * max(opts->bundle, 1) (with no bundle, render_sensor's one film). Each
 * film is what the film at its wavelength alone would be in distribution;
 * its noise is correlated with its bundle mates' (the same paths). The
 * bundle needs what render_check_bundle says. */
rsw_status render_sensor_bundle(scene *s, const render_opts *opts, film_image *out,
                                render_result_stats *stats, rsw_err *err);

#endif
