/* What a job's dataset costs the daemon in memory, in process (no HTTP):
 * 96 contexts of a 128 x 128 hdistant film, whose pixel angles (16 bytes
 * a pixel, 256 KiB a film) are the same in every context. The job's films
 * hold one block of them (counted once in raysweep_result_bytes), and a
 * film fetched holds the job's pixels and
 * angles (film_image_share), as the dataset does: building it raises the
 * process's peak memory (VmHWM, reset before) by less than 22 MiB (the
 * slab written from and the file encoded in memory; a copy of every
 * film's radiance made it 25.2 MiB, a copy of every film's angles 49.2),
 * for a dataset whose angles are still every pixel's (vza over y, x), the
 * same as one film's. And the dataset answered from a file
 * (service_job_dataset_file) holds the one encoded in memory. Under
 * --max-result-bytes without a state directory, a job is reserved a
 * sensor's angles once when its contexts do not move it (test_reserve). */
#include <malloc.h>
#include <math.h>
#include <netcdf.h>
#include <netcdf_mem.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../server/service/service.h"
#include "../support/svc_job.h"
#include "../support/test.h"
#include "../support/tfile.h"

RSW_TEST_DEFINE_GLOBALS

enum {
  N_CTX = 96,
  SIDE = 128
};

static service *svc;
static char *g_scene;

static const char *SCENE =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 1},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 128, \"height\": 128, \"rfilter\": {\"type\": "
    "\"box\"}}},"
    " \"integrator\": {\"type\": \"path\", \"max_depth\": 2},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0, -0.866], \"irradiance\": 1.0},"
    " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"
    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.3}}}";

/* The peak back to the present (Linux >= 4.0: clear_refs 5). */
static bool reset_peak(void) {
  FILE *f = fopen("/proc/self/clear_refs", "w");
  bool ok = f && fputs("5", f) >= 0;
  if (f) ok = fclose(f) == 0 && ok;
  return ok;
}

/* The service's raysweep_result_bytes (/metrics): what it counts against
 * --max-result-bytes. */
static unsigned long long result_bytes(void) {
  char *m = service_metrics_text(svc);
  const char *g = m ? strstr(m, "\nraysweep_result_bytes ") : NULL;
  unsigned long long v = g ? strtoull(g + 23, NULL, 10) : 0;
  free(m);
  return v;
}

/* body: a job of n contexts "c00", "c01", ... at wavelengths 400,
 * 400 + step, ... nm. */
static void wavelength_job(char *body, size_t size, int n, int step) {
  size_t at = (size_t)snprintf(body, size, "{\"contexts\": [");
  for (int i = 0; i < n && at < size; i++)
    at += (size_t)snprintf(body + at, size - at, "%s{\"id\": \"c%02d\", \"wavelength\": %d}", i ? ", " : "",
                           i, 400 + step * i);
  if (at < size) snprintf(body + at, size - at, "]}");
}

static void test_angles_once(void) {
  const char *scene_id = g_scene;
  /* 96 wavelengths, one film each */
  char body[8192];
  wavelength_job(body, sizeof body, N_CTX, 3);
  char *jid = svc_test_run_job(svc, scene_id, body);
  REQUIRE(jid, "the job ran");
  /* What the daemon counts against --max-result-bytes is what its films
   * hold: every film's radiance and one block of angles (before: a block
   * a film, 4.6 times as much). */
  unsigned long long counted = result_bytes(), held = (unsigned long long)N_CTX * SIDE * SIDE * 4 +
                                                      (unsigned long long)SIDE * SIDE * 16;
  CHECK(counted == held, "raysweep_result_bytes %llu, the films hold %llu", counted, held);
  /* The job's films hold one block of angles (item_done), and a film
   * fetched holds it too, and the job's pixels (film_image_share). */
  svc_film f0, f1, f0b;
  svc_error fe = {0};
  memset(&f0, 0, sizeof f0), memset(&f1, 0, sizeof f1), memset(&f0b, 0, sizeof f0b);
  REQUIRE(service_job_result(svc, jid, "c00", "meter", &f0, &fe) == RSW_OK &&
              service_job_result(svc, jid, "c95", "meter", &f1, &fe) == RSW_OK &&
              service_job_result(svc, jid, "c00", "meter", &f0b, &fe) == RSW_OK,
          "results: %s", fe.err.msg);
  CHECK(f0.img.angles && f0.img.angles == f1.img.angles, "contexts c00 and c95 share their angles (%p, %p)",
        (void *)f0.img.angles, (void *)f1.img.angles);
  CHECK(f0.img.data && f0.img.data == f0b.img.data && f0.img.data != f1.img.data,
        "two fetches of c00 hold the job's pixels (%p, %p; c95's %p)", (void *)f0.img.data,
        (void *)f0b.img.data, (void *)f1.img.data);
  svc_film_free(&f0);
  svc_film_free(&f0b);
  /* c95's pixels outlive the fetch's reference: the job still holds them */
  float v = f1.img.data ? f1.img.data[0] : NAN;
  svc_film_free(&f1);
  memset(&f1, 0, sizeof f1);
  CHECK(service_job_result(svc, jid, "c95", "meter", &f1, &fe) == RSW_OK && f1.img.data &&
            f1.img.data[0] == v,
        "c95 fetched again after a fetch let go of it");
  svc_film_free(&f1);
  /* A first dataset (libnetcdf's start-up, the allocator's arenas), then
   * the one measured. */
  void *bytes = NULL;
  size_t len = 0;
  svc_error e = {0};
  REQUIRE(service_job_dataset(svc, jid, false, &bytes, &len, &e) == RSW_OK, "dataset: %s", e.err.msg);
  malloc_trim(0); /* (what the first took goes back: the second's peak is its own) */
  REQUIRE(reset_peak(), "VmHWM reset (/proc/self/clear_refs)");
  size_t before = tfile_proc_status_bytes("VmRSS");
  void *b2 = NULL;
  size_t len2 = 0;
  REQUIRE(service_job_dataset(svc, jid, false, &b2, &len2, &e) == RSW_OK, "dataset again: %s", e.err.msg);
  size_t peak = tfile_proc_status_bytes("VmHWM"), grew = peak > before ? peak - before : 0;
  printf("  the dataset raised the peak by %.1f MiB\n", (double)grew / 1048576.0);
  /* The films held: the slab written from (6 MiB) and the file encoded in
   * memory (6 MiB, grown as it fills), some 19 MiB in all; with a copy of
   * every film's radiance, 6 MiB more, and with a copy of every film's
   * angles, 24 MiB more again (measured: 19.1, 25.2 and 49.2 MiB). */
  size_t bound = (size_t)22 << 20;
#if defined(__SANITIZE_ADDRESS__)
  grew = 0; /* (ASan's quarantine and shadow memory: no figure to compare) */
#endif
  CHECK(grew < bound, "building the dataset raised the peak by %zu bytes (bound %zu)", grew, bound);
  CHECK(len2 == len && memcmp(b2, bytes, len) == 0, "the same dataset twice");
  int nc, var, nd;
  REQUIRE(nc_open_mem("d.nc", NC_NOWRITE, len2, b2, &nc) == NC_NOERR, "open");
  CHECK(nc_inq_varid(nc, "vza", &var) == NC_NOERR && nc_inq_varndims(nc, var, &nd) == NC_NOERR && nd == 2,
        "vza over (y, x): every film's angles the same");
  double vza[SIDE * SIDE];
  CHECK(nc_get_var_double(nc, var, vza) == NC_NOERR && vza[0] >= 0 && vza[0] < 90, "vza read");
  nc_close(nc);
  /* From a file: the same bytes. */
  int fd = -1;
  uint64_t flen = 0;
  void *b3 = NULL;
  size_t len3 = 0;
  REQUIRE(service_job_dataset_file(svc, jid, false, &fd, &flen, &b3, &len3, &e) == RSW_OK, "to a file: %s",
          e.err.msg);
  CHECK(fd >= 0 && b3 == NULL && flen > 0, "written to a file (fd %d, %llu bytes)", fd,
        (unsigned long long)flen);
  char *f = fd >= 0 ? malloc(flen ? flen : 1) : NULL;
  size_t got = 0;
  while (f && got < flen) {
    ssize_t r = read(fd, f + got, flen - got);
    if (r <= 0) break;
    got += (size_t)r;
  }
  /* (libnetcdf lays a file out a little otherwise in memory: the same
   * variables, values and attributes) */
  int nf, nm;
  float *ra = malloc(sizeof(float) * N_CTX * SIDE * SIDE), *rb = malloc(sizeof(float) * N_CTX * SIDE * SIDE);
  bool same = f && got == flen && ra && rb && nc_open_mem("f.nc", NC_NOWRITE, got, f, &nf) == NC_NOERR;
  if (same && nc_open_mem("m.nc", NC_NOWRITE, len, bytes, &nm) == NC_NOERR) {
    int va, vb;
    same = nc_inq_varid(nf, "radiance", &va) == NC_NOERR && nc_inq_varid(nm, "radiance", &vb) == NC_NOERR &&
           nc_get_var_float(nf, va, ra) == NC_NOERR && nc_get_var_float(nm, vb, rb) == NC_NOERR &&
           memcmp(ra, rb, sizeof(float) * N_CTX * SIDE * SIDE) == 0 && !isnan(ra[0]);
    nc_close(nm);
    nc_close(nf);
  } else if (same) {
    nc_close(nf);
    same = false;
  }
  CHECK(same, "the file holds the dataset encoded in memory (radiance bitwise)");
  free(ra);
  free(rb);
  if (fd >= 0) close(fd);
  free(f);
  free(b3);
  free(b2);
  free(bytes);
  free(jid);
}

/* Two sensors, whose films alternate in the job (context-major, then
 * sensor): each sensor's films hold one block of angles, counted once. */
static const char *SCENE2 =
    "{\"type\": \"scene\", \"variant\": \"mono\","
    " \"meter\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 1},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 64, \"height\": 64, \"rfilter\": {\"type\": \"box\"}}},"
    " \"meter2\": {\"type\": \"hdistant\", \"target\": [0, 0, 0],"
    "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 1},"
    "   \"film\": {\"type\": \"hdrfilm\", \"width\": 32, \"height\": 32, \"rfilter\": {\"type\": \"box\"}}},"
    " \"integrator\": {\"type\": \"path\", \"max_depth\": 2},"
    " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0, -0.866], \"irradiance\": 1.0},"
    " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"
    "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.3}}}";

static void test_two_sensors(void) {
  char *id = svc_test_post(svc, SCENE2);
  REQUIRE(id, "the two-sensor scene loads");
  svc_error e = {0};
  char body[2048];
  wavelength_job(body, sizeof body, 20, 10);
  unsigned long long before = result_bytes();
  char *jid = svc_test_run_job(svc, id, body);
  REQUIRE(jid, "the job ran");
  unsigned long long counted = result_bytes() - before,
                     held = 20ull * (64 * 64 + 32 * 32) * 4 + (64ull * 64 + 32 * 32) * 16;
  CHECK(counted == held, "the two-sensor job counts %llu bytes, its films hold %llu", counted, held);
  const char *sensors[2] = {"meter", "meter2"};
  for (int k = 0; k < 2; k++) {
    svc_film a, b;
    memset(&a, 0, sizeof a), memset(&b, 0, sizeof b);
    REQUIRE(service_job_result(svc, jid, "c00", sensors[k], &a, &e) == RSW_OK &&
                service_job_result(svc, jid, "c19", sensors[k], &b, &e) == RSW_OK,
            "results: %s", e.err.msg);
    CHECK(a.img.angles && a.img.angles == b.img.angles, "%s: c00 and c19 share their angles (%p, %p)",
          sensors[k], (void *)a.img.angles, (void *)b.img.angles);
    svc_film_free(&a);
    svc_film_free(&b);
  }
  free(jid);
  free(id);
}

/* --max-result-bytes without a state directory: a job is reserved what
 * its films will hold, a sensor's angles once when no two contexts give
 * it different parameters (plan_job), once a film otherwise (a job renders
 * at its scene's revision: nothing else moves its sensors while it runs).
 * An `mdistant` sensor of
 * 256 directions: its 256 x 1 film holds 1 KiB of radiance and 4 KiB of
 * angles, which follow its directions. */
enum {
  N_DIR = 256,
  RAD = N_DIR * 4,
  ANG = N_DIR * 16
};

/* The 3 N_DIR numbers of directions looking down, tilted by tilt, with
 * sep between numbers. */
static void directions(char *out, size_t size, double tilt, const char *sep) {
  size_t at = 0;
  for (int i = 0; i < N_DIR && at < size; i++) {
    double t = tilt + 0.6 * i / N_DIR, p = 0.1 * i;
    at += (size_t)snprintf(out + at, size - at, "%s%.4f%s%.4f%s%.4f", i ? sep : "", sin(t) * cos(p), sep,
                           sin(t) * sin(p), sep, -cos(t));
  }
}

/* svc's gauge name (/metrics). */
static unsigned long long gauge(service *s, const char *name) {
  char *m = service_metrics_text(s), key[80];
  snprintf(key, sizeof key, "\n%s ", name);
  const char *g = m ? strstr(m, key) : NULL;
  unsigned long long v = g ? strtoull(g + strlen(key), NULL, 10) : 0;
  free(m);
  return v;
}

/* A job of 20 contexts at 400, 410, ... nm, spp samples, into body; with
 * tilt, context i sets meter.directions tilted by tilt(i). */
static void mdistant_job(char *body, size_t size, int spp, double (*tilt)(int)) {
  static char d[N_DIR * 3 * 12];
  size_t at = (size_t)snprintf(body, size, "{\"defaults\": {\"spp\": %d}, \"contexts\": [", spp);
  for (int i = 0; i < 20 && at < size; i++) {
    at += (size_t)snprintf(body + at, size - at, "%s{\"id\": \"c%02d\", \"wavelength\": %d", i ? ", " : "", i,
                           400 + 10 * i);
    if (tilt) directions(d, sizeof d, tilt(i), ", ");
    if (tilt && at < size)
      at += (size_t)snprintf(body + at, size - at, ", \"params\": {\"meter.directions\": [%s]}", d);
    if (at < size) at += (size_t)snprintf(body + at, size - at, "}");
  }
  if (at < size) snprintf(body + at, size - at, "]}");
}

static double tilted(int i) {
  return 0.01 * i;
}

static double same(int i) {
  (void)i;
  return 0.1;
}

static void test_reserve(void) {
  static char text[N_DIR * 3 * 12 + 1024], body[20 * N_DIR * 3 * 12 + 4096], d[N_DIR * 3 * 12];
  directions(d, sizeof d, 0.0, " ");
  snprintf(
      text, sizeof text,
      "{\"type\": \"scene\", \"variant\": \"mono\","
      " \"meter\": {\"type\": \"mdistant\", \"directions\": \"%s\", \"target\": [0, 0, 0],"
      "   \"sampler\": {\"type\": \"independent\", \"sample_count\": 1},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": %d, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"integrator\": {\"type\": \"path\", \"max_depth\": 2},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0, -0.866], \"irradiance\": 1.0},"
      " \"plate\": {\"type\": \"rectangle\", \"to_world\": [{\"scale\": [10, 10, 1]}],"
      "   \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.3}}}",
      d, N_DIR);
  rsw_err err = {0};
  service *s = NULL;
  service_opts o = {.size = sizeof o, .render_threads = 2, .max_result_bytes = 32 << 10};
  REQUIRE(service_new(&o, &s, &err) == RSW_OK, "service_new: %s", err.msg);
  char *id = svc_test_post(s, text);
  if (!id) service_free(s);
  REQUIRE(id, "the mdistant scene loads");
  svc_error e;
  /* Still: 20 x 1 KiB + 4 KiB = 24 KiB (20 x 5 KiB = 100 KiB before,
   * refused under 32 KiB). */
  mdistant_job(body, sizeof body, 1, NULL);
  char *jid = svc_test_run_job(s, id, body);
  CHECK(jid, "a sweep that does not move its sensor fits in 32 KiB");
  CHECK(gauge(s, "raysweep_result_bytes_reserved") == 20 * RAD + ANG, "reserved %llu, want %d",
        gauge(s, "raysweep_result_bytes_reserved"), 20 * RAD + ANG);
  if (jid) {
    CHECK(gauge(s, "raysweep_result_bytes") == 20 * RAD + ANG, "its films hold %llu, as reserved",
          gauge(s, "raysweep_result_bytes"));
    CHECK(service_job_delete(s, jid, &e) == RSW_OK, "delete: %s", e.err.msg);
    free(jid);
  }
  CHECK(gauge(s, "raysweep_result_bytes_reserved") == 0, "nothing reserved once it is deleted (%llu)",
        gauge(s, "raysweep_result_bytes_reserved"));
  /* Every context the same directions: still. Each its own: 100 KiB. */
  mdistant_job(body, sizeof body, 1, same);
  jid = svc_test_run_job(s, id, body);
  CHECK(jid && gauge(s, "raysweep_result_bytes_reserved") == 20 * RAD + ANG,
        "one set of directions for all: %s, reserved %llu", jid ? "accepted" : "refused",
        gauge(s, "raysweep_result_bytes_reserved"));
  if (jid) {
    CHECK(service_job_delete(s, jid, &e) == RSW_OK, "delete: %s", e.err.msg);
    free(jid);
  }
  mdistant_job(body, sizeof body, 1, tilted);
  char *json = NULL;
  jid = NULL;
  memset(&e, 0, sizeof e);
  rsw_status st = service_job_submit(s, id, body, strlen(body), NULL, &jid, &json, &e);
  CHECK(st == RSW_ERR_STORAGE, "20 sets of directions, 100 KiB, refused under 32 KiB (%s)",
        st ? e.err.msg : "accepted");
  free(json);
  free(jid);
  free(id);
  service_free(s);
}

int main(void) {
  if (!svc_test_start(&svc, SCENE, &g_scene)) return 1;
  if (g_scene) {
    RSW_TEST_RUN(test_angles_once);
    RSW_TEST_RUN(test_two_sensors);
    RSW_TEST_RUN(test_reserve);
  } else
    CHECK(false, "the scene loads");
  free(g_scene);
  service_free(svc);
  RSW_TEST_END("test_dataset_memory");
}
