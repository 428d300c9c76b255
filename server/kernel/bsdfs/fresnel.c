/* Fresnel equations (see fresnel.h for the formulas and their sources). */
#include "fresnel.h"
#include "fresnel_lanes.h"

double fresnel_conductor(double cos_i, double eta, double k) {
  double c = fabs(cos_i);
  if (c > 1.0) c = 1.0;
  double c2 = c * c, s2 = 1.0 - c2, s4 = s2 * s2;
  double eta2 = eta * eta, k2 = k * k;
  /* A = |eta_complex^2 - s^2| = a^2 + b^2 in the usual notation, where
   * a + i b = sqrt(eta_complex^2 - s^2). */
  double t1 = eta2 - k2 - s2;
  double A = sqrt(t1 * t1 + 4.0 * eta2 * k2);
  double a = sqrt(fmax(0.5 * (A + t1), 0.0));
  double ca2 = 2.0 * c * a;
  double rs_num = A + c2 - ca2, rs_den = A + c2 + ca2;
  double rs = rs_den > 0.0 ? rs_num / rs_den : 1.0;
  double rp_num = A * c2 + s4 - ca2 * s2, rp_den = A * c2 + s4 + ca2 * s2;
  double rp = rp_den > 0.0 ? rs * rp_num / rp_den : rs;
  return 0.5 * (rs + rp);
}

color fresnel_conductor_col(double cos_i, color eta, color k) {
  /* Shortcuts with the same values as the general case, bit for bit:
   * eta = 0, k = 1 (Mitsuba's `material: none` default) is a perfect
   * mirror, F = 1 exactly (t1 = -1 - s^2, A = 1 + s^2, a = 0, so Rs = Rp
   * = 1); and grey indices (mono renders, uniform spectra) need one
   * channel, not three. */
  bool grey = eta.c[0] == eta.c[1] && eta.c[0] == eta.c[2] && k.c[0] == k.c[1] && k.c[0] == k.c[2];
  if (grey) {
    if (eta.c[0] == 0.0 && k.c[0] == 1.0) return col1(1.0);
    return col1(fresnel_conductor(cos_i, eta.c[0], k.c[0]));
  }
  return col(fresnel_conductor(cos_i, eta.c[0], k.c[0]), fresnel_conductor(cos_i, eta.c[1], k.c[1]),
             fresnel_conductor(cos_i, eta.c[2], k.c[2]));
}

/* Mitsuba's fresnel(): with c_i = |cos_i|, c_t = sqrt(1 - eta_ti^2 (1 -
 * c_i^2)) (0 under total internal reflection),
 *   r_s = (c_i - eta_it c_t) / (c_i + eta_it c_t),
 *   r_p = (c_t - eta_it c_i) / (c_t + eta_it c_i),
 *   R   = (r_s^2 + r_p^2) / 2.
 * Special cases: index-matched (R = 0) and grazing incidence (R = 1). */
double fresnel_dielectric(double cos_i, double eta, double *cos_t, double *eta_it_out, double *eta_ti_out) {
  bool outside = cos_i >= 0.0;
  double eta_it = outside ? eta : 1.0 / eta;
  double eta_ti = outside ? 1.0 / eta : eta;
  double ci = fabs(cos_i);
  double ct2 = 1.0 - eta_ti * eta_ti * (1.0 - ci * ci);
  double ct = ct2 > 0.0 ? sqrt(ct2) : 0.0;
  double r;
  if (eta == 1.0) {
    r = 0.0;
  } else if (ci == 0.0) {
    r = 1.0;
  } else {
    double a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
    double a_p = (ct - eta_it * ci) / (ct + eta_it * ci);
    r = 0.5 * (a_s * a_s + a_p * a_p);
  }
  if (cos_t) *cos_t = outside ? -ct : ct;
  if (eta_it_out) *eta_it_out = eta_it;
  if (eta_ti_out) *eta_ti_out = eta_ti;
  return r;
}

void fresnel_conductor_batch(rsw_isa isa, int n, const double *cos_i, const double *eta, const double *k,
                             double *out) {
  SIMD_DISPATCH(isa, fresnel_conductor, n, cos_i, eta, k, out);
}
