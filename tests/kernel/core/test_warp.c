/* Tests of server/kernel/core/warp.c: Mitsuba's fixed test vectors
 * (docs/kernel-conventions.md#warps), inverse round trips on Mitsuba's 10 x 10
 * grid, the phi/theta representation about arbitrary axes, and a
 * chi-square goodness-of-fit test (tests/support/chi2.c) of every sampling
 * routine against its own pdf, plus a negative control showing the
 * chi-square test has power. */
#include <math.h>

#include "../../support/chi2.h"
#include "../../support/test.h"
#include "kernel/core/warp.h"

RSW_TEST_DEFINE_GLOBALS

#define SQRT1_2 0.70710678118654752440

static void check_v2(vec2 got, double x, double y, double tol, const char *what) {
  CHECK(fabs(got.x - x) <= tol && fabs(got.y - y) <= tol, "%s: got (%.17g, %.17g), want (%.17g, %.17g)", what,
        got.x, got.y, x, y);
}
static void check_v3(vec3 got, double x, double y, double z, double tol, const char *what) {
  CHECK(fabs(got.x - x) <= tol && fabs(got.y - y) <= tol && fabs(got.z - z) <= tol,
        "%s: got (%.17g, %.17g, %.17g), want (%.17g, %.17g, %.17g)", what, got.x, got.y, got.z, x, y, z);
}

/* --- the polynomial sine and cosine of warp.c --------------------------- */

/* The warps evaluate sin/cos by polynomials on a reduced range; against
 * the formulas written with libm they agree within 1e-15 (4.5 ulp of 1)
 * on a dense grid, both branches of the concentric map and all four
 * quarter turns of the polar maps included. Most of that is the
 * reference's own error: libm is handed 2 pi u rounded to double, up to
 * 4.4e-16 off for angles near 2 pi. */
static void test_trig_against_libm(void) {
  const double tol = 1e-15;
  double worst = 0.0;
  for (int i = 0; i <= 1000; i++)
    for (int j = 0; j <= 1000; j += 7) {
      vec2 u = v2(i / 1000.0, j / 1000.0);
      double a = 2.0 * u.x - 1.0, b = 2.0 * u.y - 1.0, r, phi;
      if (fabs(a) < fabs(b)) {
        r = b;
        phi = 0.5 * RSW_PI - 0.25 * RSW_PI * (a / b);
      } else {
        r = a;
        phi = a == 0.0 ? 0.0 : 0.25 * RSW_PI * (b / a);
      }
      vec2 p = warp_square_to_disk_concentric(u);
      worst = fmax(worst, fmax(fabs(p.x - r * cos(phi)), fabs(p.y - r * sin(phi))));
      double ang = 2.0 * RSW_PI * u.x;
      vec2 d = warp_square_to_uniform_disk(u);
      worst = fmax(worst, fmax(fabs(d.x - sqrt(u.y) * cos(ang)), fabs(d.y - sqrt(u.y) * sin(ang))));
      vec3 s = warp_square_to_uniform_sphere(u);
      double z = 1.0 - 2.0 * u.y, rs = sqrt(fmax(0.0, 1.0 - z * z));
      worst = fmax(worst, fmax(fabs(s.x - rs * cos(ang)), fabs(s.y - rs * sin(ang))));
    }
  CHECK(worst <= tol, "warps vs libm sin/cos: max abs difference %g > %g", worst, tol);
}

/* --- fixed vectors ------------------------------------------------------ */

static void test_fixed_vectors(void) {
  const double t = 1e-12;
  /* Mitsuba test_warp.py values. */
  check_v2(warp_square_to_disk_concentric(v2(0, 0)), -SQRT1_2, -SQRT1_2, t, "concentric(0,0)");
  check_v2(warp_square_to_disk_concentric(v2(0.5, 0.5)), 0, 0, t, "concentric(.5,.5)");
  check_v3(warp_square_to_uniform_hemisphere(v2(0.5, 0.5)), 0, 0, 1, t, "hemisphere(.5,.5)");
  check_v3(warp_square_to_uniform_hemisphere(v2(0, 0.5)), -1, 0, 0, t, "hemisphere(0,.5)");
  check_v3(warp_square_to_cosine_hemisphere(v2(0.5, 0.5)), 0, 0, 1, t, "cosine(.5,.5)");
  check_v3(warp_square_to_cosine_hemisphere(v2(0.5, 0)), 0, -1, 0, t, "cosine(.5,0)");
  /* Values that follow from the formulas of docs/kernel-conventions.md#warps. */
  check_v2(warp_square_to_disk_concentric(v2(1, 0.5)), 1, 0, t, "concentric(1,.5)");
  check_v2(warp_square_to_disk_concentric(v2(0.5, 1)), 0, 1, t, "concentric(.5,1)");
  check_v2(warp_disk_to_square_concentric(v2(-SQRT1_2, -SQRT1_2)), 0, 0, t, "concentric^-1");
  check_v2(warp_disk_to_square_concentric(v2(0, 0)), 0.5, 0.5, t, "concentric^-1(0)");
  check_v2(warp_square_to_uniform_disk(v2(0.25, 1)), 0, 1, t, "polar disk(.25,1)");
  check_v2(warp_square_to_uniform_disk(v2(0.5, 0.25)), -0.5, 0, t, "polar disk(.5,.25)");
  check_v3(warp_square_to_uniform_sphere(v2(0, 0)), 0, 0, 1, t, "sphere(0,0)");
  check_v3(warp_square_to_uniform_sphere(v2(0.25, 0.5)), 0, 1, 0, t, "sphere(.25,.5)");
  check_v3(warp_square_to_uniform_sphere(v2(0.7, 1)), 0, 0, -1, t, "sphere(.7,1)");
  /* Cosine power: cos theta = u.y^(1/(n+1)): u.y = 1/8, n = 2 -> 1/2. */
  check_v3(warp_square_to_cosine_power_hemisphere(v2(0, 0.125), 2), sqrt(0.75), 0, 0.5, t, "cospow(0,1/8;2)");
  check_v3(warp_square_to_cosine_power_hemisphere(v2(0.3, 1), 7), 0, 0, 1, t, "cospow pole");
  /* Cone: the centre is the pole, the edge of the disk the rim z = c. */
  check_v3(warp_square_to_uniform_cone(v2(0.5, 0.5), 0.3), 0, 0, 1, t, "cone centre");
  check_v3(warp_square_to_uniform_cone(v2(1, 0.5), 0.3), sqrt(1 - 0.09), 0, 0.3, t, "cone rim");
  /* Castle convention about +z: phi = 0 at +x, phi = pi/2 at +y. */
  check_v3(warp_phi_theta_to_xyz(v2(0, RSW_PI / 2), v3(0, 0, 1)), 1, 0, 0, t, "phi 0");
  check_v3(warp_phi_theta_to_xyz(v2(RSW_PI / 2, RSW_PI / 2), v3(0, 0, 1)), 0, 1, 0, t, "phi pi/2");
  check_v3(warp_phi_theta_to_xyz(v2(1.3, 0), v3(0, 0, 2)), 0, 0, 2, t, "theta 0, radius 2");
  check_v3(warp_phi_theta_to_xyz(v2(0.4, RSW_PI), v3(0, 3, 0)), 0, -3, 0, t, "theta pi");
}

static void test_pdf_values_and_domains(void) {
  const double t = 1e-15;
  vec3 up = v3(0, 0, 1), down = v3(0, 0, -1);
  vec3 tilt = v3(sqrt(1 - 0.25), 0, 0.5);
  CHECK_ABS(warp_square_to_disk_concentric_pdf(v2(0.3, -0.4)), RSW_INV_PI, t);
  CHECK(warp_square_to_disk_concentric_pdf(v2(0.8, 0.7)) == 0, "outside the disk");
  CHECK_ABS(warp_square_to_uniform_disk_pdf(v2(0, 1)), RSW_INV_PI, t);
  CHECK(warp_square_to_uniform_disk_pdf(v2(1.01, 0)) == 0, "outside the disk");
  CHECK_ABS(warp_square_to_uniform_hemisphere_pdf(tilt), RSW_INV_2PI, t);
  CHECK(warp_square_to_uniform_hemisphere_pdf(down) == 0, "lower hemisphere");
  CHECK(warp_square_to_uniform_hemisphere_pdf(v3(0, 0, 1.1)) == 0, "not unit");
  CHECK_ABS(warp_square_to_cosine_hemisphere_pdf(tilt), 0.5 * RSW_INV_PI, t);
  CHECK(warp_square_to_cosine_hemisphere_pdf(down) == 0, "lower hemisphere");
  CHECK(warp_square_to_cosine_hemisphere_pdf(v3(0, 0, 0.5)) == 0, "not unit");
  /* (n+1) cos^n / (2 pi): n = 3 at cos 1/2 -> 4/8/(2 pi). */
  CHECK_ABS(warp_square_to_cosine_power_hemisphere_pdf(tilt, 3), 0.5 * RSW_INV_2PI, t);
  CHECK_ABS(warp_square_to_cosine_power_hemisphere_pdf(up, 0), RSW_INV_2PI, t);
  CHECK(warp_square_to_cosine_power_hemisphere_pdf(down, 2) == 0, "lower hemisphere");
  CHECK(warp_square_to_cosine_power_hemisphere_pdf(v3(0, 0, 2), 2) == 0, "not unit");
  CHECK_ABS(warp_square_to_uniform_sphere_pdf(down), RSW_INV_4PI, t);
  CHECK(warp_square_to_uniform_sphere_pdf(v3(0, 0, 0)) == 0, "not unit");
  CHECK_ABS(warp_square_to_uniform_cone_pdf(tilt, 0.4), RSW_INV_2PI / 0.6, t);
  CHECK(warp_square_to_uniform_cone_pdf(tilt, 0.6) == 0, "outside the cone");
  CHECK(warp_square_to_uniform_cone_pdf(v3(0, 0, 0.9), 0.4) == 0, "not unit");
}

/* --- inverse round trips ------------------------------------------------ */

/* Mitsuba test_warp.py: 10 x 10 grid in [1e-6, 1 - 1e-6]^2, atol 1e-5. */
#define GRID    10
#define RT_ATOL 1e-5

static vec2 grid_point(int i, int j) {
  const double lo = 1e-6, span = 1.0 - 2e-6;
  return v2(lo + span * i / (GRID - 1), lo + span * j / (GRID - 1));
}

static void check_round_trip(vec2 u, vec2 back, const char *what) {
  CHECK(fabs(back.x - u.x) <= RT_ATOL && fabs(back.y - u.y) <= RT_ATOL, "%s: (%.9g, %.9g) -> (%.9g, %.9g)",
        what, u.x, u.y, back.x, back.y);
}

/* A sampled direction must be unit and have a positive pdf. */
static void check_sampled_dir(vec3 v, double pdf, const char *what) {
  CHECK(fabs(v3_len(v) - 1.0) <= 1e-12, "%s: |v| = %.17g", what, v3_len(v));
  CHECK(pdf > 0.0, "%s: pdf %g at a sampled direction (%g, %g, %g)", what, pdf, v.x, v.y, v.z);
}

static void test_round_trips_planar_and_fixed(void) {
  for (int i = 0; i < GRID; i++)
    for (int j = 0; j < GRID; j++) {
      vec2 u = grid_point(i, j);
      vec2 p = warp_square_to_disk_concentric(u);
      CHECK(warp_square_to_disk_concentric_pdf(p) > 0, "concentric sample in disk");
      check_round_trip(u, warp_disk_to_square_concentric(p), "concentric");
      p = warp_square_to_uniform_disk(u);
      CHECK(warp_square_to_uniform_disk_pdf(p) > 0, "polar sample in disk");
      check_round_trip(u, warp_uniform_disk_to_square(p), "polar disk");
      vec3 v = warp_square_to_uniform_hemisphere(u);
      check_sampled_dir(v, warp_square_to_uniform_hemisphere_pdf(v), "uniform hemisphere");
      check_round_trip(u, warp_uniform_hemisphere_to_square(v), "uniform hemisphere");
      v = warp_square_to_cosine_hemisphere(u);
      check_sampled_dir(v, warp_square_to_cosine_hemisphere_pdf(v), "cosine hemisphere");
      check_round_trip(u, warp_cosine_hemisphere_to_square(v), "cosine hemisphere");
      v = warp_square_to_uniform_sphere(u);
      check_sampled_dir(v, warp_square_to_uniform_sphere_pdf(v), "uniform sphere");
      check_round_trip(u, warp_uniform_sphere_to_square(v), "uniform sphere");
    }
}

static void test_round_trips_parametric(void) {
  const double ns[] = {0, 0.5, 1, 10, 100};
  const double cutoffs[] = {-0.5, 0, 0.1, 0.5, 0.99};
  char what[64];
  for (int i = 0; i < GRID; i++)
    for (int j = 0; j < GRID; j++) {
      vec2 u = grid_point(i, j);
      for (size_t k = 0; k < sizeof ns / sizeof ns[0]; k++) {
        snprintf(what, sizeof what, "cosine power n=%g", ns[k]);
        vec3 v = warp_square_to_cosine_power_hemisphere(u, ns[k]);
        check_sampled_dir(v, warp_square_to_cosine_power_hemisphere_pdf(v, ns[k]), what);
        check_round_trip(u, warp_cosine_power_hemisphere_to_square(v, ns[k]), what);
      }
      for (size_t k = 0; k < sizeof cutoffs / sizeof cutoffs[0]; k++) {
        snprintf(what, sizeof what, "cone cos_cutoff=%g", cutoffs[k]);
        vec3 v = warp_square_to_uniform_cone(u, cutoffs[k]);
        check_sampled_dir(v, warp_square_to_uniform_cone_pdf(v, cutoffs[k]), what);
        check_round_trip(u, warp_uniform_cone_to_square(v, cutoffs[k]), what);
      }
    }
  /* cos_cutoff = 0 is the uniform hemisphere, point for point. */
  vec2 u = v2(0.3, 0.8);
  vec3 a = warp_square_to_uniform_cone(u, 0.0), b = warp_square_to_uniform_hemisphere(u);
  check_v3(a, b.x, b.y, b.z, 1e-15, "cone(c=0) = hemisphere");
}

/* --- phi / theta -------------------------------------------------------- */

static void test_phi_theta_round_trips(void) {
  const vec3 axes[] = {v3(0, 0, 1), v3(0, 0, -1), v3(1, 0, 0),       v3(0, -2, 0),
                       v3(1, 2, 3), v3(0, 0, -5), v3(-0.3, 0.1, -2), v3(1e-3, 0, -1)};
  for (size_t a = 0; a < sizeof axes / sizeof axes[0]; a++) {
    vec3 axis = axes[a];
    double radius = v3_len(axis);
    for (int i = 0; i < 12; i++)
      for (int j = 0; j <= 8; j++) {
        double phi = 2.0 * RSW_PI * i / 12.0 + 0.1, theta = RSW_PI * j / 8.0;
        vec3 v = warp_phi_theta_to_xyz(v2(phi, theta), axis);
        CHECK_ABS(v3_len(v), radius, 1e-12 * radius);
        /* theta is the angle from the axis. */
        CHECK_ABS(v3_dot(v, axis) / (radius * radius), cos(theta), 1e-12);
        vec2 back = warp_xyz_to_phi_theta(v, axis);
        CHECK_ABS(back.y, theta, 1e-12);
        CHECK(back.x >= 0.0 && back.x < 2.0 * RSW_PI, "phi %g in [0, 2 pi)", back.x);
        if (j > 0 && j < 8) { /* phi is undefined at the poles */
          double d = fmod(fabs(back.x - phi), 2.0 * RSW_PI);
          d = fmin(d, 2.0 * RSW_PI - d);
          CHECK(d <= 1e-12, "axis %zu: phi %.17g -> %.17g", a, phi, back.x);
        }
      }
  }
  /* The meridian depends on the axis direction only, not its length. */
  vec3 p1 = warp_phi_theta_to_xyz(v2(0.7, 1.1), v3(1, 2, 3));
  vec3 p2 = warp_phi_theta_to_xyz(v2(0.7, 1.1), v3(2, 4, 6));
  check_v3(v3_scale(p1, 2.0), p2.x, p2.y, p2.z, 1e-12, "radius scales only");
  /* About -z the frame is coordinate_system(-z) = ((1,0,0), (0,-1,0)). */
  check_v3(warp_phi_theta_to_xyz(v2(0, RSW_PI / 2), v3(0, 0, -1)), 1, 0, 0, 1e-12, "-z phi 0");
  check_v3(warp_phi_theta_to_xyz(v2(RSW_PI / 2, RSW_PI / 2), v3(0, 0, -1)), 0, -1, 0, 1e-12, "-z phi pi/2");
  /* A zero axis has no pole: zero vector, no NaN. */
  check_v3(warp_phi_theta_to_xyz(v2(1, 1), v3(0, 0, 0)), 0, 0, 0, 0, "zero axis");
}

/* --- chi-square --------------------------------------------------------- */

/* Every chi-square test below in one Sidak family: 2 disks, 2 hemispheres,
 * 4 cosine powers, 1 sphere, 3 cones. alpha = 0.01 for the family. */
#define CHI2_TESTS   12
/* 1e6 samples, as Mitsuba's default. */
#define CHI2_SAMPLES 1000000

static bool s_concentric(void *user, const double *u, vec3 *out, double *w) {
  vec2 p = warp_square_to_disk_concentric(v2(u[0], u[1]));
  *out = v3(p.x, p.y, 0);
  *w = 1;
  return true;
}
static double p_concentric(void *user, vec3 p) {
  return warp_square_to_disk_concentric_pdf(v2(p.x, p.y));
}
static bool s_polar(void *user, const double *u, vec3 *out, double *w) {
  vec2 p = warp_square_to_uniform_disk(v2(u[0], u[1]));
  *out = v3(p.x, p.y, 0);
  *w = 1;
  return true;
}
static double p_polar(void *user, vec3 p) {
  return warp_square_to_uniform_disk_pdf(v2(p.x, p.y));
}
static bool s_uniform_hemi(void *user, const double *u, vec3 *out, double *w) {
  *out = warp_square_to_uniform_hemisphere(v2(u[0], u[1]));
  *w = 1;
  return true;
}
static double p_uniform_hemi(void *user, vec3 v) {
  return warp_square_to_uniform_hemisphere_pdf(v);
}
static bool s_cosine_hemi(void *user, const double *u, vec3 *out, double *w) {
  *out = warp_square_to_cosine_hemisphere(v2(u[0], u[1]));
  *w = 1;
  return true;
}
static double p_cosine_hemi(void *user, vec3 v) {
  return warp_square_to_cosine_hemisphere_pdf(v);
}
static bool s_cosine_power(void *user, const double *u, vec3 *out, double *w) {
  *out = warp_square_to_cosine_power_hemisphere(v2(u[0], u[1]), *(const double *)user);
  *w = 1;
  return true;
}
static double p_cosine_power(void *user, vec3 v) {
  return warp_square_to_cosine_power_hemisphere_pdf(v, *(const double *)user);
}
static bool s_sphere(void *user, const double *u, vec3 *out, double *w) {
  *out = warp_square_to_uniform_sphere(v2(u[0], u[1]));
  *w = 1;
  return true;
}
static double p_sphere(void *user, vec3 v) {
  return warp_square_to_uniform_sphere_pdf(v);
}
static bool s_cone(void *user, const double *u, vec3 *out, double *w) {
  *out = warp_square_to_uniform_cone(v2(u[0], u[1]), *(const double *)user);
  *w = 1;
  return true;
}
static double p_cone(void *user, vec3 v) {
  return warp_square_to_uniform_cone_pdf(v, *(const double *)user);
}

static chi2_config family_config(chi2_domain d) {
  chi2_config c = chi2_defaults(d, 2);
  c.sample_count = CHI2_SAMPLES;
  c.test_count = CHI2_TESTS;
  return c;
}

static void run_chi2(const char *what, const chi2_config *c, chi2_sample_fn s, chi2_pdf_fn p, void *user) {
  chi2_result r = chi2_run(c, s, p, user);
  CHECK(r.passed, "%s: %s (chi2 %g, dof %d, p %g)", what, r.reason, r.chi2, r.dof, r.p_value);
}

static void test_chi2_disks(void) {
  chi2_config c = family_config(CHI2_DISK);
  run_chi2("concentric disk", &c, s_concentric, p_concentric, NULL);
  run_chi2("polar disk", &c, s_polar, p_polar, NULL);
}

static void test_chi2_hemispheres_and_sphere(void) {
  chi2_config c = family_config(CHI2_SPHERE);
  run_chi2("uniform hemisphere", &c, s_uniform_hemi, p_uniform_hemi, NULL);
  run_chi2("cosine hemisphere", &c, s_cosine_hemi, p_cosine_hemi, NULL);
  run_chi2("uniform sphere", &c, s_sphere, p_sphere, NULL);
}

static void test_chi2_cosine_power(void) {
  double ns[] = {0, 1, 10, 100};
  char what[64];
  for (size_t k = 0; k < sizeof ns / sizeof ns[0]; k++) {
    chi2_config c = family_config(CHI2_SPHERE);
    /* For n = 100, 87% of the mass lies in the top row of cells
     * (cos theta > 0.98) where cos^100 falls by e^-2: Mitsuba's 4-point
     * trapezoid rule is off by ~4% there, which 1e6 samples resolve. 16
     * points per axis bring the error to ~0.15%. */
    c.ires = 16;
    snprintf(what, sizeof what, "cosine power n=%g", ns[k]);
    run_chi2(what, &c, s_cosine_power, p_cosine_power, &ns[k]);
  }
}

static void test_chi2_cones(void) {
  double cutoffs[] = {0.1, 0.5, 0.99};
  char what[64];
  for (size_t k = 0; k < sizeof cutoffs / sizeof cutoffs[0]; k++) {
    chi2_config c = family_config(CHI2_SPHERE);
    /* The cone pdf jumps at cos theta = c. A trapezoid rule cannot integrate
     * a jump inside a cell, so res = 100 puts it where the rule is exact:
     * rows are 0.02 high in cos theta, so c = 0.1 and 0.5 fall on row
     * edges, and c = 0.99 at the middle of the top row, which the
     * symmetric 4-point rule splits exactly in half (as res = 101 does for
     * the equator). With res = 101 these tests fail for the integration
     * error alone. */
    c.res = 100;
    snprintf(what, sizeof what, "cone cos_cutoff=%g", cutoffs[k]);
    run_chi2(what, &c, s_cone, p_cone, &cutoffs[k]);
  }
}

/* Negative control: cosine-weighted samples tested against the uniform
 * hemisphere density must be rejected, or the test above proves nothing. */
static void test_chi2_has_power(void) {
  chi2_config c = family_config(CHI2_SPHERE);
  chi2_result r = chi2_run(&c, s_cosine_hemi, p_uniform_hemi, NULL);
  CHECK(!r.passed, "cosine samples accepted as uniform (p = %g)", r.p_value);
  CHECK(r.p_value < 1e-12, "p = %g", r.p_value);
}

int main(void) {
  RSW_TEST_RUN(test_trig_against_libm);
  RSW_TEST_RUN(test_fixed_vectors);
  RSW_TEST_RUN(test_pdf_values_and_domains);
  RSW_TEST_RUN(test_round_trips_planar_and_fixed);
  RSW_TEST_RUN(test_round_trips_parametric);
  RSW_TEST_RUN(test_phi_theta_round_trips);
  RSW_TEST_RUN(test_chi2_disks);
  RSW_TEST_RUN(test_chi2_hemispheres_and_sphere);
  RSW_TEST_RUN(test_chi2_cosine_power);
  RSW_TEST_RUN(test_chi2_cones);
  RSW_TEST_RUN(test_chi2_has_power);
  RSW_TEST_END("test_warp");
}
