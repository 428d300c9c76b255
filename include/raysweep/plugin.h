/* raysweep environment plugin SDK: a versioned C ABI.
 *
 * A plugin is a shared object that exports one function,
 *
 *   const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *host);
 *
 * (its symbol name is RSW_ENV_PLUGIN_ENTRY). raysweepd (`render` or `serve`
 * with `--plugin-dir DIR`) dlopens every `*.so` in DIR once at start, calls
 * the entry with a table of host services, checks the returned table's ABI
 * version and type name, and registers the type as an emitter usable in
 * JSON and XML scenes: {"type": "<type_name>", <params>...}.
 *
 * The model follows Ocean's IEnvironmentPlugin (see docs/environment-plugins.md): the plugin adds the environment's spectral radiance
 * for a direction to per-wavelength Stokes vectors (I, Q, U, V), samples a
 * direction and returns its pdf (solid angle), evaluates the pdf of a
 * direction, and is prepared once with the simulation's wavelength range.
 *
 * Conventions
 * - Directions are unit 3-vectors in world space pointing AWAY from the
 *   scene towards the environment (the direction a ray escapes along).
 * - Wavelengths are in nanometres. Radiance is spectral radiance in the
 *   scene's unit (raysweep uses W m^-2 sr^-1 nm^-1 by convention).
 * - pdfs are densities per unit solid angle (sr^-1).
 * - Return codes: 0 is success; any non-zero value is an error, and the
 *   plugin must then have written a NUL-terminated message into errbuf
 *   (at most errlen bytes including the NUL; errbuf is never NULL and
 *   errlen is at least 64). The host prefixes the message with the type
 *   name and the scene place.
 * - Only the `mono` variant is served: the SDK is evaluated per wavelength.
 *   An `rgb` scene that uses a plugin type is refused by the host.
 * - Thread safety: create, destroy, clone, set_param, get_param and
 *   prepare are called from one thread at a time for a given instance,
 *   never concurrently with a render that uses it. add_radiance, sample
 *   and pdf are called CONCURRENTLY from several render threads on the
 *   same instance: they must not write to the instance (treat it as
 *   read-only; precompute in prepare) and must not keep global mutable
 *   state.
 * - Errors the host catches: a non-finite or negative radiance, a
 *   non-finite/non-positive pdf from sample, a non-finite or non-unit
 *   sampled direction, or a non-finite/negative pdf: the host counts the
 *   failure, keeps the first message, contributes black (zero) instead,
 *   and reports the count with the render (a spectral bundle: with each
 *   wavelength's film, a radiance answered at one wavelength counting
 *   for that film alone). A plugin that crashes cannot be contained in
 *   process.
 *
 * This header is C11 and C++ clean and uses no kernel type. */
#ifndef RAYSWEEP_PLUGIN_H
#define RAYSWEEP_PLUGIN_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Bumped on any incompatible change to the structs below. A plugin sets
 * rsw_env_plugin.abi_version to the value it was compiled against; the
 * host refuses a mismatch. */
#define RSW_PLUGIN_ABI_VERSION 1

/* Name of the exported entry symbol (for dlsym). */
#define RSW_ENV_PLUGIN_ENTRY "rsw_env_plugin_entry"

/* On Linux/gcc/clang, mark the entry function for export even when the
 * plugin is built with -fvisibility=hidden. */
#if defined(__GNUC__)
#define RSW_PLUGIN_EXPORT __attribute__((visibility("default")))
#else
#define RSW_PLUGIN_EXPORT
#endif

/* Log levels for rsw_plugin_host.log. */
enum {
  RSW_LOG_DEBUG = 0,
  RSW_LOG_INFO = 1,
  RSW_LOG_WARN = 2,
  RSW_LOG_ERROR = 3
};

/* ------------------------------------------------------------------------
 * Host services, owned by the host, valid until the plugin is unloaded
 * (the plugin may keep the pointer it receives in its entry function).
 * Every function is thread safe and allocation free. The warps are the
 * kernel's own (core/warp.h), so a plugin samples exactly like the kernel.
 * u[2] is a point of the unit square [0,1)^2; out-vectors are written.
 * ---------------------------------------------------------------------- */
typedef struct rsw_plugin_host {
  uint32_t abi_version; /* RSW_PLUGIN_ABI_VERSION of the host */

  /* Uniform sphere: z = 1 - 2 u1, phi = 2 pi u0; pdf 1/(4 pi). */
  void (*square_to_uniform_sphere)(const double u[2], double d[3]);
  double (*uniform_sphere_pdf)(void);

  /* Uniform hemisphere about +z; pdf 1/(2 pi) for z >= 0, else 0. */
  void (*square_to_uniform_hemisphere)(const double u[2], double d[3]);
  double (*uniform_hemisphere_pdf)(const double d[3]);

  /* Cosine-weighted hemisphere about +z; pdf cos(theta)/pi, 0 for z < 0. */
  void (*square_to_cosine_hemisphere)(const double u[2], double d[3]);
  double (*cosine_hemisphere_pdf)(const double d[3]);

  /* Cosine-power hemisphere about +z: pdf (n+1) cos^n(theta) / (2 pi),
   * n >= 0, 0 for z < 0. */
  void (*square_to_cosine_power_hemisphere)(const double u[2], double n, double d[3]);
  double (*cosine_power_hemisphere_pdf)(const double d[3], double n);

  /* Uniform cone about +z with cos of the half-angle cos_cutoff;
   * pdf 1/(2 pi (1 - cos_cutoff)) inside, 0 outside. */
  void (*square_to_uniform_cone)(const double u[2], double cos_cutoff, double d[3]);
  double (*uniform_cone_pdf)(const double d[3], double cos_cutoff);

  /* (phi, theta) -> xyz about the pole `axis` (its length is the radius;
   * phi measured from the first tangent of frame_from_normal(axis)), and
   * the inverse (phi in [0, 2 pi), theta in [0, pi]). */
  void (*phi_theta_to_xyz)(const double phi_theta[2], const double axis[3], double d[3]);
  void (*xyz_to_phi_theta)(const double d[3], const double axis[3], double phi_theta[2]);

  /* Orthonormal frame (s, t, n) from a unit normal n (Duff et al. 2017,
   * Mitsuba's coordinate_system). To rotate a +z-local sample v into the
   * frame: d = v0 s + v1 t + v2 n. */
  void (*frame_from_normal)(const double n[3], double s[3], double t[3]);

  /* Log a NUL-terminated message (level RSW_LOG_*) to the daemon's log. */
  void (*log)(int level, const char *msg);
} rsw_plugin_host;

/* ------------------------------------------------------------------------
 * Parameter descriptions. Owned by the plugin (static storage), valid
 * until unload. The host reads each declared parameter from the scene node
 * (missing -> default_value), and exposes it in the scene's parameter
 * table under the emitter's id.
 * ---------------------------------------------------------------------- */
enum {
  RSW_PARAM_FLOAT = 0,   /* one double: value[0] */
  RSW_PARAM_VECTOR3 = 1, /* three doubles: value[0..2] */
};

enum {
  /* Default: a change may be made between renders through the parameter
   * table (class `spectral`, like other per-wavelength scene data). */
  RSW_UPDATE_SPECTRAL = 0,
  /* Not updatable after creation (appears in the table read-only). */
  RSW_UPDATE_NONE = 1,
};

typedef struct rsw_plugin_param {
  const char *name;        /* [a-z_][a-z0-9_]*, unique within the plugin */
  int type;                /* RSW_PARAM_FLOAT or RSW_PARAM_VECTOR3 */
  double default_value[3]; /* used when the scene omits the parameter */
  int update_class;        /* RSW_UPDATE_SPECTRAL (default) or RSW_UPDATE_NONE */
  /* Inclusive range each component must lie in; the host refuses values
   * outside it (scene load and updates). min = max = 0 means unbounded. */
  double min, max;
} rsw_plugin_param;

/* ------------------------------------------------------------------------
 * Evaluation contexts, owned by the host, valid only during the call.
 * ---------------------------------------------------------------------- */
typedef struct rsw_stokes_context {
  const double *wavelengths; /* count wavelengths in nm */
  size_t count;
  /* stokes[k][i]: Stokes component k (0 = I, 1 = Q, 2 = U, 3 = V) at
   * wavelengths[i]. The host zeroes them; the plugin ADDS its radiance
   * (I must be finite and >= 0; leave Q, U, V alone for unpolarized light;
   * they are referred to the host's film frame). */
  double *stokes[4];
} rsw_stokes_context;

typedef struct rsw_prepare_context {
  double wavelength_min; /* nm: the range of wavelengths the render uses */
  double wavelength_max; /* nm; equal to wavelength_min for a mono render */
  const char *variant;   /* "mono" (the only variant served) */
} rsw_prepare_context;

/* ------------------------------------------------------------------------
 * The plugin's table, returned by the entry function. Owned by the plugin
 * (static storage), valid until the shared object is unloaded.
 * `instance` is an opaque pointer the plugin allocates in create/clone
 * and frees in destroy; the host never dereferences it.
 * ---------------------------------------------------------------------- */
typedef struct rsw_env_plugin {
  uint32_t abi_version;           /* must equal RSW_PLUGIN_ABI_VERSION */
  const char *type_name;          /* scene type: [a-z][a-z0-9_]*, e.g. "test" */
  const char *pretty_name;        /* human-readable, e.g. "SDK Test" */
  const rsw_plugin_param *params; /* n_params descriptions (may be NULL if 0) */
  size_t n_params;

  /* Create an instance. param_values[i] points to the value of params[i]
   * (1 or 3 doubles; defaults filled in by the host); the pointers are
   * valid only during the call. On success write *instance and return 0. */
  int (*create)(const double *const *param_values, void **instance, char *errbuf, size_t errlen);
  /* Free an instance (NULL is never passed). */
  void (*destroy)(void *instance);
  /* Optional (may be NULL): an independent copy of an instance, including
   * prepared state. */
  int (*clone)(const void *instance, void **out, char *errbuf, size_t errlen);
  /* Set one declared parameter (value has 1 or 3 doubles). The host calls
   * prepare again before the next render. */
  int (*set_param)(void *instance, const char *name, const double *value, char *errbuf, size_t errlen);
  /* Read one declared parameter into value_out (1 or 3 doubles); 0 on
   * success. */
  int (*get_param)(const void *instance, const char *name, double *value_out);
  /* Called before each render (and after parameter changes) with the
   * render's wavelength range. Precompute here whatever add_radiance /
   * sample / pdf need. */
  int (*prepare)(void *instance, const rsw_prepare_context *ctx, char *errbuf, size_t errlen);

  /* Add the radiance arriving from `direction` (i.e. seen by a ray that
   * escapes along it) to ctx->stokes. Concurrent, read-only. ctx->count
   * is any number from 1 (a render of one wavelength) up: a spectral
   * bundle asks for all its wavelengths (up to 16) in one call. The
   * answer at each wavelength must depend only on the instance as
   * prepared, the direction and that wavelength (not on the others asked
   * with it, nor on the call): the host may keep an answer and use it
   * again for the same direction. The same holds for sample and pdf. */
  void (*add_radiance)(const void *instance, rsw_stokes_context *ctx, const double direction[3]);
  /* Sample a direction from u in [0,1)^2, write it (unit) and return its
   * solid-angle pdf (> 0). Concurrent, read-only. */
  double (*sample)(const void *instance, const double u[2], double direction_out[3]);
  /* The pdf sample() would have for `direction` (>= 0). Concurrent,
   * read-only. */
  double (*pdf)(const void *instance, const double direction[3]);
} rsw_env_plugin;

/* The entry point every plugin exports (name: RSW_ENV_PLUGIN_ENTRY).
 * Called once after dlopen; `host` stays valid until unload. Return NULL
 * to refuse loading (e.g. host->abi_version too old). */
typedef const rsw_env_plugin *(*rsw_env_plugin_entry_fn)(const rsw_plugin_host *host);

RSW_PLUGIN_EXPORT const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *host);

#ifdef __cplusplus
}
#endif

#endif /* RAYSWEEP_PLUGIN_H */
