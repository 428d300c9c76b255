/* What the tabulated phase functions share (tabphase, tabphase_polarized):
 * a density of the scattering cosine mu tabulated at nodes
 * -1 = mu_0 < mu_1 < ... < mu_{n-1} = 1, linear in between and
 * normalised:
 *
 *   p(mu) = f(mu) / (2 pi I),  f the piecewise-linear interpolant of the
 *   values, I = int_{-1}^{1} f dmu (trapezoids: exact for f).
 *
 * The nodes are either regular, mu_i = -1 + i h with h = 2 / (n - 1)
 * (Mitsuba's tabphase; found without a search), or given (Eradiate's
 * `nodes`, strictly increasing; a binary search). Sampling picks an
 * interval by its share of I, then inverts the linear density inside it
 * in closed form: with end values a, b over width w and target area A,
 * a t + (b - a) t^2 / (2 w) = A gives
 * t = 2 A / (a + sqrt(a^2 + 2 (b - a) A / w)) (the cancellation-free root).
 *
 * Source: mitsuba3 src/phase/tabphase.cpp and its ContinuousDistribution,
 * IrregularContinuousDistribution (include/mitsuba/core/distr_1d.h). */
#ifndef RSW_PHASE_TABULATED_H
#define RSW_PHASE_TABULATED_H

#include <stdbool.h>
#include <stddef.h>

#include "../scene/loader.h"
#include "../scene/node.h"
#include "../scene/params.h"
#include "phase.h"

typedef struct tab_mu {
  double *values; /* n, >= 0, not all zero (owned) */
  double *nodes;  /* n (owned), or NULL: the regular grid */
  double *cdf;    /* n: cdf[i] = int_{-1}^{mu_i} f (owned) */
  size_t n;
  double h; /* regular grid: 2 / (n - 1) */
} tab_mu;

/* The interval i (nodes i and i + 1) holding mu and the fraction f of the
 * way through it; false when mu lies outside [-1, 1]. */
bool tab_mu_locate(const tab_mu *t, double mu, size_t *i, double *f);
/* A tabulated quantity v (n values on t's nodes) at (i, f). */
static inline double tab_mu_lerp(const double *v, size_t i, double f) {
  return v[i] + f * (v[i + 1] - v[i]);
}
/* The normalised density of mu (per unit mu) at mu: f(mu) / I. */
double tab_mu_pdf(const tab_mu *t, double mu);
/* The cosine at which the cdf reaches u * I (u in [0, 1]). */
double tab_mu_sample(const tab_mu *t, double u);
/* phase_ops.sample and eval_pdf of the phase function p(mu) = the
 * density above / (2 pi): mu by tab_mu_sample (u2.x), the azimuth uniform
 * (u2.y); pdf = p(mu), weight 1. */
double tab_phase_sample(const tab_mu *t, const medium_interaction *mi, vec2 u2, vec3 *wo, double *pdf);
double tab_phase_eval_pdf(const tab_mu *t, const medium_interaction *mi, vec3 wo, double *pdf);
/* Recompute the cdf (after values or nodes changed). */
void tab_mu_build(tab_mu *t);

/* Read property `name` (a list or string of n >= 2 numbers >= 0, not all
 * zero) into t->values and, when `nodes_name` is not NULL and given, the
 * nodes (n numbers, -1 first, 1 last, strictly increasing); allocate the
 * cdf and build it. Errors name the property; nothing stays allocated on
 * failure. */
rsw_status tab_mu_load(loader *ld, node *n, const char *name, const char *nodes_name, tab_mu *t);
void tab_mu_free(tab_mu *t);

/* pv_buffer checks of updates: values not all zero; nodes -1 first, 1
 * last, strictly increasing. */
rsw_status tab_mu_check_values(const object *owner, const double *v, size_t n, const char *key, rsw_err *err);
rsw_status tab_mu_check_nodes(const object *owner, const double *v, size_t n, const char *key, rsw_err *err);

#endif
