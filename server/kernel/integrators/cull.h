/* The wave's ray culls (integrators/path.c): rays that cannot meet the
 * scene's geometry need no query. ray_may_hit is the cheap half of a slab
 * test against the scene's box padded by scene_pad (path.c says why the
 * padding is safe); camera rays also take accel.h's full slab test
 * (accel_box_misses). rays_traced_batch gives both verdicts for a batch
 * of rays, vectorised at the render's ISA (integrators/cull_lanes.h), lane
 * for lane the scalar verdicts. */
#ifndef RSW_INTEGRATORS_CULL_H
#define RSW_INTEGRATORS_CULL_H

#include "../accel.h"
#include "../core/isa.h"

/* The scene's box padded by pad on every side. */
typedef struct pad_box {
  double lo[3], hi[3];
} pad_box;

static inline pad_box pad_box_of(const scene *sc, double pad) {
  return (pad_box){{sc->bbox_min.x - pad, sc->bbox_min.y - pad, sc->bbox_min.z - pad},
                   {sc->bbox_max.x + pad, sc->bbox_max.y + pad, sc->bbox_max.z + pad}};
}

/* Only the cheap half of a slab test: a ray whose origin lies beyond a
 * face of the padded box and that points away from it (comparisons, no
 * division); any other ray is traced. Without branches: which face a
 * camera ray's origin lies beyond varies from ray to ray. */
static inline bool ray_may_hit(const pad_box *b, const ray3 *r) {
  bool away = (r->o.z > b->hi[2]) & (r->d.z >= 0);
  away |= (r->o.z < b->lo[2]) & (r->d.z <= 0);
  away |= (r->o.x > b->hi[0]) & (r->d.x >= 0);
  away |= (r->o.x < b->lo[0]) & (r->d.x <= 0);
  away |= (r->o.y > b->hi[1]) & (r->d.y >= 0);
  away |= (r->o.y < b->lo[1]) & (r->d.y <= 0);
  return !away;
}

/* n rays given by components (o[c][i], d[c][i]: component c of ray i's
 * origin and direction): out[i] = ray_may_hit(pb, ray i) && !(box &&
 * accel_box_misses(box, ray i)), as 1 or 0. */
void rays_traced_batch(rsw_isa isa, int n, const double *const *o, const double *const *d, const pad_box *pb,
                       const accel_box *box, unsigned char *out);

#endif
