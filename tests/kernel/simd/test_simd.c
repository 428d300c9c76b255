/* The batched (SIMD) kernels at every ISA this CPU runs (core/isa.h):
 *  - chi-square tests of roughconductor's batched visible-normal sampling
 *    (bsdf_ops.sample_batch; Beckmann and GGX, isotropic alphas 0.3 and
 *    0.8 at incidence 0, 60 and 85 degrees, anisotropic (0.1, 0.5) at 60;
 *    ires 8 as test_bsdf.c, which resolves these lobes; the same case at
 *    alpha 0.1 and 85 degrees would need ires 32 for the scalar sampler too)
 *    against pdf() (Mitsuba's procedure, tests/support/chi2.h; 200,000
 *    samples, significance 0.01 with the Sidak correction over every run
 *    of this file, fixed seeds);
 *  - chi-square tests of diffuse's batched cosine-hemisphere sampling at
 *    incidence 0, 60 and 85 degrees (same settings), and its samples equal
 *    diffuse's sample() bit for bit (double lanes, the same operations);
 *  - the cosine-hemisphere and conductor-Fresnel double lanes equal the
 *    scalar warp_square_to_cosine_hemisphere() and fresnel_conductor() bit
 *    for bit (which makes diffuse's and conductor's scalar sample a batch
 *    of one);
 *  - lane independence: a lane's sample does not depend on the batch it is
 *    in (a batch of 1000 equals 1000 batches of one, bitwise), which is
 *    what keeps 1 and N threads bitwise identical at a given ISA;
 *  - weight = eval / pdf for the batched samples (1e-4 relative: pdf and
 *    weight are single precision, bsdfs/microfacet_lanes.h);
 *  - roughconductor's batched eval/pdf (single precision up to Fresnel)
 *    equals eval() and pdf() within 1e-4 relative (+1e-12 absolute) over
 *    random directions, both distributions, visible or not, isotropic
 *    and anisotropic, and is lane-independent (bitwise);
 *  - hdistant's batched camera rays (double lanes) equal sample_ray()'s
 *    bit for bit, at every ISA (the seed scene's sensor; the periodic
 *    canopy's, a target and the slab; a tilted rectangle target, as the
 *    atmosphere's; and one with a rotated, scaled to_world), including
 *    the concentric map's centre and edges;
 *  - --isa parsing: auto, names, an unknown name, an ISA the CPU lacks;
 *  - the batched ops of the other hot plugins (issue 12 point 3), at every
 *    ISA, generic included (simd/lanes_generic.c):
 *    chi-square tests of the batched sampling of rpv (0 and 70 degrees),
 *    bilambertian (front 30, back 60 degrees, and R = 0.1, T = 0.6 at 45
 *    degrees) and twosided (a diffuse front and a GGX back, each side)
 *    against pdf() (same settings as above);
 *    batch vs scalar over 3001 random lanes (wi and wo uniform on the
 *    sphere, so every failure path too): sample_batch equals sample() and
 *    eval_pdf_batch equals eval()/pdf() (where a plugin has them; else
 *    the fallback, kernel.h bsdf_sample_n) bit for bit for diffuse,
 *    conductor (mirror, and gold in rgb: three Fresnel channels in double
 *    lanes), dielectric (both sides), bilambertian and twosided of those;
 *    for rpv (grey and coloured) the directions and pdfs bit for bit and
 *    the values (float lanes) within 1e-5 relative (the worst seen over
 *    6e5 random pairs: 3e-6); for a twosided with a rough back, weight =
 *    eval/pdf within 1e-4; every op lane-independent
 *    (a batch of 3001 equals 3001 batches of one, bitwise);
 *    rpv's exact batches (sample_batch_exact, eval_pdf_batch_exact: the
 *    volumetric wave's) bit for bit sample(), eval() and pdf() at every
 *    ISA (grey, the atmosphere's ground, coloured, as Lambertian; the
 *    pole, the hot spot, grazing), lane-independent;
 *    the batched rays of distant, mdistant, distantflux, perspective (with
 *    a principal point offset) and radiancemeter equal sample_ray()'s bit
 *    for bit, with and without a target. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../support/bsdf_test.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"
#include "kernel/bsdfs/bsdfs_internal.h"
#include "kernel/bsdfs/fresnel.h"
#include "kernel/core/isa.h"
#include "kernel/core/rng.h"
#include "kernel/simd/simd.h"
#include "kernel/textures/texture.h"

RSW_TEST_DEFINE_GLOBALS

#define CHI2_SAMPLES 200000
/* chi2_run calls per ISA: roughconductor 2 types x 2 alphas x 3 angles + 2
 * anisotropic; diffuse 3 angles; rpv 2, bilambertian 3, twosided 4
 * (test_plugin_batch_chi2). */
#define CHI2_PER_ISA 26

static int n_isas(void) {
  int n = 0;
  for (int i = 0; i < RSW_ISA__COUNT; i++) n += rsw_isa_supported((rsw_isa)i);
  return n;
}

static bool batch_sample_1(void *user, const double *u, vec3 *out, double *weight) {
  chi2_bsdf *c = user;
  bsdf_sample bs;
  color w;
  const surface_interaction *si = &c->si;
  vec2 u2 = v2(u[1], u[2]);
  c->b->ops->sample_batch(c->b, 1, &si, &u[0], &u2, &bs, &w);
  if (!(bs.pdf > 0.0) || col_is_black(w)) {
    *weight = 0.0;
    return false;
  }
  *out = bs.wo;
  *weight = 1.0;
  return true;
}

static void run_chi2(const bsdf *b, vec3 wi, const char *what) {
  chi2_bsdf c = {b, tb_si_with(wi)};
  chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
  cfg.sample_count = CHI2_SAMPLES;
  cfg.test_count = CHI2_PER_ISA * n_isas();
  cfg.ires = 8;
  chi2_result r = chi2_run(&cfg, batch_sample_1, chi2_bsdf_pdf, &c);
  CHECK(r.passed, "chi2 %s at %s, wi = (%.4f, %.4f, %.4f): p = %g, chi2 = %g, dof = %d: %s", what,
        rsw_isa_name(rsw_isa_get()), wi.x, wi.y, wi.z, r.p_value, r.chi2, r.dof, r.reason);
}

static void test_roughconductor_batch_chi2(void) {
  const mf_type types[2] = {MF_BECKMANN, MF_GGX};
  const double alphas[2] = {0.3, 0.8};
  const double incidence[3] = {0.0, 60.0, 85.0};
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    for (int t = 0; t < 2; t++) {
      for (int a = 0; a < 2; a++) {
        rough_case r = rough_make(types[t], alphas[a], alphas[a], true, 0.0, 1.0);
        REQUIRE(r.b && r.b->ops->sample_batch, "allocation, batched op");
        char what[96];
        snprintf(what, sizeof what, "batched roughconductor %s alpha %g", mf_type_name(types[t]), alphas[a]);
        for (int i = 0; i < 3; i++) run_chi2(r.b, tb_dir_deg(incidence[i], 40.0), what);
        rough_free(&r);
      }
      rough_case r = rough_make(types[t], 0.1, 0.5, true, 0.0, 1.0);
      REQUIRE(r.b, "allocation");
      char what[96];
      snprintf(what, sizeof what, "batched roughconductor %s alpha (0.1, 0.5)", mf_type_name(types[t]));
      run_chi2(r.b, tb_dir_deg(60.0, 40.0), what);
      rough_free(&r);
    }
  }
  rsw_isa_set(rsw_isa_best());
}

/* The double lanes that make diffuse's and conductor's scalar sample a
 * batch of one give the scalar functions' bits at every ISA: the
 * cosine-hemisphere warp (simd/warp_lanes.h) against
 * warp_square_to_cosine_hemisphere(), the conductor Fresnel term
 * (bsdfs/fresnel_lanes.h) against fresnel_conductor(), over 4001 random
 * inputs and the edges (the concentric map's centre and corners; normal,
 * grazing and back incidence; k = 0 and eta = 0). */
static void test_lanes_vs_scalar(void) {
  enum {
    N = 4001
  };
  static double u[2 * N], dir[3 * N], ci[N], eta[N], kk[N], fr[N];
  pcg32 rng;
  pcg32_seed(&rng, 92, 93);
  for (int i = 0; i < N; i++) {
    u[2 * i] = pcg32_next_double(&rng), u[2 * i + 1] = pcg32_next_double(&rng);
    ci[i] = 2 * pcg32_next_double(&rng) - 1;
    eta[i] = 3 * pcg32_next_double(&rng), kk[i] = 5 * pcg32_next_double(&rng);
  }
  const double edge_u[][2] = {{0.5, 0.5}, {0.0, 0.0}, {1.0 - 0x1p-53, 0.0}, {0.0, 1.0 - 0x1p-53}, {0.5, 0.0}};
  for (int e = 0; e < 5; e++) u[2 * e] = edge_u[e][0], u[2 * e + 1] = edge_u[e][1];
  ci[0] = 1.0, ci[1] = 0.0, ci[2] = -1.0, kk[3] = 0.0, eta[4] = 0.0, eta[5] = 1.0, kk[5] = 0.0;
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_supported((rsw_isa)isa)) continue;
    cosine_hemisphere_batch((rsw_isa)isa, N, u, dir);
    fresnel_conductor_batch((rsw_isa)isa, N, ci, eta, kk, fr);
    int bad_w = 0, bad_f = 0;
    for (int i = 0; i < N; i++) {
      vec3 w = warp_square_to_cosine_hemisphere(v2(u[2 * i], u[2 * i + 1]));
      bad_w += memcmp(&w.x, &dir[3 * i], sizeof w.x) || memcmp(&w.y, &dir[3 * i + 1], sizeof w.y) ||
               memcmp(&w.z, &dir[3 * i + 2], sizeof w.z);
      double f = fresnel_conductor(ci[i], eta[i], kk[i]);
      bad_f += memcmp(&f, &fr[i], sizeof f) != 0;
    }
    CHECK(bad_w == 0, "%s: %d of %d cosine-hemisphere lanes differ from the scalar warp",
          rsw_isa_name((rsw_isa)isa), bad_w, N);
    CHECK(bad_f == 0, "%s: %d of %d conductor Fresnel lanes differ from fresnel_conductor()",
          rsw_isa_name((rsw_isa)isa), bad_f, N);
  }
}

static void test_diffuse_batch(void) {
  texture *rho = uniform_texture_const(0.7, "rho");
  bsdf *b = diffuse_new(rho);
  REQUIRE(b && b->ops->sample_batch, "allocation, batched op");
  const double incidence[3] = {0.0, 60.0, 85.0};
  enum {
    N = 3001
  };
  surface_interaction *si = malloc(N * sizeof *si);
  const surface_interaction **sp = malloc(N * sizeof *sp);
  double *u1 = malloc(N * sizeof *u1);
  vec2 *u2 = malloc(N * sizeof *u2);
  bsdf_sample *bs = malloc(N * sizeof *bs);
  color *w = malloc(N * sizeof *w);
  REQUIRE(si && sp && u1 && u2 && bs && w, "allocation");
  pcg32 rng;
  pcg32_seed(&rng, 90, 91);
  for (int i = 0; i < N; i++) {
    double z = 2 * pcg32_next_double(&rng) - 1, ph = 2 * RSW_PI * pcg32_next_double(&rng);
    double r = sqrt(fmax(0.0, 1 - z * z));
    si[i] = tb_si_with(v3(r * cos(ph), r * sin(ph), z)); /* some from below: failed samples */
    sp[i] = &si[i];
    u1[i] = pcg32_next_double(&rng);
    u2[i] = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
  }
  u2[0] = v2(0.5, 0.5); /* the concentric map's centre */
  u2[1] = v2(0.0, 1.0 - 0x1p-53);
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    for (int i = 0; i < 3; i++) run_chi2(b, tb_dir_deg(incidence[i], 20.0), "batched diffuse");
    b->ops->sample_batch(b, N, sp, u1, u2, bs, w);
    int differ = 0;
    for (int i = 0; i < N; i++) {
      bsdf_sample q;
      color wq = b->ops->sample(b, &si[i], u1[i], u2[i], &q);
      if (memcmp(&q.wo, &bs[i].wo, sizeof q.wo) || q.pdf != bs[i].pdf || memcmp(&wq, &w[i], sizeof wq) ||
          (q.pdf > 0 && (q.eta != bs[i].eta || q.sampled_type != bs[i].sampled_type)))
        differ++;
    }
    CHECK(differ == 0, "%s: %d of %d batched diffuse samples differ from sample()'s",
          rsw_isa_name((rsw_isa)isa), differ, N);
  }
  rsw_isa_set(rsw_isa_best());
  free(si);
  free(sp);
  free(u1);
  free(u2);
  free(bs);
  free(w);
  tb_free_bsdf(b);
  tb_free_tex(rho);
}

/* Random incidences and numbers; one batch of N against N batches of 1. */
static void test_lane_independence_and_weights(void) {
  enum {
    N = 1000
  };
  const mf_type types[2] = {MF_BECKMANN, MF_GGX};
  surface_interaction *si = malloc(N * sizeof *si);
  const surface_interaction **sp = malloc(N * sizeof *sp);
  double *u1 = malloc(N * sizeof *u1);
  vec2 *u2 = malloc(N * sizeof *u2);
  bsdf_sample *bs = malloc(N * sizeof *bs), *bs1 = malloc(N * sizeof *bs1);
  color *w = malloc(N * sizeof *w), *w1 = malloc(N * sizeof *w1);
  REQUIRE(si && sp && u1 && u2 && bs && bs1 && w && w1, "allocation");
  pcg32 rng;
  pcg32_seed(&rng, 12, 34);
  for (int i = 0; i < N; i++) {
    double ct = pcg32_next_double(&rng), ph = 2 * RSW_PI * pcg32_next_double(&rng);
    double st = sqrt(fmax(0.0, 1 - ct * ct));
    si[i] = tb_si_with(v3(st * cos(ph), st * sin(ph), ct));
    sp[i] = &si[i];
    u1[i] = pcg32_next_double(&rng);
    u2[i] = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
  }
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    for (int t = 0; t < 2; t++) {
      rough_case r = rough_make(types[t], 0.3, 0.15, true, 0.0, 1.0);
      REQUIRE(r.b, "allocation");
      r.b->ops->sample_batch(r.b, N, sp, u1, u2, bs, w);
      int differ = 0, bad_weight = 0, ok = 0;
      for (int i = 0; i < N; i++) {
        r.b->ops->sample_batch(r.b, 1, &sp[i], &u1[i], &u2[i], &bs1[i], &w1[i]);
        if (memcmp(&bs[i], &bs1[i], sizeof bs[i]) != 0 || memcmp(&w[i], &w1[i], sizeof w[i]) != 0) differ++;
        if (!(bs[i].pdf > 0)) continue;
        ok++;
        double ref = r.b->ops->eval(r.b, &si[i], bs[i].wo).c[0] / r.b->ops->pdf(r.b, &si[i], bs[i].wo);
        if (!(fabs(w[i].c[0] - ref) <= 1e-4 * fabs(ref))) bad_weight++;
      }
      CHECK(differ == 0, "%s %s: %d of %d lanes differ between a batch of %d and batches of 1",
            rsw_isa_name((rsw_isa)isa), mf_type_name(types[t]), differ, N, N);
      CHECK(bad_weight == 0, "%s %s: %d of %d weights are not eval/pdf", rsw_isa_name((rsw_isa)isa),
            mf_type_name(types[t]), bad_weight, ok);
      CHECK(ok > N / 2, "%s %s: only %d of %d samples valid", rsw_isa_name((rsw_isa)isa),
            mf_type_name(types[t]), ok, N);
      rough_free(&r);
    }
  }
  rsw_isa_set(rsw_isa_best());
  free(si);
  free(sp);
  free(u1);
  free(u2);
  free(bs);
  free(bs1);
  free(w);
  free(w1);
}

static void test_roughconductor_eval_pdf(void) {
  enum {
    N = 2000
  };
  surface_interaction *si = malloc(N * sizeof *si);
  const surface_interaction **sp = malloc(N * sizeof *sp);
  vec3 *wo = malloc(N * sizeof *wo);
  color *f = malloc(N * sizeof *f), *f1 = malloc(N * sizeof *f1);
  double *pdf = malloc(N * sizeof *pdf), *pdf1 = malloc(N * sizeof *pdf1);
  REQUIRE(si && sp && wo && f && f1 && pdf && pdf1, "allocation");
  pcg32 rng;
  pcg32_seed(&rng, 77, 78);
  for (int i = 0; i < N; i++) {
    vec3 d[2];
    for (int k = 0; k < 2; k++) { /* uniform on the sphere: some below the horizon */
      double z = 2 * pcg32_next_double(&rng) - 1, ph = 2 * RSW_PI * pcg32_next_double(&rng);
      double r = sqrt(fmax(0.0, 1 - z * z));
      d[k] = v3(r * cos(ph), r * sin(ph), k == 0 ? fabs(z) : z);
    }
    si[i] = tb_si_with(d[0]);
    sp[i] = &si[i];
    wo[i] = d[1];
  }
  const mf_type types[2] = {MF_BECKMANN, MF_GGX};
  const double alphas[3][2] = {{0.05, 0.05}, {0.3, 0.3}, {0.1, 0.6}};
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    for (int t = 0; t < 2; t++)
      for (int a = 0; a < 3; a++)
        for (int v = 0; v < 2; v++) {
          rough_case r = rough_make(types[t], alphas[a][0], alphas[a][1], v == 0, 0.0, 1.0);
          REQUIRE(r.b && r.b->ops->eval_pdf_batch, "allocation, batched op");
          r.b->ops->eval_pdf_batch(r.b, N, sp, wo, f, pdf);
          int bad = 0, differ = 0, nonzero = 0;
          double worst = 0;
          for (int i = 0; i < N; i++) {
            r.b->ops->eval_pdf_batch(r.b, 1, &sp[i], &wo[i], &f1[i], &pdf1[i]);
            if (memcmp(&f[i], &f1[i], sizeof f[i]) || memcmp(&pdf[i], &pdf1[i], sizeof pdf[i])) differ++;
            double fe = r.b->ops->eval(r.b, &si[i], wo[i]).c[0], pe = r.b->ops->pdf(r.b, &si[i], wo[i]);
            nonzero += fe > 0;
            double ef = fabs(f[i].c[0] - fe), ep = fabs(pdf[i] - pe);
            if (!(ef <= 1e-4 * fe + 1e-12) || !(ep <= 1e-4 * pe + 1e-12)) bad++;
            if (fe > 1e-12) worst = fmax(worst, ef / fe);
            if (pe > 1e-12) worst = fmax(worst, ep / pe);
          }
          CHECK(
              bad == 0 && differ == 0 && nonzero > N / 50,
              "%s %s alpha (%g, %g) visible %d: %d of %d differ from eval/pdf (worst relative %.2g), %d lane "
              "dependent, %d non-zero",
              rsw_isa_name((rsw_isa)isa), mf_type_name(types[t]), alphas[a][0], alphas[a][1], v == 0, bad, N,
              worst, differ, nonzero);
          rough_free(&r);
        }
  }
  rsw_isa_set(rsw_isa_best());
  free(si);
  free(sp);
  free(wo);
  free(f);
  free(f1);
  free(pdf);
  free(pdf1);
}

static void check_rays(const sensor *se, const char *what) {
  enum {
    N = 4099
  };
  vec2 *fu = malloc(N * sizeof *fu), *ap = malloc(N * sizeof *ap);
  ray3 *r = malloc(N * sizeof *r);
  double *w = malloc(N * sizeof *w);
  REQUIRE(fu && ap && r && w, "allocation");
  pcg32 rng;
  pcg32_seed(&rng, 5, 6);
  for (int i = 0; i < N; i++) {
    fu[i] = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
    ap[i] = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
  }
  const double edge[4] = {0.0, 0.5, 0.25, 1.0 - 0x1p-53};
  for (int k = 0; k < 16; k++) fu[k] = ap[15 - k] = v2(edge[k % 4], edge[k / 4]);
  REQUIRE(se->ops->sample_ray_batch, "%s: batched op", what);
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    /* One batch of N, then batches of every size up to 70 from a few
     * offsets (partial vectors and partial chunks of the lanes' passes). */
    se->ops->sample_ray_batch(se, N, fu, ap, r, w);
    for (int m = 1, at = 0; m <= 70 && at + m <= N; at += m, m++)
      se->ops->sample_ray_batch(se, m, fu + at, ap + at, r + at, w + at);
    int differ = 0;
    for (int i = 0; i < N; i++) {
      ray3 q;
      double wq = se->ops->sample_ray(se, fu[i], ap[i], &q);
      if (memcmp(&q.o, &r[i].o, sizeof q.o) || memcmp(&q.d, &r[i].d, sizeof q.d) || q.tmin != r[i].tmin ||
          q.tmax != r[i].tmax || wq != w[i])
        differ++;
    }
    CHECK(differ == 0, "%s at %s: %d of %d batched rays differ from sample_ray's", what,
          rsw_isa_name((rsw_isa)isa), differ, N);
  }
  rsw_isa_set(rsw_isa_best());
  free(fu);
  free(ap);
  free(r);
  free(w);
}

/* An hdistant sensor (its properties cam besides its 4x4 film) over a
 * ball: check_rays. */
static void check_hdistant(const char *cam, const char *what) {
  char doc[1024];
  snprintf(doc, sizeof doc,
           "{\"type\": \"scene\", \"cam\": {\"type\": \"hdistant\", %s,"
           " \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4}},"
           " \"ball\": {\"type\": \"sphere\", \"center\": [1, 2, 3], \"radius\": 2}}",
           cam);
  scene *s = tsup_load(doc, NULL);
  REQUIRE(s && s->n_sensors, "%s: the scene", what);
  check_rays(s->sensors[0], what);
  scene_free(s);
}

static void test_hdistant_rays(void) {
  scene *s = tsup_load_file("proto/examples/hdistant_seed.xml", NULL);
  REQUIRE(s && s->n_sensors, "hdistant_seed.xml");
  check_rays(s->sensors[0], "seed scene hdistant");
  scene_free(s);
  s = tsup_load_file("proto/examples/canopy_periodic.json", NULL);
  REQUIRE(s && s->n_sensors, "canopy_periodic.json");
  check_rays(s->sensors[0], "periodic canopy hdistant (a target, the slab)");
  scene_free(s);
  check_hdistant("\"to_world\": [{\"rotate\": {\"axis\": [0, 1, 0], \"angle\": 20}}],"
                 " \"target\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [3, 2, 1]},"
                 "   {\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 10}}, {\"translate\": [0.5, 0, 0.25]}]}",
                 "hdistant, a rectangle target (the atmosphere's sensor)");
  check_hdistant(
      "\"to_world\": [{\"scale\": [1, 2, 0.5]}, {\"rotate\": {\"axis\": [1, 1, 0], \"angle\": 33}}]",
      "rotated, scaled hdistant");
}

static void test_isa_parse(void) {
  rsw_isa isa;
  rsw_err err = {0};
  CHECK(rsw_isa_parse("auto", &isa, &err) == RSW_OK && isa == rsw_isa_best(), "auto is the best ISA");
  CHECK(rsw_isa_parse("generic", &isa, &err) == RSW_OK && isa == RSW_ISA_GENERIC, "generic (every CPU)");
  CHECK(rsw_isa_parse("avx3", &isa, &err) == RSW_ERR_INVALID && strcmp(err.where, "--isa") == 0 &&
            strstr(err.msg, "avx3"),
        "an unknown ISA is refused naming it: %s", err.msg);
  for (int i = 0; i < RSW_ISA__COUNT; i++) {
    err = (rsw_err){0}; /* a fresh error: rsw_fail keeps the first one */
    rsw_status st = rsw_isa_parse(rsw_isa_name((rsw_isa)i), &isa, &err);
    if (rsw_isa_supported((rsw_isa)i))
      CHECK(st == RSW_OK && isa == (rsw_isa)i, "%s parses", rsw_isa_name((rsw_isa)i));
    else
      CHECK(st == RSW_ERR_INVALID && strstr(err.msg, "lacks"), "%s refused on this CPU: %s",
            rsw_isa_name((rsw_isa)i), err.msg);
  }
}

/* ---- the other hot plugins' batched ops (issue 12 point 3) -------------- */

typedef struct plug_case {
  const char *what;
  bsdf *b;
  texture *tex[8];
} plug_case;

static texture *ctex(plug_case *c, double v) {
  for (int i = 0; i < 8; i++)
    if (!c->tex[i]) return c->tex[i] = uniform_texture_const(v, "t");
  return NULL;
}

static texture *ctex3(plug_case *c, double r, double g, double b) {
  for (int i = 0; i < 8; i++)
    if (!c->tex[i]) {
      spectrum s = {.kind = SPEC_RGB, .rgb = {r, g, b}};
      return c->tex[i] = uniform_texture_new(&s, "t");
    }
  return NULL;
}

static void case_free(plug_case *c) {
  tb_free_bsdf(c->b);
  for (int i = 0; i < 8; i++) tb_free_tex(c->tex[i]);
}

enum {
  CMP_BITWISE, /* sample and eval/pdf bit for bit the scalar ops */
  CMP_VALUE,   /* directions and pdfs bitwise, values within 1e-5 */
  CMP_RATIO,   /* weight = eval/pdf within 1e-4, eval/pdf within 1e-4 */
};

/* Field by field, bitwise (not memcmp of the struct: its padding is not
 * a value). */
static bool bs_same(const bsdf_sample *a, const bsdf_sample *b) {
  return !memcmp(&a->wo, &b->wo, sizeof a->wo) && !memcmp(&a->pdf, &b->pdf, sizeof a->pdf) &&
         !memcmp(&a->eta, &b->eta, sizeof a->eta) && a->sampled_type == b->sampled_type;
}

/* n random lanes for the BSDF batches (seeded s0, s1): wi (si[i]) and
 * wo uniform on the sphere, so every failure path too, u1, u2 uniform;
 * lane 0 at the pole, lane 1 grazing (wi.z = 0 fails everywhere), lane 2
 * at the concentric map's centre. */
static void bsdf_lanes(int n, uint64_t s0, uint64_t s1, surface_interaction *si,
                       const surface_interaction **sp, vec3 *wo, double *u1, vec2 *u2) {
  pcg32 rng;
  pcg32_seed(&rng, s0, s1);
  for (int i = 0; i < n; i++) {
    vec3 d[2];
    for (int k = 0; k < 2; k++) {
      double z = 2 * pcg32_next_double(&rng) - 1, ph = 2 * RSW_PI * pcg32_next_double(&rng);
      double r = sqrt(fmax(0.0, 1 - z * z));
      d[k] = v3(r * cos(ph), r * sin(ph), z);
    }
    si[i] = tb_si_with(d[0]);
    sp[i] = &si[i];
    wo[i] = d[1];
    u1[i] = pcg32_next_double(&rng);
    u2[i] = v2(pcg32_next_double(&rng), pcg32_next_double(&rng));
  }
  si[0].wi = v3(0, 0, 1);
  si[1].wi = v3(1, 0, 0);
  u2[2] = v2(0.5, 0.5);
}

/* Batch vs scalar and lane independence over N random lanes. */
static void check_bsdf_batch(const plug_case *c, int mode) {
  enum {
    N = 3001
  };
  const bsdf *b = c->b;
  REQUIRE(b, "%s: allocation", c->what);
  surface_interaction *si = malloc(N * sizeof *si);
  const surface_interaction **sp = malloc(N * sizeof *sp);
  double *u1 = malloc(N * sizeof *u1), *pdf = malloc(N * sizeof *pdf), *pdf1 = malloc(N * sizeof *pdf1);
  vec2 *u2 = malloc(N * sizeof *u2);
  vec3 *wo = malloc(N * sizeof *wo);
  bsdf_sample *bs = malloc(N * sizeof *bs), *bs1 = malloc(N * sizeof *bs1);
  color *w = malloc(N * sizeof *w), *w1 = malloc(N * sizeof *w1), *f = malloc(N * sizeof *f),
        *f1 = malloc(N * sizeof *f1);
  REQUIRE(si && sp && u1 && pdf && pdf1 && u2 && wo && bs && bs1 && w && w1 && f && f1, "allocation");
  bsdf_lanes(N, 314, 159, si, sp, wo, u1, u2);
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    const char *in = rsw_isa_name((rsw_isa)isa);
    bsdf_sample_n(b, N, sp, u1, u2, bs, w);
    bsdf_eval_pdf_n(b, N, sp, wo, f, pdf);
    int dep = 0, bad_s = 0, bad_e = 0, valid = 0, nonzero = 0;
    double worst = 0;
    for (int i = 0; i < N; i++) {
      bsdf_sample_n(b, 1, &sp[i], &u1[i], &u2[i], &bs1[i], &w1[i]);
      bsdf_eval_pdf_n(b, 1, &sp[i], &wo[i], &f1[i], &pdf1[i]);
      if (!bs_same(&bs[i], &bs1[i]) || memcmp(&w[i], &w1[i], sizeof w[i]) ||
          memcmp(&f[i], &f1[i], sizeof f[i]) || memcmp(&pdf[i], &pdf1[i], sizeof pdf[i]))
        dep++;
      bsdf_sample q;
      color wq = b->ops->sample(b, &si[i], u1[i], u2[i], &q);
      color fe = b->ops->eval(b, &si[i], wo[i]);
      double pe = b->ops->pdf(b, &si[i], wo[i]);
      valid += bs[i].pdf > 0;
      nonzero += fe.c[0] > 0;
      if (mode == CMP_BITWISE) {
        if (memcmp(&q.wo, &bs[i].wo, sizeof q.wo) || q.pdf != bs[i].pdf || memcmp(&wq, &w[i], sizeof wq) ||
            (q.pdf > 0 && (q.eta != bs[i].eta || q.sampled_type != bs[i].sampled_type)))
          bad_s++;
        if (memcmp(&fe, &f[i], sizeof fe) || pe != pdf[i]) bad_e++;
        continue;
      }
      double tol = mode == CMP_VALUE ? 1e-5 : 1e-4;
      if (mode == CMP_VALUE) {
        if (memcmp(&q.wo, &bs[i].wo, sizeof q.wo) || q.pdf != bs[i].pdf ||
            q.sampled_type != bs[i].sampled_type)
          bad_s++;
        for (int ch = 0; ch < 3; ch++) {
          double e = fabs(wq.c[ch] - w[i].c[ch]);
          if (!(e <= tol * fabs(wq.c[ch]) + 1e-12)) bad_s++;
          if (fabs(wq.c[ch]) > 1e-12) worst = fmax(worst, e / fabs(wq.c[ch]));
        }
      } else if (bs[i].pdf > 0) { /* CMP_RATIO: the sample's weight is eval / pdf */
        color ev = b->ops->eval(b, &si[i], bs[i].wo);
        double pv = b->ops->pdf(b, &si[i], bs[i].wo);
        for (int ch = 0; ch < 3; ch++) {
          double ref = ev.c[ch] / pv;
          if (!(fabs(w[i].c[ch] - ref) <= tol * fabs(ref) + 1e-12)) bad_s++;
        }
      }
      for (int ch = 0; ch < 3; ch++) {
        double e = fabs(fe.c[ch] - f[i].c[ch]);
        if (!(e <= tol * fabs(fe.c[ch]) + 1e-12)) bad_e++;
        if (fabs(fe.c[ch]) > 1e-12) worst = fmax(worst, e / fabs(fe.c[ch]));
      }
      if (!(fabs(pe - pdf[i]) <= tol * pe + 1e-12)) bad_e++;
    }
    CHECK(dep == 0, "%s at %s: %d of %d lanes differ between a batch of %d and batches of 1", c->what, in,
          dep, N, N);
    CHECK(bad_s == 0, "%s at %s: %d batched samples differ from sample()'s (worst relative %.2g)", c->what,
          in, bad_s, worst);
    CHECK(bad_e == 0, "%s at %s: %d batched eval/pdf differ from eval()/pdf() (worst relative %.2g)", c->what,
          in, bad_e, worst);
    CHECK(valid > N / 5, "%s at %s: only %d of %d samples valid", c->what, in, valid, N);
    if (!(b->flags & BSDF_DELTA))
      CHECK(nonzero > N / 10, "%s at %s: only %d of %d evals non-zero", c->what, in, nonzero, N);
  }
  rsw_isa_set(rsw_isa_best());
  free(si);
  free(sp);
  free(u1);
  free(pdf);
  free(pdf1);
  free(u2);
  free(wo);
  free(bs);
  free(bs1);
  free(w);
  free(w1);
  free(f);
  free(f1);
}

static void test_plugin_batch_vs_scalar(void) {
  render_ctx rgb = {.variant = VARIANT_RGB, .wavelength = 550.0};
  plug_case c = {.what = "diffuse"};
  c.b = diffuse_new(ctex3(&c, 0.2, 0.5, 0.8));
  check_bsdf_batch(&c, CMP_BITWISE);
  case_free(&c);

  c = (plug_case){.what = "conductor (mirror)"};
  c.b = conductor_new(ctex(&c, 0.0), ctex(&c, 1.0), NULL, NULL, NULL);
  check_bsdf_batch(&c, CMP_BITWISE);
  case_free(&c);

  c = (plug_case){.what = "conductor Au rgb, specular_reflectance"};
  c.b = conductor_new(NULL, NULL, ior_conductor_lookup("Au"), ctex(&c, 0.9), &rgb);
  check_bsdf_batch(&c, CMP_BITWISE);
  case_free(&c);

  c = (plug_case){.what = "conductor eta 1.5 k 3 (grey)"};
  c.b = conductor_new(ctex(&c, 1.5), ctex(&c, 3.0), NULL, NULL, NULL);
  check_bsdf_batch(&c, CMP_BITWISE);
  case_free(&c);

  c = (plug_case){.what = "dielectric 1.5"};
  c.b = dielectric_new(1.5, 1.0, NULL, ctex(&c, 0.9));
  check_bsdf_batch(&c, CMP_BITWISE);
  case_free(&c);

  c = (plug_case){.what = "bilambertian"};
  c.b = bilambertian_new(ctex3(&c, 0.3, 0.1, 0.5), ctex3(&c, 0.4, 0.6, 0.2));
  check_bsdf_batch(&c, CMP_BITWISE);
  case_free(&c);

  c = (plug_case){.what = "rpv grey"};
  c.b = rpv_new(ctex(&c, 0.12), ctex(&c, 0.7), ctex(&c, -0.2), ctex(&c, 0.4));
  check_bsdf_batch(&c, CMP_VALUE);
  case_free(&c);

  c = (plug_case){.what = "rpv coloured, rho_c = rho_0"};
  c.b = rpv_new(ctex3(&c, 0.05, 0.1, 0.3), ctex3(&c, 0.6, 0.8, 1.3), ctex3(&c, -0.3, 0.1, 0.25), NULL);
  check_bsdf_batch(&c, CMP_VALUE);
  case_free(&c);

  /* k = 1, g = 0, rho_c = 1: M = F = H = 1 exactly, diffuse's numbers. */
  c = (plug_case){.what = "rpv as Lambertian"};
  c.b = rpv_new(ctex(&c, 0.3), ctex(&c, 1.0), ctex(&c, 0.0), ctex(&c, 1.0));
  check_bsdf_batch(&c, CMP_BITWISE);
  case_free(&c);

  c = (plug_case){.what = "twosided (diffuse, rpv back)"};
  {
    bsdf *front = diffuse_new(ctex(&c, 0.6));
    bsdf *back = rpv_new(ctex(&c, 0.12), ctex(&c, 1.0), ctex(&c, 0.0), ctex(&c, 1.0));
    c.b = front && back ? twosided_new(front, back) : NULL;
    check_bsdf_batch(&c, CMP_BITWISE);
    case_free(&c);
    tb_free_bsdf(front);
    tb_free_bsdf(back);
  }

  c = (plug_case){.what = "twosided (conductor Au, diffuse)"};
  {
    bsdf *front = conductor_new(NULL, NULL, ior_conductor_lookup("Au"), NULL, &rgb);
    bsdf *back = diffuse_new(ctex(&c, 0.6));
    c.b = front && back ? twosided_new(front, back) : NULL;
    check_bsdf_batch(&c, CMP_BITWISE);
    case_free(&c);
    tb_free_bsdf(front);
    tb_free_bsdf(back);
  }

  c = (plug_case){.what = "twosided (diffuse, roughconductor GGX 0.3)"};
  {
    rough_case r = rough_make(MF_GGX, 0.3, 0.3, true, 0.0, 1.0);
    bsdf *front = diffuse_new(ctex(&c, 0.6));
    c.b = front && r.b ? twosided_new(front, r.b) : NULL;
    check_bsdf_batch(&c, CMP_RATIO);
    case_free(&c);
    tb_free_bsdf(front);
    rough_free(&r);
  }
}

/* The exact batches (bsdf_ops.sample_batch_exact, eval_pdf_batch_exact):
 * bit for bit sample(), eval() and pdf() in every lane at every ISA, over
 * N random lanes (every failure path too), and a batch of N the same as
 * N batches of one. */
static void check_bsdf_exact(const plug_case *c) {
  enum {
    N = 3001
  };
  const bsdf *b = c->b;
  REQUIRE(b && b->ops->sample_batch_exact && b->ops->eval_pdf_batch_exact, "%s: allocation, exact ops",
          c->what);
  surface_interaction *si = malloc(N * sizeof *si);
  const surface_interaction **sp = malloc(N * sizeof *sp);
  double *u1 = malloc(N * sizeof *u1), *pdf = malloc(N * sizeof *pdf);
  vec2 *u2 = malloc(N * sizeof *u2);
  vec3 *wo = malloc(N * sizeof *wo);
  bsdf_sample *bs = malloc(N * sizeof *bs);
  color *w = malloc(N * sizeof *w), *f = malloc(N * sizeof *f);
  REQUIRE(si && sp && u1 && pdf && u2 && wo && bs && w && f, "allocation");
  bsdf_lanes(N, 2718, 28, si, sp, wo, u1, u2);
  wo[3] = v3(0, 0, 1);
  wo[4] = si[4].wi; /* the hot spot: G = 0 */
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    const char *in = rsw_isa_name((rsw_isa)isa);
    b->ops->sample_batch_exact(b, N, sp, u1, u2, bs, w);
    b->ops->eval_pdf_batch_exact(b, N, sp, wo, f, pdf);
    int bad_s = 0, bad_e = 0, dep = 0, valid = 0, nonzero = 0;
    for (int i = 0; i < N; i++) {
      bsdf_sample q, q1;
      color wq = b->ops->sample(b, &si[i], u1[i], u2[i], &q), w1, f1;
      color fe = b->ops->eval(b, &si[i], wo[i]);
      double pe = b->ops->pdf(b, &si[i], wo[i]), p1;
      if (memcmp(&q.wo, &bs[i].wo, sizeof q.wo) || q.pdf != bs[i].pdf || memcmp(&wq, &w[i], sizeof wq) ||
          (q.pdf > 0 && (q.eta != bs[i].eta || q.sampled_type != bs[i].sampled_type)))
        bad_s++;
      if (memcmp(&fe, &f[i], sizeof fe) || memcmp(&pe, &pdf[i], sizeof pe)) bad_e++;
      b->ops->sample_batch_exact(b, 1, &sp[i], &u1[i], &u2[i], &q1, &w1);
      b->ops->eval_pdf_batch_exact(b, 1, &sp[i], &wo[i], &f1, &p1);
      if (!bs_same(&q1, &bs[i]) || memcmp(&w1, &w[i], sizeof w1) || memcmp(&f1, &f[i], sizeof f1) ||
          memcmp(&p1, &pdf[i], sizeof p1))
        dep++;
      valid += bs[i].pdf > 0;
      nonzero += fe.c[0] > 0;
    }
    CHECK(bad_s == 0, "%s at %s: %d exact batched samples differ from sample()'s", c->what, in, bad_s);
    CHECK(bad_e == 0, "%s at %s: %d exact batched eval/pdf differ from eval()/pdf()", c->what, in, bad_e);
    CHECK(dep == 0, "%s at %s: %d of %d lanes differ between a batch of %d and batches of 1", c->what, in,
          dep, N, N);
    CHECK(valid > N / 5 && nonzero > N / 10, "%s at %s: only %d samples valid, %d evals non-zero", c->what,
          in, valid, nonzero);
  }
  rsw_isa_set(rsw_isa_best());
  free(si);
  free(sp);
  free(u1);
  free(pdf);
  free(u2);
  free(wo);
  free(bs);
  free(w);
  free(f);
}

static void test_rpv_exact(void) {
  plug_case c = {.what = "rpv grey (exact)"};
  c.b = rpv_new(ctex(&c, 0.12), ctex(&c, 0.7), ctex(&c, -0.2), ctex(&c, 0.4));
  check_bsdf_exact(&c);
  case_free(&c);

  c = (plug_case){.what = "rpv the atmosphere's ground, rho_c = rho_0 (exact)"};
  c.b = rpv_new(ctex(&c, 0.183), ctex(&c, 0.78), ctex(&c, -0.1), NULL);
  check_bsdf_exact(&c);
  case_free(&c);

  c = (plug_case){.what = "rpv coloured (exact)"};
  c.b = rpv_new(ctex3(&c, 0.05, 0.1, 0.3), ctex3(&c, 0.6, 0.8, 1.3), ctex3(&c, -0.3, 0.1, 0.25), NULL);
  check_bsdf_exact(&c);
  case_free(&c);

  c = (plug_case){.what = "rpv as Lambertian (exact)"};
  c.b = rpv_new(ctex(&c, 0.3), ctex(&c, 1.0), ctex(&c, 0.0), ctex(&c, 1.0));
  check_bsdf_exact(&c);
  case_free(&c);
}

static void test_plugin_batch_chi2(void) {
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    plug_case c = {.what = "batched rpv"};
    c.b = rpv_new(ctex(&c, 0.12), ctex(&c, 0.7), ctex(&c, -0.2), ctex(&c, 0.4));
    REQUIRE(c.b, "allocation");
    run_chi2(c.b, tb_dir_deg(0.0, 0.0), c.what);
    run_chi2(c.b, tb_dir_deg(70.0, 30.0), c.what);
    case_free(&c);

    c = (plug_case){.what = "batched bilambertian"};
    c.b = bilambertian_new(ctex(&c, 0.4), ctex(&c, 0.5));
    REQUIRE(c.b, "allocation");
    run_chi2(c.b, tb_dir_deg(30.0, 10.0), c.what);
    run_chi2(c.b, tb_dir_deg(120.0, 200.0), c.what); /* from the back */
    case_free(&c);
    c = (plug_case){.what = "batched bilambertian R 0.1 T 0.6"};
    c.b = bilambertian_new(ctex(&c, 0.1), ctex(&c, 0.6));
    REQUIRE(c.b, "allocation");
    run_chi2(c.b, tb_dir_deg(45.0, 80.0), c.what);
    case_free(&c);

    c = (plug_case){.what = "batched twosided (diffuse, GGX 0.3)"};
    rough_case r = rough_make(MF_GGX, 0.3, 0.3, true, 0.0, 1.0);
    bsdf *front = diffuse_new(ctex(&c, 0.6));
    c.b = front && r.b ? twosided_new(front, r.b) : NULL;
    REQUIRE(c.b, "allocation");
    run_chi2(c.b, tb_dir_deg(40.0, 0.0), c.what);
    run_chi2(c.b, tb_dir_deg(180.0 - 40.0, 0.0), c.what);
    run_chi2(c.b, tb_dir_deg(0.0, 0.0), c.what);
    run_chi2(c.b, tb_dir_deg(180.0 - 75.0, 50.0), c.what);
    case_free(&c);
    tb_free_bsdf(front);
    rough_free(&r);
  }
  rsw_isa_set(rsw_isa_best());
}

static void test_sensor_batches(void) {
  static const char *const scenes[][2] = {
      {"distant", "{\"type\": \"scene\", \"cam\": {\"type\": \"distant\", \"direction\": [0.3, -0.2, -1],"
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
                  " \"ball\": {\"type\": \"sphere\", \"center\": [1, 2, 3], \"radius\": 2}}"},
      {"distant, point target",
       "{\"type\": \"scene\", \"cam\": {\"type\": \"distant\", \"target\": [0.5, 0, 0],"
       " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
       " \"ball\": {\"type\": \"sphere\", \"radius\": 2}}"},
      {"mdistant", "{\"type\": \"scene\", \"cam\": {\"type\": \"mdistant\","
                   " \"directions\": \"0 0 -1, 0.5 0.1 -1, -1 0.3 -0.2, 0 1 0\","
                   " \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 1}},"
                   " \"ball\": {\"type\": \"sphere\", \"center\": [1, 2, 3], \"radius\": 2}}"},
      {"distantflux", "{\"type\": \"scene\", \"cam\": {\"type\": \"distantflux\","
                      " \"to_world\": {\"rotate\": {\"axis\": [1, 0.5, 0], \"angle\": 20}},"
                      " \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 4}},"
                      " \"ball\": {\"type\": \"sphere\", \"center\": [1, 2, 3], \"radius\": 2}}"},
      {"perspective", "{\"type\": \"scene\", \"cam\": {\"type\": \"perspective\", \"fov\": 39,"
                      " \"principal_point_offset_x\": 0.1, \"principal_point_offset_y\": -0.05,"
                      " \"near_clip\": 0.5, \"far_clip\": 80,"
                      " \"to_world\": {\"lookat\": {\"origin\": [1, 4, 5], \"target\": [0, 0, 0],"
                      " \"up\": [0, 0, 1]}},"
                      " \"film\": {\"type\": \"hdrfilm\", \"width\": 7, \"height\": 5}},"
                      " \"ball\": {\"type\": \"sphere\", \"radius\": 2}}"},
      {"radiancemeter", "{\"type\": \"scene\", \"cam\": {\"type\": \"radiancemeter\","
                        " \"origin\": [0, 0, 5], \"direction\": [0.1, 0, -1],"
                        " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
                        " \"ball\": {\"type\": \"sphere\", \"radius\": 2}}"},
  };
  for (size_t i = 0; i < sizeof scenes / sizeof scenes[0]; i++) {
    scene *s = tsup_load(scenes[i][1], NULL);
    REQUIRE(s && s->n_sensors, "%s scene", scenes[i][0]);
    check_rays(s->sensors[0], scenes[i][0]);
    scene_free(s);
  }
  scene *s = tsup_load_file("proto/examples/cornell_box.json", NULL);
  REQUIRE(s && s->n_sensors, "cornell_box.json");
  check_rays(s->sensors[0], "Cornell box perspective");
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_isa_parse);
  RSW_TEST_RUN(test_lane_independence_and_weights);
  RSW_TEST_RUN(test_roughconductor_eval_pdf);
  RSW_TEST_RUN(test_hdistant_rays);
  RSW_TEST_RUN(test_roughconductor_batch_chi2);
  RSW_TEST_RUN(test_lanes_vs_scalar);
  RSW_TEST_RUN(test_diffuse_batch);
  RSW_TEST_RUN(test_plugin_batch_vs_scalar);
  RSW_TEST_RUN(test_rpv_exact);
  RSW_TEST_RUN(test_sensor_batches);
  RSW_TEST_RUN(test_plugin_batch_chi2);
  RSW_TEST_END("test_simd");
}
