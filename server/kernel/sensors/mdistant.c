/* `mdistant`: multi-direction distant radiancemeter (Eradiate plugin,
 * eradiate/mitsuba3 src/eradiate_plugins/sensors/mdistant.cpp;
 * docs/kernel-conventions.md#mdistant-and-mradiancemeter).
 *
 * N sub-sensors, one per triple of the `directions` string; each triple is
 * the direction that sub-sensor looks (into the scene; Eradiate passes the
 * negated viewing directions). The film is N x 1 and pixel i is sub-sensor
 * i = floor(u.x N): its rays travel along d_i = normalize(dir_i) and it
 * records the radiance leaving along -d_i (W m^-2 sr^-1 [nm^-1]).
 * Sub-sensor i's frame is look_at(0, d_i, up) with up the FIRST vector of
 * coordinate_system(d_i); it only orients the no-target disk, which is thus
 * orthogonal to d_i. Targets and ray_offset as hdistant (default offset R
 * without a target, 2R with one). There is no to_world; the parameter
 * `directions` (3 N numbers) sets the directions, frames following. */
#include <math.h>
#include <stdlib.h>

#include "../scene/params.h"
#include "../scene/plugin_def.h"
#include "sensor_common.h"

typedef struct mdistant {
  sensor base;
  ray_target target;
  size_t n;
  vec3 *d;                 /* n unit directions, into the scene */
  xform *frames;           /* n: look_at(0, d_i, first vector of coordinate_system) */
  double ray_offset_param; /* as given; < 0: resolve from the scene */
  double ray_offset;
  vec3 center;
  double radius;
} mdistant;

static size_t mdistant_index(const mdistant *m, double ux) {
  double f = floor(ux * (double)m->n);
  if (!(f >= 0.0)) return 0;
  return f >= (double)m->n ? m->n - 1 : (size_t)f;
}

static double mdistant_sample_ray(const sensor *s, vec2 film_u, vec2 aperture_u, ray3 *ray) {
  const mdistant *m = (const mdistant *)s;
  size_t i = mdistant_index(m, film_u.x);
  vec3 o;
  double w = ray_target_origin(&m->target, &m->frames[i], m->center, m->radius, m->ray_offset, m->d[i],
                               aperture_u, &o);
  ray->o = o;
  ray->d = m->d[i];
  ray->tmin = 0.0;
  ray->tmax = INFINITY;
  return w;
}

/* Batched rays (sensor_ops.sample_ray_batch): without a target or a
 * periodic slab, each lane's sub-sensor picked as mdistant_sample_ray()
 * does, its frame and direction gathered, and the origins on the bounding
 * disk in double lanes (sensors/sensor_common_lanes.h disk_origins): bit for bit the
 * scalar rays. Otherwise one by one. */
static void mdistant_sample_ray_batch(const sensor *s, int n, const vec2 *film_u, const vec2 *aperture_u,
                                      ray3 *rays, double *w) {
  const mdistant *md = (const mdistant *)s;
  if (md->target.kind != RAY_TARGET_NONE || md->target.slab.on) {
    for (int i = 0; i < n; i++) w[i] = mdistant_sample_ray(s, film_u[i], aperture_u[i], &rays[i]);
    return;
  }
  enum {
    C = 64
  };
  double m9[9 * C], d[3 * C], ap[2 * C], out[3 * C], c[3] = {md->center.x, md->center.y, md->center.z};
  size_t idx[C];
  rsw_isa isa = rsw_isa_get();
  for (int i0 = 0; i0 < n; i0 += C) {
    int cnt = n - i0 < C ? n - i0 : C;
    for (int k = 0; k < cnt; k++) {
      size_t i = idx[k] = mdistant_index(md, film_u[i0 + k].x);
      const double(*m)[4] = md->frames[i].m;
      for (int r = 0; r < 3; r++)
        for (int q = 0; q < 3; q++) m9[9 * k + 3 * r + q] = m[r][q];
      d[3 * k] = md->d[i].x, d[3 * k + 1] = md->d[i].y, d[3 * k + 2] = md->d[i].z;
      ap[2 * k] = aperture_u[i0 + k].x, ap[2 * k + 1] = aperture_u[i0 + k].y;
    }
    disk_origins_batch(isa, cnt, m9, 9, d, 3, ap, c, md->radius, md->ray_offset, out);
    for (int k = 0; k < cnt; k++) {
      ray3 *r = &rays[i0 + k];
      r->o = v3(out[3 * k], out[3 * k + 1], out[3 * k + 2]);
      r->d = md->d[idx[k]];
      r->tmin = 0.0;
      r->tmax = INFINITY;
      w[i0 + k] = 1.0;
    }
  }
}

static rsw_status mdistant_set_scene(sensor *s, const scene *sc, rsw_err *err) {
  mdistant *m = (mdistant *)s;
  rsw_status st = ray_target_check(&m->target, s->base.id, err);
  if (st != RSW_OK) return st;
  ray_target_bind(&m->target, sc, m->ray_offset_param >= 0.0);
  m->center = sc->bsphere_center; /* radius already inflated (kernel.h) */
  m->radius = sc->bsphere_radius;
  if (m->ray_offset_param < 0.0)
    m->ray_offset = m->target.kind == RAY_TARGET_NONE ? m->radius : 2.0 * m->radius;
  else
    m->ray_offset = m->ray_offset_param;
  return RSW_OK;
}

/* Pixel ix is sub-sensor floor((ix + 0.5) N / W) = ix (W = N); its
 * exitant direction is -d_i, in world coordinates. */
static void mdistant_pixel_angles(const sensor *s, int W, int H, double *zen_az) {
  const mdistant *m = (const mdistant *)s;
  for (int iy = 0; iy < H; iy++)
    for (int ix = 0; ix < W; ix++) {
      size_t i = 2 * ((size_t)iy * W + (size_t)ix);
      size_t k = mdistant_index(m, (ix + 0.5) / W);
      direction_angles(v3_neg(m->d[k]), &zen_az[i], &zen_az[i + 1]);
    }
}

static const sensor_ops mdistant_ops = {
    .sample_ray = mdistant_sample_ray,
    .set_scene = mdistant_set_scene,
    .pixel_angles = mdistant_pixel_angles,
    .sample_ray_batch = mdistant_sample_ray_batch,
};

static void mdistant_destroy(object *o) {
  mdistant *m = (mdistant *)o;
  if (!m) return;
  ray_target_release(&m->target);
  free(m->d);
  free(m->frames);
  free(m);
}

/* Sub-sensor i's frame from its direction (normalised in place). False
 * when the direction is the zero vector or no frame can be built. */
static bool mdistant_frame(mdistant *m, size_t i) {
  if (!(v3_len(m->d[i]) > 0.0)) return false;
  m->d[i] = v3_norm(m->d[i]);
  vec3 up, unused;
  coordinate_system(m->d[i], &up, &unused);
  return xf_look_at(v3(0, 0, 0), m->d[i], up, &m->frames[i]);
}

/* No direction of an update may be the zero vector (or too short to
 * normalise): checked before anything is written. */
static rsw_status mdistant_check_directions(const object *o, const double *v, size_t n, const char *key,
                                            rsw_err *err) {
  (void)o;
  for (size_t i = 0; i + 2 < n; i += 3)
    if (!(v3_len(v3(v[i], v[i + 1], v[i + 2])) > 0.0))
      return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': direction %zu is the zero vector", key, i / 3);
  return RSW_OK;
}

/* `directions`: the N directions as 3 N numbers (the film's width fixes
 * N), the key viewing-angle templates write (docs/experiments.md); a
 * spectral update: the frames follow (parameters_changed). Eradiate sets
 * them from angles the same way (MultiDistantMeasure). */
static void mdistant_traverse(object *o, param_visitor *v) {
  mdistant *m = (mdistant *)o;
  pv_buffer(v, "directions", &m->d[0].x, 3 * m->n, UPDATE_SPECTRAL, -INFINITY, INFINITY,
            mdistant_check_directions);
}

static void mdistant_parameters_changed(object *o) {
  mdistant *m = (mdistant *)o;
  for (size_t i = 0; i < m->n; i++) (void)mdistant_frame(m, i); /* checked non-zero */
}

DEFINE_PLUGIN(mdistant, CLS_SENSOR, .destroy = mdistant_destroy, .traverse = mdistant_traverse,
              .parameters_changed = mdistant_parameters_changed, .ops = &mdistant_ops);

static rsw_status mdistant_read(loader *ld, node *n, mdistant *m) {
  if (ld_has(n, "to_world"))
    return ld_fail(ld, n, "to_world", RSW_ERR_INVALID,
                   "mdistant: 'to_world' is not supported (orientation comes from 'directions')");
  rsw_status st = sensor_read_base(ld, n, &m->base);
  if (st != RSW_OK) return st;
  st = sensor_read_vec3_list(ld, n, "directions", &m->d, &m->n);
  if (st != RSW_OK) return st;
  if (m->base.film->width < 0 || (size_t)m->base.film->width != m->n || m->base.film->height != 1)
    return ld_fail(ld, n, "film", RSW_ERR_INVALID,
                   "mdistant: the film must be %zu x 1 pixels, one per direction (got %dx%d)", m->n,
                   m->base.film->width, m->base.film->height);
  m->frames = malloc(m->n * sizeof *m->frames);
  if (!m->frames) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  for (size_t i = 0; i < m->n; i++) {
    if (!(v3_len(m->d[i]) > 0.0))
      return ld_fail(ld, n, "directions", RSW_ERR_INVALID, "mdistant: direction %zu is the zero vector", i);
    if (!mdistant_frame(m, i))
      return ld_fail(ld, n, "directions", RSW_ERR_INVALID, "mdistant: cannot build a frame for direction %zu",
                     i);
  }
  st = sensor_read_target(ld, n, &m->target);
  if (st != RSW_OK) return st;
  st = ld_float(ld, n, "ray_offset", -1.0, &m->ray_offset_param);
  if (st != RSW_OK) return st;
  m->ray_offset = m->ray_offset_param;
  return RSW_OK;
}

static rsw_status mdistant_create(loader *ld, node *n, object **out) {
  mdistant *m = PLUGIN_NEW(mdistant, mdistant);
  if (!m) return plugin_created(ld, n, NULL, out);
  m->base.ops = &mdistant_ops;
  m->base.to_world = xf_identity();
  rsw_status st = mdistant_read(ld, n, m);
  if (st != RSW_OK) {
    mdistant_destroy(&m->base.base);
    return st;
  }
  return plugin_created(ld, n, &m->base.base, out);
}
