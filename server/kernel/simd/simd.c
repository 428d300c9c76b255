/* Run-time dispatch of the per-ISA batched kernels (simd.h). On x86 the
 * ISA picks sse2, avx2, avx512 or generic; elsewhere (or built with
 * RSW_SIMD_GENERIC_ONLY) every call goes to the generic kernels. */
#include "simd.h"

#if RSW_SIMD_X86
#define DISPATCH(isa, fn, ...)                                                                               \
  switch (isa) {                                                                                             \
  case RSW_ISA_AVX512: fn##_avx512(__VA_ARGS__); return;                                                     \
  case RSW_ISA_AVX2: fn##_avx2(__VA_ARGS__); return;                                                         \
  case RSW_ISA_GENERIC: fn##_generic(__VA_ARGS__); return;                                                   \
  default: fn##_sse2(__VA_ARGS__); return;                                                                   \
  }
#else
#define DISPATCH(isa, fn, ...)                                                                               \
  do {                                                                                                       \
    (void)(isa);                                                                                             \
    fn##_generic(__VA_ARGS__);                                                                               \
  } while (0)
#endif

void mf_sample_visible_batch(rsw_isa isa, int ggx, int n, const float *const *in, float *const *out) {
  DISPATCH(isa, mf_sample_visible, ggx, n, in, out);
}

void hdistant_rays_batch(rsw_isa isa, int n, const double (*m)[4], const double *fu, const double *ap,
                         const double *center, double radius, double offset, double *out) {
  DISPATCH(isa, hdistant_rays, n, m, fu, ap, center, radius, offset, out);
}

void mf_eval_batch(rsw_isa isa, int ggx, int visible, int n, const float *const *in, float *const *out) {
  DISPATCH(isa, mf_eval, ggx, visible, n, in, out);
}

void cosine_hemisphere_batch(rsw_isa isa, int n, const double *u, double *out) {
  DISPATCH(isa, cosine_hemisphere, n, u, out);
}

/* ---- batched plugins (simd/plugin_lanes.h) -------------------------------- */

void rpv_factor_batch(rsw_isa isa, int n, const float *const *in, float *out) {
  DISPATCH(isa, rpv_factor, n, in, out);
}

void fresnel_conductor_batch(rsw_isa isa, int n, const double *cos_i, const double *eta, const double *k,
                             double *out) {
  DISPATCH(isa, fresnel_conductor, n, cos_i, eta, k, out);
}

void disk_origins_batch(rsw_isa isa, int n, const double *m9, int m_step, const double *d, int d_step,
                        const double *ap, const double *center, double radius, double offset, double *out) {
  DISPATCH(isa, disk_origins, n, m9, m_step, d, d_step, ap, center, radius, offset, out);
}

void perspective_rays_batch(rsw_isa isa, int n, const double (*m)[4], const double *pp, double t,
                            double aspect, double near_clip, double far_clip, const double *fu, double *out) {
  DISPATCH(isa, perspective_rays, n, m, pp, t, aspect, near_clip, far_clip, fu, out);
}
