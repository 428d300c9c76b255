/* The kernel as the service sees it: a narrow, opaque interface.
 *
 * A scene is an opaque `struct scene`; everything the service asks of it
 * goes through these functions (sensors and their films, memory use,
 * per-pixel viewing directions), so the service needs none of the kernel's
 * internal headers for them. Not yet here (the service still includes
 * scene/scene.h, scene/params.h and render.h for them): loading,
 * parameters (the table, values, updates) and renders. */
#ifndef RSW_KERNEL_KAPI_H
#define RSW_KERNEL_KAPI_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "rsw_error.h"

struct scene;

/* ---- sensors and films ------------------------------------------------------ */

bool kapi_is_mono(const struct scene *sc);
size_t kapi_sensor_count(const struct scene *sc);
/* Sensor i's id (borrowed from the scene) and plugin name ("hdistant"). */
const char *kapi_sensor_id(const struct scene *sc, size_t i);
const char *kapi_sensor_type(const struct scene *sc, size_t i);
/* By id, or by decimal index when `name` is all digits. */
bool kapi_find_sensor(const struct scene *sc, const char *name, size_t *index);
void kapi_film_size(const struct scene *sc, size_t i, int *width, int *height);
/* The sensor sampler's sample_count (a render's default spp). */
uint32_t kapi_sensor_spp(const struct scene *sc, size_t i);

/* ---- memory ------------------------------------------------------------------- */

/* Bytes the scene's geometry holds: Embree's structures, mesh buffers,
 * area tables. */
size_t kapi_scene_bytes(const struct scene *sc);

/* Whether Embree is stuck in this process (accel.h accel_embree_stuck:
 * it ran out of memory, and a test build did not finish): no structure is
 * built any more, and the daemon is not ready. *since: when it was found;
 * *oom_count: Embree's out-of-memory failures so far (each may be NULL).
 * probe false: what is known, without testing a build (for reports). */
bool kapi_embree_stuck(long long *since, unsigned long long *oom_count, bool probe);

/* ---- per-pixel viewing directions ----------------------------------------------- */

/* Whether sensor i maps its pixels to directions (the distant family). */
bool kapi_has_directions(const struct scene *sc, size_t i);
/* For each pixel of sensor i's W x H film, row-major: the unit world
 * direction the pixel sees radiance leave along (x, y, z), its viewing
 * zenith and azimuth in degrees (Eradiate's east-right convention) — 5
 * doubles per pixel into out (W*H*5). The mapping is the sensor's own
 * (sensor_ops.pixel_directions, pixel_angles): the same one its rays use.
 * RSW_ERR_UNSUPPORTED for a sensor without one. */
rsw_status kapi_pixel_directions(const struct scene *sc, size_t i, double *out, rsw_err *err);

#endif
