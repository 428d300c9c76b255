/* Batched kernels for sse2: visible-normal microfacet sampling and
 * hdistant camera rays (4 float lanes, half as many double ones):
 * simd/microfacet_lanes.h and simd/camera_lanes.h compiled with target("sse2"); dispatched by
 * simd/simd.c. */
#include <math.h>

#include "../core/vec.h"
#include "simd.h"

#if RSW_SIMD_X86
#include <immintrin.h>

#define W             4
#define SIMD_FN       static inline __attribute__((always_inline, target("sse2")))
#define MF_LANES_ATTR __attribute__((target("sse2")))
#define VSQRT(x)      ((vf)_mm_sqrt_ps((x)))
#define MF_LANES_FN   mf_sample_visible_sse2
#define MF_EVAL_FN    mf_eval_sse2
#include "lanes.h"
#include "microfacet_lanes.h"

#define VSQRT_D(x)      ((vdn)_mm_sqrt_pd((x)))
#define CAM_LANES_ATTR  __attribute__((target("sse2")))
#define CAM_LANES_FN    hdistant_rays_sse2
#define COSINE_LANES_FN cosine_hemisphere_sse2
#include "camera_lanes.h"

/* Batched BSDF and sensor plugins (simd/plugin_lanes.h). */
#define ISA_SUFFIX sse2
#include "plugin_lanes.h"
#endif
