#include "strdist.h"

#include <string.h>

size_t rsw_edit_distance(const char *a, const char *b) {
  size_t la = strlen(a), lb = strlen(b);
  if (la > 255 || lb > 255) return (size_t)-1 / 2;
  size_t row[256];
  for (size_t j = 0; j <= lb; j++) row[j] = j;
  for (size_t i = 1; i <= la; i++) {
    size_t diag = row[0];
    row[0] = i;
    for (size_t j = 1; j <= lb; j++) {
      size_t up = row[j];
      size_t c = diag + (a[i - 1] != b[j - 1]);
      if (up + 1 < c) c = up + 1;
      if (row[j - 1] + 1 < c) c = row[j - 1] + 1;
      row[j] = c;
      diag = up;
    }
  }
  return row[lb];
}

/* Iterative matcher with single-star backtracking: linear in practice and
 * never exponential, whatever the pattern. */
bool rsw_glob_match(const char *p, const char *t) {
  const char *star = NULL, *resume = NULL;
  while (*t) {
    if (*p == '*') {
      star = p++;
      resume = t;
    } else if (*p == '?' || *p == *t) {
      p++;
      t++;
    } else if (star) {
      p = star + 1;
      t = ++resume;
    } else {
      return false;
    }
  }
  while (*p == '*') p++;
  return *p == '\0';
}
