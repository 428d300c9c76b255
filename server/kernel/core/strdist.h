/* Small string helpers shared by error messages ("did you mean ...?") and
 * key lookups. */
#ifndef RSW_CORE_STRDIST_H
#define RSW_CORE_STRDIST_H

#include <stdbool.h>
#include <stddef.h>

/* Levenshtein distance; strings longer than 255 characters compare as far
 * apart (returns a large number). */
size_t rsw_edit_distance(const char *a, const char *b);

/* Shell-style glob: `*` matches any run of characters (dots included), `?`
 * one character; everything else matches itself. */
bool rsw_glob_match(const char *pattern, const char *text);

#endif
