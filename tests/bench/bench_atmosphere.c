/* make bench: atmosphere_1d. proto/examples/atmosphere.json (written by
 * tools/make_atmosphere.py): a 2,400-layer `piecewise` atmosphere, 0-120
 * km in 50 m layers (molecules with an 8 km scale height, aerosols in 0-2
 * km, blendphase rayleigh + hg), over an RPV surface, seen by `hdistant`
 * 32x32 at 1,000 spp, `piecewise_volpath`, mono at 550 nm. One JSON line:
 *   load_s            scene_load_file wall time
 *   render_s          the render's wall time (median of 3); samples_per_s
 *                     = 32*32*spp / render_s; samples_per_cpu_s: per
 *                     second of the render threads' busy time (median of
 *                     3), which other work on a shared machine does not
 *                     inflate
 *   no_atmosphere_*   the same for the scene without the atmosphere (its
 *                     medium and shape removed, same integrator);
 *                     slowdown = no_atmosphere_samples_per_cpu_s /
 *                     samples_per_cpu_s (target <= 2), slowdown_wall the
 *                     same from wall times
 *   update_sigma_t_us one 2,400-layer override of sigma_t.data by
 *                     scene_update (values parsed beforehand: the median
 *                     of 41, alternating the 550 and 650 nm profiles so
 *                     each one changes the grid; target <= 200 us);
 *                     update_sigma_t_parse_us adds parsing the JSON array
 *                     (what a PATCH or a job override costs the kernel)
 *   job_s, contexts_per_s  a 20-context wavelength job through the daemon
 *                     (400..780 nm by 20 nm, each context overriding
 *                     sigma_t.data, albedo.data and the blend weights with
 *                     that wavelength's profiles), from the POST to the
 *                     job's end, at job_spp samples per pixel (default the
 *                     render's); in_process_s: the same 20 overrides and
 *                     renders in process (scene_update, render_sensor) on
 *                     a fresh load, for comparison (on a loaded shared
 *                     machine the two differ by more than the daemon's
 *                     own work, either way)
 * Threads: $RSW_BENCH_THREADS or all cores (the daemon: the same
 * --threads). spp: $RSW_BENCH_ATMO_SPP (default 1000); the job's:
 * $RSW_BENCH_ATMO_JOB_SPP (default: the same). Scene: $RSW_BENCH_ATMO_SCENE or
 * proto/examples/atmosphere.json. The profiles are computed here with the
 * formulas of tools/make_atmosphere.py. */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../../server/kernel/render.h"
#include "../../server/kernel/scene/params.h"
#include "../../server/kernel/scene/scene.h"
#include "../../server/kernel/scene/update.h"
#include "../support/daemon.h"
#include "../support/tsup.h"
#include "bench.h"

#define LAYERS     2400
#define N_CONTEXTS 20
#define N_UPDATES  41
#define MEDIUM     "medium_atmosphere"
#define KEY_SIGMA  MEDIUM ".sigma_t.data"
#define KEY_ALBEDO MEDIUM ".albedo.data"
#define KEY_WEIGHT MEDIUM ".phase_function.weight.data"

/* tools/make_atmosphere.py's profiles at wl nm: sigma_t [m^-1], albedo
 * and the hg share of the scattering, per layer. */
static void profiles(double wl, double *sigma_t, double *albedo, double *weight) {
  const double top = 120e3, h = 8e3, dz = top / LAYERS;
  double bm = 1.2e-5 * pow(550.0 / wl, 4.05), ba = 0.2 / 2e3 * pow(550.0 / wl, 1.3);
  for (int i = 0; i < LAYERS; i++) {
    double z0 = i * dz, z1 = (i + 1) * dz;
    double sm = bm * h * (exp(-z0 / h) - exp(-z1 / h)) / dz;
    double frac = fmin(fmax((2e3 - z0) / dz, 0.0), 1.0);
    double sa = ba * frac, ss = sm + 0.9 * sa;
    sigma_t[i] = sm + sa;
    albedo[i] = ss / (sm + sa);
    weight[i] = 0.9 * sa / ss;
  }
}

/* "[v0, v1, ...]" with %.17g (round-trip). */
static char *json_array(const double *v, size_t n) {
  size_t cap = n * 26 + 3, len = 0;
  char *s = malloc(cap);
  if (!s) return NULL;
  s[len++] = '[';
  for (size_t i = 0; i < n; i++) len += (size_t)snprintf(s + len, cap - len, "%s%.17g", i ? "," : "", v[i]);
  snprintf(s + len, cap - len, "]");
  return s;
}

static int fail(const char *what, const rsw_err *err) {
  char buf[1400];
  fprintf(stderr, "bench atmosphere_1d: %s: %s\n", what, err ? rsw_err_format(err, buf, sizeof buf) : "");
  return 1;
}

/* Render sensor 0 at spp and wl, REPS times: the median wall seconds and
 * the median samples per CPU second (render threads' busy time: a thread
 * the shared machine descheduled does not count against the code). */
#define REPS 3
static bool render_rate(scene *s, uint32_t spp, int threads, double wl, int reps, double *render_s,
                        double *rate_cpu, rsw_err *err) {
  double wall[REPS], cpu[REPS];
  for (int r = 0; r < reps; r++) {
    render_opts o = {.size = sizeof o, .spp = spp, .seed = 1 + r, .threads = threads, .wavelength = wl};
    film_image img;
    render_result_stats st;
    if (render_sensor(s, &o, &img, &st, err)) return false;
    wall[r] = st.wall_s;
    cpu[r] = (double)img.width * img.height * spp / st.busy_s;
    film_image_free(&img);
  }
  *render_s = bench_median(wall, (size_t)reps);
  if (rate_cpu) *rate_cpu = bench_median(cpu, (size_t)reps);
  return true;
}

/* Median microseconds of one sigma_t.data update, alternating two
 * profiles; with parse, the JSON text is parsed inside the timing. */
static bool time_updates(scene *s, char *const text[2], bool parse, double *us, rsw_err *err) {
  double t[N_UPDATES];
  param_value pv[2];
  for (int k = 0; k < 2; k++)
    if (param_value_parse(text[k], KEY_SIGMA, &pv[k], err)) return false;
  bool ok = true;
  for (int i = 0; i < N_UPDATES && ok; i++) {
    param_update u = {.key = KEY_SIGMA};
    double t0 = bench_wall_s();
    if (parse) {
      ok = param_value_parse(text[(i + 1) % 2], KEY_SIGMA, &u.value, err) == RSW_OK;
      if (!ok) break;
      ok = scene_update(s, &u, 1, NULL, err) == RSW_OK;
      t[i] = bench_wall_s() - t0;
      param_value_free(&u.value);
    } else {
      u.value = pv[(i + 1) % 2];
      ok = scene_update(s, &u, 1, NULL, err) == RSW_OK;
      t[i] = bench_wall_s() - t0;
    }
  }
  for (int k = 0; k < 2; k++) param_value_free(&pv[k]);
  *us = ok ? 1e6 * bench_median(t, N_UPDATES) : 0;
  return ok;
}

/* The 20-context job through the daemon: POST the scene, POST the job,
 * wait for its end. Seconds from the job's POST to its end; -1 on failure. */
static double daemon_job(const char *text, size_t len, int threads, uint32_t spp) {
  char dir[] = "/tmp/rsw_bench_atmo_XXXXXX";
  if (!mkdtemp(dir)) return -1;
  char th[16];
  snprintf(th, sizeof th, "%d", threads);
  const char *extra[] = {"--threads", th, NULL};
  tdaemon d;
  if (!tdaemon_start(&d, dir, "atmo", extra, 0)) return -1;
  const char *hdr[] = {"Content-Type: application/json", NULL};
  thttp_resp r = {0};
  double secs = -1;
  char id[80] = "";
  if (tdaemon_http(&d, "POST", "/v1/scenes", hdr, text, len, 600, &r) &&
      (r.status == 201 || r.status == 200)) {
    const char *p = strstr(r.body, "\"id\":\"");
    if (p) sscanf(p + 6, "%64[0-9a-f]", id);
  } else {
    fprintf(stderr, "bench atmosphere_1d: POST /v1/scenes: %d %s\n", r.status, r.body ? r.body : "");
  }
  thttp_resp_free(&r);
  /* The job: contexts w400 ... w780, each with its three arrays. */
  size_t cap = (size_t)N_CONTEXTS * 3 * LAYERS * 26 + 4096, n = 0;
  char *body = *id ? malloc(cap) : NULL;
  double *st = malloc(3 * LAYERS * sizeof *st), *al = st ? st + LAYERS : NULL,
         *wt = st ? st + 2 * LAYERS : NULL;
  if (body && st) {
    n += (size_t)snprintf(body + n, cap - n, "{\"defaults\": {\"spp\": %u}, \"contexts\": [", spp);
    for (int c = 0; c < N_CONTEXTS; c++) {
      double wl = 400 + 20 * c;
      profiles(wl, st, al, wt);
      char *a = json_array(st, LAYERS), *b = json_array(al, LAYERS), *w = json_array(wt, LAYERS);
      if (a && b && w)
        n += (size_t)snprintf(body + n, cap - n,
                              "%s{\"id\": \"w%.0f\", \"wavelength\": %.0f, \"params\": {\"" KEY_SIGMA
                              "\": %s, \"" KEY_ALBEDO "\": %s, \"" KEY_WEIGHT "\": %s}}",
                              c ? ", " : "", wl, wl, a, b, w);
      free(a), free(b), free(w);
    }
    n += (size_t)snprintf(body + n, cap - n, "]}");
    char path[160], job[80] = "";
    snprintf(path, sizeof path, "/v1/scenes/%s/jobs", id);
    double t0 = bench_wall_s();
    if (tdaemon_http(&d, "POST", path, hdr, body, n, 600, &r) && r.status == 202) {
      const char *p = strstr(r.body, "\"id\":\"");
      if (p) sscanf(p + 6, "%70[A-Za-z0-9_-]", job);
    } else {
      fprintf(stderr, "bench atmosphere_1d: POST jobs: %d %.400s\n", r.status, r.body ? r.body : "");
    }
    thttp_resp_free(&r);
    /* Poll every 10 ms until the job leaves queued/running. */
    snprintf(path, sizeof path, "/v1/jobs/%s", job);
    while (*job && tdaemon_http(&d, "GET", path, NULL, NULL, 0, 30, &r) && r.status == 200) {
      bool running = strstr(r.body, "\"state\":\"queued\"") || strstr(r.body, "\"state\":\"running\"");
      bool ok = strstr(r.body, "\"state\":\"succeeded\"") != NULL;
      if (!running) {
        if (ok)
          secs = bench_wall_s() - t0;
        else
          fprintf(stderr, "bench atmosphere_1d: job ended: %.600s\n", r.body);
        thttp_resp_free(&r);
        break;
      }
      thttp_resp_free(&r);
      usleep(10000);
    }
  }
  free(st);
  free(body);
  tdaemon_stop(&d, 10, NULL);
  char logp[300];
  snprintf(logp, sizeof logp, "%s/atmo.log", dir);
  unlink(logp);
  snprintf(logp, sizeof logp, "%s/atmo.port", dir);
  unlink(logp);
  rmdir(dir);
  return secs;
}

int main(void) {
  int threads = bench_threads();
  const char *e = getenv("RSW_BENCH_ATMO_SPP");
  uint32_t spp = e && atoi(e) > 0 ? (uint32_t)atoi(e) : 1000;
  e = getenv("RSW_BENCH_ATMO_JOB_SPP");
  uint32_t job_spp = e && atoi(e) > 0 ? (uint32_t)atoi(e) : spp;
  const char *path = getenv("RSW_BENCH_ATMO_SCENE");
  if (!path || !*path) path = "proto/examples/atmosphere.json";
  size_t len = 0;
  char *text = tsup_read_file(path, &len);
  if (!text) {
    fprintf(stderr, "bench atmosphere_1d: cannot read %s\n", path);
    return 1;
  }
  rsw_err err = {0};
  scene *s = NULL;
  scene_load_opts lo = {.size = sizeof lo};
  double t0 = bench_wall_s();
  if (scene_load_file(path, &lo, &s, &err)) return fail("load", &err);
  double load_s = bench_wall_s() - t0;
  double render_s, rate_cpu;
  if (!render_rate(s, spp, threads, 550, REPS, &render_s, &rate_cpu, &err)) return fail("render", &err);
  double rate = 32.0 * 32.0 * spp / render_s;

  /* One 2,400-layer override of sigma_t.data. */
  double *p550 = malloc(6 * LAYERS * sizeof *p550);
  if (!p550) return 1;
  double *p650 = p550 + 3 * LAYERS;
  profiles(550, p550, p550 + LAYERS, p550 + 2 * LAYERS);
  profiles(650, p650, p650 + LAYERS, p650 + 2 * LAYERS);
  char *arr[2] = {json_array(p550, LAYERS), json_array(p650, LAYERS)};
  double upd_us = 0, upd_parse_us = 0;
  if (!arr[0] || !arr[1]) return 1;
  if (!time_updates(s, arr, false, &upd_us, &err)) return fail("update sigma_t.data", &err);
  if (!time_updates(s, arr, true, &upd_parse_us, &err)) return fail("update sigma_t.data", &err);
  free(arr[0]), free(arr[1]), free(p550);

  scene_free(s);
  /* The job's work in process, on a fresh load as the daemon's is: the 20
   * contexts' overrides applied by scene_update and rendered, one after
   * the other. */
  double inproc_s = 0;
  if (scene_load_file(path, &lo, &s, &err)) return fail("load", &err);
  {
    double *pr = malloc(3 * LAYERS * sizeof *pr);
    if (!pr) return 1;
    for (int c = 0; c < N_CONTEXTS; c++) {
      double wl = 400 + 20 * c, t1 = bench_wall_s(), rs;
      profiles(wl, pr, pr + LAYERS, pr + 2 * LAYERS);
      param_update u[3] = {{.key = KEY_SIGMA}, {.key = KEY_ALBEDO}, {.key = KEY_WEIGHT}};
      for (int k = 0; k < 3; k++)
        u[k].value = (param_value){.kind = PV_ARRAY, .arr = pr + k * LAYERS, .n = LAYERS};
      if (scene_update(s, u, 3, NULL, &err)) return fail("a context's overrides", &err);
      if (!render_rate(s, job_spp, threads, wl, 1, &rs, NULL, &err)) return fail("a context's render", &err);
      inproc_s += bench_wall_s() - t1;
    }
    free(pr);
  }
  scene_free(s);

  /* The same scene without the atmosphere. */
  cJSON *doc = cJSON_ParseWithLength(text, len);
  if (!doc) return fail("parse the scene", NULL);
  cJSON_DeleteItemFromObjectCaseSensitive(doc, "shape_atmosphere");
  cJSON_DeleteItemFromObjectCaseSensitive(doc, MEDIUM);
  char *bare = cJSON_PrintUnformatted(doc);
  cJSON_Delete(doc);
  scene *s0 = NULL;
  if (!bare || scene_load_memory(bare, strlen(bare), "atmosphere-free", false, &lo, &s0, &err))
    return fail("load the scene without its atmosphere", &err);
  free(bare);
  double render0_s, rate0_cpu;
  if (!render_rate(s0, spp, threads, 550, REPS, &render0_s, &rate0_cpu, &err))
    return fail("render without atmosphere", &err);
  double rate0 = 32.0 * 32.0 * spp / render0_s;
  scene_free(s0);

  double job_s = daemon_job(text, len, threads, job_spp);
  free(text);
  if (job_s < 0) return fail("the 20-context job through the daemon", NULL);
  double slowdown = rate0_cpu / rate_cpu;
  printf("{\"bench\": \"atmosphere_1d\", \"layers\": %d, \"load_s\": %.3f, \"render_s\": %.3f, "
         "\"samples_per_s\": %.4g, \"samples_per_cpu_s\": %.4g, \"spp\": %u, \"threads\": %d, "
         "\"no_atmosphere_render_s\": %.3f, \"no_atmosphere_samples_per_s\": %.4g, "
         "\"no_atmosphere_samples_per_cpu_s\": %.4g, \"slowdown\": %.3f, \"slowdown_wall\": %.3f, "
         "\"target_slowdown\": 2, \"update_sigma_t_us\": %.1f, \"update_sigma_t_parse_us\": %.1f, "
         "\"target_update_us\": 200, \"job_contexts\": %d, \"job_spp\": %u, \"job_s\": %.3f, "
         "\"contexts_per_s\": %.3f, \"in_process_s\": %.3f, "
         "\"meets_target\": %s}\n",
         LAYERS, load_s, render_s, rate, rate_cpu, spp, threads, render0_s, rate0, rate0_cpu, slowdown,
         rate0 / rate, upd_us, upd_parse_us, N_CONTEXTS, job_spp, job_s, N_CONTEXTS / job_s, inproc_s,
         slowdown <= 2 && upd_us <= 200 ? "true" : "false");
  return 0;
}
