#!/usr/bin/env bash
# The examples written twice (proto/README.md), each pair read by
# `raysweepd render` into bitwise the same film: hdistant_seed.xml and
# roughconductor_3suns.json (16 spp, seed 3), cornell_box.xml and
# cornell_box.json (8 spp, and the XML's $res at its default, 128, and
# set with -D res=64, against the JSON with its film's width and height
# set to 64). The XML twins are what Mitsuba reads in make bench's peer
# lines (tests/bench/bench_peer.py), so a twin that drifts from its JSON
# would compare different scenes.
# Ends with "test_example_twins: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_example_twins
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd python3 "to write the 64x64 JSON scene"
cd "$tmp" || exit 1
ex=$root/proto/examples

# twin LABEL A B [ARGS...]: A and B render to the same bytes.
twin() {
  local label=$1 a=$2 b=$3
  shift 3
  if "$bin/raysweepd" render "$a" "$@" --threads 2 -o a.exr >/dev/null 2>err &&
    "$bin/raysweepd" render "$b" "$@" --threads 2 -o b.exr >/dev/null 2>>err; then
    if cmp -s a.exr b.exr; then ok; else bad "$label: the films differ"; fi
  else
    bad "$label: $(head -c 400 err)"
  fi
}
twin "seed: hdistant_seed.xml and roughconductor_3suns.json" "$ex/hdistant_seed.xml" \
  "$ex/roughconductor_3suns.json" --spp 16 --seed 3
twin "Cornell box: cornell_box.xml and cornell_box.json" "$ex/cornell_box.xml" "$ex/cornell_box.json" --spp 8
python3 - "$ex/cornell_box.json" cornell64.json <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
d["camera"]["film"]["width"] = d["camera"]["film"]["height"] = 64
json.dump(d, open(sys.argv[2], "w"))
PY
"$bin/raysweepd" render cornell64.json --spp 8 --threads 2 -o b.exr >/dev/null 2>err &&
  "$bin/raysweepd" render "$ex/cornell_box.xml" -D res=64 --spp 8 --threads 2 -o a.exr >/dev/null 2>>err ||
  bad "Cornell box at 64x64: $(head -c 400 err)"
if cmp -s a.exr b.exr; then ok; else bad "cornell_box.xml -D res=64 and the JSON at 64x64 differ"; fi
finish
