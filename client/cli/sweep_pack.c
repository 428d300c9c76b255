/* sweep --format dataset: the films as the daemon encoded them (EXR),
 * decoded into the dataset as they arrive and appended to one store file,
 * which is read back only if the dataset has to be built again. With
 * --spread the store is the spool, DIR/sweep.films, so that a rerun after
 * a cut-off finds the films an earlier run delivered; otherwise it is a
 * file of DIR without a name, gone with the process. No file per film,
 * and no film's bytes held in memory (the dataset holds it decoded).
 *
 * The films go into the dataset as they arrive (decoded then, while the
 * renders run, not all at the end): every context of the sweep is added
 * first, in index order, with its wavelength and coords; when the sweep
 * ends the dataset is written as it is if what arrived is what the index
 * lists (each context with a film, its wavelength the one added, each film
 * once), and otherwise built again from the films in the store, in index
 * order (sweep_write_dataset), as --format nc builds its own: the same
 * file.
 *
 * A store record: "RSF1", the header's length (uint32, little-endian), the
 * EXR's length (uint64, little-endian), the header (JSON: {"context",
 * "sensor", "channels"}), the EXR bytes. One writev(2) a record; a record
 * cut short (the process killed half-way) is dropped, and the spool cut
 * back to the records before it, when a rerun reads it. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include "sweep.h"

static const char spool_magic[4] = {'R', 'S', 'F', '1'};
#define SPOOL_HEAD 16 /* magic, header length, EXR length */

static void put_le(unsigned char *p, uint64_t v, int n) {
  for (int i = 0; i < n; i++) p[i] = (unsigned char)(v >> (8 * i));
}

static uint64_t get_le(const unsigned char *p, int n) {
  uint64_t v = 0;
  for (int i = 0; i < n; i++) v |= (uint64_t)p[i] << (8 * i);
  return v;
}

/* Add film f to d, its EXR being bytes (len f->len). */
static int film_add(rsw_dataset *d, const pack_film *f, const void *bytes) {
  const char *names[64];
  int nn = 0;
  const cJSON *ch;
  cJSON_ArrayForEach(ch, f->channels) {
    if (nn < 64 && cJSON_IsString(ch)) names[nn] = ch->valuestring;
    nn++;
  }
  if (nn > 64) return RSW_ERR_LIMIT;
  return rsw_dataset_add_film_exr(d, f->context, f->sensor, bytes, f->len, f->channels ? names : NULL, nn);
}

int pack_film_add_to(const film_pack *p, rsw_dataset *d, const pack_film *f) {
  unsigned char *b = malloc(f->len ? f->len : 1);
  if (!b) return RSW_ERR_NOMEM;
  size_t got = 0;
  while (got < f->len) {
    ssize_t r = pread(p->fd, b + got, f->len - got, f->off + (off_t)got);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) break;
    got += (size_t)r;
  }
  int s = got == f->len ? film_add(d, f, b) : RSW_ERR_IO;
  free(b);
  return s;
}

/* Keep a film (its EXR, bytes, at off in the store; channels: the
 * result's list, copied), and add it to the live dataset. */
static int pack_keep(film_pack *p, const char *c, const char *sn, const cJSON *channels, const void *bytes,
                     size_t len, off_t off) {
  if (p->n == p->cap) {
    size_t cap = p->cap ? 2 * p->cap : 64;
    pack_film *nf = realloc(p->f, cap * sizeof *nf);
    if (!nf) return -1;
    p->f = nf, p->cap = cap;
  }
  pack_film *f = &p->f[p->n];
  memset(f, 0, sizeof *f);
  f->context = strdup(c);
  f->sensor = strdup(sn);
  f->channels = channels ? cJSON_Duplicate(channels, 1) : NULL;
  f->off = off;
  f->len = len;
  f->seq = p->n;
  if (!f->context || !f->sensor || (channels && !f->channels)) {
    free(f->context), free(f->sensor);
    cJSON_Delete(f->channels);
    return -1;
  }
  p->n++;
  p->sorted = false;
  if (p->live && p->live_ok) { /* a film it refuses: the dataset is built again at the end, which says why */
    if (film_add(p->live, f, bytes))
      p->live_ok = false;
    else
      p->live_films++;
  }
  return 0;
}

/* Read the spool's records into p; cut a partial last record off. */
static int spool_read(const cli_ctx *ctx, film_pack *p) {
  size_t len = 0;
  char *text = rsw_read_file(p->spool_path, &len);
  if (!text)
    return errno == ENOENT ? 0
                           : cli_fail(ctx, CLI_IO, "cannot read '%s': %s", p->spool_path, strerror(errno));
  const unsigned char *b = (const unsigned char *)text;
  size_t at = 0;
  int rc = 0;
  while (!rc && len - at >= SPOOL_HEAD && memcmp(b + at, spool_magic, 4) == 0) {
    uint64_t hl = get_le(b + at + 4, 4), bl = get_le(b + at + 8, 8);
    if (hl > len - at - SPOOL_HEAD || bl > len - at - SPOOL_HEAD - hl) break;
    cJSON *h = cJSON_ParseWithLength((const char *)b + at + SPOOL_HEAD, (size_t)hl);
    const char *c = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(h, "context"));
    const char *sn = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(h, "sensor"));
    if (!c || !sn) {
      cJSON_Delete(h);
      break;
    }
    if (pack_keep(p, c, sn, cJSON_GetObjectItemCaseSensitive(h, "channels"), b + at + SPOOL_HEAD + hl,
                  (size_t)bl, (off_t)(at + SPOOL_HEAD + hl)))
      rc = cli_fail(ctx, CLI_IO, "out of memory");
    cJSON_Delete(h);
    at += SPOOL_HEAD + (size_t)hl + (size_t)bl;
  }
  free(text);
  if (!rc && at < len && truncate(p->spool_path, (off_t)at) != 0)
    rc = cli_fail(ctx, CLI_IO, "cannot cut '%s' back to its whole records: %s", p->spool_path,
                  strerror(errno));
  p->end = (off_t)at;
  return rc;
}

int pack_open(const cli_ctx *ctx, film_pack *p, const char *dir, bool spool, bool resume, sweep_item **sorted,
              size_t n) {
  memset(p, 0, sizeof *p);
  p->fd = -1;
  p->items = sorted, p->n_items = n;
  if (n && rsw_dataset_new(&p->live) == RSW_OK) {
    int rc = sweep_dataset_store(ctx, p->live, dir);
    if (rc) return rc;
    p->live_ok = true;
    for (size_t i = 0; i < n && p->live_ok; i++) {
      char *co = sorted[i]->coords ? cJSON_PrintUnformatted(sorted[i]->coords) : NULL;
      p->live_ok = (!sorted[i]->coords || co) &&
                   rsw_dataset_add_context(p->live, sorted[i]->id, sorted[i]->has_wl ? sorted[i]->wl : 0,
                                           co) == RSW_OK;
      free(co);
    }
  }
  if (!spool) {
    /* A file without a name (O_TMPFILE; where the file system has none,
     * one made and unlinked at once). */
    p->fd = open(dir, O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
    if (p->fd < 0) {
      char *t = sweep_dir_file(dir, ".sweep.films.XXXXXX");
      if (!t) return cli_fail(ctx, CLI_IO, "out of memory");
      p->fd = mkostemp(t, O_CLOEXEC);
      int e = errno;
      if (p->fd >= 0) unlink(t);
      free(t);
      if (p->fd < 0) return cli_fail(ctx, CLI_IO, "cannot write a film store in '%s': %s", dir, strerror(e));
    }
    return 0;
  }
  if (!(p->spool_path = sweep_dir_file(dir, FILM_SPOOL))) return cli_fail(ctx, CLI_IO, "out of memory");
  int rc = resume ? spool_read(ctx, p) : 0;
  if (rc) return rc;
  p->fd = open(p->spool_path, O_RDWR | O_CREAT | O_APPEND | O_CLOEXEC | (resume ? 0 : O_TRUNC), 0644);
  if (p->fd < 0) return cli_fail(ctx, CLI_IO, "cannot write '%s': %s", p->spool_path, strerror(errno));
  return 0;
}

int pack_add(const cli_ctx *ctx, film_pack *p, const char *c, const char *sn, const cJSON *channels,
             const void *bytes, size_t len) {
  const char *where = p->spool_path ? p->spool_path : "the sweep's film store";
  cJSON *h = cJSON_CreateObject();
  cJSON_AddStringToObject(h, "context", c);
  cJSON_AddStringToObject(h, "sensor", sn);
  if (channels) cJSON_AddItemToObject(h, "channels", cJSON_Duplicate(channels, 1));
  char *ht = cJSON_PrintUnformatted(h);
  cJSON_Delete(h);
  if (!ht) return cli_fail(ctx, CLI_IO, "out of memory");
  size_t hl = strlen(ht), total = SPOOL_HEAD + hl + len;
  unsigned char head[SPOOL_HEAD];
  memcpy(head, spool_magic, 4);
  put_le(head + 4, hl, 4);
  put_le(head + 8, len, 8);
  /* The record in one writev(2), the film's bytes not copied. */
  struct iovec iov[3] = {{head, SPOOL_HEAD}, {ht, hl}, {(void *)bytes, len}};
  int at = 0;
  size_t done = 0;
  while (done < total) {
    ssize_t w = writev(p->fd, iov + at, 3 - at);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) break;
    done += (size_t)w;
    size_t k = (size_t)w; /* past what was written: a short write goes on where it stopped */
    while (at < 3 && k >= iov[at].iov_len) k -= iov[at++].iov_len;
    if (at < 3) iov[at].iov_base = (char *)iov[at].iov_base + k, iov[at].iov_len -= k;
  }
  int e = errno;
  free(ht);
  if (done < total) return cli_fail(ctx, CLI_IO, "cannot write %s: %s", where, strerror(e));
  off_t off = p->end + (off_t)(SPOOL_HEAD + hl);
  p->end += (off_t)total;
  if (pack_keep(p, c, sn, channels, bytes, len, off)) return cli_fail(ctx, CLI_IO, "out of memory");
  return 0;
}

static int cmp_pack(const void *a, const void *b) {
  const pack_film *x = a, *y = b;
  int c = strcmp(x->context, y->context);
  if (!c) c = strcmp(x->sensor, y->sensor);
  if (!c) c = x->seq < y->seq ? -1 : x->seq > y->seq;
  return c;
}

const pack_film *pack_find(film_pack *p, const char *c, const char *sn) {
  if (!p->sorted) {
    if (p->n) qsort(p->f, p->n, sizeof *p->f, cmp_pack);
    p->sorted = true;
  }
  /* the last of its key: a film a cut-off run spooled and the rerun fetched again */
  size_t lo = 0, hi = p->n;
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    int k = strcmp(p->f[mid].context, c);
    if (!k) k = strcmp(p->f[mid].sensor, sn);
    if (k <= 0)
      lo = mid + 1;
    else
      hi = mid;
  }
  if (!lo || strcmp(p->f[lo - 1].context, c) != 0 || strcmp(p->f[lo - 1].sensor, sn) != 0) return NULL;
  return &p->f[lo - 1];
}

/* A context's wavelength as rsw_dataset_add_context keeps it. */
static double kept_wl(double wl) {
  return wl > 0 ? wl : -1;
}

rsw_dataset *pack_live(film_pack *p, const index_entry *e, size_t n) {
  if (!p->live || !p->live_ok || p->live_films != n) return NULL;
  size_t k = 0;
  const char *prev = NULL;
  for (size_t i = 0; i < n; i++) {
    const char *c = e[i].context;
    if (prev && strcmp(prev, c) == 0) continue;
    if (k >= p->n_items || strcmp(p->items[k]->id, c) != 0) return NULL; /* a context without a film */
    const cJSON *wl = cJSON_GetObjectItemCaseSensitive(e[i].line, "wavelength");
    double want = kept_wl(cJSON_IsNumber(wl) ? wl->valuedouble : 0);
    double had = kept_wl(p->items[k]->has_wl ? p->items[k]->wl : 0);
    if (want != had) return NULL;
    prev = c;
    k++;
  }
  return k == p->n_items ? p->live : NULL;
}

void pack_close(film_pack *p, bool remove_spool) {
  rsw_dataset_free(p->live);
  if (p->fd >= 0) close(p->fd);
  if (remove_spool && p->spool_path) unlink(p->spool_path);
  for (size_t i = 0; i < p->n; i++) {
    free(p->f[i].context);
    free(p->f[i].sensor);
    cJSON_Delete(p->f[i].channels);
  }
  free(p->f);
  free(p->spool_path);
  memset(p, 0, sizeof *p);
  p->fd = -1;
}
