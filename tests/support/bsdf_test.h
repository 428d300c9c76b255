/* Helpers shared by the BSDF tests: directions, a local shading point, and
 * the chi-square adapter that turns a BSDF's sample()/pdf() into
 * chi2_run's callbacks (Mitsuba's BSDFAdapter). */
#ifndef RSW_TEST_BSDF_TEST_H
#define RSW_TEST_BSDF_TEST_H

#include "../../server/kernel/bsdfs/bsdfs_internal.h"
#include "../../server/kernel/kernel.h"

/* Unit direction from zenith and azimuth in degrees (local frame, +z up). */
vec3 tb_dir_deg(double theta_deg, double phi_deg);
/* A shading point with the identity frame and the given local wi. */
surface_interaction tb_si_with(vec3 wi);
/* plugin->destroy on a BSDF or texture; NULL is a no-op. */
void tb_free_bsdf(bsdf *b);
void tb_free_tex(texture *t);

/* A roughconductor with constant alpha_u, alpha_v (the same value: one
 * isotropic texture), eta and k, and the textures it holds. */
typedef struct rough_case {
  bsdf *b;
  texture *au, *av, *eta, *k;
} rough_case;
rough_case rough_make(mf_type type, double au, double av, bool visible, double eta, double k);
void rough_free(rough_case *r);
/* "ggx" or "beckmann". */
const char *mf_type_name(mf_type t);

typedef struct chi2_bsdf {
  const bsdf *b;
  surface_interaction si;
} chi2_bsdf;
/* u[0] picks the lobe, u[1..2] the direction; a failed sample (pdf 0 or
 * black weight) has weight 0. user is a chi2_bsdf. */
bool chi2_bsdf_sample(void *user, const double *u, vec3 *out, double *weight);
double chi2_bsdf_pdf(void *user, vec3 wo);

#endif
