/* Batched kernels for avx512: visible-normal microfacet sampling and
 * hdistant camera rays (16 float lanes, half as many double ones):
 * simd/microfacet_lanes.h and simd/camera_lanes.h compiled with target("avx512f,avx512vl,avx512dq"); dispatched by
 * simd/simd.c. */
#include <math.h>

#include "../core/vec.h"
#include "simd.h"

#if RSW_SIMD_X86
#include <immintrin.h>

#define W             16
#define SIMD_FN       static inline __attribute__((always_inline, target("avx512f,avx512vl,avx512dq")))
#define MF_LANES_ATTR __attribute__((target("avx512f,avx512vl,avx512dq")))
#define VSQRT(x)      ((vf)_mm512_sqrt_ps((x)))
#define MF_LANES_FN   mf_sample_visible_avx512
#define MF_EVAL_FN    mf_eval_avx512
#include "lanes.h"
#include "microfacet_lanes.h"

#define VSQRT_D(x)      ((vdn)_mm512_sqrt_pd((x)))
#define CAM_LANES_ATTR  __attribute__((target("avx512f,avx512vl,avx512dq")))
#define CAM_LANES_FN    hdistant_rays_avx512
#define COSINE_LANES_FN cosine_hemisphere_avx512
#include "camera_lanes.h"

/* Batched BSDF and sensor plugins (simd/plugin_lanes.h). */
#define ISA_SUFFIX avx512
#include "plugin_lanes.h"
#endif
