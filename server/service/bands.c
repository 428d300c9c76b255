/* Spectral response functions (bands): parsing, the quadrature, and a
 * band's film from its nodes (bands.h).
 *
 * The quadrature. Every SRF S is a weight function on its support
 * [lo, hi]; a band's rule is the n-point Gauss rule of that weight
 * (Golub and Welsch, "Calculation of Gauss quadrature rules", Math. Comp.
 * 23, 1969): nodes inside the support, positive weights, and
 *
 *   Σ w_i p(λ_i) = ∫ p(λ) S(λ) dλ   for every polynomial p of degree <= 2n-1,
 *
 * so a spectrum that is smooth on the scale of the node spacing is
 * integrated with an error that falls off geometrically with n
 * (docs/experiments.md#spectral-response-functions-bands has the measured figures). The rule comes
 * from the recurrence of the polynomials orthogonal under S, computed by
 * the discretised Stieltjes procedure (Gautschi, "Orthogonal Polynomials:
 * Computation and Approximation", 2004, §2.2.3) on a discrete measure
 * whose moments up to degree 2n-1 equal S's:
 *   - uniform S = 1 on [wmin, wmax]: Gauss-Legendre itself;
 *   - tabulated S, linear between its samples: per interval, the
 *     (n+1)-point Gauss-Legendre rule times S (exact: S p has degree 2n
 *     on each interval);
 *   - gaussian S = exp(-(λ-μ)²/(2σ²)), σ = fwhm / (2 sqrt(2 ln 2)),
 *     truncated at μ ± 4σ (the tails hold 6.3e-5 of its integral): 32
 *     panels of 24-point Gauss-Legendre (moments to ~1e-15).
 * The nodes and weights are the eigenvalues of the Jacobi matrix and
 * μ0 times the squared first components of its eigenvectors, found by the
 * implicit QL method (Bowdler, Martin, Reinsch and Wilkinson, Numer. Math.
 * 11, 1968). */
#include "bands.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "service_internal.h"
#include "stokes.h"

/* ---- Gauss-Legendre on [-1, 1] ---------------------------------------------------- */

/* The m-point rule: nodes x (ascending) and weights w. Newton's method on
 * P_m from the Chebyshev-like first guess cos(π (i + 3/4) / (m + 1/2)). */
static void gauss_legendre(int m, double *x, double *w) {
  for (int i = 0; i < (m + 1) / 2; i++) {
    double z = cos(M_PI * (i + 0.75) / (m + 0.5)), pp = 1;
    for (int it = 0; it < 100; it++) {
      double p0 = 1, p1 = 0;
      for (int k = 1; k <= m; k++) {
        double p2 = p1;
        p1 = p0;
        p0 = ((2.0 * k - 1) * z * p1 - (k - 1.0) * p2) / k;
      }
      pp = m * (z * p0 - p1) / (z * z - 1); /* P_m'(z) */
      double dz = p0 / pp;
      z -= dz;
      if (fabs(dz) < 1e-16) break;
    }
    x[i] = -z, x[m - 1 - i] = z;
    w[i] = w[m - 1 - i] = 2 / ((1 - z * z) * pp * pp);
  }
}

/* ---- Gauss rule of a discrete measure --------------------------------------------- */

/* Eigenvalues of the symmetric tridiagonal matrix (diagonal d, e[i]
 * coupling i and i+1, e[n-1] unused) into d, and the first components of
 * the normalised eigenvectors into z (z = e_1 on entry): the implicit QL
 * method with Wilkinson's shift. false when it does not converge. */
static bool tridiag_ql(double *d, double *e, double *z, int n) {
  e[n - 1] = 0;
  for (int l = 0; l < n; l++) {
    for (int iter = 0;; iter++) {
      int m = l;
      while (m < n - 1 && fabs(e[m]) > DBL_EPSILON * (fabs(d[m]) + fabs(d[m + 1]))) m++;
      if (m == l) break;
      if (iter == 64) return false;
      double g = (d[l + 1] - d[l]) / (2 * e[l]);
      double r = hypot(g, 1.0);
      g = d[m] - d[l] + e[l] / (g + copysign(r, g));
      double s = 1, c = 1, p = 0;
      int i = m - 1;
      bool deflated = false;
      for (; i >= l; i--) {
        double f = s * e[i], b = c * e[i];
        r = hypot(f, g);
        e[i + 1] = r;
        if (r == 0) { /* split: the rotation chain stops here */
          d[i + 1] -= p;
          e[m] = 0;
          deflated = true;
          break;
        }
        s = f / r, c = g / r;
        g = d[i + 1] - p;
        r = (d[i] - g) * s + 2 * c * b;
        p = s * r;
        d[i + 1] = g + p;
        g = c * r - b;
        double zf = z[i + 1];
        z[i + 1] = s * z[i] + c * zf;
        z[i] = c * z[i] - s * zf;
      }
      if (deflated) continue;
      d[l] -= p;
      e[l] = g;
      e[m] = 0;
    }
  }
  return true;
}

/* The n-point Gauss rule of the measure Σ_k mass[k] δ(t - t[k]) (t in
 * [-1, 1], masses >= 0), by the discretised Stieltjes procedure: the
 * recurrence p_{k+1} = (t - a_k) p_k - b_k p_{k-1} of its monic orthogonal
 * polynomials, then Golub-Welsch. Nodes ascending into xs[], weights
 * into wt[] (Σ wt = Σ mass). Returns the nodes found: fewer than n when
 * the measure has fewer points of mass (its polynomials vanish there), 0
 * when out of memory or the eigenvalues do not converge. */
static int gauss_rule(const double *t, const double *mass, size_t M, int n, double *xs, double *wt) {
  double a[BAND_MAX_NODES], b[BAND_MAX_NODES];
  double *p0 = calloc(M, sizeof *p0), *p1 = malloc(M * sizeof *p1);
  if (!p0 || !p1) {
    free(p0), free(p1);
    return 0;
  }
  for (size_t k = 0; k < M; k++) p1[k] = 1; /* p_0; p0 holds p_{-1} = 0 */
  double norm_prev = 1, norm0 = 0;
  int found = 0;
  for (int j = 0; j < n; j++) {
    double nm = 0, tm = 0;
    for (size_t k = 0; k < M; k++) {
      double q = mass[k] * p1[k] * p1[k];
      nm += q, tm += q * t[k];
    }
    if (j == 0) norm0 = nm;
    if (!(nm > norm0 * 1e-28)) break; /* no more independent polynomials */
    a[j] = tm / nm;
    b[j] = j == 0 ? nm : nm / norm_prev;
    norm_prev = nm;
    found = j + 1;
    for (size_t k = 0; k < M; k++) {
      double next = (t[k] - a[j]) * p1[k] - (j ? b[j] : 0) * p0[k];
      p0[k] = p1[k], p1[k] = next;
    }
  }
  free(p0), free(p1);
  if (!found) return 0;
  double e[BAND_MAX_NODES], z[BAND_MAX_NODES];
  for (int j = 0; j < found; j++) {
    xs[j] = a[j];
    e[j] = j + 1 < found ? sqrt(b[j + 1]) : 0;
    z[j] = j == 0;
  }
  if (!tridiag_ql(xs, e, z, found)) return 0;
  for (int j = 0; j < found; j++) wt[j] = norm0 * z[j] * z[j];
  /* Ascending (insertion sort: n <= 64). */
  for (int j = 1; j < found; j++)
    for (int k = j; k > 0 && xs[k] < xs[k - 1]; k--) {
      double tn = xs[k], tw = wt[k];
      xs[k] = xs[k - 1], wt[k] = wt[k - 1];
      xs[k - 1] = tn, wt[k - 1] = tw;
    }
  return found;
}

/* ---- SRFs ------------------------------------------------------------------------- */

typedef struct srf_in {
  int kind; /* 0 uniform, 1 gaussian, 2 tabulated */
  double wmin, wmax, mean, fwhm;
  const double *twl, *tval;
  size_t tn;
} srf_in;

/* b's nodes and weights for the SRF s with n nodes (b->lo, b->hi set). */
static rsw_status band_rule(const srf_in *s, int n, band *b, const char *ptr, svc_error *e) {
  double c = 0.5 * (b->lo + b->hi), h = 0.5 * (b->hi - b->lo);
  double tn[BAND_MAX_NODES], tw[BAND_MAX_NODES];
  int found;
  if (s->kind == 0) {
    gauss_legendre(n, tn, tw);
    for (int i = 0; i < n; i++) tw[i] *= h; /* weights in nm */
    found = n;
  } else {
    /* The discrete measure, in t = (λ - c) / h with masses in nm. */
    int m = s->kind == 1 ? 24 : n + 1;
    size_t panels = s->kind == 1 ? 32 : s->tn - 1;
    size_t M = panels * (size_t)m;
    double *t = malloc(M * sizeof *t), *mass = malloc(M * sizeof *mass);
    double gx[BAND_MAX_NODES + 1 > 24 ? BAND_MAX_NODES + 1 : 24],
        gw[BAND_MAX_NODES + 1 > 24 ? BAND_MAX_NODES + 1 : 24];
    if (!t || !mass) {
      free(t), free(mass);
      return svc_fail(e, RSW_ERR_NOMEM, ptr, "out of memory");
    }
    gauss_legendre(m, gx, gw);
    size_t k = 0;
    double sigma = s->fwhm / (2 * sqrt(2 * log(2.0)));
    for (size_t p = 0; p < panels; p++) {
      double x0, x1;
      if (s->kind == 1)
        x0 = b->lo + (b->hi - b->lo) * (double)p / (double)panels,
        x1 = b->lo + (b->hi - b->lo) * (double)(p + 1) / (double)panels;
      else
        x0 = s->twl[p], x1 = s->twl[p + 1];
      double hc = 0.5 * (x0 + x1), hh = 0.5 * (x1 - x0);
      for (int q = 0; q < m; q++) {
        double x = hc + hh * gx[q], sv;
        if (s->kind == 1) {
          double u = (x - s->mean) / sigma;
          sv = exp(-0.5 * u * u);
        } else {
          double f = (x - x0) / (x1 - x0);
          sv = s->tval[p] + f * (s->tval[p + 1] - s->tval[p]);
        }
        t[k] = (x - c) / h;
        mass[k] = gw[q] * hh * sv;
        k++;
      }
    }
    found = gauss_rule(t, mass, M, n, tn, tw);
    free(t), free(mass);
    if (!found) return svc_fail(e, RSW_ERR_NOMEM, ptr, "out of memory (or no quadrature for this SRF)");
  }
  b->n_nodes = (size_t)found;
  b->integral = 0;
  for (int i = 0; i < found; i++) {
    b->wl[i] = c + h * tn[i];
    b->w[i] = tw[i];
    b->integral += tw[i];
  }
  if (!(b->integral > 0))
    return svc_fail(e, RSW_ERR_INVALID, ptr, "the SRF's integral is 0: it weights no wavelength");
  return RSW_OK;
}

/* A member that must be a finite number (positive when pos). */
static rsw_status get_num(const cJSON *o, const char *name, bool pos, const char *ptr, double *out,
                          svc_error *e) {
  char w[200];
  snprintf(w, sizeof w, "%s/%s", ptr, name);
  const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, name);
  if (!x) return svc_fail(e, RSW_ERR_MISSING, w, "this SRF needs \"%s\"", name);
  if (!cJSON_IsNumber(x)) return svc_fail(e, RSW_ERR_TYPE, w, "\"%s\" must be a number", name);
  if (!isfinite(x->valuedouble)) return svc_fail(e, RSW_ERR_INVALID, w, "\"%s\" must be finite", name);
  if (pos && !(x->valuedouble > 0)) return svc_fail(e, RSW_ERR_INVALID, w, "\"%s\" must be positive", name);
  *out = x->valuedouble;
  return RSW_OK;
}

/* The members of an object must be among names (NULL-terminated). */
static rsw_status only_members(const cJSON *o, const char *const *names, const char *ptr, const char *what,
                               svc_error *e) {
  for (const cJSON *k = o->child; k; k = k->next) {
    bool known = false;
    for (const char *const *n = names; *n && !known; n++) known = strcmp(*n, k->string) == 0;
    if (!known) {
      char w[300], list[200] = "";
      for (const char *const *n = names; *n; n++)
        snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", n == names ? "" : ", ", *n);
      snprintf(w, sizeof w, "%s/%s", ptr, k->string);
      return svc_fail(e, RSW_ERR_UNUSED_PROPERTY, w, "unknown field '%s' in %s (expected %s)", k->string,
                      what, list);
    }
  }
  return RSW_OK;
}

/* Numbers of a tabulated SRF's list into a malloc'ed array. */
static rsw_status get_list(const cJSON *o, const char *name, const char *ptr, double **out, size_t *n,
                           svc_error *e) {
  char w[200];
  snprintf(w, sizeof w, "%s/%s", ptr, name);
  const cJSON *a = cJSON_GetObjectItemCaseSensitive(o, name);
  if (!a) return svc_fail(e, RSW_ERR_MISSING, w, "a tabulated SRF needs \"%s\"", name);
  if (!cJSON_IsArray(a)) return svc_fail(e, RSW_ERR_TYPE, w, "\"%s\" must be a list of numbers", name);
  size_t len = (size_t)cJSON_GetArraySize(a);
  if (len < 2 || len > BAND_MAX_TABLE)
    return svc_fail(e, RSW_ERR_INVALID, w, "a tabulated SRF needs 2 to %d samples (%zu given)",
                    BAND_MAX_TABLE, len);
  double *v = malloc(len * sizeof *v);
  if (!v) return svc_fail(e, RSW_ERR_NOMEM, w, "out of memory");
  size_t i = 0;
  for (const cJSON *x = a->child; x; x = x->next, i++) {
    char wi[240];
    snprintf(wi, sizeof wi, "%s/%zu", w, i);
    if (!cJSON_IsNumber(x) || !isfinite(x->valuedouble)) {
      free(v);
      return svc_fail(e, cJSON_IsNumber(x) ? RSW_ERR_INVALID : RSW_ERR_TYPE, wi,
                      "\"%s\" entries must be finite numbers", name);
    }
    v[i] = x->valuedouble;
  }
  *out = v;
  *n = len;
  return RSW_OK;
}

/* One band {"id", "srf", "nodes"} at ptr into b. */
static rsw_status parse_band(const cJSON *o, const char *ptr, band *b, svc_error *e) {
  static const char *const band_keys[] = {"id", "srf", "nodes", NULL};
  if (!cJSON_IsObject(o))
    return svc_fail(e, RSW_ERR_TYPE, ptr, "a band must be an object {\"id\": ..., \"srf\": {...}}");
  rsw_status st = only_members(o, band_keys, ptr, "a band", e);
  if (st) return st;
  char w[200];
  const cJSON *id = cJSON_GetObjectItemCaseSensitive(o, "id");
  snprintf(w, sizeof w, "%s/id", ptr);
  if (!cJSON_IsString(id) || !svc_valid_id(id->valuestring))
    return svc_fail(e, id ? RSW_ERR_INVALID : RSW_ERR_MISSING, w,
                    "a band's \"id\" must match [A-Za-z0-9._-]{1,64}");
  snprintf(b->id, sizeof b->id, "%s", id->valuestring);
  int n = 0;
  const cJSON *nodes = cJSON_GetObjectItemCaseSensitive(o, "nodes");
  if (nodes) {
    snprintf(w, sizeof w, "%s/nodes", ptr);
    if (!cJSON_IsNumber(nodes) || nodes->valuedouble != floor(nodes->valuedouble) || nodes->valuedouble < 1 ||
        nodes->valuedouble > BAND_MAX_NODES)
      return svc_fail(e, RSW_ERR_INVALID, w, "\"nodes\" must be an integer from 1 to %d", BAND_MAX_NODES);
    n = (int)nodes->valuedouble;
  }
  const cJSON *srf = cJSON_GetObjectItemCaseSensitive(o, "srf");
  char sp[160];
  snprintf(sp, sizeof sp, "%s/srf", ptr);
  if (!srf) return svc_fail(e, RSW_ERR_MISSING, sp, "a band needs an \"srf\"");
  if (!cJSON_IsObject(srf)) return svc_fail(e, RSW_ERR_TYPE, sp, "\"srf\" must be an object with a \"type\"");
  const cJSON *type = cJSON_GetObjectItemCaseSensitive(srf, "type");
  snprintf(w, sizeof w, "%s/type", sp);
  static const char *const types[] = {"uniform", "gaussian", "tabulated"};
  static const char *const keys[3][4] = {{"type", "wmin", "wmax", NULL},
                                         {"type", "mean", "fwhm", NULL},
                                         {"type", "wavelengths", "values", NULL}};
  srf_in s = {.kind = -1};
  for (int k = 0; k < 3 && cJSON_IsString(type); k++)
    if (strcmp(type->valuestring, types[k]) == 0) s.kind = k;
  if (s.kind < 0)
    return svc_fail(e, type ? RSW_ERR_UNKNOWN_NAME : RSW_ERR_MISSING, w,
                    "an SRF's \"type\" is one of uniform, gaussian, tabulated");
  b->type = types[s.kind];
  st = only_members(srf, keys[s.kind], sp, "this SRF", e);
  if (st) return st;
  double width = 0;
  double *twl = NULL, *tval = NULL;
  if (s.kind == 0) {
    if ((st = get_num(srf, "wmin", true, sp, &s.wmin, e)) ||
        (st = get_num(srf, "wmax", true, sp, &s.wmax, e)))
      return st;
    if (!(s.wmax > s.wmin)) {
      snprintf(w, sizeof w, "%s/wmax", sp);
      return svc_fail(e, RSW_ERR_INVALID, w, "wmax (%g nm) must exceed wmin (%g nm): the SRF's integral is 0",
                      s.wmax, s.wmin);
    }
    b->lo = s.wmin, b->hi = s.wmax, width = s.wmax - s.wmin;
  } else if (s.kind == 1) {
    if ((st = get_num(srf, "mean", true, sp, &s.mean, e))) return st;
    const cJSON *f = cJSON_GetObjectItemCaseSensitive(srf, "fwhm");
    snprintf(w, sizeof w, "%s/fwhm", sp);
    if (cJSON_IsNumber(f) && isfinite(f->valuedouble) && !(f->valuedouble > 0))
      return svc_fail(e, RSW_ERR_INVALID, w, "\"fwhm\" must be positive (%g): the SRF's integral would be 0",
                      f->valuedouble);
    if ((st = get_num(srf, "fwhm", true, sp, &s.fwhm, e))) return st;
    double sigma = s.fwhm / (2 * sqrt(2 * log(2.0)));
    b->lo = s.mean - BAND_GAUSS_SIGMAS * sigma, b->hi = s.mean + BAND_GAUSS_SIGMAS * sigma;
    if (!(b->lo > 0))
      return svc_fail(e, RSW_ERR_RANGE, w, "the gaussian reaches below 0 nm (mean - %g sigma = %g nm)",
                      BAND_GAUSS_SIGMAS, b->lo);
    width = 2 * s.fwhm;
  } else {
    size_t nw = 0, nv = 0;
    if ((st = get_list(srf, "wavelengths", sp, &twl, &nw, e))) return st;
    if ((st = get_list(srf, "values", sp, &tval, &nv, e))) {
      free(twl);
      return st;
    }
    if (nw != nv) {
      snprintf(w, sizeof w, "%s/values", sp);
      st = svc_fail(e, RSW_ERR_INVALID, w, "%zu values for %zu wavelengths", nv, nw);
    }
    for (size_t i = 0; !st && i < nw; i++) {
      char wi[240];
      if (!(twl[i] > 0) || (i && !(twl[i] > twl[i - 1]))) {
        snprintf(wi, sizeof wi, "%s/wavelengths/%zu", sp, i);
        st = svc_fail(e, RSW_ERR_INVALID, wi, "SRF wavelengths must be positive and strictly increasing");
      } else if (tval[i] < 0) {
        snprintf(wi, sizeof wi, "%s/values/%zu", sp, i);
        st = svc_fail(e, RSW_ERR_INVALID, wi, "SRF values must not be negative (%g)", tval[i]);
      }
    }
    /* The support: from the last zero before the first positive value to
     * the first zero after the last one (the table's ends otherwise). */
    size_t first = nw, last = 0;
    for (size_t i = 0; !st && i < nw; i++)
      if (tval[i] > 0) {
        if (first == nw) first = i;
        last = i;
      }
    if (!st && first == nw) {
      snprintf(w, sizeof w, "%s/values", sp);
      st = svc_fail(e, RSW_ERR_INVALID, w, "every SRF value is 0: the SRF's integral is 0");
    }
    if (!st) {
      size_t i0 = first ? first - 1 : 0, i1 = last + 1 < nw ? last + 1 : nw - 1;
      b->lo = twl[i0], b->hi = twl[i1], width = b->hi - b->lo;
      s.twl = twl + i0, s.tval = tval + i0, s.tn = i1 - i0 + 1;
      if (s.tn < 2) {
        snprintf(w, sizeof w, "%s/values", sp);
        st = svc_fail(e, RSW_ERR_INVALID, w, "the SRF's integral is 0");
      }
    }
  }
  if (!st && !n) {
    double d = ceil(width / BAND_DEFAULT_SPAN) + 1;
    n = d < 2 ? 2 : d > BAND_DEFAULT_NODES ? BAND_DEFAULT_NODES : (int)d;
  }
  if (!st) st = band_rule(&s, n, b, sp, e);
  free(twl), free(tval);
  return st;
}

static int cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return x < y ? -1 : x > y;
}

void bands_free(band_plan *p) {
  if (!p) return;
  free(p->b);
  free(p->wl);
  free(p);
}

rsw_status bands_parse(const cJSON *v, const char *ptr, band_plan **out, svc_error *e) {
  if (!cJSON_IsArray(v) || !v->child)
    return svc_fail(e, RSW_ERR_TYPE, ptr, "\"bands\" must be a non-empty list of {\"id\", \"srf\"}");
  size_t n = (size_t)cJSON_GetArraySize(v);
  if (n > BANDS_MAX)
    return svc_fail(e, RSW_ERR_LIMIT, ptr, "%zu bands; a job may have at most %d", n, BANDS_MAX);
  band_plan *p = calloc(1, sizeof *p);
  if (p) p->b = calloc(n, sizeof *p->b);
  if (p && p->b) p->wl = malloc(n * BAND_MAX_NODES * sizeof *p->wl);
  if (!p || !p->b || !p->wl) {
    bands_free(p);
    return svc_fail(e, RSW_ERR_NOMEM, ptr, "out of memory");
  }
  rsw_status st = RSW_OK;
  for (const cJSON *o = v->child; o && !st; o = o->next, p->n++) {
    char w[64];
    snprintf(w, sizeof w, "%s/%zu", ptr, p->n);
    st = parse_band(o, w, &p->b[p->n], e);
    for (size_t j = 0; !st && j < p->n; j++)
      if (strcmp(p->b[j].id, p->b[p->n].id) == 0) {
        char wi[80];
        snprintf(wi, sizeof wi, "%s/id", w);
        st = svc_fail(e, RSW_ERR_DUPLICATE, wi, "band id '%s' appears twice", p->b[j].id);
      }
  }
  if (st) {
    bands_free(p);
    return st;
  }
  /* The distinct node wavelengths, and each node's slot among them. */
  size_t k = 0;
  for (size_t i = 0; i < p->n; i++)
    for (size_t j = 0; j < p->b[i].n_nodes; j++) p->wl[k++] = p->b[i].wl[j];
  qsort(p->wl, k, sizeof *p->wl, cmp_double);
  p->n_wl = 0;
  for (size_t i = 0; i < k; i++)
    if (!p->n_wl || p->wl[i] != p->wl[p->n_wl - 1]) p->wl[p->n_wl++] = p->wl[i];
  for (size_t i = 0; i < p->n; i++)
    for (size_t j = 0; j < p->b[i].n_nodes; j++) {
      double *hit = bsearch(&p->b[i].wl[j], p->wl, p->n_wl, sizeof *p->wl, cmp_double);
      p->b[i].slot[j] = (size_t)(hit - p->wl);
    }
  *out = p;
  return RSW_OK;
}

size_t bands_find(const band_plan *p, const char *id) {
  for (size_t i = 0; p && i < p->n; i++)
    if (strcmp(p->b[i].id, id) == 0) return i;
  return SIZE_MAX;
}

uint64_t bands_node_seed(uint64_t context_seed, double wavelength) {
  /* FNV-1a 64 over the two values' bytes, folded to 32 bits (the seeds of
   * jobs.c's default_seed). */
  uint64_t bits;
  memcpy(&bits, &wavelength, sizeof bits);
  uint64_t h = 1469598103934665603ULL;
  for (int i = 0; i < 8; i++) h = (h ^ ((context_seed >> (8 * i)) & 0xff)) * 1099511628211ULL;
  for (int i = 0; i < 8; i++) h = (h ^ ((bits >> (8 * i)) & 0xff)) * 1099511628211ULL;
  return (h ^ (h >> 32)) & 0xffffffffULL;
}

/* ---- a band's film ---------------------------------------------------------------- */

rsw_status bands_combine(const band *b, const film_image *const *nodes, film_image *out, rsw_err *err) {
  const film_image *f0 = nodes[0];
  size_t C = (size_t)f0->channels, n = (size_t)f0->width * (size_t)f0->height * C;
  for (size_t i = 1; i < b->n_nodes; i++) {
    const film_image *f = nodes[i];
    bool same = f->width == f0->width && f->height == f0->height && f->channels == f0->channels &&
                f->n_planes == f0->n_planes && f->has_irradiance == f0->has_irradiance;
    for (int p = 0; same && p < f0->n_planes; p++) same = strcmp(f->planes[p].name, f0->planes[p].name) == 0;
    if (!same)
      return rsw_fail(err, RSW_ERR_INVALID, b->id, "the films of band '%s' differ in shape or planes", b->id);
  }
  film_image o = *f0;
  o.data = NULL, o.angles = NULL;
  for (int p = 0; p < FILM_MAX_PLANES; p++) o.planes[p].data = NULL;
  o.n_planes = 0;
  o.wavelength = NAN;
  double W = b->integral;
  /* Every Stokes component (stokes.h) integrates on its own, as any
   * channel: the band's Stokes vector is Σ w_i S_i / Σ w_i, and its DoLP
   * and AoLP are the dataset's, derived from that vector (never a mean of
   * the nodes' DoLPs). E_h is per colour: a Stokes film's channel k
   * divides by its colour's, E[k % n_color]. */
  size_t n_ir = C;
  stokes_layout sl;
  if ((size_t)f0->channels <= sizeof f0->channel_names / sizeof f0->channel_names[0] &&
      stokes_layout_of(f0->channel_names, f0->channels, &sl))
    n_ir = (size_t)sl.n_color;
  double e_srf[4] = {0, 0, 0, 0};
  if (f0->has_irradiance)
    for (size_t c = 0; c < n_ir && c < 4; c++) {
      double s = 0;
      for (size_t i = 0; i < b->n_nodes; i++) s += b->w[i] * nodes[i]->irradiance[c];
      e_srf[c] = s / W;
    }
  for (size_t c = 0; f0->has_irradiance && c < C && c < FILM_MAX_CHANNELS; c++)
    o.irradiance[c] = e_srf[c % n_ir];
  bool ok = (o.data = film_pixels_new(n)) != NULL;
  if (ok) o.angles = film_angles_ref(f0->angles); /* (the nodes', shared) */
  for (int p = 0; ok && p < f0->n_planes; p++) {
    o.planes[p] = f0->planes[p];
    ok = (o.planes[p].data = film_pixels_new(n)) != NULL;
    o.n_planes = p + 1;
  }
  if (!ok) {
    film_image_free(&o);
    return rsw_fail(err, RSW_ERR_NOMEM, b->id, "out of memory for band '%s'", b->id);
  }
  /* The node films' errors: independent between renders of their own
   * seeds, but node films rendered in one spectral bundle share its seed
   * and its paths, so their errors are correlated and only bounded:
   * sd(Σ_{i∈B} w_i X_i) ≤ Σ_{i∈B} |w_i| s_i (Cauchy–Schwarz). So the
   * band's variance is Σ over bundles of (Σ_{i∈B} |w_i| s_i)²: exact for
   * nodes rendered alone, an upper bound for bundled ones
   * (docs/experiments.md#standard-errors). group[i]: node i's bundle, by
   * seed. */
  size_t group[BAND_MAX_NODES], n_groups = 0;
  for (size_t i = 0; i < b->n_nodes && i < BAND_MAX_NODES; i++) {
    size_t g = 0;
    while (g < i && nodes[g]->seed != nodes[i]->seed) g++;
    group[i] = g < i ? group[g] : n_groups++;
  }
  for (size_t q = 0; q < n; q++) {
    double s = 0;
    for (size_t i = 0; i < b->n_nodes; i++) s += b->w[i] * (double)nodes[i]->data[q];
    double l = s / W;
    o.data[q] = (float)l;
    size_t c = q % C;
    for (int p = 0; p < o.n_planes; p++) {
      const char *name = o.planes[p].name;
      double v;
      if (strcmp(name, "radiance_stderr") == 0) {
        double sum[BAND_MAX_NODES], var = 0;
        for (size_t g = 0; g < n_groups; g++) sum[g] = 0;
        for (size_t i = 0; i < b->n_nodes; i++) sum[group[i]] += fabs(b->w[i]) * nodes[i]->planes[p].data[q];
        for (size_t g = 0; g < n_groups; g++) var += sum[g] * sum[g];
        v = sqrt(var) / W;
      } else {
        v = (strcmp(name, "brf") == 0 ? M_PI : 1.0) * l / e_srf[c % n_ir < 4 ? c % n_ir : 0];
      }
      o.planes[p].data[q] = (float)v;
    }
  }
  *out = o;
  return RSW_OK;
}

/* ---- bands in jobs ---------------------------------------------------------------- */

rsw_status svc_bands_check_context(const band_plan *p, const cJSON *c, const char *ptr, svc_error *e) {
  (void)p;
  char w[120];
  if (cJSON_GetObjectItemCaseSensitive(c, "wavelength")) {
    snprintf(w, sizeof w, "%s/wavelength", ptr);
    return svc_fail(e, RSW_ERR_INVALID, w,
                    "a job with bands renders each band's wavelengths: its contexts take no wavelength");
  }
  const cJSON *coords = cJSON_GetObjectItemCaseSensitive(c, "coords");
  if (cJSON_IsObject(coords) && cJSON_GetObjectItemCaseSensitive(coords, "wavelength")) {
    snprintf(w, sizeof w, "%s/coords/wavelength", ptr);
    return svc_fail(
        e, RSW_ERR_INVALID, w,
        "a job with bands renders each band's wavelengths: its contexts take no wavelength coord");
  }
  if (cJSON_IsObject(coords) && cJSON_GetObjectItemCaseSensitive(coords, "band")) {
    snprintf(w, sizeof w, "%s/coords/band", ptr);
    return svc_fail(e, RSW_ERR_INVALID, w, "\"band\" is the dataset's band dimension in a job with bands");
  }
  return RSW_OK;
}

void svc_bands_results_json(const job *j, cJSON *o) {
  const band_plan *p = j->bands;
  cJSON *a = cJSON_AddArrayToObject(o, "bands");
  for (size_t b = 0; b < p->n; b++) {
    const band *bd = &p->b[b];
    cJSON *x = cJSON_CreateObject();
    cJSON_AddStringToObject(x, "id", bd->id);
    cJSON_AddStringToObject(x, "type", bd->type);
    cJSON_AddNumberToObject(x, "wmin", bd->lo);
    cJSON_AddNumberToObject(x, "wmax", bd->hi);
    cJSON_AddNumberToObject(x, "integral", bd->integral);
    cJSON *nodes = cJSON_AddArrayToObject(x, "nodes");
    for (size_t i = 0; i < bd->n_nodes; i++) {
      cJSON *nd = cJSON_CreateObject();
      cJSON_AddNumberToObject(nd, "node", (double)bd->slot[i]);
      cJSON_AddNumberToObject(nd, "wavelength", bd->wl[i]);
      cJSON_AddNumberToObject(nd, "weight", bd->w[i]);
      svc_json_push(nodes, nd);
    }
    svc_json_push(a, x);
  }
  /* One band film per (context, sensor, band): its address. */
  cJSON *r = cJSON_AddArrayToObject(o, "band_results");
  for (size_t i = 0; i < j->n_items; i++) {
    const render_item *it = &j->items[i];
    if (it->node != 1) continue; /* one (context, sensor) per first node */
    for (size_t b = 0; b < p->n; b++) {
      cJSON *x = cJSON_CreateObject();
      char href[512];
      snprintf(href, sizeof href, "/v1/jobs/%s/results/%s/%s?band=%s", j->id, it->context, it->sensor,
               p->b[b].id);
      cJSON_AddStringToObject(x, "context", it->context);
      cJSON_AddStringToObject(x, "sensor", it->sensor);
      cJSON_AddStringToObject(x, "band", p->b[b].id);
      cJSON_AddStringToObject(x, "href", href);
      svc_json_push(r, x);
    }
  }
}

/* A copy of item k's film (svc->lock held on entry, released on return):
 * from memory, or from the state directory. */
static rsw_status item_film_unlock(service *svc, job *j, size_t k, svc_film *out, svc_error *e) {
  const render_item *it = &j->items[k];
  if (!it->has_film && it->on_disk) {
    svc_film_ref ref;
    svc_film_ref_set(&ref, j, k);
    pthread_mutex_unlock(&svc->lock);
    return svc_state_film_read(svc, &ref, out, e);
  }
  if (!it->has_film) {
    rsw_status st = svc_fail(
        e, RSW_ERR_NOT_FOUND, it->context, "context '%s' sensor '%s' has no film at %g nm (%s)%s%s",
        it->context, it->sensor, it->wavelength, it->state == JOB_FAILED ? "failed" : "not rendered yet",
        it->error[0] ? ": " : "", it->error);
    pthread_mutex_unlock(&svc->lock);
    return st;
  }
  *out = it->film;
  film_image_share(&it->film.img, &out->img);
  pthread_mutex_unlock(&svc->lock);
  return RSW_OK;
}

rsw_status service_job_band_result(service *svc, const char *id, const char *context, const char *sensor_id,
                                   const char *band_id, const char *node_q, svc_film *out, svc_error *e) {
  if ((band_id != NULL) == (node_q != NULL))
    return svc_fail(e, RSW_ERR_INVALID, "band", "ask for one of ?band=ID and ?node=K");
  pthread_mutex_lock(&svc->lock);
  job *j = svc_find_job_locked(svc, id);
  if (!j) {
    pthread_mutex_unlock(&svc->lock);
    return svc_fail(e, RSW_ERR_NOT_FOUND, id, "no job '%s' (unknown, deleted or expired)", id);
  }
  if (!j->bands) {
    pthread_mutex_unlock(&svc->lock);
    return svc_fail(e, RSW_ERR_INVALID, band_id ? "band" : "node", "job %s has no bands", id);
  }
  const band_plan *p = j->bands;
  /* The items of (context, sensor), one per node slot. */
  size_t first = SIZE_MAX;
  for (size_t i = 0; i < j->n_items && first == SIZE_MAX; i++)
    if (strcmp(j->items[i].context, context) == 0 && strcmp(j->items[i].sensor, sensor_id) == 0) first = i;
  if (first == SIZE_MAX) {
    pthread_mutex_unlock(&svc->lock);
    return svc_fail(e, RSW_ERR_NOT_FOUND, context, "job %s has no result for context '%s' and sensor '%s'",
                    id, context, sensor_id);
  }
  /* Items are context-major, then node, then sensor: slot s of this
   * (context, sensor) is `stride` items after slot 0. */
  size_t stride = 1;
  while (first + stride < j->n_items && j->items[first + stride].node == j->items[first].node &&
         j->items[first + stride].context_index == j->items[first].context_index)
    stride++;
  if (node_q) {
    char *end;
    unsigned long long k = strtoull(node_q, &end, 10);
    if (!*node_q || *end || k >= p->n_wl) {
      pthread_mutex_unlock(&svc->lock);
      return svc_fail(e, RSW_ERR_NOT_FOUND, "node", "no node '%s': the job's nodes are 0 to %zu", node_q,
                      p->n_wl - 1);
    }
    return item_film_unlock(svc, j, first + (size_t)k * stride, out, e);
  }
  size_t b = bands_find(p, band_id);
  if (b == SIZE_MAX) {
    pthread_mutex_unlock(&svc->lock);
    return svc_fail(e, RSW_ERR_NOT_FOUND, "band", "no band '%s' in job %s", band_id, id);
  }
  const band bd = p->b[b];
  char jid[40];
  snprintf(jid, sizeof jid, "%s", j->id);
  pthread_mutex_unlock(&svc->lock);
  svc_film nodes[BAND_MAX_NODES];
  const film_image *imgs[BAND_MAX_NODES];
  memset(nodes, 0, sizeof nodes);
  rsw_status st = RSW_OK;
  size_t got = 0;
  for (; got < bd.n_nodes && !st; got++) {
    /* Looked up again each time: the job may have been deleted. */
    pthread_mutex_lock(&svc->lock);
    job *jj = svc_find_job_locked(svc, jid);
    if (!jj) {
      pthread_mutex_unlock(&svc->lock);
      st = svc_fail(e, RSW_ERR_NOT_FOUND, jid, "no job '%s' (deleted meanwhile)", jid);
      break;
    }
    st = item_film_unlock(svc, jj, first + bd.slot[got] * stride, &nodes[got], e);
    imgs[got] = &nodes[got].img;
  }
  if (!st) {
    *out = nodes[0];
    memset(&out->img, 0, sizeof out->img);
    rsw_err err = {0};
    st = bands_combine(&bd, imgs, &out->img, &err);
    if (st) svc_fail(e, err.code, "band", "%s", err.msg);
  }
  for (size_t i = 0; i < got; i++) svc_film_free(&nodes[i]);
  return st;
}
