/* The side a one-sided reflecting BSDF samples on: every valid sample
 * (pdf > 0, weight not black) of a BSDF whose lobes are reflections only,
 * and which is not two-sided, has wo.z >= 0 in the shading frame, from
 * sample() and from sample_batch(), for incident directions on both sides
 * and at grazing angles. The path integrator relies on it to end a path
 * whose continuation cannot meet anything without sampling it
 * (integrators/path.c continuation_escapes). Every BSDF plugin of the
 * registry has a case here, so a new plugin must be looked at. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../../../server/kernel/core/rng.h"
#include "../../../server/kernel/scene/loader.h"
#include "../../../server/kernel/scene/scene.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

/* Every BSDF plugin (some with several documents), and whether its lobes
 * are reflections on one side only. */
static const struct {
  const char *name, *json;
  bool one_sided_reflection;
} CASES[] = {
    {"diffuse", "{\"type\": \"diffuse\", \"reflectance\": 0.6}", true},
    {"conductor", "{\"type\": \"conductor\", \"material\": \"Au\"}", true},
    {"roughconductor", "{\"type\": \"roughconductor\", \"alpha\": 0.3}", true},
    {"roughconductor", "{\"type\": \"roughconductor\", \"alpha\": 0.05, \"distribution\": \"ggx\"}", true},
    {"roughconductor", "{\"type\": \"roughconductor\", \"alpha_u\": 0.6, \"alpha_v\": 0.1}", true},
    {"roughconductor", "{\"type\": \"roughconductor\", \"alpha\": 0.4, \"sample_visible\": false}", true},
    {"plastic", "{\"type\": \"plastic\"}", true},
    {"roughplastic", "{\"type\": \"roughplastic\", \"alpha\": 0.2}", true},
    {"rpv", "{\"type\": \"rpv\", \"rho_0\": 0.1, \"k\": 0.7, \"g\": -0.15, \"rho_c\": 0.3}", true},
    {"rtls", "{\"type\": \"rtls\"}", true},
    {"hapke", "{\"type\": \"hapke\"}", true},
    {"maignan", "{\"type\": \"maignan\"}", true},
    {"mqdiffuse",
     "{\"type\": \"mqdiffuse\", \"grid\": {\"type\": \"gridvolume\", \"shape\": [2, 2, 2],"
     " \"data\": [0.1, 0.5, 0.2, 0.9, 0.3, 0.4, 0.8, 0.05]}}",
     true},
    {"ocean_legacy",
     "{\"type\": \"ocean_legacy\", \"wavelength\": 550, \"wind_speed\": 5, \"wind_direction\": 30}", true},
    {"blendbsdf",
     "{\"type\": \"blendbsdf\", \"weight\": 0.3, \"a\": {\"type\": \"diffuse\"},"
     " \"b\": {\"type\": \"roughconductor\", \"alpha\": 0.2}}",
     true},
    {"selectbsdf",
     "{\"type\": \"selectbsdf\", \"indices\": {\"type\": \"checkerboard\", \"color0\": 0, \"color1\": 1},"
     " \"a\": {\"type\": \"diffuse\"}, \"b\": {\"type\": \"conductor\"}}",
     true},
    {"twosided", "{\"type\": \"twosided\", \"a\": {\"type\": \"diffuse\"}}", false},
    {"bilambertian", "{\"type\": \"bilambertian\", \"reflectance\": 0.4, \"transmittance\": 0.45}", false},
    {"dielectric", "{\"type\": \"dielectric\"}", false},
    {"null", "{\"type\": \"null\"}", false},
    {"mask", "{\"type\": \"mask\", \"opacity\": 0.5, \"bsdf\": {\"type\": \"diffuse\"}}", false},
};

RSW_TEST_DEFINE_GLOBALS

static bool listed(const char *name) {
  for (size_t i = 0; i < sizeof CASES / sizeof CASES[0]; i++)
    if (strcmp(CASES[i].name, name) == 0) return true;
  return false;
}

static void test_every_bsdf_listed(void) {
  for (size_t i = 0; rsw_plugins[i]; i++)
    if (rsw_plugins[i]->cls == CLS_BSDF)
      CHECK(listed(rsw_plugins[i]->name), "BSDF plugin %s has no case here", rsw_plugins[i]->name);
}

/* Local wi: both hemispheres, grazing ones and the poles included. */
static vec3 incident(pcg32 *r, int k) {
  if (k == 0) return v3(0, 0, 1);
  if (k == 1) return v3(0, 0, -1);
  double z = k % 5 == 0 ? 1e-7 * (k % 2 ? 1 : -1) : 2.0 * pcg32_next_double(r) - 1.0;
  double phi = 2.0 * RSW_PI * pcg32_next_double(r), s = sqrt(fmax(0.0, 1.0 - z * z));
  return v3(s * cos(phi), s * sin(phi), z);
}

static const unsigned REFLECT = BSDF_DIFFUSE_REFLECTION | BSDF_GLOSSY_REFLECTION | BSDF_DELTA_REFLECTION;

static void check_case(const char *json, bool one_sided) {
  char doc[1024];
  snprintf(doc, sizeof doc,
           "{\"type\": \"scene\", \"integrator\": {\"type\": \"path\"},"
           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": %s}}",
           json);
  scene *s = tsup_load(doc, "mono");
  REQUIRE(s, "%s loads", json);
  const bsdf *b = s->shapes[0]->bsdf;
  bool eligible = !(b->flags & ~REFLECT);
  CHECK(eligible == one_sided, "%s: flags 0x%x, one-sided reflection expected %d", json, b->flags, one_sided);
  if (!eligible) {
    scene_free(s);
    return;
  }
  enum {
    N = 37, /* lanes per batched call: not a multiple of a vector */
    WI = 400
  };
  pcg32 r;
  pcg32_seed(&r, 7, 11);
  long valid = 0, bad = 0;
  for (int k = 0; k < WI; k++) {
    surface_interaction si[N];
    const surface_interaction *sp[N];
    double u1[N];
    vec2 u2[N];
    vec3 wi = incident(&r, k);
    for (int j = 0; j < N; j++) {
      memset(&si[j], 0, sizeof si[j]);
      si[j].sh = (frame){v3(1, 0, 0), v3(0, 1, 0), v3(0, 0, 1)};
      si[j].ng = v3(0, 0, 1);
      si[j].wi = wi;
      si[j].shape = s->shapes[0];
      si[j].uv[0] = pcg32_next_double(&r), si[j].uv[1] = pcg32_next_double(&r);
      sp[j] = &si[j];
      u1[j] = pcg32_next_double(&r);
      u2[j] = v2(pcg32_next_double(&r), pcg32_next_double(&r));
      if (j == 0) u2[j] = v2(0, 0); /* the square's corners and edges */
      if (j == 1) u2[j] = v2(1.0 - 0x1p-32, 1.0 - 0x1p-32);
      if (j == 2) u2[j] = v2(0.5, 0.5);
    }
    bsdf_sample bs[N];
    color w[N];
    for (int pass = 0; pass < 2; pass++) {
      if (pass == 0)
        for (int j = 0; j < N; j++) w[j] = b->ops->sample(b, &si[j], u1[j], u2[j], &bs[j]);
      else if (b->ops->sample_batch)
        b->ops->sample_batch(b, N, sp, u1, u2, bs, w);
      else
        break;
      for (int j = 0; j < N; j++) {
        if (!(bs[j].pdf > 0) || col_is_black(w[j])) continue;
        valid++;
        if (!(bs[j].wo.z >= 0)) {
          if (bad++ < 3)
            printf("  %s: wi (%g %g %g) gives wo (%g %g %g), pdf %g (%s)\n", json, wi.x, wi.y, wi.z,
                   bs[j].wo.x, bs[j].wo.y, bs[j].wo.z, bs[j].pdf, pass ? "sample_batch" : "sample");
        }
      }
    }
  }
  CHECK(valid > WI * N / 4, "%s: %ld valid samples", json, valid);
  CHECK(bad == 0, "%s: %ld of %ld valid samples below the surface", json, bad, valid);
  scene_free(s);
}

static void test_reflections_stay_above(void) {
  for (size_t i = 0; i < sizeof CASES / sizeof CASES[0]; i++)
    check_case(CASES[i].json, CASES[i].one_sided_reflection);
}

int main(void) {
  RSW_TEST_RUN(test_every_bsdf_listed);
  RSW_TEST_RUN(test_reflections_stay_above);
  RSW_TEST_END("test_reflect_side");
}
