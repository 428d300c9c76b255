/* Developed film -> OpenEXR, with the render's context as string
 * attributes so a film is self-describing. */
#include <inttypes.h>
#include <stdio.h>

#include "image_exr.h"
#include "render.h"

rsw_status film_image_write_exr(const film_image *img, const char *path, const char *sensor_id, rsw_err *err) {
  char spp[32], seed[32], wl[32];
  snprintf(spp, sizeof spp, "%" PRIu32, img->spp);
  snprintf(seed, sizeof seed, "%" PRIu64, img->seed);
  snprintf(wl, sizeof wl, "%.17g", img->wavelength);
  exr_meta_entry e[5] = {
      {"raysweep:sensor", sensor_id ? sensor_id : ""},
      {"raysweep:spp", spp},
      {"raysweep:seed", seed},
      {"raysweep:variant", img->variant == VARIANT_MONO ? "mono" : "rgb"},
      {"raysweep:wavelength_nm", wl},
  };
  exr_meta meta = {.entries = e, .count = img->variant == VARIANT_MONO ? 5 : 4};
  return exr_write_image(path, img->width, img->height, img->channels, img->channel_names, img->data, img->half,
                         &meta, err);
}
