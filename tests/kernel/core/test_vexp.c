/* core/vexp.c (exp in vector lanes) and the gaussian filter's weights
 * built on it (films/filter_gaussian.c) against libm, at every ISA this
 * CPU runs (core/isa.h), generic included:
 *  - vexp_batch(x) is within 1 ulp of libm's exp(x) (in units of
 *    libm's value's last place) over the gaussian's whole domain [-8, 0]:
 *    2^20 points on a regular grid (0, -2^-17, ...) and 2^20 random doubles
 *    in it; over [-700, 700] (2^18 random), where the polynomial and the
 *    table meet every binade of the result; at the special values (signed
 *    zeros, the smallest subnormals, +-inf, NaN, |x| = 512 and next to it,
 *    where the batch hands over to libm, and the overflow and underflow
 *    edges). Where libm's exp is glibc's FMA variant (x86-64 with FMA and
 *    AVX2) the method is its, so the count of differing results printed
 *    is 0 there; the test asserts only the 1 ulp bound, which holds for
 *    any libm within 0.5 ulp of its own (glibc: 0.51);
 *  - every ISA gives the generic ISA's bits for every one of those
 *    arguments, in batches of every length 1..19 (partial lanes);
 *  - filter_gaussian_footprint equals max(0, exp(alpha t^2) - bias), with
 *    t = px - ((xlo + i) + 0.5) and the batch's exp, bit for bit, for
 *    footprints of 1 to 40 columns and rows (more than one chunk of 8
 *    lanes, partial chunks), random sample positions, at the default
 *    stddev and others; and through the libm hand-over (alpha so large
 *    that the arguments pass -512);
 *  - the gaussian rfilter's eval and its eval_footprint agree bit for bit
 *    with each other (a scene's film), and a footprint batch does not
 *    depend on the lanes beside a pixel (one column alone equals it in a
 *    footprint of 9);
 *  - a render whose only ISA-dependent step is the splat (a perspective
 *    camera, bitwise the same rays at every ISA, sees an emitting
 *    rectangle's edge; max_depth 1: emission only) gives the same film at
 *    every ISA: the gaussian's weights and render.c's sums, four doubles
 *    a pixel in one AVX vector at avx2 and avx512 and two pairs elsewhere,
 *    bit for bit; the film has pixels strictly between 0 and 1 (the
 *    filter's blur of the edge), so the weights matter to it.
 * Fixed seeds. */
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/core/isa.h"
#include "../../../server/kernel/core/vexp.h"
#include "../../../server/kernel/films/filter_gaussian.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static uint64_t bits(double x) {
  uint64_t b;
  memcpy(&b, &x, sizeof b);
  return b;
}

static uint64_t rng_state = 0x2545F4914F6CDD1Dull;
static uint64_t next_u64(void) { /* xorshift64* */
  rng_state ^= rng_state >> 12;
  rng_state ^= rng_state << 25;
  rng_state ^= rng_state >> 27;
  return rng_state * 0x2545F4914F6CDD1Dull;
}
static double next_unit(void) { /* [0, 1) on the 2^-53 grid */
  return (double)(next_u64() >> 11) * 0x1p-53;
}

/* |got - want| in units of the last place of want (a finite positive
 * want: exp's); equal NaNs and equal infinities 0. */
static double ulps(double got, double want) {
  if (isnan(want)) return isnan(got) ? 0 : INFINITY;
  if (got == want) return 0;
  if (isinf(want) || isinf(got)) return INFINITY;
  double up = nextafter(want, INFINITY) - want;
  if (want == 0) up = 0x1p-1074;
  return fabs(got - want) / up;
}

/* The arguments of the sweep (allocated; *n set). */
static double *sweep_args(int *n) {
  const int grid = 1 << 20, rnd = 1 << 20, wide = 1 << 18;
  const double special[] = {0.0,         -0.0,     0x1p-1074, -0x1p-1074, 0x1p-54, -0x1p-54, 0x1p-55,
                            -0x1p-55,    INFINITY, -INFINITY, NAN,        512.0,   -512.0,   511.999999,
                            -511.999999, 709.78,   709.79,    -708.39,    -708.4,  -745.1,   -745.2,
                            -8.0,        -2.0,     -0.5,      1e-300};
  int ns = (int)(sizeof special / sizeof special[0]);
  double *x = malloc(sizeof(double) * (size_t)(grid + rnd + wide + ns));
  if (!x) return NULL;
  int k = 0;
  for (int i = 0; i < grid; i++) x[k++] = -8.0 * i / grid;
  for (int i = 0; i < rnd; i++) x[k++] = -8.0 * next_unit();
  for (int i = 0; i < wide; i++) x[k++] = -700.0 + 1400.0 * next_unit();
  for (int i = 0; i < ns; i++) x[k++] = special[i];
  *n = k;
  return x;
}

static void test_exp_ulp(void) {
  int n;
  double *x = sweep_args(&n);
  REQUIRE(x, "memory");
  double *got = malloc(sizeof(double) * (size_t)n), *ref = malloc(sizeof(double) * (size_t)n);
  REQUIRE(got && ref, "memory");
  vexp_batch(RSW_ISA_GENERIC, n, x, ref);
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_supported((rsw_isa)isa)) continue;
    vexp_batch((rsw_isa)isa, n, x, got);
    double worst = 0, worst_x = 0;
    long differ = 0, not_generic = 0;
    for (int i = 0; i < n; i++) {
      double u = ulps(got[i], exp(x[i]));
      if (u > 0) differ++;
      if (u > worst) worst = u, worst_x = x[i];
      if (bits(got[i]) != bits(ref[i]) && !(isnan(got[i]) && isnan(ref[i]))) not_generic++;
    }
    printf("  %s: %d arguments, %ld differ from libm's exp, at most %.3g ulp (x = %.17g)\n",
           rsw_isa_name((rsw_isa)isa), n, differ, worst, worst_x);
    CHECK(worst <= 1.0, "%s: %.3g ulp from libm's exp at x = %.17g", rsw_isa_name((rsw_isa)isa), worst,
          worst_x);
    CHECK(not_generic == 0, "%s: %ld results differ from the generic ISA's", rsw_isa_name((rsw_isa)isa),
          not_generic);
  }
  /* Batches of every length 1..19 (the lanes past a partial chunk): the
   * same bits as the one long batch. */
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_supported((rsw_isa)isa)) continue;
    long bad = 0;
    for (int len = 1; len < 20; len++)
      for (int i0 = 0; i0 + len <= 4000; i0 += len) {
        int off = (2 << 20) - 2000 + i0; /* random [-8, 0] then [-700, 700] */
        vexp_batch((rsw_isa)isa, len, x + off, got);
        for (int k = 0; k < len; k++) bad += bits(got[k]) != bits(ref[off + k]);
      }
    CHECK(bad == 0, "%s: %ld results of short batches differ", rsw_isa_name((rsw_isa)isa), bad);
  }
  free(got);
  free(ref);
  free(x);
}

/* The footprint's weights as the definition gives them, each through a
 * batch of one (exp's bits: test_exp_ulp). */
static double weight_ref(double alpha, double bias, double t) {
  double a = alpha * t * t, e;
  vexp_batch(RSW_ISA_GENERIC, 1, &a, &e);
  double v = e - bias;
  return v > 0.0 ? v : 0.0;
}

static void test_footprints(void) {
  const double sigmas[] = {0.5, 0.25, 1.0, 3.7, 0.01};
  enum {
    NMAX = 80
  };
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_supported((rsw_isa)isa)) continue;
    long bad = 0, cases = 0;
    for (size_t si = 0; si < sizeof sigmas / sizeof sigmas[0]; si++) {
      double sigma = sigmas[si], alpha = -1.0 / (2.0 * sigma * sigma);
      double bias = exp(alpha * 16.0 * sigma * sigma);
      for (int nx = 1; nx <= 40; nx += (nx < 10 ? 1 : 7))
        for (int ny = 1; ny <= 40; ny += (ny < 10 ? 1 : 9)) {
          filter_footprint fp = {.px = 1000.0 * next_unit(),
                                 .py = 1000.0 * next_unit(),
                                 .alpha = alpha,
                                 .bias = bias,
                                 .nx = nx,
                                 .ny = ny};
          fp.xlo = (int)floor(fp.px) - nx / 2, fp.ylo = (int)floor(fp.py) - ny / 2;
          double out[NMAX];
          filter_gaussian_footprint((rsw_isa)isa, &fp, out);
          for (int i = 0; i < nx; i++)
            bad += bits(out[i]) != bits(weight_ref(alpha, bias, fp.px - ((fp.xlo + i) + 0.5)));
          for (int j = 0; j < ny; j++)
            bad += bits(out[nx + j]) != bits(weight_ref(alpha, bias, fp.py - ((fp.ylo + j) + 0.5)));
          cases++;
        }
    }
    CHECK(bad == 0, "%s: %ld footprint weights of %ld footprints differ from the definition",
          rsw_isa_name((rsw_isa)isa), bad, cases);
    /* The libm hand-over: alpha -1e4 puts the outer columns' arguments
     * past -512 (t >= 0.23), where the weight is exp(a) - bias <= 0: 0. */
    filter_footprint fp = {
        .px = 10.3, .py = 7.9, .xlo = 6, .nx = 9, .ylo = 5, .ny = 6, .alpha = -1e4, .bias = 0};
    double out[16];
    filter_gaussian_footprint((rsw_isa)isa, &fp, out);
    long bad_far = 0;
    for (int i = 0; i < 9; i++) {
      double t = fp.px - ((fp.xlo + i) + 0.5), want = exp(-1e4 * t * t);
      bad_far += bits(out[i]) != bits(weight_ref(-1e4, 0, t)) || ulps(out[i], want) > 1;
    }
    CHECK(bad_far == 0, "%s: %ld weights beyond the hand-over differ", rsw_isa_name((rsw_isa)isa), bad_far);
  }
}

static void test_rfilter_agrees(void) {
  scene *s =
      tsup_load("{\"type\": \"scene\", \"integrator\": {\"type\": \"path\"},"
                " \"sensor\": {\"type\": \"perspective\", \"film\": {\"type\": \"hdrfilm\","
                "   \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"gaussian\", \"stddev\": 0.7}}}}",
                "mono");
  REQUIRE(s, "scene");
  const rfilter *f = s->sensors[0]->film->filter;
  REQUIRE(f->eval_footprint, "the gaussian has eval_footprint");
  long bad = 0;
  for (int k = 0; k < 20000; k++) {
    double px = 64.0 * next_unit(), py = 64.0 * next_unit();
    int xlo = (int)ceil(px - f->radius - 0.5), ylo = (int)ceil(py - f->radius - 0.5);
    int nx = (int)floor(px + f->radius - 0.5) - xlo + 1, ny = (int)floor(py + f->radius - 0.5) - ylo + 1;
    double w[32], one;
    f->eval_footprint(f, px, xlo, nx, py, ylo, ny, w);
    for (int i = 0; i < nx; i++) bad += bits(w[i]) != bits(f->eval(f, px - ((xlo + i) + 0.5)));
    for (int j = 0; j < ny; j++) bad += bits(w[nx + j]) != bits(f->eval(f, py - ((ylo + j) + 0.5)));
    /* Column 3 alone (a footprint of one column and no rows). */
    f->eval_footprint(f, px, xlo + 3, 1, py, ylo, 0, &one);
    bad += bits(one) != bits(w[3]);
  }
  CHECK(bad == 0, "%ld weights of eval_footprint differ from eval's", bad);
  CHECK(fabs(f->eval(f, 0.0) - (1.0 - exp(-8.0))) < 1e-15, "gaussian(0) = 1 - exp(-8): %.17g",
        f->eval(f, 0.0));
  CHECK(f->eval(f, f->radius) == 0.0 && f->eval(f, -f->radius - 1) == 0.0, "0 at and beyond the radius");
  scene_free(s);
}

static void test_splat_isas(void) {
  scene *s = tsup_load("{\"type\": \"scene\", \"integrator\": {\"type\": \"path\", \"max_depth\": 1},"
                       " \"sensor\": {\"type\": \"perspective\", \"fov\": 40,"
                       "   \"sampler\": {\"type\": \"independent\"},"
                       "   \"film\": {\"type\": \"hdrfilm\", \"width\": 24, \"height\": 20,"
                       "     \"pixel_format\": \"rgb\", \"rfilter\": {\"type\": \"gaussian\"}}},"
                       " \"lamp\": {\"type\": \"rectangle\","
                       "   \"to_world\": [{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}},"
                       "     {\"translate\": [1, 0.3, 5]}],"
                       "   \"emitter\": {\"type\": \"area\","
                       "     \"radiance\": {\"type\": \"rgb\", \"value\": [1, 0.5, 0.25]}}}}",
                       "rgb");
  REQUIRE(s, "scene");
  film_image ref = {0};
  bool have_ref = false;
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    film_image img;
    if (!tsup_render(s, 8, 5, 2, &img)) {
      CHECK(false, "render at %s", rsw_isa_name((rsw_isa)isa));
      continue;
    }
    size_t n = (size_t)img.width * img.height * img.channels;
    if (!have_ref) {
      ref = img, have_ref = true;
      int between = 0;
      for (size_t i = 0; i < n; i += (size_t)img.channels)
        between += img.data[i] > 0.01f && img.data[i] < 0.99f;
      CHECK(between >= 10, "only %d pixels on the lamp's blurred edge", between);
      continue;
    }
    CHECK(n == (size_t)ref.width * ref.height * ref.channels &&
              memcmp(img.data, ref.data, n * sizeof(float)) == 0,
          "the film at %s differs from the one at %s", rsw_isa_name((rsw_isa)isa),
          rsw_isa_name(RSW_ISA_SSE2));
    film_image_free(&img);
  }
  rsw_isa_set(rsw_isa_best());
  if (have_ref) film_image_free(&ref);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_exp_ulp);
  RSW_TEST_RUN(test_footprints);
  RSW_TEST_RUN(test_rfilter_agrees);
  RSW_TEST_RUN(test_splat_isas);
  RSW_TEST_END("test_vexp");
}
