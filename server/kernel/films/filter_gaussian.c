/* The gaussian filter's weights of a footprint (filter_gaussian.h):
 * splat_filter (render.c) needs 2 x 4 of them per sample, which as libm
 * calls were ~5% of the Cornell box. Built at -O3 (Makefile SEED_O3). */
#include <math.h>
#include <string.h>

#include "../core/vexp_lanes.h"
#include "filter_gaussian.h"

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
    vexp_v8(&e);
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
static __attribute__((target("avx512f,avx512vl,avx512dq"))) void gaussian_avx512(const filter_footprint *fp,
                                                                                 double *restrict out) {
  gaussian_body(fp, out);
}
static __attribute__((target("avx2,fma"))) void gaussian_avx2(const filter_footprint *fp,
                                                              double *restrict out) {
  gaussian_body(fp, out);
}
#endif
/* sse2 and generic: libm's fma() (core/vexp_lanes.h). */
static void gaussian_base(const filter_footprint *fp, double *restrict out) {
  gaussian_body(fp, out);
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
