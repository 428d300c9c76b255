/* No geometry input can abort the process (issue 13): what float32 tracing
 * cannot represent (a projective to_world, scales of 1e-20 and below or
 * 1e39 and up, a sphere radius of 1e-30, NaN and infinite entries, a
 * placement of an instancelist) is refused at load (JSON and XML, naming
 * the property and the file line) and at update (naming the key); a
 * refused update, even one refused only by accel.c's scene-wide check
 * after it was written, leaves every parameter bitwise unchanged and
 * renders exactly as before; a camera far beyond the scene renders.
 * Before the fix each of the "crash" cases aborted this binary (Embree's
 * ray.valid() assertion, SIGABRT) and the 1e39 cases rendered zero. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../server/kernel/scene/param_table.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define FILM8                                                                                                \
  "\"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"box\"}}"
#define CAM                                                                                                  \
  "\"cam\": {\"type\": \"perspective\", \"fov\": 40, \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 6], "   \
  "\"target\": [0, 0, 0], \"up\": [0, 1, 0]}}], \"sampler\": {\"type\": \"independent\", \"sample_count\": " \
  "4}, " FILM8 "}"
#define SKY "\"sky\": {\"type\": \"constant\", \"radiance\": 1.0}"

/* A scene with a rectangle, a cube (mesh parameters) and a sphere. */
static const char *BASE = "{\"type\": \"scene\", \"variant\": \"mono\", " CAM ", " SKY ", "
                          "\"rect\": {\"type\": \"rectangle\"}, "
                          "\"box\": {\"type\": \"cube\", \"to_world\": [{\"translate\": [2, 0, 0]}, "
                          "{\"scale\": 0.5}]}, "
                          "\"ball\": {\"type\": \"sphere\", \"center\": [-2, 0, 0], \"radius\": 0.5}}";

static rsw_status load_text(const char *text, bool xml, scene **out, rsw_err *err) {
  scene_load_opts o = {0};
  return scene_load_memory(text, strlen(text), xml ? "case.xml" : "case.json", xml, &o, out, err);
}

static bool render(scene *s, film_image *out) {
  rsw_err err = {0};
  render_opts o = {.size = sizeof o, .sensor = 0, .spp = 4, .seed = 7, .threads = 2, .wavelength = 550};
  if (render_sensor(s, &o, out, NULL, &err)) {
    char buf[1200];
    printf("  render failed: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  return true;
}

static bool same_film(const film_image *a, const film_image *b) {
  return a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, sizeof(float) * (size_t)a->width * a->height * a->channels) == 0;
}

/* Every parameter's value as text (%.17g: bitwise for doubles). */
static char *params_snapshot(const scene *s) {
  sbuf b = {0};
  for (size_t i = 0; i < params_count(s); i++) {
    char *v = params_value_json(s, i, 0);
    sb_printf(&b, "%zu=%s\n", i, v ? v : "?");
    free(v);
  }
  return b.p;
}

/* ---- load ------------------------------------------------------------------------ */

typedef struct load_case {
  const char *name;
  bool xml;
  const char *text;
  const char *what;  /* must appear in the message */
  const char *where; /* must appear in the location */
} load_case;

#define JS(shape) "{\"type\": \"scene\", " CAM ", " SKY ", \"s\": " shape "}"
#define XS(shape)                                                                                            \
  "<scene version=\"3.0.0\">\n"                                                                              \
  "<sensor type=\"perspective\"><transform name=\"to_world\"><lookat origin=\"0,0,6\" target=\"0,0,0\" "     \
  "up=\"0,1,0\"/></transform>\n"                                                                             \
  "<film type=\"hdrfilm\"><integer name=\"width\" value=\"8\"/><integer name=\"height\" "                    \
  "value=\"8\"/></film>"                                                                                     \
  "</sensor>\n" shape "\n</scene>\n"

static const load_case LOADS[] = {
    {"json projective", false,
     JS("{\"type\": \"rectangle\", \"to_world\": [1,0,0,0, 0,1,0,0, 0,0,1,0, 1,0,0,1]}"), "affine", "/s"},
    {"json scale 1e-20", false, JS("{\"type\": \"rectangle\", \"to_world\": [{\"scale\": 1e-20}]}"),
     "to_world", "/s"},
    {"json scale 1e-30", false, JS("{\"type\": \"sphere\", \"to_world\": [{\"scale\": 1e-30}]}"), "to_world",
     "/s"},
    {"json scale 1e39", false, JS("{\"type\": \"rectangle\", \"to_world\": [{\"scale\": 1e39}]}"), "to_world",
     "/s"},
    {"json radius 1e-30", false, JS("{\"type\": \"sphere\", \"radius\": 1e-30}"), "radius", "/s"},
    {"json radius 1e39", false, JS("{\"type\": \"sphere\", \"radius\": 1e39}"), "radius", "/s"},
    {"json translate 1e30", false, JS("{\"type\": \"cube\", \"to_world\": [{\"translate\": [1e30, 0, 0]}]}"),
     "translation", "/s"},
    {"json inf", false, JS("{\"type\": \"rectangle\", \"to_world\": [{\"scale\": 1e400}]}"), "", "/s"},
    {"xml scale 1e-30", true,
     XS("<shape type=\"rectangle\">\n<transform name=\"to_world\"><scale "
        "value=\"1e-30\"/></transform></shape>"),
     "to_world", "case.xml:4"},
    {"xml scale 1e-20", true,
     XS("<shape type=\"cube\">\n<transform name=\"to_world\"><scale value=\"1e-20\"/></transform></shape>"),
     "to_world", "case.xml:4"},
    {"xml scale 1e39", true,
     XS("<shape type=\"cube\">\n<transform name=\"to_world\"><scale value=\"1e39\"/></transform></shape>"),
     "to_world", "case.xml:4"},
    {"xml projective", true,
     XS("<shape type=\"rectangle\">\n<transform name=\"to_world\"><matrix value=\"1 0 0 0 0 1 0 0 0 0 1 0 1 "
        "0 "
        "0 1\"/></transform></shape>"),
     "affine", "case.xml:4"},
    {"xml radius 1e-30", true,
     XS("<shape type=\"sphere\">\n<float name=\"radius\" value=\"1e-30\"/></shape>"), "radius", "case.xml"},
    {"xml nan", true,
     XS("<shape type=\"cube\">\n<transform name=\"to_world\"><scale value=\"nan\"/></transform></shape>"), "",
     "case.xml"},
    {"xml inf", true,
     XS("<shape type=\"cube\">\n<transform name=\"to_world\"><translate x=\"inf\"/></transform></shape>"), "",
     "case.xml"},
};

static void test_load_refused(void) {
  for (size_t i = 0; i < sizeof LOADS / sizeof LOADS[0]; i++) {
    const load_case *c = &LOADS[i];
    scene *s = NULL;
    rsw_err err = {0};
    rsw_status st = load_text(c->text, c->xml, &s, &err);
    CHECK(st != RSW_OK, "%s: loaded", c->name);
    if (st == RSW_OK) {
      film_image img = {0};
      render(s, &img); /* what used to abort */
      film_image_free(&img);
      scene_free(s);
      continue;
    }
    CHECK(strstr(err.msg, c->what) != NULL, "%s: message '%s' lacks '%s'", c->name, err.msg, c->what);
    CHECK(strstr(err.where, c->where) != NULL, "%s: location '%s' lacks '%s'", c->name, err.where, c->where);
  }
}

/* The limits leave ordinary small and large scenes alone. */
static void test_load_accepted(void) {
  static const char *ok[] = {
      JS("{\"type\": \"sphere\", \"radius\": 1e-5}"),
      JS("{\"type\": \"rectangle\", \"to_world\": [{\"scale\": [1e6, 1e6, 1]}]}"),
      JS("{\"type\": \"cube\", \"to_world\": [{\"translate\": [1e8, 0, 0]}]}"),
  };
  for (size_t i = 0; i < sizeof ok / sizeof ok[0]; i++) {
    scene *s = NULL;
    rsw_err err = {0};
    CHECK(load_text(ok[i], false, &s, &err) == RSW_OK, "case %zu: %s", i, err.msg);
    film_image img = {0};
    if (s) CHECK(render(s, &img), "case %zu renders", i);
    film_image_free(&img);
    scene_free(s);
  }
}

/* ---- updates ------------------------------------------------------------------- */

typedef struct upd_case {
  const char *key;
  const char *value;
} upd_case;

static const upd_case UPDS[] = {
    {"rect.to_world", "[1,0,0,0, 0,1,0,0, 0,0,1,0, 1,0,0,1]"},
    {"rect.to_world", "[1e-20,0,0,0, 0,1e-20,0,0, 0,0,1e-20,0, 0,0,0,1]"},
    {"rect.to_world", "[1e-30,0,0,0, 0,1e-30,0,0, 0,0,1e-30,0, 0,0,0,1]"},
    {"rect.to_world", "[1e39,0,0,0, 0,1e39,0,0, 0,0,1e39,0, 0,0,0,1]"},
    {"rect.to_world", "[1,0,0,1e400, 0,1,0,0, 0,0,1,0, 0,0,0,1]"},
    {"rect.to_world", "[1,0,0,0, 0,1,0,0, 0,0,1e-9,0, 0,0,0,1]"},
    {"ball.to_world", "[1e-30,0,0,0, 0,1e-30,0,0, 0,0,1e-30,0, 0,0,0,1]"},
    {"ball.to_world", "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0.5,1]"},
    {"box.to_world", "[1,0,0,1e30, 0,1,0,0, 0,0,1,0, 0,0,0,1]"},
    {"box.vertex_positions", NULL}, /* one vertex at 1e30 */
};

static void test_update_refused(void) {
  scene *s = tsup_load(BASE, NULL);
  REQUIRE(s, "load");
  film_image before = {0};
  REQUIRE(render(s, &before), "render before");
  char *snap = params_snapshot(s);
  for (size_t i = 0; i < sizeof UPDS / sizeof UPDS[0]; i++) {
    const upd_case *c = &UPDS[i];
    char big[4096];
    const char *json = c->value;
    if (!json) {
      /* The cube's 24 vertices, the first moved to 1e30. */
      size_t n = 0;
      n += (size_t)snprintf(big + n, sizeof big - n, "[1e30, 0, 0");
      for (int k = 1; k < 24; k++) n += (size_t)snprintf(big + n, sizeof big - n, ", 0, 0, 0");
      snprintf(big + n, sizeof big - n, "]");
      json = big;
    }
    param_update u = {.key = c->key};
    rsw_err err = {0};
    if (param_value_parse(json, c->key, &u.value, &err)) {
      CHECK(false, "%s: parse: %s", c->key, err.msg);
      continue;
    }
    rsw_status st = scene_update(s, &u, 1, NULL, &err);
    param_value_free(&u.value);
    CHECK(st != RSW_OK, "case %zu %s: accepted", i, c->key);
    CHECK(strcmp(err.where, c->key) == 0, "case %zu: where '%s', not the key %s (%s)", i, err.where, c->key,
          err.msg);
    char *now = params_snapshot(s);
    CHECK(strcmp(now, snap) == 0, "case %zu %s: parameters changed", i, c->key);
    free(now);
    film_image after = {0};
    CHECK(render(s, &after) && same_film(&before, &after), "case %zu %s: render differs", i, c->key);
    film_image_free(&after);
  }
  free(snap);
  film_image_free(&before);
  scene_free(s);
}

/* Vertices and a to_world each fine alone, together beyond what float32
 * tracing represents: only accel.c's scene-wide check sees it, after the
 * values were written. The update must come back as an error and put
 * everything back: parameters bitwise, the acceleration structure (the
 * render) exactly. */
static void test_update_rolled_back(void) {
  scene *s = tsup_load(BASE, NULL);
  REQUIRE(s, "load");
  film_image before = {0};
  REQUIRE(render(s, &before), "render before");
  char *snap = params_snapshot(s);
  char pos[4096];
  size_t n = 0;
  n += (size_t)snprintf(pos + n, sizeof pos - n, "[1e8, 1e8, 1e8");
  for (int k = 1; k < 24; k++) n += (size_t)snprintf(pos + n, sizeof pos - n, ", -1e8, -1e8, -1e8");
  snprintf(pos + n, sizeof pos - n, "]");
  param_update u[2] = {{.key = "box.vertex_positions"}, {.key = "box.to_world"}};
  rsw_err err = {0};
  REQUIRE(param_value_parse(pos, u[0].key, &u[0].value, &err) == RSW_OK, "parse");
  REQUIRE(param_value_parse("[1e8,0,0,0, 0,1e8,0,0, 0,0,1e8,0, 0,0,0,1]", u[1].key, &u[1].value, &err) ==
              RSW_OK,
          "parse");
  rsw_status st = scene_update(s, u, 2, NULL, &err);
  param_value_free(&u[0].value);
  param_value_free(&u[1].value);
  CHECK(st != RSW_OK, "accepted");
  CHECK(strstr(err.msg, "float32") != NULL, "message: %s", err.msg);
  char *now = params_snapshot(s);
  CHECK(strcmp(now, snap) == 0, "parameters changed");
  free(now);
  film_image after = {0};
  CHECK(render(s, &after) && same_film(&before, &after), "render differs after the failed update");
  film_image_free(&after);
  /* And the scene still takes a good update. */
  param_update ok = {.key = "box.to_world"};
  REQUIRE(param_value_parse("[0.5,0,0,2.5, 0,0.5,0,0, 0,0,0.5,0, 0,0,0,1]", ok.key, &ok.value, &err) ==
              RSW_OK,
          "parse");
  CHECK(scene_update(s, &ok, 1, NULL, &err) == RSW_OK, "good update: %s", err.msg);
  param_value_free(&ok.value);
  free(snap);
  film_image_free(&before);
  scene_free(s);
}

/* ---- rays from far away --------------------------------------------------------- */

/* A camera 5e13 from a 1e-5 sphere: the ray origin in the sphere's object
 * space is 5e18 units away, beyond Embree's range before accel.c advanced
 * far origins to the scene (the binary aborted). The sphere is far below
 * a pixel from there: the film is the sky. */
static void test_far_camera(void) {
  const char *text = "{\"type\": \"scene\", \"variant\": \"mono\", \"cam\": {\"type\": \"perspective\", "
                     "\"fov\": 40, \"to_world\": [1,0,0,0, 0,1,0,0, 0,0,-1,5e13, 0,0,0,1], \"sampler\": "
                     "{\"type\": \"independent\", \"sample_count\": 4}, " FILM8 "}, " SKY ", "
                     "\"ball\": {\"type\": \"sphere\", \"radius\": 1e-5}}";
  scene *s = tsup_load(text, NULL);
  REQUIRE(s, "load");
  film_image img = {0};
  CHECK(render(s, &img), "render");
  double mean, sem;
  tsup_stats(&img, 0, &mean, &sem);
  CHECK_REL(mean, 1.0, 1e-6);
  film_image_free(&img);
  scene_free(s);
}

/* An instancelist row float32 tracing cannot place (a scale of 1e-10, which
 * the old invertibility check let through): refused with its line. */
static void test_instancelist_row(void) {
  char path[] = "/tmp/rsw_traceable_XXXXXX";
  int fd = mkstemp(path);
  REQUIRE(fd >= 0, "mkstemp");
  FILE *f = fdopen(fd, "w");
  fprintf(f, "1 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1\n1e-10 0 0 0  0 1e-10 0 0  0 0 1e-10 0  0 0 0 1\n");
  fclose(f);
  char text[2048];
  snprintf(text, sizeof text,
           "{\"type\": \"scene\", " CAM ", " SKY ", \"g\": {\"type\": \"shapegroup\", \"leaf\": {\"type\": "
           "\"disk\"}}, \"l\": {\"type\": \"instancelist\", \"shapegroup\": {\"type\": \"ref\", \"id\": "
           "\"g\"}, \"filename\": \"%s\"}}",
           path);
  scene *s = NULL;
  rsw_err err = {0};
  rsw_status st = load_text(text, false, &s, &err);
  CHECK(st != RSW_OK, "loaded");
  char want[300];
  snprintf(want, sizeof want, "%s:2", path);
  CHECK(strstr(err.where, want) != NULL, "where '%s' (%s)", err.where, err.msg);
  scene_free(s);
  unlink(path);
}

int main(void) {
  RSW_TEST_RUN(test_load_refused);
  RSW_TEST_RUN(test_load_accepted);
  RSW_TEST_RUN(test_update_refused);
  RSW_TEST_RUN(test_update_rolled_back);
  RSW_TEST_RUN(test_far_camera);
  RSW_TEST_RUN(test_instancelist_row);
  RSW_TEST_END("test_traceable");
}
