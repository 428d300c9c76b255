/* Environment plugin loader and adapter (server/kernel/extplugin/env_plugin.c).
 *
 * Tiny plugins are written to a temporary directory and compiled at test
 * time with `cc -shared -fPIC -I include` (the compiler is part of the
 * build environment), one source template with the behaviour substituted:
 * good, wrong ABI version, missing entry symbol, duplicate / built-in /
 * invalid type names, NaN radiance, negative or zero sampled pdf. */
#include "../../support/test.h"

#include <dlfcn.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "kernel/extplugin/env_plugin.h"
#include "kernel/render.h"
#include "kernel/scene/loader.h"
#include "kernel/scene/param_table.h"
#include "kernel/scene/params.h"
#include "kernel/scene/scene.h"
#include "kernel/scene/update.h"

RSW_TEST_DEFINE_GLOBALS

/* %1$s ABI version, %2$s type name, %3$s radiance expression (i: the
 * instance), %4$s sampled pdf, %5$s pdf(), %6$s entry symbol name. */
static const char *const TEMPLATE =
    "#include <raysweep/plugin.h>\n"
    "#include <math.h>\n"
    "#include <stdio.h>\n"
    "#include <stdlib.h>\n"
    "static const rsw_plugin_host *H;\n"
    "static const rsw_plugin_param P[] = {{\"radiance\", RSW_PARAM_FLOAT, {1, 0, 0}, RSW_UPDATE_SPECTRAL, 0, "
    "1e6},\n"
    "  {\"axis\", RSW_PARAM_VECTOR3, {0, 0, 1}, RSW_UPDATE_SPECTRAL, 0, 0}};\n"
    "typedef struct inst { double L, axis[3], wl; } inst;\n"
    "static int cr(const double *const *v, void **o, char *e, size_t n) {\n"
    "  inst *i = calloc(1, sizeof *i);\n"
    "  if (!i) { snprintf(e, n, \"out of memory\"); return 1; }\n"
    "  i->L = v[0][0]; for (int k = 0; k < 3; k++) i->axis[k] = v[1][k];\n"
    "  *o = i; return 0; }\n"
    "static void de(void *i) { free(i); }\n"
    "static int sp(void *p, const char *name, const double *v, char *e, size_t n) {\n"
    "  inst *i = p;\n"
    "  if (name[0] == 'r') { i->L = v[0]; return 0; }\n"
    "  if (name[0] == 'a') { for (int k = 0; k < 3; k++) i->axis[k] = v[k]; return 0; }\n"
    "  snprintf(e, n, \"no parameter %%s\", name); return 1; }\n"
    "static int gp(const void *p, const char *name, double *v) {\n"
    "  const inst *i = p;\n"
    "  if (name[0] == 'r') { v[0] = i->L; return 0; }\n"
    "  if (name[0] == 'a') { for (int k = 0; k < 3; k++) v[k] = i->axis[k]; return 0; }\n"
    "  return 1; }\n"
    "static int pr(void *p, const rsw_prepare_context *c, char *e, size_t n) {\n"
    "  inst *i = p; (void)e, (void)n; i->wl = c->wavelength_min; return 0; }\n"
    "static void ar(const void *p, rsw_stokes_context *c, const double d[3]) {\n"
    "  const inst *i = p; (void)i, (void)d;\n"
    "  for (size_t k = 0; k < c->count; k++) c->stokes[0][k] += %3$s; }\n"
    "static double sa(const void *p, const double u[2], double d[3]) {\n"
    "  (void)p; H->square_to_uniform_sphere(u, d); return %4$s; }\n"
    "static double pd(const void *p, const double d[3]) { (void)p, (void)d; return %5$s; }\n"
    "static const rsw_env_plugin T = {%1$s, \"%2$s\", \"Test plugin\", P, 2, cr, de, NULL, sp, gp, pr, ar, "
    "sa, pd};\n"
    "const rsw_env_plugin *%6$s(const rsw_plugin_host *h) { H = h; return &T; }\n";

typedef struct spec {
  const char *abi, *type, *radiance, *sample_pdf, *pdf, *entry;
} spec;

static spec good(const char *type) {
  return (spec){"RSW_PLUGIN_ABI_VERSION", type, "i->L", "H->uniform_sphere_pdf()", "H->uniform_sphere_pdf()",
                "rsw_env_plugin_entry"};
}

static char include_dir[1024];

static void find_include_dir(void) {
  const char *td = getenv("RSW_TEST_DIR"); /* tests/ (set by tests/run.sh) */
  if (td)
    snprintf(include_dir, sizeof include_dir, "%s/../include", td);
  else
    snprintf(include_dir, sizeof include_dir, "include");
}

/* A fresh directory under /tmp (caller removes it with rm_dir). */
static bool make_dir(char *out, size_t len) {
  snprintf(out, len, "/tmp/rsw_plugin_test_XXXXXX");
  return mkdtemp(out) != NULL;
}

static void rm_dir(const char *dir) {
  char cmd[1200];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  if (system(cmd)) fprintf(stderr, "could not remove %s\n", dir);
}

/* Compile spec into dir/file.so; true on success. */
static bool build_plugin(const char *dir, const char *file, spec s) {
  char src[1100], so[1100], cmd[4096];
  snprintf(src, sizeof src, "%s/%s.c", dir, file);
  snprintf(so, sizeof so, "%s/%s.so", dir, file);
  FILE *f = fopen(src, "w");
  if (!f) return false;
  fprintf(f, TEMPLATE, s.abi, s.type, s.radiance, s.sample_pdf, s.pdf, s.entry);
  fclose(f);
  snprintf(cmd, sizeof cmd, "cc -std=c11 -Wall -Wextra -Werror -shared -fPIC -I '%s' -o '%s' '%s'",
           include_dir, so, src);
  return system(cmd) == 0;
}

/* Load a directory holding the given plugins; returns the status and the
 * message. */
static rsw_status load_specs(const spec *specs, const char *const *files, size_t n, char *msg, size_t len,
                             char *dir_out, size_t dir_len) {
  char dir[256];
  if (!make_dir(dir, sizeof dir)) return RSW_ERR_IO;
  for (size_t i = 0; i < n; i++)
    if (!build_plugin(dir, files[i], specs[i])) {
      snprintf(msg, len, "could not compile %s", files[i]);
      rm_dir(dir);
      return RSW_ERR_IO;
    }
  rsw_err err = {0};
  rsw_status st = plugins_load_dir(dir, &err);
  rsw_err_format(&err, msg, len);
  if (dir_out) snprintf(dir_out, dir_len, "%s", dir);
  rm_dir(dir);
  return st;
}

/* The built-in registry (scene/registry.c): strong references, so every
 * entry is there (a missing plugin would not link); names unique, each
 * found by registry_find, each shape with its geometry's ops. */
static void test_builtin_registry(void) {
  size_t n = 0;
  for (; rsw_plugins[n]; n++) {
    const plugin *p = rsw_plugins[n];
    CHECK(p->name && p->name[0], "registry entry %zu has no name", n);
    CHECK(registry_find(p->name) == p, "registry_find(\"%s\") finds another entry", p->name);
    for (size_t k = 0; k < n; k++)
      CHECK(strcmp(rsw_plugins[k]->name, p->name) != 0, "'%s' registered twice", p->name);
  }
  CHECK(n >= 40, "only %zu built-in plugins", n);
  CHECK(registry_find("cylinder") && registry_find("hdrfilm") && registry_find("path"), "core plugins");
}

static void test_good_plugin_loads(void) {
  spec s = good("ptest");
  const char *files[] = {"good"};
  char msg[1200] = "", dir[256];
  REQUIRE(load_specs(&s, files, 1, msg, sizeof msg, dir, sizeof dir) == RSW_OK, "good plugin refused: %s",
          msg);
  CHECK(plugins_count() == 1, "count %zu", plugins_count());
  const plugin *p = registry_find("ptest");
  REQUIRE(p != NULL, "registry_find does not see the plugin");
  CHECK(p->cls == CLS_EMITTER, "class %d", (int)p->cls);
  const char *pretty = NULL, *file = NULL;
  CHECK(plugins_at(0, &pretty, &file) == p && strcmp(pretty, "Test plugin") == 0, "pretty '%s'", pretty);
  CHECK(file && strstr(file, "good.so"), "file '%s'", file ? file : "");
  /* Loading the same type again clashes with the loaded one. */
  char dir2[256];
  rsw_status st = load_specs(&s, files, 1, msg, sizeof msg, dir2, sizeof dir2);
  CHECK(st == RSW_ERR_DUPLICATE && strstr(msg, "already provided") && strstr(msg, "good.so"),
        "second load: %s", msg);
  CHECK(plugins_count() == 1, "count after refused load %zu", plugins_count());
  plugins_unload();
  CHECK(plugins_count() == 0 && registry_find("ptest") == NULL, "unload left the type registered");
}

static void check_refused(const spec *specs, const char *const *files, size_t n, const char *want1,
                          const char *want_file, const char *what) {
  char msg[1200] = "";
  rsw_status st = load_specs(specs, files, n, msg, sizeof msg, NULL, 0);
  CHECK(st != RSW_OK, "%s: loaded", what);
  CHECK(strstr(msg, want1) != NULL, "%s: message lacks '%s': %s", what, want1, msg);
  CHECK(strstr(msg, want_file) != NULL, "%s: message does not name %s: %s", what, want_file, msg);
  CHECK(plugins_count() == 0, "%s: %zu plugins stayed loaded (all or nothing)", what, plugins_count());
  plugins_unload();
}

static void test_bad_plugins_refused(void) {
  spec s = good("pbad");
  s.abi = "99";
  const char *f1[] = {"wrong_abi"};
  check_refused(&s, f1, 1, "ABI version 99", "wrong_abi.so", "wrong ABI");

  s = good("pbad");
  s.entry = "some_other_entry";
  const char *f2[] = {"no_entry"};
  check_refused(&s, f2, 1, "rsw_env_plugin_entry", "no_entry.so", "missing symbol");

  spec two[2] = {good("pdup"), good("pdup")};
  const char *f3[] = {"a_first", "b_second"};
  check_refused(two, f3, 2, "already provided by", "b_second.so", "duplicate type");

  s = good("constant");
  const char *f4[] = {"clash"};
  check_refused(&s, f4, 1, "built-in", "clash.so", "built-in clash");

  s = good("Bad-Name");
  const char *f5[] = {"badname"};
  check_refused(&s, f5, 1, "invalid type name", "badname.so", "invalid type name");

  rsw_err err = {0};
  CHECK(plugins_load_dir("/nonexistent/rsw_plugins", &err) != RSW_OK &&
            strstr(err.msg, "/nonexistent/rsw_plugins"),
        "missing directory: %s", err.msg);
}

/* A grey diffuse sphere seen from +y under environment ENV (JSON),
 * rendered by INTEGRATOR (JSON). */
static rsw_status load_scene_with(const char *env_json, const char *integrator_json, const char *variant,
                                  scene **out, rsw_err *err) {
  char doc[2048];
  snprintf(
      doc, sizeof doc,
      "{\"type\": \"scene\","
      " \"sensor\": {\"type\": \"perspective\", \"fov\": 40,"
      "  \"to_world\": [{\"lookat\": {\"origin\": [0, 5, 0], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
      "  \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8},"
      "  \"sampler\": {\"type\": \"independent\", \"sample_count\": 4}},"
      " \"integrator\": %s,"
      " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}},"
      " \"env\": %s}",
      integrator_json, env_json);
  scene_load_opts lo = {.size = sizeof lo, .variant = variant};
  return scene_load_memory(doc, strlen(doc), "plugin_test.json", false, &lo, out, err);
}

/* The sphere under ENV through `path` (max_depth 3). */
static rsw_status load_scene(const char *env_json, const char *variant, scene **out, rsw_err *err) {
  return load_scene_with(env_json, "{\"type\": \"path\", \"max_depth\": 3}", variant, out, err);
}

static bool render(scene *s, film_image *img) {
  rsw_err err = {0};
  render_opts ro = {.size = sizeof ro, .seed = 7, .wavelength = 600, .threads = 2};
  render_result_stats rs;
  rsw_status st = render_sensor(s, &ro, img, &rs, &err);
  if (st) printf("  render failed: %s\n", err.msg);
  return st == RSW_OK;
}

static void test_plugin_matches_constant_and_updates(void) {
  spec s = good("pconst");
  const char *files[] = {"pconst"};
  char msg[1200] = "";
  REQUIRE(load_specs(&s, files, 1, msg, sizeof msg, NULL, 0) == RSW_OK, "load: %s", msg);
  scene *sp = NULL, *sc = NULL;
  rsw_err err = {0};
  film_image a = {0}, b = {0}, c = {0};
  if (load_scene("{\"type\": \"pconst\", \"radiance\": 1.5}", "mono", &sp, &err)) {
    CHECK(0, "plugin scene: %s %s", err.where, err.msg);
    goto out;
  }
  if (load_scene("{\"type\": \"constant\", \"radiance\": 1.5}", "mono", &sc, &err)) {
    CHECK(0, "constant scene: %s", err.msg);
    goto out;
  }
  if (!render(sp, &a) || !render(sc, &b)) {
    CHECK(0, "render failed");
    goto out;
  }
  /* Same warp, same pdf, same sampler dimensions: the films agree to
   * rounding (the adapter renormalises directions). */
  double maxrel = 0;
  size_t n = (size_t)a.width * a.height * a.channels;
  for (size_t i = 0; i < n; i++) {
    double d = fabs(a.data[i] - b.data[i]) / fmax(1e-12, fabs(b.data[i]));
    if (d > maxrel) maxrel = d;
  }
  double sum = 0;
  for (size_t i = 0; i < n; i++) sum += a.data[i];
  CHECK(sum / (double)n > 0.1, "plugin film is dark: mean %g", sum / (double)n);
  CHECK(maxrel < 1e-5, "plugin vs constant: max relative difference %g", maxrel);
  CHECK(emitter_failures(sp, 0, NULL, 0) == 0, "good plugin reported failures");

  /* The plugin's parameters are in the table (spectral) and updatable:
   * radiance 1.5 -> 3 doubles the film. */
  size_t idx;
  CHECK(params_lookup(sp, "env.radiance", &idx, &err) == RSW_OK, "env.radiance not in the table: %s",
        err.msg);
  param_info info;
  if (params_info(sp, idx, &info)) CHECK(info.cls == UPDATE_SPECTRAL, "class %d", (int)info.cls);
  CHECK(params_lookup(sp, "env.axis", &idx, &err) == RSW_OK, "env.axis not in the table: %s", err.msg);
  param_update up = {.key = "env.radiance", .value = {.kind = PV_NUMBER, .num = 3.0}};
  CHECK(scene_update(sp, &up, 1, NULL, &err) == RSW_OK, "update: %s", err.msg);
  if (!render(sp, &c)) goto out;
  maxrel = 0;
  for (size_t i = 0; i < n; i++) {
    double d = fabs(c.data[i] - 2.0 * a.data[i]) / fmax(1e-12, fabs(a.data[i]));
    if (d > maxrel) maxrel = d;
  }
  CHECK(maxrel < 1e-5, "radiance update: max relative difference %g from twice the film", maxrel);
  up.value.num = 2e6; /* outside the declared [0, 1e6] */
  CHECK(scene_update(sp, &up, 1, NULL, &err) != RSW_OK, "out-of-range update accepted");

  /* Unknown properties stay errors. */
  scene *bad = NULL;
  CHECK(load_scene("{\"type\": \"pconst\", \"radiannce\": 1}", "mono", &bad, &err) != RSW_OK,
        "unknown property accepted");
  scene_free(bad);
out:
  film_image_free(&a), film_image_free(&b), film_image_free(&c);
  scene_free(sp), scene_free(sc);
  plugins_unload();
}

/* Load the good plugin of type `type` (file type.so); false (said) if it
 * did not build or load. */
static bool load_good(const char *type) {
  spec s = good(type);
  const char *files[] = {type};
  char msg[1200] = "";
  if (load_specs(&s, files, 1, msg, sizeof msg, NULL, 0) == RSW_OK) return true;
  printf("  load %s: %s\n", type, msg);
  return false;
}

static void test_rgb_scene_refused(void) {
  REQUIRE(load_good("prgb"), "the plugin did not load");
  scene *sc = NULL;
  rsw_err err = {0};
  rsw_status st = load_scene("{\"type\": \"prgb\"}", "rgb", &sc, &err);
  CHECK(st == RSW_ERR_UNSUPPORTED, "rgb scene: status %d", (int)st);
  CHECK(strstr(err.msg, "mono") && strstr(err.msg, "prgb"), "message: %s", err.msg);
  scene_free(sc);
  plugins_unload();
}

/* Render with a misbehaving plugin: completes, no NaN in the film, and the
 * failure is counted with a message containing `want`. */
static void check_contained(spec s, const char *want, const char *what) {
  const char *files[] = {"pmis"};
  char msg[1200] = "";
  REQUIRE(load_specs(&s, files, 1, msg, sizeof msg, NULL, 0) == RSW_OK, "%s: load: %s", what, msg);
  scene *sc = NULL;
  rsw_err err = {0};
  film_image img = {0};
  if (load_scene("{\"type\": \"pmis\"}", "mono", &sc, &err)) {
    CHECK(0, "%s: scene: %s", what, err.msg);
  } else if (!render(sc, &img)) {
    CHECK(0, "%s: render failed", what);
  } else {
    size_t n = (size_t)img.width * img.height * img.channels, bad = 0;
    for (size_t i = 0; i < n; i++) bad += !isfinite(img.data[i]);
    CHECK(bad == 0, "%s: %zu non-finite pixels", what, bad);
    char fm[600];
    size_t k = emitter_failures(sc, 0, fm, sizeof fm);
    CHECK(k > 0, "%s: no failure reported", what);
    CHECK(strstr(fm, want) && strstr(fm, "pmis") && strstr(fm, "'env'"), "%s: message: %s", what, fm);
  }
  film_image_free(&img);
  scene_free(sc);
  plugins_unload();
}

static void test_bad_values_contained(void) {
  spec s = good("pmis");
  s.radiance = "NAN";
  check_contained(s, "add_radiance", "NaN radiance");
  s = good("pmis");
  s.radiance = "-1.0";
  check_contained(s, "add_radiance", "negative radiance");
  s = good("pmis");
  s.sample_pdf = "-1.0";
  check_contained(s, "sample returned pdf -1", "negative sampled pdf");
  s = good("pmis");
  s.sample_pdf = "0.0";
  check_contained(s, "sample returned pdf 0", "zero sampled pdf");
  s = good("pmis");
  s.pdf = "NAN";
  check_contained(s, "pdf returned", "NaN pdf");
}

/* ---- spectral bundles: one add_radiance per evaluation, failures per film ---- */

/* "pcount": a sky of (d.z > 0 ? 1 : 0.5) 500 / w, NaN above `nan_above`
 * nm; it counts its add_radiance calls and the wavelengths they ask for
 * in exported globals (atomics: render threads call concurrently). */
static const char *const COUNTING =
    "#include <raysweep/plugin.h>\n"
    "#include <math.h>\n"
    "#include <stdio.h>\n"
    "static const rsw_plugin_host *H;\n"
    "unsigned long long pcount_calls, pcount_wavelengths;\n"
    "static const rsw_plugin_param P[] = {{\"nan_above\", RSW_PARAM_FLOAT, {1e9, 0, 0}, RSW_UPDATE_SPECTRAL, "
    "0, "
    "1e9}};\n"
    "static double above;\n"
    "static int cr(const double *const *v, void **o, char *e, size_t n) {\n"
    "  (void)e, (void)n; above = v[0][0]; *o = &above; return 0; }\n"
    "static void de(void *i) { (void)i; }\n"
    "static int sp(void *p, const char *name, const double *v, char *e, size_t n) {\n"
    "  (void)p, (void)name, (void)v; snprintf(e, n, \"read-only\"); return 1; }\n"
    "static void ar(const void *p, rsw_stokes_context *c, const double d[3]) {\n"
    "  const double *a = p;\n"
    "  __atomic_fetch_add(&pcount_calls, 1, __ATOMIC_RELAXED);\n"
    "  __atomic_fetch_add(&pcount_wavelengths, c->count, __ATOMIC_RELAXED);\n"
    "  for (size_t k = 0; k < c->count; k++)\n"
    "    c->stokes[0][k] += c->wavelengths[k] > *a ? NAN : (d[2] > 0 ? 1.0 : 0.5) * 500.0 / "
    "c->wavelengths[k]; }\n"
    "static double sa(const void *p, const double u[2], double d[3]) {\n"
    "  (void)p; H->square_to_uniform_sphere(u, d); return H->uniform_sphere_pdf(); }\n"
    "static double pd(const void *p, const double d[3]) { (void)p, (void)d; return H->uniform_sphere_pdf(); "
    "}\n"
    "static const rsw_env_plugin T = {RSW_PLUGIN_ABI_VERSION, \"pcount\", \"Counting sky\", P, 1, cr, de, "
    "NULL, "
    "sp, NULL, NULL, ar, sa, pd};\n"
    "const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *h) { H = h; return &T; }\n";

typedef struct counters {
  unsigned long long *calls, *wavelengths;
} counters;

/* Build and load pcount; its counters through the loaded object's
 * symbols (the directory is removed once it is loaded). */
static bool load_counting(counters *k) {
  char dir[256], src[300], so[300], cmd[2048];
  if (!make_dir(dir, sizeof dir)) return false;
  snprintf(src, sizeof src, "%s/pcount.c", dir);
  snprintf(so, sizeof so, "%s/pcount.so", dir);
  FILE *f = fopen(src, "w");
  bool ok = f != NULL;
  if (f) {
    fputs(COUNTING, f);
    fclose(f);
  }
  snprintf(cmd, sizeof cmd, "cc -std=c11 -Wall -Wextra -Werror -shared -fPIC -I '%s' -o '%s' '%s'",
           include_dir, so, src);
  ok = ok && system(cmd) == 0;
  rsw_err err = {0};
  ok = ok && plugins_load_dir(dir, &err) == RSW_OK;
  void *h = ok ? dlopen(so, RTLD_NOW | RTLD_NOLOAD) : NULL;
  k->calls = h ? dlsym(h, "pcount_calls") : NULL;
  k->wavelengths = h ? dlsym(h, "pcount_wavelengths") : NULL;
  if (h) dlclose(h); /* (a reference of its own: the adapter's keeps it loaded) */
  rm_dir(dir);
  return k->calls && k->wavelengths;
}

/* 16 wavelengths 400..550 nm (k: 1 unbundled at 400 nm); the calls and
 * wavelengths asked of the plugin by a render of sc through a bundle of
 * k of them into out[0..k). */
static bool render_counted(scene *sc, int k, const counters *c, film_image *out, unsigned long long *calls,
                           unsigned long long *wls) {
  render_opts ro = {.size = sizeof ro, .seed = 7, .wavelength = 400, .threads = 2, .bundle = k};
  for (int i = 0; i < 16; i++) ro.bundle_wl[i] = 400.0 + 10.0 * i;
  *c->calls = *c->wavelengths = 0;
  rsw_err err = {0};
  rsw_status st = render_sensor_bundle(sc, &ro, out, NULL, &err);
  if (st) printf("  render (bundle %d) failed: %s\n", k, err.msg);
  *calls = *c->calls, *wls = *c->wavelengths;
  return st == RSW_OK;
}

/* A bundle of 16 (six pages) asks add_radiance once per evaluation, for
 * every wavelength of the bundle: as many calls as a bundle of 3 (one
 * page, one call per evaluation; before, six per evaluation: one per
 * page). The sphere under the sky: every sample that hits it takes a
 * light sample (path.c asks page 0 of a whole wave's light samples first)
 * and its bounce escapes (the sphere is convex); the others escape. The
 * camera looking away from the sphere: one call per sample. */
static void test_bundle_asks_once(void) {
  counters c;
  REQUIRE(load_counting(&c), "the counting plugin did not build or load");
  static const char *const integrators[] = {"{\"type\": \"path\", \"max_depth\": 3}",
                                            "{\"type\": \"volpath\", \"max_depth\": 3}",
                                            "{\"type\": \"direct\"}"};
  film_image f16[16], f3[3];
  memset(f16, 0, sizeof f16), memset(f3, 0, sizeof f3);
  for (int i = 0; i < 3; i++) {
    scene *sc = NULL;
    rsw_err err = {0};
    if (load_scene_with("{\"type\": \"pcount\"}", integrators[i], "mono", &sc, &err)) {
      CHECK(0, "%s: scene: %s", integrators[i], err.msg);
      continue;
    }
    unsigned long long n3, w3, n16, w16;
    if (render_counted(sc, 3, &c, f3, &n3, &w3) && render_counted(sc, 16, &c, f16, &n16, &w16)) {
      CHECK(n3 > 256 && w3 == 3 * n3, "%s: bundle of 3: %llu calls for %llu wavelengths", integrators[i], n3,
            w3);
      CHECK(n16 == n3, "%s: bundle of 16: %llu add_radiance calls, %.3g per evaluation (%llu evaluations)",
            integrators[i], n16, (double)n16 / (double)n3, n3);
      CHECK(w16 == 16 * n16, "%s: bundle of 16: %llu wavelengths in %llu calls", integrators[i], w16, n16);
      for (int b = 0; b < 16; b++)
        CHECK(f16[b].plugin_failures == 0, "%s: film %d: %llu failures", integrators[i], b,
              (unsigned long long)f16[b].plugin_failures);
    }
    for (int b = 0; b < 16; b++) film_image_free(&f16[b]);
    for (int b = 0; b < 3; b++) film_image_free(&f3[b]);
    scene_free(sc);
  }
  scene *away = NULL;
  rsw_err err = {0};
  const char *doc =
      "{\"type\": \"scene\","
      " \"sensor\": {\"type\": \"perspective\", \"fov\": 40,"
      "  \"to_world\": [{\"lookat\": {\"origin\": [0, 5, 0], \"target\": [0, 10, 0], \"up\": [0, 0, 1]}}],"
      "  \"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8},"
      "  \"sampler\": {\"type\": \"independent\", \"sample_count\": 4}},"
      " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"diffuse\"}},"
      " \"env\": {\"type\": \"pcount\"}}";
  scene_load_opts lo = {.size = sizeof lo, .variant = "mono"};
  if (scene_load_memory(doc, strlen(doc), "away.json", false, &lo, &away, &err)) {
    CHECK(0, "scene away: %s", err.msg);
  } else {
    unsigned long long n, w;
    if (render_counted(away, 16, &c, f16, &n, &w))
      CHECK(n == 8 * 8 * 4 && w == 16 * n,
            "sky alone, bundle of 16: %llu calls (%llu wavelengths) for %d escapes", n, w, 8 * 8 * 4);
    for (int b = 0; b < 16; b++) film_image_free(&f16[b]);
  }
  scene_free(away);
  plugins_unload();
}

/* A plugin that answers NaN above 475 nm, in a bundle of 16 (400..550
 * nm): each film counts its own wavelength's failures, the films at 400
 * ..470 nm none, those at 480..550 nm some, with a message naming their
 * wavelength; unbundled, the same at 470 and 480 nm. */
static void test_failures_per_film(void) {
  counters c;
  REQUIRE(load_counting(&c), "the counting plugin did not build or load");
  scene *sc = NULL;
  rsw_err err = {0};
  film_image f16[16];
  memset(f16, 0, sizeof f16);
  if (load_scene("{\"type\": \"pcount\", \"nan_above\": 475}", "mono", &sc, &err)) {
    CHECK(0, "scene: %s", err.msg);
    plugins_unload();
    return;
  }
  unsigned long long n, w;
  if (render_counted(sc, 16, &c, f16, &n, &w)) {
    for (int b = 0; b < 16; b++) {
      double wl = 400.0 + 10.0 * b;
      char want[64];
      snprintf(want, sizeof want, "at %g nm", wl);
      if (wl < 475)
        CHECK(f16[b].plugin_failures == 0 && !f16[b].plugin_failure[0], "film at %g nm: %llu failures (%s)",
              wl, (unsigned long long)f16[b].plugin_failures, f16[b].plugin_failure);
      else
        CHECK(f16[b].plugin_failures > 0 && strstr(f16[b].plugin_failure, want) &&
                  strstr(f16[b].plugin_failure, "add_radiance returned I = nan"),
              "film at %g nm: %llu failures (%s)", wl, (unsigned long long)f16[b].plugin_failures,
              f16[b].plugin_failure);
      size_t bad = 0;
      for (size_t i = 0; i < (size_t)f16[b].width * f16[b].height * f16[b].channels; i++)
        bad += !isfinite(f16[b].data[i]);
      CHECK(bad == 0, "film at %g nm: %zu non-finite values", wl, bad);
    }
    /* Every film above counts each of its evaluations once. */
    CHECK(f16[15].plugin_failures == f16[8].plugin_failures,
          "films at 480 and 550 nm: %llu and %llu failures", (unsigned long long)f16[8].plugin_failures,
          (unsigned long long)f16[15].plugin_failures);
  }
  for (int b = 0; b < 16; b++) film_image_free(&f16[b]);
  film_image one = {0};
  render_opts ro = {.size = sizeof ro, .seed = 7, .wavelength = 470, .threads = 2};
  if (render_sensor(sc, &ro, &one, NULL, &err) == RSW_OK)
    CHECK(one.plugin_failures == 0, "unbundled at 470 nm: %llu failures",
          (unsigned long long)one.plugin_failures);
  film_image_free(&one);
  ro.wavelength = 480;
  if (render_sensor(sc, &ro, &one, NULL, &err) == RSW_OK)
    CHECK(one.plugin_failures > 0 && strstr(one.plugin_failure, "at 480 nm"),
          "unbundled at 480 nm: %llu (%s)", (unsigned long long)one.plugin_failures, one.plugin_failure);
  film_image_free(&one);
  scene_free(sc);
  plugins_unload();
}

/* The memo never answers for another render: a bundle of 16 rendered
 * again with the same seed (the same directions, on threads that keep
 * their memo) after env.radiance 1.5 -> 3 is exactly twice the first, at
 * every wavelength (a scale by 2 is exact). */
static void test_bundle_memo_follows_updates(void) {
  REQUIRE(load_good("pupd"), "the plugin did not load");
  scene *sc = NULL;
  rsw_err err = {0};
  film_image a[16], b[16];
  memset(a, 0, sizeof a), memset(b, 0, sizeof b);
  render_opts ro = {.size = sizeof ro, .seed = 7, .threads = 2, .bundle = 16};
  for (int i = 0; i < 16; i++) ro.bundle_wl[i] = 400.0 + 10.0 * i;
  param_update up = {.key = "env.radiance", .value = {.kind = PV_NUMBER, .num = 3.0}};
  if (load_scene("{\"type\": \"pupd\", \"radiance\": 1.5}", "mono", &sc, &err)) {
    CHECK(0, "scene: %s", err.msg);
  } else if (render_sensor_bundle(sc, &ro, a, NULL, &err) || scene_update(sc, &up, 1, NULL, &err) ||
             render_sensor_bundle(sc, &ro, b, NULL, &err)) {
    CHECK(0, "render or update: %s", err.msg);
  } else {
    for (int k = 0; k < 16; k++) {
      size_t n = (size_t)a[k].width * a[k].height * a[k].channels, off = 0;
      double sum = 0;
      for (size_t i = 0; i < n; i++) {
        off += b[k].data[i] != 2.0 * a[k].data[i];
        sum += a[k].data[i];
      }
      CHECK(off == 0 && sum > 0, "film %d (%g nm): %zu of %zu values not twice the first render's (mean %g)",
            k, 400.0 + 10.0 * k, off, n, sum / (double)n);
    }
  }
  for (int k = 0; k < 16; k++) film_image_free(&a[k]), film_image_free(&b[k]);
  scene_free(sc);
  plugins_unload();
}

int main(void) {
  find_include_dir();
  RSW_TEST_RUN(test_builtin_registry);
  RSW_TEST_RUN(test_good_plugin_loads);
  RSW_TEST_RUN(test_bad_plugins_refused);
  RSW_TEST_RUN(test_plugin_matches_constant_and_updates);
  RSW_TEST_RUN(test_rgb_scene_refused);
  RSW_TEST_RUN(test_bad_values_contained);
  RSW_TEST_RUN(test_bundle_asks_once);
  RSW_TEST_RUN(test_failures_per_film);
  RSW_TEST_RUN(test_bundle_memo_follows_updates);
  RSW_TEST_END("test_plugin_loader");
}
