/* A 2-D piecewise-constant distribution on the unit square (pbrt-v4's
 * PiecewiseConstant2D; Mitsuba 3's DiscreteDistribution2D plays the same
 * role): a W x H grid of non-negative weights, cell (i, j) covering
 * [i/W, (i+1)/W) x [j/H, (j+1)/H), sampled by a marginal over rows and a
 * conditional over the columns of the chosen row.
 *
 * Density with respect to area on the unit square:
 *     pdf(x, y) = w[j][i] W H / sum(w),   i = floor(x W), j = floor(y H).
 * sample() is continuous: within the chosen cell the point is uniform, so
 * sample() and pdf() agree everywhere. No inverse is provided. */
#ifndef RSW_CORE_DISTR2D_H
#define RSW_CORE_DISTR2D_H

#include <stddef.h>

#include "rsw_error.h"
#include "warp.h"

typedef struct distr2d {
  int w, h;
  double *col_cdf; /* h rows of w+1 entries: per-row cdfs, each normalised */
  double *row_cdf; /* h+1 entries: marginal cdf over rows, normalised */
  double *weight;  /* w*h: the weights as given (row j at j*w) */
  double total;    /* sum of the weights */
} distr2d;

/* Build from weights[j * w + i] (row-major, row j is y in [j/h, (j+1)/h)),
 * copied. Fails (RSW_ERR_INVALID, naming `where`) on w or h < 1, a negative
 * or non-finite weight, or an all-zero grid; RSW_ERR_NOMEM when out of
 * memory. *d is written only on success; release with distr2d_free(). */
rsw_status distr2d_init(distr2d *d, const double *weights, int w, int h, const char *where, rsw_err *err);
/* Free the arrays and zero *d; a zeroed distr2d is a no-op. */
void distr2d_free(distr2d *d);

/* Map u in [0,1)^2 to a point in [0,1)^2 distributed as the weights;
 * *pdf (may be NULL) gets its density on the unit square. Thread-safe. */
vec2 distr2d_sample(const distr2d *d, vec2 u, double *pdf);
/* Density at p (0 outside [0,1)^2). Thread-safe. */
double distr2d_pdf(const distr2d *d, vec2 p);

#endif
