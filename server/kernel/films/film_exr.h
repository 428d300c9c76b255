/* A developed film as OpenEXR (films/film_exr.c, over common/film_io.h). */
#ifndef RSW_FILMS_FILM_EXR_H
#define RSW_FILMS_FILM_EXR_H

#include "film_io.h"
#include "film_planes.h"

/* The EXR attributes of a rendered film (film_io.h): sensor, spp, seed,
 * variant, the wavelength in mono, the per-pixel viewing angles when the
 * film has them, the unresolved-ray count when non-zero. Borrows img and sensor_id (the info points into them). */
film_exr_info film_image_exr_info(const film_image *img, const char *sensor_id);

/* Write a developed film as OpenEXR (float32, or float16 when the film asks
 * for it), through a temporary file renamed on success, with
 * film_image_exr_info's attributes (film_exr_write). */
rsw_status film_image_write_exr(const film_image *img, const char *path, const char *sensor_id, rsw_err *err);

#endif
