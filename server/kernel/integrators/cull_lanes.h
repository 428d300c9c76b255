/* The wave's ray culls for a batch of rays (integrators/path.c
 * wave_trace): ray_may_hit's cheap half slab test against the scene's
 * padded box and, for camera rays, accel.h's accel_box_misses, in double
 * lanes compiled per ISA by simd/lanes_all.h. The comparisons and products
 * are those of the scalar tests, in double and without FMA contraction,
 * so each lane's verdict is the scalar one, NaNs included
 * (tests/kernel/integrators/test_wave.c checks it at every ISA). */
#include "../simd/simd.h"

/* n rays, o[c][i] and d[c][i] their origins' and directions' component c;
 * pad_lo, pad_hi: ray_may_hit's padded box (3 each); lo, hi: accel_box's
 * (3 each), or NULL for no full slab test. out[i]: 1 where ray i is to be
 * traced (ray_may_hit and, with a box, not accel_box_misses), else 0. */
SIMD_ISA_DECL(void, rays_traced,
              (int n, const double *const *o, const double *const *d, const double *pad_lo,
               const double *pad_hi, const double *lo, const double *hi, unsigned char *out));

#ifdef LANES_FN
LANES_ATTR void LANES_FN(rays_traced)(int n, const double *const *o, const double *const *d,
                                      const double *pad_lo, const double *pad_hi, const double *lo,
                                      const double *hi, unsigned char *out) {
  for (int k0 = 0; k0 < n; k0 += WD) {
    int cnt = n - k0 < WD ? n - k0 : WD;
    /* Whole vectors loaded as such (lane by lane inserts went through
     * memory: 3% of the seed scene's time); a partial tail repeats its
     * last ray. */
    vdn ov[3], dv[3];
    if (cnt == WD) {
      for (int c = 0; c < 3; c++) {
        __builtin_memcpy(&ov[c], &o[c][k0], sizeof ov[c]);
        __builtin_memcpy(&dv[c], &d[c][k0], sizeof dv[c]);
      }
    } else { /* through a padded copy: whole vectors set (no lane of them left unset) */
      double t[6][WD];
      for (int c = 0; c < 3; c++)
        for (int k = 0; k < WD; k++) {
          int j = k0 + (k < cnt ? k : cnt - 1);
          t[c][k] = o[c][j], t[3 + c][k] = d[c][j];
        }
      for (int c = 0; c < 3; c++) {
        __builtin_memcpy(&ov[c], t[c], sizeof ov[c]);
        __builtin_memcpy(&dv[c], t[3 + c], sizeof dv[c]);
      }
    }
    /* ray_may_hit: an origin beyond a face of the padded box, pointing away. */
    vln away = (vln){0};
    for (int c = 0; c < 3; c++) {
      away |= (ov[c] > pad_hi[c]) & (dv[c] >= 0.0);
      away |= (ov[c] < pad_lo[c]) & (dv[c] <= 0.0);
    }
    if (lo) { /* accel_box_misses, term for term */
      vdn A[3], B[3], ad[3];
      for (int c = 0; c < 3; c++) {
        vln zero = dv[c] == 0.0, pos = dv[c] > 0.0;
        away |= zero & ((ov[c] < lo[c]) | (ov[c] > hi[c]));
        vdn near = dsel(pos, lo[c] - ov[c], ov[c] - hi[c]), far = dsel(pos, hi[c] - ov[c], ov[c] - lo[c]);
        A[c] = dsel(zero, (vdn){0} - 1.0, near);
        B[c] = dsel(zero, (vdn){0} + 1.0, far);
        ad[c] = dabs(dv[c]);
        away |= B[c] < 0.0;
      }
      away |= A[0] * ad[1] > B[1] * ad[0];
      away |= A[0] * ad[2] > B[2] * ad[0];
      away |= A[1] * ad[0] > B[0] * ad[1];
      away |= A[1] * ad[2] > B[2] * ad[1];
      away |= A[2] * ad[0] > B[0] * ad[2];
      away |= A[2] * ad[1] > B[1] * ad[2];
    }
    for (int k = 0; k < cnt; k++) out[k0 + k] = away[k] == 0;
  }
}
#endif
