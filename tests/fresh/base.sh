# Sourced by tests/fresh/run.sh and tests/container/run.sh (as root, with
# say, die and $cache set): sets $base to a tarball of a clean bookworm root
# file system, debootstrap --variant=minbase plus git and ca-certificates,
# made once and cached in $cache for 30 days (its mirror: the host's, or
# RSW_FRESH_MIRROR).
# shellcheck shell=bash
if ! command -v debootstrap >/dev/null; then
  say "installing debootstrap"
  { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap; } >/dev/null ||
    die "cannot install debootstrap with apt-get"
fi
# The host's Debian mirror (deb.debian.org on the images CI runs on).
mirror=$(cat /etc/apt/sources.list /etc/apt/sources.list.d/*.list /etc/apt/sources.list.d/*.sources 2>/dev/null |
  grep -oE 'https?://[^ ]+/debian/?( |$)' | grep -v security | head -n 1 | tr -d ' ' || true)
mirror=${RSW_FRESH_MIRROR:-${mirror:-http://deb.debian.org/debian}}
arch=$(dpkg --print-architecture)
base=$cache/bookworm-minbase-git-$arch.tar
if [ -f "$base" ] && [ -z "$(find "$base" -mtime +30)" ]; then
  say "base: $base (cached $(date -r "$base" -u +%F))"
else
  say "debootstrap --variant=minbase --include=git,ca-certificates bookworm from $mirror"
  new=$cache/new.$$
  rm -rf --one-file-system "$new"
  if ! debootstrap --variant=minbase --include=git,ca-certificates bookworm "$new" "$mirror" >"$cache/debootstrap.log" 2>&1; then
    tail -n 5 "$cache/debootstrap.log"
    rm -rf --one-file-system "$new"
    die "debootstrap from $mirror failed (no network or no mirror?): $cache/debootstrap.log"
  fi
  tar -C "$new" --numeric-owner -cf "$base.new" . && mv "$base.new" "$base"
  rm -rf --one-file-system "$new"
  say "base cached in $base ($(du -h "$base" | cut -f1))"
fi

