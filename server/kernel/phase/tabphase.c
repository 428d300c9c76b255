/* `tabphase`: a phase function tabulated on a regular grid of the
 * scattering cosine, mu_i = -1 + 2 i / (n - 1), i = 0..n-1 (mu = 1 is
 * forward scattering, mu = -dot(wi, wo), phase.h), linear in between and
 * normalised:
 *
 *   p(mu) = f(mu) / (2 pi I),  f the piecewise-linear interpolant of the
 *   values, I = int_{-1}^{1} f dmu (trapezoids: exact for f);
 *
 * so that 2 pi int p dmu = 1. Sampling inverts its cdf exactly (u.x;
 * phase/tabulated.h, shared with tabphase_polarized); the azimuth is
 * uniform (u.y); pdf = p(mu), weight 1. Polarized variants: a
 * depolarizer (as in Mitsuba and Eradiate: tabphase_polarized carries a
 * phase matrix).
 *
 * `values`: n >= 2 non-negative numbers, not all zero, as Mitsuba's
 * string of numbers separated by commas (or a list); also the parameter
 * key (a spectral update of the same length; the cdf is rebuilt).
 *
 * Source: mitsuba3 src/phase/tabphase.cpp and its ContinuousDistribution
 * (include/mitsuba/core/distr_1d.h). */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "phase.h"
#include "tabulated.h"

typedef struct tabphase {
  phase base;
  tab_mu d; /* values: the parameter; the regular grid */
} tabphase;

static double tab_sample(const phase *ph, const medium_interaction *mi, double u1, vec2 u2, vec3 *wo,
                         double *pdf) {
  (void)u1;
  return tab_phase_sample(&((const tabphase *)ph)->d, mi, u2, wo, pdf);
}

static double tab_eval_pdf(const phase *ph, const medium_interaction *mi, vec3 wo, double *pdf) {
  return tab_phase_eval_pdf(&((const tabphase *)ph)->d, mi, wo, pdf);
}

static const phase_ops tabphase_ops = {.sample = tab_sample, .eval_pdf = tab_eval_pdf};

static void tabphase_destroy(object *o) {
  tabphase *t = (tabphase *)o;
  if (!t) return;
  tab_mu_free(&t->d);
  free(t);
}

static rsw_status tabphase_create(loader *ld, node *n, object **out) {
  tab_mu d;
  rsw_status st = tab_mu_load(ld, n, "values", NULL, &d);
  if (st) return st;
  tabphase *t = calloc(1, sizeof *t);
  if (!t) {
    tab_mu_free(&d);
    return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "tabphase: out of memory");
  }
  t->base.ops = &tabphase_ops;
  t->base.base.id = n->id;
  t->d = d;
  *out = &t->base.base;
  return RSW_OK;
}

static void tabphase_traverse(object *o, param_visitor *v) {
  tabphase *t = (tabphase *)o;
  pv_buffer(v, "values", t->d.values, t->d.n, UPDATE_SPECTRAL, 0.0, INFINITY, tab_mu_check_values);
}

static void tabphase_parameters_changed(object *o) {
  tab_mu_build(&((tabphase *)o)->d);
}

DEFINE_PLUGIN(tabphase, CLS_PHASE, .destroy = tabphase_destroy, .ops = &tabphase_ops,
              .traverse = tabphase_traverse, .parameters_changed = tabphase_parameters_changed);
