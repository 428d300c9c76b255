"""What the Python benches share (imported, not run by make bench): a
raysweepd on an ephemeral loopback port and one kept-alive connection."""
import http.client
import json
import os
import subprocess
import sys
import tempfile
import time

root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
bindir = os.environ.get("RSW_BIN_DIR", os.path.join(root, "build", "bin"))


class Daemon:
    """raysweepd serve --threads THREADS on 127.0.0.1:0; req() exits the
    bench (named NAME) on any answer of 300 or more."""

    def __init__(self, name, threads=2):
        self.name = name
        pf = os.path.join(tempfile.mkdtemp(), "port")
        self.proc = subprocess.Popen([os.path.join(bindir, "raysweepd"), "serve", "--listen", "127.0.0.1:0",
                                      "--port-file", pf, "--threads", str(threads)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(500):
            if os.path.exists(pf) and open(pf).read().strip():
                break
            time.sleep(0.01)
        self.conn = http.client.HTTPConnection("127.0.0.1", int(open(pf).read()))

    def req(self, method, path, body=None):
        self.conn.request(method, path, body=body, headers={"Content-Type": "application/json"} if body else {})
        r = self.conn.getresponse()
        data = r.read()
        if r.status >= 300:
            sys.exit(f"{self.name}: {method} {path}: {r.status} {data[:300]!r}")
        return data

    def wait_job(self, jid):
        """Poll until the job ends; its final JSON (exits unless it succeeded)."""
        while True:
            j = json.loads(self.req("GET", f"/v1/jobs/{jid}"))
            if j["state"] not in ("queued", "running"):
                break
            time.sleep(0.02)
        if j["state"] != "succeeded":
            sys.exit(f"{self.name}: job {jid} {j['state']}: {j.get('error')}")
        return j

    def close(self):
        self.proc.terminate()
        self.proc.wait()
