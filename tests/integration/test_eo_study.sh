#!/usr/bin/env bash
# The Earth-observation study of docs/experiments.md, end to end against a
# real daemon: docs/examples/eo_study.json (molecular atmosphere, aerosol
# layer, RPV, Thuillier sun, a principal-plane mdistant, a sun template),
# docs/examples/eo_job.json (4 sun zeniths x 2 bands, contexts that carry
# only their coordinate), the dataset read by docs/examples/eo_dataset.py.
# Checks:
#   - the job is accepted without warnings, succeeds, and its dataset has
#     the sza/band/wavelength dimensions and the band variables;
#   - the sun's angles in the dataset are the contexts' sza (saa 0 but at
#     the zenith, never -0: atan2(-0, x) once printed "-0");
#   - physics that would catch a wrong sun or view mapping: with the sun
#     overhead the BRF is symmetric about nadir (the two 30° and the two
#     60° views agree within 4 combined standard errors); at sza 60 the
#     hot spot (view 60° on the sun's side) is the brightest direction,
#     and brighter than the opposite 60° view by more than 4 standard
#     errors; every band BRF lies in (0.1, 0.7) with a standard error
#     under 10% of it;
#   - the example's output names both bands and the four sun zeniths.
# Ends with "test_eo_study: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_eo_study
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd curl "to talk to the daemon"
pyx=${RSW_PYTHON:-/usr/bin/python3}
"$pyx" -c 'import xarray, netCDF4' 2>/dev/null || {
  bad "$pyx cannot import xarray and netCDF4 (make deps installs python3-xarray python3-netcdf4)"
  finish
}
cd "$tmp" || exit 1
start_daemon "$tmp/d"
[ -n "$started_port" ] || {
  bad "daemon did not start: $(tail -n 5 "$tmp/d/log")"
  finish
}
url=http://127.0.0.1:$started_port
jid() { python3 -c 'import json, sys; print(json.load(sys.stdin)["id"])'; }
scene=$(curl -s -X POST -H 'Content-Type: application/json' --data-binary @"$root/docs/examples/eo_study.json" \
  "$url/v1/scenes" | jid)
[ -n "$scene" ] && ok || bad "the scene was refused"
curl -s -X POST -H 'Content-Type: application/json' --data-binary @"$root/docs/examples/eo_job.json" \
  "$url/v1/scenes/$scene/jobs" >job.json
job=$(jid <job.json)
py "accepted without warnings" 'import json; j = json.load(open("job.json")); assert "warnings" not in j, j' 
for _ in $(seq 1200); do
  state=$(curl -s "$url/v1/jobs/$job" | python3 -c 'import json, sys; print(json.load(sys.stdin)["state"])')
  case $state in queued | running) sleep 0.1 ;; *) break ;; esac
done
[ "$state" = succeeded ] && ok || bad "job state $state"
code=$(curl -s -o eo.nc -w '%{http_code}' "$url/v1/jobs/$job/dataset")
[ "$code" = 200 ] && ok || bad "dataset: $code"
if "$pyx" "$root/docs/examples/eo_dataset.py" >example.out 2>pyerr; then ok; else bad "eo_dataset.py: $(tail -n 3 pyerr)"; fi
for want in "band B3:" "band B4:" "sza    0:" "sza   60:"; do
  grep -qF "$want" example.out && ok || bad "example output lacks '$want': $(head -c 400 example.out)"
done
if "$pyx" -c '
import numpy as np, xarray as xr
d = xr.open_dataset("eo.nc")
assert d.brf_srf.dims == ("sza", "band", "y", "x"), d.brf_srf.dims
assert list(d.sza.values) == [0, 20, 40, 60], d.sza.values
assert list(d.band.values) == ["B3", "B4"], d.band.values
assert d.sizes["wavelength"] > 2 and d.sizes["x"] == 5
assert np.allclose(d.saa.values[1:], 0), d.saa.values
assert not np.signbit(d.saa.values).any() and not np.signbit(d.vaa.values).any(), (d.saa.values, d.vaa.values)
vza = d.vza.isel(y=0).values
assert np.allclose(vza, [60, 30, 0, 30, 60], atol=1e-5), vza
b, s = d.brf_srf.isel(y=0).values, d.brf_srf_stderr.isel(y=0).values
assert np.all((b > 0.1) & (b < 0.7)), b
assert np.all(s < 0.1 * b), s / b
for k in range(2):
    for i, j in ((0, 4), (1, 3)):  # sza 0: symmetric about nadir
        z = abs(b[0, k, i] - b[0, k, j]) / np.hypot(s[0, k, i], s[0, k, j])
        assert z < 4, ("symmetry", k, i, j, z)
    hot = b[3, k]  # sza 60: the hot spot is the last direction (the sun on +x)
    assert hot.argmax() == 4, hot
    assert (hot[4] - hot[0]) / np.hypot(s[3, k, 4], s[3, k, 0]) > 4, hot
' 2>pyerr; then ok; else bad "dataset figures: $(tail -n 3 pyerr)"; fi
finish
