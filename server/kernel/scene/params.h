/* Scene parameters: the table every plugin reports into (Mitsuba's
 * traverse()), lookup by key, glob or Eradiate's (type, id, relative path)
 * search, and atomic updates with update classes
 * (docs/kernel-conventions.md#parameters-and-updates).
 *
 * Three files: params.c (this header) is what plugins call, the visitor
 * their traverse() reports into, which makes the table; param_table.h
 * looks entries up and prints their values; update.h writes them.
 *
 * Naming (Mitsuba's rules, same section): scene children by id in declaration
 * order; nested objects by the slot name their parent uses (`bsdf`,
 * `reflectance`, `brdf_0`, ...); uniform values end in `.value`; an object
 * shared through `ref` is listed once, under the first path that reaches it,
 * and its other paths are kept as aliases; clashing names get `_1`, `_2`.
 *
 * Update classes:
 *   none       read-only: a write is rejected;
 *   spectral   used at shading or sampling time only (reflectances,
 *              radiances, roughness, eta/k, emitter and sensor transforms):
 *              no acceleration-structure work at all;
 *   geometric  a shape's to_world (instance transform: top-level rebuild
 *              only), mesh vertex_positions (refit of that mesh's BVH),
 *              faces (topology: that mesh's BVH is rebuilt).
 * Eradiate's KernelSceneParameterFlags map onto them: SPECTRAL -> spectral,
 * GEOMETRIC -> geometric.
 *
 * Deliberate differences from Mitsuba, each for "an update equals a
 * reload": unknown keys are an error (Mitsuba ignores them); meshes expose
 * to_world, with vertex_positions in object space (Mitsuba bakes to_world
 * into the vertices); derived state that Mitsuba computes once at load
 * (the scene's bounding sphere, sensors' ray_offset, the directional
 * emitter's bounding sphere) is recomputed after a geometric update. */
#ifndef RSW_SCENE_PARAMS_H
#define RSW_SCENE_PARAMS_H

#include "../kernel.h"
#include "node.h"

typedef enum param_type {
  PARAM_FLOAT,     /* one number */
  PARAM_SPECTRUM,  /* mono: a number or a tabulated spectrum */
  PARAM_RGB,       /* rgb: an [r, g, b] triple (or one number) */
  PARAM_VECTOR,    /* [x, y, z] */
  PARAM_TRANSFORM, /* 4x4 row-major matrix */
  PARAM_BUFFER,    /* flat array (mesh buffers) */
  PARAM_BOOL,
} param_type;

typedef enum update_class {
  UPDATE_NONE = 0,
  UPDATE_SPECTRAL = 1u << 0,
  UPDATE_GEOMETRIC = 1u << 1,
} update_class;

const char *param_type_name(param_type t);     /* "float", "spectrum", ... */
const char *update_class_name(update_class c); /* "none", "spectral", "geometric" */
/* Parse "none" / "spectral" / "geometric"; false if unknown. */
bool update_class_parse(const char *s, update_class *out);

typedef struct param_table param_table;

/* Build the table of a scene (done by scene_build; exposed for tests). */
rsw_status params_build(scene *s, rsw_err *err);
void params_free(param_table *t);

/* ---- what plugins call from their traverse() --------------------------------- */

typedef struct param_visitor param_visitor;

/* Validator for a transform about to be written (e.g. a sphere's must be a
 * similarity). Returns an error naming `key`. */
typedef rsw_status (*xform_check_fn)(const object *owner, const xform *t, const char *key, rsw_err *err);
/* Getter/setter of a derived 3-vector (e.g. a `direction` that rewrites
 * to_world). set() is called only after validation: finite, and for a
 * direction (pv_vector) non-zero; a position (pv_position) may be zero. */
typedef vec3 (*vec_get_fn)(const object *owner);
typedef void (*vec_set_fn)(object *owner, vec3 v);

void pv_float(param_visitor *v, const char *name, double *ptr, update_class cls, double lo, double hi);
void pv_bool_ro(param_visitor *v, const char *name, bool value);
void pv_transform(param_visitor *v, const char *name, xform *ptr, update_class cls, xform_check_fn check);
void pv_vector(param_visitor *v, const char *name, vec_get_fn get, vec_set_fn set, update_class cls);
void pv_position(param_visitor *v, const char *name, vec_get_fn get, vec_set_fn set, update_class cls);
/* A uniform texture's spectral value (type spectrum in mono, rgb in rgb).
 * [lo, hi] comes from the slot that holds the texture (ld_texture's lo). */
void pv_spectrum(param_visitor *v, const char *name, texture *t);
/* Mesh buffers: which = "vertex_positions" | "faces" | "vertex_normals" |
 * "vertex_texcoords". */
void pv_mesh_buffer(param_visitor *v, const char *name, shape *sh);
/* Validator for a whole new buffer (pv_buffer), after the length, the
 * finiteness and the range of every value were checked: e.g. a
 * tabulated phase function must not be all zeros. Returns an error
 * naming `key`. */
typedef rsw_status (*buffer_check_fn)(const object *owner, const double *values, size_t n, const char *key,
                                      rsw_err *err);
/* A flat array of n doubles the plugin owns (a volume's grid data, a
 * tabulated phase function): an update gives exactly n numbers (the
 * shape is fixed), each finite and in [lo, hi], then `check` (may be
 * NULL); they are copied into data in place, then the owner's
 * parameters_changed runs. */
void pv_buffer(param_visitor *v, const char *name, double *data, size_t n, update_class cls, double lo,
               double hi, buffer_check_fn check);
/* A nested object under slot `name`; [lo, hi] constrains the spectral
 * values of a uniform texture reached through it (NaN: no constraint). */
void pv_object(param_visitor *v, const char *name, object *child, double lo, double hi);

#endif
