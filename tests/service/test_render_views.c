/* Per-render parameter overrides on private views of a scene (service/
 * renders.c): concurrent renders of one scene with different overrides
 * (spectral and geometric) each give bitwise the film of a serial render
 * with that override, the base state is bitwise unchanged afterwards (GET
 * params, a base render), a render with overrides does not wait for a long
 * render of the same scene, and views follow PATCHes. */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../../server/service/service.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

static const char *SCENE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"cam\": {\"type\": \"perspective\", \"fov\": 40,"
    "   \"to_world\": [{\"lookat\": {\"origin\": [0, -4, 3], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 20, \"height\": 14}},"
    " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [1, 0.5, -2], \"irradiance\": 1.0},"
    " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 2}],"
    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}},"
    " \"ball\": {\"type\": \"sphere\", \"center\": [0, 0, 0.5], \"radius\": 0.5,"
    "   \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": 0.3}}}";

/* Overrides: spectral (reflectance, irradiance, roughness, the sun's
 * direction), geometric (the ball's and the plate's to_world), and a
 * wavelength-only context. */
#define N_OV 9
static const char *OV[N_OV] = {
    "{\"sensor\": \"cam\", \"spp\": 3, \"seed\": 5}",
    "{\"sensor\": \"cam\", \"spp\": 3, \"seed\": 5, \"params\": {\"plate.bsdf.reflectance.value\": 0.2}}",
    "{\"sensor\": \"cam\", \"spp\": 3, \"seed\": 5, \"params\": {\"sun.irradiance.value\": 3.5}}",
    "{\"sensor\": \"cam\", \"spp\": 3, \"seed\": 5, \"params\": {\"ball.bsdf.alpha.value\": 0.05,"
    " \"plate.bsdf.reflectance.value\": 0.9}}",
    "{\"sensor\": \"cam\", \"spp\": 3, \"seed\": 5, \"params\": {\"sun.direction\": [-1, 0.2, -1]}}",
    "{\"sensor\": \"cam\", \"spp\": 3, \"seed\": 5, \"params\": {\"ball.to_world\": "
    "[0.5, 0, 0, 0.7, 0, 0.5, 0, 0.2, 0, 0, 0.5, 0.6, 0, 0, 0, 1]}}",
    "{\"sensor\": \"cam\", \"spp\": 3, \"seed\": 5, \"params\": {\"plate.to_world\": "
    "[3, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -0.2, 0, 0, 0, 1]}}",
    "{\"sensor\": \"cam\", \"spp\": 3, \"seed\": 5, \"wavelength\": 700}",
    "{\"sensor\": \"meter\", \"spp\": 2, \"seed\": 9, \"params\": {\"plate.bsdf.reflectance.value\": 0.3}}",
};

static service *svc;
static char *scene_id;
static svc_film serial[N_OV];

static bool same_film(const svc_film *a, const svc_film *b) {
  const film_image *x = &a->img, *y = &b->img;
  return x->width == y->width && x->height == y->height && x->channels == y->channels &&
         memcmp(x->data, y->data, (size_t)x->width * x->height * x->channels * sizeof(float)) == 0;
}

static rsw_status render(const char *q, svc_film *out, svc_error *e) {
  return service_render(svc, scene_id, q, strlen(q), NULL, out, e);
}

static char *params_json(uint64_t *rev) {
  char *json = NULL;
  svc_error e = {0};
  if (service_params_get(svc, scene_id, "*", NULL, &json, rev, &e) != RSW_OK) return NULL;
  return json;
}

typedef struct worker {
  int index;
  int bad, failed;
  char msg[1100];
} worker;

#define N_THREADS 12
#define ROUNDS    3

static void *worker_main(void *arg) {
  worker *w = arg;
  for (int r = 0; r < ROUNDS; r++)
    for (int k = 0; k < N_OV; k++) {
      int o = (k + w->index) % N_OV; /* each thread in another order */
      svc_film f;
      svc_error e = {0};
      if (render(OV[o], &f, &e) != RSW_OK) {
        w->failed++;
        snprintf(w->msg, sizeof w->msg, "override %d: %s: %s", o, e.err.where, e.err.msg);
        continue;
      }
      if (!same_film(&f, &serial[o])) {
        w->bad++;
        snprintf(w->msg, sizeof w->msg, "override %d: film differs from the serial render", o);
      }
      svc_film_free(&f);
    }
  return NULL;
}

static void test_concurrent_overrides_bitwise(void) {
  /* A PATCH first, so views must replay it. */
  char *json = NULL;
  uint64_t rev = 0;
  svc_error e = {0};
  const char *patch = "{\"plate.bsdf.reflectance.value\": 0.45, \"sun.irradiance.value\": 1.25}";
  REQUIRE(service_params_patch(svc, scene_id, patch, strlen(patch), -1, &json, &rev, &e) == RSW_OK,
          "patch: %s", e.err.msg);
  free(json);
  for (int k = 0; k < N_OV; k++)
    REQUIRE(render(OV[k], &serial[k], &e) == RSW_OK, "serial %d: %s: %s", k, e.err.where, e.err.msg);
  /* The overrides do change the film (else the test proves nothing). */
  for (int k = 1; k < 7; k++) CHECK(!same_film(&serial[0], &serial[k]), "override %d changed nothing", k);
  uint64_t rev0 = 0;
  char *before = params_json(&rev0);
  REQUIRE(before, "params before");
  worker w[N_THREADS];
  pthread_t th[N_THREADS];
  for (int i = 0; i < N_THREADS; i++) {
    w[i] = (worker){.index = i};
    REQUIRE(pthread_create(&th[i], NULL, worker_main, &w[i]) == 0, "thread");
  }
  for (int i = 0; i < N_THREADS; i++) pthread_join(th[i], NULL);
  for (int i = 0; i < N_THREADS; i++) {
    CHECK(w[i].failed == 0, "thread %d: %d renders failed (%s)", i, w[i].failed, w[i].msg);
    CHECK(w[i].bad == 0, "thread %d: %d films differ from serial (%s)", i, w[i].bad, w[i].msg);
  }
  uint64_t rev1 = 0;
  char *after = params_json(&rev1);
  REQUIRE(after, "params after");
  CHECK(rev1 == rev0, "revision moved: %llu -> %llu", (unsigned long long)rev0, (unsigned long long)rev1);
  CHECK(strcmp(before, after) == 0, "GET params changed by renders with overrides");
  free(before);
  free(after);
  svc_film base;
  REQUIRE(render(OV[0], &base, &e) == RSW_OK, "base render");
  CHECK(same_film(&base, &serial[0]), "a base render after the overrides differs");
  svc_film_free(&base);
}

/* A render with overrides while a long render of the same scene runs: it
 * finishes long before (renders of one scene no longer wait for each
 * other). */
static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static void *long_render(void *arg) {
  double *secs = arg;
  double t0 = now_s();
  svc_film f;
  svc_error e = {0};
  const char *q = "{\"sensor\": \"meter\", \"spp\": 400000000, \"timeout_s\": 3}";
  if (render(q, &f, &e) == RSW_OK) svc_film_free(&f);
  *secs = now_s() - t0;
  return NULL;
}

static void test_no_wait_for_other_render(void) {
  double long_s = 0;
  pthread_t th;
  REQUIRE(pthread_create(&th, NULL, long_render, &long_s) == 0, "thread");
  struct timespec ts = {0, 200 * 1000000L};
  nanosleep(&ts, NULL);
  double t0 = now_s();
  svc_film f;
  svc_error e = {0};
  rsw_status st = render(OV[8], &f, &e);
  double quick_s = now_s() - t0;
  pthread_join(th, NULL);
  REQUIRE(st == RSW_OK, "render beside the long one: %s", e.err.msg);
  CHECK(same_film(&f, &serial[8]), "film beside a long render differs from the serial one");
  svc_film_free(&f);
  CHECK(long_s > 2.0, "the long render ran %.2f s (expected ~3 s, else the test proves nothing)", long_s);
  CHECK(quick_s < 1.0, "a 1x1 render waited %.2f s for a long render of the same scene", quick_s);
}

/* Views follow PATCHes: after a PATCH, an override render equals the
 * same render on a scene whose text carries the patched value. */
static void test_views_follow_patches(void) {
  char *json = NULL;
  uint64_t rev = 0;
  svc_error e = {0};
  const char *patch = "{\"ball.bsdf.alpha.value\": 0.12}";
  REQUIRE(service_params_patch(svc, scene_id, patch, strlen(patch), -1, &json, &rev, &e) == RSW_OK, "patch");
  free(json);
  svc_film a, b;
  REQUIRE(render(OV[2], &a, &e) == RSW_OK, "override after patch: %s", e.err.msg);
  /* The same on the base with the override written as a PATCH, then undone. */
  const char *p2 = "{\"sun.irradiance.value\": 3.5}", *p3 = "{\"sun.irradiance.value\": 1.25}";
  REQUIRE(service_params_patch(svc, scene_id, p2, strlen(p2), -1, &json, &rev, &e) == RSW_OK, "patch 2");
  free(json);
  REQUIRE(render(OV[0], &b, &e) == RSW_OK, "base render");
  CHECK(same_film(&a, &b), "override render after a PATCH != the base patched the same way");
  REQUIRE(service_params_patch(svc, scene_id, p3, strlen(p3), -1, &json, &rev, &e) == RSW_OK, "patch 3");
  free(json);
  svc_film_free(&a), svc_film_free(&b);
}

/* Jobs of different scenes run at the same time: a short job finishes
 * while a long one on another scene is still running. */
static bool job_state_is(const char *jid, const char *state) {
  char *json = NULL;
  svc_error e = {0};
  if (service_job_get(svc, jid, &json, &e) != RSW_OK) return false;
  char want[64];
  snprintf(want, sizeof want, "\"state\":\"%s\"", state);
  bool yes = strstr(json, want) != NULL;
  free(json);
  return yes;
}

static void test_jobs_run_concurrently(void) {
  if (sysconf(_SC_NPROCESSORS_ONLN) < 2) {
    printf("  (one core: one job worker; nothing to test)\n");
    return;
  }
  bool created;
  char *other = NULL, *json = NULL, *ja = NULL, *jb = NULL;
  svc_error e = {0};
  REQUIRE(service_scene_post(svc, SCENE, strlen(SCENE), false, "rgb", &created, &other, &json, &e) == RSW_OK,
          "second scene");
  free(json);
  const char *longjob = "{\"contexts\": [{\"id\": \"a\", \"sensors\": [\"meter\"], \"spp\": 400000000}]}";
  const char *shortjob = "{\"contexts\": [{\"id\": \"b\", \"sensors\": [\"meter\"], \"spp\": 2}]}";
  REQUIRE(service_job_submit(svc, scene_id, longjob, strlen(longjob), NULL, &ja, &json, &e) == RSW_OK,
          "long job: %s", e.err.msg);
  free(json);
  for (int i = 0; i < 200 && !job_state_is(ja, "running"); i++) usleep(10000);
  REQUIRE(service_job_submit(svc, other, shortjob, strlen(shortjob), NULL, &jb, &json, &e) == RSW_OK,
          "short job: %s", e.err.msg);
  free(json);
  double t0 = now_s();
  while (!job_state_is(jb, "succeeded") && now_s() - t0 < 5) usleep(5000);
  double short_s = now_s() - t0;
  bool long_running = job_state_is(ja, "running");
  CHECK(short_s < 2.0 && long_running,
        "the short job took %.2f s beside a running job (long job running: %d)", short_s, long_running);
  char *cj = NULL;
  service_job_cancel(svc, ja, &cj, &e);
  free(cj);
  for (int i = 0; i < 500 && !job_state_is(ja, "cancelled"); i++) usleep(10000);
  CHECK(job_state_is(ja, "cancelled"), "the long job ends cancelled");
  free(ja), free(jb), free(other);
}

/* A view is the scene it stands for: a file under the data root that
 * changed since the load is refused, not silently rendered. */
static void write_obj(const char *path, double z) {
  FILE *f = fopen(path, "w");
  if (!f) return;
  fprintf(f, "v -1 -1 %g\nv 1 -1 %g\nv 0 1 %g\nf 1 2 3\n", z, z, z);
  fclose(f);
}

static void test_view_refuses_changed_file(void) {
  char dir[] = "/tmp/rsw-views-XXXXXX";
  REQUIRE(mkdtemp(dir), "temp dir");
  char obj[300];
  snprintf(obj, sizeof obj, "%s/tri.obj", dir);
  write_obj(obj, 0);
  service *s2 = NULL;
  service_opts o = {.size = sizeof o, .data_root = dir};
  rsw_err err = {0};
  REQUIRE(service_new(&o, &s2, &err) == RSW_OK, "service: %s", err.msg);
  const char *doc = "{\"type\": \"scene\", \"variant\": \"mono\","
                    " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1],"
                    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
                    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1]},"
                    " \"tri\": {\"type\": \"obj\", \"filename\": \"tri.obj\","
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";
  bool created;
  char *id = NULL, *json = NULL;
  svc_error e = {0};
  REQUIRE(service_scene_post(s2, doc, strlen(doc), false, NULL, &created, &id, &json, &e) == RSW_OK,
          "post: %s: %s", e.err.where, e.err.msg);
  free(json);
  const char *q = "{\"spp\": 2, \"params\": {\"tri.bsdf.reflectance.value\": 0.25}}";
  svc_film f;
  REQUIRE(service_render(s2, id, q, strlen(q), NULL, &f, &e) == RSW_OK, "override render: %s", e.err.msg);
  svc_film_free(&f);
  /* Another view is needed once the first is busy or gone: change the file
   * and PATCH (which drops the idle views). */
  write_obj(obj, 0.5);
  const char *patch = "{\"tri.bsdf.reflectance.value\": 0.4}";
  uint64_t rev;
  REQUIRE(service_params_patch(s2, id, patch, strlen(patch), -1, &json, &rev, &e) == RSW_OK, "patch");
  free(json);
  svc_error e2 = {0};
  CHECK(service_render(s2, id, q, strlen(q), NULL, &f, &e2) != RSW_OK && strstr(e2.err.msg, "changed"),
        "a view of a changed file was rendered (%s)", e2.err.msg);
  const char *plain = "{\"spp\": 2}";
  svc_error e3 = {0};
  CHECK(service_render(s2, id, plain, strlen(plain), NULL, &f, &e3) == RSW_OK, "the base still renders: %s",
        e3.err.msg);
  if (!e3.err.code) svc_film_free(&f);
  free(id);
  service_free(s2);
  remove(obj);
  rmdir(dir);
}

int main(void) {
  service_opts o = {.size = sizeof o, .render_threads = 0};
  rsw_err err = {0};
  if (service_new(&o, &svc, &err) != RSW_OK) {
    fprintf(stderr, "service: %s\n", err.msg);
    return 1;
  }
  bool created;
  char *json = NULL;
  svc_error e = {0};
  if (service_scene_post(svc, SCENE, strlen(SCENE), false, NULL, &created, &scene_id, &json, &e) != RSW_OK) {
    fprintf(stderr, "post: %s: %s\n", e.err.where, e.err.msg);
    return 1;
  }
  free(json);
  RSW_TEST_RUN(test_concurrent_overrides_bitwise);
  RSW_TEST_RUN(test_no_wait_for_other_render);
  RSW_TEST_RUN(test_views_follow_patches);
  RSW_TEST_RUN(test_jobs_run_concurrently);
  RSW_TEST_RUN(test_view_refuses_changed_file);
  for (int k = 0; k < N_OV; k++) svc_film_free(&serial[k]);
  free(scene_id);
  service_free(svc);
  RSW_TEST_END("test_render_views");
}
