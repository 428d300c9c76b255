#!/usr/bin/env bash
# raysweepd serve --plugin-dir with good and bad plugins side by side: the
# bad ones are refused with a message naming the file, the good ones load,
# the daemon serves (GET /v1 lists them) and a scene using one renders; a
# render through a plugin that returns NaN radiance completes with a
# finite film. Prints "test_serve_plugins: N passed, N failed".
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
echo 'int not_a_plugin = 1;' > "$tmp/no_entry.c"
cc -shared -fPIC -I include -o "$tmp/plugins/bad_abi.so" "$tmp/bad_abi.c" && \
cc -shared -fPIC -o "$tmp/plugins/no_entry.so" "$tmp/no_entry.c" || { echo "test_serve_plugins: 0 passed, 1 failed"; exit 1; }
"$bin/raysweepd" serve --listen 127.0.0.1:0 --port-file "$tmp/port" --plugin-dir "$tmp/plugins" 2> "$tmp/log" &
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
curl -sf "http://127.0.0.1:$port/v1/health/ready" > /dev/null && ok still_ready || ko still_ready "not ready"
echo "test_serve_plugins: $pass passed, $fail failed"
[ "$fail" -eq 0 ]
