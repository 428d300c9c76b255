/* Double-precision lane helpers (dsel, dabs) and the warps the batched
 * kernels share (core/warp.c's concentric disk map; the cosine-weighted
 * hemisphere, which diffuse, bilambertian and rpv sample with): part of
 * simd/lanes_all.h, after simd/lanes.h.
 *
 * Double precision on purpose: the hemisphere and concentric warps keep
 * double everywhere (core/warp.c: a float angle would move directions near
 * the poles by ~1e-7 rad relative to their tiny radius). The operations
 * are those of the scalar warps in the same order, without FMA
 * contraction, so each lane gives the scalar value bit for bit
 * (tests/unit/test_simd.c checks it). */

typedef double vdn __attribute__((vector_size(4 * W)));
typedef long long vln __attribute__((vector_size(4 * W)));
#define WD (W / 2)

SIMD_FN vdn dsel(vln m, vdn a, vdn b) {
  return (vdn)(((vln)a & m) | ((vln)b & ~m));
}
SIMD_FN vdn dabs(vdn a) {
  return (vdn)((vln)a & 0x7fffffffffffffffLL);
}

/* core/vec.h v3_norm: (x, y, z) over its length where that is > 0, else
 * unchanged, through the reciprocal as v3_norm does it. */
SIMD_FN void d_norm3(vdn *x, vdn *y, vdn *z) {
  vdn l = VSQRT_D(*x * *x + *y * *y + *z * *z);
  vln pos = l > 0.0;
  vdn il = 1.0 / dsel(pos, l, (vdn){0} + 1.0);
  *x = dsel(pos, *x * il, *x);
  *y = dsel(pos, *y * il, *y);
  *z = dsel(pos, *z * il, *z);
}

/* core/warp.c sincos_quarter: sin and cos of (pi/4) t, |t| <= 1. */
SIMD_FN void d_sincos_quarter(vdn t, vdn *s, vdn *c) {
  vdn x = 0.78539816339744830962 * t, x2 = x * x;
  vdn ps = (vdn){0} + -1.0 / 1307674368000.0;
  ps = 1.0 / 6227020800.0 + ps * x2;
  ps = -1.0 / 39916800.0 + ps * x2;
  ps = 1.0 / 362880.0 + ps * x2;
  ps = -1.0 / 5040.0 + ps * x2;
  ps = 1.0 / 120.0 + ps * x2;
  ps = -1.0 / 6.0 + ps * x2;
  vdn pc = (vdn){0} + 1.0 / 20922789888000.0;
  pc = -1.0 / 87178291200.0 + pc * x2;
  pc = 1.0 / 479001600.0 + pc * x2;
  pc = -1.0 / 3628800.0 + pc * x2;
  pc = 1.0 / 40320.0 + pc * x2;
  pc = -1.0 / 720.0 + pc * x2;
  pc = 1.0 / 24.0 + pc * x2;
  pc = -0.5 + pc * x2;
  *s = x + x * x2 * ps;
  *c = 1.0 + x2 * pc;
}

/* core/warp.c warp_square_to_disk_concentric, both branches selected. */
SIMD_FN void d_concentric(vdn ux, vdn uy, vdn *px, vdn *py) {
  vdn a = 2.0 * ux - 1.0, b = 2.0 * uy - 1.0;
  vln zero = (a == 0.0) & (b == 0.0);
  vln m = dabs(a) < dabs(b);
  vdn num = dsel(m, a, b), den = dsel(m, b, a);
  den = dsel(zero, (vdn){0} + 1.0, den); /* no 0/0 (its lanes are set to 0 below) */
  vdn s, c;
  d_sincos_quarter(num / den, &s, &c);
  vdn x = dsel(m, den * s, den * c), y = dsel(m, den * c, den * s);
  *px = dsel(zero, (vdn){0}, x);
  *py = dsel(zero, (vdn){0}, y);
}

/* Cosine-weighted hemisphere directions for n lanes (core/warp.c
 * warp_square_to_cosine_hemisphere, same operations: bitwise the scalar
 * directions): u 2 per lane (x, y), out 3 per lane. */
LANES_ATTR void LANES_FN(cosine_hemisphere)(int n, const double *u, double *out) {
  for (int k0 = 0; k0 < n; k0 += WD) {
    int cnt = n - k0 < WD ? n - k0 : WD;
    /* Loops of constant length (a partial tail goes through a padded
     * copy), so lanes move through registers: element inserts of a
     * variable count went through memory and stalled store forwarding. */
    const double *uk = u + 2 * k0;
    double pad[2 * WD], res[3 * WD];
    if (cnt < WD) {
      for (int k = 0; k < 2 * WD; k++) pad[k] = k < 2 * cnt ? uk[k] : 0.5;
      uk = pad;
    }
    vdn ux, uy;
    for (int k = 0; k < WD; k++) ux[k] = uk[2 * k], uy[k] = uk[2 * k + 1];
    vdn px, py;
    d_concentric(ux, uy, &px, &py);
    vdn r = 1.0 - (px * px + py * py);
    vdn z = VSQRT_D(dsel(r > 0.0, r, (vdn){0}));
    double *o = cnt < WD ? res : &out[3 * k0];
    for (int k = 0; k < WD; k++) o[3 * k] = px[k], o[3 * k + 1] = py[k], o[3 * k + 2] = z[k];
    if (cnt < WD)
      for (int k = 0; k < 3 * cnt; k++) out[3 * k0 + k] = res[k];
  }
}
