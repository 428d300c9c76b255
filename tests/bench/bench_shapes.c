/* make bench: a hit's surface data (hit_fill_interaction through the
 * shape's ops), one JSON object per line.
 *
 *  shape_fill_<scene>  ns per hit -> surface_interaction, one thread, CPU
 *                      time, median of REPEATS: the Cornell box example (rectangles
 *                      and cubes with uv and vertex normals), the hdistant
 *                      seed scene (one rectangle), and one sphere, disk,
 *                      cylinder and instanced rectangle.
 *
 * The hits are those of random rays (origins in a box inside the scene,
 * uniform directions) traced once with accel_intersect; only the fill is
 * timed. $RSW_BENCH_ONLY=prefix runs the figures whose name starts with it. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../server/kernel/accel.h"
#include "../../server/kernel/core/rng.h"
#include "../../server/kernel/hit.h"
#include "../../server/kernel/shapes/instance.h"
#include "../support/tsup.h"
#include "bench.h"

#define REPEATS 5
#define NHITS   4096

static bool wanted(const char *name) {
  const char *only = getenv("RSW_BENCH_ONLY");
  return !only || !*only || strncmp(name, only, strlen(only)) == 0;
}

static ray3 rays[NHITS];
static accel_hit hits[NHITS];

/* Origins uniform in [lo, hi], directions uniform. */
static int bench_fill(const char *name, scene *s, vec3 lo, vec3 hi) {
  if (!s) {
    fprintf(stderr, "bench %s: the scene did not load\n", name);
    return 1;
  }
  pcg32 g;
  pcg32_seed(&g, 7, 1);
  int n = 0;
  for (long tries = 0; n < NHITS && tries < 100L * NHITS; tries++) {
    vec3 o = v3(lo.x + (hi.x - lo.x) * pcg32_next_double(&g), lo.y + (hi.y - lo.y) * pcg32_next_double(&g),
                lo.z + (hi.z - lo.z) * pcg32_next_double(&g));
    vec3 d = warp_square_to_uniform_sphere(v2(pcg32_next_double(&g), pcg32_next_double(&g)));
    ray3 r = {o, d, 0, INFINITY};
    if (accel_intersect(s->accel, &r, &hits[n])) rays[n++] = r;
  }
  if (n < NHITS / 4) {
    fprintf(stderr, "bench %s: only %d hits\n", name, n);
    scene_free(s);
    return 1;
  }
  const int N = 1000000;
  double t[REPEATS], sink = 0;
  for (int rep = 0; rep < REPEATS; rep++) {
    double t0 = bench_thread_cpu_s();
    for (int i = 0; i < N; i++) {
      surface_interaction si;
      int k = i % n;
      hit_fill_interaction(s, &rays[k], &hits[k], &si);
      sink += si.p.x + si.sh.s.y + si.wi.z;
    }
    t[rep] = (bench_thread_cpu_s() - t0) * 1e9 / N;
  }
  qsort(t, REPEATS, sizeof t[0], bench_cmp_double);
  printf("{\"bench\": \"%s\", \"ns_per_hit\": %.2f, \"hits\": %d, \"repeats\": %d, \"checksum\": %.6g}\n",
         name, t[REPEATS / 2], n, REPEATS, sink);
  fflush(stdout);
  scene_free(s);
  return 0;
}

static const char *one_shape = "{\"type\": \"scene\", \"cam\": {\"type\": \"perspective\", \"film\": "
                               "{\"type\": \"hdrfilm\", \"width\": 2, "
                               "\"height\": 2}}, \"it\": %s}";

static scene *load_one(const char *shape_json) {
  char text[1024];
  snprintf(text, sizeof text, one_shape, shape_json);
  return tsup_load(text, "rgb");
}

int main(void) {
  int rc = 0;
  if (wanted("shape_fill_cornell_box"))
    rc |= bench_fill("shape_fill_cornell_box", tsup_load_file("proto/examples/cornell_box.json", "rgb"),
                     v3(-0.9, -0.9, 0.1), v3(0.9, 0.9, 1.9));
  if (wanted("shape_fill_seed"))
    rc |= bench_fill("shape_fill_seed", tsup_load_file("proto/examples/hdistant_seed.xml", "rgb"),
                     v3(-0.5, -0.5, 0.1), v3(0.5, 0.5, 1));
  if (wanted("shape_fill_sphere"))
    rc |= bench_fill("shape_fill_sphere", load_one("{\"type\": \"sphere\", \"radius\": 2}"), v3(-1, -1, -1),
                     v3(1, 1, 1));
  if (wanted("shape_fill_disk"))
    rc |=
        bench_fill("shape_fill_disk", load_one("{\"type\": \"disk\"}"), v3(-0.5, -0.5, 0.1), v3(0.5, 0.5, 1));
  if (wanted("shape_fill_cylinder"))
    rc |= bench_fill("shape_fill_cylinder", load_one("{\"type\": \"cylinder\", \"radius\": 2}"),
                     v3(-1, -1, 0.2), v3(1, 1, 0.8));
  if (wanted("shape_fill_instance"))
    rc |= bench_fill("shape_fill_instance",
                     tsup_load("{\"type\": \"scene\", \"cam\": {\"type\": \"perspective\", \"film\": "
                               "{\"type\": \"hdrfilm\", \"width\": 2, \"height\": 2}}, \"g\": {\"type\": "
                               "\"shapegroup\", \"r\": {\"type\": \"rectangle\"}}, \"it\": {\"type\": "
                               "\"instance\", \"to_world\": [{\"translate\": [0, 0, 0.5]}], \"shapegroup\": "
                               "{\"type\": \"ref\", \"id\": \"g\"}}}",
                               "rgb"),
                     v3(-0.5, -0.5, 0.6), v3(0.5, 0.5, 1.5));
  return rc;
}
