/* `heterogeneous`: a medium whose sigma_t and albedo vary over a grid
 * (Mitsuba's heterogeneous): sigma_t(p) = scale * sigma_t volume at p,
 * sigma_s = albedo(p) sigma_t(p), inside the sigma_t volume's box (the
 * unit cube under its to_world); nothing interacts outside it.
 *
 * Collisions are sampled by delta tracking against the majorant
 * mu = scale * max(sigma_t grid) (null collisions have sigma_n =
 * mu - sigma_t), and transmittance is estimated by ratio tracking, or
 * by residual ratio tracking with the grid's smallest value as control
 * (use_rrt, the default; integrators/volpath.c). A grid whose sigma_t and albedo are uniform is
 * a homogeneous box: it is flagged is_homogeneous and its transmittance
 * is exact (exp(-sigma_t l) over the length l inside the box).
 * A bundle of pages (render_ctx.bundle > 3): the volumes answer at the
 * page rsw_page names and their max covers every page, so the majorant
 * serves them all (volpath's track_pages). Uniform means uniform at every
 * page and channel.
 * A nested extremum_grid (media/extremum.c) gives the tracks local
 * majorants instead: a coarse grid over the sigma_t box whose cells bound
 * sigma_t in them, rebuilt with the majorant (docs/media.md#local-majorants).
 * Source: mitsuba3 src/media/heterogeneous.cpp; eradiate/mitsuba3's
 * extremum structures. */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "../volumes/volume.h"
#include "majorant_grid.h"
#include "media.h"

typedef struct heterogeneous_medium {
  medium base;
  volume *sigma_t, *albedo;
  color maj;       /* scale * max sigma_t (over every page) */
  double minorant; /* scale * min sigma_t (every page and channel) * (1 - 2^-40) */
  int pages;       /* of the bundle the last prepare() was for (1: none) */
  /* A nested extremum_grid: its cells (res[a] 0: automatic), and the grid
   * built from sigma_t (grid.mu NULL: none, or not built: out of memory). */
  const extremum_object *extremum;
  majorant_grid grid;
} heterogeneous_medium;

static bool het_intersect_aabb(const medium *m, const ray3 *r, double *mint, double *maxt) {
  const heterogeneous_medium *h = (const heterogeneous_medium *)m;
  return media_box_clip(&h->sigma_t->to_world, r, mint, maxt);
}

static color het_majorant(const medium *m, const medium_interaction *mi) {
  (void)mi;
  return ((const heterogeneous_medium *)m)->maj;
}

static void het_coefficients(const medium *m, medium_interaction *mi) {
  const heterogeneous_medium *h = (const heterogeneous_medium *)m;
  color st = col_scale(h->sigma_t->ops->eval(h->sigma_t, mi->p), h->base.scale);
  mi->sigma_t = st;
  mi->sigma_s = col_mul(st, h->albedo->ops->eval(h->albedo, mi->p));
  color n;
  for (int c = 0; c < 3; c++) n.c[c] = fmax(mi->majorant.c[c] - st.c[c], 0.0);
  mi->sigma_n = n;
}

/* Exact only when the grid is uniform (is_homogeneous); the integrators
 * call it only then. */
static color het_transmittance(const medium *m, const ray3 *r, double mint, double maxt) {
  const heterogeneous_medium *h = (const heterogeneous_medium *)m;
  double lo, hi;
  ray3 seg = *r;
  seg.tmin = mint;
  seg.tmax = maxt;
  if (!media_box_clip(&h->sigma_t->to_world, &seg, &lo, &hi)) return col1(1.0);
  color s = h->maj;
  double l = hi - lo;
  return col(exp(-s.c[0] * l), exp(-s.c[1] * l), exp(-s.c[2] * l));
}

static bool het_majorant_walk(const medium *m, const ray3 *r, double mint, double maxt, bool rrt,
                              track_walk *w) {
  const heterogeneous_medium *h = (const heterogeneous_medium *)m;
  if (!h->grid.mu) return false;
  if (h->grid.radial) return track_walk_radial(w, &h->grid, r, mint, maxt, rrt);
  return track_walk_grid(w, &h->grid, &h->sigma_t->to_world, r, mint, maxt, rrt);
}

static double het_minorant(const medium *m) {
  return ((const heterogeneous_medium *)m)->minorant;
}

static const medium_ops het_ops = {.intersect_aabb = het_intersect_aabb,
                                   .majorant = het_majorant,
                                   .coefficients = het_coefficients,
                                   .transmittance = het_transmittance,
                                   .majorant_walk = het_majorant_walk,
                                   .minorant = het_minorant};

/* Smallest and largest value of a volume's grid over pages 0..pages-1. */
static void grid_range(const volume *v, int pages, double *lo, double *hi) {
  if (!v->box_grid) { /* (a sphericalcoordsvolume: its range at every wavelength) */
    v->ops->value_range(v, lo, hi);
    return;
  }
  size_t n = (size_t)v->res[0] * v->res[1] * v->res[2] * v->channels;
  double a = INFINITY, b = -INFINITY;
  for (int p = 0; p < pages; p++) {
    const double *d = volume_page_data(v, p);
    for (size_t i = 0; i < n; i++) {
      a = fmin(a, d[i]);
      b = fmax(b, d[i]);
    }
  }
  *lo = a;
  *hi = b;
}

static void het_refresh(heterogeneous_medium *h) {
  double slo, shi, alo, ahi;
  grid_range(h->sigma_t, h->pages, &slo, &shi);
  grid_range(h->albedo, h->pages, &alo, &ahi);
  h->maj = col1(h->base.scale * h->sigma_t->max);
  h->minorant = slo > 0 ? h->base.scale * slo * (1.0 - 0x1p-40) : 0.0;
  h->base.is_homogeneous = slo == shi && alo == ahi;
  h->base.has_spectral_extinction = h->sigma_t->channels == 3;
  h->base.absorbing_only = ahi == 0.0;
  if (h->extremum && h->extremum->spherical) {
    double rmin, rmax, f0, f1;
    const xform *sph;
    const volume *v = h->sigma_t;
    if (volume_sphere(v, &rmin, &rmax, &f0, &f1, &sph)) {
      h->grid.res[0] = h->extremum->res[0]; /* (0: automatic) */
      h->grid.res[1] = h->grid.res[2] = 1;
      if (!majorant_grid_build_radial(&h->grid, v, h->pages, h->base.scale)) majorant_grid_free(&h->grid);
    }
  } else if (h->extremum && h->extremum->local && h->sigma_t->box_grid) {
    const volume *v = h->sigma_t;
    for (int a = 0; a < 3; a++) {
      int want = h->extremum->res[a];
      h->grid.res[a] =
          want > 0 ? want
                   : (int)(v->res[a] < MAJORANT_GRID_AUTO_CELLS ? v->res[a] : MAJORANT_GRID_AUTO_CELLS);
    }
    if (!majorant_grid_build(&h->grid, v, h->pages, h->base.scale)) majorant_grid_free(&h->grid);
  }
}

static rsw_status het_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  (void)err;
  heterogeneous_medium *h = (heterogeneous_medium *)o;
  h->pages = rc_pages(rc);
  het_refresh(h);
  return RSW_OK;
}

static void het_parameters_changed(object *o) {
  het_refresh((heterogeneous_medium *)o);
}

static rsw_status heterogeneous_create(loader *ld, node *n, object **out) {
  heterogeneous_medium *h = calloc(1, sizeof *h);
  if (!h) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "heterogeneous: out of memory");
  h->base.ops = &het_ops;
  h->pages = 1;
  rsw_status st = medium_read_common(ld, n, &h->base);
  if (!st) st = ld_volume_mapped(ld, n, "sigma_t", 1.0, 0.0, INFINITY, &h->sigma_t);
  if (!st) st = ld_volume_mapped(ld, n, "albedo", 0.75, 0.0, 1.0, &h->albedo);
  object *ex = NULL;
  if (!st) st = ld_child(ld, n, NULL, CLS_EXTREMUM, &ex);
  if (st) {
    free(h);
    return st;
  }
  h->extremum = (const extremum_object *)ex;
  /* an extremum over the kind of volume it walks */
  double rmin, rmax, f0, f1;
  const xform *sph;
  bool sphere = volume_sphere(h->sigma_t, &rmin, &rmax, &f0, &f1, &sph);
  const extremum_object *e = h->extremum;
  const char *why = NULL;
  if (e && e->spherical && !sphere)
    why = "extremum_spherical walks a sphericalcoordsvolume sigma_t's shells; this sigma_t is a grid over a "
          "box "
          "(give it an extremum_grid)";
  else if (e && e->local && !e->spherical && sphere)
    why = "extremum_grid walks a grid over a box; this sigma_t is a sphericalcoordsvolume (give it an "
          "extremum_spherical)";
  else if (e && e->spherical &&
           ((!isnan(e->rmin) && fabs(e->rmin - rmin) > 1e-6 * rmax) ||
            (!isnan(e->rmax) && fabs(e->rmax - rmax) > 1e-6 * rmax)))
    why = "extremum_spherical's rmin and rmax must be its sigma_t volume's";
  if (why) {
    free(h);
    return ld_fail(ld, n, NULL, RSW_ERR_INVALID, "heterogeneous: %s", why);
  }
  *out = &h->base.base;
  return RSW_OK;
}

static void het_traverse(object *o, param_visitor *v) {
  heterogeneous_medium *h = (heterogeneous_medium *)o;
  medium_traverse_common(&h->base, v);
  pv_object(v, "sigma_t", &h->sigma_t->base, 0.0, INFINITY);
  pv_object(v, "albedo", &h->albedo->base, 0.0, 1.0);
}

static void het_destroy(object *o) {
  heterogeneous_medium *h = (heterogeneous_medium *)o;
  majorant_grid_free(&h->grid);
  free(h);
}

DEFINE_PLUGIN(heterogeneous, CLS_MEDIUM, .prepare = het_prepare, .ops = &het_ops, .traverse = het_traverse,
              .parameters_changed = het_parameters_changed, .pages = plugin_pages_any,
              .destroy = het_destroy);
