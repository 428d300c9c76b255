#!/usr/bin/env bash
# A pushed document yields its own state, through the command line and
# HTTP (issue 24; docs/daemon.md#a-document-yields-its-own-state):
#  - `raysweep scene push FILE` after `raysweep set` answers another scene
#    in the file's state (before: "was already resident", the set value);
#  - `raysweep scene reset ID` prints the keys it set back and the
#    revision, and the twin is handed to pushes again;
#  - `raysweep scene copy ID` prints a new id in ID's state;
#  - POST :reset and :copy over HTTP (200, 201 with Location);
#  - an XML file pushed with an error is named in the error (its name, not
#    scene.xml:N).
# Ends with "test_scene_reset: N passed, N failed".
set -u
name=test_scene_reset
# shellcheck source=../support/shtest.sh
. "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd raysweep
start_daemon "$tmp/d"
[ -n "$started_port" ] || {
  bad "the daemon did not start: $(cat "$tmp/d/log")"
  finish
}
url=http://127.0.0.1:$started_port
export RAYSWEEP_URL=$url
rs() { "$bin/raysweep" "$@"; }
doc=$root/proto/examples/hdistant_lambertian.json
key=surface.bsdf.reflectance.value
value() { rs params "$1" --match "$key" 2>/dev/null | awk '{print $NF}'; }

a=$(rs scene push "$doc" 2>/dev/null)
doc_value=$(value "$a")
expect 0 "set" rs set "$a" "$key=0.9"
b=$(rs scene push "$doc" 2>"$tmp/push.err")
[ -n "$b" ] && [ "$b" != "$a" ] && ok || bad "a push after set answered the set scene $a again"
grep -q "loaded" "$tmp/push.err" && ok || bad "the push did not load: $(cat "$tmp/push.err")"
[ "$(value "$b")" = "$doc_value" ] && ok || bad "the new scene's $key is $(value "$b"), not the file's $doc_value"
[ "$(value "$a")" = 0.9 ] && ok || bad "the set scene lost its value: $(value "$a")"

c=$(rs scene copy "$a" 2>"$tmp/copy.err")
[ ${#c} = 64 ] && [ "$c" != "$a" ] && [ "$c" != "$b" ] && ok || bad "scene copy printed '$c'"
grep -q "copied to $c" "$tmp/copy.err" && ok || bad "scene copy's stderr: $(cat "$tmp/copy.err")"
[ "$(value "$c")" = 0.9 ] && ok || bad "the copy's $key is $(value "$c"), not 0.9"

expect 0 "scene reset" rs scene reset "$a"
contains "scene reset names the key and the revision" "$tmp/out" "$a: $key, revision 2"
[ "$(value "$a")" = "$doc_value" ] && ok || bad "after reset $key is $(value "$a")"
[ "$(value "$c")" = 0.9 ] && ok || bad "the reset changed the copy: $(value "$c")"
again=$(rs scene push "$doc" 2>"$tmp/push2.err")
[ "$again" = "$a" ] && ok || bad "a push after the reset got $again, not the twin $a"
grep -q "already resident" "$tmp/push2.err" && ok || bad "push after reset: $(cat "$tmp/push2.err")"
expect 0 "scene reset --json" rs --json scene reset "$a"
py "reset --json: nothing left to reset" \
  'import json,sys; j=json.load(open(sys.argv[1])); assert j["keys"] == [] and j["changed"] == 0 and j["revision"] == 2, j' \
  "$tmp/out"
expect 1 "scene reset of an unknown scene" rs scene reset 0000000000000000000000000000000000000000000000000000000000000000

# Over HTTP.
code=$(curl -sS -o "$tmp/r.json" -w '%{http_code}' -X POST "$url/v1/scenes/$b:reset")
[ "$code" = 200 ] && ok || bad "POST :reset: HTTP $code"
code=$(curl -sS -D "$tmp/h" -o "$tmp/c.json" -w '%{http_code}' -X POST "$url/v1/scenes/$b:copy")
[ "$code" = 201 ] && ok || bad "POST :copy: HTTP $code"
py "the copy's summary" \
  'import json,sys; j=json.load(open(sys.argv[1])); assert j["copy"] is True and j["document"] == sys.argv[2] and j["id"] != sys.argv[3], j' \
  "$tmp/c.json" "$a" "$b"
grep -qi "^location: /v1/scenes/[0-9a-f]\{64\}" "$tmp/h" && ok || bad "POST :copy has no Location: $(cat "$tmp/h")"

# An XML file with an error: the message names it.
cat >"$tmp/my_canopy.xml" <<'EOF'
<scene version="3.0.0">
  <shape type="rectangle">
    <bsdf type="nope"/>
  </shape>
</scene>
EOF
expect 1 "push a bad XML file" rs scene push "$tmp/my_canopy.xml"
contains "the XML error names the user's file" "$tmp/err" "my_canopy.xml:3"
grep -q "scene\.xml" "$tmp/err" && bad "the XML error names scene.xml: $(cat "$tmp/err")" || ok
finish
