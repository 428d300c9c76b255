#!/usr/bin/env bash
# Parameter values of any length (issue 25 item 3), against the real daemon:
#  - GET /v1/scenes/ID/params gives a buffer of 40 numbers (a tabphase's
#    `values`) as {"length": 40}; with ?full=1 (and full=true) the 40
#    numbers, equal to the pushed ones; full=maybe is a 400 naming `full`;
#  - a PATCH of the buffer reads back in full;
#  - `raysweep params ID --full --json` prints the 40 numbers, without
#    --full the stand-in.
# Ends with "test_params_full: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_params_full
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweep raysweepd
need_cmd python3 "for the checks"
need_cmd curl "to talk to the daemon"

start_daemon "$tmp/d1"
port=$started_port
if [ -z "$port" ]; then
  bad "the daemon did not start: $(cat "$tmp/d1/log")"
  finish
fi
U="http://127.0.0.1:$port"
export RAYSWEEP_URL=$U
unset RAYSWEEP_TOKEN
cd "$tmp" || exit 1

vals=$(python3 -c 'print(", ".join(str(1 + 0.25 * i) for i in range(40)))')
cat >scene.json <<JSON
{"type": "scene",
 "integrator": {"type": "volpath"},
 "box": {"type": "cube", "bsdf": {"type": "null"},
   "interior": {"type": "homogeneous", "id": "fog", "sigma_t": 0.5,
     "phase": {"type": "tabphase", "id": "tab", "values": [$vals]}}},
 "sensor": {"type": "distant", "film": {"type": "hdrfilm", "width": 1, "height": 1}}}
JSON
expect 0 "push" "$bin/raysweep" -q scene push scene.json
id=$(cat out)
key='tabphase:tab:values'

curl -s --max-time 20 "$U/v1/scenes/$id/params?match=$key" >short.json
py "without full: {length: 40}" 'import json,sys
p = json.load(open(sys.argv[1]))["params"]
assert len(p) == 1 and p[0]["value"] == {"length": 40}, p' short.json

for q in full=1 full=true "full=1&class=spectral"; do
  curl -s --max-time 20 "$U/v1/scenes/$id/params?match=$key&$q" >full.json
  py "?$q gives the 40 values" 'import json,sys
p = json.load(open(sys.argv[1]))["params"]
want = [1 + 0.25 * i for i in range(40)]
assert len(p) == 1 and p[0]["value"] == want, p' full.json
done
curl -s --max-time 20 "$U/v1/scenes/$id/params?full=1" >all.json
py "the whole table with full=1 has no stand-in" 'import json,sys
p = json.load(open(sys.argv[1]))["params"]
assert p and not any(isinstance(e["value"], dict) and "length" in e["value"] for e in p), p' all.json

code=$(curl -s --max-time 20 -o bad.json -w '%{http_code}' "$U/v1/scenes/$id/params?full=maybe")
[ "$code" = 400 ] && ok || bad "full=maybe: HTTP $code"
contains "the 400 names full" bad.json "full"

new=$(python3 -c 'print("[" + ", ".join(str(2 + i) for i in range(40)) + "]")')
code=$(curl -s --max-time 20 -o patch.json -w '%{http_code}' -X PATCH -H 'Content-Type: application/json' \
  --data "{\"$key\": $new}" "$U/v1/scenes/$id/params")
[ "$code" = 200 ] && ok || bad "PATCH: HTTP $code $(cat patch.json)"
curl -s --max-time 20 "$U/v1/scenes/$id/params?match=$key&full=1" >full2.json
py "the patched buffer reads back in full" 'import json,sys
p = json.load(open(sys.argv[1]))["params"]
assert p[0]["value"] == [2 + i for i in range(40)], p' full2.json

expect 0 "raysweep params --full" "$bin/raysweep" params "$id" --match "$key" --full --json
py "CLI --full prints the values" 'import json,sys
p = json.load(open(sys.argv[1]))["params"]
assert p[0]["value"] == [2 + i for i in range(40)], p' "$tmp/out"
expect 0 "raysweep params" "$bin/raysweep" params "$id" --match "$key"
contains "CLI without --full prints the stand-in" "$tmp/out" '{"length":40}'

finish
