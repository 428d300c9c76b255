/* `mqdiffuse`: a measured quasi-diffuse (isotropic, grey) reflectance on a
 * grid (eradiate/mitsuba3 src/eradiate_plugins/bsdfs/mqdiffuse.cpp;
 * docs/kernel-conventions.md#mqdiffuse), one-sided.
 *
 *   eval = g(cos theta_o, phi_d / 2 pi, cos theta_i) cos theta_o
 *   phi_d = atan2(wo) - atan2(wi) wrapped to [0, 2 pi)
 * g: the `grid` volume (a nested or referenced `gridvolume`, from a .vol
 * `filename` or inline `data` with shape [Z, Y, X] = [cos_i, phi_d,
 * cos_o], x fastest; Eradiate's data order) read at the point
 *   p = c (1 - 1/res) + 1/(2 res) per axis,
 * which puts its nodes on c = k / (res - 1): the grid spans [0, 1] in each
 * coordinate with its first and last nodes on the edges (Eradiate's
 * mapping onto Dr.Jit's clamped trilinear texture, whose texel k sits at
 * (k + 1/2) / res; a gridvolume's trilinear filter is the same). The
 * volume's own to_world carries p into its box, so any to_world keeps the
 * mapping. The first channel is used (the material is grey), or, for a
 * grid with a wavelength axis (`wavelengths`), each channel its own (a
 * spectral bundle's wavelengths; mono: the render's in all three). Sampling:
 * cosine hemisphere, weight eval / pdf (Eradiate's sample() wraps phi_d
 * without the + 2 pi of its eval(): negative differences read the phi = 0
 * edge there; here both use eval's rule). Values are not checked (as in
 * Eradiate: an albedo above 1 is the user's). */
#include <math.h>
#include <stdlib.h>

#include "../scene/loader.h"
#include "../scene/params.h"
#include "../volumes/volume.h"
#include "eo_surfaces.h"

typedef struct mqdiffuse {
  bsdf base;
  volume *grid;
  bool spectral; /* the grid has a wavelength axis */
} mqdiffuse;

/* The grid's point for (wi, wo) (see the top), in world space. */
static vec3 grid_point(const volume *g, vec3 wi, vec3 wo) {
  double phi = atan2(wo.y, wo.x) - atan2(wi.y, wi.x);
  phi = fmod(phi, 2.0 * RSW_PI);
  if (phi < 0.0) phi += 2.0 * RSW_PI;
  double c[3] = {wo.z, phi / (2.0 * RSW_PI), wi.z}, p[3];
  for (int k = 0; k < 3; k++) {
    double px = 1.0 / g->res[k];
    p[k] = c[k] * (1.0 - px) + 0.5 * px;
  }
  return xf_point(&g->to_world, v3(p[0], p[1], p[2]));
}

double mqdiffuse_grid_value(const volume *g, vec3 wi, vec3 wo) {
  return volume_eval_1(g, grid_point(g, wi, wo));
}

/* The value per channel: the grid's first channel in all three (the
 * material is grey), or, for a grid with a wavelength axis, each channel
 * its own (a spectral bundle's channel c at its c-th wavelength, at the
 * page rsw_page names; in mono every channel holds the render's). */
static color mq_value(const mqdiffuse *m, vec3 wi, vec3 wo) {
  if (!(wi.z > 0.0) || !(wo.z > 0.0)) return col1(0.0);
  color g = m->spectral ? volume_eval(m->grid, grid_point(m->grid, wi, wo))
                        : col1(mqdiffuse_grid_value(m->grid, wi, wo));
  for (int c = 0; c < 3; c++) {
    double v = g.c[c] * wo.z;
    g.c[c] = isfinite(v) ? v : 0.0;
  }
  return g;
}

static color mq_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  (void)u1;
  if (!eo_cosine_sample(si, u2, bs)) return col1(0.0);
  bs->sampled_type = BSDF_DIFFUSE_REFLECTION;
  color v = mq_value((const mqdiffuse *)b, si->wi, bs->wo);
  for (int c = 0; c < 3; c++) v.c[c] /= bs->pdf;
  return v;
}

static color mq_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  return mq_value((const mqdiffuse *)b, si->wi, wo);
}

static double mq_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  return eo_cosine_pdf(si, wo);
}

static const bsdf_ops mq_ops = {.sample = mq_sample, .eval = mq_eval, .pdf = mq_pdf};

static void mq_destroy(object *o) {
  free(o);
}

static rsw_status mq_create(loader *ld, node *n, object **out) {
  if (!ld_has(n, "grid"))
    return ld_fail(ld, n, "grid", RSW_ERR_MISSING,
                   "mqdiffuse needs 'grid': a gridvolume (its 'filename' a .vol file, or inline 'data' and "
                   "'shape' [cos_i, phi_d, cos_o])");
  volume *g;
  rsw_status st = ld_volume(ld, n, "grid", 0.0, -INFINITY, INFINITY, &g);
  if (st) return st;
  bool accel;
  if ((st = ld_bool(ld, n, "accel", true, &accel)) != RSW_OK) return st; /* CUDA only: accepted */
  mqdiffuse *m = calloc(1, sizeof *m);
  if (!m) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "mqdiffuse: out of memory");
  m->base.base.plugin = &plugin_mqdiffuse;
  m->base.base.id = n->id;
  m->base.ops = &mq_ops;
  m->base.flags = BSDF_DIFFUSE_REFLECTION;
  m->grid = g;
  m->spectral = volume_spectral(g);
  *out = &m->base.base;
  return RSW_OK;
}

static void mq_traverse(object *o, param_visitor *v) {
  pv_object(v, "grid", &((mqdiffuse *)o)->grid->base, NAN, NAN);
}

const plugin plugin_mqdiffuse = {
    .name = "mqdiffuse",
    .cls = CLS_BSDF,
    .create = mq_create,
    .destroy = mq_destroy,
    .ops = &mq_ops,
    .traverse = mq_traverse,
};
