/* `rayleigh`: scattering by particles much smaller than the wavelength
 * (molecules), unpolarised. With mu = -dot(wi, wo) (phase.h):
 *
 *   p(mu) = 3 / (16 pi) (1 + mu^2)   [sr^-1].
 *
 * Sampling inverts the cdf F(mu) = 3/8 (mu + mu^3 / 3) + 1/2: mu solves
 * mu^3 + 3 mu - 2 z = 0 with z = 2 (2 u - 1), whose one real root is
 * (Cardano) mu = A - 1 / A, A = cbrt(z + sqrt(z^2 + 1)); pdf = p(mu),
 * weight 1.
 *
 * Source: mitsuba3 src/phase/rayleigh.cpp (no parameters); Chandrasekhar,
 * Radiative Transfer (1960), the Rayleigh phase function. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "phase.h"

#define RAYLEIGH_NORM (3.0 / (16.0 * RSW_PI))

static double rayleigh_sample(const phase *ph, const medium_interaction *mi, double u1, vec2 u2, vec3 *wo,
                              double *pdf) {
  (void)ph, (void)u1;
  double z = 2.0 * (2.0 * u2.x - 1.0);
  double a = cbrt(z + sqrt(z * z + 1.0));
  double mu = fmin(1.0, fmax(-1.0, a - 1.0 / a));
  *wo = phase_direction(mi, mu, u2.y);
  *pdf = RAYLEIGH_NORM * (1.0 + mu * mu);
  return 1.0;
}

static double rayleigh_eval_pdf(const phase *ph, const medium_interaction *mi, vec3 wo, double *pdf) {
  (void)ph;
  double mu = phase_mu(mi, wo);
  *pdf = RAYLEIGH_NORM * (1.0 + mu * mu);
  return *pdf;
}

/* Polarized variants: the Rayleigh phase matrix (core/mueller.h
 * mu_rayleigh, no depolarization) over its F11. */
static void rayleigh_polarization(const phase *ph, const medium_interaction *mi, vec3 wo, mueller P[3]) {
  (void)ph;
  P[0] = P[1] = P[2] = mu_normalized(mu_rayleigh(phase_mu(mi, wo), 0.0));
}

static const phase_ops rayleigh_ops = {
    .sample = rayleigh_sample, .eval_pdf = rayleigh_eval_pdf, .polarization = rayleigh_polarization};

DEFINE_PLUGIN(rayleigh, CLS_PHASE, .ops = &rayleigh_ops);

static rsw_status rayleigh_create(loader *ld, node *n, object **out) {
  phase *p = PLUGIN_NEW(phase, rayleigh);
  if (p) p->ops = &rayleigh_ops;
  return plugin_created(ld, n, (object *)p, out);
}
