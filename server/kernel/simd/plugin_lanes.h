/* Lane bodies of the batched BSDF and sensor ops beyond roughconductor and
 * hdistant (issue 12 point 3): rpv's BRF factor (float lanes), the
 * conductor Fresnel term (double lanes), the distant family's disk origins
 * and the perspective camera's rays (double lanes). Included by each
 * per-ISA file after simd/lanes.h and simd/camera_lanes.h, with
 * ISA_SUFFIX naming the ISA (entry points NAME_<suffix>, simd.h) and
 * CAM_LANES_ATTR its target attribute.
 *
 * Every routine is a fixed sequence of lane-wise operations (lanes.h), so
 * a lane's result depends on its own inputs only. The double-lane ones
 * repeat the scalar code's operations in its order (no FMA contraction:
 * -std=c11), so they give the scalar results bit for bit
 * (tests/kernel/simd/test_simd.c checks it). */

#define PL_CAT2(a, b) a##_##b
#define PL_CAT(a, b)  PL_CAT2(a, b)
#define PL_NAME(f)    PL_CAT(f, ISA_SUFFIX)

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
CAM_LANES_ATTR void PL_NAME(rpv_factor)(int n, const float *const *in, float *out) {
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

/* ---- conductor Fresnel, double lanes --------------------------------------
 * bsdfs/fresnel.c fresnel_conductor(), the same operations in the same
 * order (fmax(x, 0) as a select, the same for every x but -0, where
 * sqrt(+-0) only changes the sign of a zero that is then added to a
 * positive number): bitwise the scalar value. cos_i, eta, k, out: n each. */
CAM_LANES_ATTR void PL_NAME(fresnel_conductor)(int n, const double *cos_i, const double *eta,
                                               const double *kk, double *out) {
  for (int k0 = 0; k0 < n; k0 += WD) {
    int cnt = n - k0 < WD ? n - k0 : WD;
    vdn ci, et, kv;
    if (cnt == WD) { /* whole vectors: plain loads (element inserts stall on store forwarding) */
      __builtin_memcpy(&ci, cos_i + k0, sizeof ci);
      __builtin_memcpy(&et, eta + k0, sizeof et);
      __builtin_memcpy(&kv, kk + k0, sizeof kv);
    } else {
      ci = (vdn){0} + 1.0, et = (vdn){0}, kv = (vdn){0} + 1.0;
      for (int j = 0; j < cnt; j++) ci[j] = cos_i[k0 + j], et[j] = eta[k0 + j], kv[j] = kk[k0 + j];
    }
    vdn c = dabs(ci);
    c = dsel(c > 1.0, (vdn){0} + 1.0, c);
    vdn c2 = c * c, s2 = 1.0 - c2, s4 = s2 * s2;
    vdn eta2 = et * et, k2 = kv * kv;
    vdn t1 = eta2 - k2 - s2;
    vdn A = VSQRT_D(t1 * t1 + 4.0 * eta2 * k2);
    vdn ha = 0.5 * (A + t1);
    vdn a = VSQRT_D(dsel(ha > 0.0, ha, (vdn){0}));
    vdn ca2 = 2.0 * c * a;
    vdn rs_num = A + c2 - ca2, rs_den = A + c2 + ca2;
    vln rs_ok = rs_den > 0.0;
    vdn rs = dsel(rs_ok, rs_num / dsel(rs_ok, rs_den, (vdn){0} + 1.0), (vdn){0} + 1.0);
    vdn rp_num = A * c2 + s4 - ca2 * s2, rp_den = A * c2 + s4 + ca2 * s2;
    vln rp_ok = rp_den > 0.0;
    vdn rp = dsel(rp_ok, rs * rp_num / dsel(rp_ok, rp_den, (vdn){0} + 1.0), rs);
    vdn r = 0.5 * (rs + rp);
    if (cnt == WD)
      __builtin_memcpy(out + k0, &r, sizeof r);
    else
      for (int j = 0; j < cnt; j++) out[k0 + j] = r[j];
  }
}

/* ---- distant family: origins on the bounding disk, double lanes ----------
 * sensors/sensor_common.c ray_target_origin() without a target:
 *   q = square_to_disk_concentric(ap), perp = frame (q.x, q.y, 0),
 *   o = (c + R perp) - offset d.
 * m9: the frame's 3x3 rows (9 doubles per lane, or one shared frame with
 * m_step 0); d: 3 per lane (d_step 3) or shared (0); ap 2 per lane; out 3
 * per lane. */
CAM_LANES_ATTR void PL_NAME(disk_origins)(int n, const double *m9, int m_step, const double *d, int d_step,
                                          const double *ap, const double *center, double radius,
                                          double offset, double *out) {
  for (int k0 = 0; k0 < n; k0 += WD) {
    int cnt = n - k0 < WD ? n - k0 : WD;
    /* Loops of constant length over the lanes (a partial tail goes through
     * a padded copy, or repeats its last lane), so lanes move through
     * registers: element inserts of a variable count went through memory
     * and stalled store forwarding (2-3x slower). */
    vdn ax, ay, mm[9], dx, dy, dz;
    double res[3 * WD];
    const double *ak = ap + 2 * k0;
    double apad[2 * WD];
    if (cnt < WD) {
      for (int k = 0; k < 2 * WD; k++) apad[k] = k < 2 * cnt ? ak[k] : 0.5;
      ak = apad;
    }
    for (int k = 0; k < WD; k++) ax[k] = ak[2 * k], ay[k] = ak[2 * k + 1];
    if (m_step == 0) { /* one frame: broadcast */
      for (int j = 0; j < 9; j++) mm[j] = (vdn){0} + m9[j];
    } else {
      for (int k = 0; k < WD; k++) {
        const double *mk = m9 + (long)m_step * (k0 + (k < cnt ? k : cnt - 1));
        for (int j = 0; j < 9; j++) mm[j][k] = mk[j];
      }
    }
    if (d_step == 0) {
      dx = (vdn){0} + d[0], dy = (vdn){0} + d[1], dz = (vdn){0} + d[2];
    } else {
      for (int k = 0; k < WD; k++) {
        const double *dk = d + (long)d_step * (k0 + (k < cnt ? k : cnt - 1));
        dx[k] = dk[0], dy[k] = dk[1], dz[k] = dk[2];
      }
    }
    vdn qx, qy;
    d_concentric(ax, ay, &qx, &qy);
    vdn rx = mm[0] * qx + mm[1] * qy + mm[2] * 0.0;
    vdn ry = mm[3] * qx + mm[4] * qy + mm[5] * 0.0;
    vdn rz = mm[6] * qx + mm[7] * qy + mm[8] * 0.0;
    vdn ox = (center[0] + radius * rx) + -offset * dx;
    vdn oy = (center[1] + radius * ry) + -offset * dy;
    vdn oz = (center[2] + radius * rz) + -offset * dz;
    double *ob = cnt < WD ? res : &out[3 * k0];
    for (int k = 0; k < WD; k++) ob[3 * k] = ox[k], ob[3 * k + 1] = oy[k], ob[3 * k + 2] = oz[k];
    if (cnt < WD)
      for (int k = 0; k < 3 * cnt; k++) out[3 * k0 + k] = res[k];
  }
}

/* ---- perspective camera rays, double lanes --------------------------------
 * sensors/perspective.c perspective_sample_ray(): with s = fu + pp,
 *   v = ((1 - 2 s.x) t, (1 - 2 s.y) t / aspect, 1), d = v / |v|,
 *   ray.d = to_world d, tmin = near / d.z, tmax = far / d.z (as near
 *   (1 / d.z)); origin the translation column (per lane, the same).
 * m: to_world's rows; pp: principal point offset (x, y); fu 2 per lane;
 * out 8 per lane (o xyz, d xyz, tmin, tmax: a ray3's layout, so the
 * caller may pass its rays). */
CAM_LANES_ATTR void PL_NAME(perspective_rays)(int n, const double (*m)[4], const double *pp, double t,
                                              double aspect, double near_clip, double far_clip,
                                              const double *fu, double *out) {
  for (int k0 = 0; k0 < n; k0 += WD) {
    int cnt = n - k0 < WD ? n - k0 : WD;
    vdn ux, uy; /* constant-length loops (see disk_origins) */
    double res[8 * WD];
    const double *fk = fu + 2 * k0;
    double fpad[2 * WD];
    if (cnt < WD) {
      for (int k = 0; k < 2 * WD; k++) fpad[k] = k < 2 * cnt ? fk[k] : 0.5;
      fk = fpad;
    }
    for (int k = 0; k < WD; k++) ux[k] = fk[2 * k], uy[k] = fk[2 * k + 1];
    vdn sx = ux + pp[0], sy = uy + pp[1];
    vdn vx = (1.0 - 2.0 * sx) * t, vy = (1.0 - 2.0 * sy) * t / aspect, vz = (vdn){0} + 1.0;
    vdn l = VSQRT_D(vx * vx + vy * vy + vz * vz);
    vln pos = l > 0.0;
    vdn il = 1.0 / dsel(pos, l, (vdn){0} + 1.0);
    vx = dsel(pos, vx * il, vx);
    vy = dsel(pos, vy * il, vy);
    vz = dsel(pos, vz * il, vz);
    vdn wx = m[0][0] * vx + m[0][1] * vy + m[0][2] * vz;
    vdn wy = m[1][0] * vx + m[1][1] * vy + m[1][2] * vz;
    vdn wz = m[2][0] * vx + m[2][1] * vy + m[2][2] * vz;
    vdn inv_z = 1.0 / vz;
    vdn tmin = near_clip * inv_z, tmax = far_clip * inv_z;
    double *ob = cnt < WD ? res : &out[8 * k0];
    for (int k = 0; k < WD; k++) {
      double *o = &ob[8 * k];
      o[0] = m[0][3], o[1] = m[1][3], o[2] = m[2][3];
      o[3] = wx[k], o[4] = wy[k], o[5] = wz[k];
      o[6] = tmin[k], o[7] = tmax[k];
    }
    if (cnt < WD)
      for (int k = 0; k < 8 * cnt; k++) out[8 * k0 + k] = res[k];
  }
}
