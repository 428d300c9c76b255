/* The area emitter's precomputed world triangles (emitters/area.c): a
 * sample drawn through them equals, bit for bit, the one the shape makes
 * without them (shapes/shape.c builds each triangle with the same code),
 * for a two-triangle rectangle and a 12-triangle cube light, and the
 * direction, distance and pdf follow from that point; and a chi-square test
 * of sample_direction against a density written independently of the
 * kernel (ray-triangle intersection over the light's world triangles); and
 * the batched op (sample_direction_batch, structure-of-arrays lanes per
 * ISA) bitwise sample_direction lane by lane at every ISA. (That the triangles
 * follow to_world and vertex updates is checked as update = reload in
 * tests/kernel/scene/test_update_reload.c.) */
#include <string.h>

#include "../../../server/kernel/core/isa.h"
#include "../../../server/kernel/core/rng.h"
#include "../../../server/kernel/shapes/shape.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static const char *scene_fmt =
    "{\"type\": \"scene\", \"cam\": {\"type\": \"perspective\", \"fov\": 40, \"to_world\": [{\"lookat\": "
    "{\"origin\": [0, -3, 1], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}], \"film\": {\"type\": \"hdrfilm\", "
    "\"width\": 4, \"height\": 4}},"
    " \"floor\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\"}},"
    " \"light\": {\"type\": \"%s\", \"to_world\": [{\"scale\": [0.3, 0.2, 0.1]}, {\"rotate\": {\"axis\": [1, "
    "1, 0], \"angle\": 170}}, {\"translate\": [0.1, 0.2, 1.5]}],"
    "   \"emitter\": {\"type\": \"area\", \"radiance\": 2}}}";

static void check_light(const char *shape_type) {
  char text[2048];
  snprintf(text, sizeof text, scene_fmt, shape_type);
  scene *s = tsup_load(text, "rgb");
  REQUIRE(s, "load a %s light", shape_type);
  const emitter *e = NULL;
  for (size_t i = 0; i < s->n_emitters; i++)
    if (s->emitters[i]->flags & EMITTER_SURFACE) e = s->emitters[i];
  REQUIRE(e && e->shape, "%s: the area emitter", shape_type);
  surface_interaction ref;
  memset(&ref, 0, sizeof ref);
  ref.p = v3(0.05, -0.1, 0.0);
  pcg32 r;
  pcg32_seed(&r, 5, 9);
  int differ = 0, sampled = 0;
  for (int i = 0; i < 20000; i++) {
    vec2 u = v2(pcg32_next_double(&r), pcg32_next_double(&r));
    direction_sample ds;
    color c = e->ops->sample_direction(e, &ref, u, &ds);
    position_sample ps = shape_sample_position(e->shape, u);
    if (memcmp(&ds.p, &ps.p, sizeof ps.p) != 0 || memcmp(&ds.n, &ps.n, sizeof ps.n) != 0) differ++;
    if (ds.pdf > 0) {
      sampled++;
      double d2 = v3_len2(v3_sub(ps.p, ref.p));
      double cos_e = -v3_dot(ds.d, ps.n);
      CHECK_REL(ds.pdf, d2 / (cos_e * e->shape->area), 1e-12);
      CHECK_REL(c.c[0], 2.0 / ds.pdf, 1e-12);
    }
  }
  CHECK(differ == 0, "%s: %d of 20000 samples differ from the shape's own", shape_type, differ);
  CHECK(sampled > 5000, "%s: only %d samples face the reference point", shape_type, sampled);
  scene_free(s);
}

static void test_rectangle_light(void) {
  check_light("rectangle");
}

static void test_cube_light(void) {
  check_light("cube");
}

/* ---- the batched op against sample_direction --------------------------------------- */

/* Every field sample_direction writes, bit for bit (d and dist are left
 * as they were when the distance is zero; both sides start from the same
 * bytes). */
static bool same_sample(const direction_sample *a, const direction_sample *b) {
  return !memcmp(&a->p, &b->p, sizeof a->p) && !memcmp(&a->n, &b->n, sizeof a->n) &&
         !memcmp(&a->d, &b->d, sizeof a->d) && !memcmp(&a->dist, &b->dist, sizeof a->dist) &&
         !memcmp(&a->pdf, &b->pdf, sizeof a->pdf) && a->delta == b->delta;
}

/* n lanes (over two chunks of the op's 64) with reference points in front
 * of the light, behind it (cos_e <= 0) and one on a sampled point (zero
 * distance), at each ISA this CPU runs: each lane equals sample_direction,
 * and the entries past n stay as they were. */
static void check_batch(const char *shape_type, const char *radiance) {
  char text[2048], fmt[2048];
  /* the scene with another radiance */
  snprintf(fmt, sizeof fmt, "%s", scene_fmt);
  char *r = strstr(fmt, "\"radiance\": 2");
  REQUIRE(r, "radiance in the scene text");
  char tail[512];
  snprintf(tail, sizeof tail, "%s", r + strlen("\"radiance\": 2"));
  snprintf(r, sizeof fmt - (size_t)(r - fmt), "\"radiance\": %s%s", radiance, tail);
  snprintf(text, sizeof text, fmt, shape_type);
  scene *s = tsup_load(text, "rgb");
  REQUIRE(s, "load a %s light (radiance %s)", shape_type, radiance);
  const emitter *e = NULL;
  for (size_t i = 0; i < s->n_emitters; i++)
    if (s->emitters[i]->flags & EMITTER_SURFACE) e = s->emitters[i];
  REQUIRE(e && e->ops->sample_direction_batch, "%s: the area emitter and its batch op", shape_type);
  enum {
    N = 100,
    PAD = 3
  };
  static surface_interaction si[N];
  const surface_interaction *ref[N];
  vec2 u[N];
  pcg32 rng;
  pcg32_seed(&rng, 23, 4);
  memset(si, 0, sizeof si);
  for (int k = 0; k < N; k++) {
    /* below the light (it faces down, mostly) or above it */
    double z = k % 3 == 2 ? 3.0 : -0.5 + pcg32_next_double(&rng);
    si[k].p = v3(2 * pcg32_next_double(&rng) - 1, 2 * pcg32_next_double(&rng) - 1, z);
    ref[k] = &si[k];
    u[k] = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
  }
  si[7].p = shape_sample_position(e->shape, u[7]).p; /* zero distance */
  int isas = 0;
  rsw_isa was = rsw_isa_get();
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    isas++;
    direction_sample ds[N + PAD], one[N + PAD];
    color v[N + PAD], w[N + PAD];
    memset(ds, 0xa5, sizeof ds), memset(one, 0xa5, sizeof one);
    memset(v, 0x5a, sizeof v), memset(w, 0x5a, sizeof w);
    e->ops->sample_direction_batch(e, N, ref, u, ds, v);
    int bad = 0, lit = 0, back = 0;
    for (int k = 0; k < N; k++) {
      w[k] = e->ops->sample_direction(e, ref[k], u[k], &one[k]);
      bad += memcmp(&w[k], &v[k], sizeof w[k]) != 0 || !same_sample(&one[k], &ds[k]);
      lit += one[k].pdf > 0, back += !(one[k].pdf > 0);
    }
    CHECK(bad == 0, "%s (%s) at %s: %d of %d lanes differ from sample_direction", shape_type, radiance,
          rsw_isa_name((rsw_isa)isa), bad, N);
    CHECK(!memcmp(&ds[N], &one[N], PAD * sizeof ds[0]) && !memcmp(&v[N], &w[N], PAD * sizeof v[0]),
          "%s at %s: entries past n written", shape_type, rsw_isa_name((rsw_isa)isa));
    CHECK(lit > N / 3 && back > N / 4, "%s: lit %d, unlit %d of %d lanes", shape_type, lit, back, N);
  }
  CHECK(isas >= 2, "at least two ISAs (%d)", isas);
  rsw_isa_set(was);
  scene_free(s);
}

static void test_batch_matches_scalar(void) {
  check_batch("rectangle", "2");
  check_batch("cube", "2");
  check_batch("rectangle", "{\"type\": \"checkerboard\"}");
}

/* ---- direction sampling chi-square ------------------------------------------------- */

typedef struct chi2_ctx {
  const emitter *e;
  const shape *sh;
  surface_interaction ref;
} chi2_ctx;

/* Through the wave's call (kernel.h emitter_sample_direction_n: the batched
 * op or its fallback; test_wave checks it is bitwise sample_direction lane by
 * lane), one lane at a time. */
static bool s_area(void *user, const double *u, vec3 *out, double *weight) {
  chi2_ctx *c = user;
  direction_sample ds;
  const surface_interaction *ref = &c->ref;
  vec2 uu = v2(u[0], u[1]);
  color value;
  emitter_sample_direction_n(c->e, 1, &ref, &uu, &ds, &value);
  *weight = ds.pdf > 0 ? 1 : 0;
  if (!(ds.pdf > 0)) return false;
  *out = ds.d;
  return true;
}

/* Uniform area sampling of the whole mesh, kept where the front side
 * faces ref: along d the solid-angle density sums dist^2 / (area cos_e)
 * over the front-facing triangles the ray from ref meets (Moller-Trumbore
 * on the vertices under to_world). */
static double p_area(void *user, vec3 d) {
  chi2_ctx *c = user;
  const mesh *m = &c->sh->mesh;
  vec3 dir = v3_norm(d);
  double pdf = 0;
  for (uint32_t f = 0; f < m->n_faces; f++) {
    vec3 w[3];
    for (int k = 0; k < 3; k++) {
      const float *q = &m->pos[3 * (size_t)m->faces[3 * (size_t)f + k]];
      w[k] = xf_point(&c->sh->to_world, v3(q[0], q[1], q[2]));
    }
    vec3 e1 = v3_sub(w[1], w[0]), e2 = v3_sub(w[2], w[0]);
    vec3 pv = v3_cross(dir, e2);
    double det = v3_dot(e1, pv);
    if (fabs(det) < 1e-300) continue;
    vec3 tv = v3_sub(c->ref.p, w[0]);
    double bu = v3_dot(tv, pv) / det;
    vec3 qv = v3_cross(tv, e1);
    double bv = v3_dot(dir, qv) / det, t = v3_dot(e2, qv) / det;
    if (bu < 0 || bv < 0 || bu + bv > 1 || !(t > 0)) continue;
    vec3 n = v3_norm(v3_cross(e1, e2));
    if (c->sh->flip_normals) n = v3_neg(n);
    double cos_e = -v3_dot(n, dir);
    if (cos_e > 0) pdf += t * t / (cos_e * c->sh->area);
  }
  return pdf;
}

static void run_chi2_light(const char *text, vec3 ref, const char *what) {
  scene *s = tsup_load(text, "rgb");
  REQUIRE(s, "%s: load", what);
  chi2_ctx c = {0};
  for (size_t i = 0; i < s->n_emitters; i++)
    if (s->emitters[i]->flags & EMITTER_SURFACE) c.e = s->emitters[i];
  REQUIRE(c.e, "%s: the area emitter", what);
  c.sh = c.e->shape;
  c.ref.p = ref;
  chi2_config cfg = chi2_defaults(CHI2_SPHERE, 2);
  cfg.sample_count = 200000;
  cfg.test_count = 2;
  cfg.ires = 8;
  chi2_result r = chi2_run(&cfg, s_area, p_area, &c);
  CHECK(r.passed, "chi2 %s: p = %g, chi2 = %g, dof = %d: %s", what, r.p_value, r.chi2, r.dof, r.reason);
  scene_free(s);
}

static void test_direction_sampling_chi2(void) {
  /* A tilted rectangle close above the reference point (a bounded density
   * over a large solid angle), and from inside a box whose faces emit
   * inwards (12 triangles, several seen along most directions). */
  run_chi2_light(
      "{\"type\": \"scene\", \"light\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": "
      "[1.5, 1.0, 1]}, {\"rotate\": {\"axis\": [1, 0.3, 0], \"angle\": 160}}, {\"translate\": [0.2, "
      "0, 0.6]}], \"emitter\": {\"type\": \"area\"}}}",
      v3(0, 0, 0), "rectangle light");
  run_chi2_light("{\"type\": \"scene\", \"light\": {\"type\": \"cube\", \"flip_normals\": true, "
                 "\"to_world\": [{\"scale\": [1.2, 0.8, 1.0]}, {\"rotate\": {\"axis\": [0, 1, 1], \"angle\": "
                 "25}}], \"emitter\": {\"type\": \"area\"}}}",
                 v3(0.3, -0.2, 0.1), "inward box light");
}

int main(void) {
  RSW_TEST_RUN(test_rectangle_light);
  RSW_TEST_RUN(test_cube_light);
  RSW_TEST_RUN(test_batch_matches_scalar);
  RSW_TEST_RUN(test_direction_sampling_chi2);
  RSW_TEST_END("test_area_light");
}
