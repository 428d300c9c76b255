/* Reconstruction filters `tent` and `lanczos` (films/tent.c, lanczos.c).
 *
 * The weights: eval at known points (tent 1 - |x|/r; Lanczos 1 at 0, zero
 * at the integers, the closed form between), and the integrals (tent: r;
 * Lanczos a = 3: 0.99706, by midpoint sums of the formula here).
 * Through the film: an orthographic camera sees an emitting half-plane
 * whose edge falls on a pixel boundary; with samples uniform over the
 * film, pixel i's value is sum(f L) / sum(f) -> the filter's integral
 * from -r to the edge over its whole integral,
 *   v(d) = int_{-r}^{d} f / int_{-r}^{r} f,  d = signed distance (pixels)
 * from the pixel centre to the edge, on the lit side positive:
 * tent r = 1: v = 1 - (1 - d)^2 / 2 for 0 <= d <= 1 (and 1 - v(-d));
 * Lanczos: v by quadrature of the formula, above 1 next to the edge
 * (ringing). Columns within r + 1 of the film's sides are not checked
 * (their filter support is cut). Tolerance 0.01 (the estimate's noise is
 * ~2e-3 at 16 rows x 256 samples). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static double lanczos_ref(double x, double a) {
  if (fabs(x) >= a) return 0;
  if (x == 0) return 1;
  return a * sin(RSW_PI * x) * sin(RSW_PI * x / a) / (RSW_PI * RSW_PI * x * x);
}

static scene *filter_scene(const char *rf, int w, int h, int spp) {
  char buf[2048];
  /* The half-plane x > 0 (local), seen along +z by a camera spanning
   * x in [-4, 4]: film columns left of W/2 see it. */
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\", \"integrator\": {\"type\": \"path\"},"
      " \"sensor\": {\"type\": \"orthographic\", \"to_world\": [{\"scale\": [4, 4, 1]}],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": %d},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": %d, \"height\": %d, \"pixel_format\": \"luminance\","
      "     \"rfilter\": %s}},"
      " \"lamp\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [50, 50, 1]},"
      "   {\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}}, {\"translate\": [50, 0, 3]}],"
      "   \"emitter\": {\"type\": \"area\", \"radiance\": 1}}}",
      spp, w, h, rf);
  return tsup_load(buf, "mono");
}

static void test_weights(void) {
  scene *s = filter_scene("{\"type\": \"tent\", \"radius\": 1.5}", 8, 8, 1);
  REQUIRE(s, "scene");
  const rfilter *f = s->sensors[0]->film->filter;
  CHECK(f->radius == 1.5, "tent radius %g", f->radius);
  double sum = 0;
  const int N = 300000;
  for (int i = 0; i < N; i++) {
    double x = -f->radius + 2 * f->radius * (i + 0.5) / N;
    sum += f->eval(f, x) * 2 * f->radius / N;
    CHECK(fabs(f->eval(f, x) - fmax(0, 1 - fabs(x) / 1.5)) < 1e-15, "tent at %g", x);
    if (fabs(f->eval(f, x) - fmax(0, 1 - fabs(x) / 1.5)) >= 1e-15) break;
  }
  CHECK_REL(sum, 1.5, 1e-9);
  scene_free(s);

  s = filter_scene("{\"type\": \"lanczos\"}", 8, 8, 1);
  REQUIRE(s, "scene");
  f = s->sensors[0]->film->filter;
  CHECK(f->radius == 3, "lanczos radius %g (lobes 3)", f->radius);
  CHECK(f->eval(f, 0) == 1.0, "lanczos(0) = 1");
  for (int k = 1; k <= 3; k++) CHECK(fabs(f->eval(f, k)) < 1e-15, "lanczos(%d) = %g", k, f->eval(f, k));
  CHECK(f->eval(f, 3.01) == 0 && f->eval(f, -4) == 0, "zero beyond the radius");
  sum = 0;
  for (int i = 0; i < N; i++) {
    double x = -3 + 6.0 * (i + 0.5) / N;
    CHECK_REL(f->eval(f, x), lanczos_ref(x, 3), 1e-12);
    sum += f->eval(f, x) * 6.0 / N;
    if (fabs(f->eval(f, x) - lanczos_ref(x, 3)) > 1e-12 * fabs(lanczos_ref(x, 3)) + 1e-300) break;
  }
  /* int sinc(x) sinc(x/3) over [-3, 3], by a fine midpoint rule on the
   * reference formula (not the plugin). */
  double ref = 0;
  for (int i = 0; i < 4 * N; i++) {
    double x = -3 + 6.0 * (i + 0.5) / (4 * N);
    ref += lanczos_ref(x, 3) * 6.0 / (4 * N);
  }
  CHECK_REL(sum, ref, 1e-6);
  CHECK(fabs(ref - 0.9970553) < 1e-6, "the Lanczos-3 kernel integrates to %.6f (0.99706)", ref);
  scene_free(s);
}

/* v(d) of a 1-D filter g with radius r, by quadrature. */
static double edge_fraction(double (*g)(double, double), double r, double d) {
  const int M = 20000;
  double num = 0, den = 0;
  for (int i = 0; i < M; i++) {
    double x = -r + 2 * r * (i + 0.5) / M, v = g(x, r);
    den += v;
    if (x < d) num += v;
  }
  return num / den;
}

static double tent_ref(double x, double r) {
  return fmax(0, 1 - fabs(x) / r);
}

static void check_edge(const char *rf, double r, double (*g)(double, double), bool expect_ringing) {
  enum {
    W = 32,
    H = 16
  };
  scene *s = filter_scene(rf, W, H, 256);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 11, 2, &img), "render");
  double worst = 0, peak = 0;
  for (int x = (int)ceil(r) + 1; x < W - (int)ceil(r) - 1; x++) {
    double got = 0;
    for (int y = 0; y < H; y++) got += img.data[y * W + x] / H;
    double d = W / 2.0 - (x + 0.5); /* lit side (left) positive */
    double want = edge_fraction(g, r, d);
    worst = fmax(worst, fabs(got - want));
    peak = fmax(peak, got);
  }
  CHECK(worst < 0.01, "%s: edge profile off by %.4f", rf, worst);
  if (expect_ringing) CHECK(peak > 1.01, "%s: no ringing next to the edge (peak %.4f)", rf, peak);
  film_image_free(&img);
  scene_free(s);
}

static double lanczos3(double x, double r) {
  return lanczos_ref(x, r);
}

static void test_edge_profiles(void) {
  check_edge("{\"type\": \"tent\"}", 1.0, tent_ref, false);
  CHECK_ABS(edge_fraction(tent_ref, 1.0, 0.5), 1 - 0.25 / 2, 1e-6); /* the closed form */
  check_edge("{\"type\": \"tent\", \"radius\": 2.5}", 2.5, tent_ref, false);
  check_edge("{\"type\": \"lanczos\"}", 3.0, lanczos3, true);
  check_edge("{\"type\": \"lanczos\", \"lobes\": 2}", 2.0, lanczos3, true);
}

static void test_xml_and_bad_input(void) {
  const char *xml =
      "<scene version=\"3.0.0\"><sensor type=\"perspective\"><film type=\"hdrfilm\">"
      "<integer name=\"width\" value=\"8\"/><integer name=\"height\" value=\"8\"/>"
      "<rfilter type=\"lanczos\"><integer name=\"lobes\" value=\"2\"/></rfilter></film></sensor>"
      "<sensor type=\"perspective\"><film type=\"hdrfilm\"><rfilter type=\"tent\"/></film></sensor>"
      "</scene>";
  scene *s = tsup_load(xml, NULL);
  REQUIRE(s && s->n_sensors == 2, "XML");
  CHECK(s->sensors[0]->film->filter->radius == 2 && s->sensors[1]->film->filter->radius == 1, "radii");
  scene_free(s);
  const char *bad[] = {
      "{\"type\": \"tent\", \"radius\": 0}",
      "{\"type\": \"tent\", \"radius\": 1000}",
      "{\"type\": \"lanczos\", \"lobes\": 0}",
      "{\"type\": \"lanczos\", \"lobes\": 2.5}",
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
    CHECK(tsup_refused("{\"type\": \"scene\", \"sensor\": {\"type\": \"perspective\","
                       " \"film\": {\"type\": \"hdrfilm\", \"rfilter\": %s}}}",
                       bad[i]),
          "refused: %s", bad[i]);
}

int main(void) {
  RSW_TEST_RUN(test_weights);
  RSW_TEST_RUN(test_edge_profiles);
  RSW_TEST_RUN(test_xml_and_bad_input);
  RSW_TEST_END("test_rfilters");
}
