#!/usr/bin/env python3
"""Replays the malformed-request corpus (tests/corpus/http) against a
running raysweepd and checks every answer.

  replay.py --port P [--token T] [--var NAME=VALUE]... [--only NAME] [--show]

Each case is one raw request, cases/NAME.http, sent byte for byte on its
own connection after placeholders are filled in: {AUTH} (the
Authorization header line, or nothing without --token), {CL} (the length
of the body after substitution) and {NAME} for every --var (SCENE, JOB,
BLOB, ...). expect.tsv gives, per case, tab-separated:

  NAME  STATUS  CHECKS  [NOTE]

STATUS is a code (400), a class (4xx) or alternatives (404|405). CHECKS is
"-" or ';'-separated strings the body must contain ("!text": must not
contain; {VAR} placeholders are filled in), and two flags for what
libmicrohttpd answers itself before raysweepd sees the request (documented
in docs/daemon.md): "mhd-html" (an HTML body instead of a problem) and
"close-ok" (the connection closed without an answer, within the timeout);
and "closes": after its answer the server must close the connection and
send nothing more (a framing error: what follows cannot be trusted to be
a request, RFC 9112 section 5.1). Every 4xx/5xx answer must be
application/problem+json, valid UTF-8, a JSON object whose "status" is the
HTTP status; a HEAD answer has no body. An answer must come within 5 s.
Prints a line per failure and "http corpus: N passed, N failed"; exit 1 if
any failed."""
import argparse
import json
import os
import re
import socket
import sys
import time

here = os.path.dirname(os.path.abspath(__file__))


def fill(data, vars_):
    for k, v in vars_.items():
        data = data.replace(("{%s}" % k).encode(), v.encode())
    return data


def build_request(raw, vars_):
    data = fill(raw, vars_)
    # The body is what follows the first blank line; {CL} is its length.
    if b"{CL}" in data:
        head, sep, body = data.partition(b"\r\n\r\n")
        data = head.replace(b"{CL}", str(len(body)).encode()) + sep + body
    return data


def read_answer(sock, deadline, head_request):
    buf = b""
    while b"\r\n\r\n" not in buf:
        sock.settimeout(max(0.01, deadline - time.time()))
        chunk = sock.recv(65536)
        if not chunk:
            if not buf:
                raise EOFError("connection closed without an answer")
            raise EOFError("connection closed inside the headers: %r" % buf[:200])
        buf += chunk
    head, _, rest = buf.partition(b"\r\n\r\n")
    lines = head.split(b"\r\n")
    m = re.match(rb"HTTP/1\.[01] (\d{3})", lines[0])
    if not m:
        raise ValueError("not a status line: %r" % lines[0][:200])
    status = int(m.group(1))
    hdrs = {}
    for ln in lines[1:]:
        k, _, v = ln.partition(b":")
        hdrs[k.strip().lower().decode("latin-1")] = v.strip().decode("latin-1")
    body = rest
    if head_request or status in (204, 304) or 100 <= status < 200:
        return status, hdrs, body
    if "content-length" in hdrs:
        n = int(hdrs["content-length"])
        while len(body) < n:
            sock.settimeout(max(0.01, deadline - time.time()))
            chunk = sock.recv(65536)
            if not chunk:
                break
            body += chunk
        sock.extra = body[n:]
        return status, hdrs, body[:n]
    if "chunked" in hdrs.get("transfer-encoding", "").lower():
        out = b""
        while True:
            while b"\r\n" not in body:
                sock.settimeout(max(0.01, deadline - time.time()))
                chunk = sock.recv(65536)
                if not chunk:
                    return status, hdrs, out
                body += chunk
            size_line, _, body = body.partition(b"\r\n")
            size = int(size_line.split(b";")[0], 16)
            while len(body) < size + 2:
                sock.settimeout(max(0.01, deadline - time.time()))
                chunk = sock.recv(65536)
                if not chunk:
                    break
                body += chunk
            if size == 0:
                return status, hdrs, out
            out += body[:size]
            body = body[size + 2:]
    while True:  # until close
        sock.settimeout(max(0.01, deadline - time.time()))
        chunk = sock.recv(65536)
        if not chunk:
            return status, hdrs, body
        body += chunk


def status_ok(want, got):
    for alt in want.split("|"):
        if alt.endswith("xx") and str(got)[0] == alt[0]:
            return True
        if alt == str(got):
            return True
    return False


class Sock(socket.socket):
    extra = b""  # bytes read past the answer (its Content-Length)


def closed_after(sock, deadline):
    """None when the server closed the connection with nothing after the
    answer; else what went wrong."""
    more = sock.extra
    try:
        while True:
            sock.settimeout(max(0.01, deadline - time.time()))
            chunk = sock.recv(65536)
            if not chunk:
                break
            more += chunk
    except (socket.timeout, TimeoutError):
        return "the connection stayed open after the answer"
    except OSError:
        pass  # a reset is a close too
    if more:
        return "more bytes after the answer (a second answer?): %r" % more[:120]
    return None


def check_case(name, raw, want, checks, vars_, port, timeout, show):
    req = build_request(raw, vars_)
    head_request = req.startswith(b"HEAD ")
    t0 = time.time()
    s = Sock(socket.AF_INET, socket.SOCK_STREAM)
    closes = "closes" in checks.split(";")
    close_err = None
    try:
        s.settimeout(timeout)
        s.connect(("127.0.0.1", port))
        try:
            s.sendall(req)
        except OSError:
            pass  # the server may answer and close before reading it all
        status, hdrs, body = read_answer(s, t0 + timeout, head_request)
        if closes:
            close_err = closed_after(s, t0 + timeout)
    finally:
        s.close()
    dt = time.time() - t0
    if show:
        print("%s -> %d %s (%.3f s) %s" % (name, status, hdrs.get("content-type", ""), dt, body[:300]))
    errs = []
    flags = set(c for c in checks.split(";") if c in ("mhd-html", "close-ok", "closes"))
    if flags:
        checks = ";".join(c for c in checks.split(";") if c not in flags) or "-"
    mhd_html = "mhd-html" in flags and hdrs.get("content-type", "text/html").startswith("text/html")
    if not status_ok(want, status):
        errs.append("status %d, wanted %s" % (status, want))
    if close_err:
        errs.append(close_err)
    if head_request and body:
        errs.append("a HEAD answer with a body")
    if status >= 400 and not head_request and not mhd_html:
        ct = hdrs.get("content-type", "")
        if not ct.startswith("application/problem+json"):
            errs.append("content type %r, not application/problem+json" % ct)
        try:
            text = body.decode("utf-8")
            doc = json.loads(text)
            if not isinstance(doc, dict):
                errs.append("problem body is not an object")
            elif doc.get("status") != status:
                errs.append("problem status %r != %d" % (doc.get("status"), status))
        except (UnicodeDecodeError, ValueError) as e:
            errs.append("problem body is not valid UTF-8 JSON (%s)" % e)
    text = body.decode("utf-8", "replace")
    if checks != "-":
        for c in checks.split(";"):
            c = fill(c.encode(), vars_).decode()
            if c.startswith("!"):
                if c[1:] in text:
                    errs.append("body names %r" % c[1:])
            elif c not in text:
                errs.append("body does not name %r" % c)
    if errs:
        return "%s: %s; body: %s" % (name, ", ".join(errs), text[:300].replace("\n", " "))
    return None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--token")
    ap.add_argument("--var", action="append", default=[])
    ap.add_argument("--only")
    ap.add_argument("--show", action="store_true")
    ap.add_argument("--timeout", type=float, default=5.0)
    a = ap.parse_args()
    vars_ = dict(v.split("=", 1) for v in a.var)
    vars_["AUTH"] = "Authorization: Bearer %s\r\n" % a.token if a.token else ""
    npass = nfail = 0
    seen = set()
    with open(os.path.join(here, "expect.tsv"), encoding="utf-8") as f:
        rows = [ln.rstrip("\n").split("\t") for ln in f if ln.strip() and not ln.startswith("#")]
    for row in rows:
        name, want, checks = row[0], row[1], row[2]
        seen.add(name)
        if a.only and not re.search(a.only, name):
            continue
        raw = open(os.path.join(here, "cases", name + ".http"), "rb").read()
        try:
            err = check_case(name, raw, want, checks, vars_, a.port, a.timeout, a.show)
        except EOFError as e:
            err = None if "close-ok" in checks.split(";") and "without an answer" in str(e) else \
                "%s: %s: %s" % (name, type(e).__name__, e)
        except (OSError, ValueError) as e:
            err = "%s: %s: %s" % (name, type(e).__name__, e)
        if err:
            nfail += 1
            print("FAIL " + err)
        else:
            npass += 1
    for fn in sorted(os.listdir(os.path.join(here, "cases"))):
        if fn.endswith(".http") and fn[:-5] not in seen:
            nfail += 1
            print("FAIL %s: no line in expect.tsv" % fn)
    print("http corpus: %d passed, %d failed" % (npass, nfail))
    return 1 if nfail else 0


if __name__ == "__main__":
    sys.exit(main())
