/* Batched (SIMD) kernels compiled per ISA (core/isa.h) and their run-time
 * dispatch. Each per-ISA file includes the same lane source (lanes.h and a
 * *_lanes.h body) under __attribute__((target(...))), so one algorithm
 * serves sse2 (4 lanes), avx2 (8) and avx512 (16). */
#ifndef RSW_SIMD_SIMD_H
#define RSW_SIMD_SIMD_H

#include "../core/isa.h"

#if defined(__x86_64__) || defined(__i386__)
#define RSW_SIMD_X86 1
#else
#define RSW_SIMD_X86 0
#endif

/* Visible-normal samples of n lanes (simd/microfacet_lanes.h): ggx != 0
 * for GGX, else Beckmann; in[0..6]: wi xyz (unit, local, wi.z > 0),
 * alpha_u, alpha_v, u.x, u.y (n each); out[0..5]: wo xyz, pdf (0: failed),
 * weight without Fresnel, wi.m. Single precision. At `isa` (supported;
 * rsw_isa_get() for the render's). */
void mf_sample_visible_batch(rsw_isa isa, int ggx, int n, const float *const *in, float *const *out);

/* roughconductor eval and pdf without Fresnel for n lanes (simd/
 * microfacet_lanes.h mf_eval_lanes): in[0..7] wi xyz, wo xyz, alpha_u,
 * alpha_v (n each; wi.z > 0, wo.z > 0); out[0..2] value D G / (4 wi.z),
 * pdf, wi.h. Single precision. */
void mf_eval_batch(rsw_isa isa, int ggx, int visible, int n, const float *const *in, float *const *out);

/* hdistant camera rays without a target (simd/camera_lanes.h, double
 * lanes): m the rows of to_world; fu, ap 2 per lane (x, y); out 6 per
 * lane (origin, direction). Bitwise the scalar rays. */
void hdistant_rays_batch(rsw_isa isa, int n, const double (*m)[4], const double *fu, const double *ap,
                         const double *center, double radius, double offset, double *out);

/* Cosine-weighted hemisphere directions (simd/camera_lanes.h, double
 * lanes): u 2 per lane, out 3 per lane; bitwise
 * warp_square_to_cosine_hemisphere(). */
void cosine_hemisphere_batch(rsw_isa isa, int n, const double *u, double *out);

#if RSW_SIMD_X86
#define COS_SIMD_DECL(s) void cosine_hemisphere_##s(int n, const double *u, double *out)
COS_SIMD_DECL(sse2);
COS_SIMD_DECL(avx2);
COS_SIMD_DECL(avx512);
#define CAM_SIMD_DECL(s)                                                                                     \
  void hdistant_rays_##s(int n, const double(*m)[4], const double *fu, const double *ap,                     \
                         const double *center, double radius, double offset, double *out)
CAM_SIMD_DECL(sse2);
CAM_SIMD_DECL(avx2);
CAM_SIMD_DECL(avx512);
#define MF_SIMD_DECL(s) void mf_sample_visible_##s(int ggx, int n, const float *const *in, float *const *out)
MF_SIMD_DECL(sse2);
MF_SIMD_DECL(avx2);
MF_SIMD_DECL(avx512);
#define MF_EVAL_DECL(s)                                                                                      \
  void mf_eval_##s(int ggx, int visible, int n, const float *const *in, float *const *out)
MF_EVAL_DECL(sse2);
MF_EVAL_DECL(avx2);
MF_EVAL_DECL(avx512);
#endif

#endif
