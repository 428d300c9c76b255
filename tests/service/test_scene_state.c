/* A document yields its own state (issue 24; docs/daemon.md#a-document-yields-its-own-state),
 * in process:
 *  - pushing a document again after a PATCH of its scene gives a scene in
 *    the document's state (before the fix: "already resident", the
 *    PATCHed reflectance), and never the changed one; an unchanged one is
 *    shared as before;
 *  - POST :reset sets a scene back to its document's state: renders
 *    bitwise those of a fresh load (a geometric and a spectral key), the
 *    revision moves, and the document's pushes get it again;
 *  - POST :copy makes a scene in another's current state that is its
 *    own: PATCHes of either leave the other alone, and pushes never get it;
 *  - with a state directory, all of it survives a restart;
 *  - a document's name (?name=, from `raysweep scene push FILE`) is what
 *    messages about its XML name, not scene.xml. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cjson/cJSON.h>

#include "../../server/service/service.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

static const char *PLATE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"hdistant\","
    "   \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 0], \"target\": [0, 0, 1], \"up\": [0, 1, 0]}}],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4, \"component_format\": \"float32\"}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0.3, 0, -1], \"irradiance\": 1.0},"
    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";

static service *g_svc;

/* Push PLATE: the id (owned), *created; NULL on failure. */
static char *push(service *svc, bool *created) {
  char *id = NULL, *json = NULL;
  svc_error e = {0};
  bool c = false;
  if (service_scene_post(svc, PLATE, strlen(PLATE), false, NULL, &c, &id, &json, &e)) {
    printf("  push: %s\n", e.err.msg);
    return NULL;
  }
  free(json);
  if (created) *created = c;
  return id;
}

static bool patch(service *svc, const char *id, const char *body) {
  char *json = NULL;
  uint64_t rev;
  svc_error e = {0};
  rsw_status st = service_params_patch(svc, id, body, strlen(body), -1, &json, &rev, &e);
  if (st) printf("  patch %s: %s\n", body, e.err.msg);
  free(json);
  return st == RSW_OK;
}

/* The 16 values of a render (spp 8, seed 3); false on failure. */
static bool render(service *svc, const char *id, float out[16]) {
  const char *q = "{\"spp\": 8, \"seed\": 3}";
  svc_film f;
  svc_error e = {0};
  if (service_render(svc, id, q, strlen(q), NULL, &f, &e)) {
    printf("  render: %s\n", e.err.msg);
    return false;
  }
  bool ok = f.img.width == 4 && f.img.height == 4 && f.img.channels >= 1;
  for (int i = 0; ok && i < 16; i++) out[i] = f.img.data[(size_t)i * f.img.channels];
  svc_film_free(&f);
  return ok;
}

/* A number from a scene's summary (GET), or NAN. */
static double summary_num(service *svc, const char *id, const char *key) {
  char *json = NULL;
  svc_error e = {0};
  if (service_scene_get(svc, id, &json, &e)) return NAN;
  cJSON *j = cJSON_Parse(json);
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(j, key);
  double d = cJSON_IsNumber(v) ? v->valuedouble : cJSON_IsBool(v) ? cJSON_IsTrue(v) : NAN;
  cJSON_Delete(j);
  free(json);
  return d;
}

static bool summary_str(service *svc, const char *id, const char *key, char out[80]) {
  char *json = NULL;
  svc_error e = {0};
  out[0] = '\0';
  if (service_scene_get(svc, id, &json, &e)) return false;
  cJSON *j = cJSON_Parse(json);
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(j, key);
  if (cJSON_IsString(v)) snprintf(out, 80, "%s", v->valuestring);
  cJSON_Delete(j);
  free(json);
  return out[0] != '\0';
}

/* The plate's reflectance in the parameter table. */
static double reflectance(service *svc, const char *id) {
  char *json = NULL;
  uint64_t rev;
  svc_error e = {0};
  if (service_params_get(svc, id, "plate.bsdf.reflectance.value", NULL, &json, &rev, &e)) return NAN;
  cJSON *j = cJSON_Parse(json);
  const cJSON *p = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(j, "params"), 0);
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(p, "value");
  double d = cJSON_IsNumber(v) ? v->valuedouble : NAN;
  cJSON_Delete(j);
  free(json);
  return d;
}

static void del(service *svc, const char *id) {
  svc_error e = {0};
  if (id) service_scene_delete(svc, id, true, &e);
}

static void test_push_yields_document_state(void) {
  service *svc = g_svc;
  bool created;
  char *a = push(svc, &created);
  REQUIRE(a && created, "push");
  float fa[16], fb[16];
  REQUIRE(render(svc, a, fa), "render the document");
  REQUIRE(patch(svc, a, "{\"plate.bsdf.reflectance.value\": 0.25}"), "patch");
  char *b = push(svc, &created);
  REQUIRE(b, "push again");
  CHECK(created, "a push after a PATCH loads a scene (not 'already resident')");
  CHECK(strcmp(a, b) != 0, "a push after a PATCH is not handed the changed scene");
  CHECK_REL(reflectance(svc, b), 0.5, 1e-12);
  CHECK(summary_num(svc, b, "revision") == 0, "the new scene is at revision 0");
  char doc[80];
  CHECK(summary_str(svc, b, "document", doc) && strcmp(doc, a) == 0, "its document is the twin's id: %s",
        doc);
  CHECK(summary_num(svc, b, "copy") == 0, "a fork is not a copy");
  CHECK(render(svc, b, fb) && memcmp(fa, fb, sizeof fa) == 0, "its render is bitwise the document's");
  CHECK_REL(reflectance(svc, a), 0.25, 1e-12);
  CHECK(summary_num(svc, a, "revision") == 1, "the twin keeps its revision");
  /* Unchanged, the new scene is shared as the twin was. */
  char *b2 = push(svc, &created);
  CHECK(b2 && !created && strcmp(b2, b) == 0,
        "a push while the fork is unchanged gets it (already resident)");
  /* Once it changes too, the next push gets another. */
  REQUIRE(patch(svc, b, "{\"plate.bsdf.reflectance.value\": 0.75}"), "patch the fork");
  char *c = push(svc, &created);
  CHECK(c && created && strcmp(c, a) != 0 && strcmp(c, b) != 0, "a third push gets a third scene");
  CHECK_REL(reflectance(svc, c), 0.5, 1e-12);
  del(svc, a), del(svc, b), del(svc, c);
  free(a), free(b), free(b2), free(c);
}

static void test_reset(void) {
  service *svc = g_svc;
  bool created;
  char *a = push(svc, &created);
  REQUIRE(a, "push");
  float doc[16], changed[16], back[16];
  REQUIRE(render(svc, a, doc), "render");
  REQUIRE(patch(svc, a,
                "{\"plate.bsdf.reflectance.value\": 0.25, "
                "\"plate.to_world\": [[0.5,0,0,0.2],[0,0.5,0,0],[0,0,1,0],[0,0,0,1]]}"),
          "patch a geometric and a spectral key");
  REQUIRE(render(svc, a, changed), "render changed");
  CHECK(memcmp(doc, changed, sizeof doc) != 0, "the PATCH changed the film");
  char *json = NULL;
  svc_error e = {0};
  REQUIRE(service_scene_reset(svc, a, &json, &e) == RSW_OK, "reset: %s", e.err.msg);
  cJSON *j = cJSON_Parse(json);
  const cJSON *keys = cJSON_GetObjectItemCaseSensitive(j, "keys");
  CHECK(cJSON_GetArraySize(keys) == 2, "the answer names the 2 keys set back: %s", json);
  CHECK(cJSON_GetObjectItemCaseSensitive(j, "revision")->valuedouble == 2, "revision 2: %s", json);
  cJSON_Delete(j);
  free(json), json = NULL;
  CHECK_REL(reflectance(svc, a), 0.5, 1e-12);
  CHECK(render(svc, a, back) && memcmp(doc, back, sizeof doc) == 0,
        "after the reset the film is bitwise the document's");
  /* Back in the document's state, the twin is handed to pushes again. */
  char *b = push(svc, &created);
  CHECK(b && !created && strcmp(a, b) == 0, "a push after the reset gets the twin");
  /* A reset of a scene in its document's state changes nothing. */
  REQUIRE(service_scene_reset(svc, a, &json, &e) == RSW_OK, "reset again: %s", e.err.msg);
  CHECK(strstr(json, "\"revision\":2") && strstr(json, "\"keys\":[]"), "nothing to reset: %s", json);
  free(json);
  svc_error e2 = {0};
  CHECK(service_scene_reset(svc, "0000000000000000000000000000000000000000000000000000000000000000", &json,
                            &e2) == RSW_ERR_NOT_FOUND,
        "reset of an unknown scene: 404");
  del(svc, a);
  free(a), free(b);
}

static void test_copy(void) {
  service *svc = g_svc;
  bool created;
  char *a = push(svc, &created);
  REQUIRE(a, "push");
  REQUIRE(patch(svc, a, "{\"plate.bsdf.reflectance.value\": 0.3}"), "patch");
  char *c = NULL, *json = NULL;
  svc_error e = {0};
  REQUIRE(service_scene_copy(svc, a, &c, &json, &e) == RSW_OK, "copy: %s", e.err.msg);
  free(json);
  CHECK(strcmp(c, a) != 0, "a copy has an id of its own");
  CHECK_REL(reflectance(svc, c), 0.3, 1e-12);
  CHECK(summary_num(svc, c, "copy") == 1, "copy: true");
  float fa[16], fc[16];
  CHECK(render(svc, a, fa) && render(svc, c, fc) && memcmp(fa, fc, sizeof fa) == 0,
        "the copy renders bitwise as its source");
  REQUIRE(patch(svc, c, "{\"plate.bsdf.reflectance.value\": 0.7}"), "patch the copy");
  CHECK_REL(reflectance(svc, a), 0.3, 1e-12);
  REQUIRE(patch(svc, a, "{\"plate.bsdf.reflectance.value\": 0.1}"), "patch the source");
  CHECK_REL(reflectance(svc, c), 0.7, 1e-12);
  /* A copy in the document's state is still never handed to a pusher. */
  char *json2 = NULL;
  REQUIRE(service_scene_reset(svc, c, &json2, &e) == RSW_OK, "reset the copy: %s", e.err.msg);
  free(json2);
  char *p = push(svc, &created);
  CHECK(p && created && strcmp(p, c) != 0 && strcmp(p, a) != 0, "a push gets neither the copy nor the twin");
  del(svc, a), del(svc, c), del(svc, p);
  free(a), free(c), free(p);
}

/* The XML reader names the client's file, not scene.xml. */
static void test_xml_name(void) {
  service *svc = g_svc;
  const char *xml = "<scene version=\"3.0.0\">\n  <shape type=\"rectangle\">\n    <bsdf type=\"nope\"/>\n"
                    "  </shape>\n</scene>\n";
  bool created;
  char *id = NULL, *json = NULL;
  svc_error e = {0};
  CHECK(service_scene_post_named(svc, xml, strlen(xml), true, NULL, "my_canopy.xml", &created, &id, &json,
                                 &e) != RSW_OK,
        "a bad XML scene is refused");
  CHECK(strncmp(e.err.where, "my_canopy.xml:3", 15) == 0, "the error names the user's file: '%s' %s",
        e.err.where, e.err.msg);
  CHECK(!strstr(e.err.where, "scene.xml") && !strstr(e.err.msg, "scene.xml"), "no scene.xml: %s: %s",
        e.err.where, e.err.msg);
  svc_error e2 = {0};
  CHECK(service_scene_post_named(svc, xml, strlen(xml), true, NULL, "a/b.xml", &created, &id, &json, &e2) ==
                RSW_ERR_BAD_REQUEST &&
            strcmp(e2.err.where, "name") == 0,
        "a name with a slash: 400 naming name (%s)", e2.err.msg);
  free(id), free(json);
}

/* Forks, copies and resets through a restart on a state directory. */
static void test_state_dir(void) {
  char dir[] = "/tmp/rsw-scene-state-XXXXXX";
  REQUIRE(mkdtemp(dir), "mkdtemp");
  service_opts o = {.size = sizeof o, .render_threads = 1, .state_dir = dir};
  service *svc = NULL;
  rsw_err err = {0};
  REQUIRE(service_new(&o, &svc, &err) == RSW_OK, "service_new: %s", err.msg);
  bool created;
  char *a = push(svc, &created);
  REQUIRE(a, "push");
  REQUIRE(patch(svc, a, "{\"plate.bsdf.reflectance.value\": 0.25}"), "patch");
  char *b = push(svc, &created); /* a fork in the document's state */
  char *c = NULL, *json = NULL;
  svc_error e = {0};
  REQUIRE(b && service_scene_copy(svc, a, &c, &json, &e) == RSW_OK, "copy: %s", e.err.msg);
  free(json);
  REQUIRE(patch(svc, c, "{\"plate.bsdf.reflectance.value\": 0.6}"), "patch the copy");
  service_free(svc);

  svc = NULL;
  REQUIRE(service_new(&o, &svc, &err) == RSW_OK, "service_new again: %s", err.msg);
  service_restore(svc);
  CHECK_REL(reflectance(svc, a), 0.25, 1e-12);
  CHECK(summary_num(svc, a, "revision") == 1, "the twin at revision 1");
  CHECK_REL(reflectance(svc, b), 0.5, 1e-12);
  char doc[80];
  CHECK(summary_str(svc, b, "document", doc) && strcmp(doc, a) == 0, "the fork's document after a restart");
  CHECK_REL(reflectance(svc, c), 0.6, 1e-12);
  CHECK(summary_num(svc, c, "copy") == 1, "the copy is a copy after a restart");
  /* The twin (stored, changed) is not handed out even when not resident:
   * a fresh service, nothing loaded yet, then a push. */
  service_free(svc);
  svc = NULL;
  REQUIRE(service_new(&o, &svc, &err) == RSW_OK, "service_new a third time: %s", err.msg);
  service_restore(svc);
  char *p = push(svc, &created);
  CHECK(p && strcmp(p, a) != 0, "a push after a restart is not handed the stored, changed twin");
  CHECK(p && reflectance(svc, p) == 0.5, "the push is in the document's state");
  /* A reset is stored too. */
  char *rj = NULL;
  REQUIRE(service_scene_reset(svc, a, &rj, &e) == RSW_OK, "reset: %s", e.err.msg);
  free(rj);
  service_free(svc);
  svc = NULL;
  REQUIRE(service_new(&o, &svc, &err) == RSW_OK, "service_new a fourth time: %s", err.msg);
  service_restore(svc);
  CHECK_REL(reflectance(svc, a), 0.5, 1e-12);
  CHECK(summary_num(svc, a, "revision") == 2, "the reset's revision after a restart");
  char *q = push(svc, &created);
  CHECK(q && strcmp(q, a) == 0 && !created, "after the stored reset, a push gets the twin");
  service_free(svc);
  free(a), free(b), free(c), free(p), free(q);
  char cmd[200];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  CHECK(system(cmd) == 0, "rm");
}

int main(void) {
  service_opts o = {.size = sizeof o, .render_threads = 2};
  rsw_err err = {0};
  if (service_new(&o, &g_svc, &err)) {
    printf("service_new: %s\n", err.msg);
    return 1;
  }
  RSW_TEST_RUN(test_push_yields_document_state);
  RSW_TEST_RUN(test_reset);
  RSW_TEST_RUN(test_copy);
  RSW_TEST_RUN(test_xml_name);
  service_free(g_svc);
  RSW_TEST_RUN(test_state_dir);
  RSW_TEST_END("test_scene_state");
}
