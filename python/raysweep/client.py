"""The connection to a daemon, and loading scenes into it (``connect``, ``load_file``, ``load_dict``).

A loaded scene must not depend on the client's disk: every file it references
(a mesh, a volume, a bitmap: any ``filename`` string of a JSON scene, or
``<string name="filename" value="..."/>`` of a Mitsuba XML scene) is hashed
(SHA-256), the daemon is asked which digests it lacks (``POST /v1/blobs:missing``),
only those are uploaded (``PUT /v1/blobs/{hex}``), and the references are
rewritten to ``sha256:<hex>`` before ``POST /v1/scenes``: what libraysweep and
``raysweep scene push`` do (docs/daemon.md, "Files"). An XML scene is sent byte
for byte except for those attribute values, so the daemon's ``file:line`` errors
still match the user's file.
"""

import copy
import hashlib
import json
import os
import urllib.parse
import xml.parsers.expat

from ._http import DEFAULT_URL, Transport
from .errors import RaysweepError, did_you_mean
from .scene import Scene

__all__ = ["Client", "connect"]

_SHA = "sha256:"


def connect(url=None, token=None, timeout=60.0, route=None):
    """Connect to a daemon; returns a :class:`Client`.

    ``url`` defaults to ``$RAYSWEEP_URL``, else ``http://127.0.0.1:8350``;
    ``token`` to ``$RAYSWEEP_TOKEN`` (a daemon started with ``--token-file``
    wants it). ``timeout``: seconds to wait for an answer to an ordinary
    request (renders and jobs take their own). ``route`` (default
    ``$RAYSWEEP_ROUTE``): behind a load balancer, the key every request
    carries (``X-Raysweep-Shard``), so that all of them reach the replica it
    hashes to; clients with different keys spread work over the replicas
    (docs/cluster.md). Asks ``GET /v1`` once, so a wrong address fails here
    (:class:`~raysweep.ConnectionFailed`), and a wrong token too
    (:class:`~raysweep.RaysweepError`, status 401).
    """
    url = url or os.environ.get("RAYSWEEP_URL") or DEFAULT_URL
    if token is None:
        token = os.environ.get("RAYSWEEP_TOKEN") or None
    if route is None:
        route = os.environ.get("RAYSWEEP_ROUTE") or None
    client = Client(Transport(url, token, timeout=timeout, route=route))
    client.info = client._http.json("GET", "/v1")
    # /v1 needs no token on some daemons; /v1/scenes always does when one is set.
    client._http.json("GET", "/v1/scenes")
    return client


class Client:
    """A daemon (made by :func:`connect`): loads scenes and lists what it holds.

    ``info`` is the daemon's ``GET /v1`` answer (version, variants, plugins, limits).
    """

    def __init__(self, transport):
        self._http = transport
        self.info = {}

    @property
    def url(self):
        """The daemon's base URL."""
        return self._http.url

    def __repr__(self):
        return f"<raysweep.Client {self.url} (raysweepd {self.info.get('version', '?')})>"

    # ---- scenes ---------------------------------------------------------------------------

    def load_file(self, path, variant=None, **params):
        """Load a scene file (JSON scene dictionary or Mitsuba XML) into the daemon; returns a :class:`Scene`.

        Relative ``filename`` references resolve against the file's directory;
        the files are uploaded when the daemon lacks them. ``variant``
        (``"mono"``, ``"rgb"``, ``"mono_polarized"`` or ``"rgb_polarized"``)
        overrides the scene's. Keyword arguments set
        an XML scene's parameters, as Mitsuba's ``load_file(path, rho=0.3)``:
        each replaces the value of its ``<default name=... value=...>``, or is
        declared after ``<scene>`` when the file has no default for it (on the
        same line, so the daemon's line numbers still match the file).
        Values are numbers, booleans, strings or sequences of numbers
        (written ``"1, 2, 3"``). One that the file neither declares nor uses
        (``$name``) is a ``TypeError`` naming it, as is any for a JSON scene.
        """
        path = os.fspath(path)
        try:
            with open(path, "rb") as f:
                text = f.read()
        except OSError as e:
            raise RaysweepError(f"{path}: cannot read the scene file: {e.strerror}", pointer=path) from None
        base = os.path.dirname(os.path.abspath(path))
        lower = path.lower()
        is_xml = lower.endswith(".xml") or (not lower.endswith(".json") and _looks_xml(text))
        label = os.path.basename(path)
        if is_xml:
            refs = {}

            def upload(found):  # (kept for a spread sweep's replicas)
                refs.update(found)
                self._upload_missing(found)
            doc = _xml_rewrite(text, base, upload, params)
            return self._push(doc, "application/xml", variant, label, refs)
        if params:
            raise TypeError(f"{label} is a JSON scene: it takes no parameters ({', '.join(sorted(params))}); "
                            "set them with scene.traverse() after loading")
        return self._push_json_text(text, base, variant, label)

    def load_dict(self, d, variant=None, base_dir=None):
        """Load a scene given as a Python dict (Mitsuba's scene-dictionary grammar, docs/scenes.md).

        Numpy arrays and scalars in ``d`` are sent as JSON lists and numbers.
        Relative ``filename`` references resolve against ``base_dir`` (default
        the current directory), and the files are uploaded when the daemon
        lacks them. ``d`` itself is not modified. Returns a :class:`Scene`.
        """
        if not isinstance(d, dict):
            raise TypeError(f"load_dict() wants a dict, not {type(d).__name__}")
        doc = copy.deepcopy(d)
        refs = {}
        _json_refs(doc, base_dir or os.getcwd(), refs)
        self._upload_missing(refs)
        from ._http import dumps
        return self._push(dumps(doc), "application/json", variant, None, refs)

    def scene(self, scene_id):
        """The resident scene ``scene_id`` (as ``load_*`` returned, or listed by :meth:`scenes`)."""
        info = self._http.json("GET", f"/v1/scenes/{_q(scene_id)}")
        return Scene(self, info)

    def scenes(self):
        """Every resident scene, as :class:`Scene` objects."""
        return [Scene(self, s) for s in self._http.json("GET", "/v1/scenes")["scenes"]]

    def jobs(self):
        """Every job the daemon still knows, as :class:`~raysweep.Job` objects."""
        from .jobs import Job
        return [Job(self, j) for j in self._http.json("GET", "/v1/jobs")["jobs"]]

    def job(self, job_id):
        """The job ``job_id`` as a :class:`~raysweep.Job`."""
        from .jobs import Job
        return Job(self, self._http.json("GET", f"/v1/jobs/{_q(job_id)}"))

    # ---- internals ------------------------------------------------------------------------

    def _push_json_text(self, text, base, variant, label):
        try:
            doc = json.loads(text)
        except ValueError:
            doc = None  # the daemon's answer says where it is wrong
        refs = {}
        if isinstance(doc, dict):
            _json_refs(doc, base, refs)
            if refs:
                self._upload_missing(refs)
                from ._http import dumps
                text = dumps(doc)
        return self._push(text, "application/json", variant, label, refs)

    def _push(self, body, content_type, variant, label, refs=None):
        """Push a scene document (its files, refs, already uploaded); the Scene keeps what it
        needs to push the same document to other replicas (``sweep(spread=K)``)."""
        path = "/v1/scenes"
        if variant:
            path += "?variant=" + _q(variant)
        info = self._http.json("POST", path, bytes(body), content_type=content_type, timeout=None)
        scene = Scene(self, info, label=label)
        scene._doc = (bytes(body), content_type, variant, dict(refs or {}))
        return scene

    def _upload_missing(self, refs):
        """Upload the files of ``refs`` (hex digest -> local path) that the daemon lacks."""
        if not refs:
            return
        missing = self._http.json("POST", "/v1/blobs:missing", {"digests": sorted(refs)})["missing"]
        for hexd in missing:
            path = refs.get(hexd)
            if path is None:
                continue  # not one we asked about
            with open(path, "rb") as f:
                data = f.read()
            self._http.request("PUT", f"/v1/blobs/{hexd}", data, content_type="application/octet-stream",
                               timeout=None)


def _q(s):
    return urllib.parse.quote(str(s), safe="")


def _hash_ref(name, base, refs):
    """Resolve ``name`` against ``base``, hash the file, record it in ``refs``; the ``sha256:`` reference."""
    if not name:
        raise RaysweepError("a scene references an empty file name")
    path = name if os.path.isabs(name) else os.path.join(base, name)
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    except OSError as e:
        raise RaysweepError(f"{name}: cannot read the referenced file {path}: {e.strerror}", pointer=name) from None
    hexd = h.hexdigest()
    refs[hexd] = path
    return _SHA + hexd


def _json_refs(node, base, refs):
    """Rewrite every ``"filename": "<path>"`` member under ``node`` to its ``sha256:`` reference, in place."""
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "filename" and isinstance(v, str) and not v.startswith(_SHA):
                node[k] = _hash_ref(v, base, refs)
            elif isinstance(v, (dict, list)):
                _json_refs(v, base, refs)
    elif isinstance(node, list):
        for v in node:
            _json_refs(v, base, refs)


def _looks_xml(text):
    return text.lstrip(b"\xef\xbb\xbf \t\r\n").startswith(b"<")


def _xml_value(v):
    """A Python value as the text of an XML attribute (escaped)."""
    if isinstance(v, bool):
        v = "true" if v else "false"
    elif isinstance(v, (list, tuple)) or hasattr(v, "tolist"):
        v = v.tolist() if hasattr(v, "tolist") else list(v)
        v = ", ".join(repr(float(x)) for x in (v if isinstance(v, list) else [v]))
    elif isinstance(v, float):
        v = repr(v)
    v = str(v)
    return v.replace("&", "&amp;").replace("<", "&lt;").replace('"', "&quot;").replace("'", "&apos;")


def _xml_rewrite(text, base, upload, params=None):
    """The XML document with its file references and parameters rewritten.

    Every ``<string name="filename" value="P"/>`` value becomes ``P``'s
    ``sha256:`` reference (the files are handed to ``upload``), every
    ``<default name="K" value=...>`` with K in ``params`` takes that value,
    and the other ``params`` are declared right after the ``<scene>`` start
    tag. Only those bytes change (found with expat's byte offsets), so line
    numbers do not move. A document expat cannot parse goes unchanged: the
    daemon's answer names the line.
    """
    params = dict(params or {})
    edits, refs, pending = [], {}, dict(params)
    parser = xml.parsers.expat.ParserCreate()
    depth = [0]
    scene_end = []
    declared, dollars = [], []  # the <default> names; the attribute values holding a '$'

    def start(name, attrs):
        depth[0] += 1
        at = parser.CurrentByteIndex
        dollars.extend(v for v in attrs.values() if "$" in v)
        if name == "default" and depth[0] == 2 and "name" in attrs:
            declared.append(attrs["name"])
        if name == "scene" and depth[0] == 1:
            end = _tag_end(text, at)
            if end is not None:
                scene_end.append(end)
            return
        if name == "default" and depth[0] == 2 and attrs.get("name") in params:
            span = _attr_span(text[at:], b"value")
            if span is not None:
                key = attrs["name"]
                edits.append((at + span[0], at + span[1], _xml_value(params[key])))
                pending.pop(key, None)
            return
        if name != "string" or attrs.get("name") != "filename":
            return
        value = attrs.get("value")
        if value is None or value.startswith(_SHA):
            return
        span = _attr_span(text[at:], b"value")  # scans to the tag's end, quotes respected
        if span is None:
            raise RaysweepError(f"line {parser.CurrentLineNumber}: cannot locate the value of "
                                '<string name="filename">')
        edits.append((at + span[0], at + span[1], _hash_ref(value, base, refs)))

    def end(name):
        depth[0] -= 1

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(text, True)
    except xml.parsers.expat.ExpatError:
        if params:
            raise RaysweepError("the XML scene does not parse, so its parameters cannot be set: "
                                + ", ".join(sorted(params))) from None
        return text
    if pending:
        _check_params_used(pending, declared, dollars)
        if not scene_end:
            raise RaysweepError("the XML document has no <scene> element to declare parameters in")
        decl = "".join(f'<default name="{_xml_value(k)}" value="{_xml_value(v)}"/>' for k, v in pending.items())
        edits.append((scene_end[0], scene_end[0], decl))
    upload(refs)
    out, r = [], 0
    for a, b, ref in sorted(edits, key=lambda e: e[0]):
        out += [text[r:a], ref.encode()]
        r = b
    out.append(text[r:])
    return b"".join(out)


def _check_params_used(pending, declared, dollars):
    """A parameter the document neither declares (``<default>``) nor uses (``$name``) is a
    ``TypeError`` naming it: a misspelt ``rh0=0.3`` would leave ``$rho`` at its default without a
    word (the daemon refuses such a ``-D`` alike). At each ``$`` the longest name that follows is
    the one used, as the daemon substitutes."""
    names = set(declared) | set(pending)
    used = set()
    for v in dollars:
        i = v.find("$")
        while i >= 0:
            hit = max((n for n in names if v.startswith(n, i + 1)), key=len, default=None)
            if hit is not None:
                used.add(hit)
            i = v.find("$", i + 1)
    for key in pending:
        if key not in used:
            cands = did_you_mean(key, declared)
            hint = f"; did you mean {cands[0]!r}?" if cands else ""
            have = ", ".join(declared) if declared else "none"
            raise TypeError(f"parameter {key!r}: the XML document neither declares it (<default>) nor uses it "
                            f"(${key}){hint} (it declares: {have})")


def _tag_end(text, at):
    """The offset just past the ``>`` that ends the start tag at ``at`` (quotes respected), or ``None``."""
    quote = None
    for i in range(at, len(text)):
        c = text[i:i + 1]
        if quote:
            if c == quote:
                quote = None
        elif c in (b'"', b"'"):
            quote = c
        elif c == b">":
            return i + 1
    return None


def _attr_span(tag, name):
    """[from, to) of attribute ``name``'s raw value between its quotes in the start tag that ``tag`` begins with."""
    i, n = 1, len(tag)
    while i < n and tag[i:i + 1] not in b" \t\r\n/>":
        i += 1
    while i < n:
        while i < n and tag[i:i + 1] in b" \t\r\n":
            i += 1
        if i >= n or tag[i:i + 1] in b"/>":
            return None
        a = i
        while i < n and tag[i:i + 1] not in b" \t\r\n=":
            i += 1
        attr = tag[a:i]
        while i < n and tag[i:i + 1] in b" \t\r\n":
            i += 1
        if tag[i:i + 1] != b"=":
            return None
        i += 1
        while i < n and tag[i:i + 1] in b" \t\r\n":
            i += 1
        q = tag[i:i + 1]
        if q not in (b'"', b"'"):
            return None
        i += 1
        v = i
        while i < n and tag[i:i + 1] != q:
            i += 1
        if attr == name:
            return v, i
        i += 1
    return None
