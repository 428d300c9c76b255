#!/usr/bin/env bash
# Limits refused up front, through a real daemon (issue 13): an 8192x8192
# film is refused before rendering (it used to run 4 minutes at 3.4 GB and
# then fail with 500), --max-film-bytes moves the limit and GET /v1
# reports it; the directions of a film over 1024^2 pixels, a sensor named
# twice in a context and a job of 100,001 contexts are refused with a
# problem naming the field, the last in well under a second (153-185 s
# before); the daemon keeps answering. The time bounds are the refusals'
# (a render or a pass over the list would take minutes) with room for a
# loaded machine: a 1 s bound failed once at load 15.
name=test_limits_http
. "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd curl "to talk to the daemon"
need_cmd python3 "to build bodies and read JSON answers"

start_daemon "$tmp/d" --max-film-bytes 64M
port=$started_port
if [ -z "$port" ]; then
  bad "the daemon did not start: $(cat "$tmp/d/log")"
  finish
fi
URL=http://127.0.0.1:$port
# call METHOD PATH [BODY-FILE]: the body to $tmp/body, the status to stdout.
call() {
  curl -s -o "$tmp/body" -w '%{http_code}' -X "$1" "$URL$2" -H 'Content-Type: application/json' \
    ${3:+--data-binary @"$3"}
}
# problem LABEL STATUS WANT-STATUS POINTER: a problem+json with that pointer.
problem() {
  if [ "$2" = "$3" ] && python3 -c 'import json,sys; p=json.load(open(sys.argv[1])); sys.exit(p.get("pointer") != sys.argv[2])' "$tmp/body" "$4"; then
    ok
  else
    bad "$1: $2 $(head -c 400 "$tmp/body")"
  fi
}

st=$(call GET /v1)
if [ "$st" = 200 ] && grep -qF '"max_film_bytes":67108864' "$tmp/body"; then ok; else bad "GET /v1 limits: $st $(head -c 600 "$tmp/body")"; fi

scene() { # W H: a plate seen by an hdistant "big" of W x H pixels and a 1x1 distant "meter"
  printf '{"type": "scene", "variant": "mono",
    "big": {"type": "hdistant", "film": {"type": "hdrfilm", "width": %d, "height": %d}},
    "meter": {"type": "distant", "direction": [0, 0, -1], "film": {"type": "hdrfilm", "width": 1, "height": 1}},
    "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": 1.0},
    "plate": {"type": "rectangle"}}' "$1" "$2" >"$tmp/scene.json"
  call POST /v1/scenes "$tmp/scene.json" >/dev/null
  python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["id"])' "$tmp/body"
}

# The 8192^2 film: refused before rendering, by a render and by a job.
BIG=$(scene 8192 8192)
echo '{"sensor": "big", "spp": 1}' >"$tmp/q"
t0=$(date +%s.%N)
st=$(call POST "/v1/scenes/$BIG:render" "$tmp/q")
t1=$(date +%s.%N)
problem "8192^2 render" "$st" 422 /sensor
py "8192^2 refused in under 10 s (rendering it took 4 minutes)" 'import sys; assert float(sys.argv[2]) - float(sys.argv[1]) < 10.0, float(sys.argv[2]) - float(sys.argv[1])' "$t0" "$t1"
echo '{"contexts": [{"id": "a", "sensors": ["meter", "big"]}]}' >"$tmp/q"
st=$(call POST "/v1/scenes/$BIG/jobs" "$tmp/q")
problem "8192^2 in a job" "$st" 422 /contexts/0/sensors/1
echo '{"sensor": "meter", "spp": 1}' >"$tmp/q"
st=$(call POST "/v1/scenes/$BIG:render" "$tmp/q")
[ "$st" = 200 ] && ok || bad "the small sensor of the same scene: $st"

# Directions: over 1024^2 pixels refused, a small film answered.
WIDE=$(scene 2048 1024)
st=$(call GET "/v1/scenes/$WIDE/sensors/big/directions")
if [ "$st" = 422 ] && grep -qF "sensor 'big'" "$tmp/body" && grep -qF RSW_ERR_LIMIT "$tmp/body"; then ok; else bad "2048x1024 directions: $st $(head -c 300 "$tmp/body")"; fi
SMALL=$(scene 16 8)
st=$(call GET "/v1/scenes/$SMALL/sensors/big/directions")
py "16x8 directions" 'import json,sys; d=json.load(open(sys.argv[1])); assert len(d["pixels"]) == 128 and d["pixels"][17]["ix"] == 1 and d["pixels"][17]["iy"] == 1, d' "$tmp/body"

# A sensor named twice in a context, or 10,000 times.
echo '{"contexts": [{"id": "a", "sensors": ["meter", "meter"]}]}' >"$tmp/q"
st=$(call POST "/v1/scenes/$SMALL/jobs" "$tmp/q")
problem "duplicate sensor" "$st" 422 /contexts/0/sensors/1
python3 -c 'import json; print(json.dumps({"contexts": [{"id": "a", "sensors": ["meter"] * 10000}]}))' >"$tmp/q"
st=$(call POST "/v1/scenes/$SMALL/jobs" "$tmp/q")
problem "10,000 copies of one sensor" "$st" 422 /contexts/0/sensors/1

# 100,001 contexts: refused after one pass over the list.
python3 -c 'import json; print(json.dumps({"contexts": [{"id": "c%d" % i} for i in range(100001)]}))' >"$tmp/q"
t0=$(date +%s.%N)
st=$(call POST "/v1/scenes/$SMALL/jobs" "$tmp/q")
t1=$(date +%s.%N)
problem "100,001 contexts" "$st" 422 /contexts
py "100,001 contexts refused in under 20 s (153-185 s before)" 'import sys; assert float(sys.argv[2]) - float(sys.argv[1]) < 20.0, float(sys.argv[2]) - float(sys.argv[1])' "$t0" "$t1"

st=$(curl -s -o /dev/null -w '%{http_code}' "$URL/v1/health/live")
[ "$st" = 200 ] && ok || bad "health: $st"
finish
