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

#include "../core/fastmath.h"
#include "../core/isa.h"
#include "../core/vexp.h"
#include "../kernel.h"
#include "media.h"

/* What a lookup in layer k reads, in one 64-byte line: C_k, the scaled
 * sigma_t per channel, z_k, the layer's bottom, and alb[3 k] (channel 0's
 * albedo: a collision's every channel where the albedo is gray). n + 1 of
 * them (the last: C_n, the top; sigma_t 0). */
typedef struct pw_layer {
  double cum[3], sig[3], z, alb0;
} pw_layer;

typedef struct media_layers {
  const xform *to_world; /* the box */
  uint32_t n;            /* layers */
  bool uniform;          /* z_k = k / n */
  int nc;                /* channels to compute: 1 (the rest copied) or 3 */
  pw_layer *lay;         /* n + 1, 64-byte aligned */
  double *alb;           /* 3 n: albedo per layer and channel */
  bool gray_alb;         /* every layer's 3 albedos equal (lay[k].alb0 serves) */
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
  /* cum[c (n + 1) + k] = lay[k].cum[c] (c < nc): the search's C_k packed,
   * 8 to a cache line where lay holds one (the probes of a collision's
   * search stay in a few lines instead of one line each). */
  double *cum;
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
    /* !(f > 0): 0; f >= n: n - 1; else (int) f; as a clamp to [0, n - 1]
     * (minsd and maxsd, no branch: a ray's ends decide it, at the ground
     * or the top as often as not): (int) f is n - 1 on [n - 1, n) too. */
    double f = z * L->nd;
    return (int)rsw_sel_min(rsw_sel_max(f, 0.0), L->nd - 1.0);
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

/* The tracking over the layers (layered_medium_ops' sample_real,
 * transmittance and coefficients), inline so that volpath calls them with
 * the segment's numbers in registers (an out-of-line call reads them back
 * from the caller's stores, and its results are read back the same way). */

/* C(z), z in layer k. */
static inline double media_layers_cum_in(const media_layers *L, int c, int k, double z) {
  double zc = rsw_sel_max(0.0, rsw_sel_min(1.0, z)); /* (z < 0 ? 0 : z > 1 ? 1 : z, -0 and NaN kept) */
  const pw_layer *y = &L->lay[k];
  return y->cum[c] + y->sig[c] * (zc - y->z);
}

/* tau over [t0, t1] in channel c; z0, z1 the local z at both ends, k0, k1
 * their layers. */
static inline double media_layers_tau(const media_layers *L, int c, double z0, double z1, int k0, int k1,
                                      double dz, double len) {
  if (k0 == k1) return L->lay[k0].sig[c] * len;
  return fabs(media_layers_cum_in(L, c, k1, z1) - media_layers_cum_in(L, c, k0, z0)) / fabs(dz);
}

/* Layer k's sigma_t and sigma_s (what media_layers_fill writes), returned
 * rather than stored into a medium_interaction: a bundle's pages read them
 * at once, where whole-colour loads of a struct's just-stored channels
 * waited on the store buffer. */
static inline void media_layers_sigmas(const media_layers *L, int k, color *sigma_t, color *sigma_s) {
  const pw_layer *y = &L->lay[k];
  for (int c = 0; c < 3; c++) {
    double s = y->sig[c];
    sigma_t->c[c] = s;
    sigma_s->c[c] = s * (L->gray_alb ? y->alb0 : L->alb[3 * k + c]); /* (the line already read) */
  }
}

static inline void media_layers_fill(const media_layers *L, int k, medium_interaction *mi) {
  color st, ss;
  media_layers_sigmas(L, k, &st, &ss);
  mi->sigma_t = st;
  mi->sigma_s = ss;
  for (int c = 0; c < 3; c++) mi->sigma_n.c[c] = rsw_fmax(mi->majorant.c[c] - st.c[c], 0.0);
}

static inline void media_layers_coefficients(const media_layers *L, medium_interaction *mi) {
  media_layers_fill(L, media_layer_of(L, media_layers_z(L, mi->p)), mi);
}

/* 1 + 2^-40: media_layers_sample_real's margin for a flight that passes
 * without its log. */
#define MEDIA_LAYERS_PASS_MARGIN (1.0 + 0x1p-40)

/* A free flight over [t0, t1] of a ray in the drawn channel c (0 when
 * nc = 1): the pieces media_layers_sample_real and its batch
 * (media_layers_sample_real_batch) share, so that both give the same bits.
 * oz, dz: the ray's local z origin and direction; z0, z1 (k0, k1): the
 * ends' local z (layers); total: tau over [t0, t1] in channel c. */
typedef struct media_flight {
  double t0, t1, oz, dz, z0, z1, total;
  int c, k0, k1;
} media_flight;

static inline void media_flight_setup(const media_layers *L, const ray3 *r, double t0, double t1, int channel,
                                      media_flight *f) {
  f->t0 = t0, f->t1 = t1;
  f->c = L->nc == 1 ? 0 : channel;
  f->oz = media_layers_z(L, r->o), f->dz = media_layers_dz(L, r->d);
  f->z0 = f->oz + t0 * f->dz, f->z1 = f->oz + t1 * f->dz;
  f->k0 = media_layer_of(L, f->z0), f->k1 = media_layer_of(L, f->z1);
  f->total = media_layers_tau(L, f->c, f->z0, f->z1, f->k0, f->k1, f->dz, t1 - t0);
}

/* The flight passes the box when tau* >= total. tau* = -ln(1 - u) >= u,
 * and tau* is computed within 3 ulp of it (core/fastmath.h), so u >= total
 * (1 + 2^-40) (the product rounded down by at most an ulp) makes the
 * computed tau* >= total (1 + 2^-40) (1 - 2^-52)^4 > total: the flight
 * passes, as the log would say, without the log (most flights through a
 * thin atmosphere). A NaN or infinite total fails the test and takes the
 * log. */
static inline bool media_flight_passes_fast(double u, double total) {
  return u >= total * MEDIA_LAYERS_PASS_MARGIN;
}

/* A passed flight's transmittance (= its pdf): exp(-total) in channel c,
 * the others' over the same ends (one channel: copied). */
static inline color media_flight_passed(const media_layers *L, const media_flight *f) {
  color x = col1(exp(-f->total));
  for (int j = 0; j < L->nc; j++)
    if (j != f->c) x.c[j] = exp(-media_layers_tau(L, j, f->z0, f->z1, f->k0, f->k1, f->dz, f->t1 - f->t0));
  return x;
}

/* A collision at optical thickness target (< total) in channel c: its
 * distance *t in [t0, t1] and layer *k. Within a layer z = z_k + (C* -
 * C_k) / sigma_k; across layers the index (bk) brackets C*, then a binary
 * search over C. */
static inline void media_flight_collide(const media_layers *L, const media_flight *f, double target,
                                        double *tp, int *kp) {
  int c = f->c, k0 = f->k0;
  double t0 = f->t0, dz = f->dz, t;
  int k;
  if (k0 == f->k1) {
    k = k0;
    t = t0 + target / L->lay[k].sig[c];
  } else {
    /* C* on the side the ray moves to; search the layer that holds it. */
    double cs = media_layers_cum_in(L, c, k0, f->z0) +
                target * dz; /* C moves by tau |d_z| in the ray's z direction */
    const double *cum = L->cum + (size_t)c * (L->n + 1);
    int n = (int)L->n, a = 1, b = n; /* C*'s bucket in the index: layers a - 1 .. b */
    double fb = cs * L->bk_scale[c];
    if (fb >= 0 && fb < L->nd) {
      const uint32_t *bk = L->bk + (size_t)c * (L->n + 1) + (int)fb;
      a = (int)bk[0], b = (int)bk[1];
    }
    int lo, hi;
    if (dz > 0) { /* smallest j in [1, n] with C_j > C*: k = j - 1 */
      lo = 1, hi = n;
      /* (j lies in [a, b] when C_{a-1} <= C* < C_b: then search there) */
      if ((a <= 1 || !(cum[a - 1] > cs)) && (b >= n || cum[b] > cs)) lo = a, hi = b;
      while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (cum[mid] > cs)
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
      if ((a1 == 0 || cum[a1] < cs) && (b1 >= n - 1 || !(cum[b1 + 1] < cs))) lo = a1, hi = b1;
      while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (cum[mid] < cs)
          lo = mid;
        else
          hi = mid - 1;
      }
      k = lo;
    }
    const pw_layer *y = &L->lay[k];
    double s = y->sig[c];
    double z = y->z + (s > 0 ? (cs - y->cum[c]) / s : 0.0);
    t = t0 + (z - f->z0) / dz;
  }
  t = rsw_fmin(rsw_fmax(t, t0), f->t1);
  *tp = t;
  *kp = media_layer_of(L, f->oz + t * dz);
}

/* A collision at t in layer k: the transmittance to it, exp(-tau*) = 1 - u
 * in channel c and the others' over [z0, z(t)] (one channel: copied), and
 * the pdf, tr sigma_t. */
static inline void media_flight_weights(const media_layers *L, const media_flight *f, double u, double t,
                                        int k, color *tr, color *pdf) {
  const pw_layer *y = &L->lay[k];
  color x = col1(1.0 - u), q;
  for (int j = 0; j < L->nc; j++)
    if (j != f->c)
      x.c[j] = exp(-media_layers_tau(L, j, f->z0, f->oz + t * f->dz, f->k0, k, f->dz, t - f->t0));
  if (L->nc == 1) {
    q = col1(x.c[0] * y->sig[0]);
  } else {
    for (int j = 0; j < 3; j++) q.c[j] = x.c[j] * y->sig[j];
  }
  *tr = x;
  *pdf = q;
}

/* The medium interaction of a collision at t in layer k of ray r in medium
 * m (whose flight began at mint): what media_layers_sample_real writes. */
static inline void media_layers_collision(const media_layers *L, const medium *m, const ray3 *r, double mint,
                                          double t, int k, medium_interaction *mi) {
  const pw_layer *y = &L->lay[k];
  mi->medium = m;
  mi->wi = v3_neg(r->d);
  mi->mint = mint;
  mi->t = t;
  mi->p = v3_fma(r->o, t, r->d);
  mi->majorant = col(y->sig[0], y->sig[1], y->sig[2]);
  media_layers_fill(L, k, mi);
}

/* A free flight over [mint, maxt] (within intersect_aabb's interval: the
 * caller clips) with the random number u in channel `channel`: a collision
 * (mi->t finite, mi filled) or a pass (mi->t infinite; mi's medium, wi and
 * mint set); tr the transmittance to it, pdf its density (layered.h's
 * head gives the inversion). weigh_pass false: a pass's tr and pdf are
 * left at 1 instead (no exp), for a caller to whom a pass's weight does
 * not matter (a path that ends there); the decision, and a collision's
 * numbers, are the same. Always inline: volpath's atmosphere renders 2 %
 * faster than with GCC's one out-of-line copy (2026-11-29). */
static inline __attribute__((always_inline)) void
media_layers_sample_real_w(const media_layers *L, const medium *m, const ray3 *r, double mint, double maxt,
                           double u, int channel, bool weigh_pass, medium_interaction *mi, color *tr,
                           color *pdf) {
  media_flight f;
  media_flight_setup(L, r, mint, maxt, channel, &f);
  double target = 0.0;
  bool pass = media_flight_passes_fast(u, f.total);
  if (!pass) {
    target = rsw_neg_log1m(u); /* (-log1p(-u) within 2 ulp: core/fastmath.h) */
    pass = !(target < f.total);
  }
  if (pass) {
    mi->medium = m;
    mi->wi = v3_neg(r->d);
    mi->t = INFINITY;
    mi->mint = mint;
    *tr = *pdf = weigh_pass ? media_flight_passed(L, &f) : col1(1.0);
    return;
  }
  double t;
  int k;
  media_flight_collide(L, &f, target, &t, &k);
  media_layers_collision(L, m, r, mint, t, k, mi);
  media_flight_weights(L, &f, u, t, k, tr, pdf);
}

static inline void media_layers_sample_real(const media_layers *L, const medium *m, const ray3 *r,
                                            double mint, double maxt, double u, int channel,
                                            medium_interaction *mi, color *tr, color *pdf) {
  media_layers_sample_real_w(L, m, r, mint, maxt, u, channel, true, mi, tr, pdf);
}

/* n free flights at once, structure of arrays (media_layers_sample_real
 * for each: lane i's numbers are its call's, bit for bit). In: the rays
 * o[3], d[3] (world; n each), their clipped intervals [mint, maxt], the
 * random numbers u and the drawn channels (NULL: all 0). Out (n each): t,
 * the collision's distance (INFINITY: the flight passed), layer, its layer
 * (-1: passed), and the transmittance tr and pdf per channel. A collision's
 * medium interaction is media_layers_collision(L, m, ray, mint, t, layer). */
typedef struct media_flight_batch {
  int n;
  const double *o[3], *d[3];
  const double *mint, *maxt, *u;
  const int *channel;
  double *t;
  int *layer;
  double *tr[3], *pdf[3];
} media_flight_batch;

/* The flights of b at ISA isa (the setup in its lanes where the layers
 * are equal and to_world affine; the logs, exps and searches per flight,
 * passes and collisions apart). Reads L; thread-safe. */
void media_layers_sample_real_batch(rsw_isa isa, const media_layers *L, const media_flight_batch *b);

/* n transmittances at once (media_layers_transmittance for each, bit for
 * bit): rays o[3], d[3] over [mint, maxt] (n each); tr[c][i] channel c of
 * ray i's. ISA, lanes and thread safety as media_layers_sample_real_batch. */
void media_layers_transmittance_batch(rsw_isa isa, const media_layers *L, int n, const double *const *o,
                                      const double *const *d, const double *mint, const double *maxt,
                                      double *const *tr);

/* The transmittance over [mint, maxt] of r: exp(-tau) per channel
 * (media_flight_setup's and media_flight_passed's numbers in channel 0,
 * written out: through the struct the atmosphere bench renders ~0.8%
 * slower). */
static inline __attribute__((always_inline)) color
media_layers_transmittance(const media_layers *L, const ray3 *r, double mint, double maxt) {
  double oz = media_layers_z(L, r->o), dz = media_layers_dz(L, r->d);
  double z0 = oz + mint * dz, z1 = oz + maxt * dz;
  int k0 = media_layer_of(L, z0), k1 = media_layer_of(L, z1);
  color tr = col1(exp(-media_layers_tau(L, 0, z0, z1, k0, k1, dz, maxt - mint))); /* (nc 1: copied) */
  for (int j = 1; j < L->nc; j++) tr.c[j] = exp(-media_layers_tau(L, j, z0, z1, k0, k1, dz, maxt - mint));
  return tr;
}

/* A layered medium: the plugins' structs start with one of these, and
 * their medium_ops are layered_medium_ops (box clip, majorant,
 * coefficients, exact free flights and transmittance over the layers). */
typedef struct layered_medium {
  medium base;
  media_layers L;
  /* A bundle of pages (render_ctx.bundle > 3, a plugin whose prepare()
   * fills them): the layers at pages 1.. (their box and levels L's), read
   * while rsw_page names one; NULL: none. */
  media_layers *Lp;
} layered_medium;
extern const medium_ops layered_medium_ops;

/* m's medium_extremes over its pages' columns (each page's optical
 * thickness top to bottom per channel), after the layers are filled. */
static inline void layered_extremes(layered_medium *m, int pages) {
  double ext[3 * RENDER_MAX_PAGES] = {0};
  for (int p = 0; p < pages; p++) {
    const media_layers *L = p ? &m->Lp[p - 1] : &m->L;
    for (int c = 0; c < 3; c++) ext[3 * p + c] = L->lay[L->n].cum[c < L->nc ? c : 0];
  }
  medium_extremes(&m->base, ext, 3 * pages);
}

/* The layers m answers with at the calling thread's page (rsw_page). */
static inline const media_layers *layered_layers(const medium *m) {
  const layered_medium *lm = (const layered_medium *)m;
  int p = rsw_page;
  return p ? &lm->Lp[p - 1] : &lm->L;
}

/* A bundle of pages: the transmittance over [mint, maxt] of r at pages
 * p0..pages-1 but page skip (-1: none; its tr[skip] left as it was) into
 * tr[p], the levels (and so the layers crossed) worked
 * out once, and the pages' exps in one batch (core/vexp.c: libm's
 * exp in vector lanes, the same bits as libm's on a machine whose libm
 * uses its FMA variant, as Debian 12's on x86-64 with FMA; within 1 ulp
 * elsewhere, and the same at every ISA): each page's
 * media_layers_transmittance, bit for bit where libm's bits are met.
 * One libm call per channel was a fifth of a bundled atmosphere. */
static inline void layered_transmittance_pages(const layered_medium *lm, const ray3 *r, double mint,
                                               double maxt, int p0, int pages, int skip, color *tr) {
  const media_layers *L = &lm->L;
  double oz = media_layers_z(L, r->o), dz = media_layers_dz(L, r->d);
  double z0 = oz + mint * dz, z1 = oz + maxt * dz;
  int k0 = media_layer_of(L, z0), k1 = media_layer_of(L, z1);
  enum {
    NX = (3 * RENDER_MAX_PAGES + 7) / 8 * 8 /* whole vectors of 8 */
  };
  double x[NX], e[NX];
  int n = 0;
  for (int p = p0; p < pages; p++) {
    const media_layers *Lp = p ? &lm->Lp[p - 1] : L;
    if (p == skip) continue;
    for (int c = 0; c < 3; c++) x[n++] = -media_layers_tau(Lp, c, z0, z1, k0, k1, dz, maxt - mint);
  }
  int nv = (n + 7) / 8 * 8;
  for (int i = n; i < nv; i++) x[i] = 0.0;
  vexp_batch(rsw_isa_get(), nv, x, e);
  n = 0;
  for (int p = p0; p < pages; p++)
    for (int c = 0; c < 3 && p != skip; c++) tr[p].c[c] = e[n++];
}

#endif
