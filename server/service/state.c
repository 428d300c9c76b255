/* Durable state (`raysweepd serve --state-dir DIR`): what a restart after a
 * crash, SIGKILL or upgrade needs, on disk.
 *
 *   DIR/lock                   flock'ed while a daemon uses DIR
 *   DIR/blobs/<sha256>         blobs (unless --blob-dir names another place)
 *   DIR/scenes/<id>.scene      one JSON header line {"format", "variant",
 *                              "id"; for a fork or copy "document" (its
 *                              document's id) and "copy"}, then the posted
 *                              scene text as it came
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
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <unistd.h>

#include "buf.h"
#include "rsw_file.h"
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

int (*svc_state_fault_hook)(const char *path) = NULL;

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
  int fd = open(slash ? dir : ".", O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return false;
  bool ok = fsync(fd) == 0;
  int saved = errno;
  close(fd);
  errno = saved;
  return ok;
}

typedef struct part {
  const void *p;
  size_t n;
} part;

/* A new temporary file beside path: a random suffix, created with
 * O_EXCL|O_NOFOLLOW, so nothing planted at a guessable name (a symbolic
 * link to another file) is ever written through. */
static int temp_create(const char *path, char *tmp, size_t cap) {
  for (int t = 0; t < 16; t++) {
    uint64_t r;
    if (getrandom(&r, sizeof r, GRND_NONBLOCK) != (ssize_t)sizeof r)
      r = (uint64_t)(svc_now() * 1e9) ^ ((uint64_t)getpid() << 40) ^ (uint64_t)t;
    snprintf(tmp, cap, "%s.tmp.%016" PRIx64, path, r);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
    if (fd >= 0 || errno != EEXIST) return fd;
  }
  return -1;
}

/* path <- the parts, atomically: a temporary file, fsync, rename, and
 * (sync_dir) fsync of the directory; without sync_dir (films, whose
 * directory is synced once per job) fdatasync, as the data is all that
 * matters. false with errno set on failure. */
static bool write_parts(const char *path, const part *pt, size_t np, bool sync_dir) {
  int inj = svc_state_fault_hook ? svc_state_fault_hook(path) : 0;
  if (inj) {
    errno = inj;
    return false;
  }
  char tmp[4300];
  int fd = temp_create(path, tmp, sizeof tmp);
  if (fd < 0) return false;
  bool ok = true;
  for (size_t i = 0; ok && i < np; i++) ok = write_all(fd, pt[i].p, pt[i].n);
  ok = ok && (sync_dir ? fsync(fd) : fdatasync(fd)) == 0;
  int saved = errno;
  if (close(fd) != 0 && ok) ok = false, saved = errno;
  if (ok && rename(tmp, path) != 0) ok = false, saved = errno;
  if (!ok) {
    unlink(tmp);
    errno = saved;
    return false;
  }
  return !sync_dir || fsync_dir(path);
}

bool svc_write_file(const char *path, const void *data, size_t len) {
  part pt = {data, len};
  return write_parts(path, &pt, 1, true);
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

/* A file's identity is its place: what follows the state directory in its
 * path ("jobs/<id>.req", "results/<id>/<k>.film"). Its checksum covers
 * that name first, so a file copied or moved to another's name (a film
 * swapped with another's) fails it. */
static const char *rel_name(const service *svc, const char *path) {
  size_t l = strlen(svc->state_dir);
  return strncmp(path, svc->state_dir, l) == 0 && path[l] == '/' ? path + l + 1 : path;
}

static void identity_sha(rsw_sha256_ctx *c, const service *svc, const char *path) {
  const char *rel = rel_name(svc, path);
  rsw_sha256_update(c, "raysweep-state-v2\n", 18);
  rsw_sha256_update(c, rel, strlen(rel));
  rsw_sha256_update(c, "\n", 1);
}

/* Records (.scene, .params, .req, .done) end with a checksum line: "\n",
 * SUM_TAG, the lowercase hex SHA-256 of "raysweep-state-v2\n" <its name>
 * "\n" <the content before the line>, "\n". */
#define SUM_TAG "rsw-sha256 "
#define SUM_LEN (1 + sizeof SUM_TAG - 1 + 64 + 1)

static bool write_record(service *svc, const char *path, const void *head, size_t nh, const void *body,
                         size_t nb) {
  rsw_sha256_ctx c;
  unsigned char d[32];
  if (!rsw_sha256_begin(&c)) {
    errno = ENOMEM;
    return false;
  }
  identity_sha(&c, svc, path);
  rsw_sha256_update(&c, head, nh);
  rsw_sha256_update(&c, body, nb);
  if (!rsw_sha256_end(&c, d)) {
    errno = ENOMEM;
    return false;
  }
  char sum[SUM_LEN + 1], hex[65];
  rsw_hex(d, 32, hex);
  snprintf(sum, sizeof sum, "\n" SUM_TAG "%s\n", hex);
  part pt[3] = {{head, nh}, {body, nb}, {sum, SUM_LEN}};
  if (!write_parts(path, pt, 3, true)) return false;
  atomic_store(&svc->state_unwritable, false); /* it takes writes again */
  return true;
}

/* Move a file that failed its checks out of the way, to DIR/quarantine/
 * (never served, never read again), say so on stderr and count it. */
static void quarantine(service *svc, const char *path, const char *why) {
  char q[4200], dst[8500], flat[4200];
  state_path(svc, q, sizeof q, "quarantine");
  if (mkdir(q, 0700) != 0 && errno != EEXIST) {
    warn("%s: %s; cannot create %s (%s): removed instead", path, why, q, strerror(errno));
    unlink(path);
  } else {
    snprintf(flat, sizeof flat, "%s", rel_name(svc, path));
    for (char *c = flat; *c; c++)
      if (*c == '/') *c = '_';
    uint64_t r = 0;
    if (getrandom(&r, sizeof r, GRND_NONBLOCK) != (ssize_t)sizeof r) r = (uint64_t)(svc_now() * 1e6);
    snprintf(dst, sizeof dst, "%s/%s.%lld.%08" PRIx64, q, flat, (long long)time(NULL), r & 0xffffffffu);
    if (rename(path, dst) == 0) {
      warn("%s: %s; quarantined as %s", path, why, dst);
    } else {
      warn("%s: %s; cannot move it to %s (%s): removed instead", path, why, dst, strerror(errno));
      unlink(path);
    }
  }
  atomic_fetch_add(&svc->state_quarantined, 1);
}

/* The largest record read back (a scene document with its text). */
#define RECORD_MAX_BYTES ((size_t)1 << 30)

/* A whole regular file (O_NOFOLLOW|O_NONBLOCK, then fstat), NUL-terminated;
 * NULL with errno (EINVAL: not a regular file, EFBIG: too large). */
static char *read_whole(const char *path, size_t *len) {
  int fd = rsw_open_regular(path, true);
  if (fd < 0) return NULL;
  struct stat sb;
  if (fstat(fd, &sb) != 0 || sb.st_size < 0 || (uint64_t)sb.st_size > RECORD_MAX_BYTES) {
    close(fd);
    errno = EFBIG; /* (fstat of an open descriptor does not fail) */
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
    errno = p ? EIO : ENOMEM;
    return NULL;
  }
  p[n] = '\0';
  if (len) *len = n;
  return p;
}

typedef enum rec_status {
  REC_OK,
  REC_ABSENT,
  REC_LEGACY,
  REC_BAD,
  REC_TRANSIENT /* out of memory: the file is not judged */
} rec_status;

/* An open or read error that says something about the file (what it is,
 * who may read it), not about this process's resources (EMFILE, ENOMEM):
 * only those quarantine it. */
static bool file_at_fault(int err) {
  return err == ELOOP || err == EINVAL || err == EFBIG || err == EACCES || err == EPERM || err == EIO;
}

/* Check a record's text (n bytes) against its checksum line; on REC_OK
 * *content is n minus the line. REC_LEGACY: no checksum line (written by
 * the previous version). */
static rec_status record_check(const service *svc, const char *path, const char *text, size_t n,
                               size_t *content) {
  size_t tl = sizeof SUM_TAG - 1;
  if (n < SUM_LEN || text[n - SUM_LEN] != '\n' || memcmp(text + n - SUM_LEN + 1, SUM_TAG, tl) != 0 ||
      text[n - 1] != '\n')
    return REC_LEGACY;
  char hex[65];
  memcpy(hex, text + n - 65, 64);
  hex[64] = '\0';
  if (!rsw_is_sha256_hex(hex)) return REC_BAD;
  rsw_sha256_ctx c;
  unsigned char d[32];
  char mine[65];
  if (!rsw_sha256_begin(&c)) return REC_TRANSIENT;
  identity_sha(&c, svc, path);
  rsw_sha256_update(&c, text, n - SUM_LEN);
  if (!rsw_sha256_end(&c, d)) return REC_TRANSIENT;
  rsw_hex(d, 32, mine);
  if (strcmp(mine, hex) != 0) return REC_BAD;
  *content = n - SUM_LEN;
  return REC_OK;
}

/* Read a record and check it: its content (NUL-terminated, the checksum
 * line cut), or NULL when it is absent or failed a check (then it is
 * quarantined). */
static char *read_record(service *svc, const char *path, size_t *len) {
  size_t n;
  char *text = read_whole(path, &n);
  if (!text) {
    if (file_at_fault(errno)) {
      char why[200];
      snprintf(why, sizeof why, "cannot be read as a record: %s", rsw_open_strerror(errno));
      quarantine(svc, path, why);
    } else if (errno != ENOENT) {
      warn("%s: cannot be read now: %s", path, strerror(errno));
    }
    return NULL;
  }
  size_t content = n;
  rec_status rs = record_check(svc, path, text, n, &content);
  if (rs == REC_TRANSIENT) {
    warn("%s: cannot be checked now: out of memory", path);
    free(text);
    return NULL;
  }
  if (rs == REC_LEGACY && svc->state_legacy) {
    /* The previous version's record (no checksum): the restore upgrades
     * every record of a directory without DIR/format before it serves. */
    rs = REC_OK;
  }
  if (rs != REC_OK) {
    quarantine(svc, path,
               rs == REC_LEGACY ? "no checksum line (not written by this raysweepd)"
                                : "its checksum does not match its content and name");
    free(text);
    return NULL;
  }
  text[content] = '\0';
  if (len) *len = content;
  return text;
}

/* ---- trusting the directory ------------------------------------------------- */

/* A directory the daemon writes its state in must be its own: owned by
 * this user, writable by no one else; and so must be every directory
 * above it (owned by this user or root), except that one writable by
 * others is accepted with the sticky bit (as /tmp): the rules of
 * OpenSSH's StrictModes (sshd_config(5)). */
static rsw_status trust_dir(const char *dir, const char *opt, rsw_err *err) {
  char *rp = realpath(dir, NULL);
  if (!rp) return rsw_fail(err, RSW_ERR_IO, opt, "cannot resolve '%s': %s", dir, strerror(errno));
  uid_t me = geteuid();
  struct stat sb;
  rsw_status st = RSW_OK;
  if (stat(rp, &sb) != 0 || !S_ISDIR(sb.st_mode))
    st = rsw_fail(err, RSW_ERR_IO, opt, "'%s' is not a directory", rp);
  else if (sb.st_uid != me)
    st = rsw_fail(err, RSW_ERR_IO, opt, "'%s' is owned by uid %ld, not by this user (uid %ld): refused", rp,
                  (long)sb.st_uid, (long)me);
  else if (sb.st_mode & (S_IWGRP | S_IWOTH))
    st = rsw_fail(err, RSW_ERR_IO, opt,
                  "'%s' is writable by %s (mode %04o): another user could plant or change files in it; "
                  "chmod go-w it",
                  rp, (sb.st_mode & S_IWOTH) ? "others" : "its group", (unsigned)(sb.st_mode & 07777));
  for (char *slash = strrchr(rp, '/'); !st && slash; slash = strrchr(rp, '/')) {
    if (slash == rp)
      slash[1] = '\0';
    else
      *slash = '\0';
    if (stat(rp, &sb) != 0) break;
    if (sb.st_uid != me && sb.st_uid != 0)
      st = rsw_fail(err, RSW_ERR_IO, opt,
                    "'%s', above '%s', is owned by uid %ld (neither this user nor root): refused", rp, dir,
                    (long)sb.st_uid);
    else if ((sb.st_mode & (S_IWGRP | S_IWOTH)) && !(sb.st_mode & S_ISVTX))
      st = rsw_fail(err, RSW_ERR_IO, opt,
                    "'%s', above '%s', is writable by %s without the sticky bit (mode %04o): another user "
                    "could replace the directory; refused",
                    rp, dir, (sb.st_mode & S_IWOTH) ? "others" : "its group", (unsigned)(sb.st_mode & 07777));
    if (slash == rp) break;
  }
  free(rp);
  return st;
}

/* A subdirectory: created 0700, or an existing real directory (not a
 * symbolic link) of this user's that no one else can write. */
static rsw_status own_subdir(const char *p, rsw_err *err) {
  if (mkdir(p, 0700) != 0 && errno != EEXIST)
    return rsw_fail(err, RSW_ERR_IO, "--state-dir", "cannot create '%s': %s", p, strerror(errno));
  struct stat sb;
  if (lstat(p, &sb) != 0 || !S_ISDIR(sb.st_mode))
    return rsw_fail(err, RSW_ERR_IO, "--state-dir", "'%s' is not a directory (a symbolic link?): refused", p);
  if (sb.st_uid != geteuid() || (sb.st_mode & (S_IWGRP | S_IWOTH)))
    return rsw_fail(err, RSW_ERR_IO, "--state-dir",
                    "'%s' is owned by uid %ld with mode %04o: it must be this user's and writable by no one "
                    "else",
                    p, (long)sb.st_uid, (unsigned)(sb.st_mode & 07777));
  return RSW_OK;
}

#define FORMAT_LINE "raysweep-state 2\n"

static bool dir_empty(const service *svc, const char *sub) {
  char p[4200];
  state_path(svc, p, sizeof p, "%s", sub);
  DIR *d = opendir(p);
  if (!d) return true;
  bool empty = true;
  for (struct dirent *de; empty && (de = readdir(d));)
    if (strcmp(de->d_name, ".") != 0 && strcmp(de->d_name, "..") != 0) empty = false;
  closedir(d);
  return empty;
}

rsw_status svc_state_open(service *svc, rsw_err *err) {
  if (!svc_state_on(svc)) return RSW_OK;
  if (mkdir(svc->state_dir, 0700) != 0 && errno != EEXIST)
    return rsw_fail(err, RSW_ERR_IO, "--state-dir", "cannot create '%s': %s", svc->state_dir,
                    strerror(errno));
  rsw_status st = trust_dir(svc->state_dir, "--state-dir", err);
  if (st) return st;
  static const char *const sub[] = {"scenes", "jobs", "results"};
  for (size_t i = 0; i < sizeof sub / sizeof sub[0]; i++) {
    char p[4200];
    state_path(svc, p, sizeof p, "%s", sub[i]);
    if ((st = own_subdir(p, err))) return st;
  }
  char p[4200];
  state_path(svc, p, sizeof p, "lock");
  svc->state_lock_fd = open(p, O_RDWR | O_CREAT | O_NOFOLLOW | O_CLOEXEC, 0600);
  if (svc->state_lock_fd < 0)
    return rsw_fail(err, RSW_ERR_IO, "--state-dir", "cannot open '%s': %s", p, strerror(errno));
  if (flock(svc->state_lock_fd, LOCK_EX | LOCK_NB) != 0)
    return rsw_fail(err, RSW_ERR_IO, "--state-dir",
                    "state directory '%s' is in use by another raysweepd (%s is locked)", svc->state_dir, p);
  /* DIR/format: absent in a directory of the previous version (records
   * without checksums, upgraded by the restore) or a new one. */
  state_path(svc, p, sizeof p, "format");
  size_t n;
  char *f = read_whole(p, &n);
  if (!f && errno != ENOENT)
    return rsw_fail(err, RSW_ERR_IO, "--state-dir", "cannot read '%s': %s", p, rsw_open_strerror(errno));
  if (f && strcmp(f, FORMAT_LINE) != 0) {
    free(f);
    return rsw_fail(err, RSW_ERR_IO, "--state-dir",
                    "'%s' names a format this raysweepd does not know (a newer version's directory?)", p);
  }
  svc->state_legacy = !f;
  free(f);
  if (svc->state_legacy && dir_empty(svc, "scenes") && dir_empty(svc, "jobs") && dir_empty(svc, "results")) {
    /* A new directory: of this version from the start. */
    if (!svc_write_file(p, FORMAT_LINE, strlen(FORMAT_LINE)))
      return rsw_fail(err, RSW_ERR_IO, "--state-dir", "cannot write '%s': %s", p, strerror(errno));
    svc->state_legacy = false;
  }
  return RSW_OK;
}

bool svc_state_writable(service *svc, const char **why) {
  if (!svc_state_on(svc)) return true;
  pthread_mutex_lock(&svc->probe_lock);
  double now = svc_now();
  if (now - svc->state_probe_t >= 1.0 || svc->state_probe_t == 0) {
    svc->state_probe_t = now;
    /* A small file created, written, fsync'ed and removed: what a record
     * write needs, without the rename and the directory sync. */
    char p[4200], tmp[4300];
    state_path(svc, p, sizeof p, "probe");
    int inj = svc_state_fault_hook ? svc_state_fault_hook(p) : 0;
    int fd = inj ? -1 : temp_create(p, tmp, sizeof tmp);
    bool ok = fd >= 0 && write_all(fd, "probe\n", 6) && fsync(fd) == 0;
    if (fd >= 0) {
      ok = close(fd) == 0 && ok;
      unlink(tmp);
    }
    atomic_store(&svc->state_unwritable, !ok);
  }
  pthread_mutex_unlock(&svc->probe_lock);
  bool bad = atomic_load(&svc->state_unwritable);
  if (bad && why) *why = "the state directory cannot take writes (full disk, I/O error or read-only)";
  return !bad;
}

/* A state write failed: not ready until a probe succeeds; the 507. */
static rsw_status write_failed(service *svc, svc_error *e, int err, const char *what) {
  atomic_store(&svc->state_unwritable, true);
  atomic_fetch_add(&svc->state_write_failures, 1);
  return svc_fail(e, RSW_ERR_STATE_DIR, "--state-dir",
                  "cannot store %s in the state directory %s: %s; nothing was changed (retry when it takes "
                  "writes again: GET /v1/health/ready)",
                  what, svc->state_dir, strerror(err));
}

/* ---- scenes ------------------------------------------------------------------ */

rsw_status svc_state_scene_save(service *svc, const char *id, const char *doc, bool copy, bool is_xml,
                                const char *variant, const char *body, size_t len, svc_error *e) {
  if (!svc_state_on(svc)) return RSW_OK;
  char p[4200];
  state_path(svc, p, sizeof p, "scenes/%s.scene", id);
  size_t have;
  char *old = read_record(svc, p, &have); /* stored and whole already: kept */
  free(old);
  if (old) return RSW_OK;
  char head[300], other[120] = "";
  if (doc && strcmp(doc, id) != 0)
    snprintf(other, sizeof other, ",\"document\":\"%.64s\",\"copy\":%s", doc, copy ? "true" : "false");
  int nh = snprintf(head, sizeof head, "{\"format\":\"%s\",\"variant\":%s%s%s,\"id\":\"%s\"%s}\n",
                    is_xml ? "xml" : "json", variant ? "\"" : "", variant ? variant : "null",
                    variant ? "\"" : "", id, other);
  if (!write_record(svc, p, head, (size_t)nh, body, len)) {
    int err = errno;
    unlink(p); /* a rename whose directory sync failed: not acknowledged, not kept */
    return write_failed(svc, e, err, "the scene document");
  }
  return RSW_OK;
}

bool svc_state_scene_read(service *svc, const char *id, char **body, size_t *len, bool *is_xml,
                          char variant[32], cJSON **patched, uint64_t *revision, char doc[65], bool *copy) {
  if (!svc_state_on(svc) || !rsw_is_sha256_hex(id)) return false;
  char p[4200];
  state_path(svc, p, sizeof p, "scenes/%s.scene", id);
  size_t n;
  char *text = read_record(svc, p, &n);
  if (!text) return false;
  char *nl = memchr(text, '\n', n);
  cJSON *h = nl ? cJSON_ParseWithLength(text, (size_t)(nl - text)) : NULL;
  const cJSON *f = cJSON_GetObjectItemCaseSensitive(h, "format");
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(h, "variant");
  const cJSON *dc = cJSON_GetObjectItemCaseSensitive(h, "document");
  const cJSON *cp = cJSON_GetObjectItemCaseSensitive(h, "copy");
  if (!cJSON_IsString(f) || (strcmp(f->valuestring, "xml") != 0 && strcmp(f->valuestring, "json") != 0) ||
      !(cJSON_IsNull(v) || (cJSON_IsString(v) && strlen(v->valuestring) < 8)) ||
      (dc && !(cJSON_IsString(dc) && rsw_is_sha256_hex(dc->valuestring))) || (cp && !cJSON_IsBool(cp))) {
    cJSON_Delete(h);
    free(text);
    quarantine(svc, p, "no valid header line");
    return false;
  }
  *is_xml = strcmp(f->valuestring, "xml") == 0;
  variant[0] = '\0';
  if (cJSON_IsString(v)) snprintf(variant, 32, "%s", v->valuestring);
  if (doc) snprintf(doc, 65, "%s", dc ? dc->valuestring : "");
  if (copy) *copy = cJSON_IsTrue(cp);
  cJSON_Delete(h);
  size_t off = (size_t)(nl + 1 - text);
  memmove(text, text + off, n - off + 1);
  *body = text;
  *len = n - off;
  svc_state_scene_params(svc, id, patched, revision);
  return true;
}

bool svc_state_scene_params(service *svc, const char *id, cJSON **patched, uint64_t *revision) {
  *patched = NULL;
  *revision = 0;
  if (!svc_state_on(svc) || !rsw_is_sha256_hex(id)) return false;
  char p[4200];
  state_path(svc, p, sizeof p, "scenes/%s.params", id);
  char *pt = read_record(svc, p, NULL);
  if (pt) {
    cJSON *j = cJSON_Parse(pt);
    const cJSON *rev = cJSON_GetObjectItemCaseSensitive(j, "revision");
    cJSON *prm = cJSON_DetachItemFromObjectCaseSensitive(j, "params");
    /* A revision is a count of PATCHes: a whole number from 0 to 2^53. */
    if (cJSON_IsNumber(rev) && rev->valuedouble >= 0 && rev->valuedouble <= 9007199254740992.0 &&
        rev->valuedouble == floor(rev->valuedouble) && cJSON_IsObject(prm)) {
      *revision = (uint64_t)rev->valuedouble;
      *patched = prm;
    } else {
      cJSON_Delete(prm);
      quarantine(svc, p, "not a parameter record ({\"revision\": N >= 0, \"params\": {...}})");
    }
    cJSON_Delete(j);
    free(pt);
  }
  return *patched != NULL;
}

rsw_status svc_state_scene_patched(service *svc, resident *r, svc_error *e) {
  if (!svc_state_on(svc) || r->pinned || !r->patches) return RSW_OK;
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "scene", r->id);
  cJSON_AddNumberToObject(o, "revision", (double)r->revision);
  cJSON_AddItemReferenceToObject(o, "params", r->patches);
  char *s = cJSON_PrintUnformatted(o);
  cJSON_Delete(o);
  if (!s) return svc_fail(e, RSW_ERR_NOMEM, "body", "out of memory");
  char p[4200];
  state_path(svc, p, sizeof p, "scenes/%s.params", r->id);
  bool ok = write_record(svc, p, s, strlen(s), "", 0);
  int err = errno;
  free(s);
  return ok ? RSW_OK : write_failed(svc, e, err, "the scene's parameters");
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
  int ch; /* the film's channels, as the kernel counts them (12 for rgb_polarized) */
  (void)sensor_film_bytes(se, sc->variant, &ch);
  uint64_t px = (uint64_t)fm->width * (uint64_t)fm->height;
  return px * (uint64_t)ch * 4 + (se->ops->pixel_angles ? px * 16 : 0);
}

uint64_t svc_film_angle_bytes(const scene *sc, size_t sensor_index) {
  const sensor *se = sc->sensors[sensor_index];
  return se->ops->pixel_angles ? (uint64_t)se->film->width * (uint64_t)se->film->height * 16 : 0;
}

/* The channel names are static strings in a film_image. */
static const char *static_channel(const char *name) {
  return film_channel_static(name);
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
 * none), the metadata (JSON: scene, revision, context, sensor, ...), and a
 * 64-byte trailer: three little-endian uint64 lengths (npy, angles, meta),
 * the SHA-256 of "raysweep-state-v2\n" <its name> "\n" and everything
 * before the trailer, and the magic "RSWFILM2". A file whose size or
 * trailer does not add up is not a film (a write a crash cut short): the
 * render runs again. One whose checksum fails (changed, or moved from
 * another film's name) is quarantined. The previous version's films
 * ("RSWFILM1": a 32-byte trailer without the checksum) are upgraded by the
 * restore of a directory without DIR/format. */
#define FILM_MAGIC    "RSWFILM2"
#define FILM_MAGIC_V1 "RSWFILM1"
#define FILM_TRAILER  64

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

/* The SHA-256 of a film file's first n bytes, keyed by its name. */
static bool film_digest(const service *svc, const char *path, int fd, uint64_t n, unsigned char d[32]) {
  rsw_sha256_ctx c;
  if (!rsw_sha256_begin(&c)) return false;
  identity_sha(&c, svc, path);
  static _Thread_local unsigned char buf[1 << 16];
  for (uint64_t off = 0; off < n;) {
    size_t want = n - off < sizeof buf ? (size_t)(n - off) : sizeof buf;
    ssize_t r = pread(fd, buf, want, (off_t)off);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) {
      unsigned char junk[32];
      rsw_sha256_end(&c, junk);
      return false;
    }
    rsw_sha256_update(&c, buf, (size_t)r);
    off += (uint64_t)r;
  }
  return rsw_sha256_end(&c, d);
}

/* Open a film and check its trailer (and, verify, its checksum): the
 * descriptor, or -1 when absent or torn; a film that is not a regular
 * file or fails its checksum is quarantined (-1). *legacy: a version-1
 * film (accepted only while a legacy directory is being upgraded). */
static int film_open_path(service *svc, const char *p, film_trailer *t, bool verify, bool *legacy) {
  int fd = rsw_open_regular(p, true);
  if (fd < 0) {
    if (file_at_fault(errno)) {
      char why[200];
      snprintf(why, sizeof why, "cannot be read as a film: %s", rsw_open_strerror(errno));
      quarantine(svc, p, why);
    }
    return -1;
  }
  struct stat sb;
  unsigned char tr[FILM_TRAILER];
  bool v1 = false;
  const char *bad = NULL;
  if (fstat(fd, &sb) != 0 || sb.st_size < 32 || pread(fd, tr + 32, 32, sb.st_size - 32) != 32) {
    bad = "";
  } else if (memcmp(tr + 56, FILM_MAGIC_V1, 8) == 0) {
    v1 = true;
    memcpy(tr, tr + 32, 24);
    if (!svc->state_legacy) bad = "a film of the previous format in a directory already upgraded";
  } else if (memcmp(tr + 56, FILM_MAGIC, 8) != 0 || sb.st_size < FILM_TRAILER ||
             pread(fd, tr, FILM_TRAILER, sb.st_size - FILM_TRAILER) != FILM_TRAILER) {
    bad = "";
  }
  uint64_t tl = v1 ? 32 : FILM_TRAILER;
  if (!bad) {
    t->npy = get_u64(tr), t->angles = get_u64(tr + 8), t->meta = get_u64(tr + 16);
    if (t->npy < 64 || t->npy > (uint64_t)sb.st_size || t->angles > (uint64_t)sb.st_size ||
        t->meta > (1u << 20) || t->npy + t->angles + t->meta + tl != (uint64_t)sb.st_size)
      bad = "";
  }
  if (!bad && verify && !v1) {
    unsigned char d[32];
    if (!film_digest(svc, p, fd, (uint64_t)sb.st_size - FILM_TRAILER, d))
      bad = ""; /* a read error or no memory now: not judged */
    else if (memcmp(d, tr + 24, 32) != 0)
      bad = "its checksum does not match its content and name";
  }
  if (bad) {
    close(fd);
    if (bad[0]) quarantine(svc, p, bad); /* "": torn by a crash, rendered again */
    return -1;
  }
  if (legacy) *legacy = v1;
  return fd;
}

void svc_film_ref_set(svc_film_ref *ref, const job *j, size_t k) {
  memset(ref, 0, sizeof *ref);
  snprintf(ref->job, sizeof ref->job, "%s", j->id);
  ref->k = k;
  memcpy(ref->scene, j->scene_id, sizeof ref->scene);
  snprintf(ref->context, sizeof ref->context, "%s", j->items[k].context);
  snprintf(ref->sensor, sizeof ref->sensor, "%s", j->items[k].sensor);
  ref->width = j->items[k].film_w;
  ref->height = j->items[k].film_h;
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
  rsw_err derr = {0};
  if (mkdir(p, 0700) != 0 && errno != EEXIST)
    return svc_fail(e, RSW_ERR_IO, "--state-dir", "cannot create '%s': %s", p, strerror(errno));
  if (own_subdir(p, &derr) != RSW_OK) { /* a link or someone else's: never written through */
    quarantine(svc, p, derr.msg);
    if (own_subdir(p, &derr) != RSW_OK) return svc_fail(e, RSW_ERR_IO, "--state-dir", "%s", derr.msg);
  }
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
  cJSON_AddStringToObject(m, "variant", variant_name(im->variant, im->polarized));
  snprintf(num, sizeof num, "%" PRIu64, im->unresolved_rays);
  cJSON_AddStringToObject(m, "unresolved_rays", num);
  if (im->plugin_failures) { /* (absent: none; records before them had none) */
    snprintf(num, sizeof num, "%" PRIu64, im->plugin_failures);
    cJSON_AddStringToObject(m, "plugin_failures", num);
    cJSON_AddStringToObject(m, "plugin_failure", im->plugin_failure);
  }
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
  size_t total = nh + n * sizeof(float) + na + nm + FILM_TRAILER;
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
  memcpy(q + 56, FILM_MAGIC, 8);
  film_path(svc, p, sizeof p, j->id, k);
  rsw_sha256_ctx c;
  bool ok = rsw_sha256_begin(&c);
  identity_sha(&c, svc, p);
  rsw_sha256_update(&c, out, total - FILM_TRAILER);
  ok = rsw_sha256_end(&c, q + 24) && ok;
  /* The data is fsync'ed before the rename; the directory once per job
   * (svc_state_job_finished): a film whose rename a power cut loses is
   * rendered again on resume, bitwise the same. */
  part pt = {out, total};
  ok = ok && write_parts(p, &pt, 1, false);
  int saved = errno;
  free(out);
  if (!ok) return svc_fail(e, RSW_ERR_IO, "--state-dir", "cannot store the film: %s", strerror(saved));
  return RSW_OK;
}

/* A film's metadata (from its open file), every number bounds-checked
 * against the file: false when it does not describe the file. */
static bool film_meta(int fd, const film_trailer *t, svc_film *out) {
  char *ms = malloc(t->meta + 1);
  bool got = ms && read_at(fd, ms, t->meta, (off_t)(t->npy + t->angles));
  cJSON *m = got ? cJSON_ParseWithLength(ms, t->meta) : NULL;
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
  x = cJSON_GetObjectItemCaseSensitive(m, "plugin_failures");
  if (x) {
    const cJSON *msg = cJSON_GetObjectItemCaseSensitive(m, "plugin_failure");
    if (cJSON_IsString(x) && cJSON_IsString(msg)) {
      out->img.plugin_failures = strtoull(x->valuestring, NULL, 10);
      snprintf(out->img.plugin_failure, sizeof out->img.plugin_failure, "%s", msg->valuestring);
    } else {
      ok = false;
    }
  }
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
  out->img.variant = VARIANT_RGB;
  if (!cJSON_IsString(x) || !variant_parse(x->valuestring, &out->img.variant, &out->img.polarized))
    out->img.variant = VARIANT_RGB, out->img.polarized = false;
  const cJSON *ch = cJSON_GetObjectItemCaseSensitive(m, "channels");
  int c = 0;
  for (const cJSON *y = cJSON_IsArray(ch) ? ch->child : NULL; y && c < FILM_MAX_CHANNELS; y = y->next, c++) {
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
    for (const cJSON *y = ir->child; y && ki < FILM_MAX_CHANNELS; y = y->next, ki++)
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
  if (out->img.width < 1 || out->img.width > 65536 || out->img.height < 1 || out->img.height > 65536 ||
      c < 1 || t->npy < px * tc * 4 || (t->angles && t->angles != px * 16) || out->img.spp < 1)
    ok = false;
  cJSON_Delete(m);
  if (!ok) out->img.n_planes = 0;
  return ok;
}

/* Open the film ref names, check its checksum, metadata and identity:
 * the descriptor (and *out, *t), or -1 (absent, torn, or quarantined). */
static int film_open_ref(service *svc, const svc_film_ref *ref, film_trailer *t, svc_film *out) {
  char p[4200];
  film_path(svc, p, sizeof p, ref->job, ref->k);
  int fd = film_open_path(svc, p, t, true, NULL);
  if (fd < 0) return -1;
  const char *bad = NULL;
  char size_why[128];
  if (!film_meta(fd, t, out))
    bad = "its metadata does not describe it";
  else if (strcmp(out->scene, ref->scene) != 0 || strcmp(out->context, ref->context) != 0 ||
           strcmp(out->sensor, ref->sensor) != 0)
    bad = "it is another render's film (its scene, context or sensor differ from its place's)";
  else if (ref->width && (out->img.width != ref->width || out->img.height != ref->height)) {
    snprintf(size_why, sizeof size_why, "its size (%dx%d) is not its sensor's film size (%dx%d)",
             out->img.width, out->img.height, ref->width, ref->height);
    bad = size_why;
  }
  if (bad) {
    close(fd);
    char why[200];
    snprintf(why, sizeof why, "%s (render %zu of job %s)", bad, ref->k, ref->job);
    quarantine(svc, p, why);
    return -1;
  }
  return fd;
}

/* Item k's film header from its metadata (no data); false when absent or
 * when it fails a check (then quarantined). */
bool svc_state_film_header(service *svc, const svc_film_ref *ref, svc_film *out) {
  if (!svc_state_on(svc)) return false;
  film_trailer t;
  int fd = film_open_ref(svc, ref, &t, out);
  if (fd < 0) return false;
  close(fd);
  return true;
}

rsw_status svc_state_film_read(service *svc, const svc_film_ref *ref, svc_film *out, svc_error *e) {
  film_trailer t;
  int fd = svc_state_on(svc) ? film_open_ref(svc, ref, &t, out) : -1;
  if (fd < 0)
    return svc_fail(e, RSW_ERR_IO, ref->job,
                    "the stored film of render %zu of job %s is missing, unreadable or failed its check "
                    "(see the daemon's log)",
                    ref->k, ref->job);
  film_image *im = &out->img;
  size_t want = (size_t)im->width * (size_t)im->height * (size_t)im->channels * (size_t)(1 + im->n_planes);
  bool split = im->n_planes > 0; /* else all is the film's pixels */
  float *all = split ? malloc(want * sizeof(float)) : film_pixels_new(want);
  if (t.angles && all) im->angles = film_angles_new(t.angles / 16);
  bool ok = all && (!t.angles || im->angles) &&
            read_at(fd, all, want * sizeof(float), (off_t)(t.npy - want * sizeof(float))) &&
            (!t.angles || read_at(fd, im->angles, t.angles, (off_t)t.npy));
  close(fd);
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
  if (split)
    free(all);
  else
    film_pixels_unref(all);
  if (!ok) {
    film_image_free(im);
    return svc_fail(e, RSW_ERR_IO, ref->job, "cannot read the stored film of render %zu of job %s", ref->k,
                    ref->job);
  }
  return RSW_OK;
}

int svc_state_film_npy_fd(service *svc, const svc_film_ref *ref, uint64_t *len) {
  film_trailer t;
  svc_film f;
  int fd = svc_state_on(svc) ? film_open_ref(svc, ref, &t, &f) : -1;
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

rsw_status svc_state_job_saved(service *svc, const job *j, const char *body, size_t len, svc_error *e) {
  if (!svc_state_on(svc) || svc->restore_id) return RSW_OK;
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
  /* What a request without "bundle" means: "auto" since bundles became
   * the default. A record without it is older, and resumes with 1, the
   * default its films so far were rendered with. */
  cJSON_AddStringToObject(h, "bundle_default", "auto");
  char *hs = svc_print_json(h, svc_json_mark());
  if (!hs) return svc_fail(e, RSW_ERR_NOMEM, "", "out of memory");
  char p[4200];
  state_path(svc, p, sizeof p, "jobs/%s.req", j->id);
  size_t n = strlen(hs);
  hs[n] = '\n'; /* the header line */
  bool ok = write_record(svc, p, hs, n + 1, body, len);
  int err = errno;
  free(hs);
  if (ok) return RSW_OK;
  unlink(p); /* a rename whose directory sync failed: the job was not accepted */
  return write_failed(svc, e, err, "the job's request");
}

void svc_state_job_finished(service *svc, const job *j) {
  if (!svc_state_on(svc) || svc->stopping) return; /* stopping: resumed at the next start */
  cJSON *o = cJSON_CreateObject();
  cJSON_AddStringToObject(o, "id", j->id);
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
  if (j->bundle_asked) { /* what "bundle" came to, for its answers after a restart */
    cJSON_AddNumberToObject(o, "bundle", j->bundle);
    if (j->bundle_why[0]) cJSON_AddStringToObject(o, "bundle_why", j->bundle_why);
  }
  /* The warnings as they stand at the end (a render may have added one:
   * plugin_failures); the request's header holds those of submission. */
  if (j->warnings) cJSON_AddItemToObject(o, "warnings", cJSON_Duplicate(j->warnings, 1));
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
      if (im->plugin_failures) {
        cJSON_AddNumberToObject(x, "pf", (double)im->plugin_failures);
        cJSON_AddStringToObject(x, "pfm", im->plugin_failure);
      }
      cJSON_AddBoolToObject(x, "disk", it->on_disk);
    }
    cJSON_AddItemToArray(a, x);
  }
  char *s = svc_print_json(o, svc_json_mark());
  char p[4200];
  state_path(svc, p, sizeof p, "results/%s/x", j->id);
  fsync_dir(p); /* the films' renames, before the record that counts them */
  state_path(svc, p, sizeof p, "jobs/%s.done", j->id);
  if (!s || !write_record(svc, p, s, strlen(s), "", 0)) {
    warn("cannot store job %s's outcome: %s; a restart runs it again", j->id, strerror(errno));
    if (s) atomic_store(&svc->state_unwritable, true);
  }
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
  bool bundle_auto; /* "bundle_default": "auto" (a request without "bundle" means auto) */
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
  const cJSON *bd = cJSON_GetObjectItemCaseSensitive(o, "bundle_default");
  bool ok = cJSON_IsString(id) && strlen(id->valuestring) < sizeof h->id && id->valuestring[0] &&
            strspn(id->valuestring, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") ==
                strlen(id->valuestring) &&
            cJSON_IsString(sc) && rsw_is_sha256_hex(sc->valuestring) && cJSON_IsNumber(rev) &&
            rev->valuedouble >= 0 && rev->valuedouble <= 9007199254740992.0 && cJSON_IsNumber(cr) &&
            cr->valuedouble >= 0 && cr->valuedouble < 1e12;
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
    h->bundle_auto = cJSON_IsString(bd) && strcmp(bd->valuestring, "auto") == 0;
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

/* A whole number in [lo, hi] (JSON number), else false. */
static bool get_count(const cJSON *o, const char *key, double lo, double hi, uint64_t *out) {
  const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, key);
  if (!cJSON_IsNumber(x) || !(x->valuedouble >= lo && x->valuedouble <= hi) ||
      x->valuedouble != floor(x->valuedouble))
    return false;
  *out = (uint64_t)x->valuedouble;
  return true;
}

/* A string that fits in cap bytes (with its NUL), else false. */
static bool get_str(const cJSON *o, const char *key, char *dst, size_t cap) {
  const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, key);
  if (!cJSON_IsString(x) || strlen(x->valuestring) >= cap) return false;
  memcpy(dst, x->valuestring, strlen(x->valuestring) + 1);
  return true;
}

static bool known_state(const char *s) {
  for (int i = 0; i < 5; i++)
    if (s && strcmp(s, state_names[i]) == 0) return true;
  return false;
}

/* A finished job from its outcome record. Every number is checked against
 * what the job can hold (an item's context index below contexts_total,
 * film sizes within the film limits, counts within the job limits): a
 * record that breaks one is quarantined (false), never trusted. */
static bool restore_finished(service *svc, const req_header *h, cJSON *done, const char *body, size_t len,
                             const char *path, char *why, size_t wn) {
  char id[40] = "";
  const cJSON *items = cJSON_GetObjectItemCaseSensitive(done, "items");
  uint64_t n_ctx = 0, ctx_done = 0;
  const cJSON *st = cJSON_GetObjectItemCaseSensitive(done, "state");
  int n = cJSON_GetArraySize(items);
  if (!cJSON_IsObject(done) || !get_str(done, "id", id, sizeof id) || strcmp(id, h->id) != 0)
    snprintf(why, wn, "not the outcome of job %s", h->id);
  else if (!cJSON_IsString(st) || !known_state(st->valuestring))
    snprintf(why, wn, "no valid state");
  else if (!cJSON_IsArray(items) || n > SVC_MAX_JOB_RENDERS)
    snprintf(why, wn, "items is not a list of at most %d renders", SVC_MAX_JOB_RENDERS);
  else if (!get_count(done, "contexts_total", n ? 1 : 0, n, &n_ctx) ||
           !get_count(done, "contexts_done", 0, (double)n_ctx, &ctx_done))
    snprintf(why, wn,
             "contexts_total must lie in [1, %d] (the renders) and contexts_done in [0, contexts_total]", n);
  else
    why[0] = '\0';
  if (why[0]) {
    quarantine(svc, path, why);
    return false;
  }
  job *j = new_terminal_job(svc, h);
  if (!j) return true;
  svc_job_restore_labels(j, body, len); /* coords and seed, for its dataset */
  j->state = parse_state(st->valuestring);
  const cJSON *x;
  x = cJSON_GetObjectItemCaseSensitive(done, "error");
  if (cJSON_IsString(x)) snprintf(j->error, sizeof j->error, "%s", x->valuestring);
  x = cJSON_GetObjectItemCaseSensitive(done, "started_iso");
  if (cJSON_IsString(x)) snprintf(j->started_iso, sizeof j->started_iso, "%s", x->valuestring);
  x = cJSON_GetObjectItemCaseSensitive(done, "finished_iso");
  if (cJSON_IsString(x)) snprintf(j->finished_iso, sizeof j->finished_iso, "%s", x->valuestring);
  x = cJSON_GetObjectItemCaseSensitive(done, "bundle");
  if (cJSON_IsNumber(x) && x->valuedouble >= 1 && x->valuedouble <= RENDER_MAX_BUNDLE)
    j->bundle = (int)x->valuedouble, j->bundle_asked = true;
  x = cJSON_GetObjectItemCaseSensitive(done, "bundle_why");
  if (j->bundle_asked && cJSON_IsString(x))
    snprintf(j->bundle_why, sizeof j->bundle_why, "%s", x->valuestring);
  x = cJSON_GetObjectItemCaseSensitive(done, "warnings");
  if (cJSON_IsArray(x)) {
    cJSON *w = cJSON_Duplicate(x, 1);
    if (w) cJSON_Delete(j->warnings), j->warnings = w;
  }
  x = cJSON_GetObjectItemCaseSensitive(done, "seconds");
  double secs = cJSON_IsNumber(x) && x->valuedouble >= 0 && x->valuedouble < 1e9 ? x->valuedouble : 0;
  x = cJSON_GetObjectItemCaseSensitive(done, "finished");
  double age =
      cJSON_IsNumber(x) && fabs(x->valuedouble) < 1e12 ? difftime(time(NULL), (time_t)x->valuedouble) : 0;
  /* The results TTL counts from the finish, across restarts. */
  j->t_finished = svc_now() - (age > 0 ? age : 0);
  j->t_started = j->t_finished - secs;
  j->n_contexts = (size_t)n_ctx;
  j->contexts_done = (size_t)ctx_done;
  j->items = calloc(n ? (size_t)n : 1, sizeof *j->items);
  j->context_remaining = calloc(j->n_contexts ? j->n_contexts : 1, sizeof *j->context_remaining);
  if (!j->items || !j->context_remaining) {
    warn("out of memory restoring job %s", j->id);
    svc_job_free(j);
    return true;
  }
  size_t k = 0;
  for (const cJSON *it = items->child; it; it = it->next, k++) {
    render_item *ri = &j->items[k];
    j->n_items = k + 1;
    const cJSON *y;
    uint64_t ci = 0;
    y = cJSON_GetObjectItemCaseSensitive(it, "st");
    if (!cJSON_IsObject(it) || !get_str(it, "c", ri->context, sizeof ri->context) ||
        !get_str(it, "s", ri->sensor, sizeof ri->sensor) || !get_count(it, "ci", 0, (double)n_ctx - 1, &ci) ||
        !cJSON_IsString(y) || !known_state(y->valuestring)) {
      snprintf(why, wn,
               "render %zu: needs c and s (strings), ci (an integer below contexts_total = %" PRIu64
               ") and st",
               k, n_ctx);
      break;
    }
    ri->context_index = (size_t)ci;
    ri->state = parse_state(y->valuestring);
    y = cJSON_GetObjectItemCaseSensitive(it, "w");
    ri->wavelength = cJSON_IsString(y) ? strtod(y->valuestring, NULL) : 0;
    if (!(ri->wavelength >= 0 && ri->wavelength < 1e9)) ri->wavelength = 0;
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
      uint64_t spp = 0, w = 0, hh = 0, unres = 0;
      if (!get_count(it, "spp", 1, 4294967295.0, &spp) || !get_count(it, "W", 1, 65536, &w) ||
          !get_count(it, "H", 1, 65536, &hh) ||
          (cJSON_GetObjectItemCaseSensitive(it, "unres") && !get_count(it, "unres", 0, 1.8e19, &unres))) {
        snprintf(why, wn, "render %zu: spp, W and H must be whole numbers in range", k);
        break;
      }
      im->spp = (uint32_t)spp;
      im->width = (int)w;
      im->height = (int)hh;
      ri->film_w = (int)w;
      ri->film_h = (int)hh;
      im->unresolved_rays = unres;
      uint64_t pf = 0;
      if (cJSON_GetObjectItemCaseSensitive(it, "pf") &&
          (!get_count(it, "pf", 0, 1.8e19, &pf) ||
           !get_str(it, "pfm", im->plugin_failure, sizeof im->plugin_failure))) {
        snprintf(why, wn, "render %zu: pf must be a whole number and pfm a string", k);
        break;
      }
      im->plugin_failures = pf;
      y = cJSON_GetObjectItemCaseSensitive(it, "ch");
      int c = 0;
      for (const cJSON *z = cJSON_IsArray(y) ? y->child : NULL; z && c < FILM_MAX_CHANNELS; z = z->next)
        if (cJSON_IsString(z) && static_channel(z->valuestring))
          im->channel_names[c++] = static_channel(z->valuestring);
      im->channels = c;
      y = cJSON_GetObjectItemCaseSensitive(it, "pl");
      for (const cJSON *z = cJSON_IsArray(y) ? y->child : NULL; z && im->n_planes < FILM_MAX_PLANES;
           z = z->next)
        if (cJSON_IsString(z) && film_plane_known(z->valuestring))
          film_plane_init(im, z->valuestring, &im->planes[im->n_planes++]);
      ri->on_disk = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(it, "disk"));
      memcpy(ri->film.scene, h->scene, 65);
      ri->film.revision = h->revision;
      snprintf(ri->film.context, sizeof ri->film.context, "%s", ri->context);
      snprintf(ri->film.sensor, sizeof ri->film.sensor, "%s", ri->sensor);
      svc_film_ref ref;
      svc_film hdr;
      svc_film_ref_set(&ref, j, k);
      const char *lost = NULL;
      if (!ri->on_disk) /* kept in memory only (its write failed): gone */
        lost = "the film was not stored on disk and was lost in a restart";
      else if (!svc_state_film_header(svc, &ref, &hdr))
        lost = "the stored film is missing or failed its check (quarantined; see the daemon's log)";
      if (lost) {
        ri->state = JOB_FAILED;
        ri->on_disk = false;
        snprintf(ri->error, sizeof ri->error, "%s", lost);
        j->items_failed++;
      }
    }
  }
  if (!why[0] && k != (size_t)n) snprintf(why, wn, "items changed while read");
  if (j->coords.n && j->coords.n_contexts != j->n_contexts) { /* the request's contexts are not these */
    nc_coords_free(&j->coords);
    memset(&j->coords, 0, sizeof j->coords);
  }
  if (why[0]) {
    svc_job_free(j);
    quarantine(svc, path, why);
    return false;
  }
  register_terminal(svc, j);
  return true;
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
  svc->restore_bundle_default = h->bundle_auto ? 0 : 1;
  rsw_status st = service_job_submit(svc, h->scene, body, len, h->has_idem ? h->idem : NULL, &jid, &json, &e);
  svc->restore_id = NULL;
  svc->restore_bundle_default = 0;
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
    svc_film_ref ref;
    svc_film_ref_set(&ref, j, k);
    if (!svc_state_film_header(svc, &ref, &f)) continue;
    it->film = f;
    it->seed = f.img.seed; /* its bundle's, as item_done records it */
    it->on_disk = true;
    it->state = JOB_SUCCEEDED;
    j->items_done++;
    if (--j->context_remaining[it->context_index] == 0) j->contexts_done++;
  }
}

static int cmp_names(const void *a, const void *b) {
  return strcmp(*(char *const *)a, *(char *const *)b);
}

/* ---- the previous version's directory -------------------------------------- */

static bool ends_with(const char *s, const char *suffix) {
  size_t l = strlen(s), ls = strlen(suffix);
  return l >= ls && strcmp(s + l - ls, suffix) == 0;
}

/* A record without its checksum line gets one (its content unchanged). */
static void upgrade_record(service *svc, const char *path) {
  size_t n, content;
  char *text = read_whole(path, &n);
  if (!text) {
    if (file_at_fault(errno)) quarantine(svc, path, "cannot be read as a record");
    return;
  }
  rec_status rs = record_check(svc, path, text, n, &content);
  if (rs == REC_LEGACY && !write_record(svc, path, text, n, "", 0))
    warn("%s: cannot add its checksum: %s; it is upgraded at the next start", path, strerror(errno));
  else if (rs == REC_BAD)
    quarantine(svc, path, "its checksum does not match its content and name");
  free(text);
}

/* A version-1 film gets the version-2 trailer (its bytes unchanged). */
static void upgrade_film(service *svc, const char *path) {
  film_trailer t;
  bool legacy = false;
  int fd = film_open_path(svc, path, &t, false, &legacy);
  if (fd < 0) return;
  uint64_t body = t.npy + t.angles + t.meta;
  unsigned char *buf = legacy && body <= ((uint64_t)1 << 40) ? malloc((size_t)body + FILM_TRAILER) : NULL;
  bool ok = buf && read_at(fd, buf, (size_t)body, 0);
  close(fd);
  if (!legacy) return;
  if (ok) {
    unsigned char *q = buf + body;
    put_u64(q, t.npy), put_u64(q + 8, t.angles), put_u64(q + 16, t.meta);
    memcpy(q + 56, FILM_MAGIC, 8);
    rsw_sha256_ctx c;
    ok = rsw_sha256_begin(&c);
    identity_sha(&c, svc, path);
    rsw_sha256_update(&c, buf, (size_t)body);
    ok = rsw_sha256_end(&c, q + 24) && ok;
    part pt = {buf, (size_t)body + FILM_TRAILER};
    ok = ok && write_parts(path, &pt, 1, true);
  }
  if (!ok) warn("%s: cannot upgrade the film: %s; it is upgraded at the next start", path, strerror(errno));
  free(buf);
}

/* Every regular entry of DIR/sub whose name ends in one of the suffixes
 * (a temporary file a crash left is removed). */
static void each_file(service *svc, const char *sub, void (*fn)(service *, const char *),
                      const char *const *suffixes) {
  char dir[4200];
  state_path(svc, dir, sizeof dir, "%s", sub);
  DIR *d = opendir(dir);
  if (!d) return;
  for (struct dirent *de; (de = readdir(d));) {
    char p[4600];
    snprintf(p, sizeof p, "%s/%s", dir, de->d_name);
    if (strstr(de->d_name, ".tmp.") || ends_with(de->d_name, ".tmp")) {
      unlink(p);
      continue;
    }
    for (const char *const *s = suffixes; fn && *s; s++)
      if (ends_with(de->d_name, *s)) {
        fn(svc, p);
        break;
      }
  }
  closedir(d);
}

/* Every directory of records and films, each file given to fn (NULL: only
 * the temporary files a crash left are removed). */
static void each_state_file(service *svc, void (*rec)(service *, const char *),
                            void (*on_film)(service *, const char *)) {
  static const char *const scene_sfx[] = {".scene", ".params", NULL};
  static const char *const job_sfx[] = {".req", ".done", NULL};
  static const char *const film_sfx[] = {".film", NULL};
  each_file(svc, "scenes", rec, scene_sfx);
  each_file(svc, "jobs", rec, job_sfx);
  char p[4200];
  state_path(svc, p, sizeof p, "results");
  DIR *d = opendir(p);
  for (struct dirent *de; d && (de = readdir(d));) {
    char sub[400], q[4600];
    struct stat sb;
    snprintf(sub, sizeof sub, "results/%s", de->d_name);
    snprintf(q, sizeof q, "%s/%s", p, de->d_name);
    if (de->d_name[0] == '.' || lstat(q, &sb) != 0 || !S_ISDIR(sb.st_mode)) continue;
    each_file(svc, sub, on_film, film_sfx);
  }
  if (d) closedir(d);
}

/* The previous version's directory (no DIR/format): every record gets its
 * checksum line and every film the version-2 trailer, before anything is
 * read or served; then DIR/format says so, and from then on a record or
 * film without a checksum is quarantined. (The previous version wrote the
 * same content: an upgrade trusts what the directory holds, once.) */
static void upgrade_legacy(service *svc) {
  each_state_file(svc, upgrade_record, upgrade_film);
  char p[4200];
  state_path(svc, p, sizeof p, "format");
  if (svc_write_file(p, FORMAT_LINE, strlen(FORMAT_LINE)))
    svc->state_legacy = false;
  else
    warn("cannot write %s: %s; records without checksums stay accepted until it can be", p, strerror(errno));
}

void svc_state_restore(service *svc) {
  if (!svc_state_on(svc)) return;
  double t0 = svc_now();
  if (svc->state_legacy)
    upgrade_legacy(svc);
  else
    each_state_file(svc, NULL, NULL); /* temporary files a crash left */
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
    char *text = read_record(svc, p, &len);
    req_header h;
    if (!text) continue; /* quarantined (or gone) */
    if (!parse_req(text, len, &h, &off) || strcmp(h.id, names[i]) != 0) {
      free(text);
      quarantine(svc, p, "not the request record of the job its name says");
      continue;
    }
    unsigned long long num;
    if (sscanf(h.id, "job-%*8[0-9a-f]-%llu", &num) == 1 && num > svc->next_job && num < (1ull << 53))
      svc->next_job = num;
    state_path(svc, p, sizeof p, "jobs/%s.done", h.id);
    char *dt = read_record(svc, p, NULL);
    cJSON *done = dt ? cJSON_Parse(dt) : NULL;
    if (dt && !done) quarantine(svc, p, "not JSON");
    free(dt);
    char why[300] = "";
    /* An outcome record that failed its checks: the job runs again from
     * its request, as one a crash interrupted. */
    if (!done || !restore_finished(svc, &h, done, text + off, len - off, p, why, sizeof why))
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
