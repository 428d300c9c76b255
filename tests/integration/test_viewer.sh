#!/usr/bin/env bash
# The web viewer (ui/, served at /ui/), against real daemons on loopback:
#  - the files: /ui redirects to /ui/, each file has its media type, an
#    ETag, Cache-Control and a 304 on If-None-Match; served without a token
#    by a daemon that has one, while the API there still answers 401;
#  - in headless Chromium (tests/support/viewer_driver.py, the DevTools
#    protocol): it lists the default scene, searches and edits a parameter
#    (checked with GET params), renders with spp/seed, shows the film
#    (screenshot pixels), draws the polar plot of the hdistant film where
#    the film's angles put it, follows a job to the end over the event
#    stream and cancels another; with a token configured it refuses
#    without it; shows a Stokes film (tests/plugins/polarized_sky.c) as
#    S0..S3, DoLP (grey) and AoLP (cyclic hue), pixels checked. Screenshots stay in $BUILD/test-artefacts/viewer.
# Chromium (Debian's `chromium`, in tools/deps.sh) is required: without it
# the test fails, it does not skip. RSW_VIEWER_DOCS_PNG=FILE also writes
# the page's screenshot there (docs/viewer.png is made so).
# Prints "test_viewer: N passed, N failed".
set -u
name=test_viewer
. "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd raysweep
need_cmd curl "to fetch the viewer's files"
need_cmd python3 "to drive Chromium (tests/support/viewer_driver.py)"
chromium=$(command -v chromium || command -v chromium-browser || true)
if [ -z "$chromium" ]; then
  bad "chromium is not installed: the viewer test needs Debian's chromium (make deps, tools/deps.sh)"
  finish
fi
art="$root/${BUILD:-build}/test-artefacts/viewer"
rm -rf "$art" && mkdir -p "$art"

# With the SDK examples (tests/plugins): a Stokes film's views.
start_daemon "$tmp/d1" --threads 2 --plugin-dir "$bin/../plugins"
U=http://127.0.0.1:$started_port
[ -n "$started_port" ] || { bad "daemon did not start: $(cat "$tmp/d1/log")"; finish; }
echo "secret-$$-token" >"$tmp/token"
start_daemon "$tmp/d2" --threads 2 --token-file "$tmp/token"
T=http://127.0.0.1:$started_port
[ -n "$started_port" ] || { bad "daemon with a token did not start: $(cat "$tmp/d2/log")"; finish; }

# ---- the files -----------------------------------------------------------------
hdr() { curl -s -o /dev/null -D - "$@" | tr -d '\r'; }
h=$(hdr "$U/ui")
echo "$h" | grep -q '^HTTP/1.1 301' && echo "$h" | grep -qi '^Location: /ui/$' && ok || bad "/ui does not redirect to /ui/: $h"
for f in "/ui/ text/html" "/ui/index.html text/html" "/ui/app.js text/javascript" "/ui/api.js text/javascript" \
  "/ui/plot.js text/javascript" "/ui/sweep.js text/javascript" "/ui/style.css text/css"; do
  set -- $f
  h=$(hdr "$U$1")
  if echo "$h" | grep -q '^HTTP/1.1 200' && echo "$h" | grep -qi "^Content-Type: $2; charset=utf-8$" &&
    echo "$h" | grep -qi '^ETag: "[0-9a-f]\{24\}"$' && echo "$h" | grep -qi '^Cache-Control: no-cache$' &&
    echo "$h" | grep -qi '^X-Content-Type-Options: nosniff$' && echo "$h" | grep -qi "^Content-Security-Policy: default-src 'self'"; then
    ok
  else
    bad "$1: want 200, $2, an ETag, no-cache, nosniff, a CSP; got: $h"
  fi
done
etag=$(hdr "$U/ui/app.js" | sed -n 's/^[Ee][Tt]ag: //p')
h=$(hdr -H "If-None-Match: $etag" "$U/ui/app.js")
echo "$h" | grep -q '^HTTP/1.1 304' && ok || bad "If-None-Match $etag: want 304, got $h"
h=$(hdr -H 'If-None-Match: "0000", W/'"$etag" "$U/ui/app.js")
echo "$h" | grep -q '^HTTP/1.1 304' && ok || bad "If-None-Match with a list and W/: want 304, got $h"
h=$(hdr -H 'If-None-Match: "0000"' "$U/ui/app.js")
echo "$h" | grep -q '^HTTP/1.1 200' && ok || bad "a stale If-None-Match: want 200, got $h"
st=$(curl -s -o "$tmp/out" -w '%{http_code} %{content_type}' "$U/ui/nothing.js")
[ "$st" = "404 application/problem+json" ] && ok || bad "/ui/nothing.js: $st $(head -c 200 "$tmp/out")"
st=$(curl -s -o /dev/null -w '%{http_code}' -X POST "$U/ui/app.js")
[ "$st" = 405 ] && ok || bad "POST /ui/app.js: $st, want 405"
st=$(curl -s -o /dev/null -w '%{http_code}' "$T/ui/")
[ "$st" = 200 ] && ok || bad "with a token configured, /ui/ without it: $st, want 200"
st=$(curl -s -o /dev/null -w '%{http_code}' "$T/v1/scenes")
[ "$st" = 401 ] && ok || bad "with a token configured, the API without it: $st, want 401"

# ---- scene labels: the pushed file's name ------------------------------------------
# raysweep scene push sends the file's name (?name=), the scene's summary
# carries it (`name`), the viewer shows it; the embedded default scene is
# named after its file.
mkdir -p "$tmp/scenes" && cp "$root/proto/examples/hdistant_lambertian.json" "$tmp/scenes/my-plate.json"
pid=$(RAYSWEEP_URL=$U "$bin/raysweep" -q scene push "$tmp/scenes/my-plate.json" 2>"$tmp/err")
label=$(curl -s "$U/v1/scenes/$pid" | python3 -c 'import json, sys; print(json.load(sys.stdin).get("name"))')
[ "$label" = my-plate.json ] && ok || bad "raysweep scene push: the scene's name is '$label', want my-plate.json ($(cat "$tmp/err"))"
label=$(curl -s "$U/v1/scenes" | python3 -c 'import json, sys; print([s.get("name") for s in json.load(sys.stdin)["scenes"]])')
echo "$label" | grep -q "'default_scene.xml'" && ok || bad "the default scene's name: $label"
st=$(curl -s -o "$tmp/out" -w '%{http_code}' -H 'Content-Type: application/json' \
  --data-binary @"$root/proto/examples/white_furnace.json" "$U/v1/scenes?name=a%0Ab")
[ "$st" = 400 ] && grep -q 'query parameter name' "$tmp/out" && ok || bad "a name with a newline: $st $(cat "$tmp/out")"

# ---- in Chromium ------------------------------------------------------------------
docs=()
[ -n "${RSW_VIEWER_DOCS_PNG:-}" ] && docs=(--docs-png "$RSW_VIEWER_DOCS_PNG")
out=$(timeout 300 python3 "$root/tests/support/viewer_driver.py" --chromium "$chromium" --base "$U" \
  --token-base "$T" --token "$(cat "$tmp/token")" --artefacts "$art" "${docs[@]}" 2>&1)
rc=$?
echo "$out" | grep -v '^ok   '
p=$(echo "$out" | grep -c '^ok   ')
f=$(echo "$out" | grep -c '^FAIL ')
pass=$((pass + p))
fail=$((fail + f))
if [ "$rc" -ne 0 ] && [ "$f" -eq 0 ]; then
  bad "viewer_driver.py exited $rc: $(echo "$out" | tail -n 5)"
fi
[ "$p" -ge 17 ] || bad "viewer_driver.py ran $p checks, want at least 17"
finish
