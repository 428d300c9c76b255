/* Run-time ISA choice (isa.h). */
#include "isa.h"

#include <string.h>

static const char *const names[RSW_ISA__COUNT] = {"sse2", "avx2", "avx512", "generic"};

/* -1: not chosen yet (the first rsw_isa_get() picks the best). */
static int current = -1;

const char *rsw_isa_name(rsw_isa isa) {
  return (unsigned)isa < RSW_ISA__COUNT ? names[isa] : "?";
}

bool rsw_isa_supported(rsw_isa isa) {
  if (isa == RSW_ISA_GENERIC) return true;
#if (defined(__x86_64__) || defined(__i386__)) && !defined(RSW_SIMD_GENERIC_ONLY)
  __builtin_cpu_init();
  switch (isa) {
  case RSW_ISA_SSE2: return __builtin_cpu_supports("sse2");
  case RSW_ISA_AVX2: return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  case RSW_ISA_AVX512:
    return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
           __builtin_cpu_supports("avx512dq");
  default: return false;
  }
#else
  return false;
#endif
}

rsw_isa rsw_isa_best(void) {
  if (rsw_isa_supported(RSW_ISA_AVX512)) return RSW_ISA_AVX512;
  if (rsw_isa_supported(RSW_ISA_AVX2)) return RSW_ISA_AVX2;
  if (rsw_isa_supported(RSW_ISA_SSE2)) return RSW_ISA_SSE2;
  return RSW_ISA_GENERIC;
}

rsw_status rsw_isa_parse(const char *name, rsw_isa *out, rsw_err *err) {
  if (name && strcmp(name, "auto") == 0) {
    *out = rsw_isa_best();
    return RSW_OK;
  }
  for (int i = 0; i < RSW_ISA__COUNT; i++) {
    if (name && strcmp(name, names[i]) == 0) {
      if (!rsw_isa_supported((rsw_isa)i))
        return rsw_fail(err, RSW_ERR_INVALID, "--isa", "this CPU lacks %s (it runs up to %s; use --isa auto)",
                        names[i], names[rsw_isa_best()]);
      *out = (rsw_isa)i;
      return RSW_OK;
    }
  }
  return rsw_fail(err, RSW_ERR_INVALID, "--isa",
                  "unknown ISA '%s' (expected auto, avx512, avx2, sse2 or generic)", name ? name : "");
}

rsw_isa rsw_isa_get(void) {
  int c = __atomic_load_n(&current, __ATOMIC_RELAXED);
  if (c < 0) {
    c = (int)rsw_isa_best();
    __atomic_store_n(&current, c, __ATOMIC_RELAXED);
  }
  return (rsw_isa)c;
}

bool rsw_isa_set(rsw_isa isa) {
  if (!rsw_isa_supported(isa)) return false;
  __atomic_store_n(&current, (int)isa, __ATOMIC_RELAXED);
  return true;
}
