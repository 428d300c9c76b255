/* Hit -> interaction (hit.h): plain shapes through their ops, instanced
 * members under placement * member.to_world. */
#include "hit.h"

#include "accel.h"
#include "shapes/instance.h"

/* hit_fill_interaction but for si's shading frame and wi, which
 * shape_fill_begin leaves to *sn and *tangent unless it returns true. */
static bool hit_fill_begin(const scene *sc, const ray3 *r, const accel_hit *h, surface_interaction *si,
                           vec3 *sn, vec3 *tangent, vec3 *sn_raw, bool *sn_raw_set) {
  const shape *top = sc->shapes[h->shape];
  if (!shape_is_instancing(top)) {
    bool done = shape_fill_begin(top, &top->to_world, r, h, si, sn, tangent, sn_raw, sn_raw_set);
    si->p_error += accel_surface_error(sc->accel, h->shape, &top->to_world, si->p, si->ng);
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

void hit_fill_interaction(const scene *sc, const ray3 *r, const accel_hit *h, surface_interaction *si) {
  vec3 sn, tangent;
  if (hit_fill_begin(sc, r, h, si, &sn, &tangent, NULL, NULL)) return;
  si->sh = shape_frame_from_tangent(sn, tangent);
  si->wi = frame_to_local(&si->sh, v3_neg(v3_norm(r->d)));
}

void hit_fill_interaction_batch(const scene *sc, int n, const ray3 *const *r, const accel_hit *const *h,
                                surface_interaction *const *si) {
  enum {
    C = 64 /* lanes per call, a multiple of 8 */
  };
  double in[SHAPE_FRAME_IN * C], out[12 * C];
  int lane[C];
  for (int k0 = 0; k0 < n; k0 += C) {
    int cnt = n - k0 < C ? n - k0 : C, m = 0;
    for (int k = 0; k < cnt; k++) {
      vec3 sn, tg, raw = v3(0, 0, 0);
      bool deferred = false;
      if (hit_fill_begin(sc, r[k0 + k], h[k0 + k], si[k0 + k], &sn, &tg, &raw, &deferred)) continue;
      vec3 d = r[k0 + k]->d;
      double *q = &in[m];
      q[0 * C] = sn.x, q[1 * C] = sn.y, q[2 * C] = sn.z;
      q[3 * C] = tg.x, q[4 * C] = tg.y, q[5 * C] = tg.z;
      q[6 * C] = d.x, q[7 * C] = d.y, q[8 * C] = d.z;
      q[9 * C] = raw.x, q[10 * C] = raw.y, q[11 * C] = raw.z;
      q[12 * C] = deferred ? 1.0 : 0.0;
      lane[m++] = k0 + k;
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
