/* Extremum structures (Eradiate's extremum_grid and extremum_global),
 * nested in a `heterogeneous` medium: where its tracks take their
 * majorants (media/majorant_grid.h, docs/media.md#local-majorants).
 *
 *   extremum_grid    resolution [x, y, z]: cells along each axis of the
 *                    medium's sigma_t box, 1 to 4096 each; [0, 0, 0] or
 *                    absent: automatic, min(voxels, 16) per axis
 *   extremum_global  the medium's largest extinction (what a medium
 *                    without one uses)
 * Source: eradiate/mitsuba3 src/eradiate_plugins/extremum/extremum_grid.cpp
 * (the plugin names and `resolution`). */
#include <math.h>

#include "../scene/plugin_def.h"
#include "majorant_grid.h"

#define MAX_CELLS_AXIS 4096

DEFINE_PLUGIN(extremum_grid, CLS_EXTREMUM, .pages = plugin_pages_any);
DEFINE_PLUGIN(extremum_global, CLS_EXTREMUM, .pages = plugin_pages_any);

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
