#!/usr/bin/env bash
# No geometry input takes the daemon down (issue 13): a projective
# to_world, scales of 1e-20 / 1e-30 / 1e39, a sphere radius of 1e-30 and
# non-finite entries, sent as a per-render override, a PATCH, a job
# context's override and in a scene load (JSON and XML), each answer a 422
# problem naming the key (or the scene's property), or fail the job's
# context with it; and the daemon keeps rendering, the same film as before.
# Before the fix the first render override aborted the daemon (Embree's
# ray.valid() assertion): every later request here failed to connect.
name=test_geometry_limits
. "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd curl "to talk to the daemon"
need_cmd python3 "to read JSON answers"

start_daemon "$tmp/d"
port=$started_port
if [ -z "$port" ]; then
  bad "the daemon did not start: $(cat "$tmp/d/log")"
  finish
fi
URL=http://127.0.0.1:$port
# call METHOD PATH [BODY] [CONTENT-TYPE]: the body to $tmp/body, the status to stdout.
call() {
  curl -s -o "$tmp/body" -w '%{http_code}' -X "$1" "$URL$2" -H "Content-Type: ${4:-application/json}" \
    ${3:+--data-binary "$3"}
}
ID=$(curl -s "$URL/v1/scenes" | python3 -c 'import json,sys; print(json.load(sys.stdin)["scenes"][0]["id"])')
[ -n "$ID" ] || { bad "no default scene"; finish; }

# The reference film, and a check that the daemon still renders exactly it.
ref=$(call POST "/v1/scenes/$ID:render" '{"spp": 2, "seed": 3}')
[ "$ref" = 200 ] && ok || bad "reference render: $ref $(head -c 300 "$tmp/body")"
cp "$tmp/body" "$tmp/ref.json"
still_renders() {
  local st
  st=$(call POST "/v1/scenes/$ID:render" '{"spp": 2, "seed": 3}')
  if [ "$st" = 200 ] && cmp -s "$tmp/body" "$tmp/ref.json"; then ok; else bad "$1: the daemon no longer renders the same film ($st)"; fi
}

M_PROJ='[1,0,0,0, 0,1,0,0, 0,0,1,0, 1,0,0,1]'
M_20='[1e-20,0,0,0, 0,1e-20,0,0, 0,0,1e-20,0, 0,0,0,1]'
M_30='[1e-30,0,0,0, 0,1e-30,0,0, 0,0,1e-30,0, 0,0,0,1]'
M_39='[1e39,0,0,0, 0,1e39,0,0, 0,0,1e39,0, 0,0,0,1]'
M_INF='[1,0,0,1e400, 0,1,0,0, 0,0,1,0, 0,0,0,1]'

# problem LABEL STATUS: a 422 problem+json naming rectangle.to_world.
problem() {
  if [ "$2" = 422 ] && grep -qF 'rectangle.to_world' "$tmp/body"; then ok; else bad "$1: $2 $(head -c 400 "$tmp/body")"; fi
}

for m in "$M_PROJ" "$M_20" "$M_30" "$M_39" "$M_INF"; do
  st=$(call POST "/v1/scenes/$ID:render" '{"spp": 1, "params": {"rectangle.to_world": '"$m"'}}')
  problem "render override $m" "$st"
  still_renders "after the render override $m"
  st=$(call PATCH "/v1/scenes/$ID/params" '{"rectangle.to_world": '"$m"'}')
  problem "PATCH $m" "$st"
  still_renders "after the PATCH $m"
done

# A job whose contexts override to_world: refused at submission (422 naming
# the key), or accepted with each bad context failed naming it; the good
# context renders either way.
body='{"defaults": {"spp": 1}, "contexts": [{"id": "good"},
  {"id": "proj", "params": {"rectangle.to_world": '"$M_PROJ"'}},
  {"id": "tiny", "params": {"rectangle.to_world": '"$M_30"'}},
  {"id": "huge", "params": {"rectangle.to_world": '"$M_39"'}}]}'
st=$(call POST "/v1/scenes/$ID/jobs" "$body")
if [ "$st" = 422 ]; then
  problem "job submission" "$st"
elif [ "$st" = 202 ]; then
  JOB=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["id"])' "$tmp/body")
  for _ in $(seq 200); do
    curl -s "$URL/v1/jobs/$JOB" >"$tmp/job"
    python3 -c 'import json,sys; sys.exit(json.load(open(sys.argv[1]))["state"] in ("queued","running"))' "$tmp/job" && break
    sleep 0.05
  done
  curl -s "$URL/v1/jobs/$JOB/results" >"$tmp/results"
  py "job: bad contexts fail naming the key, the good one renders" '
import json, sys
r = {x["context"]: x for x in json.load(open(sys.argv[1]))["results"]}
assert r["good"]["state"] == "succeeded", r["good"]
for c in ("proj", "tiny", "huge"):
    assert r[c]["state"] == "failed" and "rectangle.to_world" in r[c]["error"], r[c]
' "$tmp/results"
else
  bad "job submission: $st $(head -c 300 "$tmp/body")"
fi
still_renders "after the job"

# Scene loads: JSON and XML, each refused naming the property.
load() {
  local label=$1 type=$2 doc=$3 want=$4 st
  st=$(call POST /v1/scenes "$doc" "$type")
  if [ "$st" = 422 ] && grep -qF -- "$want" "$tmp/body"; then ok; else bad "load $label: $st $(head -c 400 "$tmp/body")"; fi
}
cam='"cam": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}}'
load "json radius 1e-30" application/json '{"type": "scene", '"$cam"', "b": {"type": "sphere", "radius": 1e-30}}' radius
load "json scale 1e-20" application/json '{"type": "scene", '"$cam"', "r": {"type": "rectangle", "to_world": [{"scale": 1e-20}]}}' to_world
load "json projective" application/json '{"type": "scene", '"$cam"', "r": {"type": "rectangle", "to_world": '"$M_PROJ"'}}' affine
load "json scale 1e39" application/json '{"type": "scene", '"$cam"', "r": {"type": "rectangle", "to_world": [{"scale": 1e39}]}}' to_world
xml() {
  printf '<scene version="3.0.0">\n<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film></sensor>\n%s\n</scene>\n' "$1"
}
load "xml scale 1e-30" application/xml "$(xml '<shape type="rectangle"><transform name="to_world"><scale value="1e-30"/></transform></shape>')" to_world
load "xml radius 1e-30" application/xml "$(xml '<shape type="sphere"><float name="radius" value="1e-30"/></shape>')" radius
load "xml nan" application/xml "$(xml '<shape type="cube"><transform name="to_world"><scale value="nan"/></transform></shape>')" scene.xml:3
still_renders "after the scene loads"

# The daemon is alive and answers health probes.
st=$(curl -s -o /dev/null -w '%{http_code}' "$URL/v1/health/live")
[ "$st" = 200 ] && ok || bad "health after everything: $st"
finish
