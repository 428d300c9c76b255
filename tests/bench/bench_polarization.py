#!/usr/bin/env python3
"""make bench: the polarized variants' cost, one JSON line:
  {"bench": "polarization", "scenes": [{"scene", "spp", "s_mono",
   "s_mono_polarized", "s_rgb", "s_rgb_polarized", "cost_mono", "cost_rgb"}, ...]}
Each scene rendered by `raysweepd render --threads 2` in mono, mono_polarized,
rgb and rgb_polarized, best of 3 wall times, alternating; cost = polarized
time / unpolarized time of the same colour variant (docs/polarization.md
states the figure). Scenes:
  - rayleigh_slab: a Rayleigh layer of optical thickness 0.5 over a black
    ground under the sun (the Natraj et al. 2009 geometry of
    tests/integration/test_polarization.sh), 112 view directions, 20,000 spp;
  - seed_hdistant: the hdistant seed scene (RPV and a roughconductor,
    Mitsuba's default perfect mirror, under three suns: a Mueller matrix at
    every mirror bounce that does not polarize sunlight), 800 spp.
The unpolarized variants do not carry the payload: their figures are the
kernel lines' (bench_kernel)."""
import json
import math
import os
import subprocess
import sys
import tempfile
import time

root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
bindir = os.environ.get("RSW_BIN_DIR", os.path.join(root, "build", "bin"))
VARIANTS = ["mono", "mono_polarized", "rgb", "rgb_polarized"]


def slab_scene(path):
    dirs = []
    for mu in [0.02, 0.06, 0.1, 0.16, 0.2, 0.28, 0.32, 0.4, 0.52, 0.64, 0.72, 0.84, 0.92, 0.96, 0.98, 1.0]:
        th = math.acos(mu)
        for ph in range(0, 181, 30):
            a = math.radians(180.0 - ph)
            dirs += [-math.sin(th) * math.cos(a), -math.sin(th) * math.sin(a), -mu]
    t0 = math.acos(0.2)
    w = 1e5
    sc = {"type": "scene",
          "air": {"type": "homogeneous", "sigma_t": 0.5, "albedo": 1.0, "phase": {"type": "rayleigh"}},
          "slab": {"type": "cube", "to_world": [{"scale": [w, w, 0.5]}, {"translate": [0, 0, 0.5]}],
                   "bsdf": {"type": "null"}, "interior": {"type": "ref", "id": "air"}},
          "ground": {"type": "rectangle", "to_world": [{"scale": [w, w, 1]}],
                     "bsdf": {"type": "diffuse", "reflectance": 0.0}},
          "sun": {"type": "directional", "direction": [-math.sin(t0), 0, -math.cos(t0)], "irradiance": math.pi},
          "toa": {"type": "mdistant", "directions": " ".join("%.12g" % x for x in dirs),
                  "target": {"type": "rectangle", "to_world": [{"translate": [0, 0, 1]}]},
                  "sampler": {"type": "independent", "sample_count": 20000},
                  "film": {"type": "hdrfilm", "width": len(dirs) // 3, "height": 1,
                           "component_format": "float32", "rfilter": {"type": "box"}}},
          "integrator": {"type": "volpath"}}
    json.dump(sc, open(path, "w"))


def render(scene, variant, spp, out):
    t0 = time.monotonic()
    subprocess.run([os.path.join(bindir, "raysweepd"), "render", scene, "--variant", variant, "--spp", str(spp),
                    "--threads", "2", "-o", out], check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.monotonic() - t0


def main():
    tmp = tempfile.mkdtemp(prefix="rsw-bench-pol-")
    slab = os.path.join(tmp, "slab.json")
    slab_scene(slab)
    scenes = [("rayleigh_slab", slab, 20000),
              ("seed_hdistant", os.path.join(root, "proto", "examples", "hdistant_seed.xml"), 800)]
    res = []
    for name, path, spp in scenes:
        best = {v: float("inf") for v in VARIANTS}
        for _ in range(3):
            for v in VARIANTS:
                best[v] = min(best[v], render(path, v, spp, os.path.join(tmp, "f.npy")))
        r = {"scene": name, "spp": spp}
        for v in VARIANTS:
            r["s_" + v] = round(best[v], 3)
        r["cost_mono"] = round(best["mono_polarized"] / best["mono"], 3)
        r["cost_rgb"] = round(best["rgb_polarized"] / best["rgb"], 3)
        res.append(r)
    print(json.dumps({"bench": "polarization", "scenes": res}))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
