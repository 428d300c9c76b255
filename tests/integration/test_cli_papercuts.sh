#!/usr/bin/env bash
# Papercuts of the `raysweep` CLI (issue 10), against the real daemon on an
# ephemeral loopback port:
#  - sweep -o into a non-empty directory is refused (2) unless --force, which
#    removes only what an earlier sweep wrote;
#  - merge of an incomplete set of shards fails (6) naming the missing
#    contexts and shards (--partial merges anyway);
#  - Ctrl-C (SIGINT) on sweep cancels its job on the daemon, on render stops
#    the daemon's render, on job watch leaves the job running and says how to
#    cancel it; each says so on stderr and exits 130;
#  - job watch joined mid-job counts the rate from the job's start; job show
#    shows the elapsed time while running;
#  - the 409 for removing a scene in use names the CLI's --force.
# Every check waits for an order of events (a state, a counter), never for a
# wall-clock latency: the waits are generous limits only.
# Ends with "test_cli_papercuts: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_cli_papercuts
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweep raysweepd
need_cmd python3 "for the checks"
need_cmd curl "to read the daemon's /metrics"

start_daemon "$tmp/d1"
port=$started_port
if [ -z "$port" ]; then
  bad "the daemon did not start: $(cat "$tmp/d1/log")"
  finish
fi
export RAYSWEEP_URL="http://127.0.0.1:$port"
unset RAYSWEEP_TOKEN
rs() { "$bin/raysweep" "$@"; }
# bg_raysweep OUT ERR ARGS...: raysweep in the background as $bg (its own
# pid, for kill -INT). A non-interactive shell starts background commands
# with SIGINT ignored, which raysweep honours (as nohup expects): restore
# the default first.
bg_raysweep() {
  local o=$1 e=$2
  shift 2
  python3 -c 'import os, signal, sys
signal.signal(signal.SIGINT, signal.SIG_DFL)
os.execv(sys.argv[1], sys.argv[1:])' "$bin/raysweep" "$@" >"$o" 2>"$e" &
  bg=$!
}
cd "$tmp" || exit 1

# job_field JOB FIELD: one field of GET /v1/jobs/JOB ("" when unreadable).
job_field() {
  rs job show "$1" --json 2>/dev/null | python3 -c 'import json,sys; print(json.load(sys.stdin).get(sys.argv[1], ""))' "$2" 2>/dev/null
}
# wait_for SECONDS CMD...: retry CMD every 0.1 s until it succeeds (a limit, not a measurement).
wait_for() {
  local limit=$1
  shift
  local n=$((limit * 10))
  for _ in $(seq "$n"); do
    "$@" && return 0
    sleep 0.1
  done
  return 1
}
# metric NAME: a sample of GET /metrics ("" when absent); metric_above NAME N.
metric() {
  curl -s "$RAYSWEEP_URL/metrics" 2>/dev/null | awk -v n="$1" '$1 == n {print $2}'
}
metric_above() { [ "$(metric "$1")" -gt "$2" ] 2>/dev/null; }
state_is() { [ "$(job_field "$1" state)" = "$2" ]; }
done_at_least() { [ "$(job_field "$1" renders_done)" -ge "$2" ] 2>/dev/null; }
stderr_names_job() { grep -q '^raysweep sweep: job ' "$1"; }
job_of() { sed -n 's/^raysweep sweep: job \([^: ]*\):.*/\1/p' "$1" | head -n 1; }

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
expect 0 "push plate" rs -q scene push plate.json
plate=$(cat out)

# ---- sweep -o DIR: refuse a non-empty directory unless --force ----
mkdir notes && echo keep >notes/notes.txt
expect 2 "sweep into a non-empty directory" rs sweep "$plate" --grid wavelength=400:500:100 -o notes
contains "non-empty: says so" err "not empty"
contains "non-empty: names --force" err "--force"
expect 2 "sweep --force into a directory that holds no sweep" rs sweep "$plate" --grid wavelength=400:500:100 -o notes --force
contains "--force without a sweep: nothing deleted" err "nothing was deleted"
[ -f notes/notes.txt ] && ok || bad "--force deleted a file no sweep wrote"
[ -z "$(rs job ls)" ] && ok || bad "a refused sweep submitted a job: $(rs job ls)"

expect 0 "sweep four contexts" rs -q sweep "$plate" --grid wavelength=400:700:100 --format json -o sw
[ -f sw/sweep.json ] && ok || bad "sweep wrote no sweep.json"
expect 2 "sweep again into the same directory" rs sweep "$plate" --grid wavelength=400:500:100 --format json -o sw
[ -f sw/c00003/nadir.json ] && ok || bad "a refused sweep touched the earlier output"
echo mine >sw/README.txt
expect 0 "sweep --force replaces the earlier sweep" rs sweep "$plate" --grid wavelength=400:500:100 --format json -o sw --force
contains "--force says what it removed" err "removed the earlier sweep"
contains "--force says what it kept" err "README.txt"
py "after --force: only the new sweep's films, and the user's file" '
import json, os
lines = [json.loads(l) for l in open("sw/index.jsonl")]
assert [l["context"] for l in lines] == ["c00000", "c00001"], lines
assert not os.path.exists("sw/c00002") and not os.path.exists("sw/c00003"), os.listdir("sw")
assert open("sw/README.txt").read() == "mine\n"
m = json.load(open("sw/sweep.json"))
assert m["finished"] is True and m["contexts_total"] == 2 and m["shard"] == [0, 1] and m["incomplete"] == [], m
'

# ---- merge: an incomplete set of shards fails and lists what is missing ----
grid=(--grid wavelength=400:750:50 --format json --bundle 1) # (one per path: shards are k mod 3)
expect 0 "shard 0/3" rs -q sweep "$plate" "${grid[@]}" --shard 0/3 -o s0
expect 0 "shard 1/3" rs -q sweep "$plate" "${grid[@]}" --shard 1/3 -o s1
expect 6 "merge without shard 2/3" rs merge s0 s1 -o m
contains "merge lists the missing contexts" err "c00002, c00005"
contains "merge counts them" err "2 of 8 contexts"
contains "merge names the missing shard" err "2/3"
[ ! -e m ] && ok || bad "an incomplete merge wrote $(ls m)"
expect 0 "merge --partial" rs merge s0 s1 -o mp --partial
contains "merge --partial still warns" err "c00002, c00005"
py "merge --partial: the films there, the missing ones recorded" '
import json
lines = [json.loads(l) for l in open("mp/index.jsonl")]
assert [l["context"] for l in lines] == ["c00000", "c00001", "c00003", "c00004", "c00006", "c00007"], lines
m = json.load(open("mp/sweep.json"))
assert m["incomplete"] == ["c00002", "c00005"] and m["shard"] == [0, 1], m
'
expect 6 "a partial merge stays incomplete" rs merge mp -o mp2
expect 0 "shard 2/3" rs -q sweep "$plate" "${grid[@]}" --shard 2/3 -o s2
expect 0 "merge of every shard" rs merge s2 s0 s1 -o mall
[ "$(wc -l <mall/index.jsonl)" -eq 8 ] && ok || bad "complete merge: $(wc -l <mall/index.jsonl) films"
expect 0 "a partial merge plus the missing shard" rs merge mp s2 -o mall2
cmp -s mall/index.jsonl mall2/index.jsonl && ok || bad "partial + missing shard differs from the full merge"
# --contexts with ids of its own: the missing ones are named by id.
printf '%s\n' '{"id":"red","wavelength":650}' '{"id":"green","wavelength":550}' '{"id":"blue","wavelength":450}' >rgb.jsonl
expect 0 "contexts shard 0/2" rs -q sweep "$plate" --contexts rgb.jsonl --bundle 1 --shard 0/2 -o r0
expect 6 "merge without contexts shard 1/2" rs merge r0 -o rm
contains "merge names a given id" err "green"

# ---- Ctrl-C on sweep: the job is cancelled on the daemon ----
bg_raysweep long.out long.err sweep "$plate" --grid wavelength=400:700:1 --spp 4000000 -o long
sp=$bg
wait_for 60 stderr_names_job long.err || bad "the long sweep did not start: $(cat long.err)"
long=$(job_of long.err)
kill -INT "$sp"
wait "$sp"
rc=$?
[ "$rc" -eq 130 ] && ok || bad "sweep after Ctrl-C: exit $rc, wanted 130; stderr: $(cat long.err)"
contains "sweep Ctrl-C says so" long.err "interrupted; cancelled job $long on the daemon"
wait_for 60 state_is "$long" cancelled && ok || bad "after Ctrl-C the job is $(job_field "$long" state), not cancelled"
py "the sweep wrote no films and an unfinished sweep.json" '
import json, os
m = json.load(open("long/sweep.json"))
assert m["finished"] is False and m["job"] == __import__("sys").argv[1], m
assert not os.path.exists("long/index.jsonl")
' "$long"
expect 6 "merge of an interrupted sweep" rs merge long -o lm
contains "merge: the interrupted sweep did not finish" err "did not finish"
expect 0 "--force cleans an interrupted sweep" rs -q sweep "$plate" --grid wavelength=400:400:1 -o long --force

# ---- Ctrl-C on job watch: the job goes on, the message says how to cancel ----
rs sweep "$plate" --grid wavelength=400:700:1 --spp 4000000 --timeout 1 -o long2 >/dev/null 2>long2.err
long2=$(job_of long2.err)
[ -n "$long2" ] && ok || bad "the second long sweep did not name its job: $(cat long2.err)"
streams=$(metric 'raysweep_http_requests_total{route="/v1/jobs/{id}/events",status="200"}')
bg_raysweep watch.out watch.err job watch "$long2"
wp=$bg
# The watch is following the job's events once the daemon opened its stream.
wait_for 60 metric_above 'raysweep_http_requests_total{route="/v1/jobs/{id}/events",status="200"}' "${streams:-0}" ||
  bad "job watch never opened the event stream"
kill -INT "$wp"
wait "$wp"
rc=$?
[ "$rc" -eq 130 ] && ok || bad "job watch after Ctrl-C: exit $rc, wanted 130; stderr: $(cat watch.err)"
contains "watch Ctrl-C: the job keeps running" watch.err "keeps running"
contains "watch Ctrl-C: how to cancel" watch.err "raysweep job cancel $long2"
state_is "$long2" running && ok || bad "job watch's Ctrl-C changed the job: $(job_field "$long2" state)"

# ---- job show while running: elapsed time ----
wait_for 30 python3 -c 'import sys; sys.exit(0 if float(sys.argv[1] or 0) > 0 else 1)' "$(job_field "$long2" seconds)" ||
  wait_for 30 done_at_least "$long2" 0
expect 0 "job show running" rs job show "$long2"
py "job show: elapsed so far while running" '
import re, sys
t = open(sys.argv[1]).read()
m = re.search(r"^elapsed: +(\S+) so far \(([0-9.]+) s\)", t, re.M)
assert m and float(m.group(2)) > 0, t
' out
py "GET job: seconds while running" '
import json, sys
assert float(sys.argv[1]) > 0, sys.argv[1]
' "$(job_field "$long2" seconds)"

# ---- the 409 for a scene in use names the CLI flag ----
expect 1 "scene rm while a job runs" rs scene rm "$plate"
contains "409 names the job" err "$long2"
contains "409 names the CLI flag" err "raysweep scene rm $plate --force"
expect 0 "job cancel" rs job cancel "$long2"
wait_for 60 state_is "$long2" cancelled || bad "job $long2 was not cancelled"

# ---- job watch joined mid-job: the rate counts from the job's start ----
# 30 renders of a few hundred ms each; join after at least 3 are done.
rs sweep "$plate" --grid wavelength=400:690:10 --spp 200000 -o steady >/dev/null 2>steady.err &
sp=$!
wait_for 60 stderr_names_job steady.err
steady=$(job_of steady.err)
wait_for 120 done_at_least "$steady" 3 || bad "the steady job made no progress"
done0=$(job_field "$steady" renders_done)
secs0=$(job_field "$steady" seconds)
expect 0 "job watch joined mid-job" rs job watch "$steady" --timeout 300
py "job watch: the first line counts from the job's start" '
import re, sys
done0, secs0 = int(sys.argv[2]), float(sys.argv[3])
lines = [l for l in open(sys.argv[1]) if "renders done" in l]
assert lines, open(sys.argv[1]).read()
m = re.search(r"(\d+)/(\d+) renders done +([0-9.]+)/s", lines[0])
done, total, rate = int(m.group(1)), int(m.group(2)), float(m.group(3))
# Joined with done0 renders behind it: not counted as done in the first instant.
assert done >= done0, (lines[0], done0)
# No mean rate since the start can exceed every render over the time already run.
assert rate <= total / secs0, (lines[0], total, secs0)
' err "$done0" "$secs0"
wait "$sp"

# ---- Ctrl-C on render: the dropped request stops the daemon's render ----
renders_with() { metric 'raysweep_http_requests_total{route="/v1/scenes/{id}:render",status="'"$1"'"}'; }
has_409() { [ "$(renders_with 409)" = 1 ]; }
# 32x32 pixels of ~0.1-1 s each (the kernel checks for a stop between
# pixels): minutes of work in all.
expect 0 "push hdistant" rs -q scene push "$root/proto/examples/hdistant_lambertian.json"
hd=$(cat out)
bg_raysweep render.out render.err render "$hd" --spp 200000 -o never.exr
rp=$bg
wait_for 60 metric_above raysweep_sync_renders 0 || bad "the render never started on the daemon"
kill -INT "$rp"
wait "$rp"
rc=$?
[ "$rc" -eq 130 ] && ok || bad "render after Ctrl-C: exit $rc, wanted 130; stderr: $(cat render.err)"
contains "render Ctrl-C says so" render.err "interrupted"
wait_for 60 has_409 && ok || bad "the daemon did not stop the render (409 count '$(renders_with 409)')"
[ -z "$(renders_with 200)" ] && ok || bad "the interrupted render completed"
[ ! -e never.exr ] && ok || bad "an interrupted render wrote its file"

finish
