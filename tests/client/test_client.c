/* libraysweep against the real daemon: `raysweepd serve` on 127.0.0.1 with
 * an ephemeral port (--port-file), driven only through the public header
 * include/raysweep/client.h and build/lib/libraysweep.a. Every library
 * call is exercised: server info and health, scene push (JSON and XML,
 * with a referenced PLY uploaded as a blob because the scene's directory is
 * outside the daemon's data root), list / info / delete, parameters with
 * If-Match, a render saved as EXR and NPY and read back, a wavelength sweep
 * on a Lambertian plate (rho(w) E / pi), wait with progress, cancel,
 * results, fetch, and the error paths (unknown scene, unknown key, stale
 * revision, nothing listening, wrong token). The EXR read-back uses the
 * project's reader (server/kernel/image_exr.h), which libraysweep.a holds
 * since its EXR writer is the same file. */
#include <arpa/inet.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "../../client/lib/internal.h"
#include "../support/daemon.h"
#include "../support/test.h"
#include "../support/tfile.h"
#include "image_exr.h"
#include "raysweep/client.h"

RSW_TEST_DEFINE_GLOBALS

#define PI 3.14159265358979323846

static char tmpdir[64];

static const char *bin_dir(void) {
  const char *e = getenv("RSW_BIN_DIR");
  return e && *e ? e : "build/bin";
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static bool write_bytes(const char *path, const void *p, size_t n) {
  FILE *f = fopen(path, "wb");
  if (!f) return false;
  bool ok = fwrite(p, 1, n, f) == n;
  return (fclose(f) == 0) && ok;
}

/* Single quotes to double quotes, so JSON can be written in C strings. */
static char *jq(char *buf, size_t cap, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static char *jq(char *buf, size_t cap, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(buf, cap, fmt, ap);
  va_end(ap);
  for (char *p = buf; *p; p++)
    if (*p == '\'') *p = '"';
  return buf;
}

/* ---- daemons (tests/support/daemon.h) ------------------------------------------- */

typedef tdaemon daemon_proc;

static bool daemon_start(daemon_proc *d, const char *name, const char *const *extra) {
  char data_root[160], blob_dir[160];
  snprintf(data_root, sizeof data_root, "%s/data", tmpdir);
  snprintf(blob_dir, sizeof blob_dir, "%s/%s-blobs", tmpdir, name);
  const char *argv[64] = {"--data-root", data_root, "--blob-dir", blob_dir};
  int n = 4;
  for (int i = 0; extra && extra[i] && n < 62; i++) argv[n++] = extra[i];
  argv[n] = NULL;
  return tdaemon_start(d, tmpdir, name, argv, 20.0);
}

static void daemon_stop(daemon_proc *d) {
  tdaemon_stop(d, 5.0, NULL);
}

static daemon_proc main_d;

static rsw_client *client_for(const char *url, const char *token, int max_retries) {
  rsw_client_opts o = {.size = sizeof o,
                       .base_url = url,
                       .token = token,
                       .timeout_s = 60,
                       .max_retries = max_retries,
                       .retry_backoff_s = 0.01};
  rsw_client *c = NULL;
  return rsw_client_new(&o, &c) == RSW_OK ? c : NULL;
}

static const char *why(const rsw_client *c) {
  const rsw_error_info *e = rsw_client_last_error(c);
  return e->message;
}

/* ---- scenes -------------------------------------------------------------------------- */

/* The Lambertian plate: a `distant` 1x1 float32 meter looking down at the
 * plate's centre, a 5x5 hdistant, a directional emitter of irradiance 1 at
 * nadir. %s is the plate reflectance. */
static const char *PLATE_FMT =
    "{'type': 'scene', 'variant': 'mono',"
    " 'meter': {'type': 'distant', 'direction': [0, 0, -1], 'target': [0, 0, 0],"
    "   'film': {'type': 'hdrfilm', 'width': 1, 'height': 1, 'component_format': 'float32',"
    "     'rfilter': {'type': 'box'}}},"
    " 'hemi': {'type': 'hdistant', 'sampler': {'type': 'independent', 'sample_count': 4},"
    "   'film': {'type': 'hdrfilm', 'width': 5, 'height': 5, 'component_format': 'float32',"
    "     'rfilter': {'type': 'box'}}},"
    " 'sun': {'type': 'directional', 'direction': [0, 0, -1], 'irradiance': 1.0},"
    " 'plate': {'type': 'rectangle', 'bsdf': {'type': 'diffuse', 'reflectance': %s}}}";

static bool plate_scene(rsw_client *c, const char *rho, char id[65]) {
  char doc[2048];
  jq(doc, sizeof doc, PLATE_FMT, rho);
  rsw_status s = rsw_scene_push_buffer(c, doc, strlen(doc), NULL, NULL, id, NULL);
  if (s) fprintf(stdout, "  plate scene: %s: %s\n", rsw_strerror(s), why(c));
  return s == RSW_OK;
}

/* The one pixel of a 1x1 render of sensor `meter`. */
static double meter_value(rsw_client *c, const char *id) {
  rsw_film *f = NULL;
  rsw_status s = rsw_render(c, id, "{\"sensor\": \"meter\", \"spp\": 2}", &f);
  if (s) {
    fprintf(stdout, "  render %s: %s: %s\n", id, rsw_strerror(s), why(c));
    return NAN;
  }
  double v = rsw_film_width(f) == 1 && rsw_film_height(f) == 1 ? rsw_film_data(f)[0] : NAN;
  rsw_film_free(f);
  return v;
}

static void test_info_ready(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char *json = NULL;
  rsw_status s = rsw_server_info(c, &json);
  CHECK(s == RSW_OK && json && strstr(json, "\"raysweepd\"") && strstr(json, "\"api_version\""),
        "GET /v1: %s %.200s", rsw_strerror(s), json ? json : why(c));
  rsw_free(json);
  CHECK(rsw_client_last_error(c)->status == RSW_OK, "no error after success");
  s = rsw_server_ready(c);
  CHECK(s == RSW_OK, "ready: %s %s", rsw_strerror(s), why(c));
  rsw_client_free(c);
  rsw_client_free(NULL); /* a no-op */
  /* A base URL that is not http(s) is refused up front. */
  rsw_client_opts o = {.size = sizeof o, .base_url = "ftp://127.0.0.1:1"};
  c = NULL;
  CHECK(rsw_client_new(&o, &c) == RSW_ERR_INVALID && !c, "ftp:// base URL refused");
}

/* The quad mesh referenced from a scene in a directory the daemon cannot
 * read (outside --data-root): it can only load through the uploaded blob. */
static const char *QUAD_JSON =
    "{'type': 'scene', 'variant': 'mono',"
    " 'meter': {'type': 'distant', 'direction': [0, 0, -1], 'target': [0.3, 0.2, 0],"
    "   'film': {'type': 'hdrfilm', 'width': 1, 'height': 1, 'rfilter': {'type': 'box'}}},"
    " 'sun': {'type': 'directional', 'direction': [0, 0, -1]},"
    " 'quad': {'type': 'ply', 'filename': 'meshes/quad.ply', 'bsdf': {'type': 'diffuse', 'reflectance': "
    "%s}}}";

static const char *QUAD_XML =
    "<scene version=\"3.0.0\">\n"
    "  <!-- the quad, by a relative path -->\n"
    "  <sensor type=\"distant\" id=\"meter\">\n"
    "    <vector name=\"direction\" x=\"0\" y=\"0\" z=\"-1\"/>\n"
    "    <point name=\"target\" x=\"0.3\" y=\"0.2\" z=\"0\"/>\n"
    "    <film type=\"hdrfilm\"><integer name=\"width\" value=\"1\"/><integer name=\"height\" value=\"1\"/>\n"
    "      <rfilter type=\"box\"/></film>\n"
    "  </sensor>\n"
    "  <emitter type=\"directional\"><vector name=\"direction\" x=\"0\" y=\"0\" z=\"-1\"/></emitter>\n"
    "  <shape type=\"ply\" id=\"quad\">\n"
    "    <string value='meshes/quad.ply'   name=\"filename\" />\n"
    "    <bsdf type=\"diffuse\"><float name=\"reflectance\" value=\"0.25\"/></bsdf>\n"
    "  </shape>\n"
    "</scene>\n";

static void test_push_json_with_blob(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char dir[160], path[200], doc[2048], id[65], id2[65], id3[65];
  snprintf(dir, sizeof dir, "%s/scene-json", tmpdir);
  mkdir(dir, 0755);
  snprintf(path, sizeof path, "%s/meshes", dir);
  mkdir(path, 0755);
  size_t len;
  char *ply = tfile_read("tests/data/quad_le.ply", &len);
  REQUIRE(ply, "read tests/data/quad_le.ply");
  snprintf(path, sizeof path, "%s/meshes/quad.ply", dir);
  REQUIRE(write_bytes(path, ply, len), "copy the PLY");
  free(ply);
  snprintf(path, sizeof path, "%s/quad.json", dir);
  jq(doc, sizeof doc, QUAD_JSON, "0.5");
  REQUIRE(write_bytes(path, doc, strlen(doc)), "write the scene");
  int created = -1;
  rsw_status s = rsw_scene_push_file(c, path, NULL, id, &created);
  REQUIRE(s == RSW_OK, "push %s: %s: %s", path, rsw_strerror(s), why(c));
  CHECK(strlen(id) == 64 && created == 1, "id %s, created %d", id, created);
  /* Lambertian 0.5 quad, E = 1 at nadir: L = rho E / pi. */
  double v = meter_value(c, id);
  CHECK(fabs(v - 0.5 / PI) <= 1e-5 * 0.5 / PI, "rendered %.9g, want %.9g", v, 0.5 / PI);
  /* Again: the same document after the rewrite, so the same id, resident. */
  s = rsw_scene_push_file(c, path, NULL, id2, &created);
  CHECK(s == RSW_OK && strcmp(id, id2) == 0 && created == 0, "second push: %s created %d %s", rsw_strerror(s),
        created, id2);
  /* From memory with the base directory: the same scene. */
  s = rsw_scene_push_buffer(c, doc, strlen(doc), dir, NULL, id3, &created);
  CHECK(s == RSW_OK && strcmp(id, id3) == 0 && created == 0, "push_buffer: %s %s", rsw_strerror(s), id3);
  /* A variant override goes through as ?variant=. */
  s = rsw_scene_push_file(c, path, "rgb", id3, &created);
  CHECK(s == RSW_OK && created == 1, "push as rgb: %s %s", rsw_strerror(s), why(c));
  char *info = NULL;
  if (s == RSW_OK) {
    CHECK(rsw_scene_info(c, id3, &info) == RSW_OK && info && strstr(info, "\"rgb\""), "rgb variant: %s",
          info ? info : why(c));
    rsw_free(info);
    rsw_scene_delete(c, id3, 0);
  }
  /* A missing referenced file: RSW_ERR_IO naming it. */
  jq(doc, sizeof doc, "{'type': 'scene', 'm': {'type': 'ply', 'filename': 'nope/missing.ply'}}");
  s = rsw_scene_push_buffer(c, doc, strlen(doc), dir, NULL, id3, NULL);
  CHECK(s == RSW_ERR_IO && strstr(why(c), "nope/missing.ply"), "missing file: %s %s", rsw_strerror(s),
        why(c));
  /* A missing scene file. */
  s = rsw_scene_push_file(c, "/nonexistent/scene.json", NULL, id3, NULL);
  CHECK(s == RSW_ERR_IO && strstr(why(c), "/nonexistent/scene.json"), "missing scene: %s %s", rsw_strerror(s),
        why(c));
  rsw_client_free(c);
}

static void test_push_xml(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char id[65], dir[160], path[200];
  int created = -1;
  rsw_status s = rsw_scene_push_file(c, "proto/examples/hdistant_seed.xml", NULL, id, &created);
  REQUIRE(s == RSW_OK, "push the seed XML: %s: %s", rsw_strerror(s), why(c));
  /* The daemon preloads the same document as its default scene. */
  CHECK(created == 0, "the seed scene is resident already (created %d)", created);
  char *info = NULL;
  s = rsw_scene_info(c, id, &info);
  CHECK(s == RSW_OK && info && strstr(info, "\"hdistant\""), "info: %s", info ? info : why(c));
  rsw_free(info);
  /* An XML scene referencing the PLY (single-quoted, value before name). */
  snprintf(dir, sizeof dir, "%s/scene-json", tmpdir); /* holds meshes/quad.ply */
  snprintf(path, sizeof path, "%s/quad.xml", dir);
  REQUIRE(write_bytes(path, QUAD_XML, strlen(QUAD_XML)), "write %s", path);
  s = rsw_scene_push_file(c, path, NULL, id, &created);
  REQUIRE(s == RSW_OK, "push %s: %s: %s", path, rsw_strerror(s), why(c));
  double v = meter_value(c, id);
  CHECK(fabs(v - 0.25 / PI) <= 1e-5 * 0.25 / PI, "XML quad rendered %.9g, want %.9g", v, 0.25 / PI);
  /* A malformed XML document reaches the daemon, which says where. */
  const char *bad = "<scene version=\"3.0.0\">\n  <shape type=\"sphere\">\n</scene>\n";
  s = rsw_scene_push_buffer(c, bad, strlen(bad), NULL, NULL, id, NULL);
  const rsw_error_info *e = rsw_client_last_error(c);
  CHECK(s == RSW_ERR_PARSE && e->http_status == 400, "malformed XML: %s http %d %s", rsw_strerror(s),
        e->http_status, e->message);
  rsw_client_free(c);
}

static bool list_has(rsw_client *c, const char *id) {
  char *json = NULL;
  if (rsw_scene_list(c, &json) != RSW_OK) return false;
  bool has = strstr(json, id) != NULL;
  rsw_free(json);
  return has;
}

static void test_list_info_delete(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char id[65];
  REQUIRE(plate_scene(c, "0.123", id), "scene");
  CHECK(list_has(c, id), "listed after the push");
  char *info = NULL;
  rsw_status s = rsw_scene_info(c, id, &info);
  CHECK(s == RSW_OK && info && strstr(info, "\"sensors\"") && strstr(info, "\"meter\""), "info: %s",
        info ? info : why(c));
  rsw_free(info);
  s = rsw_scene_delete(c, id, 0);
  CHECK(s == RSW_OK, "delete: %s %s", rsw_strerror(s), why(c));
  CHECK(!list_has(c, id), "not listed after the delete");
  info = NULL;
  s = rsw_scene_info(c, id, &info);
  const rsw_error_info *e = rsw_client_last_error(c);
  CHECK(s == RSW_ERR_NOT_FOUND && !info && e->status == RSW_ERR_NOT_FOUND && e->http_status == 404 &&
            strcmp(e->code, "RSW_ERR_NOT_FOUND") == 0 && *e->message,
        "info after delete: %s http %d code %s: %s", rsw_strerror(s), e->http_status, e->code, e->message);
  s = rsw_scene_delete(c, id, 1);
  CHECK(s == RSW_ERR_NOT_FOUND, "delete again: %s", rsw_strerror(s));
  rsw_client_free(c);
}

static void test_params(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char id[65];
  REQUIRE(plate_scene(c, "0.4", id), "scene");
  char *json = NULL;
  uint64_t rev = 99;
  rsw_status s = rsw_params_get(c, id, "plate.bsdf.*", NULL, &json, &rev);
  REQUIRE(s == RSW_OK, "params: %s %s", rsw_strerror(s), why(c));
  CHECK(rev == 0 && strstr(json, "plate.bsdf.reflectance.value") && !strstr(json, "sun."), "rev %llu: %.300s",
        (unsigned long long)rev, json);
  rsw_free(json);
  s = rsw_params_get(c, id, NULL, "spectral", &json, NULL);
  CHECK(s == RSW_OK && strstr(json, "plate.bsdf.reflectance.value") && strstr(json, "sun.irradiance") &&
            !strstr(json, "\"geometric\""),
        "class=spectral: %s %.300s", rsw_strerror(s), s ? why(c) : json);
  if (!s) rsw_free(json);
  uint64_t rev1 = 0;
  s = rsw_params_update(c, id, "{\"plate.bsdf.reflectance.value\": 0.6}", (int64_t)rev, &rev1);
  CHECK(s == RSW_OK && rev1 == rev + 1, "update with If-Match: %s rev %llu %s", rsw_strerror(s),
        (unsigned long long)rev1, why(c));
  double v = meter_value(c, id);
  CHECK(fabs(v - 0.6 / PI) <= 1e-5 * 0.6 / PI, "after the update %.9g, want %.9g", v, 0.6 / PI);
  /* The old revision is stale now. */
  s = rsw_params_update(c, id, "{\"plate.bsdf.reflectance.value\": 0.7}", (int64_t)rev, NULL);
  const rsw_error_info *e = rsw_client_last_error(c);
  CHECK(s == RSW_ERR_PRECONDITION && e->http_status == 412, "stale If-Match: %s http %d %s", rsw_strerror(s),
        e->http_status, e->message);
  /* Unconditional. */
  uint64_t rev2 = 0;
  s = rsw_params_update(c, id, "{\"plate.bsdf.reflectance.value\": 0.7}", -1, &rev2);
  CHECK(s == RSW_OK && rev2 == rev1 + 1, "unconditional update: %s rev %llu", rsw_strerror(s),
        (unsigned long long)rev2);
  /* An unknown key: the key and the closest candidates come back. */
  s = rsw_params_update(c, id, "{\"plate.bsdf.reflectanse.value\": 0.7}", -1, NULL);
  e = rsw_client_last_error(c);
  CHECK(s != RSW_OK && e->http_status == 422 && strcmp(e->key, "plate.bsdf.reflectanse.value") == 0 &&
            e->candidates[0] && strcmp(e->candidates[0], "plate.bsdf.reflectance.value") == 0,
        "unknown key: %s http %d key '%s' candidate '%s': %s", rsw_strerror(s), e->http_status, e->key,
        e->candidates[0] ? e->candidates[0] : "(none)", e->message);
  CHECK(s == RSW_OK || strncmp(e->code, "RSW_ERR_", 8) == 0, "code is an RSW name: %s", e->code);
  /* Malformed JSON map: 400 -> RSW_ERR_PARSE. */
  s = rsw_params_update(c, id, "{not json", -1, NULL);
  CHECK(s == RSW_ERR_PARSE && rsw_client_last_error(c)->http_status == 400, "malformed map: %s",
        rsw_strerror(s));
  rsw_scene_delete(c, id, 1);
  rsw_client_free(c);
}

/* Parse an NPY v1.0 <f4 file: shape and data (owned). */
static bool read_npy(const char *path, int shape[3], float **data, size_t *header_len) {
  size_t len;
  unsigned char *p = (unsigned char *)tfile_read(path, &len);
  if (!p || len < 10 || memcmp(p, "\x93NUMPY\x01\x00", 8) != 0) {
    free(p);
    return false;
  }
  size_t hl = (size_t)p[8] | ((size_t)p[9] << 8);
  *header_len = 10 + hl;
  char dict[256];
  snprintf(dict, sizeof dict, "%.*s", (int)(hl < 255 ? hl : 255), (char *)p + 10);
  const char *sh = strstr(dict, "'shape': (");
  bool ok = strstr(dict, "'descr': '<f4'") && strstr(dict, "'fortran_order': False") && sh &&
            sscanf(sh, "'shape': (%d, %d, %d)", &shape[0], &shape[1], &shape[2]) == 3 &&
            p[10 + hl - 1] == '\n';
  size_t n = ok ? (size_t)shape[0] * (size_t)shape[1] * (size_t)shape[2] : 0;
  ok = ok && len == 10 + hl + 4 * n;
  if (ok) {
    *data = malloc(4 * n + 1);
    for (size_t i = 0; i < n; i++) {
      const unsigned char *q = p + 10 + hl + 4 * i;
      uint32_t u = (uint32_t)q[0] | (uint32_t)q[1] << 8 | (uint32_t)q[2] << 16 | (uint32_t)q[3] << 24;
      memcpy(&(*data)[i], &u, 4);
    }
  }
  free(p);
  return ok;
}

static void test_render_save(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char id[65];
  REQUIRE(plate_scene(c, "0.3", id), "scene");
  rsw_film *f = NULL;
  rsw_status s =
      rsw_render(c, id, "{\"sensor\": \"hemi\", \"spp\": 8, \"seed\": 3, \"wavelength\": 600}", &f);
  REQUIRE(s == RSW_OK, "render: %s %s", rsw_strerror(s), why(c));
  int w = rsw_film_width(f), h = rsw_film_height(f), nc = rsw_film_channels(f);
  CHECK(w == 5 && h == 5 && nc == 1 && strcmp(rsw_film_channel_name(f, 0), "Y") == 0 &&
            rsw_film_channel_name(f, 1) == NULL,
        "film %dx%dx%d", w, h, nc);
  const char *meta = rsw_film_meta(f);
  CHECK(strstr(meta, "\"sensor\":\"hemi\"") && strstr(meta, "\"wavelength\":600") &&
            strstr(meta, "\"seed\":3"),
        "meta: %s", meta);
  const float *d = rsw_film_data(f);
  size_t n = (size_t)w * (size_t)h * (size_t)nc;
  bool positive = true;
  for (size_t i = 0; i < n; i++) positive = positive && d[i] > 0;
  CHECK(positive, "every hdistant pixel sees the lit plate");

  char exr[200], npy[200];
  snprintf(exr, sizeof exr, "%s/film.exr", tmpdir);
  snprintf(npy, sizeof npy, "%s/film.npy", tmpdir);
  s = rsw_film_save_exr(f, exr);
  CHECK(s == RSW_OK, "save EXR: %s", rsw_strerror(s));
  exr_image img = {0};
  rsw_err err = {0};
  if (s == RSW_OK && exr_read_image(exr, &img, &err) == RSW_OK) {
    CHECK(img.width == w && img.height == h && img.n_channels == 1 && strcmp(img.channel_names[0], "Y") == 0,
          "EXR %dx%dx%d", img.width, img.height, img.n_channels);
    CHECK(img.data && memcmp(img.data, d, n * sizeof *d) == 0, "EXR pixels bitwise equal to the JSON film");
    const char *sensor = exr_image_meta(&img, "raysweep:sensor");
    CHECK(sensor && strcmp(sensor, "hemi") == 0, "EXR sensor attribute: %s", sensor ? sensor : "(none)");
    exr_image_free(&img);
  } else {
    CHECK(0, "read back %s: %s", exr, err.msg);
  }
  s = rsw_film_save_npy(f, npy);
  CHECK(s == RSW_OK, "save NPY: %s", rsw_strerror(s));
  int shape[3] = {0};
  float *nd = NULL;
  size_t header = 0;
  if (s == RSW_OK && read_npy(npy, shape, &nd, &header)) {
    CHECK(shape[0] == h && shape[1] == w && shape[2] == nc, "shape (%d, %d, %d)", shape[0], shape[1],
          shape[2]);
    CHECK(header % 64 == 0, "data starts at %zu, a multiple of 64", header);
    CHECK(memcmp(nd, d, n * sizeof *d) == 0, "NPY samples bitwise equal to the JSON film");
    free(nd);
  } else {
    CHECK(0, "read back %s as NPY v1.0 <f4", npy);
  }
  /* An unwritable path fails and leaves nothing behind. */
  CHECK(rsw_film_save_npy(f, "/nonexistent-dir/x.npy") == RSW_ERR_IO, "NPY into a missing directory");
  CHECK(rsw_film_save_exr(f, "/nonexistent-dir/x.exr") == RSW_ERR_IO, "EXR into a missing directory");
  rsw_film_free(f);
  rsw_film_free(NULL);
  /* An unknown sensor: the daemon's 4xx comes back as last_error. */
  f = NULL;
  s = rsw_render(c, id, "{\"sensor\": \"nope\"}", &f);
  CHECK(s != RSW_OK && !f && rsw_client_last_error(c)->http_status / 100 == 4, "unknown sensor: %s %s",
        rsw_strerror(s), why(c));
  rsw_scene_delete(c, id, 1);
  rsw_client_free(c);
}

/* ---- jobs ------------------------------------------------------------------------------- */

typedef struct progress_log {
  int contexts, ends, failed;
  size_t last_done, last_total;
  int stop_after; /* > 0: ask to stop after this many context calls */
  char seen[32][16];
} progress_log;

static int on_progress(void *user, const char *context, const char *sensor, size_t done, size_t total,
                       int failed) {
  progress_log *p = user;
  if (!context) {
    p->ends++;
  } else {
    if (p->contexts < 32) snprintf(p->seen[p->contexts], sizeof p->seen[0], "%s", context);
    p->contexts++;
    if (failed) p->failed++;
    (void)sensor;
  }
  p->last_done = done;
  p->last_total = total;
  return p->stop_after > 0 && p->contexts >= p->stop_after;
}

static void test_contexts_builder(void) {
  rsw_contexts *x = NULL;
  REQUIRE(rsw_contexts_new(&x) == RSW_OK, "new");
  size_t i = 99;
  CHECK(rsw_contexts_add(x, "a.b_c-1", 500, &i) == RSW_OK && i == 0, "add a valid id");
  CHECK(rsw_contexts_add(x, "bad id", 500, NULL) == RSW_ERR_INVALID, "space in an id");
  CHECK(rsw_contexts_add(x, "", 500, NULL) == RSW_ERR_INVALID, "empty id");
  char long_id[80];
  memset(long_id, 'x', 65);
  long_id[65] = '\0';
  CHECK(rsw_contexts_add(x, long_id, 500, NULL) == RSW_ERR_INVALID, "65-character id");
  CHECK(rsw_contexts_set_param(x, 0, "k", "{not json") == RSW_ERR_PARSE, "bad value JSON");
  CHECK(rsw_contexts_set_param(x, 5, "k", "1") == RSW_ERR_INVALID, "index out of range");
  CHECK(rsw_contexts_set_spp(x, 0, 4) == RSW_OK && rsw_contexts_set_seed(x, 0, 7) == RSW_OK &&
            rsw_contexts_set_seed(x, 0, -1) == RSW_OK && rsw_contexts_add_sensor(x, 0, "meter") == RSW_OK,
        "per-context settings");
  CHECK(rsw_contexts_count(x) == 1 && rsw_contexts_count(NULL) == 0, "count");
  /* Templates: a JSON object, kept as given; anything else refused here. */
  CHECK(rsw_contexts_set_templates(x, "{\"sun.direction\": {not json") == RSW_ERR_PARSE,
        "bad templates JSON");
  CHECK(rsw_contexts_set_templates(x, "[1, 2]") == RSW_ERR_TYPE, "templates as an array");
  CHECK(rsw_contexts_set_templates(NULL, "{}") == RSW_ERR_INVALID, "no builder");
  CHECK(rsw_contexts_set_templates(
            x, "{\"sun.direction\": {\"sun\": {\"zenith\": \"sza\", \"azimuth\": 0}}}") == RSW_OK,
        "templates");
  char *body = client_contexts_print(x);
  CHECK(body &&
            strstr(body, "\"templates\":{\"sun.direction\":{\"sun\":{\"zenith\":\"sza\",\"azimuth\":0}}}"),
        "the job body carries the templates: %s", body ? body : "(null)");
  free(body);
  CHECK(rsw_contexts_set_templates(x, NULL) == RSW_OK, "templates removed");
  body = client_contexts_print(x);
  CHECK(body && !strstr(body, "templates"), "no templates left: %s", body ? body : "(null)");
  free(body);
  rsw_contexts_free(x);
  rsw_contexts_free(NULL);
}

/* The dataset builder's local checks: coords on contexts (set_coord takes
 * numbers and strings only), bad coords at write time named by their
 * pointer, a film of an unknown context, and a dataset of no film. */
static void test_dataset_builder(void) {
  rsw_contexts *x = NULL;
  REQUIRE(rsw_contexts_new(&x) == RSW_OK && rsw_contexts_add(x, "a", 500, NULL) == RSW_OK, "contexts");
  CHECK(rsw_contexts_set_coord(x, 0, "alpha", "0.3") == RSW_OK, "a number coord");
  CHECK(rsw_contexts_set_coord(x, 0, "kind", "\"leaf\"") == RSW_OK, "a string coord");
  CHECK(rsw_contexts_set_coord(x, 0, "k", "true") == RSW_ERR_TYPE, "a boolean coord");
  CHECK(rsw_contexts_set_coord(x, 0, "k", "{\"a\": 1}") == RSW_ERR_TYPE, "an object coord");
  CHECK(rsw_contexts_set_coord(x, 0, "k", "nope") == RSW_ERR_PARSE, "not JSON");
  CHECK(rsw_contexts_set_coord(x, 3, "k", "1") == RSW_ERR_INVALID, "index out of range");
  rsw_contexts_free(x);

  rsw_dataset *d = NULL;
  REQUIRE(rsw_dataset_new(&d) == RSW_OK, "new");
  CHECK(rsw_dataset_add_context(d, "c0", 500, "{\"k\": 1}") == RSW_OK, "context 0");
  CHECK(rsw_dataset_add_context(d, "c1", 600, "[1]") == RSW_ERR_PARSE, "coords not an object");
  CHECK(rsw_dataset_add_context(d, "c1", 600, "{\"k\": \"s\"}") == RSW_OK, "context 1");
  CHECK(rsw_dataset_add_film_file(d, "c0", "meter", "/nonexistent/film.json") == RSW_ERR_IO, "no film file");
  char path[128];
  snprintf(path, sizeof path, "%s/builder.nc", tmpdir);
  CHECK(rsw_dataset_write(d, path) == RSW_ERR_TYPE &&
            strstr(rsw_dataset_last_error(d), "/contexts/1/coords/k") != NULL,
        "mixed coord types name the pointer: %s", rsw_dataset_last_error(d));
  rsw_dataset_free(d);
  REQUIRE(rsw_dataset_new(&d) == RSW_OK, "new");
  CHECK(rsw_dataset_add_context(d, "c0", 0, NULL) == RSW_OK && rsw_dataset_set_seed(d, 4) == RSW_OK,
        "one context");
  CHECK(rsw_dataset_set_seed(d, -1) == RSW_ERR_INVALID, "a negative seed");
  CHECK(rsw_dataset_write(d, path) == RSW_OK, "a dataset without films: %s", rsw_dataset_last_error(d));
  struct stat st;
  CHECK(stat(path, &st) == 0 && st.st_size > 0, "written");
  rsw_dataset_free(d);
  rsw_dataset_free(NULL);
}

/* Submit the wavelength sweep: n contexts over [400, 700] nm on `meter`,
 * job-level tabulated reflectance. */
static bool submit_sweep(rsw_client *c, const char *id, int n, const char *idem, char job[40]) {
  rsw_contexts *x = NULL;
  if (rsw_contexts_new(&x)) return false;
  bool ok = true;
  for (int i = 0; i < n && ok; i++) {
    char ctx[16];
    snprintf(ctx, sizeof ctx, "w%02d", i);
    ok = rsw_contexts_add(x, ctx, 400.0 + 300.0 * i / (n - 1), NULL) == RSW_OK;
  }
  ok = ok && rsw_contexts_set_job_param(x, "plate.bsdf.reflectance.value",
                                        "{\"wavelengths\": [400, 700], \"values\": [0.2, 0.8]}") == RSW_OK;
  ok = ok && rsw_contexts_add_default_sensor(x, "meter") == RSW_OK;
  ok = ok && rsw_contexts_set_default_spp(x, 2) == RSW_OK && rsw_contexts_set_job_seed(x, 5) == RSW_OK;
  rsw_status s = ok ? rsw_job_submit(c, id, x, idem, job) : RSW_ERR_INVALID;
  if (s) fprintf(stdout, "  submit: %s %s\n", rsw_strerror(s), why(c));
  rsw_contexts_free(x);
  return ok && s == RSW_OK;
}

static void test_job_sweep(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char id[65], job[40], again[40];
  REQUIRE(plate_scene(c, "0.5", id), "scene");
  enum {
    N = 12
  };
  REQUIRE(submit_sweep(c, id, N, "sweep-key-1", job), "submit");
  /* The same Idempotency-Key and body: the same job. */
  CHECK(submit_sweep(c, id, N, "sweep-key-1", again) && strcmp(job, again) == 0,
        "idempotent resubmit: %s vs %s", job, again);
  progress_log p = {0};
  rsw_job_status st = {0};
  rsw_status s = rsw_job_wait(c, job, on_progress, &p, 60, &st);
  REQUIRE(s == RSW_OK, "wait: %s %s", rsw_strerror(s), why(c));
  CHECK(st.state == RSW_JOB_SUCCEEDED && st.contexts_total == N && st.contexts_done == N &&
            st.renders_done == N && st.renders_failed == 0 && st.error[0] == '\0',
        "final: state %d, contexts %zu/%zu renders %zu", (int)st.state, st.contexts_done, st.contexts_total,
        st.renders_done);
  CHECK(p.contexts == N && p.ends == 1 && p.failed == 0 && p.last_done == N && p.last_total == N,
        "progress: %d context calls, %d end calls, last %zu/%zu", p.contexts, p.ends, p.last_done,
        p.last_total);
  /* Waiting again on a finished job: the stream replays, ends at once. */
  progress_log p2 = {0};
  s = rsw_job_wait(c, job, on_progress, &p2, 10, NULL);
  CHECK(s == RSW_OK && p2.ends == 1, "second wait: %s, %d ends", rsw_strerror(s), p2.ends);

  rsw_job_status g = {0};
  s = rsw_job_get(c, job, &g);
  CHECK(s == RSW_OK && g.state == RSW_JOB_SUCCEEDED && g.seconds >= 0, "get: %s", rsw_strerror(s));
  char *json = NULL;
  s = rsw_job_list(c, &json);
  CHECK(s == RSW_OK && strstr(json, job), "job listed: %s", rsw_strerror(s));
  rsw_free(json);
  json = NULL;
  s = rsw_job_results(c, job, &json);
  CHECK(s == RSW_OK && strstr(json, "\"w00\"") && strstr(json, "\"w11\""), "results: %s", rsw_strerror(s));
  rsw_free(json);

  int bad = 0;
  for (int i = 0; i < N; i++) {
    char ctx[16];
    snprintf(ctx, sizeof ctx, "w%02d", i);
    double wl = 400.0 + 300.0 * i / (N - 1), rho = 0.2 + 0.6 * (wl - 400.0) / 300.0, want = rho * 1.0 / PI;
    rsw_film *f = NULL;
    s = rsw_job_fetch(c, job, ctx, "meter", &f);
    if (s || rsw_film_width(f) != 1 || fabs(rsw_film_data(f)[0] - want) > 1e-5 * want) {
      bad++;
      fprintf(stdout, "  %s (%g nm): %s %.9g, want rho E / pi = %.9g\n", ctx, wl, rsw_strerror(s),
              f ? rsw_film_data(f)[0] : NAN, want);
    }
    rsw_film_free(f);
  }
  CHECK(bad == 0, "%d of %d contexts off rho(w) E / pi by more than 1e-5 relative", bad, N);
  rsw_film *f = NULL;
  s = rsw_job_fetch(c, job, "w00", "hemi", &f);
  CHECK(s == RSW_ERR_NOT_FOUND && !f, "a sensor the job did not render: %s", rsw_strerror(s));
  /* The job as one dataset: an HDF5 (NetCDF-4) file. */
  char nc[128];
  snprintf(nc, sizeof nc, "%s/job.nc", tmpdir);
  s = rsw_job_fetch_dataset(c, job, 0, nc);
  CHECK(s == RSW_OK, "fetch dataset: %s %s", rsw_strerror(s), why(c));
  FILE *fp = fopen(nc, "rb");
  unsigned char magic[4] = {0};
  CHECK(fp && fread(magic, 1, 4, fp) == 4 && memcmp(magic, "\x89HDF", 4) == 0, "the dataset is HDF5");
  if (fp) fclose(fp);
  s = rsw_job_fetch_dataset(c, "job-none", 0, nc);
  CHECK(s == RSW_ERR_NOT_FOUND, "dataset of an unknown job: %s", rsw_strerror(s));

  s = rsw_job_delete(c, job);
  CHECK(s == RSW_OK, "delete: %s %s", rsw_strerror(s), why(c));
  s = rsw_job_get(c, job, &g);
  CHECK(s == RSW_ERR_NOT_FOUND, "get after delete: %s", rsw_strerror(s));
  s = rsw_job_wait(c, job, NULL, NULL, 5, NULL);
  CHECK(s == RSW_ERR_NOT_FOUND, "wait on a deleted job: %s %s", rsw_strerror(s), why(c));
  rsw_scene_delete(c, id, 1);
  rsw_client_free(c);
}

/* rsw_job_fetch_encoded: the daemon's EXR and NPY of every film of a job
 * are byte for byte what rsw_film_save_exr / _npy write of rsw_job_fetch's
 * film (two sensors, one with per-pixel angles, and brf + variance planes
 * with their irradiance attribute; wavelengths such as 401.3 nm, whose
 * %.17g text is longer than their shortest one); JSON and PNG come as
 * such; an unknown media type is refused before any request. */
static void test_fetch_encoded(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char id[65], job[40];
  REQUIRE(plate_scene(c, "0.35", id), "scene");
  rsw_contexts *x = NULL;
  REQUIRE(rsw_contexts_new(&x) == RSW_OK, "contexts");
  static const double wl[] = {401.3, 550, 612.7};
  static const char *ctxs[] = {"a", "b", "c"}, *sensors[] = {"hemi", "meter"};
  for (int i = 0; i < 3; i++) rsw_contexts_add(x, ctxs[i], wl[i], NULL);
  const char *q[] = {"radiance", "brf"};
  rsw_contexts_add_default_sensor(x, "hemi");
  rsw_contexts_add_default_sensor(x, "meter");
  rsw_contexts_set_default_spp(x, 4);
  rsw_contexts_set_quantities(x, q, 2);
  rsw_contexts_set_variance(x, 1);
  rsw_status s = rsw_job_submit(c, id, x, NULL, job);
  rsw_contexts_free(x);
  REQUIRE(s == RSW_OK, "submit: %s %s", rsw_strerror(s), why(c));
  REQUIRE(rsw_job_wait(c, job, NULL, NULL, 60, NULL) == RSW_OK, "wait: %s", why(c));
  int compared = 0, differ = 0;
  /* Twice over: the second round's angle lists come from the cache. */
  for (int round = 0; round < 2; round++)
    for (int i = 0; i < 3; i++)
      for (int k = 0; k < 2; k++) {
        rsw_film *f = NULL;
        s = rsw_job_fetch(c, job, ctxs[i], sensors[k], &f);
        REQUIRE(s == RSW_OK, "fetch %s/%s: %s", ctxs[i], sensors[k], why(c));
        char exr[200], npy[200];
        snprintf(exr, sizeof exr, "%s/enc.exr", tmpdir);
        snprintf(npy, sizeof npy, "%s/enc.npy", tmpdir);
        REQUIRE(rsw_film_save_exr(f, exr) == RSW_OK && rsw_film_save_npy(f, npy) == RSW_OK, "save");
        rsw_film_free(f);
        static const char *types[] = {"image/x-exr", "application/x-npy"};
        for (int t = 0; t < 2; t++) {
          size_t want_len = 0, len = 0;
          char *want = tfile_read(t ? npy : exr, &want_len);
          void *bytes = NULL;
          s = rsw_job_fetch_encoded(c, job, ctxs[i], sensors[k], types[t], &bytes, &len);
          CHECK(s == RSW_OK, "fetch_encoded %s/%s %s: %s %s", ctxs[i], sensors[k], types[t], rsw_strerror(s),
                why(c));
          compared++;
          if (!s && !(want && len == want_len && memcmp(bytes, want, len) == 0)) {
            differ++;
            fprintf(stdout, "  %s/%s %s: %zu bytes, the client's file %zu\n", ctxs[i], sensors[k], types[t],
                    len, want_len);
          }
          rsw_free(bytes);
          free(want);
        }
      }
  CHECK(compared == 24 && differ == 0, "%d of %d encoded films differ from the client's files", differ,
        compared);
  void *bytes = NULL;
  size_t len = 0;
  s = rsw_job_fetch_encoded(c, job, "a", "hemi", "application/json", &bytes, &len);
  CHECK(s == RSW_OK && len > 2 && ((char *)bytes)[0] == '{' && strstr(bytes, "\"zenith_deg\":["),
        "JSON as sent: %s", rsw_strerror(s));
  rsw_free(bytes);
  bytes = NULL;
  s = rsw_job_fetch_encoded(c, job, "a", "hemi", "image/png", &bytes, &len);
  CHECK(s == RSW_OK && len > 8 && memcmp(bytes, "\x89PNG", 4) == 0, "PNG: %s", rsw_strerror(s));
  rsw_free(bytes);
  bytes = (void *)1;
  s = rsw_job_fetch_encoded(c, job, "a", "hemi", "image/tiff", &bytes, &len);
  CHECK(s == RSW_ERR_INVALID && !bytes && len == 0 && strstr(why(c), "image/tiff"),
        "an unknown media type: %s %s", rsw_strerror(s), why(c));
  s = rsw_job_fetch_encoded(c, job, "zz", "hemi", "image/x-exr", &bytes, &len);
  CHECK(s == RSW_ERR_NOT_FOUND && !bytes, "an unknown context: %s", rsw_strerror(s));
  rsw_job_delete(c, job);
  rsw_scene_delete(c, id, 1);
  rsw_client_free(c);
}

/* A long job: many contexts of many samples on the 5x5 hdistant. */
static bool submit_long(rsw_client *c, const char *id, char job[40]) {
  rsw_contexts *x = NULL;
  if (rsw_contexts_new(&x)) return false;
  bool ok = true;
  for (int i = 0; i < 400 && ok; i++) {
    char ctx[16];
    snprintf(ctx, sizeof ctx, "L%03d", i);
    ok = rsw_contexts_add(x, ctx, 500, NULL) == RSW_OK;
  }
  ok = ok && rsw_contexts_add_default_sensor(x, "hemi") == RSW_OK &&
       rsw_contexts_set_default_spp(x, 4000) == RSW_OK;
  rsw_status s = ok ? rsw_job_submit(c, id, x, NULL, job) : RSW_ERR_INVALID;
  if (s) fprintf(stdout, "  submit: %s %s\n", rsw_strerror(s), why(c));
  rsw_contexts_free(x);
  return ok && s == RSW_OK;
}

static void test_wait_timeout_stop_cancel(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char id[65], job[40];
  REQUIRE(plate_scene(c, "0.45", id), "scene");
  REQUIRE(submit_long(c, id, job), "submit");
  double t0 = now_s();
  rsw_status s = rsw_job_wait(c, job, NULL, NULL, 0.3, NULL);
  double dt = now_s() - t0;
  /* The limit is honoured: not before it (a lower bound no load can
   * break), and the wait returned while the job still runs (an order, not
   * an upper bound on the time a loaded machine takes). */
  rsw_job_status js;
  memset(&js, 0, sizeof js);
  bool still =
      rsw_job_get(c, job, &js) == RSW_OK && (js.state == RSW_JOB_RUNNING || js.state == RSW_JOB_QUEUED);
  CHECK(s == RSW_ERR_TIMEOUT && dt >= 0.25 && still, "wait with a 0.3 s limit: %s after %.2f s, job %s",
        rsw_strerror(s), dt, still ? "still running" : "over");
  /* The callback stops the wait at its first context; the job runs on. */
  progress_log p = {.stop_after = 1};
  s = rsw_job_wait(c, job, on_progress, &p, 60, NULL);
  CHECK(s == RSW_ERR_CANCELLED && p.contexts == 1 && p.ends == 0, "stopped by the callback: %s, %d calls",
        rsw_strerror(s), p.contexts);
  rsw_job_status st = {0};
  s = rsw_job_get(c, job, &st);
  CHECK(s == RSW_OK && st.state == RSW_JOB_RUNNING && st.renders_total == 400, "still running: state %d",
        (int)st.state);
  s = rsw_job_cancel(c, job);
  CHECK(s == RSW_OK, "cancel: %s %s", rsw_strerror(s), why(c));
  progress_log p2 = {0};
  s = rsw_job_wait(c, job, on_progress, &p2, 30, &st);
  CHECK(s == RSW_OK && st.state == RSW_JOB_CANCELLED && st.renders_done < 400 && p2.ends == 1,
        "after cancel: %s state %d, %zu renders", rsw_strerror(s), (int)st.state, st.renders_done);
  CHECK(rsw_job_delete(c, job) == RSW_OK, "delete the cancelled job");
  rsw_scene_delete(c, id, 1);
  rsw_client_free(c);
}

/* ---- a scripted HTTP server ----------------------------------------------------------
 * For what the real daemon does not do on demand: drop an event stream in
 * the middle of an event, refuse event streams, answer 429/503 with
 * Retry-After. One thread accepts connections one at a time, reads the
 * request head, and writes the raw answer the script gives, then closes
 * the connection. */

typedef struct fake_server fake_server;
/* Write the raw answer to request number n (0-based) into out. */
typedef void (*fake_script)(fake_server *fs, int n, const char *method, const char *path, char *out,
                            size_t cap);

struct fake_server {
  int fd, port;
  pthread_t thread;
  fake_script script;
  int n_requests;
  char last_event_id[8][32]; /* Last-Event-ID of request n ("" when absent) */
  char paths[8][128];
  int polls;     /* GET /v1/jobs/{id} so far */
  char *body[8]; /* request bodies (owned), by request number */
  size_t body_len[8];
  char ctype[8][64]; /* their Content-Type */
  char route[8][80]; /* their X-Raysweep-Shard ("" when absent) */
};

static void *fake_main(void *arg) {
  fake_server *fs = arg;
  for (;;) {
    int cfd = accept(fs->fd, NULL, NULL);
    if (cfd < 0) return NULL;
    char req[4096];
    size_t got = 0;
    char *head_end = NULL;
    while (got < sizeof req - 1) {
      ssize_t r = read(cfd, req + got, sizeof req - 1 - got);
      if (r <= 0) break;
      got += (size_t)r;
      req[got] = '\0';
      if ((head_end = strstr(req, "\r\n\r\n"))) break;
    }
    req[got] = '\0';
    /* The body, by Content-Length (the client sends no chunked bodies). */
    const char *cl = strcasestr(req, "\r\nContent-Length:");
    size_t body_len = cl ? (size_t)strtoul(cl + 17, NULL, 10) : 0;
    char *body = head_end && body_len < ((size_t)1 << 24) ? malloc(body_len + 1) : NULL;
    if (body) {
      size_t have = got - (size_t)(head_end + 4 - req);
      if (have > body_len) have = body_len;
      memcpy(body, head_end + 4, have);
      while (have < body_len) {
        ssize_t r = read(cfd, body + have, body_len - have);
        if (r <= 0) break;
        have += (size_t)r;
      }
      body_len = have;
      body[body_len] = '\0';
    }
    if (strncmp(req, "QUIT", 4) == 0 || got == 0) {
      close(cfd);
      if (got && strncmp(req, "QUIT", 4) == 0) return NULL;
      continue;
    }
    char method[16] = "", path[128] = "";
    sscanf(req, "%15s %127s", method, path);
    int n = fs->n_requests++;
    if (n < 8) {
      snprintf(fs->paths[n], sizeof fs->paths[n], "%s", path);
      const char *l = strcasestr(req, "\r\nLast-Event-ID:");
      fs->last_event_id[n][0] = '\0';
      if (l) sscanf(l + 16, " %31[^\r\n]", fs->last_event_id[n]);
      const char *rt = strcasestr(req, "\r\nX-Raysweep-Shard:");
      fs->route[n][0] = '\0';
      if (rt) sscanf(rt + 19, " %79[^\r\n]", fs->route[n]);
      const char *ct = strcasestr(req, "\r\nContent-Type:");
      fs->ctype[n][0] = '\0';
      if (ct) sscanf(ct + 15, " %63[^\r\n]", fs->ctype[n]);
      free(fs->body[n]); /* a test may restart the count */
      fs->body[n] = body;
      fs->body_len[n] = body_len;
      body = NULL;
    }
    free(body);
    char out[8192];
    fs->script(fs, n, method, path, out, sizeof out);
    size_t len = strlen(out), off = 0;
    while (off < len) {
      ssize_t w = write(cfd, out + off, len - off);
      if (w <= 0) break;
      off += (size_t)w;
    }
    close(cfd);
  }
}

static bool fake_start(fake_server *fs, fake_script script) {
  memset(fs, 0, sizeof *fs);
  fs->script = script;
  fs->fd = socket(AF_INET, SOCK_STREAM, 0);
  struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = 0};
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  if (fs->fd < 0 || bind(fs->fd, (struct sockaddr *)&a, sizeof a) != 0 || listen(fs->fd, 8) != 0 ||
      getsockname(fs->fd, (struct sockaddr *)&a, &len) != 0)
    return false;
  fs->port = ntohs(a.sin_port);
  return pthread_create(&fs->thread, NULL, fake_main, fs) == 0;
}

static void fake_stop(fake_server *fs) {
  int fd = socket(AF_INET, SOCK_STREAM, 0);
  struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)fs->port)};
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (fd >= 0 && connect(fd, (struct sockaddr *)&a, sizeof a) == 0 && write(fd, "QUIT", 4) == 4) {}
  if (fd >= 0) close(fd);
  pthread_join(fs->thread, NULL);
  close(fs->fd);
  for (int i = 0; i < 8; i++) free(fs->body[i]);
}

static void answer(char *out, size_t cap, const char *status, const char *ctype, const char *extra,
                   const char *body) {
  snprintf(out, cap,
           "HTTP/1.1 %s\r\nContent-Type: %s\r\n%sConnection: close\r\nContent-Length: %zu\r\n\r\n%s", status,
           ctype, extra, strlen(body), body);
}

#define SSE_HEAD                                                                                             \
  "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-cache\r\nConnection: "            \
  "close\r\n\r\n"
#define CTX_EVENT(n, ctx)                                                                                    \
  "event: context\nid: " #n "\ndata: {\"context\": \"" ctx                                                   \
  "\", \"sensor\": \"meter\", \"state\": \"succeeded\", \"done\": " #n ", \"total\": 3}\n\n"
#define JOB_DONE                                                                                             \
  "{\"id\": \"j1\", \"state\": \"succeeded\", \"contexts_total\": 3, \"contexts_done\": 3, "                 \
  "\"renders_total\": 3, \"renders_done\": 3, \"renders_failed\": 0}"

/* Events 1 and 2 and half of event 3, then the connection closes; after a
 * reconnect (Last-Event-ID: 2), event 3 and the end. */
static void script_drop(fake_server *fs, int n, const char *method, const char *path, char *out, size_t cap) {
  (void)fs;
  (void)method;
  if (strcmp(path, "/v1/jobs/j1/events") == 0 && n == 0)
    snprintf(out, cap,
             SSE_HEAD ": ping\n\n" CTX_EVENT(1, "c0")
                 CTX_EVENT(2, "c1") "event: context\nid: 3\ndata: {\"con");
  else if (strcmp(path, "/v1/jobs/j1/events") == 0)
    snprintf(out, cap, SSE_HEAD CTX_EVENT(3, "c2") "event: end\nid: 4\ndata: {\"state\": \"succeeded\"}\n\n");
  else if (strcmp(path, "/v1/jobs/j1") == 0)
    answer(out, cap, "200 OK", "application/json", "", JOB_DONE);
  else
    answer(out, cap, "404 Not Found", "application/problem+json", "",
           "{\"status\": 404, \"code\": \"RSW_ERR_NOT_FOUND\"}");
}

/* No event streams here (406); the job is running on the first poll and
 * done on the second. */
static void script_poll(fake_server *fs, int n, const char *method, const char *path, char *out, size_t cap) {
  (void)n;
  (void)method;
  if (strcmp(path, "/v1/jobs/j1/events") == 0) {
    answer(out, cap, "406 Not Acceptable", "application/problem+json", "",
           "{\"status\": 406, \"code\": \"NOT_ACCEPTABLE\", \"detail\": \"no streams through this proxy\"}");
  } else if (strcmp(path, "/v1/jobs/j1") == 0) {
    if (fs->polls++ == 0)
      answer(out, cap, "200 OK", "application/json", "",
             "{\"id\": \"j1\", \"state\": \"running\", \"renders_total\": 3, \"renders_done\": 1}");
    else
      answer(out, cap, "200 OK", "application/json", "", JOB_DONE);
  } else if (strcmp(path, "/v1/jobs/j1/results") == 0) {
    answer(out, cap, "200 OK", "application/json", "",
           fs->polls <= 1 ? "{\"job\": \"j1\", \"results\": [{\"context\": \"c0\", \"sensor\": \"meter\", "
                            "\"state\": \"succeeded\"},"
                            " {\"context\": \"c1\", \"sensor\": \"meter\", \"state\": \"queued\"},"
                            " {\"context\": \"c2\", \"sensor\": \"meter\", \"state\": \"queued\"}]}"
                          : "{\"job\": \"j1\", \"results\": [{\"context\": \"c0\", \"sensor\": \"meter\", "
                            "\"state\": \"succeeded\"},"
                            " {\"context\": \"c1\", \"sensor\": \"meter\", \"state\": \"failed\"},"
                            " {\"context\": \"c2\", \"sensor\": \"meter\", \"state\": \"succeeded\"}]}");
  } else {
    answer(out, cap, "404 Not Found", "application/problem+json", "", "{\"status\": 404}");
  }
}

/* 429 with Retry-After: 1, then 503 without, then the answer. */
static void script_busy(fake_server *fs, int n, const char *method, const char *path, char *out, size_t cap) {
  (void)fs;
  (void)method;
  (void)path;
  if (n == 0)
    answer(out, cap, "429 Too Many Requests", "application/problem+json", "Retry-After: 1\r\n",
           "{\"status\": 429, \"code\": \"RSW_ERR_BUSY\", \"detail\": \"queue full\"}");
  else if (n == 1)
    answer(out, cap, "503 Service Unavailable", "application/problem+json", "",
           "{\"status\": 503, \"code\": \"UNAVAILABLE\", \"detail\": \"not ready\"}");
  else
    answer(out, cap, "200 OK", "application/json", "", "{\"name\": \"fake\"}");
}

/* A blob store that lacks everything it is asked about; scenes get a fixed
 * id. The bodies are kept for the test to look at. */
static void script_push(fake_server *fs, int n, const char *method, const char *path, char *out, size_t cap) {
  if (strcmp(method, "POST") == 0 && strcmp(path, "/v1/blobs:missing") == 0) {
    const char *q = n < 8 && fs->body[n] ? strstr(fs->body[n], "[") : NULL; /* echo the digests array */
    const char *e = q ? strchr(q, ']') : NULL;
    char body[2048];
    snprintf(body, sizeof body, "{\"missing\": %.*s}", q && e ? (int)(e - q + 1) : 2, q && e ? q : "[]");
    answer(out, cap, "200 OK", "application/json", "", body);
  } else if (strcmp(method, "PUT") == 0 && strncmp(path, "/v1/blobs/", 10) == 0) {
    answer(out, cap, "201 Created", "application/json", "", "");
  } else if (strcmp(method, "POST") == 0 && strncmp(path, "/v1/scenes", 10) == 0) {
    answer(out, cap, "201 Created", "application/json", "",
           "{\"id\": \"aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\", \"revision\": 0}");
  } else {
    answer(out, cap, "404 Not Found", "application/problem+json", "", "{\"status\": 404}");
  }
}

/* What goes over the wire for a push: one digest asked about per distinct
 * file, one PUT of its bytes, and the XML posted byte for byte except the
 * rewritten filename value. */
static void test_push_wire(void) {
  fake_server fs;
  REQUIRE(fake_start(&fs, script_push), "fake server");
  char url[64], dir[160], path[200];
  snprintf(url, sizeof url, "http://127.0.0.1:%d", fs.port);
  snprintf(dir, sizeof dir, "%s/scene-json", tmpdir); /* holds meshes/quad.ply (test_push_json_with_blob) */
  snprintf(path, sizeof path, "%s/meshes/quad.ply", dir);
  size_t ply_len = 0;
  char *ply = tfile_read(path, &ply_len);
  REQUIRE(ply, "read %s", path);
  free(ply);
  rsw_client *c = client_for(url, NULL, 0);
  char id[65];
  int created = -1;
  snprintf(path, sizeof path, "%s/quad.xml", dir);
  rsw_status s = c ? rsw_scene_push_file(c, path, "mono", id, &created) : RSW_ERR_NOMEM;
  REQUIRE(s == RSW_OK && created == 1 && id[0] == 'a', "push: %s %s", rsw_strerror(s), c ? why(c) : "");
  CHECK(fs.n_requests == 3 && strcmp(fs.paths[0], "/v1/blobs:missing") == 0 &&
            strncmp(fs.paths[1], "/v1/blobs/", 10) == 0 &&
            strcmp(fs.paths[2], "/v1/scenes?variant=mono&name=quad.xml") == 0, /* its file's name */
        "requests: %d (%s, %s, %s)", fs.n_requests, fs.paths[0], fs.paths[1], fs.paths[2]);
  const char *hex = fs.paths[1] + 10;
  CHECK(strlen(hex) == 64 && strspn(hex, "0123456789abcdef") == 64, "PUT names a digest: %s", fs.paths[1]);
  CHECK(fs.body_len[1] == ply_len && strcmp(fs.ctype[1], "application/octet-stream") == 0,
        "PUT carries the PLY: %zu bytes of %s", fs.body_len[1], fs.ctype[1]);
  char want[4096], ref[80];
  snprintf(ref, sizeof ref, "sha256:%.64s", hex);
  const char *at = strstr(QUAD_XML, "meshes/quad.ply");
  REQUIRE(at, "the XML names the mesh");
  snprintf(want, sizeof want, "%.*s%s%s", (int)(at - QUAD_XML), QUAD_XML, ref,
           at + strlen("meshes/quad.ply"));
  CHECK(fs.body[2] && strcmp(fs.body[2], want) == 0 && strcmp(fs.ctype[2], "application/xml") == 0,
        "posted XML (%s):\n%s\nwant:\n%s", fs.ctype[2], fs.body[2] ? fs.body[2] : "(none)", want);
  rsw_client_free(c);
  fake_stop(&fs);

  /* JSON: two references to the file, one already a digest. */
  REQUIRE(fake_start(&fs, script_push), "fake server");
  snprintf(url, sizeof url, "http://127.0.0.1:%d", fs.port);
  c = client_for(url, NULL, 0);
  char doc[1024];
  jq(doc, sizeof doc,
     "{'type': 'scene', 'a': {'type': 'ply', 'filename': 'meshes/quad.ply'},"
     " 'list': [{'b': {'type': 'ply', 'filename': './meshes/../meshes/quad.ply'}}],"
     " 'c': {'type': 'ply', 'filename': 'sha256:%s'}}",
     "0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef");
  s = c ? rsw_scene_push_buffer(c, doc, strlen(doc), dir, NULL, id, NULL) : RSW_ERR_NOMEM;
  REQUIRE(s == RSW_OK, "push JSON: %s %s", rsw_strerror(s), c ? why(c) : "");
  CHECK(fs.n_requests == 3 && fs.body[0] && strstr(fs.body[0], hex) &&
            !strstr(fs.body[0], "0123456789abcdef0123"),
        "one digest asked about: %s", fs.body[0] ? fs.body[0] : "(none)");
  const char *posted = fs.body[2] ? fs.body[2] : "";
  const char *first = strstr(posted, ref), *second = first ? strstr(first + 1, ref) : NULL;
  CHECK(first && second && !strstr(posted, "meshes/") && strstr(posted, "sha256:0123456789abcdef") &&
            strcmp(fs.ctype[2], "application/json") == 0,
        "posted JSON: %s", posted);
  rsw_client_free(c);
  fake_stop(&fs);
}

/* The routing key: sent on every request once set (options or
 * rsw_client_set_route), not sent after it is cleared, refused when it is
 * not [A-Za-z0-9._-]{1,64}. */
static void test_route_header(void) {
  fake_server fs;
  REQUIRE(fake_start(&fs, script_busy), "fake server");
  char url[64];
  snprintf(url, sizeof url, "http://127.0.0.1:%d", fs.port);
  rsw_client_opts o = {.size = sizeof o, .base_url = url, .retry_backoff_s = 0.01, .route_key = "shard-7.r1"};
  rsw_client *c = NULL;
  REQUIRE(rsw_client_new(&o, &c) == RSW_OK, "client with a route key");
  char *json = NULL;
  rsw_status s = rsw_server_info(c, &json); /* 429, 503, then 200: three requests */
  rsw_free(json);
  CHECK(s == RSW_OK && fs.n_requests == 3 && strcmp(fs.route[0], "shard-7.r1") == 0 &&
            strcmp(fs.route[2], "shard-7.r1") == 0,
        "every request (retries too) carries the key: %s, %d requests, '%s' '%s'", rsw_strerror(s),
        fs.n_requests, fs.route[0], fs.route[2]);
  CHECK(rsw_client_set_route(c, "bad key") == RSW_ERR_INVALID &&
            rsw_client_set_route(c, "") == RSW_ERR_INVALID,
        "a key with a space or an empty key is refused");
  REQUIRE(rsw_client_set_route(c, NULL) == RSW_OK, "clear the key");
  json = NULL;
  s = rsw_server_info(c, &json);
  rsw_free(json);
  CHECK(s == RSW_OK && fs.n_requests == 4 && fs.route[3][0] == '\0', "no key after clearing: '%s'",
        fs.route[3]);
  rsw_client_free(c);
  o.route_key = "x/y";
  c = NULL;
  CHECK(rsw_client_new(&o, &c) == RSW_ERR_INVALID && !c, "rsw_client_new refuses a bad route_key");
  fake_stop(&fs);
}

/* A server that ignores Accept (a film as JSON), then one that says EXR
 * but sends something else. */
static void script_wrong_type(fake_server *fs, int n, const char *method, const char *path, char *out,
                              size_t cap) {
  (void)fs;
  (void)method;
  (void)path;
  if (n == 0)
    answer(out, cap, "200 OK", "application/json", "", "{\"width\": 1, \"height\": 1}");
  else
    answer(out, cap, "200 OK", "image/x-exr; charset=binary", "", "not an EXR");
}

/* rsw_job_fetch_encoded takes only the type it asked for: a .exr file must
 * not end up holding JSON. */
static void test_fetch_encoded_wrong_type(void) {
  fake_server fs;
  REQUIRE(fake_start(&fs, script_wrong_type), "fake server");
  char url[64];
  snprintf(url, sizeof url, "http://127.0.0.1:%d", fs.port);
  rsw_client *c = client_for(url, NULL, 0);
  REQUIRE(c, "client");
  void *bytes = NULL;
  size_t len = 0;
  rsw_status s = rsw_job_fetch_encoded(c, "j1", "c0", "meter", "image/x-exr", &bytes, &len);
  CHECK(s == RSW_ERR_PARSE && !bytes && strstr(why(c), "application/json"), "JSON for an EXR: %s %s",
        rsw_strerror(s), why(c));
  s = rsw_job_fetch_encoded(c, "j1", "c0", "meter", "image/x-exr", &bytes, &len);
  CHECK(s == RSW_ERR_PARSE && !bytes && strstr(why(c), "does not start as one"), "not EXR bytes: %s %s",
        rsw_strerror(s), why(c));
  CHECK(fs.n_requests == 2 && strcmp(fs.paths[0], "/v1/jobs/j1/results/c0/meter") == 0, "%d requests, %s",
        fs.n_requests, fs.paths[0]);
  rsw_client_free(c);
  fake_stop(&fs);
}

typedef struct spread_log {
  int films, resumed, failed, bad, encoded;
  char seen[32][8];
} spread_log;

/* rsw_spread_encoded_fn: each film an EXR whose one pixel is rho / pi. */
static int on_spread_encoded(void *user, const char *context, const char *sensor, const char *result_json,
                             const void *bytes, size_t len, int resumed) {
  spread_log *l = user;
  if (resumed) {
    l->resumed++;
    if (bytes || len) l->bad++;
    return 0;
  }
  if (!bytes) {
    l->failed++;
    return 0;
  }
  l->encoded++;
  char path[200];
  snprintf(path, sizeof path, "%s/spread-%s.exr", tmpdir, context);
  exr_image img = {0};
  rsw_err err = {0};
  int i = atoi(context + 1);
  double wl = 400.0 + 300.0 * i / 11, rho = 0.2 + 0.6 * (wl - 400.0) / 300.0, want = rho / PI;
  if (!write_bytes(path, bytes, len) || exr_read_image(path, &img, &err) != RSW_OK || img.width != 1 ||
      fabs(img.data[0] - want) > 1e-5 * want || strcmp(sensor, "meter") != 0 ||
      !strstr(result_json, "\"succeeded\""))
    l->bad++;
  exr_image_free(&img);
  return 0;
}

static int on_spread_film(void *user, const char *context, const char *sensor, const char *result_json,
                          const rsw_film *film, int resumed) {
  spread_log *l = user;
  if (resumed) {
    l->resumed++;
    if (film) l->bad++;
  } else if (film) {
    int i = atoi(context + 1);
    double wl = 400.0 + 300.0 * i / 11, rho = 0.2 + 0.6 * (wl - 400.0) / 300.0, want = rho / PI;
    if (strcmp(sensor, "meter") != 0 || fabs(rsw_film_data(film)[0] - want) > 1e-5 * want ||
        !strstr(result_json, "\"succeeded\""))
      l->bad++;
    l->films++;
  } else {
    l->failed++;
  }
  return 0;
}

/* rsw_spread_run against one daemon (no balancer: every key reaches it):
 * 12 contexts in 3 shards, each film delivered once and right; a second
 * run with the same state file renders nothing and hands every film back
 * as resumed; a state file of another sweep is refused. */
/* rsw_job_check (POST .../jobs?dry_run=1): nothing queued, the renders a
 * submission would run, its warnings (a coordinate nothing reads); a bad
 * request the submission's error. rsw_spread_opts.on_warnings: the whole
 * sweep's warnings once, though each shard holds one value of the
 * coordinate (which a shard's own job cannot see). */
typedef struct warned_log {
  int calls;
  char text[2048];
} warned_log;

static void on_warned(void *user, const char *text) {
  warned_log *w = user;
  w->calls++;
  snprintf(w->text, sizeof w->text, "%s", text);
}

static int count_film(void *user, const char *c, const char *sn, const char *result_json,
                      const rsw_film *film, int resumed) {
  (void)c, (void)sn, (void)result_json, (void)film, (void)resumed;
  (*(int *)user)++;
  return 0;
}

static void test_job_check(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char id[65];
  REQUIRE(plate_scene(c, "0.5", id), "scene");
  rsw_contexts *x = NULL;
  REQUIRE(rsw_contexts_new(&x) == RSW_OK, "contexts");
  rsw_contexts_add(x, "s0", 500, NULL);
  rsw_contexts_add(x, "s30", 500, NULL);
  rsw_contexts_set_coord(x, 0, "sza", "0");
  rsw_contexts_set_coord(x, 1, "sza", "30");
  rsw_contexts_add_default_sensor(x, "meter");
  rsw_contexts_set_default_spp(x, 2);
  size_t renders = 0;
  char *w = NULL;
  rsw_status s = rsw_job_check(c, id, x, &renders, &w);
  CHECK(s == RSW_OK && renders == 2 && w && strstr(w, "coordinate_unused (sza)"),
        "check: %s (%s), %zu renders, %s", rsw_strerror(s), why(c), renders, w ? w : "(no warnings)");
  rsw_free(w);
  rsw_client_opts co = {.size = sizeof co, .base_url = main_d.base_url, .retry_backoff_s = 0.01};
  warned_log wl = {0};
  int films = 0;
  rsw_spread_opts so = {.size = sizeof so,
                        .shards = 2,
                        .on_film = count_film,
                        .film_user = &films,
                        .on_warnings = on_warned,
                        .warnings_user = &wl};
  rsw_spread_result r;
  s = rsw_spread_run(&co, id, x, &so, &r);
  CHECK(s == RSW_OK && films == 2 && wl.calls == 1 && strstr(wl.text, "coordinate_unused (sza)"),
        "spread: %s (%s), %d films, %d warning calls: %s", rsw_strerror(s), rsw_spread_last_error(), films,
        wl.calls, wl.text);
  rsw_contexts_add_default_sensor(x, "nosuch");
  s = rsw_job_check(c, id, x, &renders, NULL);
  CHECK(s != RSW_OK && strstr(why(c), "nosuch"), "a bad request: %s (%s)", rsw_strerror(s), why(c));
  rsw_contexts_free(x);
  rsw_client_free(c);
}

static void test_spread(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char id[65];
  REQUIRE(plate_scene(c, "0.5", id), "scene");
  rsw_contexts *x = NULL;
  REQUIRE(rsw_contexts_new(&x) == RSW_OK, "contexts");
  for (int i = 0; i < 12; i++) {
    char ctx[16];
    snprintf(ctx, sizeof ctx, "w%02d", i);
    rsw_contexts_add(x, ctx, 400.0 + 300.0 * i / 11, NULL);
  }
  rsw_contexts_set_job_param(x, "plate.bsdf.reflectance.value",
                             "{\"wavelengths\": [400, 700], \"values\": [0.2, 0.8]}");
  rsw_contexts_add_default_sensor(x, "meter");
  rsw_contexts_set_default_spp(x, 2);
  char state[200];
  snprintf(state, sizeof state, "%s/spread.state", tmpdir);
  rsw_client_opts co = {.size = sizeof co, .base_url = main_d.base_url, .retry_backoff_s = 0.01};
  spread_log l = {0};
  rsw_spread_opts so = {
      .size = sizeof so, .shards = 3, .state_path = state, .on_film = on_spread_film, .film_user = &l};
  rsw_spread_result r;
  rsw_status s = rsw_spread_run(&co, id, x, &so, &r);
  CHECK(s == RSW_OK && l.films == 12 && l.bad == 0 && l.resumed == 0 && r.films == 12 && r.resubmitted == 0 &&
            strcmp(r.scene_id, id) == 0,
        "spread: %s (%s), %d films, %d wrong, %d resumed", rsw_strerror(s), rsw_spread_last_error(), l.films,
        l.bad, l.resumed);
  spread_log l2 = {0};
  so.film_user = &l2;
  s = rsw_spread_run(&co, id, x, &so, &r);
  CHECK(s == RSW_OK && l2.films == 0 && l2.resumed == 12 && l2.bad == 0 && r.resumed == 12,
        "resumed from the state file: %s (%s), %d rendered, %d resumed", rsw_strerror(s),
        rsw_spread_last_error(), l2.films, l2.resumed);
  so.shards = 2; /* another sweep (a different cut) with the same state file */
  s = rsw_spread_run(&co, id, x, &so, &r);
  CHECK(s == RSW_ERR_PRECONDITION && strstr(rsw_spread_last_error(), "another sweep"),
        "a foreign state file: %s (%s)", rsw_strerror(s), rsw_spread_last_error());
  so.on_film = NULL;
  CHECK(rsw_spread_run(&co, id, x, &so, &r) == RSW_ERR_INVALID, "no on_film: invalid");
  /* Films as the daemon's EXR: on_film_encoded gets each, on_film none. */
  unlink(state);
  spread_log l3 = {0};
  so = (rsw_spread_opts){.size = sizeof so,
                         .shards = 3,
                         .state_path = state,
                         .on_film = on_spread_film,
                         .film_user = &l3,
                         .film_media_type = "image/x-exr",
                         .on_film_encoded = on_spread_encoded};
  s = rsw_spread_run(&co, id, x, &so, &r);
  CHECK(s == RSW_OK && l3.encoded == 12 && l3.films == 0 && l3.bad == 0 && r.films == 12,
        "spread of EXR films: %s (%s), %d encoded, %d decoded, %d wrong", rsw_strerror(s),
        rsw_spread_last_error(), l3.encoded, l3.films, l3.bad);
  /* Resumed from its state file: on_film_encoded again, without bytes. */
  spread_log l4 = {0};
  so.film_user = &l4;
  s = rsw_spread_run(&co, id, x, &so, &r);
  CHECK(s == RSW_OK && l4.resumed == 12 && l4.encoded == 0 && l4.bad == 0,
        "resumed EXR spread: %s, %d resumed", rsw_strerror(s), l4.resumed);
  so.on_film_encoded = NULL;
  CHECK(rsw_spread_run(&co, id, x, &so, &r) == RSW_ERR_INVALID, "film_media_type without on_film_encoded");
  so.on_film_encoded = on_spread_encoded;
  so.film_media_type = "image/gif";
  CHECK(rsw_spread_run(&co, id, x, &so, &r) == RSW_ERR_INVALID, "an unknown film_media_type");
  rsw_contexts_free(x);
  rsw_client_free(c);
}

/* Films are handed over while the job runs: the first film arrives before
 * the job's last render is reported, every film once, and the progress
 * never counts past its total. */
typedef struct early_log {
  double first_film, last_progress;
  size_t max_done, last_total;
  int films, over, bad, resumed;
  int stop_after; /* > 0: stop the run at this film */
} early_log;

static int on_early_progress(void *user, const char *context, const char *sensor, size_t done, size_t total,
                             int failed) {
  early_log *l = user;
  (void)sensor;
  if (!context || !*context) return 0;
  l->last_progress = now_s();
  if (done > total || failed) l->over++;
  if (done > l->max_done) l->max_done = done;
  l->last_total = total;
  return 0;
}

static int on_early_film(void *user, const char *context, const char *sensor, const char *result_json,
                         const void *bytes, size_t len, int resumed) {
  early_log *l = user;
  (void)context, (void)sensor, (void)result_json;
  if (resumed) {
    l->resumed++;
    return 0;
  }
  if (!l->films++) l->first_film = now_s();
  if (!bytes || len < 4 || memcmp(bytes, "\x76\x2f\x31\x01", 4) != 0) l->bad++;
  return l->stop_after > 0 && l->films == l->stop_after;
}

static void test_spread_early(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  char id[65];
  REQUIRE(plate_scene(c, "0.4", id), "scene");
  rsw_contexts *x = NULL;
  REQUIRE(rsw_contexts_new(&x) == RSW_OK, "contexts");
  enum {
    N = 48
  };
  for (int i = 0; i < N; i++) {
    char ctx[16];
    snprintf(ctx, sizeof ctx, "e%02d", i);
    rsw_contexts_add(x, ctx, 400.0 + 5.0 * i, NULL);
  }
  /* Some 10-30 ms a render: the job lasts long enough for passes to run,
   * also on a loaded machine. */
  rsw_contexts_add_default_sensor(x, "hemi");
  rsw_contexts_set_default_spp(x, 4000);
  rsw_client_opts co = {.size = sizeof co, .base_url = main_d.base_url, .retry_backoff_s = 0.01};
  early_log l = {0};
  rsw_spread_opts so = {.size = sizeof so,
                        .shards = 1,
                        .progress = on_early_progress,
                        .progress_user = &l,
                        .film_user = &l,
                        .film_media_type = "image/x-exr",
                        .on_film_encoded = on_early_film};
  rsw_spread_result r;
  rsw_status s = rsw_spread_run(&co, id, x, &so, &r);
  CHECK(s == RSW_OK && l.films == N && r.films == N && l.bad == 0, "spread: %s (%s), %d films, %d wrong",
        rsw_strerror(s), rsw_spread_last_error(), l.films, l.bad);
  CHECK(l.first_film > 0 && l.first_film < l.last_progress,
        "the first film came %.3f s after the last render was reported (want before)",
        l.first_film - l.last_progress);
  CHECK(l.over == 0 && l.max_done == N && l.last_total == N,
        "progress: %d calls past the total, last %zu/%zu", l.over, l.max_done, l.last_total);
  /* Stopped at its 5th film (while the job runs): those 5 are in the
   * journal, and the same call again hands them back as resumed and
   * fetches only the rest, from the same job. */
  char state[200];
  snprintf(state, sizeof state, "%s/early.state", tmpdir);
  so.state_path = state;
  early_log l2 = {.stop_after = 5};
  so.film_user = so.progress_user = &l2;
  s = rsw_spread_run(&co, id, x, &so, &r);
  CHECK(s == RSW_ERR_CANCELLED && l2.films == 5, "stopped by the callback: %s, %d films", rsw_strerror(s),
        l2.films);
  early_log l3 = {0};
  so.film_user = so.progress_user = &l3;
  s = rsw_spread_run(&co, id, x, &so, &r);
  CHECK(s == RSW_OK && l3.resumed == 5 && l3.films == N - 5 && l3.bad == 0 && r.resubmitted == 0,
        "resumed: %s (%s), %d resumed, %d fetched", rsw_strerror(s), rsw_spread_last_error(), l3.resumed,
        l3.films);
  rsw_contexts_free(x);
  rsw_scene_delete(c, id, 1);
  rsw_client_free(c);
}

static void test_wait_reconnects(void) {
  fake_server fs;
  REQUIRE(fake_start(&fs, script_drop), "fake server");
  char url[64];
  snprintf(url, sizeof url, "http://127.0.0.1:%d", fs.port);
  rsw_client *c = client_for(url, NULL, 0);
  progress_log p = {0};
  rsw_job_status st = {0};
  rsw_status s = c ? rsw_job_wait(c, "j1", on_progress, &p, 10, &st) : RSW_ERR_NOMEM;
  CHECK(s == RSW_OK && st.state == RSW_JOB_SUCCEEDED && st.renders_done == 3, "wait: %s %s", rsw_strerror(s),
        c ? why(c) : "");
  CHECK(p.contexts == 3 && p.ends == 1 && strcmp(p.seen[0], "c0") == 0 && strcmp(p.seen[1], "c1") == 0 &&
            strcmp(p.seen[2], "c2") == 0,
        "each context reported once: %d calls (%s %s %s)", p.contexts, p.seen[0], p.seen[1], p.seen[2]);
  CHECK(fs.n_requests == 3 && fs.last_event_id[0][0] == '\0' && strcmp(fs.last_event_id[1], "2") == 0 &&
            strcmp(fs.paths[2], "/v1/jobs/j1") == 0,
        "%d requests; reconnected with Last-Event-ID '%s'", fs.n_requests, fs.last_event_id[1]);
  rsw_client_free(c);
  fake_stop(&fs);
}

static void test_wait_polls_without_events(void) {
  fake_server fs;
  REQUIRE(fake_start(&fs, script_poll), "fake server");
  char url[64];
  snprintf(url, sizeof url, "http://127.0.0.1:%d", fs.port);
  rsw_client *c = client_for(url, NULL, 0);
  progress_log p = {0};
  rsw_job_status st = {0};
  rsw_status s = c ? rsw_job_wait(c, "j1", on_progress, &p, 10, &st) : RSW_ERR_NOMEM;
  CHECK(s == RSW_OK && st.state == RSW_JOB_SUCCEEDED, "wait by polling: %s %s", rsw_strerror(s),
        c ? why(c) : "");
  CHECK(p.contexts == 3 && p.failed == 1 && p.ends == 1 && strcmp(p.seen[0], "c0") == 0 &&
            strcmp(p.seen[2], "c2") == 0 && fs.polls == 2,
        "polled progress: %d calls, %d failed, %d polls", p.contexts, p.failed, fs.polls);
  rsw_client_free(c);
  fake_stop(&fs);
}

static void test_retry_after(void) {
  fake_server fs;
  REQUIRE(fake_start(&fs, script_busy), "fake server");
  char url[64];
  snprintf(url, sizeof url, "http://127.0.0.1:%d", fs.port);
  rsw_client *c = client_for(url, NULL, 0); /* 3 retries, backoff 0.01 s */
  char *json = NULL;
  double t0 = now_s();
  rsw_status s = c ? rsw_server_info(c, &json) : RSW_ERR_NOMEM;
  double dt = now_s() - t0;
  CHECK(s == RSW_OK && json && strstr(json, "fake") && fs.n_requests == 3,
        "after 429 and 503: %s, %d requests", rsw_strerror(s), fs.n_requests);
  /* A lower bound only: a loaded machine can only make it longer. */
  CHECK(dt >= 0.95, "Retry-After: 1 honoured: %.3f s", dt);
  rsw_free(json);
  rsw_client_free(c);
  /* Without retries the 429 comes back, its problem as the last error. */
  fs.n_requests = 0;
  c = client_for(url, NULL, -1);
  json = NULL;
  s = c ? rsw_server_info(c, &json) : RSW_ERR_NOMEM;
  const rsw_error_info *e = c ? rsw_client_last_error(c) : NULL;
  CHECK(s == RSW_ERR_BUSY && e && e->http_status == 429 && strcmp(e->message, "queue full") == 0 &&
            fs.n_requests == 1,
        "no retries: %s", rsw_strerror(s));
  /* A problem code that is no RSW name: the HTTP status decides. */
  s = c ? rsw_server_info(c, &json) : RSW_ERR_NOMEM;
  e = c ? rsw_client_last_error(c) : NULL;
  CHECK(s == RSW_ERR_UNAVAILABLE && e && e->http_status == 503 && strcmp(e->code, "UNAVAILABLE") == 0,
        "503 with code UNAVAILABLE: %s", rsw_strerror(s));
  rsw_client_free(c);
  fake_stop(&fs);
}

static void test_unknown_ids(void) {
  rsw_client *c = client_for(main_d.base_url, NULL, 0);
  REQUIRE(c, "client");
  const char *zero = "0000000000000000000000000000000000000000000000000000000000000000";
  rsw_film *f = NULL;
  rsw_status s = rsw_render(c, zero, NULL, &f);
  const rsw_error_info *e = rsw_client_last_error(c);
  CHECK(s == RSW_ERR_NOT_FOUND && e->http_status == 404 && strcmp(e->code, "RSW_ERR_NOT_FOUND") == 0,
        "render an unknown scene: %s %d %s", rsw_strerror(s), e->http_status, e->code);
  char *json = NULL;
  s = rsw_params_get(c, zero, NULL, NULL, &json, NULL);
  CHECK(s == RSW_ERR_NOT_FOUND && !json, "params of an unknown scene: %s", rsw_strerror(s));
  rsw_contexts *x = NULL;
  rsw_contexts_new(&x);
  rsw_contexts_add(x, "a", 500, NULL);
  char job[40];
  s = rsw_job_submit(c, zero, x, NULL, job);
  CHECK(s == RSW_ERR_NOT_FOUND, "a job on an unknown scene: %s", rsw_strerror(s));
  rsw_contexts_free(x);
  /* The request as JSON text: the daemon's answer, or refused here when
   * it is not an object. */
  s = rsw_job_submit_json(c, zero, "{\"contexts\": [{\"id\": \"a\"}]}", NULL, job);
  CHECK(s == RSW_ERR_NOT_FOUND, "a JSON job on an unknown scene: %s", rsw_strerror(s));
  CHECK(rsw_job_submit_json(c, zero, "[{\"id\": \"a\"}]", NULL, job) == RSW_ERR_PARSE,
        "a JSON job: an array");
  CHECK(rsw_job_submit_json(c, zero, "{\"contexts\": ", NULL, job) == RSW_ERR_PARSE, "a JSON job: malformed");
  rsw_job_status st;
  CHECK(rsw_job_get(c, "no-such-job", &st) == RSW_ERR_NOT_FOUND, "unknown job");
  CHECK(rsw_job_cancel(c, "no-such-job") == RSW_ERR_NOT_FOUND, "cancel an unknown job");
  CHECK(rsw_job_results(c, "no-such-job", &json) == RSW_ERR_NOT_FOUND, "results of an unknown job");
  CHECK(rsw_job_fetch(c, "no-such-job", "a", "b", &f) == RSW_ERR_NOT_FOUND, "fetch from an unknown job");
  CHECK(rsw_job_wait(c, "no-such-job", NULL, NULL, 5, NULL) == RSW_ERR_NOT_FOUND, "wait on an unknown job");
  CHECK(rsw_job_delete(c, "no-such-job") == RSW_ERR_NOT_FOUND, "delete an unknown job");
  rsw_client_free(c);
}

/* A port nothing listens on: bind an ephemeral one, then close it. */
static int dead_port(void) {
  int fd = socket(AF_INET, SOCK_STREAM, 0);
  struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = 0};
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  int port = 0;
  if (fd >= 0 && bind(fd, (struct sockaddr *)&a, sizeof a) == 0 &&
      getsockname(fd, (struct sockaddr *)&a, &len) == 0)
    port = ntohs(a.sin_port);
  if (fd >= 0) close(fd);
  return port;
}

static void test_connection_refused(void) {
  int port = dead_port();
  REQUIRE(port > 0, "a free port");
  char url[64];
  snprintf(url, sizeof url, "http://127.0.0.1:%d", port);
  rsw_client *c = client_for(url, NULL, -1);
  REQUIRE(c, "client");
  char *json = NULL;
  rsw_status s = rsw_server_info(c, &json);
  const rsw_error_info *e = rsw_client_last_error(c);
  CHECK(s == RSW_ERR_UNAVAILABLE && !json && e->status == RSW_ERR_UNAVAILABLE && e->http_status == 0 &&
            strstr(e->message, url),
        "nothing listening: %s: %s", rsw_strerror(s), e->message);
  rsw_client_free(c);
  /* With retries (3, backoff 0.01 s doubling): still unavailable, after
   * the backoff schedule 0.01 + 0.02 + 0.04 s. */
  c = client_for(url, NULL, 3);
  REQUIRE(c, "client");
  double t0 = now_s();
  s = rsw_server_ready(c);
  double dt = now_s() - t0;
  CHECK(s == RSW_ERR_UNAVAILABLE && dt >= 0.065, "with retries: %s after %.3f s", rsw_strerror(s), dt);
  rsw_client_free(c);
}

static void test_unauthorized(void) {
  char tok_path[160];
  snprintf(tok_path, sizeof tok_path, "%s/token", tmpdir);
  REQUIRE(write_bytes(tok_path, "client-secret-42\n", 17), "token file");
  daemon_proc d;
  const char *extra[] = {"--token-file", tok_path, "--threads", "1", NULL};
  REQUIRE(daemon_start(&d, "token", extra), "daemon with --token-file");
  rsw_client *c = client_for(d.base_url, "wrong-token", 0);
  char *json = NULL;
  rsw_status s = c ? rsw_scene_list(c, &json) : RSW_ERR_NOMEM;
  const rsw_error_info *e = c ? rsw_client_last_error(c) : NULL;
  CHECK(s == RSW_ERR_UNAUTHORIZED && e && e->http_status == 401, "wrong token: %s http %d", rsw_strerror(s),
        e ? e->http_status : 0);
  CHECK(c && rsw_server_ready(c) == RSW_OK, "health is open without the right token");
  rsw_client_free(c);
  c = client_for(d.base_url, NULL, 0);
  CHECK(c && rsw_server_info(c, &json) == RSW_ERR_UNAUTHORIZED, "no token");
  rsw_client_free(c);
  c = client_for(d.base_url, "client-secret-42", 0);
  s = c ? rsw_server_info(c, &json) : RSW_ERR_NOMEM;
  CHECK(s == RSW_OK && json && strstr(json, "raysweepd"), "right token: %s", rsw_strerror(s));
  rsw_free(json);
  rsw_client_free(c);
  daemon_stop(&d);
}

int main(void) {
  signal(SIGPIPE, SIG_IGN);
  snprintf(tmpdir, sizeof tmpdir, "/tmp/rsw-client-XXXXXX");
  if (!mkdtemp(tmpdir)) return 1;
  char data[128];
  snprintf(data, sizeof data, "%s/data", tmpdir);
  mkdir(data, 0755);
  const char *extra[] = {"--threads", "2", NULL};
  if (!daemon_start(&main_d, "main", extra)) {
    fprintf(stdout, "FAIL could not start %s/raysweepd serve\n", bin_dir());
    rsw_test_failed_++;
  } else {
    RSW_TEST_RUN(test_info_ready);
    RSW_TEST_RUN(test_push_json_with_blob);
    RSW_TEST_RUN(test_push_xml);
    RSW_TEST_RUN(test_list_info_delete);
    RSW_TEST_RUN(test_params);
    RSW_TEST_RUN(test_render_save);
    RSW_TEST_RUN(test_contexts_builder);
    RSW_TEST_RUN(test_dataset_builder);
    RSW_TEST_RUN(test_job_sweep);
    RSW_TEST_RUN(test_job_check);
    RSW_TEST_RUN(test_fetch_encoded);
    RSW_TEST_RUN(test_fetch_encoded_wrong_type);
    RSW_TEST_RUN(test_wait_timeout_stop_cancel);
    RSW_TEST_RUN(test_unknown_ids);
    RSW_TEST_RUN(test_push_wire);
    RSW_TEST_RUN(test_wait_reconnects);
    RSW_TEST_RUN(test_route_header);
    RSW_TEST_RUN(test_spread);
    RSW_TEST_RUN(test_spread_early);
    RSW_TEST_RUN(test_wait_polls_without_events);
    RSW_TEST_RUN(test_retry_after);
    RSW_TEST_RUN(test_connection_refused);
    RSW_TEST_RUN(test_unauthorized);
  }
  daemon_stop(&main_d);
  char cmd[128];
  snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
  if (getenv("RSW_KEEP_TMP"))
    fprintf(stderr, "kept %s\n", tmpdir);
  else if (system(cmd))
    fprintf(stderr, "could not remove %s\n", tmpdir);
  RSW_TEST_END("test_client");
}
