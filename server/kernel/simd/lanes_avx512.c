/* The batched kernels for avx512 (16 float lanes, half as many double ones):
 * simd/lanes_all.h's lane sources compiled with target("avx512f,avx512vl,avx512dq"). */
#include <math.h>

#include "../core/vec.h"
#include "simd.h"

#if RSW_SIMD_X86
#include <immintrin.h>

#define W          16
#define SIMD_FN    static inline __attribute__((always_inline, target("avx512f,avx512vl,avx512dq")))
#define LANES_ATTR __attribute__((target("avx512f,avx512vl,avx512dq")))
#define VSQRT(x)   ((vf)_mm512_sqrt_ps((x)))
#define VSQRT_D(x) ((vdn)_mm512_sqrt_pd((x)))
#define ISA_SUFFIX avx512
#include "lanes_all.h"
#endif
