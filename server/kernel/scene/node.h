/* The scene document tree: what the JSON and XML readers produce and what
 * the scene builder consumes. It mirrors Mitsuba's Properties: one node per
 * object (plugin type + id + named properties), properties typed as the
 * document wrote them. Readers know nothing of plugins; plugins know nothing
 * of JSON or XML (c-ray's loader/renderer split).
 *
 * Every node and property carries `loc`: a JSON pointer ("/shape/bsdf") or
 * an XML "file:line", used in every error message about it. */
#ifndef RSW_SCENE_NODE_H
#define RSW_SCENE_NODE_H

#include <stdbool.h>
#include <stddef.h>

#include "../core/transform.h"
#include "../core/vec.h"
#include "rsw_error.h"

/* Limits that keep hostile documents bounded. */
#define RSW_MAX_DEPTH 64 /* nesting of objects/arrays */
#define RSW_MAX_PROPS                                                                                        \
  4096                             /* properties per ordinary object; containers
                                     (the scene, a shapegroup) take any number of
                                     children, bounded by RSW_MAX_NODES and the
                                     document's memory cap below */
#define RSW_MAX_NODES      1000000 /* nodes per document */
/* Memory of one document tree (nodes, property arrays and name indexes at
 * their capacity, strings and numbers, as counted by node_mem_*): it stays
 * resident with the scene. A shapegroup member (a disk with a to_world and
 * a bsdf ref) takes about 1.8 KiB, so 1 GiB holds some 600,000 such
 * members. The XML reader also bounds the text $ substitution adds to a
 * document by this cap. */
#define RSW_MAX_TREE_BYTES ((size_t)1 << 30)
#define RSW_MAX_SPECTRUM   100000 /* samples in a tabulated spectrum */
#define RSW_MAX_NAME       256    /* property names, ids, plugin types */

typedef enum prop_kind {
  PROP_BOOL,
  PROP_NUMBER, /* JSON number, XML <float>/<integer>; is_int tells which */
  PROP_STRING,
  PROP_VEC3,      /* JSON 3-array, XML <point>/<vector> */
  PROP_SPECTRUM,  /* rgb / uniform / tabulated spectrum */
  PROP_TRANSFORM, /* JSON matrix or op list, XML <transform> */
  PROP_NUMBERS,   /* any other JSON array of numbers */
  PROP_NODE,      /* nested object */
  PROP_REF,       /* reference to an object by id */
} prop_kind;

typedef enum spectrum_kind {
  SPEC_UNIFORM, /* one value at every wavelength */
  SPEC_RGB,     /* linear sRGB triple */
  SPEC_TABLE,   /* (wavelength nm, value) pairs, increasing wavelengths */
} spectrum_kind;

typedef struct spectrum {
  spectrum_kind kind;
  double value;  /* SPEC_UNIFORM */
  double rgb[3]; /* SPEC_RGB */
  size_t n;      /* SPEC_TABLE: number of samples */
  double *wl;    /* owned, nm, strictly increasing */
  double *val;   /* owned */
} spectrum;

struct node;

typedef struct prop {
  char *name; /* property name; "" for an unnamed nested XML object */
  prop_kind kind;
  char *loc;
  bool used;   /* set by the builder's getters; unused => error */
  bool is_int; /* PROP_NUMBER written as an integer (XML <integer>, or an
                     integral JSON number) */
  bool b;
  double num;
  char *str;
  vec3 vec;
  spectrum spec;
  xform xf;
  double *nums; /* PROP_NUMBERS (owned) */
  size_t n_nums;
  struct node *child; /* PROP_NODE (owned) */
  char *ref;          /* PROP_REF: the id referred to */
} prop;

typedef struct node {
  char *tag;  /* XML element name ("shape", "bsdf", ...); NULL for JSON */
  char *type; /* plugin type name; "scene" for the root */
  char *id;   /* explicit id, or the JSON key, or generated */
  bool id_explicit;
  char *loc;
  prop *props;
  size_t n_props, cap_props;
  /* Name -> first property index + 1 (0: empty slot), open addressing,
   * built once a node has NODE_INDEX_MIN properties so that node_find
   * and duplicate checks stay O(1) on containers of 100,000 members. */
  size_t *name_index;
  size_t index_cap; /* 0 or a power of two */
  void *built;      /* set by the builder: the object made from this node */
  int build_state;  /* builder-private: 0 new, 1 in progress, 2 done */
} node;

/* Per-document limits. scene_limits_default holds the RSW_MAX_* values;
 * tests and embedders may pass lower ones to the *_limited readers. */
typedef struct scene_limits {
  size_t max_props;      /* properties of an ordinary object */
  size_t max_tree_bytes; /* memory of the document tree */
} scene_limits;
extern const scene_limits scene_limits_default;

/* Containers hold children by the thousand: the scene root and
 * shapegroups. They are exempt from max_props (the tree's memory cap and
 * RSW_MAX_NODES bound them instead). */
bool node_type_is_container(const char *type);

/* Allocation helpers for readers. All strings are copied. */
node *node_new(const char *tag, const char *type, const char *loc);
void node_free(node *n); /* recursive; NULL is a no-op */
/* Append a property (zeroed except name/kind/loc); returns NULL on OOM or
 * past RSW_MAX_NODES properties (readers check their own, lower, caps
 * first). The returned pointer is valid until the next add. */
prop *node_add_prop(node *n, const char *name, prop_kind kind, const char *loc);
/* First property with this name, or NULL. O(1) on large nodes. */
prop *node_find(const node *n, const char *name);
/* Memory of the tree, for the readers' memory cap, in three parts that
 * add up without overlap: node_mem_self, a node's struct and strings;
 * node_mem_arrays, its property array and name index (allocated
 * capacity, which node_add_prop grows: readers count the growth of each
 * add); node_mem_prop, what a property owns besides its slot in that array
 * (strings, numbers, spectrum samples; not its child node). */
size_t node_mem_self(const node *n);
size_t node_mem_arrays(const node *n);
size_t node_mem_prop(const prop *p);
void spectrum_free(spectrum *s);
char *rsw_strdup(const char *s);

/* Readers. On error they return non-RSW_OK with err naming the place.
 * The returned root has type "scene". variant_out (may be NULL) receives an
 * owned copy of the document's variant ("mono"/"rgb") or NULL if absent.
 *
 * `defines` are -D name=value overrides (XML $name substitution; for JSON
 * they are an error if given, since JSON has no parameters). */
typedef struct scene_define {
  const char *name, *value;
} scene_define;

rsw_status scene_read_json(const char *text, size_t len, const char *source_name, node **root_out,
                           char **variant_out, rsw_err *err);
rsw_status scene_read_xml(const char *text, size_t len, const char *source_name, const scene_define *defines,
                          size_t n_defines, node **root_out, char **variant_out, rsw_err *err);
/* The same with explicit limits (NULL: scene_limits_default). */
rsw_status scene_read_json_limited(const char *text, size_t len, const char *source_name,
                                   const scene_limits *lim, node **root_out, char **variant_out,
                                   rsw_err *err);
rsw_status scene_read_xml_limited(const char *text, size_t len, const char *source_name,
                                  const scene_define *defines, size_t n_defines, const scene_limits *lim,
                                  node **root_out, char **variant_out, rsw_err *err);

/* Parse a transform op list / matrix shared by both readers.
 * Applies ops in order, each left-multiplied onto the accumulated
 * transform (Mitsuba XML rule). */

/* Assign deterministic ids to objects without one: plugin type name, then
 * type_1, type_2, ... in document order (depth-first, declaration order),
 * skipping ids already taken. Called by both readers before returning. */
rsw_status node_assign_ids(node *root, rsw_err *err);

#endif
