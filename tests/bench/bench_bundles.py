#!/usr/bin/env python3
"""make bench: spectral bundles, one JSON line:
  {"bench": "bundles", "scenes": [{"scene", "contexts", "spp",
   "contexts_per_s_k1", "contexts_per_s", "k", "speedup",
   "stderr_ratio_median", "stderr_ratio_max", "speedup_equal_noise"}, ...]}
A 16-wavelength sweep (one job, 16 contexts 400..550 nm by 10 nm) of
  - the molecular atmosphere example (2,400 layers, Rayleigh, ozone and an
    aerosol layer; hdistant 32x32, 64 spp), and
  - the periodic canopy example (hdistant 32x32, 64 spp),
on one raysweepd (--threads 2), submitted over HTTP with "bundle" 1 and
then "auto" (what the daemon chooses: 16 on both, pages of three
wavelengths per path), `k` being what it came to; wall time from
submission to the job's end, films not fetched; best of 3, alternating.
speedup = contexts_per_s at K / at K = 1. The goals: >= 5 for the
atmosphere, >= 8 for the canopy.
A bundle's films are unbiased but may be noisier than unbundled ones at
the same spp (a path sampled for all the bundle's wavelengths fits some
worse: docs/experiments.md#spectral-bundles). So one more pair of jobs
(untimed, with the stderr planes, "variance": true) gives each
wavelength's noise: its film's rms standard error bundled over unbundled,
their median and largest over the 16 wavelengths (stderr_ratio_median,
stderr_ratio_max), and the speedup at equal noise at every wavelength,
speedup_equal_noise = speedup / stderr_ratio_max^2 (spp, and time, grow
with the variance to reach a given standard error).
"""
import json
import os
import subprocess
import sys
import tempfile
import time
import urllib.request

root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
bindir = os.environ.get("RSW_BIN_DIR", os.path.join(root, "build", "bin"))
WLS = [400.0 + 10 * i for i in range(16)]
SPP = 64
K = "auto"


def call(port, method, path, body=None):
    data = body if body is None or isinstance(body, bytes) else json.dumps(body).encode()
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", method=method, data=data,
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=600) as r:
        return json.loads(r.read() or b"null")


def run(port, sid, k):
    body = {"contexts": [{"id": f"w{int(w)}", "wavelength": w} for w in WLS], "defaults": {"spp": SPP},
            "seed": 1, "bundle": k}
    t0 = time.monotonic()
    j = call(port, "POST", f"/v1/scenes/{sid}/jobs", body)
    while j["state"] in ("queued", "running"):
        time.sleep(0.005)
        j = call(port, "GET", f"/v1/jobs/{j['id']}")
    dt = time.monotonic() - t0
    if j["state"] != "succeeded":
        sys.exit(f"bench_bundles: job {j['state']}: {j}")
    call(port, "DELETE", f"/v1/jobs/{j['id']}")
    return dt, j.get("bundle", 1)


def rms_stderr(port, sid, k):
    """Each context's film's rms standard error (its stderr plane), a job
    with "variance": true at bundle k."""
    body = {"contexts": [{"id": f"w{int(w)}", "wavelength": w} for w in WLS], "defaults": {"spp": SPP},
            "seed": 2, "bundle": k, "variance": True}
    j = call(port, "POST", f"/v1/scenes/{sid}/jobs", body)
    while j["state"] in ("queued", "running"):
        time.sleep(0.01)
        j = call(port, "GET", f"/v1/jobs/{j['id']}")
    if j["state"] != "succeeded":
        sys.exit(f"bench_bundles: job {j['state']}: {j}")
    out = {}
    for r in call(port, "GET", f"/v1/jobs/{j['id']}/results")["results"]:
        f = call(port, "GET", r["href"])
        nc = len(f["channels"])
        se = f["data"][nc - 1::nc]  # radiance_stderr.Y, the last channel
        out[r["context"]] = (sum(x * x for x in se) / len(se)) ** 0.5
    call(port, "DELETE", f"/v1/jobs/{j['id']}")
    return out


def main():
    tmp = tempfile.mkdtemp(prefix="rsw-bench-bundles-")
    atmo = json.load(open(os.path.join(root, "proto", "examples", "atmosphere_molecular.json")))
    atmo["measure"]["sampler"]["sample_count"] = SPP
    ap = os.path.join(tmp, "atmosphere.json")
    json.dump(atmo, open(ap, "w"))
    scenes = [("atmosphere_molecular_2400", ap),
              ("canopy_periodic", os.path.join(root, "proto", "examples", "canopy_periodic.json"))]
    pf = os.path.join(tmp, "port")
    d = subprocess.Popen([os.path.join(bindir, "raysweepd"), "serve", "--listen", "127.0.0.1:0", "--port-file", pf,
                          "--threads", "2"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(400):
            if os.path.exists(pf) and open(pf).read().strip():
                break
            time.sleep(0.01)
        port = int(open(pf).read())
        out = []
        for name, path in scenes:
            sid = subprocess.run([os.path.join(bindir, "raysweep"), "--server", f"http://127.0.0.1:{port}", "scene",
                                  "push", path, "-q"], check=True, capture_output=True, text=True).stdout.strip()
            t1, tk = [], []
            for _ in range(3):
                t1.append(run(port, sid, 1)[0])
                dt, k = run(port, sid, K)
                tk.append(dt)
            c1, ck = len(WLS) / min(t1), len(WLS) / min(tk)
            s1, sk = rms_stderr(port, sid, 1), rms_stderr(port, sid, K)
            ratios = sorted(sk[c] / s1[c] for c in s1 if s1[c] > 0)
            med, worst = ratios[len(ratios) // 2], ratios[-1]
            out.append({"scene": name, "contexts": len(WLS), "spp": SPP, "contexts_per_s_k1": round(c1, 2),
                        "contexts_per_s": round(ck, 2), "k": k, "speedup": round(ck / c1, 2),
                        "stderr_ratio_median": round(med, 3), "stderr_ratio_max": round(worst, 3),
                        "speedup_equal_noise": round(ck / c1 / worst ** 2, 2)})
        print(json.dumps({"bench": "bundles", "scenes": out}))
    finally:
        d.terminate()
        d.wait()


if __name__ == "__main__":
    main()
