/* Batched kernels for avx2: visible-normal microfacet sampling and
 * hdistant camera rays (8 float lanes, half as many double ones):
 * simd/microfacet_lanes.h and simd/camera_lanes.h compiled with target("avx2,fma"); dispatched by
 * simd/simd.c. */
#include <math.h>

#include "../core/vec.h"
#include "simd.h"

#if RSW_SIMD_X86
#include <immintrin.h>

#define W             8
#define SIMD_FN       static inline __attribute__((always_inline, target("avx2,fma")))
#define MF_LANES_ATTR __attribute__((target("avx2,fma")))
#define VSQRT(x)      ((vf)_mm256_sqrt_ps((x)))
#define MF_LANES_FN   mf_sample_visible_avx2
#define MF_EVAL_FN    mf_eval_avx2
#include "lanes.h"
#include "microfacet_lanes.h"

#define VSQRT_D(x)      ((vdn)_mm256_sqrt_pd((x)))
#define CAM_LANES_ATTR  __attribute__((target("avx2,fma")))
#define CAM_LANES_FN    hdistant_rays_avx2
#define COSINE_LANES_FN cosine_hemisphere_avx2
#include "camera_lanes.h"

/* Batched BSDF and sensor plugins (simd/plugin_lanes.h). */
#define ISA_SUFFIX avx2
#include "plugin_lanes.h"
#endif
