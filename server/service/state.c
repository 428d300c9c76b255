/* Durable state (`raysweepd serve --state-dir DIR`): what a restart after a
 * crash, SIGKILL or upgrade needs, on disk.
 *
 *   DIR/lock                   flock'ed while a daemon uses DIR
 *   DIR/blobs/<sha256>         blobs (unless --blob-dir names another place)
 *   DIR/scenes/<id>.scene      one JSON header line {"format", "variant"},
 *                              then the posted scene text as it came
 *   DIR/scenes/<id>.params     {"revision": N, "params": {key: value}}: the
 *                              last value of every key PATCHed
 *   DIR/jobs/<id>.req          one JSON header line {"id", "scene",
 *                              "revision", "created", "idem_key"}, then the
 *                              job request body as it came
 *   DIR/jobs/<id>.done         the outcome of a finished job (state, error,
 *                              times, one entry per render)
 *   DIR/results/<id>/<k>.film  render k's film: first exactly the bytes of
 *                              GET .../results/{context}/{sensor} as .npy
 *                              (streamed from the file), then its angles,
 *                              metadata and a trailer (svc_state_film_write)
 *
 * Every file is written to a temporary name, fsync'ed, renamed over its
 * name and the directory fsync'ed, so a file is either whole or absent
 * (films: the directory once per job, see svc_state_film_write). A film
 * file with a whole trailer means the render is done.
 *
 * A restart restores every job: a finished one from its .done (its films
 * stay on disk and are read when fetched); one without .done was queued or
 * running and is submitted again from its .req under its old id, its
 * renders whose .npy exists counted done (films are deterministic, so the
 * resumed job gives the films the uninterrupted one would have), or, when
 * that is impossible (the scene is gone or its base revision changed), ends
 * failed with the reason. Scenes reload lazily, on first use by id (a
 * state directory may hold more scenes than --max-scene-bytes allows, and
 * a restart should not wait for all of them), except those a resumed job
 * needs. */
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <inttypes.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include "buf.h"
#include "rsw_sha256.h"
#include "service_internal.h"

bool svc_state_on(const service *svc) {
  return svc && svc->state_dir[0];
}

static void warn(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
static void warn(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, "raysweepd: state: ");
  vfprintf(stderr, fmt, ap);
  fputc('\n', stderr);
  va_end(ap);
}

static bool write_all(int fd, const void *p, size_t n) {
  const char *c = p;
  while (n) {
    ssize_t w = write(fd, c, n);
    if (w < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    c += w, n -= (size_t)w;
  }
  return true;
}

static bool fsync_dir(const char *path) {
  char dir[4200];
  snprintf(dir, sizeof dir, "%s", path);
  char *slash = strrchr(dir, '/');
  if (slash) *slash = '\0';
  int fd = open(slash ? dir : ".", O_RDONLY | O_DIRECTORY);
  if (fd < 0) return false;
  bool ok = fsync(fd) == 0;
  close(fd);
  return ok;
}

/* path <- head then body, atomically (temporary file, fsync, rename,
 * fsync of the directory). false with errno set on failure. */
static bool write_atomic(const char *path, const void *head, size_t nh, const void *body, size_t nb) {
  char tmp[4300];
  snprintf(tmp, sizeof tmp, "%s.tmp.%ld.%lx", path, (long)getpid(), (unsigned long)pthread_self());
  int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) return false;
  bool ok = write_all(fd, head, nh) && write_all(fd, body, nb) && fsync(fd) == 0;
  int saved = errno;
  ok = close(fd) == 0 && ok;
  if (ok && rename(tmp, path) == 0 && fsync_dir(path)) return true;
  saved = errno ? errno : saved;
  unlink(tmp);
  errno = saved;
  return false;
}

static char *read_whole(const char *path, size_t *len) {
  int fd = open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return NULL;
  struct stat sb;
  if (fstat(fd, &sb) != 0 || sb.st_size < 0) {
    close(fd);
    return NULL;
  }
  size_t n = (size_t)sb.st_size;
  char *p = malloc(n + 1);
  size_t got = 0;
  while (p && got < n) {
    ssize_t r = read(fd, p + got, n - got);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) break;
    got += (size_t)r;
  }
  close(fd);
  if (!p || got != n) {
    free(p);
    return NULL;
  }
  p[n] = '\0';
  if (len) *len = n;
  return p;
}

static void state_path(const service *svc, char *out, size_t n, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static void state_path(const service *svc, char *out, size_t n, const char *fmt, ...) {
  int k = snprintf(out, n, "%s/", svc->state_dir);
  va_list ap;
  va_start(ap, fmt);
  if (k > 0 && (size_t)k < n) vsnprintf(out + k, n - (size_t)k, fmt, ap);
  va_end(ap);
}

rsw_status svc_state_open(service *svc, rsw_err *err) {
  if (!svc_state_on(svc)) return RSW_OK;
  static const char *const sub[] = {"", "scenes", "jobs", "results"};
  for (size_t i = 0; i < sizeof sub / sizeof sub[0]; i++) {
    char p[4200];
    state_path(svc, p, sizeof p, "%s", sub[i]);
    if (mkdir(p, 0700) != 0 && errno != EEXIST)
      return rsw_fail(err, RSW_ERR_IO, "--state-dir", "cannot create '%s': %s", p, strerror(errno));
  }
  char p[4200];
  state_path(svc, p, sizeof p, "lock");
  svc->state_lock_fd = open(p, O_RDWR | O_CREAT | O_CLOEXEC, 0600);
  if (svc->state_lock_fd < 0)
    return rsw_fail(err, RSW_ERR_IO, "--state-dir", "cannot open '%s': %s", p, strerror(errno));
  if (flock(svc->state_lock_fd, LOCK_EX | LOCK_NB) != 0)
    return rsw_fail(err, RSW_ERR_IO, "--state-dir",
                    "state directory '%s' is in use by another raysweepd (%s is locked)", svc->state_dir, p);
  return RSW_OK;
}

/* ---- scenes ------------------------------------------------------------------ */

rsw_status svc_state_scene_save(service *svc, const char *id, bool is_xml, const char *variant,
                                const char *body, size_t len, svc_error *e) {
  if (!svc_state_on(svc)) return RSW_OK;
  char p[4200];
  state_path(svc, p, sizeof p, "scenes/%s.scene", id);
  struct stat sb;
  if (stat(p, &sb) == 0) return RSW_OK;
  char head[128];
  int nh = snprintf(head, sizeof head, "{\"format\":\"%s\",\"variant\":%s%s%s}\n", is_xml ? "xml" : "json",
                    variant ? "\"" : "", variant ? variant : "null", variant ? "\"" : "");
  if (!write_atomic(p, head, (size_t)nh, body, len))
    return svc_fail(e, RSW_ERR_IO, "--state-dir", "cannot store the scene document: %s", strerror(errno));
  return RSW_OK;
}

bool svc_state_scene_read(service *svc, const char *id, char **body, size_t *len, bool *is_xml,
                          char variant[8], cJSON **patched, uint64_t *revision) {
  if (!svc_state_on(svc) || !rsw_is_sha256_hex(id)) return false;
  char p[4200];
  state_path(svc, p, sizeof p, "scenes/%s.scene", id);
  size_t n;
  char *text = read_whole(p, &n);
  if (!text) return false;
  char *nl = memchr(text, '\n', n);
  cJSON *h = nl ? cJSON_ParseWithLength(text, (size_t)(nl - text)) : NULL;
  const cJSON *f = cJSON_GetObjectItemCaseSensitive(h, "format");
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(h, "variant");
  if (!cJSON_IsString(f)) {
    warn("%s: no header line; ignored", p);
    cJSON_Delete(h);
    free(text);
    return false;
  }
  *is_xml = strcmp(f->valuestring, "xml") == 0;
  variant[0] = '\0';
  if (cJSON_IsString(v)) snprintf(variant, 8, "%s", v->valuestring);
  cJSON_Delete(h);
  size_t off = (size_t)(nl + 1 - text);
  memmove(text, text + off, n - off + 1);
  *body = text;
  *len = n - off;
  *patched = NULL;
  *revision = 0;
  state_path(svc, p, sizeof p, "scenes/%s.params", id);
  char *pt = read_whole(p, NULL);
  if (pt) {
    cJSON *j = cJSON_Parse(pt);
    const cJSON *rev = cJSON_GetObjectItemCaseSensitive(j, "revision");
    cJSON *prm = cJSON_DetachItemFromObjectCaseSensitive(j, "params");
    if (cJSON_IsNumber(rev) && cJSON_IsObject(prm)) {
      *revision = (uint64_t)rev->valuedouble;
      *patched = prm;
    } else {
      warn("%s: unreadable; the scene reloads at its posted state", p);
      cJSON_Delete(prm);
    }
    cJSON_Delete(j);
    free(pt);
  }
  return true;
}

void svc_state_scene_patched(service *svc, resident *r) {
  if (!svc_state_on(svc) || r->pinned || !r->patches) return;
  cJSON *o = cJSON_CreateObject();
  cJSON_AddNumberToObject(o, "revision", (double)r->revision);
  cJSON_AddItemReferenceToObject(o, "params", r->patches);
  char *s = cJSON_PrintUnformatted(o);
  cJSON_Delete(o);
  char p[4200];
  state_path(svc, p, sizeof p, "scenes/%s.params", r->id);
  if (!s || !write_atomic(p, s, strlen(s), "", 0))
    warn("cannot store scene %s's parameters (revision %" PRIu64 "): %s; a restart reloads an older state",
         r->id, r->revision, strerror(errno));
  free(s);
}

void svc_state_scene_remove(service *svc, const char *id) {
  if (!svc_state_on(svc) || !rsw_is_sha256_hex(id)) return;
  char p[4200];
  state_path(svc, p, sizeof p, "scenes/%s.scene", id);
  unlink(p);
  state_path(svc, p, sizeof p, "scenes/%s.params", id);
  unlink(p);
  fsync_dir(p);
}

/* ---- films ------------------------------------------------------------------- */

uint64_t svc_film_bytes(const scene *sc, size_t sensor_index) {
  const sensor *se = sc->sensors[sensor_index];
  const film *fm = se->film;
  int ch = fm->pixel_format == PIXFMT_STOKES && sc->variant == VARIANT_MONO      ? 4
           : sc->variant == VARIANT_MONO || fm->pixel_format == PIXFMT_LUMINANCE ? 1
                                                                                 : 3;
  uint64_t px = (uint64_t)fm->width * (uint64_t)fm->height;
  return px * (uint64_t)ch * 4 + (se->ops->pixel_angles ? px * 16 : 0);
}

/* The channel names are static strings in a film_image. */
static const char *static_channel(const char *name) {
  static const char *const names[] = {"R", "G", "B", "Y", "S0", "S1", "S2", "S3"};
  for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
    if (strcmp(names[i], name) == 0) return names[i];
  return NULL;
}

/* The .npy header of http_film_npy: magic, version 1.0, header length,
 * the dict padded with spaces and '\n' to a multiple of 64 bytes. */
static size_t npy_header(const film_image *im, char out[256]) {
  char dict[128];
  int dn = snprintf(dict, sizeof dict, "{'descr': '<f4', 'fortran_order': False, 'shape': (%d, %d, %d), }",
                    im->height, im->width, im->channels * (1 + im->n_planes));
  size_t header = (10 + (size_t)dn + 1 + 63) / 64 * 64;
  memcpy(out, "\x93NUMPY\x01\x00", 8);
  size_t hlen = header - 10;
  out[8] = (char)(hlen & 0xff);
  out[9] = (char)(hlen >> 8);
  memcpy(out + 10, dict, (size_t)dn);
  memset(out + 10 + dn, ' ', header - 10 - (size_t)dn - 1);
  out[header - 1] = '\n';
  return header;
}

static bool little_endian(void) {
  uint32_t x = 1;
  unsigned char c;
  memcpy(&c, &x, 1);
  return c == 1;
}

/* A film file: the .npy bytes (what GET .../results answers as .npy),
 * then the per-pixel angles (float64, host order; none when the sensor has
 * none), the metadata (JSON), and a trailer of three little-endian uint64
 * lengths (npy, angles, meta) and the magic "RSWFILM1". A file whose size
 * or trailer does not add up is not a film (a write a crash cut short):
 * the render runs again. */
#define FILM_MAGIC "RSWFILM1"

typedef struct film_trailer {
  uint64_t npy, angles, meta;
} film_trailer;

static void film_path(const service *svc, char *out, size_t n, const char *job_id, size_t k) {
  state_path(svc, out, n, "results/%s/%zu.film", job_id, k);
}

static void put_u64(unsigned char *p, uint64_t v) {
  for (int i = 0; i < 8; i++) p[i] = (unsigned char)(v >> (8 * i));
}

static uint64_t get_u64(const unsigned char *p) {
  uint64_t v = 0;
  for (int i = 0; i < 8; i++) v |= (uint64_t)p[i] << (8 * i);
  return v;
}

/* Open item k's film and check its trailer; -1 when absent or torn. */
static int film_open(const service *svc, const char *job_id, size_t k, film_trailer *t) {
  char p[4200];
  film_path(svc, p, sizeof p, job_id, k);
  int fd = open(p, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return -1;
  struct stat sb;
  unsigned char tr[32];
  if (fstat(fd, &sb) != 0 || sb.st_size < 32 || pread(fd, tr, 32, sb.st_size - 32) != 32 ||
      memcmp(tr + 24, FILM_MAGIC, 8) != 0) {
    close(fd);
    return -1;
  }
  t->npy = get_u64(tr), t->angles = get_u64(tr + 8), t->meta = get_u64(tr + 16);
  if (t->npy < 64 || t->meta > (1u << 20) || t->npy + t->angles + t->meta + 32 != (uint64_t)sb.st_size) {
    close(fd);
    return -1;
  }
  return fd;
}

static bool read_at(int fd, void *buf, size_t n, off_t off) {
  char *c = buf;
  while (n) {
    ssize_t r = pread(fd, c, n, off);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;
    c += r, n -= (size_t)r, off += r;
  }
  return true;
}

rsw_status svc_state_film_write(service *svc, const job *j, size_t k, const svc_film *f, svc_error *e) {
  if (!svc_state_on(svc)) return RSW_OK;
  const film_image *im = &f->img;
  char p[4200];
  state_path(svc, p, sizeof p, "results/%s", j->id);
  if (mkdir(p, 0700) != 0 && errno != EEXIST)
    return svc_fail(e, RSW_ERR_IO, "--state-dir", "cannot create '%s': %s", p, strerror(errno));
  size_t px = (size_t)im->width * (size_t)im->height;
  cJSON *m = cJSON_CreateObject();
  cJSON_AddStringToObject(m, "scene", f->scene);
  cJSON_AddNumberToObject(m, "revision", (double)f->revision);
  cJSON_AddStringToObject(m, "context", f->context);
  cJSON_AddStringToObject(m, "sensor", f->sensor);
  cJSON_AddNumberToObject(m, "width", im->width);
  cJSON_AddNumberToObject(m, "height", im->height);
  cJSON *ch = cJSON_AddArrayToObject(m, "channels");
  for (int c = 0; c < im->channels; c++) cJSON_AddItemToArray(ch, cJSON_CreateString(im->channel_names[c]));
  cJSON_AddBoolToObject(m, "half", im->half);
  cJSON_AddNumberToObject(m, "spp", im->spp);
  char num[40];
  snprintf(num, sizeof num, "%" PRIu64, im->seed); /* exact beyond 2^53 */
  cJSON_AddStringToObject(m, "seed", num);
  snprintf(num, sizeof num, "%.17g", im->wavelength);
  cJSON_AddStringToObject(m, "wavelength", num);
  cJSON_AddStringToObject(m, "variant", im->variant == VARIANT_MONO ? "mono" : "rgb");
  snprintf(num, sizeof num, "%" PRIu64, im->unresolved_rays);
  cJSON_AddStringToObject(m, "unresolved_rays", num);
  if (im->n_planes) { /* their channels follow the radiance ones in the .npy */
    cJSON *pl = cJSON_AddArrayToObject(m, "planes");
    for (int q = 0; q < im->n_planes; q++) cJSON_AddItemToArray(pl, cJSON_CreateString(im->planes[q].name));
  }
  if (im->has_irradiance) {
    cJSON *ir = cJSON_AddArrayToObject(m, "irradiance");
    for (int c = 0; c < im->channels; c++) {
      snprintf(num, sizeof num, "%.17g", im->irradiance[c]);
      cJSON_AddItemToArray(ir, cJSON_CreateString(num));
    }
  }
  if (im->has_sun) {
    snprintf(num, sizeof num, "%.17g", im->sun_zenith);
    cJSON_AddStringToObject(m, "sun_zenith", num);
    snprintf(num, sizeof num, "%.17g", im->sun_azimuth);
    cJSON_AddStringToObject(m, "sun_azimuth", num);
  }
  char *ms = svc_print_json(m, svc_json_mark());
  if (!ms) return svc_fail(e, RSW_ERR_NOMEM, "--state-dir", "out of memory");
  char head[256];
  size_t nh = npy_header(im, head);
  size_t n = px * (size_t)im->channels * (size_t)(1 + im->n_planes);
  size_t na = im->angles ? px * 2 * sizeof(double) : 0, nm = strlen(ms);
  size_t total = nh + n * sizeof(float) + na + nm + 32;
  unsigned char *out = malloc(total);
  float *all = im->n_planes ? film_image_interleaved(im) : NULL;
  if (!out || (im->n_planes && !all)) {
    free(out);
    free(all);
    free(ms);
    return svc_fail(e, RSW_ERR_NOMEM, "--state-dir", "out of memory for a %zu-byte film", total);
  }
  unsigned char *q = out;
  memcpy(q, head, nh), q += nh;
  memcpy(q, all ? all : im->data, n * sizeof(float));
  free(all);
  if (!little_endian())
    for (size_t i = 0; i < n; i++) {
      uint32_t u;
      memcpy(&u, q + 4 * i, 4);
      u = __builtin_bswap32(u);
      memcpy(q + 4 * i, &u, 4);
    }
  q += n * sizeof(float);
  if (na) memcpy(q, im->angles, na), q += na;
  memcpy(q, ms, nm), q += nm;
  free(ms);
  put_u64(q, nh + n * sizeof(float));
  put_u64(q + 8, na);
  put_u64(q + 16, nm);
  memcpy(q + 24, FILM_MAGIC, 8);
  /* The data is fsync'ed before the rename; the directory once per job
   * (svc_state_job_finished): a film whose rename a power cut loses is
   * rendered again on resume, bitwise the same. */
  film_path(svc, p, sizeof p, j->id, k);
  char tmp[4300];
  snprintf(tmp, sizeof tmp, "%s.tmp", p);
  int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  bool ok = fd >= 0 && write_all(fd, out, total) && fdatasync(fd) == 0;
  int saved = errno;
  if (fd >= 0) ok = close(fd) == 0 && ok;
  ok = ok && rename(tmp, p) == 0;
  if (!ok) saved = errno ? errno : saved;
  free(out);
  if (!ok) {
    unlink(tmp);
    return svc_fail(e, RSW_ERR_IO, "--state-dir", "cannot store the film: %s", strerror(saved));
  }
  return RSW_OK;
}

/* Item k's film header from its metadata (no data); false when absent. */
bool svc_state_film_header(service *svc, const char *job_id, size_t k, svc_film *out) {
  if (!svc_state_on(svc)) return false;
  film_trailer t;
  int fd = film_open(svc, job_id, k, &t);
  if (fd < 0) return false;
  char *ms = malloc(t.meta + 1);
  bool got = ms && read_at(fd, ms, t.meta, (off_t)(t.npy + t.angles));
  close(fd);
  cJSON *m = got ? cJSON_ParseWithLength(ms, t.meta) : NULL;
  free(ms);
  if (!m) return false;
  memset(out, 0, sizeof *out);
  bool ok = true;
  const cJSON *x;
#define STR(name, dst)                                                                                       \
  x = cJSON_GetObjectItemCaseSensitive(m, name);                                                             \
  if (cJSON_IsString(x))                                                                                     \
    snprintf(dst, sizeof dst, "%s", x->valuestring);                                                         \
  else                                                                                                       \
    ok = false;
  STR("scene", out->scene)
  STR("context", out->context)
  STR("sensor", out->sensor)
#undef STR
  char num[40] = "";
#define NUMSTR(name)                                                                                         \
  x = cJSON_GetObjectItemCaseSensitive(m, name);                                                             \
  if (cJSON_IsString(x))                                                                                     \
    snprintf(num, sizeof num, "%s", x->valuestring);                                                         \
  else                                                                                                       \
    ok = false;
  NUMSTR("seed")
  out->img.seed = strtoull(num, NULL, 10);
  NUMSTR("wavelength")
  out->img.wavelength = strtod(num, NULL);
  NUMSTR("unresolved_rays")
  out->img.unresolved_rays = strtoull(num, NULL, 10);
#undef NUMSTR
  x = cJSON_GetObjectItemCaseSensitive(m, "revision");
  out->revision = cJSON_IsNumber(x) ? (uint64_t)x->valuedouble : 0;
  x = cJSON_GetObjectItemCaseSensitive(m, "width");
  out->img.width = cJSON_IsNumber(x) ? x->valueint : 0;
  x = cJSON_GetObjectItemCaseSensitive(m, "height");
  out->img.height = cJSON_IsNumber(x) ? x->valueint : 0;
  x = cJSON_GetObjectItemCaseSensitive(m, "spp");
  out->img.spp = cJSON_IsNumber(x) ? (uint32_t)x->valuedouble : 0;
  out->img.half = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(m, "half"));
  x = cJSON_GetObjectItemCaseSensitive(m, "variant");
  out->img.variant = cJSON_IsString(x) && strcmp(x->valuestring, "mono") == 0 ? VARIANT_MONO : VARIANT_RGB;
  const cJSON *ch = cJSON_GetObjectItemCaseSensitive(m, "channels");
  int c = 0;
  for (const cJSON *y = cJSON_IsArray(ch) ? ch->child : NULL; y && c < 4; y = y->next, c++) {
    const char *s = cJSON_IsString(y) ? static_channel(y->valuestring) : NULL;
    if (!s) ok = false;
    out->img.channel_names[c] = s;
  }
  out->img.channels = c;
  /* Planes: described here (names, units, channels), their data comes
   * with the radiance (svc_state_film_read). */
  const cJSON *pl = cJSON_GetObjectItemCaseSensitive(m, "planes");
  int np = 0;
  for (const cJSON *y = cJSON_IsArray(pl) ? pl->child : NULL; y && ok; y = y->next, np++) {
    if (np == FILM_MAX_PLANES || !cJSON_IsString(y) || !film_plane_known(y->valuestring)) {
      ok = false;
      break;
    }
    film_plane_init(&out->img, y->valuestring, &out->img.planes[np]);
  }
  out->img.n_planes = ok ? np : 0;
  const cJSON *ir = cJSON_GetObjectItemCaseSensitive(m, "irradiance");
  if (cJSON_IsArray(ir) && cJSON_GetArraySize(ir) == c) {
    out->img.has_irradiance = true;
    int ki = 0;
    for (const cJSON *y = ir->child; y && ki < 4; y = y->next, ki++)
      out->img.irradiance[ki] = cJSON_IsString(y) ? strtod(y->valuestring, NULL) : NAN;
  }
  const cJSON *sz = cJSON_GetObjectItemCaseSensitive(m, "sun_zenith");
  const cJSON *sa = cJSON_GetObjectItemCaseSensitive(m, "sun_azimuth");
  if (cJSON_IsString(sz) && cJSON_IsString(sa)) {
    out->img.has_sun = true;
    out->img.sun_zenith = strtod(sz->valuestring, NULL);
    out->img.sun_azimuth = strtod(sa->valuestring, NULL);
  }
  uint64_t px = (uint64_t)(out->img.width > 0 ? out->img.width : 0) *
                (uint64_t)(out->img.height > 0 ? out->img.height : 0);
  uint64_t tc = (uint64_t)c * (uint64_t)(1 + out->img.n_planes);
  if (px == 0 || c < 1 || t.npy < px * tc * 4 || (t.angles && t.angles != px * 16)) ok = false;
  cJSON_Delete(m);
  if (!ok) out->img.n_planes = 0;
  return ok;
}

rsw_status svc_state_film_read(service *svc, const job *j, size_t k, svc_film *out, svc_error *e) {
  if (!svc_state_film_header(svc, j->id, k, out))
    return svc_fail(e, RSW_ERR_IO, j->id, "the stored film of render %zu of job %s is missing or unreadable",
                    k, j->id);
  film_image *im = &out->img;
  film_trailer t;
  int fd = film_open(svc, j->id, k, &t);
  size_t want = (size_t)im->width * (size_t)im->height * (size_t)im->channels * (size_t)(1 + im->n_planes);
  float *all = fd >= 0 ? malloc(want * sizeof(float)) : NULL;
  if (t.angles && all) im->angles = malloc(t.angles);
  bool ok = all && (!t.angles || im->angles) &&
            read_at(fd, all, want * sizeof(float), (off_t)(t.npy - want * sizeof(float))) &&
            (!t.angles || read_at(fd, im->angles, t.angles, (off_t)t.npy));
  if (fd >= 0) close(fd);
  if (ok && !little_endian())
    for (size_t i = 0; i < want; i++) {
      uint32_t u;
      memcpy(&u, &all[i], 4);
      u = __builtin_bswap32(u);
      memcpy(&all[i], &u, 4);
    }
  if (ok && !im->n_planes) {
    im->data = all;
    all = NULL;
  } else if (ok) { /* radiance and planes apart again */
    const char *names[FILM_MAX_PLANES];
    for (int p = 0; p < im->n_planes; p++) names[p] = im->planes[p].name;
    ok = film_image_split(im, names, im->n_planes, all);
  }
  free(all);
  if (!ok) {
    film_image_free(im);
    return svc_fail(e, RSW_ERR_IO, j->id, "cannot read the stored film of render %zu of job %s", k, j->id);
  }
  return RSW_OK;
}

int svc_state_film_npy_fd(service *svc, const char *job_id, size_t k, uint64_t *len) {
  film_trailer t;
  int fd = film_open(svc, job_id, k, &t);
  if (fd >= 0) *len = t.npy;
  return fd;
}

/* ---- jobs -------------------------------------------------------------------- */

static const char *const state_names[] = {"queued", "running", "succeeded", "failed", "cancelled"};

static job_state parse_state(const char *s) {
  for (int i = 0; i < 5; i++)
    if (s && strcmp(s, state_names[i]) == 0) return (job_state)i;
  return JOB_FAILED;
}

void svc_state_job_saved(service *svc, const job *j, const char *body, size_t len) {
  if (!svc_state_on(svc) || svc->restore_id) return;
  cJSON *h = cJSON_CreateObject();
  cJSON_AddStringToObject(h, "id", j->id);
  cJSON_AddStringToObject(h, "scene", j->scene_id);
  cJSON_AddNumberToObject(h, "revision", (double)j->revision);
  cJSON_AddNumberToObject(h, "created", (double)j->created);
  if (j->idem_key) cJSON_AddStringToObject(h, "idem_key", j->idem_key);
  char dh[65];
  rsw_hex(j->body_digest, 32, dh);
  cJSON_AddStringToObject(h, "body_sha256", dh);
  if (j->warnings) cJSON_AddItemToObject(h, "warnings", cJSON_Duplicate(j->warnings, 1));
  char *hs = svc_print_json(h, svc_json_mark());
  char p[4200];
  state_path(svc, p, sizeof p, "jobs/%s.req", j->id);
  bool ok = false;
  if (hs) {
    size_t n = strlen(hs);
    hs[n] = '\n'; /* the header line */
    ok = write_atomic(p, hs, n + 1, body, len);
  }
  free(hs);
  if (!ok) warn("cannot store job %s's request: %s; a restart will not know it", j->id, strerror(errno));
}

void svc_state_job_finished(service *svc, const job *j) {
  if (!svc_state_on(svc) || svc->stopping) return; /* stopping: resumed at the next start */
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "state", state_names[j->state]);
  if (j->error[0]) cJSON_AddStringToObject(o, "error", j->error);
  cJSON_AddStringToObject(o, "created_iso", j->created_iso);
  cJSON_AddStringToObject(o, "started_iso", j->started_iso);
  cJSON_AddStringToObject(o, "finished_iso", j->finished_iso);
  cJSON_AddNumberToObject(o, "finished", (double)time(NULL));
  cJSON_AddNumberToObject(
      o, "seconds", j->started_iso[0] && j->t_finished > j->t_started ? j->t_finished - j->t_started : 0);
  cJSON_AddNumberToObject(o, "contexts_total", (double)j->n_contexts);
  cJSON_AddNumberToObject(o, "contexts_done", (double)j->contexts_done);
  cJSON *a = cJSON_AddArrayToObject(o, "items");
  for (size_t i = 0; i < j->n_items; i++) {
    const render_item *it = &j->items[i];
    cJSON *x = cJSON_CreateObject();
    cJSON_AddStringToObject(x, "c", it->context);
    cJSON_AddStringToObject(x, "s", it->sensor);
    cJSON_AddNumberToObject(x, "ci", (double)it->context_index);
    cJSON_AddStringToObject(x, "st", state_names[it->state]);
    char num[40];
    snprintf(num, sizeof num, "%.17g", it->wavelength);
    cJSON_AddStringToObject(x, "w", num);
    snprintf(num, sizeof num, "%" PRIu64, it->seed);
    cJSON_AddStringToObject(x, "seed", num);
    if (it->node) cJSON_AddNumberToObject(x, "n", (double)it->node); /* jobs with bands */
    if (it->error[0]) cJSON_AddStringToObject(x, "err", it->error);
    if (it->state == JOB_SUCCEEDED) {
      const film_image *im = &it->film.img;
      cJSON_AddNumberToObject(x, "spp", im->spp);
      cJSON_AddNumberToObject(x, "W", im->width);
      cJSON_AddNumberToObject(x, "H", im->height);
      cJSON *ch = cJSON_AddArrayToObject(x, "ch");
      for (int c = 0; c < im->channels; c++)
        cJSON_AddItemToArray(ch, cJSON_CreateString(im->channel_names[c]));
      if (im->n_planes) {
        cJSON *pl = cJSON_AddArrayToObject(x, "pl");
        for (int q = 0; q < im->n_planes; q++)
          cJSON_AddItemToArray(pl, cJSON_CreateString(im->planes[q].name));
      }
      if (im->unresolved_rays) cJSON_AddNumberToObject(x, "unres", (double)im->unresolved_rays);
      cJSON_AddBoolToObject(x, "disk", it->on_disk);
    }
    cJSON_AddItemToArray(a, x);
  }
  char *s = svc_print_json(o, svc_json_mark());
  char p[4200];
  state_path(svc, p, sizeof p, "results/%s/x", j->id);
  fsync_dir(p); /* the films' renames, before the record that counts them */
  state_path(svc, p, sizeof p, "jobs/%s.done", j->id);
  if (!s || !write_atomic(p, s, strlen(s), "", 0))
    warn("cannot store job %s's outcome: %s; a restart runs it again", j->id, strerror(errno));
  free(s);
}

static int remove_entry(const char *path, const struct stat *sb, int flag, struct FTW *ftw) {
  (void)sb, (void)flag, (void)ftw;
  remove(path);
  return 0;
}

void svc_state_job_remove(service *svc, const job *j) {
  if (!svc_state_on(svc)) return;
  char p[4200];
  state_path(svc, p, sizeof p, "jobs/%s.req", j->id);
  unlink(p);
  state_path(svc, p, sizeof p, "jobs/%s.done", j->id);
  unlink(p);
  fsync_dir(p);
  state_path(svc, p, sizeof p, "results/%s", j->id);
  nftw(p, remove_entry, 16, FTW_DEPTH | FTW_PHYS);
}

/* ---- restore ----------------------------------------------------------------- */

typedef struct req_header {
  char id[40];
  char scene[65];
  uint64_t revision;
  time_t created;
  char idem[256];
  bool has_idem;
  unsigned char digest[32];
  cJSON *warnings; /* the job's warnings (templates.h), owned; NULL when none */
} req_header;

static bool parse_req(const char *text, size_t n, req_header *h, size_t *body_off) {
  const char *nl = memchr(text, '\n', n);
  cJSON *o = nl ? cJSON_ParseWithLength(text, (size_t)(nl - text)) : NULL;
  const cJSON *id = cJSON_GetObjectItemCaseSensitive(o, "id");
  const cJSON *sc = cJSON_GetObjectItemCaseSensitive(o, "scene");
  const cJSON *rev = cJSON_GetObjectItemCaseSensitive(o, "revision");
  const cJSON *cr = cJSON_GetObjectItemCaseSensitive(o, "created");
  const cJSON *ik = cJSON_GetObjectItemCaseSensitive(o, "idem_key");
  const cJSON *dg = cJSON_GetObjectItemCaseSensitive(o, "body_sha256");
  bool ok = cJSON_IsString(id) && strlen(id->valuestring) < sizeof h->id && cJSON_IsString(sc) &&
            rsw_is_sha256_hex(sc->valuestring) && cJSON_IsNumber(rev) && cJSON_IsNumber(cr);
  if (ok) {
    memset(h, 0, sizeof *h);
    snprintf(h->id, sizeof h->id, "%s", id->valuestring);
    snprintf(h->scene, sizeof h->scene, "%s", sc->valuestring);
    h->revision = (uint64_t)rev->valuedouble;
    h->created = (time_t)cr->valuedouble;
    if (cJSON_IsString(ik) && strlen(ik->valuestring) < sizeof h->idem) {
      snprintf(h->idem, sizeof h->idem, "%s", ik->valuestring);
      h->has_idem = true;
    }
    if (cJSON_IsString(dg) && rsw_is_sha256_hex(dg->valuestring))
      for (int i = 0; i < 32; i++) {
        unsigned v;
        sscanf(dg->valuestring + 2 * i, "%2x", &v);
        h->digest[i] = (unsigned char)v;
      }
    *body_off = (size_t)(nl + 1 - text);
    const cJSON *w = cJSON_GetObjectItemCaseSensitive(o, "warnings");
    if (cJSON_IsArray(w)) h->warnings = cJSON_DetachItemViaPointer(o, (cJSON *)w);
  }
  cJSON_Delete(o);
  return ok;
}

/* A job that will not run again, registered from its record. */
static job *new_terminal_job(service *svc, const req_header *h) {
  job *j = calloc(1, sizeof *j);
  if (!j) return NULL;
  snprintf(j->id, sizeof j->id, "%s", h->id);
  memcpy(j->scene_id, h->scene, 65);
  j->revision = h->revision;
  j->created = h->created;
  svc_iso_time(h->created, j->created_iso);
  memcpy(j->body_digest, h->digest, 32);
  if (h->has_idem) j->idem_key = strdup(h->idem);
  if (h->warnings) j->warnings = cJSON_Duplicate(h->warnings, 1);
  j->t_created = j->t_finished = svc_now();
  (void)svc;
  return j;
}

static void register_terminal(service *svc, job *j) {
  pthread_mutex_lock(&svc->lock);
  if (!svc_grow((void **)&svc->jobs, &svc->cap_jobs, svc->n_jobs + 1, sizeof *svc->jobs, 0)) {
    pthread_mutex_unlock(&svc->lock);
    warn("out of memory restoring job %s", j->id);
    svc_job_free(j);
    return;
  }
  svc->jobs[svc->n_jobs++] = j;
  cJSON *d = cJSON_CreateObject();
  cJSON_AddStringToObject(d, "state", state_names[j->state]);
  cJSON_AddNumberToObject(d, "done", (double)j->items_done);
  cJSON_AddNumberToObject(d, "total", (double)j->n_items);
  svc_job_push_event(svc, j, d, true);
  pthread_mutex_unlock(&svc->lock);
}

static void restore_finished(service *svc, const req_header *h, cJSON *done, const char *body, size_t len) {
  job *j = new_terminal_job(svc, h);
  if (!j) return;
  svc_job_restore_labels(j, body, len); /* coords and seed, for its dataset */
  const cJSON *x;
  x = cJSON_GetObjectItemCaseSensitive(done, "state");
  j->state = parse_state(cJSON_IsString(x) ? x->valuestring : NULL);
  x = cJSON_GetObjectItemCaseSensitive(done, "error");
  if (cJSON_IsString(x)) snprintf(j->error, sizeof j->error, "%s", x->valuestring);
  x = cJSON_GetObjectItemCaseSensitive(done, "started_iso");
  if (cJSON_IsString(x)) snprintf(j->started_iso, sizeof j->started_iso, "%s", x->valuestring);
  x = cJSON_GetObjectItemCaseSensitive(done, "finished_iso");
  if (cJSON_IsString(x)) snprintf(j->finished_iso, sizeof j->finished_iso, "%s", x->valuestring);
  x = cJSON_GetObjectItemCaseSensitive(done, "seconds");
  double secs = cJSON_IsNumber(x) ? x->valuedouble : 0;
  x = cJSON_GetObjectItemCaseSensitive(done, "finished");
  double age = cJSON_IsNumber(x) ? difftime(time(NULL), (time_t)x->valuedouble) : 0;
  /* The results TTL counts from the finish, across restarts. */
  j->t_finished = svc_now() - (age > 0 ? age : 0);
  j->t_started = j->t_finished - secs;
  x = cJSON_GetObjectItemCaseSensitive(done, "contexts_total");
  j->n_contexts = cJSON_IsNumber(x) ? (size_t)x->valuedouble : 0;
  x = cJSON_GetObjectItemCaseSensitive(done, "contexts_done");
  j->contexts_done = cJSON_IsNumber(x) ? (size_t)x->valuedouble : 0;
  const cJSON *items = cJSON_GetObjectItemCaseSensitive(done, "items");
  size_t n = (size_t)cJSON_GetArraySize(items);
  j->items = calloc(n ? n : 1, sizeof *j->items);
  j->context_remaining = calloc(j->n_contexts ? j->n_contexts : 1, sizeof *j->context_remaining);
  if (!j->items || !j->context_remaining) {
    warn("out of memory restoring job %s", j->id);
    svc_job_free(j);
    return;
  }
  size_t k = 0;
  for (const cJSON *it = items ? items->child : NULL; it; it = it->next, k++) {
    render_item *ri = &j->items[k];
    j->n_items = k + 1;
    const cJSON *y;
    y = cJSON_GetObjectItemCaseSensitive(it, "c");
    if (cJSON_IsString(y)) snprintf(ri->context, sizeof ri->context, "%s", y->valuestring);
    y = cJSON_GetObjectItemCaseSensitive(it, "s");
    if (cJSON_IsString(y)) snprintf(ri->sensor, sizeof ri->sensor, "%s", y->valuestring);
    y = cJSON_GetObjectItemCaseSensitive(it, "ci");
    ri->context_index = cJSON_IsNumber(y) ? (size_t)y->valuedouble : 0;
    y = cJSON_GetObjectItemCaseSensitive(it, "st");
    ri->state = parse_state(cJSON_IsString(y) ? y->valuestring : NULL);
    y = cJSON_GetObjectItemCaseSensitive(it, "w");
    ri->wavelength = cJSON_IsString(y) ? strtod(y->valuestring, NULL) : 0;
    y = cJSON_GetObjectItemCaseSensitive(it, "seed");
    ri->seed = cJSON_IsString(y) ? strtoull(y->valuestring, NULL, 10) : 0;
    y = cJSON_GetObjectItemCaseSensitive(it, "n");
    ri->node = cJSON_IsNumber(y) && y->valuedouble >= 1 ? (size_t)y->valuedouble : 0;
    y = cJSON_GetObjectItemCaseSensitive(it, "err");
    if (cJSON_IsString(y)) snprintf(ri->error, sizeof ri->error, "%s", y->valuestring);
    if (ri->state != JOB_QUEUED && ri->state != JOB_RUNNING) j->items_done++;
    if (ri->state == JOB_FAILED) j->items_failed++;
    if (ri->state == JOB_SUCCEEDED) {
      film_image *im = &ri->film.img;
      y = cJSON_GetObjectItemCaseSensitive(it, "spp");
      im->spp = cJSON_IsNumber(y) ? (uint32_t)y->valuedouble : 0;
      y = cJSON_GetObjectItemCaseSensitive(it, "W");
      im->width = cJSON_IsNumber(y) ? y->valueint : 0;
      y = cJSON_GetObjectItemCaseSensitive(it, "H");
      im->height = cJSON_IsNumber(y) ? y->valueint : 0;
      y = cJSON_GetObjectItemCaseSensitive(it, "unres");
      im->unresolved_rays = cJSON_IsNumber(y) ? (uint64_t)y->valuedouble : 0;
      y = cJSON_GetObjectItemCaseSensitive(it, "ch");
      int c = 0;
      for (const cJSON *z = cJSON_IsArray(y) ? y->child : NULL; z && c < 4; z = z->next)
        if (cJSON_IsString(z) && static_channel(z->valuestring))
          im->channel_names[c++] = static_channel(z->valuestring);
      im->channels = c;
      y = cJSON_GetObjectItemCaseSensitive(it, "pl");
      for (const cJSON *z = cJSON_IsArray(y) ? y->child : NULL; z && im->n_planes < FILM_MAX_PLANES;
           z = z->next)
        if (cJSON_IsString(z) && film_plane_known(z->valuestring))
          film_plane_init(im, z->valuestring, &im->planes[im->n_planes++]);
      ri->on_disk = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(it, "disk"));
      if (!ri->on_disk) { /* kept in memory only (its write failed): gone */
        ri->state = JOB_FAILED;
        snprintf(ri->error, sizeof ri->error, "the film was not stored on disk and was lost in a restart");
        j->items_failed++;
      }
      memcpy(ri->film.scene, h->scene, 65);
      ri->film.revision = h->revision;
      snprintf(ri->film.context, sizeof ri->film.context, "%s", ri->context);
      snprintf(ri->film.sensor, sizeof ri->film.sensor, "%s", ri->sensor);
    }
  }
  register_terminal(svc, j);
}

/* A job that cannot resume ends failed, with the reason, and says so on
 * disk too. */
static void restore_failed(service *svc, const req_header *h, const char *why) {
  job *j = new_terminal_job(svc, h);
  if (!j) return;
  j->state = JOB_FAILED;
  snprintf(j->error, sizeof j->error, "interrupted by a restart and not resumed: %s", why);
  svc_iso_time(time(NULL), j->finished_iso);
  j->context_remaining = calloc(1, sizeof *j->context_remaining);
  svc->jobs_failed_on_restore++;
  warn("job %s: %s", j->id, j->error);
  svc_state_job_finished(svc, j);
  register_terminal(svc, j);
}

static void restore_resume(service *svc, const req_header *h, const char *body, size_t len) {
  resident *r = svc_scene_acquire(svc, h->scene);
  char why[900];
  if (!r) {
    snprintf(why, sizeof why, "its scene %s is not in the state directory (deleted, or loaded with --scene)",
             h->scene);
    restore_failed(svc, h, why);
    return;
  }
  uint64_t rev = r->revision;
  svc_scene_release(svc, r);
  if (rev != h->revision) {
    snprintf(why, sizeof why,
             "scene %s is at revision %" PRIu64 " but the job was submitted at revision %" PRIu64
             " (a PATCH came between): its results would differ",
             h->scene, rev, h->revision);
    restore_failed(svc, h, why);
    return;
  }
  svc_error e = {0};
  char *jid = NULL, *json = NULL;
  svc->restore_id = h->id;
  rsw_status st = service_job_submit(svc, h->scene, body, len, h->has_idem ? h->idem : NULL, &jid, &json, &e);
  svc->restore_id = NULL;
  free(json);
  free(jid);
  if (st) {
    char msg[800];
    snprintf(why, sizeof why, "the request no longer validates: %s", rsw_err_format(&e.err, msg, sizeof msg));
    restore_failed(svc, h, why);
    return;
  }
  pthread_mutex_lock(&svc->lock);
  job *j = svc_find_job_locked(svc, h->id);
  if (j) {
    j->created = h->created;
    svc_iso_time(h->created, j->created_iso);
    svc->jobs_resumed++;
    fprintf(stderr, "raysweepd: state: job %s resumed (%zu of %zu renders were done)\n", j->id, j->items_done,
            j->n_items);
  }
  pthread_mutex_unlock(&svc->lock);
}

void svc_state_resume_items(service *svc, job *j) {
  for (size_t k = 0; k < j->n_items; k++) {
    render_item *it = &j->items[k];
    svc_film f;
    if (!svc_state_film_header(svc, j->id, k, &f)) continue;
    it->film = f;
    it->on_disk = true;
    it->state = JOB_SUCCEEDED;
    j->items_done++;
    if (--j->context_remaining[it->context_index] == 0) j->contexts_done++;
  }
}

static int cmp_names(const void *a, const void *b) {
  return strcmp(*(char *const *)a, *(char *const *)b);
}

void svc_state_restore(service *svc) {
  if (!svc_state_on(svc)) return;
  double t0 = svc_now();
  char p[4200];
  state_path(svc, p, sizeof p, "jobs");
  DIR *d = opendir(p);
  if (!d) return;
  char **names = NULL;
  size_t n = 0, cap = 0;
  for (struct dirent *de; (de = readdir(d));) {
    size_t l = strlen(de->d_name);
    if (l < 5 || strcmp(de->d_name + l - 4, ".req") != 0) continue;
    char *s = strndup(de->d_name, l - 4);
    if (!s || !svc_grow((void **)&names, &cap, n + 1, sizeof *names, 0)) {
      free(s);
      break;
    }
    names[n++] = s;
  }
  closedir(d);
  if (n) qsort(names, n, sizeof *names, cmp_names);
  size_t restored = 0;
  for (size_t i = 0; i < n; i++) {
    state_path(svc, p, sizeof p, "jobs/%s.req", names[i]);
    size_t len, off;
    char *text = read_whole(p, &len);
    req_header h;
    if (!text || !parse_req(text, len, &h, &off) || strcmp(h.id, names[i]) != 0) {
      warn("%s: unreadable job record; ignored", p);
      free(text);
      continue;
    }
    unsigned long long num;
    if (sscanf(h.id, "job-%llu", &num) == 1 && num > svc->next_job) svc->next_job = num;
    state_path(svc, p, sizeof p, "jobs/%s.done", h.id);
    char *dt = read_whole(p, NULL);
    cJSON *done = dt ? cJSON_Parse(dt) : NULL;
    free(dt);
    if (done)
      restore_finished(svc, &h, done, text + off, len - off);
    else
      restore_resume(svc, &h, text + off, len - off);
    cJSON_Delete(done);
    cJSON_Delete(h.warnings);
    free(text);
    restored++;
  }
  for (size_t i = 0; i < n; i++) free(names[i]);
  free(names);
  svc->restore_s = svc_now() - t0;
  if (restored)
    fprintf(stderr,
            "raysweepd: state: %zu job(s) restored from %s (%llu resumed, %llu failed to resume) in %.3f s\n",
            restored, svc->state_dir, (unsigned long long)svc->jobs_resumed,
            (unsigned long long)svc->jobs_failed_on_restore, svc->restore_s);
}
