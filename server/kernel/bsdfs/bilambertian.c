/* `bilambertian`: a two-sided diffuse reflector and transmitter (Eradiate's
 * leaf model).
 *
 *   eval = R / pi |cos(theta_o)|   if wi and wo lie on the same side,
 *          T / pi |cos(theta_o)|   if on opposite sides.
 * Sampling picks reflection with p_R = mean over channels of R / (R + T)
 * (0 when that is NaN, i.e. R + T = 0), else transmission; the direction
 * is cosine-distributed on the side of wi (reflection) or on the other
 * side (transmission):
 *   pdf = |cos(theta_o)| / pi * (p_R or 1 - p_R),
 *   weight = R / p_R or T / (1 - p_R).
 *
 * Source: eradiate/mitsuba3 src/eradiate_plugins/bsdfs/bilambertian.cpp;
 * kernel-behavior.md §4.2. */
#include <math.h>
#include <stdlib.h>

#include "../scene/loader.h"
#include "../scene/params.h"
#include "../textures/texture.h"
#include "bsdfs_internal.h"

static double prob_reflect(color r, color t) {
  double p = 0.0;
  for (int i = 0; i < 3; i++) p += r.c[i] / (r.c[i] + t.c[i]);
  p /= 3.0;
  return isnan(p) ? 0.0 : p;
}

static color bil_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  const bilambertian_bsdf *d = (const bilambertian_bsdf *)b;
  double ci = si->wi.z;
  if (ci == 0.0 || !isfinite(ci)) return bsdf_fail(bs);
  color r = tex_eval(d->reflectance, si), t = tex_eval(d->transmittance, si);
  double p_r = prob_reflect(r, t);
  bool reflect = u1 < p_r;
  vec3 wo = warp_square_to_cosine_hemisphere(u2);
  if (!(wo.z > 0.0)) return bsdf_fail(bs);
  /* Reflection stays on wi's side, transmission crosses. */
  bool flip = (ci < 0.0) == reflect;
  if (flip) wo.z = -wo.z;
  double p_lobe = reflect ? p_r : 1.0 - p_r;
  bs->wo = wo;
  bs->pdf = warp_square_to_cosine_hemisphere_pdf(v3(wo.x, wo.y, fabs(wo.z))) * p_lobe;
  bs->eta = 1.0;
  bs->sampled_type = reflect ? BSDF_DIFFUSE_REFLECTION : BSDF_DIFFUSE_TRANSMISSION;
  if (!(bs->pdf > 0.0)) return bsdf_fail(bs);
  return col_scale(reflect ? r : t, 1.0 / p_lobe);
}

static color bil_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const bilambertian_bsdf *d = (const bilambertian_bsdf *)b;
  double ci = si->wi.z, co = wo.z;
  if (ci == 0.0 || co == 0.0) return col1(0.0);
  texture *lobe = (ci > 0.0) == (co > 0.0) ? d->reflectance : d->transmittance;
  return col_scale(tex_eval(lobe, si), RSW_INV_PI * fabs(co));
}

static double bil_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const bilambertian_bsdf *d = (const bilambertian_bsdf *)b;
  double ci = si->wi.z, co = wo.z;
  if (ci == 0.0 || co == 0.0) return 0.0;
  double p_r = prob_reflect(tex_eval(d->reflectance, si), tex_eval(d->transmittance, si));
  double p_lobe = (ci > 0.0) == (co > 0.0) ? p_r : 1.0 - p_r;
  return RSW_INV_PI * fabs(co) * p_lobe;
}

static const bsdf_ops bil_ops = {.sample = bil_sample, .eval = bil_eval, .pdf = bil_pdf};

static void bil_destroy(object *o) {
  free(o);
}

/* R, T >= 0; for constants also R + T <= 1 per channel (energy). */
static rsw_status bil_create(loader *ld, node *n, object **out) {
  texture *r, *t;
  rsw_status st;
  if ((st = ld_texture(ld, n, "reflectance", 0.5, 0.0, &r)) != RSW_OK) return st;
  if ((st = ld_texture(ld, n, "transmittance", 0.5, 0.0, &t)) != RSW_OK) return st;
  color rc, tc;
  if (uniform_texture_value(r, &rc) && uniform_texture_value(t, &tc))
    for (int i = 0; i < 3; i++)
      if (rc.c[i] + tc.c[i] > 1.0 + 1e-12)
        return ld_fail(ld, n, "transmittance", RSW_ERR_INVALID,
                       "reflectance + transmittance = %g exceeds 1 (energy)", rc.c[i] + tc.c[i]);
  bsdf *b = bilambertian_new(r, t);
  if (!b) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "bilambertian: out of memory");
  b->base.id = n->id;
  *out = &b->base;
  return RSW_OK;
}

static void bil_traverse(object *o, param_visitor *v) {
  bilambertian_bsdf *d = (bilambertian_bsdf *)o;
  pv_object(v, "reflectance", &d->reflectance->base, 0.0, 1.0);
  pv_object(v, "transmittance", &d->transmittance->base, 0.0, 1.0);
}

const plugin plugin_bilambertian = {
    .name = "bilambertian",
    .cls = CLS_BSDF,
    .create = bil_create,
    .destroy = bil_destroy,
    .ops = &bil_ops,
    .traverse = bil_traverse,
};

bsdf *bilambertian_new(texture *reflectance, texture *transmittance) {
  bilambertian_bsdf *d = calloc(1, sizeof *d);
  if (!d) return NULL;
  d->base.base.plugin = &plugin_bilambertian;
  d->base.ops = &bil_ops;
  d->base.flags = BSDF_DIFFUSE_REFLECTION | BSDF_DIFFUSE_TRANSMISSION;
  d->reflectance = reflectance;
  d->transmittance = transmittance;
  return &d->base;
}
