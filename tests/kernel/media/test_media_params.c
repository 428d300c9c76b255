/* The parameters of participating media (issue 14), in process:
 *  - an update equals a reload, bitwise, at two mono wavelengths, for a
 *    piecewise medium's sigma_t.data and albedo.data, its blendphase's
 *    weight grid and its hg component's g, one at a time and all at once
 *    (the shape of a per-context override), each a spectral-class update
 *    that does no acceleration-structure work;
 *  - a bad value (a grid of the wrong length, a negative, NaN or infinite
 *    coefficient, an albedo or weight outside [0, 1], g outside (-1, 1))
 *    is refused by scene_update and scene_update_check with an error that
 *    names the key, and the map is atomic: a good sigma_t beside a bad
 *    albedo changes nothing (the values read back and the film are the
 *    ones from before);
 *  - the example atmosphere (proto/examples/atmosphere.json and .xml,
 *    tools/make_atmosphere.py) loads, exposes its 2,400-layer arrays under
 *    the documented keys, and the XML's float32 .vol grids hold the JSON's
 *    values rounded to float;
 *  - the media cases of the malformed-scene corpus (tests/corpus/bad/
 *    bad_*medium*, bad_*phase*, bad_*volume*) fail for their own reason:
 *    each error names the field (checked against a piece of its text).
 *
 * Scenes: an 8-layer piecewise atmosphere 4 units deep over a Lambertian
 * plate whose reflectance is tabulated (so the two wavelengths give two
 * different films), under a directional sun, seen by hdistant 8x8 at 16
 * spp, piecewise_volpath. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/scene/param_table.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define SPP     16
#define SEED    20261125u
#define THREADS 2
#define NL      8

#define MEDIUM   "medium_atmosphere"
#define K_SIGMA  MEDIUM ".sigma_t.data"
#define K_ALBEDO MEDIUM ".albedo.data"
#define K_WEIGHT MEDIUM ".phase_function.weight.data"
#define K_G      MEDIUM ".phase_function.phase_1.g"

static const double WL[2] = {450, 650};

typedef struct atmo {
  double sigma_t[NL], albedo[NL], weight[NL], g;
} atmo;

static void atmo_default(atmo *a) {
  for (int i = 0; i < NL; i++) {
    a->sigma_t[i] = 0.4 * exp(-i / 3.0);
    a->albedo[i] = 0.95 - 0.02 * i;
    a->weight[i] = i < 2 ? 0.6 : 0.0;
  }
  a->g = 0.7;
}

static void arr(sbuf *b, const double *v, int n) {
  sb_printf(b, "[");
  for (int i = 0; i < n; i++) sb_printf(b, "%s%.17g", i ? ", " : "", v[i]);
  sb_printf(b, "]");
}

static void grid(sbuf *b, const double *v) {
  sb_printf(b, "{\"type\": \"gridvolume\", \"data\": ");
  arr(b, v, NL);
  sb_printf(
      b,
      ", \"shape\": [%d, 1, 1], \"filter_type\": \"nearest\", \"to_world\": [{\"scale\": [100, 100, 4]}, "
      "{\"translate\": [-50, -50, 0]}]}",
      NL);
}

/* The scene of atmosphere a (malloc'ed text). */
static char *atmo_scene(const atmo *a) {
  sbuf b = {0};
  sb_printf(&b, "{\"type\": \"scene\", \"variant\": \"mono\",\n \"" MEDIUM "\": {\"type\": \"piecewise\", "
                "\"sigma_t\": ");
  grid(&b, a->sigma_t);
  sb_printf(&b, ", \"albedo\": ");
  grid(&b, a->albedo);
  sb_printf(&b,
            ", \"phase\": {\"type\": \"blendphase\", \"phase_0\": {\"type\": \"rayleigh\"}, "
            "\"phase_1\": {\"type\": \"hg\", \"g\": %.17g}, \"weight\": ",
            a->g);
  grid(&b, a->weight);
  sb_printf(
      &b,
      "}},\n"
      " \"shape_atmosphere\": {\"type\": \"cube\", \"to_world\": [{\"scale\": [50, 50, 2.05]}, "
      "{\"translate\": [0, 0, 1.95]}], \"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": \"ref\", "
      "\"id\": \"" MEDIUM "\"}},\n"
      " \"surface\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [50, 50, 1]}], \"bsdf\": "
      "{\"type\": \"diffuse\", \"reflectance\": {\"type\": \"spectrum\", \"wavelengths\": [400, 700], "
      "\"values\": [0.1, 0.6]}}},\n"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0.1, -0.86602540378443864676], "
      "\"irradiance\": 1.0},\n"
      " \"cam\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\"}, \"sampler\": "
      "{\"type\": \"independent\", \"sample_count\": 16}, \"film\": {\"type\": \"hdrfilm\", \"width\": 8, "
      "\"height\": 8, \"rfilter\": {\"type\": \"box\"}}},\n"
      " \"integrator\": {\"type\": \"piecewise_volpath\", \"max_depth\": 8}}\n");
  return b.p;
}

static bool render_wl(scene *s, double wl, film_image *out) {
  rsw_err err = {0};
  render_opts o = {.size = sizeof o, .spp = SPP, .seed = SEED, .threads = THREADS, .wavelength = wl};
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

/* One update of the map `items` (values as arrays or numbers), S -> S':
 * renders of the updated S equal renders of S' loaded afresh, bitwise, at
 * both wavelengths, and differ from S's. */
typedef struct upd {
  const char *key;
  const double *v; /* NULL: the number x */
  int n;
  double x;
} upd;

static void fill_value(const upd *u, param_value *pv) {
  memset(pv, 0, sizeof *pv);
  if (u->v) {
    pv->kind = PV_ARRAY;
    pv->n = (size_t)u->n;
    pv->arr = malloc(sizeof(double) * (size_t)u->n);
    if (pv->arr) memcpy(pv->arr, u->v, sizeof(double) * (size_t)u->n);
  } else {
    pv->kind = PV_NUMBER;
    pv->num = u->x;
  }
}

static void reload_case(const char *name, const atmo *before, const atmo *after, const upd *u, size_t n) {
  char *ta = atmo_scene(before), *tb = atmo_scene(after);
  scene *s = tsup_load(ta, NULL), *s2 = tsup_load(tb, NULL);
  free(ta), free(tb);
  if (!s || !s2) {
    CHECK(false, "%s: load S or S'", name);
    scene_free(s), scene_free(s2);
    return;
  }
  film_image pre[2] = {{0}}, post[2] = {{0}}, ref[2] = {{0}};
  bool ok = render_wl(s, WL[0], &pre[0]) && render_wl(s, WL[1], &pre[1]);
  CHECK(ok, "%s: render S", name);
  param_update items[4];
  for (size_t i = 0; i < n; i++) {
    items[i].key = u[i].key;
    fill_value(&u[i], &items[i].value);
  }
  rsw_err err = {0};
  update_report rep = {0};
  if (ok && scene_update(s, items, n, &rep, &err)) {
    char buf[1200];
    CHECK(false, "%s: scene_update: %s", name, rsw_err_format(&err, buf, sizeof buf));
    ok = false;
  }
  for (size_t i = 0; i < n; i++) param_value_free(&items[i].value);
  if (ok) {
    CHECK(rep.classes == UPDATE_SPECTRAL, "%s: classes %u, expected spectral", name, rep.classes);
    CHECK(rep.changed == n, "%s: changed %zu of %zu", name, rep.changed, n);
    CHECK(rep.refits == 0 && rep.rebuilds == 0 && rep.instance_updates == 0,
          "%s: acceleration work for a spectral update (%u refits, %u rebuilds, %u instance updates)", name,
          rep.refits, rep.rebuilds, rep.instance_updates);
  }
  for (int w = 0; w < 2 && ok; w++) {
    ok = render_wl(s, WL[w], &post[w]) && render_wl(s2, WL[w], &ref[w]);
    CHECK(ok, "%s: render at %g nm", name, WL[w]);
    if (!ok) break;
    CHECK(!same_film(&pre[w], &post[w]), "%s (%g nm): the update did not change the film", name, WL[w]);
    CHECK(same_film(&post[w], &ref[w]), "%s (%g nm): the updated film differs from the reloaded one", name,
          WL[w]);
  }
  CHECK(!ok || !same_film(&post[0], &post[1]), "%s: the two wavelengths gave the same film", name);
  for (int w = 0; w < 2; w++) film_image_free(&pre[w]), film_image_free(&post[w]), film_image_free(&ref[w]);
  scene_free(s);
  scene_free(s2);
}

static void test_reload_sigma_t(void) {
  atmo a, b;
  atmo_default(&a);
  b = a;
  for (int i = 0; i < NL; i++) b.sigma_t[i] = 0.15 + 0.05 * (i % 3);
  upd u = {K_SIGMA, b.sigma_t, NL, 0};
  reload_case("sigma_t.data", &a, &b, &u, 1);
}

static void test_reload_albedo(void) {
  atmo a, b;
  atmo_default(&a);
  b = a;
  for (int i = 0; i < NL; i++) b.albedo[i] = 0.5 + 0.06 * i;
  upd u = {K_ALBEDO, b.albedo, NL, 0};
  reload_case("albedo.data", &a, &b, &u, 1);
}

static void test_reload_weight(void) {
  atmo a, b;
  atmo_default(&a);
  b = a;
  for (int i = 0; i < NL; i++) b.weight[i] = 1.0 - i / (double)NL;
  upd u = {K_WEIGHT, b.weight, NL, 0};
  reload_case("blendphase weight.data", &a, &b, &u, 1);
}

static void test_reload_g(void) {
  atmo a, b;
  atmo_default(&a);
  for (int i = 0; i < NL; i++) a.weight[i] = 0.8; /* hg carries most of the scattering */
  b = a;
  b.g = -0.3;
  upd u = {K_G, NULL, 0, -0.3};
  reload_case("hg g", &a, &b, &u, 1);
}

static void test_reload_all_three(void) {
  /* One context of a wavelength loop: the three arrays at once. */
  atmo a, b;
  atmo_default(&a);
  b = a;
  for (int i = 0; i < NL; i++) {
    b.sigma_t[i] = 0.6 * exp(-i / 2.0);
    b.albedo[i] = 0.99;
    b.weight[i] = i < 3 ? 0.3 : 0.0;
  }
  upd u[3] = {{K_SIGMA, b.sigma_t, NL, 0}, {K_ALBEDO, b.albedo, NL, 0}, {K_WEIGHT, b.weight, NL, 0}};
  reload_case("sigma_t, albedo and weight together", &a, &b, u, 3);
}

/* ---- validation: refused, named, atomic ---------------------------------- */

/* The map must be refused by scene_update_check and scene_update with an
 * error naming bad_key (and `what` in its text, when given), the scene's
 * values must read back unchanged and its film stay bitwise the same. */
static void refused(const char *name, const upd *u, size_t n, const char *bad_key, const char *what) {
  atmo a;
  atmo_default(&a);
  char *t = atmo_scene(&a);
  scene *s = tsup_load(t, NULL);
  free(t);
  REQUIRE(s, "%s: load", name);
  film_image pre = {0}, post = {0};
  bool ok = render_wl(s, WL[0], &pre);
  const char *keys[] = {K_SIGMA, K_ALBEDO, K_WEIGHT, K_G};
  char *before[4] = {0};
  for (int k = 0; k < 4; k++) {
    size_t idx;
    rsw_err e = {0};
    if (params_lookup(s, keys[k], &idx, &e) == RSW_OK) before[k] = params_value_json(s, idx, 0);
    CHECK(before[k], "%s: no parameter %s", name, keys[k]);
  }
  param_update items[4];
  for (size_t i = 0; i < n; i++) {
    items[i].key = u[i].key;
    fill_value(&u[i], &items[i].value);
  }
  for (int pass = 0; pass < 2; pass++) {
    rsw_err err = {0};
    rsw_status st = pass ? scene_update(s, items, n, NULL, &err) : scene_update_check(s, items, n, &err);
    char buf[1400];
    rsw_err_format(&err, buf, sizeof buf);
    CHECK(st != RSW_OK, "%s: %s accepted the map", name, pass ? "scene_update" : "scene_update_check");
    CHECK(strstr(buf, bad_key), "%s: the error does not name %s: %s", name, bad_key, buf);
    if (what) CHECK(strstr(buf, what), "%s: the error does not say '%s': %s", name, what, buf);
  }
  for (size_t i = 0; i < n; i++) param_value_free(&items[i].value);
  for (int k = 0; k < 4; k++) {
    size_t idx;
    rsw_err e = {0};
    char *now = params_lookup(s, keys[k], &idx, &e) == RSW_OK ? params_value_json(s, idx, 0) : NULL;
    CHECK(now && before[k] && strcmp(now, before[k]) == 0, "%s: %s changed although the map was refused",
          name, keys[k]);
    free(now);
    free(before[k]);
  }
  ok = ok && render_wl(s, WL[0], &post);
  CHECK(ok && same_film(&pre, &post), "%s: the film changed although the map was refused", name);
  film_image_free(&pre);
  film_image_free(&post);
  scene_free(s);
}

static void test_refuse_wrong_length(void) {
  double v[NL + 1];
  for (int i = 0; i <= NL; i++) v[i] = 0.1;
  upd a = {K_SIGMA, v, NL - 1, 0}, b = {K_SIGMA, v, NL + 1, 0};
  refused("sigma_t.data of 7 values", &a, 1, K_SIGMA, "8");
  refused("sigma_t.data of 9 values", &b, 1, K_SIGMA, "8");
}

static void test_refuse_negative_and_nonfinite(void) {
  double v[NL];
  for (int i = 0; i < NL; i++) v[i] = 0.1;
  v[5] = -1e-3;
  upd a = {K_SIGMA, v, NL, 0};
  refused("negative sigma_t", &a, 1, K_SIGMA, NULL);
  v[5] = NAN;
  refused("NaN sigma_t", &a, 1, K_SIGMA, NULL);
  v[5] = INFINITY;
  refused("infinite sigma_t", &a, 1, K_SIGMA, NULL);
}

static void test_refuse_albedo_and_weight_range(void) {
  double v[NL];
  for (int i = 0; i < NL; i++) v[i] = 0.5;
  v[2] = 1.5;
  upd a = {K_ALBEDO, v, NL, 0}, w = {K_WEIGHT, v, NL, 0};
  refused("albedo 1.5", &a, 1, K_ALBEDO, NULL);
  refused("weight 1.5", &w, 1, K_WEIGHT, NULL);
  v[2] = -0.1;
  refused("albedo -0.1", &a, 1, K_ALBEDO, NULL);
  refused("weight -0.1", &w, 1, K_WEIGHT, NULL);
}

static void test_refuse_g(void) {
  upd a = {K_G, NULL, 0, 1.5}, b = {K_G, NULL, 0, -1.0001};
  refused("g 1.5", &a, 1, K_G, NULL);
  refused("g -1.0001", &b, 1, K_G, NULL);
}

static void test_refuse_atomic(void) {
  /* A good sigma_t and a good g beside a bad albedo: nothing applied. */
  double st[NL], al[NL];
  for (int i = 0; i < NL; i++) st[i] = 0.2, al[i] = 0.9;
  al[NL - 1] = 2;
  upd u[3] = {{K_SIGMA, st, NL, 0}, {K_G, NULL, 0, 0.1}, {K_ALBEDO, al, NL, 0}};
  refused("good sigma_t and g, bad albedo", u, 3, K_ALBEDO, NULL);
}

/* ---- the example atmosphere ---------------------------------------------------- */

static double *values_of(const scene *s, const char *key, size_t *n) {
  size_t idx;
  rsw_err e = {0};
  if (params_lookup(s, key, &idx, &e)) return NULL;
  char *txt = params_value_json(s, idx, 0);
  param_value v;
  bool ok = txt && param_value_parse(txt, key, &v, &e) == RSW_OK;
  free(txt);
  if (!ok) return NULL;
  if (v.kind != PV_ARRAY) {
    param_value_free(&v);
    return NULL;
  }
  *n = v.n;
  return v.arr; /* taken from v */
}

static void test_example_atmosphere(void) {
  scene *j = tsup_load_file("proto/examples/atmosphere.json", NULL);
  scene *x = tsup_load_file("proto/examples/atmosphere.xml", NULL);
  REQUIRE(j && x, "load proto/examples/atmosphere.json and .xml");
  const char *keys[] = {K_SIGMA, K_ALBEDO, K_WEIGHT};
  for (int k = 0; k < 3; k++) {
    size_t idx, nj = 0, nx = 0;
    rsw_err e = {0};
    param_info info;
    CHECK(params_lookup(j, keys[k], &idx, &e) == RSW_OK && params_info(j, idx, &info), "no key %s", keys[k]);
    if (params_info(j, idx, &info)) {
      CHECK(info.cls == UPDATE_SPECTRAL, "%s: class %s, expected spectral", keys[k],
            update_class_name(info.cls));
      CHECK(info.shape[0] == 2400, "%s: shape [%zu], expected [2400]", keys[k], info.shape[0]);
    }
    double *vj = values_of(j, keys[k], &nj), *vx = values_of(x, keys[k], &nx);
    CHECK(vj && vx && nj == 2400 && nx == 2400, "%s: %zu values in the JSON, %zu in the XML", keys[k], nj,
          nx);
    size_t bad = 0;
    for (size_t i = 0; vj && vx && i < nj && i < nx; i++) bad += (double)(float)vj[i] != vx[i];
    CHECK(bad == 0, "%s: %zu of the XML's values are not the JSON's rounded to float32", keys[k], bad);
    free(vj);
    free(vx);
  }
  /* Molecular + aerosol optical thickness of the example: 0.096 + 0.2. */
  size_t n = 0;
  double *st = values_of(j, K_SIGMA, &n), tau = 0;
  for (size_t i = 0; st && i < n; i++) tau += st[i] * 50.0;
  CHECK_REL(tau, 0.296, 1e-3);
  free(st);
  scene_free(j);
  scene_free(x);
}

/* ---- the media cases of the malformed-scene corpus ----------------------------- */

/* Whether text contains one of the '|'-separated pieces of alts. */
static bool names_any(const char *text, const char *alts) {
  char a[128];
  snprintf(a, sizeof a, "%s", alts);
  for (char *save = NULL, *t = strtok_r(a, "|", &save); t; t = strtok_r(NULL, "|", &save))
    if (strstr(text, t)) return true;
  return false;
}

static void test_corpus_media_errors(void) {
  /* file, the piece of the error text it must contain (its field; one of
   * several separated by '|'). */
  static const char *const cases[][2] = {
      {"bad_json_medium_negative_sigma_t.json", "sigma_t"},
      {"bad_json_medium_albedo_above_one.json", "albedo"},
      {"bad_json_medium_grid_shape.json", "shape"},
      {"bad_json_medium_grid_length.json", "data|shape"},
      {"bad_json_medium_nan_in_grid.json", "data"},
      {"bad_json_medium_unknown_phase.json", "hg2"},
      {"bad_json_medium_no_boundary.json", "medium_atmosphere"},
      {"bad_json_medium_hg_g_one.json", "/g|g ="},
      {"bad_json_medium_piecewise_3d_grid.json", "sigma_t"},
      {"bad_json_medium_as_bsdf.json", "'interior' must be a medium"},
      {"bad_json_medium_blend_weight_negative.json", "weight"},
      {"bad_json_sensor_medium_outside.json", "medium"},
      {"bad_scene_medium_negative_scale.xml", "scale"},
      {"bad_scene_medium_unknown_phase.xml", "hg2"},
      {"bad_scene_medium_vol_missing.xml", "nowhere.vol"},
      {"bad_scene_medium_vol_truncated.xml", "truncated.vol"},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    char path[512];
    snprintf(path, sizeof path, "tests/corpus/bad/%s", cases[i][0]);
    scene *s = NULL;
    rsw_err err = {0};
    scene_load_opts lo = {.size = sizeof lo};
    rsw_status st = scene_load_file(path, &lo, &s, &err);
    char buf[1400];
    rsw_err_format(&err, buf, sizeof buf);
    CHECK(st != RSW_OK, "%s loaded", cases[i][0]);
    /* An unknown plugin is the reason only where the case names it. */
    char own[160];
    snprintf(own, sizeof own, "unknown plugin type '%s'", cases[i][1]);
    CHECK(!strstr(buf, "unknown plugin") || strstr(buf, own),
          "%s: fails as an unknown plugin, not for its own reason: %s", cases[i][0], buf);
    CHECK(names_any(buf, cases[i][1]), "%s: the error does not name '%s': %s", cases[i][0], cases[i][1], buf);
    scene_free(s);
  }
}

/* A sensor inside a medium stays inside it: an update that moves the
 * boundary away from it is refused (naming the sensor) and changes
 * nothing; one that keeps it inside passes. */
static void test_refuse_sensor_leaving_medium(void) {
  const char *doc =
      "{\"type\": \"scene\", \"integrator\": {\"type\": \"volpath\"},"
      " \"fog\": {\"type\": \"homogeneous\", \"id\": \"fog\", \"sigma_t\": 0.5, \"albedo\": 0.0},"
      " \"box\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": \"ref\", "
      "\"id\": \"fog\"}},"
      " \"sky\": {\"type\": \"constant\", \"radiance\": 1.0},"
      " \"meter\": {\"type\": \"radiancemeter\", \"origin\": [0, 0, 0], \"direction\": [0, 0, 1],"
      "   \"medium\": {\"type\": \"ref\", \"id\": \"fog\"},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1}}}";
  scene *s = tsup_load(doc, NULL);
  REQUIRE(s, "load");
  size_t idx;
  rsw_err e = {0};
  REQUIRE(params_lookup(s, "box.to_world", &idx, &e) == RSW_OK, "box.to_world: %s", e.msg);
  char *before = params_value_json(s, idx, 0);
  param_update u = {.key = "box.to_world"};
  const char *away = "[[1,0,0,10],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";
  REQUIRE(param_value_parse(away, "test", &u.value, &e) == RSW_OK, "parse: %s", e.msg);
  rsw_err err = {0};
  rsw_status st = scene_update(s, &u, 1, NULL, &err);
  char buf[1400];
  rsw_err_format(&err, buf, sizeof buf);
  CHECK(st != RSW_OK, "moving the box away from the sensor inside it was accepted");
  CHECK(strstr(buf, "meter") && strstr(buf, "does not sit inside its medium"), "the error: %s", buf);
  char *now = params_value_json(s, idx, 0);
  CHECK(before && now && strcmp(before, now) == 0, "the refused update changed box.to_world");
  free(now);
  param_value_free(&u.value);
  const char *still = "[[2,0,0,0.5],[0,2,0,0],[0,0,2,0],[0,0,0,1]]";
  REQUIRE(param_value_parse(still, "test", &u.value, &e) == RSW_OK, "parse: %s", e.msg);
  memset(&err, 0, sizeof err);
  CHECK(scene_update(s, &u, 1, NULL, &err) == RSW_OK, "a box still around the sensor refused: %s", err.msg);
  param_value_free(&u.value);
  free(before);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_reload_sigma_t);
  RSW_TEST_RUN(test_reload_albedo);
  RSW_TEST_RUN(test_reload_weight);
  RSW_TEST_RUN(test_reload_g);
  RSW_TEST_RUN(test_reload_all_three);
  RSW_TEST_RUN(test_refuse_wrong_length);
  RSW_TEST_RUN(test_refuse_negative_and_nonfinite);
  RSW_TEST_RUN(test_refuse_albedo_and_weight_range);
  RSW_TEST_RUN(test_refuse_g);
  RSW_TEST_RUN(test_refuse_atomic);
  RSW_TEST_RUN(test_example_atmosphere);
  RSW_TEST_RUN(test_corpus_media_errors);
  RSW_TEST_RUN(test_refuse_sensor_leaving_medium);
  RSW_TEST_END("test_media_params");
}
