/* `tabphase_polarized` (Eradiate's): the phase matrix of a medium of
 * randomly oriented, mirror-symmetric particles, tabulated over the
 * scattering cosine mu (mu = 1 forward, mu = -dot(wi, wo), phase.h):
 *
 *   F(mu) = [ m11  m12   0    0  ]
 *           [ m12  m22   0    0  ]
 *           [  0    0   m33  m34 ]
 *           [  0    0  -m34  m44 ]
 *
 * its six elements given at the same nodes (`nodes`: n cosines, -1 first,
 * 1 last, strictly increasing; absent: the regular grid
 * mu_i = -1 + 2 i / (n - 1) of tabphase), linear in between. The intensity
 * is tabphase's: p(mu) = m11(mu) / (2 pi I), I = int m11 dmu, sampled
 * exactly (phase/tabulated.h); the other elements are in m11's units
 * (their scale is m11's, Eradiate normalises all six by m11's I).
 *
 * The table's Stokes bases, as Eradiate's (and Hansen & Travis 1974,
 * Mishchenko's tables): x in the scattering plane, Q = I_l - I_r (so that
 * Rayleigh's m12 = -3/4 (1 - mu^2) < 0). The kernel's (core/mueller.h):
 * x the scattering plane's normal, Q = I_r - I_l. Turning x by 90 degrees
 * is the rotator diag(1, -1, -1, 1) on both sides, which flips the signs
 * of m12, m21, m34 and m43; so the polarization factors are
 *
 *   P = [1, -m12, 0, 0; -m12, m22, 0, 0; 0, 0, m33, -m34; 0, 0, m34, m44] / m11.
 *
 * `m12` ... `m44` default to 0 (Eradiate's); one number stands for that
 * value at every node. Keys: m11 ... m44 and nodes (when given), spectral
 * updates of the same length (m11 >= 0, not all zero; nodes as above).
 *
 * Source: eradiate/mitsuba3 src/eradiate_plugins/phase/tabphase_polarized.cpp
 * (parameter names, matrix layout, bases); Hansen & Travis 1974, Space
 * Sci. Rev. 16, eq. 2.13. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "../volumes/volume.h"
#include "phase.h"
#include "tabulated.h"

/* The elements besides m11, in the order of their keys. */
enum {
  TPP_M12,
  TPP_M22,
  TPP_M33,
  TPP_M34,
  TPP_M44,
  TPP_N
};
static const char *const tpp_names[TPP_N] = {"m12", "m22", "m33", "m34", "m44"};

typedef struct tabphase_polarized {
  phase base;
  tab_mu d;         /* values: m11 (a parameter); nodes */
  double *m[TPP_N]; /* n each (owned) */
} tabphase_polarized;

static double tpp_sample(const phase *ph, const medium_interaction *mi, double u1, vec2 u2, vec3 *wo,
                         double *pdf) {
  (void)u1;
  return tab_phase_sample(&((const tabphase_polarized *)ph)->d, mi, u2, wo, pdf);
}

static double tpp_eval_pdf(const phase *ph, const medium_interaction *mi, vec3 wo, double *pdf) {
  return tab_phase_eval_pdf(&((const tabphase_polarized *)ph)->d, mi, wo, pdf);
}

/* F / F11 at the scattering cosine of wo, in the kernel's bases (the
 * signs above). */
static void tpp_polarization(const phase *ph, const medium_interaction *mi, vec3 wo, mueller P[3]) {
  const tabphase_polarized *t = (const tabphase_polarized *)ph;
  size_t i;
  double f;
  if (!tab_mu_locate(&t->d, phase_mu(mi, wo), &i, &f)) {
    P[0] = P[1] = P[2] = mu_depolarizer();
    return;
  }
  double e[TPP_N];
  for (int k = 0; k < TPP_N; k++) e[k] = tab_mu_lerp(t->m[k], i, f);
  mueller F = mu_zero();
  F.m[0][0] = tab_mu_lerp(t->d.values, i, f);
  F.m[0][1] = F.m[1][0] = -e[TPP_M12];
  F.m[1][1] = e[TPP_M22];
  F.m[2][2] = e[TPP_M33];
  F.m[2][3] = -e[TPP_M34];
  F.m[3][2] = e[TPP_M34];
  F.m[3][3] = e[TPP_M44];
  P[0] = P[1] = P[2] = mu_normalized(F);
}

static const phase_ops tabphase_polarized_ops = {
    .sample = tpp_sample, .eval_pdf = tpp_eval_pdf, .polarization = tpp_polarization};

static void tabphase_polarized_destroy(object *o) {
  tabphase_polarized *t = (tabphase_polarized *)o;
  if (!t) return;
  tab_mu_free(&t->d);
  for (int k = 0; k < TPP_N; k++) free(t->m[k]);
  free(t);
}

static void tabphase_polarized_traverse(object *o, param_visitor *v) {
  tabphase_polarized *t = (tabphase_polarized *)o;
  pv_buffer(v, "m11", t->d.values, t->d.n, UPDATE_SPECTRAL, 0.0, INFINITY, tab_mu_check_values);
  for (int k = 0; k < TPP_N; k++)
    pv_buffer(v, tpp_names[k], t->m[k], t->d.n, UPDATE_SPECTRAL, -INFINITY, INFINITY, NULL);
  if (t->d.nodes) pv_buffer(v, "nodes", t->d.nodes, t->d.n, UPDATE_SPECTRAL, -1.0, 1.0, tab_mu_check_nodes);
}

static void tabphase_polarized_parameters_changed(object *o) {
  tab_mu_build(&((tabphase_polarized *)o)->d);
}

DEFINE_PLUGIN(tabphase_polarized, CLS_PHASE, .destroy = tabphase_polarized_destroy,
              .ops = &tabphase_polarized_ops, .traverse = tabphase_polarized_traverse,
              .parameters_changed = tabphase_polarized_parameters_changed);

/* Element `name`: n numbers, or one for every node, or absent (zeros). */
static rsw_status tpp_read_element(loader *ld, node *n, const char *name, size_t count, double **out) {
  double *v;
  size_t k;
  bool present;
  rsw_status st = volume_read_numbers(ld, n, name, &v, &k, &present);
  if (st) return st;
  if (present && k != 1 && k != count) {
    free(v);
    return ld_fail(ld, n, name, RSW_ERR_INVALID,
                   "property '%s' has %zu values, 'm11' %zu: they must match (or give one number)", name, k,
                   count);
  }
  double *m = calloc(count, sizeof *m);
  if (!m) {
    free(v);
    return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "tabphase_polarized: out of memory");
  }
  if (present)
    for (size_t i = 0; i < count; i++) m[i] = v[k == 1 ? 0 : i];
  free(v);
  *out = m;
  return RSW_OK;
}

static rsw_status tabphase_polarized_create(loader *ld, node *n, object **out) {
  tabphase_polarized *t = PLUGIN_NEW(tabphase_polarized, tabphase_polarized);
  if (!t) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "tabphase_polarized: out of memory");
  rsw_status st = tab_mu_load(ld, n, "m11", "nodes", &t->d);
  for (int k = 0; k < TPP_N && !st; k++) st = tpp_read_element(ld, n, tpp_names[k], t->d.n, &t->m[k]);
  if (st) {
    tabphase_polarized_destroy(&t->base.base);
    return st;
  }
  t->base.ops = &tabphase_polarized_ops;
  return plugin_created(ld, n, &t->base.base, out);
}
