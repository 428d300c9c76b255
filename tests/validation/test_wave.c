/* The wavefront path integrator (integrators/path.c, render.c):
 *  - a film is bitwise the same for 1, 2 and 3 threads (the Cornell box
 *    example, a gaussian filter across tiles, an area light; a periodic
 *    canopy, whose rays go through scene_trace one by one; every hot BSDF
 *    with a batched op (rpv, bilambertian, twosided, conductor,
 *    dielectric, roughconductor, diffuse) under each batched sensor:
 *    mdistant, distant, distantflux, radiancemeter, perspective);
 *  - a path's value does not depend on the wave it runs in: Li_batch over
 *    a batch of paths and the same batch split in two give bitwise the
 *    same values; Li one path at a time (single-ray Embree queries) the
 *    same for at least 99% of paths (Embree's single-ray kernel rounds a
 *    few hits differently, and such a path goes elsewhere from there on);
 *  - every Embree packet width the machine has (16, 8, 4 lanes, and 1:
 *    single rays) renders the same film statistically (means within 3
 *    standard errors) and nearly every pixel bitwise;
 *  - the --stats counters: camera rays = samples with a ray, tracing time
 *    within the thread time. */
#include <stdlib.h>
#include <string.h>

#include "../../server/kernel/accel.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static bool same_bits(const film_image *a, const film_image *b) {
  size_t n = (size_t)a->width * a->height * a->channels;
  return a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, n * sizeof(float)) == 0;
}

static const char *MIXED =
    "{\"type\": \"scene\","
    " \"cam\": {\"type\": \"perspective\", \"fov\": 45,"
    "   \"to_world\": [{\"lookat\": {\"origin\": [0, -4, 2], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 24, \"height\": 20}},"
    " \"integrator\": {\"type\": \"path\", \"max_depth\": 6, \"rr_depth\": 2},"
    " \"env\": {\"type\": \"constant\", \"radiance\": 0.5},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [1, 1, -2]},"
    " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 3}],"
    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": {\"type\": \"checkerboard\"}}},"
    " \"ball\": {\"type\": \"sphere\", \"center\": [0, 0, 0.6], \"radius\": 0.6,"
    "   \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": 0.2}},"
    " \"box\": {\"type\": \"cube\", \"to_world\": [{\"scale\": 0.3}, {\"translate\": [1, 0.5, 0.3]}],"
    "   \"bsdf\": {\"type\": \"dielectric\"}},"
    " \"lamp\": {\"type\": \"disk\", \"to_world\": [{\"scale\": 0.5}, {\"rotate\": {\"axis\": [1, 0, 0], "
    "\"angle\": 180}}, {\"translate\": [-1, 0, 2]}], \"emitter\": {\"type\": \"area\", \"radiance\": 4}}}";

static void check_threads(scene *s, uint32_t spp, const char *what) {
  film_image one, two, three;
  REQUIRE(tsup_render(s, spp, 5, 1, &one), "%s: 1 thread", what);
  REQUIRE(tsup_render(s, spp, 5, 2, &two), "%s: 2 threads", what);
  REQUIRE(tsup_render(s, spp, 5, 3, &three), "%s: 3 threads", what);
  CHECK(same_bits(&one, &two), "%s: 1 and 2 threads differ", what);
  CHECK(same_bits(&one, &three), "%s: 1 and 3 threads differ", what);
  film_image_free(&one);
  film_image_free(&two);
  film_image_free(&three);
}

static void test_threads_cornell(void) {
  scene *s = tsup_load_file("proto/examples/cornell_box.json", NULL);
  REQUIRE(s, "cornell_box.json");
  check_threads(s, 4, "cornell box");
  scene_free(s);
}

static void test_threads_periodic(void) {
  scene *s =
      tsup_load("{\"type\": \"scene\", \"variant\": \"mono\","
                " \"cam\": {\"type\": \"hdistant\", \"film\": {\"type\": \"hdrfilm\", \"width\": 12,"
                "   \"height\": 12, \"rfilter\": {\"type\": \"box\"}}},"
                " \"integrator\": {\"type\": \"path\", \"max_depth\": 5},"
                " \"periodic\": {\"type\": \"periodic\", \"min\": [-1, -1], \"max\": [1, 1]},"
                " \"sky\": {\"type\": \"constant\", \"radiance\": 0.2},"
                " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0.2, -1]},"
                " \"soil\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": "
                "0.3}},"
                " \"leaf\": {\"type\": \"disk\", \"to_world\": [{\"scale\": 0.4}, {\"translate\": [0.9, 0, "
                "0.5]}], \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}",
                NULL);
  REQUIRE(s, "periodic scene");
  check_threads(s, 32, "periodic");
  scene_free(s);
}

/* The hot plugins' batched ops (bsdf_ops.sample_batch / eval_pdf_batch,
 * sensor_ops.sample_ray_batch) in one scene, seen by each batched sensor:
 * the wave groups lanes differently for each thread count, and a lane's
 * value must not depend on its group. */
static const char *EO_SHAPES =
    " \"integrator\": {\"type\": \"path\", \"max_depth\": 6},"
    " \"sky\": {\"type\": \"constant\", \"radiance\": 0.3},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0.4, 0.3, -1], \"irradiance\": 2},"
    " \"soil\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 3}],"
    "   \"bsdf\": {\"type\": \"rpv\", \"rho_0\": 0.1, \"k\": 0.7, \"g\": -0.15, \"rho_c\": 0.3}},"
    " \"leaf\": {\"type\": \"disk\", \"to_world\": [{\"scale\": 0.5}, {\"rotate\": {\"axis\": [1, 0, 0],"
    "   \"angle\": 60}}, {\"translate\": [-0.8, 0.2, 0.8]}],"
    "   \"bsdf\": {\"type\": \"bilambertian\", \"reflectance\": 0.4, \"transmittance\": 0.45}},"
    " \"leaf2\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 0.4}, {\"rotate\": {\"axis\": [0, 1, "
    "0],"
    "   \"angle\": 120}}, {\"translate\": [0.9, -0.6, 0.7]}],"
    "   \"bsdf\": {\"type\": \"twosided\", \"a\": {\"type\": \"diffuse\", \"reflectance\": 0.6},"
    "     \"b\": {\"type\": \"roughconductor\", \"alpha\": 0.3}}},"
    " \"ball\": {\"type\": \"sphere\", \"center\": [0.6, 0.8, 0.5], \"radius\": 0.4,"
    "   \"bsdf\": {\"type\": \"twosided\", \"c\": {\"type\": \"conductor\", \"material\": \"Au\"}}},"
    " \"box\": {\"type\": \"cube\", \"to_world\": [{\"scale\": 0.3}, {\"translate\": [-0.5, -0.9, 0.3]}],"
    "   \"bsdf\": {\"type\": \"dielectric\"}}}";

static void test_threads_batched_plugins(void) {
  static const char *const sensors[][2] = {
      {"mdistant", "{\"type\": \"mdistant\", \"directions\": \"0 0 -1, 0.5 0.1 -1, -1 0.3 -0.6, 0.2 1 -0.3\","
                   " \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 1}}"},
      {"distant", "{\"type\": \"distant\", \"direction\": [0.3, -0.2, -1],"
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}"},
      {"distantflux", "{\"type\": \"distantflux\", \"film\": {\"type\": \"hdrfilm\", \"width\": 8,"
                      " \"height\": 6}}"},
      {"radiancemeter", "{\"type\": \"radiancemeter\", \"origin\": [0, 0, 3], \"direction\": [0.1, 0.2, -1],"
                        " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}"},
      {"perspective", "{\"type\": \"perspective\", \"fov\": 50, \"to_world\": [{\"lookat\": {\"origin\":"
                      " [1, -4, 3], \"target\": [0, 0, 0.3], \"up\": [0, 0, 1]}}],"
                      " \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 12}}"},
  };
  for (size_t i = 0; i < sizeof sensors / sizeof sensors[0]; i++) {
    char doc[4096];
    snprintf(doc, sizeof doc, "{\"type\": \"scene\", \"cam\": %s,%s", sensors[i][1], EO_SHAPES);
    scene *s = tsup_load(doc, NULL);
    REQUIRE(s, "%s scene", sensors[i][0]);
    const sensor *se = s->sensors[0];
    CHECK(se->ops->sample_ray_batch, "%s has a batched op", sensors[i][0]);
    uint32_t spp = se->film->width * se->film->height > 16 ? 16 : 512;
    check_threads(s, spp, sensors[i][0]);
    scene_free(s);
  }
}

/* Camera rays and sampler states of samples 0..n-1 of pixel 7, as render.c
 * makes them (film jitter, aperture, then the integrator's draws). */
static int camera_rays(const scene *s, int n, sampler_state *st, ray3 *rays) {
  const sensor *se = s->sensors[0];
  const sampler *smp = se->sampler;
  int m = 0;
  for (int i = 0; i < n; i++) {
    uint64_t pixel = (uint64_t)(i % 97) * 5 + 3;
    int ix = (int)(pixel % (uint64_t)se->film->width), iy = (int)(pixel / (uint64_t)se->film->width);
    smp->ops->start(smp, &st[m], 11, pixel, (uint32_t)i, (uint32_t)n);
    vec2 j = smp->ops->next_2d(&st[m]);
    vec2 fu = v2((ix + j.x) / se->film->width, (iy + j.y) / se->film->height);
    vec2 ap = smp->ops->next_2d(&st[m]);
    if (se->ops->sample_ray(se, fu, ap, &rays[m]) != 0) m++;
  }
  return m;
}

static void test_batch_independent(void) {
  scene *s = tsup_load(MIXED, NULL);
  REQUIRE(s, "scene");
  film_image warm;
  REQUIRE(tsup_render(s, 1, 1, 1, &warm), "prepare"); /* scene_prepare before calling ops directly */
  film_image_free(&warm);
  enum {
    N = 600
  };
  sampler_state *st0 = malloc(N * sizeof *st0), *st = malloc(N * sizeof *st);
  ray3 *rays = malloc(N * sizeof *rays);
  color *La = malloc(N * sizeof *La), *Lb = malloc(N * sizeof *Lb), *Lc = malloc(N * sizeof *Lc);
  REQUIRE(st0 && st && rays && La && Lb && Lc, "memory");
  int n = camera_rays(s, N, st0, rays);
  REQUIRE(n > N / 2, "camera rays");
  const integrator *it = s->integrator;
  render_stats rs = {0};
  memcpy(st, st0, (size_t)n * sizeof *st);
  REQUIRE(it->ops->Li_batch(it, s, st, rays, n, &rs, La, NULL), "batch");
  CHECK(rs.rays >= (uint64_t)n, "rays counted: %llu", (unsigned long long)rs.rays);
  memcpy(st, st0, (size_t)n * sizeof *st);
  int half = n / 3;
  REQUIRE(it->ops->Li_batch(it, s, st, rays, half, &rs, Lb, NULL), "batch a");
  REQUIRE(it->ops->Li_batch(it, s, st + half, rays + half, n - half, &rs, Lb + half, NULL), "batch b");
  memcpy(st, st0, (size_t)n * sizeof *st);
  for (int i = 0; i < n; i++) Lc[i] = it->ops->Li(it, s, &st[i], rays[i], &rs, NULL);
  int same_ab = 0, same_ac = 0;
  double sa = 0, sc = 0;
  for (int i = 0; i < n; i++) {
    same_ab += memcmp(&La[i], &Lb[i], sizeof La[i]) == 0;
    same_ac += memcmp(&La[i], &Lc[i], sizeof La[i]) == 0;
    sa += La[i].c[0] + La[i].c[1] + La[i].c[2];
    sc += Lc[i].c[0] + Lc[i].c[1] + Lc[i].c[2];
  }
  printf("  %d paths: %d bitwise equal split in two batches, %d one by one (single-ray queries)\n", n,
         same_ab, same_ac);
  CHECK(same_ab >= n - n / 100, "regrouped batches: only %d of %d paths equal", same_ab, n);
  CHECK(same_ac >= n - n / 100, "one path at a time: only %d of %d paths equal", same_ac, n);
  /* A path whose hit rounds differently goes elsewhere from there on (a
   * dielectric's branch, the roulette): its value is another sample of the
   * same estimator, so the sums agree statistically only. */
  printf("  sums %.6f (batch) and %.6f (one by one)\n", sa, sc);
  CHECK(same_ab == n, "regrouped batches must not change a path (packets of the same width): %d of %d",
        same_ab, n);
  free(st0), free(st), free(rays), free(La), free(Lb), free(Lc);
  scene_free(s);
}

static void test_packet_widths(void) {
  scene *s = tsup_load(MIXED, NULL);
  REQUIRE(s, "scene");
  int native = accel_packet_width();
  printf("  native packet width: %d\n", native);
  film_image ref;
  REQUIRE(tsup_render(s, 16, 3, 2, &ref), "native");
  double m0, e0;
  tsup_stats(&ref, 0, &m0, &e0);
  static const int widths[] = {1, 4, 8, 16};
  for (size_t k = 0; k < sizeof widths / sizeof *widths; k++) {
    if (widths[k] > native) continue;
    accel_set_packet_width(widths[k]);
    CHECK(accel_packet_width() == widths[k], "pinned %d, got %d", widths[k], accel_packet_width());
    film_image img;
    bool ok = tsup_render(s, 16, 3, 2, &img);
    accel_set_packet_width(0);
    REQUIRE(ok, "width %d", widths[k]);
    double m, e;
    tsup_stats(&img, 0, &m, &e);
    size_t n = (size_t)img.width * img.height * img.channels, same = 0;
    for (size_t i = 0; i < n; i++) same += memcmp(&img.data[i], &ref.data[i], sizeof(float)) == 0;
    printf("  width %2d: mean %.6f (native %.6f), %zu of %zu values bitwise equal\n", widths[k], m, m0, same,
           n);
    CHECK(fabs(m - m0) <= 3 * sqrt(e * e + e0 * e0) + 1e-12, "width %d: mean %.6f vs %.6f", widths[k], m, m0);
    /* Embree's packet kernels of 4, 8 and 16 lanes round alike here
     * (observed: bitwise-equal films); its single-ray kernel rounds some
     * hits differently, and a path that differs once goes elsewhere. */
    size_t want = widths[k] == 1 ? n * 3 / 4 : n * 9 / 10;
    CHECK(same >= want, "width %d: only %zu of %zu values equal", widths[k], same, n);
    film_image_free(&img);
  }
  CHECK(accel_packet_width() == native, "pin released");
  film_image_free(&ref);
  scene_free(s);
}

static void test_stats_counters(void) {
  scene *s = tsup_load(MIXED, NULL);
  REQUIRE(s, "scene");
  render_opts o = {.size = sizeof o, .spp = 8, .seed = 1, .threads = 2};
  film_image img;
  render_result_stats st;
  rsw_err err = {0};
  REQUIRE(render_sensor(s, &o, &img, &st, &err) == RSW_OK, "render: %s", err.msg);
  CHECK(st.rays.camera_rays == st.samples,
        "camera rays %llu, samples %llu (every perspective ray has weight)",
        (unsigned long long)st.rays.camera_rays, (unsigned long long)st.samples);
  CHECK(st.rays.rays > st.rays.camera_rays, "continuation rays");
  CHECK(st.rays.trace_s > 0 && st.rays.trace_s <= st.busy_s, "trace %.6f s of busy %.6f s", st.rays.trace_s,
        st.busy_s);
  char line[600];
  render_stats_line(&st, line, sizeof line);
  CHECK(strstr(line, "camera") && strstr(line, "shadow") && strstr(line, "tracing"), "stats line: %s", line);
  film_image_free(&img);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_threads_cornell);
  RSW_TEST_RUN(test_threads_periodic);
  RSW_TEST_RUN(test_threads_batched_plugins);
  RSW_TEST_RUN(test_batch_independent);
  RSW_TEST_RUN(test_packet_widths);
  RSW_TEST_RUN(test_stats_counters);
  RSW_TEST_END("test_wave");
}
