/* accel_misses_bounds (accel.h): a ray it calls a miss has no hit and is
 * not occluded, for rays aimed all around the scene's box, grazing its
 * faces, edges and corners just beyond the margin, from near and from far
 * (origins beyond the clip sphere too); rays through the box, or starting
 * inside it, are never culled; and rays that pass the box clearly are. */
#include <math.h>
#include <stdio.h>

#include "../../server/kernel/accel.h"
#include "../../server/kernel/core/rng.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static const char *INSTANCED =
    "{\"type\": \"scene\","
    " \"ball\": {\"type\": \"sphere\", \"center\": [0.3, -0.2, 0.4], \"radius\": 0.5},"
    " \"lid\": {\"type\": \"disk\", \"to_world\": [{\"rotate\": {\"axis\": [1, 1, 0], \"angle\": 35}},"
    "   {\"translate\": [-0.7, 0.5, 1.1]}]},"
    " \"grp\": {\"type\": \"shapegroup\", \"leaf\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": "
    "0.05}]}},"
    " \"i1\": {\"type\": \"instance\", \"shapegroup\": {\"type\": \"ref\", \"id\": \"grp\"},"
    "   \"to_world\": [{\"rotate\": {\"axis\": [0, 1, 0], \"angle\": 80}}, {\"translate\": [1.5, 1.5, "
    "-0.3]}]},"
    " \"cube\": {\"type\": \"cube\", \"to_world\": [{\"scale\": 0.2}, {\"translate\": [-1, -1, 0.2]}]}}";

/* A point of the box grown by f times its half extent (f > 1: outside). */
static vec3 around(const scene *s, pcg32 *r, double f) {
  vec3 c = v3_scale(v3_add(s->bbox_min, s->bbox_max), 0.5),
       h = v3_scale(v3_sub(s->bbox_max, s->bbox_min), 0.5);
  double e = fmax(fmax(h.x, h.y), h.z);
  /* A flat box still gets a shell around it. */
  h = v3(fmax(h.x, 1e-3 * e), fmax(h.y, 1e-3 * e), fmax(h.z, 1e-3 * e));
  double u[3];
  for (int k = 0; k < 3; k++) u[k] = 2.0 * pcg32_next_double(r) - 1.0;
  /* Snap some coordinates to the faces: edges and corners. */
  int snap = (int)(pcg32_next(r) % 4);
  for (int k = 0; k < snap; k++) u[k] = u[k] < 0 ? -1.0 : 1.0;
  return v3(c.x + f * h.x * u[0], c.y + f * h.y * u[1], c.z + f * h.z * u[2]);
}

static void check_scene(scene *s, const char *what) {
  REQUIRE(s, "%s loads", what);
  pcg32 r;
  pcg32_seed(&r, 3, 5);
  long culled = 0, kept_inside = 0, checked = 0;
  const double grow[] = {1.0001, 1.001, 1.01, 1.05, 1.2, 2.0};
  vec3 c = v3_scale(v3_add(s->bbox_min, s->bbox_max), 0.5);
  double R = v3_len(v3_sub(s->bbox_max, c));
  for (int i = 0; i < 60000; i++) {
    /* Through a point near the box, from an origin at 1.5 to 1000 radii. */
    vec3 q = around(s, &r, grow[i % 6]);
    vec3 dir =
        v3(2 * pcg32_next_double(&r) - 1, 2 * pcg32_next_double(&r) - 1, 2 * pcg32_next_double(&r) - 1);
    if (!(v3_len(dir) > 1e-3)) continue;
    dir = v3_norm(dir);
    double far = R * (i % 3 == 0 ? 1000.0 : i % 3 == 1 ? 1.5 : 20.0);
    ray3 ray = {v3_fma(q, -far, dir), dir, 0.0, INFINITY};
    if (i % 7 == 0) ray.d = v3_scale(ray.d, 3.0); /* unnormalised too */
    bool miss = accel_misses_bounds(s->accel, &ray);
    checked++;
    if (!miss) continue;
    culled++;
    accel_hit h;
    CHECK(!accel_intersect(s->accel, &ray, &h), "%s: culled ray %d hits", what, i);
    CHECK(!accel_occluded(s->accel, &ray), "%s: culled ray %d is occluded", what, i);
  }
  /* Origins inside the box are never culled, whatever the direction. */
  for (int i = 0; i < 2000; i++) {
    vec3 q = around(s, &r, 0.999);
    vec3 dir =
        v3(2 * pcg32_next_double(&r) - 1, 2 * pcg32_next_double(&r) - 1, 2 * pcg32_next_double(&r) - 1);
    ray3 ray = {q, dir, 0.0, INFINITY};
    kept_inside += !accel_misses_bounds(s->accel, &ray);
  }
  CHECK(kept_inside == 2000, "%s: %ld of 2000 rays from inside kept", what, kept_inside);
  /* A ray aimed at the centre is kept; one passing two radii beside the
   * box is culled. */
  vec3 side = fabs(s->bbox_max.z - s->bbox_min.z) < R ? v3(0, 0, 1) : v3(1, 0, 0);
  ray3 at = {v3_fma(c, 5 * R, side), v3_neg(side), 0, INFINITY};
  CHECK(!accel_misses_bounds(s->accel, &at), "%s: a ray at the centre is kept", what);
  vec3 beside = side.z != 0 ? v3(1, 0, 0) : v3(0, 0, 1);
  ray3 by = {v3_fma(v3_fma(c, 5 * R, side), 2 * R, beside), v3_neg(side), 0, INFINITY};
  CHECK(accel_misses_bounds(s->accel, &by), "%s: a ray two radii beside is culled", what);
  printf("  %s: %ld of %ld rays culled, none hit\n", what, culled, checked);
  CHECK(culled > checked / 10, "%s: the test culls (%ld of %ld)", what, culled, checked);
  scene_free(s);
}

static void test_culled_rays_miss(void) {
  check_scene(tsup_load_file("proto/examples/hdistant_seed.xml", NULL), "seed");
  check_scene(tsup_load_file("proto/examples/cornell_box.json", NULL), "cornell");
  check_scene(tsup_load(INSTANCED, NULL), "instanced");
}

static void test_null_and_nan(void) {
  ray3 ray = {v3(0, 0, 5), v3(0, 0, -1), 0, INFINITY};
  CHECK(!accel_misses_bounds(NULL, &ray), "NULL structure: not culled");
  scene *s = tsup_load_file("proto/examples/hdistant_seed.xml", NULL);
  REQUIRE(s, "seed");
  ray3 nan = {v3(NAN, 0, 5), v3(0, 0, -1), 0, INFINITY};
  accel_hit h;
  if (accel_misses_bounds(s->accel, &nan))
    CHECK(!accel_intersect(s->accel, &nan, &h), "a culled NaN ray misses");
  ray3 par = {v3(0.5, 0.5, 0.0), v3(1, 0, 0), 0, INFINITY}; /* in the plane of the rectangle */
  CHECK(!accel_misses_bounds(s->accel, &par), "a ray in the surface's plane, from inside, is kept");
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_culled_rays_miss);
  RSW_TEST_RUN(test_null_and_nan);
  RSW_TEST_END("test_accel_bounds");
}
