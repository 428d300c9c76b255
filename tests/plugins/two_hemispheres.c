/* The Ocean SDK's example environment ("test", "SDK Test") as a raysweep
 * plugin: spectral radiance 5.108 (scene units, W m^-2 sr^-1 nm^-1) from
 * the x > 0 hemisphere at wavelengths above 500 nm and from the x < 0
 * hemisphere below 500 nm, zero otherwise. A grey Lambertian object
 * turns orange on one side and blue on the other.
 * Build: cc -shared -fPIC -I include -o test.so tests/plugins/two_hemispheres.c */
#include <raysweep/plugin.h>
#include <stdlib.h>

#define RADIANCE 5.108

/* Host services, set once by the entry function (read-only afterwards). */
static const rsw_plugin_host *host;

/* No parameters and no state: every instance is this one placeholder
 * (never written), so destroy has nothing to free. */
static int no_state;

static int create(const double *const *values, void **instance, char *errbuf, size_t errlen) {
  (void)values, (void)errbuf, (void)errlen;
  *instance = &no_state;
  return 0;
}

static void destroy(void *instance) {
  (void)instance;
}

static void add_radiance(const void *instance, rsw_stokes_context *ctx, const double d[3]) {
  (void)instance;
  for (size_t i = 0; i < ctx->count; i++) {
    double wl = ctx->wavelengths[i]; /* nm */
    if ((d[0] > 0 && wl > 500) || (d[0] < 0 && wl < 500))
      ctx->stokes[0][i] += RADIANCE; /* I only: unpolarized */
  }
}

/* Uniform over the sphere: the environment is lit "about equally" from
 * every direction, pdf 1/(4 pi). */
static double sample(const void *instance, const double u[2], double d[3]) {
  (void)instance;
  host->square_to_uniform_sphere(u, d);
  return host->uniform_sphere_pdf();
}

static double pdf(const void *instance, const double d[3]) {
  (void)instance, (void)d;
  return host->uniform_sphere_pdf();
}

static const rsw_env_plugin table = {
    .abi_version = RSW_PLUGIN_ABI_VERSION,
    .type_name = "test",
    .pretty_name = "SDK Test",
    .create = create,
    .destroy = destroy,
    .add_radiance = add_radiance,
    .sample = sample,
    .pdf = pdf,
};

const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *h) {
  host = h;
  return &table;
}
