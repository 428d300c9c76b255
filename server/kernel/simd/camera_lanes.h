/* hdistant camera rays across W/2 double lanes (the per-ISA body of
 * simd/mf_*.c, after simd/lanes.h; CAM_LANES_FN names the entry point).
 *
 * Double precision on purpose: the hemisphere and concentric warps keep
 * double everywhere (core/warp.c: a float angle would move directions near
 * the poles by ~1e-7 rad relative to their tiny radius), and the origin
 * sits a bounding radius away from the scene. The operations are those of
 * the scalar path (warp_square_to_uniform_hemisphere, xf_vector, v3_norm,
 * ray_target_origin without a target) in the same order, without FMA
 * contraction, so each lane gives the scalar ray bit for bit
 * (tests/kernel/simd/test_simd.c checks it). */

typedef double vdn __attribute__((vector_size(4 * W)));
typedef long long vln __attribute__((vector_size(4 * W)));
#define WD (W / 2)

SIMD_FN vdn dsel(vln m, vdn a, vdn b) {
  return (vdn)(((vln)a & m) | ((vln)b & ~m));
}
SIMD_FN vdn dabs(vdn a) {
  return (vdn)((vln)a & 0x7fffffffffffffffLL);
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

/* n rays: rows m[3][3] of to_world; fu, ap film and aperture samples (x,
 * y interleaved per lane: fu[2 i], fu[2 i + 1]); out[6 i ..] = o, d. */
CAM_LANES_ATTR void CAM_LANES_FN(int n, const double (*m)[4], const double *fu, const double *ap,
                                 const double *center, double radius, double offset, double *out) {
  for (int k0 = 0; k0 < n; k0 += WD) {
    int cnt = n - k0 < WD ? n - k0 : WD;
    /* Constant-length loops through a padded copy for a partial tail (see
     * COSINE_LANES_FN below). */
    const double *fk = fu + 2 * k0, *ak = ap + 2 * k0;
    double fpad[2 * WD], apad[2 * WD], res[6 * WD];
    if (cnt < WD) {
      for (int k = 0; k < 2 * WD; k++)
        fpad[k] = k < 2 * cnt ? fk[k] : 0.5, apad[k] = k < 2 * cnt ? ak[k] : 0.5;
      fk = fpad, ak = apad;
    }
    vdn ux, uy, ax, ay;
    for (int k = 0; k < WD; k++)
      ux[k] = fk[2 * k], uy[k] = fk[2 * k + 1], ax[k] = ak[2 * k], ay[k] = ak[2 * k + 1];
    /* omega = norm(to_world hemisphere(fu)), d = -omega */
    vdn px, py;
    d_concentric(ux, uy, &px, &py);
    vdn z = 1.0 - (px * px + py * py);
    vdn z1 = z + 1.0;
    vdn s = VSQRT_D(dsel(z1 > 0.0, z1, (vdn){0}));
    vdn vx = px * s, vy = py * s;
    vdn wx = m[0][0] * vx + m[0][1] * vy + m[0][2] * z;
    vdn wy = m[1][0] * vx + m[1][1] * vy + m[1][2] * z;
    vdn wz = m[2][0] * vx + m[2][1] * vy + m[2][2] * z;
    vdn l = VSQRT_D(wx * wx + wy * wy + wz * wz);
    vln pos = l > 0.0;
    vdn il = 1.0 / dsel(pos, l, (vdn){0} + 1.0);
    wx = dsel(pos, wx * il, wx);
    wy = dsel(pos, wy * il, wy);
    wz = dsel(pos, wz * il, wz);
    vdn dx = -wx, dy = -wy, dz = -wz;
    /* origin: centre + radius to_world (concentric(ap), 0), back by offset */
    vdn qx, qy;
    d_concentric(ax, ay, &qx, &qy);
    vdn rx = m[0][0] * qx + m[0][1] * qy + m[0][2] * 0.0;
    vdn ry = m[1][0] * qx + m[1][1] * qy + m[1][2] * 0.0;
    vdn rz = m[2][0] * qx + m[2][1] * qy + m[2][2] * 0.0;
    vdn ox = (center[0] + radius * rx) + -offset * dx;
    vdn oy = (center[1] + radius * ry) + -offset * dy;
    vdn oz = (center[2] + radius * rz) + -offset * dz;
    double *ob = cnt < WD ? res : &out[6 * k0];
    for (int k = 0; k < WD; k++) {
      double *o = &ob[6 * k];
      o[0] = ox[k], o[1] = oy[k], o[2] = oz[k];
      o[3] = dx[k], o[4] = dy[k], o[5] = dz[k];
    }
    if (cnt < WD)
      for (int k = 0; k < 6 * cnt; k++) out[6 * k0 + k] = res[k];
  }
}

/* Cosine-weighted hemisphere directions for n lanes (core/warp.c
 * warp_square_to_cosine_hemisphere, same operations: bitwise the scalar
 * directions): u 2 per lane (x, y), out 3 per lane. */
CAM_LANES_ATTR void COSINE_LANES_FN(int n, const double *u, double *out) {
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
