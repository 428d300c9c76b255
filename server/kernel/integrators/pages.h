/* A BSDF seen by a bundle of pages (render_ctx.bundle > 3: pages of three
 * wavelengths per path, docs/experiments.md#pages-more-than-three-wavelengths-per-path):
 * one direction for every page, each page weighted by its own value over
 * the mean of the pages' densities (one-sample spectral MIS, Wilkie et
 * al. 2014, "Hero wavelength spectral sampling"). An object answers for
 * page p while rsw_page = p; these leave it at 0. */
#ifndef RSW_INTEGRATORS_PAGES_H
#define RSW_INTEGRATORS_PAGES_H

#include <math.h>

#include "../kernel.h"

/* A chromatic phase's value per channel at pages p0..pages-1 into
 * out[p] (phase_ops.eval_pages where the phase has it, else
 * eval_channels page by page). */
static inline void phase_pages(const phase *ph, const medium_interaction *mi, vec3 wo, int p0, int pages,
                               color *out) {
  if (ph->ops->eval_pages) {
    ph->ops->eval_pages(ph, mi, wo, p0, pages, out);
    return;
  }
  for (int p = p0; p < pages; p++) {
    rsw_page = p;
    out[p] = ph->ops->eval_channels(ph, mi, wo);
  }
  rsw_page = 0;
}

/* Each page's value f[p] towards wo (local) into f[0..pages), and the mean
 * of the pages' pdfs (0 when with_pdf is false: a delta light sample). */
static inline double bsdf_eval_pages(const bsdf *b, const surface_interaction *si, int pages, vec3 wo,
                                     bool with_pdf, color *f) {
  double pdf = 0.0;
  for (int p = 0; p < pages; p++) {
    rsw_page = p;
    f[p] = b->ops->eval(b, si, wo);
    if (with_pdf) pdf += b->ops->pdf(b, si, wo);
  }
  rsw_page = 0;
  return pdf / pages;
}

/* The sample for every page: u1 picks the page j the direction is drawn
 * from (then, rescaled, the lobe within it), u2 the direction; bs->pdf is
 * the pages' mean density of bs->wo and w[p] each page's value over it.
 * A delta lobe of a BSDF that says its value (bsdf_ops.delta_value:
 * `plastic`, `dielectric`, `conductor`, `null` and the compositions over
 * them): each page's value towards bs->wo over the mean of the pages'
 * probabilities of drawing it (bs->pdf), so that a lobe the pages choose
 * with different probabilities (a spectral diffuse_reflectance weights
 * plastic's choice) stays unbiased at every page, and a composition's
 * lobes that lead elsewhere (another glass's refraction) do not count. Other delta lobes (a
 * BSDF without delta_value whose only lobe is a mirror: scene_page_blocker) take
 * each page's own weight for the same lobe and direction. A failed
 * sample: bs->pdf 0 and every weight 0. */
static inline void bsdf_sample_pages(const bsdf *b, const surface_interaction *si, int pages, double u1,
                                     vec2 u2, bsdf_sample *bs, color *w) {
  double u = u1 * pages;
  int j = (int)u < pages - 1 ? (int)u : pages - 1;
  u1 = fmin(u - j, 1.0 - 0x1p-53);
  rsw_page = j;
  color wj = b->ops->sample(b, si, u1, u2, bs);
  for (int p = 0; p < pages; p++) w[p] = col1(0);
  if (!(bs->pdf > 0)) {
    bs->pdf = 0;
  } else if ((bs->sampled_type & BSDF_DELTA) && b->ops->delta_value) {
    double pm = 0.0, pr;
    for (int p = 0; p < pages; p++) {
      rsw_page = p;
      w[p] = b->ops->delta_value(b, si, bs->sampled_type, bs->wo, &pr);
      pm += pr;
    }
    bs->pdf = pm / pages;
    for (int p = 0; p < pages; p++) w[p] = bs->pdf > 0 ? col_scale(w[p], 1.0 / bs->pdf) : col1(0);
  } else if (bs->sampled_type & BSDF_DELTA) {
    for (int p = 0; p < pages; p++) {
      bsdf_sample t;
      rsw_page = p;
      w[p] = p == j ? wj : b->ops->sample(b, si, u1, u2, &t);
      if (p != j && (t.sampled_type != bs->sampled_type || t.wo.x != bs->wo.x || t.wo.y != bs->wo.y ||
                     t.wo.z != bs->wo.z))
        w[p] = col1(0);
    }
  } else {
    bs->pdf = bsdf_eval_pages(b, si, pages, bs->wo, true, w);
    for (int p = 0; p < pages; p++) w[p] = bs->pdf > 0 ? col_scale(w[p], 1.0 / bs->pdf) : col1(0);
  }
  rsw_page = 0;
}

#endif
