#!/usr/bin/env bash
# The `raysweep` CLI against the real daemon on an ephemeral loopback port:
# every subcommand (render and sweep of a resident scene or a scene file),
# a wavelength sweep on a Lambertian plate that must give
# L = rho(lambda) E cos(theta) / pi, sharded sweeps merged == the unsharded
# sweep byte for byte, and the documented exit codes (1 server said no,
# 2 usage, 3 cannot connect, 4 job cancelled, 5 timeout, 6 local I/O).
# Ends with "test_cli_client: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_cli_client
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweep raysweepd
need_cmd python3 "for the checks"

start_daemon "$tmp/d1"
port=$started_port
if [ -z "$port" ]; then
  bad "the daemon did not start: $(cat "$tmp/d1/log")"
  finish
fi
export RAYSWEEP_URL="http://127.0.0.1:$port"
unset RAYSWEEP_TOKEN
rs() { "$bin/raysweep" "$@"; }
cd "$tmp" || exit 1

# A Lambertian plate seen at nadir under a sun at nadir: L = rho E cos 0 / pi.
cat >plate.json <<'EOF'
{
  "type": "scene",
  "variant": "mono",
  "nadir": {
    "type": "distant",
    "direction": [0, 0, -1],
    "target": [0, 0, 0],
    "sampler": {"type": "independent", "sample_count": 4},
    "film": {"type": "hdrfilm", "width": 1, "height": 1, "component_format": "float32", "rfilter": {"type": "box"}}
  },
  "integrator": {"type": "path", "max_depth": -1},
  "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": 1.0},
  "plate": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": 0.5}}
}
EOF

# ---- status ----
expect 0 "status" rs status
contains "status ready" out "ready:     yes"
expect 0 "status --json" rs status --json
py "status --json is the server's GET /v1" 'import json,sys; d=json.load(open(sys.argv[1])); assert d["name"]=="raysweepd" and "mono" in d["variants"]' out

# --route KEY (RAYSWEEP_ROUTE): X-Raysweep-Shard on every request; the
# daemon ignores it (test_balancer checks the routing itself).
expect 0 "--route with a daemon" rs --route shard-1.a status
expect 2 "--route: a key with a space" rs --route 'two words' status
contains "--route: says what a key is" err "a routing key is 1 to 64 of A-Z a-z 0-9 . _ -"
expect 2 "RAYSWEEP_ROUTE: a key with a slash" env RAYSWEEP_ROUTE=a/b "$bin/raysweep" status
contains "RAYSWEEP_ROUTE: names the variable" err "RAYSWEEP_ROUTE 'a/b'"
expect 2 "--route with sweep --spread" rs --route k1 sweep plate.json --grid wavelength=400,500 --spread 2 -o routed
contains "--route with --spread: says why" err "sweep --spread gives each shard a key of its own"
[ ! -e routed ] && ok || bad "a refused --route left routed behind"

# ---- scenes ----
expect 0 "scene push xml" rs scene push "$root/proto/examples/hdistant_seed.xml"
seed_id=$(cat out)
py "scene push prints a 64-hex id" 'import re,sys; assert re.fullmatch("[0-9a-f]{64}", sys.argv[1])' "$seed_id"
expect 0 "scene push json" rs -q scene push plate.json
plate=$(cat out)
[ ! -s err ] && ok || bad "--quiet scene push wrote to stderr: $(cat err)"
expect 0 "scene push again" rs scene push plate.json --json
py "pushing again gives the same id, not created" 'import json,sys; d=json.load(open(sys.argv[1])); assert d["id"]==sys.argv[2] and d["created"] is False, d' out "$plate"
expect 0 "scene ls" rs scene ls
contains "scene ls plate" out "$plate"
contains "scene ls seed" out "$seed_id"
expect 0 "scene ls --json" rs scene ls --json
py "scene ls --json" 'import json,sys; ids=[s["id"] for s in json.load(open(sys.argv[1]))["scenes"]]; assert sys.argv[2] in ids and sys.argv[3] in ids' out "$plate" "$seed_id"
expect 0 "scene show" rs scene show "$plate"
contains "scene show variant" out "mono"
contains "scene show sensors" out "nadir"
expect 0 "scene show --json" rs scene show "$plate" --json
py "scene show --json" 'import json,sys; d=json.load(open(sys.argv[1])); assert d["id"]==sys.argv[2] and d["sensors"]==["nadir"]' out "$plate"

# ---- params / set ----
expect 0 "params --match" rs params "$plate" --match '*.reflectance.value'
contains "params lists the reflectance" out "plate.bsdf.reflectance.value"
py "params --match filters" 'import sys; lines=open(sys.argv[1]).read().splitlines(); assert len(lines)==1 and lines[0].split()[-1]=="0.5", lines' out
expect 0 "params --class geometric" rs params "$plate" --class geometric --json
py "params --class geometric" 'import json,sys; k=[p["key"] for p in json.load(open(sys.argv[1]))["params"]]; assert "plate.to_world" in k and "plate.bsdf.reflectance.value" not in k, k' out
expect 2 "params --class bogus" rs params "$plate" --class bogus
expect 0 "set" rs set "$plate" plate.bsdf.reflectance.value=0.3
py "set prints the key, the old and new values and the revision" '
import sys
lines = open(sys.argv[1]).read().splitlines()
assert len(lines) == 2 and lines[0] == "plate.bsdf.reflectance.value: 0.5 -> 0.3", lines
assert lines[1].startswith("revision ") and int(lines[1].split()[1]) >= 1, lines' out
rev=$(sed -n 's/^revision //p' out)
expect 1 "set --if-match stale" rs set "$plate" plate.bsdf.reflectance.value=0.5 --if-match $((rev + 5))
expect 0 "set --if-match current" rs set "$plate" plate.bsdf.reflectance.value=0.5 --if-match "$rev" --json
py "set --json" '
import json, sys
d = json.load(open(sys.argv[1]))
assert d["revision"] > int(sys.argv[2]), d
assert d["changes"] == [{"key": "plate.bsdf.reflectance.value", "old": 0.3, "new": 0.5}], d' out "$rev"
expect 0 "params after set" rs params "$plate" --match 'plate.bsdf.reflectance.value' --json
py "set took effect" 'import json,sys; assert json.load(open(sys.argv[1]))["params"][0]["value"]==0.5' out

# ---- render ----
expect 0 "render exr" rs render "$plate" --spp 4 -o r.exr
expect 0 "render npy" rs render "$plate" --spp 4 -o r.npy
expect 0 "render json" rs render "$plate" --spp 4 --seed 3 --wavelength 500 -o r.json
py "render files: EXR magic, NPY header and data, JSON value rho/pi" '
import json, math, struct, sys
exr = open("r.exr", "rb").read()
assert exr[:4] == b"\x76\x2f\x31\x01" and 100 < len(exr) < 100000, len(exr)
npy = open("r.npy", "rb").read()
assert npy[:6] == b"\x93NUMPY"
hl = struct.unpack("<H", npy[8:10])[0]
header = npy[10:10 + hl].decode()
assert "<f4" in header and "(1, 1, 1)" in header, header
assert len(npy) == 10 + hl + 4
film = json.load(open("r.json"))
assert film["width"] == 1 and film["height"] == 1 and film["channels"] == ["Y"] and film["layout"] == "HWC"
v = film["data"][0]
assert abs(v - 0.5 / math.pi) < 1e-6 * 0.5 / math.pi, v
assert film["meta"]["wavelength"] == 500 and film["meta"]["seed"] == 3
(nv,) = struct.unpack("<f", npy[-4:])
assert nv == struct.unpack("<f", struct.pack("<f", v))[0], (nv, v)
'
expect 0 "render --set --json" rs render "$plate" --set plate.bsdf.reflectance.value=0.25 --json -o r2.json
py "render --set overrides for one render" 'import json,math; v=json.load(open("r2.json"))["data"][0]; assert abs(v-0.25/math.pi)<1e-6, v; assert json.load(open("out"))["file"]=="r2.json"'
# A scene FILE: pushed, then rendered (its transform given as 4 rows of 4,
# which a job's wavelength check once took for a spectrum table).
expect 0 "render FILE" rs render plate.json --spp 4 --json -o r3.json \
  --set 'nadir.to_world=[[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]]'
py "render FILE pushes it, then renders" 'import json,math; v=json.load(open("r3.json"))["data"][0]; assert abs(v-0.5/math.pi)<1e-6, v'
expect 1 "render a FILE that is no scene" rs render r.json -o x.exr
contains "render a FILE that is no scene: the push's error" err "r.json"
expect 2 "render without -o" rs render "$plate"
# A key both swept and --set: the --set would change nothing (it was
# silently overridden by every context's value).
expect 2 "sweep --set of a --grid axis" rs sweep "$plate" --grid plate.bsdf.reflectance.value=0.1:0.2:0.1 \
  --set plate.bsdf.reflectance.value=0.5 -o swept_twice
contains "sweep --set of a --grid axis: says so" err "also a --grid axis"
expect 2 "sweep --bundle 17" rs sweep "$plate" --grid wavelength=400:500:100 --bundle 17 -o bundled
contains "sweep --bundle 17: the range" err "from 1 to 16, or auto"
[ ! -e swept_twice ] && ok || bad "sweep --set of a --grid axis left swept_twice behind"
expect 2 "render unknown extension" rs render "$plate" -o r.txt
expect 2 "render bad --spp" rs render "$plate" --spp 0 -o r.exr
expect 2 "render --set not JSON" rs render "$plate" --set plate.bsdf.reflectance.value=abc -o r.exr

# ---- wavelength sweep: L(lambda) = rho(lambda) E / pi, rho tabulated 0.2 at 400 to 0.8 at 700 ----
expect 0 "sweep grid" rs sweep "$plate" --grid 'wavelength=400:700:100' \
  --set 'plate.bsdf.reflectance.value={"wavelengths":[400,700],"values":[0.2,0.8]}' --format json -o sw
py "sweep index and values rho(w)/pi" '
import json, math, os
lines = [json.loads(l) for l in open("sw/index.jsonl")]
assert len(lines) == 4, lines
assert [l["context"] for l in lines] == ["c00000", "c00001", "c00002", "c00003"]
for l, w in zip(lines, [400, 500, 600, 700]):
    assert l["wavelength"] == w and l["sensor"] == "nadir" and l["file"] == l["context"] + "/nadir.json", l
    assert "plate.bsdf.reflectance.value" in l["params"] and isinstance(l["seed"], int)
    rho = 0.2 + 0.6 * (w - 400) / 300
    v = json.load(open(os.path.join("sw", l["file"])))["data"][0]
    assert abs(v - rho / math.pi) < 1e-6, (w, v, rho / math.pi)
'
# --contexts: ids given or numbered by line; a parameter grid on a key.
printf '%s\n' '{"id":"mine","wavelength":450}' '' '{"wavelength":650,"params":{"plate.bsdf.reflectance.value":0.4}}' >ctx.jsonl
expect 0 "sweep --contexts" rs -q sweep "$plate" --contexts ctx.jsonl --format npy -o sc
# (--quiet keeps warnings: these contexts differ in a wavelength the grey plate ignores)
! grep -v ': warning: job [^ ]*: wavelength_unused (wavelength): ' err | grep -q . && ok ||
  bad "sweep --quiet wrote to stderr: $(cat err)"
[ "$(grep -c ': warning: job [^ ]*: wavelength_unused (wavelength): ' err)" = 1 ] && ok ||
  bad "sweep --quiet: the wavelength_unused warning is missing or repeated (printed at submission; the end adds only the renders' own): $(cat err)"
py "sweep --contexts ids and params" '
import json
lines = [json.loads(l) for l in open("sc/index.jsonl")]
assert [l["context"] for l in lines] == ["c00001", "mine"], lines
assert lines[0]["params"] == {"plate.bsdf.reflectance.value": 0.4} and lines[0]["file"] == "c00001/nadir.npy"
'
expect 0 "sweep grid on a key" rs sweep "$plate" --grid plate.bsdf.reflectance.value=0.1:0.3:0.1 --json --format json -o sk
py "grid on a key: inclusive end, values in params" '
import json, math
lines = [json.loads(l) for l in open("sk/index.jsonl")]
assert len(lines) == 3, lines
for l, rho in zip(lines, [0.1, 0.2, 0.3]):
    r = l["params"]["plate.bsdf.reflectance.value"]
    assert abs(r - rho) < 1e-12, r
    v = json.load(open("sk/" + l["file"]))["data"][0]
    assert abs(v - r / math.pi) < 1e-6
d = json.load(open("out")); assert d["films"] == 3 and d["state"] == "succeeded", d
'
# A list of values, and an axis that is a coordinate alone (no '.'): the
# scene's template reads it (the CLI sent it as an unknown parameter 'sza'
# before). The plate's sun at zenith sza: radiance rho cos(sza) / pi.
cat >sunplate.json <<'EOF2'
{"type": "scene", "variant": "mono",
 "templates": {"sun.direction": {"sun": {"zenith": "sza", "azimuth": 0}}},
 "camera": {"type": "distant", "direction": [0, 0, -1], "target": [0, 0, 0],
            "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}},
 "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": 1},
 "plate": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": 0.5}}}
EOF2
expect 0 "sweep --grid of a template's coordinate, as a list" rs -q sweep sunplate.json --grid sza=0,45,60 \
  --grid wavelength=450,650 --spp 4 --format json -o sza
py "grid lists: the product, coords, and the sun each context's template made" '
import json, math
lines = [json.loads(l) for l in open("sza/index.jsonl")]
assert [(l["coords"]["sza"], l["wavelength"]) for l in lines] == [
    (0, 450), (0, 650), (45, 450), (45, 650), (60, 450), (60, 650)], lines
for l in lines:
    assert l["params"] == {}, l
    v = json.load(open("sza/" + l["file"]))["data"][0]
    want = 0.5 * math.cos(math.radians(l["coords"]["sza"])) / math.pi
    assert abs(v - want) < 1e-6, (l, v, want)
'
expect 2 "sweep --grid list with a word" rs sweep sunplate.json --grid sza=0,x,60 -o x
contains "sweep --grid list: names the value" err "value 2 ('x') is not a number"
expect 2 "sweep --grid with a name that is no coordinate" rs sweep sunplate.json --grid 2sza=0,30 -o x
contains "sweep --grid bad name: says what NAME may be" err "neither wavelength, a parameter key"
expect 2 "sweep --grid list of wavelengths with a zero" rs sweep sunplate.json --grid wavelength=450,0 -o x
[ ! -e x ] && ok || bad "a refused --grid left x behind"
# --templates: the job's templates, for a scene that has none (an XML
# scene takes its templates from its jobs); inline JSON, or a file.
cat >sunplate.xml <<'EOF2'
<scene version="3.0.0">
  <sensor type="distant" id="meter">
    <vector name="direction" x="0" y="0" z="-1"/>
    <point name="target" x="0" y="0" z="0"/>
    <film type="hdrfilm"><integer name="width" value="1"/><integer name="height" value="1"/></film>
  </sensor>
  <emitter type="directional" id="sun"><vector name="direction" x="0" y="0" z="-1"/></emitter>
  <shape type="rectangle" id="plate"><bsdf type="diffuse"><float name="reflectance" value="0.5"/></bsdf></shape>
</scene>
EOF2
sun_tmpl='{"sun.direction": {"sun": {"zenith": "sza", "azimuth": 0}}}'
expect 0 "sweep --templates inline" rs -q sweep sunplate.xml --templates "$sun_tmpl" --grid sza=0,60 --spp 4 \
  --format json -o tmpl
printf '%s\n' "$sun_tmpl" >tmpl.json
expect 0 "sweep --templates FILE" rs -q sweep sunplate.xml --templates tmpl.json --grid sza=0,60 --spp 4 \
  --format json -o tmplf
py "sweep --templates: each context's sun from its sza (rgb: every channel rho cos(sza) / pi)" '
import json, math
for d in ("tmpl", "tmplf"):
    lines = [json.loads(l) for l in open(d + "/index.jsonl")]
    assert [l["coords"] for l in lines] == [{"sza": 0}, {"sza": 60}], lines
    for l in lines:
        v = json.load(open(d + "/" + l["file"]))["data"]
        want = 0.5 * math.cos(math.radians(l["coords"]["sza"])) / math.pi
        assert all(abs(c - want) < 1e-6 for c in v), (d, l, v, want)
'
# The templates are part of the sweep's identity: shards swept with other
# templates are other sweeps, and merge does not join them (it did, and
# mixed their films).
sun_v='{"sun.direction": {"sun": {"zenith": "sza", "azimuth": 180}}}'
for t in 0 1; do
  expect 0 "sweep --templates shard $t/2" rs -q sweep sunplate.xml --templates "$sun_tmpl" --grid sza=0,30,60 \
    --spp 4 --bundle 1 --shard $t/2 -o tshard$t
done
expect 0 "sweep --templates shard 1/2, other templates" rs -q sweep sunplate.xml --templates "$sun_v" \
  --grid sza=0,30,60 --spp 4 --bundle 1 --shard 1/2 -o tshard1v
expect 0 "merge shards of one --templates" rs -q merge tshard0 tshard1 -o tmerged
expect 6 "merge shards of other --templates" rs -q merge tshard0 tshard1v -o tmerged_bad
contains "merge of other --templates: says what is missing" err "are missing"
printf '{\n  "sun.direction": {\n    "sun": {"zenith": sza}\n  }\n}\n' >badtmpl.json
expect 2 "sweep --templates malformed file" rs sweep sunplate.xml --templates badtmpl.json --grid sza=0,60 -o x
contains "sweep --templates: names the file, line and column" err "--templates badtmpl.json:3:23: malformed JSON"
expect 2 "sweep --templates malformed inline" rs sweep sunplate.xml --templates '{"sun.direction": ' --grid sza=0 -o x
contains "sweep --templates inline: says where" err "malformed JSON at line 1"
expect 2 "sweep --templates an array" rs sweep sunplate.xml --templates '[1]' --grid sza=0 -o x
contains "sweep --templates array: wants an object" err "a JSON object {KEY: template}"
expect 2 "sweep --templates no such file" rs sweep sunplate.xml --templates nosuch.json --grid sza=0 -o x
contains "sweep --templates no file: names it" err "--templates nosuch.json: cannot read it"
[ ! -e x ] && ok || bad "a refused --templates left x behind"
expect 1 "sweep --templates unknown key" rs sweep sunplate.xml --grid sza=0 -o tmplbad \
  --templates '{"sun.directio": {"sun": {"zenith": "sza", "azimuth": 0}}}'
contains "sweep --templates unknown key: the daemon's pointer" err "/templates/sun.directio"
contains "sweep --templates unknown key: did you mean" err "did you mean: sun.direction"
# render --coord NAME=VALUE (and --templates): the templates render the
# render's overrides, as a job context's (a render took no coords).
expect 0 "render --coord" rs render sunplate.json --coord sza=60 -o coord.json
py "render --coord: the sun at zenith 60" 'import json, math; v = json.load(open("coord.json"))["data"][0]; assert abs(v - 0.5 * 0.5 / math.pi) < 1e-6, v'
expect 0 "render --coord --templates" rs render sunplate.xml --coord vza=60 -o coordt.json \
  --templates '{"sun.direction": {"sun": {"zenith": "vza", "azimuth": 0}}}'
py "render --coord --templates: the sun at zenith 60" 'import json, math; v = json.load(open("coordt.json"))["data"]; assert all(abs(c - 0.5 * 0.5 / math.pi) < 1e-6 for c in v), v'
expect 1 "render --coord that no template reads" rs render sunplate.xml --coord sza=60 -o coordx.json
contains "render --coord unread: the pointer" err "/coords/sza"
expect 2 "render --coord without a number" rs render sunplate.json --coord sza=high -o coordx.json
contains "render --coord: says what it needs" err "--coord needs NAME=NUMBER"
[ ! -e coordx.json ] && ok || bad "a refused render wrote coordx.json"

# job submit: a JobRequest as the daemon takes it, here with bands (which
# sweep's options do not carry), then job watch and fetch -o FILE.nc. The
# plate's reflectance is a table over the wavelength: a band's radiance is
# the SRF-weighted mean of rho(lambda) / pi.
cat >bandjob.json <<'EOF2'
{"seed": 3, "defaults": {"spp": 4},
 "params": {"plate.bsdf.reflectance.value": {"wavelengths": [400, 700], "values": [0.2, 0.8]}},
 "bands": [{"id": "blue", "srf": {"type": "uniform", "wmin": 450, "wmax": 520}},
           {"id": "red", "srf": {"type": "uniform", "wmin": 620, "wmax": 680}}],
 "contexts": [{"id": "only"}]}
EOF2
expect 0 "job submit FILE REQUEST" rs job submit plate.json bandjob.json
bjob=$(cat out)
py "job submit prints the job id" 'import re, sys; assert re.fullmatch(r"job-[0-9a-f]+-[0-9]+", sys.argv[1]), sys.argv[1]' "$bjob"
expect 0 "job watch the submitted job" rs -q job watch "$bjob" --timeout 60
expect 0 "fetch the submitted job's dataset" rs -q fetch "$bjob" -o bands.nc
if /usr/bin/python3 -c 'import netCDF4' 2>/dev/null; then
  /usr/bin/python3 - <<'EOF2' && ok || bad "job submit with bands: the band values"
import math, netCDF4
d = netCDF4.Dataset("bands.nc")
bands = [str(b) for b in d["band"][:]]
v = d["radiance_srf"][:].ravel()
assert bands == ["blue", "red"], bands
# rho is linear in lambda: a uniform band's mean is rho at its centre
for b, x in zip(bands, v):
    c = {"blue": 485.0, "red": 650.0}[b]
    want = (0.2 + 0.6 * (c - 400) / 300) / math.pi
    assert abs(x - want) < 1e-5 * want, (b, x, want)
EOF2
fi
expect 0 "job submit inline JSON, --json" rs --json job submit "$plate" '{"contexts": [{"id": "a", "wavelength": 550}]}'
py "job submit --json: id and scene" 'import json, sys; d = json.load(open("out")); assert d["id"].startswith("job-") and d["scene"] == sys.argv[1], d' "$plate"
printf '{"contexts": [{"id": "s", "wavelength": 600}]}' >stdin.json
expect 0 "job submit REQUEST from the standard input" rs job submit "$plate" - <stdin.json
py "job submit -: a job id" 'import re, sys; assert re.fullmatch(r"job-[0-9a-f]+-[0-9]+\n?", open("out").read()), open("out").read()'
printf '{"contexts": ' >stdin.json
expect 2 "job submit malformed standard input" rs job submit "$plate" - <stdin.json
contains "job submit -: names stdin" err "REQUEST stdin:1:"
printf '{"contexts": [\n  {"id": "a",\n   "wavelength": 550,}\n]}\n' >badjob.json
expect 2 "job submit malformed REQUEST file" rs job submit "$plate" badjob.json
contains "job submit: names the file and line" err "REQUEST badjob.json:3:"
expect 2 "job submit REQUEST not an object" rs job submit "$plate" '[{"id": "a"}]'
contains "job submit array: wants an object" err "REQUEST: a JSON object"
expect 1 "job submit: the daemon refuses a wavelength with bands" rs job submit "$plate" \
  '{"bands": [{"id": "b", "srf": {"type": "uniform", "wmin": 450, "wmax": 520}}], "contexts": [{"id": "a", "wavelength": 500}]}'
contains "job submit 422: the pointer" err "/contexts/0/wavelength"
# A job whose renders fail: job watch and job show say why, not only how
# many (a sun below the horizon leaves brf nothing to divide by).
expect 0 "job submit renders that fail" rs job submit sunplate.json \
  '{"quantities": ["brf"], "contexts": [{"id": "noon", "coords": {"sza": 10}}, {"id": "night", "coords": {"sza": 100}}, {"id": "night2", "coords": {"sza": 120}}]}'
fjob=$(cat out)
expect 4 "job watch: some renders failed" rs -q job watch "$fjob" --timeout 60
contains "job watch: the first failure's reason" err "night/camera failed: quantities: brdf and brf divide by the horizontal irradiance"
contains "job watch: how many more" err "(and 1 more)"
expect 0 "job show of a job with failed renders" rs job show "$fjob"
contains "job show: the first failure's reason" err "night/camera failed: quantities: brdf and brf"
expect 0 "sweep: a shard past the end" rs -q sweep "$plate" --grid wavelength=400:400:1 --shard 1/2 -o empty
[ -f empty/index.jsonl ] && [ ! -s empty/index.jsonl ] && ok || bad "an empty shard should write an empty index"
expect 1 "sweep --set unknown key" rs sweep "$plate" --grid wavelength=400:500:100 --set plate.bsdf.reflectanc.value=0.5 -o x
contains "sweep --set: did you mean" err "did you mean: plate.bsdf.reflectance.value"
expect 2 "sweep both --grid and --contexts" rs sweep "$plate" --grid wavelength=400:500:50 --contexts ctx.jsonl -o x
expect 2 "sweep bad --grid" rs sweep "$plate" --grid wavelength=400:300:10 -o x
expect 2 "sweep bad --shard" rs sweep "$plate" --grid wavelength=400:500:50 --shard 2/2 -o x
expect 2 "sweep without -o" rs sweep "$plate" --grid wavelength=400:500:50

# ---- shards: a stochastic scene (hdistant, 4 spp) so seeds matter ----
expect 0 "push hdistant" rs -q scene push "$root/proto/examples/hdistant_lambertian.json"
hd=$(cat out)
grid=(--grid wavelength=400:700:100 --grid sun.irradiance.value=1:2:1 --spp 4 --seed 11)
expect 0 "sweep unsharded" rs -q sweep "$hd" "${grid[@]}" -o u
expect 0 "sweep shard 0/2" rs -q sweep "$hd" "${grid[@]}" --shard 0/2 -o s0
expect 0 "sweep shard 1/2" rs -q sweep "$hd" "${grid[@]}" --shard 1/2 -o s1
expect 0 "merge" rs merge s1 s0 -o m
n_u=$(wc -l <u/index.jsonl)
[ "$n_u" -eq 8 ] && ok || bad "unsharded index has $n_u lines, wanted 8"
cmp -s u/index.jsonl m/index.jsonl && ok || bad "merged index differs from the unsharded one"
same=0
for f in $(cd u && ls ./*/*.exr); do cmp -s "u/$f" "m/$f" && same=$((same + 1)); done
[ "$same" -eq 8 ] && ok || bad "only $same of 8 merged films equal the unsharded ones"
[ "$(wc -l <s0/index.jsonl)" -eq 4 ] && grep -q '"c00002"' s0/index.jsonl && ! grep -q '"c00001"' s0/index.jsonl && ok ||
  bad "shard 0/2 should hold c00000, c00002, ...: $(cut -c1-40 s0/index.jsonl)"
expect 0 "sweep other seed" rs -q sweep "$hd" "${grid[@]}" --seed 12 -o u2
cmp -s u/c00003/sensor.exr u2/c00003/sensor.exr && bad "films do not depend on the seed: the shard check proves nothing" || ok
expect 0 "merge an identical duplicate" rs merge u s0 -o m2
cmp -s u/index.jsonl m2/index.jsonl && ok || bad "merge of u and s0 should equal u"
expect 6 "merge different films for one context" rs merge u u2 -o m3
contains "merge names the conflict" err "different films"
expect 6 "merge of a missing dir" rs merge nowhere -o m4

# ---- jobs ----
expect 0 "job ls" rs job ls
contains "job ls lists jobs" out "succeeded"
job1=$(awk 'NR==1{print $1}' out)
expect 0 "job show" rs job show "$job1"
contains "job show state" out "succeeded"
expect 0 "job show --json" rs job show "$job1" --json
py "job show --json" 'import json,sys; d=json.load(open(sys.argv[1])); assert d["id"]==sys.argv[2] and d["state"]=="succeeded"' out "$job1"
expect 0 "job watch finished" rs job watch "$job1"
expect 0 "fetch" rs fetch "$job1" c00001 nadir -o f.json
py "fetch film" 'import json,math; v=json.load(open("f.json"))["data"][0]; assert abs(v-0.4/math.pi)<1e-6, v'
expect 0 "fetch npy" rs fetch "$job1" c00001 nadir -o f.npy
expect 1 "fetch unknown context" rs fetch "$job1" nope nadir -o f2.json
# A long job: the sweep gives up waiting (5), then cancel, watch says 4.
expect 5 "sweep --timeout" rs sweep "$hd" --grid wavelength=400:700:10 --spp 50000 --timeout 0.3 -o big
long=$(sed -n 's/^raysweep sweep: job \([^:]*\):.*/\1/p' err | head -n 1)
[ -n "$long" ] && ok || bad "sweep did not name its job: $(cat err)"
expect 0 "job cancel" rs job cancel "$long"
contains "job cancel prints the state the cancel led to" out "$long cancelled"
expect 4 "job watch cancelled" rs job watch "$long" --timeout 20
contains "job watch says cancelled" out "cancelled"
expect 0 "job show cancelled" rs job show "$long" --json
py "job state cancelled" 'import json,sys; assert json.load(open(sys.argv[1]))["state"]=="cancelled"' out
expect 0 "job rm" rs job rm "$long"
expect 1 "job show removed" rs job show "$long"

# ---- errors ----
expect 3 "daemon not running" rs --server http://127.0.0.1:1 status
contains "not running: clear message" err "cannot connect to raysweepd at http://127.0.0.1:1"
expect 1 "unknown scene" rs scene show 0000000000000000000000000000000000000000000000000000000000000000
contains "unknown scene: the server's code" err "RSW_ERR_NOT_FOUND"
expect 1 "render unknown scene" rs render nosuchscene -o x.exr
expect 1 "unknown parameter key" rs set "$plate" plate.bsdf.reflectanc.value=0.5
contains "unknown key: did you mean" err "did you mean: plate.bsdf.reflectance.value"
expect 1 "unknown key in render --set" rs render "$plate" --set plate.bsdf.reflectanc.value=0.5 -o x.exr
contains "render --set: did you mean" err "did you mean"
echo secret-token >token
echo wrong-token >wrong
start_daemon "$tmp/d2" --token-file "$tmp/token"
port2=$started_port
if [ -n "$port2" ]; then
  expect 1 "wrong token" rs --server "http://127.0.0.1:$port2" --token-file wrong scene ls
  contains "wrong token: 401" err "401"
  expect 1 "no token" rs --server "http://127.0.0.1:$port2" scene ls
  expect 0 "right token file" rs --server "http://127.0.0.1:$port2" --token-file token scene ls
  RAYSWEEP_TOKEN=secret-token expect 0 "RAYSWEEP_TOKEN" rs --server "http://127.0.0.1:$port2" scene ls
else
  bad "the daemon with a token did not start: $(cat "$tmp/d2/log")"
fi
expect 6 "unreadable token file" rs --token-file /nonexistent/token status
expect 2 "no command" rs
expect 2 "unknown command" rs frobnicate
expect 2 "unknown subcommand" rs scene frob
expect 2 "missing argument" rs scene show
expect 2 "unknown option" rs scene ls --bogus
expect 2 "set without =" rs set "$plate" novalue
expect 0 "help" rs --help
contains "help documents exit codes" out "Exit codes"
expect 0 "command help" rs sweep --help
contains "sweep help" out "--shard I/N"
expect 0 "group help" rs job --help
contains "job help" out "raysweep job watch"

# ---- scene rm last: jobs above used the scenes ----
expect 0 "scene rm" rs scene rm "$seed_id"
expect 1 "scene show removed" rs scene show "$seed_id"
expect 0 "scene rm --force" rs scene rm "$hd" --force

finish
