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
 * before a scattering and T L M R P[., 0] through one. */
#ifndef RSW_INTEGRATORS_POLARIZATION_H
#define RSW_INTEGRATORS_POLARIZATION_H

#include "../kernel.h"

typedef struct pol_lane {
  mueller M[3];
  vec3 x;         /* world, perpendicular to the current ray */
  double S[3][4]; /* collected, per channel */
} pol_lane;

/* Channels a polarized render carries: one in mono (a Stokes film has no
 * spectral bundle), three in rgb. */
static inline int pol_channels(const scene *sc) {
  return sc->variant == VARIANT_MONO ? 1 : 3;
}

/* A path starting along camera direction d (any length). */
static inline void pol_start(pol_lane *p, vec3 d, int nch) {
  for (int c = 0; c < nch; c++) p->M[c] = mu_identity();
  p->x = stokes_basis(v3_neg(v3_norm(d)));
  memset(p->S, 0, sizeof p->S);
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
 * the current ray's reverse) adds at the camera: M R(b_out -> x) P[., 0]. */
static inline void pol_through(const pol_lane *p, vec3 pd, vec3 b_out, const mueller P[3], int nch,
                               double out[3][4]) {
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

/* A scattering: M <- M R(b_out -> x) P, x <- b_in. */
static inline void pol_scatter(pol_lane *p, vec3 pd, vec3 b_out, const mueller P[3], vec3 b_in, int nch) {
  mueller R = mu_basis_change(pd, b_out, p->x);
  for (int c = 0; c < nch; c++) {
    mueller MR = mu_mul(&p->M[c], &R);
    p->M[c] = mu_mul(&MR, &P[c]);
  }
  p->x = b_in;
}

/* A BSDF's factors towards local direction wo (lobe: bsdf_ops.polarization)
 * and their bases in world space. */
static inline void pol_bsdf(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe,
                            mueller P[3], vec3 *b_in, vec3 *b_out) {
  vec3 s_in, s_out;
  if (b->ops->polarization) {
    b->ops->polarization(b, si, wo, lobe, P, &s_in, &s_out);
  } else {
    P[0] = P[1] = P[2] = mu_depolarizer();
    s_in = stokes_basis(wo);
    s_out = stokes_basis(si->wi);
  }
  *b_in = v3_norm(frame_to_world(&si->sh, s_in));
  *b_out = v3_norm(frame_to_world(&si->sh, s_out));
}

/* A phase function's factors for the scattering from mi->wi into wo, and
 * their basis (both sides): the scattering plane's normal. */
static inline vec3 pol_phase(const phase *ph, const medium_interaction *mi, vec3 wo, mueller P[3]) {
  if (ph->ops->polarization)
    ph->ops->polarization(ph, mi, wo, P);
  else
    P[0] = P[1] = P[2] = mu_depolarizer();
  return plane_normal(wo, mi->wi);
}

/* An environment's light along direction d (towards the environment) as
 * a Stokes vector per channel: I from eval (Le), Q, U, V from
 * eval_polarization in the basis whose x is horizontal (perpendicular to
 * the vertical plane through d; docs/environment-plugins.md), scaled by w. */
static inline vec3 pol_env_stokes(const emitter *e, vec3 d, color Le, double w, int nch, double s[3][4]) {
  double q[3] = {0, 0, 0};
  if (e->ops->eval_polarization) e->ops->eval_polarization(e, d, q);
  for (int c = 0; c < nch; c++) {
    s[c][0] = Le.c[c] * w;
    for (int k = 0; k < 3; k++) s[c][k + 1] = q[k] * w;
  }
  return plane_normal(v3(0, 0, 1), v3_neg(d));
}

/* The path's result: I per channel into L, Q, U, V of channel 0 into quv. */
static inline void pol_result(const pol_lane *p, int nch, color *L, double *quv) {
  for (int c = 0; c < 3; c++) L->c[c] = p->S[c < nch ? c : 0][0];
  if (quv)
    for (int k = 0; k < 3; k++) quv[k] = p->S[0][k + 1];
}

#endif
