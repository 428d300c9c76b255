/* Render request bodies (POST /v1/scenes/{id}:render, service_render) on
 * the harness scene: an error naming the field, or a film; and whatever
 * the per-render overrides were, the scene's own parameters are unchanged
 * afterwards (overrides apply to that render only). */
#include "fuzz_service.h"

int LLVMFuzzerInitialize(int *argc, char ***argv) {
  (void)argc;
  (void)argv;
  fuzz_service_start();
  return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size > FUZZ_MAX_INPUT) return 0;
  svc_film f;
  memset(&f, 0, sizeof f);
  svc_error e = {0};
  rsw_status st = service_render(fuzz_svc, fuzz_scene_id, (const char *)data, size, NULL, &f, &e);
  fuzz_check_error(st, &e, "render");
  if (st == RSW_OK) FUZZ_CHECK(f.img.data && f.img.width >= 1 && f.img.height >= 1, "an empty film");
  svc_film_free(&f);
  char *now = fuzz_params_now();
  FUZZ_CHECK(strcmp(now, fuzz_params0) == 0, "a render's overrides changed the scene's parameters");
  free(now);
  return 0;
}
