#!/usr/bin/env bash
# make test-cluster: the Slurm recipe of docker/slurm/ on a real
# single-node Slurm (Debian's slurm-wlm and munge, `make deps-cluster`) that this
# test starts in a temporary directory: munged on a private socket with a
# key generated here, slurmctld and slurmd on localhost with a minimal
# slurm.conf (no cgroups, proctrack/linuxproc, task/none, 2 CPUs), on free
# ports. docker/slurm/submit.sh runs a 31-context sweep as a 4-task array
# (each task its own raysweepd on loopback) plus a merge job that depends
# on it (afterok); the merged films and index must equal the same sweep run
# unsharded on one daemon, byte for byte. Also: a failing task cancels the
# merge, a task resubmitted alone re-renders its shard identically, and the
# shard script refuses a task outside --shards.
#
# When a Slurm daemon cannot start (or the node never becomes idle) this
# FAILS with the daemons' logs: it never skips. Every daemon it started is
# stopped on exit, after cancelling its jobs.
name=test_slurm
. "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd raysweep
for c in slurmctld slurmd sbatch scontrol sinfo squeue scancel munged mungekey munge unmunge; do
  need_cmd "$c" "for the single-node Slurm (packages slurm-wlm and munge: make deps-cluster)"
done

shard_sh=$root/docker/slurm/raysweep-shard.sbatch
submit_sh=$root/docker/slurm/submit.sh
scene=$root/proto/examples/hdistant_lambertian.json
# 31 contexts, bundled by default (groups of 16 and 15 wavelengths: tasks 0
# and 1; tasks 2 and 3 hold none). RSW_SLURM_SPP=N: a longer sweep, to time.
spp=${RSW_SLURM_SPP:-128}
sweep_args=(--grid wavelength=400:700:10 --spp "$spp")
now() { date +%s.%N; }
secs() { python3 -c 'import sys; print("%.2f" % (float(sys.argv[2]) - float(sys.argv[1])))' "$1" "$2"; }

# ---- the shard script's own checks (no Slurm needed) ----
SLURM_ARRAY_TASK_ID=4 "$shard_sh" --shards 4 --out "$tmp/x" "$scene" >"$tmp/out" 2>&1
rc=$?
if [ $rc -eq 2 ] && grep -q "array task 4 is not a shard of 4" "$tmp/out"; then ok; else bad "task 4 of --shards 4: exit $rc, $(cat "$tmp/out")"; fi
SLURM_ARRAY_TASK_ID=2 SLURM_ARRAY_TASK_MIN=1 SLURM_ARRAY_TASK_MAX=4 SLURM_ARRAY_TASK_COUNT=4 \
  "$shard_sh" --out "$tmp/x" "$scene" >"$tmp/out" 2>&1
rc=$?
if [ $rc -eq 2 ] && grep -q "pass --shards N" "$tmp/out"; then ok; else bad "array 1-4 without --shards: exit $rc, $(cat "$tmp/out")"; fi
SLURM_ARRAY_TASK_ID=0 "$shard_sh" --shards 4 --out "$tmp/x" "$scene" --shard 1/2 >"$tmp/out" 2>&1
rc=$?
if [ $rc -eq 2 ] && grep -q "sets --shard, -o and --force itself" "$tmp/out"; then ok; else bad "--shard passed through: exit $rc, $(cat "$tmp/out")"; fi
[ ! -e "$tmp/x" ] && ok || bad "a refused task created its output directory"

# ---- a single-node Slurm in $tmp/slurm ----
S=$tmp/slurm
mkdir -p "$S/munge" "$S/state" "$S/spool" "$S/log" "$tmp/tasktmp"
chmod 700 "$S/munge"
slurm_pids=()
slurm_log_tail() {
  local f
  for f in "$S"/log/*; do
    [ -s "$f" ] && { echo "--- $f"; tail -n 15 "$f"; }
  done
}
# die_slurm WHAT: the reason, the daemons' logs, and finish (a failure).
die_slurm() {
  bad "$1"
  slurm_log_tail
  finish
}
slurm_cleanup() {
  if [ ${#slurm_pids[@]} -gt 1 ]; then # slurmctld is up: cancel what is left
    local left
    left=$(squeue -h -o %A 2>/dev/null | sort -u)
    if [ -n "$left" ]; then
      # shellcheck disable=SC2086
      scancel $left 2>/dev/null
      for _ in $(seq 100); do
        [ -z "$(squeue -h -o %A 2>/dev/null)" ] && break
        sleep 0.1
      done
    fi
  fi
  local i
  for ((i = ${#slurm_pids[@]} - 1; i >= 0; i--)); do # slurmd, slurmctld, munged
    kill "${slurm_pids[i]}" 2>/dev/null && wait "${slurm_pids[i]}" 2>/dev/null
  done
  shtest_cleanup
}
trap slurm_cleanup EXIT

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
user=$(id -un)

mungekey --create --keyfile "$S/munge/munge.key" >"$S/log/mungekey.out" 2>&1 ||
  die_slurm "mungekey --create failed"
munged -F --force --socket="$S/munge/socket" --key-file="$S/munge/munge.key" \
  --log-file="$S/log/munged.log" --pid-file="$S/munge/munged.pid" --seed-file="$S/munge/munged.seed" \
  >"$S/log/munged.out" 2>&1 &
slurm_pids+=($!)
for _ in $(seq 100); do
  [ -S "$S/munge/socket" ] && break
  sleep 0.1
done
munge --socket="$S/munge/socket" -n 2>"$S/log/munge-check.err" | unmunge --socket="$S/munge/socket" >/dev/null 2>>"$S/log/munge-check.err" ||
  die_slurm "munged did not start or cannot encode/decode a credential on $S/munge/socket"
ok

ctld_port=$(free_port)
d_port=$(free_port)
[ "$ctld_port" != "$d_port" ] || d_port=$(free_port)
cat >"$S/slurm.conf" <<EOF
# Written by tests/cluster/test_slurm.sh: one node, localhost, 2 CPUs.
ClusterName=rswtest
SlurmctldHost=$(hostname -s)(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$d_port
SlurmUser=$user
SlurmdUser=$user
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$S/munge/socket
StateSaveLocation=$S/state
SlurmdSpoolDir=$S/spool
SlurmctldPidFile=$S/slurmctld.pid
SlurmdPidFile=$S/slurmd.pid
SlurmctldLogFile=$S/log/slurmctld.log
SlurmdLogFile=$S/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/builtin
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
MailProg=/bin/true
ReturnToService=2
MinJobAge=600
NodeName=localhost NodeAddr=127.0.0.1 CPUs=2 State=UNKNOWN
PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP
EOF
# A cluster (or a job) of the caller's must not leak in.
# shellcheck disable=SC2046
unset $(compgen -e | grep -E '^(SLURM|SBATCH|SALLOC|SRUN|SQUEUE|SINFO|SCONTROL)_') RAYSWEEP_URL RAYSWEEP_TOKEN
export SLURM_CONF=$S/slurm.conf

slurmctld -D -i -f "$S/slurm.conf" >"$S/log/slurmctld.out" 2>&1 &
slurm_pids+=($!)
slurmd -D -N localhost -f "$S/slurm.conf" >"$S/log/slurmd.out" 2>&1 &
slurm_pids+=($!)
state=
for _ in $(seq 300); do # 30 s
  state=$(sinfo -h -n localhost -o %t 2>/dev/null)
  [ "$state" = idle ] && break
  kill -0 "${slurm_pids[1]}" 2>/dev/null || die_slurm "slurmctld exited at start"
  kill -0 "${slurm_pids[2]}" 2>/dev/null || die_slurm "slurmd exited at start"
  sleep 0.1
done
[ "$state" = idle ] || die_slurm "the Slurm node 'localhost' is not idle after 30 s (sinfo: '${state:-no answer}')"
ok

# wait_jobs SECONDS JOBID...: until no record of these jobs is pending or
# running; prints nothing. False on timeout.
wait_jobs() {
  local limit=$1
  shift
  local end=$(($(date +%s) + limit)) j st busy
  while [ "$(date +%s)" -lt "$end" ]; do
    busy=false
    for j in "$@"; do
      st=$(scontrol -o show job "$j" 2>/dev/null | grep -o 'JobState=[A-Z_]*')
      grep -qE 'PENDING|RUNNING|CONFIGURING|COMPLETING|REQUEUED|RESIZING|SUSPENDED' <<<"$st" && busy=true
    done
    $busy || return 0
    sleep 0.2
  done
  return 1
}
# job_states JOBID: the JobState of each record, sorted, one per line.
job_states() { scontrol -o show job "$1" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | sort | uniq -c | tr -s ' ' | sed 's/^ //'; }

# ---- the unsharded reference: one daemon (2 threads, then 1) ----
start_daemon "$tmp/ref" --threads 2
[ -n "$started_port" ] || die_slurm "raysweepd did not start: $(cat "$tmp/ref/log")"
export RAYSWEEP_URL=http://127.0.0.1:$started_port
id=$("$bin/raysweep" --quiet scene push "$scene") || die_slurm "scene push to the reference daemon failed"
t0=$(now)
expect 0 "unsharded sweep (2 threads)" "$bin/raysweep" --quiet sweep "$id" "${sweep_args[@]}" -o "$tmp/ref/out"
t_ref2=$(secs "$t0" "$(now)")
start_daemon "$tmp/ref1" --threads 1
RAYSWEEP_URL=http://127.0.0.1:$started_port "$bin/raysweep" --quiet scene push "$scene" >/dev/null
t0=$(now)
RAYSWEEP_URL=http://127.0.0.1:$started_port expect 0 "unsharded sweep (1 thread)" \
  "$bin/raysweep" --quiet sweep "$id" "${sweep_args[@]}" -o "$tmp/ref1/out"
t_ref1=$(secs "$t0" "$(now)")
unset RAYSWEEP_URL
n_ref=$(wc -l <"$tmp/ref/out/index.jsonl")
[ "$n_ref" -eq 31 ] && ok || bad "the unsharded sweep indexed $n_ref films, wanted 31"
diff -r -x sweep.json "$tmp/ref/out" "$tmp/ref1/out" >/dev/null && ok || bad "1 and 2 render threads gave different films"

# ---- the recipe: 4 array tasks + a merge job ----
export RAYSWEEP_BIN_DIR=$bin TMPDIR=$tmp/tasktmp
t0=$(now)
if ! jobs=$("$submit_sh" --shards 4 --out "$tmp/run" --cpus 1 "$scene" "${sweep_args[@]}" 2>"$tmp/err"); then
  die_slurm "submit.sh failed: $(cat "$tmp/err")"
fi
read -r array merge <<<"$jobs"
[[ "$array" =~ ^[0-9]+$ && "$merge" =~ ^[0-9]+$ ]] && ok || bad "submit.sh printed '$jobs', wanted 'ARRAY MERGE'"
wait_jobs 300 "$array" "$merge" || die_slurm "the array and merge jobs did not end within 300 s: $(squeue 2>&1)"
t_slurm=$(secs "$t0" "$(now)")
st=$(job_states "$array")
[ "$st" = "4 JobState=COMPLETED" ] && ok || bad "array tasks: '$st', wanted 4 COMPLETED; logs: $(tail -n 5 "$tmp"/run/logs/shard-*.out)"
st=$(job_states "$merge")
[ "$st" = "1 JobState=COMPLETED" ] && ok || bad "merge job: '$st', wanted COMPLETED; log: $(cat "$tmp/run/logs/merge.out")"
# afterok: the merge started after every task had ended.
{ scontrol -o show job "$array"; echo; scontrol -o show job "$merge"; } >"$tmp/jobs"
py "merge after the array" '
import re, sys
arr, mrg = open(sys.argv[1]).read().split("\n\n")
ends = re.findall(r"EndTime=(\S+)", arr)
start = re.search(r"StartTime=(\S+)", mrg).group(1)
assert len(ends) == 4 and all(e <= start for e in ends), (ends, start)' "$tmp/jobs"
# Where the time went (Slurm's times have 1 s resolution).
slurm_times=$(python3 -c '
import re, sys
from datetime import datetime as D
t = lambda s: D.fromisoformat(s).timestamp()
arr, mrg = open(sys.argv[1]).read().split("\n\n")
rec = [(t(a), t(b), t(c)) for a, b, c in re.findall(r"SubmitTime=(\S+).*?StartTime=(\S+) EndTime=(\S+)", arr)]
m = re.search(r"SubmitTime=(\S+).*?StartTime=(\S+) EndTime=(\S+)", mrg)
sub = min(r[0] for r in rec)
print("tasks ran %s s each, first start %.0f s after submit, last task end to merge start %.0f s, merge %.0f s" % (
    "/".join("%.0f" % (r[2] - r[1]) for r in sorted(rec, key=lambda r: r[1])), min(r[1] for r in rec) - sub,
    t(m.group(2)) - max(r[2] for r in rec), t(m.group(3)) - t(m.group(2))))' "$tmp/jobs" 2>&1)
for i in 0 1 2 3; do
  py "shard-$i/sweep.json" '
import json, sys
m = json.load(open(sys.argv[1] + "/sweep.json"))
n = sum(1 for _ in open(sys.argv[1] + "/index.jsonl"))
i = int(sys.argv[2])
assert m["shard"] == [i, 4] and m["finished"] and m["contexts_total"] == 31, m
assert n == [16, 15, 0, 0][i], n' "$tmp/run/shard-$i" "$i"
  contains "task $i log" "$tmp/run/logs/shard-$i.out" "shard $i/4 on"
done
# Ran as an array with at most 2 at a time (CPUs=2, 1 CPU each): all 4 tasks ran.
if diff -r -x sweep.json "$tmp/ref/out" "$tmp/run/merged" >"$tmp/diff" 2>&1; then ok; else bad "merged != unsharded: $(head -c 800 "$tmp/diff")"; fi
n_films=$(find "$tmp/run/merged" -name '*.exr' | wc -l)
[ "$n_films" -eq 31 ] && ok || bad "merged holds $n_films EXR films, wanted 31"
# Every task stopped its daemon and removed its directory.
[ -z "$(ls -A "$tmp/tasktmp")" ] && ok || bad "a task left files in TMPDIR: $(ls -A "$tmp/tasktmp")"
pgrep -f "$tmp/tasktmp" >/dev/null && bad "a task's raysweepd is still running: $(pgrep -af "$tmp/tasktmp")" || ok

# ---- a task resubmitted alone renders its shard again, identically ----
mv "$tmp/run/shard-2" "$tmp/shard-2.first"
mkdir "$tmp/run/shard-2" # resubmission over an empty directory
if again=$(sbatch --parsable --array=2 --output="$tmp/run/logs/again-%a.out" "$shard_sh" --shards 4 \
  --out "$tmp/run" "$scene" "${sweep_args[@]}" 2>"$tmp/err"); then
  wait_jobs 120 "$again" || bad "the resubmitted task did not end within 120 s"
  st=$(job_states "$again")
  [ "$st" = "1 JobState=COMPLETED" ] && ok || bad "resubmitted task 2: '$st'; log: $(cat "$tmp"/run/logs/again-2.out)"
  diff -r -x sweep.json "$tmp/shard-2.first" "$tmp/run/shard-2" >/dev/null && ok || bad "task 2 resubmitted alone rendered a different shard"
else
  bad "sbatch --array=2 failed: $(cat "$tmp/err")"
fi

# ---- a failing task: the merge job never runs ----
if jobs=$("$submit_sh" --shards 2 --out "$tmp/bad" "$scene" --grid no.such.param=1:2:1 --spp 1 2>"$tmp/err"); then
  read -r array2 merge2 <<<"$jobs"
  wait_jobs 120 "$array2" "$merge2" || bad "the failing array did not end within 120 s"
  st=$(job_states "$array2")
  [ "$st" = "2 JobState=FAILED" ] && ok || bad "failing tasks: '$st', wanted 2 FAILED"
  st=$(job_states "$merge2")
  [ "$st" = "1 JobState=CANCELLED" ] && ok || bad "merge after failed tasks: '$st', wanted CANCELLED (afterok, --kill-on-invalid-dep)"
  [ ! -e "$tmp/bad/merged" ] && ok || bad "a merge ran although the tasks failed"
  contains "failing task log" "$tmp/bad/logs/shard-0.out" "raysweep sweep exited"
else
  bad "submit.sh (failing sweep) failed: $(cat "$tmp/err")"
fi

echo "$name: 31 contexts x spp $spp (hdistant_lambertian, mono): unsharded on one daemon ${t_ref2} s with 2 threads, ${t_ref1} s with 1;" \
  "Slurm 4-task array (2 CPUs, 1 thread per task) + merge, submit to merge end: ${t_slurm} s ($slurm_times)"
finish
