/* Ray hits (accel.h) -> surface interactions, for any top-level shape:
 * what the integrators and media call after a ray query. Above both the
 * shapes and the acceleration structure (it adds accel_surface_error's
 * bound to each interaction's position error). */
#ifndef RSW_HIT_H
#define RSW_HIT_H

#include "accel_hit.h"
#include "kernel.h"

/* Hit -> interaction for any top-level shape: plain shapes go to
 * shape_fill_interaction; a hit inside an instanced group is filled from
 * the member's geometry under placement * member.to_world, and si->shape is
 * the member (its BSDF shades the hit). */
void hit_fill_interaction(const scene *sc, const ray3 *r, const struct accel_hit *h, surface_interaction *si);
/* hit_fill_interaction for n hits (lane i: r[i], h[i] -> si[i]), the
 * shading frames and wi vectorised (shape_frames_batch): each si is
 * bitwise what hit_fill_interaction gives. */
void hit_fill_interaction_batch(const scene *sc, int n, const ray3 *const *r,
                                const struct accel_hit *const *h, surface_interaction *const *si);

/* Start fetching what hit_fill_interaction will read of hit h that the
 * ray query has not brought into the cache: an instancelist placement's
 * record (shapes/instance.h). Nothing else; a hint, no effect on results. */
void hit_prefetch(const scene *sc, const struct accel_hit *h);

#endif
