/* The render worker pool (render.c): no thread per render, one-tile renders
 * on the caller's thread, and concurrent renders (each with several
 * threads) giving bitwise the film of a serial one-thread render. */
#include <pthread.h>
#include <stdio.h>
#include <string.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "../../server/kernel/render.h"
#include "../../server/kernel/scene/scene.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

/* Several tiles, a filter that splats across tile borders. */
static const char *SCENE =
    "{\"type\": \"scene\","
    " \"cam\": {\"type\": \"perspective\", \"fov\": 45,"
    "   \"to_world\": [{\"lookat\": {\"origin\": [0, -4, 2], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 37, \"height\": 35}},"
    " \"one\": {\"type\": \"distant\", \"direction\": [0, 0, -1],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [1, 1, -2]},"
    " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 3}],"
    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": {\"type\": \"checkerboard\"}}},"
    " \"ball\": {\"type\": \"sphere\", \"center\": [0, 0, 0.6], \"radius\": 0.6}}";

static bool same_bits(const film_image *a, const film_image *b) {
  return a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, (size_t)a->width * a->height * a->channels * sizeof(float)) == 0;
}

/* Thread ids seen by the progress callback (called by whichever thread
 * merged a tile). */
typedef struct tids {
  pthread_mutex_t lock;
  long id[4096];
  size_t n;
} tids;

static void on_progress(void *user, size_t done, size_t total) {
  (void)done, (void)total;
  tids *t = user;
  long me = (long)syscall(SYS_gettid);
  pthread_mutex_lock(&t->lock);
  bool seen = false;
  for (size_t i = 0; i < t->n; i++) seen |= t->id[i] == me;
  if (!seen && t->n < 4096) t->id[t->n++] = me;
  pthread_mutex_unlock(&t->lock);
}

static bool render(scene *s, size_t sensor_index, int threads, uint64_t seed, tids *t, film_image *out,
                   render_result_stats *st) {
  render_opts o = {.size = sizeof o, .sensor = sensor_index, .spp = 4, .seed = seed, .threads = threads};
  if (t) o.progress = on_progress, o.progress_user = t;
  rsw_err err = {0};
  bool ok = render_sensor(s, &o, out, st, &err) == RSW_OK;
  if (!ok) fprintf(stderr, "render: %s: %s\n", err.where, err.msg);
  return ok;
}

static void test_no_thread_per_render(void) {
  scene *s = tsup_load(SCENE, NULL);
  REQUIRE(s, "scene");
  tids t = {.lock = PTHREAD_MUTEX_INITIALIZER};
  long cores = sysconf(_SC_NPROCESSORS_ONLN);
  for (int i = 0; i < 30; i++) {
    film_image img;
    REQUIRE(render(s, 0, 4, 1, &t, &img, NULL), "render %d", i);
    film_image_free(&img);
  }
  /* The pool's threads and the caller: at most max(cores, 2) ids over 30
   * renders (a thread per render gives a new id each time). */
  long limit = cores > 2 ? cores : 2;
  CHECK((long)t.n <= limit, "30 renders ran on %zu threads (at most %ld expected)", t.n, limit);
  scene_free(s);
}

static void test_one_tile_on_caller(void) {
  scene *s = tsup_load(SCENE, NULL);
  REQUIRE(s, "scene");
  tids t = {.lock = PTHREAD_MUTEX_INITIALIZER};
  film_image img;
  render_result_stats st;
  REQUIRE(render(s, 1, 0, 1, &t, &img, &st), "1x1 render");
  film_image_free(&img);
  CHECK(t.n == 1 && t.id[0] == (long)syscall(SYS_gettid), "a 1x1 render ran on another thread");
  CHECK(st.threads == 1, "a 1x1 render used %d threads", st.threads);
  scene_free(s);
}

/* Concurrent renders, each on its own scene (a render writes the scene's
 * wavelength-dependent state) and with 3 threads, against serial
 * one-thread renders of the same seeds. */
#define N_CONC 6
typedef struct conc {
  scene *s;
  uint64_t seed;
  film_image img;
  bool ok;
} conc;

static void *conc_main(void *arg) {
  conc *c = arg;
  c->ok = true;
  for (int k = 0; k < 3 && c->ok; k++) {
    film_image img;
    c->ok = render(c->s, 0, 3, c->seed, NULL, &img, NULL);
    if (!c->ok) break;
    if (k == 0)
      c->img = img;
    else {
      c->ok = same_bits(&img, &c->img);
      film_image_free(&img);
    }
  }
  return NULL;
}

static void test_concurrent_bitwise(void) {
  conc c[N_CONC];
  pthread_t th[N_CONC];
  for (int i = 0; i < N_CONC; i++) {
    c[i] = (conc){.s = tsup_load(SCENE, NULL), .seed = 100 + (uint64_t)i};
    REQUIRE(c[i].s, "scene %d", i);
  }
  for (int i = 0; i < N_CONC; i++) REQUIRE(pthread_create(&th[i], NULL, conc_main, &c[i]) == 0, "thread");
  for (int i = 0; i < N_CONC; i++) pthread_join(th[i], NULL);
  for (int i = 0; i < N_CONC; i++) {
    CHECK(c[i].ok, "concurrent render %d failed or changed between repeats", i);
    film_image serial;
    REQUIRE(render(c[i].s, 0, 1, c[i].seed, NULL, &serial, NULL), "serial %d", i);
    CHECK(c[i].ok && same_bits(&serial, &c[i].img), "render %d: concurrent != serial one-thread film", i);
    film_image_free(&serial);
    if (c[i].ok) film_image_free(&c[i].img);
    scene_free(c[i].s);
  }
}

int main(void) {
  RSW_TEST_RUN(test_one_tile_on_caller);
  RSW_TEST_RUN(test_no_thread_per_render);
  RSW_TEST_RUN(test_concurrent_bitwise);
  RSW_TEST_END("test_render_pool");
}
