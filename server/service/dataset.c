/* GET /v1/jobs/{id}/dataset: a job's films as one NetCDF-4 dataset
 * (common/dataset_nc.h has the layout).
 *
 * What the dataset needs is taken under svc->lock: the job's records
 * copied, its films held (film_image_share: one more reference to their
 * pixels and angles, since the job may be deleted while the file is
 * encoded); films kept on disk only are read after it is released, and
 * the encoding runs without it. */
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "service_internal.h"

/* The quantities of a film, as the dataset's variables: radiance always.
 * A film that carries another quantity (dataset_nc.c's table) hands it
 * over here, one line each. */
#define MAX_FILM_VARS (1 + FILM_MAX_PLANES)
static size_t film_vars(const film_image *im, nc_var *out) {
  size_t n = 0;
  out[n++] = (nc_var){"radiance", im->data};
  /* brdf, brf, radiance_stderr (render.h film_plane): their names are the
   * dataset's quantity names (common/dataset_nc.c). */
  for (int k = 0; k < im->n_planes && n < MAX_FILM_VARS; k++)
    if (im->planes[k].data) out[n++] = (nc_var){im->planes[k].name, im->planes[k].data};
  return n;
}

/* A band film's quantities: the node films' names with "_srf" (Eradiate's
 * names for SRF-weighted variables). */
static size_t band_vars(const film_image *im, nc_var *out) {
  static const char *const from[] = {"brdf", "brf", "radiance_stderr"};
  static const char *const to[] = {"brdf_srf", "brf_srf", "radiance_srf_stderr"};
  size_t n = 0;
  out[n++] = (nc_var){"radiance_srf", im->data};
  for (int k = 0; k < im->n_planes && n < MAX_FILM_VARS; k++)
    for (int q = 0; q < 3; q++)
      if (im->planes[k].data && strcmp(im->planes[k].name, from[q]) == 0)
        out[n++] = (nc_var){to[q], im->planes[k].data};
  return n;
}

/* The labels of a film the writer takes besides its quantities (the
 * plugin failures of a band film are its nodes', which the writer keeps
 * with the node films). */
static void film_labels(const film_image *im, nc_film *f) {
  f->plugin_failures = im->plugin_failures;
  f->plugin_failure = im->plugin_failure;
  f->has_irradiance = im->has_irradiance;
  memcpy(f->irradiance, im->irradiance, sizeof f->irradiance);
  f->has_sun = im->has_sun;
  f->sun_zenith = im->sun_zenith, f->sun_azimuth = im->sun_azimuth;
}

typedef struct ds_item {
  size_t context;
  char sensor[256];
  size_t index; /* render item */
  size_t node;  /* render_item.node */
  bool present, from_disk;
  svc_film_ref ref; /* from_disk: the film's place and identity */
  svc_film film;
  nc_var vars[MAX_FILM_VARS];
} ds_item;

void svc_job_restore_labels(job *j, const char *body, size_t len) {
  cJSON *req = cJSON_ParseWithLength(body, len);
  const cJSON *seed = cJSON_GetObjectItemCaseSensitive(req, "seed");
  if (cJSON_IsNumber(seed) && seed->valuedouble >= 0 && seed->valuedouble < 18446744073709551616.0)
    j->seed = (uint64_t)seed->valuedouble;
  const cJSON *bands = cJSON_GetObjectItemCaseSensitive(req, "bands");
  svc_error be = {0};
  if (bands && !j->bands && bands_parse(bands, "/bands", &j->bands, &be) != RSW_OK) j->bands = NULL;
  const cJSON *contexts = cJSON_GetObjectItemCaseSensitive(req, "contexts");
  size_t n = (size_t)cJSON_GetArraySize(contexts);
  const void **cj = n ? malloc(n * sizeof *cj) : NULL;
  size_t i = 0;
  for (const cJSON *c = cj ? contexts->child : NULL; c && i < n; c = c->next, i++)
    cj[i] = cJSON_GetObjectItemCaseSensitive(c, "coords");
  rsw_err err = {0};
  if (cj && i == n) {
    nc_coords_free(&j->coords);
    if (nc_coords_build(cj, n, "/contexts", &j->coords, &err) != RSW_OK)
      memset(&j->coords, 0, sizeof j->coords);
  }
  free(cj);
  cJSON_Delete(req);
}

static const char *const state_names[] = {"queued", "running", "succeeded", "failed", "cancelled"};

/* The job's warnings as the dataset's attribute: "code (coordinate):
 * detail", one a line (NULL: none, or out of memory). */
static char *warnings_text(const cJSON *w) {
  size_t n = 0;
  for (const cJSON *x = w ? w->child : NULL; x; x = x->next) {
    const cJSON *f[3] = {cJSON_GetObjectItemCaseSensitive(x, "code"),
                         cJSON_GetObjectItemCaseSensitive(x, "coordinate"),
                         cJSON_GetObjectItemCaseSensitive(x, "detail")};
    for (int k = 0; k < 3; k++) n += cJSON_IsString(f[k]) ? strlen(f[k]->valuestring) + 4 : 0;
  }
  char *s = n ? malloc(n + 1) : NULL;
  if (!s) return NULL;
  size_t at = 0;
  for (const cJSON *x = w->child; x; x = x->next) {
    const cJSON *c = cJSON_GetObjectItemCaseSensitive(x, "code"),
                *k = cJSON_GetObjectItemCaseSensitive(x, "coordinate"),
                *d = cJSON_GetObjectItemCaseSensitive(x, "detail");
    at += (size_t)snprintf(s + at, n + 1 - at, "%s%s (%s): %s", at ? "\n" : "",
                           cJSON_IsString(c) ? c->valuestring : "", cJSON_IsString(k) ? k->valuestring : "",
                           cJSON_IsString(d) ? d->valuestring : "");
  }
  return s;
}

/* The dataset written to a file in the blob directory, unlinked once open:
 * its descriptor (read from the start) and length, or -1 where the
 * directory took no file (then encoded in memory after all). */
static int dataset_file(const service *svc, const nc_dataset *ds, uint64_t *len_out, rsw_err *err) {
  /* A name no other request or replica (a blob directory may be shared)
   * has: the writer's temporary file is named after it too. */
  char path[4200];
  snprintf(path, sizeof path, "%s/.dataset.XXXXXX", svc->blob_dir);
  int made = mkostemp(path, O_CLOEXEC);
  if (made < 0) return -1;
  close(made);
  rsw_err werr = {0};
  rsw_status st = nc_dataset_write(path, ds, &werr);
  if (st != RSW_OK) {
    unlink(path);
    if (st != RSW_ERR_IO) *err = werr; /* (a bad dataset: the same error in memory) */
    return st == RSW_ERR_IO ? -1 : -2;
  }
  int fd = open(path, O_RDONLY | O_CLOEXEC);
  unlink(path);
  struct stat sb;
  if (fd >= 0 && fstat(fd, &sb) != 0) {
    close(fd);
    fd = -1;
  }
  if (fd >= 0) *len_out = (uint64_t)sb.st_size;
  return fd;
}

static rsw_status job_dataset(service *svc, const char *id, bool partial, int *fd_out, uint64_t *fd_len,
                              void **bytes_out, size_t *len_out, svc_error *e) {
  pthread_mutex_lock(&svc->lock);
  job *j = svc_find_job_locked(svc, id);
  if (!j) {
    pthread_mutex_unlock(&svc->lock);
    return svc_fail(e, RSW_ERR_NOT_FOUND, id, "no job '%s' (unknown, deleted or expired)", id);
  }
  if ((j->state == JOB_QUEUED || j->state == JOB_RUNNING) && !partial) {
    job_state s = j->state;
    pthread_mutex_unlock(&svc->lock);
    return svc_fail(e, RSW_ERR_CONFLICT, id,
                    "job %s is %s: its dataset is served once it has finished (or ask for ?partial=1)", id,
                    state_names[s]);
  }
  size_t n_ctx = j->n_contexts, n_items = j->n_items;
  char jid[40], scene_id[65];
  snprintf(jid, sizeof jid, "%s", j->id);
  memcpy(scene_id, j->scene_id, sizeof scene_id);
  uint64_t revision = j->revision, seed = j->seed;
  char *warnings = warnings_text(j->warnings);
  rsw_variant variant = j->variant;
  bool polarized = false; /* the films': a job's record keeps the variant only */
  rsw_status st = RSW_OK;
  /* A job with bands: its bands (copied: the job may go) and node
   * wavelengths. */
  band_plan bp = {0};
  const char **band_ids = NULL;
  if (j->bands) {
    bp.n = j->bands->n, bp.n_wl = j->bands->n_wl;
    bp.b = malloc(bp.n * sizeof *bp.b);
    bp.wl = malloc(bp.n_wl * sizeof *bp.wl);
    band_ids = malloc(bp.n * sizeof *band_ids);
    if (!bp.b || !bp.wl || !band_ids) {
      st = svc_fail(e, RSW_ERR_NOMEM, id, "out of memory");
    } else {
      memcpy(bp.b, j->bands->b, bp.n * sizeof *bp.b);
      memcpy(bp.wl, j->bands->wl, bp.n_wl * sizeof *bp.wl);
      for (size_t b = 0; b < bp.n; b++) band_ids[b] = bp.b[b].id;
    }
  }
  rsw_err err = {0};
  nc_coords coords = {0};
  char(*ids)[72] = calloc(n_ctx ? n_ctx : 1, sizeof *ids);
  const char **id_ptr = calloc(n_ctx ? n_ctx : 1, sizeof *id_ptr);
  double *wl = malloc((n_ctx ? n_ctx : 1) * sizeof *wl);
  ds_item *it = calloc(n_items ? n_items : 1, sizeof *it);
  if (!ids || !id_ptr || !wl || !it) st = svc_fail(e, RSW_ERR_NOMEM, id, "out of memory");
  if (!st && nc_coords_copy(&j->coords, &coords, &err) != RSW_OK)
    st = svc_fail(e, err.code, id, "%s", err.msg);
  for (size_t c = 0; !st && c < n_ctx; c++) wl[c] = NAN;
  /* A job's films have their sensor's pixel angles, the same in every
   * context as a rule (16 bytes a pixel: more than a mono film's
   * radiance), one block that the job's films share (item_done) and the
   * copies here too; films read from disk share the one before theirs
   * where it is equal. */
  double *last_angles = NULL;
  size_t last_np = 0;
  for (size_t i = 0; !st && i < n_items; i++) {
    const render_item *ri = &j->items[i];
    ds_item *d = &it[i];
    d->context = ri->context_index;
    d->index = i;
    d->node = ri->node;
    snprintf(d->sensor, sizeof d->sensor, "%s", ri->sensor);
    snprintf(ids[ri->context_index], sizeof ids[0], "%s", ri->context);
    if (ri->wavelength > 0 && !ri->node) wl[ri->context_index] = ri->wavelength;
    if (ri->state != JOB_SUCCEEDED) continue;
    if (ri->has_film) {
      /* The film held, not copied (film_image_share): the job's lock is
       * the service's, so the pixels stay where they are. */
      d->film = ri->film;
      film_image_share(&ri->film.img, &d->film.img);
      size_t np = (size_t)ri->film.img.width * (size_t)ri->film.img.height;
      if (d->film.img.angles) last_angles = d->film.img.angles, last_np = np; /* (ours: held till the end) */
      d->present = true;
    } else if (ri->on_disk) {
      d->from_disk = true;
      svc_film_ref_set(&d->ref, j, i);
    }
  }
  pthread_mutex_unlock(&svc->lock);
  /* Films beyond the memory cap, or restored: from the state directory. */
  for (size_t i = 0; !st && i < n_items; i++) {
    if (!it[i].from_disk) continue;
    st = svc_state_film_read(svc, &it[i].ref, &it[i].film, e);
    it[i].present = !st;
    film_image *im = &it[i].film.img;
    size_t np = (size_t)im->width * (size_t)im->height;
    if (!st && im->angles && last_angles && last_np == np &&
        memcmp(last_angles, im->angles, np * 2 * sizeof(double)) == 0) {
      film_angles_unref(im->angles);
      im->angles = film_angles_ref(last_angles);
    } else if (!st && im->angles) {
      last_angles = im->angles, last_np = np;
    }
  }
  nc_film *films = NULL;
  size_t n_films = 0;
  if (!st && !(films = calloc(n_items ? n_items : 1, sizeof *films)))
    st = svc_fail(e, RSW_ERR_NOMEM, id, "out of memory");
  for (size_t i = 0; !st && i < n_items; i++) {
    ds_item *d = &it[i];
    if (!d->present) continue;
    const film_image *im = &d->film.img;
    if (!isfinite(wl[d->context]) && im->wavelength > 0 && !d->node) wl[d->context] = im->wavelength;
    if (n_films == 0) variant = im->variant, polarized = im->polarized; /* a restored job's record has none */
    size_t nv = film_vars(im, d->vars);
    films[n_films++] = (nc_film){.context = d->context,
                                 .sensor = d->sensor,
                                 .width = im->width,
                                 .height = im->height,
                                 .channels = im->channels,
                                 .channel_names = im->channel_names,
                                 .spp = im->spp,
                                 .seed = im->seed,
                                 .unresolved_rays = im->unresolved_rays,
                                 .angles = im->angles,
                                 .vars = d->vars,
                                 .n_vars = nv,
                                 .node = d->node};
    film_labels(im, &films[n_films - 1]);
  }
  /* Band films: per (context, sensor) whose node films are all there,
   * one per band (items are context-major, then node, then sensor). */
  film_image *bimg = NULL;
  nc_var(*bvars)[MAX_FILM_VARS] = NULL;
  size_t n_bimg = 0;
  if (!st && bp.n) {
    nc_film *grown = realloc(films, (n_items + n_items * bp.n + 1) * sizeof *films);
    bimg = calloc(n_items * bp.n + 1, sizeof *bimg);
    bvars = calloc(n_items * bp.n + 1, sizeof *bvars);
    if (grown) films = grown;
    if (!grown || !bimg || !bvars) st = svc_fail(e, RSW_ERR_NOMEM, id, "out of memory");
  }
  for (size_t i = 0; !st && bp.n && i < n_items; i++) {
    if (it[i].node != 1) continue;
    size_t ns = 0; /* sensors of this context */
    while (i + ns < n_items && it[i + ns].node == 1 && it[i + ns].context == it[i].context) ns++;
    for (size_t s = 0; s < ns && !st; s++) {
      for (size_t b = 0; b < bp.n && !st; b++) {
        const band *bd = &bp.b[b];
        const film_image *imgs[BAND_MAX_NODES];
        bool all = true;
        for (size_t k = 0; k < bd->n_nodes && all; k++) {
          size_t ix = i + s + bd->slot[k] * ns;
          all = ix < n_items && it[ix].present;
          if (all) imgs[k] = &it[ix].film.img;
        }
        if (!all) continue;
        film_image *bi = &bimg[n_bimg];
        if (bands_combine(bd, imgs, bi, &err) != RSW_OK) {
          st = svc_fail(e, err.code, id, "%s", err.msg);
          break;
        }
        size_t nv = band_vars(bi, bvars[n_bimg]);
        films[n_films] = (nc_film){.context = it[i + s].context,
                                   .sensor = it[i + s].sensor,
                                   .width = bi->width,
                                   .height = bi->height,
                                   .channels = bi->channels,
                                   .channel_names = bi->channel_names,
                                   .spp = bi->spp,
                                   .seed = bi->seed,
                                   .angles = bi->angles, /* the nodes' */
                                   .vars = bvars[n_bimg],
                                   .n_vars = nv,
                                   .band = b + 1};
        film_labels(bi, &films[n_films]);
        n_films++, n_bimg++;
      }
    }
    i += ns - 1;
  }
  for (size_t c = 0; !st && c < n_ctx; c++) id_ptr[c] = ids[c];
  if (!st) {
    nc_dataset ds = {.size = sizeof ds,
                     .scene = scene_id,
                     .variant = variant_name(variant, polarized),
                     .job = jid,
                     .has_revision = true,
                     .revision = revision,
                     .has_seed = true,
                     .seed = seed,
                     .n_contexts = n_ctx,
                     .context_ids = id_ptr,
                     .wavelengths = wl,
                     .coords = &coords,
                     .films = films,
                     .n_films = n_films,
                     .warnings = warnings,
                     .n_nodes = bp.n_wl,
                     .nodes = bp.wl,
                     .n_bands = bp.n,
                     .band_ids = band_ids};
    /* To a file when asked (the answer streams from it: no copy of the
     * whole file in memory beside the films), else, or where no file can
     * be made, in memory. */
    int fd = fd_out ? dataset_file(svc, &ds, fd_len, &err) : -1;
    if (fd == -2)
      st = svc_fail(e, err.code, err.where, "%s", err.msg);
    else if (fd >= 0)
      *fd_out = fd;
    else if (nc_dataset_encode(&ds, bytes_out, len_out, &err) != RSW_OK)
      st = svc_fail(e, err.code, err.where, "%s", err.msg);
  }
  for (size_t i = 0; it && i < n_items; i++) svc_film_free(&it[i].film);
  for (size_t i = 0; i < n_bimg; i++) film_image_free(&bimg[i]);
  free(bimg);
  free(bvars);
  free(bp.b);
  free(bp.wl);
  free(band_ids);
  free(films);
  free(it);
  free(ids);
  free(id_ptr);
  free(wl);
  free(warnings);
  nc_coords_free(&coords);
  return st;
}

rsw_status service_job_dataset(service *svc, const char *id, bool partial, void **bytes_out, size_t *len_out,
                               svc_error *e) {
  return job_dataset(svc, id, partial, NULL, NULL, bytes_out, len_out, e);
}

rsw_status service_job_dataset_file(service *svc, const char *id, bool partial, int *fd_out, uint64_t *fd_len,
                                    void **bytes_out, size_t *len_out, svc_error *e) {
  *fd_out = -1;
  *bytes_out = NULL;
  return job_dataset(svc, id, partial, fd_out, fd_len, bytes_out, len_out, e);
}
