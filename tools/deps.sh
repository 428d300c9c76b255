#!/usr/bin/env bash
# Installs the Debian 12 packages raysweep needs, when any is missing, by
# set. `tools/deps.sh [SET...]` installs the build set and each SET named:
#
#   build    (always) compiling and running: `make`, `make run`, ./make
#   test     `make test`: the test scripts' tools, the headless browser
#   cluster  `make test-cluster`: the balancers and a single-node Slurm
#   container  tests/container/run.sh (.ci/run): podman
#   bench    `make bench`: haproxy for the scale_out line
#   fuzz     `make fuzz`: clang with libFuzzer's runtime
#
# `tools/deps.sh --list [SET...]` prints the packages, one a line, and
# installs nothing (tests/integration/test_deps.sh checks the sets).
# The Makefile runs it before compiling (`make deps`: build), before the
# tests (`make deps-test`), before the cluster tests (`make deps-cluster`),
# before the benchmarks (`make deps-bench`).
# Costs one dpkg-query and no network when everything is there. Otherwise
# it runs `apt-get update` and `apt-get install` (as root, or through sudo),
# waiting up to RSW_DEPS_LOCK_WAIT seconds (default 600) for the dpkg and
# apt locks when another apt or dpkg holds them, checks again, and exits
# non-zero, naming what is still missing, when the install did not work.
set -euo pipefail

build=(
  # make, cc, ar, nm; the libraries raysweepd and libraysweep link
  build-essential pkg-config libembree-dev libopenexr-dev libmicrohttpd-dev
  libcjson-dev libcurl4-openssl-dev libexpat1-dev libssl-dev libnetcdf-dev libpng-dev
  libjpeg62-turbo-dev
)
test=(
  # curl and python3 (integration scripts, docs examples); python3-yaml
  # and python3-jsonschema (tests/openapi/check.py); clang-format (make
  # format, tools/check-format.sh); groff-base and man-db (the man pages are
  # checked with groff and read back with man: test_usage, test_install);
  # chromium (test_viewer drives the web viewer in it, headless)
  curl python3 python3-yaml python3-jsonschema clang-format groff-base man-db chromium
  # python3-xarray, python3-netcdf4 and python3-numpy read the sweep datasets
  # back (tests/integration/test_dataset.sh)
  python3-xarray python3-netcdf4 python3-numpy
  # the Python package (venv, offline pip build) and its notebook
  # (tests/integration/test_python.sh)
  python3-venv python3-setuptools python3-wheel python3-nbconvert python3-ipykernel python3-tqdm
)
cluster=(
  # the load balancers in front of replicas (run as the current user with
  # configurations in a temp directory), and a single-node Slurm (slurmctld,
  # slurmd, sbatch) with its authentication daemon (tests/cluster); curl and
  # python3 drive them; python3-yaml reads the compose and Kubernetes files
  # (test_containers.sh)
  haproxy nginx slurm-wlm munge curl python3 python3-yaml
)
bench=(
  # make bench: haproxy in front of the scale_out line's replicas
  # (tests/bench/bench_scale_out.py); python3 runs the bench scripts
  haproxy python3
)
container=(
  # podman builds docker/Dockerfile (tests/container/run.sh)
  podman curl python3
)
fuzz=(
  # clang with libFuzzer's runtime (make fuzz)
  clang libclang-rt-14-dev
)

list=0
if [ "${1:-}" = --list ]; then
  list=1
  shift
fi
pkgs=("${build[@]}")
for set in "$@"; do
  case $set in
  build) ;;
  test) pkgs+=("${test[@]}") ;;
  cluster) pkgs+=("${cluster[@]}") ;;
  container) pkgs+=("${container[@]}") ;;
  bench) pkgs+=("${bench[@]}") ;;
  fuzz) pkgs+=("${fuzz[@]}") ;;
  *)
    echo "deps: unknown package set '$set' (one of build, test, cluster, container, fuzz, bench)" >&2
    exit 2
    ;;
  esac
done
mapfile -t pkgs < <(printf '%s\n' "${pkgs[@]}" | awk '!seen[$0]++')
if [ $list = 1 ]; then
  printf '%s\n' "${pkgs[@]}"
  exit 0
fi

missing() {
  # One dpkg-query for all: a package it does not know is not listed (stderr).
  local installed
  installed=$(dpkg-query -W -f='${Package} ${db:Status-Abbrev}\n' "${pkgs[@]}" 2>/dev/null |
    awk '$2 == "ii" { print $1 }') || true
  local p
  for p in "${pkgs[@]}"; do
    grep -qx -- "$p" <<<"$installed" || printf '%s\n' "$p"
  done
}

mapfile -t todo < <(missing)
[ ${#todo[@]} -eq 0 ] && exit 0

echo "deps: installing ${todo[*]}" >&2
SUDO=()
if [ "$(id -u)" != 0 ]; then
  if command -v sudo >/dev/null; then
    SUDO=(sudo)
  else
    echo "deps: FAILED: ${todo[*]} missing, and you are not root and sudo is not installed." >&2
    echo "deps: as root, run: apt-get update && apt-get install ${todo[*]}" >&2
    exit 1
  fi
fi

# apt CMD...: apt-get CMD, waiting while another apt or dpkg holds its
# locks. apt-get install waits by itself (DPkg::Lock::Timeout); apt-get
# update does not for the lists lock, so a refusal that names a lock is
# retried every 5 s, with one line saying who holds it, until the wait is
# over.
wait_s=${RSW_DEPS_LOCK_WAIT:-600}
apt() {
  local t0=$SECONDS out rc said=0
  while :; do
    out=$(mktemp)
    rc=0
    DEBIAN_FRONTEND=noninteractive "${SUDO[@]}" apt-get -o DPkg::Lock::Timeout="$wait_s" "$@" 2>"$out" >&2 || rc=$?
    if [ $rc -ne 0 ] && grep -qiE 'could not get lock|unable to acquire the dpkg frontend lock|unable to lock' "$out" &&
      [ $((SECONDS - t0)) -lt "$wait_s" ]; then
      if [ $said = 0 ]; then
        echo "deps: waiting for the package manager's lock (another apt or dpkg is running; up to ${wait_s} s): $(grep -iE -m1 'lock' "$out")" >&2
        said=1
      fi
      rm -f "$out"
      sleep 5
      continue
    fi
    cat "$out" >&2
    rm -f "$out"
    return $rc
  done
}

if ! apt update -qq; then
  echo "deps: FAILED: apt-get update did not work (no network, no Debian mirror in /etc/apt/sources.list, or the lock was held for ${wait_s} s?)" >&2
  exit 1
fi
if ! apt install -y -qq --no-install-recommends "${todo[@]}"; then
  echo "deps: FAILED: apt-get install ${todo[*]} did not work (see above)" >&2
  exit 1
fi
mapfile -t still < <(missing)
if [ ${#still[@]} -gt 0 ]; then
  echo "deps: FAILED: still not installed after apt-get install: ${still[*]}" >&2
  exit 1
fi
echo "deps: installed ${todo[*]}" >&2
