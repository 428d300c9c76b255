/* Phase functions (server/kernel/phase/): chi-square of every sampling
 * routine against its pdf (Mitsuba's test, tests/support/chi2.h; several
 * g, incident directions, blends), eval == pdf and the weight
 * value / pdf == 1, normalisation (2 pi int p dmu = 1 by quadrature), hg
 * with g = 0 equal to isotropic, and loading / update validation of
 * their parameters (g, blend weight). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../../../server/kernel/phase/phase.h"
#include "../../../server/kernel/scene/param_table.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define CHI2_SAMPLES 200000
/* chi2_run calls in this file (Sidak correction): isotropic 2, hg 8 x 2,
 * blendphase 5 x 2 + 2, rayleigh 3 x 2, tabphase 5 x 2 + 1, tabphase_polarized
 * 2 x 2 + 1, batches 3. */
#define CHI2_TESTS   55

/* ---- helpers ------------------------------------------------------------------ */

/* The phase function with this id (objects a plugin makes for its
 * properties, e.g. a weight's constvolume, carry their holder's id). */
static object *find_obj(const scene *s, const char *id) {
  for (size_t i = 0; i < s->n_objects; i++) {
    object *o = s->objects[i];
    if (o->id && strcmp(o->id, id) == 0 && o->plugin && o->plugin->cls == CLS_PHASE) return o;
  }
  return NULL;
}

/* A mono scene holding top-level phase functions (and what they need). */
static scene *load_phases(const char *objects) {
  char text[4096];
  snprintf(text, sizeof text, "{\"type\": \"scene\", %s}", objects);
  return tsup_load(text, "mono");
}

static rsw_status load_err(const char *objects, rsw_err *err) {
  char text[4096];
  snprintf(text, sizeof text, "{\"type\": \"scene\", %s}", objects);
  scene *s = NULL;
  scene_load_opts o = {.size = sizeof o, .variant = "mono"};
  rsw_status st = scene_load_memory(text, strlen(text), "test-scene", false, &o, &s, err);
  scene_free(s);
  return st;
}

static rsw_status upd1(scene *s, const char *key, const char *json, rsw_err *err) {
  param_update u = {.key = key};
  rsw_status st = param_value_parse(json, key, &u.value, err);
  if (st) return st;
  st = scene_update(s, &u, 1, NULL, err);
  param_value_free(&u.value);
  return st;
}

static medium_interaction mi_at(vec3 wi) {
  medium_interaction mi = {0};
  mi.t = 1.0;
  mi.p = v3(0.2, -0.1, 0.4);
  mi.wi = v3_norm(wi);
  return mi;
}

typedef struct chi2_phase {
  const phase *ph;
  medium_interaction mi;
  int bad;    /* samples whose weight differs from eval / pdf */
  bool batch; /* through phase_sample_batch and phase_eval_pdf_batch (a lane each) */
} chi2_phase;

static bool phase_sample_cb(void *user, const double *u, vec3 *out, double *weight) {
  chi2_phase *c = user;
  double pdf, w, epdf, v;
  vec2 u2 = v2(u[1], u[2]);
  if (c->batch)
    phase_sample_batch(c->ph, 1, &c->mi, &u[0], &u2, out, &pdf, &w);
  else
    w = c->ph->ops->sample(c->ph, &c->mi, u[0], u2, out, &pdf);
  if (!(pdf > 0.0)) {
    *weight = 0.0;
    return false;
  }
  if (c->batch)
    phase_eval_pdf_batch(c->ph, 1, &c->mi, out, &v, &epdf);
  else
    v = c->ph->ops->eval_pdf(c->ph, &c->mi, *out, &epdf);
  if (fabs(epdf - pdf) > 1e-9 * pdf || fabs(w - v / pdf) > 1e-9 * w || fabs(v3_len(*out) - 1.0) > 1e-12)
    c->bad++;
  *weight = w;
  return true;
}

static double phase_pdf_cb(void *user, vec3 wo) {
  chi2_phase *c = user;
  double pdf, v;
  if (c->batch)
    phase_eval_pdf_batch(c->ph, 1, &c->mi, &wo, &v, &pdf);
  else
    c->ph->ops->eval_pdf(c->ph, &c->mi, wo, &pdf);
  return pdf;
}

static void run_chi2_as(const phase *ph, vec3 wi, const char *what, int ires, bool batch) {
  chi2_phase c = {ph, mi_at(wi), 0, batch};
  chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
  cfg.sample_count = CHI2_SAMPLES;
  cfg.test_count = CHI2_TESTS;
  cfg.ires = ires;
  chi2_result r = chi2_run(&cfg, phase_sample_cb, phase_pdf_cb, &c);
  CHECK(r.passed, "chi2 %s, wi = (%.3f, %.3f, %.3f): p = %g, chi2 = %g, dof = %d: %s", what, wi.x, wi.y, wi.z,
        r.p_value, r.chi2, r.dof, r.reason);
  CHECK(c.bad == 0, "%s: %d samples with pdf != eval_pdf's or weight != value / pdf", what, c.bad);
}

static void run_chi2(const phase *ph, vec3 wi, const char *what, int ires) {
  run_chi2_as(ph, wi, what, ires, false);
}

/* 2 pi int_{-1}^{1} p(mu) dmu by Simpson's rule on n intervals (p along a
 * meridian around the forward direction -wi). */
static double phase_integral(const phase *ph, vec3 wi, int n) {
  medium_interaction mi = mi_at(wi);
  frame f = frame_from_normal(v3_neg(mi.wi));
  double sum = 0.0, h = 2.0 / n;
  for (int i = 0; i <= n; i++) {
    double mu = -1.0 + i * h, s = sqrt(fmax(0.0, 1.0 - mu * mu)), pdf;
    vec3 wo = frame_to_world(&f, v3(s * 0.6, s * 0.8, mu));
    double v = ph->ops->eval_pdf(ph, &mi, wo, &pdf);
    sum += v * (i == 0 || i == n ? 1.0 : (i % 2 ? 4.0 : 2.0));
  }
  return 2.0 * RSW_PI * sum * h / 3.0;
}

static const vec3 wis[2] = {{0.0, 0.0, 1.0}, {0.3, -0.5, -0.8}};

/* ---- tests ------------------------------------------------------------------- */

static void test_isotropic(void) {
  scene *s = load_phases("\"iso\": {\"type\": \"isotropic\"}");
  REQUIRE(s, "load");
  const phase *ph = (const phase *)find_obj(s, "iso");
  REQUIRE(ph && ph->base.plugin->cls == CLS_PHASE, "isotropic object");
  for (int k = 0; k < 2; k++) run_chi2(ph, wis[k], "isotropic", 4);
  CHECK_REL(phase_integral(ph, wis[1], 200), 1.0, 1e-12);
  scene_free(s);
}

static void test_hg(void) {
  const double gs[8] = {-0.9, -0.7, -0.3, 0.0, 2e-6, 0.2, 0.5, 0.8};
  for (int i = 0; i < 8; i++) {
    char objs[256], what[64];
    snprintf(objs, sizeof objs, "\"p\": {\"type\": \"hg\", \"g\": %.17g}", gs[i]);
    snprintf(what, sizeof what, "hg g = %g", gs[i]);
    scene *s = load_phases(objs);
    REQUIRE(s, "load %s", what);
    const phase *ph = (const phase *)find_obj(s, "p");
    /* Strong forward/backward peaks need the finer pdf integration. */
    for (int k = 0; k < 2; k++) run_chi2(ph, wis[k], what, fabs(gs[i]) > 0.6 ? 16 : 4);
    CHECK_REL(phase_integral(ph, wis[1], 20000), 1.0, 1e-6);
    /* The mean cosine is g: 2 pi int mu p(mu) dmu. */
    medium_interaction mi = mi_at(wis[0]);
    double m = 0.0;
    int n = 200000;
    for (int j = 0; j < n; j++) {
      double mu = -1.0 + (j + 0.5) * 2.0 / n, pdf;
      vec3 wo = v3(sqrt(fmax(0.0, 1.0 - mu * mu)), 0.0, -mu); /* -wi = (0, 0, -1) */
      m += mu * ph->ops->eval_pdf(ph, &mi, wo, &pdf) * 2.0 / n;
    }
    CHECK_ABS(2.0 * RSW_PI * m, gs[i], 1e-6);
    scene_free(s);
  }
}

/* Forward means wo = -wi: hg with g > 0 peaks there. */
static void test_hg_convention(void) {
  scene *s = load_phases("\"p\": {\"type\": \"hg\", \"g\": 0.7}");
  REQUIRE(s, "load");
  const phase *ph = (const phase *)find_obj(s, "p");
  medium_interaction mi = mi_at(v3(0, 0, 1));
  double pdf, fwd = ph->ops->eval_pdf(ph, &mi, v3(0, 0, -1), &pdf);
  double back = ph->ops->eval_pdf(ph, &mi, v3(0, 0, 1), &pdf);
  CHECK_REL(fwd, (1 - 0.49) / (4 * RSW_PI * pow(1 - 0.7, 3)), 1e-14);
  CHECK_REL(back, (1 - 0.49) / (4 * RSW_PI * pow(1 + 0.7, 3)), 1e-14);
  /* Default g is Mitsuba's 0.8. */
  scene *d = load_phases("\"p\": {\"type\": \"hg\"}");
  REQUIRE(d, "load default");
  const phase *pd = (const phase *)find_obj(d, "p");
  CHECK_REL(pd->ops->eval_pdf(pd, &mi, v3(0, 0, -1), &pdf), (1 - 0.64) / (4 * RSW_PI * pow(0.2, 3)), 1e-14);
  scene_free(d);
  scene_free(s);
}

static void test_hg_zero_is_isotropic(void) {
  scene *s = load_phases("\"h\": {\"type\": \"hg\", \"g\": 0}, \"i\": {\"type\": \"isotropic\"}");
  REQUIRE(s, "load");
  const phase *h = (const phase *)find_obj(s, "h"), *iso = (const phase *)find_obj(s, "i");
  medium_interaction mi = mi_at(wis[1]);
  pcg32 r;
  pcg32_seed(&r, 7, 1);
  for (int k = 0; k < 1000; k++) {
    vec3 wo = warp_square_to_uniform_sphere(v2(pcg32_next_double(&r), pcg32_next_double(&r)));
    double ph, pi;
    double vh = h->ops->eval_pdf(h, &mi, wo, &ph), vi = iso->ops->eval_pdf(iso, &mi, wo, &pi);
    CHECK(vh == vi && ph == pi, "hg(0) %.17g / %.17g vs isotropic %.17g / %.17g", vh, ph, vi, pi);
    double u1 = pcg32_next_double(&r);
    vec2 u2 = v2(pcg32_next_double(&r), pcg32_next_double(&r));
    vec3 a, b;
    double pa, pb, wa = h->ops->sample(h, &mi, u1, u2, &a, &pa),
                   wb = iso->ops->sample(iso, &mi, u1, u2, &b, &pb);
    CHECK(wa == wb && pa == pb, "sample weight/pdf: hg(0) %g/%g, isotropic %g/%g", wa, pa, wb, pb);
  }
  scene_free(s);
}

static void test_blendphase(void) {
  const char *cases[5][2] = {
      {"\"weight\": 0.3, \"phase_0\": {\"type\": \"isotropic\"}, \"phase_1\": {\"type\": \"hg\", \"g\": 0.8}",
       "blend(isotropic, hg 0.8; 0.3)"},
      {"\"weight\": 0.6, \"phase_0\": {\"type\": \"hg\", \"g\": -0.5}, \"phase_1\": {\"type\": \"hg\", "
       "\"g\": 0.7}",
       "blend(hg -0.5, hg 0.7; 0.6)"},
      /* Nested blend, given in reverse order: names decide the order. */
      /* The atmosphere's molecules + aerosols. */
      {"\"weight\": 0.35, \"phase_0\": {\"type\": \"rayleigh\"}, \"phase_1\": {\"type\": \"hg\", \"g\": 0.7}",
       "blend(rayleigh, hg 0.7; 0.35)"},
      {"\"weight\": 0.5, \"phase_0\": {\"type\": \"tabphase\", \"values\": \"0, 1, 0.2, 3\"}, "
       "\"phase_1\": {\"type\": \"rayleigh\"}",
       "blend(tabphase, rayleigh; 0.5)"},
      {"\"weight\": 0.5, \"phase_1\": {\"type\": \"blendphase\", \"weight\": 0.25, \"phase_0\": {\"type\": "
       "\"isotropic\"}, \"phase_1\": {\"type\": \"hg\", \"g\": -0.6}}, \"phase_0\": {\"type\": \"hg\", "
       "\"g\": 0.4}",
       "blend(hg 0.4, blend(isotropic, hg -0.6; 0.25); 0.5)"},
  };
  for (int c = 0; c < 5; c++) {
    char objs[1024];
    snprintf(objs, sizeof objs, "\"b\": {\"type\": \"blendphase\", %s}", cases[c][0]);
    scene *s = load_phases(objs);
    REQUIRE(s, "load %s", cases[c][1]);
    const phase *ph = (const phase *)find_obj(s, "b");
    for (int k = 0; k < 2; k++) run_chi2(ph, wis[k], cases[c][1], 16);
    CHECK_REL(phase_integral(ph, wis[0], 20000), 1.0, 1e-6);
    scene_free(s);
  }
  /* The value is the lerp of the two, weight 0.3 on phase_1. */
  scene *s = load_phases("\"b\": {\"type\": \"blendphase\", \"weight\": 0.3, \"phase_0\": {\"type\": "
                         "\"isotropic\"}, \"phase_1\": {\"type\": \"hg\", \"g\": 0.8}}");
  REQUIRE(s, "load");
  const phase *ph = (const phase *)find_obj(s, "b");
  medium_interaction mi = mi_at(v3(0, 0, 1));
  double pdf, v = ph->ops->eval_pdf(ph, &mi, v3(0, 0, -1), &pdf);
  CHECK_REL(v, 0.7 * RSW_INV_4PI + 0.3 * (1 - 0.64) / (4 * RSW_PI * pow(0.2, 3)), 1e-14);
  CHECK(v == pdf, "value %g == pdf %g", v, pdf);
  /* Weight 0 and 1: one component only (its samples, its density). */
  CHECK(upd1(s, "b.weight.value.value", "1", NULL) == RSW_OK, "weight 1");
  v = ph->ops->eval_pdf(ph, &mi, v3(0, 0, -1), &pdf);
  CHECK_REL(v, (1 - 0.64) / (4 * RSW_PI * pow(0.2, 3)), 1e-14);
  run_chi2(ph, wis[1], "blend weight 1", 16);
  CHECK(upd1(s, "b.weight.value.value", "0", NULL) == RSW_OK, "weight 0");
  v = ph->ops->eval_pdf(ph, &mi, v3(0, 0, -1), &pdf);
  CHECK(v == RSW_INV_4PI, "weight 0: isotropic, got %g", v);
  run_chi2(ph, wis[1], "blend weight 0", 4);
  scene_free(s);
}

/* phase_bind (phase/phase.h): a blendphase with a weight grid looks its
 * weight up once per point when bound, and its bound eval_pdf and sample
 * are the unbound ones bit for bit (the nested blend, not bound, looks
 * its own weight up); a binding made for another phase function is not
 * taken for its own. */
static void test_phase_bind(void) {
  scene *s = load_phases(
      "\"b\": {\"type\": \"blendphase\", \"weight\": {\"type\": \"gridvolume\", \"shape\": [7, 1, 1],"
      " \"data\": [0, 0.1, 0.9, 0.4, 1, 0.25, 0.6]},"
      " \"phase_0\": {\"type\": \"rayleigh\"}, \"phase_1\": {\"type\": \"blendphase\", \"weight\": 0.3,"
      " \"phase_0\": {\"type\": \"hg\", \"g\": 0.7}, \"phase_1\": {\"type\": \"isotropic\"}}}");
  REQUIRE(s, "load");
  const phase *ph = (const phase *)find_obj(s, "b");
  const phase *inner = NULL, *ray = NULL;
  for (size_t i = 0; i < s->n_objects; i++) {
    const object *o = s->objects[i];
    if (!o->plugin || o->plugin->cls != CLS_PHASE) continue;
    if (strcmp(o->plugin->name, "blendphase") == 0 && o != &ph->base) inner = (const phase *)o;
    if (strcmp(o->plugin->name, "rayleigh") == 0) ray = (const phase *)o;
  }
  REQUIRE(ph && inner && ray, "the two blends and the rayleigh");
  pcg32 rng;
  pcg32_seed(&rng, 5, 3);
  int differ = 0, bound = 0;
  for (int k = 0; k < 2000; k++) {
    medium_interaction mi = mi_at(v3(pcg32_next_double(&rng) - 0.5, pcg32_next_double(&rng) - 0.5, 0.3));
    mi.p = v3(pcg32_next_double(&rng), pcg32_next_double(&rng), 1.2 * pcg32_next_double(&rng) - 0.1);
    vec3 wo = v3_norm(v3(pcg32_next_double(&rng) - 0.5, pcg32_next_double(&rng) - 0.5, -0.2));
    double u1 = pcg32_next_double(&rng);
    vec2 u2 = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
    double v[3], pdf[3], sw[3], spdf[3];
    vec3 so[3];
    for (int w = 0; w < 3; w++) {
      medium_interaction m = mi;
      if (w == 1) phase_bind(ph, &m), bound += m.bound == ph;
      if (w == 2) m.bound = ray, m.bound_w = 0.987; /* another phase function's binding */
      v[w] = ph->ops->eval_pdf(ph, &m, wo, &pdf[w]);
      sw[w] = ph->ops->sample(ph, &m, u1, u2, &so[w], &spdf[w]);
    }
    for (int w = 1; w < 3; w++)
      if (memcmp(&v[0], &v[w], sizeof v[0]) || memcmp(&pdf[0], &pdf[w], sizeof pdf[0]) ||
          memcmp(&sw[0], &sw[w], sizeof sw[0]) || memcmp(&spdf[0], &spdf[w], sizeof spdf[0]) ||
          memcmp(&so[0], &so[w], sizeof so[0]))
        differ++;
  }
  CHECK(bound == 2000, "phase_bind binds the blend (%d of 2000)", bound);
  CHECK(differ == 0, "%d of 2000 points differ bound / unbound", differ);
  /* A phase function without a bind op: phase_bind leaves nothing bound. */
  medium_interaction mi = mi_at(v3(0, 0, 1));
  mi.bound = ph;
  phase_bind(ray, &mi);
  CHECK(mi.bound == NULL, "rayleigh binds nothing");
  scene_free(s);
}

static void test_rayleigh(void) {
  scene *s = load_phases("\"r\": {\"type\": \"rayleigh\"}");
  REQUIRE(s, "load");
  const phase *ph = (const phase *)find_obj(s, "r");
  for (int k = 0; k < 2; k++) run_chi2(ph, wis[k], "rayleigh", 4);
  /* A quadratic in mu: Simpson's rule is exact. */
  CHECK_REL(phase_integral(ph, wis[1], 2), 1.0, 1e-14);
  CHECK_REL(phase_integral(ph, wis[0], 100), 1.0, 1e-14);
  medium_interaction mi = mi_at(v3(0, 0, 1));
  double pdf;
  CHECK_REL(ph->ops->eval_pdf(ph, &mi, v3(0, 0, -1), &pdf), 3.0 / (8.0 * RSW_PI), 1e-15);
  CHECK_REL(ph->ops->eval_pdf(ph, &mi, v3(1, 0, 0), &pdf), 3.0 / (16.0 * RSW_PI), 1e-15);
  CHECK_REL(ph->ops->eval_pdf(ph, &mi, v3(0, 0, 1), &pdf), 3.0 / (8.0 * RSW_PI), 1e-15);
  /* The sampled cosine is the cdf's inverse: F(mu(u)) = u. */
  for (int i = 0; i <= 100; i++) {
    double u = i / 100.0, w;
    vec3 wo;
    ph->ops->sample(ph, &mi, 0.5, v2(u, 0.3), &wo, &w);
    double mu = -wo.z;
    CHECK_ABS(0.375 * (mu + mu * mu * mu / 3.0) + 0.5, u, 1e-14);
  }
  scene_free(s);
}

/* rayleigh with depolarization rho: p(mu) = 3 / (8 pi (2 + rho)) ((1 + rho)
 * + (1 - rho) mu^2) (Hansen & Travis 1974 eq. 2.15's F11 over 4 pi),
 * sampled by the exact inverse of its cdf; rho = 0 bit for bit the
 * unpolarized formulas; the update of `depolarization`. */
static void test_rayleigh_depolarization(void) {
  scene *s = load_phases("\"r0\": {\"type\": \"rayleigh\", \"depolarization\": 0}, \"a\": {\"type\": "
                         "\"rayleigh\", \"depolarization\": 0.03}, \"b\": {\"type\": \"rayleigh_polarized\", "
                         "\"depolarization\": 0.3}");
  REQUIRE(s, "load");
  const phase *r0 = (const phase *)find_obj(s, "r0");
  medium_interaction mi = mi_at(wis[1]);
  /* rho = 0: the formulas before depolarization existed, bit for bit. */
  int diff = 0;
  for (int i = 0; i <= 1000; i++) {
    double u = i / 1000.0, pdf, epdf;
    vec3 wo;
    r0->ops->sample(r0, &mi, 0.5, v2(u, 0.7), &wo, &pdf);
    double z = 2.0 * (2.0 * u - 1.0), a = cbrt(z + sqrt(z * z + 1.0));
    double mu = fmin(1.0, fmax(-1.0, a - 1.0 / a));
    vec3 want = phase_direction(&mi, mu, 0.7);
    double v = r0->ops->eval_pdf(r0, &mi, want, &epdf);
    diff += memcmp(&wo, &want, sizeof wo) != 0 || pdf != 3.0 / (16.0 * RSW_PI) * (1.0 + mu * mu) ||
            v != 3.0 / (16.0 * RSW_PI) * (1.0 + phase_mu(&mi, want) * phase_mu(&mi, want));
  }
  CHECK(diff == 0, "rho = 0: %d of 1001 samples differ from the unpolarized formulas", diff);
  const double rhos[2] = {0.03, 0.3};
  const char *ids[2] = {"a", "b"};
  for (int r = 0; r < 2; r++) {
    const phase *ph = (const phase *)find_obj(s, ids[r]);
    REQUIRE(ph, "phase %s", ids[r]);
    double rho = rhos[r], A = 1.0 + rho, B = 1.0 - rho;
    char what[64];
    snprintf(what, sizeof what, "rayleigh depolarization %g", rho);
    for (int k = 0; k < 2; k++) run_chi2(ph, wis[k], what, 4);
    CHECK_REL(phase_integral(ph, wis[1], 2), 1.0, 1e-14);
    medium_interaction m0 = mi_at(v3(0, 0, 1));
    double pdf;
    CHECK_REL(ph->ops->eval_pdf(ph, &m0, v3(0, 0, -1), &pdf), 3.0 / (8.0 * RSW_PI * (2 + rho)) * 2.0, 1e-15);
    CHECK_REL(ph->ops->eval_pdf(ph, &m0, v3(1, 0, 0), &pdf), 3.0 / (8.0 * RSW_PI * (2 + rho)) * A, 1e-15);
    /* F(mu(u)) = u, F the cdf of mu. */
    for (int i = 0; i <= 100; i++) {
      double u = i / 100.0, w;
      vec3 wo;
      ph->ops->sample(ph, &m0, 0.5, v2(u, 0.3), &wo, &w);
      double mu = -wo.z;
      double F = (A * (mu + 1.0) + B * (mu * mu * mu + 1.0) / 3.0) / (2.0 * A + 2.0 * B / 3.0);
      CHECK_ABS(F, u, 1e-14);
    }
    /* The polarization factors: Hansen & Travis's F / F11. */
    mueller P[3];
    vec3 wo = v3_norm(v3(0.3, 0.4, 0.5));
    double mu = phase_mu(&m0, wo), D = (1 - rho) / (1 + rho / 2);
    ph->ops->polarization(ph, &m0, wo, P);
    double f11 = 0.75 * D * (1 + mu * mu) + 1 - D;
    CHECK_REL(P[0].m[0][1], 0.75 * D * (1 - mu * mu) / f11, 1e-14);
    CHECK_REL(P[0].m[3][3], 1.5 * D * (1 - 2 * rho) / (1 - rho) * mu / f11, 1e-14);
    /* 4 pi p(mu) is that F11. */
    CHECK_REL(4.0 * RSW_PI * ph->ops->eval_pdf(ph, &m0, wo, &pdf), f11, 1e-14);
  }
  /* The parameter: spectral, in [0, 1); derived constants follow it. */
  rsw_err err = {0};
  size_t i;
  CHECK(params_lookup(s, "r0.depolarization", &i, &err) == RSW_OK, "r0.depolarization exists");
  param_info info;
  REQUIRE(params_info(s, i, &info), "info");
  CHECK(info.cls == UPDATE_SPECTRAL, "depolarization is spectral");
  CHECK(upd1(s, "r0.depolarization", "0.3", &err) == RSW_OK, "update: %s", err.msg);
  const phase *b = (const phase *)find_obj(s, "b");
  for (int k = 0; k < 10; k++) {
    double u = (k + 0.5) / 10.0, p0, p1;
    vec3 w0, w1;
    double v0 = r0->ops->sample(r0, &mi, 0.5, v2(u, 0.2), &w0, &p0);
    double v1 = b->ops->sample(b, &mi, 0.5, v2(u, 0.2), &w1, &p1);
    CHECK(v0 == v1 && p0 == p1 && memcmp(&w0, &w1, sizeof w0) == 0, "updated to 0.3 == loaded with 0.3");
  }
  const char *bad[] = {"1", "-0.01", "1.5"};
  for (int k = 0; k < 3; k++) {
    memset(&err, 0, sizeof err);
    CHECK(upd1(s, "r0.depolarization", bad[k], &err) == RSW_ERR_RANGE, "%s rejected", bad[k]);
    CHECK(strstr(err.msg, "r0.depolarization") != NULL, "error names the key: %s", err.msg);
  }
  scene_free(s);
}

static void test_tabphase(void) {
  const char *tables[5][2] = {
      {"[1, 1]", "tabphase constant"},
      {"\"0, 1\"", "tabphase linear 0..1"},
      {"\"0.02 0.03 0.05 0.08 0.12 0.2 0.35 0.6 1.1 2.5 6.0\"", "tabphase forward peak"},
      {"[0, 1, 0, 2, 0.5, 0]", "tabphase with zeros"},
      {"[3, 0.5, 0.2, 0.1]", "tabphase backward"},
  };
  for (int c = 0; c < 5; c++) {
    char objs[512];
    snprintf(objs, sizeof objs, "\"t\": {\"type\": \"tabphase\", \"values\": %s}", tables[c][0]);
    scene *s = load_phases(objs);
    REQUIRE(s, "load %s", tables[c][1]);
    const phase *ph = (const phase *)find_obj(s, "t");
    for (int k = 0; k < 2; k++) run_chi2(ph, wis[k], tables[c][1], 8);
    CHECK_REL(phase_integral(ph, wis[1], 30000), 1.0, 1e-6);
    scene_free(s);
  }
  /* [1, 1] is isotropic; a string and a list are the same table. */
  scene *s = load_phases("\"t\": {\"type\": \"tabphase\", \"values\": \"1,1\"}, \"a\": {\"type\": "
                         "\"tabphase\", \"values\": \"1, 2,3\"}, \"b\": {\"type\": \"tabphase\", "
                         "\"values\": [1, 2, 3]}");
  REQUIRE(s, "load");
  const phase *t = (const phase *)find_obj(s, "t"), *a = (const phase *)find_obj(s, "a"),
              *b = (const phase *)find_obj(s, "b");
  medium_interaction mi = mi_at(wis[1]);
  double pa, pb;
  CHECK_REL(t->ops->eval_pdf(t, &mi, v3(0.6, 0.8, 0), &pa), RSW_INV_4PI, 1e-15);
  for (int k = 0; k < 10; k++) {
    vec3 wo = v3_norm(v3(sin(k), cos(3 * k), 0.3 * k - 1));
    CHECK(a->ops->eval_pdf(a, &mi, wo, &pa) == b->ops->eval_pdf(b, &mi, wo, &pb), "string == list");
  }
  /* Forward (mu = 1) holds the last value: 3 / (2 pi I), I = 4. */
  CHECK_REL(a->ops->eval_pdf(a, &mi, v3_neg(mi.wi), &pa), 3.0 / (2 * RSW_PI * 4.0), 1e-14);
  CHECK_REL(a->ops->eval_pdf(a, &mi, mi.wi, &pa), 1.0 / (2 * RSW_PI * 4.0), 1e-14);
  /* Updates: same length, non-negative, finite, not all zero. */
  rsw_err err = {0};
  CHECK(upd1(s, "a.values", "[3, 2, 1]", &err) == RSW_OK, "update: %s", err.msg);
  CHECK_REL(a->ops->eval_pdf(a, &mi, v3_neg(mi.wi), &pa), 1.0 / (2 * RSW_PI * 4.0), 1e-14);
  run_chi2(a, wis[0], "tabphase after an update", 8);
  const char *bad[][2] = {{"[1, 2]", "takes 3 numbers"},
                          {"[1, -2, 1]", "must be >= 0"},
                          {"[0, 0, 0]", "must not all be zero"},
                          {"0.5", "takes 3 numbers"}};
  for (int k = 0; k < 4; k++) {
    memset(&err, 0, sizeof err);
    CHECK(upd1(s, "a.values", bad[k][0], &err) != RSW_OK, "%s rejected", bad[k][0]);
    CHECK(strstr(err.msg, bad[k][1]) && strstr(err.msg, "a.values"), "%s: %s", bad[k][0], err.msg);
  }
  CHECK_REL(a->ops->eval_pdf(a, &mi, v3_neg(mi.wi), &pa), 1.0 / (2 * RSW_PI * 4.0), 1e-14);
  scene_free(s);
}

/* tabphase_polarized: sampling (regular and irregular nodes), its
 * intensity equal to tabphase's on the same regular table, the phase
 * matrix's factors (the signs of m12 and m34 in the kernel's bases; the
 * Rayleigh matrix: test_phase_polarized.c), the parameters. */
static void test_tabphase_polarized(void) {
  scene *s = load_phases(
      "\"t\": {\"type\": \"tabphase\", \"values\": \"0.02 0.03 0.05 0.08 0.12 0.2 0.35 0.6 1.1 2.5 6.0\"},"
      " \"p\": {\"type\": \"tabphase_polarized\", \"m11\": \"0.02 0.03 0.05 0.08 0.12 0.2 0.35 0.6 1.1 2.5 "
      "6.0\", \"m12\": -0.01, \"m34\": \"0 0 0 0 0 0.1 0 0 0 0 0\"},"
      " \"q\": {\"type\": \"tabphase_polarized\", \"nodes\": [-1, -0.2, 0, 0.3, 0.9, 0.99, 1],"
      " \"m11\": [1, 0.5, 0.4, 0.8, 3, 20, 40], \"m33\": [1, 0.5, 0.4, 0.8, 3, 20, 40]},"
      " \"z\": {\"type\": \"tabphase_polarized\", \"nodes\": \"-1, 0.5, 0.6, 1\", \"m11\": \"1, 0, 0, 2\"}");
  REQUIRE(s, "load");
  const phase *t = (const phase *)find_obj(s, "t"), *p = (const phase *)find_obj(s, "p"),
              *q = (const phase *)find_obj(s, "q"), *z = (const phase *)find_obj(s, "z");
  REQUIRE(t && p && q && z, "the four phases");
  medium_interaction mi = mi_at(wis[1]);
  int diff = 0;
  for (int i = 0; i <= 200; i++) {
    double pt, pp, vt, vp;
    vec3 wt, wp;
    vt = t->ops->sample(t, &mi, 0.5, v2(i / 200.0, 0.1), &wt, &pt);
    vp = p->ops->sample(p, &mi, 0.5, v2(i / 200.0, 0.1), &wp, &pp);
    diff += vt != vp || pt != pp || memcmp(&wt, &wp, sizeof wt) != 0;
  }
  CHECK(diff == 0, "regular tabphase_polarized == tabphase (%d of 201 samples differ)", diff);
  run_chi2(q, wis[0], "tabphase_polarized irregular", 16);
  run_chi2(q, wis[1], "tabphase_polarized irregular", 16);
  run_chi2(z, wis[0], "tabphase_polarized irregular, empty intervals", 8);
  run_chi2(z, wis[1], "tabphase_polarized irregular, empty intervals", 8);
  CHECK_REL(phase_integral(q, wis[1], 40000), 1.0, 1e-6);
  /* int m11 = (1 + 0.5) 0.8 / 2 + ... ; at mu = 0.3 the node value 0.8. */
  double tot = 0.5 * (1.5 * 0.8 + 0.9 * 0.2 + 1.2 * 0.3 + 3.8 * 0.6 + 23 * 0.09 + 60 * 0.01), pdf;
  vec3 w03 = phase_direction(&mi, 0.3, 0.25);
  CHECK_REL(q->ops->eval_pdf(q, &mi, w03, &pdf), 0.8 / (2 * RSW_PI * tot), 1e-12);
  /* Factors: m12 and m34 change sign in the kernel's bases; absent
   * elements are 0; one number stands for every node. */
  mueller P[3];
  vec3 w = phase_direction(&mi, 0.0, 0.6); /* mu = 0: node 5 */
  p->ops->polarization(p, &mi, w, P);
  CHECK_REL(P[0].m[0][1], 0.01 / 0.2, 1e-12);
  CHECK_REL(P[0].m[1][0], 0.01 / 0.2, 1e-12);
  CHECK_REL(P[0].m[2][3], -0.1 / 0.2, 1e-12);
  CHECK_REL(P[0].m[3][2], 0.1 / 0.2, 1e-12);
  CHECK(P[0].m[0][0] == 1.0 && P[0].m[1][1] == 0.0 && P[0].m[2][2] == 0.0 && P[0].m[3][3] == 0.0,
        "absent elements are 0");
  q->ops->polarization(q, &mi, w03, P);
  CHECK_REL(P[0].m[2][2], 1.0, 1e-14);
  CHECK(P[0].m[0][1] == 0.0 && P[0].m[1][1] == 0.0, "q: only m11 and m33");
  /* Updates: m11 (>= 0, not all zero), m34 (any sign), nodes (-1 .. 1,
   * increasing); a phase without nodes has no `nodes` key. */
  rsw_err err = {0};
  size_t idx;
  CHECK(params_lookup(s, "p.nodes", &idx, &err) != RSW_OK, "p has no nodes key");
  CHECK(upd1(s, "q.nodes", "[-1, -0.5, 0, 0.3, 0.9, 0.99, 1]", &err) == RSW_OK, "nodes update: %s", err.msg);
  CHECK(upd1(s, "p.m34", "[0, 0, 0, 0, 0, -0.1, 0, 0, 0, 0, 0]", &err) == RSW_OK, "m34 update: %s", err.msg);
  p->ops->polarization(p, &mi, w, P);
  CHECK_REL(P[0].m[2][3], 0.1 / 0.2, 1e-12);
  CHECK(upd1(s, "q.m11", "[1, 1, 1, 1, 1, 1, 1]", &err) == RSW_OK, "m11 update: %s", err.msg);
  CHECK_REL(q->ops->eval_pdf(q, &mi, w03, &pdf), RSW_INV_4PI, 1e-14);
  run_chi2(q, wis[1], "tabphase_polarized after updates", 4);
  const char *bad[][3] = {{"q.nodes", "[-1, -0.5, 0.3, 0, 0.9, 0.99, 1]", "strictly increasing"},
                          {"q.nodes", "[-0.9, -0.5, 0, 0.3, 0.9, 0.99, 1]", "must start at -1"},
                          {"q.nodes", "[-1, -0.5, 0, 0.3, 0.9, 0.99, 0.999]", "must end at 1"},
                          {"q.m11", "[0, 0, 0, 0, 0, 0, 0]", "must not all be zero"},
                          {"q.m11", "[1, 1, -1, 1, 1, 1, 1]", ">= 0"},
                          {"q.m12", "[1, 1]", "takes 7 numbers"}};
  for (int k = 0; k < 6; k++) {
    memset(&err, 0, sizeof err);
    CHECK(upd1(s, bad[k][0], bad[k][1], &err) != RSW_OK, "%s = %s rejected", bad[k][0], bad[k][1]);
    CHECK(strstr(err.msg, bad[k][2]) && strstr(err.msg, bad[k][0]), "%s: %s", bad[k][1], err.msg);
  }
  CHECK_REL(q->ops->eval_pdf(q, &mi, w03, &pdf), RSW_INV_4PI, 1e-14);
  scene_free(s);
}

/* blendphase in the polarized variants: P = sum w_i p_i P_i / sum w_i p_i,
 * a component without a phase matrix counting as a depolarizer; nested
 * blends; a blend of depolarizers is one. */
static void test_blendphase_polarization(void) {
  scene *s = load_phases(
      "\"b\": {\"type\": \"blendphase\", \"weight\": 0.35, \"phase_0\": {\"type\": \"rayleigh\", "
      "\"depolarization\": 0.1}, \"phase_1\": {\"type\": \"hg\", \"g\": 0.7}},"
      " \"n\": {\"type\": \"blendphase\", \"weight\": 0.6, \"phase_0\": {\"type\": \"isotropic\"},"
      " \"phase_1\": {\"type\": \"blendphase\", \"weight\": 0.25, \"phase_0\": {\"type\": \"rayleigh\"},"
      " \"phase_1\": {\"type\": \"tabphase_polarized\", \"m11\": [1, 2], \"m12\": [0.5, -0.5], \"m34\": "
      "0.3}}},"
      " \"d\": {\"type\": \"blendphase\", \"phase_0\": {\"type\": \"isotropic\"}, \"phase_1\": {\"type\": "
      "\"hg\", \"g\": 0.2}}");
  REQUIRE(s, "load");
  const phase *b = (const phase *)find_obj(s, "b"), *nb = (const phase *)find_obj(s, "n"),
              *d = (const phase *)find_obj(s, "d");
  REQUIRE(b && nb && d, "the blends");
  medium_interaction mi = mi_at(wis[1]);
  for (int k = 0; k < 5; k++) {
    double mu = -0.9 + 0.45 * k, pdf;
    vec3 wo = phase_direction(&mi, mu, 0.3 + 0.1 * k);
    mu = phase_mu(&mi, wo);
    mueller P[3];
    /* b: (0.65 p_r F_r / F11_r + 0.35 p_hg diag(1, 0, 0, 0)) / p. */
    double D = 0.9 / 1.05, f11 = 0.75 * D * (1 + mu * mu) + 1 - D, pr = f11 / (4 * RSW_PI);
    double phg = (1 - 0.49) / (4 * RSW_PI * pow(1 + 0.49 - 1.4 * mu, 1.5)), p = 0.65 * pr + 0.35 * phg;
    b->ops->polarization(b, &mi, wo, P);
    CHECK_REL(b->ops->eval_pdf(b, &mi, wo, &pdf), p, 1e-13);
    CHECK(P[0].m[0][0] == 1.0, "normalised");
    CHECK_REL(P[0].m[0][1], 0.65 * pr * 0.75 * D * (1 - mu * mu) / f11 / p, 1e-12);
    CHECK_REL(P[0].m[2][2], 0.65 * pr * 1.5 * D * mu / f11 / p, 1e-12);
    CHECK(memcmp(&P[0], &P[2], sizeof P[0]) == 0, "every channel");
    /* n: 0.4 iso + 0.6 (0.75 rayleigh + 0.25 table); table m11 = 1.5 + mu / 2
     * over I = 3, m12 (kernel) = -(-0.5 mu), m34 (kernel) = -0.3. */
    double ray = 3 / (16 * RSW_PI) * (1 + mu * mu), m11 = 1.5 + 0.5 * mu, tab = m11 / (2 * RSW_PI * 3);
    double a_iso = 0.4 * RSW_INV_4PI, a_r = 0.6 * 0.75 * ray, a_t = 0.6 * 0.25 * tab, sum = a_iso + a_r + a_t;
    nb->ops->polarization(nb, &mi, wo, P);
    CHECK_REL(nb->ops->eval_pdf(nb, &mi, wo, &pdf), sum, 1e-13);
    CHECK_REL(P[0].m[0][1], (a_r * (1 - mu * mu) / (1 + mu * mu) + a_t * 0.5 * mu / m11) / sum, 1e-11);
    CHECK_REL(P[0].m[2][3], a_t * -0.3 / m11 / sum, 1e-11);
    CHECK_REL(P[0].m[3][2], a_t * 0.3 / m11 / sum, 1e-11);
    CHECK_REL(P[0].m[3][3], a_r * 2 * mu / (1 + mu * mu) / sum, 1e-11);
    d->ops->polarization(d, &mi, wo, P);
    mueller dep = mu_depolarizer();
    CHECK(memcmp(&P[0], &dep, sizeof dep) == 0, "a blend of depolarizers depolarizes");
  }
  scene_free(s);
}

static void test_parameters(void) {
  scene *s = load_phases("\"b\": {\"type\": \"blendphase\", \"weight\": 0.3, \"phase_0\": {\"type\": "
                         "\"isotropic\"}, \"phase_1\": {\"type\": \"hg\", \"g\": 0.8}}");
  REQUIRE(s, "load");
  rsw_err err = {0};
  size_t i;
  CHECK(params_lookup(s, "b.phase_1.g", &i, &err) == RSW_OK, "b.phase_1.g exists");
  CHECK(params_lookup(s, "b.weight.value.value", &i, &err) == RSW_OK, "b.weight.value.value exists");
  param_info info;
  REQUIRE(params_info(s, i, &info), "info");
  CHECK(info.cls == UPDATE_SPECTRAL, "weight is spectral");
  CHECK(upd1(s, "b.phase_1.g", "0.5", &err) == RSW_OK, "g 0.5: %s", err.msg);
  memset(&err, 0, sizeof err);
  CHECK(upd1(s, "b.phase_1.g", "1", &err) == RSW_ERR_RANGE, "g = 1 rejected");
  CHECK(strstr(err.msg, "b.phase_1.g") != NULL, "error names the key: %s", err.msg);
  /* The open interval's bound is not printed as the excluded 1. */
  CHECK(strstr(err.msg, "0.99999999999999989") != NULL && strstr(err.msg, "[-1, 1]") == NULL,
        "the range says g < 1: %s", err.msg);
  CHECK(upd1(s, "b.phase_1.g", "-1.5", &err) == RSW_ERR_RANGE, "g = -1.5 rejected");
  memset(&err, 0, sizeof err);
  CHECK(upd1(s, "b.weight.value.value", "1.2", &err) == RSW_ERR_RANGE, "weight 1.2 rejected");
  CHECK(strstr(err.msg, "b.weight.value.value") != NULL, "error names the key: %s", err.msg);
  CHECK(upd1(s, "b.weight.value.value", "-0.1", &err) == RSW_ERR_RANGE, "weight -0.1 rejected");
  medium_interaction mi = mi_at(v3(0, 0, 1));
  const phase *ph = (const phase *)find_obj(s, "b");
  double pdf, v = ph->ops->eval_pdf(ph, &mi, v3(0, 0, -1), &pdf);
  CHECK_REL(v, 0.7 * RSW_INV_4PI + 0.3 * (1 - 0.25) / (4 * RSW_PI * pow(0.5, 3)), 1e-14);
  scene_free(s);
}

static void test_load_errors(void) {
  static const struct {
    const char *objs, *want;
  } bad[] = {
      {"\"p\": {\"type\": \"hg\", \"g\": 1}", "open interval"},
      {"\"p\": {\"type\": \"hg\", \"g\": -1.2}", "open interval"},
      {"\"p\": {\"type\": \"hg\", \"g\": \"x\"}", "must be a number"},
      {"\"p\": {\"type\": \"hg\", \"k\": 0.1}", "no property 'k'"},
      {"\"p\": {\"type\": \"isotropic\", \"g\": 0.1}", "no property 'g'"},
      {"\"p\": {\"type\": \"blendphase\", \"phase_0\": {\"type\": \"isotropic\"}}", "exactly two"},
      {"\"p\": {\"type\": \"blendphase\", \"weight\": 1.5, \"phase_0\": {\"type\": \"isotropic\"}, "
       "\"phase_1\": {\"type\": \"isotropic\"}}",
       "'weight' must be in [0, 1]"},
      {"\"p\": {\"type\": \"blendphase\", \"weight\": -0.5, \"phase_0\": {\"type\": \"isotropic\"}, "
       "\"phase_1\": {\"type\": \"isotropic\"}}",
       "'weight' must be >= 0"},
      {"\"p\": {\"type\": \"blendphase\", \"weight\": {\"type\": \"hg\"}, \"phase_0\": {\"type\": "
       "\"isotropic\"}, \"phase_1\": {\"type\": \"isotropic\"}}",
       "exactly two"},
      {"\"p\": {\"type\": \"mie\"}", "mie"},
      {"\"p\": {\"type\": \"rayleigh\", \"g\": 0}", "no property 'g'"},
      {"\"p\": {\"type\": \"rayleigh\", \"depolarization\": 1}", "'depolarization' must lie in [0, 1)"},
      {"\"p\": {\"type\": \"rayleigh_polarized\", \"depolarization\": -0.1}", "must lie in [0, 1)"},
      {"\"p\": {\"type\": \"tabphase\"}", "missing property 'values'"},
      {"\"p\": {\"type\": \"tabphase\", \"values\": \"1\"}", "at least 2"},
      {"\"p\": {\"type\": \"tabphase\", \"values\": \"1, x, 2\"}", "'x' (value 1) is not a number"},
      {"\"p\": {\"type\": \"tabphase\", \"values\": \"1, -1, 2\"}", "value 1 (-1) must be >= 0"},
      {"\"p\": {\"type\": \"tabphase\", \"values\": [0, 0]}", "all zeros"},
      {"\"p\": {\"type\": \"tabphase\", \"values\": true}", "list of numbers"},
      {"\"p\": {\"type\": \"tabphase_polarized\", \"nodes\": [-1, 1]}", "missing property 'm11'"},
      {"\"p\": {\"type\": \"tabphase_polarized\", \"m11\": [1, 2, 3], \"nodes\": [-1, 1]}", "must match"},
      {"\"p\": {\"type\": \"tabphase_polarized\", \"m11\": [1, 2, 3], \"nodes\": [-1, 0.5, 0.2]}",
       "'nodes' must end at 1"},
      {"\"p\": {\"type\": \"tabphase_polarized\", \"m11\": [1, 2, 3], \"nodes\": [-1, 1, 1]}",
       "strictly increasing"},
      {"\"p\": {\"type\": \"tabphase_polarized\", \"m11\": [1, 2, 3], \"m12\": [1, 2]}",
       "'m12' has 2 values, 'm11' 3"},
      {"\"p\": {\"type\": \"tabphase_polarized\", \"m11\": [1, -2, 3]}", "must be >= 0"},
      {"\"p\": {\"type\": \"tabphase_polarized\", \"m11\": [1, 2], \"m44\": \"1, x\"}", "not a number"},
  };
  for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
    rsw_err err = {0};
    rsw_status st = load_err(bad[k].objs, &err);
    CHECK(st != RSW_OK, "case %zu loads: %s", k, bad[k].objs);
    CHECK(strstr(err.msg, bad[k].want) != NULL, "case %zu: '%s' not in '%s'", k, bad[k].want, err.msg);
    CHECK(strstr(err.where, "/p") != NULL, "case %zu: location '%s' names /p", k, err.where);
  }
}

/* The batches (phase_ops.sample_batch, eval_pdf_batch through
 * phase_sample_batch and phase_eval_pdf_batch): each lane the scalar
 * call's bits (directions, pdfs, values, weights), for rayleigh (rho 0 and
 * 0.2), hg (forward, backward, |g| < 1e-5), isotropic (these three have no
 * batch op: the calls a lane at a time) and blends of them (a weight grid with 0 and 1
 * in it, a nested blend, half the points bound), batches of 1 to 200
 * lanes; and the chi-square of the batched sampling of rayleigh, hg and
 * the atmosphere's blend. */
static void test_phase_batches(void) {
  scene *s = load_phases(
      "\"r0\": {\"type\": \"rayleigh\"}, \"r2\": {\"type\": \"rayleigh\", \"depolarization\": 0.2},"
      " \"h7\": {\"type\": \"hg\", \"g\": 0.7}, \"hm\": {\"type\": \"hg\", \"g\": -0.4},"
      " \"h0\": {\"type\": \"hg\", \"g\": 1e-6}, \"iso\": {\"type\": \"isotropic\"},"
      " \"atm\": {\"type\": \"blendphase\", \"weight\": {\"type\": \"gridvolume\", \"shape\": [7, 1, 1],"
      "  \"data\": [0, 0.1, 0.9, 0.4, 1, 0.25, 0.6]},"
      "  \"phase_0\": {\"type\": \"rayleigh\"}, \"phase_1\": {\"type\": \"hg\", \"g\": 0.7}},"
      " \"nest\": {\"type\": \"blendphase\", \"weight\": 0.45, \"phase_0\": {\"type\": \"isotropic\"},"
      "  \"phase_1\": {\"type\": \"blendphase\", \"weight\": 0.3, \"phase_0\": {\"type\": \"hg\", \"g\": "
      "-0.6},"
      "  \"phase_1\": {\"type\": \"rayleigh\"}}}");
  REQUIRE(s, "load");
  const char *ids[] = {"r0", "r2", "h7", "hm", "h0", "iso", "atm", "nest"};
  enum {
    N = 200
  };
  static medium_interaction mi[N];
  static vec3 wo[N], so[N];
  static double u1[N], v[N], pdf[N], sw[N], spdf[N];
  static vec2 u2[N];
  pcg32 rng;
  pcg32_seed(&rng, 19, 4);
  for (size_t p = 0; p < sizeof ids / sizeof ids[0]; p++) {
    const phase *ph = (const phase *)find_obj(s, ids[p]);
    REQUIRE(ph, "%s", ids[p]);
    long lanes = 0, failed = 0;
    int differ = 0;
    for (int n = 1; n <= N; n += n < 20 ? 1 : 60) {
      for (int i = 0; i < n; i++) {
        mi[i] = mi_at(
            v3(pcg32_next_double(&rng) - 0.5, pcg32_next_double(&rng) - 0.5, pcg32_next_double(&rng) - 0.5));
        mi[i].p = v3(pcg32_next_double(&rng), pcg32_next_double(&rng), 1.2 * pcg32_next_double(&rng) - 0.1);
        if (i % 2) phase_bind(ph, &mi[i]);
        wo[i] = v3_norm(
            v3(pcg32_next_double(&rng) - 0.5, pcg32_next_double(&rng) - 0.5, pcg32_next_double(&rng) - 0.5));
        u1[i] = i % 13 == 0 ? 1.0 : pcg32_next_double(&rng);
        u2[i] = v2(i % 17 == 0 ? 0.0 : pcg32_next_double(&rng), pcg32_next_double(&rng));
      }
      phase_eval_pdf_batch(ph, n, mi, wo, v, pdf);
      phase_sample_batch(ph, n, mi, u1, u2, so, spdf, sw);
      for (int i = 0; i < n; i++) {
        double ev, epdf, sp, w;
        vec3 d;
        ev = ph->ops->eval_pdf(ph, &mi[i], wo[i], &epdf);
        w = ph->ops->sample(ph, &mi[i], u1[i], u2[i], &d, &sp);
        bool bad = memcmp(&ev, &v[i], sizeof ev) || memcmp(&epdf, &pdf[i], sizeof epdf) ||
                   memcmp(&w, &sw[i], sizeof w) || memcmp(&sp, &spdf[i], sizeof sp) ||
                   memcmp(&d, &so[i], sizeof d);
        differ += bad;
        failed += !(sp > 0);
        lanes++;
      }
    }
    printf("  %s: %ld lanes (%ld failed samples), %d differ\n", ids[p], lanes, failed, differ);
    CHECK(differ == 0, "%s: %d of %ld lanes differ from the scalar calls", ids[p], differ, lanes);
  }
  run_chi2_as((const phase *)find_obj(s, "r0"), wis[1], "rayleigh, batched", 4, true);
  run_chi2_as((const phase *)find_obj(s, "h7"), wis[1], "hg 0.7, batched", 16, true);
  scene *a = load_phases("\"b\": {\"type\": \"blendphase\", \"weight\": 0.35, \"phase_0\": {\"type\": "
                         "\"rayleigh\"}, \"phase_1\": {\"type\": \"hg\", \"g\": 0.7}}");
  REQUIRE(a, "load the blend");
  run_chi2_as((const phase *)find_obj(a, "b"), wis[1], "blend(rayleigh, hg 0.7; 0.35), batched", 16, true);
  scene_free(a);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_isotropic);
  RSW_TEST_RUN(test_hg);
  RSW_TEST_RUN(test_hg_convention);
  RSW_TEST_RUN(test_hg_zero_is_isotropic);
  RSW_TEST_RUN(test_blendphase);
  RSW_TEST_RUN(test_phase_bind);
  RSW_TEST_RUN(test_rayleigh);
  RSW_TEST_RUN(test_rayleigh_depolarization);
  RSW_TEST_RUN(test_tabphase);
  RSW_TEST_RUN(test_tabphase_polarized);
  RSW_TEST_RUN(test_blendphase_polarization);
  RSW_TEST_RUN(test_parameters);
  RSW_TEST_RUN(test_load_errors);
  RSW_TEST_RUN(test_phase_batches);
  RSW_TEST_END("test_phase");
}
