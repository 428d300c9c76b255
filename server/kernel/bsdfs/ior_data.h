/* Index-of-refraction data: Mitsuba's named dielectric indices and the
 * tabulated complex indices (eta + i k) of the conductor presets.
 *
 * Sources: mitsuba3 include/mitsuba/render/ior.h (dielectric table);
 * Mitsuba's data/ios/<material>.{eta,k}.spd files (conductors; they come
 * from the luxpop.com database, wavelengths in nm). The numbers are facts
 * carried over; see ior_data.c. */
#ifndef RSW_BSDFS_IOR_DATA_H
#define RSW_BSDFS_IOR_DATA_H

#include <stdbool.h>
#include <stddef.h>

#include "../core/vec.h"
#include "../kernel.h"

/* Named dielectric index ("bk7", "air", "water", ...; case-insensitive as
 * in Mitsuba). Returns false when the name is unknown. */
bool ior_dielectric_lookup(const char *name, double *ior);
/* Comma-separated list of the known names (for error messages). */
const char *ior_dielectric_names(void);

typedef struct ior_sample {
  double wl, eta, k; /* nm, real part, imaginary part */
} ior_sample;

typedef struct ior_conductor {
  const char *name; /* Mitsuba's material name ("Au", case-sensitive) */
  const ior_sample *s;
  size_t n;
} ior_conductor;

/* The preset of that name, or NULL ("none" is not a preset: the caller
 * handles it). */
const ior_conductor *ior_conductor_lookup(const char *name);
/* Comma-separated list of the presets (for error messages). */
const char *ior_conductor_names(void);

/* eta and k at wavelength wl (nm) by linear interpolation. Returns false
 * when wl lies outside the table (no extrapolation). */
bool ior_conductor_eval(const ior_conductor *c, double wl, double *eta, double *k);

/* Wavelengths (nm) at which the rgb variant evaluates spectral tables:
 * red, green, blue. A deliberate approximation: Mitsuba integrates the
 * spectrum against the CIE matching functions and converts to sRGB
 * (spectrum_to_srgb); sampling it at three representative wavelengths
 * keeps the data path simple at the price of small colour differences. */
#define IOR_RGB_WL_R 645.0
#define IOR_RGB_WL_G 526.0
#define IOR_RGB_WL_B 444.0

/* eta and k of a preset for a render context: in mono at rc->wavelength,
 * in rgb at the three wavelengths above. On a wavelength outside the
 * table, fails with RSW_ERR_RANGE naming the material (where = object
 * id, may be NULL). */
rsw_status ior_conductor_for_ctx(const ior_conductor *c, const render_ctx *rc, color *eta, color *k,
                                 rsw_err *err, const char *where);

#endif
