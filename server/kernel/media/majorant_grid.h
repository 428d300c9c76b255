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
} majorant_grid;

/* Build g (g->res set, each >= 1) over volume v at pages 0..pages-1, its
 * values times scale. A cell holds the largest value of the voxels that
 * v's lookups (nearest or trilinear) reach from a point in it, those past
 * the grid's edges as v's wrap mode reaches them, times 1 + 2^-40 (the
 * interpolation's rounding); its minorant the smallest such value times
 * 1 - 2^-40. False: out of memory (g unchanged). */
bool majorant_grid_build(majorant_grid *g, const volume *v, int pages, double scale);
void majorant_grid_free(majorant_grid *g);

/* An extremum structure of a document (media/extremum.c), nested in a
 * heterogeneous medium: extremum_grid (local majorants over res cells; 0
 * along every axis: automatic) or extremum_global (the medium's largest
 * extinction, as without one). */
typedef struct extremum_object {
  object base;
  bool local;
  int res[3];
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
} track_walk;

static inline void track_walk_global(track_walk *w, double mu, double ctl) {
  w->mu = mu;
  w->ctl = ctl;
  w->b = INFINITY;
  w->cells = NULL;
  w->ctls = NULL;
}

/* The walk of ray r (world; its parameter is the distance t) over
 * [mint, maxt] through g's cells, under the volume box to_world (affine);
 * rrt: each piece's control is its cell's minorant (else 0). False:
 * to_world is not affine (the caller walks with the global majorant). */
bool track_walk_grid(track_walk *w, const majorant_grid *g, const xform *to_world, const ray3 *r, double mint,
                     double maxt, bool rrt);

/* Move the walk to the next piece (the caller has reached w->b). */
static inline void track_walk_next(track_walk *w) {
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
