/* Local majorant grids (majorant_grid.h): the build, a separable running
 * maximum over the voxels that reach each cell, and the start of a walk. */
#include "majorant_grid.h"

#include <stdlib.h>

#include "../volumes/volume.h"

/* The voxels of an axis of n voxels whose lookups reach points of cell c
 * of r cells, [c / r, (c + 1) / r): nearest, floor(x n) for x in it,
 * voxels floor(c n / r) to ceil((c + 1) n / r) - 1; trilinear, the pair
 * floor(x n - 1/2) and the one after, voxels floor(c n / r - 1/2) to
 * floor((c + 1) n / r - 1/2) + 1. Integer arithmetic, exact. (A
 * collision rounded across a cell's side by the last bits of t is not
 * covered: its sigma_t may exceed the majorant, and it is then taken as
 * real with probability 1, a bias of the order of the rounding.) */
static void voxel_span(int c, int r, int n, bool trilinear, int *lo, int *hi) {
  if (!trilinear) {
    *lo = (int)((long long)c * n / r);
    *hi = (int)(((long long)(c + 1) * n + r - 1) / r) - 1;
    return;
  }
  /* floor((2 c n - r) / (2 r)) with a numerator that may be negative */
  long long num = 2LL * c * n - r, den = 2LL * r;
  long long f = num >= 0 ? num / den : -((-num + den - 1) / den);
  long long num1 = 2LL * (c + 1) * n - r;
  long long f1 = num1 >= 0 ? num1 / den : -((-num1 + den - 1) / den);
  *lo = (int)f;
  *hi = (int)f1 + 1;
}

/* out[i][c] = max (min: the second pair) over j in cell c's voxel span
 * (wrapped) of in[i][j], for `rows` rows of n values into rows of r
 * values; in and out hold (max, min) pairs. */
static void extremes_along(const double *in, double *out, size_t rows, int n, int r, int wrap, bool trilinear,
                           size_t in_stride, size_t in_step, size_t out_stride, size_t out_step) {
  for (size_t i = 0; i < rows; i++) {
    const double *row = in + 2 * i * in_stride;
    double *o = out + 2 * i * out_stride;
    for (int c = 0; c < r; c++) {
      int lo, hi;
      voxel_span(c, r, n, trilinear && n > 1, &lo, &hi);
      double mx = 0.0, mn = INFINITY;
      for (int j = lo; j <= hi; j++) {
        const double *x = row + 2 * (size_t)volume_wrap_index(j, n, wrap) * in_step;
        mx = x[0] > mx ? x[0] : mx;
        mn = x[1] < mn ? x[1] : mn;
      }
      o[2 * (size_t)c * out_step] = mx;
      o[2 * (size_t)c * out_step + 1] = mn;
    }
  }
}

bool majorant_grid_build(majorant_grid *g, const volume *v, int pages, double scale) {
  const int nx = (int)v->res[0], ny = (int)v->res[1], nz = (int)v->res[2];
  const int rx = g->res[0], ry = g->res[1], rz = g->res[2];
  const size_t ch = v->channels, cells = (size_t)rx * ry * rz;
  const bool tri = v->trilinear;
  /* Pass 0: each voxel's largest and smallest value over channels and
   * pages, reduced along x at once: a[z][y][cx]. Then along y:
   * b[z][cy][cx], along z: the cells (c). (max, min) pairs throughout. */
  double *a = malloc((size_t)nz * ny * rx * 2 * sizeof *a);
  double *b = malloc((size_t)nz * ry * rx * 2 * sizeof *b);
  double *row = malloc((size_t)nx * 2 * sizeof *row);
  double *c = malloc(cells * 2 * sizeof *c);
  double *mu = cells > g->cap ? malloc(cells * sizeof *mu) : g->mu;
  double *lo = cells > g->cap ? malloc(cells * sizeof *lo) : g->lo;
  if (!a || !b || !row || !c || !mu || !lo) {
    free(a), free(b), free(row), free(c);
    if (mu != g->mu) free(mu);
    if (lo != g->lo) free(lo);
    return false;
  }
  for (int z = 0; z < nz; z++)
    for (int y = 0; y < ny; y++) {
      for (int x = 0; x < nx; x++) row[2 * x] = 0.0, row[2 * x + 1] = INFINITY;
      for (int p = 0; p < pages; p++) {
        const double *d = volume_page_data(v, p) + (((size_t)z * ny + y) * nx) * ch;
        for (int x = 0; x < nx; x++)
          for (size_t k = 0; k < ch; k++) {
            double val = d[x * ch + k];
            row[2 * x] = val > row[2 * x] ? val : row[2 * x];
            row[2 * x + 1] = val < row[2 * x + 1] ? val : row[2 * x + 1];
          }
      }
      extremes_along(row, a + 2 * ((size_t)z * ny + y) * rx, 1, nx, rx, v->wrap, tri, 0, 1, 0, 1);
    }
  for (int z = 0; z < nz; z++) /* rows: cx; along y */
    extremes_along(a + 2 * (size_t)z * ny * rx, b + 2 * (size_t)z * ry * rx, (size_t)rx, ny, ry, v->wrap, tri,
                   1, (size_t)rx, 1, (size_t)rx);
  /* rows: (cy, cx) pairs; along z */
  extremes_along(b, c, (size_t)ry * rx, nz, rz, v->wrap, tri, 1, (size_t)ry * rx, 1, (size_t)ry * rx);
  const double up = 1.0 + 0x1p-40, down = 1.0 - 0x1p-40;
  for (size_t i = 0; i < cells; i++) {
    mu[i] = c[2 * i] * scale * up;
    lo[i] = c[2 * i + 1] * scale * down;
  }
  free(a), free(b), free(row), free(c);
  if (mu != g->mu) {
    free(g->mu), free(g->lo);
    g->mu = mu;
    g->lo = lo;
    g->cap = cells;
  }
  return true;
}

void majorant_grid_free(majorant_grid *g) {
  free(g->mu);
  free(g->lo);
  g->mu = g->lo = NULL;
  g->cap = 0;
}

bool track_walk_grid(track_walk *w, const majorant_grid *g, const xform *to_world, const ray3 *r, double mint,
                     double maxt, bool rrt) {
  const double(*m)[4] = to_world->inv;
  if (m[3][0] != 0.0 || m[3][1] != 0.0 || m[3][2] != 0.0 || m[3][3] != 1.0) return false;
  const double o[3] = {r->o.x, r->o.y, r->o.z}, d[3] = {r->d.x, r->d.y, r->d.z};
  w->cells = g->mu;
  w->ctls = rrt ? g->lo : NULL;
  w->maxt = maxt;
  w->radial = false;
  for (int a = 0; a < 3; a++) {
    double ol = m[a][0] * o[0] + m[a][1] * o[1] + m[a][2] * o[2] + m[a][3];
    double dl = m[a][0] * d[0] + m[a][1] * d[1] + m[a][2] * d[2];
    int n = g->res[a];
    w->res[a] = n;
    double f = (ol + mint * dl) * n;
    int c = f > 0.0 ? (f < n ? (int)f : n - 1) : 0; /* (NaN: 0) */
    w->cell[a] = c;
    if (dl > 0.0) {
      w->step[a] = 1;
      w->tnext[a] = ((double)(c + 1) / n - ol) / dl;
      w->tdelta[a] = 1.0 / (n * dl);
    } else if (dl < 0.0) {
      w->step[a] = -1;
      w->tnext[a] = ((double)c / n - ol) / dl;
      w->tdelta[a] = -1.0 / (n * dl);
    } else {
      w->step[a] = 0;
      w->tnext[a] = INFINITY;
      w->tdelta[a] = INFINITY;
    }
  }
  size_t i = ((size_t)w->cell[2] * g->res[1] + w->cell[1]) * g->res[0] + w->cell[0];
  w->mu = g->mu[i];
  w->ctl = w->ctls ? w->ctls[i] : 0.0;
  double b = fmin(w->tnext[0], fmin(w->tnext[1], w->tnext[2]));
  w->b = b < maxt ? b : INFINITY;
  return true;
}

/* The length in the world of a unit along the sphere's frame (its
 * columns' mean length: a sphere is scaled alike along its axes). */
static double frame_scale(const xform *f) {
  double s = 0;
  for (int c = 0; c < 3; c++)
    s += sqrt(f->m[0][c] * f->m[0][c] + f->m[1][c] * f->m[1][c] + f->m[2][c] * f->m[2][c]);
  return s / 3;
}

/* The automatic shell count over the radial columns col (nx (max, min)
 * pairs): the one of 1, 2, 4, ... and nx whose radial crossing costs
 * least, MAJORANT_SHELL_CROSSING a shell crossed plus sum(mu_k dr_k)
 * (len: the shell's thickness in the world). c: room for nx + 2 pairs. */
static int auto_shells(const double *col, int nx, int wrap, bool tri, double scale, double len, double *c) {
  int best = 1;
  double best_cost = INFINITY;
  for (int n = 1;; n = n * 2 < nx ? n * 2 : nx) {
    extremes_along(col, c, 1, nx, n, wrap, tri, 0, 1, 0, 1);
    double cost = MAJORANT_SHELL_CROSSING * n;
    for (int k = 0; k < n; k++) cost += c[2 * k] * scale * len / n;
    if (cost < best_cost) best_cost = cost, best = n;
    if (n >= nx) break;
  }
  return best;
}

bool majorant_grid_build_radial(majorant_grid *g, const volume *v, int pages, double scale) {
  double rmin, rmax, fill0, fill1;
  const xform *sph;
  if (!volume_sphere(v, &rmin, &rmax, &fill0, &fill1, &sph)) return false;
  const volume *in = v->inner;
  if (!in->box_grid) return false;
  const int nx = (int)in->res[0], ny = (int)in->res[1], nz = (int)in->res[2];
  const size_t ch = in->channels;
  const bool tri = in->trilinear && nx > 1;
  /* each radial voxel column x: its extremes over theta, phi, channels
   * and pages (read once, whatever the shell counts tried) */
  double *col = malloc((size_t)nx * 2 * sizeof *col);
  double *c = malloc(((size_t)(g->res[0] > nx ? g->res[0] : nx) + 2) * 2 * sizeof *c);
  if (!col || !c) {
    free(col), free(c);
    return false;
  }
  for (int x = 0; x < nx; x++) col[2 * x] = 0.0, col[2 * x + 1] = INFINITY;
  for (int p = 0; p < pages; p++) {
    const double *d = volume_page_data(in, p);
    for (int z = 0; z < nz; z++)
      for (int y = 0; y < ny; y++)
        for (int x = 0; x < nx; x++)
          for (size_t k = 0; k < ch; k++) {
            double val = d[(((size_t)z * ny + y) * nx + x) * ch + k];
            col[2 * x] = val > col[2 * x] ? val : col[2 * x];
            col[2 * x + 1] = val < col[2 * x + 1] ? val : col[2 * x + 1];
          }
  }
  const int nr = g->res[0] > 0
                     ? g->res[0]
                     : auto_shells(col, nx, in->wrap, tri, scale, (rmax - rmin) * frame_scale(sph), c);
  const size_t cells = (size_t)nr + 2;
  double *mu = cells > g->cap ? malloc(cells * sizeof *mu) : g->mu;
  double *lo = cells > g->cap ? malloc(cells * sizeof *lo) : g->lo;
  if (!mu || !lo) {
    free(col), free(c);
    if (mu != g->mu) free(mu);
    if (lo != g->lo) free(lo);
    return false;
  }
  extremes_along(col, c + 2, 1, nx, nr, in->wrap, tri, 0, 1, 0, 1);
  c[0] = c[1] = fill0;
  c[2 * (nr + 1)] = c[2 * (nr + 1) + 1] = fill1;
  const double up = 1.0 + 0x1p-40, down = 1.0 - 0x1p-40;
  for (size_t i = 0; i < cells; i++) {
    mu[i] = c[2 * i] * scale * up;
    lo[i] = c[2 * i + 1] * scale * down;
  }
  free(col), free(c);
  if (mu != g->mu) {
    free(g->mu), free(g->lo);
    g->mu = mu;
    g->lo = lo;
    g->cap = cells;
  }
  g->res[0] = nr;
  g->radial = true;
  g->rmin = rmin, g->rmax = rmax;
  g->frame = sph;
  return true;
}

void track_walk_radial_boundary(track_walk *w, double t) {
  double b = INFINITY;
  if (!w->out) { /* inward: the bin's inner sphere, if the ray reaches it, else the turn */
    if (w->bin >= 0) {
      double R = w->r0 + w->bin * w->dr;
      double disc = w->qb * w->qb - w->qa * (w->qc - R * R);
      if (disc >= 0) {
        double tr = (-w->qb - sqrt(disc)) / w->qa;
        if (tr >= t) {
          b = tr, w->nbin = w->bin - 1, w->nout = false;
          goto done;
        }
      }
    }
    b = fmax(-w->qb / w->qa, t), w->nbin = w->bin, w->nout = true;
  } else if (w->bin < w->nr) { /* outward: the bin's outer sphere */
    double R = w->r0 + (w->bin + 1) * w->dr;
    double disc = fmax(w->qb * w->qb - w->qa * (w->qc - R * R), 0.0);
    b = fmax((-w->qb + sqrt(disc)) / w->qa, t), w->nbin = w->bin + 1, w->nout = true;
  }
done:
  w->b = b < w->maxt ? b : INFINITY;
}

bool track_walk_radial(track_walk *w, const majorant_grid *g, const ray3 *r, double mint, double maxt,
                       bool rrt) {
  const double(*m)[4] = g->frame->inv;
  if (m[3][0] != 0.0 || m[3][1] != 0.0 || m[3][2] != 0.0 || m[3][3] != 1.0) return false;
  const double o[3] = {r->o.x, r->o.y, r->o.z}, d[3] = {r->d.x, r->d.y, r->d.z};
  double ol[3], dl[3];
  for (int a = 0; a < 3; a++) {
    ol[a] = m[a][0] * o[0] + m[a][1] * o[1] + m[a][2] * o[2] + m[a][3];
    dl[a] = m[a][0] * d[0] + m[a][1] * d[1] + m[a][2] * d[2];
  }
  w->qa = dl[0] * dl[0] + dl[1] * dl[1] + dl[2] * dl[2];
  if (!(w->qa > 0)) return false;
  w->qb = ol[0] * dl[0] + ol[1] * dl[1] + ol[2] * dl[2];
  w->qc = ol[0] * ol[0] + ol[1] * ol[1] + ol[2] * ol[2];
  w->radial = true;
  w->cells = g->mu;
  w->ctls = rrt ? g->lo : NULL;
  w->maxt = maxt;
  w->nr = g->res[0];
  w->r0 = g->rmin;
  w->dr = (g->rmax - g->rmin) / g->res[0];
  double rr = sqrt(fmax(w->qa * mint * mint + 2 * w->qb * mint + w->qc, 0.0));
  int bin = rr < g->rmin ? -1 : rr >= g->rmax ? w->nr : (int)((rr - g->rmin) / w->dr);
  w->bin = bin < w->nr ? bin : w->nr - 1;
  if (rr >= g->rmax) w->bin = w->nr;
  w->out = mint >= -w->qb / w->qa;
  w->mu = w->cells[w->bin + 1];
  w->ctl = w->ctls ? w->ctls[w->bin + 1] : 0.0;
  track_walk_radial_boundary(w, mint);
  return true;
}
