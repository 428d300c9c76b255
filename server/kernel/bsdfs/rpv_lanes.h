/* rpv's batched BRF factor (bsdfs/rpv.c rpv_sample_batch, rpv_eval_pdf_batch):
 * the float lanes, compiled per ISA by simd/lanes_all.h; LANES_FN names
 * the entry points, dispatched in rpv.c. A fixed sequence of lane-wise
 * operations (simd/lanes.h), so a lane's result depends on its own inputs
 * only. */
#include "../simd/simd.h"

/* in[0..8]: wi xyz, wo xyz (local, z > 0), k, g, rho_c (n each); out: n
 * factors M F H = pi f_r / rho_0. */
SIMD_ISA_DECL(void, rpv_factor, (int n, const float *const *in, float *out));

#ifdef LANES_FN
/* ---- rpv: M F H = pi f_r / rho_0, float lanes -----------------------------
 * bsdfs/rpv.c gives the formulas. Single precision: the value feeds the
 * estimator (sample weight, eval) with a relative rounding of a few 1e-7,
 * at worst 3e-6 (measured over 6e5 random direction pairs; pow as
 * exp(e log x) with Cephes' vexp/vlog loses ~1e-6 where |e log x| reaches
 * ~10, i.e. grazing directions), no systematic bias beyond that; rho_0 multiplies in double (rpv.c), so k = 1, g = 0,
 * rho_c = 1 still gives diffuse's numbers exactly (M = F = H = 1 exactly
 * here). in[0..8]: wi xyz, wo xyz (local, both z > 0), k, g, rho_c. */
SIMD_FN void rpv_dir_angles(vf x, vf y, vf *s, vf *cp, vf *sp) {
  vf r = VSQRT(x * x + y * y);
  vi pos = r > 0.0f;
  vf ir = 1.0f / vsel(pos, r, vset(1.0f));
  *s = r;
  *cp = vsel(pos, x * ir, vset(1.0f));
  *sp = vsel(pos, y * ir, vset(0.0f));
}

SIMD_FN vf rpv_factor_lanes(const vf *v) {
  vf ci = v[2], co = v[5], k = v[6], g = v[7], rho_c = v[8];
  vf si, cpi, spi, so, cpo, spo;
  rpv_dir_angles(v[0], v[1], &si, &cpi, &spi);
  rpv_dir_angles(v[3], v[4], &so, &cpo, &spo);
  vf cos_dphi = cpi * cpo + spi * spo;
  vf cos_big = ci * co + si * so * cos_dphi;
  vf ti = si / ci, to = so / co;
  /* G^2 = ti^2 + to^2 - 2 ti to cos(dphi), written without its
   * cancellation near the hot spot (wi ~ wo, where G -> 0 and float lost
   * 2e-5 of H): (ti - to)^2 + ti to 2 (1 - cos(dphi)), with 2 (1 -
   * cos(dphi)) = (cpi - cpo)^2 + (spi - spo)^2 for unit azimuth vectors. */
  vf dc = cpi - cpo, ds = spi - spo, dt = ti - to;
  vf g2 = dt * dt + ti * to * (dc * dc + ds * ds);
  vf gg = VSQRT(vmax(g2, vset(0.0f)));
  vf mbase = ci * co * (ci + co);
  vf x = 1.0f + g * g + 2.0f * g * cos_big;
  vf f = (1.0f - g * g) / (x * VSQRT(vmax(x, vset(0.0f))));
  vf h = 1.0f + (1.0f - rho_c) / (1.0f + gg);
  vf e = k - 1.0f;
  vf m = vsel(e == 0.0f, vset(1.0f), vexp(e * vlog(mbase)));
  return m * f * h;
}

/* n lanes; in: 9 arrays of n; out: n factors. Padding: normal incidence
 * and exitance, k 1, g 0, rho_c 1. */
LANES_ATTR void LANES_FN(rpv_factor)(int n, const float *const *in, float *out) {
  for (int k0 = 0; k0 < n; k0 += W) {
    int m = n - k0 < W ? n - k0 : W;
    vf v[9];
    if (m == W) { /* whole vectors: plain loads and stores */
      for (int j = 0; j < 9; j++) __builtin_memcpy(&v[j], in[j] + k0, sizeof v[j]);
      vf r = rpv_factor_lanes(v);
      __builtin_memcpy(out + k0, &r, sizeof r);
      continue;
    }
    float a[9 * W];
    const float pad[9] = {0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 1.0f, 1.0f, 0.0f, 1.0f};
    for (int j = 0; j < 9; j++)
      for (int k = 0; k < W; k++) a[j * W + k] = k < m ? in[j][k0 + k] : pad[j];
    for (int j = 0; j < 9; j++) __builtin_memcpy(&v[j], a + j * W, sizeof v[j]);
    vf r = rpv_factor_lanes(v);
    for (int k = 0; k < m; k++) out[k0 + k] = r[k];
  }
}
#endif

/* rpv's exact batch (bsdfs/rpv.c rpv_sample_batch_exact,
 * rpv_eval_pdf_batch_exact): the direction terms and F, H of
 * rpv_geometry() and rpv_brf_geom() in double lanes, the same operations
 * in the same order without FMA contraction, so each lane is the scalar
 * code's bits (M's pow stays in libm, per lane, in rpv.c). in[0..7]: wi
 * xyz, wo xyz (local, z > 0), g, rho_c (n each); out[0..2]: mbase, F, H. */
SIMD_ISA_DECL(void, rpv_terms_exact, (int n, const double *const *in, double *const *out));

#ifdef LANES_FN
/* dir_angles() of rpv.c: sin(theta), and the azimuth's cosine and sine
 * as x / s, y / s (1 and 0 at the pole). */
SIMD_FN void rpv_dir_angles_d(vdn x, vdn y, vdn *s, vdn *cp, vdn *sp) {
  vdn r = VSQRT_D(x * x + y * y);
  vln pos = r > 0.0;
  vdn q = dsel(pos, r, (vdn){0} + 1.0);
  *s = r;
  *cp = dsel(pos, x / q, (vdn){0} + 1.0);
  *sp = dsel(pos, y / q, (vdn){0});
}

LANES_ATTR void LANES_FN(rpv_terms_exact)(int n, const double *const *in, double *const *out) {
  for (int k0 = 0; k0 < n; k0 += WD) {
    int m = n - k0 < WD ? n - k0 : WD;
    vdn v[8];
    if (m == WD) {
      for (int j = 0; j < 8; j++) __builtin_memcpy(&v[j], in[j] + k0, sizeof v[j]);
    } else { /* a partial tail: its last lane repeated */
      double a[8][WD];
      for (int j = 0; j < 8; j++)
        for (int k = 0; k < WD; k++) a[j][k] = in[j][k0 + (k < m ? k : m - 1)];
      for (int j = 0; j < 8; j++) __builtin_memcpy(&v[j], a[j], sizeof v[j]);
    }
    vdn ci = v[2], co = v[5], g = v[6], rho_c = v[7];
    vdn si, cpi, spi, so, cpo, spo;
    rpv_dir_angles_d(v[0], v[1], &si, &cpi, &spi);
    rpv_dir_angles_d(v[3], v[4], &so, &cpo, &spo);
    vdn cos_dphi = cpi * cpo + spi * spo;
    vdn cos_big = ci * co + si * so * cos_dphi;
    vdn ti = si / ci, to = so / co;
    vdn g2 = ti * ti + to * to - 2.0 * ti * to * cos_dphi;
    /* sqrt(fmax(g2, 0)): NaN and g2 <= 0 give a zero (of either sign,
     * which only ever meets 1 + G) */
    vdn gg = VSQRT_D(dsel(g2 > 0.0, g2, (vdn){0}));
    vdn mbase = ci * co * (ci + co);
    vdn fb = 1.0 + g * g + 2.0 * g * cos_big;
    vdn f = (1.0 - g * g) / (fb * VSQRT_D(fb));
    vdn h = 1.0 + (1.0 - rho_c) / (1.0 + gg);
    vdn r[3] = {mbase, f, h};
    for (int j = 0; j < 3; j++) {
      if (m == WD)
        __builtin_memcpy(out[j] + k0, &r[j], sizeof r[j]);
      else
        for (int k = 0; k < m; k++) out[j][k0 + k] = r[j][k];
    }
  }
}
#endif
