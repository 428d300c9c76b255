# Sourced by the shell tests in tests/integration (set `name` first): the
# pass/fail counters and the closing "NAME: N passed, N failed" line that
# tests/run.sh sums, the built binaries ($bin), a temporary directory ($tmp)
# removed on exit, and daemons on ephemeral loopback ports stopped on exit.
# shellcheck shell=bash
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
bin=$(cd "${RSW_BIN_DIR:-$root/build/bin}" 2>/dev/null && pwd)
pass=0
fail=0
ok() { pass=$((pass + 1)); }
bad() {
  fail=$((fail + 1))
  echo "FAIL $name: $*"
}
finish() {
  echo "$name: $pass passed, $fail failed"
  [ "$fail" -eq 0 ]
  exit $?
}

# need_bins PROG...: the programs must be built in $bin, else fail and finish.
need_bins() {
  local p
  for p in "$@"; do
    if [ -z "$bin" ] || [ ! -x "$bin/$p" ]; then
      bad "$* must be built in ${RSW_BIN_DIR:-build/bin} (make build/bin/$p)"
      finish
    fi
  done
}

# need_cmd CMD WHY: CMD must be on PATH, else fail (saying WHY) and finish.
need_cmd() {
  command -v "$1" >/dev/null || {
    bad "$1 is needed $2"
    finish
  }
}

tmp=$(mktemp -d)
pids=()
shtest_cleanup() {
  local p
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null && wait "$p" 2>/dev/null; done
  rm -rf "$tmp"
}
trap shtest_cleanup EXIT

# start_daemon DIR [raysweepd serve options]: a daemon on an ephemeral
# loopback port with its data root and log in DIR; sets $started_port ("" on
# failure). Not in a command substitution: the daemon must be a child of
# this shell (so the exit trap stops it) and must not hold a pipe open.
start_daemon() {
  local d=$1
  shift
  mkdir -p "$d/data"
  "$bin/raysweepd" serve --listen 127.0.0.1:0 --port-file "$d/port" --data-root "$d/data" "$@" >"$d/log" 2>&1 &
  pids+=($!)
  started_port=$(port_of "$d/port" 200)
}

# port_of FILE TRIES: the port a process writes to FILE once it listens,
# waiting up to TRIES x 50 ms ("" when it never does).
port_of() {
  for _ in $(seq "$2"); do
    [ -s "$1" ] && break
    sleep 0.05
  done
  cat "$1" 2>/dev/null
}

# start_spread_pair: two daemons (--threads 1, in $tmp/a and $tmp/b) on
# ports $pa and $pb, and tests/support/shard_lb.py in front of them on $plb
# (a balancer for `sweep --spread`; its log $tmp/lb/lb.log); fails and
# finishes when one does not start.
start_spread_pair() {
  start_daemon "$tmp/a" --threads 1
  pa=$started_port
  start_daemon "$tmp/b" --threads 1
  pb=$started_port
  [ -n "$pa" ] && [ -n "$pb" ] || {
    bad "daemons did not start: $(cat "$tmp/a/log" "$tmp/b/log")"
    finish
  }
  mkdir -p "$tmp/lb"
  python3 "$root/tests/support/shard_lb.py" "$tmp/lb/lb.port" "$pa" "$pb" 2>"$tmp/lb/lb.log" &
  pids+=($!)
  plb=$(port_of "$tmp/lb/lb.port" 100)
  [ -n "$plb" ] || {
    bad "the balancer did not start"
    finish
  }
}

# need_xarray: $py, Debian's python3 (python3-xarray, python3-netcdf4 from
# `make deps`; not one earlier on PATH that lacks them), must import both,
# else fail and finish.
need_xarray() {
  py=${RSW_PYTHON:-/usr/bin/python3}
  "$py" -c 'import xarray, netCDF4' 2>/dev/null || {
    bad "$py cannot import xarray and netCDF4 (make deps installs python3-xarray python3-netcdf4)"
    finish
  }
}
# python_spread_check LB_URL REF_URL KILL_PID REPLICA_PORT...: the checks of
# tests/support/python_spread_check.py (need_xarray first), each counted;
# all 13 must pass. KILL_PID is the replica the checks SIGKILL mid-sweep.
python_spread_check() {
  local lb=$1 ref=$2 kill_pid=$3 out p f
  shift 3
  exec 3>&2 2>/dev/null # (bash's notice of the killed replica; the checks' own stderr is in $out)
  out=$("$py" "$root/tests/support/python_spread_check.py" "$lb" "$ref" "$@" --kill "$kill_pid" 2>&1)
  kill -9 "$kill_pid" 2>/dev/null
  wait "$kill_pid" # (gone already, unless the checks failed first)
  exec 2>&3 3>&-
  echo "$out" | grep -v '^ok   '
  p=$(echo "$out" | grep -c '^ok   ')
  f=$(echo "$out" | grep -c '^FAIL ')
  pass=$((pass + p))
  fail=$((fail + f))
  [ "$p" -eq 13 ] || bad "python_spread_check.py passed $p checks, want 13: $(echo "$out" | tail -n 3)"
}
# ds LABEL CHECK ARGS...: a tests/support/dataset_check.py check must pass
# (need_xarray first).
ds() {
  local label=$1
  shift
  if "$py" "$root/tests/support/dataset_check.py" "$@" 2>"$tmp/pyerr"; then ok; else
    bad "$label: $(tail -n 3 "$tmp/pyerr")"
  fi
}

# expect RC LABEL CMD...: run CMD (stdout to $tmp/out, stderr to $tmp/err)
# and check its exit status.
expect() {
  local want=$1 label=$2
  shift 2
  "$@" >"$tmp/out" 2>"$tmp/err"
  local got=$?
  if [ "$got" -eq "$want" ]; then ok; else bad "$label: exit $got, wanted $want; stderr: $(head -c 600 "$tmp/err")"; fi
}
# contains LABEL FILE TEXT: FILE holds TEXT.
contains() {
  if grep -qF -- "$3" "$2"; then ok; else bad "$1: '$3' not in $(head -c 600 "$2")"; fi
}
# py LABEL CODE [args]: a python3 assertion (exit 0 = pass).
py() {
  local label=$1 code=$2
  shift 2
  if python3 -c "$code" "$@" 2>"$tmp/pyerr"; then ok; else bad "$label: $(tail -n 3 "$tmp/pyerr")"; fi
}
