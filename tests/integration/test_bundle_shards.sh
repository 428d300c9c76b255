#!/usr/bin/env bash
# Spectral bundles and shards (docs/cluster.md#shards-and-spectral-bundles),
# on the Lambertian plate (mono) with a 2 x 7 grid, wavelength fastest, at
# --bundle 3 (bundle groups {0,1,2} {3,4,5} {6} {7,8,9} {10,11,12} {13}):
#   - the sweep run whole, as --shard 0/2 + 1/2 merged, and with --spread 2
#     over two daemons behind a balancer give cmp-identical films and the
#     same index; each shard holds whole bundle groups (its sweep.json's
#     bundle_leads); --shard with --bundle auto likewise (the client plans
#     auto in groups of 16: where the daemon comes to 16, its films are
#     --bundle 16's; where it comes to 3, it cuts each group of 16 into
#     threes, so shards still give the whole sweep's films);
#   - the same from a --contexts file (wavelength fastest, ids given);
#   - without --bundle the sweep is --bundle auto's (the daemon's
#     default), whole and as shards merged; groups are dealt to the shards
#     in turn (40 wavelengths in groups of 16: shard 1/4 holds the second;
#     sweep.json says "bundle_shards": "rank"); shards dealt by a group's
#     first context, as clients before that rule left them (no
#     "bundle_shards"), merge whole, and merged alone with --partial list
#     what they lack; an unknown "bundle_shards" is refused naming it;
#     with --bundle 1 the shards are
#     k mod n and sweep.json has no bundle_leads (as before bundles);
#   - a job's "bundle": "auto" comes to 16 on a mono surface scene (its
#     films those of "bundle": 16, not those of "bundle": 1) and to 1,
#     accepted, with the reason, on an rgb scene and a Stokes film
#     (environment plugins: test_bundle_env.sh); "bundle"
#     0, 17, "x", -1 and a context's bundle_group "a" are 4xx naming the
#     pointer; `sweep --bundle 17` and `--bundle x` are usage errors;
#   - --spread checks the whole sweep first (?dry_run=1): a sweep over sza
#     that nothing reads warns once, though each shard holds one value;
#     an unknown sensor fails before either replica queues a job; so does
#     --shard I/N on its daemon: each of two shards over sza warns once.
name=test_bundle_shards
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd raysweep
need_cmd python3 "for the balancer and the HTTP checks"
scene="$root/proto/examples/hdistant_lambertian.json"
start_spread_pair # $pa, $pb and the balancer $plb

rs() { "$bin/raysweep" -q --server "http://127.0.0.1:$1" "${@:2}"; }
# same LABEL REF DIR: DIR holds REF's films, bit for bit, and its index.
same() {
  local f n=0 differ=""
  for f in $(cd "$2" && find . -name '*.exr' | sort); do
    n=$((n + 1))
    cmp -s "$2/$f" "$3/$f" || differ="$differ $f"
  done
  if [ "$n" -gt 0 ] && [ -z "$differ" ]; then ok; else bad "$1: $n films, differing:${differ:- (none found)}"; fi
  if cmp -s "$2/index.jsonl" "$3/index.jsonl"; then ok; else bad "$1: index.jsonl differs"; fi
}
# leads LABEL DIR WANT: DIR/sweep.json's bundle_leads (JSON, or "none").
leads() {
  local got
  got=$(python3 -c 'import json,sys; print(json.dumps(json.load(open(sys.argv[1])).get("bundle_leads", "none")))' "$2/sweep.json")
  if [ "$got" = "$3" ]; then ok; else bad "$1: bundle_leads $got, wanted $3"; fi
}

grid=(--grid surface.bsdf.reflectance.value=0.2:0.3:0.1 --grid wavelength=400:460:10 --spp 64 --seed 7)
w3='[0, 0, 0, 3, 3, 3, 6, 7, 7, 7, 10, 10, 10, 13]'
cd "$tmp" || finish
rs "$pa" sweep "$scene" "${grid[@]}" --bundle 3 -o whole >/dev/null 2>"$tmp/err" || bad "whole sweep: $(cat "$tmp/err")"
rs "$pa" sweep "$scene" "${grid[@]}" --bundle 3 --shard 0/2 -o s0 >/dev/null 2>"$tmp/err" || bad "shard 0/2: $(cat "$tmp/err")"
rs "$pb" sweep "$scene" "${grid[@]}" --bundle 3 --shard 1/2 -o s1 >/dev/null 2>"$tmp/err" || bad "shard 1/2: $(cat "$tmp/err")"
rs "$pa" merge s0 s1 -o merged >/dev/null 2>"$tmp/err" || bad "merge: $(cat "$tmp/err")"
same "--shard 0/2 + 1/2 merged" whole merged
leads "shard 0/2's manifest" s0 "$w3"
got=$(ls s0 | grep '^c' | tr '\n' ' ')
if [ "$got" = "c00000 c00001 c00002 c00006 c00010 c00011 c00012 " ]; then ok; else bad "shard 0/2 holds $got"; fi
rs "$plb" sweep "$scene" "${grid[@]}" --bundle 3 --spread 2 -o spread >/dev/null 2>"$tmp/err" || bad "--spread 2: $(cat "$tmp/err")"
same "--spread 2 over two daemons" whole spread
for p in "$pa" "$pb"; do # each replica rendered a shard
  n=$(curl -s "http://127.0.0.1:$p/metrics" | awk '$1 == "raysweep_contexts_rendered_total" { print $2 }')
  if [ "${n:-0}" != 0 ]; then ok; else bad "replica $p rendered nothing of the spread sweep"; fi
done
# --bundle auto: groups of 16, and the daemon takes 16 here.
rs "$pa" sweep "$scene" "${grid[@]}" --bundle auto -o auto >/dev/null 2>"$tmp/err" || bad "auto: $(cat "$tmp/err")"
rs "$pa" sweep "$scene" "${grid[@]}" --bundle auto --shard 0/3 -o a0 >/dev/null 2>"$tmp/err" &&
  rs "$pa" sweep "$scene" "${grid[@]}" --bundle auto --shard 1/3 -o a1 >/dev/null 2>"$tmp/err" &&
  rs "$pa" sweep "$scene" "${grid[@]}" --bundle auto --shard 2/3 -o a2 >/dev/null 2>"$tmp/err" &&
  rs "$pa" merge a0 a1 a2 -o amerged >/dev/null 2>"$tmp/err" || bad "auto shards: $(cat "$tmp/err")"
same "--bundle auto, --shard I/3 merged" auto amerged
rs "$pa" sweep "$scene" "${grid[@]}" --bundle 16 -o whole16 >/dev/null 2>"$tmp/err" || bad "bundle 16: $(cat "$tmp/err")"
same "--bundle auto, --bundle 16" whole16 auto
# No --bundle: auto, the daemon's default, whole and in shards.
rs "$pa" sweep "$scene" "${grid[@]}" -o dflt >/dev/null 2>"$tmp/err" &&
  rs "$pa" sweep "$scene" "${grid[@]}" --shard 0/2 -o n0 >/dev/null 2>"$tmp/err" &&
  rs "$pb" sweep "$scene" "${grid[@]}" --shard 1/2 -o n1 >/dev/null 2>"$tmp/err" &&
  rs "$pa" merge n0 n1 -o nmerged >/dev/null 2>"$tmp/err" || bad "no --bundle: $(cat "$tmp/err")"
same "no --bundle, --bundle auto" auto dflt
same "no --bundle, --shard 0/2 + 1/2 merged" auto nmerged
# Groups are dealt out in turn: 40 wavelengths in groups of 16 over 4
# shards put one group on each of shards 0, 1, 2 (by the first context's
# index mod 4 all three fell on shard 0).
rs "$pa" sweep "$scene" --grid wavelength=400:439:1 --spp 1 --shard 1/4 -o g1 >/dev/null 2>"$tmp/err" ||
  bad "40 wavelengths, shard 1/4: $(cat "$tmp/err")"
got=$(ls g1 | grep '^c' | tr '\n' ' ')
want=$(seq -f 'c%05g' 16 31 | tr '\n' ' ')
if [ "$got" = "$want" ]; then ok; else bad "shard 1/4 of 40 wavelengths in groups of 16 holds '$got'"; fi
rule=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1])).get("bundle_shards"))' g1/sweep.json)
if [ "$rule" = rank ]; then ok; else bad "shard 1/4's manifest: bundle_shards $rule, wanted rank"; fi
# Shards written by a client before the rank rule (no "bundle_shards";
# a group on shard (its first context) mod N) still merge: 40 wavelengths
# over 2 shards put all three groups (first contexts 0, 16, 32) on shard
# 0. Built from the whole sweep by hand, as that client left them.
rs "$pa" sweep "$scene" --grid wavelength=400:439:1 --spp 1 -o g40 >/dev/null 2>"$tmp/err" ||
  bad "40 wavelengths: $(cat "$tmp/err")"
cp -a g40 old0 && mkdir old1 && : >old1/index.jsonl
python3 - <<'PY2'
import json
m = json.load(open("g40/sweep.json"))
m.pop("bundle_shards", None)
for i, d in enumerate(("old0", "old1")):
    m["shard"] = [i, 2]
    json.dump(m, open(d + "/sweep.json", "w"))
PY2
if rs "$pa" merge old0 old1 -o oldmerged >/dev/null 2>"$tmp/err"; then
  same "shards dealt by first context (a client before the rank rule), merged" g40 oldmerged
else
  bad "merge of shards dealt by first context: $(cat "$tmp/err")"
fi
# Shard 1/2 alone (it holds nothing): every context is missing, and
# listed as incomplete (by the rank rule it would claim the second group).
rs "$pa" merge old1 --partial -o oldpartial >/dev/null 2>"$tmp/err" || bad "merge --partial of old shard 1/2: $(cat "$tmp/err")"
py "merge --partial of an old empty shard lists every context as incomplete" '
import json, sys
m = json.load(open(sys.argv[1]))
assert len(m["incomplete"]) == 40, len(m["incomplete"])' oldpartial/sweep.json
python3 -c 'import json; m = json.load(open("old1/sweep.json")); m["bundle_shards"] = "pairs"; json.dump(m, open("old1/sweep.json", "w"))'
expect 6 "merge, a manifest with an unknown bundle_shards" rs "$pa" merge old0 old1 -o oldbad
contains "merge, a manifest with an unknown bundle_shards" "$tmp/err" "bundle_shards"
# --bundle auto where the daemon comes to 3 (a canopy on a two-sided
# plastic soil, whose delta specular lobe inside `twosided` keeps pages
# out; leaves with tabulated
# reflectance and transmittance, so that the bundle changes the paths'
# choices): 20 wavelengths per reflectance, groups of 16 (leads 0, 16, 20,
# 36: shards 0, 1, 2, 0 of 3) each cut into threes, so the shards' bundles
# are the whole sweep's (runs cut into threes across a group's end,
# {15, 16, 17}, would not be).
cp "$root/proto/examples/canopy_leaves.txt" .
python3 - "$root/proto/examples/canopy_periodic.json" canopy3.json <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
d["soil"]["bsdf"] = {"type": "twosided", "bsdf": {"type": "plastic", "diffuse_reflectance": 0.3}}
d["leaf"]["disc"]["bsdf"] = {"type": "bilambertian",
                             "reflectance": {"type": "spectrum", "wavelengths": [400, 800], "values": [0.05, 0.5]},
                             "transmittance": {"type": "spectrum", "wavelengths": [400, 800], "values": [0.3, 0.45]}}
json.dump(d, open(sys.argv[2], "w"))
PY
g20=(--grid wavelength=400:590:10 --grid soil.bsdf.brdf_0.diffuse_reflectance.value=0.2:0.3:0.1 --spp 4 --seed 7)
rs "$pa" sweep canopy3.json "${g20[@]}" --bundle auto -o dauto >/dev/null 2>"$tmp/err" &&
  rs "$pa" sweep canopy3.json "${g20[@]}" --bundle auto --shard 0/3 -o d0 >/dev/null 2>"$tmp/err" &&
  rs "$pb" sweep canopy3.json "${g20[@]}" --bundle auto --shard 1/3 -o d1 >/dev/null 2>"$tmp/err" &&
  rs "$pa" sweep canopy3.json "${g20[@]}" --bundle auto --shard 2/3 -o d2 >/dev/null 2>"$tmp/err" &&
  rs "$pa" merge d0 d1 d2 -o dmerged >/dev/null 2>"$tmp/err" || bad "auto at 3, shards: $(cat "$tmp/err")"
same "--bundle auto at 3, --shard I/3 merged" dauto dmerged
# A bundled sweep is not the unbundled one (so the checks above can fail).
rs "$pa" sweep "$scene" "${grid[@]}" --bundle 1 -o plain >/dev/null 2>"$tmp/err" || bad "plain: $(cat "$tmp/err")"
n=0
for f in $(cd whole && find . -name '*.exr'); do cmp -s "whole/$f" "plain/$f" || n=$((n + 1)); done
if [ "$n" -gt 0 ]; then ok; else bad "bundle 3 gave the films of bundle 1"; fi
# With --bundle 1: k mod n, no bundle_leads.
rs "$pa" sweep "$scene" "${grid[@]}" --bundle 1 --shard 1/2 -o p1 >/dev/null 2>"$tmp/err" || bad "plain shard: $(cat "$tmp/err")"
leads "an unbundled shard's manifest" p1 '"none"'
got=$(ls p1 | grep '^c' | tr '\n' ' ')
if [ "$got" = "c00001 c00003 c00005 c00007 c00009 c00011 c00013 " ]; then ok; else bad "unbundled shard 1/2 holds $got"; fi

# A --contexts file: wavelength fastest under two reflectances, ids given.
python3 - >ctx.jsonl <<'PY'
import json
for r in (0.2, 0.3):
    for w in range(400, 470, 10):
        print(json.dumps({"id": f"r{int(r*10)}w{w}", "wavelength": w, "params": {"surface.bsdf.reflectance.value": r}}))
PY
rs "$pa" sweep "$scene" --contexts ctx.jsonl --spp 64 --bundle 3 -o cwhole >/dev/null 2>"$tmp/err" || bad "contexts whole: $(cat "$tmp/err")"
rs "$pb" sweep "$scene" --contexts ctx.jsonl --spp 64 --bundle 3 --shard 0/2 -o c0 >/dev/null 2>"$tmp/err" &&
  rs "$pa" sweep "$scene" --contexts ctx.jsonl --spp 64 --bundle 3 --shard 1/2 -o c1 >/dev/null 2>"$tmp/err" &&
  rs "$pa" merge c0 c1 -o cmerged >/dev/null 2>"$tmp/err" || bad "contexts shards: $(cat "$tmp/err")"
same "--contexts, --shard 0/2 + 1/2 merged" cwhole cmerged
leads "a --contexts shard's manifest" c0 "$w3"
rs "$plb" sweep "$scene" --contexts ctx.jsonl --spp 64 --bundle 3 --spread 2 -o cspread >/dev/null 2>"$tmp/err" || bad "contexts --spread: $(cat "$tmp/err")"
same "--contexts, --spread 2" cwhole cspread

# Usage errors.
expect 2 "sweep --bundle 17" rs "$pa" sweep "$scene" "${grid[@]}" --bundle 17 -o u17
contains "sweep --bundle 17" "$tmp/err" "--bundle"
expect 2 "sweep --bundle x" rs "$pa" sweep "$scene" "${grid[@]}" --bundle x -o ux

# "bundle": "auto" and bad values over HTTP.
python3 - "$root/proto/examples/hdistant_lambertian.json" "$tmp/stokes.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
d["sensor"]["film"]["pixel_format"] = "stokes"
json.dump(d, open(sys.argv[2], "w"))
PY
cat >"$tmp/rsw_http.py" <<'PY'
import json, sys, time, urllib.request, urllib.error
def call(port, method, path, body=None):
    data = body if body is None or isinstance(body, bytes) else json.dumps(body).encode()
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", method=method, data=data,
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=300) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()
def push(port, path):
    st, b = call(port, "POST", "/v1/scenes", open(path, "rb").read())
    assert st in (200, 201), (st, b)
    return json.loads(b)["id"]
def job(port, sid, extra, ctxs=None):
    body = {"contexts": ctxs or [{"id": f"w{w}", "wavelength": w} for w in (400, 410, 420, 430)],
            "defaults": {"spp": 16}, "seed": 3}
    body.update(extra)
    st, b = call(port, "POST", f"/v1/scenes/{sid}/jobs", body)
    return st, json.loads(b)
def films(port, j):
    for _ in range(3000):
        st, b = call(port, "GET", f"/v1/jobs/{j['id']}")
        s = json.loads(b)
        if s["state"] not in ("queued", "running"):
            break
        time.sleep(0.05)
    assert s["state"] == "succeeded", s
    st, b = call(port, "GET", f"/v1/jobs/{j['id']}/results")
    return {r["context"]: call(port, "GET", r["href"])[1] for r in json.loads(b)["results"]}
PY
py '"bundle": "auto" on a mono surface scene: 16, the films of "bundle": 16, not those of 1' '
import sys; sys.path.insert(0, sys.argv[1]); import importlib.util as u
spec = u.spec_from_file_location("h", sys.argv[1] + "/rsw_http.py"); h = u.module_from_spec(spec); spec.loader.exec_module(h)
port = int(sys.argv[2]); sid = h.push(port, sys.argv[3])
st, a = h.job(port, sid, {"bundle": "auto"}); assert st == 202, (st, a); assert a["bundle"] == 16 and "bundle_why" not in a, a
st, t = h.job(port, sid, {"bundle": 16}); assert st == 202, (st, t); assert t["bundle"] == 16, t
st, o = h.job(port, sid, {"bundle": 1}); assert st == 202 and o["bundle"] == 1, o
fa, ft, fo = h.films(port, a), h.films(port, t), h.films(port, o)
assert fa == ft, "auto differs from 16"
assert fa != fo, "auto gave the unbundled films"
' "$tmp" "$pa" "$scene"
for s in "$root/proto/examples/cornell_box.json:rgb" "$tmp/stokes.json:Stokes"; do
  py "\"bundle\": \"auto\" on ${s##*:}: 1 with the reason" '
import sys, importlib.util as u
spec = u.spec_from_file_location("h", sys.argv[1] + "/rsw_http.py"); h = u.module_from_spec(spec); spec.loader.exec_module(h)
port = int(sys.argv[2]); sid = h.push(port, sys.argv[3])
rgb = "rgb" in sys.argv[4]
ctxs = [{"id": "a"}, {"id": "b"}] if rgb else None
st, a = h.job(port, sid, {"bundle": "auto"}, ctxs); assert st == 202, (st, a)
assert a["bundle"] == 1 and sys.argv[4] in a["bundle_why"], a
h.films(port, a)
st, e = h.job(port, sid, {"bundle": 3}, ctxs); assert st == 422 and e["pointer"] == "/bundle", (st, e)
' "$tmp" "$pa" "${s%%:*}" "${s##*:}"
done
py 'bad "bundle" values and bundle_group: 4xx naming the pointer' '
import sys, importlib.util as u
spec = u.spec_from_file_location("h", sys.argv[1] + "/rsw_http.py"); h = u.module_from_spec(spec); spec.loader.exec_module(h)
port = int(sys.argv[2]); sid = h.push(port, sys.argv[3])
for v in (0, 17, "x", -1, 2.5, "AUTO", None, [3]):
    st, e = h.job(port, sid, {"bundle": v})
    assert 400 <= st < 500 and e["pointer"] == "/bundle", (v, st, e)
for v in ("a", -1, 1.5):
    st, e = h.job(port, sid, {"bundle": 3}, [{"id": "a", "wavelength": 400, "bundle_group": v}])
    assert 400 <= st < 500 and e["pointer"] == "/contexts/0/bundle_group", (v, st, e)
' "$tmp" "$pa" "$scene"
py 'bundle_group: renders of other groups never share a bundle' '
import sys, importlib.util as u
spec = u.spec_from_file_location("h", sys.argv[1] + "/rsw_http.py"); h = u.module_from_spec(spec); spec.loader.exec_module(h)
port = int(sys.argv[2]); sid = h.push(port, sys.argv[3])
one = lambda w: [{"id": f"w{w}", "wavelength": w}]
grouped = [{"id": f"w{w}", "wavelength": w, "bundle_group": g} for w, g in ((400, 0), (410, 0), (420, 2), (430, 2))]
st, a = h.job(port, sid, {"bundle": 3}, grouped); assert st == 202, (st, a)
st, b = h.job(port, sid, {"bundle": 3}, grouped[2:]); assert st == 202, (st, b)
st, c = h.job(port, sid, {"bundle": 3}, [dict(x, bundle_group=0) for x in grouped]); assert st == 202, (st, c)
fa, fb, fc = h.films(port, a), h.films(port, b), h.films(port, c)
assert fa["w420"] == fb["w420"] and fa["w430"] == fb["w430"], "a group alone differs from the group in the job"
assert fa["w420"] != fc["w420"], "bundle_group changed nothing"
' "$tmp" "$pa" "$scene"

# --spread dry-runs the whole sweep first (POST .../jobs?dry_run=1): its
# warnings once, though each shard holds one value of sza (a shard's own
# job cannot see that sza changes nothing: none was printed before), and a
# request the daemon refuses fails before any shard's job is queued.
jobs_now() { curl -s "http://127.0.0.1:$1/v1/jobs" | python3 -c 'import json, sys; print(len(json.load(sys.stdin)["jobs"]))'; }
expect 0 "spread 2 over a coordinate nothing reads" rs "$plb" sweep "$scene" --grid sza=0,30 --spp 2 --spread 2 -o sza
n=$(grep -c "warning: the sweep: coordinate_unused (sza)" "$tmp/err")
[ "$n" = 1 ] && ok || bad "spread 2 over sza: $n coordinate_unused warnings, want 1: $(head -c 600 "$tmp/err")"
before="$(jobs_now "$pa") $(jobs_now "$pb")"
expect 1 "spread 2 with an unknown sensor" rs "$plb" sweep "$scene" --grid wavelength=500,600 --sensor nosuch \
  --spp 2 --spread 2 -o nosuch
contains "spread 2 with an unknown sensor: named" "$tmp/err" "no sensor 'nosuch'"
after="$(jobs_now "$pa") $(jobs_now "$pb")"
[ "$before" = "$after" ] && ok || bad "spread 2 with an unknown sensor queued jobs: $before before, $after after"
# --shard I/N dry-runs the whole sweep on its daemon too: each of two
# shards of one sza value warns once (its own job cannot see it); a shard
# whose own job also warns prints the warning once.
for i in 0 1; do
  expect 0 "--shard $i/2 over a coordinate nothing reads" rs "$pa" sweep "$scene" --grid sza=0,30 --spp 2 --shard $i/2 -o szash$i
  n=$(grep -c "warning: the sweep: coordinate_unused (sza)" "$tmp/err")
  [ "$n" = 1 ] && ok || bad "--shard $i/2 over sza: $n coordinate_unused warnings, want 1: $(head -c 600 "$tmp/err")"
done
expect 0 "--shard 0/2 of three sza values" rs "$pa" sweep "$scene" --grid sza=0,30,60 --spp 2 --shard 0/2 -o szash3
n=$(grep -c "coordinate_unused (sza)" "$tmp/err")
[ "$n" = 1 ] && ok || bad "--shard 0/2 of three sza: $n coordinate_unused warnings, want 1: $(head -c 600 "$tmp/err")"
finish
