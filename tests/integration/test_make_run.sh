#!/usr/bin/env bash
# `make run`: PORT= chooses the port, the daemon answers there, and a port
# that is taken is said plainly, by make run (with a free port to try) and
# by raysweepd serve itself. Ends with "test_make_run: N passed, N failed".
set -u
root=$(cd "$(dirname "$0")/../.." && pwd)
bin=${RSW_BIN_DIR:-build/bin}
case $bin in /*) ;; *) bin=$root/$bin ;; esac
pass=0
fail=0
ok() { echo "ok   $1"; pass=$((pass + 1)); }
bad() { echo "FAIL $1"; fail=$((fail + 1)); }
tmp=$(mktemp -d)
pgid=
cleanup() {
  [ -n "$pgid" ] && kill -TERM -- "-$pgid" 2>/dev/null && sleep 0.5
  [ -n "$pgid" ] && kill -KILL -- "-$pgid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
# The variables of the `make test` that runs this are not the inner make's.
mk() { env -u MAKEFLAGS -u MFLAGS -u MAKELEVEL make -s -C "$root" SAN="${SAN:-}" "$@"; }
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }

port=$(free_port)
# setsid: its own process group, so that make and the daemon stop together.
setsid bash -c 'exec env -u MAKEFLAGS -u MFLAGS -u MAKELEVEL make -s -C "$1" SAN="$2" run PORT="$3"' _ \
  "$root" "${SAN:-}" "$port" >"$tmp/run.log" 2>&1 &
pgid=$!
for _ in $(seq 1 600); do
  grep -q "listening on http://127.0.0.1:$port" "$tmp/run.log" && break
  kill -0 "$pgid" 2>/dev/null || break
  sleep 0.1
done
if grep -q "listening on http://127.0.0.1:$port" "$tmp/run.log"; then
  ok "make run PORT=$port listens on $port"
else
  bad "make run PORT=$port did not listen there: $(tail -n 5 "$tmp/run.log")"
fi
code=$(curl -s -o /dev/null -w '%{http_code}' "http://127.0.0.1:$port/v1/health/live")
[ "$code" = 200 ] && ok "GET /v1/health/live on $port: 200" || bad "GET /v1/health/live on $port: $code, want 200"

# The same port again: make run says so and names a free port.
out=$(mk run PORT="$port" 2>&1)
rc=$?
if [ "$rc" -ne 0 ] && grep -q "port $port is in use" <<<"$out" && grep -qE "try make run PORT=[0-9]+" <<<"$out"; then
  ok "make run on a taken port: $(grep -m1 'is in use' <<<"$out")"
else
  bad "make run PORT=$port while it is taken: exit $rc, output: $out"
fi
suggested=$(grep -oE "try make run PORT=[0-9]+" <<<"$out" | grep -oE "[0-9]+$")
if [ -n "$suggested" ] && [ "$suggested" != "$port" ] && ! (exec 3<>"/dev/tcp/127.0.0.1/$suggested") 2>/dev/null; then
  ok "the suggested port $suggested is free"
else
  bad "the suggested port '$suggested' is not a free one"
fi

# raysweepd serve itself, on the taken port (what make run's check cannot see
# coming: a port taken between the check and the bind).
out=$("$bin/raysweepd" serve --listen "127.0.0.1:$port" 2>&1)
rc=$?
if [ "$rc" -ne 0 ] && grep -q "cannot listen on 127.0.0.1:$port: Address already in use" <<<"$out" &&
  grep -q -- "--listen 127.0.0.1:0" <<<"$out"; then
  ok "raysweepd serve on a taken port exits $rc and says what to do"
else
  bad "raysweepd serve on a taken port: exit $rc, output: $out"
fi

# A PORT in the environment (PaaS style) is not make run's: the default stays.
line=$(PORT=1 env -u MAKEFLAGS -u MFLAGS -u MAKELEVEL make -n -C "$root" SAN="${SAN:-}" run 2>/dev/null | grep 'raysweepd serve')
grep -q -- "--listen 127.0.0.1:8350$" <<<"$line" && ok "PORT from the environment is ignored (8350)" ||
  bad "PORT=1 in the environment changed make run: $line"

echo "test_make_run: $pass passed, $fail failed"
[ "$fail" -eq 0 ]
