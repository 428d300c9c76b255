#!/usr/bin/env bash
# tools/deps.sh's package sets and its wait for the package manager's lock
# (issue 24, the first hour): `./make run` (the build set) installs no test
# or cluster tool, `make test` adds the browser but no Slurm, `make
# test-cluster` the balancers and Slurm; the Makefile asks for each set
# where it is needed; a held dpkg lock is waited for (with a line saying
# so), not a failure. apt-get, dpkg-query and sudo are stand-ins on PATH:
# nothing is installed. Ends with "test_deps: N passed, N failed".
set -u
name=test_deps
# shellcheck source=../support/shtest.sh
. "$(dirname "$0")/../support/shtest.sh"
deps=$root/tools/deps.sh

set_of() { "$deps" --list "$@" | tr '\n' ' '; }
has() { grep -qw -- "$2" <<<" $1 "; }

run_set=$(set_of)
for p in build-essential libembree-dev libmicrohttpd-dev; do
  has "$run_set" "$p" && ok || bad "the build set lacks $p: $run_set"
done
for p in chromium slurm-wlm munge nginx haproxy clang-format python3-xarray podman clang; do
  has "$run_set" "$p" && bad "the build set (./make run) installs $p: $run_set" || ok
done
test_set=$(set_of test)
for p in build-essential chromium curl python3-jsonschema clang-format; do
  has "$test_set" "$p" && ok || bad "the test set lacks $p: $test_set"
done
for p in slurm-wlm munge nginx haproxy podman; do
  has "$test_set" "$p" && bad "the test set installs the cluster tool $p: $test_set" || ok
done
cluster_set=$(set_of cluster)
for p in slurm-wlm munge nginx haproxy; do
  has "$cluster_set" "$p" && ok || bad "the cluster set lacks $p: $cluster_set"
done
has "$cluster_set" chromium && bad "the cluster set installs chromium: $cluster_set" || ok
has "$(set_of container)" podman && ok || bad "the container set lacks podman"
# make bench's scale_out line puts haproxy in front of replicas: the bench
# set has it (a fresh machine's `make bench` stopped there), and no Slurm
# or browser.
bench_set=$(set_of bench)
for p in haproxy python3; do
  has "$bench_set" "$p" && ok || bad "the bench set lacks $p: $bench_set"
done
for p in slurm-wlm munge chromium; do
  has "$bench_set" "$p" && bad "the bench set installs $p: $bench_set" || ok
done
# Each package once, whatever the sets asked for.
dups=$("$deps" --list test cluster container bench | sort | uniq -d)
[ -z "$dups" ] && ok || bad "packages listed twice: $dups"
"$deps" --list bogus >/dev/null 2>"$tmp/err" && bad "an unknown set was accepted" ||
  { grep -q "unknown package set 'bogus'" "$tmp/err" && ok || bad "unknown set: $(cat "$tmp/err")"; }

# The Makefile: compiles wait for the build set; make test, make
# test-cluster and make run ask for their own sets (make -n shows the
# commands without running them).
mk() { env -u MAKEFLAGS -u MFLAGS -u MAKELEVEL make -n -C "$root" "$@" 2>/dev/null; }
out=$(mk deps-test)
grep -qx 'tools/deps.sh test' <<<"$out" && ok || bad "make deps-test does not run tools/deps.sh test: $out"
out=$(mk deps-cluster)
grep -qx 'tools/deps.sh cluster' <<<"$out" && ok || bad "make deps-cluster does not run tools/deps.sh cluster: $out"
grep -qE '^test: .*deps-test' "$root/Makefile" && ok || bad "make test does not depend on deps-test"
grep -qE '^test-cluster: .*deps-cluster' "$root/Makefile" && ok || bad "make test-cluster does not depend on deps-cluster"
out=$(mk deps-bench)
grep -qx 'tools/deps.sh bench' <<<"$out" && ok || bad "make deps-bench does not run tools/deps.sh bench: $out"
grep -qE '^bench: .*deps-bench' "$root/Makefile" && ok || bad "make bench does not depend on deps-bench"
grep -qE '^run: .*deps-(test|cluster)' "$root/Makefile" && bad "make run installs the test or cluster tools" || ok
grep -qE 'deps\.sh (test|cluster)' "$root/make" && bad "./make installs the test or cluster set itself" || ok

# The lock: stand-ins for dpkg-query (nothing installed), sudo (runs its
# arguments) and apt-get (refuses twice with apt's lock message, then
# succeeds, and records what it was asked).
fake=$tmp/fake
mkdir -p "$fake"
cat >"$fake/dpkg-query" <<'EOF'
#!/bin/sh
[ -f "$RSW_FAKE/installed" ] && for p in "$@"; do case $p in -*) ;; *) echo "$p ii ";; esac; done
exit 0
EOF
cat >"$fake/sudo" <<'EOF'
#!/bin/sh
exec "$@"
EOF
cat >"$fake/apt-get" <<'EOF'
#!/bin/sh
echo "$*" >>"$RSW_FAKE/calls"
n=$(cat "$RSW_FAKE/refusals" 2>/dev/null || echo 0)
if [ "$n" -gt 0 ]; then
  echo $((n - 1)) >"$RSW_FAKE/refusals"
  echo "E: Could not get lock /var/lib/dpkg/lock-frontend. It is held by process 4242 (apt-get)" >&2
  echo "E: Unable to acquire the dpkg frontend lock (/var/lib/dpkg/lock-frontend), is another process using it?" >&2
  exit 100
fi
case " $* " in *" install "*) touch "$RSW_FAKE/installed" ;; esac
exit 0
EOF
chmod +x "$fake"/*
echo 2 >"$fake/refusals"
t0=$SECONDS
if RSW_FAKE=$fake PATH=$fake:$PATH RSW_DEPS_LOCK_WAIT=60 "$deps" >"$tmp/lock.out" 2>&1; then
  ok
else
  bad "deps.sh failed while the lock was held for two tries: $(cat "$tmp/lock.out")"
fi
grep -q '^deps: waiting for the package manager.s lock' "$tmp/lock.out" && ok ||
  bad "no line says deps waits for the lock: $(cat "$tmp/lock.out")"
[ "$(grep -c 'waiting for' "$tmp/lock.out")" = 1 ] && ok || bad "the wait is said more than once"
grep -q 'held by process 4242' "$tmp/lock.out" && ok || bad "the wait does not say who holds the lock"
grep -q '^deps: installed ' "$tmp/lock.out" && ok || bad "deps did not end installed: $(cat "$tmp/lock.out")"
grep -q 'DPkg::Lock::Timeout=60 install' "$fake/calls" && ok || bad "apt-get install without DPkg::Lock::Timeout: $(cat "$fake/calls")"
[ $((SECONDS - t0)) -ge 8 ] && ok || bad "the two refusals were not waited out (5 s apart)"
# A lock held longer than the wait is a failure that says so.
rm -f "$fake/installed" "$fake/calls"
echo 1000 >"$fake/refusals"
if RSW_FAKE=$fake PATH=$fake:$PATH RSW_DEPS_LOCK_WAIT=1 "$deps" >"$tmp/lock2.out" 2>&1; then
  bad "deps.sh succeeded with the lock never released"
else
  grep -q 'FAILED: apt-get update did not work.*lock was held' "$tmp/lock2.out" && ok ||
    bad "a lock held too long: $(cat "$tmp/lock2.out")"
fi
finish
