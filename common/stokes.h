/* Stokes films outside the kernel: which film channels hold a Stokes
 * vector, and the degree and angle of linear polarization derived from
 * one. Shared by the datasets (dataset_nc.c), the daemon's bands
 * (server/service/bands.c) and libraysweep's datasets.
 *
 * Three channel namings carry Stokes vectors (docs/polarization.md):
 *   S0 S1 S2 S3                  the mono `pixel_format: "stokes"` film;
 *   S0.Y S1.Y S2.Y S3.Y          variant mono_polarized;
 *   S0.R S0.G S0.B S1.R ... S3.B variant rgb_polarized;
 * component-major: film channel k is Stokes component k / n_color of
 * colour k % n_color. Planes prefix them ("brf.S0.Y").
 *
 * Conventions (Mitsuba's `stokes` integrator; the film's basis x, y:
 * docs/polarization.md#stokes-conventions): S0..S3 = I, Q, U, V;
 * Q = I_x - I_y, U = I_{+45} - I_{-45}.
 *   DoLP = sqrt(S1^2 + S2^2) / S0, 0 where S0 = 0;
 *   AoLP = 0.5 atan2(S2, S1) in degrees, in (-90, 90], 0 where S1 = S2 = 0,
 *          from x towards y. */
#ifndef RSW_COMMON_STOKES_H
#define RSW_COMMON_STOKES_H

#include <stdbool.h>

/* The most colour channels per Stokes component. */
#define STOKES_MAX_COLORS 4

typedef struct stokes_layout {
  int n_color; /* channels per component: 1 (S0..S3, S0.Y..S3.Y) or 3 (rgb) */
  /* Each colour's suffix ("Y", "R", ...; borrowed from the names), or
   * NULL for the bare S0..S3. */
  const char *color[STOKES_MAX_COLORS];
} stokes_layout;

/* The Stokes component a channel name starts with: 0..3 for "S<k>" or
 * "S<k>.<colour>", -1 otherwise. */
int stokes_component(const char *name);

/* Whether names[0..n-1] are a Stokes vector in one of the namings above
 * (*out set when so). Borrows names; out->color points into them. */
bool stokes_layout_of(const char *const *names, int n, stokes_layout *out);

/* DoLP of (s0, s1, s2): 0 where s0 = 0, NaN where an input is NaN. */
double stokes_dolp(double s0, double s1, double s2);
/* AoLP of (s1, s2) in degrees, (-90, 90]; 0 where s1 = s2 = 0 (either
 * sign of zero), NaN where an input is NaN. */
double stokes_aolp_deg(double s1, double s2);

#endif
