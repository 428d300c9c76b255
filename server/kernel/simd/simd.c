/* Run-time dispatch of the per-ISA batched kernels (simd.h). */
#include "simd.h"

void mf_sample_visible_batch(rsw_isa isa, int ggx, int n, const float *const *in, float *const *out) {
#if RSW_SIMD_X86
  switch (isa) {
  case RSW_ISA_AVX512: mf_sample_visible_avx512(ggx, n, in, out); return;
  case RSW_ISA_AVX2: mf_sample_visible_avx2(ggx, n, in, out); return;
  default: mf_sample_visible_sse2(ggx, n, in, out); return;
  }
#else
#error "the batched kernels need an x86 target (sse2, avx2, avx512)"
#endif
}

void hdistant_rays_batch(rsw_isa isa, int n, const double (*m)[4], const double *fu, const double *ap,
                         const double *center, double radius, double offset, double *out) {
  switch (isa) {
  case RSW_ISA_AVX512: hdistant_rays_avx512(n, m, fu, ap, center, radius, offset, out); return;
  case RSW_ISA_AVX2: hdistant_rays_avx2(n, m, fu, ap, center, radius, offset, out); return;
  default: hdistant_rays_sse2(n, m, fu, ap, center, radius, offset, out); return;
  }
}

void mf_eval_batch(rsw_isa isa, int ggx, int visible, int n, const float *const *in, float *const *out) {
  switch (isa) {
  case RSW_ISA_AVX512: mf_eval_avx512(ggx, visible, n, in, out); return;
  case RSW_ISA_AVX2: mf_eval_avx2(ggx, visible, n, in, out); return;
  default: mf_eval_sse2(ggx, visible, n, in, out); return;
  }
}

void cosine_hemisphere_batch(rsw_isa isa, int n, const double *u, double *out) {
  switch (isa) {
  case RSW_ISA_AVX512: cosine_hemisphere_avx512(n, u, out); return;
  case RSW_ISA_AVX2: cosine_hemisphere_avx2(n, u, out); return;
  default: cosine_hemisphere_sse2(n, u, out); return;
  }
}
