/* Runtime interfaces of the radiometric kernel: object classes, the plugin
 * record, and one small ops table per concept (texture, BSDF, emitter,
 * sensor, sampler, integrator, volume, phase function, medium). Every implementation lives in its class's
 * directory, one plugin per file, and is listed once in scene/registry.c.
 *
 * Conventions (Mitsuba 3, docs/kernel-conventions.md#frames-and-directions):
 *  - local shading frame: n = +z; wi points towards where the path came
 *    from (the sensor side), wo the other way; both point away from the
 *    surface;
 *  - bsdf eval returns f_r(wi, wo) |cos theta_o| (cosine folded in);
 *    sample returns the weight eval/pdf;
 *  - radiance in W m^-2 sr^-1 [nm^-1]; irradiance in W m^-2 [nm^-1]. */
#ifndef RSW_KERNEL_H
#define RSW_KERNEL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "core/mueller.h"
#include "core/rng.h"
#include "core/transform.h"
#include "core/vec.h"
#include "core/warp.h"
#include "rsw_error.h"

/* The largest magnitude a scene value given as a number, an rgb triple or
 * a spectrum may have (a radiance, an irradiance, a reflectance, a scale),
 * at load and in a PATCH. Sane radiometric values are far below it (the
 * Sun's irradiance is about 1.4e3 W m^-2; photon fluxes about 1e22), and
 * it keeps every product the kernel forms finite: a radiance of 1e30 times
 * BSDF, geometry and 1/pdf factors of up to 1e8 still fits a float32 film
 * (3.4e38), and squares for the variance fit a double. docs/robustness.md. */
#define RSW_MAX_MAGNITUDE 1e30

typedef enum obj_class {
  CLS_SCENE,
  CLS_SHAPE,
  CLS_BSDF,
  CLS_EMITTER,
  CLS_SENSOR,
  CLS_FILM,
  CLS_SAMPLER,
  CLS_RFILTER,
  CLS_INTEGRATOR,
  CLS_TEXTURE,
  CLS_MEDIUM,
  CLS_PHASE,
  CLS_VOLUME,
  CLS_EXTREMUM, /* a medium's local majorants (extremum_grid, extremum_global) */
  CLS__COUNT
} obj_class;

/* "shape", "bsdf", ... (the XML tag of the class). */
const char *obj_class_name(obj_class c);

typedef enum rsw_variant {
  VARIANT_RGB,
  VARIANT_MONO
} rsw_variant;

/* A variant's name: "mono", "rgb", "mono_polarized", "rgb_polarized"
 * (the polarized ones carry Stokes vectors, docs/polarization.md). */
const char *variant_name(rsw_variant v, bool polarized);
/* Parse a variant name (also Mitsuba's scalar_mono, scalar_mono_double,
 * scalar_rgb and their _polarized forms). False: not a variant. */
bool variant_parse(const char *name, rsw_variant *v, bool *polarized);

/* A spectral bundle (mono): the wavelengths one path carries
 * (docs/experiments.md#spectral-bundles). Up to three ride in the colour
 * channels; more ride in "pages" of three: page p holds wavelengths
 * 3p .. 3p + 2 in its channels, and an object evaluates at the page the
 * integrator names in rsw_page (a uniform texture keeps a value per page;
 * objects that cannot, scene_page_blocker). */
#define RENDER_MAX_BUNDLE 16
#define RENDER_MAX_PAGES  ((RENDER_MAX_BUNDLE + 2) / 3)

/* What a render is evaluated at; given to every plugin's prepare(). */
typedef struct render_ctx {
  rsw_variant variant;
  bool polarized;    /* mono_polarized, rgb_polarized */
  double wavelength; /* nm; mono only (default 550); a bundle's first */
  /* Mono: wavelengths carried per path, 0 or 1 for one (every channel at
   * `wavelength`), up to RENDER_MAX_BUNDLE; channel c of page p renders at
   * wl[3 p + c] (those past the bundle repeat its last wavelength). */
  int bundle;
  double wl[RENDER_MAX_BUNDLE];
  /* Threads the render uses (its `threads`; 0: one): prepare() may use as
   * many for work of its own (ocean_legacy's tables), its results the
   * same bits whatever their number. */
  int threads;
} render_ctx;

/* The wavelength channel c renders at (mono; page 0). */
static inline double rc_channel_wavelength(const render_ctx *rc, int c) {
  return rc->bundle > 1 ? rc->wl[c] : rc->wavelength;
}

/* Pages of three wavelengths a bundle of rc->bundle needs: 1 up to three
 * wavelengths (the colour's channels), else ceil(bundle / 3). */
static inline int rc_pages(const render_ctx *rc) {
  return rc->bundle > 3 ? (rc->bundle + 2) / 3 : 1;
}

/* The context of page p of rc: a bundle of three (or fewer) whose
 * channel c is rc's wavelength 3 p + c, for prepare() to evaluate a page
 * as it evaluates a bundle of three. */
static inline render_ctx rc_page(const render_ctx *rc, int p) {
  render_ctx q = *rc;
  if (rc->bundle <= 3) return q;
  int last = rc->bundle - 1;
  for (int c = 0; c < 3; c++) q.wl[c] = rc->wl[3 * p + c < last ? 3 * p + c : last];
  for (int c = 3; c < RENDER_MAX_BUNDLE; c++) q.wl[c] = q.wl[2];
  q.bundle = 3;
  q.wavelength = q.wl[0];
  return q;
}

/* The page of a bundle the calling thread evaluates at: 0 but while an
 * integrator that carries pages (integrator.pages) asks an object for its
 * value at another page (render.c defines it). */
extern _Thread_local int rsw_page;

struct loader;
struct node;
struct scene;
struct param_visitor;
struct param_table;
typedef struct object object;

/* A plugin: name, class, life cycle, and its class's ops table. */
typedef struct plugin {
  const char *name;
  obj_class cls;
  /* Build from a document node. Reads properties with the ld_* getters
   * (scene/loader.h); any property it does not read is an error raised by
   * the builder. Writes *out only on success. */
  rsw_status (*create)(struct loader *ld, struct node *n, object **out);
  /* Free the object's own memory (not its children: the scene owns every
   * object and frees each once). */
  void (*destroy)(object *o);
  /* Optional: evaluate wavelength-dependent state before a render (e.g. a
   * tabulated spectrum at the context's wavelength). */
  rsw_status (*prepare)(object *o, const render_ctx *rc, rsw_err *err);
  const void *ops; /* class-specific ops table, or NULL */
  /* Optional: report parameters and nested objects (scene/params.h),
   * Mitsuba's traverse(). */
  void (*traverse)(object *o, struct param_visitor *v);
  /* Optional: refresh derived state after an update wrote one of this
   * object's parameters (values were validated before any was written). */
  void (*parameters_changed)(object *o);
  /* Optional: whether what the object renders with depends on the
   * render's wavelength (mono): a tabulated spectrum, a grid with a
   * wavelength axis. A plugin whose prepare() reads rc->wavelength sets
   * it; scene_wavelength_dependent asks every object. */
  bool (*spectral)(const object *o);
  /* Optional, for a plugin with prepare(): whether the object renders a
   * bundle of more than three wavelengths (render_ctx.bundle > 3: its
   * prepare() keeps a value per page and its ops answer for rsw_page).
   * NULL: no, for a plugin with prepare() (what it prepares holds one
   * page); plugins without prepare() read their spectra through textures
   * and can. A medium that says yes answers its ops at rsw_page, its
   * majorant included (volpath samples an exact medium's flight at one
   * page and weights every page by its own transmittance, and tracks the
   * others against the largest page's majorant; a layered_medium keeps
   * its pages' layers in Lp, media/layered.h, which volpath reads
   * directly). scene_page_blocker asks every object. */
  bool (*pages)(const object *o);
} plugin;

/* Every object starts with this header. */
struct object {
  const plugin *plugin;
  const char *id; /* borrowed from the document node */
};

/* Point on a surface, as the integrator sees it. */
typedef struct surface_interaction {
  double t;     /* ray distance */
  vec3 p;       /* world position */
  vec3 ng;      /* geometric normal (unit, world, after flip_normals) */
  frame sh;     /* shading frame (n = shading normal) */
  double uv[2]; /* texture coordinates */
  vec3 wi;      /* local: towards the ray origin */
  const struct shape *shape;
  uint32_t prim;
  double p_error; /* bound on the distance between p and the surface as
                          Embree traces it in float32 (world units; accel.h
                          accel_surface_error): spawned rays start a few times
                          this off the surface (shapes/shape.h spawn_ray) */
} surface_interaction;

/* ---- textures ---------------------------------------------------------- */
typedef struct texture texture;
typedef struct texture_ops {
  color (*eval)(const texture *t, const surface_interaction *si);
  /* Mean value over the texture (used for sampling decisions). */
  color (*mean)(const texture *t);
} texture_ops;
struct texture {
  object base;
  const texture_ops *ops;
};
static inline color tex_eval(const texture *t, const surface_interaction *si) {
  return t->ops->eval(t, si);
}

/* ---- BSDFs --------------------------------------------------------------- */
enum bsdf_flags {
  BSDF_NULL = 0,
  BSDF_DIFFUSE_REFLECTION = 1u << 0,
  BSDF_GLOSSY_REFLECTION = 1u << 1,
  BSDF_DELTA_REFLECTION = 1u << 2,
  BSDF_DIFFUSE_TRANSMISSION = 1u << 3,
  BSDF_GLOSSY_TRANSMISSION = 1u << 4,
  BSDF_DELTA_TRANSMISSION = 1u << 5,
  BSDF_TWO_SIDED = 1u << 6, /* reflects from both sides (twosided) */
  /* `null`: an index-matched boundary that light crosses unchanged
   * (Mitsuba's BSDFFlags::Null); volumetric integrators pass through it,
   * shadow rays included (its sample is a delta transmission). */
  BSDF_INDEX_MATCHED = 1u << 7,
};
#define BSDF_SMOOTH                                                                                          \
  (BSDF_DIFFUSE_REFLECTION | BSDF_GLOSSY_REFLECTION | BSDF_DIFFUSE_TRANSMISSION | BSDF_GLOSSY_TRANSMISSION)
#define BSDF_DELTA (BSDF_DELTA_REFLECTION | BSDF_DELTA_TRANSMISSION)

typedef struct bsdf_sample {
  vec3 wo;               /* local */
  double pdf;            /* solid angle; for delta lobes: discrete prob. */
  double eta;            /* relative IOR of the sampled interaction (1 if
                           reflection) */
  unsigned sampled_type; /* one bsdf_flags bit */
} bsdf_sample;

typedef struct bsdf bsdf;
typedef struct bsdf_ops {
  /* Sample wo given si->wi. u1 picks a lobe, u2 the direction. Returns the
   * weight eval/pdf (delta lobes: the lobe's weight) and fills *bs; a
   * failed sample returns black with bs->pdf = 0. */
  color (*sample)(const bsdf *b, const surface_interaction *si, double u1, vec2 u2, bsdf_sample *bs);
  /* f_r(wi, wo) |cos theta_o| for the smooth lobes; 0 for delta lobes. */
  color (*eval)(const bsdf *b, const surface_interaction *si, vec3 wo);
  /* Solid-angle pdf of sample() producing wo (smooth lobes only). */
  double (*pdf)(const bsdf *b, const surface_interaction *si, vec3 wo);
  /* Optional: sample() for n lanes that share this BSDF, lane i at si[i]
   * with u1[i], u2[i], writing bs[i] and weight[i]; vectorised at the
   * render's ISA (core/isa.h). A lane's result depends on its own inputs
   * only (not on n or its neighbours), so a wave's grouping of lanes does
   * not change a film. It may differ from sample() in the last bits (its
   * single-precision parts, which the plugin names: roughconductor's
   * placement of the sample, rpv's weight); pdf() and eval() stay the
   * densities of both. NULL: the integrator calls sample() per lane. */
  void (*sample_batch)(const bsdf *b, int n, const surface_interaction *const *si, const double *u1,
                       const vec2 *u2, bsdf_sample *bs, color *weight);
  /* Optional: eval() and pdf() for n lanes that share this BSDF (lane i:
   * si[i], local wo[i]), vectorised at the render's ISA; may compute in
   * single precision (the plugin says where), so equal to eval() and pdf()
   * up to rounding (~1e-6 relative), lane by lane independent of n. NULL:
   * eval() and pdf() per lane. */
  void (*eval_pdf_batch)(const bsdf *b, int n, const surface_interaction *const *si, const vec3 *wo, color *f,
                         double *pdf);
  /* Optional: sample_batch and eval_pdf_batch that give sample(), and
   * eval() and pdf(), bit for bit in every lane (double lanes; what the
   * volumetric wave calls, whose films do not move with a batch). NULL:
   * the integrator calls the scalar ops per lane. */
  void (*sample_batch_exact)(const bsdf *b, int n, const surface_interaction *const *si, const double *u1,
                             const vec2 *u2, bsdf_sample *bs, color *weight);
  void (*eval_pdf_batch_exact)(const bsdf *b, int n, const surface_interaction *const *si, const vec3 *wo,
                               color *f, double *pdf);
  /* Optional (polarized variants, docs/polarization.md#the-payload): the
   * polarization factors P[c] = F / F00 per colour channel, F the Mueller
   * matrix of light arriving along -wo and leaving along si->wi (local
   * directions), where `lobe` is 0 for eval()'s smooth lobes (a light
   * sample) and bs->sampled_type after sample() (a delta lobe: that lobe's
   * matrix). The bases: *s_in perpendicular to wo (the incident light),
   * *s_out perpendicular to si->wi, local unit vectors. NULL: the BSDF
   * depolarizes (P = diag(1, 0, 0, 0)). */
  void (*polarization)(const bsdf *b, const surface_interaction *si, vec3 wo, unsigned lobe, mueller P[3],
                       vec3 *s_in, vec3 *s_out);
  /* Optional (a bundle of pages, integrators/pages.h): the delta lobes of
   * kind `lobe` (a sample()'s sampled_type) that send si->wi to wo (a
   * sample()'s direction), at the page rsw_page names: their value,
   * sample()'s weight times the probability sample() draws them with,
   * which goes to *prob (0 and 0 where none leads to wo: a composition's
   * other part refracting elsewhere). A lobe's direction must not depend
   * on the page (an index that does not vary with the wavelength). NULL:
   * a BSDF with delta lobes carries pages only where every page draws
   * them alike (scene_page_blocker). */
  color (*delta_value)(const bsdf *b, const surface_interaction *si, unsigned lobe, vec3 wo, double *prob);
} bsdf_ops;
struct bsdf {
  object base;
  const bsdf_ops *ops;
  unsigned flags; /* union of the lobes' bsdf_flags */
};

/* The fallback of the optional batched ops, in one place: the plugin's
 * batched op where it has one, else its scalar op lane by lane. A plugin
 * whose batched op would only repeat this loop leaves it NULL. */
static inline void bsdf_sample_n(const bsdf *b, int n, const surface_interaction *const *si, const double *u1,
                                 const vec2 *u2, bsdf_sample *bs, color *weight) {
  if (b->ops->sample_batch) {
    b->ops->sample_batch(b, n, si, u1, u2, bs, weight);
    return;
  }
  for (int i = 0; i < n; i++) weight[i] = b->ops->sample(b, si[i], u1[i], u2[i], &bs[i]);
}
static inline void bsdf_eval_pdf_n(const bsdf *b, int n, const surface_interaction *const *si, const vec3 *wo,
                                   color *f, double *pdf) {
  if (b->ops->eval_pdf_batch) {
    b->ops->eval_pdf_batch(b, n, si, wo, f, pdf);
    return;
  }
  for (int i = 0; i < n; i++) {
    f[i] = b->ops->eval(b, si[i], wo[i]);
    pdf[i] = b->ops->pdf(b, si[i], wo[i]);
  }
}

/* ---- emitters ------------------------------------------------------------ */
enum emitter_flags {
  EMITTER_DELTA_DIRECTION = 1u << 0, /* directional */
  EMITTER_INFINITE = 1u << 1,        /* environment (constant, envmap) */
  EMITTER_SURFACE = 1u << 2,         /* area */
  EMITTER_DELTA_POSITION = 1u << 3,  /* point, spot */
};

typedef struct direction_sample {
  vec3 p;      /* sampled point (on the emitter, or far away for infinite
                  and delta-direction emitters) */
  vec3 n;      /* emitter normal at p (surface emitters) */
  vec3 d;      /* unit direction from the reference point towards p */
  double dist; /* distance to p */
  double pdf;  /* solid angle density (1 for delta) */
  bool delta;
} direction_sample;

typedef struct emitter emitter;
typedef struct emitter_ops {
  /* Sample a direction from ref->p towards the emitter. Returns the
   * emitted radiance (irradiance for delta emitters) divided by ds->pdf,
   * not accounting for visibility; black on failure. */
  color (*sample_direction)(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds);
  /* Solid-angle pdf that sample_direction() picks ds->d from ref. */
  double (*pdf_direction)(const emitter *e, const surface_interaction *ref, const direction_sample *ds);
  /* Radiance arriving along a ray that hit the emitter's shape at `hit`
   * (surface emitters) or escaped the scene in world direction `d`
   * (infinite emitters; hit is NULL). d is the ray direction. */
  color (*eval)(const emitter *e, const surface_interaction *hit, vec3 d);
  /* Called once the scene's bounds are known. */
  void (*set_scene)(emitter *e, const struct scene *s);
  /* Optional (infinite emitters): the Q, U, V Stokes components of the
   * radiance arriving along ray direction d (I is what eval returns). */
  void (*eval_polarization)(const emitter *e, vec3 d, double quv[3]);
  /* Optional: sample_direction() for n reference points (ref[i], u[i] ->
   * ds[i], value[i]) in one call (the wave's next-event estimation); each
   * lane bitwise its own sample_direction(). NULL: one call per lane. */
  void (*sample_direction_batch)(const emitter *e, int n, const surface_interaction *const *ref,
                                 const vec2 *u, direction_sample *ds, color *value);
  /* Optional (environment plugins, extplugin/env_plugin.c): answers the
   * emitter replaced by black since its last prepare() at the render's
   * channel `channel` (the film: a bundle's wavelength index, 0 for one
   * wavelength), and the first one's message into msg (len bytes; may be
   * left empty). */
  size_t (*failures)(const emitter *e, int channel, char *msg, size_t len);
} emitter_ops;
struct emitter {
  object base;
  const emitter_ops *ops;
  unsigned flags;
  double sampling_weight;    /* Mitsuba's sampling_weight (default 1) */
  const struct shape *shape; /* surface emitters: the shape it sits on */
};

/* sample_direction_batch where the emitter has it, else sample_direction
 * lane by lane (as bsdf_sample_n). */
static inline void emitter_sample_direction_n(const emitter *e, int n, const surface_interaction *const *ref,
                                              const vec2 *u, direction_sample *ds, color *value) {
  if (e->ops->sample_direction_batch) {
    e->ops->sample_direction_batch(e, n, ref, u, ds, value);
    return;
  }
  for (int i = 0; i < n; i++) value[i] = e->ops->sample_direction(e, ref[i], u[i], &ds[i]);
}

/* ---- films and reconstruction filters ------------------------------------ */
typedef struct rfilter {
  object base;
  double radius;                                     /* pixels */
  double (*eval)(const struct rfilter *f, double x); /* 1-D, separable */
  /* Optional (NULL: eval point by point): a sample's column and row
   * weights in one batch, bit for bit eval's: out[i] =
   * eval(px - ((xlo + i) + 0.5)) for i < nx, out[nx + j] =
   * eval(py - ((ylo + j) + 0.5)) for j < ny. */
  void (*eval_footprint)(const struct rfilter *f, double px, int xlo, int nx, double py, int ylo, int ny,
                         double *out);
} rfilter;

/* PIXFMT_STOKES (mono only): channels S0..S3, the Stokes vector
 * (I, Q, U, V). */
typedef enum pixel_format {
  PIXFMT_RGB,
  PIXFMT_LUMINANCE,
  PIXFMT_STOKES
} pixel_format;
typedef enum component_format {
  COMPFMT_FLOAT32,
  COMPFMT_FLOAT16
} component_format;

/* The renderer's accumulated sums of a film, as its develop op reads
 * them. Per pixel, `stride` doubles: sum(f w L) rgb, sum(f), and for
 * Stokes films sum(f w (Q, U, V)); then, for a film with variance, from
 * `m_off`, per developed channel k the triple (K, sum(x - K),
 * sum((x - K)^2)) of its samples x, K being the pixel's first sample. */
#define FILM_ACC_MOMENT 3
typedef struct film_sums {
  const double *acc; /* width*height*stride */
  int width, height, stride, m_off;
  bool stokes;    /* S0..S3 */
  bool polarized; /* a polarized variant: channels S0.Y..S3.Y */
  bool lum;       /* one luminance channel Y */
  rsw_variant variant;
  uint32_t spp;
  uint64_t seed;
  double wavelength;   /* nm (mono) */
  unsigned quantities; /* RENDER_Q_* planes asked for (render.h) */
  bool variance;       /* the radiance_stderr plane */
  color e_h;           /* horizontal irradiance (brdf / brf) */
} film_sums;

struct film;
struct film_image;
typedef struct film_ops {
  /* From the accumulated sums to the developed image (radiance, then the
   * planes asked for). On failure nothing stays allocated in *out. */
  rsw_status (*develop)(const struct film *f, const film_sums *sums, struct film_image *out, rsw_err *err);
} film_ops;

typedef struct film {
  object base;
  const film_ops *ops;
  int width, height;
  pixel_format pixel_format; /* forced to luminance in mono */
  component_format component_format;
  rfilter *filter;
} film;

/* ---- samplers ------------------------------------------------------------ */
typedef struct sampler sampler;
/* Per-sample state: lives on the stack of the rendering thread. */
typedef struct sampler_state {
  const sampler *s;
  pcg32 rng;
  uint64_t pixel_key; /* hash of (seed, pixel) */
  uint32_t sample_index, spp, dim;
} sampler_state;
typedef struct sampler_ops {
  /* Begin sample `sample_index` of `spp` for pixel `pixel` under `seed`.
   * The stream depends on nothing else (determinism). */
  void (*start)(const sampler *s, sampler_state *st, uint64_t seed, uint64_t pixel, uint32_t sample_index,
                uint32_t spp);
  double (*next_1d)(sampler_state *st);
  vec2 (*next_2d)(sampler_state *st);
  /* spp actually used for a requested count (stratified rounds to a
   * square). */
  uint32_t (*adjust_spp)(const sampler *s, uint32_t spp);
  /* Optional batched forms for a wave (samplers/sampler_batch.h calls
   * them, or loops over the ops above when NULL): start() for samples
   * st[0..n) (pixel[i], sample_index[i]); next_1d() and next_2d() for
   * the lanes st[idx[k]] (idx NULL: st[k]), k < n, into out[k]. Each
   * lane's numbers are exactly those of its own per-lane calls in the
   * same order (determinism: nothing depends on n or the neighbours). */
  void (*start_batch)(const sampler *s, sampler_state *st, int n, uint64_t seed, const uint64_t *pixel,
                      const uint32_t *sample_index, uint32_t spp);
  void (*next_1d_batch)(sampler_state *st, const int *idx, int n, double *out);
  void (*next_2d_batch)(sampler_state *st, const int *idx, int n, vec2 *out);
  /* next_1d() then next_2d() per lane, in one pass (a light pick and its
   * sample, a BSDF lobe and its direction): out1[k], out2[k]. */
  void (*next_1d_2d_batch)(sampler_state *st, const int *idx, int n, double *out1, vec2 *out2);
  /* next_2d() twice per lane, in one pass (a camera sample's film and
   * aperture numbers): out1[k], out2[k]. */
  void (*next_2d_2d_batch)(sampler_state *st, const int *idx, int n, vec2 *out1, vec2 *out2);
  /* start_batch() then next_2d_2d_batch() of st[0..n) (idx NULL), in one
   * pass (a wave's camera samples). */
  void (*start_2d_2d_batch)(const sampler *s, sampler_state *st, int n, uint64_t seed, const uint64_t *pixel,
                            const uint32_t *sample_index, uint32_t spp, vec2 *out1, vec2 *out2);
} sampler_ops;
struct sampler {
  object base;
  const sampler_ops *ops;
  uint32_t sample_count;
  uint64_t seed; /* base seed, added to the render's seed */
  bool jitter;
};

/* ---- sensors ------------------------------------------------------------- */
typedef struct sensor sensor;
typedef struct sensor_ops {
  /* Ray for film sample u in [0,1)^2 and aperture sample a; returns the
   * ray weight (0 for no ray). */
  double (*sample_ray)(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray);
  /* Called once the scene's bounds are known (bounding sphere, default
   * ray_offset); may fail (e.g. a target shape without area). */
  rsw_status (*set_scene)(sensor *s, const struct scene *sc, rsw_err *err);
  /* Optional (distant family): each pixel's viewing zenith and azimuth in
   * degrees, zen_az[2 (iy W + ix)] and [2 (iy W + ix) + 1], azimuth in
   * [0, 360) in Eradiate's east-right convention (atan2(y, x)). */
  void (*pixel_angles)(const sensor *s, int W, int H, double *zen_az);
  /* Optional, with pixel_angles: each pixel centre's exitant direction
   * (towards the sensor) as a unit world vector, xyz[3 (iy W + ix) + k]. */
  void (*pixel_directions)(const sensor *s, int W, int H, double *xyz);
  /* Optional: sample_ray() for n samples at once (film_u[i],
   * aperture_u[i] -> rays[i], weights w[i]), vectorised at the render's
   * ISA (core/isa.h); each ray depends on its own sample only. NULL: the
   * renderer calls sample_ray() per sample. */
  void (*sample_ray_batch)(const sensor *s, int n, const vec2 *film_u, const vec2 *aperture_u, ray3 *rays,
                           double *w);
} sensor_ops;
struct sensor {
  object base;
  const sensor_ops *ops;
  film *film;
  sampler *sampler;
  xform to_world;
  struct medium *medium; /* the medium the sensor sits in (Mitsuba's `medium`), or NULL */
  /* Distant family (pixel_angles): the vertical its films' Stokes bases
   * refer to is to_world's +z (a hemisphere's pole: hdistant, distantflux)
   * rather than world +z (docs/polarization.md#stokes-conventions). */
  bool stokes_pole;
};

/* ---- volumes ------------------------------------------------------------- */
/* A field over a box (Mitsuba's Volume: constvolume, gridvolume). The box
 * is the unit cube [0,1]^3 under to_world; cell (ix, iy, iz) of an
 * res[0] x res[1] x res[2] grid holds `channels` values at
 * data[((iz res[1] + iy) res[0] + ix) channels + c] (x fastest: Mitsuba's
 * .vol order). After prepare() the grid is what a render sees (in mono a
 * tabulated spectrum per cell is evaluated at the context's wavelength). */
typedef struct volume volume;
/* volume.wrap: a grid's wrap_mode (clamp for every other volume). */
enum {
  VOLUME_WRAP_CLAMP,
  VOLUME_WRAP_REPEAT,
  VOLUME_WRAP_MIRROR
};
typedef struct volume_ops {
  /* Value at world point p (mono: the value in every channel of the color;
   * one-channel grids in rgb: likewise). Outside the box: the plugin's
   * wrap mode (Mitsuba's default clamps to the nearest cell). */
  color (*eval)(const volume *v, vec3 p);
  /* Smallest and largest value the volume holds in any cell and channel
   * (for tabulated spectra per cell: over every sample of the tables),
   * whatever the wavelength: ld_volume checks it against its slot's range. */
  void (*value_range)(const volume *v, double *lo, double *hi);
  /* Optional (a bundle of pages, render_ctx.bundle > 3): the values at
   * page p of the bundle prepare() was given (laid out as data; eval
   * answers at the page rsw_page names). NULL, or data for p = 0: the
   * volume's values are data at every page. volume_page_data. */
  const double *(*page_data)(const volume *v, int p);
} volume_ops;
struct volume {
  object base;
  const volume_ops *ops;
  xform to_world;          /* unit cube -> world */
  vec3 bbox_min, bbox_max; /* world bounds of the box */
  uint32_t res[3];         /* 1 x 1 x 1 for constvolume */
  uint32_t channels;       /* 1 or 3 */
  int wrap;                /* VOLUME_WRAP_*: how eval reaches cells past the grid's edges */
  bool trilinear;          /* eval interpolates between cell centres (else: the nearest cell) */
  /* data is a grid of res cells over the box (gridvolume, constvolume);
   * false (sphericalcoordsvolume): only eval, max and value_range mean
   * anything, and inner is the volume it reads. */
  bool box_grid;
  struct volume *inner;
  const double *data; /* res[0] res[1] res[2] channels values (owned by the plugin) */
  double max;         /* largest value over cells and channels (majorants) */
  /* Values the volume may take: the intersection of the ranges of the
   * slots that hold it (ld_volume), checked again on every update of its
   * parameters. [-inf, inf] when no slot constrains it. */
  double lo, hi;
  /* Bumped whenever data or max change (a parameter update, prepare() at
   * another wavelength), so that a medium can keep what it derives from
   * the grid (cumulative optical thickness, majorants) until it does. */
  uint64_t revision;
};

/* ---- phase functions and media ------------------------------------------- */
struct medium;

/* A point in a medium, as the volumetric integrators see it (Mitsuba's
 * MediumInteraction). */
typedef struct medium_interaction {
  double t;    /* distance along the ray; INFINITY: no interaction */
  double mint; /* where the sampled free-flight segment began (ray distance) */
  vec3 p;      /* world position */
  vec3 wi;     /* unit world direction towards where the path came from (-ray.d) */
  const struct medium *medium;
  color sigma_t, sigma_s, sigma_n; /* at p (after the medium's scale); sigma_n = majorant - sigma_t */
  color majorant;                  /* Mitsuba's combined_extinction used for the free flight */
  /* What the phase function `bound` looked up at p once (phase_bind,
   * phase/phase.h: blendphase's weight), so that its eval_pdf and sample
   * at this point need not look it up again; NULL: nothing bound. */
  const struct phase *bound;
  double bound_w;
} medium_interaction;

/* Phase functions use Mitsuba's convention: wi (mi->wi) points back
 * towards where the path came from, wo where it goes, both world and unit,
 * so forward scattering is wo = -wi and hg's value is
 * (1 - g^2) / (4 pi (1 + g^2 + 2 g dot(wi, wo))^1.5). */
typedef struct phase phase;
typedef struct phase_ops {
  /* Sample wo for the scattering at mi: u1 picks a component (blendphase),
   * u2 the direction. Returns the weight value / pdf and writes *pdf (solid
   * angle); a failed sample returns 0 with *pdf = 0. */
  double (*sample)(const phase *ph, const medium_interaction *mi, double u1, vec2 u2, vec3 *wo, double *pdf);
  /* The value p(wi, wo) [sr^-1] and, in *pdf, the density sample() picks
   * wo with. */
  double (*eval_pdf)(const phase *ph, const medium_interaction *mi, vec3 wo, double *pdf);
  /* Optional: look up what depends on mi->p alone, once, into
   * mi->bound_w, and set mi->bound = ph (phase_bind calls it). */
  void (*bind)(const phase *ph, medium_interaction *mi);
  /* Optional, for a phase whose `chromatic` is set: the value p(wi, wo)
   * per colour channel (a spectral bundle's wavelengths; sample() and
   * eval_pdf() give channel 0's value and the density). */
  color (*eval_channels)(const phase *ph, const medium_interaction *mi, vec3 wo);
  /* Optional, beside eval_channels: out[p] = eval_channels at page p (as
   * rsw_page = p would give it, bit for bit) for p0 <= p < pages, what
   * does not depend on the wavelength worked out once
   * (integrators/pages.h phase_pages makes the per-page calls without
   * it). */
  void (*eval_pages)(const phase *ph, const medium_interaction *mi, vec3 wo, int p0, int pages, color *out);
  /* Optional (polarized variants): the polarization factors P[c] = F / F11
   * per colour channel of the scattering from mi->wi into wo, in the bases
   * whose x is the scattering plane's normal. NULL: a depolarizer. */
  void (*polarization)(const phase *ph, const medium_interaction *mi, vec3 wo, mueller P[3]);
  /* Optional: n samples at once, lane i that of sample(ph, &mi[i], u1[i],
   * u2[i], &wo[i], &pdf[i]) returning weight[i], bit for bit
   * (phase/phase.h phase_sample_batch makes those calls without it). */
  void (*sample_batch)(const phase *ph, int n, const medium_interaction *mi, const double *u1, const vec2 *u2,
                       vec3 *wo, double *pdf, double *weight);
  /* Optional: n evaluations at once, lane i that of eval_pdf(ph, &mi[i],
   * wo[i], &pdf[i]) returning val[i], bit for bit (phase_eval_pdf_batch). */
  void (*eval_pdf_batch)(const phase *ph, int n, const medium_interaction *mi, const vec3 *wo, double *val,
                         double *pdf);
} phase_ops;
struct phase {
  object base;
  const phase_ops *ops;
  /* Its value differs between colour channels (set by prepare for a
   * spectral bundle): the integrator weights each channel with
   * eval_channels (docs/experiments.md#spectral-bundles). */
  bool chromatic;
};

/* A participating medium (Mitsuba's Medium: homogeneous, heterogeneous;
 * Eradiate's piecewise). Coefficients in inverse scene length units. */
typedef struct medium medium;
struct track_walk;
typedef struct medium_ops {
  /* The part [*mint, *maxt] of ray r (within [0, r->tmax]) where the
   * medium can interact: its volumes' box for grid media, the whole ray
   * for homogeneous. False when empty. */
  bool (*intersect_aabb)(const medium *m, const ray3 *r, double *mint, double *maxt);
  /* The majorant (combined extinction) for a free flight starting at mi
   * (mi->p, mi->wi set), Mitsuba's get_majorant. */
  color (*majorant)(const medium *m, const medium_interaction *mi);
  /* sigma_t, sigma_s and sigma_n (majorant - sigma_t) at mi->p, with
   * mi->majorant set; Mitsuba's get_scattering_coefficients. */
  void (*coefficients)(const medium *m, medium_interaction *mi);
  /* Optional, analytic media (piecewise): a real collision sampled along r
   * over [mint, maxt] (within intersect_aabb's interval: callers clip
   * first; r->d unit) by inverting the optical thickness in `channel` with
   * u (Eradiate's sample_interaction_real). Fills mi (t = INFINITY when
   * the flight passes maxt) and returns the transmittance to mi->t (or to
   * maxt) in *tr and its pdf in *pdf (pdf of t: sigma_t tr; of passing:
   * tr), per channel. */
  void (*sample_real)(const medium *m, const ray3 *r, double mint, double maxt, double u, int channel,
                      medium_interaction *mi, color *tr, color *pdf);
  /* Optional, analytic media: the exact transmittance along r over
   * [mint, maxt] (clipped by intersect_aabb first; r->d unit), Eradiate's
   * eval_transmittance_pdf_real. heterogeneous: exact only for uniform
   * grids (is_homogeneous). */
  color (*transmittance)(const medium *m, const ray3 *r, double mint, double maxt);
  /* Optional, tracked media with local majorants (heterogeneous with an
   * extremum_grid): the majorants along r over [mint, maxt] as a walk
   * over their pieces (media/majorant_grid.h), with the cells' minorants
   * as the pieces' controls when rrt. False: none, the majorant op's
   * serves the whole segment. */
  bool (*majorant_walk)(const medium *m, const ray3 *r, double mint, double maxt, bool rrt,
                        struct track_walk *w);
  /* Optional, tracked media: a lower bound of sigma_t over the medium, in
   * every channel and page (the control of residual ratio tracking
   * without local minorants); NULL: 0. */
  double (*minorant)(const medium *m);
} medium_ops;
struct medium {
  object base;
  const medium_ops *ops;
  phase *phase;                 /* nested phase (default isotropic) */
  double scale;                 /* multiplies sigma_t (Mitsuba's `scale`, default 1) */
  bool is_homogeneous;          /* coefficients do not depend on position */
  bool has_spectral_extinction; /* sigma_t differs between channels */
  bool sample_emitters;         /* NEE from scattering events (Mitsuba's sample_emitters, default true) */
  bool use_rrt; /* shadow rays by residual ratio tracking (Eradiate's use_rrt, default true) */
  /* sigma_s = 0 wherever sigma_t > 0 (albedo 0; set by prepare): the
   * volumetric integrators then weight a flight by its transmittance
   * instead of sampling collisions (exact for analytic media). */
  bool absorbing_only;
  /* A bundle of pages where has_spectral_extinction (set by prepare,
   * medium_extremes): the channels (3 p + c) of largest and smallest
   * extinction over every page (a layered medium's whole column, a
   * homogeneous one's sigma_t) and the ratio of the two (volpath's
   * flight_pages draws its channel from a mixture that favours both when
   * it is large). */
  int thick_channel, thin_channel;
  double extinction_spread;
};

/* Set m's thick_channel, thin_channel and extinction_spread from ext[k],
 * the extinction of channel k < n (infinite spread when the thinnest is
 * 0 and the thickest not). */
static inline void medium_extremes(medium *m, const double *ext, int n) {
  int thick = 0, thin = 0;
  for (int k = 1; k < n; k++) {
    if (ext[k] > ext[thick]) thick = k;
    if (ext[k] < ext[thin]) thin = k;
  }
  m->thick_channel = thick, m->thin_channel = thin;
  m->extinction_spread = ext[thin] > 0 ? ext[thick] / ext[thin] : ext[thick] > 0 ? INFINITY : 1.0;
}

/* ---- integrators --------------------------------------------------------- */
typedef struct render_stats {
  uint64_t rays;        /* intersection queries */
  uint64_t shadow_rays; /* occlusion queries */
  uint64_t unresolved;  /* periodic rays that neither hit nor left the slab (scene/periodic.h) */
  double trace_s;       /* thread time spent in ray queries (batched integrators measure it; 0 otherwise) */
  uint64_t camera_rays; /* paths started (sensor rays with a non-zero weight), counted in rays too */
} render_stats;

/* Whether the render this thread works on must stop: cancelled, or past
 * its deadline (render.c; false outside a render). The batched
 * integrators ask it every WAVE_STOP_EVERY bounces of a wave, so that a
 * wave of very long paths (an unbounded lossless medium: 65,536 bounces
 * a path) holds a cancel or a deadline back by a few bounces, not by the
 * whole wave; a wave cut short is discarded with its render. */
bool render_stop_requested(void);
#define WAVE_STOP_EVERY 16

typedef struct integrator integrator;
typedef struct integrator_ops {
  /* Radiance arriving at ray.o along -ray.d. When quv is not NULL (Stokes
   * films), the Q, U, V of that radiance are added to quv[0..2] (rgb
   * polarized: quv[3 c .. 3 c + 2] per colour channel c, scene_quv_stride
   * doubles in all). */
  color (*Li)(const integrator *it, const struct scene *sc, sampler_state *st, ray3 ray, render_stats *stats,
              double *quv);
  /* Optional: Li for n camera rays at once (a wave: the paths advance
   * bounce by bounce together, their rays traced as packets). Path i uses
   * st[i] alone, in the same order of draws as Li, so its result does not
   * depend on the batch it is in (up to Embree's packet rounding, accel.h).
   * L[i] (and quv[k i .. k i + k - 1], k = scene_quv_stride, zeroed
   * first, when quv is not NULL) are written. False: out of memory (nothing is valid). */
  bool (*Li_batch)(const integrator *it, const struct scene *sc, sampler_state *st, const ray3 *rays, int n,
                   render_stats *stats, color *L, double *quv);
} integrator_ops;
struct integrator {
  object base;
  const integrator_ops *ops;
  int max_depth; /* -1 = infinite */
  int rr_depth;
  bool hide_emitters;
  /* Carries a bundle of more than three wavelengths, page by page
   * (render_ctx.bundle > 3; path, direct, volpath, piecewise_volpath): Li_batch (or Li) then writes
   * pages 1.. of each path's radiance after page 0's, as quv (scene_extra_stride). */
  bool pages;
  /* Samples per Li_batch call it prefers (render.c's wave; 0: the default
   * there; at most render.c's RENDER_WAVE_MAX; a scene of many primitives
   * gets at most the default, render.c job_wave). */
  int wave;
};

/* ---- shapes -------------------------------------------------------------- */
/* What a kind of geometry does (bounds, intersection, surface data,
 * position sampling, area): shapes/shape.h. */
struct shape_ops;

/* Triangle mesh in object space (before to_world). */
typedef struct mesh {
  uint32_t n_verts, n_faces;
  float *pos;      /* 3 per vertex (owned) */
  float *nrm;      /* 3 per vertex or NULL (owned) */
  float *uv;       /* 2 per vertex or NULL (owned) */
  uint32_t *faces; /* 3 per face (owned) */
} mesh;

typedef struct shape {
  object base;
  const struct shape_ops *ops; /* its geometry's ops (shapes/shape.h) */
  xform to_world;              /* object -> world; the Embree instance transform */
  bool flip_normals;
  bool face_normals;                 /* ignore vertex normals */
  bool mesh_params;                  /* exposes its buffers (cube, obj, ply; not rectangle) */
  double silhouette_sampling_weight; /* Mitsuba's; no effect here */
  bsdf *bsdf;
  emitter *emitter; /* area light, or NULL */
  /* Media on either side of the surface (Mitsuba's interior/exterior:
   * interior on the side the normal points away from), or NULL. */
  struct medium *interior, *exterior;
  mesh mesh;    /* triangle meshes (ops == &shape_ops_mesh) */
  bool sampled; /* positions are sampled on it (a sensor's target) */
  /* Derived by shape_finalize(). A mesh's area and area cdf are computed
   * only when something samples it (an area emitter, a sensor target): an
   * O(faces) pass that plain geometry does not need. */
  double area;        /* world-space surface area (0 for unsampled meshes) */
  double *tri_cdf;    /* meshes: cumulative world areas, n_faces entries */
  uint32_t tri_cdf_n; /* entries allocated in tri_cdf */
  /* A cdf computed ahead by a parameter update's validation, installed by
   * parameters_changed instead of recomputing (scene/update.c). */
  double *tri_cdf_next;
  uint32_t tri_cdf_next_n;
  double area_next;
  bool cdf_staged;
  unsigned index; /* position in scene->shapes */
  /* Meshes of at most SHAPE_FACE_CACHE_MAX faces (shapes/shape.h): per
   * face, the world geometric normal and world dp/du under to_world, and
   * (face_cache_frames) the hit's shading frame, SHAPE_FACE_DOUBLES
   * doubles, as a hit's surface data computes them (the same bits);
   * refreshed by shape_finalize and parameters_changed. NULL otherwise. */
  double *face_cache;
  uint32_t face_cache_n;
  bool face_cache_frames;
} shape;

/* ---- the scene ----------------------------------------------------------- */
struct accel;

/* A periodic lateral boundary (scene/periodic.h): rays leaving the box
 * [min[0], max[0]] x [min[1], max[1]] through a side re-enter through the
 * opposite side. zmin/zmax: the geometry's vertical extent (set with the
 * bounds), beyond which a ray can hit nothing more. */
typedef struct periodic_bounds {
  bool on;
  double min[2], max[2];
  double zmin, zmax;
} periodic_bounds;

enum {
  SCENE_NULL_BOXES_MAX = 4
};

typedef struct scene {
  object base;
  rsw_variant variant;
  bool polarized;   /* mono_polarized, rgb_polarized: paths carry Mueller matrices */
  int pages;        /* pages of the bundle the last scene_prepare was for (rc_pages; 0 or 1: one) */
  object **objects; /* every object, for prepare/destroy (owned) */
  size_t n_objects, cap_objects;
  shape **shapes;
  size_t n_shapes;
  emitter **emitters; /* all emitters, area lights included */
  size_t n_emitters;
  double *emitter_cdf; /* by sampling_weight */
  double emitter_weight_sum;
  emitter *environment; /* at most one infinite emitter */
  sensor **sensors;
  size_t n_sensors;
  integrator *integrator;
  struct accel *accel;
  vec3 bbox_min, bbox_max;
  vec3 bsphere_center;
  double bsphere_radius;      /* inflated as Mitsuba: max(eps, r (1 + eps)) */
  struct node *doc;           /* the document the scene was built from (owned) */
  struct param_table *params; /* the parameter table (owned) */
  periodic_bounds periodic;   /* the `periodic` object, if any */
  double *periodic_z;         /* periodic scenes: each shape's world z-range, lo and hi
                                 (2 per shape; scene/periodic.c) */
  /* Null-BSDF boxes the volumetric integrators cross analytically
   * (media/media.h media_refresh_null_boxes; refreshed with the bounds). */
  struct {
    bool on; /* every masked box is a box now: queries may leave them out */
    unsigned n;
    struct scene_null_box {
      const struct shape *sh;
      double lo[3], hi[3];           /* object-space box */
      bool aligned;                  /* to_world scales and translates only: */
      double wlo[3], whi[3];         /* then the world box */
      const struct medium *in, *out; /* media inside / outside (Mitsuba's interior/exterior) */
    } box[SCENE_NULL_BOXES_MAX];
    vec3 rest_min, rest_max; /* bounds of everything else (empty: min > max) */
  } null_boxes;
} scene;

/* Doubles per path in an integrator's quv (integrator_ops.Li): Q, U, V of
 * each colour channel in rgb_polarized, else of one. */
#define SCENE_QUV_MAX 9
static inline int scene_quv_stride(const scene *sc) {
  return sc->polarized && sc->variant == VARIANT_RGB ? 9 : 3;
}

/* Doubles per path that an integrator's Li_batch writes to quv: the Stokes
 * Q, U, V (scene_quv_stride) or, for a bundle of pages, the colours of
 * pages 1.. (3 per page). */
#define SCENE_EXTRA_MAX (3 * (RENDER_MAX_PAGES - 1))
static inline int scene_extra_stride(const scene *sc) {
  return sc->pages > 1 ? 3 * (sc->pages - 1) : scene_quv_stride(sc);
}

#endif
