/* State-directory restore (server/service/state.c): a service starts on a
 * state directory one of whose files the input replaced, and everything
 * it restored is read back. The directory is a template made once per
 * process: the harness scene posted and PATCHed (scenes/<id>.scene,
 * .params), a finished job of 2 contexts x 2 sensors with its films on
 * disk (jobs/<id>.req, .done, results/<id>/<k>.film) and an interrupted
 * one (a .req without .done: resumed on restore).
 *
 * Input: byte 0 picks the file (modulo the template's count), byte 1 the
 * mode (modulo 3), the rest is the file's new content:
 *   0  raw: the bytes as they are (checksums fail: quarantined);
 *   1  signed: the harness adds the checksum line of a record, or the
 *      version-2 trailer of a film (the first 8 bytes are then the
 *      little-endian uint32 lengths of the .npy part and the angles part,
 *      the metadata is what follows them), so that the input reaches the
 *      parsers and bounds checks behind the checksum;
 *   2  raw in the previous version's directory (no DIR/format: records
 *      without a checksum line are accepted and upgraded).
 * Invariants: no crash, no sanitizer report, no hang (libFuzzer's
 * -timeout); every error has a message; a result served has the context
 * and sensor it was asked for and the size its job says.
 * `FUZZ_STATE_SEEDS=DIR fuzz_state_restore` writes one signed seed per
 * template file (the template's own content) into DIR. */
#include <dirent.h>
#include <fcntl.h>
#include <ftw.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cjson/cJSON.h>

#include "../../server/service/service.h"
#include "../../server/service/service_internal.h"
#include "fuzz.h"
#include "rsw_sha256.h"

#define MAX_FILES 32

static struct tfile {
  char rel[300];
  uint8_t *data;
  size_t len;
} files[MAX_FILES];
static int n_files;
static char template_dir[64], work_dir[80];
static char scene_id[72];

static int rm_entry(const char *path, const struct stat *st, int flag, struct FTW *ftw) {
  (void)st, (void)flag, (void)ftw;
  remove(path);
  return 0;
}

static void cleanup(void) {
  if (template_dir[0]) nftw(template_dir, rm_entry, 8, FTW_DEPTH | FTW_PHYS);
  if (work_dir[0]) nftw(work_dir, rm_entry, 8, FTW_DEPTH | FTW_PHYS);
}

static service *start(const char *dir) {
  service_opts so = {.size = sizeof so,
                     .render_threads = 1,
                     .state_dir = dir,
                     .max_queue = 4,
                     .max_result_bytes = 1, /* every film to disk */
                     .max_pixel_samples = 256,
                     .max_body_bytes = 1 << 20};
  service *svc = NULL;
  rsw_err err = {0};
  FUZZ_CHECK(service_new(&so, &svc, &err) == RSW_OK, "service_new(%s): %s", dir, err.msg);
  return svc;
}

static void load_file(const char *rel) {
  FUZZ_CHECK(n_files < MAX_FILES, "too many template files");
  struct tfile *t = &files[n_files++];
  snprintf(t->rel, sizeof t->rel, "%s", rel);
  char p[400];
  snprintf(p, sizeof p, "%s/%s", template_dir, t->rel);
  FILE *f = fopen(p, "rb");
  FUZZ_CHECK(f, "open %s", p);
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  t->data = malloc((size_t)n + 1);
  FUZZ_CHECK(t->data && fread(t->data, 1, (size_t)n, f) == (size_t)n, "read %s", p);
  t->len = (size_t)n;
  fclose(f);
}

static int cmp_rel(const void *a, const void *b) {
  return strcmp(((const struct tfile *)a)->rel, ((const struct tfile *)b)->rel);
}

static void load_dir(const char *sub) {
  char p[300];
  snprintf(p, sizeof p, "%s/%s", template_dir, sub);
  DIR *d = opendir(p);
  FUZZ_CHECK(d, "opendir %s", p);
  for (struct dirent *de; (de = readdir(d));) {
    if (de->d_name[0] == '.') continue;
    char rel[260], q[600];
    snprintf(rel, sizeof rel, "%s/%s", sub, de->d_name);
    snprintf(q, sizeof q, "%s/%s", template_dir, rel);
    struct stat sb;
    if (stat(q, &sb) == 0 && S_ISDIR(sb.st_mode))
      load_dir(rel);
    else
      load_file(rel);
  }
  closedir(d);
}

static void wait_end(service *svc, const char *jid) {
  uint64_t after = 0;
  bool end = false;
  for (int i = 0; !end && i < 300; i++) {
    uint64_t seq = 0;
    char *ev = NULL;
    svc_error e = {0};
    FUZZ_CHECK(service_job_next_event(svc, jid, after, 100, &seq, &ev, &end, &e) == RSW_OK, "events");
    if (ev) after = seq;
    free(ev);
  }
  FUZZ_CHECK(end, "the template job did not end");
}

static const char JOB[] =
    "{\"contexts\": [{\"id\": \"a\", \"wavelength\": 500}, {\"id\": \"b\", \"wavelength\": "
    "600, \"coords\": {}}], \"defaults\": {\"spp\": 1}, \"seed\": 3}";

static void make_template(void) {
  /* In memory where there is a tmpfs: the restore fsyncs what it rewrites. */
  struct stat sb;
  const char *base = stat("/dev/shm", &sb) == 0 && S_ISDIR(sb.st_mode) && access("/dev/shm", W_OK) == 0
                         ? "/dev/shm"
                         : "/tmp";
  snprintf(template_dir, sizeof template_dir, "%s/rsw-fuzz-st-XXXXXX", base);
  FUZZ_CHECK(mkdtemp(template_dir), "mkdtemp");
  snprintf(work_dir, sizeof work_dir, "%s.w", template_dir);
  atexit(cleanup);
  service *svc = start(template_dir);
  snprintf(svc->instance, sizeof svc->instance, "f0f0f0f0f0f0f0f0"); /* job ids the seeds can name */
  char *id = NULL;
  svc_error e = {0};
  FUZZ_CHECK(service_scene_load_text(svc, fuzz_scene_json, sizeof fuzz_scene_json - 1, false, "fuzz.json",
                                     &id, &e) == RSW_OK,
             "scene: %s", e.err.msg);
  service_free(svc); /* a startup scene is not stored: post it */
  svc = start(template_dir);
  snprintf(svc->instance, sizeof svc->instance, "f0f0f0f0f0f0f0f0");
  bool created;
  char *json = NULL;
  free(id);
  id = NULL;
  FUZZ_CHECK(service_scene_post(svc, fuzz_scene_json, sizeof fuzz_scene_json - 1, false, NULL, &created, &id,
                                &json, &e) == RSW_OK,
             "post: %s", e.err.msg);
  free(json);
  snprintf(scene_id, sizeof scene_id, "%s", id);
  const char *patch = "{\"sun.irradiance.value\": 2.5}";
  uint64_t rev;
  json = NULL;
  FUZZ_CHECK(service_params_patch(svc, id, patch, strlen(patch), -1, &json, &rev, &e) == RSW_OK, "patch: %s",
             e.err.msg);
  free(json);
  char *jid[2] = {NULL, NULL};
  for (int k = 0; k < 2; k++) {
    json = NULL;
    FUZZ_CHECK(service_job_submit(svc, id, JOB, sizeof JOB - 1, NULL, &jid[k], &json, &e) == RSW_OK,
               "job: %s", e.err.msg);
    free(json);
    wait_end(svc, jid[k]);
  }
  service_free(svc);
  /* The second job as a crash left it: its request, no outcome, one film. */
  char p[400];
  snprintf(p, sizeof p, "%s/jobs/%s.done", template_dir, jid[1]);
  unlink(p);
  for (int k = 1; k < 4; k++) {
    snprintf(p, sizeof p, "%s/results/%s/%d.film", template_dir, jid[1], k);
    unlink(p);
  }
  free(jid[0]);
  free(jid[1]);
  free(id);
  load_dir("scenes");
  load_dir("jobs");
  load_dir("results");
  qsort(files, (size_t)n_files, sizeof files[0], cmp_rel);
}

static bool ends_with(const char *s, const char *suffix) {
  size_t l = strlen(s), n = strlen(suffix);
  return l >= n && strcmp(s + l - n, suffix) == 0;
}

static void identity(rsw_sha256_ctx *c, const char *rel) {
  rsw_sha256_update(c, "raysweep-state-v2\n", 18);
  rsw_sha256_update(c, rel, strlen(rel));
  rsw_sha256_update(c, "\n", 1);
}

static void put_u64(uint8_t *p, uint64_t v) {
  for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}

/* content -> the file a writer that knows the format would make of it. */
static uint8_t *sign(const char *rel, const uint8_t *content, size_t n, size_t *out_len) {
  rsw_sha256_ctx c;
  unsigned char d[32];
  if (ends_with(rel, ".film")) {
    if (n < 8) return NULL;
    uint32_t npy = (uint32_t)content[0] | (uint32_t)content[1] << 8 | (uint32_t)content[2] << 16 |
                   (uint32_t)content[3] << 24;
    uint32_t ang = (uint32_t)content[4] | (uint32_t)content[5] << 8 | (uint32_t)content[6] << 16 |
                   (uint32_t)content[7] << 24;
    size_t body = n - 8;
    if (npy > body) npy = (uint32_t)body;
    if (ang > body - npy) ang = (uint32_t)(body - npy);
    uint8_t *o = malloc(body + 64);
    if (!o) return NULL;
    memcpy(o, content + 8, body);
    put_u64(o + body, npy), put_u64(o + body + 8, ang), put_u64(o + body + 16, body - npy - ang);
    rsw_sha256_begin(&c);
    identity(&c, rel);
    rsw_sha256_update(&c, o, body);
    rsw_sha256_end(&c, o + body + 24);
    memcpy(o + body + 56, "RSWFILM2", 8);
    *out_len = body + 64;
    return o;
  }
  rsw_sha256_begin(&c);
  identity(&c, rel);
  rsw_sha256_update(&c, content, n);
  rsw_sha256_end(&c, d);
  char hex[65];
  rsw_hex(d, 32, hex);
  uint8_t *o = malloc(n + 78); /* the line and snprintf's NUL */
  if (!o) return NULL;
  memcpy(o, content, n);
  snprintf((char *)o + n, 78, "\nrsw-sha256 %s\n", hex);
  *out_len = n + 77;
  return o;
}

/* A template file's content as mode 1 takes it (the inverse of sign). */
static uint8_t *unsign(const struct tfile *t, size_t *out_len) {
  if (ends_with(t->rel, ".film")) {
    if (t->len < 64) return NULL;
    const uint8_t *tr = t->data + t->len - 64;
    uint64_t npy = 0, ang = 0;
    for (int i = 0; i < 8; i++) npy |= (uint64_t)tr[i] << (8 * i), ang |= (uint64_t)tr[8 + i] << (8 * i);
    size_t body = t->len - 64;
    uint8_t *o = malloc(body + 8);
    if (!o) return NULL;
    for (int i = 0; i < 4; i++) o[i] = (uint8_t)(npy >> (8 * i)), o[4 + i] = (uint8_t)(ang >> (8 * i));
    memcpy(o + 8, t->data, body);
    *out_len = body + 8;
    return o;
  }
  if (t->len < 77) return NULL;
  uint8_t *o = malloc(t->len - 77 + 1);
  if (!o) return NULL;
  memcpy(o, t->data, t->len - 77);
  *out_len = t->len - 77;
  return o;
}

static void write_file(const char *rel, const uint8_t *data, size_t len) {
  char p[400];
  snprintf(p, sizeof p, "%s/%s", work_dir, rel);
  char dir[400];
  snprintf(dir, sizeof dir, "%s", p);
  char *slash = strrchr(dir, '/');
  *slash = '\0';
  mkdir(dir, 0700);
  int fd = open(p, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  FUZZ_CHECK(fd >= 0, "create %s", p);
  FUZZ_CHECK(len == 0 || write(fd, data, len) == (ssize_t)len, "write %s", p);
  close(fd);
}

static void write_seeds(const char *dir) {
  for (int i = 0; i < n_files; i++) {
    size_t n;
    uint8_t *c = unsign(&files[i], &n);
    if (!c) continue;
    char p[600];
    snprintf(p, sizeof p, "%s/seed_%s", dir, files[i].rel);
    for (char *q = p + strlen(dir) + 1; *q; q++)
      if (*q == '/') *q = '_';
    FILE *f = fopen(p, "wb");
    FUZZ_CHECK(f, "create %s", p);
    fputc(i, f);
    fputc(1, f);
    fwrite(c, 1, n, f);
    fclose(f);
    free(c);
  }
}

int LLVMFuzzerInitialize(int *argc, char ***argv) {
  (void)argc;
  (void)argv;
  make_template();
  const char *seeds = getenv("FUZZ_STATE_SEEDS");
  if (seeds) {
    write_seeds(seeds);
    exit(0);
  }
  return 0;
}

/* Read back everything the restored service knows. */
static void exercise(service *svc) {
  char *json = NULL;
  svc_error e = {0};
  rsw_status st = service_job_list(svc, &json, &e);
  FUZZ_CHECK(st == RSW_OK, "job list: %s", e.err.msg);
  cJSON *list = cJSON_Parse(json);
  free(json);
  const cJSON *jobs = cJSON_IsArray(list) ? list : cJSON_GetObjectItemCaseSensitive(list, "jobs");
  for (const cJSON *j = jobs ? jobs->child : NULL; j; j = j->next) {
    const cJSON *idj = cJSON_GetObjectItemCaseSensitive(j, "id");
    if (!cJSON_IsString(idj)) continue;
    const char *jid = idj->valuestring;
    e = (svc_error){0};
    json = NULL;
    st = service_job_results(svc, jid, &json, &e);
    FUZZ_CHECK(st == RSW_OK || e.err.msg[0], "results of %s failed without a message", jid);
    cJSON *res = st == RSW_OK ? cJSON_Parse(json) : NULL;
    free(json);
    const cJSON *items = cJSON_GetObjectItemCaseSensitive(res, "results");
    if (!items) items = cJSON_IsArray(res) ? res : NULL;
    for (const cJSON *it = items ? items->child : NULL; it; it = it->next) {
      const cJSON *c = cJSON_GetObjectItemCaseSensitive(it, "context");
      const cJSON *s = cJSON_GetObjectItemCaseSensitive(it, "sensor");
      if (!cJSON_IsString(c) || !cJSON_IsString(s)) continue;
      svc_film f = {0};
      e = (svc_error){0};
      st = service_job_result(svc, jid, c->valuestring, s->valuestring, &f, &e);
      FUZZ_CHECK(st == RSW_OK || e.err.msg[0], "a result failed without a message");
      if (st == RSW_OK) {
        FUZZ_CHECK(strcmp(f.context, c->valuestring) == 0 && strcmp(f.sensor, s->valuestring) == 0,
                   "asked for %s/%s, served %s/%s", c->valuestring, s->valuestring, f.context, f.sensor);
        int side = strcmp(f.sensor, "hd") == 0 ? 4 : 2; /* fuzz.h's scene: hd 4x4, cam 2x2 */
        FUZZ_CHECK(f.img.width == side && f.img.height == side, "a served film of %s of %dx%d pixels",
                   f.sensor, f.img.width, f.img.height);
      }
      svc_film_free(&f);
      int fd = -1;
      uint64_t len = 0;
      e = (svc_error){0};
      st = service_job_result_npy_fd(svc, jid, c->valuestring, s->valuestring, &fd, &len, &e);
      if (fd >= 0) {
        char buf[4096];
        uint64_t got = 0;
        ssize_t r;
        while (got < len && (r = read(fd, buf, sizeof buf)) > 0) got += (uint64_t)r;
        FUZZ_CHECK(got >= len, "the .npy stream is shorter (%llu) than announced (%llu)",
                   (unsigned long long)got, (unsigned long long)len);
        close(fd);
      }
    }
    cJSON_Delete(res);
    void *nc = NULL;
    size_t nc_len = 0;
    e = (svc_error){0};
    st = service_job_dataset(svc, jid, true, &nc, &nc_len, &e);
    FUZZ_CHECK(st == RSW_OK || e.err.msg[0], "the dataset of %s failed without a message", jid);
    free(nc);
  }
  cJSON_Delete(list);
  json = NULL;
  uint64_t rev = 0;
  e = (svc_error){0};
  st = service_params_get(svc, scene_id, NULL, NULL, &json, &rev, &e); /* reloads the scene */
  FUZZ_CHECK(st == RSW_OK || e.err.msg[0], "GET params failed without a message");
  free(json);
  free(service_metrics_text(svc));
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size < 2 || size > FUZZ_MAX_INPUT || n_files == 0) return 0;
  int target = data[0] % n_files, mode = data[1] % 3;
  nftw(work_dir, rm_entry, 8, FTW_DEPTH | FTW_PHYS);
  FUZZ_CHECK(mkdir(work_dir, 0700) == 0, "mkdir %s", work_dir);
  static const char *const subs[] = {"scenes", "jobs", "results"};
  for (int i = 0; i < 3; i++) {
    char p[200];
    snprintf(p, sizeof p, "%s/%s", work_dir, subs[i]);
    mkdir(p, 0700);
  }
  if (mode != 2) write_file("format", (const uint8_t *)"raysweep-state 2\n", 17);
  for (int i = 0; i < n_files; i++) {
    if (i != target) {
      write_file(files[i].rel, files[i].data, files[i].len);
      continue;
    }
    size_t n = size - 2;
    uint8_t *signed_ = mode == 1 ? sign(files[i].rel, data + 2, size - 2, &n) : NULL;
    write_file(files[i].rel, signed_ ? signed_ : data + 2, signed_ ? n : size - 2);
    free(signed_);
  }
  service *svc = start(work_dir);
  service_restore(svc);
  exercise(svc);
  service_free(svc);
  return 0;
}
