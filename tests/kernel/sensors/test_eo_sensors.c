/* Earth-observation sensors (docs/kernel-conventions.md#mdistant-and-mradiancemeter,
 * #distantflux): mdistant,
 * distantflux and mradiancemeter against closed forms, and the per-pixel
 * viewing angles of the distant-family films.
 *
 * Tolerances: zero-variance estimators (Lambertian plate under a
 * directional emitter seen with a flat shape target) to 1e-5 relative
 * (float32 films, single-precision ray tracing). distantflux sums are
 * Monte Carlo (directions are jittered within pixels): K independent renders
 * give a mean and its standard error; the mean must be within 1e-3 relative
 * of the closed form AND within 3 standard errors (+1e-5 for float32
 * rounding), and 3 standard errors must be below 1e-3 (so the 1e-3 check
 * means something). Fixed seeds. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../server/kernel/core/warp.h"
#include "../../support/test.h"
#include "../../support/tsup.h"
#include "image_exr.h"

RSW_TEST_DEFINE_GLOBALS

#define PI    3.14159265358979323846
#define RHO   0.5
#define COS30 0.86602540378443864676

/* Plate (rectangle [-1,1]^2) with `bsdf` under a directional emitter of
 * irradiance E travelling along sun_dir, seen by `sensor`. */
static scene *plate_scene(const char *sensor_json, const char *bsdf_json, const char *sun_dir, double E) {
  char buf[4096];
  snprintf(buf, sizeof buf,
           "{\"type\": \"scene\","
           " \"sensor\": %s,"
           " \"integrator\": {\"type\": \"path\"},"
           " \"sun\": {\"type\": \"directional\", \"direction\": %s, \"irradiance\": %.17g},"
           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": %s}}",
           sensor_json, sun_dir, E, bsdf_json);
  return tsup_load(buf, NULL);
}

static double film_sum(const film_image *img) {
  double s = 0;
  for (int i = 0; i < img->width * img->height; i++) s += img->data[(size_t)i * img->channels];
  return s;
}

/* ---- mdistant ------------------------------------------------------------ */

#define MD_DIRS "0 0 -1, 0.5 0 -0.8660254037844386, -0.3,0.4,-0.866  0.1 -0.7 -0.5"
static const double md_dirs[4][3] = {
    {0, 0, -1}, {0.5, 0, -0.8660254037844386}, {-0.3, 0.4, -0.866}, {0.1, -0.7, -0.5}};

static void test_mdistant_lambertian_exact(void) {
  scene *s =
      plate_scene("{\"type\": \"mdistant\", \"directions\": \"" MD_DIRS "\","
                  " \"target\": {\"type\": \"rectangle\"},"
                  " \"sampler\": {\"type\": \"independent\", \"sample_count\": 32},"
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 1,"
                  "  \"rfilter\": {\"type\": \"box\"}}}",
                  "{\"type\": \"diffuse\", \"reflectance\": 0.5}", "[0.5, 0, -0.86602540378443864676]", 2.0);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 1, 0, &img), "render");
  double expect = RHO * 2.0 * COS30 / PI;
  for (int i = 0; i < 4; i++)
    for (int c = 0; c < img.channels; c++) CHECK_REL(img.data[i * img.channels + c], expect, 1e-5);
  /* Angles: each pixel carries its exitant direction -d_i (world). */
  REQUIRE(img.angles, "mdistant film has angles");
  for (int i = 0; i < 4; i++) {
    double x = -md_dirs[i][0], y = -md_dirs[i][1], z = -md_dirs[i][2];
    double len = sqrt(x * x + y * y + z * z);
    double zen = acos(z / len) * 180 / PI, az = atan2(y, x) * 180 / PI;
    if (az < 0) az += 360;
    CHECK(fabs(img.angles[2 * i] - zen) < 1e-9, "dir %d zenith %.12g vs %.12g", i, img.angles[2 * i], zen);
    CHECK(fabs(img.angles[2 * i + 1] - az) < 1e-9, "dir %d azimuth %.12g vs %.12g", i, img.angles[2 * i + 1],
          az);
  }
  film_image_free(&img);
  scene_free(s);
}

static void test_mdistant_errors(void) {
  /* Film size must be N x 1. */
  scene *s = plate_scene("{\"type\": \"mdistant\", \"directions\": \"" MD_DIRS "\","
                         " \"film\": {\"type\": \"hdrfilm\", \"width\": 3, \"height\": 1}}",
                         "{\"type\": \"diffuse\"}", "[0, 0, -1]", 1.0);
  CHECK(s == NULL, "4 directions with a 3x1 film must be refused");
  scene_free(s);
  s = plate_scene("{\"type\": \"mdistant\", \"directions\": \"" MD_DIRS "\","
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 2}}",
                  "{\"type\": \"diffuse\"}", "[0, 0, -1]", 1.0);
  CHECK(s == NULL, "a 4x2 film must be refused");
  scene_free(s);
  s = plate_scene("{\"type\": \"mdistant\", \"directions\": \"0 0 -1 1\","
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}",
                  "{\"type\": \"diffuse\"}", "[0, 0, -1]", 1.0);
  CHECK(s == NULL, "4 numbers (not 3N) must be refused");
  scene_free(s);
  s = plate_scene("{\"type\": \"mdistant\", \"directions\": \"0 0 -1\", \"to_world\": [{\"scale\": 2}],"
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}",
                  "{\"type\": \"diffuse\"}", "[0, 0, -1]", 1.0);
  CHECK(s == NULL, "to_world must be refused");
  scene_free(s);
}

/* ---- mradiancemeter ------------------------------------------------------ */

static void test_mradiancemeter_two_meters(void) {
  scene *s =
      plate_scene("{\"type\": \"mradiancemeter\", \"origins\": \"0 0 2, 0.5 0.3 1\","
                  " \"directions\": \"0 0 -1, -0.2 0.1 -1\","
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 2, \"height\": 1,"
                  "  \"rfilter\": {\"type\": \"box\"}}}",
                  "{\"type\": \"diffuse\", \"reflectance\": 0.5}", "[0.5, 0, -0.86602540378443864676]", 1.0);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 4, 1, 0, &img), "render");
  double expect = RHO * COS30 / PI;
  CHECK_REL(img.data[0], expect, 1e-5);
  CHECK_REL(img.data[img.channels], expect, 1e-5);
  film_image_free(&img);
  scene_free(s);
  /* A meter looking away from the plate sees nothing: pixels are separate. */
  s = plate_scene("{\"type\": \"mradiancemeter\", \"origins\": \"0 0 2, 0 0 2\","
                  " \"directions\": \"0 0 -1, 0 0 1\","
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 2, \"height\": 1,"
                  "  \"rfilter\": {\"type\": \"box\"}}}",
                  "{\"type\": \"diffuse\", \"reflectance\": 0.5}", "[0.5, 0, -0.86602540378443864676]", 1.0);
  REQUIRE(s, "scene");
  REQUIRE(tsup_render(s, 4, 1, 0, &img), "render");
  CHECK_REL(img.data[0], expect, 1e-5);
  CHECK(img.data[img.channels] == 0.0f, "second meter looks up: %g", img.data[img.channels]);
  film_image_free(&img);
  scene_free(s);
  s = plate_scene("{\"type\": \"mradiancemeter\", \"origins\": \"0 0 2\", \"directions\": \"0 0 -1, 0 0 1\","
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 2, \"height\": 1}}",
                  "{\"type\": \"diffuse\"}", "[0, 0, -1]", 1.0);
  CHECK(s == NULL, "1 origin, 2 directions must be refused");
  scene_free(s);
}

/* ---- distantflux --------------------------------------------------------- */

/* K renders (seeds 1..K) of sensor 0; mean and standard error of the film
 * sum. */
static void sum_stats(scene *s, uint32_t spp, int K, double *mean, double *sem) {
  double a = 0, a2 = 0;
  for (int k = 0; k < K; k++) {
    film_image img;
    REQUIRE(tsup_render(s, spp, 1000 + (uint64_t)k, 0, &img), "render");
    double v = film_sum(&img);
    a += v;
    a2 += v * v;
    film_image_free(&img);
  }
  *mean = a / K;
  *sem = sqrt(fmax(a2 / K - *mean * *mean, 0) / (K - 1));
}

static void check_flux(scene *s, uint32_t spp, int K, double expect, const char *what) {
  double m = 0, sem = 0;
  sum_stats(s, spp, K, &m, &sem);
  double rel = fabs(m - expect) / expect;
  printf("  %s: sum %.9g expect %.9g rel %.3g 3sigma/expect %.3g\n", what, m, expect, rel, 3 * sem / expect);
  CHECK(rel <= 1e-3, "%s: pixel sum %.9g vs %.9g (rel %.3g > 1e-3)", what, m, expect, rel);
  CHECK(fabs(m - expect) <= 3 * sem + 1e-5 * expect, "%s: sum %.9g vs %.9g beyond 3 sigma (%.3g)", what, m,
        expect, 3 * sem);
  CHECK(3 * sem <= 1e-3 * expect, "%s: 3 sigma %.3g too large for a 1e-3 test", what, 3 * sem);
}

static void test_distantflux_lambertian(void) {
  scene *s =
      plate_scene("{\"type\": \"distantflux\", \"target\": {\"type\": \"rectangle\"},"
                  " \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16,"
                  "  \"rfilter\": {\"type\": \"box\"}}}",
                  "{\"type\": \"diffuse\", \"reflectance\": 1.0}", "[0.5, 0, -0.86602540378443864676]", 1.7);
  REQUIRE(s, "scene");
  check_flux(s, 256, 4, 1.7 * COS30, "lambertian");
  /* Per-pixel angles from the local hemisphere vector, as hdistant. */
  film_image img;
  REQUIRE(tsup_render(s, 1, 1, 0, &img), "render");
  REQUIRE(img.angles, "distantflux film has angles");
  vec3 v = warp_square_to_uniform_hemisphere(v2(2.5 / 16, 11.5 / 16));
  double az = atan2(v.y, v.x) * 180 / PI;
  if (az < 0) az += 360;
  size_t i = 2 * (11 * 16 + 2);
  CHECK(fabs(img.angles[i] - acos(v.z) * 180 / PI) < 1e-9, "zenith %.9g", img.angles[i]);
  CHECK(fabs(img.angles[i + 1] - az) < 1e-9, "azimuth %.9g vs %.9g", img.angles[i + 1], az);
  film_image_free(&img);
  scene_free(s);
}

static void test_distantflux_roughconductor(void) {
  /* Default roughconductor (Beckmann alpha 0.1, material none: Fresnel 1)
   * at 35 degrees: its albedo is 1 to within 1e-4, so the radiosity is
   * E cos 35. The lobe covers a few pixels: a stratified sampler keeps
   * the estimate's error well under 1e-3. */
  const double th = 35.0 * PI / 180;
  char sun[128];
  snprintf(sun, sizeof sun, "[%.17g, 0, %.17g]", sin(th), -cos(th));
  scene *s = plate_scene("{\"type\": \"distantflux\", \"target\": {\"type\": \"rectangle\"},"
                         " \"sampler\": {\"type\": \"stratified\", \"sample_count\": 1024},"
                         " \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16,"
                         "  \"rfilter\": {\"type\": \"box\"}}}",
                         "{\"type\": \"roughconductor\"}", sun, 1.0);
  REQUIRE(s, "scene");
  check_flux(s, 0, 4, cos(th), "roughconductor");
  scene_free(s);
}

static void test_distantflux_checkerboard(void) {
  /* Checkerboard 0.5/1 (4x4 checks over the plate) at normal incidence:
   * radiosity 0.75 E. The estimate's error comes from the aperture samples
   * straddling check edges: a stratified sampler makes it fall as
   * N^-3/4 (4096 spp: 3 sigma about 2e-4 relative). */
  scene *s =
      plate_scene("{\"type\": \"distantflux\", \"target\": {\"type\": \"rectangle\"},"
                  " \"sampler\": {\"type\": \"stratified\", \"sample_count\": 4096},"
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16,"
                  "  \"rfilter\": {\"type\": \"box\"}}}",
                  "{\"type\": \"diffuse\", \"reflectance\": {\"type\": \"checkerboard\", \"color0\": 0.5,"
                  "  \"color1\": 1.0, \"to_uv\": [{\"scale\": [4, 4, 1]}]}}",
                  "[0, 0, -1]", 1.3);
  REQUIRE(s, "scene");
  check_flux(s, 0, 4, 0.75 * 1.3, "checkerboard");
  scene_free(s);
}

/* ---- per-pixel angles ---------------------------------------------------- */

static void test_hdistant_angles_and_exr(void) {
  scene *s = plate_scene("{\"type\": \"hdistant\", \"id\": \"hd\", \"target\": [0, 0, 0],"
                         " \"film\": {\"type\": \"hdrfilm\", \"width\": 3, \"height\": 3,"
                         "  \"rfilter\": {\"type\": \"box\"}}}",
                         "{\"type\": \"diffuse\"}", "[0, 0, -1]", 1.0);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 1, 1, 0, &img), "render");
  REQUIRE(img.angles, "hdistant film has angles");
  /* Centre pixel: the zenith. */
  CHECK(fabs(img.angles[2 * 4]) < 1e-12, "centre zenith %.9g", img.angles[2 * 4]);
  /* Top-left pixel (ix 0, iy 0): centre u = (1/6, 1/6), concentric radius
   * 2/3 along (-1, -1): zenith acos(1 - 4/9), azimuth 225. */
  vec3 v = warp_square_to_uniform_hemisphere(v2(1.0 / 6, 1.0 / 6));
  CHECK(fabs(img.angles[0] - acos(v.z) * 180 / PI) < 1e-9, "corner zenith %.12g", img.angles[0]);
  CHECK(fabs(img.angles[0] - acos(1.0 - 4.0 / 9) * 180 / PI) < 1e-9, "corner zenith %.12g", img.angles[0]);
  CHECK(fabs(img.angles[1] - 225.0) < 1e-9, "corner azimuth %.12g", img.angles[1]);
  /* Top-right (ix 2, iy 0): local (+x, -y): azimuth 315; bottom-left
   * (ix 0, iy 2): (-x, +y): 135; middle-right (ix 2, iy 1): +x: 0. */
  CHECK(fabs(img.angles[2 * 2 + 1] - 315.0) < 1e-9, "top-right azimuth %.12g", img.angles[2 * 2 + 1]);
  CHECK(fabs(img.angles[2 * 6 + 1] - 135.0) < 1e-9, "bottom-left azimuth %.12g", img.angles[2 * 6 + 1]);
  CHECK(fabs(img.angles[2 * 5 + 1]) < 1e-9, "middle-right azimuth %.12g", img.angles[2 * 5 + 1]);
  CHECK(fabs(img.angles[2 * 5] - 180 / PI * acos(1.0 - 4.0 / 9)) < 1e-9, "middle-right zenith %.12g",
        img.angles[2 * 5]);

  /* The EXR carries them as comma-separated, row-major strings. */
  char path[] = "/tmp/rsw-angles-XXXXXX.exr";
  int fd = mkstemps(path, 4);
  REQUIRE(fd >= 0, "temp file");
  close(fd);
  rsw_err err = {0};
  REQUIRE(film_image_write_exr(&img, path, "hd", &err) == RSW_OK, "write: %s", err.msg);
  exr_image ex;
  REQUIRE(exr_read_image(path, &ex, &err) == RSW_OK, "read: %s", err.msg);
  const char *zen = NULL, *az = NULL;
  for (size_t k = 0; k < ex.n_meta; k++) {
    if (strcmp(ex.meta_keys[k], "raysweep:zenith_deg") == 0) zen = ex.meta_values[k];
    if (strcmp(ex.meta_keys[k], "raysweep:azimuth_deg") == 0) az = ex.meta_values[k];
  }
  CHECK(zen && az, "angle attributes present");
  if (zen && az) {
    const char *p = zen, *q = az;
    int n = 0;
    for (; n < 9; n++) {
      char *e1, *e2;
      double z = strtod(p, &e1), a = strtod(q, &e2);
      CHECK(e1 != p && e2 != q, "value %d parses", n);
      CHECK(fabs(z - img.angles[2 * n]) < 1e-6 && fabs(a - img.angles[2 * n + 1]) < 1e-6,
            "pixel %d: %g %g vs %g %g", n, z, a, img.angles[2 * n], img.angles[2 * n + 1]);
      p = e1;
      q = e2;
      if (*p == ',') p++;
      if (*q == ',') q++;
    }
    CHECK(*p == '\0' && *q == '\0', "exactly 9 values each");
  }
  exr_image_free(&ex);
  remove(path);
  film_image_free(&img);
  scene_free(s);
}

static void test_distant_angles(void) {
  scene *s = plate_scene("{\"type\": \"distant\", \"direction\": [0, -1, -1],"
                         " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}",
                         "{\"type\": \"diffuse\"}", "[0, 0, -1]", 1.0);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 1, 1, 0, &img), "render");
  REQUIRE(img.angles, "distant film has angles");
  CHECK(fabs(img.angles[0] - 45.0) < 1e-9 && fabs(img.angles[1] - 90.0) < 1e-9, "exitant (0,1,1): %g %g",
        img.angles[0], img.angles[1]);
  film_image_free(&img);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_mdistant_lambertian_exact);
  RSW_TEST_RUN(test_mdistant_errors);
  RSW_TEST_RUN(test_mradiancemeter_two_meters);
  RSW_TEST_RUN(test_hdistant_angles_and_exr);
  RSW_TEST_RUN(test_distant_angles);
  RSW_TEST_RUN(test_distantflux_lambertian);
  RSW_TEST_RUN(test_distantflux_checkerboard);
  RSW_TEST_RUN(test_distantflux_roughconductor);
  RSW_TEST_END("test_eo_sensors");
}
