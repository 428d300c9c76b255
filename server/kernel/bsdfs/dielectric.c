/* `dielectric`: a smooth interface between two dielectrics (glass, water),
 * with relative index eta = int_ior / ext_ior. Works from both sides.
 *
 * With R the unpolarised Fresnel reflectance at cos(theta_i):
 *   reflection   (chosen with probability R): wo = reflect(wi), pdf R,
 *                weight = specular_reflectance;
 *   transmission (probability T = 1 - R):      wo = refract(wi), pdf T,
 *                weight = specular_transmittance * eta_ti^2.
 * The eta_ti^2 = (eta_ext / eta_int)^2 factor (on entering the denser
 * side) is the radiance compression of the solid angle in radiance
 * transport (Veach's thesis §5.2); bs->eta = eta_it for transmission, 1
 * for reflection. eval and pdf are 0 (delta lobes).
 *
 * Source: mitsuba3 src/bsdfs/dielectric.cpp, include/mitsuba/render/
 * fresnel.h, ior.h; docs/kernel-conventions.md#dielectric. */
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "bsdfs_internal.h"
#include "fresnel.h"
#include "fresnel_pol.h"

static color dielectric_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2,
                               bsdf_sample *bs) {
  (void)u2;
  const dielectric_bsdf *d = (const dielectric_bsdf *)b;
  double cos_i = si->wi.z;
  double cos_t, eta_it, eta_ti;
  double r = fresnel_dielectric(cos_i, d->eta, &cos_t, &eta_it, &eta_ti);
  if (u1 <= r) {
    bs->wo = reflect_local(si->wi);
    bs->pdf = r;
    bs->eta = 1.0;
    bs->sampled_type = BSDF_DELTA_REFLECTION;
    if (!(r > 0.0)) return bsdf_fail(bs);
    return bsdf_factor(d->specular_reflectance, si);
  }
  bs->wo = refract_local(si->wi, cos_t, eta_ti);
  bs->pdf = 1.0 - r;
  bs->eta = eta_it;
  bs->sampled_type = BSDF_DELTA_TRANSMISSION;
  if (!(bs->pdf > 0.0)) return bsdf_fail(bs);
  return col_scale(bsdf_factor(d->specular_transmittance, si), eta_ti * eta_ti);
}

/* A lobe's value and its probability (R for the reflection, 1 - R for the
 * transmission) at the page rsw_page names, where the lobe sends wi to wo
 * (bsdf_ops.delta_value; the index is one number, so the direction is
 * every page's). */
static color dielectric_delta_value(const bsdf *b, const surface_interaction *si, unsigned lobe, vec3 wo,
                                    double *prob) {
  const dielectric_bsdf *d = (const dielectric_bsdf *)b;
  double cos_t, eta_it, eta_ti;
  double r = fresnel_dielectric(si->wi.z, d->eta, &cos_t, &eta_it, &eta_ti);
  *prob = 0.0;
  if (lobe == BSDF_DELTA_REFLECTION) {
    if (!delta_same_direction(wo, reflect_local(si->wi))) return col1(0.0);
    *prob = r;
    return col_scale(bsdf_factor(d->specular_reflectance, si), r);
  }
  if (lobe != BSDF_DELTA_TRANSMISSION || !delta_same_direction(wo, refract_local(si->wi, cos_t, eta_ti)))
    return col1(0.0);
  *prob = 1.0 - r;
  return col_scale(bsdf_factor(d->specular_transmittance, si), *prob * eta_ti * eta_ti);
}

static color dielectric_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  (void)si;
  (void)wo;
  return col1(0.0);
}

static double dielectric_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  (void)si;
  (void)wo;
  return 0.0;
}

/* Polarization (docs/plugins.md#polarization-surfaces): the Fresnel reflection
 * or transmission matrix (by the side wo lies on) at the light's
 * incidence cosine, with the index seen from the light's side, s-axis
 * bases (mitsuba3 src/bsdfs/dielectric.cpp). Total internal reflection:
 * |r_s| = |r_p| = 1 with their phases, a retarder. */
static void dielectric_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                                    mueller P[3], vec3 *s_in, vec3 *s_out) {
  (void)lobe;
  P[0] = P[1] = P[2] = fpol_dielectric(((const dielectric_bsdf *)b)->eta, wo, si->wi);
  *s_in = *s_out = fpol_s_axis(wo, si->wi);
}

static const bsdf_ops dielectric_ops = {.sample = dielectric_sample,
                                        .eval = dielectric_eval,
                                        .pdf = dielectric_pdf,
                                        .polarization = dielectric_polarization,
                                        .delta_value = dielectric_delta_value};

/* An index given as a number or as a material name (Mitsuba's
 * lookup_ior()): absent -> the named default. */
rsw_status bsdf_read_ior(loader *ld, node *n, const char *name, const char *def, double *out) {
  const prop *p = node_find(n, name);
  const char *mat = def;
  if (p && p->kind != PROP_STRING) {
    rsw_status st = ld_float(ld, n, name, 0.0, out);
    if (st != RSW_OK) return st;
    if (!(*out > 0.0))
      return ld_fail(ld, n, name, RSW_ERR_RANGE, "'%s' must be positive (got %g)", name, *out);
    return RSW_OK;
  }
  if (p) {
    rsw_status st = ld_string(ld, n, name, def, &mat);
    if (st != RSW_OK) return st;
  }
  if (!ior_dielectric_lookup(mat, out))
    return ld_fail(ld, n, name, RSW_ERR_INVALID, "unknown material '%s' for '%s' (known: %s)", mat, name,
                   ior_dielectric_names());
  return RSW_OK;
}

static rsw_status dielectric_create(loader *ld, node *n, object **out) {
  double int_ior, ext_ior;
  rsw_status st = bsdf_read_ior(ld, n, "int_ior", "bk7", &int_ior);
  if (st != RSW_OK) return st;
  if ((st = bsdf_read_ior(ld, n, "ext_ior", "air", &ext_ior)) != RSW_OK) return st;
  texture *sr, *st_;
  if ((st = ld_texture_opt(ld, n, "specular_reflectance", 0.0, &sr)) != RSW_OK) return st;
  if ((st = ld_texture_opt(ld, n, "specular_transmittance", 0.0, &st_)) != RSW_OK) return st;
  return plugin_created(ld, n, (object *)dielectric_new(int_ior, ext_ior, sr, st_), out);
}

static void dielectric_traverse(object *o, param_visitor *v) {
  dielectric_bsdf *d = (dielectric_bsdf *)o;
  /* eta = int_ior / ext_ior, as Mitsuba reports it. */
  pv_float(v, "eta", &d->eta, UPDATE_SPECTRAL, 1e-6, INFINITY);
  if (d->specular_reflectance)
    pv_object(v, "specular_reflectance", &d->specular_reflectance->base, 0.0, INFINITY);
  if (d->specular_transmittance)
    pv_object(v, "specular_transmittance", &d->specular_transmittance->base, 0.0, INFINITY);
}

DEFINE_PLUGIN(dielectric, CLS_BSDF, .ops = &dielectric_ops, .traverse = dielectric_traverse);

bsdf *dielectric_new(double int_ior, double ext_ior, texture *specular_reflectance,
                     texture *specular_transmittance) {
  /* Reflects and transmits from either side. */
  dielectric_bsdf *d =
      BSDF_NEW(dielectric_bsdf, dielectric, BSDF_DELTA_REFLECTION | BSDF_DELTA_TRANSMISSION | BSDF_TWO_SIDED);
  if (!d) return NULL;
  d->eta = int_ior / ext_ior;
  d->specular_reflectance = specular_reflectance;
  d->specular_transmittance = specular_transmittance;
  return &d->base;
}
