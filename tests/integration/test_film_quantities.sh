#!/usr/bin/env bash
# BRF / BRDF, error bars and PNG quick-looks end to end (issue 16, points
# 2-4), through raysweepd render, the daemon and the raysweep CLI:
#  - a render with "quantities": ["brf", "brdf"] and "variance": true
#    answers JSON whose channels are Y, brdf.Y, brf.Y, radiance_stderr.Y,
#    with meta.planes and meta.irradiance, brf = pi L / E_h and
#    brdf = L / E_h in every pixel; the .npy and the CLI's files carry
#    the same channels;
#  - a job with them stores its films with the planes: fetched from memory,
#    from a state directory (films beyond --max-result-bytes live on disk
#    only) and after a restart, the .npy is the same bytes; raysweep sweep
#    --quantities --variance writes films with them;
#  - refusals name their field: an unknown quantity, variance with a
#    gaussian rfilter or 1 spp, brf in a scene with no directional emitter
#    (HTTP 422 and the CLIs' exit status 1 / 2);
#  - PNG quick-looks (raysweepd render -o, raysweep render -o, raysweep
#    fetch -o, Accept: image/png on renders and job results) decode with
#    Python's zlib (tests/support/png_read.py) to the film's size, and the
#    film's brightest pixel is among the PNG's brightest.
# Ends with "test_film_quantities: N passed, N failed".
set -u
name=test_film_quantities
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweep raysweepd
need_cmd python3 "to read JSON films and PNGs"
need_cmd curl "to talk to the daemon"
cd "$tmp" || exit 1
pngread=$root/tests/support/png_read.py

# An RPV plate under a sun, hdistant 12x9, box filter: a film whose
# brightest pixel is unique (the hot spot).
cat >rpv.json <<'JSON'
{"type": "scene", "variant": "mono",
 "sensor": {"type": "hdistant", "id": "hd", "target": [0, 0, 0],
   "sampler": {"type": "independent", "sample_count": 16},
   "film": {"type": "hdrfilm", "width": 12, "height": 9, "component_format": "float32",
            "rfilter": {"type": "box"}}},
 "sun": {"type": "directional", "direction": [-0.4, 0.3, -0.8660254037844386], "irradiance": 2.5},
 "plate": {"type": "rectangle", "to_world": [{"scale": [10, 10, 1]}],
   "bsdf": {"type": "rpv", "rho_0": 0.12, "k": 0.9, "g": -0.25, "rho_c": 0.3}}}
JSON
sed 's/"rfilter": {"type": "box"}/"rfilter": {"type": "gaussian"}/' rpv.json >gauss.json
sed 's/"sun": {"type": "directional", "direction": \[[^]]*\], "irradiance": 2.5}/"sky": {"type": "constant"}/' \
  rpv.json >sky.json

# run LABEL CMD...: CMD must exit 0 (stdout to out, stderr to err).
run() {
  local label=$1
  shift
  if "$@" >"$tmp/out" 2>"$tmp/err"; then ok; else bad "$label: exit $?; stderr: $(head -c 600 "$tmp/err")"; fi
}

# ---- raysweepd render ---------------------------------------------------------------
run "raysweepd render -o png" "$bin/raysweepd" render rpv.json --spp 16 --seed 3 -o d.png
run "raysweepd render planes" "$bin/raysweepd" render rpv.json --spp 16 --quantities brf --variance -o d.exr
expect 1 "raysweepd render variance with gaussian" "$bin/raysweepd" render gauss.json --variance -o g.exr
contains "gaussian refusal names variance and the filter" err "variance: variance needs the box rfilter"
expect 1 "raysweepd render brf without a sun" "$bin/raysweepd" render sky.json --quantities brf -o s.exr
contains "no directional emitter" err "the scene has none"
expect 2 "raysweepd render unknown quantity" "$bin/raysweepd" render rpv.json --quantities brfx -o x.exr
expect 2 "raysweepd render colormap without png" "$bin/raysweepd" render rpv.json --colormap viridis -o x.exr

# ---- the daemon ---------------------------------------------------------------------
start_daemon "$tmp/d" --threads 2
port=$started_port
[ -n "$port" ] || { bad "the daemon did not start: $(cat "$tmp/d/log")"; finish; }
url="http://127.0.0.1:$port"
export RAYSWEEP_URL=$url
unset RAYSWEEP_TOKEN
rs() { "$bin/raysweep" "$@"; }
run "scene push" rs -q scene push rpv.json
id=$(cat out)
run "scene push sky" rs -q scene push sky.json
sky=$(cat out)
run "scene push gauss" rs -q scene push gauss.json
gauss=$(cat out)
# post OUT SCENE BODY [QUERY [CURL ARGS...]]: POST :render, prints the status.
post() { curl -s -o "$tmp/$1" -w '%{http_code}' -X POST "$url/v1/scenes/$2:render${4:-}" \
  -H 'Content-Type: application/json' "${@:5}" -d "$3"; }

st=$(post r.json "$id" '{"spp": 16, "seed": 3, "quantities": ["radiance", "brf", "brdf"], "variance": true}')
[ "$st" = 200 ] && ok || bad "render with planes: $st $(head -c 300 r.json)"
py "JSON film with planes: channels, meta, brf = pi L / E_h, brdf = L / E_h" '
import json, math, sys
d = json.load(open(sys.argv[1]))
assert d["channels"] == ["Y", "brdf.Y", "brf.Y", "radiance_stderr.Y"], d["channels"]
m = d["meta"]
assert [p["name"] for p in m["planes"]] == ["brdf", "brf", "radiance_stderr"], m["planes"]
assert [p["units"] for p in m["planes"]] == ["sr-1", "1", "W m-2 sr-1 nm-1"], m["planes"]
eh = 2.5 * 0.8660254037844386 / math.sqrt(0.16 + 0.09 + 0.75)
assert abs(m["irradiance"][0] - eh) < 1e-12, m["irradiance"]
v = d["data"]
assert len(v) == 12 * 9 * 4
for i in range(12 * 9):
    L, brdf, brf, se = v[4 * i:4 * i + 4]
    assert abs(brf - math.pi * L / eh) <= 1e-6 * brf, (i, brf, L)
    assert abs(brdf - L / eh) <= 1e-6 * brdf, (i, brdf, L)
    assert 0 < se < L, (i, se, L)
' r.json
st=$(post p.png "$id" '{"spp": 16, "seed": 3}' '' -H 'Accept: image/png')
[ "$st" = 200 ] && ok || bad "render as image/png: $st"
st=$(post v.png "$id" '{"spp": 16, "seed": 3}' '?exposure=auto-0.5&colormap=viridis' -H 'Accept: image/png')
[ "$st" = 200 ] && ok || bad "render as image/png with exposure and colormap: $st $(head -c 300 v.png)"
run "raysweep render -o png" rs -q render "$id" --spp 16 --seed 3 -o c.png
run "raysweep render -o png --colormap" rs -q render "$id" --spp 16 --seed 3 --colormap inferno --exposure 1 -o ci.png
run "raysweep render -o png --exposure auto" rs -q render "$id" --spp 16 --seed 3 --exposure auto -o ca.png
run "raysweepd render -o png --exposure auto+1" "$bin/raysweepd" render rpv.json --spp 16 --seed 3 --exposure auto+1 -o da.png
st=$(post pa.png "$id" '{"spp": 16, "seed": 3}' '?exposure=auto' -H 'Accept: image/png')
[ "$st" = 200 ] && ok || bad "render as image/png with exposure=auto: $st $(head -c 300 pa.png)"
run "raysweep render -o json with planes" rs -q render "$id" --spp 16 --seed 3 --quantities brf --variance -o c.json
run "raysweep render -o npy with planes" rs -q render "$id" --spp 16 --seed 3 --quantities brf --variance -o c.npy
py "CLI JSON carries the planes, same values as the daemon's" '
import json, sys
a, b = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
assert a["channels"] == ["Y", "brf.Y", "radiance_stderr.Y"], a["channels"]
for i in range(12 * 9):
    assert a["data"][3 * i] == b["data"][4 * i] and a["data"][3 * i + 1] == b["data"][4 * i + 2], i
    assert a["data"][3 * i + 2] == b["data"][4 * i + 3], i
' c.json r.json
py "CLI .npy: (9, 12, 3), the JSON film's numbers" '
import json, struct, sys
raw = open(sys.argv[1], "rb").read()
hl = struct.unpack("<H", raw[8:10])[0]
assert b"(9, 12, 3)" in raw[10:10 + hl], raw[10:10 + hl]
vals = struct.unpack("<%df" % (12 * 9 * 3), raw[10 + hl:])
d = json.load(open(sys.argv[2]))["data"]
assert all(abs(x - y) <= 1e-7 * abs(y) for x, y in zip(vals, d)), "values"
' c.npy c.json
# Every PNG: the film's size, and the film's brightest pixel is among the
# brightest of the PNG (8 bits can tie neighbours with it).
brightest=$(python3 -c '
import json, sys
d = json.load(open(sys.argv[1])); v = d["data"][0::4]
i = max(range(len(v)), key=lambda k: v[k]); print("%d,%d" % (i % 12, i // 12))' r.json)
for f in d.png p.png v.png c.png ci.png ca.png da.png pa.png; do
  if python3 "$pngread" "$f" >png.txt 2>&1 && [ "$(head -n 1 png.txt | cut -d' ' -f1-2)" = "12 9" ] &&
    tail -n 1 png.txt | tr ' ' '\n' | grep -qx "$brightest"; then
    ok
  else
    bad "$f: want 12x9 with the brightest pixel at $brightest: $(head -c 300 png.txt)"
  fi
done
python3 "$pngread" v.png >png.txt 2>&1
[ "$(head -n 1 png.txt | cut -d' ' -f3)" = 3 ] && ok || bad "a viridis PNG is RGB: $(head -n 1 png.txt)"
python3 "$pngread" p.png >png.txt 2>&1
[ "$(head -n 1 png.txt | cut -d' ' -f3)" = 1 ] && ok || bad "a grey PNG is one channel: $(head -n 1 png.txt)"
# The default look is Mitsuba's: each pixel the sRGB curve of its linear
# radiance clamped to [0, 1], not of radiance / the film's maximum (which
# made the hot spot white and the rest dark); auto maps the film's 99.5th
# percentile to white (here, of 108 values, the largest).
py "PNG quick-looks: sRGB of the clamped radiance; auto: the percentile to white" '
import json, sys
sys.path.insert(0, sys.argv[4])
from png_read import read_png
v = json.load(open(sys.argv[1]))["data"][0::4]
def srgb8(x):
    x = min(max(x, 0.0), 1.0)
    return round(255 * (12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055))
for path, white in ((sys.argv[2], 1.0), (sys.argv[3], sorted(v)[-1])):
    w, h, ch, rows = read_png(path)
    got = [b for row in rows for b in row]
    bad = [(i, got[i], srgb8(v[i] / white)) for i in range(w * h) if abs(got[i] - srgb8(v[i] / white)) > 1]
    assert not bad, (path, bad[:5])
assert max(v) < 0.9, "the test wants a film below 1 so that the default look is not white"
' r.json p.png pa.png "$root/tests/support"

# Refusals, before any work.
st=$(post e.json "$id" '{"quantities": ["albedo"]}')
[ "$st" = 422 ] && contains "unknown quantity" e.json '"pointer":"/quantities/0"' || bad "unknown quantity: $st"
st=$(post e.json "$gauss" '{"variance": true}')
[ "$st" = 422 ] && contains "variance with a gaussian filter" e.json '"pointer":"/variance"' || bad "gaussian: $st"
st=$(post e.json "$id" '{"variance": true, "spp": 1}')
[ "$st" = 422 ] && contains "variance with 1 spp" e.json 'at least 2 samples' || bad "1 spp: $st"
st=$(post e.json "$sky" '{"quantities": ["brf"]}')
[ "$st" = 422 ] && contains "brf without a directional emitter" e.json '"pointer":"/quantities"' || bad "sky: $st"
st=$(post e.json "$id" '{}' '?colormap=jet' -H 'Accept: image/png')
[ "$st" = 400 ] && contains "unknown colormap" e.json 'colormap must be one of gray, viridis, inferno' ||
  bad "colormap=jet: $st"
st=$(post e.json "$id" '{"variance": "yes"}')
[ "$st" = 422 ] && ok || bad "variance must be a boolean: $st"
expect 1 "raysweep render variance on a gaussian film" rs render "$gauss" --variance -o x.json
contains "CLI names the field" err "/variance"
expect 2 "raysweep render --colormap without png" rs render "$id" --colormap gray -o x.json
st=$(post e.json "$id" '{}' '?exposure=autox' -H 'Accept: image/png')
[ "$st" = 400 ] && contains "a malformed exposure" e.json 'exposure must be a number of stops, auto' ||
  bad "exposure=autox: $st"
expect 2 "raysweep render --exposure auto+" rs render "$id" --exposure auto+ -o x.png
expect 2 "raysweepd render --exposure bright" "$bin/raysweepd" render rpv.json --exposure bright -o x.png
contains "raysweepd names the forms" err "a number of stops, auto, or auto+EV"

# ---- jobs: memory, state directory, restart ------------------------------------------------
job_body='{"contexts": [{"id": "a", "seed": 1}, {"id": "b", "seed": 2, "spp": 32}], "quantities": ["brf"], "variance": true}'
wait_job() { # URL JOB -> prints the final state
  local s
  for _ in $(seq 600); do
    s=$(curl -s "$1/v1/jobs/$2" | python3 -c 'import json,sys; print(json.load(sys.stdin)["state"])' 2>/dev/null)
    case "$s" in succeeded | failed | cancelled) echo "$s"; return ;; esac
    sleep 0.05
  done
  echo timeout
}
submit() { # URL SCENE -> job id
  curl -s -X POST "$1/v1/scenes/$2/jobs" -H 'Content-Type: application/json' -d "$job_body" |
    python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])'
}
jm=$(submit "$url" "$id")
[ "$(wait_job "$url" "$jm")" = succeeded ] && ok || bad "job with planes (memory)"
curl -s "$url/v1/jobs/$jm/results" -o res.json
py "results list every channel" '
import json, sys
r = json.load(open(sys.argv[1]))["results"]
assert all(x["channels"] == ["Y", "brf.Y", "radiance_stderr.Y"] for x in r), r
' res.json
for c in a b; do
  curl -s -H 'Accept: application/x-npy' "$url/v1/jobs/$jm/results/$c/hd" -o mem_$c.npy
done
curl -s -H 'Accept: image/png' "$url/v1/jobs/$jm/results/a/hd?exposure=2" -o job.png
python3 "$pngread" job.png >png.txt 2>&1
grep -q '^12 9 1$' png.txt && ok || bad "a job result as image/png: $(head -c 200 png.txt)"
run "raysweep fetch -o png" rs -q fetch "$jm" a hd -o fetched.png
python3 "$pngread" fetched.png >png.txt 2>&1
grep -q '^12 9 1$' png.txt && ok || bad "raysweep fetch -o png: $(head -c 200 png.txt)"
run "raysweep fetch -o json" rs -q fetch "$jm" b hd -o fetched.json
contains "fetched film has the planes" fetched.json '"radiance_stderr.Y"'
st=$(curl -s -o e.json -w '%{http_code}' -X POST "$url/v1/scenes/$gauss/jobs" -H 'Content-Type: application/json' \
  -d '{"contexts": [{"id": "a"}], "variance": true}')
[ "$st" = 422 ] && contains "job refused up front" e.json '"pointer":"/variance"' || bad "job variance gaussian: $st"

printf '%s\n' '{"id": "s1", "seed": 1}' '{"id": "s2", "seed": 2}' >ctx.jsonl
run "raysweep sweep --quantities --variance" rs -q sweep "$id" --contexts ctx.jsonl --quantities brf,brdf --variance \
  --format json -o sw
py "sweep films carry the planes" '
import json, sys
d = json.load(open(sys.argv[1] + "/" + [l for l in map(json.loads, open(sys.argv[1] + "/index.jsonl"))][0]["file"]))
assert d["channels"] == ["Y", "brdf.Y", "brf.Y", "radiance_stderr.Y"], d["channels"]
' sw
expect 2 "raysweep sweep --quantities typo" rs sweep "$id" --contexts ctx.jsonl --quantities brfx -o sw2

sd=$tmp/state
start_daemon "$tmp/s" --state-dir "$sd" --max-result-bytes 1 --threads 2
surl="http://127.0.0.1:$started_port"
RAYSWEEP_URL=$surl run "scene push (state)" rs -q scene push rpv.json
js=$(submit "$surl" "$id")
[ "$(wait_job "$surl" "$js")" = succeeded ] && ok || bad "job with planes (state directory)"
for c in a b; do
  curl -s -H 'Accept: application/x-npy' "$surl/v1/jobs/$js/results/$c/hd" -o disk_$c.npy
  cmp -s mem_$c.npy disk_$c.npy && ok || bad "context $c: the film stored on disk differs from the one in memory"
  curl -s "$surl/v1/jobs/$js/results/$c/hd" -o disk_$c.json
done
py "a film read back from disk is the JSON with planes" '
import json, sys
d = json.load(open(sys.argv[1]))
assert d["channels"] == ["Y", "brf.Y", "radiance_stderr.Y"] and len(d["meta"]["irradiance"]) == 1, d["meta"]
' disk_a.json
kill "${pids[-1]}" && wait "${pids[-1]}" 2>/dev/null
rm -f "$tmp/s/port"
start_daemon "$tmp/s" --state-dir "$sd" --threads 2
surl="http://127.0.0.1:$started_port"
for c in a b; do
  curl -s -H 'Accept: application/x-npy' "$surl/v1/jobs/$js/results/$c/hd" -o after_$c.npy
  cmp -s mem_$c.npy after_$c.npy && ok || bad "context $c: the film after a restart differs"
done
curl -s "$surl/v1/jobs/$js/results/a/hd" -o after_a.json
cmp -s disk_a.json after_a.json && ok || bad "the JSON film after a restart differs"
curl -s "$surl/v1/jobs/$js/results" -o res2.json
contains "results after a restart list the planes' channels" res2.json '"brf.Y"'
finish
