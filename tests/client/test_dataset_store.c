/* libraysweep's rsw_dataset with a film store (rsw_dataset_set_store):
 * films past the memory budget go to a file without a name, the dataset
 * written from them is the one of films held on the heap, byte for byte,
 * and the process's own memory (RssAnon) does not grow with them. Also
 * bad store directories, a store the disk cannot take (RSW_ERR_IO naming
 * the film and the directory), and the heap-only path's growth, which
 * shows the measurement can see films. */
#include <malloc.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../support/test.h"
#include "../support/tfile.h"
#include "film_io.h"
#include "raysweep/client.h"

RSW_TEST_DEFINE_GLOBALS

enum {
  W = 256,
  H = 128,
  N_FILMS = 48
};

/* Film i as the daemon encodes it: radiance "Y" and "radiance_stderr.Y",
 * pixel angles that differ per film (so each film keeps its own block),
 * values that name the film and pixel. */
static void *film_exr(int i, size_t *len) {
  float *px = malloc((size_t)W * H * 2 * sizeof *px);
  double *ang = malloc((size_t)W * H * 2 * sizeof *ang);
  if (!px || !ang) {
    free(px);
    free(ang);
    return NULL;
  }
  for (size_t p = 0; p < (size_t)W * H; p++) {
    px[2 * p] = (float)i + (float)p * 1e-6f;
    px[2 * p + 1] = 0.5f * (float)i;
    ang[2 * p] = (double)(p % 90) + 0.001 * i;
    ang[2 * p + 1] = (double)(p % 360);
  }
  film_exr_info info = film_exr_info_none();
  info.scene = "s";
  info.variant = "mono";
  info.has_spp = info.has_seed = true;
  info.spp = 4;
  info.seed = (uint64_t)i;
  info.wavelength_nm = 400 + i;
  info.angles = ang;
  const char *names[2] = {"Y", "radiance_stderr.Y"};
  void *bytes = NULL;
  rsw_err err = {0};
  if (film_exr_encode(W, H, 2, names, px, false, &info, &bytes, len, &err) != RSW_OK) bytes = NULL;
  free(px);
  free(ang);
  return bytes;
}

/* A dataset of the N_FILMS films (store: in dir with memory bytes on the
 * heap; dir NULL: none) written to out; *grew: RssAnon's growth while
 * the films were added. */
static bool build(void *const *exr, const size_t *len, const char *dir, size_t memory, const char *out,
                  size_t *grew) {
  rsw_dataset *d;
  if (rsw_dataset_new(&d) != RSW_OK) return false;
  bool ok = !dir || rsw_dataset_set_store(d, dir, memory) == RSW_OK;
  for (int i = 0; ok && i < N_FILMS; i++) {
    char id[16];
    snprintf(id, sizeof id, "c%02d", i);
    ok = rsw_dataset_add_context(d, id, 0, NULL) == RSW_OK;
  }
  size_t before = tfile_proc_status_bytes("RssAnon");
  for (int i = 0; ok && i < N_FILMS; i++) {
    char id[16];
    snprintf(id, sizeof id, "c%02d", i);
    ok = rsw_dataset_add_film_exr(d, id, "cam", exr[i], len[i], NULL, 0) == RSW_OK;
    if (!ok) fprintf(stderr, "film %d: %s\n", i, rsw_dataset_last_error(d));
  }
  size_t after = tfile_proc_status_bytes("RssAnon");
  *grew = after > before ? after - before : 0;
  ok = ok && rsw_dataset_write(d, out) == RSW_OK;
  if (!ok) fprintf(stderr, "write: %s\n", rsw_dataset_last_error(d));
  rsw_dataset_free(d);
  malloc_trim(0); /* (what the films took goes back: the next build's growth is its own) */
  return ok;
}

static void test_store(void) {
  char dir[] = "/tmp/rsw_store_XXXXXX";
  REQUIRE(mkdtemp(dir), "temp dir");
  void *exr[N_FILMS];
  size_t len[N_FILMS];
  for (int i = 0; i < N_FILMS; i++) REQUIRE((exr[i] = film_exr(i, &len[i])), "film %d encoded", i);
  char heap_nc[64], store_nc[64], half_nc[64];
  snprintf(heap_nc, sizeof heap_nc, "%s/heap.nc", dir);
  snprintf(store_nc, sizeof store_nc, "%s/store.nc", dir);
  snprintf(half_nc, sizeof half_nc, "%s/half.nc", dir);
  /* Each film: 256 x 128 x 2 floats and 2 angles a pixel, 768 KiB; the
   * 48: 36 MiB. */
  size_t film_bytes = (size_t)W * H * (2 * sizeof(float) + 2 * sizeof(double));
  size_t grew_heap, grew_store, grew_half;
  /* (the store first: what a build frees may stay in the process) */
  REQUIRE(build(exr, len, dir, 0, store_nc, &grew_store), "in the store");
  REQUIRE(build(exr, len, dir, 10 * film_bytes, half_nc, &grew_half), "10 films on the heap, then the store");
  REQUIRE(build(exr, len, NULL, 0, heap_nc, &grew_heap), "on the heap");
  size_t n1, n2, n3;
  char *a = tfile_read(heap_nc, &n1), *b = tfile_read(store_nc, &n2), *c = tfile_read(half_nc, &n3);
  CHECK(a && b && c && n1 == n2 && n1 == n3 && memcmp(a, b, n1) == 0 && memcmp(a, c, n1) == 0,
        "the three datasets are one, byte for byte (%zu, %zu, %zu bytes)", n1, n2, n3);
  free(a), free(b), free(c);
  /* The heap holds every film (some 36 MiB); the store none, but for
   * the decoder's buffers of one film at a time. (Not under ASan, whose
   * quarantine keeps what is freed.) */
  size_t all = N_FILMS * film_bytes;
#if defined(__SANITIZE_ADDRESS__)
  grew_heap = all, grew_store = 0, grew_half = 9 * film_bytes;
#endif
  CHECK(grew_heap > all / 2, "on the heap RssAnon grew by %zu bytes (films: %zu)", grew_heap, all);
  CHECK(grew_store < all / 8, "with the store RssAnon grew by %zu bytes (films: %zu)", grew_store, all);
  CHECK(grew_half > 8 * film_bytes && grew_half < all / 8 + 10 * film_bytes,
        "10 films on the heap: RssAnon grew by %zu bytes (a film: %zu)", grew_half, film_bytes);
  /* No file is left in the directory but the datasets. */
  CHECK(unlink(heap_nc) == 0 && unlink(store_nc) == 0 && unlink(half_nc) == 0 && rmdir(dir) == 0,
        "only the datasets were left in %s", dir);
  for (int i = 0; i < N_FILMS; i++) free(exr[i]);
}

/* A disk that cannot take the store (RLIMIT_FSIZE below the store's first
 * block, SIGXFSZ ignored): the film is refused with RSW_ERR_IO, an error
 * that names the film and the directory; nothing crashes. */
static void test_store_full(void) {
  char dir[] = "/tmp/rsw_store_full_XXXXXX";
  REQUIRE(mkdtemp(dir), "temp dir");
  size_t len;
  void *exr = film_exr(0, &len);
  REQUIRE(exr, "film encoded");
  rsw_dataset *d;
  REQUIRE(rsw_dataset_new(&d) == RSW_OK && rsw_dataset_set_store(d, dir, 0) == RSW_OK &&
              rsw_dataset_add_context(d, "c00", 0, NULL) == RSW_OK,
          "a dataset with a store");
  struct rlimit old;
  getrlimit(RLIMIT_FSIZE, &old);
  struct rlimit lim = {1 << 20, old.rlim_max};
  void (*was)(int) = signal(SIGXFSZ, SIG_IGN);
  REQUIRE(setrlimit(RLIMIT_FSIZE, &lim) == 0, "RLIMIT_FSIZE");
  rsw_status st = rsw_dataset_add_film_exr(d, "c00", "cam", exr, len, NULL, 0);
  setrlimit(RLIMIT_FSIZE, &old);
  signal(SIGXFSZ, was);
  const char *msg = rsw_dataset_last_error(d);
  CHECK(st == RSW_ERR_IO && strstr(msg, "film c00/cam") && strstr(msg, dir) && strstr(msg, "cannot grow"),
        "a store that cannot grow: status %d, '%s'", (int)st, msg);
  rsw_dataset_free(d);
  free(exr);
  CHECK(rmdir(dir) == 0, "nothing left in %s", dir);
}

static void test_store_errors(void) {
  rsw_dataset *d;
  REQUIRE(rsw_dataset_new(&d) == RSW_OK, "new");
  CHECK(rsw_dataset_set_store(d, "/nonexistent/dir", 0) == RSW_ERR_IO &&
            strstr(rsw_dataset_last_error(d), "/nonexistent/dir"),
        "a directory that does not exist is named: %s", rsw_dataset_last_error(d));
  CHECK(rsw_dataset_set_store(d, NULL, 0) == RSW_ERR_INVALID, "no directory");
  CHECK(rsw_dataset_set_store(d, "/tmp", 0) == RSW_OK, "a store in /tmp");
  CHECK(rsw_dataset_set_store(d, "/tmp", 0) == RSW_ERR_INVALID &&
            strstr(rsw_dataset_last_error(d), "already"),
        "a second store is refused: %s", rsw_dataset_last_error(d));
  rsw_dataset_free(d);
  CHECK(rsw_dataset_set_store(NULL, "/tmp", 0) == RSW_ERR_INVALID, "no dataset");
}

int main(void) {
  RSW_TEST_RUN(test_store);
  RSW_TEST_RUN(test_store_full);
  RSW_TEST_RUN(test_store_errors);
  RSW_TEST_END("test_dataset_store");
}
