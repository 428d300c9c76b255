/* What the distant emitters (`directional`, `astroobject`) read alike:
 * sampling_weight, a spatially uniform irradiance, and an orientation
 * given by `direction` or (exclusive) `to_world`. */
#ifndef RSW_EMITTERS_DISTANT_EMITTER_H
#define RSW_EMITTERS_DISTANT_EMITTER_H

#include "../kernel.h"

struct loader;
struct node;

/* Mitsuba's to_world = look_at(0, normalize(d), up), up the first vector
 * of coordinate_system(d). False when no frame can be built. */
bool distant_look_at(vec3 d, xform *out);
/* Reads the three into e->sampling_weight, *irradiance (owned by the
 * scene) and *to_world (direction defaults to +z); errors name the key:
 * a varying irradiance, both direction and to_world, a zero direction, a
 * to_world that maps +z to zero. */
rsw_status distant_emitter_read(struct loader *ld, struct node *n, emitter *e, texture **irradiance,
                                xform *to_world);

#endif
