/* Developed film -> OpenEXR, with the render's context as string
 * attributes so a film is self-describing. */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>

#include "image_exr.h"
#include "render.h"

/* "v0,v1,..." of every pixel's angle k (0 zenith, 1 azimuth), row-major,
 * %.9g (enough for a float's worth of angle). NULL when out of memory. */
static char *angle_list(const film_image *img, int k) {
  size_t n = (size_t)img->width * img->height;
  size_t cap = n * 18 + 1, len = 0; /* "%.9g" is at most 16 chars, plus ',' */
  char *s = malloc(cap);
  if (!s) return NULL;
  s[0] = '\0';
  for (size_t i = 0; i < n; i++) {
    int w = snprintf(s + len, cap - len, i ? ",%.9g" : "%.9g", img->angles[2 * i + (size_t)k]);
    if (w < 0 || (size_t)w >= cap - len) {
      free(s);
      return NULL;
    }
    len += (size_t)w;
  }
  return s;
}

rsw_status film_image_write_exr(const film_image *img, const char *path, const char *sensor_id, rsw_err *err) {
  char spp[32], seed[32], wl[32];
  snprintf(spp, sizeof spp, "%" PRIu32, img->spp);
  snprintf(seed, sizeof seed, "%" PRIu64, img->seed);
  snprintf(wl, sizeof wl, "%.17g", img->wavelength);
  exr_meta_entry e[7] = {
      {"raysweep:sensor", sensor_id ? sensor_id : ""},
      {"raysweep:spp", spp},
      {"raysweep:seed", seed},
      {"raysweep:variant", img->variant == VARIANT_MONO ? "mono" : "rgb"},
      {"raysweep:wavelength_nm", wl},
  };
  size_t count = img->variant == VARIANT_MONO ? 5 : 4;
  char *zen = NULL, *az = NULL;
  if (img->angles) {
    zen = angle_list(img, 0);
    az = angle_list(img, 1);
    if (!zen || !az) {
      free(zen);
      free(az);
      return rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory for the pixel angles");
    }
    e[count++] = (exr_meta_entry){"raysweep:zenith_deg", zen};
    e[count++] = (exr_meta_entry){"raysweep:azimuth_deg", az};
  }
  exr_meta meta = {.entries = e, .count = count};
  rsw_status st = exr_write_image(path, img->width, img->height, img->channels, img->channel_names, img->data,
                                  img->half, &meta, err);
  free(zen);
  free(az);
  return st;
}
