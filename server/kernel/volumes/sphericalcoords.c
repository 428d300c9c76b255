/* `sphericalcoordsvolume` (Eradiate): a nested volume read in spherical
 * coordinates, for spherical-shell atmospheres. A world point p is taken
 * to the unit sphere's frame by to_world's inverse, q = to_world^-1 p,
 * r = |q|, and looked up in the nested volume at
 *
 *   x = (r - rmin) / (rmax - rmin),  y = acos(q_z / r) / pi,
 *   z = atan2(q_y, q_x) / (2 pi) + 1/2
 *
 * (so a nested gridvolume's [Z, Y, X] layout is [phi, theta, r]); fillmin
 * below rmin, fillmax above rmax (both 0 by default). A medium holding it
 * interacts in the box [-1, 1]^3 under to_world, which bounds the sphere.
 *
 * It is no grid over that box: its cells are not box cells, so the slots
 * that read a volume's cells (piecewise layers, homogeneous, an
 * mqdiffuse table, molecular_atmosphere's sigma_a) refuse it
 * (ld_volume); heterogeneous takes its largest and smallest values for
 * its majorant and minorant, and an extremum_grid over it walks one piece.
 * Source: eradiate/mitsuba3 src/eradiate_plugins/volumes/sphericalcoords.cpp
 * (the mapping, the parameters and their defaults). */
#include <math.h>
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "volume.h"

#define PI 3.14159265358979323846

typedef struct sphcoords {
  volume base;
  volume *inner;
  xform frame; /* to_world as given: the unit sphere -> world */
  double rmin, rmax, fillmin, fillmax;
  double cell; /* (data: one cell holding max; nothing reads it as a grid) */
} sphcoords;

extern const plugin plugin_sphericalcoordsvolume;

static color sph_eval(const volume *v, vec3 p) {
  const sphcoords *s = (const sphcoords *)v;
  vec3 q = xf_inv_point(&s->frame, p);
  double r = v3_len(q);
  if (r < s->rmin) return col1(s->fillmin);
  if (r > s->rmax) return col1(s->fillmax);
  double c = r > 0 ? q.z / r : 1.0; /* (the centre: theta 0) */
  vec3 u = v3((r - s->rmin) / (s->rmax - s->rmin), acos(fmin(fmax(c, -1.0), 1.0)) / PI,
              atan2(q.y, q.x) / (2 * PI) + 0.5);
  return s->inner->ops->eval(s->inner, u);
}

static void sph_value_range(const volume *v, double *lo, double *hi) {
  const sphcoords *s = (const sphcoords *)v;
  s->inner->ops->value_range(s->inner, lo, hi);
  *lo = fmin(*lo, fmin(s->fillmin, s->fillmax));
  *hi = fmax(*hi, fmax(s->fillmin, s->fillmax));
}

static const volume_ops sph_ops = {.eval = sph_eval, .value_range = sph_value_range};

/* max from the nested volume's (prepared before this one: created first)
 * and the fills. */
static void sph_refresh(sphcoords *s) {
  double m = fmax(s->inner->max, fmax(s->fillmin, s->fillmax));
  if (m != s->base.max) s->base.revision++;
  s->base.max = s->cell = m;
  s->base.channels = s->inner->channels;
}

static rsw_status sph_prepare(object *o, const render_ctx *rc, rsw_err *err) {
  (void)rc, (void)err;
  sph_refresh((sphcoords *)o);
  return RSW_OK;
}

static void sph_parameters_changed(object *o) {
  sph_refresh((sphcoords *)o);
}

static bool sph_spectral(const object *o) {
  return volume_spectral(((const sphcoords *)o)->inner);
}

static void sph_traverse(object *o, param_visitor *pv) {
  sphcoords *s = (sphcoords *)o;
  pv_object(pv, "volume", &s->inner->base, s->base.lo, s->base.hi);
}

DEFINE_PLUGIN(sphericalcoordsvolume, CLS_VOLUME, .prepare = sph_prepare, .ops = &sph_ops,
              .traverse = sph_traverse, .parameters_changed = sph_parameters_changed,
              .spectral = sph_spectral, .pages = plugin_pages_any);

static rsw_status sphericalcoordsvolume_create(loader *ld, node *n, object **out) {
  volume *inner;
  rsw_status st = ld_volume_mapped(ld, n, "volume", 1.0, -INFINITY, INFINITY, &inner);
  double rmin, rmax, fmin_, fmax_;
  if (!st) st = ld_float(ld, n, "rmin", 0.0, &rmin);
  if (!st) st = ld_float(ld, n, "rmax", 1.0, &rmax);
  if (!st) st = ld_float(ld, n, "fillmin", 0.0, &fmin_);
  if (!st) st = ld_float(ld, n, "fillmax", 0.0, &fmax_);
  if (st) return st;
  if (!(rmin >= 0 && rmin < rmax))
    return ld_fail(ld, n, "rmax", RSW_ERR_RANGE,
                   "sphericalcoordsvolume: rmin (%g) and rmax (%g) must satisfy 0 <= rmin < rmax", rmin,
                   rmax);
  xform sphere;
  st = volume_read_to_world(ld, n, &sphere);
  if (st) return st;
  sphcoords *s = PLUGIN_NEW(sphcoords, sphericalcoordsvolume);
  if (s) {
    /* the box: [-1, 1]^3 in the sphere's frame, the unit cube under
     * frame * (x -> 2 x - 1) */
    xform sc = xf_scale(v3(2, 2, 2)), tr = xf_translate(v3(-1, -1, -1));
    xform cube = xf_mul(&tr, &sc);
    xform box = xf_mul(&sphere, &cube);
    volume_init(&s->base, &sph_ops, &box);
    s->base.box_grid = false;
    s->base.inner = inner;
    s->inner = inner;
    s->frame = sphere;
    s->rmin = rmin, s->rmax = rmax, s->fillmin = fmin_, s->fillmax = fmax_;
    s->base.res[0] = s->base.res[1] = s->base.res[2] = 1;
    s->base.data = &s->cell;
    sph_refresh(s);
  }
  return plugin_created(ld, n, s ? &s->base.base : NULL, out);
}

bool volume_sphere(const volume *v, double *rmin, double *rmax, double *fillmin, double *fillmax,
                   const xform **sph) {
  if (v->base.plugin != &plugin_sphericalcoordsvolume) return false;
  const sphcoords *s = (const sphcoords *)v;
  *rmin = s->rmin, *rmax = s->rmax, *fillmin = s->fillmin, *fillmax = s->fillmax;
  *sph = &s->frame;
  return true;
}
