/* The two-level Embree acceleration structure (see accel.h for why two
 * levels). The only file that includes Embree.
 *
 * A generic Embree adapter: it never asks which kind a shape is. Shapes
 * without an intersect op (triangle meshes) are Embree triangle geometries
 * in object space; every other shape is a user geometry whose callbacks
 * call its shape_ops.intersect in double precision in the instance's
 * object space (Embree hands the callback the ray already transformed by
 * the instance), with its shape_ops.bounds as the box. Measurement code
 * (make bench) reaches Embree through accel_internal.h. */
#include "accel_internal.h"

#include <stdatomic.h>

#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "core/isa.h"
#include "shapes/instance.h"

struct accel {
  RTCDevice device; /* the process-wide device (not owned) */
  RTCScene top;
  RTCScene *sub;     /* one per shape */
  RTCGeometry *geom; /* the shape's geometry in its scene (held) */
  RTCGeometry *inst; /* its instance in the top level (held) */
  uint32_t *nverts;  /* vertex count Embree holds for each mesh */
  /* Per shape: its instance carries ACCEL_MASK_NULL_BOX only (a null-BSDF
   * box candidate, accel_null_box_candidate; only when the device supports
   * ray masks), so that masked queries do not see it. */
  uint8_t *null_box;
  size_t n_sub;
  bool top_dirty;
  /* An update's Embree work failed (out of memory): a shape scene or the
   * top level may be left uncommitted, and tracing it would crash.
   * Cleared by the next accel_commit that succeeds; accel_ready() is false
   * meanwhile, and renders refuse the scene. */
  bool stale;
  /* Shape groups: one Embree scene each, built once however many
   * instances use it. */
  const shape_group **grp;
  RTCScene *grp_scene;
  size_t n_grp;
  /* Top-level ids >= n_sub are instancelist placements, each list's in
   * one run: list l (shape index list_owner[l]) holds the placements
   * [list_first[l], list_first[l + 1]) of those ids less n_sub, placement
   * k at list_first[l] + k. Per list, not per placement, so that a hit's
   * shape and placement number cost no load that misses the cache
   * (list_placement). */
  uint32_t *list_first, *list_owner;
  size_t n_lists;
  double *list_binv; /* |A^-1|_inf of each placement's float linear part (check_traceable) */
  size_t n_list;
  /* Precision (accel.h): Embree's frame is centred on `origin`; per
   * shape, the object-space bounds of meshes (what the origin is computed
   * from) and `ext`, the largest |coordinate| of its geometry in instance
   * space. */
  const scene *scene;
  vec3 origin;
  /* Rays reach Embree only within clip_r of the origin (fill_ray): a ray
   * starting farther out is advanced along itself to that sphere first, so
   * no ray origin Embree sees, in the top level or in any instance, grows
   * with where a sensor sits. */
  double clip_r;
  vec3 *obox_lo, *obox_hi;
  double *ext;
  accel_counters counters;
  size_t bytes;
  char error[512]; /* first Embree error seen during this build */
};

/* Top-level placement id j (less n_sub) as its instancelist's shape index
 * and placement number: a binary search over the lists (none with one). */
static inline void list_placement(const accel *a, uint32_t j, uint32_t *index, uint32_t *sub) {
  size_t lo = 0, hi = a->n_lists;
  while (hi - lo > 1) {
    size_t mid = lo + (hi - lo) / 2;
    if (a->list_first[mid] <= j)
      lo = mid;
    else
      hi = mid;
  }
  *index = a->list_owner[lo];
  *sub = j - a->list_first[lo];
}

/* One Embree device per process: devices are heavyweight (each owns its
 * thread arenas), and every scene of a daemon shares it. Embree reports
 * errors through a device-wide callback; the message goes to a
 * thread-local slot, since builds of different scenes may run on different
 * threads at once. */
static RTCDevice g_device;
static _Thread_local char t_embree_error[512];

/* Embree's out-of-memory failures (accel_embree_stuck): how many, and
 * whether one came since the last probe. */
static _Atomic unsigned long long g_oom_count;
static _Atomic bool g_oom_pending;

static void on_embree_error(void *user, enum RTCError code, const char *str) {
  (void)user;
  if (code == RTC_ERROR_OUT_OF_MEMORY) {
    atomic_fetch_add(&g_oom_count, 1);
    atomic_store(&g_oom_pending, true);
  }
  if (!t_embree_error[0])
    snprintf(t_embree_error, sizeof t_embree_error, "Embree error %d: %s", (int)code, str ? str : "");
}

/* Bytes the device holds (its memory monitor's running sum). A
 * process-wide counter like the device it measures. */
static _Atomic long long g_embree_bytes;

static bool on_embree_memory(void *user, ssize_t bytes, bool post) {
  (void)user, (void)post;
  atomic_fetch_add(&g_embree_bytes, (long long)bytes);
  return true;
}

#if defined(__SANITIZE_ADDRESS__)
#include <sanitizer/lsan_interface.h>
static void lsan_ignore(const void *p) {
  if (p) __lsan_ignore_object(p);
}
#else
static void lsan_ignore(const void *p) {
  (void)p;
}
#endif

/* The device, created on first use. Not pthread_once: a creation that
 * failed (out of memory) is tried again by the next build instead of
 * leaving the process without Embree for good. */
static pthread_mutex_t g_device_lock = PTHREAD_MUTEX_INITIALIZER;

static RTCDevice device_get(void) {
  pthread_mutex_lock(&g_device_lock);
  if (!g_device) {
    RTCDevice d = rtcNewDevice(NULL);
    if (d && rtcGetDeviceError(d) != RTC_ERROR_NONE) {
      rtcReleaseDevice(d);
      d = NULL;
    }
    if (!d) (void)rtcGetDeviceError(NULL); /* the failed creation's code */
    if (d) {
      rtcSetDeviceErrorFunction(d, on_embree_error, NULL);
      rtcSetDeviceMemoryMonitorFunction(d, on_embree_memory, NULL);
    }
    g_device = d;
  }
  RTCDevice d = g_device;
  pthread_mutex_unlock(&g_device_lock);
  return d;
}

/* Forget errors from before this operation: the message slot, and the
 * device's per-thread error code, which Embree keeps until it is read: an
 * operation that failed early (a NULL from rtcNew*, out of memory) left it
 * set, and the next build on the thread, clean, reported failure. */
static void embree_error_reset(RTCDevice d) {
  t_embree_error[0] = '\0';
  if (d) (void)rtcGetDeviceError(d);
}

/* ---- after Embree ran out of memory: the probe ---------------------------------------

 * A failure inside one of Embree's parallel build tasks can leave a lock of
 * Embree's held, and then every later build waits on it forever
 * (docs/robustness.md#when-memory-runs-out); most failures do not (a large
 * mesh's arrays are allocated before the tasks start). So after one, the
 * next caller of accel_embree_stuck builds a one-triangle scene the way
 * accel_build does (a shape scene, an instance, a top-level scene) on a
 * thread of its own, and waits PROBE_S for it. One that does not finish
 * means Embree is stuck for good in this process: the probe's thread and
 * scene are left as they are, the thread demoted to SCHED_IDLE (a thread
 * stuck on a spin lock then takes only the cores nothing else wants). */
#define PROBE_S 3.0

static pthread_mutex_t g_probe_lock = PTHREAD_MUTEX_INITIALIZER;
static _Atomic long long g_stuck_since; /* 0: not stuck */
static void (*_Atomic g_probe_hook)(void);

typedef struct probe_state {
  pthread_mutex_t m;
  pthread_cond_t c;
  bool done;
  int refs; /* the prober and the thread */
} probe_state;

static void probe_release(probe_state *p) {
  pthread_mutex_lock(&p->m);
  bool last = --p->refs == 0;
  pthread_mutex_unlock(&p->m);
  if (last) {
    pthread_cond_destroy(&p->c);
    pthread_mutex_destroy(&p->m);
    free(p);
  }
}

static void probe_build(void) {
  RTCDevice d = device_get();
  if (!d) return;
  RTCScene sub = rtcNewScene(d), top = rtcNewScene(d);
  RTCGeometry tri = rtcNewGeometry(d, RTC_GEOMETRY_TYPE_TRIANGLE);
  RTCGeometry inst = rtcNewGeometry(d, RTC_GEOMETRY_TYPE_INSTANCE);
  float *v =
      tri ? rtcSetNewGeometryBuffer(tri, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 3)
          : NULL;
  unsigned *f =
      tri ? rtcSetNewGeometryBuffer(tri, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), 1)
          : NULL;
  if (sub && top && v && f && inst) {
    static const float corner[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    memcpy(v, corner, sizeof corner);
    f[0] = 0, f[1] = 1, f[2] = 2;
    rtcCommitGeometry(tri);
    rtcAttachGeometry(sub, tri);
    rtcCommitScene(sub);
    rtcSetGeometryInstancedScene(inst, sub);
    rtcCommitGeometry(inst);
    rtcAttachGeometry(top, inst);
    rtcCommitScene(top);
  }
  if (inst) rtcReleaseGeometry(inst);
  if (tri) rtcReleaseGeometry(tri);
  if (top) rtcReleaseScene(top);
  if (sub) rtcReleaseScene(sub);
  /* (its errors, out of memory again among them, are this thread's own) */
  (void)rtcGetDeviceError(d);
}

static void *probe_main(void *arg) {
  probe_state *p = arg;
  void (*hook)(void) = atomic_load(&g_probe_hook);
  if (hook)
    hook();
  else
    probe_build();
  pthread_mutex_lock(&p->m);
  p->done = true;
  pthread_cond_signal(&p->c);
  pthread_mutex_unlock(&p->m);
  probe_release(p);
  return NULL;
}

/* true: the probe's build finished within PROBE_S (or no thread could be
 * started to run it: nothing is known then). */
static bool probe_finishes(void) {
  probe_state *p = calloc(1, sizeof *p);
  if (!p) return true;
  pthread_mutex_init(&p->m, NULL);
  pthread_condattr_t ca; /* (the wait measured on the monotonic clock: a clock step cannot stretch it) */
  bool attr = pthread_condattr_init(&ca) == 0;
  bool monotonic = attr && pthread_condattr_setclock(&ca, CLOCK_MONOTONIC) == 0;
  pthread_cond_init(&p->c, monotonic ? &ca : NULL);
  if (attr) pthread_condattr_destroy(&ca);
  p->refs = 2;
  pthread_attr_t at;
  pthread_t th;
  bool started = pthread_attr_init(&at) == 0;
  if (started) {
    pthread_attr_setdetachstate(&at, PTHREAD_CREATE_DETACHED);
    started = pthread_create(&th, &at, probe_main, p) == 0;
    pthread_attr_destroy(&at);
  }
  if (!started) {
    p->refs = 1;
    probe_release(p);
    return true;
  }
  struct timespec until;
  clock_gettime(monotonic ? CLOCK_MONOTONIC : CLOCK_REALTIME, &until);
  until.tv_sec += (time_t)PROBE_S;
  pthread_mutex_lock(&p->m);
  while (!p->done && pthread_cond_timedwait(&p->c, &p->m, &until) == 0) continue;
  bool done = p->done;
  /* Stuck: the thread may spin on Embree's lock for good. It runs on only
   * while no other thread wants a core (SCHED_IDLE). (It lives: it takes
   * p->m to say it is done.) */
  if (!done) (void)pthread_setschedparam(th, SCHED_IDLE, &(struct sched_param){.sched_priority = 0});
  pthread_mutex_unlock(&p->m);
  probe_release(p);
  return done;
}

bool accel_embree_stuck(time_t *since, unsigned long long *oom_count, bool probe) {
  if (oom_count) *oom_count = atomic_load(&g_oom_count);
  if (probe && !atomic_load(&g_stuck_since) && atomic_load(&g_oom_pending)) {
    pthread_mutex_lock(&g_probe_lock);
    if (!atomic_load(&g_stuck_since) && atomic_exchange(&g_oom_pending, false) && !probe_finishes())
      atomic_store(&g_stuck_since, (long long)time(NULL));
    pthread_mutex_unlock(&g_probe_lock);
  }
  long long t = atomic_load(&g_stuck_since);
  if (since) *since = (time_t)t;
  return t != 0;
}

void accel_set_probe_hook(void (*hook)(void)) {
  atomic_store(&g_probe_hook, hook);
}

void accel_clear_embree_stuck(void) {
  atomic_store(&g_stuck_since, 0);
  atomic_store(&g_oom_pending, false);
}

/* Nothing more is built once Embree is stuck (accel_embree_stuck): the
 * build would wait forever. */
static rsw_status refuse_if_stuck(rsw_err *err, const char *where) {
  time_t t;
  if (!accel_embree_stuck(&t, NULL, true)) return RSW_OK;
  struct tm tm;
  char when[32] = "";
  if (gmtime_r(&t, &tm)) strftime(when, sizeof when, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return rsw_fail(err, RSW_ERR_UNAVAILABLE, where,
                  "Embree cannot build any more in this process: after it ran out of memory, a test build "
                  "did not finish within %.0f s (%s); restart the daemon (docs/robustness.md)",
                  PROBE_S, when);
}

size_t accel_embree_bytes(void) {
  long long b = atomic_load(&g_embree_bytes);
  return b > 0 ? (size_t)b : 0;
}

/* ---- user geometry: any shape with an intersect op ------------------------------- */

/* Embree's box of an analytic shape: its object bounds (shape_ops.bounds),
 * a flat axis padded to +-1e-6 (a disk's z). */
static void user_box(const shape *s, double lo[3], double hi[3]) {
  vec3 l, h;
  s->ops->bounds(s, &l, &h);
  lo[0] = l.x, lo[1] = l.y, lo[2] = l.z, hi[0] = h.x, hi[1] = h.y, hi[2] = h.z;
  for (int k = 0; k < 3; k++)
    if (lo[k] == hi[k]) lo[k] -= 1e-6, hi[k] += 1e-6;
}

static void unit_bounds(const struct RTCBoundsFunctionArguments *args) {
  const shape *s = args->geometryUserPtr;
  struct RTCBounds *b = args->bounds_o;
  double lo[3], hi[3];
  user_box(s, lo, hi);
  b->lower_x = (float)lo[0], b->lower_y = (float)lo[1], b->lower_z = (float)lo[2];
  b->upper_x = (float)hi[0], b->upper_y = (float)hi[1], b->upper_z = (float)hi[2];
}

/* The shape's own intersection, in double precision in its object space. */
static inline bool unit_hit(const shape *s, const double o[3], const double d[3], double tnear, double tfar,
                            double *t_out, double n_out[3]) {
  return s->ops->intersect(s, o, d, tnear, tfar, t_out, n_out);
}

static void load_ray(const void *ray, unsigned N, unsigned i, double o[3], double d[3]) {
  for (int k = 0; k < 3; k++) {
    o[k] = RAYN_F(ray, N, RAY_ORG + k, i);
    d[k] = RAYN_F(ray, N, RAY_DIR + k, i);
  }
}

/* Record a hit of ray i at distance t with geometric normal n (in the
 * space Embree handed the ray in); u, v are unused by analytic shapes. */
static void store_hit(const struct RTCIntersectFunctionNArguments *args, unsigned i, double t,
                      const double n[3]) {
  unsigned N = args->N;
  void *hit = (float *)args->rayhit + (size_t)RAY_FIELDS * N;
  RAYN_F(args->rayhit, N, RAY_TFAR, i) = (float)t;
  for (int k = 0; k < 3; k++) HITN_F(hit, N, HIT_NG + k, i) = (float)n[k];
  HITN_F(hit, N, HIT_U, i) = 0;
  HITN_F(hit, N, HIT_V, i) = 0;
  HITN_U(hit, N, HIT_PRIM, i) = args->primID;
  HITN_U(hit, N, HIT_GEOM, i) = args->geomID;
  HITN_U(hit, N, HIT_INST, i) = args->context->instID[0];
}

static void unit_intersect(const struct RTCIntersectFunctionNArguments *args) {
  const shape *s = args->geometryUserPtr;
  unsigned N = args->N;
  void *ray = args->rayhit;
  for (unsigned i = 0; i < N; i++) {
    if (!args->valid[i]) continue;
    double o[3], d[3], t, n[3];
    load_ray(ray, N, i, o, d);
    if (!unit_hit(s, o, d, RAYN_F(ray, N, RAY_TNEAR, i), RAYN_F(ray, N, RAY_TFAR, i), &t, n)) continue;
    store_hit(args, i, t, n);
  }
}

static void unit_occluded(const struct RTCOccludedFunctionNArguments *args) {
  const shape *s = args->geometryUserPtr;
  unsigned N = args->N;
  void *ray = args->ray;
  for (unsigned i = 0; i < N; i++) {
    if (!args->valid[i]) continue;
    double o[3], d[3], t, n[3];
    load_ray(ray, N, i, o, d);
    if (unit_hit(s, o, d, RAYN_F(ray, N, RAY_TNEAR, i), RAYN_F(ray, N, RAY_TFAR, i), &t, n))
      RAYN_F(ray, N, RAY_TFAR, i) = -INFINITY;
  }
}

/* Group members (analytic shapes inside a shapegroup): Embree hands the
 * ray in group space; the member's own to_world is applied here, in
 * double precision (t is unchanged by the affine map, the direction is not
 * normalised). */
static void member_bounds(const struct RTCBoundsFunctionArguments *args) {
  const shape *s = args->geometryUserPtr;
  struct RTCBounds *b = args->bounds_o;
  double ulo[3], uhi[3];
  user_box(s, ulo, uhi);
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (int c = 0; c < 8; c++) {
    vec3 p =
        xf_point(&s->to_world, v3(c & 1 ? uhi[0] : ulo[0], c & 2 ? uhi[1] : ulo[1], c & 4 ? uhi[2] : ulo[2]));
    double q[3] = {p.x, p.y, p.z};
    for (int k = 0; k < 3; k++) lo[k] = fmin(lo[k], q[k]), hi[k] = fmax(hi[k], q[k]);
  }
  /* Widen by a float ulp-scale margin: the box is rounded to float. */
  b->lower_x = nextafterf((float)lo[0], -INFINITY), b->lower_y = nextafterf((float)lo[1], -INFINITY);
  b->lower_z = nextafterf((float)lo[2], -INFINITY);
  b->upper_x = nextafterf((float)hi[0], INFINITY), b->upper_y = nextafterf((float)hi[1], INFINITY);
  b->upper_z = nextafterf((float)hi[2], INFINITY);
}

static void member_ray(const shape *s, const void *ray, unsigned N, unsigned i, double o[3], double d[3]) {
  load_ray(ray, N, i, o, d);
  vec3 oo = xf_inv_point(&s->to_world, v3(o[0], o[1], o[2]));
  vec3 dd = xf_inv_vector(&s->to_world, v3(d[0], d[1], d[2]));
  o[0] = oo.x, o[1] = oo.y, o[2] = oo.z;
  d[0] = dd.x, d[1] = dd.y, d[2] = dd.z;
}

static void member_intersect(const struct RTCIntersectFunctionNArguments *args) {
  const shape *s = args->geometryUserPtr;
  unsigned N = args->N;
  void *ray = args->rayhit;
  for (unsigned i = 0; i < N; i++) {
    if (!args->valid[i]) continue;
    double o[3], d[3], t, n[3];
    member_ray(s, ray, N, i, o, d);
    if (!unit_hit(s, o, d, RAYN_F(ray, N, RAY_TNEAR, i), RAYN_F(ray, N, RAY_TFAR, i), &t, n)) continue;
    vec3 ng = xf_normal(&s->to_world, v3(n[0], n[1], n[2])); /* group space */
    store_hit(args, i, t, (double[3]){ng.x, ng.y, ng.z});
  }
}

static void member_occluded(const struct RTCOccludedFunctionNArguments *args) {
  const shape *s = args->geometryUserPtr;
  unsigned N = args->N;
  void *ray = args->ray;
  for (unsigned i = 0; i < N; i++) {
    if (!args->valid[i]) continue;
    double o[3], d[3], t, n[3];
    member_ray(s, ray, N, i, o, d);
    if (unit_hit(s, o, d, RAYN_F(ray, N, RAY_TNEAR, i), RAYN_F(ray, N, RAY_TFAR, i), &t, n))
      RAYN_F(ray, N, RAY_TFAR, i) = -INFINITY;
  }
}

/* ---- Embree's frame and error bounds --------------------------------------------------- */

static void set_instance_transform(RTCGeometry inst, const xform *t, vec3 origin);

static _Atomic bool g_no_null_box_masks; /* accel_set_null_box_masks(false) */

void accel_set_null_box_masks(bool on) {
  atomic_store(&g_no_null_box_masks, !on);
}

static void set_placement_transform(RTCGeometry inst, const instance_shape *is, uint32_t k, vec3 origin);

static void box_add(vec3 *lo, vec3 *hi, vec3 p) {
  lo->x = fmin(lo->x, p.x), lo->y = fmin(lo->y, p.y), lo->z = fmin(lo->z, p.z);
  hi->x = fmax(hi->x, p.x), hi->y = fmax(hi->y, p.y), hi->z = fmax(hi->z, p.z);
}

/* Shape i's object-space bounds (meshes: its vertices; analytic shapes:
 * the unit box, flat for a disk) and ext, the largest |coordinate| of what
 * Embree holds for it in instance space (an instance: its group's
 * members in group space). */
static void shape_bounds(accel *a, size_t i) {
  const shape *sh = a->scene->shapes[i];
  vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
  if (shape_is_instancing(sh)) {
    const shape_group *g = ((const instance_shape *)sh)->group;
    lo = g->lo, hi = g->hi;
  } else if (shape_is_group(sh)) {
    lo = hi = v3(0, 0, 0);
  } else {
    sh->ops->bounds(sh, &lo, &hi);
  }
  a->obox_lo[i] = lo, a->obox_hi[i] = hi;
  a->ext[i] = fmax(v3_max_abs(lo), v3_max_abs(hi));
}

/* The centre of the geometry's world bounds (object boxes under to_world,
 * group boxes under each placement): a function of the scene's state only.
 * *radius gets the bounds' half diagonal (infinite when they are not
 * finite). */
static vec3 frame_origin(const accel *a, double *radius) {
  const scene *s = a->scene;
  vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
  for (size_t i = 0; i < s->n_shapes; i++) {
    const shape *sh = s->shapes[i];
    if (shape_is_group(sh)) continue;
    if (shape_is_instancing(sh)) {
      instance_bbox(sh, &lo, &hi);
      continue;
    }
    vec3 l = a->obox_lo[i], h = a->obox_hi[i];
    for (int c = 0; c < 8; c++)
      box_add(&lo, &hi, xf_point(&sh->to_world, v3(c & 1 ? h.x : l.x, c & 2 ? h.y : l.y, c & 4 ? h.z : l.z)));
  }
  *radius = 0;
  if (!(lo.x <= hi.x)) return v3(0, 0, 0);
  if (!v3_finite(lo) || !v3_finite(hi)) {
    *radius = INFINITY;
    return v3(0, 0, 0);
  }
  *radius = 0.5 * v3_len(v3_sub(hi, lo));
  if (!isfinite(*radius)) *radius = INFINITY;
  return v3_scale(v3_add(lo, hi), 0.5);
}

/* ---- the last defence: nothing Embree would assert on --------------------------
 * Embree asserts (aborts) on a ray with a coordinate of its origin or
 * direction beyond FLT_LARGE = 1.844e18 (embree common/sys/platform.h,
 * RayK<1>::valid()), and silently drops geometry beyond it. The loaders
 * and parameter updates refuse transforms and coordinates outside
 * core/transform.h's limits, naming the key; this check, run before every
 * commit, is the exact condition for the whole scene, so that whatever
 * slipped past them (an update of vertices and to_world that are each
 * fine alone, an instancelist placement) is an error and never an abort.
 *
 * What Embree computes, with c the origin and R = clip_r: top-level ray
 * origins |o - c| <= R (fill_ray) and directions of length <= ACCEL_MAX_DIR;
 * in instance space, with (A, t) the instance transform and B = A^-1,
 * origins B (o - t), |.|_inf <= |B|_inf (R + |t - c|_inf), and directions
 * B d, <= |B|_inf ACCEL_MAX_DIR; the geometry Embree holds, in instance and
 * world space. Each must stay below FLT_LARGE / 16 (margin for Embree's own
 * arithmetic on them: bounds, o + t d). */
#define ACCEL_FLT_LARGE 1.844e18
#define ACCEL_LIMIT     (ACCEL_FLT_LARGE / 16)
#define ACCEL_MAX_DIR   1024.0 /* fill_ray rescales longer or shorter directions */
#define ACCEL_CLIP      64.0   /* clip_r = ACCEL_CLIP times the bounds' half diagonal */

static double inv_norm_inf(const xform *X) {
  double w = 0;
  for (int r = 0; r < 3; r++) w = fmax(w, fabs(X->inv[r][0]) + fabs(X->inv[r][1]) + fabs(X->inv[r][2]));
  return w;
}

/* One instance transform X of shape `id`; `ext` the largest |coordinate|
 * of what Embree holds in its instance space. */
static rsw_status check_instance(const accel *a, const xform *X, double ext, const char *id, rsw_err *err) {
  const char *name = id ? id : "shape";
  if (X->m[3][0] != 0 || X->m[3][1] != 0 || X->m[3][2] != 0 || X->m[3][3] != 1)
    return rsw_fail(err, RSW_ERR_RANGE, name, "'%s': to_world is not affine; Embree cannot trace it", name);
  for (int r = 0; r < 4; r++)
    for (int c = 0; c < 4; c++)
      if (!isfinite(X->m[r][c]) || !isfinite(X->inv[r][c]))
        return rsw_fail(err, RSW_ERR_RANGE, name, "'%s': to_world is singular or not finite", name);
  double b = inv_norm_inf(X);
  vec3 t = v3(X->m[0][3], X->m[1][3], X->m[2][3]);
  double o_bound = b * (a->clip_r + v3_max_abs(v3_sub(t, a->origin)));
  double d_bound = b * ACCEL_MAX_DIR;
  if (!(o_bound <= ACCEL_LIMIT) || !(d_bound <= ACCEL_LIMIT) || !(ext <= ACCEL_LIMIT))
    return rsw_fail(err, RSW_ERR_RANGE, name,
                    "'%s': float32 tracing cannot represent it in this scene (rays in its object space would "
                    "reach %.3g, geometry %.3g; the limit is %.3g): its scale is too small for the scene's "
                    "extent, or its coordinates too large",
                    name, fmax(o_bound, d_bound), ext, ACCEL_LIMIT);
  return RSW_OK;
}

/* |A^-1|_inf of a placement's row-major 3x4 float matrix, by cofactors in
 * double (a 4x4 inverse per placement would cost a 100,000-leaf canopy
 * 0.1 s per commit); infinite when singular. */
static double placement_binv(const float *m) {
  double a[3][3];
  for (int r = 0; r < 3; r++)
    for (int c = 0; c < 3; c++) a[r][c] = m[4 * r + c];
  double c[3][3];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) {
      int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
      c[j][i] = a[i1][j1] * a[i2][j2] - a[i1][j2] * a[i2][j1];
    }
  double det = a[0][0] * c[0][0] + a[0][1] * c[1][0] + a[0][2] * c[2][0];
  if (!(fabs(det) > 0) || !isfinite(det)) return INFINITY;
  double w = 0;
  for (int r = 0; r < 3; r++) w = fmax(w, (fabs(c[r][0]) + fabs(c[r][1]) + fabs(c[r][2])) / fabs(det));
  return isfinite(w) ? w : INFINITY;
}

/* The whole scene as Embree would hold it after the next commit. */
static rsw_status check_traceable(const accel *a, rsw_err *err) {
  const scene *s = a->scene;
  if (!(a->clip_r <= ACCEL_LIMIT))
    return rsw_fail(err, RSW_ERR_RANGE, "",
                    "the scene's geometry spans %.3g, beyond what float32 tracing can represent (%.3g)",
                    a->clip_r / ACCEL_CLIP, ACCEL_LIMIT / ACCEL_CLIP);
  for (size_t i = 0; i < s->n_shapes; i++) {
    const shape *sh = s->shapes[i];
    if (shape_is_group(sh)) {
      const shape_group *g = (const shape_group *)sh;
      if (!(fmax(v3_max_abs(g->lo), v3_max_abs(g->hi)) <= ACCEL_LIMIT))
        return rsw_fail(err, RSW_ERR_RANGE, sh->base.id ? sh->base.id : "shapegroup",
                        "shapegroup '%s': its members reach coordinates float32 tracing cannot represent",
                        sh->base.id ? sh->base.id : "");
      continue;
    }
    if (shape_is_instancing(sh) && ((const instance_shape *)sh)->xf) continue; /* below */
    rsw_status st = check_instance(a, &sh->to_world, a->ext[i], sh->base.id, err);
    if (st) return st;
  }
  /* instancelist placements: fixed at load, their inverse norms computed once. */
  for (size_t l = 0; l < a->n_lists; l++) {
    const instance_shape *is = (const instance_shape *)s->shapes[a->list_owner[l]];
    double ext = a->ext[a->list_owner[l]];
    for (uint32_t k = 0; k < is->n; k++) {
      const double *t = &is->tr[3 * (size_t)k];
      double tc = fmax(fabs(t[0] - a->origin.x), fmax(fabs(t[1] - a->origin.y), fabs(t[2] - a->origin.z)));
      double b = a->list_binv[a->list_first[l] + k], o_bound = b * (a->clip_r + tc),
             d_bound = b * ACCEL_MAX_DIR;
      if (!(o_bound <= ACCEL_LIMIT) || !(d_bound <= ACCEL_LIMIT) || !(ext <= ACCEL_LIMIT)) {
        const char *name = is->base.base.id ? is->base.base.id : "instancelist";
        return rsw_fail(err, RSW_ERR_RANGE, name,
                        "'%s': placement %u: float32 tracing cannot represent it in this scene (rays in its "
                        "object space would reach %.3g, geometry %.3g; the limit is %.3g)",
                        name, k, fmax(o_bound, d_bound), ext, ACCEL_LIMIT);
      }
    }
  }
  return RSW_OK;
}

/* Every top-level instance transform again, for a new origin. */
static void rewrite_instances(accel *a) {
  const scene *s = a->scene;
  for (size_t i = 0; i < s->n_shapes; i++) {
    const shape *sh = s->shapes[i];
    if (shape_is_group(sh)) continue;
    if (shape_is_instancing(sh) && ((const instance_shape *)sh)->xf) continue;
    if (!a->inst[i]) continue;
    set_instance_transform(a->inst[i], &sh->to_world, a->origin);
    rtcCommitGeometry(a->inst[i]);
  }
  for (size_t l = 0; l < a->n_lists; l++) {
    const instance_shape *is = (const instance_shape *)s->shapes[a->list_owner[l]];
    for (uint32_t k = 0; k < is->n; k++) {
      RTCGeometry inst = rtcGetGeometry(a->top, (unsigned)(a->n_sub + a->list_first[l] + k));
      set_placement_transform(inst, is, k, a->origin);
      rtcCommitGeometry(inst);
    }
  }
  a->counters.origin_moves++;
}

vec3 accel_origin(const accel *a) {
  return a ? a->origin : v3(0, 0, 0);
}

/* The float32 error of Embree's view of the surface near p, measured
 * along the unit normal n (accel.h). Embree rounds the ray origin o ~ p in
 * its frame (error u |o - c| per coordinate, so u |n|_1 |p - c| along n),
 * then maps it into instance space with the float inverse B = A^-1 of the
 * instance transform (A, t): coordinate k of o_i = B (o - t) is off by
 * about u |B_k|_1 (|o - c| + |t - c|), which moves the point along n by
 * (A^T n)_k times that; the instance-space intersection itself is off by
 * about u ext per coordinate, (A^T n)_k times that along n. */
static inline void surface_error_terms(const accel *a, uint32_t index, const xform *X, double t[8]) {
  vec3 c = a->origin;
  t[0] = c.x, t[1] = c.y, t[2] = c.z;
  t[3] = v3_max_abs(v3_sub(v3(X->m[0][3], X->m[1][3], X->m[2][3]), c));
  t[4] = a->ext[index];
  for (int k = 0; k < 3; k++) t[5 + k] = fabs(X->inv[k][0]) + fabs(X->inv[k][1]) + fabs(X->inv[k][2]);
}

static inline double surface_error_at(const double t[8], const xform *X, vec3 p, vec3 n) {
  const double nn[3] = {n.x, n.y, n.z};
  double w = 0, an1 = 0;
  for (int k = 0; k < 3; k++) {
    double atn = fabs(X->m[0][k] * nn[0] + X->m[1][k] * nn[1] + X->m[2][k] * nn[2]); /* |(A^T n)_k| */
    an1 += atn;
    w += atn * t[5 + k];
  }
  double pc = v3_max_abs(v3_sub(p, v3(t[0], t[1], t[2])));
  double n1 = fabs(n.x) + fabs(n.y) + fabs(n.z);
  return RSW_F32_UNIT * (n1 * pc + w * (pc + t[3]) + an1 * t[4]);
}

/* The exported three through the inline two (an exported function is not
 * inlined into another under -fPIC). */
double accel_surface_error(const accel *a, uint32_t index, const xform *X, vec3 p, vec3 n) {
  double t[8];
  surface_error_terms(a, index, X, t);
  return surface_error_at(t, X, p, n);
}

void accel_surface_error_terms(const accel *a, uint32_t index, const xform *X, double t[8]) {
  surface_error_terms(a, index, X, t);
}

double accel_surface_error_at(const double t[8], const xform *X, vec3 p, vec3 n) {
  return surface_error_at(t, X, p, n);
}

/* accel_surface_error_at_n's loop, compiled per ISA below (a lane's
 * operations are surface_error_at's: the same bits at every ISA). */
static inline __attribute__((always_inline)) void surface_error_n_body(const double t[8], const xform *X,
                                                                       int m, const double *const p[3],
                                                                       const double *const n[3],
                                                                       double *out) {
  for (int j = 0; j < m; j++)
    out[j] = surface_error_at(t, X, v3(p[0][j], p[1][j], p[2][j]), v3(n[0][j], n[1][j], n[2][j]));
}

#if defined(__x86_64__) || defined(__i386__)
static __attribute__((target("avx512f,avx512vl,avx512dq"))) void
surface_error_n_avx512(const double t[8], const xform *X, int m, const double *const p[3],
                       const double *const n[3], double *out) {
  surface_error_n_body(t, X, m, p, n, out);
}
static __attribute__((target("avx2,fma"))) void surface_error_n_avx2(const double t[8], const xform *X, int m,
                                                                     const double *const p[3],
                                                                     const double *const n[3], double *out) {
  surface_error_n_body(t, X, m, p, n, out);
}
#endif

void accel_surface_error_at_n(const double t[8], const xform *X, int m, const double *const p[3],
                              const double *const n[3], double *out) {
#if defined(__x86_64__) || defined(__i386__)
  switch (rsw_isa_get()) {
  case RSW_ISA_AVX512: surface_error_n_avx512(t, X, m, p, n, out); return;
  case RSW_ISA_AVX2: surface_error_n_avx2(t, X, m, p, n, out); return;
  default: break;
  }
#endif
  surface_error_n_body(t, X, m, p, n, out);
}

/* ---- build ------------------------------------------------------------------------------ */

static rsw_status embree_fail(accel *a, rsw_err *err, const char *where, const char *what) {
  a->stale = true;
  if (!a->error[0]) snprintf(a->error, sizeof a->error, "%s", t_embree_error);
  return rsw_fail(err, RSW_ERR_EMBREE, where, "%s%s%s", what, a->error[0] ? ": " : "", a->error);
}

/* Shape s's Embree geometry, committed; NULL when Embree cannot make it
 * (out of memory). A top-level shape's is in its object space (its
 * instance applies to_world). A shapegroup member's (in_group) is in group
 * space: a mesh's vertices are copied through its to_world, an analytic
 * member's callbacks apply it (the plain ones when it is the identity, so
 * that a group of one untransformed shape traces exactly as that shape
 * would). */
static RTCGeometry shape_geometry(accel *a, const shape *s, bool in_group) {
  RTCGeometry g;
  if (!s->ops->intersect) { /* triangles */
    g = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (!g) return NULL;
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                       s->mesh.n_verts);
    unsigned *ix = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                           3 * sizeof(unsigned), s->mesh.n_faces);
    /* Out of memory inside rtcSetNewGeometryBuffer can still return a
     * buffer while the geometry is left inconsistent (its commit then never
     * returned: test_oom_cli): the reported error counts too. */
    if (!v || !ix || t_embree_error[0]) {
      rtcReleaseGeometry(g);
      return NULL;
    }
    if (in_group) {
      for (uint32_t k = 0; k < s->mesh.n_verts; k++) {
        const float *q = &s->mesh.pos[3 * (size_t)k];
        vec3 w = xf_point(&s->to_world, v3(q[0], q[1], q[2]));
        v[3 * k] = (float)w.x, v[3 * k + 1] = (float)w.y, v[3 * k + 2] = (float)w.z;
      }
    } else {
      memcpy(v, s->mesh.pos, 3 * (size_t)s->mesh.n_verts * sizeof(float));
    }
    memcpy(ix, s->mesh.faces, 3 * (size_t)s->mesh.n_faces * sizeof(unsigned));
    rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_HIGH);
    a->bytes += 3 * (size_t)s->mesh.n_verts * sizeof(float) + 3 * (size_t)s->mesh.n_faces * sizeof(unsigned);
  } else {
    bool member = in_group && !xf_is_identity(&s->to_world);
    g = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_USER);
    if (!g) return NULL;
    rtcSetGeometryUserPrimitiveCount(g, 1);
    rtcSetGeometryUserData(g, (void *)s);
    rtcSetGeometryBoundsFunction(g, member ? member_bounds : unit_bounds, NULL);
    rtcSetGeometryIntersectFunction(g, member ? member_intersect : unit_intersect);
    rtcSetGeometryOccludedFunction(g, member ? member_occluded : unit_occluded);
  }
  rtcCommitGeometry(g);
  return g;
}

/* Instance transform in Embree's frame: the translation is taken relative
 * to the origin in double precision before it is rounded to float. */
static void set_instance_transform(RTCGeometry inst, const xform *t, vec3 origin) {
  float m[12];
  const double o[3] = {origin.x, origin.y, origin.z};
  for (int r = 0; r < 3; r++) {
    for (int c = 0; c < 3; c++) m[4 * r + c] = (float)t->m[r][c];
    m[4 * r + 3] = (float)(t->m[r][3] - o[r]);
  }
  rtcSetGeometryTransform(inst, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, m);
}

/* A shapegroup's Embree scene (built on first use): each member's
 * geometry in group space (shape_geometry). */
static RTCScene group_scene(accel *a, const shape_group *g) {
  for (size_t i = 0; i < a->n_grp; i++)
    if (a->grp[i] == g) return a->grp_scene[i];
  const shape_group **ng = realloc(a->grp, (a->n_grp + 1) * sizeof *ng);
  if (!ng) return NULL;
  a->grp = ng;
  RTCScene *ns = realloc(a->grp_scene, (a->n_grp + 1) * sizeof *ns);
  if (!ns) return NULL;
  a->grp_scene = ns;
  RTCScene sc = rtcNewScene(a->device);
  if (!sc) return NULL;
  rtcSetSceneBuildQuality(sc, RTC_BUILD_QUALITY_HIGH);
  size_t i = 0;
  for (; i < g->n_members; i++) {
    RTCGeometry geo = shape_geometry(a, g->members[i], true);
    if (!geo) break;
    rtcAttachGeometryByID(sc, geo, (unsigned)i);
    rtcReleaseGeometry(geo); /* the scene holds it */
  }
  /* A member that could not be made (out of memory) fails the group:
   * committing the others would trace a group with a member missing. */
  if (i < g->n_members || t_embree_error[0]) {
    rtcReleaseScene(sc);
    return NULL;
  }
  rtcCommitScene(sc);
  a->grp[a->n_grp] = g;
  a->grp_scene[a->n_grp++] = sc;
  return sc;
}

/* Placement k of an instancelist: the float linear part as stored, the
 * double translation relative to the origin. */
static void set_placement_transform(RTCGeometry inst, const instance_shape *is, uint32_t k, vec3 origin) {
  float m[12];
  memcpy(m, &is->xf[12 * (size_t)k], sizeof m);
  const double *t = &is->tr[3 * (size_t)k];
  m[3] = (float)(t[0] - origin.x), m[7] = (float)(t[1] - origin.y), m[11] = (float)(t[2] - origin.z);
  rtcSetGeometryTransform(inst, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, m);
}

/* Instances of a group at top-level ids: an `instance` at its shape index,
 * an instancelist's placements from *next_id on (accel_build's
 * list_first gives the same ids). */
static rsw_status build_instances(accel *a, const instance_shape *is, size_t i, size_t *next_id,
                                  rsw_err *err) {
  const shape *sh = &is->base;
  RTCScene gs = group_scene(a, is->group);
  if (!gs) return embree_fail(a, err, sh->base.id, "cannot build the shape group's scene");
  for (uint32_t k = 0; k < is->n; k++) {
    RTCGeometry inst = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_INSTANCE);
    if (!inst) return embree_fail(a, err, sh->base.id, "cannot create an instance");
    rtcSetGeometryInstancedScene(inst, gs);
    if (is->xf) {
      set_placement_transform(inst, is, k, a->origin);
    } else {
      set_instance_transform(inst, &sh->to_world, a->origin);
    }
    rtcCommitGeometry(inst);
    if (is->xf) {
      size_t id = (*next_id)++;
      rtcAttachGeometryByID(a->top, inst, (unsigned)id);
      rtcReleaseGeometry(inst); /* never updated: the top level holds it */
    } else {
      rtcAttachGeometryByID(a->top, inst, (unsigned)i);
      a->inst[i] = inst;
    }
  }
  return RSW_OK;
}

rsw_status accel_build(scene *s, rsw_err *err) {
  rsw_status refused = refuse_if_stuck(err, "");
  if (refused) return refused;
  accel *a = calloc(1, sizeof *a);
  if (!a) return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
  a->device = device_get();
  if (!a->device) {
    free(a);
    return rsw_fail(err, RSW_ERR_EMBREE, "", "cannot create the Embree device%s%s",
                    t_embree_error[0] ? ": " : "", t_embree_error);
  }
  embree_error_reset(a->device);
  s->accel = a;
  a->top = rtcNewScene(a->device);
  size_t ns = s->n_shapes ? s->n_shapes : 1;
  a->sub = calloc(ns, sizeof *a->sub);
  a->geom = calloc(ns, sizeof *a->geom);
  a->inst = calloc(ns, sizeof *a->inst);
  a->nverts = calloc(ns, sizeof *a->nverts);
  a->null_box = calloc(ns, sizeof *a->null_box);
  a->obox_lo = calloc(ns, sizeof *a->obox_lo);
  a->obox_hi = calloc(ns, sizeof *a->obox_hi);
  a->ext = calloc(ns, sizeof *a->ext);
  if (!a->top || !a->sub || !a->geom || !a->inst || !a->nverts || !a->null_box || !a->obox_lo ||
      !a->obox_hi || !a->ext)
    return embree_fail(a, err, "", "cannot create the top-level scene");
  a->n_sub = s->n_shapes;
  a->scene = s;
  for (size_t i = 0; i < s->n_shapes; i++) shape_bounds(a, i);
  double radius;
  a->origin = frame_origin(a, &radius);
  a->clip_r = ACCEL_CLIP * radius;
  size_t n_list = 0, n_lists = 0;
  for (size_t i = 0; i < s->n_shapes; i++)
    if (shape_is_instancing(s->shapes[i]) && ((const instance_shape *)s->shapes[i])->xf) {
      n_list += ((const instance_shape *)s->shapes[i])->n;
      n_lists++;
    }
  if (n_list + s->n_shapes >= 0xFFFFFFF0u) return rsw_fail(err, RSW_ERR_RANGE, "", "too many instances");
  if (n_list) {
    a->list_first = malloc(n_lists * sizeof *a->list_first);
    a->list_owner = malloc(n_lists * sizeof *a->list_owner);
    a->list_binv = malloc(n_list * sizeof *a->list_binv);
    if (!a->list_first || !a->list_owner || !a->list_binv)
      return rsw_fail(err, RSW_ERR_NOMEM, "", "out of memory");
    a->n_list = n_list;
    a->n_lists = n_lists;
    /* Placements in top-level id order (as build_instances attaches them). */
    size_t j = 0, l = 0;
    for (size_t i = 0; i < s->n_shapes; i++) {
      const instance_shape *is = (const instance_shape *)s->shapes[i];
      if (!shape_is_instancing(s->shapes[i]) || !is->xf) continue;
      a->list_first[l] = (uint32_t)j, a->list_owner[l++] = (uint32_t)i;
      for (uint32_t k = 0; k < is->n; k++, j++) a->list_binv[j] = placement_binv(&is->xf[12 * (size_t)k]);
    }
  }
  {
    rsw_status cst = check_traceable(a, err);
    if (cst) return cst;
  }
  size_t next_id = s->n_shapes;
  for (size_t i = 0; i < s->n_shapes; i++) {
    const shape *sh = s->shapes[i];
    if (shape_is_group(sh)) {
      if (!group_scene(a, (const shape_group *)sh))
        return embree_fail(a, err, sh->base.id, "cannot build the shape group's scene");
      continue;
    }
    if (shape_is_instancing(sh)) {
      rsw_status st = build_instances(a, (const instance_shape *)sh, i, &next_id, err);
      if (st) return st;
      continue;
    }
    RTCScene sub = rtcNewScene(a->device);
    if (!sub) return embree_fail(a, err, sh->base.id, "cannot create a shape scene");
    a->sub[i] = sub;
    /* Meshes: Embree 3.13 honours a per-geometry build quality, and so
     * RTC_BUILD_QUALITY_REFIT when vertices move, only in a dynamic scene
     * of build quality LOW (its two-level builder); the mesh's own BVH is
     * still built with quality HIGH (shape_geometry). */
    if (!sh->ops->intersect) {
      rtcSetSceneFlags(sub, RTC_SCENE_FLAG_DYNAMIC);
      rtcSetSceneBuildQuality(sub, RTC_BUILD_QUALITY_LOW);
    } else {
      rtcSetSceneBuildQuality(sub, RTC_BUILD_QUALITY_HIGH);
    }
    RTCGeometry g = shape_geometry(a, sh, false);
    if (!g) return embree_fail(a, err, sh->base.id, "cannot create geometry");
    rtcAttachGeometryByID(sub, g, 0);
    a->geom[i] = g; /* keep our reference for updates */
    a->nverts[i] = sh->mesh.n_verts;
    rtcCommitScene(sub);
    RTCGeometry inst = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_INSTANCE);
    if (!inst) return embree_fail(a, err, sh->base.id, "cannot create an instance");
    rtcSetGeometryInstancedScene(inst, sub);
    set_instance_transform(inst, &sh->to_world, a->origin);
    if (accel_null_box_candidate(sh) && !atomic_load(&g_no_null_box_masks) &&
        rtcGetDeviceProperty(a->device, RTC_DEVICE_PROPERTY_RAY_MASK_SUPPORTED)) {
      rtcSetGeometryMask(inst, ACCEL_MASK_NULL_BOX);
      a->null_box[i] = 1;
    }
    rtcCommitGeometry(inst);
    rtcAttachGeometryByID(a->top, inst, (unsigned)i);
    a->inst[i] = inst;
  }
  rtcCommitScene(a->top);
  if (t_embree_error[0] || rtcGetDeviceError(a->device) != RTC_ERROR_NONE) {
    snprintf(a->error, sizeof a->error, "%s", t_embree_error);
    return embree_fail(a, err, "", "acceleration structure build failed");
  }
  return RSW_OK;
}

void accel_free(accel *a) {
  if (!a) return;
  /* A commit that failed part-way (out of memory inside Embree's parallel
   * build) leaves the scene's TBB task group un-waited: releasing the
   * scene then terminates the process (TBB's missing_wait thrown from a
   * destructor), and joining the commit first never returns (test_oom_cli,
   * Embree 3.13 with oneTBB 2021). So the Embree objects of a structure
   * whose build or update failed are left allocated (a leak, only after an
   * out-of-memory failure) and only our own arrays are freed. */
  bool release = !a->stale;
  if (!release) { /* the leak is deliberate: LeakSanitizer is told so */
    lsan_ignore(a->top);
    for (size_t i = 0; i < a->n_sub; i++) {
      lsan_ignore(a->sub ? a->sub[i] : NULL);
      lsan_ignore(a->geom ? a->geom[i] : NULL);
      lsan_ignore(a->inst ? a->inst[i] : NULL);
    }
    for (size_t i = 0; i < a->n_grp; i++) lsan_ignore(a->grp_scene[i]);
  }
  if (release && a->top) rtcReleaseScene(a->top);
  for (size_t i = 0; release && i < a->n_sub; i++) {
    if (a->inst[i]) rtcReleaseGeometry(a->inst[i]);
    if (a->geom[i]) rtcReleaseGeometry(a->geom[i]);
    if (a->sub[i]) rtcReleaseScene(a->sub[i]);
  }
  for (size_t i = 0; release && i < a->n_grp; i++) rtcReleaseScene(a->grp_scene[i]);
  free(a->grp);
  free(a->grp_scene);
  free(a->list_first);
  free(a->list_owner);
  free(a->list_binv);
  free(a->sub);
  free(a->geom);
  free(a->inst);
  free(a->nverts);
  free(a->null_box);
  free(a->obox_lo);
  free(a->obox_hi);
  free(a->ext);
  free(a);
}

size_t accel_memory(const accel *a) {
  return a ? a->bytes : 0;
}

/* ---- updates ---------------------------------------------------------------------------------- */

void accel_update_transform(accel *a, const shape *sh) {
  unsigned i = sh->index;
  if (!a->inst[i]) return; /* a shape group: not in the top level */
  set_instance_transform(a->inst[i], &sh->to_world, a->origin);
  rtcCommitGeometry(a->inst[i]);
  a->top_dirty = true;
  a->counters.instance_updates++;
}

static rsw_status check_embree(accel *a, rsw_err *err, const char *where, const char *what) {
  if (t_embree_error[0] || rtcGetDeviceError(a->device) != RTC_ERROR_NONE) {
    snprintf(a->error, sizeof a->error, "%s", t_embree_error);
    t_embree_error[0] = '\0';
    a->stale = true;
    return embree_fail(a, err, where, what);
  }
  return RSW_OK;
}

rsw_status accel_rebuild_shape(accel *a, const shape *sh, rsw_err *err) {
  unsigned i = sh->index;
  rsw_status refused = refuse_if_stuck(err, sh->base.id);
  if (refused) return refused;
  embree_error_reset(a->device);
  a->error[0] = '\0';
  RTCGeometry g = shape_geometry(a, sh, false);
  if (!g) {
    a->stale = true;
    return embree_fail(a, err, sh->base.id, "cannot create geometry");
  }
  rtcDetachGeometry(a->sub[i], 0);
  rtcReleaseGeometry(a->geom[i]);
  rtcAttachGeometryByID(a->sub[i], g, 0);
  a->geom[i] = g;
  a->nverts[i] = sh->mesh.n_verts;
  shape_bounds(a, i);
  rtcCommitScene(a->sub[i]);
  rtcCommitGeometry(a->inst[i]);
  a->top_dirty = true;
  a->counters.rebuilds++;
  return check_embree(a, err, sh->base.id, "rebuilding the shape's BVH failed");
}

rsw_status accel_update_vertices(accel *a, const shape *sh, rsw_err *err) {
  unsigned i = sh->index;
  if (sh->ops->intersect) return RSW_OK; /* no vertices */
  /* A different vertex count is a topology change: rebuild. */
  size_t bytes = 3 * (size_t)sh->mesh.n_verts * sizeof(float);
  float *v = rtcGetGeometryBufferData(a->geom[i], RTC_BUFFER_TYPE_VERTEX, 0);
  if (!v || a->nverts[i] != sh->mesh.n_verts) return accel_rebuild_shape(a, sh, err);
  rsw_status refused = refuse_if_stuck(err, sh->base.id);
  if (refused) return refused;
  embree_error_reset(a->device);
  a->error[0] = '\0';
  memcpy(v, sh->mesh.pos, bytes);
  shape_bounds(a, i);
  rtcUpdateGeometryBuffer(a->geom[i], RTC_BUFFER_TYPE_VERTEX, 0);
  /* Refit the shape's own BVH: its topology is unchanged. */
  rtcSetGeometryBuildQuality(a->geom[i], RTC_BUILD_QUALITY_REFIT);
  rtcCommitGeometry(a->geom[i]);
  rtcCommitScene(a->sub[i]);
  rtcCommitGeometry(a->inst[i]);
  a->top_dirty = true;
  a->counters.refits++;
  return check_embree(a, err, sh->base.id, "refitting the shape's BVH failed");
}

rsw_status accel_commit(accel *a, rsw_err *err) {
  if (!a->top_dirty && !a->stale) return RSW_OK;
  rsw_status refused = refuse_if_stuck(err, "");
  if (refused) return refused;
  embree_error_reset(a->device);
  a->error[0] = '\0';
  if (a->stale) /* a failed update may have left shape scenes uncommitted */
    for (size_t i = 0; i < a->n_sub; i++)
      if (a->sub[i]) rtcCommitScene(a->sub[i]);
  /* The geometry moved: so may the frame's origin (the same function of
   * the scene's state as at load, so that an update equals a reload). */
  double radius;
  vec3 o = frame_origin(a, &radius);
  vec3 o_was = a->origin;
  double clip_was = a->clip_r;
  a->origin = o, a->clip_r = ACCEL_CLIP * radius;
  rsw_status cst = check_traceable(a, err);
  if (cst) {
    /* Nothing is committed: the caller restores the scene's state and
     * commits that again (scene_update). */
    a->origin = o_was, a->clip_r = clip_was;
    return cst;
  }
  if (memcmp(&o, &o_was, sizeof o) != 0) rewrite_instances(a);
  rtcCommitScene(a->top);
  a->counters.top_commits++;
  rsw_status st = check_embree(a, err, "", "committing the top-level scene failed");
  if (st == RSW_OK) a->top_dirty = a->stale = false;
  return st;
}

bool accel_ready(const accel *a) {
  return !a || (!a->top_dirty && !a->stale);
}

void accel_get_counters(const accel *a, accel_counters *out) {
  if (a)
    *out = a->counters;
  else
    memset(out, 0, sizeof *out);
}

/* ---- the query hook (accel_internal.h) ---------------------------------------------------------- */

static accel_query_hook *_Atomic g_hook;

void accel_set_query_hook(accel_query_hook *fn) {
  atomic_store(&g_hook, fn);
}

RTCDevice accel_embree_device(const accel *a) {
  return a->device;
}

RTCScene accel_embree_top(const accel *a) {
  return a->top;
}

static void query_hook(const struct RTCRay *const *rays, unsigned k, unsigned width, bool occluded) {
  accel_query_hook *fn = atomic_load_explicit(&g_hook, memory_order_relaxed);
  if (fn && k) fn(rays, k, width, occluded);
}

/* ---- queries ------------------------------------------------------------------------------- */

/* The ray Embree traces for r: origin relative to the frame's origin c;
 * a direction longer than ACCEL_MAX_DIR or shorter than its inverse
 * rescaled to unit length; an origin farther than clip_r from c advanced
 * along the ray to that sphere (in double, so hits keep their distance).
 * World distance t = *t0 + (Embree's t) * *ts. False when the ray cannot
 * meet the geometry or is not finite: nothing invalid reaches Embree.
 * Rays within the sphere with ordinary directions are passed unchanged. */
enum {
  F_ORG = 0,
  F_TNEAR = 3,
  F_DIR = 4,
  F_TFAR = 7
};
/* fill_ray's values as 8 floats: org xyz, tnear, dir xyz, tfar. Inline, so
 * a packet's lanes are filled in one loop straight into Embree's SOA
 * layout (packet_load). */
static inline __attribute__((always_inline)) bool fill_ray_f(const accel *a, const ray3 *r, float f[8],
                                                             double *t0, double *ts) {
  vec3 d = r->d, oc = v3_sub(r->o, a->origin);
  double tmin = r->tmin, tmax = r->tmax;
  *t0 = 0, *ts = 1;
  /* The squared length decides (no square root for the usual direction):
   * len2 is finite and positive exactly when v3_len is. */
  double len2 = v3_dot(d, d);
  if (!v3_finite(oc) || !(len2 > 0) || !isfinite(len2) || isnan(tmin) || !(tmax >= tmin)) return false;
  /* Embree's segment starts at the origin or later: fmax(tmin, 0) as libm
   * computes it (a NaN gives 0), inline (a libm call per ray cost 5% of a
   * render's instructions). */
  tmin = tmin > 0.0 ? tmin : 0.0;
  if (__builtin_expect(len2 > ACCEL_MAX_DIR * ACCEL_MAX_DIR || len2 < 1.0 / (ACCEL_MAX_DIR * ACCEL_MAX_DIR),
                       0)) {
    double len = sqrt(len2);
    d = v3_scale(d, 1.0 / len);
    tmin *= len, tmax *= len; /* in units of the unit direction */
    *ts = 1.0 / len;
  }
  double q = v3_dot(oc, oc) - a->clip_r * a->clip_r;
  if (q > 0) {
    /* |oc + t d|^2 = clip_r^2, the nearer root t_in. */
    double dd = v3_dot(d, d), b = v3_dot(oc, d);
    double disc = b * b - dd * q;
    if (!(disc >= 0) || b >= 0) return false; /* misses the sphere, or points away from it */
    double t_in = q / (-b + sqrt(disc));      /* = (-b - sqrt(disc)) / dd, stably */
    if (!(t_in < tmax)) return false;
    oc = v3_fma(oc, t_in, d);
    tmin = tmin - t_in > 0.0 ? tmin - t_in : 0.0;
    tmax -= t_in;
    *t0 = t_in * *ts;
  }
  f[F_ORG] = (float)oc.x;
  f[F_ORG + 1] = (float)oc.y;
  f[F_ORG + 2] = (float)oc.z;
  f[F_TNEAR] = (float)tmin;
  f[F_DIR] = (float)d.x;
  f[F_DIR + 1] = (float)d.y;
  f[F_DIR + 2] = (float)d.z;
  f[F_TFAR] = tmax >= 3.0e38 ? INFINITY : (float)tmax;
  return true;
}

static bool fill_ray(const accel *a, struct RTCRay *ray, const ray3 *r, double *t0, double *ts,
                     unsigned mask) {
  float f[8];
  if (!fill_ray_f(a, r, f, t0, ts)) return false;
  ray->org_x = f[F_ORG];
  ray->org_y = f[F_ORG + 1];
  ray->org_z = f[F_ORG + 2];
  ray->dir_x = f[F_DIR];
  ray->dir_y = f[F_DIR + 1];
  ray->dir_z = f[F_DIR + 2];
  ray->tnear = f[F_TNEAR];
  ray->tfar = f[F_TFAR];
  ray->time = 0;
  ray->mask = mask;
  ray->id = 0;
  ray->flags = 0;
  return true;
}

bool accel_intersect(const accel *a, const ray3 *r, accel_hit *h) {
  return accel_intersect_mask(a, r, h, 0xFFFFFFFFu);
}

bool accel_intersect_mask(const accel *a, const ray3 *r, accel_hit *h, unsigned mask) {
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  struct RTCRayHit rh;
  double t0, ts;
  if (!fill_ray(a, &rh.ray, r, &t0, &ts, mask)) return false;
  if (atomic_load_explicit(&g_hook, memory_order_relaxed)) {
    const struct RTCRay *rp = &rh.ray;
    query_hook(&rp, 1, 1, false);
  }
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(a->top, &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
  h->t = t0 + rh.ray.tfar * ts;
  uint32_t id = rh.hit.instID[0];
  if (id < a->n_sub) {
    h->shape = id;
    h->sub = 0;
  } else {
    list_placement(a, id - (uint32_t)a->n_sub, &h->shape, &h->sub);
  }
  h->member = rh.hit.geomID;
  h->prim = rh.hit.primID;
  h->u = rh.hit.u;
  h->v = rh.hit.v;
  h->ng = v3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z);
  return true;
}

bool accel_occluded(const accel *a, const ray3 *r) {
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  struct RTCRay ray;
  double t0, ts;
  if (!fill_ray(a, &ray, r, &t0, &ts, 0xFFFFFFFFu)) return false;
  if (atomic_load_explicit(&g_hook, memory_order_relaxed)) {
    const struct RTCRay *rp = &ray;
    query_hook(&rp, 1, 1, true);
  }
  rtcOccluded1(a->top, &ctx, &ray);
  return ray.tfar < 0;
}

bool accel_cull_box(const accel *a, accel_box *b) {
  if (!a || !a->scene) return false;
  const scene *sc = a->scene;
  const double m = 0x1p-14 * a->clip_r;
  b->lo[0] = sc->bbox_min.x - m, b->lo[1] = sc->bbox_min.y - m, b->lo[2] = sc->bbox_min.z - m;
  b->hi[0] = sc->bbox_max.x + m, b->hi[1] = sc->bbox_max.y + m, b->hi[2] = sc->bbox_max.z + m;
  return true;
}

bool accel_misses_bounds(const accel *a, const ray3 *r) {
  accel_box b;
  return accel_cull_box(a, &b) && accel_box_misses(&b, r);
}

/* ---- packet queries ---------------------------------------------------------------------------- */

/* Widest packet the device traces natively: 16 (AVX-512), 8 (AVX/AVX2),
 * 4 (SSE), or 1 when Embree was built without packet support. Asked once
 * per process: it depends on the CPU and on how Embree was built only. */
static int g_packet_width;
static pthread_once_t g_packet_once = PTHREAD_ONCE_INIT;
static int g_packet_pin; /* accel_set_packet_width (0: native) */

static void packet_width_init(void) {
  RTCDevice d = device_get();
  int w = 1;
  if (d) {
    if (rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED))
      w = 16;
    else if (rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED))
      w = 8;
    else if (rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED))
      w = 4;
    (void)rtcGetDeviceError(d);
  }
  g_packet_width = w;
}

int accel_packet_width(void) {
  pthread_once(&g_packet_once, packet_width_init);
  int w = g_packet_width;
  if (g_packet_pin > 0 && g_packet_pin < w) w = g_packet_pin;
  return w;
}

void accel_set_packet_width(int w) {
  g_packet_pin = w == 16 || w == 8 || w == 4 || w == 1 ? w : 0;
}

/* The valid lanes of a filled packet to the query hook. */
static void packet_record(const packet_buf *pb, unsigned N, int n, bool occluded) {
  if (!atomic_load_explicit(&g_hook, memory_order_relaxed)) return;
  struct RTCRay rays[16];
  const struct RTCRay *rp[16];
  unsigned k = 0;
  const float *p = pb->f;
  for (int i = 0; i < n; i++) {
    if (!pb->valid[i]) continue;
    struct RTCRay *ray = &rays[k];
    ray->org_x = RAYN_F(p, N, RAY_ORG, i);
    ray->org_y = RAYN_F(p, N, RAY_ORG + 1, i);
    ray->org_z = RAYN_F(p, N, RAY_ORG + 2, i);
    ray->tnear = RAYN_F(p, N, RAY_TNEAR, i);
    ray->dir_x = RAYN_F(p, N, RAY_DIR, i);
    ray->dir_y = RAYN_F(p, N, RAY_DIR + 1, i);
    ray->dir_z = RAYN_F(p, N, RAY_DIR + 2, i);
    ray->tfar = RAYN_F(p, N, RAY_TFAR, i);
    rp[k] = ray;
    k++;
  }
  query_hook(rp, k, N, occluded);
}

static unsigned packet_n(int n) {
  int w = accel_packet_width();
  return n <= 4 && w >= 4 ? 4u : n <= 8 && w >= 8 ? 8u : (unsigned)w;
}

/* Lanes [0, n) of an N-wide packet from r (fill_ray's rules; the rest,
 * and rays fill_ray refuses, invalid); false when no lane holds a ray
 * Embree can trace. The lanes are written straight into the SOA layout.
 * Inline, so that packet_load's constant N = 16 makes the invalid marks
 * whole vector stores and the lanes' offsets constants. */
static inline __attribute__((always_inline)) bool packet_load_n(const accel *a, packet_buf *pb, unsigned N,
                                                                const ray3 *const *r, int n, unsigned mask) {
  float *p = pb->f;
  float *hit = p + (size_t)RAY_FIELDS * N;
  for (unsigned i = 0; i < N; i++) {
    RAYN_F(p, N, 7, i) = 0;            /* time */
    ((unsigned *)p)[9 * N + i] = mask; /* mask */
    ((unsigned *)p)[10 * N + i] = i;   /* id */
    ((unsigned *)p)[11 * N + i] = 0;   /* flags */
    HITN_U(hit, N, HIT_GEOM, i) = RTC_INVALID_GEOMETRY_ID;
    HITN_U(hit, N, HIT_INST, i) = RTC_INVALID_GEOMETRY_ID;
    pb->valid[i] = 0;
  }
  bool any = false;
  for (int i = 0; i < n; i++) {
    float f[8];
    if (!fill_ray_f(a, r[i], f, &pb->t0[i], &pb->ts[i])) continue;
    RAYN_F(p, N, RAY_ORG, i) = f[F_ORG];
    RAYN_F(p, N, RAY_ORG + 1, i) = f[F_ORG + 1];
    RAYN_F(p, N, RAY_ORG + 2, i) = f[F_ORG + 2];
    RAYN_F(p, N, RAY_TNEAR, i) = f[F_TNEAR];
    RAYN_F(p, N, RAY_DIR, i) = f[F_DIR];
    RAYN_F(p, N, RAY_DIR + 1, i) = f[F_DIR + 1];
    RAYN_F(p, N, RAY_DIR + 2, i) = f[F_DIR + 2];
    RAYN_F(p, N, RAY_TFAR, i) = f[F_TFAR];
    pb->valid[i] = -1;
    any = true;
  }
  return any;
}

static bool packet_load(const accel *a, packet_buf *pb, unsigned N, const ray3 *const *r, int n,
                        unsigned mask) {
  return N == 16 ? packet_load_n(a, pb, 16, r, n, mask) : packet_load_n(a, pb, N, r, n, mask);
}

/* The packet query's results (intersect_packet): hit i to *h[i] as
 * intersect_packet says. Inline, for a constant N. */
static inline __attribute__((always_inline)) void packet_hits(const accel *a, const packet_buf *pb,
                                                              unsigned N, int n, accel_hit *const *h,
                                                              bool *hit, bool all) {
  const float *p = pb->f;
  const float *hb = p + (size_t)RAY_FIELDS * N;
  for (int i = 0; i < n; i++) {
    unsigned geom = HITN_U(hb, N, HIT_GEOM, i);
    hit[i] = pb->valid[i] && geom != RTC_INVALID_GEOMETRY_ID;
  }
  for (int i = 0; i < n; i++) {
    if (!all && !hit[i]) continue;
    accel_hit *o = h[i];
    o->t = pb->t0[i] + RAYN_F(p, N, RAY_TFAR, i) * pb->ts[i];
    uint32_t id = HITN_U(hb, N, HIT_INST, i);
    if (hit[i] & (id >= a->n_sub)) { /* one predictable branch: false for a miss too */
      list_placement(a, id - (uint32_t)a->n_sub, &o->shape, &o->sub);
    } else {
      o->shape = id;
      o->sub = 0;
    }
    o->member = HITN_U(hb, N, HIT_GEOM, i);
    o->prim = HITN_U(hb, N, HIT_PRIM, i);
    o->u = HITN_F(hb, N, HIT_U, i);
    o->v = HITN_F(hb, N, HIT_V, i);
    o->ng = v3(HITN_F(hb, N, HIT_NG, i), HITN_F(hb, N, HIT_NG + 1, i), HITN_F(hb, N, HIT_NG + 2, i));
  }
}

/* The packet query of accel_intersect_packet: hit i written to *h[i];
 * all: every *h[i] written (a miss's with meaningless values: no branch
 * on an unpredictable outcome), else only the hits'. */
static void intersect_packet(const accel *a, const ray3 *const *r, int n, accel_hit *const *h, bool *hit,
                             bool coherent, unsigned mask, bool all) {
  unsigned N = packet_n(n);
  if (n > (int)N && N > 1) { /* more rays than one packet holds */
    for (int k = 0; k < n; k += (int)N)
      intersect_packet(a, r + k, n - k < (int)N ? n - k : (int)N, h + k, hit + k, coherent, mask, all);
    return;
  }
  if (N == 1 || n == 1) {
    for (int i = 0; i < n; i++) hit[i] = accel_intersect_mask(a, r[i], h[i], mask);
    return;
  }
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  if (coherent) ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  packet_buf pb;
  bool any = packet_load(a, &pb, N, r, n, mask);
  if (any) {
    packet_record(&pb, N, n, false);
    if (N == 16)
      rtcIntersect16(pb.valid, a->top, &ctx, (struct RTCRayHit16 *)pb.f);
    else if (N == 8)
      rtcIntersect8(pb.valid, a->top, &ctx, (struct RTCRayHit8 *)pb.f);
    else
      rtcIntersect4(pb.valid, a->top, &ctx, (struct RTCRayHit4 *)pb.f);
  }
  if (N == 16) /* the usual width as a constant */
    packet_hits(a, &pb, 16, n, h, hit, all);
  else
    packet_hits(a, &pb, N, n, h, hit, all);
}

void accel_intersect_packet(const accel *a, const ray3 *const *r, int n, accel_hit *const *h, bool *hit,
                            bool coherent) {
  intersect_packet(a, r, n, h, hit, coherent, 0xFFFFFFFFu, true);
}

void accel_intersect_packet_mask(const accel *a, const ray3 *const *r, int n, accel_hit *h, bool *hit,
                                 bool coherent, unsigned mask) {
  enum {
    P = 16
  };
  for (int k = 0; k < n; k += P) {
    int m = n - k < P ? n - k : P;
    accel_hit *hp[P];
    for (int i = 0; i < m; i++) hp[i] = &h[k + i];
    intersect_packet(a, r + k, m, hp, hit + k, coherent, mask, false);
  }
}

void accel_occluded_packet(const accel *a, const ray3 *const *r, int n, bool *occ) {
  unsigned N = packet_n(n);
  if (n > (int)N && N > 1) {
    for (int k = 0; k < n; k += (int)N)
      accel_occluded_packet(a, r + k, n - k < (int)N ? n - k : (int)N, occ + k);
    return;
  }
  if (N == 1 || n == 1) {
    for (int i = 0; i < n; i++) occ[i] = accel_occluded(a, r[i]);
    return;
  }
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  packet_buf pb;
  bool any = packet_load(a, &pb, N, r, n, 0xFFFFFFFFu);
  if (any) {
    packet_record(&pb, N, n, true);
    if (N == 16)
      rtcOccluded16(pb.valid, a->top, &ctx, (struct RTCRay16 *)pb.f);
    else if (N == 8)
      rtcOccluded8(pb.valid, a->top, &ctx, (struct RTCRay8 *)pb.f);
    else
      rtcOccluded4(pb.valid, a->top, &ctx, (struct RTCRay4 *)pb.f);
  }
  for (int i = 0; i < n; i++) occ[i] = pb.valid[i] && RAYN_F(pb.f, N, RAY_TFAR, i) < 0;
}

bool accel_null_box_candidate(const shape *sh) {
  return sh->bsdf && (sh->bsdf->flags & BSDF_INDEX_MATCHED) && !sh->emitter && !sh->ops->intersect &&
         sh->mesh.n_faces == 12;
}

bool accel_null_box_masked(const accel *a, uint32_t index) {
  return a && index < a->n_sub && a->null_box && a->null_box[index];
}
