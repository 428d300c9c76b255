#!/usr/bin/env bash
# Bands over HTTP (docs/experiments.md#spectral-response-functions-bands), against a real daemon:
#   - a job with bands: its results list the nodes, the bands and the band
#     results; ?band=ID answers the band's film (brf plane = brf_srf,
#     wavelength null), ?node=K a node's; a band job's plain result is 422
#     (key "band"), an unknown band or node 404, both at once 422;
#   - its dataset, read by docs/examples/bands_dataset.py (xarray): the band
#     and wavelength dimensions, sza/saa, the *_srf variables;
#   - with --state-dir and films beyond the memory cap (served from disk),
#     the band film and the dataset are the same after a restart (bitwise
#     for the film's JSON), the sun's angles included.
# Ends with "test_bands_http: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_bands_http
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd raysweep
need_cmd curl "to talk to the daemon"
pyx=${RSW_PYTHON:-/usr/bin/python3}
"$pyx" -c 'import xarray, netCDF4' 2>/dev/null || {
  bad "$pyx cannot import xarray and netCDF4 (make deps installs python3-xarray python3-netcdf4)"
  finish
}
cd "$tmp" || exit 1

# The README's plate, 4x3 pixels, 16 spp.
python3 - "$root/proto/examples/hdistant_lambertian.json" >scene.json <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
s["sensor"]["film"].update(width=4, height=3)
s["sensor"]["sampler"]["sample_count"] = 16
print(json.dumps(s))
PY
cat >job.json <<'JSON'
{"quantities": ["brf"], "variance": true, "seed": 5,
 "bands": [{"id": "blue", "srf": {"type": "uniform", "wmin": 450, "wmax": 520}},
           {"id": "red", "srf": {"type": "gaussian", "mean": 640, "fwhm": 30}}],
 "contexts": [{"id": "c0"}, {"id": "c1", "params": {"sun.irradiance.value": 3.0}}]}
JSON

start_daemon "$tmp/d" --state-dir "$tmp/st" --max-result-bytes 100
[ -n "$started_port" ] || {
  bad "daemon did not start: $(tail -n 5 "$tmp/d/log")"
  finish
}
url=http://127.0.0.1:$started_port
jid() { python3 -c 'import json, sys; print(json.load(sys.stdin)["id"])'; }
scene=$(curl -s -X POST -H 'Content-Type: application/json' --data @scene.json "$url/v1/scenes" | jid)
job=$(curl -s -X POST -H 'Content-Type: application/json' --data @job.json "$url/v1/scenes/$scene/jobs" | jid)
if "$bin/raysweep" --server "$url" job watch "$job" >/dev/null 2>err; then ok; else bad "job watch: $(head -c 300 err)"; fi

get() { curl -s -o "$2" -w '%{http_code}' "$url/v1/jobs/$job/$1"; }
[ "$(get results results.json)" = 200 ] && ok || bad "results"
py "results: nodes, bands, band results" '
import json, sys
r = json.load(open("results.json"))
nodes = sorted({x["node"] for x in r["results"]})
assert [b["id"] for b in r["bands"]] == ["blue", "red"], r["bands"]
assert len(nodes) == sum(len(b["nodes"]) for b in r["bands"]), nodes
assert all(x["href"].endswith("?node=%d" % x["node"]) for x in r["results"])
assert len(r["band_results"]) == 4 and r["band_results"][0]["href"].endswith("?band=blue"), r["band_results"]
assert abs(r["bands"][0]["integral"] - 70) < 1e-9
'
[ "$(get 'results/c1/sensor?band=red' red.json)" = 200 ] && ok || bad "?band=red: $(head -c 300 red.json)"
py "band film: brf plane, no wavelength, the sun" '
import json
f = json.load(open("red.json"))
m = f["meta"]
assert m["wavelength"] is None and m["context"] == "c1", m
assert f["channels"] == ["Y", "brf.Y", "radiance_stderr.Y"], f["channels"]
assert m["sun_zenith_deg"] == 30 and m["sun_azimuth_deg"] == 180, m
assert abs(m["irradiance"][0] - 3 * 3 ** 0.5 / 2) < 1e-9, m["irradiance"]
'
[ "$(get 'results/c0/sensor?node=0' node0.json)" = 200 ] && ok || bad "?node=0"
py "node film: the first node" '
import json
f = json.load(open("node0.json")); r = json.load(open("results.json"))
assert f["meta"]["wavelength"] == r["bands"][0]["nodes"][0]["wavelength"], f["meta"]
'
code=$(get results/c0/sensor plain.json)
[ "$code" = 422 ] && grep -qF '"key":"band"' plain.json && ok || bad "plain result of a band job: $code $(head -c 300 plain.json)"
[ "$(get 'results/c0/sensor?band=nope' x)" = 404 ] && ok || bad "unknown band"
[ "$(get 'results/c0/sensor?node=99' x)" = 404 ] && ok || bad "unknown node"
[ "$(get 'results/c0/sensor?band=red&node=0' x)" = 422 ] && ok || bad "band and node at once"
code=$(curl -s -o red.npy -w '%{http_code}' -H 'Accept: application/x-npy' "$url/v1/jobs/$job/results/c0/sensor?band=red")
[ "$code" = 200 ] && ok || bad "?band=red as .npy: $code"

[ "$(get dataset bands.nc)" = 200 ] && ok || bad "dataset"
if "$pyx" "$root/docs/examples/bands_dataset.py" >example.out 2>pyerr; then ok; else bad "bands_dataset.py: $(tail -n 3 pyerr)"; fi
contains "example: band variables" example.out "('context', 'band', 'y', 'x')"
contains "example: the bands" example.out "['blue', 'red']"
contains "example: node wavelengths" example.out "('context', 'wavelength', 'y', 'x')"
contains "example: sza, saa" example.out "[30. 30.] [180. 180.]"
if "$pyx" -c '
import sys, xarray
d = xarray.open_dataset("bands.nc")
for v in ["radiance_srf", "radiance_srf_stderr", "brf_srf", "brf_srf_stderr", "irradiance_srf",
          "irradiance", "brf_stderr", "radiance", "brf", "radiance_stderr"]:
    assert v in d.data_vars, v
for c in ["sza", "saa", "vza", "vaa", "band", "wavelength"]:
    assert c in d.coords, c
assert d.irradiance_srf.dims == ("context", "band")
' 2>pyerr; then ok; else bad "dataset variables: $(tail -n 3 pyerr)"; fi

# A restart: films from disk, the same band film and dataset.
kill "${pids[-1]}" && wait "${pids[-1]}" 2>/dev/null
start_daemon "$tmp/d2" --state-dir "$tmp/st" --max-result-bytes 100
url=http://127.0.0.1:$started_port
[ "$(get 'results/c1/sensor?band=red' red2.json)" = 200 ] && ok || bad "?band=red after a restart: $(head -c 300 red2.json)"
cmp -s red.json red2.json && ok || bad "the band film differs after a restart"
[ "$(get dataset bands2.nc)" = 200 ] && ok || bad "dataset after a restart"
if "$pyx" -c '
import xarray
a, b = xarray.open_dataset("bands.nc"), xarray.open_dataset("bands2.nc")
for v in list(a.data_vars) + list(a.coords):
    assert a[v].equals(b[v]), v
' 2>pyerr; then ok; else bad "dataset after a restart: $(tail -n 3 pyerr)"; fi
finish
