/* Local majorants for tracked media: a coarse grid over a volume's box
 * whose every cell bounds the extinction anywhere in it, and the walk of a
 * ray over its cells (a 3D DDA, Amanatides and Woo 1987), so that delta
 * and ratio tracking take tentative collisions at the majorant of the cell
 * they are in rather than at the medium's largest extinction (Yue et al.
 * 2010, "Unbiased, adaptive stochastic sampling for rendering
 * inhomogeneous participating media"; Eradiate's extremum_grid). A cell
 * where the extinction is 0 costs no collision at all.
 *
 * A track spends its optical thickness tau = -ln(1 - u) (in majorant
 * units) piece by piece: within a piece of majorant mu and length len it
 * collides at t + tau / mu when tau < mu len, else it crosses the piece
 * with tau - mu len left. That is the free-flight distribution of the
 * piecewise-constant majorant, so each tentative collision still draws
 * one number and the estimators are those of a global majorant with mu
 * read where the collision falls (docs/media.md#local-majorants). */
#ifndef RSW_MEDIA_MAJORANT_GRID_H
#define RSW_MEDIA_MAJORANT_GRID_H

#include <math.h>
#include <stdbool.h>
#include <stdint.h>

#include "../kernel.h"

/* res[0] x res[1] x res[2] cells over the unit cube of a volume's box
 * (x fastest); mu: each cell's majorant (scale x the largest value over
 * every channel and page of the voxels that can reach it), NULL until
 * built. */
typedef struct majorant_grid {
  int res[3];
  double *mu;
  double *lo; /* each cell's minorant: scale x the smallest value reached in it */
  size_t cap; /* cells allocated (each array) */
  /* Radial (extremum_spherical over a sphericalcoordsvolume): res[0]
   * shells of equal thickness between rmin and rmax of the sphere's frame
   * (the unit sphere under *frame), cells res[0] + 2: [0] inside rmin
   * (fillmin), [1..res[0]] the shells, [res[0] + 1] outside rmax
   * (fillmax). */
  bool radial;
  double rmin, rmax;
  const xform *frame;
} majorant_grid;

/* Build g (g->res set, each >= 1) over volume v at pages 0..pages-1, its
 * values times scale. A cell holds the largest value of the voxels that
 * v's lookups (nearest or trilinear) reach from a point in it, those past
 * the grid's edges as v's wrap mode reaches them, times 1 + 2^-40 (the
 * interpolation's rounding); its minorant the smallest such value times
 * 1 - 2^-40. False: out of memory (g unchanged). */
bool majorant_grid_build(majorant_grid *g, const volume *v, int pages, double scale);
/* The radial grid (g->res[0] shells) over sphericalcoordsvolume v;
 * g->res[0] 0: the number of shells that a radial crossing of the shell
 * finds cheapest, among 1, 2, 4, ... up to the nested grid's radial
 * voxels and that count, each costing MAJORANT_SHELL_CROSSING tentative
 * collisions a shell crossed plus its majorants' optical thickness
 * sum(mu_k dr_k) (Yue et al. 2011's trade-off, along the radius); g->res[0]
 * is then that count. False: out of memory, or v's nested volume is no
 * grid over a box (g unchanged). */
bool majorant_grid_build_radial(majorant_grid *g, const volume *v, int pages, double scale);

/* What crossing a shell costs, in tentative collisions (measured on
 * docs/examples/spherical_shell.json: a crossing is a square root and a
 * few products, a collision a lookup, a number drawn and the weights). */
#define MAJORANT_SHELL_CROSSING 0.15
void majorant_grid_free(majorant_grid *g);

/* An extremum structure of a document (media/extremum.c), nested in a
 * heterogeneous medium: extremum_grid (local majorants over res cells; 0
 * along every axis: automatic) or extremum_global (the medium's largest
 * extinction, as without one). */
typedef struct extremum_object {
  object base;
  bool local;     /* extremum_grid or extremum_spherical */
  bool spherical; /* extremum_spherical: res[0] radial shells (0: automatic) */
  int res[3];
  double rmin, rmax; /* extremum_spherical's, when given (else NAN) */
} extremum_object;

/* Cells per axis of an automatic extremum_grid over n voxels. */
#define MAJORANT_GRID_AUTO_CELLS 16

/* The walk of a track over the pieces of its segment: mu, the majorant
 * of the current piece, which ends at b (INFINITY: the last piece, which
 * runs to the segment's end). Without a grid (track_walk_global) there is
 * one piece. */
typedef struct track_walk {
  double mu, b;
  double ctl;          /* the piece's control extinction (residual ratio tracking), 0 without */
  const double *cells; /* NULL: one piece */
  const double *ctls;  /* the cells' controls, or NULL (0) */
  int res[3], cell[3], step[3];
  double tnext[3], tdelta[3], maxt;
  /* A radial walk (majorant_grid.radial): |q(t)|^2 = qa t^2 + 2 qb t + qc
   * in the sphere's frame; bin -1 (inside rmin) .. nr (outside rmax),
   * out: r grows; after b, bin nbin and direction nout. */
  bool radial, out, nout;
  int bin, nbin, nr;
  double qa, qb, qc, r0, dr;
} track_walk;

static inline void track_walk_global(track_walk *w, double mu, double ctl) {
  w->mu = mu;
  w->ctl = ctl;
  w->b = INFINITY;
  w->cells = NULL;
  w->ctls = NULL;
  w->radial = false;
}

/* The walk of ray r (world; its parameter is the distance t) over
 * [mint, maxt] through g's cells, under the volume box to_world (affine);
 * rrt: each piece's control is its cell's minorant (else 0). False:
 * to_world is not affine (the caller walks with the global majorant). */
bool track_walk_grid(track_walk *w, const majorant_grid *g, const xform *to_world, const ray3 *r, double mint,
                     double maxt, bool rrt);
/* The same over a radial grid (g->radial; its frame affine). */
bool track_walk_radial(track_walk *w, const majorant_grid *g, const ray3 *r, double mint, double maxt,
                       bool rrt);

/* A radial walk's next boundary from t (its bin and direction set): the
 * sphere it crosses next, or the point nearest the centre where it turns
 * outward; INFINITY past maxt or when none is left. */
void track_walk_radial_boundary(track_walk *w, double t);

/* Move the walk to the next piece (the caller has reached w->b). */
static inline void track_walk_next(track_walk *w) {
  if (w->radial) {
    double t = w->b;
    w->bin = w->nbin;
    w->out = w->nout;
    w->mu = w->cells[w->bin + 1];
    w->ctl = w->ctls ? w->ctls[w->bin + 1] : 0.0;
    track_walk_radial_boundary(w, t);
    return;
  }
  int a =
      w->tnext[0] < w->tnext[1] ? (w->tnext[0] < w->tnext[2] ? 0 : 2) : (w->tnext[1] < w->tnext[2] ? 1 : 2);
  int c = w->cell[a] + w->step[a];
  if (c < 0 || c >= w->res[a]) { /* (left the grid before maxt: rounding; the last cell runs on) */
    w->b = INFINITY;
    return;
  }
  w->cell[a] = c;
  w->tnext[a] += w->tdelta[a];
  size_t i = ((size_t)w->cell[2] * w->res[1] + w->cell[1]) * w->res[0] + w->cell[0];
  w->mu = w->cells[i];
  w->ctl = w->ctls ? w->ctls[i] : 0.0;
  double b = fmin(w->tnext[0], fmin(w->tnext[1], w->tnext[2]));
  w->b = b < w->maxt ? b : INFINITY;
}

#endif
