/* GET /v1/jobs/{id}/dataset: a job's films as one NetCDF-4 dataset
 * (common/dataset_nc.h has the layout).
 *
 * What the dataset needs is copied out under svc->lock (the job may be
 * deleted while the file is encoded), films kept on disk only are read
 * after it is released, and the encoding runs without it. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

typedef struct ds_item {
  size_t context;
  char sensor[256];
  size_t index; /* render item */
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

rsw_status service_job_dataset(service *svc, const char *id, bool partial, void **bytes_out, size_t *len_out,
                               svc_error *e) {
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
  rsw_variant variant = j->variant;
  rsw_status st = RSW_OK;
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
  for (size_t i = 0; !st && i < n_items; i++) {
    const render_item *ri = &j->items[i];
    ds_item *d = &it[i];
    d->context = ri->context_index;
    d->index = i;
    snprintf(d->sensor, sizeof d->sensor, "%s", ri->sensor);
    snprintf(ids[ri->context_index], sizeof ids[0], "%s", ri->context);
    if (ri->wavelength > 0) wl[ri->context_index] = ri->wavelength;
    if (ri->state != JOB_SUCCEEDED) continue;
    if (ri->has_film) {
      const film_image *src = &ri->film.img;
      d->film = ri->film;
      d->film.img.data = NULL;
      d->film.img.angles = NULL;
      size_t np = (size_t)src->width * (size_t)src->height;
      size_t plane_bytes = np * (size_t)src->channels * sizeof(float);
      bool planes_ok = true;
      for (int k = 0; k < src->n_planes; k++) {
        d->film.img.planes[k].data = src->planes[k].data ? malloc(plane_bytes) : NULL;
        if (src->planes[k].data && !d->film.img.planes[k].data)
          planes_ok = false;
        else if (src->planes[k].data)
          memcpy(d->film.img.planes[k].data, src->planes[k].data, plane_bytes);
      }
      d->film.img.data = malloc(plane_bytes);
      if (src->angles) d->film.img.angles = malloc(np * 2 * sizeof(double));
      if (!planes_ok || !d->film.img.data || (src->angles && !d->film.img.angles)) {
        svc_film_free(&d->film);
        st = svc_fail(e, RSW_ERR_NOMEM, id, "out of memory for the dataset");
        break;
      }
      memcpy(d->film.img.data, src->data, np * (size_t)src->channels * sizeof(float));
      if (src->angles) memcpy(d->film.img.angles, src->angles, np * 2 * sizeof(double));
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
  }
  nc_film *films = NULL;
  size_t n_films = 0;
  if (!st && !(films = calloc(n_items ? n_items : 1, sizeof *films)))
    st = svc_fail(e, RSW_ERR_NOMEM, id, "out of memory");
  for (size_t i = 0; !st && i < n_items; i++) {
    ds_item *d = &it[i];
    if (!d->present) continue;
    const film_image *im = &d->film.img;
    if (!isfinite(wl[d->context]) && im->wavelength > 0) wl[d->context] = im->wavelength;
    if (n_films == 0) variant = im->variant; /* a restored job's record has none */
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
                                 .n_vars = nv};
  }
  for (size_t c = 0; !st && c < n_ctx; c++) id_ptr[c] = ids[c];
  if (!st) {
    nc_dataset ds = {.size = sizeof ds,
                     .scene = scene_id,
                     .variant = variant == VARIANT_MONO ? "mono" : "rgb",
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
                     .n_films = n_films};
    if (nc_dataset_encode(&ds, bytes_out, len_out, &err) != RSW_OK)
      st = svc_fail(e, err.code, err.where, "%s", err.msg);
  }
  for (size_t i = 0; it && i < n_items; i++) svc_film_free(&it[i].film);
  free(films);
  free(it);
  free(ids);
  free(id_ptr);
  free(wl);
  nc_coords_free(&coords);
  return st;
}
