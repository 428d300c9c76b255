#!/usr/bin/env bash
# sweep --format dataset (docs/client.md#sweep-datasets-netcdf-xarray): the
# sweep as DIR/dataset.nc alone, built from the daemon's EXRs, no file per
# film; checked against --format nc (JSON films, then the dataset):
#   - the Lambertian plate (mono, a sun), an RGB scene (channels the EXR
#     stores B, G, R; context ids out of order) and the plate with brdf,
#     brf and radiance_stderr planes:
#     dataset.nc is --format nc's byte for byte (and, with xarray, the same
#     variables, coords and values); DIR holds dataset.nc, index.jsonl and
#     sweep.json only; index.jsonl is --format nc's but for "dataset":
#     "dataset.nc" in place of "file"; sweep.json says "output": "dataset";
#   - --spread 2 over two daemons behind a balancer: the same dataset;
#   - RAYSWEEP_DATASET_MEMORY=0 (every film in the film store's file) and
#     a budget of one film (--format nc): the same datasets; a bad value is
#     a usage error naming it, before anything is created;
#   - resume: a --spread run stopped (SIGTERM) after some contexts leaves its
#     journal and its spool (sweep.films), no dataset; a film spooled twice
#     is taken once, a partial record at the spool's end (a write cut
#     short) is dropped, and the rerun resumes
#     (films of the earlier run not fetched again) to the whole sweep's
#     dataset, spool and journal removed; a spool gone missing is refused
#     (naming sweep.films and --force), and --force starts over;
#   - --force over a finished dataset sweep removes dataset.nc, index.jsonl
#     and sweep.json and keeps a file no sweep wrote;
#   - merge of a dataset sweep, --shard and --layout with --format dataset
#     are usage errors (exit 2) naming what to do, and create nothing.
name=test_sweep_dataset
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd raysweep
need_cmd python3 "for the balancer and the checks"
scene="$root/proto/examples/hdistant_lambertian.json"
start_spread_pair # $pa, $pb and the balancer $plb

rs() { "$bin/raysweep" -q --server "http://127.0.0.1:$1" "${@:2}"; }
# like_nc LABEL NC DIR: DIR is a dataset sweep of what NC (a --format nc
# directory) swept: the same dataset.nc bytes, the same index but for
# "file", nothing else but sweep.json (the films' store, a file without a
# name, left nothing).
like_nc() {
  if cmp -s "$2/dataset.nc" "$3/dataset.nc"; then ok; else bad "$1: dataset.nc differs from --format nc's"; fi
  py "$1: the directory and its index" '
import json, os, sys
ref, d = sys.argv[1], sys.argv[2]
got = sorted(os.listdir(d))
assert got == ["dataset.nc", "index.jsonl", "sweep.json"], got
a = [json.loads(l) for l in open(os.path.join(ref, "index.jsonl"))]
b = [json.loads(l) for l in open(os.path.join(d, "index.jsonl"))]
assert len(a) == len(b) and a, f"{len(a)} films in --format nc, {len(b)} here"
for x, y in zip(a, b):
    x.pop("file")
    assert y.pop("dataset") == "dataset.nc" and "file" not in y, y
    assert x == y, f"index lines differ: {x} / {y}"
m = json.load(open(os.path.join(d, "sweep.json")))
assert m.get("output") == "dataset" and m["finished"], m
' "$2" "$3"
}

grid=(--grid wavelength=400:470:10 --spp 16 --seed 3 --bundle 1)
cd "$tmp" || finish

# ---- against --format nc ----
rs "$pa" sweep "$scene" "${grid[@]}" --format nc -o nc 2>"$tmp/err" || bad "--format nc: $(cat "$tmp/err")"
rs "$pa" sweep "$scene" "${grid[@]}" --format dataset -o ds 2>"$tmp/err" || bad "--format dataset: $(cat "$tmp/err")"
like_nc "mono, a sun" nc ds
py "the EXR answers carry the sun's angles" '
import json, sys
meta = json.load(open(sys.argv[1]))["meta"]
assert "sun_zenith_deg" in meta, sorted(meta)
' nc/c00000/sensor.json
if /usr/bin/python3 -c 'import xarray, netCDF4' 2>/dev/null; then
  need_xarray
  ds "xarray: the same variables, coords and values" same nc/dataset.nc ds/dataset.nc
fi
rgb="$root/proto/examples/hdistant_seed.xml"
printf '%s\n' '{"id": "z1", "seed": 1}' '{"id": "a2", "seed": 2}' '{"id": "m3", "seed": 3}' >rgb.jsonl
rs "$pa" sweep "$rgb" --contexts rgb.jsonl --spp 4 --format nc -o rgb_nc 2>"$tmp/err" ||
  bad "rgb, nc: $(cat "$tmp/err")"
rs "$pa" sweep "$rgb" --contexts rgb.jsonl --spp 4 --format dataset -o rgb_ds 2>"$tmp/err" ||
  bad "rgb, dataset: $(cat "$tmp/err")"
like_nc "rgb" rgb_nc rgb_ds
planes=(--grid wavelength=500:520:10 --spp 8 --quantities brdf,brf --variance)
rs "$pa" sweep "$scene" "${planes[@]}" --format nc -o pl_nc 2>"$tmp/err" || bad "planes, nc: $(cat "$tmp/err")"
rs "$pa" sweep "$scene" "${planes[@]}" --format dataset -o pl_ds 2>"$tmp/err" ||
  bad "planes, dataset: $(cat "$tmp/err")"
like_nc "brdf, brf, radiance_stderr" pl_nc pl_ds

# ---- the films past RAYSWEEP_DATASET_MEMORY in a file without a name ----
RAYSWEEP_DATASET_MEMORY=0 rs "$pa" sweep "$scene" "${grid[@]}" --format dataset -o ds_store 2>"$tmp/err" ||
  bad "--format dataset, no memory budget: $(cat "$tmp/err")"
like_nc "--format dataset, every film in the store" nc ds_store
RAYSWEEP_DATASET_MEMORY=20000 rs "$pa" sweep "$scene" "${planes[@]}" --format nc -o pl_store 2>"$tmp/err" ||
  bad "--format nc, a film on the heap, the rest in the store: $(cat "$tmp/err")"
cmp -s pl_nc/dataset.nc pl_store/dataset.nc && ok || bad "--format nc with the store: another dataset"
RAYSWEEP_DATASET_MEMORY=0 rs "$plb" sweep "$scene" "${grid[@]}" --format dataset --spread 2 -o spread_store \
  2>"$tmp/err" || bad "--spread 2, every film in the store: $(cat "$tmp/err")"
like_nc "--spread 2, every film in the store" nc spread_store
RAYSWEEP_DATASET_MEMORY=lots expect 2 "a bad RAYSWEEP_DATASET_MEMORY" rs "$pa" sweep "$scene" "${grid[@]}" \
  --format dataset -o bad_mem
contains "the error names RAYSWEEP_DATASET_MEMORY" "$tmp/err" "RAYSWEEP_DATASET_MEMORY needs a number of bytes (got 'lots')"
[ ! -e bad_mem ] && ok || bad "a bad RAYSWEEP_DATASET_MEMORY created bad_mem"

# ---- --spread over two daemons ----
rs "$plb" sweep "$scene" "${grid[@]}" --format dataset --spread 2 -o spread 2>"$tmp/err" ||
  bad "--spread 2: $(cat "$tmp/err")"
like_nc "--spread 2" nc spread

# ---- resume an interrupted --spread run ----
slow=(--grid wavelength=400:595:5 --spp 1024 --seed 5)
rs "$pa" sweep "$scene" "${slow[@]}" --format nc -o slow_nc 2>"$tmp/err" || bad "slow ref: $(cat "$tmp/err")"
"$bin/raysweep" -q --server "http://127.0.0.1:$plb" sweep "$scene" "${slow[@]}" --format dataset --spread 2 \
  -o cut 2>"$tmp/cut.err" &
sweep_pid=$!
for _ in $(seq 600); do
  n=$(grep -c '"context"' cut/sweep.spread.jsonl 2>/dev/null)
  [ "${n:-0}" -ge 2 ] && break
  sleep 0.02
done
kill -TERM "$sweep_pid"
wait "$sweep_pid"
rc=$?
done_n=$(grep -c '"context"' cut/sweep.spread.jsonl)
if [ "$rc" -eq 143 ] && [ "$done_n" -ge 2 ] && [ "$done_n" -lt 40 ]; then ok; else
  bad "stopped run: exit $rc (wanted 143), $done_n contexts journaled (wanted 2-39): $(cat "$tmp/cut.err")"
fi
[ -s cut/sweep.films ] && [ ! -e cut/dataset.nc ] && ok || bad "stopped run: $(ls cut | tr '\n' ' ')"
cp -a cut cut_nospool
cp -a cut cut_force
# the spool's first film once more (a film spooled again, as when a run is
# killed between its spool record and its journal line: the resumed
# dataset is then built again from the films kept, the last of each), and
# a record cut short at its end (dropped on resume)
py "a film spooled twice" '
import struct, sys
b = open(sys.argv[1], "rb").read()
assert b[:4] == b"RSF1", b[:4]
hl, bl = struct.unpack("<IQ", b[4:16])
open(sys.argv[1], "ab").write(b[:16 + hl + bl])
' cut/sweep.films
printf 'RSF1\x40\x00\x00\x00' >>cut/sweep.films
"$bin/raysweep" --server "http://127.0.0.1:$plb" sweep "$scene" "${slow[@]}" --format dataset --spread 2 -o cut \
  >/dev/null 2>"$tmp/err"
rc=$?
[ "$rc" -eq 0 ] && ok || bad "resume: exit $rc: $(cat "$tmp/err")"
contains "resume: films of the earlier run" "$tmp/err" "from an earlier run"
like_nc "resumed --spread" slow_nc cut
# without the spool the journal cannot be trusted
rm cut_nospool/sweep.films
expect 6 "resume without the spool" rs "$plb" sweep "$scene" "${slow[@]}" --format dataset --spread 2 -o cut_nospool
contains "resume without the spool: the error says why" "$tmp/err" "does not hold it (start over with --force)"
# --force over the stopped run starts over (spool and journal removed first)
touch cut_force/notes.txt
expect 0 "--force over a stopped dataset run" rs "$plb" sweep "$scene" "${grid[@]}" --format dataset --spread 2 \
  --force -o cut_force
got=$(cd cut_force && ls -A | LC_ALL=C sort | tr '\n' ' ')
[ "$got" = 'dataset.nc index.jsonl notes.txt sweep.json ' ] && ok || bad "--force over a stopped run: left '$got'"
if cmp -s cut_force/dataset.nc nc/dataset.nc; then ok; else bad "--force over a stopped run: another dataset"; fi

# ---- --force over a finished dataset sweep ----
touch ds/notes.txt
expect 0 "--force over a dataset sweep" rs "$pa" sweep "$scene" --grid wavelength=500:500:1 --spp 4 --format exr \
  --force -o ds
got=$(cd ds && ls -A | LC_ALL=C sort | tr '\n' ' ')
[ "$got" = 'c00000 index.jsonl notes.txt sweep.json ' ] && ok || bad "--force over a dataset sweep: left '$got'"

# ---- what --format dataset refuses ----
expect 2 "merge of a dataset sweep" rs "$pa" merge spread -o merged
contains "merge: the error names --format dataset" "$tmp/err" "was swept with --format dataset"
[ ! -e merged ] && ok || bad "the refused merge created merged"
expect 2 "--format dataset --shard" rs "$pa" sweep "$scene" "${grid[@]}" --format dataset --shard 0/2 -o bad_shard
contains "--shard: the error names it" "$tmp/err" "--shard: --format dataset writes the sweep as one dataset"
[ ! -e bad_shard ] && ok || bad "--format dataset --shard created bad_shard"
expect 2 "--format dataset --layout flat" rs "$pa" sweep "$scene" "${grid[@]}" --format dataset --layout flat \
  -o bad_layout
contains "--layout: the error names it" "$tmp/err" "--layout: --format dataset writes no film files"
[ ! -e bad_layout ] && ok || bad "--format dataset --layout created bad_layout"
expect 2 "--format cdf" rs "$pa" sweep "$scene" "${grid[@]}" --format cdf -o bad_fmt
contains "--format cdf: the error lists dataset" "$tmp/err" "--format needs exr, npy, json, nc or dataset (got 'cdf')"
finish
