/* Rays leaving a surface (shapes/shape.h spawn_ray, spawn_ray_between;
 * accel.h accel_surface_error): no self-intersection, no skipped geometry,
 * at the world origin and 100 km from it.
 *
 *  - self-intersection: each scene holds one flat or convex shape (a
 *    rotated, non-uniformly scaled rectangle; a sphere; a 5 cm disk; a
 *    thin open cylinder (a 5 cm trunk, hit inside and out); a
 *    face-normal OBJ mesh, whose hit point comes from o + t d; an instance
 *    of a group holding a transformed mesh; an instancelist disk; a 10 km
 *    plate hit near its edges). Rays are shot at it from outside; from
 *    each hit, rays leave into random directions down to grazing
 *    (cos = 1e-4) on both sides. A ray leaving a flat or convex shape on
 *    its outside can hit nothing; one entering the sphere, or crossing the
 *    cylinder's inside, must reach the far wall (t >= half the chord) or
 *    leave through an open end. Every violation counts. The counts
 *    for smaller multiples of the error bound than RSW_SPAWN_ERRORS are
 *    printed, to show the margin.
 *  - no skipped geometry: two parallel plates 50 um apart; every ray
 *    leaving the lower one upwards must hit the upper one (Mitsuba's
 *    offset, (1 + max|p|) 8.9e-5 m, would skip it even at the origin).
 *  - shadow segments between a plate and an area light facing it are
 *    never occluded (nothing lies between them).
 * Fixed seeds; every count must be zero. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../server/kernel/accel.h"
#include "../../../server/kernel/core/rng.h"
#include "../../../server/kernel/hit.h"
#include "../../../server/kernel/scene/periodic.h"
#include "../../../server/kernel/shapes/instance.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846
static const double U[3] = {0.6, 0.48, 0.64};
static const double K_TRY[] = {0.25, 0.5, 1, 2, 4, RSW_SPAWN_ERRORS};
#define N_K (sizeof K_TRY / sizeof K_TRY[0])

static vec3 sphere_dir(pcg32 *g) {
  double z = 1 - 2 * pcg32_next_double(g), ph = 2 * PI * pcg32_next_double(g), s = sqrt(fmax(0, 1 - z * z));
  return v3(s * cos(ph), s * sin(ph), z);
}

/* A direction on the side of n with cos to n log-uniform in [1e-4, 1]. */
static vec3 side_dir(pcg32 *g, vec3 n) {
  double c = pow(10.0, -4.0 * pcg32_next_double(g)), s = sqrt(1 - c * c), ph = 2 * PI * pcg32_next_double(g);
  frame f = frame_from_normal(n);
  return v3_add(v3_scale(f.n, c), v3_add(v3_scale(f.s, s * cos(ph)), v3_scale(f.t, s * sin(ph))));
}

static bool trace(const scene *s, ray3 r, surface_interaction *si) {
  accel_hit h;
  double off;
  if (!scene_trace(s, &r, &h, &off)) return false;
  hit_fill_interaction(s, &r, &h, si);
  si->t += off;
  return true;
}

/* The shape under test: flat (or convex, seen from outside), a sphere of
 * radius r, or an open tube of radius r along the unit axis (its normals
 * point away from the axis). */
typedef struct shape_kind {
  enum {
    K_FLAT,
    K_SPHERE,
    K_TUBE
  } kind;
  double r;
  vec3 axis;
} shape_kind;
static const shape_kind FLAT_SHAPE = {K_FLAT, 0, {0, 0, 0}};

/* The distance a ray leaving the surface point with normal ng into d
 * travels inside the shape before it meets the far wall; 0 when it leaves
 * on the free side (then it must hit nothing). */
static double far_wall(const shape_kind *k, vec3 ng, vec3 d) {
  double dn = v3_dot(d, ng);
  if (k->kind == K_SPHERE) return 2 * k->r * fabs(dn); /* d is on the side it entered from */
  if (k->kind == K_TUBE && dn < 0) {
    double da = v3_dot(d, k->axis), perp2 = 1 - da * da;
    return perp2 > 0 ? 2 * k->r * -dn / perp2 : INFINITY;
  }
  return 0;
}

/* scene_json: printf format with one %s for the shift ", {translate}".
 * Hits are aimed at points within `aim` of `centre` (before the shift). */
static void self_hits(const char *name, const char *scene_fmt, vec3 centre, double aim,
                      const shape_kind *kind, double D, int n_hits) {
  char shift[200], text[4096];
  snprintf(shift, sizeof shift, ", {\"translate\": [%.17g, %.17g, %.17g]}", D * U[0], D * U[1], D * U[2]);
  snprintf(text, sizeof text, scene_fmt, shift, shift);
  scene *s = tsup_load(text, NULL);
  REQUIRE(s, "%s loads", name);
  vec3 c = v3_add(centre, v3(D * U[0], D * U[1], D * U[2]));
  double R = 3 * aim + 1;
  pcg32 g;
  pcg32_seed(&g, 11, 3);
  unsigned long bad[N_K] = {0}, hits = 0, rays = 0;
  double max_off = 0;
  for (int tries = 0; hits < (unsigned long)n_hits && tries < 50 * n_hits; tries++) {
    vec3 target = v3_add(c, v3_scale(sphere_dir(&g), aim * cbrt(pcg32_next_double(&g))));
    vec3 o = v3_add(target, v3_scale(sphere_dir(&g), R));
    ray3 r = {o, v3_norm(v3_sub(target, o)), 0, INFINITY};
    surface_interaction si;
    if (!trace(s, r, &si)) continue;
    hits++;
    max_off = fmax(max_off, RSW_SPAWN_ERRORS * si.p_error);
    vec3 out = v3_dot(si.ng, r.d) < 0 ? si.ng : v3_neg(si.ng);
    for (int j = 0; j < 8; j++) {
      bool inward = j & 1;
      vec3 d = side_dir(&g, inward ? v3_neg(out) : out);
      rays++;
      for (size_t k = 0; k < N_K; k++) {
        ray3 q = {v3_fma(si.p, K_TRY[k] * si.p_error, inward ? v3_neg(out) : out), d, 0, INFINITY};
        surface_interaction s2;
        bool hit = trace(s, q, &s2);
        bool ok;
        if (kind->kind == K_SPHERE) {
          ok = inward ? hit && s2.t >= 0.5 * far_wall(kind, si.ng, d) : !hit;
        } else if (kind->kind == K_TUBE) {
          double chord = far_wall(kind, si.ng, d); /* the tube's inside, or 0 */
          ok = chord > 0 ? !hit || s2.t >= 0.5 * chord : !hit;
        } else {
          ok = !hit;
        }
        bad[k] += !ok;
      }
    }
  }
  printf("  %-22s shift %6.0f m: %lu hits, %lu rays, offset <= %.2g m; failures at k =", name, D, hits, rays,
         max_off);
  for (size_t k = 0; k < N_K; k++) printf(" %g: %lu", K_TRY[k], bad[k]);
  printf("\n");
  CHECK(hits >= (unsigned long)n_hits / 2, "%s: too few hits (%lu)", name, hits);
  CHECK(bad[N_K - 1] == 0, "%s shifted by %g m: %lu of %lu spawned rays self-intersect", name, D,
        bad[N_K - 1], rays);
  scene_free(s);
}

#define SCENE_HEAD "{\"type\": \"scene\", "

static const char *RECT =
    SCENE_HEAD "\"a\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [3, 0.5, 1]}, "
               "{\"rotate\": {\"axis\": [1, 2, 3], \"angle\": 37}}%s]}}";
static const char *SPHERE = SCENE_HEAD "\"a\": {\"type\": \"sphere\", \"radius\": 2, \"to_world\": "
                                       "[{\"rotate\": {\"axis\": [1, 1, 0], \"angle\": 20}}%s]}}";
static const char *DISK = SCENE_HEAD "\"a\": {\"type\": \"disk\", \"to_world\": [{\"scale\": 0.05}, "
                                     "{\"rotate\": {\"axis\": [0, 1, 1], \"angle\": 70}}%s]}}";
static const char *INST = SCENE_HEAD
    "\"g\": {\"type\": \"shapegroup\", \"m\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [0.2, "
    "0.04, 1]}, "
    "{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 50}}, {\"translate\": [0.3, 0, 0]}]}}, "
    "\"i\": {\"type\": \"instance\", \"shapegroup\": {\"type\": \"ref\", \"id\": \"g\"}, \"to_world\": "
    "[{\"rotate\": {\"axis\": [0, 0, 1], \"angle\": 33}}, {\"translate\": [-0.3, 0.1, 2]}%s]}}";
static const char *BIG =
    SCENE_HEAD "\"a\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [5000, 5000, 1]}, "
               "{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 10}}%s]}}";

/* A 5 cm trunk 1.2 m long on a slanted axis (p1 - p0 = (0.3, 0.6, 1.0)),
 * open at both ends, so rays also hit its inside. */
static const char *TUBE_FMT =
    SCENE_HEAD "\"a\": {\"type\": \"cylinder\", \"radius\": 0.05, \"p0\": [-0.15, "
               "-0.3, -0.5], \"p1\": [0.15, 0.3, 0.5], \"to_world\": [{\"scale\": 1}%s]}}";

static void test_no_self_intersection(void) {
  const double shifts[] = {0, 1e5};
  const shape_kind sphere = {K_SPHERE, 2, {0, 0, 0}};
  const shape_kind tube = {K_TUBE, 0.05, v3_norm(v3(0.3, 0.6, 1.0))};
  for (int i = 0; i < 2; i++) {
    double D = shifts[i];
    self_hits("rotated rectangle", RECT, v3(0, 0, 0), 1.5, &FLAT_SHAPE, D, 3000);
    self_hits("sphere r=2", SPHERE, v3(0, 0, 0), 2.5, &sphere, D, 3000);
    self_hits("cylinder r=5cm", TUBE_FMT, v3(0, 0, 0), 0.4, &tube, D, 3000);
    self_hits("disk r=5cm", DISK, v3(0, 0, 0), 0.05, &FLAT_SHAPE, D, 3000);
    self_hits("instance of a mesh", INST, v3(0, 0.1, 2), 0.25, &FLAT_SHAPE, D, 3000);
    /* A 10 km plate, aimed 4.5 km from its centre. */
    self_hits("10 km plate, edge", BIG, v3(4500, 0, 0), 400, &FLAT_SHAPE, D, 2000);
  }
}

/* Meshes without uv or normals take the position from o + t d; an
 * instancelist disk takes its placement's double translation. */
static void test_no_self_intersection_files(void) {
  char obj[] = "/tmp/rsw_spawn_obj_XXXXXX", lst[] = "/tmp/rsw_spawn_lst_XXXXXX";
  int fd = mkstemp(obj);
  REQUIRE(fd >= 0, "mkstemp");
  FILE *f = fdopen(fd, "w");
  fputs("v -1 -1 0.1\nv 1 -1 -0.2\nv 1 1 0.3\nv -1 1 0\nf 1 2 3\n", f);
  fclose(f);
  fd = mkstemp(lst);
  REQUIRE(fd >= 0, "mkstemp");
  f = fdopen(fd, "w");
  fputs("0.5 0.25 1.5 0.3 -0.2 0.9 0.05\n", f);
  fclose(f);
  const double shifts[] = {0, 1e5};
  for (int i = 0; i < 2; i++) {
    double D = shifts[i];
    char fmt[2048];
    snprintf(fmt, sizeof fmt,
             SCENE_HEAD
             "\"a\": {\"type\": \"obj\", \"filename\": \"%s\", \"face_normals\": true, \"to_world\": "
             "[{\"rotate\": {\"axis\": [1, 2, 0], \"angle\": 25}}%%s]}}",
             obj);
    self_hits("OBJ, face normals", fmt, v3(0, 0, 0), 1.0, &FLAT_SHAPE, D, 3000);
    /* The list's rows hold the shift themselves: write it again. */
    f = fopen(lst, "w");
    REQUIRE(f, "list");
    fprintf(f, "%.17g %.17g %.17g 0.3 -0.2 0.9 0.05\n", 0.5 + D * U[0], 0.25 + D * U[1], 1.5 + D * U[2]);
    fclose(f);
    snprintf(fmt, sizeof fmt,
             SCENE_HEAD "\"g\": {\"type\": \"shapegroup\", \"d\": {\"type\": \"disk\"}}, "
                        "\"l\": {\"type\": \"instancelist\", \"filename\": \"%s\", "
                        "\"shapegroup\": {\"type\": \"ref\", \"id\": \"g\"}}}",
             lst);
    self_hits("instancelist disk 5cm", fmt, v3(0.5, 0.25, 1.5), 0.05, &FLAT_SHAPE, D, 3000);
  }
  unlink(obj);
  unlink(lst);
}

/* Two plates 50 um apart: rays leaving the lower one upwards all hit the
 * upper one. */
static void test_no_skipped_geometry(void) {
  const double shifts[] = {0, 1e3, 1e5};
  for (int i = 0; i < 3; i++) {
    double D = shifts[i];
    char text[2048];
    snprintf(text, sizeof text,
             SCENE_HEAD
             "\"lo\": {\"type\": \"rectangle\", \"to_world\": [{\"translate\": [%.17g, %.17g, %.17g]}]}, "
             "\"hi\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 3}, {\"translate\": "
             "[%.17g, %.17g, %.17g]}]}}",
             D * U[0], D * U[1], D * U[2], D * U[0], D * U[1], 50e-6 + D * U[2]);
    scene *s = tsup_load(text, NULL);
    REQUIRE(s, "plates load");
    pcg32 g;
    pcg32_seed(&g, 5, 9);
    unsigned long missed = 0, n = 0;
    for (int k = 0; k < 3000; k++) {
      vec3 p = v3(D * U[0] + 1.8 * (pcg32_next_double(&g) - 0.5),
                  D * U[1] + 1.8 * (pcg32_next_double(&g) - 0.5), D * U[2] - 1.0);
      ray3 r = {p, v3(0, 0, 1), 0, INFINITY};
      surface_interaction si;
      if (!trace(s, r, &si) || si.shape != s->shapes[0]) continue;
      /* Leave upwards, down to cos = 0.1 (the upper plate is 3x wider). */
      vec3 d = side_dir(&g, v3(0, 0, 1));
      if (d.z < 0.1) d = v3_norm(v3(d.x, d.y, 0.1));
      ray3 q = spawn_ray(&si, d);
      surface_interaction s2;
      n++;
      missed += !(trace(s, q, &s2) && s2.shape == s->shapes[1]);
    }
    printf("  plates 50 um apart, shift %6.0f m: %lu of %lu rays miss the upper plate\n", D, missed, n);
    CHECK(n > 2000 && missed == 0, "shifted by %g m: %lu of %lu rays skip the plate 50 um above", D, missed,
          n);
    scene_free(s);
  }
}

/* Shadow segments from a plate to points on a tilted area light above
 * it: nothing lies between, so none may be occluded. */
static void test_shadow_segments(void) {
  const double shifts[] = {0, 1e5};
  for (int i = 0; i < 2; i++) {
    double D = shifts[i];
    char sh[200], text[2048];
    snprintf(sh, sizeof sh, ", {\"translate\": [%.17g, %.17g, %.17g]}", D * U[0], D * U[1], D * U[2]);
    snprintf(text, sizeof text,
             SCENE_HEAD
             "\"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 2}%s]}, "
             "\"lamp\": {\"type\": \"rectangle\", \"emitter\": {\"type\": \"area\"}, \"to_world\": "
             "[{\"scale\": 0.5}, {\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 160}}, "
             "{\"translate\": [0.3, 0, 1.2]}%s]}}",
             sh, sh);
    scene *s = tsup_load(text, NULL);
    REQUIRE(s, "scene loads");
    const shape *lamp = s->shapes[1];
    REQUIRE(lamp->emitter, "lamp is an emitter");
    pcg32 g;
    pcg32_seed(&g, 8, 1);
    unsigned long occluded = 0, n = 0;
    for (int k = 0; k < 4000; k++) {
      vec3 p = v3(D * U[0] + 3.8 * (pcg32_next_double(&g) - 0.5),
                  D * U[1] + 3.8 * (pcg32_next_double(&g) - 0.5), D * U[2] + 3);
      ray3 r = {p, v3(0, 0, -1), 0, INFINITY};
      surface_interaction si;
      if (!trace(s, r, &si) || si.shape != s->shapes[0]) continue;
      position_sample ps = shape_sample_position(lamp, v2(pcg32_next_double(&g), pcg32_next_double(&g)));
      if (!(v3_dot(ps.n, v3_sub(si.p, ps.p)) > 0)) continue;
      ray3 q = spawn_ray_between(&si, ps.p, ps.n,
                                 accel_surface_error(s->accel, lamp->index, &lamp->to_world, ps.p, ps.n));
      n++;
      occluded += scene_occluded(s, &q);
    }
    printf("  plate to lamp, shift %6.0f m: %lu of %lu shadow segments occluded\n", D, occluded, n);
    CHECK(n > 1000 && occluded == 0, "shifted by %g m: %lu of %lu shadow segments are occluded", D, occluded,
          n);
    scene_free(s);
  }
}

int main(void) {
  RSW_TEST_RUN(test_no_self_intersection);
  RSW_TEST_RUN(test_no_self_intersection_files);
  RSW_TEST_RUN(test_no_skipped_geometry);
  RSW_TEST_RUN(test_shadow_segments);
  RSW_TEST_END("test_spawn");
}
