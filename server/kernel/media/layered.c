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

/* C(z), z in layer k. */
static inline double cum_in(const media_layers *L, int c, int k, double z) {
  double zc = z < 0.0 ? 0.0 : z > 1.0 ? 1.0 : z;
  const pw_layer *y = &L->lay[k];
  return y->cum[c] + y->sig[c] * (zc - y->z);
}

/* tau over [t0, t1] in channel c; z0, z1 the local z at both ends, k0, k1
 * their layers. */
static inline double tau_layers(const media_layers *L, int c, double z0, double z1, int k0, int k1, double dz,
                                double len) {
  if (k0 == k1) return L->lay[k0].sig[c] * len;
  return fabs(cum_in(L, c, k1, z1) - cum_in(L, c, k0, z0)) / fabs(dz);
}

static inline double tau_between(const media_layers *L, int c, double z0, double z1, double dz, double len) {
  return tau_layers(L, c, z0, z1, media_layer_of(L, z0), media_layer_of(L, z1), dz, len);
}

static void fill_layer(const media_layers *L, int k, medium_interaction *mi) {
  for (int c = 0; c < 3; c++) {
    double s = L->lay[k].sig[c];
    mi->sigma_t.c[c] = s;
    mi->sigma_s.c[c] = s * L->alb[3 * k + c];
    mi->sigma_n.c[c] = fmax(mi->majorant.c[c] - s, 0.0);
  }
}

static void layers_coefficients(const media_layers *L, medium_interaction *mi) {
  fill_layer(L, media_layer_of(L, media_layers_z(L, mi->p)), mi);
}

static inline void spread(color *x, int nc) {
  if (nc == 1) x->c[1] = x->c[2] = x->c[0];
}

static void layers_sample_real(const media_layers *L, const medium *m, const ray3 *r, double mint,
                               double maxt, double u, int channel, medium_interaction *mi, color *tr,
                               color *pdf) {
  int nc = L->nc;
  double t0 = mint, t1 = maxt; /* within intersect_aabb's interval (the caller clips) */
  mi->medium = m;
  mi->wi = v3_neg(r->d);
  mi->t = INFINITY;
  mi->mint = t0;
  double oz = media_layers_z(L, r->o), dz = media_layers_dz(L, r->d);
  double z0 = oz + t0 * dz, z1 = oz + t1 * dz;
  int c = nc == 1 ? 0 : channel;
  double target = -log1p(-u);
  int k0 = media_layer_of(L, z0), k1 = media_layer_of(L, z1);
  double total = tau_layers(L, c, z0, z1, k0, k1, dz, t1 - t0);
  if (!(target < total)) { /* the flight passes the box */
    for (int j = 0; j < nc; j++)
      tr->c[j] = j == c ? exp(-total) : exp(-tau_layers(L, j, z0, z1, k0, k1, dz, t1 - t0));
    spread(tr, nc);
    *pdf = *tr;
    return;
  }
  double t;
  int k;
  if (k0 == k1) {
    k = k0;
    t = t0 + target / L->lay[k].sig[c];
  } else {
    /* C* on the side the ray moves to; search the layer that holds it. */
    double cs = cum_in(L, c, k0, z0) + target * dz; /* C moves by tau |d_z| in the ray's z direction */
    const pw_layer *lay = L->lay;
    int n = (int)L->n, a = 1, b = n; /* C*'s bucket in the index: layers a - 1 .. b */
    double f = cs * L->bk_scale[c];
    if (f >= 0 && f < L->nd) {
      const uint32_t *bk = L->bk + (size_t)c * (L->n + 1) + (int)f;
      a = (int)bk[0], b = (int)bk[1];
    }
    int lo, hi;
    if (dz > 0) { /* smallest j in [1, n] with C_j > C*: k = j - 1 */
      lo = 1, hi = n;
      /* (j lies in [a, b] when C_{a-1} <= C* < C_b: then search there) */
      if ((a <= 1 || !(lay[a - 1].cum[c] > cs)) && (b >= n || lay[b].cum[c] > cs)) lo = a, hi = b;
      while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (lay[mid].cum[c] > cs)
          hi = mid;
        else
          lo = mid + 1;
      }
      k = lo - 1;
    } else { /* largest k in [0, n - 1] with C_k < C* */
      lo = 0, hi = n - 1;
      /* (k lies in [a', b'] when C_a' < C* (or a' = 0) and C_{b'+1} >= C*
       * (or b' = n - 1)) */
      int a1 = a > 2 ? a - 2 : 0, b1 = b < n - 1 ? b : n - 1;
      if ((a1 == 0 || lay[a1].cum[c] < cs) && (b1 >= n - 1 || !(lay[b1 + 1].cum[c] < cs))) lo = a1, hi = b1;
      while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (lay[mid].cum[c] < cs)
          lo = mid;
        else
          hi = mid - 1;
      }
      k = lo;
    }
    double s = lay[k].sig[c];
    double z = lay[k].z + (s > 0 ? (cs - lay[k].cum[c]) / s : 0.0);
    t = t0 + (z - z0) / dz;
  }
  t = fmin(fmax(t, t0), t1);
  double zt = oz + t * dz;
  k = media_layer_of(L, zt);
  mi->t = t;
  mi->p = v3_fma(r->o, t, r->d);
  mi->majorant = col(L->lay[k].sig[0], L->lay[k].sig[1], L->lay[k].sig[2]);
  fill_layer(L, k, mi);
  for (int j = 0; j < nc; j++) {
    tr->c[j] = j == c ? 1.0 - u : exp(-tau_between(L, j, z0, zt, dz, t - t0)); /* exp(-tau*) = 1 - u */
    pdf->c[j] = tr->c[j] * L->lay[k].sig[j];
  }
  spread(tr, nc);
  spread(pdf, nc);
}

static color layers_transmittance(const media_layers *L, const ray3 *r, double mint, double maxt) {
  double oz = media_layers_z(L, r->o), dz = media_layers_dz(L, r->d);
  double z0 = oz + mint * dz, z1 = oz + maxt * dz;
  color tr;
  int nc = L->nc;
  for (int j = 0; j < nc; j++) tr.c[j] = exp(-tau_between(L, j, z0, z1, dz, maxt - mint));
  spread(&tr, nc);
  return tr;
}

/* ---- the medium_ops ------------------------------------------------------------ */

static inline const media_layers *layers_of(const medium *m) {
  return &((const layered_medium *)m)->L;
}

static bool lm_intersect_aabb(const medium *m, const ray3 *r, double *mint, double *maxt) {
  return media_box_clip_at(&layers_of(m)->box, r, mint, maxt);
}

static color lm_majorant(const medium *m, const medium_interaction *mi) {
  (void)mi;
  return layers_of(m)->maj;
}

static void lm_coefficients(const medium *m, medium_interaction *mi) {
  layers_coefficients(layers_of(m), mi);
}

static void lm_sample_real(const medium *m, const ray3 *r, double mint, double maxt, double u, int channel,
                           medium_interaction *mi, color *tr, color *pdf) {
  layers_sample_real(layers_of(m), m, r, mint, maxt, u, channel, mi, tr, pdf);
}

static color lm_transmittance(const medium *m, const ray3 *r, double mint, double maxt) {
  return layers_transmittance(layers_of(m), r, mint, maxt);
}

const medium_ops layered_medium_ops = {.intersect_aabb = lm_intersect_aabb,
                                       .majorant = lm_majorant,
                                       .coefficients = lm_coefficients,
                                       .sample_real = lm_sample_real,
                                       .transmittance = lm_transmittance};
