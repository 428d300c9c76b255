/* The body of shape_frames_batch (shapes/fill_simd.c) for one ISA: 8
 * double lanes (VD; FRAME_LANES, one vector of lanes, is shared with
 * mesh_hit_lanes.h), included once per ISA after FRAME_FN (the entry
 * point), FRAME_ATTR (its target attribute) and FRAME_SQRT(x) (the ISA's
 * packed square root of a VD) are defined.
 *
 * Each lane runs, operation for operation and in the same order, the
 * scalar code of shape_frame_from_tangent (shapes/shape.h: the tangent
 * made orthogonal to sn, or coordinate_system(sn) from core/vec.h) and of
 * wi = frame_to_local(frame, -v3_norm(d)): IEEE +, -, *, / and sqrt round
 * the same in a vector lane, and -std=c11 turns FMA contraction off, so a
 * lane is bitwise the scalar result. Both branches are computed and the
 * right one selected (the unselected one may divide by zero; harmless). */
#ifndef FRAME_ANY
/* Some lane of mask m is set. */
#define FRAME_ANY(m)                                                                                         \
  ({                                                                                                         \
    VL m_ = (m);                                                                                             \
    long long a_ = 0;                                                                                        \
    for (int i_ = 0; i_ < VW; i_++) a_ |= m_[i_];                                                            \
    a_ != 0;                                                                                                 \
  })
#endif
#ifndef FRAME_ALL
/* Every lane of mask m is set. */
#define FRAME_ALL(m)                                                                                         \
  ({                                                                                                         \
    VL m_ = (m);                                                                                             \
    long long a_ = -1;                                                                                       \
    for (int i_ = 0; i_ < VW; i_++) a_ &= m_[i_];                                                            \
    a_ != 0;                                                                                                 \
  })
/* Lane 0 of x in every lane, bit for bit (zero + x[0] would turn -0 into +0). */
#define FRAME_LANE0(x) ((VD)((VL){0} + ((VL)(x))[0]))
#endif
/* memo (NULL: none): FRAME_MEMO vectors, the normal and tangent of a
 * previous call's lane 0 (each in every lane) and the frame they gave,
 * s and t (valid where memo_ok). A lane's frame is a function of its own
 * normal and tangent only, so where every lane has the memo's normal and
 * tangent bit for bit (a flat face's hits, filled face by face), the
 * memo's frame is theirs: bitwise what the arithmetic below would give,
 * without its square roots and divisions. Otherwise the frame is computed
 * and lane 0's becomes the memo. */
#ifndef FRAME_MEMO
#define FRAME_MEMO 12
#endif
FRAME_ATTR inline __attribute__((always_inline)) void FRAME_LANES(const VD *v, VD *res, VD *memo,
                                                                  bool *memo_ok) {
  {
    VD nx = v[0], ny = v[1], nz = v[2], tx = v[3], ty = v[4], tz = v[5], dx = v[6], dy = v[7], dz = v[8];
    const VD zero = (VD){0}, one = zero + 1.0;
    /* A deferred shading normal: v3_norm(raw), or the fallback (nx, ny,
     * nz) where !(v3_len2 > 0.5) (mesh_fill_inline_raw). */
    if (FRAME_ANY(v[12] != 0.0)) {
      VD rx = v[9], ry = v[10], rz = v[11];
      VD rl = FRAME_SQRT(rx * rx + ry * ry + rz * rz);
      VL rpos = rl > 0.0;
      VD rinv = one / FSEL(rpos, rl, one);
      rx = FSEL(rpos, rx * rinv, rx), ry = FSEL(rpos, ry * rinv, ry), rz = FSEL(rpos, rz * rinv, rz);
      VL take = (v[12] != 0.0) & (rx * rx + ry * ry + rz * rz > 0.5);
      nx = FSEL(take, rx, nx), ny = FSEL(take, ry, ny), nz = FSEL(take, rz, nz);
    }
    VD sx = zero, sy = zero, sz = zero, cx = zero, cy = zero, cz = zero;
    if (memo && *memo_ok &&
        FRAME_ALL(((VL)nx == (VL)memo[0]) & ((VL)ny == (VL)memo[1]) & ((VL)nz == (VL)memo[2]) &
                  ((VL)tx == (VL)memo[3]) & ((VL)ty == (VL)memo[4]) & ((VL)tz == (VL)memo[5]))) {
      sx = memo[6], sy = memo[7], sz = memo[8], cx = memo[9], cy = memo[10], cz = memo[11];
      goto framed;
    }
    /* The tangent made orthogonal to sn. */
    VL none = (tx == 0.0) & (ty == 0.0) & (tz == 0.0);
    VL use = none & ~none;
    if (FRAME_ANY(~none)) { /* square roots and divisions only where a lane needs them */
      VD dot = nx * tx + ny * ty + nz * tz;
      VD ux = tx - nx * dot, uy = ty - ny * dot, uz = tz - nz * dot;
      VD tl = FRAME_SQRT(ux * ux + uy * uy + uz * uz);
      VD tlen = FRAME_SQRT(tx * tx + ty * ty + tz * tz);
      use = ~none & (tl > 1e-9 * (tlen + 1e-300));
      VD inv = one / FSEL(use, tl, one);
      sx = ux * inv, sy = uy * inv, sz = uz * inv;
      cx = ny * sz - nz * sy, cy = nz * sx - nx * sz, cz = nx * sy - ny * sx;
    }
    if (FRAME_ANY(~use)) {
      /* coordinate_system(sn): sgn = copysign(1, n.z), a = -1 / (sgn + n.z). */
      VD sgn = (VD)(((VL)one) | ((VL)nz & (long long)0x8000000000000000ULL));
      VD a = -1.0 / (sgn + nz);
      VD b = nx * ny * a;
      VD s2x = nx * nx * a * sgn + 1.0, s2y = b * sgn, s2z = -nx * sgn;
      VD t2x = b, t2y = sgn + ny * ny * a, t2z = -ny;
      sx = FSEL(use, sx, s2x), sy = FSEL(use, sy, s2y), sz = FSEL(use, sz, s2z);
      cx = FSEL(use, cx, t2x), cy = FSEL(use, cy, t2y), cz = FSEL(use, cz, t2z);
    }
    if (memo) {
      const VD key[FRAME_MEMO] = {nx, ny, nz, tx, ty, tz, sx, sy, sz, cx, cy, cz};
      for (int i = 0; i < FRAME_MEMO; i++) memo[i] = FRAME_LANE0(key[i]);
      *memo_ok = true;
    }
  framed:;
    /* wi = local(-v3_norm(d)); v3_norm leaves a zero-length d as it is. */
    VD dl = FRAME_SQRT(dx * dx + dy * dy + dz * dz);
    VL pos = dl > 0.0;
    VD dinv = one / FSEL(pos, dl, one);
    VD wx = -FSEL(pos, dx * dinv, dx), wy = -FSEL(pos, dy * dinv, dy), wz = -FSEL(pos, dz * dinv, dz);
    VD ix = wx * sx + wy * sy + wz * sz;
    VD iy = wx * cx + wy * cy + wz * cz;
    VD iz = wx * nx + wy * ny + wz * nz;
    res[0] = sx, res[1] = sy, res[2] = sz, res[3] = cx, res[4] = cy, res[5] = cz;
    res[6] = nx, res[7] = ny, res[8] = nz, res[9] = ix, res[10] = iy, res[11] = iz;
  }
}

FRAME_ATTR void FRAME_FN(int n, int stride, const double *in, double *out) {
  for (int k0 = 0; k0 < n; k0 += VW) {
    VD v[SHAPE_FRAME_IN], res[12];
    for (int c = 0; c < SHAPE_FRAME_IN; c++)
      __builtin_memcpy(&v[c], &in[(size_t)c * stride + k0], sizeof v[c]);
    FRAME_LANES(v, res, NULL, NULL);
    for (int c = 0; c < 12; c++) __builtin_memcpy(&out[(size_t)c * stride + k0], &res[c], sizeof res[c]);
  }
}
