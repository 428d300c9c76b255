/* The area emitter's precomputed world triangles (emitters/area.c): a
 * sample drawn through them equals, bit for bit, the one the shape makes
 * without them (shapes/shape.c builds each triangle with the same code),
 * for a two-triangle rectangle and a 12-triangle cube light, and the
 * direction, distance and pdf follow from that point. (That the triangles
 * follow to_world and vertex updates is checked as update = reload in
 * tests/validation/test_update_reload.c.) */
#include <string.h>

#include "../../server/kernel/core/rng.h"
#include "../../server/kernel/shapes/shape.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

static const char *scene_fmt =
    "{\"type\": \"scene\", \"cam\": {\"type\": \"perspective\", \"fov\": 40, \"to_world\": [{\"lookat\": "
    "{\"origin\": [0, -3, 1], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}], \"film\": {\"type\": \"hdrfilm\", "
    "\"width\": 4, \"height\": 4}},"
    " \"floor\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\"}},"
    " \"light\": {\"type\": \"%s\", \"to_world\": [{\"scale\": [0.3, 0.2, 0.1]}, {\"rotate\": {\"axis\": [1, "
    "1, 0], \"angle\": 170}}, {\"translate\": [0.1, 0.2, 1.5]}],"
    "   \"emitter\": {\"type\": \"area\", \"radiance\": 2}}}";

static void check_light(const char *shape_type) {
  char text[2048];
  snprintf(text, sizeof text, scene_fmt, shape_type);
  scene *s = tsup_load(text, "rgb");
  REQUIRE(s, "load a %s light", shape_type);
  const emitter *e = NULL;
  for (size_t i = 0; i < s->n_emitters; i++)
    if (s->emitters[i]->flags & EMITTER_SURFACE) e = s->emitters[i];
  REQUIRE(e && e->shape, "%s: the area emitter", shape_type);
  surface_interaction ref;
  memset(&ref, 0, sizeof ref);
  ref.p = v3(0.05, -0.1, 0.0);
  pcg32 r;
  pcg32_seed(&r, 5, 9);
  int differ = 0, sampled = 0;
  for (int i = 0; i < 20000; i++) {
    vec2 u = v2(pcg32_next_double(&r), pcg32_next_double(&r));
    direction_sample ds;
    color c = e->ops->sample_direction(e, &ref, u, &ds);
    position_sample ps = shape_sample_position(e->shape, u);
    if (memcmp(&ds.p, &ps.p, sizeof ps.p) != 0 || memcmp(&ds.n, &ps.n, sizeof ps.n) != 0) differ++;
    if (ds.pdf > 0) {
      sampled++;
      double d2 = v3_len2(v3_sub(ps.p, ref.p));
      double cos_e = -v3_dot(ds.d, ps.n);
      CHECK_REL(ds.pdf, d2 / (cos_e * e->shape->area), 1e-12);
      CHECK_REL(c.c[0], 2.0 / ds.pdf, 1e-12);
    }
  }
  CHECK(differ == 0, "%s: %d of 20000 samples differ from the shape's own", shape_type, differ);
  CHECK(sampled > 5000, "%s: only %d samples face the reference point", shape_type, sampled);
  scene_free(s);
}

static void test_rectangle_light(void) {
  check_light("rectangle");
}

static void test_cube_light(void) {
  check_light("cube");
}

int main(void) {
  RSW_TEST_RUN(test_rectangle_light);
  RSW_TEST_RUN(test_cube_light);
  RSW_TEST_END("test_area_light");
}
