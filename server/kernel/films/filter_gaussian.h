/* The gaussian reconstruction filter's weights of a sample's whole
 * footprint in one call (rfilter.eval_footprint, films/rfilters.c), eight
 * lanes at a time with core/vexp_lanes.h's exp: the same bits at every
 * ISA. Thread-safe (no state). */
#ifndef RSW_FILMS_FILTER_GAUSSIAN_H
#define RSW_FILMS_FILTER_GAUSSIAN_H

#include "../core/isa.h"

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
 * gaussian's column and row weights, with core/vexp_lanes.h's exp (so the
 * same bits at every ISA). */
void filter_gaussian_footprint(rsw_isa isa, const filter_footprint *fp, double *restrict out);

#endif
