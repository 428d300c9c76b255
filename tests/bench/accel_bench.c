/* The Embree ceilings (accel_bench.h): random rays and a render's own
 * recorded queries traced by Embree alone, on the scene's structure or on a
 * flat single-level copy of its triangles. */
#include "accel_bench.h"

#include <stdatomic.h>

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../server/kernel/accel_internal.h"
#include "../../server/kernel/core/rng.h"
#include "../../server/kernel/shapes/instance.h"

/* ---- ray recording (the replay ceiling) ---------------------------------------------------- */

/* One recorded query, as Embree saw it (after fill_ray). */
typedef struct rec_ray {
  float o[3], d[3], tnear, tfar;
  uint8_t occluded; /* an occlusion query */
  uint8_t width;    /* first ray of a query: the lanes of its packet (1: rtcIntersect1/Occluded1) */
} rec_ray;

struct accel_ray_log {
  rec_ray *r;
  size_t cap;
  _Atomic size_t n;
};

static accel_ray_log *_Atomic g_rec; /* the log being recorded into, or NULL */

/* Record k rays (lanes of one query); the whole query or nothing. */
static void record_rays(const struct RTCRay *const *rays, unsigned k, unsigned width, bool occluded) {
  accel_ray_log *lg = atomic_load(&g_rec);
  if (!lg || k == 0) return;
  size_t at = atomic_fetch_add(&lg->n, k);
  if (at + k > lg->cap) {
    atomic_store(&lg->n, lg->cap); /* full: later queries are not recorded */
    return;
  }
  for (unsigned i = 0; i < k; i++) {
    const struct RTCRay *ray = rays[i];
    rec_ray *q = &lg->r[at + i];
    q->o[0] = ray->org_x, q->o[1] = ray->org_y, q->o[2] = ray->org_z;
    q->d[0] = ray->dir_x, q->d[1] = ray->dir_y, q->d[2] = ray->dir_z;
    q->tnear = ray->tnear, q->tfar = ray->tfar;
    q->occluded = occluded;
    q->width = i == 0 ? (uint8_t)width : 0;
  }
}

accel_ray_log *accel_record_begin(size_t max_rays) {
  accel_ray_log *lg = calloc(1, sizeof *lg);
  if (!lg) return NULL;
  lg->r = malloc((max_rays ? max_rays : 1) * sizeof *lg->r);
  if (!lg->r) {
    free(lg);
    return NULL;
  }
  lg->cap = max_rays;
  atomic_store(&lg->n, 0);
  atomic_store(&g_rec, lg);
  accel_set_query_hook(record_rays);
  return lg;
}

void accel_record_end(void) {
  accel_set_query_hook(NULL);
  atomic_store(&g_rec, NULL);
}

size_t accel_ray_log_count(const accel_ray_log *lg) {
  size_t n = atomic_load(&((accel_ray_log *)lg)->n);
  return n < lg->cap ? n : lg->cap;
}

void accel_ray_log_free(accel_ray_log *lg) {
  if (!lg) return;
  free(lg->r);
  free(lg);
}

/* ---- the random-ray ceiling ------------------------------------------------------------------ */

typedef struct ceiling_job {
  RTCScene scene;
  vec3 c;
  double r;
  uint64_t n, seed;
  unsigned index;
  uint64_t hits;
  float *rays; /* n x (org, dir) */
  struct ceiling_sync *sync;
  bool ok;
} ceiling_job;

/* Workers report ready after generating rays and wait for `go`, so the
 * caller's clock covers the queries only. */
typedef struct ceiling_sync {
  pthread_mutex_t lock;
  pthread_cond_t cond;
  int ready;
  bool go, abort;
} ceiling_sync;

/* A worker: ready (its rays made), then wait for go; true when told to
 * abort (not every worker could start). */
static bool sync_ready_wait(ceiling_sync *sync) {
  pthread_mutex_lock(&sync->lock);
  sync->ready++;
  pthread_cond_broadcast(&sync->cond);
  while (!sync->go) pthread_cond_wait(&sync->cond, &sync->lock);
  bool abort = sync->abort;
  pthread_mutex_unlock(&sync->lock);
  return abort;
}

/* The caller: once the `started` workers are ready, release them at once
 * (abort: to trace nothing) and return the seconds until the last one
 * ends; the sync is destroyed. */
static double sync_release_timed(ceiling_sync *sync, pthread_t *th, int started, bool abort) {
  pthread_mutex_lock(&sync->lock);
  while (sync->ready < started) pthread_cond_wait(&sync->cond, &sync->lock);
  sync->abort = abort;
  sync->go = true;
  pthread_cond_broadcast(&sync->cond);
  pthread_mutex_unlock(&sync->lock);
  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  for (int i = 0; i < started; i++) pthread_join(th[i], NULL);
  clock_gettime(CLOCK_MONOTONIC, &t1);
  pthread_mutex_destroy(&sync->lock);
  pthread_cond_destroy(&sync->cond);
  return (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec);
}

static vec3 uniform_sphere_point(pcg32 *g) {
  double z = 1.0 - 2.0 * pcg32_next_double(g), phi = 2.0 * RSW_PI * pcg32_next_double(g);
  double s = sqrt(fmax(0.0, 1.0 - z * z));
  return v3(s * cos(phi), s * sin(phi), z);
}

/* Generates its rays, waits at the barrier (so that the caller times only
 * the queries), then traces them. */
static void *ceiling_worker(void *arg) {
  ceiling_job *j = arg;
  pcg32 g;
  pcg32_seed(&g, j->seed, j->index + 1);
  j->rays = malloc(j->n * 6 * sizeof(float));
  j->ok = j->rays != NULL;
  for (uint64_t i = 0; j->ok && i < j->n; i++) {
    /* Origin uniform in the bounding ball, direction uniform on the
     * sphere: incoherent rays as secondary bounces produce them. */
    double rr = j->r * cbrt(pcg32_next_double(&g));
    vec3 o = v3_fma(j->c, rr, uniform_sphere_point(&g));
    vec3 d = uniform_sphere_point(&g);
    float *q = &j->rays[6 * i];
    q[0] = (float)o.x, q[1] = (float)o.y, q[2] = (float)o.z;
    q[3] = (float)d.x, q[4] = (float)d.y, q[5] = (float)d.z;
  }
  if (sync_ready_wait(j->sync)) j->ok = false;
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  uint64_t hits = 0;
  for (uint64_t i = 0; j->ok && i < j->n; i++) {
    const float *q = &j->rays[6 * i];
    struct RTCRayHit rh;
    rh.ray.org_x = q[0], rh.ray.org_y = q[1], rh.ray.org_z = q[2];
    rh.ray.dir_x = q[3], rh.ray.dir_y = q[4], rh.ray.dir_z = q[5];
    rh.ray.tnear = 0, rh.ray.tfar = INFINITY, rh.ray.time = 0, rh.ray.mask = 0xFFFFFFFFu, rh.ray.id = 0,
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(j->scene, &ctx, &rh);
    hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
  }
  j->hits = hits;
  free(j->rays);
  j->rays = NULL;
  return NULL;
}

static RTCScene build_flat(const scene *s) {
  RTCScene fs = rtcNewScene(accel_embree_device(s->accel));
  rtcSetSceneBuildQuality(fs, RTC_BUILD_QUALITY_HIGH);
  for (size_t i = 0; i < s->n_shapes; i++) {
    const shape *sh = s->shapes[i];
    if (sh->ops->intersect || shape_is_group(sh) || shape_is_instancing(sh)) continue;
    RTCGeometry g = rtcNewGeometry(accel_embree_device(s->accel), RTC_GEOMETRY_TYPE_TRIANGLE);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                       sh->mesh.n_verts);
    unsigned *ix = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                           3 * sizeof(unsigned), sh->mesh.n_faces);
    for (uint32_t k = 0; k < sh->mesh.n_verts; k++) {
      const float *p = &sh->mesh.pos[3 * (size_t)k];
      vec3 w = v3_sub(xf_point(&sh->to_world, v3(p[0], p[1], p[2])), accel_origin(s->accel));
      v[3 * k] = (float)w.x, v[3 * k + 1] = (float)w.y, v[3 * k + 2] = (float)w.z;
    }
    memcpy(ix, sh->mesh.faces, 3 * (size_t)sh->mesh.n_faces * sizeof(unsigned));
    rtcCommitGeometry(g);
    rtcAttachGeometry(fs, g);
    rtcReleaseGeometry(g);
  }
  rtcCommitScene(fs);
  return fs;
}

double accel_ceiling_rays_per_s(const scene *s, bool flat, uint64_t n_rays, int threads, uint64_t seed) {
  if (!s->accel || threads < 1 || threads > 256) return 0;
  RTCScene sc = flat ? build_flat(s) : accel_embree_top(s->accel);
  if (!sc) return 0;
  ceiling_job jobs[256];
  pthread_t th[256];
  ceiling_sync sync = {.ready = 0};
  pthread_mutex_init(&sync.lock, NULL);
  pthread_cond_init(&sync.cond, NULL);
  if (n_rays > ((uint64_t)1 << 26)) n_rays = (uint64_t)1 << 26;
  int started = 0;
  for (int i = 0; i < threads; i++) {
    jobs[i] = (ceiling_job){.scene = sc,
                            .c = v3_sub(s->bsphere_center, accel_origin(s->accel)),
                            .r = s->bsphere_radius,
                            .n = n_rays / (uint64_t)threads,
                            .seed = seed,
                            .index = (unsigned)i,
                            .sync = &sync};
    if (pthread_create(&th[i], NULL, ceiling_worker, &jobs[i]) != 0) break;
    started++;
  }
  double dt = sync_release_timed(&sync, th, started, started < threads);
  bool ok = started == threads;
  for (int i = 0; i < started; i++) ok = ok && jobs[i].ok;
  if (flat) rtcReleaseScene(sc);
  return ok && dt > 0 ? (double)(n_rays / (uint64_t)threads) * started / dt : 0;
}

/* ---- replay ceiling ------------------------------------------------------------------------- */

typedef struct replay_job {
  RTCScene top;
  const rec_ray *r;
  size_t lo, hi; /* queries starting in [lo, hi) */
  size_t n_end;  /* records in the log */
  ceiling_sync *sync;
  uint64_t hits;
} replay_job;

static void *replay_worker(void *arg) {
  replay_job *j = arg;
  sync_ready_wait(j->sync);
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  uint64_t hits = 0;
  size_t i = j->lo;
  while (i < j->hi) {
    const rec_ray *q = &j->r[i];
    unsigned w = q->width ? q->width : 1;
    size_t k = 1;
    while (i + k < j->n_end && k < w && j->r[i + k].width == 0) k++;
    if (w == 1) {
      struct RTCRayHit rh;
      rh.ray.org_x = q->o[0], rh.ray.org_y = q->o[1], rh.ray.org_z = q->o[2];
      rh.ray.dir_x = q->d[0], rh.ray.dir_y = q->d[1], rh.ray.dir_z = q->d[2];
      rh.ray.tnear = q->tnear, rh.ray.tfar = q->tfar, rh.ray.time = 0, rh.ray.mask = 0xFFFFFFFFu;
      rh.ray.id = 0, rh.ray.flags = 0;
      if (q->occluded) {
        rtcOccluded1(j->top, &ctx, &rh.ray);
        hits += rh.ray.tfar < 0;
      } else {
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(j->top, &ctx, &rh);
        hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
      }
    } else {
      packet_buf pb;
      for (unsigned l = 0; l < w; l++) {
        if (l >= k) {
          pb.valid[l] = 0;
          continue;
        }
        const rec_ray *p = &j->r[i + l];
        float *f = pb.f;
        RAYN_F(f, w, RAY_ORG, l) = p->o[0], RAYN_F(f, w, RAY_ORG + 1, l) = p->o[1];
        RAYN_F(f, w, RAY_ORG + 2, l) = p->o[2];
        RAYN_F(f, w, RAY_DIR, l) = p->d[0], RAYN_F(f, w, RAY_DIR + 1, l) = p->d[1];
        RAYN_F(f, w, RAY_DIR + 2, l) = p->d[2];
        RAYN_F(f, w, RAY_TNEAR, l) = p->tnear, RAYN_F(f, w, 7, l) = 0, RAYN_F(f, w, RAY_TFAR, l) = p->tfar;
        ((unsigned *)f)[9 * w + l] = 0xFFFFFFFFu;
        ((unsigned *)f)[10 * w + l] = l;
        ((unsigned *)f)[11 * w + l] = 0;
        float *hb = f + (size_t)RAY_FIELDS * w;
        HITN_U(hb, w, HIT_GEOM, l) = RTC_INVALID_GEOMETRY_ID;
        HITN_U(hb, w, HIT_INST, l) = RTC_INVALID_GEOMETRY_ID;
        pb.valid[l] = -1;
      }
      if (q->occluded) {
        if (w == 16)
          rtcOccluded16(pb.valid, j->top, &ctx, (struct RTCRay16 *)pb.f);
        else if (w == 8)
          rtcOccluded8(pb.valid, j->top, &ctx, (struct RTCRay8 *)pb.f);
        else
          rtcOccluded4(pb.valid, j->top, &ctx, (struct RTCRay4 *)pb.f);
        for (size_t l = 0; l < k; l++) hits += RAYN_F(pb.f, w, RAY_TFAR, l) < 0;
      } else {
        if (w == 16)
          rtcIntersect16(pb.valid, j->top, &ctx, (struct RTCRayHit16 *)pb.f);
        else if (w == 8)
          rtcIntersect8(pb.valid, j->top, &ctx, (struct RTCRayHit8 *)pb.f);
        else
          rtcIntersect4(pb.valid, j->top, &ctx, (struct RTCRayHit4 *)pb.f);
        const float *hb = pb.f + (size_t)RAY_FIELDS * w;
        for (size_t l = 0; l < k; l++) hits += HITN_U(hb, w, HIT_GEOM, l) != RTC_INVALID_GEOMETRY_ID;
      }
    }
    i += k;
  }
  j->hits = hits;
  return NULL;
}

double accel_replay_rays_per_s(const scene *s, const accel_ray_log *lg, int threads, bool flat) {
  size_t n = accel_ray_log_count(lg);
  const accel *a = s->accel;
  if (!a || n == 0 || threads < 1 || threads > 256) return 0;
  RTCScene top = flat ? build_flat(s) : accel_embree_top(a);
  if (!top) return 0;
  replay_job jobs[256];
  pthread_t th[256];
  ceiling_sync sync = {.ready = 0};
  pthread_mutex_init(&sync.lock, NULL);
  pthread_cond_init(&sync.cond, NULL);
  /* Contiguous shares, cut at query starts. */
  size_t lo = 0;
  int started = 0;
  for (int t = 0; t < threads; t++) {
    size_t hi = t == threads - 1 ? n : n * (size_t)(t + 1) / (size_t)threads;
    while (hi < n && lg->r[hi].width == 0) hi++;
    if (hi < lo) hi = lo;
    jobs[t] = (replay_job){.top = top, .r = lg->r, .lo = lo, .hi = hi, .n_end = n, .sync = &sync};
    lo = hi;
    if (pthread_create(&th[t], NULL, replay_worker, &jobs[t]) != 0) break;
    started++;
  }
  double dt = sync_release_timed(&sync, th, started, false);
  if (flat) rtcReleaseScene(top);
  size_t done = started == threads ? n : 0;
  return done && dt > 0 ? (double)done / dt : 0;
}
