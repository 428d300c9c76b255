/* Films: decoding the daemon's JSON film, the accessors, and saving as
 * OpenEXR (through the project's one EXR writer, server/kernel/image_exr.c,
 * linked into the library) or as NumPy .npy. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "film_io.h"
#include "image_exr.h"
#include "image_png.h"
#include "internal.h"

/* Most channels a film may have (the EXR writer's cap as well). */
#define FILM_MAX_CHANNELS 64

struct rsw_film {
  int width, height, channels;
  char **names; /* channels entries */
  float *data;  /* H * W * C, HWC, row 0 = top */
  char *meta;   /* JSON object text */
};

int rsw_film_width(const rsw_film *f) {
  return f ? f->width : 0;
}
int rsw_film_height(const rsw_film *f) {
  return f ? f->height : 0;
}
int rsw_film_channels(const rsw_film *f) {
  return f ? f->channels : 0;
}
const char *rsw_film_channel_name(const rsw_film *f, int i) {
  return f && i >= 0 && i < f->channels ? f->names[i] : NULL;
}
const float *rsw_film_data(const rsw_film *f) {
  return f ? f->data : NULL;
}
const char *rsw_film_meta(const rsw_film *f) {
  return f ? f->meta : NULL;
}

void rsw_film_free(rsw_film *f) {
  if (!f) return;
  for (int i = 0; f->names && i < f->channels; i++) free(f->names[i]);
  free(f->names);
  free(f->data);
  free(f->meta);
  free(f);
}

rsw_status film_from_json(rsw_client *c, const char *text, size_t len, const char *what, rsw_film **out) {
  cJSON *doc = cJSON_ParseWithLength(text, len);
  if (!doc) return client_fail(c, RSW_ERR_PARSE, "%s: the film is not JSON", what);
  const cJSON *w = cJSON_GetObjectItemCaseSensitive(doc, "width");
  const cJSON *h = cJSON_GetObjectItemCaseSensitive(doc, "height");
  const cJSON *ch = cJSON_GetObjectItemCaseSensitive(doc, "channels");
  const cJSON *layout = cJSON_GetObjectItemCaseSensitive(doc, "layout");
  const cJSON *data = cJSON_GetObjectItemCaseSensitive(doc, "data");
  const cJSON *meta = cJSON_GetObjectItemCaseSensitive(doc, "meta");
  rsw_status s = RSW_OK;
  int nc = cJSON_GetArraySize(ch);
  if (!cJSON_IsNumber(w) || !cJSON_IsNumber(h) || w->valuedouble < 1 || h->valuedouble < 1 ||
      w->valuedouble > 1e6 || h->valuedouble > 1e6 || !cJSON_IsArray(ch) || nc < 1 ||
      nc > FILM_MAX_CHANNELS || !cJSON_IsArray(data) ||
      (layout && !(cJSON_IsString(layout) && strcmp(layout->valuestring, "HWC") == 0))) {
    cJSON_Delete(doc);
    return client_fail(c, RSW_ERR_PARSE, "%s: not a film (width, height, channels, layout \"HWC\", data)",
                       what);
  }
  int width = w->valueint, height = h->valueint;
  size_t n = (size_t)width * (size_t)height * (size_t)nc;
  if (n > EXR_MAX_SAMPLES) {
    cJSON_Delete(doc);
    return client_fail(c, RSW_ERR_LIMIT, "%s: film of %zu samples is too large", what, n);
  }
  rsw_film *f = calloc(1, sizeof *f);
  if (f) {
    f->width = width;
    f->height = height;
    f->names = calloc((size_t)nc, sizeof *f->names);
    f->data = malloc(n * sizeof *f->data);
    f->meta = cJSON_IsObject(meta) ? cJSON_PrintUnformatted(meta) : NULL;
    if (!f->meta) {
      f->meta = malloc(3);
      if (f->meta) strcpy(f->meta, "{}");
    }
  }
  if (!f || !f->names || !f->data || !f->meta) {
    rsw_film_free(f);
    cJSON_Delete(doc);
    return client_fail(c, RSW_ERR_NOMEM, "%s: no memory for a %dx%dx%d film", what, width, height, nc);
  }
  const cJSON *it;
  cJSON_ArrayForEach(it, ch) {
    if (!cJSON_IsString(it)) {
      s = client_fail(c, RSW_ERR_PARSE, "%s: channel %d is not a name", what, f->channels);
      break;
    }
    f->names[f->channels] = malloc(strlen(it->valuestring) + 1);
    if (!f->names[f->channels]) {
      s = client_fail(c, RSW_ERR_NOMEM, "out of memory");
      break;
    }
    strcpy(f->names[f->channels++], it->valuestring);
  }
  size_t k = 0;
  if (!s) {
    cJSON_ArrayForEach(it, data) {
      if (k >= n) break;
      /* The daemon writes non-finite samples as null. */
      if (cJSON_IsNumber(it))
        f->data[k++] = (float)it->valuedouble;
      else if (cJSON_IsNull(it))
        f->data[k++] = NAN;
      else
        break;
    }
    if (k != n || cJSON_GetArraySize(data) != (int)n)
      s = client_fail(c, RSW_ERR_PARSE, "%s: data holds %d numbers, want %dx%dx%d = %zu", what,
                      cJSON_GetArraySize(data), height, width, nc, n);
  }
  cJSON_Delete(doc);
  if (s) {
    rsw_film_free(f);
    return s;
  }
  *out = f;
  return RSW_OK;
}

/* ---- saving ------------------------------------------------------------------------- */

/* A meta member that must be a number holding an integer in [0, max]
 * (absent or null: *has false). False when it is something else. */
static bool meta_uint(const cJSON *meta, const char *key, double max, bool *has, uint64_t *out) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(meta, key);
  *has = false;
  if (!v || cJSON_IsNull(v)) return true;
  if (!cJSON_IsNumber(v) || !(v->valuedouble >= 0) || v->valuedouble > max ||
      v->valuedouble != floor(v->valuedouble))
    return false;
  *has = true;
  *out = (uint64_t)v->valuedouble;
  return true;
}

/* A meta member that must be a string (absent or null: *out NULL). */
static bool meta_string(const cJSON *meta, const char *key, const char **out) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(meta, key);
  *out = NULL;
  if (!v || cJSON_IsNull(v)) return true;
  if (!cJSON_IsString(v)) return false;
  *out = v->valuestring;
  return true;
}

/* The per-pixel angle arrays (zenith_deg, azimuth_deg) interleaved into
 * *angles (malloc'ed), or NULL when the meta has neither. False when only
 * one is there, or either is not npix numbers, or out of memory. */
static bool meta_angles(const cJSON *meta, size_t npix, double **angles) {
  const cJSON *zen = cJSON_GetObjectItemCaseSensitive(meta, "zenith_deg");
  const cJSON *az = cJSON_GetObjectItemCaseSensitive(meta, "azimuth_deg");
  *angles = NULL;
  if (!zen && !az) return true;
  if (!cJSON_IsArray(zen) || !cJSON_IsArray(az) || (size_t)cJSON_GetArraySize(zen) != npix ||
      (size_t)cJSON_GetArraySize(az) != npix)
    return false;
  double *a = malloc(2 * npix * sizeof *a);
  if (!a) return false;
  const cJSON *arr[2] = {zen, az};
  for (int k = 0; k < 2; k++) {
    size_t i = 0;
    const cJSON *it;
    cJSON_ArrayForEach(it, arr[k]) {
      if (!cJSON_IsNumber(it)) {
        free(a);
        return false;
      }
      a[2 * i++ + (size_t)k] = it->valuedouble;
    }
  }
  *angles = a;
  return true;
}

/* The film's meta (the daemon's JSON film meta) becomes the "raysweep:"
 * attributes of film_io.h, through the same code and number formats as
 * raysweepd render -o and the daemon's own EXR answers. */
rsw_status rsw_film_save_exr(const rsw_film *f, const char *path) {
  if (!f || !path) return RSW_ERR_INVALID;
  cJSON *meta = cJSON_Parse(f->meta);
  film_exr_info info = film_exr_info_none();
  double *angles = NULL, irradiance[12];
  rsw_status s = RSW_OK;
  if (cJSON_IsObject(meta)) {
    uint64_t spp = 0;
    const cJSON *wl = cJSON_GetObjectItemCaseSensitive(meta, "wavelength");
    bool ok = meta_string(meta, "scene", &info.scene) && meta_string(meta, "context", &info.context) &&
              meta_string(meta, "sensor", &info.sensor) && meta_string(meta, "variant", &info.variant) &&
              meta_string(meta, "isa", &info.isa) &&
              meta_uint(meta, "revision", 18446744073709549568.0, &info.has_revision, &info.revision) &&
              meta_uint(meta, "spp", 4294967295.0, &info.has_spp, &spp) &&
              meta_uint(meta, "seed", 18446744073709549568.0, &info.has_seed, &info.seed) &&
              (!wl || cJSON_IsNull(wl) || cJSON_IsNumber(wl));
    bool has_unresolved; /* absent or null: 0, which writes no attribute */
    ok = ok &&
         meta_uint(meta, "unresolved_rays", 18446744073709549568.0, &has_unresolved, &info.unresolved_rays);
    bool has_pf; /* absent: none, which writes no attribute */
    ok = ok && meta_uint(meta, "plugin_failures", 18446744073709549568.0, &has_pf, &info.plugin_failures) &&
         meta_string(meta, "plugin_failure", &info.plugin_failure);
    info.spp = (uint32_t)spp;
    if (ok && cJSON_IsNumber(wl)) info.wavelength_nm = wl->valuedouble;
    if (ok && !meta_angles(meta, (size_t)f->width * (size_t)f->height, &angles)) ok = false;
    info.angles = angles;
    /* brdf / brf films: the horizontal irradiance, one per radiance
     * channel. */
    const cJSON *ir = cJSON_GetObjectItemCaseSensitive(meta, "irradiance");
    if (ok && ir && !cJSON_IsNull(ir)) {
      int n = cJSON_GetArraySize(ir), k = 0;
      ok = cJSON_IsArray(ir) && n >= 1 && n <= 12; /* a Stokes film: up to S0.R..S3.B */
      for (const cJSON *x = ok ? ir->child : NULL; x; x = x->next, k++) {
        if (!cJSON_IsNumber(x)) ok = false;
        irradiance[k] = cJSON_IsNumber(x) ? x->valuedouble : 0;
      }
      info.irradiance = irradiance;
      info.n_irradiance = ok ? n : 0;
    }
    /* One directional emitter: its angles, as the daemon's EXR answers
     * carry them. */
    const cJSON *sz = cJSON_GetObjectItemCaseSensitive(meta, "sun_zenith_deg");
    const cJSON *sa = cJSON_GetObjectItemCaseSensitive(meta, "sun_azimuth_deg");
    if (ok && cJSON_IsNumber(sz) && cJSON_IsNumber(sa))
      info.has_sun = true, info.sun_zenith = sz->valuedouble, info.sun_azimuth = sa->valuedouble;
    if (!ok) s = RSW_ERR_PARSE;
  } else if (f->meta && strcmp(f->meta, "{}") != 0) {
    s = RSW_ERR_PARSE;
  }
  if (!s) {
    rsw_err err = {0};
    s = film_exr_write(path, f->width, f->height, f->channels, (const char *const *)f->names, f->data, false,
                       &info, &err);
  }
  free(angles);
  cJSON_Delete(meta);
  return s;
}

rsw_status rsw_film_save_png(const rsw_film *f, const char *path, const char *exposure,
                             const char *colormap) {
  if (!f || !path) return RSW_ERR_INVALID;
  png_look look = {.colormap = colormap};
  if (exposure && !png_exposure_parse(exposure, &look)) return RSW_ERR_INVALID;
  rsw_err err = {0};
  return png_write_film(path, f->width, f->height, f->channels, (const char *const *)f->names, f->data, &look,
                        &err);
}

static void put_le32(unsigned char *p, float v) {
  uint32_t u;
  memcpy(&u, &v, 4);
  p[0] = (unsigned char)u;
  p[1] = (unsigned char)(u >> 8);
  p[2] = (unsigned char)(u >> 16);
  p[3] = (unsigned char)(u >> 24);
}

/* NPY format 1.0: magic "\x93NUMPY", version 1.0, a little-endian u16
 * header length, then a Python dict literal padded with spaces and ended
 * by '\n' so that the data starts at a multiple of 64 bytes (NumPy's
 * ARRAY_ALIGN), then the samples, little-endian float32, C order. */
rsw_status rsw_film_save_npy(const rsw_film *f, const char *path) {
  if (!f || !path) return RSW_ERR_INVALID;
  char dict[160];
  int dn = snprintf(dict, sizeof dict, "{'descr': '<f4', 'fortran_order': False, 'shape': (%d, %d, %d), }",
                    f->height, f->width, f->channels);
  if (dn < 0 || (size_t)dn >= sizeof dict) return RSW_ERR_INVALID;
  size_t header = (10 + (size_t)dn + 1 + 63) / 64 * 64;
  unsigned char head[256];
  memcpy(head, "\x93NUMPY\x01\x00", 8);
  head[8] = (unsigned char)((header - 10) & 0xff);
  head[9] = (unsigned char)((header - 10) >> 8);
  memcpy(head + 10, dict, (size_t)dn);
  memset(head + 10 + dn, ' ', header - 10 - (size_t)dn - 1);
  head[header - 1] = '\n';

  size_t tlen = strlen(path) + 32;
  char *tmp = malloc(tlen);
  if (!tmp) return RSW_ERR_NOMEM;
  snprintf(tmp, tlen, "%s.tmp.%ld", path, (long)getpid());
  FILE *out = fopen(tmp, "wb");
  if (!out) {
    free(tmp);
    return RSW_ERR_IO;
  }
  bool ok = fwrite(head, 1, header, out) == header;
  size_t n = (size_t)f->width * (size_t)f->height * (size_t)f->channels;
  unsigned char chunk[4096];
  for (size_t i = 0; i < n && ok;) {
    size_t k = 0;
    for (; k < sizeof chunk / 4 && i < n; k++, i++) put_le32(chunk + 4 * k, f->data[i]);
    ok = fwrite(chunk, 4, k, out) == k;
  }
  ok = (fflush(out) == 0) && ok;
  ok = (fclose(out) == 0) && ok;
  if (ok) ok = rename(tmp, path) == 0;
  if (!ok) unlink(tmp);
  free(tmp);
  return ok ? RSW_OK : RSW_ERR_IO;
}

/* ---- one render ------------------------------------------------------------------------ */

rsw_status rsw_render(rsw_client *c, const char *id, const char *request_json, rsw_film **film_out) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char esc[256], path[300];
  if (!id || !client_escape(id, esc, sizeof esc))
    return client_fail(c, RSW_ERR_INVALID, "scene id missing or too long");
  if (!film_out) return client_fail(c, RSW_ERR_INVALID, "render: film_out is NULL");
  snprintf(path, sizeof path, "/v1/scenes/%s:render", esc);
  const char *body = request_json && *request_json ? request_json : "{}";
  /* The request's timeout_s (the daemon stops the render there and
   * answers) bounds the whole exchange here too, with a grace for the
   * answer to arrive: a server that never answers is given up. */
  double deadline = 0;
  cJSON *req = cJSON_Parse(body);
  cJSON *t = cJSON_GetObjectItemCaseSensitive(req, "timeout_s");
  if (cJSON_IsNumber(t) && t->valuedouble > 0 && t->valuedouble < 1e9)
    deadline = t->valuedouble + CLIENT_RENDER_GRACE_S + t->valuedouble / 10.0;
  cJSON_Delete(req);
  http_resp r;
  rsw_status s = http_request(c,
                              &(http_req){.method = "POST",
                                          .path = path,
                                          .content_type = "application/json",
                                          .body = body,
                                          .body_len = strlen(body),
                                          .accept = "application/json",
                                          .computed = true,
                                          .deadline_s = deadline},
                              &r);
  if (s) return s;
  char what[320];
  snprintf(what, sizeof what, "POST %s", path);
  s = film_from_json(c, r.body, r.len, what, film_out);
  http_resp_free(&r);
  return s;
}
