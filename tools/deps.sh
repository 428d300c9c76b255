#!/usr/bin/env bash
# Installs the Debian 12 packages raysweep builds and tests with, when any is
# missing: `make deps`, every `make` (it runs first) and ./make (which runs it
# before make exists). Costs one dpkg-query and no network when everything
# is there. Otherwise it runs `apt-get update` and `apt-get install` (as root,
# or through sudo), checks again, and exits non-zero, naming what is still
# missing, when the install did not work.
set -euo pipefail
pkgs=(
  # build: make, cc, ar, nm; the libraries
  build-essential pkg-config libembree-dev libopenexr-dev libmicrohttpd-dev
  libcjson-dev libcurl4-openssl-dev libexpat1-dev libssl-dev libnetcdf-dev libpng-dev
  # tests: curl and python3 (integration scripts, docs examples); python3-yaml
  # and python3-jsonschema (tests/openapi/check.py); clang-format (make
  # format, tools/check-format.sh); groff-base and man-db (the man pages are
  # checked with groff and read back with man: test_usage, test_install);
  # chromium (test_viewer drives the web viewer in it, headless)
  curl python3 python3-yaml python3-jsonschema clang-format groff-base man-db chromium
  # python3-xarray, python3-netcdf4 and python3-numpy read the sweep datasets
  # back (tests/integration/test_dataset.sh)
  python3-xarray python3-netcdf4 python3-numpy
  # test: the Python package (venv, offline pip build) and its notebook (tests/integration/test_python.sh)
  python3-venv python3-setuptools python3-wheel python3-nbconvert python3-ipykernel python3-tqdm
  # make test-cluster: the load balancers in front of replicas (run as the
  # current user with configurations in a temp directory), and a
  # single-node Slurm (slurmctld, slurmd, sbatch) with its authentication
  # daemon (tests/cluster/test_slurm.sh)
  haproxy nginx slurm-wlm munge
)
# build: libjpeg for bitmap textures from JPEG files (server/kernel/image_ldr.c)
pkgs+=(libjpeg62-turbo-dev)
# `tools/deps.sh fuzz` (make fuzz): clang with libFuzzer's runtime as well.
if [ "${1:-}" = fuzz ]; then
  pkgs+=(clang libclang-rt-14-dev)
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
if ! "${SUDO[@]}" apt-get update -qq >&2; then
  echo "deps: FAILED: apt-get update did not work (no network, or no Debian mirror in /etc/apt/sources.list?)" >&2
  exit 1
fi
if ! DEBIAN_FRONTEND=noninteractive "${SUDO[@]}" apt-get install -y -qq --no-install-recommends "${todo[@]}" >&2; then
  echo "deps: FAILED: apt-get install ${todo[*]} did not work (see above)" >&2
  exit 1
fi
mapfile -t still < <(missing)
if [ ${#still[@]} -gt 0 ]; then
  echo "deps: FAILED: still not installed after apt-get install: ${still[*]}" >&2
  exit 1
fi
echo "deps: installed ${todo[*]}" >&2
