/* Scene parameters: the table every plugin reports into (Mitsuba's
 * traverse()), lookup by key, glob or Eradiate's (type, id, relative path)
 * search, and atomic updates with update classes
 * (docs/kernel-conventions.md#parameters-and-updates).
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

/* ---- values ----------------------------------------------------------------- */

/* A value given for an update, as parsed from JSON (see param_value_parse). */
typedef enum param_value_kind {
  PV_NUMBER, /* 0.3 */
  PV_BOOL,   /* true */
  PV_ARRAY,  /* [0.1, 0.2, 0.3], [16 numbers], [[4 rows of 4]] (flattened) */
  PV_TABLE,  /* {"wavelengths": [...], "values": [...]} or
                 {"type": "spectrum", "value": [[wl, v], ...]} */
} param_value_kind;

typedef struct param_value {
  param_value_kind kind;
  double num;
  bool b;
  double *arr; /* PV_ARRAY: n numbers (owned) */
  size_t n;
  size_t rows;    /* PV_ARRAY given as nested rows: number of rows, else 0 */
  spectrum table; /* PV_TABLE (owned) */
} param_value;

/* Parse a JSON text ("0.3", "[0.1,0.2,0.3]", a 16-number matrix, a
 * tabulated spectrum object). `where` names the input in errors. */
rsw_status param_value_parse(const char *json, const char *where, param_value *out, rsw_err *err);
void param_value_free(param_value *v);

/* ---- the table ----------------------------------------------------------------- */

typedef struct param_table param_table;

typedef struct param_info {
  const char *key;
  param_type type;
  update_class cls;
  size_t shape[2];          /* dims; shape[1] = 0 for 1-D */
  const char *object_type;  /* plugin name of the owner ("diffuse", ...) */
  const char *object_class; /* "bsdf", "shape", "texture", ... */
  const char *object_id;
  const char *const *aliases;
  size_t n_aliases;
} param_info;

/* Build the table of a scene (done by scene_build; exposed for tests). */
rsw_status params_build(scene *s, rsw_err *err);
void params_free(param_table *t);

size_t params_count(const scene *s);
/* Entry i in table order (traversal order). */
bool params_info(const scene *s, size_t i, param_info *out);
/* Index of the entry for a key: an exact key or alias, or Eradiate's search
 * written TYPE:ID:PATH (object class or plugin name, object id, path
 * relative to that object). On failure: RSW_ERR_NOT_FOUND naming the key
 * and listing the three closest keys. */
rsw_status params_lookup(const scene *s, const char *key, size_t *index, rsw_err *err);
/* The up to three keys closest to `key` (edit distance); returns how many
 * were written. The strings are borrowed from the table. */
size_t params_closest(const scene *s, const char *key, const char *out[3]);
/* Indices of entries whose key (or an alias) matches glob (`*` matches any
 * run of characters, dots included; `?` one character) and whose class is
 * in class_mask (UPDATE_* bits; UPDATE_NONE entries match when
 * include_none is true). *out is malloc'ed. A pattern containing ':' is
 * taken as a TYPE:ID:PATH search. Matching nothing is RSW_ERR_NOT_FOUND. */
rsw_status params_match(const scene *s, const char *glob, unsigned class_mask, bool include_none,
                        size_t **out, size_t *count, rsw_err *err);

/* The current value of entry i as JSON text (malloc'ed): a number, an
 * array, a 4x4 nested array, or {"wavelengths": [...], "values": [...]}.
 * Buffers longer than max_items (0: no limit) are elided as
 * {"length": n}. */
char *params_value_json(const scene *s, size_t i, size_t max_items);

/* ---- updates -------------------------------------------------------------------- */

typedef struct param_update {
  const char *key; /* key, alias or TYPE:ID:PATH */
  param_value value;
} param_update;

typedef struct update_report {
  unsigned classes;                            /* UPDATE_* bits of the entries that changed */
  size_t changed;                              /* entries whose value changed (equal values are
                         no-ops) */
  double seconds;                              /* wall time of the whole update */
  unsigned refits, rebuilds, instance_updates; /* acceleration work done */
} update_report;

/* Validate every entry of the map (key exists, writable, type and shape,
 * legal value); if any fails, change nothing and return its error naming
 * the key. Otherwise apply all, refresh derived state (frames, areas,
 * emitter distributions, bounding sphere, sensor offsets, Embree) and fill
 * *report (may be NULL). Not thread-safe with renders of the same scene. */
rsw_status scene_update(scene *s, const param_update *items, size_t n, update_report *report, rsw_err *err);

/* The checks of scene_update without applying anything: every key
 * resolves (no key twice), is writable, and its value has the right type,
 * shape and range for the scene as it is. (The mesh-area check that needs
 * the new vertices together is left to scene_update.) For validating
 * overrides before they are used, e.g. every context of a job at submit.
 * Only reads the scene. */
rsw_status scene_update_check(const scene *s, const param_update *items, size_t n, rsw_err *err);

/* ---- what plugins call from their traverse() --------------------------------- */

typedef struct param_visitor param_visitor;

/* Validator for a transform about to be written (e.g. a sphere's must be a
 * similarity). Returns an error naming `key`. */
typedef rsw_status (*xform_check_fn)(const object *owner, const xform *t, const char *key, rsw_err *err);
/* Getter/setter of a derived 3-vector (e.g. a `direction` that rewrites
 * to_world). set() is called only after validation (non-zero, finite). */
typedef vec3 (*vec_get_fn)(const object *owner);
typedef void (*vec_set_fn)(object *owner, vec3 v);

void pv_float(param_visitor *v, const char *name, double *ptr, update_class cls, double lo, double hi);
void pv_bool_ro(param_visitor *v, const char *name, bool value);
void pv_transform(param_visitor *v, const char *name, xform *ptr, update_class cls, xform_check_fn check);
void pv_vector(param_visitor *v, const char *name, vec_get_fn get, vec_set_fn set, update_class cls);
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
