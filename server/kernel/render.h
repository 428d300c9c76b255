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

#include "film_io.h"
#include "kernel.h"

typedef struct render_opts {
  size_t size;   /* sizeof(render_opts) */
  size_t sensor; /* index into scene->sensors */
  uint32_t spp;  /* 0: the sensor sampler's sample_count */
  uint64_t seed;
  double wavelength;        /* nm, mono only; 0 means 550 */
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
} render_opts;

/* A developed film: HWC float32, row 0 = first (top) row. */
typedef struct film_image {
  int width, height, channels;
  const char *channel_names[4]; /* static strings: "R","G","B" or "Y" */
  float *data;                  /* owned */
  bool half;                    /* the film asked for float16 storage */
  /* What was rendered (for metadata). */
  uint32_t spp;
  uint64_t seed;
  double wavelength;
  rsw_variant variant;
  /* Viewing zenith, azimuth (degrees) of each pixel, 2 per pixel,
   * row-major (owned); NULL when the sensor has no pixel_angles op. */
  double *angles;
  /* Rays the periodic boundary could not resolve (render_stats.unresolved:
   * within ~1e-5 rad of horizontal, still inside the slab after 65,536
   * walls), each counted as blocked / ending its path. Non-zero means the
   * film depends on that policy; written to the film's metadata. */
  uint64_t unresolved_rays;
} film_image;

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
void film_image_free(film_image *img);

/* The EXR attributes of a rendered film (film_io.h): sensor, spp, seed,
 * variant, the wavelength in mono, the per-pixel viewing angles when the
 * film has them, the unresolved-ray count when non-zero. Borrows img and sensor_id (the info points into them). */
film_exr_info film_image_exr_info(const film_image *img, const char *sensor_id);

/* Write a developed film as OpenEXR (float32, or float16 when the film asks
 * for it), through a temporary file renamed on success, with
 * film_image_exr_info's attributes (film_exr_write). */
rsw_status film_image_write_exr(const film_image *img, const char *path, const char *sensor_id, rsw_err *err);

#endif
