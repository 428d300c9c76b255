"""Films and datasets as numpy, xarray and NetCDF.

The optional packages (xarray, netCDF4) are imported here only, when first needed.
"""

import os
import socket
import tempfile

import numpy as np

from .errors import ConnectionFailed, RaysweepError

# What stream_to_file reads at a time.
_CHUNK = 1 << 20

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


def stokes_channels(names):
    """A Stokes film's channels (docs/polarization.md) as ``(labels, index)``, else None.

    Stokes films name their channels ``S0 .. S3`` (mono ``pixel_format:
    "stokes"``), ``S0.Y .. S3.Y`` (mono_polarized) or ``S0.R S0.G S0.B S1.R
    ... S3.B`` (rgb_polarized), and their planes ``brf.S0.Y`` (``brf.S0``).
    ``labels`` are the channel dimension's labels with the Stokes component
    taken out (``Y``, ``R G B``, ``brf.Y``, ...; the bare ``S0`` is ``Y``),
    ``index[k][c]`` the film channel of component k of label c.
    """
    where = {}
    labels = []
    for i, name in enumerate(names):
        parts = name.split(".")
        ks = [j for j, t in enumerate(parts) if len(t) == 2 and t[0] == "S" and t[1] in "0123"]
        if len(ks) != 1:
            return None
        j = ks[0]
        colour = ".".join(parts[j + 1:]) or "Y"
        label = ".".join(parts[:j] + [colour])
        if label not in labels:
            labels.append(label)
        key = (int(parts[j][1]), label)
        if key in where:
            return None
        where[key] = i
    if len(where) != 4 * len(labels):
        return None
    return labels, [[where[(k, lab)] for lab in labels] for k in range(4)]


def film_dataarray(film):
    """A JSON film as an ``xarray.DataArray`` over (y, x, channel), or (y, x, stokes, channel).

    Coordinates: ``channel`` (its names: ``Y`` or ``R G B``, then ``brf.Y``,
    ``radiance_stderr.Y``, ... for the planes asked for), ``wavelength`` (nm,
    mono), and for distant-family sensors ``vza`` and ``vaa`` (each pixel's
    viewing zenith and azimuth in degrees, Eradiate's convention) and, for a
    scene with one directional emitter, ``sza`` and ``saa``. The film's
    ``meta`` (scene, revision, sensor, spp, seed, variant, ...) is in ``attrs``,
    always with ``plugin_failures`` (environment plugin answers replaced by
    black while making the film; 0: none) and ``plugin_failure`` (the first
    one's message; "": none), as the datasets' variables of those names.
    A Stokes film (:func:`stokes_channels`) has a ``stokes`` dimension too,
    labelled ``S0 .. S3``: :func:`raysweep.dolp` and :func:`raysweep.aolp`
    take it.
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
    # The meta names plugin failures only when there were some; attrs always do.
    attrs["plugin_failures"] = int(meta.get("plugin_failures") or 0)
    attrs["plugin_failure"] = str(meta.get("plugin_failure") or "") if attrs["plugin_failures"] else ""
    attrs["units"] = _UNITS.get(meta.get("variant"), "W m-2 sr-1")
    attrs["long_name"] = "radiance"
    if meta.get("planes"):
        attrs["planes"] = ", ".join(f"{p['name']} [{p['units']}]" for p in meta["planes"])
    data = film_array(film)
    st = stokes_channels(film["channels"])
    if st is not None:
        labels, index = st
        coords["channel"] = labels
        coords["stokes"] = list(STOKES)
        data = np.stack([data[:, :, idx] for idx in index], axis=2)
        return xr.DataArray(data, dims=("y", "x", "stokes", "channel"), coords=coords, attrs=attrs,
                            name="radiance")
    return xr.DataArray(data, dims=("y", "x", "channel"), coords=coords, attrs=attrs, name="radiance")


STOKES = ("S0", "S1", "S2", "S3")
AOLP_CONVENTION = ("0.5 atan2(S2, S1) in degrees, in (-90, 90], 0 where S1 = S2 = 0; from x towards y of the "
                   "film's Stokes basis (docs/polarization.md#stokes-conventions)")


def _components(x, axis):
    """S0, S1, S2 of x: a DataArray or Dataset with a ``stokes`` dimension, or an array along ``axis``."""
    if hasattr(x, "data_vars"):  # a Dataset: its radiance (radiance_srf for bands)
        name = "radiance" if "radiance" in x.data_vars else "radiance_srf"
        if name not in x.data_vars:
            raise RaysweepError("dolp/aolp: the dataset has no radiance or radiance_srf variable")
        x = x[name]
    if hasattr(x, "dims"):
        if "stokes" not in x.dims:
            raise RaysweepError(f"dolp/aolp: no 'stokes' dimension in {tuple(x.dims)} (not a Stokes film)")
        return [x.sel(stokes=k) for k in STOKES[:3]], True
    a = np.asarray(x)
    if a.shape[axis] != 4:
        raise RaysweepError(f"dolp/aolp: axis {axis} has {a.shape[axis]} values, wanted S0..S3")
    return [np.take(a, k, axis=axis) for k in range(3)], False


def dolp(x, axis=-1):
    """The degree of linear polarization sqrt(S1^2 + S2^2) / S0 (0 where S0 = 0).

    ``x``: a film or dataset variable with a ``stokes`` dimension (``render``
    of a Stokes film, ``ds.radiance``, ``ds.radiance_srf``), a whole dataset
    (its radiance), or a numpy array whose ``axis`` holds S0..S3. Datasets
    carry it already as ``dolp`` (``dolp_srf`` for bands).
    """
    (s0, s1, s2), is_xr = _components(x, axis)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.sqrt(s1 * s1 + s2 * s2) / s0
    r = r.where(s0 != 0, 0.0) if is_xr else np.where(s0 == 0, 0.0, r)
    if is_xr:
        r.name = "dolp"
        r.attrs = {"long_name": "degree of linear polarization", "units": "1"}
    return r


def aolp(x, axis=-1):
    """The angle of linear polarization 0.5 atan2(S2, S1) in degrees, in (-90, 90].

    Takes what :func:`dolp` takes; 0 where S1 = S2 = 0. Datasets carry it
    already as ``aolp`` (``aolp_srf``), with the convention in its attrs.
    """
    (_, s1, s2), is_xr = _components(x, axis)
    if is_xr:
        import xarray as xr
        r = 0.5 * np.degrees(xr.apply_ufunc(np.arctan2, s2, s1))
    else:
        r = 0.5 * np.degrees(np.arctan2(s2, s1))
    r = r.where(r > -90, r + 180) if is_xr else np.where(r <= -90, r + 180, r)
    zero = (s1 == 0) & (s2 == 0)
    r = r.where(~zero, 0.0) if is_xr else np.where(zero, 0.0, r)
    if is_xr:
        r.name = "aolp"
        r.attrs = {"long_name": "angle of linear polarization", "units": "degree", "comment": AOLP_CONVENTION}
    return r


def _attr(v):
    """A value netCDF and xarray attrs take: lists of numbers as arrays, other lists as text."""
    if isinstance(v, list):
        if all(isinstance(x, (int, float)) for x in v):
            return np.array(v)
        return ", ".join(map(str, v))
    if isinstance(v, bool):
        return int(v)
    return v


def stream_to_file(http, path, dest):
    """GET ``path`` (a NetCDF-4 answer) into the file ``dest``, returned.

    The answer goes to a new file beside ``dest``, ``_CHUNK`` bytes at a time,
    and is renamed over ``dest`` once whole (its Content-Length, when the
    daemon sends one, checked): memory stays small whatever the size, and
    ``dest`` never holds part of an answer. Whatever goes wrong, the partial
    file is removed and the error raised (:class:`ConnectionFailed` for an
    answer cut short).
    """
    folder = os.path.dirname(os.path.abspath(dest))
    fd, part = tempfile.mkstemp(prefix="." + os.path.basename(dest) + ".", suffix=".part", dir=folder)
    try:
        with os.fdopen(fd, "wb") as f, http.open("GET", path, accept="application/x-netcdf", timeout=None) as r:
            want = r.headers.get("Content-Length")
            got = 0
            while True:
                try:
                    piece = r.read(_CHUNK)
                except (socket.timeout, TimeoutError, ConnectionError, OSError) as e:
                    raise ConnectionFailed(f"GET {path}: the answer stopped coming: {e}", method="GET",
                                           path=path) from None
                if not piece:
                    break
                f.write(piece)
                got += len(piece)
            if want is not None and want.isdigit() and got != int(want):
                raise ConnectionFailed(f"GET {path}: the answer ended after {got} of its {want} bytes",
                                       method="GET", path=path)
        os.replace(part, dest)
    except BaseException:
        try:
            os.unlink(part)
        except OSError:
            pass
        raise
    return dest


def open_netcdf_file(path):
    """The NetCDF-4 file ``path`` as an ``xarray.Dataset``, loaded into memory (the file closed)."""
    try:
        import xarray as xr
    except ImportError:
        raise ImportError("reading a dataset needs xarray (Debian: apt-get install python3-xarray "
                          "python3-netcdf4); without it, use job.films() or job.save_dataset(path)") from None
    try:
        with xr.open_dataset(path) as ds:
            return ds.load()
    except (ImportError, ValueError) as e:
        raise ImportError("reading a dataset needs netCDF4 (Debian: apt-get install python3-netcdf4) "
                          f"or h5netcdf: {e}") from None


def fetch_netcdf(http, path):
    """GET ``path`` (a NetCDF-4 answer) as an ``xarray.Dataset`` loaded into memory, through a
    temporary file ($TMPDIR, removed): the values are held once, not beside the file's bytes."""
    folder = tempfile.mkdtemp(prefix="raysweep-")
    try:
        return open_netcdf_file(stream_to_file(http, path, os.path.join(folder, "dataset.nc")))
    finally:
        for name in os.listdir(folder):
            os.unlink(os.path.join(folder, name))
        os.rmdir(folder)


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
