#!/usr/bin/env bash
# make test-cluster: the Python package's Scene.sweep(spread=2)
# (docs/python.md#sweeps-over-several-daemons) through HAProxy (a
# configuration from docker/lb/gen.py, active health checks every 200 ms)
# in front of two replicas, against the same sweeps on a third daemon: the
# checks of tests/support/python_spread_check.py (grids at bundle None, 1
# and 3, one axis, bands, contexts that are no grid, the sweep's warning
# once, a replica SIGKILLed mid-sweep whose
# shard runs again on the other, journals that resume the shards' jobs,
# the refusals), here with a real balancer,
# which answers for a dead replica as HAProxy does (503, or its keys
# moved to the live one: the job not found there).
name=test_python_balancer
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd haproxy "(make deps-cluster installs it): the balancer under test"
need_cmd python3 "to generate the balancer configuration"
need_xarray
start_daemon "$tmp/ref" --threads 1
pref=$started_port
[ -n "$pref" ] || { bad "the reference daemon did not start: $(cat "$tmp/ref/log")"; finish; }
ports=()
rep_args=()
for i in 1 2; do
  start_daemon "$tmp/r$i" --threads 1
  [ -n "$started_port" ] || { bad "replica $i did not start: $(cat "$tmp/r$i/log")"; finish; }
  ports+=("$started_port")
  rep_args+=(--replica "127.0.0.1:$started_port")
done
kill_pid=${pids[-1]} # replica 2
lb=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
python3 "$root/docker/lb/gen.py" haproxy --listen "127.0.0.1:$lb" "${rep_args[@]}" --check-interval-ms 200 \
  -o "$tmp/haproxy.cfg"
haproxy -f "$tmp/haproxy.cfg" -db >"$tmp/haproxy.log" 2>&1 &
pids+=($!)
for _ in $(seq 100); do
  curl -sf -o /dev/null "http://127.0.0.1:$lb/v1/health/ready" && break
  sleep 0.1
done
python_spread_check "http://127.0.0.1:$lb" "http://127.0.0.1:$pref" "$kill_pid" "${ports[@]}"
finish
