#!/usr/bin/env bash
# raysweepd serve --plugin-dir with good and bad plugins side by side: the
# bad ones are refused with a message naming the file, the good ones load,
# the daemon serves (GET /v1 lists them) and a scene using one renders; a
# render through a plugin that returns NaN radiance completes with a
# finite film whose meta says how many answers were replaced by black and
# the first one's message (a render and a job's results, not silently);
# in a bundle of 16 wavelengths, through a plugin that answers NaN above
# 475 nm, each film carries its own wavelength's count (none below).
# Prints "test_serve_plugins: N passed, N failed".
set -u
here=$(cd "$(dirname "$0")/../.." && pwd)
cd "$here"
bin=${RSW_BIN_DIR:-build/bin}
build=$(dirname "$bin")
pass=0; fail=0
ok() { echo "ok   $1"; pass=$((pass + 1)); }
ko() { echo "FAIL $1: $2"; fail=$((fail + 1)); }
tmp=$(mktemp -d /tmp/rsw-serve-plugins-XXXXXX)
pid=""
cleanup() { [ -n "$pid" ] && kill -TERM "$pid" 2>/dev/null; wait "$pid" 2>/dev/null; rm -rf "$tmp"; }
trap cleanup EXIT

mkdir -p "$tmp/plugins"
cp "$build"/plugins/*.so "$tmp/plugins/" 2>/dev/null
# A plugin with the wrong ABI version and one with no entry point.
cat > "$tmp/bad_abi.c" <<'C'
#include <raysweep/plugin.h>
static const rsw_env_plugin T = {.abi_version = 999, .type_name = "badabi"};
RSW_PLUGIN_EXPORT const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *h) { (void)h; return &T; }
C
# nan_plugin TYPE PRETTY WHEN: a uniform sky of 1 whose radiance is NaN
# where the C expression WHEN holds (d: the direction, w: the wavelength);
# the host replaces it by black.
nan_plugin() {
  cat > "$tmp/$1.c" <<C
#include <math.h>
#include <raysweep/plugin.h>
static const rsw_plugin_host *host;
static int state;
static int create(const double *const *v, void **inst, char *eb, size_t n) { (void)v, (void)eb, (void)n; *inst = &state; return 0; }
static void destroy(void *inst) { (void)inst; }
static void add_radiance(const void *inst, rsw_stokes_context *ctx, const double d[3]) {
  (void)inst, (void)d;
  for (size_t i = 0; i < ctx->count; i++) {
    double w = ctx->wavelengths[i];
    ctx->stokes[0][i] += ($3) ? NAN : 1.0;
  }
}
static double sample(const void *inst, const double u[2], double d[3]) { (void)inst; host->square_to_uniform_sphere(u, d); return host->uniform_sphere_pdf(); }
static double pdf(const void *inst, const double d[3]) { (void)inst, (void)d; return host->uniform_sphere_pdf(); }
static const rsw_env_plugin T = {.abi_version = RSW_PLUGIN_ABI_VERSION, .type_name = "$1", .pretty_name = "$2",
  .create = create, .destroy = destroy, .add_radiance = add_radiance, .sample = sample, .pdf = pdf};
RSW_PLUGIN_EXPORT const rsw_env_plugin *rsw_env_plugin_entry(const rsw_plugin_host *h) { host = h; return &T; }
C
  cc -shared -fPIC -I include -o "$tmp/plugins/$1.so" "$tmp/$1.c"
}
nan_plugin nan_sky "NaN towards +x" "d[0] > 0" &&
  nan_plugin nan_above "NaN above 475 nm" "w > 475" || { echo "test_serve_plugins: 0 passed, 1 failed"; exit 1; }
echo 'int not_a_plugin = 1;' > "$tmp/no_entry.c"
cc -shared -fPIC -I include -o "$tmp/plugins/bad_abi.so" "$tmp/bad_abi.c" && \
cc -shared -fPIC -o "$tmp/plugins/no_entry.so" "$tmp/no_entry.c" || { echo "test_serve_plugins: 0 passed, 1 failed"; exit 1; }
mkdir -p "$tmp/data"
"$bin/raysweepd" serve --listen 127.0.0.1:0 --port-file "$tmp/port" --plugin-dir "$tmp/plugins" --state-dir "$tmp/data" 2> "$tmp/log" &
pid=$!
for _ in $(seq 100); do [ -s "$tmp/port" ] && break; sleep 0.05; done
port=$(cat "$tmp/port" 2>/dev/null)
if [ -z "$port" ]; then
  ko start "the daemon did not start: $(cat "$tmp/log")"
  echo "test_serve_plugins: $pass passed, $fail failed"; exit 1
fi
ok start
grep -q "plugin refused: .*bad_abi.so" "$tmp/log" && ok refused_abi || ko refused_abi "$(cat "$tmp/log")"
grep -q "plugin refused: .*no_entry.so" "$tmp/log" && ok refused_entry || ko refused_entry "$(cat "$tmp/log")"
info=$(curl -s "http://127.0.0.1:$port/v1")
echo "$info" | grep -q '"sunsky"' && echo "$info" | grep -q '"test"' && ok good_plugins_listed || ko good_plugins_listed "$info"
echo "$info" | grep -q '"badabi"' && ko bad_not_listed "$info" || ok bad_not_listed
scene='{"type": "scene", "variant": "mono",
 "meter": {"type": "radiancemeter", "origin": [0, 0, 0], "direction": [1, 0, 0],
   "film": {"type": "hdrfilm", "width": 1, "height": 1, "component_format": "float32"}},
 "sky": {"type": "test"}}'
id=$(curl -s -X POST "http://127.0.0.1:$port/v1/scenes" -H 'Content-Type: application/json' -d "$scene" | sed 's/.*"id":"\([0-9a-f]*\)".*/\1/')
# Looking towards +x at 600 nm the "test" sky is 5.108; at 450 nm it is 0.
v600=$(curl -s -X POST "http://127.0.0.1:$port/v1/scenes/$id:render" -H 'Content-Type: application/json' -d '{"spp": 4, "wavelength": 600}')
echo "$v600" | grep -q '"data":\[5.10' && ok render_600 || ko render_600 "$v600"
v450=$(curl -s -X POST "http://127.0.0.1:$port/v1/scenes/$id:render" -H 'Content-Type: application/json' -d '{"spp": 4, "wavelength": 450}')
echo "$v450" | grep -q '"data":\[0\]' && ok render_450 || ko render_450 "$v450"
# The NaN sky: a meter looking at +x sees black, and the film says so.
nscene='{"type": "scene", "variant": "mono",
 "meter": {"type": "radiancemeter", "origin": [0, 0, 0], "direction": [1, 0, 0],
   "film": {"type": "hdrfilm", "width": 1, "height": 1, "component_format": "float32"}},
 "sky": {"type": "nan_sky", "id": "bad_sky"}}'
nid=$(curl -s -X POST "http://127.0.0.1:$port/v1/scenes" -H 'Content-Type: application/json' -d "$nscene" | sed 's/.*"id":"\([0-9a-f]*\)".*/\1/')
vn=$(curl -s -X POST "http://127.0.0.1:$port/v1/scenes/$nid:render" -H 'Content-Type: application/json' -d '{"spp": 4, "wavelength": 600}')
echo "$vn" | grep -q '"data":\[0\]' && echo "$vn" | grep -q '"plugin_failures":4,' &&
  echo "$vn" | grep -q "\"plugin_failure\":\"emitter 'bad_sky' (plugin type 'nan_sky'): add_radiance returned I = nan at 600 nm" &&
  ok nan_render_says_so || ko nan_render_says_so "$vn"
# raysweepd render says so on stderr and in the EXR's attributes.
echo "$nscene" > "$tmp/nan.json"
mkdir -p "$tmp/nan_only" && cp "$tmp/plugins/nan_sky.so" "$tmp/nan_only/"
"$bin/raysweepd" render "$tmp/nan.json" --spp 4 --wavelength 600 --plugin-dir "$tmp/nan_only" -o "$tmp/nan.exr" 2> "$tmp/render.err"
grep -q "warning: 4 environment plugin failures were replaced by black; first: emitter 'bad_sky'" "$tmp/render.err" &&
  grep -aq "raysweep:plugin_failures" "$tmp/nan.exr" && grep -aq "add_radiance returned I = nan at 600 nm" "$tmp/nan.exr" &&
  ok nan_render_cli_says_so || ko nan_render_cli_says_so "$(cat "$tmp/render.err")"
# A job of two wavelengths (one bundle): each result says so too, and
# again after a restart (the job's record and its films keep it).
cat > "$tmp/nanjob.py" <<'PY'
import json, sys, time, urllib.request
port, what = sys.argv[1], sys.argv[2]
def call(path, body=None):
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", data=body and json.dumps(body).encode(),
                                 headers={"Content-Type": "application/json"})
    return json.loads(urllib.request.urlopen(req, timeout=60).read())
if what == "submit":
    j = call(f"/v1/scenes/{sys.argv[3]}/jobs", {"contexts": [{"id": "a", "wavelength": 500},
                                                             {"id": "b", "wavelength": 600}], "defaults": {"spp": 2}})
    jid = j["id"]
    for _ in range(400):
        if call(f"/v1/jobs/{jid}")["state"] not in ("queued", "running"):
            break
        time.sleep(0.05)
else:
    jid = what
res = call(f"/v1/jobs/{jid}/results")["results"]
assert len(res) == 2, res
for r in res:
    assert r.get("plugin_failures", 0) > 0 and "add_radiance returned I = nan" in r["plugin_failure"], r
    f = call(r["href"])
    assert f["data"] == [0] and f["meta"]["plugin_failures"] == r["plugin_failures"], f
    assert f["meta"]["plugin_failure"] == r["plugin_failure"], f
w = [x for x in call(f"/v1/jobs/{jid}").get("warnings", []) if x["code"] == "plugin_failures"]
assert len(w) == 1 and "replaced by black" in w[0]["detail"] and "nan_sky" in w[0]["detail"], w
print(jid)
PY
njob=$(python3 "$tmp/nanjob.py" "$port" submit "$nid" 2>"$tmp/pyerr") && ok nan_job_says_so || ko nan_job_says_so "$(tail -n 3 "$tmp/pyerr")"
# A bundle of 16 (400..550 nm) under nan_above, a grey plate seen by
# hdistant: the films at 400..470 nm carry no failure, those at 480..550
# nm some, each with a message at its own wavelength; the job warns once.
cat > "$tmp/bundlejob.py" <<'PY'
import json, sys, time, urllib.request
port = sys.argv[1]
def call(path, body=None):
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", data=body and json.dumps(body).encode(),
                                 headers={"Content-Type": "application/json"})
    return json.loads(urllib.request.urlopen(req, timeout=60).read())
scene = {"type": "scene", "variant": "mono",
         "sensor": {"type": "hdistant", "target": [0, 0, 0], "sampler": {"type": "independent", "sample_count": 4},
                    "to_world": [{"lookat": {"origin": [0, 0, 0], "target": [0, 0, 1], "up": [0, 1, 0]}}],
                    "film": {"type": "hdrfilm", "width": 4, "height": 4, "rfilter": {"type": "box"}}},
         "plate": {"type": "rectangle", "to_world": [{"scale": [10, 10, 1]}],
                   "bsdf": {"type": "diffuse", "reflectance": 0.5}},
         "sky": {"type": "nan_above", "id": "sky"}}
sid = call("/v1/scenes", scene)["id"]
wls = [400.0 + 10 * i for i in range(16)]
j = call(f"/v1/scenes/{sid}/jobs", {"contexts": [{"id": f"w{int(w)}", "wavelength": w} for w in wls], "bundle": 16})
for _ in range(400):
    j = call(f"/v1/jobs/{j['id']}")
    if j["state"] not in ("queued", "running"):
        break
    time.sleep(0.05)
assert j["state"] == "succeeded" and j["bundle"] == 16, j
res = {r["context"]: r for r in call(f"/v1/jobs/{j['id']}/results")["results"]}
assert len(res) == 16, res
for w in wls:
    r = res[f"w{int(w)}"]
    f = call(r["href"])
    assert all(v == v for v in f["data"]), (w, f["data"])
    if w < 475:
        assert "plugin_failures" not in r and "plugin_failures" not in f["meta"], (w, r, f["meta"])
    else:
        assert r.get("plugin_failures", 0) > 0 and f"I = nan at {w:g} nm" in r["plugin_failure"], (w, r)
        assert f["meta"]["plugin_failures"] == r["plugin_failures"], (w, f["meta"], r)
        assert f["meta"]["plugin_failure"] == r["plugin_failure"], (w, f["meta"], r)
w = [x for x in j.get("warnings", []) if x["code"] == "plugin_failures"]
assert len(w) == 1 and "nan_above" in w[0]["detail"], j
PY
python3 "$tmp/bundlejob.py" "$port" 2>"$tmp/pyerr" && ok nan_bundle_per_film || ko nan_bundle_per_film "$(tail -n 3 "$tmp/pyerr")"
# raysweep sweep prints the job's warning.
"$bin/raysweep" --server "http://127.0.0.1:$port" sweep "$nid" --grid wavelength=500:600:100 --spp 2 \
  -o "$tmp/nansweep" > /dev/null 2> "$tmp/sweep.err"
grep -q "warning: job .*environment plugin answers were replaced by black" "$tmp/sweep.err" &&
  ok nan_sweep_says_so || ko nan_sweep_says_so "$(cat "$tmp/sweep.err")"
# raysweep render warns, and the EXR the client library writes from the
# film's meta carries the attributes.
"$bin/raysweep" --server "http://127.0.0.1:$port" render "$nid" --wavelength 600 --spp 4 -o "$tmp/client.exr" \
  > /dev/null 2> "$tmp/crender.err"
grep -q "warning: 4 environment plugin answers in .* were replaced by black; first: emitter 'bad_sky'" "$tmp/crender.err" &&
  grep -aq "raysweep:plugin_failures" "$tmp/client.exr" && ok nan_client_render_says_so ||
  ko nan_client_render_says_so "$(cat "$tmp/crender.err")"
kill -TERM "$pid"; wait "$pid" 2>/dev/null
rm -f "$tmp/port"
"$bin/raysweepd" serve --listen 127.0.0.1:0 --port-file "$tmp/port" --plugin-dir "$tmp/plugins" --state-dir "$tmp/data" 2>> "$tmp/log" &
pid=$!
for _ in $(seq 100); do [ -s "$tmp/port" ] && break; sleep 0.05; done
port=$(cat "$tmp/port" 2>/dev/null)
python3 "$tmp/nanjob.py" "$port" "$njob" >/dev/null 2>"$tmp/pyerr" && ok nan_job_after_restart || ko nan_job_after_restart "$(tail -n 3 "$tmp/pyerr")"
curl -sf "http://127.0.0.1:$port/v1/health/ready" > /dev/null && ok still_ready || ko still_ready "not ready"
echo "test_serve_plugins: $pass passed, $fail failed"
[ "$fail" -eq 0 ]
