/* What a plugin file includes, and the record boilerplate every plugin
 * repeated, written once (scene/registry.c). docs/adding-a-plugin.md walks
 * through a new BSDF with these:
 *
 *   DEFINE_PLUGIN(lommel, CLS_BSDF, .ops = &lommel_ops, .traverse = lommel_traverse)
 *     defines `const plugin plugin_lommel` for the document type "lommel"
 *     (the name comes from the token, as the registry line's does) and
 *     declares lommel_create(), which the file defines; destroy defaults to
 *     plugin_free_object (a `.destroy = ...` member replaces it);
 *   PLUGIN_NEW(lommel_bsdf, lommel) / BSDF_NEW(lommel_bsdf, lommel, flags)
 *     a zeroed record whose header names the plugin (and, for a BSDF, its
 *     ops table and lobes), NULL when out of memory;
 *   plugin_created(ld, n, o, out)
 *     the end of every create(): the node's id on o and *out = o, or the
 *     node's out-of-memory error when o is NULL.
 * Then one line in scene/registry.c's PLUGINS list. */
#ifndef RSW_SCENE_PLUGIN_DEF_H
#define RSW_SCENE_PLUGIN_DEF_H

#include <stddef.h>

#include "../kernel.h"
#include "loader.h"
#include "node.h"
#include "params.h"

/* The destroy of a plugin whose object owns nothing beyond its record. */
void plugin_free_object(object *o);

/* plugin.pages saying yes: for a plugin whose prepare() keeps a value per
 * page (uniform, the conductors' index presets) or holds nothing spectral
 * (a film's pixel format, a bitmap's variant). */
bool plugin_pages_any(const object *o);

/* A zeroed record of `size` bytes (a plugin struct whose first member is
 * the class's struct, itself starting with the object header), its
 * header naming plugin p; NULL when out of memory. */
void *plugin_object_new(size_t size, const plugin *p);
#define PLUGIN_NEW(type, name) ((type *)plugin_object_new(sizeof(type), &plugin_##name))

/* plugin_object_new for a BSDF: also its ops table (p->ops) and lobes. */
bsdf *bsdf_object_new(size_t size, const plugin *p, unsigned flags);
#define BSDF_NEW(type, name, flags) ((type *)bsdf_object_new(sizeof(type), &plugin_##name, (flags)))

/* create()'s success: o takes node n's id and *out = o, RSW_OK; o NULL:
 * the loader's out-of-memory error on n. */
rsw_status plugin_created(loader *ld, node *n, object *o, object **out);

/* Designated initializers that name a member twice (the defaults below,
 * then the plugin's own) are what DEFINE_PLUGIN means: the later one wins
 * (C11 6.7.9p19), so GCC's and clang's warning about it is off inside. */
#define DEFINE_PLUGIN(NAME, CLASS, ...)                                                                      \
  static rsw_status NAME##_create(loader *ld, node *n, object **out);                                        \
  _Pragma("GCC diagnostic push") _Pragma(                                                                    \
      "GCC diagnostic ignored \"-Woverride-init\"") const plugin plugin_##NAME = {                           \
      .name = #NAME, .cls = (CLASS), .create = NAME##_create, .destroy = plugin_free_object, __VA_ARGS__};   \
  _Pragma("GCC diagnostic pop") extern const plugin plugin_##NAME

/* A plugin defined outside the PLUGINS list (an application embedding the
 * kernel, or a test building the example of docs/adding-a-plugin.md):
 * registry_find() finds it from then on. Call before loading scenes, from
 * one thread. False when its name is taken or the table (16) is full. */
bool registry_add(const plugin *p);

#endif
