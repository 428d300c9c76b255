#!/usr/bin/env python3
"""make bench: scaling out behind a load balancer, one JSON line:
  {"bench": "scale_out", "contexts": 200, "one_daemon_contexts_per_s",
   "two_daemons_contexts_per_s", "efficiency", "balancer_added_ms_p50",
   "balancer_added_ms_p99", ..., "files": {...}}
Throughput: `raysweep sweep` of one job of 200 small contexts (32x32 mono
hdistant film, 16 spp) against one raysweepd (--threads 1), then
`raysweep sweep --spread 2` through HAProxy (docker/lb/gen.py) in front of
two raysweepd (--threads 1 each); wall time of the whole command (scene
push, submission, progress, every film fetched and written), best of 3,
the two set-ups alternating. The client (film fetches, the output) and
HAProxy share the machine's cores with the daemons.
The measured output is `--format dataset`: the sweep as one NetCDF-4
dataset, DIR/dataset.nc, built from the daemon's EXRs with no file per
film (docs/client.md). The same sweeps with one EXR file per film
(`--format exr --layout flat`, the cheaper layout for the file system;
RSW_SCALE_OUT_LAYOUT=dirs measures the default layout instead) run
alternately with them and are reported under "files", with the same
fields, so that what a file per film costs stays in view.
efficiency = throughput(2) / (2 x throughput(1)); the target is >= 0.9
on two free cores.
The client's own cost per film: `client_cpu_ms_per_film`, the CPU time
(user + system) of the `raysweep` process divided by the films it wrote,
median of the runs of each set-up (load on the rest of the machine does
not inflate it); `one_daemon_overhead_ms_per_film`, the one-daemon
command's wall time beyond its job's render time (the job's `seconds`)
per film: what the client adds end to end (start, scene push, keys,
submission, fetching and writing), median of the runs.
`one_daemon_job_s`, `two_daemons_job_s`: the render time of the best
runs' jobs (for two daemons the slower replica's job), and
`render_efficiency` = one_daemon_job_s / (2 x two_daemons_job_s): the
renders' own scaling, so that a shortfall of `efficiency` can be told
apart as the daemons' share of the cores (other work on the machine) or
the client's.
`machine_pair_efficiency`: the machine's own ceiling for two busy
single-threaded processes, with no daemon, client or balancer: the scene
rendered by `raysweepd render --threads 1` alone, then by two such
processes at once (render time from --stats, best of 3 each, run between
the sweeps): alone / the slower of the pair. On a machine whose two cores
are not two free cores (SMT siblings, a shared host), it falls below 1,
and `efficiency` with it.
Added latency: GET /v1/health/live on a kept-alive connection, 2000 times
straight to a daemon and 2000 times through HAProxy (the routing header
set); the difference of the percentiles.
"""
import http.client
import json
import os
import re
import resource
import shutil
import socket
import subprocess
import sys
import tempfile
import time

root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
bindir = os.environ.get("RSW_BIN_DIR", os.path.join(root, "build", "bin"))
scene = os.path.join(root, "proto", "examples", "hdistant_lambertian.json")
N_CONTEXTS = 200
SPP = 16
LAYOUT = os.environ.get("RSW_SCALE_OUT_LAYOUT", "flat")


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    p = s.getsockname()[1]
    s.close()
    return p


def daemon(tmp, name, procs):
    d = os.path.join(tmp, name)
    os.makedirs(d)
    pf = os.path.join(d, "port")
    p = subprocess.Popen([os.path.join(bindir, "raysweepd"), "serve", "--listen", "127.0.0.1:0", "--port-file", pf,
                          "--threads", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    procs.append(p)
    for _ in range(400):
        if os.path.exists(pf) and open(pf).read().strip():
            return int(open(pf).read())
        time.sleep(0.01)
    sys.exit(f"bench_scale_out: raysweepd did not start")


def wait_ready(port):
    for _ in range(200):
        try:
            c = http.client.HTTPConnection("127.0.0.1", port, timeout=2)
            c.request("GET", "/v1/health/ready")
            if c.getresponse().status == 200:
                return
        except OSError:
            pass
        time.sleep(0.05)
    sys.exit(f"bench_scale_out: nothing ready on port {port}")


# The outputs measured: the sweep as one dataset, and one EXR file per film.
OUTPUTS = {"dataset": ["--format", "dataset"], "files": ["--format", "exr", "--layout", LAYOUT]}


def sweep(url, out, extra, output="dataset"):
    # 200 contexts: wavelengths 400, 401.5, ..., 698.5 nm, one per path
    # (--bundle 1: each context its own render, so that the sweep's film
    # count and each film's cost are those this bench measures)
    cmd = [os.path.join(bindir, "raysweep"), "--server", url, "-q", "sweep", scene, "--grid",
           "wavelength=400:698.5:1.5", "--spp", str(SPP), "--bundle", "1", "-o", out] + OUTPUTS[output] + extra
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    r = subprocess.run(cmd, capture_output=True, text=True)
    dt = time.monotonic() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        sys.exit(f"bench_scale_out: {' '.join(cmd)}: exit {r.returncode}: {r.stderr[-500:]}")
    n = sum(1 for _ in open(os.path.join(out, "index.jsonl")))
    if n != N_CONTEXTS:
        sys.exit(f"bench_scale_out: {n} films, wanted {N_CONTEXTS}")
    if output == "dataset" and sorted(os.listdir(out)) != ["dataset.nc", "index.jsonl", "sweep.json"]:
        sys.exit(f"bench_scale_out: {out} holds {sorted(os.listdir(out))[:5]}, not the dataset alone")
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    return dt, cpu / n * 1e3


PAIR_SPP = 2048  # (0.4 to 0.7 s on one core here: about as long as a sweep's renders)


def render_seconds(procs):
    """Each process's render time (`raysweepd render --stats`), after it ends."""
    out = []
    for p in procs:
        err = p.communicate()[1]
        m = re.search(r"samples in ([0-9.]+) s", err)
        if p.returncode != 0 or not m:
            sys.exit(f"bench_scale_out: raysweepd render: exit {p.returncode}: {err[-300:]}")
        out.append(float(m.group(1)))
    return out


def pair_run(tmp, n):
    """n renders of the scene at once, one thread each: their render times."""
    procs = [subprocess.Popen([os.path.join(bindir, "raysweepd"), "render", scene, "--threads", "1", "--spp",
                               str(PAIR_SPP), "--stats", "-o", os.path.join(tmp, f"pair{k}.exr")],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True) for k in range(n)]
    return render_seconds(procs)


def last_job_seconds(port):
    """The render time of the newest job of the daemon on port."""
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    c.request("GET", "/v1/jobs")
    jobs = json.loads(c.getresponse().read())["jobs"]
    return max(jobs, key=lambda j: (j["created"], j["id"]))["seconds"]


def median(v):
    v = sorted(v)
    return v[len(v) // 2] if len(v) % 2 else 0.5 * (v[len(v) // 2 - 1] + v[len(v) // 2])


def latencies(direct, via, n):
    """Alternating requests straight to a daemon and through the balancer,
    so both see the same noise of a shared machine."""
    cd = http.client.HTTPConnection("127.0.0.1", direct, timeout=10)
    cv = http.client.HTTPConnection("127.0.0.1", via, timeout=10)
    out = ([], [])
    for i in range(n + 50):
        for k, (c, h) in enumerate(((cd, {}), (cv, {"X-Raysweep-Shard": "bench-1"}))):
            t0 = time.perf_counter()
            c.request("GET", "/v1/health/live", headers=h)
            r = c.getresponse()
            r.read()
            dt = time.perf_counter() - t0
            if r.status != 200:
                sys.exit(f"bench_scale_out: /v1/health/live answered {r.status}")
            if i >= 50:  # warm-up
                out[k].append(dt * 1e3)
    res = []
    for v in out:
        v.sort()
        res += [v[len(v) // 2], v[min(len(v) - 1, int(len(v) * 0.99))]]
    return res


def main():
    if not shutil.which("haproxy"):
        sys.exit("bench_scale_out: haproxy is needed (make deps-bench)")
    tmp = tempfile.mkdtemp()
    procs = []
    load0 = os.getloadavg()[0]
    try:
        one = daemon(tmp, "one", procs)
        url1 = f"http://127.0.0.1:{one}"
        a, b = daemon(tmp, "a", procs), daemon(tmp, "b", procs)
        lb = free_port()
        cfg = os.path.join(tmp, "haproxy.cfg")
        subprocess.run([sys.executable, os.path.join(root, "docker", "lb", "gen.py"), "haproxy", "--listen",
                        f"127.0.0.1:{lb}", "--replica", f"127.0.0.1:{a}", "--replica", f"127.0.0.1:{b}", "-o", cfg],
                       check=True)
        procs.append(subprocess.Popen(["haproxy", "-f", cfg, "-db"], stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))
        wait_ready(lb)
        url2 = f"http://127.0.0.1:{lb}"
        # Warm-up (the scene is pushed, then resident), then the two set-ups
        # alternately, each output in turn, so a shared machine's load falls
        # on all alike.
        sweep(url1, os.path.join(tmp, "o"), ["--spread", "1"])
        sweep(url2, os.path.join(tmp, "t"), ["--spread", "2"])
        runs = {o: {"runs1": [], "runs2": [], "cpu1": [], "cpu2": [], "over1": [], "jobs1": [], "jobs2": []}
                for o in OUTPUTS}
        alone, pair = [], []
        for i in range(3):
            alone.append(pair_run(tmp, 1)[0])
            pair.append(max(pair_run(tmp, 2)))
            for o, r in runs.items():
                dt, cpu = sweep(url1, os.path.join(tmp, f"o{o}{i}"), ["--spread", "1"], o)
                r["runs1"].append(dt)
                r["cpu1"].append(cpu)
                r["jobs1"].append(last_job_seconds(one))
                r["over1"].append((dt - r["jobs1"][-1]) / N_CONTEXTS * 1e3)
                dt, cpu = sweep(url2, os.path.join(tmp, f"t{o}{i}"), ["--spread", "2"], o)
                r["runs2"].append(dt)
                r["cpu2"].append(cpu)
                r["jobs2"].append(max(last_job_seconds(a), last_job_seconds(b)))

        def figures(r):
            t1, t2 = min(r["runs1"]), min(r["runs2"])
            # The renders alone (the jobs' own seconds, the slower replica's
            # for two): how much of a shortfall is the daemons' share of the cores.
            j1, j2 = r["jobs1"][r["runs1"].index(t1)], r["jobs2"][r["runs2"].index(t2)]
            th1, th2 = N_CONTEXTS / t1, N_CONTEXTS / t2
            return {
                "one_daemon_s": round(t1, 3),
                "two_daemons_s": round(t2, 3),
                "one_daemon_runs_s": [round(t, 3) for t in r["runs1"]],
                "two_daemons_runs_s": [round(t, 3) for t in r["runs2"]],
                "one_daemon_contexts_per_s": round(th1, 1),
                "two_daemons_contexts_per_s": round(th2, 1),
                "efficiency": round(th2 / (2 * th1), 3),
                "client_cpu_ms_per_film": {"one_daemon": round(median(r["cpu1"]), 3),
                                           "two_daemons": round(median(r["cpu2"]), 3)},
                "one_daemon_overhead_ms_per_film": round(median(r["over1"]), 3),
                "one_daemon_job_s": round(j1, 3),
                "two_daemons_job_s": round(j2, 3),
                "render_efficiency": round(j1 / (2 * j2), 3),
            }

        d50, d99, v50, v99 = latencies(a, lb, 2000)
        print(json.dumps({
            "bench": "scale_out",
            "contexts": N_CONTEXTS,
            "spp": SPP,
            "threads_per_daemon": 1,
            "output": "dataset",
            **figures(runs["dataset"]),
            # One EXR file per film (--layout LAYOUT), alternating with the above.
            "files": {"layout": LAYOUT, **figures(runs["files"])},
            "machine_pair_efficiency": round(min(alone) / min(pair), 3),
            "pair_alone_s": [round(t, 3) for t in alone],
            "pair_s": [round(t, 3) for t in pair],
            "direct_ms_p50": round(d50, 3),
            "direct_ms_p99": round(d99, 3),
            "via_haproxy_ms_p50": round(v50, 3),
            "via_haproxy_ms_p99": round(v99, 3),
            "balancer_added_ms_p50": round(v50 - d50, 3),
            "balancer_added_ms_p99": round(v99 - d99, 3),
            "cores": os.cpu_count(),
            # Other work on the machine (1-minute load average before and
            # after): on a shared machine, compare runs of similar load.
            "load_avg": [round(load0, 2), round(os.getloadavg()[0], 2)],
        }))
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            p.wait()
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
