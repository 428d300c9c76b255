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
#   - journals: the sweep's process SIGKILLed or sent SIGINT once its
#     shards' jobs run, then the same sweep run again: the unsharded
#     dataset from those jobs, none submitted again, the journal removed
#     (SIGINT: the jobs left running, and said so); a balancer of the
#     check's own killed mid-sweep: the sweep fails within seconds naming
#     its journal, and resumes through another balancer; journal= without
#     spread=, another sweep's journal and a file that is none refused;
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
python_spread_check "http://127.0.0.1:$plb" "http://127.0.0.1:$pref" "$kill_pid" "$pa" "$pb"
finish
