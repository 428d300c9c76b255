/* `stokes`: Mitsuba 3's wrapper that makes its nested integrator write the
 * Stokes vector (mitsuba3 src/integrators/stokes.cpp), as Mitsuba and
 * Eradiate scenes for the polarized variants write it:
 *
 *   <integrator type="stokes"> <integrator type="volpath"/> </integrator>
 *
 * Here every film of a polarized variant is a Stokes film already
 * (docs/polarization.md#films), so the wrapper renders with its nested
 * integrator as it is. In an unpolarized variant it is refused: there is no
 * Stokes vector to write (Mitsuba would write S0 alone). */
#include <stdlib.h>

#include "../scene/loader.h"
#include "../scene/plugin_def.h"
#include "integrator.h"

typedef struct stokes_integrator {
  integrator base;
  const integrator *inner;
} stokes_integrator;

static color stokes_Li(const integrator *it, const scene *sc, sampler_state *st, ray3 ray,
                       render_stats *stats, double *quv) {
  const integrator *in = ((const stokes_integrator *)it)->inner;
  return in->ops->Li(in, sc, st, ray, stats, quv);
}

static bool stokes_Li_batch(const integrator *it, const scene *sc, sampler_state *st, const ray3 *rays, int n,
                            render_stats *stats, color *L, double *quv) {
  const integrator *in = ((const stokes_integrator *)it)->inner;
  if (in->ops->Li_batch) return in->ops->Li_batch(in, sc, st, rays, n, stats, L, quv);
  int qs = scene_quv_stride(sc);
  for (int i = 0; i < n; i++) {
    double *q = quv ? &quv[qs * i] : NULL;
    for (int k = 0; q && k < qs; k++) q[k] = 0;
    L[i] = in->ops->Li(in, sc, &st[i], rays[i], stats, q);
  }
  return true;
}

static const integrator_ops stokes_ops = {.Li = stokes_Li, .Li_batch = stokes_Li_batch};

DEFINE_PLUGIN(stokes, CLS_INTEGRATOR, .ops = &stokes_ops);

static rsw_status stokes_create(loader *ld, node *n, object **out) {
  if (!ld->polarized)
    return ld_fail(ld, n, NULL, RSW_ERR_UNSUPPORTED,
                   "integrator 'stokes' needs a polarized variant (mono_polarized or rgb_polarized): "
                   "this scene's films have no Stokes vector");
  object **kids = NULL;
  size_t count = 0;
  rsw_status st = ld_children(ld, n, CLS_INTEGRATOR, &kids, &count);
  if (st != RSW_OK) return st;
  const integrator *inner = count == 1 ? (const integrator *)kids[0] : NULL;
  free(kids);
  if (!inner)
    return ld_fail(ld, n, NULL, count ? RSW_ERR_INVALID : RSW_ERR_MISSING,
                   "integrator 'stokes' takes one nested integrator, got %zu", count);
  stokes_integrator *s = PLUGIN_NEW(stokes_integrator, stokes);
  if (!s) return plugin_created(ld, n, NULL, out);
  s->base.ops = &stokes_ops;
  s->base.max_depth = inner->max_depth;
  s->base.rr_depth = inner->rr_depth;
  s->base.hide_emitters = inner->hide_emitters;
  s->inner = inner;
  return plugin_created(ld, n, &s->base.base, out);
}
