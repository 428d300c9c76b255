/* Quick-look PNGs of a film: tone-mapped 8-bit sRGB through libpng. This
 * header mentions none of libpng's types; the one file that includes
 * png.h is image_png.c.
 *
 * The mapping (a look, not a measurement) is Mitsuba's conversion of a
 * linear film to 8-bit sRGB: each value times 2^exposure, clamped to
 * [0, 1] (at exposure 0 a radiance of 1 is full white), then
 *   - three channels (R, G, B): each sRGB-encoded (IEC 61966-2-1 transfer
 *     curve), an RGB PNG;
 *   - one channel (Y, or S0 / S0.Y of a Stokes film): with colormap "gray", the
 *     sRGB-encoded grey (a grayscale PNG); with "viridis" or "inferno",
 *     the linear value through that perceptually uniform map (matplotlib's,
 *     tabulated at 9 points and interpolated linearly), an RGB PNG.
 * With auto_exposure every value is first divided by the film's
 * PNG_AUTO_PERCENTILE-th percentile of the finite values > 0 of the
 * channels shown (nearest rank), not by its maximum: a lamp or a glint
 * clips instead of darkening the whole picture (docs/viewer.md "Tone
 * mapping"). NaN, infinite and negative values show as black. Row 0 is
 * the top. */
#ifndef RSW_IMAGE_PNG_H
#define RSW_IMAGE_PNG_H

#include <stdbool.h>
#include <stddef.h>

#include "rsw_error.h"

typedef struct png_look {
  double exposure;      /* stops; 0 by default */
  bool auto_exposure;   /* scale by the PNG_AUTO_PERCENTILE value first */
  const char *colormap; /* NULL or "gray", "viridis", "inferno" */
} png_look;

/* The percentile auto exposure maps to white (the viewer uses the same). */
#define PNG_AUTO_PERCENTILE 99.5

/* Parse an exposure as given on a command line or in ?exposure=: a number
 * of stops (|EV| <= 1000), "auto", or "auto+EV" / "auto-EV" (auto, then
 * EV stops). false, with look unchanged, for anything else. */
bool png_exposure_parse(const char *text, png_look *look);

/* True when name is a colormap png_look takes (NULL counts as gray). */
bool png_colormap_known(const char *name);
/* The colormap names, for messages: "gray, viridis, inferno". */
const char *png_colormap_list(void);

/* Encode / write the quick-look of a film (width x height x n_channels
 * float32 HWC, channel_names as the film's). The channels shown are the
 * film's radiance: R, G, B when it has them, else Y, else S0 (a Stokes
 * film's intensity: S0, S0.Y, or S0.R S0.G S0.B as R, G, B); other
 * channels (planes such as brf.Y, S1..S3) are ignored. look may be NULL
 * (defaults). png_write_film writes "<path>.tmp.<pid>" and renames it over
 * path once complete. Errors: RSW_ERR_INVALID (no R/G/B, Y or S0 channel;
 * unknown colormap; exposure not finite), RSW_ERR_NOMEM, RSW_ERR_IO
 * (naming path). Borrows everything; thread-safe. */
rsw_status png_encode_film(int width, int height, int n_channels, const char *const *channel_names,
                           const float *data, const png_look *look, void **bytes_out, size_t *len_out,
                           rsw_err *err);
rsw_status png_write_film(const char *path, int width, int height, int n_channels,
                          const char *const *channel_names, const float *data, const png_look *look,
                          rsw_err *err);

#endif
