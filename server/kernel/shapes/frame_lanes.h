/* The body of shape_frames_batch (shapes/fill_simd.c) for one ISA: 8
 * double lanes (vd8), included once per ISA after FRAME_FN (the entry
 * point), FRAME_ATTR (its target attribute) and FRAME_SQRT(x) (the ISA's
 * packed square root of a vd8) are defined.
 *
 * Each lane runs, operation for operation and in the same order, the
 * scalar code of shape_frame_from_tangent (shapes/shape.h: the tangent
 * made orthogonal to sn, or coordinate_system(sn) from core/vec.h) and of
 * wi = frame_to_local(frame, -v3_norm(d)): IEEE +, -, *, / and sqrt round
 * the same in a vector lane, and -std=c11 turns FMA contraction off, so a
 * lane is bitwise the scalar result. Both branches are computed and the
 * right one selected (the unselected one may divide by zero; harmless). */
FRAME_ATTR void FRAME_FN(int n, int stride, const double *in, double *out) {
  for (int k0 = 0; k0 < n; k0 += 8) {
    vd8 v[SHAPE_FRAME_IN];
    for (int c = 0; c < SHAPE_FRAME_IN; c++) __builtin_memcpy(&v[c], &in[(size_t)c * stride + k0], sizeof v[c]);
    vd8 nx = v[0], ny = v[1], nz = v[2], tx = v[3], ty = v[4], tz = v[5], dx = v[6], dy = v[7], dz = v[8];
    const vd8 zero = (vd8){0}, one = zero + 1.0;
    /* A deferred shading normal: v3_norm(raw), or the fallback (nx, ny,
     * nz) where !(v3_len2 > 0.5) (mesh_fill_inline_raw). */
    {
      vd8 rx = v[9], ry = v[10], rz = v[11];
      vd8 rl = FRAME_SQRT(rx * rx + ry * ry + rz * rz);
      vl8 rpos = rl > 0.0;
      vd8 rinv = one / fsel8(rpos, rl, one);
      rx = fsel8(rpos, rx * rinv, rx), ry = fsel8(rpos, ry * rinv, ry), rz = fsel8(rpos, rz * rinv, rz);
      vl8 take = (v[12] != 0.0) & (rx * rx + ry * ry + rz * rz > 0.5);
      nx = fsel8(take, rx, nx), ny = fsel8(take, ry, ny), nz = fsel8(take, rz, nz);
    }
    /* The tangent made orthogonal to sn. */
    vl8 none = (tx == 0.0) & (ty == 0.0) & (tz == 0.0);
    vd8 dot = nx * tx + ny * ty + nz * tz;
    vd8 ux = tx - nx * dot, uy = ty - ny * dot, uz = tz - nz * dot;
    vd8 tl = FRAME_SQRT(ux * ux + uy * uy + uz * uz);
    vd8 tlen = FRAME_SQRT(tx * tx + ty * ty + tz * tz);
    vl8 use = ~none & (tl > 1e-9 * (tlen + 1e-300));
    vd8 inv = one / fsel8(use, tl, one);
    vd8 sx = ux * inv, sy = uy * inv, sz = uz * inv;
    vd8 cx = ny * sz - nz * sy, cy = nz * sx - nx * sz, cz = nx * sy - ny * sx;
    /* coordinate_system(sn): sgn = copysign(1, n.z), a = -1 / (sgn + n.z). */
    vd8 sgn = (vd8)(((vl8)one) | ((vl8)nz & (long long)0x8000000000000000ULL));
    vd8 a = -1.0 / (sgn + nz);
    vd8 b = nx * ny * a;
    vd8 s2x = nx * nx * a * sgn + 1.0, s2y = b * sgn, s2z = -nx * sgn;
    vd8 t2x = b, t2y = sgn + ny * ny * a, t2z = -ny;
    sx = fsel8(use, sx, s2x), sy = fsel8(use, sy, s2y), sz = fsel8(use, sz, s2z);
    cx = fsel8(use, cx, t2x), cy = fsel8(use, cy, t2y), cz = fsel8(use, cz, t2z);
    /* wi = local(-v3_norm(d)); v3_norm leaves a zero-length d as it is. */
    vd8 dl = FRAME_SQRT(dx * dx + dy * dy + dz * dz);
    vl8 pos = dl > 0.0;
    vd8 dinv = one / fsel8(pos, dl, one);
    vd8 wx = -fsel8(pos, dx * dinv, dx), wy = -fsel8(pos, dy * dinv, dy), wz = -fsel8(pos, dz * dinv, dz);
    vd8 ix = wx * sx + wy * sy + wz * sz;
    vd8 iy = wx * cx + wy * cy + wz * cz;
    vd8 iz = wx * nx + wy * ny + wz * nz;
    const vd8 res[12] = {sx, sy, sz, cx, cy, cz, nx, ny, nz, ix, iy, iz};
    for (int c = 0; c < 12; c++) __builtin_memcpy(&out[(size_t)c * stride + k0], &res[c], sizeof res[c]);
  }
}
