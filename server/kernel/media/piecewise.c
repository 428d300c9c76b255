/* `piecewise`: Eradiate's plane-parallel medium. sigma_t (scaled by
 * `scale`) and albedo are constant in each of N equal layers stacked along
 * the local z axis of the sigma_t volume's box (a [1, 1, N] grid: layer k
 * is local z in [k/N, (k+1)/N)); nothing interacts outside the box. The
 * exact tracking over the layers is layered.c's (shared with
 * molecular_atmosphere). Grids with a wavelength axis (gridvolume) give
 * each channel of a spectral bundle its own layers, and each page of a
 * bundle of pages its own (lm.Lp, from volume_page_data).
 * Source: eradiate/mitsuba3 src/eradiate_plugins/media/piecewise.cpp
 * (parameters, defaults: albedo 0.75, sigma_t 1, scale 1). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../scene/plugin_def.h"
#include "../volumes/volume.h"
#include "layered.h"
#include "media.h"

typedef struct piecewise_medium {
  layered_medium lm; /* (first: the ops see a layered_medium) */
  volume *sigma_t, *albedo;
  int pages;       /* of the bundle the last prepare() was for (1: none) */
  int pages_alloc; /* lm.Lp's layers allocated */
} piecewise_medium;

/* A grid value of layer k in channel c (one-channel grids: every channel)
 * of the values d (volume_page_data). */
static inline double grid_at(const volume *v, const double *d, uint32_t k, int c) {
  return d[(size_t)k * v->channels + (v->channels == 3 ? (size_t)c : 0)];
}

/* Page p's layers (0: lm.L) from the volumes' values at that page;
 * returns the largest albedo. */
static double pw_fill(piecewise_medium *pw, int p) {
  media_layers *L = p ? &pw->lm.Lp[p - 1] : &pw->lm.L;
  uint32_t n = L->n;
  bool alb_grid = pw->albedo->res[2] > 1;
  const double *st = volume_page_data(pw->sigma_t, p), *al = volume_page_data(pw->albedo, p);
  double amax = 0.0;
  L->to_world = &pw->sigma_t->to_world;
  for (uint32_t k = 0; k < n; k++)
    for (int c = 0; c < 3; c++) {
      double a = grid_at(pw->albedo, al, alb_grid ? k : 0, c);
      L->lay[k].sig[c] = pw->lm.base.scale * grid_at(pw->sigma_t, st, k, c);
      L->alb[3 * k + c] = a;
      if (a > amax) amax = a;
    }
  L->nc = pw->sigma_t->channels == 3 ? 3 : 1; /* (before finish: the index covers nc channels) */
  media_layers_finish(L);
  return amax;
}

/* Layer values, cumulative thickness, majorant: O(N) per page, after
 * sigma_t, albedo or scale changed (prepare() runs before every render,
 * after the volumes' own prepare). */
static void pw_refresh(piecewise_medium *pw) {
  double amax = 0.0;
  for (int p = 0; p < pw->pages; p++) amax = fmax(amax, pw_fill(pw, p));
  pw->lm.base.absorbing_only = amax == 0.0;
  pw->lm.base.has_spectral_extinction = pw->sigma_t->channels == 3;
  layered_extremes(&pw->lm, pw->pages);
}

/* Pages 1..pages-1 of a bundle allocated (their levels those of lm.L).
 * False: out of memory. */
static bool pw_pages_alloc(piecewise_medium *pw, int pages) {
  if (pw->pages_alloc >= pages - 1) return true;
  if (!pw->lm.Lp) {
    pw->lm.Lp = calloc(RENDER_MAX_PAGES - 1, sizeof *pw->lm.Lp);
    if (!pw->lm.Lp) return false;
  }
  for (; pw->pages_alloc < pages - 1; pw->pages_alloc++) {
    media_layers *L = &pw->lm.Lp[pw->pages_alloc];
    if (!media_layers_alloc(L, pw->lm.L.n)) {
      media_layers_free(L);
      return false;
    }
  }
  return true;
}

static rsw_status pw_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  piecewise_medium *pw = (piecewise_medium *)o;
  int pages = rc_pages(rc);
  if (!pw_pages_alloc(pw, pages)) return rsw_fail(err, RSW_ERR_NOMEM, "", "piecewise: out of memory");
  pw->pages = pages;
  pw_refresh(pw);
  return RSW_OK;
}

static void pw_parameters_changed(object *o) {
  pw_refresh((piecewise_medium *)o);
}

static void pw_destroy(object *o) {
  piecewise_medium *pw = (piecewise_medium *)o;
  media_layers_free(&pw->lm.L);
  for (int p = 0; pw->lm.Lp && p < pw->pages_alloc; p++) media_layers_free(&pw->lm.Lp[p]);
  free(pw->lm.Lp);
  free(pw);
}

static bool same_xform(const xform *a, const xform *b) {
  return memcmp(a->m, b->m, sizeof a->m) == 0;
}

static rsw_status piecewise_create(loader *ld, node *n, object **out) {
  piecewise_medium *pw = calloc(1, sizeof *pw);
  if (!pw) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "piecewise: out of memory");
  pw->lm.base.ops = &layered_medium_ops;
  pw->pages = 1;
  rsw_status st = medium_read_common(ld, n, &pw->lm.base);
  if (!st) st = ld_volume(ld, n, "sigma_t", 1.0, 0.0, INFINITY, &pw->sigma_t);
  if (!st) st = ld_volume(ld, n, "albedo", 0.75, 0.0, 1.0, &pw->albedo);
  if (!st && (pw->sigma_t->res[0] != 1 || pw->sigma_t->res[1] != 1))
    st = ld_fail(ld, n, "sigma_t", RSW_ERR_INVALID,
                 "piecewise: sigma_t must be a [1, 1, N] grid (layers along z), got %ux%ux%u (x, y, z)",
                 pw->sigma_t->res[0], pw->sigma_t->res[1], pw->sigma_t->res[2]);
  if (!st) {
    const volume *a = pw->albedo;
    bool one = a->res[0] == 1 && a->res[1] == 1 && a->res[2] == 1;
    bool layers = a->res[0] == 1 && a->res[1] == 1 && a->res[2] == pw->sigma_t->res[2];
    if (!one && !layers)
      st = ld_fail(
          ld, n, "albedo", RSW_ERR_INVALID,
          "piecewise: albedo must be constant or a [1, 1, %u] grid like sigma_t, got %ux%ux%u (x, y, z)",
          pw->sigma_t->res[2], a->res[0], a->res[1], a->res[2]);
    else if (layers && !one && !same_xform(&a->to_world, &pw->sigma_t->to_world))
      st = ld_fail(ld, n, "albedo", RSW_ERR_INVALID,
                   "piecewise: the albedo grid must have the same to_world as sigma_t (its layers are "
                   "sigma_t's)");
  }
  if (!st) {
    if (!media_layers_alloc(&pw->lm.L, pw->sigma_t->res[2]))
      st = ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "piecewise: out of memory");
    pw->lm.L.to_world = &pw->sigma_t->to_world;
  }
  if (st) {
    pw_destroy(&pw->lm.base.base);
    return st;
  }
  *out = &pw->lm.base.base;
  return RSW_OK;
}

static void pw_traverse(object *o, param_visitor *v) {
  piecewise_medium *pw = (piecewise_medium *)o;
  medium_traverse_common(&pw->lm.base, v);
  pv_object(v, "sigma_t", &pw->sigma_t->base, 0.0, INFINITY);
  pv_object(v, "albedo", &pw->albedo->base, 0.0, 1.0);
}

DEFINE_PLUGIN(piecewise, CLS_MEDIUM, .destroy = pw_destroy, .prepare = pw_prepare, .ops = &layered_medium_ops,
              .traverse = pw_traverse, .parameters_changed = pw_parameters_changed,
              .pages = plugin_pages_any); /* (pw_fill: a page's layers each) */
