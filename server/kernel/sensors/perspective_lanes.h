/* The perspective camera's batched rays (sensors/perspective.c
 * perspective_sample_ray_batch), double lanes compiled per ISA by
 * simd/lanes_all.h: the scalar operations in their order, so bitwise
 * perspective_sample_ray() (tests/unit/test_simd.c checks it). */
#include "../simd/simd.h"

/* m to_world's rows, pp the principal point offset, fu 2 per lane; out 8
 * per lane (o, d, tmin, tmax). */
SIMD_ISA_DECL(void, perspective_rays,
              (int n, const double (*m)[4], const double *pp, double t, double aspect, double near_clip,
               double far_clip, const double *fu, double *out));

#ifdef LANES_FN
/* ---- perspective camera rays, double lanes --------------------------------
 * sensors/perspective.c perspective_sample_ray(): with s = fu + pp,
 *   v = ((1 - 2 s.x) t, (1 - 2 s.y) t / aspect, 1), d = v / |v|,
 *   ray.d = to_world d, tmin = near / d.z, tmax = far / d.z (as near
 *   (1 / d.z)); origin the translation column (per lane, the same).
 * m: to_world's rows; pp: principal point offset (x, y); fu 2 per lane;
 * out 8 per lane (o xyz, d xyz, tmin, tmax: a ray3's layout, so the
 * caller may pass its rays). */
LANES_ATTR void LANES_FN(perspective_rays)(int n, const double (*m)[4], const double *pp, double t,
                                           double aspect, double near_clip, double far_clip, const double *fu,
                                           double *out) {
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
    d_norm3(&vx, &vy, &vz);
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
#endif
