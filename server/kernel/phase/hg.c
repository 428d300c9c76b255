/* `hg`: the Henyey-Greenstein phase function with asymmetry g in (-1, 1),
 * the mean cosine of the scattering angle (g > 0 forward, g < 0 backward,
 * g = 0 isotropic). With mu = -dot(wi, wo) (phase.h):
 *
 *   p(mu) = (1 - g^2) / (4 pi (1 + g^2 - 2 g mu)^(3/2))   [sr^-1].
 *
 * Sampling inverts the cdf of mu in closed form, with
 * s = (1 - g^2) / (1 - g + 2 g u):  mu = (1 + g^2 - s^2) / (2 g)
 * (mu = 2 u - 1 for |g| < 1e-5, where that quotient cancels), the azimuth
 * uniform; pdf = p(mu), weight 1.
 *
 * Source: mitsuba3 src/phase/hg.cpp (parameter g, default 0.8, open
 * interval); Henyey & Greenstein 1941. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "phase.h"

typedef struct hg_phase {
  phase base;
  double g;
} hg_phase;

static double hg_eval(double g, double mu) {
  double d = 1.0 + g * g - 2.0 * g * mu;
  return RSW_INV_4PI * (1.0 - g * g) / (d * sqrt(d));
}

static double hg_sample(const phase *ph, const medium_interaction *mi, double u1, vec2 u2, vec3 *wo,
                        double *pdf) {
  (void)u1;
  double g = ((const hg_phase *)ph)->g, mu;
  if (fabs(g) < 1e-5) {
    mu = 2.0 * u2.x - 1.0;
  } else {
    double s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u2.x);
    mu = (1.0 + g * g - s * s) / (2.0 * g);
  }
  mu = rsw_fmin(rsw_fmax(mu, -1.0), 1.0); /* (fmin(1, fmax(-1, mu)) bit for bit, no libm calls) */
  *wo = phase_direction(mi, mu, u2.y);
  *pdf = hg_eval(g, mu);
  if (!(*pdf > 0.0)) return phase_fail(pdf);
  return 1.0;
}

static double hg_eval_pdf(const phase *ph, const medium_interaction *mi, vec3 wo, double *pdf) {
  double v = hg_eval(((const hg_phase *)ph)->g, phase_mu(mi, wo));
  *pdf = v;
  return v;
}

static const phase_ops hg_ops = {.sample = hg_sample, .eval_pdf = hg_eval_pdf};

/* g lies in the open interval (-1, 1): the largest closed one inside it. */
#define HG_G_LO nextafter(-1.0, 0.0)
#define HG_G_HI nextafter(1.0, 0.0)

/* Mitsuba's key `g`; a spectral update (no derived state). */
static void hg_traverse(object *o, param_visitor *v) {
  pv_float(v, "g", &((hg_phase *)o)->g, UPDATE_SPECTRAL, HG_G_LO, HG_G_HI);
}

DEFINE_PLUGIN(hg, CLS_PHASE, .ops = &hg_ops, .traverse = hg_traverse);

static rsw_status hg_create(loader *ld, node *n, object **out) {
  double g;
  rsw_status st = ld_float(ld, n, "g", 0.8, &g);
  if (st) return st;
  if (!(g > -1.0 && g < 1.0))
    return ld_fail(ld, n, "g", RSW_ERR_RANGE, "property 'g' must lie in the open interval (-1, 1) (got %g)",
                   g);
  hg_phase *h = PLUGIN_NEW(hg_phase, hg);
  if (h) h->base.ops = &hg_ops, h->g = g;
  return plugin_created(ld, n, (object *)h, out);
}
