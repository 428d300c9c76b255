#!/usr/bin/env bash
# Spectral bundles of more than three wavelengths (pages of three per path,
# docs/experiments.md#spectral-bundles), on a periodic canopy whose leaves
# are bilambertian with tabulated reflectance and transmittance (a red
# edge; no transmittance below 500 nm, so a page there never samples
# transmission and the other pages' one-sample MIS must count it), a
# tabulated soil and a tabulated sun; 16 contexts at 400..700 nm:
#   - "bundle": 16 and 7 (pages 6 and 3, the last one partly filled) are
#     statistically the unbundled films: per film, the means within 4
#     combined standard errors (the stderr planes) and at most 2% of pixels
#     beyond 3 sigma (Gaussian: 0.27%), and over the 16 films the rms of
#     those z-scores below 1.4 (measured 0.50 and 0.73; drawing every
#     direction from the first page alone, which never samples the leaves'
#     transmission, gives 1.91 and 1.61); fixed seeds, 64 spp;
#   - a job that names no bundle renders with "auto", the daemon's default
#     (16 here): its films bitwise those of "bundle": "auto" with the same
#     seed, and not those of "bundle": 1 (one seed for its 8 films, not 8);
#   - bitwise the same with 1 and 2 render threads;
#   - each page at its own wavelengths: a Lambertian plate's BRF in a
#     bundle of 16 is its reflectance table at each context's wavelength
#     (closed form, 1e-6; the sun's spectrum differs at each, so each
#     page's horizontal irradiance is its own);
#   - a gold mirror (`conductor`: one delta lobe, drawn alike by every
#     page) under a uniform sky, seen at 30 degrees: `auto` takes 16, and
#     each bundled film is the film of its wavelength rendered alone
#     (within 1e-6: every path sees the mirrored sky, F_Au(30, w)), gold
#     reflecting more than 1.5x as much at 700 nm as at 400;
#   - water that follows the render's wavelength (`ocean_legacy` with
#     "wavelength": "render": each page's channels their own index,
#     whitecaps, underlight and transmittance tables) under a sun and a
#     uniform sky: `auto` takes 16 (and on the same ocean at a fixed
#     550 nm), a bundle of 16 is statistically the unbundled films (the
#     criteria above; measured max |z| 0.87, rms 0.53, <= 0.8% of pixels
#     beyond 3 sigma), bitwise across threads, and per unit of the sun's
#     irradiance the films are brighter at 500 nm than at 700 (1.28x:
#     the underlight of blue water);
#   - through the molecular atmosphere example (piecewise_volpath, 2,400
#     layers, an aerosol layer: chromatic free flights and phase), 16
#     wavelengths 400..550 nm at 128 spp: a bundle of 16 against the
#     unbundled films (the same criteria: measured max |z| 1.57, rms 0.69,
#     <= 0.6% of pixels beyond 3 sigma), and bitwise across threads;
#   - a plastic plate whose spectral diffuse reflectance (0.02 to 0.7)
#     makes its specular lobe's choice differ between the pages, under a
#     sun and a uniform sky: `auto` takes 16, a bundle of 16 is
#     statistically the unbundled films at 256 spp (the criteria above;
#     measured max |z| 2.3, rms 1.13, <= 1.2% of pixels beyond 3 sigma)
#     and bitwise across threads;
#   - a glass pane (`dielectric`, index 1.5, a spectral
#     specular_reflectance) under a spectral sky: `auto` takes 16, and in
#     the bundle each pixel of every film is sky(w) (f_R s(w) + f_T / 1.5^2)
#     with the same fractions f_R of paths reflected and f_T crossed at
#     every wavelength (1e-6, float32 films: every page draws its lobes
#     alike and is weighted by its own value), f_R + f_T = 1 (1e-3, air's
#     index 1.000277), f_R between 0.04 and 0.3 (measured 0.21);
#     bitwise across threads;
#   - through a homogeneous slab (optical thickness 0.6 at 400 nm to 0.2
#     at 700, albedo 0.95 to 0.6, Rayleigh) over a Lambertian plate, under
#     volpath and under piecewise_volpath: `auto` takes 16, a bundle of 16
#     is statistically the unbundled films at 128 spp (the criteria
#     above; measured max |z| 1.41, rms 0.76) and bitwise across threads;
#     with no albedo, each page's BRF seen by a distant sensor is
#     rho(w) exp(-tau(w) (1/mu_s + 1/mu_v)) (closed form, 1e-6: every path
#     is weighted by the exact transmittances); a slab whose extinction
#     spans a factor 9 (0.9 at 400 nm to 0.1 at 700): a bundle of 16 is
#     statistically the unbundled films at 256 spp (film means within 4
#     combined standard errors, rms of their z below 1.4; the pixels'
#     weights are heavy-tailed, so no 3 sigma pixel count), its noisiest film's rms
#     standard error at most 3.5x the unbundled film's (measured 1.80 and
#     2.94 at 400 and 700 nm with the path's hero channel, volpath.c's
#     flight_pages; 4.48 at 400 nm with a channel drawn at each flight);
#     a thick slab (optical thickness 4 at 400 nm to 1 at 700, albedo
#     0.99 to 0.9; 128 spp): the same, its noisiest film at most 2.5x
#     (measured 1.58; 14.5 with a channel drawn at each flight);
#     the same two slabs tracked (a `heterogeneous` grid with a
#     wavelength axis under volpath, the real-or-null choices at the
#     path's hero channel): the same criteria, the noisiest film at most
#     4.2x (measured 3.23 and 3.34; 5.89 and 5.23 with the channels'
#     mean probability at each choice);
#   - grids with a wavelength axis: a piecewise medium whose sigma_t is a
#     gridvolume of 3 layers tabulated at 400, 550 and 700 nm (albedo a
#     spectrum, Rayleigh) over a Lambertian plate, and the molecular
#     atmosphere example with a spectral gridvolume sigma_a: `auto` takes
#     16, a bundle of 16 (400..550 nm) is statistically the unbundled
#     films (the criteria above; measured max |z| 1.67 and 1.54, rms 0.79
#     and 0.72) and bitwise across threads; the same for the layers with
#     a blendphase (rayleigh, hg) whose weight grid has a wavelength axis
#     (chromatic: each channel its own mixture; max |z| 1.27, rms 0.72),
#     and for a blend of that blend and an HG whose own weight is a
#     spectrum (each channel its components' own values);
#     with no
#     albedo, each page's BRF through the layers is
#     rho(w) exp(-tau(w) (1/mu_s + 1/mu_v)) (closed form, 1e-6);
#   - an `mqdiffuse` plate whose grid has a wavelength axis (each channel
#     at its own wavelength): `auto` takes 16, a bundle of 16 is
#     statistically the unbundled films at 64 spp, bitwise across threads;
#   - the molecular atmosphere with a constant sigma_a spectrum (a
#     constvolume): bundles of 3 and of 16 are statistically the
#     unbundled films (before, a bundle read the first wavelength's
#     sigma_a in every channel and page: max |z| far beyond 4);
#   - `direct` (light and BSDF samples with MIS) on the plastic plate
#     under its sun and sky: `auto` takes 16, a bundle of 16 is
#     statistically the unbundled films at 256 spp and bitwise across
#     threads; a Lambertian plate's BRF in a bundle of 16 under `direct`
#     is its reflectance table (closed form, 1e-6);
#   - a blend of a diffuse and a plastic (the plastic's delta lobe inside
#     `blendbsdf`): `auto` takes 16, a bundle of 16 is statistically the
#     unbundled films at 256 spp and bitwise across threads;
#   - a two-sided plastic plate seen from its back (twosided's back side:
#     the nested plastic's delta lobe with wi mirrored): `auto` takes 16,
#     a bundle of 16 is statistically the unbundled films at 256 spp (the
#     criteria above) and bitwise across threads;
#   - tracked media (volpath: delta tracking against the largest page's
#     majorant, each page weighted by its own sigma_s or sigma_n): a
#     heterogeneous medium over a spectral 2x2x2 grid (Rayleigh, spectral
#     albedo) and the molecular atmosphere under volpath: `auto` takes 16,
#     a bundle of 16 is statistically the unbundled films (measured max |z|
#     1.76 and 1.48, rms 0.91 and 0.53) and bitwise across threads; an
#     absorbing heterogeneous medium of 3 layers (ratio tracking of every
#     page at once) at 16,384 spp: each page's BRF within 4 standard
#     errors of the closed form above (measured |z| <= 0.4);
#   - "auto" takes 16 on the canopy (also on a gold roughconductor soil:
#     its index preset per page; on a plastic, a roughplastic and a
#     two-sided plastic soil, a blend of a diffuse and a plastic) and the
#     atmosphere, also under volpath, and on a soil masking a dielectric;
#     a refusal names what stands in the way: 17 (the range);
#   - two delta transmissions told apart by their directions: a plate
#     masking a glass (the pass-through and the refraction) and a blend of
#     two glasses (index 1.5 and 1.33), under a sun and a sky: `auto` takes
#     16, a bundle of 16 is statistically the unbundled films at 256 spp
#     and bitwise across threads.
name=test_bundle_pages
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd raysweep
python3 -c 'import json' || { bad "python3 missing"; finish; }
cp "$root/proto/examples/canopy_leaves.txt" "$tmp/"
python3 - "$root/proto/examples" "$tmp" <<'PY'
import json, sys
ex, tmp = sys.argv[1], sys.argv[2]
d = json.load(open(f"{ex}/canopy_periodic.json"))
wl = [400, 500, 501, 550, 600, 680, 700, 720, 750, 800]
r = [0.04, 0.06, 0.06, 0.12, 0.07, 0.03, 0.10, 0.30, 0.45, 0.48]
t = [0.00, 0.00, 0.04, 0.10, 0.05, 0.01, 0.08, 0.28, 0.42, 0.45]
d["leaf"]["disc"]["bsdf"] = {"type": "bilambertian",
                             "reflectance": {"type": "spectrum", "wavelengths": wl, "values": r},
                             "transmittance": {"type": "spectrum", "wavelengths": wl, "values": t}}
d["soil"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "spectrum", "wavelengths": [400, 800], "values": [0.08, 0.3]}}
d["sun"]["irradiance"] = {"type": "spectrum", "wavelengths": [400, 600, 800], "values": [1.5, 1.8, 1.1]}
json.dump(d, open(f"{tmp}/canopy.json", "w"))
p = json.load(open(f"{ex}/hdistant_lambertian.json"))
p["integrator"] = {"type": "direct"}
json.dump(p, open(f"{tmp}/direct.json", "w"))
p = json.load(open(f"{ex}/hdistant_lambertian.json"))
p["sensor"]["film"]["width"] = p["sensor"]["film"]["height"] = 16
p["sky"] = {"type": "constant", "radiance": 0.2}
p["surface"]["bsdf"] = {"type": "plastic", "diffuse_reflectance": {"type": "spectrum", "wavelengths": [400, 550, 700],
                                                                  "values": [0.02, 0.1, 0.7]}}
json.dump(p, open(f"{tmp}/plastic.json", "w"))
json.dump(dict(p, integrator={"type": "direct"}), open(f"{tmp}/direct_plastic.json", "w"))
q = json.loads(json.dumps(p))
q["surface"]["bsdf"] = {"type": "twosided", "bsdf": p["surface"]["bsdf"]}
q["surface"]["to_world"] = [{"scale": [10, 10, 1]}, {"rotate": {"axis": [1, 0, 0], "angle": 180}}]
json.dump(q, open(f"{tmp}/twosided_back.json", "w"))
q["surface"]["bsdf"] = {"type": "blendbsdf", "weight": 0.5, "bsdf_0": {"type": "diffuse"},
                        "bsdf_1": p["surface"]["bsdf"]}
q["surface"]["to_world"] = p["surface"]["to_world"]
json.dump(q, open(f"{tmp}/blend.json", "w"))
q["surface"]["bsdf"] = {"type": "mask", "opacity": 0.5, "bsdf": {"type": "dielectric"}}
json.dump(q, open(f"{tmp}/mask_glass.json", "w"))
q["surface"]["bsdf"] = {"type": "blendbsdf", "weight": 0.4,
                        "bsdf_0": {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0,
                                   "specular_transmittance": {"type": "spectrum", "wavelengths": [400, 700],
                                                              "values": [0.3, 0.9]}},
                        "bsdf_1": {"type": "dielectric", "int_ior": 1.33, "ext_ior": 1.0}}
json.dump(q, open(f"{tmp}/glasses.json", "w"))
del p["sun"]
p["sky"] = {"type": "constant", "radiance": {"type": "spectrum", "wavelengths": [400, 700], "values": [1.0, 0.3]}}
p["surface"]["bsdf"] = {"type": "dielectric", "int_ior": 1.5,
                        "specular_reflectance": {"type": "spectrum", "wavelengths": [400, 700], "values": [0.9, 0.2]}}
json.dump(p, open(f"{tmp}/glass.json", "w"))
p = json.load(open(f"{ex}/hdistant_lambertian.json"))
p["sensor"]["film"]["width"] = p["sensor"]["film"]["height"] = 16
p["sky"] = {"type": "constant", "radiance": 0.05}
p["surface"]["bsdf"] = {"type": "ocean_legacy", "wavelength": "render", "wind_speed": 5, "wind_direction": 30,
                        "pigmentation": 1.0}
json.dump(p, open(f"{tmp}/sea.json", "w"))
p["surface"]["bsdf"]["wavelength"] = 550
json.dump(p, open(f"{tmp}/sea550.json", "w"))
a = json.load(open(f"{ex}/atmosphere_molecular.json"))
a["integrator"]["type"] = "volpath"
json.dump(a, open(f"{tmp}/volpath.json", "w"))
s = json.load(open(f"{ex}/hdistant_lambertian.json"))
s["sensor"]["film"]["width"] = s["sensor"]["film"]["height"] = 16
s["atmo"] = {"type": "homogeneous", "phase": {"type": "rayleigh"},
             "sigma_t": {"type": "spectrum", "wavelengths": [400, 550, 700], "values": [0.6, 0.35, 0.2]},
             "albedo": {"type": "spectrum", "wavelengths": [400, 700], "values": [0.95, 0.6]}}
s["slab"] = {"type": "cube", "to_world": [{"scale": [1000, 1000, 0.5]}, {"translate": [0, 0, 0.51]}],
             "bsdf": {"type": "null"}, "interior": {"type": "ref", "id": "atmo"}}
for kind in ("volpath", "piecewise"):
    s["integrator"] = {"type": "volpath" if kind == "volpath" else "piecewise_volpath", "max_depth": -1}
    json.dump(s, open(f"{tmp}/slab_{kind}.json", "w"))
    wide = json.loads(json.dumps(s))
    wide["atmo"]["sigma_t"]["values"] = [1.8, 0.6, 0.2]
    json.dump(wide, open(f"{tmp}/wide_{kind}.json", "w"))
    wide["atmo"]["sigma_t"]["values"] = [8, 4, 2]
    wide["atmo"]["albedo"]["values"] = [0.99, 0.9]
    json.dump(wide, open(f"{tmp}/thick_{kind}.json", "w"))
for name, sig, alb in (("wide", [1.8, 0.6, 0.2], [0.95, 0.6]), ("thick", [8, 4, 2], [0.99, 0.9])):
    h = json.loads(json.dumps(s))  # the same slabs, tracked: a grid with a wavelength axis
    h["atmo"] = {"type": "heterogeneous", "phase": {"type": "rayleigh"},
                 "sigma_t": {"type": "gridvolume", "shape": [1, 1, 1, 3], "wavelengths": [400, 550, 700], "data": sig},
                 "albedo": {"type": "spectrum", "wavelengths": [400, 700], "values": alb}}
    h["integrator"] = {"type": "volpath", "max_depth": -1}
    json.dump(h, open(f"{tmp}/het_{name}.json", "w"))
t = dict(s)
t["atmo"] = dict(s["atmo"], albedo=0.0)
t["sensor"] = {"type": "distant", "direction": [-0.5, 0, -0.8660254037844386], "target": [0, 0, 0],
               "sampler": {"type": "independent", "sample_count": 4},
               "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}}
for kind in ("volpath", "piecewise"):
    t["integrator"] = {"type": "volpath" if kind == "volpath" else "piecewise_volpath", "max_depth": -1}
    json.dump(t, open(f"{tmp}/absorb_{kind}.json", "w"))
w = json.loads(json.dumps(s))
del w["atmo"]
w["layers"] = {"type": "piecewise", "phase": {"type": "rayleigh"},
               "sigma_t": {"type": "gridvolume", "shape": [3, 1, 1, 3], "wavelengths": [400, 550, 700],
                           "filter_type": "nearest", "data": [1.2, 0.5, 0.1, 0.6, 0.3, 0.15, 0.9, 0.25, 0.05],
                           "to_world": [{"scale": [2000, 2000, 1]}, {"translate": [-1000, -1000, 0.01]}]},
               "albedo": {"type": "spectrum", "wavelengths": [400, 700], "values": [0.95, 0.6]}}
w["slab"]["interior"]["id"] = "layers"
w["integrator"] = {"type": "piecewise_volpath", "max_depth": -1}
json.dump(w, open(f"{tmp}/layers.json", "w"))
w["layers"]["phase"] = {"type": "blendphase", "phase_0": {"type": "rayleigh"}, "phase_1": {"type": "hg", "g": 0.7},
                        "weight": {"type": "gridvolume", "shape": [3, 1, 1, 3], "wavelengths": [400, 550, 700],
                                   "filter_type": "nearest", "data": [0.8, 0.5, 0.1, 0.4, 0.2, 0.1, 0.0, 0.0, 0.0],
                                   "to_world": w["layers"]["sigma_t"]["to_world"]}}
json.dump(w, open(f"{tmp}/layers_blend.json", "w"))
w["layers"]["phase"] = {"type": "blendphase", "phase_0": w["layers"]["phase"], "phase_1": {"type": "hg", "g": -0.4},
                        "weight": {"type": "spectrum", "wavelengths": [400, 700], "values": [0.1, 0.6]}}
json.dump(w, open(f"{tmp}/layers_nested_blend.json", "w"))
q = json.load(open(f"{ex}/hdistant_lambertian.json"))
q["sensor"]["film"]["width"] = q["sensor"]["film"]["height"] = 16
q["surface"]["bsdf"] = {"type": "mqdiffuse", "grid": {"type": "gridvolume", "shape": [2, 3, 2, 2], "wavelengths": [400, 700],
                        "data": [0.05, 0.4, 0.1, 0.5, 0.08, 0.3, 0.2, 0.6, 0.1, 0.45, 0.05, 0.35,
                                 0.07, 0.5, 0.12, 0.3, 0.06, 0.4, 0.15, 0.55, 0.09, 0.3, 0.1, 0.4]}}
json.dump(q, open(f"{tmp}/mqdiffuse.json", "w"))
w["layers"]["phase"] = {"type": "rayleigh"}
w["layers"]["albedo"] = 0.0
w["sensor"] = t["sensor"]
json.dump(w, open(f"{tmp}/layers_absorb.json", "w"))
h = json.loads(json.dumps(w))
h["layers"] = {"type": "heterogeneous", "sigma_t": w["layers"]["sigma_t"], "albedo": 0.0}
h["integrator"] = {"type": "volpath", "max_depth": -1}
json.dump(h, open(f"{tmp}/het_absorb.json", "w"))
h = json.load(open(f"{tmp}/layers.json"))
h["layers"] = {"type": "heterogeneous", "phase": {"type": "rayleigh"},
               "sigma_t": {"type": "gridvolume", "shape": [2, 2, 2, 3], "wavelengths": [400, 550, 700],
                           "data": [1.2, 0.5, 0.2, 0.4, 0.3, 0.1, 0.9, 0.6, 0.3, 0.2, 0.2, 0.2,
                                    0.5, 0.4, 0.1, 1.0, 0.3, 0.05, 0.3, 0.3, 0.3, 0.7, 0.2, 0.1],
                           "to_world": [{"scale": [20, 20, 1]}, {"translate": [-10, -10, 0.01]}]},
               "albedo": {"type": "spectrum", "wavelengths": [400, 700], "values": [0.95, 0.6]}}
h["integrator"] = {"type": "volpath", "max_depth": -1}
json.dump(h, open(f"{tmp}/het.json", "w"))
a = json.load(open(f"{ex}/atmosphere_molecular.json"))
a["medium_atmosphere"]["sigma_a"] = {"type": "gridvolume", "shape": [1, 1, 1, 3], "wavelengths": [380, 480, 580],
                                     "data": [2e-6, 8e-6, 1e-6]}
json.dump(a, open(f"{tmp}/atmo_sigma_a.json", "w"))
a["medium_atmosphere"]["sigma_a"] = {"type": "spectrum", "wavelengths": [380, 480, 580], "values": [2e-6, 8e-6, 1e-6]}
json.dump(a, open(f"{tmp}/atmo_sigma_a_spectrum.json", "w"))
PY
start_daemon "$tmp/d2" --threads 2
p2=$started_port
start_daemon "$tmp/d1" --threads 1
p1=$started_port
[ -n "$p1" ] && [ -n "$p2" ] || { bad "daemons did not start: $(cat "$tmp/d1/log" "$tmp/d2/log")"; finish; }

export RSW_JOB_BIN="$bin"
cp "$root/tests/support/bundle_job.py" "$tmp/job.py"

py "bundles of 16 and of 7 are statistically the unbundled films (one-sample MIS over the pages)" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[3])
a, _ = films(port, sid, 1, 7, WLS)
for k, seed in ((16, 8), (7, 9)):
    b, j = films(port, sid, k, seed, WLS)
    assert j["bundle"] == k, j
    agree(a, b, k)
    seeds = {}
    for ctx, fb in b.items():
        assert fb["meta"]["wavelength"] == float(ctx[1:]), (ctx, fb["meta"])
        seeds.setdefault(fb["meta"]["seed"], []).append(ctx)
    want = [16] if k == 16 else [2, 7, 7]
    assert sorted(len(v) for v in seeds.values()) == want, (k, seeds)
' "$tmp" "$p2" "$tmp/canopy.json"

py "a job that names no bundle renders with auto, the default: 16 here, its films bitwise those of auto, not those of bundle 1" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[3])
d, jd = films(port, sid, None, 5, WLS[:8], spp=8)
a, ja = films(port, sid, "auto", 5, WLS[:8], spp=8)
o, jo = films(port, sid, 1, 5, WLS[:8], spp=8)
assert jd["bundle"] == ja["bundle"] == 16 and jo["bundle"] == 1, (jd.get("bundle"), ja.get("bundle"), jo.get("bundle"))
assert all(d[c]["data"] == a[c]["data"] for c in a), "default and auto differ"
assert sum(d[c]["data"] != o[c]["data"] for c in o) >= 7, "the default renders as bundle 1 does"
assert len({d[c]["meta"]["seed"] for c in d}) == 1 and len({o[c]["meta"]["seed"] for c in o}) == 8
' "$tmp" "$p2" "$tmp/canopy.json"

py "a bundle of 16 is bitwise the same with 1 and 2 render threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
same_across_threads([int(p) for p in sys.argv[2:4]], sys.argv[4], WLS, 8)
' "$tmp" "$p1" "$p2" "$tmp/canopy.json"

py "each page at its own wavelengths: a Lambertian plate's BRF in a bundle of 16 is its reflectance table (closed form)" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[3])
wls = [400.0 + 19 * i for i in range(16)]
f, j = films(port, sid, 16, 3, wls, spp=4, quantities=["brf"])
def rho(w):  # the example'"'"'s table: (400, 0.05), (550, 0.1), (700, 0.45)
    return 0.05 + (w - 400) / 150 * 0.05 if w <= 550 else 0.1 + (w - 550) / 150 * 0.35
seeds = set()
for ctx, x in f.items():
    n = len(x["channels"]); w = x["meta"]["wavelength"]; seeds.add(x["meta"]["seed"])
    brf = x["data"][x["channels"].index("brf.Y")::n]
    assert all(abs(b - rho(w)) < 1e-6 for b in brf), (w, brf[:3], rho(w))
assert len(seeds) == 1 and len(f) == 16, seeds
' "$tmp" "$p2" "$root/proto/examples/hdistant_lambertian.json"

py "a gold mirror (conductor: one delta lobe, its index per page) under a uniform sky: a bundle of 16 gives the film of each wavelength alone" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
import json
port = int(sys.argv[2])
mirror = {"type": "scene", "variant": "mono",
          "meter": {"type": "distant", "direction": [-0.5, 0, -0.8660254037844386], "target": [0, 0, 0],
                    "sampler": {"type": "independent", "sample_count": 4},
                    "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}},
          "integrator": {"type": "path", "max_depth": -1},
          "sky": {"type": "constant", "radiance": 1.0},
          "plate": {"type": "rectangle", "to_world": [{"scale": [10, 10, 1]}],
                    "bsdf": {"type": "conductor", "material": "Au"}}}
json.dump(mirror, open(sys.argv[1] + "/mirror.json", "w"))
sid = push(port, sys.argv[1] + "/mirror.json")
wls = [400.0 + 20 * i for i in range(16)]
b, j = films(port, sid, "auto", 3, wls, spp=4)
assert j["bundle"] == 16 and "bundle_why" not in j, j
o, _ = films(port, sid, 1, 3, wls, spp=4)
R = {w: b["w%d" % int(w)]["data"][0] for w in wls}
for w in wls:   # every path sees the mirrored sky: R(w) = F_Au(30 deg, w), no noise
    x = o["w%d" % int(w)]["data"][0]
    assert abs(R[w] - x) <= 1e-6 * x, (w, R[w], x)
assert R[700.0] > 1.5 * R[400.0] and len(set(b[c]["meta"]["seed"] for c in b)) == 1, R
' "$tmp" "$p2"

py "water that follows the render (ocean_legacy \"render\"): auto takes 16 (also at a fixed wavelength); a bundle of 16 is statistically the unbundled films, and bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[4])
a, b = bundled_pair(port, sid, WLS, 64, (7, 8))
zs = agree(a, b, "ocean")
assert len({b[c]["meta"]["seed"] for c in b}) == 1
lev = {c: sum(a[c]["data"][0::len(a[c]["channels"])]) for c in a}
# Per unit of the sun (1.9 at 500 nm, 1.4 at 700): underlight in blue water, little at 700 nm.
assert lev["w500"] / 1.9 > 1.15 * lev["w700"] / 1.4, lev
j = submit(port, push(port, sys.argv[5]), {"contexts": [{"id": "a", "wavelength": 500}, {"id": "b", "wavelength": 510},
                                                       {"id": "c", "wavelength": 520}, {"id": "d", "wavelength": 530}],
                                           "defaults": {"spp": 1}})
assert j["bundle"] == 16 and "bundle_why" not in j, j
same_across_threads([int(p) for p in sys.argv[2:4]], sys.argv[4], WLS[:8], 8)
' "$tmp" "$p2" "$p1" "$tmp/sea.json" "$tmp/sea550.json"

py "plastic (a delta lobe whose choice differs between the pages): auto takes 16, a bundle of 16 is statistically the unbundled films, and bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
auto_agrees([int(p) for p in sys.argv[2:4]], sys.argv[4], WLS, 256, (7, 8), 8)
' "$tmp" "$p2" "$p1" "$tmp/plastic.json"

py "direct: a plastic under a sun and a sky (light and BSDF samples, MIS, a delta lobe): auto takes 16, a bundle of 16 is statistically the unbundled films, and bitwise across threads; a Lambertian plate's BRF in a bundle of 16 is its reflectance table (closed form)" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
auto_agrees([int(p) for p in sys.argv[2:4]], sys.argv[4], WLS, 256, (41, 42), 8)
port = int(sys.argv[2])
wls = [400.0 + 19 * i for i in range(16)]
f, j = films(port, push(port, sys.argv[5]), 16, 3, wls, spp=4, quantities=["brf"])
def rho(w):  # hdistant_lambertian.json: (400, 0.05), (550, 0.1), (700, 0.45)
    return 0.05 + (w - 400) / 150 * 0.05 if w <= 550 else 0.1 + (w - 550) / 150 * 0.35
for ctx, x in f.items():
    n = len(x["channels"]); w = x["meta"]["wavelength"]
    brf = x["data"][x["channels"].index("brf.Y")::n]
    assert all(abs(v - rho(w)) < 1e-6 for v in brf), (w, brf[:3], rho(w))
' "$tmp" "$p2" "$p1" "$tmp/direct_plastic.json" "$tmp/direct.json"

py "a blend of a diffuse and a plastic (a composition over a delta lobe): auto takes 16, a bundle of 16 is statistically the unbundled films, and bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
auto_agrees([int(p) for p in sys.argv[2:4]], sys.argv[4], WLS, 256, (41, 42), 8)
' "$tmp" "$p2" "$p1" "$tmp/blend.json"

py "a two-sided plastic seen from its back (twosided: the back side's delta lobe, wi mirrored): auto takes 16, a bundle of 16 is statistically the unbundled films, and bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
auto_agrees([int(p) for p in sys.argv[2:4]], sys.argv[4], WLS, 256, (17, 18), 8)
' "$tmp" "$p2" "$p1" "$tmp/twosided_back.json"

py "a glass pane (dielectric, one index, a spectral specular_reflectance) under a spectral sky: in a bundle of 16 every film is the same reflections, each page weighted by its own reflectance" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[4])
b, j = films(port, sid, "auto", 8, WLS, spp=64)
assert j["bundle"] == 16 and "bundle_why" not in j, j
def lerp(w, a, b): return a + (b - a) * (w - 400) / 300
# Per pixel, film(w) = sky(w) (f_R s(w) + f_T / 1.5^2): f_R, f_T the fractions of its paths that
# reflected and that crossed the pane (to the sky below), the same at every page; from 400 and 700 nm:
F = {c: [x / lerp(b[c]["meta"]["wavelength"], 1.0, 0.3) for x in b[c]["data"][0::len(b[c]["channels"])]] for c in b}
fR = [(x - y) / 0.7 for x, y in zip(F["w400"], F["w700"])]
fT = [(y - r * 0.2) * 2.25 for r, y in zip(fR, F["w700"])]
assert all(abs(r + t - 1) < 1e-3 for r, t in zip(fR, fT)), "every path reflects or crosses"  # (air: 1.000277)
for c in F:
    s_w = lerp(b[c]["meta"]["wavelength"], 0.9, 0.2)
    assert all(abs(x - (r * s_w + t / 2.25)) < 1e-6 for x, r, t in zip(F[c], fR, fT)), c  # (float32 films)
R = sum(fR) / len(fR)   # Fresnel of 1.5 over the view zeniths: 0.04 at normal incidence, more towards grazing
assert 0.04 < R < 0.3 and len({b[c]["meta"]["seed"] for c in b}) == 1, R
same_across_threads([int(p) for p in sys.argv[2:4]], sys.argv[4], WLS, 8)
' "$tmp" "$p2" "$p1" "$tmp/glass.json"

py "through the molecular atmosphere (piecewise_volpath, aerosols): a bundle of 16 is statistically the unbundled films, and bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[4])
wls = [400.0 + 10 * i for i in range(16)]
a, b = bundled_pair(port, sid, wls, 128, (7, 8), 16)
agree(a, b, "atmosphere")
same_across_threads([int(p) for p in sys.argv[2:4]], sys.argv[4], wls, 4)
' "$tmp" "$p2" "$p1" "$root/proto/examples/atmosphere_molecular.json"

py "through a homogeneous slab (spectral sigma_t and albedo, Rayleigh), under volpath and piecewise_volpath: auto takes 16, a bundle of 16 is statistically the unbundled films, and bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
for path in sys.argv[4:6]:
    auto_agrees([int(p) for p in sys.argv[2:4]], path, WLS, 128, (21, 22), 16)
' "$tmp" "$p2" "$p1" "$tmp/slab_volpath.json" "$tmp/slab_piecewise.json"

py "a slab whose extinction spans a factor 9 (optical thickness 0.9 at 400 nm, 0.1 at 700), and a thick one (4 to 1): a bundle of 16 is statistically the unbundled films, its noisiest film at most 3.5x (2.5x) the standard error of the unbundled one (path-level spectral MIS: a hero channel per path)" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2])
for path, spp, most in ((sys.argv[3], 256, 3.5), (sys.argv[4], 256, 3.5), (sys.argv[5], 128, 2.5)):
    sid = push(port, path)
    a, b = bundled_pair(port, sid, WLS, spp, (31, 32))
    zs = [film_z(a[c], b[c]) for c in a]  # (heavy tails: pixel stderrs too low for the 3 sigma count)
    assert max(abs(z) for z in zs) < 4 and (sum(z * z for z in zs) / len(zs)) ** 0.5 < 1.4, (path, zs)
    worst = max(rms_stderr(b[c]) / rms_stderr(a[c]) for c in a)
    assert worst < most, (path, "stderr ratio", worst)
' "$tmp" "$p2" "$tmp/wide_volpath.json" "$tmp/wide_piecewise.json" "$tmp/thick_piecewise.json"

py "the same two slabs tracked (heterogeneous, volpath): a bundle of 16 is statistically the unbundled films, its noisiest film at most 4.2x the standard error of the unbundled one (the real-or-null choices at the path's hero channel)" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2])
for path, spp in ((sys.argv[3], 256), (sys.argv[4], 128)):
    sid = push(port, path)
    a, b = bundled_pair(port, sid, WLS, spp, (31, 32))
    zs = [film_z(a[c], b[c]) for c in a]
    assert max(abs(z) for z in zs) < 4 and (sum(z * z for z in zs) / len(zs)) ** 0.5 < 1.4, (path, zs)
    worst = max(rms_stderr(b[c]) / rms_stderr(a[c]) for c in a)
    assert worst < 4.2, (path, "stderr ratio", worst)
' "$tmp" "$p2" "$tmp/het_wide.json" "$tmp/het_thick.json"

py "an absorbing homogeneous slab in a bundle of 16: each page's BRF is rho(w) exp(-tau(w) (1/mu_s + 1/mu_v)) (closed form), under volpath and piecewise_volpath" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
wls = [400.0 + 19 * i for i in range(16)]
port = int(sys.argv[2])
for path in sys.argv[3:5]:
    f, j = films(port, push(port, path), 16, 4, wls, spp=16, quantities=["brf"])
    assert j["bundle"] == 16 and len(f) == 16, j
    for ctx, x in f.items():
        n = len(x["channels"]); w = x["meta"]["wavelength"]
        brf = x["data"][x["channels"].index("brf.Y")::n]
        want = plate_brf(w, lerp(w, [400, 550, 700], [0.6, 0.35, 0.2]))
        assert all(abs(b - want) < 1e-6 for b in brf), (path, w, brf, want)
' "$tmp" "$p2" "$tmp/absorb_volpath.json" "$tmp/absorb_piecewise.json"

py "grids with a wavelength axis: a piecewise medium over a spectral sigma_t grid, and the molecular atmosphere with a spectral sigma_a grid: auto takes 16, a bundle of 16 is statistically the unbundled films, and bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
wls = [400.0 + 10 * i for i in range(16)]
for path, spp in ((sys.argv[4], 128), (sys.argv[5], 64), (sys.argv[6], 128), (sys.argv[7], 128)):
    auto_agrees([int(p) for p in sys.argv[2:4]], path, wls, spp, (41, 42), 4)
' "$tmp" "$p2" "$p1" "$tmp/layers.json" "$tmp/atmo_sigma_a.json" "$tmp/layers_blend.json" "$tmp/layers_nested_blend.json"

py "an mqdiffuse plate whose grid has a wavelength axis: auto takes 16, a bundle of 16 is statistically the unbundled films, and bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
auto_agrees([int(p) for p in sys.argv[2:4]], sys.argv[4], WLS, 64, (43, 44), 4)
' "$tmp" "$p2" "$p1" "$tmp/mqdiffuse.json"

py "the molecular atmosphere with a constant sigma_a spectrum: a bundle of 3 and of 16 is statistically the unbundled films (each channel its own absorption; a bundle once gave every channel the first wavelength's)" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2]); sid = push(port, sys.argv[3])
wls = [400.0 + 10 * i for i in range(16)]
a, _ = films(port, sid, 1, 41, wls, spp=64)
for k in (3, 16):
    b, j = films(port, sid, k, 42, wls, spp=64)
    assert j["bundle"] == k, j
    agree(a, b, f"sigma_a spectrum, bundle {k}")
' "$tmp" "$p2" "$tmp/atmo_sigma_a_spectrum.json"

py "tracked media (volpath): a heterogeneous medium over a spectral 3-D grid, and the molecular atmosphere: auto takes 16, a bundle of 16 is statistically the unbundled films, and bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
for path, spp, wls in ((sys.argv[4], 128, WLS), (sys.argv[5], 64, [400.0 + 10 * i for i in range(16)])):
    auto_agrees([int(p) for p in sys.argv[2:4]], path, wls, spp, (41, 42), 4)
' "$tmp" "$p2" "$p1" "$tmp/het.json" "$tmp/volpath.json"

py "ratio tracking for every page at once: an absorbing heterogeneous medium of 3 layers over a spectral grid (volpath), a bundle of 16: each page's BRF is within 4 standard errors of rho(w) exp(-tau(w) (1/mu_s + 1/mu_v))" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
wls = [400.0 + 19 * i for i in range(16)]
port = int(sys.argv[2])
f, j = films(port, push(port, sys.argv[3]), 16, 6, wls, spp=16384, quantities=["brf"])
assert j["bundle"] == 16 and len(f) == 16, j
for ctx, x in f.items():
    d = dict(zip(x["channels"], x["data"])); w = x["meta"]["wavelength"]
    want = plate_brf(w, layers_tau(w))
    se = d["radiance_stderr.Y"] * d["brf.Y"] / d["Y"]
    assert 0 < se < 0.05 * want and abs(d["brf.Y"] - want) < 4 * se, (w, d, want)
' "$tmp" "$p2" "$tmp/het_absorb.json"

py "an absorbing piecewise medium over a spectral grid in a bundle of 16: each page's BRF is rho(w) exp(-tau(w) (1/mu_s + 1/mu_v)), tau(w) the layers' mean sigma_t(w) (closed form)" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
wls = [400.0 + 19 * i for i in range(16)]
port = int(sys.argv[2])
f, j = films(port, push(port, sys.argv[3]), 16, 4, wls, spp=16, quantities=["brf"])
assert j["bundle"] == 16 and len(f) == 16, j
for ctx, x in f.items():
    n = len(x["channels"]); w = x["meta"]["wavelength"]
    brf = x["data"][x["channels"].index("brf.Y")::n]
    want = plate_brf(w, layers_tau(w))
    assert all(abs(b - want) < 1e-6 for b in brf), (w, brf, want)
' "$tmp" "$p2" "$tmp/layers_absorb.json"

py "auto takes 16 on the canopy and the atmosphere (also under volpath); refusals name what stands in the way" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
port = int(sys.argv[2])
assert call(port, "GET", "/v1")[1]["limits"]["max_bundle"] == 16
ctx = [{"id": f"w{w}", "wavelength": w} for w in (500, 510, 520, 530)]
j = submit(port, push(port, sys.argv[3]), {"contexts": ctx, "defaults": {"spp": 2}, "bundle": "auto"})
assert j["bundle"] == 16 and "bundle_why" not in j, j
atmo = push(port, sys.argv[4])
j = submit(port, atmo, {"contexts": ctx, "defaults": {"spp": 1}, "bundle": "auto"})
assert j["bundle"] == 16 and "bundle_why" not in j, j
import json
canopy = json.load(open(sys.argv[3]))
for soil, k, words in (({"type": "roughconductor", "material": "Au", "alpha": 0.3}, 16, []),
                       ({"type": "plastic", "diffuse_reflectance": 0.3}, 16, []),
                       ({"type": "roughplastic", "diffuse_reflectance": 0.3}, 16, []),
                       ({"type": "twosided", "bsdf": {"type": "plastic"}}, 16, []),
                       ({"type": "blendbsdf", "weight": 0.5, "bsdf_0": {"type": "diffuse"},
                         "bsdf_1": {"type": "plastic"}}, 16, []),
                       ({"type": "mask", "opacity": 0.5, "bsdf": {"type": "dielectric"}}, 16, [])):
    canopy["soil"]["bsdf"] = soil
    path = sys.argv[1] + "/canopy_" + soil["type"] + ".json"
    json.dump(canopy, open(path, "w"))
    j = submit(port, push(port, path), {"contexts": ctx, "defaults": {"spp": 1}, "bundle": "auto"})
    assert j["bundle"] == k and all(w in j.get("bundle_why", "") for w in words), (soil, j)
vol = push(port, sys.argv[7])
j = submit(port, vol, {"contexts": ctx, "defaults": {"spp": 1}, "bundle": "auto"})
assert j["bundle"] == 16 and "bundle_why" not in j, j
def refuse(sid, bundle, words):
    st, p = call(port, "POST", f"/v1/scenes/{sid}/jobs", {"contexts": ctx, "bundle": bundle})
    assert st == 422 and p.get("pointer") == "/bundle", (st, p)
    for w in words:
        assert w in p["detail"], (w, p["detail"])
refuse(atmo, 17, ["from 1", "to 16"])
' "$tmp" "$p2" "$tmp/canopy.json" "$root/proto/examples/atmosphere_molecular.json" "$tmp/direct.json" "$tmp/mask_glass.json" "$tmp/volpath.json"

py "two delta transmissions told apart by their directions (a plate masking a glass, a blend of two glasses): auto takes 16, a bundle of 16 is statistically the unbundled films, and bitwise across threads" '
import sys
sys.path.insert(0, sys.argv[1]); from job import *
for path in sys.argv[4:6]:
    auto_agrees([int(p) for p in sys.argv[2:4]], path, WLS, 256, (61, 62), 16)
' "$tmp" "$p2" "$p1" "$tmp/mask_glass.json" "$tmp/glasses.json"
finish
