#!/usr/bin/env bash
# Durable state and bounded memory (issue 13, parts 3 and 4), against real
# daemons on loopback:
#  - --max-scene-bytes evicts idle scenes least recently used: without a
#    state directory a request for an evicted scene is a 404 whose code is
#    RSW_ERR_EVICTED; with one it reloads by itself (PATCHed state included)
#    and renders bitwise what it rendered before;
#  - --max-result-bytes: with --state-dir films beyond the cap are served
#    from disk (NPY streamed from the file, JSON read back), bitwise equal to
#    synchronous renders ("bundle": 1: each context alone); without it a job whose films cannot fit is
#    refused up front with 507 RSW_ERR_STORAGE;
#  - SIGKILL mid-job (16 renders of one per path) with --state-dir,
#    restart: the films finished before
#    the kill are fetchable bitwise, the job resumes to completion with the
#    films of an uninterrupted run, a job whose scene vanished ends failed
#    with the reason; scenes and blobs survive;
#  - without --blob-dir (and no --state-dir) the temporary blob directory
#    is gone after a normal exit.
# Prints "test_state: N passed, N failed".
set -u
name=test_state
. "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd curl "to talk to the daemon"
need_cmd python3 "to read JSON and compare films"

# A mono scene; $1 the plate's reflectance, $2 the film side.
scene() {
  cat <<EOF
{"type": "scene", "variant": "mono",
 "meter": {"type": "hdistant", "sampler": {"type": "independent", "sample_count": 4},
   "film": {"type": "hdrfilm", "width": $2, "height": $2}},
 "sun": {"type": "directional", "direction": [0, 0, -1]},
 "plate": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": $1}}}
EOF
}
U=""
post_scene() { # $1 body file -> scene id on stdout
  curl -s -XPOST "$U/v1/scenes" -H 'Content-Type: application/json' --data-binary @"$1" |
    python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])'
}
code_of() { python3 -c 'import json,sys; print(json.load(open(sys.argv[1])).get("code",""))' "$1"; }
field() { python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); print(d.get(sys.argv[2],""))' "$1" "$2"; }
render_npy() { # $1 scene, $2 body, $3 out -> status
  curl -s -o "$3" -w '%{http_code}' -XPOST "$U/v1/scenes/$1:render" -H 'Content-Type: application/json' \
    -H 'Accept: application/x-npy' -d "$2"
}
wait_job() { # $1 job, $2 seconds -> final state on stdout
  local s=""
  for _ in $(seq $(($2 * 20))); do
    curl -s "$U/v1/jobs/$1" >"$tmp/job.json"
    s=$(field "$tmp/job.json" state)
    case "$s" in succeeded | failed | cancelled) break ;; esac
    sleep 0.05
  done
  echo "$s"
}
metric() { curl -s "$U/metrics" | awk -v m="$1" '$1 == m {print $2}'; }

scene 0.5 8 >"$tmp/a.json"
scene 0.25 8 >"$tmp/b.json"
scene 0.75 8 >"$tmp/c.json"

# ---- eviction without a state directory: 404 RSW_ERR_EVICTED ------------------------
start_daemon "$tmp/d1" --max-scene-bytes 1 --threads 2
U=127.0.0.1:$started_port
if [ -z "$started_port" ]; then
  bad "daemon with --max-scene-bytes did not start: $(cat "$tmp/d1/log")"
  finish
fi
A=$(post_scene "$tmp/a.json")
B=$(post_scene "$tmp/b.json") # the budget holds one: A (idle) goes
st=$(curl -s -o "$tmp/out" -w '%{http_code}' "$U/v1/scenes/$A")
[ "$st" = 404 ] && [ "$(code_of "$tmp/out")" = RSW_ERR_EVICTED ] && ok ||
  bad "GET an evicted scene: $st $(head -c 300 "$tmp/out")"
st=$(curl -s -o "$tmp/out" -w '%{http_code}' -XPOST "$U/v1/scenes/$A:render" -H 'Content-Type: application/json' -d '{}')
[ "$st" = 404 ] && [ "$(code_of "$tmp/out")" = RSW_ERR_EVICTED ] && ok ||
  bad "render an evicted scene: $st $(head -c 300 "$tmp/out")"
st=$(curl -s -o "$tmp/out" -w '%{http_code}' "$U/v1/scenes/$B")
[ "$st" = 200 ] && ok || bad "the scene just posted stays resident: $st"
st=$(curl -s -o "$tmp/out" -w '%{http_code}' "$U/v1/scenes/0000000000000000000000000000000000000000000000000000000000000000")
[ "$st" = 404 ] && [ "$(code_of "$tmp/out")" = RSW_ERR_NOT_FOUND ] && ok || bad "an unknown scene stays RSW_ERR_NOT_FOUND: $(head -c 300 "$tmp/out")"
[ "$(metric raysweep_scenes_evicted_total)" -ge 1 ] 2>/dev/null && ok || bad "raysweep_scenes_evicted_total: $(metric raysweep_scenes_evicted_total)"
[ "$(metric raysweep_scene_bytes_limit)" = 1 ] && ok || bad "raysweep_scene_bytes_limit: $(metric raysweep_scene_bytes_limit)"
curl -s "$U/v1" >"$tmp/info.json"
py "GET /v1 reports the limits" 'import json,sys; l=json.load(open(sys.argv[1]))["limits"]; assert l["max_scene_bytes"]==1 and l["max_result_bytes"]==0 and l["state_dir"] is False, l' "$tmp/info.json"
# Re-posting brings it back.
A2=$(post_scene "$tmp/a.json")
[ "$A2" = "$A" ] && [ "$(render_npy "$A" '{"spp":2}' "$tmp/r.npy")" = 200 ] && ok || bad "re-posting an evicted scene"
# ---- result cap without a state directory: 507 up front ------------------------------
kill "${pids[-1]}" && wait "${pids[-1]}" 2>/dev/null
start_daemon "$tmp/d2" --max-result-bytes 2000 --threads 2
U=127.0.0.1:$started_port
# 8x8 mono hdistant film: 64 * 4 = 256 bytes of radiance, 64 * 16 = 1024 of
# angles, reserved once for a sweep that does not move the sensor: four
# wavelengths take 2048 bytes, two 1536.
A=$(post_scene "$tmp/a.json")
st=$(curl -s -o "$tmp/out" -w '%{http_code}' -XPOST "$U/v1/scenes/$A/jobs" -H 'Content-Type: application/json' \
  -d '{"contexts":[{"id":"a","wavelength":500},{"id":"b","wavelength":550},{"id":"c","wavelength":600},{"id":"d","wavelength":650}]}')
[ "$st" = 507 ] && [ "$(code_of "$tmp/out")" = RSW_ERR_STORAGE ] && ok ||
  bad "a job whose films exceed --max-result-bytes: $st $(head -c 300 "$tmp/out")"
st=$(curl -s -o "$tmp/out" -w '%{http_code}' -XPOST "$U/v1/scenes/$A/jobs" -H 'Content-Type: application/json' \
  -d '{"contexts":[{"id":"a","wavelength":500},{"id":"b","wavelength":550}]}')
[ "$st" = 202 ] && ok || bad "a job that fits: $st $(head -c 300 "$tmp/out")"
j=$(field "$tmp/out" id)
[ "$(wait_job "$j" 20)" = succeeded ] && ok || bad "the job that fits"
st=$(curl -s -o "$tmp/out" -w '%{http_code}' -XPOST "$U/v1/scenes/$A/jobs" -H 'Content-Type: application/json' \
  -d '{"contexts":[{"id":"b","wavelength":550}]}')
[ "$st" = 507 ] && ok || bad "a second job while the first one's film is held: $st"
curl -s -o /dev/null -XDELETE "$U/v1/jobs/$j"
st=$(curl -s -o "$tmp/out" -w '%{http_code}' -XPOST "$U/v1/scenes/$A/jobs" -H 'Content-Type: application/json' \
  -d '{"contexts":[{"id":"b","wavelength":550}]}')
[ "$st" = 202 ] && ok || bad "after deleting the first job its storage is free again: $st"
kill "${pids[-1]}" && wait "${pids[-1]}" 2>/dev/null

# ---- with a state directory: eviction reloads; results beyond the cap from disk --------
sd=$tmp/state
# --threads 1: one job worker (there are as many as render threads), so that
# the second job below waits in the queue behind the first until the kill.
start_daemon "$tmp/d3" --state-dir "$sd" --max-scene-bytes 1 --max-result-bytes 2000 --threads 1
U=127.0.0.1:$started_port
A=$(post_scene "$tmp/a.json")
curl -s -o /dev/null -XPATCH "$U/v1/scenes/$A/params" -H 'Content-Type: application/json' -d '{"plate.bsdf.reflectance.value": 0.3}'
render_npy "$A" '{"spp":3,"seed":7,"wavelength":550}' "$tmp/before.npy" >/dev/null
ov='{"spp":3,"seed":7,"wavelength":550,"params":{"sun.irradiance.value":2}}' # renders on a view
render_npy "$A" "$ov" "$tmp/before_ov.npy" >/dev/null
B=$(post_scene "$tmp/b.json") # evicts A (its document and PATCH are on disk)
[ "$(metric raysweep_scenes_evicted_total)" -ge 1 ] 2>/dev/null && ok || bad "A was not evicted"
st=$(render_npy "$A" '{"spp":3,"seed":7,"wavelength":550}' "$tmp/after.npy")
[ "$st" = 200 ] && cmp -s "$tmp/before.npy" "$tmp/after.npy" && ok ||
  bad "an evicted scene reloads from the state directory with its PATCH, bitwise: $st"
st=$(render_npy "$A" "$ov" "$tmp/after_ov.npy")
[ "$st" = 200 ] && cmp -s "$tmp/before_ov.npy" "$tmp/after_ov.npy" && ok ||
  bad "a render view of the reloaded scene has its PATCH too (a render with overrides), bitwise: $st"
curl -s "$U/v1/scenes/$A/params?match=plate.bsdf.reflectance.value" >"$tmp/p.json"
py "the reloaded scene keeps its revision and PATCHed value" \
  'import json,sys; d=json.load(open(sys.argv[1])); assert d["revision"]==1 and d["params"][0]["value"]==0.3, d' "$tmp/p.json"
[ "$(metric raysweep_scenes_reloaded_total)" -ge 1 ] 2>/dev/null && ok || bad "raysweep_scenes_reloaded_total"
# Four 1280-byte films against a 2000-byte cap: one in memory, the rest on disk.
curl -s -o "$tmp/out" -XPOST "$U/v1/scenes/$B/jobs" -H 'Content-Type: application/json' \
  -d '{"contexts":[{"id":"w500","wavelength":500},{"id":"w550","wavelength":550},{"id":"w600","wavelength":600},{"id":"w650","wavelength":650}],"defaults":{"spp":3},"bundle":1}'
jb=$(field "$tmp/out" id)
[ "$(wait_job "$jb" 30)" = succeeded ] && ok || bad "the job over the result cap"
rb=$(metric raysweep_result_bytes)
[ "${rb:-99999}" -le 2000 ] && [ "$(metric raysweep_results_written_total)" = 4 ] && ok ||
  bad "films beyond the cap stay out of memory: result_bytes $rb, written $(metric raysweep_results_written_total)"
curl -s "$U/v1/jobs/$jb/results" >"$tmp/res.json"
same=0
for c in w500 w550 w600 w650; do
  seed=$(python3 -c 'import json,sys; print([r["seed"] for r in json.load(open(sys.argv[1]))["results"] if r["context"]==sys.argv[2]][0])' "$tmp/res.json" "$c")
  curl -s -H 'Accept: application/x-npy' "$U/v1/jobs/$jb/results/$c/meter" -o "$tmp/job_$c.npy"
  curl -s "$U/v1/jobs/$jb/results/$c/meter" -o "$tmp/job_$c.json"
  render_npy "$B" "{\"spp\":3,\"seed\":$seed,\"wavelength\":${c#w}}" "$tmp/sync_$c.npy" >/dev/null
  curl -s -XPOST "$U/v1/scenes/$B:render" -H 'Content-Type: application/json' -d "{\"spp\":3,\"seed\":$seed,\"wavelength\":${c#w}}" -o "$tmp/sync_$c.json"
  cmp -s "$tmp/job_$c.npy" "$tmp/sync_$c.npy" &&
    python3 -c 'import json,sys; a=json.load(open(sys.argv[1])); b=json.load(open(sys.argv[2])); assert a["data"]==b["data"] and a["meta"]["zenith_deg"]==b["meta"]["zenith_deg"]' \
      "$tmp/job_$c.json" "$tmp/sync_$c.json" && same=$((same + 1))
done
[ "$same" = 4 ] && ok || bad "results served from disk (NPY and JSON) equal synchronous renders: $same of 4"
# A blob survives the restart too.
printf 'state test blob %s' "$$" >"$tmp/blob"
bh=$(sha256sum "$tmp/blob" | cut -c1-64)
curl -s -o /dev/null -XPUT --data-binary @"$tmp/blob" -H 'Content-Type: application/octet-stream' "$U/v1/blobs/$bh"

# ---- SIGKILL mid-job, restart ---------------------------------------------------------
scene 0.5 16 >"$tmp/k.json"
K=$(post_scene "$tmp/k.json")
# spp for about 0.15 s a render here (sanitizer builds are slower)
render_npy "$K" '{"spp":16,"wavelength":550}' "$tmp/cal.npy" >/dev/null # warm-up
t0=$(date +%s%N)
render_npy "$K" '{"spp":2048,"wavelength":550}' "$tmp/cal.npy" >/dev/null
t1=$(date +%s%N)
spp=$(python3 -c 'import sys; dt=max(1e-4,(int(sys.argv[2])-int(sys.argv[1]))/1e9); print(max(64,min(1000000,int(2048*0.3/dt))))' "$t0" "$t1")
body=$(python3 -c 'import json,sys; print(json.dumps({"contexts":[{"id":"c%d"%i,"wavelength":400+20*i} for i in range(16)],"defaults":{"spp":int(sys.argv[1])},"bundle":1}))' "$spp")
curl -s -o "$tmp/out" -XPOST "$U/v1/scenes/$K/jobs" -H 'Content-Type: application/json' -d "$body"
jk=$(field "$tmp/out" id)
curl -s -o "$tmp/out" -XPOST "$U/v1/scenes/$A/jobs" -H 'Content-Type: application/json' -d '{"contexts":[{"id":"q","wavelength":500}]}'
jq2=$(field "$tmp/out" id) # queued behind jk: its scene vanishes below
done_before=0
for _ in $(seq 400); do
  curl -s "$U/v1/jobs/$jk" >"$tmp/job.json"
  done_before=$(field "$tmp/job.json" renders_done)
  [ "${done_before:-0}" -ge 2 ] && break
  sleep 0.02
done
curl -s "$U/v1/jobs/$jq2" >"$tmp/jq2.json"
echo "spp $spp killed at $done_before" >&2; kill -9 "${pids[-1]}"
wait "${pids[-1]}" 2>/dev/null
[ "$done_before" -ge 2 ] && [ "$done_before" -lt 16 ] && ok || bad "the kill came mid-job (renders done: $done_before of 16)"
[ "$(field "$tmp/jq2.json" state)" = queued ] && ok || bad "the second job was still queued at the kill: $(cat "$tmp/jq2.json")"
# the films finished before the kill, as the state directory holds them
mkdir -p "$tmp/killed"
# (a film file begins with the .npy bytes; its 64-byte trailer's first uint64 is their length)
for f in "$sd"/results/"$jk"/*.film; do
  [ -e "$f" ] || continue
  python3 -c 'import struct,sys; b=open(sys.argv[1],"rb").read(); n=struct.unpack("<Q",b[-64:-56])[0]; assert b[-8:]==b"RSWFILM2"; open(sys.argv[2],"wb").write(b[:n])' \
    "$f" "$tmp/killed/$(basename "$f" .film).npy"
done
n_killed=$(ls "$tmp/killed" | wc -l)
rm -f "$sd"/scenes/"$A".* # the second job cannot resume: its scene is gone
rm -f "$tmp/d3/port"
t0=$(date +%s%N)
start_daemon "$tmp/d3" --state-dir "$sd" --max-scene-bytes 1 --max-result-bytes 2000 --threads 2
U=127.0.0.1:$started_port
[ -n "$started_port" ] && ok || bad "restart with the state directory: $(cat "$tmp/d3/log")"
[ "$(wait_job "$jk" 60)" = succeeded ] && ok || bad "the interrupted job resumed to completion: $(cat "$tmp/job.json")"
[ "$(metric raysweep_jobs_resumed_total)" -ge 1 ] 2>/dev/null && ok || bad "raysweep_jobs_resumed_total"
[ "$(wait_job "$jq2" 10)" = failed ] && grep -q "not resumed" "$tmp/job.json" && ok ||
  bad "a job that cannot resume ends failed with the reason: $(cat "$tmp/job.json")"
kept=0
for f in "$tmp"/killed/*.npy; do
  k=$(basename "$f" .npy)
  c=c$k
  curl -s -H 'Accept: application/x-npy' "$U/v1/jobs/$jk/results/$c/meter" -o "$tmp/after_$c.npy"
  cmp -s "$f" "$tmp/after_$c.npy" && kept=$((kept + 1))
done
[ "$n_killed" -ge 2 ] && [ "$kept" = "$n_killed" ] && ok || bad "films finished before the kill are fetchable bitwise: $kept of $n_killed"
for c in c0 c15; do curl -s -H 'Accept: application/x-npy' "$U/v1/jobs/$jk/results/$c/meter" -o "$tmp/resumed_$c.npy"; done
st=$(curl -s -o /dev/null -w '%{http_code}' "$U/v1/scenes/$B")
[ "$st" = 200 ] && ok || bad "a scene survives the restart (loaded by id): $st"
st=$(curl -s -o /dev/null -w '%{http_code}' -I "$U/v1/blobs/$bh")
[ "$st" = 200 ] && ok || bad "a blob survives the restart: $st"
curl -s -H 'Accept: application/x-npy' "$U/v1/jobs/$jb/results/w600/meter" -o "$tmp/job_w600_after.npy"
cmp -s "$tmp/job_w600.npy" "$tmp/job_w600_after.npy" && ok || bad "an older job's result after the restart"
# SIGTERM (an upgrade) with a job running: it resumes at the next start
# instead of ending cancelled.
curl -s -o "$tmp/out" -XPOST "$U/v1/scenes/$K/jobs" -H 'Content-Type: application/json' -d "$body"
jt=$(field "$tmp/out" id)
for _ in $(seq 400); do
  curl -s "$U/v1/jobs/$jt" >"$tmp/job.json"
  [ "$(field "$tmp/job.json" renders_done)" -ge 1 ] 2>/dev/null && break
  sleep 0.02
done
kill -TERM "${pids[-1]}" && wait "${pids[-1]}" 2>/dev/null
rm -f "$tmp/d3/port"
start_daemon "$tmp/d3" --state-dir "$sd" --threads 2
U=127.0.0.1:$started_port
[ "$(wait_job "$jt" 60)" = succeeded ] && ok || bad "a job running at SIGTERM resumes after the restart: $(cat "$tmp/job.json")"
kill "${pids[-1]}" && wait "${pids[-1]}" 2>/dev/null
# The uninterrupted reference: the same job on an in-memory daemon.
start_daemon "$tmp/d4" --threads 2
U=127.0.0.1:$started_port
K2=$(post_scene "$tmp/k.json")
curl -s -o "$tmp/out" -XPOST "$U/v1/scenes/$K2/jobs" -H 'Content-Type: application/json' -d "$body"
jr=$(field "$tmp/out" id)
[ "$(wait_job "$jr" 60)" = succeeded ] && ok || bad "the reference job"
same=0
for c in c0 c15; do
  curl -s -H 'Accept: application/x-npy' "$U/v1/jobs/$jr/results/$c/meter" -o "$tmp/ref_$c.npy"
  cmp -s "$tmp/ref_$c.npy" "$tmp/resumed_$c.npy" && same=$((same + 1))
done
[ "$same" = 2 ] && ok || bad "the resumed job's films equal an uninterrupted run's: $same of 2"

# ---- no blob directory left behind without --blob-dir -------------------------------
printf 'leftover check %s %s' "$$" "$RANDOM" >"$tmp/blob2"
bh2=$(sha256sum "$tmp/blob2" | cut -c1-64)
curl -s -o /dev/null -XPUT --data-binary @"$tmp/blob2" -H 'Content-Type: application/octet-stream' "$U/v1/blobs/$bh2"
during=$(ls -d /tmp/raysweepd-blobs-*/"$bh2" 2>/dev/null | wc -l)
kill -TERM "${pids[-1]}" && wait "${pids[-1]}" 2>/dev/null
after=$(ls -d /tmp/raysweepd-blobs-*/"$bh2" 2>/dev/null | wc -l)
[ "$during" = 1 ] && [ "$after" = 0 ] && ok || bad "temporary blob directory after exit: $during while running, $after after"

# No daemon reported a sanitizer error (SAN=1 builds) or a crash.
if grep -lE "AddressSanitizer|LeakSanitizer|runtime error:" "$tmp"/d*/log >/dev/null 2>&1; then
  bad "sanitizer report in a daemon log: $(grep -hE -A5 "AddressSanitizer|LeakSanitizer|runtime error:" "$tmp"/d*/log | head -c 1500)"
else
  ok
fi

finish
