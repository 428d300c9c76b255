/* The BSDFs' polarization factors (bsdf_ops.polarization, the polarized
 * variants: docs/plugins.md#polarization-surfaces): Fresnel matrices of
 * interfaces, in the bases whose x is the s direction (the normal of the
 * plane of incidence), and the mixing of lobes.
 *
 * Directions are local (shading frame, n = +z); as in the op, light
 * arrives along -wo and leaves along wi. For a specular reflection or
 * transmission, and for a microfacet whose normal is the half vector of
 * wo and wi, the plane of incidence holds wo and wi, so its normal
 * plane_normal(wo, wi) (core/mueller.h) is the s axis of both beams
 * (Mitsuba 3's conductor.cpp, dielectric.cpp, roughconductor.cpp take
 * cross(n, wo) and cross(n, wi), the same line for coplanar wo, wi, n).
 * When wo and wi are parallel (normal incidence) any axis perpendicular to
 * both serves, the same one for both beams.
 *
 * Sources: Born & Wolf, Principles of Optics, sect. 1.5.2 and 14.2
 * (through core/mueller.h); mitsuba3 src/bsdfs/conductor.cpp,
 * dielectric.cpp, roughconductor.cpp (Fresnel matrices rotated into the
 * beams' bases), eradiate/mitsuba3 src/eradiate_plugins/bsdfs/maignan.cpp
 * and ocean_legacy.cpp (a facet's Fresnel matrix, the diffuse terms
 * depolarizing). */
#ifndef RSW_BSDFS_FRESNEL_POL_H
#define RSW_BSDFS_FRESNEL_POL_H

#include "../core/mueller_fresnel.h"
#include "../kernel.h"

/* The s axis of the beams -wo -> wi (see above). */
static inline vec3 fpol_s_axis(vec3 wo, vec3 wi) {
  return plane_normal(wo, wi);
}

/* Every channel a depolarizer, bases the s axis (any would do). */
static inline void fpol_depolarize(mueller P[3], vec3 wo, vec3 wi, vec3 *s_in, vec3 *s_out) {
  P[0] = P[1] = P[2] = mu_depolarizer();
  *s_in = *s_out = fpol_s_axis(wo, wi);
}

/* P[c] = the normalized reflection matrix of an interface of complex
 * relative index eta.c[c] + i k.c[c] at incidence cosine cos_i (one
 * evaluation when the channels agree). */
static inline void fpol_reflection(mueller P[3], double cos_i, color eta, color k) {
  for (int c = 0; c < 3; c++) {
    if (c > 0 && eta.c[c] == eta.c[c - 1] && k.c[c] == k.c[c - 1]) {
      P[c] = P[c - 1];
      continue;
    }
    P[c] = mu_normalized(mu_fresnel_reflection(fabs(cos_i), mu_cmplx(eta.c[c], k.c[c])));
  }
}

/* A smooth dielectric interface of relative index eta (interior over
 * exterior, the normal on the exterior side), light arriving along -wo and
 * leaving along wi: the reflection matrix when both lie on one side, else
 * the transmission matrix, each with the index seen from the side the
 * light comes from (1 / eta from inside; total internal reflection keeps
 * the amplitudes' phases). */
static inline mueller fpol_dielectric(double eta, vec3 wo, vec3 wi) {
  double ci = fabs(wo.z), eta_it = wo.z >= 0.0 ? eta : 1.0 / eta;
  if (wo.z * wi.z > 0.0) return mu_normalized(mu_fresnel_reflection(ci, eta_it));
  return mu_normalized(mu_fresnel_transmission(ci, eta_it));
}

/* a in the bases (a_in, a_out) re-expressed in (s_in, s_out), for the
 * beams -wo -> wi: R(a_out -> s_out) a R(s_in -> a_in). */
static inline mueller fpol_rebase(mueller a, vec3 wo, vec3 wi, vec3 a_in, vec3 a_out, vec3 s_in, vec3 s_out) {
  vec3 d_in = v3_neg(wo);
  mueller Ri = mu_basis_change(d_in, s_in, a_in), Ro = mu_basis_change(wi, a_out, s_out);
  mueller t = mu_mul(&a, &Ri);
  return mu_mul(&Ro, &t);
}

/* The factors of a sum of lobes f = sum_k f_k with factors P_k (all in
 * the same bases), per channel: (sum_k f_k P_k) / (sum_k f_k), as the
 * Mueller matrices add (F = sum_k f_k P_k, normalized). Accumulate with
 * fpol_mix_add from acc zeroed and w zeroed, finish with fpol_mix_end
 * (channels of total weight 0 depolarize). */
static inline void fpol_mix_add(mueller acc[3], double w[3], color f, const mueller P[3]) {
  for (int c = 0; c < 3; c++) {
    if (!(f.c[c] != 0.0)) continue;
    w[c] += f.c[c];
    for (int i = 0; i < 4; i++)
      for (int j = 0; j < 4; j++) acc[c].m[i][j] += f.c[c] * P[c].m[i][j];
  }
}
static inline void fpol_mix_end(mueller acc[3], const double w[3]) {
  for (int c = 0; c < 3; c++) acc[c] = w[c] > 0.0 ? mu_normalized(acc[c]) : mu_depolarizer();
}

/* Specular factors F[c] (normalized) of weight fs mixed with a
 * depolarizing part of weight fd, per channel (plastic, roughplastic,
 * ocean_legacy): P = (fs F + fd D) / (fs + fd). */
static inline void fpol_with_diffuse(mueller P[3], const mueller F[3], color fs, color fd) {
  mueller acc[3] = {mu_zero(), mu_zero(), mu_zero()},
          D[3] = {mu_depolarizer(), mu_depolarizer(), mu_depolarizer()};
  double w[3] = {0, 0, 0};
  fpol_mix_add(acc, w, fs, F);
  fpol_mix_add(acc, w, fd, D);
  fpol_mix_end(acc, w);
  for (int c = 0; c < 3; c++) P[c] = acc[c];
}

/* A wrapped BSDF's factors as its op gives them (the depolarizer when it
 * has none). */
static inline void fpol_forward(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                                mueller P[3], vec3 *s_in, vec3 *s_out) {
  if (b->ops->polarization)
    b->ops->polarization(b, si, wo, lobe, P, s_in, s_out);
  else
    fpol_depolarize(P, wo, si->wi, s_in, s_out);
}

/* The factors of a BSDF in the bases (s_in, s_out) given: its op's (or
 * the depolarizer's) re-expressed there. */
static inline void fpol_child(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                              mueller P[3], vec3 s_in, vec3 s_out) {
  if (!b->ops->polarization) {
    P[0] = P[1] = P[2] = mu_depolarizer();
    return;
  }
  vec3 a_in, a_out;
  b->ops->polarization(b, si, wo, lobe, P, &a_in, &a_out);
  for (int c = 0; c < 3; c++) P[c] = fpol_rebase(P[c], wo, si->wi, a_in, a_out, s_in, s_out);
}

#endif
