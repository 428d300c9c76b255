/* Reconstruction filters: `box` and `gaussian` (mitsuba3
 * src/rfilters/box.cpp, src/rfilters/gaussian.cpp). 1-D, separable:
 * the 2-D weight of a sample at offset (x, y) pixels is eval(x) eval(y). */
#include <math.h>
#include <stdlib.h>

#include "../core/vexp.h"
#include "../scene/plugin_def.h"
#include "filter_gaussian.h"

/* box: radius 0.5 (fixed, no parameters), weight 1 on [-0.5, 0.5). */
static double box_eval(const rfilter *f, double x) {
  (void)f;
  return (x >= -0.5 && x < 0.5) ? 1.0 : 0.0;
}

/* gaussian: stddev sigma (default 0.5), cut off at radius r = 4 sigma and
 * shifted down so it reaches 0 there:
 *   eval(x) = max(0, exp(-x^2 / (2 sigma^2)) - exp(-r^2 / (2 sigma^2))). */
typedef struct gaussian_filter {
  rfilter base;
  double stddev;
  double alpha; /* -1 / (2 sigma^2) */
  double bias;  /* exp(alpha r^2) */
} gaussian_filter;

/* exp through core/vexp.c (libm's bits where libm's exp is its FMA
 * variant; the same bits at every ISA); a sample's weights in one batch,
 * 8 lanes (4 columns, 4 rows at the default stddev). */
static double gaussian_eval(const rfilter *f, double x) {
  const gaussian_filter *g = (const gaussian_filter *)f;
  double a = g->alpha * x * x, e;
  vexp_batch(rsw_isa_get(), 1, &a, &e);
  double v = e - g->bias;
  return v > 0.0 ? v : 0.0;
}

static void gaussian_eval_footprint(const rfilter *f, double px, int xlo, int nx, double py, int ylo, int ny,
                                    double *out) {
  const gaussian_filter *g = (const gaussian_filter *)f;
  filter_footprint fp = {
      .px = px, .py = py, .xlo = xlo, .nx = nx, .ylo = ylo, .ny = ny, .alpha = g->alpha, .bias = g->bias};
  filter_gaussian_footprint(rsw_isa_get(), &fp, out);
}

DEFINE_PLUGIN(box, CLS_RFILTER);

DEFINE_PLUGIN(gaussian, CLS_RFILTER);

static rsw_status box_create(loader *ld, node *n, object **out) {
  rfilter *f = PLUGIN_NEW(rfilter, box);
  if (!f) return plugin_created(ld, n, NULL, out);
  f->radius = 0.5;
  f->eval = box_eval;
  return plugin_created(ld, n, &f->base, out);
}

static rsw_status gaussian_create(loader *ld, node *n, object **out) {
  double sigma = 0.5;
  /* An upper bound keeps the splat footprint (radius 4 sigma) bounded. */
  rsw_status st = ld_float_range(ld, n, "stddev", 0.5, 1e-6, 64.0, &sigma);
  if (st != RSW_OK) return st;
  gaussian_filter *g = PLUGIN_NEW(gaussian_filter, gaussian);
  if (!g) return plugin_created(ld, n, NULL, out);
  g->stddev = sigma;
  g->base.radius = 4.0 * sigma;
  g->alpha = -1.0 / (2.0 * sigma * sigma);
  g->bias = exp(g->alpha * g->base.radius * g->base.radius);
  g->base.eval = gaussian_eval;
  g->base.eval_footprint = gaussian_eval_footprint;
  return plugin_created(ld, n, &g->base.base, out);
}
