/* The builder's side of the document tree: what plugins call from their
 * create() to read their properties. Each getter marks the property used;
 * the builder rejects any property left unused (Mitsuba's
 * ParserConfig.unused_properties = Error). Getters validate the type and
 * finiteness and, on error, record the property's location in ld->err.
 *
 * "absent" means the document did not give the property: the default is
 * used (Mitsuba's defaults: docs/kernel-conventions.md, by class). */
#ifndef RSW_SCENE_LOADER_H
#define RSW_SCENE_LOADER_H

#include "../kernel.h"
#include "node.h"

typedef struct loader loader;

/* How the getters reach what lies above them: the scene assembly
 * (scene/build.c) sets these. Building a nested object runs its plugin's
 * create(), which calls these getters again; through pointers, the
 * getters stay below every plugin (tools/check-layers.py). */
typedef struct loader_hooks {
  /* The plugin of node n (by its type), checking the XML tag agrees with
   * its class; an unknown type is an error naming it. */
  rsw_status (*node_plugin)(loader *ld, node *n, const plugin **out);
  /* Build (or return the already built) object of node n, of class cls
   * (CLS__COUNT for any class), rejecting properties it left unused. */
  rsw_status (*build)(loader *ld, node *n, obj_class cls, object **out);
  /* The plugin registered under name, or NULL. */
  const plugin *(*find)(const char *name);
  /* A uniform texture holding s (error locations: where, may be NULL);
   * NULL when out of memory. */
  texture *(*uniform_texture)(const spectrum *s, const char *id, const char *where);
} loader_hooks;

struct loader {
  rsw_variant variant;
  bool polarized; /* mono_polarized, rgb_polarized */
  rsw_err *err;
  const char *base_dir; /* directory relative file names resolve against */
  rsw_status (*resolve)(void *user, const char *name, char **path_out, rsw_err *err);
  void *resolve_user;
  node *root;
  scene *scene; /* the scene being built (objects are added here) */
  /* id -> node index (builder-private) */
  node **ids;
  size_t n_ids, cap_ids;
  /* id -> the node a ref to it resolves to (open addressing; cap 0 or a
   * power of two), so that 100,000 refs resolve in linear time */
  node **ref_slots;
  size_t ref_cap;
  const loader_hooks *hooks;
};

/* The scene assembly's hooks (scene/build.c): what a loader made outside
 * scene_build (a test building one plugin) points ld->hooks at. */
extern const loader_hooks scene_build_hooks;

/* Index the document's ids and refs (before building anything). */
rsw_status ld_index(loader *ld);
/* The node a ref to id resolves to, or NULL. */
node *ld_resolve_ref(loader *ld, const char *id);
/* Class of the object a node/ref property p of owner stands for (without
 * building it); *target gets its node. */
rsw_status ld_prop_class(loader *ld, node *owner, prop *p, obj_class *cls, node **target);
/* The plugin registered under type, or NULL (through ld->hooks). */
const plugin *ld_find_plugin(loader *ld, const char *type);

/* Report an error about property `name` of n (or about n itself when name
 * is NULL) and return code. */
rsw_status ld_fail(loader *ld, node *n, const char *name, rsw_status code, const char *fmt, ...)
    __attribute__((format(printf, 5, 6)));

bool ld_has(const node *n, const char *name); /* does not mark used */

rsw_status ld_float(loader *ld, node *n, const char *name, double def, double *out);
/* As ld_float, and the value must lie in [lo, hi]. */
rsw_status ld_float_range(loader *ld, node *n, const char *name, double def, double lo, double hi,
                          double *out);
rsw_status ld_int(loader *ld, node *n, const char *name, long long def, long long lo, long long hi,
                  long long *out);
rsw_status ld_bool(loader *ld, node *n, const char *name, bool def, bool *out);
/* *out is borrowed from the document (valid while the scene lives). */
rsw_status ld_string(loader *ld, node *n, const char *name, const char *def, const char **out);
/* *present (may be NULL) tells whether the property was given. */
rsw_status ld_vec3(loader *ld, node *n, const char *name, vec3 def, vec3 *out, bool *present);
rsw_status ld_transform(loader *ld, node *n, const char *name, xform *out, bool *present);
/* A file name resolved against the scene's directory; must exist and be
 * readable. *out is owned by the caller (free()). */
rsw_status ld_path(loader *ld, node *n, const char *name, char **out);

/* A spectral texture: absent -> uniform(def); a number, a 3-vector (rgb),
 * an rgb/uniform/tabulated spectrum -> a `uniform` texture; a nested
 * texture object or a ref to one -> that texture. `lo` is the smallest
 * allowed value for constant inputs (0 for reflectances; -INFINITY for no
 * check). *out is owned by the scene. */
rsw_status ld_texture(loader *ld, node *n, const char *name, double def, double lo, texture **out);
/* As ld_texture but *out = NULL when absent. */
rsw_status ld_texture_opt(loader *ld, node *n, const char *name, double lo, texture **out);

/* A volume (Mitsuba's props.volume()): absent -> a constvolume of def; a
 * number, rgb or spectrum (or a nested uniform texture) -> a constvolume
 * holding it; a nested or referenced volume -> that volume. Every value the
 * volume holds (any cell, channel, tabulated wavelength) must lie in
 * [lo, hi] (-INFINITY / INFINITY: no bound), checked here and, through
 * the volume's lo/hi, on every update of its parameters
 * (volumes/constvolume.c). *out is owned by the scene. */
rsw_status ld_volume(loader *ld, node *n, const char *name, double def, double lo, double hi, volume **out);
/* ld_volume for slots that only evaluate the volume (a heterogeneous
 * medium's sigma_t and albedo, a blend weight): it also takes volumes
 * that are no grid over a box (sphericalcoordsvolume), which ld_volume
 * refuses naming the slot. */
rsw_status ld_volume_mapped(loader *ld, node *n, const char *name, double def, double lo, double hi,
                            volume **out);

/* The nested object (or referenced object) of class cls. With name NULL,
 * the one child of that class whatever its key (error if several); with a
 * name, the property of that name (error if it is another class).
 * *out = NULL when absent. */
rsw_status ld_child(loader *ld, node *n, const char *name, obj_class cls, object **out);
/* All children of class cls in declaration order. *out is malloc'ed (free
 * it); the objects are owned by the scene. */
rsw_status ld_children(loader *ld, node *n, obj_class cls, object ***out, size_t *count);

/* Register an object created outside a node (e.g. a default film) with the
 * scene, which then owns it. */
rsw_status ld_adopt(loader *ld, object *o);
/* Create a plugin instance of `type` with no properties (defaults). */
rsw_status ld_create_default(loader *ld, const char *type, obj_class cls, const char *id, object **out);

/* Evaluate a spectrum property for a render context (mono: value at the
 * wavelength, linear interpolation, error outside the table; rgb: the
 * triple; uniform: the value everywhere). */
rsw_status spectrum_eval(const spectrum *s, const render_ctx *rc, color *out, rsw_err *err,
                         const char *where);

/* The plugin registered under name: the built-in ones (scene/registry.c),
 * then the environment plugins (extplugin/env_plugin.h). For the scene
 * assembly, above the plugins (scene/build.c); plugins call
 * ld_find_plugin. NULL if unknown. */
const plugin *registry_find(const char *name);
/* All registered plugins, NULL-terminated. */
extern const plugin *const rsw_plugins[];

#endif
