/* 2-D piecewise-constant distribution (see distr2d.h). */
#include "distr2d.h"

#include <math.h>
#include <stdlib.h>

void distr2d_free(distr2d *d) {
  if (!d) return;
  free(d->col_cdf);
  free(d->row_cdf);
  free(d->weight);
  *d = (distr2d){0};
}

rsw_status distr2d_init(distr2d *d, const double *weights, int w, int h, const char *where, rsw_err *err) {
  if (w < 1 || h < 1)
    return rsw_fail(err, RSW_ERR_INVALID, where, "distribution needs at least 1x1 cells (got %dx%d)", w, h);
  size_t n = (size_t)w * (size_t)h;
  for (size_t k = 0; k < n; k++)
    if (!(weights[k] >= 0) || !isfinite(weights[k]))
      return rsw_fail(err, RSW_ERR_INVALID, where,
                      "weight %zu (column %zu, row %zu) is negative or not finite", k, k % (size_t)w,
                      k / (size_t)w);
  distr2d t = {.w = w, .h = h};
  t.col_cdf = malloc(sizeof(double) * (size_t)h * ((size_t)w + 1));
  t.row_cdf = malloc(sizeof(double) * ((size_t)h + 1));
  t.weight = malloc(sizeof(double) * n);
  if (!t.col_cdf || !t.row_cdf || !t.weight) {
    distr2d_free(&t);
    return rsw_fail(err, RSW_ERR_NOMEM, where, "out of memory for a %dx%d distribution", w, h);
  }
  t.row_cdf[0] = 0;
  for (int j = 0; j < h; j++) {
    double *c = &t.col_cdf[(size_t)j * (w + 1)];
    c[0] = 0;
    for (int i = 0; i < w; i++) {
      double v = weights[(size_t)j * w + i];
      t.weight[(size_t)j * w + i] = v;
      c[i + 1] = c[i] + v;
    }
    double row = c[w];
    /* An empty row is never chosen by the marginal; give it a uniform cdf
     * so that its cdf is still well formed. */
    for (int i = 1; i <= w; i++) c[i] = row > 0 ? c[i] / row : (double)i / w;
    c[w] = 1.0;
    t.row_cdf[j + 1] = t.row_cdf[j] + row;
  }
  t.total = t.row_cdf[h];
  if (!(t.total > 0) || !isfinite(t.total)) {
    distr2d_free(&t);
    return rsw_fail(err, RSW_ERR_INVALID, where, "all %dx%d weights are zero (or their sum overflows)", w, h);
  }
  for (int j = 1; j <= h; j++) t.row_cdf[j] /= t.total;
  t.row_cdf[h] = 1.0;
  *d = t;
  return RSW_OK;
}

/* Largest k in [0, n-1] with cdf[k] <= u (cdf has n+1 entries, cdf[0] = 0,
 * cdf[n] = 1); skips zero-width intervals since cdf[k+1] > u as well. */
static int find_interval(const double *cdf, int n, double u) {
  int lo = 0, hi = n - 1;
  while (lo < hi) {
    int mid = (lo + hi + 1) / 2;
    if (cdf[mid] <= u)
      lo = mid;
    else
      hi = mid - 1;
  }
  return lo;
}

/* Position within [cdf[k], cdf[k+1]) rescaled to [0,1), clamped below 1
 * so the continuous coordinate stays inside its cell. */
static double remap(const double *cdf, int k, double u) {
  double width = cdf[k + 1] - cdf[k];
  double f = width > 0 ? (u - cdf[k]) / width : 0.5;
  if (!(f >= 0)) f = 0;
  if (f >= 1) f = nextafter(1.0, 0.0);
  return f;
}

vec2 distr2d_sample(const distr2d *d, vec2 u, double *pdf) {
  /* Row j with probability row_j / total, then column i of that row with
   * probability w_ij / row_j; the product w_ij / total spread over a cell of
   * area 1/(W H) gives the density w_ij W H / total. */
  int j = find_interval(d->row_cdf, d->h, u.y);
  double fy = remap(d->row_cdf, j, u.y);
  const double *c = &d->col_cdf[(size_t)j * (d->w + 1)];
  int i = find_interval(c, d->w, u.x);
  double fx = remap(c, i, u.x);
  if (pdf) *pdf = d->weight[(size_t)j * d->w + i] * d->w * d->h / d->total;
  double x = (i + fx) / d->w, y = (j + fy) / d->h;
  /* (i + fx) / w may round up to (i+1)/w: keep the point in its cell. */
  if (x >= (double)(i + 1) / d->w) x = nextafter((double)(i + 1) / d->w, 0.0);
  if (y >= (double)(j + 1) / d->h) y = nextafter((double)(j + 1) / d->h, 0.0);
  return v2(x, y);
}

double distr2d_pdf(const distr2d *d, vec2 p) {
  if (!(p.x >= 0 && p.x < 1 && p.y >= 0 && p.y < 1)) return 0.0;
  int i = (int)(p.x * d->w), j = (int)(p.y * d->h);
  if (i >= d->w) i = d->w - 1;
  if (j >= d->h) j = d->h - 1;
  return d->weight[(size_t)j * d->w + i] * d->w * d->h / d->total;
}
