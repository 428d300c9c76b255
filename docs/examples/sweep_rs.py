#!/usr/bin/env python3
# Wavelength sweep of a Lambertian plate with the raysweep package (docs/python.md).
import raysweep as rs

client = rs.connect()                      # $RAYSWEEP_URL, else http://127.0.0.1:8350
scene = client.load_file("plate.json")
params = scene.traverse()                  # like mi.traverse(scene)
params["plate.bsdf.reflectance.value"] = {"wavelengths": [400, 700], "values": [0.2, 0.8]}
params.update()                            # one atomic PATCH
ds = scene.sweep(grid={"wavelength": range(400, 701, 50)}, spp=4)   # an xarray.Dataset
for w, value in ds.radiance.isel(y=0, x=0).to_series().items():
    print(w, value)
