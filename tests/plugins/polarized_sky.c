/* "polarized_sky": an example environment plugin whose light is partially
 * linearly polarized, for Stokes films (pixel_format "stokes") and their
 * datasets (docs/polarization.md). The same Stokes vector in every
 * direction and at every wavelength:
 *
 *   I = radiance                               (W m^-2 sr^-1 nm^-1)
 *   Q = radiance p cos(2 chi)
 *   U = radiance p sin(2 chi)
 *   V = 0
 *
 * so a camera ray that escapes sees DoLP = p and AoLP = chi exactly
 * (docs/polarization.md's conventions: AoLP = 0.5 atan2(U, Q)), and a
 * non-polarizing surface keeps both. Sampled uniformly over the sphere.
 *
 * Parameters (all updatable, class spectral): radiance (default 1),
 * polarization (p, default 0.5, in [0, 1]), polarization_angle (chi,
 * degrees, default 30, in [-90, 90]). (Not "dolp" and "aolp": a sweep's
 * coord takes the key's last name, and those are the dataset's
 * variables.)
 * Build: cc -shared -fPIC -I include -o polarized_sky.so polarized_sky.c -lm */
#include <math.h>
#include <raysweep/plugin.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI 3.14159265358979323846

static const rsw_plugin_host *host;

enum {
  P_RADIANCE,
  P_DOLP,
  P_AOLP,
  P_COUNT
};

static const rsw_plugin_param params[P_COUNT] = {
    [P_RADIANCE] =
        {.name = "radiance", .type = RSW_PARAM_FLOAT, .default_value = {1.0}, .min = 0, .max = INFINITY},
    [P_DOLP] = {.name = "polarization", .type = RSW_PARAM_FLOAT, .default_value = {0.5}, .min = 0, .max = 1},
    [P_AOLP] = {.name = "polarization_angle",
                .type = RSW_PARAM_FLOAT,
                .default_value = {30.0},
                .min = -90,
                .max = 90},
};

typedef struct polsky {
  double value[P_COUNT];
  double stokes[3]; /* I, Q, U (derived) */
} polsky;

static int find(const char *name) {
  for (int k = 0; k < P_COUNT; k++)
    if (strcmp(params[k].name, name) == 0) return k;
  return -1;
}

static int derive(polsky *s, char *errbuf, size_t errlen) {
  double L = s->value[P_RADIANCE], p = s->value[P_DOLP], a = s->value[P_AOLP] * PI / 180;
  if (!isfinite(L) || L < 0 || !(p >= 0 && p <= 1) || !isfinite(a)) {
    snprintf(errbuf, errlen, "radiance (%g) must be finite and >= 0, polarization (%g) in [0, 1]", L, p);
    return -1;
  }
  s->stokes[0] = L;
  s->stokes[1] = L * p * cos(2 * a);
  s->stokes[2] = L * p * sin(2 * a);
  return 0;
}

static int create(const double *const *values, void **instance, char *errbuf, size_t errlen) {
  polsky *s = calloc(1, sizeof *s);
  if (!s) {
    snprintf(errbuf, errlen, "out of memory");
    return -1;
  }
  for (int k = 0; k < P_COUNT; k++) s->value[k] = values[k][0];
  if (derive(s, errbuf, errlen)) {
    free(s);
    return -1;
  }
  *instance = s;
  return 0;
}

static void destroy(void *instance) {
  free(instance);
}

static int clone(const void *instance, void **out, char *errbuf, size_t errlen) {
  polsky *s = malloc(sizeof *s);
  if (!s) {
    snprintf(errbuf, errlen, "out of memory");
    return -1;
  }
  memcpy(s, instance, sizeof *s);
  *out = s;
  return 0;
}

static int set_param(void *instance, const char *name, const double *value, char *errbuf, size_t errlen) {
  polsky *s = instance;
  int k = find(name);
  if (k < 0) {
    snprintf(errbuf, errlen, "no parameter '%s'", name);
    return -1;
  }
  double old = s->value[k];
  s->value[k] = value[0];
  if (derive(s, errbuf, errlen)) {
    s->value[k] = old;
    derive(s, errbuf, errlen);
    return -1;
  }
  return 0;
}

static int get_param(const void *instance, const char *name, double *value_out) {
  int k = find(name);
  if (k < 0) return -1;
  value_out[0] = ((const polsky *)instance)->value[k];
  return 0;
}

static int prepare(void *instance, const rsw_prepare_context *ctx, char *errbuf, size_t errlen) {
  (void)instance, (void)ctx, (void)errbuf, (void)errlen;
  return 0;
}

static void add_radiance(const void *instance, rsw_stokes_context *ctx, const double d[3]) {
  (void)d;
  const polsky *s = instance;
  for (size_t i = 0; i < ctx->count; i++)
    for (int k = 0; k < 3; k++) ctx->stokes[k][i] += s->stokes[k];
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
    .type_name = "polarized_sky",
    .pretty_name = "Polarized uniform sky",
    .params = params,
    .n_params = P_COUNT,
    .create = create,
    .destroy = destroy,
    .clone = clone,
    .set_param = set_param,
    .get_param = get_param,
    .prepare = prepare,
    .add_radiance = add_radiance,
    .sample = sample,
    .pdf = pdf,
};

RSW_PLUGIN_EXPORT const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *h) {
  host = h;
  return &table;
}
