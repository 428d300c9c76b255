/* Volumes (server/kernel/volumes/): constvolume values and grids in both
 * variants (tabulated spectra in mono at two wavelengths), the box from
 * to_world, ld_volume (numbers, spectra, nested and referenced volumes,
 * the slot's range at load and on update), parameter keys and update
 * validation naming the key. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../../server/kernel/scene/params.h"
#include "../../server/kernel/volumes/volume.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

/* ---- helpers ------------------------------------------------------------------ */

static object *find_cls(const scene *s, const char *id, obj_class cls) {
  for (size_t i = 0; i < s->n_objects; i++) {
    object *o = s->objects[i];
    if (o->id && strcmp(o->id, id) == 0 && o->plugin && o->plugin->cls == cls) return o;
  }
  return NULL;
}
static volume *find_vol(const scene *s, const char *id) {
  return (volume *)find_cls(s, id, CLS_VOLUME);
}

static scene *load(const char *objects, const char *variant) {
  char text[8192];
  snprintf(text, sizeof text, "{\"type\": \"scene\", %s}", objects);
  return tsup_load(text, variant);
}

static rsw_status load_err(const char *objects, const char *variant, rsw_err *err) {
  char text[8192];
  snprintf(text, sizeof text, "{\"type\": \"scene\", %s}", objects);
  scene *s = NULL;
  scene_load_opts o = {.size = sizeof o, .variant = variant};
  rsw_status st = scene_load_memory(text, strlen(text), "test-scene", false, &o, &s, err);
  scene_free(s);
  return st;
}

static rsw_status upd1(scene *s, const char *key, const char *json, rsw_err *err) {
  param_update u = {.key = key};
  rsw_status st = param_value_parse(json, key, &u.value, err);
  if (st) return st;
  st = scene_update(s, &u, 1, NULL, err);
  param_value_free(&u.value);
  return st;
}

static bool prepare(scene *s, rsw_variant var, double wl) {
  render_ctx rc = {.variant = var, .wavelength = wl};
  rsw_err err = {0};
  rsw_status st = scene_prepare(s, &rc, &err);
  if (st) printf("  prepare: %s: %s\n", err.where, err.msg);
  return st == RSW_OK;
}

/* ---- constvolume -------------------------------------------------------------- */

static void test_constvolume_mono(void) {
  scene *s =
      load("\"v\": {\"type\": \"constvolume\", \"value\": 0.4}, \"d\": {\"type\": \"constvolume\"}, "
           "\"t\": {\"type\": \"constvolume\", \"value\": {\"type\": \"spectrum\", \"value\": [[500, 1], "
           "[600, 3]]}}",
           "mono");
  REQUIRE(s, "load");
  volume *v = find_vol(s, "v"), *d = find_vol(s, "d"), *t = find_vol(s, "t");
  REQUIRE(v && d && t, "volumes");
  REQUIRE(prepare(s, VARIANT_MONO, 550), "prepare");
  CHECK(v->res[0] == 1 && v->res[1] == 1 && v->res[2] == 1 && v->channels == 1, "one cell, one channel");
  CHECK(volume_eval(v, v3(0.5, 0.5, 0.5)).c[0] == 0.4, "value 0.4");
  CHECK(volume_eval(v, v3(-7, 3, 100)).c[0] == 0.4, "everywhere");
  CHECK(v->max == 0.4 && v->data[0] == 0.4, "max %g, data %g", v->max, v->data[0]);
  CHECK(volume_eval_1(d, v3(0, 0, 0)) == 1.0, "default value 1 (Mitsuba)");
  CHECK_REL(volume_eval_1(t, v3(0, 0, 0)), 2.0, 1e-15);
  CHECK_REL(t->max, 2.0, 1e-15);
  REQUIRE(prepare(s, VARIANT_MONO, 575), "prepare 575");
  CHECK_REL(volume_eval_1(t, v3(0, 0, 0)), 2.5, 1e-15);
  CHECK_REL(t->max, 2.5, 1e-15);
  /* Outside the table: an error naming the property. */
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 700};
  rsw_err err = {0};
  CHECK(scene_prepare(s, &rc, &err) == RSW_ERR_RANGE, "700 nm outside the table");
  CHECK(strstr(err.where, "/t/value") != NULL, "where: %s", err.where);
  scene_free(s);
}

static void test_constvolume_rgb(void) {
  scene *s =
      load("\"v\": {\"type\": \"constvolume\", \"value\": [0.1, 0.2, 0.3], \"to_world\": [{\"scale\": [2, "
           "3, 4]}, {\"translate\": [1, 0, -1]}]}",
           "rgb");
  REQUIRE(s, "load");
  volume *v = find_vol(s, "v");
  REQUIRE(v, "volume");
  REQUIRE(prepare(s, VARIANT_RGB, 550), "prepare");
  color c = volume_eval(v, v3(0, 0, 0));
  CHECK(c.c[0] == 0.1 && c.c[1] == 0.2 && c.c[2] == 0.3, "rgb value %g %g %g", c.c[0], c.c[1], c.c[2]);
  CHECK(v->channels == 3 && v->max == 0.3, "3 channels, max %g", v->max);
  CHECK(v->bbox_min.x == 1 && v->bbox_min.y == 0 && v->bbox_min.z == -1, "bbox min");
  CHECK(v->bbox_max.x == 3 && v->bbox_max.y == 3 && v->bbox_max.z == 3, "bbox max");
  scene_free(s);
}

static void test_constvolume_params(void) {
  scene *s = load("\"v\": {\"type\": \"constvolume\", \"value\": 0.4}", "mono");
  REQUIRE(s, "load");
  rsw_err err = {0};
  size_t i;
  REQUIRE(params_lookup(s, "v.value.value", &i, &err) == RSW_OK, "v.value.value: %s", err.msg);
  REQUIRE(params_lookup(s, "v.to_world", &i, &err) == RSW_OK, "v.to_world: %s", err.msg);
  param_info info;
  params_info(s, i, &info);
  CHECK(info.cls == UPDATE_SPECTRAL, "to_world is spectral (no acceleration structure holds a volume)");
  /* Unconstrained on its own: any finite value. */
  CHECK(upd1(s, "v.value.value", "-3", &err) == RSW_OK, "-3: %s", err.msg);
  CHECK(upd1(s, "v.value.value", "{\"wavelengths\": [400, 700], \"values\": [1, 4]}", &err) == RSW_OK,
        "table: %s", err.msg);
  volume *v = find_vol(s, "v");
  REQUIRE(prepare(s, VARIANT_MONO, 500), "prepare");
  CHECK_REL(volume_eval_1(v, v3(0, 0, 0)), 2.0, 1e-15);
  CHECK_REL(v->max, 2.0, 1e-15);
  CHECK(upd1(s, "v.to_world", "[2,0,0,0, 0,2,0,0, 0,0,2,5, 0,0,0,1]", &err) == RSW_OK, "to_world: %s",
        err.msg);
  CHECK(v->bbox_min.z == 5 && v->bbox_max.z == 7 && v->bbox_max.x == 2, "box follows to_world");
  CHECK(upd1(s, "v.to_world", "[0,0,0,0, 0,2,0,0, 0,0,2,5, 0,0,0,1]", &err) == RSW_ERR_INVALID,
        "singular to_world rejected");
  scene_free(s);
}

/* ---- ld_volume (through blendphase's weight, a [0, 1] slot) --------------------- */

static const char *const PHASES =
    "\"phase_0\": {\"type\": \"isotropic\"}, \"phase_1\": {\"type\": \"hg\", \"g\": 0.5}";

static void test_ld_volume_forms(void) {
  char objs[2048];
  const char *forms[] = {
      "0.25",
      "{\"type\": \"constvolume\", \"value\": 0.25}",
      "{\"type\": \"uniform\", \"value\": 0.25}",
      "{\"type\": \"ref\", \"id\": \"w\"}",
      "{\"type\": \"spectrum\", \"value\": [[400, 0], [700, 0.5]]}",
  };
  for (size_t k = 0; k < sizeof forms / sizeof forms[0]; k++) {
    snprintf(objs, sizeof objs,
             "\"w\": {\"type\": \"constvolume\", \"value\": 0.25}, \"b\": {\"type\": \"blendphase\", "
             "\"weight\": %s, "
             "%s}",
             forms[k], PHASES);
    scene *s = load(objs, "mono");
    REQUIRE(s, "load weight %s", forms[k]);
    REQUIRE(prepare(s, VARIANT_MONO, 550), "prepare");
    /* The weight volume is what blendphase reads: find it through the
     * parameter table (its key under b). */
    rsw_err err = {0};
    size_t i;
    const char *key = k == 3 ? "w.value.value" : "b.weight.value.value";
    CHECK(params_lookup(s, key, &i, &err) == RSW_OK, "%s: key %s: %s", forms[k], key, err.msg);
    if (k == 3) CHECK(params_lookup(s, "b.weight.value.value", &i, &err) == RSW_OK, "alias through the ref");
    const phase *ph = (const phase *)find_cls(s, "b", CLS_PHASE);
    medium_interaction mi = {.wi = v3(0, 0, 1)};
    double pdf, v = ph->ops->eval_pdf(ph, &mi, v3(0, 0, -1), &pdf);
    CHECK_REL(v, 0.75 * RSW_INV_4PI + 0.25 * 0.75 / (4 * RSW_PI * 0.125), 1e-14);
    /* The slot's range holds on update, whichever key reaches it. */
    memset(&err, 0, sizeof err);
    CHECK(upd1(s, key, "1.5", &err) == RSW_ERR_RANGE, "%s: 1.5 rejected", forms[k]);
    CHECK(strstr(err.msg, key) != NULL, "names %s: %s", key, err.msg);
    CHECK(upd1(s, key, "0.5", &err) == RSW_OK, "%s: 0.5 accepted: %s", forms[k], err.msg);
    scene_free(s);
  }
}

static void test_ld_volume_errors(void) {
  static const struct {
    const char *weight, *want, *where;
  } bad[] = {
      {"2", "'weight' must be in [0, 1] (got 2)", "/b/weight"},
      {"-1", "'weight' must be >= 0", "/b/weight"},
      {"{\"type\": \"constvolume\", \"value\": 3}", "'weight' must be in [0, 1] (got 3)", "/b/weight"},
      {"{\"type\": \"ref\", \"id\": \"big\"}", "'weight' must be in [0, 1] (got 7)", "/b/weight"},
      {"{\"type\": \"spectrum\", \"value\": [[400, 0.5], [700, 1.5]]}", "(the volume holds 0.5 to 1.5)",
       "/b/weight"},
      {"{\"type\": \"checkerboard\"}", "constvolume holds spectra", "/b/weight"},
      {"\"x\"", "must be", "/b/weight"},
      {"{\"type\": \"constvolume\", \"value\": 0.5, \"shape\": 3}", "no property 'shape'", "/b/weight/shape"},
  };
  for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
    char objs[2048];
    snprintf(objs, sizeof objs,
             "\"big\": {\"type\": \"constvolume\", \"value\": 7}, \"b\": {\"type\": \"blendphase\", "
             "\"weight\": %s, "
             "%s}",
             bad[k].weight, PHASES);
    rsw_err err = {0};
    CHECK(load_err(objs, "mono", &err) != RSW_OK, "case %zu loads", k);
    CHECK(strstr(err.msg, bad[k].want) != NULL, "case %zu: '%s' not in '%s'", k, bad[k].want, err.msg);
    CHECK(strstr(err.where, bad[k].where) != NULL, "case %zu: where '%s', want '%s'", k, err.where,
          bad[k].where);
  }
  /* A tabulated value needs mono. */
  rsw_err err = {0};
  CHECK(
      load_err("\"v\": {\"type\": \"constvolume\", \"value\": {\"type\": \"spectrum\", \"value\": [[400, 1], "
               "[700, 2]]}}",
               "rgb", &err) == RSW_ERR_UNSUPPORTED,
      "table in rgb: %s", err.msg);
}

int main(void) {
  RSW_TEST_RUN(test_constvolume_mono);
  RSW_TEST_RUN(test_constvolume_rgb);
  RSW_TEST_RUN(test_constvolume_params);
  RSW_TEST_RUN(test_ld_volume_forms);
  RSW_TEST_RUN(test_ld_volume_errors);
  RSW_TEST_END("test_volume");
}
