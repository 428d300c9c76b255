/* `area`: a diffuse emitter on its shape's front side (the side its normal
 * points to), radiance W m^-2 sr^-1 [nm^-1] (mitsuba3 src/emitters/area.cpp).
 *
 * Next-event estimation samples a point uniformly on the shape's area and
 * converts the density to solid angle at the reference point:
 * pdf_omega = pdf_A dist^2 / |cos theta_e|, with cos theta_e between the
 * emitter normal and the direction back to the reference point.
 *
 * The shape's world-space triangles (vertex, edges, unit normal) are
 * computed once per load and per geometric update (set_scene runs after
 * both, scene_refresh_bounds), not per sample; without them (a mesh above
 * SHAPE_TRIS_MAX faces, or no memory) each sample makes its triangle with
 * the same code, so the result is the same bit for bit. */
#include <stdlib.h>

#include "../scene/plugin_def.h"
#include "../shapes/shape.h"
#include "../textures/texture.h"

typedef struct area_light {
  emitter base;
  texture *radiance;
  double *tris;    /* world triangles of base.shape (owned), or NULL */
  uint32_t tris_n; /* faces they were made for (entries: SHAPE_TRI_DOUBLES each) */
} area_light;

static void area_set_scene(emitter *e, const scene *sc) {
  (void)sc;
  area_light *a = (area_light *)e;
  shape_world_tris_refresh(e->shape, &a->tris, &a->tris_n);
}

static color area_sample(const emitter *e, const surface_interaction *ref, vec2 u, direction_sample *ds) {
  const area_light *a = (const area_light *)e;
  position_sample ps =
      shape_sample_position_tris(e->shape, u, shape_world_tris_for(e->shape, a->tris, a->tris_n));
  vec3 d = v3_sub(ps.p, ref->p);
  double dist2 = v3_len2(d);
  double dist = sqrt(dist2);
  ds->p = ps.p;
  ds->n = ps.n;
  ds->delta = false;
  ds->pdf = 0;
  if (!(dist > 0)) return col1(0);
  ds->d = v3_scale(d, 1.0 / dist);
  ds->dist = dist;
  double cos_e = -v3_dot(ds->d, ps.n); /* > 0: the front side faces ref */
  if (!(cos_e > 0)) return col1(0);
  ds->pdf = ps.pdf * dist2 / cos_e;
  surface_interaction at = {.p = ps.p, .uv = {ps.uv[0], ps.uv[1]}, .shape = e->shape};
  return col_scale(tex_eval(a->radiance, &at), 1.0 / ds->pdf);
}

static double area_pdf(const emitter *e, const surface_interaction *ref, const direction_sample *ds) {
  double cos_e = -v3_dot(ds->d, ds->n);
  if (!(cos_e > 0)) return 0.0;
  return shape_pdf_position(e->shape) * ds->dist * ds->dist / cos_e;
}

static color area_eval(const emitter *e, const surface_interaction *hit, vec3 d) {
  const area_light *a = (const area_light *)e;
  (void)d;
  if (!(hit->wi.z > 0)) return col1(0); /* back side: Mitsuba tests Frame::cos_theta(si.wi) > 0 */
  return tex_eval(a->radiance, hit);
}

static const emitter_ops area_ops = {.sample_direction = area_sample,
                                     .pdf_direction = area_pdf,
                                     .eval = area_eval,
                                     .set_scene = area_set_scene};

static void area_destroy(object *o) {
  if (o) free(((area_light *)o)->tris);
  free(o);
}

static rsw_status area_create(loader *ld, node *n, object **out) {
  area_light *a = calloc(1, sizeof *a);
  if (!a) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "out of memory");
  a->base.ops = &area_ops;
  a->base.flags = EMITTER_SURFACE;
  rsw_status st = ld_float_range(ld, n, "sampling_weight", 1.0, 0.0, INFINITY, &a->base.sampling_weight);
  if (!st) st = ld_texture(ld, n, "radiance", 1.0, 0.0, &a->radiance);
  if (st) {
    free(a);
    return st;
  }
  *out = &a->base.base;
  return RSW_OK;
}

static void area_traverse(object *o, param_visitor *v) {
  area_light *a = (area_light *)o;
  pv_object(v, "radiance", &a->radiance->base, 0.0, INFINITY);
  pv_float(v, "sampling_weight", &a->base.sampling_weight, UPDATE_SPECTRAL, 0.0, INFINITY);
}

DEFINE_PLUGIN(area, CLS_EMITTER, .destroy = area_destroy, .ops = &area_ops, .traverse = area_traverse);
