/* Tabulated optical properties of sea water used by `ocean_legacy`
 * (ocean_data.c gives each table's source). Every lookup interpolates
 * linearly and is 0 outside its table, as Eradiate's
 * (Irregular)ContinuousDistribution::eval_pdf is. Wavelengths in nm. */
#ifndef RSW_BSDFS_OCEAN_DATA_H
#define RSW_BSDFS_OCEAN_DATA_H

/* Effective whitecap reflectance, 200-4000 nm (Whitlock et al. 1982,
 * Koepke 1984). */
double ocean_whitecap_reflectance(double wavelength);
/* Complex refractive index of pure water, 200-4000 nm (Hale and Querry
 * 1973): real and imaginary parts. */
double ocean_ior_real(double wavelength);
double ocean_ior_imag(double wavelength);
/* Morel (1988) diffuse attenuation K_w, chi and e, 400-700 nm. */
double ocean_attn_k(double wavelength);
double ocean_attn_chi(double wavelength);
double ocean_attn_e(double wavelength);
/* Molecular scattering coefficient of water as 6S tabulates it
 * (m^-1), 400-700 nm. */
double ocean_molecular_scatter_6s(double wavelength);

#endif
