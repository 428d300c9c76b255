/* Parameter-map templates (server/service/templates.c, docs/experiments.md
 * "Templates") in process:
 *  - a job whose overrides come from templates renders bitwise the films
 *    of the same job with the rendered values sent as explicit params: sun
 *    angles, an mdistant principal plane, a table over a coordinate,
 *    per-layer arrays of a piecewise medium over the wavelength; the
 *    scene's templates, the job's over them, explicit params over both;
 *  - the conventions: the sun's direction and the mdistant's pixel angles
 *    for given zeniths and azimuths;
 *  - every refusal (422 and the pointer), with nothing queued;
 *  - the no-op sweep warning (a coordinate nothing reads, a wavelength
 *    sweep of a wavelength-independent scene) and its absence for seed
 *    replicates and real sweeps; the warning survives a restart (record,
 *    answer, dataset attribute);
 *  - what rendering costs per context (printed). */
#include <math.h>
#include <netcdf.h>
#include <netcdf_mem.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../server/service/service.h"
#include "../../server/service/service_internal.h"
#include "../../server/service/templates.h"
#include "../support/test.h"

RSW_TEST_DEFINE_GLOBALS

#define DEG (3.14159265358979323846 / 180.0)

/* A 4-layer piecewise medium over a diffuse ground, a sun and a 3-direction
 * mdistant; %s: extra top-level members (",\"templates\": {...}" or ""). */
static const char *PW_FMT =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"atmo\": {\"type\": \"piecewise\","
    "   \"sigma_t\": {\"type\": \"gridvolume\", \"data\": [0.3, 0.2, 0.1, 0.05], \"shape\": [4, 1, 1],"
    "     \"filter_type\": \"nearest\", \"to_world\": [{\"scale\": [20, 20, 4]}, {\"translate\": [-10, -10, "
    "0]}]},"
    "   \"albedo\": {\"type\": \"gridvolume\", \"data\": [0.9, 0.8, 0.7, 0.6], \"shape\": [4, 1, 1],"
    "     \"filter_type\": \"nearest\", \"to_world\": [{\"scale\": [20, 20, 4]}, {\"translate\": [-10, -10, "
    "0]}]},"
    "   \"phase\": {\"type\": \"rayleigh\"}},"
    " \"box\": {\"type\": \"cube\", \"to_world\": [{\"scale\": [10, 10, 2]}, {\"translate\": [0, 0, 2]}],"
    "   \"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": \"ref\", \"id\": \"atmo\"}},"
    " \"ground\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"
    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.3}},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.0},"
    " \"md\": {\"type\": \"mdistant\", \"directions\": \"0, 0, -1, 0.5, 0, -0.8, -0.5, 0, -0.8\","
    "   \"target\": [0, 0, 0], \"film\": {\"type\": \"hdrfilm\", \"width\": 3, \"height\": 1}},"
    " \"integrator\": {\"type\": \"piecewise_volpath\", \"max_depth\": -1}%s}";

static service *svc;

static char *post_doc(service *s, const char *extra, svc_error *e) {
  char doc[4096];
  snprintf(doc, sizeof doc, PW_FMT, extra);
  bool created;
  char *id = NULL, *json = NULL;
  if (service_scene_post(s, doc, strlen(doc), false, NULL, &created, &id, &json, e)) return NULL;
  free(json);
  return id;
}

/* Submit; *json_out (may be NULL) gets the 202 answer. */
static rsw_status submit(service *s, const char *scene_id, const char *body, char **jid, char **json_out,
                         svc_error *e) {
  char *json = NULL;
  *jid = NULL;
  rsw_status st = service_job_submit(s, scene_id, body, strlen(body), NULL, jid, &json, e);
  if (json_out)
    *json_out = json;
  else
    free(json);
  return st;
}

static bool wait_job(service *s, const char *jid) {
  uint64_t after = 0, seq;
  bool end = false;
  svc_error e = {0};
  for (int guard = 0; !end && guard < 2000; guard++) {
    char *ev = NULL;
    if (service_job_next_event(s, jid, after, 10000, &seq, &ev, &end, &e)) return false;
    if (ev) after = seq;
    free(ev);
  }
  return end;
}

/* Every film of the listed contexts (sensor md) equal bitwise in jobs a, b. */
static bool same_films(const char *a, const char *b, const char *const *ctx, int n) {
  bool same = true;
  for (int i = 0; i < n; i++) {
    svc_film fa, fb;
    svc_error e = {0};
    if (service_job_result(svc, a, ctx[i], "md", &fa, &e) ||
        service_job_result(svc, b, ctx[i], "md", &fb, &e)) {
      CHECK(false, "film %s: %s", ctx[i], e.err.msg);
      return false;
    }
    size_t n_px = (size_t)fa.img.width * (size_t)fa.img.height * (size_t)fa.img.channels;
    bool eq = fa.img.width == fb.img.width && memcmp(fa.img.data, fb.img.data, n_px * sizeof(float)) == 0;
    if (!eq) CHECK(false, "context %s: films differ (%g vs %g)", ctx[i], fa.img.data[0], fb.img.data[0]);
    same = same && eq;
    svc_film_free(&fa);
    svc_film_free(&fb);
  }
  return same;
}

static float pixel(const char *jid, const char *ctx, int k) {
  svc_film f;
  svc_error e = {0};
  if (service_job_result(svc, jid, ctx, "md", &f, &e)) return NAN;
  float v = f.img.data[k];
  svc_film_free(&f);
  return v;
}

/* -(sin z cos a, sin z sin a, cos z): what the templates compute. */
static void toward(double zen, double az, double *d) {
  double z = zen * DEG, a = az * DEG, sz = sin(z);
  d[0] = -(sz * cos(a));
  d[1] = -(sz * sin(a));
  d[2] = -cos(z);
}

static int vec_json(char *out, size_t cap, const double *d, int n) {
  int k = snprintf(out, cap, "[");
  for (int i = 0; i < n; i++) k += snprintf(out + k, cap - (size_t)k, "%s%.17g", i ? ", " : "", d[i]);
  return k + snprintf(out + k, cap - (size_t)k, "]");
}

static double lerp(double c, double x0, double x1, double a, double b) {
  double f = (c - x0) / (x1 - x0);
  return f == 0 ? a : f == 1 ? b : (1 - f) * a + f * b;
}

/* Sun angles and an mdistant principal plane: templates against the
 * explicit vectors; the convention checked on the vectors and on the
 * film's pixel angles. */
static void test_angles_bitwise(void) {
  svc_error e = {0};
  char *id = post_doc(svc, "", &e);
  REQUIRE(id, "post: %s", e.err.msg);
  static const double sza[] = {0, 30, 60}, saa[] = {0, 45, 200};
  static const char *const ctx[] = {"c0", "c1", "c2"};
  char tb[4096], xb[8192];
  int nt = snprintf(tb, sizeof tb,
                    "{\"seed\": 5, \"defaults\": {\"spp\": 16}, \"templates\": {"
                    "\"sun.direction\": {\"sun\": {\"zenith\": \"sza\", \"azimuth\": \"saa\"}},"
                    "\"md.directions\": {\"view\": {\"construct\": \"hplane\", \"zeniths\": [-40, 0, 40],"
                    " \"azimuth\": \"saa\"}}}, \"contexts\": [");
  int nx = snprintf(xb, sizeof xb, "{\"seed\": 5, \"defaults\": {\"spp\": 16}, \"contexts\": [");
  for (int i = 0; i < 3; i++) {
    double sun[3], md[9];
    toward(sza[i], saa[i], sun);
    for (int k = 0; k < 3; k++) toward(k == 0 ? -40 : k == 1 ? 0 : 40, saa[i], md + 3 * k);
    char vs[200], vm[600];
    vec_json(vs, sizeof vs, sun, 3);
    vec_json(vm, sizeof vm, md, 9);
    nt += snprintf(tb + nt, sizeof tb - (size_t)nt,
                   "%s{\"id\": \"%s\", \"coords\": {\"sza\": %g, \"saa\": %g}}", i ? ", " : "", ctx[i],
                   sza[i], saa[i]);
    nx += snprintf(
        xb + nx, sizeof xb - (size_t)nx,
        "%s{\"id\": \"%s\", \"coords\": {\"sza\": %g, \"saa\": %g}, \"params\": {\"sun.direction\": %s,"
        " \"md.directions\": %s}}",
        i ? ", " : "", ctx[i], sza[i], saa[i], vs, vm);
  }
  snprintf(tb + nt, sizeof tb - (size_t)nt, "]}");
  snprintf(xb + nx, sizeof xb - (size_t)nx, "]}");
  char *ja = NULL, *jb = NULL, *answer = NULL;
  REQUIRE(submit(svc, id, tb, &ja, &answer, &e) == RSW_OK, "templated job: %s %s", e.err.where, e.err.msg);
  CHECK(!strstr(answer, "warnings"), "a real sweep has no warning: %s", answer);
  free(answer);
  REQUIRE(submit(svc, id, xb, &jb, NULL, &e) == RSW_OK, "explicit job: %s %s", e.err.where, e.err.msg);
  REQUIRE(wait_job(svc, ja) && wait_job(svc, jb), "jobs end");
  CHECK(same_films(ja, jb, ctx, 3), "sun and view templates equal explicit vectors bitwise");
  CHECK(pixel(ja, "c0", 1) != pixel(ja, "c2", 1), "the sun moved: the films differ (%g, %g)",
        pixel(ja, "c0", 1), pixel(ja, "c2", 1));
  /* The convention: a sun at zenith 60, azimuth 0 shines from +x (light
   * travels towards -x and down). */
  double d[3];
  toward(60, 0, d);
  CHECK(d[0] < 0 && fabs(d[1]) < 1e-15 && d[2] < 0 && fabs(d[2] + 0.5) < 1e-15, "sun (60, 0): %g %g %g", d[0],
        d[1], d[2]);
  /* mdistant pixel k views from zenith |z_k|, azimuth saa (z > 0) or saa +
   * 180 (z < 0): the film's own angles say so. */
  svc_film f;
  REQUIRE(service_job_result(svc, ja, "c1", "md", &f, &e) == RSW_OK && f.img.angles, "angles of c1");
  CHECK_ABS(f.img.angles[0], 40.0, 1e-9);
  CHECK_ABS(fmod(f.img.angles[1] + 360, 360), 45.0 + 180.0, 1e-9);
  CHECK_ABS(f.img.angles[2], 0.0, 1e-9);
  CHECK_ABS(f.img.angles[4], 40.0, 1e-9);
  CHECK_ABS(fmod(f.img.angles[5] + 360, 360), 45.0, 1e-9);
  svc_film_free(&f);
  /* An update equals a reload: c1's directions written into the document
   * render c1's film. */
  double sun[3], md[9];
  toward(sza[1], saa[1], sun);
  for (int k = 0; k < 3; k++) toward(k == 0 ? -40 : k == 1 ? 0 : 40, saa[1], md + 3 * k);
  char doc[4096], mds[600], suns[200], body[400];
  snprintf(doc, sizeof doc, PW_FMT, "");
  vec_json(suns, sizeof suns, sun, 3);
  int k = 0;
  for (int i = 0; i < 9; i++) k += snprintf(mds + k, sizeof mds - (size_t)k, "%s%.17g", i ? ", " : "", md[i]);
  char *p = strstr(doc, "\"direction\": [0, 0, -1], \"irradiance\"");
  char *q = strstr(doc, "\"0, 0, -1, 0.5, 0, -0.8, -0.5, 0, -0.8\"");
  REQUIRE(p && q && p < q, "the document's directions");
  char re[4600];
  snprintf(re, sizeof re, "%.*s\"direction\": %s, \"irradiance\"%.*s\"%s\"%s", (int)(p - doc), doc, suns,
           (int)(q - p - strlen("\"direction\": [0, 0, -1], \"irradiance\"")),
           p + strlen("\"direction\": [0, 0, -1], \"irradiance\""), mds,
           q + strlen("\"0, 0, -1, 0.5, 0, -0.8, -0.5, 0, -0.8\""));
  bool created;
  char *rid = NULL, *rjson = NULL, *jr = NULL;
  REQUIRE(service_scene_post(svc, re, strlen(re), false, NULL, &created, &rid, &rjson, &e) == RSW_OK,
          "reload: %s", e.err.msg);
  snprintf(body, sizeof body, "{\"seed\": 5, \"defaults\": {\"spp\": 16}, \"contexts\": [{\"id\": \"c1\"}]}");
  REQUIRE(submit(svc, rid, body, &jr, NULL, &e) == RSW_OK && wait_job(svc, jr), "reloaded job: %s",
          e.err.msg);
  static const char *const c1[] = {"c1"};
  CHECK(same_films(ja, jr, c1, 1), "sun and mdistant directions: an update equals a reload");
  free(rid), free(rjson), free(jr);
  free(ja), free(jb), free(id);
}

/* A table over a plain coordinate (the ground's reflectance) and
 * per-layer profiles over the wavelength (the medium's grids), with
 * coords-only contexts: the coordinate wavelength sets the wavelength. */
static void test_tables_bitwise(void) {
  svc_error e = {0};
  char *id = post_doc(svc, "", &e);
  REQUIRE(id, "post: %s", e.err.msg);
  static const double t[] = {0, 0.25, 1}, wl[] = {400, 650, 800};
  static const double s400[] = {0.3, 0.2, 0.1, 0.05}, s800[] = {0.03, 0.02, 0.01, 0.005};
  static const double a400[] = {0.9, 0.8, 0.7, 0.6}, a800[] = {0.5, 0.4, 0.3, 0.2};
  static const char *const ctx[] = {"c0", "c1", "c2"};
  char tb[4096], xb[8192];
  int nt = snprintf(tb, sizeof tb,
                    "{\"seed\": 9, \"defaults\": {\"spp\": 16}, \"templates\": {"
                    "\"ground.bsdf.reflectance.value\": {\"coord\": \"t\", \"x\": [0, 1], \"y\": [0.1, 0.7]},"
                    "\"atmo.sigma_t.data\": {\"coord\": \"wavelength\", \"x\": [400, 800],"
                    " \"y\": [[0.3, 0.2, 0.1, 0.05], [0.03, 0.02, 0.01, 0.005]]},"
                    "\"atmo.albedo.data\": {\"coord\": \"wavelength\", \"x\": [400, 800],"
                    " \"y\": [[0.9, 0.8, 0.7, 0.6], [0.5, 0.4, 0.3, 0.2]]}}, \"contexts\": [");
  int nx = snprintf(xb, sizeof xb, "{\"seed\": 9, \"defaults\": {\"spp\": 16}, \"contexts\": [");
  for (int i = 0; i < 3; i++) {
    double s[4], a[4];
    for (int k = 0; k < 4; k++) {
      s[k] = lerp(wl[i], 400, 800, s400[k], s800[k]);
      a[k] = lerp(wl[i], 400, 800, a400[k], a800[k]);
    }
    char vs[300], va[300];
    vec_json(vs, sizeof vs, s, 4);
    vec_json(va, sizeof va, a, 4);
    nt += snprintf(tb + nt, sizeof tb - (size_t)nt,
                   "%s{\"id\": \"%s\", \"coords\": {\"t\": %g, \"wavelength\": %g}}", i ? ", " : "", ctx[i],
                   t[i], wl[i]);
    nx += snprintf(
        xb + nx, sizeof xb - (size_t)nx,
        "%s{\"id\": \"%s\", \"wavelength\": %g, \"params\": {\"ground.bsdf.reflectance.value\": %.17g,"
        " \"atmo.sigma_t.data\": %s, \"atmo.albedo.data\": %s}}",
        i ? ", " : "", ctx[i], wl[i], lerp(t[i], 0, 1, 0.1, 0.7), vs, va);
  }
  snprintf(tb + nt, sizeof tb - (size_t)nt, "]}");
  snprintf(xb + nx, sizeof xb - (size_t)nx, "]}");
  char *ja = NULL, *jb = NULL, *answer = NULL;
  REQUIRE(submit(svc, id, tb, &ja, &answer, &e) == RSW_OK, "templated job: %s %s", e.err.where, e.err.msg);
  CHECK(!strstr(answer, "warnings"), "no warning: the wavelength is read by a template: %s", answer);
  free(answer);
  REQUIRE(submit(svc, id, xb, &jb, NULL, &e) == RSW_OK, "explicit job: %s %s", e.err.where, e.err.msg);
  REQUIRE(wait_job(svc, ja) && wait_job(svc, jb), "jobs end");
  CHECK(same_films(ja, jb, ctx, 3), "tables and per-layer profiles equal explicit values bitwise");
  CHECK(pixel(ja, "c0", 0) != pixel(ja, "c2", 0), "the templates change the films");
  char *res = NULL;
  REQUIRE(service_job_results(svc, ja, &res, &e) == RSW_OK, "results");
  CHECK(strstr(res, "\"wavelength\":650"), "the coordinate wavelength set the wavelength: %.300s", res);
  free(res);
  free(ja), free(jb), free(id);
}

/* The scene's templates, the job's over them per key, a context's
 * explicit params over both; the templates are part of the scene id. */
static void test_scene_templates(void) {
  svc_error e = {0};
  char *plain = post_doc(svc, "", &e);
  char *id = post_doc(svc,
                      ", \"templates\": {\"sun.direction\": {\"sun\": {\"zenith\": \"sza\", \"azimuth\": 0}},"
                      " \"ground.bsdf.reflectance.value\": {\"value\": 0.6}}",
                      &e);
  REQUIRE(plain && id, "post: %s", e.err.msg);
  CHECK(strcmp(plain, id) != 0, "the templates are part of the scene id");
  double d30[3], d50[3];
  toward(30, 0, d30);
  toward(50, 10, d50);
  char v30[200], v50[200], b1[2048], b2[2048], b3[2048];
  vec_json(v30, sizeof v30, d30, 3);
  vec_json(v50, sizeof v50, d50, 3);
  static const char *const ctx[] = {"a", "b"};
  /* b's explicit direction wins over the scene's template; the job's
   * reflectance template wins over the scene's. */
  snprintf(b1, sizeof b1,
           "{\"seed\": 2, \"defaults\": {\"spp\": 8}, \"templates\": {\"ground.bsdf.reflectance.value\": "
           "{\"coord\": \"sza\", \"x\": [0, 90], \"y\": [0.2, 0.4]}}, \"contexts\": ["
           "{\"id\": \"a\", \"coords\": {\"sza\": 30}},"
           "{\"id\": \"b\", \"coords\": {\"sza\": 45}, \"params\": {\"sun.direction\": %s}}]}",
           v50);
  snprintf(b2, sizeof b2,
           "{\"seed\": 2, \"defaults\": {\"spp\": 8}, \"contexts\": ["
           "{\"id\": \"a\", \"coords\": {\"sza\": 30}, \"params\": {\"sun.direction\": %s,"
           " \"ground.bsdf.reflectance.value\": %.17g}},"
           "{\"id\": \"b\", \"coords\": {\"sza\": 45}, \"params\": {\"sun.direction\": %s,"
           " \"ground.bsdf.reflectance.value\": %.17g}}]}",
           v30, lerp(30, 0, 90, 0.2, 0.4), v50, lerp(45, 0, 90, 0.2, 0.4));
  char *ja = NULL, *jb = NULL;
  REQUIRE(submit(svc, id, b1, &ja, NULL, &e) == RSW_OK, "templated: %s %s", e.err.where, e.err.msg);
  REQUIRE(submit(svc, plain, b2, &jb, NULL, &e) == RSW_OK, "explicit: %s %s", e.err.where, e.err.msg);
  REQUIRE(wait_job(svc, ja) && wait_job(svc, jb), "jobs end");
  CHECK(same_films(ja, jb, ctx, 2), "scene templates, job templates over them, explicit params over both");
  /* A job-level param over a scene template: the template is dropped. */
  snprintf(b3, sizeof b3,
           "{\"seed\": 2, \"defaults\": {\"spp\": 8}, \"params\": {\"sun.direction\": %s}, \"contexts\": ["
           "{\"id\": \"a\", \"coords\": {\"sza\": 30}}]}",
           v50);
  char *jc = NULL;
  CHECK(submit(svc, id, b3, &jc, NULL, &e) == RSW_OK, "job params over a scene template: %s", e.err.msg);
  free(jc);
  /* A scene whose template is wrong is refused at its POST. */
  svc_error e2 = {0};
  char *bad = post_doc(
      svc, ", \"templates\": {\"sun.direction\": {\"sun\": {\"zenith\": 200, \"azimuth\": 0}}}", &e2);
  CHECK(!bad && rsw_status_http(e2.err.code) == 422 &&
            strcmp(e2.err.where, "scene.json#/templates/sun.direction/sun/zenith") == 0,
        "a bad scene template: %d %s %s", rsw_status_http(e2.err.code), e2.err.where, e2.err.msg);
  free(bad);
  svc_error e3 = {0};
  bad = post_doc(svc, ", \"templates\": {\"sun.directoin\": {\"value\": [0, 0, -1]}}", &e3);
  CHECK(!bad && e3.err.code == RSW_ERR_UNKNOWN_NAME && strcmp(e3.candidates[0], "sun.direction") == 0,
        "an unknown scene template key, with did-you-mean: %s %s", e3.err.where, e3.candidates[0]);
  free(bad);
  free(ja), free(jb), free(id), free(plain);
}

/* Every refusal: 422, its pointer, and no job. */
static void test_refusals(void) {
  svc_error e = {0};
  char *id = post_doc(svc, "", &e);
  REQUIRE(id, "post: %s", e.err.msg);
#define SUN_T "\"templates\": {\"sun.direction\": {\"sun\": {\"zenith\": \"sza\", \"azimuth\": 0}}}"
#define TAB_T(x, y)                                                                                          \
  "\"templates\": {\"ground.bsdf.reflectance.value\": {\"coord\": \"t\", \"x\": " x ", \"y\": " y "}}"
  static const struct {
    const char *body, *pointer, *what;
    rsw_status code;
  } cases[] = {
      {"{\"templates\": {\"sun.directoin\": {\"sun\": {\"zenith\": 0, \"azimuth\": 0}}}, \"contexts\": "
       "[{\"id\": "
       "\"a\"}]}",
       "/templates/sun.directoin", "unknown key", RSW_ERR_UNKNOWN_NAME},
      {"{" SUN_T ", \"contexts\": [{\"id\": \"a\", \"coords\": {\"sza\": 10}}, {\"id\": \"b\", \"coords\": "
       "{\"x\": 1}}]}",
       "/contexts/1/coords/sza", "coordinate missing", RSW_ERR_MISSING},
      {"{" SUN_T ", \"contexts\": [{\"id\": \"a\", \"coords\": {\"sza\": \"high\"}}]}",
       "/contexts/0/coords/sza", "coordinate a string", RSW_ERR_INVALID},
      {"{" SUN_T ", \"contexts\": [{\"id\": \"a\", \"coords\": {\"sza\": 1e999}}]}", "/contexts/0/coords/sza",
       "coordinate infinite", RSW_ERR_INVALID},
      {"{" SUN_T ", \"contexts\": [{\"id\": \"a\", \"coords\": {\"sza\": 190}}]}", "/contexts/0/coords/sza",
       "zenith out of range", RSW_ERR_RANGE},
      {"{" TAB_T("[0, 1]", "[0.1, 0.7]") ", \"contexts\": [{\"id\": \"a\", \"coords\": {\"t\": 1.5}}]}",
       "/contexts/0/coords/t", "outside the table", RSW_ERR_RANGE},
      {"{" TAB_T("[0, 1, 1]", "[0.1, 0.7, 0.8]") ", \"contexts\": [{\"id\": \"a\", \"coords\": {\"t\": 0}}]}",
       "/templates/ground.bsdf.reflectance.value/x/2", "x not increasing", RSW_ERR_INVALID},
      {"{" TAB_T("[0, 1]",
                 "[[0.1], [0.7, 0.8]]") ", \"contexts\": [{\"id\": \"a\", \"coords\": {\"t\": 0}}]}",
       "/templates/ground.bsdf.reflectance.value/y/1", "ragged y", RSW_ERR_INVALID},
      {"{" TAB_T("[0, 1]", "[0.1, 1e999]") ", \"contexts\": [{\"id\": \"a\", \"coords\": {\"t\": 0}}]}",
       "/templates/ground.bsdf.reflectance.value/y/1", "y infinite", RSW_ERR_INVALID},
      {"{" TAB_T("[0, 1e999]", "[0.1, 0.2]") ", \"contexts\": [{\"id\": \"a\", \"coords\": {\"t\": 0}}]}",
       "/templates/ground.bsdf.reflectance.value/x/1", "x infinite", RSW_ERR_INVALID},
      {"{" TAB_T("[0, 1]", "[0.1, -0.7]") ", \"contexts\": [{\"id\": \"a\", \"coords\": {\"t\": 1}}]}",
       "/templates/ground.bsdf.reflectance.value", "rendered value out of range", RSW_ERR_RANGE},
      {"{\"templates\": {\"sun.sampling_weight\": {\"sun\": {\"zenith\": 0, \"azimuth\": 0}}}, "
       "\"contexts\": [{\"id\": \"a\"}]}",
       "/templates/sun.sampling_weight", "a vector for a float", RSW_ERR_TYPE},
      {"{\"templates\": {\"sun.direction\": {\"moon\": 1}}, \"contexts\": [{\"id\": \"a\"}]}",
       "/templates/sun.direction", "unknown form", RSW_ERR_INVALID},
      {"{\"templates\": {\"sun.direction\": {\"sun\": {\"zenith\": 0, \"azimuth\": 0, \"x\": 1}}}, "
       "\"contexts\": "
       "[{\"id\": \"a\"}]}",
       "/templates/sun.direction/sun/x", "unknown member", RSW_ERR_UNUSED_PROPERTY},
      {"{\"params\": {\"sun.direction\": [0, 0, -1]}, " SUN_T ", \"contexts\": [{\"id\": \"a\", \"coords\": "
       "{\"sza\": 0}}]}",
       "/templates/sun.direction", "template and job params", RSW_ERR_DUPLICATE},
      {"{\"contexts\": [{\"id\": \"a\", \"wavelength\": 500, \"coords\": {\"wavelength\": 550}}]}",
       "/contexts/0/coords/wavelength", "two wavelengths", RSW_ERR_INVALID},
      {"{\"contexts\": [{\"id\": \"a\", \"coords\": {\"wavelength\": -5}}]}", "/contexts/0/coords/wavelength",
       "negative wavelength", RSW_ERR_INVALID},
      {"{\"templates\": {\"md.directions\": {\"view\": {\"zeniths\": [0, 10], \"azimuth\": 0}}}, "
       "\"contexts\": "
       "[{\"id\": \"a\"}]}",
       "/templates/md.directions", "2 directions for a 3-pixel mdistant", RSW_ERR_INVALID},
      {"{\"templates\": {\"sun.direction\": {\"view\": {\"construct\": \"vplane\", \"zeniths\": [0]}}}, "
       "\"contexts\": [{\"id\": \"a\"}]}",
       "/templates/sun.direction/view/construct", "unknown construct", RSW_ERR_INVALID},
      {"{\"templates\": [1], \"contexts\": [{\"id\": \"a\"}]}", "/templates", "templates not an object",
       RSW_ERR_TYPE},
  };
  pthread_mutex_lock(&svc->lock);
  size_t jobs_before = svc->n_jobs;
  pthread_mutex_unlock(&svc->lock);
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    svc_error ei = {0};
    char *jid = NULL;
    rsw_status st = submit(svc, id, cases[i].body, &jid, NULL, &ei);
    CHECK(st != RSW_OK && rsw_status_http(st) == 422 && st == cases[i].code &&
              strcmp(ei.err.where, cases[i].pointer) == 0,
          "%s: got %s (%d) at '%s' (%s); want %s at '%s'", cases[i].what, rsw_status_name(st),
          rsw_status_http(st), ei.err.where, ei.err.msg, rsw_status_name(cases[i].code), cases[i].pointer);
    free(jid);
  }
  svc_error eu = {0};
  char *jid = NULL;
  submit(svc, id, cases[0].body, &jid, NULL, &eu);
  CHECK(strcmp(eu.candidates[0], "sun.direction") == 0, "did-you-mean: %s", eu.candidates[0]);
  pthread_mutex_lock(&svc->lock);
  size_t jobs_after = svc->n_jobs;
  pthread_mutex_unlock(&svc->lock);
  CHECK(jobs_after == jobs_before, "no refused job was queued (%zu -> %zu)", jobs_before, jobs_after);
  free(id);
}

static bool has_warning(const char *json, const char *code, const char *coord) {
  char pat[200];
  snprintf(pat, sizeof pat, "\"code\":\"%s\",\"coordinate\":\"%s\"", code, coord);
  return json && strstr(json, pat) != NULL;
}

static void test_warnings(void) {
  svc_error e = {0};
  char *id = post_doc(svc, "", &e);
  REQUIRE(id, "post: %s", e.err.msg);
  struct {
    const char *body, *code, *coord, *what;
  } cases[] = {
      {"{\"contexts\": [{\"id\": \"a\", \"coords\": {\"sza\": 0}}, {\"id\": \"b\", \"coords\": {\"sza\": "
       "30}}]}",
       "coordinate_unused", "sza", "a coordinate nothing reads"},
      {"{\"contexts\": [{\"id\": \"a\", \"coords\": {\"sza\": 0, \"albedo\": 0.1}, \"params\": "
       "{\"ground.bsdf.reflectance.value\": 0.1}}, {\"id\": \"b\", \"coords\": {\"sza\": 30, \"albedo\": "
       "0.1}, "
       "\"params\": {\"ground.bsdf.reflectance.value\": 0.1}}, {\"id\": \"c\", \"coords\": {\"sza\": 0, "
       "\"albedo\": 0.5}, \"params\": {\"ground.bsdf.reflectance.value\": 0.5}}, {\"id\": \"d\", \"coords\": "
       "{\"sza\": 30, \"albedo\": 0.5}, \"params\": {\"ground.bsdf.reflectance.value\": 0.5}}]}",
       "coordinate_unused", "sza", "sza unused on a grid whose albedo is used"},
      {"{\"contexts\": [{\"id\": \"a\", \"wavelength\": 400}, {\"id\": \"b\", \"wavelength\": 500}]}",
       "wavelength_unused", "wavelength", "a wavelength sweep of a grey scene"},
      {"{\"contexts\": [{\"id\": \"a\", \"coords\": {\"wavelength\": 400}}, {\"id\": \"b\", \"coords\": "
       "{\"wavelength\": 500}}]}",
       "wavelength_unused", "wavelength", "a coords-only wavelength sweep of a grey scene"},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    char *jid = NULL, *answer = NULL, *got = NULL;
    svc_error ei = {0};
    REQUIRE(submit(svc, id, cases[i].body, &jid, &answer, &ei) == RSW_OK, "%s: %s", cases[i].what,
            ei.err.msg);
    CHECK(has_warning(answer, cases[i].code, cases[i].coord), "%s: the 202 answer warns: %s", cases[i].what,
          answer);
    CHECK(service_job_get(svc, jid, &got, &ei) == RSW_OK && has_warning(got, cases[i].code, cases[i].coord),
          "%s: GET warns", cases[i].what);
    CHECK(!has_warning(answer, "coordinate_unused", "albedo"), "%s: albedo is used", cases[i].what);
    CHECK(!strstr(answer, "coordinate_unused\",\"coordinate\":\"wavelength"), "%s: said once", cases[i].what);
    wait_job(svc, jid);
    free(jid), free(answer), free(got);
  }
  /* No warning: replicates with their own seeds; a wavelength sweep of a
   * spectral scene (a job-level table); a coordinate that labels
   * explicit overrides. */
  static const char *const quiet[] = {
      "{\"contexts\": [{\"id\": \"r0\", \"seed\": 1, \"coords\": {\"rep\": 0}}, {\"id\": \"r1\", \"seed\": "
      "2, "
      "\"coords\": {\"rep\": 1}}, {\"id\": \"r2\", \"seed\": 3, \"coords\": {\"rep\": 2}}]}",
      "{\"params\": {\"ground.bsdf.reflectance.value\": {\"wavelengths\": [400, 700], \"values\": [0.2, "
      "0.8]}},"
      " \"contexts\": [{\"id\": \"a\", \"coords\": {\"wavelength\": 400}}, {\"id\": \"b\", \"coords\": "
      "{\"wavelength\": 500}}]}",
      "{\"contexts\": [{\"id\": \"a\", \"coords\": {\"rho\": 0.1}, \"params\": "
      "{\"ground.bsdf.reflectance.value\": "
      "0.1}}, {\"id\": \"b\", \"coords\": {\"rho\": 0.2}, \"params\": {\"ground.bsdf.reflectance.value\": "
      "0.2}}]}",
  };
  for (size_t i = 0; i < sizeof quiet / sizeof quiet[0]; i++) {
    char *jid = NULL, *answer = NULL;
    svc_error ei = {0};
    REQUIRE(submit(svc, id, quiet[i], &jid, &answer, &ei) == RSW_OK, "quiet %zu: %s", i, ei.err.msg);
    CHECK(!strstr(answer, "warnings"), "quiet %zu: no warning: %s", i, answer);
    wait_job(svc, jid);
    free(jid), free(answer);
  }
  /* The scene's own spectra (scene_wavelength_dependent): a tabulated
   * reflectance, a grid with a wavelength axis; a table of one value
   * everywhere depends on nothing. */
  static const struct {
    const char *from, *to;
    bool spectral;
  } scenes[] = {
      {"\"reflectance\": 0.3",
       "\"reflectance\": {\"type\": \"spectrum\", \"wavelengths\": [400, 800], "
       "\"values\": [0.2, 0.4]}",
       true},
      {"\"reflectance\": 0.3",
       "\"reflectance\": {\"type\": \"spectrum\", \"wavelengths\": [400, 800], "
       "\"values\": [0.3, 0.3]}",
       false},
      {"\"data\": [0.3, 0.2, 0.1, 0.05], \"shape\": [4, 1, 1]",
       "\"data\": [0.3, 0.2, 0.2, 0.1, 0.1, 0.05, 0.05, 0.01], \"shape\": [4, 1, 1, 2], \"wavelengths\": "
       "[400, 800]",
       true},
  };
  for (size_t i = 0; i < sizeof scenes / sizeof scenes[0]; i++) {
    char doc[4096], alt[4400];
    snprintf(doc, sizeof doc, PW_FMT, "");
    char *at = strstr(doc, scenes[i].from);
    REQUIRE(at, "scene %zu", i);
    snprintf(alt, sizeof alt, "%.*s%s%s", (int)(at - doc), doc, scenes[i].to, at + strlen(scenes[i].from));
    bool created;
    char *sid = NULL, *sjson = NULL, *jid = NULL, *answer = NULL;
    svc_error ei = {0};
    REQUIRE(service_scene_post(svc, alt, strlen(alt), false, NULL, &created, &sid, &sjson, &ei) == RSW_OK,
            "scene %zu: %s %s", i, ei.err.where, ei.err.msg);
    const char *sweep = "{\"defaults\": {\"spp\": 1}, \"contexts\": [{\"id\": \"a\", \"wavelength\": 450}, "
                        "{\"id\": \"b\", \"wavelength\": 650}]}";
    REQUIRE(submit(svc, sid, sweep, &jid, &answer, &ei) == RSW_OK, "scene %zu sweep: %s", i, ei.err.msg);
    CHECK(has_warning(answer, "wavelength_unused", "wavelength") == !scenes[i].spectral, "scene %zu (%s): %s",
          i, scenes[i].spectral ? "spectral" : "grey", answer);
    wait_job(svc, jid);
    free(sid), free(sjson), free(jid), free(answer);
  }
  free(id);
}

/* The warning is in the job's record: after a restart it is still in
 * the answer and in the dataset's attributes. */
static void test_warning_survives_restart(void) {
  char dir[] = "/tmp/rsw-tmpl-state-XXXXXX";
  REQUIRE(mkdtemp(dir), "mkdtemp");
  service_opts o = {.size = sizeof o, .render_threads = 1, .state_dir = dir};
  service *s = NULL;
  rsw_err err = {0};
  REQUIRE(service_new(&o, &s, &err) == RSW_OK, "service: %s", err.msg);
  svc_error e = {0};
  char *id = post_doc(s, "", &e);
  REQUIRE(id, "post: %s", e.err.msg);
  const char *body = "{\"defaults\": {\"spp\": 1}, \"contexts\": [{\"id\": \"a\", \"coords\": {\"look\": 0}},"
                     " {\"id\": \"b\", \"coords\": {\"look\": 10}}]}";
  const char *coord = "look";
  char *jid = NULL;
  submit(s, id, body, &jid, NULL, &e);
  REQUIRE(jid, "submit: %s %s", e.err.where, e.err.msg);
  if (!wait_job(s, jid)) CHECK(false, "job ends");
  char keep[40];
  snprintf(keep, sizeof keep, "%s", jid);
  service_free(s);
  s = NULL;
  REQUIRE(service_new(&o, &s, &err) == RSW_OK, "service again: %s", err.msg);
  service_restore(s);
  char *got = NULL;
  CHECK(service_job_get(s, keep, &got, &e) == RSW_OK && has_warning(got, "coordinate_unused", coord),
        "restored job warns: %s", got ? got : e.err.msg);
  free(got);
  void *bytes = NULL;
  size_t len = 0;
  if (service_job_dataset(s, keep, false, &bytes, &len, &e) == RSW_OK) {
    int nc;
    char att[2048] = "";
    size_t alen = 0;
    if (nc_open_mem("ds.nc", NC_NOWRITE, len, bytes, &nc) == NC_NOERR) {
      if (nc_inq_attlen(nc, NC_GLOBAL, "warnings", &alen) == NC_NOERR && alen < sizeof att)
        nc_get_att_text(nc, NC_GLOBAL, "warnings", att);
      nc_close(nc);
    }
    CHECK(strstr(att, "coordinate_unused (") != NULL, "the dataset's warnings attribute: '%s'", att);
  } else {
    CHECK(false, "dataset: %s", e.err.msg);
  }
  free(bytes);
  free(jid), free(id);
  service_free(s);
  char cmd[200];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  CHECK(system(cmd) == 0, "cleanup");
}

/* What rendering costs: an EO context's templates (a sun, an mdistant
 * plane of 9 directions, two 2400-layer profiles over the wavelength, a
 * reflectance table), rendered for many contexts. Printed, and bounded
 * loosely (the budget is microseconds per context). */
static void test_render_cost(void) {
  svc_error e = {0};
  char *id = post_doc(svc, "", &e);
  REQUIRE(id, "post: %s", e.err.msg);
  resident *r = svc_scene_acquire(svc, id);
  REQUIRE(r, "acquire");
  enum {
    L = 2400,
    N = 2000
  };
  char *doc = malloc(8 * (size_t)L * 30 + 4096);
  REQUIRE(doc, "memory");
  size_t n =
      (size_t)sprintf(doc, "{\"sun.direction\": {\"sun\": {\"zenith\": \"sza\", \"azimuth\": \"saa\"}},"
                           " \"ground.bsdf.reflectance.value\": {\"coord\": \"wavelength\", \"x\": [400, "
                           "600, 800], \"y\": [0.1, 0.2, 0.3]}");
  const char *keys[2] = {"atmo.sigma_t.data", "atmo.albedo.data"};
  for (int k = 0; k < 2; k++) {
    n += (size_t)sprintf(doc + n, ", \"%s\": {\"coord\": \"wavelength\", \"x\": [400, 800], \"y\": [",
                         keys[k]);
    for (int row = 0; row < 2; row++) {
      n += (size_t)sprintf(doc + n, "%s[", row ? ", " : "");
      for (int i = 0; i < L; i++)
        n += (size_t)sprintf(doc + n, "%s%.6g", i ? ", " : "", 0.1 + 1e-4 * i + row * 0.1);
      n += (size_t)sprintf(doc + n, "]");
    }
    n += (size_t)sprintf(doc + n, "]}");
  }
  sprintf(doc + n, "}");
  cJSON *tj = cJSON_Parse(doc);
  free(doc);
  /* The compiled set checks keys against a 4-layer scene: the profile
   * lengths are checked only when rendered values are validated, which
   * is not timed here. */
  tmpl_set *ts = NULL;
  REQUIRE(tj && tmpl_compile(r->sc, NULL, "", tj, NULL, &ts, &e) == RSW_OK, "compile: %s %s", e.err.where,
          e.err.msg);
  cJSON *small =
      cJSON_Parse("{\"sun.direction\": {\"sun\": {\"zenith\": \"sza\", \"azimuth\": \"saa\"}},"
                  " \"md.directions\": {\"view\": {\"zeniths\": [-40, 0, 40], \"azimuth\": \"saa\"}},"
                  " \"ground.bsdf.reflectance.value\": {\"coord\": \"wavelength\", \"x\": [400, 600, "
                  "800], \"y\": [0.1, 0.2, 0.3]}}");
  tmpl_set *ss = NULL;
  REQUIRE(small && tmpl_compile(r->sc, NULL, "", small, NULL, &ss, &e) == RSW_OK, "compile: %s", e.err.msg);
  cJSON *coords = cJSON_Parse("{\"sza\": 30, \"saa\": 120}");
  double us[2];
  bool ok = true;
  for (int pass = 0; pass < 2; pass++) {
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    int reps = pass ? N : 50 * N;
    for (int i = 0; i < reps && ok; i++) {
      cJSON *out = cJSON_CreateObject();
      ok = tmpl_render(pass ? ts : ss, r->sc, coords, 400 + (i % 400), out, "/contexts/0", &e) == RSW_OK;
      cJSON_Delete(out);
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    us[pass] = ((double)(t1.tv_sec - t0.tv_sec) * 1e6 + (double)(t1.tv_nsec - t0.tv_nsec) / 1e3) / reps;
  }
  CHECK(ok, "render: %s", e.err.msg);
  printf(
      "  templates: %.2f us per context (sun, 3-direction hplane, table); %.1f us with 2 x %d-layer profiles "
      "more\n",
      us[0], us[1], L);
#ifndef __SANITIZE_ADDRESS__ /* (sanitizer builds run several times slower) */
  CHECK(us[0] < 100 && us[1] < 5000, "rendering stays cheap: %.2f, %.1f us per context", us[0], us[1]);
#endif
  cJSON_Delete(coords);
  cJSON_Delete(tj);
  cJSON_Delete(small);
  tmpl_free(ts);
  tmpl_free(ss);
  svc_scene_release(svc, r);
  free(id);
}

int main(void) {
  service_opts o = {.size = sizeof o, .render_threads = 2};
  rsw_err err = {0};
  if (service_new(&o, &svc, &err)) {
    printf("service_new: %s\n", err.msg);
    return 1;
  }
  RSW_TEST_RUN(test_angles_bitwise);
  RSW_TEST_RUN(test_tables_bitwise);
  RSW_TEST_RUN(test_scene_templates);
  RSW_TEST_RUN(test_refusals);
  RSW_TEST_RUN(test_warnings);
  RSW_TEST_RUN(test_warning_survives_restart);
  RSW_TEST_RUN(test_render_cost);
  service_free(svc);
  RSW_TEST_END("test_templates");
}
