#!/usr/bin/env bash
# tests/fuzz/run.sh SECONDS NAME...: fuzz each harness build-fuzz/bin/fuzz_NAME
# for SECONDS, one process each, $FUZZ_JOBS harnesses at a time (default:
# the machine's cores, so that each harness has a core of its own and
# still runs SECONDS; FUZZ_JOBS=1 runs them one after the other). Seeds:
# tests/fuzz/corpus/NAME (read only) and tests/fuzz/crashes/NAME; new
# inputs go to build-fuzz/corpus/NAME, a finding to
# build-fuzz/crashes/NAME/. Prints one line per harness, in the order
# given ("fuzz NAME: N runs in S s, corpus C, ok|FINDING path"), and fails
# if any harness found something. Copy a finding into
# tests/fuzz/crashes/NAME/ once it is fixed: make test replays it from
# then on.
set -u
cd "$(dirname "$0")/../.."
secs=$1
shift
export ASAN_OPTIONS="detect_leaks=1:allocator_may_return_null=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
export LSAN_OPTIONS="suppressions=$PWD/tests/lsan.supp:print_suppressions=0${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"
jobs=${FUZZ_JOBS:-$(nproc 2>/dev/null || echo 1)}
[ "$jobs" -ge 1 ] 2>/dev/null || jobs=1
# fuzz_one NAME: fuzz one harness; its report goes to build-fuzz/fuzz_NAME.result
# (one line ending in ", ok", or the finding's lines).
fuzz_one() {
  local h=$1
  local bin=build-fuzz/bin/fuzz_$h work=build-fuzz/corpus/$h art=build-fuzz/crashes/$h
  local log=build-fuzz/fuzz_$h.log out=build-fuzz/fuzz_$h.result
  mkdir -p "$work" "$art"
  local seeds=(tests/fuzz/corpus/"$h")
  [ -d tests/fuzz/crashes/"$h" ] && seeds+=(tests/fuzz/crashes/"$h")
  local before
  before=$(find "$art" -type f | wc -l)
  local dict=()
  case $h in scene_json | scene_xml | scene_render) dict=(-dict=tests/fuzz/scene.dict) ;; esac
  "$bin" "${dict[@]}" -max_total_time="$secs" -timeout=30 -rss_limit_mb=3072 -max_len=16384 -print_final_stats=1 \
    -artifact_prefix="$art/" "$work" "${seeds[@]}" >"$log" 2>&1
  local rc=$?
  local runs corpus after
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
  corpus=$(find "$work" -type f | wc -l)
  after=$(find "$art" -type f | wc -l)
  if [ "$rc" -ne 0 ] || [ "$after" -gt "$before" ]; then
    {
      echo "fuzz $h: ${runs:-?} runs in $secs s, corpus $corpus, FINDING (exit $rc): $(find "$art" -type f -newer "$bin" | head -n 3 | tr '\n' ' ')"
      grep -m 3 -E 'ERROR: |fuzz invariant broken|runtime error' "$log" | sed 's/^/  /'
      echo "  log: $log"
    } >"$out"
    return
  fi
  echo "fuzz $h: ${runs:-?} runs in $secs s, corpus $corpus, ok" >"$out"
}
for h in "$@"; do
  while [ "$(jobs -pr | wc -l)" -ge "$jobs" ]; do wait -n; done
  rm -f build-fuzz/fuzz_"$h".result
  fuzz_one "$h" &
done
wait
found=0
for h in "$@"; do
  if [ -s build-fuzz/fuzz_"$h".result ]; then
    cat build-fuzz/fuzz_"$h".result
    grep -q '^fuzz [^:]*: .*, ok$' build-fuzz/fuzz_"$h".result || found=1
  else
    echo "fuzz $h: no report (the harness did not run)"
    found=1
  fi
done
exit $found
