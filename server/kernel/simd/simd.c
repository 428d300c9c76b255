/* Run-time dispatch of the batched kernels of the machinery (simd.h); a
 * plugin's kernels are dispatched beside it (SIMD_DISPATCH). */
#include "simd.h"

void cosine_hemisphere_batch(rsw_isa isa, int n, const double *u, double *out) {
  SIMD_DISPATCH(isa, cosine_hemisphere, n, u, out);
}
