/* make bench: per-plugin costs, one JSON object per line.
 *
 *  rough_*        ns per roughconductor sample / eval / pdf call (one
 *                 thread; Beckmann and GGX, visible normals, material
 *                 none = F 1, and a gold preset in rgb)
 *  sampler_*      ns per sample start plus the two 2-D draws a camera ray
 *                 takes (independent, stratified)
 *  sensor_*       ns per sample_ray (hdistant of the seed scene,
 *                 perspective of the Cornell box)
 *  area_sample    ns per area-light sample_direction (the Cornell box
 *                 light, from the floor's centre)
 *  lanes_*        ns per lane of the hot plugins' ops as the wave calls
 *                 them (groups of 64 lanes of one BSDF, waves of 256
 *                 camera samples): `ns_per_lane_scalar` the scalar op per
 *                 lane through its pointer (what the wave does for a
 *                 plugin without a batched op), `ns_per_lane_batch` the
 *                 batched op, at `isa` (the best the CPU has, or
 *                 $RSW_BENCH_ISA). BSDFs: diffuse, conductor (mirror and
 *                 gold in rgb), dielectric, twosided (diffuse both sides),
 *                 rpv (grey, coloured), bilambertian, roughconductor;
 *                 sample and eval+pdf. Sensors: hdistant, distant,
 *                 mdistant, distantflux, perspective, radiancemeter.
 *  scene_*        whole renders: the seed scene (32x32, 3200 spp) and the
 *                 Cornell box example (128x128, 64 spp, max_depth 8), all
 *                 cores ($RSW_BENCH_THREADS): wall seconds, and the CPU
 *                 seconds of all threads (cpu_s, ns_per_sample_cpu: what
 *                 a shared machine's other load does not inflate)
 *
 * Each figure is the median of REPEATS timings within one run (the machine
 * is shared: medians resist a busy spell). $RSW_BENCH_ONLY=prefix runs the
 * figures whose name starts with it. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../../server/kernel/bsdfs/bsdfs_internal.h"
#include "../../server/kernel/core/isa.h"
#include "../../server/kernel/core/rng.h"
#include "../../server/kernel/core/warp.h"
#include "../../server/kernel/render.h"
#include "../../server/kernel/scene/scene.h"
#include "../../server/kernel/textures/texture.h"
#include "../support/bsdf_test.h"
#include "bench.h"

#define REPEATS 5
#define NDIR    4096

static bool wanted(const char *name) {
  const char *only = getenv("RSW_BENCH_ONLY");
  return !only || !*only || strncmp(name, only, strlen(only)) == 0;
}

static void emit(const char *name, double ns, double sink) {
  printf("{\"bench\": \"%s\", \"ns_per_call\": %.2f, \"repeats\": %d, \"checksum\": %.6g}\n", name, ns,
         REPEATS, sink);
  fflush(stdout);
}

/* Inputs drawn once: incident directions over the hemisphere (cosine
 * weighted, as a path meets them) and uniform pairs. */
static vec3 dirs[NDIR];
static vec2 us[NDIR];

static void make_inputs(void) {
  pcg32 r;
  pcg32_seed(&r, 42, 7);
  for (int i = 0; i < NDIR; i++) {
    vec2 u = v2(pcg32_next_double(&r), pcg32_next_double(&r));
    dirs[i] = warp_square_to_cosine_hemisphere(u);
    if (!(dirs[i].z > 1e-4)) dirs[i] = v3(0, 0, 1);
    us[i] = v2(pcg32_next_double(&r), pcg32_next_double(&r));
  }
}

enum {
  OP_SAMPLE,
  OP_EVAL,
  OP_PDF
};

static void bench_bsdf(const char *name, const bsdf *b, int op) {
  if (!wanted(name)) return;
  const int N = 400000;
  double t[REPEATS], sink = 0;
  surface_interaction si = tb_si_with(v3(0, 0, 1));
  for (int rep = 0; rep < REPEATS; rep++) {
    double t0 = bench_thread_cpu_s();
    for (int i = 0; i < N; i++) {
      si.wi = dirs[i & (NDIR - 1)];
      vec2 u = us[(i * 7 + 3) & (NDIR - 1)];
      if (op == OP_SAMPLE) {
        bsdf_sample bs;
        color w = b->ops->sample(b, &si, 0.5, u, &bs);
        sink += w.c[0] + bs.pdf;
      } else if (op == OP_EVAL) {
        sink += b->ops->eval(b, &si, dirs[(i * 5 + 1) & (NDIR - 1)]).c[1];
      } else {
        sink += b->ops->pdf(b, &si, dirs[(i * 5 + 1) & (NDIR - 1)]);
      }
    }
    t[rep] = (bench_thread_cpu_s() - t0) * 1e9 / N;
  }
  emit(name, bench_median(t, REPEATS), sink);
}

static void bench_rough(void) {
  const char *names[2] = {"beckmann", "ggx"};
  for (int ty = 0; ty < 2; ty++) {
    rough_case r = rough_make(ty ? MF_GGX : MF_BECKMANN, 0.1, 0.1, true, 0.0, 1.0);
    if (!r.b) continue;
    char n[64];
    snprintf(n, sizeof n, "rough_%s_sample", names[ty]);
    bench_bsdf(n, r.b, OP_SAMPLE);
    snprintf(n, sizeof n, "rough_%s_eval", names[ty]);
    bench_bsdf(n, r.b, OP_EVAL);
    snprintf(n, sizeof n, "rough_%s_pdf", names[ty]);
    bench_bsdf(n, r.b, OP_PDF);
    rough_free(&r);
  }
  /* A coloured preset in rgb: three Fresnel channels are needed here. */
  texture *a = uniform_texture_const(0.1, "alpha");
  render_ctx rc = {.variant = VARIANT_RGB, .wavelength = 550.0};
  const ior_conductor *au = ior_conductor_lookup("Au");
  bsdf *b = a && au ? roughconductor_new(MF_BECKMANN, a, a, true, NULL, NULL, au, NULL, &rc) : NULL;
  if (b) {
    bench_bsdf("rough_beckmann_gold_rgb_sample", b, OP_SAMPLE);
    bench_bsdf("rough_beckmann_gold_rgb_eval", b, OP_EVAL);
    tb_free_bsdf(b);
  }
  tb_free_tex(a);
  texture *rho = uniform_texture_const(0.5, "rho");
  bsdf *d = rho ? diffuse_new(rho) : NULL;
  if (d) {
    bench_bsdf("diffuse_sample", d, OP_SAMPLE);
    bench_bsdf("diffuse_eval", d, OP_EVAL);
    tb_free_bsdf(d);
  }
  tb_free_tex(rho);
}

static scene *load(const char *path);

/* ---- batched ops vs the scalar ones, ns per lane ------------------------- */

#define LANES 16384
#define GROUP 64

static void emit_lanes(const char *name, double ns_scalar, double ns_batch, double sink) {
  printf("{\"bench\": \"%s\", \"ns_per_lane_scalar\": %.2f, \"ns_per_lane_batch\": %.2f, \"speedup\": %.2f, "
         "\"isa\": \"%s\", \"repeats\": %d, \"checksum\": %.6g}\n",
         name, ns_scalar, ns_batch, ns_scalar / ns_batch, rsw_isa_name(rsw_isa_get()), REPEATS, sink);
  fflush(stdout);
}

/* wi: the cosine-weighted directions of make_inputs(), every other one
 * mirrored below the surface when both_sides (twosided, bilambertian). */
static void bench_bsdf_lanes(const char *name, const bsdf *b, bool both_sides) {
  char n1[96], n2[96];
  snprintf(n1, sizeof n1, "lanes_%s_sample", name);
  snprintf(n2, sizeof n2, "lanes_%s_eval_pdf", name);
  if (!wanted(n1) && !wanted(n2)) return;
  static surface_interaction si[LANES];
  static const surface_interaction *sp[LANES];
  static double u1[LANES], pdf[LANES];
  static vec2 u2[LANES];
  static vec3 wo[LANES];
  static bsdf_sample bs[LANES];
  static color w[LANES], f[LANES];
  for (int i = 0; i < LANES; i++) {
    vec3 d = dirs[i & (NDIR - 1)];
    if (both_sides && (i & 1)) d.z = -d.z;
    si[i] = tb_si_with(d);
    sp[i] = &si[i];
    u1[i] = us[(i * 11 + 5) & (NDIR - 1)].x;
    u2[i] = us[(i * 7 + 3) & (NDIR - 1)];
    wo[i] = dirs[(i * 5 + 1) & (NDIR - 1)];
    if (both_sides && (i % 3 == 0)) wo[i].z = -wo[i].z;
  }
  for (int op = 0; op < 2; op++) {
    if (!wanted(op ? n2 : n1)) continue;
    double ts[REPEATS], tb[REPEATS], sink = 0;
    for (int rep = 0; rep < REPEATS; rep++) {
      for (int mode = 0; mode < 2; mode++) {
        double t0 = bench_thread_cpu_s();
        for (int k = 0; k < 8; k++)
          for (int i0 = 0; i0 < LANES; i0 += GROUP) {
            if (op == 0 && mode == 0)
              for (int i = i0; i < i0 + GROUP; i++) w[i] = b->ops->sample(b, sp[i], u1[i], u2[i], &bs[i]);
            else if (op == 0)
              bsdf_sample_n(b, GROUP, sp + i0, u1 + i0, u2 + i0, bs + i0, w + i0);
            else if (mode == 0)
              for (int i = i0; i < i0 + GROUP; i++) {
                f[i] = b->ops->eval(b, sp[i], wo[i]);
                pdf[i] = b->ops->pdf(b, sp[i], wo[i]);
              }
            else
              bsdf_eval_pdf_n(b, GROUP, sp + i0, wo + i0, f + i0, pdf + i0);
          }
        double ns = (bench_thread_cpu_s() - t0) * 1e9 / (8.0 * LANES);
        if (mode == 0)
          ts[rep] = ns;
        else
          tb[rep] = ns;
        for (int i = 0; i < LANES; i += 97) sink += op ? f[i].c[0] + pdf[i] : w[i].c[0] + bs[i].pdf;
      }
    }
    emit_lanes(op ? n2 : n1, bench_median(ts, REPEATS), bench_median(tb, REPEATS), sink);
  }
}

static void bench_bsdfs_lanes(void) {
  render_ctx rgb = {.variant = VARIANT_RGB, .wavelength = 550.0};
  texture *t[8] = {uniform_texture_const(0.5, "a"), uniform_texture_const(0.0, "eta"),
                   uniform_texture_const(1.0, "k"), uniform_texture_const(0.12, "rho0"),
                   uniform_texture_const(0.7, "k"), uniform_texture_const(-0.2, "g"),
                   uniform_texture_const(0.4, "t"), NULL};
  spectrum s3 = {.kind = SPEC_RGB, .rgb = {0.05, 0.1, 0.3}};
  t[7] = uniform_texture_new(&s3, "rgb");
  for (int i = 0; i < 8; i++)
    if (!t[i]) return;
  bsdf *b;
  if ((b = diffuse_new(t[0]))) {
    bench_bsdf_lanes("diffuse", b, false);
    bsdf *ts = twosided_new(b, NULL);
    if (ts) bench_bsdf_lanes("twosided_diffuse", ts, true);
    tb_free_bsdf(ts);
    tb_free_bsdf(b);
  }
  if ((b = conductor_new(t[1], t[2], NULL, NULL, NULL))) bench_bsdf_lanes("conductor_mirror", b, false);
  tb_free_bsdf(b);
  if ((b = conductor_new(NULL, NULL, ior_conductor_lookup("Au"), NULL, &rgb)))
    bench_bsdf_lanes("conductor_gold_rgb", b, false);
  tb_free_bsdf(b);
  if ((b = dielectric_new(1.5, 1.0, NULL, NULL))) bench_bsdf_lanes("dielectric", b, true);
  tb_free_bsdf(b);
  if ((b = rpv_new(t[3], t[4], t[5], NULL))) bench_bsdf_lanes("rpv", b, false);
  tb_free_bsdf(b);
  if ((b = rpv_new(t[7], t[4], t[5], t[6]))) bench_bsdf_lanes("rpv_rgb", b, false);
  tb_free_bsdf(b);
  if ((b = bilambertian_new(t[6], t[6]))) bench_bsdf_lanes("bilambertian", b, true);
  tb_free_bsdf(b);
  rough_case r = rough_make(MF_BECKMANN, 0.1, 0.1, true, 0.0, 1.0);
  if (r.b) bench_bsdf_lanes("roughconductor_beckmann", r.b, false);
  rough_free(&r);
  for (int i = 0; i < 8; i++) tb_free_tex(t[i]);
}

static void bench_sensor_lanes(const char *name, const sensor *se) {
  if (!wanted(name) || !se->ops->sample_ray_batch) return;
  enum {
    WAVE_N = 256
  };
  static vec2 fu[LANES], ap[LANES];
  static ray3 rays[LANES];
  static double w[LANES];
  for (int i = 0; i < LANES; i++) fu[i] = us[i & (NDIR - 1)], ap[i] = us[(i * 3 + 1) & (NDIR - 1)];
  double ts[REPEATS], tb[REPEATS], sink = 0;
  for (int rep = 0; rep < REPEATS; rep++)
    for (int mode = 0; mode < 2; mode++) {
      double t0 = bench_thread_cpu_s();
      for (int k = 0; k < 8; k++)
        for (int i0 = 0; i0 < LANES; i0 += WAVE_N) {
          if (mode == 0)
            for (int i = i0; i < i0 + WAVE_N; i++) w[i] = se->ops->sample_ray(se, fu[i], ap[i], &rays[i]);
          else
            se->ops->sample_ray_batch(se, WAVE_N, fu + i0, ap + i0, rays + i0, w + i0);
        }
      double ns = (bench_thread_cpu_s() - t0) * 1e9 / (8.0 * LANES);
      if (mode == 0)
        ts[rep] = ns;
      else
        tb[rep] = ns;
      for (int i = 0; i < LANES; i += 97) sink += w[i] + rays[i].d.x + rays[i].o.y;
    }
  emit_lanes(name, bench_median(ts, REPEATS), bench_median(tb, REPEATS), sink);
}

static void bench_sensors_lanes(void) {
  static const char *const scenes[][2] = {
      {"lanes_sensor_hdistant", "proto/examples/hdistant_seed.xml"},
      {"lanes_sensor_perspective", "proto/examples/cornell_box.json"},
  };
  static const char *const inline_scenes[][2] = {
      {"lanes_sensor_distant",
       "{\"type\": \"scene\", \"cam\": {\"type\": \"distant\", \"direction\": [0.3, -0.2, -1],"
       " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
       " \"ball\": {\"type\": \"sphere\", \"radius\": 2}}"},
      {"lanes_sensor_mdistant", "{\"type\": \"scene\", \"cam\": {\"type\": \"mdistant\","
                                " \"directions\": \"0 0 -1, 0.5 0.1 -1, -1 0.3 -0.2, 0 1 0\","
                                " \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 1}},"
                                " \"ball\": {\"type\": \"sphere\", \"radius\": 2}}"},
      {"lanes_sensor_distantflux", "{\"type\": \"scene\", \"cam\": {\"type\": \"distantflux\","
                                   " \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 4}},"
                                   " \"ball\": {\"type\": \"sphere\", \"radius\": 2}}"},
      {"lanes_sensor_radiancemeter", "{\"type\": \"scene\", \"cam\": {\"type\": \"radiancemeter\","
                                     " \"origin\": [0, 0, 5], \"direction\": [0, 0, -1],"
                                     " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
                                     " \"ball\": {\"type\": \"sphere\", \"radius\": 2}}"},
  };
  for (size_t i = 0; i < 2; i++) {
    if (!wanted(scenes[i][0])) continue;
    scene *s = load(scenes[i][1]);
    if (s) bench_sensor_lanes(scenes[i][0], s->sensors[0]);
    scene_free(s);
  }
  for (size_t i = 0; i < sizeof inline_scenes / sizeof inline_scenes[0]; i++) {
    if (!wanted(inline_scenes[i][0])) continue;
    rsw_err err = {0};
    scene *s = NULL;
    scene_load_opts lo = {.size = sizeof lo};
    const char *txt = inline_scenes[i][1];
    if (scene_load_memory(txt, strlen(txt), inline_scenes[i][0], false, &lo, &s, &err)) {
      fprintf(stderr, "bench_plugins: %s: %s\n", inline_scenes[i][0], err.msg);
      continue;
    }
    render_opts o = {.size = sizeof o, .spp = 1, .seed = 1, .threads = 1};
    film_image img;
    render_result_stats st;
    if (render_sensor(s, &o, &img, &st, &err) == RSW_OK) film_image_free(&img);
    bench_sensor_lanes(inline_scenes[i][0], s->sensors[0]);
    scene_free(s);
  }
}

static scene *load(const char *path) {
  rsw_err err = {0};
  scene *s = NULL;
  scene_load_opts lo = {.size = sizeof lo};
  if (scene_load_file(path, &lo, &s, &err)) {
    fprintf(stderr, "bench_plugins: %s: %s: %s\n", path, err.where, err.msg);
    return NULL;
  }
  /* One render prepares the scene (prepare(), set_scene()). */
  render_opts o = {.size = sizeof o, .spp = 1, .seed = 1, .threads = 1};
  film_image img;
  render_result_stats st;
  if (render_sensor(s, &o, &img, &st, &err) == RSW_OK) film_image_free(&img);
  return s;
}

/* Start of a sample and the two 2-D draws of a camera ray. */
static void bench_sampler(const char *name, const sampler *smp) {
  if (!wanted(name)) return;
  const int N = 1000000;
  double t[REPEATS], sink = 0;
  for (int rep = 0; rep < REPEATS; rep++) {
    double t0 = bench_thread_cpu_s();
    for (int i = 0; i < N; i++) {
      sampler_state st;
      smp->ops->start(smp, &st, 1, (uint64_t)(i >> 6), (uint32_t)(i & 63), 64);
      vec2 a = smp->ops->next_2d(&st), b = smp->ops->next_2d(&st);
      sink += a.x + b.y;
    }
    t[rep] = (bench_thread_cpu_s() - t0) * 1e9 / N;
  }
  emit(name, bench_median(t, REPEATS), sink);
}

static void bench_sensor(const char *name, const sensor *se) {
  if (!wanted(name)) return;
  const int N = 1000000;
  double t[REPEATS], sink = 0;
  for (int rep = 0; rep < REPEATS; rep++) {
    double t0 = bench_thread_cpu_s();
    for (int i = 0; i < N; i++) {
      ray3 ray;
      double w = se->ops->sample_ray(se, us[i & (NDIR - 1)], us[(i * 3 + 1) & (NDIR - 1)], &ray);
      sink += w + ray.d.x + ray.o.y;
    }
    t[rep] = (bench_thread_cpu_s() - t0) * 1e9 / N;
  }
  emit(name, bench_median(t, REPEATS), sink);
}

static void bench_area(const scene *s) {
  if (!wanted("area_sample")) return;
  const emitter *e = NULL;
  for (size_t i = 0; i < s->n_emitters; i++)
    if (s->emitters[i]->flags & EMITTER_SURFACE) e = s->emitters[i];
  if (!e) return;
  const int N = 1000000;
  double t[REPEATS], sink = 0;
  surface_interaction ref = tb_si_with(v3(0, 0, 1));
  ref.p = v3(0, -0.99, 0);
  for (int rep = 0; rep < REPEATS; rep++) {
    double t0 = bench_thread_cpu_s();
    for (int i = 0; i < N; i++) {
      direction_sample ds;
      color c = e->ops->sample_direction(e, &ref, us[i & (NDIR - 1)], &ds);
      sink += c.c[0] + ds.pdf;
    }
    t[rep] = (bench_thread_cpu_s() - t0) * 1e9 / N;
  }
  emit("area_sample", bench_median(t, REPEATS), sink);
}

static void bench_render(const char *name, scene *s) {
  if (!wanted(name)) return;
  rsw_err err = {0};
  render_opts o = {.size = sizeof o, .spp = 0, .seed = 1, .threads = bench_threads()};
  double t[3], c[3];
  render_result_stats st = {0};
  for (int rep = 0; rep < 3; rep++) {
    film_image img;
    double c0 = bench_process_cpu_s();
    if (render_sensor(s, &o, &img, &st, &err)) {
      fprintf(stderr, "bench %s: %s\n", name, err.msg);
      return;
    }
    c[rep] = bench_process_cpu_s() - c0;
    film_image_free(&img);
    t[rep] = st.wall_s;
  }
  double w = bench_median(t, 3), cpu = bench_median(c, 3);
  printf("{\"bench\": \"%s\", \"wall_s\": %.4f, \"cpu_s\": %.4f, \"samples_per_s\": %.4g, "
         "\"ns_per_sample_per_core\": %.1f, \"ns_per_sample_cpu\": %.1f, \"threads\": %d, \"repeats\": 3}\n",
         name, w, cpu, st.samples / w, w * 1e9 * st.threads / (double)st.samples,
         cpu * 1e9 / (double)st.samples, st.threads);
  fflush(stdout);
}

int main(void) {
  make_inputs();
  const char *isa_name = getenv("RSW_BENCH_ISA");
  if (isa_name && *isa_name) {
    rsw_isa isa;
    rsw_err err = {0};
    if (rsw_isa_parse(isa_name, &isa, &err) != RSW_OK || !rsw_isa_set(isa)) {
      fprintf(stderr, "bench_plugins: RSW_BENCH_ISA: %s\n", err.msg);
      return 1;
    }
  }
  bench_rough();
  bench_bsdfs_lanes();
  bench_sensors_lanes();
  scene *seed = load("proto/examples/hdistant_seed.xml");
  scene *cb = load("proto/examples/cornell_box.json");
  if (!seed || !cb) return 1;
  bench_sampler("sampler_independent", seed->sensors[0]->sampler);
  bench_sampler("sampler_stratified", cb->sensors[0]->sampler);
  bench_sensor("sensor_hdistant", seed->sensors[0]);
  bench_sensor("sensor_perspective", cb->sensors[0]);
  bench_area(cb);
  bench_render("scene_seed_hdistant", seed);
  bench_render("scene_cornell_box", cb);
  scene_free(seed);
  scene_free(cb);
  return 0;
}
