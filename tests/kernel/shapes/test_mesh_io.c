/* OBJ and PLY loading: small meshes with known contents (written here into
 * a mkdtemp() directory, plus the checked-in fixtures in tests/data), and
 * every malformed file of tests/corpus/bad/meshes failing with the right
 * status and location. */
#include <dirent.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../support/test.h"
#include "kernel/shapes/mesh_io.h"

RSW_TEST_DEFINE_GLOBALS

static char tmpdir[256];

static const char *tpath(const char *name) {
  static char buf[512];
  snprintf(buf, sizeof buf, "%s/%s", tmpdir, name);
  return buf;
}

/* tests/ directory: $RSW_TEST_DIR (set by tests/run.sh) or ./tests. */
static const char *test_dir(void) {
  const char *d = getenv("RSW_TEST_DIR");
  return d && d[0] ? d : "tests";
}

static const char *data_path(const char *rel) {
  static char buf[1024];
  snprintf(buf, sizeof buf, "%s/%s", test_dir(), rel);
  return buf;
}

static const char *write_file(const char *name, const void *data, size_t n) {
  const char *p = tpath(name);
  FILE *f = fopen(p, "wb");
  if (!f) return p;
  fwrite(data, 1, n, f);
  fclose(f);
  return p;
}

static const char *write_text(const char *name, const char *s) {
  return write_file(name, s, strlen(s));
}

/* Full error text "where: msg". */
static const char *err_text(const rsw_err *e) {
  static char buf[1200];
  return rsw_err_format(e, buf, sizeof buf);
}

/* Corner i of triangle f. */
static const float *corner(const mesh *m, uint32_t f, int i) {
  return m->pos + 3 * (size_t)m->faces[3 * (size_t)f + i];
}

static double tri_area_sum(const mesh *m) {
  double sum = 0;
  for (uint32_t f = 0; f < m->n_faces; f++) {
    const float *a = corner(m, f, 0), *b = corner(m, f, 1), *c = corner(m, f, 2);
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    double e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double x = e1[1] * e2[2] - e1[2] * e2[1];
    double y = e1[2] * e2[0] - e1[0] * e2[2];
    double z = e1[0] * e2[1] - e1[1] * e2[0];
    sum += 0.5 * sqrt(x * x + y * y + z * z);
  }
  return sum;
}

/* The fixture quad: [-1,1]^2 at z = 0, normal +z, uv = ((x+1)/2, (y+1)/2)
 * (before any flip), triangles (0,1,2), (0,2,3). */
static void check_quad(const mesh *m, bool flipped, const char *what) {
  REQUIRE(m->n_verts == 4 && m->n_faces == 2, "%s: %u verts %u faces", what, m->n_verts, m->n_faces);
  REQUIRE(m->uv && m->nrm, "%s: uv %p nrm %p", what, (void *)m->uv, (void *)m->nrm);
  const float want[4][3] = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  for (uint32_t i = 0; i < 4; i++) {
    for (int c = 0; c < 3; c++)
      CHECK(m->pos[3 * i + c] == want[i][c], "%s: pos[%u][%d] = %g", what, i, c, m->pos[3 * i + c]);
    CHECK(m->nrm[3 * i] == 0 && m->nrm[3 * i + 1] == 0 && m->nrm[3 * i + 2] == 1, "%s: normal %u", what, i);
    float u = (want[i][0] + 1) / 2, v = (want[i][1] + 1) / 2;
    if (flipped) v = 1 - v;
    CHECK(m->uv[2 * i] == u && m->uv[2 * i + 1] == v, "%s: uv %u = (%g, %g), want (%g, %g)", what, i,
          m->uv[2 * i], m->uv[2 * i + 1], u, v);
  }
  const uint32_t tris[6] = {0, 1, 2, 0, 2, 3};
  for (int i = 0; i < 6; i++) CHECK(m->faces[i] == tris[i], "%s: faces[%d] = %u", what, i, m->faces[i]);
}

static void test_fixture_quads(void) {
  mesh m;
  rsw_err err = {0};
  REQUIRE(mesh_load_obj(data_path("data/quad.obj"), false, &m, &err) == RSW_OK, "%s", err_text(&err));
  check_quad(&m, false, "quad.obj");
  mesh_free(&m);
  REQUIRE(mesh_load_obj(data_path("data/quad.obj"), true, &m, &err) == RSW_OK, "%s", err_text(&err));
  check_quad(&m, true, "quad.obj flipped");
  mesh_free(&m);
  REQUIRE(mesh_load_ply(data_path("data/quad_le.ply"), &m, &err) == RSW_OK, "%s", err_text(&err));
  check_quad(&m, false, "quad_le.ply");
  mesh_free(&m);
  mesh_free(&m); /* zeroed: a second free is a no-op */
  mesh_free(NULL);
}

/* Cube [-1,1]^3 with 8 shared positions and one normal per face: the
 * (v, vn) dedup gives 24 vertices, 6 quads give 12 triangles. Written with
 * CRLF line endings, comments and statements we ignore. */
static const char cube_obj[] = "# cube\r\nmtllib cube.mtl\r\no cube\r\ng side\r\nusemtl white\r\n"
                               "v -1 -1 -1\r\nv 1 -1 -1\r\nv 1 1 -1\r\nv -1 1 -1\r\n"
                               "v -1 -1 1\r\nv 1 -1 1\r\nv 1 1 1\r\nv -1 1 1\r\n"
                               "vn 0 0 -1\r\nvn 0 0 1\r\nvn 0 -1 0\r\nvn 0 1 0\r\nvn -1 0 0\r\n"
                               "vn 1 0 0\r\ns 1\r\n"
                               "f 1//1 4//1 3//1 2//1\r\n"
                               "f 5//2 6//2 7//2 8//2  # top\r\n"
                               "f 1//3 2//3 6//3 5//3\r\n"
                               "f 4//4 8//4 7//4 3//4\r\n"
                               "f 1//5 5//5 8//5 4//5\r\n"
                               "f\t2//6\t3//6\t7//6\t6//6\r\n";

static void test_obj_cube(void) {
  mesh m;
  rsw_err err = {0};
  const char *p = write_text("cube.obj", cube_obj);
  REQUIRE(mesh_load_obj(p, true, &m, &err) == RSW_OK, "%s", err_text(&err));
  CHECK(m.n_verts == 24, "verts %u", m.n_verts);
  CHECK(m.n_faces == 12, "faces %u", m.n_faces);
  CHECK(m.uv == NULL, "uvs without vt");
  REQUIRE(m.nrm != NULL, "normals lost");
  CHECK_REL(tri_area_sum(&m), 24.0, 1e-12);
  /* Every triangle's normal (right-handed winding) matches its vertex
   * normals: the fan kept the winding. */
  int bad = 0;
  for (uint32_t f = 0; f < m.n_faces; f++) {
    const float *a = corner(&m, f, 0), *b = corner(&m, f, 1), *c = corner(&m, f, 2);
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    double e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                   e1[0] * e2[1] - e1[1] * e2[0]};
    const float *vn = m.nrm + 3 * (size_t)m.faces[3 * f];
    if (n[0] * vn[0] + n[1] * vn[1] + n[2] * vn[2] <= 0) bad++;
  }
  CHECK(bad == 0, "%d triangles wound against their normals", bad);
  mesh_free(&m);
}

static void test_obj_negative_and_forms(void) {
  /* Negative indices count back from the last element defined so far;
   * mixed corner forms; a vertex reused with the same (v, vt) is shared. */
  const char *src = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 1.0\n" /* w ignored */
                    "vt 0.25 0.75\nvt 0.5\n"                   /* v defaults to 0 */
                    "f -4/-2 -3/-1 -2/-1\n"                    /* (0,vt0) (1,vt1) (2,vt1) */
                    "f 1/1 3/2 4\n";                           /* (0,vt0) (2,vt1) (3,-) */
  mesh m;
  rsw_err err = {0};
  const char *p = write_text("neg.obj", src);
  REQUIRE(mesh_load_obj(p, true, &m, &err) == RSW_OK, "%s", err_text(&err));
  CHECK(m.n_verts == 4, "verts %u (dedup of (v, vt) pairs)", m.n_verts);
  REQUIRE(m.n_faces == 2, "faces %u", m.n_faces);
  const uint32_t want[6] = {0, 1, 2, 0, 2, 3};
  for (int i = 0; i < 6; i++) CHECK(m.faces[i] == want[i], "faces[%d] = %u", i, m.faces[i]);
  REQUIRE(m.uv != NULL, "uvs lost");
  CHECK(m.nrm == NULL, "normals invented");
  /* flip: v -> 1 - v */
  CHECK(m.uv[0] == 0.25f && m.uv[1] == 0.25f, "uv0 (%g, %g)", m.uv[0], m.uv[1]);
  CHECK(m.uv[2] == 0.5f && m.uv[3] == 1.0f, "uv1 (%g, %g)", m.uv[2], m.uv[3]);
  CHECK(m.uv[6] == 0.0f && m.uv[7] == 0.0f, "corner without vt: (%g, %g)", m.uv[6], m.uv[7]);
  CHECK(m.pos[9] == 0 && m.pos[10] == 1 && m.pos[11] == 0, "v4 (%g %g %g)", m.pos[9], m.pos[10], m.pos[11]);
  mesh_free(&m);
}

/* Cube as an ascii PLY: 8 vertices, 6 quads; an extra element and a list
 * property on the faces that must be skipped. */
static const char cube_ply_ascii[] = "ply\nformat ascii 1.0\ncomment cube\n"
                                     "element vertex 8\nproperty double x\nproperty double y\n"
                                     "property double z\nproperty uchar red\n"
                                     "element face 6\nproperty list int uint vertex_index\n"
                                     "property list uchar float weights\n"
                                     "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
                                     "end_header\n"
                                     "-1 -1 -1 255\n1 -1 -1 0\n1 1 -1 0\n-1 1 -1 0\n"
                                     "-1 -1 1 0\n1 -1 1 0\n1 1 1 0\n-1 1 1 0\n"
                                     "4 0 3 2 1 2 0.5 0.5\n4 4 5 6 7 0\n4 0 1 5 4 0\n"
                                     "4 3 7 6 2 1 9\n4 0 4 7 3 0\n4 1 2 6 5 0\n"
                                     "0 1\n";

static void test_ply_ascii_cube(void) {
  mesh m;
  rsw_err err = {0};
  const char *p = write_text("cube.ply", cube_ply_ascii);
  REQUIRE(mesh_load_ply(p, &m, &err) == RSW_OK, "%s", err_text(&err));
  CHECK(m.n_verts == 8 && m.n_faces == 12, "%u verts %u faces", m.n_verts, m.n_faces);
  CHECK(m.nrm == NULL && m.uv == NULL, "attributes invented");
  CHECK_REL(tri_area_sum(&m), 24.0, 1e-12);
  CHECK(m.faces[0] == 0 && m.faces[1] == 3 && m.faces[2] == 2 && m.faces[3] == 0 && m.faces[4] == 2 &&
            m.faces[5] == 1,
        "fan of the first quad");
  mesh_free(&m);
}

/* Binary little-endian: mixed types, s/t uvs, a skipped list property on
 * the vertices, a triangle and a pentagon. */
static void test_ply_binary_types(void) {
  const char *hdr = "ply\r\nformat binary_little_endian 1.0\r\n"
                    "element vertex 5\r\nproperty float x\r\nproperty double y\r\n"
                    "property short z\r\nproperty list uchar ushort junk\r\n"
                    "property float s\r\nproperty float t\r\n"
                    "element face 2\r\nproperty uchar flags\r\n"
                    "property list uint int vertex_indices\r\nend_header\r\n";
  unsigned char buf[1024];
  size_t n = strlen(hdr);
  memcpy(buf, hdr, n);
#define PUT(v)                                                                                               \
  do {                                                                                                       \
    memcpy(buf + n, &(v), sizeof(v));                                                                        \
    n += sizeof(v);                                                                                          \
  } while (0)
  for (int i = 0; i < 5; i++) {
    float x = (float)i;
    double y = 0.5 * i;
    int16_t z = (int16_t)-i;
    uint8_t nj = (uint8_t)(i % 3);
    PUT(x);
    PUT(y);
    PUT(z);
    PUT(nj);
    for (int j = 0; j < nj; j++) {
      uint16_t junk = 0xBEEF;
      PUT(junk);
    }
    float s = 0.1f * (float)i, t = 1.0f - 0.1f * (float)i;
    PUT(s);
    PUT(t);
  }
  uint8_t flags = 7;
  uint32_t c3 = 3, c5 = 5;
  int32_t tri[3] = {4, 3, 2}, pent[5] = {0, 1, 2, 3, 4};
  PUT(flags);
  PUT(c3);
  for (int i = 0; i < 3; i++) PUT(tri[i]);
  PUT(flags);
  PUT(c5);
  for (int i = 0; i < 5; i++) PUT(pent[i]);
#undef PUT
  mesh m;
  rsw_err err = {0};
  const char *p = write_file("types.ply", buf, n);
  REQUIRE(mesh_load_ply(p, &m, &err) == RSW_OK, "%s", err_text(&err));
  CHECK(m.n_verts == 5 && m.n_faces == 4, "%u verts %u faces", m.n_verts, m.n_faces);
  REQUIRE(m.uv != NULL, "s/t not read as uv");
  CHECK(m.nrm == NULL, "normals invented");
  for (int i = 0; i < 5; i++) {
    CHECK(m.pos[3 * i] == (float)i && m.pos[3 * i + 1] == 0.5f * (float)i && m.pos[3 * i + 2] == (float)-i,
          "vertex %d = (%g %g %g)", i, m.pos[3 * i], m.pos[3 * i + 1], m.pos[3 * i + 2]);
    CHECK(m.uv[2 * i] == 0.1f * (float)i && m.uv[2 * i + 1] == 1.0f - 0.1f * (float)i, "uv %d", i);
  }
  const uint32_t want[12] = {4, 3, 2, 0, 1, 2, 0, 2, 3, 0, 3, 4};
  for (int i = 0; i < 12; i++) CHECK(m.faces[i] == want[i], "faces[%d] = %u", i, m.faces[i]);
  mesh_free(&m);
}

/* Every malformed corpus file: status and a piece of "where: msg". */
static const struct bad_case {
  const char *file;
  bool obj;
  rsw_status status;
  const char *text; /* must appear in "where: msg" */
  const char *text2;
} bad_cases[] = {
    {"bad_header.ply", false, RSW_ERR_FILE, "bad_header.ply:4:", "count"},
    {"big_endian.ply", false, RSW_ERR_UNSUPPORTED, "big_endian", "unsupported"},
    {"huge_count.ply", false, RSW_ERR_LIMIT, "huge_count.ply:4:", "exceeds"},
    {"index_out_of_range.ply", false, RSW_ERR_FILE,
     "index_out_of_range.ply:20:", "index 7 out of range [0, 4)"},
    {"index_out_of_range_binary.ply", false, RSW_ERR_FILE, "byte 425 (face 0)", "index 4 out of range"},
    {"negative_index_binary.ply", false, RSW_ERR_FILE, "(face 0)", "index -1 out of range"},
    {"nonfinite_binary.ply", false, RSW_ERR_FILE, "byte 284 (vertex 0)", "non-finite x"},
    {"no_end_header.ply", false, RSW_ERR_FILE, "no_end_header.ply:5:", "no end_header line"},
    {"no_faces.ply", false, RSW_ERR_FILE, "no_faces.ply", "no faces"},
    {"truncated_ascii.ply", false, RSW_ERR_FILE, "truncated_ascii.ply:21: face 1", "truncated:"},
    {"truncated_binary.ply", false, RSW_ERR_FILE, "(face 0)", "truncated:"},
    {"bad_number.obj", true, RSW_ERR_FILE, "bad_number.obj:4:", "bad number \"-1.x\""},
    {"index_out_of_range.obj", true, RSW_ERR_FILE,
     "index_out_of_range.obj:13:", "vertex index 5 out of range"},
    {"no_faces.obj", true, RSW_ERR_FILE, "no_faces.obj", "no faces"},
    {"nonfinite.obj", true, RSW_ERR_FILE, "nonfinite.obj:5:", "non-finite"},
    {"two_corner_face.obj", true, RSW_ERR_FILE, "two_corner_face.obj:13:", "2 corners"},
    {"zero_index.obj", true, RSW_ERR_FILE, "zero_index.obj:13:", "index 0"},
};

static void test_bad_corpus(void) {
  for (size_t i = 0; i < sizeof bad_cases / sizeof *bad_cases; i++) {
    const struct bad_case *c = &bad_cases[i];
    char rel[256];
    snprintf(rel, sizeof rel, "corpus/bad/meshes/%s", c->file);
    mesh m = {0};
    rsw_err err = {0};
    rsw_status s =
        c->obj ? mesh_load_obj(data_path(rel), true, &m, &err) : mesh_load_ply(data_path(rel), &m, &err);
    CHECK(s == c->status, "%s: status %s, want %s (%s)", c->file, rsw_status_name(s),
          rsw_status_name(c->status), err_text(&err));
    const char *t = err_text(&err);
    CHECK(strstr(t, c->text) && strstr(t, c->text2), "%s: error \"%s\" lacks \"%s\" / \"%s\"", c->file, t,
          c->text, c->text2);
    CHECK(m.pos == NULL && m.faces == NULL, "%s: output written on failure", c->file);
  }
  /* The README lists every file of the directory and nothing else. */
  DIR *d = opendir(data_path("corpus/bad/meshes"));
  REQUIRE(d, "no corpus directory");
  struct dirent *e;
  int files = 0;
  while ((e = readdir(d))) {
    if (e->d_name[0] == '.' || strcmp(e->d_name, "README") == 0) continue;
    files++;
    bool listed = false;
    for (size_t i = 0; i < sizeof bad_cases / sizeof *bad_cases; i++)
      listed |= strcmp(bad_cases[i].file, e->d_name) == 0;
    CHECK(listed, "corpus file %s has no test case", e->d_name);
  }
  closedir(d);
  CHECK(files >= 8, "only %d corpus files", files);
}

static void test_inline_errors(void) {
  static const struct {
    const char *src;
    bool obj;
    const char *text;
  } cases[] = {
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", true,
       "x.obj:4: vertex index -4 out of range (3 defined so far)"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/ 2 3\n", true, "bad face corner \"1/\""},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2 3\n", true,
       "x.obj:4: texture coordinate index 1 out of range (0 defined"},
      {"v 0 0\n", true, "x.obj:1: missing vertex coordinate"},
      {"v 0 0 nan\n", true, "x.obj:1: non-finite"},
      {"vn 0 0 1\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//2\n", true, "normal index 2 out of range"},
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
       "property float y\nend_header\n0 0\n1 1\n2 2\n",
       false, "lacks z"},
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
       "property float y\nproperty float z\nelement face 1\n"
       "property list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 0 0\n0 1 0\n3 0 1 2.5\n",
       false, "x.ply:13: face 0: non-integer"},
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
       "property float y\nproperty float z\nelement face 1\n"
       "property list float int vertex_indices\nend_header\n",
       false, "x.ply:8: bad PLY header: list count type"},
      {"ply\nformat ascii 2.0\n", false, "x.ply:2: bad PLY header"},
      {"plyx\n", false, "does not start with \"ply\""},
      {"ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
       "property float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
       "012345678901234567890123456789012345",
       false, "at least 37 bytes of data but 36 follow"},
  };
  for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
    const char *p = write_text(cases[i].obj ? "x.obj" : "x.ply", cases[i].src);
    mesh m;
    rsw_err err = {0};
    rsw_status s = cases[i].obj ? mesh_load_obj(p, false, &m, &err) : mesh_load_ply(p, &m, &err);
    CHECK(s != RSW_OK, "case %zu accepted", i);
    if (s == RSW_OK) {
      mesh_free(&m);
      continue;
    }
    CHECK(strstr(err_text(&err), cases[i].text), "case %zu: \"%s\" lacks \"%s\"", i, err_text(&err),
          cases[i].text);
  }
  mesh m;
  rsw_err err = {0};
  CHECK(mesh_load_obj(tpath("missing.obj"), true, &m, &err) == RSW_ERR_FILE, "missing file");
  CHECK(strstr(err.where, "missing.obj") != NULL, "where = %s", err.where);
}

static void cleanup_dir(void) {
  DIR *d = opendir(tmpdir);
  if (!d) return;
  struct dirent *e;
  while ((e = readdir(d)))
    if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) unlink(tpath(e->d_name));
  closedir(d);
  rmdir(tmpdir);
}

int main(void) {
  snprintf(tmpdir, sizeof tmpdir, "/tmp/rsw_test_mesh_XXXXXX");
  if (!mkdtemp(tmpdir)) {
    perror("mkdtemp");
    return 1;
  }
  RSW_TEST_RUN(test_fixture_quads);
  RSW_TEST_RUN(test_obj_cube);
  RSW_TEST_RUN(test_obj_negative_and_forms);
  RSW_TEST_RUN(test_ply_ascii_cube);
  RSW_TEST_RUN(test_ply_binary_types);
  RSW_TEST_RUN(test_bad_corpus);
  RSW_TEST_RUN(test_inline_errors);
  cleanup_dir();
  RSW_TEST_END("test_mesh_io");
}
