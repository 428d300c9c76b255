/* Mitsuba 3's chi-square goodness-of-fit test (docs/kernel-conventions.md#chi-square-tests;
 * mitsuba3 src/python/python/chi2.py, include/mitsuba/core/math.h), in C.
 *
 * The domain is the sphere, parameterised by (phi, -cos theta) in
 * [-pi, pi] x [-1, 1], with res/aspect x res cells (aspect 2: 50 x 101
 * cells for res = 101). Planar domains (disk, square) use the same code
 * with their own parameterisation. */
#ifndef RSW_TEST_CHI2_H
#define RSW_TEST_CHI2_H

#include "../../server/kernel/core/vec.h"
#include <stdbool.h>
#include <stddef.h>

/* Draws one sample. u has sample_dim uniforms in [0,1). Writes the sampled
 * direction (sphere domain) or point (planar: x, y in .x, .y) and its
 * weight (1 normally; 0 when the sampler failed, e.g. BSDF value 0).
 * Returns false when no sample was produced (counted as weight 0). */
typedef bool (*chi2_sample_fn)(void *user, const double *u, vec3 *out, double *weight);
/* Density at a point of the domain (solid angle for the sphere domain,
 * area for planar domains). */
typedef double (*chi2_pdf_fn)(void *user, vec3 p);

typedef enum chi2_domain {
  CHI2_SPHERE, /* (phi, -cos theta) in [-pi,pi] x [-1,1], aspect 2 */
  CHI2_DISK,   /* unit disk, bounding square [-1,1]^2 */
} chi2_domain;

typedef struct chi2_config {
  chi2_domain domain;
  int sample_dim;      /* 2, or 3 for BSDFs (lobe choice + direction) */
  size_t sample_count; /* Mitsuba: 1,000,000 */
  int res;             /* Mitsuba: 101 */
  int ires;            /* Mitsuba: 4 */
  unsigned seed;       /* Mitsuba: 0 */
  double alpha;        /* significance, Mitsuba: 0.01 */
  int test_count;      /* Sidak correction: alpha' = 1-(1-alpha)^(1/n) */
} chi2_config;

/* Defaults above with the given domain and sample_dim. */
chi2_config chi2_defaults(chi2_domain domain, int sample_dim);

typedef struct chi2_result {
  bool passed;
  double p_value;
  double chi2;
  int dof;
  char reason[256]; /* why it failed, when it failed */
} chi2_result;

/* Runs the test. Per-sample uniforms come from PCG32 streams seeded from
 * TEA(index, seed), as Mitsuba does, so results are reproducible. */
chi2_result chi2_run(const chi2_config *cfg, chi2_sample_fn sample, chi2_pdf_fn pdf, void *user);

/* Regularised lower incomplete gamma P(a, x) (exposed for tests). */
double chi2_gamma_p(double a, double x);

#endif
