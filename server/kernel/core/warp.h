/* Warps: maps from the unit square to sampling domains, each as a triplet
 * sample / pdf / inverse (pbrt-v4 style), following Mitsuba 3's
 * include/mitsuba/core/warp.h conventions exactly (docs/kernel-conventions.md#warps)
 * and CastleSphereSampling's phi/theta representation.
 *
 * Conventions: u in [0,1)^2; directions are unit vectors in a local frame
 * whose +z is the pole; pdfs are with respect to solid angle (sphere,
 * hemisphere, cone) or area (disk). */
#ifndef RSW_CORE_WARP_H
#define RSW_CORE_WARP_H

#include "vec.h"

typedef struct vec2 {
  double x, y;
} vec2;

static inline vec2 v2(double x, double y) {
  vec2 r = {x, y};
  return r;
}

/* --- planar ------------------------------------------------------------ */
/* Shirley-Chiu concentric map, Mitsuba's branch-reduced form; pdf 1/pi. */
vec2 warp_square_to_disk_concentric(vec2 u);
vec2 warp_disk_to_square_concentric(vec2 p);
double warp_square_to_disk_concentric_pdf(vec2 p);
/* Polar map r = sqrt(u.y), phi = 2 pi u.x; pdf 1/pi. */
vec2 warp_square_to_uniform_disk(vec2 u);
vec2 warp_uniform_disk_to_square(vec2 p);
double warp_square_to_uniform_disk_pdf(vec2 p);

/* --- hemisphere / sphere / cone ----------------------------------------- */
/* Uniform hemisphere through the concentric map: z = 1 - r^2,
 * (x, y) = p sqrt(z + 1). pdf 1/(2 pi) on z >= 0, else 0. */
vec3 warp_square_to_uniform_hemisphere(vec2 u);
vec2 warp_uniform_hemisphere_to_square(vec3 v);
double warp_square_to_uniform_hemisphere_pdf(vec3 v);

/* Cosine-weighted hemisphere (Malley's method on the concentric disk);
 * pdf cos(theta)/pi. */
vec3 warp_square_to_cosine_hemisphere(vec2 u);
vec2 warp_cosine_hemisphere_to_square(vec3 v);
double warp_square_to_cosine_hemisphere_pdf(vec3 v);

/* Cosine-power hemisphere: density (n+1) cos^n(theta) / (2 pi), n >= 0
 * (Castle's RandomHemispherePointCosThetaExp; Global Illumination
 * Compendium (36)). */
vec3 warp_square_to_cosine_power_hemisphere(vec2 u, double n);
vec2 warp_cosine_power_hemisphere_to_square(vec3 v, double n);
double warp_square_to_cosine_power_hemisphere_pdf(vec3 v, double n);

/* Uniform sphere: z = 1 - 2 u.y, phi = 2 pi u.x; pdf 1/(4 pi). */
vec3 warp_square_to_uniform_sphere(vec2 u);
vec2 warp_uniform_sphere_to_square(vec3 v);
double warp_square_to_uniform_sphere_pdf(vec3 v);

/* Uniform cone around +z with cos of the half-angle cos_cutoff;
 * pdf 1/(2 pi (1 - cos_cutoff)) inside, 0 outside. */
vec3 warp_square_to_uniform_cone(vec2 u, double cos_cutoff);
vec2 warp_uniform_cone_to_square(vec3 v, double cos_cutoff);
double warp_square_to_uniform_cone_pdf(vec3 v, double cos_cutoff);

/* --- angles (CastleSphereSampling representation) ----------------------- */
/* (phi, theta) -> xyz about the pole axis `axis` (need not be unit: its
 * length is the radius). phi is measured from the first vector of
 * coordinate_system(normalize(axis)), theta from axis. */
vec3 warp_phi_theta_to_xyz(vec2 phi_theta, vec3 axis);
/* Inverse of the above: phi in [0, 2 pi), theta in [0, pi]. */
vec2 warp_xyz_to_phi_theta(vec3 v, vec3 axis);

#endif
