/* A sweep as one NetCDF-4 dataset (CF conventions), readable by
 * xarray.open_dataset with no options. The one writer of the project:
 * raysweepd's GET /v1/jobs/{id}/dataset, libraysweep's rsw_dataset (so
 * `raysweep sweep --format nc`, `fetch --format nc` and `merge`) all go
 * through nc_dataset_write / nc_dataset_encode. This header mentions none
 * of libnetcdf's types; dataset_nc.c is the one file that includes
 * netcdf.h.
 *
 * Layout of the file (names without a sensor prefix when the dataset holds
 * one sensor; with several, every per-sensor name below starts with
 * "<sensor>_", the sensor id with characters other than [A-Za-z0-9_]
 * replaced by '_'):
 *
 *   dimensions   the contexts' coords when they form a complete grid (each
 *                coord one dimension, its distinct values sorted: numbers
 *                ascending, strings bytewise; the first coord named is the
 *                first dimension), else one dimension "context";
 *                then y, x (film rows from the top, columns) and, for
 *                films of more than one channel, channel.
 *   coordinates  grid: one variable per coord (float64 or string) along
 *                its dimension; otherwise "context" (the ids) along
 *                context and each coord a variable along context.
 *                context (the ids; grid: over the grid's dimensions),
 *                wavelength (nm; mono, unless a coord is named wavelength),
 *                channel (the channel names), and for distant-family
 *                sensors vza, vaa: each pixel's viewing zenith and azimuth
 *                (degrees, Eradiate's convention), over (y, x) when every
 *                film of the sensor has the same angles, else over
 *                (contexts..., y, x).
 *   data         one float32 variable per sensor and quantity (radiance,
 *                and those of nc_quantity_find) over (contexts..., y, x
 *                [, channel]); a film that is missing (failed, or not
 *                rendered yet in a partial dataset) is NaN (_FillValue);
 *                brf_stderr = pi radiance_stderr / E_h where a film has
 *                both brf and radiance_stderr; irradiance (E_h, float64)
 *                per sensor over (contexts... [, channel]) where films
 *                have it (unless a coord of that name exists); sza, saa
 *                (degrees) as coordinates over the contexts where films
 *                name one directional emitter (the same);
 *                jobs with bands: per-wavelength variables over
 *                (contexts..., wavelength, y, x [, channel]) with
 *                "wavelength" the node wavelengths, and the band
 *                variables radiance_srf, radiance_srf_stderr, brdf_srf,
 *                brf_srf, brf_srf_stderr over (contexts..., band, y, x
 *                [, channel]) with irradiance_srf over (contexts...,
 *                band [, channel]);
 *                Stokes films (stokes.h: channels S0..S3, S0.Y..S3.Y,
 *                S0.R..S3.B): a dimension and coordinate "stokes" (S0..S3)
 *                after x on every quantity, channel then over the colours
 *                (none for one), and dolp (1) and aolp (degrees) over the
 *                quantity's dimensions less stokes, derived from the
 *                radiance's Stokes vector (dolp_srf, aolp_srf from
 *                radiance_srf); irradiance per colour;
 *                seed (uint64) per film over the contexts' dimensions;
 *                spp as a global attribute when every film has the same,
 *                else a uint32 variable; unresolved_rays when any is not 0;
 *                plugin_failures (uint64) and plugin_failure (string) per
 *                film, always (0 and "" for a film without failures; a
 *                stable schema), _FillValue on plugin_failures where a
 *                film is missing;
 *   attributes   Conventions, title, source, raysweep_version, scene,
 *                revision, variant, seed (the job seed), spp, job,
 *                films_missing when some film is missing, and warnings
 *                (the job's, a sweep that changes nothing, one a line).
 *
 * Thread-safe: libnetcdf is not, so every call here holds one process-wide
 * lock while it runs. */
#ifndef RSW_COMMON_DATASET_NC_H
#define RSW_COMMON_DATASET_NC_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "rsw_error.h"

/* The most coords a context may carry, and their names' longest length. */
#define NC_MAX_COORDS     8
#define NC_MAX_COORD_NAME 64
/* The longest string value of a coord, in bytes. */
#define NC_MAX_COORD_STR  256

/* One per-pixel quantity a dataset variable can hold: its name (the
 * variable's, after the sensor prefix) and CF attributes. Adding a
 * quantity to the datasets is one line in dataset_nc.c's table plus the
 * line that hands its data over (nc_var) where the films are gathered
 * (server/service/dataset.c, client/lib/dataset.c). */
typedef struct nc_quantity {
  const char *name;
  const char *long_name;
  const char *units_mono; /* CF/UDUNITS units, mono films */
  const char *units_rgb;  /* rgb films */
} nc_quantity;
/* The quantity called name, or NULL. */
const nc_quantity *nc_quantity_find(const char *name);

/* The coords of a job's contexts, one column per coord name: validated
 * and built by nc_coords_build. Owned; free with nc_coords_free. */
typedef struct nc_coord {
  char *name;
  bool is_string;
  double *num; /* n_contexts values (numbers) */
  char **str;  /* n_contexts values (strings) */
} nc_coord;
typedef struct nc_coords {
  nc_coord *c;
  size_t n, n_contexts;
} nc_coords;

/* Build the columns from the "coords" member of each of n contexts
 * (coords_json[i]: a cJSON object, or NULL when the context has none;
 * passed as void * so that this header needs no cJSON). Every context
 * must name the same coords (or none does), each a number or a string of
 * one type across contexts, at most NC_MAX_COORDS names of
 * [A-Za-z][A-Za-z0-9_]{0,63} that are not names the dataset uses itself
 * (x, y, channel, stokes, context, seed, spp, vza, vaa, unresolved_rays,
 * plugin_failures, plugin_failure, a quantity). A coord named sza, saa,
 * irradiance or irradiance_srf replaces the dataset's variable of that name. Errors name the JSON pointer "<prefix>/<i>/coords[/<name>]":
 * RSW_ERR_TYPE (not an object; not a number or string; types mixed
 * across contexts), RSW_ERR_INVALID (a name; a string too long or with a
 * control character; a non-finite number), RSW_ERR_MISSING (a context
 * lacks a coord the others have), RSW_ERR_LIMIT (too many),
 * RSW_ERR_NOMEM. out is written only on success. Borrows everything. */
rsw_status nc_coords_build(const void *const *coords_json, size_t n, const char *prefix, nc_coords *out,
                           rsw_err *err);
void nc_coords_free(nc_coords *c);
/* A deep copy of src into *out (RSW_ERR_NOMEM; *out written on success). */
rsw_status nc_coords_copy(const nc_coords *src, nc_coords *out, rsw_err *err);

/* One quantity of one film: name (a nc_quantity) and its height x width x
 * channels float32 values (HWC, row 0 = top). */
typedef struct nc_var {
  const char *name;
  const float *data;
} nc_var;

/* One film: which context (index into the dataset's contexts) and sensor,
 * its shape, what it was rendered with and its quantities. */
typedef struct nc_film {
  size_t context;
  const char *sensor;
  int width, height, channels;
  const char *const *channel_names; /* channels names */
  uint32_t spp;
  uint64_t seed;
  uint64_t unresolved_rays;
  const double *angles; /* NULL, or (zenith, azimuth) per pixel, degrees */
  const nc_var *vars;
  size_t n_vars;
  /* brdf / brf films: the horizontal irradiance E_h per channel (W m-2
   * [nm-1]), the variable "irradiance" ("irradiance_srf" for a band). */
  bool has_irradiance;
  double irradiance[4];
  /* One directional emitter: its zenith and azimuth (degrees, Eradiate's
   * convention), the context's sza and saa. */
  bool has_sun;
  double sun_zenith, sun_azimuth;
  /* Environment plugin answers (a non-finite or negative radiance, a bad
   * pdf or direction) the renderer replaced by black while making this film, and the first
   * one's message (NULL or "": none): the variables plugin_failures and
   * plugin_failure. */
  uint64_t plugin_failures;
  const char *plugin_failure;
  /* Jobs with bands: 1 + the index of the film's wavelength in
   * nc_dataset.nodes (a node film), or 1 + its band's index in
   * nc_dataset.band_ids (a band film, whose quantities are the *_srf
   * ones); 0 otherwise. */
  size_t node, band;
} nc_film;

/* What the dataset is about. Zero-initialise, set size, fill. */
typedef struct nc_dataset {
  size_t size; /* sizeof(nc_dataset) */
  const char *scene, *variant, *job; /* NULL: not written */
  bool has_revision, has_seed;
  uint64_t revision, seed; /* base revision; the job seed */
  size_t n_contexts;
  const char *const *context_ids; /* n_contexts, distinct */
  const double *wavelengths;      /* n_contexts (NaN: none), or NULL */
  const nc_coords *coords;        /* NULL or n == 0: no coords */
  const nc_film *films;           /* at most one per (context, sensor[, node or band]) */
  size_t n_films;
  const char *warnings; /* the job's warnings, one "code (coordinate): detail" a line; NULL: none */
  /* Jobs with bands: the node wavelengths (nm, ascending; the dimension
   * and coordinate "wavelength" of the per-wavelength variables) and the
   * band ids (the dimension and coordinate "band" of the *_srf ones). */
  size_t n_nodes, n_bands;
  const double *nodes;
  const char *const *band_ids;
  /* The most bytes a data variable is written from at once (0:
   * NC_SLAB_BYTES): a variable over that goes in slabs of whole images,
   * so that writing a dataset needs no copy of all its films' pixels at
   * once; the file is the same either way (each chunk is one image, and
   * the chunks go in the same order). */
  size_t slab_bytes;
} nc_dataset;

#define NC_SLAB_BYTES ((size_t)64 << 20)

/* Initialise libnetcdf (and HDF5: their run-time configuration, a few ms)
 * now rather than at the first nc_dataset_write, for a caller that has
 * time to spare before it writes. Thread-safe (serialised). */
void nc_dataset_init(void);

/* Write d to path (through "<path>.tmp.<pid>", renamed on success) or
 * encode it in memory (*bytes_out owned: free()). Borrows d. Errors:
 * RSW_ERR_INVALID (a film of another shape than its sensor's others, an
 * unknown quantity, a context index out of range, two films of one
 * (context, sensor), a name used twice), RSW_ERR_IO (libnetcdf, the
 * file), RSW_ERR_NOMEM. Thread-safe (serialised). */
rsw_status nc_dataset_write(const char *path, const nc_dataset *d, rsw_err *err);
rsw_status nc_dataset_encode(const nc_dataset *d, void **bytes_out, size_t *len_out, rsw_err *err);

#endif
