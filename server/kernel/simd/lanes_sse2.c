/* The batched kernels for sse2 (4 float lanes, half as many double ones):
 * simd/lanes_all.h's lane sources compiled with target("sse2"). */
#include <math.h>

#include "../core/vec.h"
#include "simd.h"

#if RSW_SIMD_X86
#include <immintrin.h>

#define W          4
#define SIMD_FN    static inline __attribute__((always_inline, target("sse2")))
#define LANES_ATTR __attribute__((target("sse2")))
#define VSQRT(x)   ((vf)_mm_sqrt_ps((x)))
#define VSQRT_D(x) ((vdn)_mm_sqrt_pd((x)))
#define ISA_SUFFIX sse2
#include "lanes_all.h"
#endif
