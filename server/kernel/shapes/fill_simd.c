/* shape_frames_batch (shapes/shape.h): the shading frames and local wi of
 * a wave's hits, 8 double lanes at a time, compiled per ISA from
 * shapes/frame_lanes.h and picked at run time (core/isa.h). Every ISA
 * gives the scalar bits (see frame_lanes.h), so the choice changes speed
 * only. */
#include <math.h>

#include "../core/isa.h"
#include "shape.h"

typedef double vd8 __attribute__((vector_size(64)));
typedef long long vl8 __attribute__((vector_size(64)));

/* m ? a : b, lane by lane (m all-ones or zero). */
#define fsel8(m, a, b) ((vd8)((((vl8)(a)) & (m)) | (((vl8)(b)) & ~(m))))

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>

#define FRAME_FN   frames_avx512
#define FRAME_ATTR static __attribute__((target("avx512f,avx512vl,avx512dq")))
#define FRAME_SQRT(x) ((vd8)_mm512_sqrt_pd((__m512d)(x)))
#include "frame_lanes.h"
#undef FRAME_FN
#undef FRAME_ATTR
#undef FRAME_SQRT

/* Two 4-lane halves (a statement expression: a 64-byte vector is no
 * AVX2 function argument). */
typedef double vd4 __attribute__((vector_size(32)));
#define SQRT8_AVX2(x)                                                                                        \
  __extension__({                                                                                            \
    vd8 x_ = (x);                                                                                            \
    vd4 lo_ = (vd4)_mm256_sqrt_pd((__m256d)(vd4){x_[0], x_[1], x_[2], x_[3]});                               \
    vd4 hi_ = (vd4)_mm256_sqrt_pd((__m256d)(vd4){x_[4], x_[5], x_[6], x_[7]});                               \
    (vd8){lo_[0], lo_[1], lo_[2], lo_[3], hi_[0], hi_[1], hi_[2], hi_[3]};                                   \
  })
#define FRAME_FN      frames_avx2
#define FRAME_ATTR    static __attribute__((target("avx2,fma")))
#define FRAME_SQRT(x) SQRT8_AVX2(x)
#include "frame_lanes.h"
#undef FRAME_FN
#undef FRAME_ATTR
#undef FRAME_SQRT
#endif

/* Portable (sse2 and other targets): the same lanes with a scalar square
 * root per lane (sqrt is correctly rounded either way). */
#define SQRT8_PLAIN(x)                                                                                       \
  __extension__({                                                                                            \
    vd8 x_ = (x);                                                                                            \
    for (int k_ = 0; k_ < 8; k_++) x_[k_] = sqrt(x_[k_]);                                                    \
    x_;                                                                                                      \
  })
#define FRAME_FN      frames_plain
#define FRAME_ATTR    static
#define FRAME_SQRT(x) SQRT8_PLAIN(x)
#include "frame_lanes.h"

void shape_frames_batch(int n, int stride, const double *in, double *out) {
#if defined(__x86_64__) || defined(__i386__)
  switch (rsw_isa_get()) {
  case RSW_ISA_AVX512: frames_avx512(n, stride, in, out); return;
  case RSW_ISA_AVX2: frames_avx2(n, stride, in, out); return;
  default: break;
  }
#endif
  frames_plain(n, stride, in, out);
}
