/* The batched kernels for `generic`: the portable build of the lane
 * sources (simd/lanes_all.h) with GCC/clang vector extensions only: no
 * target attribute, no intrinsic, 4 float lanes (2 double ones), which
 * every target with 128-bit vectors maps to its registers (SSE2, NEON,
 * AltiVec...) and any other lowers to scalar code. The square roots are
 * lane by lane __builtin_sqrtf/sqrt, correctly rounded as the packed
 * instructions are (-fno-math-errno makes them single instructions).
 * Always compiled: the only kernels of a non-x86 build, `--isa generic` on
 * x86. */
#include <math.h>

#include "../core/vec.h"
#include "simd.h"

#define W 4
typedef float vf __attribute__((vector_size(4 * W)));
typedef double vdn __attribute__((vector_size(4 * W)));

static inline __attribute__((always_inline)) vf vsqrt_generic(vf x) {
  for (int k = 0; k < W; k++) x[k] = __builtin_sqrtf(x[k]);
  return x;
}
static inline __attribute__((always_inline)) vdn vsqrt_generic_d(vdn x) {
  for (int k = 0; k < W / 2; k++) x[k] = __builtin_sqrt(x[k]);
  return x;
}

#define SIMD_FN static inline __attribute__((always_inline))
#define LANES_ATTR
#define VSQRT(x)   vsqrt_generic((x))
#define VSQRT_D(x) vsqrt_generic_d((x))
#define ISA_SUFFIX generic
#include "lanes_all.h"
