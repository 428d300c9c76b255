/* Sensors, hdrfilm and reconstruction filters, built through their
 * plugins' create() from document nodes (docs/kernel-conventions.md#sensors,
 * #films-and-samplers; mitsuba3 src/sensors/{distant,radiancemeter,perspective}.cpp, src/films/hdrfilm.cpp,
 * src/rfilters/{box,gaussian}.cpp). */
#include "../../support/test.h"
RSW_TEST_DEFINE_GLOBALS

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "kernel/scene/loader.h"
#include "kernel/shapes/shape.h"

/* ---- document helpers --------------------------------------------------- */

static node *mk(const char *type, const char *id) {
  node *n = node_new(NULL, type, type);
  if (n && id) n->id = rsw_strdup(id);
  return n;
}
static void set_num(node *n, const char *name, double v) {
  prop *p = node_add_prop(n, name, PROP_NUMBER, name);
  p->num = v;
  p->is_int = v == floor(v);
}
static void set_str(node *n, const char *name, const char *v) {
  prop *p = node_add_prop(n, name, PROP_STRING, name);
  p->str = rsw_strdup(v);
}
static void set_bool(node *n, const char *name, bool v) {
  node_add_prop(n, name, PROP_BOOL, name)->b = v;
}
static void set_vec(node *n, const char *name, vec3 v) {
  node_add_prop(n, name, PROP_VEC3, name)->vec = v;
}
static void set_xf(node *n, const char *name, xform xf) {
  node_add_prop(n, name, PROP_TRANSFORM, name)->xf = xf;
}
static void add_child(node *n, const char *name, node *c) {
  node_add_prop(n, name, PROP_NODE, name)->child = c;
}
static node *film_node(int w, int h) {
  node *f = mk("hdrfilm", "film");
  set_num(f, "width", w);
  set_num(f, "height", h);
  return f;
}

/* One build: a fake scene that owns nested objects, a loader on it. */
typedef struct harness {
  scene sc;
  rsw_err err;
  loader ld;
  node *doc;
  object *obj;
} harness;

static void h_init(harness *h, node *doc, rsw_variant v) {
  memset(h, 0, sizeof *h);
  h->ld.variant = v;
  h->ld.err = &h->err;
  h->ld.root = doc;
  h->ld.scene = &h->sc;
  h->ld.hooks = &scene_build_hooks;
  h->ld.base_dir = ".";
  h->sc.variant = v;
  h->doc = doc;
}

static rsw_status h_build(harness *h, node *doc, rsw_variant v) {
  h_init(h, doc, v);
  const plugin *pl = registry_find(doc->type);
  if (!pl) return RSW_ERR_UNKNOWN_PLUGIN;
  return pl->create(&h->ld, doc, &h->obj);
}

static void h_free(harness *h) {
  if (h->obj) h->obj->plugin->destroy(h->obj);
  for (size_t i = 0; i < h->sc.n_objects; i++)
    if (h->sc.objects[i]->plugin->destroy) h->sc.objects[i]->plugin->destroy(h->sc.objects[i]);
  free(h->sc.objects);
  node_free(h->doc);
}

static bool all_used(const node *n) {
  for (size_t i = 0; i < n->n_props; i++) {
    if (!n->props[i].used) return false;
    if (n->props[i].kind == PROP_NODE && !all_used(n->props[i].child)) return false;
  }
  return true;
}

/* Build a sensor and call set_scene with bounding sphere (c, r). */
static sensor *build_sensor(harness *h, node *doc, vec3 c, double r) {
  if (h_build(h, doc, VARIANT_MONO) != RSW_OK) return NULL;
  sensor *s = (sensor *)h->obj;
  h->sc.bsphere_center = c;
  h->sc.bsphere_radius = r;
  if (s->ops->set_scene(s, &h->sc, &h->err) != RSW_OK) return NULL;
  return s;
}

#define CHECK_VEC(a, b, tol)                                                                                 \
  do {                                                                                                       \
    vec3 a__ = (a), b__ = (b);                                                                               \
    CHECK(v3_len(v3_sub(a__, b__)) <= (tol), "%s = (%.9f, %.9f, %.9f) vs %s = (%.9f, %.9f, %.9f)", #a,       \
          a__.x, a__.y, a__.z, #b, b__.x, b__.y, b__.z);                                                     \
  } while (0)

/* ---- hdistant ------------------------------------------------------------ */

/* hdistant's test vectors (eradiate/mitsuba3 test_hdistant.py), identity to_world. */
static const struct {
  double u[2];
  vec3 d;
} hdistant_vectors[] = {
    {{0.5, 0.5}, {0, 0, -1}},
    {{0, 0}, {0.70710678118654752, 0.70710678118654752, 0}},
    {{1, 0}, {-0.70710678118654752, 0.70710678118654752, 0}},
    {{0, 1}, {0.70710678118654752, -0.70710678118654752, 0}},
    {{1, 1}, {-0.70710678118654752, -0.70710678118654752, 0}},
};
#define N_VECTORS (sizeof hdistant_vectors / sizeof hdistant_vectors[0])

static void test_hdistant_vectors_identity(void) {
  harness h;
  sensor *s = build_sensor(&h, mk("hdistant", "m"), v3(0, 0, 0), 1.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  CHECK(all_used(h.doc), "unused property");
  for (size_t i = 0; i < N_VECTORS; i++) {
    ray3 r;
    double w =
        s->ops->sample_ray(s, v2(hdistant_vectors[i].u[0], hdistant_vectors[i].u[1]), v2(0.5, 0.5), &r);
    CHECK_VEC(r.d, hdistant_vectors[i].d, 1e-6);
    CHECK_ABS(w, 1.0, 0);
    CHECK_ABS(v3_len(r.d), 1.0, 1e-12);
  }
  h_free(&h);
}

static void test_hdistant_vectors_rotated(void) {
  /* Rotation about +x by 90 degrees: the axis goes to -y. Each ray must be
   * the identity-case ray rotated the same way. */
  xform rot = xf_rotate(v3(1, 0, 0), 90.0);
  node *doc = mk("hdistant", "m");
  set_xf(doc, "to_world", rot);
  harness h;
  sensor *s = build_sensor(&h, doc, v3(0, 0, 0), 1.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  for (size_t i = 0; i < N_VECTORS; i++) {
    ray3 r;
    s->ops->sample_ray(s, v2(hdistant_vectors[i].u[0], hdistant_vectors[i].u[1]), v2(0.5, 0.5), &r);
    CHECK_VEC(r.d, xf_vector(&rot, hdistant_vectors[i].d), 1e-6);
  }
  ray3 r;
  s->ops->sample_ray(s, v2(0.5, 0.5), v2(0.5, 0.5), &r);
  CHECK_VEC(r.d, v3(0, 1, 0), 1e-9); /* zenith exitant = to_world z = -y */
  h_free(&h);

  /* Eradiate's orientation for a measure direction D: look_at(0, D, up). */
  vec3 dir = v3_norm(v3(1, 0, 1));
  xform la;
  REQUIRE(xf_look_at(v3(0, 0, 0), dir, v3(0, 1, 0), &la), "look_at");
  doc = mk("hdistant", "m");
  set_xf(doc, "to_world", la);
  s = build_sensor(&h, doc, v3(0, 0, 0), 1.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  s->ops->sample_ray(s, v2(0.5, 0.5), v2(0.5, 0.5), &r);
  CHECK_VEC(r.d, v3_neg(dir), 1e-9);
  h_free(&h);
}

static void test_hdistant_point_target(void) {
  vec3 p = v3(1, 2, 3);
  node *doc = mk("hdistant", "m");
  set_vec(doc, "target", p);
  harness h;
  sensor *s = build_sensor(&h, doc, v3(0, 0, 0), 5.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  CHECK(all_used(h.doc), "unused property");
  for (int i = 0; i < 20; i++) {
    vec2 u = v2((i % 5 + 0.3) / 5.0, (i / 5 + 0.7) / 4.0);
    ray3 r;
    double w = s->ops->sample_ray(s, u, v2(0.1 * i / 2.0, 0.9), &r);
    vec3 omega = v3_neg(r.d);
    /* Default ray_offset with a target is 2R = 10. */
    CHECK_VEC(r.o, v3_fma(p, 10.0, omega), 1e-9);
    CHECK_ABS(w, 1.0, 0);
  }
  h_free(&h);

  doc = mk("hdistant", "m");
  set_vec(doc, "target", p);
  set_num(doc, "ray_offset", 3.0);
  s = build_sensor(&h, doc, v3(0, 0, 0), 5.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  ray3 r;
  s->ops->sample_ray(s, v2(0.2, 0.8), v2(0.5, 0.5), &r);
  CHECK_VEC(r.o, v3_fma(p, 3.0, v3_neg(r.d)), 1e-12);
  h_free(&h);
}

static void test_hdistant_no_target_disk(void) {
  vec3 c = v3(1, -2, 0.5);
  double R = 2.0;
  xform rot = xf_rotate(v3_norm(v3(1, 1, 0)), 35.0);
  vec3 axis = v3_norm(xf_vector(&rot, v3(0, 0, 1)));
  node *doc = mk("hdistant", "m");
  set_xf(doc, "to_world", rot);
  harness h;
  sensor *s = build_sensor(&h, doc, c, R);
  REQUIRE(s, "build failed: %s", h.err.msg);
  double max_r = 0;
  for (int i = 0; i < 64; i++) {
    vec2 a = v2((i % 8 + 0.5) / 8.0, (i / 8 + 0.5) / 8.0);
    ray3 r;
    /* An off-zenith direction: the disk must still be orthogonal to the
     * sensor axis, not to the ray. */
    double w = s->ops->sample_ray(s, v2(0.1, 0.3), a, &r);
    CHECK_ABS(w, 1.0, 0);
    /* Without a target the default offset is R: q = o + R d - c is the
     * point on the disk. */
    vec3 q = v3_sub(v3_fma(r.o, R, r.d), c);
    CHECK_ABS(v3_dot(q, axis), 0.0, 1e-9);
    CHECK(v3_len(q) <= R * (1 + 1e-12), "|q| = %g > R", v3_len(q));
    if (v3_len(q) > max_r) max_r = v3_len(q);
  }
  CHECK(max_r > 0.8 * R, "disk samples do not spread (max radius %g)", max_r);
  ray3 r;
  s->ops->sample_ray(s, v2(0.1, 0.3), v2(0.5, 0.5), &r);
  CHECK(fabs(v3_dot(r.d, axis)) < 0.99, "test direction is too close to the axis");
  h_free(&h);
}

static void test_hdistant_shape_target(void) {
  node *doc = mk("hdistant", "m");
  add_child(doc, "target", mk("disk", "plate")); /* unit disk, z = 0 */
  harness h;
  sensor *s = build_sensor(&h, doc, v3(0, 0, 0), 3.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  for (int i = 0; i < 32; i++) {
    ray3 r;
    double w = s->ops->sample_ray(s, v2(0.3, 0.6), v2((i + 0.5) / 32.0, 0.77), &r);
    CHECK_REL(w, 1.0, 1e-9);         /* uniform area sampling: 1/(pdf A) = 1 */
    vec3 ps = v3_fma(r.o, 6.0, r.d); /* default offset 2R = 6 */
    CHECK_ABS(ps.z, 0.0, 1e-9);
    CHECK(hypot(ps.x, ps.y) <= 1.0 + 1e-9, "target sample off the disk");
  }
  /* A target without area cannot weight its samples: set_scene fails. */
  shape *plate = NULL;
  for (size_t i = 0; i < h.sc.n_objects; i++)
    if (h.sc.objects[i]->plugin->cls == CLS_SHAPE) plate = (shape *)h.sc.objects[i];
  REQUIRE(plate, "target shape not adopted by the scene");
  plate->area = 0.0;
  CHECK(s->ops->set_scene(s, &h.sc, &h.err) == RSW_ERR_INVALID, "zero-area target accepted");
  CHECK(strcmp(h.err.where, "m") == 0, "error does not name the sensor: '%s'", h.err.where);
  h_free(&h);
}

static void test_hdistant_bad_target(void) {
  node *doc = mk("hdistant", "m");
  set_str(doc, "target", "somewhere");
  harness h;
  CHECK(h_build(&h, doc, VARIANT_MONO) == RSW_ERR_TYPE, "string target accepted");
  CHECK(strstr(h.err.where, "target") != NULL, "error does not name 'target': '%s'", h.err.where);
  h_free(&h);
}

/* ---- distant ------------------------------------------------------------- */

static void test_distant_direction_vs_to_world(void) {
  vec3 dir = v3(1, -1, -2);
  node *doc = mk("distant", "m");
  set_vec(doc, "direction", dir);
  add_child(doc, "film", film_node(1, 1));
  harness h1, h2;
  sensor *s1 = build_sensor(&h1, doc, v3(0.5, 0, 0), 2.0);
  REQUIRE(s1, "build failed: %s", h1.err.msg);
  CHECK(all_used(h1.doc), "unused property");

  vec3 dn = v3_norm(dir), s_, up;
  coordinate_system(dn, &s_, &up);
  xform la;
  REQUIRE(xf_look_at(v3(0, 0, 0), dn, up, &la), "look_at");
  doc = mk("distant", "m");
  set_xf(doc, "to_world", la);
  add_child(doc, "film", film_node(1, 1));
  sensor *s2 = build_sensor(&h2, doc, v3(0.5, 0, 0), 2.0);
  REQUIRE(s2, "build failed: %s", h2.err.msg);

  for (int i = 0; i < 16; i++) {
    vec2 a = v2((i % 4 + 0.25) / 4.0, (i / 4 + 0.75) / 4.0);
    ray3 r1, r2;
    double w1 = s1->ops->sample_ray(s1, v2(0.5, 0.5), a, &r1);
    double w2 = s2->ops->sample_ray(s2, v2(0.5, 0.5), a, &r2);
    CHECK_VEC(r1.d, dn, 1e-12);
    CHECK_VEC(r2.d, r1.d, 1e-12);
    CHECK_VEC(r2.o, r1.o, 1e-12);
    CHECK(w1 == 1.0 && w2 == 1.0, "weights %g %g", w1, w2);
    /* No target: disk orthogonal to the ray through the centre, shifted
     * back by R. */
    vec3 q = v3_sub(v3_fma(r1.o, 2.0, r1.d), v3(0.5, 0, 0));
    CHECK_ABS(v3_dot(q, dn), 0.0, 1e-9);
    CHECK(v3_len(q) <= 2.0 + 1e-9, "off the disk");
  }
  h_free(&h1);
  h_free(&h2);

  /* Both given: error naming the property. */
  doc = mk("distant", "m");
  set_vec(doc, "direction", dir);
  set_xf(doc, "to_world", la);
  add_child(doc, "film", film_node(1, 1));
  CHECK(h_build(&h1, doc, VARIANT_MONO) == RSW_ERR_INVALID, "direction + to_world accepted");
  h_free(&h1);
}

static void test_distant_point_target(void) {
  node *doc = mk("distant", "m");
  set_vec(doc, "direction", v3(0, 0, -1));
  set_vec(doc, "target", v3(1, 1, 0));
  add_child(doc, "film", film_node(1, 1));
  harness h;
  sensor *s = build_sensor(&h, doc, v3(0, 0, 0), 4.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  ray3 r;
  double w = s->ops->sample_ray(s, v2(0.5, 0.5), v2(0.3, 0.3), &r);
  CHECK_VEC(r.o, v3(1, 1, 8), 1e-12); /* p - 2R d */
  CHECK_VEC(r.d, v3(0, 0, -1), 1e-12);
  CHECK_ABS(w, 1.0, 0);
  h_free(&h);
}

static void test_distant_film_must_be_1x1(void) {
  node *doc = mk("distant", "m");
  add_child(doc, "film", film_node(2, 2));
  harness h;
  CHECK(h_build(&h, doc, VARIANT_MONO) == RSW_ERR_INVALID, "2x2 film accepted");
  h_free(&h);
  /* The default film is 768x576: also an error. */
  CHECK(h_build(&h, mk("distant", "m"), VARIANT_MONO) == RSW_ERR_INVALID, "default film accepted");
  h_free(&h);
}

/* ---- radiancemeter -------------------------------------------------------- */

static void test_radiancemeter(void) {
  node *doc = mk("radiancemeter", "m");
  set_vec(doc, "origin", v3(1, 2, 3));
  set_vec(doc, "direction", v3(0, 3, 0));
  add_child(doc, "film", film_node(1, 1));
  harness h;
  sensor *s = build_sensor(&h, doc, v3(0, 0, 0), 1.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  CHECK(all_used(h.doc), "unused property");
  ray3 r;
  double w = s->ops->sample_ray(s, v2(0.1, 0.9), v2(0.2, 0.4), &r);
  CHECK_VEC(r.d, v3(0, 1, 0), 1e-12);
  CHECK_VEC(r.o, v3(1, 2 + RSW_RAY_EPSILON, 3), 1e-12);
  CHECK_ABS(w, 1.0, 0);
  h_free(&h);

  doc = mk("radiancemeter", "m");
  set_vec(doc, "origin", v3(1, 2, 3));
  add_child(doc, "film", film_node(1, 1));
  CHECK(h_build(&h, doc, VARIANT_MONO) == RSW_ERR_MISSING, "origin without direction accepted");
  h_free(&h);

  doc = mk("radiancemeter", "m");
  add_child(doc, "film", film_node(3, 1));
  CHECK(h_build(&h, doc, VARIANT_MONO) == RSW_ERR_INVALID, "3x1 film accepted");
  h_free(&h);
}

/* ---- perspective ---------------------------------------------------------- */

static double angle_deg(vec3 a, vec3 b) {
  return acos(fmin(1.0, v3_dot(v3_norm(a), v3_norm(b)))) * 180.0 / RSW_PI;
}

static void test_perspective_rays(void) {
  vec3 eye = v3(1, 2, 3), up = v3(0, 1, 0);
  vec3 dir = v3_norm(v3(1, 0, 1));
  xform la;
  REQUIRE(xf_look_at(eye, v3_add(eye, dir), up, &la), "look_at");
  node *doc = mk("perspective", "cam");
  set_xf(doc, "to_world", la);
  set_num(doc, "fov", 90.0);
  set_str(doc, "fov_axis", "x");
  add_child(doc, "film", film_node(200, 100));
  harness h;
  sensor *s = build_sensor(&h, doc, v3(0, 0, 0), 1.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  CHECK(all_used(h.doc), "unused property");

  ray3 r;
  double w = s->ops->sample_ray(s, v2(0.5, 0.5), v2(0.5, 0.5), &r);
  CHECK_VEC(r.o, eye, 1e-12);
  CHECK_VEC(r.d, dir, 1e-12); /* centre pixel: along to_world z */
  CHECK_ABS(w, 1.0, 0);
  CHECK_REL(r.tmin, 1e-2, 1e-12);
  CHECK_REL(r.tmax, 1e4, 1e-12);

  /* Left/right edges at fov_x / 2 = 45 degrees; film x increasing goes to
   * image right = cross(dir, up). */
  vec3 right = v3_norm(v3_cross(dir, up));
  ray3 rl, rr;
  s->ops->sample_ray(s, v2(0.0, 0.5), v2(0.5, 0.5), &rl);
  s->ops->sample_ray(s, v2(1.0, 0.5), v2(0.5, 0.5), &rr);
  CHECK_ABS(angle_deg(rl.d, dir), 45.0, 1e-9);
  CHECK_ABS(angle_deg(rr.d, dir), 45.0, 1e-9);
  CHECK(v3_dot(rl.d, right) < 0 && v3_dot(rr.d, right) > 0, "film x does not go to image right");
  double prev = -2;
  for (int i = 0; i <= 10; i++) {
    s->ops->sample_ray(s, v2(i / 10.0, 0.5), v2(0.5, 0.5), &r);
    CHECK(v3_dot(r.d, right) > prev, "not monotonic in film x");
    prev = v3_dot(r.d, right);
  }
  /* Top row (film y = 0) looks up: y extent tan(45)/aspect = 0.5. */
  s->ops->sample_ray(s, v2(0.5, 0.0), v2(0.5, 0.5), &r);
  CHECK(v3_dot(r.d, up) > 0, "film y = 0 is not the top");
  CHECK_ABS(angle_deg(r.d, dir), atan(0.5) * 180 / RSW_PI, 1e-9);
  /* Corner: both extents. */
  s->ops->sample_ray(s, v2(1.0, 1.0), v2(0.5, 0.5), &r);
  vec3 expect = v3_norm(v3_add(v3_add(dir, right), v3_scale(up, -0.5)));
  CHECK_VEC(r.d, expect, 1e-12);
  CHECK_REL(r.tmin, 1e-2 / v3_dot(r.d, dir), 1e-12);
  h_free(&h);
}

static void test_perspective_fov(void) {
  harness h;
  ray3 r;
  /* Default: focal_length 50mm along the diagonal; on a 3:2 film this is
   * the 36 mm width: fov_x = 2 atan(18 / 50). */
  node *doc = mk("perspective", "cam");
  add_child(doc, "film", film_node(36, 24));
  sensor *s = build_sensor(&h, doc, v3(0, 0, 0), 1.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  s->ops->sample_ray(s, v2(0.0, 0.5), v2(0.5, 0.5), &r);
  CHECK_ABS(angle_deg(r.d, v3(0, 0, 1)), atan(18.0 / 50.0) * 180 / RSW_PI, 1e-9);
  h_free(&h);

  /* fov_axis y: 60 degrees vertically. */
  doc = mk("perspective", "cam");
  set_num(doc, "fov", 60.0);
  set_str(doc, "fov_axis", "y");
  add_child(doc, "film", film_node(200, 100));
  s = build_sensor(&h, doc, v3(0, 0, 0), 1.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  s->ops->sample_ray(s, v2(0.5, 0.0), v2(0.5, 0.5), &r);
  CHECK_ABS(angle_deg(r.d, v3(0, 0, 1)), 30.0, 1e-9);
  h_free(&h);

  /* focal_length "35mm" -> diagonal fov 2 atan(43.27 / 70). */
  doc = mk("perspective", "cam");
  set_str(doc, "focal_length", "35mm");
  add_child(doc, "film", film_node(100, 100));
  s = build_sensor(&h, doc, v3(0, 0, 0), 1.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  s->ops->sample_ray(s, v2(0.0, 0.0), v2(0.5, 0.5), &r);
  CHECK_ABS(angle_deg(r.d, v3(0, 0, 1)), atan(sqrt(36.0 * 36 + 24 * 24) / 70.0) * 180 / RSW_PI, 1e-9);
  h_free(&h);
}

static void test_perspective_errors(void) {
  harness h;
  node *doc = mk("perspective", "cam");
  set_num(doc, "fov", 40.0);
  set_str(doc, "focal_length", "50mm");
  CHECK(h_build(&h, doc, VARIANT_MONO) == RSW_ERR_INVALID, "fov + focal_length accepted");
  h_free(&h);

  doc = mk("perspective", "cam");
  set_num(doc, "fov", 40.0);
  set_str(doc, "fov_axis", "z");
  CHECK(h_build(&h, doc, VARIANT_MONO) == RSW_ERR_INVALID, "fov_axis z accepted");
  h_free(&h);

  doc = mk("perspective", "cam");
  set_num(doc, "fov", 180.0);
  CHECK(h_build(&h, doc, VARIANT_MONO) == RSW_ERR_RANGE, "fov 180 accepted");
  h_free(&h);

  doc = mk("perspective", "cam");
  set_xf(doc, "to_world", xf_scale(v3(2, 2, 2)));
  CHECK(h_build(&h, doc, VARIANT_MONO) == RSW_ERR_INVALID, "scaled to_world accepted");
  h_free(&h);

  doc = mk("perspective", "cam");
  set_num(doc, "near_clip", 10.0);
  set_num(doc, "far_clip", 1.0);
  CHECK(h_build(&h, doc, VARIANT_MONO) == RSW_ERR_RANGE, "near > far accepted");
  h_free(&h);

  doc = mk("perspective", "cam");
  set_str(doc, "focal_length", "abc");
  CHECK(h_build(&h, doc, VARIANT_MONO) == RSW_ERR_INVALID, "focal_length abc accepted");
  h_free(&h);
}

/* ---- film and filters ---------------------------------------------------- */

static void test_sensor_defaults(void) {
  harness h;
  sensor *s = build_sensor(&h, mk("hdistant", "m"), v3(0, 0, 0), 1.0);
  REQUIRE(s, "build failed: %s", h.err.msg);
  REQUIRE(s->film && s->sampler, "no default film/sampler");
  CHECK(strcmp(s->film->base.plugin->name, "hdrfilm") == 0, "default film");
  CHECK(s->film->width == 768 && s->film->height == 576, "default size %dx%d", s->film->width,
        s->film->height);
  CHECK(s->film->component_format == COMPFMT_FLOAT16, "default component format");
  CHECK(s->film->pixel_format == PIXFMT_LUMINANCE, "mono must force luminance");
  REQUIRE(s->film->filter, "no default rfilter");
  CHECK(strcmp(s->film->filter->base.plugin->name, "gaussian") == 0, "default rfilter");
  CHECK_REL(s->film->filter->radius, 2.0, 1e-15);
  CHECK(strcmp(s->sampler->base.plugin->name, "independent") == 0, "default sampler");
  CHECK(s->sampler->sample_count == 4, "default spp %u", s->sampler->sample_count);
  h_free(&h);
}

static rsw_status build_film(harness *h, const char *key, const char *value, rsw_variant v) {
  node *f = film_node(4, 3);
  if (key) set_str(f, key, value);
  return h_build(h, f, v);
}

static void test_hdrfilm_formats(void) {
  harness h;
  REQUIRE(build_film(&h, "pixel_format", "rgb", VARIANT_RGB) == RSW_OK, "%s", h.err.msg);
  film *f = (film *)h.obj;
  CHECK(f->pixel_format == PIXFMT_RGB, "rgb");
  CHECK(f->width == 4 && f->height == 3, "size");
  render_ctx mono = {.variant = VARIANT_MONO, .wavelength = 550};
  render_ctx rgb = {.variant = VARIANT_RGB};
  CHECK(f->base.plugin->prepare(&f->base, &mono, &h.err) == RSW_OK, "prepare");
  CHECK(f->pixel_format == PIXFMT_LUMINANCE, "prepare(mono) keeps rgb");
  f->base.plugin->prepare(&f->base, &rgb, &h.err);
  CHECK(f->pixel_format == PIXFMT_RGB, "prepare(rgb) does not restore rgb");
  h_free(&h);

  CHECK(build_film(&h, "pixel_format", "luminance", VARIANT_RGB) == RSW_OK, "luminance");
  CHECK(((film *)h.obj)->pixel_format == PIXFMT_LUMINANCE, "luminance");
  h_free(&h);
  CHECK(build_film(&h, "pixel_format", "rgba", VARIANT_RGB) == RSW_ERR_UNSUPPORTED, "rgba");
  CHECK(strstr(h.err.msg, "rgba") != NULL, "message does not name the value: %s", h.err.msg);
  h_free(&h);
  CHECK(build_film(&h, "pixel_format", "rgba", VARIANT_MONO) == RSW_OK, "rgba in mono");
  CHECK(((film *)h.obj)->pixel_format == PIXFMT_LUMINANCE, "mono luminance");
  h_free(&h);
  CHECK(build_film(&h, "pixel_format", "cmyk", VARIANT_MONO) == RSW_ERR_INVALID, "cmyk");
  h_free(&h);
  CHECK(build_film(&h, "component_format", "float32", VARIANT_MONO) == RSW_OK, "float32");
  CHECK(((film *)h.obj)->component_format == COMPFMT_FLOAT32, "float32");
  h_free(&h);
  CHECK(build_film(&h, "component_format", "uint32", VARIANT_MONO) == RSW_ERR_UNSUPPORTED, "uint32");
  h_free(&h);
  CHECK(build_film(&h, "file_format", "pfm", VARIANT_MONO) == RSW_ERR_UNSUPPORTED, "pfm");
  h_free(&h);
  CHECK(build_film(&h, "file_format", "jpeg", VARIANT_MONO) == RSW_ERR_INVALID, "jpeg");
  h_free(&h);
  CHECK(build_film(&h, "file_format", "OpenEXR", VARIANT_MONO) == RSW_OK, "OpenEXR");
  h_free(&h);

  node *fn = film_node(4, 3);
  set_num(fn, "crop_width", 2);
  CHECK(h_build(&h, fn, VARIANT_MONO) == RSW_ERR_UNSUPPORTED, "partial crop accepted");
  h_free(&h);
  fn = film_node(4, 3);
  set_num(fn, "crop_offset_x", 3);
  set_num(fn, "crop_width", 2);
  CHECK(h_build(&h, fn, VARIANT_MONO) == RSW_ERR_INVALID, "crop outside the film accepted");
  h_free(&h);
  fn = film_node(4, 3);
  set_num(fn, "crop_width", 4);
  set_num(fn, "crop_height", 3);
  set_bool(fn, "sample_border", false);
  add_child(fn, "rfilter", mk("box", "bf"));
  CHECK(h_build(&h, fn, VARIANT_MONO) == RSW_OK, "full crop / box: %s", h.err.msg);
  CHECK(all_used(h.doc), "unused property");
  CHECK(strcmp(((film *)h.obj)->filter->base.plugin->name, "box") == 0, "nested rfilter");
  h_free(&h);
  fn = film_node(0, 3);
  CHECK(h_build(&h, fn, VARIANT_MONO) == RSW_ERR_RANGE, "width 0 accepted");
  h_free(&h);
}

static void test_rfilters(void) {
  harness h;
  REQUIRE(h_build(&h, mk("gaussian", "g"), VARIANT_MONO) == RSW_OK, "%s", h.err.msg);
  rfilter *g = (rfilter *)h.obj;
  CHECK_REL(g->radius, 2.0, 1e-15);
  /* eval(0) = 1 - exp(-r^2/(2 sigma^2)) = 1 - exp(-8); eval(r) = 0. */
  CHECK_REL(g->eval(g, 0.0), 1.0 - exp(-8.0), 1e-14);
  CHECK_ABS(g->eval(g, 2.0), 0.0, 1e-15);
  CHECK_ABS(g->eval(g, -2.5), 0.0, 0);
  CHECK_REL(g->eval(g, 0.5), exp(-0.5) - exp(-8.0), 1e-14);
  h_free(&h);

  node *n = mk("gaussian", "g");
  set_num(n, "stddev", 1.0);
  REQUIRE(h_build(&h, n, VARIANT_MONO) == RSW_OK, "%s", h.err.msg);
  CHECK_REL(((rfilter *)h.obj)->radius, 4.0, 1e-15);
  h_free(&h);

  REQUIRE(h_build(&h, mk("box", "b"), VARIANT_MONO) == RSW_OK, "%s", h.err.msg);
  rfilter *b = (rfilter *)h.obj;
  CHECK_REL(b->radius, 0.5, 0);
  CHECK(b->eval(b, 0.0) == 1.0 && b->eval(b, -0.5) == 1.0 && b->eval(b, 0.49) == 1.0, "box in");
  CHECK(b->eval(b, 0.5) == 0.0 && b->eval(b, -0.51) == 0.0, "box out");
  h_free(&h);
}

int main(void) {
  RSW_TEST_RUN(test_hdistant_vectors_identity);
  RSW_TEST_RUN(test_hdistant_vectors_rotated);
  RSW_TEST_RUN(test_hdistant_point_target);
  RSW_TEST_RUN(test_hdistant_no_target_disk);
  RSW_TEST_RUN(test_hdistant_shape_target);
  RSW_TEST_RUN(test_hdistant_bad_target);
  RSW_TEST_RUN(test_distant_direction_vs_to_world);
  RSW_TEST_RUN(test_distant_point_target);
  RSW_TEST_RUN(test_distant_film_must_be_1x1);
  RSW_TEST_RUN(test_radiancemeter);
  RSW_TEST_RUN(test_perspective_rays);
  RSW_TEST_RUN(test_perspective_fov);
  RSW_TEST_RUN(test_perspective_errors);
  RSW_TEST_RUN(test_sensor_defaults);
  RSW_TEST_RUN(test_hdrfilm_formats);
  RSW_TEST_RUN(test_rfilters);
  RSW_TEST_END("test_sensors");
}
