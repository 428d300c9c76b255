/* "An update equals a reload, bitwise" (issue 3, docs/kernel-conventions.md#parameters-and-updates):
 * for each case, scene S is loaded and rendered once (so every cache is
 * warm), scene_update() applies a change, and the scene is rendered again
 * with the same sensor, seed, spp, thread count and wavelength; separately
 * S' (S with the change written into its JSON) is loaded and rendered. The
 * two films must be memcmp-identical, and differ from the render before
 * the update (so the case exercises something).
 *
 * Films are small (16x16, 16 spp; distant 1x1) to keep the binary fast.
 * Sensors vary: hdistant with a shape target, hdistant without a target
 * (depends on the scene's bounding sphere), distant, perspective. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../server/kernel/core/transform.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define SPP     16
#define SEED    20240611u
#define THREADS 2

/* ---- sensors and emitters used by the cases ------------------------------ */

#define FILM16                                                                                               \
  "\"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16, \"rfilter\": {\"type\": \"box\"}}"
#define SAMPLER "\"sampler\": {\"type\": \"independent\", \"sample_count\": 16}"

/* hdistant aimed at a [-1,1]^2 rectangle target (zero variance on a flat
 * Lambertian plate, full hemisphere for glossy lobes). */
#define HDIST_T                                                                                              \
  "\"cam\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\"}, " SAMPLER ", " FILM16 "}"
/* hdistant without target: origins on the bounding sphere's disk. */
#define HDIST_NT "\"cam\": {\"type\": \"hdistant\", " SAMPLER ", " FILM16 "}"
#define PERSP                                                                                                \
  "\"cam\": {\"type\": \"perspective\", \"fov\": 60, \"to_world\": [{\"lookat\": {\"origin\": "              \
  "[0.5, -2.5, 2.5], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}], " SAMPLER ", " FILM16 "}"
#define SUN                                                                                                  \
  "\"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0.1, -0.86602540378443864676], "                \
  "\"irradiance\": 1.0}"

/* ---- helpers ---------------------------------------------------------------- */

static bool render_wl(scene *s, double wavelength, film_image *out) {
  rsw_err err = {0};
  render_opts o = {
      .size = sizeof o, .sensor = 0, .spp = SPP, .seed = SEED, .threads = THREADS, .wavelength = wavelength};
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

/* Number of differing floats and the largest relative difference (for
 * failure messages). */
static size_t film_diff(const film_image *a, const film_image *b, double *worst) {
  size_t n = (size_t)a->width * a->height * a->channels, bad = 0;
  *worst = 0;
  if (a->width != b->width || a->height != b->height || a->channels != b->channels) return n;
  for (size_t i = 0; i < n; i++) {
    if (memcmp(&a->data[i], &b->data[i], sizeof(float)) == 0) continue;
    bad++;
    double m = fmax(fabs(a->data[i]), fabs(b->data[i]));
    double d = m > 0 ? fabs((double)a->data[i] - b->data[i]) / m : 0;
    if (d > *worst) *worst = d;
  }
  return bad;
}

typedef struct upd_text {
  const char *key;
  const char *json;
} upd_text;

/* One case: S, the update (JSON values), S', the wavelengths to render at
 * (mono), the expected update classes, and the relative tolerance (0:
 * bitwise). */
typedef struct reload_case {
  const char *name;
  const char *variant;
  const char *before;
  const char *after;
  upd_text upd[3];
  size_t n_upd;
  double wl[2];
  size_t n_wl;
  unsigned classes;
  double rel_tol;
} reload_case;

static void run_case(const reload_case *c) {
  size_t n_wl = c->n_wl ? c->n_wl : 1;
  scene *s = tsup_load(c->before, c->variant);
  REQUIRE(s, "%s: load S", c->name);
  film_image pre[2] = {{0}}, post[2] = {{0}}, ref[2] = {{0}};
  bool ok = true;
  for (size_t w = 0; w < n_wl && ok; w++) ok = render_wl(s, c->n_wl ? c->wl[w] : 0, &pre[w]);
  CHECK(ok, "%s: render S", c->name);

  param_update items[3];
  size_t n_parsed = 0;
  rsw_err err = {0};
  for (size_t i = 0; i < c->n_upd && ok; i++) {
    items[i].key = c->upd[i].key;
    if (param_value_parse(c->upd[i].json, c->upd[i].key, &items[i].value, &err) != RSW_OK) {
      char buf[1200];
      CHECK(false, "%s: parse %s = %s: %s", c->name, c->upd[i].key, c->upd[i].json,
            rsw_err_format(&err, buf, sizeof buf));
      ok = false;
    } else {
      n_parsed++;
    }
  }
  update_report rep = {0};
  if (ok) {
    if (scene_update(s, items, c->n_upd, &rep, &err) != RSW_OK) {
      char buf[1200];
      CHECK(false, "%s: scene_update: %s", c->name, rsw_err_format(&err, buf, sizeof buf));
      ok = false;
    }
  }
  for (size_t i = 0; i < n_parsed; i++) param_value_free(&items[i].value);
  if (ok) {
    CHECK(rep.classes == c->classes, "%s: report.classes = %u, expected %u", c->name, rep.classes,
          c->classes);
    CHECK(rep.changed == c->n_upd, "%s: report.changed = %zu, expected %zu", c->name, rep.changed, c->n_upd);
    for (size_t w = 0; w < n_wl && ok; w++) ok = render_wl(s, c->n_wl ? c->wl[w] : 0, &post[w]);
    CHECK(ok, "%s: render S after the update", c->name);
  }
  scene *s2 = ok ? tsup_load(c->after, c->variant) : NULL;
  if (ok && !s2) {
    CHECK(false, "%s: load S'", c->name);
    ok = false;
  }
  for (size_t w = 0; w < n_wl && ok; w++) ok = render_wl(s2, c->n_wl ? c->wl[w] : 0, &ref[w]);
  for (size_t w = 0; w < n_wl && ok; w++) {
    double wl = c->n_wl ? c->wl[w] : 0;
    CHECK(!same_film(&pre[w], &post[w]), "%s (wl %g): the update did not change the film", c->name, wl);
    double worst;
    size_t bad = film_diff(&post[w], &ref[w], &worst);
    if (c->rel_tol == 0) {
      CHECK(bad == 0, "%s (wl %g): updated film differs from reloaded film in %zu values (worst rel %.3g)",
            c->name, wl, bad, worst);
    } else {
      CHECK(worst <= c->rel_tol,
            "%s (wl %g): updated film differs from reloaded film: %zu values, worst rel %.3g > %g", c->name,
            wl, bad, worst, c->rel_tol);
    }
  }
  for (size_t w = 0; w < 2; w++) {
    film_image_free(&pre[w]);
    film_image_free(&post[w]);
    film_image_free(&ref[w]);
  }
  scene_free(s2);
  scene_free(s);
}

/* "[m00, m01, ..., m33]" (flat) or "[[..], [..], [..], [..]]" (rows), with
 * %.17g so that the numbers round-trip exactly. */
static void xform_json(const xform *t, bool nested, char *buf, size_t len) {
  size_t n = (size_t)snprintf(buf, len, "[");
  for (int r = 0; r < 4; r++) {
    if (nested) n += (size_t)snprintf(buf + n, len - n, "%s[", r ? ", " : "");
    for (int k = 0; k < 4; k++)
      n += (size_t)snprintf(buf + n, len - n, "%s%.17g", (k || (r && !nested)) ? ", " : "", t->m[r][k]);
    if (nested) n += (size_t)snprintf(buf + n, len - n, "]");
  }
  snprintf(buf + n, len - n, "]");
}

/* ---- spectral cases ------------------------------------------------------------ */

static void test_diffuse_number(void) {
  const char *fmt =
      "{\"type\": \"scene\", " HDIST_T ", " SUN ","
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": %s}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "0.3");
  snprintf(b, sizeof b, fmt, "0.7");
  reload_case c = {.name = "diffuse reflectance (number)",
                   .before = a,
                   .after = b,
                   .upd = {{"plate.bsdf.reflectance.value", "0.7"}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_diffuse_rgb(void) {
  const char *fmt = "{\"type\": \"scene\", " PERSP ", " SUN ","
                    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\","
                    "   \"reflectance\": {\"type\": \"rgb\", \"value\": %s}}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "[0.2, 0.4, 0.6]");
  snprintf(b, sizeof b, fmt, "[0.7, 0.1, 0.35]");
  reload_case c = {.name = "diffuse reflectance (rgb)",
                   .before = a,
                   .after = b,
                   .upd = {{"plate.bsdf.reflectance.value", "[0.7, 0.1, 0.35]"}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_twosided_shared_brdf(void) {
  /* twosided with one child: brdf_1 is the same object as brdf_0 (listed
   * once, as brdf_0); the update through brdf_0 must reach the face the
   * sensor sees, as a reload does. */
  const char *fmt = "{\"type\": \"scene\", " HDIST_T ", " SUN ","
                    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"twosided\","
                    "   \"inner\": {\"type\": \"diffuse\", \"reflectance\": %s}}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "0.25");
  snprintf(b, sizeof b, fmt, "0.9");
  reload_case c = {.name = "twosided brdf_0 reflectance",
                   .before = a,
                   .after = b,
                   .upd = {{"plate.bsdf.brdf_0.reflectance.value", "0.9"}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_directional_irradiance(void) {
  const char *fmt =
      "{\"type\": \"scene\", " HDIST_T ","
      " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0.1, -0.86602540378443864676],"
      "   \"irradiance\": {\"type\": \"rgb\", \"value\": %s}},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "[1, 1, 1]");
  snprintf(b, sizeof b, fmt, "[2.5, 0.5, 1.25]");
  reload_case c = {.name = "directional irradiance",
                   .before = a,
                   .after = b,
                   .upd = {{"sun.irradiance.value", "[2.5, 0.5, 1.25]"}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_roughconductor_alpha(void) {
  const char *fmt =
      "{\"type\": \"scene\", " HDIST_T ", " SUN ","
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": %s}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "0.3");
  snprintf(b, sizeof b, fmt, "0.08");
  reload_case c = {.name = "roughconductor alpha",
                   .before = a,
                   .after = b,
                   .upd = {{"plate.bsdf.alpha.value", "0.08"}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_roughconductor_eta_k(void) {
  const char *fmt2 = "{\"type\": \"scene\", " HDIST_T ", " SUN ","
                     " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"roughconductor\","
                     "   \"alpha\": 0.2, \"eta\": %s, \"k\": %s}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt2, "1.5", "3.0");
  snprintf(b, sizeof b, fmt2, "0.2", "4.5");
  reload_case c = {.name = "roughconductor eta and k",
                   .before = a,
                   .after = b,
                   .upd = {{"plate.bsdf.eta.value", "0.2"}, {"plate.bsdf.k.value", "4.5"}},
                   .n_upd = 2,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_mono_tabulated_reflectance(void) {
  /* A tabulated spectrum set with {"wavelengths", "values"}, rendered at
   * two wavelengths (the update must reach the evaluation at each). */
  const char *fmt = "{\"type\": \"scene\", " HDIST_T ", " SUN ","
                    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\":"
                    "   {\"type\": \"spectrum\", \"wavelengths\": [400, 500, 600, 700], \"values\": %s}}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "[0.1, 0.3, 0.5, 0.7]");
  snprintf(b, sizeof b, fmt, "[0.9, 0.6, 0.2, 0.05]");
  reload_case c = {.name = "mono tabulated reflectance",
                   .variant = "mono",
                   .before = a,
                   .after = b,
                   .upd = {{"plate.bsdf.reflectance.value",
                            "{\"wavelengths\": [400, 500, 600, 700], \"values\": [0.9, 0.6, 0.2, 0.05]}"}},
                   .n_upd = 1,
                   .wl = {450, 650},
                   .n_wl = 2,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

/* ---- emitter and sensor transforms and directions ---------------------------- */

static void test_directional_direction(void) {
  const char *fmt =
      "{\"type\": \"scene\", " HDIST_T ","
      " \"sun\": {\"type\": \"directional\", \"direction\": %s, \"irradiance\": 1.0},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "[0.5, 0.1, -0.86602540378443864676]");
  snprintf(b, sizeof b, fmt, "[-0.2, 0.4, -1]");
  reload_case c = {.name = "directional direction",
                   .before = a,
                   .after = b,
                   .upd = {{"sun.direction", "[-0.2, 0.4, -1]"}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_directional_to_world(void) {
  /* S gives the sun a direction, S' a to_world (a rotation taking +z
   * below the horizon); the update writes that to_world. */
  xform r = xf_rotate(v3(1, 0.3, 0), 150);
  char m[1024], a[4096], b[4096];
  xform_json(&r, false, m, sizeof m);
  snprintf(a, sizeof a,
           "{\"type\": \"scene\", " HDIST_T ", " SUN ","
           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}");
  snprintf(b, sizeof b,
           "{\"type\": \"scene\", " HDIST_T ","
           " \"sun\": {\"type\": \"directional\", \"to_world\": %s, \"irradiance\": 1.0},"
           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}",
           m);
  CHECK(xf_vector(&r, v3(0, 0, 1)).z < -0.5, "test setup: the rotated sun must shine downwards");
  reload_case c = {.name = "directional to_world",
                   .before = a,
                   .after = b,
                   .upd = {{"sun.to_world", m}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_hdistant_direction(void) {
  /* hdistant's `direction` is its hemisphere axis to_world (0,0,1).
   * Written, it keeps the film's azimuthal orientation (sensors/hdistant.c,
   * hdistant_set_direction): to_world = look_at(0, d, up) with
   * up = normalize(cross(d, x_old)), x_old = the old to_world (1,0,0),
   * here (1,0,0) since S's to_world is the identity. S' spells that
   * look_at out. */
  vec3 d = v3_norm(v3(0.3, -0.2, 1));
  vec3 up = v3_norm(v3_cross(d, v3(1, 0, 0)));
  char a[4096], b[4096];
  snprintf(
      a, sizeof a,
      "{\"type\": \"scene\", " HDIST_T ", " SUN ","
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": 0.3}}}");
  snprintf(b, sizeof b,
           "{\"type\": \"scene\", \"cam\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\"},"
           "   \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 0], \"target\": [%.17g, %.17g, %.17g],"
           "   \"up\": [%.17g, %.17g, %.17g]}}], " SAMPLER ", " FILM16 "}, " SUN ","
           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": 0.3}}}",
           d.x, d.y, d.z, up.x, up.y, up.z);
  char v[256];
  snprintf(v, sizeof v, "[%.17g, %.17g, %.17g]", d.x, d.y, d.z);
  reload_case c = {.name = "hdistant direction",
                   .before = a,
                   .after = b,
                   .upd = {{"cam.direction", v}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_distant_direction(void) {
  const char *fmt =
      "{\"type\": \"scene\", \"cam\": {\"type\": \"distant\", \"direction\": %s,"
      "   \"target\": [0.3, 0.3, 0], \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " " SUN ","
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": 0.3}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "[0.2, 0.1, -1]");
  snprintf(b, sizeof b, fmt, "[-0.45, 0.1, -1]");
  reload_case c = {.name = "distant direction",
                   .before = a,
                   .after = b,
                   .upd = {{"cam.direction", "[-0.45, 0.1, -1]"}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_perspective_to_world(void) {
  xform la;
  REQUIRE(xf_look_at(v3(-1, -2, 2), v3(0.1, 0, 0), v3(0, 0, 1), &la), "look_at");
  char m[1024], a[4096], b[4096];
  xform_json(&la, true, m, sizeof m);
  snprintf(a, sizeof a,
           "{\"type\": \"scene\", " PERSP ", " SUN ","
           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}");
  snprintf(
      b, sizeof b,
      "{\"type\": \"scene\", \"cam\": {\"type\": \"perspective\", \"fov\": 60, \"to_world\": %s, " SAMPLER
      ", " FILM16 "}, " SUN ","
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}",
      m);
  reload_case c = {.name = "perspective to_world",
                   .before = a,
                   .after = b,
                   .upd = {{"cam.to_world", m}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_checkerboard_color_and_to_uv(void) {
  /* A texture's nested uniform (color0) and its to_uv, in one update. */
  const char *fmt = "{\"type\": \"scene\", " HDIST_T ", " SUN ","
                    " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\":"
                    "   {\"type\": \"checkerboard\", \"color0\": %s, \"color1\": 0.8, \"to_uv\": %s}}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "0.2", "[{\"scale\": 1}]");
  snprintf(b, sizeof b, fmt, "0.45", "[3, 0, 0, 0.25, 0, 3, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]");
  reload_case c = {
      .name = "checkerboard color0 and to_uv",
      .before = a,
      .after = b,
      .upd = {{"plate.bsdf.reflectance.color0.value", "0.45"},
              {"plate.bsdf.reflectance.to_uv", "[3, 0, 0, 0.25, 0, 3, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]"}},
      .n_upd = 2,
      .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_constant_radiance(void) {
  const char *fmt =
      "{\"type\": \"scene\", " HDIST_T ","
      " \"sky\": {\"type\": \"constant\", \"radiance\": %s},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "1.0");
  snprintf(b, sizeof b, fmt, "{\"type\": \"rgb\", \"value\": [0.3, 0.6, 1.4]}");
  reload_case c = {.name = "constant radiance",
                   .before = a,
                   .after = b,
                   .upd = {{"sky.radiance.value", "[0.3, 0.6, 1.4]"}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_sampling_weight(void) {
  /* Two suns: the emitter-selection distribution must be rebuilt (the
   * expectation does not change, the samples do). */
  const char *fmt =
      "{\"type\": \"scene\", " PERSP ", " SUN ","
      " \"sun2\": {\"type\": \"directional\", \"direction\": [-0.3, 0.4, -1], \"irradiance\": 0.5,"
      "   \"sampling_weight\": %s},"
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";
  char a[4096], b[4096];
  snprintf(a, sizeof a, fmt, "1");
  snprintf(b, sizeof b, fmt, "5");
  reload_case c = {.name = "directional sampling_weight",
                   .before = a,
                   .after = b,
                   .upd = {{"sun2.sampling_weight", "5"}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

/* Area light over a floor, seen by a perspective camera; `light_xf` is the
 * light's to_world, `radiance` its radiance. */
#define AREA_FMT                                                                                             \
  "{\"type\": \"scene\", " PERSP ","                                                                         \
  " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 2}],"                                    \
  "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}},"                                             \
  " \"light\": {\"type\": \"rectangle\", \"to_world\": %s,"                                                  \
  "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0},"                                                \
  "   \"emitter\": {\"type\": \"area\", \"radiance\": %s}}}"

static void test_area_radiance(void) {
  const char *xf =
      "[{\"scale\": 0.3}, {\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}}, {\"translate\": [0, 0, 1]}]";
  char a[4096], b[4096];
  snprintf(a, sizeof a, AREA_FMT, xf, "5");
  snprintf(b, sizeof b, AREA_FMT, xf, "{\"type\": \"rgb\", \"value\": [9, 4, 2]}");
  reload_case c = {.name = "area radiance",
                   .before = a,
                   .after = b,
                   .upd = {{"light.emitter.radiance.value", "[9, 4, 2]"}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_area_light_to_world(void) {
  /* Moving and resizing an emitting shape: its area (hence the emitted
   * power sampled by next-event estimation) must be refreshed. */
  xform sc = xf_scale(v3(0.6, 0.2, 1)), rx = xf_rotate(v3(1, 0, 0), 160),
        tr = xf_translate(v3(0.3, -0.2, 0.8));
  xform t1 = xf_mul(&rx, &sc);
  xform t = xf_mul(&tr, &t1);
  char m[1024], a[4096], b[4096];
  xform_json(&t, false, m, sizeof m);
  snprintf(
      a, sizeof a, AREA_FMT,
      "[{\"scale\": 0.3}, {\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}}, {\"translate\": [0, 0, 1]}]",
      "5");
  snprintf(b, sizeof b, AREA_FMT, m, "5");
  reload_case c = {.name = "area light to_world",
                   .before = a,
                   .after = b,
                   .upd = {{"light.to_world", m}},
                   .n_upd = 1,
                   .classes = UPDATE_GEOMETRIC};
  run_case(&c);
}

static void test_sphere_to_world(void) {
  /* A sphere over a ground plate: a similarity (rotation, uniform scale,
   * translation) is legal for a sphere. */
  xform sc = xf_scale(v3(0.7, 0.7, 0.7)), rz = xf_rotate(v3(0, 0, 1), 40),
        tr = xf_translate(v3(-0.3, 0.4, 0.9));
  xform t1 = xf_mul(&rz, &sc);
  xform t = xf_mul(&tr, &t1);
  char m[1024], a[4096], b[4096];
  xform_json(&t, false, m, sizeof m);
  const char *fmt = "{\"type\": \"scene\", " PERSP ", " SUN ","
                    " \"ground\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 2}],"
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.4}},"
                    " \"ball\": {\"type\": \"sphere\", \"to_world\": %s,"
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.8}}}";
  snprintf(a, sizeof a, fmt, "[{\"scale\": 0.5}, {\"translate\": [0, 0, 0.5]}]");
  snprintf(b, sizeof b, fmt, m);
  reload_case c = {.name = "sphere to_world",
                   .before = a,
                   .after = b,
                   .upd = {{"ball.to_world", m}},
                   .n_upd = 1,
                   .classes = UPDATE_GEOMETRIC};
  run_case(&c);
}

/* ---- geometric cases ------------------------------------------------------------ */

static void test_rectangle_to_world(void) {
  /* A tilted, moved plate over a ground plate, seen by a perspective
   * camera: shading, shadows and visibility all change. */
  xform rot = xf_rotate(v3(1, 1, 0), 30), tr = xf_translate(v3(0.2, 0.1, 0.4));
  xform t = xf_mul(&tr, &rot);
  char m[1024], a[4096], b[4096];
  xform_json(&t, false, m, sizeof m);
  const char *fmt =
      "{\"type\": \"scene\", " PERSP ", " SUN ","
      " \"ground\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 3}, {\"translate\": [0, 0, -0.5]}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.4}},"
      " \"plate\": {\"type\": \"rectangle\", \"to_world\": %s,"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.8}}}";
  snprintf(a, sizeof a, fmt, "[{\"scale\": 0.5}]");
  snprintf(b, sizeof b, fmt, m);
  char mn[1024];
  xform_json(&t, true, mn, sizeof mn);
  reload_case c = {.name = "rectangle to_world",
                   .before = a,
                   .after = b,
                   .upd = {{"plate.to_world", mn}},
                   .n_upd = 1,
                   .classes = UPDATE_GEOMETRIC};
  run_case(&c);
}

static void test_rectangle_far_hdistant_no_target(void) {
  /* hdistant without target depends on the scene's bounding sphere, which
   * an update must recompute as a reload does. */
  xform rot = xf_rotate(v3(0, 0, 1), 30), tr = xf_translate(v3(7, -3, 2));
  xform t = xf_mul(&tr, &rot);
  char m[1024], a[4096], b[4096];
  xform_json(&t, false, m, sizeof m);
  const char *fmt = "{\"type\": \"scene\", " HDIST_NT ", " SUN ","
                    " \"plate\": {\"type\": \"rectangle\", \"to_world\": %s,"
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";
  snprintf(a, sizeof a, fmt, "[{\"scale\": 1}]");
  snprintf(b, sizeof b, fmt, m);
  reload_case c = {.name = "rectangle moved far, hdistant without target",
                   .before = a,
                   .after = b,
                   .upd = {{"plate.to_world", m}},
                   .n_upd = 1,
                   .classes = UPDATE_GEOMETRIC};
  run_case(&c);
}

/* A 3x3-vertex ascii PLY grid over [-1,1]^2 (8 triangles), without normals
 * or texture coordinates; z of the centre vertex is `zc` and of the corner
 * (1,1) is `zk`; each cell is split along one diagonal or the other. Values are multiples of 1/8 so the file's text and the
 * update's doubles give the same floats. */
static bool write_grid_ply(const char *path, double zc, double zk, bool flip_diagonals, double out_pos[27]) {
  FILE *f = fopen(path, "w");
  if (!f) return false;
  fprintf(f, "ply\nformat ascii 1.0\nelement vertex 9\nproperty float x\nproperty float y\nproperty float z\n"
             "element face 8\nproperty list uchar int vertex_indices\nend_header\n");
  int k = 0;
  for (int j = 0; j < 3; j++)
    for (int i = 0; i < 3; i++) {
      double x = i - 1.0, y = j - 1.0, z = 0;
      if (i == 1 && j == 1) z = zc;
      if (i == 2 && j == 2) z = zk;
      fprintf(f, "%.17g %.17g %.17g\n", x, y, z);
      out_pos[k++] = x, out_pos[k++] = y, out_pos[k++] = z;
    }
  for (int j = 0; j < 2; j++)
    for (int i = 0; i < 2; i++) {
      int v0 = j * 3 + i;
      if (flip_diagonals)
        fprintf(f, "3 %d %d %d\n3 %d %d %d\n", v0, v0 + 1, v0 + 3, v0 + 1, v0 + 4, v0 + 3);
      else
        fprintf(f, "3 %d %d %d\n3 %d %d %d\n", v0, v0 + 1, v0 + 4, v0, v0 + 4, v0 + 3);
    }
  return fclose(f) == 0;
}

static void test_ply_vertex_positions(void) {
  char pa[256], pb[256];
  snprintf(pa, sizeof pa, "/tmp/rsw_ptest_%ld_a.ply", (long)getpid());
  snprintf(pb, sizeof pb, "/tmp/rsw_ptest_%ld_b.ply", (long)getpid());
  double pos_a[27], pos_b[27];
  REQUIRE(write_grid_ply(pa, 0, 0, false, pos_a), "write %s", pa);
  REQUIRE(write_grid_ply(pb, 0.625, -0.375, false, pos_b), "write %s", pb);
  const char *fmt = "{\"type\": \"scene\", " PERSP ", " SUN ","
                    " \"m\": {\"type\": \"ply\", \"filename\": \"%s\","
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}}}";
  char a[4096], b[4096], v[2048];
  snprintf(a, sizeof a, fmt, pa);
  snprintf(b, sizeof b, fmt, pb);
  size_t n = (size_t)snprintf(v, sizeof v, "[");
  for (int i = 0; i < 27; i++) n += (size_t)snprintf(v + n, sizeof v - n, "%s%.17g", i ? ", " : "", pos_b[i]);
  snprintf(v + n, sizeof v - n, "]");
  /* Bitwise first: the refit of that mesh's BVH should find the same
   * closest hits as a fresh build (issue 3 allows 1e-6 relative if a refit
   * broke a tie differently; no tie arises here, so none is allowed). */
  reload_case c = {.name = "ply vertex_positions",
                   .before = a,
                   .after = b,
                   .upd = {{"m.vertex_positions", v}},
                   .n_upd = 1,
                   .classes = UPDATE_GEOMETRIC};
  run_case(&c);
  unlink(pa);
  unlink(pb);
}

/* The same grid as an area light above a floor (flipped to face it): its
 * world triangles, precomputed by the area emitter for sampling, must
 * follow the new vertices (and then its transform). */
static void test_emitting_ply_vertex_positions(void) {
  char pa[256], pb[256];
  snprintf(pa, sizeof pa, "/tmp/rsw_etest_%ld_a.ply", (long)getpid());
  snprintf(pb, sizeof pb, "/tmp/rsw_etest_%ld_b.ply", (long)getpid());
  double pos_a[27], pos_b[27];
  REQUIRE(write_grid_ply(pa, 0, 0, false, pos_a), "write %s", pa);
  REQUIRE(write_grid_ply(pb, 0.625, -0.375, false, pos_b), "write %s", pb);
  const char *fmt = "{\"type\": \"scene\", " PERSP ","
                    " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 2}],"
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}},"
                    " \"m\": {\"type\": \"ply\", \"filename\": \"%s\", \"flip_normals\": true,"
                    "   \"to_world\": [{\"scale\": 0.4}, {\"translate\": [0, 0, %s]}],"
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0},"
                    "   \"emitter\": {\"type\": \"area\", \"radiance\": 3}}}";
  char a[4096], b[4096], v[2048];
  snprintf(a, sizeof a, fmt, pa, "1");
  snprintf(b, sizeof b, fmt, pb, "1");
  size_t n = (size_t)snprintf(v, sizeof v, "[");
  for (int i = 0; i < 27; i++) n += (size_t)snprintf(v + n, sizeof v - n, "%s%.17g", i ? ", " : "", pos_b[i]);
  snprintf(v + n, sizeof v - n, "]");
  reload_case c = {.name = "emitting ply vertex_positions",
                   .before = a,
                   .after = b,
                   .upd = {{"m.vertex_positions", v}},
                   .n_upd = 1,
                   .classes = UPDATE_GEOMETRIC};
  run_case(&c);
  /* The transform of the same emitting mesh. */
  xform t = xf_scale(v3(0.5, 0.3, 0.4));
  xform tr = xf_translate(v3(0.1, 0, 1.2));
  t = xf_mul(&tr, &t);
  char m[1024], b2[4096];
  xform_json(&t, false, m, sizeof m);
  const char *fmt2 = "{\"type\": \"scene\", " PERSP ","
                     " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": 2}],"
                     "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}},"
                     " \"m\": {\"type\": \"ply\", \"filename\": \"%s\", \"flip_normals\": true,"
                     "   \"to_world\": %s,"
                     "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0},"
                     "   \"emitter\": {\"type\": \"area\", \"radiance\": 3}}}";
  snprintf(b2, sizeof b2, fmt2, pa, m);
  reload_case c2 = {.name = "emitting ply to_world",
                    .before = a,
                    .after = b2,
                    .upd = {{"m.to_world", m}},
                    .n_upd = 1,
                    .classes = UPDATE_GEOMETRIC};
  run_case(&c2);
  unlink(pa);
  unlink(pb);
}

static void test_ply_faces(void) {
  /* Same vertices (a non-planar grid), the other diagonal in every cell:
   * a topology change (that mesh's BVH rebuilt). */
  char pa[256], pb[256];
  snprintf(pa, sizeof pa, "/tmp/rsw_ptest_%ld_c.ply", (long)getpid());
  snprintf(pb, sizeof pb, "/tmp/rsw_ptest_%ld_d.ply", (long)getpid());
  double pos[27];
  REQUIRE(write_grid_ply(pa, 0.75, -0.5, false, pos), "write %s", pa);
  REQUIRE(write_grid_ply(pb, 0.75, -0.5, true, pos), "write %s", pb);
  const char *fmt = "{\"type\": \"scene\", " PERSP ", " SUN ","
                    " \"m\": {\"type\": \"ply\", \"filename\": \"%s\","
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}}}";
  char a[4096], b[4096], v[1024];
  snprintf(a, sizeof a, fmt, pa);
  snprintf(b, sizeof b, fmt, pb);
  size_t n = (size_t)snprintf(v, sizeof v, "[");
  for (int j = 0; j < 2; j++)
    for (int i = 0; i < 2; i++) {
      int v0 = j * 3 + i;
      n += (size_t)snprintf(v + n, sizeof v - n, "%s%d, %d, %d, %d, %d, %d", (i || j) ? ", " : "", v0, v0 + 1,
                            v0 + 3, v0 + 1, v0 + 4, v0 + 3);
    }
  snprintf(v + n, sizeof v - n, "]");
  reload_case c = {.name = "ply faces",
                   .before = a,
                   .after = b,
                   .upd = {{"m.faces", v}},
                   .n_upd = 1,
                   .classes = UPDATE_GEOMETRIC};
  run_case(&c);
  unlink(pa);
  unlink(pb);
}

static void test_ply_to_world(void) {
  char pa[256];
  snprintf(pa, sizeof pa, "/tmp/rsw_ptest_%ld_e.ply", (long)getpid());
  double pos[27];
  REQUIRE(write_grid_ply(pa, 0.75, -0.5, false, pos), "write %s", pa);
  xform rz = xf_rotate(v3(0, 0, 1), 25), tr = xf_translate(v3(0.2, 0.3, -0.1));
  xform t = xf_mul(&tr, &rz);
  char m[1024], a[4096], b[4096];
  xform_json(&t, false, m, sizeof m);
  const char *fmt = "{\"type\": \"scene\", " PERSP ", " SUN ","
                    " \"m\": {\"type\": \"ply\", \"filename\": \"%s\", \"to_world\": %s,"
                    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}}}";
  snprintf(a, sizeof a, fmt, pa, "[{\"scale\": 1}]");
  snprintf(b, sizeof b, fmt, pa, m);
  reload_case c = {.name = "ply to_world",
                   .before = a,
                   .after = b,
                   .upd = {{"m.to_world", m}},
                   .n_upd = 1,
                   .classes = UPDATE_GEOMETRIC};
  run_case(&c);
  unlink(pa);
}

static void test_hdistant_direction_rotated(void) {
  /* As above from a to_world rotated about z: the new local +x is the old
   * one projected orthogonally to the new axis (up = cross(d, x_old)). */
  xform rz = xf_rotate(v3(0, 0, 1), 30);
  char m[1024], a[4096], b[4096];
  xform_json(&rz, false, m, sizeof m);
  vec3 d = v3_norm(v3(-0.4, 0.25, 1));
  vec3 x_old = v3_norm(xf_vector(&rz, v3(1, 0, 0)));
  vec3 up = v3_norm(v3_cross(d, x_old));
  snprintf(a, sizeof a,
           "{\"type\": \"scene\", \"cam\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\"},"
           "   \"to_world\": %s, " SAMPLER ", " FILM16 "}, " SUN ","
           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": 0.3}}}",
           m);
  snprintf(b, sizeof b,
           "{\"type\": \"scene\", \"cam\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\"},"
           "   \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 0], \"target\": [%.17g, %.17g, %.17g],"
           "   \"up\": [%.17g, %.17g, %.17g]}}], " SAMPLER ", " FILM16 "}, " SUN ","
           " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"roughconductor\", \"alpha\": 0.3}}}",
           d.x, d.y, d.z, up.x, up.y, up.z);
  char v[256];
  snprintf(v, sizeof v, "[%.17g, %.17g, %.17g]", d.x, d.y, d.z);
  reload_case c = {.name = "hdistant direction from a rotated to_world",
                   .before = a,
                   .after = b,
                   .upd = {{"cam.direction", v}},
                   .n_upd = 1,
                   .classes = UPDATE_SPECTRAL};
  run_case(&c);
}

static void test_distant_ray_offset_refresh(void) {
  /* distant with a point target puts its origins 2R back along the ray,
   * R the scene's bounding radius, resolved at load. Moving `blocker` from
   * below the plate to high above the target changes R; with the load-time
   * R the origins would start below the blocker and see the plate, with
   * the refreshed one (as a reload) they start above it and see it. */
  const char *fmt =
      "{\"type\": \"scene\", \"cam\": {\"type\": \"distant\", \"direction\": [0, 0, -1],"
      "   \"target\": [0.3, 0.3, 0], \"sampler\": {\"type\": \"independent\", \"sample_count\": 4},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " " SUN ","
      " \"plate\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}},"
      " \"blocker\": {\"type\": \"rectangle\", \"to_world\": %s,"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.9}}}";
  xform sc = xf_scale(v3(0.2, 0.2, 1)), tr = xf_translate(v3(0.3, 0.3, 4));
  xform t = xf_mul(&tr, &sc);
  char m[1024], a[4096], b[4096];
  xform_json(&t, false, m, sizeof m);
  snprintf(a, sizeof a, fmt, "[{\"translate\": [0, 0, -2]}]");
  snprintf(b, sizeof b, fmt, m);
  reload_case c = {.name = "distant ray_offset after a geometric update",
                   .before = a,
                   .after = b,
                   .upd = {{"blocker.to_world", m}},
                   .n_upd = 1,
                   .classes = UPDATE_GEOMETRIC};
  run_case(&c);
}

int main(void) {
  RSW_TEST_RUN(test_diffuse_number);
  RSW_TEST_RUN(test_diffuse_rgb);
  RSW_TEST_RUN(test_twosided_shared_brdf);
  RSW_TEST_RUN(test_directional_irradiance);
  RSW_TEST_RUN(test_roughconductor_alpha);
  RSW_TEST_RUN(test_roughconductor_eta_k);
  RSW_TEST_RUN(test_mono_tabulated_reflectance);
  RSW_TEST_RUN(test_checkerboard_color_and_to_uv);
  RSW_TEST_RUN(test_constant_radiance);
  RSW_TEST_RUN(test_area_radiance);
  RSW_TEST_RUN(test_sampling_weight);
  RSW_TEST_RUN(test_directional_direction);
  RSW_TEST_RUN(test_directional_to_world);
  RSW_TEST_RUN(test_hdistant_direction);
  RSW_TEST_RUN(test_hdistant_direction_rotated);
  RSW_TEST_RUN(test_distant_direction);
  RSW_TEST_RUN(test_distant_ray_offset_refresh);
  RSW_TEST_RUN(test_perspective_to_world);
  RSW_TEST_RUN(test_rectangle_to_world);
  RSW_TEST_RUN(test_rectangle_far_hdistant_no_target);
  RSW_TEST_RUN(test_ply_vertex_positions);
  RSW_TEST_RUN(test_emitting_ply_vertex_positions);
  RSW_TEST_RUN(test_ply_faces);
  RSW_TEST_RUN(test_ply_to_world);
  RSW_TEST_RUN(test_sphere_to_world);
  RSW_TEST_RUN(test_area_light_to_world);
  RSW_TEST_END("test_update_reload");
}
