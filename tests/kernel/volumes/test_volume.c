/* Volumes (server/kernel/volumes/): constvolume values and grids in both
 * variants (tabulated spectra in mono at two wavelengths), the box from
 * to_world, ld_volume (numbers, spectra, nested and referenced volumes,
 * the slot's range at load and on update), parameter keys and update
 * validation naming the key. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../server/kernel/core/rng.h"
#include "../../../server/kernel/scene/param_table.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../../server/kernel/volumes/volume.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

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

/* ---- gridvolume ----------------------------------------------------------------- */

/* Value at the centre of cell (ix, iy, iz) of a unit-cube grid of res r. */
static double at_cell(const volume *v, int ix, int iy, int iz) {
  vec3 p = v3((ix + 0.5) / v->res[0], (iy + 0.5) / v->res[1], (iz + 0.5) / v->res[2]);
  return volume_eval_1(v, p);
}

static void test_grid_layout(void) {
  /* Mitsuba's tensor order [Z, Y, X], x fastest. */
  scene *s = load("\"n\": {\"type\": \"gridvolume\", \"shape\": [2, 2, 3], \"filter_type\": \"nearest\", "
                  "\"data\": [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11]}, "
                  "\"t\": {\"type\": \"gridvolume\", \"shape\": [2, 2, 3], "
                  "\"data\": \"0 1 2 3 4 5 6 7 8 9 10 11\"}",
                  "mono");
  REQUIRE(s, "load");
  volume *n = find_vol(s, "n"), *t = find_vol(s, "t");
  REQUIRE(n && t, "volumes");
  CHECK(n->res[0] == 3 && n->res[1] == 2 && n->res[2] == 2 && n->channels == 1, "res %u %u %u", n->res[0],
        n->res[1], n->res[2]);
  CHECK(n->max == 11 && t->max == 11, "max");
  for (int iz = 0; iz < 2; iz++)
    for (int iy = 0; iy < 2; iy++)
      for (int ix = 0; ix < 3; ix++) {
        double want = (iz * 2 + iy) * 3 + ix;
        CHECK(at_cell(n, ix, iy, iz) == want, "nearest cell %d %d %d: %g", ix, iy, iz,
              at_cell(n, ix, iy, iz));
        CHECK_ABS(at_cell(t, ix, iy, iz), want, 1e-12);
      }
  /* Trilinear between centres; clamped outside (Mitsuba's defaults). */
  CHECK_ABS(volume_eval_1(t, v3(0.5, 0.25, 0.25)), 1.0, 1e-12);
  /* Halfway between cells 0 and 1 on every axis: the mean of the 8. */
  CHECK_ABS(volume_eval_1(t, v3(1.0 / 3.0, 0.5, 0.5)), 0.5 + 1.5 + 3.0, 1e-12);
  CHECK_ABS(volume_eval_1(t, v3(-5, -5, -5)), 0.0, 1e-12);
  CHECK_ABS(volume_eval_1(t, v3(9, 9, 9)), 11.0, 1e-12);
  CHECK_ABS(volume_eval_1(t, v3(0.5, 0.5, 0.5)), 5.5, 1e-12);
  CHECK(volume_eval_1(n, v3(1e300, -1e300, 0.9)) == 8, "far away: clamped");
  scene_free(s);
}

static void test_grid_wrap_and_box(void) {
  scene *s = load("\"r\": {\"type\": \"gridvolume\", \"shape\": [1, 1, 4], \"data\": [0, 1, 2, 3], "
                  "\"filter_type\": \"nearest\", \"wrap_mode\": \"repeat\"}, "
                  "\"m\": {\"type\": \"gridvolume\", \"shape\": [1, 1, 4], \"data\": [0, 1, 2, 3], "
                  "\"filter_type\": \"nearest\", \"wrap_mode\": \"mirror\"}, "
                  /* Eradiate's layers: [N, 1, 1] along z over a 0..120 box. */
                  "\"z\": {\"type\": \"gridvolume\", \"shape\": [3, 1, 1], \"data\": [5, 6, 7], "
                  "\"filter_type\": \"nearest\", \"to_world\": [{\"scale\": [10, 10, 120]}, "
                  "{\"translate\": [-5, -5, 0]}]}",
                  "mono");
  REQUIRE(s, "load");
  volume *r = find_vol(s, "r"), *m = find_vol(s, "m"), *z = find_vol(s, "z");
  REQUIRE(r && m && z, "volumes");
  CHECK(volume_eval_1(r, v3(1.125, 0.5, 0.5)) == 0, "repeat: 4.5 -> cell 0");
  CHECK(volume_eval_1(r, v3(-0.125, 0.5, 0.5)) == 3, "repeat: -0.5 -> cell 3");
  CHECK(volume_eval_1(m, v3(1.125, 0.5, 0.5)) == 3, "mirror: 4.5 -> cell 3");
  CHECK(volume_eval_1(m, v3(1.375, 0.5, 0.5)) == 2, "mirror: 5.5 -> cell 2");
  CHECK(volume_eval_1(m, v3(-0.125, 0.5, 0.5)) == 0, "mirror: -0.5 -> cell 0");
  CHECK(z->res[0] == 1 && z->res[1] == 1 && z->res[2] == 3, "layers along z");
  CHECK(volume_eval_1(z, v3(0, 0, 10)) == 5 && volume_eval_1(z, v3(4, -4, 60)) == 6 &&
            volume_eval_1(z, v3(0, 0, 119)) == 7,
        "layer values by height");
  CHECK(z->bbox_min.z == 0 && z->bbox_max.z == 120 && z->bbox_min.x == -5 && z->bbox_max.y == 5, "box");
  scene_free(s);
}

/* A nearest [1, 1, N] profile looks up z alone (gridvolume.c layer_cell):
 * bit for bit the cell of the general lookup, written out here (the whole
 * inverse transform, every axis folded and wrapped), for 20,000 random
 * points inside, around and far outside a rotated, scaled, shifted box,
 * half of them on a layer's boundary (the world point of local z = j / N,
 * which lands on either side), in each wrap mode, and for a [2, 1, N] grid (not a profile: the general
 * path) as a control. */
static int ref_wrap(int i, int n, int w) {
  if (w == 0) return i < 0 ? 0 : i >= n ? n - 1 : i;
  if (w == 1) {
    i %= n;
    return i < 0 ? i + n : i;
  }
  i %= 2 * n;
  if (i < 0) i += 2 * n;
  return i >= n ? 2 * n - 1 - i : i;
}
static double ref_fold(double x, int n, int w) {
  if (fabs(x) < 1e9) return x;
  if (w == 0) return x < 0 ? -1.0 : (double)n;
  return fmod(x, 2.0 * n);
}
static double ref_nearest(const volume *v, int w, vec3 p) {
  vec3 q = xf_inv_point(&v->to_world, p);
  double x[3] = {q.x, q.y, q.z};
  int i[3];
  for (int a = 0; a < 3; a++) {
    int n = (int)v->res[a];
    double c = ref_fold(x[a] * n, n, w);
    i[a] = ref_wrap((int)floor(isfinite(c) ? c : 0.0), n, w);
  }
  return v->data[((size_t)i[2] * v->res[1] + i[1]) * v->res[0] + i[0]];
}
static void test_grid_profile_lookup(void) {
  enum {
    N = 37
  };
  static const char *wraps[3] = {"clamp", "repeat", "mirror"};
  sbuf b = {0};
  sb_printf(&b, "{\"type\": \"scene\"");
  for (int g = 0; g < 4; g++) {
    bool two = g == 3; /* [2, 1, N]: the control */
    sb_printf(&b,
              ", \"g%d\": {\"type\": \"gridvolume\", \"filter_type\": \"nearest\", \"wrap_mode\": \"%s\", "
              "\"shape\": [%d, 1, %d], \"data\": [",
              g, wraps[g % 3], N, two ? 2 : 1);
    for (int i = 0; i < N * (two ? 2 : 1); i++) sb_printf(&b, "%s%d", i ? ", " : "", i);
    sb_printf(
        &b,
        "], \"to_world\": [{\"scale\": [3, 2, 1200]}, {\"rotate\": {\"axis\": [1, 2, 3], \"angle\": 17}}, "
        "{\"translate\": [-1.5, 4, 7]}]}");
  }
  sb_printf(&b, "}");
  scene *s = tsup_load(b.p, "mono");
  free(b.p);
  REQUIRE(s, "load");
  pcg32 rng;
  pcg32_seed(&rng, 7, 26);
  int differ = 0;
  for (int g = 0; g < 4; g++) {
    char id[16]; /* (room for any int: -Wformat-truncation at -O1) */
    snprintf(id, sizeof id, "g%d", g);
    volume *v = find_vol(s, id);
    REQUIRE(v, "%s", id);
    for (int k = 0; k < 5000; k++) {
      double r = k % 10 == 0 ? 1e13 : k % 10 == 1 ? 5e3 : 1500.0;
      vec3 p = v3(r * (2 * pcg32_next_double(&rng) - 1), r * (2 * pcg32_next_double(&rng) - 1),
                  r * (2 * pcg32_next_double(&rng) - 1));
      if (k % 2) { /* on a layer's boundary, where a rounding of z moves the point across */
        double zl = (double)(int)(pcg32_next_double(&rng) * (N + 1)) / N;
        p = xf_point(&v->to_world, v3(pcg32_next_double(&rng), pcg32_next_double(&rng), zl));
      }
      double got = volume_eval_1(v, p), want = ref_nearest(v, g % 3, p);
      if (memcmp(&got, &want, sizeof got)) differ++;
    }
  }
  CHECK(differ == 0, "%d lookups differ from the general nearest lookup", differ);
  scene_free(s);
}

static void test_grid_channels(void) {
  const char *g = "\"c\": {\"type\": \"gridvolume\", \"shape\": [1, 1, 2, 3], \"filter_type\": \"nearest\", "
                  "\"data\": [0.1, 0.2, 0.3, 0.6, 0.5, 0.4]}";
  scene *s = load(g, "rgb");
  REQUIRE(s, "load rgb");
  volume *v = find_vol(s, "c");
  color c = volume_eval(v, v3(0.75, 0.5, 0.5));
  CHECK(v->channels == 3 && c.c[0] == 0.6 && c.c[1] == 0.5 && c.c[2] == 0.4, "rgb cell");
  CHECK(v->max == 0.6, "max over channels");
  scene_free(s);
  s = load(g, "mono");
  REQUIRE(s, "load mono");
  v = find_vol(s, "c");
  CHECK(v->channels == 1, "mono: one channel");
  CHECK_REL(volume_eval_1(v, v3(0.25, 0.5, 0.5)), col_luminance(col(0.1, 0.2, 0.3)), 1e-15);
  CHECK_REL(v->max, col_luminance(col(0.6, 0.5, 0.4)), 1e-15);
  scene_free(s);
}

static void test_grid_spectral_cells(void) {
  scene *s = load("\"w\": {\"type\": \"gridvolume\", \"shape\": [2, 1, 1], \"filter_type\": \"nearest\", "
                  "\"wavelengths\": [500, 600, 700], \"data\": [1, 3, 5, 10, 30, 20]}",
                  "mono");
  REQUIRE(s, "load");
  volume *v = find_vol(s, "w");
  REQUIRE(prepare(s, VARIANT_MONO, 550), "prepare 550");
  CHECK_REL(at_cell(v, 0, 0, 0), 2.0, 1e-15);
  CHECK_REL(at_cell(v, 0, 0, 1), 20.0, 1e-15);
  CHECK_REL(v->max, 20.0, 1e-15);
  uint64_t rev = v->revision;
  REQUIRE(prepare(s, VARIANT_MONO, 550), "prepare 550 again");
  CHECK(v->revision == rev, "same wavelength: nothing re-evaluated");
  REQUIRE(prepare(s, VARIANT_MONO, 650), "prepare 650");
  CHECK(v->revision != rev, "new wavelength: revision bumped");
  CHECK_REL(at_cell(v, 0, 0, 0), 4.0, 1e-15);
  CHECK_REL(at_cell(v, 0, 0, 1), 25.0, 1e-15);
  CHECK_REL(v->max, 25.0, 1e-15);
  /* The data key holds the tables; an update re-evaluates at 650 nm. */
  rsw_err err = {0};
  size_t i;
  param_info info;
  REQUIRE(params_lookup(s, "w.data", &i, &err) == RSW_OK, "w.data: %s", err.msg);
  params_info(s, i, &info);
  CHECK(info.type == PARAM_BUFFER && info.shape[0] == 6 && info.cls == UPDATE_SPECTRAL,
        "w.data: buffer of 6");
  CHECK(upd1(s, "w.data", "[1, 3, 5, 10, 50, 20]", &err) == RSW_OK, "update: %s", err.msg);
  CHECK_REL(at_cell(v, 0, 0, 1), 35.0, 1e-15);
  CHECK_REL(v->max, 35.0, 1e-15);
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 450};
  memset(&err, 0, sizeof err);
  CHECK(scene_prepare(s, &rc, &err) == RSW_ERR_RANGE, "450 nm outside the tables");
  CHECK(strstr(err.where, "/w/data") && strstr(err.msg, "[500, 700]"), "error: %s: %s", err.where, err.msg);
  scene_free(s);
}

/* A .vol file (Mitsuba's layout) with a bounding box. */
static bool write_vol(const char *path, const char magic[4], uint32_t enc, uint32_t res[3], uint32_t ch,
                      const float bbox[6], const float *v, size_t n) {
  FILE *f = fopen(path, "wb");
  if (!f) return false;
  uint32_t hdr[5] = {enc, res[0], res[1], res[2], ch};
  bool ok = fwrite(magic, 1, 4, f) == 4 && fwrite(hdr, 4, 5, f) == 5 && fwrite(bbox, 4, 6, f) == 6 &&
            fwrite(v, 4, n, f) == n;
  return fclose(f) == 0 && ok;
}

/* A resolver that knows one blob: sha256:0...07 -> the file at user. */
static rsw_status blob_resolve(void *user, const char *name, char **path_out, rsw_err *err) {
  char want[80];
  snprintf(want, sizeof want, "sha256:%064d", 7);
  if (strcmp(name, want) != 0) return rsw_fail(err, RSW_ERR_NOT_FOUND, name, "no such blob '%s'", name);
  *path_out = strdup((const char *)user);
  return *path_out ? RSW_OK : RSW_ERR_NOMEM;
}

static void test_grid_vol_file(void) {
  char path[] = "/tmp/rsw_test_volXXXXXX";
  int fd = mkstemp(path);
  REQUIRE(fd >= 0, "mkstemp");
  close(fd);
  const float vals[12] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11.5f};
  const float bbox[6] = {-1, -2, 0, 1, 2, 4};
  uint32_t res[3] = {3, 2, 2};
  REQUIRE(write_vol(path, "VOL\3", 1, res, 1, bbox, vals, 12), "write");
  char objs[1024];
  snprintf(objs, sizeof objs,
           "\"f\": {\"type\": \"gridvolume\", \"filename\": \"%s\", \"filter_type\": \"nearest\"}, "
           "\"b\": {\"type\": \"gridvolume\", \"filename\": \"%s\", \"use_grid_bbox\": true, "
           "\"to_world\": [{\"translate\": [0, 0, 10]}]}, "
           "\"i\": {\"type\": \"gridvolume\", \"shape\": [2, 2, 3], \"filter_type\": \"nearest\", "
           "\"data\": [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11.5]}",
           path, path);
  scene *s = load(objs, "mono");
  REQUIRE(s, "load");
  volume *f = find_vol(s, "f"), *b = find_vol(s, "b"), *in = find_vol(s, "i");
  REQUIRE(f && b && in, "volumes");
  CHECK(f->res[0] == 3 && f->res[1] == 2 && f->res[2] == 2 && f->max == 11.5, "res and max");
  for (int k = 0; k < 12; k++)
    CHECK(f->data[k] == in->data[k], "value %d: file %g, inline %g", k, f->data[k], in->data[k]);
  /* The file's box under to_world: [-1, 1] x [-2, 2] x [10, 14]. */
  CHECK(b->bbox_min.x == -1 && b->bbox_max.y == 2 && b->bbox_min.z == 10 && b->bbox_max.z == 14, "grid bbox");
  /* Local (2.5/3, 1/4, 3/4) is the centre of cell (2, 0, 1). */
  CHECK_ABS(volume_eval_1(b, v3(-1 + 2 * (2.5 / 3), -2 + 4 * 0.25, 10 + 4 * 0.75)), 8.0, 1e-12);
  scene_free(s);
  /* Through the scene's resolver, as the daemon maps a sha256: blob. */
  snprintf(objs, sizeof objs,
           "{\"type\": \"scene\", \"f\": {\"type\": \"gridvolume\", \"filename\": \"sha256:%064d\"}}", 7);
  scene_load_opts o = {.size = sizeof o, .variant = "mono", .resolve = blob_resolve, .resolve_user = path};
  rsw_err rerr = {0};
  s = NULL;
  CHECK(scene_load_memory(objs, strlen(objs), "blob-scene", false, &o, &s, &rerr) == RSW_OK, "blob: %s",
        rerr.msg);
  if (s) CHECK(find_vol(s, "f") && find_vol(s, "f")->max == 11.5, "blob grid");
  scene_free(s);
  snprintf(objs, sizeof objs,
           "{\"type\": \"scene\", \"f\": {\"type\": \"gridvolume\", \"filename\": \"sha256:%064d\"}}", 8);
  memset(&rerr, 0, sizeof rerr);
  s = NULL;
  CHECK(scene_load_memory(objs, strlen(objs), "blob-scene", false, &o, &s, &rerr) == RSW_ERR_NOT_FOUND &&
            strstr(rerr.where, "/f/filename") && strstr(rerr.msg, "no such blob"),
        "unknown blob: %s: %s", rerr.where, rerr.msg);
  scene_free(s);
  /* Broken files: each error names the property. */
  static const struct {
    const char *magic;
    uint32_t enc, ch;
    size_t n;
    const char *want;
  } bad[] = {
      {"VOX\3", 1, 1, 12, "not a .vol grid"},  {"VOL\2", 1, 1, 12, "not a .vol grid"},
      {"VOL\3", 2, 1, 12, "encoding 2"},       {"VOL\3", 1, 2, 24, "2 channels"},
      {"VOL\3", 1, 1, 11, "header announces"},
  };
  float big[24] = {0};
  for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
    REQUIRE(write_vol(path, bad[k].magic, bad[k].enc, res, bad[k].ch, bbox, big, bad[k].n), "write");
    snprintf(objs, sizeof objs, "\"f\": {\"type\": \"gridvolume\", \"filename\": \"%s\"}", path);
    rsw_err err = {0};
    CHECK(load_err(objs, "mono", &err) != RSW_OK, "bad file %zu loads", k);
    CHECK(strstr(err.msg, bad[k].want) && strstr(err.where, "/f/filename"), "bad file %zu: %s: %s", k,
          err.where, err.msg);
  }
  float nan_v[12] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 0};
  nan_v[7] = NAN;
  REQUIRE(write_vol(path, "VOL\3", 1, res, 1, bbox, nan_v, 12), "write");
  rsw_err err = {0};
  CHECK(load_err(objs, "mono", &err) == RSW_ERR_INVALID && strstr(err.msg, "value 7"), "NaN: %s", err.msg);
  unlink(path);
  memset(&err, 0, sizeof err);
  CHECK(load_err(objs, "mono", &err) == RSW_ERR_FILE && strstr(err.where, "/f/filename"), "missing: %s",
        err.msg);
}

static void test_grid_update(void) {
  /* A weight grid (slot [0, 1]) under a blendphase. */
  char objs[2048];
  snprintf(objs, sizeof objs,
           "\"b\": {\"type\": \"blendphase\", \"weight\": {\"type\": \"gridvolume\", \"shape\": [3, 1, 1], "
           "\"data\": [0.1, 0.5, 0.9]}, %s}",
           PHASES);
  scene *s = load(objs, "mono");
  REQUIRE(s, "load");
  rsw_err err = {0};
  size_t i;
  REQUIRE(params_lookup(s, "b.weight.data", &i, &err) == RSW_OK, "b.weight.data: %s", err.msg);
  CHECK(params_lookup(s, "b.weight.to_world", &i, &err) == RSW_OK, "b.weight.to_world");
  volume *v = NULL;
  for (size_t k = 0; k < s->n_objects && !v; k++)
    if (s->objects[k]->plugin && strcmp(s->objects[k]->plugin->name, "gridvolume") == 0)
      v = (volume *)s->objects[k];
  REQUIRE(v, "weight volume");
  static const struct {
    const char *json, *want;
  } bad[] = {
      {"[0.1, 0.5]", "takes 3 numbers"},
      {"[0.1, 1.5, 0.2]", "value 1.5 at index 1 must lie in [0, 1]"},
      {"[-0.1, 0.5, 0.2]", "value -0.1 at index 0"},
      {"{\"wavelengths\": [400, 500], \"values\": [1, 2]}", "flat list of 3 numbers"},
  };
  for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
    memset(&err, 0, sizeof err);
    CHECK(upd1(s, "b.weight.data", bad[k].json, &err) != RSW_OK, "%s rejected", bad[k].json);
    CHECK(strstr(err.msg, bad[k].want) && strstr(err.msg, "b.weight.data"), "%s: %s", bad[k].json, err.msg);
  }
  CHECK(v->data[1] == 0.5 && v->max == 0.9, "a rejected update changes nothing");
  uint64_t rev = v->revision;
  CHECK(upd1(s, "b.weight.data", "[0.2, 0.3, 0.4]", &err) == RSW_OK, "update: %s", err.msg);
  CHECK(v->data[1] == 0.3 && v->max == 0.4 && v->revision != rev, "data, max and revision refreshed");

  /* Atomic with another key: a bad g rejects the whole map. */
  param_update u[2] = {{.key = "b.weight.data"}, {.key = "b.phase_1.g"}};
  REQUIRE(param_value_parse("[1, 1, 1]", "x", &u[0].value, &err) == RSW_OK, "parse");
  REQUIRE(param_value_parse("2", "x", &u[1].value, &err) == RSW_OK, "parse");
  CHECK(scene_update(s, u, 2, NULL, &err) == RSW_ERR_RANGE, "bad g rejects the map");
  CHECK(v->data[0] == 0.2 && v->max == 0.4, "nothing written");
  param_value_free(&u[0].value);
  param_value_free(&u[1].value);
  REQUIRE(params_lookup(s, "b.weight.data", &i, &err) == RSW_OK, "lookup");
  char *json = params_value_json(s, i, 0);
  CHECK(json && strcmp(json, "[0.20000000000000001, 0.29999999999999999, 0.40000000000000002]") == 0,
        "value: %s", json);
  free(json);
  scene_free(s);
  /* max_value: a fixed max, and a bound for updates; raw and accel are
   * accepted (no effect outside spectral and CUDA variants). */
  s = load("\"g\": {\"type\": \"gridvolume\", \"shape\": [2, 1, 1], \"data\": [1, 2], \"max_value\": 5, "
           "\"raw\": true, \"accel\": false}",
           "mono");
  REQUIRE(s, "load max_value");
  v = find_vol(s, "g");
  CHECK(v->max == 5, "fixed max %g", v->max);
  CHECK(upd1(s, "g.data", "[4, 5]", &err) == RSW_OK && v->max == 5, "update within max_value: %s", err.msg);
  memset(&err, 0, sizeof err);
  CHECK(upd1(s, "g.data", "[4, 6]", &err) == RSW_ERR_RANGE && strstr(err.msg, "must be <= 5"),
        "above max_value: %s", err.msg);
  scene_free(s);
}

/* An update of `data` equals loading the updated values, bitwise, at two
 * wavelengths (plain and tabulated grids). */
static void test_grid_update_equals_reload(void) {
  const char *fmt = "\"g\": {\"type\": \"gridvolume\", \"shape\": [3, 2, 1], \"data\": [%s]}, "
                    "\"t\": {\"type\": \"gridvolume\", \"shape\": [2, 1, 1], \"wavelengths\": [500, 700], "
                    "\"data\": [%s]}";
  const char *g1 = "0.5, 1, 1.5, 2, 2.5, 3", *g2 = "0.25, 0.75, 7, 2, 0.125, 3.5";
  const char *t1 = "1, 2, 3, 4", *t2 = "1.5, 0.5, 8, 16";
  char a[2048], b[2048];
  snprintf(a, sizeof a, fmt, g1, t1);
  snprintf(b, sizeof b, fmt, g2, t2);
  const double wls[2] = {550, 633};
  for (int w = 0; w < 2; w++) {
    scene *sa = load(a, "mono"), *sb = load(b, "mono");
    REQUIRE(sa && sb, "load");
    REQUIRE(prepare(sa, VARIANT_MONO, 500), "prepare");
    rsw_err err = {0};
    char j1[128], j2[128];
    snprintf(j1, sizeof j1, "[%s]", g2);
    snprintf(j2, sizeof j2, "[%s]", t2);
    CHECK(upd1(sa, "g.data", j1, &err) == RSW_OK, "g.data: %s", err.msg);
    CHECK(upd1(sa, "t.data", j2, &err) == RSW_OK, "t.data: %s", err.msg);
    REQUIRE(prepare(sa, VARIANT_MONO, wls[w]) && prepare(sb, VARIANT_MONO, wls[w]), "prepare");
    const char *ids[2] = {"g", "t"};
    for (int k = 0; k < 2; k++) {
      volume *va = find_vol(sa, ids[k]), *vb = find_vol(sb, ids[k]);
      CHECK(va->max == vb->max, "%s max %g vs %g", ids[k], va->max, vb->max);
      for (int q = 0; q < 50; q++) {
        vec3 p = v3(0.37 * q - 3, fmod(0.61 * q, 1.2), fmod(0.173 * q, 1.1));
        color x = volume_eval(va, p), y = volume_eval(vb, p);
        CHECK(memcmp(&x, &y, sizeof x) == 0, "%s at %g nm, point %d: %.17g vs %.17g", ids[k], wls[w], q,
              x.c[0], y.c[0]);
      }
    }
    scene_free(sa);
    scene_free(sb);
  }
}

static void test_grid_errors(void) {
  static const struct {
    const char *vol, *want, *where;
  } bad[] = {
      {"\"data\": [1, 2]", "'data' needs 'shape'", "/v"},
      {"\"shape\": [1, 1, 2]", "exactly one of 'data'", "/v"},
      {"\"shape\": [1, 1, 2], \"data\": [1, 2], \"filename\": \"x.vol\"", "exactly one of 'data'", "/v"},
      {"\"shape\": [1, 1, 3], \"data\": [1, 2]", "holds 2 values, but shape 1 x 1 x 3 takes 3", "/v/data"},
      {"\"shape\": [1, 2], \"data\": [1, 2]", "[Z, Y, X] or [Z, Y, X, C]", "/v/shape"},
      {"\"shape\": [1, 0, 2], \"data\": [1, 2]", "not a positive whole number", "/v/shape"},
      {"\"shape\": [1, 1.5, 2], \"data\": [1, 2]", "not a positive whole number", "/v/shape"},
      {"\"shape\": [1, 1, 1, 2], \"data\": [1, 2]", "2 channels", "/v/shape"},
      {"\"shape\": [1, 1, 2], \"data\": \"1, two\"", "'two' (value 1) is not a number", "/v/data"},
      {"\"shape\": [1, 1, 2], \"data\": [1, 2], \"filter_type\": \"cubic\"", "unknown value 'cubic'",
       "/v/filter_type"},
      {"\"shape\": [1, 1, 2], \"data\": [1, 2], \"wrap_mode\": \"border\"", "unknown value 'border'",
       "/v/wrap_mode"},
      {"\"shape\": [1, 1, 2], \"data\": [1, 2], \"use_grid_bbox\": true", "needs a .vol 'filename'",
       "/v/use_grid_bbox"},
      {"\"shape\": [1, 1, 1], \"wavelengths\": 500, \"data\": [1]", "at least 2 wavelengths",
       "/v/wavelengths"},
      {"\"shape\": [1, 1, 1], \"wavelengths\": [500, 400], \"data\": [1, 2]", "strictly increasing",
       "/v/wavelengths"},
      {"\"shape\": [1, 1, 1, 3], \"wavelengths\": [500, 600], \"data\": [1, 2]",
       "must match the 2 wavelengths", "/v/shape"},
      {"\"shape\": [1, 1, 2], \"data\": [1, 2], \"raw\": 1", "must be a boolean", "/v/raw"},
      {"\"shape\": [1, 1, 2], \"data\": [1, 2], \"max_value\": 1.5", "below the grid's largest value (2)",
       "/v/max_value"},
      {"\"shape\": [1, 1, 2], \"data\": [1, 2], \"scale\": 2", "no property 'scale'", "/v/scale"},
  };
  for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
    char objs[1024];
    snprintf(objs, sizeof objs, "\"v\": {\"type\": \"gridvolume\", %s}", bad[k].vol);
    rsw_err err = {0};
    CHECK(load_err(objs, "mono", &err) != RSW_OK, "case %zu loads", k);
    CHECK(strstr(err.msg, bad[k].want) != NULL, "case %zu: '%s' not in '%s'", k, bad[k].want, err.msg);
    CHECK(strstr(err.where, bad[k].where) != NULL, "case %zu: where '%s', want '%s'", k, err.where,
          bad[k].where);
  }
  rsw_err err = {0};
  CHECK(load_err(
            "\"v\": {\"type\": \"gridvolume\", \"shape\": [1, 1, 1], \"wavelengths\": [500, 600], \"data\": "
            "[1, 2]}",
            "rgb", &err) == RSW_ERR_UNSUPPORTED &&
            strstr(err.msg, "mono"),
        "tables in rgb: %s", err.msg);
  /* The slot's range: a blend weight grid above 1. */
  char objs[1024];
  snprintf(objs, sizeof objs,
           "\"b\": {\"type\": \"blendphase\", \"weight\": {\"type\": \"gridvolume\", \"shape\": [2, 1, 1], "
           "\"data\": [0, 1.5]}, %s}",
           PHASES);
  memset(&err, 0, sizeof err);
  CHECK(load_err(objs, "mono", &err) == RSW_ERR_RANGE && strstr(err.msg, "the volume holds 0 to 1.5") &&
            strstr(err.where, "/b/weight"),
        "weight grid out of range: %s: %s", err.where, err.msg);
}

/* The XML forms: data and shape as strings of numbers, nested volumes
 * and phases by name. */
static void test_xml(void) {
  const char *xml = "<scene version=\"3.0.0\">\n"
                    "  <phase type=\"blendphase\" id=\"b\">\n"
                    "    <volume type=\"gridvolume\" name=\"weight\">\n"
                    "      <string name=\"shape\" value=\"3, 1, 1\"/>\n"
                    "      <string name=\"data\" value=\"0.25 0.5 0.75\"/>\n"
                    "      <string name=\"filter_type\" value=\"nearest\"/>\n"
                    "      <transform name=\"to_world\"><scale value=\"1, 1, 3\"/></transform>\n"
                    "    </volume>\n"
                    "    <phase type=\"rayleigh\" name=\"phase_0\"/>\n"
                    "    <phase type=\"hg\" name=\"phase_1\"><float name=\"g\" value=\"0.5\"/></phase>\n"
                    "  </phase>\n"
                    "  <volume type=\"constvolume\" id=\"c\"><float name=\"value\" value=\"2\"/></volume>\n"
                    "</scene>\n";
  scene *s = tsup_load(xml, "mono");
  REQUIRE(s, "load");
  rsw_err err = {0};
  size_t i;
  CHECK(params_lookup(s, "b.weight.data", &i, &err) == RSW_OK, "b.weight.data: %s", err.msg);
  CHECK(params_lookup(s, "b.phase_1.g", &i, &err) == RSW_OK, "b.phase_1.g");
  CHECK(params_lookup(s, "c.value.value", &i, &err) == RSW_OK, "c.value.value");
  const phase *ph = (const phase *)find_cls(s, "b", CLS_PHASE);
  REQUIRE(ph, "phase");
  /* At z = 2.5 (top layer) w = 0.75: forward 0.25 rayleigh + 0.75 hg(0.5). */
  medium_interaction mi = {.p = v3(0.5, 0.5, 2.5), .wi = v3(0, 0, 1)};
  double pdf, v = ph->ops->eval_pdf(ph, &mi, v3(0, 0, -1), &pdf);
  CHECK_REL(v, 0.25 * 3 / (8 * RSW_PI) + 0.75 * 0.75 / (4 * RSW_PI * 0.125), 1e-14);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_constvolume_mono);
  RSW_TEST_RUN(test_constvolume_rgb);
  RSW_TEST_RUN(test_constvolume_params);
  RSW_TEST_RUN(test_ld_volume_forms);
  RSW_TEST_RUN(test_ld_volume_errors);
  RSW_TEST_RUN(test_grid_layout);
  RSW_TEST_RUN(test_grid_wrap_and_box);
  RSW_TEST_RUN(test_grid_profile_lookup);
  RSW_TEST_RUN(test_grid_channels);
  RSW_TEST_RUN(test_grid_spectral_cells);
  RSW_TEST_RUN(test_grid_vol_file);
  RSW_TEST_RUN(test_grid_update);
  RSW_TEST_RUN(test_grid_update_equals_reload);
  RSW_TEST_RUN(test_grid_errors);
  RSW_TEST_RUN(test_xml);
  RSW_TEST_END("test_volume");
}
