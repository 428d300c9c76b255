/* Developed film -> OpenEXR, with the render's context as string
 * attributes so a film is self-describing (see film_io.h). */
#include "film_io.h"

#include <inttypes.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "image_exr.h"

/* Most attributes an info gives: scene, revision, context, sensor, spp,
 * seed, variant, wavelength, zenith, azimuth, unresolved rays, plugin
 * failures and their message, isa, irradiance, the sun's zenith and
 * azimuth. */
#define FILM_EXR_MAX_ATTRS 18

/* The attribute list of one info: entries point into info, the number
 * buffers here and the two angle lists (owned). */
typedef struct attrs {
  exr_meta_entry e[FILM_EXR_MAX_ATTRS];
  size_t count;
  char revision[24], spp[16], seed[24], wavelength[32], unresolved[24], plugin_failures[24], irradiance[12 * 26],
      sun_zenith[32], sun_azimuth[32];
  char *zenith, *azimuth;
} attrs;

film_exr_info film_exr_info_none(void) {
  return (film_exr_info){.wavelength_nm = NAN};
}

/* "v0,v1,..." of every pixel's angle k (0 zenith, 1 azimuth), row-major,
 * %.9g (enough for a float's worth of angle). NULL when out of memory. */
static char *format_angle_list(const double *angles, size_t n, int k, size_t *len_out) {
  size_t cap = n * 18 + 1, len = 0; /* "%.9g" is at most 16 chars, plus ',' */
  char *s = malloc(cap);
  if (!s) return NULL;
  s[0] = '\0';
  for (size_t i = 0; i < n; i++) {
    int w = snprintf(s + len, cap - len, i ? ",%.9g" : "%.9g", angles[2 * i + (size_t)k]);
    if (w < 0 || (size_t)w >= cap - len) {
      free(s);
      return NULL;
    }
    len += (size_t)w;
  }
  *len_out = len;
  return s;
}

/* The lists of the last angles formatted. A sweep's films share their
 * sensor's angles (the same sensor at every wavelength), so each film
 * after the first copies the text instead of formatting 2 x W x H
 * numbers again: the same bytes, at memcpy speed. Films up to
 * ANGLE_CACHE_MAX pixels (the larger ones' render time dwarfs the
 * formatting). */
#define ANGLE_CACHE_MAX ((size_t)1 << 16)
static struct {
  pthread_mutex_t lock;
  double *angles; /* 2 n, a copy */
  size_t n;
  char *list[2];
  size_t len[2];
} angle_cache = {.lock = PTHREAD_MUTEX_INITIALIZER};

static char *copy_text(const char *s, size_t len) {
  char *t = malloc(len + 1);
  if (t) memcpy(t, s, len + 1);
  return t;
}

char *film_angle_list(const double *angles, size_t n, int k, size_t *len_out) {
  size_t len = 0;
  char *s = NULL;
  if (n > ANGLE_CACHE_MAX || k < 0 || k > 1) {
    s = format_angle_list(angles, n, k, &len);
    if (s && len_out) *len_out = len;
    return s;
  }
  pthread_mutex_lock(&angle_cache.lock);
  if (angle_cache.n == n && angle_cache.angles && memcmp(angle_cache.angles, angles, 2 * n * sizeof *angles) == 0)
    s = copy_text(angle_cache.list[k], len = angle_cache.len[k]);
  pthread_mutex_unlock(&angle_cache.lock);
  if (s) {
    if (len_out) *len_out = len;
    return s;
  }
  /* Not these angles: format both lists and keep them. */
  size_t l2[2] = {0, 0};
  char *both[2] = {format_angle_list(angles, n, 0, &l2[0]), format_angle_list(angles, n, 1, &l2[1])};
  double *copy = malloc(2 * n * sizeof *copy);
  if (both[0] && both[1] && copy) {
    memcpy(copy, angles, 2 * n * sizeof *copy);
    s = copy_text(both[k], len = l2[k]);
    pthread_mutex_lock(&angle_cache.lock);
    free(angle_cache.angles);
    free(angle_cache.list[0]);
    free(angle_cache.list[1]);
    angle_cache.angles = copy, angle_cache.n = n;
    angle_cache.list[0] = both[0], angle_cache.list[1] = both[1];
    angle_cache.len[0] = l2[0], angle_cache.len[1] = l2[1];
    pthread_mutex_unlock(&angle_cache.lock);
    if (s && len_out) *len_out = len;
    return s;
  }
  /* Out of memory for the cache: the list alone, if it was made. */
  free(copy);
  s = both[k], len = l2[k];
  free(both[1 - k]);
  if (s && len_out) *len_out = len;
  return s;
}

static void add(attrs *a, const char *key, const char *value) {
  if (value && value[0]) a->e[a->count++] = (exr_meta_entry){key, value};
}

static rsw_status build_attrs(const film_exr_info *info, int width, int height, attrs *a, const char *where,
                              rsw_err *err) {
  memset(a, 0, sizeof *a);
  if (!info) return RSW_OK;
  snprintf(a->revision, sizeof a->revision, "%" PRIu64, info->revision);
  snprintf(a->spp, sizeof a->spp, "%" PRIu32, info->spp);
  snprintf(a->seed, sizeof a->seed, "%" PRIu64, info->seed);
  snprintf(a->wavelength, sizeof a->wavelength, "%.17g", info->wavelength_nm);
  snprintf(a->unresolved, sizeof a->unresolved, "%" PRIu64, info->unresolved_rays);
  bool rgb = info->variant && strcmp(info->variant, "rgb") == 0;
  add(a, "raysweep:scene", info->scene);
  if (info->has_revision) add(a, "raysweep:revision", a->revision);
  add(a, "raysweep:context", info->context);
  add(a, "raysweep:sensor", info->sensor);
  if (info->has_spp) add(a, "raysweep:spp", a->spp);
  if (info->has_seed) add(a, "raysweep:seed", a->seed);
  add(a, "raysweep:variant", info->variant);
  if (!rgb && isfinite(info->wavelength_nm)) add(a, "raysweep:wavelength_nm", a->wavelength);
  if (info->angles && width > 0 && height > 0) {
    size_t n = (size_t)width * (size_t)height;
    a->zenith = film_angle_list(info->angles, n, 0, NULL);
    a->azimuth = film_angle_list(info->angles, n, 1, NULL);
    if (!a->zenith || !a->azimuth) {
      free(a->zenith);
      free(a->azimuth);
      return rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory for the pixel angles");
    }
    add(a, "raysweep:zenith_deg", a->zenith);
    add(a, "raysweep:azimuth_deg", a->azimuth);
  }
  if (info->unresolved_rays) add(a, "raysweep:unresolved_rays", a->unresolved);
  if (info->plugin_failures) {
    snprintf(a->plugin_failures, sizeof a->plugin_failures, "%" PRIu64, info->plugin_failures);
    add(a, "raysweep:plugin_failures", a->plugin_failures);
    add(a, "raysweep:plugin_failure", info->plugin_failure);
  }
  add(a, "raysweep:isa", info->isa);
  if (info->irradiance && info->n_irradiance > 0 && info->n_irradiance <= 12) {
    size_t len = 0;
    for (int c = 0; c < info->n_irradiance; c++)
      len += (size_t)snprintf(a->irradiance + len, sizeof a->irradiance - len, c ? ",%.17g" : "%.17g",
                              info->irradiance[c]);
    add(a, "raysweep:irradiance", a->irradiance);
  }
  if (info->has_sun) { /* the JSON meta's sun_zenith_deg and sun_azimuth_deg, the same "%.9g" */
    snprintf(a->sun_zenith, sizeof a->sun_zenith, "%.9g", info->sun_zenith);
    snprintf(a->sun_azimuth, sizeof a->sun_azimuth, "%.9g", info->sun_azimuth);
    add(a, "raysweep:sun_zenith_deg", a->sun_zenith);
    add(a, "raysweep:sun_azimuth_deg", a->sun_azimuth);
  }
  return RSW_OK;
}

static void attrs_free(attrs *a) {
  free(a->zenith);
  free(a->azimuth);
}

rsw_status film_exr_write(const char *path, int width, int height, int n_channels,
                          const char *const *channel_names, const float *data, bool half,
                          const film_exr_info *info, rsw_err *err) {
  attrs a;
  rsw_status st = build_attrs(info, width, height, &a, path ? path : "", err);
  if (st) return st;
  exr_meta meta = {.entries = a.e, .count = a.count};
  st = exr_write_image(path, width, height, n_channels, channel_names, data, half, &meta, err);
  attrs_free(&a);
  return st;
}

rsw_status film_exr_encode(int width, int height, int n_channels, const char *const *channel_names,
                           const float *data, bool half, const film_exr_info *info, void **bytes_out,
                           size_t *len_out, rsw_err *err) {
  attrs a;
  rsw_status st = build_attrs(info, width, height, &a, "(EXR in memory)", err);
  if (st) return st;
  exr_meta meta = {.entries = a.e, .count = a.count};
  st = exr_encode_image(width, height, n_channels, channel_names, data, half, &meta, bytes_out, len_out, err);
  attrs_free(&a);
  return st;
}
