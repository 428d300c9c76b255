/* The body of shape_mesh_hits_batch (shapes/fill_simd.c) for one ISA,
 * included after FRAME_FN / FRAME_ATTR / VD / VL / FSEL as frame_lanes.h
 * (MESH_FN names the entry point).
 *
 * Each lane runs, operation for operation and in the same order, the
 * scalar code of a cached mesh's hit (shapes/shape.h mesh_fill_inline_raw
 * with a face-cache entry, then accel_surface_error for the hit's
 * position error): the barycentric position under to_world (mat_point,
 * its projective row included), the texture coordinates, the
 * interpolated shading normal under the inverse transpose (xf_normal) and
 * the position error bound; then the shading frame and wi
 * (FRAME_LANES, frame_lanes.h). IEEE +, -, *, / and fabs round the same in a
 * vector lane and -std=c11 turns FMA contraction off, so a lane is bitwise
 * the scalar result. */
FRAME_ATTR void MESH_FN(int n, int stride, const double *k, const double *face, const double *in,
                        double *out) {
  const VD zero = (VD){0}, one = zero + 1.0;
  const VL abs_mask = (VL){0} + 0x7fffffffffffffffLL;
  /* k[i] in every lane, bit for bit (zero + k[i] would turn -0 into +0). */
  VD kb[SHAPE_MH_K];
  for (int i = 0; i < SHAPE_MH_K; i++) {
    long long bits;
    __builtin_memcpy(&bits, &k[i], sizeof bits);
    kb[i] = (VD)((VL){0} + bits);
  }
#define B(i)    kb[i]
#define VABS(x) ((VD)((VL)(x)&abs_mask))
  const bool nrm = k[SHAPE_MH_NRM] != 0, uv = k[SHAPE_MH_UV] != 0, flip = k[SHAPE_MH_FLIP] != 0;
  /* One face for every lane: its data in every lane (bit for bit). */
  VD fv[SHAPE_MH_IN_D];
  if (face)
    for (int c = 2; c < SHAPE_MH_IN_D; c++) {
      long long bits;
      __builtin_memcpy(&bits, &face[c - 2], sizeof bits);
      fv[c] = (VD)((VL){0} + bits);
    }
    /* accel_surface_error's terms of the normal n: |(A^T n)_k| summed, and
   * weighted by S_k, and |n|_1 (once for a face's lanes). */
#define NORMAL_TERMS(nx, ny, nz, an1, wsum, n1)                                                              \
  do {                                                                                                       \
    VD atn0 = VABS(B(SHAPE_MH_M) * (nx) + B(SHAPE_MH_M + 4) * (ny) + B(SHAPE_MH_M + 8) * (nz));              \
    VD atn1 = VABS(B(SHAPE_MH_M + 1) * (nx) + B(SHAPE_MH_M + 5) * (ny) + B(SHAPE_MH_M + 9) * (nz));          \
    VD atn2 = VABS(B(SHAPE_MH_M + 2) * (nx) + B(SHAPE_MH_M + 6) * (ny) + B(SHAPE_MH_M + 10) * (nz));         \
    (an1) = atn0 + atn1 + atn2;                                                                              \
    (wsum) = atn0 * B(SHAPE_MH_S) + atn1 * B(SHAPE_MH_S + 1) + atn2 * B(SHAPE_MH_S + 2);                     \
    (n1) = VABS(nx) + VABS(ny) + VABS(nz);                                                                   \
  } while (0)
  VD f_an1 = zero, f_wsum = zero, f_n1 = zero;
  if (face)
    NORMAL_TERMS(fv[SHAPE_MH_IN_N], fv[SHAPE_MH_IN_N + 1], fv[SHAPE_MH_IN_N + 2], f_an1, f_wsum, f_n1);
  /* An affine to_world (last row 0 0 0 1) gives w = 1 exactly for the
   * finite object-space points of a hit: no division (mat_point). */
  const bool affine = k[SHAPE_MH_M + 12] == 0 && k[SHAPE_MH_M + 13] == 0 && k[SHAPE_MH_M + 14] == 0 &&
                      k[SHAPE_MH_M + 15] == 1;
  /* A face's lanes share their tangent, and often their shading normal
   * (a flat face's vertex normals): its frame is reused while they do
   * (frame_lanes.h). */
  VD memo[FRAME_MEMO];
  bool memo_ok = false;
  for (int k0 = 0; k0 < n; k0 += VW) {
    VD v[SHAPE_MH_IN];
    if (face) {
      __builtin_memcpy(&v[0], &in[k0], sizeof v[0]);
      __builtin_memcpy(&v[1], &in[(size_t)stride + k0], sizeof v[1]);
      _Pragma("GCC unroll 32") for (int c = 2; c < SHAPE_MH_IN_D; c++) v[c] = fv[c];
      _Pragma("GCC unroll 4") for (int c = SHAPE_MH_IN_D; c < SHAPE_MH_IN; c++)
          __builtin_memcpy(&v[c], &in[(size_t)c * stride + k0], sizeof v[c]);
      goto loaded;
    }
#define LOAD(lo, hi)                                                                                         \
  _Pragma("GCC unroll 16") for (int c = (lo); c < (hi); c++)                                                 \
      __builtin_memcpy(&v[c], &in[(size_t)c * stride + k0], sizeof v[c])
    LOAD(0, SHAPE_MH_IN_NA);
    if (nrm)
      LOAD(SHAPE_MH_IN_NA, SHAPE_MH_IN_UVA);
    else
      _Pragma("GCC unroll 16") for (int c = SHAPE_MH_IN_NA; c < SHAPE_MH_IN_UVA; c++) v[c] = zero;
    if (uv)
      LOAD(SHAPE_MH_IN_UVA, SHAPE_MH_IN_N);
    else
      _Pragma("GCC unroll 16") for (int c = SHAPE_MH_IN_UVA; c < SHAPE_MH_IN_N; c++) v[c] = zero;
    LOAD(SHAPE_MH_IN_N, SHAPE_MH_IN);
#undef LOAD
  loaded:;
    VD b1 = v[0], b2 = v[1];
    VD b0 = one - b1 - b2;
    /* po = p0 b0 + p1 b1 + p2 b2 (object space), then mat_point. */
    VD po[3];
    for (int c = 0; c < 3; c++) po[c] = v[2 + c] * b0 + v[5 + c] * b1 + v[8 + c] * b2;
    VD p[3];
    for (int r = 0; r < 3; r++)
      p[r] = B(SHAPE_MH_M + 4 * r) * po[0] + B(SHAPE_MH_M + 4 * r + 1) * po[1] +
             B(SHAPE_MH_M + 4 * r + 2) * po[2] + B(SHAPE_MH_M + 4 * r + 3);
    if (!affine) {
      VD w = B(SHAPE_MH_M + 12) * po[0] + B(SHAPE_MH_M + 13) * po[1] + B(SHAPE_MH_M + 14) * po[2] +
             B(SHAPE_MH_M + 15);
      VL proj = w != 1.0;
      VD wd = FSEL(proj, w, one);
      for (int r = 0; r < 3; r++) p[r] = FSEL(proj, p[r] / wd, p[r]);
    }
    /* The interpolated vertex normal under the inverse transpose
     * (xf_normal: component c = inv[0][c] no.x + inv[1][c] no.y +
     * inv[2][c] no.z), flipped with the shape's normals. */
    VD raw[3] = {zero, zero, zero};
    if (nrm) {
      VD no[3];
      for (int c = 0; c < 3; c++)
        no[c] = b0 * v[SHAPE_MH_IN_NA + c] + b1 * v[SHAPE_MH_IN_NA + 3 + c] + b2 * v[SHAPE_MH_IN_NA + 6 + c];
      for (int c = 0; c < 3; c++) {
        raw[c] =
            B(SHAPE_MH_INV + c) * no[0] + B(SHAPE_MH_INV + 3 + c) * no[1] + B(SHAPE_MH_INV + 6 + c) * no[2];
        if (flip) raw[c] = -raw[c];
      }
    }
    VD u0 = b1, u1 = b2;
    if (uv) {
      u0 = b0 * v[SHAPE_MH_IN_UVA] + b1 * v[SHAPE_MH_IN_UVA + 2] + b2 * v[SHAPE_MH_IN_UVA + 4];
      u1 = b0 * v[SHAPE_MH_IN_UVA + 1] + b1 * v[SHAPE_MH_IN_UVA + 3] + b2 * v[SHAPE_MH_IN_UVA + 5];
    }
    /* accel_surface_error(p, n) with the shape's terms (accel.h). */
    VD nx = v[SHAPE_MH_IN_N], ny = v[SHAPE_MH_IN_N + 1], nz = v[SHAPE_MH_IN_N + 2];
    VD an1 = f_an1, wsum = f_wsum, n1 = f_n1;
    if (!face) NORMAL_TERMS(nx, ny, nz, an1, wsum, n1);
    VD pc = VABS(p[0] - B(SHAPE_MH_C));
    VD ay = VABS(p[1] - B(SHAPE_MH_C + 1)), az = VABS(p[2] - B(SHAPE_MH_C + 2));
    pc = FSEL(ay > pc, ay, pc);
    pc = FSEL(az > pc, az, pc);
    VD err = RSW_F32_UNIT * (n1 * pc + wsum * (pc + B(SHAPE_MH_TC)) + an1 * B(SHAPE_MH_EXT));
    /* The shading frame and wi (frame_lanes.h) from sn = n after
     * flip_normals, the face's dp/du, d and the raw normal. */
    VD snx[SHAPE_FRAME_IN], res[SHAPE_MH_OUT];
    snx[0] = flip ? -nx : nx;
    snx[1] = flip ? -ny : ny;
    snx[2] = flip ? -nz : nz;
    snx[3] = v[SHAPE_MH_IN_T], snx[4] = v[SHAPE_MH_IN_T + 1], snx[5] = v[SHAPE_MH_IN_T + 2];
    snx[6] = v[SHAPE_MH_IN_D], snx[7] = v[SHAPE_MH_IN_D + 1], snx[8] = v[SHAPE_MH_IN_D + 2];
    snx[9] = raw[0], snx[10] = raw[1], snx[11] = raw[2];
    snx[12] = nrm ? one : zero;
    FRAME_LANES(snx, res + 6, face ? memo : NULL, &memo_ok);
    res[0] = p[0], res[1] = p[1], res[2] = p[2], res[3] = err, res[4] = u0, res[5] = u1;
    _Pragma("GCC unroll 16") for (int c = 0; c < SHAPE_MH_OUT; c++)
        __builtin_memcpy(&out[(size_t)c * stride + k0], &res[c], sizeof res[c]);
  }
#undef B
#undef VABS
#undef NORMAL_TERMS
}
