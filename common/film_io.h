/* A film's EXR with what it is: the render's context as string attributes
 * named "raysweep:<key>", so the file describes itself. Every EXR of a film
 * the project writes goes through film_exr_write or film_exr_encode
 * (raysweepd render -o, the daemon's image/x-exr answers and job results,
 * rsw_film_save_exr and so the CLI), so all carry the same keys written
 * the same way:
 *
 *   raysweep:scene          scene id (daemon films)
 *   raysweep:revision       parameter revision rendered (daemon films)
 *   raysweep:context        context id (daemon films: the job's context, or
 *                           "render" for a synchronous render)
 *   raysweep:sensor         sensor id
 *   raysweep:spp            samples per pixel, decimal
 *   raysweep:seed           render seed, decimal
 *   raysweep:variant        "mono" or "rgb"
 *   raysweep:wavelength_nm  mono films: the wavelength, %.17g
 *   raysweep:zenith_deg, raysweep:azimuth_deg
 *                           distant-family sensors: each pixel's viewing
 *                           zenith and azimuth in degrees (Eradiate's
 *                           east-right convention), %.9g, comma-separated,
 *                           row-major
 *   raysweep:unresolved_rays
 *                           only when non-zero: rays that could not be
 *                           resolved (UNRESOLVED_WHY), decimal
 *   raysweep:plugin_failures, raysweep:plugin_failure
 *                           only when non-zero: environment plugin answers
 *                           the render replaced by black (decimal), and the
 *                           first one's message
 *   raysweep:isa            the instruction set the batched shading ran
 *                           ("avx512", "avx2", "sse2", "generic"), when known
 *   raysweep:irradiance     films with brdf/brf channels: the horizontal
 *                           irradiance E_h they divide by, per radiance
 *                           channel, %.17g, comma-separated
 *   raysweep:sun_zenith_deg, raysweep:sun_azimuth_deg
 *                           daemon films of a scene with one directional
 *                           emitter: its zenith and azimuth in degrees
 *                           (Eradiate's convention), %.9g, as the JSON
 *                           meta's sun_zenith_deg and sun_azimuth_deg
 *
 * Planes beyond radiance are channels "<plane>.<channel>" (brf.Y,
 * radiance_stderr.R, ...), EXR's layer naming.
 *
 * The number formats are those of the daemon's JSON film meta, so a film
 * fetched as JSON and saved by the client library gives the same strings.
 * No OpenEXR types here; the pixels go through image_exr.c. */
#ifndef RSW_KERNEL_FILM_IO_H
#define RSW_KERNEL_FILM_IO_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "rsw_error.h"

/* What a film's unresolved_rays counts, for the warnings that print it
 * after "N rays" (render_stats.unresolved): a periodic slab's rays that
 * stayed near-horizontal inside it for 65,536 cell walls
 * (docs/mitsuba-differences.md), and media tracks given up
 * (docs/media.md#tracks-given-up). */
#define UNRESOLVED_WHY                                                                                   \
  "were unresolved (a periodic slab's near-horizontal rays after 65,536 cell walls, or media tracks "  \
  "given up: docs/media.md#tracks-given-up) and ended their paths or were counted as blocked; the film " \
  "depends on that policy"

typedef struct film_exr_info {
  const char *scene, *context, *sensor, *variant; /* NULL or "": not written */
  bool has_revision, has_spp, has_seed;
  uint64_t revision, seed;
  uint64_t unresolved_rays; /* written when non-zero */
  uint64_t plugin_failures; /* written when non-zero, with plugin_failure */
  const char *plugin_failure;
  uint32_t spp;
  const char *isa; /* NULL or "": not written */
  double wavelength_nm; /* written when finite and variant is not "rgb" */
  /* NULL, or 2 per pixel (zenith, azimuth), row-major, degrees. */
  const double *angles;
  /* n_irradiance (0: not written) horizontal irradiances, one per
   * radiance channel. */
  const double *irradiance;
  int n_irradiance;
  /* The scene's one directional emitter (has_sun): its zenith and azimuth
   * in degrees, Eradiate's convention. */
  bool has_sun;
  double sun_zenith, sun_azimuth;
} film_exr_info;

/* The text of raysweep:zenith_deg (k 0) or raysweep:azimuth_deg (k 1) for
 * n pixels' angles (2 per pixel, as film_exr_info.angles): "%.9g" values
 * joined by ','. The daemon's JSON film meta writes the same lists. The
 * last angles' lists are kept, so the films of one sensor format them
 * once. Malloc'ed (*len_out, may be NULL: its length); NULL when out of
 * memory. Thread-safe. */
char *film_angle_list(const double *angles, size_t n, int k, size_t *len_out);

/* An info that writes nothing (wavelength NaN); set what is known. */
film_exr_info film_exr_info_none(void);

/* Write / encode in memory a film (width x height x n_channels float32,
 * HWC, channel_names as for exr_write_image; half: store float16) with
 * info's attributes. Arguments and errors as exr_write_image and
 * exr_encode_image (image_exr.h), plus RSW_ERR_NOMEM for the angle lists.
 * Borrows everything. Thread-safe. */
rsw_status film_exr_write(const char *path, int width, int height, int n_channels,
                          const char *const *channel_names, const float *data, bool half,
                          const film_exr_info *info, rsw_err *err);
rsw_status film_exr_encode(int width, int height, int n_channels, const char *const *channel_names,
                           const float *data, bool half, const film_exr_info *info, void **bytes_out,
                           size_t *len_out, rsw_err *err);

#endif
