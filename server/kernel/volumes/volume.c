/* What every volume shares (box, to_world, lists of numbers). ld_volume()
 * (Mitsuba's props.volume()), which makes a constvolume of a constant,
 * lives with the constvolume plugin (volumes/constvolume.c). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../textures/texture.h"
#include "volume.h"

void volume_update_bbox(volume *v) {
  vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
  for (int k = 0; k < 8; k++) {
    vec3 p = xf_point(&v->to_world, v3(k & 1, (k >> 1) & 1, (k >> 2) & 1));
    lo = v3(fmin(lo.x, p.x), fmin(lo.y, p.y), fmin(lo.z, p.z));
    hi = v3(fmax(hi.x, p.x), fmax(hi.y, p.y), fmax(hi.z, p.z));
  }
  v->bbox_min = lo;
  v->bbox_max = hi;
}

void volume_init(volume *v, const volume_ops *ops, const xform *to_world) {
  v->ops = ops;
  v->to_world = *to_world;
  v->lo = -INFINITY;
  v->hi = INFINITY;
  v->box_grid = true;
  volume_update_bbox(v);
}

rsw_status volume_read_to_world(loader *ld, node *n, xform *out) {
  return ld_transform(ld, n, "to_world", out, NULL);
}

void volume_traverse_to_world(volume *v, param_visitor *pv) {
  pv_transform(pv, "to_world", &v->to_world, UPDATE_SPECTRAL, NULL);
}

rsw_status volume_read_numbers(loader *ld, node *n, const char *name, double **out, size_t *count,
                               bool *present) {
  prop *p = node_find(n, name);
  *out = NULL;
  *count = 0;
  if (present) *present = p != NULL;
  if (!p) return RSW_OK;
  size_t k = 0;
  double *x = NULL;
  switch (p->kind) {
  case PROP_NUMBER: k = 1; break;
  case PROP_VEC3: k = 3; break;
  case PROP_NUMBERS: k = p->n_nums; break;
  case PROP_STRING:
    /* Count first, so that one allocation holds them. */
    for (const char *c = p->str; *c;) {
      while (*c == ',' || *c == ' ' || *c == '\t' || *c == '\n' || *c == '\r') c++;
      if (!*c) break;
      k++;
      while (*c && *c != ',' && *c != ' ' && *c != '\t' && *c != '\n' && *c != '\r') c++;
    }
    break;
  default:
    return ld_fail(ld, n, name, RSW_ERR_TYPE,
                   "property '%s' must be a list of numbers (an array, or a string of numbers separated by "
                   "commas or spaces)",
                   name);
  }
  if (k == 0) return ld_fail(ld, n, name, RSW_ERR_INVALID, "property '%s' is empty", name);
  if (k > VOLUME_MAX_VALUES)
    return ld_fail(ld, n, name, RSW_ERR_LIMIT, "property '%s' holds %zu values (at most %zu)", name, k,
                   VOLUME_MAX_VALUES);
  x = malloc(k * sizeof *x);
  if (!x) return ld_fail(ld, n, name, RSW_ERR_NOMEM, "out of memory");
  if (p->kind == PROP_NUMBER) x[0] = p->num;
  if (p->kind == PROP_VEC3) x[0] = p->vec.x, x[1] = p->vec.y, x[2] = p->vec.z;
  if (p->kind == PROP_NUMBERS) memcpy(x, p->nums, k * sizeof *x);
  if (p->kind == PROP_STRING) {
    size_t i = 0;
    for (const char *c = p->str; *c && i < k;) {
      while (*c == ',' || *c == ' ' || *c == '\t' || *c == '\n' || *c == '\r') c++;
      if (!*c) break;
      char *end;
      errno = 0;
      x[i] = strtod(c, &end);
      if (end == c || (*end && *end != ',' && *end != ' ' && *end != '\t' && *end != '\n' && *end != '\r')) {
        int len = 0;
        while (c[len] && c[len] != ',' && c[len] != ' ' && len < 40) len++;
        free(x);
        return ld_fail(ld, n, name, RSW_ERR_PARSE, "property '%s': '%.*s' (value %zu) is not a number", name,
                       len, c, i);
      }
      c = end;
      i++;
    }
  }
  for (size_t i = 0; i < k; i++)
    if (!isfinite(x[i])) {
      free(x);
      return ld_fail(ld, n, name, RSW_ERR_INVALID, "property '%s': value %zu is not finite", name, i);
    }
  p->used = true;
  *out = x;
  *count = k;
  return RSW_OK;
}
