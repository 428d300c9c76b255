#!/usr/bin/env python3
"""The container recipes of docker/ against the real daemon (no Docker
engine or Kubernetes runs here): run by tests/cluster/test_containers.sh.

- docker/Dockerfile: parsed instruction by instruction. The build stage is
  replayed in an empty directory (its COPY lines from the repository, its
  `make deps` for real -- a no-op when the packages are there -- and its
  `make` as `make -n`), so a file the Makefile needs and the image does not
  copy is caught. The runtime stage's packages must exist in apt and their
  dependency closure must hold every shared library raysweepd and raysweep
  link (ldd + dpkg -S). Non-root USER, EXPOSE = the --listen port,
  HEALTHCHECK on /v1/health/live at that port, and ENTRYPOINT + CMD run as
  a real daemon (addresses and paths mapped into a temporary directory):
  the probes answer, /metrics wants the token.
- docker/compose/compose.yaml: three replicas with the image's command
  (run for real), the token secret at the path the command reads, HAProxy
  mounting a configuration whose servers are exactly the replica services
  at the daemon's port, hashing on X-Raysweep-Shard, checking
  /v1/health/ready, and which `haproxy -c` accepts.
- docker/k8s/*.yaml: the Deployment's args run for real, probe paths and
  ports, the Secret -> volume -> --token-file wiring, resources and
  --threads, the preStop drain (in the image, its timing inside
  terminationGracePeriodSeconds, and run against the daemon), security
  context = the image's user, Services' selectors and ports, the HAProxy
  ConfigMap (`haproxy -c`), one namespace.
- docker/raysweepd-drain against a daemon with a job running: it returns
  only when the job has finished (and the job succeeded, i.e. was not
  cancelled), and gives up with exit 1 at --timeout.

Prints "test_containers: N passed, N failed".
"""
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request

import yaml

NAME = "test_containers"
ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.path.abspath(os.environ.get("RSW_BIN_DIR") or os.path.join(ROOT, "build", "bin"))
DOCKER = os.path.join(ROOT, "docker")
passed = failed = 0
TMP = tempfile.mkdtemp(prefix="rsw-containers.")
daemons = []


def ok():
    global passed
    passed += 1


def bad(msg):
    global failed
    failed += 1
    print(f"FAIL {NAME}: {msg}", flush=True)


def check(cond, msg):
    ok() if cond else bad(msg)
    return bool(cond)


def finish():
    for p in daemons:
        if p.poll() is None:
            p.kill()
            p.wait()
    shutil.rmtree(TMP, ignore_errors=True)
    print(f"{NAME}: {passed} passed, {failed} failed")
    sys.exit(0 if failed == 0 else 1)


def run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, **kw)


# ---------------------------------------------------------------- the daemon
def serve_help():
    r = run([os.path.join(BIN, "raysweepd"), "serve", "--help"])
    return r.stdout + r.stderr


def listen_port(argv):
    """The port of --listen in a serve argv (8350 when absent)."""
    if "--listen" in argv:
        v = argv[argv.index("--listen") + 1]
        return int(v.rpartition(":")[2]) if ":" in v else 8350
    return 8350


def http(port, path, token=None, method="GET", body=None, timeout=10):
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", method=method, data=body)
    if token:
        req.add_header("Authorization", f"Bearer {token}")
    if body is not None:
        req.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


class Daemon:
    """raysweepd started with a manifest's serve argv: --listen becomes
    127.0.0.1:0 (+ --port-file), --token-file and --blob-dir point into a
    temporary directory (the token file holds `token`)."""

    def __init__(self, label, argv, token="t0ken-" + "ab" * 16):
        self.label, self.token, self.ok = label, token, False
        d = tempfile.mkdtemp(dir=TMP)
        self.dir = d
        self.paths = {}
        args = list(argv)
        if args[:1] == ["raysweepd"]:
            args = args[1:]
        if args[:1] != ["serve"]:
            bad(f"{label}: the command is not `raysweepd serve ...`: {argv}")
            return
        mapped = ["serve"]
        # Every raysweepd serve option takes one value (server/serve.c).
        if len(args) % 2 != 1:
            bad(f"{label}: options and values do not pair up: {argv}")
            return
        for a, v in zip(args[1::2], args[2::2]):
            if a == "--listen":
                mapped += ["--listen", "127.0.0.1:0", "--port-file", os.path.join(d, "port")]
            elif a == "--token-file":
                t = os.path.join(d, "token")
                with open(t, "w") as f:
                    f.write(token + "\n")
                self.paths[v] = t
                mapped += [a, t]
            elif a in ("--blob-dir", "--state-dir", "--data-root", "--plugin-dir"):
                b = os.path.join(d, a.lstrip("-"))  # an empty directory in its place
                os.mkdir(b)
                self.paths[v] = b
                mapped += [a, b]
            elif a in ("--scene", "--port-file"):
                bad(f"{label}: {a} {v}: the test does not map this option yet (teach it)")
                return
            else:
                mapped += [a, v]
        self.argv = mapped
        self.log = open(os.path.join(d, "log"), "w+")
        self.p = subprocess.Popen([os.path.join(BIN, "raysweepd")] + mapped, stdout=self.log, stderr=subprocess.STDOUT)
        daemons.append(self.p)
        pf = os.path.join(d, "port")
        for _ in range(300):
            if os.path.exists(pf) and open(pf).read().strip():
                break
            if self.p.poll() is not None:
                break
            time.sleep(0.05)
        if not (os.path.exists(pf) and open(pf).read().strip()):
            self.log.seek(0)
            bad(f"{label}: raysweepd {' '.join(mapped)} did not start (exit {self.p.poll()}): {self.log.read()[-600:]}")
            return
        self.port = int(open(pf).read())
        self.ok = True

    def stop(self):
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
            try:
                return self.p.wait(10)
            except subprocess.TimeoutExpired:
                self.p.kill()
                return None
        return self.p.returncode


def probe_daemon(label, argv, probes):
    """Start the daemon with argv, check probes [(path, want_status)], the
    token on /metrics, and a clean SIGTERM exit. Returns the Daemon."""
    d = Daemon(label, argv)
    if not d.ok:
        return d
    ok()
    for path, want in probes:
        st, body = http(d.port, path)
        check(st == want, f"{label}: GET {path} without a token answered {st}, wanted {want} ({body[:200]!r})")
    if "--token-file" in argv:
        st, _ = http(d.port, "/metrics")
        check(st == 401, f"{label}: GET /metrics without the token answered {st}, wanted 401")
        st, body = http(d.port, "/metrics", d.token)
        check(st == 200 and b"raysweep_ready 1" in body, f"{label}: GET /metrics with the token answered {st}")
    return d


# ---------------------------------------------------------------- Dockerfile
def parse_dockerfile(path):
    """[(stage_name, [(INSTR, args_text)])]; continuation lines joined."""
    stages, cur, buf = [], None, ""
    for raw in open(path):
        line = raw.rstrip("\n")
        if not buf and (not line.strip() or line.lstrip().startswith("#")):
            continue
        if buf and line.lstrip().startswith("#"):
            continue  # a comment inside a continued instruction
        if line.endswith("\\"):
            buf += line[:-1] + " "
            continue
        buf += line
        instr, _, rest = buf.strip().partition(" ")
        instr, rest = instr.upper(), rest.strip()
        buf = ""
        if instr == "FROM":
            m = re.match(r"(\S+)(?:\s+AS\s+(\S+))?$", rest, re.I)
            cur = (m.group(2) or str(len(stages)), [("FROM", m.group(1))])
            stages.append(cur)
        else:
            cur[1].append((instr, rest))
    return stages


def exec_form(text):
    """An instruction's argv: JSON exec form, or shell form as sh -c."""
    t = text.strip()
    if t.startswith("["):
        return json.loads(t)
    return ["/bin/sh", "-c", t]


def dockerignored(rel, patterns):
    rel = rel.rstrip("/")
    for p in patterns:
        p = p.rstrip("/")
        if rel == p or rel.startswith(p + "/"):
            return True
    return False


def replay_build_stage(instrs, ignore):
    """Replay the build stage's COPY/WORKDIR/RUN in an empty directory."""
    emu = tempfile.mkdtemp(dir=TMP, prefix="image-src.")
    work = "/"
    outs = set()

    def host(p):  # an image path as a path under emu
        p = p if p.startswith("/") else os.path.join(work, p)
        return os.path.join(emu, os.path.normpath(p).lstrip("/"))

    for instr, rest in instrs:
        if instr == "WORKDIR":
            work = rest
            os.makedirs(host("."), exist_ok=True)
        elif instr == "COPY":
            args = shlex.split(rest)
            if any(a.startswith("--from") for a in args):
                continue
            *srcs, dst = [a for a in args if not a.startswith("--")]
            for s in srcs:
                src = os.path.join(ROOT, s)
                if not os.path.exists(src):
                    bad(f"Dockerfile: COPY {s}: no such file in the repository")
                    continue
                if dockerignored(s, ignore):
                    bad(f"Dockerfile: COPY {s}: excluded by .dockerignore")
                    continue
                tgt = host(dst)
                if os.path.isdir(src):
                    shutil.copytree(src, tgt, dirs_exist_ok=True,
                                    ignore=lambda d, names: [n for n in names if dockerignored(
                                        os.path.relpath(os.path.join(d, n), ROOT), ignore)])
                else:
                    if dst.endswith("/"):
                        tgt = os.path.join(tgt, os.path.basename(s))
                    os.makedirs(os.path.dirname(tgt), exist_ok=True)
                    shutil.copy2(src, tgt)
        elif instr == "RUN":
            for step in [s.strip() for s in rest.split("&&")]:
                words = shlex.split(step)
                if not words:
                    continue
                if words[0] in ("apt-get", "rm") and (words[0] == "apt-get" or "/var/lib/apt/lists/*" in step):
                    continue  # package manager housekeeping: not replayed here
                if words[:2] == ["mkdir", "-p"]:
                    for w in words[2:]:
                        os.makedirs(host(w), exist_ok=True)
                elif words == ["make", "deps"]:
                    r = run(["make", "deps"], cwd=host("."))
                    check(r.returncode == 0, f"Dockerfile: `make deps` with only the files copied before it: {r.stderr[-800:]}")
                elif words[0] == "make":
                    # make -n -B: every command of a from-scratch build, without
                    # running it. It must compile the same sources as in the
                    # repository (a directory the image does not copy has no
                    # sources to find), and every -I directory must exist.
                    goals = [w for w in words[1:] if not w.startswith("-j")]
                    r = run(["make", "-n", "-B"] + goals, cwd=host("."))
                    if check(r.returncode == 0, f"Dockerfile: `{step}` (as make -n) in the copied tree: {r.stderr[-800:]}"):
                        for b in ("raysweepd", "raysweep"):
                            check(f"-o build/bin/{b} " in r.stdout, f"Dockerfile: `{step}` does not build build/bin/{b}")
                        ref = run(["make", "-n", "-B"] + goals, cwd=ROOT)
                        srcs = lambda out: set(re.findall(r" -c (\S+\.c(?:pp)?) ", out))
                        missing = sorted(srcs(ref.stdout) - srcs(r.stdout))
                        check(ref.returncode == 0 and not missing,
                              f"Dockerfile: `{step}` in the image would not compile {missing[:8]} (not copied?)")
                        incs = set(re.findall(r" -I([\w./-]+)(?=\s)", r.stdout))
                        gone = sorted(i for i in incs if not i.startswith("/") and not os.path.isdir(host(i)))
                        check(not gone, f"Dockerfile: include directories {gone} are not copied into the image")
                elif words[0] == "install" and "-D" in words:
                    src, dst = words[-2], words[-1]
                    check(src.startswith("build/bin/") and os.path.exists(os.path.join(ROOT, src)) or
                          os.path.exists(os.path.join(BIN, os.path.basename(src))),
                          f"Dockerfile: install {src}: not a built program")
                    outs.add(dst)
                elif words[0].startswith("/out/"):
                    r = run([os.path.join(BIN, os.path.basename(words[0]))] + words[1:])
                    check(r.returncode == 0, f"Dockerfile: `{step}` fails with the built binary: {r.stderr}")
                else:
                    bad(f"Dockerfile: build step `{step}` is not one this test knows how to replay (teach it)")
        elif instr in ("ARG", "ENV", "FROM"):
            pass
        else:
            bad(f"Dockerfile: build stage instruction {instr} not replayed (teach the test)")
    return outs


def apt_closure(pkgs):
    """pkgs and every package they depend on (Depends, Pre-Depends), recursively."""
    r = run(["apt-cache", "depends", "--recurse", "--no-recommends", "--no-suggests", "--no-conflicts",
             "--no-breaks", "--no-replaces", "--no-enhances"] + pkgs)
    names = set(pkgs)
    for line in r.stdout.splitlines():
        if line and not line.startswith(" "):
            names.add(line.strip())
        m = re.match(r"\s+\|?(?:Pre)?Depends: (\S+)", line)
        if m:
            names.add(m.group(1))
    return {n.split(":")[0] for n in names if not n.startswith("<")}


def linked_packages(binary):
    """{library path: owning Debian package or None} for what binary links;
    one dpkg -S for all (usrmerge: a library may be listed under /lib or
    /usr/lib)."""
    libs = [m.group(1) for m in re.finditer(r"=> (/\S+)", run(["ldd", binary]).stdout)]
    cands = {}
    for lib in libs:
        real = os.path.realpath(lib)
        for c in (lib, real, real.removeprefix("/usr"), "/usr" + real, lib.removeprefix("/usr"), "/usr" + lib):
            cands.setdefault(c, set()).add(lib)
    owner = {}
    for line in run(["dpkg", "-S"] + sorted(cands)).stdout.splitlines():
        pkgs, _, path = line.partition(": ")
        for lib in cands.get(path.strip(), ()):
            owner.setdefault(lib, pkgs.split(",")[0].split(":")[0].strip())
    return {lib: owner.get(lib) for lib in libs}


def check_dockerfile():
    path = os.path.join(DOCKER, "Dockerfile")
    stages = parse_dockerfile(path)
    names = [s[0] for s in stages]
    check(names == ["build", "runtime"], f"Dockerfile: stages {names}, wanted build and runtime")
    for n, ins in stages:
        check(ins[0][1] == "debian:12", f"Dockerfile: stage {n} is FROM {ins[0][1]}, wanted debian:12")
    ignore = [l.strip() for l in open(os.path.join(ROOT, ".dockerignore")) if l.strip() and not l.startswith("#")]
    build = dict(stages).get("build", [])
    runtime = dict(stages).get("runtime", [])
    check(any(i == "RUN" and "make deps" in r for i, r in build), "Dockerfile: the build stage does not run `make deps`")
    outs = replay_build_stage(build, ignore)

    # runtime packages
    pk = []
    for i, r in runtime:
        if i == "RUN" and "apt-get install" in r:
            words = shlex.split(r.split("apt-get install", 1)[1].split("&&")[0])
            pk += [w for w in words if not w.startswith("-")]
    check("curl" in pk, "Dockerfile: curl (HEALTHCHECK, raysweepd-drain) is not in the runtime packages")
    cand, cur = {}, None
    for line in run(["apt-cache", "policy"] + pk).stdout.splitlines():
        if line and not line.startswith(" "):
            cur = line.rstrip(":")
        elif cur and line.strip().startswith("Candidate:"):
            cand[cur] = line.split(":", 1)[1].strip()
    for p in pk:
        check(cand.get(p, "(none)") != "(none)", f"Dockerfile: runtime package {p} has no installation candidate in apt")
    closure = apt_closure(pk)
    for b in ("raysweepd", "raysweep"):
        for lib, owner in linked_packages(os.path.join(BIN, b)).items():
            check(owner in closure, f"Dockerfile: {b} links {lib} ({owner or 'no package'}), which the runtime packages do not pull in")

    copies = [(shlex.split(r)) for i, r in runtime if i == "COPY"]
    installed = {}
    for c in copies:
        frm = [a for a in c if a.startswith("--from")]
        *srcs, dst = [a for a in c if not a.startswith("--")]
        for s in srcs:
            if frm:
                if s.startswith("/out/"):
                    check(s in outs, f"Dockerfile: COPY --from=build {s}: the build stage does not install it")
            else:
                f = os.path.join(ROOT, s)
                check(os.path.exists(f) and not dockerignored(s, ignore), f"Dockerfile: COPY {s}: missing or ignored")
            if dst.endswith("/"):
                installed[os.path.basename(s.rstrip("/"))] = dst + os.path.basename(s.rstrip("/"))
            else:
                installed[os.path.basename(dst)] = dst
    for prog in ("raysweepd", "raysweep", "raysweepd-drain"):
        check(installed.get(prog, "").startswith("/usr/local/bin/"), f"Dockerfile: {prog} is not copied to /usr/local/bin")
    check(os.access(os.path.join(DOCKER, "raysweepd-drain"), os.X_OK), "docker/raysweepd-drain is not executable")

    get = lambda k: [r for i, r in runtime if i == k]
    user = (get("USER") or ["root"])[-1].split(":")[0]
    check(user not in ("root", "0"), f"Dockerfile: the runtime runs as {user}")
    uid = None
    for r in get("RUN"):
        m = re.search(r"useradd .*--uid (\d+)", r)
        if m:
            uid = m.group(1)
    check(user == uid or user == "raysweep", f"Dockerfile: USER {user} is not the user created (uid {uid})")
    entry = exec_form((get("ENTRYPOINT") or ["[]"])[-1])
    cmd = exec_form((get("CMD") or ["[]"])[-1])
    argv = entry + cmd
    check(entry == ["raysweepd"], f"Dockerfile: ENTRYPOINT {entry}, wanted [\"raysweepd\"]")
    port = listen_port(argv)
    check(argv[argv.index("--listen") + 1].startswith("0.0.0.0:") if "--listen" in argv else False,
          f"Dockerfile: CMD does not listen on 0.0.0.0 (a container's loopback is its own): {cmd}")
    check("--token-file" in argv, "Dockerfile: CMD has no --token-file (raysweepd refuses 0.0.0.0 without one)")
    check(get("EXPOSE") == [str(port)], f"Dockerfile: EXPOSE {get('EXPOSE')}, CMD listens on {port}")
    hc = get("HEALTHCHECK")
    hc_argv = exec_form(hc[-1].split("CMD", 1)[1]) if hc and "CMD" in hc[-1] else []
    url = next((a for a in hc_argv if a.startswith("http://")), "")
    check(url == f"http://127.0.0.1:{port}/v1/health/live",
          f"Dockerfile: HEALTHCHECK hits '{url}', wanted http://127.0.0.1:{port}/v1/health/live")
    check(hc_argv[:1] == ["curl"] and "-f" in "".join(a for a in hc_argv if a.startswith("-") and not a.startswith("--")),
          f"Dockerfile: HEALTHCHECK should be curl -f (fail on HTTP errors): {hc_argv}")
    d = probe_daemon("Dockerfile CMD", argv, [("/v1/health/live", 200), ("/v1/health/ready", 200)])
    if d.ok:
        check(d.stop() == 0, "Dockerfile CMD: raysweepd did not exit 0 on SIGTERM")
    token_path = argv[argv.index("--token-file") + 1] if "--token-file" in argv else None
    return {"uid": uid, "port": port, "token_path": token_path, "bin": installed, "argv": argv}


# ---------------------------------------------------------------- HAProxy
def haproxy_check(label, cfg_text, want_servers=None, want_port=None, template=None):
    f = os.path.join(TMP, "haproxy-" + re.sub(r"\W", "_", label) + ".cfg")
    with open(f, "w") as fh:
        fh.write(cfg_text)
    if shutil.which("haproxy") is None:
        bad(f"{label}: haproxy is needed to check the configuration (make deps)")
    else:
        r = run(["haproxy", "-c", "-f", f])
        check(r.returncode == 0, f"{label}: haproxy -c: {r.stdout[-400:]}{r.stderr[-400:]}")
    lines = [l.split("#")[0].strip() for l in cfg_text.splitlines()]
    check("balance hdr(X-Raysweep-Shard)" in lines, f"{label}: no `balance hdr(X-Raysweep-Shard)`")
    check("hash-type consistent" in lines, f"{label}: no `hash-type consistent`")
    # A request without a key goes as the key "-" (else round-robin: a job away from its scene)
    check("http-request set-header X-Raysweep-Shard - unless { req.hdr(X-Raysweep-Shard) -m len 1: }" in lines,
          f"{label}: requests without X-Raysweep-Shard are not given the key '-'")
    check("option httpchk GET /v1/health/ready" in lines, f"{label}: the health check is not GET /v1/health/ready")
    check("http-check expect status 200" in lines, f"{label}: the health check does not expect 200")
    servers = [l.split()[2] for l in lines if l.startswith("server ")]
    if want_servers is not None:
        hosts = sorted(s.rpartition(":")[0] for s in servers)
        check(hosts == sorted(want_servers), f"{label}: servers {hosts}, wanted {sorted(want_servers)}")
        check(all(s.rpartition(":")[2] == str(want_port) for s in servers), f"{label}: servers {servers} not on port {want_port}")
    if template is not None:
        tpl = [l.split() for l in lines if l.startswith("server-template ")]
        check(len(tpl) == 1 and tpl[0][3] == template, f"{label}: server-template {tpl}, wanted {template}")
    binds = [l.split()[1] for l in lines if l.startswith("bind ")]
    return [int(b.rpartition(":")[2]) for b in binds]


# ---------------------------------------------------------------- compose
def check_compose(img):
    cdir = os.path.join(DOCKER, "compose")
    c = yaml.safe_load(open(os.path.join(cdir, "compose.yaml")))
    svcs = c.get("services", {})
    reps = sorted(n for n in svcs if n.startswith("raysweep-"))
    check(reps == ["raysweep-1", "raysweep-2", "raysweep-3"] and "haproxy" in svcs,
          f"compose: services {sorted(svcs)}, wanted raysweep-1..3 and haproxy")
    version = re.search(r'RSW_VERSION "([^"]+)"', open(os.path.join(ROOT, "include/raysweep/version.h")).read()).group(1)
    for n in reps:
        s = svcs[n]
        check(s.get("image") == f"raysweep:{version}", f"compose {n}: image {s.get('image')}, wanted raysweep:{version}")
        b = s.get("build", {})
        check(os.path.realpath(os.path.join(cdir, b.get("context", "?"))) == ROOT and b.get("dockerfile") == "docker/Dockerfile",
              f"compose {n}: build {b} is not the repository root with docker/Dockerfile")
        argv = ["raysweepd"] + s.get("command", img["argv"][1:])
        check(listen_port(argv) == img["port"], f"compose {n}: listens on {listen_port(argv)}, the image exposes {img['port']}")
        check("raysweep_token" in s.get("secrets", []), f"compose {n}: no raysweep_token secret")
        tok = argv[argv.index("--token-file") + 1] if "--token-file" in argv else None
        check(tok == "/run/secrets/raysweep_token", f"compose {n}: --token-file {tok}, but compose mounts the secret at /run/secrets/raysweep_token")
        if "--threads" in argv:
            check(float(argv[argv.index("--threads") + 1]) == float(s.get("cpus", 0)),
                  f"compose {n}: --threads {argv[argv.index('--threads') + 1]} but cpus {s.get('cpus')}")
        check("ports" not in s, f"compose {n}: a replica publishes a port (only the balancer should)")
    sec = c.get("secrets", {}).get("raysweep_token", {})
    check(sec.get("file") == "./token", f"compose: secret raysweep_token is {sec}, wanted file ./token")
    gi = open(os.path.join(ROOT, ".gitignore")).read().split()
    check("docker/compose/token" in gi, "compose: docker/compose/token (the secret) is not in .gitignore")
    d = probe_daemon("compose raysweep-1", ["raysweepd"] + svcs["raysweep-1"].get("command", []),
                     [("/v1/health/live", 200), ("/v1/health/ready", 200)])
    if d.ok:
        check(d.stop() == 0, "compose raysweep-1: raysweepd did not exit 0 on SIGTERM")

    h = svcs.get("haproxy", {})
    mounts = [v.split(":") for v in h.get("volumes", [])]
    cfg = [m for m in mounts if len(m) >= 2 and m[1] == "/usr/local/etc/haproxy/haproxy.cfg"]
    if check(cfg, f"compose haproxy: nothing mounted at /usr/local/etc/haproxy/haproxy.cfg: {mounts}"):
        src = os.path.normpath(os.path.join(cdir, cfg[0][0]))
        if check(os.path.isfile(src), f"compose haproxy: {cfg[0][0]} does not exist"):
            binds = haproxy_check(f"compose {os.path.relpath(src, ROOT)}", open(src).read(), reps, img["port"])
            pub = [p.split(":")[-1] for p in h.get("ports", [])]
            check(pub and all(int(p) in binds for p in pub), f"compose haproxy: publishes {pub}, HAProxy binds {binds}")
            check(all(p.startswith("127.0.0.1:") for p in h.get("ports", [])), "compose haproxy: the port is published beyond loopback")
    dep = h.get("depends_on", {})
    check(all(dep.get(n, {}).get("condition") == "service_healthy" for n in reps),
          f"compose haproxy: depends_on {dep}: HAProxy resolves the replicas at start, wait for them to be healthy")


# ---------------------------------------------------------------- Kubernetes
def k8s_objects():
    objs = []
    for f in sorted(os.listdir(os.path.join(DOCKER, "k8s"))):
        if f.endswith(".yaml"):
            for o in yaml.safe_load_all(open(os.path.join(DOCKER, "k8s", f))):
                if o:
                    objs.append((f, o))
    return objs


def port_number(container, ref):
    if isinstance(ref, int):
        return ref
    for p in container.get("ports", []):
        if p.get("name") == ref:
            return p["containerPort"]
    return None


def cpu(v):
    v = str(v)
    return float(v[:-1]) / 1000 if v.endswith("m") else float(v)


def check_k8s(img, drain_ok):
    objs = k8s_objects()
    kinds = {(o["kind"], o["metadata"]["name"]): (f, o) for f, o in objs}
    ns = [o["metadata"]["name"] for f, o in objs if o["kind"] == "Namespace"]
    check(len(ns) == 1, f"k8s: {len(ns)} Namespace objects, wanted 1")
    for f, o in objs:
        if o["kind"] != "Namespace":
            check(o["metadata"].get("namespace") == ns[0], f"k8s {f}: {o['kind']} {o['metadata']['name']} not in namespace {ns[0]}")
    dep = kinds.get(("Deployment", "raysweep"), (None, None))[1]
    if not check(dep, "k8s: no Deployment raysweep"):
        return
    pod = dep["spec"]["template"]["spec"]
    labels = dep["spec"]["template"]["metadata"]["labels"]
    check(dep["spec"]["selector"]["matchLabels"].items() <= labels.items(), "k8s Deployment: selector does not match its pods")
    c = pod["containers"][0]
    argv = c.get("command", ["raysweepd"]) + c.get("args", [])
    version = re.search(r'RSW_VERSION "([^"]+)"', open(os.path.join(ROOT, "include/raysweep/version.h")).read()).group(1)
    check(c.get("image") == f"raysweep:{version}", f"k8s Deployment: image {c.get('image')}, wanted raysweep:{version}")
    port = listen_port(argv)
    check(port_number(c, "http") == port, f"k8s Deployment: containerPort http {port_number(c, 'http')}, the daemon listens on {port}")
    flags = [a for a in argv if a.startswith("--")]
    helptext = serve_help()
    for fl in flags:
        check(re.search(re.escape(fl) + r"\b", helptext), f"k8s Deployment: {fl} is not an option of raysweepd serve")
    # probes
    for kind, path in (("readinessProbe", "/v1/health/ready"), ("livenessProbe", "/v1/health/live"), ("startupProbe", "/v1/health/live")):
        p = c.get(kind, {}).get("httpGet", {})
        check(p.get("path") == path and port_number(c, p.get("port")) == port,
              f"k8s Deployment: {kind} is {p}, wanted GET {path} on port {port}")
    # resources and threads
    res = c.get("resources", {})
    for k in ("requests", "limits"):
        check({"cpu", "memory"} <= set(res.get(k, {})), f"k8s Deployment: resources.{k} lacks cpu or memory: {res.get(k)}")
    if "--threads" in argv:
        check(float(argv[argv.index("--threads") + 1]) == cpu(res.get("limits", {}).get("cpu", 0)),
              f"k8s Deployment: --threads {argv[argv.index('--threads') + 1]} != cpu limit {res.get('limits', {}).get('cpu')}")
    else:
        bad("k8s Deployment: no --threads: raysweepd would start one thread per host core, not per CPU limit")
    # token: Secret -> volume -> mount -> --token-file
    tok = argv[argv.index("--token-file") + 1] if "--token-file" in argv else None
    wired = False
    for m in c.get("volumeMounts", []):
        vol = next((v for v in pod.get("volumes", []) if v["name"] == m["name"]), {})
        s = vol.get("secret")
        if s and tok and os.path.dirname(tok) == m["mountPath"].rstrip("/"):
            item = next((i for i in s.get("items", []) if i["path"] == os.path.basename(tok)), None)
            wired = item is not None and m.get("readOnly") is True
            sec = kinds.get(("Secret", s["secretName"]), (None, None))[1]
            if check(sec, f"k8s: no Secret {s['secretName']} example"):
                check(item and item["key"] in sec.get("stringData", {}), f"k8s Secret {s['secretName']}: no key {item and item['key']}")
                # The placeholder must not work as a token.
                t = os.path.join(TMP, "placeholder-token")
                with open(t, "w") as fh:
                    fh.write(sec["stringData"][item["key"]])
                r = run([os.path.join(BIN, "raysweepd"), "serve", "--listen", "127.0.0.1:0", "--token-file", t], timeout=10)
                check(r.returncode == 2 and "token" in r.stderr,
                      f"k8s Secret example: raysweepd accepts the placeholder as a token (exit {r.returncode})")
            mode = s.get("defaultMode", 0o644)
            gid = pod.get("securityContext", {}).get("fsGroup")
            check(mode & 0o040 and str(gid) == img["uid"], f"k8s: the token file (mode {oct(mode)}, fsGroup {gid}) is not readable by uid {img['uid']}")
    check(wired, f"k8s Deployment: --token-file {tok} is not a read-only mounted key of a Secret")
    check(not any(e.get("name", "").upper().find("TOKEN") >= 0 for e in c.get("env", [])), "k8s Deployment: a token in env")
    # user, file system
    sc = {**pod.get("securityContext", {}), **c.get("securityContext", {})}
    check(sc.get("runAsNonRoot") is True and str(sc.get("runAsUser")) == img["uid"],
          f"k8s Deployment: runAsNonRoot/runAsUser {sc.get('runAsNonRoot')}/{sc.get('runAsUser')}, image uid {img['uid']}")
    if sc.get("readOnlyRootFilesystem"):
        mounts = [m["mountPath"] for m in c.get("volumeMounts", [])]
        blob = argv[argv.index("--blob-dir") + 1] if "--blob-dir" in argv else None
        check(blob in mounts, f"k8s Deployment: read-only root but --blob-dir {blob} is not a volume")
        check("/tmp" in mounts, "k8s Deployment: read-only root but /tmp is not a volume")
    # preStop drain
    pre = c.get("lifecycle", {}).get("preStop", {}).get("exec", {}).get("command", [])
    check(pre[:1] == ["raysweepd-drain"] and "raysweepd-drain" in img["bin"], f"k8s Deployment: preStop {pre} is not the image's raysweepd-drain")
    opt = lambda k, d: float(pre[pre.index(k) + 1]) if k in pre else d
    grace = pod.get("terminationGracePeriodSeconds", 30)
    check(opt("--timeout", 300) + opt("--linger", 15) < grace,
          f"k8s Deployment: drain --timeout + --linger ({opt('--timeout', 300)} + {opt('--linger', 15)}) must be < terminationGracePeriodSeconds {grace}")
    if "--token-file" in pre:
        check(pre[pre.index("--token-file") + 1] == tok, "k8s preStop: --token-file differs from the daemon's")
    if "--url" in pre:
        check(pre[pre.index("--url") + 1] == f"http://127.0.0.1:{port}", f"k8s preStop: --url is not the daemon's port {port}")
    d = probe_daemon("k8s Deployment", argv, [("/v1/health/live", 200), ("/v1/health/ready", 200)])
    if d.ok:
        mp = [d.paths.get(a, a) for a in pre]
        if "--url" in mp:
            mp[mp.index("--url") + 1] = f"http://127.0.0.1:{d.port}"
        else:
            mp += ["--url", f"http://127.0.0.1:{d.port}"]
        t0 = time.time()
        r = run([os.path.join(DOCKER, "raysweepd-drain")] + mp[1:] + ["--linger", "0"], timeout=60)
        check(r.returncode == 0 and time.time() - t0 < 10 and "idle" in r.stderr,
              f"k8s preStop on an idle replica: exit {r.returncode} after {time.time() - t0:.1f} s: {r.stderr}")
        check(d.stop() == 0, "k8s Deployment: raysweepd did not exit 0 on SIGTERM")
    # Services
    hl = kinds.get(("Service", "raysweep-replicas"), (None, None))[1]
    if check(hl, "k8s: no headless Service raysweep-replicas"):
        check(hl["spec"].get("clusterIP") == "None", "k8s Service raysweep-replicas: not headless")
        check(hl["spec"]["selector"].items() <= labels.items(), "k8s Service raysweep-replicas: selector misses the replicas")
        check(all(port_number(c, p["targetPort"]) == port for p in hl["spec"]["ports"]), "k8s Service raysweep-replicas: targetPort is not the daemon's")
    cm = kinds.get(("ConfigMap", "raysweep-haproxy"), (None, None))[1]
    bal = kinds.get(("Deployment", "raysweep-balancer"), (None, None))[1]
    svc = kinds.get(("Service", "raysweep"), (None, None))[1]
    if check(cm and bal and svc, "k8s: the balancer (ConfigMap raysweep-haproxy, Deployment raysweep-balancer, Service raysweep) is incomplete"):
        hp = hl["spec"]["ports"][0]["port"] if hl else port
        binds = haproxy_check("k8s ConfigMap raysweep-haproxy", cm["data"]["haproxy.cfg"],
                              template=f"raysweep-replicas.{ns[0]}.svc.cluster.local:{hp}")
        bc = bal["spec"]["template"]["spec"]["containers"][0]
        check(bal["spec"]["replicas"] == 1, "k8s raysweep-balancer: more than one HAProxy could hash one shard to two replicas")
        vm = next((m for m in bc.get("volumeMounts", []) if m["mountPath"] == "/usr/local/etc/haproxy"), None)
        vol = next((v for v in bal["spec"]["template"]["spec"]["volumes"] if vm and v["name"] == vm["name"]), {})
        check(vol.get("configMap", {}).get("name") == "raysweep-haproxy", "k8s raysweep-balancer: the ConfigMap is not mounted at /usr/local/etc/haproxy")
        check(port_number(bc, "http") in binds, f"k8s raysweep-balancer: containerPort {port_number(bc, 'http')}, HAProxy binds {binds}")
        bl = bal["spec"]["template"]["metadata"]["labels"]
        check(svc["spec"]["selector"].items() <= bl.items() and not svc["spec"]["selector"].items() <= labels.items(),
              "k8s Service raysweep: must select the balancer and not the replicas")
        check(all(port_number(bc, p["targetPort"]) in binds for p in svc["spec"]["ports"]), "k8s Service raysweep: targetPort is not HAProxy's")


# ---------------------------------------------------------------- drain
def check_drain():
    """raysweepd-drain waits for a running job, and gives up at --timeout."""
    d = Daemon("drain", ["serve", "--listen", "127.0.0.1:0", "--token-file", "/t", "--threads", "1"])
    if not d.ok:
        return False
    tokf = d.paths["/t"]
    scene = open(os.path.join(ROOT, "proto/examples/hdistant_lambertian.json"), "rb").read()
    st, body = http(d.port, "/v1/scenes", d.token, "POST", scene)
    if not check(st in (200, 201), f"drain: scene push answered {st}: {body[:300]!r}"):
        return False
    sid = json.loads(body)["id"]

    def submit(n, spp):
        # hdistant_lambertian tabulates the sun over [400, 700] nm, and a job
        # whose wavelength leaves the table is refused at submission.
        ctx = [{"id": f"w{i}", "wavelength": 400 + 300 * i / max(n - 1, 1)} for i in range(n)]
        st, body = http(d.port, f"/v1/scenes/{sid}/jobs", d.token, "POST",
                        json.dumps({"defaults": {"spp": spp}, "contexts": ctx}).encode())
        check(st == 202, f"drain: job submission ({n} contexts) answered {st}: {body[:300]!r}")
        return json.loads(body)["id"] if st == 202 else None

    def job_state(j):
        st, body = http(d.port, f"/v1/jobs/{j}", d.token)
        return json.loads(body).get("state") if st == 200 else f"HTTP {st}"

    drain = [os.path.join(DOCKER, "raysweepd-drain"), "--url", f"http://127.0.0.1:{d.port}", "--token-file", tokf]
    # A job of about a second: the drain must outlast it and find it succeeded.
    j = submit(6, 128)
    if not check(j, "drain: job submission failed"):
        return False
    before = job_state(j)
    check(before in ("queued", "running"), f"drain: the job was {before} before the drain started (too short to test)")
    t0 = time.time()
    r = run(drain + ["--linger", "0", "--interval", "0.1", "--timeout", "120"], timeout=150)
    waited = time.time() - t0
    state = job_state(j)
    check(r.returncode == 0 and state == "succeeded",
          f"drain: returned {r.returncode} after {waited:.2f} s with the job {state}: {r.stderr}")
    print(f"{NAME}: raysweepd-drain waited {waited:.2f} s for a running 6-context job (state then: {state})", flush=True)
    # A long job and a short timeout: exit 1, the job still running.
    j2 = submit(60, 1024)
    t0 = time.time()
    r = run(drain + ["--timeout", "0.5", "--interval", "0.1"], timeout=30)
    check(r.returncode == 1 and "still busy" in r.stderr and 0.4 < time.time() - t0 < 5,
          f"drain --timeout 0.5 on a busy replica: exit {r.returncode} after {time.time() - t0:.2f} s: {r.stderr}")
    check(job_state(j2) in ("queued", "running"), f"drain: the long job is {job_state(j2)}, wanted still running")
    # A wrong token: metrics unreadable, so it never reports idle.
    bad_tok = os.path.join(TMP, "wrong-token")
    with open(bad_tok, "w") as fh:
        fh.write("wrong\n")
    r = run(drain[:3] + ["--token-file", bad_tok, "--timeout", "0.3", "--interval", "0.1"], timeout=30)
    check(r.returncode == 1 and "401" in r.stderr, f"drain with a wrong token: exit {r.returncode}: {r.stderr[-300:]}")
    http(d.port, f"/v1/jobs/{j2}:cancel", d.token, "POST", b"{}")
    check(d.stop() == 0, "drain: raysweepd did not exit 0 on SIGTERM")
    # No daemon: nothing to drain.
    r = run(drain + ["--timeout", "5"], timeout=30)
    check(r.returncode == 0 and "nothing to drain" in r.stderr, f"drain with no daemon: exit {r.returncode}: {r.stderr}")
    return True


def main():
    for b in ("raysweepd", "raysweep"):
        if not os.access(os.path.join(BIN, b), os.X_OK):
            bad(f"{b} must be built in {BIN} (make)")
            finish()
    oa = yaml.safe_load(open(os.path.join(ROOT, "proto/openapi.yaml")))
    for p in ("/v1/health/live", "/v1/health/ready"):
        check(oa["paths"].get(p, {}).get("get", {}).get("security") == [], f"openapi: GET {p} missing or not open (security: [])")
    routes = run([os.path.join(BIN, "raysweepd"), "routes"]).stdout.split("\n")
    for p in ("/v1/health/live", "/v1/health/ready", "/metrics"):
        check(f"GET {p}" in routes, f"raysweepd routes: no GET {p}")
    try:
        t = time.time()
        img = check_dockerfile()
        t1 = time.time()
        check_compose(img)
        t2 = time.time()
        drain_ok = check_drain()
        t3 = time.time()
        check_k8s(img, drain_ok)
        print(f"{NAME}: seconds: Dockerfile {t1 - t:.1f}, compose {t2 - t1:.1f}, drain {t3 - t2:.1f}, k8s {time.time() - t3:.1f}")
    except Exception as e:  # a parse error is a failure with its reason, not a crash
        import traceback
        bad(f"{type(e).__name__}: {e}\n{traceback.format_exc()}")
    finish()


if __name__ == "__main__":
    main()
