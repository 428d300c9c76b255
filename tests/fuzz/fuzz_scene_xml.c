/* The XML scene reader (server/kernel/scene/xml_read.c, expat): any bytes
 * give a document tree or an error naming the place, never a crash. Two
 * -D defines ($spp, $r) so that parameter substitution is reached. */
#include "../../server/kernel/scene/node.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size > FUZZ_MAX_INPUT) return 0;
  static const scene_define defs[] = {{"spp", "4"}, {"r", "0.5"}};
  node *root = NULL;
  char *variant = NULL;
  rsw_err err = {0};
  rsw_status st = scene_read_xml((const char *)data, size, "fuzz.xml", defs, 2, &root, &variant, &err);
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
