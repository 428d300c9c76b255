/* `null`: an index-matched boundary (Mitsuba's null BSDF). It bounds a
 * participating medium without scattering: light crosses it unchanged.
 *
 *   sample: wo = -wi with weight 1 (a delta transmission, eta 1);
 *   eval = pdf = 0 (no smooth lobe).
 *
 * The volumetric integrators (integrators/volpath.c) pass through it
 * without counting a bounce and let shadow rays through it
 * (BSDF_INDEX_MATCHED, Mitsuba's eval_null_transmission = 1); `path`
 * sees a delta transmission and treats it as an opaque surface to shadow
 * rays. Source: mitsuba3 src/bsdfs/null.cpp. */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "bsdfs_internal.h"
#include "fresnel_pol.h"

static color null_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  (void)b, (void)u1, (void)u2;
  bs->wo = v3_neg(si->wi);
  bs->pdf = 1.0;
  bs->eta = 1.0;
  bs->sampled_type = BSDF_DELTA_TRANSMISSION;
  return col1(1.0);
}

static color null_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b, (void)si, (void)wo;
  return col1(0.0);
}

static double null_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b, (void)si, (void)wo;
  return 0.0;
}

/* Polarization (docs/plugins.md#polarization-surfaces): the light crosses
 * unchanged, the identity (with `path`, which scatters at it). */
static void null_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                              mueller P[3], vec3 *s_in, vec3 *s_out) {
  (void)b, (void)lobe;
  P[0] = P[1] = P[2] = mu_identity();
  *s_in = *s_out = fpol_s_axis(wo, si->wi);
}

/* A bundle of pages (bsdf_ops.delta_value): the crossing (wo = -wi),
 * weight 1 with probability 1 at every page (what a composition over a
 * `null` asks). */
static color null_delta_value(const bsdf *b, const surface_interaction *si, unsigned lobe, vec3 wo,
                              double *prob) {
  (void)b;
  *prob = lobe == BSDF_DELTA_TRANSMISSION && delta_same_direction(wo, v3_neg(si->wi)) ? 1.0 : 0.0;
  return col1(*prob);
}

static const bsdf_ops null_ops = {.sample = null_sample,
                                  .eval = null_eval,
                                  .pdf = null_pdf,
                                  .polarization = null_polarization,
                                  .delta_value = null_delta_value};

static rsw_status null_create(loader *ld, node *n, object **out) {
  bsdf *b = BSDF_NEW(bsdf, null, BSDF_INDEX_MATCHED | BSDF_DELTA_TRANSMISSION | BSDF_TWO_SIDED);
  return plugin_created(ld, n, (object *)b, out);
}

DEFINE_PLUGIN(null, CLS_BSDF, .ops = &null_ops);
