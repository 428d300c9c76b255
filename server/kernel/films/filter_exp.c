/* exp(x) in batches for the gaussian filter's weights (films/rfilters.c):
 * splat_filter (render.c) needs 2 x 4 of them per sample, which as libm
 * calls were ~5% of the Cornell box.
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
 * the polynomial exp(r) - 1 - r's minimax one on |r| <= ln2 / 256 (abs
 * error 1.6 2^-66; its authors bound the whole at 0.51 ulp with fused
 * multiply-adds). k is rounded by adding 1.5 2^52 (its low bits are then
 * k's), and the table holds s's bits less (k mod N) << 45, so that adding
 * k << 45 puts k >> 7 into the exponent.
 *
 * Every multiply-add below is an explicit fma(), the same ones in the same
 * order as glibc 2.36's x86-64 __exp_fma (its e_exp.c compiled with
 * -mfma, contracted by GCC): on a machine whose libm picks that variant
 * this returns libm's bits (tests/kernel/films/test_filter_exp.c: 2^21
 * arguments across the filter's domain [-8, 0] and 2^18 in [-700, 700],
 * at every ISA; elsewhere it is within 1 ulp of libm's), and since fma
 * rounds once by definition, every ISA, with the instruction or with
 * libm's fma(), gives the same bits. The file is built at -O3 (Makefile
 * SEED_O3), where GCC makes each V8_FMA below one vector instruction (at
 * -O2 its loop stays a loop of scalar ones, 2.5x slower).
 * |x| >= 512 (where the result nears overflow or the subnormals) and NaN
 * go to libm's exp.
 *
 * The table: s = 2^(k/N) rounded to double, t = (2^(k/N) - s) / s rounded
 * to double, for k = 0..127, each from 2^(k/N) to 80 digits (Python's
 * decimal and fractions modules: float(Fraction(v)) rounds correctly);
 * tab[2k] = bits(t), tab[2k + 1] = bits(s) - (k << 45). */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "filter_exp.h"

enum {
  EXP_TABLE_BITS = 7,
  EXP_N = 1 << EXP_TABLE_BITS
};

static const double INV_LN2_N = 0x1.71547652b82fep0 * EXP_N;
static const double NEG_LN2_HI_N = -0x1.62e42fefa0000p-8; /* -ln2 / N, its high bits (k * it is exact) */
static const double NEG_LN2_LO_N = -0x1.cf79abc9e3b3ap-47;
static const double SHIFT = 0x1.8p52;
static const double C2 = 0x1.ffffffffffdbdp-2, C3 = 0x1.555555555543cp-3, C4 = 0x1.55555cf172b91p-5,
                    C5 = 0x1.1111167a4d017p-7;

static const uint64_t TAB[2 * EXP_N] = {
    0x0000000000000000, 0x3ff0000000000000, 0x3c9b3b4f1a88bf6e, 0x3feff63da9fb3335, 0xbc7160139cd8dc5d,
    0x3fefec9a3e778061, 0xbc905e7a108766d1, 0x3fefe315e86e7f85, 0x3c8cd2523567f613, 0x3fefd9b0d3158574,
    0xbc8bce8023f98efa, 0x3fefd06b29ddf6de, 0x3c60f74e61e6c861, 0x3fefc74518759bc8, 0x3c90a3e45b33d399,
    0x3fefbe3ecac6f383, 0x3c979aa65d837b6d, 0x3fefb5586cf9890f, 0x3c8eb51a92fdeffc, 0x3fefac922b7247f7,
    0x3c3ebe3d702f9cd1, 0x3fefa3ec32d3d1a2, 0xbc6a033489906e0b, 0x3fef9b66affed31b, 0xbc9556522a2fbd0e,
    0x3fef9301d0125b51, 0xbc5080ef8c4eea55, 0x3fef8abdc06c31cc, 0xbc91c923b9d5f416, 0x3fef829aaea92de0,
    0x3c80d3e3e95c55af, 0x3fef7a98c8a58e51, 0xbc801b15eaa59348, 0x3fef72b83c7d517b, 0xbc8f1ff055de323d,
    0x3fef6af9388c8dea, 0x3c8b898c3f1353bf, 0x3fef635beb6fcb75, 0xbc96d99c7611eb26, 0x3fef5be084045cd4,
    0x3c9aecf73e3a2f60, 0x3fef54873168b9aa, 0xbc8fe782cb86389d, 0x3fef4d5022fcd91d, 0x3c8a6f4144a6c38d,
    0x3fef463b88628cd6, 0x3c807a05b0e4047d, 0x3fef3f49917ddc96, 0x3c968efde3a8a894, 0x3fef387a6e756238,
    0x3c875e18f274487d, 0x3fef31ce4fb2a63f, 0x3c80472b981fe7f2, 0x3fef2b4565e27cdd, 0xbc96b87b3f71085e,
    0x3fef24dfe1f56381, 0x3c82f7e16d09ab31, 0x3fef1e9df51fdee1, 0xbc3d219b1a6fbffa, 0x3fef187fd0dad990,
    0x3c8b3782720c0ab4, 0x3fef1285a6e4030b, 0x3c6e149289cecb8f, 0x3fef0cafa93e2f56, 0x3c834d754db0abb6,
    0x3fef06fe0a31b715, 0x3c864201e2ac744c, 0x3fef0170fc4cd831, 0x3c8fdd395dd3f84a, 0x3feefc08b26416ff,
    0xbc86a3803b8e5b04, 0x3feef6c55f929ff1, 0xbc924aedcc4b5068, 0x3feef1a7373aa9cb, 0xbc9907f81b512d8e,
    0x3feeecae6d05d866, 0xbc71d1e83e9436d2, 0x3feee7db34e59ff7, 0xbc991919b3ce1b15, 0x3feee32dc313a8e5,
    0x3c859f48a72a4c6d, 0x3feedea64c123422, 0xbc9312607a28698a, 0x3feeda4504ac801c, 0xbc58a78f4817895b,
    0x3feed60a21f72e2a, 0xbc7c2c9b67499a1b, 0x3feed1f5d950a897, 0x3c4363ed60c2ac11, 0x3feece086061892d,
    0x3c9666093b0664ef, 0x3feeca41ed1d0057, 0x3c6ecce1daa10379, 0x3feec6a2b5c13cd0, 0x3c93ff8e3f0f1230,
    0x3feec32af0d7d3de, 0x3c7690cebb7aafb0, 0x3feebfdad5362a27, 0x3c931dbdeb54e077, 0x3feebcb299fddd0d,
    0xbc8f94340071a38e, 0x3feeb9b2769d2ca7, 0xbc87deccdc93a349, 0x3feeb6daa2cf6642, 0xbc78dec6bd0f385f,
    0x3feeb42b569d4f82, 0xbc861246ec7b5cf6, 0x3feeb1a4ca5d920f, 0x3c93350518fdd78e, 0x3feeaf4736b527da,
    0x3c7b98b72f8a9b05, 0x3feead12d497c7fd, 0x3c9063e1e21c5409, 0x3feeab07dd485429, 0x3c34c7855019c6ea,
    0x3feea9268a5946b7, 0x3c9432e62b64c035, 0x3feea76f15ad2148, 0xbc8ce44a6199769f, 0x3feea5e1b976dc09,
    0xbc8c33c53bef4da8, 0x3feea47eb03a5585, 0xbc845378892be9ae, 0x3feea34634ccc320, 0xbc93cedd78565858,
    0x3feea23882552225, 0x3c5710aa807e1964, 0x3feea155d44ca973, 0xbc93b3efbf5e2228, 0x3feea09e667f3bcd,
    0xbc6a12ad8734b982, 0x3feea012750bdabf, 0xbc6367efb86da9ee, 0x3fee9fb23c651a2f, 0xbc80dc3d54e08851,
    0x3fee9f7df9519484, 0xbc781f647e5a3ecf, 0x3fee9f75e8ec5f74, 0xbc86ee4ac08b7db0, 0x3fee9f9a48a58174,
    0xbc8619321e55e68a, 0x3fee9feb564267c9, 0x3c909ccb5e09d4d3, 0x3feea0694fde5d3f, 0xbc7b32dcb94da51d,
    0x3feea11473eb0187, 0x3c94ecfd5467c06b, 0x3feea1ed0130c132, 0x3c65ebe1abd66c55, 0x3feea2f336cf4e62,
    0xbc88a1c52fb3cf42, 0x3feea427543e1a12, 0xbc9369b6f13b3734, 0x3feea589994cce13, 0xbc805e843a19ff1e,
    0x3feea71a4623c7ad, 0xbc94d450d872576e, 0x3feea8d99b4492ed, 0x3c90ad675b0e8a00, 0x3feeaac7d98a6699,
    0x3c8db72fc1f0eab4, 0x3feeace5422aa0db, 0xbc65b6609cc5e7ff, 0x3feeaf3216b5448c, 0x3c7bf68359f35f44,
    0x3feeb1ae99157736, 0xbc93091fa71e3d83, 0x3feeb45b0b91ffc6, 0xbc5da9b88b6c1e29, 0x3feeb737b0cdc5e5,
    0xbc6c23f97c90b959, 0x3feeba44cbc8520f, 0xbc92434322f4f9aa, 0x3feebd829fde4e50, 0xbc85ca6cd7668e4b,
    0x3feec0f170ca07ba, 0x3c71affc2b91ce27, 0x3feec49182a3f090, 0x3c6dd235e10a73bb, 0x3feec86319e32323,
    0xbc87c50422622263, 0x3feecc667b5de565, 0x3c8b1c86e3e231d5, 0x3feed09bec4a2d33, 0xbc91bbd1d3bcbb15,
    0x3feed503b23e255d, 0x3c90cc319cee31d2, 0x3feed99e1330b358, 0x3c8469846e735ab3, 0x3feede6b5579fdbf,
    0xbc82dfcd978e9db4, 0x3feee36bbfd3f37a, 0x3c8c1a7792cb3387, 0x3feee89f995ad3ad, 0xbc907b8f4ad1d9fa,
    0x3feeee07298db666, 0xbc55c3d956dcaeba, 0x3feef3a2b84f15fb, 0xbc90a40e3da6f640, 0x3feef9728de5593a,
    0xbc68d6f438ad9334, 0x3feeff76f2fb5e47, 0xbc91eee26b588a35, 0x3fef05b030a1064a, 0x3c74ffd70a5fddcd,
    0x3fef0c1e904bc1d2, 0xbc91bdfbfa9298ac, 0x3fef12c25bd71e09, 0x3c736eae30af0cb3, 0x3fef199bdd85529c,
    0x3c8ee3325c9ffd94, 0x3fef20ab5fffd07a, 0x3c84e08fd10959ac, 0x3fef27f12e57d14b, 0x3c63cdaf384e1a67,
    0x3fef2f6d9406e7b5, 0x3c676b2c6c921968, 0x3fef3720dcef9069, 0xbc808a1883ccb5d2, 0x3fef3f0b555dc3fa,
    0xbc8fad5d3ffffa6f, 0x3fef472d4a07897c, 0xbc900dae3875a949, 0x3fef4f87080d89f2, 0x3c74a385a63d07a7,
    0x3fef5818dcfba487, 0xbc82919e2040220f, 0x3fef60e316c98398, 0x3c8e5a50d5c192ac, 0x3fef69e603db3285,
    0x3c843a59ac016b4b, 0x3fef7321f301b460, 0xbc82d52107b43e1f, 0x3fef7c97337b9b5f, 0xbc892ab93b470dc9,
    0x3fef864614f5a129, 0x3c74b604603a88d3, 0x3fef902ee78b3ff6, 0x3c83c5ec519d7271, 0x3fef9a51fbc74c83,
    0xbc8ff7128fd391f0, 0x3fefa4afa2a490da, 0xbc8dae98e223747d, 0x3fefaf482d8e67f1, 0x3c8ec3bc41aa2008,
    0x3fefba1bee615a27, 0x3c842b94c3a9eb32, 0x3fefc52b376bba97, 0x3c8a64a931d185ee, 0x3fefd0765b6e4540,
    0xbc8e37bae43be3ed, 0x3fefdbfdad9cbe14, 0x3c77893b4d91cd9d, 0x3fefe7c1819e90d8, 0x3c5305c14160cc89,
    0x3feff3c22b8f71f1,
};

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
static inline __attribute__((always_inline)) void exp_v8(v8d *xp) {
  v8d x = *xp, kd, r, p, q;
  V8_FMA(kd, x, V8(INV_LN2_N), V8(SHIFT));
  v8u ki = (v8u)kd;
  kd -= SHIFT;
  V8_FMA(r, kd, V8(NEG_LN2_HI_N), x);
  V8_FMA(r, kd, V8(NEG_LN2_LO_N), r);
  v8u idx = 2 * (ki % EXP_N);
  v8u tbits, sbits;
  for (int k = 0; k < 8; k++) {
    tbits[k] = TAB[idx[k]];
    sbits[k] = TAB[idx[k] + 1];
  }
  v8d t = (v8d)tbits; /* (a vector cast: the same bits) */
  v8d s = (v8d)(sbits + (ki << (52 - EXP_TABLE_BITS)));
  v8d r2 = r * r;
  V8_FMA(q, r, V8(C3), V8(C2));
  V8_FMA(p, r2, q, t + r);
  V8_FMA(q, r, V8(C5), V8(C4));
  V8_FMA(p, r2 * r2, q, p);
  V8_FMA(*xp, s, p, s);
}

/* exp of n values, 8 at a time (a partial tail through a padded copy),
 * then the rare lanes beyond |x| < 512 through libm. */
static inline __attribute__((always_inline)) void exp_body(int n, const double *restrict x,
                                                           double *restrict out) {
  int i0 = 0;
  for (; i0 + 8 <= n; i0 += 8) { /* whole vectors: fixed-size copies, one load and one store each */
    v8d v;
    memcpy(&v, x + i0, sizeof v);
    exp_v8(&v);
    memcpy(out + i0, &v, sizeof v);
  }
  if (i0 < n) {
    int m = n - i0;
    v8d v = {0};
    memcpy(&v, x + i0, sizeof(double) * (size_t)m);
    exp_v8(&v);
    memcpy(out + i0, &v, sizeof(double) * (size_t)m);
  }
  for (int i = 0; i < n; i++)
    if (!(fabs(x[i]) < 512.0)) out[i] = exp(x[i]);
}

/* The lanes of a gaussian footprint whose exp argument a is beyond
 * |a| < 512 (or NaN), through libm (never at a footprint's own pixels:
 * there a >= -8). Out of line, so that the vector body keeps its
 * registers. */
static __attribute__((noinline, cold)) void gaussian_fix(const filter_footprint *fp, const double *a, int m,
                                                         double *w) {
  for (int k = 0; k < m; k++)
    if (!(fabs(a[k]) < 512.0)) {
      double v = exp(a[k]) - fp->bias;
      w[k] = v > 0.0 ? v : 0.0;
    }
}

/* The gaussian's weights of a footprint (filter_gaussian_footprint), 8
 * lanes at a time, the arguments made in the lanes from scalars: a
 * lane's operations are splat_filter's px - (x + 0.5) (xlo + i is exact
 * in double) and gaussian_eval's. Lanes past the footprint's end get
 * t = 0. */
static inline __attribute__((always_inline)) void gaussian_body(const filter_footprint *fp,
                                                                double *restrict out) {
  const v8d iota = {0, 1, 2, 3, 4, 5, 6, 7};
  int n = fp->nx + fp->ny;
  for (int i0 = 0; i0 < n; i0 += 8) {
    v8d i = iota + (double)i0, zero = {0};
    v8l col = i < (double)fp->nx, live = i < (double)n;
    v8d c, xc = V8(fp->px), yc = V8(fp->py), pc = i + (double)fp->xlo, pr = i + (double)(fp->ylo - fp->nx);
    v8d p;
    v8_sel(&c, &col, &xc, &yc);
    v8_sel(&p, &col, &pc, &pr);
    v8d t = c - (p + 0.5);
    v8_sel(&t, &live, &t, &zero);
    v8d a = fp->alpha * t * t, e = a;
    exp_v8(&e);
    v8d v = e - fp->bias;
    v8l pos = v > 0.0;
    v8_sel(&v, &pos, &v, &zero);
    v8d aa = (v8d)((v8l)a & 0x7fffffffffffffffLL);
    v8l ok = aa < 512.0;
    long long all_ok = -1;
    for (int k = 0; k < 8; k++) all_ok &= ok[k];
    int m = n - i0 < 8 ? n - i0 : 8;
    if (!all_ok) {
      double ab[8], vb[8];
      memcpy(ab, &a, sizeof ab);
      memcpy(vb, &v, sizeof vb);
      gaussian_fix(fp, ab, m, vb);
      memcpy(&v, vb, sizeof vb);
    }
    if (m == 8)
      memcpy(out + i0, &v, sizeof v);
    else
      for (int k = 0; k < m; k++) out[i0 + k] = v[k];
  }
}

#if defined(__x86_64__) || defined(__i386__)
static __attribute__((target("avx512f,avx512vl,avx512dq"))) void exp_avx512(int n, const double *restrict x,
                                                                            double *restrict out) {
  exp_body(n, x, out);
}
static __attribute__((target("avx2,fma"))) void exp_avx2(int n, const double *restrict x,
                                                         double *restrict out) {
  exp_body(n, x, out);
}
static __attribute__((target("avx512f,avx512vl,avx512dq"))) void gaussian_avx512(const filter_footprint *fp,
                                                                                 double *restrict out) {
  gaussian_body(fp, out);
}
static __attribute__((target("avx2,fma"))) void gaussian_avx2(const filter_footprint *fp,
                                                              double *restrict out) {
  gaussian_body(fp, out);
}
#endif
/* sse2 (the x86-64 baseline) and generic: fma() from libm (one rounding:
 * the same bits, in software where the CPU lacks the instruction). */
static void exp_base(int n, const double *restrict x, double *restrict out) {
  exp_body(n, x, out);
}
static void gaussian_base(const filter_footprint *fp, double *restrict out) {
  gaussian_body(fp, out);
}

void filter_exp_batch(rsw_isa isa, int n, const double *restrict x, double *restrict out) {
#if defined(__x86_64__) || defined(__i386__)
  switch (isa) {
  case RSW_ISA_AVX512: exp_avx512(n, x, out); return;
  case RSW_ISA_AVX2: exp_avx2(n, x, out); return;
  default: break;
  }
#endif
  (void)isa;
  exp_base(n, x, out);
}

void filter_gaussian_footprint(rsw_isa isa, const filter_footprint *fp, double *restrict out) {
#if defined(__x86_64__) || defined(__i386__)
  switch (isa) {
  case RSW_ISA_AVX512: gaussian_avx512(fp, out); return;
  case RSW_ISA_AVX2: gaussian_avx2(fp, out); return;
  default: break;
  }
#endif
  (void)isa;
  gaussian_base(fp, out);
}
