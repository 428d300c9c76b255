/* The JSON scene reader (server/kernel/scene/json_read.c): any bytes give
 * a document tree or an error naming the place, never a crash. */
#include "../../server/kernel/scene/node.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size > FUZZ_MAX_INPUT) return 0;
  node *root = NULL;
  char *variant = NULL;
  rsw_err err = {0};
  rsw_status st = scene_read_json((const char *)data, size, "fuzz.json", &root, &variant, &err);
  if (st == RSW_OK) {
    FUZZ_CHECK(root != NULL, "RSW_OK without a tree");
  } else {
    FUZZ_CHECK(root == NULL, "a tree with an error");
    FUZZ_CHECK(err.msg[0] != '\0', "an error without a message (status %d)", (int)st);
  }
  node_free(root);
  free(variant);
  return 0;
}
