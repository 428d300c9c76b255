/* Closed-form scenes (docs/kernel-conventions.md#sensors, #path): each renders a
 * scene whose answer is known exactly or in distribution.
 *
 * Tolerances: zero-variance estimators (Lambertian plate under a
 * directional emitter, hdistant/distant/radiancemeter with a flat target)
 * are checked to 1e-5 relative (single-precision ray tracing and float32
 * films); Monte Carlo estimates to 3 standard errors of the film mean, with
 * fixed seeds. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include "../support/test.h"
#include "../support/tsup.h"
#include "image_exr.h"

RSW_TEST_DEFINE_GLOBALS

#define RHO   0.5
#define COS30 0.86602540378443864676

/* Lambertian plate (rectangle [-1,1]^2, rho = RHO) under a directional
 * emitter of irradiance 1 from 30 degrees zenith, seen by `sensor`. */
static scene *plate_scene(const char *sensor_json, const char *variant_name) {
  char buf[4096];
  snprintf(buf, sizeof buf,
           "{\"type\": \"scene\","
           " \"sensor\": %s,"
           " \"integrator\": {\"type\": \"path\"},"
           " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0, -0.86602540378443864676],"
           "           \"irradiance\": 1.0},"
           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": %g}}}",
           sensor_json, RHO);
  return tsup_load(buf, variant_name);
}

static const double L_PLATE = RHO * 1.0 * COS30 / 3.14159265358979323846;

static void check_all_pixels(const film_image *img, double expect, double rel) {
  int bad = 0;
  double worst = 0;
  for (int i = 0; i < img->width * img->height * img->channels; i++) {
    double d = fabs(img->data[i] - expect) / expect;
    if (d > worst) worst = d;
    if (d > rel) bad++;
  }
  CHECK(bad == 0, "%d pixels differ from %.9g by more than %g relative (worst %g)", bad, expect, rel, worst);
}

static void check_mean_3sigma(const film_image *img, double expect) {
  for (int c = 0; c < img->channels; c++) {
    double m, sem;
    tsup_stats(img, c, &m, &sem);
    CHECK(fabs(m - expect) <= 3 * sem + 1e-12, "channel %d mean %.6g vs expected %.6g (3 sigma = %.3g)", c, m,
          expect, 3 * sem);
    CHECK(sem < 0.05 * expect, "channel %d: standard error %.3g too large for a meaningful test", c, sem);
  }
}

static void test_hdistant_shape_target_exact(void) {
  scene *s = plate_scene("{\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\"},"
                         " \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
                         " \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16,"
                         "  \"rfilter\": {\"type\": \"box\"}}}",
                         NULL);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 1, 0, &img), "render");
  check_all_pixels(&img, L_PLATE, 1e-5);
  film_image_free(&img);
  scene_free(s);
}

static void test_hdistant_point_target_exact(void) {
  scene *s = plate_scene("{\"type\": \"hdistant\", \"target\": [0.1, -0.2, 0],"
                         " \"sampler\": {\"type\": \"independent\", \"sample_count\": 8},"
                         " \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16,"
                         "  \"rfilter\": {\"type\": \"box\"}}}",
                         "mono");
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 2, 0, &img), "render");
  CHECK(img.channels == 1, "mono film has one channel");
  check_all_pixels(&img, L_PLATE, 1e-5);
  film_image_free(&img);
  scene_free(s);
}

static void test_hdistant_large_target_quarter(void) {
  /* A target twice the plate's size: 1/4 of the rays hit the plate. */
  scene *s = plate_scene("{\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\","
                         "   \"to_world\": [{\"scale\": 2}]},"
                         " \"sampler\": {\"type\": \"independent\", \"sample_count\": 64},"
                         " \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16,"
                         "  \"rfilter\": {\"type\": \"box\"}}}",
                         NULL);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 3, 0, &img), "render");
  check_mean_3sigma(&img, 0.25 * L_PLATE);
  film_image_free(&img);
  scene_free(s);
}

static void test_hdistant_no_target_two_over_pi(void) {
  /* No target: origins on the bounding sphere's cross-section disk in the
   * plane orthogonal to the sensor axis (radius sqrt 2 for the plate), so
   * the hit fraction is 4 / (2 pi) = 2/pi in every direction. */
  scene *s = plate_scene("{\"type\": \"hdistant\","
                         " \"sampler\": {\"type\": \"independent\", \"sample_count\": 64},"
                         " \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16,"
                         "  \"rfilter\": {\"type\": \"box\"}}}",
                         NULL);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 4, 0, &img), "render");
  check_mean_3sigma(&img, 2.0 / 3.14159265358979323846 * L_PLATE);
  film_image_free(&img);
  scene_free(s);
}

static void test_distant_and_radiancemeter_exact(void) {
  /* Eradiate's test: distant looking down at the target point. */
  scene *s = plate_scene("{\"type\": \"distant\", \"direction\": [0.2, 0.1, -1], \"target\": [0.3, 0.3, 0],"
                         " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1,"
                         "  \"rfilter\": {\"type\": \"box\"}}}",
                         NULL);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 4, 5, 0, &img), "render");
  check_all_pixels(&img, L_PLATE, 1e-5);
  film_image_free(&img);
  scene_free(s);
  s = plate_scene("{\"type\": \"radiancemeter\", \"origin\": [0, 0, 3], \"direction\": [0.1, 0, -1],"
                  " \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1,"
                  "  \"rfilter\": {\"type\": \"box\"}}}",
                  NULL);
  REQUIRE(s, "scene");
  REQUIRE(tsup_render(s, 4, 5, 0, &img), "render");
  check_all_pixels(&img, L_PLATE, 1e-5);
  film_image_free(&img);
  scene_free(s);
}

static void test_checkerboard_plate(void) {
  /* Checkerboard 0.5/1.0 plate at normal incidence, shape target: the mean
   * over the target is 0.5 (0.5 + 1) / pi (docs/kernel-conventions.md#hdistant). */
  const char *sc =
      "{\"type\": \"scene\","
      " \"sensor\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\"},"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 64},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1]},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\","
      "   \"reflectance\": {\"type\": \"checkerboard\", \"color0\": 0.5, \"color1\": 1.0,"
      "                     \"to_uv\": [{\"scale\": [4, 4, 1]}]}}}}";
  scene *s = tsup_load(sc, NULL);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 6, 0, &img), "render");
  check_mean_3sigma(&img, 0.5 * 1.5 / 3.14159265358979323846);
  film_image_free(&img);
  scene_free(s);
}

static void test_white_furnace(void) {
  /* A diffuse sphere of reflectance 1 inside a constant environment of
   * radiance L: every pixel sees L, whatever the number of bounces. */
  const char *sc =
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"perspective\", \"fov\": 30,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 32},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16, \"rfilter\": {\"type\": "
      "\"box\"}}},"
      " \"integrator\": {\"type\": \"path\", \"rr_depth\": 5},"
      " \"env\": {\"type\": \"constant\", \"radiance\": 2.5},"
      " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 1.0}}}";
  scene *s = tsup_load(sc, NULL);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 7, 0, &img), "render");
  check_mean_3sigma(&img, 2.5);
  /* Pixel by pixel: none may be far off (would mean a leak or a hole). */
  int bad = 0;
  for (int i = 0; i < img.width * img.height * img.channels; i++)
    if (fabs(img.data[i] - 2.5) > 1.0) bad++;
  CHECK(bad == 0, "%d pixels far from L", bad);
  film_image_free(&img);
  scene_free(s);
}

static void test_area_light_seen_directly(void) {
  /* A camera looking straight at an area emitter sees its radiance;
   * hide_emitters removes it. */
  const char *fmt =
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"perspective\", \"fov\": 10,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\", \"hide_emitters\": %s},"
      " \"light\": {\"type\": \"rectangle\", \"emitter\": {\"type\": \"area\", \"radiance\": [1, 2, 3]}}}";
  char buf[2048];
  snprintf(buf, sizeof buf, fmt, "false");
  scene *s = tsup_load(buf, NULL);
  REQUIRE(s, "scene");
  film_image img;
  REQUIRE(tsup_render(s, 0, 8, 0, &img), "render");
  for (int i = 0; i < img.width * img.height; i++) {
    CHECK_REL(img.data[3 * i], 1.0, 1e-6);
    CHECK_REL(img.data[3 * i + 2], 3.0, 1e-6);
  }
  film_image_free(&img);
  scene_free(s);
  snprintf(buf, sizeof buf, fmt, "true");
  s = tsup_load(buf, NULL);
  REQUIRE(s, "scene");
  REQUIRE(tsup_render(s, 0, 8, 0, &img), "render");
  double m, sem;
  tsup_stats(&img, 0, &m, &sem);
  CHECK(m == 0.0, "hidden emitter still visible (%g)", m);
  film_image_free(&img);
  scene_free(s);
}

static void test_area_light_irradiance(void) {
  /* A Lambertian plate lit by a parallel emitting disk of radiance Le and
   * radius a at height h receives E = pi Le a^2 / (h^2 + a^2) at its
   * centre; a radiancemeter looking at the centre reads rho E / pi.
   * Exercises area-light NEE and BSDF sampling with MIS. */
  const char *sc =
      "{\"type\": \"scene\","
      " \"meter\": {\"type\": \"radiancemeter\", \"origin\": [0, 0, 0.5], \"direction\": [0, 0, -1],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 40000},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\", \"max_depth\": 2},"
      " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 100}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}},"
      " \"lamp\": {\"type\": \"disk\", \"flip_normals\": true,"
      "   \"to_world\": [{\"scale\": 0.5}, {\"translate\": [0, 0, 1]}],"
      "   \"emitter\": {\"type\": \"area\", \"radiance\": 3.0}}}";
  scene *s = tsup_load(sc, NULL);
  REQUIRE(s, "scene");
  /* Several independent estimates to get an error bar. */
  double sum = 0, sum2 = 0;
  const int K = 8;
  for (int k = 0; k < K; k++) {
    film_image img;
    REQUIRE(tsup_render(s, 0, 100 + (uint64_t)k, 0, &img), "render");
    sum += img.data[0];
    sum2 += img.data[0] * img.data[0];
    film_image_free(&img);
  }
  double m = sum / K, sem = sqrt(fmax(sum2 / K - m * m, 0) / (K - 1));
  double a = 0.5, h = 1.0, E = 3.14159265358979323846 * 3.0 * a * a / (h * h + a * a);
  double expect = 0.5 * E / 3.14159265358979323846;
  /* The meter's ray passes through the lamp's back side (one-sided
   * emitter, no BSDF hit: the disk is a default diffuse, so block it).
   * The lamp is at z = 1 and the meter at z = 0.5, below it. */
  CHECK(fabs(m - expect) <= 3 * sem + 1e-9, "mean %.6g vs %.6g (3 sigma %.3g)", m, expect, 3 * sem);
  scene_free(s);
}

static void test_mono_tabulated_spectrum(void) {
  /* mono: a tabulated reflectance is evaluated at the render wavelength by
   * linear interpolation (400 nm: 0.2, 700 nm: 0.8 -> 0.5 at 550). */
  const char *sc =
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"sensor\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4, \"rfilter\": {\"type\": \"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1],"
      "   \"irradiance\": {\"type\": \"spectrum\", \"wavelengths\": [300, 900], \"values\": [2, 2]}},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\","
      "   \"reflectance\": {\"type\": \"spectrum\", \"value\": [[400, 0.2], [700, 0.8]]}}}}";
  scene *s = tsup_load(sc, NULL);
  REQUIRE(s, "scene");
  film_image img;
  rsw_err err = {0};
  render_opts o = {.size = sizeof o, .wavelength = 550};
  REQUIRE(render_sensor(s, &o, &img, NULL, &err) == RSW_OK, "render: %s", err.msg);
  check_all_pixels(&img, 0.5 * 2 / 3.14159265358979323846, 1e-5);
  film_image_free(&img);
  o.wavelength = 650;
  REQUIRE(render_sensor(s, &o, &img, NULL, &err) == RSW_OK, "render: %s", err.msg);
  check_all_pixels(&img, 0.7 * 2 / 3.14159265358979323846, 1e-5);
  film_image_free(&img);
  /* Outside the table: a clear error, no film. */
  o.wavelength = 350;
  rsw_err_clear(&err);
  CHECK(render_sensor(s, &o, &img, NULL, &err) == RSW_ERR_RANGE, "350 nm must be rejected");
  CHECK(strstr(err.msg, "350") != NULL, "error names the wavelength: %s", err.msg);
  scene_free(s);
  /* rgb: a tabulated spectrum is refused at load time. */
  s = tsup_load(sc, "rgb");
  CHECK(s == NULL, "tabulated spectrum must be refused in rgb");
  scene_free(s);
}

static void test_bitmap_texture(void) {
  /* A 2x2 RGB bitmap as the plate's reflectance, nearest lookup. Row 0 of
   * the image is its top, v = 0 its bottom (Mitsuba's convention); the
   * rectangle's uv is ((x+1)/2, (y+1)/2). A radiancemeter looking straight
   * down at (x, y) under a sun at zenith reads rho(uv) / pi exactly. */
  char path[] = "/tmp/rsw-bitmap-XXXXXX.exr";
  int fd = mkstemps(path, 4);
  REQUIRE(fd >= 0, "temp file");
  close(fd);
  const float px[12] = {0.1f, 0.2f, 0.3f, 0.4f,  0.5f, 0.6f,   /* top row: (0,0), (1,0) */
                        0.7f, 0.8f, 0.9f, 0.25f, 0.5f, 0.75f}; /* bottom row */
  const char *names[3] = {"R", "G", "B"};
  rsw_err err = {0};
  REQUIRE(exr_write_image(path, 2, 2, 3, names, px, false, NULL, &err) == RSW_OK, "write: %s", err.msg);
  /* (x, y) -> expected texel: bottom-left, bottom-right, top-left. */
  const double pts[3][2] = {{-0.5, -0.5}, {0.5, -0.5}, {-0.5, 0.5}};
  const int texel[3] = {2, 3, 0};
  for (int k = 0; k < 3; k++) {
    for (int mono = 0; mono < 2; mono++) {
      char sc[2048];
      snprintf(
          sc, sizeof sc,
          "{\"type\": \"scene\","
          " \"m\": {\"type\": \"radiancemeter\", \"origin\": [%g, %g, 1], \"direction\": [0, 0, -1],"
          "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"component_format\": "
          "\"float32\","
          "     \"rfilter\": {\"type\": \"box\"}}},"
          " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1]},"
          " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\","
          "   \"reflectance\": {\"type\": \"bitmap\", \"filename\": \"%s\", \"filter_type\": \"nearest\"}}}}",
          pts[k][0], pts[k][1], path);
      scene *s = tsup_load(sc, mono ? "mono" : "rgb");
      REQUIRE(s, "scene");
      film_image img;
      REQUIRE(tsup_render(s, 2, 1, 1, &img), "render");
      const float *t = &px[3 * texel[k]];
      if (mono) {
        double y = 0.212671 * t[0] + 0.715160 * t[1] + 0.072169 * t[2];
        CHECK_REL(img.data[0], y / 3.14159265358979323846, 1e-5);
      } else {
        for (int c = 0; c < 3; c++) CHECK_REL(img.data[c], t[c] / 3.14159265358979323846, 1e-5);
      }
      film_image_free(&img);
      scene_free(s);
    }
  }
  remove(path);
}

static void test_mesh_plate_without_attributes(void) {
  /* A PLY plate with neither normals nor uvs (its face normals come from
   * Embree's hit) and one with vertex normals: both are the Lambertian
   * plate of the closed form, seen by a radiancemeter. */
  const char *plys[2] = {
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
      "-1 -1 0\n1 -1 0\n1 1 0\n-1 1 0\n3 0 1 2\n3 0 2 3\n",
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "property float nx\nproperty float ny\nproperty float nz\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
      "-1 -1 0 0 0 1\n1 -1 0 0 0 1\n1 1 0 0 0 1\n-1 1 0 0 0 1\n3 0 1 2\n3 0 2 3\n"};
  for (int k = 0; k < 2; k++) {
    char path[] = "/tmp/rsw-plate-XXXXXX.ply";
    int fd = mkstemps(path, 4);
    REQUIRE(fd >= 0, "temp file");
    FILE *f = fdopen(fd, "w");
    fputs(plys[k], f);
    fclose(f);
    char sc[2048];
    snprintf(
        sc, sizeof sc,
        "{\"type\": \"scene\","
        " \"m\": {\"type\": \"radiancemeter\", \"origin\": [0.3, -0.2, 2], \"direction\": [-0.1, 0.05, -1],"
        "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"component_format\": \"float32\","
        "     \"rfilter\": {\"type\": \"box\"}}},"
        " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0, -0.86602540378443864676]},"
        " \"plate\": {\"type\": \"ply\", \"filename\": \"%s\","
        "   \"to_world\": [{\"rotate\": {\"axis\": [0, 0, 1], \"angle\": 30}}, {\"translate\": [0, 0, 0.1]}],"
        "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}",
        path);
    scene *s = tsup_load(sc, NULL);
    REQUIRE(s, "scene");
    film_image img;
    REQUIRE(tsup_render(s, 4, 1, 1, &img), "render");
    CHECK_REL(img.data[0], L_PLATE, 1e-5);
    film_image_free(&img);
    scene_free(s);
    remove(path);
  }
}

int main(void) {
  RSW_TEST_RUN(test_mesh_plate_without_attributes);
  RSW_TEST_RUN(test_bitmap_texture);
  RSW_TEST_RUN(test_hdistant_shape_target_exact);
  RSW_TEST_RUN(test_hdistant_point_target_exact);
  RSW_TEST_RUN(test_hdistant_large_target_quarter);
  RSW_TEST_RUN(test_hdistant_no_target_two_over_pi);
  RSW_TEST_RUN(test_distant_and_radiancemeter_exact);
  RSW_TEST_RUN(test_checkerboard_plate);
  RSW_TEST_RUN(test_white_furnace);
  RSW_TEST_RUN(test_area_light_seen_directly);
  RSW_TEST_RUN(test_area_light_irradiance);
  RSW_TEST_RUN(test_mono_tabulated_spectrum);
  RSW_TEST_END("test_radiometry");
}
