/* make bench: participating media, one JSON object per line.
 *
 *  media_piecewise_tr_N       ns per exact transmittance of a `piecewise`
 *                             medium of N layers (random rays through the
 *                             box, one thread), N = 1, 2400, 240000
 *  media_piecewise_flight_N   ns per analytic free flight (sample_real)
 *  media_atmo_*               whole renders of a 2,400-layer plane-parallel
 *                             atmosphere (0-120 km, molecular 8 km scale
 *                             height plus a 0-2 km aerosol layer, blended
 *                             rayleigh + hg phase) over an RPV ground under
 *                             a sun, hdistant 16x16 at 256 spp, mono 550 nm,
 *                             with piecewise_volpath and volpath; and the
 *                             same scene without the atmosphere with path
 *                             and with piecewise_volpath: CPU seconds of all
 *                             threads per sample (what a shared machine's
 *                             other load does not inflate), samples per CPU
 *                             second, and the ratio to the no-atmosphere
 *                             `path` render.
 *  media_dense_slab_RULE      a non-absorbing slab of optical thickness 32
 *                             under a sun (tests/kernel/media/
 *                             test_dense_media.c) with volpath's rr_rule
 *                             `throughput` and `mitsuba`: R + T against
 *                             the incident irradiance, CPU seconds per
 *                             render, variance x time and mean squared
 *                             error x time (docs/media.md#dense-media-the-roulette-and-the-segment-lengths).
 *
 *  media_cloud                a 64^3 cloud (tests/support/tsup.c
 *                             tsup_cloud_scene: a ball of sigma_t up to
 *                             40 in an empty box, albedo 0.95, hg 0.85)
 *                             under volpath, hdistant 16x16 at 64 spp: CPU
 *                             ns per sample with the global majorant, with
 *                             an automatic extremum_grid (16^3) and with
 *                             one cell per 2^3 voxels (32^3), the speedups
 *                             over the global majorant, and the film means
 *                             with their standard errors over the
 *                             REPEATS renders (the estimates must agree:
 *                             docs/media.md#local-majorants).
 *  media_shell                docs/examples/spherical_shell.json (a
 *                             Rayleigh shell of 120 layers around a planet,
 *                             sphericalcoordsvolume) at 65,536 spp: CPU ns
 *                             per sample with the global majorant and with
 *                             an automatic extremum_spherical, the speedup,
 *                             and the film values (mean and standard error
 *                             over the REPEATS renders).
 *
 * Medians of REPEATS timings. $RSW_BENCH_ONLY=prefix runs the figures
 * whose name starts with it. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../server/kernel/core/rng.h"
#include "../support/tsup.h"
#include "bench.h"
#include "image_exr.h"

#define REPEATS 5

static bool wanted(const char *name) {
  const char *only = getenv("RSW_BENCH_ONLY");
  return !only || !*only || strncmp(name, only, strlen(only)) == 0;
}

/* The atmosphere of the bench (meters): N layers over 0-120 km. */
static void atmo_layers(int n, double *sig, double *alb, double *w) {
  const double H = 120000.0;
  for (int i = 0; i < n; i++) {
    double z = (i + 0.5) * H / n;
    double sm = 1.16e-5 * exp(-z / 8000.0), sa = z < 2000 ? 1e-4 : 0.0;
    sig[i] = sm + sa;
    alb[i] = (sm + 0.9 * sa) / sig[i];
    w[i] = 0.9 * sa / (sm + 0.9 * sa);
  }
}

static void grid(sbuf *b, const double *v, int n) {
  sb_printf(b,
            "{\"type\": \"gridvolume\", \"shape\": [%d, 1, 1], \"filter_type\": \"nearest\","
            " \"to_world\": [{\"translate\": [-0.5, -0.5, 0]}, {\"scale\": [2000000, 2000000, 120000]}], "
            "\"data\": [",
            n);
  for (int i = 0; i < n; i++) sb_printf(b, "%s%.9g", i ? "," : "", v[i]);
  sb_printf(b, "]}");
}

static char *atmo_scene(int n, const char *integ, bool atmosphere, int spp) {
  sbuf b = {0};
  sb_printf(&b,
            "{\"type\": \"scene\", \"integrator\": {\"type\": \"%s\"},"
            " \"sensor\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
            "   \"sampler\": {\"type\": \"independent\", \"sample_count\": %d},"
            "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16, \"rfilter\": {\"type\": "
            "\"box\"}}},"
            " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0, -0.8660254037844386], "
            "\"irradiance\": 1.8},"
            " \"surface\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [1000000, 1000000, 1]}],"
            "   \"bsdf\": {\"type\": \"rpv\", \"rho_0\": 0.1, \"k\": 0.8, \"g\": -0.1}}",
            integ, spp);
  if (atmosphere) {
    double *sig = malloc(3 * (size_t)n * sizeof *sig);
    if (!sig) return NULL;
    atmo_layers(n, sig, sig + n, sig + 2 * n);
    /* The box reaches 1 m below the ground, so the ground lies inside. */
    sb_printf(&b,
              ", \"atmosphere\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
              " \"to_world\": [{\"scale\": [1000000, 1000000, 60000.5]}, {\"translate\": [0, 0, 59999.5]}],"
              " \"interior\": {\"type\": \"piecewise\", \"sigma_t\": ");
    grid(&b, sig, n);
    sb_printf(&b, ", \"albedo\": ");
    grid(&b, sig + n, n);
    sb_printf(&b, ", \"phase\": {\"type\": \"blendphase\", \"weight\": ");
    grid(&b, sig + 2 * n, n);
    sb_printf(&b, ", \"phase_0\": {\"type\": \"rayleigh\"}, \"phase_1\": {\"type\": \"hg\", \"g\": 0.7}}}}");
    free(sig);
  }
  sb_printf(&b, "}");
  return b.p;
}

static void bench_ops(int n) {
  char name_tr[64], name_ff[64];
  snprintf(name_tr, sizeof name_tr, "media_piecewise_tr_%d", n);
  snprintf(name_ff, sizeof name_ff, "media_piecewise_flight_%d", n);
  if (!wanted(name_tr) && !wanted(name_ff)) return;
  char *text = atmo_scene(n, "piecewise_volpath", true, 1);
  scene *s = text ? tsup_load(text, "mono") : NULL;
  free(text);
  if (!s) return;
  const medium *m = NULL;
  for (size_t i = 0; i < s->n_shapes && !m; i++) m = s->shapes[i]->interior;
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 550};
  rsw_err err = {0};
  if (!m || scene_prepare(s, &rc, &err)) {
    scene_free(s);
    return;
  }
  enum {
    R = 4096
  };
  static ray3 rays[R];
  static double lo[R], hi[R], us[R];
  pcg32 rng;
  pcg32_seed(&rng, 11, 3);
  for (int i = 0; i < R; i++) {
    double ct = 2 * pcg32_next_double(&rng) - 1, ph = 2 * 3.141592653589793 * pcg32_next_double(&rng);
    double st = sqrt(1 - ct * ct);
    rays[i] =
        (ray3){v3(0, 0, 120000 * pcg32_next_double(&rng)), v3(st * cos(ph), st * sin(ph), ct), 0, INFINITY};
    if (!m->ops->intersect_aabb(m, &rays[i], &lo[i], &hi[i])) lo[i] = hi[i] = 0;
    us[i] = pcg32_next_double(&rng);
  }
  for (int which = 0; which < 2; which++) {
    if (!wanted(which ? name_ff : name_tr)) continue;
    double t[REPEATS], sink = 0;
    for (int r = 0; r < REPEATS; r++) {
      double t0 = bench_thread_cpu_s();
      for (int rep = 0; rep < 50; rep++)
        for (int i = 0; i < R; i++) {
          if (which) {
            medium_interaction mi;
            color tr, pdf;
            m->ops->sample_real(m, &rays[i], lo[i], hi[i], us[i], 0, &mi, &tr, &pdf);
            sink += tr.c[0];
          } else {
            sink += m->ops->transmittance(m, &rays[i], lo[i], hi[i]).c[0];
          }
        }
      t[r] = (bench_thread_cpu_s() - t0) / (50.0 * R) * 1e9;
    }
    printf(
        "{\"bench\": \"%s\", \"layers\": %d, \"ns_per_call\": %.2f, \"repeats\": %d, \"checksum\": %.6g}\n",
        which ? name_ff : name_tr, n, bench_median(t, REPEATS), REPEATS, sink);
    fflush(stdout);
  }
  scene_free(s);
}

/* CPU seconds per sample of a whole render (median), or NAN. */
static double render_cpu_per_sample(const char *integ, bool atmosphere, int spp, int threads) {
  char *text = atmo_scene(2400, integ, atmosphere, spp);
  scene *s = text ? tsup_load(text, "mono") : NULL;
  free(text);
  if (!s) return NAN;
  double t[REPEATS];
  for (int r = 0; r < REPEATS; r++) {
    film_image img;
    double t0 = bench_process_cpu_s();
    if (!tsup_render(s, (uint32_t)spp, (uint64_t)r, threads, &img)) {
      scene_free(s);
      return NAN;
    }
    t[r] = (bench_process_cpu_s() - t0) / (16.0 * 16.0 * spp);
    film_image_free(&img);
  }
  scene_free(s);
  return bench_median(t, REPEATS);
}

static void bench_renders(void) {
  if (!wanted("media_atmo")) return;
  const int spp = 256, threads = bench_threads();
  double base = render_cpu_per_sample("path", false, spp, threads);
  struct {
    const char *name, *integ;
    bool atmo;
  } cases[] = {{"media_atmo_none_path", "path", false},
               {"media_atmo_none_piecewise_volpath", "piecewise_volpath", false},
               {"media_atmo_piecewise_volpath", "piecewise_volpath", true},
               {"media_atmo_volpath", "volpath", true}};
  for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
    double c = k == 0 ? base : render_cpu_per_sample(cases[k].integ, cases[k].atmo, spp, threads);
    printf("{\"bench\": \"%s\", \"layers\": %d, \"spp\": %d, \"threads\": %d, \"cpu_ns_per_sample\": %.1f,"
           " \"samples_per_cpu_s\": %.4g, \"ratio_to_none_path\": %.3f, \"repeats\": %d}\n",
           cases[k].name, cases[k].atmo ? 2400 : 0, spp, threads, c * 1e9, 1.0 / c, c / base, REPEATS);
    fflush(stdout);
  }
}

/* media_dense_slab_<rule>: K renders (seeds 1..K) of both sensors at SPP
 * samples with volpath's rr_rule `throughput` (the default) and `mitsuba`:
 * R, T and R + T (mean over the renders; incident cos 30 = 0.866), the
 * variance of one render's R + T, the CPU seconds of one render (median),
 * and efficiency figures: variance x CPU time, and mean squared error
 * against the incident irradiance x CPU time (lower is better; the
 * second counts the mitsuba rule's missing flux). */
static void bench_dense(void) {
  if (!wanted("media_dense")) return;
  enum {
    K = 32,
    SPP = 1024
  };
  const int threads = bench_threads();
  const char *rules[] = {"throughput", "mitsuba"};
  const double E = 0.86602540378443864676;
  for (int k = 0; k < 2; k++) {
    char integ[80];
    snprintf(integ, sizeof integ, "{\"type\": \"volpath\", \"rr_rule\": \"%s\"}", rules[k]);
    /* Optical thickness 32, albedo 1, isotropic, sun at 30 degrees. */
    char *text = tsup_dense_slab(integ, "{\"type\": \"homogeneous\", \"sigma_t\": 32, \"albedo\": 1}",
                                 30.0 * 3.14159265358979323846 / 180);
    scene *s = tsup_load(text, "mono");
    free(text);
    if (!s) return;
    double t[K], v[K], sr = 0, st = 0;
    for (int r = 0; r < K; r++) {
      double x[2];
      double t0 = bench_process_cpu_s();
      for (int sn = 0; sn < 2; sn++) {
        rsw_err err = {0};
        render_opts o = {
            .size = sizeof o, .sensor = (size_t)sn, .spp = SPP, .seed = (uint64_t)r + 1, .threads = threads};
        film_image img;
        if (render_sensor(s, &o, &img, NULL, &err)) {
          scene_free(s);
          return;
        }
        x[sn] = img.data[0];
        film_image_free(&img);
      }
      t[r] = bench_process_cpu_s() - t0;
      sr += x[0], st += x[1];
      v[r] = x[0] + x[1];
    }
    scene_free(s);
    double m = 0, var = 0, mse = 0;
    for (int r = 0; r < K; r++) m += v[r] / K;
    for (int r = 0; r < K; r++) {
      var += (v[r] - m) * (v[r] - m) / (K - 1);
      mse += (v[r] - E) * (v[r] - E) / K;
    }
    double tc = bench_median(t, K);
    printf("{\"bench\": \"media_dense_slab_%s\", \"tau\": 32, \"spp\": %d, \"renders\": %d, \"threads\": %d,"
           " \"R\": %.5f, \"T\": %.5f, \"R_plus_T\": %.5f, \"incident\": %.5f, \"var\": %.3g,"
           " \"cpu_s_per_render\": %.3f, \"var_x_cpu_s\": %.3g, \"mse_x_cpu_s\": %.3g}\n",
           rules[k], SPP, K, threads, sr / K, st / K, m, E, var, tc, var * tc, mse * tc);
    fflush(stdout);
  }
}

static void bench_cloud(void) {
  if (!wanted("media_cloud")) return;
  enum {
    RES = 64,
    SPP = 64
  };
  const int threads = bench_threads();
  const char *ex[3] = {"", "\"ex\": {\"type\": \"extremum_grid\"},",
                       "\"ex\": {\"type\": \"extremum_grid\", \"resolution\": [32, 32, 32]},"};
  double ns[3], mean[3], se[3];
  for (int k = 0; k < 3; k++) {
    char *text = tsup_cloud_scene(RES, ex[k], SPP);
    scene *s = tsup_load(text, "mono");
    free(text);
    if (!s) return;
    double t[REPEATS], sum = 0, sum2 = 0;
    for (int r = 0; r < REPEATS; r++) {
      film_image img;
      double t0 = bench_process_cpu_s();
      if (!tsup_render(s, SPP, (uint64_t)r + 1, threads, &img)) {
        scene_free(s);
        return;
      }
      t[r] = (bench_process_cpu_s() - t0) / (16.0 * 16.0 * SPP);
      double m, e;
      tsup_stats(&img, 0, &m, &e);
      sum += m, sum2 += m * m;
      film_image_free(&img);
    }
    scene_free(s);
    ns[k] = bench_median(t, REPEATS) * 1e9;
    mean[k] = sum / REPEATS;
    se[k] = sqrt(fmax(sum2 / REPEATS - mean[k] * mean[k], 0) / (REPEATS - 1));
  }
  printf("{\"bench\": \"media_cloud\", \"voxels\": \"%dx%dx%d\", \"spp\": %d, \"threads\": %d,"
         " \"global_cpu_ns_per_sample\": %.1f, \"extremum_auto_cpu_ns_per_sample\": %.1f,"
         " \"extremum_32_cpu_ns_per_sample\": %.1f, \"speedup_auto\": %.2f, \"speedup_32\": %.2f,"
         " \"mean_global\": %.5f, \"se_global\": %.5f, \"mean_auto\": %.5f, \"se_auto\": %.5f,"
         " \"mean_32\": %.5f, \"se_32\": %.5f, \"repeats\": %d}\n",
         RES, RES, RES, SPP, threads, ns[0], ns[1], ns[2], ns[0] / ns[1], ns[0] / ns[2], mean[0], se[0],
         mean[1], se[1], mean[2], se[2], REPEATS);
  fflush(stdout);
}

static void bench_shell(void) {
  if (!wanted("media_shell")) return;
  enum {
    SPP = 65536
  };
  const int threads = bench_threads();
  size_t len;
  char *doc = tsup_read_file("docs/examples/spherical_shell.json", &len);
  if (!doc) return;
  const char *at = strstr(doc, "\"albedo\": 1,");
  if (!at) {
    free(doc);
    return;
  }
  sbuf ex = {0};
  sb_printf(&ex, "%.*s\"albedo\": 1, \"ex\": {\"type\": \"extremum_spherical\"},%s", (int)(at - doc), doc,
            at + strlen("\"albedo\": 1,"));
  const char *texts[2] = {doc, ex.p};
  double ns[2], mean[2], se[2];
  for (int k = 0; k < 2; k++) {
    scene *s = tsup_load(texts[k], "mono");
    if (!s) break;
    double t[REPEATS], sum = 0, sum2 = 0;
    for (int r = 0; r < REPEATS; r++) {
      film_image img;
      double t0 = bench_process_cpu_s();
      if (!tsup_render(s, SPP, (uint64_t)r + 1, threads, &img)) break;
      t[r] = (bench_process_cpu_s() - t0) / SPP;
      sum += img.data[0], sum2 += img.data[0] * img.data[0];
      film_image_free(&img);
    }
    scene_free(s);
    ns[k] = bench_median(t, REPEATS) * 1e9;
    mean[k] = sum / REPEATS;
    se[k] = sqrt(fmax(sum2 / REPEATS - mean[k] * mean[k], 0) / (REPEATS - 1));
  }
  free(doc), free(ex.p);
  printf("{\"bench\": \"media_shell\", \"layers\": 120, \"spp\": %d, \"threads\": %d,"
         " \"global_cpu_ns_per_sample\": %.1f, \"extremum_spherical_cpu_ns_per_sample\": %.1f, \"speedup\": "
         "%.2f,"
         " \"value_global\": %.6f, \"se_global\": %.6f, \"value_extremum\": %.6f, \"se_extremum\": %.6f,"
         " \"repeats\": %d}\n",
         SPP, threads, ns[0], ns[1], ns[0] / ns[1], mean[0], se[0], mean[1], se[1], REPEATS);
  fflush(stdout);
}

int main(void) {
  bench_shell();
  bench_cloud();
  bench_dense();
  bench_ops(1);
  bench_ops(2400);
  bench_ops(240000);
  bench_renders();
  return 0;
}
