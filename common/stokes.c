/* Stokes channel layouts and DoLP / AoLP (stokes.h). */
#include "stokes.h"

#include <math.h>
#include <string.h>

int stokes_component(const char *name) {
  if (!name || name[0] != 'S' || name[1] < '0' || name[1] > '3') return -1;
  return name[2] == '\0' || name[2] == '.' ? name[1] - '0' : -1;
}

bool stokes_layout_of(const char *const *names, int n, stokes_layout *out) {
  if (!names || n < 4 || n % 4 != 0 || n / 4 > STOKES_MAX_COLORS) return false;
  stokes_layout l = {.n_color = n / 4};
  for (int k = 0; k < n; k++) {
    const char *nm = names[k];
    int comp = k / l.n_color, c = k % l.n_color;
    if (stokes_component(nm) != comp) return false;
    const char *suffix = nm[2] == '.' ? nm + 3 : NULL;
    if (suffix && (!*suffix || strchr(suffix, '.'))) return false;
    /* Bare S0..S3 only as the one-colour film; every component names the
     * same colours in the same order. */
    if (!suffix && l.n_color != 1) return false;
    if (comp == 0)
      l.color[c] = suffix;
    else if ((suffix == NULL) != (l.color[c] == NULL) || (suffix && strcmp(suffix, l.color[c]) != 0))
      return false;
  }
  for (int a = 0; a < l.n_color; a++)
    for (int b = a + 1; b < l.n_color; b++)
      if (strcmp(l.color[a], l.color[b]) == 0) return false;
  *out = l;
  return true;
}

double stokes_dolp(double s0, double s1, double s2) {
  if (isnan(s0) || isnan(s1) || isnan(s2)) return NAN;
  return s0 == 0 ? 0.0 : sqrt(s1 * s1 + s2 * s2) / s0;
}

double stokes_aolp_deg(double s1, double s2) {
  if (isnan(s1) || isnan(s2)) return NAN;
  if (s1 == 0 && s2 == 0) return 0.0;
  /* atan2 is in [-180, 180] degrees: half of it in [-90, 90]; -90 (S2 = -0
   * with S1 < 0) is the same axis as 90. */
  double a = 0.5 * atan2(s2, s1) * (180.0 / M_PI);
  return a <= -90.0 ? a + 180.0 : a;
}
