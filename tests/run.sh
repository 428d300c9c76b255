#!/usr/bin/env bash
# Runs every test program given, sums their "N passed, N failed" lines, and
# ends with one closing line "N passed, N failed" (.ci/run parses it). A
# program that crashes or prints no summary counts as one failure.
#
#   tests/run.sh [-j N] TEST...
#
# Up to N programs run at once (default: $TEST_JOBS, else twice the number
# of online cores, since most programs spend much of their time waiting on
# a daemon, a socket or a child. On a 2-core machine shared with other
# builds, pairs of runs measured -j 4 at 56 % and 93 % of -j 1's wall time
# and -j 2 at 66 %, 77 % and 92 %: the load of the rest of the machine
# decides as much. -j 1 runs them one after another.) Each program's output
# is kept in a file of its own and printed whole when it is its turn, in
# the order of the list, so the log reads as a serial run's. The programs
# named in `alone` run after the others, one at a time, with nothing beside
# them: each bounds a latency of its own (a refusal within 0.5 s, a quick
# render within 1 s while a long one runs, an answer within 1 s under
# load; test_state calibrates a job's length to kill the daemon in its
# middle), which a test program running beside it could push over. No test
# uses a fixed port or a fixed file name (each has its own mktemp
# directory and ephemeral ports), and the inner `make install` / `make run`
# of test_install, test_docs_examples and test_make_run find everything
# built by `make test` first, so nothing else needs serialising.
# RSW_TEST_TIMES=FILE: the wall times of the last run ("NAME WALL USER SYS"
# per program, seconds), read to order this run and rewritten after it
# (make test keeps them in BUILD/test-times).
set -u
here=$(cd "$(dirname "$0")" && pwd)
export RSW_TEST_DIR="$here"
export LSAN_OPTIONS="suppressions=$here/lsan.supp:print_suppressions=0${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"

alone=" test_http_limits test_render_views test_service_limits test_state "

jobs=${TEST_JOBS:-}
case ${1:-} in
  -j) jobs=${2:-}; shift 2 ;;
  -j*) jobs=${1#-j}; shift ;;
esac
[ -n "$jobs" ] || jobs=$((2 * $(nproc 2>/dev/null || echo 1)))
if ! [[ $jobs =~ ^[1-9][0-9]*$ ]]; then
  echo "tests/run.sh: -j wants a positive number of jobs, not '$jobs'" >&2
  exit 2
fi

out=$(mktemp -d "${TMPDIR:-/tmp}/rsw-tests-XXXXXX") || exit 1
running=()
cleanup() {
  local p
  for p in "${running[@]}"; do kill "$p" 2>/dev/null; done
  rm -rf "$out"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# The list, the programs that may share the machine first.
list=()
for t in "$@"; do [[ $alone == *" $(basename "$t" .sh) "* ]] || list+=("$t"); done
n_shared=${#list[@]}
for t in "$@"; do [[ $alone == *" $(basename "$t" .sh) "* ]] && list+=("$t"); done

# The order they start in: longest first (by RSW_TEST_TIMES, the wall times
# of the last run, when it exists; else the shell scripts, which wait on
# daemons and are the long ones, before the compiled programs), so that no
# long program starts last and runs alone. Output keeps the list's order.
declare -A prev=()
if [ -n "${RSW_TEST_TIMES:-}" ] && [ -f "$RSW_TEST_TIMES" ]; then
  while read -r k w _; do prev[$k]=$w; done <"$RSW_TEST_TIMES"
fi
order=()
if [ "$n_shared" -gt 0 ]; then
  mapfile -t order < <(for ((k = 0; k < n_shared; k++)); do
    b=$(basename "${list[$k]}")
    est=${prev[$b]:-}
    [ -n "$est" ] || case $b in *.sh) est=30 ;; *) est=5 ;; esac
    echo "$est $k"
  done | sort -k1,1gr -k2,2n | cut -d' ' -f2)
fi

# start I: runs program I in the background; its output goes to $out/I.out
# and its exit status to $out/I.rc.
start() {
  local i=$1
  (
    TIMEFORMAT='%R %U %S'
    { time "${list[$i]}" >"$out/$i.out" 2>&1; } 2>"$out/$i.time"
    echo $? >"$out/$i.rc"
  ) &
  running+=($!)
}

pass=0; fail=0; next=0
# report: prints, in list order, every finished program not printed yet.
report() {
  local t name rc line p f
  while [ "$next" -lt "${#list[@]}" ] && [ -f "$out/$next.rc" ]; do
    t=${list[$next]}
    name=$(basename "$t" .sh)
    rc=$(<"$out/$next.rc")
    cat "$out/$next.out"
    line=$(grep -E "^$name: [0-9]+ passed, [0-9]+ failed$" "$out/$next.out" | tail -n 1)
    rm -f "$out/$next.out"
    echo "$(basename "$t") $(tail -n 1 "$out/$next.time")" >>"$out/times"
    next=$((next + 1))
    if [ -z "$line" ]; then
      echo "FAIL $name: exited $rc without a summary line"
      fail=$((fail + 1)); continue
    fi
    p=$(echo "$line" | sed -E 's/.*: ([0-9]+) passed, ([0-9]+) failed/\1/')
    f=$(echo "$line" | sed -E 's/.*: ([0-9]+) passed, ([0-9]+) failed/\2/')
    pass=$((pass + p)); fail=$((fail + f))
    if [ "$rc" -ne 0 ] && [ "$f" -eq 0 ]; then
      echo "FAIL $name: exit status $rc"; fail=$((fail + 1))
    fi
  done
}

active=0
for k in "${order[@]}"; do
  if [ "$active" -ge "$jobs" ]; then
    wait -n; active=$((active - 1))
    report
  fi
  start "$k"; active=$((active + 1))
done
while [ "$active" -gt 0 ]; do
  wait -n; active=$((active - 1))
  report
done
wait
report
i=$n_shared
while [ "$i" -lt "${#list[@]}" ]; do
  start "$i"; i=$((i + 1))
  wait
  report
done
running=()
[ -n "${RSW_TEST_TIMES:-}" ] && [ -f "$out/times" ] && cp "$out/times" "$RSW_TEST_TIMES"
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
