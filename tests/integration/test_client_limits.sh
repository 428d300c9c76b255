#!/usr/bin/env bash
# The client gives up (issue 22 item 4), against test servers that misbehave
# on purpose and a real daemon:
#  - `raysweep render --timeout 5` against a server that drips its answer one
#    byte a second gives up within 5 s + its grace (2 s + 0.5 s) + 2 s of
#    slack, exit 5, naming the URL (before: still waiting after 60 s);
#  - a request that moves no byte for --stall-timeout seconds (a server that
#    sends its status line and then nothing) fails within that + 2 s, exit
#    5, naming the URL and the stall; RAYSWEEP_STALL_TIMEOUT does the same;
#  - a render (the daemon computes before it answers) is exempt from the
#    stall limit until its answer starts: a silent server holds it past the
#    stall limit, and only the render's own --timeout ends it;
#  - bad values of the limits are usage errors (2);
#  - SIGTERM on `raysweep sweep` (Slurm's scancel, a notebook restart)
#    cancels its job on the daemon, says so, and exits 143.
# The time limits are upper bounds with slack for a loaded machine (they
# would not hold for a client that waits forever); the lower bounds check
# that the limit, not an early failure, ended the request.
# Ends with "test_client_limits: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_client_limits
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweep raysweepd
need_cmd python3 "for the test servers"
cd "$tmp" || exit 1

# A misbehaving HTTP server on an ephemeral port (its port in $1.port):
#   drip:   a 200 whose 100,000-byte body comes one byte a second;
#   stall:  the status line and one header, then nothing;
#   silent: reads the request and never answers.
misbehave() {
  python3 - "$1" "$tmp/$1.port" >"$tmp/$1.log" 2>&1 <<'EOF' &
import socket, sys, threading, time
mode, port_file = sys.argv[1], sys.argv[2]
srv = socket.socket()
srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
srv.bind(("127.0.0.1", 0))
srv.listen(16)
open(port_file + ".tmp", "w").write(str(srv.getsockname()[1]))
import os
os.rename(port_file + ".tmp", port_file)
def serve(c):
    try:
        c.settimeout(120)
        buf = b""
        while b"\r\n\r\n" not in buf:
            d = c.recv(65536)
            if not d:
                return
            buf += d
        if mode == "silent":
            time.sleep(120)
        elif mode == "stall":
            c.sendall(b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n")
            time.sleep(120)
        else:
            c.sendall(b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: 100000\r\n\r\n")
            for _ in range(120):
                c.sendall(b" ")
                time.sleep(1)
    except OSError:
        pass
    finally:
        c.close()
while True:
    c, _ = srv.accept()
    threading.Thread(target=serve, args=(c,), daemon=True).start()
EOF
  pids+=($!)
  for _ in $(seq 100); do
    [ -s "$tmp/$1.port" ] && break
    sleep 0.05
  done
}
misbehave drip
misbehave stall
misbehave silent
drip=$(cat "$tmp/drip.port" 2>/dev/null)
stall=$(cat "$tmp/stall.port" 2>/dev/null)
silent=$(cat "$tmp/silent.port" 2>/dev/null)
[ -n "$drip" ] && [ -n "$stall" ] && [ -n "$silent" ] && ok || bad "the test servers did not start"

# timed LIMIT_LO LIMIT_HI RC LABEL CMD...: CMD exits RC after between LO and
# HI seconds (stderr in $tmp/err).
timed() {
  local lo=$1 hi=$2 want=$3 label=$4
  shift 4
  local t0 t1 got
  t0=$(date +%s.%N)
  timeout 120 "$@" >"$tmp/out" 2>"$tmp/err"
  got=$?
  t1=$(date +%s.%N)
  local dt
  dt=$(python3 -c 'import sys; print("%.2f" % (float(sys.argv[2]) - float(sys.argv[1])))' "$t0" "$t1")
  if [ "$got" -eq "$want" ] && python3 -c 'import sys; sys.exit(0 if float(sys.argv[2]) <= float(sys.argv[1]) <= float(sys.argv[3]) else 1)' "$dt" "$lo" "$hi"; then
    ok
  else
    bad "$label: exit $got after $dt s, wanted $want within [$lo, $hi] s; stderr: $(head -c 600 "$tmp/err")"
  fi
}

# ---- render --timeout bounds the whole transfer ----
timed 4.5 9.5 5 "render --timeout 5 against a dripping server" \
  "$bin/raysweep" --server "http://127.0.0.1:$drip" render abc --timeout 5 -o drip.json
contains "the timeout names the URL" err "http://127.0.0.1:$drip/v1/scenes/abc:render"
[ ! -e drip.json ] && ok || bad "a film was written from a dripped answer"

# ---- the low-speed limit ----
timed 1.5 5 5 "scene ls against a server that stalls after its status line" \
  "$bin/raysweep" --server "http://127.0.0.1:$stall" --stall-timeout 2 scene ls
contains "the stall names the URL" err "http://127.0.0.1:$stall/v1/scenes"
contains "the stall says what happened" err "no progress for 2 s"
export RAYSWEEP_STALL_TIMEOUT=2
timed 1.5 5 5 "RAYSWEEP_STALL_TIMEOUT=2: job ls against a silent server" \
  "$bin/raysweep" --server "http://127.0.0.1:$silent" job ls
contains "the stall (env) names the URL" err "http://127.0.0.1:$silent/v1/jobs"
unset RAYSWEEP_STALL_TIMEOUT
# A render waits for its answer to start: the stall limit (1 s) does not end
# it, its --timeout (3 s + 2.3 s of grace) does.
timed 4.8 9 5 "render against a silent server: its --timeout, not the stall limit" \
  "$bin/raysweep" --server "http://127.0.0.1:$silent" --stall-timeout 1 render abc --timeout 3 -o silent.json
contains "the render's timeout names the URL" err "http://127.0.0.1:$silent/v1/scenes/abc:render"

expect 2 "--stall-timeout x" "$bin/raysweep" --stall-timeout x scene ls
contains "--stall-timeout x: says which" err "--stall-timeout"
expect 2 "--connect-timeout 0" "$bin/raysweep" --connect-timeout 0 scene ls
RAYSWEEP_CONNECT_TIMEOUT=-1 expect 2 "RAYSWEEP_CONNECT_TIMEOUT=-1" "$bin/raysweep" scene ls
contains "the environment variable is named" err "RAYSWEEP_CONNECT_TIMEOUT"

# ---- SIGTERM on sweep: cancel the job, say so, exit 143 ----
start_daemon "$tmp/d"
port=$started_port
if [ -z "$port" ]; then
  bad "the daemon did not start: $(cat "$tmp/d/log")"
  finish
fi
export RAYSWEEP_URL="http://127.0.0.1:$port"
cat >plate.json <<'EOF'
{
  "type": "scene",
  "variant": "mono",
  "hd": {"type": "hdistant", "film": {"type": "hdrfilm", "width": 8, "height": 8}},
  "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": 1.0},
  "plate": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": 0.5}}
}
EOF
expect 0 "push plate" "$bin/raysweep" -q scene push plate.json
plate=$(cat "$tmp/out")
# A background command of a non-interactive shell starts with SIGINT
# ignored, SIGTERM not: no need to restore anything.
"$bin/raysweep" sweep "$plate" --grid wavelength=400:700:1 --spp 4000000 -o long >long.out 2>long.err &
sp=$!
for _ in $(seq 600); do
  grep -q '^raysweep sweep: job ' long.err && break
  sleep 0.1
done
job=$(sed -n 's/^raysweep sweep: job \([^: ]*\):.*/\1/p' long.err | head -n 1)
[ -n "$job" ] && ok || bad "the long sweep did not name its job: $(cat long.err)"
kill -TERM "$sp"
wait "$sp"
rc=$?
[ "$rc" -eq 143 ] && ok || bad "sweep after SIGTERM: exit $rc, wanted 143; stderr: $(cat long.err)"
contains "sweep SIGTERM says so" long.err "terminated (SIGTERM); cancelled job $job on the daemon"
state=""
for _ in $(seq 600); do
  state=$("$bin/raysweep" job show "$job" --json 2>/dev/null | python3 -c 'import json,sys; print(json.load(sys.stdin)["state"])' 2>/dev/null)
  [ "$state" = cancelled ] && break
  sleep 0.1
done
[ "$state" = cancelled ] && ok || bad "after SIGTERM the job is '$state', not cancelled"
finish
