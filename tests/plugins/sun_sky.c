/* "sunsky": an example environment plugin with parameters. A uniform sky
 * plus a sun-like lobe (Phong-like cosine power around the sun direction):
 *
 *   L(d) = sky + sun * max(0, d . a)^n        (W m^-2 sr^-1 nm^-1, any
 *                                              wavelength)
 *
 * with a = sun_direction / |sun_direction| and n = sharpness.
 *
 * Sampling: a mixture of the cosine-power lobe about a (the host's
 * cosine-power warp, density (n+1) cos^n(theta) / (2 pi) on the hemisphere
 * about a; Global Illumination Compendium (36)) with probability p and the
 * uniform sphere (1 / (4 pi)) with probability 1 - p, where p is the lobe's
 * share of the radiant energy:
 *
 *   E_sky = int_S2 sky dw          = 4 pi sky
 *   E_sun = int_H2 sun cos^n dw    = 2 pi sun / (n + 1)
 *   p     = E_sun / (E_sun + E_sky)   (0 when both are 0)
 *
 * and the exact mixture density
 *
 *   pdf(d) = p (n+1) max(0, d . a)^n / (2 pi) + (1 - p) / (4 pi).
 *
 * Parameters (all updatable, class spectral): sky (default 0.1), sun
 * (default 10), sun_direction (default (0, 0, 1)), sharpness (default 100).
 * Build: cc -shared -fPIC -I include -o sunsky.so sun_sky.c */
#include <math.h>
#include <raysweep/plugin.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI 3.14159265358979323846

/* Host services, set once by the entry function (read-only afterwards). */
static const rsw_plugin_host *host;

enum {
  P_SKY,
  P_SUN,
  P_SUN_DIRECTION,
  P_SHARPNESS,
  P_COUNT
};

static const rsw_plugin_param params[P_COUNT] = {
    [P_SKY] = {.name = "sky", .type = RSW_PARAM_FLOAT, .default_value = {0.1}, .min = 0, .max = INFINITY},
    [P_SUN] = {.name = "sun", .type = RSW_PARAM_FLOAT, .default_value = {10.0}, .min = 0, .max = INFINITY},
    [P_SUN_DIRECTION] = {.name = "sun_direction", .type = RSW_PARAM_VECTOR3, .default_value = {0, 0, 1}},
    [P_SHARPNESS] =
        {.name = "sharpness", .type = RSW_PARAM_FLOAT, .default_value = {100.0}, .min = 0, .max = 1e6},
};

typedef struct sunsky {
  /* Parameters as set. */
  double sky, sun, sun_direction[3], sharpness;
  /* Derived by derive(): the lobe frame (s, t, a) and the lobe's
   * selection probability p. */
  double s[3], t[3], a[3], p_sun;
} sunsky;

static double dot3(const double x[3], const double y[3]) {
  return x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
}

/* Check the parameters and compute the derived state; 0 or an error. */
static int derive(sunsky *k, char *errbuf, size_t errlen) {
  const double *v = k->sun_direction;
  double len = sqrt(dot3(v, v));
  if (!isfinite(len) || len == 0) {
    snprintf(errbuf, errlen, "sun_direction (%g, %g, %g) must be finite and non-zero", v[0], v[1], v[2]);
    return -1;
  }
  if (!(k->sky >= 0) || !isfinite(k->sky) || !(k->sun >= 0) || !isfinite(k->sun)) {
    snprintf(errbuf, errlen, "sky (%g) and sun (%g) must be finite and >= 0", k->sky, k->sun);
    return -1;
  }
  if (!(k->sharpness >= 0) || !isfinite(k->sharpness)) {
    snprintf(errbuf, errlen, "sharpness (%g) must be finite and >= 0", k->sharpness);
    return -1;
  }
  for (int i = 0; i < 3; i++) k->a[i] = v[i] / len;
  host->frame_from_normal(k->a, k->s, k->t);
  double e_sky = 4 * PI * k->sky, e_sun = 2 * PI * k->sun / (k->sharpness + 1);
  k->p_sun = e_sun + e_sky > 0 ? e_sun / (e_sun + e_sky) : 0;
  return 0;
}

static int create(const double *const *values, void **instance, char *errbuf, size_t errlen) {
  sunsky *k = calloc(1, sizeof *k);
  if (!k) {
    snprintf(errbuf, errlen, "out of memory");
    return -1;
  }
  k->sky = values[P_SKY][0];
  k->sun = values[P_SUN][0];
  memcpy(k->sun_direction, values[P_SUN_DIRECTION], sizeof k->sun_direction);
  k->sharpness = values[P_SHARPNESS][0];
  if (derive(k, errbuf, errlen)) {
    free(k);
    return -1;
  }
  *instance = k;
  return 0;
}

static void destroy(void *instance) {
  free(instance);
}

static int clone_instance(const void *instance, void **out, char *errbuf, size_t errlen) {
  sunsky *k = malloc(sizeof *k);
  if (!k) {
    snprintf(errbuf, errlen, "out of memory");
    return -1;
  }
  memcpy(k, instance, sizeof *k);
  *out = k;
  return 0;
}

/* The slot of a parameter by name, or NULL. */
static double *slot(sunsky *k, const char *name) {
  if (strcmp(name, "sky") == 0) return &k->sky;
  if (strcmp(name, "sun") == 0) return &k->sun;
  if (strcmp(name, "sun_direction") == 0) return k->sun_direction;
  if (strcmp(name, "sharpness") == 0) return &k->sharpness;
  return NULL;
}

/* Writes the value; the derived state follows in prepare(), which the host
 * calls before the next render (and which refuses bad values). */
static int set_param(void *instance, const char *name, const double *value, char *errbuf, size_t errlen) {
  sunsky *k = instance;
  double *dst = slot(k, name);
  if (!dst) {
    snprintf(errbuf, errlen, "no parameter '%s'", name);
    return -1;
  }
  memcpy(dst, value, (strcmp(name, "sun_direction") == 0 ? 3 : 1) * sizeof(double));
  return 0;
}

static int get_param(const void *instance, const char *name, double *value_out) {
  double *src = slot((sunsky *)instance, name);
  if (!src) return -1;
  memcpy(value_out, src, (strcmp(name, "sun_direction") == 0 ? 3 : 1) * sizeof(double));
  return 0;
}

static int prepare(void *instance, const rsw_prepare_context *ctx, char *errbuf, size_t errlen) {
  (void)ctx; /* grey: the same radiance at every wavelength */
  return derive(instance, errbuf, errlen);
}

static void add_radiance(const void *instance, rsw_stokes_context *ctx, const double d[3]) {
  const sunsky *k = instance;
  double c = dot3(d, k->a);
  double L = k->sky + (c > 0 ? k->sun * pow(c, k->sharpness) : 0);
  for (size_t i = 0; i < ctx->count; i++) ctx->stokes[0][i] += L;
}

static double pdf(const void *instance, const double d[3]) {
  const sunsky *k = instance;
  double local[3] = {dot3(d, k->s), dot3(d, k->t), dot3(d, k->a)};
  double lobe = k->p_sun > 0 ? host->cosine_power_hemisphere_pdf(local, k->sharpness) : 0;
  return k->p_sun * lobe + (1 - k->p_sun) * host->uniform_sphere_pdf();
}

/* u[0] picks the component and is then rescaled to [0, 1) for reuse. */
static double sample(const void *instance, const double u[2], double d[3]) {
  const sunsky *k = instance;
  const double below_one = 0x1.fffffffffffffp-1;
  if (u[0] < k->p_sun) {
    double v[2] = {fmin(u[0] / k->p_sun, below_one), u[1]}, l[3];
    host->square_to_cosine_power_hemisphere(v, k->sharpness, l);
    for (int i = 0; i < 3; i++) d[i] = l[0] * k->s[i] + l[1] * k->t[i] + l[2] * k->a[i];
  } else {
    double v[2] = {fmin((u[0] - k->p_sun) / (1 - k->p_sun), below_one), u[1]};
    host->square_to_uniform_sphere(v, d);
  }
  return pdf(instance, d);
}

static const rsw_env_plugin table = {
    .abi_version = RSW_PLUGIN_ABI_VERSION,
    .type_name = "sunsky",
    .pretty_name = "Sky with a sun lobe (SDK example)",
    .params = params,
    .n_params = P_COUNT,
    .create = create,
    .destroy = destroy,
    .clone = clone_instance,
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
