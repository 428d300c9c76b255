#!/usr/bin/env python3
# A sweep as one xarray Dataset: radiance over (wavelength, reflectance, y, x).
import xarray as xr

ds = xr.open_dataset("sweep_nc/dataset.nc")
print(ds.radiance.dims, dict(ds.sizes))
# The plate's radiance at 550 nm, averaged over the film, for each reflectance:
print(ds.radiance.sel(wavelength=550).mean(("y", "x")).values)
