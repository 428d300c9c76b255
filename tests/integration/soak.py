#!/usr/bin/env python3
"""The concurrency soak of tests/integration/test_soak.sh (issue 22 item 6).

  soak.py --port P --pid DAEMON_PID --seconds S [--clients 32] [--no-rss]

Three small mono scenes: A and B are PATCHed all the time (their keys
plate.bsdf.reflectance.value and sun.irradiance.value), C never. Every
render and every job context overrides both keys of A and B with one of
two values each (C: no overrides), so what a film must be does not depend
on the PATCHes racing it: it is a pure function of (scene, values, sensor,
spp, seed, wavelength). The references are those films rendered first, one
request at a time, on the same daemon.

Then CLIENTS threads for SECONDS seconds, each on its own keep-alive
connection, loop over a mix: PATCH (A or B), render with overrides (npy),
a job of 2 to 4 contexts (waited for, each film fetched as npy, the job
deleted), a scene DELETE (then posted again), and a scene POST. The daemon
runs with a scene budget that holds about two of the three scenes, so
posts evict. A 404 (scene evicted or deleted) posts the scene again and
moves on; 409 (in use) and 412 are accepted. Every film must be bitwise
(byte for byte, npy) the reference; any other status, a 5xx included, is a
failure.

RSS: VmRSS of the daemon is read from /proc at a third of the run and at
its end; the end may exceed the first by at most 8 MiB + 10 % (the
tolerance covers allocator arenas settling; a leak of one film or request
body per operation, thousands of operations, exceeds it).

Prints one line per failure (FAIL ...), the counts, and
"soak: N passed, N failed"; exit 1 if any failed."""
import argparse
import http.client
import json
import random
import sys
import threading
import time

SPP, SEED, WL = 8, 7, 550.0
VALUES = {"plate.bsdf.reflectance.value": (0.2, 0.6), "sun.irradiance.value": (1.0, 2.5)}
SENSORS = ("hd", "cam")


def scene_doc(tag, size):
    # tag makes the three documents (and so their ids) differ.
    return json.dumps({
        "type": "scene", "variant": "mono",
        "hd": {"type": "hdistant", "film": {"type": "hdrfilm", "width": size, "height": size}},
        "cam": {"type": "perspective", "fov": 40,
                "to_world": [{"lookat": {"origin": [0, -3, 4], "target": [0, 0, 0], "up": [0, 0, 1]}}],
                "film": {"type": "hdrfilm", "width": size, "height": size}},
        "integrator": {"type": "path", "max_depth": 4},
        "sun": {"type": "directional", "direction": [0.3, 0.2, -0.9], "irradiance": 1.5},
        "plate": {"type": "rectangle", "to_world": [{"scale": [4, 4, 1]}],
                  "bsdf": {"type": "diffuse", "reflectance": 0.4}},
        "ball": {"type": "sphere", "center": [0, 0, 0.6], "radius": 0.5 + 0.1 * tag,
                 "bsdf": {"type": "roughconductor", "alpha": 0.2}},
    })


DOCS = {"A": scene_doc(0, 8), "B": scene_doc(1, 8), "C": scene_doc(2, 6)}
PATCHED = ("A", "B")


class Client:
    def __init__(self, port):
        self.port = port
        self.c = None

    def req(self, method, path, body=None, headers=None):
        h = dict(headers or {})
        data = None
        if body is not None:
            data = body.encode() if isinstance(body, str) else body
            h.setdefault("Content-Type", "application/json")
        for attempt in range(3):
            if self.c is None:
                self.c = http.client.HTTPConnection("127.0.0.1", self.port, timeout=120)
            try:
                self.c.request(method, path, body=data, headers=h)
                r = self.c.getresponse()
                return r.status, r.read()
            except (http.client.HTTPException, OSError):
                # A keep-alive connection the server closed between
                # requests: a new one (at most twice).
                self.c.close()
                self.c = None
                if attempt == 2:
                    raise
        raise RuntimeError("unreachable")


class Soak:
    def __init__(self, port, ids):
        self.port = port
        self.ids = ids
        self.refs = {}
        self.lock = threading.Lock()
        self.fails = []
        self.counts = {}
        self.films_checked = 0

    def fail(self, msg):
        with self.lock:
            if len(self.fails) < 50:
                self.fails.append(msg)

    def count(self, what):
        with self.lock:
            self.counts[what] = self.counts.get(what, 0) + 1

    def push(self, cl, name):
        st, body = cl.req("POST", "/v1/scenes", DOCS[name])
        if st not in (200, 201):
            self.fail("POST scene %s: %d %s" % (name, st, body[:200]))
            return False
        # A document yields its own state (docs/daemon.md): the first
        # scene while it is unchanged, else a scene of its own loaded from
        # the same document, which this soak does not use (deleted).
        ans = json.loads(body)
        got = ans["id"]
        if ans.get("document") != self.ids[name]:
            self.fail("scene %s posted again is of document %s, not %s" % (name, ans.get("document"), self.ids[name]))
        elif got != self.ids[name]:
            if ans.get("revision") != 0:  # 201, or 200 when another client posted it first
                self.fail("scene %s posted again: another scene %s, at revision %s" % (name, got, ans.get("revision")))
            self.count("fork")
            cl.req("DELETE", "/v1/scenes/" + got, None)
        return True

    def overrides(self, name, rnd):
        if name not in PATCHED:
            return {}
        return {k: rnd.choice(v) for k, v in VALUES.items()}

    @staticmethod
    def key(name, params, sensor):
        return (name, tuple(sorted(params.items())), sensor)

    def render(self, cl, name, params, sensor):
        req = {"sensor": sensor, "spp": SPP, "seed": SEED, "wavelength": WL}
        if params:
            req["params"] = params
        return cl.req("POST", "/v1/scenes/%s:render" % self.ids[name], json.dumps(req),
                      {"Accept": "application/x-npy"})

    def check_film(self, what, k, got):
        ref = self.refs.get(k)
        if ref is None:
            self.fail("%s: no reference for %r" % (what, k))
        elif got != ref:
            self.fail("%s: film %r differs from the one served alone (%d vs %d bytes)" % (what, k, len(got), len(ref)))
        else:
            with self.lock:
                self.films_checked += 1

    # ---- the references, one request at a time --------------------------------------
    def references(self):
        cl = Client(self.port)
        for name in DOCS:
            combos = [{}] if name not in PATCHED else [
                {"plate.bsdf.reflectance.value": r, "sun.irradiance.value": e}
                for r in VALUES["plate.bsdf.reflectance.value"] for e in VALUES["sun.irradiance.value"]]
            for params in combos:
                for s in SENSORS:
                    if not self.push(cl, name):
                        return False
                    st, body = self.render(cl, name, params, s)
                    if st != 200:
                        self.fail("reference %s %r %s: %d %s" % (name, params, s, st, body[:200]))
                        return False
                    self.refs[self.key(name, params, s)] = body
        return True

    # ---- the actions ------------------------------------------------------------------
    def a_patch(self, cl, rnd):
        name = rnd.choice(PATCHED)
        k = rnd.choice(list(VALUES))
        st, body = cl.req("PATCH", "/v1/scenes/%s/params" % self.ids[name], json.dumps({k: rnd.choice(VALUES[k])}))
        if st == 404:
            self.count("patch 404")
            self.push(cl, name)
        elif st != 200:
            self.fail("PATCH %s: %d %s" % (name, st, body[:200]))
        else:
            self.count("patch")

    def a_render(self, cl, rnd):
        name = rnd.choice(list(DOCS))
        params = self.overrides(name, rnd)
        s = rnd.choice(SENSORS)
        st, body = self.render(cl, name, params, s)
        if st == 404:
            self.count("render 404")
            self.push(cl, name)
        elif st != 200:
            self.fail("render %s %r %s: %d %s" % (name, params, s, st, body[:200]))
        else:
            self.count("render")
            self.check_film("render", self.key(name, params, s), body)

    def a_job(self, cl, rnd):
        name = rnd.choice(list(DOCS))
        ctxs = []
        for i in range(rnd.randint(2, 4)):
            p = self.overrides(name, rnd)
            c = {"id": "c%d" % i, "wavelength": WL, "spp": SPP, "seed": SEED,
                 "sensors": [rnd.choice(SENSORS)]}
            if p:
                c["params"] = p
            ctxs.append(c)
        st, body = cl.req("POST", "/v1/scenes/%s/jobs" % self.ids[name], json.dumps({"contexts": ctxs}))
        if st == 404:
            self.count("job 404")
            self.push(cl, name)
            return
        if st != 202:
            self.fail("job on %s: %d %s" % (name, st, body[:200]))
            return
        job = json.loads(body)["id"]
        state = None
        for _ in range(1200):
            st, body = cl.req("GET", "/v1/jobs/%s" % job)
            if st != 200:
                self.fail("GET job %s: %d %s" % (job, st, body[:200]))
                return
            state = json.loads(body)["state"]
            if state in ("succeeded", "failed", "cancelled"):
                break
            time.sleep(0.05)
        if state != "succeeded":
            self.fail("job %s on %s ended %s: %s" % (job, name, state, body[:300]))
            return
        for c in ctxs:
            s = c["sensors"][0]
            st, film = cl.req("GET", "/v1/jobs/%s/results/%s/%s" % (job, c["id"], s), headers={"Accept": "application/x-npy"})
            if st != 200:
                self.fail("GET result %s/%s/%s: %d %s" % (job, c["id"], s, st, film[:200]))
                continue
            self.check_film("job", self.key(name, c.get("params", {}), s), film)
        st, body = cl.req("DELETE", "/v1/jobs/%s" % job)
        if st not in (200, 204):
            self.fail("DELETE job %s: %d %s" % (job, st, body[:200]))
        self.count("job")

    def a_delete(self, cl, rnd):
        name = rnd.choice(list(DOCS))
        st, body = cl.req("DELETE", "/v1/scenes/%s" % self.ids[name])
        if st in (200, 204):
            self.count("scene delete")
        elif st in (404, 409):
            self.count("scene delete %d" % st)
        else:
            self.fail("DELETE scene %s: %d %s" % (name, st, body[:200]))
        self.push(cl, name)

    def a_push(self, cl, rnd):
        if self.push(cl, rnd.choice(list(DOCS))):
            self.count("scene post")

    def worker(self, i, until):
        rnd = random.Random(1000 + i)
        cl = Client(self.port)
        # Weights: renders and PATCHes most, then jobs, posts and deletes.
        actions = [self.a_render] * 5 + [self.a_patch] * 4 + [self.a_job] * 2 + [self.a_push, self.a_delete]
        while time.time() < until:
            try:
                rnd.choice(actions)(cl, rnd)
            except Exception as e:  # a dropped connection, a bad body
                self.fail("client %d: %s: %s" % (i, type(e).__name__, e))
                cl = Client(self.port)


def vmrss_kib(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return -1


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--pid", type=int, required=True)
    ap.add_argument("--seconds", type=float, default=60)
    ap.add_argument("--clients", type=int, default=32)
    ap.add_argument("--no-rss", action="store_true")
    a = ap.parse_args()
    npass = 0
    ids = {}
    cl = Client(a.port)
    for name, doc in DOCS.items():
        st, body = cl.req("POST", "/v1/scenes", doc)
        if st not in (200, 201):
            print("FAIL soak: POST scene %s: %d %s" % (name, st, body[:200]))
            print("soak: 0 passed, 1 failed")
            return 1
        ids[name] = json.loads(body)["id"]
    soak = Soak(a.port, ids)
    if not soak.references():
        for f in soak.fails:
            print("FAIL soak: " + f)
        print("soak: 0 passed, %d failed" % len(soak.fails))
        return 1
    npass += 1
    t0 = time.time()
    until = t0 + a.seconds
    threads = [threading.Thread(target=soak.worker, args=(i, until)) for i in range(a.clients)]
    for t in threads:
        t.start()
    time.sleep(a.seconds / 3)
    rss_third = vmrss_kib(a.pid)
    for t in threads:
        t.join()
    rss_end = vmrss_kib(a.pid)
    print("soak: %d clients, %.1f s; %s; %d films bitwise equal to their reference" % (
        a.clients, time.time() - t0, ", ".join("%s %d" % kv for kv in sorted(soak.counts.items())),
        soak.films_checked))
    print("soak: VmRSS %d KiB at a third, %d KiB at the end" % (rss_third, rss_end))
    fails = list(soak.fails)
    # Something of each kind happened (a soak that did nothing proves nothing).
    for what in ("patch", "render", "job", "scene delete", "scene post"):
        if not soak.counts.get(what):
            fails.append("no successful %s in the run" % what)
    if soak.films_checked < 50:
        fails.append("only %d films checked" % soak.films_checked)
    if not a.no_rss:
        limit = rss_third * 1.10 + 8 * 1024
        if rss_end > limit:
            fails.append("VmRSS grew from %d KiB to %d KiB (limit %d KiB: +8 MiB + 10 %%)" % (rss_third, rss_end, limit))
    for f in fails:
        print("FAIL soak: " + f)
    npass += 1 if not fails else 0
    print("soak: %d passed, %d failed" % (npass, len(fails)))
    return 1 if fails else 0


if __name__ == "__main__":
    sys.exit(main())
