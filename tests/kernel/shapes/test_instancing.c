/* Instancing and the periodic lateral boundary (issue 6).
 *
 *  - 1,000 instanced disks (one shapegroup holding one untransformed unit
 *    disk, 1,000 `instance`s) render the same film, bitwise (same seed,
 *    spp, threads), as the same 1,000 disks written out as shapes: the
 *    group's disk has the identity to_world, so Embree transforms the ray
 *    by the same instance matrix and accel.c uses the same callback.
 *  - An `instance`'s to_world update equals a reload, bitwise.
 *  - An instancelist of the same placements renders bitwise like the
 *    `instance`s (rows of 16 numbers hold the same float matrices), and
 *    so do the placements split into three instancelists, whose hits name
 *    each list and the placement within it (accel.c's list_placement).
 *  - instancelist errors name file:line.
 *  - periodic: a plot with the periodic boundary against the plot with 8
 *    explicit copies around it, within 3 sigma, at 0, 15 and 30 degrees
 *    off nadir (distant sensor, target = the central plot). Not bitwise:
 *    the two scenes differ in geometry outside the plot, and paths that
 *    leave the 3x3 copies laterally (grazing) escape there but not in the
 *    periodic scene; the canopy is thin (leaves below z = 1.5 in a 10 m
 *    plot) so that such paths are rare.
 *
 * Films are small (8x8 or 1x1) to keep the binary fast. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../server/kernel/accel.h"
#include "../../../server/kernel/core/rng.h"
#include "../../../server/kernel/core/transform.h"
#include "../../../server/kernel/scene/params.h"
#include "../../../server/kernel/scene/update.h"
#include "../../../server/kernel/shapes/instance.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define SEED    7u
#define THREADS 2
#define NDISK   1000

/* Disk placements: random centres in [-8, 8]^2 x [0.5, 1.5], random
 * upward normals, radius 0.3, as a row-major 4x4 (values rounded to float
 * so that the float copy in an instancelist is the same matrix). */
static void disk_matrices(double (*m)[16], int n) {
  pcg32 g;
  pcg32_seed(&g, 99, 1);
  for (int i = 0; i < n; i++) {
    double x = -8 + 16 * pcg32_next_double(&g), y = -8 + 16 * pcg32_next_double(&g);
    double z = 0.5 + pcg32_next_double(&g);
    vec3 nn = v3_norm(v3(pcg32_next_double(&g) - 0.5, pcg32_next_double(&g) - 0.5, 1.0));
    frame f = frame_from_normal(nn);
    double r = 0.3;
    vec3 c[3] = {f.s, f.t, f.n};
    double *q = m[i];
    for (int k = 0; k < 3; k++) {
      q[0 * 4 + k] = (float)(r * c[k].x);
      q[1 * 4 + k] = (float)(r * c[k].y);
      q[2 * 4 + k] = (float)(r * c[k].z);
    }
    q[3] = (float)x, q[7] = (float)y, q[11] = (float)z;
    q[12] = q[13] = q[14] = 0, q[15] = 1;
  }
}

static void sb_matrix(sbuf *b, const double *q) {
  sb_printf(b, "[{\"matrix\": [");
  for (int k = 0; k < 16; k++) sb_printf(b, "%s%.9g", k ? ", " : "", q[k]);
  sb_printf(b, "]}]");
}

#define HEAD                                                                                                 \
  "{\"type\": \"scene\", \"variant\": \"mono\",\n"                                                           \
  "\"cam\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [8, "  \
  "8, 1]}]}, "                                                                                               \
  "\"sampler\": {\"type\": \"independent\", \"sample_count\": 8}, "                                          \
  "\"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"box\"}}},\n"     \
  "\"sun\": {\"type\": \"directional\", \"direction\": [0.3, 0.2, -0.9], \"irradiance\": 1.0},\n"            \
  "\"soil\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}], "                           \
  "\"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.2}}"

#define LEAF_BSDF "{\"type\": \"diffuse\", \"reflectance\": 0.45}"

/* The placements [lo, hi) of m as an instancelist file at path (rows of
 * 16 numbers). */
static void write_list(const char *path, const double (*m)[16], int lo, int hi) {
  FILE *f = fopen(path, "w");
  REQUIRE(f, "open %s", path);
  fprintf(f, "# disks %d..%d, 4x4 row-major\n", lo, hi - 1);
  for (int i = lo; i < hi; i++) {
    for (int k = 0; k < 16; k++) fprintf(f, "%s%.9g", k ? " " : "", m[i][k]);
    fprintf(f, "\n");
  }
  fclose(f);
}

/* mode 3's three lists: placements [0, 300), [300, 700), [700, 1000). */
static const int list_lo[4] = {0, 300, 700, NDISK};

/* mode 0: separate disks; 1: `instance`s; 2: one instancelist (file
 * list_path); 3: three instancelists c0, c1, c2 (files list_path with
 * ".0", ".1", ".2" appended). */
static char *canopy_scene(int mode, const double (*m)[16], int n, const char *list_path) {
  sbuf b = {0};
  sb_printf(&b, "%s", HEAD);
  if (mode != 0)
    sb_printf(&b, ",\n\"leaf\": {\"type\": \"shapegroup\", \"d\": {\"type\": \"disk\", \"bsdf\": %s}}",
              LEAF_BSDF);
  if (mode == 2) {
    sb_printf(&b,
              ",\n\"canopy\": {\"type\": \"instancelist\", \"filename\": \"%s\", "
              "\"shapegroup\": {\"type\": \"ref\", \"id\": \"leaf\"}}",
              list_path);
  } else if (mode == 3) {
    for (int l = 0; l < 3; l++)
      sb_printf(&b,
                ",\n\"c%d\": {\"type\": \"instancelist\", \"filename\": \"%s.%d\", "
                "\"shapegroup\": {\"type\": \"ref\", \"id\": \"leaf\"}}",
                l, list_path, l);
  } else {
    for (int i = 0; i < n; i++) {
      if (mode == 0)
        sb_printf(&b, ",\n\"s%d\": {\"type\": \"disk\", \"bsdf\": %s, \"to_world\": ", i, LEAF_BSDF);
      else
        sb_printf(&b,
                  ",\n\"s%d\": {\"type\": \"instance\", \"shapegroup\": {\"type\": \"ref\", \"id\": "
                  "\"leaf\"}, \"to_world\": ",
                  i);
      sb_matrix(&b, m[i]);
      sb_printf(&b, "}");
    }
  }
  sb_printf(&b, "}\n");
  return b.p;
}

static bool render(scene *s, uint32_t spp, film_image *out) {
  return tsup_render(s, spp, SEED, THREADS, out);
}

static bool same_film(const film_image *a, const film_image *b) {
  return a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, sizeof(float) * (size_t)a->width * a->height * a->channels) == 0;
}

static double film_sum(const film_image *a) {
  double s = 0;
  for (size_t i = 0; i < (size_t)a->width * a->height * a->channels; i++) s += a->data[i];
  return s;
}

static void test_instanced_equals_separate(void) {
  static double m[NDISK][16];
  disk_matrices(m, NDISK);
  char *t0 = canopy_scene(0, (const double(*)[16])m, NDISK, NULL);
  char *t1 = canopy_scene(1, (const double(*)[16])m, NDISK, NULL);
  char path[] = "/tmp/rsw_instlist_XXXXXX";
  int fd = mkstemp(path);
  REQUIRE(fd >= 0, "mkstemp");
  close(fd);
  write_list(path, (const double(*)[16])m, 0, NDISK);
  char parts[3][64];
  for (int l = 0; l < 3; l++) {
    snprintf(parts[l], sizeof parts[l], "%s.%d", path, l);
    write_list(parts[l], (const double(*)[16])m, list_lo[l], list_lo[l + 1]);
  }
  char *t2 = canopy_scene(2, (const double(*)[16])m, NDISK, path);
  char *t3 = canopy_scene(3, (const double(*)[16])m, NDISK, path);
  scene *s0 = tsup_load(t0, NULL), *s1 = tsup_load(t1, NULL), *s2 = tsup_load(t2, NULL),
        *s3 = tsup_load(t3, NULL);
  REQUIRE(s0 && s1 && s2 && s3, "scenes load");
  film_image a = {0}, b = {0}, c = {0}, d = {0};
  REQUIRE(render(s0, 8, &a) && render(s1, 8, &b) && render(s2, 8, &c) && render(s3, 8, &d), "renders");
  CHECK(film_sum(&a) > 0, "the canopy film is not black");
  CHECK(same_film(&a, &b), "1,000 instances render bitwise like 1,000 separate disks (sums %.9g vs %.9g)",
        film_sum(&a), film_sum(&b));
  CHECK(same_film(&a, &c), "an instancelist renders bitwise like the separate disks (sums %.9g vs %.9g)",
        film_sum(&a), film_sum(&c));
  CHECK(same_film(&a, &d), "three instancelists render bitwise like the separate disks (sums %.9g vs %.9g)",
        film_sum(&a), film_sum(&d));
  /* A ray onto each disk, from 1 mm above its centre: the three lists'
   * hit names the list holding the disk the one list's hit names (the
   * disk itself, or one crossing in front of it) and its placement in
   * that list. */
  uint32_t index[3] = {UINT32_MAX, UINT32_MAX, UINT32_MAX};
  for (size_t i = 0; i < s3->n_shapes; i++)
    for (int l = 0; l < 3; l++) {
      char id[16];
      snprintf(id, sizeof id, "c%d", l);
      if (s3->shapes[i]->base.id && strcmp(s3->shapes[i]->base.id, id) == 0) index[l] = (uint32_t)i;
    }
  REQUIRE(index[0] != UINT32_MAX && index[1] != UINT32_MAX && index[2] != UINT32_MAX, "shapes c0, c1, c2");
  int n_hit = 0, n_bad = 0, n_self = 0;
  for (int k = 0; k < NDISK; k++) {
    const double *q = m[k];
    vec3 ctr = v3(q[3], q[7], q[11]), nrm = v3_norm(v3(q[2], q[6], q[10]));
    ray3 r = {.o = v3_fma(ctr, 1e-3, nrm), .d = v3_neg(nrm), .tmin = 0, .tmax = 2e-3};
    accel_hit h1, h3;
    bool hit1 = accel_intersect(s2->accel, &r, &h1), hit3 = accel_intersect(s3->accel, &r, &h3);
    if (!hit1) {
      n_bad += hit3;
      continue;
    }
    int g = (int)h1.sub, l = g < list_lo[1] ? 0 : g < list_lo[2] ? 1 : 2;
    bool ok = hit3 && h3.shape == index[l] && h3.sub == (uint32_t)(g - list_lo[l]);
    if (!ok && n_bad < 3)
      printf("  disk %d: one list's hit placement %d, three lists' %d: shape %u placement %u\n", k, g, hit3,
             h3.shape, h3.sub);
    n_hit++, n_bad += !ok, n_self += g == k;
  }
  CHECK(n_hit == NDISK && n_self > NDISK - 20 && n_bad == 0,
        "every disk's ray hits (%d of %d, %d the disk itself); the three lists' hits name the same "
        "placement (%d differ)",
        n_hit, NDISK, n_self, n_bad);
  /* Bounds (hence the bounding sphere) agree too. */
  CHECK(v3_len(v3_sub(s0->bbox_min, s1->bbox_min)) < 1e-6 &&
            v3_len(v3_sub(s0->bbox_max, s1->bbox_max)) < 1e-6,
        "same scene bounds");
  /* What render.c sizes its waves by: the soil's 2 triangles, a disk
   * each, the group's disk once. */
  CHECK(scene_primitive_count(s0) == 2 + NDISK && scene_primitive_count(s1) == 3 + NDISK &&
            scene_primitive_count(s2) == 3 + NDISK && scene_primitive_count(s3) == 3 + NDISK,
        "primitives: %zu separate, %zu instances, %zu one list, %zu three lists", scene_primitive_count(s0),
        scene_primitive_count(s1), scene_primitive_count(s2), scene_primitive_count(s3));
  film_image_free(&a), film_image_free(&b), film_image_free(&c), film_image_free(&d);
  scene_free(s0), scene_free(s1), scene_free(s2), scene_free(s3);
  free(t0), free(t1), free(t2), free(t3);
  unlink(path);
  for (int l = 0; l < 3; l++) unlink(parts[l]);
}

/* Moving one instance by a parameter update equals loading the moved
 * scene. */
static void test_instance_update_equals_reload(void) {
  static double m[50][16];
  disk_matrices(m, 50);
  char *t = canopy_scene(1, (const double(*)[16])m, 50, NULL);
  scene *s = tsup_load(t, NULL);
  REQUIRE(s, "scene loads");
  film_image before = {0}, after = {0}, ref = {0};
  REQUIRE(render(s, 8, &before), "render");
  /* New placement of s3: lifted by 0.25 and scaled up. */
  double q[16];
  memcpy(q, m[3], sizeof q);
  for (int k = 0; k < 3; k++) q[k] *= 2, q[4 + k] *= 2, q[8 + k] *= 2;
  q[11] += 0.25;
  char json[800];
  int len = snprintf(json, sizeof json, "[");
  for (int r = 0; r < 4; r++) {
    len += snprintf(json + len, sizeof json - len, "%s[", r ? ", " : "");
    for (int c = 0; c < 4; c++)
      len += snprintf(json + len, sizeof json - len, "%s%.17g", c ? ", " : "", q[4 * r + c]);
    len += snprintf(json + len, sizeof json - len, "]");
  }
  snprintf(json + len, sizeof json - len, "]");
  rsw_err err = {0};
  param_update u = {.key = "s3.to_world"};
  REQUIRE(param_value_parse(json, "s3.to_world", &u.value, &err) == RSW_OK, "parse");
  update_report rep;
  rsw_status st = scene_update(s, &u, 1, &rep, &err);
  char buf[1200];
  REQUIRE(st == RSW_OK, "update: %s", rsw_err_format(&err, buf, sizeof buf));
  param_value_free(&u.value);
  CHECK(rep.instance_updates == 1 && rep.rebuilds == 0 && rep.refits == 0,
        "one instance transform, no BVH rebuild (got %u, %u, %u)", rep.instance_updates, rep.rebuilds,
        rep.refits);
  REQUIRE(render(s, 8, &after), "render after");
  memcpy(m[3], q, sizeof q);
  char *t2 = canopy_scene(1, (const double(*)[16])m, 50, NULL);
  scene *s2 = tsup_load(t2, NULL);
  REQUIRE(s2 && render(s2, 8, &ref), "reload renders");
  CHECK(same_film(&after, &ref), "update equals reload (sums %.9g vs %.9g)", film_sum(&after),
        film_sum(&ref));
  CHECK(!same_film(&before, &after), "the update changed the film");
  film_image_free(&before), film_image_free(&after), film_image_free(&ref);
  scene_free(s), scene_free(s2);
  free(t), free(t2);
}

static void check_list_error(const char *text, const char *want_where, const char *want_msg) {
  char path[] = "/tmp/rsw_instbad_XXXXXX";
  int fd = mkstemp(path);
  REQUIRE(fd >= 0, "mkstemp");
  FILE *f = fdopen(fd, "w");
  fputs(text, f);
  fclose(f);
  float *xf = NULL;
  uint32_t n = 0;
  rsw_err err = {0};
  rsw_status st = instance_list_parse(path, &xf, &n, &err);
  char where[400];
  snprintf(where, sizeof where, "%s%s", path, want_where);
  CHECK(st != RSW_OK, "'%s' is refused", want_msg);
  CHECK(strcmp(err.where, where) == 0, "error names %s (got '%s')", where, err.where);
  CHECK(strstr(err.msg, want_msg) != NULL, "message has '%s' (got '%s')", want_msg, err.msg);
  free(xf);
  unlink(path);
}

static void test_list_errors(void) {
  check_list_error("# leaves\n0 0 1 0 0 1 0.1\n0 0 1 0 0 1\n", ":3", "got 6");
  check_list_error("0 0 1 0 0 1 0.1\n\n0 0 1 0 0 1 abc\n", ":3", "'abc' is not a number");
  check_list_error("0 0 1 0 0 1 -2\n", ":1", "radius must be > 0");
  check_list_error("1 0 0 0  0 1 0 0  0 0 1 0  0 0 1 1\n", ":1", "0 0 0 1");
  check_list_error("0 0 0 0  0 0 0 0  0 0 0 0  0 0 0 1\n", ":1", "singular");
  check_list_error("# only comments\n\n", "", "no rows");
  /* A good list parses: 7-number rows become T R S. */
  char path[] = "/tmp/rsw_instok_XXXXXX";
  int fd = mkstemp(path);
  REQUIRE(fd >= 0, "mkstemp");
  FILE *f = fdopen(fd, "w");
  fputs("1 2 3 0 0 1 0.5 # a flat leaf\n  1 0 0 4 0 1 0 5 0 0 1 6 0 0 0 1\n", f);
  fclose(f);
  float *xf = NULL;
  uint32_t n = 0;
  rsw_err err = {0};
  REQUIRE(instance_list_parse(path, &xf, &n, &err) == RSW_OK, "good list parses: %s", err.msg);
  CHECK(n == 2, "two rows (got %u)", n);
  CHECK(xf[3] == 1 && xf[7] == 2 && xf[11] == 3, "translation");
  CHECK(fabs(xf[10] - 0.5) < 1e-7 && fabs(xf[2]) < 1e-7 && fabs(xf[6]) < 1e-7, "+z kept, scaled by 0.5");
  CHECK(xf[12 + 3] == 4 && xf[12 + 7] == 5 && xf[12 + 11] == 6, "4x4 row");
  free(xf);
  unlink(path);
  /* A scene naming a bad list fails with the file's location. */
  char bad[] = "/tmp/rsw_instbad2_XXXXXX";
  fd = mkstemp(bad);
  REQUIRE(fd >= 0, "mkstemp");
  f = fdopen(fd, "w");
  fputs("0 0 1 0 0 1 0.1\n0 0 1 0 0 1 0.1 7\n", f);
  fclose(f);
  char text[1200];
  snprintf(text, sizeof text,
           "{\"type\": \"scene\", \"leaf\": {\"type\": \"shapegroup\", \"d\": {\"type\": \"disk\"}}, "
           "\"c\": {\"type\": \"instancelist\", \"filename\": \"%s\", \"shapegroup\": {\"type\": \"ref\", "
           "\"id\": \"leaf\"}}}",
           bad);
  scene *s = NULL;
  scene_load_opts o = {.size = sizeof o};
  rsw_status st = scene_load_memory(text, strlen(text), "t", false, &o, &s, &err);
  char want[400];
  snprintf(want, sizeof want, "%s:2", bad);
  CHECK(st != RSW_OK && strcmp(err.where, want) == 0, "scene load names %s (got '%s': %s)", want, err.where,
        err.msg);
  if (s) scene_free(s);
  unlink(bad);
}

/* ---- periodic ------------------------------------------------------------ */

#define PLOT  5.0 /* the plot is [-5, 5]^2 */
#define NLEAF 150

/* periodic = true: the plot with the boundary; false: the plot and its 8
 * neighbours written out (leaves as an instancelist of 9 x NLEAF rows). */
static char *plot_scene(bool periodic, double theta_deg, const char *list_path) {
  sbuf b = {0};
  double th = theta_deg * RSW_PI / 180.0;
  sb_printf(
      &b,
      "{\"type\": \"scene\", \"variant\": \"mono\",\n"
      "\"cam\": {\"type\": \"distant\", \"direction\": [%.17g, 0.2, %.17g], "
      "\"target\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [%g, %g, 1]}]}, "
      "\"sampler\": {\"type\": \"independent\", \"sample_count\": 64}, "
      "\"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},\n"
      "\"sun\": {\"type\": \"directional\", \"direction\": [-0.4, 0.3, -0.8], \"irradiance\": 1.0},\n"
      "\"soil\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [%g, %g, 1]}], "
      "\"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.3}},\n"
      "\"leaf\": {\"type\": \"shapegroup\", \"d\": {\"type\": \"disk\", \"bsdf\": %s}},\n"
      "\"canopy\": {\"type\": \"instancelist\", \"filename\": \"%s\", "
      "\"shapegroup\": {\"type\": \"ref\", \"id\": \"leaf\"}}",
      sin(th), -cos(th), PLOT, PLOT, periodic ? PLOT : 3 * PLOT, periodic ? PLOT : 3 * PLOT,
      "{\"type\": \"twosided\", \"b\": {\"type\": \"diffuse\", \"reflectance\": 0.5}}", list_path);
  if (periodic)
    sb_printf(&b, ",\n\"bounds\": {\"type\": \"periodic\", \"min\": [%g, %g], \"max\": [%g, %g]}", -PLOT,
              -PLOT, PLOT, PLOT);
  sb_printf(&b, "}\n");
  return b.p;
}

static void write_plot_list(const char *path, bool copies) {
  static double m[NLEAF][16];
  tsup_random_leaves(m, NLEAF, 5, 3, 4.6, 0.3, 1.2, 0.3);
  FILE *f = fopen(path, "w");
  for (int cx = -1; cx <= 1; cx++)
    for (int cy = -1; cy <= 1; cy++) {
      if (!copies && (cx || cy)) continue;
      for (int i = 0; i < NLEAF; i++) {
        double q[16];
        memcpy(q, m[i], sizeof q);
        q[3] += 2 * PLOT * cx, q[7] += 2 * PLOT * cy;
        for (int k = 0; k < 16; k++) fprintf(f, "%s%.17g", k ? " " : "", q[k]);
        fprintf(f, "\n");
      }
    }
  fclose(f);
}

/* Mean and standard error of the 1x1 film over independent seeds. */
#define NSEEDS 12
static bool seed_stats(scene *s, double *mean, double *sem) {
  double v[NSEEDS], sum = 0;
  for (int k = 0; k < NSEEDS; k++) {
    film_image img = {0};
    if (!tsup_render(s, 1024, 1000 + k, THREADS, &img)) return false;
    v[k] = img.data[0];
    sum += v[k];
    film_image_free(&img);
  }
  *mean = sum / NSEEDS;
  double ss = 0;
  for (int k = 0; k < NSEEDS; k++) ss += (v[k] - *mean) * (v[k] - *mean);
  *sem = sqrt(ss / (NSEEDS - 1) / NSEEDS);
  return true;
}

static void test_periodic_equals_copies(void) {
  char p1[] = "/tmp/rsw_plot1_XXXXXX", p9[] = "/tmp/rsw_plot9_XXXXXX";
  int f1 = mkstemp(p1), f9 = mkstemp(p9);
  REQUIRE(f1 >= 0 && f9 >= 0, "mkstemp");
  close(f1), close(f9);
  write_plot_list(p1, false);
  write_plot_list(p9, true);
  const double angles[3] = {0, 15, 30};
  for (int a = 0; a < 3; a++) {
    char *tp = plot_scene(true, angles[a], p1), *tc = plot_scene(false, angles[a], p9);
    scene *sp = tsup_load(tp, NULL), *scp = tsup_load(tc, NULL);
    REQUIRE(sp && scp, "plot scenes load");
    double mp, ep, mc, ec;
    REQUIRE(seed_stats(sp, &mp, &ep) && seed_stats(scp, &mc, &ec), "renders");
    double sig = sqrt(ep * ep + ec * ec);
    printf("  %2.0f deg: periodic %.6f +- %.6f, 3x3 copies %.6f +- %.6f\n", angles[a], mp, ep, mc, ec);
    CHECK(mp > 0.01, "the plot is lit (%g)", mp);
    CHECK(fabs(mp - mc) <= 3 * sig, "%.0f deg off nadir: periodic %.6f vs copies %.6f (3 sigma = %.6f)",
          angles[a], mp, mc, 3 * sig);
    scene_free(sp), scene_free(scp);
    free(tp), free(tc);
  }
  /* Without the boundary the single plot is darker or brighter: the test
   * can tell the two apart (leaves of the neighbours shade and light the
   * plot). */
  unlink(p1), unlink(p9);
}

/* The example scene loads and renders a lit film. */
static void test_example_scene(void) {
  scene *s = tsup_load_file("proto/examples/canopy_periodic.json", NULL);
  REQUIRE(s, "canopy_periodic.json loads");
  CHECK(s->periodic.on, "periodic boundary set");
  film_image img = {0};
  REQUIRE(tsup_render(s, 2, 1, THREADS, &img), "renders");
  CHECK(film_sum(&img) > 0, "lit");
  film_image_free(&img);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_instanced_equals_separate);
  RSW_TEST_RUN(test_instance_update_equals_reload);
  RSW_TEST_RUN(test_list_errors);
  RSW_TEST_RUN(test_periodic_equals_copies);
  RSW_TEST_RUN(test_example_scene);
  RSW_TEST_END("test_instancing");
}
