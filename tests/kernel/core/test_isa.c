/* Renders at every ISA this CPU runs (core/isa.h, --isa):
 *  - at each ISA, 1 and 2 threads give bitwise-identical films (the seed
 *    scene, whose roughconductor samples through the batched op, and the
 *    Cornell box);
 *  - across ISAs the films agree statistically: the seed scene (64 spp,
 *    box filter) pixel by pixel, |a - b| <= 3 sqrt(se_a^2 + se_b^2) with
 *    each pixel's standard error from the radiance_stderr plane, for at
 *    least 99 % of the pixels (0.27 % fail by chance at 3 sigma), and its
 *    mean over the film within 3 standard errors; the Cornell box (4 spp,
 *    gaussian filter: no per-pixel error) by its film mean within 3
 *    standard errors of the pixel spread;
 *  - the film says which ISA ran (film_image.isa).
 * Fixed seeds. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/core/isa.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static bool same_bits(const film_image *a, const film_image *b) {
  size_t n = (size_t)a->width * a->height * a->channels;
  return a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, n * sizeof(float)) == 0;
}

static bool render(scene *s, uint32_t spp, int threads, bool variance, film_image *out) {
  render_opts o = {.size = sizeof o, .spp = spp, .seed = 7, .threads = threads, .variance = variance};
  render_result_stats st;
  rsw_err err = {0};
  if (render_sensor(s, &o, out, &st, &err) != RSW_OK) {
    fprintf(stderr, "render: %s: %s\n", err.where, err.msg);
    return false;
  }
  return true;
}

static const float *stderr_plane(const film_image *img) {
  for (int p = 0; p < img->n_planes; p++)
    if (strcmp(img->planes[p].name, "radiance_stderr") == 0) return img->planes[p].data;
  return NULL;
}

static void test_seed_scene(void) {
  scene *s = tsup_load_file("proto/examples/hdistant_seed.xml", NULL);
  REQUIRE(s, "hdistant_seed.xml");
  film_image ref = {0};
  bool have_ref = false;
  for (int i = 0; i < RSW_ISA__COUNT; i++) {
    if (!rsw_isa_set((rsw_isa)i)) continue;
    const char *name = rsw_isa_name((rsw_isa)i);
    film_image one, two;
    REQUIRE(render(s, 64, 1, true, &one), "%s, 1 thread", name);
    REQUIRE(render(s, 64, 2, true, &two), "%s, 2 threads", name);
    CHECK(one.isa && strcmp(one.isa, name) == 0, "film isa %s, ran %s", one.isa ? one.isa : "(none)", name);
    CHECK(same_bits(&one, &two), "%s: 1 and 2 threads differ", name);
    film_image_free(&two);
    const float *e = stderr_plane(&one);
    REQUIRE(e, "radiance_stderr plane");
    if (!have_ref) {
      ref = one;
      have_ref = true;
      continue;
    }
    const float *e0 = stderr_plane(&ref);
    size_t n = (size_t)one.width * one.height * one.channels, bad = 0, same = 0;
    double sum = 0, sum0 = 0, v = 0, v0 = 0;
    for (size_t k = 0; k < n; k++) {
      double d = fabs((double)one.data[k] - ref.data[k]);
      double sig = sqrt((double)e[k] * e[k] + (double)e0[k] * e0[k]);
      bad += !(d <= 3 * sig + 1e-12);
      same += memcmp(&one.data[k], &ref.data[k], sizeof(float)) == 0;
      sum += one.data[k], sum0 += ref.data[k];
      v += (double)e[k] * e[k], v0 += (double)e0[k] * e0[k];
    }
    printf("  seed scene %s vs %s: %zu of %zu values beyond 3 sigma, %zu bitwise equal; means %.6g, %.6g\n",
           name, ref.isa, bad, n, same, sum / n, sum0 / n);
    CHECK(bad <= n / 100, "%s vs %s: %zu of %zu pixels beyond 3 sigma", name, ref.isa, bad, n);
    CHECK(fabs(sum - sum0) / n <= 3 * sqrt(v + v0) / n + 1e-12, "%s vs %s: film means %.6g, %.6g", name,
          ref.isa, sum / n, sum0 / n);
    film_image_free(&one);
  }
  if (have_ref) film_image_free(&ref);
  rsw_isa_set(rsw_isa_best());
  scene_free(s);
}

static void test_cornell_box(void) {
  scene *s = tsup_load_file("proto/examples/cornell_box.json", NULL);
  REQUIRE(s, "cornell_box.json");
  double m0 = 0, e0 = 0;
  const char *ref = NULL;
  for (int i = 0; i < RSW_ISA__COUNT; i++) {
    if (!rsw_isa_set((rsw_isa)i)) continue;
    const char *name = rsw_isa_name((rsw_isa)i);
    film_image one, two;
    REQUIRE(render(s, 4, 1, false, &one), "%s, 1 thread", name);
    REQUIRE(render(s, 4, 2, false, &two), "%s, 2 threads", name);
    CHECK(same_bits(&one, &two), "%s: 1 and 2 threads differ", name);
    for (int c = 0; c < one.channels; c++) {
      double m, e;
      tsup_stats(&one, c, &m, &e);
      if (!ref) {
        if (c == 0) m0 = m, e0 = e;
        continue;
      }
      if (c == 0) {
        printf("  cornell box %s vs %s: channel 0 mean %.6g vs %.6g\n", name, ref, m, m0);
        CHECK(fabs(m - m0) <= 3 * sqrt(e * e + e0 * e0), "%s vs %s: mean %.6g vs %.6g", name, ref, m, m0);
      }
    }
    if (!ref) ref = name;
    film_image_free(&one);
    film_image_free(&two);
  }
  rsw_isa_set(rsw_isa_best());
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_seed_scene);
  RSW_TEST_RUN(test_cornell_box);
  RSW_TEST_END("test_isa");
}
