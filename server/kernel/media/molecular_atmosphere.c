/* `molecular_atmosphere`: a plane-parallel atmosphere built from a
 * thermophysical profile and evaluated at the render's wavelength (Eradiate's
 * MolecularAtmosphere, with its ParticleLayer mixed in layer by layer).
 * docs/atmosphere.md is the user's description; the physics:
 *
 *  - Profile (`thermoprops`): one of the six AFGL 1986 model atmospheres
 *    (Anderson et al. 1986, AFGL-TR-86-0110; data/afgl_1986) on the
 *    user's levels z_0 = 0 < z_1 < ... < z_N [m], or an inline profile at
 *    those levels. Number densities are log-linear in altitude between
 *    the table's (or the inline profile's) levels and each layer holds
 *    their exact average over the layer (so columns do not depend on the
 *    levels); temperature is linear, taken at the layer's middle.
 *  - Rayleigh scattering: sigma_s = n_air sigma_R(lambda) with the
 *    cross section of Bodhaine et al. (1999), J. Atmos. Oceanic Technol.
 *    16, 1854, eqs. (16)-(23): the refractive index of air of Peck and
 *    Reeder (1972) scaled to 360 ppm CO2 (eq. 19), the King factor of
 *    N2, O2, Ar and CO2 (eqs. 23), N_s = 2.546899e19 cm^-3; phase function
 *    `rayleigh`.
 *  - Absorption: O3 with the cross sections of Bogumil et al. (2003)
 *    (data/ozone; quadratic in temperature, 230-1066.2 nm; 0 above the
 *    table), times the profile's O3 density, plus an optional
 *    user-supplied `sigma_a` (m^-1 per layer, possibly a spectrum each).
 *  - Particle layers: optical thickness tau_ref at w_ref spread between
 *    bottom and top by a distribution (Eradiate's: uniform; exponential
 *    with `rate` over the layer's normalised altitude, or `scale_height`
 *    in metres; gaussian with `mean` and `std` in normalised altitude,
 *    truncated to the layer); each model layer gets the distribution's
 *    mass inside it, so the thickness sums to tau_ref exactly. The
 *    spectral dependence is the Angstrom law (lambda / w_ref)^-alpha or an
 *    extinction spectrum ratio ext(lambda) / ext(w_ref); single-scattering
 *    albedo constant or a spectrum; phase function any nested one.
 *  - Mixing, per layer: sigma_t and sigma_s add; the phase function is
 *    the scattering-weighted mixture, computed as Eradiate's nested
 *    `blendphase` (component j mixed onto components 0..j-1 with weight
 *    s_j / (s_0 + ... + s_j); 0 is Rayleigh), arithmetic for arithmetic,
 *    so that the same layers given to `piecewise` + `blendphase` render
 *    the same film bit for bit; in the polarized variants its phase
 *    matrix too (blendphase's: the components' matrices weighted by their
 *    shares).
 *
 * The layers live in the box [-width/2, width/2]^2 x [0, z_N] (metres;
 * tracked exactly by layered.c, as piecewise); a wavelength change costs
 * one O(N) recomputation in prepare(). Mono only. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../phase/phase.h"
#include "../scene/plugin_def.h"
#include "../volumes/volume.h"
#include "atmo_data.h"
#include "layered.h"
#include "media.h"
#include "molecular_atmosphere.h"

enum {
  DIST_UNIFORM,
  DIST_EXPONENTIAL,
  DIST_GAUSSIAN
};

/* A spectral quantity: a constant or a tabulated spectrum of the document. */
typedef struct ma_spec {
  double value;
  const spectrum *spec; /* NULL: value */
} ma_spec;

typedef struct ma_particle {
  char key[64]; /* particle_layer_<i> */
  double bottom, top, tau_ref, w_ref;
  int dist;
  double rate, mean, std;
  bool has_angstrom;
  double angstrom;
  ma_spec ext, ssa;
  phase *ph;
} ma_particle;

typedef struct mol_atmo mol_atmo;

typedef struct ma_phase {
  phase base;
  const mol_atmo *m;
} ma_phase;

struct mol_atmo {
  layered_medium lm; /* (first: the ops see a layered_medium) */
  xform box;
  double width;
  uint32_t n;
  double *z;                /* n + 1 levels [m] */
  double *n_air, *n_o3, *t; /* per layer: m^-3, m^-3, K */
  double *sig_t, *alb, *w;  /* per layer (w: np per layer, nested blend weights) */
  double *wc;               /* a bundle's w per channel: (k np + j) 3 + c */
  double *s_comp;           /* scratch: per component scattering (1 + np) */
  double **frac;            /* per particle layer: its share of tau in each layer */
  volume *sigma_a;          /* NULL: none */
  bool has_absorption, has_scattering;
  size_t np;
  ma_particle *p;
  phase *rayleigh;
  ma_phase mix;
  double wl;                     /* wavelength of the layer values (a bundle's first); 0: none yet */
  double wl3[RENDER_MAX_BUNDLE]; /* a bundle's: wavelength b (render_ctx.wl) */
  /* A bundle of pages (render_ctx.bundle > 3): pages 1.. keep their
   * layers in lm.Lp and their blend weights per channel in wcp (page p at
   * wcp + (p - 1) 3 n np), allocated by the first such prepare. */
  double *wcp;
  int pages_alloc; /* pages 1.. allocated (lm.Lp, wcp) */
  int bundle;      /* the wavelengths the layer values hold (0 or 1: one in every channel) */
  uint64_t sa_revision;
  bool dirty;
  bool absorbing_only; /* every layer's albedo is 0 (all channels) */
};

/* ---- cross sections ---------------------------------------------------------- */

double atmo_rayleigh_cross_section(double wavelength_nm) {
  /* Bodhaine et al. (1999): lambda in micrometres, sigma in cm^2. */
  double l = wavelength_nm * 1e-3, il2 = 1.0 / (l * l);
  double n300 = 1.0 + (8060.51 + 2480990.0 / (132.274 - il2) + 17455.7 / (39.32957 - il2)) * 1e-8;
  const double co2 = 360e-6; /* mole fraction */
  double n = 1.0 + (n300 - 1.0) * (1.0 + 0.54 * (co2 - 0.0003));
  double f_n2 = 1.034 + 3.17e-4 * il2, f_o2 = 1.096 + 1.385e-3 * il2 + 1.448e-4 * il2 * il2;
  double c = co2 * 100.0; /* percent */
  double f_air = (78.084 * f_n2 + 20.946 * f_o2 + 0.934 * 1.00 + c * 1.15) / (78.084 + 20.946 + 0.934 + c);
  const double ns = 2.546899e19; /* cm^-3 */
  double lc = l * 1e-4, n2 = n * n;
  double s = 24.0 * RSW_PI * RSW_PI * RSW_PI * (n2 - 1.0) * (n2 - 1.0) /
             (lc * lc * lc * lc * ns * ns * (n2 + 2.0) * (n2 + 2.0)) * f_air;
  return s * 1e-4; /* m^2 */
}

/* Index i with wl[i] <= x < wl[i + 1] (x inside the table). */
static int table_find(const double *wl, int n, double x) {
  int lo = 0, hi = n - 2;
  while (lo < hi) {
    int mid = (lo + hi + 1) / 2;
    if (wl[mid] <= x)
      lo = mid;
    else
      hi = mid - 1;
  }
  return lo;
}

bool atmo_o3_coefficients(double wavelength_nm, double c[3]) {
  const atmo_o3_table *o = &atmo_o3_bogumil_2003;
  c[0] = c[1] = c[2] = 0.0;
  if (wavelength_nm > o->wl[o->n - 1]) return true;
  if (!(wavelength_nm >= o->wl[0])) return false;
  int i = table_find(o->wl, o->n, wavelength_nm);
  double f = (wavelength_nm - o->wl[i]) / (o->wl[i + 1] - o->wl[i]);
  c[0] = o->c0[i] + f * (o->c0[i + 1] - o->c0[i]);
  c[1] = o->c1[i] + f * (o->c1[i + 1] - o->c1[i]);
  c[2] = o->c2[i] + f * (o->c2[i + 1] - o->c2[i]);
  return true;
}

static double o3_cross_section(const double c[3], double t) {
  double d = t - 273.15, s = (c[0] + c[1] * d + c[2] * d * d) * 1e-24; /* 1e-20 cm^2 = 1e-24 m^2 */
  return s > 0.0 ? s : 0.0;
}

/* ---- profiles --------------------------------------------------------------- */

/* The average over [a, b] of the log-linear interpolant of (zt, v) (n
 * levels, zt increasing, [a, b] inside [zt[0], zt[n-1]]): the exact
 * integral of each exponential piece. */
static double loglin_average(const double *zt, const double *v, int n, double a, double b) {
  double sum = 0.0;
  for (int i = 0; i + 1 < n; i++) {
    double lo = fmax(a, zt[i]), hi = fmin(b, zt[i + 1]);
    if (!(hi > lo)) continue;
    double v0 = v[i], v1 = v[i + 1], h = zt[i + 1] - zt[i];
    if (v0 <= 0.0 || v1 <= 0.0 || v0 == v1) { /* linear (a zero end, or constant) */
      double f0 = v0 + (v1 - v0) * (lo - zt[i]) / h, f1 = v0 + (v1 - v0) * (hi - zt[i]) / h;
      sum += 0.5 * (f0 + f1) * (hi - lo);
      continue;
    }
    double k = log(v1 / v0) / h; /* v(z) = v0 e^{k (z - zt_i)} */
    sum += v0 * (exp(k * (hi - zt[i])) - exp(k * (lo - zt[i]))) / k;
  }
  return sum / (b - a);
}

static double lin_at(const double *zt, const double *v, int n, double x) {
  if (x <= zt[0]) return v[0];
  if (x >= zt[n - 1]) return v[n - 1];
  int i = table_find(zt, n, x);
  return v[i] + (v[i + 1] - v[i]) * (x - zt[i]) / (zt[i + 1] - zt[i]);
}

/* ---- particle layers -------------------------------------------------------- */

/* The distribution's CDF at normalised altitude x in [0, 1]. */
static double dist_cdf(const ma_particle *p, double x) {
  if (x <= 0.0) return 0.0;
  if (x >= 1.0) return 1.0;
  switch (p->dist) {
  case DIST_EXPONENTIAL:
    if (p->rate == 0.0) return x;
    return expm1(-p->rate * x) / expm1(-p->rate);
  case DIST_GAUSSIAN: {
    double s = p->std * sqrt(2.0), e0 = erf((0.0 - p->mean) / s), e1 = erf((1.0 - p->mean) / s);
    return (erf((x - p->mean) / s) - e0) / (e1 - e0);
  }
  default: return x;
  }
}

static double spec_at(const ma_spec *s, double wl, bool *ok) {
  if (!s->spec) return s->value;
  const spectrum *sp = s->spec;
  if (sp->kind == SPEC_UNIFORM) return sp->value;
  if (sp->kind != SPEC_TABLE || !(wl >= sp->wl[0] && wl <= sp->wl[sp->n - 1])) {
    *ok = false;
    return 0.0;
  }
  if (sp->n == 1) return sp->val[0];
  int i = table_find(sp->wl, (int)sp->n, wl);
  double f = (wl - sp->wl[i]) / (sp->wl[i + 1] - sp->wl[i]);
  return sp->val[i] + f * (sp->val[i + 1] - sp->val[i]);
}

/* ---- the layers at a wavelength ---------------------------------------------- */

/* The layer values at wavelength wl into channel ch (ch < 0: every
 * channel; then also the scalar per-layer values and the phase mixture's
 * weights, which a bundle, refused with particles, does not vary). */
static rsw_status ma_refresh_channel(mol_atmo *m, double wl, int ch, int page, media_layers *L, double *wc,
                                     bool first, rsw_err *err) {
  uint32_t n = m->n;
  const char *id = m->lm.base.base.id ? m->lm.base.base.id : "";
  double sr = m->has_scattering ? atmo_rayleigh_cross_section(wl) : 0.0;
  double c3[3] = {0, 0, 0};
  bool o3 = m->has_absorption;
  if (o3 && !atmo_o3_coefficients(wl, c3))
    return rsw_fail(err, RSW_ERR_INVALID, "",
                    "molecular_atmosphere '%s': wavelength %g nm is below the ozone "
                    "cross sections' range (Bogumil et al. 2003: 230-1066.2 nm)",
                    id, wl);
  /* Particle layers: sigma_t per model layer (in m->frac, scaled below). */
  size_t np = m->np;
  double *pt = m->s_comp + 1 + np, *pssa = pt + np; /* per particle: extinction ratio, albedo */
  for (size_t j = 0; j < np; j++) {
    ma_particle *p = &m->p[j];
    bool ok = true;
    double ratio;
    if (p->has_angstrom) {
      ratio = pow(wl / p->w_ref, -p->angstrom);
    } else {
      double e0 = spec_at(&p->ext, p->w_ref, &ok), e = spec_at(&p->ext, wl, &ok);
      if (ok && !(e0 > 0.0))
        return rsw_fail(err, RSW_ERR_INVALID, "",
                        "molecular_atmosphere '%s': %s: the extinction spectrum is 0 "
                        "at w_ref = %g nm",
                        id, p->key, p->w_ref);
      ratio = ok ? e / e0 : 0.0;
    }
    double a = spec_at(&p->ssa, wl, &ok);
    if (!ok)
      return rsw_fail(err, RSW_ERR_INVALID, "",
                      "molecular_atmosphere '%s': %s: wavelength %g nm is outside "
                      "its tabulated spectra",
                      id, p->key, wl);
    pt[j] = p->tau_ref * ratio;
    pssa[j] = a < 0.0 ? 0.0 : a > 1.0 ? 1.0 : a;
    /* fractions (bottom/top/distribution may have changed) */
    double span = p->top - p->bottom;
    for (uint32_t k = 0; k < n; k++)
      m->frac[j][k] =
          dist_cdf(p, (m->z[k + 1] - p->bottom) / span) - dist_cdf(p, (m->z[k] - p->bottom) / span);
  }
  /* sigma_a at this channel's wavelength: a bundle's volume holds its
   * channels (page by page: volume_page_data) */
  const double *sa = NULL;
  bool sa_grid = false;
  uint32_t sa_ch = 0, sa_off = 0;
  if (m->sigma_a) {
    sa = volume_page_data(m->sigma_a, page);
    sa_grid = m->sigma_a->res[2] > 1;
    sa_ch = m->sigma_a->channels;
    sa_off = sa_ch == 3 && ch > 0 ? (uint32_t)ch : 0;
    m->sa_revision = m->sigma_a->revision;
  }
  double amax = 0.0;
  for (uint32_t k = 0; k < n; k++) {
    double dz = m->z[k + 1] - m->z[k];
    double ss = m->n_air[k] * sr, sabs = 0.0;
    if (m->has_absorption) {
      if (o3) sabs += m->n_o3[k] * o3_cross_section(c3, m->t[k]);
      if (sa) sabs += sa[(sa_grid ? k : 0) * sa_ch + sa_off];
    }
    double st = ss + sabs;
    double *s = m->s_comp;
    s[0] = ss;
    for (size_t j = 0; j < np; j++) {
      double e = pt[j] * m->frac[j][k] / dz;
      st += e;
      s[1 + j] = pssa[j] * e;
      ss += s[1 + j];
    }
    double al = st > 0.0 ? ss / st : 0.0;
    if (al > 1.0) al = 1.0;
    if (ch <= 0 && first) {
      /* Nested blend weights: component j onto 0..j-1. */
      double acc = s[0];
      for (size_t j = 0; j < np; j++) {
        acc += s[1 + j];
        m->w[k * np + j] = acc > 0.0 ? s[1 + j] / acc : 0.0;
      }
      m->sig_t[k] = st;
      m->alb[k] = al;
    }
    if (ch >= 0) { /* a bundle: channel ch's blend weights */
      double acc = s[0];
      for (size_t j = 0; j < np; j++) {
        acc += s[1 + j];
        wc[(k * np + j) * 3 + (size_t)ch] = acc > 0.0 ? s[1 + j] / acc : 0.0;
      }
    }
    for (int c = ch < 0 ? 0 : ch; c < (ch < 0 ? 3 : ch + 1); c++) {
      L->lay[k].sig[c] = m->lm.base.scale * st;
      L->alb[3 * k + c] = al;
    }
    if (al > amax) amax = al;
  }
  if (ch <= 0 && first)
    m->absorbing_only = amax == 0.0;
  else
    m->absorbing_only = m->absorbing_only && amax == 0.0;
  return RSW_OK;
}

/* Pages 1..pages-1 of a bundle allocated (their levels those of lm.L).
 * False: out of memory. */
static bool ma_pages_alloc(mol_atmo *m, int pages) {
  if (m->pages_alloc >= pages - 1) return true;
  size_t per = 3 * (size_t)m->n * (m->np ? m->np : 1);
  media_layers *lp = calloc(RENDER_MAX_PAGES - 1, sizeof *lp);
  double *wcp = calloc((RENDER_MAX_PAGES - 1) * per, sizeof *wcp);
  bool ok = lp && wcp;
  for (int p = 0; ok && p < RENDER_MAX_PAGES - 1; p++) {
    ok = media_layers_alloc(&lp[p], m->n);
    if (!ok) break;
    lp[p].to_world = m->lm.L.to_world;
    lp[p].uniform = m->lm.L.uniform;
    for (uint32_t k = 0; k <= m->n; k++) lp[p].lay[k].z = m->lm.L.lay[k].z;
  }
  if (!ok) {
    for (int p = 0; lp && p < RENDER_MAX_PAGES - 1; p++) media_layers_free(&lp[p]);
    free(lp);
    free(wcp);
    return false;
  }
  m->lm.Lp = lp;
  m->wcp = wcp;
  m->pages_alloc = RENDER_MAX_PAGES - 1;
  return true;
}

/* The layer values at rc's wavelength, or a bundle's channel by channel
 * (page by page: lm.L and wc, then lm.Lp and wcp). */
static rsw_status ma_refresh(mol_atmo *m, const render_ctx *rc, rsw_err *err) {
  double wl = rc->wavelength > 0 ? rc->wavelength : 550.0;
  int bundle = rc->bundle > 1 ? rc->bundle : 0;
  int pages = rc_pages(rc);
  rsw_status st = RSW_OK;
  if (pages > 1 && !ma_pages_alloc(m, pages))
    return rsw_fail(err, RSW_ERR_NOMEM, "", "molecular_atmosphere: out of memory");
  if (!bundle) {
    st = ma_refresh_channel(m, wl, -1, 0, &m->lm.L, m->wc, true, err);
  } else {
    size_t per = 3 * (size_t)m->n * (m->np ? m->np : 1);
    for (int p = 0; p < pages && !st; p++) {
      render_ctx pc = rc_page(rc, p);
      media_layers *L = p ? &m->lm.Lp[p - 1] : &m->lm.L;
      double *wc = p ? m->wcp + (size_t)(p - 1) * per : m->wc;
      for (int c = 0; c < 3 && !st; c++) st = ma_refresh_channel(m, pc.wl[c], c, p, L, wc, p == 0, err);
      L->nc = 3;
      if (p) media_layers_finish(L);
    }
    memcpy(m->wl3, rc->wl, sizeof m->wl3);
  }
  if (st) return st;
  m->lm.L.nc = bundle ? 3 : 1;
  m->lm.base.has_spectral_extinction = bundle != 0;
  m->mix.base.chromatic = bundle != 0 && m->np > 0;
  media_layers_finish(&m->lm.L);
  layered_extremes(&m->lm, pages);
  m->lm.base.absorbing_only = m->absorbing_only;
  m->wl = wl;
  m->bundle = bundle;
  m->dirty = false;
  return RSW_OK;
}

/* ---- the mixed phase function ------------------------------------------------ */

static int ma_layer_at(const mol_atmo *m, vec3 p) {
  return media_layer_of(&m->lm.L, media_layers_z(&m->lm.L, p));
}

static double clamp01(double w) {
  return w > 1.0 ? 1.0 : w > 0.0 ? w : 0.0;
}

static double ma_weight(const mol_atmo *m, int k, size_t j) {
  return clamp01(m->w[(size_t)k * m->np + j]);
}

/* Components 0..j mixed (0: Rayleigh), as nested blendphases. */
static double mix_eval(const mol_atmo *m, int k, size_t j, const medium_interaction *mi, vec3 wo,
                       double *pdf) {
  if (j == 0) return m->rayleigh->ops->eval_pdf(m->rayleigh, mi, wo, pdf);
  double w = ma_weight(m, k, j - 1), p0 = 0, p1 = 0, v0 = 0, v1 = 0;
  const phase *ph = m->p[j - 1].ph;
  if (w < 1.0) v0 = mix_eval(m, k, j - 1, mi, wo, &p0);
  if (w > 0.0) v1 = ph->ops->eval_pdf(ph, mi, wo, &p1);
  *pdf = (1.0 - w) * p0 + w * p1;
  return (1.0 - w) * v0 + w * v1;
}

static double mix_sample(const mol_atmo *m, int k, size_t j, const medium_interaction *mi, double u1, vec2 u2,
                         vec3 *wo, double *pdf) {
  if (j == 0) return m->rayleigh->ops->sample(m->rayleigh, mi, u1, u2, wo, pdf);
  double w = ma_weight(m, k, j - 1), cpdf, cw;
  const phase *ph = m->p[j - 1].ph;
  if (w >= 1.0 || (w > 0.0 && u1 <= w)) {
    u1 = w >= 1.0 ? u1 : u1 / w;
    cw = ph->ops->sample(ph, mi, u1 < 1.0 ? u1 : 1.0, u2, wo, &cpdf);
  } else {
    u1 = w <= 0.0 ? u1 : (u1 - w) / (1.0 - w);
    cw = mix_sample(m, k, j - 1, mi, u1 < 1.0 ? u1 : 1.0, u2, wo, &cpdf);
  }
  if (!(cpdf > 0.0) || !(cw > 0.0)) return *pdf = 0.0, 0.0;
  double val = mix_eval(m, k, j, mi, *wo, pdf);
  if (!(*pdf > 0.0)) return *pdf = 0.0, 0.0;
  return val / *pdf;
}

/* Polarized variants: components 0..j's factors, each weighted by its
 * share of mix_eval's value times `scale` (phase.h phase_mix_add), into
 * acc; the order and arithmetic of blendphase's, so that the same layers
 * as piecewise + blendphase give the same matrices. */
static void mix_polarization(const mol_atmo *m, int k, size_t j, const medium_interaction *mi, vec3 wo,
                             double scale, mueller acc[3]) {
  double pdf;
  if (j == 0) {
    phase_mix_add(m->rayleigh, mi, wo, scale * m->rayleigh->ops->eval_pdf(m->rayleigh, mi, wo, &pdf), acc);
    return;
  }
  double w = ma_weight(m, k, j - 1);
  const phase *ph = m->p[j - 1].ph;
  if (w < 1.0) mix_polarization(m, k, j - 1, mi, wo, scale * (1.0 - w), acc);
  if (w > 0.0) phase_mix_add(ph, mi, wo, scale * w * ph->ops->eval_pdf(ph, mi, wo, &pdf), acc);
}

/* The layer of mi->p: found once per scattering when bound (phase_bind). */
static int ma_phase_layer(const phase *ph, const mol_atmo *m, const medium_interaction *mi) {
  return mi->bound == ph ? (int)mi->bound_w : ma_layer_at(m, mi->p);
}

static void ma_phase_bind(const phase *ph, medium_interaction *mi) {
  mi->bound_w = ma_layer_at(((const ma_phase *)ph)->m, mi->p);
  mi->bound = ph;
}

static double ma_phase_sample(const phase *ph, const medium_interaction *mi, double u1, vec2 u2, vec3 *wo,
                              double *pdf) {
  const mol_atmo *m = ((const ma_phase *)ph)->m;
  return mix_sample(m, ma_phase_layer(ph, m, mi), m->np, mi, u1, u2, wo, pdf);
}

static double ma_phase_eval_pdf(const phase *ph, const medium_interaction *mi, vec3 wo, double *pdf) {
  const mol_atmo *m = ((const ma_phase *)ph)->m;
  return mix_eval(m, ma_phase_layer(ph, m, mi), m->np, mi, wo, pdf);
}

/* mix_eval's value with each channel's weights (a spectral bundle's, at
 * the calling thread's page): the components evaluated once, then mixed
 * per channel in mix_eval's order, component j onto 0..j-1. */
static color ma_phase_eval_channels(const phase *ph, const medium_interaction *mi, vec3 wo) {
  const mol_atmo *m = ((const ma_phase *)ph)->m;
  int k = ma_phase_layer(ph, m, mi);
  size_t np = m->np;
  const double *wc = rsw_page ? m->wcp + (size_t)(rsw_page - 1) * 3 * m->n * (np ? np : 1) : m->wc;
  double pdf;
  color v = col1(m->rayleigh->ops->eval_pdf(m->rayleigh, mi, wo, &pdf));
  for (size_t j = 1; j <= np; j++) {
    const phase *pj = m->p[j - 1].ph;
    double vj = pj->ops->eval_pdf(pj, mi, wo, &pdf);
    for (int c = 0; c < 3; c++) {
      double w = clamp01(wc[((size_t)k * np + j - 1) * 3 + (size_t)c]);
      v.c[c] = (1.0 - w) * v.c[c] + w * vj;
    }
  }
  return v;
}

/* ma_phase_eval_channels at pages p0..pages-1: the components' values
 * once, each page's weights mixed in the same order. */
static void ma_phase_eval_pages(const phase *ph, const medium_interaction *mi, vec3 wo, int p0, int pages,
                                color *out) {
  const mol_atmo *m = ((const ma_phase *)ph)->m;
  int k = ma_phase_layer(ph, m, mi);
  size_t np = m->np, stride = 3 * m->n * (np ? np : 1);
  double pdf, v0 = m->rayleigh->ops->eval_pdf(m->rayleigh, mi, wo, &pdf);
  for (int p = p0; p < pages; p++) out[p] = col1(v0);
  for (size_t j = 1; j <= np; j++) {
    const phase *pj = m->p[j - 1].ph;
    double vj = pj->ops->eval_pdf(pj, mi, wo, &pdf);
    for (int p = p0; p < pages; p++) {
      const double *wc = p ? m->wcp + (size_t)(p - 1) * stride : m->wc;
      for (int c = 0; c < 3; c++) {
        double w = clamp01(wc[((size_t)k * np + j - 1) * 3 + (size_t)c]);
        out[p].c[c] = (1.0 - w) * out[p].c[c] + w * vj;
      }
    }
  }
}

/* The mixture's factors (polarized variants carry no spectral bundle:
 * the weights are the layer's, m->w). */
static void ma_phase_polarization(const phase *ph, const medium_interaction *mi, vec3 wo, mueller P[3]) {
  const mol_atmo *m = ((const ma_phase *)ph)->m;
  mueller acc[3] = {mu_zero(), mu_zero(), mu_zero()};
  mix_polarization(m, ma_phase_layer(ph, m, mi), m->np, mi, wo, 1.0, acc);
  for (int c = 0; c < 3; c++) P[c] = mu_normalized(acc[c]);
}

static const phase_ops ma_phase_ops = {.sample = ma_phase_sample,
                                       .eval_pdf = ma_phase_eval_pdf,
                                       .bind = ma_phase_bind,
                                       .eval_channels = ma_phase_eval_channels,
                                       .eval_pages = ma_phase_eval_pages,
                                       .polarization = ma_phase_polarization};

/* ---- life cycle -------------------------------------------------------------- */

static rsw_status ma_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  mol_atmo *m = (mol_atmo *)o;
  double wl = rc->wavelength > 0 ? rc->wavelength : 550.0;
  int bundle = rc->bundle > 1 ? rc->bundle : 0;
  bool same = !m->dirty && wl == m->wl && bundle == m->bundle &&
              (!bundle || memcmp(m->wl3, rc->wl, sizeof m->wl3) == 0);
  /* (a bundle's pages: every wavelength compared, wl3 holds them all) */
  if (same && (!m->sigma_a || m->sigma_a->revision == m->sa_revision)) return RSW_OK;
  return ma_refresh(m, rc, err);
}

static void ma_parameters_changed(object *o) {
  mol_atmo *m = (mol_atmo *)o;
  m->dirty = true;
  if (m->wl > 0) { /* (errors come back at the next prepare) */
    render_ctx rc = {.variant = VARIANT_MONO, .wavelength = m->wl, .bundle = m->bundle};
    memcpy(rc.wl, m->wl3, sizeof rc.wl);
    ma_refresh(m, &rc, NULL);
  }
}

static void ma_destroy(object *o) {
  mol_atmo *m = (mol_atmo *)o;
  media_layers_free(&m->lm.L);
  for (int p = 0; m->lm.Lp && p < m->pages_alloc; p++) media_layers_free(&m->lm.Lp[p]);
  free(m->lm.Lp);
  free(m->wcp);
  free(m->z);
  free(m->n_air);
  free(m->n_o3);
  free(m->t);
  free(m->sig_t);
  free(m->alb);
  free(m->w);
  free(m->wc);
  free(m->s_comp);
  if (m->frac)
    for (size_t j = 0; j < m->np; j++) free(m->frac[j]);
  free(m->frac);
  free(m->p);
  free(m);
}

/* A nested property group (thermoprops, a particle layer, a distribution):
 * every property read (else an error naming the first unused one). */
static rsw_status group_done(loader *ld, node *g, const char *what) {
  for (size_t i = 0; i < g->n_props; i++)
    if (!g->props[i].used)
      return ld_fail(ld, g, g->props[i].name, RSW_ERR_UNUSED_PROPERTY, "%s has no property '%s'", what,
                     g->props[i].name);
  return RSW_OK;
}

static rsw_status read_spec(loader *ld, node *g, const char *name, double def, double lo, double hi,
                            ma_spec *out, bool *present) {
  prop *p = node_find(g, name);
  out->spec = NULL;
  out->value = def;
  if (present) *present = p != NULL;
  if (!p) return RSW_OK;
  if (p->kind == PROP_SPECTRUM && p->spec.kind != SPEC_RGB) {
    p->used = true;
    const spectrum *s = &p->spec;
    if (s->kind == SPEC_UNIFORM) {
      out->value = s->value;
      if (!(s->value >= lo && s->value <= hi))
        return ld_fail(ld, g, name, RSW_ERR_RANGE, "%s must lie in [%g, %g]", name, lo, hi);
      return RSW_OK;
    }
    for (size_t i = 0; i < s->n; i++)
      if (!(s->val[i] >= lo && s->val[i] <= hi))
        return ld_fail(ld, g, name, RSW_ERR_RANGE, "%s: the value at %g nm (%g) is outside [%g, %g]", name,
                       s->wl[i], s->val[i], lo, hi);
    out->spec = s;
    return RSW_OK;
  }
  return ld_float_range(ld, g, name, def, lo, hi, &out->value);
}

static rsw_status numbers_at_levels(loader *ld, node *g, const char *name, size_t n, double lo,
                                    double **out) {
  size_t cnt = 0;
  bool present = false;
  rsw_status st = volume_read_numbers(ld, g, name, out, &cnt, &present);
  if (st) return st;
  if (!present) return ld_fail(ld, g, NULL, RSW_ERR_MISSING, "an inline profile needs '%s'", name);
  if (cnt != n)
    return ld_fail(ld, g, name, RSW_ERR_INVALID, "'%s' has %zu values, one per level of z (%zu)", name, cnt,
                   n);
  for (size_t i = 0; i < n; i++)
    if (!(out[0][i] >= lo))
      return ld_fail(ld, g, name, RSW_ERR_RANGE, "%s[%zu] = %g must be >= %g", name, i, out[0][i], lo);
  return RSW_OK;
}

static const char AFGL_LIST[] =
    "afgl_1986-us_standard, afgl_1986-tropical, afgl_1986-midlatitude_summer, afgl_1986-midlatitude_winter, "
    "afgl_1986-subarctic_summer, afgl_1986-subarctic_winter";

static rsw_status read_thermoprops(loader *ld, node *n, mol_atmo *m) {
  prop *tp = node_find(n, "thermoprops");
  if (!tp || tp->kind != PROP_NODE)
    return ld_fail(
        ld, n, tp ? "thermoprops" : NULL, tp ? RSW_ERR_TYPE : RSW_ERR_MISSING,
        "molecular_atmosphere: needs \"thermoprops\": {\"identifier\": \"afgl_1986-us_standard\", \"z\": "
        "[levels in metres from 0]} or an inline profile (z, p, t, n_air, n_o3)");
  tp->used = true;
  node *g = tp->child;
  double *z = NULL;
  size_t nz = 0;
  bool present = false;
  rsw_status st = volume_read_numbers(ld, g, "z", &z, &nz, &present);
  if (st) return st;
  if (present && (ld_has(g, "toa_altitude") || ld_has(g, "n_layers"))) {
    free(z);
    return ld_fail(ld, g, "toa_altitude", RSW_ERR_INVALID, "give z, or toa_altitude and n_layers, not both");
  }
  if (!present && ld_has(g, "toa_altitude")) { /* N equal layers: z_k = toa k / N */
    double toa;
    long long nl;
    st = ld_float_range(ld, g, "toa_altitude", 120e3, 1e-300, INFINITY, &toa);
    if (!st) st = ld_int(ld, g, "n_layers", 120, 1, 1 << 24, &nl);
    if (st) return st;
    nz = (size_t)nl + 1;
    z = malloc(nz * sizeof *z);
    if (!z) return ld_fail(ld, g, NULL, RSW_ERR_NOMEM, "molecular_atmosphere: out of memory");
    for (size_t k = 0; k < nz; k++) z[k] = toa * (double)k / (double)nl;
    present = true;
  }
  if (!present)
    return ld_fail(ld, g, NULL, RSW_ERR_MISSING,
                   "needs 'z', the levels in metres (or toa_altitude and n_layers)");
  m->z = z;
  if (nz < 2) return ld_fail(ld, g, "z", RSW_ERR_INVALID, "z needs at least 2 levels (1 layer)");
  if (z[0] != 0.0) return ld_fail(ld, g, "z", RSW_ERR_INVALID, "z must start at 0 (got z[0] = %g)", z[0]);
  for (size_t i = 1; i < nz; i++)
    if (!(z[i] > z[i - 1]))
      return ld_fail(ld, g, "z", RSW_ERR_INVALID, "z must increase strictly (z[%zu] = %g <= z[%zu] = %g)", i,
                     z[i], i - 1, z[i - 1]);
  if (nz - 1 > (1u << 24)) return ld_fail(ld, g, "z", RSW_ERR_LIMIT, "more than 2^24 layers");
  uint32_t nl = (uint32_t)(nz - 1);
  m->n = nl;
  m->n_air = calloc(nl, sizeof(double));
  m->n_o3 = calloc(nl, sizeof(double));
  m->t = calloc(nl, sizeof(double));
  if (!m->n_air || !m->n_o3 || !m->t)
    return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "molecular_atmosphere: out of memory");
  const char *ident = NULL;
  st = ld_string(ld, g, "identifier", NULL, &ident);
  if (st) return st;
  if (ident) {
    const atmo_afgl *a = NULL;
    for (int i = 0; i < ATMO_AFGL_COUNT; i++)
      if (strcmp(atmo_afgl_1986[i].identifier, ident) == 0) a = &atmo_afgl_1986[i];
    if (!a)
      return ld_fail(ld, g, "identifier", RSW_ERR_INVALID, "unknown identifier '%s' (one of: %s)", ident,
                     AFGL_LIST);
    double ztop = a->z[a->n - 1] * 1e3;
    if (z[nl] > ztop)
      return ld_fail(ld, g, "z", RSW_ERR_RANGE,
                     "the top level %g m is above the AFGL 1986 tables' top "
                     "(%g m)",
                     z[nl], ztop);
    double zt[64], air[64], o3[64], t[64];
    for (int i = 0; i < a->n && i < 64; i++)
      zt[i] = a->z[i] * 1e3, air[i] = a->air[i] * 1e6, o3[i] = a->o3[i] * 1e6, t[i] = a->t[i];
    for (uint32_t k = 0; k < nl; k++) {
      m->n_air[k] = loglin_average(zt, air, a->n, z[k], z[k + 1]);
      m->n_o3[k] = loglin_average(zt, o3, a->n, z[k], z[k + 1]);
      m->t[k] = lin_at(zt, t, a->n, 0.5 * (z[k] + z[k + 1]));
    }
  } else {
    double *p = NULL, *t = NULL, *air = NULL, *o3 = NULL;
    st = numbers_at_levels(ld, g, "p", nz, 0.0, &p);
    if (!st) st = numbers_at_levels(ld, g, "t", nz, 1e-300, &t);
    if (!st) st = numbers_at_levels(ld, g, "n_air", nz, 0.0, &air);
    if (!st) st = numbers_at_levels(ld, g, "n_o3", nz, 0.0, &o3);
    if (!st)
      for (uint32_t k = 0; k < nl; k++) {
        m->n_air[k] = loglin_average(z, air, (int)nz, z[k], z[k + 1]);
        m->n_o3[k] = loglin_average(z, o3, (int)nz, z[k], z[k + 1]);
        m->t[k] = 0.5 * (t[k] + t[k + 1]);
      }
    free(p);
    free(t);
    free(air);
    free(o3);
    if (st) return st;
  }
  return group_done(ld, g, "thermoprops");
}

static rsw_status read_particle(loader *ld, mol_atmo *m, node *g, ma_particle *p) {
  rsw_status st = ld_float_range(ld, g, "bottom", 0.0, 0.0, INFINITY, &p->bottom);
  if (!st) st = ld_float_range(ld, g, "top", 1000.0, 0.0, INFINITY, &p->top);
  if (st) return st;
  if (!(p->bottom < p->top))
    return ld_fail(ld, g, "top", RSW_ERR_INVALID, "bottom (%g m) must lie below top (%g m)", p->bottom,
                   p->top);
  if (p->top > m->z[m->n])
    return ld_fail(ld, g, "top", RSW_ERR_RANGE, "top (%g m) is above the atmosphere's top level (%g m)",
                   p->top, m->z[m->n]);
  st = ld_float_range(ld, g, "tau_ref", 0.2, 0.0, INFINITY, &p->tau_ref);
  if (!st) st = ld_float_range(ld, g, "w_ref", 550.0, 1e-300, INFINITY, &p->w_ref);
  if (st) return st;
  /* distribution: a name, or {"type": name, parameters} */
  p->dist = DIST_UNIFORM;
  p->rate = 5.0, p->mean = 0.5, p->std = 1.0 / 6.0; /* Eradiate's defaults */
  prop *dp = node_find(g, "distribution");
  if (dp) {
    const char *name = NULL;
    node *dg = NULL;
    if (dp->kind == PROP_STRING) {
      st = ld_string(ld, g, "distribution", "uniform", &name);
      if (st) return st;
    } else if (dp->kind == PROP_NODE) {
      dp->used = true;
      dg = dp->child;
      name = dg->type;
    } else {
      return ld_fail(ld, g, "distribution", RSW_ERR_TYPE,
                     "distribution is \"uniform\", "
                     "\"exponential\" or \"gaussian\", or {\"type\": one of them, parameters}");
    }
    if (strcmp(name, "uniform") == 0) {
      p->dist = DIST_UNIFORM;
    } else if (strcmp(name, "exponential") == 0) {
      p->dist = DIST_EXPONENTIAL;
      if (dg) {
        bool has_h = ld_has(dg, "scale_height");
        if (has_h && ld_has(dg, "rate"))
          return ld_fail(ld, dg, "rate", RSW_ERR_INVALID, "exponential: give rate or scale_height, not both");
        if (has_h) {
          double h;
          st = ld_float_range(ld, dg, "scale_height", 1.0, 1e-300, INFINITY, &h);
          if (st) return st;
          p->rate = (p->top - p->bottom) / h;
        } else {
          st = ld_float_range(ld, dg, "rate", 5.0, 0.0, 1e6, &p->rate);
          if (st) return st;
        }
      }
    } else if (strcmp(name, "gaussian") == 0) {
      p->dist = DIST_GAUSSIAN;
      if (dg) {
        st = ld_float_range(ld, dg, "mean", 0.5, -1e6, 1e6, &p->mean);
        if (!st) st = ld_float_range(ld, dg, "std", 1.0 / 6.0, 1e-6, 1e6, &p->std);
        if (st) return st;
        double s2 = p->std * sqrt(2.0);
        if (!(erf((1.0 - p->mean) / s2) - erf(-p->mean / s2) > 1e-12))
          return ld_fail(
              ld, dg, "mean", RSW_ERR_INVALID,
              "gaussian: mean %g and std %g (in the layer's normalised altitude, 0 at bottom, 1 at "
              "top) put no mass inside the layer",
              p->mean, p->std);
      }
    } else {
      return ld_fail(ld, dg ? dg : g, dg ? "type" : "distribution", RSW_ERR_INVALID,
                     "unknown distribution '%s' (uniform, exponential or gaussian)", name);
    }
    if (dg) {
      st = group_done(ld, dg, "a particle distribution");
      if (st) return st;
    }
  }
  bool has_ext = false;
  p->has_angstrom = ld_has(g, "angstrom");
  st = read_spec(ld, g, "extinction", 1.0, 0.0, INFINITY, &p->ext, &has_ext);
  if (st) return st;
  if (has_ext && p->has_angstrom)
    return ld_fail(ld, g, "angstrom", RSW_ERR_INVALID,
                   "give an extinction spectrum or an "
                   "angstrom exponent, not both");
  if (!has_ext) {
    p->has_angstrom = true;
    st = ld_float_range(ld, g, "angstrom", 0.0, -10.0, 10.0, &p->angstrom);
    if (st) return st;
  }
  st = read_spec(ld, g, "albedo", 1.0, 0.0, 1.0, &p->ssa, NULL);
  if (st) return st;
  object *ph = NULL;
  st = ld_child(ld, g, "phase", CLS_PHASE, &ph);
  if (st) return st;
  if (!ph) {
    st = ld_create_default(ld, "hg", CLS_PHASE, NULL, &ph);
    if (st) return st;
  }
  p->ph = (phase *)ph;
  return group_done(ld, g, "a particle layer");
}

static rsw_status molecular_atmosphere_create(loader *ld, node *n, object **out) {
  if (ld->variant != VARIANT_MONO)
    return ld_fail(ld, n, NULL, RSW_ERR_INVALID,
                   "molecular_atmosphere is spectral: it needs the mono variant");
  mol_atmo *m = calloc(1, sizeof *m);
  if (!m) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "molecular_atmosphere: out of memory");
  m->lm.base.ops = &layered_medium_ops;
  m->mix.base.ops = &ma_phase_ops;
  m->mix.base.base.id = "phase_function";
  m->mix.m = m;
  m->lm.base.phase = &m->mix.base;
  rsw_status st = ld_float_range(ld, n, "scale", 1.0, 0.0, INFINITY, &m->lm.base.scale);
  if (!st) st = ld_bool(ld, n, "sample_emitters", true, &m->lm.base.sample_emitters);
  if (!st) st = ld_bool(ld, n, "has_absorption", true, &m->has_absorption);
  if (!st) st = ld_bool(ld, n, "has_scattering", true, &m->has_scattering);
  if (!st) st = ld_float_range(ld, n, "width", 1e9, 1e-300, 1e15, &m->width);
  if (!st) st = read_thermoprops(ld, n, m);
  uint32_t nl = m->n;
  if (!st) {
    object *ray = NULL;
    st = ld_create_default(ld, "rayleigh", CLS_PHASE, NULL, &ray);
    m->rayleigh = (phase *)ray;
  }
  if (!st && ld_has(n, "sigma_a")) {
    st = ld_volume(ld, n, "sigma_a", 0.0, 0.0, INFINITY, &m->sigma_a);
    if (!st) {
      const volume *v = m->sigma_a;
      bool one = v->res[0] == 1 && v->res[1] == 1 && v->res[2] == 1;
      if (!one && !(v->res[0] == 1 && v->res[1] == 1 && v->res[2] == nl))
        st = ld_fail(
            ld, n, "sigma_a", RSW_ERR_INVALID,
            "molecular_atmosphere: sigma_a must be constant or a [1, 1, %u] grid (one value per layer), got "
            "%ux%ux%u",
            nl, v->res[0], v->res[1], v->res[2]);
    }
  }
  /* particle layers: every property named particle_layers, in order */
  for (size_t i = 0; !st && i < n->n_props; i++)
    if (strcmp(n->props[i].name, "particle_layers") == 0) m->np++;
  if (!st && m->np) {
    m->p = calloc(m->np, sizeof *m->p);
    m->frac = calloc(m->np, sizeof *m->frac);
    if (!m->p || !m->frac) st = ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "molecular_atmosphere: out of memory");
    for (size_t i = 0, j = 0; !st && i < n->n_props; i++) {
      prop *pp = &n->props[i];
      if (strcmp(pp->name, "particle_layers") != 0) continue;
      if (pp->kind != PROP_NODE) {
        st =
            ld_fail(ld, n, "particle_layers", RSW_ERR_TYPE,
                    "molecular_atmosphere: particle_layers is a list of objects (bottom, top, tau_ref, ...)");
        break;
      }
      pp->used = true;
      snprintf(m->p[j].key, sizeof m->p[j].key, "particle_layer_%zu", j);
      m->frac[j] = calloc(nl, sizeof(double));
      if (!m->frac[j]) st = ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "molecular_atmosphere: out of memory");
      if (!st) st = read_particle(ld, m, pp->child, &m->p[j]);
      j++;
    }
  }
  if (!st) {
    m->sig_t = calloc(nl, sizeof(double));
    m->alb = calloc(nl, sizeof(double));
    m->w = calloc((size_t)nl * (m->np ? m->np : 1), sizeof(double));
    m->wc = calloc(3 * (size_t)nl * (m->np ? m->np : 1), sizeof(double));
    m->s_comp = calloc(1 + 3 * m->np, sizeof(double));
    if (!m->sig_t || !m->alb || !m->w || !m->wc || !m->s_comp || !media_layers_alloc(&m->lm.L, nl))
      st = ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "molecular_atmosphere: out of memory");
  }
  if (!st) {
    /* The box: [{"scale": [W, W, top]}, {"translate": [-W/2, -W/2, 0]}], composed as the JSON reader composes
     * a list of operations (so a gridvolume given that list has the same to_world, bit for bit). */
    double top = m->z[nl], w = m->width;
    xform id = xf_identity(), sc = xf_scale(v3(w, w, top)), tr = xf_translate(v3(-w / 2, -w / 2, 0.0));
    xform a = xf_mul(&sc, &id);
    m->box = xf_mul(&tr, &a);
    m->lm.L.to_world = &m->box;
    /* Equal layers (z_k = k top / N to rounding) take the O(1) layer lookup, the same as piecewise. */
    bool uniform = true;
    for (uint32_t k = 0; k <= nl && uniform; k++) uniform = fabs(m->z[k] - top * k / nl) <= 1e-12 * top;
    m->lm.L.uniform = uniform;
    if (!uniform)
      for (uint32_t k = 0; k <= nl; k++) m->lm.L.lay[k].z = k == nl ? 1.0 : m->z[k] / top;
    m->lm.L.nc = 1;
    m->dirty = true;
  }
  if (st) {
    ma_destroy(&m->lm.base.base);
    return st;
  }
  *out = &m->lm.base.base;
  return RSW_OK;
}

/* Keys: scale, has_absorption/has_scattering (read-only), sigma_a, and per
 * particle layer particle_layer_<i>.{tau_ref, w_ref, angstrom, albedo (a
 * constant), bottom, top, phase_function}. All spectral-class: the layers
 * are recomputed at the current wavelength. */
static void ma_traverse(object *o, param_visitor *v) {
  mol_atmo *m = (mol_atmo *)o;
  pv_float(v, "scale", &m->lm.base.scale, UPDATE_SPECTRAL, 0.0, INFINITY);
  pv_bool_ro(v, "has_absorption", m->has_absorption);
  pv_bool_ro(v, "has_scattering", m->has_scattering);
  if (m->sigma_a) pv_object(v, "sigma_a", &m->sigma_a->base, 0.0, INFINITY);
  for (size_t j = 0; j < m->np; j++) {
    ma_particle *p = &m->p[j];
    char key[96];
    snprintf(key, sizeof key, "%s.tau_ref", p->key);
    pv_float(v, key, &p->tau_ref, UPDATE_SPECTRAL, 0.0, INFINITY);
    snprintf(key, sizeof key, "%s.w_ref", p->key);
    pv_float(v, key, &p->w_ref, UPDATE_SPECTRAL, 1e-300, INFINITY);
    if (p->has_angstrom) {
      snprintf(key, sizeof key, "%s.angstrom", p->key);
      pv_float(v, key, &p->angstrom, UPDATE_SPECTRAL, -10.0, 10.0);
    }
    if (!p->ssa.spec) {
      snprintf(key, sizeof key, "%s.albedo", p->key);
      pv_float(v, key, &p->ssa.value, UPDATE_SPECTRAL, 0.0, 1.0);
    }
    snprintf(key, sizeof key, "%s.phase_function", p->key);
    pv_object(v, key, &p->ph->base, NAN, NAN);
  }
}

/* Whether a wavelength sweep changes the medium (the no-op sweep warning,
 * scene_wavelength_dependent): Rayleigh and ozone always do; particles do
 * when their extinction follows an Angstrom law or a spectrum, or their
 * albedo is a spectrum. (A user sigma_a volume answers for itself.) */
static bool ma_spectral(const object *o) {
  const mol_atmo *m = (const mol_atmo *)o;
  if (m->has_scattering || m->has_absorption) return true;
  for (size_t i = 0; i < m->np; i++) {
    const ma_particle *p = &m->p[i];
    if ((p->has_angstrom && p->angstrom != 0.0) || p->ext.spec || p->ssa.spec) return true;
  }
  return false;
}

DEFINE_PLUGIN(molecular_atmosphere, CLS_MEDIUM, .destroy = ma_destroy, .prepare = ma_prepare,
              .ops = &layered_medium_ops, .traverse = ma_traverse,
              .parameters_changed = ma_parameters_changed, .spectral = ma_spectral,
              .pages = plugin_pages_any); /* (ma_refresh: a page's layers and weights each) */

/* ---- what tests and benches read --------------------------------------------- */

bool molecular_atmosphere_layers(const medium *md, double wavelength, const double **z, uint32_t *n,
                                 const double **sigma_t, const double **albedo, const double **weight,
                                 size_t *n_particles) {
  if (!md || md->base.plugin != &plugin_molecular_atmosphere) return false;
  mol_atmo *m = (mol_atmo *)md;
  if (m->dirty || m->wl != wavelength || m->bundle ||
      (m->sigma_a && m->sigma_a->revision != m->sa_revision)) {
    render_ctx rc = {.variant = VARIANT_MONO, .wavelength = wavelength};
    if (ma_refresh(m, &rc, NULL)) return false;
  }
  *z = m->z;
  *n = m->n;
  *sigma_t = m->sig_t;
  *albedo = m->alb;
  *weight = m->w;
  *n_particles = m->np;
  return true;
}

bool molecular_atmosphere_columns(const medium *md, double *air, double *o3) {
  if (!md || md->base.plugin != &plugin_molecular_atmosphere) return false;
  const mol_atmo *m = (const mol_atmo *)md;
  double a = 0, b = 0;
  for (uint32_t k = 0; k < m->n; k++) {
    double dz = m->z[k + 1] - m->z[k];
    a += m->n_air[k] * dz;
    b += m->n_o3[k] * dz;
  }
  *air = a;
  *o3 = b;
  return true;
}
