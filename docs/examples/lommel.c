/* `lommel`: the Lommel-Seeliger law, single scattering in a half-space of
 * isotropic scatterers of albedo w (Hapke 2012, "Theory of Reflectance
 * and Emittance Spectroscopy", 2nd ed.: the single-scattering term of the
 * bidirectional reflectance with an isotropic phase function), one-sided:
 *
 *   f_r(wi, wo) = w / (4 pi) / (cos theta_i + cos theta_o),
 *   eval = f_r cos theta_o; sample: cosine hemisphere, pdf cos / pi.
 *
 * The worked example of docs/adding-a-plugin.md (a test registers it:
 * tests/kernel/scene/test_plugin_example.c). */
#include "kernel/bsdfs/bsdfs_internal.h"
#include "kernel/scene/plugin_def.h"

typedef struct lommel_bsdf {
  bsdf base; /* first: the object header, the ops table and the lobes */
  texture *albedo;
} lommel_bsdf;

static color lommel_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const lommel_bsdf *l = (const lommel_bsdf *)b;
  double ci = si->wi.z, co = wo.z;
  if (!(ci > 0.0) || !(co > 0.0)) return col1(0.0);
  return col_scale(tex_eval(l->albedo, si), RSW_INV_4PI / (ci + co) * co);
}

static double lommel_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return 0.0;
  return warp_square_to_cosine_hemisphere_pdf(wo);
}

static color lommel_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2,
                           bsdf_sample *bs) {
  (void)u1; /* one lobe: nothing to pick */
  if (!(si->wi.z > 0.0)) return bsdf_fail(bs);
  bs->wo = warp_square_to_cosine_hemisphere(u2);
  bs->pdf = lommel_pdf(b, si, bs->wo);
  bs->eta = 1.0;
  bs->sampled_type = BSDF_GLOSSY_REFLECTION;
  if (!(bs->pdf > 0.0)) return bsdf_fail(bs);
  return col_scale(lommel_eval(b, si, bs->wo), 1.0 / bs->pdf); /* eval / pdf */
}

static const bsdf_ops lommel_ops = {.sample = lommel_sample, .eval = lommel_eval, .pdf = lommel_pdf};

/* The parameters a PATCH may change (docs/parameters.md): `albedo`. */
static void lommel_traverse(object *o, param_visitor *v) {
  pv_object(v, "albedo", &((lommel_bsdf *)o)->albedo->base, 0.0, 1.0);
}

DEFINE_PLUGIN(lommel, CLS_BSDF, .ops = &lommel_ops, .traverse = lommel_traverse);

/* `albedo` (0.5, a texture in [0, 1]). */
static rsw_status lommel_create(loader *ld, node *n, object **out) {
  texture *albedo;
  rsw_status st = ld_texture(ld, n, "albedo", 0.5, 0.0, &albedo);
  if (st == RSW_OK) st = bsdf_check_const_range(ld, n, "albedo", albedo, 0.0, false, 1.0, false);
  if (st != RSW_OK) return st;
  lommel_bsdf *l = BSDF_NEW(lommel_bsdf, lommel, BSDF_GLOSSY_REFLECTION);
  if (l) l->albedo = albedo;
  return plugin_created(ld, n, (object *)l, out);
}
