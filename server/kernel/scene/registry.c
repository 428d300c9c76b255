/* The one list of plugins. Adding a plugin is one new file defining
 * `const plugin plugin_<name>` (scene/plugin_def.h DEFINE_PLUGIN;
 * docs/adding-a-plugin.md) and one line here. */
#include "../plugins/env_plugin.h"
#include "loader.h"
#include "plugin_def.h"

#include <stdlib.h>
#include <string.h>

/* Strong references: every plugin object is pulled out of the kernel
 * library by this table, so a missing plugin is a link error (no
 * --whole-archive, no weak symbols). */
/* One line per plugin family: kept out of clang-format, which reflows it. */
// clang-format off
#define PLUGINS(X)                                                            \
  X(scene)                                                                    \
  X(rectangle) X(disk) X(sphere) X(cylinder) X(cube) X(obj) X(ply)           \
  X(diffuse) X(conductor) X(roughconductor) X(dielectric) X(twosided)        \
  X(rpv) X(bilambertian) X(hapke)                                             \
  X(directional) X(constant) X(area) X(envmap)                                \
  X(hdistant) X(distant) X(radiancemeter) X(perspective)                      \
  X(mdistant) X(distantflux) X(mradiancemeter)                                \
  X(hdrfilm) X(box) X(gaussian)                                               \
  X(independent) X(stratified)                                                \
  X(path)                                                                     \
  X(uniform) X(checkerboard) X(bitmap)                                       \
  X(shapegroup) X(instance) X(instancelist) X(periodic)                      \
  X(isotropic) X(hg) X(blendphase) X(rayleigh) X(tabphase)                    \
  X(constvolume) X(gridvolume)                                                \
  X(null) X(homogeneous) X(heterogeneous) X(piecewise) X(molecular_atmosphere) \
  X(volpath) X(piecewise_volpath)
// clang-format on

#define DECLARE_(name) extern const plugin plugin_##name;
PLUGINS(DECLARE_)
#undef DECLARE_

const plugin *const rsw_plugins[] = {
#define ENTRY_(name) &plugin_##name,
    PLUGINS(ENTRY_)
#undef ENTRY_
        NULL};

/* Plugins added at run time (registry_add). */
enum {
  ADDED_MAX = 16
};
static const plugin *added[ADDED_MAX];
static size_t n_added;

const plugin *registry_find(const char *name) {
  size_t n = sizeof rsw_plugins / sizeof rsw_plugins[0] - 1;
  for (size_t i = 0; i < n; i++)
    if (strcmp(rsw_plugins[i]->name, name) == 0) return rsw_plugins[i];
  for (size_t i = 0; i < n_added; i++)
    if (strcmp(added[i]->name, name) == 0) return added[i];
  return plugins_find(name); /* environment plugins loaded with --plugin-dir */
}

bool registry_add(const plugin *p) {
  if (!p || !p->name || n_added == ADDED_MAX || registry_find(p->name)) return false;
  added[n_added++] = p;
  return true;
}

/* ---- the record boilerplate (plugin_def.h) -------------------------------- */

void plugin_free_object(object *o) {
  free(o);
}

void *plugin_object_new(size_t size, const plugin *p) {
  object *o = calloc(1, size);
  if (o) o->plugin = p;
  return o;
}

bsdf *bsdf_object_new(size_t size, const plugin *p, unsigned flags) {
  bsdf *b = plugin_object_new(size, p);
  if (!b) return NULL;
  b->ops = p->ops;
  b->flags = flags;
  return b;
}

rsw_status plugin_created(loader *ld, node *n, object *o, object **out) {
  if (!o) return ld_fail(ld, n, NULL, RSW_ERR_NOMEM, "%s: out of memory", n->type);
  o->id = n->id;
  *out = o;
  return RSW_OK;
}

static const char *const class_names[CLS__COUNT] = {
    [CLS_SCENE] = "scene",     [CLS_SHAPE] = "shape",     [CLS_BSDF] = "bsdf",
    [CLS_EMITTER] = "emitter", [CLS_SENSOR] = "sensor",   [CLS_FILM] = "film",
    [CLS_SAMPLER] = "sampler", [CLS_RFILTER] = "rfilter", [CLS_INTEGRATOR] = "integrator",
    [CLS_TEXTURE] = "texture", [CLS_MEDIUM] = "medium",   [CLS_PHASE] = "phase",
    [CLS_VOLUME] = "volume",
};

const char *obj_class_name(obj_class c) {
  return (unsigned)c < CLS__COUNT ? class_names[c] : "object";
}
