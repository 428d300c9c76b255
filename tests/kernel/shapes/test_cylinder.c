/* The `cylinder` shape (issue 11 item 6): Mitsuba 3's open tube
 * (src/shapes/cylinder.cpp), checked against closed forms.
 *
 *  - area = 2 pi r L for p0/p1/radius and a to_world (JSON and XML);
 *  - an area emitter on a cylinder seen directly reads its radiance L;
 *  - at the centre of a long tube emitting inwards (flip_normals), a
 *    Lambertian plate receives E = pi L (minus what the two openings let
 *    out, < 2e-4 relative), so a radiancemeter reads rho L: NEE with the
 *    cylinder's uniform area sampling and MIS, within 3 sigma;
 *  - a horizontal Lambertian cylinder (rho, radius r, length l) under a
 *    sun of irradiance E at theta_s from the zenith, rotated about the
 *    axis, seen from the zenith by a `distant` sensor aimed at a target of
 *    area A: (1/A) int L cos = rho E r l (sin ts + (pi - ts) cos ts) /
 *    (2 pi A), within 3 sigma; the same through a shapegroup + instance;
 *  - the tube as a `distant` sensor's target (uniform area sampling) from
 *    the zenith under a zenith sun reads 2 rho E / pi^2, within 3 sigma;
 *  - chi-square of the area emitter's direction sampling from an outside
 *    point (the density: pdf_A d^2 / cos at the tube's entry point);
 *  - a to_world update equals a reload, bitwise;
 *  - bad radius, p0 == p1 and a shearing to_world are errors naming the
 *    property. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/accel.h"
#include "../../../server/kernel/core/transform.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../../server/kernel/shapes/shape.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

static shape *first_shape(scene *s, const char *id) {
  for (size_t i = 0; i < s->n_shapes; i++)
    if (strcmp(s->shapes[i]->base.id, id) == 0) return s->shapes[i];
  return NULL;
}

/* ---- area ------------------------------------------------------------------- */

static void test_area(void) {
  /* radius 0.5, axis of length |(1, 2, 2)| = 3, then scaled by 2:
   * r = 1, L = 6, area = 12 pi. */
  scene *s =
      tsup_load("{\"type\": \"scene\", \"tube\": {\"type\": \"cylinder\", \"p0\": [1, -1, 0.5],"
                " \"p1\": [2, 1, 2.5], \"radius\": 0.5, \"to_world\": [{\"rotate\": {\"axis\": [1, 1, 0],"
                " \"angle\": 33}}, {\"scale\": 2}, {\"translate\": [3, 0, -1]}]}}",
                NULL);
  REQUIRE(s, "load");
  shape *t = first_shape(s, "tube");
  REQUIRE(t, "tube");
  CHECK_REL(t->area, 12 * PI, 1e-12);
  /* Defaults: p0 (0,0,0), p1 (0,0,1), radius 1: area 2 pi, and the bounds
   * are [-1, 1]^2 x [0, 1]. */
  scene_free(s);
  s = tsup_load("{\"type\": \"scene\", \"tube\": {\"type\": \"cylinder\"}}", NULL);
  REQUIRE(s, "load defaults");
  CHECK_REL(first_shape(s, "tube")->area, 2 * PI, 1e-15);
  CHECK_ABS(s->bbox_min.x, -1, 1e-12);
  CHECK_ABS(s->bbox_max.y, 1, 1e-12);
  CHECK_ABS(s->bbox_min.z, 0, 1e-12);
  CHECK_ABS(s->bbox_max.z, 1, 1e-12);
  scene_free(s);
  /* XML, Mitsuba's element names. */
  s = tsup_load("<scene version=\"3.0.0\"><shape type=\"cylinder\" id=\"tube\">"
                "<point name=\"p0\" x=\"0\" y=\"0\" z=\"-2\"/><point name=\"p1\" x=\"0\" y=\"0\" z=\"2\"/>"
                "<float name=\"radius\" value=\"0.25\"/><boolean name=\"flip_normals\" value=\"true\"/>"
                "</shape></scene>",
                NULL);
  REQUIRE(s, "load xml");
  shape *x = first_shape(s, "tube");
  CHECK_REL(x->area, 2 * PI * 0.25 * 4, 1e-12);
  CHECK(x->flip_normals, "flip_normals not read");
  scene_free(s);
}

/* ---- errors -------------------------------------------------------------------- */

static void expect_error(const char *doc, rsw_status code, const char *where_part, const char *msg_part) {
  scene *s = NULL;
  rsw_err err = {0};
  rsw_status st = scene_load_memory(doc, strlen(doc), "c.json", doc[0] == '<', NULL, &s, &err);
  CHECK(st == code, "status %d (%s), expected %d", (int)st, err.msg, (int)code);
  CHECK(strstr(err.where, where_part) != NULL, "where '%s' lacks '%s'", err.where, where_part);
  CHECK(strstr(err.msg, msg_part) != NULL, "message '%s' lacks '%s'", err.msg, msg_part);
  scene_free(s);
}

static void test_errors(void) {
  expect_error("{\"type\": \"scene\", \"tube\": {\"type\": \"cylinder\", \"radius\": 0}}", RSW_ERR_RANGE,
               "/tube/radius", "radius must be > 0");
  expect_error("{\"type\": \"scene\", \"tube\": {\"type\": \"cylinder\", \"radius\": -2}}", RSW_ERR_RANGE,
               "/tube/radius", "radius must be > 0");
  expect_error(
      "{\"type\": \"scene\", \"tube\": {\"type\": \"cylinder\", \"p0\": [1, 2, 3], \"p1\": [1, 2, 3]}}",
      RSW_ERR_INVALID, "/tube/p1", "p0 and p1 must differ");
  expect_error(
      "<scene version=\"3.0.0\"><shape type=\"cylinder\"><point name=\"p1\" x=\"0\" y=\"0\" z=\"0\"/>"
      "</shape></scene>",
      RSW_ERR_INVALID, "c.json:1", "p0 and p1 must differ");
  /* Shear / an elliptic cross-section. */
  expect_error(
      "{\"type\": \"scene\", \"tube\": {\"type\": \"cylinder\", \"to_world\": [{\"scale\": [1, 2, 1]}]}}",
      RSW_ERR_INVALID, "/tube", "circular and right");
  expect_error("{\"type\": \"scene\", \"tube\": {\"type\": \"cylinder\", \"to_world\": "
               "[[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}}",
               RSW_ERR_INVALID, "/tube", "circular and right");
  expect_error("{\"type\": \"scene\", \"tube\": {\"type\": \"cylinder\", \"radius\": \"big\"}}", RSW_ERR_TYPE,
               "/tube/radius", "must be a number");
}

/* ---- radiometry ------------------------------------------------------------------ */

static void test_emitter_seen_directly(void) {
  /* A narrow camera at (0, -6, 0.5) looks at a radius-1 tube (axis z,
   * z in [0, 1]... scaled to [-2, 3]); every pixel sees the outside. */
  const char *doc =
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"perspective\", \"fov\": 8,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [0, -6, 0.5], \"target\": [0, 0, 0.5], \"up\": [0, 0, "
      "1]}}],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\"},"
      " \"tube\": {\"type\": \"cylinder\", \"p0\": [0, 0, -2], \"p1\": [0, 0, 3],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0},"
      "   \"emitter\": {\"type\": \"area\", \"radiance\": [1, 2, 3]}}}";
  scene *s = tsup_load(doc, NULL);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 8, 0, &img), "render");
  for (int i = 0; i < img.width * img.height; i++) {
    CHECK_REL(img.data[3 * i], 1.0, 1e-6);
    CHECK_REL(img.data[3 * i + 1], 2.0, 1e-6);
    CHECK_REL(img.data[3 * i + 2], 3.0, 1e-6);
  }
  film_image_free(&img);
  scene_free(s);
}

static void test_inside_tube_irradiance(void) {
  /* Tube of radius 1 along x, x in [-20, 20], emitting inwards (flip
   * normals) with L = 2; a small Lambertian plate (rho 0.5, normal +z) at
   * the centre; a radiancemeter above it looking down. max_depth 2: direct
   * light only. The openings (discs of radius 1 at distance 20, seen near
   * grazing by the plate) withhold less than 2e-4 of pi L. */
  const double L = 2.0, rho = 0.5;
  const char *doc =
      "{\"type\": \"scene\","
      " \"meter\": {\"type\": \"radiancemeter\", \"origin\": [0, 0, 0.5], \"direction\": [0, 0, -1],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 60000},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\", \"max_depth\": 2},"
      " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 0.01}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}},"
      " \"tube\": {\"type\": \"cylinder\", \"p0\": [-20, 0, 0], \"p1\": [20, 0, 0], \"flip_normals\": true,"
      "   \"emitter\": {\"type\": \"area\", \"radiance\": 2.0}}}";
  scene *s = tsup_load(doc, "mono");
  REQUIRE(s, "scene");
  double sum = 0, sum2 = 0;
  const int K = 8;
  for (int k = 0; k < K; k++) {
    film_image img;
    REQUIRE(tsup_render(s, 0, 300 + (uint64_t)k, 0, &img), "render");
    sum += img.data[0];
    sum2 += img.data[0] * img.data[0];
    film_image_free(&img);
  }
  double m = sum / K, sem = sqrt(fmax(sum2 / K - m * m, 0) / (K - 1));
  double expect = rho * L;
  printf("  inside tube: %.6f +- %.6f (expected %.6f, -2e-4 rel at most)\n", m, sem, expect);
  CHECK(fabs(m - expect) <= 3 * sem + 2e-4 * expect, "mean %.6g vs %.6g (3 sigma %.3g)", m, expect, 3 * sem);
  CHECK(sem < 0.01 * expect, "standard error %.3g too large for a meaningful test", sem);
  scene_free(s);
}

/* Horizontal tube (axis x, radius r, length l) under a sun at ts from the
 * zenith, tilted in the y-z plane; `distant` from the zenith aimed at a
 * rectangle target of half-sides (a, b). */
static double projected_reading(double rho, double E, double r, double l, double ts, double a, double b) {
  double area = 4 * a * b;
  return rho * E * r * l * (sin(ts) + (PI - ts) * cos(ts)) / (2 * PI * area);
}

static void distant_tube(bool grouped, double ts_deg, double *mean, double *sem) {
  double ts = ts_deg * PI / 180;
  char tube[1024], doc[4096];
  const char *tube_body =
      "\"type\": \"cylinder\", \"p0\": [-1.5, 0, 0], \"p1\": [1.5, 0, 0], \"radius\": 0.4,"
      " \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}";
  if (grouped)
    snprintf(tube, sizeof tube,
             "\"grp\": {\"type\": \"shapegroup\", \"tube\": {%s}},"
             " \"inst\": {\"type\": \"instance\", \"shapegroup\": {\"type\": \"ref\", \"id\": \"grp\"},"
             "   \"to_world\": [{\"translate\": [0, 0, 0.25]}]}",
             tube_body);
  else
    snprintf(tube, sizeof tube, "\"tube\": {%s, \"to_world\": [{\"translate\": [0, 0, 0.25]}]}", tube_body);
  snprintf(
      doc, sizeof doc,
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"distant\", \"direction\": [0, 0, -1],"
      "   \"target\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [2, 1, 1]}]},"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 40000},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\"},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, %.17g, %.17g], \"irradiance\": 1.5},"
      " %s}",
      -sin(ts), -cos(ts), tube);
  scene *s = tsup_load(doc, "mono");
  *mean = *sem = NAN;
  if (!s) return;
  double sum = 0, sum2 = 0;
  const int K = 8;
  for (int k = 0; k < K; k++) {
    film_image img;
    if (!tsup_render(s, 0, 50 + (uint64_t)k, 0, &img)) break;
    sum += img.data[0];
    sum2 += img.data[0] * img.data[0];
    film_image_free(&img);
  }
  *mean = sum / K;
  *sem = sqrt(fmax(sum2 / K - *mean * *mean, 0) / (K - 1));
  scene_free(s);
}

static void test_projected_reflected_power(void) {
  const double angles[2] = {0, 30};
  for (int i = 0; i < 2; i++) {
    double expect = projected_reading(0.6, 1.5, 0.4, 3.0, angles[i] * PI / 180, 2, 1);
    for (int g = 0; g < 2; g++) {
      double m, sem;
      distant_tube(g, angles[i], &m, &sem);
      printf("  %s tube, sun %g deg: %.6f +- %.6f (expected %.6f)\n", g ? "instanced" : "plain", angles[i], m,
             sem, expect);
      CHECK(fabs(m - expect) <= 3 * sem, "%s, sun %g: mean %.6g vs %.6g (3 sigma %.3g)",
            g ? "instanced" : "plain", angles[i], m, expect, 3 * sem);
      CHECK(sem < 0.01 * expect, "standard error %.3g too large", sem);
    }
  }
}

static void test_sensor_target(void) {
  /* `distant` from the zenith aimed at the tube itself (a horizontal
   * Lambertian tube under a zenith sun): target points are uniform in the
   * angle theta around the axis; a point on the lower half is hidden by
   * its mirror image on the upper half, so the reading is
   * (1/pi) int_{-pi/2}^{pi/2} rho E cos(theta) / pi dtheta = 2 rho E / pi^2. */
  const char *doc =
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"distant\", \"direction\": [0, 0, -1],"
      "   \"target\": {\"type\": \"ref\", \"id\": \"tube\"},"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 40000},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.5},"
      " \"tube\": {\"type\": \"cylinder\", \"p0\": [-1, 0, 0.5], \"p1\": [1, 0, 0.5], \"radius\": 0.3,"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}}}";
  scene *s = tsup_load(doc, "mono");
  REQUIRE(s, "scene");
  double sum = 0, sum2 = 0;
  const int K = 8;
  for (int k = 0; k < K; k++) {
    film_image img;
    REQUIRE(tsup_render(s, 0, 70 + (uint64_t)k, 0, &img), "render");
    sum += img.data[0];
    sum2 += img.data[0] * img.data[0];
    film_image_free(&img);
  }
  double m = sum / K, sem = sqrt(fmax(sum2 / K - m * m, 0) / (K - 1)), expect = 2 * 0.6 * 1.5 / (PI * PI);
  printf("  tube as the target: %.6f +- %.6f (expected %.6f)\n", m, sem, expect);
  CHECK(fabs(m - expect) <= 3 * sem, "mean %.6g vs %.6g (3 sigma %.3g)", m, expect, 3 * sem);
  CHECK(sem < 0.01 * expect, "standard error %.3g too large", sem);
  scene_free(s);
}

/* ---- direction sampling chi-square ------------------------------------------------- */

typedef struct chi2_ctx {
  const emitter *e;
  const shape *sh;
  surface_interaction ref;
  bool drop_cosine; /* a wrong density, to show the test can fail */
} chi2_ctx;

static bool s_area(void *user, const double *u, vec3 *out, double *weight) {
  chi2_ctx *c = user;
  direction_sample ds;
  color w = c->e->ops->sample_direction(c->e, &c->ref, v2(u[0], u[1]), &ds);
  if (!(ds.pdf > 0)) {
    *weight = 0;
    return false;
  }
  (void)w;
  *out = ds.d;
  *weight = 1;
  return true;
}

/* Density of the sampled direction, written independently of the kernel:
 * the sampler picks a point uniformly on the tube (1 / area) and keeps it
 * when its front side faces ref, so the solid-angle density of d sums
 * dist^2 / (area cos_e) over the points where the ray from ref along d
 * meets the tube (roots of the infinite cylinder with 0 <= z <= 1 in
 * object space) front side first. */
static double p_area(void *user, vec3 d) {
  chi2_ctx *c = user;
  const xform *t = &c->sh->to_world;
  vec3 o = xf_inv_point(t, c->ref.p), dd = xf_inv_vector(t, d);
  double a = dd.x * dd.x + dd.y * dd.y, b = o.x * dd.x + o.y * dd.y, cc = o.x * o.x + o.y * o.y - 1;
  double disc = b * b - a * cc;
  if (!(a > 0) || disc < 0) return 0;
  double pdf = 0;
  for (int k = 0; k < 2; k++) {
    double tk = (-b + (k ? 1 : -1) * sqrt(disc)) / a;
    vec3 po = v3_fma(o, tk, dd);
    if (!(tk > 0) || po.z < 0 || po.z > 1) continue;
    vec3 pw = xf_point(t, po);
    vec3 n = v3_norm(xf_normal(t, v3(po.x, po.y, 0)));
    if (c->sh->flip_normals) n = v3_neg(n);
    double dist = v3_len(v3_sub(pw, c->ref.p));
    double cos_e = -v3_dot(n, v3_norm(d));
    if (cos_e > 0) pdf += dist * dist / ((c->drop_cosine ? 1.0 : cos_e) * c->sh->area);
  }
  return pdf;
}

static void test_direction_sampling_chi2(void) {
  /* From inside a tube emitting inwards: the density is bounded (seen
   * from outside it diverges at the silhouette, where cos_e -> 0, beyond
   * what the cell integration can follow) and cut off at the openings. */
  scene *s =
      tsup_load("{\"type\": \"scene\", \"tube\": {\"type\": \"cylinder\", \"p0\": [0, 0, -4],"
                " \"p1\": [0, 0, 4.5], \"radius\": 0.8, \"flip_normals\": true, \"to_world\": [{\"rotate\":"
                " {\"axis\": [1, 0, 0], \"angle\": 20}}], \"emitter\": {\"type\": \"area\"}}}",
                NULL);
  REQUIRE(s, "scene");
  REQUIRE(s->n_emitters == 1, "one emitter");
  chi2_ctx c = {.e = s->emitters[0], .sh = first_shape(s, "tube")};
  c.ref.p = v3(0.3, -0.2, 0.3);
  chi2_config cfg = chi2_defaults(CHI2_SPHERE, 2);
  /* The density climbs steeply towards the openings (dist^2 / cos_e grows
   * as the direction nears the axis) and drops to 0 past their rims:
   * Mitsuba's 4x4 trapezoid rule per cell misjudges those cells (chi2
   * 10402 for 4992 dof here); 40x40 integrates them (p = 0.42). */
  cfg.ires = 40;
  chi2_result r = chi2_run(&cfg, s_area, p_area, &c);
  printf("  chi2 = %.1f, dof %d, p = %.3g\n", r.chi2, r.dof, r.p_value);
  CHECK(r.passed, "chi-square failed: %s (p = %g)", r.reason, r.p_value);
  /* The test can fail: a density that ignores the cosine is rejected. */
  c.drop_cosine = true;
  r = chi2_run(&cfg, s_area, p_area, &c);
  CHECK(!r.passed, "chi-square accepted a density without the cosine (p = %g)", r.p_value);
  scene_free(s);
}

/* ---- update equals reload ------------------------------------------------------------ */

static bool render_once(scene *s, film_image *out) {
  rsw_err err = {0};
  render_opts o = {.size = sizeof o, .sensor = 0, .spp = 16, .seed = 11, .threads = 2};
  if (render_sensor(s, &o, out, NULL, &err)) {
    char buf[1200];
    printf("  render failed: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  return true;
}

static void test_update_equals_reload(void) {
  const char *fmt =
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"perspective\", \"fov\": 60,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [0.5, -3.5, 2.5], \"target\": [0, 0, 0.3], \"up\": [0, 0, "
      "1]}}],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16, \"rfilter\": {\"type\": "
      "\"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0.1, -0.86602540378443864676], "
      "\"irradiance\": 1},"
      " \"ground\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 3}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.4}},"
      " \"tube\": {\"type\": \"cylinder\", %s, \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.8}}}";
  /* The new to_world: a trunk of radius 0.3 and length 1.7, tilted. */
  xform sc = xf_scale(v3(0.3, 0.3, 1.7)), rx = xf_rotate(v3(1, 0.2, 0), 25),
        tr = xf_translate(v3(0.2, -0.1, 0));
  xform t1 = xf_mul(&rx, &sc);
  xform t = xf_mul(&tr, &t1);
  char m[1024], a[4096], b[4096], tw[1100];
  size_t n = (size_t)snprintf(m, sizeof m, "[");
  for (int i = 0; i < 16; i++)
    n += (size_t)snprintf(m + n, sizeof m - n, "%s%.17g", i ? ", " : "", t.m[i / 4][i % 4]);
  snprintf(m + n, sizeof m - n, "]");
  snprintf(a, sizeof a, fmt, "\"p0\": [0, 0, 0], \"p1\": [0.3, 0.2, 1.2], \"radius\": 0.5");
  snprintf(tw, sizeof tw, "\"to_world\": %s", m);
  snprintf(b, sizeof b, fmt, tw);
  scene *s = tsup_load(a, NULL), *s2 = tsup_load(b, NULL);
  REQUIRE(s && s2, "load");
  film_image pre = {0}, post = {0}, ref = {0};
  REQUIRE(render_once(s, &pre), "render S");
  param_update item = {.key = "tube.to_world"};
  rsw_err err = {0};
  REQUIRE(param_value_parse(m, item.key, &item.value, &err) == RSW_OK, "parse: %s", err.msg);
  update_report rep = {0};
  rsw_status st = scene_update(s, &item, 1, &rep, &err);
  param_value_free(&item.value);
  REQUIRE(st == RSW_OK, "update: %s", err.msg);
  CHECK(rep.classes == UPDATE_GEOMETRIC, "classes %u", rep.classes);
  CHECK(rep.instance_updates == 1 && rep.rebuilds == 0, "instance updates %u, rebuilds %u",
        rep.instance_updates, rep.rebuilds);
  CHECK_REL(first_shape(s, "tube")->area, 2 * PI * 0.3 * 1.7, 1e-12);
  REQUIRE(render_once(s, &post) && render_once(s2, &ref), "render");
  size_t cnt = (size_t)pre.width * pre.height * pre.channels;
  CHECK(memcmp(pre.data, post.data, cnt * sizeof(float)) != 0, "the update did not change the film");
  CHECK(memcmp(post.data, ref.data, cnt * sizeof(float)) == 0, "updated film differs from the reloaded one");
  /* A shearing to_world is refused, naming the key, and changes nothing. */
  REQUIRE(param_value_parse("[1, 0.5, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]", item.key, &item.value,
                            &err) == RSW_OK,
          "parse");
  memset(&err, 0, sizeof err);
  st = scene_update(s, &item, 1, &rep, &err);
  param_value_free(&item.value);
  CHECK(st == RSW_ERR_INVALID, "shear accepted (%d)", (int)st);
  CHECK(strstr(err.msg, "tube.to_world") && strstr(err.msg, "circular"), "message: %s", err.msg);
  CHECK_REL(first_shape(s, "tube")->area, 2 * PI * 0.3 * 1.7, 1e-12);
  film_image_free(&pre);
  film_image_free(&post);
  film_image_free(&ref);
  scene_free(s);
  scene_free(s2);
}

/* The Embree frame is centred on the geometry's bounds (accel.h): a lone
 * 100 m trunk from z = 0 to z = 100 centres it half way up, not at its
 * foot (the unit tube spans 0 <= z <= 1 in object space). */
static void test_frame_centre(void) {
  scene *s = tsup_load("{\"type\": \"scene\", \"t\": {\"type\": \"cylinder\", \"p0\": [5, 0, 0],"
                       " \"p1\": [5, 0, 100], \"radius\": 0.5}}",
                       NULL);
  REQUIRE(s, "scene loads");
  vec3 c = accel_origin(s->accel);
  printf("  frame centre (%g, %g, %g)\n", c.x, c.y, c.z);
  CHECK(fabs(c.x - 5) < 1e-9 && fabs(c.y) < 1e-9 && fabs(c.z - 50) < 1e-9,
        "the frame centre is the trunk's middle (5, 0, 50), got (%g, %g, %g)", c.x, c.y, c.z);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_area);
  RSW_TEST_RUN(test_errors);
  RSW_TEST_RUN(test_emitter_seen_directly);
  RSW_TEST_RUN(test_inside_tube_irradiance);
  RSW_TEST_RUN(test_projected_reflected_power);
  RSW_TEST_RUN(test_sensor_target);
  RSW_TEST_RUN(test_direction_sampling_chi2);
  RSW_TEST_RUN(test_update_equals_reload);
  RSW_TEST_RUN(test_frame_centre);
  RSW_TEST_END("test_cylinder");
}
