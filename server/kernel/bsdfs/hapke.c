/* `hapke`: the six-parameter Hapke regolith model (Eradiate, after
 * Nguyen et al. 2025), one-sided.
 *
 * i, e: incidence and emergence zenith angles, mu_0 = cos i, mu = cos e,
 * psi: relative azimuth in [0, pi], tb = theta (degrees -> radians),
 *   chi   = 1 / sqrt(1 + pi tan^2 tb)
 *   E1(x) = exp(-(2/pi) cot tb cot x),  E2(x) = exp(-(1/pi) cot^2 tb cot^2 x)
 *   f     = exp(-2 tan(psi/2))          (psi/2 kept below pi/2)
 *   cos g = mu_0 mu + sin i sin e cos psi
 *   Mu(x; a, b, C, s) = chi [cos x + sin x tan tb
 *                       (C E2(a) + s sin^2(psi/2) E2(b)) / (2 - E1(a) - (psi/pi) E1(b))]
 *   e <= i: mu_e = Mu(e; i, e, cos psi, +1), mu_0e = Mu(i; i, e, 1, -1)
 *   e >  i: mu_e = Mu(e; e, i, 1, -1),       mu_0e = Mu(i; e, i, cos psi, +1)
 *   eta_e  = chi (mu   + sin e tan tb E2(e) / (2 - E1(e)))
 *   eta_0e = chi (mu_0 + sin i tan tb E2(i) / (2 - E1(i)))
 *   S = mu_e mu_0 chi / (eta_e eta_0e (1 - f + f chi X / Y)),
 *       (X, Y) = (mu, eta_e) if e < i, else (mu_0, eta_0e)   (shadowing)
 *   H(w, x) = 1 / (1 - w x (r0 + (1 - 2 r0 x) / 2 ln((1 + x) / x))),
 *       r0 = (1 - gamma) / (1 + gamma), gamma = sqrt(1 - w)
 *   M = H(w, mu_0e) H(w, mu_e) - 1                    (multiple scattering)
 *   P(g) = (1 - c)(1 - b^2) / (1 + 2 b cos g + b^2)^(3/2)
 *        + c (1 - b^2) / (1 - 2 b cos g + b^2)^(3/2)   (double HG)
 *   B(g) = B_0 / (1 + tan(g/2) / h)                   (opposition surge)
 *   f_r = w / (4 pi) mu_0e / (mu_0e + mu_e) / mu_0 (P (1 + B) + M) S,
 *   eval = f_r cos(theta_o).
 * The h = 0 guard: tan(g/2) / h is 0/0 at g = 0 and +inf elsewhere; B is
 * taken as its limit along g (B_0 at g = 0, 0 otherwise), never NaN.
 * Sampling: cosine hemisphere.
 *
 * Source: eradiate/mitsuba3 src/eradiate_plugins/bsdfs/hapke.cpp;
 * Hapke (2012) "Theory of reflectance and emittance spectroscopy", ch. 12;
 * docs/kernel-conventions.md#hapke. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "../textures/texture.h"
#include "bsdfs_internal.h"

typedef struct hapke_geom {
  double tan_tb, cot_tb, chi, psi;
} hapke_geom;

static double e1(const hapke_geom *g, double cot_x) {
  return exp(-2.0 * RSW_INV_PI * g->cot_tb * cot_x);
}
static double e2(const hapke_geom *g, double cot_x) {
  return exp(-RSW_INV_PI * g->cot_tb * g->cot_tb * cot_x * cot_x);
}

/* Mu(x; a, b, C, s) of the header, with cos/sin of x and cot of a, b. */
static double mu_eff(const hapke_geom *g, double cos_x, double sin_x, double cot_a, double cot_b, double cc,
                     double s) {
  double sh = sin(0.5 * g->psi);
  double num = cc * e2(g, cot_a) + s * sh * sh * e2(g, cot_b);
  double den = 2.0 - e1(g, cot_a) - g->psi * RSW_INV_PI * e1(g, cot_b);
  return g->chi * (cos_x + sin_x * g->tan_tb * num / den);
}

static double chandra_h(double w, double x) {
  double gamma = sqrt(1.0 - w);
  double r0 = (1.0 - gamma) / (1.0 + gamma);
  return 1.0 / (1.0 - w * x * (r0 + 0.5 * (1.0 - 2.0 * r0 * x) * log((1.0 + x) / x)));
}

double hapke_fr(double w, double b, double c, double theta_deg, double B_0, double h, vec3 wi, vec3 wo) {
  double mu0 = wi.z, mu = wo.z;
  if (!(mu0 > 0.0) || !(mu > 0.0)) return 0.0;
  double sin_i = sqrt(wi.x * wi.x + wi.y * wi.y), sin_e = sqrt(wo.x * wo.x + wo.y * wo.y);
  double i = atan2(sin_i, mu0), e = atan2(sin_e, mu);
  /* cos psi from the azimuths; azimuth 0 at the pole. */
  double cos_psi = 1.0;
  if (sin_i > 0.0 && sin_e > 0.0) cos_psi = (wi.x * wo.x + wi.y * wo.y) / (sin_i * sin_e);
  cos_psi = fmin(fmax(cos_psi, -1.0), 1.0);
  hapke_geom g;
  g.psi = acos(cos_psi);
  double tb = theta_deg * RSW_PI / 180.0;
  g.tan_tb = tan(tb);
  g.cot_tb = 1.0 / g.tan_tb; /* +inf at theta = 0: then E1 = E2 = 0 */
  g.chi = 1.0 / sqrt(1.0 + RSW_PI * g.tan_tb * g.tan_tb);
  double cot_i = mu0 / sin_i, cot_e = mu / sin_e; /* +inf at the pole */

  double f = exp(-2.0 * tan(fmin(0.5 * g.psi, nextafter(0.5 * RSW_PI, 0.0))));
  double mu_e, mu_0e;
  if (e <= i) {
    mu_e = mu_eff(&g, mu, sin_e, cot_i, cot_e, cos_psi, 1.0);
    mu_0e = mu_eff(&g, mu0, sin_i, cot_i, cot_e, 1.0, -1.0);
  } else {
    mu_e = mu_eff(&g, mu, sin_e, cot_e, cot_i, 1.0, -1.0);
    mu_0e = mu_eff(&g, mu0, sin_i, cot_e, cot_i, cos_psi, 1.0);
  }
  double eta_e = g.chi * (mu + sin_e * g.tan_tb * e2(&g, cot_e) / (2.0 - e1(&g, cot_e)));
  double eta_0e = g.chi * (mu0 + sin_i * g.tan_tb * e2(&g, cot_i) / (2.0 - e1(&g, cot_i)));
  double ratio = e < i ? mu / eta_e : mu0 / eta_0e;
  double S = mu_e * mu0 * g.chi / (eta_e * eta_0e * (1.0 - f + f * g.chi * ratio));

  double M = chandra_h(w, mu_0e) * chandra_h(w, mu_e) - 1.0;

  double cos_g = fmin(fmax(mu0 * mu + sin_i * sin_e * cos_psi, -1.0), 1.0);
  double b2 = b * b;
  double P = (1.0 - c) * (1.0 - b2) / pow(1.0 + 2.0 * b * cos_g + b2, 1.5) +
             c * (1.0 - b2) / pow(1.0 - 2.0 * b * cos_g + b2, 1.5);
  /* tan(g/2) from the chord |wi - wo| = 2 sin(g/2), exact near g = 0
   * (acos(cos g) is not: it gives g ~ 1e-8 for wi == wo). */
  double chord = v3_len(v3_sub(wi, wo));
  double t_half = tan(asin(fmin(0.5 * chord, 1.0)));
  double B;
  if (t_half == 0.0)
    B = B_0; /* g = 0: tan(g/2) / h = 0 for every h, including the 0/0 of h = 0 */
  else if (h == 0.0)
    B = 0.0; /* limit of B_0 / (1 + tan(g/2) / h) as h -> 0 for g > 0 */
  else
    B = B_0 / (1.0 + t_half / h);

  double fr = w / (4.0 * RSW_PI) * mu_0e / (mu_0e + mu_e) / mu0 * (P * (1.0 + B) + M) * S;
  return isfinite(fr) ? fr : 0.0;
}

static color hapke_value(const hapke_bsdf *hb, const surface_interaction *si, vec3 wo) {
  color w = tex_eval(hb->w, si), b = tex_eval(hb->b, si), c = tex_eval(hb->c, si);
  color th = tex_eval(hb->theta, si), b0 = tex_eval(hb->B_0, si), h = tex_eval(hb->h, si);
  color out;
  for (int k = 0; k < 3; k++)
    out.c[k] = hapke_fr(w.c[k], b.c[k], c.c[k], th.c[k], b0.c[k], h.c[k], si->wi, wo) * wo.z;
  return out;
}

static color hapke_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  (void)u1;
  if (!(si->wi.z > 0.0)) return bsdf_fail(bs);
  bs->wo = warp_square_to_cosine_hemisphere(u2);
  bs->pdf = warp_square_to_cosine_hemisphere_pdf(bs->wo);
  bs->eta = 1.0;
  bs->sampled_type = BSDF_GLOSSY_REFLECTION;
  if (!(bs->pdf > 0.0) || !(bs->wo.z > 0.0)) return bsdf_fail(bs);
  return col_scale(hapke_value((const hapke_bsdf *)b, si, bs->wo), 1.0 / bs->pdf);
}

static color hapke_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return col1(0.0);
  return hapke_value((const hapke_bsdf *)b, si, wo);
}

static double hapke_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return 0.0;
  return warp_square_to_cosine_hemisphere_pdf(wo);
}

static const bsdf_ops hapke_ops = {.sample = hapke_sample, .eval = hapke_eval, .pdf = hapke_pdf};

/* Ranges (Eradiate / Hapke): w in [0, 1], b in [0, 1), c in [0, 1],
 * theta in [0, 90) degrees, B_0 >= 0, h >= 0. */
static rsw_status hapke_create(loader *ld, node *n, object **out) {
  static const struct {
    const char *name;
    double def, lo, hi;
    bool hi_open;
  } spec[6] = {{"w", 0.5, 0.0, 1.0, false},       {"b", 0.2, 0.0, 1.0, true},
               {"c", 0.5, 0.0, 1.0, false},       {"theta", 30.0, 0.0, 90.0, true},
               {"B_0", 0.0, 0.0, INFINITY, true}, {"h", 0.0, 0.0, INFINITY, true}};
  texture *t[6];
  rsw_status st;
  for (int k = 0; k < 6; k++) {
    if ((st = ld_texture(ld, n, spec[k].name, spec[k].def, spec[k].lo, &t[k])) != RSW_OK) return st;
    if ((st = bsdf_check_const_range(ld, n, spec[k].name, t[k], spec[k].lo, false, spec[k].hi,
                                     spec[k].hi_open)) != RSW_OK)
      return st;
  }
  return plugin_created(ld, n, (object *)hapke_new(t[0], t[1], t[2], t[3], t[4], t[5]), out);
}

static void hapke_traverse(object *o, param_visitor *v) {
  hapke_bsdf *hb = (hapke_bsdf *)o;
  pv_object(v, "w", &hb->w->base, 0.0, 1.0);
  pv_object(v, "b", &hb->b->base, 0.0, nextafter(1.0, 0.0));
  pv_object(v, "c", &hb->c->base, 0.0, 1.0);
  pv_object(v, "theta", &hb->theta->base, 0.0, nextafter(90.0, 0.0));
  pv_object(v, "B_0", &hb->B_0->base, 0.0, INFINITY);
  pv_object(v, "h", &hb->h->base, 0.0, INFINITY);
}

DEFINE_PLUGIN(hapke, CLS_BSDF, .ops = &hapke_ops, .traverse = hapke_traverse);

bsdf *hapke_new(texture *w, texture *b, texture *c, texture *theta, texture *B_0, texture *h) {
  hapke_bsdf *hb = BSDF_NEW(hapke_bsdf, hapke, BSDF_GLOSSY_REFLECTION);
  if (!hb) return NULL;
  hb->w = w;
  hb->b = b;
  hb->c = c;
  hb->theta = theta;
  hb->B_0 = B_0;
  hb->h = h;
  return &hb->base;
}
