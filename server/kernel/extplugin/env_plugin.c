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

/* The channels of a render: a bundle's wavelengths (3 per page), or one. */
#define MAX_CHANNELS (3 * RENDER_MAX_PAGES)

/* Answers replaced by black at one channel of the render (one film: a
 * bundle's wavelength), and the first one's message. */
typedef struct failure_slot {
  atomic_ullong count;
  atomic_int msg_state; /* 0 empty, 1 being written, 2 ready */
  char msg[512];
} failure_slot;

typedef struct env_adapter {
  emitter base;
  const loaded_plugin *lp;
  void *inst;
  double *values;    /* 3 per parameter: the table's view of them */
  double wavelength; /* nm, from prepare: the render's (a bundle's first) */
  /* A spectral bundle (render_ctx.bundle > 1): the wavelengths of page p's
   * channels at wl[3 p .. 3 p + 2] (those past the bundle repeat its
   * last), the bundle's n_wl first; 0 pages: one wavelength, `wavelength`,
   * in every channel. */
  int pages, n_wl;
  double wl[MAX_CHANNELS];
  /* The instance's state as of its last prepare() or parameter change,
   * unique in the process (g_generation): no answer kept from another
   * render or another instance passes for one of this one's. */
  unsigned long long gen;
  failure_slot fail[MAX_CHANNELS]; /* per channel; [0] alone without pages */
} env_adapter;

static atomic_ullong g_generation;

static const emitter_ops adapter_ops;

/* The channels of the render: 3 per page, or the one. */
static int n_channels(const env_adapter *a) {
  return a->pages ? 3 * a->pages : 1;
}

/* The channels [*c0, *c1) of the page the calling thread asks at
 * (rsw_page): that page's three, or the one. */
static void page_channels(const env_adapter *a, int *c0, int *c1) {
  int p = rsw_page < a->pages ? rsw_page : 0;
  *c0 = a->pages ? 3 * p : 0;
  *c1 = a->pages ? *c0 + 3 : 1;
}

static void record_failure(const env_adapter *ca, int c0, int c1, const char *fmt, ...)
    __attribute__((format(printf, 4, 5), cold, noinline));
/* Counts a failure at channels [c0, c1) (the films it reaches) and keeps
 * the first message of each. Takes a const adapter because the ops
 * receive one; the slots are the only state the render writes (atomics,
 * so concurrent writers are safe). */
static void record_failure(const env_adapter *ca, int c0, int c1, const char *fmt, ...) {
  env_adapter *a = (env_adapter *)ca;
  char text[sizeof a->fail[0].msg];
  int k =
      snprintf(text, sizeof text,
               "emitter '%s' (plugin type '%s'): ", a->base.base.id ? a->base.base.id : "?", a->lp->rec.name);
  if (k < 0 || (size_t)k >= sizeof text) k = 0;
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(text + k, sizeof text - (size_t)k, fmt, ap);
  va_end(ap);
  for (int c = c0; c < c1; c++) {
    failure_slot *f = &a->fail[c];
    atomic_fetch_add_explicit(&f->count, 1, memory_order_relaxed);
    int expected = 0;
    if (!atomic_compare_exchange_strong(&f->msg_state, &expected, 1)) continue;
    memcpy(f->msg, text, sizeof text);
    atomic_store_explicit(&f->msg_state, 2, memory_order_release);
  }
}

/* I of the plugin's radiance towards unit direction d at the n
 * wavelengths wl into I[0..n), as the plugin answered it (page_color
 * checks it). Q, U, V reach Stokes films through
 * adapter_eval_polarization. The first z (>= n) of each Stokes component
 * are zeroed: z a constant at every call, so that the zeros are written
 * in place, not by a memset whose masked stores the plugin's first
 * reads of them could not forward from (a stall that cost an unbundled
 * render 7%). */
static inline __attribute__((always_inline)) void
plugin_radiance(const env_adapter *a, vec3 d, const double *wl, size_t n, size_t z, double *I) {
  static const double zeros[MAX_CHANNELS];
  double q[MAX_CHANNELS], u[MAX_CHANNELS], v[MAX_CHANNELS], dir[3];
  memcpy(I, zeros, z * sizeof *I), memcpy(q, zeros, z * sizeof *q);
  memcpy(u, zeros, z * sizeof *u), memcpy(v, zeros, z * sizeof *v);
  out3(d, dir);
  rsw_stokes_context ctx = {.wavelengths = wl, .count = n, .stokes = {I, q, u, v}};
  a->lp->api->add_radiance(a->inst, &ctx, dir);
}

/* The plugin's radiance towards unit direction d at every channel into
 * I[0..n_channels) in one call: the one wavelength, a page's three, or a
 * bundle's n_wl (the channels past them repeat the last's answer). */
static void all_channels(const env_adapter *a, vec3 d, double *I) {
  if (!a->pages) {
    plugin_radiance(a, d, &a->wavelength, 1, 1, I);
  } else if (a->pages == 1) {
    plugin_radiance(a, d, a->wl, 3, 3, I);
  } else {
    plugin_radiance(a, d, a->wl, (size_t)a->n_wl, MAX_CHANNELS, I);
    for (int c = a->n_wl; c < 3 * a->pages; c++) I[c] = I[a->n_wl - 1];
  }
}

/* Channel c's answer v towards d, 0 (counted for channel c alone) where
 * it is not finite or negative. */
static inline double checked(const env_adapter *a, int c, double v, vec3 d) {
  if (__builtin_expect(isfinite(v) && v >= 0, 1)) return v;
  record_failure(
      a, c, c + 1,
      "add_radiance returned I = %g at %g nm for direction (%g, %g, %g) (must be finite and >= 0); "
      "used 0",
      v, a->pages ? a->wl[c] : a->wavelength, d.x, d.y, d.z);
  return 0.0;
}

/* The colour of the calling thread's page from every channel's answer
 * I towards d (checked). */
static color page_color(const env_adapter *a, const double *I, vec3 d) {
  if (!a->pages) return col1(checked(a, 0, I[0], d));
  int c0 = 3 * (rsw_page < a->pages ? rsw_page : 0);
  return col(checked(a, c0, I[c0], d), checked(a, c0 + 1, I[c0 + 1], d), checked(a, c0 + 2, I[c0 + 2], d));
}

/* ---- every page of a bundle from one call ------------------------------------
 *
 * A bundle's integrator asks an emitter once per page (the page in
 * rsw_page), page 0 first, every page with the same direction (an
 * escape) or the same sample numbers (a light sample: sample() takes no
 * wavelength, so every page gets the same direction). The plugin is
 * asked once, at page 0, for all the bundle's wavelengths; the other
 * pages read its answers from a per-thread memo. The integrators ask the
 * pages of one evaluation in one of two orders, and the memo finds the
 * entry with a few comparisons in both:
 *  - right after page 0 (an escape in path, volpath and direct; volpath's
 *    and direct's light samples): the newest entry;
 *  - after page 0 of a whole wave's light samples, lane after lane in the
 *    order their page 0 was asked (path.c's wave_light_samples, up to
 *    RENDER_WAVE_MAX lanes): the entry after the one read last, or for
 *    the first lane the first of the last run of page-0 asks.
 * An entry holds the plugin's raw answers, keyed by the instance, its
 * generation and the direction or the sample numbers, bit for bit: what
 * it holds is what the plugin would answer again (add_radiance, sample
 * and pdf are functions of the prepared instance and their arguments,
 * plugin.h), so the films are bit for bit those of one call per page.
 * Anything else (another order, more lanes than slots) asks the plugin
 * again. Each page's ask checks and counts its own channels' failures, as
 * when each page asked the plugin. */
#define MEMO_SLOTS 1024 /* >= RENDER_WAVE_MAX: path.c's wave of light samples */

enum memo_kind {
  MEMO_EVAL,
  MEMO_SAMPLE
};

typedef struct memo_entry {
  const env_adapter *a;
  unsigned long long gen;
  int kind;
  double key[3];          /* MEMO_EVAL: the ray's direction; MEMO_SAMPLE: u */
  double pdf, dir[3];     /* MEMO_SAMPLE: sample()'s answer */
  double I[MAX_CHANNELS]; /* add_radiance's at every channel (a sample: if good) */
} memo_entry;

/* The ring: the page-0 asks of a bundle's evaluations, entry i (counted
 * from the thread's first) in e[i % MEMO_SLOTS]. spare: the last page > 0
 * that found none, asked for every page for the pages after it. */
static _Thread_local struct {
  memo_entry e[MEMO_SLOTS];
  memo_entry spare;
  unsigned long long head; /* entries written */
  unsigned long long rd;   /* the entry a page > 0 read last */
  unsigned long long run;  /* the first of the last run of page-0 asks */
  bool writing;            /* the last ask was at page 0 */
} t_memo;

static bool memo_is(const memo_entry *m, const env_adapter *a, int kind, const double *key, size_t n) {
  if (m->a != a || m->gen != a->gen || m->kind != kind) return false;
  for (size_t i = 0; i < n; i++) { /* bit for bit (-0 is not 0; a NaN is itself) */
    uint64_t x, y;
    memcpy(&x, &m->key[i], sizeof x);
    memcpy(&y, &key[i], sizeof y);
    if (x != y) return false;
  }
  return true;
}

/* The entry a page > 0 asks for (a, kind, key) in the orders above, or
 * NULL. */
static const memo_entry *memo_find(const env_adapter *a, int kind, const double *key, size_t n) {
  unsigned long long h = t_memo.head, lo = h > MEMO_SLOTS ? h - MEMO_SLOTS : 0;
  t_memo.writing = false;
  const unsigned long long at[3] = {h - 1, t_memo.rd, t_memo.rd + 1};
  for (int i = 0; i < 3; i++)
    if (h && at[i] >= lo && at[i] < h && memo_is(&t_memo.e[at[i] % MEMO_SLOTS], a, kind, key, n)) {
      t_memo.rd = at[i];
      return &t_memo.e[at[i] % MEMO_SLOTS];
    }
  if (memo_is(&t_memo.spare, a, kind, key, n)) return &t_memo.spare;
  /* The first lane of a wave's light samples: the run's first entry or
   * one of the next few (page-0 asks just before the wave's). */
  for (unsigned long long i = t_memo.run < lo ? lo : t_memo.run; i < h && i < t_memo.run + 8; i++)
    if (memo_is(&t_memo.e[i % MEMO_SLOTS], a, kind, key, n)) {
      t_memo.rd = i;
      return &t_memo.e[i % MEMO_SLOTS];
    }
  return NULL;
}

/* The entry for a new evaluation (a, kind, key) at the calling thread's
 * page, for the caller to fill: the ring's newest at page 0, else the
 * spare. */
static memo_entry *memo_add(const env_adapter *a, int kind, const double *key, size_t n) {
  memo_entry *m = &t_memo.spare;
  if (rsw_page == 0) {
    if (!t_memo.writing) t_memo.run = t_memo.head;
    t_memo.writing = true;
    m = &t_memo.e[t_memo.head++ % MEMO_SLOTS];
  }
  m->a = a, m->gen = a->gen, m->kind = kind;
  memset(m->key, 0, sizeof m->key);
  memcpy(m->key, key, n * sizeof *key);
  return m;
}

/* The plugin's sample for u into m (its pdf and direction, and where they
 * are good every channel's radiance towards the direction). */
static void plugin_sample(const env_adapter *a, const double u[2], memo_entry *m) {
  m->dir[0] = m->dir[1] = m->dir[2] = NAN;
  m->pdf = a->lp->api->sample(a->inst, u, m->dir);
  vec3 dir = in3(m->dir);
  double len = v3_len(dir);
  if (isfinite(m->pdf) && m->pdf > 0 && isfinite(len) && fabs(len - 1.0) <= 1e-3)
    all_channels(a, v3_scale(dir, 1.0 / len), m->I);
}

static color adapter_sample(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds) {
  const env_adapter *a = (const env_adapter *)e;
  (void)ref;
  double uu[2] = {u.x, u.y};
  memo_entry own;
  const memo_entry *m = &own;
  if (a->pages > 1) {
    m = rsw_page > 0 ? memo_find(a, MEMO_SAMPLE, uu, 2) : NULL;
    if (!m) {
      memo_entry *w = memo_add(a, MEMO_SAMPLE, uu, 2);
      plugin_sample(a, uu, w);
      m = w;
    }
  } else {
    plugin_sample(a, uu, &own);
  }
  double pdf = m->pdf;
  const double *d = m->dir;
  ds->dist = INFINITY;
  ds->delta = false;
  ds->pdf = 0.0;
  ds->d = ds->p = v3(0, 0, 1);
  ds->n = v3(0, 0, -1);
  int c0, c1;
  page_channels(a, &c0, &c1);
  if (!isfinite(pdf) || !(pdf > 0)) {
    record_failure(a, c0, c1, "sample returned pdf %g (must be finite and > 0); sample dropped", pdf);
    return col1(0);
  }
  vec3 dir = in3(d);
  double len = v3_len(dir);
  if (!isfinite(len) || fabs(len - 1.0) > 1e-3) {
    record_failure(a, c0, c1, "sample returned direction (%g, %g, %g), not a unit vector; sample dropped",
                   d[0], d[1], d[2]);
    return col1(0);
  }
  dir = v3_scale(dir, 1.0 / len);
  ds->d = ds->p = dir;
  ds->n = v3_neg(dir);
  ds->pdf = pdf;
  color L = page_color(a, m->I, dir);
  for (int c = 0; c < 3; c++) L.c[c] /= pdf;
  return L;
}

/* The pdf is asked once for every page (integrators ask it at page 0
 * only): a failure counts for every channel. */
static double adapter_pdf(const emitter *e, const surface_interaction *ref, const direction_sample *ds) {
  const env_adapter *a = (const env_adapter *)e;
  (void)ref;
  double d[3];
  out3(ds->d, d);
  double pdf = a->lp->api->pdf(a->inst, d);
  if (!isfinite(pdf) || pdf < 0) {
    record_failure(a, 0, n_channels(a),
                   "pdf returned %g for direction (%g, %g, %g) (must be finite and >= 0); used 0", pdf, d[0],
                   d[1], d[2]);
    return 0.0;
  }
  return pdf;
}

static color adapter_eval(const emitter *e, const surface_interaction *hit, vec3 d) {
  const env_adapter *a = (const env_adapter *)e;
  (void)hit;
  double len = v3_len(d);
  if (!(len > 0) || !isfinite(len)) return col1(0);
  vec3 u = v3_scale(d, 1.0 / len);
  double I[MAX_CHANNELS];
  if (a->pages <= 1) {
    all_channels(a, u, I);
    return page_color(a, I, u);
  }
  double key[3];
  out3(d, key);
  const memo_entry *m = rsw_page > 0 ? memo_find(a, MEMO_EVAL, key, 3) : NULL;
  if (!m) {
    memo_entry *w = memo_add(a, MEMO_EVAL, key, 3);
    all_channels(a, u, w->I);
    m = w;
  }
  return page_color(a, m->I, u);
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
    int c0, c1;
    page_channels(a, &c0, &c1);
    record_failure(a, c0, c1, "add_radiance returned a non-finite Q, U or V at %g nm; used 0", a->wavelength);
    return;
  }
  quv[0] = s[1], quv[1] = s[2], quv[2] = s[3];
}

static size_t adapter_failures(const emitter *e, int channel, char *msg, size_t len) {
  env_adapter *a = (env_adapter *)e;
  if (channel < 0 || channel >= MAX_CHANNELS) return 0;
  failure_slot *f = &a->fail[channel];
  size_t n = (size_t)atomic_load(&f->count);
  if (n && msg && len && atomic_load_explicit(&f->msg_state, memory_order_acquire) == 2)
    snprintf(msg, len, "%s", f->msg);
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
  a->gen = atomic_fetch_add(&g_generation, 1) + 1;
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

/* A bundle asks for all its wavelengths in one add_radiance (prepared
 * with the bundle's range) and serves its pages from the answer (the memo
 * above); sample and pdf do not depend on the wavelength, so every page
 * draws the same direction. */
static bool adapter_pages(const object *o) {
  (void)o;
  return true;
}

static rsw_status adapter_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  env_adapter *a = (env_adapter *)o;
  for (int c = 0; c < MAX_CHANNELS; c++) {
    atomic_store(&a->fail[c].count, 0);
    atomic_store(&a->fail[c].msg_state, 0);
  }
  a->gen = atomic_fetch_add(&g_generation, 1) + 1;
  if (rc->variant != VARIANT_MONO)
    return rsw_fail(err, RSW_ERR_UNSUPPORTED, "",
                    "emitter '%s' (plugin type '%s') serves only the mono variant", o->id ? o->id : "?",
                    a->lp->rec.name);
  a->wavelength = rc->wavelength > 0 ? rc->wavelength : 550.0;
  rsw_prepare_context pc = {
      .wavelength_min = a->wavelength, .wavelength_max = a->wavelength, .variant = "mono"};
  a->pages = rc->bundle > 1 ? rc_pages(rc) : 0;
  a->n_wl = a->pages > 1 ? rc->bundle : 3;
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
      record_failure(a, 0, MAX_CHANNELS, "set_param('%s') failed: %s", api->params[i].name,
                     eb[0] ? eb : "(no message)");
    }
  }
  a->gen = atomic_fetch_add(&g_generation, 1) + 1;
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
