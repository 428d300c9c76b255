/* Fresnel equations and the specular reflect/refract helpers shared by the
 * BSDF plugins. All directions are in the local shading frame (n = +z),
 * pointing away from the surface.
 *
 * Sources: mitsuba3 include/mitsuba/render/fresnel.h (fresnel(),
 * fresnel_conductor(), reflect(), refract()); docs/kernel-conventions.md#conductors-and-fresnel. */
#ifndef RSW_BSDFS_FRESNEL_H
#define RSW_BSDFS_FRESNEL_H

#include "../core/isa.h"
#include "../core/vec.h"

/* Unpolarised Fresnel reflectance of a conductor with complex relative
 * index eta + i k, at incidence cosine cos_i (its absolute value, clamped
 * to [0, 1], is used). With c = cos_i, s^2 = 1 - c^2:
 *   t1 = eta^2 - k^2 - s^2,  A = sqrt(t1^2 + 4 eta^2 k^2),
 *   a  = sqrt((A + t1) / 2),
 *   Rs = (A + c^2 - 2 c a) / (A + c^2 + 2 c a),
 *   Rp = Rs (A c^2 + s^4 - 2 c a s^2) / (A c^2 + s^4 + 2 c a s^2),
 *   F  = (Rs + Rp) / 2.
 * eta = 0, k = 1 gives F = 1 (a perfect mirror); at normal incidence
 * F = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2). */
double fresnel_conductor(double cos_i, double eta, double k);
/* fresnel_conductor() for n lanes at `isa` (bsdfs/fresnel_lanes.h, double
 * lanes, bitwise the scalar values). */
void fresnel_conductor_batch(rsw_isa isa, int n, const double *cos_i, const double *eta, const double *k,
                             double *out);
/* Per channel. */
color fresnel_conductor_col(double cos_i, color eta, color k);

/* Unpolarised Fresnel reflectance of a smooth dielectric interface with
 * relative index eta = eta_int / eta_ext (Mitsuba's fresnel()).
 * cos_i > 0: the incident direction lies on the exterior side.
 * Outputs (each may be NULL):
 *   cos_t:  cosine of the refracted direction, with the sign opposite to
 *           cos_i (it points into the other side); 0 under total internal
 *           reflection;
 *   eta_it: eta of the interface as seen from the incident side
 *           (eta if cos_i >= 0, else 1/eta);
 *   eta_ti: 1 / eta_it.
 * Returns R in [0, 1] (1 under total internal reflection; 0 when
 * eta == 1). */
double fresnel_dielectric(double cos_i, double eta, double *cos_t, double *eta_it, double *eta_ti);

/* Mirror reflection about the local normal +z. */
static inline vec3 reflect_local(vec3 wi) {
  return v3(-wi.x, -wi.y, wi.z);
}

/* Mirror reflection of wi about the unit vector m: 2 (wi.m) m - wi. */
static inline vec3 reflect_about(vec3 wi, vec3 m) {
  return v3_sub(v3_scale(m, 2.0 * v3_dot(wi, m)), wi);
}

/* Refraction through the local normal, given fresnel_dielectric()'s cos_t
 * and eta_ti: (-eta_ti wi.x, -eta_ti wi.y, cos_t). */
static inline vec3 refract_local(vec3 wi, double cos_t, double eta_ti) {
  return v3(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
}

#endif
