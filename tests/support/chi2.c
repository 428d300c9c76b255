/* Pearson chi-square goodness-of-fit test for 2-D sampling routines, after
 * Mitsuba 3's ChiSquareTest (src/python/python/chi2.py) and its pooled
 * statistic chi2() (include/mitsuba/core/math.h); docs/kernel-conventions.md#chi-square-tests.
 *
 * Hypothesis: the samples drawn by `sample` are distributed with density
 * `pdf`. Both are reduced to a histogram on a grid over a 2-D parameter
 * plane:
 *   observed[c] = sum of sample weights that fall into cell c
 *   expected[c] = N * integral over cell c of pdf(map_forward(x, y)) dx dy
 * The parameterisations used have unit Jacobian, so the pdf integrates
 * directly:
 *   sphere: (phi, y = -cos theta) in [-pi,pi] x [-1,1];
 *           d(omega) = sin theta d(theta) d(phi) = |dy| d(phi);
 *   disk:   (x, y) in [-1,1]^2, the pdf is an area density.
 * The statistic sum (obs - exp)^2 / exp over cells (sorted by expected
 * count, cells with expected < 5 pooled) follows a chi-square law with
 * dof = terms - 1 under the hypothesis; p = 1 - P(dof/2, chi2/2). */
#include "chi2.h"

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../server/kernel/core/rng.h"

/* Mitsuba pools cells whose expected count is below this threshold. */
#define CHI2_POOL_THRESHOLD 5.0
/* Samples may exceed the domain bounds by this fraction of its extents
 * (Mitsuba: 1e-4) before the run is failed. */
#define CHI2_DOMAIN_EPS     1e-4
#define CHI2_MAX_DIM        16
/* Points per axis of the trapezoid rule in disk cells cut by the circle:
 * the integrand has a kink there, so the default ires would leave errors
 * of a few percent of the cell's count. */
#define CHI2_BOUNDARY_IRES  49

chi2_config chi2_defaults(chi2_domain domain, int sample_dim) {
  chi2_config c;
  c.domain = domain;
  c.sample_dim = sample_dim;
  c.sample_count = 1000000;
  c.res = 101;
  c.ires = 4;
  c.seed = 0;
  c.alpha = 0.01;
  c.test_count = 1;
  return c;
}

/* Appends a failure reason ("; "-separated) and marks the result failed. */
static void chi2_fail(chi2_result *r, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void chi2_fail(chi2_result *r, const char *fmt, ...) {
  r->passed = false;
  size_t len = strlen(r->reason);
  if (len > 0 && len + 2 < sizeof r->reason) {
    memcpy(r->reason + len, "; ", 3);
    len += 2;
  }
  if (len + 1 >= sizeof r->reason) return;
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(r->reason + len, sizeof r->reason - len, fmt, ap);
  va_end(ap);
}

/* ---- regularised incomplete gamma (Numerical Recipes §6.2 method) ----- */

/* ln of the common prefactor x^a e^-x / Gamma(a). */
static double gamma_log_prefactor(double a, double x) {
  return a * log(x) - x - lgamma(a);
}

/* Series P(a,x) = x^a e^-x / Gamma(a) * sum_n x^n / (a (a+1) ... (a+n)),
 * used for x < a + 1 where it converges quickly (terms shrink once
 * a + n > x). */
static double gamma_p_series(double a, double x) {
  double ap = a, term = 1.0 / a, sum = term;
  for (int n = 0; n < 100000; n++) {
    ap += 1.0;
    term *= x / ap;
    sum += term;
    if (fabs(term) < fabs(sum) * DBL_EPSILON) break;
  }
  return sum * exp(gamma_log_prefactor(a, x));
}

/* Continued fraction for Q(a,x) = 1 - P(a,x), used for x >= a + 1:
 * Q = x^a e^-x / Gamma(a) * 1/(x+1-a- 1(1-a)/(x+3-a- 2(2-a)/(x+5-a- ...))),
 * evaluated with the modified Lentz method. */
static double gamma_q_contfrac(double a, double x) {
  const double tiny = DBL_MIN / DBL_EPSILON;
  double b = x + 1.0 - a, c = 1.0 / tiny, d = 1.0 / b, h = d;
  for (int i = 1; i < 100000; i++) {
    double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (fabs(d) < tiny) d = tiny;
    c = b + an / c;
    if (fabs(c) < tiny) c = tiny;
    d = 1.0 / d;
    double delta = d * c;
    h *= delta;
    if (fabs(delta - 1.0) < DBL_EPSILON) break;
  }
  return exp(gamma_log_prefactor(a, x)) * h;
}

double chi2_gamma_p(double a, double x) {
  if (!(a > 0.0) || !(x >= 0.0)) return NAN;
  if (x == 0.0) return 0.0;
  if (isinf(x)) return 1.0;
  if (x < a + 1.0) return gamma_p_series(a, x);
  return 1.0 - gamma_q_contfrac(a, x);
}

/* Q(a, x) = 1 - P(a, x), computed without cancellation in the tail. */
static double chi2_gamma_q(double a, double x) {
  if (!(a > 0.0) || !(x >= 0.0)) return NAN;
  if (x == 0.0) return 1.0;
  if (isinf(x)) return 0.0;
  if (x < a + 1.0) return 1.0 - gamma_p_series(a, x);
  return gamma_q_contfrac(a, x);
}

/* ---- domains ---------------------------------------------------------- */

typedef struct chi2_grid {
  double xmin, ymin, xext, yext; /* bounds of the parameter plane */
  int nx, ny;                    /* cells */
} chi2_grid;

static chi2_grid grid_for(const chi2_config *cfg) {
  chi2_grid g;
  if (cfg->domain == CHI2_SPHERE) {
    /* Mitsuba: res / aspect cells in phi (aspect 2), res in -cos theta. */
    g.xmin = -RSW_PI;
    g.xext = 2.0 * RSW_PI;
    g.ymin = -1.0;
    g.yext = 2.0;
    g.nx = cfg->res / 2 > 0 ? cfg->res / 2 : 1;
    g.ny = cfg->res;
  } else {
    g.xmin = -1.0;
    g.xext = 2.0;
    g.ymin = -1.0;
    g.yext = 2.0;
    g.nx = cfg->res;
    g.ny = cfg->res;
  }
  return g;
}

/* Parameter point -> domain point (Mitsuba's SphericalDomain.map_forward:
 * cos theta = -y, direction (cos phi sin theta, sin phi sin theta,
 * cos theta)). */
static vec3 map_forward(chi2_domain d, double x, double y) {
  if (d == CHI2_SPHERE) {
    double cos_theta = -y;
    double sin_theta = sqrt(fmax(0.0, 1.0 - cos_theta * cos_theta));
    return v3(cos(x) * sin_theta, sin(x) * sin_theta, cos_theta);
  }
  return v3(x, y, 0.0);
}

/* Domain point -> parameter point; false when the point lies outside the
 * domain (not finite, off the unit sphere, or off the unit disk). */
static bool map_backward(chi2_domain d, vec3 v, double *x, double *y) {
  if (!v3_finite(v)) return false;
  if (d == CHI2_SPHERE) {
    if (fabs(v3_len2(v) - 1.0) > CHI2_DOMAIN_EPS) return false;
    *x = atan2(v.y, v.x);
    *y = -v.z;
    return *y >= -1.0 - 2.0 * CHI2_DOMAIN_EPS && *y <= 1.0 + 2.0 * CHI2_DOMAIN_EPS;
  }
  *x = v.x;
  *y = v.y;
  double lim = 1.0 + 2.0 * CHI2_DOMAIN_EPS;
  return v.x * v.x + v.y * v.y <= lim * lim;
}

/* ---- histogram of samples --------------------------------------------- */

/* Mitsuba's PCG32::next_float64: 52 random mantissa bits in [1,2) minus 1. */
static double pcg32_next_float64(pcg32 *r) {
  uint64_t lo = pcg32_next(r), hi = pcg32_next(r);
  uint64_t bits = ((lo | (hi << 32)) >> 12) | 0x3ff0000000000000ULL;
  double d;
  memcpy(&d, &bits, sizeof d);
  return d - 1.0;
}

static int cell_index(double t, int n) {
  double c = t * n;
  if (c < 0.0) c = 0.0;
  if (c > n - 1) c = n - 1;
  return (int)c;
}

static void tabulate_histogram(const chi2_config *cfg, const chi2_grid *g, chi2_sample_fn sample, void *user,
                               double *hist, chi2_result *r) {
  size_t outside = 0, bad_weight = 0;
  double total = 0.0;
  for (size_t i = 0; i < cfg->sample_count; i++) {
    /* Mitsuba: PCG32(initstate = sample_tea_64(index, seed),
     *                initseq   = sample_tea_64(seed, index)). */
    pcg32 rng;
    pcg32_seed(&rng, tea64((uint32_t)i, cfg->seed, 4), tea64(cfg->seed, (uint32_t)i, 4));
    double u[CHI2_MAX_DIM];
    for (int k = 0; k < cfg->sample_dim; k++) u[k] = pcg32_next_float64(&rng);
    vec3 p = v3(0, 0, 0);
    double w = 1.0;
    if (!sample(user, u, &p, &w)) continue;
    if (w == 0.0) continue;
    if (!isfinite(w) || w < 0.0) {
      if (bad_weight++ == 0) chi2_fail(r, "sample %zu has weight %g", i, w);
      continue;
    }
    double x, y;
    if (!map_backward(cfg->domain, p, &x, &y)) {
      if (outside++ == 0) chi2_fail(r, "sample %zu outside the domain: (%.9g, %.9g, %.9g)", i, p.x, p.y, p.z);
      continue;
    }
    int cx = cell_index((x - g->xmin) / g->xext, g->nx);
    int cy = cell_index((y - g->ymin) / g->yext, g->ny);
    hist[(size_t)cy * g->nx + cx] += w;
    total += w;
  }
  if (outside > 1) chi2_fail(r, "%zu samples outside the domain in all", outside);
  double sum = total / (double)cfg->sample_count;
  if (sum > 1.1) chi2_fail(r, "sample weights add up to %g > 1.1 per sample", sum);
}

/* ---- expected counts -------------------------------------------------- */

/* i-th of n trapezoid points on [a, b], nudged inward by 1e-4 of a step as
 * Mitsuba does (so a pdf is never evaluated exactly on a cell edge), and
 * its weight: end points 1/2, interior 1, times the step. */
static double trap_point(double a, double b, int i, int n, double *weight) {
  double step = (b - a) / (n - 1);
  *weight = ((i == 0 || i == n - 1) ? 0.5 : 1.0) * step;
  return a + (i + 1e-4) * (1.0 - 2e-4) * step;
}

/* Integral of the pdf over the sphere-domain cell [x0,x1] x [y0,y1]. */
static double integrate_sphere_cell(const chi2_config *cfg, chi2_pdf_fn pdf, void *user, double x0, double x1,
                                    double y0, double y1, int *bad_pdf) {
  double sum = 0.0;
  for (int j = 0; j < cfg->ires; j++) {
    double wy;
    double y = trap_point(y0, y1, j, cfg->ires, &wy);
    for (int i = 0; i < cfg->ires; i++) {
      double wx;
      double x = trap_point(x0, x1, i, cfg->ires, &wx);
      double f = pdf(user, map_forward(CHI2_SPHERE, x, y));
      if (!isfinite(f) || f < 0.0) {
        (*bad_pdf)++;
        continue;
      }
      sum += wx * wy * f;
    }
  }
  return sum;
}

/* Integral of the pdf over cell [x0,x1] x [y0,y1] intersected with the unit
 * disk: the density is 0 outside the disk. Iterated integral, both limits
 * clipped to the disk so no point is evaluated outside it:
 *   x over [max(x0,-xm), min(x1,xm)], xm = sqrt(1 - min|y|^2 on the cell),
 *   y over [max(y0,-s), min(y1,s)], s = sqrt(1 - x^2).
 * Inside the disk this is exactly Mitsuba's ires x ires trapezoid rule; a
 * cell that the circle crosses uses CHI2_BOUNDARY_IRES points per axis. A
 * cell that meets the disk in a set of positive area thus always gets a
 * positive expected count. */
static double integrate_disk_cell(const chi2_config *cfg, chi2_pdf_fn pdf, void *user, double x0, double x1,
                                  double y0, double y1, int *bad_pdf) {
  double ymin_abs = (y0 <= 0.0 && y1 >= 0.0) ? 0.0 : fmin(fabs(y0), fabs(y1));
  if (ymin_abs >= 1.0) return 0.0;
  double xm = sqrt(1.0 - ymin_abs * ymin_abs);
  double cx0 = fmax(x0, -xm), cx1 = fmin(x1, xm);
  if (!(cx0 < cx1)) return 0.0;
  double fx = fmax(fabs(x0), fabs(x1)), fy = fmax(fabs(y0), fabs(y1));
  int n = (fx * fx + fy * fy <= 1.0) ? cfg->ires : CHI2_BOUNDARY_IRES;
  double sum = 0.0;
  for (int i = 0; i < n; i++) {
    double wx;
    double x = trap_point(cx0, cx1, i, n, &wx);
    double s = sqrt(fmax(0.0, 1.0 - x * x));
    double cy0 = fmax(y0, -s), cy1 = fmin(y1, s);
    if (!(cy0 < cy1)) continue;
    for (int j = 0; j < n; j++) {
      double wy;
      double y = trap_point(cy0, cy1, j, n, &wy);
      double f = pdf(user, v3(x, y, 0.0));
      if (!isfinite(f) || f < 0.0) {
        (*bad_pdf)++;
        continue;
      }
      sum += wx * wy * f;
    }
  }
  return sum;
}

static void tabulate_pdf(const chi2_config *cfg, const chi2_grid *g, chi2_pdf_fn pdf, void *user,
                         double *expected, chi2_result *r) {
  double cw = g->xext / g->nx, ch = g->yext / g->ny;
  double n = (double)cfg->sample_count, total = 0.0;
  int bad_pdf = 0;
  for (int cy = 0; cy < g->ny; cy++) {
    double y0 = g->ymin + cy * ch, y1 = y0 + ch;
    for (int cx = 0; cx < g->nx; cx++) {
      double x0 = g->xmin + cx * cw, x1 = x0 + cw;
      double v = cfg->domain == CHI2_SPHERE ? integrate_sphere_cell(cfg, pdf, user, x0, x1, y0, y1, &bad_pdf)
                                            : integrate_disk_cell(cfg, pdf, user, x0, x1, y0, y1, &bad_pdf);
      expected[(size_t)cy * g->nx + cx] = v * n;
      total += v;
    }
  }
  if (bad_pdf > 0) chi2_fail(r, "pdf returned a negative or non-finite value at %d points", bad_pdf);
  if (total > 1.1) chi2_fail(r, "pdf integrates to %g > 1.1", total);
}

/* ---- statistic -------------------------------------------------------- */

typedef struct chi2_cell {
  double expected, observed;
  size_t index;
} chi2_cell;

static int cell_cmp(const void *pa, const void *pb) {
  const chi2_cell *a = pa, *b = pb;
  if (a->expected < b->expected) return -1;
  if (a->expected > b->expected) return 1;
  return (a->index > b->index) - (a->index < b->index); /* stable order */
}

/* Mitsuba's math::chi2(obs, exp, pool_threshold): cells in ascending order
 * of expected count; skip cells with both counts 0; a cell with expected >=
 * threshold is one term (obs-exp)^2/exp; smaller cells accumulate into a
 * pool that becomes one term when its expected total exceeds the
 * threshold. Returns the statistic; *dof = terms - 1. */
static double pooled_chi2(const chi2_cell *cells, size_t n, int *dof) {
  double stat = 0.0, pool_obs = 0.0, pool_exp = 0.0;
  int terms = 0;
  for (size_t i = 0; i < n; i++) {
    double e = cells[i].expected, o = cells[i].observed;
    if (e == 0.0 && o == 0.0) continue;
    if (e < CHI2_POOL_THRESHOLD) {
      pool_obs += o;
      pool_exp += e;
      if (pool_exp > CHI2_POOL_THRESHOLD) {
        stat += (pool_obs - pool_exp) * (pool_obs - pool_exp) / pool_exp;
        pool_obs = pool_exp = 0.0;
        terms++;
      }
    } else {
      stat += (o - e) * (o - e) / e;
      terms++;
    }
  }
  *dof = terms - 1;
  return stat;
}

chi2_result chi2_run(const chi2_config *cfg, chi2_sample_fn sample, chi2_pdf_fn pdf, void *user) {
  chi2_result r;
  memset(&r, 0, sizeof r);
  r.passed = true;
  r.p_value = NAN;
  if (!cfg || !sample || !pdf) {
    chi2_fail(&r, "chi2_run: config, sample and pdf functions are required");
    return r;
  }
  if (cfg->domain != CHI2_SPHERE && cfg->domain != CHI2_DISK) {
    chi2_fail(&r, "chi2_config.domain: unknown domain %d", (int)cfg->domain);
    return r;
  }
  if (cfg->sample_dim < 1 || cfg->sample_dim > CHI2_MAX_DIM) {
    chi2_fail(&r, "chi2_config.sample_dim: %d not in [1, %d]", cfg->sample_dim, CHI2_MAX_DIM);
    return r;
  }
  if (cfg->res < 2 || cfg->res > 4096 || cfg->ires < 2 || cfg->ires > 1024) {
    chi2_fail(&r, "chi2_config.res/ires: %d/%d not in [2, 4096]/[2, 1024]", cfg->res, cfg->ires);
    return r;
  }
  if (cfg->sample_count < 1 || cfg->sample_count > UINT32_MAX) {
    chi2_fail(&r, "chi2_config.sample_count: %zu not in [1, 2^32)", cfg->sample_count);
    return r;
  }
  if (!(cfg->alpha > 0.0 && cfg->alpha < 1.0)) {
    chi2_fail(&r, "chi2_config.alpha: %g not in (0, 1)", cfg->alpha);
    return r;
  }

  chi2_grid g = grid_for(cfg);
  size_t ncells = (size_t)g.nx * (size_t)g.ny;
  double *hist = calloc(ncells, sizeof *hist);
  double *expected = calloc(ncells, sizeof *expected);
  chi2_cell *cells = calloc(ncells, sizeof *cells);
  if (!hist || !expected || !cells) {
    chi2_fail(&r, "chi2_run: out of memory for %zu cells", ncells);
    goto done;
  }

  tabulate_histogram(cfg, &g, sample, user, hist, &r);
  tabulate_pdf(cfg, &g, pdf, user, expected, &r);

  size_t zero_exp_hits = 0;
  for (size_t i = 0; i < ncells; i++) {
    cells[i].expected = expected[i];
    cells[i].observed = hist[i];
    cells[i].index = i;
    if (expected[i] == 0.0 && hist[i] != 0.0) {
      if (zero_exp_hits++ == 0)
        chi2_fail(&r, "cell (%zu, %zu) has expected count 0 but observed %g", i % (size_t)g.nx,
                  i / (size_t)g.nx, hist[i]);
    }
  }
  if (zero_exp_hits > 1) chi2_fail(&r, "%zu cells with expected 0 hold samples", zero_exp_hits);
  qsort(cells, ncells, sizeof *cells, cell_cmp);

  r.chi2 = pooled_chi2(cells, ncells, &r.dof);
  if (r.dof < 1) chi2_fail(&r, "too few degrees of freedom (%d)", r.dof);

  /* p = 1 - P(dof/2, chi2/2), evaluated as Q(dof/2, chi2/2) so that tiny
   * p-values keep their precision. */
  if (r.dof >= 1) r.p_value = chi2_gamma_q(0.5 * r.dof, 0.5 * r.chi2);

  /* Sidak correction for test_count independent tests. */
  int tests = cfg->test_count > 1 ? cfg->test_count : 1;
  double alpha = 1.0 - pow(1.0 - cfg->alpha, 1.0 / tests);
  if (r.passed && (!isfinite(r.p_value) || r.p_value < alpha))
    chi2_fail(&r, "rejected: chi2 = %.6g, dof = %d, p = %.6g < alpha' = %.6g", r.chi2, r.dof, r.p_value,
              alpha);

done:
  free(hist);
  free(expected);
  free(cells);
  return r;
}
