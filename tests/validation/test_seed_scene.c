/* The hdistant seed scene (proto/examples/hdistant_seed.xml, the scene the
 * project started from, unchanged) and determinism.
 *
 * Three directional emitters (red, green, blue) light a roughconductor
 * rectangle (Beckmann, alpha 0.1: a narrow glossy lobe). Each colour's
 * brightest hdistant pixel must be the one whose exitant direction is that
 * emitter's mirror direction under the documented film mapping
 * (docs/kernel-conventions.md#hdistant: omega = to_world H(u), H the concentric uniform
 * hemisphere map, u = pixel centre). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../../server/kernel/core/warp.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static void brightest(const film_image *img, int c, int *bx, int *by) {
  float best = -1;
  for (int y = 0; y < img->height; y++)
    for (int x = 0; x < img->width; x++) {
      float v = img->data[(y * img->width + x) * img->channels + c];
      if (v > best) best = v, *bx = x, *by = y;
    }
}

static double centre_dot(vec3 omega, int x, int y, int W, int H) {
  return v3_dot(warp_square_to_uniform_hemisphere(v2((x + 0.5) / W, (y + 0.5) / H)), omega);
}

/* Pixel whose centre direction is closest to omega, and that closeness. */
static double pixel_of(vec3 omega, int W, int H, int *bx, int *by) {
  double best = -2;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      double d = centre_dot(omega, x, y, W, H);
      if (d > best) best = d, *bx = x, *by = y;
    }
  return best;
}

static void test_seed_mirror_directions(void) {
  scene *s = tsup_load_file("proto/examples/hdistant_seed.xml", NULL);
  REQUIRE(s, "seed scene must load unchanged");
  REQUIRE(s->n_sensors == 1 && s->n_emitters == 3 && s->n_shapes == 1, "seed scene structure");
  CHECK(strcmp(s->emitters[0]->base.id, "directional") == 0 &&
            strcmp(s->emitters[2]->base.id, "directional_2") == 0,
        "deterministic ids for unnamed emitters: %s, %s", s->emitters[0]->base.id, s->emitters[2]->base.id);
  CHECK(strcmp(s->shapes[0]->base.id, "rectangle") == 0, "rectangle id: %s", s->shapes[0]->base.id);
  film_image img;
  REQUIRE(tsup_render(s, 256, 0, 0, &img), "render");
  REQUIRE(img.channels == 3 && img.width == 32 && img.height == 32, "32x32 RGB film");
  /* Light travels along d; the mirror direction of the incident -d about
   * +z is (d.x, d.y, -d.z) normalised. */
  const vec3 dirs[3] = {v3(1, 0, -1), v3(1, 1, -1), v3(0, 1, -1)};
  for (int c = 0; c < 3; c++) {
    vec3 omega = v3_norm(v3(dirs[c].x, dirs[c].y, -dirs[c].z));
    int ex = 0, ey = 0, bx = 0, by = 0;
    double best = pixel_of(omega, 32, 32, &ex, &ey);
    brightest(&img, c, &bx, &by);
    /* Ties: a mirror direction on a pixel border (blue: azimuth 90 deg lies
     * between two columns) is equally close to both pixels. */
    CHECK(fabs(centre_dot(omega, bx, by, 32, 32) - best) < 1e-12,
          "channel %d: brightest pixel (%d, %d), mirror direction at (%d, %d)", c, bx, by, ex, ey);
  }
  film_image_free(&img);
  scene_free(s);
}

static bool same_bits(const film_image *a, const film_image *b) {
  size_t n = (size_t)a->width * a->height * a->channels;
  return a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, n * sizeof(float)) == 0;
}

static void check_threads_bitwise(const char *scene_text, uint32_t spp) {
  scene *s = tsup_load(scene_text, NULL);
  REQUIRE(s, "scene");
  film_image one, two, four;
  REQUIRE(tsup_render(s, spp, 42, 1, &one), "1 thread");
  REQUIRE(tsup_render(s, spp, 42, 2, &two), "2 threads");
  REQUIRE(tsup_render(s, spp, 42, 4, &four), "4 threads");
  CHECK(same_bits(&one, &two), "1 and 2 threads differ");
  CHECK(same_bits(&one, &four), "1 and 4 threads differ");
  film_image other;
  REQUIRE(tsup_render(s, spp, 43, 2, &other), "seed 43");
  CHECK(!same_bits(&one, &other), "a different seed must change the film");
  film_image_free(&one);
  film_image_free(&two);
  film_image_free(&four);
  film_image_free(&other);
  scene_free(s);
}

static void test_determinism_box_independent(void) {
  /* Film larger than one tile so that tiles finish out of order. */
  check_threads_bitwise(
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"perspective\", \"fov\": 45,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [0, -4, 2], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 40, \"height\": 36, \"rfilter\": {\"type\": "
      "\"box\"}}},"
      " \"env\": {\"type\": \"constant\", \"radiance\": 0.5},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [1, 1, -2]},"
      " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 3}]},"
      " \"ball\": {\"type\": \"sphere\", \"center\": [0, 0, 0.6], \"radius\": 0.6,"
      "   \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": 0.2}},"
      " \"box\": {\"type\": \"cube\", \"to_world\": [{\"scale\": 0.3}, {\"translate\": [1, 0.5, 0.3]}],"
      "   \"bsdf\": {\"type\": \"dielectric\"}}}",
      8);
}

static void test_determinism_gaussian_stratified(void) {
  /* The gaussian filter splats across tile borders: the ordered merge must
   * keep sums independent of scheduling. */
  check_threads_bitwise(
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"perspective\", \"fov\": 45,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [0, -4, 2], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
      "   \"sampler\": {\"type\": \"stratified\", \"sample_count\": 9},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 37, \"height\": 35}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [1, 1, -2]},"
      " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 3}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": {\"type\": \"checkerboard\"}}},"
      " \"lamp\": {\"type\": \"disk\", \"to_world\": [{\"scale\": 0.5}, {\"rotate\": {\"axis\": [1, 0, 0], "
      "\"angle\": 180}},"
      "   {\"translate\": [0, 0, 2]}], \"emitter\": {\"type\": \"area\", \"radiance\": 4}}}",
      0);
}

static void test_seed_determinism(void) {
  scene *s = tsup_load_file("proto/examples/hdistant_seed.xml", NULL);
  REQUIRE(s, "seed");
  film_image a, b;
  REQUIRE(tsup_render(s, 64, 7, 1, &a), "1 thread");
  REQUIRE(tsup_render(s, 64, 7, 2, &b), "2 threads");
  CHECK(same_bits(&a, &b), "seed scene: 1 and 2 threads differ");
  film_image_free(&a);
  film_image_free(&b);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_seed_mirror_directions);
  RSW_TEST_RUN(test_determinism_box_independent);
  RSW_TEST_RUN(test_determinism_gaussian_stratified);
  RSW_TEST_RUN(test_seed_determinism);
  RSW_TEST_END("test_seed_scene");
}
