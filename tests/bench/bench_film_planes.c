/* make bench: film_planes. What the planes cost a render: the same
 * 128x128 hdistant film over an RPV plate under a sun (mono, box filter,
 * spp $RSW_BENCH_PLANES_SPP or 64), rendered plain, with variance (the
 * per-pixel moments accumulated in splat) and with variance + brf + brdf
 * (the planes developed). Best of 3 each, interleaved so that machine
 * load hits all three alike. One JSON line per variant:
 *   {"bench": "film_planes", "variant", "wall_s", "overhead": wall / plain} */
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include <unistd.h>

#include "../../server/kernel/render.h"
#include "../../server/kernel/scene/scene.h"
#include "bench.h"

int main(void) {
  const char *e = getenv("RSW_BENCH_THREADS");
  int threads = e ? atoi(e) : 0;
  if (threads <= 0) threads = (int)sysconf(_SC_NPROCESSORS_ONLN);
  e = getenv("RSW_BENCH_PLANES_SPP");
  uint32_t spp = e && atoi(e) > 0 ? (uint32_t)atoi(e) : 64;
  static const char text[] =
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"sensor\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 128, \"height\": 128, \"rfilter\": {\"type\": "
      "\"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [-0.4, 0.3, -0.87], \"irradiance\": 2.5},"
      " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"
      "   \"bsdf\": {\"type\": \"rpv\", \"rho_0\": 0.12, \"k\": 0.9, \"g\": -0.25, \"rho_c\": 0.3}}}";
  scene *sc = NULL;
  rsw_err err = {0};
  scene_load_opts lo = {.size = sizeof lo};
  if (scene_load_memory(text, sizeof text - 1, "bench.json", false, &lo, &sc, &err)) {
    fprintf(stderr, "bench_film_planes: %s\n", err.msg);
    return 1;
  }
  static const struct {
    const char *name;
    unsigned q;
    bool variance;
  } v[3] = {
      {"plain", 0, false}, {"variance", 0, true}, {"variance_brf_brdf", RENDER_Q_BRF | RENDER_Q_BRDF, true}};
  double best[3] = {1e300, 1e300, 1e300};
  for (int rep = 0; rep < 3; rep++)
    for (int k = 0; k < 3; k++) {
      render_opts o = {
          .size = sizeof o, .spp = spp, .threads = threads, .quantities = v[k].q, .variance = v[k].variance};
      film_image img;
      double t0 = bench_wall_s();
      if (render_sensor(sc, &o, &img, NULL, &err)) {
        fprintf(stderr, "bench_film_planes: %s\n", err.msg);
        return 1;
      }
      double t = bench_wall_s() - t0;
      if (t < best[k]) best[k] = t;
      film_image_free(&img);
    }
  for (int k = 0; k < 3; k++)
    printf("{\"bench\": \"film_planes\", \"variant\": \"%s\", \"width\": 128, \"height\": 128, \"spp\": %u, "
           "\"threads\": %d, \"wall_s\": %.4f, \"overhead\": %.3f}\n",
           v[k].name, spp, threads, best[k], best[k] / best[0]);
  scene_free(sc);
  return 0;
}
