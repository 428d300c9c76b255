/* Layered tracking shared by `piecewise` and `molecular_atmosphere`
 * (layered.h). */
#include <stdlib.h>
#include <string.h>

#include "layered.h"
#include "media.h"

bool media_layers_alloc(media_layers *L, uint32_t n) {
  L->n = n;
  L->nd = n;
  L->uniform = true;
  L->nc = 1;
  L->lay = aligned_alloc(64, ((size_t)n + 1) * sizeof *L->lay);
  L->alb = malloc(3 * (size_t)n * sizeof *L->alb);
  L->bk = malloc(3 * ((size_t)n + 1) * sizeof *L->bk);
  if (!L->lay || !L->alb || !L->bk) return false;
  memset(L->lay, 0, ((size_t)n + 1) * sizeof *L->lay);
  for (uint32_t k = 0; k <= n; k++) L->lay[k].z = (double)k / n;
  return true;
}

void media_layers_free(media_layers *L) {
  free(L->lay);
  free(L->alb);
  free(L->bk);
  L->lay = NULL;
  L->alb = NULL;
  L->bk = NULL;
}

void media_layers_finish(media_layers *L) {
  uint32_t n = L->n;
  color mx = col1(0.0);
  for (int c = 0; c < 3; c++) L->lay[0].cum[c] = 0.0, L->lay[n].sig[c] = 0.0;
  for (uint32_t k = 0; k < n; k++)
    for (int c = 0; c < 3; c++) {
      double s = L->lay[k].sig[c];
      /* (equal layers: s / n, as piecewise always did) */
      L->lay[k + 1].cum[c] = L->lay[k].cum[c] + (L->uniform ? s / n : s * (L->lay[k + 1].z - L->lay[k].z));
      if (s > mx.c[c]) mx.c[c] = s;
    }
  L->maj = mx;
  for (int c = 0; c < 3; c++) {
    double top = L->lay[n].cum[c], scale = n / top;
    L->bk_scale[c] = c < L->nc && top > 0 && isfinite(scale) ? scale : -1.0;
    if (!(L->bk_scale[c] > 0)) continue;
    uint32_t *bk = L->bk + (size_t)c * (n + 1), i = 1;
    for (uint32_t j = 0; j <= n; j++) {
      double thr = j / scale;
      while (i < n && !(L->lay[i].cum[c] > thr)) i++;
      bk[j] = i;
    }
  }
  media_box_init(&L->box, L->to_world);
  const double(*inv)[4] = L->to_world->inv;
  for (int j = 0; j < 4; j++) L->zrow[j] = inv[2][j];
  L->affine = inv[3][0] == 0.0 && inv[3][1] == 0.0 && inv[3][2] == 0.0 && inv[3][3] == 1.0;
}

/* ---- the medium_ops ------------------------------------------------------------ */

static inline const media_layers *layers_of(const medium *m) {
  return layered_layers(m);
}

static bool lm_intersect_aabb(const medium *m, const ray3 *r, double *mint, double *maxt) {
  return media_box_clip_at(&layers_of(m)->box, r, mint, maxt);
}

static color lm_majorant(const medium *m, const medium_interaction *mi) {
  (void)mi;
  return layers_of(m)->maj;
}

static void lm_coefficients(const medium *m, medium_interaction *mi) {
  media_layers_coefficients(layers_of(m), mi);
}

static void lm_sample_real(const medium *m, const ray3 *r, double mint, double maxt, double u, int channel,
                           medium_interaction *mi, color *tr, color *pdf) {
  media_layers_sample_real(layers_of(m), m, r, mint, maxt, u, channel, mi, tr, pdf);
}

static color lm_transmittance(const medium *m, const ray3 *r, double mint, double maxt) {
  return media_layers_transmittance(layers_of(m), r, mint, maxt);
}

const medium_ops layered_medium_ops = {.intersect_aabb = lm_intersect_aabb,
                                       .majorant = lm_majorant,
                                       .coefficients = lm_coefficients,
                                       .sample_real = lm_sample_real,
                                       .transmittance = lm_transmittance};
