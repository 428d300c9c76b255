/* Sweep datasets on the client: the daemon's GET /v1/jobs/{id}/dataset
 * saved to a file, and rsw_dataset, which builds the same NetCDF-4 file
 * from films the client holds (a sweep spread over several jobs, shards
 * merged) through the project's one writer, common/dataset_nc.c. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "dataset_nc.h"
#include "image_exr.h"
#include "internal.h"
#include "stokes.h"

/* A plane's channel ("brf.Y", "brf.S0.Y"): a dot after a name that is no
 * Stokes component (a mono_polarized film's radiance is "S0.Y"). */
static bool plane_channel(const char *name) {
  return strchr(name, '.') && stokes_component(name) < 0;
}

rsw_status rsw_job_fetch_dataset(rsw_client *c, const char *job_id, int partial, const char *path) {
  if (!c) return RSW_ERR_INVALID;
  client_clear_error(c);
  char rpath[320];
  if (!job_id || !*job_id || strlen(job_id) > 200 || strchr(job_id, '/'))
    return client_fail(c, RSW_ERR_INVALID, "job id missing or too long");
  if (!path || !*path) return client_fail(c, RSW_ERR_INVALID, "fetch dataset: no output path");
  char esc[256];
  if (!client_escape(job_id, esc, sizeof esc)) return client_fail(c, RSW_ERR_INVALID, "job id too long");
  snprintf(rpath, sizeof rpath, "/v1/jobs/%s/dataset%s", esc, partial ? "?partial=1" : "");
  http_resp r;
  rsw_status s = http_request(
      c, &(http_req){.method = "GET", .path = rpath, .accept = "application/x-netcdf", .computed = true}, &r);
  if (s) return s;
  size_t n = strlen(path) + 32;
  char *tmp = malloc(n);
  if (!tmp) {
    http_resp_free(&r);
    return client_fail(c, RSW_ERR_NOMEM, "out of memory");
  }
  snprintf(tmp, n, "%s.tmp.%ld", path, (long)getpid());
  FILE *f = fopen(tmp, "wb");
  bool ok = f && fwrite(r.body, 1, r.len, f) == r.len;
  if (f) ok = fclose(f) == 0 && ok;
  ok = ok && rename(tmp, path) == 0;
  int e = errno;
  if (!ok) unlink(tmp);
  free(tmp);
  http_resp_free(&r);
  if (!ok) return client_fail(c, RSW_ERR_IO, "cannot write '%s': %s", path, strerror(e));
  return RSW_OK;
}

/* ---- rsw_dataset -------------------------------------------------------------------- */

#define DS_MAX_PLANES 3

/* Where the films' pixels and angles go (rsw_dataset_set_store): the
 * heap up to `memory` bytes of them, then a file without a name in the
 * store's directory, mapped shared in blocks of STORE_BLOCK (a film over
 * that: a block of its own) and fully allocated first (posix_fallocate),
 * so that a full disk is an error here, never a SIGBUS at a page fault.
 * The kernel writes such pages back to the file and drops them as memory
 * runs short, so a dataset of any size is built in bounded memory. */
#define STORE_BLOCK ((size_t)64 << 20)

typedef struct ds_store {
  int fd; /* -1: no store (everything on the heap) */
  size_t memory, on_heap;
  off_t size; /* of the file */
  char *at;   /* the current block's free space */
  size_t left;
  struct {
    void *p;
    size_t len;
  } * maps;
  size_t n_maps, cap_maps;
  char *dir;         /* where the file is (for errors) */
  rsw_status failed; /* the last NULL's: RSW_ERR_NOMEM, or RSW_ERR_IO (the file) */
} ds_store;

/* n bytes (> 0) for pixels or angles: from the heap (*mapped false; free
 * them) while the heap holds under memory bytes of them, else from the
 * file (*mapped true: freed with the store). NULL: out of memory, or the
 * file could not grow (st->failed and err say which and why). */
static void *store_alloc(ds_store *st, size_t n, bool *mapped, char *err, size_t err_len) {
  *mapped = false;
  st->failed = RSW_ERR_NOMEM;
  if (st->fd < 0 || st->on_heap + n <= st->memory) {
    void *p = malloc(n);
    if (p) st->on_heap += n;
    if (!p) snprintf(err, err_len, "out of memory");
    return p;
  }
  n = (n + 63) & ~(size_t)63;
  if (st->left < n) {
    size_t page = (size_t)sysconf(_SC_PAGESIZE);
    size_t len = n > STORE_BLOCK ? (n + page - 1) / page * page : STORE_BLOCK;
    if (st->n_maps == st->cap_maps) {
      size_t cap = st->cap_maps ? 2 * st->cap_maps : 8;
      void *m = realloc(st->maps, cap * sizeof *st->maps);
      if (!m) {
        snprintf(err, err_len, "out of memory");
        return NULL;
      }
      st->maps = m, st->cap_maps = cap;
    }
    st->failed = RSW_ERR_IO;
    int e = posix_fallocate(st->fd, st->size, (off_t)len);
    if (e) {
      snprintf(err, err_len, "the film store in '%s' cannot grow to %.1f MiB: %s", st->dir,
               (double)(st->size + (off_t)len) / 1048576.0, strerror(e));
      return NULL;
    }
    void *p = mmap(NULL, len, PROT_READ | PROT_WRITE, MAP_SHARED, st->fd, st->size);
    if (p == MAP_FAILED) {
      snprintf(err, err_len, "cannot map the film store in '%s': %s", st->dir, strerror(errno));
      return NULL;
    }
    st->maps[st->n_maps].p = p, st->maps[st->n_maps++].len = len;
    st->size += (off_t)len;
    st->at = p, st->left = len;
  }
  void *p = st->at;
  st->at += n, st->left -= n;
  *mapped = true;
  return p;
}

static void store_close(ds_store *st) {
  for (size_t i = 0; i < st->n_maps; i++) munmap(st->maps[i].p, st->maps[i].len);
  free(st->maps);
  free(st->dir);
  if (st->fd >= 0) close(st->fd);
  *st = (ds_store){.fd = -1};
}

/* A film's pixel angles in degrees, 2 per pixel (zenith, azimuth), one
 * block for every film whose lists are the same (a sweep's films share
 * their sensor's: one copy, not one a film): refs counts the films and
 * the dataset's cache that hold it. mapped: in the store's file (not
 * freed). */
typedef struct ds_angles {
  size_t refs;
  bool mapped;
  double v[];
} ds_angles;

static ds_angles *angles_new(ds_store *st, size_t np, char *err, size_t err_len) {
  bool mapped;
  ds_angles *a = store_alloc(st, sizeof *a + (np ? 2 * np : 1) * sizeof(double), &mapped, err, err_len);
  if (a) a->refs = 1, a->mapped = mapped;
  return a;
}

static ds_angles *angles_ref(ds_angles *a) {
  if (a) a->refs++;
  return a;
}

static void angles_unref(ds_angles *a) {
  if (a && !--a->refs && !a->mapped) free(a);
}

typedef struct ds_film {
  size_t context;
  char *sensor;
  int width, height, channels;
  char **names;
  float *data;
  bool mapped;       /* data and plane_data in the store's file (not freed) */
  ds_angles *angles; /* NULL: none */
  uint32_t spp;
  uint64_t seed, unresolved;
  /* Planes after the radiance channels ("brf.Y", "radiance_stderr.R"):
   * each its own quantity, de-interleaved as the daemon keeps them
   * (render.h film_plane), so both write the same dataset. */
  int n_planes;
  char *plane_names[DS_MAX_PLANES];
  float *plane_data[DS_MAX_PLANES];
  nc_var vars[1 + DS_MAX_PLANES];
  /* From the film's meta, as the daemon's dataset takes them. */
  bool has_irradiance, has_sun;
  double irradiance[4], sun_zenith, sun_azimuth;
  uint64_t plugin_failures; /* meta's plugin_failures (absent: 0) */
  char *plugin_failure;     /* and plugin_failure; NULL with none */
} ds_film;

struct rsw_dataset {
  char **ids;
  double *wl;
  cJSON **coords;
  size_t n, cap;
  size_t last; /* the context the last film went to (films come in order) */
  ds_film *films;
  size_t nf, capf;
  char *scene, *variant;
  bool has_revision, has_seed;
  uint64_t revision, seed;
  /* rsw_dataset_add_film_exr: the last angle lists parsed (a sweep's films
   * share their sensor's), text and values (n_angles pixels), the values
   * shared with the films that have them. */
  char *angle_text[2];
  ds_angles *angle_vals;
  size_t n_angles;
  ds_store store;
  char error[1024];
};

static rsw_status ds_fail(rsw_dataset *d, rsw_status s, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static rsw_status ds_fail(rsw_dataset *d, rsw_status s, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(d->error, sizeof d->error, fmt, ap);
  va_end(ap);
  return s;
}

rsw_status rsw_dataset_new(rsw_dataset **out) {
  if (!out) return RSW_ERR_INVALID;
  rsw_dataset *d = calloc(1, sizeof *d);
  if (!d) return RSW_ERR_NOMEM;
  d->store.fd = -1;
  *out = d;
  return RSW_OK;
}

static void film_clear(ds_film *f) {
  free(f->sensor);
  for (int i = 0; f->names && i < f->channels; i++) free(f->names[i]);
  free(f->names);
  if (!f->mapped) free(f->data);
  angles_unref(f->angles);
  free(f->plugin_failure);
  for (int k = 0; k < f->n_planes; k++) {
    free(f->plane_names[k]); /* (plane_data[k] lies in data) */
  }
}

void rsw_dataset_free(rsw_dataset *d) {
  if (!d) return;
  for (size_t i = 0; i < d->n; i++) {
    free(d->ids[i]);
    cJSON_Delete(d->coords[i]);
  }
  free(d->ids);
  free(d->wl);
  free(d->coords);
  for (size_t i = 0; i < d->nf; i++) film_clear(&d->films[i]);
  free(d->films);
  free(d->scene);
  free(d->variant);
  free(d->angle_text[0]);
  free(d->angle_text[1]);
  angles_unref(d->angle_vals);
  store_close(&d->store);
  free(d);
}

rsw_status rsw_dataset_set_store(rsw_dataset *d, const char *dir, size_t memory_bytes) {
  if (!d) return RSW_ERR_INVALID;
  d->error[0] = '\0';
  if (!dir || !*dir) return ds_fail(d, RSW_ERR_INVALID, "no directory for the film store");
  if (d->store.fd >= 0) return ds_fail(d, RSW_ERR_INVALID, "the dataset has its film store already");
  /* A file without a name (O_TMPFILE; where the file system has none, one
   * made and unlinked at once): nothing is left behind, whatever ends the
   * process. */
  int fd = open(dir, O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
  if (fd < 0) {
    size_t n = strlen(dir) + 32;
    char *t = malloc(n);
    if (!t) return ds_fail(d, RSW_ERR_NOMEM, "out of memory");
    snprintf(t, n, "%s/.dataset.store.XXXXXX", dir);
    fd = mkostemp(t, O_CLOEXEC);
    int e = errno;
    if (fd >= 0) unlink(t);
    free(t);
    if (fd < 0) return ds_fail(d, RSW_ERR_IO, "cannot make a film store in '%s': %s", dir, strerror(e));
  }
  if (!(d->store.dir = strdup(dir))) {
    close(fd);
    return ds_fail(d, RSW_ERR_NOMEM, "out of memory");
  }
  d->store.fd = fd;
  d->store.memory = memory_bytes;
  return RSW_OK;
}

const char *rsw_dataset_last_error(const rsw_dataset *d) {
  return d ? d->error : "";
}

rsw_status rsw_dataset_set_seed(rsw_dataset *d, long long seed) {
  if (!d) return RSW_ERR_INVALID;
  if (seed < 0) return ds_fail(d, RSW_ERR_INVALID, "the job seed must be a non-negative integer");
  d->has_seed = true;
  d->seed = (uint64_t)seed;
  return RSW_OK;
}

rsw_status rsw_dataset_add_context(rsw_dataset *d, const char *id, double wavelength,
                                   const char *coords_json) {
  if (!d) return RSW_ERR_INVALID;
  d->error[0] = '\0';
  if (!id || !*id || strlen(id) > 64)
    return ds_fail(d, RSW_ERR_INVALID, "a context id needs 1 to 64 characters");
  cJSON *coords = NULL;
  if (coords_json) {
    coords = cJSON_Parse(coords_json);
    if (!cJSON_IsObject(coords)) {
      cJSON_Delete(coords);
      return ds_fail(d, RSW_ERR_PARSE, "context '%s': coords must be a JSON object {name: number or string}",
                     id);
    }
  }
  if (d->n == d->cap) {
    size_t cap = d->cap ? 2 * d->cap : 64;
    char **ni = realloc(d->ids, cap * sizeof *ni);
    if (ni) d->ids = ni;
    double *nw = ni ? realloc(d->wl, cap * sizeof *nw) : NULL;
    if (nw) d->wl = nw;
    cJSON **nc = nw ? realloc(d->coords, cap * sizeof *nc) : NULL;
    if (nc) d->coords = nc;
    if (!nc) {
      cJSON_Delete(coords);
      return ds_fail(d, RSW_ERR_NOMEM, "out of memory");
    }
    d->cap = cap;
  }
  char *copy = strdup(id);
  if (!copy) {
    cJSON_Delete(coords);
    return ds_fail(d, RSW_ERR_NOMEM, "out of memory");
  }
  d->ids[d->n] = copy;
  d->wl[d->n] = wavelength > 0 ? wavelength : NAN;
  d->coords[d->n] = coords;
  d->n++;
  return RSW_OK;
}

static bool find_context(rsw_dataset *d, const char *id, size_t *out) {
  for (size_t k = 0; k < d->n; k++) {
    size_t i = (d->last + k) % d->n;
    if (strcmp(d->ids[i], id) == 0) {
      *out = d->last = i;
      return true;
    }
  }
  return false;
}

/* A meta member that must be an integer in [0, max] (absent or null: false). */
static bool meta_u64(const cJSON *meta, const char *key, uint64_t *out) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(meta, key);
  if (!cJSON_IsNumber(v) || !(v->valuedouble >= 0) || v->valuedouble != floor(v->valuedouble) ||
      v->valuedouble >= 18446744073709551616.0)
    return false;
  *out = (uint64_t)v->valuedouble;
  return true;
}

/* meta's string member key equals *kept, or sets it when still unset. */
static rsw_status same_string(rsw_dataset *d, const cJSON *meta, const char *key, char **kept,
                              const char *what) {
  const char *v = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(meta, key));
  if (!v) return RSW_OK;
  if (!*kept) return (*kept = strdup(v)) ? RSW_OK : ds_fail(d, RSW_ERR_NOMEM, "out of memory");
  if (strcmp(*kept, v) != 0)
    return ds_fail(d, RSW_ERR_INVALID, "%s: %s '%s' differs from the other films' '%s'", what, key, v, *kept);
  return RSW_OK;
}

/* A film's samples and labels, however they came (rsw_film, EXR bytes). */
typedef struct film_in {
  int width, height, channels; /* channels: every one, planes' too */
  const char *const *names;
  const float *data; /* HWC */
  const cJSON *meta; /* the JSON film meta's members (the angles may be left out: angles) */
  ds_angles *angles; /* taken over (a reference); NULL: meta's zenith_deg, azimuth_deg */
} film_in;

static rsw_status add_film(rsw_dataset *d, const char *context, const char *sensor, const film_in *in) {
  ds_angles *angles_in = in->angles;
  /* The first film: libnetcdf's start-up now, while a sweep still waits
   * for renders, not when the dataset is written at its end. */
  if (!d->nf) nc_dataset_init();
  char what[400];
  snprintf(what, sizeof what, "film %.64s/%.256s", context, sensor);
  size_t ci;
  if (!find_context(d, context, &ci)) {
    angles_unref(angles_in);
    return ds_fail(d, RSW_ERR_INVALID, "%s: no context '%s' was added (rsw_dataset_add_context)", what,
                   context);
  }
  if (d->nf == d->capf) {
    size_t cap = d->capf ? 2 * d->capf : 64;
    ds_film *nf = realloc(d->films, cap * sizeof *nf);
    if (!nf) {
      angles_unref(angles_in);
      return ds_fail(d, RSW_ERR_NOMEM, "out of memory");
    }
    d->films = nf, d->capf = cap;
  }
  int all = in->channels;
  ds_film f = {.context = ci, .width = in->width, .height = in->height, .channels = all, .angles = angles_in};
  /* The radiance channels come first; every channel after them is
   * "<plane>.<channel>", the planes one after another, each with as many
   * channels as the radiance. */
  int base = 0;
  while (base < all && !plane_channel(in->names[base])) base++;
  f.channels = base;
  size_t np = (size_t)f.width * (size_t)f.height, ns = np * (size_t)f.channels;
  const cJSON *meta = in->meta;
  rsw_status s = RSW_OK;
  if (base < 1 || (all - base) % base != 0 || (all - base) / base > DS_MAX_PLANES)
    s = ds_fail(d, RSW_ERR_INVALID, "%s: channels are not the radiance's followed by whole planes", what);
  f.sensor = strdup(sensor);
  f.names = calloc((size_t)(f.channels > 0 ? f.channels : 1), sizeof *f.names);
  if (!s && (!f.sensor || !f.names)) s = ds_fail(d, RSW_ERR_NOMEM, "out of memory");
  /* The radiance and its planes in one allocation (the heap's or the
   * store's). */
  int n_planes = base > 0 ? (all - base) / base : 0;
  char why[200];
  float *pix = s ? NULL
                 : store_alloc(&d->store, (ns ? ns : 1) * sizeof(float) * (size_t)(1 + n_planes), &f.mapped,
                               why, sizeof why);
  if (!s && !pix) s = ds_fail(d, d->store.failed, "%s: %s", what, why);
  f.data = pix;
  for (int i = 0; !s && i < f.channels; i++)
    if (!(f.names[i] = strdup(in->names[i]))) s = ds_fail(d, RSW_ERR_NOMEM, "out of memory");
  const float *src = in->data;
  for (size_t px = 0; !s && px < np; px++)
    memcpy(f.data + px * (size_t)base, src + px * (size_t)all, (size_t)base * sizeof *f.data);
  for (int k = 0; !s && base > 0 && k < (all - base) / base; k++) {
    const char *first = in->names[base * (k + 1)];
    const char *dot = strchr(first, '.');
    size_t len = dot ? (size_t)(dot - first) : 0;
    for (int c = 0; !s && c < base; c++) {
      const char *nm = in->names[base * (k + 1) + c];
      if (!dot || strncmp(nm, first, len + 1) != 0 || strcmp(nm + len + 1, f.names[c]) != 0)
        s = ds_fail(d, RSW_ERR_INVALID, "%s: channel '%s' does not follow the plane layout", what, nm);
    }
    if (s) break;
    if (!(f.plane_names[k] = strndup(first, len))) {
      s = ds_fail(d, RSW_ERR_NOMEM, "out of memory");
      break;
    }
    f.plane_data[k] = pix + (ns ? ns : 1) * (size_t)(k + 1);
    f.n_planes = k + 1;
    for (size_t px = 0; px < np; px++)
      memcpy(f.plane_data[k] + px * (size_t)base, src + px * (size_t)all + (size_t)base * (size_t)(k + 1),
             (size_t)base * sizeof(float));
  }
  uint64_t spp = 0, rev;
  if (!s && cJSON_IsObject(meta)) {
    meta_u64(meta, "spp", &spp);
    meta_u64(meta, "seed", &f.seed);
    meta_u64(meta, "unresolved_rays", &f.unresolved);
    const char *pfm = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(meta, "plugin_failure"));
    if (meta_u64(meta, "plugin_failures", &f.plugin_failures) && f.plugin_failures && pfm &&
        !(f.plugin_failure = strdup(pfm)))
      s = ds_fail(d, RSW_ERR_NOMEM, "out of memory");
    f.spp = spp > 0xffffffffu ? 0xffffffffu : (uint32_t)spp;
    if (meta_u64(meta, "revision", &rev)) {
      if (d->has_revision && rev != d->revision)
        s = ds_fail(d, RSW_ERR_INVALID, "%s: revision %llu differs from the other films' %llu", what,
                    (unsigned long long)rev, (unsigned long long)d->revision);
      d->has_revision = true, d->revision = rev;
    }
    if (!s) s = same_string(d, meta, "scene", &d->scene, what);
    if (!s) s = same_string(d, meta, "variant", &d->variant, what);
    const cJSON *wl = cJSON_GetObjectItemCaseSensitive(meta, "wavelength");
    if (!s && cJSON_IsNumber(wl) && !isfinite(d->wl[ci])) d->wl[ci] = wl->valuedouble;
    const cJSON *ir = cJSON_GetObjectItemCaseSensitive(meta, "irradiance");
    /* E_h per channel, or a Stokes film's per colour (the writer takes the
     * first of each colour's). */
    stokes_layout sl;
    int n_ir = cJSON_GetArraySize(ir), n_col = f.channels;
    if (stokes_layout_of((const char *const *)f.names, f.channels, &sl)) n_col = sl.n_color;
    if (!s && cJSON_IsArray(ir) && (n_ir == f.channels || n_ir == n_col) && n_ir >= n_col && n_col <= 4) {
      int k = 0;
      const cJSON *x;
      f.has_irradiance = true;
      cJSON_ArrayForEach(x, ir) {
        if (k == n_col) break;
        f.irradiance[k++] = cJSON_IsNumber(x) ? x->valuedouble : NAN;
      }
    }
    const cJSON *sz = cJSON_GetObjectItemCaseSensitive(meta, "sun_zenith_deg");
    const cJSON *sa = cJSON_GetObjectItemCaseSensitive(meta, "sun_azimuth_deg");
    if (!s && cJSON_IsNumber(sz) && cJSON_IsNumber(sa))
      f.has_sun = true, f.sun_zenith = sz->valuedouble, f.sun_azimuth = sa->valuedouble;
    const cJSON *zen = cJSON_GetObjectItemCaseSensitive(meta, "zenith_deg");
    const cJSON *az = cJSON_GetObjectItemCaseSensitive(meta, "azimuth_deg");
    if (!s && !f.angles && (zen || az)) {
      if (!cJSON_IsArray(zen) || !cJSON_IsArray(az) || (size_t)cJSON_GetArraySize(zen) != np ||
          (size_t)cJSON_GetArraySize(az) != np)
        s = ds_fail(d, RSW_ERR_PARSE, "%s: zenith_deg and azimuth_deg must list one angle per pixel", what);
      else if (!(f.angles = angles_new(&d->store, np, why, sizeof why)))
        s = ds_fail(d, d->store.failed, "%s: %s", what, why);
      const cJSON *arr[2] = {zen, az};
      for (int k = 0; !s && k < 2; k++) {
        size_t i = 0;
        const cJSON *it;
        cJSON_ArrayForEach(it, arr[k]) {
          if (!cJSON_IsNumber(it)) {
            s = ds_fail(d, RSW_ERR_PARSE, "%s: an angle is not a number", what);
            break;
          }
          f.angles->v[2 * i++ + (size_t)k] = it->valuedouble;
        }
      }
    }
  }
  if (s) {
    film_clear(&f);
    return s;
  }
  d->films[d->nf++] = f;
  return RSW_OK;
}

rsw_status rsw_dataset_add_film(rsw_dataset *d, const char *context, const char *sensor,
                                const rsw_film *film) {
  if (!d) return RSW_ERR_INVALID;
  d->error[0] = '\0';
  if (!context || !sensor || !*sensor || !film)
    return ds_fail(d, RSW_ERR_INVALID, "a film needs its context, sensor and film");
  int nc = rsw_film_channels(film);
  const char **names = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *names);
  if (!names) return ds_fail(d, RSW_ERR_NOMEM, "out of memory");
  for (int i = 0; i < nc; i++) names[i] = rsw_film_channel_name(film, i);
  cJSON *meta = cJSON_Parse(rsw_film_meta(film));
  film_in in = {.width = rsw_film_width(film),
                .height = rsw_film_height(film),
                .channels = nc,
                .names = names,
                .data = rsw_film_data(film),
                .meta = meta};
  rsw_status s = add_film(d, context, sensor, &in);
  cJSON_Delete(meta);
  free(names);
  return s;
}

rsw_status rsw_dataset_add_film_file(rsw_dataset *d, const char *context, const char *sensor,
                                     const char *path) {
  if (!d) return RSW_ERR_INVALID;
  d->error[0] = '\0';
  if (!path) return ds_fail(d, RSW_ERR_INVALID, "no film path");
  FILE *fp = fopen(path, "rb");
  if (!fp) return ds_fail(d, RSW_ERR_IO, "cannot open '%s': %s", path, strerror(errno));
  char *text = NULL;
  size_t len = 0, cap = 0;
  rsw_status s = RSW_OK;
  for (;;) {
    if (len + 65536 + 1 > cap) {
      size_t nc = cap ? 2 * cap : 1 << 20;
      if (nc > CLIENT_MAX_BODY) {
        s = ds_fail(d, RSW_ERR_LIMIT, "'%s' is larger than a film may be", path);
        break;
      }
      char *nt = realloc(text, nc);
      if (!nt) {
        s = ds_fail(d, RSW_ERR_NOMEM, "out of memory");
        break;
      }
      text = nt, cap = nc;
    }
    size_t got = fread(text + len, 1, cap - len - 1, fp);
    len += got;
    if (got == 0) break;
  }
  if (!s && ferror(fp)) s = ds_fail(d, RSW_ERR_IO, "cannot read '%s'", path);
  fclose(fp);
  /* film_from_json reports through a client's last-error slot: a
   * client that never connects. */
  rsw_client *tmp = s ? NULL : calloc(1, sizeof *tmp);
  if (!s && !tmp) s = ds_fail(d, RSW_ERR_NOMEM, "out of memory");
  rsw_film *film = NULL;
  if (!s && (s = film_from_json(tmp, text, len, path, &film)))
    ds_fail(d, s, "%s", rsw_client_last_error(tmp)->message);
  free(text);
  free(tmp);
  if (!s) s = rsw_dataset_add_film(d, context, sensor, film);
  rsw_film_free(film);
  return s;
}

/* n "%.9g" angles joined by ',' into out[2 i + k]; false when text is not
 * exactly that. strtod, as cJSON reads the JSON meta's numbers. */
static bool parse_angles(const char *text, size_t n, int k, double *out) {
  const char *p = text;
  for (size_t i = 0; i < n; i++) {
    char *end;
    if (i && *p++ != ',') return false;
    out[2 * i + (size_t)k] = strtod(p, &end);
    if (end == p) return false;
    p = end;
  }
  return *p == '\0';
}

/* The pixel angles of an EXR film's lists (both present, or neither:
 * *out NULL): a reference for the caller. The lists of the film before
 * are kept with their values, so a sweep's films parse them once and
 * share one block of them. */
static rsw_status exr_angles(rsw_dataset *d, const char *zen, const char *az, size_t np, const char *what,
                             ds_angles **out) {
  *out = NULL;
  if (!zen && !az) return RSW_OK;
  if (!zen || !az)
    return ds_fail(d, RSW_ERR_PARSE, "%s: zenith_deg and azimuth_deg must list one angle per pixel", what);
  if (d->angle_vals && d->n_angles == np && strcmp(d->angle_text[0], zen) == 0 &&
      strcmp(d->angle_text[1], az) == 0) {
    *out = angles_ref(d->angle_vals);
    return RSW_OK;
  }
  char why[200];
  ds_angles *a = angles_new(&d->store, np, why, sizeof why);
  if (!a) return ds_fail(d, d->store.failed, "%s: %s", what, why);
  if (!parse_angles(zen, np, 0, a->v) || !parse_angles(az, np, 1, a->v)) {
    angles_unref(a);
    return ds_fail(d, RSW_ERR_PARSE, "%s: zenith_deg and azimuth_deg must list one angle per pixel", what);
  }
  char *t0 = strdup(zen), *t1 = strdup(az);
  if (t0 && t1) { /* else no cache: the next film parses its own */
    free(d->angle_text[0]), free(d->angle_text[1]), angles_unref(d->angle_vals);
    d->angle_text[0] = t0, d->angle_text[1] = t1, d->angle_vals = angles_ref(a), d->n_angles = np;
  } else {
    free(t0), free(t1);
  }
  *out = a;
  return RSW_OK;
}

/* An EXR film's "raysweep:" attribute key, as a number member of meta
 * (cJSON reads the JSON meta's numbers with strtod, as here). */
static void meta_number(cJSON *meta, const exr_image *img, const char *attr, const char *key) {
  const char *v = exr_image_meta(img, attr);
  char *end;
  double x = v ? strtod(v, &end) : 0;
  if (v && end != v && !*end) cJSON_AddNumberToObject(meta, key, x);
}

rsw_status rsw_dataset_add_film_exr(rsw_dataset *d, const char *context, const char *sensor,
                                    const void *bytes, size_t len, const char *const *channels,
                                    int n_channels) {
  if (!d) return RSW_ERR_INVALID;
  d->error[0] = '\0';
  if (!context || !sensor || !*sensor || !bytes)
    return ds_fail(d, RSW_ERR_INVALID, "a film needs its context, sensor and EXR bytes");
  char what[400];
  snprintf(what, sizeof what, "film %.64s/%.256s", context, sensor);
  exr_image img = {0};
  rsw_err err = {0};
  rsw_status s = exr_decode_image(bytes, len, what, &img, &err);
  if (s) {
    char buf[1100];
    return ds_fail(d, s == RSW_ERR_NOMEM ? s : RSW_ERR_PARSE, "%s", rsw_err_format(&err, buf, sizeof buf));
  }
  int nc = img.n_channels;
  size_t np = (size_t)img.width * (size_t)img.height, ns = np * (size_t)nc;
  const char *const *names = (const char *const *)img.channel_names;
  float *data = img.data;
  if (channels) { /* the film's order (the file's is alphabetical) */
    float *o = NULL;
    if (n_channels != nc)
      s = ds_fail(d, RSW_ERR_PARSE, "%s: the EXR has %d channels, not the %d of its result", what, nc,
                  n_channels);
    else if (!(o = malloc((ns ? ns : 1) * sizeof *o)))
      s = ds_fail(d, RSW_ERR_NOMEM, "out of memory");
    for (int c = 0; !s && c < nc; c++) {
      int from = exr_image_channel(&img, channels[c]);
      if (from < 0) {
        s = ds_fail(d, RSW_ERR_PARSE, "%s: the EXR has no channel '%s'", what,
                    channels[c] ? channels[c] : "?");
        break;
      }
      for (size_t px = 0; px < np; px++)
        o[px * (size_t)nc + (size_t)c] = img.data[px * (size_t)nc + (size_t)from];
    }
    if (s) {
      free(o);
      exr_image_free(&img);
      return s;
    }
    data = o, names = channels;
  }
  /* The JSON film writes non-finite samples as null, which reads as NaN:
   * the same here, so both give one dataset. */
  for (size_t i = 0; i < ns; i++)
    if (!isfinite(data[i])) data[i] = NAN;
  /* The meta members add_film reads, from their attributes (film_io.h). */
  cJSON *meta = cJSON_CreateObject();
  ds_angles *angles = NULL;
  if (!meta) s = ds_fail(d, RSW_ERR_NOMEM, "out of memory");
  static const char *const strs[][2] = {{"raysweep:scene", "scene"},
                                        {"raysweep:variant", "variant"},
                                        {"raysweep:plugin_failure", "plugin_failure"}};
  static const char *const nums[][2] = {{"raysweep:revision", "revision"},
                                        {"raysweep:spp", "spp"},
                                        {"raysweep:seed", "seed"},
                                        {"raysweep:unresolved_rays", "unresolved_rays"},
                                        {"raysweep:plugin_failures", "plugin_failures"},
                                        {"raysweep:wavelength_nm", "wavelength"},
                                        {"raysweep:sun_zenith_deg", "sun_zenith_deg"},
                                        {"raysweep:sun_azimuth_deg", "sun_azimuth_deg"}};
  for (size_t i = 0; !s && i < sizeof strs / sizeof strs[0]; i++) {
    const char *v = exr_image_meta(&img, strs[i][0]);
    if (v) cJSON_AddStringToObject(meta, strs[i][1], v);
  }
  for (size_t i = 0; !s && i < sizeof nums / sizeof nums[0]; i++)
    meta_number(meta, &img, nums[i][0], nums[i][1]);
  const char *ir = s ? NULL : exr_image_meta(&img, "raysweep:irradiance");
  if (ir) {
    cJSON *arr = cJSON_AddArrayToObject(meta, "irradiance");
    for (const char *p = ir; arr && *p;) {
      char *end;
      double x = strtod(p, &end);
      if (end == p) break;
      cJSON_AddItemToArray(arr, cJSON_CreateNumber(x));
      p = *end == ',' ? end + 1 : end;
    }
  }
  if (!s)
    s = exr_angles(d, exr_image_meta(&img, "raysweep:zenith_deg"),
                   exr_image_meta(&img, "raysweep:azimuth_deg"), np, what, &angles);
  if (!s) {
    film_in in = {.width = img.width,
                  .height = img.height,
                  .channels = nc,
                  .names = names,
                  .data = data,
                  .meta = meta,
                  .angles = angles};
    s = add_film(d, context, sensor, &in); /* takes angles over */
  }
  cJSON_Delete(meta);
  if (data != img.data) free(data);
  exr_image_free(&img);
  return s;
}

rsw_status rsw_dataset_write(rsw_dataset *d, const char *path) {
  if (!d) return RSW_ERR_INVALID;
  d->error[0] = '\0';
  if (!path || !*path) return ds_fail(d, RSW_ERR_INVALID, "no output path");
  rsw_err err = {0};
  nc_coords coords = {0};
  rsw_status s = nc_coords_build((const void *const *)d->coords, d->n, "/contexts", &coords, &err);
  nc_film *films = s ? NULL : calloc(d->nf ? d->nf : 1, sizeof *films);
  if (!s && !films) s = rsw_fail(&err, RSW_ERR_NOMEM, "", "out of memory");
  for (size_t i = 0; !s && i < d->nf; i++) {
    ds_film *f = &d->films[i];
    f->vars[0] = (nc_var){"radiance", f->data};
    for (int k = 0; k < f->n_planes; k++) f->vars[1 + k] = (nc_var){f->plane_names[k], f->plane_data[k]};
    films[i] =
        (nc_film){.context = f->context,
                  .sensor = f->sensor,
                  .width = f->width,
                  .height = f->height,
                  .channels = f->channels,
                  .channel_names = (const char *const *)f->names,
                  .spp = f->spp,
                  .seed = f->seed,
                  .unresolved_rays = f->unresolved,
                  .angles = f->angles ? f->angles->v : NULL,
                  .vars = f->vars,
                  .n_vars = 1 + (size_t)f->n_planes,
                  .has_irradiance = f->has_irradiance,
                  .irradiance = {f->irradiance[0], f->irradiance[1], f->irradiance[2], f->irradiance[3]},
                  .has_sun = f->has_sun,
                  .sun_zenith = f->sun_zenith,
                  .sun_azimuth = f->sun_azimuth,
                  .plugin_failures = f->plugin_failures,
                  .plugin_failure = f->plugin_failure};
  }
  if (!s) {
    nc_dataset ds = {.size = sizeof ds,
                     .scene = d->scene,
                     .variant = d->variant,
                     .has_revision = d->has_revision,
                     .revision = d->revision,
                     .has_seed = d->has_seed,
                     .seed = d->seed,
                     .n_contexts = d->n,
                     .context_ids = (const char *const *)d->ids,
                     .wavelengths = d->wl,
                     .coords = &coords,
                     .films = films,
                     .n_films = d->nf};
    s = nc_dataset_write(path, &ds, &err);
  }
  if (s) {
    char buf[1100];
    ds_fail(d, s, "%s", rsw_err_format(&err, buf, sizeof buf));
  }
  free(films);
  nc_coords_free(&coords);
  return s;
}
