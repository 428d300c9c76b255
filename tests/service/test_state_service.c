/* The service's durable state and memory budget in process (the daemon's
 * side is tests/integration/test_state.sh):
 *  - without a blob directory the service's temporary one is removed by
 *    service_free (it used to stay in /tmp with every uploaded blob);
 *  - eviction under max_scene_bytes picks the least recently used idle
 *    scene and never one an in-flight request holds;
 *  - a state directory is locked: a second service on it is refused. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../server/service/service.h"
#include "../../server/service/service_internal.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

static const char *PLATE_FMT =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.0},"
    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": %g}}}";

static char *post(service *svc, double rho) {
  char doc[1024];
  snprintf(doc, sizeof doc, PLATE_FMT, rho);
  bool created;
  char *id = NULL, *json = NULL;
  svc_error e = {0};
  if (service_scene_post(svc, doc, strlen(doc), false, NULL, &created, &id, &json, &e)) return NULL;
  free(json);
  return id;
}

static void test_temp_blob_dir_removed(void) {
  service *svc = NULL;
  rsw_err err = {0};
  service_opts o = {.size = sizeof o, .render_threads = 1};
  REQUIRE(service_new(&o, &svc, &err) == RSW_OK, "service_new: %s", err.msg);
  char dir[4096];
  snprintf(dir, sizeof dir, "%s", svc->blob_dir);
  bool created;
  svc_error e = {0};
  const char *data = "blob bytes";
  const char *h = "2d1fd2d3d4b7c1ebbe5b4e3b77c3b1dc0a8b1a1f4b9b0cf6de3be1a8b0f2fa4c";
  /* The digest of data, computed by the service for us when wrong. */
  service_blob_put(svc, h, data, strlen(data), &created, &e);
  char hex[65] = "";
  const char *say = strstr(e.err.msg, "SHA-256 is ");
  if (say) snprintf(hex, sizeof hex, "%.64s", say + 11);
  svc_error e2 = {0};
  CHECK(hex[0] && service_blob_put(svc, hex, data, strlen(data), &created, &e2) == RSW_OK, "blob put: %s",
        e2.err.msg);
  struct stat sb;
  CHECK(stat(dir, &sb) == 0, "the temporary blob directory %s exists while the service runs", dir);
  service_free(svc);
  CHECK(stat(dir, &sb) != 0 && errno == ENOENT, "the temporary blob directory %s is removed by service_free",
        dir);
}

static void test_lru_never_in_flight(void) {
  service *svc = NULL;
  rsw_err err = {0};
  service_opts o = {.size = sizeof o, .render_threads = 1, .max_scene_bytes = 1};
  REQUIRE(service_new(&o, &svc, &err) == RSW_OK, "service_new: %s", err.msg);
  char *a = post(svc, 0.1);
  REQUIRE(a, "post a");
  resident *ra = svc_scene_acquire(svc, a); /* an in-flight request */
  REQUIRE(ra, "acquire a");
  char *b = post(svc, 0.2);
  REQUIRE(b, "post b");
  char *json = NULL;
  svc_error e = {0};
  CHECK(service_scene_get(svc, a, &json, &e) == RSW_OK, "a is held: not evicted (%s)", e.err.msg);
  free(json), json = NULL;
  svc_scene_release(svc, ra);
  /* Touch b after a: a is now the least recently used idle scene. */
  svc_scene_release(svc, svc_scene_acquire(svc, b));
  char *c = post(svc, 0.3);
  REQUIRE(c, "post c");
  svc_error e3 = {0};
  CHECK(service_scene_get(svc, a, &json, &e3) == RSW_ERR_EVICTED, "a evicted: %s",
        rsw_status_name(e3.err.code));
  CHECK(rsw_status_http(RSW_ERR_EVICTED) == 404 && rsw_status_http(RSW_ERR_STORAGE) == 507,
        "EVICTED is a 404, STORAGE a 507");
  free(json), json = NULL;
  svc_error e4 = {0};
  CHECK(service_scene_get(svc, c, &json, &e4) == RSW_OK, "the newest scene stays");
  free(json);
  free(a), free(b), free(c);
  service_free(svc);
}

static void test_state_dir_locked(void) {
  char dir[] = "/tmp/rsw-state-lock-XXXXXX";
  REQUIRE(mkdtemp(dir), "mkdtemp");
  service *s1 = NULL, *s2 = NULL;
  rsw_err err = {0};
  service_opts o = {.size = sizeof o, .render_threads = 1, .state_dir = dir};
  REQUIRE(service_new(&o, &s1, &err) == RSW_OK, "first service: %s", err.msg);
  rsw_err err2 = {0};
  CHECK(service_new(&o, &s2, &err2) != RSW_OK && strstr(err2.msg, "in use"), "a second one is refused: %s",
        err2.msg);
  if (s2) service_free(s2);
  service_free(s1);
  char cmd[200];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  CHECK(system(cmd) == 0, "cleanup");
}

int main(void) {
  RSW_TEST_RUN(test_temp_blob_dir_removed);
  RSW_TEST_RUN(test_lru_never_in_flight);
  RSW_TEST_RUN(test_state_dir_locked);
  RSW_TEST_END("test_state_service");
}
