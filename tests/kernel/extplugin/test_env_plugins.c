/* The SDK's example environment plugins (tests/plugins/, built by `make`
 * into BUILD/plugins/ against include/raysweep/plugin.h only), loaded with
 * plugins_load_dir() and rendered through the kernel (issue 7, Tests):
 *
 *  - "test" (two_hemispheres.c), mono: a grey Lambertian sphere seen from
 *    +y is lit on its x > 0 side at 600 nm and on its x < 0 side at 450 nm;
 *  - chi-square of each plugin's sample() against its pdf(), through the
 *    adapter emitter (so the host's checks are on the path);
 *  - furnace: "sunsky" with sun = 0 (a constant sky) renders the same film
 *    as the built-in `constant` within 3 sigma;
 *  - a "sunsky" parameter is in the parameter table (class spectral) and an
 *    update equals a reload, bitwise.
 * Bad plugins (ABI, symbols, duplicates, NaN) are test_env_plugin_loader's.
 *
 * The plugin directory is found from this executable's own path:
 * BUILD/tests/test_env_plugins -> BUILD/plugins (RSW_PLUGIN_DIR overrides). */
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../server/kernel/extplugin/env_plugin.h"
#include "../../../server/kernel/scene/param_table.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../support/chi2.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define PI            3.14159265358979323846
#define HEMI_RADIANCE 5.108 /* two_hemispheres.c's RADIANCE */

/* ---- helpers ----------------------------------------------------------------- */

static bool render_at(scene *s, uint32_t spp, uint64_t seed, double wavelength, film_image *out) {
  rsw_err err = {0};
  render_opts o = {.size = sizeof o, .spp = spp, .seed = seed, .threads = 2, .wavelength = wavelength};
  if (render_sensor(s, &o, out, NULL, &err)) {
    char buf[1200];
    printf("  render failed: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  return true;
}

/* No plugin failure (NaN, bad pdf) may have been caught during a render. */
static void check_no_failures(const scene *s, const char *what) {
  char msg[600];
  size_t n = emitter_failures(s, 0, msg, sizeof msg);
  CHECK(n == 0, "%s: %zu plugin failures, first: %s", what, n, msg);
}

/* ---- two hemispheres ------------------------------------------------------------ */

/* Camera at (0, D, 0) looking at the origin with up +z. look_at gives
 * local +x = left = normalize(cross(up, dir)) = cross(+z, -y) = +x: the
 * camera's left is world +x, and Mitsuba's perspective camera puts local
 * +x on the LEFT of the image (film x grows towards -left). So image
 * columns left of the centre show world x > 0. */
#define CAM_D 4.0
#define FOV   40.0
#define RES   32

static const char *hemi_scene =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"cam\": {\"type\": \"perspective\", \"fov\": 40, \"fov_axis\": \"x\","
    "   \"to_world\": [{\"lookat\": {\"origin\": [0, 4, 0], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 64},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 32, \"height\": 32, \"rfilter\": {\"type\": \"box\"}}},"
    " \"integrator\": {\"type\": \"path\"},"
    " \"env\": {\"type\": \"test\"},"
    " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}}";

/* Per-half statistics of one render at `wavelength`; lit_sign = +1 when
 * the x > 0 hemisphere emits (above 500 nm), -1 when x < 0 does.
 *
 * Expected values, per pixel centre ray d (camera space -> world):
 *  - background (the ray escapes): the plugin's radiance along d, i.e. L
 *    where sign(d_x) = lit_sign, else exactly 0;
 *  - the sphere (convex, so only direct light): a Lambertian point with
 *    normal n and reflectance rho lit by radiance L from the half space
 *    s d_x > 0 reflects
 *        L_o = rho/pi * L * int_{d.n>0, s d_x>0} (d.n) dw
 *            = rho L (1 + s n_x) / 2
 *    (the sky-view factor of a plane tilted by acos(s n_x) from the lit
 *    pole). So the dark side is black only at n_x = -s (the silhouette
 *    seen from +y); on the visible dark half it falls from rho L / 2 at
 *    the centre towards 0 at the limb. Checked: the per-half mean of the
 *    residual pixel - expected is within 3 sigma (+ 1% for the pixel
 *    footprint), and the lit half is brighter than the dark half. */
static void hemi_case(double wavelength, int lit_sign) {
  scene *s = tsup_load(hemi_scene, NULL);
  REQUIRE(s, "load the two-hemisphere scene");
  film_image img = {0};
  bool ok = render_at(s, 0, 11, wavelength, &img);
  CHECK(ok, "render at %g nm", wavelength);
  if (!ok) {
    scene_free(s);
    return;
  }
  check_no_failures(s, "two hemispheres");
  const double rho = 0.5, L = HEMI_RADIANCE;
  double tan_half = tan(FOV * 0.5 * PI / 180.0);
  /* [side][0 background, 1 sphere]: side 0 = world x > 0, 1 = x < 0. */
  double sum[2][2] = {{0}}, sum2[2][2] = {{0}}, vmax[2][2] = {{0}};
  double resid[2] = {0}, resid2[2] = {0}, expect_sum[2] = {0};
  int cnt[2][2] = {{0}};
  for (int y = 0; y < RES; y++) {
    for (int x = 0; x < RES; x++) {
      /* Pixel centre in camera space: +x left, +y up, +z forward. */
      double cx = -(2.0 * (x + 0.5) / RES - 1.0) * tan_half;
      double cy = (1.0 - 2.0 * (y + 0.5) / RES) * tan_half;
      /* World: left = +x, up = +z, forward = -y. */
      double dx = cx, dy = -1.0, dz = cy;
      double dl = sqrt(dx * dx + dy * dy + dz * dz);
      dx /= dl, dy /= dl, dz /= dl;
      /* Nearest approach of the ray to the origin decides sphere vs
       * background; pixels near the silhouette or straddling x = 0 are
       * skipped (their footprint mixes the cases). */
      double ox = 0, oy = CAM_D, oz = 0;
      double tc = -(ox * dx + oy * dy + oz * dz);
      double px = ox + tc * dx, py = oy + tc * dy, pz = oz + tc * dz;
      double b = sqrt(px * px + py * py + pz * pz);
      double pix_half = 2.0 * tan_half / RES * CAM_D; /* pixel size at the origin */
      int kind;
      if (b < 1.0 - 2 * pix_half)
        kind = 1;
      else if (b > 1.0 + 2 * pix_half)
        kind = 0;
      else
        continue;
      double v = img.data[(size_t)(y * RES + x) * img.channels];
      if (kind == 0) {
        if (fabs(dx) < 0.05) continue; /* escape directions near x = 0 */
        int side = dx > 0 ? 0 : 1;
        sum[side][0] += v, sum2[side][0] += v * v, cnt[side][0]++;
        vmax[side][0] = fmax(vmax[side][0], fabs(v - ((dx > 0) == (lit_sign > 0) ? L : 0)));
        continue;
      }
      double t = tc - sqrt(1.0 - b * b); /* first hit: the normal is the point */
      double nx = ox + t * dx;
      if (fabs(nx) < 2 * pix_half) continue;
      int side = nx > 0 ? 0 : 1;
      double e = rho * L * (1 + lit_sign * nx) / 2;
      sum[side][1] += v, sum2[side][1] += v * v, cnt[side][1]++;
      resid[side] += v - e, resid2[side] += (v - e) * (v - e), expect_sum[side] += e;
    }
  }
  int lit = lit_sign > 0 ? 0 : 1, dark = 1 - lit;
  REQUIRE(cnt[0][0] > 20 && cnt[1][0] > 20 && cnt[0][1] > 50 && cnt[1][1] > 50, "pixel counts %d %d %d %d",
          cnt[0][0], cnt[1][0], cnt[0][1], cnt[1][1]);
  /* Background: exact (an escaped camera ray sees the plugin directly). */
  CHECK(sum[dark][0] / cnt[dark][0] < 1e-6, "%g nm: dark background mean %g (expected 0)", wavelength,
        sum[dark][0] / cnt[dark][0]);
  CHECK(vmax[dark][0] < 1e-6, "%g nm: dark background max %g", wavelength, vmax[dark][0]);
  CHECK(vmax[lit][0] < 1e-5 * L, "%g nm: lit background off L by up to %g", wavelength, vmax[lit][0]);
  /* Sphere halves against the closed form. */
  const char *names[2] = {"x>0", "x<0"};
  for (int h = 0; h < 2; h++) {
    int n = cnt[h][1];
    double mean_r = resid[h] / n;
    double var = (resid2[h] - resid[h] * resid[h] / n) / (n - 1);
    double sem = sqrt(fmax(var, 0) / n);
    double expect_mean = expect_sum[h] / n;
    CHECK(fabs(mean_r) <= 3 * sem + 0.01 * expect_mean,
          "%g nm: sphere %s half mean %.6g vs expected %.6g (3 sigma %.3g)", wavelength, names[h],
          sum[h][1] / n, expect_mean, 3 * sem);
  }
  double lit_mean = sum[lit][1] / cnt[lit][1], dark_mean = sum[dark][1] / cnt[dark][1];
  double lit_sem = sqrt(fmax(sum2[lit][1] / cnt[lit][1] - lit_mean * lit_mean, 0) / cnt[lit][1]);
  double dark_sem = sqrt(fmax(sum2[dark][1] / cnt[dark][1] - dark_mean * dark_mean, 0) / cnt[dark][1]);
  CHECK(lit_mean - dark_mean > 3 * sqrt(lit_sem * lit_sem + dark_sem * dark_sem) && lit_mean > 2 * dark_mean,
        "%g nm: lit half %.5g is not clearly brighter than the dark half %.5g", wavelength, lit_mean,
        dark_mean);
  film_image_free(&img);
  scene_free(s);
}

static void test_two_hemispheres_600nm(void) {
  hemi_case(600.0, +1);
}
static void test_two_hemispheres_450nm(void) {
  hemi_case(450.0, -1);
}

/* At exactly 500 nm neither hemisphere emits: the film is black. */
static void test_two_hemispheres_500nm_black(void) {
  scene *s = tsup_load(hemi_scene, NULL);
  REQUIRE(s, "load");
  film_image img = {0};
  if (render_at(s, 4, 3, 500.0, &img)) {
    double m, sem;
    tsup_stats(&img, 0, &m, &sem);
    CHECK(m == 0, "mean at 500 nm is %g", m);
    film_image_free(&img);
  } else {
    CHECK(false, "render at 500 nm");
  }
  scene_free(s);
}

/* ---- chi-square of sample() against pdf() ----------------------------------------- */

typedef struct env_user {
  const emitter *e;
  surface_interaction ref;
} env_user;

static bool env_sample(void *user, const double *u, vec3 *out, double *weight) {
  env_user *eu = user;
  direction_sample ds;
  eu->e->ops->sample_direction(eu->e, &eu->ref, v2(u[0], u[1]), &ds);
  if (!(ds.pdf > 0)) return false;
  *out = ds.d;
  *weight = 1.0;
  return true;
}

static double env_pdf(void *user, vec3 d) {
  env_user *eu = user;
  direction_sample ds = {.d = d, .dist = INFINITY};
  return eu->e->ops->pdf_direction(eu->e, &eu->ref, &ds);
}

#define N_CHI2 3

static void chi2_case(const char *emitter_json, const char *name) {
  char sc[1024];
  snprintf(sc, sizeof sc, "{\"type\": \"scene\", \"variant\": \"mono\", \"env\": %s}", emitter_json);
  scene *s = tsup_load(sc, NULL);
  REQUIRE(s, "%s: load", name);
  REQUIRE(s->environment, "%s: no environment emitter", name);
  rsw_err err = {0};
  render_ctx rc = {.variant = VARIANT_MONO, .wavelength = 550.0};
  REQUIRE(scene_prepare(s, &rc, &err) == RSW_OK, "%s: prepare", name);
  env_user eu = {.e = s->environment};
  chi2_config cfg = chi2_defaults(CHI2_SPHERE, 2);
  cfg.test_count = N_CHI2;
  /* The default sun lobe (n = 100) puts most of its mass in the top row of
   * cells, where Mitsuba's 4-point rule misintegrates cos^100 by ~4%
   * (test_warp.c's cosine-power case): 16 points per axis. */
  cfg.ires = 16;
  chi2_result r = chi2_run(&cfg, env_sample, env_pdf, &eu);
  CHECK(r.passed, "%s: chi-square failed (p = %g, chi2 = %g, dof %d): %s", name, r.p_value, r.chi2, r.dof,
        r.reason);
  check_no_failures(s, name);
  scene_free(s);
}

static void test_chi2_two_hemispheres(void) {
  chi2_case("{\"type\": \"test\"}", "test");
}
static void test_chi2_sunsky_defaults(void) {
  chi2_case("{\"type\": \"sunsky\"}", "sunsky defaults");
}
static void test_chi2_sunsky_tilted(void) {
  chi2_case("{\"type\": \"sunsky\", \"sun\": 3, \"sky\": 0.2, \"sharpness\": 8,"
            " \"sun_direction\": [0.3, -0.5, 0.6]}",
            "sunsky tilted");
}

/* The mixture pdf integrates to 1 over the sphere (midpoint rule in
 * (phi, cos theta); the lobe has sharpness 8 so the grid resolves it). */
static void test_sunsky_pdf_normalised(void) {
  scene *s = tsup_load("{\"type\": \"scene\", \"variant\": \"mono\", \"env\": {\"type\": \"sunsky\","
                       " \"sharpness\": 8, \"sun_direction\": [1, 1, 0]}}",
                       NULL);
  REQUIRE(s && s->environment, "load");
  env_user eu = {.e = s->environment};
  const int nphi = 400, nz = 400;
  double sum = 0;
  for (int i = 0; i < nphi; i++) {
    for (int j = 0; j < nz; j++) {
      double phi = 2 * PI * (i + 0.5) / nphi, z = -1 + 2.0 * (j + 0.5) / nz, r = sqrt(1 - z * z);
      sum += env_pdf(&eu, v3(r * cos(phi), r * sin(phi), z));
    }
  }
  double integral = sum * (2 * PI / nphi) * (2.0 / nz);
  CHECK_REL(integral, 1.0, 2e-3);
  scene_free(s);
}

/* ---- furnace: a constant plugin equals `constant` ------------------------------------ */

static void test_furnace_constant_plugin(void) {
  const char *fmt =
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"cam\": {\"type\": \"perspective\", \"fov\": 30,"
      "   \"to_world\": [{\"lookat\": {\"origin\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 16},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16, \"rfilter\": {\"type\": "
      "\"box\"}}},"
      " \"integrator\": {\"type\": \"path\", \"rr_depth\": 5},"
      " \"env\": %s,"
      " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.5}},"
      " \"floor\": {\"type\": \"rectangle\", \"to_world\": [{\"translate\": [0, 0, -1.2]}, {\"scale\": 3}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.7}}}";
  char a[2048], b[2048];
  snprintf(a, sizeof a, fmt, "{\"type\": \"sunsky\", \"sky\": 2.5, \"sun\": 0}");
  snprintf(b, sizeof b, fmt, "{\"type\": \"constant\", \"radiance\": 2.5}");
  scene *sa = tsup_load(a, NULL), *sb = tsup_load(b, NULL);
  CHECK(sa && sb, "load");
  film_image ia = {0}, ib = {0};
  if (sa && sb && render_at(sa, 0, 5, 550, &ia) && render_at(sb, 0, 6, 550, &ib)) {
    double ma, sa_, mb, sb_;
    tsup_stats(&ia, 0, &ma, &sa_);
    tsup_stats(&ib, 0, &mb, &sb_);
    double tol = 3 * sqrt(sa_ * sa_ + sb_ * sb_);
    CHECK(fabs(ma - mb) <= tol + 1e-12, "plugin mean %.6g vs constant %.6g (3 sigma %.3g)", ma, mb, tol);
    CHECK(ma > 0.5 && ma < 2.5, "plugin mean %g outside (0.5, 2.5)", ma);
    check_no_failures(sa, "furnace");
    film_image_free(&ia);
    film_image_free(&ib);
  } else {
    CHECK(false, "render");
  }
  scene_free(sa);
  scene_free(sb);
}

/* ---- parameters: in the table, and an update equals a reload ------------------------- */

#define SUNSKY_SCENE(PARAMS)                                                                                 \
  "{\"type\": \"scene\", \"variant\": \"mono\","                                                             \
  " \"cam\": {\"type\": \"perspective\", \"fov\": 45,"                                                       \
  "   \"to_world\": [{\"lookat\": {\"origin\": [0, -4, 1], \"target\": [0, 0, 0], \"up\": [0, 0, 1]}}],"     \
  "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 8},"                                        \
  "   \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16, \"rfilter\": {\"type\": \"box\"}}},"  \
  " \"integrator\": {\"type\": \"path\", \"max_depth\": 3},"                                                 \
  " \"sky\": {\"type\": \"sunsky\"" PARAMS "},"                                                              \
  " \"ball\": {\"type\": \"sphere\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.6}}}"

static void test_sunsky_params_in_table(void) {
  scene *s = tsup_load(SUNSKY_SCENE(""), NULL);
  REQUIRE(s, "load");
  const char *keys[] = {"sky.sky", "sky.sun", "sky.sun_direction", "sky.sharpness"};
  const param_type types[] = {PARAM_FLOAT, PARAM_FLOAT, PARAM_VECTOR, PARAM_FLOAT};
  rsw_err err = {0};
  for (int i = 0; i < 4; i++) {
    size_t idx;
    if (params_lookup(s, keys[i], &idx, &err) != RSW_OK) {
      CHECK(false, "%s is not in the parameter table", keys[i]);
      continue;
    }
    param_info info;
    REQUIRE(params_info(s, idx, &info), "info %s", keys[i]);
    CHECK(info.cls == UPDATE_SPECTRAL, "%s has class %s", keys[i], update_class_name(info.cls));
    CHECK(info.type == types[i], "%s has type %s", keys[i], param_type_name(info.type));
    CHECK(strcmp(info.object_type, "sunsky") == 0, "%s belongs to '%s'", keys[i], info.object_type);
  }
  size_t idx;
  if (params_lookup(s, "sky.sharpness", &idx, &err) == RSW_OK) {
    char *v = params_value_json(s, idx, 0);
    CHECK(v && atof(v) == 100.0, "default sharpness reads %s", v ? v : "(null)");
    free(v);
  }
  scene_free(s);
}

static bool apply(scene *s, const char *key, const char *json) {
  param_update u = {.key = key};
  rsw_err err = {0};
  char buf[1200];
  if (param_value_parse(json, key, &u.value, &err)) {
    printf("  parse %s: %s\n", key, rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  update_report rep = {0};
  rsw_status st = scene_update(s, &u, 1, &rep, &err);
  param_value_free(&u.value);
  if (st) printf("  update %s: %s\n", key, rsw_err_format(&err, buf, sizeof buf));
  return st == RSW_OK && rep.classes == UPDATE_SPECTRAL && rep.changed == 1;
}

static bool same_film(const film_image *a, const film_image *b) {
  return a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, sizeof(float) * (size_t)a->width * a->height * a->channels) == 0;
}

/* Render S, update, render; load S' and render: bitwise equal, and
 * different from before the update. */
static void update_case(const char *key, const char *json, const char *after_scene) {
  scene *s = tsup_load(SUNSKY_SCENE(""), NULL);
  REQUIRE(s, "load S");
  film_image pre = {0}, post = {0}, ref = {0};
  bool ok = render_at(s, 0, 77, 600, &pre);
  CHECK(ok, "render S");
  if (ok) {
    ok = apply(s, key, json);
    CHECK(ok, "update %s = %s", key, json);
  }
  if (ok) CHECK(ok = render_at(s, 0, 77, 600, &post), "render S after the update");
  scene *s2 = ok ? tsup_load(after_scene, NULL) : NULL;
  if (ok) CHECK(s2 && (ok = render_at(s2, 0, 77, 600, &ref)), "load and render S'");
  if (ok) {
    CHECK(same_film(&post, &ref), "%s: update differs from reload", key);
    CHECK(!same_film(&pre, &post), "%s: the update changed nothing", key);
    check_no_failures(s, key);
  }
  film_image_free(&pre);
  film_image_free(&post);
  film_image_free(&ref);
  scene_free(s);
  scene_free(s2);
}

static void test_sunsky_update_sun_direction(void) {
  update_case("sky.sun_direction", "[0.5, -0.5, 0.7]", SUNSKY_SCENE(", \"sun_direction\": [0.5, -0.5, 0.7]"));
}
static void test_sunsky_update_sharpness(void) {
  update_case("sky.sharpness", "12", SUNSKY_SCENE(", \"sharpness\": 12"));
}

/* Values the plugin's prepare() refuses (a zero sun direction) or the
 * declared range refuses (negative sharpness) do not reach a film. */
static void test_sunsky_bad_values(void) {
  scene *s = tsup_load(SUNSKY_SCENE(""), NULL);
  REQUIRE(s, "load");
  param_update u = {.key = "sky.sharpness"};
  rsw_err err = {0};
  REQUIRE(param_value_parse("-1", "sharpness", &u.value, &err) == RSW_OK, "parse");
  CHECK(scene_update(s, &u, 1, NULL, &err) != RSW_OK, "negative sharpness accepted");
  param_value_free(&u.value);
  scene_free(s);
  /* At load: a zero direction is refused by create() with a message. */
  rsw_err e2 = {0};
  scene *bad = NULL;
  const char *txt = SUNSKY_SCENE(", \"sun_direction\": [0, 0, 0]");
  scene_load_opts o = {.size = sizeof o};
  CHECK(scene_load_memory(txt, strlen(txt), "bad", false, &o, &bad, &e2) != RSW_OK,
        "zero sun_direction loaded");
  char buf[1200];
  CHECK(strstr(rsw_err_format(&e2, buf, sizeof buf), "sun_direction") != NULL, "message: %s", buf);
  scene_free(bad);
}

/* ---- the docs hold the example verbatim ------------------------------------------------- */

static char *slurp(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  char *buf = NULL;
  if (fseek(f, 0, SEEK_END) == 0) {
    long n = ftell(f);
    if (n >= 0 && n < (1L << 24) && fseek(f, 0, SEEK_SET) == 0 && (buf = malloc((size_t)n + 1))) {
      if (fread(buf, 1, (size_t)n, f) != (size_t)n) {
        free(buf);
        buf = NULL;
      } else {
        buf[n] = 0;
      }
    }
  }
  fclose(f);
  return buf;
}

/* The repository root: RSW_TEST_DIR/.. (set by tests/run.sh), else two
 * levels above this executable (BUILD/tests/<this>). */
static bool repo_root(char *out, size_t len) {
  const char *td = getenv("RSW_TEST_DIR");
  if (td && *td) return snprintf(out, len, "%s/..", td) < (int)len;
  char exe[PATH_MAX];
  ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
  if (n <= 0) return false;
  exe[n] = 0;
  for (int k = 0; k < 3; k++) {
    char *slash = strrchr(exe, '/');
    if (!slash) return false;
    *slash = 0;
  }
  return snprintf(out, len, "%s", exe) < (int)len;
}

/* docs/environment-plugins.md ("Writing an environment plugin") shows
 * tests/plugins/two_hemispheres.c in full, so the documented example is the
 * built and tested one. */
static void test_readme_holds_example(void) {
  char root[PATH_MAX], path[PATH_MAX + 64];
  REQUIRE(repo_root(root, sizeof root), "repository root");
  snprintf(path, sizeof path, "%s/docs/environment-plugins.md", root);
  char *readme = slurp(path);
  snprintf(path, sizeof path, "%s/tests/plugins/two_hemispheres.c", root);
  char *src = slurp(path);
  CHECK(readme && src, "read docs/environment-plugins.md and two_hemispheres.c under %s", root);
  if (readme && src) {
    CHECK(strstr(readme, src) != NULL,
          "docs/environment-plugins.md does not hold tests/plugins/two_hemispheres.c verbatim");
    /* (tests/integration/test_docs_examples.sh runs it, from the repository root.) */
    CHECK(strstr(readme, "cc -shared -fPIC -I include -o plugins/test.so tests/plugins/two_hemispheres.c") !=
              NULL,
          "docs/environment-plugins.md lacks the one-line build command");
  }
  free(readme);
  free(src);
}

/* ---- main ---------------------------------------------------------------------------- */

/* BUILD/tests/<this> -> BUILD/plugins, unless RSW_PLUGIN_DIR says. */
static bool plugin_dir(char *out, size_t len) {
  const char *env = getenv("RSW_PLUGIN_DIR");
  if (env && *env) return snprintf(out, len, "%s", env) < (int)len;
  char exe[PATH_MAX];
  ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
  if (n <= 0) return false;
  exe[n] = 0;
  char *slash = strrchr(exe, '/');
  if (!slash) return false;
  *slash = 0; /* BUILD/tests */
  slash = strrchr(exe, '/');
  if (!slash) return false;
  *slash = 0; /* BUILD */
  return snprintf(out, len, "%s/plugins", exe) < (int)len;
}

int main(void) {
  char dir[PATH_MAX + 16];
  rsw_err err = {0};
  if (!plugin_dir(dir, sizeof dir)) {
    printf("FAIL cannot find the plugin directory\ntest_env_plugins: 0 passed, 1 failed\n");
    return 1;
  }
  if (plugins_load_dir(dir, &err) != RSW_OK) {
    char buf[1200];
    printf("FAIL plugins_load_dir(%s): %s\ntest_env_plugins: 0 passed, 1 failed\n", dir,
           rsw_err_format(&err, buf, sizeof buf));
    return 1;
  }
  RSW_TEST_RUN(test_two_hemispheres_600nm);
  RSW_TEST_RUN(test_two_hemispheres_450nm);
  RSW_TEST_RUN(test_two_hemispheres_500nm_black);
  RSW_TEST_RUN(test_chi2_two_hemispheres);
  RSW_TEST_RUN(test_chi2_sunsky_defaults);
  RSW_TEST_RUN(test_chi2_sunsky_tilted);
  RSW_TEST_RUN(test_sunsky_pdf_normalised);
  RSW_TEST_RUN(test_furnace_constant_plugin);
  RSW_TEST_RUN(test_sunsky_params_in_table);
  RSW_TEST_RUN(test_sunsky_update_sun_direction);
  RSW_TEST_RUN(test_sunsky_update_sharpness);
  RSW_TEST_RUN(test_sunsky_bad_values);
  RSW_TEST_RUN(test_readme_holds_example);
  plugins_unload();
  RSW_TEST_END("test_env_plugins");
}
