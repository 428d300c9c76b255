/* shape_frames_batch (shapes/shape.h): the shading frames and local wi of
 * a wave's hits, a vector of doubles at a time (8 avx512, 4 avx2, 2
 * sse2), compiled per ISA from shapes/frame_lanes.h and picked at run time
 * (core/isa.h). Every ISA gives the scalar bits (see frame_lanes.h), so
 * the choice changes speed only. */
#include <math.h>

#include "../core/isa.h"
#include "shape.h"

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>

typedef double vd_8 __attribute__((vector_size(64)));
typedef long long vl_8 __attribute__((vector_size(64)));
typedef double vd_4 __attribute__((vector_size(32)));
typedef long long vl_4 __attribute__((vector_size(32)));
typedef double vd_2 __attribute__((vector_size(16)));
typedef long long vl_2 __attribute__((vector_size(16)));

#define VW            8
#define VD            vd_8
#define VL            vl_8
#define FSEL(m, a, b) ((VD)((((VL)(a)) & (m)) | (((VL)(b)) & ~(m))))
#define FRAME_FN      frames_avx512
#define FRAME_ATTR    static __attribute__((target("avx512f,avx512vl,avx512dq")))
#define FRAME_SQRT(x) ((VD)_mm512_sqrt_pd((__m512d)(x)))
#define MESH_FN       mesh_hits_avx512
#define FRAME_LANES   frame_lanes_avx512
#include "frame_lanes.h"
#include "mesh_hit_lanes.h"
#undef MESH_FN
#undef FRAME_LANES
#undef VW
#undef VD
#undef VL
#undef FRAME_FN
#undef FRAME_ATTR
#undef FRAME_SQRT

#define VW            4
#define VD            vd_4
#define VL            vl_4
#define FRAME_FN      frames_avx2
#define FRAME_ATTR    static __attribute__((target("avx2,fma")))
#define FRAME_SQRT(x) ((VD)_mm256_sqrt_pd((__m256d)(x)))
#define MESH_FN       mesh_hits_avx2
#define FRAME_LANES   frame_lanes_avx2
#include "frame_lanes.h"
#include "mesh_hit_lanes.h"
#undef MESH_FN
#undef FRAME_LANES
#undef VW
#undef VD
#undef VL
#undef FRAME_FN
#undef FRAME_ATTR
#undef FRAME_SQRT

#define VW            2
#define VD            vd_2
#define VL            vl_2
#define FRAME_FN      frames_sse2
#define FRAME_ATTR    static
#define FRAME_SQRT(x) ((VD)_mm_sqrt_pd((__m128d)(x)))
#define MESH_FN       mesh_hits_sse2
#define FRAME_LANES   frame_lanes_sse2
#include "frame_lanes.h"
#include "mesh_hit_lanes.h"
#undef MESH_FN
#undef FRAME_LANES
#undef VW
#undef VD
#undef VL
#undef FRAME_FN
#undef FRAME_ATTR
#undef FRAME_SQRT
#else
/* Other targets: one lane at a time through the same body. */
typedef double vd_1 __attribute__((vector_size(8)));
typedef long long vl_1 __attribute__((vector_size(8)));
#define VW            1
#define VD            vd_1
#define VL            vl_1
#define FSEL(m, a, b) ((VD)((((VL)(a)) & (m)) | (((VL)(b)) & ~(m))))
#define FRAME_FN      frames_sse2
#define FRAME_ATTR    static
#define FRAME_SQRT(x) ((VD){sqrt((x)[0])})
#define MESH_FN       mesh_hits_sse2
#define FRAME_LANES   frame_lanes_sse2
#include "frame_lanes.h"
#include "mesh_hit_lanes.h"
#endif

void shape_frames_batch(int n, int stride, const double *in, double *out) {
#if defined(__x86_64__) || defined(__i386__)
  switch (rsw_isa_get()) {
  case RSW_ISA_AVX512: frames_avx512(n, stride, in, out); return;
  case RSW_ISA_AVX2: frames_avx2(n, stride, in, out); return;
  default: break;
  }
#endif
  frames_sse2(n, stride, in, out);
}

void shape_mesh_hits_batch(int n, int stride, const double *k, const double *face, const double *in,
                           double *out) {
#if defined(__x86_64__) || defined(__i386__)
  switch (rsw_isa_get()) {
  case RSW_ISA_AVX512: mesh_hits_avx512(n, stride, k, face, in, out); return;
  case RSW_ISA_AVX2: mesh_hits_avx2(n, stride, k, face, in, out); return;
  default: break;
  }
#endif
  mesh_hits_sse2(n, stride, k, face, in, out);
}
