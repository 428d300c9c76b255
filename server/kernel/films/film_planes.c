/* A film's planes beyond radiance (film_planes.h): their names, channel names,
 * interleaving for the one-array formats (EXR channels, .npy), and the
 * horizontal irradiance the BRDF and BRF divide by. */
#include <math.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../scene/scene.h"
#include "../sensors/sensor_common.h"
#include "film_planes.h"

/* Every channel a film can have, and each plane's channel names in the
 * same order: "<plane>.<channel>" (EXR's layer.channel convention). */
enum {
  N_BASE = 24
};
static const char *const base_channels[N_BASE] = {
    "R",    "G",    "B",    "Y",    "S0",   "S1",   "S2",   "S3",   "S0.Y", "S1.Y", "S2.Y", "S3.Y",
    "S0.R", "S0.G", "S0.B", "S1.R", "S1.G", "S1.B", "S2.R", "S2.G", "S2.B", "S3.R", "S3.G", "S3.B",
};
static const char *const plane_names[FILM_MAX_PLANES] = {"brdf", "brf", "radiance_stderr"};
static const char *const plane_channels[FILM_MAX_PLANES][N_BASE] = {
    {
        "brdf.R",    "brdf.G",    "brdf.B",    "brdf.Y",    "brdf.S0",   "brdf.S1",
        "brdf.S2",   "brdf.S3",   "brdf.S0.Y", "brdf.S1.Y", "brdf.S2.Y", "brdf.S3.Y",
        "brdf.S0.R", "brdf.S0.G", "brdf.S0.B", "brdf.S1.R", "brdf.S1.G", "brdf.S1.B",
        "brdf.S2.R", "brdf.S2.G", "brdf.S2.B", "brdf.S3.R", "brdf.S3.G", "brdf.S3.B",
    },
    {
        "brf.R",    "brf.G",    "brf.B",    "brf.Y",    "brf.S0",   "brf.S1",   "brf.S2",   "brf.S3",
        "brf.S0.Y", "brf.S1.Y", "brf.S2.Y", "brf.S3.Y", "brf.S0.R", "brf.S0.G", "brf.S0.B", "brf.S1.R",
        "brf.S1.G", "brf.S1.B", "brf.S2.R", "brf.S2.G", "brf.S2.B", "brf.S3.R", "brf.S3.G", "brf.S3.B",
    },
    {
        "radiance_stderr.R",    "radiance_stderr.G",    "radiance_stderr.B",    "radiance_stderr.Y",
        "radiance_stderr.S0",   "radiance_stderr.S1",   "radiance_stderr.S2",   "radiance_stderr.S3",
        "radiance_stderr.S0.Y", "radiance_stderr.S1.Y", "radiance_stderr.S2.Y", "radiance_stderr.S3.Y",
        "radiance_stderr.S0.R", "radiance_stderr.S0.G", "radiance_stderr.S0.B", "radiance_stderr.S1.R",
        "radiance_stderr.S1.G", "radiance_stderr.S1.B", "radiance_stderr.S2.R", "radiance_stderr.S2.G",
        "radiance_stderr.S2.B", "radiance_stderr.S3.R", "radiance_stderr.S3.G", "radiance_stderr.S3.B",
    },
};

const char *film_channel_static(const char *name) {
  for (int k = 0; k < N_BASE; k++)
    if (strcmp(base_channels[k], name) == 0) return base_channels[k];
  return NULL;
}

static int plane_index(const char *name) {
  for (int i = 0; i < FILM_MAX_PLANES; i++)
    if (strcmp(plane_names[i], name) == 0) return i;
  return -1;
}

/* Name, units, long name and channel names of plane `which` (index into
 * plane_names) for img's channels; data stays as it is. */
static void plane_describe(const film_image *img, int which, film_plane *p) {
  static const char *const long_names[FILM_MAX_PLANES] = {"bi-directional reflection distribution function",
                                                          "bi-directional reflectance factor",
                                                          "standard error of the mean radiance"};
  p->name = plane_names[which];
  p->long_name = long_names[which];
  p->units = which == 0                     ? "sr-1"
             : which == 1                   ? "1"
             : img->variant == VARIANT_MONO ? "W m-2 sr-1 nm-1"
                                            : "W m-2 sr-1";
  for (int c = 0; c < img->channels && c < FILM_MAX_CHANNELS; c++) {
    p->channel_names[c] = NULL;
    for (int k = 0; k < N_BASE; k++)
      if (img->channel_names[c] && strcmp(img->channel_names[c], base_channels[k]) == 0)
        p->channel_names[c] = plane_channels[which][k];
  }
}

bool render_quantity_bit(const char *name, unsigned *bit) {
  static const struct {
    const char *name;
    unsigned bit;
  } q[] = {{"radiance", 0}, {"brdf", RENDER_Q_BRDF}, {"brf", RENDER_Q_BRF}};
  for (size_t i = 0; i < sizeof q / sizeof q[0]; i++)
    if (strcmp(q[i].name, name) == 0) {
      *bit = q[i].bit;
      return true;
    }
  return false;
}

rsw_status render_check_planes(const scene *sc, size_t sensor_index, uint32_t spp, unsigned quantities,
                               bool variance, rsw_err *err) {
  if (variance && sensor_index < sc->n_sensors) {
    const sensor *se = sc->sensors[sensor_index];
    const rfilter *f = se->film->filter;
    if (!(f->radius <= 0.5 + 1e-12))
      return rsw_fail(
          err, RSW_ERR_INVALID, "variance",
          "variance needs the box rfilter (radius 0.5); sensor '%s' splats with '%s' (radius %g), "
          "which spreads each sample over neighbouring pixels with unequal weights, so a pixel "
          "is no plain mean of its own independent samples and has no standard error",
          se->base.id ? se->base.id : "", f->base.plugin ? f->base.plugin->name : "?", f->radius);
    uint32_t n = spp ? spp : se->sampler->sample_count;
    if (se->sampler->ops->adjust_spp) n = se->sampler->ops->adjust_spp(se->sampler, n);
    if (n < 2)
      return rsw_fail(err, RSW_ERR_INVALID, "variance",
                      "variance needs at least 2 samples per pixel (spp is %u)", n);
  }
  if (quantities & (RENDER_Q_BRDF | RENDER_Q_BRF)) {
    bool any = false;
    for (size_t i = 0; i < sc->n_emitters && !any; i++)
      any = sc->emitters[i]->flags & EMITTER_DELTA_DIRECTION;
    if (!any)
      return rsw_fail(err, RSW_ERR_INVALID, "quantities",
                      "brdf and brf divide by the horizontal irradiance of the scene's directional emitters; "
                      "the scene has none");
  }
  return RSW_OK;
}

uint64_t render_planes_bytes(const sensor *se, rsw_variant variant, unsigned quantities, bool variance) {
  int c;
  (void)sensor_film_bytes(se, variant, &c);
  uint64_t n = (uint64_t)((quantities & RENDER_Q_BRDF) != 0) + ((quantities & RENDER_Q_BRF) != 0) + variance;
  if (!n) return 0;
  /* render.c: 3 doubles per channel of moments; a float per channel per
   * plane, twice (film and encoding), and the interleaved copy of all. */
  uint64_t per_pixel =
      (variance ? 3u * 8u * (uint64_t)c : 0) + 2u * 4u * (uint64_t)c * n + 4u * (uint64_t)c * (1 + n);
  const film *fm = se->film;
  uint64_t pixels = (uint64_t)(fm->width > 0 ? fm->width : 0) * (uint64_t)(fm->height > 0 ? fm->height : 0);
  if (pixels && per_pixel > UINT64_MAX / pixels) return UINT64_MAX;
  return pixels * per_pixel;
}

rsw_status render_horizontal_irradiance(const scene *sc, color *e_h, rsw_err *err) {
  color sum = col1(0);
  size_t n_dir = 0, n_lit = 0;
  surface_interaction ref;
  memset(&ref, 0, sizeof ref);
  ref.p = sc->bsphere_center;
  for (size_t i = 0; i < sc->n_emitters; i++) {
    const emitter *em = sc->emitters[i];
    if (!(em->flags & EMITTER_DELTA_DIRECTION)) continue;
    n_dir++;
    direction_sample ds;
    memset(&ds, 0, sizeof ds);
    /* A delta emitter's sample is its irradiance normal to the beam (pdf
     * 1), ds.d the unit direction towards it. */
    color e = em->ops->sample_direction(em, &ref, v2(0.5, 0.5), &ds);
    double mu = ds.d.z;
    if (mu <= 0) continue;
    n_lit++;
    sum = col_add(sum, col_scale(e, mu));
  }
  if (n_dir == 0)
    return rsw_fail(err, RSW_ERR_INVALID, "quantities",
                    "brdf and brf divide by the horizontal irradiance of the scene's directional emitters; "
                    "the scene has none");
  if (n_lit == 0)
    return rsw_fail(err, RSW_ERR_INVALID, "quantities",
                    "brdf and brf divide by the horizontal irradiance of the scene's directional emitters; "
                    "every one of its %zu lies at or below the horizon",
                    n_dir);
  *e_h = sum;
  return RSW_OK;
}

bool render_sun_angles(const scene *sc, double *zenith_deg, double *azimuth_deg) {
  const emitter *sun = NULL;
  for (size_t i = 0; i < sc->n_emitters; i++)
    if (sc->emitters[i]->flags & EMITTER_DELTA_DIRECTION) {
      if (sun) return false;
      sun = sc->emitters[i];
    }
  if (!sun) return false;
  surface_interaction ref;
  memset(&ref, 0, sizeof ref);
  ref.p = sc->bsphere_center;
  direction_sample ds;
  memset(&ds, 0, sizeof ds);
  (void)sun->ops->sample_direction(sun, &ref, v2(0.5, 0.5), &ds);
  /* ds.d points towards the sun: (sin θ cos φ, sin θ sin φ, cos θ). */
  direction_angles(ds.d, zenith_deg, azimuth_deg);
  return true;
}

int film_image_all_channels(const film_image *img, const char **names) {
  int n = 0;
  for (int c = 0; c < img->channels; c++) names[n++] = img->channel_names[c];
  for (int p = 0; p < img->n_planes; p++)
    for (int c = 0; c < img->channels; c++) names[n++] = img->planes[p].channel_names[c];
  return n;
}

float *film_image_interleaved(const film_image *img) {
  size_t px = (size_t)img->width * (size_t)img->height, C = (size_t)img->channels;
  size_t T = C * (size_t)(1 + img->n_planes);
  float *out = malloc(px * T * sizeof *out);
  if (!out) return NULL;
  for (size_t i = 0; i < px; i++) {
    memcpy(&out[i * T], &img->data[i * C], C * sizeof *out);
    for (int p = 0; p < img->n_planes; p++)
      memcpy(&out[i * T + C * (size_t)(1 + p)], &img->planes[p].data[i * C], C * sizeof *out);
  }
  return out;
}

bool film_image_split(film_image *img, const char *const *names, int n_planes, const float *all) {
  if (n_planes < 0 || n_planes > FILM_MAX_PLANES) return false;
  size_t px = (size_t)img->width * (size_t)img->height, C = (size_t)img->channels;
  size_t T = C * (size_t)(1 + n_planes);
  img->n_planes = 0;
  for (int p = 0; p < n_planes; p++) {
    int w = plane_index(names[p]);
    if (w < 0 || (p > 0 && w <= plane_index(img->planes[p - 1].name))) return false;
    plane_describe(img, w, &img->planes[p]);
    for (size_t c = 0; c < C; c++)
      if (!img->planes[p].channel_names[c]) return false;
  }
  img->data = film_pixels_new(px * C);
  bool ok = img->data != NULL;
  for (int p = 0; p < n_planes; p++) {
    img->planes[p].data = film_pixels_new(px * C);
    if (!img->planes[p].data) ok = false;
    img->n_planes = p + 1; /* so film_image_free releases what exists */
  }
  if (!ok) return false;
  for (size_t i = 0; i < px; i++) {
    memcpy(&img->data[i * C], &all[i * T], C * sizeof(float));
    for (int p = 0; p < n_planes; p++)
      memcpy(&img->planes[p].data[i * C], &all[i * T + C * (size_t)(1 + p)], C * sizeof(float));
  }
  return true;
}

/* A block's count, before its values (16 bytes: they stay aligned as
 * malloc's). */
typedef struct block_head {
  _Atomic size_t refs;
  size_t pad;
} block_head;

static void *block_new(size_t bytes) {
  if (bytes > SIZE_MAX - sizeof(block_head)) return NULL;
  block_head *h = malloc(sizeof *h + (bytes ? bytes : 1));
  if (!h) return NULL;
  atomic_init(&h->refs, 1);
  return h + 1;
}

static void *block_ref(void *b) {
  if (b) atomic_fetch_add(&((block_head *)b - 1)->refs, 1);
  return b;
}

static void block_unref(void *b) {
  if (!b) return;
  block_head *h = (block_head *)b - 1;
  if (atomic_fetch_sub(&h->refs, 1) == 1) free(h);
}

double *film_angles_new(size_t pixels) {
  return pixels > SIZE_MAX / (2 * sizeof(double)) ? NULL : block_new(pixels * 2 * sizeof(double));
}

double *film_angles_ref(double *a) {
  return block_ref(a);
}

void film_angles_unref(double *a) {
  block_unref(a);
}

float *film_pixels_new(size_t values) {
  return values > SIZE_MAX / sizeof(float) ? NULL : block_new(values * sizeof(float));
}

float *film_pixels_ref(float *p) {
  return block_ref(p);
}

void film_pixels_unref(float *p) {
  block_unref(p);
}

void film_image_share(const film_image *src, film_image *dst) {
  film_image d = *src;
  d.data = film_pixels_ref(src->data);
  d.angles = film_angles_ref(src->angles);
  for (int p = 0; p < src->n_planes; p++) d.planes[p].data = film_pixels_ref(src->planes[p].data);
  *dst = d;
}

bool film_plane_known(const char *name) {
  return plane_index(name) >= 0;
}

const film_plane *film_image_plane(const film_image *img, const char *name) {
  for (int p = 0; p < img->n_planes; p++)
    if (strcmp(img->planes[p].name, name) == 0) return &img->planes[p];
  return NULL;
}

void film_plane_init(const film_image *img, const char *name, film_plane *p) {
  plane_describe(img, plane_index(name), p);
}

uint64_t film_image_nonfinite(const film_image *img) {
  size_t n = (size_t)img->width * (size_t)img->height * (size_t)img->channels;
  uint64_t bad = 0;
  for (size_t i = 0; img->data && i < n; i++) bad += !isfinite(img->data[i]);
  for (int p = 0; p < img->n_planes; p++)
    for (size_t i = 0; img->planes[p].data && i < n; i++) bad += !isfinite(img->planes[p].data[i]);
  return bad;
}

void film_image_free(film_image *img) {
  if (!img) return;
  film_pixels_unref(img->data);
  img->data = NULL;
  film_angles_unref(img->angles);
  img->angles = NULL;
  /* The planes' descriptions stay, like the film's size and channels. */
  for (int p = 0; p < img->n_planes; p++) {
    film_pixels_unref(img->planes[p].data);
    img->planes[p].data = NULL;
  }
}
