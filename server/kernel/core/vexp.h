/* exp(x) in batches that vectorise, with libm's bits on a machine whose
 * libm takes glibc's FMA route and within 1 ulp elsewhere, and the same
 * bits at every ISA (vexp_lanes.h says how). Thread-safe (no state).
 * Users: the gaussian filter's weights (films/filter_gaussian.c), a
 * layered medium's page transmittances (media/layered.h). */
#ifndef RSW_CORE_VEXP_H
#define RSW_CORE_VEXP_H

#include "isa.h"

/* out[i] = exp(x[i]) for i in [0, n), on the ISA isa (core/isa.h; every
 * ISA gives the same bits). x and out must not overlap. */
void vexp_batch(rsw_isa isa, int n, const double *restrict x, double *restrict out);

#endif
