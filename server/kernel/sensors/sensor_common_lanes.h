/* The distant family's batched rays (sensors/sensor_common.c
 * hemisphere_rays_batch for hdistant and distantflux, disk_origins_batch
 * for distant and mdistant), double lanes compiled per ISA by
 * simd/lanes_all.h. The operations are those of the scalar path
 * (warp_square_to_uniform_hemisphere, xf_vector, v3_norm,
 * ray_target_origin without a target) in the same order, without FMA
 * contraction, so each lane gives the scalar ray bit for bit
 * (tests/unit/test_simd.c checks it). Double precision on purpose: the
 * origin sits a bounding radius away from the scene. The sensors' scalar
 * sample_ray ops are not batches of one: they also serve ray targets and
 * the periodic slab, which the lanes leave to them. */
#include "../simd/simd.h"

/* hdistant camera rays: m the rows of to_world; fu, ap 2 per lane (x, y);
 * out 8 per lane (origin, direction, tmin 0, tmax infinity: a ray3). */
SIMD_ISA_DECL(void, hdistant_rays,
              (int n, const double (*m)[4], const double *fu, const double *ap, const double *center,
               double radius, double offset, double *out));
/* Origins on the bounding disk: frame rows m9 (9 per lane, m_step 9; or
 * shared, m_step 0), d 3 per lane (d_step 3) or shared (0), ap 2 per lane;
 * out 3 per lane. */
SIMD_ISA_DECL(void, disk_origins,
              (int n, const double *m9, int m_step, const double *d, int d_step, const double *ap,
               const double *center, double radius, double offset, double *out));

#ifdef LANES_FN
/* x and y of WD interleaved (x, y) pairs at p: two vector loads and two
 * shuffles (element inserts of the pairs went through the stack). */
SIMD_FN void d_deinterleave(const double *p, vdn *x, vdn *y) {
  vdn lo, hi;
  __builtin_memcpy(&lo, p, sizeof lo);
  __builtin_memcpy(&hi, p + WD, sizeof hi);
#if WD == 8
  *x = __builtin_shufflevector(lo, hi, 0, 2, 4, 6, 8, 10, 12, 14);
  *y = __builtin_shufflevector(lo, hi, 1, 3, 5, 7, 9, 11, 13, 15);
#elif WD == 4
  *x = __builtin_shufflevector(lo, hi, 0, 2, 4, 6);
  *y = __builtin_shufflevector(lo, hi, 1, 3, 5, 7);
#elif WD == 2
  *x = __builtin_shufflevector(lo, hi, 0, 2);
  *y = __builtin_shufflevector(lo, hi, 1, 3);
#else
#error "d_deinterleave: WD must be 2, 4 or 8"
#endif
}

/* Lane k of the eight rows r[0..7] to ob[8 k .. 8 k + 7], for every lane:
 * a transpose in shuffles (unpack pairs, then pairs of pairs, then
 * halves), then whole-vector stores. */
SIMD_FN void d_store_rows8(double *ob, const vdn *r) {
#if WD == 8
  vdn t[8], u[8];
  for (int i = 0; i < 8; i += 2) {
    t[i] = __builtin_shufflevector(r[i], r[i + 1], 0, 8, 2, 10, 4, 12, 6, 14);
    t[i + 1] = __builtin_shufflevector(r[i], r[i + 1], 1, 9, 3, 11, 5, 13, 7, 15);
  }
  /* t[0] = (r0[0], r1[0], r0[2], r1[2], ..), t[1] the odd lanes. */
  for (int i = 0; i < 8; i += 4)
    for (int j = 0; j < 2; j++) {
      u[i + j] = __builtin_shufflevector(t[i + j], t[i + j + 2], 0, 1, 8, 9, 4, 5, 12, 13);
      u[i + j + 2] = __builtin_shufflevector(t[i + j], t[i + j + 2], 2, 3, 10, 11, 6, 7, 14, 15);
    }
  /* u[j] (j < 4): rows 0..3 of lanes j and j + 4; u[4 + j]: rows 4..7. */
  for (int j = 0; j < 4; j++) {
    vdn lo = __builtin_shufflevector(u[j], u[j + 4], 0, 1, 2, 3, 8, 9, 10, 11);
    vdn hi = __builtin_shufflevector(u[j], u[j + 4], 4, 5, 6, 7, 12, 13, 14, 15);
    __builtin_memcpy(ob + 8 * j, &lo, sizeof lo);
    __builtin_memcpy(ob + 8 * (j + 4), &hi, sizeof hi);
  }
#elif WD == 4
  for (int h = 0; h < 8; h += 4) { /* rows 0..3, then 4..7: two 4x4 transposes */
    vdn t0 = __builtin_shufflevector(r[h], r[h + 1], 0, 4, 2, 6);
    vdn t1 = __builtin_shufflevector(r[h], r[h + 1], 1, 5, 3, 7);
    vdn t2 = __builtin_shufflevector(r[h + 2], r[h + 3], 0, 4, 2, 6);
    vdn t3 = __builtin_shufflevector(r[h + 2], r[h + 3], 1, 5, 3, 7);
    vdn l0 = __builtin_shufflevector(t0, t2, 0, 1, 4, 5), l2 = __builtin_shufflevector(t0, t2, 2, 3, 6, 7);
    vdn l1 = __builtin_shufflevector(t1, t3, 0, 1, 4, 5), l3 = __builtin_shufflevector(t1, t3, 2, 3, 6, 7);
    __builtin_memcpy(ob + h, &l0, sizeof l0);
    __builtin_memcpy(ob + 8 + h, &l1, sizeof l1);
    __builtin_memcpy(ob + 16 + h, &l2, sizeof l2);
    __builtin_memcpy(ob + 24 + h, &l3, sizeof l3);
  }
#elif WD == 2
  for (int h = 0; h < 8; h += 2) {
    vdn l0 = __builtin_shufflevector(r[h], r[h + 1], 0, 2),
        l1 = __builtin_shufflevector(r[h], r[h + 1], 1, 3);
    __builtin_memcpy(ob + h, &l0, sizeof l0);
    __builtin_memcpy(ob + 8 + h, &l1, sizeof l1);
  }
#else
#error "d_store_rows8: WD must be 2, 4 or 8"
#endif
}

/* n rays: rows m[3][3] of to_world; fu, ap film and aperture samples (x,
 * y interleaved per lane: fu[2 i], fu[2 i + 1]); out[8 i ..] = o, d, 0,
 * infinity (the layout of a ray3, which the caller's rays are).
 *
 * HD_CHUNK lanes at a time, in three passes over their vectors (the film
 * samples' disk points, the aperture samples', then the rest): a vector's
 * whole chain of dependent operations (two concentric maps' divisions and
 * polynomials, two square roots and a division) is longer than the core
 * looks ahead, while a pass's vectors are independent and short enough to
 * overlap. The same operations per lane in the same order: the rays of a
 * single pass bit for bit. */
#define HD_CHUNK 32
LANES_ATTR void LANES_FN(hdistant_rays)(int n, const double (*m)[4], const double *fu, const double *ap,
                                        const double *center, double radius, double offset, double *out) {
  enum {
    HV = HD_CHUNK / WD /* vectors per chunk */
  };
  for (int c0 = 0; c0 < n; c0 += HD_CHUNK) {
    int cnt = n - c0 < HD_CHUNK ? n - c0 : HD_CHUNK;
    int nv = (cnt + WD - 1) / WD;
    /* A partial chunk goes through padded copies (every lane of its
     * vectors set, as cosine_hemisphere in simd/warp_lanes.h). */
    const double *fk = fu + 2 * c0, *ak = ap + 2 * c0;
    double fpad[2 * HD_CHUNK], apad[2 * HD_CHUNK], res[8 * HD_CHUNK];
    if (cnt < HD_CHUNK) {
      for (int k = 0; k < 2 * HD_CHUNK; k++)
        fpad[k] = k < 2 * cnt ? fk[k] : 0.5, apad[k] = k < 2 * cnt ? ak[k] : 0.5;
      fk = fpad, ak = apad;
    }
    vdn px[HV], py[HV], qx[HV], qy[HV];
    for (int v = 0; v < nv; v++) { /* the film samples' disk points */
      vdn ux, uy;
      d_deinterleave(fk + 2 * WD * v, &ux, &uy);
      d_concentric(ux, uy, &px[v], &py[v]);
    }
    for (int v = 0; v < nv; v++) { /* the aperture samples' */
      vdn ax, ay;
      d_deinterleave(ak + 2 * WD * v, &ax, &ay);
      d_concentric(ax, ay, &qx[v], &qy[v]);
    }
    double *ob = cnt < HD_CHUNK ? res : &out[8 * c0];
    vdn wx[HV], wy[HV], wz[HV];
    for (int v = 0; v < nv; v++) { /* omega = to_world hemisphere(fu) */
      vdn z = 1.0 - (px[v] * px[v] + py[v] * py[v]);
      vdn z1 = z + 1.0;
      vdn s = VSQRT_D(dsel(z1 > 0.0, z1, (vdn){0}));
      vdn vx = px[v] * s, vy = py[v] * s;
      wx[v] = m[0][0] * vx + m[0][1] * vy + m[0][2] * z;
      wy[v] = m[1][0] * vx + m[1][1] * vy + m[1][2] * z;
      wz[v] = m[2][0] * vx + m[2][1] * vy + m[2][2] * z;
    }
    for (int v = 0; v < nv; v++) {
      d_norm3(&wx[v], &wy[v], &wz[v]); /* omega normalised, d = -omega */
      vdn dx = -wx[v], dy = -wy[v], dz = -wz[v];
      /* origin: centre + radius to_world (concentric(ap), 0), back by offset */
      vdn rx = m[0][0] * qx[v] + m[0][1] * qy[v] + m[0][2] * 0.0;
      vdn ry = m[1][0] * qx[v] + m[1][1] * qy[v] + m[1][2] * 0.0;
      vdn rz = m[2][0] * qx[v] + m[2][1] * qy[v] + m[2][2] * 0.0;
      vdn ox = (center[0] + radius * rx) + -offset * dx;
      vdn oy = (center[1] + radius * ry) + -offset * dy;
      vdn oz = (center[2] + radius * rz) + -offset * dz;
      const vdn rows[8] = {ox, oy, oz, dx, dy, dz, (vdn){0}, (vdn){0} + INFINITY};
      d_store_rows8(&ob[8 * WD * v], rows);
    }
    if (cnt < HD_CHUNK)
      for (int k = 0; k < 8 * cnt; k++) out[8 * c0 + k] = res[k];
  }
}
#undef HD_CHUNK

/* ---- distant family: origins on the bounding disk, double lanes ----------
 * sensors/sensor_common.c ray_target_origin() without a target:
 *   q = square_to_disk_concentric(ap), perp = frame (q.x, q.y, 0),
 *   o = (c + R perp) - offset d.
 * m9: the frame's 3x3 rows (9 doubles per lane, or one shared frame with
 * m_step 0); d: 3 per lane (d_step 3) or shared (0); ap 2 per lane; out 3
 * per lane. */
LANES_ATTR void LANES_FN(disk_origins)(int n, const double *m9, int m_step, const double *d, int d_step,
                                       const double *ap, const double *center, double radius, double offset,
                                       double *out) {
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
    } else { /* through a copy: whole vectors set (no lane of them left unset) */
      double t[9][WD];
      for (int k = 0; k < WD; k++) {
        const double *mk = m9 + (long)m_step * (k0 + (k < cnt ? k : cnt - 1));
        for (int j = 0; j < 9; j++) t[j][k] = mk[j];
      }
      for (int j = 0; j < 9; j++) __builtin_memcpy(&mm[j], t[j], sizeof mm[j]);
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
#endif
