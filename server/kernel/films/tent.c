/* `tent` reconstruction filter (mitsuba3 src/rfilters/tent.cpp):
 *   eval(x) = max(0, 1 - |x| / r),  radius r (`radius`, default 1 pixel).
 * 1-D and separable, like every rfilter (kernel.h); its integral is r. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"

typedef struct tent_filter {
  rfilter base;
  double inv_radius;
} tent_filter;

static double tent_eval(const rfilter *f, double x) {
  double v = 1.0 - fabs(x) * ((const tent_filter *)f)->inv_radius;
  return v > 0.0 ? v : 0.0;
}

DEFINE_PLUGIN(tent, CLS_RFILTER);

static rsw_status tent_create(loader *ld, node *n, object **out) {
  double r;
  /* The same bound as gaussian's footprint (films/rfilters.c). */
  rsw_status st = ld_float_range(ld, n, "radius", 1.0, 1e-3, 256.0, &r);
  if (st) return st;
  tent_filter *t = PLUGIN_NEW(tent_filter, tent);
  if (!t) return plugin_created(ld, n, NULL, out);
  t->base.radius = r;
  t->base.eval = tent_eval;
  t->inv_radius = 1.0 / r;
  return plugin_created(ld, n, &t->base.base, out);
}
