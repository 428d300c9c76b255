/* A developed film and its planes beyond radiance (brdf, brf,
 * radiance_stderr): the types a render fills (render.h) and what
 * films/film_planes.c does with them. */
#ifndef RSW_FILMS_FILM_PLANES_H
#define RSW_FILMS_FILM_PLANES_H

#include "../kernel.h"

/* render_opts.quantities: L / E_h (sr^-1) and pi L / E_h (dimensionless),
 * Eradiate's BRDF and BRF, with E_h the horizontal irradiance
 * (render_horizontal_irradiance). */
enum {
  RENDER_Q_BRDF = 1u << 0,
  RENDER_Q_BRF = 1u << 1
};

/* The RENDER_Q_* bit of a quantity name: "brdf", "brf", or "radiance"
 * (0: always in a film). false for any other name. */
bool render_quantity_bit(const char *name, unsigned *bit);
/* "radiance, brdf, brf", for messages. */
#define RENDER_QUANTITY_NAMES "radiance, brdf, brf"

/* A named per-pixel array of a film beyond its radiance, with the film's
 * width, height and channels (HWC float32, row 0 on top). Names are
 * static: "brdf", "brf", "radiance_stderr" (the NetCDF variable names,
 * which other formats use as the prefix of a channel: "brf.Y"). */
#define FILM_MAX_PLANES   3
/* The most channels a film has: rgb_polarized's S0..S3 per colour. */
#define FILM_MAX_CHANNELS 12
typedef struct film_plane {
  const char *name;
  const char *units;                            /* CF/UDUNITS text: "sr-1", "1", radiance's units */
  const char *long_name;                        /* CF long_name */
  const char *channel_names[FILM_MAX_CHANNELS]; /* "<name>.<film channel>", static */
  float *data;                                  /* a counted block (film_pixels_new) */
} film_plane;

/* A developed film: HWC float32, row 0 = first (top) row. */
typedef struct film_image {
  int width, height, channels;
  const char *channel_names[FILM_MAX_CHANNELS]; /* static: "R","G","B", "Y", "S0".."S3", "S0.Y".., "S0.R".. */
  float *data;                                  /* a counted block (film_pixels_new) */
  bool half;                                    /* the film asked for float16 storage */
  /* What was rendered (for metadata). */
  uint32_t spp;
  uint64_t seed;
  double wavelength;
  rsw_variant variant;
  bool polarized; /* a polarized variant's film (channels S0.Y..S3.Y, or S0.R..S3.B) */
  /* Viewing zenith, azimuth (degrees) of each pixel, 2 per pixel,
   * row-major; NULL when the sensor has no pixel_angles op. A counted
   * block (film_angles_new): films whose angles are the same (a bundle's
   * pages, a job's contexts, a film and its copies) hold one, and
   * film_image_free lets go of it. Never written once a film has it. */
  double *angles;
  /* Rays that could not be resolved (render_stats.unresolved, UNRESOLVED_WHY:
   * within ~1e-5 rad of horizontal, still inside the slab after 65,536
   * walls), each counted as blocked / ending its path. Non-zero means the
   * film depends on that policy; written to the film's metadata. */
  uint64_t unresolved_rays;
  /* Calls to environment plugins whose answer the render replaced by black
   * or a dropped sample (a NaN or negative radiance, a bad pdf or
   * direction: env_plugin.c) during the render that made this film, and
   * the first one's message; written to the film's metadata. */
  uint64_t plugin_failures;
  char plugin_failure[256];
  /* Values of the image and its planes that are not finite (inf, NaN): 0
   * for any film of a scene within the parameter bounds (RSW_MAX_MAGNITUDE),
   * but counted rather than assumed (film_image_nonfinite). */
  uint64_t nonfinite;
  /* The instruction set the batched shading ran (core/isa.h: "avx512",
   * "avx2", "sse2", "generic"; static), or NULL when not known (a film restored
   * from a state directory). */
  const char *isa;
  /* Planes beyond radiance, in the fixed order brdf, brf,
   * radiance_stderr (those asked for). */
  film_plane planes[FILM_MAX_PLANES];
  int n_planes;
  /* brdf / brf films: the horizontal irradiance E_h the radiance was
   * divided by, per film channel (W m^-2 [nm^-1]). */
  bool has_irradiance;
  double irradiance[FILM_MAX_CHANNELS];
  /* Scenes with one directional emitter: the sun's zenith and azimuth
   * (degrees, Eradiate's convention: zenith from +z, azimuth from +x
   * counter-clockwise; the light travels along -(sin θ cos φ, sin θ sin φ,
   * cos θ)), render_sun_angles. */
  bool has_sun;
  double sun_zenith, sun_azimuth;
} film_image;

/* E_h, the irradiance of the scene's directional emitters on a horizontal
 * surface (world +z up, Eradiate's convention) at the prepared
 * wavelength: the sum over every `directional` emitter of its irradiance
 * times the cosine of its zenith angle (emitters at or below the horizon
 * add nothing). Eradiate divides by the same (its extract_irradiance:
 * irradiance * cos(sza)). Call after scene_prepare. RSW_ERR_INVALID
 * (where "quantities") when no directional emitter lights the horizontal
 * from above. */
rsw_status render_horizontal_irradiance(const scene *sc, color *e_h, rsw_err *err);

/* The angles of the scene's one directional emitter (render.h
 * film_image.has_sun), at the prepared state: false when the scene has
 * none or several. */
bool render_sun_angles(const scene *sc, double *zenith_deg, double *azimuth_deg);

/* What a render with these planes needs, checked before it starts (so a
 * job can refuse a request up front): variance needs sensor's film to use
 * the box rfilter and spp (after the sampler's rounding; 0: the sampler's
 * sample_count) >= 2; brdf and brf need a directional emitter in the
 * scene. RSW_ERR_INVALID with where "variance" or "quantities". */
rsw_status render_check_planes(const scene *sc, size_t sensor, uint32_t spp, unsigned quantities,
                               bool variance, rsw_err *err);

/* The memory planes add to a render of sensor se beyond sensor_film_bytes
 * (scene.h), in bytes: the moment accumulators (variance), each plane and
 * its encoded copy, and the interleaved copy the encoders make.
 * Saturates at UINT64_MAX. */
uint64_t render_planes_bytes(const sensor *se, rsw_variant variant, unsigned quantities, bool variance);

/* A film's channels, radiance then every plane's: names (static) into
 * names[] (room for FILM_MAX_CHANNELS * (1 + FILM_MAX_PLANES)) and the count. */
int film_image_all_channels(const film_image *img, const char **names);
/* The film's radiance and planes interleaved per pixel in the order of
 * film_image_all_channels (HWC; malloc'ed, free()), or NULL when out of
 * memory. */
float *film_image_interleaved(const film_image *img);
/* Give img (radiance channels set, data NULL) its planes by name (the
 * channel lists of film_image_all_channels past the radiance ones), and
 * split the interleaved pixels into data and planes (all allocated here;
 * film_image_free). false when a name is no plane, or out of memory. */
bool film_image_split(film_image *img, const char *const *plane_names, int n_planes, const float *all);
/* Name, units, long name and channel names of plane `name` (one of
 * "brdf", "brf", "radiance_stderr") for img's channels; p->data untouched. */
void film_plane_init(const film_image *img, const char *name, film_plane *p);
/* Counted blocks, for a film's pixels and its angles: films with the
 * same values (a film and its copies, a bundle's pages' angles, a job's
 * contexts' angles) hold one block, never written once a film has it.
 * film_angles_new: 2 doubles for each of pixels (film_image.angles);
 * film_pixels_new: values floats (film_image.data and each plane's data).
 * NULL when out of memory. *_ref: one more holder of the block (NULL:
 * none), returned; *_unref: one fewer, freed with the last. Thread-safe
 * (the counts are atomic). */
double *film_angles_new(size_t pixels);
double *film_angles_ref(double *a);
void film_angles_unref(double *a);
float *film_pixels_new(size_t values);
float *film_pixels_ref(float *p);
void film_pixels_unref(float *p);

/* *dst: src, holding its pixels, planes and angles (one more reference
 * to each; release with film_image_free). Never fails: nothing is
 * copied. The film's values are never written once it is made, so the
 * two stay equal. */
void film_image_share(const film_image *src, film_image *dst);
/* True when name is a plane ("brdf", "brf", "radiance_stderr"). */
bool film_plane_known(const char *name);
/* The static string of a film channel name ("R", "Y", "S0", "S0.Y", ...;
 * film_image.channel_names holds these), or NULL for an unknown one. */
const char *film_channel_static(const char *name);
/* The plane called name, or NULL. */
const film_plane *film_image_plane(const film_image *img, const char *name);

/* Release img's pixels, angles and planes (the descriptions stay). */
void film_image_free(film_image *img);
/* How many values of the image and its planes are inf or NaN. */
uint64_t film_image_nonfinite(const film_image *img);

#endif
