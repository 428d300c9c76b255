#!/usr/bin/env bash
# Every EXR of a film carries the same self-describing "raysweep:" string
# attributes, whoever writes it: `raysweepd render -o` (the reference), the
# daemon's `Accept: image/x-exr` answers (a synchronous render and a job
# result), and the client library through the CLI (`raysweep render -o
# x.exr`, `raysweep fetch`, `raysweep sweep --format exr`). The same context
# (mono, hdistant 32x32, 4 spp, seed 7, 550 nm; and an rgb one) is rendered
# each way and the attributes are read back from the file bytes by a small
# Python reader of
# the EXR header (independent of OpenEXR): every attribute of raysweepd
# render's file must be there with the same value (sensor, spp, seed,
# variant, wavelength_nm, the per-pixel zenith_deg / azimuth_deg), and the
# daemon's films add exactly raysweep:scene, raysweep:revision and
# raysweep:context (the job's context id, or "render").
# A periodic scene whose distant sensor looks exactly horizontally inside
# the slab (4 unresolved rays at 4 spp) adds raysweep:unresolved_rays = 4
# to every writer's file, "unresolved_rays": 4 to the daemon's JSON meta,
# job results and /metrics total, and a warning to the stderr of raysweepd
# render and raysweep render; the films above (none unresolved) have no such attribute or key.
# Ends with "test_exr_attrs: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_exr_attrs
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweep raysweepd
need_cmd python3 "to read the EXR headers"
need_cmd curl "to ask the daemon for EXR films"
cd "$tmp" || exit 1
scene=$root/proto/examples/hdistant_lambertian.json

# run LABEL CMD...: CMD must exit 0 (stdout to out, stderr to err).
run() {
  local label=$1
  shift
  if "$@" >"$tmp/out" 2>"$tmp/err"; then ok; else bad "$label: exit $?; stderr: $(head -c 600 "$tmp/err")"; fi
}

# The reference: one process, no daemon.
run "raysweepd render" "$bin/raysweepd" render "$scene" --spp 4 --seed 7 --wavelength 550 --threads 2 -o ref.exr

start_daemon "$tmp/d"
port=$started_port
if [ -z "$port" ]; then
  bad "the daemon did not start: $(cat "$tmp/d/log")"
  finish
fi
url="http://127.0.0.1:$port"
export RAYSWEEP_URL=$url
unset RAYSWEEP_TOKEN
rs() { "$bin/raysweep" "$@"; }
# The ISA the daemon's renders run (GET /v1; raysweepd render picks the
# same on this CPU): every writer carries it as raysweep:isa.
isa=$(curl -sf "$url/v1" | python3 -c 'import json, sys; print(json.load(sys.stdin)["isa"])')
case $isa in avx512 | avx2 | sse2 | generic) ok ;; *) bad "GET /v1 isa: '$isa'" ;; esac

run "scene push" rs -q scene push "$scene"
id=$(cat out)
# The daemon's own EXR: a synchronous render...
run "daemon render EXR" curl -sf -X POST "$url/v1/scenes/$id:render" -H 'Content-Type: application/json' \
  -H 'Accept: image/x-exr' -d '{"spp": 4, "seed": 7, "wavelength": 550}' -o daemon_render.exr
# ... and a job result (the CLI's sweep submits the job).
printf '%s\n' '{"id": "w550", "wavelength": 550, "spp": 4, "seed": 7}' >ctx.jsonl
run "sweep --format exr" rs --json sweep "$id" --contexts ctx.jsonl --format exr -o sw
job=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["job"])' out 2>/dev/null)
run "daemon job result EXR" curl -sf "$url/v1/jobs/$job/results/w550/sensor" -H 'Accept: image/x-exr' -o daemon_job.exr
# The client library through the CLI.
run "raysweep render -o x.exr" rs -q render "$id" --spp 4 --seed 7 --wavelength 550 -o cli_render.exr
run "raysweep fetch -o x.exr" rs -q fetch "$job" w550 sensor -o cli_fetch.exr
# sweep writes the daemon's EXR and .npy as they came (rsw_job_fetch_encoded,
# no decoding on the client), unsharded and --spread alike: byte for byte
# the files `raysweep fetch` writes from the decoded JSON film
# (rsw_film_save_exr / _npy), 401.3 nm (a %.17g longer than its shortest
# form) as well as 550.
printf '%s\n' '{"id": "w550", "wavelength": 550, "spp": 4, "seed": 7}' \
  '{"id": "w401", "wavelength": 401.3, "spp": 4, "seed": 7}' >ctx2.jsonl
for fmt in exr npy; do
  run "sweep --format $fmt (2 contexts)" rs --json sweep "$id" --contexts ctx2.jsonl --format $fmt -o "sw2_$fmt"
  job2=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["job"])' out 2>/dev/null)
  run "sweep --format $fmt --spread 1" rs -q sweep "$id" --contexts ctx2.jsonl --format $fmt --spread 1 -o "sw2s_$fmt"
  for c in w550 w401; do
    run "raysweep fetch -o $c.$fmt" rs -q fetch "$job2" $c sensor -o "cli2_$c.$fmt"
    if cmp -s "sw2_$fmt/$c/sensor.$fmt" "cli2_$c.$fmt" && cmp -s "sw2s_$fmt/$c/sensor.$fmt" "cli2_$c.$fmt"; then ok; else
      bad "sweep --format $fmt $c: the film differs from raysweep fetch's (unsharded: $(cmp "sw2_$fmt/$c/sensor.$fmt" "cli2_$c.$fmt" 2>&1 | head -c 200); --spread 1: $(cmp "sw2s_$fmt/$c/sensor.$fmt" "cli2_$c.$fmt" 2>&1 | head -c 200))"
    fi
  done
done

# check REF WANT_JSON SCENE_ID LABEL=FILE=CONTEXT...: REF must hold the
# attributes WANT_JSON plus the two angle lists; each FILE must hold REF's
# attributes with the same values, plus scene, revision and CONTEXT.
cat >check.py <<'EOF'
import json, struct, sys

standard = {"channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
            "screenWindowCenter", "screenWindowWidth", "type"}

def attrs(path):
    """The non-standard string attributes of an EXR header read from the
    bytes, the non-standard attribute types, the data window's pixel count."""
    b = open(path, "rb").read()
    assert b[:4] == b"\x76\x2f\x31\x01", path + ": not an EXR file"
    i, out, types, npix = 8, {}, {}, 0
    while b[i] != 0:
        j = b.index(0, i); key = b[i:j].decode(); i = j + 1
        j = b.index(0, i); typ = b[i:j].decode(); i = j + 1
        (n,) = struct.unpack("<i", b[i:i + 4]); i += 4
        if key not in standard:
            types[key] = typ
            if typ == "string":
                out[key] = b[i:i + n].decode()
        if key == "dataWindow":
            x0, y0, x1, y1 = struct.unpack("<4i", b[i:i + 16])
            npix = (x1 - x0 + 1) * (y1 - y0 + 1)
        i += n
    return out, types, npix

angles = {"raysweep:zenith_deg", "raysweep:azimuth_deg"}
ref_path, want, scene_id = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3]
ref, ref_types, npix = attrs(ref_path)
errors = []
for k, v in want.items():
    if ref.get(k) != v:
        errors.append("raysweepd render: %s = %r, want %r" % (k, ref.get(k), v))
for k in angles:
    if len(ref.get(k, "").split(",")) != npix:
        errors.append("raysweepd render: %s is not %d angles" % (k, npix))
if set(ref_types) != set(want) | angles:
    errors.append("raysweepd render: attributes %s" % sorted(set(ref_types)))
for arg in sys.argv[4:]:
    label, path, context = arg.split("=")
    try:
        got, types, _ = attrs(path)
    except Exception as e:
        errors.append("%s: %s" % (label, e))
        continue
    for k, v in ref.items():
        if got.get(k) != v:
            shown = (got.get(k) or "(none)")[:60]
            errors.append("%s: %s = %s, raysweepd render wrote %s" % (label, k, shown, v[:60]))
    extra = {k: v for k, v in got.items() if k not in ref}
    # A scene with one directional emitter: its angles too (the JSON meta's
    # sun_zenith_deg and sun_azimuth_deg), which raysweepd render -o does not write.
    sun = {"raysweep:sun_zenith_deg", "raysweep:sun_azimuth_deg"}
    if sun <= set(extra):
        try:
            [float(extra.pop(k)) for k in sun]
        except ValueError:
            errors.append("%s: the sun's angles are not numbers" % label)
    if set(extra) != {"raysweep:scene", "raysweep:revision", "raysweep:context"}:
        errors.append("%s: attributes beyond raysweepd render's: %s" % (label, sorted(extra)))
    elif extra["raysweep:scene"] != scene_id or extra["raysweep:context"] != context or \
            not extra["raysweep:revision"].isdigit():
        errors.append("%s: scene/revision/context %s" % (label, extra))
    if set(types) != set(got):
        errors.append("%s: non-string attributes %s" % (label, sorted(set(types) - set(got))))
if errors:
    print("\n".join(errors[:16]))
    sys.exit(1)
EOF
check() {
  if python3 check.py "$@" >"$tmp/py" 2>&1; then ok; else bad "$(cat "$tmp/py")"; fi
}
check ref.exr '{"raysweep:sensor": "sensor", "raysweep:spp": "4", "raysweep:seed": "7",
  "raysweep:variant": "mono", "raysweep:wavelength_nm": "550", "raysweep:isa": "'"$isa"'"}' "$id" \
  "daemon render (image/x-exr)=daemon_render.exr=render" \
  "daemon job result (image/x-exr)=daemon_job.exr=w550" \
  "raysweep render -o (rsw_film_save_exr)=cli_render.exr=render" \
  "raysweep fetch -o (rsw_film_save_exr)=cli_fetch.exr=w550" \
  "raysweep sweep --format exr=sw/w550/sensor.exr=w550"

# rgb (no wavelength), from Mitsuba XML.
xml=$root/proto/examples/hdistant_seed.xml
run "raysweepd render rgb" "$bin/raysweepd" render "$xml" --spp 4 --seed 9 --threads 2 -o ref_rgb.exr
run "scene push rgb" rs -q scene push "$xml"
id_rgb=$(cat out)
run "daemon render EXR rgb" curl -sf -X POST "$url/v1/scenes/$id_rgb:render" -H 'Content-Type: application/json' \
  -H 'Accept: image/x-exr' -d '{"spp": 4, "seed": 9}' -o daemon_rgb.exr
run "raysweep render -o x.exr rgb" rs -q render "$id_rgb" --spp 4 --seed 9 -o cli_rgb.exr
check ref_rgb.exr '{"raysweep:sensor": "hdistant", "raysweep:spp": "4", "raysweep:seed": "9",
  "raysweep:variant": "rgb", "raysweep:isa": "'"$isa"'"}' "$id_rgb" \
  "daemon render rgb (image/x-exr)=daemon_rgb.exr=render" \
  "raysweep render -o rgb (rsw_film_save_exr)=cli_rgb.exr=render"

# Unresolved rays under a periodic boundary: a distant sensor looking exactly
# horizontally between the soil and a sheet (tests/kernel/scene/test_periodic_sun.c).
cat >horizontal.json <<'EOF'
{"type": "scene", "variant": "mono",
 "cam": {"type": "distant", "direction": [0.6, 0.8, 0], "target": [0, 0, 0.5],
   "sampler": {"type": "independent", "sample_count": 2},
   "film": {"type": "hdrfilm", "width": 1, "height": 1}},
 "sky": {"type": "constant", "radiance": 1},
 "sheet": {"type": "rectangle", "to_world": [{"translate": [0, 0, 1]}], "bsdf": {"type": "diffuse"}},
 "soil": {"type": "rectangle", "bsdf": {"type": "diffuse"}},
 "cell": {"type": "periodic", "min": [-1, -1], "max": [1, 1]}}
EOF
run "raysweepd render unresolved" "$bin/raysweepd" render horizontal.json --spp 4 --seed 3 --threads 2 -o ref_unres.exr
if grep -q "warning: 4 rays .*unresolved.*periodic.*given up" err; then ok; else bad "raysweepd render: no unresolved-ray warning: $(head -c 600 err)"; fi
run "scene push unresolved" rs -q scene push horizontal.json
id_unres=$(cat out)
run "daemon render EXR unresolved" curl -sf -X POST "$url/v1/scenes/$id_unres:render" \
  -H 'Content-Type: application/json' -H 'Accept: image/x-exr' -d '{"spp": 4, "seed": 3}' -o daemon_unres.exr
run "daemon render JSON unresolved" curl -sf -X POST "$url/v1/scenes/$id_unres:render" \
  -H 'Content-Type: application/json' -d '{"spp": 4, "seed": 3}' -o daemon_unres.json
run "daemon render JSON resolved" curl -sf -X POST "$url/v1/scenes/$id:render" \
  -H 'Content-Type: application/json' -d '{"spp": 4, "seed": 7, "wavelength": 550}' -o daemon_res.json
printf '%s\n' '{"id": "h", "spp": 4, "seed": 3}' >ctx_unres.jsonl
run "sweep unresolved" rs --json sweep "$id_unres" --contexts ctx_unres.jsonl --format exr -o sw_unres
job_unres=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["job"])' out 2>/dev/null)
run "job results unresolved" curl -sf "$url/v1/jobs/$job_unres/results" -o results_unres.json
run "job results resolved" curl -sf "$url/v1/jobs/$job/results" -o results_res.json
run "metrics" curl -sf "$url/metrics" -o metrics.txt
run "raysweep render -o x.exr unresolved" rs -q render "$id_unres" --spp 4 --seed 3 -o cli_unres.exr
if grep -q "warning: 4 rays .*unresolved.*periodic.*given up" err; then ok; else bad "raysweep render: no unresolved-ray warning: $(head -c 600 err)"; fi
run "raysweep render -o x.exr resolved" rs -q render "$id" --spp 4 --seed 7 --wavelength 550 -o cli_res.exr
if [ ! -s err ]; then ok; else bad "raysweep -q render without unresolved rays printed: $(head -c 600 err)"; fi
cat >check_json.py <<'EOF'
import json
errors = []
meta = json.load(open("daemon_unres.json"))["meta"]
if meta.get("unresolved_rays") != 4:
    errors.append("daemon JSON meta unresolved_rays = %r, want 4" % meta.get("unresolved_rays"))
if "unresolved_rays" in json.load(open("daemon_res.json"))["meta"]:
    errors.append("daemon JSON meta of a film without unresolved rays has unresolved_rays")
res = json.load(open("results_unres.json"))["results"]
if [r.get("unresolved_rays") for r in res] != [4]:
    errors.append("job results unresolved_rays %r, want [4]" % [r.get("unresolved_rays") for r in res])
if any("unresolved_rays" in r for r in json.load(open("results_res.json"))["results"]):
    errors.append("job results of films without unresolved rays have unresolved_rays")
# 4 each: the EXR and JSON synchronous renders and the job (the CLI's render comes after).
total = [l.split()[1] for l in open("metrics.txt") if l.startswith("raysweep_unresolved_rays_total ")]
if total != ["12"]:
    errors.append("/metrics raysweep_unresolved_rays_total %r, want 12" % total)
if errors:
    print("\n".join(errors))
    raise SystemExit(1)
EOF
if python3 check_json.py >"$tmp/py" 2>&1; then ok; else bad "$(cat "$tmp/py")"; fi
check ref_unres.exr '{"raysweep:sensor": "cam", "raysweep:spp": "4", "raysweep:seed": "3",
  "raysweep:variant": "mono", "raysweep:wavelength_nm": "550", "raysweep:unresolved_rays": "4",
  "raysweep:isa": "'"$isa"'"}' "$id_unres" \
  "daemon render unresolved (image/x-exr)=daemon_unres.exr=render" \
  "daemon job result unresolved (sweep --format exr)=sw_unres/h/cam.exr=h" \
  "raysweep render -o unresolved (rsw_film_save_exr)=cli_unres.exr=render"
finish
