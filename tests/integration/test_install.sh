#!/usr/bin/env bash
# `make install` installs a usable raysweep:
#  - PREFIX=DIR: DIR/bin/raysweepd and DIR/bin/raysweep (executable),
#    DIR/share/man/man1/raysweepd.1 and raysweep.1, the headers, the
#    libraries and DIR/lib/pkgconfig/raysweep.pc (prefix DIR, Version the
#    one in include/raysweep/version.h);
#  - the installed binaries run from there: `raysweepd version`,
#    `raysweep --version`, `raysweepd render --help`, a render, and the
#    installed `raysweep status` against the installed `raysweepd serve`;
#  - the installed man pages format (when man is installed);
#  - DESTDIR=STAGE PREFIX=/usr puts the same tree under STAGE/usr, with a
#    raysweep.pc that still says prefix=/usr.
# Environment: SAN=1 installs the sanitizer build. Ends with the summary
# line "test_install: N passed, N failed" that tests/run.sh sums.
set -u
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root" || exit 1

name=test_install
source "$root/tests/support/shtest.sh"
daemon=
version=$(sed -n 's/^#define RSW_VERSION "\([^"]*\)"$/\1/p' include/raysweep/version.h)

# The make variables of a `make test` that runs this script are dropped, so
# the inner make is a plain one (with SAN passed on).
inner_make() { env -u MAKEFLAGS -u MFLAGS -u MAKELEVEL make -s -C "$root" SAN="${SAN:-}" "$@"; }

expected_files="bin/raysweep
bin/raysweepd
include/raysweep/client.h
include/raysweep/plugin.h
include/raysweep/status.h
include/raysweep/version.h
lib/libraysweep.a
lib/libraysweep.so
lib/pkgconfig/raysweep.pc
share/man/man1/raysweep.1
share/man/man1/raysweepd.1"

# tree DIR: the installed files under DIR, relative, sorted.
tree() { (cd "$1" && find . -type f | sed 's|^\./||' | sort); }

# ---- PREFIX ------------------------------------------------------------------
prefix=$tmp/prefix
if inner_make install PREFIX="$prefix" >"$tmp/install.log" 2>&1; then ok; else
  bad "make install PREFIX=$prefix: $(tail -n 10 "$tmp/install.log")"
  finish
fi
got=$(tree "$prefix")
[ "$got" = "$expected_files" ] && ok || bad "make install PREFIX installed:
$got
want:
$expected_files"
for b in raysweepd raysweep; do
  [ -x "$prefix/bin/$b" ] && ok || bad "$prefix/bin/$b is not executable"
done
pc=$prefix/lib/pkgconfig/raysweep.pc
grep -qx "prefix=$prefix" "$pc" && ok || bad "raysweep.pc: no 'prefix=$prefix': $(head -n 1 "$pc")"
grep -qx "Version: $version" "$pc" && ok || bad "raysweep.pc: $(grep Version "$pc"), want Version: $version (version.h)"

# ---- the installed programs, from PATH ---------------------------------------
export PATH="$prefix/bin:$PATH"
[ "$(command -v raysweepd)" = "$prefix/bin/raysweepd" ] && ok || bad "raysweepd on PATH is $(command -v raysweepd)"
out=$(cd "$tmp" && raysweepd version 2>&1) && [ "$out" = "raysweepd $version (variants: mono, rgb, mono_polarized, rgb_polarized)" ] && ok ||
  bad "installed raysweepd version: $out"
out=$(cd "$tmp" && raysweep --version 2>&1) && [ "$out" = "raysweep $version" ] && ok ||
  bad "installed raysweep --version: $out"
out=$(cd "$tmp" && raysweepd render --help 2>&1) && [[ $out == "usage: raysweepd render "* ]] && ok ||
  bad "installed raysweepd render --help: $(echo "$out" | head -n 2)"
if (cd "$tmp" && raysweepd render "$root/proto/examples/hdistant_lambertian.json" --spp 4 --threads 1 -o plate.exr) \
  >"$tmp/render.log" 2>&1 && [ -s "$tmp/plate.exr" ]; then ok; else
  bad "installed raysweepd render: $(tail -n 3 "$tmp/render.log")"
fi
(cd "$tmp" && raysweepd serve --listen 127.0.0.1:0 --port-file "$tmp/port" --threads 1) >"$tmp/daemon.log" 2>&1 &
daemon=$!
pids+=("$daemon")
for _ in $(seq 100); do
  [ -s "$tmp/port" ] && break
  kill -0 "$daemon" 2>/dev/null || break
  sleep 0.1
done
if [ -s "$tmp/port" ]; then
  out=$(cd "$tmp" && raysweep --server "http://127.0.0.1:$(cat "$tmp/port")" status 2>&1)
  rc=$?
  [ "$rc" -eq 0 ] && [[ $out == *"$version"* ]] && ok ||
    bad "installed raysweep status against installed raysweepd serve: exit $rc: $out"
else
  bad "installed raysweepd serve: no port file after 10 s: $(tail -n 5 "$tmp/daemon.log")"
fi

# ---- the installed man pages ---------------------------------------------------
if command -v man >/dev/null; then
  for p in raysweepd raysweep; do
    out=$(MANPATH="$prefix/share/man" man -P cat "$p" 2>/dev/null | grep -c "^SYNOPSIS")
    [ "$out" = 1 ] && ok || bad "man $p (MANPATH=$prefix/share/man) shows no SYNOPSIS"
  done
else
  bad "man is not installed (man-db: make deps installs it)"
fi

# ---- DESTDIR: a staged tree for packaging ---------------------------------------
stage=$tmp/stage
if inner_make install DESTDIR="$stage" PREFIX=/usr >"$tmp/stage.log" 2>&1; then ok; else
  bad "make install DESTDIR=$stage PREFIX=/usr: $(tail -n 10 "$tmp/stage.log")"
  finish
fi
got=$(tree "$stage")
want=$(echo "$expected_files" | sed 's|^|usr/|')
[ "$got" = "$want" ] && ok || bad "make install DESTDIR installed:
$got
want:
$want"
grep -qx "prefix=/usr" "$stage/usr/lib/pkgconfig/raysweep.pc" && ok ||
  bad "DESTDIR raysweep.pc: $(head -n 1 "$stage/usr/lib/pkgconfig/raysweep.pc"), want prefix=/usr"
out=$("$stage/usr/bin/raysweep" --version 2>&1) && [ "$out" = "raysweep $version" ] && ok ||
  bad "staged raysweep --version: $out"

finish
