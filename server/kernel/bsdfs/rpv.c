/* `rpv`: the Rahman-Pinty-Verstraete reflection model (Eradiate), one-sided.
 *
 * With cos(theta_i), cos(theta_o) > 0 and dphi = phi_i - phi_o:
 *   cos(Theta) = cos(theta_i) cos(theta_o) + sin(theta_i) sin(theta_o) cos(dphi)
 *   F = (1 - g^2) / (1 + g^2 + 2 g cos(Theta))^(3/2)          (Henyey-Greenstein)
 *   G = sqrt(tan^2(theta_i) + tan^2(theta_o)
 *            - 2 tan(theta_i) tan(theta_o) cos(dphi))
 *   H = 1 + (1 - rho_c) / (1 + G)                             (hot spot)
 *   M = (cos(theta_i) cos(theta_o) (cos(theta_i) + cos(theta_o)))^(k - 1)
 *   f_r = rho_0 M F H / pi,   eval = f_r cos(theta_o).
 * At the pole the azimuth is taken as 0 (sin(phi) = 0, cos(phi) = 1).
 * The formula is symmetric in wi and wo, so f_r is reciprocal.
 * Sampling: cosine hemisphere, pdf cos(theta_o) / pi, weight eval / pdf.
 *
 * rho_c defaults to the same texture object as rho_0; it is then not a
 * parameter of its own (Eradiate's rpv.cpp does the same).
 *
 * Source: eradiate/mitsuba3 src/eradiate_plugins/bsdfs/rpv.cpp;
 * Rahman, Pinty, Verstraete (1993) JGR 98(D11); docs/kernel-conventions.md#rpv. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "../simd/simd.h"
#include "../textures/texture.h"
#include "bsdfs_internal.h"
#include "rpv_lanes.h"

/* sin(theta), cos(phi), sin(phi) of a local direction; azimuth 0 at the
 * pole. */
static void dir_angles(vec3 w, double *sin_t, double *cos_p, double *sin_p) {
  double s = sqrt(w.x * w.x + w.y * w.y);
  *sin_t = s;
  if (s > 0.0) {
    *cos_p = w.x / s;
    *sin_p = w.y / s;
  } else {
    *cos_p = 1.0;
    *sin_p = 0.0;
  }
}

/* The terms of pi f_r that depend on the directions only: computed once
 * per evaluation, not once per channel. */
typedef struct rpv_geom {
  double cos_big; /* cos(Theta) */
  double gg;      /* G */
  double mbase;   /* cos(theta_i) cos(theta_o) (cos(theta_i) + cos(theta_o)) */
} rpv_geom;

static rpv_geom rpv_geometry(vec3 wi, vec3 wo) {
  double ci = wi.z, co = wo.z;
  double si, cpi, spi, so, cpo, spo;
  dir_angles(wi, &si, &cpi, &spi);
  dir_angles(wo, &so, &cpo, &spo);
  double cos_dphi = cpi * cpo + spi * spo; /* cos(phi_i - phi_o) */
  rpv_geom t;
  t.cos_big = ci * co + si * so * cos_dphi;
  double ti = si / ci, to = so / co;
  double g2 = ti * ti + to * to - 2.0 * ti * to * cos_dphi;
  t.gg = sqrt(fmax(g2, 0.0));
  t.mbase = ci * co * (ci + co);
  return t;
}

/* pi f_r = rho_0 M F H (the BRF) for one channel. */
static double rpv_brf_geom(double rho_0, double k, double g, double rho_c, const rpv_geom *t) {
  /* x^1.5 as x sqrt(x): within 2 ulp of pow, about a sixth of its time. */
  double fb = 1.0 + g * g + 2.0 * g * t->cos_big;
  double f = (1.0 - g * g) / (fb * sqrt(fb));
  double h = 1.0 + (1.0 - rho_c) / (1.0 + t->gg);
  double m = pow(t->mbase, k - 1.0);
  return rho_0 * m * f * h;
}

double rpv_fr(double rho_0, double k, double g, double rho_c, vec3 wi, vec3 wo) {
  rpv_geom t = rpv_geometry(wi, wo);
  return rpv_brf_geom(rho_0, k, g, rho_c, &t) * RSW_INV_PI;
}

static bool grey(color c) {
  return c.c[0] == c.c[1] && c.c[0] == c.c[2];
}

/* pi f_r per channel, which is also the sampling weight eval / pdf =
 * f_r cos / (cos / pi). Kept apart from the cosine so that k = 1, g = 0,
 * rho_c = 1 gives exactly diffuse's numbers (M = F = H = 1 exactly).
 * Grey parameters (every mono render) take one channel's work. */
/* Do n doubles at a and b have the same bits? */
static inline bool same_bits(const double *a, const double *b, int n) {
  for (int i = 0; i < n; i++) {
    uint64_t x, y;
    memcpy(&x, &a[i], sizeof x);
    memcpy(&y, &b[i], sizeof y);
    if (x != y) return false;
  }
  return true;
}

/* This thread's last evaluation: its directions and geometry, and for grey
 * parameters (rho_0, k, g, rho_c) the parameters and the value. A bundle
 * of pages asks every page at the same directions (pages.h's
 * bsdf_eval_pages, after the sample at one page), where the parameters
 * are most often the same constants: the geometry once, and grey pages
 * like the last one no pow at all. Keyed bit for bit, so a page's value
 * is the one it would compute. */
static _Thread_local struct {
  bool ok;       /* dir and t set */
  double dir[6]; /* wi, wo */
  rpv_geom t;
  double prm[4]; /* the grey parameters of v */
  double v;      /* rpv_brf_geom's value (NAN: none) */
} rpv_last = {.v = NAN};

static color rpv_value(const rpv_bsdf *r, const surface_interaction *si, vec3 wo) {
  vec3 wi = si->wi;
  color rho_0 = tex_eval(r->rho_0, si), k = tex_eval(r->k, si), g = tex_eval(r->g, si);
  color rho_c = r->rho_c == r->rho_0 ? rho_0 : tex_eval(r->rho_c, si);
  const double dir[6] = {wi.x, wi.y, wi.z, wo.x, wo.y, wo.z};
  if (!rpv_last.ok || !same_bits(dir, rpv_last.dir, 6)) {
    rpv_last.ok = true;
    memcpy(rpv_last.dir, dir, sizeof dir);
    rpv_last.t = rpv_geometry(wi, wo);
    rpv_last.v = NAN;
  }
  const rpv_geom *t = &rpv_last.t;
  if (grey(rho_0) && grey(k) && grey(g) && grey(rho_c)) {
    const double prm[4] = {rho_0.c[0], k.c[0], g.c[0], rho_c.c[0]};
    if (isnan(rpv_last.v) || !same_bits(prm, rpv_last.prm, 4)) {
      memcpy(rpv_last.prm, prm, sizeof prm);
      rpv_last.v = rpv_brf_geom(prm[0], prm[1], prm[2], prm[3], t);
    }
    double v = rpv_last.v;
    return col1(isfinite(v) ? v : 0.0);
  }
  color out;
  for (int i = 0; i < 3; i++) {
    double v = rpv_brf_geom(rho_0.c[i], k.c[i], g.c[i], rho_c.c[i], t);
    out.c[i] = isfinite(v) ? v : 0.0;
  }
  return out;
}

/* Not a batch of one: the batched ops compute M F H in float lanes
 * (bsdfs/rpv_lanes.h), within 3e-6 of this double version, which stays the
 * reference (eval, pdf and the per-lane ops of volpath and twosided). */
static color rpv_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  (void)u1;
  if (!(si->wi.z > 0.0)) return bsdf_fail(bs);
  bs->wo = warp_square_to_cosine_hemisphere(u2);
  bs->pdf = warp_square_to_cosine_hemisphere_pdf(bs->wo);
  bs->eta = 1.0;
  bs->sampled_type = BSDF_GLOSSY_REFLECTION;
  if (!(bs->pdf > 0.0) || !(bs->wo.z > 0.0)) return bsdf_fail(bs);
  return rpv_value((const rpv_bsdf *)b, si, bs->wo);
}

static color rpv_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return col1(0.0);
  return col_scale(rpv_value((const rpv_bsdf *)b, si, wo), RSW_INV_PI * wo.z);
}

static double rpv_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  (void)b;
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return 0.0;
  return warp_square_to_cosine_hemisphere_pdf(wo);
}

/* ---- batched ops --------------------------------------------------------
 * pi f_r of up to RPV_C lanes with M F H in float lanes
 * (bsdfs/rpv_lanes.h rpv_factor_lanes says why single precision is
 * safe there, and why rpv_value() keeps a double version) and rho_0 times it in double. Grey lanes take channel 0's
 * factor; when a chunk holds a coloured lane, each lane computes three
 * (a grey lane's three are the same numbers), so a lane's value depends on
 * its own inputs only. Equal to rpv_value() within 3e-6 relative (the
 * worst of 6e5 random pairs; tests/kernel/simd/test_simd.c checks 1e-5). */
enum {
  RPV_C = 64
};

static void rpv_factor_batch(rsw_isa isa, int n, const float *const *in, float *out) {
  SIMD_DISPATCH(isa, rpv_factor, n, in, out);
}

static void rpv_values_batch(const rpv_bsdf *r, int m, const surface_interaction *const *si, const vec3 *wo,
                             color *out) {
  float in[9][RPV_C], fac[3][RPV_C];
  color rho_0[RPV_C], kc[RPV_C], gc[RPV_C], rc[RPV_C];
  bool all_grey = true;
  for (int j = 0; j < m; j++) {
    rho_0[j] = tex_eval(r->rho_0, si[j]);
    kc[j] = tex_eval(r->k, si[j]);
    gc[j] = tex_eval(r->g, si[j]);
    rc[j] = r->rho_c == r->rho_0 ? rho_0[j] : tex_eval(r->rho_c, si[j]);
    all_grey = all_grey && grey(rho_0[j]) && grey(kc[j]) && grey(gc[j]) && grey(rc[j]);
    vec3 wi = si[j]->wi, o = wo[j];
    in[0][j] = (float)wi.x, in[1][j] = (float)wi.y, in[2][j] = (float)wi.z;
    in[3][j] = (float)o.x, in[4][j] = (float)o.y, in[5][j] = (float)o.z;
  }
  const float *ip[9] = {in[0], in[1], in[2], in[3], in[4], in[5], in[6], in[7], in[8]};
  rsw_isa isa = rsw_isa_get();
  int nch = all_grey ? 1 : 3;
  for (int ch = 0; ch < nch; ch++) {
    for (int j = 0; j < m; j++)
      in[6][j] = (float)kc[j].c[ch], in[7][j] = (float)gc[j].c[ch], in[8][j] = (float)rc[j].c[ch];
    rpv_factor_batch(isa, m, ip, fac[ch]);
  }
  for (int j = 0; j < m; j++)
    for (int ch = 0; ch < 3; ch++) {
      double v = rho_0[j].c[ch] * (double)fac[all_grey ? 0 : ch][j];
      out[j].c[ch] = isfinite(v) ? v : 0.0;
    }
}

/* ---- the exact batch (sample_batch_exact, eval_pdf_batch_exact) ----------
 * Bit for bit rpv_value() per lane: with uniform grey parameters (read
 * once, tex_eval's value) the direction terms, F and H in double lanes
 * (bsdfs/rpv_lanes.h rpv_terms_exact, rpv_geometry()'s and
 * rpv_brf_geom()'s operations in their order), M through libm's pow per
 * lane, and the product in rpv_brf_geom()'s order; other parameters take
 * rpv_value() itself, lane by lane. */
static void rpv_terms_exact_batch(rsw_isa isa, int n, const double *const *in, double *const *out) {
  SIMD_DISPATCH(isa, rpv_terms_exact, n, in, out);
}

/* The uniform grey parameters rho_0, k, g, rho_c into p[0..3]; false:
 * a parameter varies or is coloured. */
static bool rpv_uniform_grey(const rpv_bsdf *r, double *p) {
  const texture *t[4] = {r->rho_0, r->k, r->g, r->rho_c};
  for (int i = 0; i < 4; i++) {
    color c;
    if (!uniform_texture_value(t[i], &c) || !grey(c)) return false;
    p[i] = c.c[0];
  }
  return true;
}

static void rpv_values_exact(const rpv_bsdf *r, int m, const surface_interaction *const *si, const vec3 *wo,
                             color *out) {
  double p[4];
  if (!rpv_uniform_grey(r, p)) {
    for (int j = 0; j < m; j++) out[j] = rpv_value(r, si[j], wo[j]);
    return;
  }
  double in[8][RPV_C], t[3][RPV_C];
  for (int j = 0; j < m; j++) {
    vec3 wi = si[j]->wi, o = wo[j];
    in[0][j] = wi.x, in[1][j] = wi.y, in[2][j] = wi.z;
    in[3][j] = o.x, in[4][j] = o.y, in[5][j] = o.z;
    in[6][j] = p[2], in[7][j] = p[3];
  }
  const double *ip[8] = {in[0], in[1], in[2], in[3], in[4], in[5], in[6], in[7]};
  double *op[3] = {t[0], t[1], t[2]};
  rpv_terms_exact_batch(rsw_isa_get(), m, ip, op);
  double e = p[1] - 1.0;
  for (int j = 0; j < m; j++) {
    double x = p[0] * pow(t[0][j], e) * t[1][j] * t[2][j];
    out[j] = col1(isfinite(x) ? x : 0.0);
  }
}

/* The values of lanes vs[0..m) towards vwo (exact: rpv_values_exact, else
 * the float lanes' rpv_values_batch). */
static void rpv_values(const rpv_bsdf *r, bool exact, int m, const surface_interaction *const *vs,
                       const vec3 *vwo, color *out) {
  if (exact)
    rpv_values_exact(r, m, vs, vwo, out);
  else
    rpv_values_batch(r, m, vs, vwo, out);
}

/* sample_batch (exact false) and sample_batch_exact: the cosine-hemisphere
 * warp in double lanes (bitwise the scalar directions and pdfs), the
 * value as above. */
static void rpv_sample_lanes(const bsdf *b, bool exact, int n, const surface_interaction *const *si,
                             const vec2 *u2, bsdf_sample *bs, color *weight) {
  const rpv_bsdf *r = (const rpv_bsdf *)b;
  rsw_isa isa = rsw_isa_get();
  for (int i0 = 0; i0 < n; i0 += RPV_C) {
    int m = n - i0 < RPV_C ? n - i0 : RPV_C;
    double u[2 * RPV_C], out[3 * RPV_C];
    int lane[RPV_C], k = 0;
    for (int j = 0; j < m; j++) {
      if (!(si[i0 + j]->wi.z > 0.0)) {
        weight[i0 + j] = bsdf_fail(&bs[i0 + j]);
        continue;
      }
      u[2 * k] = u2[i0 + j].x, u[2 * k + 1] = u2[i0 + j].y;
      lane[k++] = i0 + j;
    }
    cosine_hemisphere_batch(isa, k, u, out);
    const surface_interaction *vs[RPV_C];
    vec3 vwo[RPV_C];
    int v = 0, vlane[RPV_C];
    for (int j = 0; j < k; j++) {
      int i = lane[j];
      bsdf_sample *s = &bs[i];
      s->wo = v3(out[3 * j], out[3 * j + 1], out[3 * j + 2]);
      s->pdf = warp_square_to_cosine_hemisphere_pdf(s->wo);
      s->eta = 1.0;
      s->sampled_type = BSDF_GLOSSY_REFLECTION;
      if (!(s->pdf > 0.0) || !(s->wo.z > 0.0)) {
        weight[i] = bsdf_fail(s);
        continue;
      }
      vs[v] = si[i], vwo[v] = s->wo, vlane[v++] = i;
    }
    color val[RPV_C];
    if (v > 0) rpv_values(r, exact, v, vs, vwo, val);
    for (int j = 0; j < v; j++) weight[vlane[j]] = val[j];
  }
}

static void rpv_sample_batch(const bsdf *b, int n, const surface_interaction *const *si, const double *u1,
                             const vec2 *u2, bsdf_sample *bs, color *weight) {
  (void)u1;
  rpv_sample_lanes(b, false, n, si, u2, bs, weight);
}

static void rpv_sample_batch_exact(const bsdf *b, int n, const surface_interaction *const *si,
                                   const double *u1, const vec2 *u2, bsdf_sample *bs, color *weight) {
  (void)u1;
  rpv_sample_lanes(b, true, n, si, u2, bs, weight);
}

/* eval_pdf_batch (exact false) and eval_pdf_batch_exact. */
static void rpv_eval_pdf_lanes(const bsdf *b, bool exact, int n, const surface_interaction *const *si,
                               const vec3 *wo, color *f, double *pdf) {
  const rpv_bsdf *r = (const rpv_bsdf *)b;
  for (int i0 = 0; i0 < n; i0 += RPV_C) {
    int m = n - i0 < RPV_C ? n - i0 : RPV_C;
    const surface_interaction *vs[RPV_C];
    vec3 vwo[RPV_C];
    int v = 0, vlane[RPV_C];
    for (int j = 0; j < m; j++) {
      int i = i0 + j;
      f[i] = col1(0.0);
      pdf[i] = 0.0;
      if (!(si[i]->wi.z > 0.0) || !(wo[i].z > 0.0)) continue;
      pdf[i] = warp_square_to_cosine_hemisphere_pdf(wo[i]);
      vs[v] = si[i], vwo[v] = wo[i], vlane[v++] = i;
    }
    color val[RPV_C];
    if (v > 0) rpv_values(r, exact, v, vs, vwo, val);
    for (int j = 0; j < v; j++) f[vlane[j]] = col_scale(val[j], RSW_INV_PI * vwo[j].z);
  }
}

static void rpv_eval_pdf_batch(const bsdf *b, int n, const surface_interaction *const *si, const vec3 *wo,
                               color *f, double *pdf) {
  rpv_eval_pdf_lanes(b, false, n, si, wo, f, pdf);
}

static void rpv_eval_pdf_batch_exact(const bsdf *b, int n, const surface_interaction *const *si,
                                     const vec3 *wo, color *f, double *pdf) {
  rpv_eval_pdf_lanes(b, true, n, si, wo, f, pdf);
}

static const bsdf_ops rpv_ops = {.sample = rpv_sample,
                                 .eval = rpv_eval,
                                 .pdf = rpv_pdf,
                                 .sample_batch = rpv_sample_batch,
                                 .eval_pdf_batch = rpv_eval_pdf_batch,
                                 .sample_batch_exact = rpv_sample_batch_exact,
                                 .eval_pdf_batch_exact = rpv_eval_pdf_batch_exact};

rsw_status bsdf_check_const_range(loader *ld, node *n, const char *name, const texture *t, double lo,
                                  bool lo_open, double hi, bool hi_open) {
  color c;
  if (!t || !uniform_texture_value(t, &c)) return RSW_OK; /* varying: not checked */
  for (int i = 0; i < 3; i++) {
    double v = c.c[i];
    bool ok = isfinite(v) && (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
    if (!ok)
      return ld_fail(ld, n, name, RSW_ERR_INVALID, "%s = %g lies outside %c%g, %g%c", name, v,
                     lo_open ? '(' : '[', lo, hi, hi_open ? ')' : ']');
  }
  return RSW_OK;
}

/* Ranges as Eradiate documents them: rho_0 >= 0, k >= 0, -1 < g < 1,
 * rho_c >= 0. */
static rsw_status rpv_create(loader *ld, node *n, object **out) {
  texture *rho_0, *k, *g, *rho_c;
  rsw_status st;
  if ((st = ld_texture(ld, n, "rho_0", 0.1, 0.0, &rho_0)) != RSW_OK) return st;
  if ((st = ld_texture(ld, n, "k", 0.1, 0.0, &k)) != RSW_OK) return st;
  if ((st = ld_texture(ld, n, "g", 0.0, -INFINITY, &g)) != RSW_OK) return st;
  if ((st = ld_texture_opt(ld, n, "rho_c", 0.0, &rho_c)) != RSW_OK) return st;
  if ((st = bsdf_check_const_range(ld, n, "k", k, 0.0, false, INFINITY, true)) != RSW_OK) return st;
  if ((st = bsdf_check_const_range(ld, n, "g", g, -1.0, true, 1.0, true)) != RSW_OK) return st;
  return plugin_created(ld, n, (object *)rpv_new(rho_0, k, g, rho_c), out);
}

static void rpv_traverse(object *o, param_visitor *v) {
  rpv_bsdf *r = (rpv_bsdf *)o;
  pv_object(v, "rho_0", &r->rho_0->base, 0.0, INFINITY);
  pv_object(v, "k", &r->k->base, 0.0, INFINITY);
  pv_object(v, "g", &r->g->base, nextafter(-1.0, 0.0), nextafter(1.0, 0.0));
  if (r->rho_c != r->rho_0) pv_object(v, "rho_c", &r->rho_c->base, 0.0, INFINITY);
}

DEFINE_PLUGIN(rpv, CLS_BSDF, .ops = &rpv_ops, .traverse = rpv_traverse);

bsdf *rpv_new(texture *rho_0, texture *k, texture *g, texture *rho_c) {
  rpv_bsdf *r = BSDF_NEW(rpv_bsdf, rpv, BSDF_GLOSSY_REFLECTION);
  if (!r) return NULL;
  r->rho_0 = rho_0;
  r->k = k;
  r->g = g;
  r->rho_c = rho_c ? rho_c : rho_0;
  return &r->base;
}
