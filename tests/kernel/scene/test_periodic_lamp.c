/* Under `periodic`, a surface emitter reaching past the column counts only
 * with its part inside the column (scene/periodic.h: geometry outside the
 * column is not seen); light sampling of the part outside used to add it a
 * second time through wrapped shadow rays.
 *
 * Scene: the column [-1, 1]^2, a Lambertian soil (rho 0.5) at z = 0, a
 * downward-facing rectangle lamp of radiance 1 at z = 2 scaled S x S, a
 * radiancemeter at z = 1 looking down, path max_depth 2 (emitter hits and
 * one bounce). For any S >= 1 the column's lamp tiles an infinite plane, so
 * the soil's irradiance is pi and its radiance rho = 0.5 exactly, as long
 * as the lamp covers the column. Checked within 3 standard errors over 16
 * seeds, for S = 1 (the lamp is exactly the cell), and 1.5, 3 and 10
 * shifted off centre by (0.3, -0.2). Before the fix: +31 % at S = 3. */
#include <math.h>
#include <stdio.h>

#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define SEEDS 16
#define SPP   8192

static void lamp_case(double S, double dx, double dy) {
  char text[2048];
  snprintf(text, sizeof text,
           "{\"type\": \"scene\", \"periodic\": {\"type\": \"periodic\", \"min\": [-1, -1], \"max\": [1, 1]},"
           " \"integrator\": {\"type\": \"path\", \"max_depth\": 2},"
           " \"soil\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [1, 1, 1]}],"
           "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}},"
           " \"lamp\": {\"type\": \"rectangle\", \"flip_normals\": true,"
           "   \"to_world\": [{\"scale\": [%.17g, %.17g, 1]}, {\"translate\": [%.17g, %.17g, 2]}],"
           "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0},"
           "   \"emitter\": {\"type\": \"area\", \"radiance\": 1}},"
           " \"meter\": {\"type\": \"radiancemeter\", \"origin\": [0.1, 0.2, 1], \"direction\": [0, 0, -1],"
           "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}",
           S, S, dx, dy);
  scene *s = tsup_load(text, "mono");
  REQUIRE(s, "scene S = %g loads", S);
  double sum = 0, sum2 = 0;
  for (int k = 0; k < SEEDS; k++) {
    film_image img = {0};
    REQUIRE(tsup_render(s, SPP, 100 + k, 2, &img), "render");
    double v = img.data[0];
    sum += v, sum2 += v * v;
    film_image_free(&img);
  }
  double m = sum / SEEDS, se = sqrt(fmax(0, (sum2 - sum * sum / SEEDS) / (SEEDS - 1)) / SEEDS);
  printf("  lamp %gx the cell: L = %.5f +- %.5f (expected 0.5)\n", S, m, se);
  CHECK(fabs(m - 0.5) <= 3 * se + 1e-6, "lamp %gx the cell: %.5f +- %.5f, expected 0.5", S, m, se);
  scene_free(s);
}

static void test_lamp_past_the_column(void) {
  lamp_case(1, 0, 0); /* exactly the cell */
  lamp_case(1.5, 0.3, -0.2);
  lamp_case(3, 0.3, -0.2);
  lamp_case(10, 0.3, -0.2);
}

int main(void) {
  RSW_TEST_RUN(test_lamp_past_the_column);
  RSW_TEST_END("test_periodic_lamp");
}
