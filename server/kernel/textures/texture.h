/* Texture helpers shared by plugins. */
#ifndef RSW_TEXTURES_TEXTURE_H
#define RSW_TEXTURES_TEXTURE_H

#include "../kernel.h"
#include "../scene/node.h"

/* A `uniform` texture holding a spectrum; its value is re-evaluated by
 * prepare() for each render (wavelength in mono). The spectrum is copied.
 * Returned owned; free with plugin->destroy, or hand it to the scene with
 * ld_adopt(). */
texture *uniform_texture_new(const spectrum *s, const char *id);
/* Shorthand for a constant (uniform spectrum v, already prepared). */
texture *uniform_texture_const(double v, const char *id);
/* Record where in the document the value came from, for error messages
 * at render time (copied). */
bool uniform_texture_set_where(texture *t, const char *where);
/* The spectrum a uniform texture holds (NULL for other textures). */
const spectrum *uniform_texture_spectrum(const texture *t);
/* Replace it (copied). The value used for rendering is recomputed by the
 * next prepare(); uniform and rgb values take effect at once as well.
 * Returns false when out of memory (then nothing changed). */
bool uniform_texture_set_spectrum(texture *t, const spectrum *s);
/* Copy s into *out (owned: spectrum_free), or false when out of memory. */
bool uniform_spectrum_copy(spectrum *out, const spectrum *s);
/* Exchange the texture's spectrum with *s (both owned), without
 * allocating: so that an update can prepare the new value first and undo
 * it without a failure. Returns false (nothing changed) if t is not a
 * uniform texture. */
bool uniform_texture_swap_spectrum(texture *t, spectrum *s);
/* The uniform texture's current value, at the page rsw_page names (for
 * parameter tables, tests and the batched BSDF ops). */
bool uniform_texture_value(const texture *t, color *out);

#endif
