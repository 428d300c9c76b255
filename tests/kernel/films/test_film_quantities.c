/* Film planes beyond radiance (render.h): BRDF, BRF and the per-pixel
 * standard error of the mean.
 *  - A Lambertian plate under directional emitters has BRF rho and BRDF
 *    rho / pi in every pixel (a zero-variance scene: 1e-5), in mono and in
 *    rgb, with E_h = E cos(theta_s); its radiance_stderr is exactly 0 (a
 *    constant film). With two emitters E_h is the sum, and the film-mean
 *    BRF is rho within 3 standard errors.
 *  - An RPV plate seen by hdistant: each pixel's BRF is the mean of
 *    pi f_r over the pixel's solid angle (the concentric map preserves
 *    area), computed by a 128x128 midpoint rule per pixel (k = 0.9 keeps the
 *    Minnaert factor's horizon singularity mild enough for it); the film's BRF
 *    agrees within 3 of its own standard errors (pi stderr / E_h), as the
 *    film-wide mean and in at least 99 % of the pixels.
 *  - Over 200 seeds, the spread of each pixel's mean is what its stderr
 *    predicts: sum over seeds and pixels of (m - mean m)^2 / stderr^2 is
 *    chi-square with 16 x 199 degrees of freedom (accepted inside the
 *    0.1 % and 99.9 % quantiles, Wilson-Hilferty).
 *  - The stderr, like the film, does not depend on the thread count.
 *  - Refusals name their field: variance with a splatting filter or one
 *    sample per pixel; brf without a directional emitter or with the sun
 *    below the horizon. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/core/warp.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

static bool render_q(scene *s, uint32_t spp, uint64_t seed, int threads, unsigned q, bool variance,
                     film_image *out, rsw_err *err) {
  render_opts o = {.size = sizeof o,
                   .spp = spp,
                   .seed = seed,
                   .threads = threads,
                   .wavelength = 550,
                   .quantities = q,
                   .variance = variance};
  return render_sensor(s, &o, out, NULL, err) == RSW_OK;
}

/* A plate of reflectance rho under a sun of irradiance e1 (30 degrees
 * from the zenith) and, when e2 is not NULL, a second directional emitter
 * e2 (36.9 degrees). */
static scene *lambertian_plate(const char *variant, const char *rho, const char *e1, const char *e2) {
  char buf[4096], moon[256] = "";
  if (e2)
    snprintf(moon, sizeof moon,
             " \"moon\": {\"type\": \"directional\", \"direction\": [0, -0.6, -0.8], \"irradiance\": %s},",
             e2);
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\", \"variant\": \"%s\","
      " \"sensor\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 8},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 12, \"height\": 10, \"component_format\": \"float32\","
      "     \"rfilter\": {\"type\": \"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0, -0.8660254037844386],"
      "   \"irradiance\": %s},%s"
      " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": %s}}}",
      variant, e1, moon, rho);
  return tsup_load(buf, NULL);
}

/* One sun: every sample of every pixel is the same number, so BRF = rho
 * and BRDF = rho / pi to float precision and the stderr is exactly 0. */
static void check_plate(const char *variant, const char *rho_json, const double *rho, const double *e1) {
  scene *s = lambertian_plate(variant, rho_json, variant[0] == 'm' ? "1.7" : "[1.7, 1.2, 0.9]", NULL);
  REQUIRE(s, "%s plate", variant);
  film_image img;
  rsw_err err = {0};
  REQUIRE(render_q(s, 0, 7, 2, RENDER_Q_BRF | RENDER_Q_BRDF, true, &img, &err), "%s render: %s", variant,
          err.msg);
  REQUIRE(img.n_planes == 3, "%s: %d planes, want brdf, brf, radiance_stderr", variant, img.n_planes);
  CHECK(strcmp(img.planes[0].name, "brdf") == 0 && strcmp(img.planes[1].name, "brf") == 0 &&
            strcmp(img.planes[2].name, "radiance_stderr") == 0,
        "%s: plane order", variant);
  CHECK(strcmp(img.planes[1].units, "1") == 0 && strcmp(img.planes[0].units, "sr-1") == 0, "%s: units",
        variant);
  CHECK(img.has_irradiance, "%s: irradiance recorded", variant);
  const film_plane *brf = film_image_plane(&img, "brf"), *brdf = film_image_plane(&img, "brdf");
  const film_plane *se = film_image_plane(&img, "radiance_stderr");
  REQUIRE(brf && brdf && se, "planes by name");
  double worst = 0, worst_se = 0;
  size_t px = (size_t)img.width * img.height;
  for (int c = 0; c < img.channels; c++) {
    double eh = e1[c] * 0.8660254037844386;
    CHECK(fabs(img.irradiance[c] - eh) <= 1e-12 * eh, "%s: E_h[%d] %.17g, want %.17g", variant, c,
          img.irradiance[c], eh);
    for (size_t i = 0; i < px; i++) {
      size_t q = i * (size_t)img.channels + (size_t)c;
      worst = fmax(worst, fabs(brf->data[q] - rho[c]) / rho[c]);
      worst = fmax(worst, fabs(brdf->data[q] * PI - rho[c]) / rho[c]);
      worst_se = fmax(worst_se, fabs(se->data[q]));
    }
  }
  CHECK(worst <= 1e-5, "%s: BRF / BRDF off rho by %.3g (relative), want <= 1e-5", variant, worst);
  CHECK(worst_se == 0, "%s: stderr of a constant film is %.3g, want exactly 0", variant, worst_se);
  film_image_free(&img);
  scene_free(s);
}

/* Two directional emitters: E_h is the sum of E cos(theta_s), and since
 * next-event estimation picks one emitter per sample the film is noisy:
 * the film-mean BRF is rho within 3 of the standard errors the film
 * carries. */
static void test_two_emitters_add(void) {
  scene *s = lambertian_plate("mono", "0.3", "1.7", "0.4");
  REQUIRE(s, "plate");
  film_image img;
  rsw_err err = {0};
  REQUIRE(render_q(s, 64, 5, 2, RENDER_Q_BRF, true, &img, &err), "render: %s", err.msg);
  double eh = 1.7 * 0.8660254037844386 + 0.4 * 0.8;
  CHECK(fabs(img.irradiance[0] - eh) <= 1e-12 * eh, "E_h %.17g, want %.17g", img.irradiance[0], eh);
  const film_plane *brf = film_image_plane(&img, "brf"), *se = film_image_plane(&img, "radiance_stderr");
  REQUIRE(brf && se, "planes");
  size_t px = (size_t)img.width * img.height;
  double sum = 0, var = 0;
  for (size_t i = 0; i < px; i++) {
    sum += brf->data[i];
    double sg = PI * se->data[i] / eh;
    var += sg * sg;
  }
  double z = (sum / px - 0.3) / (sqrt(var) / px);
  CHECK(fabs(z) <= 3, "film-mean BRF %.6g off 0.3 by %.2f standard errors", sum / px, z);
  CHECK(var > 0, "a noisy film with zero stderr");
  film_image_free(&img);
  scene_free(s);
}

static void test_lambertian_brf_mono(void) {
  double rho[1] = {0.3}, e1[1] = {1.7};
  check_plate("mono", "0.3", rho, e1);
}

static void test_lambertian_brf_rgb(void) {
  double rho[3] = {0.2, 0.4, 0.6}, e1[3] = {1.7, 1.2, 0.9};
  check_plate("rgb", "[0.2, 0.4, 0.6]", rho, e1);
}

/* ---- RPV ------------------------------------------------------------------------ */

static const double RHO0 = 0.12, K = 0.9, G = -0.25, RHOC = 0.3;
static const double SUN[3] = {-0.4, 0.3, -0.8660254037844386}; /* travel direction, normalised below */

/* pi f_r of RPV (docs/kernel-conventions.md#rpv) for unit wi, wo above the plate
 * (normal +z). */
static double rpv_brf(const double *wi, const double *wo) {
  double ci = wi[2], co = wo[2];
  double si = sqrt(fmax(0, 1 - ci * ci)), so = sqrt(fmax(0, 1 - co * co));
  double cdphi = si > 0 && so > 0 ? (wi[0] * wo[0] + wi[1] * wo[1]) / (si * so) : 1;
  double cT = ci * co + si * so * cdphi;
  double F = (1 - G * G) / pow(1 + G * G + 2 * G * cT, 1.5);
  double ti = si / ci, to = so / co;
  double Gg = sqrt(fmax(0, ti * ti + to * to - 2 * ti * to * cdphi));
  double H = 1 + (1 - RHOC) / (1 + Gg);
  double M = pow(ci * co * (ci + co), K - 1);
  return RHO0 * M * F * H;
}

static scene *rpv_plate(int w, int h, int spp) {
  char buf[4096];
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"sensor\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": %d},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": %d, \"height\": %d, \"component_format\": \"float32\","
      "     \"rfilter\": {\"type\": \"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [%.17g, %.17g, %.17g], \"irradiance\": 2.5},"
      " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"
      "   \"bsdf\": {\"type\": \"rpv\", \"rho_0\": %g, \"k\": %g, \"g\": %g, \"rho_c\": %g}}}",
      spp, w, h, SUN[0], SUN[1], SUN[2], RHO0, K, G, RHOC);
  return tsup_load(buf, NULL);
}

static void test_rpv_brf_3sigma(void) {
  const int W = 8, H = 8, N = 128;
  scene *s = rpv_plate(W, H, 256);
  REQUIRE(s, "rpv scene");
  film_image img;
  rsw_err err = {0};
  REQUIRE(render_q(s, 0, 11, 2, RENDER_Q_BRF, true, &img, &err), "render: %s", err.msg);
  const film_plane *brf = film_image_plane(&img, "brf"), *se = film_image_plane(&img, "radiance_stderr");
  REQUIRE(brf && se && !film_image_plane(&img, "brdf"), "planes brf and radiance_stderr only");
  double n = sqrt(SUN[0] * SUN[0] + SUN[1] * SUN[1] + SUN[2] * SUN[2]);
  double wi[3] = {-SUN[0] / n, -SUN[1] / n, -SUN[2] / n};
  double eh = 2.5 * wi[2];
  CHECK(fabs(img.irradiance[0] - eh) < 1e-12, "E_h %.17g, want %.17g", img.irradiance[0], eh);
  double sum_d = 0, sum_var = 0;
  int outside = 0;
  for (int iy = 0; iy < H; iy++)
    for (int ix = 0; ix < W; ix++) {
      double expect = 0;
      for (int b = 0; b < N; b++)
        for (int a = 0; a < N; a++) {
          vec3 v = warp_square_to_uniform_hemisphere(v2((ix + (a + 0.5) / N) / W, (iy + (b + 0.5) / N) / H));
          double wo[3] = {v.x, v.y, v.z};
          expect += rpv_brf(wi, wo);
        }
      expect /= N * N;
      size_t q = (size_t)iy * W + ix;
      double sigma = PI * se->data[q] / eh;
      double d = brf->data[q] - expect;
      sum_d += d;
      sum_var += sigma * sigma;
      if (fabs(d) > 3 * sigma) outside++;
      CHECK(sigma > 0, "pixel (%d, %d): stderr 0 in a noisy pixel", ix, iy);
    }
  double z = sum_d / sqrt(sum_var);
  CHECK(fabs(z) <= 3, "film-mean BRF off its closed form by %.2f standard errors", z);
  CHECK(outside <= W * H / 100 + 1, "%d of %d pixels off their closed form by more than 3 sigma", outside,
        W * H);
  printf("  rpv: film-mean z = %.3f, %d/%d pixels beyond 3 sigma\n", z, outside, W * H);
  film_image_free(&img);
  scene_free(s);
}

/* Wilson-Hilferty: the chi-square(k) quantile at standard normal z. */
static double chi2_quantile(double k, double z) {
  double a = 2 / (9 * k);
  return k * pow(1 - a + z * sqrt(a), 3);
}

static void test_stderr_predicts_spread(void) {
  enum {
    W = 4,
    H = 4,
    SEEDS = 200
  };
  scene *s = rpv_plate(W, H, 16);
  REQUIRE(s, "rpv scene");
  static double mean[SEEDS][W * H], se2[SEEDS][W * H];
  for (int k = 0; k < SEEDS; k++) {
    film_image img;
    rsw_err err = {0};
    REQUIRE(render_q(s, 0, 1000 + (uint64_t)k, 1, 0, true, &img, &err), "seed %d: %s", k, err.msg);
    const film_plane *se = film_image_plane(&img, "radiance_stderr");
    REQUIRE(se, "stderr plane");
    for (int i = 0; i < W * H; i++) {
      mean[k][i] = img.data[i];
      se2[k][i] = (double)se->data[i] * se->data[i];
    }
    film_image_free(&img);
  }
  double chi2 = 0;
  for (int i = 0; i < W * H; i++) {
    double m = 0, v = 0;
    for (int k = 0; k < SEEDS; k++) m += mean[k][i], v += se2[k][i];
    m /= SEEDS, v /= SEEDS;
    for (int k = 0; k < SEEDS; k++) chi2 += (mean[k][i] - m) * (mean[k][i] - m) / v;
  }
  double dof = (double)W * H * (SEEDS - 1);
  double lo = chi2_quantile(dof, -3.0902), hi = chi2_quantile(dof, 3.0902);
  printf("  chi2 = %.1f for %.0f degrees of freedom (accepted in [%.1f, %.1f])\n", chi2, dof, lo, hi);
  CHECK(chi2 >= lo && chi2 <= hi, "chi2 %.1f outside [%.1f, %.1f]: stderr does not predict the spread", chi2,
        lo, hi);
  scene_free(s);
}

static void test_stderr_deterministic(void) {
  scene *s = rpv_plate(20, 13, 9);
  REQUIRE(s, "rpv scene");
  film_image a, b;
  rsw_err err = {0};
  REQUIRE(render_q(s, 0, 3, 1, RENDER_Q_BRF, true, &a, &err), "1 thread: %s", err.msg);
  REQUIRE(render_q(s, 0, 3, 4, RENDER_Q_BRF, true, &b, &err), "4 threads: %s", err.msg);
  size_t n = (size_t)a.width * a.height * a.channels;
  CHECK(memcmp(a.data, b.data, n * sizeof(float)) == 0, "radiance differs between 1 and 4 threads");
  for (int p = 0; p < a.n_planes; p++)
    CHECK(memcmp(a.planes[p].data, b.planes[p].data, n * sizeof(float)) == 0,
          "%s differs between 1 and 4 threads", a.planes[p].name);
  /* Asking for planes leaves the radiance bitwise as it was. */
  film_image c;
  REQUIRE(render_q(s, 0, 3, 2, 0, false, &c, &err), "plain: %s", err.msg);
  CHECK(c.n_planes == 0 && memcmp(a.data, c.data, n * sizeof(float)) == 0,
        "radiance changes when planes are asked for");
  film_image_free(&a);
  film_image_free(&b);
  film_image_free(&c);
  scene_free(s);
}

static void expect_refusal(scene *s, uint32_t spp, unsigned q, bool variance, const char *where,
                           const char *words) {
  film_image img;
  rsw_err err = {0};
  bool ok = render_q(s, spp, 0, 1, q, variance, &img, &err);
  if (ok) film_image_free(&img);
  CHECK(!ok && err.code == RSW_ERR_INVALID && strcmp(err.where, where) == 0 && strstr(err.msg, words),
        "want a refusal at '%s' saying '%s'; got %s at '%s': %s", where, words, ok ? "success" : "an error",
        err.where, err.msg);
}

static void test_refusals(void) {
  scene *g = tsup_load("{\"type\": \"scene\", \"variant\": \"mono\","
                       " \"sensor\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
                       "   \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4}},"
                       " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, 1]},"
                       " \"plate\": {\"type\": \"rectangle\"}}",
                       NULL);
  REQUIRE(g, "scene");
  expect_refusal(g, 4, 0, true, "variance", "box rfilter");
  expect_refusal(g, 4, RENDER_Q_BRF, false, "quantities", "below the horizon");
  scene_free(g);
  scene *e = tsup_load("{\"type\": \"scene\", \"variant\": \"mono\","
                       " \"sensor\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
                       "   \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4,"
                       "     \"rfilter\": {\"type\": \"box\"}}},"
                       " \"sky\": {\"type\": \"constant\"},"
                       " \"plate\": {\"type\": \"rectangle\"}}",
                       NULL);
  REQUIRE(e, "scene");
  expect_refusal(e, 1, 0, true, "variance", "at least 2 samples");
  expect_refusal(e, 4, RENDER_Q_BRDF, false, "quantities", "has none");
  scene_free(e);
}

int main(void) {
  RSW_TEST_RUN(test_lambertian_brf_mono);
  RSW_TEST_RUN(test_lambertian_brf_rgb);
  RSW_TEST_RUN(test_two_emitters_add);
  RSW_TEST_RUN(test_rpv_brf_3sigma);
  RSW_TEST_RUN(test_stderr_predicts_spread);
  RSW_TEST_RUN(test_stderr_deterministic);
  RSW_TEST_RUN(test_refusals);
  RSW_TEST_END("test_film_quantities");
}
