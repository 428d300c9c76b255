/* Eradiate's land and ocean surface BSDFs added with issue 25 (rtls,
 * maignan, ocean_legacy, mqdiffuse, selectbsdf): structs, direct
 * constructors and the closed forms the tests compare against.
 * Ownership as in bsdfs_internal.h: constructors return an owned bsdf and
 * borrow their textures. docs/kernel-conventions.md has each model. */
#ifndef RSW_BSDFS_EO_SURFACES_H
#define RSW_BSDFS_EO_SURFACES_H

#include "bsdfs_internal.h"

/* The one-sided cosine-hemisphere lobe these models sample (rpv and hapke
 * repeat it): fills bs and returns true when wi and the drawn wo both lie
 * above the surface; else bs is a failed sample. */
static inline bool eo_cosine_sample(const surface_interaction *si, vec2 u2, bsdf_sample *bs) {
  if (!(si->wi.z > 0.0)) return bsdf_fail(bs), false;
  bs->wo = warp_square_to_cosine_hemisphere(u2);
  bs->pdf = warp_square_to_cosine_hemisphere_pdf(bs->wo);
  bs->eta = 1.0;
  bs->sampled_type = BSDF_GLOSSY_REFLECTION;
  if (!(bs->pdf > 0.0) || !(bs->wo.z > 0.0)) return bsdf_fail(bs), false;
  return true;
}
/* Its density; 0 unless both directions lie above the surface. */
static inline double eo_cosine_pdf(const surface_interaction *si, vec3 wo) {
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return 0.0;
  return warp_square_to_cosine_hemisphere_pdf(wo);
}

/* ---- rtls: Ross-Thick Li-Sparse (MODIS BRDF kernels) --------------------- */
extern const plugin plugin_rtls;

typedef struct rtls_bsdf {
  bsdf base;
  texture *f_iso, *f_vol, *f_geo;
  double h, r, b; /* crown height / centre ratio h/b, shape ratio b/r */
} rtls_bsdf;

bsdf *rtls_new(texture *f_iso, texture *f_vol, texture *f_geo, double h, double r, double b);
/* The Ross-Thick and Li-Sparse-Reciprocal kernels at (wi, wo), both in the
 * upper hemisphere. */
void rtls_kernels(vec3 wi, vec3 wo, double h, double r, double b, double *k_vol, double *k_geo);

/* ---- maignan: Maignan et al. (2009) bare soil / vegetation ---------------- */
extern const plugin plugin_maignan;

typedef struct maignan_bsdf {
  bsdf base;
  texture *C, *ndvi, *refr_re, *refr_im, *ext_ior;
} maignan_bsdf;

bsdf *maignan_new(texture *C, texture *ndvi, texture *refr_re, texture *refr_im, texture *ext_ior);
/* eval(wi, wo) of one channel (Eradiate's value, which is f_r cos(theta_o)). */
double maignan_value(double C, double ndvi, double refr_re, double refr_im, double ext_ior, vec3 wi, vec3 wo);

#endif
