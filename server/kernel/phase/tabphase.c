/* `tabphase`: a phase function tabulated on a regular grid of the
 * scattering cosine, mu_i = -1 + 2 i / (n - 1), i = 0..n-1 (mu = 1 is
 * forward scattering, mu = -dot(wi, wo), phase.h), linear in between and
 * normalised:
 *
 *   p(mu) = f(mu) / (2 pi I),  f the piecewise-linear interpolant of the
 *   values, I = int_{-1}^{1} f dmu (trapezoids: exact for f);
 *
 * so that 2 pi int p dmu = 1. Sampling picks an interval by its share of
 * I (u.x), then inverts the linear density inside it in closed form:
 * with end values a, b over width h and target area A,
 * a t + (b - a) t^2 / (2 h) = A gives t = 2 A / (a + sqrt(a^2 + 2 (b - a) A / h))
 * (the cancellation-free root); the azimuth is uniform (u.y); pdf = p(mu),
 * weight 1.
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
#include "../volumes/volume.h"
#include "phase.h"

typedef struct tabphase {
  phase base;
  double *values; /* n (owned; the parameter) */
  double *cdf;    /* n: cdf[i] = int_{-1}^{mu_i} f (owned) */
  size_t n;
  double h; /* 2 / (n - 1) */
} tabphase;

static void tab_build(tabphase *t) {
  t->cdf[0] = 0.0;
  for (size_t i = 0; i + 1 < t->n; i++)
    t->cdf[i + 1] = t->cdf[i] + 0.5 * t->h * (t->values[i] + t->values[i + 1]);
}

/* The normalised density of mu (per unit mu) at mu. */
static double tab_pdf_mu(const tabphase *t, double mu) {
  if (!(mu >= -1.0 && mu <= 1.0)) return 0.0;
  double x = (mu + 1.0) / t->h;
  size_t i = (size_t)x;
  if (i > t->n - 2) i = t->n - 2;
  double f = x - (double)i;
  return (t->values[i] + f * (t->values[i + 1] - t->values[i])) / t->cdf[t->n - 1];
}

static double tab_sample(const phase *ph, const medium_interaction *mi, double u1, vec2 u2, vec3 *wo,
                         double *pdf) {
  (void)u1;
  const tabphase *t = (const tabphase *)ph;
  double total = t->cdf[t->n - 1], target = u2.x * total;
  /* The interval i with cdf[i] <= target < cdf[i + 1]: first cdf above
   * target, so that empty intervals are never picked. */
  size_t lo = 0, hi = t->n - 1;
  while (hi - lo > 1) {
    size_t mid = (lo + hi) / 2;
    if (t->cdf[mid] <= target)
      lo = mid;
    else
      hi = mid;
  }
  double a = t->values[lo], b = t->values[lo + 1], area = target - t->cdf[lo];
  double disc = a * a + 2.0 * (b - a) * area / t->h;
  double den = a + sqrt(fmax(0.0, disc));
  double dt = den > 0.0 ? 2.0 * area / den : 0.0;
  double mu = fmin(1.0, fmax(-1.0, -1.0 + (double)lo * t->h + fmin(dt, t->h)));
  *wo = phase_direction(mi, mu, u2.y);
  *pdf = tab_pdf_mu(t, mu) * (0.5 / RSW_PI);
  if (!(*pdf > 0.0)) return phase_fail(pdf);
  return 1.0;
}

static double tab_eval_pdf(const phase *ph, const medium_interaction *mi, vec3 wo, double *pdf) {
  *pdf = tab_pdf_mu((const tabphase *)ph, phase_mu(mi, wo)) * (0.5 / RSW_PI);
  return *pdf;
}

static const phase_ops tabphase_ops = {.sample = tab_sample, .eval_pdf = tab_eval_pdf};

static void tabphase_destroy(object *o) {
  tabphase *t = (tabphase *)o;
  if (!t) return;
  free(t->values);
  free(t->cdf);
  free(t);
}

/* Not all zero (the range check already made them finite and >= 0). */
static rsw_status tab_check(const object *owner, const double *v, size_t n, const char *key, rsw_err *err) {
  (void)owner;
  for (size_t i = 0; i < n; i++)
    if (v[i] > 0.0) return RSW_OK;
  return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': the values must not all be zero", key);
}

static rsw_status tabphase_create(loader *ld, node *n, object **out) {
  double *v;
  size_t k;
  bool present;
  rsw_status st = volume_read_numbers(ld, n, "values", &v, &k, &present);
  if (st) return st;
  if (!present)
    return ld_fail(ld, n, NULL, RSW_ERR_MISSING, "tabphase '%s': missing property 'values'",
                   n->id ? n->id : "");
  bool any = false;
  for (size_t i = 0; i < k && !st; i++) {
    if (v[i] < 0.0)
      st = ld_fail(ld, n, "values", RSW_ERR_RANGE, "property 'values': value %zu (%g) must be >= 0", i, v[i]);
    any |= v[i] > 0.0;
  }
  if (!st && k < 2)
    st = ld_fail(ld, n, "values", RSW_ERR_INVALID, "property 'values' needs at least 2 values (got %zu)", k);
  if (!st && !any) st = ld_fail(ld, n, "values", RSW_ERR_INVALID, "property 'values' must not be all zeros");
  tabphase *t = st ? NULL : calloc(1, sizeof *t);
  double *cdf = st ? NULL : malloc(k * sizeof *cdf);
  if (!st && (!t || !cdf)) st = ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "tabphase: out of memory");
  if (st) {
    free(v);
    free(t);
    free(cdf);
    return st;
  }
  t->base.ops = &tabphase_ops;
  t->base.base.id = n->id;
  t->values = v;
  t->cdf = cdf;
  t->n = k;
  t->h = 2.0 / (double)(k - 1);
  tab_build(t);
  *out = &t->base.base;
  return RSW_OK;
}

static void tabphase_traverse(object *o, param_visitor *v) {
  tabphase *t = (tabphase *)o;
  pv_buffer(v, "values", t->values, t->n, UPDATE_SPECTRAL, 0.0, INFINITY, tab_check);
}

static void tabphase_parameters_changed(object *o) {
  tab_build((tabphase *)o);
}

DEFINE_PLUGIN(tabphase, CLS_PHASE, .destroy = tabphase_destroy, .ops = &tabphase_ops,
              .traverse = tabphase_traverse, .parameters_changed = tabphase_parameters_changed);
