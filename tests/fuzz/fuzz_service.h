/* Set-up shared by the service-level harnesses (params, render_body,
 * job_body, http): one service per process with a private blob directory
 * (removed at exit), one render thread, small limits (a request may ask for
 * at most 256 pixel samples, so no input makes a render expensive), and
 * the harness scene (fuzz.h) loaded. */
#ifndef RSW_FUZZ_SERVICE_H
#define RSW_FUZZ_SERVICE_H

#include <ftw.h>

#include "../../server/service/service.h"
#include "fuzz.h"

static service *fuzz_svc;
static char fuzz_scene_id[72];
static char fuzz_blob_dir[64];
static char *fuzz_params0; /* the scene's parameters as first loaded */

static inline int fuzz_rm_entry(const char *path, const struct stat *st, int flag, struct FTW *ftw) {
  (void)st;
  (void)flag;
  (void)ftw;
  remove(path);
  return 0;
}

static inline void fuzz_service_end(void) {
  service_shutdown(fuzz_svc);
  service_free(fuzz_svc);
  fuzz_svc = NULL;
  free(fuzz_params0);
  if (fuzz_blob_dir[0]) nftw(fuzz_blob_dir, fuzz_rm_entry, 8, FTW_DEPTH | FTW_PHYS);
}

/* Load the harness scene (again, after a delete); its id in fuzz_scene_id. */
static inline void fuzz_scene_load(void) {
  char *id = NULL;
  svc_error e = {0};
  rsw_status st = service_scene_load_text(fuzz_svc, fuzz_scene_json, sizeof fuzz_scene_json - 1, false,
                                          "fuzz.json", &id, &e);
  FUZZ_CHECK(st == RSW_OK && id, "the harness scene does not load: %s", e.err.msg);
  snprintf(fuzz_scene_id, sizeof fuzz_scene_id, "%s", id);
  free(id);
}

/* The scene's parameter listing (malloc'ed). */
static inline char *fuzz_params_now(void) {
  char *json = NULL;
  uint64_t rev = 0;
  svc_error e = {0};
  rsw_status st = service_params_get(fuzz_svc, fuzz_scene_id, NULL, NULL, &json, &rev, &e);
  FUZZ_CHECK(st == RSW_OK && json, "GET params fails: %s", e.err.msg);
  return json;
}

static inline void fuzz_service_start(void) {
  snprintf(fuzz_blob_dir, sizeof fuzz_blob_dir, "/tmp/rsw-fuzz-XXXXXX");
  FUZZ_CHECK(mkdtemp(fuzz_blob_dir) != NULL, "mkdtemp");
  char blobs[96];
  snprintf(blobs, sizeof blobs, "%s/blobs", fuzz_blob_dir);
  service_opts so = {.size = sizeof so,
                     .render_threads = 1,
                     .blob_dir = blobs,
                     .max_queue = 4,
                     .result_ttl_s = 60,
                     .max_pixel_samples = 256,
                     .max_body_bytes = 1 << 20};
  rsw_err err = {0};
  FUZZ_CHECK(service_new(&so, &fuzz_svc, &err) == RSW_OK, "service_new: %s", err.msg);
  atexit(fuzz_service_end);
  fuzz_scene_load();
  fuzz_params0 = fuzz_params_now();
}

/* Errors must say what is wrong. */
static inline void fuzz_check_error(rsw_status st, const svc_error *e, const char *what) {
  FUZZ_CHECK(st == RSW_OK || e->err.msg[0] != '\0', "%s failed (status %d) without a message", what, (int)st);
}

/* A render of the harness scene after whatever the input did must work
 * (a PATCH or an override that was accepted must not make it fail, let
 * alone crash). */
static inline void fuzz_render_ok(const char *body) {
  svc_film f;
  memset(&f, 0, sizeof f);
  svc_error e = {0};
  rsw_status st = service_render(fuzz_svc, fuzz_scene_id, body, strlen(body), NULL, &f, &e);
  /* Except one user error: a PATCH may tabulate a spectrum over a range
   * that leaves out the render's wavelength (550 nm by default); a mono
   * scene is free to be meant for [562, 700] nm only. The render then
   * refuses with RSW_ERR_RANGE naming the spectrum (scene/build.c). */
  if (st == RSW_ERR_RANGE && strstr(e.err.msg, "lies outside the spectrum's table")) st = RSW_OK;
  FUZZ_CHECK(st == RSW_OK, "render %s after an accepted input fails: %s (%s)", body, e.err.msg, e.err.where);
  svc_film_free(&f);
}

#endif
