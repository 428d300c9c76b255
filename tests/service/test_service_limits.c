/* Limits refused up front (issue 13), in process through the service API:
 * a film too large for --max-film-bytes (an 8192x8192 render used to run
 * 4 minutes at 3.4 GB and then fail) is refused before anything renders,
 * by a synchronous render and by a job, naming the field; the directions
 * route refuses films over its pixel limit and answers the rest with the
 * sensor's own mapping; a sensor named twice in a context is refused (a
 * 50 KB body used to queue 10,000 renders of one sensor); a job over the
 * context cap is refused in milliseconds (it took 153-185 s, the duplicate
 * scan ran first), and a duplicate context id among 50,000 is found in
 * linear time. Figures before the fix are in the commit message. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <cjson/cJSON.h>

#include "../../server/kernel/core/warp.h"
#include "../../server/service/service.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

static service *svc;

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* A mono plate seen by an hdistant of W x H pixels ("big") and a 1x1
 * distant ("meter"). */
static char *post_scene(int W, int H) {
  char doc[2048];
  snprintf(
      doc, sizeof doc,
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"big\": {\"type\": \"hdistant\", \"film\": {\"type\": \"hdrfilm\", \"width\": %d, \"height\": %d,"
      "   \"rfilter\": {\"type\": \"box\"}}},"
      " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1],"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.0},"
      " \"plate\": {\"type\": \"rectangle\"}}",
      W, H);
  bool created;
  char *id = NULL, *json = NULL;
  svc_error e = {0};
  if (service_scene_post(svc, doc, strlen(doc), false, NULL, &created, &id, &json, &e)) {
    printf("  post: %s\n", e.err.msg);
    return NULL;
  }
  free(json);
  return id;
}

static void test_film_refused_up_front(void) {
  char *id = post_scene(8192, 8192);
  REQUIRE(id, "scene");
  svc_film f;
  svc_error e = {0};
  const char *q = "{\"sensor\": \"big\", \"spp\": 1}";
  double t0 = now_s();
  rsw_status st = service_render(svc, id, q, strlen(q), NULL, &f, &e);
  double dt = now_s() - t0;
  CHECK(st == RSW_ERR_LIMIT, "render of an 8192^2 film: %d %s", st, e.err.msg);
  CHECK(strcmp(e.err.where, "/sensor") == 0, "where: %s", e.err.where);
  CHECK(strstr(e.err.msg, "8192x8192") && strstr(e.err.msg, "--max-film-bytes"), "message: %s", e.err.msg);
  CHECK(rsw_status_http(st) == 413 || rsw_status_http(st) == 422, "status %d", rsw_status_http(st));
  CHECK(dt < 0.5, "refused in %.3f s, not before rendering", dt);
  if (!st) svc_film_free(&f);
  /* The small sensor of the same scene renders. */
  const char *q2 = "{\"sensor\": \"meter\", \"spp\": 1}";
  svc_error e2 = {0};
  CHECK(service_render(svc, id, q2, strlen(q2), NULL, &f, &e2) == RSW_OK, "meter: %s", e2.err.msg);
  svc_film_free(&f);
  /* A job naming it, explicitly or through "every sensor". */
  const char *jobs[] = {"{\"contexts\": [{\"id\": \"a\", \"sensors\": [\"meter\"]}, {\"id\": \"b\", "
                        "\"sensors\": [\"meter\", \"big\"]}]}",
                        "{\"contexts\": [{\"id\": \"a\"}]}"};
  const char *where[] = {"/contexts/1/sensors/1", "/contexts/0"};
  for (int i = 0; i < 2; i++) {
    char *jid = NULL, *json = NULL;
    svc_error ej = {0};
    st = service_job_submit(svc, id, jobs[i], strlen(jobs[i]), NULL, &jid, &json, &ej);
    CHECK(st == RSW_ERR_LIMIT && strcmp(ej.err.where, where[i]) == 0, "job %d: %d at '%s': %s", i, st,
          ej.err.where, ej.err.msg);
    free(jid), free(json);
  }
  CHECK(service_scene_delete(svc, id, true, &e) == RSW_OK, "delete");
  free(id);
}

static void test_directions(void) {
  char *id = post_scene(2048, 1024);
  REQUIRE(id, "scene");
  char *json = NULL;
  svc_error e = {0};
  double t0 = now_s();
  rsw_status st = service_directions(svc, id, "big", &json, &e);
  CHECK(st == RSW_ERR_LIMIT && strcmp(e.err.where, "big") == 0, "2048x1024 directions: %d %s", st, e.err.msg);
  CHECK(now_s() - t0 < 0.5, "refused up front");
  free(json);
  CHECK(service_scene_delete(svc, id, true, &e) == RSW_OK, "delete");
  free(id);
  /* A 64x32 film: every pixel, with the hemisphere mapping's angles. */
  id = post_scene(64, 32);
  REQUIRE(id, "scene");
  json = NULL;
  REQUIRE(service_directions(svc, id, "big", &json, &e) == RSW_OK, "directions: %s", e.err.msg);
  cJSON *j = cJSON_Parse(json);
  REQUIRE(j, "valid JSON");
  const cJSON *px = cJSON_GetObjectItem(j, "pixels");
  CHECK(cJSON_GetArraySize(px) == 64 * 32, "%d pixels", cJSON_GetArraySize(px));
  /* Pixel (ix, iy): the uniform hemisphere at ((ix + .5)/W, (iy + .5)/H)
   * (docs/kernel-conventions.md#viewing-angles); the default hdistant's to_world is the
   * identity, so the world direction is that vector. */
  const cJSON *p = cJSON_GetArrayItem(px, 5 * 64 + 7);
  vec3 v = warp_square_to_uniform_hemisphere(v2((7 + 0.5) / 64, (5 + 0.5) / 32));
  CHECK(cJSON_GetObjectItem(p, "ix")->valueint == 7 && cJSON_GetObjectItem(p, "iy")->valueint == 5, "order");
  CHECK_ABS(cJSON_GetObjectItem(p, "x")->valuedouble, v.x, 1e-15);
  CHECK_ABS(cJSON_GetObjectItem(p, "y")->valuedouble, v.y, 1e-15);
  CHECK_ABS(cJSON_GetObjectItem(p, "z")->valuedouble, v.z, 1e-15);
  CHECK_REL(cJSON_GetObjectItem(p, "zenith_deg")->valuedouble, acos(v.z) * 180.0 / M_PI, 1e-12);
  cJSON_Delete(j);
  free(json);
  CHECK(service_scene_delete(svc, id, true, &e) == RSW_OK, "delete");
  free(id);
}

static void test_duplicate_sensor(void) {
  char *id = post_scene(2, 2);
  REQUIRE(id, "scene");
  const char *bodies[] = {
      "{\"contexts\": [{\"id\": \"a\", \"sensors\": [\"meter\", \"meter\"]}]}",
      "{\"defaults\": {\"sensors\": [\"big\", \"meter\", \"big\"]}, \"contexts\": [{\"id\": \"a\"}]}",
      "{\"contexts\": [{\"id\": \"a\", \"sensors\": [\"meter\", \"1\"]}]}", /* by id and by index */
  };
  const char *where[] = {"/contexts/0/sensors/1", "/defaults/sensors/2", "/contexts/0/sensors/1"};
  for (int i = 0; i < 3; i++) {
    char *jid = NULL, *json = NULL;
    svc_error e = {0};
    rsw_status st = service_job_submit(svc, id, bodies[i], strlen(bodies[i]), NULL, &jid, &json, &e);
    CHECK(st == RSW_ERR_DUPLICATE && strcmp(e.err.where, where[i]) == 0, "case %d: %d at '%s': %s", i, st,
          e.err.where, e.err.msg);
    free(jid), free(json);
  }
  /* 10,000 copies of one sensor: refused at the second. */
  size_t cap = 20 + 10000 * 9;
  char *big = malloc(cap);
  size_t n = (size_t)snprintf(big, cap, "{\"contexts\": [{\"id\": \"a\", \"sensors\": [");
  for (int k = 0; k < 10000; k++) n += (size_t)snprintf(big + n, cap - n, "%s\"meter\"", k ? "," : "");
  snprintf(big + n, cap - n, "]}]}");
  char *jid = NULL, *json = NULL;
  svc_error e = {0};
  CHECK(service_job_submit(svc, id, big, strlen(big), NULL, &jid, &json, &e) == RSW_ERR_DUPLICATE,
        "10,000 copies of one sensor accepted");
  free(jid), free(json), free(big);
  svc_error ed = {0};
  CHECK(service_scene_delete(svc, id, true, &ed) == RSW_OK, "delete");
  free(id);
}

/* {"contexts": [{"id": "c0"}, ...]} with n contexts; the last id repeats
 * the first when dup. */
static char *contexts_body(size_t n, bool dup) {
  size_t cap = 64 + n * 24;
  char *b = malloc(cap);
  size_t k = (size_t)snprintf(b, cap, "{\"contexts\": [");
  for (size_t i = 0; i < n; i++)
    k += (size_t)snprintf(b + k, cap - k, "%s{\"id\": \"c%zu\"}", i ? "," : "", dup && i == n - 1 ? 0 : i);
  snprintf(b + k, cap - k, "]}");
  return b;
}

static void test_many_contexts(void) {
  char *id = post_scene(1, 1);
  REQUIRE(id, "scene");
  /* Over the cap: refused after one pass over the list. */
  char *body = contexts_body(100001, false);
  char *jid = NULL, *json = NULL;
  svc_error e = {0};
  double t0 = now_s();
  rsw_status st = service_job_submit(svc, id, body, strlen(body), NULL, &jid, &json, &e);
  double dt = now_s() - t0;
  printf("  100,001 contexts refused in %.1f ms\n", 1e3 * dt);
  CHECK(st == RSW_ERR_LIMIT && strcmp(e.err.where, "/contexts") == 0, "%d at '%s': %s", st, e.err.where,
        e.err.msg);
  CHECK(dt < 1.0, "refused in %.3f s (153 s before)", dt);
  free(body), free(jid), free(json);
  /* A duplicate at the end of 50,000: found, in linear time (the
   * pairwise scan took about 45 s at this size). */
  body = contexts_body(50000, true);
  jid = NULL, json = NULL;
  svc_error e2 = {0};
  t0 = now_s();
  st = service_job_submit(svc, id, body, strlen(body), NULL, &jid, &json, &e2);
  dt = now_s() - t0;
  printf("  50,000 contexts with a duplicate refused in %.1f ms\n", 1e3 * dt);
  CHECK(st == RSW_ERR_DUPLICATE && strcmp(e2.err.where, "/contexts/49999") == 0, "%d at '%s': %s", st,
        e2.err.where, e2.err.msg);
  CHECK(dt < 2.0, "refused in %.3f s", dt);
  free(body), free(jid), free(json);
  svc_error ed = {0};
  CHECK(service_scene_delete(svc, id, true, &ed) == RSW_OK, "delete");
  free(id);
}

/* The limit is an option, and GET /v1 reports it. */
static void test_limit_option(void) {
  service *s2 = NULL;
  service_opts o = {.size = sizeof o, .render_threads = 1, .max_film_bytes = 4096};
  rsw_err err = {0};
  REQUIRE(service_new(&o, &s2, &err) == RSW_OK, "service_new: %s", err.msg);
  char *info = service_info_json(s2);
  CHECK(info && strstr(info, "\"max_film_bytes\":4096"), "GET /v1: %s", info ? info : "(null)");
  free(info);
  service *keep = svc;
  svc = s2;
  char *id = post_scene(16, 16); /* 256 pixels, 22 KB to render */
  svc = keep;
  REQUIRE(id, "scene");
  svc_film f;
  svc_error e = {0};
  const char *q = "{\"sensor\": \"big\", \"spp\": 1}";
  CHECK(service_render(s2, id, q, strlen(q), NULL, &f, &e) == RSW_ERR_LIMIT, "16x16 over 4096 bytes");
  free(id);
  service_free(s2);
  info = service_info_json(svc);
  CHECK(info && strstr(info, "\"max_film_bytes\":1073741824"), "default 1 GiB: %s", info ? info : "(null)");
  free(info);
}

int main(void) {
  service_opts o = {.size = sizeof o, .render_threads = 2};
  rsw_err err = {0};
  if (service_new(&o, &svc, &err)) {
    printf("service_new: %s\n", err.msg);
    return 1;
  }
  RSW_TEST_RUN(test_film_refused_up_front);
  RSW_TEST_RUN(test_directions);
  RSW_TEST_RUN(test_duplicate_sensor);
  RSW_TEST_RUN(test_many_contexts);
  RSW_TEST_RUN(test_limit_option);
  service_free(svc);
  RSW_TEST_END("test_service_limits");
}
