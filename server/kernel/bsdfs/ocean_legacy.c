/* `ocean_legacy`: the ocean surface of the 6S code as Eradiate carries it
 * (eradiate/mitsuba3 src/eradiate_plugins/bsdfs/ocean_legacy.cpp and
 * include/mitsuba/eradiate/oceanprops.h), one-sided, unpolarized.
 *
 *   eval = [W + (1 - W) U + (1 - c) R_glint] cos(theta_o) / pi
 *
 * c: whitecap coverage, Monahan and O'Muircheartaigh (1980):
 *    c = clamp(2.95e-6 ws^3.52, 0, 1); W = c R_eff(lambda), R_eff from
 *    Whitlock et al. (1982) x Koepke's 0.4 (ocean_data.c).
 * R_glint = pi D G F / (4 cos(theta_i) cos(theta_o)): Cox and Munk (1954)
 *    slopes, sigma_c^2 = 0.003 + 0.00192 ws (crosswind),
 *    sigma_u^2 = 0.00316 ws (upwind); D is the anisotropic Beckmann
 *    distribution with alpha = sqrt(2) sigma, rotated to the wind, times
 *    the Gram-Charlier factor
 *      1 - c21/2 (xe^2 - 1) xn - c03/6 (xn^2 - 3) xn + c40/24 (xe^4 - 6 xe^2 + 3)
 *        + c04/24 (xn^4 - 6 xn^2 + 3) + c22/4 (xe^2 - 1)(xn^2 - 1),
 *    xn, xe the upwind / crosswind slopes over sigma_u, sigma_c,
 *    c21 = 0.01 - 0.0086 ws, c03 = 0.04 - 0.033 ws, c40 = 0.40,
 *    c22 = 0.12, c04 = 0.23; G (when `shadowing`) the height-correlated
 *    Smith term 1 / (1 + Lambda(wi) + Lambda(wo)) with Beckmann's exact
 *    Lambda; F the 6S Fresnel reflectance (ocean_fresnel_6s) of water,
 *    n = Hale and Querry (1973) + 0.00017492711 (0.03 + 1.805 chlorinity)
 *    (Friedman 1969, Sverdrup 1942).
 * U (400-700 nm only, else 0): underlight,
 *    U = r_omega t_u t_d / ((n_re^2 + n_im^2)(1 - 0.485 r_omega)),
 *    r_omega from Morel (1988) by 6S's fixed-point iteration, t_d and t_u
 *    the downwelling / upwelling transmittances 1 - (glint albedo),
 *    tabulated on 64 x 64 (zenith, azimuth from the wind) by Gauss-Legendre
 *    quadrature of the glint (Eradiate's scheme; see ocean_tables for the
 *    one departure).
 * Wind direction: degrees, North Left as in 6SV; phi_w = 90 - wd in the
 * local frame. Sampling (Eradiate's): the diffuse lobe (cosine) with
 * probability proportional to W + t_d(wi) (1 - W), the glint (Beckmann
 * visible normals, reflected) proportional to 1 - c; pdf their mixture,
 * weight eval / pdf.
 * docs/kernel-conventions.md#ocean_legacy. */
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "../core/isa.h"
#include "../scene/loader.h"
#include "../scene/params.h"
#include "../scene/plugin_def.h"
#include "../simd/simd.h"
#include "eo_surfaces.h"
#include "fresnel_pol.h"
#include "microfacet.h"
#include "ocean_data.h"
#if RSW_SIMD_X86
#include <immintrin.h>
#endif

/* Rotation of v into the wind frame (x upwind). */
static vec3 to_wind(double phi_w, vec3 v) {
  double c = cos(phi_w), s = sin(phi_w);
  return v3(c * v.x + s * v.y, -s * v.x + c * v.y, v.z);
}
static vec3 from_wind(double phi_w, vec3 v) {
  double c = cos(phi_w), s = sin(phi_w);
  return v3(c * v.x - s * v.y, s * v.x + c * v.y, v.z);
}

static mf_distr ocean_distr(const ocean_bsdf *o) {
  return mf_make(MF_BECKMANN, sqrt(2.0) * o->sigma_u, sqrt(2.0) * o->sigma_c, true);
}

double ocean_fresnel_6s(double n_re, double n_im, double cos_chi, double sin_chi) {
  double nr2 = n_re * n_re, ni2 = n_im * n_im;
  double s = nr2 - ni2 - sin_chi * sin_chi;
  double a1 = fabs(s), a2 = sqrt(s * s + 4.0 * nr2 * ni2);
  double u = sqrt(0.5 * fabs(a1 + a2)), v = sqrt(0.5 * fabs(a2 - a1));
  double b1 = (nr2 - ni2) * cos_chi, b2 = 2.0 * n_re * n_im * cos_chi;
  double rr = ((cos_chi - u) * (cos_chi - u) + v * v) / ((cos_chi + u) * (cos_chi + u) + v * v);
  double rl = ((b1 - u) * (b1 - u) + (b2 + v) * (b2 + v)) / ((b1 + u) * (b1 + u) + (b2 - v) * (b2 - v));
  return 0.5 * (rr + rl);
}

/* Gram-Charlier factor for the wind-frame normal mp (normalized). */
static double gram_charlier(double ws, double sigma_u, double sigma_c, vec3 mp) {
  const double c40 = 0.40, c22 = 0.12, c04 = 0.23;
  double c21 = 0.01 - 0.0086 * ws, c03 = 0.04 - 0.033 * ws;
  double xn = mp.x / (sigma_u * mp.z), xe = mp.y / (sigma_c * mp.z);
  double xe2 = xe * xe, xn2 = xn * xn;
  return 1.0 - c21 / 2.0 * (xe2 - 1.0) * xn - c03 / 6.0 * (xn2 - 3.0) * xn +
         c40 / 24.0 * (xe2 * xe2 - 6.0 * xe2 + 3.0) + c04 / 24.0 * (xn2 * xn2 - 6.0 * xn2 + 3.0) +
         c22 / 4.0 * (xe2 - 1.0) * (xn2 - 1.0);
}

double ocean_gram_charlier(const ocean_bsdf *o, vec3 m) {
  return gram_charlier(o->wind_speed, o->sigma_u, o->sigma_c, v3_norm(to_wind(o->phi_w, m)));
}

/* Beckmann's exact Lambda for the anisotropic distribution (wind frame). */
static double beckmann_lambda(double au, double av, vec3 v) {
  double r = sqrt(au * au * v.x * v.x + av * av * v.y * v.y);
  if (!(r > 0.0) || !(v.z > 0.0)) return 0.0;
  double a = v.z / r;
  return 0.5 * (erf(a) - 1.0) + exp(-a * a) / (2.0 * a * sqrt(RSW_PI));
}

static ocean_wl fixed_wl(const ocean_bsdf *o) {
  bool t = ocean_tables_ready(o);
  return (ocean_wl){o->wavelength,        o->n_re,           o->n_im, o->r_omega, o->whitecap,
                    t ? o->t_down : NULL, t ? o->t_up : NULL};
}

/* Gauss-Legendre nodes and weights on [-1, 1] (Newton on P_n). */
static void gauss_legendre(int n, double *x, double *w) {
  for (int i = 0; i < n; i++) {
    double z = cos(RSW_PI * (i + 0.75) / (n + 0.5)), pp = 1.0;
    for (int it = 0; it < 100; it++) {
      double p1 = 1.0, p2 = 0.0;
      for (int j = 1; j <= n; j++) {
        double p3 = p2;
        p2 = p1;
        p1 = ((2.0 * j - 1.0) * z * p2 - (j - 1.0) * p3) / j;
      }
      pp = n * (z * p1 - p2) / (z * z - 1.0);
      double z1 = z;
      z = z1 - p1 / pp;
      if (fabs(z - z1) < 1e-15) break;
    }
    x[i] = z;
    w[i] = 2.0 / ((1.0 - z * z) * pp * pp);
  }
}

/* Transmittance 1 - (glint albedo) for incidence theta with the wind at
 * azimuth phi from the incidence plane (Eradiate's eval_ocean_transmittance:
 * Cox-Munk-Gram-Charlier D / m_z^4, no shadowing, 6S Fresnel, cosines
 * clamped to 1e-6, quadrature over the hemisphere). Upwelling: theta
 * refracted and the index inverted. */
enum {
  OCEAN_NQ = 32
};

/* The quadrature over the hemisphere: nq x nq Gauss-Legendre points,
 * zenith in [0, pi/2], azimuth in [0, 2 pi], their directions (x, y, z),
 * weights w and the weights' sum (made once per table build; the sums in
 * the order transmittance() takes them); x, y, z and w hold nq^2 each. */
typedef struct hemi_quad {
  int n;
  double *x, *y, *z, *w, sum;
} hemi_quad;

static void hemi_quad_make(int nq, hemi_quad *q) {
  double gx[128], gw[128];
  gauss_legendre(nq, gx, gw);
  q->n = nq * nq;
  q->sum = 0.0;
  for (int a = 0; a < nq; a++) {
    double th = (gx[a] + 1.0) * RSW_PI / 4.0, wth = gw[a] * RSW_PI / 4.0;
    double st = sin(th), ct = cos(th);
    for (int b = 0; b < nq; b++) {
      double ph = (gx[b] + 1.0) * RSW_PI, wph = gw[b] * RSW_PI;
      int k = a * nq + b;
      q->w[k] = ct * st * wth * wph;
      q->x[k] = st * cos(ph), q->y[k] = st * sin(ph), q->z[k] = ct;
      q->sum += q->w[k];
    }
  }
}

/* 1 - (glint albedo) for nw indices n_re[w] + i n_im[w] at once into
 * t[w] (downwelling: the slopes' geometry is the same for every index;
 * upwelling takes one index, nw 1, its refraction of theta its own). */
enum {
  OCEAN_MAX_NW = 3 * RENDER_MAX_PAGES
};

/* One cell's incidence wi (clamped cosine ci), its wind rotation (c, s),
 * the slopes and the nw indices nr + i ni. */
typedef struct glint_cell {
  vec3 wi;
  double c, s, ci, ws, sig_u, sig_c;
  int nw;
  const double *nr, *ni;
} glint_cell;

/* The glint at quadrature points k0 .. k1 - 1, times their weights, added
 * to td[w] point by point (the scalar path; ocean_lanes.h the same on
 * lanes). */
static void glint_sums(const hemi_quad *q, const glint_cell *gc, int k0, int k1, double *td) {
  vec3 wi = gc->wi;
  double c = gc->c, s = gc->s, sig_u = gc->sig_u, sig_c = gc->sig_c, ci = gc->ci;
  for (int k = k0; k < k1; k++) {
    double gweight = q->w[k];
    vec3 wo = v3(q->x[k], q->y[k], q->z[k]);
    double co = wo.z < 1e-6 ? 1e-6 : wo.z;
    vec3 m = v3_norm(v3_add(wi, wo));
    vec3 mp = v3_norm(v3(c * m.x + s * m.y, -s * m.x + c * m.y, m.z));
    double xn = mp.x / (sig_u * mp.z), xe = mp.y / (sig_c * mp.z);
    double D = gram_charlier(gc->ws, sig_u, sig_c, mp) / (2.0 * RSW_PI * sig_u * sig_c) *
               exp(-0.5 * (xe * xe + xn * xn)) / (m.z * m.z * m.z * m.z);
    double cchi = fmin(fmax(v3_dot(wo, m), -0.999999999), 0.999999999);
    double schi = fmin(sqrt(1.0 - cchi * cchi), 0.999999999);
    bool lit = wi.z > 0.0 && wo.z > 0.0;
    for (int w = 0; w < gc->nw; w++) {
      double g = D * ocean_fresnel_6s(gc->nr[w], gc->ni[w], cchi, schi) * RSW_PI / (4.0 * ci * co);
      if (!lit) g = 1.0;
      td[w] += g * gweight;
    }
  }
}

#if RSW_SIMD_X86
#define OL_NAME(f)     OL_NAME2(f, OL_SUFFIX)
#define OL_NAME2(f, s) OL_NAME3(f, s)
#define OL_NAME3(f, s) f##_##s

#define W          2
#define OL_FN      static inline __attribute__((always_inline, target("sse2")))
#define OL_ATTR    static __attribute__((target("sse2")))
#define OL_SQRT(x) ((vd)_mm_sqrt_pd((x)))
#define OL_SUFFIX  sse2
#include "ocean_lanes.h"
#undef W
#undef OL_FN
#undef OL_ATTR
#undef OL_SQRT
#undef OL_SUFFIX

#define W          4
#define OL_FN      static inline __attribute__((always_inline, target("avx2")))
#define OL_ATTR    static __attribute__((target("avx2")))
#define OL_SQRT(x) ((vd)_mm256_sqrt_pd((x)))
#define OL_SUFFIX  avx2
#include "ocean_lanes.h"
#undef W
#undef OL_FN
#undef OL_ATTR
#undef OL_SQRT
#undef OL_SUFFIX

#define W          8
#define OL_FN      static inline __attribute__((always_inline, target("avx512f")))
#define OL_ATTR    static __attribute__((target("avx512f")))
#define OL_SQRT(x) ((vd)_mm512_sqrt_pd((x)))
#define OL_SUFFIX  avx512
#include "ocean_lanes.h"
#undef W
#undef OL_FN
#undef OL_ATTR
#undef OL_SQRT
#undef OL_SUFFIX
#endif

/* Every point's glint into td on the ISA renders use (rsw_isa_get(); the
 * generic one and the points past the last whole vector: the scalar
 * path), the same bits on each. */
static void glint_sums_isa(const hemi_quad *q, const glint_cell *gc, double *td) {
  int k = 0;
#if RSW_SIMD_X86
  switch (rsw_isa_get()) {
  case RSW_ISA_AVX512: glint_sums_avx512(q, gc, 0, k = q->n / 8 * 8, td); break;
  case RSW_ISA_AVX2: glint_sums_avx2(q, gc, 0, k = q->n / 4 * 4, td); break;
  case RSW_ISA_SSE2: glint_sums_sse2(q, gc, 0, k = q->n / 2 * 2, td); break;
  default: break;
  }
#endif
  glint_sums(q, gc, k, q->n, td);
}

static void transmittance(double theta, double phi, int nw, const double *n_re, const double *n_im, double ws,
                          double sig_u, double sig_c, bool up, const hemi_quad *q, double *t) {
  double nr[OCEAN_MAX_NW], ni[OCEAN_MAX_NW], td[OCEAN_MAX_NW];
  for (int w = 0; w < nw; w++) nr[w] = n_re[w], ni[w] = n_im[w], td[w] = 0.0;
  if (up) {
    theta = asin(sin(theta) / nr[0]);
    nr[0] = 1.0 / nr[0];
    ni[0] = 0.0;
  }
  vec3 wi = v3(sin(theta), 0.0, cos(theta));
  glint_cell gc = {.wi = wi,
                   .c = cos(phi),
                   .s = sin(phi),
                   .ci = wi.z < 1e-6 ? 1e-6 : wi.z,
                   .ws = ws,
                   .sig_u = sig_u,
                   .sig_c = sig_c,
                   .nw = nw,
                   .nr = nr,
                   .ni = ni};
  glint_sums_isa(q, &gc, td);
  for (int w = 0; w < nw; w++) {
    if (td[w] >= q->sum) td[w] = q->sum;
    t[w] = 1.0 - td[w] / q->sum;
  }
}

double ocean_transmittance(const ocean_bsdf *o, double theta, double phi, bool up, int nq) {
  hemi_quad q = {0};
  if (nq < 1 || nq > 128) return NAN;
  double *mem = malloc(4 * (size_t)nq * nq * sizeof *mem);
  if (!mem) return NAN;
  q.x = mem, q.y = mem + nq * nq, q.z = mem + 2 * nq * nq, q.w = mem + 3 * nq * nq;
  hemi_quad_make(nq, &q);
  double t;
  transmittance(theta, phi, 1, &o->n_re, &o->n_im, o->wind_speed, o->sigma_u, o->sigma_c, up, &q, &t);
  free(mem);
  return t;
}

/* The tables on Eradiate's grid: zenith linspace(0, pi/2, 64) x azimuth
 * linspace(0, 2 pi, 64), for nw indices at once (t_down[w], t_up[w]; the
 * downwelling ones share the slopes). Departure: OCEAN_NQ = 32
 * Gauss-Legendre points per dimension where Eradiate takes 64 (16 times
 * cheaper to build; tests/kernel/bsdfs/test_ocean_legacy.c bounds the
 * difference). */
typedef struct table_build {
  const ocean_bsdf *o;
  int nw;
  const double *n_re, *n_im;
  float **t_down, **t_up;
  const hemi_quad *q;
  atomic_int next; /* the next azimuth row to claim */
} table_build;

/* Row j (one azimuth, every zenith) of every table: each cell whole. */
static void build_row(const table_build *b, int j) {
  const ocean_bsdf *o = b->o;
  double phi = 2.0 * RSW_PI * j / (OCEAN_T_RES - 1);
  for (int i = 0; i < OCEAN_T_RES; i++) { /* zenith */
    double th = 0.5 * RSW_PI * i / (OCEAN_T_RES - 1), t[OCEAN_MAX_NW];
    transmittance(th, phi, b->nw, b->n_re, b->n_im, o->wind_speed, o->sigma_u, o->sigma_c, false, b->q, t);
    for (int w = 0; w < b->nw; w++) b->t_down[w][j * OCEAN_T_RES + i] = (float)t[w];
    for (int w = 0; w < b->nw; w++) {
      transmittance(th, phi, 1, &b->n_re[w], &b->n_im[w], o->wind_speed, o->sigma_u, o->sigma_c, true, b->q,
                    t);
      b->t_up[w][j * OCEAN_T_RES + i] = (float)t[0];
    }
  }
}

static void *build_rows(void *arg) {
  table_build *b = arg;
  for (int j; (j = atomic_fetch_add(&b->next, 1)) < OCEAN_T_RES;) build_row(b, j);
  return NULL;
}

/* The tables on Eradiate's grid: zenith linspace(0, pi/2, 64) x azimuth
 * linspace(0, 2 pi, 64), for nw indices at once (t_down[w], t_up[w]; the
 * downwelling ones share the slopes), on `threads` threads (the caller's
 * and threads - 1 started for the build): they claim azimuth rows in turn
 * and each computes its cells whole, so the tables are the same bits
 * whatever the threads. Departure: OCEAN_NQ = 32 Gauss-Legendre points
 * per dimension where Eradiate takes 64 (16 times cheaper to build;
 * tests/kernel/bsdfs/test_ocean_legacy.c bounds the difference). */
static void build_tables(const ocean_bsdf *o, int nw, const double *n_re, const double *n_im, float **t_down,
                         float **t_up, int threads) {
  double qx[OCEAN_NQ * OCEAN_NQ], qy[OCEAN_NQ * OCEAN_NQ], qz[OCEAN_NQ * OCEAN_NQ], qw[OCEAN_NQ * OCEAN_NQ];
  hemi_quad q = {.x = qx, .y = qy, .z = qz, .w = qw};
  hemi_quad_make(OCEAN_NQ, &q);
  table_build b = {.o = o, .nw = nw, .n_re = n_re, .n_im = n_im, .t_down = t_down, .t_up = t_up, .q = &q};
  atomic_init(&b.next, 0);
  pthread_t th[OCEAN_T_RES];
  int started = 0;
  if (threads > OCEAN_T_RES) threads = OCEAN_T_RES;
  while (started < threads - 1 && pthread_create(&th[started], NULL, build_rows, &b) == 0) started++;
  build_rows(&b); /* (rows no thread could be started for: the caller's) */
  for (int k = 0; k < started; k++) pthread_join(th[k], NULL);
}

void ocean_tables(ocean_bsdf *o) {
  float *down = o->t_down, *up = o->t_up;
  if (ocean_tables_ready(o)) return;
  build_tables(o, 1, &o->n_re, &o->n_im, &down, &up, o->threads);
  o->t_key[0] = o->n_re, o->t_key[1] = o->n_im, o->t_key[2] = o->wind_speed;
}

/* Bilinear lookup as Dr.Jit's clamped texture does it: texel k centred at
 * (k + 0.5) / 64 of [0, 1]; u from the zenith, v from the azimuth of
 * `dir` relative to the wind. */
/* A lookup's texels and weights, the same for every wavelength's table. */
typedef struct lut_at {
  int k00, k01, k10, k11;
  double fx, fy;
} lut_at;

static lut_at lut_coords(const ocean_bsdf *o, double cos_theta, vec3 dir) {
  double u = acos(fmin(fmax(cos_theta, -1.0), 1.0)) * (2.0 / RSW_PI);
  double v = (atan2(dir.y, dir.x) - o->phi_w) / (2.0 * RSW_PI);
  v -= floor(v);
  double x = u * OCEAN_T_RES - 0.5, y = v * OCEAN_T_RES - 0.5;
  x = fmin(fmax(x, 0.0), OCEAN_T_RES - 1.0), y = fmin(fmax(y, 0.0), OCEAN_T_RES - 1.0);
  int i = (int)x, j = (int)y;
  int i1 = i + 1 < OCEAN_T_RES ? i + 1 : i, j1 = j + 1 < OCEAN_T_RES ? j + 1 : j;
  return (lut_at){
      j * OCEAN_T_RES + i, j * OCEAN_T_RES + i1, j1 * OCEAN_T_RES + i, j1 * OCEAN_T_RES + i1, x - i, y - j};
}

static double lut_read(const float *t, const lut_at *c) {
  if (!t) return 1.0; /* not built: see eo_surfaces.h */
  double a = t[c->k00] * (1 - c->fx) + t[c->k01] * c->fx;
  double b = t[c->k10] * (1 - c->fx) + t[c->k11] * c->fx;
  return a * (1 - c->fy) + b * c->fy;
}

/* Morel (1988) / 6S: the ratio of upwelling to downwelling irradiance
 * below the surface, by fixed-point iteration (relative change < 1e-4;
 * at most 100 steps). */
static double r_omega(double wl, double pig) {
  double plog = log10(pig);
  double bw = ocean_molecular_scatter_6s(wl);
  double b = 0.30 * pow(pig, 0.62);
  double ratio = 0.002 + 0.02 * (0.5 - 0.25 * plog) * (550.0 / wl);
  double bb = 0.5 * bw + b * ratio;
  double k = ocean_attn_k(wl) + ocean_attn_chi(wl) * pow(pig, ocean_attn_e(wl));
  if (bb == 0.0 || k == 0.0) return 0.0;
  double u = 0.75, r = 0.33 * bb / u / k;
  for (int it = 0; it < 100; it++) {
    u = 0.9 * (1.0 - r) / (1.0 + 2.25 * r);
    double rn = 0.33 * bb / (u * k);
    if (fabs((rn - r) / rn) < 1e-4) break;
    r = rn;
  }
  return r;
}

/* The water at wavelength wl (nm), tables not built (o's wind and
 * coverage already derived). */
static ocean_wl wl_state(const ocean_bsdf *o, double wl) {
  ocean_wl w = {.wavelength = wl};
  w.n_re = ocean_ior_real(wl) + 0.00017492711 * (0.03 + 1.805 * o->chlorinity);
  w.n_im = ocean_ior_imag(wl);
  w.r_omega = r_omega(wl, o->pigmentation);
  w.whitecap = o->coverage * ocean_whitecap_reflectance(wl);
  return w;
}

void ocean_update(ocean_bsdf *o) {
  static _Atomic unsigned long gens;
  o->gen = ++gens;
  double wd = 90.0 - o->wind_direction;
  wd -= 360.0 * floor(wd / 360.0);
  o->phi_w = wd * RSW_PI / 180.0;
  o->sigma_c = sqrt(0.003 + 0.00192 * o->wind_speed);
  o->sigma_u = sqrt(0.00316 * o->wind_speed);
  o->coverage = fmin(fmax(2.95e-6 * pow(o->wind_speed, 3.52), 0.0), 1.0);
  ocean_wl w = wl_state(o, o->wavelength);
  o->n_re = w.n_re, o->n_im = w.n_im, o->r_omega = w.r_omega, o->whitecap = w.whitecap;
}

bool ocean_tables_ready(const ocean_bsdf *o) {
  return o->t_key[0] == o->n_re && o->t_key[1] == o->n_im && o->t_key[2] == o->wind_speed;
}

/* The tables are built before a render on its threads (rc->threads), not
 * at load or on each update: a build takes about a second of CPU. */
/* An ocean that follows the render: the tables of each of the n waters
 * w[k] from the cache, those missing built there at once (each in an
 * entry this prepare() has not used, taken in turn). False: out of
 * memory. */
static bool cached_tables(ocean_bsdf *o, int n, ocean_wl **w) {
  if (!o->cache && !(o->cache = calloc(OCEAN_CACHE, sizeof *o->cache))) return false;
  double nr[OCEAN_MAX_NW], ni[OCEAN_MAX_NW];
  float *down[OCEAN_MAX_NW], *up[OCEAN_MAX_NW];
  int nb = 0;
  for (int k = 0; k < n; k++) {
    ocean_table *t = NULL;
    for (int i = 0; i < OCEAN_CACHE && !t; i++) {
      ocean_table *c = &o->cache[i];
      if (c->stamp && c->key[0] == w[k]->n_re && c->key[1] == w[k]->n_im && c->key[2] == o->wind_speed) t = c;
    }
    while (!t) { /* (a render uses at most RENDER_MAX_BUNDLE < OCEAN_CACHE entries) */
      ocean_table *c = &o->cache[o->next];
      o->next = (o->next + 1) % OCEAN_CACHE;
      if (c->stamp == o->stamp) continue;
      c->key[0] = w[k]->n_re, c->key[1] = w[k]->n_im, c->key[2] = o->wind_speed;
      nr[nb] = w[k]->n_re, ni[nb] = w[k]->n_im, down[nb] = c->t_down, up[nb] = c->t_up, nb++;
      t = c;
    }
    t->stamp = o->stamp;
    w[k]->t_down = t->t_down, w[k]->t_up = t->t_up;
  }
  if (nb) build_tables(o, nb, nr, ni, down, up, o->threads);
  return true;
}

/* The tables are built before a render on its threads (rc->threads), not
 * at load or on each update: a build takes about a second of CPU. An ocean that follows the
 * render prepares each channel of each page at its wavelength
 * (rc_page: docs/experiments.md#pages-more-than-three-wavelengths-per-path),
 * its tables from a cache keyed by the water's index and the wind, those
 * missing built together (the downwelling ones share their slopes). */
static rsw_status ocean_prepare(object *ob, const render_ctx *rc, rsw_err *err) {
  ocean_bsdf *o = (ocean_bsdf *)ob;
  o->threads = rc->threads;
  if (!o->follow) {
    ocean_tables(o);
    return RSW_OK;
  }
  if (++o->stamp == 0) o->stamp = 1; /* (0 marks an empty entry) */
  ocean_wl *own[OCEAN_MAX_NW];       /* the distinct waters, in page and channel order */
  int n = 0, pages = rc_pages(rc);
  for (int p = 0; p < pages; p++) {
    render_ctx pc = rc_page(rc, p);
    for (int c = 0; c < 3; c++) {
      double wl = rc_channel_wavelength(&pc, c);
      if (!(wl >= 200.0 && wl <= 4000.0))
        return rsw_fail(err, RSW_ERR_RANGE, ob->id ? ob->id : "ocean_legacy",
                        "ocean_legacy follows the render's wavelength, %g nm, outside its 200 to 4000 nm",
                        wl);
      if (c > 0 && wl == rc_channel_wavelength(&pc, c - 1)) continue; /* (a copy: below) */
      o->pg[p][c] = wl_state(o, wl);
      own[n++] = &o->pg[p][c];
    }
  }
  if (!cached_tables(o, n, own))
    return rsw_fail(err, RSW_ERR_NOMEM, ob->id ? ob->id : "ocean_legacy",
                    "ocean_legacy: out of memory for its transmittance tables");
  for (int p = 0; p < RENDER_MAX_PAGES; p++) {
    render_ctx pc = rc_page(rc, p < pages ? p : 0);
    for (int c = 0; c < 3; c++)
      if (p >= pages)
        o->pg[p][c] = o->pg[0][c];
      else if (c > 0 && rc_channel_wavelength(&pc, c) == rc_channel_wavelength(&pc, c - 1))
        o->pg[p][c] = o->pg[p][c - 1];
    o->chromatic[p] =
        o->pg[p][1].wavelength != o->pg[p][0].wavelength || o->pg[p][2].wavelength != o->pg[p][0].wavelength;
  }
  return RSW_OK;
}

/* The water each colour channel renders with at the page the caller
 * evaluates at (rsw_page): n = 1 where the channels are alike (w[0]), else
 * 3. */
static int page_water(const ocean_bsdf *o, ocean_wl *fixed, const ocean_wl **w) {
  if (!o->follow) {
    *fixed = fixed_wl(o);
    w[0] = w[1] = w[2] = fixed;
    return 1;
  }
  const ocean_wl *pg = o->pg[rsw_page];
  w[0] = &pg[0], w[1] = &pg[1], w[2] = &pg[2];
  return o->chromatic[rsw_page] ? 3 : 1;
}

/* What eval and pdf compute at (wi, wo) whatever the wavelength (wi
 * towards the sensor, wo towards the light, 6S's incident direction): the
 * glint before its Fresnel term, the tables' lookups, the lobes'
 * densities. Each channel and page then adds its own water's terms. */
typedef struct ocean_geom {
  bool lit;                     /* wi.z > 0 and wo.z > 0 */
  double r, cchi, schi;         /* the glint: r F(cchi) pi */
  lut_at down, up;              /* underlight: t_d at the light, t_u at the view */
  lut_at at_wi;                 /* the glint lobe's probability: t_d at wi */
  double cos_pdf, mf_p, mf_den; /* the pdf: (1 - ps) cos_pdf + ps mf_p / mf_den (mf_den 0: no glint) */
} ocean_geom;

static void geom_make(const ocean_bsdf *o, vec3 wi, vec3 wo, ocean_geom *g) {
  g->lit = wi.z > 0.0 && wo.z > 0.0;
  if (!g->lit) return;
  /* The glint of light from wo seen from wi (Cox-Munk D, Smith G, 6S's F). */
  double ci = wo.z, co = wi.z;
  vec3 m = v3_norm(v3_add(wo, wi));
  vec3 mp = to_wind(o->phi_w, m);
  mf_distr d = ocean_distr(o);
  double D = mf_D(&d, mp) * gram_charlier(o->wind_speed, o->sigma_u, o->sigma_c, mp);
  g->r = D / (4.0 * ci * co);
  if (o->shadowing) {
    vec3 a = to_wind(o->phi_w, wo), b = to_wind(o->phi_w, wi);
    g->r /= 1.0 + beckmann_lambda(d.alpha_u, d.alpha_v, a) + beckmann_lambda(d.alpha_u, d.alpha_v, b);
  }
  double cchi = v3_dot(wi, m);
  g->cchi = fmin(fmax(cchi, -0.999999999), 0.999999999);
  g->schi = fmin(sqrt(1.0 - g->cchi * g->cchi), 0.999999999);
  g->down = lut_coords(o, wo.z, wo);
  g->up = lut_coords(o, wi.z, wo);
  g->at_wi = lut_coords(o, wi.z, wi);
  g->cos_pdf = warp_square_to_cosine_hemisphere_pdf(wo);
  vec3 h = v3_norm(v3_add(wi, wo));
  double wh = v3_dot(wi, h);
  g->mf_den = 0.0;
  if (wh > 0.0) {
    g->mf_p = mf_pdf(&d, to_wind(o->phi_w, wi), to_wind(o->phi_w, h));
    g->mf_den = 4.0 * wh;
  }
}

/* The geometry at (wi, wo), made again only when the ocean, its state or
 * the directions (bit for bit) changed since this thread's last: a bundle
 * asks every page at the same directions, and pdf() follows eval(). */
static const ocean_geom *geom(const ocean_bsdf *o, vec3 wi, vec3 wo) {
  static _Thread_local struct {
    const ocean_bsdf *o;
    unsigned long gen;
    vec3 wi, wo;
    ocean_geom g;
  } tl;
  if (tl.o != o || tl.gen != o->gen || memcmp(&tl.wi, &wi, sizeof wi) || memcmp(&tl.wo, &wo, sizeof wo)) {
    geom_make(o, wi, wo, &tl.g);
    tl.o = o, tl.gen = o->gen, tl.wi = wi, tl.wo = wo;
  }
  return &tl.g;
}

static double glint_g(const ocean_wl *w, const ocean_geom *g) {
  return g->r * ocean_fresnel_6s(w->n_re, w->n_im, g->cchi, g->schi) * RSW_PI;
}

static double underlight_g(const ocean_wl *w, const ocean_geom *g) {
  if (w->wavelength < 400.0 || w->wavelength > 700.0 || !w->t_down) return 0.0;
  double td = lut_read(w->t_down, &g->down);
  double tu = lut_read(w->t_up, &g->up);
  return w->r_omega * tu * td / ((w->n_re * w->n_re + w->n_im * w->n_im) * (1.0 - 0.485 * w->r_omega));
}

double ocean_glint(const ocean_bsdf *o, vec3 wi, vec3 wo) {
  ocean_wl w = fixed_wl(o);
  ocean_geom g;
  geom_make(o, wo, wi, &g); /* (wi here is the light's, geom_make's wo) */
  return g.lit ? glint_g(&w, &g) : 0.0;
}

/* eval() for a radiance path (cos_o: wo.z). */
static double ocean_value(const ocean_bsdf *o, const ocean_wl *wl, const ocean_geom *g, double cos_o) {
  if (!g->lit) return 0.0;
  double w = wl->whitecap, v;
  switch (o->component) {
  case 1: v = w; break;
  case 2: v = (1.0 - o->coverage) * glint_g(wl, g); break;
  case 3: v = (1.0 - w) * underlight_g(wl, g); break;
  case 4: v = w + (1.0 - w) * underlight_g(wl, g); break;
  default:
    v = (w + (1.0 - w) * underlight_g(wl, g) + (1.0 - o->coverage) * glint_g(wl, g)) * cos_o * RSW_INV_PI;
    break;
  }
  return isfinite(v) ? v : 0.0;
}

/* The value of each channel (n from page_water). */
static color ocean_values(const ocean_bsdf *o, int n, const ocean_wl *const *w, const ocean_geom *g,
                          double cos_o) {
  if (n == 1) return col1(ocean_value(o, w[0], g, cos_o));
  return col(ocean_value(o, w[0], g, cos_o), ocean_value(o, w[1], g, cos_o), ocean_value(o, w[2], g, cos_o));
}

/* The probability of the glint lobe (Eradiate's) with t_d looked up at
 * `at`; where the channels differ, the mean of theirs (the channel-mean
 * density, as media do: docs/experiments.md#spectral-bundles), so that
 * every channel's value over it is unbiased. */
static double p_glint1(const ocean_bsdf *o, const ocean_wl *w, const lut_at *at) {
  double t_i = lut_read(w->t_down, at);
  double pd = w->whitecap + t_i * (1.0 - w->whitecap), ps = 1.0 - o->coverage;
  return ps / (ps + pd);
}

static double p_glint(const ocean_bsdf *o, int n, const ocean_wl *const *w, const lut_at *at) {
  if (n == 1) return p_glint1(o, w[0], at);
  return (p_glint1(o, w[0], at) + p_glint1(o, w[1], at) + p_glint1(o, w[2], at)) / 3.0;
}

static double ocean_pdf_dir(const ocean_bsdf *o, int n, const ocean_wl *const *w, const ocean_geom *g) {
  if (!g->lit) return 0.0;
  double ps = p_glint(o, n, w, &g->at_wi);
  double p = (1.0 - ps) * g->cos_pdf;
  if (g->mf_den > 0.0) p += ps * g->mf_p / g->mf_den;
  return p;
}

static color ocean_sample(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs) {
  const ocean_bsdf *o = (const ocean_bsdf *)b;
  vec3 wi = si->wi;
  if (!(wi.z > 0.0)) return bsdf_fail(bs);
  ocean_wl fx;
  const ocean_wl *w[3];
  int n = page_water(o, &fx, w);
  lut_at at = lut_coords(o, wi.z, wi);
  double ps = p_glint(o, n, w, &at);
  if (u1 >= ps) {
    bs->wo = warp_square_to_cosine_hemisphere(u2);
    bs->sampled_type = BSDF_DIFFUSE_REFLECTION;
  } else {
    mf_distr d = ocean_distr(o);
    double mpdf;
    vec3 m = from_wind(o->phi_w, mf_sample(&d, to_wind(o->phi_w, wi), u2, &mpdf));
    bs->wo = v3_sub(v3_scale(m, 2.0 * v3_dot(wi, m)), wi);
    bs->sampled_type = BSDF_GLOSSY_REFLECTION;
  }
  bs->eta = 1.0;
  const ocean_geom *g = geom(o, wi, bs->wo);
  bs->pdf = ocean_pdf_dir(o, n, w, g);
  if (!(bs->pdf > 0.0)) return bsdf_fail(bs);
  if (n == 1) return col1(ocean_value(o, w[0], g, bs->wo.z) / bs->pdf);
  return col_scale(ocean_values(o, n, w, g, bs->wo.z), 1.0 / bs->pdf);
}

static color ocean_eval(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const ocean_bsdf *o = (const ocean_bsdf *)b;
  ocean_wl fx;
  const ocean_wl *w[3];
  int n = page_water(o, &fx, w);
  return ocean_values(o, n, w, geom(o, si->wi, wo), wo.z);
}

static double ocean_pdf(const bsdf *b, const surface_interaction *si, vec3 wo) {
  const ocean_bsdf *o = (const ocean_bsdf *)b;
  ocean_wl fx;
  const ocean_wl *w[3];
  int n = page_water(o, &fx, w);
  return ocean_pdf_dir(o, n, w, geom(o, si->wi, wo));
}

/* Polarization (docs/plugins.md#polarization-surfaces), as Eradiate's polarized
 * variant (eradiate/mitsuba3 ocean_legacy.cpp): the glint is the Fresnel
 * matrix of water (n_re + i n_im, from air) at the facet reflecting -wo
 * into wi (Mishchenko & Travis 1997 there: the facet's matrix rotated to
 * the meridian planes; here in the facet's s-axis bases, the same
 * matrix), whitecaps and underlight depolarize; mixed by their values,
 * P = (g F / F00 + d D) / (g + d), for every lobe (a sample's weight is
 * the whole eval over the mixture pdf). `component` keeps its terms. */
static void ocean_polarization(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                               mueller P[3], vec3 *s_in, vec3 *s_out) {
  (void)lobe;
  const ocean_bsdf *o = (const ocean_bsdf *)b;
  vec3 wi = si->wi;
  fpol_depolarize(P, wo, wi, s_in, s_out);
  if (!(wi.z > 0.0) || !(wo.z > 0.0) || o->component == 1 || o->component >= 3) return;
  ocean_wl fx;
  const ocean_wl *wl[3];
  page_water(o, &fx, wl); /* (Stokes films render one wavelength: the channels are alike) */
  const ocean_geom *ge = geom(o, wi, wo);
  double w = wl[0]->whitecap, g = (1.0 - o->coverage) * glint_g(wl[0], ge);
  double d = o->component == 2 ? 0.0 : w + (1.0 - w) * underlight_g(wl[0], ge);
  if (!(g > 0.0) || !isfinite(g)) return;
  vec3 h = v3_norm(v3_add(wi, wo));
  mueller F[3];
  F[0] = F[1] = F[2] =
      mu_normalized(mu_fresnel_reflection(v3_dot(wo, h), mu_cmplx(wl[0]->n_re, wl[0]->n_im)));
  fpol_with_diffuse(P, F, col1(g), col1(d));
}

static const bsdf_ops ocean_ops = {
    .sample = ocean_sample, .eval = ocean_eval, .pdf = ocean_pdf, .polarization = ocean_polarization};

static void ocean_destroy(object *o) {
  free(((ocean_bsdf *)o)->cache);
  free(o);
}

/* Ranges: Eradiate's documented ones (wavelength [200, 4000] nm, the
 * tables' span; wind speed (0, 37.54] m/s, where the coverage reaches 1;
 * pigmentation >= 0.3 mg/m^3); chlorinity >= 0; wind direction any. */
static rsw_status ocean_create(loader *ld, node *n, object **out) {
  double wl, ws, wd, chl, pig;
  bool shadowing;
  long long comp;
  rsw_status st;
  if (!ld_has(n, "wavelength"))
    return ld_fail(ld, n, "wavelength", RSW_ERR_MISSING,
                   "ocean_legacy needs 'wavelength' (nm, 200 to 4000, as in Eradiate, or \"render\": each "
                   "render's own)");
  const prop *wp = node_find(n, "wavelength");
  bool follow = wp->kind == PROP_STRING;
  if (follow) {
    const char *s;
    if ((st = ld_string(ld, n, "wavelength", NULL, &s)) != RSW_OK) return st;
    if (strcmp(s, "render") != 0)
      return ld_fail(ld, n, "wavelength", RSW_ERR_INVALID,
                     "ocean_legacy's wavelength is a number (nm, 200 to 4000) or \"render\" (each render's "
                     "own), not '%s'",
                     s);
    wl = 550.0;
  } else if ((st = ld_float_range(ld, n, "wavelength", 550.0, 200.0, 4000.0, &wl)) != RSW_OK) {
    return st;
  }
  if ((st = ld_float_range(ld, n, "wind_speed", 0.1, 0.0, 37.54, &ws)) != RSW_OK) return st;
  if (!(ws > 0.0)) return ld_fail(ld, n, "wind_speed", RSW_ERR_RANGE, "wind_speed must be > 0 m/s");
  if ((st = ld_float_range(ld, n, "wind_direction", 0.0, -1e6, 1e6, &wd)) != RSW_OK) return st;
  if ((st = ld_float_range(ld, n, "chlorinity", 19.0, 0.0, 1e3, &chl)) != RSW_OK) return st;
  if ((st = ld_float_range(ld, n, "pigmentation", 0.3, 0.3, 1e6, &pig)) != RSW_OK) return st;
  if ((st = ld_bool(ld, n, "shadowing", true, &shadowing)) != RSW_OK) return st;
  if ((st = ld_int(ld, n, "component", 0, 0, 4, &comp)) != RSW_OK) return st;
  if (ld_has(n, "coverage"))
    return ld_fail(ld, n, "coverage", RSW_ERR_INVALID,
                   "coverage is derived from wind_speed (Monahan); it cannot be set");
  bsdf *b = ocean_legacy_new(wl, ws, wd, chl, pig, shadowing, (int)comp);
  if (!b) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "ocean_legacy: out of memory");
  b->base.id = n->id;
  ((ocean_bsdf *)b)->follow = follow;
  *out = &b->base;
  return RSW_OK;
}

static void ocean_traverse(object *ob, param_visitor *v) {
  ocean_bsdf *o = (ocean_bsdf *)ob;
  if (!o->follow) /* (one that follows the render has no wavelength of its own) */
    pv_float(v, "wavelength", &o->wavelength, UPDATE_SPECTRAL, 200.0, 4000.0);
  pv_float(v, "wind_speed", &o->wind_speed, UPDATE_SPECTRAL, nextafter(0.0, 1.0), 37.54);
  pv_float(v, "wind_direction", &o->wind_direction, UPDATE_SPECTRAL, -1e6, 1e6);
  pv_float(v, "chlorinity", &o->chlorinity, UPDATE_SPECTRAL, 0.0, 1e3);
  pv_float(v, "pigmentation", &o->pigmentation, UPDATE_SPECTRAL, 0.3, 1e6);
  pv_bool_ro(v, "shadowing", o->shadowing);
  pv_float(v, "coverage", &o->coverage, UPDATE_NONE, 0.0, 1.0);
}

static void ocean_changed(object *ob) {
  ocean_update((ocean_bsdf *)ob);
}

/* Whether a wavelength sweep changes it (scene_wavelength_dependent). */
static bool ocean_spectral(const object *ob) {
  return ((const ocean_bsdf *)ob)->follow;
}

const plugin plugin_ocean_legacy = {
    .name = "ocean_legacy",
    .cls = CLS_BSDF,
    .create = ocean_create,
    .destroy = ocean_destroy,
    .ops = &ocean_ops,
    .traverse = ocean_traverse,
    .parameters_changed = ocean_changed,
    .prepare = ocean_prepare,
    .spectral = ocean_spectral,
    .pages = plugin_pages_any, /* (one that follows the render prepares each page: ocean_prepare) */
};

bsdf *ocean_legacy_new(double wavelength, double wind_speed, double wind_direction, double chlorinity,
                       double pigmentation, bool shadowing, int component) {
  ocean_bsdf *o = calloc(1, sizeof *o);
  if (!o) return NULL;
  o->base.base.plugin = &plugin_ocean_legacy;
  o->base.ops = &ocean_ops;
  o->base.flags = BSDF_DIFFUSE_REFLECTION | BSDF_GLOSSY_REFLECTION;
  o->wavelength = wavelength, o->wind_speed = wind_speed, o->wind_direction = wind_direction;
  o->chlorinity = chlorinity, o->pigmentation = pigmentation, o->shadowing = shadowing;
  o->component = component;
  o->t_key[0] = NAN;
  ocean_update(o);
  return &o->base;
}
