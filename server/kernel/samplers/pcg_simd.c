/* Batched PCG32 seeding for the samplers' start_batch
 * (samplers/sampler_common.h), compiled per ISA from samplers/pcg_lanes.h
 * (8 lanes avx512, 4 avx2, 2 sse2) and picked at run time (core/isa.h).
 * Integer arithmetic: every ISA gives the scalar streams bit for bit.
 *
 * The draws of streams in sampler_states stay scalar (the samplers' batch
 * loops): a lane's state has to be gathered from its sampler_state and
 * scattered back, and measured on the seed scene at AVX-512 vector draws
 * took 8% of a render against 4% for the scalar loop (AVX2 emulates the
 * 64-bit multiply: worse still). A wave's camera numbers are drawn here
 * (sampler_pcg_draw_batch), from the arrays the seeding has just filled:
 * the seed scene's 3.4% of a render for those draws became 1.4%. */
#include "pcg_simd.h"
#include "../core/isa.h"

/* Vectors of lanes per step of the seeding (pcg_lanes.h): two took 0.69x
 * the CPU time of one on the Zen 1 EPYC (AVX2); four, no less than one. */
#define PCG_IL 2

#if defined(__x86_64__) || defined(__i386__)
typedef uint64_t vu_8 __attribute__((vector_size(64)));
typedef uint32_t vu32_8 __attribute__((vector_size(32)));
typedef double vd_8 __attribute__((vector_size(64)));
typedef int64_t vi_8 __attribute__((vector_size(64)));
typedef uint64_t vu_4 __attribute__((vector_size(32)));
typedef uint32_t vu32_4 __attribute__((vector_size(16)));
typedef double vd_4 __attribute__((vector_size(32)));
typedef int64_t vi_4 __attribute__((vector_size(32)));
typedef uint64_t vu_2 __attribute__((vector_size(16)));
typedef uint32_t vu32_2 __attribute__((vector_size(8)));

#define VW          8
#define VU          vu_8
#define VU32        vu32_8
#define VD          vd_8
#define VI          vi_8
#define PCG_SEED_FN pcg_seed_avx512
#define PCG_DRAW_FN pcg_draw_avx512
#define PCG_VMUL    1
#define PCG_ATTR    static __attribute__((target("avx512f,avx512vl,avx512dq")))
#include "pcg_lanes.h"
#undef VW
#undef VU
#undef VU32
#undef VD
#undef VI
#undef PCG_SEED_FN
#undef PCG_DRAW_FN
#undef PCG_VMUL
#undef PCG_ATTR

#define VW          4
#define VU          vu_4
#define VU32        vu32_4
#define VD          vd_4
#define VI          vi_4
#define PCG_SEED_FN pcg_seed_avx2
#define PCG_DRAW_FN pcg_draw_avx2
#define PCG_VMUL    0
#define PCG_ATTR    static __attribute__((target("avx2,fma")))
#include "pcg_lanes.h"
#undef VW
#undef VU
#undef VU32
#undef VD
#undef VI
#undef PCG_SEED_FN
#undef PCG_DRAW_FN
#undef PCG_VMUL
#undef PCG_ATTR
#endif

/* sse2 and other targets: two lanes (x86) or one (seeding only). */
#if defined(__x86_64__) || defined(__i386__)
#define VW 2
#else
#define VW 1
#endif
typedef uint64_t vu_p __attribute__((vector_size(8 * VW)));
typedef uint32_t vu32_p __attribute__((vector_size(4 * VW)));
typedef double vd_p __attribute__((vector_size(8 * VW)));
typedef int64_t vi_p __attribute__((vector_size(8 * VW)));
#define VU          vu_p
#define VU32        vu32_p
#define VD          vd_p
#define VI          vi_p
#define PCG_SEED_FN pcg_seed_plain
#define PCG_DRAW_FN pcg_draw_plain
#define PCG_VMUL    0
#define PCG_ATTR    static
#include "pcg_lanes.h"

/* fn's instance for the render's ISA (fn_avx512, fn_avx2, fn_plain),
 * called with the arguments. */
#if defined(__x86_64__) || defined(__i386__)
#define PCG_CALL(fn, ...)                                                                                    \
  do {                                                                                                       \
    switch (rsw_isa_get()) {                                                                                 \
    case RSW_ISA_AVX512: fn##_avx512(__VA_ARGS__); return;                                                   \
    case RSW_ISA_AVX2: fn##_avx2(__VA_ARGS__); return;                                                       \
    default: fn##_plain(__VA_ARGS__); return;                                                                \
    }                                                                                                        \
  } while (0)
#else
#define PCG_CALL(fn, ...) fn##_plain(__VA_ARGS__)
#endif

void sampler_pcg_seed_batch(int n, const uint64_t *key, const uint32_t *index, uint64_t *state,
                            uint64_t *inc) {
  PCG_CALL(pcg_seed, n, key, index, state, inc);
}

void sampler_pcg_draw_batch(int n, uint64_t *state, const uint64_t *inc, int draws, double *out) {
  PCG_CALL(pcg_draw, n, state, inc, draws, out);
}
