#!/usr/bin/env bash
# The polarized variant mono_polarized (docs/polarization.md), end to end
# through `raysweepd render`:
#   - a Rayleigh atmosphere over a black and over a Lambertian surface
#     against the published vector radiative-transfer tables of Natraj et
#     al. 2009 (tests/data/natraj2009): at 3 view zeniths x 7 azimuths per
#     case, I, Q and U within 4.5 standard errors of the table's (the stderr
#     planes, 0.26-0.42% of I; fixed seeds), I within 1.5% everywhere and
#     0.5% on average, DoLP within 0.01; and the negative control: the
#     unpolarized mono render misses the tables' I by more than 2.5% on
#     average (the error polarization removes);
#   - where nothing polarizes (a Lambertian plate under the sun), S0 is the
#     mono render bit for bit and S1..S3 are 0;
#   - frame rotations: single scattering at 90 degrees seen by a camera is
#     fully polarized (DoLP 1 to 1e-5 over the pixel's 0.1 degree), and
#     rolling the camera by 30 degrees (right-handed about its view
#     direction: clockwise as its viewer sees it) turns the AoLP by +30
#     degrees (counter-clockwise as the viewer sees it: the scene turned the
#     other way in the image);
#   - rgb_polarized: one render whose ground is black in R and of albedo
#     0.25 in G, each channel against its own table, as above;
#   - the direct integrator's Q/I and U/I are path's where every sample
#     crosses the same Mueller matrix;
#   - a job's films are counted with all their Stokes channels against
#     --max-result-bytes (12 floats a pixel in rgb_polarized);
#   - Mitsuba's `stokes` integrator wrapper renders its nested integrator's
#     film bit for bit, and is refused in an unpolarized variant;
#   - variants named wrongly are refused naming the variant.
name=test_polarization
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd curl "to submit a job to the daemon"
pyx=${RSW_PYTHON:-/usr/bin/python3}
"$pyx" -c 'import numpy' 2>/dev/null || {
  bad "$pyx cannot import numpy (make deps installs python3-numpy)"
  finish
}
rsd="$bin/raysweepd"

# ---- Natraj et al. 2009 --------------------------------------------------
cat >"$tmp/natraj.py" <<'PY'
import json, math, sys
table, case, out, variant, spp = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4], int(sys.argv[5])
d = json.load(open(table))
c = d["cases"][case]
# rgb_polarized: the ground's reflectance per colour channel (argv[6], JSON)
albedo = json.loads(sys.argv[6]) if len(sys.argv) > 6 else c["albedo"]
if isinstance(albedo, list):
    albedo = {"type": "rgb", "value": albedo}
MU = [0.2, 0.52, 0.84]
t0 = math.acos(c["mu0"])
sun = [math.sin(t0), 0.0, math.cos(t0)]  # towards the sun; the light travels towards azimuth 180
dirs = []
for mu in MU:
    th = math.acos(mu)
    for ph in d["phi"]:
        a = math.radians(180.0 - ph)  # the README's convention: a_sun - phi
        dirs += [-math.sin(th) * math.cos(a), -math.sin(th) * math.sin(a), -mu]
W = 1e5
sc = {"type": "scene", "variant": variant,
      "air": {"type": "homogeneous", "sigma_t": c["tau"], "albedo": 1.0, "phase": {"type": "rayleigh"}},
      "slab": {"type": "cube", "to_world": [{"scale": [W, W, 0.5]}, {"translate": [0, 0, 0.5]}],
               "bsdf": {"type": "null"}, "interior": {"type": "ref", "id": "air"}},
      "ground": {"type": "rectangle", "to_world": [{"scale": [W, W, 1]}],
                 "bsdf": {"type": "diffuse", "reflectance": albedo}},
      "sun": {"type": "directional", "direction": [-s for s in sun], "irradiance": math.pi},
      "toa": {"type": "mdistant", "directions": " ".join("%.12g" % x for x in dirs),
              "target": {"type": "rectangle", "to_world": [{"translate": [0, 0, 1]}]},
              "sampler": {"type": "independent", "sample_count": spp},
              "film": {"type": "hdrfilm", "width": len(dirs) // 3, "height": 1,
                       "component_format": "float32", "rfilter": {"type": "box"}}},
      "integrator": {"type": "volpath"}}
json.dump(sc, open(out, "w"))
PY
cat >"$tmp/check.py" <<'PY'
import json, sys
import numpy as np
table, case, pol, mono = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
# rgb_polarized films: colour channel ch of nc (S0.R S0.G S0.B S1.R ...)
ch, nc = (int(sys.argv[5]), 3) if len(sys.argv) > 5 else (0, 1)
d = json.load(open(table))
c = d["cases"][case]
rows = [d["mu"].index(m) for m in (0.2, 0.52, 0.84)]
I, Q, U = (np.array(c[k])[rows] for k in "IQU")
a = np.load(pol)[0]  # 21 pixels: S0..S3 (per colour), then their standard errors
S = a[:, [k * nc + ch for k in range(4)]].reshape(3, 7, 4)
E = a[:, [4 * nc + k * nc + ch for k in range(4)]].reshape(3, 7, 4)
err = np.abs(S[..., 0] - I) / I
dolp = np.hypot(S[..., 1], S[..., 2]) / S[..., 0]
ddolp = np.abs(dolp - np.hypot(Q, U) / I)
zi, zq, zu = (S[..., 0] - I) / E[..., 0], (S[..., 1] - Q) / E[..., 1], (S[..., 2] - U) / E[..., 2]
m = np.load(mono)[0][:, ch].reshape(3, 7)
merr = np.mean(np.abs(m - I) / I)
name = "tau %g albedo %g mu0 %g%s" % (c["tau"], c["albedo"], c["mu0"], " (rgb_polarized, %s)" % "RGB"[ch] if nc == 3 else "")
print("%s: I max err %.4f (mean %.4f, stderr %.4f), DoLP max diff %.4f, max |z| I %.2f Q %.2f U %.2f; "
      "unpolarized I mean err %.4f" % (name, err.max(), err.mean(), np.mean(E[..., 0] / I), ddolp.max(),
                                       np.abs(zi).max(), np.abs(zq).max(), np.abs(zu).max(), merr))
bad = []
if err.max() > 0.015 or err.mean() > 0.005: bad.append("I off by %.4f (mean %.4f)" % (err.max(), err.mean()))
if np.abs(zi).max() > 4.5: bad.append("I beyond 4.5 sigma")
if ddolp.max() > 0.01: bad.append("DoLP off by %.4f" % ddolp.max())
if max(np.abs(zq).max(), np.abs(zu).max()) > 4.5: bad.append("Q/U beyond 4.5 sigma")
if merr < 0.025: bad.append("the unpolarized render matches too well (%.4f): the control cannot fail" % merr)
print("; ".join(bad) if bad else "ok")
PY
data="$root/tests/data/natraj2009/up.json"
# Cases: index 4 t + 2 a + m into up.json (tau 0.02 0.1 0.25 0.5 1, albedo
# 0 0.25, mu0 0.2 0.6): tau 0.25 mu0 0.2 and tau 1 mu0 0.2 over black here,
# tau 0.5 mu0 0.6 over black and over albedo 0.25 in rgb_polarized below
# (thinner ones are too close to unpolarized for the control).
for cs in "8 200000" "16 100000"; do
  set -- $cs
  "$pyx" "$tmp/natraj.py" "$data" "$1" "$tmp/n$1.json" mono_polarized "$2"
  "$pyx" "$tmp/natraj.py" "$data" "$1" "$tmp/m$1.json" mono "$2"
  "$rsd" render "$tmp/n$1.json" --variance -o "$tmp/n$1.npy" >/dev/null 2>"$tmp/err" || bad "render: $(cat "$tmp/err")"
  "$rsd" render "$tmp/m$1.json" -o "$tmp/m$1.npy" >/dev/null 2>"$tmp/err" || bad "render: $(cat "$tmp/err")"
  out=$("$pyx" "$tmp/check.py" "$data" "$1" "$tmp/n$1.npy" "$tmp/m$1.npy" 2>&1)
  echo "  natraj: $out" | head -1
  [ "$(echo "$out" | tail -1)" = ok ] && ok || bad "natraj case $1: $out"
done

# rgb_polarized: one render, the ground black in R and of albedo 0.25 in G
# (B black too): R against case 13's table, G against case 15's; the
# control is the rgb render of the same scene.
"$pyx" "$tmp/natraj.py" "$data" 13 "$tmp/rgbp.json" rgb_polarized 120000 "[0, 0.25, 0]"
"$pyx" "$tmp/natraj.py" "$data" 13 "$tmp/rgb.json" rgb 120000 "[0, 0.25, 0]"
"$rsd" render "$tmp/rgbp.json" --variance -o "$tmp/rgbp.npy" >/dev/null 2>"$tmp/err" || bad "render: $(cat "$tmp/err")"
"$rsd" render "$tmp/rgb.json" -o "$tmp/rgb.npy" >/dev/null 2>"$tmp/err" || bad "render: $(cat "$tmp/err")"
for cc in "13 0" "15 1"; do
  set -- $cc
  out=$("$pyx" "$tmp/check.py" "$data" "$1" "$tmp/rgbp.npy" "$tmp/rgb.npy" "$2" 2>&1)
  echo "  natraj: $out" | head -1
  [ "$(echo "$out" | tail -1)" = ok ] && ok || bad "natraj rgb_polarized channel $2: $out"
done

# ---- nothing polarizes: S0 is the mono film ---------------------------------
"$pyx" - "$root/proto/examples/hdistant_lambertian.json" "$tmp/plate.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
d["variant"] = "mono"
json.dump(d, open(sys.argv[2], "w"))
PY
"$rsd" render "$tmp/plate.json" --spp 64 -o "$tmp/plate_mono.npy" >/dev/null 2>"$tmp/err" || bad "$(cat "$tmp/err")"
"$rsd" render "$tmp/plate.json" --variant mono_polarized --spp 64 -o "$tmp/plate_pol.npy" >/dev/null 2>"$tmp/err" ||
  bad "$(cat "$tmp/err")"
out=$("$pyx" - "$tmp/plate_mono.npy" "$tmp/plate_pol.npy" <<'PY'
import sys
import numpy as np
m, p = np.load(sys.argv[1]), np.load(sys.argv[2])
if p.shape[-1] != 4: print("the polarized film has %d channels" % p.shape[-1])
elif not np.array_equal(p[..., 0], m[..., 0]): print("S0 differs from the mono film (max %g)" % np.abs(p[..., 0] - m[..., 0]).max())
elif np.any(p[..., 1:] != 0): print("S1..S3 are not 0 (max %g)" % np.abs(p[..., 1:]).max())
else: print("ok")
PY
)
[ "$out" = ok ] && ok || bad "plate: $out"

# ---- the Stokes basis turns with the camera ----------------------------------
cat >"$tmp/cam.py" <<'PY'
import json, math, sys
out, roll = sys.argv[1], float(sys.argv[2])
r = math.radians(roll)
up = [0.0, -math.sin(r), math.cos(r)]  # the camera looks along +x; up turned about it
sc = {"type": "scene", "variant": "mono_polarized",
      "air": {"type": "homogeneous", "sigma_t": 0.001, "albedo": 1.0, "phase": {"type": "rayleigh"}},
      "box": {"type": "cube", "to_world": [{"scale": [50, 50, 50]}], "bsdf": {"type": "null"},
              "interior": {"type": "ref", "id": "air"}},
      "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": 1.0},
      "cam": {"type": "perspective", "fov": 0.1, "medium": {"type": "ref", "id": "air"},
              "to_world": [{"lookat": {"origin": [0, 0, 0], "target": [1, 0, 0], "up": up}}],
              "sampler": {"type": "independent", "sample_count": 64},
              "film": {"type": "hdrfilm", "width": 1, "height": 1, "component_format": "float32",
                       "rfilter": {"type": "box"}}},
      "integrator": {"type": "volpath", "max_depth": 2}}
json.dump(sc, open(out, "w"))
PY
for roll in 0 30; do
  "$pyx" "$tmp/cam.py" "$tmp/cam$roll.json" "$roll"
  "$rsd" render "$tmp/cam$roll.json" -o "$tmp/cam$roll.npy" >/dev/null 2>"$tmp/err" || bad "$(cat "$tmp/err")"
done
out=$("$pyx" - "$tmp/cam0.npy" "$tmp/cam30.npy" <<'PY'
import math, sys
import numpy as np
res = []
for f in sys.argv[1:]:
    s = np.load(f).reshape(-1)[:4].astype(float)
    res.append((math.hypot(s[1], s[2]) / s[0], math.degrees(0.5 * math.atan2(s[2], s[1]))))
(d0, a0), (d1, a1) = res
turn = (a1 - a0 + 90.0) % 180.0 - 90.0
print("DoLP %.7f %.7f, AoLP %.4f -> %.4f (turned %.4f)" % (d0, d1, a0, a1, turn))
print("ok" if abs(d0 - 1) < 1e-5 and abs(d1 - 1) < 1e-5 and abs(a0) < 1e-3 and abs(turn - 30) < 1e-3 else "wrong")
PY
)
echo "  rotation: $(echo "$out" | head -1)"
[ "$(echo "$out" | tail -1)" = ok ] && ok || bad "rotation: $out"

# ---- the direct integrator carries the payload: a rough gold plane under
# the sun, seen off the sun's plane by a narrow camera; every light sample
# crosses the same facet matrix, so Q/I and U/I equal path's (max_depth 2)
# to 1e-4, and the light is polarized (DoLP > 0.005; measured 0.013) ----------------
cat >"$tmp/gold.py" <<'PY'
import json, sys
out, integ = sys.argv[1], sys.argv[2]
sc = {"type": "scene", "variant": "mono_polarized",
      "plane": {"type": "rectangle", "to_world": [{"scale": [10, 10, 1]}],
                "bsdf": {"type": "roughconductor", "material": "Au", "alpha": 0.3}},
      "sun": {"type": "directional", "direction": [-0.5, -0.3, -0.81], "irradiance": 1.0},
      "cam": {"type": "perspective", "fov": 0.1,
              "to_world": [{"lookat": {"origin": [0.2, 3, 2], "target": [0, 0, 0], "up": [0, 0, 1]}}],
              "sampler": {"type": "independent", "sample_count": 64},
              "film": {"type": "hdrfilm", "width": 1, "height": 1, "component_format": "float32",
                       "rfilter": {"type": "box"}}},
      "integrator": {"type": "path", "max_depth": 2} if integ == "path" else {"type": "direct"}}
json.dump(sc, open(out, "w"))
PY
for i in path direct; do
  "$pyx" "$tmp/gold.py" "$tmp/gold_$i.json" "$i"
  "$rsd" render "$tmp/gold_$i.json" -o "$tmp/gold_$i.npy" >/dev/null 2>"$tmp/err" || bad "$i: $(cat "$tmp/err")"
done
out=$("$pyx" - "$tmp/gold_path.npy" "$tmp/gold_direct.npy" <<'PY'
import math, sys
import numpy as np
p, d = (np.load(f).reshape(-1)[:4].astype(float) for f in sys.argv[1:])
qp, qd = p[1:3] / p[0], d[1:3] / d[0]
print("path Q/I U/I %s, direct %s" % (qp, qd))
print("ok" if np.abs(qp - qd).max() < 1e-4 and math.hypot(*qd) > 0.005 else "differ")
PY
)
echo "  direct: $(echo "$out" | head -1)"
[ "$(echo "$out" | tail -1)" = ok ] && ok || bad "direct vs path: $out"

# ---- a job's result storage counts every Stokes channel: 12 floats per
# pixel of an rgb_polarized film (the 1x1 camera), 4 of a mono_polarized one
# (a daemon with 10 bytes of result storage refuses naming the size) ----------
start_daemon "$tmp/d" --max-result-bytes 10
if [ -n "$started_port" ]; then
  for v in rgb_polarized:48 mono_polarized:16; do
    sid=$(curl -s -X POST -H 'Content-Type: application/json' --data-binary @"$tmp/cam0.json" \
      "http://127.0.0.1:$started_port/v1/scenes?variant=${v%%:*}" | "$pyx" -c 'import json, sys; print(json.load(sys.stdin)["id"])')
    curl -s -X POST -H 'Content-Type: application/json' -d '{"contexts": [{"id": "c"}]}' \
      "http://127.0.0.1:$started_port/v1/scenes/$sid/jobs" >"$tmp/job.json"
    contains "${v%%:*}: result bytes" "$tmp/job.json" "take ${v##*:} bytes"
  done
else
  bad "daemon did not start: $(cat "$tmp/d/log")"
fi

# ---- Mitsuba's `stokes` wrapper: the nested integrator's films, bit for bit;
# refused in an unpolarized variant --------------------------------------------
"$pyx" - "$tmp/cam0.json" "$tmp/camw.json" "$tmp/camw_mono.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
d["integrator"] = {"type": "stokes", "inner": d["integrator"]}
json.dump(d, open(sys.argv[2], "w"))
d["variant"] = "mono"
json.dump(d, open(sys.argv[3], "w"))
PY
"$rsd" render "$tmp/camw.json" -o "$tmp/camw.npy" >/dev/null 2>"$tmp/err" || bad "stokes wrapper: $(cat "$tmp/err")"
cmp -s "$tmp/camw.npy" "$tmp/cam0.npy" && ok || bad "the stokes wrapper's film differs from its nested integrator's"
"$rsd" render "$tmp/camw_mono.json" -o "$tmp/x.npy" >/dev/null 2>"$tmp/err" && bad "stokes in mono was accepted"
contains "stokes in mono" "$tmp/err" "needs a polarized variant"

# Mitsuba XML as Mitsuba writes it for a polarized variant: the scene's
# variant scalar_mono_polarized and the stokes wrapper (the seed scene, its
# roughconductor made of gold: it polarizes, so S1 is not 0 everywhere; the
# default material, a perfect mirror, only retards p against s).
sed 's/<scene version="2.1.0">/<scene version="2.1.0" variant="scalar_mono_polarized">/;
     s|<integrator type="path"/>|<integrator type="stokes"><integrator type="path"/></integrator>|;
     s|<bsdf type="roughconductor"/>|<bsdf type="roughconductor"><string name="material" value="Au"/></bsdf>|' \
  "$root/proto/examples/hdistant_seed.xml" >"$tmp/seed_pol.xml"
"$rsd" render "$tmp/seed_pol.xml" --spp 16 -o "$tmp/seed_pol.npy" >/dev/null 2>"$tmp/err" || bad "XML: $(cat "$tmp/err")"
out=$("$pyx" - "$tmp/seed_pol.npy" <<'PY'
import sys
import numpy as np
a = np.load(sys.argv[1])
print("ok" if a.shape[-1] == 4 and np.abs(a[..., 1]).max() > 0 and a[..., 0].max() > 0 else
      "shape %s, max |S1| %g" % (a.shape, np.abs(a[..., 1]).max()))
PY
)
[ "$out" = ok ] && ok || bad "XML scalar_mono_polarized + stokes: $out"

# ---- bad variants -------------------------------------------------------------
"$rsd" render "$tmp/plate.json" --variant mono_polarised -o "$tmp/x.npy" >/dev/null 2>"$tmp/err" &&
  bad "an unknown variant was accepted"
contains "unknown variant" "$tmp/err" "mono_polarized"
"$rsd" render "$tmp/plate.json" --variant polarized -o "$tmp/x.npy" >/dev/null 2>"$tmp/err" &&
  bad "variant polarized was accepted"
contains "unknown variant" "$tmp/err" "rgb_polarized"
finish
