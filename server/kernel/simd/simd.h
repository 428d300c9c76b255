/* Batched (SIMD) kernels compiled per ISA (core/isa.h) and their run-time
 * dispatch: the machinery. Each per-ISA file (simd/lanes_<isa>.c) defines
 * its lane width and target attribute and includes simd/lanes_all.h, the
 * one list of lane sources: the lane helpers here (lanes.h float lanes,
 * warp_lanes.h double lanes and the warps) and each plugin's lanes, which
 * sit beside the plugin (bsdfs/rpv_lanes.h, sensors/sensor_common_lanes.h...),
 * so one algorithm serves generic (4 float lanes), sse2 (4), avx2 (8) and
 * avx512 (16).
 *
 * A plugin's lane file declares its entry points with SIMD_ISA_DECL, which
 * the per-ISA files then define as NAME_<isa> (LANES_FN(NAME)), and the
 * plugin picks one at run time with SIMD_DISPATCH. */
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

/* SIMD_ISA_DECL(void, f, (int n, ...)): the prototypes of f_generic and,
 * on x86, f_sse2, f_avx2, f_avx512 (one definition each, from the lane
 * source compiled by simd/lanes_<isa>.c). */
#if RSW_SIMD_X86
#define SIMD_ISA_DECL(ret, fn, params)                                                                       \
  ret fn##_generic params;                                                                                   \
  ret fn##_sse2 params;                                                                                      \
  ret fn##_avx2 params;                                                                                      \
  ret fn##_avx512 params
#else
#define SIMD_ISA_DECL(ret, fn, params) ret fn##_generic params
#endif

/* SIMD_DISPATCH(isa, f, args...): call f_<isa>(args...) and return (isa
 * supported; rsw_isa_get() for the render's). Elsewhere than x86 (or
 * built with RSW_SIMD_GENERIC_ONLY) every call goes to f_generic. */
#if RSW_SIMD_X86
#define SIMD_DISPATCH(isa, fn, ...)                                                                          \
  switch (isa) {                                                                                             \
  case RSW_ISA_AVX512: fn##_avx512(__VA_ARGS__); return;                                                     \
  case RSW_ISA_AVX2: fn##_avx2(__VA_ARGS__); return;                                                         \
  case RSW_ISA_GENERIC: fn##_generic(__VA_ARGS__); return;                                                   \
  default: fn##_sse2(__VA_ARGS__); return;                                                                   \
  }
#else
#define SIMD_DISPATCH(isa, fn, ...)                                                                          \
  do {                                                                                                       \
    (void)(isa);                                                                                             \
    fn##_generic(__VA_ARGS__);                                                                               \
    return;                                                                                                  \
  } while (0)
#endif

/* Cosine-weighted hemisphere directions (simd/warp_lanes.h, double
 * lanes): u 2 per lane, out 3 per lane; bitwise
 * warp_square_to_cosine_hemisphere(). */
void cosine_hemisphere_batch(rsw_isa isa, int n, const double *u, double *out);
SIMD_ISA_DECL(void, cosine_hemisphere, (int n, const double *u, double *out));

#endif
