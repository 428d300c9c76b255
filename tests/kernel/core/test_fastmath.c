/* core/fastmath.h against libm:
 *  - rsw_fmax, rsw_fmin give fmax's and fmin's bits for every pair of a
 *    set of values with signed zeros, infinities, NaN, subnormals and
 *    random doubles;
 *  - rsw_sel_min, rsw_sel_max give the bits of the selects x < y ? x : y
 *    and x > y ? x : y for every pair of those values;
 *  - rsw_neg_log1m(u) is -log1p(-u) within 2 ulp (of log1p's value) over
 *    the whole domain [0, 1]: 0 and 1, 2,000 random mantissas in every
 *    binade from the smallest subnormal (2^-1074) to [0.5, 1), the 4,096
 *    doubles just below 1 and the first 4,096 above 0.5, and a million
 *    draws on the samplers' grid (k 2^-53). The bound is a tight one: the
 *    largest error seen is 1 ulp (checked >= 0.75: a bound of 0.5 ulp, what a
 *    correctly rounded function would meet, fails), and the two differ
 *    somewhere (a copy of log1p would not be worth the check).
 * Fixed seeds. */
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "../../../server/kernel/core/fastmath.h"
#include "../../support/test.h"

RSW_TEST_DEFINE_GLOBALS

static uint64_t bits(double x) {
  uint64_t b;
  memcpy(&b, &x, sizeof b);
  return b;
}

static double from_bits(uint64_t b) {
  double x;
  memcpy(&x, &b, sizeof x);
  return x;
}

static uint64_t rng_state = 0x9E3779B97F4A7C15ull;
static uint64_t next_u64(void) { /* xorshift64* */
  rng_state ^= rng_state >> 12;
  rng_state ^= rng_state << 25;
  rng_state ^= rng_state >> 27;
  return rng_state * 0x2545F4914F6CDD1Dull;
}

/* 64 values into v: signed zeros, infinities, NaN, subnormals, then
 * random bits (NaNs included). */
static int test_values(double v[64]) {
  const double fixed[12] = {0.0, -0.0, 1.0,       -1.0,       INFINITY,  -INFINITY,
                            NAN, -NAN, 0x1p-1074, -0x1p-1074, 0x1p-1022, 1e300};
  int n = 0;
  for (; n < 12; n++) v[n] = fixed[n];
  for (; n < 64; n++) v[n] = from_bits(next_u64()) * (n % 2 ? 1.0 : 1e-300);
  return n;
}

/* The selects rsw_sel_min and rsw_sel_max stand for, as branches (noinline:
 * the reference is the C expression, whatever code GCC picks for it). */
static __attribute__((noinline)) double sel_min_ref(double x, double y) {
  if (x < y) return x;
  return y;
}
static __attribute__((noinline)) double sel_max_ref(double x, double y) {
  if (x > y) return x;
  return y;
}

static void test_minmax_bits(void) {
  double v[64];
  int n = test_values(v);
  int bad = 0, bad_sel = 0;
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++) {
      double x = v[i], y = v[j];
      bool nan_max = isnan(fmax(x, y)), nan_min = isnan(fmin(x, y));
      /* (NaN results: any NaN; else the same bits) */
      if (nan_max ? !isnan(rsw_fmax(x, y)) : bits(rsw_fmax(x, y)) != bits(fmax(x, y))) bad++;
      if (nan_min ? !isnan(rsw_fmin(x, y)) : bits(rsw_fmin(x, y)) != bits(fmin(x, y))) bad++;
      /* (the selects: every bit, a NaN's too, both returning y's) */
      bad_sel += bits(rsw_sel_min(x, y)) != bits(sel_min_ref(x, y));
      bad_sel += bits(rsw_sel_max(x, y)) != bits(sel_max_ref(x, y));
    }
  CHECK(bad == 0, "%d of %d pairs differ from libm's fmax/fmin", bad, 2 * n * n);
  CHECK(bits(rsw_fmax(-0.0, 0.0)) == bits(0.0) && bits(rsw_fmax(0.0, -0.0)) == bits(-0.0),
        "signed zeros: fmax returns its second argument");
  CHECK(bad_sel == 0, "%d of %d pairs differ from the selects", bad_sel, 2 * n * n);
  CHECK(bits(rsw_sel_min(-0.0, 0.0)) == bits(0.0) && bits(rsw_sel_max(0.0, -0.0)) == bits(-0.0) &&
            isnan(rsw_sel_min(1.0, NAN)) && rsw_sel_min(NAN, 1.0) == 1.0,
        "rsw_sel_*: equal operands and a NaN give the second operand");
}

/* |a - b| in ulp of b (b finite, > 0 here: -log1p(-u) for u in (0, 1)). */
static double ulp_err(double a, double b) {
  double ulp = nextafter(b, INFINITY) - b;
  return fabs(a - b) / ulp;
}

static double worst = 0.0, worst_u = 0.0;
static long checked = 0, differ = 0;

static void check_u(double u) {
  double ref = -log1p(-u), got = rsw_neg_log1m(u);
  checked++;
  if (bits(ref) != bits(got)) differ++;
  double e = ref > 0 ? ulp_err(got, ref) : (got == ref ? 0.0 : INFINITY);
  if (e > worst) worst = e, worst_u = u;
}

static void test_neg_log1m_ulp(void) {
  check_u(0.0);
  CHECK(rsw_neg_log1m(0.0) == 0.0 && !signbit(rsw_neg_log1m(0.0)), "u = 0: +0");
  CHECK(rsw_neg_log1m(1.0) == INFINITY, "u = 1: +inf, as -log1p(-1), got %g", rsw_neg_log1m(1.0));
  for (int e = -1074; e <= -1; e++) { /* the binade [2^e, 2^(e+1)) (subnormals: e < -1022) */
    double lo = ldexp(1.0, e);
    for (int k = 0; k < 2000; k++) {
      double f = (double)(next_u64() >> 11) * 0x1p-53; /* [0, 1) */
      double u = lo + lo * f;                          /* (subnormal binades: rounded onto the grid) */
      if (u < 1.0) check_u(u);
    }
  }
  double u = 1.0;
  for (int k = 0; k < 4096; k++) check_u(u = nextafter(u, 0.0));
  u = 0.5;
  for (int k = 0; k < 4096; k++) check_u(u = nextafter(u, 1.0));
  for (int k = 0; k < 1000000; k++) check_u((double)(next_u64() >> 11) * 0x1p-53);
  printf("rsw_neg_log1m: %ld values, %ld differ from -log1p(-u), largest error %.3f ulp (u = %.17g)\n",
         checked, differ, worst, worst_u);
  CHECK(worst <= 2.0, "largest error %.3f ulp at u = %.17g (bound 2)", worst, worst_u);
  CHECK(worst >= 0.75, "largest error %.3f ulp: the 2 ulp bound is loose (expected >= 0.75)", worst);
  CHECK(differ > 0, "no value differs from log1p's");
}

int main(void) {
  RSW_TEST_RUN(test_minmax_bits);
  RSW_TEST_RUN(test_neg_log1m_ulp);
  RSW_TEST_END("test_fastmath");
}
