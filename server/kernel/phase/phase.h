/* What the phase-function plugins share: the scattering angle in the
 * physics convention and the direction it stands for.
 *
 * Mitsuba's convention (kernel.h): mi->wi points back towards where the
 * path came from, wo where it goes. The scattering angle theta is between
 * the forward direction -wi and wo, so mu = cos(theta) = -dot(wi, wo) and
 * mu = 1 is forward scattering (mitsuba3 src/phase/tabphase.cpp notes). A
 * phase function p(mu) [sr^-1] integrates to 1 over the sphere:
 * 2 pi int_{-1}^{1} p(mu) dmu = 1. */
#ifndef RSW_PHASE_PHASE_H
#define RSW_PHASE_PHASE_H

#include <math.h>

#include "../core/fastmath.h"
#include "../kernel.h"

/* mu = cos(theta) of the scattering from mi->wi into wo. */
static inline double phase_mu(const medium_interaction *mi, vec3 wo) {
  return -v3_dot(mi->wi, wo);
}

/* The unit world direction at scattering cosine mu and azimuth
 * phi = 2 pi u around the forward direction -wi. */
static inline vec3 phase_direction(const medium_interaction *mi, double mu, double u) {
  frame f = frame_from_normal(v3_neg(mi->wi));
  double s = sqrt(rsw_fmax(1.0 - mu * mu, 0.0)), phi = 2.0 * RSW_PI * u; /* (fmax(0, .) bit for bit) */
  return frame_to_world(&f, v3(s * cos(phi), s * sin(phi), mu));
}

/* Before the eval_pdf and sample calls of one scattering at mi (mi->p
 * fixed): let ph look up what it needs at mi->p once. Results are those of
 * the unbound calls, bit for bit. */
static inline void phase_bind(const phase *ph, medium_interaction *mi) {
  mi->bound = NULL;
  if (ph->ops->bind) ph->ops->bind(ph, mi);
}

/* A failed sample (kernel.h phase_ops.sample). */
static inline double phase_fail(double *pdf) {
  *pdf = 0.0;
  return 0.0;
}

/* n scatterings at once (kernel.h phase_ops.sample_batch; without it, one
 * sample call a lane): lane i is sample(ph, &mi[i], u1[i], u2[i], &wo[i],
 * &pdf[i]), its return value in weight[i], bit for bit. */
static inline void phase_sample_batch(const phase *ph, int n, const medium_interaction *mi, const double *u1,
                                      const vec2 *u2, vec3 *wo, double *pdf, double *weight) {
  if (ph->ops->sample_batch) {
    ph->ops->sample_batch(ph, n, mi, u1, u2, wo, pdf, weight);
    return;
  }
  for (int i = 0; i < n; i++) weight[i] = ph->ops->sample(ph, &mi[i], u1[i], u2[i], &wo[i], &pdf[i]);
}

/* n evaluations at once (phase_ops.eval_pdf_batch; without it, one
 * eval_pdf call a lane): lane i is eval_pdf(ph, &mi[i], wo[i], &pdf[i]),
 * its return value in val[i], bit for bit. */
static inline void phase_eval_pdf_batch(const phase *ph, int n, const medium_interaction *mi, const vec3 *wo,
                                        double *val, double *pdf) {
  if (ph->ops->eval_pdf_batch) {
    ph->ops->eval_pdf_batch(ph, n, mi, wo, val, pdf);
    return;
  }
  for (int i = 0; i < n; i++) val[i] = ph->ops->eval_pdf(ph, &mi[i], wo[i], &pdf[i]);
}

/* Polarized variants, mixtures (blendphase, molecular_atmosphere): the
 * factors of sum_i a_i p_i are P = sum_i a_i p_i P_i / sum_i a_i p_i, P_i
 * component i's factors (phase_ops.polarization; without it a
 * depolarizer), p_i its value at wo. phase_mix_add adds component ph of
 * weight a_i p_i = ap into acc[] (start from mu_zero()); then
 * P[c] = mu_normalized(acc[c]) (the sum's M00 is sum a_i p_i). */
static inline void phase_mix_add(const phase *ph, const medium_interaction *mi, vec3 wo, double ap,
                                 mueller acc[3]) {
  mueller P[3];
  if (ph->ops->polarization)
    ph->ops->polarization(ph, mi, wo, P);
  else
    P[0] = P[1] = P[2] = mu_depolarizer();
  for (int c = 0; c < 3; c++)
    for (int i = 0; i < 4; i++)
      for (int j = 0; j < 4; j++) acc[c].m[i][j] += ap * P[c].m[i][j];
}

#endif
