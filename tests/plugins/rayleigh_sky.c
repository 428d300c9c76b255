/* "rayleigh_sky": an example environment plugin whose radiance depends on
 * the wavelength and is tabulated in prepare(). A sky over the upper
 * hemisphere (d.z > 0), the same in every direction, with the lambda^-n
 * spectral shape of Rayleigh scattering (n = 4; Bohren and Huffman,
 * "Absorption and Scattering of Light by Small Particles", 1983, ch. 5):
 *
 *   L(lambda, d) = sky * (550 / lambda)^exponent   for d.z > 0, else 0
 *                                                  (W m^-2 sr^-1 nm^-1)
 *
 * prepare() tabulates L at whole nanometres over the render's wavelength
 * range (ctx->wavelength_min .. wavelength_max, widened to whole nm), and
 * add_radiance() interpolates that table linearly: exact at whole
 * nanometres. A wavelength outside the prepared range gets a NaN, which
 * the host counts as a failure and reports with the render: the plugin
 * relies on prepare() having been given every wavelength it is asked for
 * (a spectral bundle's whole range).
 *
 * Sampling: the cosine-weighted upper hemisphere (the host's warp),
 * pdf cos(theta) / pi.
 *
 * Parameters (updatable, class spectral): sky (default 1, >= 0), exponent
 * (default 4, in [0, 8]).
 * Build: cc -shared -fPIC -I include -o rayleigh_sky.so rayleigh_sky.c -lm */
#include <math.h>
#include <raysweep/plugin.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Host services, set once by the entry function (read-only afterwards). */
static const rsw_plugin_host *host;

enum {
  P_SKY,
  P_EXPONENT,
  P_COUNT
};

static const rsw_plugin_param params[P_COUNT] = {
    [P_SKY] = {.name = "sky", .type = RSW_PARAM_FLOAT, .default_value = {1.0}, .min = 0, .max = INFINITY},
    [P_EXPONENT] = {.name = "exponent", .type = RSW_PARAM_FLOAT, .default_value = {4.0}, .min = 0, .max = 8},
};

typedef struct rsky {
  double sky, exponent;
  /* Prepared: L at lo, lo + 1, ..., lo + n - 1 nm (lo whole). */
  double lo;
  size_t n;
  double *table;
} rsky;

static int create(const double *const *values, void **instance, char *errbuf, size_t errlen) {
  rsky *k = calloc(1, sizeof *k);
  if (!k) {
    snprintf(errbuf, errlen, "out of memory");
    return -1;
  }
  k->sky = values[P_SKY][0];
  k->exponent = values[P_EXPONENT][0];
  *instance = k;
  return 0;
}

static void destroy(void *instance) {
  rsky *k = instance;
  free(k->table);
  free(k);
}

static double *slot(rsky *k, const char *name) {
  if (strcmp(name, "sky") == 0) return &k->sky;
  if (strcmp(name, "exponent") == 0) return &k->exponent;
  return NULL;
}

static int set_param(void *instance, const char *name, const double *value, char *errbuf, size_t errlen) {
  double *dst = slot(instance, name);
  if (!dst) {
    snprintf(errbuf, errlen, "no parameter '%s'", name);
    return -1;
  }
  *dst = value[0];
  return 0;
}

static int get_param(const void *instance, const char *name, double *value_out) {
  double *src = slot((rsky *)instance, name);
  if (!src) return -1;
  *value_out = *src;
  return 0;
}

static int prepare(void *instance, const rsw_prepare_context *ctx, char *errbuf, size_t errlen) {
  rsky *k = instance;
  double lo = floor(ctx->wavelength_min), hi = ceil(ctx->wavelength_max);
  if (!(lo > 0) || !(hi >= lo) || hi - lo > 1e5) {
    snprintf(errbuf, errlen, "wavelength range %g..%g nm is not one this sky can tabulate",
             ctx->wavelength_min, ctx->wavelength_max);
    return -1;
  }
  size_t n = (size_t)(hi - lo) + 1;
  double *t = malloc(n * sizeof *t);
  if (!t) {
    snprintf(errbuf, errlen, "out of memory");
    return -1;
  }
  for (size_t i = 0; i < n; i++) t[i] = k->sky * pow(550.0 / (lo + (double)i), k->exponent);
  free(k->table);
  k->table = t, k->n = n, k->lo = lo;
  return 0;
}

static void add_radiance(const void *instance, rsw_stokes_context *ctx, const double d[3]) {
  const rsky *k = instance;
  for (size_t i = 0; i < ctx->count; i++) {
    double x = ctx->wavelengths[i] - k->lo;
    if (!(x >= 0 && x <= (double)(k->n - 1)) || !k->table) {
      ctx->stokes[0][i] = NAN; /* not prepared for it: the host reports it */
      continue;
    }
    if (d[2] <= 0) continue;
    size_t j = (size_t)x < k->n - 1 ? (size_t)x : k->n - 1;
    double f = x - (double)j, L = k->table[j];
    if (f > 0) L += f * (k->table[j + 1] - L);
    ctx->stokes[0][i] += L;
  }
}

static double pdf(const void *instance, const double d[3]) {
  (void)instance;
  return d[2] > 0 ? host->cosine_hemisphere_pdf(d) : 0;
}

static double sample(const void *instance, const double u[2], double d[3]) {
  host->square_to_cosine_hemisphere(u, d);
  return pdf(instance, d);
}

static const rsw_env_plugin table = {
    .abi_version = RSW_PLUGIN_ABI_VERSION,
    .type_name = "rayleigh_sky",
    .pretty_name = "Rayleigh-coloured sky, tabulated in prepare (SDK example)",
    .params = params,
    .n_params = P_COUNT,
    .create = create,
    .destroy = destroy,
    .set_param = set_param,
    .get_param = get_param,
    .prepare = prepare,
    .add_radiance = add_radiance,
    .sample = sample,
    .pdf = pdf,
};

const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *h) {
  host = h;
  return &table;
}
