/* 8- and 16-bit image files for bitmap textures: PNG (libpng) and JPEG
 * (libjpeg). This header mentions none of their types; the one kernel
 * file that includes png.h and jpeglib.h is image_ldr.c (common/image_png.c
 * writes the quick-look PNGs).
 *
 * Decoded samples are the stored code values scaled to [0, 1] (v / 255,
 * or v / 65535 for 16-bit PNGs), with no transfer curve applied: the
 * caller decides (Mitsuba's bitmap decodes sRGB unless `raw`). Palette
 * PNGs are expanded to RGB, low bit depths to 8 bits; alpha is dropped.
 * Pixels are float32, interleaved HWC, 1 (grey) or 3 (RGB) channels, row
 * 0 the top of the image. */
#ifndef RSW_KERNEL_IMAGE_LDR_H
#define RSW_KERNEL_IMAGE_LDR_H

#include <stdbool.h>
#include <stddef.h>

#include "rsw_error.h"

typedef enum ldr_format {
  LDR_NONE, /* neither: e.g. OpenEXR */
  LDR_PNG,
  LDR_JPEG
} ldr_format;

/* A decoded image (owned; release with ldr_image_free). */
typedef struct ldr_image {
  int width, height;
  int n_channels; /* 1 or 3 */
  float *data;    /* width * height * n_channels */
} ldr_image;

/* Which format the file's first bytes say (LDR_NONE when neither or
 * unreadable: the caller's own reader reports the file). */
ldr_format ldr_sniff(const char *path);

/* Read a PNG or JPEG file. Writes *out only on success. Errors name the
 * file: RSW_ERR_FILE (missing, unreadable, corrupt, truncated, not PNG or
 * JPEG), RSW_ERR_LIMIT (more than 2^28 samples), RSW_ERR_NOMEM.
 * Thread-safe. */
rsw_status ldr_read_image(const char *path, ldr_image *out, rsw_err *err);

/* Free the pixels and zero *img; NULL is a no-op. */
void ldr_image_free(ldr_image *img);

/* The sRGB decoding (IEC 61966-2-1): c / 12.92 for c <= 0.04045, else
 * ((c + 0.055) / 1.055)^2.4. */
double srgb_to_linear(double c);

#endif
