/* The parameter table read: entries by index, lookup by key, alias, glob or
 * Eradiate's TYPE:ID:PATH search, and values as JSON (params.h names the
 * entries). */
#ifndef RSW_SCENE_PARAM_TABLE_H
#define RSW_SCENE_PARAM_TABLE_H

#include "params.h"

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

#endif
