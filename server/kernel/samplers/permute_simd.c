/* stratified_permute_batch (samplers/sampler_common.h): the stratified
 * sampler's permutation for many lanes, 32-bit integer lanes (16 avx512,
 * 8 avx2, 4 sse2) compiled per ISA from samplers/permute_lanes.h and picked
 * at run time (core/isa.h). Bitwise the scalar permutation at every ISA. */
#include "../core/isa.h"
#include "sampler_common.h"

#if defined(__x86_64__) || defined(__i386__)
typedef uint32_t vp_16 __attribute__((vector_size(64)));
typedef uint32_t vp_8 __attribute__((vector_size(32)));

#define VW        16
#define VU32      vp_16
#define PERM_FN   permute_avx512
#define PERM_ATTR static __attribute__((target("avx512f,avx512vl,avx512dq")))
#include "permute_lanes.h"
#undef VW
#undef VU32
#undef PERM_FN
#undef PERM_ATTR

#define VW        8
#define VU32      vp_8
#define PERM_FN   permute_avx2
#define PERM_ATTR static __attribute__((target("avx2,fma")))
#include "permute_lanes.h"
#undef VW
#undef VU32
#undef PERM_FN
#undef PERM_ATTR

#define VW 4
#else
#define VW 1
#endif
typedef uint32_t vp_p __attribute__((vector_size(4 * VW)));
#define VU32      vp_p
#define PERM_FN   permute_plain
#define PERM_ATTR static
#include "permute_lanes.h"

void stratified_permute_batch(int n, const uint32_t *in, uint32_t l, const uint32_t *seed, uint32_t *out) {
#if defined(__x86_64__) || defined(__i386__)
  switch (rsw_isa_get()) {
  case RSW_ISA_AVX512: permute_avx512(n, in, l, seed, out); return;
  case RSW_ISA_AVX2: permute_avx2(n, in, l, seed, out); return;
  default: break;
  }
#endif
  permute_plain(n, in, l, seed, out);
}
