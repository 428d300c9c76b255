/* Cheaper stand-ins for libm calls on the volumetric hot path.
 *
 * rsw_fmax, rsw_fmin: fmax and fmin, bit for bit (gcc calls libm's for
 * them, which on x86-64 is maxsd / minsd behind a NaN check): with no NaN,
 * x > y ? x : y (so fmax(-0, +0) is +0, the second argument, as maxsd);
 * with one NaN, the other argument.
 *
 * rsw_neg_log1m(u) = -log(1 - u) for u in [0, 1), the optical thickness of
 * a free flight (-log1p(-u)) from libm's log, which is cheaper than its
 * log1p (about 14 against 22 ns on this project's machine). v = 1 - u is
 * rounded, but its rounding error e = (1 - u) - v is exact in double
 * (Fast2Sum: |1| >= |u|; Knuth, TAOCP vol. 2, 4.2.2), and
 * log(1 - u) = log(v + e) = log(v) + e / v - (e / v)^2 / 2 + ..., where
 * |e / v| <= 2^-53 / (1 - u) makes the third term far below an ulp of the
 * result. So the error is log's (glibc: < 1 ulp) plus the sum's rounding:
 * at most 2 ulp of log1p(-u), which tests/kernel/core/test_fastmath.c checks
 * against libm's log1p over [0, 1) (every binade down to the subnormals and
 * up to the last double below 1). */
#ifndef RSW_CORE_FASTMATH_H
#define RSW_CORE_FASTMATH_H

#include <math.h>

/* x < y ? x : y and x > y ? x : y, bit for bit (equal operands or a NaN:
 * y), as one minsd / maxsd each on x86-64: written as selects, GCC turns
 * the pair of them on one comparison (a slab's near and far distance,
 * ta > tb ? tb : ta and ta > tb ? ta : tb) into a branch and two moves,
 * and a ray's direction decides that branch, so that it mispredicts about
 * every other ray. (Inline assembly, not _mm_min_sd: GCC folds that one on
 * constants with other NaN rules than the instruction's.) */
#if defined(__GNUC__) && defined(__x86_64__) && defined(__AVX__)
#define RSW_SEL_BODY(op, cmp)                                                                                \
  double r;                                                                                                  \
  __asm__("v" op "sd %2, %1, %0" : "=x"(r) : "x"(x), "xm"(y));                                               \
  return r;
#elif defined(__GNUC__) && defined(__x86_64__)
#define RSW_SEL_BODY(op, cmp)                                                                                \
  __asm__(op "sd %1, %0" : "+x"(x) : "xm"(y));                                                               \
  return x;
#else
#define RSW_SEL_BODY(op, cmp) return x cmp y ? x : y;
#endif
static inline double rsw_sel_min(double x, double y) {
  RSW_SEL_BODY("min", <)
}
static inline double rsw_sel_max(double x, double y) {
  RSW_SEL_BODY("max", >)
}
#undef RSW_SEL_BODY

static inline double rsw_fmax(double x, double y) {
  return x > y || y != y ? x : y;
}

static inline double rsw_fmin(double x, double y) {
  return x < y || y != y ? x : y;
}

/* -log1p(-u) within 2 ulp, u in [0, 1] (1: +inf, as log1p's). */
static inline double rsw_neg_log1m(double u) {
  double v = 1.0 - u;
  double e = (-u) - (v - 1.0);                 /* Fast2Sum's exact error of 1 + (-u) */
  return v > 0.0 ? -log(v) - e / v : INFINITY; /* (u = 0: +0, as -log1p(-0)) */
}

#endif
