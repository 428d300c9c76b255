#!/usr/bin/env python3
"""tests/integration/test_python_spread.sh's checks of ``Scene.sweep(spread=K)``.

Usage: python_spread_check.py LB_URL REF_URL REPLICA_PORT... --kill PID

Each check prints ``ok   NAME`` or ``FAIL NAME: why``. The reference sweeps
run on one daemon (REF_URL); the spread ones through the balancer (LB_URL).
"""
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(root, "python"))
import raysweep as rs  # noqa: E402
import xarray as xr  # noqa: E402

SCENE = os.path.join(root, "proto", "examples", "hdistant_lambertian.json")


def rendered(port):
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics") as r:
        for line in r.read().decode().splitlines():
            if line.startswith("raysweep_contexts_rendered_total "):
                return float(line.split()[1])
    return 0.0


def jobs_on(ports):
    """The ids of the jobs the replicas hold."""
    out = set()
    for p in ports:
        with urllib.request.urlopen(f"http://127.0.0.1:{p}/v1/jobs") as r:
            out |= {j["id"] for j in json.load(r)["jobs"]}
    return out


# A spread sweep with a journal in a process of its own: argv LB JOURNAL GRID(JSON) SPP.
# SIGINT raises KeyboardInterrupt there as at a terminal: a process started in
# the background by a non-interactive shell (make test) inherits SIGINT
# ignored, and Python then installs no handler of its own.
CHILD = """
import json, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)
sys.path.insert(0, %r)
import raysweep as rs
lb, path, grid, spp = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), int(sys.argv[4])
rs.connect(lb).load_file(%r).sweep(grid=grid, spp=spp, bundle=1, spread=2, journal=path, progress=False)
""" % (os.path.join(root, "python"), SCENE)


def journal_jobs(path, timeout=60.0):
    """The jobs a journal records, once it records one for every shard (None after timeout s)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            with open(path) as f:
                ids = [e["job"] for e in json.load(f)["shards"]]
            if ids and all(ids):
                return ids
        except (OSError, ValueError):
            pass
        time.sleep(0.01)
    return None


def same(ref, got):
    """None when got is ref but for the job attribute, else what differs."""
    a, b = ref.copy(), got.copy()
    a.attrs.pop("job", None)
    b.attrs.pop("job", None)
    try:
        xr.testing.assert_identical(a, b)
    except AssertionError as e:
        return str(e)[:600]
    for v in a.variables:  # (assert_identical leaves a coordinate's attributes out)
        if a[v].attrs != b[v].attrs:
            return f"{v}'s attributes: {a[v].attrs} != {b[v].attrs}"
    return None


def check(name, fn):
    try:
        why = fn()
    except Exception as e:  # noqa: BLE001 (a failed check names what it raised)
        why = f"{type(e).__name__}: {e}"
    print(f"ok   {name}" if why is None else f"FAIL {name}: {why}", flush=True)


def main():
    args = sys.argv[1:]
    kill = int(args[args.index("--kill") + 1])
    lb, ref_url, ports = args[0], args[1], [int(p) for p in args[2:args.index("--kill")]]
    one = rs.connect(ref_url)
    bal = rs.connect(lb)
    # wavelength fastest, 3 x 5: at --bundle 3, groups {0,1,2} {3,4} {5,6,7} ...
    grid = {"surface.bsdf.reflectance.value": [0.2, 0.5, 0.8], "wavelength": [450, 500, 550, 600, 650]}

    for bundle in (None, 1, 3):
        def whole(bundle=bundle):
            ref = one.load_file(SCENE).sweep(grid=grid, spp=8, bundle=bundle, progress=False)
            before = [rendered(p) for p in ports]
            got = bal.load_file(SCENE).sweep(grid=grid, spp=8, bundle=bundle, spread=2, progress=False)
            did = [rendered(p) - b for p, b in zip(ports, before)]
            why = same(ref, got)
            if why:
                return why
            if got.radiance.dims != ("reflectance", "wavelength", "y", "x"):
                return f"dims {got.radiance.dims}"
            if len(got.attrs["job"].split(", ")) != 2 or min(did) == 0 or sum(did) != 15:
                return f"jobs {got.attrs['job']}, contexts rendered per replica {did} (want both, 15 in all)"
            return None
        check(f"spread=2, bundle {bundle}: the unsharded dataset, both replicas rendering", whole)

    def one_axis():
        g = {"wavelength": [400, 450, 500, 550, 600, 650, 700]}
        ref = one.load_file(SCENE).sweep(grid=g, spp=8, bundle=1, progress=False)
        got = bal.load_file(SCENE).sweep(grid=g, spp=8, bundle=1, spread=2, progress=False)
        if got.radiance.dims != ("wavelength", "y", "x") or len(got.attrs["job"].split(", ")) != 2:
            return f"dims {got.radiance.dims}, jobs {got.attrs['job']}"
        return same(ref, got)
    check("spread=2 of one axis (wavelength, bundle 1: two shards): the unsharded dataset", one_axis)

    def bands():
        b = [{"id": "blue", "srf": {"type": "uniform", "wmin": 450, "wmax": 520}},
             {"id": "red", "srf": {"type": "gaussian", "mean": 640, "fwhm": 30}}]
        g = {"surface.bsdf.reflectance.value": [0.2, 0.5, 0.8]}
        ref = one.load_file(SCENE).sweep(grid=g, spp=8, bands=b, quantities=["brf"], variance=True, progress=False)
        got = bal.load_file(SCENE).sweep(grid=g, spp=8, bands=b, quantities=["brf"], variance=True, spread=2,
                                         progress=False)
        if got.brf_srf.dims != ("reflectance", "band", "y", "x"):
            return f"brf_srf dims {got.brf_srf.dims}"
        return same(ref, got)
    check("spread=2 with bands, brf and variance: the unsharded dataset", bands)

    def not_grid():
        ctx = rs.grid_contexts(grid)[::2]  # no complete grid: a context dimension
        ref = one.load_file(SCENE).sweep(contexts=ctx, spp=8, progress=False)
        got = bal.load_file(SCENE).sweep(contexts=ctx, spp=8, spread=2, progress=False)
        if "context" not in got.radiance.dims:
            return f"dims {got.radiance.dims}"
        return same(ref, got)
    check("spread=2 of contexts that are no grid: the unsharded dataset (a context dimension)", not_grid)

    tmp = tempfile.mkdtemp(prefix="rsw-journal-")
    g = {"wavelength": [450, 500, 550, 600], "surface.bsdf.reflectance.value": [0.2, 0.5, 0.8]}
    ref_j = one.load_file(SCENE).sweep(grid=g, spp=1024, bundle=1, progress=False)

    def interrupted(sig, label):
        """A journal sweep's process stopped by sig once its shards' jobs run; the same sweep
        run again here: the unsharded dataset, from the same jobs."""
        path = os.path.join(tmp, f"{label}.json")
        before = jobs_on(ports)
        child = subprocess.Popen([sys.executable, "-c", CHILD, lb, path, json.dumps(g), "1024"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        ids = journal_jobs(path)
        if ids is None:
            child.kill()
            return f"no journal with both shards' jobs after 60 s: {child.communicate()[1][-400:]}"
        child.send_signal(sig)
        err = child.communicate()[1]
        live = set()
        for p in ports:
            with urllib.request.urlopen(f"http://127.0.0.1:{p}/v1/jobs") as r:
                live |= {x["id"] for x in json.load(r)["jobs"] if x["state"] in ("queued", "running", "succeeded")}
        if not set(ids) <= live:
            return f"the journal's jobs {ids} are not all running or done after the signal (live: {sorted(live)})"
        if sig == signal.SIGINT and "keep running" not in err:
            return f"Ctrl-C did not say the jobs keep running: {err[-400:]}"
        t0 = time.monotonic()
        got = bal.load_file(SCENE).sweep(grid=g, spp=1024, bundle=1, spread=2, journal=path, progress=False)
        new = jobs_on(ports) - before
        print(f"  {label}: stopped once both jobs were submitted, resumed in {time.monotonic() - t0:.2f} s, jobs {ids}")
        if new != set(ids):
            return f"jobs submitted: {sorted(new)}, want only the journal's {ids} (nothing submitted again)"
        if sorted(got.attrs["job"].split(", ")) != sorted(ids):
            return f"the dataset's jobs {got.attrs['job']}, want the journal's {ids}"
        if os.path.exists(path):
            return "the journal is still there after the sweep completed"
        return same(ref_j, got)
    check("journal: a sweep whose process is killed resumes its shards' jobs (none submitted again)",
          lambda: interrupted(signal.SIGKILL, "killed"))
    check("journal: Ctrl-C leaves the shards' jobs running, and the same sweep follows them",
          lambda: interrupted(signal.SIGINT, "ctrl-c"))

    def balancer_lost():
        """A journal sweep through a balancer of its own, which goes away once the shards' jobs
        run: the sweep fails naming the journal; through a new balancer (another address), the
        same sweep follows the same jobs."""
        lbs = []

        def balancer():
            pf = os.path.join(tmp, f"lb{len(lbs)}.port")
            lbs.append(subprocess.Popen([sys.executable, os.path.join(root, "tests", "support", "shard_lb.py"), pf]
                                        + [str(p) for p in ports], stderr=subprocess.DEVNULL))
            for _ in range(500):
                if os.path.exists(pf) and open(pf).read().strip():
                    return f"http://127.0.0.1:{open(pf).read().strip()}"
                time.sleep(0.01)
            raise RuntimeError("the test's balancer did not start")
        try:
            path = os.path.join(tmp, "lost.json")
            before = jobs_on(ports)
            child = subprocess.Popen([sys.executable, "-c", CHILD, balancer(), path, json.dumps(g), "1024"],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            ids = journal_jobs(path)
            if ids is None:
                child.kill()
                return f"no journal with both shards' jobs after 60 s: {child.communicate()[1][-400:]}"
            lbs[0].kill()
            t0 = time.monotonic()
            err = child.communicate(timeout=60)[1]
            failed_s = time.monotonic() - t0
            if child.returncode == 0 or "ConnectionFailed" not in err or path not in err:
                return f"the sweep without its balancer: exit {child.returncode}, {err[-500:]}"
            got = rs.connect(balancer()).load_file(SCENE).sweep(grid=g, spp=1024, bundle=1, spread=2, journal=path,
                                                                progress=False)
            new = jobs_on(ports) - before
            print(f"  balancer lost: the sweep failed {failed_s:.2f} s after, naming its journal; resumed through "
                  f"another balancer, jobs {ids}")
            if new != set(ids):
                return f"jobs submitted: {sorted(new)}, want only the journal's {ids} (nothing submitted again)"
            return same(ref_j, got)
        finally:
            for p in lbs:
                p.kill()
                p.wait()
    check("journal: a sweep whose balancer goes away names its journal; through another balancer it resumes",
          balancer_lost)

    def journal_refusals():
        s = bal.load_file(SCENE)
        try:
            s.sweep(grid={"wavelength": [500]}, journal=os.path.join(tmp, "x.json"), progress=False)
            return "journal= without spread= was taken"
        except TypeError as e:
            if "spread=K" not in str(e):
                return f"journal= without spread=: {e}"
        for label, text, words in (("another sweep's", json.dumps({"raysweep": "spread journal", "version": 1,
                                                                   "sweep": "0" * 64, "shards": [
                                                                       {"shard": 0, "key": "k", "base": "k",
                                                                        "tries": 0, "job": "job-x"}]}),
                                    "records another sweep"),
                                   ("a file that is no journal", "[1, 2]", "not a raysweep spread journal")):
            path = os.path.join(tmp, "other.json")
            with open(path, "w") as f:
                f.write(text)
            try:
                s.sweep(grid={"wavelength": [500, 600]}, spp=4, spread=2, journal=path, progress=False)
                return f"{label} journal was taken"
            except ValueError as e:
                if words not in str(e) or path not in str(e):
                    return f"{label} journal: {e}"
            with open(path) as f:
                if f.read() != text:
                    return f"{label} journal was changed"
        return None
    check("journal: without spread=, another sweep's and a file that is no journal are refused", journal_refusals)

    def replica_lost():
        g = {"wavelength": [450, 500, 550, 600, 650, 700], "surface.bsdf.reflectance.value": [0.2, 0.5, 0.8]}
        ref = one.load_file(SCENE).sweep(grid=g, spp=512, bundle=1, progress=False)
        t = threading.Timer(0.5, lambda: os.kill(kill, signal.SIGKILL))
        t.start()
        t0 = time.monotonic()
        got = bal.load_file(SCENE).sweep(grid=g, spp=512, bundle=1, spread=2, progress=False)
        t.join()
        print(f"  replica killed at 0.5 s: the sweep took {time.monotonic() - t0:.2f} s, jobs {got.attrs['job']}")
        return same(ref, got)
    check("a replica killed mid-sweep: its shard runs again elsewhere, the unsharded dataset", replica_lost)

    def warned():
        import warnings
        s = bal.load_file(SCENE)
        with warnings.catch_warnings(record=True) as got:
            warnings.simplefilter("always")
            line = sys._getframe().f_lineno + 1
            s.sweep(grid={"sza": [0, 30]}, spp=4, spread=2, progress=False)
        ours = [w for w in got if issubclass(w.category, rs.SweepWarning)]
        if len(ours) != 1 or ours[0].message.code != "coordinate_unused" or ours[0].message.coordinate != "sza":
            return f"warnings {[str(w.message) for w in got]} (want one coordinate_unused on sza)"
        if ours[0].lineno != line or ours[0].filename != __file__:
            return f"the warning names {ours[0].filename}:{ours[0].lineno}, not the sweep's line {line}"
        # (each shard holds one sza: only the whole sweep's dry run sees the coordinate change nothing)
        return None
    check("a sweep over a coordinate nothing reads warns once, at the caller's line", warned)

    def refusals():
        s = bal.load_file(SCENE)
        for bad, exc, words in ((0, ValueError, "spread must be"), (2.5, ValueError, "spread must be"),
                                (True, ValueError, "spread must be")):
            try:
                s.sweep(grid={"wavelength": [500]}, spread=bad, progress=False)
                return f"spread={bad!r} was taken"
            except exc as e:
                if words not in str(e):
                    return f"spread={bad!r}: {e}"
        try:
            s.submit(grid={"wavelength": [500]}, spread=2)
            return "submit(spread=2) was taken"
        except TypeError as e:
            if "sweep()" not in str(e):
                return f"submit(spread=2): {e}"
        try:
            bal.scene(s.id).sweep(grid={"wavelength": [500]}, spread=2, progress=False)
            return "a scene found by id was spread"
        except TypeError as e:
            if "load_file" not in str(e):
                return f"a scene found by id: {e}"
        edited = one.load_file(SCENE)
        edited.traverse().update({"surface.bsdf.reflectance.value": 0.3})
        try:
            edited.sweep(grid={"wavelength": [500]}, spread=2, progress=False)
            return "an edited scene was spread"
        except rs.RaysweepError as e:
            if "revision 1" not in str(e):
                return f"an edited scene: {e}"
        return None
    check("refuses a bad spread, submit(spread=), a scene found by id, an edited scene", refusals)


if __name__ == "__main__":
    main()
