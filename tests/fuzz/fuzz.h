/* Shared helpers of the fuzz harnesses in tests/fuzz/ (see README.md there).
 *
 * Each harness defines LLVMFuzzerTestOneInput (and, when it needs set-up,
 * LLVMFuzzerInitialize). It is built two ways: with clang and libFuzzer
 * (`make fuzz`), and with the project's compiler and tests/fuzz/driver.c,
 * which replays the checked-in corpus and crash inputs (`make test`).
 *
 * A harness aborts (a finding) only on a broken invariant: a crash, a
 * sanitizer report, or a result that contradicts the contract. Errors that
 * the input deserves (a bad document, a refused request) are the normal
 * outcome. */
#ifndef RSW_FUZZ_H
#define RSW_FUZZ_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerInitialize(int *argc, char ***argv);

/* Inputs larger than this are skipped: the readers' own limits are tested
 * elsewhere, and big inputs only slow the fuzzer down. */
#define FUZZ_MAX_INPUT ((size_t)64 << 10)

/* A broken invariant: say what and abort (libFuzzer saves the input). */
#define FUZZ_CHECK(cond, ...)                                                                                \
  do {                                                                                                       \
    if (!(cond)) {                                                                                           \
      fprintf(stderr, "fuzz invariant broken (%s:%d): %s: ", __FILE__, __LINE__, #cond);                     \
      fprintf(stderr, __VA_ARGS__);                                                                          \
      fputc('\n', stderr);                                                                                   \
      abort();                                                                                               \
    }                                                                                                        \
  } while (0)

/* The input as a NUL-terminated malloc'ed copy (NULL on OOM). */
static inline char *fuzz_strndup(const uint8_t *data, size_t size) {
  char *s = malloc(size + 1);
  if (!s) return NULL;
  if (size) memcpy(s, data, size);
  s[size] = '\0';
  return s;
}

/* The scene the service-level harnesses (params, render, job, http) load:
 * mono, one 4x4 hdistant sensor (id "hd") and one 2x2 perspective camera
 * ("cam"), 2 spp, a depth-3 path tracer, a sun and a rectangle with a
 * tabulated reflectance, a sphere, so that PATCH keys of every class exist. */
static const char fuzz_scene_json[] =
    "{\"type\":\"scene\",\"variant\":\"mono\","
    "\"hd\":{\"type\":\"hdistant\",\"target\":[0,0,0],"
    "\"sampler\":{\"type\":\"independent\",\"sample_count\":2},"
    "\"film\":{\"type\":\"hdrfilm\",\"width\":4,\"height\":4,\"rfilter\":{\"type\":\"box\"}}},"
    "\"cam\":{\"type\":\"perspective\",\"fov\":40,"
    "\"to_world\":[{\"lookat\":{\"origin\":[0,0,5],\"target\":[0,0,0],\"up\":[0,1,0]}}],"
    "\"sampler\":{\"type\":\"independent\",\"sample_count\":2},"
    "\"film\":{\"type\":\"hdrfilm\",\"width\":2,\"height\":2,\"rfilter\":{\"type\":\"box\"}}},"
    "\"integrator\":{\"type\":\"path\",\"max_depth\":3},"
    "\"sun\":{\"type\":\"directional\",\"direction\":[0.5,0,-0.8660254037844386],\"irradiance\":1.5},"
    "\"rectangle\":{\"type\":\"rectangle\",\"to_world\":[{\"scale\":[10,10,1]}],"
    "\"bsdf\":{\"type\":\"diffuse\",\"reflectance\":{\"type\":\"spectrum\","
    "\"value\":[[400,0.05],[550,0.1],[700,0.45]]}}},"
    "\"ball\":{\"type\":\"sphere\",\"center\":[0,0,1],\"radius\":0.5,"
    "\"bsdf\":{\"type\":\"roughconductor\",\"alpha\":0.3}}}";

#endif

#include <sys/mman.h>
#include <unistd.h>

/* The input as a file the path-based readers can open: an anonymous memory
 * file, named /proc/self/fd/N (written into path). Returns the descriptor
 * (close it when done) or -1. */
static inline int fuzz_memfile(const uint8_t *data, size_t size, char *path, size_t path_size) {
  int fd = memfd_create("fuzz-input", 0);
  if (fd < 0) return -1;
  size_t off = 0;
  while (off < size) {
    ssize_t w = write(fd, data + off, size - off);
    if (w <= 0) {
      close(fd);
      return -1;
    }
    off += (size_t)w;
  }
  snprintf(path, path_size, "/proc/self/fd/%d", fd);
  return fd;
}
