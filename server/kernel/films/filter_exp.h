/* exp(x) for the reconstruction filters' weights, in batches that
 * vectorise (films/filter_exp.c says how and how exactly), and the
 * gaussian filter's weights of a sample's footprint with it.
 * Both thread-safe (no state). */
#ifndef RSW_FILMS_FILTER_EXP_H
#define RSW_FILMS_FILTER_EXP_H

#include "../core/isa.h"

/* out[i] = exp(x[i]) for i in [0, n), on the ISA isa (core/isa.h; every
 * ISA gives the same bits). x and out must not overlap. */
void filter_exp_batch(rsw_isa isa, int n, const double *restrict x, double *restrict out);

/* A sample at (px, py) pixels and the pixels its filter reaches: columns
 * xlo .. xlo + nx - 1, rows ylo .. ylo + ny - 1; the gaussian's
 * alpha = -1 / (2 sigma^2) and bias (films/rfilters.c). */
typedef struct filter_footprint {
  double px, py;
  int xlo, nx, ylo, ny;
  double alpha, bias;
} filter_footprint;

/* out[i] = max(0, exp(alpha t^2) - bias) for t = px - ((xlo + i) + 0.5),
 * i < nx, then t = py - ((ylo + j) + 0.5) at out[nx + j], j < ny: the
 * gaussian's column and row weights, with filter_exp_batch's exp (so the
 * same bits at every ISA). */
void filter_gaussian_footprint(rsw_isa isa, const filter_footprint *fp, double *restrict out);

#endif
