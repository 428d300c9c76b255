#!/usr/bin/env bash
# Every EXR of a film carries the same self-describing "raysweep:" string
# attributes, whoever writes it: `raysweepd render -o` (the reference), the
# daemon's `Accept: image/x-exr` answers (a synchronous render and a job
# result), and the client library through the CLI (`raysweep render -o
# x.exr`, `raysweep fetch`, `raysweep sweep --format exr`). The same context
# (mono, hdistant 32x32, 4 spp, seed 7, 550 nm) is rendered each way and the
# attributes are read back from the file bytes by a small Python reader of
# the EXR header (independent of OpenEXR): every attribute of raysweepd
# render's file must be there with the same value (sensor, spp, seed,
# variant, wavelength_nm, the per-pixel zenith_deg / azimuth_deg), and the
# daemon's films add exactly raysweep:scene, raysweep:revision and
# raysweep:context (the job's context id, or "render").
# Ends with "test_exr_attrs: N passed, N failed" (tests/run.sh sums it).
set -u
root=$(cd "$(dirname "$0")/../.." && pwd)
bin=$(cd "${RSW_BIN_DIR:-$root/build/bin}" 2>/dev/null && pwd)
name=test_exr_attrs
pass=0
fail=0
ok() { pass=$((pass + 1)); }
bad() {
  fail=$((fail + 1))
  echo "FAIL $name: $*"
}
finish() {
  echo "$name: $pass passed, $fail failed"
  [ "$fail" -eq 0 ]
  exit $?
}
if [ -z "$bin" ] || [ ! -x "$bin/raysweep" ] || [ ! -x "$bin/raysweepd" ]; then
  bad "raysweep and raysweepd must be built in ${RSW_BIN_DIR:-build/bin}"
  finish
fi
command -v python3 >/dev/null || {
  bad "python3 is needed to read the EXR headers"
  finish
}
command -v curl >/dev/null || {
  bad "curl is needed to ask the daemon for EXR films"
  finish
}

tmp=$(mktemp -d)
pid=
cleanup() {
  [ -n "$pid" ] && kill "$pid" 2>/dev/null && wait "$pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
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

mkdir -p d/data
"$bin/raysweepd" serve --listen 127.0.0.1:0 --port-file d/port --data-root d/data >d/log 2>&1 &
pid=$!
for _ in $(seq 200); do
  [ -s d/port ] && break
  sleep 0.05
done
port=$(cat d/port 2>/dev/null)
if [ -z "$port" ]; then
  bad "the daemon did not start: $(cat d/log)"
  finish
fi
url="http://127.0.0.1:$port"
export RAYSWEEP_URL=$url
unset RAYSWEEP_TOKEN
rs() { "$bin/raysweep" "$@"; }

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

if python3 - "$id" sw/w550/sensor.exr >"$tmp/py" 2>&1 <<'EOF'; then ok; else bad "$(cat "$tmp/py")"; fi
import struct, sys

def attrs(path):
    """String attributes of an EXR header, read from the bytes."""
    b = open(path, "rb").read()
    assert b[:4] == b"\x76\x2f\x31\x01", path + ": not an EXR file"
    i, out, types = 8, {}, {}
    while b[i] != 0:
        j = b.index(0, i); key = b[i:j].decode(); i = j + 1
        j = b.index(0, i); typ = b[i:j].decode(); i = j + 1
        (n,) = struct.unpack("<i", b[i:i + 4]); i += 4
        types[key] = typ
        if typ == "string":
            out[key] = b[i:i + n].decode()
        i += n
    return out, types

standard = {"channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
            "screenWindowCenter", "screenWindowWidth"}
ref, ref_types = attrs("ref.exr")
want = {"raysweep:sensor": "sensor", "raysweep:spp": "4", "raysweep:seed": "7", "raysweep:variant": "mono",
        "raysweep:wavelength_nm": "550"}
errors = []
for k, v in want.items():
    if ref.get(k) != v:
        errors.append("raysweepd render: %s = %r, want %r" % (k, ref.get(k), v))
for k in ("raysweep:zenith_deg", "raysweep:azimuth_deg"):
    if len(ref.get(k, "").split(",")) != 32 * 32:
        errors.append("raysweepd render: %s is not 1024 angles" % k)
if set(ref_types) - standard != set(ref):
    errors.append("raysweepd render: unexpected attributes %s" % sorted(set(ref_types) - standard - set(ref)))

scene_id, sweep_film = sys.argv[1], sys.argv[2]
films = {"daemon render (image/x-exr)": ("daemon_render.exr", "render"),
         "daemon job result (image/x-exr)": ("daemon_job.exr", "w550"),
         "raysweep render -o (rsw_film_save_exr)": ("cli_render.exr", "render"),
         "raysweep fetch -o (rsw_film_save_exr)": ("cli_fetch.exr", "w550"),
         "raysweep sweep --format exr": (sweep_film, "w550")}
for label, (path, context) in films.items():
    try:
        got, types = attrs(path)
    except Exception as e:
        errors.append("%s: %s" % (label, e))
        continue
    for k, v in ref.items():
        if got.get(k) != v:
            shown = (got.get(k) or "(none)")[:60]
            errors.append("%s: %s = %s, raysweepd render wrote %s" % (label, k, shown, v[:60]))
    extra = {k: v for k, v in got.items() if k not in ref}
    if set(extra) != {"raysweep:scene", "raysweep:revision", "raysweep:context"}:
        errors.append("%s: attributes beyond raysweepd render's: %s" % (label, sorted(extra)))
    if extra.get("raysweep:scene") != scene_id or extra.get("raysweep:context") != context or \
            not extra.get("raysweep:revision", "").isdigit():
        errors.append("%s: scene/revision/context %s" % (label, extra))
    if set(types) - standard != set(got):
        errors.append("%s: non-string attributes %s" % (label, sorted(set(types) - standard - set(got))))
if errors:
    print("\n".join(errors[:12]))
    sys.exit(1)
EOF
finish
