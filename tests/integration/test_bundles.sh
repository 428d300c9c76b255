#!/usr/bin/env bash
# Spectral bundles (a job's "bundle": docs/experiments.md#spectral-bundles), on
# the molecular atmosphere example (2,400 Rayleigh + ozone layers and an
# aerosol layer whose share of the scattering differs across the bundle:
# chromatic free flights and a chromatic phase mixture) and 6 contexts at
# 400..650 nm:
#   - statistically equal to the unbundled films: for each context, the
#     film means agree within 4 combined standard errors (the stderr
#     planes), and at most 2% of pixels differ by more than 3 sigma
#     (Gaussian: 0.27%; the allowance covers the per-pixel stderr's own
#     noise at 256 spp); fixed seeds;
#   - a bundled film names its own wavelength and its bundle's seed, and
#     GET .../results names that seed too (it named the context's own);
#   - each channel renders at its own wavelength: a Lambertian plate's BRF
#     in a bundle is its reflectance table at each context's wavelength;
#   - bitwise the same with 1 and 2 render threads;
#   - formed whatever the order of a grid's axes (same overrides, other
#     wavelengths, cut into threes in the job's order), never across
#     overrides, never over a context's own seed;
#   - refused with a 422 naming /bundle: bundle 0 and 17, an rgb scene, a
#     Stokes film the job renders (naming the sensor; a job of the scene's
#     other sensor is accepted).
name=test_bundles
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
python3 -c 'import json' || { bad "python3 missing"; finish; }
cp "$root/proto/examples/atmosphere_molecular.json" "$tmp/atmo.json"
python3 - "$root/proto/examples/hdistant_lambertian.json" "$tmp/stokes.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
d["stokes"] = json.loads(json.dumps(d["sensor"]))
d["stokes"]["film"]["pixel_format"] = "stokes"
json.dump(d, open(sys.argv[2], "w"))
PY
start_daemon "$tmp/d2" --threads 2
p2=$started_port
start_daemon "$tmp/d1" --threads 1
p1=$started_port
[ -n "$p1" ] && [ -n "$p2" ] || { bad "daemons did not start: $(cat "$tmp/d1/log" "$tmp/d2/log")"; finish; }

export RSW_JOB_BIN="$bin"
cp "$root/tests/support/bundle_job.py" "$tmp/bundle_job.py"
cat >"$tmp/job.py" <<'PY'
import json, math, sys, time
from bundle_job import call
def push(port, path):
    st, s = call(port, "POST", "/v1/scenes", open(path, "rb").read())
    assert st in (200, 201), (st, s)
    return s["id"]
def films(port, sid, bundle, seed, wls, spp=256):
    body = {"contexts": [{"id": f"w{int(w)}", "wavelength": w} for w in wls],
            "defaults": {"spp": spp}, "variance": True, "seed": seed}
    if bundle is not None:
        body["bundle"] = bundle
    st, j = call(port, "POST", f"/v1/scenes/{sid}/jobs", body)
    assert st == 202 or st == 201 or st == 200, (st, j)
    jid = j["id"]
    for _ in range(3000):
        st, j = call(port, "GET", f"/v1/jobs/{jid}")
        if j["state"] not in ("queued", "running"):
            break
        time.sleep(0.1)
    assert j["state"] == "succeeded", j
    st, idx = call(port, "GET", f"/v1/jobs/{jid}/results")
    out = {}
    for r in idx["results"]:
        st, f = call(port, "GET", r["href"])
        # the listing names the seed the film was rendered with (its bundle'"'"'s)
        assert r["seed"] == f["meta"]["seed"], (r, f["meta"]["seed"])
        out[r["context"]] = f
    return out
PY

py "bundled films are statistically the unbundled ones, name their wavelength and the bundle's seed" '
import sys, math
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[3])
wls = [400.0, 450.0, 500.0, 550.0, 600.0, 650.0]
a = films(port, sid, 1, 7, wls)
b = films(port, sid, 3, 8, wls)
seeds = {}
for ctx in a:
    fa, fb = a[ctx], b[ctx]
    assert fb["meta"]["wavelength"] == fa["meta"]["wavelength"] == float(ctx[1:]), (ctx, fb["meta"]["wavelength"])
    seeds.setdefault(fb["meta"]["seed"], []).append(ctx)
    nc = len(fa["channels"])
    A, SA = fa["data"][0::nc], fa["data"][nc - 1::nc]
    B, SB = fb["data"][0::nc], fb["data"][nc - 1::nc]
    n = len(A)
    var = sum(x * x + y * y for x, y in zip(SA, SB))
    gz = (sum(A) - sum(B)) / math.sqrt(var)
    far = sum(1 for x, y, s, t in zip(A, B, SA, SB) if abs(x - y) > 3 * math.sqrt(s * s + t * t)) / n
    assert abs(gz) < 4, (ctx, "film means differ by", gz, "sigma")
    assert far <= 0.02, (ctx, far, "of pixels beyond 3 sigma")
# two bundles of three: each shares its first context'"'"'s seed
assert sorted(len(v) for v in seeds.values()) == [3, 3], seeds
' "$tmp" "$p2" "$tmp/atmo.json"

py "a bundled job is bitwise the same with 1 and 2 render threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
wls = [400.0, 425.0, 450.0, 475.0]
f = [films(int(p), push(int(p), sys.argv[4]), 3, 11, wls, spp=16) for p in sys.argv[2:4]]
for ctx in f[0]:
    assert f[0][ctx]["data"] == f[1][ctx]["data"], ctx
' "$tmp" "$p1" "$p2" "$tmp/atmo.json"

py "bundles form whatever the axes' order (the same overrides, other wavelengths), never across overrides or over a context's own seed" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[3])
key = "surface.bsdf.reflectance.value"
ctx = []
for w in (400.0, 450.0, 500.0, 550.0):        # wavelength slowest, as --grid wavelength=... --grid KEY=...
    for r in (0.2, 0.4):
        ctx.append({"id": f"w{int(w)}r{int(r * 10)}", "wavelength": w, "params": {key: r}})
ctx.append({"id": "own", "wavelength": 600.0, "params": {key: 0.2}, "seed": 5})
st, j = call(port, "POST", f"/v1/scenes/{sid}/jobs", {"contexts": ctx, "defaults": {"spp": 4}, "bundle": 3})
assert st in (200, 201, 202), (st, j)
for _ in range(600):
    st, j = call(port, "GET", "/v1/jobs/" + j["id"])
    if j["state"] not in ("queued", "running"): break
    time.sleep(0.05)
assert j["state"] == "succeeded", j
st, idx = call(port, "GET", "/v1/jobs/" + j["id"] + "/results")
seed = {r["context"]: call(port, "GET", r["href"])[1]["meta"]["seed"] for r in idx["results"]}
groups = {}
for c, s in seed.items():
    groups.setdefault(s, []).append(c)
got = sorted(sorted(g) for g in groups.values())
want = sorted([sorted(["w400r2", "w450r2", "w500r2"]), ["w550r2"], sorted(["w400r4", "w450r4", "w500r4"]), ["w550r4"], ["own"]])
assert got == want, got
assert seed["own"] == 5, seed["own"]
' "$tmp" "$p2" "$root/proto/examples/hdistant_lambertian.json"

py "each channel of a bundle at its own wavelength: a Lambertian plate's BRF is its reflectance table there (closed form)" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[3])
body = {"contexts": [{"id": f"w{w}", "wavelength": w} for w in (420, 480, 530, 610)], "defaults": {"spp": 4},
        "quantities": ["brf"], "bundle": 3}
st, j = call(port, "POST", f"/v1/scenes/{sid}/jobs", body)
for _ in range(600):
    st, j = call(port, "GET", "/v1/jobs/" + j["id"])
    if j["state"] not in ("queued", "running"): break
    time.sleep(0.05)
assert j["state"] == "succeeded", j
st, idx = call(port, "GET", "/v1/jobs/" + j["id"] + "/results")
def rho(w):  # the example'"'"'s table: (400, 0.05), (550, 0.1), (700, 0.45)
    return 0.05 + (w - 400) / 150 * 0.05 if w <= 550 else 0.1 + (w - 550) / 150 * 0.35
seeds = set()
for r in idx["results"]:
    f = call(port, "GET", r["href"])[1]
    n = len(f["channels"]); w = f["meta"]["wavelength"]; seeds.add(f["meta"]["seed"])
    brf = f["data"][n - 1::n]
    assert all(abs(b - rho(w)) < 1e-6 for b in brf), (w, brf[:3], rho(w))
assert len(seeds) == 2, seeds
' "$tmp" "$p2" "$root/proto/examples/hdistant_lambertian.json"

py "bad bundles are refused, naming /bundle and what blocks it" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2])
def refuse(path, bundle, words):
    sid = push(port, path)
    st, p = call(port, "POST", f"/v1/scenes/{sid}/jobs", {"contexts": [{"id": "a"}], "bundle": bundle})
    assert st == 422, (st, p)
    assert p.get("pointer") == "/bundle" or "/bundle" in json.dumps(p), p
    for w in words:
        assert w in p["detail"], (w, p["detail"])
refuse(sys.argv[3], 17, ["from 1", "to 16"])
refuse(sys.argv[3], 0, ["from 1"])
refuse(sys.argv[4], 3, ["sensor '"'"'stokes'"'"'", "Stokes"])
# the job renders only the other sensor: bundled
sid = push(port, sys.argv[4])
st, j = call(port, "POST", f"/v1/scenes/{sid}/jobs", {"contexts": [{"id": "a", "wavelength": 500}, {"id": "b", "wavelength": 510}],
                                                   "defaults": {"sensors": ["sensor"], "spp": 2}, "bundle": 2})
assert st in (200, 201, 202), (st, j)
refuse(sys.argv[5], 2, ["mono"])
' "$tmp" "$p2" "$tmp/atmo.json" "$tmp/stokes.json" "$root/proto/examples/cornell_box.json"
finish
