/* Batched (SIMD) kernels compiled per ISA (core/isa.h) and their run-time
 * dispatch. Each per-ISA file includes the same lane source (lanes.h and a
 * *_lanes.h body) under __attribute__((target(...))), so one algorithm
 * serves sse2 (4 lanes), avx2 (8) and avx512 (16). */
#ifndef RSW_SIMD_SIMD_H
#define RSW_SIMD_SIMD_H

#include "../core/isa.h"

/* RSW_SIMD_GENERIC_ONLY (make SIMD=generic): build as for a CPU other
 * than x86, the generic kernels alone (simd/lanes_generic.c). */
#if (defined(__x86_64__) || defined(__i386__)) && !defined(RSW_SIMD_GENERIC_ONLY)
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

/* ---- batched plugins (simd/plugin_lanes.h) -------------------------------- */

/* rpv's M F H (pi f_r / rho_0) for n lanes, float: in[0..8] wi xyz, wo
 * xyz (local, z > 0), k, g, rho_c (n each); out n. */
void rpv_factor_batch(rsw_isa isa, int n, const float *const *in, float *out);

/* fresnel_conductor() for n lanes (double lanes, bitwise the scalar). */
void fresnel_conductor_batch(rsw_isa isa, int n, const double *cos_i, const double *eta, const double *k,
                             double *out);

/* The distant family's origins without a target (double lanes, bitwise
 * ray_target_origin()): frame rows m9 (9 per lane, m_step 9; or shared,
 * m_step 0), d 3 per lane (d_step 3) or shared (0), ap 2 per lane; out 3
 * per lane. */
void disk_origins_batch(rsw_isa isa, int n, const double *m9, int m_step, const double *d, int d_step,
                        const double *ap, const double *center, double radius, double offset, double *out);

/* perspective camera rays (double lanes, bitwise perspective_sample_ray()):
 * m to_world's rows, pp the principal point offset, fu 2 per lane; out 8
 * per lane (o, d, tmin, tmax). */
void perspective_rays_batch(rsw_isa isa, int n, const double (*m)[4], const double *pp, double t,
                            double aspect, double near_clip, double far_clip, const double *fu, double *out);

#define PL_SIMD_DECL(s)                                                                                      \
  void rpv_factor_##s(int n, const float *const *in, float *out);                                            \
  void fresnel_conductor_##s(int n, const double *cos_i, const double *eta, const double *k, double *out);   \
  void disk_origins_##s(int n, const double *m9, int m_step, const double *d, int d_step, const double *ap,  \
                        const double *center, double radius, double offset, double *out);                    \
  void perspective_rays_##s(int n, const double(*m)[4], const double *pp, double t, double aspect,           \
                            double near_clip, double far_clip, const double *fu, double *out)
PL_SIMD_DECL(generic);

/* The portable kernels (simd/lanes_generic.c), every target. */
void cosine_hemisphere_generic(int n, const double *u, double *out);
void hdistant_rays_generic(int n, const double (*m)[4], const double *fu, const double *ap,
                           const double *center, double radius, double offset, double *out);
void mf_sample_visible_generic(int ggx, int n, const float *const *in, float *const *out);
void mf_eval_generic(int ggx, int visible, int n, const float *const *in, float *const *out);

#if RSW_SIMD_X86
PL_SIMD_DECL(sse2);
PL_SIMD_DECL(avx2);
PL_SIMD_DECL(avx512);
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
