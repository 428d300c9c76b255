/* Wavelength sweep of a Lambertian plate with libraysweep. */
#include <raysweep/client.h>
#include <stdio.h>
#include <stdlib.h>

int main(void) {
  rsw_client_opts opts = {.size = sizeof opts, .base_url = getenv("RAYSWEEP_URL")};
  rsw_client *c = NULL;
  rsw_contexts *x = NULL;
  rsw_job_status end = {0};
  char scene[65], job[40], id[16];
  rsw_status s = rsw_client_new(&opts, &c);
  if (!s) s = rsw_scene_push_file(c, "plate.json", NULL, scene, NULL);
  if (!s) s = rsw_contexts_new(&x);
  if (!s)
    s = rsw_contexts_set_job_param(x, "plate.bsdf.reflectance.value",
                                   "{\"wavelengths\": [400, 700], \"values\": [0.2, 0.8]}");
  for (int w = 400; !s && w <= 700; w += 50) {
    snprintf(id, sizeof id, "w%d", w);
    s = rsw_contexts_add(x, id, w, NULL);
  }
  if (!s) s = rsw_job_submit(c, scene, x, NULL, job);
  if (!s) s = rsw_job_wait(c, job, NULL, NULL, 0, &end); /* follows the job's events */
  if (!s && end.state != RSW_JOB_SUCCEEDED) s = RSW_ERR_RENDER;
  for (int w = 400; !s && w <= 700; w += 50) {
    rsw_film *f = NULL;
    snprintf(id, sizeof id, "w%d", w);
    if (!(s = rsw_job_fetch(c, job, id, "camera", &f))) printf("%d %.9g\n", w, rsw_film_data(f)[0]);
    rsw_film_free(f);
  }
  if (s) fprintf(stderr, "sweep: %s: %s%s\n", rsw_strerror(s), rsw_client_last_error(c)->message, end.error);
  rsw_contexts_free(x);
  rsw_client_free(c);
  return s != RSW_OK;
}
