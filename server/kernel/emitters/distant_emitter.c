/* distant_emitter.h: the properties `directional` and `astroobject`
 * share (mitsuba3 src/emitters/directional.cpp; eradiate/mitsuba3
 * src/eradiate_plugins/emitters/astroobject.cpp). */
#include "distant_emitter.h"

#include <math.h>

#include "../scene/loader.h"
#include "../textures/texture.h"

bool distant_look_at(vec3 d, xform *out) {
  vec3 dn = v3_norm(d), up, unused;
  coordinate_system(dn, &up, &unused);
  return xf_look_at(v3(0, 0, 0), dn, up, out);
}

rsw_status distant_emitter_read(loader *ld, node *n, emitter *e, texture **irradiance, xform *to_world) {
  rsw_status st = ld_float_range(ld, n, "sampling_weight", 1.0, 0.0, INFINITY, &e->sampling_weight);
  if (!st) st = ld_texture(ld, n, "irradiance", 1.0, 0.0, irradiance);
  color tmp;
  if (!st && !uniform_texture_value(*irradiance, &tmp))
    st = ld_fail(ld, n, "irradiance", RSW_ERR_INVALID,
                 "irradiance must not vary spatially (give a number, rgb or spectrum, not a texture)");
  bool has_dir = false, has_xf = false;
  vec3 d;
  if (!st) st = ld_vec3(ld, n, "direction", v3(0, 0, 1), &d, &has_dir);
  if (!st) st = ld_transform(ld, n, "to_world", to_world, &has_xf);
  if (!st && has_dir && has_xf)
    st = ld_fail(ld, n, "direction", RSW_ERR_INVALID, "give either 'direction' or 'to_world', not both");
  if (!st && has_dir && !(v3_len(d) > 0))
    st = ld_fail(ld, n, "direction", RSW_ERR_INVALID, "direction must be non-zero");
  if (!st && !has_xf && !distant_look_at(d, to_world))
    st = ld_fail(ld, n, "direction", RSW_ERR_INVALID, "cannot build a frame from 'direction'");
  if (!st && !(v3_len(v3_norm(xf_vector(to_world, v3(0, 0, 1)))) > 0))
    st = ld_fail(ld, n, "to_world", RSW_ERR_INVALID, "to_world maps +z to a zero vector");
  return st;
}
