/* The tabulated density of the scattering cosine (tabulated.h). */
#include "tabulated.h"

#include <math.h>
#include <stdlib.h>

#include "../volumes/volume.h"

/* Start and width of interval i. */
static double tab_start(const tab_mu *t, size_t i) {
  return t->nodes ? t->nodes[i] : -1.0 + (double)i * t->h;
}
static double tab_width(const tab_mu *t, size_t i) {
  return t->nodes ? t->nodes[i + 1] - t->nodes[i] : t->h;
}

void tab_mu_build(tab_mu *t) {
  t->cdf[0] = 0.0;
  for (size_t i = 0; i + 1 < t->n; i++)
    t->cdf[i + 1] = t->cdf[i] + 0.5 * tab_width(t, i) * (t->values[i] + t->values[i + 1]);
}

/* The last i in [0, n - 2] with a[i] <= x (a non-decreasing, n >= 2). */
static size_t tab_search(const double *a, size_t n, double x) {
  size_t lo = 0, hi = n - 1;
  while (hi - lo > 1) {
    size_t mid = (lo + hi) / 2;
    if (a[mid] <= x)
      lo = mid;
    else
      hi = mid;
  }
  return lo;
}

bool tab_mu_locate(const tab_mu *t, double mu, size_t *i, double *f) {
  if (!(mu >= -1.0 && mu <= 1.0)) return false;
  if (!t->nodes) {
    double x = (mu + 1.0) / t->h;
    size_t k = (size_t)x;
    if (k > t->n - 2) k = t->n - 2;
    *i = k;
    *f = x - (double)k;
    return true;
  }
  size_t lo = tab_search(t->nodes, t->n, mu);
  *i = lo;
  *f = (mu - t->nodes[lo]) / (t->nodes[lo + 1] - t->nodes[lo]);
  return true;
}

double tab_mu_pdf(const tab_mu *t, double mu) {
  size_t i;
  double f;
  if (!tab_mu_locate(t, mu, &i, &f)) return 0.0;
  return tab_mu_lerp(t->values, i, f) / t->cdf[t->n - 1];
}

double tab_phase_sample(const tab_mu *t, const medium_interaction *mi, vec2 u2, vec3 *wo, double *pdf) {
  double mu = tab_mu_sample(t, u2.x);
  *wo = phase_direction(mi, mu, u2.y);
  *pdf = tab_mu_pdf(t, mu) * (0.5 / RSW_PI);
  if (!(*pdf > 0.0)) return phase_fail(pdf);
  return 1.0;
}

double tab_phase_eval_pdf(const tab_mu *t, const medium_interaction *mi, vec3 wo, double *pdf) {
  *pdf = tab_mu_pdf(t, phase_mu(mi, wo)) * (0.5 / RSW_PI);
  return *pdf;
}

double tab_mu_sample(const tab_mu *t, double u) {
  double total = t->cdf[t->n - 1], target = u * total;
  /* The interval i with cdf[i] <= target < cdf[i + 1]: first cdf above
   * target, so that empty intervals are never picked. */
  size_t lo = tab_search(t->cdf, t->n, target);
  double a = t->values[lo], b = t->values[lo + 1], area = target - t->cdf[lo], w = tab_width(t, lo);
  double disc = a * a + 2.0 * (b - a) * area / w;
  double den = a + sqrt(fmax(0.0, disc));
  double dt = den > 0.0 ? 2.0 * area / den : 0.0;
  return fmin(1.0, fmax(-1.0, tab_start(t, lo) + fmin(dt, w)));
}

void tab_mu_free(tab_mu *t) {
  free(t->values);
  free(t->nodes);
  free(t->cdf);
  t->values = t->nodes = t->cdf = NULL;
}

/* The first defect of nodes v (n of them), or NULL. */
static const char *nodes_defect(const double *v, size_t n, size_t *at) {
  if (v[0] != -1.0) return (*at = 0, "must start at -1");
  if (v[n - 1] != 1.0) return (*at = n - 1, "must end at 1");
  for (size_t i = 0; i + 1 < n; i++)
    if (!(v[i + 1] > v[i])) return (*at = i + 1, "must be strictly increasing");
  return NULL;
}

rsw_status tab_mu_check_values(const object *owner, const double *v, size_t n, const char *key,
                               rsw_err *err) {
  (void)owner;
  for (size_t i = 0; i < n; i++)
    if (v[i] > 0.0) return RSW_OK;
  return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': the values must not all be zero", key);
}

rsw_status tab_mu_check_nodes(const object *owner, const double *v, size_t n, const char *key, rsw_err *err) {
  (void)owner;
  size_t at;
  const char *why = nodes_defect(v, n, &at);
  return why ? rsw_fail(err, RSW_ERR_INVALID, key, "'%s': the nodes %s (node %zu: %g)", key, why, at, v[at])
             : RSW_OK;
}

rsw_status tab_mu_load(loader *ld, node *n, const char *name, const char *nodes_name, tab_mu *t) {
  double *v, *nodes = NULL;
  size_t k, kn = 0;
  bool present;
  *t = (tab_mu){0};
  rsw_status st = volume_read_numbers(ld, n, name, &v, &k, &present);
  if (st) return st;
  if (!present)
    return ld_fail(ld, n, NULL, RSW_ERR_MISSING, "%s '%s': missing property '%s'", n->type,
                   n->id ? n->id : "", name);
  bool any = false;
  for (size_t i = 0; i < k && !st; i++) {
    if (v[i] < 0.0)
      st = ld_fail(ld, n, name, RSW_ERR_RANGE, "property '%s': value %zu (%g) must be >= 0", name, i, v[i]);
    any |= v[i] > 0.0;
  }
  if (!st && k < 2)
    st = ld_fail(ld, n, name, RSW_ERR_INVALID, "property '%s' needs at least 2 values (got %zu)", name, k);
  if (!st && !any) st = ld_fail(ld, n, name, RSW_ERR_INVALID, "property '%s' must not be all zeros", name);
  if (!st && nodes_name) st = volume_read_numbers(ld, n, nodes_name, &nodes, &kn, &present);
  if (!st && nodes && kn != k)
    st = ld_fail(ld, n, nodes_name, RSW_ERR_INVALID,
                 "property '%s' has %zu values, '%s' %zu: they must match", nodes_name, kn, name, k);
  size_t at;
  const char *why = !st && nodes ? nodes_defect(nodes, kn, &at) : NULL;
  if (why)
    st = ld_fail(ld, n, nodes_name, RSW_ERR_INVALID, "property '%s' %s (node %zu: %g)", nodes_name, why, at,
                 nodes[at]);
  double *cdf = st ? NULL : malloc(k * sizeof *cdf);
  if (!st && !cdf) st = ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "%s: out of memory", n->type);
  if (st) {
    free(v);
    free(nodes);
    return st;
  }
  *t = (tab_mu){.values = v, .nodes = nodes, .cdf = cdf, .n = k, .h = 2.0 / (double)(k - 1)};
  tab_mu_build(t);
  return RSW_OK;
}
