/* kapi.h: the service's narrow view of the kernel. Per-pixel directions
 * come from the sensor's own film mapping: the direction of each pixel is
 * minus the ray the sensor traces at that pixel's centre, with a rotated
 * to_world too; sensors and films as the scene has them. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../server/kernel/kapi.h"
#include "../../server/kernel/scene/scene.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static const char *SCENE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"h\": {\"type\": \"hdistant\", \"to_world\": [{\"rotate\": {\"axis\": [1, 1, 0], \"angle\": 30}}],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 7},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 9, \"height\": 5}},"
    " \"d\": {\"type\": \"distant\", \"direction\": [1, -2, -3],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
    " \"cam\": {\"type\": \"perspective\", \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 3}},"
    " \"plate\": {\"type\": \"rectangle\"}}";

static void test_sensors(void) {
  scene *s = tsup_load(SCENE, NULL);
  REQUIRE(s, "scene");
  CHECK(kapi_is_mono(s), "mono");
  CHECK(kapi_sensor_count(s) == 3, "3 sensors (%zu)", kapi_sensor_count(s));
  size_t i = 9;
  CHECK(kapi_find_sensor(s, "d", &i) && i == 1, "find d: %zu", i);
  CHECK(kapi_find_sensor(s, "2", &i) && i == 2, "find by index");
  CHECK(!kapi_find_sensor(s, "nope", &i), "unknown sensor");
  CHECK(strcmp(kapi_sensor_id(s, 0), "h") == 0 && strcmp(kapi_sensor_type(s, 0), "hdistant") == 0, "id/type");
  int W, H;
  kapi_film_size(s, 0, &W, &H);
  CHECK(W == 9 && H == 5, "film %dx%d", W, H);
  CHECK(kapi_sensor_spp(s, 0) == 7, "spp %u", kapi_sensor_spp(s, 0));
  CHECK(kapi_scene_bytes(s) > 0, "bytes");
  scene_free(s);
}

static void test_directions_match_rays(void) {
  scene *s = tsup_load(SCENE, NULL);
  REQUIRE(s, "scene");
  for (size_t si = 0; si < 2; si++) {
    int W, H;
    kapi_film_size(s, si, &W, &H);
    double *px = malloc((size_t)W * H * 5 * sizeof *px);
    rsw_err err = {0};
    REQUIRE(px && kapi_pixel_directions(s, si, px, &err) == RSW_OK, "directions: %s", err.msg);
    const sensor *se = s->sensors[si];
    for (int iy = 0; iy < H; iy++)
      for (int ix = 0; ix < W; ix++) {
        const double *d = px + 5 * ((size_t)iy * W + ix);
        ray3 r;
        se->ops->sample_ray(se, v2((ix + 0.5) / W, (iy + 0.5) / H), v2(0.5, 0.5), &r);
        CHECK(fabs(d[0] + r.d.x) < 1e-12 && fabs(d[1] + r.d.y) < 1e-12 && fabs(d[2] + r.d.z) < 1e-12,
              "sensor %zu pixel (%d, %d): (%g %g %g) vs ray -(%g %g %g)", si, ix, iy, d[0], d[1], d[2], r.d.x,
              r.d.y, r.d.z);
        CHECK(d[3] >= 0 && d[3] <= 180 && d[4] >= 0 && d[4] < 360, "angles in range: %g %g", d[3], d[4]);
      }
    if (si == 1) {
      /* distant: zenith from the world direction -d. */
      double z = 3 / sqrt(14.0);
      CHECK(fabs(px[3] - acos(z) * 180 / 3.14159265358979323846) < 1e-9, "distant zenith %g", px[3]);
    }
    free(px);
  }
  rsw_err err = {0};
  double dummy[60];
  CHECK(!kapi_has_directions(s, 2) && kapi_pixel_directions(s, 2, dummy, &err) == RSW_ERR_UNSUPPORTED,
        "perspective has no directions");
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_sensors);
  RSW_TEST_RUN(test_directions_match_rays);
  RSW_TEST_END("test_kapi");
}
