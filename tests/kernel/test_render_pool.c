/* The render worker pool (render.c): no thread per render, one-tile renders
 * on the caller's thread, concurrent renders (each with several
 * threads) giving bitwise the film of a serial one-thread render, and a
 * small box-filter film cut into smaller tiles on several threads
 * (tile_size) with the one-thread film's bits. */
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

/* render_sensor, its error printed. */
static bool render_with(scene *s, const render_opts *o, film_image *out, render_result_stats *st) {
  rsw_err err = {0};
  bool ok = render_sensor(s, o, out, st, &err) == RSW_OK;
  if (!ok) fprintf(stderr, "render: %s: %s\n", err.where, err.msg);
  return ok;
}

static bool render(scene *s, size_t sensor_index, int threads, uint64_t seed, tids *t, film_image *out,
                   render_result_stats *st) {
  render_opts o = {.size = sizeof o, .sensor = sensor_index, .spp = 4, .seed = seed, .threads = threads};
  if (t) o.progress = on_progress, o.progress_user = t;
  return render_with(s, &o, out, st);
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

/* A box-filter film of 19 x 1 pixels: 3 tiles of 8 x 8 at most. At 1,024
 * spp and two or more threads render.c cuts it into one-pixel tiles (the
 * path integrator's waves of 1,024 still fill), and the film, with its
 * variance, keeps the one-thread render's bits; a gaussian filter's
 * tiles stay 8 x 8 (their sums would round otherwise). */
static const char *SMALL =
    "{\"type\": \"scene\", \"integrator\": {\"type\": \"path\"},"
    " \"cam\": {\"type\": \"perspective\", \"fov\": 45,"
    "   \"to_world\": [{\"lookat\": {\"origin\": [0, -4, 2], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 19, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
    " \"gauss\": {\"type\": \"perspective\", \"fov\": 45,"
    "   \"to_world\": [{\"lookat\": {\"origin\": [0, -4, 2], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 19, \"height\": 1, \"rfilter\": {\"type\": "
    "\"gaussian\"}}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [1, 1, -2]},"
    " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 3}],"
    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": {\"type\": \"checkerboard\"}}},"
    " \"ball\": {\"type\": \"sphere\", \"center\": [0, 0, 0.6], \"radius\": 0.6}}";

/* The tile count a render reports to its progress callback. */
static void on_total(void *user, size_t done, size_t total) {
  (void)done;
  *(size_t *)user = total;
}

static bool render_small(scene *s, size_t sensor_index, int threads, bool variance, film_image *out,
                         size_t *tiles) {
  render_opts o = {.size = sizeof o,
                   .sensor = sensor_index,
                   .spp = 1024,
                   .seed = 3,
                   .threads = threads,
                   .variance = variance,
                   .progress = on_total,
                   .progress_user = tiles};
  return render_with(s, &o, out, NULL);
}

static void test_small_box_film_tiles(void) {
  scene *s = tsup_load(SMALL, NULL);
  REQUIRE(s, "scene");
  for (int v = 0; v < 2; v++) {
    film_image one;
    size_t tiles1 = 0;
    REQUIRE(render_small(s, 0, 1, v, &one, &tiles1), "one thread");
    CHECK(tiles1 == 3, "one thread: 3 tiles of 8 x 8 (got %zu)", tiles1);
    for (int threads = 2; threads <= 5; threads += 3) {
      film_image img;
      size_t tiles = 0;
      REQUIRE(render_small(s, 0, threads, v, &img, &tiles), "%d threads", threads);
      CHECK(tiles == 19, "%d threads: 19 one-pixel tiles (got %zu)", threads, tiles);
      CHECK(same_bits(&one, &img), "box filter%s: %d threads' film != one thread's", v ? ", variance" : "",
            threads);
      film_image_free(&img);
    }
    film_image_free(&one);
  }
  film_image g1, g2;
  size_t t1 = 0, t2 = 0;
  REQUIRE(render_small(s, 1, 1, false, &g1, &t1) && render_small(s, 1, 2, false, &g2, &t2), "gaussian");
  CHECK(t1 == 3 && t2 == 3, "a gaussian filter keeps 8 x 8 tiles (got %zu, %zu)", t1, t2);
  CHECK(same_bits(&g1, &g2), "gaussian filter: 2 threads' film != one thread's");
  film_image_free(&g1), film_image_free(&g2);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_one_tile_on_caller);
  RSW_TEST_RUN(test_no_thread_per_render);
  RSW_TEST_RUN(test_concurrent_bitwise);
  RSW_TEST_RUN(test_small_box_film_tiles);
  RSW_TEST_END("test_render_pool");
}
