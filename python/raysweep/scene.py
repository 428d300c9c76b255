"""A resident scene and its parameter table (Mitsuba's ``traverse`` / ``SceneParameters``)."""

import urllib.parse

import numpy as np

from . import _data
from .errors import RaysweepError, UnknownKeyError, did_you_mean

__all__ = ["Scene", "SceneParameters"]


def _q(s):
    return urllib.parse.quote(str(s), safe="")


class Scene:
    """A scene resident in the daemon (made by ``client.load_file`` / ``load_dict``).

    Attributes: ``id`` (the SHA-256 of the document, its variant and its
    files), ``variant`` (``mono``, ``rgb``, ``mono_polarized`` or
    ``rgb_polarized``), ``sensors`` (sensor ids in scene order), ``revision`` (the base revision when last seen), ``label`` (the
    file's name for ``load_file``).
    """

    def __init__(self, client, info, label=None):
        self._doc = None  # (body, content type, variant, files) as pushed by this client: spread=
        self.client = client
        self.id = info["id"]
        self.variant = info.get("variant")
        self.sensors = list(info.get("sensors") or [])
        self.revision = info.get("revision", 0)
        self.label = label

    def __repr__(self):
        name = f" {self.label}" if self.label else ""
        return f"<raysweep.Scene {self.id[:12]}{name} {self.variant} sensors={self.sensors} rev={self.revision}>"

    @property
    def _http(self):
        return self.client._http

    @property
    def _path(self):
        return f"/v1/scenes/{self.id}"

    def info(self):
        """The daemon's description of the scene (``GET /v1/scenes/{id}``: shapes, params, bytes, jobs_active ...)."""
        info = self._http.json("GET", self._path)
        self.revision = info.get("revision", self.revision)
        return info

    def delete(self, force=False):
        """Unload the scene; ``force=True`` cancels its running jobs first (else 409 while jobs run)."""
        self._http.request("DELETE", self._path + ("?force=true" if force else ""))

    # ---- parameters -----------------------------------------------------------------------

    def traverse(self, match=None):
        """The parameter table as a :class:`SceneParameters` (Mitsuba's ``mi.traverse(scene)``).

        ``match``: a glob (``'*.reflectance.value'``; ``*`` also matches dots)
        to fetch only some keys.
        """
        path = self._path + "/params" + ("?match=" + _q(match) if match else "")
        table = self._http.json("GET", path)
        self.revision = table["revision"]
        return SceneParameters(self, table)

    def _keys(self):
        """Every key and alias of the scene (for "did you mean")."""
        try:
            table = self._http.json("GET", self._path + "/params")
        except RaysweepError:
            return []
        keys = []
        for e in table["params"]:
            keys.append(e["key"])
            keys.extend(e.get("aliases") or [])
        return keys

    def _suggest(self, err):
        """Add local "did you mean" candidates to an unknown-key error that came without any."""
        if isinstance(err, UnknownKeyError) and err.key and not err.candidates:
            err.with_candidates(did_you_mean(err.key, self._keys()))
        return err

    def update(self, values, if_match=None):
        """Apply a parameter map atomically (``PATCH /v1/scenes/{id}/params``); returns the daemon's answer.

        ``values``: key -> value (numbers, arrays, ``{"wavelengths": [...],
        "values": [...]}`` spectra). ``if_match``: a revision; the update is
        refused (412) if the scene has moved on. The answer has ``revision``,
        ``changed`` (entries whose value changed), ``classes`` and ``seconds``.
        """
        headers = {"If-Match": f'"{int(if_match)}"'} if if_match is not None else None
        try:
            ans = self._http.json("PATCH", self._path + "/params", _encode_values(values), headers=headers,
                                  timeout=None)
        except RaysweepError as e:
            raise self._suggest(e) from None
        self.revision = ans["revision"]
        return ans

    # ---- renders and jobs -----------------------------------------------------------------

    def render(self, spp=None, seed=0, wavelength=None, sensor=None, quantities=None, variance=False,
               params=None, timeout=None, xarray=None, coords=None, templates=None):
        """Render one film synchronously (Mitsuba's ``mi.render(scene, spp=, seed=, sensor=)``).

        ``spp``: samples per pixel (default the sensor's sampler's);
        ``seed``; ``wavelength``: nm (mono; default 550); ``sensor``: id or
        index (default the first); ``quantities``: planes beyond radiance
        (``["brf"]``, ``["brdf", "brf"]``); ``variance``: add
        ``radiance_stderr``; ``params``: overrides for this render only;
        ``timeout``: seconds, after which the daemon stops the render (504);
        ``coords``: the render's coordinates (``{"sza": 30}``), from which the
        scene's templates and ``templates`` (this render's, ``{key: template}``)
        render its overrides, as for a sweep's context (docs/experiments.md).

        Returns an ``xarray.DataArray`` over (y, x, channel) with the viewing
        angles as coordinates when xarray is installed (``xarray=False``: never),
        else a float32 numpy array of shape (height, width, channels). Ctrl-C
        drops the request, and the daemon stops the render.
        """
        body = {"seed": int(seed)}
        if spp is not None:
            body["spp"] = int(spp)
        if wavelength is not None:
            body["wavelength"] = float(wavelength)
        if sensor is not None:
            body["sensor"] = str(sensor)
        if quantities:
            body["quantities"] = [quantities] if isinstance(quantities, str) else list(quantities)
        if variance:
            body["variance"] = True
        if params:
            body["params"] = _encode_values(params)
        if timeout is not None:
            body["timeout_s"] = float(timeout)
        if coords:
            body["coords"] = {str(k): _number(v, f"coords[{k!r}]") for k, v in dict(coords).items()}
        if templates:
            body["templates"] = dict(templates)
        try:
            film = self._http.json("POST", self._path + ":render", body, timeout=None)
        except RaysweepError as e:
            raise self._suggest(e) from None
        use_xr = _data.have_xarray() if xarray is None else xarray
        return _data.film_dataarray(film) if use_xr else _data.film_array(film)

    def submit(self, grid=None, contexts=None, **options):
        """Submit a job of kernel contexts and return at once with a :class:`~raysweep.Job` (a future).

        Takes the arguments of :meth:`sweep` but ``progress``, ``timeout`` and ``spread``.
        """
        if "spread" in options:
            raise TypeError("submit() runs one job on one daemon; spread= is sweep()'s (it runs the shards' "
                            "jobs and joins their datasets)")
        from .jobs import submit
        return submit(self, grid=grid, contexts=contexts, **options)

    def sweep(self, grid=None, contexts=None, progress=None, timeout=None, spread=None, journal=None, **options):
        """Run a job of kernel contexts and return its dataset (an ``xarray.Dataset``).

        Give either ``grid`` or ``contexts``:

        - ``grid``: a dict NAME -> values (a list, a numpy array, a range);
          the contexts are their product, first axis slowest, as
          ``raysweep sweep --grid``. NAME is ``wavelength`` (each context's
          wavelength, nm), a parameter key (each context sets it; its coord
          is the key's last name before ``.value``:
          ``surface.bsdf.reflectance.value`` gives ``reflectance``), or a
          plain coordinate name that the scene's or the job's ``templates``
          read (``sza``). Every NAME is a dimension of the dataset.
        - ``contexts``: a list of Context dicts (``id``, ``wavelength``,
          ``params``, ``sensors``, ``spp``, ``seed``, ``coords``; docs/daemon.md).

        Options: ``spp``, ``seed`` (the job seed), ``sensors`` (ids to
        render; default all), ``wavelength`` (for contexts that give none),
        ``params`` (job-level overrides; a tabulated spectrum is evaluated at
        each context's wavelength), ``quantities`` (``["brf"]``...),
        ``variance``, ``bands`` (spectral response functions), ``templates``
        (docs/experiments.md), ``bundle`` (wavelengths carried per path,
        1 to 16, or ``"auto"``, the most the scene allows; ``None``, the
        default, leaves it to the daemon, which takes ``"auto"``; 1 renders
        one wavelength per path, as before bundles:
        docs/experiments.md#spectral-bundles).

        ``progress``: ``None`` shows a bar in a notebook (tqdm when
        installed) or on a terminal, ``True`` always, ``False`` never.
        ``timeout``: seconds to wait (``TimeoutError``; the job keeps
        running). Ctrl-C (or interrupting the kernel) cancels the job and
        raises ``KeyboardInterrupt``. A job that fails raises
        :class:`~raysweep.JobFailed`. Without xarray the result is a dict
        ``{(context, sensor): numpy array}``.

        ``spread``: a number of shards K, for a client connected to a load
        balancer in front of several daemons (docs/cluster.md): the sweep is
        cut into K shards as ``raysweep sweep --spread K`` cuts it (whole
        bundle groups), each shard runs on a replica of its own (its
        routing key is chosen so), a shard whose replica is lost runs again
        elsewhere, and the result is the dataset of the unsharded sweep,
        film for film (its ``job`` attribute lists the shards' jobs). The
        scene must be one this client loaded (its document is pushed to
        every replica) and unchanged since (revision 0).

        ``journal``: with ``spread``, a file that records the shards' routing
        keys and jobs while the sweep runs. The same sweep run again with
        the same ``journal`` (after a Ctrl-C, which then leaves the jobs
        running, a timeout, a lost balancer, or a restarted kernel) follows
        the jobs that the replicas kept, and submits again only the shards
        whose jobs are gone. A journal of another sweep is refused
        (``ValueError``). The file is removed when the sweep completes.
        """
        if journal is not None and spread is None:
            raise TypeError("journal= records the shards of a spread sweep: give spread=K too (spread=1 "
                            "runs the sweep as one shard)")
        if spread is not None:
            from . import _spread
            from .jobs import job_contexts
            ctxs = job_contexts(self, grid, contexts, options.get("params"), options.get("wavelength"))
            return _spread.run(self, ctxs, spread, options, progress=progress, timeout=timeout, journal=journal)
        # A Ctrl-C while the job is being submitted waits for the daemon's
        # answer, so that the job it may have accepted is known and cancelled.
        # One that comes as the block ends is raised by the handler it puts
        # back (CPython runs the handler in place when it checks, not the one
        # in place when the signal came), so the block is inside the try too.
        job = None
        try:
            with _deferred_interrupt() as interrupted:
                job = self.submit(grid=grid, contexts=contexts, _stacklevel=4, **options)
            if interrupted:
                raise KeyboardInterrupt
            return job.result(timeout=timeout, progress=progress)
        except KeyboardInterrupt:
            if job is not None:
                job.cancel()
                import sys
                print(f"raysweep: interrupted: cancelled job {job.id}", file=sys.stderr)
            raise


class _deferred_interrupt:
    """Holds back SIGINT inside a ``with`` block (main thread only); the value is truthy if one came."""

    def __init__(self):
        self._hits = []
        self._old = None

    def __bool__(self):
        return bool(self._hits)

    def __enter__(self):
        import signal
        import threading
        if threading.current_thread() is threading.main_thread():
            try:
                self._old = signal.signal(signal.SIGINT, lambda *_: self._hits.append(1))
            except ValueError:  # not the main interpreter
                self._old = None
        return self

    def __exit__(self, *exc):
        import signal
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
        return False


def _encode_values(values):
    """A parameter map as JSON-ready values (numpy arrays as lists, spectra dicts as they are)."""
    if not isinstance(values, dict):
        raise TypeError(f"parameter values must be a dict of key -> value, not {type(values).__name__}")
    return {str(k): _encode_value(v) for k, v in values.items()}


def _encode_value(v):
    if isinstance(v, dict):
        return {k: _encode_value(x) for k, x in v.items()}
    if isinstance(v, (np.ndarray, np.generic)):
        return v.tolist()
    if isinstance(v, (list, tuple)):
        return [_encode_value(x) for x in v]
    return v


def _decode_value(entry):
    """A table entry's value as Python: numpy arrays for vectors, transforms, buffers and lists."""
    v = entry.get("value")
    if isinstance(v, dict):
        if set(v) == {"length"}:
            return _Unfetched(v["length"])
        return {k: (np.asarray(x, dtype=np.float64) if isinstance(x, list) else x) for k, x in v.items()}
    if isinstance(v, list):
        return np.asarray(v, dtype=np.float64)
    return v


def _short(v):
    """A value in a few characters, for the table's repr."""
    if isinstance(v, dict) and "wavelengths" in v and "values" in v:
        w, x = np.ravel(v["wavelengths"]), np.ravel(v["values"])
        if w.size:
            return f"spectrum of {w.size} nodes, {w.min():g}-{w.max():g} nm: {x.min():g}..{x.max():g}"
    if isinstance(v, (np.ndarray, list, tuple)):
        a = np.ravel(np.asarray(v, dtype=np.float64))
        text = " ".join(f"{x:.4g}" for x in a[:6])
        return f"[{text}{' ...' if a.size > 6 else ''}]" + (f" ({a.size})" if a.size > 6 else "")
    return repr(v)


class _Unfetched:
    """A buffer the table gave as its length only (more than 16 numbers): fetched on first access."""

    def __init__(self, length):
        self.length = length

    def __repr__(self):
        return f"<{self.length} values, not fetched>"


class SceneParameters:
    """A scene's parameter table, like Mitsuba's ``SceneParameters`` (from :meth:`Scene.traverse`).

    - ``p[key]``: the value (a float, a bool, a numpy array for vectors,
      transforms (4x4) and buffers, a dict of numpy arrays for a tabulated
      spectrum); aliases work too; an unknown key raises
      :class:`~raysweep.UnknownKeyError` (a ``KeyError``) naming the closest keys.
    - ``key in p``, ``len(p)``, ``p.keys()``, ``p.items()``, iteration.
    - ``p[key] = value`` records a change; :meth:`update` sends every change
      in one atomic PATCH. As in Mitsuba, change a value by assigning it:
      an array edited in place is not seen until it is assigned back
      (``v = p[k]; v[0] = 1; p[k] = v``).
    - ``p.properties(key)``: the entry's type, update class, shape and owner.
    """

    def __init__(self, scene, table):
        self.scene = scene
        self.revision = table["revision"]
        self._entries = {}
        self._alias = {}
        self._values = {}
        self._dirty = {}
        for e in table["params"]:
            self._entries[e["key"]] = e
            self._values[e["key"]] = _decode_value(e)
            for a in e.get("aliases") or []:
                self._alias[a] = e["key"]

    # ---- mapping ------------------------------------------------------------------------

    def _resolve(self, key):
        if key in self._entries:
            return key
        if key in self._alias:
            return self._alias[key]
        cands = did_you_mean(key, list(self._entries) + list(self._alias))
        hint = "; did you mean " + ", ".join(repr(c) for c in cands) + "?" if cands else ""
        raise UnknownKeyError(f"unknown parameter {key!r}{hint}", key=key, candidates=cands,
                              code="RSW_ERR_UNKNOWN_NAME")

    def __getitem__(self, key):
        k = self._resolve(key)
        v = self._values[k]
        if isinstance(v, _Unfetched):
            v = self._values[k] = self._fetch_full(k, v.length)
        return v

    def _fetch_full(self, key, length):
        path = f"{self.scene._path}/params?match={_q(key)}&full=1"
        table = self.scene._http.json("GET", path)
        for e in table["params"]:
            if e["key"] == key:
                v = _decode_value(e)
                if not isinstance(v, _Unfetched):
                    return v
        raise RaysweepError(f"{key}: the daemon gives this buffer of {length} values only as its length "
                            "(GET .../params?full=1 is not supported by this daemon)", key=key)

    def __setitem__(self, key, value):
        k = self._resolve(key)
        if self._entries[k].get("class") == "none":
            raise RaysweepError(f"parameter {key!r} is read-only (update class none)", key=key,
                                code="RSW_ERR_READONLY")
        self._dirty[k] = value
        self._values[k] = value

    def __contains__(self, key):
        return key in self._entries or key in self._alias

    def __iter__(self):
        return iter(self._entries)

    def __len__(self):
        return len(self._entries)

    def keys(self):
        """The keys (not the aliases), in the daemon's order."""
        return list(self._entries)

    def items(self):
        """(key, value) pairs; long buffers are fetched as they come."""
        return [(k, self[k]) for k in self._entries]

    def values(self):
        """The values, in key order."""
        return [self[k] for k in self._entries]

    def get(self, key, default=None):
        """``p[key]``, or ``default`` for an unknown key."""
        return self[key] if key in self else default

    def properties(self, key):
        """The entry of ``key`` without its value: type, class (update class), shape, object type/class/id, aliases."""
        e = dict(self._entries[self._resolve(key)])
        e.pop("value", None)
        return e

    def keep(self, keys):
        """Keep only ``keys`` (a list of keys, or a glob string like ``'*.value'``), as Mitsuba's ``keep``."""
        import fnmatch
        if isinstance(keys, str):
            wanted = {k for k in self._entries if fnmatch.fnmatchcase(k, keys)}
        else:
            wanted = {self._resolve(k) for k in keys}
        for k in list(self._entries):
            if k not in wanted:
                del self._entries[k], self._values[k]
                self._dirty.pop(k, None)
        self._alias = {a: k for a, k in self._alias.items() if k in wanted}

    # ---- updates ------------------------------------------------------------------------

    def set_dirty(self, key):
        """Send ``key``'s current value with the next :meth:`update` (after an in-place edit of its array)."""
        k = self._resolve(key)
        self._dirty[k] = self[k]

    def update(self, values=None):
        """Send the changed keys (and ``values``, a dict, set first) in one atomic PATCH.

        Returns the daemon's answer (``revision``, ``changed``, ``classes``,
        ``seconds``), or ``None`` when nothing changed. When the daemon refuses
        the update, nothing changed in the scene: the error is raised, and the
        refused values are dropped from this table (it shows the scene's state again).
        """
        for k, v in (values or {}).items():
            self[k] = v
        if not self._dirty:
            return None
        dirty, self._dirty = self._dirty, {}
        try:
            ans = self.scene.update(dirty)
        except RaysweepError:
            for k in dirty:
                self._values[k] = _decode_value(self._entries[k])
            raise
        self.revision = ans["revision"]
        for k, v in dirty.items():
            self._entries[k] = dict(self._entries[k], value=_encode_value(v))
        return ans

    def __repr__(self):
        rows = [f"SceneParameters[ revision {self.revision}"]
        width = max((len(k) for k in self._entries), default=0)
        for k, e in self._entries.items():
            mark = "*" if k in self._dirty else " "
            text = _short(self._values[k])
            rows.append(f" {mark} {k:<{width}}  {e.get('type', ''):<9} {e.get('class', ''):<9} "
                        f"{text[:60]}")
        return "\n".join(rows) + "\n]"


def _number(v, what):
    """A coordinate's value as a JSON number (numpy scalars too); a TypeError naming it otherwise."""
    if getattr(v, "ndim", None) == 0:
        v = v.item()
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError(f"{what} must be a number, not {type(v).__name__}")
    return v
