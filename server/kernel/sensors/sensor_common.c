#include "sensor_common.h"

#include "../scene/params.h"

#include <ctype.h>
#include <math.h>
#include <stddef.h>
#include <stdlib.h>

#include "../accel.h"
#include "../scene/periodic.h"
#include "../scene/scene.h"
#include "../shapes/shape.h"
#include "sensor_common_lanes.h"

/* The nested object of class cls, or a default instance of `def_type`
 * when the document gives none (mitsuba3 src/render/sensor.cpp creates an
 * hdrfilm and an independent sampler the same way). */
static rsw_status child_or_default(loader *ld, node *n, obj_class cls, const char *def_type,
                                   const char *def_id, object **out) {
  object *o = NULL;
  rsw_status st = ld_child(ld, n, NULL, cls, &o);
  if (st != RSW_OK) return st;
  if (!o) {
    st = ld_create_default(ld, def_type, cls, def_id, &o);
    if (st != RSW_OK) return st;
  }
  if (!o || o->plugin == NULL || o->plugin->cls != cls)
    return ld_fail(ld, n, NULL, RSW_ERR_TYPE, "%s: expected a %s", n->type, obj_class_name(cls));
  *out = o;
  return RSW_OK;
}

rsw_status sensor_read_base(loader *ld, node *n, sensor *s) {
  object *f = NULL, *smp = NULL;
  rsw_status st = child_or_default(ld, n, CLS_FILM, "hdrfilm", "film", &f);
  if (st != RSW_OK) return st;
  st = child_or_default(ld, n, CLS_SAMPLER, "independent", "sampler", &smp);
  if (st != RSW_OK) return st;
  object *med = NULL;
  st = ld_child(ld, n, "medium", CLS_MEDIUM, &med);
  if (st != RSW_OK) return st;
  s->medium = (struct medium *)med;

  /* Mitsuba: shutter_open (0), shutter_close (0), the open time must not be
   * negative. Nothing in a scene moves, so the values change nothing. */
  double open = 0, close = 0;
  st = ld_float(ld, n, "shutter_open", 0.0, &open);
  if (st != RSW_OK) return st;
  st = ld_float(ld, n, "shutter_close", 0.0, &close);
  if (st != RSW_OK) return st;
  if (close < open)
    return ld_fail(ld, n, "shutter_close", RSW_ERR_RANGE,
                   "%s: shutter_close (%g) is before shutter_open (%g)", n->type, close, open);

  s->film = (film *)f;
  s->sampler = (sampler *)smp;
  return RSW_OK;
}

rsw_status sensor_require_1x1_film(loader *ld, node *n, const sensor *s) {
  if (s->film->width != 1 || s->film->height != 1)
    return ld_fail(ld, n, NULL, RSW_ERR_INVALID,
                   "%s: this sensor only supports films of 1x1 pixels (got %dx%d)", n->type, s->film->width,
                   s->film->height);
  return RSW_OK;
}

rsw_status sensor_read_target(loader *ld, node *n, ray_target *t) {
  ray_target r = {.kind = RAY_TARGET_NONE};
  prop *p = node_find(n, "target");
  if (p) {
    if (p->kind == PROP_VEC3) {
      rsw_status st = ld_vec3(ld, n, "target", v3(0, 0, 0), &r.point, NULL);
      if (st != RSW_OK) return st;
      r.kind = RAY_TARGET_POINT;
    } else if (p->kind == PROP_NODE || p->kind == PROP_REF) {
      object *o = NULL;
      rsw_status st = ld_child(ld, n, "target", CLS_SHAPE, &o);
      if (st != RSW_OK) return st;
      if (!o)
        return ld_fail(ld, n, "target", RSW_ERR_TYPE, "%s: 'target' must be a point or a shape", n->type);
      r.kind = RAY_TARGET_SHAPE;
      r.shape = (const shape *)o;
      st = shape_enable_sampling((shape *)o, ld->err, n->loc);
      if (st != RSW_OK) return st;
    } else {
      return ld_fail(ld, n, "target", RSW_ERR_TYPE,
                     "%s: unsupported 'target' type (must be a point or a shape)", n->type);
    }
  }
  *t = r;
  return RSW_OK;
}

rsw_status ray_target_check(const ray_target *t, const char *where, rsw_err *err) {
  if (t->kind != RAY_TARGET_SHAPE) return RSW_OK;
  double a = t->shape->area;
  if (!(a > 0.0) || !isfinite(a))
    return rsw_fail(err, RSW_ERR_INVALID, where, "target shape '%s' has no usable surface area (%g)",
                    t->shape->base.id ? t->shape->base.id : "?", a);
  return RSW_OK;
}

void ray_target_bind(ray_target *t, const scene *sc, bool explicit_offset) {
  t->slab = sc->periodic;
  if (explicit_offset) t->slab.on = false;
  if (t->kind == RAY_TARGET_SHAPE) shape_world_tris_refresh(t->shape, &t->tris, &t->tris_n);
}

void ray_target_release(ray_target *t) {
  free(t->tris);
  t->tris = NULL;
  t->tris_n = 0;
}

/* The offset, raised (periodic scenes) to put p - offset d outside the
 * slab. */
static double slab_offset(const ray_target *t, vec3 p, vec3 d, double offset) {
  return t->slab.on ? fmax(offset, periodic_slab_offset(&t->slab, p, d)) : offset;
}

double ray_target_origin(const ray_target *t, const xform *to_world, vec3 center, double radius,
                         double offset, vec3 d, vec2 u, vec3 *o) {
  switch (t->kind) {
  case RAY_TARGET_POINT: *o = v3_fma(t->point, -slab_offset(t, t->point, d, offset), d); return 1.0;
  case RAY_TARGET_SHAPE: {
    position_sample ps =
        shape_sample_position_tris(t->shape, u, shape_world_tris_for(t->shape, t->tris, t->tris_n));
    *o = v3_fma(ps.p, -slab_offset(t, ps.p, d, offset), d);
    double denom = ps.pdf * t->shape->area;
    return denom > 0.0 ? 1.0 / denom : 0.0;
  }
  case RAY_TARGET_NONE:
  default: {
    const periodic_bounds *b = &t->slab;
    if (b->on && d.z != 0.0) {
      vec3 p = v3(b->min[0] + u.x * (b->max[0] - b->min[0]), b->min[1] + u.y * (b->max[1] - b->min[1]),
                  d.z < 0.0 ? b->zmax : b->zmin);
      *o = v3_fma(p, -periodic_slab_offset(b, p, d), d);
      return 1.0;
    }
    vec2 q = warp_square_to_disk_concentric(u);
    vec3 perp = xf_vector(to_world, v3(q.x, q.y, 0.0));
    *o = v3_fma(v3_fma(center, radius, perp), -offset, d);
    return 1.0;
  }
  }
}

void ray_target_origins(const ray_target *t, const xform *to_world, vec3 center, double radius, double offset,
                        int n, const vec2 *u, ray3 *rays, double *w) {
  const shape *s = t->shape;
  const double *tris = t->kind == RAY_TARGET_SHAPE ? shape_world_tris_for(s, t->tris, t->tris_n) : NULL;
  if (!(tris && shape_is_mesh(s) && !t->slab.on)) {
    for (int i = 0; i < n; i++)
      w[i] = ray_target_origin(t, to_world, center, radius, offset, rays[i].d, u[i], &rays[i].o);
    return;
  }
  /* A mesh target: its position samples in one loop, the weight (the same
   * for every lane: pdf = 1 / area) once. */
  double denom = (1.0 / s->area) * s->area;
  double wt = denom > 0.0 ? 1.0 / denom : 0.0;
  for (int i = 0; i < n; i++) {
    position_sample ps;
    mesh_sample_inline(s, u[i], tris, &ps);
    rays[i].o = v3_fma(ps.p, -offset, rays[i].d);
    w[i] = wt;
  }
}

rsw_status sensor_read_vec3_list(loader *ld, node *n, const char *name, vec3 **out, size_t *count) {
  const char *text = NULL;
  rsw_status st = ld_string(ld, n, name, NULL, &text);
  if (st != RSW_OK) return st;
  if (!text)
    return ld_fail(ld, n, name, RSW_ERR_MISSING, "%s: '%s' is required (a string of 3N numbers)", n->type,
                   name);
  size_t cap = 16, k = 0;
  double *v = malloc(cap * sizeof *v);
  if (!v) return ld_fail(ld, n, name, RSW_ERR_NOMEM, "out of memory");
  const char *p = text;
  for (;;) {
    while (*p == ',' || isspace((unsigned char)*p)) p++;
    if (!*p) break;
    char *end = NULL;
    double x = strtod(p, &end);
    if (end == p || !isfinite(x)) {
      free(v);
      return ld_fail(ld, n, name, RSW_ERR_INVALID,
                     "%s: '%s': entry %zu is not a finite number (near \"%.20s\")", n->type, name, k, p);
    }
    if (k == cap) {
      cap *= 2;
      double *nv = realloc(v, cap * sizeof *v);
      if (!nv) {
        free(v);
        return ld_fail(ld, n, name, RSW_ERR_NOMEM, "out of memory");
      }
      v = nv;
    }
    v[k++] = x;
    p = end;
  }
  if (k == 0 || k % 3 != 0) {
    free(v);
    return ld_fail(ld, n, name, RSW_ERR_INVALID, "%s: '%s' must hold 3N numbers, N >= 1 (got %zu)", n->type,
                   name, k);
  }
  vec3 *r = malloc(k / 3 * sizeof *r);
  if (!r) {
    free(v);
    return ld_fail(ld, n, name, RSW_ERR_NOMEM, "out of memory");
  }
  for (size_t i = 0; i < k / 3; i++) r[i] = v3(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
  free(v);
  *out = r;
  *count = k / 3;
  return RSW_OK;
}

void direction_angles(vec3 w, double *zenith, double *azimuth) {
  const double deg = 180.0 / 3.14159265358979323846;
  double z = w.z > 1.0 ? 1.0 : (w.z < -1.0 ? -1.0 : w.z);
  double phi = atan2(w.y, w.x) * deg;
  if (phi < 0.0) phi += 360.0;
  if (phi >= 360.0) phi -= 360.0;
  *zenith = acos(z) * deg;
  *azimuth = phi + 0.0; /* atan2(-0, x) is -0: printed "-0" */
}

void hemisphere_pixel_angles(int W, int H, double *zen_az) {
  for (int iy = 0; iy < H; iy++)
    for (int ix = 0; ix < W; ix++) {
      vec3 v = warp_square_to_uniform_hemisphere(v2((ix + 0.5) / W, (iy + 0.5) / H));
      size_t i = 2 * ((size_t)iy * W + (size_t)ix);
      direction_angles(v, &zen_az[i], &zen_az[i + 1]);
    }
}

vec3 sensor_axis_get(const object *o) {
  return v3_norm(xf_vector(&((const sensor *)o)->to_world, v3(0, 0, 1)));
}

void sensor_axis_set(object *o, vec3 dir) {
  sensor *s = (sensor *)o;
  vec3 dn = v3_norm(dir);
  vec3 x_old = v3_norm(xf_vector(&s->to_world, v3(1, 0, 0)));
  vec3 up = v3_cross(dn, x_old);
  if (!(v3_len(up) > 1e-9)) up = v3_cross(dn, v3(1, 0, 0));
  if (!(v3_len(up) > 1e-9)) {
    vec3 unused;
    coordinate_system(dn, &unused, &up);
  }
  xform t;
  if (xf_look_at(v3(0, 0, 0), dn, v3_norm(up), &t)) s->to_world = t;
}

rsw_status sensor_check_axis_xf(const object *o, const xform *t, const char *key, rsw_err *err) {
  (void)o;
  vec3 d = xf_vector(t, v3(0, 0, 1));
  if (!(v3_len(d) > 0.0) || !v3_finite(d))
    return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': to_world maps +z to a zero vector", key);
  return RSW_OK;
}

void sensor_traverse_axis(object *o, param_visitor *v) {
  sensor *s = (sensor *)o;
  pv_transform(v, "to_world", &s->to_world, UPDATE_SPECTRAL, sensor_check_axis_xf);
  pv_vector(v, "direction", sensor_axis_get, sensor_axis_set, UPDATE_SPECTRAL);
}

double sensor_ray_offset(const ray_target *t, double param, double radius) {
  if (param >= 0.0) return param;
  return t->kind == RAY_TARGET_NONE ? radius : 2.0 * radius;
}

void meter_frame_bind(meter_frame *f, const scene *sc) {
  f->origin = accel_origin(sc->accel);
  f->slab = sc->periodic;
}

vec3 radiancemeter_ray_origin(vec3 o, vec3 d, const meter_frame *f) {
  o = periodic_wrap_point(&f->slab, o);
  double d1 = fabs(d.x) + fabs(d.y) + fabs(d.z);
  double e = RSW_SPAWN_ERRORS * RSW_F32_UNIT * d1 * v3_max_abs(v3_sub(o, f->origin));
  return v3_fma(o, fmax(RSW_RAY_EPSILON, e), d);
}

uint64_t sensor_film_bytes(const sensor *se, rsw_variant variant, int *channels) {
  const film *fm = se->film;
  /* A Stokes film: the mono variant's or a polarized variant's (rgb:
   * S0..S3 per colour). */
  bool stokes = fm->pixel_format == PIXFMT_STOKES;
  bool lum = !stokes && (variant == VARIANT_MONO || fm->pixel_format == PIXFMT_LUMINANCE);
  int c = stokes ? (variant == VARIANT_MONO ? 4 : 12) : lum ? 1 : 3;
  if (channels) *channels = c;
  /* Mirrors render.c's allocations (accumulator, film, angles) and the
   * encoders' copy of the film and its angles. */
  uint64_t per_pixel = (stokes ? (variant == VARIANT_MONO ? 7u : 13u) : 4u) * 8u + 2u * 4u * (uint64_t)c +
                       (se->ops->pixel_angles ? 2u * 16u : 0u);
  uint64_t pixels = (uint64_t)(fm->width > 0 ? fm->width : 0) * (uint64_t)(fm->height > 0 ? fm->height : 0);
  if (pixels && per_pixel > UINT64_MAX / pixels) return UINT64_MAX;
  return pixels * per_pixel;
}

static void hdistant_rays_batch(rsw_isa isa, int n, const double (*m)[4], const double *fu, const double *ap,
                                const double *center, double radius, double offset, double *out) {
  SIMD_DISPATCH(isa, hdistant_rays, n, m, fu, ap, center, radius, offset, out);
}

void disk_origins_batch(rsw_isa isa, int n, const double *m9, int m_step, const double *d, int d_step,
                        const double *ap, const double *center, double radius, double offset, double *out) {
  SIMD_DISPATCH(isa, disk_origins, n, m9, m_step, d, d_step, ap, center, radius, offset, out);
}

void hemisphere_rays_batch(const sensor *s, vec3 center, double radius, double offset, int n,
                           const vec2 *film_u, const vec2 *aperture_u, ray3 *rays) {
  /* A vec2 array is the lanes' interleaved (x, y) and a ray3 array their
   * output layout: no copies on either side. */
  _Static_assert(sizeof(vec2) == 2 * sizeof(double) && sizeof(ray3) == 8 * sizeof(double) &&
                     offsetof(ray3, d) == 3 * sizeof(double) && offsetof(ray3, tmin) == 6 * sizeof(double),
                 "vec2 and ray3 as the hdistant lanes lay them out");
  if (n <= 0) return;
  double c[3] = {center.x, center.y, center.z};
  hdistant_rays_batch(rsw_isa_get(), n, (const double(*)[4])s->to_world.m, &film_u[0].x, &aperture_u[0].x, c,
                      radius, offset, &rays[0].o.x);
}
