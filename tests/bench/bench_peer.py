#!/usr/bin/env python3
"""make bench: peer. The issue tables' scenes rendered side by side by
raysweepd and by Mitsuba 3 (Eradiate's fork, which has hdistant, rpv and
the piecewise medium), in one run, alternating, on the same cores; each scene's films' means are
reported beside the times, to show both renderers did the same work.

    RSW_PEER_MITSUBA=/path/to/mitsuba   Mitsuba's `mitsuba` command (built
                                        from source, docs/performance.md#the-peer)
    RSW_PEER_VARIANTS=llvm_rgb,...      the variants it was built with
                                        (default llvm_rgb,scalar_rgb,scalar_mono)
    RSW_PEER_REPEAT=N                   timed runs of each (default 3)
    RSW_BENCH_THREADS=T                 threads (default 2)

Without RSW_PEER_MITSUBA it prints one line saying it was skipped.

Each run is a whole process, from start to the film on disk (load, render,
write), after one untimed run of each (the page cache warm, Dr.Jit's LLVM
kernels compiled and cached: the peer "with its kernels cached"). llvm
variants run without -t (Dr.Jit uses every core: T on this machine);
scalar variants with -t T; raysweepd with --threads T. One JSON line per
scene: the medians of each program's own render time (raysweepd's
"wrote ... T s", Mitsuba's "Rendering finished. (took T)"), every run's,
ratio = ours / the fastest peer variant's median (goal: seed and
Cornell 0.8, atmosphere 0.5), and the same for whole processes
(process_ratio: loading, Dr.Jit's start and writing the film included).

The scenes (each file is read by both): seed_hdistant
(proto/examples/hdistant_seed.xml, 32x32, 3200 spp, rgb), cornell_box
(proto/examples/cornell_box.xml at 256x256, 64 spp, rgb) and
atmosphere_1d (proto/examples/atmosphere.xml, the 2,400-layer piecewise
atmosphere, 32x32, 1000 spp; ours mono at 550 nm, the profiles its .vol
grids hold)."""
import array
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
bindir = os.path.abspath(os.environ.get("RSW_BIN_DIR", os.path.join(root, "build", "bin")))
ex = os.path.join(root, "proto", "examples")

SCENES = [
    # name, file, our extra arguments, Mitsuba's -D, the variants that apply, goal
    ("seed_hdistant", "hdistant_seed.xml", [], [], ("llvm_rgb", "scalar_rgb"), 0.8),
    ("cornell_box", "cornell_box.xml", ["-D", "res=256"], ["-Dres=256"], ("llvm_rgb", "scalar_rgb"), 0.8),
    ("atmosphere_1d", "atmosphere.xml", ["--variant", "mono", "--wavelength", "550"], [],
     ("llvm_rgb", "scalar_mono"), 0.5),
]


def timed(cmd, cwd):
    """(process wall time, the render's own time as the program reports it)."""
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    dt = time.perf_counter() - t0
    out = r.stdout.decode(errors="replace")
    if r.returncode != 0:
        sys.exit(f"bench peer: {' '.join(cmd)}: exit {r.returncode}: {out[-600:]}")
    m = re.search(r"spp, ([0-9.]+) s, ", out)  # raysweepd render: wrote F (WxH, N spp, T s, K threads)
    if m:
        return dt, float(m.group(1))
    m = re.search(r"Rendering finished\. \(took ([0-9.]+)(ms|s|m)", out)  # Mitsuba's log
    if not m:
        sys.exit(f"bench peer: {' '.join(cmd)}: no render time in its output: {out[-600:]}")
    return dt, float(m.group(1)) * {"ms": 1e-3, "s": 1.0, "m": 60.0}[m.group(2)]


def film_mean(path):
    """The mean over pixels and channels of a PFM (Mitsuba's) or .npy (ours) float32 film."""
    data = open(path, "rb").read()
    if data.startswith(b"\x93NUMPY"):
        hlen = int.from_bytes(data[8:10], "little")
        body = data[10 + hlen:]
    else:  # PF/Pf, width height, scale (negative: little-endian)
        body = data.split(b"\n", 3)[3]
    a = array.array("f")
    a.frombytes(body[:len(body) // 4 * 4])
    return sum(a) / len(a)


def peer_copy(scene, out):
    """The scene for Mitsuba: its film written as PFM (to compare means),
    without raysweep's variant attribute, its files by absolute path."""
    text = open(scene).read()
    text = re.sub(r'(<scene[^>]*?) variant="[^"]*"', r"\1", text)
    text = re.sub(r'(<film type="hdrfilm"[^>]*>)', r'\1<string name="file_format" value="pfm"/>', text)
    d = os.path.dirname(scene)
    text = re.sub(r'(name="filename" value=")([^"/][^"]*)"', lambda m: m.group(1) + os.path.join(d, m.group(2)) + '"',
                  text)
    path = os.path.join(out, os.path.basename(scene))
    open(path, "w").write(text)
    return path


def main():
    mitsuba = os.environ.get("RSW_PEER_MITSUBA", "")
    if not mitsuba:
        print(json.dumps({"bench": "peer", "skipped": "RSW_PEER_MITSUBA is not set (Mitsuba 3's `mitsuba` "
                          "command: docs/performance.md#the-peer)"}))
        return
    if not os.access(mitsuba, os.X_OK):
        sys.exit(f"bench peer: RSW_PEER_MITSUBA={mitsuba}: not an executable file")
    built = os.environ.get("RSW_PEER_VARIANTS", "llvm_rgb,scalar_rgb,scalar_mono").split(",")
    repeat = int(os.environ.get("RSW_PEER_REPEAT", "3"))
    threads = os.environ.get("RSW_BENCH_THREADS", "2")
    only = [a for a in sys.argv[1:]]
    out = tempfile.mkdtemp(prefix="rsw-peer-")
    for name, file, ours_args, peer_d, variants, goal in SCENES:
        if only and name not in only:
            continue
        scene = os.path.join(ex, file)
        films = {"raysweep": os.path.join(out, name + ".rsw.npy")}
        runners = {"raysweep": [os.path.join(bindir, "raysweepd"), "render", scene, "--threads", threads,
                                *ours_args, "-o", films["raysweep"]]}
        pscene = peer_copy(scene, out)
        for v in variants:
            if v not in built:
                continue
            films[v] = os.path.join(out, f"{name}.{v}.pfm")
            cmd = [mitsuba, "-m", v, *peer_d, "-o", films[v], pscene]
            if not v.startswith("llvm"):
                cmd[1:1] = ["-t", threads]
            runners[v] = cmd
        if len(runners) == 1:
            print(json.dumps({"bench": "peer", "scene": name, "skipped": f"none of {variants} built"}))
            continue
        for cmd in runners.values():  # untimed: caches warm, LLVM kernels compiled
            timed(cmd, ex)
        walls = {k: [] for k in runners}
        renders = {k: [] for k in runners}
        for _ in range(repeat):
            for k, cmd in runners.items():
                w, r = timed(cmd, ex)
                walls[k].append(round(w, 3))
                renders[k].append(round(r, 3))
        med = {k: round(statistics.median(v), 3) for k, v in renders.items()}
        wmed = {k: round(statistics.median(v), 3) for k, v in walls.items()}
        peers = {k: v for k, v in med.items() if k != "raysweep"}
        fastest = min(peers, key=peers.get)
        wfastest = min((k for k in wmed if k != "raysweep"), key=wmed.get)
        means = {k: round(film_mean(f), 5) for k, f in films.items()}
        print(json.dumps({"bench": "peer", "scene": name, "threads": int(threads),
                          "ours_render_s": med["raysweep"], "peer_render_s": peers, "fastest_peer": fastest,
                          "ratio": round(med["raysweep"] / peers[fastest], 3), "goal": goal,
                          "ours_process_s": wmed["raysweep"],
                          "peer_process_s": {k: v for k, v in wmed.items() if k != "raysweep"},
                          "process_ratio": round(wmed["raysweep"] / wmed[wfastest], 3),
                          "film_means": means, "render_runs": renders, "load": round(os.getloadavg()[0], 2)}),
              flush=True)


if __name__ == "__main__":
    main()
