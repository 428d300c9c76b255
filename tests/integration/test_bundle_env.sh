#!/usr/bin/env bash
# Spectral bundles under environment emitters that prepare per render
# (docs/experiments.md#spectral-bundles): environment plugins (asked for
# all the bundle's wavelengths in one add_radiance per evaluation, prepared
# with its whole range) and `envmap` (its luminance at every wavelength in
# mono). 16 wavelengths per job, fixed seeds:
#   - tests/plugins/rayleigh_sky.c (a sky of sky (550 / w)^4 over the upper
#     hemisphere, tabulated in prepare over the range it is given; asked
#     outside it, NaN) over a Lambertian plate with a reflectance table,
#     seen by hdistant: "auto" takes 16; a bundle of 16 (400..700 nm) and
#     one of 3 are statistically the unbundled films (per film the means
#     within 4 combined standard errors of the stderr planes, at most 2% of
#     pixels beyond 3 sigma, over the films the rms of those z below 1.4);
#     each bundled film's mean is the closed form rho(w) sky (550 / w)^4
#     within 4 standard errors and 1e-6 (light and BSDF samples share the
#     cosine density: every path carries exactly that; a prepare given
#     only the first page's
#     range, or a page evaluated at page 0's wavelengths, misses it by far
#     more); bitwise the same with 1 and 2 render threads;
#   - tests/plugins/two_hemispheres.c (light from +x above 500 nm, from -x
#     below) on a grey sphere seen by a camera, a bundle of 16 across 500 nm
#     (435..585 nm): statistically the unbundled films, the films above
#     500 nm lit on the other side than those below;
#   - an `envmap` (an RGB OpenEXR image rendered by raysweepd) over a grey
#     plate: "auto" takes 16, the bundle's 16 films are bit for bit one
#     another (the map's luminance at every wavelength) and statistically
#     the unbundled films.
name=test_bundle_env
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd raysweep
plugins="$bin/../plugins"
[ -f "$plugins/rayleigh_sky.so" ] || {
  bad "the example plugins must be built in $plugins (make)"
  finish
}
# An RGB environment map: a rendered film (red, green and blue suns on a
# rough conductor, 16x8).
(cd "$root/proto/examples" && "$bin/raysweepd" render hdistant_seed.xml --spp 64 -o "$tmp/env.exr" 2>"$tmp/env.err") ||
  bad "rendering the environment map: $(cat "$tmp/env.err")"
python3 - "$root/proto/examples" "$tmp" <<'PY'
import json, sys
ex, tmp = sys.argv[1], sys.argv[2]
p = json.load(open(f"{ex}/hdistant_lambertian.json"))
p["sensor"]["film"]["width"] = p["sensor"]["film"]["height"] = 16
del p["sun"]
p["sky"] = {"type": "rayleigh_sky", "sky": 0.5}
json.dump(p, open(f"{tmp}/rayleigh.json", "w"))
p["sky"] = {"type": "envmap", "filename": f"{tmp}/env.exr", "scale": 2.0}
p["surface"]["bsdf"]["reflectance"] = 0.4
json.dump(p, open(f"{tmp}/envmap.json", "w"))
b = json.load(open(f"{ex}/../../docs/examples/two_hemispheres.json"))
b["camera"]["film"]["width"] = b["camera"]["film"]["height"] = 16
json.dump(b, open(f"{tmp}/hemispheres.json", "w"))
PY
start_daemon "$tmp/d2" --threads 2 --plugin-dir "$plugins"
p2=$started_port
start_daemon "$tmp/d1" --threads 1 --plugin-dir "$plugins"
p1=$started_port
[ -n "$p1" ] && [ -n "$p2" ] || {
  bad "daemons did not start: $(cat "$tmp/d1/log" "$tmp/d2/log")"
  finish
}
export RSW_JOB_BIN="$bin"
cp "$root/tests/support/bundle_job.py" "$tmp/job.py"

py "an environment plugin: auto takes 16; bundles of 16 and 3 are the unbundled films; bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
ports = [int(sys.argv[2]), int(sys.argv[3])]
auto_agrees(ports, sys.argv[4], WLS, 64, (21, 22), 16)
sid = push(ports[0], sys.argv[4])
a, _ = films(ports[0], sid, 1, 21, WLS)
b, j = films(ports[0], sid, 3, 23, WLS)
assert j["bundle"] == 3, j
agree(a, b, 3)
' "$tmp" "$p2" "$p1" "$tmp/rayleigh.json"

py "an environment plugin in a bundle of 16 and of 3: each film is rho(w) sky (550 / w)^4 (4 standard errors)" '
import sys, math
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[3])
for k in (16, 3):
    f, j = films(port, sid, k, 31, WLS)
    assert j["bundle"] == k, j
    for ctx, fb in f.items():
        w = fb["meta"]["wavelength"]
        nc = len(fb["channels"])
        X, S = fb["data"][0::nc], fb["data"][nc - 1::nc]
        mean, se = sum(X) / len(X), math.sqrt(sum(s * s for s in S)) / len(X)
        want = lerp(w, [400, 550, 700], [0.05, 0.1, 0.45]) * 0.5 * (550 / w) ** 4
        assert abs(mean - want) < 4 * se + 1e-6 * want, (k, ctx, mean, want, se)
' "$tmp" "$p2" "$tmp/rayleigh.json"

py "a bundle across 500 nm under two_hemispheres: the unbundled films, lit from the side of each wavelength" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[3])
wls = [435.0 + 10 * i for i in range(16)]
a, b = bundled_pair(port, sid, wls, 32, (41, 42), 16)
agree(a, b, "two_hemispheres")
def sides(f):
    nc = len(f["channels"]); w = f["width"]; X = f["data"][0::nc]
    left = sum(x for i, x in enumerate(X) if i % w < w // 2)
    return left, sum(X) - left
for ctx, f in b.items():
    left, right = sides(f)
    lit_right = f["meta"]["wavelength"] > 500
    assert (right > 2 * left) if lit_right else (left > 2 * right), (ctx, left, right)
' "$tmp" "$p2" "$tmp/hemispheres.json"

py "an envmap: auto takes 16; the films of the bundle are bit for bit one another and statistically the unbundled films" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[3])
a, b = bundled_pair(port, sid, WLS, 64, (51, 52))
agree(a, b, "envmap")
first = b["w400"]["data"]
for ctx, f in b.items():
    assert f["data"] == first, ctx
' "$tmp" "$p2" "$tmp/envmap.json"
finish
