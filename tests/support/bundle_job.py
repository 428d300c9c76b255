"""Helpers of the spectral-bundle tests (tests/integration/test_bundle_pages.sh,
test_bundle_env.sh): submit a job of wavelength contexts to a daemon, fetch
its films, and compare bundled films with unbundled ones per pixel with
the stderr planes. RSW_JOB_BIN names the directory of the built
binaries (the tests' $bin)."""
import json, os, subprocess, time, urllib.request, urllib.error
BIN = os.environ["RSW_JOB_BIN"]
def call(port, method, path, body=None):
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", method=method,
                                 data=body if body is None or isinstance(body, bytes) else json.dumps(body).encode(),
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=300) as r:
            return r.status, json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"null")
def push(port, path):
    return subprocess.run([f"{BIN}/raysweep", "--server", f"http://127.0.0.1:{port}", "scene", "push", path, "-q"],
                          check=True, capture_output=True, text=True).stdout.strip()
def submit(port, sid, body):
    st, j = call(port, "POST", f"/v1/scenes/{sid}/jobs", body)
    assert st in (200, 201, 202), (st, j)
    for _ in range(6000):
        st, j = call(port, "GET", "/v1/jobs/" + j["id"])
        if j["state"] not in ("queued", "running"):
            break
        time.sleep(0.05)
    assert j["state"] == "succeeded", j
    return j
def films(port, sid, bundle, seed, wls, spp=64, quantities=None):
    body = {"contexts": [{"id": f"w{int(w)}", "wavelength": w} for w in wls],
            "defaults": {"spp": spp}, "variance": True, "seed": seed}
    if bundle is not None:
        body["bundle"] = bundle
    if quantities:
        body["quantities"] = quantities
    j = submit(port, sid, body)
    st, idx = call(port, "GET", "/v1/jobs/" + j["id"] + "/results")
    return {r["context"]: call(port, "GET", r["href"])[1] for r in idx["results"]}, j
WLS = [400.0 + 20 * i for i in range(16)]
def film_z(fa, fb):
    """The difference of two films' means over their combined standard
    error (the stderr planes, their last channel)."""
    import math
    nc = len(fa["channels"])
    A, SA = fa["data"][0::nc], fa["data"][nc - 1::nc]
    B, SB = fb["data"][0::nc], fb["data"][nc - 1::nc]
    return (sum(A) - sum(B)) / math.sqrt(sum(x * x + y * y for x, y in zip(SA, SB)))
def agree(a, b, label):
    """Each bundled film b[ctx] is statistically the unbundled a[ctx]: its
    mean within 4 combined standard errors (the stderr planes), at most 2%
    of its pixels beyond 3 sigma, and over the films the rms of those
    z-scores below 1.4; returns the films' z-scores."""
    import math
    zs = []
    for ctx in a:
        fa, fb = a[ctx], b[ctx]
        nc = len(fa["channels"])
        A, SA = fa["data"][0::nc], fa["data"][nc - 1::nc]
        B, SB = fb["data"][0::nc], fb["data"][nc - 1::nc]
        zs.append(film_z(fa, fb))
        far = sum(1 for x, y, s, t in zip(A, B, SA, SB) if abs(x - y) > 3 * math.sqrt(s * s + t * t)) / len(A)
        assert abs(zs[-1]) < 4, (label, ctx, "film means differ by", zs[-1], "sigma")
        assert far <= 0.02, (label, ctx, far, "of pixels beyond 3 sigma")
    rms = math.sqrt(sum(z * z for z in zs) / len(zs))
    assert rms < 1.4, (label, "rms of the films z-scores", rms)
    return zs
def same_across_threads(ports, path, wls, spp):
    f = [films(p, push(p, path), 16, 11, wls, spp=spp)[0] for p in ports]
    for ctx in f[0]:
        assert f[0][ctx]["data"] == f[1][ctx]["data"], ctx
def lerp(w, x, y):
    """y at w, linear between the nodes x (the scenes' spectra)."""
    for i in range(len(x) - 1):
        if w <= x[i + 1]:
            return y[i] + (y[i + 1] - y[i]) * (w - x[i]) / (x[i + 1] - x[i])
    return y[-1]
def plate_brf(w, tau):
    """hdistant_lambertian.json's plate (its reflectance table) seen at 30
    degrees under its sun at 30 degrees through optical thickness tau(w)."""
    import math
    return lerp(w, [400, 550, 700], [0.05, 0.1, 0.45]) * math.exp(-tau * 2 / 0.8660254037844386)
def layers_tau(w):
    """The 3 layers' optical thickness (their sigma_t tables, mean: 1/3 each)."""
    return sum(lerp(w, [400, 550, 700], v) for v in ([1.2, 0.5, 0.1], [0.6, 0.3, 0.15], [0.9, 0.25, 0.05])) / 3
def bundled_pair(port, sid, wls, spp, seeds, k="auto"):
    """The unbundled films (seeds[0]) and those of bundle k (seeds[1]) of
    scene sid; k "auto" must come to 16 without a reason."""
    a, _ = films(port, sid, 1, seeds[0], wls, spp=spp)
    b, j = films(port, sid, k, seeds[1], wls, spp=spp)
    assert j["bundle"] == (16 if k == "auto" else k) and "bundle_why" not in j, (sid, j)
    return a, b
def auto_agrees(ports, path, wls, spp, seeds, threads_spp):
    """On ports[0]: "auto" takes 16 for the scene at path, and a bundle of 16
    (seeds[1]) is statistically the unbundled films (seeds[0]); bitwise the
    same on both ports (their render threads) at threads_spp."""
    port = ports[0]; sid = push(port, path)
    a, b = bundled_pair(port, sid, wls, spp, seeds)
    agree(a, b, path)
    same_across_threads(ports, path, wls, threads_spp)
def rms_stderr(f):
    """The rms over pixels of film f's standard error plane (its last channel)."""
    nc = len(f["channels"])
    se = f["data"][nc - 1::nc]
    return (sum(x * x for x in se) / len(se)) ** 0.5
