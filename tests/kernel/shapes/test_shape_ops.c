/* The shapes' ops (shapes/shape.h shape_ops), per analytic shape: intersect
 * against an answer found independently of it (bisection on the implicit
 * surface along the ray, brute force), the surface data of a hit (on the
 * surface, the normal the closed form gives), sample_position's density by
 * chi-square (mapped onto the unit sphere or disk by an area-preserving
 * map, its density then the closed-form 1 / area times the map's constant
 * Jacobian), and each shape's area against its closed form. Fixed seeds;
 * chi-square at Mitsuba's 1% significance. */
#include <string.h>

#include "../../../server/kernel/accel.h"
#include "../../../server/kernel/core/rng.h"
#include "../../../server/kernel/shapes/shape.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

/* A sphere of radius 0.7 at (1, -2, 0.5); a disk scaled by 1.5 and rotated;
 * a cylinder of radius 0.4 from (0, 0, 1) to (1, 1, 3); a rectangle
 * scaled by (2, 0.5). */
static const char *scene_text =
    "{\"type\": \"scene\", \"cam\": {\"type\": \"perspective\", \"film\": {\"type\": \"hdrfilm\", \"width\": "
    "2, "
    "\"height\": 2}},"
    " \"ball\": {\"type\": \"sphere\", \"center\": [1, -2, 0.5], \"radius\": 0.7},"
    " \"plate\": {\"type\": \"disk\", \"to_world\": [{\"scale\": [1.5, 1.5, 1.5]}, {\"rotate\": {\"axis\": "
    "[1, 2, "
    "0], \"angle\": 40}}, {\"translate\": [0.3, 0.2, -1]}]},"
    " \"tube\": {\"type\": \"cylinder\", \"p0\": [0, 0, 1], \"p1\": [1, 1, 3], \"radius\": 0.4},"
    " \"quad\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [2, 0.5, 1]}, {\"translate\": [0, 0, "
    "-3]}], \"emitter\": {\"type\": \"area\", \"radiance\": 1}}}";

static scene *g_scene;

static const shape *find(const char *id) {
  for (size_t i = 0; i < g_scene->n_shapes; i++)
    if (g_scene->shapes[i]->base.id && strcmp(g_scene->shapes[i]->base.id, id) == 0)
      return g_scene->shapes[i];
  return NULL;
}

/* ---- intersect vs bisection on the implicit surface ------------------------------ */

/* Object-space implicit function (negative inside) and whether a point
 * with f = 0 lies on the bounded surface. */
typedef struct implicit {
  double (*f)(vec3 p);
  bool (*on)(vec3 p);
  bool (*edge)(vec3 p); /* within rounding of the surface's boundary */
} implicit;
static double f_sphere(vec3 p) {
  return v3_len2(p) - 1.0;
}
static bool on_any(vec3 p) {
  return true;
}
static double f_tube(vec3 p) {
  return p.x * p.x + p.y * p.y - 1.0;
}
static bool on_tube(vec3 p) {
  return p.z >= 0 && p.z <= 1;
}
static bool edge_none(vec3 p) {
  return false;
}
static bool edge_tube(vec3 p) {
  return fabs(p.z) < 1e-6 || fabs(p.z - 1) < 1e-6;
}
static bool edge_disk(vec3 p) {
  return fabs(p.x * p.x + p.y * p.y - 1) < 1e-6;
}
static double f_plane(vec3 p) {
  return p.z;
}
static bool on_disk(vec3 p) {
  return p.x * p.x + p.y * p.y <= 1.0;
}

/* The first t in (tnear, tfar) where f changes sign along o + t d at a
 * point on the surface: a march of 20000 steps, then 200 bisections.
 * Returns false when none; *grazing when some step came within 1e-5 of
 * the surface without a sign change (an answer a march cannot give). */
static bool brute_hit(const implicit *im, vec3 o, vec3 d, double tnear, double tfar, double *t_out,
                      bool *grazing) {
  const int steps = 20000;
  double dt = (tfar - tnear) / steps;
  double t0 = tnear, f0 = im->f(v3_fma(o, t0, d));
  *grazing = false;
  for (int k = 1; k <= steps; k++) {
    double t1 = tnear + k * dt, f1 = im->f(v3_fma(o, t1, d));
    double f2 = im->f(v3_fma(o, t1 + dt, d));
    /* Near the surface with no sign change around: a tangent ray. */
    if (fabs(f1) < 1e-5 && (f0 < 0) == (f1 < 0) && (f1 < 0) == (f2 < 0)) *grazing = true;
    if ((f0 < 0) != (f1 < 0)) {
      double a = t0, b = t1, fa = f0;
      for (int it = 0; it < 200; it++) {
        double m = 0.5 * (a + b), fm = im->f(v3_fma(o, m, d));
        if ((fa < 0) == (fm < 0))
          a = m, fa = fm;
        else
          b = m;
      }
      double t = 0.5 * (a + b);
      vec3 p = v3_fma(o, t, d);
      /* At the surface's edge the two answers may differ in rounding. */
      if (im->edge(p)) *grazing = true;
      if (im->on(p)) {
        *t_out = t;
        return true;
      }
    }
    t0 = t1, f0 = f1;
  }
  return false;
}

static void check_intersect(const char *id, const implicit *im) {
  const shape *s = find(id);
  REQUIRE(s && s->ops->intersect, "%s: an analytic shape", id);
  pcg32 g;
  pcg32_seed(&g, 17, 3);
  int hits = 0, misses = 0, wrong = 0, skipped = 0;
  for (int i = 0; i < 600; i++) {
    /* Origins in [-2.5, 2.5]^3, directions of length in [0.5, 2] (not
     * normalised, as Embree hands them in instance space). */
    vec3 o =
        v3(5 * pcg32_next_double(&g) - 2.5, 5 * pcg32_next_double(&g) - 2.5, 5 * pcg32_next_double(&g) - 2.5);
    vec3 d = v3_sub(v3(1.6 * pcg32_next_double(&g) - 0.8, 1.6 * pcg32_next_double(&g) - 0.8,
                       1.6 * pcg32_next_double(&g) - 0.8),
                    o);
    double tnear = 0.05 * pcg32_next_double(&g), tfar = 3.0;
    if (i % 5 == 0) tfar = 0.3 + pcg32_next_double(&g); /* a short segment */
    double oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z}, t = -1, n[3];
    bool got = s->ops->intersect(s, oo, dd, tnear, tfar, &t, n);
    double tb = 0;
    bool grazing;
    bool want = brute_hit(im, o, d, tnear, tfar, &tb, &grazing);
    if (grazing) {
      skipped++;
      continue;
    }
    if (got != want) {
      wrong++;
      continue;
    }
    if (!got) {
      misses++;
      continue;
    }
    hits++;
    if (fabs(t - tb) > 1e-9 * (1 + fabs(tb))) wrong++;
    /* The normal: the implicit surface's gradient direction. */
    vec3 p = v3_fma(o, t, d), nn = v3_norm(v3(n[0], n[1], n[2]));
    vec3 want_n = im->f == f_plane ? v3(0, 0, 1) : im->f == f_tube ? v3_norm(v3(p.x, p.y, 0)) : v3_norm(p);
    if (v3_len(v3_sub(nn, want_n)) > 1e-9) wrong++;
  }
  CHECK(wrong == 0, "%s: %d of %d rays disagree with the brute-force answer", id, wrong,
        hits + misses + wrong);
  CHECK(hits > 40 && misses > 40, "%s: too few hits (%d) or misses (%d) to test", id, hits, misses);
  CHECK(skipped < 60, "%s: %d grazing rays skipped", id, skipped);
}

static void test_sphere_intersect(void) {
  implicit im = {f_sphere, on_any, edge_none};
  check_intersect("ball", &im);
}
static void test_disk_intersect(void) {
  implicit im = {f_plane, on_disk, edge_disk};
  check_intersect("plate", &im);
}
static void test_cylinder_intersect(void) {
  implicit im = {f_tube, on_tube, edge_tube};
  check_intersect("tube", &im);
}

/* ---- a hit's surface data ------------------------------------------------------ */

/* World rays aimed at the shape's object-space origin region; the hit
 * from intersect (in object space, t unchanged by the affine map) filled
 * through shape_fill_interaction: p on the surface (object space, to
 * 1e-12), ng the closed-form normal, a right-handed orthonormal shading
 * frame, wi = -d in it. */
static void check_fill(const char *id, const implicit *im) {
  const shape *s = find(id);
  REQUIRE(s, "%s", id);
  pcg32 g;
  pcg32_seed(&g, 4, 11);
  int n_hit = 0, bad = 0;
  for (int i = 0; i < 400; i++) {
    vec3 to = v3(1.2 * pcg32_next_double(&g) - 0.6, 1.2 * pcg32_next_double(&g) - 0.6, pcg32_next_double(&g));
    vec3 from =
        v3_scale(warp_square_to_uniform_sphere(v2(pcg32_next_double(&g), pcg32_next_double(&g))), 6.0);
    ray3 r = {xf_point(&s->to_world, from), xf_vector(&s->to_world, v3_sub(to, from)), 0, INFINITY};
    vec3 oo = xf_inv_point(&s->to_world, r.o), dd = xf_inv_vector(&s->to_world, r.d);
    double o3[3] = {oo.x, oo.y, oo.z}, d3[3] = {dd.x, dd.y, dd.z}, t, n[3];
    if (!s->ops->intersect(s, o3, d3, 0, INFINITY, &t, n)) continue;
    n_hit++;
    accel_hit h;
    memset(&h, 0, sizeof h);
    h.t = t;
    h.ng = v3(n[0], n[1], n[2]);
    surface_interaction si;
    memset(&si, 0, sizeof si);
    shape_fill_interaction(s, &r, &h, &si);
    vec3 po = xf_inv_point(&s->to_world, si.p);
    vec3 want_n = v3_norm(xf_normal(&s->to_world, im->f == f_plane  ? v3(0, 0, 1)
                                                  : im->f == f_tube ? v3(po.x, po.y, 0)
                                                                    : po));
    if (s->flip_normals) want_n = v3_neg(want_n);
    bool ok = fabs(im->f(po)) < 1e-12 && im->on(po) && v3_len(v3_sub(si.ng, want_n)) < 1e-9 &&
              fabs(v3_len(si.sh.s) - 1) < 1e-12 && fabs(v3_dot(si.sh.s, si.sh.n)) < 1e-12 &&
              v3_len(v3_sub(v3_cross(si.sh.n, si.sh.s), si.sh.t)) < 1e-12 &&
              v3_len(v3_sub(frame_to_world(&si.sh, si.wi), v3_neg(v3_norm(r.d)))) < 1e-12 && si.shape == s;
    if (!ok) bad++;
  }
  CHECK(n_hit > 100, "%s: only %d hits", id, n_hit);
  CHECK(bad == 0, "%s: %d of %d hits with wrong surface data", id, bad, n_hit);
}

static void test_sphere_fill(void) {
  implicit im = {f_sphere, on_any, edge_none};
  check_fill("ball", &im);
}
static void test_disk_fill(void) {
  implicit im = {f_plane, on_disk, edge_disk};
  check_fill("plate", &im);
}
static void test_cylinder_fill(void) {
  implicit im = {f_tube, on_tube, edge_tube};
  check_fill("tube", &im);
}

/* ---- areas and sample_position ---------------------------------------------------- */

static void test_areas(void) {
  const double pi = RSW_PI;
  CHECK_REL(find("ball")->area, 4 * pi * 0.7 * 0.7, 1e-12);
  CHECK_REL(find("plate")->area, pi * 1.5 * 1.5, 1e-12);
  CHECK_REL(find("tube")->area, 2 * pi * 0.4 * sqrt(6.0), 1e-12); /* |p1 - p0| = sqrt 6 */
  CHECK_REL(find("quad")->area, 4.0 * 2.0 * 0.5, 1e-12);
  const char *ids[] = {"ball", "plate", "tube", "quad"};
  for (int i = 0; i < 4; i++) CHECK_REL(shape_pdf_position(find(ids[i])), 1.0 / find(ids[i])->area, 1e-15);
}

/* Points sampled on the shape, mapped back to object space and then onto
 * the unit sphere (sphere: the point itself; cylinder: Archimedes' map
 * (phi, z) -> (phi, w = 2z - 1), area-preserving up to 4 pi / (2 pi)) or
 * the unit disk (disk: object (x, y)). The chi-square pdf is the shape's
 * pdf times the world area of the shape over the target's area: the
 * closed-form areas, so a wrong pdf or a wrong area fails too. */
typedef struct pos_ctx {
  const shape *s;
  double jac; /* closed-form world area / area of the chi-square domain */
  int kind;   /* 0 sphere, 1 disk, 2 cylinder */
  int bad;    /* samples off the surface or with a wrong normal */
} pos_ctx;

static bool s_pos(void *user, const double *u, vec3 *out, double *weight) {
  pos_ctx *c = user;
  position_sample ps = shape_sample_position(c->s, v2(u[0], u[1]));
  vec3 po = xf_inv_point(&c->s->to_world, ps.p);
  vec3 want_n = v3_norm(xf_normal(&c->s->to_world, c->kind == 0   ? po
                                                   : c->kind == 1 ? v3(0, 0, 1)
                                                                  : v3(po.x, po.y, 0)));
  if (v3_len(v3_sub(want_n, ps.n)) > 1e-9 || !(ps.pdf > 0)) c->bad++;
  if (c->kind == 0) {
    if (fabs(v3_len(po) - 1) > 1e-12) c->bad++;
    *out = po;
  } else if (c->kind == 1) {
    if (fabs(po.z) > 1e-12) c->bad++;
    *out = v3(po.x, po.y, 0);
  } else {
    double rr = sqrt(po.x * po.x + po.y * po.y), w = 2 * po.z - 1, st = sqrt(fmax(0, 1 - w * w));
    if (fabs(rr - 1) > 1e-12 || po.z < 0 || po.z > 1) c->bad++;
    *out = v3(st * po.x / rr, st * po.y / rr, w);
  }
  *weight = 1;
  return true;
}

static double p_pos(void *user, vec3 p) {
  pos_ctx *c = user;
  if (c->kind == 1 && p.x * p.x + p.y * p.y > 1) return 0;
  return shape_pdf_position(c->s) * c->jac;
}

static void check_positions(const char *id, int kind, double closed_area) {
  pos_ctx c = {find(id), 0, kind, 0};
  REQUIRE(c.s, "%s", id);
  c.jac = closed_area / (kind == 1 ? RSW_PI : 4 * RSW_PI);
  chi2_config cfg = chi2_defaults(kind == 1 ? CHI2_DISK : CHI2_SPHERE, 2);
  cfg.sample_count = 400000;
  cfg.test_count = 3;
  chi2_result r = chi2_run(&cfg, s_pos, p_pos, &c);
  CHECK(r.passed, "%s: sample_position chi-square failed: %s (p = %g)", id, r.reason, r.p_value);
  CHECK(c.bad == 0, "%s: %d samples off the surface or with a wrong normal", id, c.bad);
}

static void test_sphere_positions(void) {
  check_positions("ball", 0, 4 * RSW_PI * 0.7 * 0.7);
}
static void test_disk_positions(void) {
  check_positions("plate", 1, RSW_PI * 1.5 * 1.5);
}
static void test_cylinder_positions(void) {
  check_positions("tube", 2, 2 * RSW_PI * 0.4 * sqrt(6.0));
}

/* The ops tables: every kind has all of them, meshes no intersect. */
static void test_tables(void) {
  const shape_ops *all[] = {&shape_ops_mesh, &shape_ops_sphere, &shape_ops_disk, &shape_ops_cylinder};
  for (int i = 0; i < 4; i++) {
    const shape_ops *o = all[i];
    CHECK(o->kind && o->bounds && o->world_bounds && o->fill && o->sample_position && o->finalize,
          "shape_ops %d incomplete", i);
    CHECK((o->intersect == NULL) == (o == &shape_ops_mesh), "%s: intersect op", o->kind);
  }
  CHECK(find("quad")->ops == &shape_ops_mesh && find("ball")->ops == &shape_ops_sphere &&
            find("plate")->ops == &shape_ops_disk && find("tube")->ops == &shape_ops_cylinder,
        "plugins carry their geometry's table");
}

int main(void) {
  g_scene = tsup_load(scene_text, "rgb");
  if (!g_scene) {
    fprintf(stdout, "FAIL cannot load the shapes scene\ntest_shape_ops: 0 passed, 1 failed\n");
    return 1;
  }
  RSW_TEST_RUN(test_tables);
  RSW_TEST_RUN(test_areas);
  RSW_TEST_RUN(test_sphere_intersect);
  RSW_TEST_RUN(test_disk_intersect);
  RSW_TEST_RUN(test_cylinder_intersect);
  RSW_TEST_RUN(test_sphere_fill);
  RSW_TEST_RUN(test_disk_fill);
  RSW_TEST_RUN(test_cylinder_fill);
  RSW_TEST_RUN(test_sphere_positions);
  RSW_TEST_RUN(test_disk_positions);
  RSW_TEST_RUN(test_cylinder_positions);
  scene_free(g_scene);
  RSW_TEST_END("test_shape_ops");
}
