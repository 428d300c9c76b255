#!/usr/bin/python3
"""Drives the web viewer (ui/, served at /ui/) in headless Chromium through
the DevTools protocol, for tests/integration/test_viewer.sh. Standard
library only: the websocket client (RFC 6455, text frames) and the PNG
decoder are here.

    viewer_driver.py --chromium PATH --base http://127.0.0.1:PORT
                     --token-base http://127.0.0.1:PORT2 --token TOKEN
                     --artefacts DIR [--docs-png FILE]

Prints `ok   NAME` or `FAIL NAME: why` per check; the exit status is 1 when
any failed. Screenshots go to --artefacts (and, with --docs-png, the
screenshot of the whole page to that file, for the README).
"""

import argparse
import base64
import json
import math
import os
import re
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import png_read  # noqa: E402 (tests/support, beside this file)

failed = 0

# A principal plane of 9 directions from -80° to +80° in the x-z plane
# (each triple is the direction a sub-sensor looks, into the scene), over a
# rough conductor lit from θ = 30° in the x-z plane: the brightest
# direction is near the specular one, +30° towards φ = 0°.
MDISTANT_SCENE = {
    "type": "scene", "variant": "mono",
    "pp": {"type": "mdistant",
           "directions": "-0.9848 0 -0.1736 -0.866 0 -0.5 -0.6428 0 -0.766 -0.342 0 -0.9397 0 0 -1 "
                         "0.342 0 -0.9397 0.6428 0 -0.766 0.866 0 -0.5 0.9848 0 -0.1736",
           "sampler": {"type": "independent", "sample_count": 64},
           "film": {"type": "hdrfilm", "width": 9, "height": 1, "rfilter": {"type": "box"}}},
    "sun": {"type": "directional", "direction": [0.5, 0, -0.866], "irradiance": 2.0},
    "plate": {"type": "rectangle", "bsdf": {"type": "roughconductor"}},
}

# A 4x4 Stokes camera under tests/plugins/polarized_sky.c (the daemon runs
# with --plugin-dir build/plugins): every pixel sees DoLP 0.6 and AoLP 30°.
STOKES_SCENE = {
    "type": "scene", "variant": "mono",
    "cam": {"type": "perspective", "fov": 20,
            "to_world": [{"lookat": {"origin": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0]}}],
            "sampler": {"type": "independent", "sample_count": 4},
            "film": {"type": "hdrfilm", "width": 4, "height": 4, "pixel_format": "stokes",
                     "rfilter": {"type": "box"}}},
    "sky": {"type": "polarized_sky", "polarization": 0.6, "polarization_angle": 30},
}

# An RPV plate under a sun whose zenith is the coordinate `sza` (a template
# of the scene), a 4x4 hdistant film: the job form sweeps sza and the
# plate's rho_0 (a parameter key), the sweep view plots its BRF.
SWEEP_SCENE = {
    "type": "scene", "variant": "mono",
    "hd": {"type": "hdistant", "target": [0, 0, 0],
           "sampler": {"type": "independent", "sample_count": 16},
           "film": {"type": "hdrfilm", "width": 4, "height": 4, "rfilter": {"type": "box"}}},
    "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": 2.0},
    "plate": {"type": "rectangle", "to_world": [{"scale": [10, 10, 1]}],
              "bsdf": {"type": "rpv", "rho_0": 0.12, "k": 0.9, "g": -0.25, "rho_c": 0.3}},
    "templates": {"sun.direction": {"sun": {"zenith": "sza", "azimuth": 0}}},
}

# matplotlib's viridis at 9 stops, as ui/plot.js interpolates it.
VIRIDIS = [(68, 1, 84), (72, 40, 120), (62, 73, 137), (49, 104, 142), (38, 130, 142),
           (31, 158, 137), (53, 183, 121), (110, 206, 88), (253, 231, 37)]


def viridis(t):
    t = min(1.0, max(0.0, t))
    x = t * 8
    i = min(7, int(x))
    f = x - i
    return tuple(VIRIDIS[i][k] + (VIRIDIS[i + 1][k] - VIRIDIS[i][k]) * f for k in range(3))


def p995(values):
    """The 99.5th percentile (nearest rank) of the finite values > 0."""
    v = sorted(x for x in values if x is not None and math.isfinite(x) and x > 0)
    return v[min(len(v), max(1, math.ceil(0.995 * len(v)))) - 1]


def ok(name):
    print(f"ok   {name}", flush=True)


def fail(name, why):
    global failed
    failed += 1
    print(f"FAIL {name}: {why}", flush=True)


# ---- the daemon's API, for set-up and for checking what the UI did -----------
def http(method, url, body=None, token=None, accept="application/json"):
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(url, data=data, method=method)
    if data is not None:
        req.add_header("Content-Type", "application/json")
    req.add_header("Accept", accept)
    if token:
        req.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            raw = r.read()
            return r.status, json.loads(raw) if raw else None
    except urllib.error.HTTPError as e:
        raw = e.read()
        try:
            return e.code, json.loads(raw)
        except ValueError:
            return e.code, raw


# ---- a minimal websocket client ------------------------------------------------
class WebSocket:
    def __init__(self, url):
        assert url.startswith("ws://")
        hostport, path = url[5:].split("/", 1)
        host, port = hostport.rsplit(":", 1)
        self.sock = socket.create_connection((host, int(port)), timeout=30)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (f"GET /{path} HTTP/1.1\r\nHost: {hostport}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
             f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("the DevTools socket closed during the handshake")
            head += chunk
        head, self.buf = head.split(b"\r\n\r\n", 1)
        if b" 101 " not in head.split(b"\r\n", 1)[0]:
            raise ConnectionError(f"websocket handshake refused: {head[:200]!r}")

    def _read(self, n):
        while len(self.buf) < n:
            chunk = self.sock.recv(1 << 16)
            if not chunk:
                raise ConnectionError("the DevTools socket closed")
            self.buf += chunk
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def _send_frame(self, opcode, payload):
        head = bytes([0x80 | opcode])
        n = len(payload)
        if n < 126:
            head += bytes([0x80 | n])
        elif n < 1 << 16:
            head += bytes([0x80 | 126]) + struct.pack(">H", n)
        else:
            head += bytes([0x80 | 127]) + struct.pack(">Q", n)
        mask = os.urandom(4)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(head + mask + masked)

    def send(self, text):
        self._send_frame(1, text.encode())

    def recv(self):
        message = b""
        while True:
            b0, b1 = self._read(2)
            opcode, n = b0 & 0x0F, b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._read(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._read(8))[0]
            mask = self._read(4) if b1 & 0x80 else None
            payload = self._read(n)
            if mask:
                payload = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
            if opcode == 8:
                raise ConnectionError("the DevTools socket was closed by the browser")
            if opcode == 9:
                self._send_frame(10, payload)
                continue
            if opcode in (0, 1, 2):
                message += payload
                if b0 & 0x80:
                    return message.decode()


class Page:
    """One browser tab over the DevTools protocol."""

    def __init__(self, ws_url):
        self.ws = WebSocket(ws_url)
        self.seq = 0
        self.errors = []  # uncaught exceptions and console errors of the page
        self.call("Page.enable")
        self.call("Runtime.enable")
        self.call("Emulation.setDeviceMetricsOverride",
                  {"width": 1360, "height": 1180, "deviceScaleFactor": 1, "mobile": False})

    def call(self, method, params=None):
        self.seq += 1
        me = self.seq
        self.ws.send(json.dumps({"id": me, "method": method, "params": params or {}}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == me:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            m = msg.get("method")
            if m == "Runtime.exceptionThrown":
                d = msg["params"]["exceptionDetails"]
                self.errors.append((d.get("exception") or {}).get("description") or d.get("text"))
            elif m == "Runtime.consoleAPICalled" and msg["params"].get("type") == "error":
                self.errors.append(" ".join(str(a.get("value", a.get("description", ""))) for a in msg["params"]["args"]))

    def js(self, expr):
        r = self.call("Runtime.evaluate", {"expression": expr, "awaitPromise": True, "returnByValue": True})
        if "exceptionDetails" in r:
            raise RuntimeError(f"{expr[:80]}: {r['exceptionDetails'].get('text')} "
                               f"{(r['exceptionDetails'].get('exception') or {}).get('description', '')}")
        return r["result"].get("value")

    def wait(self, expr, timeout=15.0):
        """Poll expr until it is truthy (in JavaScript); returns its value (True for
        an element), or None after timeout."""
        end = time.monotonic() + timeout
        while True:
            v = self.js(f"(() => {{ const v = ({expr}); return v instanceof Node ? true : v; }})()")
            if v:
                return v
            if time.monotonic() > end:
                return None
            time.sleep(0.1)

    def goto(self, url):
        self.call("Page.navigate", {"url": url})
        self.wait("document.readyState === 'complete'", 20)

    def rect(self, selector):
        return self.js(f"(() => {{ const e = document.querySelector({json.dumps(selector)}); if (!e) return null;"
                       " e.scrollIntoView({block: 'center'}); const r = e.getBoundingClientRect();"
                       " return {x: r.left, y: r.top, w: r.width, h: r.height, sx: window.scrollX, sy: window.scrollY}; })()")

    def click(self, selector):
        r = self.rect(selector)
        if not r:
            raise RuntimeError(f"nothing matches {selector}")
        x, y = r["x"] + r["w"] / 2, r["y"] + r["h"] / 2
        for t in ("mouseMoved", "mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", {"type": t, "x": x, "y": y, "button": "left", "clickCount": 1})

    def select_job(self, job, tries=5):
        """Click a job in the list until its results are listed: the list is
        redrawn while jobs run, and a click that lands during a redraw hits
        nothing (the tests share 2 cores with the rest of make test)."""
        for _ in range(tries):
            self.click(f'#jobs li[data-job="{job}"]')
            if self.wait(f"document.getElementById('results').dataset.job === '{job}'", 6):
                return True
        return False

    def hover(self, x, y):
        self.call("Input.dispatchMouseEvent", {"type": "mouseMoved", "x": x, "y": y})

    def type_into(self, selector, text):
        """Focus a field, select what it holds, and type text over it."""
        self.js(f"(() => {{ const e = document.querySelector({json.dumps(selector)}); e.focus(); e.select(); }})()")
        self.call("Input.insertText", {"text": text})

    def key(self, name, code):
        for t in ("rawKeyDown", "keyUp"):
            self.call("Input.dispatchKeyEvent", {"type": t, "key": name, "code": name,
                                                 "windowsVirtualKeyCode": code, "nativeVirtualKeyCode": code})

    def screenshot(self, rect=None):
        p = {"format": "png", "captureBeyondViewport": True}
        if rect:
            # The clip is in document coordinates, the rectangle in the viewport's.
            p["clip"] = {"x": rect["x"] + rect["sx"], "y": rect["y"] + rect["sy"], "width": rect["w"],
                         "height": rect["h"], "scale": 1}
        return base64.b64decode(self.call("Page.captureScreenshot", p)["data"])


# ---- PNG (8-bit RGB or RGBA, non-interlaced: what Chromium writes) -------------
def png_decode(data):
    """(width, height, rows of (r, g, b) pixels), by png_read.py's decoder."""
    w, h, ch, rows = png_read.decode_png(data, (2, 6))
    return w, h, [[tuple(line[x * ch:x * ch + 3]) for x in range(w)] for line in rows]


# ---- the checks ------------------------------------------------------------------------
def check(name, fn):
    try:
        why = fn()
    except Exception as e:  # a check that crashes fails, with the reason
        why = f"{type(e).__name__}: {e}"
    if why:
        fail(name, why)
    else:
        ok(name)
    return not why


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--chromium", required=True)
    ap.add_argument("--base", required=True)
    ap.add_argument("--token-base", required=True)
    ap.add_argument("--token", required=True)
    ap.add_argument("--artefacts", required=True)
    ap.add_argument("--docs-png")
    a = ap.parse_args()
    os.makedirs(a.artefacts, exist_ok=True)
    profile = tempfile.mkdtemp(prefix="rsw-chromium-")
    cmd = [a.chromium, "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
           "--no-first-run", "--no-default-browser-check", "--disable-extensions", "--disable-sync",
           "--disable-background-networking", "--disable-component-update", "--mute-audio",
           "--remote-debugging-port=0", f"--user-data-dir={profile}", "about:blank"]
    log = open(os.path.join(a.artefacts, "chromium.log"), "w")
    browser = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    try:
        run(a, profile, browser)
    finally:
        browser.terminate()
        try:
            browser.wait(10)
        except subprocess.TimeoutExpired:
            browser.kill()
            browser.wait()
        shutil.rmtree(profile, ignore_errors=True)
    sys.exit(1 if failed else 0)


def connect(profile, browser):
    port_file = os.path.join(profile, "DevToolsActivePort")
    end = time.monotonic() + 30
    while not os.path.exists(port_file) or os.path.getsize(port_file) == 0:
        if browser.poll() is not None or time.monotonic() > end:
            raise RuntimeError("chromium did not start (see chromium.log in the artefacts)")
        time.sleep(0.1)
    port = int(open(port_file).read().split()[0])
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
        pages = [t for t in json.load(r) if t.get("type") == "page"]
    return Page(pages[0]["webSocketDebuggerUrl"])


def run(a, profile, browser):
    t0 = time.monotonic()
    page = connect(profile, browser)
    print(f"# chromium ready in {time.monotonic() - t0:.1f} s", flush=True)
    base = a.base
    st, scenes = http("GET", f"{base}/v1/scenes")
    scene = scenes["scenes"][0]["id"]
    art = lambda n: os.path.join(a.artefacts, n)

    # 1. The scene list and the parameter table.
    page.goto(f"{base}/ui/")

    def listed():
        ids = page.wait(f"(() => {{ const s = [...document.querySelectorAll('#scenes li[data-scene]')].map(e => e.dataset.scene);"
                        f" return s.length && document.querySelectorAll('#params tbody tr').length ? s : null; }})()")
        if not ids:
            return f"no scene listed, or no parameter table; banner: {page.js('document.getElementById(`banner`).textContent')}"
        if scene not in ids:
            return f"the default scene {scene} is not in {ids}"
        n = page.js("document.querySelectorAll('#params tbody tr').length")
        st2, table = http("GET", f"{base}/v1/scenes/{scene}/params")
        if n != len(table["params"]):
            return f"the table shows {n} rows, the scene has {len(table['params'])} parameters"
    check("lists the default scene and its parameter table", listed)

    key = "rectangle.bsdf.alpha.value"

    def search():
        page.type_into("#param-search", "alpha rectangle")
        shown = page.js("[...document.querySelectorAll('#params tbody tr')].map(e => e.dataset.key)")
        page.type_into("#param-search", "")
        if shown != [key]:
            return f"searching 'alpha rectangle' shows {shown}, want [{key}]"
    check("searches the parameter table", search)

    # 2. Inline edit: click the value, type, Enter: a PATCH.
    def edit():
        page.click(f'#params tr[data-key="{key}"] td.value')
        if not page.wait(f'document.querySelector(\'#params tr[data-key="{key}"] td.value input\')', 30):
            return "clicking the value opened no editor"
        page.type_into(f'#params tr[data-key="{key}"] td.value input', "0.25")
        page.key("Enter", 13)
        if not page.wait("document.getElementById('params').dataset.revision === '1'", 30):
            return f"the table's revision did not become 1; banner: {page.js('document.getElementById(`banner`).textContent')}"
        st2, table = http("GET", f"{base}/v1/scenes/{scene}/params?match={key}")
        v = table["params"][0]["value"]
        vals = v if isinstance(v, list) else [v]
        if table["revision"] != 1 or any(abs(x - 0.25) > 1e-12 for x in vals):
            return f"GET params says revision {table['revision']}, value {v}; want 1 and 0.25"
        shown = page.js(f'document.querySelector(\'#params tr[data-key="{key}"] td.value\').textContent')
        if "0.25" not in shown:
            return f"the table shows {shown!r} after the edit"
    check("edits a parameter inline (PATCH, checked with GET params)", edit)

    # 3. Render with spp and seed; the film on its canvas.
    spp, seed = 256, 3
    shown = {}

    def render():
        page.type_into("#r-spp", str(spp))
        page.type_into("#r-seed", str(seed))
        page.js("document.getElementById('film').dataset.ready = ''")
        page.click("#render")
        if not page.wait("document.getElementById('film').dataset.ready === '1'", 30):
            return f"no film shown; banner: {page.js('document.getElementById(`banner`).textContent')}"
        status = page.js("document.getElementById('render-status').textContent")
        if f"{spp} spp, seed {seed}" not in status:
            return f"render status {status!r}"
    if not check("renders with spp and seed from the form", render):
        return

    def film_pixels():
        r = page.rect("#film")
        png = page.screenshot(r)
        open(art("film.png"), "wb").write(png)
        w, h, rows = png_decode(png)
        shown["film"] = (w, h, rows)
        px = [p for row in rows for p in row]
        lit = sum(1 for p in px if sum(p) > 30)
        if w < 64 or h < 64:
            return f"the film canvas is {w}x{h} on screen"
        if lit < 0.05 * len(px) or len(set(px)) < 16:
            return f"the film looks blank: {lit} of {len(px)} pixels lit, {len(set(px))} colours"
        page.hover(r["x"] + r["w"] * 0.3, r["y"] + r["h"] * 0.6)
        text = page.wait("(() => { const t = document.getElementById('hover').textContent; return t.includes('pixel (') && t; })()", 30)
        if not text or "θ" not in text:
            return f"hovering the film shows {text!r}"
    check("shows the film (screenshot pixels) and the value under the pointer", film_pixels)

    # 4. The polar plot of the hdistant film, oriented by the film's angles.
    def polar():
        if page.js("document.getElementById('plot').dataset.kind") != "polar":
            return "no polar plot for the hdistant film"
        st2, film = http("POST", f"{base}/v1/scenes/{scene}:render", {"spp": spp, "seed": seed})
        c = len(film["channels"])
        lum = [sum(film["data"][k * c:(k + 1) * c]) for k in range(film["width"] * film["height"])]
        k = max(range(len(lum)), key=lum.__getitem__)
        th, ph = film["meta"]["zenith_deg"][k], math.radians(film["meta"]["azimuth_deg"][k])
        geo = page.js("(() => { const d = document.getElementById('plot').dataset; return {cx: +d.cx, cy: +d.cy, r: +d.r}; })()")
        r = page.rect("#plot")
        png = page.screenshot(r)
        open(art("polar.png"), "wb").write(png)
        w, h, rows = png_decode(png)
        at = lambda x, y: rows[min(h - 1, max(0, round(y)))][min(w - 1, max(0, round(x)))]
        bright = lambda x, y: sum(at(x, y))
        ex, ey = geo["cx"] + th / 90 * geo["r"] * math.cos(ph), geo["cy"] - th / 90 * geo["r"] * math.sin(ph)
        mx, my = geo["cx"] - th / 90 * geo["r"] * math.cos(ph), geo["cy"] + th / 90 * geo["r"] * math.sin(ph)
        inside = [at(x, y) for y in range(h) for x in range(w)
                  if (x - geo["cx"]) ** 2 + (y - geo["cy"]) ** 2 < (geo["r"] - 3) ** 2]
        if len(set(inside)) < 16:
            return "the disk of the polar plot is blank"
        if sum(at(4, 4)) < 700:
            return f"outside the disk is not background: {at(4, 4)}"
        # Pixel k's colour on the film canvas must be where the plot puts
        # (θ, φ) (a grid line may cross that point: look within 4 px), and
        # not at the point opposite.
        fw, fh, frows = shown["film"]
        sx, sy = fw / film["width"], fh / film["height"]
        want = frows[int((k // film["width"] + 0.5) * sy)][int((k % film["width"] + 0.5) * sx)]
        near = lambda x0, y0: min(max(abs(p - q) for p, q in zip(at(x0 + dx, y0 + dy), want))
                                  for dx in range(-4, 5) for dy in range(-4, 5))
        if near(ex, ey) > 24:
            return (f"the film's brightest pixel {k} (θ {th:.1f}°, φ {math.degrees(ph):.1f}°, colour {want}) is not "
                    f"at ({ex:.0f}, {ey:.0f}) on the plot: {at(ex, ey)}")
        if near(mx, my) <= 24:
            return f"the point opposite (φ + 180°) has the same colour {want}"
        page.hover(r["x"] + ex, r["y"] + ey)
        text = page.wait("(() => { const t = document.getElementById('hover').textContent; return t.startsWith('plot:') && t; })()", 30)
        want = f"pixel ({k % film['width']}, {k // film['width']})"
        if not text or want not in text:
            return f"hovering the brightest point shows {text!r}, want {want}"
    check("draws the polar plot of the hdistant film (zenith radius, east-right azimuth)", polar)

    # 5. Jobs: progress from the event stream, to the end; cancel.
    n_ctx = 6

    def job_follow():
        st2, job = http("POST", f"{base}/v1/scenes/{scene}/jobs",
                        {"defaults": {"spp": 400}, "contexts": [{"id": f"c{i}", "seed": i} for i in range(n_ctx)]})
        if st2 != 202:
            return f"submitting the job: {st2} {job}"
        jid = job["id"]
        page.click("#jobs-refresh")
        sel = f'#jobs li[data-job="{jid}"]'
        if not page.wait(f"document.querySelector('{sel}')", 30):
            return "the job is not listed"
        end = page.wait(f"(() => {{ const e = document.querySelector('{sel}'); return e && e.dataset.state === 'succeeded'"
                        f" && e.dataset.done === '{n_ctx}' && e.dataset.total === '{n_ctx}' && Object.assign({{}}, e.dataset); }})()", 40)
        if not end:
            return f"the job did not show succeeded {n_ctx}/{n_ctx}: {page.js(f'Object.assign({{}}, document.querySelector(`{sel}`).dataset)')}"
        if int(end["events"]) < 1:
            return f"no event came through the event stream: {end}"
        if not page.select_job(jid) or not page.wait("document.querySelectorAll('#results a').length === %d" % n_ctx, 30):
            return "the job's results are not listed"
        page.click("#results a")
        if not page.wait(f"document.getElementById('film-title').dataset.job === '{jid}'", 30):
            return "clicking a result did not show its film"
    check("follows a running job to the end (event stream) and shows its results", job_follow)

    def job_cancel():
        st2, job = http("POST", f"{base}/v1/scenes/{scene}/jobs",
                        {"defaults": {"spp": 20000}, "contexts": [{"id": f"long{i}"} for i in range(20)]})
        jid = job["id"]
        page.click("#jobs-refresh")
        sel = f'#jobs li[data-job="{jid}"] button'
        if not page.wait(f"document.querySelector('{sel}')", 30):
            return "the running job has no cancel button"
        cancelled = f"document.querySelector('#jobs li[data-job=\"{jid}\"]').dataset.state === 'cancelled'"
        for _ in range(5):  # (a click during the list's redraw hits nothing: again)
            if not page.js(f"!!document.querySelector('{sel}')"):
                break
            page.click(sel)
            if page.wait(cancelled, 6):
                break
        if not page.wait(cancelled, 20):
            return "the job did not show cancelled"
        st2, j = http("GET", f"{base}/v1/jobs/{jid}")
        if j["state"] != "cancelled":
            return f"the API says {j['state']}"
    check("cancels a running job", job_cancel)

    page.click('#jobs li[data-state="succeeded"]')  # a finished job's results, for the picture
    page.type_into("#param-search", "bsdf")
    time.sleep(0.3)
    png = page.screenshot()
    open(art("viewer.png"), "wb").write(png)
    if page.errors:
        fail("no script errors", "; ".join(map(str, page.errors[:3])))
    else:
        ok("no script errors")

    # 6. A daemon with a token: the page loads, the API refuses it until the token is given.
    tb = a.token_base

    def token():
        page.goto(f"{tb}/ui/")
        if not page.wait("document.body.dataset.auth === 'required'", 30):
            return "the page did not say that a token is needed"
        text = page.js("document.getElementById('banner').textContent")
        if "requires a bearer token" not in text:
            return f"banner: {text!r}"
        if page.js("document.querySelectorAll('#scenes li[data-scene]').length"):
            return "scenes are listed without the token"
        open(art("token-refused.png"), "wb").write(page.screenshot())
        page.type_into("#token", "wrong-" + a.token)
        page.click("#token-form button[type=submit]")
        if not page.wait("document.getElementById('banner').textContent.includes('refused the token')", 30):
            return f"a wrong token: banner {page.js('document.getElementById(`banner`).textContent')!r}"
        page.type_into("#token", a.token)
        page.click("#token-form button[type=submit]")
        if not page.wait("document.body.dataset.auth === 'ok' && document.querySelectorAll('#scenes li[data-scene]').length > 0", 30):
            return "with the token the scenes are not listed"
        if page.js("sessionStorage.getItem('raysweep.token')") != a.token:
            return "the token is not kept in sessionStorage"
    check("with a token configured, refuses without it and works with it", token)
    if page.errors:
        fail("no script errors (token daemon)", "; ".join(map(str, page.errors[:3])))

    # 7. An mdistant principal plane: value against signed zenith.
    def plane():
        st2, sc = http("POST", f"{base}/v1/scenes", MDISTANT_SCENE)
        if st2 not in (200, 201):
            return f"posting the mdistant scene: {st2} {sc}"
        page.goto(f"{base}/ui/")
        li = f'#scenes li[data-scene="{sc["id"]}"]'
        if not page.wait(f"document.querySelector('{li}')", 30):
            return "the mdistant scene is not listed"
        page.click(li)
        if not page.wait(f"(document.querySelector('#scenes li.selected') || {{dataset: {{}}}}).dataset.scene === '{sc['id']}'"
                         " && document.getElementById('r-sensor').value === 'pp'", 10):
            return "the mdistant scene was not selected"
        page.js("document.getElementById('plot').dataset.kind = ''")
        page.type_into("#r-spp", "64")
        page.type_into("#r-seed", "0")
        page.click("#render")
        if not page.wait("document.getElementById('plot').dataset.kind === 'plane'", 30):
            return f"no principal-plane plot; banner: {page.js('document.getElementById(`banner`).textContent')}"
        st2, film = http("POST", f"{base}/v1/scenes/{sc['id']}:render", {"spp": 64, "seed": 0})
        k = max(range(film["width"]), key=lambda i: film["data"][i])
        th, ph = film["meta"]["zenith_deg"][k], film["meta"]["azimuth_deg"][k]
        signed = th if math.cos(math.radians(ph)) >= 0 else -th  # phi0 is 0 here: the first direction's
        geo = page.js("(() => { const d = document.getElementById('plot').dataset; return {x0: +d.x0, x1: +d.x1}; })()")
        r = page.rect("#plot")
        png = page.screenshot(r)
        open(art("mdistant.png"), "wb").write(png)
        w, h, rows = png_decode(png)
        line = [(y, x) for y in range(h) for x in range(w)
                if max(abs(p - q) for p, q in zip(rows[y][x], (38, 130, 142))) < 30]
        if len(line) < 50:
            return f"the plot has no line ({len(line)} pixels of its colour)"
        top_y, top_x = min(line)
        want_x = geo["x0"] + (signed + 90) / 180 * (geo["x1"] - geo["x0"])
        if abs(top_x - want_x) > 6:
            return (f"the highest point of the line is at x {top_x}, the brightest direction (signed θ {signed:.1f}°) "
                    f"is at x {want_x:.0f}")
    check("plots an mdistant principal plane against signed zenith", plane)

    # 8. The job form: a grid of a template's coordinate and a parameter key.
    st2, sw = http("POST", f"{base}/v1/scenes?name=sweep-plate.json", SWEEP_SCENE)
    sweep = {}

    def job_form():
        if st2 not in (200, 201):
            return f"posting the sweep scene: {st2} {sw}"
        page.goto(f"{base}/ui/")
        li = f'#scenes li[data-scene="{sw["id"]}"]'
        if not page.wait(f"document.querySelector('{li}')", 30):
            return "the sweep scene is not listed"
        shown = page.js(f"document.querySelector('{li} .id').textContent")
        if shown != "sweep-plate.json":
            return f"the scene pushed as sweep-plate.json is listed as {shown!r}"
        page.click(li)
        if not page.wait("document.getElementById('r-sensor').value === 'hd' && document.getElementById('j-sensors').value === 'hd'", 30):
            return "the sweep scene was not selected"
        page.js("document.getElementById('job-box').open = true")
        page.type_into(".grid-row:nth-child(1) .g-name", "sza")
        page.type_into(".grid-row:nth-child(1) .g-values", "0, 30, 60")
        page.click("#j-add")
        page.type_into(".grid-row:nth-child(2) .g-name", "plate.bsdf.rho_0.value")
        page.type_into(".grid-row:nth-child(2) .g-values", "0.1:0.3:0.1")
        page.type_into("#j-spp", "32")
        page.click("#j-brf")
        page.click("#j-submit")
        jid = page.wait("document.getElementById('j-status').dataset.job", 30)
        if not jid:
            return f"no job submitted; banner: {page.js('document.getElementById(`banner`).textContent')}"
        sweep["job"] = jid
        end = time.monotonic() + 60
        while True:
            st3, j = http("GET", f"{base}/v1/jobs/{jid}")
            if j["state"] not in ("queued", "running") or time.monotonic() > end:
                break
            time.sleep(0.2)
        if j["state"] != "succeeded":
            return f"the job ended {j['state']}: {j.get('error')}"
        st3, res = http("GET", f"{base}/v1/jobs/{jid}/results")
        got = sorted((r["coords"]["sza"], round(r["coords"]["rho_0"], 9)) for r in res["results"])
        want = sorted((z, round(r, 9)) for z in (0, 30, 60) for r in (0.1, 0.2, 0.3))
        if got != want:
            return f"the job's contexts have coords {got}, want the grid {want}"
        if sorted(res["results"][0]["channels"]) != ["Y", "brf.Y", "radiance_stderr.Y"]:
            return f"the films' channels are {res['results'][0]['channels']}, want Y, brf.Y, radiance_stderr.Y"
        sweep["results"] = res["results"]
    check("submits a job from the form (a grid of a template's coordinate and a parameter key)", job_form)

    # 9. The sweep view: BRF against sza, one line per rho_0, with error bars.
    def sweep_view():
        if "results" not in sweep:
            return "no job to plot"
        jid = sweep["job"]
        if not page.wait(f"document.getElementById('sweep').dataset.job === '{jid}' && "
                         "document.getElementById('sweep').dataset.points === '9'", 20):
            return (f"no sweep plot of 9 points; banner: {page.js('document.getElementById(`banner`).textContent')}; "
                    f"{page.js('Object.assign({}, document.getElementById(`sweep`).dataset)')}")
        ctl = page.js("['sw-quantity', 'sw-x', 'sw-series'].map(i => document.getElementById(i).value)")
        if ctl != ["brf", "sza", "rho_0"]:
            return f"the sweep's quantity, x and lines are {ctl}, want brf against sza, one line per rho_0"
        pts = page.js("[...document.querySelectorAll('#sweep circle')].map(c => ({ctx: c.dataset.context, x: +c.dataset.x,"
                      " y: +c.dataset.y, err: +c.dataset.err, s: c.dataset.series}))")
        lines = page.js("document.querySelectorAll('#sweep path.series').length")
        bars = page.js("document.querySelectorAll('#sweep line.err').length")
        if len(pts) != 9 or lines != 3 or bars != 27:
            return f"{len(pts)} points, {lines} lines, {bars} error-bar strokes; want 9, 3, 27"
        by = {r["context"]: r for r in sweep["results"]}
        for p in pts:
            r = by[p["ctx"]]
            st3, film = http("GET", f"{base}{r['href']}")
            d, n = film["data"], film["width"] * film["height"]
            brf = [d[3 * k + 1] for k in range(n)]
            err = math.sqrt(sum((d[3 * k + 2] * d[3 * k + 1] / d[3 * k]) ** 2 for k in range(n))) / n
            if abs(p["x"] - r["coords"]["sza"]) > 1e-9 or abs(float(p["s"]) - r["coords"]["rho_0"]) > 1e-9:
                return f"point {p} is not at its context's coords {r['coords']}"
            if abs(p["y"] - sum(brf) / n) > 1e-6 * abs(p["y"]) or not (err > 0 and abs(p["err"] - err) <= 1e-6 * err):
                return f"point {p}: want BRF {sum(brf) / n} ± {err} (the film's mean and its standard error)"
        png = page.screenshot(page.rect("#sweep"))
        open(art("sweep.png"), "wb").write(png)
        # The whole page, one film of the job shown as BRF (docs/viewer.png).
        page.js("document.getElementById('film').dataset.ready = ''")
        page.click("#results a")
        page.wait("document.getElementById('film').dataset.ready === '1'", 30)
        page.js("(() => { const e = document.getElementById('plane'); e.value = 'brf'; e.dispatchEvent(new Event('change')); })()")
        page.click("#exposure-auto")
        page.type_into("#param-search", "plate bsdf")
        time.sleep(0.3)
        open(art("viewer-sweep.png"), "wb").write(page.screenshot())
        page.type_into("#param-search", "")
        if a.docs_png:
            shutil.copyfile(art("viewer-sweep.png"), a.docs_png)
        # Against rho_0 instead: sza is then held at one value (3 points).
        page.js("(() => { const e = document.getElementById('sw-x'); e.value = 'rho_0'; e.dispatchEvent(new Event('change')); })()")
        if not page.wait("document.getElementById('sweep').dataset.ready === '1' && document.getElementById('sweep').dataset.points === '3'", 30):
            return f"against rho_0 with sza held: {page.js('Object.assign({}, document.getElementById(`sweep`).dataset)')}"
        held = page.js("[...document.querySelectorAll('#sw-fixed select')].map(e => e.dataset.coord + '=' + e.value)")
        if held != ["sza=0"]:
            return f"the coordinates held are {held}, want sza=0"
    check("plots the job's BRF against a coordinate, a line per value of another, with error bars", sweep_view)

    # 10. Planes of a mono film, and no channel choice carried over.
    def planes():
        if "job" not in sweep:
            return "no sweep job"
        rgb_job = page.js('document.querySelector(\'#jobs li[data-state="succeeded"]:not([data-job="%s"])\').dataset.job' % sweep["job"])
        if not page.select_job(rgb_job):
            return "the rgb job's results are not listed"
        page.click("#results a")
        if not page.wait("document.getElementById('film').dataset.mode === 'rgb'", 30):
            return "the rgb job's film is not shown as RGB"
        page.js("(() => { const e = document.getElementById('channel'); e.value = '2'; e.dispatchEvent(new Event('change')); })()")
        if not page.select_job(sweep["job"]):
            return "the sweep job's results are not listed"
        page.js("document.getElementById('film').dataset.ready = ''")
        page.click("#results a")
        if not page.wait(f"document.getElementById('film-title').dataset.job === '{sweep['job']}' && "
                         "document.getElementById('film').dataset.ready === '1'", 10):
            return "the mono film is not shown"
        opts = page.js("[...document.getElementById('plane').options].map(o => o.value)")
        if opts != ["radiance", "brf", "radiance_stderr"]:
            return f"the quantities offered are {opts}, want radiance, brf, radiance_stderr"
        f = page.js("Object.assign({}, document.getElementById('film').dataset)")
        if f["mode"] != "false-colour" or f["plane"] != "radiance" or not page.js("document.getElementById('channel-label').hidden"):
            return f"a mono film shows as {f} (want radiance in false colour, no channel choice)"
        png = page.screenshot(page.rect("#film"))
        open(art("mono-film.png"), "wb").write(png)
        w, h, rows = png_decode(png)
        ramp = [viridis(i / 255) for i in range(256)]
        off = [p for p in {p for row in rows[2:-2] for p in row[2:-2]}
               if min(max(abs(a - b) for a, b in zip(p, q)) for q in ramp) > 6]
        if off:
            return f"{len(off)} pixels of the mono film are not viridis colours (painted as RGB?): {off[:3]}"
        page.js("(() => { const e = document.getElementById('plane'); e.value = 'brf'; e.dispatchEvent(new Event('change')); })()")
        if page.js("document.getElementById('film').dataset.plane") != "brf":
            return "choosing BRF does not show the brf plane"
        # Back to an rgb film: its own default (RGB), not the B chosen before.
        if not page.select_job(rgb_job):
            return "the rgb job's results are not listed again"
        page.click("#results a")
        if not page.wait("document.getElementById('film').dataset.mode === 'rgb' && document.getElementById('channel').value === 'rgb'", 30):
            return f"the next rgb film shows channel {page.js('document.getElementById(`channel`).value')}, want RGB"
    check("offers a mono film's planes (radiance, BRF, stderr) in false colour, no channel carried over", planes)

    # 11. Tone mapping: 0 EV is linear and clamped (a radiance of 1 at full
    # scale), auto puts the 99.5th percentile there.
    def tone():
        if "job" not in sweep:
            return "no sweep job"
        if not page.select_job(sweep["job"]):
            return "the sweep job's results are not listed"
        page.js("document.getElementById('film').dataset.ready = ''")
        page.click("#results a")
        if not page.wait("document.getElementById('film').dataset.ready === '1' && document.getElementById('film').dataset.plane === 'radiance'", 30):
            return "the film is not shown"
        ctx = page.js("document.getElementById('film-title').textContent").split(" · ")[1]
        r = next(r for r in sweep["results"] if r["context"] == ctx)
        st3, film = http("GET", f"{base}{r['href']}")
        L = film["data"][0::3]
        if float(page.js("document.getElementById('film').dataset.white")) != 1.0:
            return "at 0 EV full scale is not 1"
        rr = page.rect("#film")
        w, h, rows = png_decode(page.screenshot(rr))
        for k in (0, 5, 10, 15):
            px = rows[int((k // 4 + 0.5) * h / 4)][int((k % 4 + 0.5) * w / 4)]
            want = viridis(min(1.0, L[k]))
            if max(abs(a - b) for a, b in zip(px, want)) > 3:
                return f"pixel {k} (radiance {L[k]:.4f}) shows {px}, want viridis({L[k]:.4f}) = {want} (0 EV: linear, 1 at full scale)"
        page.click("#exposure-auto")
        ev = float(page.js("document.getElementById('exposure').value"))
        want = -math.log2(p995(L))
        if abs(ev - want) > 0.01:
            return f"auto exposure is {ev} EV, want {want:.3f} (the 99.5th percentile at full scale)"
    check("tone-maps as Mitsuba (0 EV: linear, clamped) with auto at the 99.5th percentile", tone)

    # 12. The BRF toggle of a hemispherical film without a brf plane.
    def brf_toggle():
        page.type_into("#r-spp", "16")
        page.type_into("#r-seed", "1")
        page.js("document.getElementById('film').dataset.ready = ''")
        page.click("#render")
        if not page.wait("document.getElementById('film').dataset.ready === '1' && !document.getElementById('film-title').dataset.job", 30):
            return "no render shown"
        opts = page.js("[...document.getElementById('plane').options].map(o => o.value)")
        if opts != ["radiance", "brf*"]:
            return f"the quantities offered for an hdistant film are {opts}, want radiance and the computed BRF"
        page.js("(() => { const e = document.getElementById('plane'); e.value = 'brf*'; e.dispatchEvent(new Event('change')); })()")
        if page.js("document.getElementById('plot').dataset.kind") != "polar" or page.js("document.getElementById('film').dataset.plane") != "brf*":
            return "the polar plot of the BRF is not drawn"
        st3, film = http("POST", f"{base}/v1/scenes/{sw['id']}:render", {"spp": 16, "seed": 1, "quantities": ["brf"]})
        rr = page.rect("#film")
        page.hover(rr["x"] + rr["w"] * 0.6, rr["y"] + rr["h"] * 0.35)  # pixel (2, 1)
        text = page.wait("(() => { const t = document.getElementById('hover').textContent; return t.includes('BRF') && t; })()", 30)
        if not text:
            return "hovering the film shows no BRF"
        shown = float(text.rsplit(":", 1)[1])
        k = 1 * 4 + 2
        want = film["data"][2 * k + 1]
        if abs(shown - want) > 1e-4 * want:
            return f"the BRF shown at pixel (2, 1) is {shown}, the render's brf plane says {want}: {text}"
    check("toggles an hdistant film to BRF = pi L / E_h (the render's brf plane agrees)", brf_toggle)

    # 13. Jobs: their distinguishing number, readable durations, progress
    # within a long render.
    def labels():
        got = page.js("[...document.querySelectorAll('#jobs li[data-job]')].map(e => [e.dataset.job, "
                      "e.querySelector('.label').textContent, e.querySelector('.meta').textContent])")
        if len(got) < 3:
            return f"{len(got)} jobs listed"
        for jid, label, meta in got:
            if label != "#%d" % int(jid.rsplit("-", 1)[1]):
                return f"job {jid} is labelled {label!r}"
            if "e-" in meta or not re.search(r"\d (µs|ms|s|min)\b", meta):
                return f"job {jid}'s duration reads {meta!r}"
        row = page.js(f"document.querySelector('#jobs li[data-job=\"{sweep['job']}\"] .id').textContent")
        if not row.endswith(" · sweep-plate.json"):
            return f"the sweep job's line names its scene as {row!r}, want sweep-plate.json"
        st3, job = http("POST", f"{base}/v1/scenes/{scene}/jobs", {"defaults": {"spp": 200000}, "contexts": [{"id": "long"}]})
        jid = job["id"]
        page.click("#jobs-refresh")
        sel = f'#jobs li[data-job="{jid}"]'
        moved = page.wait(f"(() => {{ const e = document.querySelector('{sel}'); return e && e.dataset.done === '0' && +e.dataset.progress > 0"
                          f" && e.querySelector('.meta').textContent; }})()", 15)
        st3, j = http("GET", f"{base}/v1/jobs/{jid}")
        http("POST", f"{base}/v1/jobs/{jid}:cancel")
        if not moved:
            return f"the job's bar did not move during its first render: {page.js(f'Object.assign({{}}, document.querySelector(`{sel}`).dataset)')}"
        if "samples" not in moved:
            return f"the job's line does not say how far the render is: {moved!r}"
        r = j.get("render") or {}
        if j["state"] == "running" and not (0 < r.get("samples_done", 0) <= r.get("samples_total", 0) == 32 * 32 * 200000):
            return f"GET job says render {r}, want samples_done > 0 of 32*32*200000"
    check("labels jobs by number, reads durations, shows progress within a render", labels)

    # 14. A Stokes film: S0..S3, DoLP (grey, 0..1) and AoLP (cyclic hue) views.
    def stokes():
        st2, sc = http("POST", f"{base}/v1/scenes", STOKES_SCENE)
        if st2 not in (200, 201):
            return f"posting the Stokes scene: {st2} {sc}"
        # The page opens its first scene by itself. A click on another scene
        # while that first scene is still loading must win: hold the first
        # scene's answers back 1.5 s, so they arrive after the click's.
        st2, listing = http("GET", f"{base}/v1/scenes")
        first = listing["scenes"][0]["id"]
        hold = page.call("Page.addScriptToEvaluateOnNewDocument", {"source": (
            "(() => { const f = window.fetch; window.fetch = async (u, o) => { const r = await f(u, o);"
            f" if (String(u).startsWith('/v1/scenes/{first}')) await new Promise((k) => setTimeout(k, 1500));"
            " return r; }; })();")})
        page.goto(f"{base}/ui/")
        page.call("Page.removeScriptToEvaluateOnNewDocument", {"identifier": hold["identifier"]})
        li = f'#scenes li[data-scene="{sc["id"]}"]'
        if not page.wait(f"document.querySelector('{li}')", 30):
            return "the Stokes scene is not listed"
        page.click(li)
        chosen = (f"(document.querySelector('#scenes li.selected') || {{dataset: {{}}}}).dataset.scene === '{sc['id']}'"
                  " && document.getElementById('r-sensor').value === 'cam'")
        if not page.wait(chosen, 30):
            return "the Stokes scene was not selected"
        time.sleep(3.5)  # both held answers (the scene, its parameters) have arrived
        if not page.js(chosen):
            return (f"the Stokes scene was clicked, but the page then opened "
                    f"{page.js('(document.querySelector(`#scenes li.selected`) || {dataset: {}}).dataset.scene')}, "
                    f"the scene it opens by itself")
        page.type_into("#r-spp", "4")
        page.js("document.getElementById('film').dataset.ready = ''")
        page.click("#render")
        if not page.wait("document.getElementById('film').dataset.ready === '1'", 30):
            return f"no Stokes film shown; banner: {page.js('document.getElementById(`banner`).textContent')}"
        opts = page.js("[...document.getElementById('channel').options].map(o => o.textContent)")
        if opts != ["S0", "S1", "S2", "S3", "DoLP", "AoLP"]:
            return f"the views offered are {opts}, want S0, S1, S2, S3, DoLP, AoLP"
        # DoLP 0.6: linear grey 153; AoLP 30°: hue (30 + 90) / 180 of the circle, blue.
        for view, want in (("dolp", (153, 153, 153)), ("aolp", (0, 0, 255))):
            page.js(f"(() => {{ const e = document.getElementById('channel'); e.value = '{view}'; e.dispatchEvent(new Event('change')); }})()")
            if not page.wait(f"document.getElementById('film').dataset.mode === '{view}'", 30):
                return f"choosing {view} does not show it: {page.js('Object.assign({}, document.getElementById(`film`).dataset)')}"
            rr = page.rect("#film")
            png = page.screenshot(rr)
            open(art(f"stokes-{view}.png"), "wb").write(png)
            w, h, rows = png_decode(png)
            px = {rows[int((j + 0.5) * h / 4)][int((i + 0.5) * w / 4)] for j in range(4) for i in range(4)}
            off = [p for p in px if max(abs(a - b) for a, b in zip(p, want)) > 3]
            if off:
                return f"the {view} view shows {sorted(px)}, want {want} everywhere"
            page.hover(rr["x"] + rr["w"] * 0.4, rr["y"] + rr["h"] * 0.4)
            label = "DoLP" if view == "dolp" else "AoLP (°)"
            text = page.wait(f"(() => {{ const t = document.getElementById('hover').textContent; return t.includes('{label}:') && t; }})()", 30)
            if not text:
                return f"hovering the {view} view does not show it"
            v = float(text.rsplit(":", 1)[1])
            if abs(v - (0.6 if view == "dolp" else 30.0)) > 1e-3:
                return f"the hover says {text!r}"
    check("shows a Stokes film's S0..S3, DoLP (grey) and AoLP (cyclic hue)", stokes)
    print(f"# browser part: {time.monotonic() - t0:.1f} s", flush=True)


if __name__ == "__main__":
    main()
