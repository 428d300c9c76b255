/* Eradiate's land and ocean surface BSDFs added with issue 25 (rtls,
 * maignan, ocean_legacy, mqdiffuse, selectbsdf): structs, direct
 * constructors and the closed forms the tests compare against.
 * Ownership as in bsdfs_internal.h: constructors return an owned bsdf and
 * borrow their textures. docs/kernel-conventions.md has each model. */
#ifndef RSW_BSDFS_EO_SURFACES_H
#define RSW_BSDFS_EO_SURFACES_H

#include "bsdfs_internal.h"

/* The one-sided cosine-hemisphere lobe these models sample (rpv and hapke
 * repeat it): fills bs and returns true when wi and the drawn wo both lie
 * above the surface; else bs is a failed sample. */
static inline bool eo_cosine_sample(const surface_interaction *si, vec2 u2, bsdf_sample *bs) {
  if (!(si->wi.z > 0.0)) return bsdf_fail(bs), false;
  bs->wo = warp_square_to_cosine_hemisphere(u2);
  bs->pdf = warp_square_to_cosine_hemisphere_pdf(bs->wo);
  bs->eta = 1.0;
  bs->sampled_type = BSDF_GLOSSY_REFLECTION;
  if (!(bs->pdf > 0.0) || !(bs->wo.z > 0.0)) return bsdf_fail(bs), false;
  return true;
}
/* Its density; 0 unless both directions lie above the surface. */
static inline double eo_cosine_pdf(const surface_interaction *si, vec3 wo) {
  if (!(si->wi.z > 0.0) || !(wo.z > 0.0)) return 0.0;
  return warp_square_to_cosine_hemisphere_pdf(wo);
}

/* ---- rtls: Ross-Thick Li-Sparse (MODIS BRDF kernels) --------------------- */
extern const plugin plugin_rtls;

typedef struct rtls_bsdf {
  bsdf base;
  texture *f_iso, *f_vol, *f_geo;
  double h, r, b; /* crown height / centre ratio h/b, shape ratio b/r */
} rtls_bsdf;

bsdf *rtls_new(texture *f_iso, texture *f_vol, texture *f_geo, double h, double r, double b);
/* The Ross-Thick and Li-Sparse-Reciprocal kernels at (wi, wo), both in the
 * upper hemisphere. */
void rtls_kernels(vec3 wi, vec3 wo, double h, double r, double b, double *k_vol, double *k_geo);

/* ---- maignan: Maignan et al. (2009) bare soil / vegetation ---------------- */
extern const plugin plugin_maignan;

typedef struct maignan_bsdf {
  bsdf base;
  texture *C, *ndvi, *refr_re, *refr_im, *ext_ior;
} maignan_bsdf;

bsdf *maignan_new(texture *C, texture *ndvi, texture *refr_re, texture *refr_im, texture *ext_ior);
/* eval(wi, wo) of one channel (Eradiate's value, which is f_r cos(theta_o)). */
double maignan_value(double C, double ndvi, double refr_re, double refr_im, double ext_ior, vec3 wi, vec3 wo);

/* ---- mqdiffuse: measured quasi-diffuse reflectance on a grid ------------- */
extern const plugin plugin_mqdiffuse;
/* The grid's value (no cosine) at (wi, wo), both above the surface. */
double mqdiffuse_grid_value(const volume *grid, vec3 wi, vec3 wo);

/* ---- selectbsdf: nested BSDFs picked by an index texture ---------------- */
extern const plugin plugin_selectbsdf;

/* ---- ocean_legacy: the 6S ocean surface (Eradiate) ------------------------ */
extern const plugin plugin_ocean_legacy;

enum {
  OCEAN_T_RES = 64 /* transmittance tables: zenith x azimuth */
};

/* What one wavelength makes of the water (ocean_update's derived
 * values at that wavelength, and its transmittance tables; NULL: not
 * built, underlight 0 and t_d = 1). */
typedef struct ocean_wl {
  double wavelength, n_re, n_im, r_omega, whitecap;
  const float *t_down, *t_up;
} ocean_wl;

/* Transmittance tables for one (n_re, n_im, wind_speed): a cache entry of
 * an ocean that follows the render's wavelength. */
typedef struct ocean_table {
  double key[3];
  unsigned stamp; /* the prepare() that last used it */
  float t_down[OCEAN_T_RES * OCEAN_T_RES], t_up[OCEAN_T_RES * OCEAN_T_RES];
} ocean_table;

enum {
  OCEAN_CACHE = 48 /* tables an ocean that follows the render keeps (32 KiB each) */
};

typedef struct ocean_bsdf {
  bsdf base;
  /* "wavelength": "render": each colour channel of each page at its own
   * render wavelength (prepare() fills pg and chromatic); else the fixed
   * `wavelength` below for every channel */
  bool follow;
  ocean_wl pg[RENDER_MAX_PAGES][3];
  bool chromatic[RENDER_MAX_PAGES]; /* page p's channels differ */
  ocean_table *cache;               /* follow: OCEAN_CACHE entries, allocated by the first prepare() */
  unsigned stamp, next;
  unsigned long gen; /* a number no other state of any ocean had (ocean_update): keys eval's reuse */
  int threads;       /* threads a table build may use (prepare(): the render's; 0 or 1: the caller's alone) */
  /* parameters */
  double wavelength;     /* nm */
  double wind_speed;     /* m/s at 10 m */
  double wind_direction; /* degrees, North Left (6SV): where the wind blows from */
  double chlorinity;     /* g/kg */
  double pigmentation;   /* mg/m^3 */
  double coverage;       /* whitecap fraction, derived (read-only) */
  bool shadowing;
  int component; /* 0 all, 1 whitecaps, 2 glint, 3 underlight, 4 whitecaps + underlight */
  /* derived (ocean_update) */
  double phi_w; /* wind azimuth in the local frame, radians (East Right) */
  double n_re, n_im, sigma_u, sigma_c, r_omega, whitecap;
  double t_key[3]; /* n_re, n_im, wind_speed the tables were made for */
  float t_down[OCEAN_T_RES * OCEAN_T_RES], t_up[OCEAN_T_RES * OCEAN_T_RES];
} ocean_bsdf;

/* Parameters as Eradiate names them; NULL when out of memory. */
bsdf *ocean_legacy_new(double wavelength, double wind_speed, double wind_direction, double chlorinity,
                       double pigmentation, bool shadowing, int component);
/* Recompute the derived state after a parameter changed (the
 * transmittance tables are then stale). */
void ocean_update(ocean_bsdf *o);
/* Build the transmittance tables if stale (the plugin's prepare() does it
 * before each render; about 0.15 s of CPU a pair, on o->threads threads). Until then underlight is 0 and the
 * sampling takes t_d = 1: direct users of ocean_legacy_new call it. */
void ocean_tables(ocean_bsdf *o);
bool ocean_tables_ready(const ocean_bsdf *o);
/* The sun-glint term pi D G F / (4 cos_i cos_o) (the BRF of the glint,
 * before the (1 - coverage) factor), wi and wo in the local frame. */
double ocean_glint(const ocean_bsdf *o, vec3 wi, vec3 wo);
/* The transmittance the tables hold (downwelling, or upwelling when up)
 * at incidence theta with the wind at azimuth phi, by nq x nq
 * Gauss-Legendre points (the tables use 32; Eradiate 64). */
double ocean_transmittance(const ocean_bsdf *o, double theta, double phi, bool up, int nq);
/* Fresnel reflectance as 6S computes it (n_re + i n_im, incidence cosine
 * and sine). */
double ocean_fresnel_6s(double n_re, double n_im, double cos_chi, double sin_chi);
/* The Gram-Charlier factor of Cox and Munk's slope distribution at the
 * microfacet normal m (local frame). */
double ocean_gram_charlier(const ocean_bsdf *o, vec3 m);

#endif
