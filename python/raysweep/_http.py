"""The HTTP transport: JSON requests, problem+json errors, retries, server-sent events.

Standard library only (urllib). One :class:`Transport` may be used from several
threads at once: every request opens its own connection.
"""

import json
import re
import socket
import time
import urllib.error
import urllib.parse
import urllib.request

from .errors import ConnectionFailed, RaysweepError

try:
    import numpy as _np
except ImportError:  # pragma: no cover - numpy is a dependency
    _np = None

DEFAULT_URL = "http://127.0.0.1:8350"


def _json_default(o):
    """Encode numpy arrays and scalars (and anything with ``tolist``) as JSON lists and numbers."""
    if _np is not None and isinstance(o, (_np.ndarray, _np.generic)):
        return o.tolist()
    if hasattr(o, "tolist"):
        return o.tolist()
    raise TypeError(f"cannot send a {type(o).__name__} as JSON")


def dumps(obj):
    """``obj`` as compact JSON bytes; NaN and infinities are refused (ValueError), as the daemon would."""
    try:
        return json.dumps(obj, default=_json_default, allow_nan=False, separators=(",", ":")).encode()
    except ValueError as e:
        raise ValueError(f"cannot send a non-finite number (NaN or infinity) to the daemon: {e}") from None


class Transport:
    """Requests to one daemon.

    ``url``: the daemon's base URL; ``token``: the bearer token or ``None``;
    ``timeout``: seconds to wait for an answer (``None``: forever);
    ``max_retries`` and ``retry_backoff``: a refused connection, 429 and 503
    are retried that many times, waiting ``retry_backoff`` seconds and doubling
    (a ``Retry-After`` from the daemon wins), as libraysweep does (docs/client.md).
    ``route``: the routing key sent as ``X-Raysweep-Shard`` on every request
    (a load balancer sends all of them to the replica it hashes to;
    docs/cluster.md), or ``None``.
    """

    def __init__(self, url=DEFAULT_URL, token=None, timeout=60.0, max_retries=3, retry_backoff=0.2, route=None):
        parts = urllib.parse.urlsplit(url)
        if parts.scheme not in ("http", "https") or not parts.netloc:
            raise ValueError(f"url must be http://HOST:PORT or https://..., not {url!r}")
        if route is not None and not re.fullmatch(r"[A-Za-z0-9._-]{1,64}", str(route)):
            raise ValueError(f"route must be 1 to 64 of A-Z a-z 0-9 . _ -, not {route!r}")
        self.route = route
        self.url = url.rstrip("/")
        self.token = token
        self.timeout = timeout
        self.max_retries = max_retries
        self.retry_backoff = retry_backoff

    def open(self, method, path, body=None, content_type=None, accept=None, headers=None, timeout=-1):
        """Send one request; the open response (a file-like ``http.client.HTTPResponse``).

        ``body`` is bytes, or any JSON value (sent as JSON). An answer of 400 or
        more raises :class:`RaysweepError` built from its problem+json; an
        unreachable daemon raises :class:`ConnectionFailed`. The caller closes
        the response (``with``).
        """
        if body is not None and not isinstance(body, (bytes, bytearray)):
            body = dumps(body)
            content_type = content_type or "application/json"
        hdrs = {"User-Agent": "raysweep-python"}
        if content_type:
            hdrs["Content-Type"] = content_type
        if accept:
            hdrs["Accept"] = accept
        if self.token:
            hdrs["Authorization"] = f"Bearer {self.token}"
        if self.route:
            hdrs["X-Raysweep-Shard"] = self.route
        hdrs.update(headers or {})
        timeout = self.timeout if timeout == -1 else timeout
        wait = self.retry_backoff
        for attempt in range(self.max_retries + 1):
            req = urllib.request.Request(self.url + path, data=body, headers=hdrs, method=method)
            try:
                return urllib.request.urlopen(req, timeout=timeout)
            except urllib.error.HTTPError as e:
                retry_after = e.headers.get("Retry-After") if e.headers else None
                if e.code in (429, 503) and attempt < self.max_retries:
                    e.close()
                    time.sleep(_retry_delay(retry_after, wait))
                    wait *= 2
                    continue
                raise _problem(e, method, path) from None
            except urllib.error.URLError as e:
                refused = isinstance(e.reason, ConnectionRefusedError)
                if refused and attempt < self.max_retries:
                    time.sleep(wait)
                    wait *= 2
                    continue
                err = ConnectionFailed(f"cannot reach the daemon at {self.url}: {e.reason}", method=method, path=path)
                err.refused = refused  # (nothing listens at the address: no other routing key reaches anything)
                raise err from None
            except (socket.timeout, TimeoutError):
                raise ConnectionFailed(f"{method} {path}: no answer from {self.url} within {timeout} s",
                                       method=method, path=path) from None
            except ConnectionError as e:
                raise ConnectionFailed(f"{method} {path}: the connection to {self.url} failed: {e}",
                                       method=method, path=path) from None
        raise AssertionError("unreachable")  # pragma: no cover

    def request(self, method, path, body=None, **kw):
        """Send one request; ``(status, headers, body bytes)``. Errors as for :meth:`open`."""
        with self.open(method, path, body, **kw) as r:
            try:
                data = r.read()
            except (socket.timeout, TimeoutError):
                raise ConnectionFailed(f"{method} {path}: the answer from {self.url} stopped coming",
                                       method=method, path=path) from None
            return r.status, r.headers, data

    def json(self, method, path, body=None, **kw):
        """Send one request and decode its JSON answer (``None`` for an empty body)."""
        _, _, data = self.request(method, path, body, **kw)
        if not data:
            return None
        try:
            return json.loads(data)
        except ValueError:
            raise RaysweepError(f"{method} {path}: the answer is not JSON: {data[:200]!r}",
                                method=method, path=path) from None

    def events(self, path, last_event_id=None, timeout=75.0):
        """Server-sent events of ``path``: yields ``(event, id, data)`` with ``data`` decoded JSON.

        Comment lines (the daemon's keep-alives) are skipped. Ends when the
        server closes the stream; raises :class:`ConnectionFailed` when nothing
        (not even a keep-alive) arrives within ``timeout`` seconds.
        """
        headers = {"Last-Event-ID": str(last_event_id)} if last_event_id is not None else None
        with self.open("GET", path, accept="text/event-stream", headers=headers, timeout=timeout) as r:
            event, eid, data = None, None, []
            while True:
                try:
                    raw = r.readline()
                except (socket.timeout, TimeoutError, ConnectionError, OSError) as e:
                    raise ConnectionFailed(f"GET {path}: the event stream stopped: {e}", path=path) from None
                if not raw:
                    return
                line = raw.decode("utf-8", "replace").rstrip("\r\n")
                if not line:
                    if data:
                        text = "\n".join(data)
                        try:
                            value = json.loads(text)
                        except ValueError:
                            value = text
                        yield event or "message", eid, value
                    event, data = None, []
                elif line.startswith(":"):
                    continue
                else:
                    name, _, value = line.partition(":")
                    value = value[1:] if value.startswith(" ") else value
                    if name == "event":
                        event = value
                    elif name == "id":
                        eid = value
                    elif name == "data":
                        data.append(value)


def _retry_delay(retry_after, default):
    try:
        return max(0.0, min(float(retry_after), 30.0))
    except (TypeError, ValueError):
        return default


def _problem(e, method, path):
    """The :class:`RaysweepError` of an HTTP error answer (problem+json, or any text)."""
    try:
        data = e.read()
    except Exception:  # noqa: BLE001 - a broken error body still gives an error
        data = b""
    finally:
        e.close()
    try:
        problem = json.loads(data) if data else {}
    except ValueError:
        problem = {}
    if not isinstance(problem, dict) or not problem:
        text = data.decode("utf-8", "replace").strip()[:300] or e.reason
        problem = {"status": e.code, "title": str(e.reason), "detail": f"{method} {path}: {text}"}
    return RaysweepError.from_problem(problem, e.code, method, path)
