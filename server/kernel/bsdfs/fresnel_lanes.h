/* fresnel_conductor() (bsdfs/fresnel.c) for many lanes, double lanes,
 * compiled per ISA by simd/lanes_all.h and dispatched by
 * fresnel_conductor_batch() (fresnel.c). The same operations in the same
 * order as the scalar function (no FMA contraction: -std=c11), so bitwise
 * its values (tests/unit/test_simd.c checks it). */
#include "../simd/simd.h"

SIMD_ISA_DECL(void, fresnel_conductor,
              (int n, const double *cos_i, const double *eta, const double *k, double *out));

#ifdef LANES_FN
/* ---- conductor Fresnel, double lanes --------------------------------------
 * bsdfs/fresnel.c fresnel_conductor(), the same operations in the same
 * order (fmax(x, 0) as a select, the same for every x but -0, where
 * sqrt(+-0) only changes the sign of a zero that is then added to a
 * positive number): bitwise the scalar value. cos_i, eta, k, out: n each. */
LANES_ATTR void LANES_FN(fresnel_conductor)(int n, const double *cos_i, const double *eta, const double *kk,
                                            double *out) {
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
#endif
