/* A render of very few pixels with a huge spp still stops when it is
 * cancelled or passes its deadline (render.c checks between pixels and
 * every STOP_CHECK_SAMPLES samples within a pixel).
 *
 * The checks are orders of events, not latencies: a short calibration
 * render of the same 1x1 scene gives this machine's samples per second;
 * the stopped render holds FULL samples, so it must return its error in
 * less than half the time the calibration says all of them would take
 * (some 35 s here, against a deadline or cancel 0.2 s after the start).
 * Before the in-pixel check, the render only stopped after its one pixel's
 * last sample.
 *
 * Inside a wave: a radiancemeter in an unbounded lossless fog takes some
 * 65,536 bounces a path (the roulette's backstop), about 28 ms here, so
 * one wave of 256 paths takes 7 s; a deadline or a cancel 0.2 s after the
 * start must end it in less than a quarter of that (the wave loops ask
 * render_stop_requested). Before that check, the render stopped after the
 * wave. */
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <time.h>
#include <unistd.h>

#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

/* A radiancemeter (1x1 film) on a Lambertian plate under a constant sky:
 * every sample is a path with a bounce. */
static const char *SCENE = "{\"type\": \"scene\","
                           " \"sky\": {\"type\": \"constant\"},"
                           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\"}},"
                           " \"meter\": {\"type\": \"radiancemeter\", \"origin\": [0, 0, 1],"
                           "   \"direction\": [0, 0, -1],"
                           "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}";

#define CALIBRATION (1u << 16)
#define FULL        (1u << 26)

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* Seconds FULL samples would take, from a CALIBRATION-sample render; -1
 * when that render fails. */
static double full_render_s(scene *s) {
  film_image img = {0};
  double t0 = now();
  if (!tsup_render(s, CALIBRATION, 1, 1, &img)) return -1;
  double dt = now() - t0;
  film_image_free(&img);
  return dt * ((double)FULL / CALIBRATION);
}

static void test_deadline_inside_a_pixel(void) {
  scene *s = tsup_load(SCENE, "mono");
  REQUIRE(s, "scene loads");
  double full = full_render_s(s);
  REQUIRE(full > 0, "calibration render");
  rsw_err err = {0};
  film_image img = {0};
  double t0 = now();
  render_opts o = {.size = sizeof o, .spp = FULL, .seed = 1, .threads = 1, .deadline = t0 + 0.2};
  rsw_status st = render_sensor(s, &o, &img, NULL, &err);
  double dt = now() - t0;
  printf("  deadline 0.2 s: status %d after %.3f s (all %u samples: ~%.0f s)\n", (int)st, dt, FULL, full);
  CHECK(st == RSW_ERR_TIMEOUT, "the render answers RSW_ERR_TIMEOUT (got %d)", (int)st);
  CHECK(dt < 0.5 * full, "the render stopped before its pixel's last sample (%.3f s of ~%.0f s)", dt, full);
  film_image_free(&img);
  scene_free(s);
}

/* The fog: every path of a wave scatters until the backstop ends it. */
static const char *FOG =
    "{\"type\": \"scene\", \"integrator\": {\"type\": \"volpath\"},"
    " \"fog\": {\"type\": \"homogeneous\", \"sigma_t\": 1, \"albedo\": 1},"
    " \"lamp\": {\"type\": \"rectangle\", \"emitter\": {\"type\": \"area\", \"radiance\": 1}},"
    " \"s\": {\"type\": \"radiancemeter\", \"origin\": [0, 0, 2], \"direction\": [0, 0, -1],"
    "   \"medium\": {\"type\": \"ref\", \"id\": \"fog\"},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}";

#define FOG_WAVE 256 /* samples: one wave (render.c's WAVE) */

/* Seconds the fog's whole wave takes, from a 4-sample render; -1 when it
 * fails. */
static double fog_wave_s(scene *s) {
  film_image img = {0};
  double t0 = now();
  if (!tsup_render(s, 4, 1, 1, &img)) return -1;
  double full = (now() - t0) * (FOG_WAVE / 4.0);
  film_image_free(&img);
  return full;
}

static void test_deadline_inside_a_wave(void) {
  scene *s = tsup_load(FOG, "mono");
  REQUIRE(s, "scene loads");
  double full = fog_wave_s(s);
  REQUIRE(full > 0, "calibration render");
  film_image img = {0};
  rsw_err err = {0};
  double t0 = now();
  render_opts o = {.size = sizeof o, .spp = FOG_WAVE, .seed = 1, .threads = 1, .deadline = t0 + 0.2};
  rsw_status st = render_sensor(s, &o, &img, NULL, &err);
  double dt = now() - t0;
  printf("  deadline 0.2 s: status %d after %.3f s (the wave: ~%.1f s)\n", (int)st, dt, full);
  CHECK(st == RSW_ERR_TIMEOUT, "the render answers RSW_ERR_TIMEOUT (got %d)", (int)st);
  CHECK(dt < 0.25 * full, "the render stopped inside its wave (%.3f s of ~%.1f s)", dt, full);
  film_image_free(&img);
  scene_free(s);
}

typedef struct canceller {
  atomic_int flag;
} canceller;

static void *cancel_soon(void *arg) {
  canceller *c = arg;
  usleep(200000);
  atomic_store(&c->flag, 1);
  return NULL;
}

static void test_cancel_inside_a_pixel(void) {
  scene *s = tsup_load(SCENE, "mono");
  REQUIRE(s, "scene loads");
  double full = full_render_s(s);
  REQUIRE(full > 0, "calibration render");
  canceller c;
  atomic_init(&c.flag, 0);
  pthread_t th;
  REQUIRE(pthread_create(&th, NULL, cancel_soon, &c) == 0, "thread");
  rsw_err err = {0};
  film_image img = {0};
  double t0 = now();
  render_opts o = {.size = sizeof o, .spp = FULL, .seed = 1, .threads = 2, .cancel = &c.flag};
  rsw_status st = render_sensor(s, &o, &img, NULL, &err);
  double dt = now() - t0;
  pthread_join(th, NULL);
  printf("  cancel at 0.2 s: status %d after %.3f s (all %u samples: ~%.0f s)\n", (int)st, dt, FULL, full);
  CHECK(st == RSW_ERR_CANCELLED, "the render answers RSW_ERR_CANCELLED (got %d)", (int)st);
  CHECK(dt < 0.5 * full, "the render stopped before its pixel's last sample (%.3f s of ~%.0f s)", dt, full);
  film_image_free(&img);
  scene_free(s);
}

static void test_cancel_inside_a_wave(void) {
  scene *s = tsup_load(FOG, "mono");
  REQUIRE(s, "scene loads");
  double full = fog_wave_s(s);
  REQUIRE(full > 0, "calibration render");
  film_image img = {0};
  canceller c;
  atomic_init(&c.flag, 0);
  pthread_t th;
  REQUIRE(pthread_create(&th, NULL, cancel_soon, &c) == 0, "thread");
  rsw_err err = {0};
  double t0 = now();
  render_opts o = {.size = sizeof o, .spp = FOG_WAVE, .seed = 1, .threads = 1, .cancel = &c.flag};
  rsw_status st = render_sensor(s, &o, &img, NULL, &err);
  double dt = now() - t0;
  pthread_join(th, NULL);
  printf("  cancel at 0.2 s: status %d after %.3f s (the wave: ~%.1f s)\n", (int)st, dt, full);
  CHECK(st == RSW_ERR_CANCELLED, "the render answers RSW_ERR_CANCELLED (got %d)", (int)st);
  CHECK(dt < 0.25 * full, "the render stopped inside its wave (%.3f s of ~%.1f s)", dt, full);
  film_image_free(&img);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_deadline_inside_a_wave);
  RSW_TEST_RUN(test_cancel_inside_a_wave);
  RSW_TEST_RUN(test_deadline_inside_a_pixel);
  RSW_TEST_RUN(test_cancel_inside_a_pixel);
  RSW_TEST_END("test_render_stop");
}
