/* The service layer in process (no HTTP): scene ids, parameter patches
 * with revisions, synchronous renders with overrides that leave the base
 * state untouched, jobs with per-context wavelengths and events, and the
 * wavelength checks of a job's overrides. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../server/service/service.h"
#include "../support/svc_job.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

static const char *PLATE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"component_format\": \"float32\"}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.0},"
    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";

static service *svc;

static void test_scene_ids(void) {
  bool created = false;
  char *id = NULL, *json = NULL, *id2 = NULL, *json2 = NULL;
  svc_error e = {0};
  REQUIRE(service_scene_post(svc, PLATE, strlen(PLATE), false, NULL, &created, &id, &json, &e) == RSW_OK,
          "post: %s", e.err.msg);
  CHECK(created, "first post creates");
  CHECK(strlen(id) == 64, "id is a SHA-256 hex digest");
  /* Same document with other whitespace: same canonical form, same id. */
  char *spaced = malloc(strlen(PLATE) + 8);
  sprintf(spaced, "  %s\n\n", PLATE);
  REQUIRE(service_scene_post(svc, spaced, strlen(spaced), false, NULL, &created, &id2, &json2, &e) == RSW_OK,
          "repost: %s", e.err.msg);
  CHECK(!created, "reposting the same scene is a no-op");
  CHECK(strcmp(id, id2) == 0, "same id");
  free(id2), free(json2);
  /* Another variant is another scene. */
  REQUIRE(service_scene_post(svc, PLATE, strlen(PLATE), false, "rgb", &created, &id2, &json2, &e) == RSW_OK,
          "rgb");
  CHECK(created && strcmp(id, id2) != 0, "variant is part of the id");
  CHECK(service_scene_delete(svc, id2, false, &e) == RSW_OK, "delete");
  free(id2), free(json2), free(spaced), free(id), free(json);
  /* A bad scene names the place. */
  svc_error e2 = {0};
  char *i3 = NULL, *j3 = NULL;
  CHECK(service_scene_post(svc, "{\"s\": {\"type\": \"nope\"}}", 23, false, NULL, &created, &i3, &j3, &e2) !=
            RSW_OK,
        "unknown plugin rejected");
  CHECK(rsw_status_http(e2.err.code) == 422 && strstr(e2.err.where, "/s"), "422 with pointer: %d %s",
        rsw_status_http(e2.err.code), e2.err.where);
}

/* Post a scene document; its id (owned), or NULL after a failed check. */
static char *post_doc(const char *doc) {
  bool created;
  char *id = NULL, *json = NULL;
  svc_error e = {0};
  rsw_status st = service_scene_post(svc, doc, strlen(doc), false, NULL, &created, &id, &json, &e);
  CHECK(st == RSW_OK, "post: %s", e.err.msg);
  free(json);
  return st ? NULL : id;
}

static char *post_plate(void) {
  return post_doc(PLATE);
}

static void test_render_overrides_restore_base(void) {
  char *id = post_plate();
  REQUIRE(id, "scene");
  svc_film a, b, c;
  svc_error e = {0};
  const char *q1 = "{\"spp\": 4, \"seed\": 1}";
  const char *q2 = "{\"spp\": 4, \"seed\": 1, \"params\": {\"plate.bsdf.reflectance.value\": 0.25}}";
  REQUIRE(service_render(svc, id, q1, strlen(q1), NULL, &a, &e) == RSW_OK, "render: %s", e.err.msg);
  REQUIRE(service_render(svc, id, q2, strlen(q2), NULL, &b, &e) == RSW_OK, "render with override: %s",
          e.err.msg);
  REQUIRE(service_render(svc, id, q1, strlen(q1), NULL, &c, &e) == RSW_OK, "render again: %s", e.err.msg);
  CHECK_REL(a.img.data[0], 0.5 / 3.14159265358979323846, 1e-5);
  CHECK_REL(b.img.data[0], 0.25 / 3.14159265358979323846, 1e-5);
  CHECK(memcmp(a.img.data, c.img.data, sizeof(float)) == 0, "the override did not leak into the base state");
  svc_film_free(&a), svc_film_free(&b), svc_film_free(&c);
  /* Unknown key: 422 naming it, with candidates. */
  const char *q3 = "{\"params\": {\"plate.bsdf.reflectanse.value\": 0.25}}";
  svc_error e3 = {0};
  svc_film d;
  CHECK(service_render(svc, id, q3, strlen(q3), NULL, &d, &e3) != RSW_OK, "unknown key rejected");
  CHECK(strcmp(e3.key, "plate.bsdf.reflectanse.value") == 0, "key named: %s", e3.key);
  CHECK(strcmp(e3.candidates[0], "plate.bsdf.reflectance.value") == 0, "closest key first: %s",
        e3.candidates[0]);
  free(id);
}

/* A render with coords: the scene's templates and the request's render
 * into its overrides, as for a job's context (a render could take no
 * coords: a templated scene rendered its document's values). The plate
 * under a sun at zenith sza: rho cos(sza) / pi. */
static void test_render_coords(void) {
  static const char *doc =
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"templates\": {\"sun.direction\": {\"sun\": {\"zenith\": \"sza\", \"azimuth\": 0}},"
      "   \"plate.bsdf.reflectance.value\": {\"coord\": \"wavelength\", \"x\": [400, 700], \"y\": [0.2, "
      "0.8]}},"
      " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.0},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";
  char *id = post_doc(doc);
  REQUIRE(id, "scene");
  svc_error e = {0};
  const double pi = 3.14159265358979323846;
  struct {
    const char *body;
    double want;
  } ok[] = {
      /* the sun from sza; the reflectance table at the render's wavelength (550: 0.5) */
      {"{\"coords\": {\"sza\": 60}, \"spp\": 4}", 0.5 * 0.5 / pi},
      /* coords.wavelength is the render's wavelength */
      {"{\"coords\": {\"sza\": 0, \"wavelength\": 700}, \"spp\": 4}", 0.8 / pi},
      /* the request's params win over the scene's template */
      {"{\"coords\": {\"sza\": 60}, \"params\": {\"plate.bsdf.reflectance.value\": 0.3}, \"spp\": 4}",
       0.3 * 0.5 / pi},
      /* the request's template replaces the scene's for its key */
      {"{\"coords\": {\"sza\": 60, \"vza\": 0}, \"spp\": 4, \"templates\": {\"sun.direction\": {\"sun\": "
       "{\"zenith\": \"vza\", \"azimuth\": 0}}}}",
       0.5 / pi},
  };
  for (size_t i = 0; i < sizeof ok / sizeof ok[0]; i++) {
    svc_film f;
    e = (svc_error){0};
    rsw_status st = service_render(svc, id, ok[i].body, strlen(ok[i].body), NULL, &f, &e);
    CHECK(st == RSW_OK, "%s: %s at %s", ok[i].body, e.err.msg, e.err.where);
    if (st) continue;
    CHECK_REL(f.img.data[0], ok[i].want, 1e-5);
    svc_film_free(&f);
  }
  struct {
    const char *body, *where, *says;
  } bad[] = {
      {"{\"coords\": {\"sz\": 60}}", "/coords/sz", "no template reads the coordinate 'sz'"},
      {"{\"coords\": {\"sza\": 200}}", "/coords/sza", "outside [0, 180]"},
      {"{\"coords\": {}}", "/coords/sza", "sza"},
      {"{\"coords\": {\"sza\": 0, \"wavelength\": 700}, \"wavelength\": 500}", "/coords/wavelength",
       "differs"},
      {"{\"coords\": [60]}", "/coords", "coords must be an object"},
      {"{\"coords\": {\"sza\": 10}, \"templates\": {\"sun.direction\": {\"value\": [0, 0, 0]}}}",
       "/templates/sun.direction", "rendered for /coords"},
      {"{\"coords\": {\"sza\": 10}, \"templates\": {\"sun.directio\": {\"value\": [0, 0, -1]}}}",
       "/templates/sun.directio", "sun.direction"},
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    svc_film f;
    e = (svc_error){0};
    rsw_status st = service_render(svc, id, bad[i].body, strlen(bad[i].body), NULL, &f, &e);
    CHECK(st != RSW_OK && strcmp(e.err.where, bad[i].where) == 0 &&
              (strstr(e.err.msg, bad[i].says) || strcmp(e.candidates[0], bad[i].says) == 0),
          "%s: %s: %s at %s", bad[i].body, rsw_status_name(st), e.err.msg, e.err.where);
    if (!st) svc_film_free(&f);
  }
  /* Without coords a templated scene renders its document's values, as before. */
  svc_film f;
  e = (svc_error){0};
  const char *plain = "{\"spp\": 4}";
  REQUIRE(service_render(svc, id, plain, strlen(plain), NULL, &f, &e) == RSW_OK, "plain: %s", e.err.msg);
  CHECK_REL(f.img.data[0], 0.5 / pi, 1e-5);
  svc_film_free(&f);
  free(id);
}

/* A sensor that names nothing: the answer names the closest id and the
 * scene's sensors (it said only "no sensor 'metr' in the scene"), in a
 * render and in a job's context. */
static void test_unknown_sensor(void) {
  char *id = post_plate();
  REQUIRE(id, "scene");
  svc_film f;
  svc_error e = {0};
  const char *q = "{\"sensor\": \"metr\"}";
  CHECK(service_render(svc, id, q, strlen(q), NULL, &f, &e) == RSW_ERR_UNKNOWN_NAME, "a misspelt sensor");
  CHECK(strcmp(e.err.where, "/sensor") == 0 && strstr(e.err.msg, "did you mean 'meter'?") &&
            strstr(e.err.msg, "its sensors: meter"),
        "render: %s at %s", e.err.msg, e.err.where);
  CHECK(strcmp(e.candidates[0], "meter") == 0, "candidate: '%s'", e.candidates[0]);
  e = (svc_error){0};
  q = "{\"sensor\": 3}";
  CHECK(service_render(svc, id, q, strlen(q), NULL, &f, &e) == RSW_ERR_UNKNOWN_NAME, "an index past the end");
  CHECK(!strstr(e.err.msg, "did you mean") && strstr(e.err.msg, "its sensors: meter; an index counts from 0"),
        "render by index: %s", e.err.msg);
  e = (svc_error){0};
  const char *job =
      "{\"contexts\": [{\"id\": \"a\", \"wavelength\": 550, \"sensors\": [\"meter\", \"mter\"]}]}";
  char *job_id = NULL, *json = NULL;
  CHECK(service_job_submit(svc, id, job, strlen(job), NULL, &job_id, &json, &e) == RSW_ERR_UNKNOWN_NAME,
        "a job's sensor");
  CHECK(strcmp(e.err.where, "/contexts/0/sensors/1") == 0 && strstr(e.err.msg, "did you mean 'meter'?"),
        "job: %s at %s", e.err.msg, e.err.where);
  free(job_id);
  free(json);
  free(id);
}

static void test_patch_revisions(void) {
  char *id = post_plate();
  REQUIRE(id, "scene");
  char *json = NULL;
  uint64_t rev = 0, rev2 = 0;
  svc_error e = {0};
  REQUIRE(service_params_get(svc, id, "*", NULL, &json, &rev, &e) == RSW_OK, "get");
  free(json);
  const char *patch = "{\"plate.bsdf.reflectance.value\": 0.3}";
  REQUIRE(service_params_patch(svc, id, patch, strlen(patch), (int64_t)rev, &json, &rev2, &e) == RSW_OK,
          "patch: %s", e.err.msg);
  free(json);
  CHECK(rev2 == rev + 1, "revision advances: %llu -> %llu", (unsigned long long)rev,
        (unsigned long long)rev2);
  svc_error e2 = {0};
  CHECK(service_params_patch(svc, id, patch, strlen(patch), (int64_t)rev, &json, &rev2, &e2) ==
            RSW_ERR_PRECONDITION,
        "stale If-Match");
  CHECK(rsw_status_http(e2.err.code) == 412, "412");
  /* Back to 0.5 so the other tests see the base scene. */
  const char *back = "{\"plate.bsdf.reflectance.value\": 0.5}";
  svc_error e3 = {0};
  CHECK(service_params_patch(svc, id, back, strlen(back), -1, &json, &rev2, &e3) == RSW_OK, "patch back");
  free(json);
  free(id);
}

/* A PATCH through a search key, then through the path, then the search key
 * again: the record views replay names the entry once, so a render (or a
 * job) overriding it by its path renders the override (the film equals a
 * render of the scene PATCHed to the same value) and views reproduce the
 * last PATCH. */
static void test_patch_search_key_then_override_by_path(void) {
  static const char *doc =
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"meter\": {\"type\": \"distant\", \"direction\": [0, 0, -1], \"target\": [0, 0, 0],"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"component_format\": \"float32\"}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.0},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}}}";
  char *id = post_doc(doc), *json = NULL;
  REQUIRE(id, "scene");
  svc_error e = {0};
  static const char *const patches[] = {"{\"texture:bsdf:value\": 0.4}",
                                        "{\"plate.bsdf.reflectance.value\": 0.3}",
                                        "{\"texture:bsdf:value\": 0.35}"};
  uint64_t rev;
  for (size_t k = 0; k < 3; k++) {
    REQUIRE(service_params_patch(svc, id, patches[k], strlen(patches[k]), -1, &json, &rev, &e) == RSW_OK,
            "patch %s: %s", patches[k], e.err.msg);
    free(json);
  }
  svc_film a, b, c;
  const char *q1 = "{\"spp\": 4, \"seed\": 1, \"params\": {\"plate.bsdf.reflectance.value\": 0.2}}";
  const char *q2 = "{\"spp\": 4, \"seed\": 1, \"params\": {\"sun.irradiance.value\": 1.0}}";
  const char *q3 = "{\"spp\": 4, \"seed\": 1}";
  REQUIRE(service_render(svc, id, q1, strlen(q1), NULL, &a, &e) == RSW_OK, "render with override by path: %s",
          e.err.msg);
  CHECK_REL(a.img.data[0], 0.2 / 3.14159265358979323846, 1e-5);
  /* A view (any override) replays the last PATCH. */
  REQUIRE(service_render(svc, id, q2, strlen(q2), NULL, &b, &e) == RSW_OK, "render on a view: %s", e.err.msg);
  CHECK_REL(b.img.data[0], 0.35 / 3.14159265358979323846, 1e-5);
  const char *p02 = "{\"plate.bsdf.reflectance.value\": 0.2}";
  REQUIRE(service_params_patch(svc, id, p02, strlen(p02), -1, &json, &rev, &e) == RSW_OK, "patch 0.2: %s",
          e.err.msg);
  free(json);
  REQUIRE(service_render(svc, id, q3, strlen(q3), NULL, &c, &e) == RSW_OK, "render: %s", e.err.msg);
  CHECK(memcmp(a.img.data, c.img.data, sizeof(float)) == 0, "override film %.9g != PATCHed film %.9g",
        a.img.data[0], c.img.data[0]);
  svc_film_free(&a), svc_film_free(&b), svc_film_free(&c);
  CHECK(service_scene_delete(svc, id, false, &e) == RSW_OK, "delete");
  free(id);
}

static void test_job_spectral_loop(void) {
  char *id = post_plate();
  REQUIRE(id, "scene");
  /* Job-level tabulated reflectance, evaluated at each context's wavelength. */
  char body[8192];
  size_t n = (size_t)snprintf(body, sizeof body,
                              "{\"seed\": 3, \"params\": {\"plate.bsdf.reflectance.value\": "
                              "{\"wavelengths\": [400, 700], \"values\": [0.2, 0.8]}}, \"contexts\": [");
  for (int i = 0; i < 10; i++)
    n += (size_t)snprintf(body + n, sizeof body - n, "%s{\"id\": \"w%d\", \"wavelength\": %d, \"spp\": 2}",
                          i ? ", " : "", i, 400 + 30 * i);
  snprintf(body + n, sizeof body - n, "]}");
  char *jid = NULL, *json = NULL;
  svc_error e = {0};
  REQUIRE(service_job_submit(svc, id, body, strlen(body), NULL, &jid, &json, &e) == RSW_OK, "submit: %s",
          e.err.msg);
  free(json);
  /* Follow the events to the end. */
  uint64_t after = 0, seq;
  bool end = false;
  int contexts = 0;
  for (int guard = 0; !end && guard < 200; guard++) {
    char *ev = NULL;
    REQUIRE(service_job_next_event(svc, jid, after, 5000, &seq, &ev, &end, &e) == RSW_OK, "events");
    if (!ev) continue;
    after = seq;
    if (!end) contexts++;
    free(ev);
  }
  CHECK(end && contexts == 10, "10 context events then end (%d)", contexts);
  for (int i = 0; i < 10; i++) {
    char ctx[16];
    snprintf(ctx, sizeof ctx, "w%d", i);
    svc_film f;
    REQUIRE(service_job_result(svc, jid, ctx, "meter", &f, &e) == RSW_OK, "result %s: %s", ctx, e.err.msg);
    double w = 400 + 30 * i, rho = 0.2 + 0.6 * (w - 400) / 300;
    CHECK_REL(f.img.data[0], rho / 3.14159265358979323846, 1e-5);
    svc_film_free(&f);
  }
  /* The base state is untouched by job-level overrides. */
  char *tab = NULL;
  uint64_t rev;
  REQUIRE(service_params_get(svc, id, "plate.bsdf.reflectance.value", NULL, &tab, &rev, &e) == RSW_OK, "get");
  CHECK(strstr(tab, "\"value\":0.5") != NULL, "base value still 0.5: %s", tab);
  free(tab);
  free(jid);
  free(id);
}

/* A context's overrides against its wavelength (jobs.c, table_range): a
 * transform written as 4 rows of 4 is no spectrum table (it was taken
 * for [[wl, value], ...] and the job refused: "wavelength 550 nm lies
 * outside the table of 'meter.to_world' [1, 0] nm"); a table written
 * {"type": "spectrum", "value": [[wl, v], ...]} is one, and a wavelength
 * outside it is refused up front, naming the key (it was taken, and its
 * render failed; and a sweep over wavelengths with it was warned that the
 * wavelength changes nothing). */
static void test_job_override_tables(void) {
  char *id = post_plate();
  REQUIRE(id, "scene");
  /* the sensor turned about x by 180 degrees: it still looks down (-z) */
  const char *rows = "{\"contexts\": [{\"id\": \"r\", \"wavelength\": 550, \"spp\": 1, \"params\": "
                     "{\"meter.to_world\": [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]]}}]}";
  const char *table =
      "{\"params\": {\"plate.bsdf.reflectance.value\": {\"type\": \"spectrum\", \"value\": "
      "[[400, 0.2], [700, 0.8]]}}, \"contexts\": [{\"id\": \"t\", \"wavelength\": %d, \"spp\": 1}, "
      "{\"id\": \"u\", \"wavelength\": 500, \"spp\": 1}]}";
  svc_error e = {0};
  char *jid = svc_test_run_job(svc, id, rows), *json = NULL;
  CHECK(jid, "a transform as 4 rows of 4 is accepted");
  if (jid) {
    svc_film f;
    REQUIRE(service_job_result(svc, jid, "r", "meter", &f, &e) == RSW_OK, "result r: %s", e.err.msg);
    CHECK_REL(f.img.data[0], 0.5 / 3.14159265358979323846, 1e-6);
    svc_film_free(&f);
  }
  free(jid), jid = NULL;
  char body[512];
  snprintf(body, sizeof body, table, 800);
  memset(&e, 0, sizeof e);
  rsw_status st = service_job_submit(svc, id, body, strlen(body), NULL, &jid, &json, &e);
  CHECK(st == RSW_ERR_RANGE && strstr(e.err.msg, "plate.bsdf.reflectance.value") &&
            strstr(e.err.msg, "[400, 700]") && strcmp(e.err.where, "/contexts/0/wavelength") == 0,
        "800 nm against a table of [wl, value] pairs: %d %s (%s)", (int)st, e.err.msg, e.err.where);
  free(json), json = NULL;
  free(jid), jid = NULL;
  snprintf(body, sizeof body, table, 550);
  memset(&e, 0, sizeof e);
  st = service_job_submit(svc, id, body, strlen(body), NULL, &jid, &json, &e);
  CHECK(st == RSW_OK, "550 and 500 nm in it: %s", st ? e.err.msg : "accepted");
  /* (the table makes the wavelength matter: it was said not to) */
  CHECK(!json || !strstr(json, "wavelength_unused"), "no wavelength_unused warning: %s", json ? json : "");
  free(json);
  free(jid);
  free(id);
}

int main(void) {
  service_opts o = {.size = sizeof o, .render_threads = 2};
  rsw_err err = {0};
  if (service_new(&o, &svc, &err)) {
    printf("service_new: %s\n", err.msg);
    return 1;
  }
  RSW_TEST_RUN(test_scene_ids);
  RSW_TEST_RUN(test_render_overrides_restore_base);
  RSW_TEST_RUN(test_unknown_sensor);
  RSW_TEST_RUN(test_render_coords);
  RSW_TEST_RUN(test_patch_revisions);
  RSW_TEST_RUN(test_job_spectral_loop);
  RSW_TEST_RUN(test_patch_search_key_then_override_by_path);
  RSW_TEST_RUN(test_job_override_tables);
  service_free(svc);
  RSW_TEST_END("test_service");
}
