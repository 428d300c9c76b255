/* `rayleigh` (also `rayleigh_polarized`, Eradiate's name): scattering by
 * particles much smaller than the wavelength (molecules), with the
 * depolarization factor rho of anisotropic molecules (`depolarization`,
 * default 0, in [0, 1) as Eradiate's rayleigh_polarized). With
 * mu = -dot(wi, wo) (phase.h), a = 1 + rho, b = 1 - rho:
 *
 *   p(mu) = 3 / (8 pi (2 + rho)) (a + b mu^2)   [sr^-1],
 *
 * the F11 of the phase matrix (core/mueller.h mu_rayleigh, Hansen & Travis
 * 1974 eq. 2.15) over 4 pi; rho = 0 gives 3 / (16 pi) (1 + mu^2).
 *
 * Sampling inverts the cdf F(mu) = (a (mu + 1) + b (mu^3 + 1) / 3) /
 * (2 a + 2 b / 3) exactly: mu solves the depressed cubic
 * mu^3 + 3 k mu - 2 z = 0 with k = a / b and z = c (2 u - 1),
 * c = (3 a + b) / (2 b), whose one real root is (Cardano)
 * mu = A - k / A, A = cbrt(z + sqrt(z^2 + k^3)); pdf = p(mu), weight 1.
 * (rho = 0: k = 1, c = 2, the unpolarized Rayleigh inversion, bit for bit.)
 *
 * Polarized variants: P = F / F11 of mu_rayleigh(mu, rho), in the
 * scattering plane's bases.
 *
 * Source: mitsuba3 src/phase/rayleigh.cpp (no parameters); eradiate/mitsuba3
 * src/eradiate_plugins/phase/rayleigh_polarized.cpp (`depolarization`; it
 * samples the rho = 0 density, we the exact one); Chandrasekhar, Radiative
 * Transfer (1960); Hansen & Travis 1974, Space Sci. Rev. 16, eq. 2.15. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "phase.h"

typedef struct rayleigh_phase {
  phase base;
  double rho;        /* depolarization factor (the parameter) */
  double norm, a, b; /* p(mu) = norm (a + b mu^2) */
  double k, k3, c;   /* the sampling cubic's constants */
} rayleigh_phase;

/* The derived constants of rho (exact for rho = 0: norm = 3 / (16 pi),
 * a = b = k = k3 = 1, c = 2). */
static void rayleigh_derive(rayleigh_phase *r) {
  double rho = r->rho;
  r->a = 1.0 + rho;
  r->b = 1.0 - rho;
  r->norm = 3.0 / (8.0 * RSW_PI * (2.0 + rho));
  r->k = r->a / r->b;
  r->k3 = r->k * r->k * r->k;
  r->c = (3.0 * r->a + r->b) / (2.0 * r->b);
}

static double rayleigh_value(const rayleigh_phase *r, double mu) {
  return r->norm * (r->a + r->b * mu * mu);
}

static double rayleigh_sample(const phase *ph, const medium_interaction *mi, double u1, vec2 u2, vec3 *wo,
                              double *pdf) {
  (void)u1;
  const rayleigh_phase *r = (const rayleigh_phase *)ph;
  double z = r->c * (2.0 * u2.x - 1.0);
  double a = cbrt(z + sqrt(z * z + r->k3));
  double mu = rsw_fmin(rsw_fmax(a - r->k / a, -1.0), 1.0); /* (fmin(1, fmax(-1, .)) bit for bit) */
  *wo = phase_direction(mi, mu, u2.y);
  *pdf = rayleigh_value(r, mu);
  return 1.0;
}

static double rayleigh_eval_pdf(const phase *ph, const medium_interaction *mi, vec3 wo, double *pdf) {
  *pdf = rayleigh_value((const rayleigh_phase *)ph, phase_mu(mi, wo));
  return *pdf;
}

/* Polarized variants: the Rayleigh phase matrix (core/mueller.h
 * mu_rayleigh) over its F11. */
static void rayleigh_polarization(const phase *ph, const medium_interaction *mi, vec3 wo, mueller P[3]) {
  P[0] = P[1] = P[2] = mu_normalized(mu_rayleigh(phase_mu(mi, wo), ((const rayleigh_phase *)ph)->rho));
}

static const phase_ops rayleigh_ops = {
    .sample = rayleigh_sample, .eval_pdf = rayleigh_eval_pdf, .polarization = rayleigh_polarization};

/* rho lies in [0, 1): the largest closed interval inside it. */
#define RAYLEIGH_RHO_HI nextafter(1.0, 0.0)

/* Eradiate's key `depolarization`; a spectral update (parameters_changed
 * derives the constants). */
static void rayleigh_traverse(object *o, param_visitor *v) {
  pv_float(v, "depolarization", &((rayleigh_phase *)o)->rho, UPDATE_SPECTRAL, 0.0, RAYLEIGH_RHO_HI);
}

static void rayleigh_parameters_changed(object *o) {
  rayleigh_derive((rayleigh_phase *)o);
}

DEFINE_PLUGIN(rayleigh, CLS_PHASE, .ops = &rayleigh_ops, .traverse = rayleigh_traverse,
              .parameters_changed = rayleigh_parameters_changed);
DEFINE_PLUGIN(rayleigh_polarized, CLS_PHASE, .ops = &rayleigh_ops, .traverse = rayleigh_traverse,
              .parameters_changed = rayleigh_parameters_changed);

static rsw_status rayleigh_make(loader *ld, node *n, const plugin *pl, object **out) {
  double rho;
  rsw_status st = ld_float(ld, n, "depolarization", 0.0, &rho);
  if (st) return st;
  if (!(rho >= 0.0 && rho < 1.0))
    return ld_fail(ld, n, "depolarization", RSW_ERR_RANGE,
                   "property 'depolarization' must lie in [0, 1) (got %g)", rho);
  rayleigh_phase *r = plugin_object_new(sizeof *r, pl);
  if (r) {
    r->base.ops = &rayleigh_ops;
    r->rho = rho;
    rayleigh_derive(r);
  }
  return plugin_created(ld, n, (object *)r, out);
}

static rsw_status rayleigh_create(loader *ld, node *n, object **out) {
  return rayleigh_make(ld, n, &plugin_rayleigh, out);
}

static rsw_status rayleigh_polarized_create(loader *ld, node *n, object **out) {
  return rayleigh_make(ld, n, &plugin_rayleigh_polarized, out);
}
