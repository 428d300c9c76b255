/* The one list of plugins. Adding a plugin is one new file defining
 * `const plugin plugin_<name>` (scene/plugin_def.h DEFINE_PLUGIN;
 * docs/adding-a-plugin.md) and one line here. */
#include "loader.h"

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
  X(plastic) X(roughplastic) X(blendbsdf) X(mask)                             \
  X(rtls) X(maignan) X(ocean_legacy) X(selectbsdf) X(mqdiffuse)               \
  X(directional) X(constant) X(area) X(envmap) X(astroobject)                 \
  X(point) X(spot)                                                            \
  X(hdistant) X(distant) X(radiancemeter) X(perspective)                      \
  X(thinlens) X(orthographic)                                                 \
  X(mdistant) X(distantflux) X(mradiancemeter) X(mpdistant)                   \
  X(hdrfilm) X(box) X(gaussian) X(tent) X(lanczos)                            \
  X(independent) X(stratified)                                                \
  X(path) X(direct) X(stokes)                                                 \
  X(uniform) X(checkerboard) X(bitmap)                                       \
  X(shapegroup) X(instance) X(instancelist) X(periodic)                      \
  X(isotropic) X(hg) X(blendphase) X(rayleigh) X(rayleigh_polarized)        \
  X(tabphase) X(tabphase_polarized)                                          \
  X(constvolume) X(gridvolume) X(sphericalcoordsvolume)                    \
  X(extremum_grid) X(extremum_global) X(extremum_spherical)                   \
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
