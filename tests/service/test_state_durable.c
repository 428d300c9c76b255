/* The state directory acknowledges only what is durable and trusts only
 * what proves itself (issue 22, items 1 and 2; docs/state.md#robustness-the-state-directory),
 * in process, with a restart being service_free + service_new on the same
 * directory:
 *  - a full disk (the state writer's test hook fails every write with
 *    ENOSPC) makes a PATCH, a job and a scene post answer 507
 *    RSW_ERR_STATE_DIR naming the directory, with nothing changed (the
 *    scene renders bitwise as before), and the service not ready until the
 *    directory takes writes again; a restart shows exactly what was
 *    acknowledged;
 *  - a state directory writable by group or others, owned by another user
 *    or under a directory others can write without the sticky bit is
 *    refused;
 *  - symbolic links planted at a temporary name or at a record's name are
 *    never written through;
 *  - a FIFO in place of a film answers an error at once (never a hang);
 *  - films swapped with each other are quarantined, never served;
 *  - a job record whose item index reaches past its context count (the
 *    GET .../dataset crash) is quarantined and the job runs again;
 *  - a FIFO or a link out of the root under --data-root, and a FIFO in the
 *    blob directory, are refused (RSW_ERR_FILE, 422) without blocking;
 *  - records of the previous version (no checksum) are upgraded once, in a
 *    directory without DIR/format; in an upgraded one they are quarantined;
 *  - a job without "bundle" renders with auto, and one recorded before that
 *    default resumes with 1.
 * Every test runs under alarm(): a hang is a failure, not a stuck run. */
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cjson/cJSON.h>

#include "../../server/service/service.h"
#include "../../server/service/service_internal.h"
#include "../support/test.h"
#include "rsw_sha256.h"

RSW_TEST_DEFINE_GLOBALS

static const char *PLATE_FMT =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.0},"
    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": %g}}}";

static const char *JOB2 = "{\"contexts\": [{\"id\": \"c0\", \"wavelength\": 500}, {\"id\": \"c1\", "
                          "\"wavelength\": 600}], \"defaults\": {\"spp\": 4}}";

/* The fault hook: every write under the state directory fails with
 * fail_errno while it is non-zero. */
static int fail_errno;
static char hook_dir[256];
static int hook(const char *path) {
  return fail_errno && strncmp(path, hook_dir, strlen(hook_dir)) == 0 ? fail_errno : 0;
}

static void mkstate(char *dir, size_t n) {
  snprintf(dir, n, "/tmp/rsw-durable-XXXXXX");
  if (!mkdtemp(dir)) {
    perror("mkdtemp");
    exit(1);
  }
}

static void rmtree(const char *dir) {
  char cmd[600];
  snprintf(cmd, sizeof cmd, "chmod -R u+rwx '%s' 2>/dev/null; rm -rf '%s'", dir, dir);
  if (system(cmd) != 0) fprintf(stderr, "cannot remove %s\n", dir);
}

static service *open_svc(const char *dir, const char *data_root) {
  service *svc = NULL;
  rsw_err err = {0};
  service_opts o = {.size = sizeof o,
                    .render_threads = 1,
                    .state_dir = dir,
                    .data_root = data_root,
                    .max_result_bytes = 1}; /* every film to disk */
  if (service_new(&o, &svc, &err) != RSW_OK) {
    fprintf(stderr, "service_new(%s): %s\n", dir, err.msg);
    return NULL;
  }
  service_restore(svc);
  return svc;
}

static rsw_status post_doc(service *svc, const char *doc, char **id, svc_error *e) {
  bool created;
  char *json = NULL;
  *id = NULL;
  rsw_status st = service_scene_post(svc, doc, strlen(doc), false, NULL, &created, id, &json, e);
  free(json);
  return st;
}

static char *post(service *svc, double rho) {
  char doc[1024];
  snprintf(doc, sizeof doc, PLATE_FMT, rho);
  char *id;
  svc_error e = {0};
  return post_doc(svc, doc, &id, &e) == RSW_OK ? id : NULL;
}

static rsw_status patch(service *svc, const char *id, double rho, svc_error *e) {
  char body[200];
  snprintf(body, sizeof body, "{\"plate.bsdf.reflectance.value\": %g}", rho);
  char *json = NULL;
  uint64_t rev;
  rsw_status st = service_params_patch(svc, id, body, strlen(body), -1, &json, &rev, e);
  free(json);
  return st;
}

static uint64_t revision_of(service *svc, const char *id) {
  char *json = NULL;
  uint64_t rev = UINT64_MAX;
  svc_error e = {0};
  if (service_params_get(svc, id, NULL, NULL, &json, &rev, &e) != RSW_OK) rev = UINT64_MAX;
  free(json);
  return rev;
}

/* The scene's 1x1 film now. */
static bool render(service *svc, const char *id, float out[1]) {
  svc_film f = {0};
  svc_error e = {0};
  const char *body = "{\"spp\": 16, \"seed\": 7}";
  if (service_render(svc, id, body, strlen(body), NULL, &f, &e) != RSW_OK) return false;
  bool ok = f.img.width == 1 && f.img.height == 1 && f.img.channels == 1;
  if (ok) memcpy(out, f.img.data, sizeof(float));
  svc_film_free(&f);
  return ok;
}

static char *submit(service *svc, const char *scene_id, svc_error *e) {
  char *jid = NULL, *json = NULL;
  rsw_status st = service_job_submit(svc, scene_id, JOB2, strlen(JOB2), NULL, &jid, &json, e);
  free(json);
  if (st) {
    free(jid);
    return NULL;
  }
  return jid;
}

static char *job_state_of(service *svc, const char *jid) {
  char *json = NULL;
  svc_error e = {0};
  if (service_job_get(svc, jid, &json, &e) != RSW_OK) return NULL;
  cJSON *j = cJSON_Parse(json);
  free(json);
  const cJSON *s = cJSON_GetObjectItemCaseSensitive(j, "state");
  char *out = cJSON_IsString(s) ? strdup(s->valuestring) : NULL;
  cJSON_Delete(j);
  return out;
}

static char *wait_job(service *svc, const char *jid) {
  for (int i = 0; i < 2000; i++) {
    char *s = job_state_of(svc, jid);
    if (!s || (strcmp(s, "queued") != 0 && strcmp(s, "running") != 0)) return s;
    free(s);
    usleep(5000);
  }
  return NULL;
}

static int count_jobs(service *svc) {
  char *json = NULL;
  svc_error e = {0};
  if (service_job_list(svc, &json, &e) != RSW_OK) return -1;
  cJSON *j = cJSON_Parse(json);
  free(json);
  const cJSON *a = cJSON_IsArray(j) ? j : cJSON_GetObjectItemCaseSensitive(j, "jobs");
  int n = cJSON_GetArraySize(a);
  cJSON_Delete(j);
  return n;
}

static int count_files(const char *dir, const char *suffix) {
  char cmd[600];
  snprintf(cmd, sizeof cmd, "ls '%s' 2>/dev/null | grep -c -- '%s$'", dir, suffix);
  FILE *p = popen(cmd, "r");
  int n = -1;
  if (p) {
    if (fscanf(p, "%d", &n) != 1) n = -1;
    pclose(p);
  }
  return n;
}

static unsigned long long metric(service *svc, const char *name) {
  char *text = service_metrics_text(svc);
  unsigned long long v = ~0ull;
  char key[128];
  snprintf(key, sizeof key, "\n%s ", name);
  const char *at = text ? strstr(text, key) : NULL;
  if (at) v = strtoull(at + strlen(key), NULL, 10);
  free(text);
  return v;
}

/* ---- 1. a full disk --------------------------------------------------------- */

static void test_full_disk(void) {
  alarm(120);
  char dir[64];
  mkstate(dir, sizeof dir);
  snprintf(hook_dir, sizeof hook_dir, "%s", dir);
  svc_state_fault_hook = hook;
  service *svc = open_svc(dir, NULL);
  REQUIRE(svc, "service");
  char *id = post(svc, 0.5);
  REQUIRE(id, "post");
  svc_error e = {0};
  CHECK(patch(svc, id, 0.3, &e) == RSW_OK, "PATCH acknowledged: %s", e.err.msg);
  uint64_t acked = revision_of(svc, id);
  CHECK(acked == 1, "revision 1 after one PATCH: %llu", (unsigned long long)acked);
  float before[1], after[1];
  REQUIRE(render(svc, id, before), "render");
  char *j1 = submit(svc, id, &e);
  CHECK(j1 != NULL, "a job acknowledged: %s", e.err.msg);
  char *w1 = j1 ? wait_job(svc, j1) : NULL;
  CHECK(w1 && strcmp(w1, "succeeded") == 0, "the acknowledged job succeeds: %s", w1 ? w1 : "?");
  free(w1);

  fail_errno = ENOSPC; /* the disk is full */
  svc_error ep = {0};
  rsw_status st = patch(svc, id, 0.7, &ep);
  CHECK(st == RSW_ERR_STATE_DIR && rsw_status_http(st) == 507, "PATCH on a full disk: %s (%s)",
        rsw_status_name(st), ep.err.msg);
  CHECK(strstr(ep.err.msg, dir) != NULL, "the 507 names the state directory: %s", ep.err.msg);
  CHECK(revision_of(svc, id) == acked, "the scene stays at revision %llu", (unsigned long long)acked);
  CHECK(render(svc, id, after) && memcmp(before, after, sizeof before) == 0,
        "the scene renders bitwise as before the refused PATCH");
  int jobs = count_jobs(svc);
  svc_error ej = {0};
  char *j2 = submit(svc, id, &ej);
  CHECK(!j2 && ej.err.code == RSW_ERR_STATE_DIR, "a job on a full disk: %s (%s)",
        rsw_status_name(ej.err.code), ej.err.msg);
  CHECK(count_jobs(svc) == jobs, "the refused job is not listed (%d jobs, was %d)", count_jobs(svc), jobs);
  char doc[1024];
  snprintf(doc, sizeof doc, PLATE_FMT, 0.9);
  char *id9 = NULL;
  svc_error es = {0};
  CHECK(post_doc(svc, doc, &id9, &es) == RSW_ERR_STATE_DIR, "a scene post on a full disk: %s (%s)",
        rsw_status_name(es.err.code), es.err.msg);
  free(id9);
  const char *why = NULL;
  svc->state_probe_t = 0; /* no wait for the once-a-second probe */
  CHECK(!service_accepts_jobs(svc, &why) && why && strstr(why, "state directory"),
        "not ready while the directory cannot take writes: %s", why ? why : "(ready)");
  CHECK(metric(svc, "raysweep_state_writable") == 0, "raysweep_state_writable 0");
  CHECK(metric(svc, "raysweep_state_write_failures_total") >= 3, "write failures counted");

  fail_errno = 0; /* space again */
  svc->state_probe_t = 0;
  why = NULL;
  CHECK(service_accepts_jobs(svc, &why), "ready again once it takes writes: %s", why ? why : "");
  service_free(svc);

  /* A restart: the acknowledged state, nothing more. */
  svc = open_svc(dir, NULL);
  REQUIRE(svc, "restart");
  CHECK(revision_of(svc, id) == acked, "after a restart the scene is at the acknowledged revision: %llu",
        (unsigned long long)revision_of(svc, id));
  CHECK(render(svc, id, after) && memcmp(before, after, sizeof before) == 0,
        "after a restart it renders bitwise as acknowledged");
  char *s1 = j1 ? job_state_of(svc, j1) : NULL;
  CHECK(s1 && strcmp(s1, "succeeded") == 0, "the acknowledged job exists after a restart: %s",
        s1 ? s1 : "404");
  free(s1);
  CHECK(count_jobs(svc) == 1, "and no other: %d", count_jobs(svc));
  char p[300];
  snprintf(p, sizeof p, "%s/scenes", dir);
  CHECK(count_files(p, ".scene") == 1, "the refused scene was not kept: %d documents",
        count_files(p, ".scene"));
  /* EIO and EROFS are refused the same way. */
  fail_errno = EROFS;
  svc_error e2 = {0};
  CHECK(patch(svc, id, 0.1, &e2) == RSW_ERR_STATE_DIR && revision_of(svc, id) == acked,
        "EROFS: 507, nothing changed (%s)", e2.err.msg);
  fail_errno = 0;
  service_free(svc);
  svc_state_fault_hook = NULL;
  free(j1);
  free(id);
  rmtree(dir);
  alarm(0);
}

/* ---- 2. trust ------------------------------------------------------------------ */

static bool refused(const char *dir, const char *want) {
  service *svc = NULL;
  rsw_err err = {0};
  service_opts o = {.size = sizeof o, .render_threads = 1, .state_dir = dir};
  rsw_status st = service_new(&o, &svc, &err);
  if (svc) service_free(svc);
  if (st == RSW_OK) return false;
  if (!strstr(err.msg, want)) fprintf(stderr, "  (refused, but: %s)\n", err.msg);
  return strstr(err.msg, want) != NULL;
}

static void test_trust(void) {
  alarm(60);
  char dir[64], sub[128];
  mkstate(dir, sizeof dir);
  snprintf(sub, sizeof sub, "%s/state", dir);
  REQUIRE(mkdir(sub, 0700) == 0, "mkdir");
  REQUIRE(chmod(sub, 0777) == 0, "chmod");
  CHECK(refused(sub, "writable by others"), "a world-writable state directory is refused");
  chmod(sub, 0770);
  CHECK(refused(sub, "writable by its group"), "a group-writable state directory is refused");
  chmod(sub, 0700);
  chmod(dir, 0777); /* the parent: others can replace the directory */
  CHECK(refused(sub, "without the sticky bit"),
        "under a world-writable parent without the sticky bit: refused");
  chmod(dir, 01777); /* as /tmp */
  service *svc = open_svc(sub, NULL);
  CHECK(svc != NULL, "under a world-writable parent with the sticky bit: accepted");
  struct stat sb;
  char p[300];
  snprintf(p, sizeof p, "%s/jobs", sub);
  CHECK(stat(p, &sb) == 0 && (sb.st_mode & 0777) == 0700, "subdirectories are created 0700: %o",
        (unsigned)(sb.st_mode & 0777));
  service_free(svc);
  chmod(dir, 0700);
  if (geteuid() == 0) { /* only root can give a directory away */
    CHECK(chown(sub, 65534, 65534) == 0, "chown");
    CHECK(refused(sub, "owned by uid 65534"), "a state directory another user owns is refused");
    CHECK(chown(sub, 0, 0) == 0, "chown back");
  }
  /* A subdirectory replaced by a symbolic link: refused. */
  snprintf(p, sizeof p, "%s/results", sub);
  CHECK(system("true") == 0 && rmdir(p) == 0 && symlink("/tmp", p) == 0, "plant results -> /tmp");
  CHECK(refused(sub, "not a directory"), "a subdirectory that is a symbolic link is refused");
  rmtree(dir);
  alarm(0);
}

/* ---- 3. planted links ---------------------------------------------------------- */

static void test_planted_links(void) {
  alarm(60);
  char dir[64];
  mkstate(dir, sizeof dir);
  char victim[128], p[400];
  snprintf(victim, sizeof victim, "%s/victim", dir);
  FILE *f = fopen(victim, "w");
  REQUIRE(f, "victim");
  fputs("precious\n", f);
  fclose(f);
  char sd[128];
  snprintf(sd, sizeof sd, "%s/st", dir);
  service *svc = open_svc(sd, NULL);
  REQUIRE(svc, "service");
  char *id = post(svc, 0.5);
  REQUIRE(id, "post");
  /* The next job id is predictable (GET /v1 gives the instance): links
   * at the names the previous version used, and at the record's own. */
  char next[40];
  snprintf(next, sizeof next, "job-%.8s-%06llu", svc->instance, (unsigned long long)svc->next_job + 1);
  snprintf(p, sizeof p, "%s/results/%s", sd, next);
  REQUIRE(mkdir(p, 0700) == 0, "mkdir %s", p);
  snprintf(p, sizeof p, "%s/results/%s/0.film.tmp", sd, next);
  CHECK(symlink(victim, p) == 0, "plant %s", p);
  snprintf(p, sizeof p, "%s/results/%s/0.film", sd, next);
  CHECK(symlink(victim, p) == 0, "plant %s", p);
  snprintf(p, sizeof p, "%s/jobs/%s.done", sd, next);
  CHECK(symlink(victim, p) == 0, "plant %s", p);
  /* And the next job's film directory as a link to the victim's. */
  char next2[40], vdir[200];
  snprintf(next2, sizeof next2, "job-%.8s-%06llu", svc->instance, (unsigned long long)svc->next_job + 2);
  snprintf(vdir, sizeof vdir, "%s/vdir", dir);
  REQUIRE(mkdir(vdir, 0700) == 0, "mkdir %s", vdir);
  snprintf(p, sizeof p, "%s/results/%s", sd, next2);
  CHECK(symlink(vdir, p) == 0, "plant %s", p);
  svc_error e = {0};
  char *jid = submit(svc, id, &e);
  REQUIRE(jid && strcmp(jid, next) == 0, "the job took the predicted id %s: %s", next, jid ? jid : e.err.msg);
  char *jid2 = submit(svc, id, &e);
  REQUIRE(jid2 && strcmp(jid2, next2) == 0, "the job took the predicted id %s", next2);
  char *s2 = wait_job(svc, jid2);
  CHECK(s2 && strcmp(s2, "succeeded") == 0, "the second job succeeds: %s", s2 ? s2 : "?");
  free(s2);
  CHECK(count_files(vdir, "film") == 0, "nothing written through the directory link: %d files",
        count_files(vdir, "film"));
  free(jid2);
  char *s = wait_job(svc, jid);
  CHECK(s && strcmp(s, "succeeded") == 0, "the job succeeds: %s", s ? s : "?");
  free(s);
  char buf[64] = "";
  f = fopen(victim, "r");
  CHECK(f && fgets(buf, sizeof buf, f) && strcmp(buf, "precious\n") == 0, "the victim is untouched: '%s'",
        buf);
  if (f) fclose(f);
  struct stat sb;
  snprintf(p, sizeof p, "%s/results/%s/0.film", sd, next);
  CHECK(lstat(p, &sb) == 0 && S_ISREG(sb.st_mode), "the film is a regular file in the state directory");
  svc_film fm = {0};
  svc_error er = {0};
  CHECK(service_job_result(svc, jid, "c0", "meter", &fm, &er) == RSW_OK, "its film is served: %s",
        er.err.msg);
  svc_film_free(&fm);
  service_free(svc);
  free(jid);
  free(id);
  rmtree(dir);
  alarm(0);
}

/* A finished two-context job with its films on disk; *svc_out stays open. */
static char *finished_job(const char *sd, service **svc_out, char **scene_out) {
  service *svc = open_svc(sd, NULL);
  if (!svc) return NULL;
  char *id = post(svc, 0.5);
  svc_error e = {0};
  char *jid = id ? submit(svc, id, &e) : NULL;
  char *s = jid ? wait_job(svc, jid) : NULL;
  bool ok = s && strcmp(s, "succeeded") == 0;
  free(s);
  *svc_out = svc;
  *scene_out = id;
  if (!ok) {
    free(jid);
    return NULL;
  }
  return jid;
}

/* ---- 4. a FIFO in place of a film ----------------------------------------------- */

static void test_fifo_film(void) {
  alarm(60); /* a blocking open would hang here: SIGALRM ends the test */
  char dir[64];
  mkstate(dir, sizeof dir);
  service *svc;
  char *sid;
  char *jid = finished_job(dir, &svc, &sid);
  REQUIRE(jid, "a finished job");
  char p[400];
  snprintf(p, sizeof p, "%s/results/%s/0.film", dir, jid);
  REQUIRE(unlink(p) == 0 && mkfifo(p, 0600) == 0, "a FIFO in place of film 0");
  svc_film fm = {0};
  svc_error e = {0};
  CHECK(service_job_result(svc, jid, "c0", "meter", &fm, &e) != RSW_OK, "GET the result: an error");
  svc_film_free(&fm);
  int fd = -1;
  uint64_t len = 0;
  svc_error e2 = {0};
  CHECK(service_job_result_npy_fd(svc, jid, "c0", "meter", &fd, &len, &e2) == RSW_OK && fd < 0,
        "no descriptor to stream from");
  if (fd >= 0) close(fd);
  void *bytes = NULL;
  size_t n = 0;
  svc_error e3 = {0};
  CHECK(service_job_dataset(svc, jid, false, &bytes, &n, &e3) != RSW_OK, "the dataset: an error, not a hang");
  free(bytes);
  struct stat sb;
  CHECK(lstat(p, &sb) != 0, "the FIFO was moved to quarantine");
  CHECK(metric(svc, "raysweep_state_quarantined_total") >= 1, "and counted");
  service_free(svc);
  free(jid);
  free(sid);
  rmtree(dir);
  alarm(0);
}

/* ---- 5. swapped films ---------------------------------------------------------- */

static void test_swapped_films(void) {
  alarm(60);
  char dir[64];
  mkstate(dir, sizeof dir);
  service *svc;
  char *sid;
  char *jid = finished_job(dir, &svc, &sid);
  REQUIRE(jid, "a finished job");
  char a[400], b[400], t[400];
  snprintf(a, sizeof a, "%s/results/%s/0.film", dir, jid);
  snprintf(b, sizeof b, "%s/results/%s/1.film", dir, jid);
  snprintf(t, sizeof t, "%s/results/%s/swap", dir, jid);
  REQUIRE(rename(a, t) == 0 && rename(b, a) == 0 && rename(t, b) == 0, "swap the two films");
  /* While it runs: every read checks. */
  svc_film fm = {0};
  svc_error e = {0};
  CHECK(service_job_result(svc, jid, "c0", "meter", &fm, &e) != RSW_OK,
        "c0's place holds c1's film: not served (%s)", e.err.msg);
  svc_film_free(&fm);
  CHECK(metric(svc, "raysweep_state_quarantined_total") == 1, "quarantined and counted: %llu",
        metric(svc, "raysweep_state_quarantined_total"));
  service_free(svc);
  /* A restart checks too: the other one is quarantined on restore. */
  svc = open_svc(dir, NULL);
  REQUIRE(svc, "restart");
  memset(&fm, 0, sizeof fm);
  svc_error e2 = {0};
  CHECK(service_job_result(svc, jid, "c1", "meter", &fm, &e2) != RSW_OK, "c1: not served either");
  svc_film_free(&fm);
  CHECK(metric(svc, "raysweep_state_quarantined_total") == 1, "the restore quarantined the second one");
  char q[300];
  snprintf(q, sizeof q, "%s/quarantine", dir);
  CHECK(count_files(q, "") == 2, "both are in %s: %d", q, count_files(q, ""));
  service_free(svc);
  free(jid);
  free(sid);
  rmtree(dir);
  alarm(0);
}

/* ---- 6. out-of-bounds numbers in a record ---------------------------------------- */

/* Rewrite a record with a valid checksum (as someone who knows the format
 * would): the bounds checks must hold on their own. */
static bool rewrite_record(const char *dir, const char *rel, const char *content) {
  char p[600], hex[65];
  snprintf(p, sizeof p, "%s/%s", dir, rel);
  rsw_sha256_ctx c;
  unsigned char d[32];
  if (!rsw_sha256_begin(&c)) return false;
  rsw_sha256_update(&c, "raysweep-state-v2\n", 18);
  rsw_sha256_update(&c, rel, strlen(rel));
  rsw_sha256_update(&c, "\n", 1);
  rsw_sha256_update(&c, content, strlen(content));
  if (!rsw_sha256_end(&c, d)) return false;
  rsw_hex(d, 32, hex);
  FILE *f = fopen(p, "w");
  if (!f) return false;
  fprintf(f, "%s\nrsw-sha256 %s\n", content, hex);
  return fclose(f) == 0;
}

/* A record's content (the checksum line cut). */
static char *record_content(const char *dir, const char *rel) {
  char p[600];
  snprintf(p, sizeof p, "%s/%s", dir, rel);
  FILE *f = fopen(p, "r");
  if (!f) return NULL;
  char *buf = calloc(1, 1 << 20);
  size_t n = buf ? fread(buf, 1, (1 << 20) - 1, f) : 0;
  fclose(f);
  if (buf && n > 77) buf[n - 77] = '\0';
  return buf;
}

static void test_record_bounds(void) {
  alarm(120);
  char dir[64];
  mkstate(dir, sizeof dir);
  service *svc;
  char *sid;
  char *jid = finished_job(dir, &svc, &sid);
  REQUIRE(jid, "a finished job");
  service_free(svc);
  char rel[200];
  snprintf(rel, sizeof rel, "jobs/%s.done", jid);
  char *content = record_content(dir, rel);
  cJSON *d = content ? cJSON_Parse(content) : NULL;
  free(content);
  REQUIRE(d, "the outcome record parses");
  cJSON *items = cJSON_GetObjectItemCaseSensitive(d, "items");
  cJSON *it1 = cJSON_GetArrayItem(items, 1);
  REQUIRE(it1 && cJSON_GetObjectItemCaseSensitive(it1, "ci"), "item 1 has ci");
  cJSON_ReplaceItemInObjectCaseSensitive(it1, "ci", cJSON_CreateNumber(5)); /* contexts_total is 2 */
  char *bad = cJSON_PrintUnformatted(d);
  cJSON_Delete(d);
  REQUIRE(bad && rewrite_record(dir, rel, bad), "rewrite the record with ci = 5");
  free(bad);
  svc = open_svc(dir, NULL);
  REQUIRE(svc, "restart");
  CHECK(metric(svc, "raysweep_state_quarantined_total") == 1, "the record is quarantined: %llu",
        metric(svc, "raysweep_state_quarantined_total"));
  char *s = wait_job(svc, jid);
  CHECK(s && strcmp(s, "succeeded") == 0, "the job runs again from its request: %s", s ? s : "404");
  free(s);
  void *bytes = NULL;
  size_t n = 0;
  svc_error e = {0};
  CHECK(service_job_dataset(svc, jid, false, &bytes, &n, &e) == RSW_OK && n > 0,
        "GET .../dataset answers (it crashed on ci >= contexts_total): %s", e.err.msg);
  free(bytes);
  service_free(svc);
  /* Other numbers out of range: each quarantined, none trusted. */
  static const char *const edits[][2] = {{"contexts_total", "1e300"}, {"contexts_done", "-1"}, {"W", "1e9"}};
  for (size_t k = 0; k < sizeof edits / sizeof edits[0]; k++) {
    content = record_content(dir, rel);
    d = content ? cJSON_Parse(content) : NULL;
    free(content);
    REQUIRE(d, "the outcome record parses (%zu)", k);
    cJSON *target =
        strcmp(edits[k][0], "W") == 0 ? cJSON_GetArrayItem(cJSON_GetObjectItem(d, "items"), 0) : d;
    cJSON_ReplaceItemInObjectCaseSensitive(target, edits[k][0],
                                           cJSON_CreateNumber(strtod(edits[k][1], NULL)));
    bad = cJSON_PrintUnformatted(d);
    cJSON_Delete(d);
    REQUIRE(bad && rewrite_record(dir, rel, bad), "rewrite");
    free(bad);
    svc = open_svc(dir, NULL);
    REQUIRE(svc, "restart");
    CHECK(metric(svc, "raysweep_state_quarantined_total") == 1, "%s = %s: quarantined", edits[k][0],
          edits[k][1]);
    s = wait_job(svc, jid);
    CHECK(s && strcmp(s, "succeeded") == 0, "%s = %s: the job runs again: %s", edits[k][0], edits[k][1],
          s ? s : "404");
    free(s);
    service_free(svc);
  }
  free(jid);
  free(sid);
  rmtree(dir);
  alarm(0);
}

/* ---- 7. --data-root and the blob directory ------------------------------------ */

static void test_data_root(void) {
  alarm(60); /* a blocking open of the FIFO would hang here */
  char dir[64], root[128], p[400], doc[1024];
  mkstate(dir, sizeof dir);
  snprintf(root, sizeof root, "%s/root", dir);
  REQUIRE(mkdir(root, 0700) == 0, "mkdir root");
  snprintf(p, sizeof p, "%s/fifo.obj", root);
  REQUIRE(mkfifo(p, 0600) == 0, "mkfifo");
  snprintf(p, sizeof p, "%s/out.obj", root);
  REQUIRE(symlink("/etc/hostname", p) == 0, "a link out of the root");
  snprintf(p, sizeof p, "%s/in.obj", root);
  REQUIRE(symlink("fifo.obj", p) == 0, "a link to the FIFO inside the root");
  char sd[128];
  snprintf(sd, sizeof sd, "%s/st", dir);
  service *svc = open_svc(sd, root);
  REQUIRE(svc, "service");
  static const char *const names[] = {"fifo.obj", "out.obj", "in.obj"};
  for (size_t i = 0; i < 3; i++) {
    snprintf(doc, sizeof doc,
             "{\"type\": \"scene\", \"meter\": {\"type\": \"distant\", \"film\": {\"type\": \"hdrfilm\", "
             "\"width\": 1, \"height\": 1}}, \"m\": {\"type\": \"obj\", \"filename\": \"%s\"}}",
             names[i]);
    char *id = NULL;
    svc_error e = {0};
    rsw_status st = post_doc(svc, doc, &id, &e);
    CHECK(st == RSW_ERR_FILE && rsw_status_http(st) == 422, "a scene naming %s: %s (%s)", names[i],
          rsw_status_name(st), e.err.msg);
    free(id);
  }
  /* A FIFO in the blob directory under a blob's name. */
  const char *h = "2d1fd2d3d4b7c1ebbe5b4e3b77c3b1dc0a8b1a1f4b9b0cf6de3be1a8b0f2fa4c";
  snprintf(p, sizeof p, "%s/blobs/%s", sd, h);
  REQUIRE(mkfifo(p, 0600) == 0, "mkfifo blob");
  snprintf(doc, sizeof doc,
           "{\"type\": \"scene\", \"meter\": {\"type\": \"distant\", \"film\": {\"type\": \"hdrfilm\", "
           "\"width\": 1, \"height\": 1}}, \"m\": {\"type\": \"obj\", \"filename\": \"sha256:%s\"}}",
           h);
  char *id = NULL;
  svc_error e = {0};
  CHECK(post_doc(svc, doc, &id, &e) == RSW_ERR_FILE, "a scene naming a FIFO blob: %s (%s)",
        rsw_status_name(e.err.code), e.err.msg);
  free(id);
  service_free(svc);
  rmtree(dir);
  alarm(0);
}

/* ---- 8. the previous version's records ------------------------------------------ */

/* Cut the checksum line off a record, as the previous version wrote it. */
static bool strip(const char *dir, const char *rel) {
  char *c = record_content(dir, rel);
  char p[600];
  snprintf(p, sizeof p, "%s/%s", dir, rel);
  FILE *f = c ? fopen(p, "w") : NULL;
  bool ok = f && fputs(c, f) >= 0;
  if (f) ok = fclose(f) == 0 && ok;
  free(c);
  return ok;
}

static void test_legacy(void) {
  alarm(60);
  char dir[64];
  mkstate(dir, sizeof dir);
  service *svc = open_svc(dir, NULL);
  REQUIRE(svc, "service");
  char *id = post(svc, 0.5);
  svc_error e = {0};
  REQUIRE(id && patch(svc, id, 0.25, &e) == RSW_OK, "post and PATCH");
  service_free(svc);
  char rel[200], p[400];
  snprintf(rel, sizeof rel, "scenes/%s.scene", id);
  CHECK(strip(dir, rel), "strip %s", rel);
  snprintf(rel, sizeof rel, "scenes/%s.params", id);
  CHECK(strip(dir, rel), "strip %s", rel);
  /* In an upgraded directory (DIR/format) a record without a checksum is
   * quarantined. */
  svc = open_svc(dir, NULL);
  REQUIRE(svc, "restart");
  CHECK(revision_of(svc, id) == UINT64_MAX, "a record without its checksum is not trusted");
  CHECK(metric(svc, "raysweep_state_quarantined_total") == 1, "quarantined: %llu",
        metric(svc, "raysweep_state_quarantined_total"));
  service_free(svc);
  rmtree(dir);
  /* In the previous version's directory (no DIR/format) it is upgraded. */
  mkstate(dir, sizeof dir);
  svc = open_svc(dir, NULL);
  REQUIRE(svc, "service");
  free(id);
  id = post(svc, 0.5);
  REQUIRE(id && patch(svc, id, 0.25, &e) == RSW_OK, "post and PATCH");
  service_free(svc);
  snprintf(rel, sizeof rel, "scenes/%s.scene", id);
  CHECK(strip(dir, rel), "strip %s", rel);
  snprintf(rel, sizeof rel, "scenes/%s.params", id);
  CHECK(strip(dir, rel), "strip %s", rel);
  snprintf(p, sizeof p, "%s/format", dir);
  CHECK(unlink(p) == 0, "remove DIR/format");
  svc = open_svc(dir, NULL);
  REQUIRE(svc, "restart");
  CHECK(revision_of(svc, id) == 1, "the upgraded scene reloads at its revision: %llu",
        (unsigned long long)revision_of(svc, id));
  struct stat sb;
  CHECK(stat(p, &sb) == 0, "DIR/format is written");
  char *c = record_content(dir, rel);
  CHECK(c && strstr(c, "\"revision\":1") && c[0] == '{', "the record now has its checksum line: %s",
        c ? c : "");
  free(c);
  service_free(svc);
  free(id);
  rmtree(dir);
  /* A film of the previous version (a 32-byte trailer without checksum):
   * upgraded, and served bitwise as before. */
  mkstate(dir, sizeof dir);
  char *sid;
  char *jid = finished_job(dir, &svc, &sid);
  REQUIRE(jid, "a finished job");
  svc_film before = {0};
  CHECK(service_job_result(svc, jid, "c1", "meter", &before, &e) == RSW_OK, "c1: %s", e.err.msg);
  service_free(svc);
  snprintf(p, sizeof p, "%s/results/%s/1.film", dir, jid);
  FILE *f = fopen(p, "rb");
  REQUIRE(f, "open %s", p);
  static unsigned char buf[1 << 16];
  size_t n = fread(buf, 1, sizeof buf, f);
  fclose(f);
  REQUIRE(n > 64 && n < sizeof buf && memcmp(buf + n - 8, "RSWFILM2", 8) == 0, "a version-2 film");
  memmove(buf + n - 64 + 24, "RSWFILM1", 8); /* lengths stay, the checksum goes */
  f = fopen(p, "wb");
  REQUIRE(f && fwrite(buf, 1, n - 32, f) == n - 32 && fclose(f) == 0, "write the version-1 film");
  snprintf(rel, sizeof rel, "jobs/%s.done", jid);
  CHECK(strip(dir, rel), "strip %s", rel);
  snprintf(rel, sizeof rel, "jobs/%s.req", jid);
  CHECK(strip(dir, rel), "strip %s", rel);
  snprintf(p, sizeof p, "%s/format", dir);
  CHECK(unlink(p) == 0, "remove DIR/format");
  svc = open_svc(dir, NULL);
  REQUIRE(svc, "restart");
  svc_film after = {0};
  e = (svc_error){0};
  CHECK(service_job_result(svc, jid, "c1", "meter", &after, &e) == RSW_OK && before.img.data &&
            after.img.data && memcmp(before.img.data, after.img.data, sizeof(float)) == 0,
        "the upgraded film is served bitwise as before: %s", e.err.msg);
  CHECK(metric(svc, "raysweep_state_quarantined_total") == 0, "nothing quarantined");
  svc_film_free(&before);
  svc_film_free(&after);
  service_free(svc);
  free(jid);
  free(sid);
  rmtree(dir);
  alarm(0);
}

/* ---- 9. a job recorded before "bundle": "auto" became the default --------------- */

/* The job's answer's "bundle": what it came to, 0 when absent, -1 when
 * the job is not there. */
static int bundle_of(service *svc, const char *jid) {
  char *json = NULL;
  svc_error e = {0};
  if (service_job_get(svc, jid, &json, &e) != RSW_OK) return -1;
  cJSON *j = cJSON_Parse(json);
  free(json);
  const cJSON *b = cJSON_GetObjectItemCaseSensitive(j, "bundle");
  int k = cJSON_IsNumber(b) ? (int)b->valuedouble : 0;
  cJSON_Delete(j);
  return k;
}

/* A request recorded without "bundle" renders with "auto" and says so in
 * its header; one whose record predates that (no "bundle_default") resumes
 * with 1, the setting its films so far were rendered with. */
static void test_bundle_default(void) {
  alarm(60);
  char dir[64], rel[200], p[400];
  mkstate(dir, sizeof dir);
  service *svc;
  char *sid;
  char *jid = finished_job(dir, &svc, &sid); /* JOB2 names no bundle */
  REQUIRE(jid, "a finished job");
  CHECK(bundle_of(svc, jid) == 16, "a job without bundle came to auto's 16: %d", bundle_of(svc, jid));
  service_free(svc);
  snprintf(rel, sizeof rel, "jobs/%s.req", jid);
  char *c = record_content(dir, rel);
  const char *mark = ",\"bundle_default\":\"auto\"";
  char *at = c ? strstr(c, mark) : NULL;
  CHECK(at && at < strchr(c, '\n'), "the request's header says what no bundle means: %.300s", c ? c : "");
  /* The previous version's directory: no DIR/format, records without
   * checksum or "bundle_default", the job interrupted before it finished. */
  if (at) memmove(at, at + strlen(mark), strlen(at + strlen(mark)) + 1);
  snprintf(p, sizeof p, "%s/%s", dir, rel);
  FILE *f = c ? fopen(p, "w") : NULL;
  CHECK(f && fputs(c, f) >= 0 && fclose(f) == 0, "rewrite %s", rel);
  free(c);
  snprintf(p, sizeof p, "%s/jobs/%s.done", dir, jid);
  CHECK(unlink(p) == 0, "remove the job's outcome");
  snprintf(p, sizeof p, "%s/results/%s", dir, jid);
  rmtree(p);
  snprintf(p, sizeof p, "%s/format", dir);
  CHECK(unlink(p) == 0, "remove DIR/format");
  svc = open_svc(dir, NULL);
  REQUIRE(svc, "restart");
  char *s = wait_job(svc, jid);
  CHECK(s && strcmp(s, "succeeded") == 0, "the old job resumed and finished: %s", s ? s : "(gone)");
  free(s);
  CHECK(bundle_of(svc, jid) == 0, "it rendered with 1, as recorded: its answer has no bundle (%d)",
        bundle_of(svc, jid));
  svc_error e = {0};
  char *j2 = submit(svc, sid, &e);
  s = j2 ? wait_job(svc, j2) : NULL;
  CHECK(s && strcmp(s, "succeeded") == 0 && bundle_of(svc, j2) == 16,
        "a new job without bundle, after the restart: auto (%d)", j2 ? bundle_of(svc, j2) : -1);
  free(s);
  free(j2);
  service_free(svc);
  free(jid);
  free(sid);
  rmtree(dir);
  alarm(0);
}

int main(void) {
  signal(SIGPIPE, SIG_IGN);
  RSW_TEST_RUN(test_full_disk);
  RSW_TEST_RUN(test_trust);
  RSW_TEST_RUN(test_planted_links);
  RSW_TEST_RUN(test_fifo_film);
  RSW_TEST_RUN(test_swapped_films);
  RSW_TEST_RUN(test_record_bounds);
  RSW_TEST_RUN(test_data_root);
  RSW_TEST_RUN(test_legacy);
  RSW_TEST_RUN(test_bundle_default);
  RSW_TEST_END("test_state_durable");
}
