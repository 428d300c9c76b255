#!/usr/bin/env bash
# Stokes films' results outside the kernel, end to end (docs/polarization.md,
# "Stokes results"): a mono `pixel_format: "stokes"` camera under the SDK
# example tests/plugins/polarized_sky.c (I = 1, Q = p cos 2chi, U = p sin 2chi:
# every ray that escapes sees DoLP = p and AoLP = chi exactly) and a
# normal-incidence sun of irradiance 2 (for brf: E_h = 2):
#   - `raysweep sweep --grid sky.polarization_angle=... --grid wavelength=...
#     --quantities brf --variance --format nc`: the dataset has a stokes
#     dimension labelled S0..S3, radiance / brf / radiance_stderr /
#     brf_stderr over (..., y, x, stokes) with every component, and dolp
#     (= p) and aolp (= chi, also for chi = 90 and -45) over (..., y, x),
#     with units, long_name and the AoLP convention;
#   - the daemon's dataset of the same job (`raysweep fetch JOB -o F.nc`) is
#     the client's, bitwise;
#   - the JSON films (and the job's result list) keep S0..S3, brf.S0..S3 and
#     radiance_stderr.S0..S3;
#   - the same scene in the variant mono_polarized (films S0.Y..S3.Y): the
#     same layout, variant "mono_polarized", dolp and aolp those of the
#     dataset's radiance, and the daemon's dataset is the client's; its PNG
#     quick-look is S0;
#   - the same in rgb_polarized (S0.R..S3.B): a channel dimension after
#     stokes, each colour's dolp; the daemon's dataset is the client's.
# Ends with "test_stokes_datasets: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_stokes_datasets
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweep raysweepd
need_cmd curl "to ask the daemon for a job's results"
py=${RSW_PYTHON:-/usr/bin/python3}
"$py" -c 'import xarray, netCDF4' 2>/dev/null || {
  bad "$py cannot import xarray and netCDF4 (make deps installs python3-xarray python3-netcdf4)"
  finish
}
plugins=$bin/../plugins
[ -f "$plugins/polarized_sky.so" ] || {
  bad "$plugins/polarized_sky.so is missing (make builds it)"
  finish
}
cd "$tmp" || exit 1
cat >scene.json <<'JSON'
{"type": "scene", "variant": "mono",
 "camera": {"type": "perspective", "fov": 20,
   "to_world": [{"lookat": {"origin": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0]}}],
   "sampler": {"type": "independent", "sample_count": 4},
   "film": {"type": "hdrfilm", "width": 3, "height": 2, "pixel_format": "stokes",
            "component_format": "float32", "rfilter": {"type": "box"}}},
 "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": 2.0},
 "sky": {"type": "polarized_sky", "polarization": 0.6}}
JSON
start_daemon "$tmp/d" --plugin-dir "$plugins"
[ -n "$started_port" ] || {
  bad "daemon did not start: $(tail -n 5 "$tmp/d/log")"
  finish
}
url=http://127.0.0.1:$started_port
rs() { "$bin/raysweep" --server "$url" "$@"; }
run() {
  local label=$1
  shift
  if "$@" >"$tmp/out" 2>"$tmp/err"; then ok; else bad "$label: exit $?; stderr: $(head -c 600 "$tmp/err")"; fi
}
pycheck() { # LABEL CODE ARGS...
  local label=$1 code=$2
  shift 2
  if "$py" -c "$code" "$@" 2>"$tmp/pyerr"; then ok; else bad "$label: $(tail -n 3 "$tmp/pyerr")"; fi
}

run "sweep a Stokes film --format nc" rs sweep scene.json --grid sky.polarization_angle=-45:90:45 \
  --grid wavelength=500:600:100 --quantities brf --variance --seed 5 --format nc -o sw
pycheck "the dataset: stokes dimension, every component, dolp and aolp" '
import math, sys
import numpy as np, xarray as xr
ds = xr.open_dataset(sys.argv[1])
assert list(ds.stokes.values) == ["S0", "S1", "S2", "S3"], ds.stokes.values
assert "channel" not in ds.dims, ds.dims
for q in ("radiance", "brf", "radiance_stderr", "brf_stderr"):
    assert ds[q].dims == ("polarization_angle", "wavelength", "y", "x", "stokes"), (q, ds[q].dims)
for q in ("dolp", "aolp"):
    assert ds[q].dims == ("polarization_angle", "wavelength", "y", "x"), (q, ds[q].dims)
assert ds.dolp.attrs["units"] == "1" and ds.dolp.attrs["long_name"] == "degree of linear polarization"
assert ds.aolp.attrs["units"] == "degree" and "atan2(S2, S1)" in ds.aolp.attrs["comment"], ds.aolp.attrs
assert "counter-clockwise" in ds.aolp.attrs["comment"]
chi = ds.polarization_angle.values
assert list(chi) == [-45, 0, 45, 90], chi
p = 0.6
want = np.stack([np.ones_like(chi), p * np.cos(np.radians(2 * chi)), p * np.sin(np.radians(2 * chi)),
                 np.zeros_like(chi)], axis=-1)  # (chi, stokes)
r = ds.radiance.values
assert np.allclose(r, want[:, None, None, None, :], atol=1e-6), r[:, 0, 0, 0]
assert np.allclose(ds.brf.values, math.pi * r / 2.0, rtol=1e-6), "brf = pi L / E_h per component"
assert np.allclose(ds.dolp.values, p, atol=1e-6), ds.dolp.values
got = ds.aolp.values[:, 0, 0, 0]
assert np.allclose(got, chi, atol=1e-4), got
assert np.allclose(ds.aolp.values, chi[:, None, None, None], atol=1e-4)
# sel by label: S0 is the unpolarized radiance
assert np.allclose(ds.radiance.sel(stokes="S0").values, 1.0, atol=1e-6)
' sw/dataset.nc
job=$("$py" -c 'import json; print(json.load(open("sw/sweep.json"))["job"])')
run "fetch the daemon's dataset" rs fetch "$job" -o daemon.nc
if "$py" "$root/tests/support/dataset_check.py" same daemon.nc sw/dataset.nc --ignore-attr job 2>"$tmp/pyerr"; then
  ok
else
  bad "daemon's dataset != the client's: $(tail -n 3 "$tmp/pyerr")"
fi
pycheck "the JSON films keep every component" '
import json, os, sys
d = sys.argv[1]
lines = [json.loads(l) for l in open(os.path.join(d, "index.jsonl"))]
assert len(lines) == 8, len(lines)
f = json.load(open(os.path.join(d, lines[0]["file"])))
want = [p + s for p in ("", "brf.", "radiance_stderr.") for s in ("S0", "S1", "S2", "S3")]
assert f["channels"] == want, f["channels"]
' sw
curl -s "$url/v1/jobs/$job/results" >results.json
pycheck "the job's results list S0..S3" '
import json, sys
r = json.load(open(sys.argv[1]))
items = r["results"] if isinstance(r, dict) else r
assert items and all(x["channels"][:4] == ["S0", "S1", "S2", "S3"] for x in items), str(items)[:400]
' results.json

# The variant mono_polarized: channels S0.Y..S3.Y (planes brf.S0.Y ...), the
# same layout; the sky's Stokes vector reaches each pixel turned into the
# camera's basis, so DoLP and AoLP are checked against the dataset's own
# radiance (and DoLP <= p: averaging turned vectors never polarizes more).
sed 's/"variant": "mono"/"variant": "mono_polarized"/; s/"pixel_format": "stokes",//' scene.json >mp.json
run "sweep a mono_polarized film --format nc" rs sweep mp.json --grid sky.polarization_angle=-45:90:45 \
  --quantities brf --variance --seed 5 --format nc -o mp
pycheck "mono_polarized: S0.Y films, the same dataset layout" '
import json, os, sys
import numpy as np, xarray as xr
d = sys.argv[1]
ds = xr.open_dataset(os.path.join(d, "dataset.nc"))
assert ds.attrs["variant"] == "mono_polarized", ds.attrs["variant"]
assert ds.radiance.dims == ("polarization_angle", "y", "x", "stokes"), ds.radiance.dims
assert ds.brf.dims == ds.radiance.dims and ds.dolp.dims == ("polarization_angle", "y", "x")
r = ds.radiance.values.astype(np.float64)
dolp = np.hypot(r[..., 1], r[..., 2]) / r[..., 0]
assert np.allclose(ds.dolp.values, dolp, atol=1e-6), (ds.dolp.values, dolp)
assert (ds.dolp.values <= 0.6 + 1e-6).all() and (ds.dolp.values > 0).all(), ds.dolp.values
a = 0.5 * np.degrees(np.arctan2(r[..., 2], r[..., 1]))
diff = (ds.aolp.values - a + 90) % 180 - 90
assert np.abs(diff).max() < 1e-3, diff
assert np.allclose(r[..., 0], 1.0, atol=1e-6)
line = json.loads(open(os.path.join(d, "index.jsonl")).readline())
ch = json.load(open(os.path.join(d, line["file"])))["channels"]
assert ch[:5] == ["S0.Y", "S1.Y", "S2.Y", "S3.Y", "brf.S0.Y"], ch
' mp
mjob=$("$py" -c 'import json; print(json.load(open("mp/sweep.json"))["job"])')
run "fetch the daemon's mono_polarized dataset" rs fetch "$mjob" -o mp_daemon.nc
if "$py" "$root/tests/support/dataset_check.py" same mp_daemon.nc mp/dataset.nc --ignore-attr job 2>"$tmp/pyerr"; then
  ok
else
  bad "mono_polarized: the daemon's dataset != the client's: $(tail -n 3 "$tmp/pyerr")"
fi
# The PNG quick-look of a Stokes film is its S0 (here 1: white at 0 EV).
mscene=$(rs -q scene push mp.json)
run "render a mono_polarized film to PNG" rs render "$mscene" --spp 4 -o mp.png
pycheck "the PNG shows S0" '
import sys
sys.path.insert(0, sys.argv[2])
import png_read
w, h, ch, rows = png_read.decode_png(open(sys.argv[1], "rb").read(), (0,))
assert (w, h, ch) == (3, 2, 1), (w, h, ch)
assert all(v == 255 for r in rows for v in r), rows
' mp.png "$root/tests/support"
# The variant rgb_polarized (environment plugins serve mono only, so a
# Rayleigh medium: a camera looking horizontally through it under a sun at
# the zenith sees single scattering at 90 degrees, DoLP 1 and AoLP 0 in
# every colour): channels S0.R S0.G S0.B S1.R ... S3.B; the dataset gains
# the channel dimension after stokes, dolp per colour; the daemon's dataset
# is the client's; the film's JSON lists the 12 channels and their planes.
cat >rp.json <<'JSON'
{"type": "scene", "variant": "rgb_polarized",
 "air": {"type": "homogeneous", "sigma_t": 0.05, "albedo": {"type": "rgb", "value": [0.9, 0.6, 0.3]},
         "phase": {"type": "rayleigh"}},
 "box": {"type": "cube", "to_world": [{"scale": [50, 50, 50]}], "bsdf": {"type": "null"},
         "interior": {"type": "ref", "id": "air"}},
 "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": 1.0},
 "cam": {"type": "perspective", "fov": 0.1, "medium": {"type": "ref", "id": "air"},
         "to_world": [{"lookat": {"origin": [0, 0, 0], "target": [1, 0, 0], "up": [0, 0, 1]}}],
         "sampler": {"type": "independent", "sample_count": 64},
         "film": {"type": "hdrfilm", "width": 3, "height": 2, "component_format": "float32",
                  "rfilter": {"type": "box"}}},
 "integrator": {"type": "volpath", "max_depth": 2}}
JSON
run "sweep an rgb_polarized film --format nc" rs sweep rp.json --grid sun.irradiance.value=1:2:1 \
  --quantities brf --variance --seed 5 --format nc -o rp
pycheck "rgb_polarized: S0.R..S3.B films, stokes x channel" '
import json, os, sys
import numpy as np, xarray as xr
d = sys.argv[1]
ds = xr.open_dataset(os.path.join(d, "dataset.nc"))
assert ds.attrs["variant"] == "rgb_polarized", ds.attrs["variant"]
assert ds.radiance.dims[-4:] == ("y", "x", "stokes", "channel"), ds.radiance.dims
assert list(ds.channel.values) == ["R", "G", "B"], ds.channel.values
assert ds.dolp.dims == ds.radiance.dims[:-2] + ("channel",), ds.dolp.dims
r = ds.radiance.values.astype(np.float64)
s0 = r[..., 0, :]
assert (s0 > 0).all() and (np.diff(s0, axis=-1) < 0).all(), s0  # albedo 0.9 > 0.6 > 0.3
assert np.allclose(ds.dolp.values, 1.0, atol=1e-5), ds.dolp.values
assert np.allclose(ds.aolp.values, 0.0, atol=1e-3), ds.aolp.values
line = json.loads(open(os.path.join(d, "index.jsonl")).readline())
ch = json.load(open(os.path.join(d, line["file"])))["channels"]
assert ch[:13] == ["S0.R", "S0.G", "S0.B", "S1.R", "S1.G", "S1.B", "S2.R", "S2.G", "S2.B",
                   "S3.R", "S3.G", "S3.B", "brf.S0.R"], ch
' rp
rjob=$("$py" -c 'import json; print(json.load(open("rp/sweep.json"))["job"])')
run "fetch the daemon's rgb_polarized dataset" rs fetch "$rjob" -o rp_daemon.nc
if "$py" "$root/tests/support/dataset_check.py" same rp_daemon.nc rp/dataset.nc --ignore-attr job 2>"$tmp/pyerr"; then
  ok
else
  bad "rgb_polarized: the daemon's dataset != the client's: $(tail -n 3 "$tmp/pyerr")"
fi
# Under `make test SAN=1` a sanitizer report in the daemon's log is a failure.
if grep -qE 'Sanitizer|runtime error:' "$tmp/d/log"; then bad "$(grep -m 3 -E 'Sanitizer|runtime error:' "$tmp/d/log")"; else ok; fi
finish
