/* A second, independent EXR reader for tests: OpenEXR's C++ library (Imf,
 * libOpenEXR-3_1), which in Debian's 3.1 has its own chunk decoding and
 * zlib decompression and does not use OpenEXR Core. C callable; built
 * from imf_read.cpp and linked only into the tests that name it in the
 * Makefile. */
#ifndef RSW_TEST_IMF_READ_H
#define RSW_TEST_IMF_READ_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#define IMF_READ_MAX_CHANNELS 16

/* A decoded scanline EXR: float32, HWC, channels in the file's
 * (alphabetical) order, row 0 = top of the data window. */
typedef struct imf_image {
  int width, height, n_channels;
  char names[IMF_READ_MAX_CHANNELS][64];
  float *data; /* malloc'ed; free() it */
} imf_image;

/* Read part 0 of the file at path with Imf::InputFile (HALF and FLOAT
 * channels are converted to float by Imf). Returns 0 and fills *out, or -1
 * and writes the library's message into msg (msg_len bytes). */
int imf_read_float(const char *path, imf_image *out, char *msg, size_t msg_len);

/* The value of the string attribute key of part 0 (malloc'ed, free() it),
 * or NULL when there is none or it is not a string. */
char *imf_read_string_attr(const char *path, const char *key);

#ifdef __cplusplus
}
#endif

#endif
