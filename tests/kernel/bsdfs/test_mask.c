/* `mask` (bsdfs/mask.c): a half-opaque mask halves the hit.
 *
 * A masked diffuse plate (rho 0.5, z = 1) lit by a sun of irradiance 1 at
 * the zenith lies over an upward lamp of radiance 2 (z = 0, black BSDF);
 * rays looking straight down see
 *   L = (1 - alpha) 2 + alpha rho / pi
 * (through the mask to the lamp, or the plate's sunlit diffuse
 * reflection). The lamp has sampling_weight 0, so that light samples go
 * to the sun alone and the plate's part has no variance. An mradiancemeter of 400 identical rays gives 400
 * independent estimates: alpha 0 and 1 are exact (1e-5), alpha 0.5 within
 * 3 standard errors of the mean. Also a chi-square test of the smooth
 * part of sample() against pdf() (the pass-through is a delta; 200,000
 * samples, significance 0.01, fixed seed), and the XML form. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "../../support/bsdf_test.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

enum {
  NPIX = 400
};

static scene *mask_scene(const char *opacity_json) {
  sbuf b = {0};
  sb_printf(&b, "{\"type\": \"scene\", \"sensor\": {\"type\": \"mradiancemeter\", \"origins\": \"");
  for (int i = 0; i < NPIX; i++) sb_printf(&b, "%s0.1 0.2 2", i ? " " : "");
  sb_printf(&b, "\", \"directions\": \"");
  for (int i = 0; i < NPIX; i++) sb_printf(&b, "%s0 0 -1", i ? " " : "");
  sb_printf(
      &b,
      "\", \"sampler\": {\"type\": \"independent\", \"sample_count\": 64},"
      " \"film\": {\"type\": \"hdrfilm\", \"width\": %d, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\"},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1]},"
      " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"translate\": [0, 0, 1]}],"
      "   \"bsdf\": {\"type\": \"mask\", \"opacity\": %s,"
      "     \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}},"
      " \"lamp\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [3, 3, 1]}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0},"
      "   \"emitter\": {\"type\": \"area\", \"radiance\": 2, \"sampling_weight\": 0}}}",
      NPIX, opacity_json);
  scene *s = tsup_load(b.p, "mono");
  free(b.p);
  return s;
}

static void mask_estimate(const char *opacity, double *mean, double *sem) {
  scene *s = mask_scene(opacity);
  *mean = *sem = NAN;
  if (!s) return;
  film_image img;
  if (tsup_render(s, 0, 17, 2, &img)) {
    tsup_stats(&img, 0, mean, sem);
    film_image_free(&img);
  }
  scene_free(s);
}

static void test_half_opaque_halves_the_hit(void) {
  const double plate = 0.5 / RSW_PI, lamp = 2.0;
  double m, sem;
  mask_estimate("0", &m, &sem);
  CHECK_REL(m, lamp, 1e-5);
  mask_estimate("1", &m, &sem);
  CHECK_REL(m, plate, 1e-5);
  mask_estimate("0.5", &m, &sem);
  double want = 0.5 * lamp + 0.5 * plate;
  CHECK(fabs(m - want) <= 3 * sem, "alpha 0.5: %.5f +- %.2g, expected %.5f", m, sem, want);
  CHECK(sem < 0.01 * want, "standard error %.3g too large for a meaningful test", sem);
  mask_estimate("0.25", &m, &sem);
  want = 0.75 * lamp + 0.25 * plate;
  CHECK(fabs(m - want) <= 3 * sem, "alpha 0.25: %.5f +- %.2g, expected %.5f", m, sem, want);
}

static bool sample_smooth(void *user, const double *u, vec3 *out, double *weight) {
  chi2_bsdf *c = user;
  bsdf_sample bs;
  color w = c->b->ops->sample(c->b, &c->si, u[0], v2(u[1], u[2]), &bs);
  if (!(bs.pdf > 0.0) || col_is_black(w) || (bs.sampled_type & BSDF_DELTA)) {
    *weight = 0.0;
    return false;
  }
  *out = bs.wo;
  *weight = 1.0;
  return true;
}

static void test_chi2(void) {
  scene *s = tsup_load("{\"type\": \"scene\", \"s\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"mask\","
                       " \"opacity\": 0.3, \"b\": {\"type\": \"roughplastic\", \"alpha\": 0.2}}}}",
                       NULL);
  REQUIRE(s, "scene");
  chi2_bsdf c = {s->shapes[0]->bsdf, tb_si_with(tb_dir_deg(40, 10))};
  chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
  cfg.sample_count = 200000;
  cfg.ires = 8;
  chi2_result r = chi2_run(&cfg, sample_smooth, chi2_bsdf_pdf, &c);
  CHECK(r.passed, "chi2: p = %g: %s", r.p_value, r.reason);
  /* The pass-through: u1 >= alpha gives -wi with pdf 1 - alpha, weight 1. */
  bsdf_sample bs;
  color w = c.b->ops->sample(c.b, &c.si, 0.9, v2(0.5, 0.5), &bs);
  CHECK(bs.sampled_type == BSDF_DELTA_TRANSMISSION && fabs(bs.pdf - 0.7) < 1e-15 && w.c[0] == 1.0 &&
            bs.wo.x == -c.si.wi.x && bs.wo.z == -c.si.wi.z,
        "pass-through sample");
  scene_free(s);
}

static void test_xml_and_bad_input(void) {
  const char *xml = "<scene version=\"3.0.0\"><shape type=\"rectangle\"><bsdf type=\"mask\">"
                    "<float name=\"opacity\" value=\"0.2\"/><bsdf type=\"plastic\"/></bsdf></shape></scene>";
  scene *s = tsup_load(xml, NULL);
  CHECK(s != NULL, "XML mask");
  scene_free(s);
  const char *bad[] = {
      "{\"type\": \"mask\", \"opacity\": 0.5}",
      "{\"type\": \"mask\", \"opacity\": 2, \"b\": {\"type\": \"diffuse\"}}",
      "{\"type\": \"mask\", \"a\": {\"type\": \"diffuse\"}, \"b\": {\"type\": \"diffuse\"}}",
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
    CHECK(tsup_refused("{\"type\": \"scene\", \"s\": {\"type\": \"rectangle\", \"bsdf\": %s}}", bad[i]),
          "refused: %s", bad[i]);
}

int main(void) {
  RSW_TEST_RUN(test_half_opaque_halves_the_hit);
  RSW_TEST_RUN(test_chi2);
  RSW_TEST_RUN(test_xml_and_bad_input);
  RSW_TEST_END("test_mask");
}
