#!/usr/bin/env bash
# The concurrency soak (issue 22 item 6): 32 clients for RSW_SOAK_SECONDS
# (default 60; 20 under SAN=1, where each request costs several times more)
# against one daemon with a scene budget that holds about two of its three
# scenes, mixing PATCHes, renders with overrides, jobs, scene deletes and
# posts (evictions). Every film is bitwise the same request served alone,
# and the daemon's VmRSS at the end is within 8 MiB + 10 % of its VmRSS at a
# third of the run (not checked under SAN=1: ASan's quarantine keeps freed
# memory by design). tests/integration/soak.py does the work and says
# more.
# Ends with "test_soak: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_soak
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd python3 "for the clients"

secs=${RSW_SOAK_SECONDS:-60}
rss=()
if [ "${SAN:-0}" = 1 ]; then
  secs=${RSW_SOAK_SECONDS:-20}
  rss=(--no-rss)
fi
# Each scene counts about 36 KiB + 16 KiB a shape + its geometry (README,
# Memory): 160 KiB holds two of them, not three.
start_daemon "$tmp/d" --max-scene-bytes 160K
port=$started_port
if [ -z "$port" ]; then
  bad "the daemon did not start: $(cat "$tmp/d/log")"
  finish
fi
dpid=${pids[-1]}
python3 "$root/tests/integration/soak.py" --port "$port" --pid "$dpid" --seconds "$secs" "${rss[@]}" >"$tmp/soak" 2>&1
grep -v '^soak: [0-9]* passed' "$tmp/soak" | sed "s/^FAIL soak: /FAIL $name: /"
line=$(tail -n 1 "$tmp/soak")
if [[ $line =~ ^soak:\ ([0-9]+)\ passed,\ ([0-9]+)\ failed$ ]]; then
  pass=$((pass + BASH_REMATCH[1]))
  fail=$((fail + BASH_REMATCH[2]))
else
  bad "soak.py ended without its summary: $(tail -n 5 "$tmp/soak")"
fi
# Evictions happened (the budget was exercised), and the daemon is still up.
evicted=$(curl -s "http://127.0.0.1:$port/metrics" | sed -n 's/^raysweep_scenes_evicted_total \([0-9]*\)$/\1/p')
[ "${evicted:-0}" -gt 0 ] && ok || bad "no scene was evicted (raysweep_scenes_evicted_total '${evicted}')"
echo "test_soak: $evicted scenes evicted"
if grep -qE 'ERROR: (AddressSanitizer|LeakSanitizer)|runtime error:' "$tmp/d/log"; then
  bad "sanitizer report in the daemon's log: $(grep -m 3 -E 'ERROR: |runtime error:' "$tmp/d/log")"
else
  ok
fi
finish
