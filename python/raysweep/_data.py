"""Films and datasets as numpy, xarray and NetCDF.

The optional packages (xarray, netCDF4) are imported here only, when first needed.
"""

import numpy as np

from .errors import RaysweepError

# The radiance's units by variant (docs/client.md, "Sweep datasets").
_UNITS = {"mono": "W m-2 sr-1 nm-1", "rgb": "W m-2 sr-1"}


def have_xarray():
    """Whether xarray can be imported."""
    try:
        import xarray  # noqa: F401
    except ImportError:
        return False
    return True


def film_array(film):
    """A JSON film (the daemon's FilmJson) as a float32 array of shape (height, width, channels).

    Non-finite values, which JSON films send as ``null``, become NaN.
    """
    h, w, ch = film["height"], film["width"], film["channels"]
    data = np.array(film["data"], dtype=np.float64)  # None -> nan
    if data.size != h * w * len(ch):
        raise RaysweepError(f"a film of {h}x{w}x{len(ch)} values came with {data.size}")
    return data.astype(np.float32).reshape(h, w, len(ch))


def film_dataarray(film):
    """A JSON film as an ``xarray.DataArray`` over (y, x, channel).

    Coordinates: ``channel`` (its names: ``Y`` or ``R G B``, then ``brf.Y``,
    ``radiance_stderr.Y``, ... for the planes asked for), ``wavelength`` (nm,
    mono), and for distant-family sensors ``vza`` and ``vaa`` (each pixel's
    viewing zenith and azimuth in degrees, Eradiate's convention) and, for a
    scene with one directional emitter, ``sza`` and ``saa``. The film's
    ``meta`` (scene, revision, sensor, spp, seed, variant, ...) is in ``attrs``.
    """
    import xarray as xr

    meta = dict(film.get("meta") or {})
    h, w = film["height"], film["width"]
    coords = {"channel": list(film["channels"])}
    zen, azi = meta.pop("zenith_deg", None), meta.pop("azimuth_deg", None)
    if zen is not None and azi is not None and len(zen) == h * w and len(azi) == h * w:
        coords["vza"] = (("y", "x"), np.array(zen, dtype=np.float64).reshape(h, w))
        coords["vaa"] = (("y", "x"), np.array(azi, dtype=np.float64).reshape(h, w))
    if meta.get("wavelength") is not None:
        coords["wavelength"] = float(meta["wavelength"])
    if "sun_zenith_deg" in meta:
        coords["sza"] = float(meta.pop("sun_zenith_deg"))
    if "sun_azimuth_deg" in meta:
        coords["saa"] = float(meta.pop("sun_azimuth_deg"))
    attrs = {k: _attr(v) for k, v in meta.items() if k not in ("wavelength", "planes") and v is not None}
    attrs["units"] = _UNITS.get(meta.get("variant"), "W m-2 sr-1")
    attrs["long_name"] = "radiance"
    if meta.get("planes"):
        attrs["planes"] = ", ".join(f"{p['name']} [{p['units']}]" for p in meta["planes"])
    return xr.DataArray(film_array(film), dims=("y", "x", "channel"), coords=coords, attrs=attrs,
                        name="radiance")


def _attr(v):
    """A value netCDF and xarray attrs take: lists of numbers as arrays, other lists as text."""
    if isinstance(v, list):
        if all(isinstance(x, (int, float)) for x in v):
            return np.array(v)
        return ", ".join(map(str, v))
    if isinstance(v, bool):
        return int(v)
    return v


def open_netcdf_bytes(data):
    """A NetCDF-4 file held in memory (bytes) as an ``xarray.Dataset``, loaded into memory.

    ``xr.open_dataset(io.BytesIO(data))`` does not work with Debian's packages:
    xarray's only in-memory NetCDF-4 engine is h5netcdf, which is not
    installed. netCDF4 opens the bytes itself (``netCDF4.Dataset(memory=...)``),
    and xarray reads that through its ``NetCDF4DataStore`` (docs/python.md).
    """
    try:
        import xarray as xr
    except ImportError:
        raise ImportError("reading a dataset needs xarray (Debian: apt-get install python3-xarray "
                          "python3-netcdf4); without it, use job.films() or job.save_dataset(path)") from None
    try:
        import netCDF4
    except ImportError:
        netCDF4 = None
    if netCDF4 is not None:
        nc = netCDF4.Dataset("raysweep-dataset.nc", mode="r", memory=bytes(data))
        try:
            with xr.open_dataset(xr.backends.NetCDF4DataStore(nc)) as ds:
                return ds.load()
        finally:
            if nc.isopen():
                nc.close()
    import io
    try:
        with xr.open_dataset(io.BytesIO(bytes(data)), engine="h5netcdf") as ds:
            return ds.load()
    except (ImportError, ValueError) as e:
        raise ImportError("reading a dataset needs netCDF4 (Debian: apt-get install python3-netcdf4) "
                          f"or h5netcdf: {e}") from None
