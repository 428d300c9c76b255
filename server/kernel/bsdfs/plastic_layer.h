/* What `plastic` and `roughplastic` share: a diffuse base under a
 * dielectric coating (relative index eta = int_ior / ext_ior), Mitsuba 3's
 * model with internal scattering (mitsuba3 src/bsdfs/plastic.cpp,
 * roughplastic.cpp; Weidlich and Wilkie 2007, "Arbitrarily layered
 * micro-facet surfaces").
 *
 * The diffuse base of reflectance rho, seen through the coating, after
 * light bounced between base and coating, reflects
 *   rho' = rho / (1 - Fdr)          (nonlinear false: the default)
 *   rho' = rho / (1 - rho Fdr)      (nonlinear true)
 * with Fdr the coating's internal diffuse reflectance. */
#ifndef RSW_BSDFS_PLASTIC_LAYER_H
#define RSW_BSDFS_PLASTIC_LAYER_H

#include "bsdfs_internal.h"

struct param_visitor;

typedef struct plastic_layer {
  texture *diffuse;  /* diffuse_reflectance (0.5) */
  texture *specular; /* specular_reflectance, NULL = 1 */
  double eta;        /* int_ior / ext_ior */
  bool nonlinear;
} plastic_layer;

/* Mitsuba's fresnel_diffuse_reflectance(eta): the hemispherical average
 * of the Fresnel reflectance for diffuse light arriving from the side of
 * relative index eta. Fits: Egan and Hilgeman (1973) for eta < 1,
 *   -1.4399 eta^2 + 0.7099 eta + 0.6681 + 0.0636 / eta;
 * d'Eon and Irving (2011) for eta >= 1, a quintic in 1/eta with
 * coefficients 0.919317, -3.4793, 6.75335, -7.80989, 4.98554, -1.36881. */
double fresnel_diffuse_reflectance(double eta);

/* Reads int_ior ("polypropylene"), ext_ior ("air"), diffuse_reflectance
 * (0.5), specular_reflectance (optional) and nonlinear (false). */
rsw_status plastic_layer_load(struct loader *ld, struct node *n, plastic_layer *out);
/* Keys `eta` (spectral), `diffuse_reflectance`, `specular_reflectance`. */
void plastic_layer_traverse(plastic_layer *l, struct param_visitor *v);

/* rho' at si for the internal reflectance fdr (see above). */
color plastic_diffuse(const plastic_layer *l, const surface_interaction *si, double fdr);
/* Mitsuba's specular_sampling_weight s / (d + s) from the textures' means
 * (taken at each call, so a texture update needs no refresh). */
double plastic_specular_weight(const plastic_layer *l);

#endif
