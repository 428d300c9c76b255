/* Clip distances and a rigid to_world for projective cameras
 * (sensors/projective.h). */
#include "projective.h"

#include <math.h>

rsw_status projective_read(loader *ld, node *n, const sensor *s, projective *out) {
  out->aspect = (double)s->film->width / (double)s->film->height;
  rsw_status st = ld_float(ld, n, "near_clip", 1e-2, &out->near_clip);
  if (!st) st = ld_float(ld, n, "far_clip", 1e4, &out->far_clip);
  if (st) return st;
  if (!(out->near_clip > 0.0))
    return ld_fail(ld, n, "near_clip", RSW_ERR_RANGE, "'near_clip' must be greater than zero");
  if (!(out->near_clip < out->far_clip))
    return ld_fail(ld, n, "near_clip", RSW_ERR_RANGE, "'near_clip' must be smaller than 'far_clip'");
  return ld_float(ld, n, "focus_distance", out->far_clip, &out->focus_distance);
}

static bool rigid(const xform *t) {
  double scale;
  return xf_is_similarity(t, &scale) && fabs(scale - 1.0) <= 1e-4;
}

rsw_status projective_read_rigid(loader *ld, node *n, xform *out) {
  rsw_status st = ld_transform(ld, n, "to_world", out, NULL);
  if (st) return st;
  if (!rigid(out))
    return ld_fail(ld, n, "to_world", RSW_ERR_INVALID, "scale factors in 'to_world' are not allowed");
  return RSW_OK;
}

rsw_status projective_check_rigid(const object *o, const xform *t, const char *key, rsw_err *err) {
  (void)o;
  if (!rigid(t))
    return rsw_fail(err, RSW_ERR_INVALID, key, "'%s': a camera's to_world must be a rotation and translation",
                    key);
  return RSW_OK;
}
