/* `isotropic`: the same probability into every direction,
 *
 *   p(wi, wo) = 1 / (4 pi) [sr^-1];
 *   sample: wo uniform on the sphere (pdf 1 / (4 pi)), weight 1.
 *
 * Source: mitsuba3 src/phase/isotropic.cpp (no parameters). */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "phase.h"

static double isotropic_sample(const phase *ph, const medium_interaction *mi, double u1, vec2 u2, vec3 *wo,
                               double *pdf) {
  (void)ph, (void)mi, (void)u1;
  *wo = warp_square_to_uniform_sphere(u2);
  *pdf = RSW_INV_4PI;
  return 1.0;
}

static double isotropic_eval_pdf(const phase *ph, const medium_interaction *mi, vec3 wo, double *pdf) {
  (void)ph, (void)mi, (void)wo;
  *pdf = RSW_INV_4PI;
  return RSW_INV_4PI;
}

static const phase_ops isotropic_ops = {.sample = isotropic_sample, .eval_pdf = isotropic_eval_pdf};

DEFINE_PLUGIN(isotropic, CLS_PHASE, .ops = &isotropic_ops);

static rsw_status isotropic_create(loader *ld, node *n, object **out) {
  phase *p = PLUGIN_NEW(phase, isotropic);
  if (p) p->ops = &isotropic_ops;
  return plugin_created(ld, n, (object *)p, out);
}
