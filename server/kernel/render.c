/* Tile-parallel rendering with a deterministic result (see render.h).
 *
 * Each pixel (ix, iy) takes spp samples; sample s draws, in order, a 2-D
 * film jitter, a 2-D aperture sample, then whatever the integrator needs
 * (Mitsuba's render_sample order, docs/kernel-conventions.md#the-render-pipeline). The film sample
 * is u = ((ix, iy) + jitter) / (W, H). The sample's contribution w L is
 * splatted with the film's reconstruction filter: with the box filter of
 * radius 0.5 it lands in its own pixel with weight 1 (Mitsuba ignores the
 * jitter for placement), so a pixel is the plain mean of its samples; other
 * filters spread it over the pixels whose centres lie within the radius,
 * and a pixel is sum(f w L) / sum(f).
 *
 * Samples are taken in waves (render_tile, wave_flush): up to WAVE samples
 * of a tile, pixel by pixel and sample by sample, get their camera rays,
 * then go through the integrator's Li_batch together (or Li one by one for
 * an integrator without it), then are splatted in that same order through
 * splat(), so the tile's sums are those of a one-sample-at-a-time loop. */
#include "render.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "accel.h"
#include "core/isa.h"
#include "samplers/sampler_batch.h"
#include "scene/scene.h"

/* Tiles are TILE x TILE pixels; a box-filter film with few of them has
 * smaller ones (tile_size). */
#define TILE             8
/* Tiles per thread tile_size aims at: the render ends when its slowest
 * thread does, and a thread that claims the last tile can finish up to a
 * tile's work after the others. */
#define TILES_PER_THREAD 16

_Thread_local int rsw_page;

/* Accumulator layout per pixel: sum(f w L) rgb, sum(f), and for Stokes
 * films sum(f w (Q, U, V)) (rgb_polarized: per colour channel, nq = 9);
 * then, for a film with variance, per developed channel k (Y; R, G, B;
 * S0..S3; or S0.R..S3.B) the triple (K, sum(x - K), sum((x - K)^2)) of
 * its samples x, K being the pixel's first sample (the shifted-data
 * algorithm: no cancellation, and exactly 0 for a constant pixel). */
#define ACC_MOMENT FILM_ACC_MOMENT

typedef struct tile_buf {
  int x0, y0, w, h; /* region covered, margin included, clipped to film */
  double *acc;      /* w*h*stride */
} tile_buf;

typedef struct job {
  scene *sc;
  const sensor *se;
  const film *fm;
  const render_opts *opts;
  uint32_t spp;
  int W, H, tiles_x, tiles_y;
  int tw, th; /* tile width and height (tile_size) */
  int wave;   /* samples per wave (job_wave) */
  size_t n_tiles;
  int margin;       /* pixels a splat can reach beyond its own */
  bool box;         /* box filter of radius 0.5: own pixel only */
  bool stokes;      /* Stokes film: Q, U, V accumulated too */
  int nq;           /* Stokes films: Q, U, V values per sample (3, or 9 in rgb_polarized);
                       a bundle of pages: the colours of pages 1.. (scene_extra_stride) */
  bool lum;         /* one luminance channel (develop's mapping) */
  int m_ch;         /* variance: developed channels with moments (0: none) */
  int m_off;        /* offset of the first moment triple */
  int stride;       /* doubles per pixel in accumulators */
  double *film_acc; /* W*H*stride */
  /* Ordered merge (under `lock`). */
  pthread_mutex_t lock;
  size_t next_commit;
  tile_buf **done; /* finished, not yet merged */
  atomic_bool failed;
  atomic_bool stopped; /* deadline passed (set by any worker) */
  /* Stats (merged under lock). */
  render_stats rays;
  uint64_t samples, invalid;
  double busy_s;
  /* Work distribution (under the pool's lock; see "the worker pool"). */
  size_t next_tile;
  int max_workers; /* threads that may work on it at once, caller included */
  int active;      /* threads working on it now, caller included */
  int peak;        /* most threads that worked on it at once */
  bool listed;     /* in the pool's list of jobs with tiles to claim */
  struct job *prev, *next;
  pthread_cond_t idle; /* active dropped to 0 (the caller waits on it) */
} job;

static void splat_filter(const job *jb, tile_buf *tb, double px, double py, color v, const double *quv);

/* Channels of a sample as develop sees them: a film's, or a bundle's
 * wavelengths (three of page 0, then the other pages'). */
#define SPLAT_X_MAX (FILM_MAX_CHANNELS > 3 + SCENE_EXTRA_MAX ? FILM_MAX_CHANNELS : 3 + SCENE_EXTRA_MAX)

/* The box filter's pixel for a sample at (px, py): its accumulator. */
static inline double *box_pixel(const job *jb, tile_buf *tb, double px, double py) {
  int ix = (int)px, iy = (int)py;
  if (ix >= jb->W) ix = jb->W - 1;
  if (iy >= jb->H) iy = jb->H - 1;
  return &tb->acc[(size_t)jb->stride * ((size_t)(iy - tb->y0) * tb->w + (ix - tb->x0))];
}

/* The box filter inline (every sample of most renders), others out of line. */
static inline void splat(const job *jb, tile_buf *tb, double px, double py, color v, const double *quv) {
  if (jb->box) {
    double *a = box_pixel(jb, tb, px, py);
    if (jb->m_ch) {
      /* The sample as develop sees it (Y, R G B or S0..S3), then its
       * shifted first and second moments (Eradiate's `moment` integrator
       * keeps the raw E[x^2]; see ACC_MOMENT). */
      double x[SPLAT_X_MAX] = {v.c[0], v.c[1], v.c[2], 0};
      if (!jb->stokes) { /* a bundle's pages 1..: its channels 3.. */
        for (int k = 0; k < jb->nq; k++) x[3 + k] = quv[k];
      } else if (jb->nq == 3) {
        x[1] = quv[0], x[2] = quv[1], x[3] = quv[2];
      } else if (jb->stokes) { /* film order S0.R S0.G S0.B S1.R ... */
        for (int c = 0; c < 3; c++) {
          x[c] = v.c[c];
          for (int k = 0; k < 3; k++) x[3 * (k + 1) + c] = quv[3 * c + k];
        }
      } else if (jb->lum && jb->sc->variant != VARIANT_MONO) {
        x[0] = col_luminance(v);
      }
      bool first = a[3] == 0;
      for (int k = 0; k < jb->m_ch; k++) {
        double *m = &a[jb->m_off + ACC_MOMENT * k];
        if (first) m[0] = x[k];
        double d = x[k] - m[0];
        m[1] += d, m[2] += d * d;
      }
    }
    a[0] += v.c[0], a[1] += v.c[1], a[2] += v.c[2], a[3] += 1.0;
    for (int k = 0; k < jb->nq; k++) a[4 + k] += quv[k];
    return;
  }
  splat_filter(jb, tb, px, py, v, quv);
}

/* One pixel's sums a += wgt (v, 1, quv[0..nq)). */
static inline void splat_add(double *a, double wgt, double v0, double v1, double v2, int nq,
                             const double *quv) {
  a[0] += wgt * v0, a[1] += wgt * v1, a[2] += wgt * v2, a[3] += wgt;
  for (int k = 0; k < nq; k++) a[4 + k] += wgt * quv[k];
}

/* The filtered sums of a footprint of nx x ny pixels, rows row_stride
 * doubles apart from acc (the first pixel's), four doubles a pixel (no
 * extra values): each pixel's a += wgt (v0, v1, v2, 1) in one AVX vector,
 * the same products and sums as splat_add's (wgt * 1 is wgt): its bits. */
#if defined(__x86_64__) || defined(__i386__)
static __attribute__((target("avx2"))) void splat_sums_avx(double *acc, size_t row_stride, int nx, int ny,
                                                           const double *fw, double v0, double v1,
                                                           double v2) {
  typedef double v4d __attribute__((vector_size(32)));
  const v4d c = {v0, v1, v2, 1.0};
  for (int y = 0; y < ny; y++) {
    double fy = fw[nx + y];
    if (fy == 0) continue;
    double *row = acc + row_stride * (size_t)y;
    for (int x = 0; x < nx; x++) {
      double wgt = fy * fw[x];
      if (wgt == 0) continue;
      v4d a;
      memcpy(&a, row + 4 * x, sizeof a);
      a += c * wgt;
      memcpy(row + 4 * x, &a, sizeof a);
    }
  }
}
#endif

/* Out of line: inlined into wave_flush its loop ran short of registers. */
static __attribute__((noinline)) void splat_filter(const job *jb, tile_buf *tb, double px, double py, color v,
                                                   const double *quv) {
  int S = jb->stride;
  const rfilter *f = jb->fm->filter;
  double r = f->radius;
  int xlo = (int)ceil(px - r - 0.5), xhi = (int)floor(px + r - 0.5);
  int ylo = (int)ceil(py - r - 0.5), yhi = (int)floor(py + r - 0.5);
  if (xlo < tb->x0) xlo = tb->x0;
  if (ylo < tb->y0) ylo = tb->y0;
  if (xhi > tb->x0 + tb->w - 1) xhi = tb->x0 + tb->w - 1;
  if (yhi > tb->y0 + tb->h - 1) yhi = tb->y0 + tb->h - 1;
  int nx = xhi - xlo + 1, ny = yhi - ylo + 1;
  if (nx <= 0 || ny <= 0) return;
  const double v0 = v.c[0], v1 = v.c[1], v2 = v.c[2];
  const int nq = jb->nq;
  /* The filter's column and row weights once, in one batch where the
   * filter has one (the gaussian's exp calls: 2 x 4 a sample); a larger
   * footprint than FW_MAX (a plugin's filter wider than ours) takes its
   * weights point by point. */
  enum {
    FW_MAX = 128
  };
  if (nx + ny > FW_MAX) {
    for (int y = ylo; y <= yhi; y++) {
      double fy = f->eval(f, py - (y + 0.5));
      if (fy == 0) continue;
      for (int x = xlo; x <= xhi; x++) {
        double wgt = fy * f->eval(f, px - (x + 0.5));
        if (wgt == 0) continue;
        splat_add(&tb->acc[(size_t)S * ((size_t)(y - tb->y0) * tb->w + (x - tb->x0))], wgt, v0, v1, v2, nq,
                  quv);
      }
    }
    return;
  }
  double fw[FW_MAX];
  if (f->eval_footprint) {
    f->eval_footprint(f, px, xlo, nx, py, ylo, ny, fw);
  } else {
    for (int x = xlo; x <= xhi; x++) fw[x - xlo] = f->eval(f, px - (x + 0.5));
    for (int y = ylo; y <= yhi; y++) fw[nx + y - ylo] = f->eval(f, py - (y + 0.5));
  }
  /* The footprint's first pixel's sums. */
  double *acc0 = &tb->acc[(size_t)S * ((size_t)(ylo - tb->y0) * tb->w + (xlo - tb->x0))];
#if defined(__x86_64__) || defined(__i386__)
  rsw_isa isa = rsw_isa_get();
  if (S == 4 && (isa == RSW_ISA_AVX2 || isa == RSW_ISA_AVX512)) {
    splat_sums_avx(acc0, (size_t)S * tb->w, nx, ny, fw, v0, v1, v2);
    return;
  }
#endif
  /* The rows' first pixels, the colour and the extra count in locals
   * (read through tb and jb, GCC reloaded them after every store to the
   * sums). */
  for (int y = 0; y < ny; y++) {
    double fy = fw[nx + y];
    if (fy == 0) continue;
    double *row = acc0 + (size_t)S * tb->w * (size_t)y;
    for (int x = 0; x < nx; x++) {
      double wgt = fy * fw[x];
      if (wgt != 0) splat_add(row + (size_t)S * x, wgt, v0, v1, v2, nq, quv);
    }
  }
}

static double now_s(void);

/* True when the render must stop: cancelled, or past its deadline (which
 * marks the job stopped, so the render answers RSW_ERR_TIMEOUT). */
static bool job_should_stop(job *jb) {
  if (jb->opts->cancel && atomic_load(jb->opts->cancel)) return true;
  if (jb->opts->deadline > 0 && now_s() > jb->opts->deadline) {
    atomic_store(&jb->stopped, true);
    return true;
  }
  return false;
}

/* The render this thread is working on (run_tile), for
 * render_stop_requested. */
static _Thread_local job *t_job;

bool render_stop_requested(void) {
  return t_job && job_should_stop(t_job);
}

/* Samples per wave (integrator_ops.Li_batch): enough paths that each
 * bounce fills Embree packets and the shading stages stay hot in the
 * instruction cache, few enough that the lanes' state stays in L2. An
 * integrator may ask for a larger wave (integrator.wave, up to
 * RENDER_WAVE_MAX; `path`: its per-wave work is spread over more lanes). */
#ifndef WAVE
#define WAVE 256
#endif
#define RENDER_WAVE_MAX 1024
/* A scene of more primitives than this (scene_primitive_count) renders in
 * waves of at most WAVE: its BVH and instance data need the core's L2
 * that a larger wave's lanes take (path's 1,024 lanes hold about 1 MB).
 * Measured in one-thread CPU time, waves of 256 against 1,024, alternating
 * pairs: the canopy bench's scene (100,000 instanced leaves) 0.84x
 * periodic and 0.91x without the boundary, mesh_1m's heightfield (10^6
 * triangles) 0.95x; the small scenes (the seed scene's 2 triangles, the
 * Cornell box's 34) keep the larger wave, where it measured best. */
#define WAVE_BIG_SCENE  65536
/* The extra values of a path (Stokes Q, U, V or a bundle's pages 1..):
 * Li's slots per path in wave_buf.quv (Li_batch packs nq per path). */
#define LI_SLOTS        (SCENE_QUV_MAX > SCENE_EXTRA_MAX ? SCENE_QUV_MAX : SCENE_EXTRA_MAX)
#if WAVE > RENDER_WAVE_MAX
#error "WAVE exceeds RENDER_WAVE_MAX"
#endif

/* One sample of a wave: where it lands (its weight: wave_buf.w). */
typedef struct wave_sample {
  double px, py;
} wave_sample;

typedef struct wave_buf {
  wave_sample ws[RENDER_WAVE_MAX];
  sampler_state st[RENDER_WAVE_MAX];
  ray3 ray[RENDER_WAVE_MAX];
  color L[RENDER_WAVE_MAX];
  double quv[LI_SLOTS * RENDER_WAVE_MAX];
  int live[RENDER_WAVE_MAX];
  vec2 film_u[RENDER_WAVE_MAX], aperture_u[RENDER_WAVE_MAX];
  double w[RENDER_WAVE_MAX]; /* the camera rays' weights */
  /* Which sample each slot takes (render_tile), for wave_start. */
  uint64_t pixel[RENDER_WAVE_MAX];
  uint32_t index[RENDER_WAVE_MAX];
  int ix[RENDER_WAVE_MAX], iy[RENDER_WAVE_MAX];
} wave_buf;

/* Samples [0, n) of wb begin: their sampler streams, film jitter and
 * aperture draws, together (samplers/sampler_batch.h: each sample's
 * numbers are those of its own per-sample calls), then film positions and
 * camera rays (the sensor's batched op where it has one). */
static void wave_start(job *jb, wave_buf *wb, int n) {
  const sampler *smp = jb->se->sampler;
  const sensor *se = jb->se;
  sampler_start_2d_2d_batch(smp, wb->st, n, jb->opts->seed, wb->pixel, wb->index, jb->spp, wb->film_u,
                            wb->aperture_u);
  for (int i = 0; i < n; i++) {
    double px = wb->ix[i] + wb->film_u[i].x, py = wb->iy[i] + wb->film_u[i].y;
    wb->ws[i].px = px;
    wb->ws[i].py = py;
    wb->film_u[i] = v2(px / jb->W, py / jb->H);
  }
  if (!se->ops->sample_ray_batch)
    for (int i = 0; i < n; i++)
      wb->w[i] = se->ops->sample_ray(se, wb->film_u[i], wb->aperture_u[i], &wb->ray[i]);
}

/* The film's Stokes basis (docs/polarization.md#stokes-conventions) for
 * light arriving along -d: cameras x = d x up, up the sensor's to_world
 * +y (Mitsuba's: the image's right, y its up); the distant family x in
 * the meridian plane (the vertical plane through d: Q = I_l - I_r, as
 * Coulson, Dave & Sekera 1960), the vertical being world +z or, for a
 * hemisphere sensor, its pole. */
static vec3 film_stokes_x(const sensor *se, vec3 d) {
  vec3 pd = v3_neg(d);
  if (se->ops->pixel_angles) {
    vec3 z = se->stokes_pole ? v3_norm(xf_vector(&se->to_world, v3(0, 0, 1))) : v3(0, 0, 1);
    vec3 h = v3_cross(z, pd);
    if (!(v3_len(h) > 1e-9)) h = v3_cross(v3_norm(xf_vector(&se->to_world, v3(0, 1, 0))), pd);
    return v3_norm(h);
  }
  return plane_normal(d, v3_norm(xf_vector(&se->to_world, v3(0, 1, 0))));
}

/* q = (Q, U, V) per channel (nq / 3 of them) of a sample whose camera
 * ray is along d, from the integrator's basis (stokes_basis(-d),
 * integrators/polarization.h) into the film's. */
static void film_stokes_rotate(const sensor *se, vec3 d, double *q, int nq) {
  d = v3_norm(d);
  vec3 pd = v3_neg(d);
  mueller R = mu_basis_change(pd, stokes_basis(pd), film_stokes_x(se, d));
  for (int c = 0; c < nq; c += 3) {
    double Q = q[c], U = q[c + 1];
    q[c] = R.m[1][1] * Q + R.m[1][2] * U;
    q[c + 1] = R.m[2][1] * Q + R.m[2][2] * U;
  }
}

/* Trace and splat samples [0, n) of wb: the live ones (w != 0) go through
 * the integrator together; every sample is splatted in order, so the tile's
 * sums are those of the one-sample loop. False: out of memory. */
static bool wave_flush(job *jb, tile_buf *tb, wave_buf *wb, int n, render_stats *rs, uint64_t *invalid) {
  const integrator *it = jb->sc->integrator;
  const sensor *se = jb->se;
  if (se->ops->sample_ray_batch) /* the wave's camera rays together (vectorised, core/isa.h) */
    se->ops->sample_ray_batch(se, n, wb->film_u, wb->aperture_u, wb->ray, wb->w);
  int m = 0;
  for (int i = 0; i < n; i++) /* compacted in place: live sample k's state and ray move to slot k */
    if (wb->w[i] != 0) {
      wb->live[m] = i;
      if (m != i) {
        wb->st[m] = wb->st[i];
        wb->ray[m] = wb->ray[i];
      }
      m++;
    }
  rs->camera_rays += (uint64_t)m;
  double *quv = jb->nq ? wb->quv : NULL;
  if (it->ops->Li_batch) {
    if (m && !it->ops->Li_batch(it, jb->sc, wb->st, wb->ray, m, rs, wb->L, quv)) return false;
  } else {
    for (int k = 0; k < m; k++) { /* Li's slots: LI_SLOTS apart */
      double *q = &wb->quv[LI_SLOTS * k];
      for (int j = 0; j < LI_SLOTS; j++) q[j] = 0;
      wb->L[k] = it->ops->Li(it, jb->sc, &wb->st[k], wb->ray[k], rs, quv ? q : NULL);
    }
  }
  /* The box filter without moments or extra values (most renders): a run
   * of samples of one pixel adds into registers, stored when the pixel
   * changes; splat()'s additions in its order, so the same sums. */
  const bool run = jb->box && !jb->m_ch && !jb->nq;
  double *ra = NULL, r0 = 0, r1 = 0, r2 = 0, r3 = 0;
  int k = 0;
  for (int i = 0; i < n; i++) {
    const wave_sample *s = &wb->ws[i];
    const double w = wb->w[i];
    color v = col1(0);
    double q[SCENE_QUV_MAX > SCENE_EXTRA_MAX ? SCENE_QUV_MAX : SCENE_EXTRA_MAX];
    if (k < m && wb->live[k] == i) {
      v = col_scale(wb->L[k], w);
      /* All finite, without a branch each: x * 0 is +-0 for a finite x and
       * NaN for an infinite or NaN one. */
      double z = v.c[0] * 0.0 + v.c[1] * 0.0 + v.c[2] * 0.0;
      if (jb->nq) { /* Li_batch packs nq values per path, Li's slots are LI_SLOTS apart */
        const double *src = &wb->quv[(it->ops->Li_batch ? jb->nq : LI_SLOTS) * k];
        for (int c = 0; c < jb->nq; c++) q[c] = src[c] * w;
        if (jb->sc->polarized) film_stokes_rotate(se, wb->ray[k].d, q, jb->nq);
        for (int c = 0; c < jb->nq; c++) z += q[c] * 0.0;
      }
      if (!(z == 0.0)) {
        (*invalid)++;
        v = col1(0);
        for (int c = 0; c < jb->nq; c++) q[c] = 0;
      }
      k++;
    } else {
      for (int c = 0; c < jb->nq; c++) q[c] = 0;
    }
    if (run) {
      double *a = box_pixel(jb, tb, s->px, s->py);
      if (a != ra) {
        if (ra) ra[0] = r0, ra[1] = r1, ra[2] = r2, ra[3] = r3;
        ra = a, r0 = a[0], r1 = a[1], r2 = a[2], r3 = a[3];
      }
      r0 += v.c[0], r1 += v.c[1], r2 += v.c[2], r3 += 1.0;
      continue;
    }
    splat(jb, tb, s->px, s->py, v, q);
  }
  if (ra) ra[0] = r0, ra[1] = r1, ra[2] = r2, ra[3] = r3;
  return true;
}

static tile_buf *render_tile(job *jb, size_t t, render_stats *rs, uint64_t *samples, uint64_t *invalid) {
  int tx = (int)(t % (size_t)jb->tiles_x), ty = (int)(t / (size_t)jb->tiles_x);
  int px0 = tx * jb->tw, py0 = ty * jb->th;
  int px1 = px0 + jb->tw < jb->W ? px0 + jb->tw : jb->W;
  int py1 = py0 + jb->th < jb->H ? py0 + jb->th : jb->H;
  tile_buf *tb = malloc(sizeof *tb);
  wave_buf *wb = malloc(sizeof *wb);
  if (!tb || !wb) {
    free(tb);
    free(wb);
    return NULL;
  }
  tb->x0 = px0 - jb->margin > 0 ? px0 - jb->margin : 0;
  tb->y0 = py0 - jb->margin > 0 ? py0 - jb->margin : 0;
  int x1 = px1 + jb->margin < jb->W ? px1 + jb->margin : jb->W;
  int y1 = py1 + jb->margin < jb->H ? py1 + jb->margin : jb->H;
  tb->w = x1 - tb->x0;
  tb->h = y1 - tb->y0;
  tb->acc = calloc((size_t)tb->w * tb->h * (size_t)jb->stride, sizeof(double));
  if (!tb->acc) {
    free(tb);
    free(wb);
    return NULL;
  }
  const int wave = jb->wave;
  /* Samples are taken pixel by pixel, sample by sample, `wave` at a time
   * (a wave may span pixels). Cancellation and deadlines are honoured
   * before each wave, so a film of a few pixels with a huge spp stops
   * too; the partial tile is discarded with the render. */
  int n = 0;
  for (int iy = py0; iy < py1; iy++) {
    for (int ix = px0; ix < px1; ix++) {
      uint64_t pixel = (uint64_t)iy * (uint64_t)jb->W + (uint64_t)ix;
      for (uint32_t s = 0; s < jb->spp; s++) {
        if (n == 0 && job_should_stop(jb)) goto out;
        wb->pixel[n] = pixel;
        wb->index[n] = s;
        wb->ix[n] = ix;
        wb->iy[n] = iy;
        if (++n == wave) {
          wave_start(jb, wb, n);
          if (!wave_flush(jb, tb, wb, n, rs, invalid)) goto fail;
          *samples += (uint64_t)n;
          if (jb->opts->samples)
            atomic_fetch_add_explicit(&jb->opts->samples->done, (uint64_t)n, memory_order_relaxed);
          n = 0;
        }
      }
    }
  }
  if (n) {
    wave_start(jb, wb, n);
    if (!wave_flush(jb, tb, wb, n, rs, invalid)) goto fail;
    *samples += (uint64_t)n;
    if (jb->opts->samples)
      atomic_fetch_add_explicit(&jb->opts->samples->done, (uint64_t)n, memory_order_relaxed);
  }
out:
  free(wb);
  return tb;
fail:
  free(wb);
  free(tb->acc);
  free(tb);
  return NULL;
}

/* The tile size of a render on `threads` threads: TILE x TILE, halved
 * (down to one pixel) while that gives fewer than TILES_PER_THREAD tiles
 * per thread and the halved tile still holds a wave of samples (`wave`:
 * the integrator's; a smaller tile would trace part-filled waves). Only
 * for the box filter: a pixel's sums then hold its own samples alone, in
 * sample order, so the film is bitwise the same whatever the tiles (with
 * a wider filter, a pixel's sums from neighbouring tiles are added per
 * tile, and the grouping would change their rounding). A small film at a
 * high spp (the canopy bench's 76 x 1 pixels at 1,000 spp on 2 threads: 10
 * tiles of up to 8 pixels, 38 of 2) so keeps every thread busy to the
 * end. */
static void tile_size(const job *jb, int threads, int wave, int *tw, int *th) {
  int w = TILE, h = TILE;
  for (;;) {
    if (!jb->box || threads <= 1 || (w == 1 && h == 1)) break;
    size_t n = (size_t)((jb->W + w - 1) / w) * (size_t)((jb->H + h - 1) / h);
    if (n >= (size_t)TILES_PER_THREAD * (size_t)threads) break;
    int w2 = w > 1 ? w / 2 : 1, h2 = h > 1 ? h / 2 : 1;
    uint64_t px = (uint64_t)(w2 < jb->W ? w2 : jb->W) * (uint64_t)(h2 < jb->H ? h2 : jb->H);
    if (px * jb->spp < (uint64_t)wave) break;
    w = w2, h = h2;
  }
  *tw = w, *th = h;
}

/* Samples per wave: the integrator's (integrator.wave), at most WAVE in a
 * scene of more than WAVE_BIG_SCENE primitives. A path's value does not
 * depend on its wave, so neither does the film. */
static int job_wave(const scene *sc) {
  const int iw = sc->integrator->wave;
  int w = iw > 0 && iw <= RENDER_WAVE_MAX ? iw : WAVE;
  if (w > WAVE && scene_primitive_count(sc) > WAVE_BIG_SCENE) w = WAVE;
  return w;
}

static void merge_tile(job *jb, tile_buf *tb) {
  int S = jb->stride;
  for (int y = 0; y < tb->h; y++)
    for (int x = 0; x < tb->w; x++) {
      const double *a = &tb->acc[(size_t)S * ((size_t)y * tb->w + x)];
      double *d = &jb->film_acc[(size_t)S * ((size_t)(tb->y0 + y) * jb->W + (tb->x0 + x))];
      for (int k = 0; k < S; k++) d[k] += a[k];
    }
  free(tb->acc);
  free(tb);
}

/* Render tile t and merge every finished tile that is next in tile order,
 * so floating-point sums never depend on scheduling. */
static void run_tile(job *jb, size_t t) {
  render_stats rs = {0};
  uint64_t samples = 0, invalid = 0;
  double t0 = now_s();
  t_job = jb;
  tile_buf *tb = render_tile(jb, t, &rs, &samples, &invalid);
  t_job = NULL;
  double busy = now_s() - t0;
  pthread_mutex_lock(&jb->lock);
  jb->busy_s += busy;
  jb->rays.rays += rs.rays;
  jb->rays.shadow_rays += rs.shadow_rays;
  jb->rays.unresolved += rs.unresolved;
  jb->rays.trace_s += rs.trace_s;
  jb->rays.camera_rays += rs.camera_rays;
  jb->samples += samples;
  jb->invalid += invalid;
  if (!tb) {
    atomic_store(&jb->failed, true);
  } else {
    jb->done[t] = tb;
    while (jb->next_commit < jb->n_tiles && jb->done[jb->next_commit]) {
      merge_tile(jb, jb->done[jb->next_commit]);
      jb->done[jb->next_commit] = NULL;
      jb->next_commit++;
    }
    if (jb->opts->progress) jb->opts->progress(jb->opts->progress_user, jb->next_commit, jb->n_tiles);
  }
  pthread_mutex_unlock(&jb->lock);
}

/* ---- the worker pool ------------------------------------------------------
 *
 * One process-wide set of threads (cores - 1 of them, started on the first
 * render that can use them) serves every render: no thread is started or
 * joined per render. A render lists itself while it has tiles left to
 * claim; the caller's thread works on its own render too, so a render
 * always progresses even when every pool thread is busy elsewhere, and a
 * one-tile or one-thread render (a 1x1 film) never touches the pool at all.
 * Pool threads take one tile at a time, from the listed renders in turn
 * (round robin, each render capped at its `threads`), so concurrent renders
 * share the cores tile by tile. Which thread renders a tile never changes
 * the film: tiles are merged in tile order (run_tile). */
static struct {
  pthread_mutex_t lock;
  pthread_cond_t work; /* a render was listed */
  job *head;           /* listed renders; the next claim starts here */
  int n_threads;
} g_pool = {PTHREAD_MUTEX_INITIALIZER, PTHREAD_COND_INITIALIZER, NULL, 0};
static pthread_once_t g_pool_once = PTHREAD_ONCE_INIT;

static void pool_unlist(job *jb) { /* pool lock held */
  if (!jb->listed) return;
  jb->listed = false;
  if (jb->next == jb) {
    g_pool.head = NULL;
  } else {
    jb->prev->next = jb->next;
    jb->next->prev = jb->prev;
    if (g_pool.head == jb) g_pool.head = jb->next;
  }
  jb->prev = jb->next = NULL;
}

static void pool_list(job *jb) { /* pool lock held */
  job *h = g_pool.head;
  if (!h) {
    jb->prev = jb->next = jb;
    g_pool.head = jb;
  } else { /* at the tail: the renders listed before it keep their turn */
    jb->next = h;
    jb->prev = h->prev;
    h->prev->next = jb;
    h->prev = jb;
  }
  jb->listed = true;
}

/* Claim the next tile of jb (pool lock held); false when none is left or
 * the render must stop (it is unlisted then). */
static bool pool_claim(job *jb, size_t *t) {
  if (jb->next_tile >= jb->n_tiles || atomic_load(&jb->failed) || atomic_load(&jb->stopped) ||
      job_should_stop(jb)) {
    jb->next_tile = jb->n_tiles;
    pool_unlist(jb);
    return false;
  }
  *t = jb->next_tile++;
  if (jb->next_tile >= jb->n_tiles) pool_unlist(jb);
  return true;
}

static void *pool_main(void *arg) {
  (void)arg;
  pthread_mutex_lock(&g_pool.lock);
  for (;;) {
    job *jb = NULL;
    size_t t = 0;
    while (!jb) {
      /* One turn of the ring from the head; `last` is taken before the
       * claim, which may unlist c (and move the head past it). */
      for (job *c = g_pool.head; c;) {
        job *nx = c->next;
        bool last = nx == g_pool.head;
        if (c->active < c->max_workers && pool_claim(c, &t)) {
          jb = c;
          if (c->listed) g_pool.head = c->next; /* the next claim starts after it */
          break;
        }
        c = last || !g_pool.head ? NULL : nx;
      }
      if (!jb) pthread_cond_wait(&g_pool.work, &g_pool.lock);
    }
    jb->active++;
    if (jb->active > jb->peak) jb->peak = jb->active;
    pthread_mutex_unlock(&g_pool.lock);
    run_tile(jb, t);
    pthread_mutex_lock(&g_pool.lock);
    if (--jb->active == 0) pthread_cond_signal(&jb->idle);
  }
  return NULL;
}

static void pool_start(void) {
  long n = sysconf(_SC_NPROCESSORS_ONLN) - 1;
  if (n > 255) n = 255;
  pthread_attr_t at;
  pthread_attr_init(&at);
  pthread_attr_setdetachstate(&at, PTHREAD_CREATE_DETACHED);
  for (long i = 0; i < n; i++) {
    pthread_t th;
    if (pthread_create(&th, &at, pool_main, NULL) != 0) break;
    g_pool.n_threads++;
  }
  pthread_attr_destroy(&at);
}

/* Render every tile of jb: on the caller's thread alone when only one
 * thread may or can work on it, else with the pool's help. */
static void run_job(job *jb) {
  if (jb->max_workers > 1 && jb->n_tiles > 1) pthread_once(&g_pool_once, pool_start);
  pthread_mutex_lock(&g_pool.lock);
  bool alone = jb->max_workers <= 1 || jb->n_tiles <= 1 || g_pool.n_threads == 0;
  pthread_mutex_unlock(&g_pool.lock);
  jb->peak = 1;
  if (alone) {
    for (size_t t = 0; t < jb->n_tiles; t++) {
      if (atomic_load(&jb->failed) || atomic_load(&jb->stopped) || job_should_stop(jb)) break;
      run_tile(jb, t);
    }
    return;
  }
  pthread_mutex_lock(&g_pool.lock);
  jb->active = 1; /* the caller */
  pool_list(jb);
  if (jb->max_workers - 1 >= g_pool.n_threads)
    pthread_cond_broadcast(&g_pool.work);
  else
    for (int i = 1; i < jb->max_workers; i++) pthread_cond_signal(&g_pool.work);
  for (;;) {
    size_t t;
    if (!pool_claim(jb, &t)) break;
    pthread_mutex_unlock(&g_pool.lock);
    run_tile(jb, t);
    pthread_mutex_lock(&g_pool.lock);
  }
  jb->active--;
  while (jb->active > 0) pthread_cond_wait(&jb->idle, &g_pool.lock);
  pool_unlist(jb);
  pthread_mutex_unlock(&g_pool.lock);
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

rsw_status render_check_bundle(const scene *sc, size_t sensor_index, int bundle, rsw_err *err) {
  if (bundle <= 1) return RSW_OK;
  if (bundle > RENDER_MAX_BUNDLE)
    return rsw_fail(err, RSW_ERR_INVALID, "bundle",
                    "bundle must be an integer from 1 (one wavelength per path) to %d (the wavelengths a "
                    "path carries)",
                    RENDER_MAX_BUNDLE);
  if (sc->variant != VARIANT_MONO)
    return rsw_fail(err, RSW_ERR_INVALID, "bundle",
                    "spectral bundles apply to mono scenes; this scene is rgb");
  const sensor *se = sensor_index < sc->n_sensors ? sc->sensors[sensor_index] : NULL;
  if (se && se->film->pixel_format == PIXFMT_STOKES)
    return rsw_fail(err, RSW_ERR_UNSUPPORTED, "bundle",
                    "sensor '%s' has a Stokes film (S0..S3 in its channels): it renders with \"bundle\": 1",
                    se->base.id);
  if (bundle > 3) {
    const char *why = "";
    const object *blk = scene_page_blocker(sc, &why);
    if (blk)
      return rsw_fail(err, RSW_ERR_UNSUPPORTED, "bundle",
                      "%s '%s' (%s) %s: this scene renders bundles of at most 3 wavelengths",
                      obj_class_name(blk->plugin->cls), blk->id ? blk->id : "", blk->plugin->name, why);
  }
  return RSW_OK;
}

/* A bundle's film b in the layout of a one-wavelength mono film: every
 * colour sum and the moments from channel b. NULL: out of memory. */
static double *bundle_channel_sums(const job *jb, int b, int *stride) {
  int m1 = jb->m_ch ? 1 : 0;
  int S = jb->m_off + ACC_MOMENT * m1;
  size_t np = (size_t)jb->W * jb->H;
  double *d = malloc(np * (size_t)S * sizeof *d);
  if (!d) return NULL;
  for (size_t i = 0; i < np; i++) {
    const double *a = &jb->film_acc[i * (size_t)jb->stride];
    double *o = &d[i * (size_t)S];
    o[0] = o[1] = o[2] = a[b < 3 ? b : 4 + (b - 3)]; /* pages 1.. follow the filter weight */
    o[3] = a[3];
    for (int k = 4; k < jb->m_off; k++) o[k] = 0;
    if (m1)
      for (int k = 0; k < ACC_MOMENT; k++) o[jb->m_off + k] = a[jb->m_off + ACC_MOMENT * b + k];
  }
  *stride = S;
  return d;
}

rsw_status render_sensor(scene *sc, const render_opts *opts, film_image *out, render_result_stats *stats,
                         rsw_err *err) {
  if (opts->bundle > 1)
    return rsw_fail(err, RSW_ERR_INVALID, "bundle",
                    "a spectral bundle renders several films: "
                    "render_sensor_bundle");
  return render_sensor_bundle(sc, opts, out, stats, err);
}

rsw_status render_sensor_bundle(scene *sc, const render_opts *opts, film_image *out,
                                render_result_stats *stats, rsw_err *err) {
  double t0 = now_s();
  if (opts->sensor >= sc->n_sensors)
    return rsw_fail(err, RSW_ERR_NOT_FOUND, "sensor",
                    sc->n_sensors ? "no sensor with index %zu (the scene has %zu)"
                                  : "the scene has no sensor%.0zu%.0zu",
                    opts->sensor, sc->n_sensors);
  if (!accel_ready(sc->accel))
    return rsw_fail(err, RSW_ERR_EMBREE, "scene",
                    "the scene's acceleration structure is incomplete after a failed update: update or "
                    "reload the scene");
  const sensor *se = sc->sensors[opts->sensor];
  const film *fm = se->film;
  render_ctx rc = {.variant = sc->variant,
                   .polarized = sc->polarized,
                   .wavelength = opts->wavelength > 0 ? opts->wavelength : 550.0,
                   .threads = opts->threads > 0 ? opts->threads : (int)sysconf(_SC_NPROCESSORS_ONLN)};
  int nb = opts->bundle > 1 ? opts->bundle : 1;
  if (nb > 1) {
    rsw_status bst = render_check_bundle(sc, opts->sensor, nb, err);
    if (bst) return bst;
    rc.bundle = nb;
    for (int c = 0; c < RENDER_MAX_BUNDLE; c++) rc.wl[c] = opts->bundle_wl[c < nb ? c : nb - 1];
    rc.wavelength = rc.wl[0];
    for (int c = 0; c < nb; c++)
      if (!(rc.wl[c] > 0 && rc.wl[c] < 1e6))
        return rsw_fail(err, RSW_ERR_RANGE, "wavelength", "wavelength must be a positive number of nm");
  }
  if (!(rc.wavelength > 0 && rc.wavelength < 1e6))
    return rsw_fail(err, RSW_ERR_RANGE, "wavelength", "wavelength must be a positive number of nm");
  rsw_status st = scene_prepare(sc, &rc, err);
  if (st) return st;
  uint32_t spp = opts->spp ? opts->spp : se->sampler->sample_count;
  if (se->sampler->ops->adjust_spp) spp = se->sampler->ops->adjust_spp(se->sampler, spp);
  if (spp == 0) return rsw_fail(err, RSW_ERR_RANGE, "spp", "spp must be at least 1");
  bool box = fm->filter->radius <= 0.5 + 1e-12;
  st = render_check_planes(sc, opts->sensor, spp, opts->quantities, opts->variance, err);
  if (st) return st;
  color e_h = col1(0), e_hp[RENDER_MAX_PAGES] = {{{0}}}; /* a bundle of pages: each page's */
  if (opts->quantities & (RENDER_Q_BRDF | RENDER_Q_BRF)) {
    st = render_horizontal_irradiance(sc, &e_h, err);
    e_hp[0] = e_h;
    for (int p = 1; p < sc->pages && !st; p++) {
      rsw_page = p;
      st = render_horizontal_irradiance(sc, &e_hp[p], err);
      rsw_page = 0;
    }
    if (st) return st;
  }

  job jb;
  memset(&jb, 0, sizeof jb);
  jb.sc = sc;
  jb.se = se;
  jb.fm = fm;
  jb.opts = opts;
  jb.spp = spp;
  jb.W = fm->width;
  jb.H = fm->height;
  jb.box = box;
  int nt = opts->threads > 0 ? opts->threads : (int)sysconf(_SC_NPROCESSORS_ONLN);
  if (nt < 1) nt = 1;
  if (nt > 256) nt = 256;
  jb.wave = job_wave(sc);
  tile_size(&jb, nt, jb.wave, &jb.tw, &jb.th);
  jb.tiles_x = (jb.W + jb.tw - 1) / jb.tw;
  jb.tiles_y = (jb.H + jb.th - 1) / jb.th;
  jb.n_tiles = (size_t)jb.tiles_x * jb.tiles_y;
  jb.stokes = sc->polarized || (fm->pixel_format == PIXFMT_STOKES && sc->variant == VARIANT_MONO);
  /* (a bundle sums its wavelengths' channels apart) */
  jb.lum = !jb.stokes && nb == 1 && (sc->variant == VARIANT_MONO || fm->pixel_format == PIXFMT_LUMINANCE);
  jb.nq = jb.stokes || sc->pages > 1 ? scene_extra_stride(sc) : 0;
  jb.m_ch = !opts->variance ? 0 : jb.stokes ? 4 * jb.nq / 3 : jb.lum ? 1 : nb > 3 ? nb : 3;
  jb.m_off = 4 + jb.nq;
  jb.stride = jb.m_off + ACC_MOMENT * jb.m_ch;
  jb.margin = jb.box ? 0 : (int)ceil(fm->filter->radius + 0.5);
  jb.film_acc = calloc((size_t)jb.W * jb.H * (size_t)jb.stride, sizeof(double));
  jb.done = calloc(jb.n_tiles, sizeof *jb.done);
  if (!jb.film_acc || !jb.done) {
    free(jb.film_acc);
    free(jb.done);
    return rsw_fail(err, RSW_ERR_NOMEM, "film", "out of memory for a %dx%d film", jb.W, jb.H);
  }
  pthread_mutex_init(&jb.lock, NULL);
  pthread_cond_init(&jb.idle, NULL);
  if ((size_t)nt > jb.n_tiles) nt = (int)jb.n_tiles;
  jb.max_workers = nt;
  if (opts->samples) {
    atomic_store_explicit(&opts->samples->done, 0, memory_order_relaxed);
    atomic_store_explicit(&opts->samples->total, (uint64_t)jb.W * (uint64_t)jb.H * spp, memory_order_relaxed);
  }
  run_job(&jb);
  pthread_cond_destroy(&jb.idle);
  pthread_mutex_destroy(&jb.lock);
  for (size_t i = 0; i < jb.n_tiles; i++)
    if (jb.done[i]) merge_tile(&jb, jb.done[i]);
  free(jb.done);
  if (atomic_load(&jb.failed)) {
    free(jb.film_acc);
    return rsw_fail(err, RSW_ERR_NOMEM, "render", "out of memory while rendering");
  }
  if (opts->cancel && atomic_load(opts->cancel)) {
    free(jb.film_acc);
    return rsw_fail(err, RSW_ERR_CANCELLED, "render", "render cancelled");
  }
  if (atomic_load(&jb.stopped)) {
    free(jb.film_acc);
    return rsw_fail(err, RSW_ERR_TIMEOUT, "timeout_s", "render stopped at its deadline after %.3f s",
                    now_s() - t0);
  }

  /* Develop: the film's op turns the sums into the image and its planes
   * (a bundle's, film by film from its channel's sums). */
  for (int b = 0; b < nb; b++) {
    int stride = jb.stride;
    double *acc = nb == 1 ? jb.film_acc : bundle_channel_sums(&jb, b, &stride);
    if (!acc) st = rsw_fail(err, RSW_ERR_NOMEM, "film", "out of memory");
    film_sums sums = {.acc = acc,
                      .width = jb.W,
                      .height = jb.H,
                      .stride = stride,
                      .m_off = jb.m_off,
                      .stokes = jb.stokes,
                      .polarized = sc->polarized,
                      .lum = nb == 1 ? jb.lum : true,
                      .variant = sc->variant,
                      .spp = spp,
                      .seed = opts->seed,
                      .wavelength = sc->variant == VARIANT_MONO ? rc_channel_wavelength(&rc, b) : 0.0,
                      .quantities = opts->quantities,
                      .variance = opts->variance,
                      .e_h = nb == 1   ? e_h
                             : nb <= 3 ? col1(e_h.c[b])
                                       : col1(e_hp[b / 3].c[b % 3])};
    if (!st) st = fm->ops->develop(fm, &sums, &out[b], err);
    if (acc != jb.film_acc) free(acc);
    if (!st && se->ops->pixel_angles && b > 0) {
      out[b].angles = film_angles_ref(out[0].angles); /* (a bundle's pages: one sensor, one block) */
    } else if (!st && se->ops->pixel_angles) {
      out[b].angles = film_angles_new((size_t)jb.W * jb.H);
      if (!out[b].angles) {
        film_image_free(&out[b]);
        st = rsw_fail(err, RSW_ERR_NOMEM, "film", "out of memory");
      } else {
        se->ops->pixel_angles(se, jb.W, jb.H, out[b].angles);
      }
    }
    if (st) {
      for (int k = 0; k < b; k++) film_image_free(&out[k]);
      free(jb.film_acc);
      return st;
    }
    film_image *img = &out[b];
    img->unresolved_rays = jb.rays.unresolved;
    img->plugin_failures = emitter_failures(sc, b, img->plugin_failure, sizeof img->plugin_failure);
    img->nonfinite = film_image_nonfinite(img);
    img->isa = rsw_isa_name(rsw_isa_get());
    img->has_sun = render_sun_angles(sc, &img->sun_zenith, &img->sun_azimuth);
  }
  free(jb.film_acc);
  if (stats) {
    stats->rays = jb.rays;
    stats->samples = jb.samples;
    stats->invalid_samples = jb.invalid;
    stats->threads = jb.peak;
    stats->busy_s = jb.busy_s;
    stats->packet_width = accel_packet_width();
    stats->wall_s = now_s() - t0;
  }
  return RSW_OK;
}

void render_stats_line(const render_result_stats *st, char *buf, size_t size) {
  const render_stats *r = &st->rays;
  uint64_t cont = r->rays >= r->camera_rays ? r->rays - r->camera_rays : 0;
  double w = st->wall_s > 0 ? st->wall_s : 1e-9;
  double other = st->busy_s > r->trace_s ? st->busy_s - r->trace_s : 0;
  double busy = st->busy_s > 0 ? st->busy_s : 1e-9;
  snprintf(buf, size,
           "%llu samples in %.3f s (%.4g samples/s, %d threads); rays: %llu camera, %llu continuation, %llu "
           "shadow (%.4g rays/s, Embree packets of %d); thread time %.3f s: tracing %.3f s (%.0f%%), "
           "shading and the rest %.3f s (%.0f%%)",
           (unsigned long long)st->samples, st->wall_s, (double)st->samples / w, st->threads,
           (unsigned long long)r->camera_rays, (unsigned long long)cont, (unsigned long long)r->shadow_rays,
           (double)(r->rays + r->shadow_rays) / w, st->packet_width, st->busy_s, r->trace_s,
           100.0 * r->trace_s / busy, other, 100.0 * other / busy);
}
