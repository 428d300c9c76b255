#include "transform.h"

#include <stdio.h>
#include <string.h>

static void mat_mul(const double a[4][4], const double b[4][4], double r[4][4]) {
  double t[4][4];
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++) {
      double s = 0;
      for (int k = 0; k < 4; k++) s += a[i][k] * b[k][j];
      t[i][j] = s;
    }
  memcpy(r, t, sizeof t);
}

/* Gauss-Jordan with partial pivoting. */
static bool mat_inverse(const double a[4][4], double r[4][4]) {
  double m[4][8];
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++) {
      if (!isfinite(a[i][j])) return false;
      m[i][j] = a[i][j];
      m[i][j + 4] = (i == j) ? 1.0 : 0.0;
    }
  double scale = 0;
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++)
      if (fabs(a[i][j]) > scale) scale = fabs(a[i][j]);
  if (scale == 0) return false;
  for (int c = 0; c < 4; c++) {
    int p = c;
    for (int i = c + 1; i < 4; i++)
      if (fabs(m[i][c]) > fabs(m[p][c])) p = i;
    if (fabs(m[p][c]) <= 1e-14 * scale) return false;
    if (p != c)
      for (int j = 0; j < 8; j++) {
        double t = m[c][j];
        m[c][j] = m[p][j];
        m[p][j] = t;
      }
    double inv = 1.0 / m[c][c];
    for (int j = 0; j < 8; j++) m[c][j] *= inv;
    for (int i = 0; i < 4; i++) {
      if (i == c || m[i][c] == 0) continue;
      double f = m[i][c];
      for (int j = 0; j < 8; j++) m[i][j] -= f * m[c][j];
    }
  }
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++) r[i][j] = m[i][j + 4];
  return true;
}

xform xf_identity(void) {
  xform t;
  memset(&t, 0, sizeof t);
  for (int i = 0; i < 4; i++) t.m[i][i] = t.inv[i][i] = 1.0;
  return t;
}

bool xf_from_matrix(const double m[4][4], xform *out) {
  xform t;
  memcpy(t.m, m, sizeof t.m);
  if (!mat_inverse(t.m, t.inv)) return false;
  *out = t;
  return true;
}

xform xf_mul(const xform *a, const xform *b) {
  xform r;
  mat_mul(a->m, b->m, r.m);
  mat_mul(b->inv, a->inv, r.inv);
  return r;
}

xform xf_inverse(const xform *a) {
  xform r;
  memcpy(r.m, a->inv, sizeof r.m);
  memcpy(r.inv, a->m, sizeof r.inv);
  return r;
}

xform xf_translate(vec3 v) {
  xform t = xf_identity();
  t.m[0][3] = v.x;
  t.m[1][3] = v.y;
  t.m[2][3] = v.z;
  t.inv[0][3] = -v.x;
  t.inv[1][3] = -v.y;
  t.inv[2][3] = -v.z;
  return t;
}

xform xf_scale(vec3 s) {
  xform t = xf_identity();
  t.m[0][0] = s.x;
  t.m[1][1] = s.y;
  t.m[2][2] = s.z;
  t.inv[0][0] = 1.0 / s.x;
  t.inv[1][1] = 1.0 / s.y;
  t.inv[2][2] = 1.0 / s.z;
  return t;
}

/* Rodrigues' rotation about a unit axis, counter-clockwise for a positive
 * angle when looking down the axis (Mitsuba's Transform::rotate). */
xform xf_rotate(vec3 axis, double angle_deg) {
  vec3 a = v3_norm(axis);
  double th = angle_deg * (RSW_PI / 180.0);
  double s = sin(th), c = cos(th), cc = 1.0 - c;
  xform t = xf_identity();
  t.m[0][0] = a.x * a.x + (1 - a.x * a.x) * c;
  t.m[0][1] = a.x * a.y * cc - a.z * s;
  t.m[0][2] = a.x * a.z * cc + a.y * s;
  t.m[1][0] = a.x * a.y * cc + a.z * s;
  t.m[1][1] = a.y * a.y + (1 - a.y * a.y) * c;
  t.m[1][2] = a.y * a.z * cc - a.x * s;
  t.m[2][0] = a.x * a.z * cc - a.y * s;
  t.m[2][1] = a.y * a.z * cc + a.x * s;
  t.m[2][2] = a.z * a.z + (1 - a.z * a.z) * c;
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) t.inv[i][j] = t.m[j][i];
  return t;
}

bool xf_look_at(vec3 origin, vec3 target, vec3 up, xform *out) {
  vec3 dir = v3_sub(target, origin);
  if (!(v3_len(dir) > 0)) return false;
  dir = v3_norm(dir);
  vec3 left = v3_cross(v3_norm(up), dir);
  if (!(v3_len(left) > 1e-12)) return false;
  left = v3_norm(left);
  vec3 new_up = v3_cross(dir, left);
  double m[4][4] = {{left.x, new_up.x, dir.x, origin.x},
                    {left.y, new_up.y, dir.y, origin.y},
                    {left.z, new_up.z, dir.z, origin.z},
                    {0, 0, 0, 1}};
  return xf_from_matrix(m, out);
}

bool xf_is_identity(const xform *t) {
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++)
      if (t->m[i][j] != (i == j ? 1.0 : 0.0)) return false;
  return true;
}

bool xf_is_similarity(const xform *t, double *scale) {
  vec3 c[3];
  for (int j = 0; j < 3; j++) c[j] = v3(t->m[0][j], t->m[1][j], t->m[2][j]);
  double l0 = v3_len(c[0]), l1 = v3_len(c[1]), l2 = v3_len(c[2]);
  double tol = 1e-6 * (l0 + l1 + l2);
  if (fabs(l0 - l1) > tol || fabs(l0 - l2) > tol) return false;
  if (fabs(v3_dot(c[0], c[1])) > tol * l0 || fabs(v3_dot(c[0], c[2])) > tol * l0 ||
      fabs(v3_dot(c[1], c[2])) > tol * l0)
    return false;
  if (t->m[3][0] != 0 || t->m[3][1] != 0 || t->m[3][2] != 0 || t->m[3][3] != 1) return false;
  if (scale) *scale = (l0 + l1 + l2) / 3.0;
  return true;
}

bool xf_traceable(const double m[4][4], const char *what, char *buf, unsigned long len) {
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++)
      if (!isfinite(m[i][j])) {
        snprintf(buf, len, "%s: matrix entry [%d][%d] is not finite", what, i, j);
        return false;
      }
  if (m[3][0] != 0 || m[3][1] != 0 || m[3][2] != 0 || m[3][3] != 1) {
    snprintf(buf, len,
             "%s: the last row is [%g, %g, %g, %g]; a to_world must be affine (last row 0 0 0 1): a "
             "projective transform cannot be traced",
             what, m[3][0], m[3][1], m[3][2], m[3][3]);
    return false;
  }
  for (int i = 0; i < 3; i++)
    if (!(fabs(m[i][3]) <= RSW_TRACE_MAX_COORD)) {
      snprintf(buf, len, "%s: translation %g exceeds %g, the largest coordinate float32 tracing accepts",
               what, m[i][3], RSW_TRACE_MAX_COORD);
      return false;
    }
  /* The linear part's inverse by cofactors (A^-1 = adj(A) / det A). */
  const double(*a)[4] = m;
  double c[3][3];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) {
      int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
      c[j][i] = a[i1][j1] * a[i2][j2] - a[i1][j2] * a[i2][j1]; /* adjugate: transposed cofactor */
    }
  double det = a[0][0] * c[0][0] + a[0][1] * c[1][0] + a[0][2] * c[2][0];
  double fa = 0, fi = 0;
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) fa += a[i][j] * a[i][j];
  fa = sqrt(fa);
  if (det != 0 && isfinite(det)) {
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) {
        double x = c[i][j] / det;
        fi += x * x;
      }
    fi = sqrt(fi);
  }
  double smax = fa / sqrt(3.0);
  double smin = fi > 0 && isfinite(fi) ? sqrt(3.0) / fi : 0.0;
  if (!(smin >= RSW_TRACE_MIN_SCALE)) {
    snprintf(buf, len,
             "%s: scales down to %.3g (singular or nearly so); float32 tracing needs every scale >= %g", what,
             smin, RSW_TRACE_MIN_SCALE);
    return false;
  }
  if (!(smax <= RSW_TRACE_MAX_SCALE)) {
    snprintf(buf, len, "%s: scales up to %.3g; float32 tracing needs every scale <= %g", what, smax,
             RSW_TRACE_MAX_SCALE);
    return false;
  }
  if (!(smax <= RSW_TRACE_MAX_COND * smin)) {
    snprintf(buf, len,
             "%s: scales range from %.3g to %.3g (condition %.3g); float32 tracing needs a ratio <= %g "
             "(nearly singular)",
             what, smin, smax, smax / smin, RSW_TRACE_MAX_COND);
    return false;
  }
  return true;
}
