/* `lanczos` reconstruction filter (mitsuba3 src/rfilters/lanczos.cpp): the
 * windowed sinc with a = `lobes` (integer, default 3), radius a pixels:
 *   eval(x) = sin(pi x) sin(pi x / a) / ((pi x)(pi x / a))  for |x| <= a,
 *   1 below |x| < 1e-7 (its limit), 0 beyond a.
 * Negative lobes: a film pixel is sum(f w L) / sum(f) (films/hdrfilm.c),
 * so edges ring, as in Mitsuba. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"

static double lanczos_eval(const rfilter *f, double x) {
  x = fabs(x);
  double a = f->radius;
  if (x < 0x1p-24) return 1.0;
  if (x > a) return 0.0;
  double x1 = RSW_PI * x, x2 = x1 / a;
  return sin(x1) * sin(x2) / (x1 * x2);
}

DEFINE_PLUGIN(lanczos, CLS_RFILTER);

static rsw_status lanczos_create(loader *ld, node *n, object **out) {
  long long lobes;
  rsw_status st = ld_int(ld, n, "lobes", 3, 1, 64, &lobes);
  if (st) return st;
  rfilter *f = PLUGIN_NEW(rfilter, lanczos);
  if (!f) return plugin_created(ld, n, NULL, out);
  f->radius = (double)lobes;
  f->eval = lanczos_eval;
  return plugin_created(ld, n, &f->base, out);
}
