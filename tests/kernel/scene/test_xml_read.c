/* Tests for the Mitsuba XML scene reader (server/kernel/scene/xml_read.c):
 * the hdistant seed scene, every transform operation against hand-computed
 * matrices, property parsing, $param substitution, version checks, limits,
 * and the malformed-document corpus tests/corpus/bad/bad_xml_*.xml (each
 * must fail at the line its README.xml.txt entry names). */
#include "../../support/test.h"

#include <dirent.h>
#include <stdlib.h>
#include <string.h>

#include "kernel/scene/node.h"

RSW_TEST_DEFINE_GLOBALS

/* ---- helpers -------------------------------------------------------------- */

/* Path of a file in the source tree: under $RSW_TEST_DIR/.. when run through
 * tests/run.sh, else relative to the repository root (the cwd). */
static void src_path(char *buf, size_t cap, const char *rel) {
  const char *dir = getenv("RSW_TEST_DIR");
  if (dir && dir[0])
    snprintf(buf, cap, "%s/../%s", dir, rel);
  else
    snprintf(buf, cap, "%s", rel);
}

/* Whole file, NUL-terminated (owned); NULL when unreadable. */
static char *slurp(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  size_t cap = 4096, n = 0;
  char *buf = malloc(cap);
  size_t got;
  while (buf && (got = fread(buf + n, 1, cap - n - 1, f)) > 0) {
    n += got;
    if (n + 1 == cap) {
      char *p = realloc(buf, cap *= 2);
      if (!p) free(buf);
      buf = p;
    }
  }
  fclose(f);
  if (buf) buf[n] = '\0';
  *len = n;
  return buf;
}

static rsw_status parse_str(const char *xml, const scene_define *defs, size_t n_defs, node **root,
                            rsw_err *err) {
  *root = NULL;
  rsw_err_clear(err);
  return scene_read_xml(xml, strlen(xml), "t.xml", defs, n_defs, root, NULL, err);
}

/* i-th property of n, which must be a nested object. */
static node *child(const node *n, size_t i) {
  if (!n || i >= n->n_props || n->props[i].kind != PROP_NODE) return NULL;
  return n->props[i].child;
}

/* Parse <scene><shape type="t"><transform name="to_world">OPS</transform>
 * </shape></scene> and return the transform (identity on failure). */
static bool parse_xf(const char *ops, xform *out) {
  char xml[2048];
  snprintf(xml, sizeof xml,
           "<scene version=\"3.0.0\"><shape type=\"t\"><transform name=\"to_world\">%s"
           "</transform></shape></scene>",
           ops);
  node *root;
  rsw_err err;
  *out = xf_identity();
  if (parse_str(xml, NULL, 0, &root, &err) != RSW_OK) {
    printf("  parse of %s failed: %s: %s\n", ops, err.where, err.msg);
    return false;
  }
  node *shape = child(root, 0);
  prop *p = shape ? node_find(shape, "to_world") : NULL;
  bool ok = p && p->kind == PROP_TRANSFORM;
  if (ok) *out = p->xf;
  node_free(root);
  return ok;
}

/* Max |a.m - b| over all 16 entries, and check m * inv = identity. */
static double xf_diff(const xform *a, const double b[4][4]) {
  double d = 0;
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++) {
      double e = fabs(a->m[i][j] - b[i][j]);
      if (e > d) d = e;
      double s = 0;
      for (int k = 0; k < 4; k++) s += a->m[i][k] * a->inv[k][j];
      e = fabs(s - (i == j ? 1.0 : 0.0));
      if (e > d) d = e;
    }
  return d;
}

#define CHECK_XF(ops, ...)                                                                                   \
  do {                                                                                                       \
    xform xf_;                                                                                               \
    const double want_[4][4] = __VA_ARGS__;                                                                  \
    CHECK(parse_xf(ops, &xf_), "transform %s did not parse", ops);                                           \
    double d_ = xf_diff(&xf_, want_);                                                                        \
    CHECK(d_ < 1e-12, "transform %s differs from the expected matrix by %g", ops, d_);                       \
  } while (0)

/* ---- the seed scene ---------------------------------------------------------- */

static void test_seed_scene(void) {
  char path[1024];
  src_path(path, sizeof path, "proto/examples/hdistant_seed.xml");
  size_t len;
  char *text = slurp(path, &len);
  REQUIRE(text, "cannot read %s", path);
  node *root = NULL;
  char *variant = (char *)"sentinel";
  rsw_err err;
  rsw_err_clear(&err);
  rsw_status st = scene_read_xml(text, len, "hdistant_seed.xml", NULL, 0, &root, &variant, &err);
  free(text);
  REQUIRE(st == RSW_OK, "seed failed: %s: %s", err.where, err.msg);
  CHECK(variant == NULL, "no variant attribute, variant_out must be NULL");
  CHECK(strcmp(root->tag, "scene") == 0 && strcmp(root->type, "scene") == 0, "root tag/type");
  CHECK(strcmp(root->loc, "hdistant_seed.xml:1") == 0, "root loc %s", root->loc);

  /* sensor, integrator, 3 emitters, shape, in document order */
  static const char *const tags[] = {"sensor", "integrator", "emitter", "emitter", "emitter", "shape"};
  static const char *const types[] = {"hdistant",    "path",        "directional",
                                      "directional", "directional", "rectangle"};
  static const char *const ids[] = {"hdistant",      "path",          "directional",
                                    "directional_1", "directional_2", "rectangle"};
  REQUIRE(root->n_props == 6, "root has %zu children, expected 6", root->n_props);
  for (size_t i = 0; i < 6; i++) {
    node *n = child(root, i);
    REQUIRE(n, "child %zu is not an object", i);
    CHECK(strcmp(root->props[i].name, "") == 0, "unnamed child %zu has name %s", i, root->props[i].name);
    CHECK(strcmp(n->tag, tags[i]) == 0, "child %zu tag %s != %s", i, n->tag, tags[i]);
    CHECK(strcmp(n->type, types[i]) == 0, "child %zu type %s != %s", i, n->type, types[i]);
    CHECK(n->id && strcmp(n->id, ids[i]) == 0, "child %zu id %s != %s", i, n->id ? n->id : "(null)", ids[i]);
    CHECK(n->id_explicit == (i == 0), "child %zu id_explicit", i);
  }

  /* sensor: to_world from lookat(0,0,0 -> 0,0,1, up 0,1,0) is the identity */
  node *sensor = child(root, 0);
  CHECK(strcmp(sensor->loc, "hdistant_seed.xml:2") == 0, "sensor loc %s", sensor->loc);
  REQUIRE(sensor->n_props == 3, "sensor has %zu props", sensor->n_props);
  prop *tw = node_find(sensor, "to_world");
  REQUIRE(tw && tw->kind == PROP_TRANSFORM, "sensor to_world");
  CHECK(xf_is_identity(&tw->xf), "lookat along +z with up +y must be the identity");
  CHECK(strcmp(tw->loc, "hdistant_seed.xml:3") == 0, "to_world loc %s", tw->loc);

  node *sampler = child(sensor, 1);
  REQUIRE(sampler && strcmp(sampler->tag, "sampler") == 0, "sampler");
  CHECK(strcmp(sampler->type, "independent") == 0 && strcmp(sampler->id, "independent") == 0,
        "sampler type/id");
  prop *spp = node_find(sampler, "sample_count");
  REQUIRE(spp && spp->kind == PROP_NUMBER, "sample_count");
  CHECK(spp->is_int && spp->num == 3200, "sample_count = %g (is_int %d)", spp->num, spp->is_int);
  CHECK(strcmp(spp->loc, "hdistant_seed.xml:7") == 0, "sample_count loc %s", spp->loc);

  node *film = child(sensor, 2);
  REQUIRE(film && strcmp(film->tag, "film") == 0, "film");
  CHECK(strcmp(film->type, "hdrfilm") == 0 && strcmp(film->id, "hdrfilm") == 0, "film type/id");
  REQUIRE(film->n_props == 5, "film has %zu props", film->n_props);
  prop *w = node_find(film, "width"), *h = node_find(film, "height");
  CHECK(w && w->is_int && w->num == 32, "film width");
  CHECK(h && h->is_int && h->num == 32, "film height");
  prop *pf = node_find(film, "pixel_format"), *cf = node_find(film, "component_format");
  CHECK(pf && pf->kind == PROP_STRING && strcmp(pf->str, "rgb") == 0, "pixel_format");
  CHECK(cf && cf->kind == PROP_STRING && strcmp(cf->str, "float32") == 0, "component_format");
  node *rf = child(film, 4);
  CHECK(rf && strcmp(rf->tag, "rfilter") == 0 && strcmp(rf->type, "box") == 0 && strcmp(rf->id, "box") == 0 &&
            rf->n_props == 0,
        "rfilter box");

  /* emitters: direction vectors and rgb irradiance */
  static const double dirs[3][3] = {{1, 0, -1}, {1, 1, -1}, {0, 1, -1}};
  static const double rgbs[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int e = 0; e < 3; e++) {
    node *em = child(root, 2 + (size_t)e);
    prop *d = node_find(em, "direction"), *irr = node_find(em, "irradiance");
    REQUIRE(d && d->kind == PROP_VEC3, "emitter %d direction", e);
    CHECK(d->vec.x == dirs[e][0] && d->vec.y == dirs[e][1] && d->vec.z == dirs[e][2],
          "emitter %d direction (%g %g %g)", e, d->vec.x, d->vec.y, d->vec.z);
    REQUIRE(irr && irr->kind == PROP_SPECTRUM && irr->spec.kind == SPEC_RGB, "emitter %d irradiance", e);
    for (int k = 0; k < 3; k++)
      CHECK(irr->spec.rgb[k] == rgbs[e][k], "emitter %d rgb[%d] = %g", e, k, irr->spec.rgb[k]);
  }

  /* shape: nested unnamed bsdf with generated id */
  node *shape = child(root, 5);
  node *bsdf = child(shape, 0);
  REQUIRE(bsdf, "shape's bsdf");
  CHECK(strcmp(bsdf->tag, "bsdf") == 0 && strcmp(bsdf->type, "roughconductor") == 0 &&
            strcmp(bsdf->id, "roughconductor") == 0,
        "bsdf roughconductor");
  CHECK(strcmp(bsdf->loc, "hdistant_seed.xml:33") == 0, "bsdf loc %s", bsdf->loc);
  node_free(root);
}

/* ---- transform operations ------------------------------------------------- */

static void test_transform_ops(void) {
  CHECK_XF("", {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}});
  CHECK_XF("<translate x=\"1\" y=\"2\" z=\"3\"/>", {{1, 0, 0, 1}, {0, 1, 0, 2}, {0, 0, 1, 3}, {0, 0, 0, 1}});
  CHECK_XF("<translate y=\"-2\"/>", {{1, 0, 0, 0}, {0, 1, 0, -2}, {0, 0, 1, 0}, {0, 0, 0, 1}});
  CHECK_XF("<translate value=\"1, 2 3\"/>", {{1, 0, 0, 1}, {0, 1, 0, 2}, {0, 0, 1, 3}, {0, 0, 0, 1}});
  /* rotate 90 degrees counter-clockwise about z: x -> y, y -> -x */
  CHECK_XF("<rotate z=\"1\" angle=\"90\"/>", {{0, -1, 0, 0}, {1, 0, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}});
  /* about x (axis via value=, unnormalised): y -> z, z -> -y */
  CHECK_XF("<rotate value=\"2, 0, 0\" angle=\"90\"/>",
           {{1, 0, 0, 0}, {0, 0, -1, 0}, {0, 1, 0, 0}, {0, 0, 0, 1}});
  /* about y by 180: x -> -x, z -> -z */
  CHECK_XF("<rotate y=\"1\" angle=\"180\"/>", {{-1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, -1, 0}, {0, 0, 0, 1}});
  CHECK_XF("<scale value=\"2\"/>", {{2, 0, 0, 0}, {0, 2, 0, 0}, {0, 0, 2, 0}, {0, 0, 0, 1}});
  CHECK_XF("<scale value=\"1 2 3\"/>", {{1, 0, 0, 0}, {0, 2, 0, 0}, {0, 0, 3, 0}, {0, 0, 0, 1}});
  CHECK_XF("<scale x=\"4\"/>", {{4, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}});
  CHECK_XF("<matrix value=\"1 2 0 4  0 1 0 5  0 0 2 6  0 0 0 1\"/>",
           {{1, 2, 0, 4}, {0, 1, 0, 5}, {0, 0, 2, 6}, {0, 0, 0, 1}});
  CHECK_XF("<matrix value=\"0,-1,0, 1,0,0, 0,0,3\"/>",
           {{0, -1, 0, 0}, {1, 0, 0, 0}, {0, 0, 3, 0}, {0, 0, 0, 1}});
  /* lookat: columns (left, up, dir, origin); along +z with up +y the
   * rotation is the identity, translation the origin */
  CHECK_XF("<lookat origin=\"1, 2, 3\" target=\"1, 2, 4\" up=\"0, 1, 0\"/>",
           {{1, 0, 0, 1}, {0, 1, 0, 2}, {0, 0, 1, 3}, {0, 0, 0, 1}});
  /* looking down -z from (0,0,5) with up +y: dir (0,0,-1),
   * left = up x dir = (-1,0,0), new up = dir x left = (0,1,0) */
  CHECK_XF("<lookat origin=\"0 0 5\" target=\"0 0 0\" up=\"0 1 0\"/>",
           {{-1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, -1, 5}, {0, 0, 0, 1}});
  /* no up: up = coordinate_system(+z).first = (1,0,0); left = (1,0,0) x z =
   * (0,-1,0); new up = z x left = (1,0,0) */
  CHECK_XF("<lookat origin=\"0 0 0\" target=\"0 0 2\"/>",
           {{0, 1, 0, 0}, {-1, 0, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}});
  /* each op is left-multiplied: translate then scale = S * T */
  CHECK_XF("<translate x=\"1\"/><scale value=\"2\"/>",
           {{2, 0, 0, 2}, {0, 2, 0, 0}, {0, 0, 2, 0}, {0, 0, 0, 1}});
  CHECK_XF("<scale value=\"2\"/><translate x=\"1\"/>",
           {{2, 0, 0, 1}, {0, 2, 0, 0}, {0, 0, 2, 0}, {0, 0, 0, 1}});
  /* rotate z 90 then translate x 1: T * R */
  CHECK_XF("<rotate z=\"1\" angle=\"90\"/><translate x=\"1\"/>",
           {{0, -1, 0, 1}, {1, 0, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}});
  /* translate x 1 then rotate z 90: R * T moves the translation to +y */
  CHECK_XF("<translate x=\"1\"/><rotate z=\"1\" angle=\"90\"/>",
           {{0, -1, 0, 0}, {1, 0, 0, 1}, {0, 0, 1, 0}, {0, 0, 0, 1}});

  /* bad operations fail on their own line */
  node *root;
  rsw_err err;
  CHECK(parse_str("<scene version=\"3.0.0\"><shape type=\"t\">\n<transform name=\"a\">\n"
                  "<rotate angle=\"30\"/></transform></shape></scene>",
                  NULL, 0, &root, &err) == RSW_ERR_INVALID &&
            strcmp(err.where, "t.xml:3") == 0,
        "zero rotation axis: %s %s", err.where, err.msg);
  CHECK(parse_str("<scene version=\"3.0.0\"><shape type=\"t\"><transform name=\"a\">"
                  "<matrix value=\"1 0 0 0 0 1 0 0 0 0 0 0 0 0 0 1\"/></transform></shape>"
                  "</scene>",
                  NULL, 0, &root, &err) == RSW_ERR_INVALID,
        "singular matrix must fail: %s", err.msg);
  CHECK(parse_str("<scene version=\"3.0.0\"><shape type=\"t\"><transform name=\"a\">"
                  "<lookat origin=\"0 0 0\" target=\"0 0 1\" up=\"0 0 3\"/></transform>"
                  "</shape></scene>",
                  NULL, 0, &root, &err) == RSW_ERR_INVALID,
        "up parallel to dir must fail: %s", err.msg);
  CHECK(parse_str("<scene version=\"3.0.0\"><shape type=\"t\"><transform name=\"a\">"
                  "<lookat origin=\"0 0\" target=\"0 0 1\"/></transform></shape></scene>",
                  NULL, 0, &root, &err) == RSW_ERR_INVALID,
        "two-number origin must fail: %s", err.msg);
  CHECK(parse_str("<scene version=\"3.0.0\"><shape type=\"t\"><transform name=\"a\">"
                  "<scale value=\"1e200\"/><scale value=\"1e200\"/></transform></shape></scene>",
                  NULL, 0, &root, &err) == RSW_ERR_INVALID,
        "overflowing transform must fail: %s", err.msg);
}

/* ---- properties ---------------------------------------------------------------- */

static void test_properties(void) {
  const char *xml = "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n"
                    "<scene version=\"3.0.0\" variant=\"mono\">\n"     /* 2 */
                    "  <!-- a comment -->\n"                           /* 3 */
                    "  <bsdf type=\"diffuse\" id=\"white\">\n"         /* 4 */
                    "    <rgb name=\"reflectance\" value=\"0.25\"/>\n" /* 5 */
                    "  </bsdf>\n"
                    "  <shape type=\"sphere\" name=\"ball\">\n" /* 7 */
                    "    <integer name=\"a\" value=\"-9007199254740992\"/>\n"
                    "    <integer name=\"b\" value=\" +7 \"/>\n"
                    "    <float name=\"c\" value=\"-1.5e-3\"/>\n" /* 10 */
                    "    <boolean name=\"d\" value=\"TRUE\"/>\n"
                    "    <boolean name=\"e\" value=\"false\"/>\n"
                    "    <string name=\"f\" value=\"a b &amp; c\"/>\n"
                    "    <point name=\"g\" value=\"1.5\"/>\n"
                    "    <vector name=\"h\" y=\"2\"/>\n" /* 15 */
                    "    <spectrum name=\"i\" value=\"0.75\"/>\n"
                    "    <spectrum name=\"j\" value=\"400:0.1, 500:0.2,600:0.4\n 700:0.8\"/>\n"
                    "    <ref id=\"white\"/>\n" /* 19: j spans two lines */
                    "    <ref name=\"interior\" id=\"white\"/>\n"
                    "    <texture type=\"checkerboard\" name=\"k\"/>\n" /* 21 */
                    "  </shape>\n"
                    "</scene>\n";
  node *root = NULL;
  char *variant = NULL;
  rsw_err err;
  rsw_err_clear(&err);
  rsw_status st = scene_read_xml(xml, strlen(xml), "p.xml", NULL, 0, &root, &variant, &err);
  REQUIRE(st == RSW_OK, "parse failed: %s: %s", err.where, err.msg);
  CHECK(variant && strcmp(variant, "mono") == 0, "variant %s", variant ? variant : "(null)");
  free(variant);
  node *bsdf = child(root, 0), *shape = child(root, 1);
  REQUIRE(bsdf && shape, "two objects");
  CHECK(strcmp(bsdf->id, "white") == 0 && bsdf->id_explicit, "explicit id");
  prop *refl = node_find(bsdf, "reflectance");
  CHECK(refl && refl->spec.kind == SPEC_RGB && refl->spec.rgb[0] == 0.25 && refl->spec.rgb[1] == 0.25 &&
            refl->spec.rgb[2] == 0.25,
        "single-value rgb is replicated");
  CHECK(strcmp(root->props[1].name, "ball") == 0, "named object prop name %s", root->props[1].name);
  CHECK(strcmp(shape->id, "sphere") == 0, "generated id %s", shape->id);
  CHECK(strcmp(shape->loc, "p.xml:7") == 0, "shape loc %s", shape->loc);

  prop *p;
  p = node_find(shape, "a");
  CHECK(p && p->is_int && p->num == -9007199254740992.0, "integer -2^53");
  p = node_find(shape, "b");
  CHECK(p && p->is_int && p->num == 7, "integer with blanks... %g", p ? p->num : -1);
  p = node_find(shape, "c");
  CHECK(p && !p->is_int && p->num == -1.5e-3 && strcmp(p->loc, "p.xml:10") == 0, "float");
  p = node_find(shape, "d");
  CHECK(p && p->kind == PROP_BOOL && p->b, "boolean TRUE");
  p = node_find(shape, "e");
  CHECK(p && p->kind == PROP_BOOL && !p->b, "boolean false");
  p = node_find(shape, "f");
  CHECK(p && p->kind == PROP_STRING && strcmp(p->str, "a b & c") == 0, "string with entity");
  p = node_find(shape, "g");
  CHECK(p && p->kind == PROP_VEC3 && p->vec.x == 1.5 && p->vec.y == 1.5 && p->vec.z == 1.5,
        "point value replicated");
  p = node_find(shape, "h");
  CHECK(p && p->kind == PROP_VEC3 && p->vec.x == 0 && p->vec.y == 2 && p->vec.z == 0,
        "vector x/z default to 0");
  p = node_find(shape, "i");
  CHECK(p && p->kind == PROP_SPECTRUM && p->spec.kind == SPEC_UNIFORM && p->spec.value == 0.75,
        "uniform spectrum");
  p = node_find(shape, "j");
  REQUIRE(p && p->kind == PROP_SPECTRUM && p->spec.kind == SPEC_TABLE && p->spec.n == 4,
          "tabulated spectrum");
  static const double wl[4] = {400, 500, 600, 700}, val[4] = {0.1, 0.2, 0.4, 0.8};
  for (int i = 0; i < 4; i++)
    CHECK(p->spec.wl[i] == wl[i] && p->spec.val[i] == val[i], "sample %d: %g:%g", i, p->spec.wl[i],
          p->spec.val[i]);
  REQUIRE(shape->n_props == 13, "shape has %zu props", shape->n_props);
  p = &shape->props[10];
  CHECK(p->kind == PROP_REF && strcmp(p->name, "") == 0 && strcmp(p->ref, "white") == 0 &&
            strcmp(p->loc, "p.xml:19") == 0,
        "unnamed ref");
  p = node_find(shape, "interior");
  CHECK(p && p->kind == PROP_REF && strcmp(p->ref, "white") == 0, "named ref");
  p = node_find(shape, "k");
  CHECK(p && p->kind == PROP_NODE && strcmp(p->child->tag, "texture") == 0 &&
            strcmp(p->child->id, "checkerboard") == 0,
        "named nested texture");
  node_free(root);

  /* numbers: strict, finite, within limits */
  static const char *const bad[] = {
      "<integer name=\"x\" value=\"9007199254740993\"/>",
      "<integer name=\"x\" value=\"99999999999999999999999\"/>",
      "<integer name=\"x\" value=\"1e3\"/>",
      "<integer name=\"x\" value=\"\"/>",
      "<float name=\"x\" value=\"1e999\"/>",
      "<float name=\"x\" value=\"inf\"/>",
      "<float name=\"x\" value=\"0x10\"/>",
      "<float name=\"x\" value=\"1.0.0\"/>",
      "<float name=\"x\" value=\"1 2\"/>",
      "<float name=\"x\"/>",
      "<boolean name=\"x\" value=\"1\"/>",
      "<rgb name=\"x\" value=\"1, 2, 3, 4\"/>",
      "<rgb name=\"x\" value=\"\"/>",
      "<spectrum name=\"x\" value=\"500:1\"/>",
      "<spectrum name=\"x\" value=\"500:1, 400:2\"/>",
      "<spectrum name=\"x\" value=\"-5:1, 400:2\"/>",
      "<spectrum name=\"x\" value=\"400:1, 500\"/>",
      "<spectrum name=\"x\" value=\"1 2\"/>",
      "<spectrum name=\"x\" value=\"1\" filename=\"a.spd\"/>",
      "<vector name=\"x\" value=\"1 2\"/>",
      "<vector name=\"x\" x=\"a\"/>",
      "<string name=\"_x\" value=\"reserved\"/>",
      "<string value=\"no name\"/>",
      "<ref name=\"r\"/>",
      "<bsdf type=\"\"/>",
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    char doc[512];
    snprintf(doc, sizeof doc, "<scene version=\"3.0.0\">\n<shape type=\"s\">\n%s\n</shape></scene>", bad[i]);
    st = parse_str(doc, NULL, 0, &root, &err);
    CHECK(st != RSW_OK && strcmp(err.where, "t.xml:3") == 0 && root == NULL,
          "%s: status %d where \"%s\" msg %s", bad[i], st, err.where, err.msg);
  }
}

/* ---- $param substitution -------------------------------------------------------- */

static double float_prop(const node *root, const char *name) {
  node *shape = child(root, 0);
  prop *p = shape ? node_find(shape, name) : NULL;
  return p && p->kind == PROP_NUMBER ? p->num : -1;
}

static void test_params(void) {
  const char *xml = "<scene version=\"3.0.0\">\n"
                    "  <default name=\"r\" value=\"2\"/>\n"
                    "  <default name=\"rr\" value=\"7\"/>\n"
                    "  <default name=\"kind\" value=\"sph\"/>\n"
                    "  <shape type=\"${kind}ere\">\n"
                    "    <float name=\"a\" value=\"$r\"/>\n"
                    "    <float name=\"b\" value=\"$rr\"/>\n"
                    "    <float name=\"c\" value=\"1$r.5\"/>\n"
                    "  </shape>\n"
                    "</scene>\n";
  /* "${kind}" is not Mitsuba syntax: "$" followed by "{" names no parameter */
  node *root;
  rsw_err err;
  rsw_status st = parse_str(xml, NULL, 0, &root, &err);
  CHECK(st == RSW_ERR_INVALID && strcmp(err.where, "t.xml:5") == 0 && strstr(err.msg, "$"),
        "${...} must be undefined: %d %s %s", st, err.where, err.msg);

  xml = "<scene version=\"3.0.0\">\n"
        "  <default name=\"r\" value=\"2\"/>\n"
        "  <default name=\"rr\" value=\"7\"/>\n"
        "  <default name=\"kind\" value=\"sph\"/>\n"
        "  <shape type=\"$kindere\">\n"
        "    <float name=\"a\" value=\"$r\"/>\n"
        "    <float name=\"b\" value=\"$rr\"/>\n"
        "    <float name=\"c\" value=\"1$r.5\"/>\n"
        "    <float name=\"d\" value=\"$extra\"/>\n"
        "  </shape>\n"
        "</scene>\n";
  /* defaults only: $extra is undefined (line 9) */
  st = parse_str(xml, NULL, 0, &root, &err);
  CHECK(st == RSW_ERR_INVALID && strcmp(err.where, "t.xml:9") == 0 && strstr(err.msg, "$extra"),
        "undefined $extra: %d %s %s", st, err.where, err.msg);

  /* a -D define that no <default> declares is accepted (as Mitsuba) */
  scene_define d1[] = {{"extra", "4"}};
  st = parse_str(xml, d1, 1, &root, &err);
  REQUIRE(st == RSW_OK, "with -D extra: %s %s", err.where, err.msg);
  CHECK(strcmp(child(root, 0)->type, "sphere") == 0, "type from $kind: %s", child(root, 0)->type);
  CHECK(float_prop(root, "a") == 2, "a = $r default");
  CHECK(float_prop(root, "b") == 7, "b = $rr (longest name wins)");
  CHECK(float_prop(root, "c") == 12.5, "c = 1$r.5 = 12.5");
  CHECK(float_prop(root, "d") == 4, "d = $extra from -D");
  node_free(root);

  /* defines override defaults */
  scene_define d2[] = {{"r", "3"}, {"extra", "0.5"}};
  st = parse_str(xml, d2, 2, &root, &err);
  REQUIRE(st == RSW_OK, "with overrides: %s %s", err.where, err.msg);
  CHECK(float_prop(root, "a") == 3, "a = -D r");
  CHECK(float_prop(root, "b") == 7, "b unaffected by -D r");
  CHECK(float_prop(root, "c") == 13.5, "c = 1$r.5 with r = 3");
  CHECK(float_prop(root, "d") == 0.5, "d = -D extra");
  node_free(root);

  /* A define that no <default> declares and no $name uses is an error
   * naming it (Mitsuba ignores it: a misspelt -D rr0=9 would leave $rr at
   * its default without a word); the closest declared name is offered. */
  scene_define d3[] = {{"extra", "1"}, {"unused", "x"}};
  st = parse_str(xml, d3, 2, &root, &err);
  CHECK(st == RSW_ERR_UNKNOWN_NAME && strcmp(err.where, "-D unused") == 0 &&
            strstr(err.msg, "it declares: r, rr, kind"),
        "an unused -D: %d %s %s", (int)st, err.where, err.msg);
  if (st == RSW_OK) node_free(root);
  scene_define d4[] = {{"extra", "1"}, {"rr0", "9"}};
  st = parse_str(xml, d4, 2, &root, &err);
  CHECK(st == RSW_ERR_UNKNOWN_NAME && strstr(err.msg, "did you mean \"rr\"?"), "a misspelt -D: %d %s",
        (int)st, err.msg);
  if (st == RSW_OK) node_free(root);
  /* a declared default that nothing uses may still be set */
  scene_define d5[] = {{"idle", "1"}};
  st = parse_str("<scene version=\"3.0.0\">\n<default name=\"idle\" value=\"0\"/></scene>", d5, 1, &root,
                 &err);
  CHECK(st == RSW_OK, "a -D of a declared, unused default: %s %s", err.where, err.msg);
  if (st == RSW_OK) node_free(root);

  /* a default must precede its use; one declaration per name */
  st = parse_str("<scene version=\"3.0.0\">\n<shape type=\"s\"><float name=\"a\" value=\"$r\"/>"
                 "</shape>\n<default name=\"r\" value=\"1\"/></scene>",
                 NULL, 0, &root, &err);
  CHECK(st == RSW_ERR_INVALID && strcmp(err.where, "t.xml:2") == 0, "use before default");
  st = parse_str("<scene version=\"3.0.0\">\n<default name=\"r\" value=\"1\"/>\n"
                 "<default name=\"r\" value=\"2\"/></scene>",
                 NULL, 0, &root, &err);
  CHECK(st == RSW_ERR_DUPLICATE && strcmp(err.where, "t.xml:3") == 0, "duplicate default");
  /* a lone '$' is an error too */
  st = parse_str("<scene version=\"3.0.0\">\n<shape type=\"s\">\n<string name=\"a\" value=\"5$\"/>"
                 "</shape></scene>",
                 NULL, 0, &root, &err);
  CHECK(st == RSW_ERR_INVALID && strcmp(err.where, "t.xml:3") == 0, "lone $: %s", err.msg);
  /* bad defines */
  scene_define dup[] = {{"r", "1"}, {"r", "2"}};
  st = parse_str("<scene version=\"3.0.0\"/>", dup, 2, &root, &err);
  CHECK(st == RSW_ERR_USAGE, "duplicate -D: %d", st);
  scene_define empty[] = {{"", "1"}};
  st = parse_str("<scene version=\"3.0.0\"/>", empty, 1, &root, &err);
  CHECK(st == RSW_ERR_USAGE, "empty -D name: %d", st);
}

/* ---- generated ids ------------------------------------------------------------- */

/* Unnamed objects get type, type_1, ... in depth-first document order,
 * skipping ids written explicitly anywhere in the document. */
static void test_generated_ids(void) {
  const char *xml = "<scene version=\"3.0.0\">\n"
                    "  <bsdf type=\"d\"/>\n"
                    "  <shape type=\"s\"><bsdf type=\"d\"/><bsdf type=\"e\"/></shape>\n"
                    "  <bsdf type=\"d\"/>\n"
                    "  <bsdf type=\"x\" id=\"d_1\"/>\n"
                    "  <bsdf type=\"x\" id=\"x\"/>\n"
                    "  <bsdf type=\"x\"/>\n"
                    "  <bsdf type=\"d\"/>\n"
                    "</scene>\n";
  node *root;
  rsw_err err;
  REQUIRE(parse_str(xml, NULL, 0, &root, &err) == RSW_OK, "%s %s", err.where, err.msg);
  static const char *const want[] = {"d", "s", "d_3", "d_1", "x", "x_1", "d_4"};
  REQUIRE(root->n_props == 7, "%zu children", root->n_props);
  for (size_t i = 0; i < 7; i++)
    CHECK(strcmp(child(root, i)->id, want[i]) == 0, "child %zu id %s, want %s", i, child(root, i)->id,
          want[i]);
  node *shape = child(root, 1);
  /* the shape's children come before the later top-level objects */
  CHECK(strcmp(child(shape, 0)->id, "d_2") == 0, "nested id %s", child(shape, 0)->id);
  CHECK(strcmp(child(shape, 1)->id, "e") == 0, "nested id %s", child(shape, 1)->id);
  node_free(root);
}

/* ---- versions and limits ----------------------------------------------------- */

static void test_versions(void) {
  static const struct {
    const char *version;
    rsw_status want;
  } cases[] = {
      {"2.1.0", RSW_OK},
      {"3.0.0", RSW_OK},
      {"2.0.0", RSW_OK},
      {"3.5.12", RSW_OK},
      {"0.6.0", RSW_ERR_UNSUPPORTED},
      {"1.9.9", RSW_ERR_UNSUPPORTED},
      {"4.0.0", RSW_ERR_UNSUPPORTED},
      {"3.0", RSW_ERR_PARSE},
      {"3.0.0.1", RSW_ERR_PARSE},
      {"v3.0.0", RSW_ERR_PARSE},
      {"", RSW_ERR_PARSE},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    char xml[256];
    snprintf(xml, sizeof xml, "\n<scene version=\"%s\">\n<integrator type=\"path\"/>\n</scene>",
             cases[i].version);
    node *root;
    rsw_err err;
    rsw_status st = parse_str(xml, NULL, 0, &root, &err);
    CHECK(st == cases[i].want, "version \"%s\": status %d, want %d (%s)", cases[i].version, st, cases[i].want,
          err.msg);
    if (st != RSW_OK) CHECK(strcmp(err.where, "t.xml:2") == 0, "version error where %s", err.where);
    node_free(root);
  }
}

static void test_limits(void) {
  node *root = (node *)&root; /* sentinel: must stay untouched on failure */
  rsw_err err;
  rsw_err_clear(&err);
  /* The size check comes before any byte is read, so a short buffer with a
   * large claimed length exercises it without allocating 256 MiB. */
  static const char tiny[] = "<scene version=\"3.0.0\"/>";
  rsw_status st = scene_read_xml(tiny, ((size_t)256 << 20) + 1, "big.xml", NULL, 0, &root, NULL, &err);
  CHECK(st == RSW_ERR_LIMIT && strcmp(err.where, "big.xml:1") == 0, "size limit: %d %s", st, err.where);
  CHECK(root == (node *)&root, "root_out written on failure");

  /* exactly RSW_MAX_DEPTH nested elements are fine, one more is not */
  size_t cap = 64 * 32 + 256;
  char *doc = malloc(cap);
  REQUIRE(doc, "oom");
  for (int extra = 0; extra <= 1; extra++) {
    int levels = RSW_MAX_DEPTH - 1 + extra; /* plus the <scene> */
    size_t n = (size_t)snprintf(doc, cap, "<scene version=\"3.0.0\">");
    for (int i = 0; i < levels; i++) n += (size_t)snprintf(doc + n, cap - n, "<bsdf type=\"d\">");
    for (int i = 0; i < levels; i++) n += (size_t)snprintf(doc + n, cap - n, "</bsdf>");
    snprintf(doc + n, cap - n, "</scene>");
    st = parse_str(doc, NULL, 0, &root, &err);
    CHECK(st == (extra ? RSW_ERR_LIMIT : RSW_OK), "depth %d: status %d (%s)", levels + 1, st, err.msg);
    if (st == RSW_OK) {
      /* generated ids: d, d_1, ..., in depth-first order */
      node *outer = child(root, 0);
      CHECK(outer && strcmp(outer->id, "d") == 0, "outer id");
      node *inner = child(outer, 0);
      CHECK(inner && strcmp(inner->id, "d_1") == 0, "second id");
      node_free(root);
    }
  }
  free(doc);

  /* the error record the caller passes in is overwritten, not kept */
  rsw_fail(&err, RSW_ERR_IO, "old", "stale");
  st = scene_read_xml("<x/>", 4, "e.xml", NULL, 0, &root, NULL, &err);
  CHECK(st == RSW_ERR_PARSE && strcmp(err.where, "e.xml:1") == 0, "stale error replaced");
  /* NULL source name, NULL text */
  st = scene_read_xml(NULL, 0, NULL, NULL, 0, &root, NULL, &err);
  CHECK(st == RSW_ERR_PARSE && strstr(err.where, ":1") != NULL, "NULL text: %s", err.where);
}

/* ---- the memory cap counts the whole tree --------------------------------------- */

static size_t str_bytes(const char *s) {
  return s ? strlen(s) + 1 : 0;
}

/* Memory of a tree as allocated, recounted from its fields: structs,
 * strings, the property arrays and name indexes at their capacity, and
 * what each property owns. Generated ids (given after reading) are left
 * out. */
static size_t tree_bytes(const node *n) {
  size_t b = sizeof *n + str_bytes(n->tag) + str_bytes(n->type) + str_bytes(n->loc) +
             (n->id_explicit ? str_bytes(n->id) : 0) + n->cap_props * sizeof(prop) +
             n->index_cap * sizeof(size_t);
  for (size_t i = 0; i < n->n_props; i++) {
    const prop *p = &n->props[i];
    b += str_bytes(p->name) + str_bytes(p->loc) + str_bytes(p->str) + str_bytes(p->ref) +
         p->n_nums * sizeof(double) + 2 * p->spec.n * sizeof(double);
    if (p->child) b += tree_bytes(p->child);
  }
  return b;
}

/* The reader's count equals that recount: a cap of exactly the tree's
 * memory reads, one byte less fails. Before the fix the count left out
 * string values, spectrum samples, explicit ids, the root, and the
 * growth of property arrays and name indexes (a shapegroup of 40 members
 * has a 128-slot index), so the cap could be passed unnoticed. */
static void test_memory_count(void) {
  size_t cap = 64 << 10, n = 0;
  char *doc = malloc(cap);
  REQUIRE(doc, "oom");
  n += (size_t)snprintf(doc + n, cap - n,
                        "<scene version=\"3.0.0\">\n<default name=\"p\" value=\"a longer string value\"/>\n"
                        "<bsdf type=\"diffuse\" id=\"leaf\"><spectrum name=\"reflectance\" "
                        "value=\"400:0.1, 500:0.2, 600:0.3, 700:0.4, 800:0.5, 900:0.6, 1000:0.7, 1100:0.8, "
                        "1200:0.9, 1300:0.9, 1400:0.9, 1500:0.9, 1600:0.9, 1700:0.9, 1800:0.9, 1900:0.9, "
                        "2000:0.9\"/></bsdf>\n<shape type=\"shapegroup\" id=\"g\">\n");
  for (int i = 0; i < 40; i++)
    n += (size_t)snprintf(
        doc + n, cap - n,
        "<shape type=\"disk\" name=\"d%d\"><string name=\"note\" value=\"$p $p %d\"/><ref id=\"leaf\"/>"
        "<transform name=\"to_world\"><translate x=\"%d\"/></transform></shape>\n",
        i, i, i);
  n += (size_t)snprintf(doc + n, cap - n, "</shape>\n</scene>\n");
  REQUIRE(n < cap, "document buffer too small");
  node *root = NULL;
  rsw_err err;
  rsw_err_clear(&err);
  REQUIRE(scene_read_xml(doc, strlen(doc), "m.xml", NULL, 0, &root, NULL, &err) == RSW_OK, "read: %s: %s",
          err.where, err.msg);
  size_t total = tree_bytes(root);
  node *g = child(root, 1);
  CHECK(g && g->index_cap >= 80, "the group has a name index (index_cap %zu)", g ? g->index_cap : 0);
  node_free(root);
  printf("  tree of %zu bytes\n", total);
  scene_limits lim = scene_limits_default;
  for (int less = 0; less <= 1; less++) {
    lim.max_tree_bytes = total - (size_t)less;
    root = NULL;
    rsw_err_clear(&err);
    rsw_status st = scene_read_xml_limited(doc, strlen(doc), "m.xml", NULL, 0, &lim, &root, NULL, &err);
    CHECK(st == (less ? RSW_ERR_LIMIT : RSW_OK), "cap of %zu bytes: status %d (%s: %s)", lim.max_tree_bytes,
          (int)st, err.where, err.msg);
    if (less) CHECK(strstr(err.msg, "memory cap of") != NULL, "message '%s'", err.msg);
    node_free(root);
  }
  free(doc);
}

/* ---- a bad value names its property (found by tests/corpus/http) ---------------- */

static void test_value_errors_name_property(void) {
  static const char *const docs[] = {
      "<scene version=\"3.0.0\"><shape type=\"sphere\"><float name=\"radius\" value=\"x\"/></shape></scene>",
      "<scene version=\"3.0.0\"><sensor type=\"p\"><integer name=\"width\" value=\"3.5\"/></sensor></scene>",
      "<scene version=\"3.0.0\"><shape type=\"obj\"><boolean name=\"flip_normals\" "
      "value=\"yes\"/></shape></scene>",
  };
  static const char *const names[] = {"radius", "width", "flip_normals"};
  for (size_t i = 0; i < 3; i++) {
    node *root;
    rsw_err err;
    rsw_status st = parse_str(docs[i], NULL, 0, &root, &err);
    CHECK(st == RSW_ERR_INVALID && strstr(err.msg, names[i]) != NULL, "%s: status %d, message '%s'", names[i],
          st, err.msg);
    node_free(root);
  }
}

/* ---- malformed corpus ------------------------------------------------------------ */

/* Expected line of a corpus file from its README entry "name: ... -- line N";
 * 0 when the README has no entry. */
static unsigned long readme_line(const char *readme, const char *file) {
  size_t fl = strlen(file);
  for (const char *p = readme; p && *p; p = strchr(p, '\n') ? strchr(p, '\n') + 1 : NULL) {
    if (strncmp(p, file, fl) == 0 && p[fl] == ':') {
      const char *eol = strchr(p, '\n');
      const char *tag = strstr(p, "-- line ");
      if (tag && (!eol || tag < eol)) return strtoul(tag + 8, NULL, 10);
      return 0;
    }
  }
  return 0;
}

static void test_bad_corpus(void) {
  char dir[1024], path[1400];
  src_path(dir, sizeof dir, "tests/corpus/bad");
  snprintf(path, sizeof path, "%s/README.xml.txt", dir);
  size_t rlen;
  char *readme = slurp(path, &rlen);
  REQUIRE(readme, "cannot read %s", path);
  DIR *d = opendir(dir);
  if (!d) free(readme);
  REQUIRE(d, "cannot open %s", dir);
  int count = 0;
  struct dirent *e;
  while ((e = readdir(d))) {
    const char *nm = e->d_name;
    size_t l = strlen(nm);
    if (strncmp(nm, "bad_xml_", 8) != 0 || l < 4 || strcmp(nm + l - 4, ".xml") != 0) continue;
    count++;
    snprintf(path, sizeof path, "%s/%s", dir, nm);
    size_t len;
    char *text = slurp(path, &len);
    CHECK(text, "cannot read %s", path);
    if (!text) continue;
    node *root = NULL;
    rsw_err err;
    rsw_err_clear(&err);
    rsw_status st = scene_read_xml(text, len, nm, NULL, 0, &root, NULL, &err);
    free(text);
    unsigned long want = readme_line(readme, nm);
    CHECK(want > 0, "%s has no \"-- line N\" entry in README.xml.txt", nm);
    char where[300];
    snprintf(where, sizeof where, "%s:%lu", nm, want);
    CHECK(st != RSW_OK && root == NULL, "%s must fail (status %d)", nm, st);
    CHECK(strcmp(err.where, where) == 0, "%s: where \"%s\", want \"%s\" (%s)", nm, err.where, where, err.msg);
    CHECK(err.msg[0] != '\0', "%s: empty message", nm);
    if (st == RSW_OK) node_free(root);
  }
  closedir(d);
  free(readme);
  CHECK(count >= 15, "only %d bad_xml_*.xml files", count);
}

int main(void) {
  RSW_TEST_RUN(test_seed_scene);
  RSW_TEST_RUN(test_transform_ops);
  RSW_TEST_RUN(test_properties);
  RSW_TEST_RUN(test_params);
  RSW_TEST_RUN(test_generated_ids);
  RSW_TEST_RUN(test_versions);
  RSW_TEST_RUN(test_limits);
  RSW_TEST_RUN(test_memory_count);
  RSW_TEST_RUN(test_bad_corpus);
  RSW_TEST_RUN(test_value_errors_name_property);
  RSW_TEST_END("test_xml_read");
}
