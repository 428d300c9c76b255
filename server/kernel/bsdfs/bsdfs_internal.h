/* BSDF plugin structs and direct constructors, shared by the plugin files
 * and by tests that build BSDFs without the scene loader.
 *
 * Ownership: the constructors return an owned bsdf (free it with
 * b->base.plugin->destroy(&b->base)); they borrow the textures and nested
 * BSDFs they are given (in a scene, the scene owns those). They return
 * NULL when out of memory. */
#ifndef RSW_BSDFS_INTERNAL_H
#define RSW_BSDFS_INTERNAL_H

#include "../kernel.h"
#include "ior_data.h"
#include "microfacet.h"

extern const plugin plugin_diffuse;
extern const plugin plugin_conductor;
extern const plugin plugin_roughconductor;
extern const plugin plugin_dielectric;
extern const plugin plugin_twosided;
extern const plugin plugin_plastic;
extern const plugin plugin_roughplastic;
extern const plugin plugin_null;

/* ---- diffuse ------------------------------------------------------------ */
typedef struct diffuse_bsdf {
  bsdf base;
  texture *reflectance;
} diffuse_bsdf;

bsdf *diffuse_new(texture *reflectance);

/* ---- conductors (smooth and rough share the complex index) -------------- */
typedef struct conductor_ior {
  texture *eta, *k;              /* used when material is NULL */
  const ior_conductor *material; /* preset, or NULL ("none") */
  color mat_eta, mat_k;          /* the preset at the render's wavelength
                                     (set at creation for 550 nm / rgb,
                                     refreshed by prepare()) */
  /* A bundle of pages (render_ctx.bundle > 3): the preset at pages 1..
   * (page 0's is mat_eta, mat_k), what eval answers while rsw_page names
   * one. */
  color page_eta[RENDER_MAX_PAGES - 1], page_k[RENDER_MAX_PAGES - 1];
} conductor_ior;

/* eta and k at si. */
void conductor_ior_eval(const conductor_ior *c, const surface_interaction *si, color *eta, color *k);
/* Reads `material` / `eta` / `k` of a conductor node (Mitsuba's rule: a
 * material other than "none" together with eta is an error; with a
 * material, eta/k are not read, so a stray k is an unused property). */
rsw_status conductor_ior_load(struct loader *ld, struct node *n, conductor_ior *out);
/* Reports eta/k (when not a preset) to a parameter traversal. */
struct param_visitor;
void conductor_ior_traverse(conductor_ior *c, struct param_visitor *v);
/* Sets the preset's cached values for rc (no-op without a preset). */
rsw_status conductor_ior_prepare(conductor_ior *c, const render_ctx *rc, rsw_err *err, const char *where);

typedef struct conductor_bsdf {
  bsdf base;
  conductor_ior ior;
  texture *specular_reflectance; /* NULL = 1 */
} conductor_bsdf;

/* eta/k textures (material NULL) or a preset (eta/k NULL; its values are
 * evaluated for rc, which may be NULL for mono 550 nm). NULL also when
 * rc's wavelength lies outside the preset's table. */
bsdf *conductor_new(texture *eta, texture *k, const ior_conductor *material, texture *specular_reflectance,
                    const render_ctx *rc);

typedef struct roughconductor_bsdf {
  bsdf base;
  conductor_ior ior;
  texture *specular_reflectance; /* NULL = 1 */
  mf_type type;
  texture *alpha_u, *alpha_v; /* the same texture when isotropic */
  bool sample_visible;
} roughconductor_bsdf;

bsdf *roughconductor_new(mf_type type, texture *alpha_u, texture *alpha_v, bool sample_visible, texture *eta,
                         texture *k, const ior_conductor *material, texture *specular_reflectance,
                         const render_ctx *rc);

/* ---- dielectric --------------------------------------------------------- */
typedef struct dielectric_bsdf {
  bsdf base;
  double eta;                      /* int_ior / ext_ior */
  texture *specular_reflectance;   /* NULL = 1 */
  texture *specular_transmittance; /* NULL = 1 */
} dielectric_bsdf;

bsdf *dielectric_new(double int_ior, double ext_ior, texture *specular_reflectance,
                     texture *specular_transmittance);

/* ---- twosided ----------------------------------------------------------- */
typedef struct twosided_bsdf {
  bsdf base;
  bsdf *brdf[2]; /* front, back (the same object when only one is given) */
} twosided_bsdf;

/* back may be NULL (= front). Neither may have transmission lobes (the
 * plugin's create() checks; this constructor trusts its caller). */
bsdf *twosided_new(bsdf *front, bsdf *back);

/* ---- Earth-observation surfaces (Eradiate) ------------------------------ */
extern const plugin plugin_rpv;
extern const plugin plugin_bilambertian;
extern const plugin plugin_hapke;

typedef struct rpv_bsdf {
  bsdf base;
  texture *rho_0, *k, *g;
  texture *rho_c; /* == rho_0 unless given */
} rpv_bsdf;

/* rho_c NULL: the same texture as rho_0. */
bsdf *rpv_new(texture *rho_0, texture *k, texture *g, texture *rho_c);
/* RPV f_r(wi, wo) of one channel (no cosine factor), for tests. */
double rpv_fr(double rho_0, double k, double g, double rho_c, vec3 wi, vec3 wo);

typedef struct bilambertian_bsdf {
  bsdf base;
  texture *reflectance, *transmittance;
} bilambertian_bsdf;

bsdf *bilambertian_new(texture *reflectance, texture *transmittance);

typedef struct hapke_bsdf {
  bsdf base;
  texture *w, *b, *c, *theta, *B_0, *h; /* theta in degrees */
} hapke_bsdf;

bsdf *hapke_new(texture *w, texture *b, texture *c, texture *theta, texture *B_0, texture *h);
/* Hapke f_r(wi, wo) of one channel (no cosine factor; theta in degrees). */
double hapke_fr(double w, double b, double c, double theta_deg, double B_0, double h, vec3 wi, vec3 wo);

/* Range check of a constant (uniform) texture at load, per channel;
 * varying textures are not checked. Open or closed bounds. */
struct loader;
struct node;
rsw_status bsdf_check_const_range(struct loader *ld, struct node *n, const char *name, const texture *t,
                                  double lo, bool lo_open, double hi, bool hi_open);

/* An index of refraction given as a number > 0 or as a material name
 * (Mitsuba's lookup_ior(), ior_data.h); absent: the named default `def`. */
rsw_status bsdf_read_ior(struct loader *ld, struct node *n, const char *name, const char *def, double *out);

/* Helpers shared by the plugin files. */
static inline color bsdf_factor(const texture *t, const surface_interaction *si) {
  return t ? tex_eval(t, si) : col1(1.0);
}
static inline color bsdf_fail(bsdf_sample *bs) {
  bs->wo = v3(0.0, 0.0, 0.0);
  bs->pdf = 0.0;
  bs->eta = 1.0;
  bs->sampled_type = 0;
  return col1(0.0);
}

/* Whether delta lobes' directions a and b (unit) are one: the same
 * computation gives the same bits; 1e-12 allows another order of the
 * same operations (a composition's pass-through against an index-matched
 * refraction). */
static inline bool delta_same_direction(vec3 a, vec3 b) {
  return fabs(a.x - b.x) <= 1e-12 && fabs(a.y - b.y) <= 1e-12 && fabs(a.z - b.z) <= 1e-12;
}

#endif
