/* The polarized variants' payload in the path tracers (path.c, volpath.c;
 * docs/polarization.md#the-payload).
 *
 * A path carries, besides its scalar throughput T (per colour channel, as
 * in every variant), per channel a Mueller matrix M: the product, from
 * the camera's end, of the polarization factors P = F / F00 of its
 * scatterings and of the basis rotations between them, and the Stokes
 * basis x of the light that arrives at its current vertex along -ray.d.
 * Light reaching the path there with Stokes vector S (in basis x) adds
 * T M S to the camera's Stokes vector, kept per channel in S in the basis
 * stokes_basis(-d0) of the camera ray d0 (the renderer turns it into the
 * film's basis). A scattering with factors P, whose bases are b_in for
 * the light arriving along -wo and b_out for the light leaving along
 * -ray.d, makes M <- M R(b_out -> x) P and x <- b_in. Unpolarized light
 * (S = (L, 0, 0, 0)) is turned by no rotation, so it adds T L M[., 0]
 * before a scattering and T L M R P[., 0] through one.
 *
 * A depolarizing scattering (P = diag(1, 0, 0, 0), passed as P = NULL)
 * leaves M with its first column only (M R D = [M e0, 0, 0, 0]: every
 * rotator's first row is e0); from then on (col0) M R P = M[., 0] P[0, .]
 * and M R P e0 = M[., 0], so such paths skip the bases and the 4x4
 * products (the seed scene's RPV, a Lambertian ground). */
#ifndef RSW_INTEGRATORS_POLARIZATION_H
#define RSW_INTEGRATORS_POLARIZATION_H

#include <stdlib.h>

#include "../kernel.h"

typedef struct pol_lane {
  mueller *M;     /* pol_channels of them, storage the caller's (pol_alloc) */
  vec3 x;         /* world, perpendicular to the current ray */
  double S[3][4]; /* collected, per channel */
  bool col0;      /* M's columns 1..3 are zero (x does not matter) */
  /* volpath: its pending shadow ray's Stokes vectors per unit intensity */
  double pend[3][4];
} pol_lane;

/* Channels a polarized render carries: one in mono (a Stokes film has no
 * spectral bundle), three in rgb. */
static inline int pol_channels(const scene *sc) {
  return sc->variant == VARIANT_MONO ? 1 : 3;
}

/* n lanes and their nch matrices each (pol_free them; NULL: out of
 * memory), as two blocks of at most a wave's 256 x 3 x 128 bytes: a
 * wave's scratch past the allocator's thresholds was mapped, or trimmed,
 * and faulted in again at every wave (780,000 page faults in a render of
 * the seed scene). */
static inline pol_lane *pol_alloc(int n, int nch) {
  pol_lane *p = malloc((size_t)n * sizeof *p);
  mueller *m = malloc((size_t)n * (size_t)nch * sizeof *m);
  if (!p || !m) {
    free(p);
    free(m);
    return NULL;
  }
  for (int i = 0; i < n; i++) p[i].M = m + (size_t)i * nch;
  return p;
}
static inline void pol_free(pol_lane *p) {
  if (p) free(p[0].M);
  free(p);
}

/* A path starting along camera direction d (any length). */
static inline void pol_start(pol_lane *p, vec3 d, int nch) {
  for (int c = 0; c < nch; c++) p->M[c] = mu_identity();
  p->x = stokes_basis(v3_neg(v3_norm(d)));
  memset(p->S, 0, sizeof p->S);
  p->col0 = false;
}

/* Unpolarized light of intensity v (per channel, T and MIS weights
 * included) arriving at the current vertex along -ray.d. */
static inline void pol_add(pol_lane *p, color v, int nch) {
  for (int c = 0; c < nch; c++)
    for (int k = 0; k < 4; k++) p->S[c][k] += v.c[c] * p->M[c].m[k][0];
}

/* Light of Stokes vector s[c] per channel (weights included) in basis
 * bs, travelling along pd = -ray.d, arriving at the current vertex. */
static inline void pol_add_stokes(pol_lane *p, vec3 pd, vec3 bs, const double s[3][4], int nch) {
  if (p->col0) {
    for (int c = 0; c < nch; c++)
      for (int k = 0; k < 4; k++) p->S[c][k] += p->M[c].m[k][0] * s[c][0];
    return;
  }
  mueller R = mu_basis_change(pd, bs, p->x);
  for (int c = 0; c < nch; c++) {
    double r[4], o[4];
    mu_apply(&R, s[c], r);
    mu_apply(&p->M[c], r, o);
    for (int k = 0; k < 4; k++) p->S[c][k] += o[k];
  }
}

/* The Stokes vectors, per unit intensity and channel, that unpolarized
 * light scattered by P (bases: b_out for the light leaving along pd,
 * the current ray's reverse) adds at the camera: M R(b_out -> x) P[., 0]
 * (M[., 0] when P depolarizes or M has its first column only). */
static inline void pol_through(const pol_lane *p, vec3 pd, vec3 b_out, const mueller *P, int nch,
                               double out[3][4]) {
  if (!P || p->col0) {
    for (int c = 0; c < nch; c++)
      for (int k = 0; k < 4; k++) out[c][k] = p->M[c].m[k][0];
    return;
  }
  mueller R = mu_basis_change(pd, b_out, p->x);
  for (int c = 0; c < nch; c++) {
    double col[4] = {P[c].m[0][0], P[c].m[1][0], P[c].m[2][0], P[c].m[3][0]}, r[4];
    mu_apply(&R, col, r);
    mu_apply(&p->M[c], r, out[c]);
  }
}

/* out[c] scaled by v.c[c], added to the collected vectors. */
static inline void pol_collect(pol_lane *p, const double out[3][4], color v, int nch) {
  for (int c = 0; c < nch; c++)
    for (int k = 0; k < 4; k++) p->S[c][k] += v.c[c] * out[c][k];
}

/* A scattering: M <- M R(b_out -> x) P, x <- b_in (P NULL: depolarizes). */
static inline void pol_scatter(pol_lane *p, vec3 pd, vec3 b_out, const mueller *P, vec3 b_in, int nch) {
  if (!P) {
    for (int c = 0; c < nch; c++)
      for (int k = 0; k < 4; k++) p->M[c].m[k][1] = p->M[c].m[k][2] = p->M[c].m[k][3] = 0.0;
    p->col0 = true;
    return;
  }
  if (p->col0) { /* M[., 0] P[0, .] */
    for (int c = 0; c < nch; c++) {
      double m[4] = {p->M[c].m[0][0], p->M[c].m[1][0], p->M[c].m[2][0], p->M[c].m[3][0]};
      for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) p->M[c].m[i][j] = m[i] * P[c].m[0][j];
    }
    p->col0 = false;
    p->x = b_in;
    return;
  }
  mueller R = mu_basis_change(pd, b_out, p->x);
  for (int c = 0; c < nch; c++) {
    mueller MR = mu_mul(&p->M[c], &R);
    p->M[c] = mu_mul(&MR, &P[c]);
  }
  p->x = b_in;
}

/* A BSDF's factors towards local direction wo (lobe: bsdf_ops.polarization)
 * into P and their bases in world space; returns P, or NULL (nothing
 * written) for a BSDF that depolarizes. */
static inline const mueller *pol_bsdf(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                                      mueller P[3], vec3 *b_in, vec3 *b_out) {
  if (!b->ops->polarization) return NULL;
  vec3 s_in, s_out;
  b->ops->polarization(b, si, wo, lobe, P, &s_in, &s_out);
  *b_in = v3_norm(frame_to_world(&si->sh, s_in));
  *b_out = v3_norm(frame_to_world(&si->sh, s_out));
  return P;
}

/* A phase function's factors for the scattering from mi->wi into wo, and
 * their basis (both sides): the scattering plane's normal. */
static inline const mueller *pol_phase(const phase *ph, const medium_interaction *mi, vec3 wo, mueller P[3],
                                       vec3 *basis) {
  if (!ph->ops->polarization) return NULL;
  ph->ops->polarization(ph, mi, wo, P);
  *basis = plane_normal(wo, mi->wi);
  return P;
}

/* An environment's light along direction d (towards the environment) as
 * a Stokes vector per unit intensity and channel: Q, U, V from
 * eval_polarization over I = Le, in the basis whose x is horizontal
 * (perpendicular to the vertical plane through d;
 * docs/polarization.md#stokes-conventions), returned. */
static inline vec3 pol_env_unit(const emitter *e, vec3 d, color Le, int nch, double s[3][4]) {
  double q[3] = {0, 0, 0};
  e->ops->eval_polarization(e, d, q);
  for (int c = 0; c < nch; c++) {
    s[c][0] = 1.0;
    for (int k = 0; k < 3; k++) s[c][k + 1] = Le.c[c] != 0 ? q[k] / Le.c[c] : 0.0;
  }
  return plane_normal(v3(0, 0, 1), v3_neg(d));
}

static inline bool pol_env_polarized(const emitter *e) {
  return (e->flags & EMITTER_INFINITE) && e->ops->eval_polarization;
}

/* An environment's light Le along ray direction d reaching the current
 * vertex, worth v = T Le w in intensity. */
static inline void pol_add_env(pol_lane *p, const emitter *e, vec3 d, color Le, color v, int nch) {
  if (!pol_env_polarized(e)) {
    pol_add(p, v, nch);
    return;
  }
  double s[3][4];
  d = v3_norm(d);
  vec3 b = pol_env_unit(e, d, Le, nch, s);
  for (int c = 0; c < nch; c++)
    for (int k = 0; k < 4; k++) s[c][k] *= v.c[c];
  pol_add_stokes(p, v3_neg(d), b, s, nch);
}

/* The Stokes vectors per unit of a light sample's intensity contribution
 * that emitter e's light from direction d (towards e) adds through the
 * factors P (bases b_in, b_out; pd = -ray.d): M R(b_out -> x) P
 * R(b_e -> b_in) S / I, S the light's Stokes vector ((1, 0, 0, 0) for
 * every emitter but a polarized environment). */
static inline void pol_through_light(const pol_lane *p, const emitter *e, vec3 d, vec3 pd, vec3 b_in,
                                     vec3 b_out, const mueller *P, int nch, double out[3][4]) {
  if (!pol_env_polarized(e) || !P) {
    pol_through(p, pd, b_out, P, nch, out);
    return;
  }
  double s[3][4];
  d = v3_norm(d);
  vec3 be = pol_env_unit(e, d, e->ops->eval(e, NULL, d), nch, s);
  mueller Rin = mu_basis_change(v3_neg(d), be, b_in), Rout = mu_basis_change(pd, b_out, p->x);
  for (int c = 0; c < nch; c++) {
    double r[4], t[4];
    mu_apply(&Rin, s[c], r);
    mu_apply(&P[c], r, t);
    if (p->col0) { /* M[., 0] times the intensity of P R_in S */
      for (int k = 0; k < 4; k++) out[c][k] = p->M[c].m[k][0] * t[0];
      continue;
    }
    mu_apply(&Rout, t, r);
    mu_apply(&p->M[c], r, out[c]);
  }
}

/* A light sample of emitter e from direction d (world, towards e) through
 * the BSDF at si (local wo, lobe as bsdf_ops.polarization), worth v in
 * intensity: its Stokes vectors collected (pd = -ray.d). */
static inline void pol_collect_light(pol_lane *p, const surface_interaction *si, vec3 wo, unsigned lobe,
                                     const emitter *e, vec3 d, vec3 pd, color v, int nch) {
  mueller P[3];
  vec3 b_in = {0}, b_out = {0};
  double out[3][4];
  const mueller *pp = pol_bsdf(si->shape->bsdf, si, wo, lobe, P, &b_in, &b_out);
  pol_through_light(p, e, d, pd, b_in, b_out, pp, nch, out);
  pol_collect(p, out, v, nch);
}

/* The path's result: I per channel into L, Q, U, V of channel c into
 * quv[3 c .. 3 c + 2] (nch channels: kernel.h scene_quv_stride). */
static inline void pol_result(const pol_lane *p, int nch, color *L, double *quv) {
  for (int c = 0; c < 3; c++) L->c[c] = p->S[c < nch ? c : 0][0];
  if (quv)
    for (int c = 0; c < nch; c++)
      for (int k = 0; k < 3; k++) quv[3 * c + k] = p->S[c][k + 1];
}

#endif
