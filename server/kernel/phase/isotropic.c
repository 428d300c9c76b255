/* `isotropic`: the same probability into every direction,
 *
 *   p(wi, wo) = 1 / (4 pi) [sr^-1];
 *   sample: wo uniform on the sphere (pdf 1 / (4 pi)), weight 1.
 *
 * Source: mitsuba3 src/phase/isotropic.cpp (no parameters). */
#include <stdlib.h>

#include "../scene/loader.h"
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

static void isotropic_destroy(object *o) {
  free(o);
}

static rsw_status isotropic_create(loader *ld, node *n, object **out) {
  phase *p = calloc(1, sizeof *p);
  if (!p) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "isotropic: out of memory");
  p->ops = &isotropic_ops;
  p->base.id = n->id;
  *out = &p->base;
  return RSW_OK;
}

const plugin plugin_isotropic = {
    .name = "isotropic",
    .cls = CLS_PHASE,
    .create = isotropic_create,
    .destroy = isotropic_destroy,
    .ops = &isotropic_ops,
};
