/* `piecewise`: Eradiate's plane-parallel medium. sigma_t (scaled by
 * `scale`) and albedo are constant in each of N layers stacked along the
 * local z axis of the sigma_t volume's box (a [1, 1, N] grid: layer k is
 * local z in [k/N, (k+1)/N)); nothing interacts outside the box.
 *
 * Optical thickness is exact. With C(z) = int_0^z sigma(z') dz' (local z
 * units; C_k = C(k/N) = sum_{i<k} sigma_i / N, kept per channel and
 * refreshed whenever sigma_t or scale may have changed), a ray
 * x(t) = o + t d (d unit in the world) with local z(t) = z_o + t d_z has
 *
 *   tau(t0, t1) = |C(z(t1)) - C(z(t0))| / |d_z|   (layers crossed)
 *               = sigma_k (t1 - t0)                 (within one layer k),
 *
 * so transmittance is exp(-tau) with no tracking noise, and a free flight
 * tau* = -ln(1 - u) is inverted by a binary search over C (O(log N)):
 * the layer k with C_k <= C* < C_{k+1}, then z = k/N + (C* - C_k) /
 * sigma_k. A point's layer is floor(N z) (O(1)).
 * Source: eradiate/mitsuba3 src/eradiate_plugins/media/piecewise.cpp
 * (parameters, defaults: albedo 0.75, sigma_t 1, scale 1). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../scene/loader.h"
#include "../scene/params.h"
#include "media.h"

/* What a lookup in layer k reads, in one 64-byte line: C_k, the scaled
 * sigma_t per channel and k / n, the layer's bottom (no division per
 * lookup). n + 1 of them (the last: C_n, the top; sigma_t 0). */
typedef struct pw_layer {
  double cum[3], sig[3], z, pad;
} pw_layer;

typedef struct piecewise_medium {
  medium base;
  volume *sigma_t, *albedo;
  uint32_t n;    /* layers */
  pw_layer *lay; /* n + 1, 64-byte aligned */
  double *alb;   /* 3 n: albedo per layer and channel */
  double nd;     /* n as a double */
  color maj;     /* the largest layer's sigma_t */
} piecewise_medium;

static inline int layer_of(const piecewise_medium *pw, double z) {
  double f = z * pw->nd;
  if (!(f > 0)) return 0;
  if (f >= pw->nd) return (int)pw->n - 1;
  return (int)f;
}

/* C(z), z in layer k. */
static inline double cum_in(const piecewise_medium *pw, int c, int k, double z) {
  double zc = z < 0.0 ? 0.0 : z > 1.0 ? 1.0 : z;
  const pw_layer *L = &pw->lay[k];
  return L->cum[c] + L->sig[c] * (zc - L->z);
}

/* tau over [t0, t1] in channel c; z0, z1 the local z at both ends, k0, k1
 * their layers. */
static inline double tau_layers(const piecewise_medium *pw, int c, double z0, double z1, int k0, int k1,
                                double dz, double len) {
  if (k0 == k1) return pw->lay[k0].sig[c] * len;
  return fabs(cum_in(pw, c, k1, z1) - cum_in(pw, c, k0, z0)) / fabs(dz);
}

static inline double tau_between(const piecewise_medium *pw, int c, double z0, double z1, double dz,
                                 double len) {
  return tau_layers(pw, c, z0, z1, layer_of(pw, z0), layer_of(pw, z1), dz, len);
}

static bool pw_intersect_aabb(const medium *m, const ray3 *r, double *mint, double *maxt) {
  return media_box_clip(&((const piecewise_medium *)m)->sigma_t->to_world, r, mint, maxt);
}

static color pw_majorant(const medium *m, const medium_interaction *mi) {
  (void)mi;
  return ((const piecewise_medium *)m)->maj;
}

static void fill_layer(const piecewise_medium *pw, int k, medium_interaction *mi) {
  for (int c = 0; c < 3; c++) {
    double s = pw->lay[k].sig[c];
    mi->sigma_t.c[c] = s;
    mi->sigma_s.c[c] = s * pw->alb[3 * k + c];
    mi->sigma_n.c[c] = fmax(mi->majorant.c[c] - s, 0.0);
  }
}

static void pw_coefficients(const medium *m, medium_interaction *mi) {
  const piecewise_medium *pw = (const piecewise_medium *)m;
  vec3 pl = xf_inv_point(&pw->sigma_t->to_world, mi->p);
  fill_layer(pw, layer_of(pw, pl.z), mi);
}

/* Channels to compute: one when every channel holds the same layers (mono,
 * one-channel grids), the rest copied. */
static inline int n_channels(const piecewise_medium *pw) {
  return pw->base.has_spectral_extinction ? 3 : 1;
}

static inline void spread(color *x, int nc) {
  if (nc == 1) x->c[1] = x->c[2] = x->c[0];
}

static void pw_sample_real(const medium *m, const ray3 *r, double mint, double maxt, double u, int channel,
                           medium_interaction *mi, color *tr, color *pdf) {
  const piecewise_medium *pw = (const piecewise_medium *)m;
  const xform *tw = &pw->sigma_t->to_world;
  int nc = n_channels(pw);
  double t0 = mint, t1 = maxt; /* within intersect_aabb's interval (the caller clips) */
  mi->medium = m;
  mi->wi = v3_neg(r->d);
  mi->t = INFINITY;
  mi->mint = t0;
  double oz = xf_inv_point(tw, r->o).z, dz = xf_inv_vector(tw, r->d).z;
  double z0 = oz + t0 * dz, z1 = oz + t1 * dz;
  int c = nc == 1 ? 0 : channel;
  double target = -log1p(-u);
  int k0 = layer_of(pw, z0), k1 = layer_of(pw, z1);
  double total = tau_layers(pw, c, z0, z1, k0, k1, dz, t1 - t0);
  if (!(target < total)) { /* the flight passes the box */
    for (int j = 0; j < nc; j++)
      tr->c[j] = j == c ? exp(-total) : exp(-tau_layers(pw, j, z0, z1, k0, k1, dz, t1 - t0));
    spread(tr, nc);
    *pdf = *tr;
    return;
  }
  double t;
  int k;
  if (k0 == k1) {
    k = k0;
    t = t0 + target / pw->lay[k].sig[c];
  } else {
    /* C* on the side the ray moves to; search the layer that holds it. */
    double cs = cum_in(pw, c, k0, z0) + target * dz; /* C moves by tau |d_z| in the ray's z direction */
    const pw_layer *lay = pw->lay;
    int lo, hi;
    if (dz > 0) { /* smallest j in [1, n] with C_j > C*: k = j - 1 */
      lo = 1, hi = (int)pw->n;
      while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (lay[mid].cum[c] > cs)
          hi = mid;
        else
          lo = mid + 1;
      }
      k = lo - 1;
    } else { /* largest k in [0, n - 1] with C_k < C* */
      lo = 0, hi = (int)pw->n - 1;
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
  k = layer_of(pw, zt);
  mi->t = t;
  mi->p = v3_fma(r->o, t, r->d);
  mi->majorant = col(pw->lay[k].sig[0], pw->lay[k].sig[1], pw->lay[k].sig[2]);
  fill_layer(pw, k, mi);
  for (int j = 0; j < nc; j++) {
    tr->c[j] = j == c ? 1.0 - u : exp(-tau_between(pw, j, z0, zt, dz, t - t0)); /* exp(-tau*) = 1 - u */
    pdf->c[j] = tr->c[j] * pw->lay[k].sig[j];
  }
  spread(tr, nc);
  spread(pdf, nc);
}

static color pw_transmittance(const medium *m, const ray3 *r, double mint, double maxt) {
  const piecewise_medium *pw = (const piecewise_medium *)m;
  const xform *tw = &pw->sigma_t->to_world;
  double oz = xf_inv_point(tw, r->o).z, dz = xf_inv_vector(tw, r->d).z;
  double z0 = oz + mint * dz, z1 = oz + maxt * dz;
  color tr;
  int nc = n_channels(pw);
  for (int j = 0; j < nc; j++) tr.c[j] = exp(-tau_between(pw, j, z0, z1, dz, maxt - mint));
  spread(&tr, nc);
  return tr;
}

static const medium_ops pw_ops = {.intersect_aabb = pw_intersect_aabb,
                                  .majorant = pw_majorant,
                                  .coefficients = pw_coefficients,
                                  .sample_real = pw_sample_real,
                                  .transmittance = pw_transmittance};

/* A grid value of layer k in channel c (one-channel grids: every channel). */
static inline double grid_at(const volume *v, uint32_t k, int c) {
  return v->data[(size_t)k * v->channels + (v->channels == 3 ? (size_t)c : 0)];
}

/* Layer values, cumulative thickness, majorant: O(N), after sigma_t, albedo
 * or scale changed (prepare() runs before every render, after the volumes'
 * own prepare). */
static void pw_refresh(piecewise_medium *pw) {
  uint32_t n = pw->n;
  bool alb_grid = pw->albedo->res[2] > 1;
  double amax = 0.0;
  color mx = col1(0.0);
  for (int c = 0; c < 3; c++) pw->lay[0].cum[c] = 0.0, pw->lay[n].sig[c] = 0.0;
  for (uint32_t k = 0; k < n; k++)
    for (int c = 0; c < 3; c++) {
      double s = pw->base.scale * grid_at(pw->sigma_t, k, c);
      double a = grid_at(pw->albedo, alb_grid ? k : 0, c);
      pw->lay[k].sig[c] = s;
      pw->alb[3 * k + c] = a;
      pw->lay[k + 1].cum[c] = pw->lay[k].cum[c] + s / n;
      if (s > mx.c[c]) mx.c[c] = s;
      if (a > amax) amax = a;
    }
  pw->maj = mx;
  pw->base.absorbing_only = amax == 0.0;
  pw->base.has_spectral_extinction = pw->sigma_t->channels == 3;
}

static rsw_status pw_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  (void)rc, (void)err;
  pw_refresh((piecewise_medium *)o);
  return RSW_OK;
}

static void pw_parameters_changed(object *o) {
  pw_refresh((piecewise_medium *)o);
}

static void pw_destroy(object *o) {
  piecewise_medium *pw = (piecewise_medium *)o;
  free(pw->lay);
  free(pw->alb);
  free(pw);
}

static bool same_xform(const xform *a, const xform *b) {
  return memcmp(a->m, b->m, sizeof a->m) == 0;
}

static rsw_status pw_create(loader *ld, node *n, object **out) {
  piecewise_medium *pw = calloc(1, sizeof *pw);
  if (!pw) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "piecewise: out of memory");
  pw->base.ops = &pw_ops;
  rsw_status st = medium_read_common(ld, n, &pw->base);
  if (!st) st = ld_volume(ld, n, "sigma_t", 1.0, 0.0, INFINITY, &pw->sigma_t);
  if (!st) st = ld_volume(ld, n, "albedo", 0.75, 0.0, 1.0, &pw->albedo);
  if (!st && (pw->sigma_t->res[0] != 1 || pw->sigma_t->res[1] != 1))
    st = ld_fail(ld, n, "sigma_t", RSW_ERR_INVALID,
                 "piecewise: sigma_t must be a [1, 1, N] grid (layers along z), got %ux%ux%u (x, y, z)",
                 pw->sigma_t->res[0], pw->sigma_t->res[1], pw->sigma_t->res[2]);
  if (!st) {
    const volume *a = pw->albedo;
    bool one = a->res[0] == 1 && a->res[1] == 1 && a->res[2] == 1;
    bool layers = a->res[0] == 1 && a->res[1] == 1 && a->res[2] == pw->sigma_t->res[2];
    if (!one && !layers)
      st = ld_fail(
          ld, n, "albedo", RSW_ERR_INVALID,
          "piecewise: albedo must be constant or a [1, 1, %u] grid like sigma_t, got %ux%ux%u (x, y, z)",
          pw->sigma_t->res[2], a->res[0], a->res[1], a->res[2]);
    else if (layers && !one && !same_xform(&a->to_world, &pw->sigma_t->to_world))
      st = ld_fail(ld, n, "albedo", RSW_ERR_INVALID,
                   "piecewise: the albedo grid must have the same to_world as sigma_t (its layers are "
                   "sigma_t's)");
  }
  if (!st) {
    pw->n = pw->sigma_t->res[2];
    pw->lay = aligned_alloc(64, ((size_t)pw->n + 1) * sizeof *pw->lay);
    pw->alb = malloc(3 * (size_t)pw->n * sizeof *pw->alb);
    pw->nd = pw->n;
    if (pw->lay) {
      memset(pw->lay, 0, ((size_t)pw->n + 1) * sizeof *pw->lay);
      for (uint32_t k = 0; k <= pw->n; k++) pw->lay[k].z = (double)k / pw->n;
    }
    if (!pw->lay || !pw->alb) st = ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "piecewise: out of memory");
  }
  if (st) {
    pw_destroy(&pw->base.base);
    return st;
  }
  *out = &pw->base.base;
  return RSW_OK;
}

static void pw_traverse(object *o, param_visitor *v) {
  piecewise_medium *pw = (piecewise_medium *)o;
  medium_traverse_common(&pw->base, v);
  pv_object(v, "sigma_t", &pw->sigma_t->base, 0.0, INFINITY);
  pv_object(v, "albedo", &pw->albedo->base, 0.0, 1.0);
}

const plugin plugin_piecewise = {.name = "piecewise",
                                 .cls = CLS_MEDIUM,
                                 .create = pw_create,
                                 .destroy = pw_destroy,
                                 .prepare = pw_prepare,
                                 .ops = &pw_ops,
                                 .traverse = pw_traverse,
                                 .parameters_changed = pw_parameters_changed};
