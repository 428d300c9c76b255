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
 *    within the thread time;
 *  - the wave's batched ops give each lane bitwise what its per-lane call
 *    gives, at every ISA the CPU has: the samplers' start/next_1d/next_2d
 *    batches (independent, stratified; any subset and order of lanes; a
 *    1-D then a 2-D number per lane), the
 *    emitters' sample_direction_batch or its fallback (directional,
 *    constant, area), the
 *    hits' shading frames (shape_frames_batch, edge cases included), the
 *    batched hit fill against the scalar one (hit_fill_interaction_batch,
 *    cached meshes and other shapes mixed); the
 *    batched draws pass a chi-square test of uniformity, the constant
 *    emitter's batched directions one against its pdf_direction (the area
 *    emitter's: tests/kernel/emitters/test_area_light.c);
 *    a stratified film is bitwise the same for 1, 2 and 3 threads;
 *  - the wave's shortcuts give what they replace: the emitter pick by a
 *    count (a few emitters) the binary search's pick, the batched ray
 *    culls (rays_traced_batch) the scalar verdicts at every ISA, the
 *    shadow rays towards surface emitters in lanes
 *    (spawn_rays_between_batch) spawn_ray_between's at every ISA. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/accel.h"
#include "../../../server/kernel/core/isa.h"
#include "../../../server/kernel/hit.h"
#include "../../../server/kernel/integrators/cull.h"
#include "../../../server/kernel/integrators/integrator.h"
#include "../../../server/kernel/samplers/sampler_batch.h"
#include "../../../server/kernel/shapes/instance.h"
#include "../../../server/kernel/shapes/shape.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

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

/* ---- the wave's batched ops, lane by lane ------------------------------------ */

static const char *sampler_scene(const char *type) {
  static char buf[700];
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"hdistant\", \"sampler\": {\"type\": \"%s\", \"sample_count\": 49},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 10, \"height\": 6, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\", \"max_depth\": 4},"
      " \"sky\": {\"type\": \"constant\", \"radiance\": 0.3},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [1, 0.5, -1]},"
      " \"floor\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": 0.3}}}",
      type);
  return buf;
}

static bool same_state(const sampler_state *a, const sampler_state *b) {
  return a->s == b->s && a->rng.state == b->rng.state && a->rng.inc == b->rng.inc &&
         a->pixel_key == b->pixel_key && a->sample_index == b->sample_index && a->spp == b->spp &&
         a->dim == b->dim;
}

/* start_batch, then batched draws over changing subsets of lanes in
 * changing orders, against the per-lane ops, at spp samples per pixel
 * (49: the stratified permutation walks cycles; 64: a power of two, its
 * one-round path). */
static void check_sampler_batches(const sampler *smp, const char *what, uint32_t spp) {
  enum {
    N = 77
  };
  sampler_state a[N], b[N];
  uint64_t pixel[N];
  uint32_t index[N];
  for (int k = 0; k < N; k++) pixel[k] = 1000 + (uint64_t)(k / 9), index[k] = (uint32_t)(k * 5 % spp);
  sampler_start_batch(smp, a, N, 3, pixel, index, spp);
  for (int k = 0; k < N; k++) smp->ops->start(smp, &b[k], 3, pixel[k], index[k], spp);
  int bad = 0;
  for (int k = 0; k < N; k++) bad += !same_state(&a[k], &b[k]);
  CHECK(bad == 0, "%s: start_batch differs in %d of %d lanes", what, bad, N);
  int idx[N];
  double d1[N];
  vec2 d2[N];
  for (int round = 0; round < 16; round++) {
    int n = 0; /* a subset, in a scrambled order */
    for (int k = 0; k < N; k++) {
      int i = (k * 31 + round * 7) % N;
      if ((i + round) % 3 != 0) idx[n++] = i;
    }
    const int *use = round % 4 == 0 ? NULL : idx;
    int m = use ? n : N;
    /* 1-D, 2-D, a 1-D then a 2-D number per lane, or two 2-D numbers */
    int kind = round % 5 == 4 ? 3 : round % 3; /* (round 4: every lane in order) */
    vec2 e2[N];
    if (kind == 3)
      sampler_next_2d_2d_batch(smp, a, use, m, d2, e2);
    else if (kind == 1)
      sampler_next_2d_batch(smp, a, use, m, d2);
    else if (kind == 0)
      sampler_next_1d_batch(smp, a, use, m, d1);
    else
      sampler_next_1d_2d_batch(smp, a, use, m, d1, d2);
    for (int k = 0; k < m; k++) {
      sampler_state *q = &b[use ? use[k] : k];
      if (kind == 0 || kind == 2) {
        double v = smp->ops->next_1d(q);
        bad += memcmp(&v, &d1[k], sizeof v) != 0;
      }
      if (kind != 0) {
        vec2 v = smp->ops->next_2d(q);
        bad += memcmp(&v, &d2[k], sizeof v) != 0;
      }
      if (kind == 3) {
        vec2 v = smp->ops->next_2d(q);
        bad += memcmp(&v, &e2[k], sizeof v) != 0;
      }
    }
  }
  for (int k = 0; k < N; k++) bad += !same_state(&a[k], &b[k]);
  CHECK(bad == 0, "%s: batched draws differ from per-lane draws (%d mismatches)", what, bad);
}

static void test_sampler_batches(void) {
  static const char *types[] = {"independent", "stratified"};
  for (size_t t = 0; t < 2; t++) {
    scene *s = tsup_load(sampler_scene(types[t]), NULL);
    REQUIRE(s, "%s scene", types[t]);
    const sampler *smp = s->sensors[0]->sampler;
    CHECK(smp->ops->start_batch && smp->ops->next_1d_batch && smp->ops->next_2d_batch, "%s has batch ops",
          types[t]);
    CHECK(smp->ops->next_2d_2d_batch && smp->ops->next_1d_2d_batch, "%s has the paired batches", types[t]);
    for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
      if (!rsw_isa_set((rsw_isa)isa)) continue;
      char what[64];
      snprintf(what, sizeof what, "%s at %s, spp 49", types[t], rsw_isa_name((rsw_isa)isa));
      check_sampler_batches(smp, what, 49);
      snprintf(what, sizeof what, "%s at %s, spp 64", types[t], rsw_isa_name((rsw_isa)isa));
      check_sampler_batches(smp, what, 64);
    }
    rsw_isa_set(rsw_isa_best());
    if (t == 1) check_threads(s, 49, "stratified sampler");
    scene_free(s);
  }
}

/* The batched draws of the independent sampler are uniform on [0,1)^2:
 * 16 x 16 cells, 2^18 draws (many samples of a few pixels, each sample
 * drawing a few numbers), Pearson's chi-square with 255 degrees of
 * freedom at significance 0.01. */
static void test_sampler_batch_chi2(void) {
  scene *s = tsup_load(sampler_scene("independent"), NULL);
  REQUIRE(s, "scene");
  const sampler *smp = s->sensors[0]->sampler;
  enum {
    B = 16,
    N = 256,
    ROUNDS = 256
  };
  static double count[B * B];
  memset(count, 0, sizeof count);
  sampler_state st[N];
  uint64_t pixel[N];
  uint32_t index[N];
  vec2 u[N];
  double total = 0;
  for (int r = 0; r < ROUNDS; r++) {
    for (int k = 0; k < N; k++) pixel[k] = (uint64_t)r, index[k] = (uint32_t)k;
    sampler_start_batch(smp, st, N, 5, pixel, index, N);
    for (int j = 0; j < 4; j++) {
      sampler_next_2d_batch(smp, st, NULL, N, u);
      for (int k = 0; k < N; k++) {
        int cx = (int)(u[k].x * B), cy = (int)(u[k].y * B);
        CHECK(cx >= 0 && cx < B && cy >= 0 && cy < B, "draw outside [0,1)^2: %g %g", u[k].x, u[k].y);
        if (cx >= 0 && cx < B && cy >= 0 && cy < B) count[cy * B + cx]++, total++;
      }
    }
  }
  double expect = total / (B * B), x2 = 0;
  for (int c = 0; c < B * B; c++) x2 += (count[c] - expect) * (count[c] - expect) / expect;
  double p = 1.0 - chi2_gamma_p(0.5 * (B * B - 1), 0.5 * x2);
  printf("  batched draws: chi2 %.1f (255 dof), p = %.3f\n", x2, p);
  CHECK(p > 0.01, "batched independent draws are not uniform: chi2 %.1f, p %.4f", x2, p);
  scene_free(s);
}

static bool same_ds(const direction_sample *a, const direction_sample *b) {
  return memcmp(&a->p, &b->p, sizeof a->p) == 0 && memcmp(&a->n, &b->n, sizeof a->n) == 0 &&
         memcmp(&a->d, &b->d, sizeof a->d) == 0 && memcmp(&a->dist, &b->dist, sizeof a->dist) == 0 &&
         memcmp(&a->pdf, &b->pdf, sizeof a->pdf) == 0 && a->delta == b->delta;
}

/* Every emitter of MIXED with a batched op: lanes at random reference
 * points, batched against per-lane sample_direction(). */
static void test_emitter_batches(void) {
  scene *s = tsup_load(MIXED, NULL);
  REQUIRE(s, "scene");
  film_image warm;
  REQUIRE(tsup_render(s, 1, 1, 1, &warm), "prepare");
  film_image_free(&warm);
  enum {
    N = 70
  };
  surface_interaction si[N];
  const surface_interaction *ref[N];
  vec2 u[N];
  pcg32 rng;
  pcg32_seed(&rng, 17, 5);
  memset(si, 0, sizeof si);
  for (int k = 0; k < N; k++) {
    si[k].p = v3(4 * pcg32_next_double(&rng) - 2, 4 * pcg32_next_double(&rng) - 2, pcg32_next_double(&rng));
    si[k].ng = si[k].sh.n = v3(0, 0, 1);
    ref[k] = &si[k];
    u[k] = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
  }
  int tested = 0;
  for (size_t e_i = 0; e_i < s->n_emitters; e_i++) {
    const emitter *e = s->emitters[e_i];
    direction_sample ds[N], one;
    color v[N];
    emitter_sample_direction_n(e, N, ref, u, ds, v);
    int bad = 0;
    for (int k = 0; k < N; k++) {
      memset(&one, 0, sizeof one);
      color w = e->ops->sample_direction(e, ref[k], u[k], &one);
      bad += memcmp(&w, &v[k], sizeof w) != 0 || (ds[k].pdf > 0 && !same_ds(&one, &ds[k]));
    }
    CHECK(bad == 0, "emitter %s: batched samples differ in %d of %d lanes", e->base.plugin->name, bad, N);
    tested++;
  }
  CHECK(tested == 3, "directional, constant and area tested (%d)", tested);
  scene_free(s);
}

/* chi2 of an emitter's batched direction sampling from a fixed point. */
typedef struct emitter_chi2 {
  const emitter *e;
  surface_interaction ref;
} emitter_chi2;

static bool emitter_chi2_sample(void *user, const double *u, vec3 *out, double *weight) {
  emitter_chi2 *c = user;
  const surface_interaction *ref = &c->ref;
  vec2 uu = v2(u[0], u[1]);
  direction_sample ds;
  color v;
  emitter_sample_direction_n(c->e, 1, &ref, &uu, &ds, &v);
  if (!(ds.pdf > 0)) return false;
  *out = ds.d;
  *weight = 1;
  return true;
}

/* The constant emitter's density: uniform on the sphere. */
static double emitter_chi2_pdf(void *user, vec3 d) {
  emitter_chi2 *c = user;
  direction_sample ds = {.d = d, .dist = INFINITY};
  return c->e->ops->pdf_direction(c->e, &c->ref, &ds);
}

static void test_emitter_batch_chi2(void) {
  scene *s = tsup_load(MIXED, NULL);
  REQUIRE(s, "scene");
  film_image warm;
  REQUIRE(tsup_render(s, 1, 1, 1, &warm), "prepare");
  film_image_free(&warm);
  int tested = 0;
  for (size_t e_i = 0; e_i < s->n_emitters; e_i++) {
    const emitter *e = s->emitters[e_i];
    /* The area light's batched op is tested against its density in
     * tests/kernel/emitters/test_area_light.c. */
    if (!(e->flags & EMITTER_INFINITE)) continue;
    emitter_chi2 c = {.e = e};
    c.ref.p = v3(-0.95, 0.05, 1.85);
    c.ref.ng = c.ref.sh.n = v3(0, 0, 1);
    chi2_config cfg = chi2_defaults(CHI2_SPHERE, 2);
    cfg.sample_count = 1000000;
    chi2_result r = chi2_run(&cfg, emitter_chi2_sample, emitter_chi2_pdf, &c);
    printf("  %s batched directions: chi2 p = %.3f%s%s\n", e->base.plugin->name, r.p_value,
           r.passed ? "" : ": ", r.passed ? "" : r.reason);
    CHECK(r.passed, "%s batched direction sampling fails chi-square: %s", e->base.plugin->name, r.reason);
    tested++;
  }
  CHECK(tested == 1, "constant tested (%d)", tested);
  scene_free(s);
}

/* shape_frames_batch against shape_frame_from_tangent and the scalar wi,
 * lane by lane, with the edge cases: no tangent, a tangent along the
 * normal, a zero direction, deferred normals (one too short to keep). */
static void test_frames_batch(void) {
  enum {
    N = 61,
    S = 64
  };
  static double in[SHAPE_FRAME_IN * S], out[12 * S];
  vec3 sn[N], tg[N], d[N], raw[N];
  bool def[N];
  pcg32 rng;
  pcg32_seed(&rng, 23, 9);
  for (int k = 0; k < N; k++) {
    vec3 a =
        v3(2 * pcg32_next_double(&rng) - 1, 2 * pcg32_next_double(&rng) - 1, 2 * pcg32_next_double(&rng) - 1);
    sn[k] = v3_norm(a);
    tg[k] = v3(3 * pcg32_next_double(&rng) - 1.5, pcg32_next_double(&rng), pcg32_next_double(&rng) - 0.5);
    d[k] = v3(pcg32_next_double(&rng) - 0.5, pcg32_next_double(&rng) - 0.5, -pcg32_next_double(&rng));
    raw[k] = v3_scale(v3(pcg32_next_double(&rng), pcg32_next_double(&rng) - 0.5, 1), 0.3 + k % 3);
    def[k] = k % 4 == 1;
    if (k % 7 == 0) tg[k] = v3(0, 0, 0);
    if (k % 7 == 3) tg[k] = v3_scale(sn[k], 2.5);
    if (k == 5) d[k] = v3(0, 0, 0);
    if (k == 9) raw[k] = v3(1e-200, 0, 0), def[k] = true;
    if (k == 13) sn[k] = v3(0, 0, -1);
    const double v[SHAPE_FRAME_IN] = {sn[k].x, sn[k].y, sn[k].z,  tg[k].x,  tg[k].y,  tg[k].z,       d[k].x,
                                      d[k].y,  d[k].z,  raw[k].x, raw[k].y, raw[k].z, def[k] ? 1 : 0};
    for (int c = 0; c < SHAPE_FRAME_IN; c++) in[c * S + k] = v[c];
  }
  for (int k = N; k < S; k++)
    for (int c = 0; c < SHAPE_FRAME_IN; c++) in[c * S + k] = 0;
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    shape_frames_batch(N, S, in, out);
    int bad = 0;
    for (int k = 0; k < N; k++) {
      vec3 n = sn[k];
      if (def[k]) { /* as mesh_fill_inline makes an interpolated normal */
        vec3 q = v3_norm(raw[k]);
        if (v3_len2(q) > 0.5) n = q;
      }
      frame f = shape_frame_from_tangent(n, tg[k]);
      vec3 wi = frame_to_local(&f, v3_neg(v3_norm(d[k])));
      const double want[12] = {f.s.x, f.s.y, f.s.z, f.t.x, f.t.y, f.t.z,
                               f.n.x, f.n.y, f.n.z, wi.x,  wi.y,  wi.z};
      for (int c = 0; c < 12; c++) bad += memcmp(&want[c], &out[c * S + k], sizeof(double)) != 0;
    }
    CHECK(bad == 0, "%s: shape_frames_batch differs from the scalar fill in %d values",
          rsw_isa_name((rsw_isa)isa), bad);
  }
  rsw_isa_set(rsw_isa_best());
}

/* hit_fill_interaction_batch against hit_fill_interaction, lane by lane
 * and bit for bit, at every ISA: cached meshes (shape_mesh_hits_batch:
 * vertex normals and uv, uv only (an OBJ with face_normals), flip_normals, rotated
 * and scaled, filled face by face or, a larger mesh, lane by lane) mixed in one batch with the other shapes' hits (a sphere, a
 * disk, an instanced rectangle). */
static void test_hits_batch(void) {
  /* A wavy 10 x 10 grid (162 faces: filled lane by lane), with vertex
   * normals and uv, as an OBJ file. */
  char obj[] = "/tmp/rsw_test_hits_XXXXXX.obj";
  int fd = mkstemps(obj, 4);
  REQUIRE(fd >= 0, "temporary OBJ");
  FILE *f = fdopen(fd, "w");
  REQUIRE(f, "temporary OBJ");
  for (int j = 0; j < 10; j++)
    for (int i = 0; i < 10; i++) {
      double x = i / 4.5 - 1, y = j / 4.5 - 1, z = 0.1 * sin(3 * x) * cos(2 * y);
      fprintf(f, "v %.6f %.6f %.6f\nvt %.4f %.4f\nvn %.5f %.5f 1\n", x, y, z, i / 9.0, j / 9.0,
              -0.3 * cos(3 * x) * cos(2 * y), 0.2 * sin(3 * x) * sin(2 * y));
    }
  for (int j = 0; j < 9; j++)
    for (int i = 0; i < 9; i++) {
      int a = 1 + j * 10 + i, b = a + 1, c = a + 10, d = c + 1;
      fprintf(f, "f %d/%d/%d %d/%d/%d %d/%d/%d\nf %d/%d/%d %d/%d/%d %d/%d/%d\n", a, a, a, b, b, b, d, d, d, a,
              a, a, d, d, d, c, c, c);
    }
  fclose(f);
  static const char *HITS =
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"perspective\", \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4}},"
      " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [3, 2, 1]}, {\"rotate\": {\"axis\": "
      "[1, 1, 0],"
      " \"angle\": 20}}, {\"translate\": [0.1, -0.2, -0.3]}]},"
      " \"flat\": {\"type\": \"obj\", \"filename\": \"tests/data/quad.obj\", \"face_normals\": true,"
      " \"to_world\": [{\"scale\": 0.7},"
      " {\"translate\": [0.5, 0.3, 0.9]}]},"
      " \"flipped\": {\"type\": \"rectangle\", \"flip_normals\": true, \"to_world\": [{\"rotate\": "
      "{\"axis\": [0, 1,"
      " 0], \"angle\": 100}}, {\"translate\": [-1.2, 0, 0.5]}]},"
      " \"box\": {\"type\": \"cube\", \"to_world\": [{\"scale\": 0.3}, {\"translate\": [1, 0.5, 0.3]}]},"
      " \"grid\": {\"type\": \"obj\", \"filename\": \"%s\", \"to_world\": [{\"scale\": [0.8, 0.6, 1]}, "
      "{\"rotate\":"
      " {\"axis\": [0, 1, 1], \"angle\": 30}}, {\"translate\": [0.4, 0.4, 1.4]}]},"
      " \"ball\": {\"type\": \"sphere\", \"center\": [-0.3, 0.8, 0.4], \"radius\": 0.3},"
      " \"lid\": {\"type\": \"disk\", \"to_world\": [{\"translate\": [0.8, -0.9, 0.6]}]},"
      " \"group\": {\"type\": \"shapegroup\", \"leaf\": {\"type\": \"rectangle\"}},"
      " \"copy\": {\"type\": \"instance\", \"shapegroup\": {\"type\": \"ref\", \"id\": \"group\"},"
      " \"to_world\": [{\"scale\": 0.4}, {\"translate\": [-0.5, -0.8, 1.1]}]}}";
  char text[4096];
  snprintf(text, sizeof text, HITS, obj);
  scene *s = tsup_load(text, NULL);
  remove(obj);
  REQUIRE(s, "scene");
  film_image warm;
  REQUIRE(tsup_render(s, 1, 1, 1, &warm), "prepare");
  film_image_free(&warm);
  enum {
    N = 200
  };
  static ray3 rays[N];
  static accel_hit h[N];
  static surface_interaction one[N], many[N];
  const ray3 *rp[N];
  const accel_hit *hp[N];
  surface_interaction *sp[N];
  pcg32 rng;
  pcg32_seed(&rng, 7, 3);
  int n = 0, cached = 0, large = 0, tries = 0;
  /* The first 64 rays from above the floor's far corner (many on one
   * face of it: that face's hits filled with its data given once), the
   * rest from anywhere. */
  int floor_face[2] = {0, 0};
  while (n < N && tries++ < 100 * N) {
    vec3 o =
        v3(4 * pcg32_next_double(&rng) - 2, 4 * pcg32_next_double(&rng) - 2, 3 * pcg32_next_double(&rng));
    vec3 t =
        v3(2 * pcg32_next_double(&rng) - 1, 2 * pcg32_next_double(&rng) - 1, pcg32_next_double(&rng) - 0.2);
    if (n < 64) o = v3(-2.5, -1.5, 2), t = v3(-2.2 + 0.6 * t.x, -1.5 + 0.5 * t.y, -1);
    ray3 r = {o, v3_scale(v3_sub(t, o), 0.5 + pcg32_next_double(&rng)), 0, INFINITY};
    if (!accel_intersect(s->accel, &r, &h[n])) continue;
    rays[n] = r;
    const shape *top = s->shapes[h[n].shape];
    cached += top->face_cache != NULL && !shape_is_instancing(top);
    large += top->face_cache != NULL && top->mesh.n_faces > 64;
    if (n < 64 && h[n].shape == s->shapes[0]->index) floor_face[h[n].prim & 1]++;
    n++;
  }
  REQUIRE(n == N, "%d hits", n);
  CHECK(floor_face[0] >= 8 || floor_face[1] >= 8, "8 hits on one face of the floor (%d, %d)", floor_face[0],
        floor_face[1]);
  CHECK(cached > N / 3 && cached < N - 10 && large > 10,
        "a mix of cached meshes (small and large) and other hits (%d cached, %d on the grid)", cached, large);
  for (int k = 0; k < N; k++) {
    memset(&one[k], 0, sizeof one[k]);
    hit_fill_interaction(s, &rays[k], &h[k], &one[k]);
    rp[k] = &rays[k], hp[k] = &h[k], sp[k] = &many[k];
  }
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    memset(many, 0, sizeof many);
    hit_fill_interaction_batch(s, N, rp, hp, sp);
    int bad = 0;
    for (int k = 0; k < N; k++) bad += memcmp(&one[k], &many[k], sizeof one[k]) != 0;
    CHECK(bad == 0, "%s: hit_fill_interaction_batch differs from hit_fill_interaction in %d of %d hits",
          rsw_isa_name((rsw_isa)isa), bad, N);
  }
  rsw_isa_set(rsw_isa_best());
  scene_free(s);
}

/* shape_mesh_hits_batch with one face's data given once, where the face's
 * frame is reused while a vector's lanes repeat the normal and tangent
 * it was made from (frame_lanes.h), against the same lanes with the
 * face's data in every lane (every frame computed; test_hits_batch checks
 * that against the scalar fill), bit for bit at every ISA: a flat face
 * (equal vertex normals: the frame reused, but where an interpolated
 * normal comes out an ulp off), a bent one (the normal differs from lane
 * to lane: a frame reused wrongly shows), a face without dp/du, each with
 * and without vertex normals, flipped or not, n not a multiple of any
 * vector width. */
static void test_hits_frame_reuse(void) {
  enum {
    S = 64,
    N = 61
  };
  static const double faces[3][SHAPE_MH_IN_D - 2] = {
      /* p0, p1, p2; na, nb, nc; uv a, b, c; n; dp/du */
      {-1, -1, 0, 1, -1, 0, 1, 1, 0, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 1, 1, 0, 0, 1, 2, 0, 0},
      {0,   0,   0.5, 1, 0, 0.3, 0, 1, 0.2, 0.1,  -0.2, 1,    -0.3, 0.1, 0.9,
       0.2, 0.3, 1.1, 0, 0, 1,   0, 0, 1,   -0.3, -0.2, 0.93, 1,    0,   0.2},
      {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0},
  };
  double k[SHAPE_MH_K] = {0};
  for (int i = 0; i < 4; i++) k[SHAPE_MH_M + 5 * i] = 1;
  for (int i = 0; i < 3; i++) k[SHAPE_MH_INV + 4 * i] = 1;
  k[SHAPE_MH_M + 3] = 0.25, k[SHAPE_MH_C] = 0.1, k[SHAPE_MH_TC] = 0.5, k[SHAPE_MH_EXT] = 2;
  for (int i = 0; i < 3; i++) k[SHAPE_MH_S + i] = 0.5 + i;
  static double in[SHAPE_MH_IN * S], a[SHAPE_MH_OUT * S], b[SHAPE_MH_OUT * S];
  pcg32 rng;
  pcg32_seed(&rng, 11, 5);
  int cases = 0;
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    for (int f = 0; f < 3; f++)
      for (int nrm = 0; nrm < 2; nrm++)
        for (int flip = 0; flip < 2; flip++) {
          k[SHAPE_MH_NRM] = nrm, k[SHAPE_MH_UV] = 1, k[SHAPE_MH_FLIP] = flip;
          memset(in, 0, sizeof in);
          for (int j = 0; j < N; j++) {
            /* Barycentrics summing to 1 exactly in most lanes (the
             * interpolated normal then the vertices'), random in some. */
            double u = (j % 5 == 4) ? pcg32_next_double(&rng) * 0.5 : 0.125 * (j % 4);
            double v = (j % 5 == 4) ? pcg32_next_double(&rng) * 0.5 : 0.25 * (j % 3);
            in[j] = u, in[S + j] = v;
            for (int c = 2; c < SHAPE_MH_IN_D; c++) in[c * S + j] = faces[f][c - 2];
            for (int c = 0; c < 3; c++) in[(SHAPE_MH_IN_D + c) * S + j] = pcg32_next_double(&rng) - 0.5;
          }
          memset(a, 0, sizeof a);
          memset(b, 0, sizeof b);
          shape_mesh_hits_batch(N, S, k, NULL, in, a);
          shape_mesh_hits_batch(N, S, k, faces[f], in, b);
          int bad = 0;
          for (int c = 0; c < SHAPE_MH_OUT; c++)
            for (int j = 0; j < N; j++) bad += memcmp(&a[c * S + j], &b[c * S + j], sizeof a[0]) != 0;
          CHECK(bad == 0, "%s, face %d, normals %d, flip %d: %d values differ", rsw_isa_name((rsw_isa)isa), f,
                nrm, flip, bad);
          cases++;
        }
  }
  rsw_isa_set(rsw_isa_best());
  CHECK(cases >= 12, "%d cases", cases);
}

/* pick_emitter_index against the binary search it replaces for a few
 * emitters (the first k < n - 1 with cdf[k] > t, else n - 1): every
 * count of emitters on both sides of PICK_COUNT_MAX, weights with zeros
 * (equal cdf entries), an infinite one, and u at 0, at every cdf entry,
 * one ulp either side, and a NaN. */
static size_t pick_by_search(const scene *sc, double u) {
  double t = u * sc->emitter_weight_sum;
  size_t lo = 0, hi = sc->n_emitters - 1;
  while (lo < hi) {
    size_t mid = (lo + hi) / 2;
    if (sc->emitter_cdf[mid] <= t)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

static void test_pick_emitter(void) {
  enum {
    NMAX = PICK_COUNT_MAX + 4
  };
  const double weight_sets[][NMAX] = {{1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1},
                                      {0.3, 0, 0, 2, 0.1, 0, 5, 1e-9, 0, 0.7, 0, 3},
                                      {0, 0, 1, 0, 0, 1, 0, 0, 0, 1, 0, 0},
                                      {2, INFINITY, 1, 0, 1, 1, 1, 1, 1, 1, 1, 1},
                                      {1e-300, 1, 1e300, 1, 0, 0, 0, 0, 0, 2, 0, 0}};
  int bad = 0, tried = 0, counted = 0;
  for (size_t w = 0; w < sizeof weight_sets / sizeof weight_sets[0]; w++) {
    for (size_t n = 1; n <= NMAX; n++) {
      double cdf[NMAX], sum = 0;
      for (size_t i = 0; i < n; i++) sum += weight_sets[w][i], cdf[i] = sum;
      scene sc = {.n_emitters = n, .emitter_cdf = cdf, .emitter_weight_sum = sum};
      double us[4 * NMAX + 8];
      int nu = 0;
      us[nu++] = 0.0, us[nu++] = 0.5, us[nu++] = nextafter(1.0, 0.0), us[nu++] = NAN;
      for (size_t i = 0; i < n; i++) {
        double u = sum > 0 && isfinite(sum) ? cdf[i] / sum : 0.5;
        us[nu++] = u, us[nu++] = nextafter(u, 0.0), us[nu++] = nextafter(u, 1.0);
      }
      for (int j = 0; j < nu; j++) {
        size_t a = pick_emitter_index(&sc, us[j]), b = pick_by_search(&sc, us[j]);
        if (a != b) {
          if (bad < 5)
            fprintf(stderr, "weights %zu, n %zu, u %.17g: picked %zu, search %zu\n", w, n, us[j], a, b);
          bad++;
        }
        tried++;
        counted += n <= PICK_COUNT_MAX;
      }
    }
  }
  CHECK(bad == 0, "pick_emitter_index differs from the binary search in %d of %d picks", bad, tried);
  CHECK(counted > 100 && counted < tried, "both forms tried (%d counted of %d)", counted, tried);
}

/* rays_traced_batch against ray_may_hit and accel_box_misses, ray by ray
 * at every ISA, with and without the full slab test: random rays around
 * and through a box, and the edge cases (direction components of zero
 * and -0, origins on the padded and the full box's faces, infinities,
 * NaNs, a zero direction), over counts that leave a partial last vector. */
/* spawn_rays_between_batch (path's shadow rays towards surface emitters,
 * structure-of-arrays lanes per ISA) against spawn_ray_between bit for
 * bit, at every ISA this CPU runs and several batch sizes: points on both
 * sides of each other's normals, a point on the light that is the
 * surface point itself with no error (zero length), and nothing written
 * past n. */
static void test_spawn_between_batch(void) {
  enum {
    N = 150
  };
  static surface_interaction si[N];
  const surface_interaction *sp[N];
  vec3 q[N], nq[N];
  double qerr[N];
  pcg32 rng;
  pcg32_seed(&rng, 57, 3);
  memset(si, 0, sizeof si);
  for (int k = 0; k < N; k++) {
    double v[12];
    for (int j = 0; j < 12; j++) v[j] = 4 * pcg32_next_double(&rng) - 2;
    si[k].p = v3(v[0], v[1], v[2]);
    si[k].ng = v3_norm(v3(v[3], v[4], v[5]));
    si[k].p_error = 1e-6 * (1 + pcg32_next_double(&rng));
    q[k] = v3(v[6], v[7], v[8]);
    nq[k] = v3_norm(v3(v[9], v[10], v[11]));
    qerr[k] = 1e-6 * pcg32_next_double(&rng);
    sp[k] = &si[k];
  }
  si[5].p_error = 0, q[5] = si[5].p, qerr[5] = 0; /* zero length */
  int isas = 0, zero = 0;
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_supported((rsw_isa)isa)) continue;
    isas++;
    const int counts[] = {N, 1, 7, 64, 65};
    for (size_t ci = 0; ci < sizeof counts / sizeof counts[0]; ci++) {
      int n = counts[ci], bad = 0;
      ray3 r[N + 1];
      memset(r, 0xa5, sizeof r);
      ray3 guard = r[n];
      spawn_rays_between_batch((rsw_isa)isa, n, sp, q, nq, qerr, r);
      for (int k = 0; k < n; k++) {
        ray3 w = spawn_ray_between(&si[k], q[k], nq[k], qerr[k]);
        bad += memcmp(&w.o, &r[k].o, sizeof w.o) || memcmp(&w.d, &r[k].d, sizeof w.d) ||
               memcmp(&w.tmin, &r[k].tmin, sizeof w.tmin) || memcmp(&w.tmax, &r[k].tmax, sizeof w.tmax);
        zero += n == N && w.tmax == 0;
      }
      CHECK(bad == 0 && !memcmp(&r[n], &guard, sizeof guard),
            "%s, %d rays: %d differ from spawn_ray_between%s", rsw_isa_name((rsw_isa)isa), n, bad,
            memcmp(&r[n], &guard, sizeof guard) ? " (and it wrote past n)" : "");
    }
  }
  /* (every ISA this build has: the portable build, make test-generic, has one) */
  CHECK(isas >= 1 && zero == isas, "%d ISAs, %d zero-length rays", isas, zero);
}

static void test_rays_traced_batch(void) {
  enum {
    N = 203
  };
  const pad_box pb = {{-1.0, -2.0, -0.001}, {1.0, 2.0, 0.001}};
  const accel_box box = {{-1.25, -2.25, -0.25}, {1.25, 2.25, 0.25}};
  static double c[6][N];
  ray3 r[N];
  pcg32 rng;
  pcg32_seed(&rng, 31, 7);
  const double special[] = {0.0, -0.0, 1.0, -1.0, 0.001, -0.001, 1.25, -2.25, 0.25, INFINITY, -INFINITY, NAN};
  const int ns = (int)(sizeof special / sizeof special[0]);
  for (int k = 0; k < N; k++) {
    double v[6];
    for (int j = 0; j < 3; j++) v[j] = 6 * pcg32_next_double(&rng) - 3;
    for (int j = 3; j < 6; j++) v[j] = 2 * pcg32_next_double(&rng) - 1;
    if (k % 3 == 1) /* a component from the edge cases */
      v[pcg32_next(&rng) % 6] = special[pcg32_next(&rng) % (uint32_t)ns];
    if (k % 5 == 2) v[3 + pcg32_next(&rng) % 3] = 0.0;
    if (k == 7) v[3] = v[4] = v[5] = 0.0;
    r[k] = (ray3){v3(v[0], v[1], v[2]), v3(v[3], v[4], v[5]), 0.0, INFINITY};
    for (int j = 0; j < 6; j++) c[j][k] = v[j];
  }
  const double *o[3] = {c[0], c[1], c[2]}, *d[3] = {c[3], c[4], c[5]};
  int traced[2] = {0, 0}, first = -1;
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_supported((rsw_isa)isa)) continue;
    if (first < 0) first = isa;
    for (int full = 0; full < 2; full++) {
      const int counts[] = {N, 1, 2, 3, 5, 8, 13};
      for (size_t ci = 0; ci < sizeof counts / sizeof counts[0]; ci++) {
        int n = counts[ci], bad = 0;
        unsigned char out[N + 1];
        out[n] = 0xAA;
        rays_traced_batch((rsw_isa)isa, n, o, d, &pb, full ? &box : NULL, out);
        for (int k = 0; k < n; k++) {
          bool want = ray_may_hit(&pb, &r[k]) && !(full && accel_box_misses(&box, &r[k]));
          bad += out[k] != (want ? 1 : 0);
          if (n == N && isa == first) traced[full] += want;
        }
        CHECK(bad == 0 && out[n] == 0xAA, "%s, %s, %d rays: %d verdicts differ from the scalar tests%s",
              rsw_isa_name((rsw_isa)isa), full ? "full slab test" : "half", n, bad,
              out[n] == 0xAA ? "" : " (and it wrote past the last)");
      }
    }
  }
  /* Both outcomes occur, and the full test culls more. */
  CHECK(traced[1] > 10 && traced[0] < N - 10 && traced[1] < traced[0], "traced: %d half, %d full of %d",
        traced[0], traced[1], N);
}

int main(void) {
  RSW_TEST_RUN(test_pick_emitter);
  RSW_TEST_RUN(test_rays_traced_batch);
  RSW_TEST_RUN(test_spawn_between_batch);
  RSW_TEST_RUN(test_threads_cornell);
  RSW_TEST_RUN(test_threads_periodic);
  RSW_TEST_RUN(test_threads_batched_plugins);
  RSW_TEST_RUN(test_batch_independent);
  RSW_TEST_RUN(test_packet_widths);
  RSW_TEST_RUN(test_stats_counters);
  RSW_TEST_RUN(test_sampler_batches);
  RSW_TEST_RUN(test_sampler_batch_chi2);
  RSW_TEST_RUN(test_emitter_batches);
  RSW_TEST_RUN(test_emitter_batch_chi2);
  RSW_TEST_RUN(test_frames_batch);
  RSW_TEST_RUN(test_hits_batch);
  RSW_TEST_RUN(test_hits_frame_reuse);
  RSW_TEST_END("test_wave");
}
