/* Placement and intensity of the delta-position emitters
 * (emitters/delta_position.h; mitsuba3 src/emitters/point.cpp, spot.cpp). */
#include "delta_position.h"

#include "../scene/loader.h"
#include "../textures/texture.h"

double delta_position_pdf(const emitter *e, const surface_interaction *ref, const direction_sample *ds) {
  (void)e, (void)ref, (void)ds;
  return 0.0;
}

color delta_position_eval(const emitter *e, const surface_interaction *hit, vec3 d) {
  (void)e, (void)hit, (void)d;
  return col1(0);
}

void delta_position_set_scene(emitter *e, const scene *s) {
  (void)e, (void)s;
}

void delta_position_move(xform *to_world, vec3 p) {
  double m[4][4];
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++) m[i][j] = to_world->m[i][j];
  m[0][3] = p.x, m[1][3] = p.y, m[2][3] = p.z;
  xform t;
  /* The linear part is unchanged, so the matrix stays invertible. */
  if (xf_from_matrix(m, &t)) *to_world = t;
}

rsw_status delta_position_intensity(loader *ld, node *n, texture **out) {
  texture *t;
  rsw_status st = ld_texture(ld, n, "intensity", 1.0, 0.0, &t);
  if (st) return st;
  color c;
  if (!uniform_texture_value(t, &c))
    return ld_fail(ld, n, "intensity", RSW_ERR_INVALID,
                   "intensity must not vary spatially (give a number, rgb or spectrum, not a texture)");
  *out = t;
  return RSW_OK;
}

rsw_status delta_position_place(loader *ld, node *n, bool allow_position, xform *out) {
  bool has_pos = false, has_xf = false;
  vec3 p = v3(0, 0, 0);
  xform xf = xf_identity();
  rsw_status st = RSW_OK;
  if (allow_position) st = ld_vec3(ld, n, "position", v3(0, 0, 0), &p, &has_pos);
  if (!st) st = ld_transform(ld, n, "to_world", &xf, &has_xf);
  if (st) return st;
  if (has_pos && has_xf)
    return ld_fail(ld, n, "position", RSW_ERR_INVALID, "give either 'position' or 'to_world', not both");
  *out = has_pos ? xf_translate(p) : xf;
  return RSW_OK;
}
