/* Batched visible-normal microfacet sampling for avx512 (16 lanes):
 * simd/microfacet_lanes.h compiled with target("avx512f,avx512vl,avx512dq"); dispatched by
 * simd/simd.c. */
#include <math.h>

#include "simd.h"

#if RSW_SIMD_X86
#include <immintrin.h>

#define W 16
#define SIMD_FN static inline __attribute__((always_inline, target("avx512f,avx512vl,avx512dq")))
#define MF_LANES_ATTR __attribute__((target("avx512f,avx512vl,avx512dq")))
#define VSQRT(x) ((vf)_mm512_sqrt_ps((x)))
#define MF_LANES_FN mf_sample_visible_avx512
#include "lanes.h"
#include "microfacet_lanes.h"
#endif
