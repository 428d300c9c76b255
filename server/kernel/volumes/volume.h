/* Volumes (constvolume, gridvolume): what the plugins share and what media
 * and phase functions call. The struct and its ops are in kernel.h; the
 * loader getter ld_volume() is declared in scene/loader.h. */
#ifndef RSW_VOLUMES_VOLUME_H
#define RSW_VOLUMES_VOLUME_H

#include "../kernel.h"
#include "../scene/loader.h"
#include "../scene/params.h"

/* Cell index i (any integer) of an axis of n cells as the grid's wrap mode
 * (volume.wrap) reaches it: clamped to [0, n - 1], periodic in n
 * (repeat), or reflected at each edge (mirror). */
static inline int volume_wrap_index(int i, int n, int wrap) {
  switch (wrap) {
  case VOLUME_WRAP_REPEAT: i %= n; return i < 0 ? i + n : i;
  case VOLUME_WRAP_MIRROR:
    i %= 2 * n;
    if (i < 0) i += 2 * n;
    return i >= n ? 2 * n - 1 - i : i;
  default: return i < 0 ? 0 : i >= n ? n - 1 : i;
  }
}

/* A sphericalcoordsvolume's shell (its rmin, rmax, fills, and the unit
 * sphere's frame: to_world as given); false for any other volume. */
bool volume_sphere(const volume *v, double *rmin, double *rmax, double *fillmin, double *fillmax,
                   const xform **sph);

/* Value at world point p (kernel.h volume_ops.eval). */
static inline color volume_eval(const volume *v, vec3 p) {
  return v->ops->eval(v, p);
}
/* Its first channel (Mitsuba's eval_1: a scalar field such as a blend
 * weight; in mono every channel holds the same value). */
static inline double volume_eval_1(const volume *v, vec3 p) {
  return v->ops->eval(v, p).c[0];
}

/* The values at page p of a bundle of pages (volume_ops.page_data), laid
 * out as v->data. */
static inline const double *volume_page_data(const volume *v, int p) {
  return p > 0 && v->ops->page_data ? v->ops->page_data(v, p) : v->data;
}

/* Whether v's values depend on the render's wavelength (a grid with a
 * wavelength axis, a constvolume holding a tabulated spectrum). */
static inline bool volume_spectral(const volume *v) {
  const plugin *pl = v->base.plugin;
  return pl && pl->spectral && pl->spectral(&v->base);
}

/* Set up the common part: ops, to_world (the unit cube -> world), the box,
 * an unconstrained range. */
void volume_init(volume *v, const volume_ops *ops, const xform *to_world);
/* World bounds of the unit cube under v->to_world (after to_world changed). */
void volume_update_bbox(volume *v);
/* Reads `to_world` (default identity) and checks it can be inverted. */
rsw_status volume_read_to_world(loader *ld, node *n, xform *out);
/* Reports `to_world` (a spectral update: a volume's box is read at
 * sampling time only, no acceleration structure holds it). */
void volume_traverse_to_world(volume *v, param_visitor *pv);

/* Most values a list property may hold (2^28: 2 GiB as doubles). */
#define VOLUME_MAX_VALUES ((size_t)1 << 28)

/* A list of numbers: a JSON array (or a single number, or the 3-vector a
 * three-number array reads as), or a string of numbers separated by
 * commas and/or white space (Mitsuba's tabphase `values`; how XML gives
 * inline data). *out is malloc'ed (free it), *n >= 1; *present (may be
 * NULL) tells whether the property was given (when absent *out = NULL,
 * *n = 0). Every value must be finite. */
rsw_status volume_read_numbers(loader *ld, node *n, const char *name, double **out, size_t *count,
                               bool *present);

/* A constvolume holding the (uniform) texture `value`; NULL when out of
 * memory. Not yet adopted by a scene. */
volume *constvolume_new(texture *value, rsw_variant variant, const char *id);

#endif
