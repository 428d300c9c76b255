/* `lanczos` reconstruction filter (mitsuba3 src/rfilters/lanczos.cpp): the
 * windowed sinc with a = `lobes` (integer, default 3), radius a pixels:
 *   eval(x) = sin(pi x) sin(pi x / a) / ((pi x)(pi x / a))  for |x| <= a,
 *   1 below |x| < 1e-7 (its limit), 0 beyond a.
 * Negative lobes: a film pixel is sum(f w L) / sum(f) (films/hdrfilm.c),
 * so edges ring, as in Mitsuba. */
#include <math.h>
#include <stdlib.h>

#include "../scene/loader.h"

static double lanczos_eval(const rfilter *f, double x) {
  x = fabs(x);
  double a = f->radius;
  if (x < 0x1p-24) return 1.0;
  if (x > a) return 0.0;
  double x1 = RSW_PI * x, x2 = x1 / a;
  return sin(x1) * sin(x2) / (x1 * x2);
}

static void lanczos_destroy(object *o) {
  free(o);
}

extern const plugin plugin_lanczos;

static rsw_status lanczos_create(loader *ld, node *n, object **out) {
  long long lobes;
  rsw_status st = ld_int(ld, n, "lobes", 3, 1, 64, &lobes);
  if (st) return st;
  rfilter *f = calloc(1, sizeof *f);
  if (!f) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  f->base.plugin = &plugin_lanczos;
  f->base.id = n->id;
  f->radius = (double)lobes;
  f->eval = lanczos_eval;
  *out = &f->base;
  return RSW_OK;
}

const plugin plugin_lanczos = {
    .name = "lanczos", .cls = CLS_RFILTER, .create = lanczos_create, .destroy = lanczos_destroy};
