/* Parts shared by the sensor plugins (private to sensors/): what Mitsuba's
 * Sensor base class reads (film, sampler, shutter), the 1x1-film check of
 * the single-pixel sensors, and the ray-target strategy of the distant
 * family (distant, hdistant), docs/kernel-conventions.md#sensors. */
#ifndef RSW_SENSORS_SENSOR_COMMON_H
#define RSW_SENSORS_SENSOR_COMMON_H

#include "../core/isa.h"
#include "../kernel.h"
#include "../scene/loader.h"

/* Read the properties every sensor has (mitsuba3 src/render/sensor.cpp):
 * the nested film (default: an `hdrfilm` with its defaults), the nested
 * sampler (default: `independent`, sample_count 4), and shutter_open /
 * shutter_close (accepted and validated; ignored since nothing moves).
 * Fills s->film and s->sampler (owned by the scene). */
rsw_status sensor_read_base(loader *ld, node *n, sensor *s);

/* The horizontal field of view in degrees of a projective camera
 * (perspective, thinlens) from fov / fov_axis / focal_length, Mitsuba's
 * parse_fov (sensors/perspective.c says how); aspect = film W / H. */
rsw_status perspective_parse_fov(loader *ld, node *n, double aspect, double *fov_x);
/* The range of the `x_fov` key (degrees; the open interval (0, 180)). */
#define X_FOV_MIN 1e-6
#define X_FOV_MAX (180.0 - 1e-6)

/* Error unless s->film is 1x1 pixels (distant, radiancemeter: Mitsuba's
 * "This sensor only supports films of size 1x1 Pixels!"). */
rsw_status sensor_require_1x1_film(loader *ld, node *n, const sensor *s);

/* Where the rays of a distant sensor are aimed. */
typedef enum ray_target_kind {
  RAY_TARGET_NONE,  /* disk cross-section of the scene's bounding sphere */
  RAY_TARGET_POINT, /* one world point */
  RAY_TARGET_SHAPE, /* uniform area samples on a (flat) shape */
} ray_target_kind;

typedef struct ray_target {
  ray_target_kind kind;
  vec3 point;         /* RAY_TARGET_POINT */
  const shape *shape; /* RAY_TARGET_SHAPE (owned by the scene) */
  /* The scene's periodic boundary (ray_target_bind), when origins are to
   * be put outside its geometry's slab; .on false otherwise. */
  periodic_bounds slab;
  /* RAY_TARGET_SHAPE: its world triangles (shape_world_tris_refresh, by
   * ray_target_bind), owned; NULL when not made. */
  double *tris;
  uint32_t tris_n;
} ray_target;

/* Read the optional `target` property: a 3-vector is a point target, a
 * nested or referenced shape a shape target; anything else is an error
 * (Mitsuba: "Unsupported 'target' parameter type"). */
rsw_status sensor_read_target(loader *ld, node *n, ray_target *t);

/* Checks that need the finished scene: a shape target must have a finite,
 * positive area (the weight divides by it). `where` names the sensor. */
rsw_status ray_target_check(const ray_target *t, const char *where, rsw_err *err);

/* Set the scene (each sensor's set_scene). In a periodic scene (infinite
 * canopy) "outside the scene" means outside the geometry's slab, which
 * the bounding sphere of one column does not ensure; unless the sensor's
 * ray_offset was given explicitly (explicit_offset: used as given),
 * ray_target_origin then (issue 11):
 *   point, shape: moves the origin further back along -d until it lies
 *     outside the slab (exact: nothing lies there), when offset does not;
 *   none: samples the cell [min, max] uniformly on the slab's face that
 *     d enters through (exact average over the infinite canopy, which a
 *     disk of radius R is not), origin just outside it; weight 1. A
 *     horizontal d keeps the disk.
 * Without a periodic boundary nothing changes. A shape target's world
 * triangles are made here too (its to_world and vertices only change in
 * updates, after which set_scene runs again). */
void ray_target_bind(ray_target *t, const scene *sc, bool explicit_offset);
/* Frees what ray_target_bind made (the sensor's destroy). */
void ray_target_release(ray_target *t);

/* Origin of a ray with unit direction d (pointing into the scene) for the
 * aperture sample u; returns the ray weight (eradiate/mitsuba3
 * src/eradiate_plugins/sensors/hdistant.cpp, mitsuba3 src/sensors/distant.cpp):
 *   point:  o = p - offset d,                         weight 1
 *   shape:  ps = sample_position(u), o = ps.p - offset d,
 *           weight 1 / (ps.pdf * area)   (= 1 for uniform area sampling)
 *   none:   q = square_to_disk_concentric(u),
 *           o = c + R to_world (q.x, q.y, 0) - offset d,   weight 1
 * so without a target the origins fill the disk of radius R around the
 * bounding-sphere centre c in the plane orthogonal to the sensor axis
 * to_world (0,0,1), shifted back by offset. */
double ray_target_origin(const ray_target *t, const xform *to_world, vec3 center, double radius,
                         double offset, vec3 d, vec2 u, vec3 *o);

/* ray_target_origin for n rays of unit directions rays[i].d and aperture
 * samples u[i], into rays[i].o and w[i], bit for bit: a mesh target
 * without the periodic slab in one loop, else one call a ray. */
void ray_target_origins(const ray_target *t, const xform *to_world, vec3 center, double radius, double offset,
                        int n, const vec2 *u, ray3 *rays, double *w);

/* Read a string property of 3N numbers separated by commas and/or white
 * space (Eradiate's mdistant `directions`, mradiancemeter `origins`) into
 * *out (malloc'ed, N entries, caller frees). Error when it is absent,
 * empty, not numbers, or not a multiple of 3 long. */
rsw_status sensor_read_vec3_list(loader *ld, node *n, const char *name, vec3 **out, size_t *count);

/* Viewing angles of an exitant direction w (unit, world or local), in
 * degrees, Eradiate's east-right convention: zenith acos(w.z), azimuth
 * atan2(w.y, w.x) wrapped to [0, 360). */
void direction_angles(vec3 w, double *zenith, double *azimuth);

/* pixel_angles of the hemispherical films (hdistant, distantflux): each
 * pixel's angles from the LOCAL vector square_to_uniform_hemisphere at its
 * centre ((ix + 0.5)/W, (iy + 0.5)/H), as Eradiate's post-processing does
 * (eradiate src/eradiate/warp.py; docs/kernel-conventions.md#viewing-angles). */
void hemisphere_pixel_angles(int W, int H, double *zen_az);

/* ---- the hemispherical sensors' shared parameters (hdistant, distantflux) --
 * Mitsuba does not expose these sensors' transforms; we do, with the
 * `direction` convenience key (the hemisphere axis, pointing away from the
 * scene). Setting the axis keeps the film's azimuthal orientation: the new
 * local +x is the old one projected onto the plane orthogonal to the axis
 * (for an axis along the old +x, Eradiate's rule with orientation 0:
 * up = cross(D, +x), then coordinate_system()). Neither is geometric. */
struct param_visitor;
vec3 sensor_axis_get(const object *o);
void sensor_axis_set(object *o, vec3 dir);
/* to_world must map +z to a non-zero vector. */
rsw_status sensor_check_axis_xf(const object *o, const xform *t, const char *key, rsw_err *err);
/* pv_transform("to_world") + pv_vector("direction") for a sensor. */
void sensor_traverse_axis(object *o, struct param_visitor *v);
/* The default ray_offset (Eradiate's set_scene): R without a target, 2R
 * with one; a given value (>= 0) wins. */
double sensor_ray_offset(const ray_target *t, double param, double radius);

/* What a radiancemeter's ray origin depends on in the scene (set at
 * set_scene by meter_frame_bind): Embree's frame origin (accel_origin())
 * and the periodic boundary, if any. */
typedef struct meter_frame {
  vec3 origin;
  periodic_bounds slab;
} meter_frame;
void meter_frame_bind(meter_frame *f, const scene *sc);

/* Ray origin of a radiancemeter at o looking along unit d: o, first
 * brought into the periodic column (periodic scenes: exact, and what
 * scene_trace does anyway), nudged along d by Mitsuba's RayEpsilon, or,
 * where Embree's float32 frame (centred on f->origin) is coarser there,
 * by RSW_SPAWN_ERRORS times its rounding error along d, so that a meter
 * lying on a surface does not see that surface whatever the scene's size;
 * unchanged by a translation of the whole scene. The nudge is sized by
 * the wrapped origin: an origin many periods away from the column is
 * traced from inside it, where the float error is that of the column. */
vec3 radiancemeter_ray_origin(vec3 o, vec3 d, const meter_frame *f);

/* hdistant's rays for n film samples without a target (hdistant,
 * distantflux): the double lanes of sensors/sensor_common_lanes.h at the render's
 * ISA, bit for bit hdistant_sample_ray()'s directions and origins on the
 * disk of `radius` around `center`, pushed back by `offset`. */
void hemisphere_rays_batch(const sensor *s, vec3 center, double radius, double offset, int n,
                           const vec2 *film_u, const vec2 *aperture_u, ray3 *rays);

/* The distant family's ray origins without a target (distant, mdistant;
 * sensors/sensor_common_lanes.h, double lanes at `isa`, bitwise
 * ray_target_origin()): frame rows m9 (9 per lane, m_step 9; or shared,
 * m_step 0), d 3 per lane (d_step 3) or shared (0), ap 2 per lane; out 3
 * per lane. */
void disk_origins_batch(rsw_isa isa, int n, const double *m9, int m_step, const double *d, int d_step,
                        const double *ap, const double *center, double radius, double offset, double *out);

#endif
