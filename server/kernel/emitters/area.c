/* `area`: a diffuse emitter on its shape's front side (the side its normal
 * points to), radiance W m^-2 sr^-1 [nm^-1] (mitsuba3 src/emitters/area.cpp).
 *
 * Next-event estimation samples a point uniformly on the shape's area and
 * converts the density to solid angle at the reference point:
 * pdf_omega = pdf_A dist^2 / |cos theta_e|, with cos theta_e between the
 * emitter normal and the direction back to the reference point.
 *
 * The shape's world-space triangles (vertex, edges, unit normal) are
 * computed once per load and per geometric update (set_scene runs after
 * both, scene_refresh_bounds), not per sample; without them (a mesh above
 * SHAPE_TRIS_MAX faces, or no memory) each sample makes its triangle with
 * the same code, so the result is the same bit for bit. */
#include <math.h>
#include <stdlib.h>

#include "../core/isa.h"
#include "../scene/plugin_def.h"
#include "../shapes/shape.h"
#include "../textures/texture.h"

typedef struct area_light {
  emitter base;
  texture *radiance;
  double *tris;    /* world triangles of base.shape (owned), or NULL */
  uint32_t tris_n; /* faces they were made for (entries: SHAPE_TRI_DOUBLES each) */
} area_light;

static void area_set_scene(emitter *e, const scene *sc) {
  (void)sc;
  area_light *a = (area_light *)e;
  shape_world_tris_refresh(e->shape, &a->tris, &a->tris_n);
}

static color area_sample(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds) {
  const area_light *a = (const area_light *)e;
  position_sample ps =
      shape_sample_position_tris(e->shape, u, shape_world_tris_for(e->shape, a->tris, a->tris_n));
  vec3 d = v3_sub(ps.p, ref->p);
  double dist2 = v3_len2(d);
  double dist = sqrt(dist2);
  ds->p = ps.p;
  ds->n = ps.n;
  ds->delta = false;
  ds->pdf = 0;
  if (!(dist > 0)) return col1(0);
  ds->d = v3_scale(d, 1.0 / dist);
  ds->dist = dist;
  double cos_e = -v3_dot(ds->d, ps.n); /* > 0: the front side faces ref */
  if (!(cos_e > 0)) return col1(0);
  ds->pdf = ps.pdf * dist2 / cos_e;
  surface_interaction at = {.p = ps.p, .uv = {ps.uv[0], ps.uv[1]}, .shape = e->shape};
  return col_scale(tex_eval(a->radiance, &at), 1.0 / ds->pdf);
}

/* ---- the wave's batch (emitter_ops.sample_direction_batch) -------------------- */

/* area_sample for up to AREA_C lanes, its geometry in structure-of-arrays
 * form: the positions (and normals) are drawn lane by lane, then the
 * direction, distance, cosine and pdf of every lane in one loop that the
 * compiler vectorises (compiled per ISA below, picked by rsw_isa_get), then
 * the results written out. Each lane makes the operations of area_sample in
 * its order (the kernel is built without floating-point contraction: no
 * fused multiply-adds), so every ISA gives its bits. */
enum {
  AREA_C = 64
};
typedef struct area_lanes {
  double px[AREA_C], py[AREA_C], pz[AREA_C]; /* sampled point */
  double nx[AREA_C], ny[AREA_C], nz[AREA_C]; /* its unit normal (after flip_normals) */
  double rx[AREA_C], ry[AREA_C], rz[AREA_C]; /* reference point */
  double dx[AREA_C], dy[AREA_C], dz[AREA_C]; /* out: unit direction */
  double dist[AREA_C], pdf[AREA_C], ipdf[AREA_C];
  double dist_ok[AREA_C], cos_ok[AREA_C]; /* out: 1 where dist > 0, cos_e > 0 */
  /* A mesh's position samples (area_pos_body): the face picked, the
   * area target u.x * area, the face's cdf step [prev, prev + w), u.y. */
  uint32_t f[AREA_C];
  double tg[AREA_C], prev[AREA_C], w[AREA_C], uy[AREA_C];
  double b1[AREA_C], b2[AREA_C]; /* the barycentrics of p1 and p2 */
} area_lanes;

/* mesh_sample_inline's position and normal for lanes whose face, target
 * and cdf step are in L (its operations in its order: the same bits), from
 * the world triangles tris; flip: the normal negated (flip_normals). The
 * barycentrics (a division and a square root a lane) in one loop that
 * vectorises, then the triangles' data lane by lane (GCC 12 leaves a loop
 * that gathers a triangle's several doubles scalar). */
static inline __attribute__((always_inline)) void area_pos_body(area_lanes *L, int n, const double *tris,
                                                                bool flip) {
  for (int i = 0; i < n; i++) {
    double w = L->w[i];
    double ux = w > 0 ? (L->tg[i] - L->prev[i]) / w : 0.5;
    ux = ux < 0 ? 0 : ux;
    ux = ux >= 1 ? 0x1.fffffffffffffp-1 : ux;
    double t = sqrt(1.0 - ux);
    L->b1[i] = 1.0 - t, L->b2[i] = t * L->uy[i];
  }
  for (int i = 0; i < n; i++) {
    double b1 = L->b1[i], b2 = L->b2[i];
    const double *T = &tris[SHAPE_TRI_DOUBLES * (size_t)L->f[i]];
    L->px[i] = (T[0] + T[3] * b1) + T[6] * b2;
    L->py[i] = (T[1] + T[4] * b1) + T[7] * b2;
    L->pz[i] = (T[2] + T[5] * b1) + T[8] * b2;
    L->nx[i] = flip ? -T[9] : T[9];
    L->ny[i] = flip ? -T[10] : T[10];
    L->nz[i] = flip ? -T[11] : T[11];
  }
}

/* pdf_a: the position density 1 / area, as shape_sample_position_tris. */
static inline __attribute__((always_inline)) void area_geom_body(area_lanes *L, int n, double pdf_a) {
  for (int i = 0; i < n; i++) {
    double ddx = L->px[i] - L->rx[i], ddy = L->py[i] - L->ry[i], ddz = L->pz[i] - L->rz[i];
    double dist2 = ddx * ddx + ddy * ddy + ddz * ddz;
    double dist = sqrt(dist2);
    double inv = 1.0 / dist;
    double ux = ddx * inv, uy = ddy * inv, uz = ddz * inv;
    double cos_e = -(ux * L->nx[i] + uy * L->ny[i] + uz * L->nz[i]);
    double pdf = pdf_a * dist2 / cos_e;
    L->dx[i] = ux, L->dy[i] = uy, L->dz[i] = uz;
    L->dist[i] = dist;
    L->pdf[i] = pdf;
    L->ipdf[i] = 1.0 / pdf;
    L->dist_ok[i] = dist > 0 ? 1.0 : 0.0;
    L->cos_ok[i] = cos_e > 0 ? 1.0 : 0.0;
  }
}

/* tris: NULL when L holds the positions already, else area_pos_body's
 * first. */
static inline __attribute__((always_inline)) void area_lanes_body(area_lanes *L, int n, double pdf_a,
                                                                  const double *tris, bool flip) {
  if (tris) area_pos_body(L, n, tris, flip);
  area_geom_body(L, n, pdf_a);
}

#if defined(__x86_64__) || defined(__i386__)
static __attribute__((target("avx512f,avx512vl,avx512dq"))) void
area_geom_avx512(area_lanes *L, int n, double pdf_a, const double *tris, bool flip) {
  area_lanes_body(L, n, pdf_a, tris, flip);
}
static __attribute__((target("avx2,fma"))) void area_geom_avx2(area_lanes *L, int n, double pdf_a,
                                                               const double *tris, bool flip) {
  area_lanes_body(L, n, pdf_a, tris, flip);
}
#endif
/* sse2 (the x86-64 baseline) and generic. */
static void area_geom_base(area_lanes *L, int n, double pdf_a, const double *tris, bool flip) {
  area_lanes_body(L, n, pdf_a, tris, flip);
}

static void area_geom(area_lanes *L, int n, double pdf_a, const double *tris, bool flip) {
#if defined(__x86_64__) || defined(__i386__)
  switch (rsw_isa_get()) {
  case RSW_ISA_AVX512: area_geom_avx512(L, n, pdf_a, tris, flip); return;
  case RSW_ISA_AVX2: area_geom_avx2(L, n, pdf_a, tris, flip); return;
  default: break;
  }
#endif
  area_geom_base(L, n, pdf_a, tris, flip);
}

static void area_sample_chunk(const area_light *a, int n, const surface_interaction *const *ref,
                              const vec2 *u, direction_sample *ds, color *value, area_lanes *L) {
  const emitter *e = &a->base;
  const shape *s = e->shape;
  const double *tris = shape_world_tris_for(s, a->tris, a->tris_n);
  bool is_mesh = shape_is_mesh(s), flip = s->flip_normals;
  /* A uniform radiance (the common case) is read once, not per lane. */
  color rad;
  bool uniform = uniform_texture_value(a->radiance, &rad);
  double uv[AREA_C][2];
  if (is_mesh && uniform && tris) {
    /* Without texture coordinates to give, the positions in the lanes
     * too: the face's pick here (mesh_sample_inline's search), the rest
     * in area_pos_body. */
    const double *cdf = s->tri_cdf;
    for (int i = 0; i < n; i++) {
      double target = u[i].x * s->area;
      uint32_t lo = 0, hi = s->mesh.n_faces - 1;
      while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        bool right = cdf[mid] <= target;
        lo = right ? mid + 1 : lo;
        hi = right ? hi : mid;
      }
      double prev = lo ? cdf[lo - 1] : 0.0;
      L->f[i] = lo;
      L->tg[i] = target;
      L->prev[i] = prev;
      L->w[i] = cdf[lo] - prev;
      L->uy[i] = u[i].y;
      L->rx[i] = ref[i]->p.x, L->ry[i] = ref[i]->p.y, L->rz[i] = ref[i]->p.z;
    }
  }
  for (int i = 0; i < n && !(is_mesh && uniform && tris); i++) {
    /* shape_sample_position_tris without its pdf (the same for every
     * lane: pdf_a below) */
    position_sample ps;
    if (is_mesh) {
      mesh_sample_inline(s, u[i], tris, &ps);
      if (flip) ps.n = v3_neg(ps.n);
    } else {
      ps = shape_sample_position_tris(s, u[i], tris);
    }
    L->px[i] = ps.p.x, L->py[i] = ps.p.y, L->pz[i] = ps.p.z;
    L->nx[i] = ps.n.x, L->ny[i] = ps.n.y, L->nz[i] = ps.n.z;
    L->rx[i] = ref[i]->p.x, L->ry[i] = ref[i]->p.y, L->rz[i] = ref[i]->p.z;
    uv[i][0] = ps.uv[0], uv[i][1] = ps.uv[1];
  }
  area_geom(L, n, 1.0 / s->area, is_mesh && uniform && tris ? tris : NULL, flip);
  for (int i = 0; i < n; i++) {
    direction_sample *d = &ds[i];
    d->p = v3(L->px[i], L->py[i], L->pz[i]);
    d->n = v3(L->nx[i], L->ny[i], L->nz[i]);
    d->delta = false;
    d->pdf = 0;
    value[i] = col1(0);
    if (L->dist_ok[i] == 0) continue;
    d->d = v3(L->dx[i], L->dy[i], L->dz[i]);
    d->dist = L->dist[i];
    if (L->cos_ok[i] == 0) continue;
    d->pdf = L->pdf[i];
    if (!uniform) {
      surface_interaction at = {.p = d->p, .uv = {uv[i][0], uv[i][1]}, .shape = s};
      rad = tex_eval(a->radiance, &at);
    }
    value[i] = col_scale(rad, L->ipdf[i]);
  }
}

static void area_sample_batch(const emitter *e, int n, const surface_interaction *const *ref, const vec2 *u,
                              direction_sample *ds, color *value) {
  area_lanes L;
  for (int i = 0; i < n; i += AREA_C)
    area_sample_chunk((const area_light *)e, n - i < AREA_C ? n - i : AREA_C, ref + i, u + i, ds + i,
                      value + i, &L);
}

static double area_pdf(const emitter *e, const surface_interaction *ref, const direction_sample *ds) {
  double cos_e = -v3_dot(ds->d, ds->n);
  if (!(cos_e > 0)) return 0.0;
  return shape_pdf_position(e->shape) * ds->dist * ds->dist / cos_e;
}

static color area_eval(const emitter *e, const surface_interaction *hit, vec3 d) {
  const area_light *a = (const area_light *)e;
  (void)d;
  if (!(hit->wi.z > 0)) return col1(0); /* back side: Mitsuba tests Frame::cos_theta(si.wi) > 0 */
  return tex_eval(a->radiance, hit);
}

static const emitter_ops area_ops = {.sample_direction = area_sample,
                                     .pdf_direction = area_pdf,
                                     .eval = area_eval,
                                     .set_scene = area_set_scene,
                                     .sample_direction_batch = area_sample_batch};

static void area_destroy(object *o) {
  if (o) free(((area_light *)o)->tris);
  free(o);
}

static rsw_status area_create(loader *ld, node *n, object **out) {
  area_light *a = calloc(1, sizeof *a);
  if (!a) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  a->base.ops = &area_ops;
  a->base.flags = EMITTER_SURFACE;
  rsw_status st = ld_float_range(ld, n, "sampling_weight", 1.0, 0.0, INFINITY, &a->base.sampling_weight);
  if (!st) st = ld_texture(ld, n, "radiance", 1.0, 0.0, &a->radiance);
  if (st) {
    free(a);
    return st;
  }
  *out = &a->base.base;
  return RSW_OK;
}

static void area_traverse(object *o, param_visitor *v) {
  area_light *a = (area_light *)o;
  pv_object(v, "radiance", &a->radiance->base, 0.0, INFINITY);
  pv_float(v, "sampling_weight", &a->base.sampling_weight, UPDATE_SPECTRAL, 0.0, INFINITY);
}

DEFINE_PLUGIN(area, CLS_EMITTER, .destroy = area_destroy, .ops = &area_ops, .traverse = area_traverse);
