/* Large shapegroups (issue 11 item 5): a leaf cloud of 32,000 disks in one
 * shapegroup (one JSON object of 32,000 keys, or one XML <shape> with
 * 32,000 children, or one JSON "members" list) loads, renders, and equals
 * the same disks split into 8 groups of 4,000, bitwise (same seed, spp, threads; every disk is
 * intersected by the same double-precision member callback whatever its
 * group, so only exact float ties between two disks could differ).
 *
 * Also: the load time of 32,000- and 100,000-member groups (printed, and
 * bounded loosely so that a quadratic lookup, minutes at this size, fails);
 * an ordinary object keeps its 4,096-key cap, with an error naming the
 * object; the document memory cap (lowered here) fails with an error
 * naming the key path and the cap, in JSON and XML; a duplicate key among
 * 32,000 is found and named. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

#include "../../../server/kernel/core/rng.h"
#include "../../../server/kernel/core/transform.h"
#include "../../../server/kernel/scene/param_table.h"
#include "../../../server/kernel/scene/params.h"
#include "../../support/test.h"
#include "../../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

#define NLEAF   32000
#define SEED    5u
#define THREADS 2

static double now_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* Leaf placements: centres in [-8, 8]^2 x [0.5, 2.5], random upward
 * normals, radius 0.08 (LAI about 2.5 over the 16 m plot); row-major 3x4
 * rows of a to_world, printed with %.9g. */
static double (*leaves(int n))[12] {
  double(*m)[12] = malloc((size_t)n * sizeof *m);
  pcg32 g;
  pcg32_seed(&g, 17, 3);
  for (int i = 0; i < n; i++) {
    double x = -8 + 16 * pcg32_next_double(&g), y = -8 + 16 * pcg32_next_double(&g);
    double z = 0.5 + 2 * pcg32_next_double(&g);
    vec3 nn = v3_norm(v3(pcg32_next_double(&g) - 0.5, pcg32_next_double(&g) - 0.5, 0.7));
    frame f = frame_from_normal(nn);
    vec3 c[3] = {f.s, f.t, f.n};
    for (int k = 0; k < 3; k++) {
      m[i][0 * 4 + k] = 0.08 * c[k].x;
      m[i][1 * 4 + k] = 0.08 * c[k].y;
      m[i][2 * 4 + k] = 0.08 * c[k].z;
    }
    m[i][3] = x, m[i][7] = y, m[i][11] = z;
  }
  return m;
}

#define HEAD                                                                                                 \
  "{\"type\": \"scene\", \"variant\": \"mono\",\n"                                                           \
  "\"cam\": {\"type\": \"hdistant\", \"target\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [8, "  \
  "8, 1]}]}, "                                                                                               \
  "\"sampler\": {\"type\": \"independent\", \"sample_count\": 8}, "                                          \
  "\"film\": {\"type\": \"hdrfilm\", \"width\": 8, \"height\": 8, \"rfilter\": {\"type\": \"box\"}}},\n"     \
  "\"sun\": {\"type\": \"directional\", \"direction\": [0.3, 0.2, -0.9], \"irradiance\": 1.0},\n"            \
  "\"soil\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}], "                           \
  "\"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.2}},\n"                                              \
  "\"leaf\": {\"type\": \"bilambertian\", \"reflectance\": 0.45, \"transmittance\": 0.4}"

static void sb_leaf(sbuf *b, int i, const double *q, bool keyed) {
  if (keyed) sb_printf(b, "\"d%d\": ", i);
  sb_printf(b, "{\"type\": \"disk\", \"bsdf\": {\"type\": \"ref\", \"id\": \"leaf\"}, \"to_world\": [");
  for (int k = 0; k < 12; k++) sb_printf(b, "%s%.9g", k ? ", " : "", q[k]);
  sb_printf(b, ", 0, 0, 0, 1]}");
}

/* n leaves in `groups` shapegroups (each instanced once, identity); as
 * keys "d<i>", or (list) as one "members" list per group. */
static char *cloud_json_as(const double (*m)[12], int n, int groups, bool list) {
  sbuf b = {0};
  sb_printf(&b, "%s", HEAD);
  int per = (n + groups - 1) / groups;
  for (int g = 0; g < groups; g++) {
    sb_printf(&b, ",\n\"g%d\": {\"type\": \"shapegroup\"%s", g, list ? ", \"members\": [" : "");
    for (int i = g * per; i < n && i < (g + 1) * per; i++) {
      sb_printf(&b, "%s\n ", list && i == g * per ? "" : ",");
      sb_leaf(&b, i, m[i], !list);
    }
    sb_printf(&b,
              "%s},\n\"i%d\": {\"type\": \"instance\", \"shapegroup\": {\"type\": \"ref\", \"id\": \"g%d\"}}",
              list ? "]" : "", g, g);
  }
  sb_printf(&b, "}\n");
  return b.p;
}

static char *cloud_json(const double (*m)[12], int n, int groups) {
  return cloud_json_as(m, n, groups, false);
}

/* The same scene as Mitsuba XML, one group. */
static char *cloud_xml(const double (*m)[12], int n) {
  sbuf b = {0};
  sb_printf(
      &b,
      "<scene version=\"3.0.0\" variant=\"mono\">\n"
      "<sensor type=\"hdistant\"><shape type=\"rectangle\" name=\"target\"><transform name=\"to_world\">"
      "<scale x=\"8\" y=\"8\" z=\"1\"/></transform></shape>"
      "<sampler type=\"independent\"><integer name=\"sample_count\" value=\"8\"/></sampler>"
      "<film type=\"hdrfilm\"><integer name=\"width\" value=\"8\"/><integer name=\"height\" value=\"8\"/>"
      "<rfilter type=\"box\"/></film></sensor>\n"
      "<emitter type=\"directional\"><vector name=\"direction\" x=\"0.3\" y=\"0.2\" z=\"-0.9\"/>"
      "<float name=\"irradiance\" value=\"1\"/></emitter>\n"
      "<shape type=\"rectangle\" id=\"soil\"><transform name=\"to_world\"><scale x=\"10\" y=\"10\" z=\"1\"/>"
      "</transform><bsdf type=\"diffuse\"><float name=\"reflectance\" value=\"0.2\"/></bsdf></shape>\n"
      "<bsdf type=\"bilambertian\" id=\"leaf\"><float name=\"reflectance\" value=\"0.45\"/>"
      "<float name=\"transmittance\" value=\"0.4\"/></bsdf>\n"
      "<shape type=\"shapegroup\" id=\"g0\">\n");
  for (int i = 0; i < n; i++) {
    sb_printf(
        &b, "<shape type=\"disk\" id=\"d%d\"><ref id=\"leaf\"/><transform name=\"to_world\"><matrix value=\"",
        i);
    for (int k = 0; k < 12; k++) sb_printf(&b, "%s%.9g", k ? " " : "", m[i][k]);
    sb_printf(&b, " 0 0 0 1\"/></transform></shape>\n");
  }
  sb_printf(&b, "</shape>\n<shape type=\"instance\" id=\"i0\"><ref name=\"shapegroup\" "
                "id=\"g0\"/></shape>\n</scene>\n");
  return b.p;
}

static bool same_film(const film_image *a, const film_image *b) {
  return a->width == b->width && a->height == b->height && a->channels == b->channels &&
         memcmp(a->data, b->data, sizeof(float) * (size_t)a->width * a->height * a->channels) == 0;
}

static double cpu_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* Wall and CPU (all threads: Embree builds in parallel) time of a load. */
static scene *timed_load(const char *text, const char *what, double *seconds) {
  double t0 = now_s(), c0 = cpu_s();
  scene *s = tsup_load(text, NULL);
  *seconds = now_s() - t0;
  printf("  load %s: %.3f s wall, %.3f s CPU (%zu bytes of document)\n", what, *seconds, cpu_s() - c0,
         strlen(text));
  return s;
}

static void test_one_group_equals_eight(void) {
  double(*m)[12] = leaves(NLEAF);
  char *one = cloud_json(m, NLEAF, 1), *eight = cloud_json(m, NLEAF, 8), *xml = cloud_xml(m, NLEAF);
  char *lst = cloud_json_as(m, NLEAF, 1, true);
  double t1, t8, tx, tl;
  scene *s1 = timed_load(one, "32,000 disks in 1 group (JSON)", &t1);
  scene *s8 = timed_load(eight, "32,000 disks in 8 groups (JSON)", &t8);
  scene *sx = timed_load(xml, "32,000 disks in 1 group (XML)", &tx);
  scene *sl = timed_load(lst, "32,000 disks in 1 group (JSON list)", &tl);
  CHECK(s1 && s8 && sx && sl, "load");
  /* Generous: linear work takes well under a second here; a quadratic
   * step (32,000^2 string compares per pass) takes minutes. */
  CHECK(t1 < 30 && t8 < 30 && tx < 30, "load too slow: %.1f / %.1f / %.1f s", t1, t8, tx);
  if (s1 && s8 && sx && sl) {
    size_t idx;
    rsw_err err = {0};
    CHECK(params_lookup(s1, "g0.d31999.bsdf.reflectance.value", &idx, &err) == RSW_OK,
          "member parameter key: %s", err.msg);
    CHECK(params_lookup(sl, "g0.members_31999.bsdf.reflectance.value", &idx, &err) == RSW_OK,
          "list member parameter key: %s", err.msg);
    film_image f1 = {0}, f8 = {0}, fx = {0}, fl = {0};
    double r0 = now_s();
    bool ok = tsup_render(s1, 0, SEED, THREADS, &f1);
    printf("  render 8x8x8 spp, 1 group: %.3f s\n", now_s() - r0);
    ok = ok && tsup_render(s8, 0, SEED, THREADS, &f8) && tsup_render(sx, 0, SEED, THREADS, &fx) &&
         tsup_render(sl, 0, SEED, THREADS, &fl);
    CHECK(ok, "render");
    if (ok) {
      double sum = 0;
      for (int i = 0; i < f1.width * f1.height; i++) sum += f1.data[i];
      printf("  mean pixel %.6f\n", sum / (f1.width * f1.height));
      CHECK(sum > 0, "black film");
      CHECK(same_film(&f1, &f8), "one group and eight groups render differently");
      CHECK(same_film(&f1, &fx), "the XML group renders differently from the JSON group");
      CHECK(same_film(&f1, &fl), "the member list renders differently from the keyed members");
    }
    film_image_free(&fl);
    film_image_free(&f1);
    film_image_free(&f8);
    film_image_free(&fx);
  }
  scene_free(s1);
  scene_free(s8);
  scene_free(sx);
  scene_free(sl);
  free(lst);
  free(one);
  free(eight);
  free(xml);
  free(m);
}

static void test_load_100k(void) {
  double(*m)[12] = leaves(100000);
  char *one = cloud_json(m, 100000, 1);
  double t;
  scene *s = timed_load(one, "100,000 disks in 1 group (JSON)", &t);
  CHECK(s != NULL, "load");
  CHECK(t < 60, "load too slow: %.1f s", t);
  scene_free(s);
  free(one);
  free(m);
}

static void expect_load_error(const char *doc, bool xml, rsw_status code, const char *where_part,
                              const char *msg_part) {
  scene *s = NULL;
  rsw_err err = {0};
  rsw_status st = scene_load_memory(doc, strlen(doc), xml ? "big.xml" : "big.json", xml, NULL, &s, &err);
  CHECK(st == code, "status %d, expected %d (%s)", (int)st, (int)code, err.msg);
  CHECK(strstr(err.where, where_part) != NULL, "where '%s' lacks '%s'", err.where, where_part);
  CHECK(strstr(err.msg, msg_part) != NULL, "message '%s' lacks '%s'", err.msg, msg_part);
  scene_free(s);
}

static void test_caps(void) {
  /* An ordinary object keeps the 4,096-key cap; the error names it. */
  sbuf b = {0};
  sb_printf(&b, "{\"type\": \"scene\", \"mat\": {\"type\": \"diffuse\"");
  for (int i = 0; i < 4096; i++) sb_printf(&b, ", \"k%d\": 1", i);
  sb_printf(&b, "}}");
  expect_load_error(b.p, false, RSW_ERR_LIMIT, "big.json#/mat", "has 4097 keys, more than the 4096");
  free(b.p);
  b = (sbuf){0};
  sb_printf(&b, "<scene version=\"3.0.0\"><bsdf type=\"diffuse\" id=\"mat\">\n");
  for (int i = 0; i < 4097; i++) sb_printf(&b, "<float name=\"k%d\" value=\"1\"/>\n", i);
  sb_printf(&b, "</bsdf></scene>");
  expect_load_error(b.p, true, RSW_ERR_LIMIT, "big.xml:4098",
                    "diffuse 'mat' (opened at big.xml:1) has more than the 4096");
  free(b.p);

  /* The list form: only in containers; every element an object. */
  expect_load_error(
      "{\"type\": \"scene\", \"mat\": {\"type\": \"twosided\", \"b\": [{\"type\": \"diffuse\"}]}}", false,
      RSW_ERR_TYPE, "big.json#/mat/b", "accepted only in the scene and in shapegroups");
  expect_load_error(
      "{\"type\": \"scene\", \"g\": {\"type\": \"shapegroup\", \"members\": [{\"type\": \"disk\"}, 3]}}",
      false, RSW_ERR_TYPE, "big.json#/g/members/1", "every element needs a \"type\"");

  /* The memory cap, lowered to 4 MiB: a 32,000-member group runs over it
   * part way; the error names the key being read and the cap. */
  double(*m)[12] = leaves(NLEAF);
  char *one = cloud_json(m, NLEAF, 1), *xml = cloud_xml(m, NLEAF);
  scene_limits lim = scene_limits_default;
  lim.max_tree_bytes = (size_t)4 << 20;
  node *root = NULL;
  rsw_err err = {0};
  rsw_status st = scene_read_json_limited(one, strlen(one), "big.json", &lim, &root, NULL, &err);
  CHECK(st == RSW_ERR_LIMIT, "json: status %d (%s)", (int)st, err.msg);
  CHECK(strstr(err.where, "big.json#/g0/d") != NULL, "json: where '%s'", err.where);
  CHECK(strstr(err.msg, "memory cap of 4194304 bytes (4 MiB)") != NULL, "json: message '%s'", err.msg);
  printf("  %s: %s\n", err.where, err.msg);
  node_free(root);
  root = NULL;
  memset(&err, 0, sizeof err);
  st = scene_read_xml_limited(xml, strlen(xml), "big.xml", NULL, 0, &lim, &root, NULL, &err);
  CHECK(st == RSW_ERR_LIMIT, "xml: status %d (%s)", (int)st, err.msg);
  CHECK(strstr(err.where, "big.xml:") != NULL, "xml: where '%s'", err.where);
  CHECK(strstr(err.msg, "memory cap of 4194304 bytes") && strstr(err.msg, "disk 'd"), "xml: message '%s'",
        err.msg);
  printf("  %s: %s\n", err.where, err.msg);
  node_free(root);
  /* With the default cap both read. */
  root = NULL;
  CHECK(scene_read_json_limited(one, strlen(one), "big.json", NULL, &root, NULL, &err) == RSW_OK,
        "default cap");
  node_free(root);

  /* A duplicate key among 32,000 (hash check): named. */
  char *dup = malloc(strlen(one) + 200);
  strcpy(dup, one);
  char *end = strstr(dup, "},\n\"i0\"");
  REQUIRE(end, "group end");
  const char *ins = ",\n \"d17\": {\"type\": \"disk\"}";
  size_t k = strlen(ins);
  memmove(end + k, end, strlen(end) + 1);
  memcpy(end, ins, k);
  expect_load_error(dup, false, RSW_ERR_DUPLICATE, "big.json#/g0/d17", "duplicate key 'd17'");
  free(dup);
  free(one);
  free(xml);
  free(m);
}

/* Peak resident set of this process so far, in bytes (Linux: KiB). */
static double peak_rss(void) {
  struct rusage u;
  getrusage(RUSAGE_SELF, &u);
  return 1024.0 * (double)u.ru_maxrss;
}

/* Read `doc` as XML under a 4 MiB cap: the error must be the cap's, at
 * big.xml:`line`, containing `msg_part`; with `amplified` (a small
 * document that $ substitution makes large) the process's peak memory
 * must not grow past 6 x the cap either. */
static void expect_xml_cap(const char *what, const char *doc, unsigned line, const char *msg_part,
                           bool amplified) {
  scene_limits lim = scene_limits_default;
  lim.max_tree_bytes = (size_t)4 << 20;
  node *root = NULL;
  rsw_err err = {0};
  double rss0 = peak_rss(), t0 = now_s();
  rsw_status st = scene_read_xml_limited(doc, strlen(doc), "big.xml", NULL, 0, &lim, &root, NULL, &err);
  double t = now_s() - t0, grew = peak_rss() - rss0;
  char where[32];
  snprintf(where, sizeof where, "big.xml:%u", line);
  printf("  %s: %zu-byte document, status %d in %.3f s, peak memory +%.1f MiB; %s: %s\n", what, strlen(doc),
         (int)st, t, grew / 1048576.0, err.where, err.msg);
  CHECK(st == RSW_ERR_LIMIT, "%s: status %d, expected the cap's %d", what, (int)st, (int)RSW_ERR_LIMIT);
  CHECK(strcmp(err.where, where) == 0, "%s: where '%s', expected '%s'", what, err.where, where);
  CHECK(strstr(err.msg, "memory cap of 4194304 bytes (4 MiB)") && strstr(err.msg, msg_part),
        "%s: message '%s' lacks the cap or '%s'", what, err.msg, msg_part);
  CHECK(!amplified || grew < 6.0 * lim.max_tree_bytes, "%s: peak memory grew by %.1f MiB under a 4 MiB cap",
        what, grew / 1048576.0);
  node_free(root);
}

/* The XML reader's memory cap counts what a property's value holds, and
 * $ substitution (a few bytes of "$p$p$p" make up to 16 MiB per
 * attribute) is bounded by the cap too. Run first, while the process's
 * peak memory is still low. Before the fix all three documents read
 * (status 0), the first holding 40 MiB under a 4 MiB cap. */
static void test_xml_cap_values(void) {
  /* 512 KiB parameter, ten <string>s of 8 x $p each: 40 MiB of strings
   * from a 0.5 MiB document. Fails at the first string (line 4). */
  const size_t pn = (size_t)512 << 10;
  sbuf b = {0};
  sb_printf(&b, "<scene version=\"3.0.0\">\n<default name=\"p\" value=\"");
  char *pad = malloc(pn + 1);
  REQUIRE(pad, "oom");
  memset(pad, 'x', pn);
  pad[pn] = '\0';
  sb_printf(&b, "%s\"/>\n<bsdf type=\"diffuse\">\n", pad);
  for (int k = 0; k < 10; k++) sb_printf(&b, "<string name=\"s%d\" value=\"$p$p$p$p$p$p$p$p\"/>\n", k);
  sb_printf(&b, "</bsdf>\n</scene>\n");
  expect_xml_cap("8 x $p strings", b.p, 4, "in diffuse '' (opened at big.xml:3)", true);
  free(b.p);

  /* The same without $: two 3 MiB literal strings. Fails at the second.
   * (Memory here follows the document's own size: expat's copies, and
   * under ASan its quarantine.) */
  b = (sbuf){0};
  sb_printf(&b, "<scene version=\"3.0.0\">\n<bsdf type=\"diffuse\">\n");
  for (int k = 0; k < 2; k++) {
    sb_printf(&b, "<string name=\"s%d\" value=\"", k);
    for (int r = 0; r < 6; r++) sb_printf(&b, "%s", pad);
    sb_printf(&b, "\"/>\n");
  }
  sb_printf(&b, "</bsdf>\n</scene>\n");
  expect_xml_cap("3 MiB literal strings", b.p, 4, "in diffuse ''", false);
  free(b.p);

  /* Substitution into values that are parsed and dropped: "0.5" and
   * 512 KiB of blanks, ten times; the eighth passes 4 MiB (line 11). */
  b = (sbuf){0};
  memset(pad, ' ', pn);
  sb_printf(&b, "<scene version=\"3.0.0\">\n<default name=\"p\" value=\"0.5%s\"/>\n<bsdf type=\"diffuse\">\n",
            pad);
  for (int k = 0; k < 10; k++) sb_printf(&b, "<rgb name=\"c%d\" value=\"$p\"/>\n", k);
  sb_printf(&b, "</bsdf>\n</scene>\n");
  expect_xml_cap("$p into <rgb>", b.p, 11, "$ substitution", true);
  free(b.p);
  free(pad);
}

int main(void) {
  RSW_TEST_RUN(test_xml_cap_values);
  RSW_TEST_RUN(test_one_group_equals_eight);
  RSW_TEST_RUN(test_load_100k);
  RSW_TEST_RUN(test_caps);
  RSW_TEST_END("test_shapegroup_big");
}
