/* The instruction set the kernel's batched (SIMD) routines run on.
 *
 * The batched plugin ops (kernel.h: bsdf_ops.sample_batch) are compiled
 * once per ISA from the same source (GCC/clang vector extensions under
 * __attribute__((target(...))), e.g. bsdfs/microfacet_simd.c) and picked at
 * run time: the best the CPU has (__builtin_cpu_supports), or the one
 * `--isa` pins. The choice is process-wide, set once before any render.
 *
 * Lane width: sse2 4 floats, avx2 8, avx512 16, generic 4. Every lane computes the
 * same operations whatever the width, so a render at a given ISA does not
 * depend on how its lanes were grouped (1 and N threads agree bitwise).
 * Across ISAs results agree statistically, not necessarily bitwise. */
#ifndef RSW_CORE_ISA_H
#define RSW_CORE_ISA_H

#include <stdbool.h>

#include "rsw_error.h"

typedef enum rsw_isa {
  RSW_ISA_SSE2,
  RSW_ISA_AVX2,    /* avx2 + fma */
  RSW_ISA_AVX512,  /* avx512f + avx512vl + avx512dq */
  RSW_ISA_GENERIC, /* GCC vector extensions without target attributes
                      (simd/lanes_generic.c): every CPU; the only one of a
                      non-x86 build (or one made with make SIMD=generic) */
  RSW_ISA__COUNT
} rsw_isa;

/* "sse2", "avx2", "avx512", "generic". */
const char *rsw_isa_name(rsw_isa isa);
/* Whether this CPU runs isa. */
bool rsw_isa_supported(rsw_isa isa);
/* The widest ISA this CPU runs (generic where no x86 one is built). */
rsw_isa rsw_isa_best(void);
/* "auto" (the best), "avx512", "avx2", "sse2" or "generic".
 * RSW_ERR_INVALID (where
 * "--isa") for another name or for an ISA this CPU lacks. */
rsw_status rsw_isa_parse(const char *name, rsw_isa *out, rsw_err *err);
/* The ISA renders use (default: rsw_isa_best()). rsw_isa_set() is for
 * start-up and tests (not thread-safe against running renders); it
 * refuses (returns false) an ISA the CPU lacks. */
rsw_isa rsw_isa_get(void);
bool rsw_isa_set(rsw_isa isa);

#endif
