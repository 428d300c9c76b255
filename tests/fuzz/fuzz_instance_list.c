/* The instance-list reader (server/kernel/shapes/instance.c, the
 * instancelist shape's file): placements or an error naming file:line. */
#include <math.h>

#include "../../server/kernel/shapes/instance.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size > FUZZ_MAX_INPUT) return 0;
  char path[64];
  int fd = fuzz_memfile(data, size, path, sizeof path);
  if (fd < 0) return 0;
  float *xf = NULL;
  uint32_t n = 0;
  rsw_err err = {0};
  rsw_status st = instance_list_parse(path, &xf, &n, &err);
  if (st == RSW_OK) {
    FUZZ_CHECK(n == 0 || xf != NULL, "%u placements without data", n);
    for (size_t i = 0; i < (size_t)n * 12; i++)
      FUZZ_CHECK(isfinite(xf[i]), "placement %zu not finite", i / 12);
  } else {
    FUZZ_CHECK(err.msg[0] != '\0', "an error without a message");
  }
  free(xf);
  close(fd);
  return 0;
}
