#!/usr/bin/env bash
# The Python package's Scene.sweep(spread=K) (docs/python.md, "Sweeps over
# several daemons"), through tests/support/shard_lb.py in front of two
# daemons, against the same sweeps on one daemon
# (tests/support/python_spread_check.py):
#   - a 3 x 5 grid at bundle None, 1 and 3: the dataset is the unsharded
#     one (xarray identical but for the job attribute; dims over the grid),
#     and both replicas rendered contexts;
#   - one axis (wavelength); bands with brf and variance over a reflectance
#     axis; contexts that are no complete grid (a context dimension): the
#     unsharded dataset;
#   - a sweep over a coordinate nothing reads, each shard one value of it:
#     one SweepWarning at the caller's line (from the whole sweep's dry run);
#   - one replica SIGKILLed mid-sweep: its shard is submitted again under
#     a key that reaches the other, and the dataset is the unsharded one;
#   - spread 0, 2.5 or True, a scene found by id (no document to push) and
#     a scene with parameters set since its push are refused, naming why.
name=test_python_spread
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd python3 "for the balancer"
need_xarray
start_spread_pair # $pa, $pb and the balancer $plb
start_daemon "$tmp/ref" --threads 1
pref=$started_port
[ -n "$pref" ] || { bad "the reference daemon did not start: $(cat "$tmp/ref/log")"; finish; }
kill_pid=${pids[1]} # daemon b (start_spread_pair: a, b, the balancer)
exec 3>&2 2>/dev/null # (bash's notice of the replica the check kills; the check's own stderr is in $out)
out=$("$py" "$root/tests/support/python_spread_check.py" "http://127.0.0.1:$plb" "http://127.0.0.1:$pref" \
  "$pa" "$pb" --kill "$kill_pid" 2>&1)
kill -9 "$kill_pid" 2>/dev/null; wait "$kill_pid" # (gone already, unless the check failed first)
exec 2>&3 3>&-
echo "$out" | grep -v '^ok   '
p=$(echo "$out" | grep -c '^ok   ')
f=$(echo "$out" | grep -c '^FAIL ')
pass=$((pass + p))
fail=$((fail + f))
[ "$p" -eq 9 ] || bad "python_spread_check.py passed $p checks, want 9: $(echo "$out" | tail -n 3)"
finish
