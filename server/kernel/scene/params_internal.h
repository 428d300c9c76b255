/* The parameter table's entries, shared by the files that build it
 * (params.c: the visitor plugins call), read it (param_table.c: lookup and
 * values) and write through it (update.c). Private to scene/. */
#ifndef RSW_SCENE_PARAMS_INTERNAL_H
#define RSW_SCENE_PARAMS_INTERNAL_H

#include <stdint.h>
#include <stdlib.h>

#include "params.h"

typedef enum entry_kind {
  EK_FLOAT,
  EK_BOOL,
  EK_TRANSFORM,
  EK_VECTOR,
  EK_SPECTRUM,
  EK_MESHBUF,
  EK_DBUF /* pv_buffer: a plugin's array of doubles, fixed length */
} entry_kind;
typedef enum mesh_buf {
  MB_POSITIONS,
  MB_FACES,
  MB_NORMALS,
  MB_TEXCOORDS
} mesh_buf;

typedef struct entry {
  char *key;
  entry_kind kind;
  update_class cls;
  object *owner;
  double lo, hi;
  double *fptr;
  bool bval;
  xform *xptr;
  xform_check_fn check;
  vec_get_fn vget;
  vec_set_fn vset;
  bool position; /* EK_VECTOR: a point (pv_position), may be zero; else a direction */
  texture *tex;
  shape *sh;
  mesh_buf buf;
  double *dptr; /* EK_DBUF */
  size_t dn;
  buffer_check_fn dcheck;
  char **aliases;
  size_t n_aliases;
} entry;

typedef struct objrec {
  object *o;
  char *path;
  size_t e_begin, e_end; /* entries added while it was traversed */
} objrec;

struct param_table {
  entry *e;
  size_t n, cap;
  objrec *objs; /* first path of every object reached */
  size_t n_objs, cap_objs;
  objrec *alias; /* further paths of shared objects */
  size_t n_alias, cap_alias;
  /* objs by object pointer and by path: index + 1 (0 = empty), open
   * addressing, so that traversing 100,000 group members stays linear. */
  size_t *by_obj, *by_path;
  size_t ocap;
  /* Open-addressing hash: key or alias -> entry index + 1 (0 = empty). */
  const char **hkey;
  size_t *hval;
  size_t hcap;
};

static inline bool grow(void **arr, size_t *cap, size_t n, size_t elem) {
  if (n < *cap) return true;
  size_t c = *cap ? 2 * *cap : 32;
  void *p = realloc(*arr, c * elem);
  if (!p) return false;
  *arr = p;
  *cap = c;
  return true;
}

static inline uint64_t hash_str(const char *s) {
  uint64_t h = 1469598103934665603ULL;
  for (; *s; s++) h = (h ^ (unsigned char)*s) * 1099511628211ULL;
  return h;
}

/* prefix + "." + name (name alone when prefix is empty), malloc'ed. */
char *params_join(const char *prefix, const char *name);

#endif
