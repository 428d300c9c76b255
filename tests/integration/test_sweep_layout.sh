#!/usr/bin/env bash
# sweep --layout flat (docs/client.md#sweep-directories): films as
# DIR/CONTEXT.SENSOR.EXT, no directory per context, on the Lambertian plate
# (mono), checked against the default layout (DIR/CONTEXT/SENSOR.EXT):
#   - each format (exr, npy, json, nc): no directory in DIR, every file
#     index.jsonl names is there, bit for bit the default layout's film,
#     index.jsonl the same but for "file", dataset.nc the same bytes;
#     sweep.json says "layout": "flat" (and the default's has no "layout");
#   - --shard 0/2 + 1/2 merged equals the whole flat sweep (films, index);
#     a flat shard and a default-layout shard of one sweep merge too (the
#     layout is not part of the sweep);
#   - --spread 2 over two daemons behind a balancer equals the whole sweep;
#   - resume: a --spread run stopped (SIGTERM) after some films is refused
#     with --layout dirs (exit 2 naming --layout), and the same command with
#     --layout flat resumes it (films of the earlier run kept, not fetched
#     again) to the whole sweep's films;
#   - --force over a stopped flat run (sweep.json but no index.jsonl)
#     removes its films, keeps a file no sweep wrote;
#   - odd context ids (a.b next to a, ..., .hid, -x_): '.' written %2E, no
#     two films share a name, none is hidden, each equals the default
#     layout's; --force removes them all and keeps a file no sweep wrote;
#   - --layout tree, --layout '' and a missing value are usage errors (exit
#     2, stderr naming --layout) that create nothing.
name=test_sweep_layout
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd raysweep
need_cmd python3 "for the balancer and the checks"
scene="$root/proto/examples/hdistant_lambertian.json"
start_spread_pair # $pa, $pb and the balancer $plb

rs() { "$bin/raysweep" -q --server "http://127.0.0.1:$1" "${@:2}"; }
# flat_like LABEL REF DIR: DIR is a flat sweep directory (no directory in
# it, every indexed file there and a plain name) whose films equal, bit for
# bit, those REF's index names for the same (context, sensor), and whose
# index is REF's but for "file".
flat_like() {
  py "$1" '
import json, os, sys, filecmp
ref, d = sys.argv[1], sys.argv[2]
subdirs = [e for e in os.listdir(d) if os.path.isdir(os.path.join(d, e))]
assert not subdirs, f"directories in a flat sweep: {subdirs}"
hidden = [e for e in os.listdir(d) if e.startswith(".")]
assert not hidden, f"hidden files: {hidden}"
def index(p):
    return [json.loads(l) for l in open(os.path.join(p, "index.jsonl"))]
a, b = index(ref), index(d)
assert len(a) == len(b) and a, f"{len(a)} films in the reference, {len(b)} here"
names = set()
for x, y in zip(a, b):
    fx, fy = x.pop("file"), y.pop("file")
    assert x == y, f"index lines differ: {x} / {y}"
    assert "/" not in fy and fy not in names, f"file {fy!r}"
    names.add(fy)
    assert filecmp.cmp(os.path.join(ref, fx), os.path.join(d, fy), shallow=False), f"{fy} differs from {fx}"
' "$2" "$3"
}
# same LABEL A B: the same films (by index.jsonl) and the same index.
same() {
  if cmp -s "$2/index.jsonl" "$3/index.jsonl"; then ok; else bad "$1: index.jsonl differs"; fi
  py "$1: films" '
import json, os, sys, filecmp
a, b = sys.argv[1], sys.argv[2]
files = [json.loads(l)["file"] for l in open(os.path.join(a, "index.jsonl"))]
assert files
for f in files:
    assert filecmp.cmp(os.path.join(a, f), os.path.join(b, f), shallow=False), f
' "$2" "$3"
}
layout_of() { python3 -c 'import json,sys; print(json.load(open(sys.argv[1])).get("layout", "none"))' "$1/sweep.json"; }

grid=(--grid wavelength=400:470:10 --spp 16 --seed 3 --bundle 1) # (one per path: shards k mod 2)
cd "$tmp" || finish

# ---- each format ----
for f in exr npy json nc; do
  rs "$pa" sweep "$scene" "${grid[@]}" --format $f -o "d_$f" 2>"$tmp/err" || bad "dirs $f: $(cat "$tmp/err")"
  rs "$pa" sweep "$scene" "${grid[@]}" --format $f --layout flat -o "f_$f" 2>"$tmp/err" ||
    bad "flat $f: $(cat "$tmp/err")"
  flat_like "--format $f: flat films" "d_$f" "f_$f"
  [ "$(layout_of "f_$f")" = flat ] && ok || bad "--format $f: sweep.json layout $(layout_of "f_$f")"
  [ "$(layout_of "d_$f")" = none ] && ok || bad "--format $f: the default's sweep.json has layout $(layout_of "d_$f")"
done
[ -f f_exr/c00003.sensor.exr ] && ok || bad "no f_exr/c00003.sensor.exr: $(ls f_exr | head -3)"
if cmp -s d_nc/dataset.nc f_nc/dataset.nc; then ok; else bad "--format nc: dataset.nc differs between layouts"; fi

# ---- shards and merge ----
rs "$pa" sweep "$scene" "${grid[@]}" --layout flat --shard 0/2 -o s0 2>"$tmp/err" || bad "shard 0/2: $(cat "$tmp/err")"
rs "$pb" sweep "$scene" "${grid[@]}" --layout flat --shard 1/2 -o s1 2>"$tmp/err" || bad "shard 1/2: $(cat "$tmp/err")"
[ "$(ls s0 | grep -c '\.exr$')" = 4 ] && ok || bad "shard 0/2 holds $(ls s0)"
expect 0 "merge of flat shards" rs "$pa" merge s0 s1 -o merged
same "flat shards merged" f_exr merged
rs "$pb" sweep "$scene" "${grid[@]}" --shard 1/2 -o s1d 2>"$tmp/err" || bad "shard 1/2 dirs: $(cat "$tmp/err")"
expect 0 "merge of a flat and a default-layout shard" rs "$pa" merge s0 s1d -o mixed
py "mixed layouts merged: every film, from either layout" '
import json, os, sys, filecmp
m, ref = sys.argv[1], sys.argv[2]
lines = [json.loads(l) for l in open(os.path.join(m, "index.jsonl"))]
assert len(lines) == 8, len(lines)
flat = [l["file"] for l in lines if "/" not in l["file"]]
assert len(flat) == 4, flat
refs = {(l["context"], l["sensor"]): l["file"] for l in map(json.loads, open(os.path.join(ref, "index.jsonl")))}
for l in lines:
    assert filecmp.cmp(os.path.join(m, l["file"]), os.path.join(ref, refs[(l["context"], l["sensor"])]), shallow=False)
' mixed d_exr

# ---- --spread over two daemons ----
rs "$plb" sweep "$scene" "${grid[@]}" --layout flat --spread 2 -o spread 2>"$tmp/err" ||
  bad "--spread 2: $(cat "$tmp/err")"
same "--spread 2, flat" f_exr spread

# ---- resume an interrupted --spread run ----
# (40 contexts: each shard hands over its first films after 4 renders of
# 20, so the cut below lands well before the end even on a loaded machine)
slow=(--grid wavelength=400:595:5 --spp 1024 --seed 5)
rs "$pa" sweep "$scene" "${slow[@]}" --layout flat -o slow_ref 2>"$tmp/err" || bad "slow ref: $(cat "$tmp/err")"
"$bin/raysweep" -q --server "http://127.0.0.1:$plb" sweep "$scene" "${slow[@]}" --layout flat --spread 2 \
  -o cut 2>"$tmp/cut.err" &
sweep_pid=$!
for _ in $(seq 600); do
  [ "$(ls cut 2>/dev/null | grep -c '\.exr$')" -ge 2 ] && break
  sleep 0.02
done
kill -TERM "$sweep_pid"
wait "$sweep_pid"
rc=$?
saved=$(ls cut | grep -c '\.exr$')
if [ "$rc" -eq 143 ] && [ "$saved" -ge 2 ] && [ "$saved" -lt 40 ]; then ok; else
  bad "stopped run: exit $rc (wanted 143), $saved films saved (wanted 2-39): $(cat "$tmp/cut.err")"
fi
[ -s cut/sweep.spread.jsonl ] && ok || bad "stopped run: no cut/sweep.spread.jsonl"
# a film the journal says was saved (it must not be fetched again)
first=$(python3 -c '
import json, sys
done = [json.loads(l)["context"] for l in open(sys.argv[1]) if "\"context\"" in l]
print(done[0] + ".sensor.exr" if done else "")' cut/sweep.spread.jsonl)
[ -n "$first" ] && [ -f "cut/$first" ] && ok || bad "stopped run: the journal names no saved film ('$first')"
inode=$(stat -c %i "cut/$first")
# --force over the stopped run (no index.jsonl yet: sweep.json's layout and
# contexts say which films are its own)
cp -a cut cut_force
touch cut_force/c00001.notes.txt
expect 0 "--force over a stopped flat run" rs "$pa" sweep "$scene" --grid wavelength=500:500:1 --spp 4 \
  --layout flat --force -o cut_force
got=$(cd cut_force && ls -A | LC_ALL=C sort | tr '\n' ' ')
want='c00000.sensor.exr c00001.notes.txt index.jsonl sweep.json '
[ "$got" = "$want" ] && ok || bad "--force over a stopped run: left '$got', wanted '$want'"
expect 2 "resume with another layout" rs "$plb" sweep "$scene" "${slow[@]}" --spread 2 -o cut
contains "resume with another layout: the error names --layout" "$tmp/err" "--layout dirs: -o cut holds an unfinished --spread run of this sweep with --layout flat"
[ -s cut/sweep.spread.jsonl ] && ok || bad "the refused rerun removed the journal"
"$bin/raysweep" --server "http://127.0.0.1:$plb" sweep "$scene" "${slow[@]}" --layout flat --spread 2 -o cut \
  >/dev/null 2>"$tmp/err"
rc=$?
[ "$rc" -eq 0 ] && ok || bad "resume: exit $rc: $(cat "$tmp/err")"
contains "resume: films of the earlier run" "$tmp/err" "from an earlier run"
[ "$(stat -c %i "cut/$first")" = "$inode" ] && ok || bad "resume: cut/$first was written again"
same "resumed --spread, flat" slow_ref cut
[ ! -e cut/sweep.spread.jsonl ] && ok || bad "resume: the journal is still there"

# ---- odd context ids ----
printf '%s\n' '{"id": "a.b", "wavelength": 500}' '{"id": "a", "wavelength": 510}' \
  '{"id": "...", "wavelength": 520}' '{"id": ".hid", "wavelength": 530}' '{"id": "-x_", "wavelength": 540}' \
  '{"id": "a.b.c", "wavelength": 550}' >odd.jsonl
rs "$pa" sweep "$scene" --contexts odd.jsonl --spp 8 -o odd_d 2>"$tmp/err" || bad "odd ids, dirs: $(cat "$tmp/err")"
rs "$pa" sweep "$scene" --contexts odd.jsonl --spp 8 --layout flat -o odd 2>"$tmp/err" ||
  bad "odd ids, flat: $(cat "$tmp/err")"
got=$(cd odd && ls -A | grep -v '^index.jsonl$\|^sweep.json$' | LC_ALL=C sort | tr '\n' ' ')
want='%2E%2E%2E.sensor.exr %2Ehid.sensor.exr -x_.sensor.exr a%2Eb%2Ec.sensor.exr a%2Eb.sensor.exr a.sensor.exr '
[ "$got" = "$want" ] && ok || bad "odd ids: files '$got', wanted '$want'"
flat_like "odd ids: films" odd_d odd
touch odd/a.notes.txt
expect 0 "--force over a flat sweep" rs "$pa" sweep "$scene" "${grid[@]}" --layout flat --force -o odd
got=$(cd odd && ls -A | LC_ALL=C sort | tr '\n' ' ')
want='a.notes.txt c00000.sensor.exr c00001.sensor.exr c00002.sensor.exr c00003.sensor.exr c00004.sensor.exr c00005.sensor.exr c00006.sensor.exr c00007.sensor.exr index.jsonl sweep.json '
[ "$got" = "$want" ] && ok || bad "--force: left '$got', wanted '$want'"

# ---- bad values ----
for v in tree "" flat,dirs; do
  expect 2 "--layout '$v'" rs "$pa" sweep "$scene" "${grid[@]}" --layout "$v" -o "bad_$v"
  contains "--layout '$v': the error names it" "$tmp/err" "--layout needs dirs or flat (got '$v')"
  [ ! -e "bad_$v" ] && ok || bad "--layout '$v' created bad_$v"
done
expect 2 "--layout without a value" rs "$pa" sweep "$scene" "${grid[@]}" -o bad_none --layout
contains "--layout without a value: the error names it" "$tmp/err" "--layout"
finish
