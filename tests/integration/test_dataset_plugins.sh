#!/usr/bin/env bash
# Environment plugin failures in every dataset: a sweep through a plugin
# whose radiance is NaN or negative (tests/support/plugins/failing_sky.c)
# and one through a constant emitter, each as `raysweep sweep --format nc`
# (the client's dataset, client/lib/dataset.c) and `raysweep fetch JOB -o
# F.nc` (the daemon's, GET /v1/jobs/{id}/dataset):
#   - plugin_failures and plugin_failure per film equal the films' meta:
#     > 0 with the plugin's message for the failing sky, 0 and "" for the
#     constant one (the variables are there either way);
#   - the daemon's dataset and the client's are the same, bitwise (but
#     for the daemon's job and warnings attributes), and so is the one
#     `raysweep merge` makes of two shards;
#   - after a restart with --state-dir (films read back from disk) the
#     daemon's dataset still carries them.
# Ends with "test_dataset_plugins: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_dataset_plugins
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweep raysweepd
need_cmd cc "to build the failing plugin"
need_xarray
cd "$tmp" || exit 1

mkdir -p plugins
cc -shared -fPIC -I "$root/include" -o plugins/failing_sky.so "$root/tests/support/plugins/failing_sky.c" || {
  bad "cannot build tests/support/plugins/failing_sky.c"
  finish
}
# A radiance meter (1x1) towards +x under the failing sky, and under a
# constant emitter.
scene() {
  printf '{"type": "scene", "variant": "mono",
  "meter": {"type": "radiancemeter", "origin": [0, 0, 0], "direction": [1, 0, 0],
    "film": {"type": "hdrfilm", "width": 1, "height": 1, "component_format": "float32"}},
  "sky": %s}\n' "$1"
}
scene '{"type": "failing_sky", "id": "bad_sky"}' >bad.json
scene '{"type": "constant", "radiance": {"type": "uniform", "value": 1}}' >good.json

start_daemon "$tmp/d" --plugin-dir "$tmp/plugins" --state-dir "$tmp/st" --max-result-bytes 100
[ -n "$started_port" ] || {
  bad "daemon did not start: $(tail -n 5 "$tmp/d/log")"
  finish
}
url=http://127.0.0.1:$started_port
rs() { "$bin/raysweep" --server "$url" "$@"; }
job_of() { "$py" -c 'import json, sys; print(json.load(open(sys.argv[1]))["job"])' "$1/sweep.json"; }

for sky in bad good; do
  want=$([ $sky = bad ] && echo some || echo none)
  expect 0 "$sky: sweep --format nc" rs sweep $sky.json --grid wavelength=500:600:100 --spp 2 --format nc -o $sky
  ds "$sky: the client's dataset" failures $sky/dataset.nc $sky $want
  expect 0 "$sky: fetch JOB -o F.nc" rs fetch "$(job_of $sky)" -o ${sky}_daemon.nc
  ds "$sky: the daemon's dataset" failures ${sky}_daemon.nc $sky $want
  # (The job and its warnings are attributes of the daemon's alone.)
  ds "$sky: the daemon's dataset = the client's" same ${sky}_daemon.nc $sky/dataset.nc --ignore-attr job \
    --ignore-attr warnings
done

# Shards merged (`raysweep merge`, from the films' JSON): the same dataset.
for k in 0 1; do
  expect 0 "bad: shard $k/2" rs sweep bad.json --grid wavelength=500:600:100 --spp 2 --format nc --shard $k/2 -o s$k
done
expect 0 "bad: merge" rs merge s0 s1 -o merged
ds "bad: merged shards = unsharded" same merged/dataset.nc bad/dataset.nc

kill "${pids[-1]}" && wait "${pids[-1]}" 2>/dev/null
start_daemon "$tmp/d2" --plugin-dir "$tmp/plugins" --state-dir "$tmp/st" --max-result-bytes 100
url=http://127.0.0.1:$started_port
expect 0 "after a restart: fetch JOB -o F.nc" rs fetch "$(job_of bad)" -o restarted.nc
ds "after a restart: the failures are still there" failures restarted.nc bad some
ds "after a restart: the same dataset" same restarted.nc bad_daemon.nc
finish
