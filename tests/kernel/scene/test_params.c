/* Scene parameters (scene/params.h, docs/kernel-conventions.md#parameters-and-updates): naming as
 * Mitsuba's traverse(), entry types/classes/shapes, lookup (exact, alias,
 * glob, class filter, Eradiate's TYPE:ID:PATH search), value JSON, value
 * parsing, atomic updates (a bad entry changes nothing), no-op updates,
 * update classes against the acceleration structure's counters, and the
 * refresh of derived state (bounding sphere) after a geometric update.
 *
 * "An update equals a reload" for renders is
 * tests/kernel/scene/test_update_reload.c. */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../server/kernel/accel.h"
#include "../../../server/kernel/core/transform.h"
#include "../../../server/kernel/scene/param_table.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

/* ---- helpers ----------------------------------------------------------------- */

/* Index of an exact key (or alias), SIZE_MAX when absent. */
static size_t idx_of(const scene *s, const char *key) {
  size_t i;
  rsw_err err = {0};
  return params_lookup(s, key, &i, &err) == RSW_OK ? i : SIZE_MAX;
}

/* Apply one update given as JSON text. Returns the status; *err filled. */
static rsw_status upd1(scene *s, const char *key, const char *json, update_report *rep, rsw_err *err) {
  param_update u = {.key = key};
  rsw_status st = param_value_parse(json, key, &u.value, err);
  if (st != RSW_OK) return st;
  st = scene_update(s, &u, 1, rep, err);
  param_value_free(&u.value);
  return st;
}

/* Same, failing the test with the error text when the update fails. */
static bool upd1_ok(scene *s, const char *key, const char *json, update_report *rep) {
  rsw_err err = {0};
  if (upd1(s, key, json, rep, &err) != RSW_OK) {
    char buf[1200];
    CHECK(false, "update %s = %s failed: %s", key, json, rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  return true;
}

static char *value_json(const scene *s, const char *key) {
  size_t i = idx_of(s, key);
  return i == SIZE_MAX ? NULL : params_value_json(s, i, 0);
}

/* The value of a one-number entry (mono spectrum, float), NAN if it is not
 * a plain number. */
static double value_num(const scene *s, const char *key) {
  char *j = value_json(s, key);
  cJSON *v = j ? cJSON_Parse(j) : NULL;
  double d = cJSON_IsNumber(v) ? v->valuedouble : NAN;
  cJSON_Delete(v);
  free(j);
  return d;
}

static bool render16(scene *s, film_image *out) {
  return tsup_render(s, 8, 99, 2, out);
}

static bool same_film(const film_image *a, const film_image *b) {
  return a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, sizeof(float) * (size_t)a->width * a->height * a->channels) == 0;
}

static void xform_json(const xform *t, char *buf, size_t len) {
  size_t n = (size_t)snprintf(buf, len, "[");
  for (int k = 0; k < 16; k++)
    n += (size_t)snprintf(buf + n, len - n, "%s%.17g", k ? ", " : "", t->m[k / 4][k % 4]);
  snprintf(buf + n, len - n, "]");
}

static bool err_mentions(const rsw_err *err, const char *what) {
  char buf[1200];
  return strstr(rsw_err_format(err, buf, sizeof buf), what) != NULL;
}

/* Eradiate's naming example (docs/kernel-conventions.md#parameters-and-updates,
 * from eradiate tests/01_unit/kernel/test_render.py): a top-level BSDF declared first
 * and shared by three shapes; disk_2 has its own. */
static const char *ERD_SCENE =
    "{\"type\": \"scene\","
    " \"bsdf\": {\"type\": \"diffuse\", \"id\": \"my_bsdf\"},"
    " \"rectangle_1\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"ref\", \"id\": \"my_bsdf\"}},"
    " \"rectangle_2\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"ref\", \"id\": \"my_bsdf\"}},"
    " \"disk_1\": {\"type\": \"disk\", \"bsdf\": {\"type\": \"ref\", \"id\": \"my_bsdf\"}},"
    " \"disk_2\": {\"type\": \"disk\", \"bsdf\": {\"type\": \"diffuse\"}}}";

/* A small ascii PLY quad (4 vertices, 2 faces), with vertex normals and
 * texture coordinates when `attrs`. */
static bool write_quad_ply(const char *path, bool attrs) {
  FILE *f = fopen(path, "w");
  if (!f) return false;
  fprintf(
      f,
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n%s"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n",
      attrs ? "property float nx\nproperty float ny\nproperty float nz\nproperty float u\nproperty float v\n"
            : "");
  static const double q[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
  for (int i = 0; i < 4; i++) {
    fprintf(f, "%g %g 0", q[i][0], q[i][1]);
    if (attrs) fprintf(f, " 0 0 1 %g %g", (q[i][0] + 1) / 2, (q[i][1] + 1) / 2);
    fprintf(f, "\n");
  }
  fprintf(f, "3 0 1 2\n3 0 2 3\n");
  return fclose(f) == 0;
}

/* A scene with every kind of entry the tests below use: a rectangle with a
 * diffuse BSDF, a directional emitter "emitter", a ply mesh "m" (no
 * attributes), a ply mesh "n" (normals, uv), a sphere "ball", a
 * roughconductor plate "metal", a twosided plate "ts", a perspective
 * camera "cam". */
static char ply_plain[256], ply_attrs[256];

static scene *misc_scene(const char *variant) {
  char buf[8192];
  snprintf(
      buf, sizeof buf,
      "{\"type\": \"scene\","
      " \"cam\": {\"type\": \"perspective\", \"fov\": 60, \"to_world\": [{\"lookat\": {\"origin\": [0.3, -4, "
      "4],"
      "   \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}], \"sampler\": {\"type\": \"independent\", "
      "\"sample_count\": 8},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16, \"rfilter\": {\"type\": "
      "\"box\"}}},"
      " \"emitter\": {\"type\": \"directional\", \"direction\": [0.3, 0.2, -1], \"irradiance\": 1.0},"
      " \"my_shape\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.3}},"
      " \"m\": {\"type\": \"ply\", \"filename\": \"%s\", \"to_world\": [{\"translate\": [1.5, 0, 0.2]}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}},"
      " \"n\": {\"type\": \"ply\", \"filename\": \"%s\", \"to_world\": [{\"translate\": [-1.5, 0, 0.2]}]},"
      " \"ball\": {\"type\": \"sphere\", \"to_world\": [{\"scale\": 0.4}, {\"translate\": [0, 1.2, 0.5]}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": {\"type\": \"rgb\", \"value\": [0.2, 0.5, "
      "0.8]}}},"
      " \"metal\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 0.5}, {\"translate\": [0, -1.5, "
      "0.1]}],"
      "   \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": 0.2, \"eta\": 1.5, \"k\": 3}},"
      " \"ts\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 0.3}, {\"translate\": [1.5, 1.5, 0.3]}],"
      "   \"bsdf\": {\"type\": \"twosided\", \"inner\": {\"type\": \"diffuse\", \"reflectance\": 0.4}}}}",
      ply_plain, ply_attrs);
  return tsup_load(buf, variant);
}

/* ---- naming ------------------------------------------------------------------ */

static void test_naming_eradiate_example(void) {
  scene *s = tsup_load(ERD_SCENE, "mono");
  REQUIRE(s, "load");
  static const char *const expect[] = {
      "allow_thread_reordering",
      "my_bsdf.reflectance.value",
      "rectangle_1.to_world",
      "rectangle_1.silhouette_sampling_weight",
      "rectangle_2.to_world",
      "rectangle_2.silhouette_sampling_weight",
      "disk_1.to_world",
      "disk_1.silhouette_sampling_weight",
      "disk_2.to_world",
      "disk_2.silhouette_sampling_weight",
      "disk_2.bsdf.reflectance.value",
  };
  size_t n_expect = sizeof expect / sizeof *expect;
  size_t n = params_count(s);
  CHECK(n == n_expect, "params_count = %zu, expected %zu", n, n_expect);
  for (size_t i = 0; i < n; i++) {
    param_info pi;
    REQUIRE(params_info(s, i, &pi), "params_info(%zu)", i);
    bool found = false;
    for (size_t k = 0; k < n_expect; k++) found = found || strcmp(pi.key, expect[k]) == 0;
    CHECK(found, "unexpected key '%s'", pi.key);
  }
  size_t ix[11];
  for (size_t k = 0; k < n_expect; k++) {
    ix[k] = idx_of(s, expect[k]);
    CHECK(ix[k] != SIZE_MAX, "missing key '%s'", expect[k]);
  }
  /* Declaration order: the scene's own flag, then the children in the
   * order they were declared. */
  CHECK(ix[0] == 0, "allow_thread_reordering is entry %zu, expected 0", ix[0]);
  CHECK(ix[1] < ix[2] && ix[2] < ix[4] && ix[4] < ix[6] && ix[6] < ix[8],
        "children out of declaration order: my_bsdf %zu, rectangle_1 %zu, rectangle_2 %zu, disk_1 %zu, "
        "disk_2 %zu",
        ix[1], ix[2], ix[4], ix[6], ix[8]);
  CHECK(!params_info(s, n, &(param_info){0}), "params_info past the end must fail");

  /* Shared BSDF: listed once, its other paths are aliases. */
  static const char *const aliases[] = {"rectangle_1.bsdf.reflectance.value",
                                        "rectangle_2.bsdf.reflectance.value",
                                        "disk_1.bsdf.reflectance.value"};
  for (size_t k = 0; k < 3; k++)
    CHECK(idx_of(s, aliases[k]) == ix[1], "alias %s -> %zu, expected %zu (my_bsdf.reflectance.value)",
          aliases[k], idx_of(s, aliases[k]), ix[1]);
  param_info pi = {0};
  if (ix[1] != SIZE_MAX && params_info(s, ix[1], &pi)) {
    CHECK(pi.n_aliases == 3, "my_bsdf.reflectance.value has %zu aliases, expected 3", pi.n_aliases);
    for (size_t k = 0; k < 3; k++) {
      bool found = false;
      for (size_t a = 0; a < pi.n_aliases; a++) found = found || strcmp(pi.aliases[a], aliases[k]) == 0;
      CHECK(found, "alias %s not listed by params_info", aliases[k]);
    }
    CHECK(strcmp(pi.object_class, "texture") == 0, "owner class of my_bsdf.reflectance.value: %s",
          pi.object_class);
  }
  CHECK(ix[10] != ix[1], "disk_2's own BSDF must be a separate entry");
  if (ix[10] != SIZE_MAX && params_info(s, ix[10], &pi))
    CHECK(pi.n_aliases == 0, "disk_2.bsdf.reflectance.value has %zu aliases", pi.n_aliases);
  scene_free(s);
}

static void test_naming_misc(void) {
  scene *s = misc_scene(NULL);
  REQUIRE(s, "load");
  static const char *const present[] = {
      "my_shape.bsdf.reflectance.value",
      "my_shape.to_world",
      "my_shape.silhouette_sampling_weight",
      "emitter.irradiance.value",
      "emitter.to_world",
      "emitter.sampling_weight",
      "emitter.direction",
      "m.vertex_positions",
      "m.faces",
      "m.to_world",
      "m.bsdf.reflectance.value",
      "n.vertex_positions",
      "n.faces",
      "n.vertex_normals",
      "n.vertex_texcoords",
      "ball.to_world",
      "ball.bsdf.reflectance.value",
      "metal.bsdf.alpha.value",
      "metal.bsdf.eta.value",
      "metal.bsdf.k.value",
      "ts.bsdf.brdf_0.reflectance.value",
      "cam.to_world",
      "allow_thread_reordering",
  };
  for (size_t k = 0; k < sizeof present / sizeof *present; k++)
    CHECK(idx_of(s, present[k]) != SIZE_MAX, "missing key '%s'", present[k]);
  /* No attributes in m's file: no such buffers. */
  CHECK(idx_of(s, "m.vertex_normals") == SIZE_MAX, "m has no vertex normals, yet m.vertex_normals exists");
  CHECK(idx_of(s, "m.vertex_texcoords") == SIZE_MAX, "m has no uv, yet m.vertex_texcoords exists");
  /* twosided with one child: brdf_1 is brdf_0. */
  CHECK(idx_of(s, "ts.bsdf.brdf_1.reflectance.value") == idx_of(s, "ts.bsdf.brdf_0.reflectance.value"),
        "ts.bsdf.brdf_1 must alias brdf_0");
  /* Every key is unique and every entry names its owner. */
  size_t n = params_count(s);
  for (size_t i = 0; i < n; i++) {
    param_info a;
    REQUIRE(params_info(s, i, &a), "info %zu", i);
    CHECK(a.object_class && a.object_type, "%s: owner class/type missing", a.key);
    CHECK(idx_of(s, a.key) == i, "lookup of '%s' gives %zu, expected %zu", a.key, idx_of(s, a.key), i);
  }
  scene_free(s);

  /* An hdistant sensor reports `direction`. */
  s = tsup_load("{\"type\": \"scene\", \"h\": {\"type\": \"hdistant\", \"film\": {\"type\": \"hdrfilm\","
                " \"width\": 4, \"height\": 4}}, \"p\": {\"type\": \"rectangle\"}}",
                NULL);
  REQUIRE(s, "load hdistant");
  CHECK(idx_of(s, "h.direction") != SIZE_MAX, "h.direction missing");
  CHECK(idx_of(s, "h.to_world") != SIZE_MAX, "h.to_world missing");
  scene_free(s);
}

/* ---- types, classes, shapes -------------------------------------------------- */

static void check_info(const scene *s, const char *key, param_type t, update_class c, size_t d0, size_t d1,
                       const char *owner_class) {
  size_t i = idx_of(s, key);
  param_info pi;
  if (i == SIZE_MAX || !params_info(s, i, &pi)) {
    CHECK(false, "%s: no entry", key);
    return;
  }
  CHECK(pi.type == t, "%s: type %s, expected %s", key, param_type_name(pi.type), param_type_name(t));
  CHECK(pi.cls == c, "%s: class %s, expected %s", key, update_class_name(pi.cls), update_class_name(c));
  CHECK(pi.shape[0] == d0 && pi.shape[1] == d1, "%s: shape [%zu, %zu], expected [%zu, %zu]", key, pi.shape[0],
        pi.shape[1], d0, d1);
  if (owner_class)
    CHECK(strcmp(pi.object_class, owner_class) == 0, "%s: owner class %s, expected %s", key, pi.object_class,
          owner_class);
}

static void test_info_types_classes(void) {
  CHECK(strcmp(param_type_name(PARAM_TRANSFORM), "transform") == 0, "param_type_name(TRANSFORM)");
  CHECK(strcmp(param_type_name(PARAM_FLOAT), "float") == 0, "param_type_name(FLOAT)");
  CHECK(strcmp(param_type_name(PARAM_SPECTRUM), "spectrum") == 0, "param_type_name(SPECTRUM)");
  CHECK(strcmp(update_class_name(UPDATE_NONE), "none") == 0, "update_class_name(NONE)");
  CHECK(strcmp(update_class_name(UPDATE_SPECTRAL), "spectral") == 0, "update_class_name(SPECTRAL)");
  CHECK(strcmp(update_class_name(UPDATE_GEOMETRIC), "geometric") == 0, "update_class_name(GEOMETRIC)");
  update_class uc = UPDATE_NONE;
  CHECK(update_class_parse("geometric", &uc) && uc == UPDATE_GEOMETRIC, "parse geometric");
  CHECK(update_class_parse("spectral", &uc) && uc == UPDATE_SPECTRAL, "parse spectral");
  CHECK(update_class_parse("none", &uc) && uc == UPDATE_NONE, "parse none");
  CHECK(!update_class_parse("geometrical", &uc), "parse of an unknown class must fail");

  scene *s = misc_scene(NULL);
  REQUIRE(s, "load rgb");
  check_info(s, "my_shape.to_world", PARAM_TRANSFORM, UPDATE_GEOMETRIC, 4, 4, "shape");
  check_info(s, "my_shape.silhouette_sampling_weight", PARAM_FLOAT, UPDATE_NONE, 1, 0, "shape");
  /* rgb variant: a reflectance given as rgb has shape [3]; one given as a
   * number stays one number (shape [1], JSON a number; params.h: "an
   * [r, g, b] triple (or one number)"), as Mitsuba's uniform spectrum in
   * rgb variants. */
  check_info(s, "my_shape.bsdf.reflectance.value", PARAM_RGB, UPDATE_SPECTRAL, 1, 0, "texture");
  check_info(s, "ball.bsdf.reflectance.value", PARAM_RGB, UPDATE_SPECTRAL, 3, 0, "texture");
  check_info(s, "m.vertex_positions", PARAM_BUFFER, UPDATE_GEOMETRIC, 12, 0, "shape");
  check_info(s, "m.faces", PARAM_BUFFER, UPDATE_GEOMETRIC, 6, 0, "shape");
  check_info(s, "m.to_world", PARAM_TRANSFORM, UPDATE_GEOMETRIC, 4, 4, "shape");
  /* Normals and uv are used at shading time only: spectral (params.h),
   * no acceleration-structure work. */
  check_info(s, "n.vertex_normals", PARAM_BUFFER, UPDATE_SPECTRAL, 12, 0, "shape");
  check_info(s, "n.vertex_texcoords", PARAM_BUFFER, UPDATE_SPECTRAL, 8, 0, "shape");
  check_info(s, "emitter.to_world", PARAM_TRANSFORM, UPDATE_SPECTRAL, 4, 4, "emitter");
  check_info(s, "emitter.direction", PARAM_VECTOR, UPDATE_SPECTRAL, 3, 0, "emitter");
  check_info(s, "emitter.sampling_weight", PARAM_FLOAT, UPDATE_SPECTRAL, 1, 0, "emitter");
  check_info(s, "cam.to_world", PARAM_TRANSFORM, UPDATE_SPECTRAL, 4, 4, "sensor");
  check_info(s, "allow_thread_reordering", PARAM_BOOL, UPDATE_NONE, 1, 0, NULL);
  /* Owner identity. */
  param_info pi;
  size_t i = idx_of(s, "my_shape.to_world");
  if (i != SIZE_MAX && params_info(s, i, &pi)) {
    CHECK(strcmp(pi.object_type, "rectangle") == 0, "owner type %s", pi.object_type);
    CHECK(pi.object_id && strcmp(pi.object_id, "my_shape") == 0, "owner id %s",
          pi.object_id ? pi.object_id : "(null)");
  }
  i = idx_of(s, "metal.bsdf.alpha.value");
  if (i != SIZE_MAX && params_info(s, i, &pi)) CHECK(pi.cls == UPDATE_SPECTRAL, "alpha: spectral");
  scene_free(s);

  s = misc_scene("mono");
  REQUIRE(s, "load mono");
  check_info(s, "my_shape.bsdf.reflectance.value", PARAM_SPECTRUM, UPDATE_SPECTRAL, 1, 0, "texture");
  check_info(s, "emitter.irradiance.value", PARAM_SPECTRUM, UPDATE_SPECTRAL, 1, 0, "texture");
  scene_free(s);
}

/* ---- lookup ------------------------------------------------------------------ */

static bool match_set(const scene *s, const char *glob, unsigned mask, bool none, const char *const *keys,
                      size_t nk) {
  size_t *out = NULL, count = 0;
  rsw_err err = {0};
  if (params_match(s, glob, mask, none, &out, &count, &err) != RSW_OK) {
    char buf[1200];
    CHECK(false, "params_match(%s): %s", glob, rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  bool ok = count == nk;
  CHECK(count == nk, "params_match(%s, mask %u, none %d): %zu entries, expected %zu", glob, mask, none, count,
        nk);
  for (size_t k = 0; k < nk; k++) {
    size_t want = idx_of(s, keys[k]);
    bool found = false;
    for (size_t j = 0; j < count; j++) found = found || out[j] == want;
    CHECK(found, "params_match(%s): %s not matched", glob, keys[k]);
    ok = ok && found;
  }
  free(out);
  return ok;
}

static void test_lookup(void) {
  scene *s = tsup_load(ERD_SCENE, "mono");
  REQUIRE(s, "load");
  size_t mb = idx_of(s, "my_bsdf.reflectance.value"), d2 = idx_of(s, "disk_2.bsdf.reflectance.value");
  REQUIRE(mb != SIZE_MAX && d2 != SIZE_MAX, "keys");

  static const char *const refl[] = {"my_bsdf.reflectance.value", "disk_2.bsdf.reflectance.value"};
  match_set(s, "*.reflectance.value", UPDATE_SPECTRAL | UPDATE_GEOMETRIC, false, refl, 2);
  /* `*` crosses dots; aliases match but give their entry once. */
  match_set(s, "*reflectance*", UPDATE_SPECTRAL, false, refl, 2);
  match_set(s, "rect*value", UPDATE_SPECTRAL, false, refl, 1);
  static const char *const disks[] = {"disk_1.to_world", "disk_2.to_world"};
  match_set(s, "disk_?.to_world", UPDATE_GEOMETRIC, false, disks, 2);
  static const char *const geo[] = {"rectangle_1.to_world", "rectangle_2.to_world", "disk_1.to_world",
                                    "disk_2.to_world"};
  match_set(s, "*", UPDATE_GEOMETRIC, false, geo, 4);
  match_set(s, "*", UPDATE_SPECTRAL, false, refl, 2);
  static const char *const sil[] = {"rectangle_1.silhouette_sampling_weight",
                                    "rectangle_2.silhouette_sampling_weight"};
  match_set(s, "rectangle_?.sil*", 0, true, sil, 2);
  static const char *const geo_none[] = {"allow_thread_reordering",
                                         "rectangle_1.to_world",
                                         "rectangle_2.to_world",
                                         "disk_1.to_world",
                                         "disk_2.to_world",
                                         "rectangle_1.silhouette_sampling_weight",
                                         "rectangle_2.silhouette_sampling_weight",
                                         "disk_1.silhouette_sampling_weight",
                                         "disk_2.silhouette_sampling_weight"};
  match_set(s, "*", UPDATE_GEOMETRIC, true, geo_none, 9);
  size_t *out = NULL, count = 0;
  rsw_err err = {0};
  CHECK(params_match(s, "*", UPDATE_SPECTRAL | UPDATE_GEOMETRIC, true, &out, &count, &err) == RSW_OK &&
            count == params_count(s),
        "'*' with every class must match all %zu entries (got %zu)", params_count(s), count);
  free(out);
  out = NULL;
  /* Read-only entries are left out unless include_none. */
  err = (rsw_err){0};
  CHECK(params_match(s, "*.silhouette_sampling_weight", UPDATE_SPECTRAL | UPDATE_GEOMETRIC, false, &out,
                     &count, &err) == RSW_ERR_NOT_FOUND,
        "read-only entries must not match without include_none");
  free(out);
  out = NULL;
  err = (rsw_err){0};
  CHECK(params_match(s, "zzz*", UPDATE_SPECTRAL | UPDATE_GEOMETRIC, true, &out, &count, &err) ==
            RSW_ERR_NOT_FOUND,
        "no match must be RSW_ERR_NOT_FOUND");
  free(out);
  out = NULL;

  /* Eradiate's search TYPE:ID:PATH: by object class or plugin name, and
   * through a shape to its (shared) BSDF. */
  CHECK(idx_of(s, "bsdf:my_bsdf:reflectance.value") == mb,
        "bsdf:my_bsdf:reflectance.value -> %zu, expected %zu", idx_of(s, "bsdf:my_bsdf:reflectance.value"),
        mb);
  CHECK(idx_of(s, "diffuse:my_bsdf:reflectance.value") == mb, "diffuse:my_bsdf:reflectance.value -> %zu",
        idx_of(s, "diffuse:my_bsdf:reflectance.value"));
  CHECK(idx_of(s, "shape:disk_2:bsdf.reflectance.value") == d2, "shape:disk_2:bsdf.reflectance.value -> %zu",
        idx_of(s, "shape:disk_2:bsdf.reflectance.value"));
  CHECK(idx_of(s, "shape:rectangle_2:bsdf.reflectance.value") == mb,
        "shape:rectangle_2:bsdf.reflectance.value -> %zu (the shared entry %zu)",
        idx_of(s, "shape:rectangle_2:bsdf.reflectance.value"), mb);
  CHECK(idx_of(s, "shape:disk_1:to_world") == idx_of(s, "disk_1.to_world"), "shape:disk_1:to_world");
  static const char *const one[] = {"my_bsdf.reflectance.value"};
  match_set(s, "bsdf:my_bsdf:reflectance.value", UPDATE_SPECTRAL, false, one, 1);
  size_t ix;
  err = (rsw_err){0};
  CHECK(params_lookup(s, "bsdf:nope:reflectance.value", &ix, &err) == RSW_ERR_NOT_FOUND,
        "search: unknown id");
  err = (rsw_err){0};
  CHECK(params_lookup(s, "shape:my_bsdf:reflectance.value", &ix, &err) == RSW_ERR_NOT_FOUND,
        "search: my_bsdf is not a shape");
  err = (rsw_err){0};
  CHECK(params_lookup(s, "bsdf:my_bsdf:nope.value", &ix, &err) == RSW_ERR_NOT_FOUND, "search: unknown path");

  /* Unknown keys: NOT_FOUND naming the key and suggesting close ones. */
  err = (rsw_err){0};
  CHECK(params_lookup(s, "nope", &ix, &err) == RSW_ERR_NOT_FOUND, "unknown key");
  CHECK(err_mentions(&err, "nope"), "error must name the key: %s", err.msg);
  err = (rsw_err){0};
  CHECK(params_lookup(s, "disk_2.bsdf.reflectanse.value", &ix, &err) == RSW_ERR_NOT_FOUND, "misspelt key");
  CHECK(err_mentions(&err, "disk_2.bsdf.reflectance.value"), "suggestions must include the right key: %s",
        err.msg);
  err = (rsw_err){0};
  CHECK(params_lookup(s, "rectangle_1.to_wrld", &ix, &err) == RSW_ERR_NOT_FOUND, "misspelt key 2");
  CHECK(err_mentions(&err, "rectangle_1.to_world"), "suggestions must include rectangle_1.to_world: %s",
        err.msg);
  err = (rsw_err){0};
  CHECK(params_lookup(s, "", &ix, &err) == RSW_ERR_NOT_FOUND, "empty key");
  scene_free(s);
}

/* ---- value JSON ---------------------------------------------------------------- */

static void test_value_json(void) {
  scene *s = misc_scene(NULL);
  REQUIRE(s, "load");
  CHECK(value_num(s, "emitter.sampling_weight") == 1.0, "sampling_weight JSON: %g",
        value_num(s, "emitter.sampling_weight"));

  char *j = value_json(s, "ball.bsdf.reflectance.value");
  cJSON *v = j ? cJSON_Parse(j) : NULL;
  CHECK(v && cJSON_IsArray(v) && cJSON_GetArraySize(v) == 3 && cJSON_GetArrayItem(v, 0)->valuedouble == 0.2 &&
            cJSON_GetArrayItem(v, 1)->valuedouble == 0.5 && cJSON_GetArrayItem(v, 2)->valuedouble == 0.8,
        "rgb JSON: %s", j ? j : "(null)");
  cJSON_Delete(v);
  free(j);

  /* 4x4 nested rows, values exactly the loaded transform. */
  xform sc = xf_scale(v3(0.4, 0.4, 0.4)), tr = xf_translate(v3(0, 1.2, 0.5));
  xform t = xf_mul(&tr, &sc);
  j = value_json(s, "ball.to_world");
  v = j ? cJSON_Parse(j) : NULL;
  bool ok = v && cJSON_IsArray(v) && cJSON_GetArraySize(v) == 4;
  for (int r = 0; ok && r < 4; r++) {
    cJSON *row = cJSON_GetArrayItem(v, r);
    ok = cJSON_IsArray(row) && cJSON_GetArraySize(row) == 4;
    for (int c = 0; ok && c < 4; c++) ok = cJSON_GetArrayItem(row, c)->valuedouble == t.m[r][c];
  }
  CHECK(ok, "to_world JSON: %s", j ? j : "(null)");
  cJSON_Delete(v);
  free(j);

  /* Buffers: full, and elided past max_items. */
  size_t i = idx_of(s, "m.vertex_positions");
  REQUIRE(i != SIZE_MAX, "m.vertex_positions");
  j = params_value_json(s, i, 0);
  v = j ? cJSON_Parse(j) : NULL;
  static const double q[12] = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0};
  ok = v && cJSON_IsArray(v) && cJSON_GetArraySize(v) == 12;
  for (int k = 0; ok && k < 12; k++) ok = cJSON_GetArrayItem(v, k)->valuedouble == q[k];
  CHECK(ok, "vertex_positions JSON (object space): %s", j ? j : "(null)");
  cJSON_Delete(v);
  free(j);
  j = params_value_json(s, i, 5);
  v = j ? cJSON_Parse(j) : NULL;
  cJSON *len = v ? cJSON_GetObjectItemCaseSensitive(v, "length") : NULL;
  CHECK(cJSON_IsObject(v) && cJSON_IsNumber(len) && len->valuedouble == 12, "elided buffer JSON: %s",
        j ? j : "(null)");
  cJSON_Delete(v);
  free(j);
  j = params_value_json(s, i, 12);
  v = j ? cJSON_Parse(j) : NULL;
  CHECK(cJSON_IsArray(v) && cJSON_GetArraySize(v) == 12, "12 items with max_items 12 are not elided: %s",
        j ? j : "(null)");
  cJSON_Delete(v);
  free(j);
  j = value_json(s, "m.faces");
  v = j ? cJSON_Parse(j) : NULL;
  static const double fq[6] = {0, 1, 2, 0, 2, 3};
  ok = v && cJSON_IsArray(v) && cJSON_GetArraySize(v) == 6;
  for (int k = 0; ok && k < 6; k++) ok = cJSON_GetArrayItem(v, k)->valuedouble == fq[k];
  CHECK(ok, "faces JSON: %s", j ? j : "(null)");
  cJSON_Delete(v);
  free(j);
  j = value_json(s, "allow_thread_reordering");
  v = j ? cJSON_Parse(j) : NULL;
  CHECK(cJSON_IsBool(v), "bool JSON: %s", j ? j : "(null)");
  cJSON_Delete(v);
  free(j);
  scene_free(s);

  /* Mono: a tabulated spectrum comes back as {"wavelengths", "values"}. */
  s = tsup_load(
      "{\"type\": \"scene\", \"p\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\","
      " \"reflectance\": {\"type\": \"spectrum\", \"wavelengths\": [400, 700], \"values\": [0.25, 0.75]}}}}",
      "mono");
  REQUIRE(s, "load mono");
  j = value_json(s, "p.bsdf.reflectance.value");
  v = j ? cJSON_Parse(j) : NULL;
  cJSON *wl = v ? cJSON_GetObjectItemCaseSensitive(v, "wavelengths") : NULL;
  cJSON *va = v ? cJSON_GetObjectItemCaseSensitive(v, "values") : NULL;
  CHECK(cJSON_IsArray(wl) && cJSON_IsArray(va) && cJSON_GetArraySize(wl) == 2 &&
            cJSON_GetArraySize(va) == 2 && cJSON_GetArrayItem(wl, 1)->valuedouble == 700 &&
            cJSON_GetArrayItem(va, 0)->valuedouble == 0.25,
        "table JSON: %s", j ? j : "(null)");
  cJSON_Delete(v);
  free(j);
  scene_free(s);
}

/* ---- value parsing ---------------------------------------------------------------- */

static void test_value_parse(void) {
  param_value v = {0};
  rsw_err err = {0};
  REQUIRE(param_value_parse("0.3", "t", &v, &err) == RSW_OK, "number");
  CHECK(v.kind == PV_NUMBER && v.num == 0.3, "0.3: kind %d num %g", v.kind, v.num);
  param_value_free(&v);
  REQUIRE(param_value_parse(" -2e-3 ", "t", &v, &err) == RSW_OK, "number with spaces");
  CHECK(v.kind == PV_NUMBER && v.num == -2e-3, "-2e-3");
  param_value_free(&v);
  REQUIRE(param_value_parse("true", "t", &v, &err) == RSW_OK, "bool");
  CHECK(v.kind == PV_BOOL && v.b, "true");
  param_value_free(&v);
  REQUIRE(param_value_parse("[0.1, 0.2, 0.3]", "t", &v, &err) == RSW_OK, "array");
  CHECK(v.kind == PV_ARRAY && v.n == 3 && v.rows == 0 && v.arr[0] == 0.1 && v.arr[2] == 0.3, "array 3");
  param_value_free(&v);
  REQUIRE(param_value_parse("[[1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12], [0, 0, 0, 1]]", "t", &v, &err) ==
              RSW_OK,
          "nested 4x4");
  bool ok = v.kind == PV_ARRAY && v.n == 16 && v.rows == 4;
  static const double m[16] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 0, 0, 0, 1};
  for (int k = 0; ok && k < 16; k++) ok = v.arr[k] == m[k];
  CHECK(ok, "nested 4x4: kind %d n %zu rows %zu, row-major flattening", v.kind, v.n, v.rows);
  param_value_free(&v);
  REQUIRE(param_value_parse("[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 0, 0, 0, 1]", "t", &v, &err) == RSW_OK,
          "flat 16");
  CHECK(v.kind == PV_ARRAY && v.n == 16 && v.rows == 0 && v.arr[4] == 5, "flat 16");
  param_value_free(&v);
  REQUIRE(param_value_parse("{\"wavelengths\": [400, 500, 600], \"values\": [0.1, 0.2, 0.4]}", "t", &v,
                            &err) == RSW_OK,
          "table (wavelengths/values)");
  CHECK(v.kind == PV_TABLE && v.table.kind == SPEC_TABLE && v.table.n == 3 && v.table.wl[2] == 600 &&
            v.table.val[1] == 0.2,
        "table 1");
  param_value_free(&v);
  REQUIRE(param_value_parse("{\"type\": \"spectrum\", \"value\": [[400, 0.1], [500, 0.2], [600, 0.4]]}", "t",
                            &v, &err) == RSW_OK,
          "table (pairs)");
  CHECK(v.kind == PV_TABLE && v.table.n == 3 && v.table.wl[1] == 500 && v.table.val[2] == 0.4, "table 2");
  param_value_free(&v);

  static const char *const bad[] = {
      "",
      "   ",
      "abc",
      "[1,",
      "NaN",
      "nan",
      "Infinity",
      "-inf",
      "[1, \"a\"]",
      "[1, null]",
      "\"0.3\"",
      "null",
      "[[1, 2], [3]]",
      "{\"wavelengths\": [400, 500], \"values\": [0.1]}",
      "{\"wavelengths\": [500, 400], \"values\": [0.1, 0.2]}",
      "{\"values\": [0.1, 0.2]}",
      "{\"type\": \"spectrum\", \"value\": [[400, 0.1, 3]]}",
      "0.3 0.4",
  };
  for (size_t k = 0; k < sizeof bad / sizeof *bad; k++) {
    param_value w = {0};
    err = (rsw_err){0};
    rsw_status st = param_value_parse(bad[k], "my.where", &w, &err);
    CHECK(st != RSW_OK, "'%s' must not parse", bad[k]);
    if (st == RSW_OK) {
      param_value_free(&w);
      continue;
    }
    CHECK(err.code == st && err.msg[0], "'%s': error record not filled", bad[k]);
    CHECK(err_mentions(&err, "my.where"), "'%s': error must name the input: %s", bad[k], err.msg);
  }
}

/* ---- atomicity ------------------------------------------------------------------- */

typedef struct bad_case {
  const char *key;
  const char *json; /* NULL: NaN number built directly */
} bad_case;

/* param_value_from_json (what the service calls on a request body's
 * member, with no print-and-parse in between) gives what parsing the
 * member's text gives: the same kind, the same doubles bitwise, and on
 * bad values the same error code and message. */
static bool values_equal(const param_value *a, const param_value *b) {
  if (a->kind != b->kind || a->n != b->n || a->rows != b->rows || a->b != b->b) return false;
  if (memcmp(&a->num, &b->num, sizeof a->num) != 0) return false;
  if (a->n && memcmp(a->arr, b->arr, a->n * sizeof *a->arr) != 0) return false;
  if (a->kind == PV_TABLE) {
    if (a->table.kind != b->table.kind || a->table.n != b->table.n) return false;
    if (a->table.n && (memcmp(a->table.wl, b->table.wl, a->table.n * sizeof(double)) != 0 ||
                       memcmp(a->table.val, b->table.val, a->table.n * sizeof(double)) != 0))
      return false;
  }
  return true;
}

static void test_value_from_json(void) {
  static const char *const texts[] = {
      "0.30000000000000004",
      "-2e-3",
      "1e308",
      "true",
      "[0.1, 0.2, 0.3]",
      "[[1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12], [0, 0, 0, 1]]",
      "{\"wavelengths\": [400, 500, 600], \"values\": [0.1, 0.2, 0.4]}",
      "{\"type\": \"spectrum\", \"value\": [[400, 0.1], [500, 0.2]]}",
      "{\"type\": \"rgb\", \"value\": [0.2, 0.5, 0.7]}",
      "{\"type\": \"uniform\", \"value\": 0.25}",
      "{\"type\": \"rgb\", \"value\": [1, 2]}",
      "[[1, 2], [3]]",
      "\"text\"",
      "null",
      "{\"wavelengths\": [500, 400], \"values\": [0.1, 0.2]}",
  };
  for (size_t i = 0; i < sizeof texts / sizeof texts[0]; i++) {
    cJSON *j = cJSON_Parse(texts[i]);
    REQUIRE(j != NULL, "%s parses", texts[i]);
    param_value a = {0}, b = {0};
    rsw_err ea = {0}, eb = {0};
    rsw_status sa = param_value_parse(texts[i], "k", &a, &ea);
    rsw_status sb = param_value_from_json(j, "k", &b, &eb);
    CHECK(sa == sb, "%s: parse %d, from_json %d", texts[i], (int)sa, (int)sb);
    if (sa == RSW_OK && sb == RSW_OK)
      CHECK(values_equal(&a, &b), "%s: the values differ", texts[i]);
    else
      CHECK(strcmp(ea.msg, eb.msg) == 0 && strcmp(ea.where, eb.where) == 0,
            "%s: '%s' at '%s' vs '%s' at '%s'", texts[i], ea.msg, ea.where, eb.msg, eb.where);
    param_value_free(&a);
    param_value_free(&b);
    cJSON_Delete(j);
  }
}

static void test_atomic_bad_entry(void) {
  scene *s = misc_scene(NULL);
  REQUIRE(s, "load");
  film_image before;
  REQUIRE(render16(s, &before), "render before");
  char *v0 = value_json(s, "my_shape.bsdf.reflectance.value");
  char *m0 = value_json(s, "m.to_world");
  REQUIRE(v0 && m0, "value_json");
  static const bad_case bad[] = {
      {"my_shape.bsdf.reflectanse.value", "0.5"},                          /* unknown key */
      {"my_shape.to_world", "[1, 2]"},                                     /* wrong shape */
      {"my_shape.to_world", "[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]"}, /* 3 rows */
      {"emitter.irradiance.value", NULL},                                  /* NaN */
      {"emitter.sampling_weight", NULL},                                   /* NaN */
      {"my_shape.silhouette_sampling_weight", "2"},                        /* read-only */
      {"allow_thread_reordering", "false"},                                /* read-only */
      {"ball.bsdf.reflectance.value", "[-0.1, 0.2, 0.3]"},                 /* negative reflectance */
      {"ball.bsdf.reflectance.value", "[0.1, 0.2]"},                       /* rgb of 2 */
      {"metal.bsdf.alpha.value", "0"},                                     /* alpha 0 */
      {"metal.bsdf.alpha.value", "-0.2"},
      {"my_shape.to_world", "[0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1]"}, /* singular */
      {"ball.to_world", "[1, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]"}, /* sphere: non-uniform scale */
      {"m.vertex_positions", "[0, 0, 0, 1, 0, 0, 1, 1, 0]"},                 /* wrong count */
      {"m.faces", "[0, 1, 2, 0, 2, 9]"},                                     /* index out of range */
      {"emitter.direction", "[0, 0, 0]"},                                    /* zero direction */
      {"emitter.sampling_weight", "-1"},
      {"cam.to_world", "[0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]"}, /* singular */
      {"my_shape.to_world", "true"},                                        /* bool for a transform */
      {"emitter.sampling_weight", "[1, 2, 3]"},                             /* array for a float */
      {"my_shape.bsdf.reflectance.value",
       "{\"wavelengths\": [400, 500], \"values\": [0.1, 0.2]}"}, /* table in rgb */
  };
  for (size_t k = 0; k < sizeof bad / sizeof *bad; k++) {
    /* Good entry first, then the bad one; and the bad one first. */
    for (int order = 0; order < 2; order++) {
      param_update items[2];
      rsw_err err = {0};
      param_update *good = &items[order], *bd = &items[1 - order];
      good->key = "my_shape.bsdf.reflectance.value";
      REQUIRE(param_value_parse("0.8", "good", &good->value, &err) == RSW_OK, "parse good");
      bd->key = bad[k].key;
      if (bad[k].json) {
        if (param_value_parse(bad[k].json, bad[k].key, &bd->value, &err) != RSW_OK) {
          char buf[1200];
          CHECK(false, "%s = %s: the value must parse (the update should reject it): %s", bad[k].key,
                bad[k].json, rsw_err_format(&err, buf, sizeof buf));
          param_value_free(&good->value);
          continue;
        }
      } else {
        bd->value = (param_value){.kind = PV_NUMBER, .num = NAN};
      }
      update_report rep = {.changed = 12345};
      rsw_status st = scene_update(s, items, 2, &rep, &err);
      CHECK(st != RSW_OK, "update with bad %s = %s must fail", bad[k].key, bad[k].json ? bad[k].json : "NaN");
      CHECK(st != RSW_OK && err_mentions(&err, bad[k].key), "error for %s must name it: %s", bad[k].key,
            err.msg);
      param_value_free(&items[0].value);
      param_value_free(&items[1].value);
      char *v1 = value_json(s, "my_shape.bsdf.reflectance.value");
      CHECK(v1 && strcmp(v0, v1) == 0, "bad %s: the good entry changed to %s (was %s)", bad[k].key,
            v1 ? v1 : "(null)", v0);
      free(v1);
      char *m1 = value_json(s, "m.to_world");
      CHECK(m1 && strcmp(m0, m1) == 0, "bad %s: m.to_world changed", bad[k].key);
      free(m1);
    }
  }
  /* Nothing the failed updates touched shows in a render. */
  film_image after;
  REQUIRE(render16(s, &after), "render after");
  CHECK(same_film(&before, &after), "renders differ after rejected updates");
  film_image_free(&after);
  /* The scene still accepts a good update afterwards. */
  update_report rep;
  if (upd1_ok(s, "my_shape.bsdf.reflectance.value", "0.8", &rep)) {
    CHECK(rep.changed == 1, "changed = %zu", rep.changed);
    REQUIRE(render16(s, &after), "render after good update");
    CHECK(!same_film(&before, &after), "a good update must change the render");
    film_image_free(&after);
  }
  film_image_free(&before);
  free(v0);
  free(m0);
  scene_free(s);
}

/* ---- no-ops, classes, counters --------------------------------------------------- */

static bool same_counters(const accel_counters *a, const accel_counters *b) {
  return a->top_commits == b->top_commits && a->instance_updates == b->instance_updates &&
         a->refits == b->refits && a->rebuilds == b->rebuilds;
}

static void test_equal_values_noop(void) {
  scene *s = misc_scene(NULL);
  REQUIRE(s, "load");
  accel_counters c0, c1;
  accel_get_counters(s->accel, &c0);
  update_report rep = {.changed = 99, .classes = 99};
  if (upd1_ok(s, "my_shape.bsdf.reflectance.value", "0.3", &rep))
    CHECK(rep.changed == 0 && rep.classes == 0, "equal reflectance: changed %zu classes %u", rep.changed,
          rep.classes);
  rep = (update_report){.changed = 99, .classes = 99};
  if (upd1_ok(s, "ball.bsdf.reflectance.value", "[0.2, 0.5, 0.8]", &rep))
    CHECK(rep.changed == 0 && rep.classes == 0, "equal rgb: changed %zu classes %u", rep.changed,
          rep.classes);
  /* The current to_world written back, read from the table itself. */
  char *mj = value_json(s, "ball.to_world");
  rep = (update_report){.changed = 99, .classes = 99};
  if (mj && upd1_ok(s, "ball.to_world", mj, &rep))
    CHECK(rep.changed == 0 && rep.classes == 0, "equal to_world: changed %zu classes %u", rep.changed,
          rep.classes);
  free(mj);
  char *vp = value_json(s, "m.vertex_positions");
  rep = (update_report){.changed = 99, .classes = 99};
  if (vp && upd1_ok(s, "m.vertex_positions", vp, &rep))
    CHECK(rep.changed == 0 && rep.classes == 0, "equal vertex_positions: changed %zu classes %u", rep.changed,
          rep.classes);
  free(vp);
  accel_get_counters(s->accel, &c1);
  CHECK(same_counters(&c0, &c1), "no-op updates did acceleration work (commits %lu->%lu, refits %lu->%lu)",
        c0.top_commits, c1.top_commits, c0.refits, c1.refits);
  CHECK(rep.refits == 0 && rep.rebuilds == 0 && rep.instance_updates == 0, "no-op report shows accel work");
  scene_free(s);
}

static void test_update_classes_counters(void) {
  scene *s = misc_scene(NULL);
  REQUIRE(s, "load");
  REQUIRE(s->accel, "accel");
  accel_counters c0, c1;
  accel_get_counters(s->accel, &c0);

  /* Spectral: no Embree work at all. */
  param_update u[5] = {{.key = "my_shape.bsdf.reflectance.value"},
                       {.key = "emitter.irradiance.value"},
                       {.key = "emitter.direction"},
                       {.key = "cam.to_world"},
                       {.key = "metal.bsdf.alpha.value"}};
  static const char *const vals[5] = {"0.55", "[2, 1, 0.5]", "[0.1, -0.3, -1]",
                                      "[[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 5], [0, 0, 0, 1]]", "0.1"};
  rsw_err err = {0};
  size_t np = 0;
  for (; np < 5; np++)
    if (param_value_parse(vals[np], u[np].key, &u[np].value, &err) != RSW_OK) break;
  CHECK(np == 5, "parse spectral values: %s", err.msg);
  update_report rep = {0};
  if (np == 5) {
    rsw_status st = scene_update(s, u, 5, &rep, &err);
    CHECK(st == RSW_OK, "spectral update: %s", err.msg);
    CHECK(rep.classes == UPDATE_SPECTRAL, "spectral update: classes %u", rep.classes);
    CHECK(rep.changed == 5, "spectral update: changed %zu", rep.changed);
    CHECK(rep.refits == 0 && rep.rebuilds == 0 && rep.instance_updates == 0,
          "spectral update reported accel work: %u refits, %u rebuilds, %u instance updates", rep.refits,
          rep.rebuilds, rep.instance_updates);
    CHECK(rep.seconds >= 0, "seconds %g", rep.seconds);
  }
  for (size_t k = 0; k < np; k++) param_value_free(&u[k].value);
  accel_get_counters(s->accel, &c1);
  CHECK(same_counters(&c0, &c1), "spectral update touched Embree: commits %lu->%lu, instances %lu->%lu",
        c0.top_commits, c1.top_commits, c0.instance_updates, c1.instance_updates);

  /* A shape's to_world: instance transform and one top-level commit, no
   * refit or rebuild. */
  c0 = c1;
  if (upd1_ok(s, "my_shape.to_world", "[1, 0, 0, 0.25, 0, 1, 0, -0.5, 0, 0, 1, 0.1, 0, 0, 0, 1]", &rep)) {
    accel_get_counters(s->accel, &c1);
    CHECK(rep.classes == UPDATE_GEOMETRIC, "to_world: classes %u", rep.classes);
    CHECK(c1.top_commits == c0.top_commits + 1, "to_world: top commits %lu -> %lu", c0.top_commits,
          c1.top_commits);
    CHECK(c1.instance_updates > c0.instance_updates, "to_world: instance updates %lu -> %lu",
          c0.instance_updates, c1.instance_updates);
    CHECK(c1.refits == c0.refits && c1.rebuilds == c0.rebuilds, "to_world: refits %lu->%lu rebuilds %lu->%lu",
          c0.refits, c1.refits, c0.rebuilds, c1.rebuilds);
    CHECK(rep.instance_updates >= 1 && rep.refits == 0 && rep.rebuilds == 0, "to_world report: %u/%u/%u",
          rep.instance_updates, rep.refits, rep.rebuilds);
    c0 = c1;
  }
  /* A mesh's to_world is an instance transform too. */
  if (upd1_ok(s, "m.to_world", "[1, 0, 0, 1.25, 0, 1, 0, 0, 0, 0, 1, 0.3, 0, 0, 0, 1]", &rep)) {
    accel_get_counters(s->accel, &c1);
    CHECK(c1.refits == c0.refits && c1.rebuilds == c0.rebuilds && c1.top_commits == c0.top_commits + 1,
          "mesh to_world: refits %lu->%lu rebuilds %lu->%lu commits %lu->%lu", c0.refits, c1.refits,
          c0.rebuilds, c1.rebuilds, c0.top_commits, c1.top_commits);
    c0 = c1;
  }
  /* Vertex positions: a refit of that mesh only. */
  if (upd1_ok(s, "m.vertex_positions", "[-1, -1, 0, 1, -1, 0.25, 1, 1, 0.5, -1, 1, 0]", &rep)) {
    accel_get_counters(s->accel, &c1);
    CHECK(rep.classes == UPDATE_GEOMETRIC, "vertex_positions: classes %u", rep.classes);
    CHECK(c1.refits == c0.refits + 1, "vertex_positions: refits %lu -> %lu", c0.refits, c1.refits);
    CHECK(c1.rebuilds == c0.rebuilds, "vertex_positions: rebuilds %lu -> %lu", c0.rebuilds, c1.rebuilds);
    CHECK(rep.refits == 1 && rep.rebuilds == 0, "vertex_positions report: refits %u rebuilds %u", rep.refits,
          rep.rebuilds);
    c0 = c1;
  }
  /* Faces: topology, a rebuild of that mesh's BVH. */
  if (upd1_ok(s, "m.faces", "[0, 1, 3, 1, 2, 3]", &rep)) {
    accel_get_counters(s->accel, &c1);
    CHECK(rep.classes == UPDATE_GEOMETRIC, "faces: classes %u", rep.classes);
    CHECK(c1.rebuilds == c0.rebuilds + 1, "faces: rebuilds %lu -> %lu", c0.rebuilds, c1.rebuilds);
    CHECK(rep.rebuilds == 1, "faces report: rebuilds %u", rep.rebuilds);
    c0 = c1;
  }
  /* Mixed: both bits. */
  param_update mix[2] = {{.key = "my_shape.bsdf.reflectance.value"}, {.key = "ball.to_world"}};
  err = (rsw_err){0};
  if (param_value_parse("0.65", "a", &mix[0].value, &err) == RSW_OK &&
      param_value_parse("[0.5, 0, 0, 0.1, 0, 0.5, 0, 1.2, 0, 0, 0.5, 0.5, 0, 0, 0, 1]", "b", &mix[1].value,
                        &err) == RSW_OK) {
    CHECK(scene_update(s, mix, 2, &rep, &err) == RSW_OK, "mixed update: %s", err.msg);
    CHECK(rep.classes == (UPDATE_SPECTRAL | UPDATE_GEOMETRIC) && rep.changed == 2,
          "mixed: classes %u changed %zu", rep.classes, rep.changed);
  } else {
    CHECK(false, "parse mixed: %s", err.msg);
  }
  param_value_free(&mix[0].value);
  param_value_free(&mix[1].value);

  /* Updates are visible in the table: the written values read back. */
  char *j = value_json(s, "my_shape.bsdf.reflectance.value");
  cJSON *v = j ? cJSON_Parse(j) : NULL;
  bool ok =
      v &&
      ((cJSON_IsNumber(v) && v->valuedouble == 0.65) ||
       (cJSON_IsArray(v) && cJSON_GetArraySize(v) == 3 && cJSON_GetArrayItem(v, 1)->valuedouble == 0.65));
  CHECK(ok, "reflectance reads back as %s, expected 0.65", j ? j : "(null)");
  cJSON_Delete(v);
  free(j);
  scene_free(s);
}

static void test_update_by_alias_and_search(void) {
  scene *s = tsup_load(ERD_SCENE, "mono");
  REQUIRE(s, "load");
  update_report rep;
  if (upd1_ok(s, "rectangle_2.bsdf.reflectance.value", "0.25", &rep)) {
    CHECK(value_num(s, "my_bsdf.reflectance.value") == 0.25, "after an update by alias: %g",
          value_num(s, "my_bsdf.reflectance.value"));
    CHECK(rep.changed == 1 && rep.classes == UPDATE_SPECTRAL, "alias update: changed %zu classes %u",
          rep.changed, rep.classes);
  }
  if (upd1_ok(s, "bsdf:my_bsdf:reflectance.value", "0.75", &rep)) {
    CHECK(value_num(s, "disk_1.bsdf.reflectance.value") == 0.75, "after an update by search: %g",
          value_num(s, "disk_1.bsdf.reflectance.value"));
    CHECK(value_num(s, "disk_2.bsdf.reflectance.value") == 0.5, "disk_2's own BSDF must be untouched: %g",
          value_num(s, "disk_2.bsdf.reflectance.value"));
  }
  /* Mono: a number becomes a tabulated spectrum and back. */
  if (upd1_ok(s, "disk_2.bsdf.reflectance.value", "{\"wavelengths\": [400, 800], \"values\": [0.1, 0.9]}",
              &rep)) {
    CHECK(rep.changed == 1, "table update changed %zu", rep.changed);
    char *j = value_json(s, "disk_2.bsdf.reflectance.value");
    CHECK(j && strstr(j, "wavelengths"), "table reads back as %s", j ? j : "(null)");
    free(j);
  }
  scene_free(s);
}

/* A position (a `point` emitter's) may be PATCHed to the origin; a direction
 * (a directional emitter's, a sensor's) may not, and the error names it. */
static void test_zero_vector_position_vs_direction(void) {
  scene *s = tsup_load("{\"type\": \"scene\", \"cam\": {\"type\": \"hdistant\","
                       "   \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4}},"
                       " \"lamp\": {\"type\": \"point\", \"position\": [0, 0, 2], \"intensity\": 1},"
                       " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1},"
                       " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\"}}}",
                       NULL);
  REQUIRE(s, "load");
  update_report rep;
  if (upd1_ok(s, "lamp.position", "[0, 0, 0]", &rep)) {
    char *v = value_json(s, "lamp.position");
    CHECK(v && strcmp(v, "[0, 0, 0]") == 0 && rep.changed == 1,
          "lamp.position after the update: %s (changed %zu)", v ? v : "(null)", (size_t)rep.changed);
    free(v);
  }
  static const char *const dirs[] = {"sun.direction", "cam.direction"};
  for (size_t k = 0; k < 2; k++) {
    rsw_err err = {0};
    rsw_status st = upd1(s, dirs[k], "[0, 0, 0]", NULL, &err);
    CHECK(st == RSW_ERR_INVALID && err_mentions(&err, dirs[k]) && strstr(err.msg, "direction"),
          "%s = [0, 0, 0]: status %d, %s", dirs[k], (int)st, err.msg);
  }
  scene_free(s);
}

/* ---- derived state ---------------------------------------------------------------- */

static void test_bsphere_refresh(void) {
  const char *fmt = "{\"type\": \"scene\", \"cam\": {\"type\": \"hdistant\","
                    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 64},"
                    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16, \"rfilter\": "
                    "{\"type\": \"box\"}}},"
                    " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1.0},"
                    " \"plate\": {\"type\": \"rectangle\", \"to_world\": %s,"
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";
  xform sc = xf_scale(v3(2, 2, 2)), tr = xf_translate(v3(40, -25, 10));
  xform t = xf_mul(&tr, &sc);
  char m[1024], a[4096], b[4096];
  xform_json(&t, m, sizeof m);
  snprintf(a, sizeof a, fmt, "[{\"scale\": 1}]");
  snprintf(b, sizeof b, fmt, m);
  scene *s = tsup_load(a, NULL), *s2 = tsup_load(b, NULL);
  REQUIRE(s && s2, "load");
  vec3 c0 = s->bsphere_center;
  double r0 = s->bsphere_radius;
  update_report rep;
  if (upd1_ok(s, "plate.to_world", m, &rep)) {
    CHECK(s->bsphere_center.x != c0.x && s->bsphere_radius != r0, "bounding sphere not refreshed");
    CHECK(memcmp(&s->bsphere_center, &s2->bsphere_center, sizeof(vec3)) == 0 &&
              s->bsphere_radius == s2->bsphere_radius,
          "bounding sphere (%.17g %.17g %.17g; %.17g) != reload's (%.17g %.17g %.17g; %.17g)",
          s->bsphere_center.x, s->bsphere_center.y, s->bsphere_center.z, s->bsphere_radius,
          s2->bsphere_center.x, s2->bsphere_center.y, s2->bsphere_center.z, s2->bsphere_radius);
    CHECK(memcmp(&s->bbox_min, &s2->bbox_min, sizeof(vec3)) == 0 &&
              memcmp(&s->bbox_max, &s2->bbox_max, sizeof(vec3)) == 0,
          "bounding box != reload's");
    /* hdistant without a target still sees the plate: a fraction 2/pi of
     * its rays hit (test_radiometry's no-target case), radiance
     * rho E cos(0) / pi. Tolerance: 3 standard errors. */
    film_image img;
    if (tsup_render(s, 0, 4, 2, &img)) {
      double mean, sem, expect = 2.0 / M_PI * 0.5 / M_PI;
      tsup_stats(&img, 0, &mean, &sem);
      CHECK(fabs(mean - expect) <= 3 * sem + 1e-12, "moved plate: mean %.6g vs %.6g (3 sigma %.3g)", mean,
            expect, 3 * sem);
      CHECK(sem < 0.05 * expect, "standard error %.3g too large", sem);
      film_image_free(&img);
    }
  }
  scene_free(s2);
  scene_free(s);
}

/* ---- mono tables at the render's wavelength ------------------------------------ */

static bool render_at(scene *s, double wl, film_image *out, rsw_err *err) {
  render_opts o = {.size = sizeof o, .spp = 4, .seed = 3, .threads = 1, .wavelength = wl};
  return render_sensor(s, &o, out, NULL, err) == RSW_OK;
}

static void test_mono_table_range(void) {
  /* A tabulated value is evaluated at the render's wavelength by linear
   * interpolation; outside the table it is an error, not zero (issue 3,
   * item 5) — after an update as after a load. */
  scene *s = tsup_load(
      "{\"type\": \"scene\", \"cam\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\"},"
      " \"film\": {\"type\": \"hdrfilm\", \"width\": 4, \"height\": 4, \"rfilter\": {\"type\": \"box\"}}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0, 0, -1], \"irradiance\": 1},"
      " \"p\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}",
      "mono");
  REQUIRE(s, "load");
  update_report rep;
  film_image img;
  rsw_err err = {0};
  if (upd1_ok(s, "p.bsdf.reflectance.value", "{\"wavelengths\": [400, 500], \"values\": [0.2, 0.6]}", &rep)) {
    /* Zero-variance scene: L = rho(450) E / pi with rho(450) = 0.4. */
    if (render_at(s, 450, &img, &err)) {
      CHECK_REL(img.data[0], 0.4 / M_PI, 1e-5);
      film_image_free(&img);
    } else {
      CHECK(false, "render at 450 nm inside the table failed: %s", err.msg);
    }
    err = (rsw_err){0};
    bool ok = render_at(s, 650, &img, &err);
    CHECK(!ok, "render at 650 nm outside the table [400, 500] must fail");
    if (ok) film_image_free(&img);
  }
  if (upd1_ok(s, "p.bsdf.reflectance.value", "{\"type\": \"spectrum\", \"value\": [[600, 0.3], [700, 0.7]]}",
              &rep)) {
    err = (rsw_err){0};
    if (render_at(s, 650, &img, &err)) {
      CHECK_REL(img.data[0], 0.5 / M_PI, 1e-5);
      film_image_free(&img);
    } else {
      CHECK(false, "render at 650 nm inside the new table failed: %s", err.msg);
    }
  }
  /* Back to a number. */
  if (upd1_ok(s, "p.bsdf.reflectance.value", "0.25", &rep)) {
    err = (rsw_err){0};
    if (render_at(s, 450, &img, &err)) {
      CHECK_REL(img.data[0], 0.25 / M_PI, 1e-5);
      film_image_free(&img);
    } else {
      CHECK(false, "render after setting a number failed: %s", err.msg);
    }
  }
  scene_free(s);
}

int main(void) {
  snprintf(ply_plain, sizeof ply_plain, "/tmp/rsw_params_%ld_plain.ply", (long)getpid());
  snprintf(ply_attrs, sizeof ply_attrs, "/tmp/rsw_params_%ld_attrs.ply", (long)getpid());
  if (!write_quad_ply(ply_plain, false) || !write_quad_ply(ply_attrs, true)) {
    printf("cannot write test meshes under /tmp\n");
    return 1;
  }
  RSW_TEST_RUN(test_naming_eradiate_example);
  RSW_TEST_RUN(test_naming_misc);
  RSW_TEST_RUN(test_info_types_classes);
  RSW_TEST_RUN(test_lookup);
  RSW_TEST_RUN(test_value_json);
  RSW_TEST_RUN(test_value_parse);
  RSW_TEST_RUN(test_value_from_json);
  RSW_TEST_RUN(test_atomic_bad_entry);
  RSW_TEST_RUN(test_equal_values_noop);
  RSW_TEST_RUN(test_update_classes_counters);
  RSW_TEST_RUN(test_update_by_alias_and_search);
  RSW_TEST_RUN(test_zero_vector_position_vs_direction);
  RSW_TEST_RUN(test_bsphere_refresh);
  RSW_TEST_RUN(test_mono_table_range);
  unlink(ply_plain);
  unlink(ply_attrs);
  RSW_TEST_END("test_params");
}
