/* A sweep as one NetCDF-4 dataset (see dataset_nc.h for the layout). The
 * one file that includes libnetcdf's headers.
 *
 * CF conventions (CF-1.10, cfconventions.org): every variable has units
 * and long_name; the coords of a complete grid are coordinate variables
 * (a 1-D variable named as its dimension), everything else that labels
 * the data (context ids, wavelengths, coords of a non-grid job, pixel
 * angles) is an auxiliary coordinate listed in the data variables'
 * "coordinates" attribute, which is also what makes xarray open them as
 * coordinates. */
#include "dataset_nc.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <netcdf.h>
#include <netcdf_mem.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "raysweep/version.h"
#include "stokes.h"

/* The quantities a dataset variable may hold. Radiance: W m^-2 sr^-1
 * nm^-1 in mono (spectral, at the context's wavelength), W m^-2 sr^-1 in
 * rgb. BRDF = L / E_h (sr^-1) and BRF = pi L / E_h (dimensionless), with
 * E_h the horizontal irradiance of the directional emitters (Eradiate's
 * definitions); radiance_stderr: the standard error of the mean radiance,
 * same units. */
static const nc_quantity quantities[] = {
    {"radiance", "radiance", "W m-2 sr-1 nm-1", "W m-2 sr-1"},
    {"radiance_stderr", "standard error of the mean radiance", "W m-2 sr-1 nm-1", "W m-2 sr-1"},
    {"brdf", "bidirectional reflectance distribution function", "sr-1", "sr-1"},
    {"brf", "bidirectional reflectance factor", "1", "1"},
    {"brf_stderr", "standard error of the bidirectional reflectance factor", "1", "1"},
    /* Bands (docs/experiments.md#spectral-response-functions-bands): the SRF-weighted means, Eradiate's
     * *_srf variables. */
    {"radiance_srf", "radiance (SRF-weighted)", "W m-2 sr-1 nm-1", "W m-2 sr-1"},
    {"radiance_srf_stderr", "standard error of radiance_srf", "W m-2 sr-1 nm-1", "W m-2 sr-1"},
    {"brdf_srf", "bidirectional reflectance distribution function (SRF-weighted)", "sr-1", "sr-1"},
    {"brf_srf", "bidirectional reflectance factor (SRF-weighted)", "1", "1"},
    {"brf_srf_stderr", "standard error of brf_srf", "1", "1"},
    /* Stokes films (stokes.h): derived from the Stokes vector of the
     * radiance (of radiance_srf: the band's SRF-weighted vector, never a
     * mean of DoLPs). brf and brdf divide every component by the same
     * E_h, so theirs are the same and not repeated. */
    {"dolp", "degree of linear polarization", "1", "1"},
    {"aolp", "angle of linear polarization", "degree", "degree"},
    {"dolp_srf", "degree of linear polarization of the SRF-weighted Stokes vector", "1", "1"},
    {"aolp_srf", "angle of linear polarization of the SRF-weighted Stokes vector", "degree", "degree"},
};
#define N_QUANTITIES (sizeof quantities / sizeof quantities[0])

/* The quantities over the band dimension. */
static bool band_quantity(const char *name) {
  return strstr(name, "_srf") != NULL;
}

/* The derived standard errors: pi * <stderr> / E (brf_stderr from
 * radiance_stderr, brf_srf_stderr from radiance_srf_stderr), written
 * where a film has brf (brf_srf), the stderr and its irradiance. */
static const struct derived {
  const char *name, *from, *needs;
} derived[] = {{"brf_stderr", "radiance_stderr", "brf"},
               {"brf_srf_stderr", "radiance_srf_stderr", "brf_srf"}};
#define N_DERIVED 2

/* The polarization quantities of Stokes films, from the Stokes vector of
 * `from`: over the film's dimensions less stokes. */
static const struct polar {
  const char *name, *from;
  bool aolp;
} polar[] = {{"dolp", "radiance", false},
             {"aolp", "radiance", true},
             {"dolp_srf", "radiance_srf", false},
             {"aolp_srf", "radiance_srf", true}};
#define N_POLAR 4

static const struct polar *polar_find(const char *name) {
  for (size_t k = 0; k < N_POLAR; k++)
    if (strcmp(polar[k].name, name) == 0) return &polar[k];
  return NULL;
}

/* The AoLP convention, the aolp variables' comment (docs/polarization.md). */
#define AOLP_COMMENT                                                                                         \
  "0.5 atan2(S2, S1) in degrees, in (-90, 90], 0 where S1 = S2 = 0; from x towards y of the film's Stokes "  \
  "basis (counter-clockwise as seen looking into the beam): for cameras x is the image's right, for "        \
  "distant "                                                                                                 \
  "sensors x is horizontal, perpendicular to the meridian plane (docs/polarization.md)"
#define STOKES_COMMENT                                                                                       \
  "S0..S3 = I, Q, U, V; Q = I_x - I_y, U = I_+45 - I_-45, V circular; for cameras x is the image's right, "  \
  "for distant sensors x is horizontal, perpendicular to the meridian plane (docs/polarization.md)"

const nc_quantity *nc_quantity_find(const char *name) {
  for (size_t i = 0; i < N_QUANTITIES; i++)
    if (strcmp(quantities[i].name, name) == 0) return &quantities[i];
  return NULL;
}

/* Names the writer uses itself (besides the quantities): a coord may not
 * take them. "wavelength" is allowed: a coord of that name replaces the
 * wavelength variable. */
static const char *const reserved[] = {
    "x",   "y",   "channel", "stokes",          "context",         "seed",
    "spp", "vza", "vaa",     "unresolved_rays", "plugin_failures", "plugin_failure",
};

static bool valid_coord_name(const char *s) {
  size_t n = strlen(s);
  if (n < 1 || n > NC_MAX_COORD_NAME) return false;
  if (!((s[0] >= 'A' && s[0] <= 'Z') || (s[0] >= 'a' && s[0] <= 'z'))) return false;
  for (size_t i = 1; i < n; i++) {
    char c = s[i];
    if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_'))
      return false;
  }
  return true;
}

static bool reserved_name(const char *s) {
  for (size_t i = 0; i < sizeof reserved / sizeof reserved[0]; i++)
    if (strcmp(reserved[i], s) == 0) return true;
  return nc_quantity_find(s) != NULL;
}

void nc_coords_free(nc_coords *c) {
  if (!c) return;
  for (size_t k = 0; k < c->n; k++) {
    free(c->c[k].name);
    free(c->c[k].num);
    if (c->c[k].str)
      for (size_t i = 0; i < c->n_contexts; i++) free(c->c[k].str[i]);
    free(c->c[k].str);
  }
  free(c->c);
  memset(c, 0, sizeof *c);
}

rsw_status nc_coords_copy(const nc_coords *src, nc_coords *out, rsw_err *err) {
  nc_coords c = {.n_contexts = src->n_contexts};
  size_t n = src->n_contexts;
  if (src->n && !(c.c = calloc(src->n, sizeof *c.c)))
    return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  bool ok = true;
  for (size_t k = 0; k < src->n && ok; k++, c.n++) {
    const nc_coord *s = &src->c[k];
    nc_coord *d = &c.c[k];
    d->is_string = s->is_string;
    d->name = strdup(s->name);
    if (s->is_string) {
      d->str = calloc(n ? n : 1, sizeof *d->str);
      for (size_t i = 0; d->str && i < n && ok; i++) ok = (d->str[i] = strdup(s->str[i])) != NULL;
    } else if ((d->num = malloc((n ? n : 1) * sizeof *d->num))) {
      memcpy(d->num, s->num, n * sizeof *d->num);
    }
    ok = ok && d->name && (d->str || d->num);
  }
  if (!ok) {
    nc_coords_free(&c);
    return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  }
  *out = c;
  return RSW_OK;
}

static bool valid_coord_string(const char *s) {
  size_t n = strlen(s);
  if (n < 1 || n > NC_MAX_COORD_STR) return false;
  for (size_t i = 0; i < n; i++)
    if ((unsigned char)s[i] < 0x20 || s[i] == 0x7f) return false;
  return true;
}

rsw_status nc_coords_build(const void *const *coords_json, size_t n, const char *prefix, nc_coords *out,
                           rsw_err *err) {
  nc_coords c = {.n_contexts = n};
  char w[320];
  /* The first context's names set the list; every other must match. */
  const cJSON *first = NULL;
  size_t first_i = 0;
  for (size_t i = 0; i < n; i++) {
    const cJSON *o = coords_json[i];
    if (!o) continue;
    snprintf(w, sizeof w, "%s/%zu/coords", prefix, i);
    if (!cJSON_IsObject(o))
      return rsw_fail(err, RSW_ERR_TYPE, w, "coords must be an object {name: number or string}");
    if (!first && o->child) first = o, first_i = i;
  }
  if (!first) {
    *out = c;
    return RSW_OK;
  }
  rsw_status st = RSW_OK;
  size_t nn = 0;
  for (const cJSON *k = first->child; k; k = k->next) nn++;
  if (nn > NC_MAX_COORDS) {
    snprintf(w, sizeof w, "%s/%zu/coords", prefix, first_i);
    return rsw_fail(err, RSW_ERR_LIMIT, w, "%zu coords; a context may have at most %d", nn, NC_MAX_COORDS);
  }
  c.c = calloc(nn ? nn : 1, sizeof *c.c);
  if (!c.c) return rsw_fail(err, RSW_ERR_NOMEM, prefix, "out of memory");
  for (const cJSON *k = first->child; k && !st; k = k->next) {
    snprintf(w, sizeof w, "%s/%zu/coords/%.64s", prefix, first_i, k->string);
    if (!valid_coord_name(k->string))
      st = rsw_fail(err, RSW_ERR_INVALID, w, "coord name '%.64s' must match [A-Za-z][A-Za-z0-9_]{0,63}",
                    k->string);
    else if (reserved_name(k->string))
      st = rsw_fail(err, RSW_ERR_INVALID, w, "coord name '%s' is a name the dataset uses itself", k->string);
    for (size_t j = 0; j < c.n && !st; j++)
      if (strcmp(c.c[j].name, k->string) == 0)
        st = rsw_fail(err, RSW_ERR_DUPLICATE, w, "coord '%s' appears twice", k->string);
    if (st) break;
    nc_coord *cc = &c.c[c.n++];
    cc->is_string = cJSON_IsString(k);
    cc->name = strdup(k->string);
    if (cc->is_string)
      cc->str = calloc(n, sizeof *cc->str);
    else
      cc->num = calloc(n, sizeof *cc->num);
    if (!cc->name || (!cc->str && !cc->num)) st = rsw_fail(err, RSW_ERR_NOMEM, prefix, "out of memory");
  }
  for (size_t i = 0; i < n && !st; i++) {
    const cJSON *o = coords_json[i];
    if (!o || !o->child) {
      snprintf(w, sizeof w, o ? "%s/%zu/coords" : "%s/%zu", prefix, i);
      st = rsw_fail(err, RSW_ERR_MISSING, w,
                    "this context has no coords; every context of a job with coords needs them (%s...)",
                    c.c[0].name);
      break;
    }
    size_t seen = 0;
    for (const cJSON *k = o->child; k && !st; k = k->next) {
      snprintf(w, sizeof w, "%s/%zu/coords/%.64s", prefix, i, k->string);
      size_t j = 0;
      while (j < c.n && strcmp(c.c[j].name, k->string) != 0) j++;
      if (j == c.n) {
        st = rsw_fail(err, RSW_ERR_INVALID, w,
                      "coord '%.64s' is not one of context %zu's: every context must name the same coords",
                      k->string, first_i);
        break;
      }
      seen++;
      nc_coord *cc = &c.c[j];
      if (cJSON_IsNumber(k)) {
        if (cc->is_string)
          st = rsw_fail(err, RSW_ERR_TYPE, w, "coord '%s' is a string in context %zu and a number here",
                        cc->name, first_i);
        else if (!isfinite(k->valuedouble))
          st = rsw_fail(err, RSW_ERR_INVALID, w, "a coord's number must be finite");
        else
          cc->num[i] = k->valuedouble;
      } else if (cJSON_IsString(k)) {
        if (!cc->is_string)
          st = rsw_fail(err, RSW_ERR_TYPE, w, "coord '%s' is a number in context %zu and a string here",
                        cc->name, first_i);
        else if (!valid_coord_string(k->valuestring))
          st = rsw_fail(err, RSW_ERR_INVALID, w,
                        "a coord's string must have 1 to %d bytes and no control characters",
                        NC_MAX_COORD_STR);
        else if (!(cc->str[i] = strdup(k->valuestring)))
          st = rsw_fail(err, RSW_ERR_NOMEM, w, "out of memory");
      } else {
        st = rsw_fail(err, RSW_ERR_TYPE, w, "a coord's value must be a number or a string");
      }
      if (!st && seen > c.n) st = rsw_fail(err, RSW_ERR_DUPLICATE, w, "coord '%s' appears twice", k->string);
    }
    if (!st && seen < c.n) {
      for (size_t j = 0; j < c.n; j++)
        if (!cJSON_GetObjectItemCaseSensitive(o, c.c[j].name)) {
          snprintf(w, sizeof w, "%s/%zu/coords/%s", prefix, i, c.c[j].name);
          st = rsw_fail(err, RSW_ERR_MISSING, w, "coord '%s' is missing (context %zu has it)", c.c[j].name,
                        first_i);
          break;
        }
      if (!st) {
        snprintf(w, sizeof w, "%s/%zu/coords", prefix, i);
        st = rsw_fail(err, RSW_ERR_DUPLICATE, w, "a coord appears twice");
      }
    }
  }
  if (st) {
    nc_coords_free(&c);
    return st;
  }
  *out = c;
  return RSW_OK;
}

/* ---- the writer ------------------------------------------------------------------- */

static pthread_mutex_t g_nc_lock = PTHREAD_MUTEX_INITIALIZER;

/* Report a libnetcdf error and return RSW_ERR_IO. */
static rsw_status nc_fail(rsw_err *err, int rc, const char *what) {
  if (rc == NC_ENAMEINUSE)
    return rsw_fail(err, RSW_ERR_INVALID, what, "the name '%s' is used twice in the dataset", what);
  if (rc == NC_ENOMEM) return rsw_fail(err, RSW_ERR_NOMEM, what, "out of memory");
  return rsw_fail(err, RSW_ERR_IO, what, "NetCDF: %s", nc_strerror(rc));
}

#define NC_TRY(call, what)                                                                                   \
  do {                                                                                                       \
    int rc_ = (call);                                                                                        \
    if (rc_ != NC_NOERR) return nc_fail(err, rc_, (what));                                                   \
  } while (0)

/* Sorted distinct values of one coord, and each context's position. */
typedef struct axis {
  size_t n;          /* distinct values */
  size_t *first;     /* n: a context holding each value, in sorted order */
  size_t *pos;       /* n_contexts: the context's index along the axis */
  const nc_coord *c; /* borrowed */
} axis;

static const nc_coord *g_sort_coord; /* under g_nc_lock */

static int cmp_ctx(const void *a, const void *b) {
  size_t i = *(const size_t *)a, j = *(const size_t *)b;
  const nc_coord *c = g_sort_coord;
  int r;
  if (c->is_string)
    r = strcmp(c->str[i], c->str[j]);
  else
    r = c->num[i] < c->num[j] ? -1 : c->num[i] > c->num[j];
  if (r) return r;
  return i < j ? -1 : i > j;
}

static bool same_value(const nc_coord *c, size_t i, size_t j) {
  return c->is_string ? strcmp(c->str[i], c->str[j]) == 0 : c->num[i] == c->num[j];
}

/* One sensor's films and what its variables look like. */
typedef struct sensor_set {
  const char *id;
  char prefix[80]; /* "" or "<sanitized id>_" */
  const nc_film *shape;
  const nc_film **by_ctx;  /* n_contexts x slots (node films), NULL where missing */
  const nc_film **by_band; /* n_contexts x n_bands (band films) */
  size_t n_present;
  bool any_angles, same_angles, spp_varies, any_unresolved, any_irr, any_band_irr;
  char **qnames; /* quantities, table order */
  size_t n_q;
  /* Stokes films (stokes.h): the stokes dimension, and channel over the
   * colours; n_col: the channel dimension's length (1: none). */
  bool stokes;
  stokes_layout sl;
  int n_col;
  int dim_y, dim_x, dim_ch, dim_st;
} sensor_set;

typedef struct writer {
  const nc_dataset *d;
  int ncid;
  bool grid;
  size_t n_cdims; /* dims of the context layout: coords (grid) or 1 */
  int cdim[NC_MAX_COORDS];
  axis ax[NC_MAX_COORDS];
  size_t *cell; /* n_contexts: linear index of each context in the layout */
  size_t n_cells;
  size_t slots;         /* films per (context, sensor): the node wavelengths, or 1 */
  int wl_dim, band_dim; /* -1: none */
  sensor_set *s;
  size_t n_s;
  bool spp_uniform;
  uint32_t spp;
  size_t missing;
  char coordinates[1024]; /* auxiliary coordinates every data variable lists */
} writer;

static void writer_free(writer *w) {
  for (size_t k = 0; k < NC_MAX_COORDS; k++) {
    free(w->ax[k].first);
    free(w->ax[k].pos);
  }
  free(w->cell);
  for (size_t i = 0; i < w->n_s; i++) {
    free(w->s[i].by_ctx);
    free(w->s[i].by_band);
    free(w->s[i].qnames);
  }
  free(w->s);
}

static int cmp_film_sensor(const void *a, const void *b) {
  return strcmp((*(const nc_film *const *)a)->sensor, (*(const nc_film *const *)b)->sensor);
}

/* Context layout: a complete grid over the coords, or a list. */
static rsw_status plan_layout(writer *w, rsw_err *err) {
  const nc_dataset *d = w->d;
  size_t n = d->n_contexts;
  const nc_coords *cs = d->coords && d->coords->n ? d->coords : NULL;
  w->cell = calloc(n ? n : 1, sizeof *w->cell);
  if (!w->cell) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  if (cs && cs->n_contexts != n)
    return rsw_fail(err, RSW_ERR_INVALID, "coords", "coords for %zu contexts, the dataset has %zu",
                    cs->n_contexts, n);
  bool grid = cs != NULL && n > 0;
  size_t *order = grid ? malloc(n * sizeof *order) : NULL;
  if (grid && !order) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  unsigned long long cells = 1;
  for (size_t k = 0; grid && k < cs->n; k++) {
    axis *a = &w->ax[k];
    a->c = &cs->c[k];
    a->pos = malloc(n * sizeof *a->pos);
    a->first = malloc(n * sizeof *a->first);
    if (!a->pos || !a->first) {
      free(order);
      return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
    }
    for (size_t i = 0; i < n; i++) order[i] = i;
    g_sort_coord = a->c;
    qsort(order, n, sizeof *order, cmp_ctx);
    a->n = 0;
    for (size_t r = 0; r < n; r++) {
      if (r == 0 || !same_value(a->c, order[r], order[r - 1])) a->first[a->n++] = order[r];
      a->pos[order[r]] = a->n - 1;
    }
    cells *= a->n;
    if (cells > n) grid = false;
  }
  free(order);
  if (grid && cells == n) {
    /* Every combination at most once: then n cells, n contexts = complete. */
    bool *used = calloc(n, 1);
    if (!used) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
    for (size_t i = 0; i < n && grid; i++) {
      size_t lin = 0;
      for (size_t k = 0; k < cs->n; k++) lin = lin * w->ax[k].n + w->ax[k].pos[i];
      if (used[lin]) grid = false;
      used[lin] = true;
      w->cell[i] = lin;
    }
    free(used);
  } else {
    grid = false;
  }
  w->grid = grid;
  if (!grid)
    for (size_t i = 0; i < n; i++) w->cell[i] = i;
  w->n_cells = n;
  w->n_cdims = grid ? cs->n : 1;
  return RSW_OK;
}

static void sanitize(const char *id, char *out, size_t cap) {
  size_t o = 0;
  if (!((id[0] >= 'A' && id[0] <= 'Z') || (id[0] >= 'a' && id[0] <= 'z'))) out[o++] = 's';
  for (const char *p = id; *p && o + 2 < cap; p++) {
    char c = *p;
    bool ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_';
    out[o++] = ok ? c : '_';
  }
  out[o++] = '_';
  out[o] = '\0';
}

/* Group the films by sensor (sorted by id, so the order of the films
 * never matters) and check that each sensor's agree. */
static rsw_status plan_sensors(writer *w, rsw_err *err) {
  const nc_dataset *d = w->d;
  const nc_film **f = malloc((d->n_films ? d->n_films : 1) * sizeof *f);
  if (!f) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  for (size_t i = 0; i < d->n_films; i++) f[i] = &d->films[i];
  qsort(f, d->n_films, sizeof *f, cmp_film_sensor);
  size_t ns = 0;
  for (size_t i = 0; i < d->n_films; i++)
    if (i == 0 || strcmp(f[i]->sensor, f[i - 1]->sensor) != 0) ns++;
  w->s = calloc(ns ? ns : 1, sizeof *w->s);
  if (!w->s) {
    free(f);
    return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  }
  rsw_status st = RSW_OK;
  w->spp_uniform = true;
  bool spp_set = false;
  for (size_t i = 0; i < d->n_films && !st; i++) {
    const nc_film *x = f[i];
    char where[320];
    snprintf(where, sizeof where, "film %s/%.200s",
             x->context < d->n_contexts ? d->context_ids[x->context] : "?", x->sensor);
    if (i == 0 || strcmp(x->sensor, f[i - 1]->sensor) != 0) {
      sensor_set *s = &w->s[w->n_s++];
      s->id = x->sensor;
      s->shape = x;
      s->same_angles = true;
      s->stokes = x->channel_names && stokes_layout_of(x->channel_names, x->channels, &s->sl);
      s->n_col = s->stokes ? s->sl.n_color : x->channels;
      if (ns > 1) sanitize(x->sensor, s->prefix, sizeof s->prefix);
      s->by_ctx = calloc(d->n_contexts * w->slots + 1, sizeof *s->by_ctx);
      s->by_band = calloc(d->n_contexts * d->n_bands + 1, sizeof *s->by_band);
      s->qnames = calloc(N_QUANTITIES, sizeof *s->qnames);
      if (!s->by_ctx || !s->by_band || !s->qnames) {
        st = rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
        break;
      }
    }
    sensor_set *s = &w->s[w->n_s - 1];
    if (x->context >= d->n_contexts) {
      st = rsw_fail(err, RSW_ERR_INVALID, where, "context index %zu out of range", x->context);
      break;
    }
    if (x->width < 1 || x->height < 1 || x->channels < 1 || !x->channel_names) {
      st = rsw_fail(err, RSW_ERR_INVALID, where, "a film needs a size and channel names");
      break;
    }
    if (x->band > d->n_bands || x->node > d->n_nodes || (x->band && x->node) ||
        (d->n_nodes && !x->band && !x->node)) {
      st = rsw_fail(err, RSW_ERR_INVALID, where, "a film's node or band is out of range");
      break;
    }
    const nc_film **slot = x->band ? &s->by_band[x->context * d->n_bands + x->band - 1]
                                   : &s->by_ctx[x->context * w->slots + (x->node ? x->node - 1 : 0)];
    if (*slot) {
      st = rsw_fail(err, RSW_ERR_INVALID, where, "two films of one context and sensor");
      break;
    }
    const nc_film *sh = s->shape;
    bool same = x->width == sh->width && x->height == sh->height && x->channels == sh->channels;
    for (int c = 0; same && c < x->channels; c++)
      same = strcmp(x->channel_names[c], sh->channel_names[c]) == 0;
    if (!same) {
      st =
          rsw_fail(err, RSW_ERR_INVALID, where, "its shape or channels differ from the sensor's other films");
      break;
    }
    *slot = x;
    if (x->band) {
      s->any_band_irr |= x->has_irradiance;
    } else {
      s->n_present++;
      s->any_irr |= x->has_irradiance;
    }
    if (x->angles) {
      if (!s->any_angles)
        s->any_angles = true;
      else if (x->angles != sh->angles && /* (a client's films share one block) */
               memcmp(x->angles, sh->angles ? sh->angles : x->angles,
                      (size_t)x->width * (size_t)x->height * 2 * sizeof(double)) != 0)
        s->same_angles = false;
      if (!sh->angles) s->same_angles = false;
    } else if (s->any_angles || sh->angles) {
      s->same_angles = false;
    }
    if (x->unresolved_rays) s->any_unresolved = true;
    if (!spp_set)
      w->spp = x->spp, spp_set = true;
    else if (x->spp != w->spp)
      w->spp_uniform = false;
    if (x->n_vars < 1) {
      st = rsw_fail(err, RSW_ERR_INVALID, where, "a film needs at least one quantity");
      break;
    }
    for (size_t v = 0; v < x->n_vars && !st; v++) {
      const nc_quantity *q = x->vars[v].name ? nc_quantity_find(x->vars[v].name) : NULL;
      if (q && band_quantity(q->name) != (x->band != 0)) q = NULL;
      if (q && polar_find(q->name)) q = NULL; /* derived here, never handed in */
      if (!q || !x->vars[v].data) {
        st = rsw_fail(err, RSW_ERR_INVALID, where, "no quantity '%s' (dataset_nc.c's table)",
                      x->vars[v].name ? x->vars[v].name : "(null)");
        break;
      }
      s->qnames[q - quantities] = (char *)q->name;
    }
  }
  free(f);
  if (st) return st;
  /* Quantities in table order. */
  for (size_t i = 0; i < w->n_s; i++) {
    sensor_set *s = &w->s[i];
    for (size_t k = 0; k < N_DERIVED; k++) {
      size_t qd = (size_t)(nc_quantity_find(derived[k].name) - quantities);
      size_t qf = (size_t)(nc_quantity_find(derived[k].from) - quantities);
      size_t qn = (size_t)(nc_quantity_find(derived[k].needs) - quantities);
      bool irr = k == 0 ? s->any_irr : s->any_band_irr;
      if (s->qnames[qf] && s->qnames[qn] && irr) s->qnames[qd] = (char *)quantities[qd].name;
    }
    for (size_t k = 0; k < N_POLAR && s->stokes; k++) {
      size_t qd = (size_t)(nc_quantity_find(polar[k].name) - quantities);
      size_t qf = (size_t)(nc_quantity_find(polar[k].from) - quantities);
      if (s->qnames[qf]) s->qnames[qd] = (char *)quantities[qd].name;
    }
    for (size_t q = 0; q < N_QUANTITIES; q++)
      if (s->qnames[q]) s->qnames[s->n_q++] = s->qnames[q];
    for (size_t c = 0; c < d->n_contexts * w->slots; c++)
      if (!s->by_ctx[c]) w->missing++;
    /* A sensor whose angles are in some films only varies. */
    if (s->any_angles && s->n_present < d->n_contexts * w->slots) s->same_angles = false;
  }
  return RSW_OK;
}

static rsw_status put_text_att(int ncid, int var, const char *name, const char *value, rsw_err *err) {
  NC_TRY(nc_put_att_text(ncid, var, name, strlen(value), value), name);
  return RSW_OK;
}

#define TRY(x)                                                                                               \
  do {                                                                                                       \
    rsw_status st_ = (x);                                                                                    \
    if (st_) return st_;                                                                                     \
  } while (0)

static void name_cat(char *out, size_t cap, const char *prefix, const char *name) {
  snprintf(out, cap, "%s%s", prefix, name);
}

/* rgb and rgb_polarized: radiance per colour, not per nm. */
static bool is_rgb(const nc_dataset *d) {
  return d->variant && strncmp(d->variant, "rgb", 3) == 0;
}

/* Append a name to the coordinates attribute list. */
static void coords_add(writer *w, const char *name) {
  size_t l = strlen(w->coordinates);
  snprintf(w->coordinates + l, sizeof w->coordinates - l, "%s%s", l ? " " : "", name);
}

/* Define a variable over the context layout dims, then `mid` (the
 * wavelength or band dimension; -1: none), then `extra` more. */
static rsw_status def_ctx_var2(writer *w, const char *name, nc_type type, int mid, int n_extra,
                               const int *extra, int *varid, rsw_err *err) {
  int dims[NC_MAX_COORDS + 5];
  int nd = 0;
  for (size_t k = 0; k < w->n_cdims; k++) dims[nd++] = w->cdim[k];
  if (mid >= 0) dims[nd++] = mid;
  for (int k = 0; k < n_extra; k++) dims[nd++] = extra[k];
  NC_TRY(nc_def_var(w->ncid, name, type, nd, dims, varid), name);
  return RSW_OK;
}

/* A variable with one value or image per film: over the wavelength
 * dimension too in a job with bands. */
static rsw_status def_ctx_var(writer *w, const char *name, nc_type type, int n_extra, const int *extra,
                              int *varid, rsw_err *err) {
  return def_ctx_var2(w, name, type, w->wl_dim, n_extra, extra, varid, err);
}

/* start[] of a context's cell in the layout dims. */
static void cell_start(const writer *w, size_t ctx, size_t *start) {
  if (!w->grid) {
    start[0] = w->cell[ctx];
    return;
  }
  for (size_t k = 0; k < w->n_cdims; k++) start[k] = w->ax[k].pos[ctx];
}

/* An angle as every writer's file holds it: to 9 significant digits,
 * the precision of the JSON film meta (zenith_deg, azimuth_deg) that
 * libraysweep builds its datasets from, so the daemon's dataset and one
 * built on the client from the same films are bitwise equal. */
static double canonical_angle(double a) {
  char buf[40];
  snprintf(buf, sizeof buf, "%.9g", a);
  return strtod(buf, NULL);
}

/* ---- writing: define the file (globals, layout, sun, each sensor), then
 * put its values (layout, then each sensor's films). The calls run in one
 * fixed order, so a dataset's bytes depend on its content only. */

/* Per sensor: its variables' ids (-1: none). */
typedef struct sensor_vars {
  int ch, st, vza, vaa, seed, spp, unres, pf, pf_msg, irr, irr_srf;
  int q[N_QUANTITIES];
} sensor_vars;

/* The variables write_all defines and then fills. */
typedef struct file_vars {
  int coord[NC_MAX_COORDS], ctx, wl; /* wl: the contexts' wavelength (-1: none) */
  int nodes, bands;                  /* jobs with bands (-1: none) */
  int sun[2];                        /* sza, saa (-1: none) */
  double *sun_deg;                   /* n_contexts x (zenith, azimuth), NAN where no film says */
  sensor_vars *sv;                   /* per sensor set */
} file_vars;

static const char *const sun_names[2] = {"sza", "saa"};

/* The global attributes. */
static rsw_status write_globals(const writer *w, rsw_err *err) {
  const nc_dataset *d = w->d;
  int ncid = w->ncid;
  TRY(put_text_att(ncid, NC_GLOBAL, "Conventions", "CF-1.10", err));
  TRY(put_text_att(ncid, NC_GLOBAL, "title", "raysweep sweep", err));
  TRY(put_text_att(ncid, NC_GLOBAL, "source", "raysweep " RSW_VERSION, err));
  TRY(put_text_att(ncid, NC_GLOBAL, "raysweep_version", RSW_VERSION, err));
  if (d->scene) TRY(put_text_att(ncid, NC_GLOBAL, "scene", d->scene, err));
  if (d->has_revision) {
    unsigned long long v = d->revision;
    NC_TRY(nc_put_att_ulonglong(ncid, NC_GLOBAL, "revision", NC_UINT64, 1, &v), "revision");
  }
  if (d->variant) TRY(put_text_att(ncid, NC_GLOBAL, "variant", d->variant, err));
  if (d->has_seed) {
    unsigned long long v = d->seed;
    NC_TRY(nc_put_att_ulonglong(ncid, NC_GLOBAL, "seed", NC_UINT64, 1, &v), "seed");
  }
  if (w->spp_uniform && d->n_films) {
    unsigned v = w->spp;
    NC_TRY(nc_put_att_uint(ncid, NC_GLOBAL, "spp", NC_UINT, 1, &v), "spp");
  }
  if (d->job) TRY(put_text_att(ncid, NC_GLOBAL, "job", d->job, err));
  if (d->warnings && d->warnings[0]) TRY(put_text_att(ncid, NC_GLOBAL, "warnings", d->warnings, err));
  if (w->missing) {
    unsigned long long v = w->missing;
    NC_TRY(nc_put_att_ulonglong(ncid, NC_GLOBAL, "films_missing", NC_UINT64, 1, &v), "films_missing");
  }
  return RSW_OK;
}

/* The context layout: the coords (grid dimensions or variables over the
 * context list), the context ids, the contexts' wavelength, and with bands
 * the node wavelengths and the bands. */
static rsw_status define_layout(writer *w, file_vars *fv, rsw_err *err) {
  const nc_dataset *d = w->d;
  int ncid = w->ncid;
  const nc_coords *cs = d->coords && d->coords->n ? d->coords : NULL;
  bool rgb = is_rgb(d);
  bool wl_coord = false;
  if (w->grid) {
    for (size_t k = 0; k < cs->n; k++) {
      const nc_coord *c = &cs->c[k];
      NC_TRY(nc_def_dim(ncid, c->name, w->ax[k].n, &w->cdim[k]), c->name);
      NC_TRY(nc_def_var(ncid, c->name, c->is_string ? NC_STRING : NC_DOUBLE, 1, &w->cdim[k], &fv->coord[k]),
             c->name);
    }
  } else {
    NC_TRY(nc_def_dim(ncid, "context", d->n_contexts, &w->cdim[0]), "context");
    for (size_t k = 0; cs && k < cs->n; k++) {
      const nc_coord *c = &cs->c[k];
      NC_TRY(nc_def_var(ncid, c->name, c->is_string ? NC_STRING : NC_DOUBLE, 1, &w->cdim[0], &fv->coord[k]),
             c->name);
      coords_add(w, c->name);
    }
  }
  for (size_t k = 0; cs && k < cs->n; k++) {
    const nc_coord *c = &cs->c[k];
    bool is_wl = strcmp(c->name, "wavelength") == 0;
    wl_coord |= is_wl;
    TRY(put_text_att(ncid, fv->coord[k], "long_name", is_wl ? "wavelength" : c->name, err));
    if (is_wl && !c->is_string) {
      TRY(put_text_att(ncid, fv->coord[k], "units", "nm", err));
      TRY(put_text_att(ncid, fv->coord[k], "standard_name", "radiation_wavelength", err));
    } else if (!c->is_string) {
      TRY(put_text_att(ncid, fv->coord[k], "units", "1", err));
    }
  }
  TRY(def_ctx_var2(w, "context", NC_STRING, -1, 0, NULL, &fv->ctx, err));
  TRY(put_text_att(ncid, fv->ctx, "long_name", "kernel context id", err));
  if (w->grid) coords_add(w, "context");
  bool any_wl = false;
  for (size_t i = 0; d->wavelengths && !rgb && i < d->n_contexts; i++) any_wl |= isfinite(d->wavelengths[i]);
  if (any_wl && !wl_coord) {
    TRY(def_ctx_var2(w, "wavelength", NC_DOUBLE, -1, 0, NULL, &fv->wl, err));
    double fill = NAN;
    NC_TRY(nc_def_var_fill(ncid, fv->wl, 0, &fill), "wavelength");
    TRY(put_text_att(ncid, fv->wl, "long_name", "wavelength", err));
    TRY(put_text_att(ncid, fv->wl, "standard_name", "radiation_wavelength", err));
    TRY(put_text_att(ncid, fv->wl, "units", "nm", err));
    coords_add(w, "wavelength");
  }
  /* Jobs with bands: the node wavelengths and the bands, each a
   * dimension with its coordinate variable. */
  if (d->n_nodes) {
    NC_TRY(nc_def_dim(ncid, "wavelength", d->n_nodes, &w->wl_dim), "wavelength");
    NC_TRY(nc_def_var(ncid, "wavelength", NC_DOUBLE, 1, &w->wl_dim, &fv->nodes), "wavelength");
    TRY(put_text_att(ncid, fv->nodes, "long_name", "wavelength", err));
    TRY(put_text_att(ncid, fv->nodes, "standard_name", "radiation_wavelength", err));
    TRY(put_text_att(ncid, fv->nodes, "units", "nm", err));
    TRY(put_text_att(ncid, fv->nodes, "comment", "the quadrature nodes of the job's bands", err));
  }
  if (d->n_bands) {
    NC_TRY(nc_def_dim(ncid, "band", d->n_bands, &w->band_dim), "band");
    NC_TRY(nc_def_var(ncid, "band", NC_STRING, 1, &w->band_dim, &fv->bands), "band");
    TRY(put_text_att(ncid, fv->bands, "long_name", "spectral band (the job's band ids)", err));
  }
  return RSW_OK;
}

/* Whether a coord named `name` labels the contexts (it wins over a
 * variable the writer would define under that name). */
static bool coord_taken(const writer *w, const char *name) {
  const nc_coords *cs = w->d->coords;
  for (size_t k = 0; cs && k < cs->n; k++)
    if (strcmp(cs->c[k].name, name) == 0) return true;
  return false;
}

/* The sun's angles per context, from the films (any sensor, any node):
 * coordinates, unless a coord of the same name labels the contexts. */
static rsw_status define_sun(writer *w, file_vars *fv, rsw_err *err) {
  const nc_dataset *d = w->d;
  int ncid = w->ncid;
  fv->sun_deg = calloc(2 * (d->n_contexts ? d->n_contexts : 1), sizeof *fv->sun_deg);
  if (!fv->sun_deg) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  double *sun = fv->sun_deg;
  bool any_sun = false;
  for (size_t c = 0; c < 2 * d->n_contexts; c++) sun[c] = NAN;
  for (size_t i = 0; i < d->n_films; i++) {
    const nc_film *f = &d->films[i];
    if (!f->has_sun || f->context >= d->n_contexts || isfinite(sun[2 * f->context])) continue;
    sun[2 * f->context] = canonical_angle(f->sun_zenith);
    sun[2 * f->context + 1] = canonical_angle(f->sun_azimuth);
    any_sun = true;
  }
  static const char *const sun_std[2] = {"solar_zenith_angle", "solar_azimuth_angle"};
  static const char *const sun_long[2] = {"solar zenith angle", "solar azimuth angle"};
  for (int a = 0; any_sun && a < 2; a++) {
    if (coord_taken(w, sun_names[a])) continue;
    TRY(def_ctx_var2(w, sun_names[a], NC_DOUBLE, -1, 0, NULL, &fv->sun[a], err));
    double fill = NAN;
    NC_TRY(nc_def_var_fill(ncid, fv->sun[a], 0, &fill), sun_names[a]);
    TRY(put_text_att(ncid, fv->sun[a], "long_name", sun_long[a], err));
    TRY(put_text_att(ncid, fv->sun[a], "standard_name", sun_std[a], err));
    TRY(put_text_att(ncid, fv->sun[a], "units", "degree", err));
    TRY(put_text_att(ncid, fv->sun[a], "comment",
                     a == 0 ? "zenith of the direction towards the directional emitter (from +z)"
                            : "its azimuth, counter-clockwise from +x (Eradiate's convention)",
                     err));
    coords_add(w, sun_names[a]);
  }
  return RSW_OK;
}

/* A sensor's viewing angles per pixel: coordinates, one image for the
 * sensor when every film has the same angles, else one per film. */
static rsw_status define_view_angles(writer *w, const sensor_set *s, sensor_vars *v, rsw_err *err) {
  int ncid = w->ncid;
  char nm[160];
  int dyx[2] = {s->dim_y, s->dim_x};
  const char *names[2] = {"vza", "vaa"};
  const char *std[2] = {"sensor_zenith_angle", "sensor_azimuth_angle"};
  const char *longn[2] = {"viewing zenith angle", "viewing azimuth angle"};
  int *ids[2] = {&v->vza, &v->vaa};
  for (int a = 0; a < 2; a++) {
    name_cat(nm, sizeof nm, s->prefix, names[a]);
    if (s->same_angles)
      NC_TRY(nc_def_var(ncid, nm, NC_DOUBLE, 2, dyx, ids[a]), nm);
    else
      TRY(def_ctx_var(w, nm, NC_DOUBLE, 2, dyx, ids[a], err));
    double fill = NAN;
    NC_TRY(nc_def_var_fill(ncid, *ids[a], 0, &fill), nm);
    TRY(put_text_att(ncid, *ids[a], "long_name", longn[a], err));
    TRY(put_text_att(ncid, *ids[a], "standard_name", std[a], err));
    TRY(put_text_att(ncid, *ids[a], "units", "degree", err));
    TRY(put_text_att(ncid, *ids[a], "comment",
                     a == 0 ? "zenith of the direction the pixel looks from (the reverse of its ray)"
                            : "azimuth of that direction, Eradiate's convention: counter-clockwise "
                              "from the +x (east) axis",
                     err));
    coords_add(w, nm);
  }
  return RSW_OK;
}

/* A sensor's images, one float variable per quantity, chunked one image
 * per chunk. */
static rsw_status define_quantities(writer *w, const sensor_set *s, sensor_vars *v, rsw_err *err) {
  int ncid = w->ncid;
  const nc_film *sh = s->shape;
  bool rgb = is_rgb(w->d);
  char nm[160];
  for (size_t q = 0; q < s->n_q; q++) {
    const nc_quantity *qq = nc_quantity_find(s->qnames[q]);
    const struct polar *pq = polar_find(qq->name);
    name_cat(nm, sizeof nm, s->prefix, qq->name);
    /* y, x, then stokes (not for DoLP and AoLP) and channel where the
     * sensor has them; each chunk one whole image. */
    int extra[4];
    size_t ext[4];
    int n_extra = 0;
    extra[n_extra] = s->dim_y, ext[n_extra++] = (size_t)sh->height;
    extra[n_extra] = s->dim_x, ext[n_extra++] = (size_t)sh->width;
    if (s->stokes && !pq) extra[n_extra] = s->dim_st, ext[n_extra++] = 4;
    if (s->dim_ch >= 0) extra[n_extra] = s->dim_ch, ext[n_extra++] = (size_t)s->n_col;
    int id;
    int mid = band_quantity(qq->name) ? w->band_dim : w->wl_dim;
    TRY(def_ctx_var2(w, nm, NC_FLOAT, mid, n_extra, extra, &id, err));
    v->q[q] = id;
    float fill = NAN;
    NC_TRY(nc_def_var_fill(ncid, id, 0, &fill), nm);
    size_t chunk[NC_MAX_COORDS + 5], nd = 0;
    for (size_t k = 0; k < w->n_cdims; k++) chunk[nd++] = 1;
    if (mid >= 0) chunk[nd++] = 1;
    for (int k = 0; k < n_extra; k++) chunk[nd++] = ext[k];
    NC_TRY(nc_def_var_chunking(ncid, id, NC_CHUNKED, chunk), nm);
    TRY(put_text_att(ncid, id, "long_name", qq->long_name, err));
    TRY(put_text_att(ncid, id, "units", rgb ? qq->units_rgb : qq->units_mono, err));
    TRY(put_text_att(ncid, id, "sensor", s->id, err));
    if (pq && pq->aolp) TRY(put_text_att(ncid, id, "comment", AOLP_COMMENT, err));
    if (pq && !pq->aolp)
      TRY(put_text_att(ncid, id, "comment", "sqrt(S1^2 + S2^2) / S0, 0 where S0 = 0", err));
    if (w->coordinates[0]) TRY(put_text_att(ncid, id, "coordinates", w->coordinates, err));
  }
  return RSW_OK;
}

/* A sensor's per-film numbers: seed, spp (when it varies), E_h, the
 * rays that could not be resolved (UNRESOLVED_WHY) and the environment plugin
 * answers replaced by black. */
static rsw_status define_film_numbers(writer *w, const sensor_set *s, sensor_vars *v, rsw_err *err) {
  int ncid = w->ncid;
  bool rgb = is_rgb(w->d);
  char nm[160];
  name_cat(nm, sizeof nm, s->prefix, "seed");
  TRY(def_ctx_var(w, nm, NC_UINT64, 0, NULL, &v->seed, err));
  TRY(put_text_att(ncid, v->seed, "long_name", "render seed", err));
  TRY(put_text_att(ncid, v->seed, "units", "1", err));
  if (w->missing) {
    unsigned long long fill = 0;
    NC_TRY(nc_def_var_fill(ncid, v->seed, 0, &fill), nm);
  }
  v->spp = -1;
  if (!w->spp_uniform) {
    name_cat(nm, sizeof nm, s->prefix, "spp");
    TRY(def_ctx_var(w, nm, NC_UINT, 0, NULL, &v->spp, err));
    TRY(put_text_att(ncid, v->spp, "long_name", "samples per pixel", err));
    TRY(put_text_att(ncid, v->spp, "units", "1", err));
    if (w->missing) {
      unsigned fill = 0;
      NC_TRY(nc_def_var_fill(ncid, v->spp, 0, &fill), nm);
    }
  }
  /* E_h, the irradiance the brdf and brf divide by (Eradiate's
   * "irradiance": horizontal spectral irradiance), per channel. */
  v->irr = v->irr_srf = -1;
  for (int b = 0; b < 2; b++) {
    if (!(b ? s->any_band_irr : s->any_irr)) continue;
    int *id = b ? &v->irr_srf : &v->irr;
    name_cat(nm, sizeof nm, s->prefix, b ? "irradiance_srf" : "irradiance");
    /* A coord of that name (a sweep over an irradiance) labels the
     * contexts already: it wins, as for sza and saa. */
    if (coord_taken(w, nm)) continue;
    TRY(def_ctx_var2(w, nm, NC_DOUBLE, b ? w->band_dim : w->wl_dim, s->dim_ch >= 0 ? 1 : 0, &s->dim_ch, id,
                     err));
    double fill = NAN;
    NC_TRY(nc_def_var_fill(ncid, *id, 0, &fill), nm);
    TRY(put_text_att(ncid, *id, "long_name",
                     b ? "horizontal irradiance of the directional emitters (SRF-weighted)"
                       : "horizontal irradiance of the directional emitters",
                     err));
    TRY(put_text_att(ncid, *id, "units", rgb ? "W m-2" : "W m-2 nm-1", err));
    TRY(put_text_att(ncid, *id, "sensor", s->id, err));
  }
  v->unres = -1;
  if (s->any_unresolved) {
    name_cat(nm, sizeof nm, s->prefix, "unresolved_rays");
    TRY(def_ctx_var(w, nm, NC_UINT64, 0, NULL, &v->unres, err));
    TRY(put_text_att(ncid, v->unres, "long_name", "rays that could not be resolved (periodic slab, media tracks given up)", err));
    TRY(put_text_att(ncid, v->unres, "units", "1", err));
  }
  /* Plugin failures: always there, 0 and "" for a clean film, so that
   * code reading a dataset finds the same variables whether or not a
   * plugin misbehaved (unlike unresolved_rays, which predates the rule).
   * A missing film's count is unknown: _FillValue (netCDF's default for
   * uint64, which xarray then reads as NaN) rather than a 0 it never
   * earned. */
  name_cat(nm, sizeof nm, s->prefix, "plugin_failures");
  TRY(def_ctx_var(w, nm, NC_UINT64, 0, NULL, &v->pf, err));
  TRY(put_text_att(ncid, v->pf, "long_name", "environment plugin answers replaced by black", err));
  TRY(put_text_att(ncid, v->pf, "units", "1", err));
  TRY(put_text_att(ncid, v->pf, "comment",
                   "per film: how many times an environment plugin answered a non-finite or negative "
                   "radiance (or a bad pdf or direction) that the renderer replaced by black "
                   "(0: none; docs/environment-plugins.md)",
                   err));
  if (w->missing) {
    unsigned long long fill = NC_FILL_UINT64;
    NC_TRY(nc_def_var_fill(ncid, v->pf, 0, &fill), nm);
  }
  name_cat(nm, sizeof nm, s->prefix, "plugin_failure");
  TRY(def_ctx_var(w, nm, NC_STRING, 0, NULL, &v->pf_msg, err));
  TRY(put_text_att(ncid, v->pf_msg, "long_name", "first environment plugin answer replaced by black", err));
  TRY(put_text_att(ncid, v->pf_msg, "comment",
                   "per film: the first such answer's message, naming the emitter and the plugin type "
                   "(empty: none)",
                   err));
  return RSW_OK;
}

/* One sensor's dimensions (y, x, channel) and variables; coordinates are
 * the layout's (base_len bytes of w->coordinates) and its own. */
static rsw_status define_sensor(writer *w, sensor_set *s, sensor_vars *v, size_t base_len, rsw_err *err) {
  int ncid = w->ncid;
  const nc_film *sh = s->shape;
  char nm[160];
  w->coordinates[base_len] = '\0';
  name_cat(nm, sizeof nm, s->prefix, "y");
  NC_TRY(nc_def_dim(ncid, nm, (size_t)sh->height, &s->dim_y), nm);
  name_cat(nm, sizeof nm, s->prefix, "x");
  NC_TRY(nc_def_dim(ncid, nm, (size_t)sh->width, &s->dim_x), nm);
  s->dim_ch = s->dim_st = -1;
  v->ch = v->st = -1;
  if (s->stokes) {
    name_cat(nm, sizeof nm, s->prefix, "stokes");
    NC_TRY(nc_def_dim(ncid, nm, 4, &s->dim_st), nm);
    NC_TRY(nc_def_var(ncid, nm, NC_STRING, 1, &s->dim_st, &v->st), nm);
    TRY(put_text_att(ncid, v->st, "long_name", "Stokes parameter", err));
    TRY(put_text_att(ncid, v->st, "comment", STOKES_COMMENT, err));
  }
  if (s->n_col > 1) {
    name_cat(nm, sizeof nm, s->prefix, "channel");
    NC_TRY(nc_def_dim(ncid, nm, (size_t)s->n_col, &s->dim_ch), nm);
    NC_TRY(nc_def_var(ncid, nm, NC_STRING, 1, &s->dim_ch, &v->ch), nm);
    TRY(put_text_att(ncid, v->ch, "long_name", "film channel", err));
  }
  if (s->any_angles) TRY(define_view_angles(w, s, v, err));
  TRY(define_quantities(w, s, v, err));
  return define_film_numbers(w, s, v, err);
}

/* Values of the layout: coords, context ids, wavelengths, the sun's
 * angles, node wavelengths and band ids. Each variable in one write, its
 * values in layout order (w->cell): a write costs HDF5 about as much for
 * one value as for all of them. A wavelength or sun angle that is not
 * finite is the variable's fill value, NaN. */
static rsw_status put_layout(const writer *w, const file_vars *fv, rsw_err *err) {
  const nc_dataset *d = w->d;
  int ncid = w->ncid;
  const nc_coords *cs = d->coords && d->coords->n ? d->coords : NULL;
  size_t n = d->n_contexts, most = n;
  for (size_t k = 0; cs && w->grid && k < cs->n; k++) most = w->ax[k].n > most ? w->ax[k].n : most;
  double *num = malloc((most ? most : 1) * sizeof *num);
  const char **str = malloc((most ? most : 1) * sizeof *str);
  int rc = num && str ? NC_NOERR : NC_ENOMEM;
  const char *what = "layout";
  for (size_t k = 0; rc == NC_NOERR && cs && k < cs->n; k++) {
    const nc_coord *c = &cs->c[k];
    size_t len = w->grid ? w->ax[k].n : n;
    for (size_t r = 0; r < len; r++) {
      size_t ctx = w->grid ? w->ax[k].first[r] : r;
      if (c->is_string)
        str[r] = c->str[ctx];
      else
        num[r] = c->num[ctx];
    }
    what = c->name;
    rc = c->is_string ? nc_put_var_string(ncid, fv->coord[k], str)
                      : nc_put_var_double(ncid, fv->coord[k], num);
  }
  if (rc == NC_NOERR) {
    for (size_t ctx = 0; ctx < n; ctx++) str[w->cell[ctx]] = d->context_ids[ctx];
    what = "context";
    if (n) rc = nc_put_var_string(ncid, fv->ctx, str);
  }
  if (rc == NC_NOERR && fv->wl >= 0 && n) {
    for (size_t ctx = 0; ctx < n; ctx++)
      num[w->cell[ctx]] = isfinite(d->wavelengths[ctx]) ? d->wavelengths[ctx] : NAN;
    what = "wavelength";
    rc = nc_put_var_double(ncid, fv->wl, num);
  }
  for (int a = 0; rc == NC_NOERR && a < 2 && n; a++) {
    if (fv->sun[a] < 0) continue; /* none, or a coord of that name labels the contexts */
    for (size_t ctx = 0; ctx < n; ctx++) {
      double v = fv->sun_deg[2 * ctx + (size_t)a];
      num[w->cell[ctx]] = isfinite(v) ? v : NAN;
    }
    what = sun_names[a];
    rc = nc_put_var_double(ncid, fv->sun[a], num);
  }
  free(num);
  free(str);
  if (rc != NC_NOERR) return nc_fail(err, rc, what);
  if (fv->nodes >= 0) NC_TRY(nc_put_var_double(ncid, fv->nodes, d->nodes), "wavelength");
  for (size_t b = 0; fv->bands >= 0 && b < d->n_bands; b++) {
    const char *p = d->band_ids[b];
    NC_TRY(nc_put_var1_string(ncid, fv->bands, &b, &p), "band");
  }
  return RSW_OK;
}

/* Viewing angles (np pixels of (zenith, azimuth)) into vza and vaa: the
 * whole variables (start NULL) or one film's image at start/count. */
static rsw_status put_view_angles(const writer *w, const sensor_vars *v, const double *angles, size_t np,
                                  const size_t *start, const size_t *count, rsw_err *err) {
  double *za = malloc(np * 2 * sizeof *za);
  if (!za) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  for (size_t p = 0; p < np; p++)
    za[p] = canonical_angle(angles[2 * p]), za[np + p] = canonical_angle(angles[2 * p + 1]);
  int rc =
      start ? nc_put_vara_double(w->ncid, v->vza, start, count, za) : nc_put_var_double(w->ncid, v->vza, za);
  if (rc == NC_NOERR)
    rc = start ? nc_put_vara_double(w->ncid, v->vaa, start, count, za + np)
               : nc_put_var_double(w->ncid, v->vaa, za + np);
  free(za);
  return rc == NC_NOERR ? RSW_OK : nc_fail(err, rc, "vza");
}

/* Film f of sensor s (a node or plain film, or a band film: is_band) at
 * its context's cell and its node or band (mid). deriv: room for one image
 * of derived standard errors. */
static rsw_status put_film(const writer *w, const sensor_set *s, const sensor_vars *v, const nc_film *f,
                           size_t ctx, size_t mid, bool is_band, float *deriv, rsw_err *err) {
  int ncid = w->ncid;
  size_t np = (size_t)s->shape->width * (size_t)s->shape->height;
  size_t start[NC_MAX_COORDS + 5], count[NC_MAX_COORDS + 5];
  bool has_mid = is_band ? w->band_dim >= 0 : w->wl_dim >= 0;
  cell_start(w, ctx, start);
  size_t nd = w->n_cdims;
  if (has_mid) start[nd++] = mid;
  for (size_t q = 0; q < nd; q++) count[q] = 1;
  /* (seed, spp and unresolved_rays: put_film_numbers, a variable at once) */
  int irr = is_band ? v->irr_srf : v->irr;
  if (irr >= 0 && f->has_irradiance) {
    /* Per colour: a Stokes film's E_h is its colours' (the first n_col
     * values), the same for every component. */
    start[nd] = 0, count[nd] = (size_t)s->n_col;
    NC_TRY(nc_put_vara_double(ncid, irr, start, count, f->irradiance), "irradiance");
  }
  /* y, x, then the film's channels: [stokes, ][channel]. */
  size_t ncd = 2;
  start[nd] = start[nd + 1] = start[nd + 2] = start[nd + 3] = 0;
  count[nd] = (size_t)f->height, count[nd + 1] = (size_t)f->width;
  if (s->stokes) count[nd + ncd++] = 4;
  if (s->dim_ch >= 0) count[nd + ncd++] = (size_t)s->n_col;
  /* (a node or plain film's quantities: put_film_quantities, a variable at once) */
  for (size_t q = 0; is_band && q < f->n_vars; q++) {
    size_t qi = 0;
    while (strcmp(s->qnames[qi], f->vars[q].name) != 0) qi++;
    NC_TRY(nc_put_vara_float(ncid, v->q[qi], start, count, f->vars[q].data), f->vars[q].name);
  }
  /* Derived standard errors: pi * stderr / E per channel. */
  for (size_t dq = 0; dq < N_DERIVED && f->has_irradiance; dq++) {
    const float *from = NULL, *needs = NULL;
    for (size_t q = 0; q < f->n_vars; q++) {
      if (strcmp(f->vars[q].name, derived[dq].from) == 0) from = f->vars[q].data;
      if (strcmp(f->vars[q].name, derived[dq].needs) == 0) needs = f->vars[q].data;
    }
    size_t qi = 0;
    while (qi < s->n_q && strcmp(s->qnames[qi], derived[dq].name) != 0) qi++;
    if (!from || !needs || qi == s->n_q) continue;
    size_t C = (size_t)f->channels, K = (size_t)s->n_col;
    for (size_t p = 0; p < np * C; p++) deriv[p] = (float)(M_PI * (double)from[p] / f->irradiance[p % C % K]);
    NC_TRY(nc_put_vara_float(ncid, v->q[qi], start, count, deriv), derived[dq].name);
  }
  /* DoLP and AoLP per pixel and colour, from the film's Stokes vector
   * (component-major channels: S_k of colour c is channel k K + c). */
  for (size_t pk = 0; pk < N_POLAR && s->stokes; pk++) {
    const float *from = NULL;
    for (size_t q = 0; q < f->n_vars; q++)
      if (strcmp(f->vars[q].name, polar[pk].from) == 0) from = f->vars[q].data;
    size_t qi = 0;
    while (qi < s->n_q && strcmp(s->qnames[qi], polar[pk].name) != 0) qi++;
    if (!from || qi == s->n_q) continue;
    size_t C = (size_t)f->channels, K = (size_t)s->n_col;
    for (size_t p = 0; p < np; p++)
      for (size_t c = 0; c < K; c++) {
        const float *st = from + p * C + c;
        deriv[p * K + c] = (float)(polar[pk].aolp ? stokes_aolp_deg(st[K], st[2 * K])
                                                  : stokes_dolp(st[0], st[K], st[2 * K]));
      }
    size_t pcount[NC_MAX_COORDS + 5];
    memcpy(pcount, count, sizeof pcount);
    pcount[nd + 2] = K; /* y, x[, channel]: beyond the dims when K = 1 */
    NC_TRY(nc_put_vara_float(ncid, v->q[qi], start, pcount, deriv), polar[pk].name);
  }
  if (!is_band && s->any_angles && !s->same_angles && f->angles)
    TRY(put_view_angles(w, v, f->angles, np, start, count, err));
  return RSW_OK;
}

/* A sensor's channel labels (the film's channel names, or a Stokes
 * film's colours) and Stokes labels S0..S3. */
static rsw_status put_labels(const writer *w, const sensor_set *s, const sensor_vars *v, rsw_err *err) {
  static const char *const st_names[4] = {"S0", "S1", "S2", "S3"};
  for (size_t k = 0; v->st >= 0 && k < 4; k++) {
    const char *p = st_names[k];
    NC_TRY(nc_put_var1_string(w->ncid, v->st, &k, &p), "stokes");
  }
  for (size_t k = 0; v->ch >= 0 && k < (size_t)s->n_col; k++) {
    const char *p = s->stokes ? s->sl.color[k] : s->shape->channel_names[k];
    NC_TRY(nc_put_var1_string(w->ncid, v->ch, &k, &p), "channel");
  }
  return RSW_OK;
}

/* A sensor's plugin failures, each variable in one call (a call per film
 * doubled the time to encode 200 small films): counts and messages in the
 * variables' C order, the layout's cell (w->cell) then the node. */
static rsw_status put_plugin_failures(const writer *w, const sensor_set *s, const sensor_vars *v,
                                      rsw_err *err) {
  size_t n = w->n_cells * w->slots;
  unsigned long long *count = malloc((n ? n : 1) * sizeof *count);
  const char **msg = malloc((n ? n : 1) * sizeof *msg);
  rsw_status st = RSW_OK;
  if (!count || !msg) st = rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  for (size_t k = 0; !st && k < n; k++) {
    const nc_film *f = s->by_ctx[k];
    size_t at = w->cell[k / w->slots] * w->slots + k % w->slots;
    count[at] = f ? f->plugin_failures : NC_FILL_UINT64;
    msg[at] = f && f->plugin_failures && f->plugin_failure ? f->plugin_failure : "";
  }
  int rc = st ? NC_NOERR : nc_put_var_ulonglong(w->ncid, v->pf, count);
  if (rc == NC_NOERR && !st) rc = nc_put_var_string(w->ncid, v->pf_msg, msg);
  if (!st && rc != NC_NOERR) st = nc_fail(err, rc, "plugin_failures");
  free(count);
  free(msg);
  return st;
}

/* A sensor's node (or plain) films' quantities, each variable in as few
 * calls as d->slab_bytes allows (a call per film cost HDF5 about as much
 * as the whole variable): the images in the variable's C order, the
 * layout's cell (w->cell), the node, then y, x[, stokes][, channel]; NaN,
 * the fill value, where a film is missing or lacks the quantity. A slab
 * is a run of positions in that order that is a box of the leading
 * dimensions: a fixed index in the dimensions before some j, a range in
 * j, all of the ones after. */
static rsw_status put_film_quantities(const writer *w, const sensor_set *s, const sensor_vars *v,
                                      rsw_err *err) {
  size_t n = w->n_cells * w->slots;
  size_t img = (size_t)s->shape->width * (size_t)s->shape->height * (s->stokes ? 4 : 1) *
               (s->dim_ch >= 0 ? (size_t)s->n_col : 1);
  if (!n || !img) return RSW_OK;
  /* The leading dimensions (the layout's, then the node's where the job
   * has bands) and their lengths; then the image's. */
  size_t len[NC_MAX_COORDS + 5], start[NC_MAX_COORDS + 5], count[NC_MAX_COORDS + 5];
  int m = 0;
  for (size_t k = 0; k < w->n_cdims; k++) {
    int rc = nc_inq_dimlen(w->ncid, w->cdim[k], &len[m++]);
    if (rc != NC_NOERR) return nc_fail(err, rc, "dimensions");
  }
  if (w->wl_dim >= 0) len[m++] = w->slots;
  int nd = m;
  len[nd++] = (size_t)s->shape->height, len[nd++] = (size_t)s->shape->width;
  if (s->stokes) len[nd++] = 4;
  if (s->dim_ch >= 0) len[nd++] = (size_t)s->n_col;
  /* The slab: inner[j] positions per step of dimension j; the first j
   * whose step fits the budget (the last, one image a call, at least),
   * and steps of it per call. */
  size_t budget = w->d->slab_bytes ? w->d->slab_bytes : NC_SLAB_BYTES;
  size_t max_imgs = budget / (img * sizeof(float)) ? budget / (img * sizeof(float)) : 1;
  size_t inner[NC_MAX_COORDS + 5];
  inner[m - 1] = 1;
  for (int k = m - 2; k >= 0; k--) inner[k] = inner[k + 1] * len[k + 1];
  int j = 0;
  while (j < m - 1 && inner[j] > max_imgs) j++;
  size_t step = max_imgs / inner[j] < len[j] ? max_imgs / inner[j] : len[j];
  if (!step) step = 1;
  size_t per_call = step * inner[j] < n ? step * inner[j] : n;
  /* Which film (by_ctx index) each position holds, SIZE_MAX: none. */
  size_t *at_pos = malloc(n * sizeof *at_pos);
  float *buf = at_pos ? malloc(per_call * img * sizeof *buf) : NULL;
  rsw_status st = buf ? RSW_OK : rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  for (size_t k = 0; !st && k < n; k++) at_pos[k] = SIZE_MAX;
  for (size_t k = 0; !st && k < n; k++)
    if (s->by_ctx[k]) at_pos[w->cell[k / w->slots] * w->slots + k % w->slots] = k;
  for (size_t qi = 0; !st && qi < s->n_q; qi++) {
    bool any = false;
    for (size_t k = 0; k < n && !any; k++)
      for (size_t q = 0; s->by_ctx[k] && q < s->by_ctx[k]->n_vars && !any; q++)
        any = strcmp(s->by_ctx[k]->vars[q].name, s->qnames[qi]) == 0;
    if (!any) continue; /* derived, or a band quantity */
    for (size_t base = 0; !st && base < n;) {
      /* The box at base: j's index runs to the end of its dimension at
       * most (base is a multiple of inner[j]). */
      size_t ij = base / inner[j] % len[j];
      size_t steps = len[j] - ij < step ? len[j] - ij : step, cnt = steps * inner[j];
      for (int k = 0; k < nd; k++) {
        start[k] = k < m ? base / inner[k] % len[k] : 0;
        count[k] = k < j ? 1 : k == j ? steps : len[k];
      }
      for (size_t i = 0; i < cnt; i++) {
        size_t k = at_pos[base + i];
        const nc_film *f = k == SIZE_MAX ? NULL : s->by_ctx[k];
        const float *src = NULL;
        for (size_t q = 0; f && q < f->n_vars && !src; q++)
          if (strcmp(f->vars[q].name, s->qnames[qi]) == 0) src = f->vars[q].data;
        if (src)
          memcpy(buf + i * img, src, img * sizeof *buf);
        else
          for (size_t x = 0; x < img; x++) buf[i * img + x] = NAN;
      }
      int rc = cnt == n ? nc_put_var_float(w->ncid, v->q[qi], buf)
                        : nc_put_vara_float(w->ncid, v->q[qi], start, count, buf);
      if (rc != NC_NOERR) st = nc_fail(err, rc, s->qnames[qi]);
      base += cnt;
    }
  }
  free(buf);
  free(at_pos);
  return st;
}

/* A sensor's seed, spp (when it varies) and unresolved rays, each
 * variable in one call as put_plugin_failures: a missing film's seed and
 * spp are 0 (their fill value when films are missing), its unresolved
 * rays the fill value. */
static rsw_status put_film_numbers(const writer *w, const sensor_set *s, const sensor_vars *v, rsw_err *err) {
  size_t n = w->n_cells * w->slots;
  if (!n) return RSW_OK;
  unsigned long long *seed = malloc(n * sizeof *seed), *unres = malloc(n * sizeof *unres);
  unsigned *spp = malloc(n * sizeof *spp);
  rsw_status st = RSW_OK;
  if (!seed || !unres || !spp) st = rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  for (size_t k = 0; !st && k < n; k++) {
    const nc_film *f = s->by_ctx[k];
    size_t at = w->cell[k / w->slots] * w->slots + k % w->slots;
    seed[at] = f ? f->seed : 0;
    spp[at] = f ? f->spp : 0;
    unres[at] = f ? f->unresolved_rays : NC_FILL_UINT64;
  }
  int rc = st ? NC_NOERR : nc_put_var_ulonglong(w->ncid, v->seed, seed);
  const char *what = "seed";
  if (rc == NC_NOERR && !st && v->spp >= 0) what = "spp", rc = nc_put_var_uint(w->ncid, v->spp, spp);
  if (rc == NC_NOERR && !st && v->unres >= 0)
    what = "unresolved_rays", rc = nc_put_var_ulonglong(w->ncid, v->unres, unres);
  if (!st && rc != NC_NOERR) st = nc_fail(err, rc, what);
  free(seed);
  free(unres);
  free(spp);
  return st;
}

/* A sensor's films: its shared viewing angles, then node (or plain)
 * films, then band films. */
static rsw_status put_sensor(const writer *w, const sensor_set *s, const sensor_vars *v, rsw_err *err) {
  const nc_dataset *d = w->d;
  const nc_film *sh = s->shape;
  size_t np = (size_t)sh->width * (size_t)sh->height;
  float *deriv = malloc(np * (size_t)sh->channels * sizeof *deriv + 1);
  if (!deriv) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  rsw_status st = put_labels(w, s, v, err);
  if (!st && s->any_angles && s->same_angles) st = put_view_angles(w, v, sh->angles, np, NULL, NULL, err);
  size_t n_slots = d->n_contexts * w->slots, n_all = n_slots + d->n_contexts * d->n_bands;
  for (size_t k = 0; !st && k < n_all; k++) {
    bool is_band = k >= n_slots;
    const nc_film *f = is_band ? s->by_band[k - n_slots] : s->by_ctx[k];
    if (!f) continue;
    size_t ctx = is_band ? (k - n_slots) / d->n_bands : k / w->slots;
    size_t mid = is_band ? (k - n_slots) % d->n_bands : k % w->slots;
    st = put_film(w, s, v, f, ctx, mid, is_band, deriv, err);
  }
  free(deriv);
  if (!st) st = put_film_quantities(w, s, v, err);
  if (!st) st = put_film_numbers(w, s, v, err);
  return st ? st : put_plugin_failures(w, s, v, err);
}

static rsw_status write_all(writer *w, rsw_err *err) {
  file_vars fv = {.wl = -1, .nodes = -1, .bands = -1, .sun = {-1, -1}};
  rsw_status st = write_globals(w, err);
  if (!st) st = define_layout(w, &fv, err);
  if (!st) st = define_sun(w, &fv, err);
  size_t base_len = strlen(w->coordinates);
  if (!st && !(fv.sv = calloc(w->n_s ? w->n_s : 1, sizeof *fv.sv)))
    st = rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  for (size_t i = 0; !st && i < w->n_s; i++) st = define_sensor(w, &w->s[i], &fv.sv[i], base_len, err);
  if (!st) {
    int rc = nc_enddef(w->ncid);
    if (rc != NC_NOERR) st = nc_fail(err, rc, "enddef");
  }
  if (!st) st = put_layout(w, &fv, err);
  for (size_t i = 0; !st && i < w->n_s; i++) st = put_sensor(w, &w->s[i], &fv.sv[i], err);
  free(fv.sun_deg);
  free(fv.sv);
  return st;
}

/* Plan and write d into the open ncid. */
static rsw_status build(int ncid, const nc_dataset *d, rsw_err *err) {
  writer w = {.d = d, .ncid = ncid, .wl_dim = -1, .band_dim = -1};
  rsw_status st = RSW_OK;
  if (!d || d->size < sizeof *d || (d->n_contexts && !d->context_ids))
    st = rsw_fail(err, RSW_ERR_INVALID, "", "a dataset needs its size and context ids");
  if (!st && ((d->n_nodes && !d->nodes) || (d->n_bands && !d->band_ids)))
    st = rsw_fail(err, RSW_ERR_INVALID, "", "a dataset with bands needs its node wavelengths and band ids");
  if (!st) w.slots = d->n_nodes ? d->n_nodes : 1;
  if (!st) st = plan_layout(&w, err);
  if (!st) st = plan_sensors(&w, err);
  if (!st) st = write_all(&w, err);
  writer_free(&w);
  return st;
}

/* A rough size of the file, for the in-memory buffer's first allocation. */
static size_t size_hint(const nc_dataset *d) {
  size_t b = 1 << 16;
  for (size_t i = 0; d && i < d->n_films; i++)
    b += (size_t)d->films[i].width * d->films[i].height * d->films[i].channels * 4 * d->films[i].n_vars;
  return b;
}

void nc_dataset_init(void) {
  pthread_mutex_lock(&g_nc_lock);
  nc_initialize(); /* (once: libnetcdf keeps that it is) */
  pthread_mutex_unlock(&g_nc_lock);
}

rsw_status nc_dataset_write(const char *path, const nc_dataset *d, rsw_err *err) {
  if (!path || !*path) return rsw_fail(err, RSW_ERR_INVALID, "", "no path for the dataset");
  char tmp[4200];
  if ((size_t)snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid()) >= sizeof tmp)
    return rsw_fail(err, RSW_ERR_INVALID, path, "path too long");
  pthread_mutex_lock(&g_nc_lock);
  int ncid;
  int rc = nc_create(tmp, NC_NETCDF4 | NC_CLOBBER, &ncid);
  if (rc != NC_NOERR) {
    pthread_mutex_unlock(&g_nc_lock);
    return rsw_fail(err, RSW_ERR_IO, path, "cannot create the dataset: %s", nc_strerror(rc));
  }
  rsw_status st = build(ncid, d, err);
  rc = nc_close(ncid);
  pthread_mutex_unlock(&g_nc_lock);
  if (!st && rc != NC_NOERR)
    st = rsw_fail(err, RSW_ERR_IO, path, "cannot write the dataset: %s", nc_strerror(rc));
  if (!st && rename(tmp, path) != 0)
    st = rsw_fail(err, RSW_ERR_IO, path, "cannot rename the dataset into place");
  if (st) unlink(tmp);
  return st;
}

rsw_status nc_dataset_encode(const nc_dataset *d, void **bytes_out, size_t *len_out, rsw_err *err) {
  pthread_mutex_lock(&g_nc_lock);
  int ncid;
  int rc = nc_create_mem("raysweep.nc", NC_NETCDF4, size_hint(d), &ncid);
  if (rc != NC_NOERR) {
    pthread_mutex_unlock(&g_nc_lock);
    return rsw_fail(err, rc == NC_ENOMEM ? RSW_ERR_NOMEM : RSW_ERR_IO, "(dataset in memory)",
                    "cannot create the dataset: %s", nc_strerror(rc));
  }
  rsw_status st = build(ncid, d, err);
  NC_memio mio = {0};
  rc = nc_close_memio(ncid, &mio);
  pthread_mutex_unlock(&g_nc_lock);
  if (!st && rc != NC_NOERR)
    st = rsw_fail(err, RSW_ERR_IO, "(dataset in memory)", "cannot write the dataset: %s", nc_strerror(rc));
  if (st) {
    free(mio.memory);
    return st;
  }
  *bytes_out = mio.memory;
  *len_out = mio.size;
  return RSW_OK;
}
