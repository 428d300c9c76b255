#!/usr/bin/env bash
# The command-line help, the version and the usage text agree everywhere:
#  - `raysweepd COMMAND --help` (every command), `raysweepd --help`,
#    `raysweep --help`, `raysweep COMMAND --help`, `raysweepd --version`
#    and `raysweep --version` exit 0 with their text on stdout and nothing
#    on stderr;
#  - one version: include/raysweep/version.h is the only place that defines
#    it (no other RSW_VERSION definition, no version literal in the sources
#    or the Makefile), and `raysweepd version`, `raysweepd --version`,
#    `raysweep --version` and GET /v1's "version" all report it;
#  - every usage entry of the usage blocks of README.md and docs/*.md and of
#    the man pages'
#    SYNOPSIS (docs/man/raysweepd.1, raysweep.1) equals, whitespace
#    collapsed, the usage lines of the matching `PROG COMMAND --help`, and
#    both list exactly the commands `PROG --help` lists;
#  - the man pages format without groff warnings (when groff is installed).
# Environment: RSW_BIN_DIR (default build/bin). Ends with the summary line
# "test_usage: N passed, N failed" that tests/run.sh sums.
set -u
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root" || exit 1
bin=${RSW_BIN_DIR:-build/bin}
case $bin in /*) ;; *) bin=$root/$bin ;; esac
tool=(python3 "$root/tests/support/docs_check.py")

name=test_usage
source "$root/tests/support/shtest.sh"

# helps NAME CMD...: CMD exits 0, prints something on stdout and nothing on
# stderr; its stdout is left in $tmp/out.
helps() {
  local name=$1 rc
  shift
  "$@" >"$tmp/out" 2>"$tmp/err"
  rc=$?
  if [ "$rc" -ne 0 ]; then
    bad "$name: exit $rc (want 0): $(head -c 300 "$tmp/err")"
  elif [ ! -s "$tmp/out" ]; then
    bad "$name: nothing on stdout"
  elif [ -s "$tmp/err" ]; then
    bad "$name: wrote to stderr: $(head -c 300 "$tmp/err")"
  else
    ok
    return 0
  fi
  return 1
}

# ---- --help and --version exit 0 with usage on stdout ----------------------
for c in render params serve routes version; do
  if helps "raysweepd $c --help" "$bin/raysweepd" "$c" --help; then
    grep -q "^usage: raysweepd $c" "$tmp/out" && ok || bad "raysweepd $c --help: no 'usage: raysweepd $c' line"
  fi
  helps "raysweepd help $c" "$bin/raysweepd" help "$c"
done
helps "raysweepd render -h" "$bin/raysweepd" render scene.json -h
helps "raysweepd --help" "$bin/raysweepd" --help
helps "raysweep --help" "$bin/raysweep" --help
helps "raysweep sweep --help" "$bin/raysweep" sweep --help

# ---- one version -------------------------------------------------------------
version=$(sed -n 's/^#define RSW_VERSION "\([^"]*\)"$/\1/p' include/raysweep/version.h)
if [ -z "$version" ]; then
  bad "include/raysweep/version.h defines no RSW_VERSION"
  finish
fi
ok
defs=$(grep -rn --include='*.[ch]' '#define RSW_VERSION\b' server client include tests | grep -v '^include/raysweep/version.h:')
[ -z "$defs" ] && ok || bad "RSW_VERSION is defined outside include/raysweep/version.h: $defs"
lits=$(grep -rnE '"[0-9]+\.[0-9]+\.[0-9]+"|libraysweep/[0-9]|Version: [0-9]' server client Makefile)
[ -z "$lits" ] && ok || bad "a version is written out instead of taken from include/raysweep/version.h: $lits"
if helps "raysweepd version" "$bin/raysweepd" version; then
  [ "$(cat "$tmp/out")" = "raysweepd $version (variants: mono, rgb, mono_polarized, rgb_polarized)" ] && ok ||
    bad "raysweepd version: '$(cat "$tmp/out")', want raysweepd $version"
fi
if helps "raysweepd --version" "$bin/raysweepd" --version; then
  [ "$(cat "$tmp/out")" = "raysweepd $version (variants: mono, rgb, mono_polarized, rgb_polarized)" ] && ok ||
    bad "raysweepd --version: '$(cat "$tmp/out")', want raysweepd $version"
fi
if helps "raysweep --version" "$bin/raysweep" --version; then
  [ "$(cat "$tmp/out")" = "raysweep $version" ] && ok || bad "raysweep --version: '$(cat "$tmp/out")', want raysweep $version"
fi
start_daemon "$tmp/d" --threads 1
if [ -n "$started_port" ]; then
  info=$(curl -sS --fail-with-body "http://127.0.0.1:$started_port/v1")
  got=$(echo "$info" | sed -n 's/.*"version":"\([^"]*\)".*/\1/p')
  [ "$got" = "$version" ] && ok || bad "GET /v1 says version '$got', version.h says $version"
else
  bad "daemon: no port file after 10 s: $(tail -n 5 "$tmp/d/log")"
fi

# ---- the docs' usage blocks and man pages == --help ---------------------------
# compare PROG SOURCE ENTRIES_FILE: each entry equals `PROG WORDS --help`'s
# usage, and the entries name exactly the commands `PROG --help` lists.
compare() {
  local prog=$1 src=$2 list=$3 entry words help
  "$bin/$prog" --help | "${tool[@]}" listing "$prog" | sort >"$tmp/listed"
  : >"$tmp/documented"
  while IFS= read -r entry; do
    words=$(echo "$entry" | "${tool[@]}" words "$prog")
    [ -n "$words" ] || continue
    echo "$words" >>"$tmp/documented"
    # shellcheck disable=SC2086  # the command words are separate arguments
    help=$("$bin/$prog" $words --help 2>/dev/null | "${tool[@]}" help-entry "$prog")
    if [ "$help" = "$entry" ]; then ok; else
      bad "$src: the usage of '$prog $words' differs from \`$prog $words --help\`:
    $src:   $entry
    --help: $help"
    fi
  done <"$list"
  sort "$tmp/documented" -o "$tmp/documented"
  if cmp -s "$tmp/listed" "$tmp/documented"; then ok; else
    bad "$src documents other $prog commands than \`$prog --help\` lists: $(diff "$tmp/listed" "$tmp/documented" | grep '^[<>]' | tr '\n' ' ')"
  fi
}
for prog in raysweepd raysweep; do
  "${tool[@]}" usage "$prog" README.md docs/*.md >"$tmp/readme.$prog"
  [ -s "$tmp/readme.$prog" ] && ok || bad "README.md and docs/*.md have no usage block for $prog"
  compare "$prog" "README.md and docs/*.md" "$tmp/readme.$prog"
  page=docs/man/$prog.1
  if [ ! -f "$page" ]; then
    bad "$page is missing"
    continue
  fi
  "${tool[@]}" man "$prog" "$page" >"$tmp/man.$prog"
  [ -s "$tmp/man.$prog" ] && ok || bad "$page has no SYNOPSIS entries for $prog"
  compare "$prog" "$page" "$tmp/man.$prog"
  if command -v groff >/dev/null; then
    warn=$(groff -man -ww -z "$page" 2>&1)
    [ -z "$warn" ] && ok || bad "$page: groff warnings: $warn"
  else
    bad "groff is not installed (groff-base: make deps installs it)"
  fi
done

finish
