/* Single-precision lane math for the batched kernels, written once with
 * GCC/clang vector extensions and included by each per-ISA translation
 * unit after it has defined:
 *   W        lanes (4 sse2, 8 avx2, 16 avx512)
 *   SIMD_FN  the storage and target attributes of every helper, e.g.
 *            static inline __attribute__((always_inline, target("avx2,fma")))
 *   VSQRT(x) the ISA's packed square root (an intrinsic)
 * Types: vf (W floats), vi (W int32, masks are all-ones / zero lanes),
 * vd (W doubles).
 *
 * Every routine is a fixed sequence of lane-wise operations (no cross-lane
 * step, no reduction that feeds back into a lane's value), so a lane's
 * result depends on its inputs only, never on its neighbours or on W
 * beyond the ISA's own rounding (no FMA contraction: the project compiles
 * with -std=c11, i.e. -ffp-contract=off).
 *
 * Accuracy: vlog/vexp/vsin/vcos are Cephes' single-precision polynomials
 * (Moshier, "Methods and programs for mathematical functions", 1989), a few
 * ulp; verf is Abramowitz & Stegun 7.1.28 as mf_erff() (4e-7 absolute,
 * its 16th power taken in double); verfinv is Giles 2010 as mf_erfinvf(). */
#ifndef W
#error "define W, SIMD_FN and VSQRT before including simd/lanes.h"
#endif

typedef float vf __attribute__((vector_size(4 * W)));
typedef int vi __attribute__((vector_size(4 * W)));
typedef double vd __attribute__((vector_size(8 * W)));

SIMD_FN vf vset(float x) {
  return (vf){0} + x;
}
SIMD_FN vf vsel(vi m, vf a, vf b) { /* m ? a : b */
  return (vf)(((vi)a & m) | ((vi)b & ~m));
}
SIMD_FN vf vmax(vf a, vf b) { /* NaN in a gives b */
  return vsel(a > b, a, b);
}
SIMD_FN vf vmin(vf a, vf b) {
  return vsel(a < b, a, b);
}
SIMD_FN vf vclamp(vf v, float lo, float hi) {
  return vsel(v > lo, vmin(v, vset(hi)), vset(lo));
}
SIMD_FN vf vabs(vf a) {
  return (vf)((vi)a & 0x7fffffff);
}
SIMD_FN vf vcopysign(vf mag, vf sgn) {
  return (vf)(((vi)vabs(mag)) | ((vi)sgn & (int)0x80000000));
}
SIMD_FN vf vfloor(vf x) { /* |x| < 2^31 */
  vf t = __builtin_convertvector(__builtin_convertvector(x, vi), vf);
  return t - vsel(t > x, vset(1.0f), vset(0.0f));
}
SIMD_FN bool vany(vi m) {
  int r = 0;
  for (int k = 0; k < W; k++) r |= m[k];
  return r != 0;
}

/* log(x): x = m 2^e with m in [sqrt(1/2), sqrt(2)); -inf at 0, NaN below. */
SIMD_FN vf vlog(vf x) {
  vi bits = (vi)x;
  vi e = ((bits >> 23) & 0xff) - 126;
  vf m = (vf)((bits & 0x007fffff) | 0x3f000000); /* [0.5, 1) */
  vi small = m < 0.707106781186547524f;
  e = e + small; /* small lanes: -1 */
  m = vsel(small, m + m, m) - 1.0f;
  vf fe = __builtin_convertvector(e, vf);
  vf z = m * m;
  vf y = vset(7.0376836292e-2f);
  y = y * m - 1.1514610310e-1f;
  y = y * m + 1.1676998740e-1f;
  y = y * m - 1.2420140846e-1f;
  y = y * m + 1.4249322787e-1f;
  y = y * m - 1.6668057665e-1f;
  y = y * m + 2.0000714765e-1f;
  y = y * m - 2.4999993993e-1f;
  y = y * m + 3.3333331174e-1f;
  y = y * m * z;
  y = y + -2.12194440e-4f * fe;
  y = y - 0.5f * z;
  vf r = m + y + 0.693359375f * fe;
  r = vsel(x == 0.0f, vset(-INFINITY), r);
  r = vsel(x < 0.0f, vset(NAN), r);
  return vsel(x == INFINITY, vset(INFINITY), r);
}

/* exp(x), x clamped to [-87.3, 88.3] (exp(-87.3) ~ 1e-38 stands for 0). */
SIMD_FN vf vexp(vf x) {
  x = vclamp(x, -87.3f, 88.3f);
  vf fx = vfloor(x * 1.44269504088896341f + 0.5f);
  x = x - fx * 0.693359375f;
  x = x - fx * -2.12194440e-4f;
  vf z = x * x;
  vf y = vset(1.9875691500e-4f);
  y = y * x + 1.3981999507e-3f;
  y = y * x + 8.3334519073e-3f;
  y = y * x + 4.1665795894e-2f;
  y = y * x + 1.6666665459e-1f;
  y = y * x + 5.0000001201e-1f;
  y = y * z + x + 1.0f;
  vi n = __builtin_convertvector(fx, vi);
  return y * (vf)((n + 127) << 23);
}

/* sin and cos of 2 pi u for any finite u (exact reduction: u - round(u)
 * and the quarter-turn subtraction are exact in float). */
SIMD_FN void vsincos_turns(vf u, vf *s, vf *c) {
  vf t = u - vfloor(u + 0.5f);                    /* [-0.5, 0.5] */
  vf jf = vfloor(4.0f * t + 0.5f);                /* -2..2 */
  vf r = (t - 0.25f * jf) * 6.28318530717958648f; /* [-pi/4, pi/4] */
  vf z = r * r;
  vf sr = ((-1.9515295891e-4f * z + 8.3321608736e-3f) * z - 1.6666654611e-1f) * z * r + r;
  vf cr = ((2.443315711809948e-5f * z - 1.388731625493765e-3f) * z + 4.166664568298827e-2f) * z * z -
          0.5f * z + 1.0f;
  vi j = __builtin_convertvector(jf, vi) & 3;
  vi odd = (j & 1) != 0;
  vf ss = vsel(odd, cr, sr), cc = vsel(odd, sr, cr);
  vi sneg = j >= 2, cneg = (j == 1) | (j == 2);
  *s = vsel(sneg, -ss, ss);
  *c = vsel(cneg, -cc, cc);
}

/* erf(x) as mf_erff(): A&S 7.1.28, the polynomial's 16th power in double
 * (in float, 16 compounded roundings cost ~3e-6 near x = 0.1); +-1 beyond
 * |x| = 6 (and at +-inf). */
SIMD_FN vf verf(vf x) {
  vf ax = vmin(vabs(x), vset(6.0f));
  vd a = __builtin_convertvector(ax, vd), a2 = a * a, a4 = a2 * a2;
  vd p = (1.0 + 0.0705230784 * a) + (0.0422820123 + 0.0092705272 * a) * a2 +
         ((0.0001520143 + 0.0002765672 * a) + 0.0000430638 * a2) * a4;
  vd p2 = p * p, p4 = p2 * p2, p8 = p4 * p4, p16 = p8 * p8;
  vf r = __builtin_convertvector(1.0 - 1.0 / p16, vf);
  r = vsel(ax >= 6.0f, vset(1.0f), r);
  return vcopysign(r, x);
}

/* erfinv(x) as mf_erfinvf() (Giles 2010, both branches computed and the
 * right one selected); +-inf at +-1, NaN outside [-1, 1]. */
SIMD_FN vf verfinv(vf x) {
  vf w = -vlog((1.0f - x) * (1.0f + x));
  vf a = w - 2.5f, a2 = a * a, a4 = a2 * a2;
  vf q01 = 1.50140941f + 0.246640727f * a, q23 = -0.00417768164f + -0.00125372503f * a;
  vf q45 = 0.00021858087f + -4.39150654e-06f * a, q67 = -3.5233877e-06f + 3.43273939e-07f * a;
  vf p_lo = (q01 + q23 * a2) + ((q45 + q67 * a2) + 2.81022636e-08f * a4) * a4;
  /* The tail branch only where a lane takes it (|x| > 0.9966, or NaN):
   * most vectors have none, and the selection below is the same. */
  vi lo = w < 5.0f;
  vf p_hi = p_lo;
  if (vany(~lo)) {
    vf b = VSQRT(vmax(w, vset(0.0f))) - 3.0f, b2 = b * b, b4 = b2 * b2;
    vf s01 = 2.83297682f + 1.00167406f * b, s23 = 0.00943887047f + -0.0076224613f * b;
    vf s45 = 0.00573950773f + -0.00367342844f * b, s67 = 0.00134934322f + 0.000100950558f * b;
    p_hi = (s01 + s23 * b2) + ((s45 + s67 * b2) + -0.000200214257f * b4) * b4;
  }
  vf r = vsel(lo, p_lo, p_hi) * x;
  r = vsel(vabs(x) == 1.0f, vcopysign(vset(INFINITY), x), r);
  return vsel(vabs(x) > 1.0f, vset(NAN), r);
}
