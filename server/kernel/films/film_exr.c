/* A rendered film's EXR attributes and file (film_exr.h), through the one
 * EXR writer of the project (common/film_io.h). */
#include <stdlib.h>

#include "film_exr.h"

film_exr_info film_image_exr_info(const film_image *img, const char *sensor_id) {
  film_exr_info info = film_exr_info_none();
  info.sensor = sensor_id;
  info.has_spp = info.has_seed = true;
  info.spp = img->spp;
  info.seed = img->seed;
  info.variant = variant_name(img->variant, img->polarized);
  if (img->variant == VARIANT_MONO) info.wavelength_nm = img->wavelength;
  info.angles = img->angles;
  info.unresolved_rays = img->unresolved_rays;
  info.plugin_failures = img->plugin_failures;
  info.plugin_failure = img->plugin_failure;
  info.isa = img->isa;
  if (img->has_irradiance) {
    info.irradiance = img->irradiance;
    info.n_irradiance = img->channels;
  }
  return info;
}

rsw_status film_image_write_exr(const film_image *img, const char *path, const char *sensor_id,
                                rsw_err *err) {
  film_exr_info info = film_image_exr_info(img, sensor_id);
  if (!img->n_planes)
    return film_exr_write(path, img->width, img->height, img->channels, img->channel_names, img->data,
                          img->half, &info, err);
  const char *names[FILM_MAX_CHANNELS * (1 + FILM_MAX_PLANES)];
  int n = film_image_all_channels(img, names);
  float *all = film_image_interleaved(img);
  if (!all) return rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory for the film's planes");
  rsw_status st = film_exr_write(path, img->width, img->height, n, names, all, img->half, &info, err);
  free(all);
  return st;
}
