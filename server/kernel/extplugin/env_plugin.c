/* Environment plugins (include/raysweep/plugin.h): the loader and the
 * adapter emitter that puts a plugin instance behind the kernel's
 * emitter_ops, like the built-in `constant` (emitters/constant.c).
 *
 * The adapter guards the render against a misbehaving plugin: a radiance
 * that is not finite or negative, a sampled pdf that is not finite or not
 * > 0, a sampled direction that is not finite or not unit length, a pdf
 * that is not finite or negative. Each is counted (atomically: render
 * threads call concurrently), the first message is kept, and black (or a
 * zero pdf) is used instead, so no NaN reaches a film. A plugin that
 * crashes cannot be contained in process. */
#include "env_plugin.h"

#include <dirent.h>
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../scene/loader.h"
#include "../scene/params.h"
#include "raysweep/plugin.h"

/* Vector parameters are reported through pv_vector(), whose get/set
 * callbacks receive only the owner: one trampoline per vector slot. */
#define MAX_VECTOR_PARAMS 8
#define MAX_PARAMS        64

typedef struct loaded_plugin {
  plugin rec; /* what registry_find() returns; first member */
  const rsw_env_plugin *api;
  void *handle;
  char *file;
  int vec_slot[MAX_PARAMS]; /* param index -> vector trampoline slot, or -1 */
} loaded_plugin;

/* The process-wide loaded set (see env_plugin.h for why it is global).
 * Separate allocations, so plugin records never move. */
static loaded_plugin **g_loaded;
static size_t g_n_loaded;

/* ---- host services ------------------------------------------------------- */

static void out3(vec3 v, double d[3]) {
  d[0] = v.x, d[1] = v.y, d[2] = v.z;
}
static vec3 in3(const double d[3]) {
  return v3(d[0], d[1], d[2]);
}

static void h_sphere(const double u[2], double d[3]) {
  out3(warp_square_to_uniform_sphere(v2(u[0], u[1])), d);
}
static double h_sphere_pdf(void) {
  return RSW_INV_4PI;
}
static void h_hemi(const double u[2], double d[3]) {
  out3(warp_square_to_uniform_hemisphere(v2(u[0], u[1])), d);
}
static double h_hemi_pdf(const double d[3]) {
  return warp_square_to_uniform_hemisphere_pdf(in3(d));
}
static void h_cos(const double u[2], double d[3]) {
  out3(warp_square_to_cosine_hemisphere(v2(u[0], u[1])), d);
}
static double h_cos_pdf(const double d[3]) {
  return warp_square_to_cosine_hemisphere_pdf(in3(d));
}
static void h_cospow(const double u[2], double n, double d[3]) {
  out3(warp_square_to_cosine_power_hemisphere(v2(u[0], u[1]), n), d);
}
static double h_cospow_pdf(const double d[3], double n) {
  return warp_square_to_cosine_power_hemisphere_pdf(in3(d), n);
}
static void h_cone(const double u[2], double c, double d[3]) {
  out3(warp_square_to_uniform_cone(v2(u[0], u[1]), c), d);
}
static double h_cone_pdf(const double d[3], double c) {
  return warp_square_to_uniform_cone_pdf(in3(d), c);
}
static void h_pt2xyz(const double pt[2], const double axis[3], double d[3]) {
  out3(warp_phi_theta_to_xyz(v2(pt[0], pt[1]), in3(axis)), d);
}
static void h_xyz2pt(const double d[3], const double axis[3], double pt[2]) {
  vec2 r = warp_xyz_to_phi_theta(in3(d), in3(axis));
  pt[0] = r.x, pt[1] = r.y;
}
static void h_frame(const double n[3], double s[3], double t[3]) {
  vec3 vs, vt;
  coordinate_system(in3(n), &vs, &vt);
  out3(vs, s), out3(vt, t);
}
static void h_log(int level, const char *msg) {
  static const char *const names[] = {"debug", "info", "warning", "error"};
  const char *lv = level >= 0 && level <= 3 ? names[level] : "info";
  fprintf(stderr, "raysweepd: plugin %s: %s\n", lv, msg ? msg : "");
}

static const rsw_plugin_host host_services = {
    .abi_version = RSW_PLUGIN_ABI_VERSION,
    .square_to_uniform_sphere = h_sphere,
    .uniform_sphere_pdf = h_sphere_pdf,
    .square_to_uniform_hemisphere = h_hemi,
    .uniform_hemisphere_pdf = h_hemi_pdf,
    .square_to_cosine_hemisphere = h_cos,
    .cosine_hemisphere_pdf = h_cos_pdf,
    .square_to_cosine_power_hemisphere = h_cospow,
    .cosine_power_hemisphere_pdf = h_cospow_pdf,
    .square_to_uniform_cone = h_cone,
    .uniform_cone_pdf = h_cone_pdf,
    .phi_theta_to_xyz = h_pt2xyz,
    .xyz_to_phi_theta = h_xyz2pt,
    .frame_from_normal = h_frame,
    .log = h_log,
};

/* ---- the adapter emitter --------------------------------------------------- */

typedef struct env_adapter {
  emitter base;
  const loaded_plugin *lp;
  void *inst;
  double *values;    /* 3 per parameter: the table's view of them */
  double wavelength; /* nm, from prepare: the render's (a bundle's first) */
  /* A spectral bundle (render_ctx.bundle > 1): the wavelengths of page p's
   * channels at wl[3 p .. 3 p + 2], asked for together; 0 pages: one
   * wavelength, `wavelength`, in every channel. */
  int pages;
  double wl[3 * RENDER_MAX_PAGES];
  atomic_ullong failures;
  atomic_int msg_state; /* 0 empty, 1 being written, 2 ready */
  char msg[512];
} env_adapter;

static const emitter_ops adapter_ops;

static void record_failure(const env_adapter *ca, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Counts a failure and keeps the first message. Takes a const adapter
 * because the ops receive one; the counters are the only state the render
 * writes (atomics, so concurrent writers are safe). */
static void record_failure(const env_adapter *ca, const char *fmt, ...) {
  env_adapter *a = (env_adapter *)ca;
  atomic_fetch_add_explicit(&a->failures, 1, memory_order_relaxed);
  int expected = 0;
  if (!atomic_compare_exchange_strong(&a->msg_state, &expected, 1)) return;
  int k =
      snprintf(a->msg, sizeof a->msg,
               "emitter '%s' (plugin type '%s'): ", a->base.base.id ? a->base.base.id : "?", a->lp->rec.name);
  if (k < 0 || (size_t)k >= sizeof a->msg) k = 0;
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(a->msg + k, sizeof a->msg - (size_t)k, fmt, ap);
  va_end(ap);
  atomic_store_explicit(&a->msg_state, 2, memory_order_release);
}

/* I of the plugin's radiance towards unit direction d at the n
 * wavelengths wl into I[0..n); each that is not finite or negative is 0
 * (recorded). Q, U, V reach Stokes films through
 * adapter_eval_polarization. */
static void radiance_at(const env_adapter *a, vec3 d, const double *wl, size_t n, double *I) {
  double q[3] = {0}, u[3] = {0}, v[3] = {0}, dir[3];
  for (size_t i = 0; i < n; i++) I[i] = 0;
  out3(d, dir);
  rsw_stokes_context ctx = {.wavelengths = wl, .count = n, .stokes = {I, q, u, v}};
  a->lp->api->add_radiance(a->inst, &ctx, dir);
  for (size_t i = 0; i < n; i++)
    if (!isfinite(I[i]) || I[i] < 0) {
      record_failure(
          a,
          "add_radiance returned I = %g at %g nm for direction (%g, %g, %g) (must be finite and >= 0); "
          "used 0",
          I[i], wl[i], d.x, d.y, d.z);
      I[i] = 0.0;
    }
}

/* The plugin's radiance towards unit direction d in the colour's
 * channels: at the prepared wavelength in all three, or at the three
 * wavelengths of the bundle's page rsw_page. */
static color radiance(const env_adapter *a, vec3 d) {
  double I[3];
  if (!a->pages) {
    radiance_at(a, d, &a->wavelength, 1, I);
    return col1(I[0]);
  }
  radiance_at(a, d, &a->wl[3 * (rsw_page < a->pages ? rsw_page : 0)], 3, I);
  return col(I[0], I[1], I[2]);
}

static color adapter_sample(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds) {
  const env_adapter *a = (const env_adapter *)e;
  (void)ref;
  double uu[2] = {u.x, u.y}, d[3] = {NAN, NAN, NAN};
  double pdf = a->lp->api->sample(a->inst, uu, d);
  ds->dist = INFINITY;
  ds->delta = false;
  ds->pdf = 0.0;
  ds->d = ds->p = v3(0, 0, 1);
  ds->n = v3(0, 0, -1);
  if (!isfinite(pdf) || !(pdf > 0)) {
    record_failure(a, "sample returned pdf %g (must be finite and > 0); sample dropped", pdf);
    return col1(0);
  }
  vec3 dir = in3(d);
  double len = v3_len(dir);
  if (!isfinite(len) || fabs(len - 1.0) > 1e-3) {
    record_failure(a, "sample returned direction (%g, %g, %g), not a unit vector; sample dropped", d[0], d[1],
                   d[2]);
    return col1(0);
  }
  dir = v3_scale(dir, 1.0 / len);
  ds->d = ds->p = dir;
  ds->n = v3_neg(dir);
  ds->pdf = pdf;
  color L = radiance(a, dir);
  for (int c = 0; c < 3; c++) L.c[c] /= pdf;
  return L;
}

static double adapter_pdf(const emitter *e, const surface_interaction *ref, const direction_sample *ds) {
  const env_adapter *a = (const env_adapter *)e;
  (void)ref;
  double d[3];
  out3(ds->d, d);
  double pdf = a->lp->api->pdf(a->inst, d);
  if (!isfinite(pdf) || pdf < 0) {
    record_failure(a, "pdf returned %g for direction (%g, %g, %g) (must be finite and >= 0); used 0", pdf,
                   d[0], d[1], d[2]);
    return 0.0;
  }
  return pdf;
}

static color adapter_eval(const emitter *e, const surface_interaction *hit, vec3 d) {
  (void)hit;
  double len = v3_len(d);
  if (!(len > 0) || !isfinite(len)) return col1(0);
  return radiance((const env_adapter *)e, v3_scale(d, 1.0 / len));
}

/* Q, U, V of the plugin's radiance along ray direction d (Stokes films). */
static void adapter_eval_polarization(const emitter *e, vec3 d, double quv[3]) {
  const env_adapter *a = (const env_adapter *)e;
  double len = v3_len(d);
  quv[0] = quv[1] = quv[2] = 0;
  if (!(len > 0) || !isfinite(len)) return;
  double s[4] = {0, 0, 0, 0}, dir[3];
  out3(v3_scale(d, 1.0 / len), dir);
  rsw_stokes_context ctx = {
      .wavelengths = &a->wavelength, .count = 1, .stokes = {&s[0], &s[1], &s[2], &s[3]}};
  a->lp->api->add_radiance(a->inst, &ctx, dir);
  if (!isfinite(s[1]) || !isfinite(s[2]) || !isfinite(s[3])) {
    record_failure(a, "add_radiance returned a non-finite Q, U or V at %g nm; used 0", a->wavelength);
    return;
  }
  quv[0] = s[1], quv[1] = s[2], quv[2] = s[3];
}

static size_t adapter_failures(const emitter *e, char *msg, size_t len) {
  env_adapter *a = (env_adapter *)e;
  size_t n = (size_t)atomic_load(&a->failures);
  if (n && msg && len && atomic_load_explicit(&a->msg_state, memory_order_acquire) == 2)
    snprintf(msg, len, "%s", a->msg);
  return n;
}

static const emitter_ops adapter_ops = {.sample_direction = adapter_sample,
                                        .pdf_direction = adapter_pdf,
                                        .eval = adapter_eval,
                                        .eval_polarization = adapter_eval_polarization,
                                        .failures = adapter_failures};

static const loaded_plugin *find_loaded(const char *name) {
  for (size_t i = 0; name && i < g_n_loaded; i++)
    if (strcmp(g_loaded[i]->rec.name, name) == 0) return g_loaded[i];
  return NULL;
}

static void adapter_destroy(object *o) {
  env_adapter *a = (env_adapter *)o;
  if (a->inst) a->lp->api->destroy(a->inst);
  free(a->values);
  free(a);
}

static bool unbounded(const rsw_plugin_param *p) {
  return p->min == 0 && p->max == 0;
}

static rsw_status adapter_create(loader *ld, node *n, object **out) {
  const loaded_plugin *lp = find_loaded(n->type);
  if (!lp) return ld_fail(ld, n, NULL, RSW_ERR_UNKNOWN_PLUGIN, "plugin type '%s' is not loaded", n->type);
  const rsw_env_plugin *api = lp->api;
  if (ld->variant != VARIANT_MONO)
    return ld_fail(ld, n, NULL, RSW_ERR_UNSUPPORTED,
                   "emitter type '%s' is an environment plugin (%s), which serves only the mono variant "
                   "(the plugin SDK is evaluated per wavelength); render this scene with variant mono",
                   lp->rec.name, lp->file);
  env_adapter *a = calloc(1, sizeof *a);
  double *values = calloc(3 * (api->n_params ? api->n_params : 1), sizeof *values);
  const double **ptrs = calloc(api->n_params ? api->n_params : 1, sizeof *ptrs);
  if (!a || !values || !ptrs) {
    free(a), free(values), free(ptrs);
    return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  }
  a->base.base.plugin = &lp->rec;
  a->base.base.id = n->id;
  a->base.ops = &adapter_ops;
  a->base.flags = EMITTER_INFINITE;
  a->lp = lp;
  a->values = values;
  a->wavelength = 550.0;
  rsw_status st = ld_float_range(ld, n, "sampling_weight", 1.0, 0.0, INFINITY, &a->base.sampling_weight);
  for (size_t i = 0; !st && i < api->n_params; i++) {
    const rsw_plugin_param *p = &api->params[i];
    double lo = unbounded(p) ? -INFINITY : p->min, hi = unbounded(p) ? INFINITY : p->max;
    double *v = &values[3 * i];
    ptrs[i] = v;
    if (p->type == RSW_PARAM_FLOAT) {
      st = ld_float_range(ld, n, p->name, p->default_value[0], lo, hi, v);
    } else {
      vec3 r;
      st = ld_vec3(ld, n, p->name, in3(p->default_value), &r, NULL);
      if (!st) {
        out3(r, v);
        for (int k = 0; k < 3 && !st; k++)
          if (v[k] < lo || v[k] > hi)
            st = ld_fail(ld, n, p->name, RSW_ERR_RANGE, "component %d is %g, outside [%g, %g]", k, v[k], lo,
                         hi);
      }
    }
  }
  if (!st) {
    char eb[512] = "";
    if (api->create(ptrs, &a->inst, eb, sizeof eb) || !a->inst) {
      eb[sizeof eb - 1] = 0;
      a->inst = NULL;
      st = ld_fail(ld, n, NULL, RSW_ERR_INVALID, "plugin '%s' (%s) create failed: %s", lp->rec.name, lp->file,
                   eb[0] ? eb : "(no message)");
    }
  }
  free(ptrs);
  if (st) {
    adapter_destroy(&a->base.base);
    return st;
  }
  *out = &a->base.base;
  return RSW_OK;
}

/* A plugin's emission may depend on the wavelength: assumed so. */
static bool adapter_spectral(const object *o) {
  (void)o;
  return true;
}

/* A bundle asks for each page's three wavelengths in one add_radiance
 * (prepared with the bundle's range); sample and pdf do not depend on
 * the wavelength, so every page draws the same direction. */
static bool adapter_pages(const object *o) {
  (void)o;
  return true;
}

static rsw_status adapter_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  env_adapter *a = (env_adapter *)o;
  atomic_store(&a->failures, 0);
  atomic_store(&a->msg_state, 0);
  if (rc->variant != VARIANT_MONO)
    return rsw_fail(err, RSW_ERR_UNSUPPORTED, "",
                    "emitter '%s' (plugin type '%s') serves only the mono variant", o->id ? o->id : "?",
                    a->lp->rec.name);
  a->wavelength = rc->wavelength > 0 ? rc->wavelength : 550.0;
  rsw_prepare_context pc = {
      .wavelength_min = a->wavelength, .wavelength_max = a->wavelength, .variant = "mono"};
  a->pages = rc->bundle > 1 ? rc_pages(rc) : 0;
  for (int p = 0; p < a->pages; p++) {
    render_ctx q = rc_page(rc, p);
    for (int c = 0; c < 3; c++) {
      double w = rc_channel_wavelength(&q, c);
      a->wl[3 * p + c] = w;
      pc.wavelength_min = fmin(pc.wavelength_min, w);
      pc.wavelength_max = fmax(pc.wavelength_max, w);
    }
  }
  char eb[512] = "";
  if (a->lp->api->prepare && a->lp->api->prepare(a->inst, &pc, eb, sizeof eb)) {
    eb[sizeof eb - 1] = 0;
    char at[64];
    if (pc.wavelength_min < pc.wavelength_max)
      snprintf(at, sizeof at, "for %g..%g nm", pc.wavelength_min, pc.wavelength_max);
    else
      snprintf(at, sizeof at, "at %g nm", pc.wavelength_min);
    return rsw_fail(err, RSW_ERR_INVALID, "", "emitter '%s' (plugin type '%s', %s): prepare failed %s: %s",
                    o->id ? o->id : "?", a->lp->rec.name, a->lp->file, at, eb[0] ? eb : "(no message)");
  }
  return RSW_OK;
}

/* Push the table's values into the plugin (after an update). set_param
 * errors cannot be returned from here: they are recorded as failures and
 * reported with the next render. prepare() runs before every render, so
 * derived state is refreshed there. */
static void adapter_parameters_changed(object *o) {
  env_adapter *a = (env_adapter *)o;
  const rsw_env_plugin *api = a->lp->api;
  for (size_t i = 0; i < api->n_params; i++) {
    if (api->params[i].update_class == RSW_UPDATE_NONE) continue;
    double cur[3] = {NAN, NAN, NAN};
    size_t nc = api->params[i].type == RSW_PARAM_FLOAT ? 1 : 3;
    if (api->get_param && api->get_param(a->inst, api->params[i].name, cur) == 0 &&
        memcmp(cur, &a->values[3 * i], nc * sizeof(double)) == 0)
      continue;
    char eb[512] = "";
    if (api->set_param(a->inst, api->params[i].name, &a->values[3 * i], eb, sizeof eb)) {
      eb[sizeof eb - 1] = 0;
      record_failure(a, "set_param('%s') failed: %s", api->params[i].name, eb[0] ? eb : "(no message)");
    }
  }
}

/* pv_vector trampolines: slot k is the k-th vector parameter. */
static size_t vec_param_index(const env_adapter *a, int slot) {
  for (size_t i = 0; i < a->lp->api->n_params; i++)
    if (a->lp->vec_slot[i] == slot) return i;
  return 0; /* unreachable: slots are assigned at load */
}
#define VEC_TRAMPOLINE(k)                                                                                    \
  static vec3 vget_##k(const object *o) {                                                                    \
    const env_adapter *a = (const env_adapter *)o;                                                           \
    return in3(&a->values[3 * vec_param_index(a, k)]);                                                       \
  }                                                                                                          \
  static void vset_##k(object *o, vec3 v) {                                                                  \
    env_adapter *a = (env_adapter *)o;                                                                       \
    out3(v, &a->values[3 * vec_param_index(a, k)]);                                                          \
  }
VEC_TRAMPOLINE(0)
VEC_TRAMPOLINE(1)
VEC_TRAMPOLINE(2)
VEC_TRAMPOLINE(3)
VEC_TRAMPOLINE(4)
VEC_TRAMPOLINE(5)
VEC_TRAMPOLINE(6)
VEC_TRAMPOLINE(7)
#undef VEC_TRAMPOLINE
static const vec_get_fn vec_getters[MAX_VECTOR_PARAMS] = {vget_0, vget_1, vget_2, vget_3,
                                                          vget_4, vget_5, vget_6, vget_7};
static const vec_set_fn vec_setters[MAX_VECTOR_PARAMS] = {vset_0, vset_1, vset_2, vset_3,
                                                          vset_4, vset_5, vset_6, vset_7};

static void adapter_traverse(object *o, param_visitor *v) {
  env_adapter *a = (env_adapter *)o;
  const rsw_env_plugin *api = a->lp->api;
  pv_float(v, "sampling_weight", &a->base.sampling_weight, UPDATE_SPECTRAL, 0.0, INFINITY);
  for (size_t i = 0; i < api->n_params; i++) {
    const rsw_plugin_param *p = &api->params[i];
    update_class cls = p->update_class == RSW_UPDATE_NONE ? UPDATE_NONE : UPDATE_SPECTRAL;
    if (p->type == RSW_PARAM_FLOAT) {
      pv_float(v, p->name, &a->values[3 * i], cls, unbounded(p) ? -INFINITY : p->min,
               unbounded(p) ? INFINITY : p->max);
    } else {
      int k = a->lp->vec_slot[i];
      pv_vector(v, p->name, vec_getters[k], vec_setters[k], cls);
    }
  }
}

/* ---- loading ------------------------------------------------------------------ */

static bool valid_name(const char *s, bool allow_leading_underscore) {
  if (!s || !((*s >= 'a' && *s <= 'z') || (allow_leading_underscore && *s == '_'))) return false;
  size_t n = 0;
  for (; *s; s++, n++)
    if (!((*s >= 'a' && *s <= 'z') || (*s >= '0' && *s <= '9') || *s == '_')) return false;
  return n <= 64;
}

static void unload_one(loaded_plugin *lp) {
  if (!lp) return;
  if (lp->handle) dlclose(lp->handle);
  free(lp->file);
  free(lp);
}

/* Check the table a plugin returned; on failure fill err naming file. */
static rsw_status check_table(const rsw_env_plugin *api, const char *file, loaded_plugin *lp, rsw_err *err) {
  if (!api)
    return rsw_fail(err, RSW_ERR_INVALID, file,
                    "plugin %s: its entry %s() returned NULL (plugin refused to load)", file,
                    RSW_ENV_PLUGIN_ENTRY);
  if (api->abi_version != RSW_PLUGIN_ABI_VERSION)
    return rsw_fail(err, RSW_ERR_UNSUPPORTED, file,
                    "plugin %s: ABI version %u, but this raysweepd speaks ABI version %d "
                    "(rebuild it against this raysweepd's include/raysweep/plugin.h)",
                    file, (unsigned)api->abi_version, RSW_PLUGIN_ABI_VERSION);
  if (!valid_name(api->type_name, false))
    return rsw_fail(err, RSW_ERR_INVALID, file,
                    "plugin %s: invalid type name '%s' (must match [a-z][a-z0-9_]*)", file,
                    api->type_name ? api->type_name : "(null)");
  const char *missing = !api->create         ? "create"
                        : !api->destroy      ? "destroy"
                        : !api->add_radiance ? "add_radiance"
                        : !api->sample       ? "sample"
                        : !api->pdf          ? "pdf"
                                             : NULL;
  if (!missing && api->n_params && !api->set_param) missing = "set_param (the plugin declares parameters)";
  if (missing)
    return rsw_fail(err, RSW_ERR_INVALID, file, "plugin %s (type '%s'): callback %s is NULL", file,
                    api->type_name, missing);
  if (api->n_params > MAX_PARAMS || (api->n_params && !api->params))
    return rsw_fail(err, RSW_ERR_INVALID, file,
                    "plugin %s (type '%s'): %zu parameters (at most %d, params non-NULL)", file,
                    api->type_name, api->n_params, MAX_PARAMS);
  int n_vec = 0;
  for (size_t i = 0; i < api->n_params; i++) {
    const rsw_plugin_param *p = &api->params[i];
    lp->vec_slot[i] = -1;
    if (!valid_name(p->name, true) || strcmp(p->name, "sampling_weight") == 0)
      return rsw_fail(
          err, RSW_ERR_INVALID, file,
          "plugin %s (type '%s'): parameter %zu has invalid name '%s' (must match [a-z_][a-z0-9_]*, "
          "not sampling_weight)",
          file, api->type_name, i, p->name ? p->name : "(null)");
    for (size_t j = 0; j < i; j++)
      if (strcmp(api->params[j].name, p->name) == 0)
        return rsw_fail(err, RSW_ERR_DUPLICATE, file, "plugin %s (type '%s'): parameter '%s' declared twice",
                        file, api->type_name, p->name);
    if (p->type != RSW_PARAM_FLOAT && p->type != RSW_PARAM_VECTOR3)
      return rsw_fail(err, RSW_ERR_INVALID, file, "plugin %s (type '%s'): parameter '%s' has unknown type %d",
                      file, api->type_name, p->name, p->type);
    if (p->update_class != RSW_UPDATE_SPECTRAL && p->update_class != RSW_UPDATE_NONE)
      return rsw_fail(err, RSW_ERR_INVALID, file,
                      "plugin %s (type '%s'): parameter '%s' has unknown update class %d", file,
                      api->type_name, p->name, p->update_class);
    if (!(p->min <= p->max))
      return rsw_fail(err, RSW_ERR_INVALID, file, "plugin %s (type '%s'): parameter '%s' has min %g > max %g",
                      file, api->type_name, p->name, p->min, p->max);
    if (p->type == RSW_PARAM_VECTOR3) {
      if (n_vec == MAX_VECTOR_PARAMS)
        return rsw_fail(err, RSW_ERR_LIMIT, file, "plugin %s (type '%s'): more than %d vector parameters",
                        file, api->type_name, MAX_VECTOR_PARAMS);
      lp->vec_slot[i] = n_vec++;
    }
  }
  return RSW_OK;
}

static rsw_status load_one(const char *path, rsw_err *err) {
  loaded_plugin *lp = calloc(1, sizeof *lp);
  char *file = rsw_strdup(path);
  if (!lp || !file) {
    free(lp), free(file);
    return rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory");
  }
  lp->file = file;
  lp->handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
  if (!lp->handle) {
    const char *why = dlerror();
    rsw_fail(err, RSW_ERR_FILE, path, "plugin %s: cannot load: %s", path, why ? why : "dlopen failed");
    unload_one(lp);
    return err->code;
  }
  dlerror();
  void *sym = dlsym(lp->handle, RSW_ENV_PLUGIN_ENTRY);
  if (!sym) {
    rsw_fail(err, RSW_ERR_NOT_FOUND, path,
             "plugin %s: no exported symbol %s (define `const rsw_env_plugin *%s(const rsw_plugin_host *)` "
             "with C linkage)",
             path, RSW_ENV_PLUGIN_ENTRY, RSW_ENV_PLUGIN_ENTRY);
    unload_one(lp);
    return err->code;
  }
  rsw_env_plugin_entry_fn entry;
  memcpy(&entry, &sym, sizeof entry); /* object -> function pointer (POSIX dlsym) */
  const rsw_env_plugin *api = entry(&host_services);
  rsw_status st = check_table(api, path, lp, err);
  if (!st) {
    const char *name = api->type_name;
    const plugin *builtin = NULL;
    for (size_t i = 0; rsw_plugins[i]; i++)
      if (strcmp(rsw_plugins[i]->name, name) == 0) builtin = rsw_plugins[i];
    const loaded_plugin *other = find_loaded(name);
    if (builtin)
      st = rsw_fail(err, RSW_ERR_DUPLICATE, path,
                    "plugin %s: type name '%s' clashes with the built-in %s '%s'", path, name,
                    obj_class_name(builtin->cls), name);
    else if (other)
      st = rsw_fail(err, RSW_ERR_DUPLICATE, path,
                    "plugin %s: type name '%s' is already provided by plugin %s", path, name, other->file);
  }
  if (st) {
    unload_one(lp);
    return st;
  }
  lp->api = api;
  lp->rec = (plugin){.name = api->type_name,
                     .cls = CLS_EMITTER,
                     .create = adapter_create,
                     .destroy = adapter_destroy,
                     .prepare = adapter_prepare,
                     .ops = &adapter_ops,
                     .traverse = adapter_traverse,
                     .parameters_changed = adapter_parameters_changed,
                     .spectral = adapter_spectral,
                     .pages = adapter_pages};
  loaded_plugin **grown = realloc(g_loaded, (g_n_loaded + 1) * sizeof *grown);
  if (!grown) {
    unload_one(lp);
    return rsw_fail(err, RSW_ERR_NOMEM, path, "out of memory");
  }
  g_loaded = grown;
  g_loaded[g_n_loaded++] = lp;
  return RSW_OK;
}

static int cmp_str(const void *a, const void *b) {
  return strcmp(*(char *const *)a, *(char *const *)b);
}

/* The `*.so` files of dir, sorted (owned: free each and the array). */
static rsw_status list_dir(const char *dir, char ***out, size_t *count, rsw_err *err) {
  DIR *d = opendir(dir);
  if (!d) return rsw_fail(err, RSW_ERR_FILE, dir, "--plugin-dir %s: cannot open the directory", dir);
  char **names = NULL;
  size_t n = 0, cap = 0;
  rsw_status st = RSW_OK;
  for (struct dirent *de; !st && (de = readdir(d));) {
    size_t len = strlen(de->d_name);
    if (len < 4 || strcmp(de->d_name + len - 3, ".so") != 0 || de->d_name[0] == '.') continue;
    if (n == cap) {
      char **g = realloc(names, (cap = cap ? 2 * cap : 16) * sizeof *g);
      if (!g) {
        st = rsw_fail(err, RSW_ERR_NOMEM, dir, "out of memory");
        break;
      }
      names = g;
    }
    size_t plen = strlen(dir) + len + 2;
    if (!(names[n] = malloc(plen))) {
      st = rsw_fail(err, RSW_ERR_NOMEM, dir, "out of memory");
      break;
    }
    snprintf(names[n++], plen, "%s/%s", dir, de->d_name);
  }
  closedir(d);
  if (!st && n) qsort(names, n, sizeof *names, cmp_str);
  if (st) {
    for (size_t i = 0; i < n; i++) free(names[i]);
    free(names);
    return st;
  }
  *out = names;
  *count = n;
  return RSW_OK;
}

rsw_status plugins_load_dir(const char *dir, rsw_err *err) {
  char **names = NULL;
  size_t n = 0;
  rsw_status st = list_dir(dir, &names, &n, err);
  if (st) return st;
  size_t before = g_n_loaded;
  for (size_t i = 0; !st && i < n; i++) st = load_one(names[i], err);
  if (st) /* all or nothing for this directory */
    while (g_n_loaded > before) unload_one(g_loaded[--g_n_loaded]);
  for (size_t i = 0; i < n; i++) free(names[i]);
  free(names);
  return st;
}

size_t plugins_load_dir_lenient(const char *dir, void (*report)(void *user, const rsw_err *e), void *user,
                                rsw_err *err) {
  char **names = NULL;
  size_t n = 0, refused = 0;
  if (list_dir(dir, &names, &n, err)) return (size_t)-1;
  for (size_t i = 0; i < n; i++) {
    rsw_err e = {0};
    if (load_one(names[i], &e) != RSW_OK) {
      refused++;
      if (report) report(user, &e);
    }
    free(names[i]);
  }
  free(names);
  return refused;
}

void plugins_unload(void) {
  while (g_n_loaded) unload_one(g_loaded[--g_n_loaded]);
  free(g_loaded);
  g_loaded = NULL;
}

const plugin *plugins_find(const char *name) {
  const loaded_plugin *lp = find_loaded(name);
  return lp ? &lp->rec : NULL;
}

size_t plugins_count(void) {
  return g_n_loaded;
}

const plugin *plugins_at(size_t i, const char **pretty_name, const char **file) {
  if (i >= g_n_loaded) return NULL;
  if (pretty_name) *pretty_name = g_loaded[i]->api->pretty_name ? g_loaded[i]->api->pretty_name : "";
  if (file) *file = g_loaded[i]->file;
  return &g_loaded[i]->rec;
}
