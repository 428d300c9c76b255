/* The wire gaps of issue 13 that the service owns, through the public
 * service API (server/service/service.h): every request body is read
 * strictly and every value a job will use is checked before the 202.
 *  - trailing garbage ("{} xyz") and an empty body are refused by PATCH,
 *    render, jobs and blobs:missing;
 *  - a context or default wavelength of 1e400 (inf) and an spp of 0 are
 *    refused at submit;
 *  - job-level and context parameter values are validated at submit (an
 *    accepted job must not fail on them later);
 *  - a \u0000 in a key, a sensor id or a scene's file name is refused, not
 *    cut short;
 *  - an unreadable blob's error does not show the server's blob directory;
 *  - one sensor named twice in a context's list (10,000 copies queued
 *    10,000 renders) is refused (the check is h-geom's, on main: this
 *    test fails on h-fuzz alone);
 *  - a context wavelength outside a tabulated spectrum it renders with is
 *    refused at submit (found by fuzz_job_body).
 * Each check names the field in the error (where, key or message). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../server/service/service.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

static service *svc;
static char dir[64], blob_dir[128], scene_id[72];

static const char scene_json[] =
    "{\"type\":\"scene\",\"variant\":\"mono\","
    "\"hd\":{\"type\":\"hdistant\",\"target\":[0,0,0],"
    "\"sampler\":{\"type\":\"independent\",\"sample_count\":2},"
    "\"film\":{\"type\":\"hdrfilm\",\"width\":2,\"height\":2,\"rfilter\":{\"type\":\"box\"}}},"
    "\"integrator\":{\"type\":\"path\",\"max_depth\":3},"
    "\"sun\":{\"type\":\"directional\",\"direction\":[0,0,-1],\"irradiance\":1.5},"
    "\"rectangle\":{\"type\":\"rectangle\",\"bsdf\":{\"type\":\"diffuse\",\"reflectance\":0.5}}}";

/* The error names `field` somewhere: where, key or message. */
static bool names(const svc_error *e, const char *field) {
  return strstr(e->err.where, field) || strstr(e->key, field) || strstr(e->err.msg, field);
}

#define REFUSED(st, e, field, what)                                                                          \
  CHECK((st) != RSW_OK && names(&(e), field),                                                                \
        "%s: status %d, where '%s', key '%s', message '%s' (wanted '%s')", what, (int)(st), (e).err.where,   \
        (e).key, (e).err.msg, field)

static rsw_status patch(const char *body, svc_error *e) {
  char *json = NULL;
  uint64_t rev;
  memset(e, 0, sizeof *e);
  rsw_status st = service_params_patch(svc, scene_id, body, strlen(body), -1, &json, &rev, e);
  free(json);
  return st;
}

static rsw_status render(const char *body, svc_error *e) {
  svc_film f;
  memset(&f, 0, sizeof f);
  memset(e, 0, sizeof *e);
  rsw_status st = service_render(svc, scene_id, body, strlen(body), NULL, &f, e);
  svc_film_free(&f);
  return st;
}

static rsw_status submit(const char *body, svc_error *e) {
  char *id = NULL, *json = NULL;
  memset(e, 0, sizeof *e);
  rsw_status st = service_job_submit(svc, scene_id, body, strlen(body), NULL, &id, &json, e);
  if (st == RSW_OK && id) {
    /* Accepted by mistake: cancel it so it does not linger. */
    char *j = NULL;
    svc_error e2 = {0};
    service_job_cancel(svc, id, &j, &e2);
    free(j);
  }
  free(id);
  free(json);
  return st;
}

static rsw_status missing(const char *body, svc_error *e) {
  char *json = NULL;
  memset(e, 0, sizeof *e);
  rsw_status st = service_blobs_missing(svc, body, strlen(body), &json, e);
  free(json);
  return st;
}

static void test_trailing_garbage(void) {
  svc_error e;
  REFUSED(patch("{} xyz", &e), e, "JSON", "PATCH {} xyz");
  REFUSED(patch("{}{}", &e), e, "JSON", "PATCH {}{}");
  REFUSED(render("{\"spp\":1} xyz", &e), e, "JSON", "render {} xyz");
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\"}]} xyz", &e), e, "JSON", "jobs {} xyz");
  REFUSED(missing("{\"digests\":[]} xyz", &e), e, "JSON", "blobs:missing {} xyz");
  /* Whitespace after the document is fine. */
  CHECK(patch("{} \r\n\t", &e) == RSW_OK, "PATCH with trailing blanks: %s", e.err.msg);
  CHECK(missing("{\"digests\":[]}\n", &e) == RSW_OK, "blobs:missing with a newline: %s", e.err.msg);
}

static void test_empty_body(void) {
  svc_error e;
  REFUSED(patch("", &e), e, "body", "PATCH empty");
  REFUSED(render("", &e), e, "body", "render empty");
  REFUSED(submit("", &e), e, "body", "jobs empty");
  REFUSED(missing("", &e), e, "body", "blobs:missing empty");
}

static void test_job_numbers(void) {
  svc_error e;
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\",\"wavelength\":1e400}]}", &e), e, "wavelength",
          "context 1e400");
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\"}],\"defaults\":{\"wavelength\":1e400}}", &e), e, "wavelength",
          "defaults 1e400");
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\"}],\"defaults\":{\"spp\":0}}", &e), e, "spp", "defaults.spp 0");
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\",\"spp\":0}]}", &e), e, "spp", "context spp 0");
  REFUSED(render("{\"wavelength\":1e400}", &e), e, "wavelength", "render 1e400");
}

static void test_job_params_at_submit(void) {
  svc_error e;
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\"}],\"params\":{\"rectangle.bsdf.reflectance.value\":-3}}", &e),
          e, "rectangle.bsdf.reflectance.value", "job-level reflectance -3");
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\"}],\"params\":{\"sun.direction\":[0,0,0]}}", &e), e,
          "sun.direction", "job-level direction 0");
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\"},{\"id\":\"b\",\"params\":{\"sun.direction\":[0,0,0]}}]}", &e),
          e, "sun.direction", "context direction 0");
  CHECK(strstr(e.err.where, "/contexts/1") != NULL, "the second context is named: where '%s'", e.err.where);
  /* A context may override a job-level value with a legal one. */
  CHECK(submit("{\"contexts\":[{\"id\":\"ok\",\"params\":{\"sun.irradiance.value\":2}}],"
               "\"params\":{\"rectangle.bsdf.reflectance.value\":0.2}}",
               &e) == RSW_OK,
        "a legal job: %s", e.err.msg);
}

static void test_nul(void) {
  svc_error e;
  REFUSED(patch("{\"sun.irradiance.value\\u0000x\": 2}", &e), e, "sun.irradiance.value",
          "PATCH key with NUL");
  REFUSED(render("{\"sensor\":\"hd\\u0000x\"}", &e), e, "sensor", "render sensor with NUL");
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\",\"sensors\":[\"hd\\u0000\"]}]}", &e), e, "sensors",
          "job sensor with NUL");
  bool created;
  char *id = NULL, *json = NULL;
  memset(&e, 0, sizeof e);
  static const char doc[] = "{\"type\":\"scene\",\"m\":{\"type\":\"obj\",\"filename\":\"m.obj\\u0000.ply\"}}";
  rsw_status st = service_scene_post(svc, doc, strlen(doc), false, NULL, &created, &id, &json, &e);
  REFUSED(st, e, "filename", "scene with a NUL in a file name");
  free(id);
  free(json);
}

static void test_blob_dir_not_shown(void) {
  /* A blob whose file is a directory: unreadable, even to root. */
  static const char data[] = "v 0 0 0\n";
  static const char hex[] = "6a32e69ee7c3a1fbd18e1e9f8c4b1d4cfc0d3e73bf3d43e3bb85b8ebdeb04a61";
  bool created;
  svc_error e = {0};
  (void)data;
  char path[512];
  snprintf(path, sizeof path, "%s/%s", blob_dir, hex);
  REQUIRE(mkdir(path, 0700) == 0 || access(path, F_OK) == 0, "mkdir %s", path);
  char doc[512];
  snprintf(doc, sizeof doc, "{\"type\":\"scene\",\"m\":{\"type\":\"obj\",\"filename\":\"sha256:%s\"}}", hex);
  char *id = NULL, *json = NULL;
  rsw_status st = service_scene_post(svc, doc, strlen(doc), false, NULL, &created, &id, &json, &e);
  CHECK(st != RSW_OK, "a scene with an unreadable blob loaded");
  CHECK(!strstr(e.err.msg, blob_dir) && !strstr(e.err.where, blob_dir),
        "the error shows the blob directory: %s: %s", e.err.where, e.err.msg);
  CHECK(names(&e, hex), "the error names the blob: %s: %s", e.err.where, e.err.msg);
  free(id);
  free(json);
  /* A blob that is not there at all. */
  memset(&e, 0, sizeof e);
  snprintf(doc, sizeof doc, "{\"type\":\"scene\",\"m\":{\"type\":\"ply\",\"filename\":\"sha256:%064d\"}}", 0);
  st = service_scene_post(svc, doc, strlen(doc), false, NULL, &created, &id, &json, &e);
  CHECK(st != RSW_OK && !strstr(e.err.msg, blob_dir) && !strstr(e.err.where, blob_dir),
        "a missing blob: status %d, %s: %s", (int)st, e.err.where, e.err.msg);
  free(id);
  free(json);
  rmdir(path);
}

static void test_duplicate_sensor(void) {
  svc_error e;
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\",\"sensors\":[\"hd\",\"0\"]}]}", &e), e,
          "/contexts/0/sensors/1", "one sensor twice (by id and index)");
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\"}],\"defaults\":{\"sensors\":[\"hd\",\"hd\"]}}", &e), e,
          "sensors", "one sensor twice in defaults");
}

/* Found by fuzz_job_body: a context wavelength outside a tabulated
 * spectrum's table was accepted and its renders failed. Runs last: it
 * PATCHes the scene's reflectance to a table over [400, 700] nm. */
static void test_wavelength_in_tables(void) {
  svc_error e;
  REQUIRE(patch("{\"rectangle.bsdf.reflectance.value\":{\"wavelengths\":[400,700],\"values\":[0.2,0.8]}}",
                &e) == RSW_OK,
          "PATCH a table: %s", e.err.msg);
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\",\"wavelength\":260}]}", &e), e,
          "rectangle.bsdf.reflectance.value", "260 nm against the base table");
  CHECK(strstr(e.err.where, "/contexts/0/wavelength") != NULL, "where '%s'", e.err.where);
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\"}],\"defaults\":{\"wavelength\":800}}", &e), e,
          "/defaults/wavelength", "800 nm by default");
  REFUSED(submit("{\"contexts\":[{\"id\":\"a\",\"wavelength\":500}],\"params\":{\"sun.irradiance.value\":"
                 "{\"wavelengths\":[510,600],\"values\":[1,1]}}}",
                 &e),
          e, "sun.irradiance.value", "500 nm against a job-level table");
  CHECK(submit("{\"contexts\":[{\"id\":\"a\",\"wavelength\":500},{\"id\":\"b\"}]}", &e) == RSW_OK,
        "500 nm and the default 550 nm: %s", e.err.msg);
  CHECK(submit("{\"contexts\":[{\"id\":\"a\",\"wavelength\":260,\"params\":"
               "{\"rectangle.bsdf.reflectance.value\":0.3}}]}",
               &e) == RSW_OK,
        "260 nm with the table overridden by a number: %s", e.err.msg);
}

static void test_strict_fields(void) {
  svc_error e;
  REFUSED(missing("{\"digests\":[],\"x\":1}", &e), e, "x", "blobs:missing unknown field");
}

int main(void) {
  snprintf(dir, sizeof dir, "/tmp/rsw-wire-XXXXXX");
  if (!mkdtemp(dir)) return 1;
  snprintf(blob_dir, sizeof blob_dir, "%s/blobs", dir);
  service_opts o = {.size = sizeof o, .render_threads = 1, .blob_dir = blob_dir, .data_root = dir};
  rsw_err err = {0};
  if (service_new(&o, &svc, &err)) {
    printf("service_new: %s\n", err.msg);
    return 1;
  }
  char *id = NULL;
  svc_error e = {0};
  if (service_scene_load_text(svc, scene_json, strlen(scene_json), false, "wire.json", &id, &e)) {
    printf("scene: %s\n", e.err.msg);
    return 1;
  }
  snprintf(scene_id, sizeof scene_id, "%s", id);
  free(id);
  RSW_TEST_RUN(test_trailing_garbage);
  RSW_TEST_RUN(test_empty_body);
  RSW_TEST_RUN(test_job_numbers);
  RSW_TEST_RUN(test_job_params_at_submit);
  RSW_TEST_RUN(test_nul);
  RSW_TEST_RUN(test_blob_dir_not_shown);
  RSW_TEST_RUN(test_strict_fields);
  RSW_TEST_RUN(test_duplicate_sensor);
  RSW_TEST_RUN(test_wavelength_in_tables);
  service_shutdown(svc);
  service_free(svc);
  rmdir(blob_dir);
  rmdir(dir);
  RSW_TEST_END("test_service_wire");
}
