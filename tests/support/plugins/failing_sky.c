/* A misbehaving environment plugin for the tests (never an SDK example):
 * its radiance is NaN above 550 nm and negative (-1) at and below it, from
 * every direction, so every escape is an answer the host replaces by
 * black and counts in the film's plugin_failures (docs/environment-plugins.md).
 * Build: cc -shared -fPIC -I include -o failing_sky.so tests/support/plugins/failing_sky.c */
#include <math.h>
#include <raysweep/plugin.h>

static const rsw_plugin_host *host;
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
  (void)instance, (void)d;
  for (size_t i = 0; i < ctx->count; i++) ctx->stokes[0][i] += ctx->wavelengths[i] > 550 ? NAN : -1.0;
}

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
    .type_name = "failing_sky",
    .pretty_name = "NaN or negative everywhere (tests)",
    .create = create,
    .destroy = destroy,
    .add_radiance = add_radiance,
    .sample = sample,
    .pdf = pdf,
};

RSW_PLUGIN_EXPORT const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *h) {
  host = h;
  return &table;
}
