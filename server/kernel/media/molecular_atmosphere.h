/* `molecular_atmosphere` (molecular_atmosphere.c): what tests, benches and
 * the solar spectrum read besides the plugin itself. */
#ifndef RSW_MEDIA_MOLECULAR_ATMOSPHERE_H
#define RSW_MEDIA_MOLECULAR_ATMOSPHERE_H

#include "../kernel.h"

/* Rayleigh scattering cross section of air [m^2] at a wavelength [nm]
 * (Bodhaine et al. 1999, eqs. 16-23, 360 ppm CO2). */
double atmo_rayleigh_cross_section(double wavelength_nm);
/* The Bogumil et al. (2003) O3 coefficients c0, c1, c2 [1e-20 cm^2] at a
 * wavelength (0 above the table); false below it (230 nm). */
bool atmo_o3_coefficients(double wavelength_nm, double c[3]);

/* The medium's layers at a wavelength (recomputed if needed): n layers
 * between the levels z[0..n] [m], sigma_t [m^-1, before `scale`], albedo,
 * and the nested blend weights weight[k n_particles + j] (component j + 1
 * onto 0..j; 0 is Rayleigh). Borrowed; valid until the next update or
 * render. False if md is not a molecular_atmosphere or the wavelength is
 * out of its data's range. */
bool molecular_atmosphere_layers(const medium *md, double wavelength, const double **z, uint32_t *n,
                                 const double **sigma_t, const double **albedo, const double **weight,
                                 size_t *n_particles);
/* Columns [m^-2] of air and O3 (sum of layer density x thickness). */
bool molecular_atmosphere_columns(const medium *md, double *air, double *o3);

#endif
