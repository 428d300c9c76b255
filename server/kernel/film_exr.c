/* A rendered film's EXR attributes and file (render.h), through the one
 * EXR writer of the project (common/film_io.h). */
#include "film_io.h"
#include "render.h"

film_exr_info film_image_exr_info(const film_image *img, const char *sensor_id) {
  film_exr_info info = film_exr_info_none();
  info.sensor = sensor_id;
  info.has_spp = info.has_seed = true;
  info.spp = img->spp;
  info.seed = img->seed;
  info.variant = img->variant == VARIANT_MONO ? "mono" : "rgb";
  if (img->variant == VARIANT_MONO) info.wavelength_nm = img->wavelength;
  info.angles = img->angles;
  info.unresolved_rays = img->unresolved_rays;
  return info;
}

rsw_status film_image_write_exr(const film_image *img, const char *path, const char *sensor_id,
                                rsw_err *err) {
  film_exr_info info = film_image_exr_info(img, sensor_id);
  return film_exr_write(path, img->width, img->height, img->channels, img->channel_names, img->data,
                        img->half, &info, err);
}
