/* The batched free flights' setup (media/layered.c
 * media_layers_sample_real_batch) in double lanes, compiled per ISA by
 * simd/lanes_all.h: media_flight_setup and media_flight_passes_fast of
 * media/layered.h for layers of equal thickness under an affine to_world,
 * the same operations in the same order without FMA contraction, so each
 * lane's numbers are the scalar ones bit for bit
 * (tests/kernel/media/test_layered.c checks it at every ISA). */
#include "../simd/simd.h"

/* n flights. geo: the local z row of to_world's inverse (4), the layer
 * count N as a double and N - 1; lay: the layers as media_layers.lay's
 * 8 doubles each (cum[3], sig[3], z, alb0); o[3], d[3]: the rays; t0, t1,
 * u; c: the drawn channel (0 when nc = 1). out[0..4]: oz, dz, z0, z1,
 * total; k0, k1: the ends' layers; fast: 1 where the flight passes
 * without its log (media_flight_passes_fast). u and fast NULL: the setup
 * alone (a transmittance's). */
SIMD_ISA_DECL(void, flight_setup,
              (int n, const double *geo, const double *lay, const double *const *o, const double *const *d,
               const double *t0, const double *t1, const double *u, const int *c, double *const *out, int *k0,
               int *k1, unsigned char *fast));

#ifdef LANES_FN
/* WD int32 lanes: layer indices (N < 2^31). */
typedef int vin __attribute__((vector_size(2 * W)));

/* media_layer_of for equal layers: 0 unless f = z N > 0, N - 1 from
 * f >= N on, else (int) f (the lanes converted are those in range, through
 * int32: every ISA has that conversion, not all the int64 one). */
SIMD_FN vln flight_layer_of(vdn z, double nd, double top) {
  vdn f = z * nd;
  vln pos = f > 0.0, high = f >= nd;
  vdn k = dsel(high, (vdn){0} + top, dsel(pos, f, (vdn){0}));
  return __builtin_convertvector(__builtin_convertvector(k, vin), vln);
}

/* lay[8 k + j] in each lane (a layer's C, sigma or z), element by
 * element into the vector (not through an array: a vector load of scalar
 * stores stalls their forwarding). */
SIMD_FN vdn flight_gather(const double *lay, vln k, vin j) {
  vdn x = (vdn){0};
  for (int l = 0; l < WD; l++) x[l] = lay[8 * k[l] + j[l]];
  return x;
}

/* media_layers_cum_in: C at z in the layer whose C_k, sigma_k, z_k these
 * are (z clamped to [0, 1], NaN kept). */
SIMD_FN vdn flight_cum_in(vdn cum, vdn sig, vdn zk, vdn z) {
  vdn zc = dsel(z < 0.0, (vdn){0}, dsel(z > 1.0, (vdn){0} + 1.0, z));
  return cum + sig * (zc - zk);
}

LANES_ATTR void LANES_FN(flight_setup)(int n, const double *geo, const double *lay, const double *const *o,
                                       const double *const *d, const double *t0, const double *t1,
                                       const double *u, const int *c, double *const *out, int *k0, int *k1,
                                       unsigned char *fast) {
  const double m0 = geo[0], m1 = geo[1], m2 = geo[2], m3 = geo[3], nd = geo[4], top = geo[5];
  for (int i0 = 0; i0 < n; i0 += WD) {
    int cnt = n - i0 < WD ? n - i0 : WD;
    /* Whole vectors loaded as such; a partial tail through a copy of
     * constant length that repeats its last flight (lane by lane inserts
     * of a variable count went through memory). */
    const double *src[9] = {o[0], o[1], o[2], d[0], d[1], d[2], t0, t1, u ? u : t0};
    vdn v[9];
    vin ch;
    if (cnt == WD) {
      for (int a = 0; a < 9; a++) __builtin_memcpy(&v[a], src[a] + i0, sizeof v[a]);
      __builtin_memcpy(&ch, c + i0, sizeof ch);
    } else {
      double in[9][WD];
      int cc[WD];
      for (int k = 0; k < WD; k++) {
        int j = i0 + (k < cnt ? k : cnt - 1);
        for (int a = 0; a < 9; a++) in[a][k] = src[a][j];
        cc[k] = c[j];
      }
      for (int a = 0; a < 9; a++) __builtin_memcpy(&v[a], in[a], sizeof v[a]);
      __builtin_memcpy(&ch, cc, sizeof ch);
    }
    /* media_layers_z, media_layers_dz (affine) */
    vdn oz = m0 * v[0] + m1 * v[1] + m2 * v[2] + m3;
    vdn dz = m0 * v[3] + m1 * v[4] + m2 * v[5];
    vdn z0 = oz + v[6] * dz, z1 = oz + v[7] * dz;
    vln ka = flight_layer_of(z0, nd, top), kb = flight_layer_of(z1, nd, top);
    /* Each end's layer: C_k, sigma_k and z_k in the lane's channel. */
    vin cs = ch + 3, zs = (vin){0} + 6;
    vdn y[6] = {flight_gather(lay, ka, ch), flight_gather(lay, ka, cs), flight_gather(lay, ka, zs),
                flight_gather(lay, kb, ch), flight_gather(lay, kb, cs), flight_gather(lay, kb, zs)};
    /* media_layers_tau: within one layer sigma_k (t1 - t0), else
     * |C(z1) - C(z0)| / |dz| (both computed, one kept) */
    vdn within = y[1] * (v[7] - v[6]);
    vdn across = dabs(flight_cum_in(y[3], y[4], y[5], z1) - flight_cum_in(y[0], y[1], y[2], z0)) / dabs(dz);
    vdn total = dsel(ka == kb, within, across);
    vln quick = v[8] >= total * (1.0 + 0x1p-40); /* (MEDIA_LAYERS_PASS_MARGIN) */
    for (int k = 0; k < cnt; k++) {
      int j = i0 + k;
      out[0][j] = oz[k], out[1][j] = dz[k], out[2][j] = z0[k], out[3][j] = z1[k], out[4][j] = total[k];
      k0[j] = (int)ka[k], k1[j] = (int)kb[k];
      if (fast) fast[j] = quick[k] != 0;
    }
  }
}
#endif
