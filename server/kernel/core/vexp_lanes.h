/* exp(x) on eight lanes of doubles, the same bits at every ISA: the
 * kernel of core/vexp.c's batches (vexp_batch) and of the gaussian
 * filter's footprint weights (films/filter_gaussian.c), which make their
 * lanes themselves. Include it only in a file built at -O3 (below).
 *
 * The method is the table-driven one of Tang ("Table-driven implementation
 * of the exponential function in IEEE floating-point arithmetic", ACM TOMS
 * 15(2), 1989) in the variant of Szabolcs Nagy's exp for ARM's
 * optimized-routines (2018, math/exp.c; glibc's since 2.28), N = 128:
 *   k = round(x N / ln2),  r = x - k ln2 / N  (|r| <= ln2 / 2N, with
 *                                              ln2 / N split hi + lo),
 *   2^(k/N) = 2^(k >> 7) 2^((k mod N)/N) ~ s (1 + t)   (table: s, t),
 *   exp(x) = s (1 + t) exp(r) ~ s + s (t + r + r^2 (C2 + r C3)
 *                                              + r^4 (C4 + r C5)),
 * (C2..C5: VEXP_C2..VEXP_C5 below) the polynomial exp(r) - 1 - r's minimax one on |r| <= ln2 / 256 (abs
 * error 1.6 2^-66; its authors bound the whole at 0.51 ulp with fused
 * multiply-adds). k is rounded by adding 1.5 2^52 (its low bits are then
 * k's), and the table holds s's bits less (k mod N) << 45, so that adding
 * k << 45 puts k >> 7 into the exponent.
 *
 * Every multiply-add below is an explicit fma(), the same ones in the same
 * order as glibc 2.36's x86-64 __exp_fma (its e_exp.c compiled with
 * -mfma, contracted by GCC): on a machine whose libm picks that variant
 * this returns libm's bits (tests/kernel/core/test_vexp.c: 2^21
 * arguments across the filter's domain [-8, 0] and 2^18 in [-700, 700],
 * at every ISA; elsewhere it is within 1 ulp of libm's), and since fma
 * rounds once by definition, every ISA, with the instruction or with
 * libm's fma(), gives the same bits. Its users are built at -O3
 * (Makefile SEED_O3), where GCC makes each V8_FMA below one vector
 * instruction (at -O2 its loop stays a loop of scalar ones, 2.5x slower).
 * |x| >= 512 (where the result nears overflow or the subnormals) and NaN
 * go to libm's exp.
 *
 * The table: s = 2^(k/N) rounded to double, t = (2^(k/N) - s) / s rounded
 * to double, for k = 0..127, each from 2^(k/N) to 80 digits (Python's
 * decimal and fractions modules: float(Fraction(v)) rounds correctly);
 * table[2k] = bits(t), table[2k + 1] = bits(s) - (k << 45). */
#ifndef RSW_CORE_VEXP_LANES_H
#define RSW_CORE_VEXP_LANES_H

#include <stdint.h>

enum {
  VEXP_TABLE_BITS = 7,
  VEXP_N = 1 << VEXP_TABLE_BITS
};

static const double VEXP_INV_LN2_N = 0x1.71547652b82fep0 * VEXP_N;
static const double VEXP_NEG_LN2_HI_N = -0x1.62e42fefa0000p-8; /* -ln2 / N, its high bits (k * it is exact) */
static const double VEXP_NEG_LN2_LO_N = -0x1.cf79abc9e3b3ap-47;
static const double VEXP_SHIFT = 0x1.8p52;
static const double VEXP_C2 = 0x1.ffffffffffdbdp-2, VEXP_C3 = 0x1.555555555543cp-3,
                    VEXP_C4 = 0x1.55555cf172b91p-5, VEXP_C5 = 0x1.1111167a4d017p-7;

/* The table (core/vexp.c). */
extern const uint64_t vexp_table[2 * VEXP_N] __attribute__((visibility("hidden")));

/* Eight lanes of doubles (one AVX-512 register, two AVX2 ones, four
 * SSE2 ones: GCC splits them), kept as locals of always-inline helpers
 * (no vector passes through a call). */
typedef double v8d __attribute__((vector_size(64)));
typedef uint64_t v8u __attribute__((vector_size(64)));
typedef int64_t v8l __attribute__((vector_size(64)));
#define V8(c) ((v8d){0} + (c))
/* r = a b + c lane by lane, rounded once (one vfmadd on an FMA target, a
 * call of libm's fma() elsewhere). */
#define V8_FMA(r, a, b, c)                                                                                   \
  do {                                                                                                       \
    for (int k_ = 0; k_ < 8; k_++) (r)[k_] = __builtin_fma((a)[k_], (b)[k_], (c)[k_]);                       \
  } while (0)
/* m ? a : b lane by lane (m: all ones or zero). */
static inline __attribute__((always_inline)) void v8_sel(v8d *r, const v8l *m, const v8d *a, const v8d *b) {
  *r = (v8d)(((v8l)*a & *m) | ((v8l)*b & ~*m));
}

/* *x = exp(*x) lane by lane, the method above for |x| < 512 (lanes beyond:
 * not exp; the callers replace them). */
static inline __attribute__((always_inline)) void vexp_v8(v8d *xp) {
  v8d x = *xp, kd, r, p, q;
  V8_FMA(kd, x, V8(VEXP_INV_LN2_N), V8(VEXP_SHIFT));
  v8u ki = (v8u)kd;
  kd -= VEXP_SHIFT;
  V8_FMA(r, kd, V8(VEXP_NEG_LN2_HI_N), x);
  V8_FMA(r, kd, V8(VEXP_NEG_LN2_LO_N), r);
  v8u idx = 2 * (ki % VEXP_N);
  v8u tbits, sbits;
  for (int k = 0; k < 8; k++) {
    tbits[k] = vexp_table[idx[k]];
    sbits[k] = vexp_table[idx[k] + 1];
  }
  v8d t = (v8d)tbits; /* (a vector cast: the same bits) */
  v8d s = (v8d)(sbits + (ki << (52 - VEXP_TABLE_BITS)));
  v8d r2 = r * r;
  V8_FMA(q, r, V8(VEXP_C3), V8(VEXP_C2));
  V8_FMA(p, r2, q, t + r);
  V8_FMA(q, r, V8(VEXP_C5), V8(VEXP_C4));
  V8_FMA(p, r2 * r2, q, p);
  V8_FMA(*xp, s, p, s);
}

#endif
