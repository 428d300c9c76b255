/* GET /metrics: request counts by route and status, scenes, jobs,
 * renders and updates, in Prometheus's text format. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../kernel/kapi.h"
#include "buf.h"
#include "rsw_sha256.h"
#include "service_internal.h"

void service_count_request(service *svc, const char *route, int status) {
  pthread_mutex_lock(&svc->lock);
  size_t i = 0;
  for (; i < svc->n_reqs; i++)
    if (svc->reqs[i].status == status && strcmp(svc->reqs[i].route, route) == 0) break;
  if (i == svc->n_reqs) {
    if (!svc_grow((void **)&svc->reqs, &svc->cap_reqs, svc->n_reqs + 1, sizeof *svc->reqs, 0)) {
      pthread_mutex_unlock(&svc->lock);
      return;
    }
    snprintf(svc->reqs[i].route, sizeof svc->reqs[i].route, "%s", route);
    svc->reqs[i].status = status;
    svc->reqs[i].n = 0;
    svc->n_reqs++;
  }
  svc->reqs[i].n++;
  pthread_mutex_unlock(&svc->lock);
}

size_t svc_scene_bytes(const scene *sc) {
  return kapi_scene_bytes(sc);
}

char *service_metrics_text(service *svc) {
  svc_buf b = svc_buf_make(0);
  pthread_mutex_lock(&svc->lock);
  svc_buf_printf(&b, "# HELP raysweep_http_requests_total HTTP requests by route template and status.\n");
  svc_buf_printf(&b, "# TYPE raysweep_http_requests_total counter\n");
  for (size_t i = 0; i < svc->n_reqs; i++)
    svc_buf_printf(&b, "raysweep_http_requests_total{route=\"%s\",status=\"%d\"} %llu\n", svc->reqs[i].route,
                   svc->reqs[i].status, (unsigned long long)svc->reqs[i].n);
  size_t bytes = 0;
  for (size_t i = 0; i < svc->n_scenes; i++) bytes += svc_scene_bytes(svc->scenes[i]->sc);
  svc_buf_printf(
      &b, "# HELP raysweep_scenes_resident Scenes held in memory.\n# TYPE raysweep_scenes_resident gauge\n");
  svc_buf_printf(&b, "raysweep_scenes_resident %zu\n", svc->n_scenes);
  svc_buf_printf(&b, "# HELP raysweep_scene_bytes Bytes held by resident scenes' geometry.\n# TYPE "
                     "raysweep_scene_bytes gauge\n");
  svc_buf_printf(&b, "raysweep_scene_bytes %zu\n", bytes);
  static const char *const states[] = {"queued", "running", "succeeded", "failed", "cancelled"};
  size_t by_state[5] = {0};
  for (size_t i = 0; i < svc->n_jobs; i++) by_state[svc->jobs[i]->state]++;
  svc_buf_printf(&b, "# HELP raysweep_jobs Jobs by state.\n# TYPE raysweep_jobs gauge\n");
  for (int s = 0; s < 5; s++) svc_buf_printf(&b, "raysweep_jobs{state=\"%s\"} %zu\n", states[s], by_state[s]);
  svc_buf_printf(
      &b, "# HELP raysweep_queue_depth Jobs waiting for the worker.\n# TYPE raysweep_queue_depth gauge\n");
  svc_buf_printf(&b, "raysweep_queue_depth %zu\n", svc->n_queue);
  svc_buf_printf(&b, "# HELP raysweep_sync_renders Synchronous renders (POST :render) in progress.\n");
  svc_buf_printf(&b, "# TYPE raysweep_sync_renders gauge\nraysweep_sync_renders %zu\n", svc->sync_renders);
  svc_buf_printf(&b, "# HELP raysweep_contexts_rendered_total Renders of (context, sensor) completed.\n");
  svc_buf_printf(&b,
                 "# TYPE raysweep_contexts_rendered_total counter\nraysweep_contexts_rendered_total %llu\n",
                 (unsigned long long)svc->contexts_rendered);
  svc_buf_printf(&b, "# HELP raysweep_renders_failed_total Renders that failed.\n");
  svc_buf_printf(&b, "# TYPE raysweep_renders_failed_total counter\nraysweep_renders_failed_total %llu\n",
                 (unsigned long long)svc->renders_failed);
  svc_buf_printf(&b, "# HELP raysweep_render_seconds_total Wall time spent rendering.\n");
  svc_buf_printf(&b, "# TYPE raysweep_render_seconds_total counter\nraysweep_render_seconds_total %.6f\n",
                 svc->render_seconds);
  svc_buf_printf(&b,
                 "# HELP raysweep_unresolved_rays_total Rays that could not be resolved (a periodic slab's "
                 "near-horizontal rays, media tracks given up), counted as blocked or ending their path.\n");
  svc_buf_printf(&b, "# TYPE raysweep_unresolved_rays_total counter\nraysweep_unresolved_rays_total %llu\n",
                 (unsigned long long)svc->unresolved_rays);
  svc_buf_printf(&b, "# HELP raysweep_films_nonfinite_total Films rendered with an inf or NaN value (their "
                     "meta has nonfinite).\n");
  svc_buf_printf(&b, "# TYPE raysweep_films_nonfinite_total counter\nraysweep_films_nonfinite_total %llu\n",
                 (unsigned long long)svc->films_nonfinite);
  static const char *const classes[] = {"none", "spectral", "geometric"};
  svc_buf_printf(&b, "# HELP raysweep_update_seconds_total Time spent applying parameter updates, by the "
                     "costliest class touched.\n");
  svc_buf_printf(&b, "# TYPE raysweep_update_seconds_total counter\n");
  for (int c = 0; c < 3; c++)
    svc_buf_printf(&b, "raysweep_update_seconds_total{class=\"%s\"} %.6f\n", classes[c],
                   svc->update_seconds[c]);
  svc_buf_printf(
      &b, "# HELP raysweep_updates_total Parameter updates applied, by the costliest class touched.\n");
  svc_buf_printf(&b, "# TYPE raysweep_updates_total counter\n");
  for (int c = 0; c < 3; c++)
    svc_buf_printf(&b, "raysweep_updates_total{class=\"%s\"} %llu\n", classes[c],
                   (unsigned long long)svc->updates[c]);
  long long stuck_since = 0;
  unsigned long long ooms = 0;
  bool stuck = kapi_embree_stuck(&stuck_since, &ooms, false);
  svc_buf_printf(&b, "# HELP raysweep_embree_out_of_memory_total Embree's failures for want of memory.\n"
                     "# TYPE raysweep_embree_out_of_memory_total counter\n");
  svc_buf_printf(&b, "raysweep_embree_out_of_memory_total %llu\n", ooms);
  svc_buf_printf(&b,
                 "# HELP raysweep_embree_stuck_since When Embree was found unable to build any more (Unix "
                 "time; 0: it is not). Non-zero: restart the daemon.\n"
                 "# TYPE raysweep_embree_stuck_since gauge\n");
  svc_buf_printf(&b, "raysweep_embree_stuck_since %lld\n", stuck ? stuck_since : 0LL);
  /* Memory budget, result storage and durable state. 0: no limit. */
  svc_buf_printf(&b, "# HELP raysweep_scene_bytes_limit The resident-scene budget (--max-scene-bytes; 0: "
                     "none).\n# TYPE raysweep_scene_bytes_limit gauge\n");
  svc_buf_printf(&b, "raysweep_scene_bytes_limit %llu\n", (unsigned long long)svc->opts.max_scene_bytes);
  svc_buf_printf(&b, "# HELP raysweep_scene_budget_bytes Resident scenes' bytes as the budget counts them "
                     "(geometry, acceleration and a measured per-scene and per-shape overhead).\n"
                     "# TYPE raysweep_scene_budget_bytes gauge\n");
  svc_buf_printf(&b, "raysweep_scene_budget_bytes %zu\n", svc->scene_bytes);
  svc_buf_printf(&b, "# HELP raysweep_scenes_evicted_total Idle scenes evicted to stay within the budget.\n"
                     "# TYPE raysweep_scenes_evicted_total counter\n");
  svc_buf_printf(&b, "raysweep_scenes_evicted_total %llu\n", (unsigned long long)svc->scenes_evicted);
  svc_buf_printf(&b, "# HELP raysweep_scenes_reloaded_total Scenes reloaded from the state directory.\n"
                     "# TYPE raysweep_scenes_reloaded_total counter\n");
  svc_buf_printf(&b, "raysweep_scenes_reloaded_total %llu\n", (unsigned long long)svc->scenes_reloaded);
  svc_buf_printf(&b, "# HELP raysweep_result_bytes Finished films held in memory.\n"
                     "# TYPE raysweep_result_bytes gauge\n");
  svc_buf_printf(&b, "raysweep_result_bytes %llu\n", (unsigned long long)svc->result_bytes);
  svc_buf_printf(&b, "# HELP raysweep_result_bytes_reserved Film bytes reserved by live jobs (no state "
                     "directory).\n# TYPE raysweep_result_bytes_reserved gauge\n");
  svc_buf_printf(&b, "raysweep_result_bytes_reserved %llu\n", (unsigned long long)svc->result_committed);
  svc_buf_printf(&b, "# HELP raysweep_result_bytes_limit The in-memory result cap (--max-result-bytes; 0: "
                     "none).\n# TYPE raysweep_result_bytes_limit gauge\n");
  svc_buf_printf(&b, "raysweep_result_bytes_limit %llu\n", (unsigned long long)svc->opts.max_result_bytes);
  svc_buf_printf(&b, "# HELP raysweep_results_written_total Films written to the state directory.\n"
                     "# TYPE raysweep_results_written_total counter\n");
  svc_buf_printf(&b, "raysweep_results_written_total %llu\n", (unsigned long long)svc->results_on_disk);
  svc_buf_printf(&b, "# HELP raysweep_result_disk_bytes_total Bytes of films written to the state "
                     "directory.\n# TYPE raysweep_result_disk_bytes_total counter\n");
  svc_buf_printf(&b, "raysweep_result_disk_bytes_total %llu\n", (unsigned long long)svc->result_disk_bytes);
  svc_buf_printf(&b, "# HELP raysweep_jobs_resumed_total Jobs resumed after a restart.\n"
                     "# TYPE raysweep_jobs_resumed_total counter\n");
  svc_buf_printf(&b, "raysweep_jobs_resumed_total %llu\n", (unsigned long long)svc->jobs_resumed);
  svc_buf_printf(&b, "# HELP raysweep_jobs_restore_failed_total Interrupted jobs that could not resume "
                     "after a restart (failed with the reason).\n# TYPE raysweep_jobs_restore_failed_total "
                     "counter\n");
  svc_buf_printf(&b, "raysweep_jobs_restore_failed_total %llu\n",
                 (unsigned long long)svc->jobs_failed_on_restore);
  svc_buf_printf(&b, "# HELP raysweep_restore_seconds Time the last start spent restoring the state "
                     "directory.\n# TYPE raysweep_restore_seconds gauge\n");
  svc_buf_printf(&b, "raysweep_restore_seconds %.6f\n", svc->restore_s);
  svc_buf_printf(&b, "# HELP raysweep_state_quarantined_total Files of the state directory that failed their "
                     "checks (checksum, identity, bounds, not a regular file), moved to DIR/quarantine.\n"
                     "# TYPE raysweep_state_quarantined_total counter\n");
  svc_buf_printf(&b, "raysweep_state_quarantined_total %llu\n",
                 (unsigned long long)atomic_load(&svc->state_quarantined));
  svc_buf_printf(&b, "# HELP raysweep_state_write_failures_total Writes to the state directory that failed "
                     "(the request answered 507, nothing changed).\n"
                     "# TYPE raysweep_state_write_failures_total counter\n");
  svc_buf_printf(&b, "raysweep_state_write_failures_total %llu\n",
                 (unsigned long long)atomic_load(&svc->state_write_failures));
  svc_buf_printf(&b, "# HELP raysweep_state_writable Whether the state directory took the last write (1 "
                     "without one).\n# TYPE raysweep_state_writable gauge\n");
  svc_buf_printf(&b, "raysweep_state_writable %d\n", atomic_load(&svc->state_unwritable) ? 0 : 1);
  svc_buf_printf(&b, "# HELP raysweep_ready Whether the server accepts work.\n# TYPE raysweep_ready gauge\n");
  svc_buf_printf(&b, "raysweep_ready %d\n", atomic_load(&svc->ready) ? 1 : 0);
  pthread_mutex_unlock(&svc->lock);
  return svc_buf_take(&b);
}

void svc_count_update(service *svc, const struct update_report *rep) {
  int c = (rep->classes & UPDATE_GEOMETRIC) ? 2 : (rep->classes & UPDATE_SPECTRAL) ? 1 : 0;
  pthread_mutex_lock(&svc->lock);
  svc->update_seconds[c] += rep->seconds;
  svc->updates[c]++;
  pthread_mutex_unlock(&svc->lock);
}
