/* OpenEXR image files: write a film's pixels, read a bitmap texture or an
 * environment map. This header mentions none of OpenEXR's types; the one
 * file that includes openexr.h is image_exr.c.
 *
 * Pixels are float32, interleaved HWC (pixel (x, y), channel c is at
 * data[(y * width + x) * n_channels + c]), row 0 is the top of the image
 * (EXR's increasing-y scanline order, the data window's first row). */
#ifndef RSW_KERNEL_IMAGE_EXR_H
#define RSW_KERNEL_IMAGE_EXR_H

#include <stdbool.h>
#include <stddef.h>

#include "rsw_error.h"

/* Largest image either direction accepts, in samples (width x height x
 * channels): 2^28 floats = 1 GiB. */
#define EXR_MAX_SAMPLES  ((size_t)1 << 28)
/* Most channels a file may have. */
#define EXR_MAX_CHANNELS 64

/* One string attribute of the header ("key" -> "value"). */
typedef struct exr_meta_entry {
  const char *key;
  const char *value;
} exr_meta_entry;

/* Extra header content for exr_write_image(). Borrowed for the call. */
typedef struct exr_meta {
  const exr_meta_entry *entries; /* written as EXR string attributes */
  size_t count;
  /* false (default): ZIP compression, 16 lines a chunk; a chunk that
   * does not compress smaller is stored raw (see image_exr.c on OpenEXR
   * 3.1.5's writer). */
  bool uncompressed;
} exr_meta;

/* A decoded image (owned; release with exr_image_free). */
typedef struct exr_image {
  int width, height; /* of the data window */
  int n_channels;
  char **channel_names; /* n_channels, in the file's (alphabetical) order */
  float *data;          /* width * height * n_channels, HWC, row 0 = top */
  /* String attributes of the header, in file order (n_meta of each). */
  size_t n_meta;
  char **meta_keys;
  char **meta_values;
} exr_image;

/* Write a single-part scanline EXR.
 * width, height >= 1; n_channels in [1, EXR_MAX_CHANNELS] with distinct
 * names (e.g. {"R","G","B"} or {"Y"}); data is HWC float32 in the order of
 * channel_names (any order: the file stores channels alphabetically and
 * each is taken from its own position). half selects float16 samples
 * (round to nearest even; values beyond the half range become +-inf).
 * The file is written to "<path>.tmp.<pid>" and renamed over path only
 * once complete, so a failure leaves path as it was and no temp file.
 * Borrows every argument. Thread-safe for distinct paths.
 * Errors: RSW_ERR_INVALID (arguments), RSW_ERR_LIMIT (size),
 * RSW_ERR_IO (cannot create/write/rename), all naming path. */
rsw_status exr_write_image(const char *path, int width, int height, int n_channels,
                           const char *const *channel_names, const float *data, bool half,
                           const exr_meta *meta_or_NULL, rsw_err *err);

/* Encode the same file exr_write_image would write into memory instead:
 * *bytes_out (malloc'ed, free() it) holds *len_out bytes of a complete EXR.
 * Arguments and errors as for exr_write_image (errors name
 * "(EXR in memory)"); outputs are written only on success. Thread-safe. */
rsw_status exr_encode_image(int width, int height, int n_channels, const char *const *names,
                            const float *data, bool half, const exr_meta *meta_or_NULL, void **bytes_out,
                            size_t *len_out, rsw_err *err);

/* Read part 0 of a scanline or tiled (level 0 of a mip/rip map) EXR whose
 * channels are HALF, FLOAT or UINT and not subsampled, into float32 HWC.
 * Writes *out only on success; release it with exr_image_free.
 * Errors name the file: RSW_ERR_FILE (missing, unreadable, corrupt or
 * truncated), RSW_ERR_UNSUPPORTED (deep data, subsampled channels),
 * RSW_ERR_LIMIT (too large), RSW_ERR_NOMEM. Thread-safe. */
rsw_status exr_read_image(const char *path, exr_image *out, rsw_err *err);

/* The same from the len bytes of an EXR file in memory (borrowed), e.g.
 * the daemon's image/x-exr answer; label names it in errors (NULL:
 * "(EXR in memory)"). */
rsw_status exr_decode_image(const void *bytes, size_t len, const char *label, exr_image *out, rsw_err *err);

/* Index of the channel called name, or -1. */
int exr_image_channel(const exr_image *img, const char *name);

/* Value of the string attribute key, or NULL (borrowed from img). */
const char *exr_image_meta(const exr_image *img, const char *key);

/* Free what exr_read_image allocated and zero *img; NULL is a no-op. */
void exr_image_free(exr_image *img);

#endif
