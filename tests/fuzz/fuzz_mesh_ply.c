/* The PLY mesh reader (server/kernel/shapes/mesh_io.c, ascii and binary):
 * a mesh whose indices are in range and whose positions are finite, or an
 * error. */
#include <math.h>

#include "../../server/kernel/shapes/mesh_io.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size > FUZZ_MAX_INPUT) return 0;
  char path[64];
  int fd = fuzz_memfile(data, size, path, sizeof path);
  if (fd < 0) return 0;
  mesh m = {0};
  rsw_err err = {0};
  rsw_status st = mesh_load_ply(path, &m, &err);
  if (st == RSW_OK) {
    FUZZ_CHECK(m.n_faces == 0 || m.faces != NULL, "faces missing");
    FUZZ_CHECK(m.n_verts == 0 || m.pos != NULL, "positions missing");
    for (uint32_t i = 0; i < 3 * m.n_faces; i++)
      FUZZ_CHECK(m.faces[i] < m.n_verts, "face index %u of %u vertices", m.faces[i], m.n_verts);
    for (uint32_t i = 0; i < 3 * m.n_verts; i++) FUZZ_CHECK(isfinite(m.pos[i]), "position not finite");
  } else {
    FUZZ_CHECK(err.msg[0] != '\0', "an error without a message");
  }
  mesh_free(&m);
  close(fd);
  return 0;
}
