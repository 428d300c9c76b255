/* Parameter updates (PATCH /v1/scenes/{id}/params, service_params_patch)
 * against the loaded harness scene, then a render of each sensor: a PATCH
 * is refused with an error naming the key, or accepted and the scene still
 * renders. The scene is deleted and reloaded after every input, so each
 * input starts from the same state. */
#include "fuzz_service.h"

int LLVMFuzzerInitialize(int *argc, char ***argv) {
  (void)argc;
  (void)argv;
  fuzz_service_start();
  return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size > FUZZ_MAX_INPUT) return 0;
  char *json = NULL;
  uint64_t rev = 0;
  svc_error e = {0};
  rsw_status st =
      service_params_patch(fuzz_svc, fuzz_scene_id, (const char *)data, size, -1, &json, &rev, &e);
  fuzz_check_error(st, &e, "PATCH");
  free(json);
  if (st == RSW_OK) {
    fuzz_render_ok("{\"spp\":1}");
    fuzz_render_ok("{\"spp\":1,\"sensor\":\"cam\"}");
    e = (svc_error){0};
    FUZZ_CHECK(service_scene_delete(fuzz_svc, fuzz_scene_id, true, &e) == RSW_OK, "delete: %s", e.err.msg);
    fuzz_scene_load();
  } else {
    /* A refused PATCH changes nothing. */
    char *now = fuzz_params_now();
    FUZZ_CHECK(strcmp(now, fuzz_params0) == 0, "a refused PATCH changed the parameters");
    free(now);
  }
  return 0;
}
