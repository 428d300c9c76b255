"""Checks of sweep datasets (NetCDF-4) with xarray, for tests/integration/test_dataset.sh.

    dataset_check.py grid DATASET SWEEPDIR VERSION SEED
        DATASET is the 2x3 grid sweep (wavelength x reflectance) of SWEEPDIR
        (a `raysweep sweep --format json|nc` directory): dims, coords,
        attributes, and every value against the per-film JSON results that
        index.jsonl lists.
    dataset_check.py same A B [--ignore-attr NAME]...
        A and B hold the same variables, coordinates and data, bitwise
        (NaN where NaN), and the same global attributes but the ignored ones.
    dataset_check.py context DATASET N
        a job whose coords do not form a grid: one "context" dimension of N,
        the coords a and b as coordinates along it.
    dataset_check.py failures DATASET SWEEPDIR some|none
        each film's plugin_failures (uint64 over the contexts' dimensions,
        with long_name and comment) and plugin_failure (its first message)
        equal the JSON film meta's (absent: 0 and ""); "some": every film
        has failures, named by the failing_sky plugin; "none": every count
        is 0.

Exit status 0 when every check passes; otherwise the first failure on stderr.
"""
import json
import os
import sys

import numpy as np
import xarray as xr


def fail(msg):
    sys.stderr.write(msg + "\n")
    sys.exit(1)


def check(cond, msg):
    if not cond:
        fail(msg)


def grid(path, sweep_dir, version, seed):
    ds = xr.open_dataset(path)
    check(dict(ds.sizes) == {"wavelength": 2, "reflectance": 3, "y": 3, "x": 4}, f"dims {dict(ds.sizes)}")
    check(list(ds.wavelength.values) == [450.0, 550.0], f"wavelength {ds.wavelength.values}")
    check(np.allclose(ds.reflectance.values, [0.2, 0.4, 0.6], rtol=0, atol=1e-12),
          f"reflectance {ds.reflectance.values}")
    check(ds.radiance.dims == ("wavelength", "reflectance", "y", "x"), f"radiance dims {ds.radiance.dims}")
    check(ds.radiance.dtype == np.float32, f"radiance dtype {ds.radiance.dtype}")
    a = ds.radiance.attrs
    check(a.get("units") == "W m-2 sr-1 nm-1" and a.get("long_name") == "radiance", f"radiance attrs {a}")
    check(ds.wavelength.attrs.get("units") == "nm", "wavelength units")
    for v in ("vza", "vaa"):
        check(v in ds.coords and ds[v].dims == ("y", "x"), f"{v} is not a (y, x) coordinate")
        check(ds[v].attrs.get("units") == "degree", f"{v} units")
    g = ds.attrs
    check(g.get("Conventions") == "CF-1.10", f"Conventions {g.get('Conventions')}")
    check(g.get("raysweep_version") == version, f"raysweep_version {g.get('raysweep_version')} != {version}")
    check(g.get("variant") == "mono", f"variant {g.get('variant')}")
    check(int(g.get("seed", -1)) == seed, f"seed {g.get('seed')}")
    check(int(g.get("spp", -1)) == 16, f"spp {g.get('spp')}")
    check(int(g.get("revision", -1)) == 0, f"revision {g.get('revision')}")
    check(len(g.get("scene", "")) == 64, f"scene {g.get('scene')}")
    # ds.radiance.sel(wavelength=550) works: docs/client.md's promise.
    check(ds.radiance.sel(wavelength=550).shape == (3, 3, 4), "sel(wavelength=550)")
    n = 0
    with open(os.path.join(sweep_dir, "index.jsonl")) as f:
        for line in f:
            e = json.loads(line)
            with open(os.path.join(sweep_dir, e["file"])) as ff:
                film = json.load(ff)
            wl = e["wavelength"]
            r = e["params"]["surface.bsdf.reflectance.value"]
            check(e["coords"] == {"wavelength": wl, "reflectance": r}, f"index coords {e.get('coords')}")
            cell = ds.sel(wavelength=wl, reflectance=r)
            want = np.array(film["data"], dtype=np.float32).reshape(film["height"], film["width"])
            got = cell.radiance.values
            check(got.tobytes() == want.tobytes(), f"{e['file']}: radiance {got} != film {want}")
            check(cell.context.item() == e["context"], f"context {cell.context.item()} != {e['context']}")
            check(int(cell.seed.item()) == e["seed"], f"seed {cell.seed.item()} != {e['seed']}")
            zen = np.array(film["meta"]["zenith_deg"]).reshape(3, 4)
            az = np.array(film["meta"]["azimuth_deg"]).reshape(3, 4)
            check(np.allclose(ds.vza.values, zen, atol=1e-6) and np.allclose(ds.vaa.values, az, atol=1e-6),
                  "vza/vaa differ from the film's zenith_deg/azimuth_deg")
            check(film["meta"]["scene"] == g["scene"], "scene")
            n += 1
    check(n == 6, f"{n} films in the index, wanted 6")


def same(a_path, b_path, ignore):
    a, b = xr.open_dataset(a_path), xr.open_dataset(b_path)
    check(dict(a.sizes) == dict(b.sizes), f"dims {dict(a.sizes)} != {dict(b.sizes)}")
    check(sorted(a.variables) == sorted(b.variables), f"variables {sorted(a.variables)} != {sorted(b.variables)}")
    for v in a.variables:
        x, y = a[v], b[v]
        check(x.dims == y.dims, f"{v}: dims {x.dims} != {y.dims}")
        check(x.dtype == y.dtype, f"{v}: dtype {x.dtype} != {y.dtype}")
        if x.dtype.kind in "fiu":
            check(x.values.tobytes() == y.values.tobytes(), f"{v}: values differ")
        else:
            check(list(x.values.ravel()) == list(y.values.ravel()), f"{v}: values differ")
        check(x.attrs == y.attrs, f"{v}: attributes {x.attrs} != {y.attrs}")
    ga = {k: v for k, v in a.attrs.items() if k not in ignore}
    gb = {k: v for k, v in b.attrs.items() if k not in ignore}
    check(ga == gb, f"global attributes {ga} != {gb}")


def context(path, n):
    ds = xr.open_dataset(path)
    check(dict(ds.sizes) == {"context": n, "y": 3, "x": 4}, f"dims {dict(ds.sizes)}")
    check(ds.radiance.dims == ("context", "y", "x"), f"radiance dims {ds.radiance.dims}")
    check(list(ds.context.values) == [f"k{i}" for i in range(n)], f"context {ds.context.values}")
    check("a" in ds.coords and ds.a.dims == ("context",), "coord a along context")
    check("b" in ds.coords and ds.b.dims == ("context",), "coord b along context")
    check(list(ds.a.values) == [1.0, 1.0, 2.0] and list(ds.b.values) == ["x", "y", "x"],
          f"coords {ds.a.values} {ds.b.values}")
    check("wavelength" in ds.coords and list(ds.wavelength.values) == [500.0, 500.0, 600.0],
          f"wavelength {ds.get('wavelength')}")
    check(not np.isnan(ds.radiance.values).any(), "NaN in a complete job")


def planes(path, sweep_dir):
    """brf, brdf and radiance_stderr beside radiance, with the values of the
    films' plane channels (brf.Y ...) and brf = pi brdf."""
    ds = xr.open_dataset(path)
    for q in ("brf", "brdf", "radiance_stderr"):
        check(q in ds.data_vars, f"no {q} variable: {sorted(ds.data_vars)}")
        if q in ds.data_vars:
            check(ds[q].dims == ds.radiance.dims, f"{q} dims {ds[q].dims} != radiance {ds.radiance.dims}")
    check(ds.brf.attrs.get("units") == "1" and ds.brdf.attrs.get("units") == "sr-1",
          f"units brf {ds.brf.attrs.get('units')}, brdf {ds.brdf.attrs.get('units')}")
    brf, brdf = ds.brf.values.astype(np.float64), ds.brdf.values.astype(np.float64)
    check(np.allclose(brf, np.pi * brdf, rtol=1e-6), "brf != pi brdf")
    # A Lambertian plate under a sun is the zero-variance case.
    check((ds.radiance_stderr.values == 0).all(), "radiance_stderr of a Lambertian plate is not 0")
    # Every value against the films' own channels.
    n = 0
    for line in open(os.path.join(sweep_dir, "index.jsonl")):
        e = json.loads(line)
        film = json.load(open(os.path.join(sweep_dir, e["file"])))
        names = film["channels"]
        data = np.asarray(film["data"], dtype=np.float32).reshape(film["height"], film["width"], len(names))
        sel = {k: v for k, v in e.get("coords", {}).items()}
        for q in ("brf", "brdf", "radiance_stderr"):
            got = ds[q].sel(sel).values
            want = data[:, :, names.index(q + ".Y")]
            check(got.tobytes() == want.tobytes(), f"{q} at {sel} differs from {e['file']}")
        n += 1
    check(n == 6, f"{n} films in index.jsonl, wanted 6")


def failures(path, sweep_dir, want):
    ds = xr.open_dataset(path)
    for v in ("plugin_failures", "plugin_failure"):
        check(v in ds.data_vars, f"no {v} variable: {sorted(ds.data_vars)}")
    n, m = ds.plugin_failures, ds.plugin_failure
    ctx_dims = ds.radiance.dims[:-2]
    check(n.dims == ctx_dims and m.dims == ctx_dims, f"dims {n.dims}, {m.dims}, wanted {ctx_dims}")
    check(n.dtype == np.uint64, f"plugin_failures dtype {n.dtype}")
    check(n.attrs.get("units") == "1" and "replaced by black" in n.attrs.get("long_name", "") and
          "non-finite or negative" in n.attrs.get("comment", ""), f"plugin_failures attrs {n.attrs}")
    check("comment" in m.attrs, f"plugin_failure attrs {m.attrs}")
    films = 0
    for line in open(os.path.join(sweep_dir, "index.jsonl")):
        e = json.loads(line)
        meta = json.load(open(os.path.join(sweep_dir, e["file"])))["meta"]
        cell = ds.sel(e.get("coords", {}))
        got, msg = int(cell.plugin_failures.item()), cell.plugin_failure.item()
        check(got == meta.get("plugin_failures", 0) and msg == meta.get("plugin_failure", ""),
              f"{e['file']}: dataset says {got} '{msg}', the film {meta.get('plugin_failures')} "
              f"'{meta.get('plugin_failure')}'")
        if want == "some":
            check(got > 0 and "add_radiance returned I =" in msg and "failing_sky" in msg,
                  f"{e['file']}: {got} '{msg}', wanted failures of failing_sky")
        else:
            check(got == 0 and msg == "", f"{e['file']}: {got} '{msg}', wanted none")
        films += 1
    check(films == n.size and films > 0, f"{films} films in index.jsonl, the dataset has {n.size}")


def main():
    cmd = sys.argv[1]
    if cmd == "grid":
        grid(sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5]))
    elif cmd == "same":
        ignore = [sys.argv[i + 1] for i in range(4, len(sys.argv) - 1) if sys.argv[i] == "--ignore-attr"]
        same(sys.argv[2], sys.argv[3], ignore)
    elif cmd == "planes":
        planes(sys.argv[2], sys.argv[3])
    elif cmd == "failures":
        failures(sys.argv[2], sys.argv[3], sys.argv[4])
    elif cmd == "context":
        context(sys.argv[2], int(sys.argv[3]))
    else:
        fail(f"unknown check {cmd}")


if __name__ == "__main__":
    main()
