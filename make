#!/bin/sh
# ./make ARGS...: `make ARGS...`, also on a fresh Debian 12 that has no make
# or C compiler yet: when either is missing it first installs the packages
# building and running need (tools/deps.sh's build set: apt-get, as root or
# through sudo), then runs make with the same arguments in this directory
# (`make test` adds the tests' packages, `make test-cluster` the cluster's). Where make and cc are
# installed, `./make test` and `make test` are the same command.
set -e
cd "$(dirname "$0")"
if ! command -v make >/dev/null 2>&1 || ! command -v cc >/dev/null 2>&1; then
  echo "./make: make or cc is missing: installing the Debian packages first (tools/deps.sh)" >&2
  tools/deps.sh
fi
exec make "$@"
