/* Layered tracking shared by `piecewise` and `molecular_atmosphere`
 * (layered.h). */
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "../simd/simd.h"
#include "layered.h"
#include "layered_lanes.h"
#include "media.h"

bool media_layers_alloc(media_layers *L, uint32_t n) {
  L->n = n;
  L->nd = n;
  L->uniform = true;
  L->nc = 1;
  L->lay = aligned_alloc(64, ((size_t)n + 1) * sizeof *L->lay);
  L->alb = malloc(3 * (size_t)n * sizeof *L->alb);
  L->bk = malloc(3 * ((size_t)n + 1) * sizeof *L->bk);
  L->cum = aligned_alloc(64, (3 * ((size_t)n + 1) * sizeof *L->cum + 63) / 64 * 64);
  if (!L->lay || !L->alb || !L->bk || !L->cum) return false;
  memset(L->lay, 0, ((size_t)n + 1) * sizeof *L->lay);
  for (uint32_t k = 0; k <= n; k++) L->lay[k].z = (double)k / n;
  return true;
}

void media_layers_free(media_layers *L) {
  free(L->lay);
  free(L->alb);
  free(L->bk);
  free(L->cum);
  L->lay = NULL;
  L->alb = NULL;
  L->bk = NULL;
  L->cum = NULL;
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
  for (int c = 0; c < 3; c++)
    for (uint32_t k = 0; k <= n; k++) L->cum[(size_t)c * (n + 1) + k] = L->lay[k].cum[c];
  L->gray_alb = true;
  for (uint32_t k = 0; k < n; k++) {
    const double *a = &L->alb[3 * (size_t)k];
    L->lay[k].alb0 = a[0];
    L->gray_alb &= a[1] == a[0] && a[2] == a[0];
  }
  L->lay[n].alb0 = 0.0;
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

/* ---- batched free flights ------------------------------------------------------- */

/* The lanes read media_layers.lay as 8 doubles a layer. */
_Static_assert(sizeof(pw_layer) == 8 * sizeof(double) && offsetof(pw_layer, sig) == 3 * sizeof(double) &&
                   offsetof(pw_layer, z) == 6 * sizeof(double),
               "pw_layer: cum[3], sig[3], z, alb0");

static void flight_setup_batch(rsw_isa isa, int n, const double *geo, const double *lay,
                               const double *const *o, const double *const *d, const double *t0,
                               const double *t1, const double *u, const int *c, double *const *out, int *k0,
                               int *k1, unsigned char *fast) {
  SIMD_DISPATCH(isa, flight_setup, n, geo, lay, o, d, t0, t1, u, c, out, k0, k1, fast);
}

/* Flights per round: the setup's scratch on the stack. */
#define FLIGHT_CHUNK 64

/* The setups f[0..n) (n <= FLIGHT_CHUNK) of flights i0.. of rays o, d over
 * [mint, maxt] in channels ch (resolved: 0 when nc = 1): in the lanes
 * where the layers are equal and to_world affine, else one
 * media_flight_setup each; and, with u, fast[i] = media_flight_passes_fast. */
static void flights_setup(rsw_isa isa, const media_layers *L, int i0, int n, const double *const *o,
                          const double *const *d, const double *mint, const double *maxt, const double *u,
                          const int *ch, media_flight *f, unsigned char *fast) {
  if (L->uniform && L->affine) {
    const double geo[6] = {L->zrow[0], L->zrow[1], L->zrow[2], L->zrow[3], L->nd, (double)L->n - 1};
    double s[5][FLIGHT_CHUNK];
    int k0[FLIGHT_CHUNK], k1[FLIGHT_CHUNK];
    const double *oc[3] = {o[0] + i0, o[1] + i0, o[2] + i0}, *dc[3] = {d[0] + i0, d[1] + i0, d[2] + i0};
    double *const out[5] = {s[0], s[1], s[2], s[3], s[4]};
    flight_setup_batch(isa, n, geo, (const double *)L->lay, oc, dc, mint + i0, maxt + i0, u ? u + i0 : NULL,
                       ch, out, k0, k1, u ? fast : NULL);
    for (int i = 0; i < n; i++)
      f[i] = (media_flight){.t0 = mint[i0 + i],
                            .t1 = maxt[i0 + i],
                            .oz = s[0][i],
                            .dz = s[1][i],
                            .z0 = s[2][i],
                            .z1 = s[3][i],
                            .total = s[4][i],
                            .c = ch[i],
                            .k0 = k0[i],
                            .k1 = k1[i]};
    return;
  }
  for (int i = 0; i < n; i++) {
    int j = i0 + i;
    ray3 r = {v3(o[0][j], o[1][j], o[2][j]), v3(d[0][j], d[1][j], d[2][j]), mint[j], maxt[j]};
    media_flight_setup(L, &r, mint[j], maxt[j], ch[i], &f[i]);
    if (u) fast[i] = media_flight_passes_fast(u[j], f[i].total);
  }
}

void media_layers_sample_real_batch(rsw_isa isa, const media_layers *L, const media_flight_batch *b) {
  for (int i0 = 0; i0 < b->n; i0 += FLIGHT_CHUNK) {
    int cnt = b->n - i0 < FLIGHT_CHUNK ? b->n - i0 : FLIGHT_CHUNK;
    const double *u = b->u + i0;
    media_flight f[FLIGHT_CHUNK];
    int ch[FLIGHT_CHUNK];
    unsigned char fast[FLIGHT_CHUNK];
    for (int i = 0; i < cnt; i++) ch[i] = L->nc == 1 || !b->channel ? 0 : b->channel[i0 + i];
    flights_setup(isa, L, i0, cnt, b->o, b->d, b->mint, b->maxt, b->u, ch, f, fast);
    /* Passes and collisions apart, without branching on either: the
     * logs of the flights the quick test left open, then each kind. */
    int open[FLIGHT_CHUNK], pass[FLIGHT_CHUNK], hit[FLIGHT_CHUNK], no = 0, np = 0, nh = 0;
    double target[FLIGHT_CHUNK];
    for (int i = 0; i < cnt; i++) {
      open[no] = i, no += !fast[i];
      pass[np] = i, np += fast[i];
    }
    for (int q = 0; q < no; q++) {
      int i = open[q];
      target[i] = rsw_neg_log1m(u[i]); /* (as media_layers_sample_real) */
      bool p = !(target[i] < f[i].total);
      pass[np] = i, np += p;
      hit[nh] = i, nh += !p;
    }
    for (int q = 0; q < np; q++) {
      int i = pass[q], j = i0 + i;
      color x = media_flight_passed(L, &f[i]);
      b->t[j] = INFINITY;
      b->layer[j] = -1;
      for (int c = 0; c < 3; c++) b->tr[c][j] = b->pdf[c][j] = x.c[c];
    }
    for (int q = 0; q < nh; q++) {
      int i = hit[q], j = i0 + i, k;
      double t;
      color x, y;
      media_flight_collide(L, &f[i], target[i], &t, &k);
      media_flight_weights(L, &f[i], u[i], t, k, &x, &y);
      b->t[j] = t;
      b->layer[j] = k;
      for (int c = 0; c < 3; c++) b->tr[c][j] = x.c[c], b->pdf[c][j] = y.c[c];
    }
  }
}

void media_layers_transmittance_batch(rsw_isa isa, const media_layers *L, int n, const double *const *o,
                                      const double *const *d, const double *mint, const double *maxt,
                                      double *const *tr) {
  static const int zero[FLIGHT_CHUNK]; /* channel 0 first, as media_layers_transmittance */
  for (int i0 = 0; i0 < n; i0 += FLIGHT_CHUNK) {
    int cnt = n - i0 < FLIGHT_CHUNK ? n - i0 : FLIGHT_CHUNK;
    media_flight f[FLIGHT_CHUNK];
    flights_setup(isa, L, i0, cnt, o, d, mint, maxt, NULL, zero, f, NULL);
    for (int i = 0; i < cnt; i++) {
      color x = media_flight_passed(L, &f[i]); /* (exp(-tau) per channel, channel 0's the setup's) */
      for (int c = 0; c < 3; c++) tr[c][i0 + i] = x.c[c];
    }
  }
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
