/* A BSDF seen by a bundle of pages (integrators/pages.h): one direction
 * for every page of three wavelengths, drawn from a page the lobe number
 * picks, each page weighted by its value over the pages' mean density.
 *  - chi-square of bsdf_sample_pages against the mean pdf
 *    (bsdf_eval_pages), at 3 incidences, for a bilambertian leaf whose
 *    transmittance is 0 at the first page's wavelengths (so a page's own
 *    sampling misses a lobe another page has), for an rpv soil with a
 *    spectral rho_0 and for a gold roughconductor (its index preset per
 *    page) and for water following the render's wavelength (`ocean_legacy`
 *    "render": each channel its own index, whitecaps, underlight and lobe
 *    choice), for a plastic and a roughplastic whose spectral diffuse
 *    reflectance makes the lobe choice differ between the pages (their
 *    smooth lobes; the delta lobe is left out of the histogram), with
 *    bundles of 16 (6 pages) and 7 (3 pages);
 *  - delta lobes that say their value (bsdf_ops.delta_value): plastic's
 *    specular lobe, drawn with a probability that differs between the
 *    pages, and glass's reflection and transmission (one index, a
 *    spectral transmittance): drawn with the pages' mean probability
 *    (200,000 samples, within 4 binomial standard errors), each page
 *    weighted by its value over it (1e-12), each page's value and
 *    probability bit for bit the BSDF's at its wavelengths alone;
 *  - each page's weight times the mean pdf is that page's value (1e-12),
 *    and each page's value is the BSDF's at its own wavelengths: the leaf
 *    (and the gold roughconductor) evaluated at page p equals the same BSDF
 *    prepared at the page's three wavelengths alone, bit for bit (the
 *    ocean: pages 0, 3 and 5, value and pdf);
 *  - the uniform texture answers for rsw_page and leaves it at 0;
 *  - `null` (a delta lobe every page draws alike) gives weight 1 at every page;
 *  - twosided over a plastic (and over a gold conductor) says its nested
 *    delta lobe's value at each page: the front side's is the nested
 *    BSDF's, the back side's the nested BSDF's with wi mirrored, bit for
 *    bit, and it is drawn with the pages' mean probability (as above);
 *  - compositions over delta lobes say their values: a blendbsdf over a
 *    plastic and a mask over a plastic (its pass-through too), drawn with
 *    the pages' mean probability (as above);
 *  - what carries pages: plastic, roughplastic, dielectric, the ocean,
 *    twosided, blendbsdf, mask and selectbsdf over them, a blend of two
 *    dielectrics and a mask over a dielectric among them (two delta
 *    transmissions, told apart by their directions); the `stokes`
 *    integrator is refused, named;
 *  - `homogeneous` and `heterogeneous` media carry pages under volpath
 *    and piecewise_volpath (a heterogeneous one's majorant covers every
 *    page: volpath tracks them at once); at page
 *    p the homogeneous medium's coefficients, free flight and
 *    transmittance are bit for bit the medium's prepared at the page's
 *    three wavelengths alone, and rsw_page is left at 0;
 *  - grids with a wavelength axis: a `piecewise` medium whose sigma_t is
 *    a gridvolume of 4 layers tabulated at 400, 550 and 700 nm (and whose
 *    albedo is a spectrum) carries pages; each page's layers (sigma_t,
 *    albedo, cumulative thickness) are bit for bit the medium's prepared
 *    at the page's wavelengths alone, and the grid's eval at page p is
 *    its value there; an mqdiffuse's grid refuses any bundle (it reads
 *    one channel), and so does a blendphase of a spectral weight over a
 *    blendphase of a spectral weight (it reads its components at channel
 *    0);
 *  - a blendphase whose weight depends on the wavelength (once read at a
 *    bundle's first wavelength in every channel) renders a bundle
 *    chromatic: each channel's mixture at its own weight, each page bit
 *    for bit the phase prepared at the page's wavelengths alone;
 *  - each medium names its thickest and thinnest channels over a
 *    bundle's pages and their ratio (a homogeneous one by sigma_t, 9; a
 *    piecewise one by its column, 3.45 / 0.35; 1.43 over 400..460 nm):
 *    what volpath's free flights favour when the ratio passes 4.
 * Chi-square: 200,000 samples per run, significance 0.01 with the Sidak
 * correction over the runs of this file; fixed seeds. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../../../server/kernel/integrators/pages.h"
#include "../../../server/kernel/media/layered.h"
#include "../../support/bsdf_test.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define CHI2_TESTS 36

static const char *LEAF =
    "{\"type\": \"bilambertian\","
    " \"reflectance\": {\"type\": \"spectrum\", \"wavelengths\": [400, 500, 700], \"values\": [0.05, 0.1, "
    "0.5]},"
    " \"transmittance\": {\"type\": \"spectrum\", \"wavelengths\": [400, 460, 470, 700], \"values\": [0, 0, "
    "0.2, 0.45]}}";
static const char *SOIL =
    "{\"type\": \"rpv\", \"rho_0\": {\"type\": \"spectrum\", \"wavelengths\": [400, 700], "
    "\"values\": [0.02, 0.3]}, \"k\": 0.7, \"g\": -0.2}";

static const char *METAL = "{\"type\": \"roughconductor\", \"material\": \"Au\", \"alpha\": 0.25}";

/* Water that follows the render's wavelength: its index, whitecaps,
 * underlight (none past 700 nm) and the tables that weight its lobe
 * choice differ between the channels of a page and between the pages. */
static const char *OCEAN = "{\"type\": \"ocean_legacy\", \"wavelength\": \"render\", \"wind_speed\": 5, "
                           "\"wind_direction\": 30, \"pigmentation\": 1}";

static scene *bsdf_scene(const char *bsdf_json) {
  char buf[2048];
  snprintf(buf, sizeof buf, "{\"type\": \"scene\", \"s\": {\"type\": \"rectangle\", \"bsdf\": %s}}",
           bsdf_json);
  return tsup_load(buf, "mono");
}

/* Prepared at page p's three wavelengths alone, of a bundle of 16
 * wavelengths 400, 420, ... nm (prepare_bundle's). */
static bool prepare_page_alone(scene *s, int p, rsw_err *err) {
  render_ctx rc = {.variant = VARIANT_MONO, .bundle = 3};
  for (int c = 0; c < RENDER_MAX_BUNDLE; c++)
    rc.wl[c] = 400.0 + 20.0 * (3 * p + (c < 3 ? c : 2) < 15 ? 3 * p + (c < 3 ? c : 2) : 15);
  rc.wavelength = rc.wl[0];
  return scene_prepare(s, &rc, err) == RSW_OK;
}

/* Prepared for a bundle of k wavelengths 400, 420, ... nm. */
static bool prepare_bundle(scene *s, int k) {
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 400.0, .bundle = k};
  for (int c = 0; c < RENDER_MAX_BUNDLE; c++) rc.wl[c] = 400.0 + 20.0 * (c < k ? c : k - 1);
  rsw_err err = {0};
  return scene_prepare(s, &rc, &err) == RSW_OK;
}

/* A plastic whose diffuse reflectance rises 20-fold over the bundle: its
 * specular lobe's choice probability differs between the pages; a
 * roughplastic alike; glass with a spectral specular_transmittance (one
 * index: every page draws its lobes alike). */
static const char *PLASTIC =
    "{\"type\": \"plastic\", \"diffuse_reflectance\": {\"type\": \"spectrum\", \"wavelengths\": [400, 700], "
    "\"values\": [0.03, 0.6]}}";
static const char *ROUGHPLASTIC =
    "{\"type\": \"roughplastic\", \"alpha\": 0.2, \"diffuse_reflectance\": {\"type\": \"spectrum\", "
    "\"wavelengths\": [400, 700], \"values\": [0.03, 0.6]}}";
static const char *GLASS =
    "{\"type\": \"dielectric\", \"int_ior\": 1.5, \"specular_transmittance\": {\"type\": \"spectrum\", "
    "\"wavelengths\": [400, 700], \"values\": [0.9, 0.2]}}";

/* One ocean scene for the file: prepared again for each bundle, it keeps
 * the transmittance tables it built (about half a second a wavelength). */
static scene *g_ocean;
static scene *ocean_scene(void) {
  if (!g_ocean) g_ocean = bsdf_scene(OCEAN);
  return g_ocean;
}

typedef struct pages_case {
  const bsdf *b;
  surface_interaction si;
  int pages;
} pages_case;

static bool sample_pages(void *user, const double *u, vec3 *out, double *weight) {
  pages_case *c = user;
  bsdf_sample bs;
  color w[RENDER_MAX_PAGES];
  bsdf_sample_pages(c->b, &c->si, c->pages, u[0], v2(u[1], u[2]), &bs, w);
  bool smooth = bs.pdf > 0 && !(bs.sampled_type & BSDF_DELTA); /* (a delta lobe is not in the pdf) */
  *weight = smooth ? 1.0 : 0.0;
  *out = bs.wo;
  return smooth;
}

static double pdf_pages(void *user, vec3 wo) {
  pages_case *c = user;
  color f[RENDER_MAX_PAGES];
  return bsdf_eval_pages(c->b, &c->si, c->pages, wo, true, f);
}

static void test_chi2(void) {
  const char *bsdfs[6] = {LEAF, SOIL, METAL, OCEAN, PLASTIC, ROUGHPLASTIC};
  const int ks[2] = {16, 7};
  const double th[3] = {10, 50, 80};
  int runs = 0;
  for (int i = 0; i < 6; i++) {
    scene *s = i == 3 ? ocean_scene() : bsdf_scene(bsdfs[i]);
    for (int j = 0; j < 2; j++) {
      REQUIRE(s && prepare_bundle(s, ks[j]), "scene %d", i);
      REQUIRE(s->pages == (ks[j] + 2) / 3, "pages %d", s->pages);
      for (int t = 0; t < 3; t++) {
        pages_case c = {s->shapes[0]->bsdf, tb_si_with(tb_dir_deg(th[t], 30)), s->pages};
        chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
        cfg.sample_count = 200000;
        cfg.test_count = CHI2_TESTS;
        cfg.ires = 8;
        chi2_result r = chi2_run(&cfg, sample_pages, pdf_pages, &c);
        CHECK(r.passed, "chi2 bsdf %d bundle %d theta %g: p = %g: %s", i, ks[j], th[t], r.p_value, r.reason);
        runs++;
      }
      CHECK(rsw_page == 0, "rsw_page left at 0");
    }
    if (i != 3) scene_free(s);
  }
  CHECK(runs == CHI2_TESTS, "runs %d", runs);
}

/* Page p of b (prepared for a bundle of 16) evaluates bit for bit as the
 * BSDF json prepared at the page's three wavelengths alone (its pdf too),
 * for every page, or every third one and the last when `some`. */
static void page_alone(const bsdf *b, int pages, const char *json, const surface_interaction *si, bool some) {
  color f[RENDER_MAX_PAGES];
  for (int p = 0; p < pages; p++) {
    if (some && p % 3 && p != pages - 1) continue;
    scene *one = bsdf_scene(json);
    rsw_err err = {0};
    REQUIRE(one && prepare_page_alone(one, p, &err), "page %d alone: %s", p, err.msg);
    const bsdf *b1 = one->shapes[0]->bsdf;
    for (int k = 0; k < 5; k++) {
      vec3 wo = tb_dir_deg(20 + 35 * k, 40 * k);
      color g = b1->ops->eval(b1, si, wo);
      bsdf_eval_pages(b, si, pages, wo, false, f);
      CHECK(g.c[0] == f[p].c[0] && g.c[1] == f[p].c[1] && g.c[2] == f[p].c[2], "page %d at %d", p, k);
      rsw_page = p;
      double pdf = b->ops->pdf(b, si, wo);
      rsw_page = 0;
      CHECK(pdf == b1->ops->pdf(b1, si, wo), "page %d's pdf at %d", p, k);
    }
    scene_free(one);
  }
}

/* 2000 samples of every page at seed `state` (an LCG): each page's weight
 * times the mean pdf is its value, and eval's pdf is the sample's.
 * Returns how many samples succeeded; *below counts those transmitted
 * (wo.z < 0), *glossy those of a glossy reflection. */
static int check_weights(const bsdf *b, const surface_interaction *si, int pages, uint64_t state, int *below,
                         int *glossy) {
  int checked = 0;
  *below = *glossy = 0;
  for (int n = 0; n < 2000; n++) {
    double u[3];
    for (int k = 0; k < 3; k++) {
      state = state * 6364136223846793005ULL + 1442695040888963407ULL;
      u[k] = (double)(state >> 11) * 0x1p-53;
    }
    bsdf_sample bs;
    color w[RENDER_MAX_PAGES], f[RENDER_MAX_PAGES];
    bsdf_sample_pages(b, si, pages, u[0], v2(u[1], u[2]), &bs, w);
    if (!(bs.pdf > 0)) continue;
    double pdf = bsdf_eval_pages(b, si, pages, bs.wo, true, f);
    CHECK_REL(pdf, bs.pdf, 1e-14);
    *below += bs.wo.z < 0;
    *glossy += bs.sampled_type == BSDF_GLOSSY_REFLECTION;
    for (int p = 0; p < pages; p++)
      for (int c = 0; c < 3; c++) CHECK_REL(w[p].c[c] * pdf, f[p].c[c], 1e-12);
    checked++;
  }
  return checked;
}

/* Weights are values over the mean pdf; a page's value is the BSDF's at
 * that page's wavelengths alone. */
static void test_weights(void) {
  scene *s = bsdf_scene(LEAF);
  REQUIRE(s && prepare_bundle(s, 16), "leaf");
  const bsdf *b = s->shapes[0]->bsdf;
  surface_interaction si = tb_si_with(tb_dir_deg(35, 0));
  int transmitted, glossy;
  int checked = check_weights(b, &si, s->pages, 7, &transmitted, &glossy);
  CHECK(checked == 2000, "every sample succeeds (%d)", checked);
  CHECK(transmitted > 300, "transmission is sampled (%d of 2000)", transmitted);
  /* Page 0 (400, 420, 440 nm) transmits nothing; page 2 (520..560 nm) does. */
  color f[RENDER_MAX_PAGES];
  vec3 down = tb_dir_deg(160, 10);
  bsdf_eval_pages(b, &si, s->pages, down, false, f);
  CHECK(col_is_black(f[0]) && f[2].c[0] > 0, "page 0 transmits nothing, page 2 does");
  page_alone(b, s->pages, LEAF, &si, false);
  scene_free(s);
}

/* `null`: a delta transmission of weight 1 at every page. */
static void test_null(void) {
  scene *s = bsdf_scene("{\"type\": \"null\"}");
  REQUIRE(s && prepare_bundle(s, 10), "null");
  surface_interaction si = tb_si_with(tb_dir_deg(25, 0));
  bsdf_sample bs;
  color w[RENDER_MAX_PAGES];
  bsdf_sample_pages(s->shapes[0]->bsdf, &si, s->pages, 0.9, v2(0.3, 0.6), &bs, w);
  CHECK(bs.pdf > 0 && (bs.sampled_type & BSDF_DELTA), "a delta sample");
  for (int p = 0; p < s->pages; p++) CHECK(w[p].c[0] == 1 && w[p].c[1] == 1 && w[p].c[2] == 1, "page %d", p);
  scene_free(s);
}

/* The gold roughconductor: each page's Fresnel from its own wavelengths'
 * index (gold's reflectance rises steeply from 450 to 600 nm). */
static void test_metal(void) {
  scene *s = bsdf_scene(METAL);
  REQUIRE(s && prepare_bundle(s, 16), "metal");
  const bsdf *b = s->shapes[0]->bsdf;
  surface_interaction si = tb_si_with(tb_dir_deg(30, 0));
  page_alone(b, s->pages, METAL, &si, false);
  color f[RENDER_MAX_PAGES];
  bsdf_eval_pages(b, &si, s->pages, tb_dir_deg(30, 180), false, f);
  CHECK(f[5].c[0] > 1.5 * f[0].c[0], "gold reflects more at 700 nm than at 400 nm (%g, %g)", f[5].c[0],
        f[0].c[0]);
  scene_free(s);
}

/* The ocean that follows the render: each page's weight times the mean
 * pdf is its value; its pages and its channels differ (the index and the
 * underlight, none at 700 nm); each page is the ocean prepared at its
 * wavelengths alone, bit for bit. */
static void test_ocean(void) {
  scene *s = ocean_scene();
  REQUIRE(s && prepare_bundle(s, 16), "ocean");
  const bsdf *b = s->shapes[0]->bsdf;
  surface_interaction si = tb_si_with(tb_dir_deg(35, 0));
  int below, glints;
  int checked = check_weights(b, &si, s->pages, 11, &below, &glints);
  CHECK(checked > 1900 && glints > 100, "samples %d, glints %d", checked, glints);
  /* Off the glint, the diffuse terms (underlight: none at 700 nm, the
   * last page's three channels) differ between channels and pages. */
  color f[RENDER_MAX_PAGES];
  bsdf_eval_pages(b, &si, s->pages, tb_dir_deg(60, 90), false, f);
  CHECK(f[0].c[0] != f[0].c[1] && f[0].c[1] != f[0].c[2], "page 0's channels differ");
  CHECK(f[2].c[0] > 3 * f[5].c[0] && f[5].c[0] == f[5].c[2], "underlight at 520 nm, not at 700 (%g, %g)",
        f[2].c[0], f[5].c[0]);
  page_alone(b, s->pages, OCEAN, &si, true);
  scene_free(s);
  g_ocean = NULL;
}

/* A delta lobe's probability towards wo at page p (bsdf_ops.delta_value). */
static double delta_prob(const bsdf *b, const surface_interaction *si, int p, unsigned lobe, vec3 wo,
                         color *v) {
  double pr;
  rsw_page = p;
  *v = b->ops->delta_value(b, si, lobe, wo, &pr);
  rsw_page = 0;
  return pr;
}

/* Delta lobes whose choice differs between the pages (plastic) or does
 * not (glass), and compositions whose parts' lobes of one kind lead to
 * different directions (two glasses, a mask's pass-through and its
 * glass): over 200,000 samples each direction the lobe is drawn towards
 * is drawn with the pages' mean probability for it (within 4 binomial
 * standard errors), each page's weight times that mean is the page's own
 * value towards it (1e-12), and each page's value and probability are
 * the BSDF's at the page's wavelengths alone, bit for bit. ndir: the
 * distinct directions expected. */
static void delta_case(const char *json, unsigned lobe, int pk, int ndir) {
  scene *s = bsdf_scene(json);
  REQUIRE(s && prepare_bundle(s, 16), "%s", json);
  const bsdf *b = s->shapes[0]->bsdf;
  surface_interaction si = tb_si_with(tb_dir_deg(40, 0));
  enum {
    D = 4
  };
  vec3 dir[D];
  int nd = 0, hits[D] = {0}, checked[D] = {0};
  double pm[D] = {0}, pr[D][RENDER_MAX_PAGES];
  color v[D][RENDER_MAX_PAGES];
  uint64_t state = 5;
  int n = 200000;
  for (int k = 0; k < n; k++) {
    double u[3];
    for (int i = 0; i < 3; i++) {
      state = state * 6364136223846793005ULL + 1442695040888963407ULL;
      u[i] = (double)(state >> 11) * 0x1p-53;
    }
    bsdf_sample bs;
    color w[RENDER_MAX_PAGES];
    bsdf_sample_pages(b, &si, s->pages, u[0], v2(u[1], u[2]), &bs, w);
    if (bs.sampled_type != lobe || !(bs.pdf > 0)) continue;
    int d = 0;
    while (d < nd && !(dir[d].x == bs.wo.x && dir[d].y == bs.wo.y && dir[d].z == bs.wo.z)) d++;
    if (d == nd) {
      REQUIRE(nd < D, "more than %d directions", D);
      dir[nd++] = bs.wo;
      for (int p = 0; p < s->pages; p++) pm[d] += pr[d][p] = delta_prob(b, &si, p, lobe, bs.wo, &v[d][p]);
      pm[d] /= s->pages;
    }
    hits[d]++;
    if (checked[d]++ >= 100) continue;
    CHECK_REL(bs.pdf, pm[d], 1e-14);
    for (int p = 0; p < s->pages; p++)
      for (int c = 0; c < 3; c++) CHECK_REL(w[p].c[c] * pm[d], v[d][p].c[c], 1e-12);
  }
  CHECK(nd == ndir, "%d directions drawn, %d expected", nd, ndir);
  for (int d = 0; d < nd; d++) {
    CHECK(pk ? pr[d][0] > 2 * pr[d][5] : pr[d][0] == pr[d][5],
          "direction %d: page 0's probability %g, page 5's %g", d, pr[d][0], pr[d][5]);
    double se = sqrt(pm[d] * (1 - pm[d]) / n);
    CHECK(fabs((double)hits[d] / n - pm[d]) < 4 * se,
          "direction %d drawn %g of the time, the mean probability %g (se %g)", d, (double)hits[d] / n, pm[d],
          se);
    for (int p = 0; p < s->pages; p += 5) {
      scene *one = bsdf_scene(json);
      render_ctx rc = {.variant = VARIANT_MONO, .bundle = 3};
      for (int c = 0; c < RENDER_MAX_BUNDLE; c++)
        rc.wl[c] = 400.0 + 20.0 * (p == 5 ? 15 : 3 * p + (c < 3 ? c : 2));
      rc.wavelength = rc.wl[0];
      rsw_err err = {0};
      REQUIRE(one && scene_prepare(one, &rc, &err) == RSW_OK, "page %d alone", p);
      color v1;
      double p1 = delta_prob(one->shapes[0]->bsdf, &si, 0, lobe, dir[d], &v1);
      CHECK(p1 == pr[d][p] && v1.c[0] == v[d][p].c[0] && v1.c[1] == v[d][p].c[1] && v1.c[2] == v[d][p].c[2],
            "direction %d, page %d alone", d, p);
      scene_free(one);
    }
  }
  CHECK(rsw_page == 0, "rsw_page left at 0");
  scene_free(s);
}

static void test_delta(void) {
  delta_case(PLASTIC, BSDF_DELTA_REFLECTION, 1, 1);
  delta_case(GLASS, BSDF_DELTA_TRANSMISSION, 0, 1);
  delta_case(GLASS, BSDF_DELTA_REFLECTION, 0, 1);
}

/* Compositions over delta lobes: a blend of a diffuse and a plastic (the
 * specular lobe's probability halved, still differing between the
 * pages), a mask over a plastic (its pass-through, 1 - opacity at every
 * page, and the plastic's lobe times the opacity), a blend of two glasses
 * (index 1.5 and 1.33: two transmitted directions, each its glass's
 * lobe; one reflected, both glasses' lobes) and a mask over a glass (the
 * pass-through and the glass's refraction, two directions): drawn with
 * the pages' mean probability, weighted by each page's value
 * (delta_case). */
static void test_compositions(void) {
  char json[512];
  snprintf(json, sizeof json,
           "{\"type\": \"blendbsdf\", \"weight\": 0.5, \"bsdf_0\": {\"type\": \"diffuse\"}, \"bsdf_1\": %s}",
           PLASTIC);
  delta_case(json, BSDF_DELTA_REFLECTION, 1, 1);
  snprintf(json, sizeof json, "{\"type\": \"mask\", \"opacity\": 0.6, \"bsdf\": %s}", PLASTIC);
  delta_case(json, BSDF_DELTA_REFLECTION, 1, 1);
  delta_case(json, BSDF_DELTA_TRANSMISSION, 0, 1);
  const char *glasses =
      "{\"type\": \"blendbsdf\", \"weight\": 0.3, \"bsdf_0\": {\"type\": \"dielectric\", "
      "\"int_ior\": 1.5, \"ext_ior\": 1.0}, \"bsdf_1\": {\"type\": \"dielectric\", \"int_ior\": "
      "1.33, \"ext_ior\": 1.0}}";
  delta_case(glasses, BSDF_DELTA_TRANSMISSION, 0, 2);
  delta_case(glasses, BSDF_DELTA_REFLECTION, 0, 1);
  const char *masked =
      "{\"type\": \"mask\", \"opacity\": 0.6, \"bsdf\": {\"type\": \"dielectric\", \"int_ior\": "
      "1.5, \"ext_ior\": 1.0}}";
  delta_case(masked, BSDF_DELTA_TRANSMISSION, 0, 2);
  delta_case(masked, BSDF_DELTA_REFLECTION, 0, 1);
}

/* twosided over a plastic and over a gold conductor: its delta_value is
 * the nested BSDF's at each page, the back side's with wi mirrored, bit
 * for bit; the plastic's drawn with the pages' mean probability
 * (delta_case); a wi in the surface's plane has none. */
static void test_twosided(void) {
  char two[512];
  snprintf(two, sizeof two, "{\"type\": \"twosided\", \"bsdf\": %s}", PLASTIC);
  delta_case(two, BSDF_DELTA_REFLECTION, 1, 1);
  const char *nested[2] = {PLASTIC, "{\"type\": \"conductor\", \"material\": \"Au\"}"};
  for (int i = 0; i < 2; i++) {
    snprintf(two, sizeof two, "{\"type\": \"twosided\", \"bsdf\": %s}", nested[i]);
    scene *s = bsdf_scene(two), *one = bsdf_scene(nested[i]);
    REQUIRE(s && one && prepare_bundle(s, 16) && prepare_bundle(one, 16), "%s", two);
    const bsdf *b = s->shapes[0]->bsdf, *n = one->shapes[0]->bsdf;
    CHECK(b->ops->delta_value && n->ops->delta_value, "%s says its delta lobes' values", two);
    surface_interaction front = tb_si_with(tb_dir_deg(40, 0)), back = front;
    back.wi.z = -front.wi.z;
    vec3 wf = v3(-front.wi.x, -front.wi.y, front.wi.z), wb = v3(-back.wi.x, -back.wi.y, back.wi.z);
    for (int p = 0; p < s->pages; p++) {
      color vf, vb, vn;
      double pf = delta_prob(b, &front, p, BSDF_DELTA_REFLECTION, wf, &vf);
      double pb = delta_prob(b, &back, p, BSDF_DELTA_REFLECTION, wb, &vb);
      double pn = delta_prob(n, &front, p, BSDF_DELTA_REFLECTION, wf, &vn);
      CHECK(pn > 0 && pf == pn && pb == pn && memcmp(&vf, &vn, sizeof vn) == 0 &&
                memcmp(&vb, &vn, sizeof vn) == 0,
            "%s page %d: front %g, back %g, nested %g", two, p, pf, pb, pn);
    }
    surface_interaction flat = front;
    flat.wi.z = 0.0;
    color v;
    CHECK(delta_prob(b, &flat, 0, BSDF_DELTA_REFLECTION, wf, &v) == 0.0 && col_max(v) == 0.0, "%s: wi.z = 0",
          two);
    color vx;
    CHECK(delta_prob(b, &front, 0, BSDF_DELTA_REFLECTION, v3(0, 0, 1), &vx) == 0.0 && col_max(vx) == 0.0,
          "%s: not the mirror direction", two);
    scene_free(s);
    scene_free(one);
  }
}

/* What carries pages (scene_page_blocker): plastic, roughplastic,
 * dielectric, the ocean that follows the render, and twosided, blendbsdf,
 * mask and selectbsdf over them, a blend of two dielectrics and a mask
 * over a dielectric among them (each part's lobe counts only towards its
 * own direction); the `stokes` integrator is refused, named. */
static void test_blockers(void) {
  const char *yes[12] = {PLASTIC,
                         ROUGHPLASTIC,
                         GLASS,
                         OCEAN,
                         "{\"type\": \"twosided\", \"bsdf\": {\"type\": \"roughplastic\"}}",
                         "{\"type\": \"twosided\", \"bsdf\": {\"type\": \"plastic\"}}",
                         "{\"type\": \"blendbsdf\", \"weight\": 0.3, \"bsdf_0\": {\"type\": \"dielectric\"}, "
                         "\"bsdf_1\": {\"type\": \"plastic\"}}",
                         "{\"type\": \"mask\", \"opacity\": 0.5, \"bsdf\": {\"type\": \"plastic\"}}",
                         "{\"type\": \"selectbsdf\", \"indices\": 1, \"bsdf_0\": {\"type\": \"diffuse\"}, "
                         "\"bsdf_1\": {\"type\": \"dielectric\"}}",
                         "{\"type\": \"blendbsdf\", \"weight\": 0.3, \"bsdf_0\": {\"type\": \"dielectric\"}, "
                         "\"bsdf_1\": {\"type\": \"dielectric\", \"int_ior\": 1.33}}",
                         "{\"type\": \"mask\", \"opacity\": 0.5, \"bsdf\": {\"type\": \"dielectric\"}}",
                         "{\"type\": \"blendbsdf\", \"weight\": 0.3, \"bsdf_0\": {\"type\": \"diffuse\"}, "
                         "\"bsdf_1\": {\"type\": \"roughplastic\"}}"};
  for (int i = 0; i < 12; i++) {
    scene *s = bsdf_scene(yes[i]);
    const char *why = "";
    const object *blk = s ? scene_page_blocker(s, &why) : NULL;
    CHECK(s && !blk, "%s carries pages (%s: %s)", yes[i], blk ? blk->plugin->name : "", why);
    scene_free(s);
  }
  scene *s =
      tsup_load("{\"type\": \"scene\", \"integrator\": {\"type\": \"stokes\", \"integrator\": {\"type\": "
                "\"path\"}}, \"s\": {\"type\": \"rectangle\"}}",
                "mono_polarized");
  const char *why = "";
  const object *blk = s ? scene_page_blocker(s, &why) : NULL;
  CHECK(blk && strcmp(blk->plugin->name, "stokes") == 0 && strstr(why, "at most three"),
        "stokes refused: %s %s", blk ? blk->plugin->name : "none", why);
  scene_free(s);
}

/* A medium (spectral sigma_t and albedo) inside a cube, rendered by the
 * integrator named. */
static scene *medium_scene(const char *integrator_type, const char *medium_json) {
  char buf[2048];
  snprintf(buf, sizeof buf,
           "{\"type\": \"scene\", \"integrator\": {\"type\": \"%s\"}, \"m\": %s, \"box\": {\"type\": "
           "\"cube\", \"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": \"ref\", \"id\": \"m\"}}}",
           integrator_type, medium_json);
  return tsup_load(buf, "mono");
}

static const char *HOMOGENEOUS =
    "{\"type\": \"homogeneous\", \"sigma_t\": {\"type\": \"spectrum\", \"wavelengths\": [400, 550, 700], "
    "\"values\": [0.9, 0.35, 0.1]}, \"albedo\": {\"type\": \"spectrum\", \"wavelengths\": [400, 700], "
    "\"values\": [0.95, 0.6]}}";

static void test_media(void) {
  const char *integrators[2] = {"volpath", "piecewise_volpath"};
  for (int i = 0; i < 2; i++) {
    scene *s = medium_scene(integrators[i], HOMOGENEOUS);
    const char *why = "";
    const object *blk = s ? scene_page_blocker(s, &why) : NULL;
    CHECK(s && !blk, "homogeneous under %s carries pages (%s: %s)", integrators[i],
          blk ? blk->plugin->name : "", why);
    scene_free(s);
    s = medium_scene(integrators[i],
                     "{\"type\": \"heterogeneous\", \"sigma_t\": {\"type\": \"gridvolume\", "
                     "\"shape\": [2, 1, 1, 2], \"wavelengths\": [400, 700], \"data\": [1, 2, 3, 4]}}");
    blk = s ? scene_page_blocker(s, &why) : NULL;
    CHECK(s && !blk, "heterogeneous under %s carries pages (%s: %s)", integrators[i],
          blk ? blk->plugin->name : "", why);
    /* its majorant covers every page: 4 at 700 nm (page 5) */
    REQUIRE(s && prepare_bundle(s, 16), "heterogeneous prepared for a bundle of 16");
    const medium *hm = s->shapes[0]->interior;
    medium_interaction at = {.p = v3(0, 0, 0)};
    CHECK(col_max(hm->ops->majorant(hm, &at)) == 4.0, "the majorant %g", col_max(hm->ops->majorant(hm, &at)));
    scene_free(s);
  }
  scene *s = medium_scene("volpath", HOMOGENEOUS);
  REQUIRE(s && prepare_bundle(s, 16) && s->pages == 6, "homogeneous prepared for a bundle of 16");
  const medium *m = s->shapes[0]->interior;
  REQUIRE(m && m->has_spectral_extinction && !m->absorbing_only, "the box's medium");
  ray3 r = {.o = v3(0.1, -0.2, -2), .d = v3_norm(v3(0.1, 0.2, 1)), .tmin = 0, .tmax = INFINITY};
  for (int p = 0; p < s->pages; p++) {
    scene *one = medium_scene("volpath", HOMOGENEOUS);
    rsw_err err = {0};
    REQUIRE(one && prepare_page_alone(one, p, &err), "page %d alone: %s", p, err.msg);
    const medium *m1 = one->shapes[0]->interior;
    medium_interaction a = {.p = r.o}, b = {.p = r.o};
    rsw_page = p;
    m->ops->coefficients(m, &a);
    color ta = m->ops->transmittance(m, &r, 1.0, 2.5), tra, pdfa;
    medium_interaction fa = {0}, fb = {0};
    m->ops->sample_real(m, &r, 1.0, 5.0, 0.6, 2, &fa, &tra, &pdfa);
    rsw_page = 0;
    m1->ops->coefficients(m1, &b);
    color tb = m1->ops->transmittance(m1, &r, 1.0, 2.5), trb, pdfb;
    m1->ops->sample_real(m1, &r, 1.0, 5.0, 0.6, 2, &fb, &trb, &pdfb);
    CHECK(memcmp(&a.sigma_t, &b.sigma_t, sizeof a.sigma_t) == 0 &&
              memcmp(&a.sigma_s, &b.sigma_s, sizeof a.sigma_s) == 0 && memcmp(&ta, &tb, sizeof ta) == 0,
          "page %d: coefficients (%g %g %g) and transmittance (%g) as the medium's alone (%g %g %g, %g)", p,
          a.sigma_t.c[0], a.sigma_t.c[1], a.sigma_t.c[2], ta.c[0], b.sigma_t.c[0], b.sigma_t.c[1],
          b.sigma_t.c[2], tb.c[0]);
    CHECK(fa.t == fb.t && memcmp(&tra, &trb, sizeof tra) == 0 && memcmp(&pdfa, &pdfb, sizeof pdfa) == 0,
          "page %d: free flight t %g as alone %g", p, fa.t, fb.t);
    scene_free(one);
  }
  medium_interaction q0 = {.p = r.o}, q5 = {.p = r.o};
  m->ops->coefficients(m, &q0);
  rsw_page = 5;
  m->ops->coefficients(m, &q5);
  rsw_page = 0;
  CHECK(q0.sigma_t.c[0] > 2 * q5.sigma_t.c[0], "page 0's sigma_t %g, page 5's %g", q0.sigma_t.c[0],
        q5.sigma_t.c[0]);
  scene_free(s);
}

/* The first object of scene s made by the plugin named. */
static const object *find_object(const scene *s, const char *name) {
  for (size_t i = 0; i < s->n_objects; i++)
    if (s->objects[i]->plugin && strcmp(s->objects[i]->plugin->name, name) == 0) return s->objects[i];
  return NULL;
}

static const char *LAYERS =
    "{\"type\": \"piecewise\", \"sigma_t\": {\"type\": \"gridvolume\", \"shape\": [4, 1, 1, 3], "
    "\"wavelengths\": [400, 550, 700], \"filter_type\": \"nearest\", \"data\": [0.9, 0.4, 0.1, 0.5, 0.3, "
    "0.2, 0.05, 0.05, 0.05, 2.0, 0.1, 0.0]}, \"albedo\": {\"type\": \"spectrum\", \"wavelengths\": [400, "
    "700], \"values\": [0.95, 0.5]}}";

/* Each medium names its thickest and thinnest channels over a bundle's
 * pages and their ratio (the prior of a path's hero channel favours both,
 * volpath's draw_hero): a homogeneous medium by sigma_t (0.9 at 400 nm over 0.1 at
 * 700), a piecewise one by its column (3.45 over 0.35, the layers' sums
 * at 400 and 700 nm); a bundle 400..460 nm of the layers spans 1.43. */
static void test_extremes(void) {
  scene *s = medium_scene("piecewise_volpath", HOMOGENEOUS);
  REQUIRE(s && prepare_bundle(s, 16), "homogeneous prepared for a bundle of 16");
  const medium *m = s->shapes[0]->interior;
  CHECK(m->thick_channel == 0 && m->thin_channel == 15 && fabs(m->extinction_spread - 9.0) < 1e-12,
        "homogeneous: thick %d, thin %d, spread %.17g", m->thick_channel, m->thin_channel,
        m->extinction_spread);
  scene_free(s);
  s = medium_scene("piecewise_volpath", LAYERS);
  REQUIRE(s && prepare_bundle(s, 16), "piecewise prepared for a bundle of 16");
  m = s->shapes[0]->interior;
  CHECK(m->thick_channel == 0 && m->thin_channel == 15 && fabs(m->extinction_spread - 3.45 / 0.35) < 1e-9,
        "piecewise: thick %d, thin %d, spread %.17g", m->thick_channel, m->thin_channel,
        m->extinction_spread);
  REQUIRE(prepare_bundle(s, 4), "piecewise prepared for a bundle of 4");
  CHECK(m->thick_channel == 0 && m->thin_channel == 3 && fabs(m->extinction_spread - 3.45 / 2.41) < 1e-9,
        "piecewise, 400..460 nm: thick %d, thin %d, spread %.17g", m->thick_channel, m->thin_channel,
        m->extinction_spread);
  scene_free(s);
}

/* The molecular atmosphere's phase (Rayleigh and an aerosol layer's hg,
 * weights per page) answers a bundle's pages in one call (eval_pages)
 * with each page's eval_channels bits, over 200 directions at 3 heights
 * (in the aerosol layer, at its top, above it). */
static void test_phase_pages(void) {
  scene *s = medium_scene(
      "piecewise_volpath",
      "{\"type\": \"molecular_atmosphere\", \"thermoprops\": {\"identifier\": \"afgl_1986-us_standard\", "
      "\"toa_altitude\": 120000, \"n_layers\": 240}, \"width\": 1000000, \"particle_layers\": [{\"bottom\": "
      "0, "
      "\"top\": 2000, \"distribution\": \"uniform\", \"tau_ref\": 0.2, \"w_ref\": 550, \"angstrom\": 1.3, "
      "\"albedo\": 0.9, \"phase\": {\"type\": \"hg\", \"g\": 0.7}}]}");
  REQUIRE(s && prepare_bundle(s, 16) && s->pages == 6, "molecular_atmosphere prepared for a bundle of 16");
  const medium *m =
      find_object(s, "molecular_atmosphere") ? (const medium *)find_object(s, "molecular_atmosphere") : NULL;
  REQUIRE(m && m->phase && m->phase->chromatic && m->phase->ops->eval_pages,
          "a chromatic phase with eval_pages");
  const phase *ph = m->phase;
  pcg32 rng;
  pcg32_seed(&rng, 5, 6);
  int bad = 0, n = 0;
  const double zs[3] = {500.0, 2000.0, 30000.0};
  for (int h = 0; h < 3; h++)
    for (int i = 0; i < 200; i++) {
      medium_interaction mi = {.medium = m, .p = v3(0, 0, zs[h])};
      mi.wi = warp_square_to_uniform_sphere(v2(pcg32_next_double(&rng), pcg32_next_double(&rng)));
      vec3 wo = warp_square_to_uniform_sphere(v2(pcg32_next_double(&rng), pcg32_next_double(&rng)));
      color all[RENDER_MAX_PAGES];
      ph->ops->eval_pages(ph, &mi, wo, 0, s->pages, all);
      for (int p = 0; p < s->pages; p++, n++) {
        rsw_page = p;
        color one = ph->ops->eval_channels(ph, &mi, wo);
        rsw_page = 0;
        bad += memcmp(&one, &all[p], sizeof one) != 0;
      }
    }
  CHECK(bad == 0, "%d of %d pages' eval_pages differ from their eval_channels", bad, n);
  scene_free(s);
}

/* A blendphase whose weight is a grid with a wavelength axis. */
#define BLEND_SPECTRAL                                                                                       \
  "{\"type\": \"blendphase\", \"weight\": {\"type\": \"gridvolume\", \"shape\": [1, 1, 1, 3], "              \
  "\"wavelengths\": [400, 550, 700], \"data\": [0.1, 0.5, 0.9]}, \"phase_0\": {\"type\": \"rayleigh\"}, "    \
  "\"phase_1\": {\"type\": \"hg\", \"g\": 0.7}}"

/* A blendphase over a spectral blendphase, its own weight a spectrum. */
#define BLEND_NESTED                                                                                         \
  "{\"type\": \"blendphase\", \"weight\": {\"type\": \"spectrum\", \"wavelengths\": [400, 700], "            \
  "\"values\": [0.2, 0.8]}, \"phase_0\": " BLEND_SPECTRAL ", \"phase_1\": {\"type\": \"hg\", \"g\": -0.3}}"

/* A blendphase whose weight depends on the wavelength (its own, or a
 * nested blendphase's) renders a bundle chromatic: its value per channel
 * at the channel's own weights, at each page bit for bit the phase
 * prepared at the page's wavelengths alone (eval_channels), and each
 * channel the phase prepared at the channel's wavelength alone (one
 * wavelength: eval_pdf; 1e-12); sample and eval_pdf stay channel 0's. */
static void test_chromatic_blend(void) {
  const char *meds[2] = {"{\"type\": \"homogeneous\", \"phase\": " BLEND_SPECTRAL "}",
                         "{\"type\": \"homogeneous\", \"phase\": " BLEND_NESTED "}"};
  for (int i = 0; i < 2; i++) {
    const char *med = meds[i];
    scene *s = medium_scene("volpath", med);
    const char *why = "";
    REQUIRE(s && !scene_page_blocker(s, &why), "blend %d carries pages: %s", i, why);
    REQUIRE(prepare_bundle(s, 16), "prepared for a bundle of 16");
    const phase *ph = s->shapes[0]->interior->phase;
    CHECK(ph->chromatic && ph->ops->eval_channels, "blend %d: chromatic in a bundle", i);
    medium_interaction mi = {.p = v3(0, 0, 0), .wi = v3(0, 0, 1)};
    vec3 wo = v3_norm(v3(0.3, 0.2, 0.9));
    for (int p = 0; p < s->pages; p++) {
      scene *one = medium_scene("volpath", med);
      rsw_err err = {0};
      REQUIRE(one && prepare_page_alone(one, p, &err), "page %d alone: %s", p, err.msg);
      const phase *p1 = one->shapes[0]->interior->phase;
      rsw_page = p;
      color a = ph->ops->eval_channels(ph, &mi, wo);
      rsw_page = 0;
      color b = p1->ops->eval_channels(p1, &mi, wo);
      CHECK(memcmp(&a, &b, sizeof a) == 0, "blend %d, page %d: %g %g %g, alone %g %g %g", i, p, a.c[0],
            a.c[1], a.c[2], b.c[0], b.c[1], b.c[2]);
      scene_free(one);
      for (int c = 0; c < 3 && 3 * p + c < 16; c++) {
        scene *w1 = medium_scene("volpath", med);
        render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 400.0 + 20.0 * (3 * p + c)};
        REQUIRE(w1 && scene_prepare(w1, &rc, &err) == RSW_OK, "%s", err.msg);
        const phase *pw = w1->shapes[0]->interior->phase;
        double pdf, v = pw->ops->eval_pdf(pw, &mi, wo, &pdf);
        CHECK(fabs(a.c[c] - v) <= 1e-12 * v, "blend %d at %g nm: %.17g in the bundle, %.17g alone", i,
              rc.wavelength, a.c[c], v);
        scene_free(w1);
      }
    }
    color c0 = ph->ops->eval_channels(ph, &mi, wo);
    CHECK(c0.c[0] != c0.c[2], "the channels differ: %g %g", c0.c[0], c0.c[2]);
    scene_free(s);
    s = medium_scene("volpath", med);
    render_ctx mono = {.variant = VARIANT_MONO, .wavelength = 500.0};
    rsw_err err = {0};
    REQUIRE(s && scene_prepare(s, &mono, &err) == RSW_OK, "%s", err.msg);
    CHECK(!s->shapes[0]->interior->phase->chromatic, "one wavelength: not chromatic");
    scene_free(s);
  }
}

static void test_grids(void) {
  scene *s = medium_scene("piecewise_volpath", LAYERS);
  const char *why = "";
  const object *blk = s ? scene_page_blocker(s, &why) : NULL;
  CHECK(s && !blk, "a piecewise medium over a spectral grid carries pages (%s: %s)",
        blk ? blk->plugin->name : "", why);
  REQUIRE(s && prepare_bundle(s, 16) && s->pages == 6, "prepared for a bundle of 16");
  const layered_medium *lm = (const layered_medium *)s->shapes[0]->interior;
  REQUIRE(lm && lm->Lp, "the box's medium has its pages' layers");
  const medium *m = &lm->base;
  CHECK(m->has_spectral_extinction && !m->absorbing_only, "spectral extinction");
  for (int p = 0; p < s->pages; p++) {
    scene *one = medium_scene("piecewise_volpath", LAYERS);
    rsw_err err = {0};
    REQUIRE(one && prepare_page_alone(one, p, &err), "page %d alone: %s", p, err.msg);
    const media_layers *a = p ? &lm->Lp[p - 1] : &lm->L;
    const media_layers *b = &((const layered_medium *)one->shapes[0]->interior)->L;
    CHECK(a->n == 4 && b->n == 4 && memcmp(a->lay, b->lay, 5 * sizeof *a->lay) == 0 &&
              memcmp(a->alb, b->alb, 12 * sizeof *a->alb) == 0,
          "page %d: layers (sigma_t %g %g %g) as the medium's alone (%g %g %g)", p, a->lay[0].sig[0],
          a->lay[0].sig[1], a->lay[0].sig[2], b->lay[0].sig[0], b->lay[0].sig[1], b->lay[0].sig[2]);
    /* the grid's eval at page p: its value at the page's wavelengths */
    const volume *g = (const volume *)find_object(s, "gridvolume"),
                 *g1 = (const volume *)find_object(one, "gridvolume");
    REQUIRE(g && g1, "the grids");
    vec3 at = v3(0.1, 0.2, 0.3);
    rsw_page = p;
    color ga = g->ops->eval(g, at);
    rsw_page = 0;
    color gb = g1->ops->eval(g1, at);
    CHECK(memcmp(&ga, &gb, sizeof ga) == 0, "page %d: the grid's value %g %g %g, alone %g %g %g", p, ga.c[0],
          ga.c[1], ga.c[2], gb.c[0], gb.c[1], gb.c[2]);
    scene_free(one);
  }
  CHECK(lm->L.lay[0].sig[0] > 3 * lm->Lp[4].lay[0].sig[2], "400 nm thicker than 700 nm: %g, %g",
        lm->L.lay[0].sig[0], lm->Lp[4].lay[0].sig[2]);
  CHECK(rsw_page == 0, "rsw_page left at 0");
  scene_free(s);
}

/* An mqdiffuse whose grid has a wavelength axis (0.1 at 400 nm, 0.2 at
 * 700, at every node) carries pages: its value in channel c of page p is
 * the BSDF's prepared at that wavelength alone (1e-12). */
static void test_mqdiffuse(void) {
  const char *mq =
      "{\"type\": \"mqdiffuse\", \"grid\": {\"type\": \"gridvolume\", \"shape\": [2, 2, 2, 2], "
      "\"wavelengths\": [400, 700], \"data\": [0.1, 0.2, 0.1, 0.2, 0.1, 0.2, 0.1, 0.2, 0.1, 0.2, 0.1, "
      "0.2, 0.1, 0.2, 0.1, 0.2]}}";
  scene *s = bsdf_scene(mq);
  const char *why = "";
  const object *blk = s ? scene_page_blocker(s, &why) : NULL;
  CHECK(s && !blk, "mqdiffuse over a spectral grid carries pages (%s: %s)", blk ? blk->plugin->name : "",
        why);
  REQUIRE(s && prepare_bundle(s, 16), "prepared for a bundle of 16");
  const bsdf *b = s->shapes[0]->bsdf;
  surface_interaction si = tb_si_with(v3_norm(v3(0.3, 0.1, 0.8)));
  vec3 wo = v3_norm(v3(-0.2, 0.4, 0.7));
  for (int p = 0; p < s->pages; p++) {
    rsw_page = p;
    color a = b->ops->eval(b, &si, wo);
    rsw_page = 0;
    for (int c = 0; c < 3 && 3 * p + c < 16; c++) {
      scene *one = bsdf_scene(mq);
      render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 400.0 + 20.0 * (3 * p + c)};
      rsw_err err = {0};
      REQUIRE(one && scene_prepare(one, &rc, &err) == RSW_OK, "%s", err.msg);
      const bsdf *b1 = one->shapes[0]->bsdf;
      color v = b1->ops->eval(b1, &si, wo);
      CHECK(fabs(a.c[c] - v.c[0]) <= 1e-12 * v.c[0] && v.c[0] > 0,
            "at %g nm: %.17g in the bundle, %.17g alone", rc.wavelength, a.c[c], v.c[0]);
      scene_free(one);
    }
  }
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_chi2);
  RSW_TEST_RUN(test_weights);
  RSW_TEST_RUN(test_metal);
  RSW_TEST_RUN(test_ocean);
  RSW_TEST_RUN(test_null);
  RSW_TEST_RUN(test_delta);
  RSW_TEST_RUN(test_twosided);
  RSW_TEST_RUN(test_compositions);
  RSW_TEST_RUN(test_blockers);
  RSW_TEST_RUN(test_media);
  RSW_TEST_RUN(test_grids);
  RSW_TEST_RUN(test_chromatic_blend);
  RSW_TEST_RUN(test_extremes);
  RSW_TEST_RUN(test_phase_pages);
  RSW_TEST_RUN(test_mqdiffuse);
  RSW_TEST_END("test_pages");
}
