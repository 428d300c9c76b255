/* The coated diffuse base of `plastic` and `roughplastic`
 * (bsdfs/plastic_layer.h). */
#include "plastic_layer.h"

#include "../scene/loader.h"
#include "../scene/params.h"

double fresnel_diffuse_reflectance(double eta) {
  if (eta < 1.0) return -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 / eta;
  double x = 1.0 / eta;
  return 0.919317 + x * (-3.4793 + x * (6.75335 + x * (-7.80989 + x * (4.98554 + x * -1.36881))));
}

rsw_status plastic_layer_load(loader *ld, node *n, plastic_layer *out) {
  double int_ior, ext_ior;
  rsw_status st = bsdf_read_ior(ld, n, "int_ior", "polypropylene", &int_ior);
  if (!st) st = bsdf_read_ior(ld, n, "ext_ior", "air", &ext_ior);
  if (!st) st = ld_texture(ld, n, "diffuse_reflectance", 0.5, 0.0, &out->diffuse);
  if (!st) st = ld_texture_opt(ld, n, "specular_reflectance", 0.0, &out->specular);
  if (!st) st = ld_bool(ld, n, "nonlinear", false, &out->nonlinear);
  if (st) return st;
  out->eta = int_ior / ext_ior;
  return RSW_OK;
}

void plastic_layer_traverse(plastic_layer *l, param_visitor *v) {
  pv_float(v, "eta", &l->eta, UPDATE_SPECTRAL, 1e-6, INFINITY);
  pv_object(v, "diffuse_reflectance", &l->diffuse->base, 0.0, INFINITY);
  if (l->specular) pv_object(v, "specular_reflectance", &l->specular->base, 0.0, INFINITY);
}

color plastic_diffuse(const plastic_layer *l, const surface_interaction *si, double fdr) {
  color d = tex_eval(l->diffuse, si);
  for (int c = 0; c < 3; c++) d.c[c] /= 1.0 - (l->nonlinear ? d.c[c] * fdr : fdr);
  return d;
}

double plastic_specular_weight(const plastic_layer *l) {
  double d = col_mean(l->diffuse->ops->mean(l->diffuse));
  double s = l->specular ? col_mean(l->specular->ops->mean(l->specular)) : 1.0;
  return d + s > 0 ? s / (d + s) : 0.5;
}
