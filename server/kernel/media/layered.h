/* Plane-parallel layers along the local z of a box (the unit cube under
 * to_world): what `piecewise` and `molecular_atmosphere` share. Layer k
 * spans local z in [z_k, z_{k+1}) with z_0 = 0, z_n = 1; sigma_t and the
 * albedo are constant in it; nothing interacts outside the box.
 *
 * Optical thickness is exact. With C(z) = int_0^z sigma(z') dz' (local z
 * units; C_k = C(z_k) = sum_{i<k} sigma_i (z_{i+1} - z_i), per channel), a
 * ray x(t) = o + t d (d unit in the world) with local z(t) = z_o + t d_z
 * has
 *
 *   tau(t0, t1) = |C(z(t1)) - C(z(t0))| / |d_z|   (layers crossed)
 *               = sigma_k (t1 - t0)                 (within one layer k),
 *
 * so transmittance is exp(-tau) with no tracking noise, and a free flight
 * tau* = -ln(1 - u) is inverted by a binary search over C (O(log N)):
 * the layer k with C_k <= C* < C_{k+1}, then z = z_k + (C* - C_k) /
 * sigma_k. A point's layer is floor(N z) (O(1)) for equal layers, a
 * binary search over the z_k otherwise.
 * Source: eradiate/mitsuba3 src/eradiate_plugins/media/piecewise.cpp. */
#ifndef RSW_MEDIA_LAYERED_H
#define RSW_MEDIA_LAYERED_H

#include <math.h>

#include "../kernel.h"
#include "media.h"

/* What a lookup in layer k reads, in one 64-byte line: C_k, the scaled
 * sigma_t per channel and z_k, the layer's bottom. n + 1 of them (the
 * last: C_n, the top; sigma_t 0). */
typedef struct pw_layer {
  double cum[3], sig[3], z, pad;
} pw_layer;

typedef struct media_layers {
  const xform *to_world; /* the box */
  uint32_t n;            /* layers */
  bool uniform;          /* z_k = k / n */
  int nc;                /* channels to compute: 1 (the rest copied) or 3 */
  pw_layer *lay;         /* n + 1, 64-byte aligned */
  double *alb;           /* 3 n: albedo per layer and channel */
  double nd;             /* n as a double */
  color maj;             /* the largest layer's sigma_t */
  /* From to_world (media_layers_finish): the box for clipping, and the
   * local z row of its inverse (affine: its last row is 0 0 0 1, so that
   * media_layers_z is xf_inv_point's z, bit for bit). */
  media_box box;
  double zrow[4];
  bool affine;
  /* An index over C for the free flights' search, per channel c < nc:
   * bk[c (n + 1) + j] (j = 0..n) is the smallest i in [1, n] with C_i >
   * j C_n / n (n if none), so that C* in [j, j + 1) C_n / n has its layer
   * between two entries; bk_scale[c] = n / C_n (-1: no index). The search
   * checks the bracket against C before it trusts it, so it finds the
   * layer the full binary search finds, bit for bit. */
  uint32_t *bk;
  double bk_scale[3];
} media_layers;

/* Allocate n layers (lay, alb) with z_k = k / n; false: out of memory
 * (what was allocated stays for media_layers_free). */
bool media_layers_alloc(media_layers *L, uint32_t n);
void media_layers_free(media_layers *L);
/* After the layers' sig (per channel, k < n) and alb, or to_world, changed:
 * C_k, the majorant and what media_layers keeps of to_world. */
void media_layers_finish(media_layers *L);

/* The local z of world point p (xf_inv_point(to_world, p).z), and of
 * world direction d (xf_inv_vector(...).z). */
static inline double media_layers_z(const media_layers *L, vec3 p) {
  if (!L->affine) return xf_inv_point(L->to_world, p).z;
  const double *m = L->zrow;
  return m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3];
}
static inline double media_layers_dz(const media_layers *L, vec3 d) {
  const double *m = L->zrow;
  return m[0] * d.x + m[1] * d.y + m[2] * d.z;
}

static inline int media_layer_of(const media_layers *L, double z) {
  if (L->uniform) {
    double f = z * L->nd;
    if (!(f > 0)) return 0;
    if (f >= L->nd) return (int)L->n - 1;
    return (int)f;
  }
  if (!(z > 0)) return 0;
  if (z >= 1.0) return (int)L->n - 1;
  int lo = 0, hi = (int)L->n - 1; /* the largest k with z_k <= z */
  while (lo < hi) {
    int mid = (lo + hi + 1) / 2;
    if (L->lay[mid].z <= z)
      lo = mid;
    else
      hi = mid - 1;
  }
  return lo;
}

/* A layered medium: the plugins' structs start with one of these, and
 * their medium_ops are layered_medium_ops (box clip, majorant,
 * coefficients, exact free flights and transmittance over the layers). */
typedef struct layered_medium {
  medium base;
  media_layers L;
} layered_medium;
extern const medium_ops layered_medium_ops;

#endif
