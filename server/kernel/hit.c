/* Hit -> interaction (hit.h): plain shapes through their ops, instanced
 * members under placement * member.to_world. */
#include "hit.h"

#include <string.h>

#include "accel.h"
#include "shapes/instance.h"

/* hit_fill_interaction but for si's shading frame and wi, which
 * shape_fill_begin leaves to *sn and *tangent unless it returns true.
 * terms: NULL, or a plain shape's accel_surface_error_terms under its
 * to_world (taken once for its hits). */
static bool hit_fill_begin(const scene *sc, const ray3 *r, const accel_hit *h, surface_interaction *si,
                           vec3 *sn, vec3 *tangent, vec3 *sn_raw, bool *sn_raw_set, const double *terms) {
  const shape *top = sc->shapes[h->shape];
  if (!shape_is_instancing(top)) {
    bool done = shape_fill_begin(top, &top->to_world, r, h, si, sn, tangent, sn_raw, sn_raw_set);
    si->p_error += terms ? accel_surface_error_at(terms, &top->to_world, si->p, si->ng)
                         : accel_surface_error(sc->accel, h->shape, &top->to_world, si->p, si->ng);
    return done;
  }
  const instance_shape *is = (const instance_shape *)top;
  const shape *m = is->group->members[h->member];
  /* The member seen through placement * member.to_world: shaded with that
   * transform exactly as a plain shape would be (barycentrics are
   * invariant under the affine maps involved). A member at the group's
   * origin (identity to_world, the usual leaf) skips the product. */
  xform place = instance_transform(is, h->sub);
  xform to_world = xf_is_identity(&m->to_world) ? place : xf_mul(&place, &m->to_world);
  accel_hit hh = *h;
  if (shape_is_mesh(m)) {
    /* Embree's Ng is in group space (member to_world baked in): back to
     * the member's object space, n_obj ~ M^T n_group (normals map by
     * M^-T), the orientation kept. */
    const double(*a)[4] = m->to_world.m;
    vec3 g = h->ng;
    hh.ng = v3(a[0][0] * g.x + a[1][0] * g.y + a[2][0] * g.z, a[0][1] * g.x + a[1][1] * g.y + a[2][1] * g.z,
               a[0][2] * g.x + a[1][2] * g.y + a[2][2] * g.z);
  }
  bool done = shape_fill_begin(m, &to_world, r, &hh, si, sn, tangent, sn_raw, sn_raw_set);
  /* The position is computed from the member's own coordinates (object
   * space barycentrics or re-projection) under placement * member, so its
   * error is that of Embree's instance frame, not of the world offset. */
  si->p_error += accel_surface_error(sc->accel, h->shape, &place, si->p, si->ng);
  return done;
}

void hit_prefetch(const scene *sc, const accel_hit *h) {
  const shape *top = sc->shapes[h->shape];
  if (shape_is_instancing(top)) instance_prefetch((const instance_shape *)top, h->sub);
}

void hit_fill_interaction(const scene *sc, const ray3 *r, const accel_hit *h, surface_interaction *si) {
  vec3 sn, tangent;
  if (hit_fill_begin(sc, r, h, si, &sn, &tangent, NULL, NULL, NULL)) return;
  si->sh = shape_frame_from_tangent(sn, tangent);
  si->wi = frame_to_local(&si->sh, v3_neg(v3_norm(r->d)));
}

/* A hit that shape_mesh_hits_batch fills: a plain (not instanced) mesh
 * with a face cache. */
static inline bool hit_cached_mesh(const shape *s) {
  return shape_is_mesh(s) && s->face_cache && !shape_is_instancing(s);
}

/* Face f of mesh s as shape_mesh_hits_batch's in[2 .. SHAPE_MH_IN_D),
 * written to q[c * step] (step 1: one face's constants; S: a lane of the
 * per-lane arrays). */
static inline void mesh_face_in(const shape *s, uint32_t f, bool nrm, bool uv, double *q, int step) {
  const mesh *ms = &s->mesh;
  const uint32_t *ix = &ms->faces[3 * (size_t)f];
  const uint32_t i0 = ix[0], i1 = ix[1], i2 = ix[2];
  const float *p0 = &ms->pos[3 * (size_t)i0], *p1 = &ms->pos[3 * (size_t)i1], *p2 = &ms->pos[3 * (size_t)i2];
  q[0] = p0[0], q[step] = p0[1], q[2 * step] = p0[2];
  q[3 * step] = p1[0], q[4 * step] = p1[1], q[5 * step] = p1[2];
  q[6 * step] = p2[0], q[7 * step] = p2[1], q[8 * step] = p2[2];
  if (nrm) {
    const float *na = &ms->nrm[3 * (size_t)i0], *nb = &ms->nrm[3 * (size_t)i1],
                *nc = &ms->nrm[3 * (size_t)i2];
    double *e = &q[(SHAPE_MH_IN_NA - 2) * step];
    e[0] = na[0], e[step] = na[1], e[2 * step] = na[2];
    e[3 * step] = nb[0], e[4 * step] = nb[1], e[5 * step] = nb[2];
    e[6 * step] = nc[0], e[7 * step] = nc[1], e[8 * step] = nc[2];
  }
  if (uv) {
    const float *ua = &ms->uv[2 * (size_t)i0], *ub = &ms->uv[2 * (size_t)i1], *uc = &ms->uv[2 * (size_t)i2];
    double *e = &q[(SHAPE_MH_IN_UVA - 2) * step];
    e[0] = ua[0], e[step] = ua[1], e[2 * step] = ub[0], e[3 * step] = ub[1], e[4 * step] = uc[0];
    e[5 * step] = uc[1];
  }
  /* The face's normal and dp/du: zero where the face's uv determinant
   * is, as mesh_fill_inline_raw leaves it. */
  const double *fc = &s->face_cache[SHAPE_FACE_DOUBLES * (size_t)f];
  double *e = &q[(SHAPE_MH_IN_N - 2) * step];
  e[0] = fc[0], e[step] = fc[1], e[2 * step] = fc[2], e[3 * step] = fc[3], e[4 * step] = fc[4];
  e[5 * step] = fc[5];
}

/* A mesh of at most HIT_FACE_GROUPS faces has its hits filled face by
 * face (the face's data once for its lanes) where a face has at least
 * HIT_FACE_MIN of a batch's hits, and its other hits by the scalar fill;
 * a larger mesh lane by lane in vectors; a cached mesh with fewer than
 * HIT_MESH_MIN hits in a batch by the scalar fill (the batched call's
 * set-up would cost more: measured on the Cornell box). */
#define HIT_FACE_GROUPS 64
#define HIT_FACE_MIN    8
#define HIT_MESH_MIN    4
/* Hits per chunk of hit_fill_interaction_batch (a multiple of 8): the
 * more hits a chunk holds, the more of a small mesh's faces have
 * HIT_FACE_MIN of them (the Cornell box: 256 took 0.97-0.98x the CPU
 * time of 64, 512 no less than 256). */
#define HIT_BATCH       256

/* The hits lane[0..cnt) on one cached mesh s (top-level shape `index`,
 * t its accel_surface_error_terms), their whole si through shape_mesh_hits_batch (bitwise
 * hit_fill_interaction) as HIT_FACE_GROUPS says; returns how many it
 * left to the caller's scalar fill, listed in left[]. */
static int hit_fill_cached(const shape *s, const double t[8], int cnt, const int *lane, const ray3 *const *r,
                           const accel_hit *const *h, surface_interaction *const *si, int *left) {
  enum {
    S = 64 /* lanes per call, a multiple of 8 */
  };
  const mesh *ms = &s->mesh;
  const bool nrm = ms->nrm && !s->face_normals, uv = ms->uv != NULL;
  /* A small mesh's lanes by face (counting sort): a face with at least
   * HIT_FACE_MIN of them is filled with its data given once, the others
   * are left to the caller; a large mesh's lanes go lane by lane (runs[]:
   * a face, or -1 for lane by lane). */
  int order[HIT_BATCH], start[HIT_FACE_GROUPS + 1], n_runs = 0, rest = 0;
  int run_face[HIT_FACE_GROUPS + 1], run_len[HIT_FACE_GROUPS + 1];
  const int *ls = lane;
  if (ms->n_faces <= HIT_FACE_GROUPS && cnt < HIT_FACE_MIN) { /* all by the scalar fill */
    memcpy(left, lane, cnt * sizeof *left);
    return cnt;
  }
  if (ms->n_faces <= HIT_FACE_GROUPS) {
    memset(start, 0, (ms->n_faces + 1) * sizeof *start);
    for (int j = 0; j < cnt; j++) start[h[lane[j]]->prim + 1]++;
    /* Faces with enough lanes first (in face order), then the rest. */
    int big = 0;
    for (uint32_t f = 0; f < ms->n_faces; f++)
      if (start[f + 1] >= HIT_FACE_MIN) big += start[f + 1];
    if (big == 0) { /* no face has enough: all by the scalar fill, unsorted */
      memcpy(left, lane, cnt * sizeof *left);
      return cnt;
    }
    int at_big = 0, at_rest = big;
    for (uint32_t f = 0; f < ms->n_faces; f++) {
      int c = start[f + 1];
      if (c >= HIT_FACE_MIN) {
        start[f] = at_big, at_big += c;
        run_face[n_runs] = (int)f, run_len[n_runs++] = c;
      } else {
        start[f] = at_rest, at_rest += c;
      }
    }
    rest = cnt - big;
    for (int j = 0; j < cnt; j++) order[start[h[lane[j]]->prim]++] = lane[j];
    ls = order;
  } else {
    rest = cnt;
  }
  int n_left = 0;
  if (rest && ms->n_faces <= HIT_FACE_GROUPS) { /* a small mesh's scattered hits: the scalar fill */
    memcpy(left, ls + (cnt - rest), rest * sizeof *left);
    n_left = rest;
  } else if (rest) {
    run_face[n_runs] = -1, run_len[n_runs++] = rest;
  }
  if (n_runs == 0) return n_left; /* nothing for the vector fill */
  double k[SHAPE_MH_K];
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++) k[SHAPE_MH_M + 4 * i + j] = s->to_world.m[i][j];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) k[SHAPE_MH_INV + 3 * i + j] = s->to_world.inv[i][j];
  for (int i = 0; i < 3; i++) k[SHAPE_MH_C + i] = t[i], k[SHAPE_MH_S + i] = t[5 + i];
  k[SHAPE_MH_TC] = t[3];
  k[SHAPE_MH_EXT] = t[4];
  k[SHAPE_MH_NRM] = nrm;
  k[SHAPE_MH_UV] = uv;
  k[SHAPE_MH_FLIP] = s->flip_normals;
  double a[SHAPE_MH_IN * S], o[SHAPE_MH_OUT * S], face[SHAPE_MH_IN_D - 2];
  int j0 = 0;
  for (int run = 0; run < n_runs; run++) {
    const bool by_face = run_face[run] >= 0;
    if (by_face) mesh_face_in(s, (uint32_t)run_face[run], nrm, uv, face, 1);
    for (int end = j0 + run_len[run]; j0 < end;) {
      int m = end - j0 < S ? end - j0 : S;
      for (int j = 0; j < m; j++) {
        const accel_hit *hj = h[ls[j0 + j]];
        double *q = &a[j];
        q[0] = hj->u, q[S] = hj->v;
        if (!by_face) mesh_face_in(s, hj->prim, nrm, uv, &q[2 * S], S);
        vec3 d = r[ls[j0 + j]]->d;
        double *e = &q[SHAPE_MH_IN_D * S];
        e[0] = d.x, e[S] = d.y, e[2 * S] = d.z;
      }
      for (int j = m; j < ((m + 7) & ~7); j++) /* the last vector's unused lanes */
        for (int c = 0; c < SHAPE_MH_IN; c++) a[c * S + j] = 0;
      shape_mesh_hits_batch(m, S, k, by_face ? face : NULL, a, o);
      for (int j = 0; j < m; j++) {
        const accel_hit *hj = h[ls[j0 + j]];
        surface_interaction *x = si[ls[j0 + j]];
        const double *fo = &o[j];
        const double *fc = &s->face_cache[SHAPE_FACE_DOUBLES * (size_t)hj->prim];
        vec3 n = v3(fc[0], fc[1], fc[2]);
        x->t = hj->t;
        x->shape = s;
        x->prim = hj->prim;
        x->p = v3(fo[0], fo[S], fo[2 * S]);
        x->p_error = fo[3 * S];
        x->uv[0] = fo[4 * S], x->uv[1] = fo[5 * S];
        x->ng = s->flip_normals ? v3_neg(n) : n;
        x->sh.s = v3(fo[6 * S], fo[7 * S], fo[8 * S]);
        x->sh.t = v3(fo[9 * S], fo[10 * S], fo[11 * S]);
        x->sh.n = v3(fo[12 * S], fo[13 * S], fo[14 * S]);
        x->wi = v3(fo[15 * S], fo[16 * S], fo[17 * S]);
      }
      j0 += m;
    }
  }
  return n_left;
}

/* Hit i by the scalar fill (terms as hit_fill_begin's), its frame and wi
 * left to the frames batch as entry *m of in (lane[*m] = i) unless the
 * fill made them. */
static inline void hit_fill_one(const scene *sc, int i, const ray3 *const *r, const accel_hit *const *h,
                                surface_interaction *const *si, const double *terms, double *in, int *lane,
                                int *m, int C) {
  vec3 sn, tg, raw = v3(0, 0, 0);
  bool deferred = false;
  if (hit_fill_begin(sc, r[i], h[i], si[i], &sn, &tg, &raw, &deferred, terms)) return;
  vec3 d = r[i]->d;
  double *q = &in[*m];
  q[0 * C] = sn.x, q[1 * C] = sn.y, q[2 * C] = sn.z;
  q[3 * C] = tg.x, q[4 * C] = tg.y, q[5 * C] = tg.z;
  q[6 * C] = d.x, q[7 * C] = d.y, q[8 * C] = d.z;
  q[9 * C] = raw.x, q[10 * C] = raw.y, q[11 * C] = raw.z;
  q[12 * C] = deferred ? 1.0 : 0.0;
  lane[(*m)++] = i;
}

void hit_fill_interaction_batch(const scene *sc, int n, const ray3 *const *r, const accel_hit *const *h,
                                surface_interaction *const *si) {
  enum {
    C = HIT_BATCH
  };
  double in[SHAPE_FRAME_IN * C], out[12 * C];
  int lane[C], cached[C];
  for (int k0 = 0; k0 < n; k0 += C) {
    int cnt = n - k0 < C ? n - k0 : C, m = 0, nc = 0;
    for (int k = 0; k < cnt; k++) {
      if (hit_cached_mesh(sc->shapes[h[k0 + k]->shape]))
        cached[nc++] = k0 + k;
      else
        hit_fill_one(sc, k0 + k, r, h, si, NULL, in, lane, &m, C);
    }
    /* The cached meshes' hits, shape by shape (a hit's values do not
     * depend on its group); a shape with few of them by the scalar fill. */
    while (nc > 0) {
      uint32_t index = h[cached[0]]->shape;
      int take[C], nt = 0, rest = 0;
      /* Without a branch: which shape a hit is on is unpredictable (the
       * branch's mispredictions cost a third of this function on the
       * Cornell box). Both lists are written; the counts say which holds. */
      for (int j = 0; j < nc; j++) {
        int c = cached[j], on = h[c]->shape == index;
        take[nt] = c, cached[rest] = c;
        nt += on, rest += 1 - on;
      }
      nc = rest;
      const shape *s = sc->shapes[index];
      double terms[8];
      accel_surface_error_terms(sc->accel, index, &s->to_world, terms);
      int left[C], nl = nt;
      if (nt >= HIT_MESH_MIN)
        nl = hit_fill_cached(s, terms, nt, take, r, h, si, left);
      else
        memcpy(left, take, nt * sizeof *left);
      for (int j = 0; j < nl; j++) hit_fill_one(sc, left[j], r, h, si, terms, in, lane, &m, C);
    }
    if (m == 0) continue;
    for (int j = m; j < ((m + 7) & ~7); j++) /* the last vector's unused lanes */
      for (int c = 0; c < SHAPE_FRAME_IN; c++) in[c * C + j] = 0;
    shape_frames_batch(m, C, in, out);
    for (int j = 0; j < m; j++) {
      surface_interaction *o = si[lane[j]];
      const double *f = &out[j];
      o->sh.s = v3(f[0 * C], f[1 * C], f[2 * C]);
      o->sh.t = v3(f[3 * C], f[4 * C], f[5 * C]);
      o->sh.n = v3(f[6 * C], f[7 * C], f[8 * C]);
      o->wi = v3(f[9 * C], f[10 * C], f[11 * C]);
    }
  }
}
