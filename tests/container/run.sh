#!/usr/bin/env bash
# The container image, built and run (.ci/run runs this; `make test` does
# not). No Docker engine runs here, and `podman run` cannot (the sandbox
# cannot set rlimits), but podman can build, and the image's own files can
# be run in a chroot. As root (through sudo when not root):
#   1. podman (tools/deps.sh container) and the fresh-root test's cached
#      bookworm root (tests/fresh/base.sh) imported as the local image
#      `debian:12` (there is no registry to pull from);
#   2. podman build --isolation chroot --pull=never --network host -f
#      docker/Dockerfile, this checkout's working tree as the context
#      (.dockerignore leaves build outputs out): the time it took;
#   3. the runtime stage kept lean: no compiler (gcc, cc, cpp, clang, make)
#      and no -dev package installed; its size over the base image's
#      at most RSW_CONTAINER_MAX_MB (default 150; 99 MB on 2026-11-27) MB;
#   4. the image mounted (podman image mount) and, in a mount namespace of
#      our own with a tmpfs on /tmp, its own binaries run in a chroot as the
#      image's user (uid 10001): `raysweepd version`, then `raysweepd serve`
#      on a loopback port, its health answered by the image's curl (what
#      HEALTHCHECK runs), and a render of the embedded default scene whose
#      film must have the right size and finite, non-negative values.
# podman's storage is kept in $RSW_CONTAINER_CACHE (default
# /var/cache/raysweep-container), with the image as raysweep:ci, so a second
# build reuses the package layer (--format docker: HEALTHCHECK is kept). Prints a timestamped line per step and ends with
# "container: PASS (...)" or "container: FAIL: why" (exit status 1).
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
start=$(date +%s)
say() { echo "[container +$(($(date +%s) - start))s] $*"; }
die() {
  echo "container: FAIL: $*"
  exit 1
}

if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null || die "must run as root (podman build, image mount, chroot), and sudo is not installed"
  exec sudo RSW_FRESH_CACHE="${RSW_FRESH_CACHE:-}" RSW_FRESH_MIRROR="${RSW_FRESH_MIRROR:-}" \
    RSW_CONTAINER_CACHE="${RSW_CONTAINER_CACHE:-}" RSW_CONTAINER_MAX_MB="${RSW_CONTAINER_MAX_MB:-}" "$0" "$@"
fi
# A private mount namespace: the tmpfs and /proc below cannot leak out.
if [ -z "${RSW_CONTAINER_NS:-}" ] && command -v unshare >/dev/null && unshare --mount --propagation private true 2>/dev/null; then
  RSW_CONTAINER_NS=1 exec unshare --mount --propagation private "$0" "$@"
fi

# ---- 1. podman and the base image -------------------------------------------------
"$repo/tools/deps.sh" container || die "cannot install podman (tools/deps.sh container)"
cache=${RSW_FRESH_CACHE:-/var/cache/raysweep-fresh}
mkdir -p "$cache"
(
  exec 9>"$cache/lock"
  flock -w 1800 9 || die "another fresh-root test holds $cache/lock"
  # shellcheck source=../fresh/base.sh
  . "$repo/tests/fresh/base.sh"
  echo "$base" >"$cache/base.path.$$"
)
base=$(cat "$cache/base.path.$$")
rm -f "$cache/base.path.$$"
store=${RSW_CONTAINER_CACHE:-/var/cache/raysweep-container}
mkdir -p "$store/root" "$store/run"
exec 8>"$store/lock"
flock -w 1800 8 || die "another container test holds $store/lock"
pm() { podman --root "$store/root" --runroot "$store/run" --storage-driver overlay "$@"; }
tag=localhost/raysweep:ci
mnt=
daemon=
cleanup() {
  local rc=$?
  set +e
  if [ -n "$daemon" ] && kill -0 "$daemon" 2>/dev/null; then
    kill -TERM "$daemon" 2>/dev/null
    sleep 1
    kill -KILL "$daemon" 2>/dev/null
  fi
  for m in "${mounts[@]}"; do umount "$m" 2>/dev/null || umount -l "$m"; done
  [ -n "$mnt" ] && pm image unmount "$tag" >/dev/null 2>&1
  exit "$rc"
}
mounts=()
trap cleanup EXIT
trap 'exit 1' INT TERM HUP

digest=$(sha256sum "$base" | cut -c1-16)
if [ "$(pm image inspect --format '{{index .Labels "rsw.base"}}' localhost/debian:12 2>/dev/null)" = "$digest" ]; then
  say "debian:12 is $base (imported before)"
else
  say "importing $base as debian:12"
  pm import -q --change "LABEL rsw.base=$digest" "$base" localhost/debian:12 >/dev/null ||
    die "podman import $base failed"
fi
base_bytes=$(pm image inspect --format '{{.Size}}' localhost/debian:12)

# ---- 2. the build ------------------------------------------------------------------
say "podman build --isolation chroot --pull=never --network host -f docker/Dockerfile (log: $store/build.log)"
# The image and its build stage's layers stay (the next build reuses them);
# what no build used for 3 days goes.
pm image prune -f --filter until=72h >/dev/null 2>&1 || true
t0=$(date +%s)
if ! pm build --format docker --isolation chroot --pull=never --network host -f "$repo/docker/Dockerfile" -t "$tag" "$repo" \
  >"$store/build.log" 2>&1; then
  tail -n 30 "$store/build.log"
  die "podman build failed: $store/build.log"
fi
t_build=$(($(date +%s) - t0))
say "built in ${t_build} s"

# ---- 3. lean ----------------------------------------------------------------------
bytes=$(pm image inspect --format '{{.Size}}' "$tag")
added_mb=$(((bytes - base_bytes) / 1000000))
say "image $((bytes / 1000000)) MB: the base's $((base_bytes / 1000000)) MB + ${added_mb} MB"
mnt=$(pm image mount "$tag") || die "podman image mount failed"
[ -x "$mnt/usr/local/bin/raysweepd" ] || die "the image has no /usr/local/bin/raysweepd"
dev=$(chroot "$mnt" dpkg-query -W -f '${Package}\n' | grep -E -- '-dev$|^(gcc|g\+\+|cpp|clang|make|build-essential)(-[0-9.]+)?$' || true)
[ -z "$dev" ] || die "the runtime image has build packages: $(echo $dev)"
for t in gcc cc cpp clang make ld; do
  [ ! -e "$mnt/usr/bin/$t" ] || die "the runtime image has /usr/bin/$t"
done
max=${RSW_CONTAINER_MAX_MB:-150}
[ "$added_mb" -le "$max" ] || die "the runtime stage adds ${added_mb} MB to the base (at most $max MB)"

# ---- 4. run it in a chroot ---------------------------------------------------------
# The image's layers are read-only: a tmpfs for /tmp (and the blobs), /proc
# and /dev for the daemon, all in this namespace only.
mount -t tmpfs -o size=256m,mode=1777 tmpfs "$mnt/tmp" && mounts+=("$mnt/tmp")
mount -t proc proc "$mnt/proc" && mounts+=("$mnt/proc")
mount --bind /dev "$mnt/dev" && mounts+=("$mnt/dev")
in_image() { chroot --userspec=10001:10001 "$mnt" /usr/bin/env -i HOME=/tmp LANG=C.UTF-8 PATH=/usr/local/bin:/usr/bin:/bin "$@"; }
ver=$(in_image raysweepd version 2>&1) || die "raysweepd version in the image: $ver"
say "raysweepd version: $(head -n 1 <<<"$ver")"
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
# exec: $! is the daemon itself (chroot and env exec), so the TERM below
# reaches it; 8>&-: it does not hold this script's lock.
(exec chroot --userspec=10001:10001 "$mnt" /usr/bin/env -i HOME=/tmp LANG=C.UTF-8 PATH=/usr/local/bin:/usr/bin:/bin \
  raysweepd serve --listen "127.0.0.1:$port" --blob-dir /tmp/blobs) >"$store/serve.log" 2>&1 8>&- &
daemon=$!
for _ in $(seq 1 300); do
  grep -q "listening on http://127.0.0.1:$port" "$store/serve.log" && break
  kill -0 "$daemon" 2>/dev/null || break
  sleep 0.1
done
grep -q "listening on http://127.0.0.1:$port" "$store/serve.log" ||
  die "raysweepd serve in the image did not listen: $(tail -n 5 "$store/serve.log")"
grep -q "embedded default" "$store/serve.log" || die "serve did not load the embedded default scene: $(cat "$store/serve.log")"
url=http://127.0.0.1:$port
in_image curl -fsS -o /dev/null --max-time 2 "$url/v1/health/live" || die "the image's HEALTHCHECK (curl /v1/health/live) failed"
id=$(in_image curl -fsS "$url/v1/scenes" | sed 's/.*"id":"\([0-9a-f]*\)".*/\1/')
film=$(in_image curl -fsS -X POST "$url/v1/scenes/$id:render" -H 'Content-Type: application/json' -d '{"spp": 16, "seed": 1}') ||
  die "the render of the embedded scene failed"
check=$(python3 -c '
import json, math, sys
f = json.loads(sys.stdin.read())
w, h, c = f["width"], f["height"], len(f["channels"])
d = f["data"]
assert (w, h) == (32, 32), ("film size", w, h)
assert len(d) == w * h * c, ("data length", len(d), w, h, c)
assert all(math.isfinite(x) and x >= 0 for x in d), "a value is negative or not finite"
assert max(d) > 0, "all zero"
print(f"{w}x{h}x{c} film, values in [{min(d):.4g}, {max(d):.4g}]")
' <<<"$film" 2>&1) || die "the render from the image is wrong: $check"
say "render: $check"
kill -TERM "$daemon"
for _ in $(seq 1 100); do kill -0 "$daemon" 2>/dev/null || break; sleep 0.1; done
! kill -0 "$daemon" 2>/dev/null || die "the daemon in the image did not stop on SIGTERM"
daemon=
grep -q "shutting down" "$store/serve.log" || die "the daemon in the image did not say it was shutting down: $(tail -n 3 "$store/serve.log")"
pgrep -u 10001 -x raysweepd >/dev/null && die "a raysweepd of the image's user is still running after the TERM" 
echo "container: PASS ($(($(date +%s) - start)) s; podman build ${t_build} s; image $((bytes / 1000000)) MB, the runtime stage adds ${added_mb} MB to debian:12)"
