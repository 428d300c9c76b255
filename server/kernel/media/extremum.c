/* Extremum structures (Eradiate's extremum_grid and extremum_global),
 * nested in a `heterogeneous` medium: where its tracks take their
 * majorants (media/majorant_grid.h, docs/media.md#local-majorants).
 *
 *   extremum_grid    resolution [x, y, z]: cells along each axis of the
 *                    medium's sigma_t box, 1 to 4096 each; [0, 0, 0] or
 *                    absent: automatic, min(voxels, 16) per axis
 *   extremum_spherical  over a sphericalcoordsvolume sigma_t: resolution
 *                    [n, 1, 1], n radial shells between its rmin and rmax
 *                    (1 to 65536; [0, 0, 0] or absent: one per radial
 *                    voxel of its nested grid); rmin and rmax, when
 *                    given, must be the volume's
 *   extremum_global  the medium's largest extinction (what a medium
 *                    without one uses)
 * Source: eradiate/mitsuba3 src/eradiate_plugins/extremum/extremum_grid.cpp
 * and extremum_spherical.cpp (the plugin names, `resolution`, rmin, rmax;
 * Eradiate's spherical traversal is radial only, as here). */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "majorant_grid.h"

#define MAX_CELLS_AXIS 4096

DEFINE_PLUGIN(extremum_grid, CLS_EXTREMUM, .pages = plugin_pages_any);
DEFINE_PLUGIN(extremum_global, CLS_EXTREMUM, .pages = plugin_pages_any);
DEFINE_PLUGIN(extremum_spherical, CLS_EXTREMUM, .pages = plugin_pages_any);

#define MAX_SHELLS 65536

static rsw_status extremum_grid_create(loader *ld, node *n, object **out) {
  vec3 r;
  bool given = false;
  rsw_status st = ld_vec3(ld, n, "resolution", v3(0, 0, 0), &r, &given);
  if (st) return st;
  const double v[3] = {r.x, r.y, r.z};
  bool zero = v[0] == 0 && v[1] == 0 && v[2] == 0;
  for (int a = 0; a < 3 && !zero; a++)
    if (!(v[a] >= 1 && v[a] <= MAX_CELLS_AXIS) || v[a] != floor(v[a]))
      return ld_fail(ld, n, "resolution", RSW_ERR_INVALID,
                     "extremum_grid: resolution must be 3 whole numbers of cells from 1 to %d, or [0, 0, 0] "
                     "(automatic); component %d is %g",
                     MAX_CELLS_AXIS, a, v[a]);
  extremum_object *e = PLUGIN_NEW(extremum_object, extremum_grid);
  if (e) {
    e->local = true;
    for (int a = 0; a < 3; a++) e->res[a] = zero ? 0 : (int)v[a];
  }
  return plugin_created(ld, n, e ? &e->base : NULL, out);
}

static rsw_status extremum_global_create(loader *ld, node *n, object **out) {
  extremum_object *e = PLUGIN_NEW(extremum_object, extremum_global);
  return plugin_created(ld, n, e ? &e->base : NULL, out);
}

static rsw_status extremum_spherical_create(loader *ld, node *n, object **out) {
  vec3 r;
  rsw_status st = ld_vec3(ld, n, "resolution", v3(0, 0, 0), &r, NULL);
  if (st) return st;
  bool zero = r.x == 0 && r.y == 0 && r.z == 0;
  if (!zero && (!(r.x >= 1 && r.x <= MAX_SHELLS) || r.x != floor(r.x) || r.y != 1 || r.z != 1))
    return ld_fail(
        ld, n, "resolution", RSW_ERR_INVALID,
        "extremum_spherical: resolution must be [n, 1, 1], n whole radial shells from 1 to %d (the "
        "traversal is radial only, as Eradiate's), or [0, 0, 0] (one per radial voxel); got [%g, %g, %g]",
        MAX_SHELLS, r.x, r.y, r.z);
  extremum_object *e = PLUGIN_NEW(extremum_object, extremum_spherical);
  if (e) {
    e->local = e->spherical = true;
    e->res[0] = zero ? 0 : (int)r.x;
    e->res[1] = e->res[2] = 1;
    /* rmin and rmax, when given, are checked against the volume by the
     * medium (heterogeneous.c) */
    e->rmin = e->rmax = NAN;
    if (ld_has(n, "rmin")) st = ld_float(ld, n, "rmin", 0.0, &e->rmin);
    if (!st && ld_has(n, "rmax")) st = ld_float(ld, n, "rmax", 1.0, &e->rmax);
    if (st) {
      free(e);
      return st;
    }
  }
  return plugin_created(ld, n, e ? &e->base : NULL, out);
}
