/* The one list of plugins. Adding a plugin is one new file defining
 * `const plugin plugin_<name>` and one line here. */
#include "../plugins/env_plugin.h"
#include "loader.h"

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
  X(rtls) X(maignan) X(ocean_legacy) X(selectbsdf) X(mqdiffuse)              \
  X(directional) X(constant) X(area) X(envmap) X(astroobject)                \
  X(hdistant) X(distant) X(radiancemeter) X(perspective)                      \
  X(mdistant) X(distantflux) X(mradiancemeter) X(mpdistant)                  \
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

const plugin *registry_find(const char *name) {
  size_t n = sizeof rsw_plugins / sizeof rsw_plugins[0] - 1;
  for (size_t i = 0; i < n; i++)
    if (strcmp(rsw_plugins[i]->name, name) == 0) return rsw_plugins[i];
  return plugins_find(name); /* environment plugins loaded with --plugin-dir */
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
