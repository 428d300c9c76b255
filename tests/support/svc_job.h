/* In-process service tests (tests/service): a job submitted and waited
 * for through the service's own calls, no HTTP. Header-only, so that the
 * kernel tests, which link tests/support without the service, need none
 * of it. */
#ifndef RSW_TEST_SVC_JOB_H
#define RSW_TEST_SVC_JOB_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../server/service/service.h"

/* Submit body (a JobRequest) on scene_id and follow its events to the
 * end; the job id (free), or NULL (said why on stdout). */
static inline char *svc_test_run_job(service *svc, const char *scene_id, const char *body) {
  char *jid = NULL, *json = NULL;
  svc_error e = {0};
  if (service_job_submit(svc, scene_id, body, strlen(body), NULL, &jid, &json, &e)) {
    printf("  submit: %s (%s)\n", e.err.msg, e.err.where);
    return NULL;
  }
  free(json);
  uint64_t after = 0, seq;
  bool end = false;
  for (int guard = 0; !end && guard < 100000; guard++) {
    char *ev = NULL;
    if (service_job_next_event(svc, jid, after, 5000, &seq, &ev, &end, &e)) break;
    if (ev) after = seq;
    free(ev);
  }
  return jid;
}

/* scene_json (a JSON scene) posted: its id (free), or NULL (said why on
 * stdout). */
static inline char *svc_test_post(service *svc, const char *scene_json) {
  bool created;
  char *id = NULL, *json = NULL;
  svc_error e = {0};
  if (service_scene_post(svc, scene_json, strlen(scene_json), false, NULL, &created, &id, &json, &e)) {
    printf("  post: %s (%s)\n", e.err.msg, e.err.where);
    id = NULL;
  }
  free(json);
  return id;
}

/* A service on 2 render threads (*svc) with scene_json posted (*scene_id,
 * free; NULL when it did not load); false when no service starts. Both
 * said on stdout. */
static inline bool svc_test_start(service **svc, const char *scene_json, char **scene_id) {
  rsw_err err = {0};
  service_opts o = {.size = sizeof o, .render_threads = 2};
  *scene_id = NULL;
  if (service_new(&o, svc, &err)) {
    printf("service_new: %s\n", err.msg);
    return false;
  }
  *scene_id = svc_test_post(*svc, scene_json);
  return true;
}

#endif
