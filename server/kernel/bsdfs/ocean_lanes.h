/* ocean_legacy's transmittance quadrature (transmittance(): the glint
 * summed over the hemisphere's points) on W double lanes, included by
 * ocean_legacy.c once per x86 ISA after it has defined:
 *   W          doubles per vector (2 sse2, 4 avx2, 8 avx512)
 *   OL_FN      the storage and target attributes of the lane helpers
 *   OL_ATTR    the target attribute of the entry point
 *   OL_SQRT(x) the ISA's packed double square root
 *   OL_NAME(f) f with the ISA's suffix
 *
 * Each lane is one quadrature point and runs glint_point()'s operations in
 * its order (IEEE +, -, *, /, sqrt round the same on every ISA; no FMA: the
 * project compiles with -ffp-contract=off; exp is libm's, lane by lane),
 * and the lanes are added to the sums one by one in the points' order, so
 * the sums are glint_point()'s bit for bit at every W
 * (tests/kernel/bsdfs/test_ocean_legacy.c compares the tables). */
#ifndef W
#error "define W, OL_FN, OL_ATTR, OL_SQRT and OL_NAME before including ocean_lanes.h"
#endif

typedef double OL_NAME(vd) __attribute__((vector_size(8 * W)));
typedef long long OL_NAME(vm) __attribute__((vector_size(8 * W)));
#define vd OL_NAME(vd)
#define vm OL_NAME(vm)

OL_FN vd OL_NAME(vsel)(vm m, vd a, vd b) { /* m ? a : b */
  return (vd)(((vm)a & m) | ((vm)b & ~m));
}
OL_FN vd OL_NAME(vabs)(vd a) {
  return (vd)((vm)a & 0x7fffffffffffffffLL);
}
/* v3_norm's l > 0 ? v / l : v of (x, y, z). */
OL_FN void OL_NAME(vnorm)(vd *x, vd *y, vd *z) {
  vd l = OL_SQRT(*x * *x + *y * *y + *z * *z), inv = 1.0 / l;
  vm pos = l > 0;
  *x = OL_NAME(vsel)(pos, *x * inv, *x);
  *y = OL_NAME(vsel)(pos, *y * inv, *y);
  *z = OL_NAME(vsel)(pos, *z * inv, *z);
}
/* ocean_fresnel_6s, lane-wise. */
OL_FN vd OL_NAME(vfresnel)(double n_re, double n_im, vd cos_chi, vd sin_chi) {
  double nr2 = n_re * n_re, ni2 = n_im * n_im;
  vd s = nr2 - ni2 - sin_chi * sin_chi;
  vd a1 = OL_NAME(vabs)(s), a2 = OL_SQRT(s * s + 4.0 * nr2 * ni2);
  vd u = OL_SQRT(0.5 * OL_NAME(vabs)(a1 + a2)), v = OL_SQRT(0.5 * OL_NAME(vabs)(a2 - a1));
  vd b1 = (nr2 - ni2) * cos_chi, b2 = 2.0 * n_re * n_im * cos_chi;
  vd rr = ((cos_chi - u) * (cos_chi - u) + v * v) / ((cos_chi + u) * (cos_chi + u) + v * v);
  vd rl = ((b1 - u) * (b1 - u) + (b2 + v) * (b2 + v)) / ((b1 + u) * (b1 + u) + (b2 - v) * (b2 - v));
  return 0.5 * (rr + rl);
}
OL_FN vd OL_NAME(vload)(const double *p) {
  vd v;
  memcpy(&v, p, sizeof v);
  return v;
}

/* glint_sums over points k0 .. k1 - 1 (k1 - k0 a multiple of W). */
OL_ATTR void OL_NAME(glint_sums)(const hemi_quad *q, const glint_cell *gc, int k0, int k1, double *td) {
  const double c40 = 0.40, c22 = 0.12, c04 = 0.23;
  double c = gc->c, s = gc->s, sig_u = gc->sig_u, sig_c = gc->sig_c, ci = gc->ci;
  double c21 = 0.01 - 0.0086 * gc->ws, c03 = 0.04 - 0.033 * gc->ws;
  vec3 wi = gc->wi;
  for (int k = k0; k < k1; k += W) {
    vd wx = OL_NAME(vload)(q->x + k), wy = OL_NAME(vload)(q->y + k), wz = OL_NAME(vload)(q->z + k);
    vd co = OL_NAME(vsel)(wz < 1e-6, (vd){0} + 1e-6, wz);
    vd mx = wi.x + wx, my = wi.y + wy, mz = wi.z + wz;
    OL_NAME(vnorm)(&mx, &my, &mz);
    vd px = c * mx + s * my, py = -s * mx + c * my, pz = mz;
    OL_NAME(vnorm)(&px, &py, &pz);
    vd xn = px / (sig_u * pz), xe = py / (sig_c * pz);
    vd xe2 = xe * xe, xn2 = xn * xn;
    vd gch = 1.0 - c21 / 2.0 * (xe2 - 1.0) * xn - c03 / 6.0 * (xn2 - 3.0) * xn +
             c40 / 24.0 * (xe2 * xe2 - 6.0 * xe2 + 3.0) + c04 / 24.0 * (xn2 * xn2 - 6.0 * xn2 + 3.0) +
             c22 / 4.0 * (xe2 - 1.0) * (xn2 - 1.0);
    vd ex = -0.5 * (xe * xe + xn * xn);
    for (int i = 0; i < W; i++) ex[i] = exp(ex[i]);
    vd D = gch / (2.0 * RSW_PI * sig_u * sig_c) * ex / (mz * mz * mz * mz);
    vd cchi = wx * mx + wy * my + wz * mz;
    cchi = OL_NAME(vsel)(cchi > -0.999999999, cchi, (vd){0} - 0.999999999);
    cchi = OL_NAME(vsel)(cchi < 0.999999999, cchi, (vd){0} + 0.999999999);
    vd schi = OL_SQRT(1.0 - cchi * cchi);
    schi = OL_NAME(vsel)(schi < 0.999999999, schi, (vd){0} + 0.999999999);
    vm lit = (wi.z > 0.0 ? ~(vm){0} : (vm){0}) & (wz > 0.0);
    vd gw = OL_NAME(vload)(q->w + k);
    for (int w = 0; w < gc->nw; w++) {
      vd g = D * OL_NAME(vfresnel)(gc->nr[w], gc->ni[w], cchi, schi) * RSW_PI / (4.0 * ci * co);
      g = OL_NAME(vsel)(lit, g, (vd){0} + 1.0) * gw;
      double t = td[w];
      for (int i = 0; i < W; i++) t += g[i];
      td[w] = t;
    }
  }
}

#undef vd
#undef vm
