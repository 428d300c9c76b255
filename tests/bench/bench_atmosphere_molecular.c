/* make bench: atmosphere_molecular. proto/examples/atmosphere_molecular.json:
 * a 2,400-layer `molecular_atmosphere` (AFGL 1986 US standard, 0-120 km,
 * Rayleigh + O3, a 0-2 km aerosol layer) over RPV, `hdistant` 32x32,
 * `piecewise_volpath`, mono. One JSON line:
 *   wavelength_update_us  the medium's prepare() at a new wavelength (all
 *                         2,400 layers recomputed: Rayleigh, O3, particles,
 *                         blend weights, cumulative optical thickness), the
 *                         median of 41 alternating 450 / 650 nm;
 *                         scene_prepare_us: the whole scene's prepare
 *   render_s              the render's wall time at 550 nm (median of 3),
 *                         samples_per_cpu_s per second of render-thread time
 *   piecewise_*           the same layers sent as an explicit piecewise +
 *                         blendphase medium (the same film, bit for bit:
 *                         tests/kernel/media/test_molecular_atmosphere.c);
 *                         render_ratio = piecewise_samples_per_cpu_s /
 *                         samples_per_cpu_s (goal <= 1.05)
 * Threads: $RSW_BENCH_THREADS or all cores. spp: $RSW_BENCH_ATMO_SPP
 * (default 250). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../server/kernel/media/molecular_atmosphere.h"
#include "../../server/kernel/render.h"
#include "../../server/kernel/scene/scene.h"
#include "../support/tsup.h"
#include "bench.h"

#define SCENE "proto/examples/atmosphere_molecular.json"

static const medium *find_medium(const scene *s) {
  for (size_t i = 0; i < s->n_objects; i++)
    if (s->objects[i]->plugin && strcmp(s->objects[i]->plugin->name, "molecular_atmosphere") == 0)
      return (const medium *)s->objects[i];
  return NULL;
}

/* Median wall time and samples per CPU second of 3 renders at 550 nm. */
static int render3(scene *s, uint32_t spp, int threads, double *wall, double *per_cpu) {
  double w[3], c[3];
  for (int i = 0; i < 3; i++) {
    rsw_err err = {0};
    render_opts o = {.size = sizeof o, .spp = spp, .seed = 1, .threads = threads, .wavelength = 550};
    film_image img;
    render_result_stats st;
    if (render_sensor(s, &o, &img, &st, &err)) {
      fprintf(stderr, "bench_atmosphere_molecular: render failed: %s\n", err.msg);
      return 1;
    }
    w[i] = st.wall_s;
    c[i] = (double)st.samples / (st.busy_s > 0 ? st.busy_s : st.wall_s);
    film_image_free(&img);
  }
  *wall = bench_median(w, 3);
  *per_cpu = bench_median(c, 3);
  return 0;
}

int main(void) {
  const char *e = getenv("RSW_BENCH_ATMO_SPP");
  uint32_t spp = e && atoi(e) > 0 ? (uint32_t)atoi(e) : 250;
  int threads = bench_threads();
  scene *s = tsup_load_file(SCENE, "mono");
  if (!s) return 1;
  medium *m = (medium *)find_medium(s);
  if (!m) return 1;
  /* the medium's prepare at a new wavelength */
  double t_med[41], t_scene[41];
  for (int i = 0; i < 41; i++) {
    rsw_err err = {0};
    render_ctx rc = {.variant = VARIANT_MONO, .wavelength = i % 2 ? 450.0 : 650.0};
    double t0 = bench_wall_s();
    if (m->base.plugin->prepare(&m->base, &rc, &err)) return 1;
    t_med[i] = 1e6 * (bench_wall_s() - t0);
    rc.wavelength = i % 2 ? 460.0 : 660.0;
    t0 = bench_wall_s();
    if (scene_prepare(s, &rc, &err)) return 1;
    t_scene[i] = 1e6 * (bench_wall_s() - t0);
  }
  double wl_us = bench_median(t_med, 41), scene_us = bench_median(t_scene, 41);
  double wall, per_cpu;
  if (render3(s, spp, threads, &wall, &per_cpu)) return 1;
  /* The same layers as piecewise: rewrite the document's medium. */
  const double *z, *st, *al, *w;
  uint32_t n;
  size_t np;
  if (!molecular_atmosphere_layers(m, 550, &z, &n, &st, &al, &w, &np) || np != 1) return 1;
  size_t len;
  char *doc = tsup_read_file(SCENE, &len);
  char *a = doc ? strstr(doc, "\"medium_atmosphere\": {") : NULL,
       *b = a ? strstr(a, "\"shape_atmosphere\"") : NULL;
  if (!a || !b) return 1;
  sbuf t = {0};
  sb_printf(&t, "%.*s\"medium_atmosphere\": {\"type\": \"piecewise\", ", (int)(a - doc), doc);
  const double *arr[3] = {st, al, w};
  const char *names[3] = {"sigma_t", "albedo", "weight"};
  for (int g = 0; g < 3; g++) {
    if (g == 2)
      sb_printf(&t, "\"phase\": {\"type\": \"blendphase\", \"phase_0\": {\"type\": \"rayleigh\"}, "
                    "\"phase_1\": {\"type\": \"hg\", \"g\": 0.7}, ");
    sb_printf(&t, "\"%s\": {\"type\": \"gridvolume\", \"data\": [", names[g]);
    for (uint32_t k = 0; k < n; k++) sb_printf(&t, "%s%.17g", k ? ", " : "", arr[g][k]);
    sb_printf(&t,
              "], \"shape\": [%u, 1, 1], \"filter_type\": \"nearest\", \"to_world\": [{\"scale\": [1000000, "
              "1000000, 120000]}, {\"translate\": [-500000, -500000, 0]}]}%s",
              n, g < 2 ? ", " : "}}, ");
  }
  sb_printf(&t, "%s", b);
  free(doc);
  scene *p = tsup_load(t.p, "mono");
  free(t.p);
  if (!p) return 1;
  double pwall, pper_cpu;
  if (render3(p, spp, threads, &pwall, &pper_cpu)) return 1;
  printf("{\"bench\": \"atmosphere_molecular\", \"layers\": %u, \"wavelength_update_us\": %.1f, "
         "\"scene_prepare_us\": %.1f, \"spp\": %u, \"threads\": %d, \"render_s\": %.3f, "
         "\"samples_per_cpu_s\": %.4g, \"piecewise_render_s\": %.3f, \"piecewise_samples_per_cpu_s\": %.4g, "
         "\"render_ratio\": %.3f, \"target_render_ratio\": 1.05}\n",
         n, wl_us, scene_us, spp, threads, wall, per_cpu, pwall, pper_cpu, pper_cpu / per_cpu);
  scene_free(p);
  scene_free(s);
  return 0;
}
