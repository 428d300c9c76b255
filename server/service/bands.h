/* Spectral response functions (bands) of a job: the "bands" member parsed
 * and checked, each band's quadrature (wavelength nodes and weights), and
 * a band's film combined from the films of its nodes.
 *
 * A job with bands renders every context once per distinct node
 * wavelength (nodes shared by several bands render once); a band's value
 * is the SRF-weighted mean of its nodes (docs/experiments.md#spectral-response-functions-bands):
 *
 *   radiance_srf = ∫ L(λ) S(λ) dλ / ∫ S(λ) dλ ≈ Σ w_i L(λ_i) / Σ w_i
 *
 * with (λ_i, w_i) the Gauss rule of the weight S (w_i in nm). */
#ifndef RSW_SERVICE_BANDS_H
#define RSW_SERVICE_BANDS_H

#include <cjson/cJSON.h>

#include "../kernel/render.h"
#include "service.h"

#define BANDS_MAX          64   /* bands in one job */
#define BAND_MAX_NODES     64   /* nodes of one band ("nodes") */
#define BAND_MAX_TABLE     8192 /* samples of a tabulated SRF */
#define BAND_GAUSS_SIGMAS  4.0  /* a gaussian SRF is truncated at mean ± 4 sigma */
#define BAND_DEFAULT_SPAN  20.0 /* default: one node per 20 nm of width, plus one */
#define BAND_DEFAULT_NODES 16   /* ... at most this many */

typedef struct band {
  char id[65];
  const char *type;            /* "uniform", "gaussian", "tabulated" (static) */
  double lo, hi;               /* the SRF's support (nm): where it is not 0 */
  size_t n_nodes;              /* nodes of the rule */
  double wl[BAND_MAX_NODES];   /* node wavelengths (nm), ascending */
  double w[BAND_MAX_NODES];    /* weights (nm): Σ w = ∫ S dλ */
  size_t slot[BAND_MAX_NODES]; /* each node's index in band_plan.wl */
  double integral;             /* Σ w (nm) */
} band;

/* A job's bands and the distinct node wavelengths they need, ascending. */
typedef struct band_plan {
  band *b;
  size_t n;
  double *wl;
  size_t n_wl;
} band_plan;

/* Parse and check a job's "bands" (v, at JSON pointer ptr): a non-empty
 * list of {"id": ID, "srf": SRF[, "nodes": N]}, SRF one of
 * {"type": "uniform", "wmin", "wmax"}, {"type": "gaussian", "mean",
 * "fwhm"}, {"type": "tabulated", "wavelengths", "values"}. Errors (e,
 * RSW_ERR_* naming the pointer): not a list or object, an unknown member,
 * an id that is not [A-Za-z0-9._-]{1,64} or appears twice, a number that
 * is not finite or not positive where it must be, wmin >= wmax, fwhm <= 0,
 * a gaussian reaching below 0 nm, tabulated wavelengths not strictly
 * increasing or of another length than values, a negative value, an SRF
 * whose integral is 0, more than BANDS_MAX bands. *out (bands_free) only
 * on success. */
rsw_status bands_parse(const cJSON *v, const char *ptr, band_plan **out, svc_error *e);
void bands_free(band_plan *p);

/* The default seed of a node render: the context's seed (what a render of
 * the context without bands would get) mixed with the node's wavelength,
 * so the renders of a band are independent and a node's film does not
 * depend on which other bands the job has. */
uint64_t bands_node_seed(uint64_t context_seed, double wavelength);

/* A band's film from its nodes' films (nodes[i] the film at b->wl[i],
 * all of one shape): radiance = Σ w_i L_i / Σ w_i; radiance_stderr (when
 * the nodes have it; renders independent) = sqrt(Σ w_i² s_i²) / Σ w_i;
 * the irradiance E_srf = Σ w_i E_i / Σ w_i; brdf = L_srf / E_srf, brf =
 * π L_srf / E_srf. The wavelength is NaN, the spp, seed, angles and sun
 * those of the first node. RSW_ERR_INVALID (films that differ in shape
 * or planes), RSW_ERR_NOMEM. *out (film_image_free) only on success. */
rsw_status bands_combine(const band *b, const film_image *const *nodes, film_image *out, rsw_err *err);

/* The index of the band called id, or SIZE_MAX. */
size_t bands_find(const band_plan *p, const char *id);

#endif
