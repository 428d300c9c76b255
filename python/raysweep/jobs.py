"""Jobs of kernel contexts as futures: submit, follow, cancel, fetch (``Job``, ``as_completed``).

A job is followed through its server-sent events (``GET /v1/jobs/{id}/events``,
one ``context`` event per finished render and a final ``end``), resumed with
``Last-Event-ID`` after a dropped connection, and through ``GET /v1/jobs/{id}``
polling when the event stream cannot be had.
"""

import itertools
import numbers
import queue
import re
import threading
import time
import warnings

from . import _data, _progress
from .errors import ConnectionFailed, JobFailed, RaysweepError, SweepWarning

__all__ = ["Job", "as_completed", "grid_contexts"]

_END_STATES = ("succeeded", "failed", "cancelled")
_COORD = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,63}$")


def _axis_coord(name):
    """The coord a grid axis fills, as ``raysweep sweep --grid`` names it (docs/client.md):
    ``wavelength``, a parameter key's last name before ``.value``, or the name itself."""
    base = name[:-6] if name.endswith(".value") else name
    last = re.split(r"[.:]", base)[-1]
    return last


def _sanitize(c):
    c = re.sub(r"[^A-Za-z0-9_]", "_", c)
    return c if c[:1].isalpha() else "p" + c


def grid_contexts(grid, param_keys=None):
    """The contexts of a grid: a dict NAME -> values, their product with the first axis slowest.

    NAME ``wavelength`` sets each context's wavelength; a parameter key (it
    holds a ``.`` or ``:``) sets that parameter; any other NAME is a coordinate
    only (for templates). Every axis is also a coord of the contexts (the
    key's last name before ``.value``, or its whole key when two axes would
    share one), so the job's dataset has one dimension per axis. Context ids
    are ``c00000``, ``c00001``, ... as ``raysweep sweep`` numbers them.
    ``param_keys`` (optional): the scene's keys, to refuse an unknown key with
    the closest ones before anything is sent.
    """
    if not isinstance(grid, dict) or not grid:
        raise TypeError("grid must be a non-empty dict NAME -> values")
    names = list(grid)
    axes = []
    for name in names:
        values = grid[name]
        if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
            raise TypeError(f"grid[{name!r}] must be a list of values, not {type(values).__name__}")
        # (numpy scalars as Python numbers; an array of several stays one,
        # and is refused below)
        vals = [v.item() if getattr(v, "ndim", None) == 0 else v for v in values]
        if not vals:
            raise ValueError(f"grid[{name!r}] is empty")
        for v in vals:
            if isinstance(v, bool) or not isinstance(v, (numbers.Real, str)):
                shown = v.tolist() if hasattr(v, "tolist") else v
                raise TypeError(f"grid[{name!r}]: {shown!r} is neither a number nor a string: a grid axis "
                                "takes one number a context (for vectors and transforms give each context "
                                "its value through contexts=[...]; for sun and view angles, templates)")
        is_key = "." in name or ":" in name
        # An Eradiate search (TYPE:ID:PATH) is resolved by the daemon alone.
        if is_key and ":" not in name and param_keys is not None and name not in param_keys:
            from .errors import UnknownKeyError, did_you_mean
            cands = did_you_mean(name, param_keys)
            hint = "; did you mean " + ", ".join(repr(c) for c in cands) + "?" if cands else ""
            raise UnknownKeyError(f"grid: unknown parameter {name!r}{hint}", key=name, candidates=cands,
                                  code="RSW_ERR_UNKNOWN_NAME")
        if not is_key and name != "wavelength" and not _COORD.match(name):
            raise ValueError(f"grid: {name!r} is neither wavelength, a parameter key, nor a coordinate name "
                             "([A-Za-z][A-Za-z0-9_]*)")
        axes.append((name, vals, is_key))
    coords = [_axis_coord(n) if k else n for n, _, k in axes]
    for i, (name, _, is_key) in enumerate(axes):
        if is_key and coords.count(coords[i]) > 1:
            coords[i] = name
    coords = [_sanitize(c) for c in coords]
    total = 1
    for _, vals, _ in axes:
        total *= len(vals)
    width = max(5, len(str(total - 1)))
    contexts = []
    for i, combo in enumerate(itertools.product(*(vals for _, vals, _ in axes))):
        ctx = {"id": f"c{i:0{width}d}", "coords": {}}
        for (name, _, is_key), coord, v in zip(axes, coords, combo):
            ctx["coords"][coord] = v
            if name == "wavelength":
                ctx["wavelength"] = v
            elif is_key:
                ctx.setdefault("params", {})[name] = v
        contexts.append(ctx)
    return contexts


def job_contexts(scene, grid=None, contexts=None, params=None, wavelength=None):
    """The contexts a job on ``scene`` renders, from ``grid`` or ``contexts`` (ids given to those without)."""
    from .scene import _encode_values
    if (grid is None) == (contexts is None):
        raise TypeError("give either grid={NAME: values} or contexts=[{...}, ...]")
    if grid is not None:
        # What every context of a grid sets, a job-level value would not change.
        both = [n for n in grid if params and n in params]
        if both:
            raise TypeError(f"params[{both[0]!r}]: also a grid axis, whose values every context sets; "
                            "give one of the two")
        if wavelength is not None and isinstance(grid, dict) and "wavelength" in grid:
            raise TypeError("wavelength=: the grid's wavelength axis gives every context its own; "
                            "give one of the two")
        keys = None
        if any("." in n and ":" not in n for n in grid):
            keys = set(scene._keys())
        return grid_contexts(grid, keys)
    contexts = [dict(c) for c in contexts]
    width = max(5, len(str(len(contexts) - 1)))
    for i, c in enumerate(contexts):
        c.setdefault("id", f"c{i:0{width}d}")
        if "params" in c:
            c["params"] = _encode_values(c["params"])
    return contexts


def submit(scene, grid=None, contexts=None, spp=None, seed=None, sensors=None, wavelength=None, params=None,
           quantities=None, variance=False, bands=None, templates=None, idempotency_key=None, bundle=None,
           _stacklevel=3, _warn=True, _dry_run=False):
    """Submit a job on ``scene`` (see :meth:`raysweep.Scene.sweep` for the arguments); a :class:`Job`.

    The job's warnings are raised as :class:`~raysweep.SweepWarning` (``_stacklevel``: the
    frame they name, the caller of ``Scene.submit`` or ``Scene.sweep``; none with ``_warn``
    false). ``_dry_run``: check the job (``?dry_run=1``), raise its warnings, queue nothing
    and return the daemon's JobDryRun dict."""
    from .scene import _encode_values
    contexts = job_contexts(scene, grid, contexts, params, wavelength)
    body = {"contexts": contexts}
    defaults = {}
    if spp is not None:
        defaults["spp"] = int(spp)
    if sensors is not None:
        defaults["sensors"] = [sensors] if isinstance(sensors, str) else list(sensors)
    if wavelength is not None:
        defaults["wavelength"] = float(wavelength)
    if defaults:
        body["defaults"] = defaults
    if seed is not None:
        body["seed"] = int(seed)
    if params:
        body["params"] = _encode_values(params)
    if quantities:
        body["quantities"] = [quantities] if isinstance(quantities, str) else list(quantities)
    if variance:
        body["variance"] = True
    if bands:
        body["bands"] = list(bands)
    if templates:
        body["templates"] = dict(templates)
    if bundle is not None:
        body["bundle"] = "auto" if bundle == "auto" else int(bundle)
    headers = {"Idempotency-Key": idempotency_key} if idempotency_key and not _dry_run else None
    try:
        status = scene._http.json("POST", f"{scene._path}/jobs" + ("?dry_run=1" if _dry_run else ""), body,
                                  headers=headers, timeout=None)
    except RaysweepError as e:
        raise scene._suggest(e) from None
    if _dry_run and not status.get("dry_run"):
        # A daemon from before ?dry_run queued the job: take it back.
        Job(scene.client, status, scene=scene).delete()
        return {"dry_run": False}
    # A sweep that changes nothing along an axis is said at once, not left in the
    # dataset's attributes: the job's warnings as Python warnings (stacklevel: the
    # caller of sweep() or submit()).
    who = f"job {status.get('id')}" if status.get("id") else "the sweep"
    for w in (status.get("warnings") or []) if _warn else []:
        if isinstance(w, dict):
            warnings.warn(SweepWarning(f"{who}: {w.get('code')} ({w.get('coordinate')}): "
                                       f"{w.get('detail')}", code=w.get("code"), coordinate=w.get("coordinate"),
                                       job=status.get("id")), stacklevel=_stacklevel)
    return status if _dry_run else Job(scene.client, status, scene=scene)


class Job:
    """A job on the daemon, used like a ``concurrent.futures.Future``.

    ``result()`` waits and returns the dataset; ``done()``, ``running()``,
    ``cancelled()``, ``cancel()``, ``exception()``; :func:`as_completed`
    yields jobs as they end. ``status`` is the last Job resource seen
    (``state``, ``renders_done``, ``renders_total``, ``seconds``, ``warnings``...).
    """

    def __init__(self, client, status, scene=None):
        self.client = client
        self.id = status["id"]
        self.status = status
        self.scene = scene
        self._dataset = None

    def __repr__(self):
        s = self.status
        return (f"<raysweep.Job {self.id} {s.get('state')} {s.get('renders_done', 0)}/"
                f"{s.get('renders_total', '?')} renders>")

    @property
    def _http(self):
        return self.client._http

    @property
    def _path(self):
        return f"/v1/jobs/{self.id}"

    @property
    def state(self):
        """The state last seen: queued, running, succeeded, failed or cancelled."""
        return self.status.get("state")

    @property
    def warnings(self):
        """The daemon's warnings about the sweep (a coordinate or the wavelength changes nothing), a list."""
        return list(self.status.get("warnings") or [])

    def refresh(self):
        """Ask the daemon for the job's state (``GET /v1/jobs/{id}``); returns the status dict."""
        self.status = self._http.json("GET", self._path)
        return self.status

    def done(self):
        """Whether the job has ended (succeeded, failed or cancelled)."""
        if self.state not in _END_STATES:
            self.refresh()
        return self.state in _END_STATES

    def running(self):
        """Whether the job is running now."""
        return self.refresh().get("state") == "running"

    def cancelled(self):
        """Whether the job ended cancelled."""
        return self.done() and self.state == "cancelled"

    def cancel(self):
        """Ask the daemon to cancel the job (its render stops within 16 bounces); ``False`` if it had ended.

        A cancelled job keeps the films it finished.
        """
        if self.state in _END_STATES:
            return False
        self.status = self._http.json("POST", self._path + ":cancel")
        return self.state != "succeeded" and self.state != "failed"

    def delete(self):
        """Delete the job and its results on the daemon (cancelling it if it runs)."""
        self._http.request("DELETE", self._path)

    # ---- waiting ------------------------------------------------------------------------

    def wait(self, timeout=None, progress=False):
        """Wait until the job ends; returns its final status dict.

        ``timeout``: seconds (``TimeoutError`` after; the job keeps running).
        ``progress``: as for :meth:`raysweep.Scene.sweep` (default none here).
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        bar = None
        if self.state not in _END_STATES:
            bar = _progress.make_bar(progress, self.status.get("renders_total", 0), self.id)
        try:
            self._follow(deadline, bar)
        finally:
            if bar is not None:
                bar.close(self.state if self.state in _END_STATES else None)
        return self.status

    def _follow(self, deadline, bar):
        last_id, failures = None, 0
        while self.state not in _END_STATES:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                raise TimeoutError(f"job {self.id} still {self.state} after the timeout (it keeps running)")
            try:
                for event, eid, data in self._http.events(self.status.get("href_events", self._path + "/events"),
                                                          last_id, timeout=_read_timeout(left)):
                    failures = 0
                    last_id = eid or last_id
                    if isinstance(data, dict) and bar is not None and "done" in data:
                        bar.update(data["done"], data.get("total"))
                    if event == "end":
                        break
                    if deadline is not None and time.monotonic() > deadline:
                        raise TimeoutError(f"job {self.id} still running after the timeout (it keeps running)")
                self.refresh()
            except ConnectionFailed:
                failures += 1
                if deadline is not None and time.monotonic() >= deadline:
                    continue  # the loop's check raises TimeoutError
                if failures > 3:
                    self._poll(deadline, bar)
                    return
                self.refresh()
        if bar is not None:
            bar.update(self.status.get("renders_done", 0), self.status.get("renders_total"))

    def _poll(self, deadline, bar, interval=0.5):
        """Fallback when the event stream cannot be had: ask for the status every ``interval`` seconds."""
        while self.refresh().get("state") not in _END_STATES:
            if bar is not None:
                bar.update(self.status.get("renders_done", 0), self.status.get("renders_total"))
            if deadline is not None and time.monotonic() >= deadline:
                raise TimeoutError(f"job {self.id} still {self.state} after the timeout (it keeps running)")
            time.sleep(interval)

    def exception(self, timeout=None):
        """Wait for the job; the :class:`~raysweep.JobFailed` it ended with, or ``None`` if it succeeded."""
        self.wait(timeout)
        return self._failure()

    def _failure(self):
        s = self.status
        if s.get("state") == "succeeded" and not s.get("renders_failed"):
            return None
        why = s.get("error") or (f"{s.get('renders_failed')} of {s.get('renders_total')} renders failed"
                                 if s.get("renders_failed") else "")
        failures = self._render_failures() if s.get("renders_failed") else []
        if failures:  # what went wrong, not only how often (the daemon says it per render)
            c, se, e = failures[0]
            why += f"; {c}/{se}: {e}" + (f" ({len(failures) - 1} more in .failures)" if len(failures) > 1 else "")
        err = JobFailed(f"job {self.id} {s.get('state')}" + (f": {why}" if why else ""), job=self,
                        state=s.get("state"), code="RSW_ERR_CANCELLED" if s.get("state") == "cancelled" else None)
        err.failures = failures
        return err

    def _render_failures(self):
        """[(context, sensor, error)] of the job's failed renders, in the job's order ([] when the
        results cannot be read)."""
        try:
            res = self.results().get("results") or []
        except (RaysweepError, OSError):
            return []
        return [(r.get("context"), r.get("sensor"), r.get("error") or "no reason given")
                for r in res if isinstance(r, dict) and r.get("state") == "failed"]

    def result(self, timeout=None, progress=False):
        """Wait for the job and return its dataset (:meth:`dataset`), or its films without xarray.

        Raises :class:`~raysweep.JobFailed` when the job failed, was
        cancelled, or some of its renders failed (the films it has stay
        available through :meth:`dataset` with ``partial=True`` and :meth:`films`).
        """
        self.wait(timeout, progress=progress)
        err = self._failure()
        if err is not None:
            raise err
        if _data.have_xarray():
            return self.dataset()
        return self.films()

    # ---- results ------------------------------------------------------------------------

    def results(self):
        """The index of the job's films (``GET /v1/jobs/{id}/results``): a dict with ``results`` (and ``bands``)."""
        return self._http.json("GET", self._path + "/results")

    def films(self, xarray=False):
        """Every film of the job: a dict ``{(context, sensor): array}`` (float32, (y, x, channel)).

        Jobs with bands add ``(context, sensor, band)`` entries for the band
        films, and their node films are keyed ``(context, sensor, node)``.
        ``xarray=True`` gives ``xarray.DataArray`` films as ``render`` does.
        """
        index = self.results()
        out = {}
        convert = _data.film_dataarray if xarray else _data.film_array
        for r in index.get("results", []):
            if r.get("state") != "succeeded":
                continue
            key = (r["context"], r["sensor"]) + ((r["node"],) if "node" in r else ())
            out[key] = convert(self._http.json("GET", r["href"]))
        for r in index.get("band_results", []) or []:
            out[(r["context"], r["sensor"], r["band"])] = convert(self._http.json("GET", r["href"]))
        return out

    def dataset_bytes(self, partial=False):
        """The job's NetCDF-4 dataset as bytes (``GET /v1/jobs/{id}/dataset``; 409 while running unless ``partial``)."""
        path = self._path + "/dataset" + ("?partial=1" if partial else "")
        return self._http.request("GET", path, accept="application/x-netcdf", timeout=None)[2]

    def save_dataset(self, path, partial=False):
        """Write the job's NetCDF-4 dataset to ``path`` (opens with ``xarray.open_dataset(path)``).

        The answer is streamed to a file beside ``path`` in 1 MiB pieces, then
        renamed over it once whole: memory stays small however large the
        dataset, and ``path`` is never left holding part of one.
        """
        query = "?partial=1" if partial else ""
        return _data.stream_to_file(self._http, self._path + "/dataset" + query, path)

    def dataset(self, partial=False):
        """The job's films as one ``xarray.Dataset`` (docs/client.md, "Sweep datasets"), loaded in memory.

        The NetCDF file goes through a temporary file (``$TMPDIR``), so the
        dataset's values are held once, not beside a copy of the file.
        """
        if self._dataset is not None and not partial:
            return self._dataset
        if not _data.have_xarray():
            _data.open_netcdf_bytes(b"")  # raises the ImportError that says what to install
        ds = _data.fetch_netcdf(self._http, self._path + "/dataset" + ("?partial=1" if partial else ""))
        if not partial and self.state in _END_STATES:
            self._dataset = ds
        return ds


def _read_timeout(left):
    # A keep-alive comes every 15 s: 40 s of silence means the stream is dead.
    return 40.0 if left is None else max(0.05, min(left, 40.0))


def as_completed(jobs, timeout=None):
    """Yield the ``jobs`` as they end (any end state), like ``concurrent.futures.as_completed``.

    Each job is followed by a thread of its own (its event stream); jobs
    that have already ended come first. ``timeout``: seconds for all of
    them, then ``TimeoutError``.
    """
    jobs = list(dict.fromkeys(jobs))
    deadline = None if timeout is None else time.monotonic() + timeout
    finished = queue.Queue()

    def follow(job):
        try:
            job.wait()
        except BaseException as e:  # noqa: BLE001 - handed to the consumer
            finished.put((job, e))
        else:
            finished.put((job, None))

    pending = 0
    for job in jobs:
        if job.state in _END_STATES:
            yield job
            continue
        threading.Thread(target=follow, args=(job,), daemon=True, name=f"raysweep-{job.id}").start()
        pending += 1
    while pending:
        left = None if deadline is None else deadline - time.monotonic()
        if left is not None and left <= 0:
            raise TimeoutError(f"{pending} of {len(jobs)} jobs still running after the timeout")
        try:
            job, err = finished.get(timeout=left)
        except queue.Empty:
            raise TimeoutError(f"{pending} of {len(jobs)} jobs still running after the timeout") from None
        pending -= 1
        if err is not None:
            raise err
        yield job
