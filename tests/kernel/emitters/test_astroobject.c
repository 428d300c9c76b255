/* astroobject (server/kernel/emitters/astroobject.c,
 * docs/kernel-conventions.md#emitters), the finite solar disc:
 *  - chi-square of sample_direction() against pdf_direction(): on the
 *    sphere for a 30-degree disc, and for the Sun's 0.5358 degrees and a
 *    5-degree disc in the disc's own frame (the direction's offset over
 *    sin r, mapped to the unit disk; density pdf sin^2 r / cos theta);
 *    400,000 samples, alpha 0.01 Sidak-corrected over 3 runs;
 *  - 200,000 sampled directions of the Sun all lie within its angular
 *    radius of the axis, and eval() is E / Omega inside, 0 outside;
 *  - irradiance: a Lambertian plate (rho 0.4) under the Sun at 35 degrees
 *    from zenith, seen by `distant`, reads rho E cos(35) (1 + cos r) / 2 /
 *    pi (the exact cone integral) within 3 sin(r) / sqrt(spp) of the
 *    point sun's value (a bound on the Monte Carlo error: the incidence
 *    cosine varies by at most sin(r) over the disc), and so the point
 *    sun's (`directional`) rho E cos(35) / pi within that plus 5.5e-6;
 *    also for a 20-degree disc, whose (1 + cos r)/2 = 0.9924 the test
 *    resolves; JSON and XML;
 *  - angular_diameter 0 and 180 are refused, as is a second environment
 *    emitter; the parameters are irradiance, to_world, direction,
 *    angular_diameter, sampling_weight. Fixed seeds. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"
#include "kernel/core/rng.h"
#include "kernel/scene/param_table.h"
#include "kernel/scene/params.h"
#include "kernel/scene/scene.h"
#include "kernel/scene/update.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

static scene *sun_scene(double diameter, vec3 towards, bool xml, const char *emitter_extra) {
  char buf[4096];
  if (!xml)
    snprintf(buf, sizeof buf,
             "{\"type\": \"scene\", \"sun\": {\"type\": \"astroobject\", \"angular_diameter\": %.17g,"
             " \"direction\": [%.17g, %.17g, %.17g], \"irradiance\": 1.9}, %s"
             " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 10}],"
             "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.4}},"
             " \"sensor\": {\"type\": \"distant\", \"direction\": [0.1, 0.2, -1], \"target\": [0, 0, 0],"
             "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4096},"
             "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}",
             diameter, towards.x, towards.y, towards.z, emitter_extra ? emitter_extra : "");
  else
    snprintf(
        buf, sizeof buf,
        "<scene version=\"3.0.0\"><emitter type=\"astroobject\"><float name=\"angular_diameter\" "
        "value=\"%.17g\"/><vector name=\"direction\" x=\"%.17g\" y=\"%.17g\" z=\"%.17g\"/>"
        "<float name=\"irradiance\" value=\"1.9\"/></emitter>"
        "<shape type=\"rectangle\"><transform name=\"to_world\"><scale value=\"10\"/></transform>"
        "<bsdf type=\"diffuse\"><float name=\"reflectance\" value=\"0.4\"/></bsdf></shape>"
        "<sensor type=\"distant\"><vector name=\"direction\" x=\"0.1\" y=\"0.2\" z=\"-1\"/>"
        "<point name=\"target\" x=\"0\" y=\"0\" z=\"0\"/><sampler type=\"independent\">"
        "<integer name=\"sample_count\" value=\"4096\"/></sampler><film type=\"hdrfilm\">"
        "<integer name=\"width\" value=\"1\"/><integer name=\"height\" value=\"1\"/></film></sensor></scene>",
        diameter, towards.x, towards.y, towards.z);
  return tsup_load(buf, "mono");
}

typedef struct ctx {
  const emitter *e;
  surface_interaction ref;
  vec3 axis, s, t; /* the disc's frame */
  double sin_r, cos_r;
  bool disk; /* map to the unit disk */
} ctx;

static bool s_fn(void *user, const double *u, vec3 *out, double *weight) {
  ctx *c = user;
  direction_sample ds;
  color v = c->e->ops->sample_direction(c->e, &c->ref, v2(u[0], u[1]), &ds);
  if (!(ds.pdf > 0) || col_is_black(v)) return false;
  *out = c->disk ? v3(v3_dot(ds.d, c->s) / c->sin_r, v3_dot(ds.d, c->t) / c->sin_r, 0) : ds.d;
  *weight = 1;
  return true;
}

static double p_fn(void *user, vec3 p) {
  ctx *c = user;
  vec3 d = p;
  double jac = 1;
  if (c->disk) {
    double q2 = p.x * p.x + p.y * p.y;
    if (q2 > 1) return 0;
    double x = p.x * c->sin_r, y = p.y * c->sin_r, z = sqrt(1 - x * x - y * y);
    d = v3_add(v3_add(v3_scale(c->s, x), v3_scale(c->t, y)), v3_scale(c->axis, z));
    jac = c->sin_r * c->sin_r / z;
  }
  direction_sample ds = {.d = d, .dist = INFINITY};
  return c->e->ops->pdf_direction(c->e, &c->ref, &ds) * jac;
}

static ctx make_ctx(const scene *s, vec3 axis, double diameter, bool disk) {
  ctx c = {.e = s->environment, .disk = disk};
  c.axis = v3_norm(axis);
  coordinate_system(c.axis, &c.s, &c.t);
  c.sin_r = sin(diameter / 2 * PI / 180), c.cos_r = cos(diameter / 2 * PI / 180);
  return c;
}

static void test_chi2(void) {
  vec3 axis = v3(0.3, -0.2, 0.9);
  const double diam[3] = {30, 0.5358, 5};
  for (int k = 0; k < 3; k++) {
    scene *s = sun_scene(diam[k], axis, false, NULL);
    REQUIRE(s && s->environment, "scene");
    ctx c = make_ctx(s, axis, diam[k], k > 0);
    chi2_config cfg = chi2_defaults(k ? CHI2_DISK : CHI2_SPHERE, 2);
    cfg.sample_count = 400000;
    cfg.test_count = 3;
    cfg.ires = 32; /* the cone's edge cuts cells */
    chi2_result r = chi2_run(&cfg, s_fn, p_fn, &c);
    CHECK(r.passed, "diameter %g: %s (chi2 %g, dof %d, p %g)", diam[k], r.reason, r.chi2, r.dof, r.p_value);
    scene_free(s);
  }
}

static void test_in_disc(void) {
  vec3 axis = v3(-0.4, 0.1, 0.7);
  scene *s = sun_scene(0.5358, axis, false, NULL);
  REQUIRE(s && s->environment, "scene");
  const emitter *e = s->environment;
  vec3 a = v3_norm(axis);
  double r = 0.5358 / 2 * PI / 180, omega = 2 * PI * (1 - cos(r)), worst = 0;
  pcg32 rng;
  pcg32_seed(&rng, 3, 3);
  surface_interaction ref = {0};
  int out = 0;
  for (int i = 0; i < 200000; i++) {
    direction_sample ds;
    color v = e->ops->sample_direction(e, &ref, v2(pcg32_next_double(&rng), pcg32_next_double(&rng)), &ds);
    double ang = acos(fmin(1.0, v3_dot(ds.d, a)));
    worst = fmax(worst, ang);
    if (ang > r * (1 + 1e-9)) out++;
    if (i == 0) {
      CHECK_REL(v.c[0], 1.9, 1e-12);
      CHECK_REL(ds.pdf, 1 / omega, 1e-9);
    }
  }
  printf("  widest sampled direction: %.6f deg from the axis (radius %.6f)\n", worst * 180 / PI,
         r * 180 / PI);
  CHECK(out == 0, "%d of 200000 samples outside the disc", out);
  CHECK(worst > 0.95 * r, "the samples fill the disc (widest %g of %g)", worst, r);
  CHECK_REL(e->ops->eval(e, NULL, a).c[0], 1.9 / omega, 1e-12);
  vec3 off = v3_norm(v3_add(a, v3_scale(v3(1, 0, 0), 2 * r)));
  CHECK(e->ops->eval(e, NULL, off).c[0] == 0.0, "nothing outside the disc");
  scene_free(s);
}

static void test_irradiance(void) {
  vec3 towards = v3(sin(35 * PI / 180), 0, cos(35 * PI / 180));
  double point = 0.4 * 1.9 * cos(35 * PI / 180) / PI; /* the point sun's radiance */
  const double diam[2] = {0.5358, 20};
  for (int k = 0; k < 2; k++)
    for (int x = 0; x < 2; x++) {
      scene *s = sun_scene(diam[k], towards, x, NULL);
      REQUIRE(s, "scene");
      film_image img;
      REQUIRE(tsup_render(s, 0, 17, 1, &img), "render");
      double r = diam[k] / 2 * PI / 180, want = point * (1 + cos(r)) / 2;
      /* One pixel: no spread over pixels to estimate an error from. */
      double tol = 3 * point * sin(r) / sqrt(4096.0) + 1e-12;
      printf("  diameter %g (%s): L = %.9g, cone integral %.9g, point sun %.9g\n", diam[k],
             x ? "XML" : "JSON", img.data[0], want, point);
      CHECK(fabs(img.data[0] - want) <= tol, "diameter %g: %.9g vs %.9g (tolerance %.3g)", diam[k],
            img.data[0], want, tol);
      /* The Sun: the point sun's radiance, within the same Monte Carlo
       * bound plus the cone's (1 - cos r) / 2 = 5.5e-6. */
      if (k == 0)
        CHECK(fabs(img.data[0] - point) <= tol + point * (1 - cos(r)) / 2,
              "the Sun: %.9g vs the point sun %.9g", img.data[0], point);
      film_image_free(&img);
      if (k == 0 && x == 0) {
        const char *keys[5] = {"sun.irradiance.value", "sun.to_world", "sun.direction",
                               "sun.angular_diameter", "sun.sampling_weight"};
        for (int q = 0; q < 5; q++) {
          size_t idx;
          rsw_err err = {0};
          CHECK(params_lookup(s, keys[q], &idx, &err) == RSW_OK, "%s: %s", keys[q], err.msg);
        }
      }
      scene_free(s);
    }
}

static void test_refused(void) {
  CHECK(sun_scene(0, v3(0, 0, 1), false, NULL) == NULL, "diameter 0 refused");
  CHECK(sun_scene(180, v3(0, 0, 1), false, NULL) == NULL, "diameter 180 refused");
  CHECK(sun_scene(0.5, v3(0, 0, 1), false, "\"sky\": {\"type\": \"constant\"},") == NULL,
        "a second environment emitter is refused");
}

int main(void) {
  RSW_TEST_RUN(test_chi2);
  RSW_TEST_RUN(test_in_disc);
  RSW_TEST_RUN(test_irradiance);
  RSW_TEST_RUN(test_refused);
  RSW_TEST_END("test_astroobject");
}
