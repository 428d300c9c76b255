/* What the medium plugins (homogeneous.c, heterogeneous.c, piecewise.c)
 * share: reading the common properties, a volume's box along a ray, the
 * scene-level checks of media.
 *
 * Rays given to medium_ops come from the volumetric integrators with unit
 * directions, so ray parameters are lengths in scene units and optical
 * thickness is coefficient x length. */
#ifndef RSW_MEDIA_MEDIA_H
#define RSW_MEDIA_MEDIA_H

#include "../core/fastmath.h"
#include "../kernel.h"

struct loader;
struct node;
struct param_visitor;

/* Mitsuba's Medium base properties: the nested phase function (any key;
 * default `isotropic`), `scale` (>= 0, default 1) and `sample_emitters`
 * (default true). */
rsw_status medium_read_common(struct loader *ld, struct node *n, medium *m);

/* `scale` and the phase function as parameters (scale is spectral-class:
 * the plugin's parameters_changed refreshes what depends on it). */
void medium_traverse_common(medium *m, struct param_visitor *v);

/* The part [*mint, *maxt] of ray r over [r->tmin, r->tmax] inside the unit
 * cube under to_world (a volume's box). False when empty. */
bool media_box_clip(const xform *to_world, const ray3 *r, double *mint, double *maxt);

/* The same with what depends on the box alone worked out once
 * (media_box_init, again whenever to_world changes): whether it is a scale
 * and translation (then its world bounds), for media that clip many rays
 * against one box. Same results as media_box_clip, bit for bit. */
typedef struct media_box {
  const xform *to_world;
  bool aligned;
  double lo[3], hi[3]; /* world bounds (aligned) */
} media_box;
void media_box_init(media_box *b, const xform *to_world);
bool media_box_clip_at(const media_box *b, const ray3 *r, double *mint, double *maxt);
/* An aligned box's clip of o + t d over [tmin, tmax], with inv[a] = 1 /
 * d[a] (world) wherever d[a] != 0, worked out by the caller once per
 * direction (volpath shares it with its null boxes' slab test): what
 * media_box_clip_at finds, bit for bit (it calls this). Inline, with the
 * ray's numbers as values: a call that reads them back from memory stalls
 * on the caller's stores. */
static inline bool media_box_clip_aligned(const media_box *b, vec3 o, vec3 d, double tmin, double tmax,
                                          const double inv[3], double *mint, double *maxt) {
  double lo = tmin, hi = tmax;
  const double o3[3] = {o.x, o.y, o.z}, d3[3] = {d.x, d.y, d.z};
  for (int a = 0; a < 3; a++) {
    double b0 = b->lo[a], b1 = b->hi[a];
    if (d3[a] == 0.0) {
      if (o3[a] < b0 || o3[a] > b1) return false;
      continue;
    }
    double ta = (b0 - o3[a]) * inv[a], tb = (b1 - o3[a]) * inv[a];
    /* (selects, not branches: the ray's direction decides them) */
    double t0 = rsw_sel_min(tb, ta), t1 = rsw_sel_max(ta, tb); /* (ta > tb ? tb : ta, ta > tb ? ta : tb) */
    lo = t0 > lo ? t0 : lo;
    hi = t1 < hi ? t1 : hi;
  }
  if (!(lo < hi)) return false;
  *mint = lo;
  *maxt = hi;
  return true;
}

/* Scene-level checks (scene/build.c calls it once the acceleration
 * structure exists): every medium in the document is bounded by a shape
 * (as its interior or exterior) or holds a sensor, and a sensor with a
 * medium sits inside it (the first surface its film-centre ray meets that
 * bounds a medium has the sensor's medium on the ray's origin side).
 * Errors name the medium's or the sensor's JSON pointer / XML line. */
rsw_status scene_check_media(const scene *s, struct node *root, rsw_err *err);
/* Does a sensor of s sit in a medium (so that an update must check it
 * still does)? */
bool scene_has_sensor_media(const scene *s);

/* Which masked null boxes (accel.h) the volumetric integrators may cross
 * analytically (scene->null_boxes): all of them or none. Each must be a
 * closed axis-aligned box in object space (12 outward triangles, two per
 * side) under an orientation-preserving to_world, and the scene not
 * periodic; else (a vertex update that bent one, say) none is, and every
 * query sees them as before. Also the bounds of every other shape (rays
 * missing them need no query). Run with the scene's bounds (load and
 * every geometric update: an update equals a reload). */
void media_refresh_null_boxes(scene *s);

#endif
