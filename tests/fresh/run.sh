#!/usr/bin/env bash
# The README's two commands on a fresh Debian 12, for real (.ci/run runs this;
# `make test` does not). As root (through sudo when not root):
#   1. a clean bookworm root file system: debootstrap --variant=minbase, plus
#      git and ca-certificates only (the tarball is cached between runs in
#      $RSW_FRESH_CACHE, default /var/cache/raysweep-fresh, for 30 days);
#   2. this checkout's HEAD, git-cloned into it (/root/raysweep);
#   3. in a chroot: `./make -j2 test` (no make, no compiler, nothing else
#      installed before it): it must end "N passed, 0 failed" with N > 0;
#   4. make -jN with make present but a library missing (libmicrohttpd-dev
#      removed, server/http/server.c touched): `make -j2` must install it
#      before compiling anything;
#   5. a no-op `make` must be fast (one dpkg-query; no apt, no network);
#   6. `./make run` (PORT= another port when 8350 is taken here) must start
#      the daemon with the embedded default scene, which must answer a
#      render of the right size with finite, non-negative values;
#      then the daemon is stopped.
# Everything is mounted in a mount namespace of its own (unshare) and
# unmounted on exit whatever happens; the root file system is removed
# unless --keep. Prints a timestamped line per step and ends with
# "fresh: PASS (N s)" or "fresh: FAIL: why" (exit status 1).
# A Debian mirror that cannot be reached is a failure, not a skip.
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
keep=0
[ "${1:-}" = --keep ] && keep=1
start=$(date +%s)
say() { echo "[fresh +$(($(date +%s) - start))s] $*"; }
die() {
  echo "fresh: FAIL: $*"
  exit 1
}

if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null || die "must run as root (debootstrap, mount, chroot), and sudo is not installed"
  exec sudo RSW_FRESH_CACHE="${RSW_FRESH_CACHE:-}" RSW_FRESH_MIRROR="${RSW_FRESH_MIRROR:-}" "$0" "$@"
fi
# A private mount namespace: the mounts below cannot leak out of this process.
if [ -z "${RSW_FRESH_NS:-}" ] && command -v unshare >/dev/null && unshare --mount --propagation private true 2>/dev/null; then
  RSW_FRESH_NS=1 exec unshare --mount --propagation private "$0" "$@"
fi

cache=${RSW_FRESH_CACHE:-/var/cache/raysweep-fresh}
mkdir -p "$cache"
exec 9>"$cache/lock"
flock -w 1800 9 || die "another fresh-root test holds $cache/lock"

# ---- debootstrap (cached): $base ---------------------------------------------------
# shellcheck source=base.sh
. "$repo/tests/fresh/base.sh"

# ---- the root file system and the clone ----------------------------------------
work=$(mktemp -d /var/tmp/raysweep-fresh.XXXXXX)
root=$work/root
mounts=()
daemon=
child=
cleanup() {
  local rc=$?
  set +e
  local g
  for g in $child $daemon; do
    if kill -0 "$g" 2>/dev/null; then
      kill -TERM -- "-$g" 2>/dev/null; sleep 2; kill -KILL -- "-$g" 2>/dev/null
    fi
  done
  local i
  for ((i = ${#mounts[@]} - 1; i >= 0; i--)); do
    umount "${mounts[i]}" 2>/dev/null || umount -l "${mounts[i]}"
  done
  if grep -q " $root" /proc/mounts; then
    echo "fresh: mounts left under $root; not removing it"
  elif [ "$keep" = 1 ]; then
    echo "fresh: kept $work"
  else
    rm -rf --one-file-system "$work"
  fi
  exit "$rc"
}
trap cleanup EXIT
trap 'exit 1' INT TERM HUP

mkdir -p "$root"
tar -C "$root" --numeric-owner -xpf "$base"
cp -L /etc/resolv.conf "$root/etc/resolv.conf"
head=$(git -C "$repo" rev-parse HEAD)
[ -z "$(git -C "$repo" status --porcelain)" ] || say "note: uncommitted changes in $repo are not part of this test (HEAD only)"
git clone -q --no-checkout "$repo" "$root/root/raysweep"
git -C "$root/root/raysweep" checkout -q "$head"
say "root file system in $root; $(git -C "$repo" log -1 --format='%h %s' "$head")"

mnt() { # mnt TARGET MOUNT-ARGS...
  local target=$1
  shift
  mount "$@" "$target"
  mounts+=("$target")
}
mnt "$root/proc" -t proc proc
mnt "$root/sys" -t sysfs sysfs
mnt "$root/dev" --bind /dev
mnt "$root/dev/pts" --bind /dev/pts
mnt "$root/dev/shm" -t tmpfs tmpfs

# in_root CMD: CMD by /bin/sh in the clone, with a clean environment.
in_root() {
  chroot "$root" /usr/bin/env -i HOME=/root LANG=C.UTF-8 TERM=dumb \
    PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin /bin/sh -c "cd /root/raysweep && $1"
}
# in_root_long LOG CMD: the same in a session of its own, waited for so that a
# signal to this script is handled at once (cleanup stops the session).
in_root_long() {
  local log=$1 rc=0
  shift
  setsid bash -c "$(declare -f in_root); root='$root'; in_root \"\$1\"" _ "$1" >"$log" 2>&1 &
  child=$!
  wait "$child" || rc=$?
  child=
  return "$rc"
}
for tool in make cc; do
  ! in_root "command -v $tool" >/dev/null || die "the fresh root already has $tool: not a fresh machine"
done

# ---- 3. the test command -------------------------------------------------------
say "./make -j2 test (log: $work/test.log)"
t0=$(date +%s)
rc=0
in_root_long "$work/test.log" './make -j2 test' || rc=$?
t_test=$(($(date +%s) - t0))
summary=$(grep -E '^[0-9]+ passed, [0-9]+ failed$' "$work/test.log" | tail -n 1 || true)
grep -E '^FAIL ' "$work/test.log" | head -n 20 || true
say "./make -j2 test: exit $rc in ${t_test}s: ${summary:-no summary line}"
if [ -z "$summary" ] || [ "$rc" -ne 0 ]; then
  tail -n 30 "$work/test.log"
  keep=1
  die "./make -j2 test did not pass (exit $rc, '${summary:-no summary line}'); log kept in $work/test.log"
fi
npass=${summary%% passed*}
nfail=${summary#*, }
nfail=${nfail%% failed}
[ "$nfail" -eq 0 ] && [ "$npass" -gt 0 ] || die "./make -j2 test: '$summary'"
grep -q '^deps: installed ' "$work/test.log" || die "./make -j2 test did not install the packages itself (no 'deps: installed' line)"

# ---- 4. make -j2 with make present and a library missing ----------------------------
in_root 'apt-get remove -y -qq libmicrohttpd-dev >/dev/null 2>&1; touch server/http/server.c'
! in_root 'dpkg -s libmicrohttpd-dev >/dev/null 2>&1' || die "could not remove libmicrohttpd-dev"
rc=0
in_root_long "$work/race.log" 'make -j2' || rc=$?
first_cc=$(grep -n -m1 -E '^cc .* -c ' "$work/race.log" | cut -d: -f1 || true)
installed=$(grep -n -m1 '^deps: installed .*libmicrohttpd-dev' "$work/race.log" | cut -d: -f1 || true)
if [ "$rc" -ne 0 ] || [ -z "$installed" ] || [ -z "$first_cc" ] || [ "$installed" -gt "$first_cc" ]; then
  tail -n 20 "$work/race.log"
  die "make -j2 without libmicrohttpd-dev: exit $rc; deps installed it at log line ${installed:-never}, first compile at line ${first_cc:-never}"
fi
say "make -j2 without libmicrohttpd-dev: installed it (log line $installed) before the first compile (line $first_cc)"

# ---- 5. a no-op make ---------------------------------------------------------------
t0=$(date +%s%N)
out=$(in_root 'make 2>&1')
ms=$((($(date +%s%N) - t0) / 1000000))
! grep -qE '^(cc|deps:) ' <<<"$out" || die "a second make is not a no-op: $out"
[ "$ms" -lt 5000 ] || die "a no-op make took $ms ms"
say "no-op make: $ms ms"

# ---- 6. the run command ---------------------------------------------------------------
port=8350
run_cmd='./make run'
if (exec 3<>/dev/tcp/127.0.0.1/8350) 2>/dev/null; then
  port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])' 2>/dev/null ||
    echo 18350)
  run_cmd="./make run PORT=$port"
  say "8350 is taken on this host: $run_cmd"
fi
say "$run_cmd"
setsid chroot "$root" /usr/bin/env -i HOME=/root LANG=C.UTF-8 TERM=dumb \
  PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
  /bin/sh -c "cd /root/raysweep && exec $run_cmd" >"$work/run.log" 2>&1 &
daemon=$!
for _ in $(seq 1 1200); do
  grep -q "listening on http://127.0.0.1:$port" "$work/run.log" && break
  kill -0 "$daemon" 2>/dev/null || break
  sleep 0.1
done
grep -q "listening on http://127.0.0.1:$port" "$work/run.log" || { cat "$work/run.log"; die "$run_cmd did not start listening on $port"; }
grep -q "embedded default" "$work/run.log" || die "$run_cmd did not load the embedded default scene: $(cat "$work/run.log")"
# The render, fetched inside the root (its curl and python3 came with the deps).
cat >"$root/tmp/render_check.sh" <<'EOF'
set -e
url=http://127.0.0.1:$1
id=$(curl -sSf "$url/v1/scenes" | sed 's/.*"id":"\([0-9a-f]*\)".*/\1/')
curl -sSf -X POST "$url/v1/scenes/$id:render" -H 'Content-Type: application/json' -d '{"spp": 16, "seed": 1}' |
  python3 -c '
import json, math, sys
f = json.load(sys.stdin)
w, h, c = f["width"], f["height"], len(f["channels"])
d = f["data"]
assert (w, h) == (32, 32), ("film size", w, h)
assert len(d) == w * h * c, ("data length", len(d), w, h, c)
assert all(math.isfinite(x) and x >= 0 for x in d), "a value is negative or not finite"
assert max(d) > 0, "all zero"
spp = f["meta"]["spp"]
print(f"{w}x{h}x{c} film, values in [{min(d):.4g}, {max(d):.4g}], spp {spp}")
'
EOF
check=$(in_root "sh /tmp/render_check.sh $port" 2>&1) || die "the render from $run_cmd is wrong: $check"
say "render: $check"
kill -TERM -- "-$daemon"
for _ in $(seq 1 100); do kill -0 "$daemon" 2>/dev/null || break; sleep 0.1; done
! kill -0 "$daemon" 2>/dev/null || die "the daemon did not stop on SIGTERM"
daemon=
grep -q "shutting down" "$work/run.log" || die "the daemon did not say it was shutting down: $(tail -n 3 "$work/run.log")"
say "daemon stopped"
echo "fresh: PASS ($(($(date +%s) - start)) s; ./make -j2 test ${t_test} s: $summary)"
