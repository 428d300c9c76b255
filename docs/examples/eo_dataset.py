#!/usr/bin/env python3
# The Earth-observation study's dataset (docs/experiments.md): BRF in two
# bands over the principal plane, for four sun zeniths.
import xarray as xr

ds = xr.open_dataset("eo.nc")
brf = ds.brf_srf.isel(y=0)                  # (sza, band, x): x is the view direction
err = ds.brf_srf_stderr.isel(y=0)
vza = ds.vza.isel(y=0).values               # the view zeniths of the five directions
for b in ds.band.values:
    print(f"band {b}: BRF at view zeniths {vza.round(1).tolist()}")
    for sza in ds.sza.values:
        row = brf.sel(band=b, sza=sza).values
        e = err.sel(band=b, sza=sza).values
        print(f"  sza {sza:4.0f}: " + " ".join(f"{v:.3f}±{s:.3f}" for v, s in zip(row, e)))
