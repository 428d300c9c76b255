/* `blendbsdf` (bsdfs/blendbsdf.c): chi-square tests of sample() against
 * pdf() for blends of smooth lobes and of a smooth with a delta lobe
 * (delta samples left out of the histogram; their mass is 1 - the pdf's
 * integral), eval and pdf the weighted mixtures of the components', and a
 * render: diffuse 0.2 and 0.8 blended at w = 0.25 is diffuse 0.35 (a plate
 * under a sun, no variance: 1e-5 relative), in JSON and XML.
 * Chi-square: 200,000 samples per run, significance 0.01 with the Sidak
 * correction over the runs of this file; fixed seeds. */
#include <math.h>
#include <stdio.h>

#include "../../support/bsdf_test.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define CHI2_TESTS 9

static scene *bsdf_scene(const char *bsdf_json) {
  char buf[2048];
  snprintf(buf, sizeof buf, "{\"type\": \"scene\", \"s\": {\"type\": \"rectangle\", \"bsdf\": %s}}",
           bsdf_json);
  return tsup_load(buf, NULL);
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
  const char *cases[3] = {
      "{\"type\": \"blendbsdf\", \"weight\": 0.3, \"a\": {\"type\": \"diffuse\"},"
      " \"b\": {\"type\": \"roughconductor\", \"alpha\": 0.2}}",
      "{\"type\": \"blendbsdf\", \"weight\": 0.7, \"bsdf_0\": {\"type\": \"roughplastic\", \"alpha\": 0.3},"
      " \"bsdf_1\": {\"type\": \"diffuse\", \"reflectance\": 0.9}}",
      "{\"type\": \"blendbsdf\", \"weight\": 0.5, \"x\": {\"type\": \"conductor\"}, \"y\": {\"type\": "
      "\"diffuse\"}}",
  };
  const double th[3] = {5, 45, 75};
  for (int i = 0; i < 3; i++) {
    scene *s = bsdf_scene(cases[i]);
    REQUIRE(s, "scene %d", i);
    for (int k = 0; k < 3; k++) {
      chi2_bsdf c = {s->shapes[0]->bsdf, tb_si_with(tb_dir_deg(th[k], 40))};
      chi2_config cfg = chi2_defaults(CHI2_SPHERE, 3);
      cfg.sample_count = 200000;
      cfg.test_count = CHI2_TESTS;
      cfg.ires = 8;
      chi2_result r = chi2_run(&cfg, sample_smooth, chi2_bsdf_pdf, &c);
      CHECK(r.passed, "chi2 case %d theta %g: p = %g: %s", i, th[k], r.p_value, r.reason);
    }
    scene_free(s);
  }
}

/* eval and pdf are the mixtures; a delta sample keeps its weight and gets
 * its pick probability in its pdf. */
static void test_mixture(void) {
  scene *s = bsdf_scene("{\"type\": \"blendbsdf\", \"weight\": 0.25,"
                        " \"bsdf_0\": {\"type\": \"diffuse\", \"reflectance\": 0.2},"
                        " \"bsdf_1\": {\"type\": \"roughconductor\", \"alpha\": 0.3}}");
  scene *a = bsdf_scene("{\"type\": \"diffuse\", \"reflectance\": 0.2}");
  scene *b = bsdf_scene("{\"type\": \"roughconductor\", \"alpha\": 0.3}");
  REQUIRE(s && a && b, "scenes");
  const bsdf *m = s->shapes[0]->bsdf, *f0 = a->shapes[0]->bsdf, *f1 = b->shapes[0]->bsdf;
  surface_interaction si = tb_si_with(tb_dir_deg(30, 0));
  for (double t = 1; t < 90; t += 7) {
    vec3 wo = tb_dir_deg(t, 170);
    CHECK_REL(m->ops->eval(m, &si, wo).c[1],
              0.75 * f0->ops->eval(f0, &si, wo).c[1] + 0.25 * f1->ops->eval(f1, &si, wo).c[1], 1e-12);
    CHECK_REL(m->ops->pdf(m, &si, wo), 0.75 * f0->ops->pdf(f0, &si, wo) + 0.25 * f1->ops->pdf(f1, &si, wo),
              1e-12);
  }
  scene_free(s), scene_free(a), scene_free(b);
  s = bsdf_scene("{\"type\": \"blendbsdf\", \"weight\": 0.4, \"bsdf_0\": {\"type\": \"diffuse\"},"
                 " \"bsdf_1\": {\"type\": \"conductor\"}}");
  REQUIRE(s, "scene");
  m = s->shapes[0]->bsdf;
  bsdf_sample bs;
  color w = m->ops->sample(m, &si, 0.1, v2(0.5, 0.5), &bs);
  CHECK(bs.sampled_type == BSDF_DELTA_REFLECTION && fabs(bs.pdf - 0.4) < 1e-15, "delta pick: pdf %g", bs.pdf);
  CHECK_REL(w.c[0], 1.0, 1e-12);
  CHECK((m->flags & (BSDF_DELTA_REFLECTION | BSDF_DIFFUSE_REFLECTION)) ==
            (BSDF_DELTA_REFLECTION | BSDF_DIFFUSE_REFLECTION),
        "flags are the union");
  scene_free(s);
}

static void test_render_json_xml(void) {
  const double want = 0.35 / RSW_PI; /* rho E / pi, sun at the zenith */
  const char *js =
      "{\"type\": \"scene\","
      " \"sensor\": {\"type\": \"radiancemeter\", \"origin\": [0.2, 0.1, 1], \"direction\": [0, 0, -1],"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\", \"max_depth\": 2},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1]},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"blendbsdf\", \"weight\": 0.25,"
      "   \"bsdf_0\": {\"type\": \"diffuse\", \"reflectance\": 0.2},"
      "   \"bsdf_1\": {\"type\": \"diffuse\", \"reflectance\": 0.8}}}}";
  const char *xml =
      "<scene version=\"3.0.0\">"
      " <sensor type=\"radiancemeter\"><point name=\"origin\" value=\"0.2, 0.1, 1\"/>"
      "  <vector name=\"direction\" value=\"0, 0, -1\"/>"
      "  <film type=\"hdrfilm\"><integer name=\"width\" value=\"1\"/>"
      "   <integer name=\"height\" value=\"1\"/><rfilter type=\"box\"/></film></sensor>"
      " <integrator type=\"path\"><integer name=\"max_depth\" value=\"2\"/></integrator>"
      " <emitter type=\"directional\"><vector name=\"direction\" value=\"0, 0, -1\"/></emitter>"
      " <shape type=\"rectangle\"><bsdf type=\"blendbsdf\"><float name=\"weight\" value=\"0.25\"/>"
      "  <bsdf type=\"diffuse\"><float name=\"reflectance\" value=\"0.2\"/></bsdf>"
      "  <bsdf type=\"diffuse\"><float name=\"reflectance\" value=\"0.8\"/></bsdf>"
      " </bsdf></shape></scene>";
  const char *docs[2] = {js, xml};
  for (int i = 0; i < 2; i++) {
    scene *s = tsup_load(docs[i], "mono");
    REQUIRE(s, "%s scene", i ? "XML" : "JSON");
    film_image img;
    REQUIRE(tsup_render(s, 4, 1, 1, &img), "render");
    CHECK_REL(img.data[0], want, 1e-5);
    film_image_free(&img);
    scene_free(s);
  }
}

static void test_bad_input(void) {
  const char *bad[] = {
      "{\"type\": \"blendbsdf\", \"a\": {\"type\": \"diffuse\"}, \"b\": {\"type\": \"diffuse\"}}",
      "{\"type\": \"blendbsdf\", \"weight\": 1.5, \"a\": {\"type\": \"diffuse\"}, \"b\": {\"type\": "
      "\"diffuse\"}}",
      "{\"type\": \"blendbsdf\", \"weight\": 0.5, \"a\": {\"type\": \"diffuse\"}}",
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
    CHECK(tsup_refused("{\"type\": \"scene\", \"s\": {\"type\": \"rectangle\", \"bsdf\": %s}}", bad[i]),
          "refused: %s", bad[i]);
}

int main(void) {
  RSW_TEST_RUN(test_chi2);
  RSW_TEST_RUN(test_mixture);
  RSW_TEST_RUN(test_render_json_xml);
  RSW_TEST_RUN(test_bad_input);
  RSW_TEST_END("test_blendbsdf");
}
