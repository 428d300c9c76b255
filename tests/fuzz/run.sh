#!/usr/bin/env bash
# tests/fuzz/run.sh SECONDS NAME...: fuzz each harness build-fuzz/bin/fuzz_NAME
# for SECONDS, one at a time, one process each (the machine's cores are
# shared). Seeds: tests/fuzz/corpus/NAME (read only) and
# tests/fuzz/crashes/NAME; new inputs go to build-fuzz/corpus/NAME, a
# finding to build-fuzz/crashes/NAME/. Prints one line per harness
# ("fuzz NAME: N runs in S s, corpus C, ok|FINDING path") and fails if
# any harness found something. Copy a finding into tests/fuzz/crashes/NAME/
# once it is fixed: make test replays it from then on.
set -u
cd "$(dirname "$0")/../.."
secs=$1
shift
export ASAN_OPTIONS="detect_leaks=1:allocator_may_return_null=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
export LSAN_OPTIONS="suppressions=$PWD/tests/lsan.supp:print_suppressions=0${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"
found=0
for h in "$@"; do
  bin=build-fuzz/bin/fuzz_$h
  work=build-fuzz/corpus/$h
  art=build-fuzz/crashes/$h
  mkdir -p "$work" "$art"
  seeds=(tests/fuzz/corpus/"$h")
  [ -d tests/fuzz/crashes/"$h" ] && seeds+=(tests/fuzz/crashes/"$h")
  log=build-fuzz/fuzz_$h.log
  before=$(find "$art" -type f | wc -l)
  dict=()
  case $h in scene_json | scene_xml | scene_render) dict=(-dict=tests/fuzz/scene.dict) ;; esac
  "$bin" "${dict[@]}" -max_total_time="$secs" -timeout=30 -rss_limit_mb=3072 -max_len=16384 -print_final_stats=1 \
    -artifact_prefix="$art/" "$work" "${seeds[@]}" >"$log" 2>&1
  rc=$?
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
  corpus=$(find "$work" -type f | wc -l)
  after=$(find "$art" -type f | wc -l)
  if [ "$rc" -ne 0 ] || [ "$after" -gt "$before" ]; then
    found=1
    echo "fuzz $h: ${runs:-?} runs in $secs s, corpus $corpus, FINDING (exit $rc): $(find "$art" -type f -newer "$bin" | head -n 3 | tr '\n' ' ')"
    grep -m 3 -E 'ERROR: |fuzz invariant broken|runtime error' "$log" | sed 's/^/  /'
    echo "  log: $log"
  else
    echo "fuzz $h: ${runs:-?} runs in $secs s, corpus $corpus, ok"
  fi
done
exit $found
