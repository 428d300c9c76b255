/* Reconstruction filters: `box` and `gaussian` (mitsuba3
 * src/rfilters/box.cpp, src/rfilters/gaussian.cpp). 1-D, separable:
 * the 2-D weight of a sample at offset (x, y) pixels is eval(x) eval(y). */
#include <math.h>
#include <stdlib.h>

#include "../scene/loader.h"

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

static double gaussian_eval(const rfilter *f, double x) {
  const gaussian_filter *g = (const gaussian_filter *)f;
  double v = exp(g->alpha * x * x) - g->bias;
  return v > 0.0 ? v : 0.0;
}

static void rfilter_destroy(object *o) {
  free(o);
}

static rsw_status box_create(loader *ld, node *n, object **out);
static rsw_status gaussian_create(loader *ld, node *n, object **out);

const plugin plugin_box = {
    .name = "box",
    .cls = CLS_RFILTER,
    .create = box_create,
    .destroy = rfilter_destroy,
};

const plugin plugin_gaussian = {
    .name = "gaussian",
    .cls = CLS_RFILTER,
    .create = gaussian_create,
    .destroy = rfilter_destroy,
};

static rsw_status box_create(loader *ld, node *n, object **out) {
  rfilter *f = calloc(1, sizeof *f);
  if (!f) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  f->base.plugin = &plugin_box;
  f->base.id = n->id;
  f->radius = 0.5;
  f->eval = box_eval;
  *out = &f->base;
  return RSW_OK;
}

static rsw_status gaussian_create(loader *ld, node *n, object **out) {
  double sigma = 0.5;
  /* An upper bound keeps the splat footprint (radius 4 sigma) bounded. */
  rsw_status st = ld_float_range(ld, n, "stddev", 0.5, 1e-6, 64.0, &sigma);
  if (st != RSW_OK) return st;
  gaussian_filter *g = calloc(1, sizeof *g);
  if (!g) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  g->base.base.plugin = &plugin_gaussian;
  g->base.base.id = n->id;
  g->stddev = sigma;
  g->base.radius = 4.0 * sigma;
  g->alpha = -1.0 / (2.0 * sigma * sigma);
  g->bias = exp(g->alpha * g->base.radius * g->base.radius);
  g->base.eval = gaussian_eval;
  *out = &g->base.base;
  return RSW_OK;
}
