/* What `thinlens` and `orthographic` share with Mitsuba's ProjectiveCamera
 * (mitsuba3 include/mitsuba/render/sensor.h): near_clip (0.01) and
 * far_clip (10000) with 0 < near < far, focus_distance (default
 * far_clip), and the film's aspect. */
#ifndef RSW_SENSORS_PROJECTIVE_H
#define RSW_SENSORS_PROJECTIVE_H

#include "sensor_common.h"

typedef struct projective {
  double near_clip, far_clip, focus_distance;
  double aspect; /* film width / height */
} projective;

/* Reads the three distances (after sensor_read_base, which gives the film). */
rsw_status projective_read(loader *ld, node *n, const sensor *s, projective *out);
/* to_world, refused when it scales (Mitsuba: "Scale factors in the
 * camera-to-world transformation are not allowed!"). */
rsw_status projective_read_rigid(loader *ld, node *n, xform *out);
/* The same check for a parameter update of to_world. */
rsw_status projective_check_rigid(const object *o, const xform *t, const char *key, rsw_err *err);

#endif
