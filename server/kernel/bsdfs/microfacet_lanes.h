/* Visible-normal sampling of the Beckmann and GGX distributions, and
 * roughconductor's eval and pdf without Fresnel, across W float lanes:
 * compiled per ISA by simd/lanes_all.h (LANES_FN names the entry points),
 * dispatched by mf_sample_visible_batch() and mf_eval_batch()
 * (bsdfs/microfacet.c).
 *
 * The same algorithms as the scalar samplers of bsdfs/microfacet.c
 * (beckmann_sample_visible: Jakob 2014's Newton inversion; ggx: Heitz
 * 2018), in single precision throughout, so not bitwise the scalar code
 * (which is why both exist). That is safe here for the reason
 * given in microfacet.c's error budget: these values only place the
 * microfacet normal m; the caller evaluates pdf and weight in double from
 * the m drawn (roughconductor.c rough_sample_batch), so a float error only
 * moves probability mass by ~1e-6 and never makes a weight inconsistent
 * with its pdf. The Newton steps of the Beckmann inversion run on all
 * lanes at once; a lane whose residual reached float resolution keeps its
 * x (masked), and the loop ends early only when every lane has. */
#include "../simd/simd.h"

/* ggx != 0 for GGX, else Beckmann; in[0..6]: wi xyz (unit, local, wi.z >
 * 0), alpha_u, alpha_v, u.x, u.y (n each); out[0..5]: wo xyz, pdf (0:
 * failed), weight without Fresnel, wi.m. */
SIMD_ISA_DECL(void, mf_sample_visible, (int ggx, int n, const float *const *in, float *const *out));
/* in[0..7] wi xyz, wo xyz, alpha_u, alpha_v (n each; wi.z > 0, wo.z > 0);
 * out[0..2] value D G / (4 wi.z), pdf, wi.h. */
SIMD_ISA_DECL(void, mf_eval, (int ggx, int visible, int n, const float *const *in, float *const *out));

#ifdef LANES_FN

/* ---- evaluation: roughconductor's eval() and pdf() without Fresnel ------
 *
 * Per lane (wi.z > 0 and wo.z > 0, the caller's test): the half vector
 * h, D(h), Smith's G1 products (Mitsuba's fit for Beckmann, as
 * mf_smith_g1) and, for the pdf, the exact visible G1 (mf_visible_g1) or
 * D cos; out: value = D G / (4 wi.z), pdf = pdf_m(h) / (4 wo.h), and
 * wi.h (for Fresnel, evaluated by the caller in double). Single precision
 * here: value feeds the estimator with a relative rounding of ~1e-6 per
 * sample (not a systematic bias beyond that order), pdf only the MIS
 * weights; both far below any render's noise. verf and vexp as above. */

SIMD_FN vf mf_g1_lanes(int ggx, vf vx, vf vy, vf vz, vf hx, vf hy, vf hz, vf au, vf av) {
  vi back = (vx * hx + vy * hy + vz * hz) * vz <= 0.0f;
  vf ax = au * vx, ay = av * vy;
  vf xy2 = ax * ax + ay * ay;
  vf t = xy2 / (vz * vz);
  vf g;
  if (ggx) {
    g = 2.0f / (1.0f + VSQRT(1.0f + t));
  } else {
    vf a = 1.0f / VSQRT(t), a2 = a * a;
    vf fit = (3.535f * a + 2.181f * a2) / (1.0f + 2.276f * a + 2.577f * a2);
    g = vsel(a >= 1.6f, vset(1.0f), fit);
  }
  g = vsel(xy2 == 0.0f, vset(1.0f), g);
  return vsel(back, vset(0.0f), g);
}

SIMD_FN vf mf_visible_g1_lanes(int ggx, vf vx, vf vy, vf vz, vf hx, vf hy, vf hz, vf au, vf av) {
  if (ggx) return mf_g1_lanes(1, vx, vy, vz, hx, hy, hz, au, av);
  const float inv_sqrt_pi = 0.564189584f;
  vi back = (vx * hx + vy * hy + vz * hz) * vz <= 0.0f;
  vf ax = au * vx, ay = av * vy;
  vf xy2 = ax * ax + ay * ay;
  vf a = vabs(vz) / VSQRT(vsel(xy2 == 0.0f, vset(1.0f), xy2));
  vf ea = vexp(-vmin(a * a, vset(87.0f)));
  vf g = 2.0f / (1.0f + verf(a) + inv_sqrt_pi * ea / a);
  g = vsel(xy2 == 0.0f, vset(1.0f), g);
  return vsel(back, vset(0.0f), g);
}

/* D(h) (mf_D) for unit h: 0 where D cos <= 1e-20 or h.z <= 0; for
 * Beckmann, exp of less than -87 is 0 (the scalar exp's underflow), which
 * also keeps a grazing h's tiny c2^2 out of the division. */
SIMD_FN vf mf_D_lanes(int ggx, vf hx, vf hy, vf hz, vf au, vf av) {
  vf c = hz, c2 = c * c;
  vf xu = hx / au, yv = hy / av;
  vf D;
  if (ggx) {
    vf t = xu * xu + yv * yv + c2;
    D = 1.0f / ((float)RSW_PI * au * av * t * t);
  } else {
    vf arg = (xu * xu + yv * yv) / c2;
    vf e = vexp(-vmin(arg, vset(87.0f)));
    D = vsel(arg < 87.0f, e / ((float)RSW_PI * au * av * c2 * c2), vset(0.0f));
  }
  return vsel((D * c > 1e-20f) & (c > 0.0f), D, vset(0.0f));
}

SIMD_FN void mf_beckmann_lanes(const float *wx, const float *wy, const float *wz, const float *au,
                               const float *av, const float *u0, const float *u1, float *mx, float *my,
                               float *mz) {
  const float inv_sqrt_pi = 0.564189584f;
  vf ax, ay, x0, y0, z0, ux0, uy0;
  __builtin_memcpy(&ax, au, sizeof ax);
  __builtin_memcpy(&ay, av, sizeof ay);
  __builtin_memcpy(&x0, wx, sizeof x0);
  __builtin_memcpy(&y0, wy, sizeof y0);
  __builtin_memcpy(&z0, wz, sizeof z0);
  __builtin_memcpy(&ux0, u0, sizeof ux0);
  __builtin_memcpy(&uy0, u1, sizeof uy0);
  /* Stretch wi to the alpha = 1 configuration. */
  vf px = ax * x0, py = ay * y0, pz = z0;
  vf inv = 1.0f / VSQRT(px * px + py * py + pz * pz);
  px *= inv;
  py *= inv;
  pz *= inv;
  vf sin_t = VSQRT(vmax(1.0f - pz * pz, vset(0.0f)));
  vi has_t = sin_t > 0.0f;
  vf cos_phi = vsel(has_t, vclamp(px / sin_t, -1.0f, 1.0f), vset(1.0f));
  vf sin_phi = vsel(has_t, vclamp(py / sin_t, -1.0f, 1.0f), vset(0.0f));

  /* Slopes for alpha = 1 at incidence cosine ci = pz. */
  vf ci = pz;
  vf sin_i = sin_t;
  vf tan_i = sin_i / ci, cot_i = ci / sin_i; /* cot = inf at normal incidence */
  vf maxval = verf(cot_i);
  ux0 = vclamp(ux0, 1e-6f, 1.0f - 1e-6f);
  uy0 = vclamp(uy0, 1e-6f, 1.0f - 1e-6f);
  vf xx = maxval - (maxval + 1.0f) * verf(VSQRT(-vlog(ux0)));
  vi has_tail = (tan_i > 0.0f) & (cot_i < 9.0f);
  vf cc = vmin(cot_i, vset(9.0f));
  vf tail = vsel(has_tail, inv_sqrt_pi * tan_i * vexp(-cc * cc), vset(0.0f));
  vf ux = ux0 * (1.0f + maxval + tail);
  vf slope = vset(0.0f);
  vi active = (vi){0} - 1; /* lanes still iterating */
  for (int i = 0; i < 3; i++) {
    slope = verfinv(xx);
    vf value = 1.0f + xx + inv_sqrt_pi * tan_i * vexp(-slope * slope) - ux;
    active &= ~(vabs(value) <= 4e-7f * ux);
    if (!vany(active)) break;
    vf deriv = 1.0f - slope * tan_i;
    xx = vsel(active, xx - value / deriv, xx);
  }
  /* Lanes that did not converge: keep x inside erfinv's domain. */
  if (vany(active)) {
    vf xc = vclamp(xx, -1.0f + 6e-8f, 1.0f - 6e-8f);
    slope = vsel(active, verfinv(xc), slope);
  }
  vf sy = verfinv(2.0f * uy0 - 1.0f);

  /* Rotate back to wi's azimuth, unstretch. */
  vf gx = -(cos_phi * slope - sin_phi * sy) * ax;
  vf gy = -(sin_phi * slope + cos_phi * sy) * ay;
  vf n = 1.0f / VSQRT(gx * gx + gy * gy + 1.0f);
  gx *= n;
  gy *= n;
  __builtin_memcpy(mx, &gx, sizeof gx);
  __builtin_memcpy(my, &gy, sizeof gy);
  __builtin_memcpy(mz, &n, sizeof n);
}

SIMD_FN void mf_ggx_lanes(const float *wx, const float *wy, const float *wz, const float *au, const float *av,
                          const float *u0, const float *u1, float *mx, float *my, float *mz) {
  vf ax, ay, x0, y0, z0, ux, uy;
  __builtin_memcpy(&ax, au, sizeof ax);
  __builtin_memcpy(&ay, av, sizeof ay);
  __builtin_memcpy(&x0, wx, sizeof x0);
  __builtin_memcpy(&y0, wy, sizeof y0);
  __builtin_memcpy(&z0, wz, sizeof z0);
  __builtin_memcpy(&ux, u0, sizeof ux);
  __builtin_memcpy(&uy, u1, sizeof uy);
  vf hx = ax * x0, hy = ay * y0, hz = z0;
  vf inv = 1.0f / VSQRT(hx * hx + hy * hy + hz * hz);
  hx *= inv;
  hy *= inv;
  hz *= inv;
  vf lensq = hx * hx + hy * hy;
  vi has = lensq > 0.0f;
  vf il = 1.0f / VSQRT(vsel(has, lensq, vset(1.0f)));
  vf t1x = vsel(has, -hy * il, vset(1.0f)), t1y = vsel(has, hx * il, vset(0.0f));
  /* t2 = vh x t1 (t1.z = 0) */
  vf t2x = -hz * t1y, t2y = hz * t1x, t2z = hx * t1y - hy * t1x;
  vf sf, cf;
  vsincos_turns(uy, &sf, &cf);
  vf r = VSQRT(vmax(ux, vset(0.0f)));
  vf p1 = r * cf, p2 = r * sf;
  vf s = 0.5f * (1.0f + hz);
  p2 = (1.0f - s) * VSQRT(vmax(1.0f - p1 * p1, vset(0.0f))) + s * p2;
  vf pz = VSQRT(vmax(1.0f - p1 * p1 - p2 * p2, vset(0.0f)));
  vf nx = t1x * p1 + t2x * p2 + hx * pz;
  vf ny = t1y * p1 + t2y * p2 + hy * pz;
  vf nz = t2z * p2 + hz * pz;
  vf gx = ax * nx, gy = ay * ny, gz = vmax(nz, vset(0.0f));
  vf n = 1.0f / VSQRT(gx * gx + gy * gy + gz * gz);
  gx *= n;
  gy *= n;
  gz *= n;
  __builtin_memcpy(mx, &gx, sizeof gx);
  __builtin_memcpy(my, &gy, sizeof gy);
  __builtin_memcpy(mz, &gz, sizeof gz);
}

/* The rest of a visible-normal sample from m (unit): wo = 2 (wi.m) m - wi,
 * pdf = D(m) G1vis(wi, m) |wi.m| / wi.z / (4 wo.m) and weight = eval / pdf
 * = G1(wo, m) G1(wi, m) / G1vis(wi, m) without Fresnel, all in single
 * precision: pdf and weight are then consistent with each other to
 * float rounding (~1e-6 relative), which is what an unbiased estimator
 * needs; pdf() in double is the density that the chi-square tests check
 * the m drawn against. pdf = 0 marks a failed sample. */
SIMD_FN void mf_sample_tail_lanes(int ggx, const float *const *in, const float *m3, float *const *out,
                                  int k0) {
  vf wx, wy, wz, au, av, mx, my, mz;
  __builtin_memcpy(&wx, in[0] + k0, sizeof wx);
  __builtin_memcpy(&wy, in[1] + k0, sizeof wy);
  __builtin_memcpy(&wz, in[2] + k0, sizeof wz);
  __builtin_memcpy(&au, in[3] + k0, sizeof au);
  __builtin_memcpy(&av, in[4] + k0, sizeof av);
  __builtin_memcpy(&mx, m3 + 0 * W, sizeof mx);
  __builtin_memcpy(&my, m3 + 1 * W, sizeof my);
  __builtin_memcpy(&mz, m3 + 2 * W, sizeof mz);
  vf wi_m = wx * mx + wy * my + wz * mz;
  vf ox = 2.0f * wi_m * mx - wx, oy = 2.0f * wi_m * my - wy, oz = 2.0f * wi_m * mz - wz;
  vf wo_m = ox * mx + oy * my + oz * mz;
  vf D = mf_D_lanes(ggx, mx, my, mz, au, av);
  vf g1vis = mf_visible_g1_lanes(ggx, wx, wy, wz, mx, my, mz, au, av);
  vf pdf_m = D * g1vis * vabs(wi_m) / wz;
  vi ok = (pdf_m > 0.0f) & (oz > 0.0f) & (wo_m > 0.0f);
  vf pdf = vsel(ok, pdf_m / (4.0f * vsel(ok, wo_m, vset(1.0f))), vset(0.0f));
  vf g_o = mf_g1_lanes(ggx, ox, oy, oz, mx, my, mz, au, av);
  vf g_i = mf_g1_lanes(ggx, wx, wy, wz, mx, my, mz, au, av);
  vf weight = vsel(ok, g_o * (g_i / vsel(ok, g1vis, vset(1.0f))), vset(0.0f));
  __builtin_memcpy(out[0] + k0, &ox, sizeof ox);
  __builtin_memcpy(out[1] + k0, &oy, sizeof oy);
  __builtin_memcpy(out[2] + k0, &oz, sizeof oz);
  __builtin_memcpy(out[3] + k0, &pdf, sizeof pdf);
  __builtin_memcpy(out[4] + k0, &weight, sizeof weight);
  __builtin_memcpy(out[5] + k0, &wi_m, sizeof wi_m);
}

/* One vector of samples: lanes k0.. of in[0..6], results to out[0..5] +
 * k0, the microfacet normals in between in a local vector triple. */
SIMD_FN void mf_sample_visible_lanes(int ggx, const float *const *in, float *const *out, int k0) {
  float m3[3 * W];
  if (ggx)
    mf_ggx_lanes(in[0] + k0, in[1] + k0, in[2] + k0, in[3] + k0, in[4] + k0, in[5] + k0, in[6] + k0, m3,
                 m3 + W, m3 + 2 * W);
  else
    mf_beckmann_lanes(in[0] + k0, in[1] + k0, in[2] + k0, in[3] + k0, in[4] + k0, in[5] + k0, in[6] + k0, m3,
                      m3 + W, m3 + 2 * W);
  mf_sample_tail_lanes(ggx, in, m3, out, k0);
}

/* n lanes (any n >= 0): whole vectors straight from and to the caller's
 * arrays; a partial tail through a padded copy (normal incidence, u =
 * 1/2, alpha = 1; its results are dropped). in[0..6]: wi xyz, alpha_u,
 * alpha_v, u.x, u.y; out[0..5]: wo xyz, pdf, weight without Fresnel,
 * wi.m. */
LANES_ATTR void LANES_FN(mf_sample_visible)(int ggx, int n, const float *const *in, float *const *out) {
  int k0 = 0;
  for (; k0 + W <= n; k0 += W) mf_sample_visible_lanes(ggx, in, out, k0);
  if (k0 < n) {
    int m = n - k0;
    float a[7][W], b[6][W];
    const float pad[7] = {0.0f, 0.0f, 1.0f, 1.0f, 1.0f, 0.5f, 0.5f};
    for (int j = 0; j < 7; j++)
      for (int k = 0; k < W; k++) a[j][k] = k < m ? in[j][k0 + k] : pad[j];
    const float *ap[7] = {a[0], a[1], a[2], a[3], a[4], a[5], a[6]};
    float *bp[6] = {b[0], b[1], b[2], b[3], b[4], b[5]};
    mf_sample_visible_lanes(ggx, ap, bp, 0);
    for (int j = 0; j < 6; j++)
      for (int k = 0; k < m; k++) out[j][k0 + k] = b[j][k];
  }
}

/* One vector of lanes from in[j] + k0 (8 arrays: wi xyz, wo xyz, alpha_u,
 * alpha_v), results to out[j] + k0 (value, pdf, wi.h): loaded from and
 * stored to the caller's arrays directly. */
SIMD_FN void mf_eval_lanes(int ggx, int visible, const float *const *in, float *const *out, int k0) {
  vf wx, wy, wz, ox, oy, oz, au, av;
  __builtin_memcpy(&wx, in[0] + k0, sizeof wx);
  __builtin_memcpy(&wy, in[1] + k0, sizeof wy);
  __builtin_memcpy(&wz, in[2] + k0, sizeof wz);
  __builtin_memcpy(&ox, in[3] + k0, sizeof ox);
  __builtin_memcpy(&oy, in[4] + k0, sizeof oy);
  __builtin_memcpy(&oz, in[5] + k0, sizeof oz);
  __builtin_memcpy(&au, in[6] + k0, sizeof au);
  __builtin_memcpy(&av, in[7] + k0, sizeof av);
  vf hx = wx + ox, hy = wy + oy, hz = wz + oz;
  vf hl = VSQRT(hx * hx + hy * hy + hz * hz);
  vf ih = 1.0f / vsel(hl > 0.0f, hl, vset(1.0f));
  hx *= ih;
  hy *= ih;
  hz *= ih;
  vf D = mf_D_lanes(ggx, hx, hy, hz, au, av);
  vf G = mf_g1_lanes(ggx, wx, wy, wz, hx, hy, hz, au, av) * mf_g1_lanes(ggx, ox, oy, oz, hx, hy, hz, au, av);
  vf value = D * G / (4.0f * wz);
  vf wi_h = wx * hx + wy * hy + wz * hz, wo_h = ox * hx + oy * hy + oz * hz;
  vf pdf_m;
  if (visible)
    pdf_m = D * mf_visible_g1_lanes(ggx, wx, wy, wz, hx, hy, hz, au, av) * vabs(wi_h) / wz;
  else
    pdf_m = D * hz;
  vf pdf = vsel((wi_h > 0.0f) & (wo_h > 0.0f), pdf_m / (4.0f * wo_h), vset(0.0f));
  __builtin_memcpy(out[0] + k0, &value, sizeof value);
  __builtin_memcpy(out[1] + k0, &pdf, sizeof pdf);
  __builtin_memcpy(out[2] + k0, &wi_h, sizeof wi_h);
}

/* n lanes; in: 8 arrays of n (wi xyz, wo xyz, alpha_u, alpha_v); out: 3
 * arrays of n (value, pdf, wi.h). Whole vectors straight from and to the
 * caller's arrays; a partial tail through a padded copy (wi = wo = +z,
 * alpha 1). */
LANES_ATTR void LANES_FN(mf_eval)(int ggx, int visible, int n, const float *const *in, float *const *out) {
  int k0 = 0;
  for (; k0 + W <= n; k0 += W) mf_eval_lanes(ggx, visible, in, out, k0);
  if (k0 < n) {
    int m = n - k0;
    float a[8][W], b[3][W];
    const float pad[8] = {0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 1.0f, 1.0f, 1.0f};
    for (int j = 0; j < 8; j++)
      for (int k = 0; k < W; k++) a[j][k] = k < m ? in[j][k0 + k] : pad[j];
    const float *ap[8] = {a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]};
    float *bp[3] = {b[0], b[1], b[2]};
    mf_eval_lanes(ggx, visible, ap, bp, 0);
    for (int j = 0; j < 3; j++)
      for (int k = 0; k < m; k++) out[j][k0 + k] = b[j][k];
  }
}
#endif
