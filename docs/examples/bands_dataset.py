#!/usr/bin/env python3
# A job with bands as one xarray Dataset: per-wavelength and band variables.
import xarray as xr

ds = xr.open_dataset("bands.nc")
print(ds.brf_srf.dims)          # ('context', 'band', 'y', 'x'): contexts without coords
print(list(ds.band.values))     # the band ids
print(ds.brf.dims)              # ('context', 'wavelength', 'y', 'x'): the node wavelengths
print(ds.sza.values, ds.saa.values)  # the sun per context, in Eradiate's convention
# Each band's BRF and its error bar, averaged over the film:
for b in ds.band.values:
    print(b, float(ds.brf_srf.sel(band=b).mean()), float(ds.brf_srf_stderr.sel(band=b).mean()))
