/* The BSDFs' polarization factors (bsdf_ops.polarization, bsdfs/fresnel_pol.h;
 * docs/plugins.md#polarization-surfaces), against the Fresnel equations computed
 * here in real arithmetic (Born & Wolf, Principles of Optics, sect. 1.5.2,
 * 1.5.4 and 14.2), independently of core/mueller.h's complex amplitudes:
 *  - dielectric reflection at Brewster's angle: unpolarized light comes
 *    out fully s-polarized (Q/I = +1, x = s);
 *  - conductor (gold at 550 nm, the ior table) reflection:
 *    Q/I = (Rs - Rp) / (Rs + Rp) at several angles;
 *  - dielectric transmission, from either side: Q/I = (Ts - Tp) / (Ts + Tp)
 *    with Ts = 1 - Rs, Tp = 1 - Rp;
 *  - total internal reflection: linear light stays fully polarized and
 *    its U turns into V by the s-p phase difference delta,
 *    tan(delta / 2) = cos t sqrt(sin^2 t - n^2) / sin^2 t;
 *  - every BSDF's factors are those of a passive surface (diattenuation
 *    and polarizance <= 1, a fully polarized input gives at most a fully
 *    polarized output), in bases perpendicular to the beams;
 *  - rough and layered surfaces: a microfacet's Fresnel matrix at the half
 *    vector, the diffuse share depolarizing, the wrappers forwarding.
 * Deterministic (fixed directions and a fixed pcg32 stream); tolerances
 * are rounding-level (1e-12) unless stated. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../support/bsdf_test.h"
#include "../../support/test.h"
#include "../../support/tsup.h"
#include "kernel/bsdfs/eo_surfaces.h"
#include "kernel/bsdfs/fresnel.h"
#include "kernel/bsdfs/ior_data.h"
#include "kernel/core/rng.h"

RSW_TEST_DEFINE_GLOBALS

static scene *bsdf_scene(const char *bsdf_json) {
  char buf[4096];
  snprintf(buf, sizeof buf, "{\"type\": \"scene\", \"s\": {\"type\": \"rectangle\", \"bsdf\": %s}}",
           bsdf_json);
  return tsup_load(buf, "mono");
}

/* The factors of b for light arriving along -wo and leaving along wi. */
static void factors(const bsdf *b, vec3 wi, vec3 wo, unsigned lobe, mueller P[3], vec3 *s_in, vec3 *s_out) {
  surface_interaction si = tb_si_with(wi);
  b->ops->polarization(b, &si, wo, lobe, P, s_in, s_out);
}

/* Real-arithmetic Fresnel reflectances of a dielectric (relative index n,
 * no total reflection) at incidence cosine c. */
static void dielectric_rs_rp(double c, double n, double *Rs, double *Rp) {
  double ct = sqrt(1.0 - (1.0 - c * c) / (n * n));
  double rs = (c - n * ct) / (c + n * ct), rp = (n * c - ct) / (n * c + ct);
  *Rs = rs * rs, *Rp = rp * rp;
}

/* Conductor reflectances (Born & Wolf 14.2; the real form of
 * bsdfs/fresnel.h's comment), index eta + i k, incidence cosine c. */
static void conductor_rs_rp(double c, double eta, double k, double *Rs, double *Rp) {
  double s2 = 1.0 - c * c, t1 = eta * eta - k * k - s2;
  double A = sqrt(t1 * t1 + 4.0 * eta * eta * k * k), a = sqrt(0.5 * (A + t1));
  *Rs = (A + c * c - 2.0 * c * a) / (A + c * c + 2.0 * c * a);
  *Rp = *Rs * (A * c * c + s2 * s2 - 2.0 * c * a * s2) / (A * c * c + s2 * s2 + 2.0 * c * a * s2);
}

static void check_bases(vec3 wi, vec3 wo, vec3 s_in, vec3 s_out, const char *what) {
  CHECK(fabs(v3_len(s_in) - 1.0) < 1e-12 && fabs(v3_len(s_out) - 1.0) < 1e-12, "%s: unit bases", what);
  CHECK(fabs(v3_dot(s_in, wo)) < 1e-12, "%s: s_in . wo = %g", what, v3_dot(s_in, wo));
  CHECK(fabs(v3_dot(s_out, wi)) < 1e-12, "%s: s_out . wi = %g", what, v3_dot(s_out, wi));
}

static void test_brewster_reflection_is_s_polarized(void) {
  scene *s = bsdf_scene("{\"type\": \"dielectric\", \"int_ior\": 1.5, \"ext_ior\": 1.0}");
  REQUIRE(s, "scene");
  const bsdf *b = s->shapes[0]->bsdf;
  double tb = atan(1.5);
  for (int k = 0; k < 2; k++) {
    double phi = k ? 1.1 : 0.0;
    vec3 wo = v3(sin(tb) * cos(phi), sin(tb) * sin(phi), cos(tb)), wi = reflect_local(wo);
    mueller P[3];
    vec3 si_, so_;
    factors(b, wi, wo, BSDF_DELTA_REFLECTION, P, &si_, &so_);
    check_bases(wi, wo, si_, so_, "brewster");
    /* s is perpendicular to the plane of incidence (z, wo). */
    CHECK(fabs(v3_dot(si_, v3(0, 0, 1))) < 1e-12 && fabs(v3_dot(so_, v3(0, 0, 1))) < 1e-12, "s horizontal");
    const mueller *m = &P[0];
    CHECK_ABS(m->m[0][0], 1.0, 0.0);
    CHECK_ABS(m->m[1][0], 1.0, 1e-12); /* Q/I of unpolarized light: +1 (x = s) */
    CHECK_ABS(m->m[2][0], 0.0, 1e-12);
    CHECK_ABS(m->m[3][0], 0.0, 1e-12);
    double dolp = sqrt(m->m[1][0] * m->m[1][0] + m->m[2][0] * m->m[2][0]);
    CHECK_ABS(dolp, 1.0, 1e-12);
  }
  /* Lobe 0 (the light sample) and the sampled lobe agree on the geometry. */
  vec3 wo = tb_dir_deg(tb * 180.0 / RSW_PI, 0.0), wi = reflect_local(wo), a, c;
  mueller P0[3], P1[3];
  factors(b, wi, wo, 0, P0, &a, &c);
  factors(b, wi, wo, BSDF_DELTA_REFLECTION, P1, &a, &c);
  CHECK(memcmp(&P0[0], &P1[0], sizeof P0[0]) == 0, "lobe 0 = the reflection lobe for reflection geometry");
  /* Normal incidence: no diattenuation, U and V flip (r_p = -r_s). */
  factors(b, v3(0, 0, 1), v3(0, 0, 1), BSDF_DELTA_REFLECTION, P0, &a, &c);
  CHECK_ABS(P0[0].m[1][0], 0.0, 1e-12);
  CHECK_ABS(P0[0].m[1][1], 1.0, 1e-12);
  CHECK_ABS(P0[0].m[2][2], -1.0, 1e-12);
  CHECK_ABS(P0[0].m[3][3], -1.0, 1e-12);
  scene_free(s);
}

static void test_conductor_gold_against_fresnel(void) {
  scene *s = bsdf_scene("{\"type\": \"conductor\", \"material\": \"Au\"}");
  REQUIRE(s, "scene");
  const bsdf *b = s->shapes[0]->bsdf;
  double eta, k;
  REQUIRE(ior_conductor_eval(ior_conductor_lookup("Au"), 550.0, &eta, &k), "gold at 550 nm");
  const double th[] = {0.0, 20.0, 45.0, 60.0, 75.0, 85.0, 89.0};
  for (size_t i = 0; i < sizeof th / sizeof th[0]; i++) {
    vec3 wo = tb_dir_deg(th[i], 35.0), wi = reflect_local(wo), a, c;
    mueller P[3];
    factors(b, wi, wo, BSDF_DELTA_REFLECTION, P, &a, &c);
    check_bases(wi, wo, a, c, "gold");
    double Rs, Rp;
    conductor_rs_rp(wo.z, eta, k, &Rs, &Rp);
    CHECK_ABS(P[0].m[1][0], (Rs - Rp) / (Rs + Rp), 1e-12);
    CHECK_ABS(P[0].m[0][1], (Rs - Rp) / (Rs + Rp), 1e-12);
    /* c^2 + d^2 = Rs Rp: the non-depolarizing block. */
    double cc = P[0].m[2][2], dd = P[0].m[2][3], norm = 0.5 * (Rs + Rp);
    CHECK_ABS((cc * cc + dd * dd) * norm * norm, Rs * Rp, 1e-12);
    CHECK_ABS(P[0].m[3][3], cc, 1e-15);
    CHECK_ABS(P[0].m[3][2], -dd, 1e-15);
    CHECK(P[0].m[2][2] < 0.0 || th[i] > 60.0, "theta %g: reflection flips U at small angles", th[i]);
    /* The scalar Fresnel term the BSDF samples with is this matrix's M00. */
    CHECK_REL(norm, fresnel_conductor(wo.z, eta, k), 1e-12);
  }
  scene_free(s);
}

static void test_dielectric_transmission(void) {
  scene *s = bsdf_scene("{\"type\": \"dielectric\", \"int_ior\": 1.5, \"ext_ior\": 1.0}");
  REQUIRE(s, "scene");
  const bsdf *b = s->shapes[0]->bsdf;
  const double th[] = {0.0, 30.0, 56.309932474020215, 70.0, 85.0};
  for (int side = 0; side < 2; side++)
    for (size_t i = 0; i < sizeof th / sizeof th[0]; i++) {
      double n = side ? 1.0 / 1.5 : 1.5, t = th[i] * RSW_PI / 180.0;
      if (side && sin(t) >= n) continue;
      vec3 wo = tb_dir_deg(th[i], 20.0);
      if (side) wo.z = -wo.z; /* the light comes from inside */
      double cos_t, eta_it, eta_ti;
      /* The radiance direction wi leaving along the refracted light. */
      fresnel_dielectric(wo.z, 1.5, &cos_t, &eta_it, &eta_ti);
      vec3 wi = refract_local(wo, cos_t, eta_ti), a, c;
      mueller P[3];
      factors(b, wi, wo, BSDF_DELTA_TRANSMISSION, P, &a, &c);
      check_bases(wi, wo, a, c, "transmission");
      double Rs, Rp;
      dielectric_rs_rp(fabs(wo.z), n, &Rs, &Rp);
      double Ts = 1.0 - Rs, Tp = 1.0 - Rp;
      CHECK_ABS(P[0].m[1][0], (Ts - Tp) / (Ts + Tp), 1e-12);
      CHECK_ABS(P[0].m[2][2], 2.0 * sqrt(Ts * Tp) / (Ts + Tp), 1e-12);
      CHECK_ABS(P[0].m[3][2], 0.0, 1e-15);
    }
  /* Brewster's angle from outside: Tp = 1, DoLP = Rs / (2 - Rs). */
  double tb = atan(1.5), Rs, Rp, cos_t, eta_it, eta_ti;
  vec3 wo = v3(sin(tb), 0, cos(tb));
  fresnel_dielectric(wo.z, 1.5, &cos_t, &eta_it, &eta_ti);
  vec3 wi = refract_local(wo, cos_t, eta_ti), a, c;
  mueller P[3];
  factors(b, wi, wo, BSDF_DELTA_TRANSMISSION, P, &a, &c);
  dielectric_rs_rp(wo.z, 1.5, &Rs, &Rp);
  CHECK_ABS(Rp, 0.0, 1e-15);
  CHECK_ABS(fabs(P[0].m[1][0]), Rs / (2.0 - Rs), 1e-12);
  CHECK(P[0].m[1][0] < 0, "transmitted light is p-rich (Q < 0 with x = s)");
  scene_free(s);
}

static void test_total_internal_reflection_retards(void) {
  scene *s = bsdf_scene("{\"type\": \"dielectric\", \"int_ior\": 1.5, \"ext_ior\": 1.0}");
  REQUIRE(s, "scene");
  const bsdf *b = s->shapes[0]->bsdf;
  const double th[] = {45.0, 50.0, 60.0, 75.0};
  double n = 1.0 / 1.5;
  for (size_t i = 0; i < sizeof th / sizeof th[0]; i++) {
    vec3 wo = tb_dir_deg(th[i], 70.0);
    wo.z = -wo.z;
    vec3 wi = reflect_local(wo), a, c;
    mueller P[3];
    factors(b, wi, wo, BSDF_DELTA_REFLECTION, P, &a, &c);
    check_bases(wi, wo, a, c, "tir");
    double t = th[i] * RSW_PI / 180.0, st2 = sin(t) * sin(t);
    double delta = 2.0 * atan(cos(t) * sqrt(st2 - n * n) / st2); /* Born & Wolf 1.5 (60) */
    /* Linear light at +45 degrees to s: (1, 0, 1, 0). */
    double in[4] = {1, 0, 1, 0}, out[4];
    mu_apply(&P[0], in, out);
    CHECK_ABS(out[0], 1.0, 1e-12); /* no diattenuation */
    CHECK_ABS(out[1], 0.0, 1e-12);
    CHECK_ABS(sqrt(out[1] * out[1] + out[2] * out[2] + out[3] * out[3]), 1.0, 1e-12);
    CHECK_ABS(fabs(out[2]), fabs(cos(delta)), 1e-12);
    CHECK_ABS(fabs(out[3]), fabs(sin(delta)), 1e-12);
    CHECK(fabs(out[3]) > 0.3, "theta %g: part of the light turns circular (V = %g)", th[i], out[3]);
    /* Linear light along s or p stays linear (DoLP 1, no V). */
    double in2[4] = {1, 1, 0, 0};
    mu_apply(&P[0], in2, out);
    CHECK_ABS(out[1], 1.0, 1e-12);
    CHECK_ABS(out[3], 0.0, 1e-12);
  }
  scene_free(s);
}

/* A passive surface's matrix: for every fully polarized input the output
 * has I >= 0 and DoP <= 1; so, too, diattenuation and polarizance <= 1. */
static void check_passive(const mueller *m, const char *what, int *bad) {
  double D = sqrt(m->m[0][1] * m->m[0][1] + m->m[0][2] * m->m[0][2] + m->m[0][3] * m->m[0][3]);
  double Pz = sqrt(m->m[1][0] * m->m[1][0] + m->m[2][0] * m->m[2][0] + m->m[3][0] * m->m[3][0]);
  bool ok = m->m[0][0] == 1.0 && D <= 1.0 + 1e-12 && Pz <= 1.0 + 1e-12;
  for (int k = 0; k < 24 && ok; k++) {
    double th = RSW_PI * (k % 6) / 5.0, ph = 2.0 * RSW_PI * (k / 6) / 4.0 + 0.3;
    double in[4] = {1, sin(th) * cos(ph), sin(th) * sin(ph), cos(th)}, out[4];
    mu_apply(m, in, out);
    double p = sqrt(out[1] * out[1] + out[2] * out[2] + out[3] * out[3]);
    ok = out[0] >= -1e-12 && p <= out[0] + 1e-12;
  }
  if (!ok && (*bad)++ < 3) {
    printf("  %s: not passive:\n", what);
    for (int i = 0; i < 4; i++)
      printf("    %.6g %.6g %.6g %.6g\n", m->m[i][0], m->m[i][1], m->m[i][2], m->m[i][3]);
  }
}

static const char *const PASSIVE[] = {
    "{\"type\": \"conductor\", \"material\": \"Au\"}",
    "{\"type\": \"conductor\"}",
    "{\"type\": \"dielectric\", \"int_ior\": 1.33}",
    "{\"type\": \"roughconductor\", \"material\": \"Cu\", \"alpha\": 0.3}",
    "{\"type\": \"roughconductor\", \"material\": \"Al\", \"distribution\": \"ggx\", \"alpha_u\": 0.1, "
    "\"alpha_v\": 0.4}",
    "{\"type\": \"plastic\", \"diffuse_reflectance\": 0.3}",
    "{\"type\": \"roughplastic\", \"diffuse_reflectance\": 0.3, \"alpha\": 0.2}",
    "{\"type\": \"maignan\", \"C\": 5, \"ndvi\": 0.5, \"refr_re\": 1.5, \"refr_im\": 0.1}",
    "{\"type\": \"ocean_legacy\", \"wavelength\": 550, \"wind_speed\": 5}",
    "{\"type\": \"twosided\", \"bsdf\": {\"type\": \"roughconductor\", \"material\": \"Au\"}}",
    "{\"type\": \"blendbsdf\", \"weight\": 0.3, \"bsdf_0\": {\"type\": \"roughplastic\"},"
    " \"bsdf_1\": {\"type\": \"roughconductor\", \"material\": \"Ag\", \"alpha\": 0.2}}",
    "{\"type\": \"mask\", \"opacity\": 0.4, \"bsdf\": {\"type\": \"conductor\", \"material\": \"Au\"}}",
    "{\"type\": \"selectbsdf\", \"indices\": 1, \"a\": {\"type\": \"diffuse\"},"
    " \"b\": {\"type\": \"roughconductor\", \"material\": \"Au\"}}",
};

static void test_every_matrix_is_passive(void) {
  pcg32 r;
  pcg32_seed(&r, 2024, 27);
  for (size_t i = 0; i < sizeof PASSIVE / sizeof PASSIVE[0]; i++) {
    scene *s = bsdf_scene(PASSIVE[i]);
    REQUIRE(s, "%s", PASSIVE[i]);
    const bsdf *b = s->shapes[0]->bsdf;
    REQUIRE(b->ops->polarization, "%s has a polarization op", PASSIVE[i]);
    int bad = 0;
    for (int k = 0; k < 400; k++) {
      vec3 wi = warp_square_to_uniform_sphere(v2(pcg32_next_double(&r), pcg32_next_double(&r)));
      vec3 wo = warp_square_to_uniform_sphere(v2(pcg32_next_double(&r), pcg32_next_double(&r)));
      if (k % 2 == 0) wo.z = fabs(wo.z), wi.z = fabs(wi.z);
      const unsigned lobes[] = {0, BSDF_DELTA_REFLECTION, BSDF_GLOSSY_REFLECTION, BSDF_DIFFUSE_REFLECTION,
                                BSDF_DELTA_TRANSMISSION};
      for (int l = 0; l < 5; l++) {
        mueller P[3];
        vec3 a, c;
        factors(b, wi, wo, lobes[l], P, &a, &c);
        check_bases(wi, wo, a, c, PASSIVE[i]);
        for (int ch = 0; ch < 3; ch++) check_passive(&P[ch], PASSIVE[i], &bad);
      }
    }
    CHECK(bad == 0, "%s: %d matrices not passive", PASSIVE[i], bad);
    scene_free(s);
  }
}

/* Q/I of unpolarized light after P (channel 0). */
static double q_of(const mueller *P) {
  return P[0].m[1][0];
}

/* The microfacet models: the Fresnel matrix at the half vector h, in the
 * bases of the plane holding wo, wi and h (not the macro surface's), and
 * the layered ones' diffuse share depolarizing. */
static void test_rough_and_layered(void) {
  vec3 wi = tb_dir_deg(35.0, 10.0), wo = tb_dir_deg(50.0, 150.0), a, c;
  vec3 h = v3_norm(v3_add(wi, wo)), n_inc = v3_norm(v3_cross(wo, wi));
  double ch = v3_dot(wo, h), eta, k, Rs, Rp;
  mueller P[3];
  REQUIRE(ior_conductor_eval(ior_conductor_lookup("Cu"), 550.0, &eta, &k), "copper");
  scene *s = bsdf_scene("{\"type\": \"roughconductor\", \"material\": \"Cu\", \"alpha\": 0.3}");
  REQUIRE(s, "roughconductor");
  factors(s->shapes[0]->bsdf, wi, wo, 0, P, &a, &c);
  conductor_rs_rp(ch, eta, k, &Rs, &Rp);
  CHECK_ABS(q_of(P), (Rs - Rp) / (Rs + Rp), 1e-12);
  CHECK_ABS(fabs(v3_dot(a, n_inc)), 1.0, 1e-12);
  CHECK_ABS(fabs(v3_dot(c, n_inc)), 1.0, 1e-12);
  mueller P2[3];
  factors(s->shapes[0]->bsdf, wi, wo, BSDF_GLOSSY_REFLECTION, P2, &a, &c);
  CHECK(memcmp(P, P2, sizeof P) == 0, "one lobe: the sample's matrix is eval's");
  scene_free(s);

  /* roughplastic: the specular lobe alone (a black base) is the coating's
   * Fresnel matrix at h; with a base, Q/I scales by f_s / (f_s + f_d). */
  dielectric_rs_rp(ch, 1.49, &Rs, &Rp);
  scene *sp = bsdf_scene("{\"type\": \"roughplastic\", \"int_ior\": 1.49, \"ext_ior\": 1, \"alpha\": 0.3, "
                         "\"diffuse_reflectance\": 0.0}");
  scene *sd = bsdf_scene("{\"type\": \"roughplastic\", \"int_ior\": 1.49, \"ext_ior\": 1, \"alpha\": 0.3, "
                         "\"diffuse_reflectance\": 0.6}");
  REQUIRE(sp && sd, "roughplastic");
  surface_interaction si = tb_si_with(wi);
  const bsdf *bp = sp->shapes[0]->bsdf, *bd = sd->shapes[0]->bsdf;
  double fs = bp->ops->eval(bp, &si, wo).c[0], f = bd->ops->eval(bd, &si, wo).c[0];
  REQUIRE(fs > 0 && f > fs, "both lobes (fs %g, f %g)", fs, f);
  factors(bp, wi, wo, 0, P, &a, &c);
  CHECK_ABS(q_of(P), (Rs - Rp) / (Rs + Rp), 1e-12);
  factors(bd, wi, wo, BSDF_DIFFUSE_REFLECTION, P, &a, &c);
  CHECK_ABS(q_of(P), fs / f * (Rs - Rp) / (Rs + Rp), 1e-12);
  CHECK_ABS(P[0].m[1][1], fs / f * 0.5 * (Rs + Rp) / (0.5 * (Rs + Rp)), 1e-12);
  scene_free(sp);
  scene_free(sd);

  /* plastic: the delta lobe is the coating's reflection, the diffuse lobe
   * (eval's, lobe 0) depolarizes. */
  scene *pl = bsdf_scene("{\"type\": \"plastic\", \"int_ior\": 1.5, \"ext_ior\": 1}");
  REQUIRE(pl, "plastic");
  vec3 r = reflect_local(wo);
  factors(pl->shapes[0]->bsdf, r, wo, BSDF_DELTA_REFLECTION, P, &a, &c);
  dielectric_rs_rp(wo.z, 1.5, &Rs, &Rp);
  CHECK_ABS(q_of(P), (Rs - Rp) / (Rs + Rp), 1e-12);
  factors(pl->shapes[0]->bsdf, wi, wo, 0, P, &a, &c);
  CHECK(memcmp(&P[0], &(mueller){{{1}}}, sizeof P[0]) == 0, "diffuse lobe depolarizes");
  scene_free(pl);
}

/* maignan: the facet's Fresnel matrix at alpha (cos alpha = sqrt((1 +
 * wi.wo) / 2)) of the complex index (refr_re + i refr_im) / ext_ior;
 * ocean_legacy's glint (component 2): water's at the half vector. */
static void test_eo_surfaces(void) {
  vec3 wi = tb_dir_deg(30.0, 0.0), wo = tb_dir_deg(45.0, 120.0), a, c;
  mueller P[3];
  double Rs, Rp;
  scene *s = bsdf_scene("{\"type\": \"maignan\", \"C\": 5, \"refr_re\": 1.6, \"refr_im\": 0.2, "
                        "\"ext_ior\": 1.0}");
  REQUIRE(s, "maignan");
  factors(s->shapes[0]->bsdf, wi, wo, 0, P, &a, &c);
  conductor_rs_rp(sqrt(0.5 * (1.0 + v3_dot(wi, wo))), 1.6, 0.2, &Rs, &Rp);
  CHECK_ABS(q_of(P), (Rs - Rp) / (Rs + Rp), 1e-12);
  CHECK(q_of(P) > 0.05, "maignan polarizes (Q/I %g)", q_of(P));
  scene_free(s);
  s = bsdf_scene("{\"type\": \"ocean_legacy\", \"wavelength\": 550, \"wind_speed\": 5, \"component\": 2}");
  REQUIRE(s, "ocean");
  const ocean_bsdf *o = (const ocean_bsdf *)s->shapes[0]->bsdf;
  factors(&o->base, wi, wo, BSDF_GLOSSY_REFLECTION, P, &a, &c);
  conductor_rs_rp(v3_dot(wo, v3_norm(v3_add(wi, wo))), o->n_re, o->n_im, &Rs, &Rp);
  CHECK_ABS(q_of(P), (Rs - Rp) / (Rs + Rp), 1e-12);
  scene_free(s);
  /* Whitecaps alone (component 1) depolarize; the whole model lies
   * between. */
  s = bsdf_scene("{\"type\": \"ocean_legacy\", \"wavelength\": 550, \"wind_speed\": 5, \"component\": 1}");
  REQUIRE(s, "ocean whitecaps");
  factors(s->shapes[0]->bsdf, wi, wo, 0, P, &a, &c);
  CHECK(q_of(P) == 0.0 && P[0].m[1][1] == 0.0, "whitecaps depolarize");
  scene_free(s);
  s = bsdf_scene("{\"type\": \"ocean_legacy\", \"wavelength\": 550, \"wind_speed\": 5}");
  REQUIRE(s, "ocean");
  factors(s->shapes[0]->bsdf, wi, wo, 0, P, &a, &c);
  CHECK(q_of(P) > 0.0 && q_of(P) < (Rs - Rp) / (Rs + Rp), "glint share: Q/I %g", q_of(P));
  scene_free(s);
}

/* Wrappers: twosided's back side is the nested BSDF's mirror image,
 * blendbsdf mixes by the components' values, mask's pass-through is the
 * identity, selectbsdf forwards. */
static void test_wrappers(void) {
  vec3 wi = tb_dir_deg(35.0, 10.0), wo = tb_dir_deg(50.0, 150.0), a, c, a2, c2;
  mueller P[3], Q[3];
  scene *s = bsdf_scene("{\"type\": \"twosided\", \"bsdf\": {\"type\": \"roughconductor\", \"material\": "
                        "\"Au\"}}");
  REQUIRE(s, "twosided");
  factors(s->shapes[0]->bsdf, wi, wo, 0, P, &a, &c);
  vec3 wib = v3(wi.x, wi.y, -wi.z), wob = v3(wo.x, wo.y, -wo.z);
  factors(s->shapes[0]->bsdf, wib, wob, 0, Q, &a2, &c2);
  check_bases(wib, wob, a2, c2, "twosided back");
  CHECK_ABS(q_of(Q), q_of(P), 1e-12);
  CHECK_ABS(Q[0].m[2][2], P[0].m[2][2], 1e-12);
  /* D P D: the circular coupling keeps its sign, U-Q couplings flip. */
  CHECK_ABS(Q[0].m[2][3], P[0].m[2][3], 1e-12);
  scene_free(s);

  const char *blend =
      "{\"type\": \"blendbsdf\", \"weight\": 0.25, \"bsdf_0\": {\"type\": \"diffuse\", "
      "\"reflectance\": 0.5}, \"bsdf_1\": {\"type\": \"roughconductor\", \"material\": \"Au\", "
      "\"alpha\": 0.3}}";
  s = bsdf_scene(blend);
  scene *rc = bsdf_scene("{\"type\": \"roughconductor\", \"material\": \"Au\", \"alpha\": 0.3}");
  REQUIRE(s && rc, "blend");
  surface_interaction si = tb_si_with(wi);
  const bsdf *bb = s->shapes[0]->bsdf, *br = rc->shapes[0]->bsdf;
  double f = bb->ops->eval(bb, &si, wo).c[0], f1 = 0.25 * br->ops->eval(br, &si, wo).c[0];
  factors(br, wi, wo, 0, Q, &a2, &c2);
  factors(bb, wi, wo, BSDF_GLOSSY_REFLECTION, P, &a, &c);
  CHECK_ABS(q_of(P), f1 / f * q_of(Q), 1e-12);
  CHECK(q_of(P) != 0.0, "the conductor's share polarizes");
  scene_free(s);
  scene_free(rc);

  s = bsdf_scene("{\"type\": \"mask\", \"opacity\": 0.3, \"bsdf\": {\"type\": \"conductor\"}}");
  REQUIRE(s, "mask");
  factors(s->shapes[0]->bsdf, wi, v3_neg(wi), BSDF_DELTA_TRANSMISSION, P, &a, &c);
  CHECK(memcmp(&P[0], &(mueller){{{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}}, sizeof P[0]) == 0,
        "pass-through: the identity");
  factors(s->shapes[0]->bsdf, reflect_local(wo), wo, BSDF_DELTA_REFLECTION, P, &a, &c);
  CHECK(P[0].m[2][2] != 1.0 && P[0].m[2][3] != 0.0, "the nested mirror retards");
  scene_free(s);

  s = bsdf_scene("{\"type\": \"null\"}");
  REQUIRE(s, "null");
  factors(s->shapes[0]->bsdf, wi, v3_neg(wi), BSDF_DELTA_TRANSMISSION, P, &a, &c);
  CHECK(memcmp(&P[0], &(mueller){{{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}}, sizeof P[0]) == 0,
        "null: the identity");
  check_bases(wi, v3_neg(wi), a, c, "null");
  scene_free(s);

  s = bsdf_scene("{\"type\": \"selectbsdf\", \"indices\": 1, \"a\": {\"type\": \"diffuse\"},"
                 " \"b\": {\"type\": \"dielectric\", \"int_ior\": 1.5, \"ext_ior\": 1}}");
  REQUIRE(s, "selectbsdf");
  double tb = atan(1.5);
  wo = v3(sin(tb), 0, cos(tb));
  factors(s->shapes[0]->bsdf, reflect_local(wo), wo, BSDF_DELTA_REFLECTION, P, &a, &c);
  CHECK_ABS(q_of(P), 1.0, 1e-12);
  scene_free(s);
}

/* ---- renders (variant mono_polarized, path) -------------------------------
 * The distant sensor looks along d at the origin; its film's Stokes basis
 * has x = z x (-d) normalized, horizontal (render.c film_stokes_x): for a
 * plane of incidence through the vertical, x is the s direction. */
static scene *plane_scene(const char *variant, const char *bsdf_json, double view_deg, uint32_t spp) {
  double t = view_deg * RSW_PI / 180.0;
  char buf[4096];
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\", \"integrator\": {\"type\": \"path\"},"
      " \"sensor\": {\"type\": \"distant\", \"direction\": [%.17g, 0, %.17g], \"target\": [0, 0, 0],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": %u},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"sky\": {\"type\": \"constant\", \"radiance\": 1.0},"
      " \"plane\": {\"type\": \"rectangle\", \"bsdf\": %s},"
      " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [20, 20, 1]}, "
      "   {\"translate\": [0, 0, -1]}], \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.0}}}",
      -sin(t), -cos(t), spp, bsdf_json);
  return tsup_load(buf, variant);
}

/* Glass at Brewster's angle over a black floor (the transmitted light is
 * absorbed), under a uniform unpolarized sky: every sample that reflects
 * brings (1, 1, 0, 0) in the s basis, so the pixel's DoLP is 1 and its
 * AoLP 0 (x = s), and S0 = R(theta_B) = Rs / 2 within 4 standard errors
 * (65,536 samples; Bernoulli variance R (1 - R) / N). */
static void test_render_brewster_glass(void) {
  double tb = atan(1.5) * 180.0 / RSW_PI;
  const uint32_t N = 65536;
  scene *s =
      plane_scene("mono_polarized", "{\"type\": \"dielectric\", \"int_ior\": 1.5, \"ext_ior\": 1.0}", tb, N);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 7, 2, &img), "render");
  REQUIRE(img.channels == 4 && strcmp(img.channel_names[0], "S0.Y") == 0 &&
              strcmp(img.channel_names[1], "S1.Y") == 0,
          "Stokes channels (%d)", img.channels);
  double S0 = img.data[0], Q = img.data[1], U = img.data[2], V = img.data[3];
  double Rs, Rp;
  dielectric_rs_rp(cos(atan(1.5)), 1.5, &Rs, &Rp);
  double R = 0.5 * (Rs + Rp), se = sqrt(R * (1.0 - R) / N);
  CHECK(fabs(S0 - R) <= 4.0 * se, "S0 = %.6g vs R = %.6g (4 se = %.2g)", S0, R, 4.0 * se);
  REQUIRE(S0 > 0, "light reflected");
  CHECK_ABS(sqrt(Q * Q + U * U) / S0, 1.0, 1e-6);
  CHECK_ABS(Q / S0, 1.0, 1e-6); /* AoLP 0: along x, the s direction */
  CHECK_ABS(V / S0, 0.0, 1e-6);
  film_image_free(&img);
  scene_free(s);
}

/* A gold plane seen at 60 degrees under the uniform sky: every sample
 * reflects with the same Fresnel matrix, so S0 = F and
 * Q / S0 = (Rs - Rp) / (Rs + Rp) (float film: 1e-6), U = V = 0. */
static void test_render_gold_plane(void) {
  scene *s = plane_scene("mono_polarized", "{\"type\": \"conductor\", \"material\": \"Au\"}", 60.0, 16);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 3, 1, &img), "render");
  REQUIRE(img.channels == 4, "Stokes channels");
  double eta, k, Rs, Rp;
  REQUIRE(ior_conductor_eval(ior_conductor_lookup("Au"), 550.0, &eta, &k), "gold");
  conductor_rs_rp(0.5, eta, k, &Rs, &Rp);
  double S0 = img.data[0];
  CHECK_REL(S0, 0.5 * (Rs + Rp), 1e-6);
  CHECK_ABS(img.data[1] / S0, (Rs - Rp) / (Rs + Rp), 1e-6);
  CHECK_ABS(img.data[2] / S0, 0.0, 1e-6);
  CHECK_ABS(img.data[3] / S0, 0.0, 1e-6);
  film_image_free(&img);
  scene_free(s);
}

/* A rough gold plane under a sun, no sky, seen off the sun's plane: every
 * sample is the sun's light through eval's matrix (lobe 0), the Fresnel
 * matrix at the half vector h, so the pixel is linearly polarized along
 * the facet's s axis e = wo x wi (wo towards the sun, wi towards the
 * sensor) with DoLP |Rs - Rp| / (Rs + Rp) at wo . h. In the film's basis
 * (x = z x wi horizontal, y = wi x x) its AoLP is atan2(e.y, e.x): this
 * checks the rotations from the facet's bases to the film's. */
static void test_render_rough_gold_off_plane(void) {
  double ts = 40.0 * RSW_PI / 180.0, tv = 30.0 * RSW_PI / 180.0, pv = 120.0 * RSW_PI / 180.0;
  vec3 wo = v3(sin(ts), 0, cos(ts)), wi = v3(sin(tv) * cos(pv), sin(tv) * sin(pv), cos(tv));
  char buf[4096];
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\", \"integrator\": {\"type\": \"path\"},"
      " \"sensor\": {\"type\": \"distant\", \"direction\": [%.17g, %.17g, %.17g], \"target\": [0, 0, 0],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [%.17g, 0, %.17g], \"irradiance\": 1},"
      " \"plane\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"roughconductor\", \"material\": \"Au\","
      "   \"alpha\": 0.2}}}",
      -wi.x, -wi.y, -wi.z, -wo.x, -wo.z);
  scene *s = tsup_load(buf, "mono_polarized");
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 5, 1, &img), "render");
  REQUIRE(img.channels == 4 && img.data[0] > 0, "a lit Stokes pixel");
  double eta, k, Rs, Rp;
  REQUIRE(ior_conductor_eval(ior_conductor_lookup("Au"), 550.0, &eta, &k), "gold");
  vec3 h = v3_norm(v3_add(wo, wi));
  conductor_rs_rp(v3_dot(wo, h), eta, k, &Rs, &Rp);
  double dolp = fabs(Rs - Rp) / (Rs + Rp);
  vec3 x = v3_norm(v3_cross(v3(0, 0, 1), wi)), y = v3_cross(wi, x), e = v3_norm(v3_cross(wo, wi));
  double chi = atan2(v3_dot(e, y), v3_dot(e, x)), sgn = Rs > Rp ? 1.0 : -1.0;
  double S0 = img.data[0];
  CHECK_ABS(img.data[1] / S0, sgn * dolp * cos(2.0 * chi), 2e-6);
  CHECK_ABS(img.data[2] / S0, sgn * dolp * sin(2.0 * chi), 2e-6);
  CHECK_ABS(img.data[3] / S0, 0.0, 1e-6);
  CHECK(fabs(sin(2.0 * chi)) > 0.2, "the geometry turns the basis (chi %g deg)", chi * 180 / RSW_PI);
  film_image_free(&img);
  scene_free(s);
}

/* Where nothing polarizes (a diffuse plate, a sun and a uniform sky), the
 * polarized render's S0 is the mono render, bitwise, and Q = U = V = 0. */
static void test_render_depolarizing_scene_is_mono(void) {
  const char *fmt =
      "{\"type\": \"scene\", \"integrator\": {\"type\": \"path\"},"
      " \"cam\": {\"type\": \"perspective\", \"fov\": 40,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [1, -2, 3], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 8},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 12, \"height\": 10, \"rfilter\": {\"type\": "
      "\"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0.3, 0.2, -1], \"irradiance\": 2},"
      " \"sky\": {\"type\": \"constant\", \"radiance\": 0.5},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.4}},"
      " \"ball\": {\"type\": \"sphere\", \"center\": [0.3, 0.2, 0.4], \"radius\": 0.4,"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.7}}}";
  scene *a = tsup_load(fmt, "mono"), *b = tsup_load(fmt, "mono_polarized");
  REQUIRE(a && b, "scenes");
  film_image ia, ib;
  REQUIRE(tsup_render(a, 0, 11, 2, &ia), "mono render");
  REQUIRE(tsup_render(b, 0, 11, 2, &ib), "polarized render");
  REQUIRE(ib.channels == 4 && ia.width == ib.width && ia.height == ib.height, "films");
  int diff = 0, pol = 0, lit = 0;
  for (int i = 0; i < ia.width * ia.height; i++) {
    float m = ia.data[i * ia.channels], p = ib.data[4 * i];
    if (memcmp(&m, &p, sizeof m) != 0) diff++;
    if (ib.data[4 * i + 1] != 0 || ib.data[4 * i + 2] != 0 || ib.data[4 * i + 3] != 0) pol++;
    lit += m > 0;
  }
  CHECK(diff == 0, "%d pixels: S0 differs from the mono render", diff);
  CHECK(pol == 0, "%d pixels carry polarization", pol);
  CHECK(lit == ia.width * ia.height, "every pixel lit (%d)", lit);
  film_image_free(&ia);
  film_image_free(&ib);
  scene_free(a);
  scene_free(b);
}

int main(void) {
  RSW_TEST_RUN(test_brewster_reflection_is_s_polarized);
  RSW_TEST_RUN(test_conductor_gold_against_fresnel);
  RSW_TEST_RUN(test_dielectric_transmission);
  RSW_TEST_RUN(test_total_internal_reflection_retards);
  RSW_TEST_RUN(test_every_matrix_is_passive);
  RSW_TEST_RUN(test_rough_and_layered);
  RSW_TEST_RUN(test_eo_surfaces);
  RSW_TEST_RUN(test_wrappers);
  RSW_TEST_RUN(test_render_brewster_glass);
  RSW_TEST_RUN(test_render_gold_plane);
  RSW_TEST_RUN(test_render_rough_gold_off_plane);
  RSW_TEST_RUN(test_render_depolarizing_scene_is_mono);
  RSW_TEST_END("test_fresnel_pol");
}
