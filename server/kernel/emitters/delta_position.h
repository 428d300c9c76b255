/* What the delta-position emitters (`point`, `spot`) share: the light
 * sample towards a point source, its placement (`position` or
 * `to_world`) and its constant `intensity`. */
#ifndef RSW_EMITTERS_DELTA_POSITION_H
#define RSW_EMITTERS_DELTA_POSITION_H

#include "../kernel.h"

struct loader;
struct node;

/* Fills ds for a source at p seen from x: unit direction towards p,
 * distance, pdf 1, delta. Returns 1 / r^2 (m^-2), or 0 (ds->pdf 0) when x
 * is at p. */
static inline double delta_position_sample(vec3 p, vec3 x, direction_sample *ds) {
  vec3 d = v3_sub(p, x);
  double r = v3_len(d);
  ds->p = p;
  ds->n = v3(0, 0, 0);
  ds->delta = true;
  if (!(r > 0) || !isfinite(r)) {
    ds->d = v3(0, 0, 1);
    ds->dist = 0;
    ds->pdf = 0;
    return 0;
  }
  ds->d = v3_scale(d, 1.0 / r);
  ds->dist = r;
  ds->pdf = 1.0;
  return 1.0 / (r * r);
}

/* The ops a delta position shares: it is never hit by chance (pdf 0,
 * eval 0) and needs nothing from the scene. */
double delta_position_pdf(const emitter *e, const surface_interaction *ref, const direction_sample *ds);
color delta_position_eval(const emitter *e, const surface_interaction *hit, vec3 d);
void delta_position_set_scene(emitter *e, const struct scene *s);

/* to_world with its translation replaced by p (the linear part kept). */
void delta_position_move(xform *to_world, vec3 p);
/* `intensity` (W sr^-1 [nm^-1], default 1, >= 0), refused when it varies
 * spatially (Mitsuba's rule for point and spot). *out is owned by the
 * scene. */
rsw_status delta_position_intensity(struct loader *ld, struct node *n, texture **out);
/* The placement: `to_world` (default identity), or, where allow_position,
 * `position` (translate(position)); giving both is an error. */
rsw_status delta_position_place(struct loader *ld, struct node *n, bool allow_position, xform *out);

#endif
