/* The batched kernels for avx2 (8 float lanes, half as many double ones):
 * simd/lanes_all.h's lane sources compiled with target("avx2,fma"). */
#include <math.h>

#include "../core/vec.h"
#include "simd.h"

#if RSW_SIMD_X86
#include <immintrin.h>

#define W          8
#define SIMD_FN    static inline __attribute__((always_inline, target("avx2,fma")))
#define LANES_ATTR __attribute__((target("avx2,fma")))
#define VSQRT(x)   ((vf)_mm256_sqrt_ps((x)))
#define VSQRT_D(x) ((vdn)_mm256_sqrt_pd((x)))
#define ISA_SUFFIX avx2
#include "lanes_all.h"
#endif
