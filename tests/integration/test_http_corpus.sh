#!/usr/bin/env bash
# The malformed-request corpus (tests/corpus/http, >= 250 raw requests over
# every route) against a real daemon (with a bearer token, a blob directory
# and a data root): every case must get its expected status, 4xx (or a
# documented 5xx) as a valid problem+json body naming the field
# (tests/corpus/http/replay.py checks each). Before and after the whole
# corpus the same small render is taken: the daemon must still be up and
# give the same film bit for bit.
# Ends with "test_http_corpus: N passed, N failed" (one per case, plus the
# set-up and the render checks).
set -u
name=test_http_corpus
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd python3 "for the replay"
need_cmd curl "for the set-up"
corpus=$root/tests/corpus/http

token=corpus-token-0123456789
printf '%s\n' "$token" >"$tmp/token"
mkdir -p "$tmp/d/blobs"
start_daemon "$tmp/d" --token-file "$tmp/token" --blob-dir "$tmp/d/blobs"
port=$started_port
if [ -z "$port" ]; then
  bad "the daemon did not start: $(cat "$tmp/d/log")"
  finish
fi
base=http://127.0.0.1:$port
c() { curl -sS -H "Authorization: Bearer $token" "$@"; }

# The scenes ({SCENE}; {SCENE2} for DELETE cases), two blobs ({BLOB}, and {BADBLOB} whose file is then
# replaced by a directory: unreadable even to root) and a finished job
# ({JOB}, context c1).
scene=$(c -H 'Content-Type: application/json' --data-binary @"$corpus/scene.json" "$base/v1/scenes" |
  python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
[ -n "$scene" ] && ok || bad "POST the corpus scene failed"
scene2=$(c -H 'Content-Type: application/xml' --data-binary @"$root/proto/examples/hdistant_seed.xml" \
  "$base/v1/scenes" | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
put_blob() {
  printf '%s' "$1" >"$tmp/blob"
  local h
  h=$(sha256sum "$tmp/blob" | cut -d' ' -f1)
  c -o /dev/null -w '%{http_code}' -X PUT -H 'Content-Type: application/octet-stream' --data-binary @"$tmp/blob" \
    "$base/v1/blobs/$h" >"$tmp/code"
  echo "$h"
}
blob=$(put_blob 'v 0 0 0')
badblob=$(put_blob 'v 1 1 1')
bf=$(find "$tmp/d/blobs" -name "*$badblob*" | head -n 1)
if [ -n "$bf" ]; then
  rm -f "$bf" && mkdir "$bf" && ok
else
  bad "blob $badblob not found under the blob directory"
fi
job=$(c -H 'Content-Type: application/json' -d '{"contexts":[{"id":"c1"}],"defaults":{"spp":1}}' \
  "$base/v1/scenes/$scene/jobs" | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
for _ in $(seq 100); do
  c "$base/v1/jobs/$job" | grep -q '"state":"succeeded"' && break
  sleep 0.1
done
if c "$base/v1/jobs/$job" | grep -q '"state":"succeeded"'; then ok; else bad "job $job did not succeed"; fi

render() {
  c -H 'Content-Type: application/json' -H 'Accept: application/json' -d '{"spp":4,"seed":3}' \
    "$base/v1/scenes/$scene:render" -o "$1"
}
render "$tmp/before.json"
py "render before the corpus" 'import json,sys; d=json.load(open(sys.argv[1])); assert len(d["data"]) == 16' \
  "$tmp/before.json"

python3 "$corpus/replay.py" --port "$port" --token "$token" --var "SCENE=$scene" --var "SCENE2=$scene2" --var "JOB=$job" \
  --var "BLOB=$blob" --var "BADBLOB=$badblob" --var "BLOBDIR=$tmp/d/blobs" --var "TOKEN=$token" >"$tmp/replay"
cat "$tmp/replay" | grep '^FAIL' | sed "s/^FAIL /FAIL $name: /"
line=$(tail -n 1 "$tmp/replay")
if [[ $line =~ ^http\ corpus:\ ([0-9]+)\ passed,\ ([0-9]+)\ failed$ ]]; then
  pass=$((pass + BASH_REMATCH[1]))
  fail=$((fail + BASH_REMATCH[2]))
else
  bad "replay.py ended without its summary: $(tail -n 3 "$tmp/replay")"
fi

# Still up, still the same film.
render "$tmp/after.json"
py "render after the corpus equals the one before" '
import json, sys
a = json.load(open(sys.argv[1])); b = json.load(open(sys.argv[2]))
assert a["data"] == b["data"], "films differ"
assert a["meta"]["revision"] == b["meta"]["revision"], "revision changed"
' "$tmp/before.json" "$tmp/after.json"
# No sanitizer report from the daemon (SAN=1 builds).
if grep -qE 'ERROR: (AddressSanitizer|LeakSanitizer)|runtime error:' "$tmp/d/log"; then
  bad "sanitizer report in the daemon's log: $(grep -m 3 -E 'ERROR: |runtime error:' "$tmp/d/log")"
else
  ok
fi
finish
