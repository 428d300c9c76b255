/* Job request bodies (POST /v1/scenes/{id}/jobs, service_job_submit) on
 * the harness scene: refused with an error naming the field, or accepted
 * and run to its end event, and its dataset encodes. Every context is validated before the 202, so
 * an accepted job must succeed with no failed render. The job is deleted after, and the scene's own
 * parameters must be unchanged. Its dry run (?dry_run=1,
 * service_job_check) first: it refuses exactly what the submission refuses,
 * with the same error, and accepts with the renders the job then has.
 * Inputs over 8 KiB are skipped (a context costs a render). */
#include <cjson/cJSON.h>

#include "fuzz_service.h"

int LLVMFuzzerInitialize(int *argc, char ***argv) {
  (void)argc;
  (void)argv;
  fuzz_service_start();
  return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size > 8192) return 0;
  char *job_id = NULL, *json = NULL, *dry = NULL;
  svc_error e = {0}, de = {0};
  rsw_status dst = service_job_check(fuzz_svc, fuzz_scene_id, (const char *)data, size, &dry, &de);
  fuzz_check_error(dst, &de, "job dry run");
  rsw_status st =
      service_job_submit(fuzz_svc, fuzz_scene_id, (const char *)data, size, NULL, &job_id, &json, &e);
  fuzz_check_error(st, &e, "job submit");
  FUZZ_CHECK(dst == st && (st == RSW_OK || strcmp(de.err.msg, e.err.msg) == 0),
             "the dry run answered %d (%s), the submission %d (%s)", (int)dst, de.err.msg, (int)st,
             e.err.msg);
  if (st == RSW_OK) {
    cJSON *a = cJSON_Parse(dry), *b = cJSON_Parse(json);
    const cJSON *na = cJSON_GetObjectItemCaseSensitive(a, "renders_total");
    const cJSON *nb = cJSON_GetObjectItemCaseSensitive(b, "renders_total");
    FUZZ_CHECK(cJSON_IsNumber(na) && cJSON_IsNumber(nb) && na->valuedouble == nb->valuedouble,
               "the dry run's renders_total is not the job's: %s vs %s", dry, json);
    cJSON_Delete(a);
    cJSON_Delete(b);
  }
  free(dry);
  free(json);
  if (st == RSW_OK) {
    FUZZ_CHECK(job_id != NULL, "accepted without a job id");
    uint64_t after = 0;
    bool end = false;
    for (int waited = 0; !end && waited < 200; waited++) {
      uint64_t seq = 0;
      char *ev = NULL;
      e = (svc_error){0};
      st = service_job_next_event(fuzz_svc, job_id, after, 100, &seq, &ev, &end, &e);
      FUZZ_CHECK(st == RSW_OK, "events: %s", e.err.msg);
      if (ev) after = seq;
      free(ev);
    }
    FUZZ_CHECK(end, "the job did not end within 20 s");
    char *job = NULL;
    e = (svc_error){0};
    FUZZ_CHECK(service_job_get(fuzz_svc, job_id, &job, &e) == RSW_OK, "job get: %s", e.err.msg);
    cJSON *j = cJSON_Parse(job);
    const cJSON *state = cJSON_GetObjectItemCaseSensitive(j, "state");
    const cJSON *failed = cJSON_GetObjectItemCaseSensitive(j, "renders_failed");
    FUZZ_CHECK(cJSON_IsString(state) && strcmp(state->valuestring, "succeeded") == 0 &&
                   cJSON_IsNumber(failed) && failed->valuedouble == 0,
               "an accepted job did not succeed (contexts are validated before the 202): %s", job);
    cJSON_Delete(j);
    free(job);
    /* Its dataset (coords, grid or not) encodes. */
    void *nc = NULL;
    size_t nc_len = 0;
    e = (svc_error){0};
    FUZZ_CHECK(service_job_dataset(fuzz_svc, job_id, false, &nc, &nc_len, &e) == RSW_OK && nc_len > 0,
               "the dataset of a finished job: %s", e.err.msg);
    free(nc);
    e = (svc_error){0};
    FUZZ_CHECK(service_job_delete(fuzz_svc, job_id, &e) == RSW_OK, "job delete: %s", e.err.msg);
  }
  free(job_id);
  char *now = fuzz_params_now();
  FUZZ_CHECK(strcmp(now, fuzz_params0) == 0, "a job's overrides changed the scene's parameters");
  free(now);
  return 0;
}
