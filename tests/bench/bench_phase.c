/* make bench: phase functions and volumes, one JSON object per line.
 *
 *  phase_<name>_sample, phase_<name>_eval
 *                 ns per sample() / eval_pdf() call (one thread) of
 *                 isotropic, hg (g 0.7), rayleigh, tabphase (181 values)
 *                 and blendphase (rayleigh + hg, constant weight)
 *  grid_eval_trilinear, grid_eval_nearest
 *                 ns per gridvolume eval at random points of a 64^3 grid
 *  grid_update_2400
 *                 a 2,400-layer gridvolume's `data` written through
 *                 scene_update (validation, copy, max refresh): us per
 *                 update, and with the JSON text parsed first
 *                 (param_value_parse + scene_update), as an override
 *                 arrives
 *
 * Each figure is the median of REPEATS timings (thread CPU time). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../server/kernel/core/rng.h"
#include "../../server/kernel/scene/params.h"
#include "../../server/kernel/scene/scene.h"
#include "../../server/kernel/scene/update.h"
#include "../../server/kernel/volumes/volume.h"
#include "bench.h"

#define REPEATS 5
#define NIN     4096

static bool wanted(const char *name) {
  const char *only = getenv("RSW_BENCH_ONLY");
  return !only || !*only || strncmp(name, only, strlen(only)) == 0;
}

static vec3 dirs[NIN], pts[NIN];
static vec2 us[NIN];
static double u1s[NIN];

static scene *load(const char *text) {
  scene *s = NULL;
  rsw_err err = {0};
  scene_load_opts o = {.size = sizeof o, .variant = "mono"};
  if (scene_load_memory(text, strlen(text), "bench", false, &o, &s, &err)) {
    fprintf(stderr, "bench_phase: %s: %s\n", err.where, err.msg);
    exit(1);
  }
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 550};
  if (scene_prepare(s, &rc, &err)) exit(1);
  return s;
}

static object *find(const scene *s, const char *id, obj_class cls) {
  for (size_t i = 0; i < s->n_objects; i++) {
    object *o = s->objects[i];
    if (o->id && strcmp(o->id, id) == 0 && o->plugin && o->plugin->cls == cls) return o;
  }
  return NULL;
}

static void bench_phase(const char *name, const phase *ph) {
  char label[96];
  for (int op = 0; op < 2; op++) {
    snprintf(label, sizeof label, "phase_%s_%s", name, op ? "eval" : "sample");
    if (!wanted(label)) continue;
    const int N = 400000;
    double t[REPEATS], sink = 0;
    medium_interaction mi = {.t = 1, .p = v3(0.5, 0.5, 0.5)};
    for (int rep = 0; rep < REPEATS; rep++) {
      double t0 = bench_thread_cpu_s();
      for (int i = 0; i < N; i++) {
        int k = i & (NIN - 1);
        mi.wi = dirs[k];
        double pdf;
        if (op) {
          sink += ph->ops->eval_pdf(ph, &mi, dirs[(k * 7 + 3) & (NIN - 1)], &pdf);
        } else {
          vec3 wo;
          sink += ph->ops->sample(ph, &mi, u1s[k], us[k], &wo, &pdf) * wo.z;
        }
      }
      t[rep] = (bench_thread_cpu_s() - t0) * 1e9 / N;
    }
    printf("{\"bench\": \"%s\", \"ns_per_call\": %.2f, \"repeats\": %d, \"checksum\": %.6g}\n", label,
           bench_median(t, REPEATS), REPEATS, sink);
    fflush(stdout);
  }
}

static void bench_grid_eval(const char *label, const volume *v) {
  if (!wanted(label)) return;
  const int N = 1000000;
  double t[REPEATS], sink = 0;
  for (int rep = 0; rep < REPEATS; rep++) {
    double t0 = bench_thread_cpu_s();
    for (int i = 0; i < N; i++) sink += volume_eval_1(v, pts[i & (NIN - 1)]);
    t[rep] = (bench_thread_cpu_s() - t0) * 1e9 / N;
  }
  printf("{\"bench\": \"%s\", \"ns_per_call\": %.2f, \"repeats\": %d, \"checksum\": %.6g}\n", label,
         bench_median(t, REPEATS), REPEATS, sink);
  fflush(stdout);
}

/* A JSON list of n numbers: layer k of version w. */
static char *layers_json(int n, int w) {
  char *b = malloc((size_t)n * 32 + 8), *p = b;
  *p++ = '[';
  for (int k = 0; k < n; k++)
    p += sprintf(p, "%s%.17g", k ? ", " : "", 1e-5 * exp(-k * 0.00625) * (1 + 0.01 * w));
  strcpy(p, "]");
  return b;
}

static void bench_grid_update(void) {
  if (!wanted("grid_update_2400")) return;
  const int n = 2400;
  char *data = layers_json(n, 0);
  size_t len = strlen(data) + 256;
  char *text = malloc(len);
  snprintf(text, len,
           "{\"type\": \"scene\", \"g\": {\"type\": \"gridvolume\", \"shape\": [%d, 1, 1], \"data\": %s}}", n,
           data);
  scene *s = load(text);
  char *json[2] = {layers_json(n, 1), layers_json(n, 2)};
  param_update u[2] = {{.key = "g.data"}, {.key = "g.data"}};
  rsw_err err = {0};
  for (int k = 0; k < 2; k++)
    if (param_value_parse(json[k], "g.data", &u[k].value, &err)) exit(1);
  const int N = 400;
  double t[REPEATS], tp[REPEATS];
  for (int rep = 0; rep < REPEATS; rep++) {
    double t0 = bench_thread_cpu_s();
    for (int i = 0; i < N; i++)
      if (scene_update(s, &u[i & 1], 1, NULL, &err)) exit(1);
    t[rep] = (bench_thread_cpu_s() - t0) * 1e6 / N;
    t0 = bench_thread_cpu_s();
    for (int i = 0; i < N; i++) {
      param_update p = {.key = "g.data"};
      if (param_value_parse(json[i & 1], "g.data", &p.value, &err) || scene_update(s, &p, 1, NULL, &err))
        exit(1);
      param_value_free(&p.value);
    }
    tp[rep] = (bench_thread_cpu_s() - t0) * 1e6 / N;
  }
  printf("{\"bench\": \"grid_update_2400\", \"us_per_update\": %.2f, \"us_parse_and_update\": %.2f, "
         "\"repeats\": "
         "%d}\n",
         bench_median(t, REPEATS), bench_median(tp, REPEATS), REPEATS);
  fflush(stdout);
  for (int k = 0; k < 2; k++) param_value_free(&u[k].value), free(json[k]);
  scene_free(s);
  free(text);
  free(data);
}

int main(void) {
  pcg32 r;
  pcg32_seed(&r, 42, 7);
  for (int i = 0; i < NIN; i++) {
    dirs[i] = warp_square_to_uniform_sphere(v2(pcg32_next_double(&r), pcg32_next_double(&r)));
    us[i] = v2(pcg32_next_double(&r), pcg32_next_double(&r));
    u1s[i] = pcg32_next_double(&r);
    pts[i] = v3(pcg32_next_double(&r), pcg32_next_double(&r), pcg32_next_double(&r));
  }
  /* A 181-value forward-peaked table (1-degree steps of theta would be
   * irregular in mu; Mitsuba's tables are regular in mu). */
  char tab[181 * 24 + 1] = "", *p = tab;
  for (int i = 0; i < 181; i++) p += sprintf(p, "%s%.6g", i ? ", " : "", exp(4.0 * (-1.0 + i / 90.0)));
  size_t cap = 16384 + (size_t)2 * 64 * 64 * 64 * 4; /* two grids of "nn " */
  char *text = malloc(cap);
  int w = snprintf(
      text, cap,
      "{\"type\": \"scene\", \"iso\": {\"type\": \"isotropic\"}, \"hg\": {\"type\": \"hg\", \"g\": 0.7}, "
      "\"ray\": {\"type\": \"rayleigh\"}, \"tab\": {\"type\": \"tabphase\", \"values\": \"%s\"}, "
      "\"blend\": {\"type\": \"blendphase\", \"weight\": 0.3, \"phase_0\": {\"type\": \"rayleigh\"}, "
      "\"phase_1\": {\"type\": \"hg\", \"g\": 0.7}}",
      tab);
  /* Two 64^3 grids of the same values, trilinear and nearest. */
  const char *filters[2] = {"trilinear", "nearest"};
  for (int f = 0; f < 2; f++) {
    w += snprintf(text + w, cap - w,
                  ", \"%s\": {\"type\": \"gridvolume\", \"filter_type\": \"%s\", "
                  "\"shape\": [64, 64, 64], \"data\": \"",
                  filters[f], filters[f]);
    for (int i = 0; i < 64 * 64 * 64; i++) w += snprintf(text + w, cap - w, "%d ", i % 97);
    w += snprintf(text + w, cap - w, "\"}");
  }
  snprintf(text + w, cap - w, "}");
  scene *s = load(text);
  free(text);
  const char *ph[5] = {"iso", "hg", "ray", "tab", "blend"};
  const char *names[5] = {"isotropic", "hg", "rayleigh", "tabphase181", "blendphase"};
  for (int k = 0; k < 5; k++) bench_phase(names[k], (const phase *)find(s, ph[k], CLS_PHASE));
  bench_grid_eval("grid_eval_trilinear", (const volume *)find(s, "trilinear", CLS_VOLUME));
  bench_grid_eval("grid_eval_nearest", (const volume *)find(s, "nearest", CLS_VOLUME));
  scene_free(s);
  bench_grid_update();
  return 0;
}
