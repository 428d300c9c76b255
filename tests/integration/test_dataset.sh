#!/usr/bin/env bash
# A sweep is one dataset (NetCDF-4, CF conventions), read back with
# Debian's python3-xarray + python3-netcdf4 (tests/support/dataset_check.py):
#   - a 2x3 grid sweep (wavelength x reflectance, `raysweep sweep --grid ...
#     --format nc`): dims, coords, attributes, and every value against the
#     per-film JSON results; the daemon's own dataset of the same job
#     (`raysweep fetch JOB -o F.nc`, GET /v1/jobs/{id}/dataset) holds the
#     same data bitwise;
#   - the sweep in two shards, merged (`raysweep merge`), and run with
#     --spread 2: the same dataset as the unsharded one (every variable
#     bitwise, the attributes equal);
#   - a job whose coords are not a grid: one "context" dimension;
#   - a finished job's dataset survives a restart with --state-dir; it is
#     answered from a file in the blob directory, which is gone after;
#   - docs/client.md's xarray example (docs/examples/dataset.py) runs on it;
#   - bad coords are 422 naming the JSON pointer; the dataset of a running
#     job is 409 unless ?partial=1; a film's fetch cannot be .nc.
# Ends with "test_dataset: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_dataset
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweep raysweepd
need_cmd curl "to ask the daemon for datasets"
need_xarray
cd "$tmp" || exit 1

run() {
  local label=$1
  shift
  if "$@" >"$tmp/out" 2>"$tmp/err"; then ok; else bad "$label: exit $?; stderr: $(head -c 600 "$tmp/err")"; fi
}

# A small mono hdistant scene (4x3 pixels, 16 spp) over a Lambertian plate.
"$py" - "$root/proto/examples/hdistant_lambertian.json" >scene.json <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
s["sensor"]["film"].update(width=4, height=3)
s["sensor"]["sampler"]["sample_count"] = 16
print(json.dumps(s))
PY

start_daemon "$tmp/d"
[ -n "$started_port" ] || {
  bad "daemon did not start: $(tail -n 5 "$tmp/d/log")"
  finish
}
url=http://127.0.0.1:$started_port
rs() { "$bin/raysweep" --server "$url" "$@"; }
version=$("$bin/raysweep" --version | awk '{print $2}')

grid=(--grid wavelength=450:550:100 --grid surface.bsdf.reflectance.value=0.2:0.6:0.2 --seed 3)
run "sweep --format nc" rs sweep scene.json "${grid[@]}" --format nc -o full
[ -f full/dataset.nc ] && ok || bad "sweep --format nc wrote no full/dataset.nc"
ds "grid sweep dataset" grid full/dataset.nc full "$version" 3
# docs/client.md's example (docs/examples/dataset.py) on this sweep.
ln -s full sweep_nc
if "$py" "$root/docs/examples/dataset.py" >example.out 2>pyerr; then ok; else bad "docs/examples/dataset.py: $(tail -n 2 pyerr)"; fi
contains "docs/examples/dataset.py prints the dims" example.out "('wavelength', 'reflectance', 'y', 'x')"
job=$("$py" -c 'import json; print(json.load(open("full/sweep.json"))["job"])')
run "fetch JOB -o F.nc" rs fetch "$job" -o daemon.nc
ds "grid: the daemon's dataset" grid daemon.nc full "$version" 3
ds "daemon's dataset = the client's" same daemon.nc full/dataset.nc --ignore-attr job
contains "daemon's dataset names its job" <("$py" -c 'import sys, xarray; print(xarray.open_dataset(sys.argv[1]).attrs["job"])' daemon.nc) "$job"

# Two shards merged: the unsharded dataset.
run "shard 0/2" rs sweep scene.json "${grid[@]}" --format nc --shard 0/2 -o s0
run "shard 1/2" rs sweep scene.json "${grid[@]}" --format nc --shard 1/2 -o s1
run "merge" rs merge s0 s1 -o merged
ds "merged shards = unsharded" same merged/dataset.nc full/dataset.nc
ds "merged grid dataset" grid merged/dataset.nc merged "$version" 3
run "sweep --spread 2 --format nc" rs sweep scene.json "${grid[@]}" --format nc --spread 2 -o spread
ds "--spread dataset = unsharded" same spread/dataset.nc full/dataset.nc

# brf, brdf and radiance_stderr are dataset variables too (the daemon's
# planes, the client's "<plane>.<channel>" film channels: the same file).
run "sweep --quantities --variance --format nc" rs sweep scene.json "${grid[@]}" --quantities brf,brdf \
  --variance --format nc -o planes
ds "planes: variables and values" planes planes/dataset.nc planes
pjob=$("$py" -c 'import json; print(json.load(open("planes/sweep.json"))["job"])')
run "fetch JOB -o F.nc (planes)" rs fetch "$pjob" -o planes_daemon.nc
ds "planes: daemon's dataset = the client's" same planes_daemon.nc planes/dataset.nc --ignore-attr job

# Not a grid: a context dimension, the coords along it.
scene=$(rs scene push scene.json 2>/dev/null)
cat >job.json <<'JSON'
{"contexts": [
  {"id": "k0", "wavelength": 500, "coords": {"a": 1, "b": "x"}},
  {"id": "k1", "wavelength": 500, "coords": {"a": 1, "b": "y"}},
  {"id": "k2", "wavelength": 600, "coords": {"a": 2, "b": "x"}}]}
JSON
ctxjob=$(curl -s -X POST -H 'Content-Type: application/json' --data @job.json "$url/v1/scenes/$scene/jobs" |
  "$py" -c 'import json, sys; print(json.load(sys.stdin)["id"])')
run "job watch" rs job watch "$ctxjob"
run "fetch the non-grid dataset" rs fetch "$ctxjob" -o ctx.nc
ds "non-grid job: context dimension" context ctx.nc 3
code=$(curl -s -o hdr.nc -D hdr -w '%{http_code}' "$url/v1/jobs/$ctxjob/dataset")
[ "$code" = 200 ] && ok || bad "GET dataset: $code"
contains "dataset media type" hdr "Content-Type: application/x-netcdf"
[ "$(head -c 4 hdr.nc | od -An -c | tr -d ' ')" = "211HDF" ] && ok || bad "the dataset is not an HDF5 (NetCDF-4) file"

# Bad coords: 422 naming the JSON pointer.
post() { curl -s -o resp -w '%{http_code}' -X POST -H 'Content-Type: application/json' --data "$1" "$url/v1/scenes/$scene/jobs"; }
badc() { # LABEL BODY POINTER
  local code
  code=$(post "$2")
  if [ "$code" = 422 ] && grep -qF "\"pointer\":\"$3\"" resp; then ok; else bad "$1: $code $(head -c 300 resp)"; fi
}
badc "coords not an object" '{"contexts":[{"id":"a","coords":[1]}]}' /contexts/0/coords
badc "a coord neither number nor string" '{"contexts":[{"id":"a","coords":{"k":true}}]}' /contexts/0/coords/k
badc "types mixed across contexts" '{"contexts":[{"id":"a","coords":{"k":1}},{"id":"b","coords":{"k":"s"}}]}' /contexts/1/coords/k
badc "a context without the coords" '{"contexts":[{"id":"a","coords":{"k":1}},{"id":"b"}]}' /contexts/1
badc "a coord the others lack" '{"contexts":[{"id":"a","coords":{"k":1}},{"id":"b","coords":{"k":2,"m":3}}]}' /contexts/1/coords/m
badc "a name the dataset uses" '{"contexts":[{"id":"a","coords":{"x":1}}]}' /contexts/0/coords/x
badc "too many coords" '{"contexts":[{"id":"a","coords":{"a":1,"b":1,"c":1,"d":1,"e":1,"f":1,"g":1,"h":1,"i":1}}]}' /contexts/0/coords
badc "a bad name" '{"contexts":[{"id":"a","coords":{"9a":1}}]}' /contexts/0/coords/9a

# A running job: 409 problem+json, unless ?partial=1.
slow=$(curl -s -X POST -H 'Content-Type: application/json' \
  --data '{"contexts":[{"id":"quick","spp":1},{"id":"slow","spp":4000000}]}' "$url/v1/scenes/$scene/jobs" |
  "$py" -c 'import json, sys; print(json.load(sys.stdin)["id"])')
for _ in $(seq 100); do
  curl -s "$url/v1/jobs/$slow" | grep -q '"renders_done":1' && break
  sleep 0.1
done
code=$(curl -s -o resp -D hdr -w '%{http_code}' "$url/v1/jobs/$slow/dataset")
[ "$code" = 409 ] && grep -qi 'content-type: application/problem+json' hdr && ok || bad "running job's dataset: $code"
code=$(curl -s -o partial.nc -w '%{http_code}' "$url/v1/jobs/$slow/dataset?partial=1")
[ "$code" = 200 ] && ok || bad "?partial=1: $code $(head -c 300 partial.nc)"
"$py" -c '
import sys, numpy as np, xarray as xr
ds = xr.open_dataset(sys.argv[1])
r = ds.radiance
assert r.dims[0] == "context" and list(ds.context.values) == ["quick", "slow"], ds
assert not np.isnan(r.values[0]).any() and np.isnan(r.values[1]).all(), r.values
assert int(ds.attrs["films_missing"]) == 1
# A missing film has no plugin failure count (the fill: NaN), a clean one 0.
n = ds.plugin_failures.values
assert n[0] == 0 and np.isnan(n[1]), n
' partial.nc 2>pyerr && ok || bad "partial dataset: $(tail -n 2 pyerr)"
expect 0 "fetch --partial" rs fetch "$slow" -o partial2.nc --partial
expect 1 "fetch of a running job's dataset" rs fetch "$slow" -o running.nc
curl -s -o /dev/null -X POST "$url/v1/jobs/$slow:cancel"
code=$(curl -s -o resp -w '%{http_code}' -H 'Accept: application/json' "$url/v1/jobs/$ctxjob/dataset")
[ "$code" = 406 ] && ok || bad "Accept: application/json: $code"
code=$(curl -s -o resp -w '%{http_code}' "$url/v1/jobs/$ctxjob/dataset?partial=maybe")
[ "$code" = 400 ] && ok || bad "?partial=maybe: $code"
code=$(curl -s -o resp -w '%{http_code}' "$url/v1/jobs/job-nope/dataset")
[ "$code" = 404 ] && ok || bad "unknown job: $code"
# A restart with --state-dir: the dataset of a finished job (its films
# served from disk, its coords and seed from the stored request) is the same.
start_daemon "$tmp/d2" --state-dir "$tmp/st" --max-result-bytes 100
url2=http://127.0.0.1:$started_port
curl -s -o /dev/null -X POST -H 'Content-Type: application/json' --data @scene.json "$url2/v1/scenes"
sed 's/"contexts"/"seed": 9, "contexts"/' job.json >job9.json
stjob=$(curl -s -X POST -H 'Content-Type: application/json' --data @job9.json "$url2/v1/scenes/$scene/jobs" |
  "$py" -c 'import json, sys; print(json.load(sys.stdin)["id"])')
run "state: job watch" "$bin/raysweep" --server "$url2" job watch "$stjob"
run "state: dataset before" "$bin/raysweep" --server "$url2" fetch "$stjob" -o before.nc
kill "${pids[-1]}" && wait "${pids[-1]}" 2>/dev/null
start_daemon "$tmp/d3" --state-dir "$tmp/st" --max-result-bytes 100
url2=http://127.0.0.1:$started_port
run "state: dataset after a restart" "$bin/raysweep" --server "$url2" fetch "$stjob" -o after.nc
ds "state: the dataset survives a restart" same before.nc after.nc
# The daemon writes a dataset to a file in its blob directory and answers
# from it: the same bytes each time, and nothing left there.
curl -s -o stream1.nc "$url2/v1/jobs/$stjob/dataset" && curl -s -o stream2.nc "$url2/v1/jobs/$stjob/dataset"
cmp -s stream1.nc after.nc && cmp -s stream2.nc after.nc && ok ||
  bad "state: the dataset streamed from its file is not the one fetched"
left=$(ls -A "$tmp/st/blobs" | grep -c '^\.dataset')
[ "$left" = 0 ] && ok || bad "state: $left dataset files left in the blob directory"
"$py" -c 'import sys, xarray; d = xarray.open_dataset(sys.argv[1]); assert int(d.attrs["seed"]) == 9 and "a" in d.coords' \
  after.nc 2>pyerr && ok || bad "state: seed and coords after a restart: $(tail -n 2 pyerr)"

expect 2 "fetch JOB CONTEXT SENSOR -o F.nc" rs fetch "$ctxjob" k0 sensor -o one.nc
contains "fetch .nc with a context says why" "$tmp/err" "JOB alone"
expect 2 "fetch JOB alone to .exr" rs fetch "$ctxjob" -o one.exr
finish
