/* `diffuse`: the Lambertian BRDF, one-sided (black from the back).
 *
 *   f_r(wi, wo) = rho / pi for cos(theta_i) > 0 and cos(theta_o) > 0,
 *   eval = f_r cos(theta_o);
 *   sample: wo ~ cos(theta_o) / pi (cosine hemisphere), weight = rho.
 *
 * Source: mitsuba3 src/bsdfs/diffuse.cpp; docs/kernel-conventions.md#diffuse-and-twosided
 * (reflectance default 0.5). */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "../simd/simd.h"
#include "bsdfs_internal.h"

static color diffuse_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const diffuse_bsdf *d = (const diffuse_bsdf *)b;
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return col1(0.0);
  return col_scale(tex_eval(d->reflectance, si), RSW_INV_PI * wo.z);
}

static double diffuse_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return 0.0;
  return warp_square_to_cosine_hemisphere_pdf(wo);
}

/* Sampling (bsdf_ops.sample_batch): the cosine-hemisphere warp of up to
 * 64 lanes at a time in double lanes (simd/warp_lanes.h), bitwise the
 * scalar warp; pdf, checks and reflectance per lane. */
static void diffuse_sample_batch(const bsdf *b, int n, const surface_interaction *const *si, const double *u1,
                                 const vec2 *u2, bsdf_sample *bs, color *weight) {
  (void)u1;
  const diffuse_bsdf *d = (const diffuse_bsdf *)b;
  enum {
    C = 64
  };
  rsw_isa isa = rsw_isa_get();
  for (int i0 = 0; i0 < n; i0 += C) {
    int m = n - i0 < C ? n - i0 : C;
    double u[2 * C], out[3 * C];
    int lane[C], k = 0;
    for (int j = 0; j < m; j++) {
      if (!(si[i0 + j]->wi.z > 0.0)) {
        weight[i0 + j] = bsdf_fail(&bs[i0 + j]);
        continue;
      }
      u[2 * k] = u2[i0 + j].x, u[2 * k + 1] = u2[i0 + j].y;
      lane[k++] = i0 + j;
    }
    cosine_hemisphere_batch(isa, k, u, out);
    for (int j = 0; j < k; j++) {
      int i = lane[j];
      bsdf_sample *s = &bs[i];
      s->wo = v3(out[3 * j], out[3 * j + 1], out[3 * j + 2]);
      s->pdf = warp_square_to_cosine_hemisphere_pdf(s->wo);
      s->eta = 1.0;
      s->sampled_type = BSDF_DIFFUSE_REFLECTION;
      weight[i] = !(s->pdf > 0.0) || !(s->wo.z > 0.0) ? bsdf_fail(s) : tex_eval(d->reflectance, si[i]);
    }
  }
}

/* The scalar op is the batch of one: the lanes give
 * warp_square_to_cosine_hemisphere()'s bits (tests/unit/test_simd.c). */
static color diffuse_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2,
                            bsdf_sample *bs) {
  color w;
  diffuse_sample_batch(b, 1, &si, &u1, &u2, bs, &w);
  return w;
}

static const bsdf_ops diffuse_ops = {
    .sample = diffuse_sample, .eval = diffuse_eval, .pdf = diffuse_pdf, .sample_batch = diffuse_sample_batch};

static rsw_status diffuse_create(loader *ld, node *n, object **out) {
  texture *refl;
  rsw_status st = ld_texture(ld, n, "reflectance", 0.5, 0.0, &refl);
  if (st != RSW_OK) return st;
  return plugin_created(ld, n, (object *)diffuse_new(refl), out);
}

static void diffuse_traverse(object *o, param_visitor *v) {
  pv_object(v, "reflectance", &((diffuse_bsdf *)o)->reflectance->base, 0.0, INFINITY);
}

DEFINE_PLUGIN(diffuse, CLS_BSDF, .ops = &diffuse_ops, .traverse = diffuse_traverse);

bsdf *diffuse_new(texture *reflectance) {
  diffuse_bsdf *d = BSDF_NEW(diffuse_bsdf, diffuse, BSDF_DIFFUSE_REFLECTION);
  if (d) d->reflectance = reflectance;
  return (bsdf *)d;
}
