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
 * docs/kernel-conventions.md#bilambertian. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "../simd/simd.h"
#include "../textures/texture.h"
#include "bsdfs_internal.h"

static double prob_reflect(color r, color t) {
  double p = 0.0;
  for (int i = 0; i < 3; i++) p += r.c[i] / (r.c[i] + t.c[i]);
  p /= 3.0;
  return isnan(p) ? 0.0 : p;
}

/* The sample from wo = cosine_hemisphere(u2) on: shared by the scalar and
 * the batched op (which warps its lanes together), so both give the same
 * bits. */
static color bil_finish(const bilambertian_bsdf *d, const surface_interaction *si, double u1, vec3 wo,
                        bsdf_sample *bs) {
  double ci = si->wi.z;
  color r = tex_eval(d->reflectance, si), t = tex_eval(d->transmittance, si);
  double p_r = prob_reflect(r, t);
  bool reflect = u1 < p_r;
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

static bool bil_valid(const surface_interaction *si) {
  double ci = si->wi.z;
  return !(ci == 0.0 || !isfinite(ci));
}

/* One body with the batched op (bil_finish); only the warp differs, and
 * its lanes give the scalar warp's bits (tests/unit/test_simd.c). Kept
 * scalar rather than a batch of one: volpath and twosided call it per lane
 * (canopies), where a one-lane vector warp costs more than the scalar. */
static color bil_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  if (!bil_valid(si)) return bsdf_fail(bs);
  return bil_finish((const bilambertian_bsdf *)b, si, u1, warp_square_to_cosine_hemisphere(u2), bs);
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

/* Batched sampling (bsdf_ops.sample_batch): the cosine-hemisphere warp of
 * up to 64 lanes in double lanes (simd/warp_lanes.h, bitwise the scalar
 * warp), the rest per lane (bil_finish): bit for bit bil_sample(). */
static void bil_sample_batch(const bsdf *b, int n, const surface_interaction *const *si, const double *u1,
                             const vec2 *u2, bsdf_sample *bs, color *weight) {
  const bilambertian_bsdf *d = (const bilambertian_bsdf *)b;
  enum {
    C = 64
  };
  rsw_isa isa = rsw_isa_get();
  for (int i0 = 0; i0 < n; i0 += C) {
    int m = n - i0 < C ? n - i0 : C;
    double u[2 * C], out[3 * C];
    int lane[C], k = 0;
    for (int j = 0; j < m; j++) {
      if (!bil_valid(si[i0 + j])) {
        weight[i0 + j] = bsdf_fail(&bs[i0 + j]);
        continue;
      }
      u[2 * k] = u2[i0 + j].x, u[2 * k + 1] = u2[i0 + j].y;
      lane[k++] = i0 + j;
    }
    cosine_hemisphere_batch(isa, k, u, out);
    for (int j = 0; j < k; j++) {
      int i = lane[j];
      weight[i] = bil_finish(d, si[i], u1[i], v3(out[3 * j], out[3 * j + 1], out[3 * j + 2]), &bs[i]);
    }
  }
}

/* Batched eval and pdf: bil_eval() and bil_pdf() per lane with the two
 * textures evaluated once (no vector kernel: nothing but the textures and
 * a few products), bit for bit the scalar values. */
static void bil_eval_pdf_batch(const bsdf *b, int n, const surface_interaction *const *si, const vec3 *wo,
                               color *f, double *pdf) {
  const bilambertian_bsdf *d = (const bilambertian_bsdf *)b;
  for (int i = 0; i < n; i++) {
    double ci = si[i]->wi.z, co = wo[i].z;
    f[i] = col1(0.0);
    pdf[i] = 0.0;
    if (ci == 0.0 || co == 0.0) continue;
    color r = tex_eval(d->reflectance, si[i]), t = tex_eval(d->transmittance, si[i]);
    bool same = (ci > 0.0) == (co > 0.0);
    f[i] = col_scale(same ? r : t, RSW_INV_PI * fabs(co));
    double p_r = prob_reflect(r, t);
    pdf[i] = RSW_INV_PI * fabs(co) * (same ? p_r : 1.0 - p_r);
  }
}

static const bsdf_ops bil_ops = {.sample = bil_sample,
                                 .eval = bil_eval,
                                 .pdf = bil_pdf,
                                 .sample_batch = bil_sample_batch,
                                 .eval_pdf_batch = bil_eval_pdf_batch};

/* R, T >= 0; for constants also R + T <= 1 per channel (energy). */
static rsw_status bilambertian_create(loader *ld, node *n, object **out) {
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
  return plugin_created(ld, n, (object *)bilambertian_new(r, t), out);
}

static void bil_traverse(object *o, param_visitor *v) {
  bilambertian_bsdf *d = (bilambertian_bsdf *)o;
  pv_object(v, "reflectance", &d->reflectance->base, 0.0, 1.0);
  pv_object(v, "transmittance", &d->transmittance->base, 0.0, 1.0);
}

DEFINE_PLUGIN(bilambertian, CLS_BSDF, .ops = &bil_ops, .traverse = bil_traverse);

bsdf *bilambertian_new(texture *reflectance, texture *transmittance) {
  bilambertian_bsdf *d =
      BSDF_NEW(bilambertian_bsdf, bilambertian, BSDF_DIFFUSE_REFLECTION | BSDF_DIFFUSE_TRANSMISSION);
  if (!d) return NULL;
  d->reflectance = reflectance;
  d->transmittance = transmittance;
  return &d->base;
}
