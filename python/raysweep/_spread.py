"""``Scene.sweep(..., spread=K)``: one sweep cut into K shards, run at once on the
replicas behind a load balancer, and joined into the dataset of the unsharded sweep.

The shards are cut as ``raysweep sweep --spread K`` cuts them (docs/cluster.md,
"Shards and spectral bundles"): contexts that differ only in their wavelength
form bundle groups (the rule of common/bundle_plan.c), the groups are dealt out
in turn, and every context carries its group as ``bundle_group``, so that each
shard's job forms the very bundles of the unsharded sweep and every film is
bitwise the unsharded one's. Each shard has its own routing key
(``X-Raysweep-Shard``), chosen so that the shards reach different replicas; it
pushes the scene's document there and submits its job. A shard whose job is
lost (its replica gone: the connection fails, or the job or scene is not found,
or the replica refuses with 503) is submitted again under another key. The
shards' datasets are joined along their contexts and, when the whole sweep is a
complete grid over its coords, laid out over them as the daemon lays out the
unsharded sweep's (docs/client.md, "Sweep datasets").

With ``journal=PATH`` the shards' routing keys and jobs are kept in a file,
rewritten whenever one changes: the same sweep run again (after a Ctrl-C, a
timeout, a lost balancer, a dead kernel) follows the jobs the replicas kept and
submits only the shards whose jobs are gone. The file goes when the sweep
completes.
"""

import hashlib
import json
import os
import secrets
import time

from .errors import ConnectionFailed, RaysweepError

_BUNDLE_MAX = 16  # "auto", or no bundle given: the most any daemon takes (RSW_BUNDLE_MAX)
_BUNDLE_MAX_RUN = 64
_KEY_TRIES = 16  # candidate keys per shard before one shares a replica with another shard
_RESUBMITS = 3  # per shard
_LOST = (404, 429, 502, 503, 504)  # the job or scene not there, or no replica behind the key


def bundle_leads(contexts, bundle):
    """lead[i]: the index of the first context of context i's bundle group (docs/cluster.md).

    Contexts with the same JSON but for ``id``, ``wavelength``, ``coords`` and
    ``bundle_group`` share groups, in their order, cut into runs of ``bundle``
    (``"auto"`` or ``None``: 16); a wavelength already in the run starts the next
    one. A context with a ``seed`` of its own, or without a wavelength, is a group
    of its own; contexts that give a ``bundle_group`` keep it (the first of each
    value leads)."""
    n = len(contexts)
    lead = list(range(n))
    k = _BUNDLE_MAX if bundle is None or bundle == "auto" else int(bundle)
    if k <= 1:
        return lead
    k = min(k, _BUNDLE_MAX_RUN)
    given, runs = {}, {}
    for i, c in enumerate(contexts):
        if "bundle_group" in c:
            lead[i] = given.setdefault(json.dumps(c["bundle_group"]), i)
            continue
        wl = c.get("wavelength")
        if "seed" in c or isinstance(wl, bool) or not isinstance(wl, (int, float)):
            continue
        text = json.dumps({key: v for key, v in c.items() if key not in ("id", "wavelength", "coords")},
                          separators=(",", ":"))
        runs.setdefault(text, []).append(i)
    for members in runs.values():
        start = 0
        while start < len(members):
            first, seen, end = members[start], set(), start
            while end < len(members) and end - start < k and contexts[members[end]]["wavelength"] not in seen:
                seen.add(contexts[members[end]]["wavelength"])
                lead[members[end]] = first
                end += 1
            start = end
    return lead


def shard_of(lead, n_shards):
    """Which shard holds each context: the rank of its group among the groups, in the order of
    their first contexts, mod ``n_shards`` (rsw_bundle_shard_keys)."""
    rank, out = {}, []
    for i, first in enumerate(lead):
        if first == i:
            rank[i] = len(rank)
        out.append(rank[first] % n_shards)
    return out


class _Shard:
    def __init__(self, k, contexts):
        self.k = k
        self.contexts = contexts
        self.key = None  # the routing key it runs under
        self.base = None  # the first key chosen (its resubmissions' keys extend it)
        self.tries = 0
        self.job = None
        self.job_id = None  # (a journal's job, before it is found again)
        self.dataset = None


class _Journal:
    """``journal=PATH``: the shards' keys and jobs, and the sweep they belong to (a digest of
    the scene's document, the contexts, the options and the shard count)."""

    def __init__(self, path, sweep, shards):
        self.path = os.fspath(path)
        self.sweep = sweep
        self.shards = shards

    def load(self):
        """Take the shards' keys and jobs from the file; False when there is none."""
        try:
            with open(self.path, encoding="utf-8") as f:
                text = f.read()
        except FileNotFoundError:
            return False
        try:
            doc = json.loads(text)
            entries = {e["shard"]: e for e in doc["shards"]}
            ok = doc.get("raysweep") == "spread journal" and isinstance(doc.get("sweep"), str)
        except (ValueError, KeyError, TypeError):
            ok = False
        if not ok:
            raise ValueError(f"journal {self.path}: not a raysweep spread journal (delete it, or give "
                             "another path)")
        if doc["sweep"] != self.sweep or sorted(entries) != sorted(sh.k for sh in self.shards):
            raise ValueError(f"journal {self.path} records another sweep (another scene document, other "
                             "contexts, options or spread): delete it to start over, or give another path")
        for sh in self.shards:
            e = entries[sh.k]
            sh.key, sh.base, sh.tries, sh.job_id = e.get("key"), e.get("base"), int(e.get("tries") or 0), e.get("job")
            if not isinstance(sh.key, str) or not isinstance(sh.base, str):
                raise ValueError(f"journal {self.path}: shard {sh.k} has no routing key (delete it to start over)")
        return True

    def save(self):
        """Write the file anew beside itself, then over it (never half a journal)."""
        doc = {"raysweep": "spread journal", "version": 1, "sweep": self.sweep,
               "shards": [{"shard": sh.k, "key": sh.key, "base": sh.base, "tries": sh.tries,
                           "job": sh.job.id if sh.job is not None else sh.job_id} for sh in self.shards]}
        tmp = f"{self.path}.tmp{os.getpid()}"
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(doc, f, indent=1)
            f.write("\n")
        os.replace(tmp, self.path)

    def remove(self):
        try:
            os.remove(self.path)
        except FileNotFoundError:
            pass


def _sweep_digest(scene, contexts, n_shards, options):
    """What a journal belongs to: the scene's document (and its files), the contexts, the
    options but the idempotency key, and the number of shards."""
    body, content_type, variant, refs = scene._doc
    what = {"scene": hashlib.sha256(body).hexdigest(), "content_type": content_type, "variant": variant,
            "files": sorted(refs), "contexts": contexts, "spread": n_shards,
            "options": {k: v for k, v in options.items() if k != "idempotency_key"}}
    from ._http import _json_default
    text = json.dumps(what, default=_json_default, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _client_for(base, key):
    from ._http import Transport
    from .client import Client
    t = base._http
    return Client(Transport(t.url, t.token, timeout=t.timeout, max_retries=t.max_retries,
                            retry_backoff=t.retry_backoff, route=key))


def _probe(scene, key):
    """The ``instance`` of the replica that ``key`` reaches (GET /v1), or None when none answers."""
    try:
        return _client_for(scene.client, key)._http.json("GET", "/v1").get("instance") or "?"
    except (ConnectionFailed, RaysweepError) as e:
        if getattr(e, "refused", False):  # (the balancer itself is gone: other keys would not help)
            raise ConnectionFailed(f"spread: the balancer at {scene.client.url} refuses connections") from None
        if _lost(e):
            return None
        raise


def _pick_key(scene, sh, base, used):
    """The first of _KEY_TRIES candidate keys (``base``, ``base.c1``, ...) that reaches a
    replica, preferring one that no key in ``used`` (instances) reaches."""
    first = None
    for c in range(_KEY_TRIES):
        key = base + (f".c{c}" if c else "")
        inst = _probe(scene, key)
        if inst is None:
            continue
        if inst not in used:
            used.add(inst)
            sh.key = key
            return
        first = first or key
    if first is None:
        raise ConnectionFailed(f"spread: no replica answers through {scene.client.url} for shard {sh.k} "
                               f"({_KEY_TRIES} routing keys tried)")
    sh.key = first  # (fewer replicas than shards: this one shares one)


def _choose_keys(scene, shards, prefix):
    """A routing key for each shard that reaches a replica no other shard has (GET /v1's
    ``instance``)."""
    used = set()
    for sh in shards:
        _pick_key(scene, sh, f"{prefix}-{sh.k}", used)


def _submit(scene, sh, options):
    """Push the scene's document through the shard's key and submit its job there."""
    body, content_type, variant, refs = scene._doc
    c = _client_for(scene.client, sh.key)
    c._upload_missing(refs)
    there = c._push(body, content_type, variant, scene.label, refs)
    from .jobs import submit
    opts = dict(options)
    if opts.get("idempotency_key"):  # (one job a shard, each its own key)
        opts["idempotency_key"] = f"{opts['idempotency_key']}-shard{sh.k}"
    # (the sweep's warnings came from its dry run, once)
    sh.job = submit(there, contexts=sh.contexts, _warn=False, **opts)


def _start(scene, sh, options, why=None, jr=None):
    """Submit the shard (again, with why: the error that lost its job), under a new key
    for each try after the first; at most _RESUBMITS times again. jr: the journal that
    records the shard's new job."""
    while True:
        if why is not None:
            sh.tries += 1
            if sh.tries > _RESUBMITS:
                raise ConnectionFailed(f"spread: shard {sh.k}'s job was lost {sh.tries} times (last key "
                                       f"{sh.key}): {why}") from None
            _pick_key(scene, sh, f"{sh.base}.r{sh.tries}", set())
        try:
            _submit(scene, sh, options)
            if jr is not None:
                jr.save()
            return
        except (ConnectionFailed, RaysweepError) as e:
            if not _lost(e):
                raise
            why = e


def _reattach(scene, sh, options, jr):
    """A journal's shard: its job found again through its key, else (gone with its replica or
    its results, or cancelled) submitted again; a shard that had no job yet is submitted."""
    if sh.job_id is None:
        _start(scene, sh, options, jr=jr)
        return
    try:
        sh.job = _client_for(scene.client, sh.key).job(sh.job_id)
    except (ConnectionFailed, RaysweepError) as e:
        if not _lost(e):
            raise
        _start(scene, sh, options, why=e, jr=jr)
        return
    if sh.job.state == "cancelled":  # (someone cancelled it: this run wants its films)
        _start(scene, sh, options, why=f"job {sh.job.id} was cancelled", jr=jr)


def _lost(e):
    return isinstance(e, ConnectionFailed) or (isinstance(e, RaysweepError) and getattr(e, "status", None) in _LOST)


def run(scene, contexts, n_shards, options, progress=None, timeout=None, journal=None):
    """The sweep of ``contexts`` (ids set) in ``n_shards`` shards: its dataset. ``journal``: a
    path that records the shards' keys and jobs, so that the same sweep run again resumes."""
    if not isinstance(n_shards, int) or isinstance(n_shards, bool) or not 1 <= n_shards <= 256:
        raise ValueError(f"spread must be a number of shards from 1 to 256, not {n_shards!r}")
    if getattr(scene, "_doc", None) is None:
        raise TypeError("spread= pushes the scene's document to every replica: use a scene that this "
                        "client loaded (client.load_file or load_dict), not one found by client.scene(id)")
    rev = scene.info().get("revision", 0)
    if rev:
        raise RaysweepError(f"spread= renders the scene's document on every replica, but this scene is at "
                            f"revision {rev} (parameters set since it was loaded, on one replica only): give "
                            "them to the sweep as params=, or load the edited document", code="RSW_ERR_CONFLICT")
    # The whole sweep checked once (nothing queued): a bad request fails here, before any
    # shard runs, and the warnings about the sweep (a coordinate along which it changes
    # nothing, which a shard alone may not show) are raised at sweep()'s caller.
    from .jobs import submit
    submit(scene, contexts=contexts, _stacklevel=4, _dry_run=True, **options)
    lead = bundle_leads(contexts, options.get("bundle"))
    which = shard_of(lead, n_shards)
    shards = []
    for k in range(n_shards):
        mine = [dict(c, bundle_group=lead[i]) for i, c in enumerate(contexts) if which[i] == k]
        if mine:
            shards.append(_Shard(k, mine))
    jr = None
    if journal is not None:
        jr = _Journal(journal, _sweep_digest(scene, contexts, n_shards, options), shards)
    try:
        if jr is not None and jr.load():
            for sh in shards:
                _reattach(scene, sh, options, jr)
        else:
            prefix = f"py{os.getpid()}-{secrets.token_hex(4)}"
            _choose_keys(scene, shards, prefix)
            for sh in shards:
                sh.base = sh.key
            if jr is not None:
                jr.save()
            for sh in shards:
                _start(scene, sh, options, jr=jr)
        ds = _finish(scene, shards, contexts, options, progress, timeout, jr)
    except KeyboardInterrupt:
        if jr is not None:  # (the jobs kept running, for the run that resumes them)
            import sys
            ids = ", ".join(sh.job.id for sh in shards if sh.job is not None)
            print(f"raysweep: interrupted: jobs {ids or '(none yet)'} keep running; the same sweep with "
                  f"journal={jr.path!r} follows them", file=sys.stderr)
        raise
    except ConnectionFailed as e:
        if jr is None or not os.path.exists(jr.path):
            raise
        raise ConnectionFailed(f"{e}; the shards' jobs are recorded in {jr.path}: run the same sweep "
                               "again (journal= that file) to follow them once the balancer answers") from None
    if jr is not None:
        jr.remove()
    return ds


def _finish(scene, shards, contexts, options, progress, timeout, jr):
    """Follow the shards' jobs and join their datasets."""
    deadline = None if timeout is None else time.monotonic() + timeout
    from . import _progress
    total = sum(sh.job.status.get("renders_total") or 0 for sh in shards)
    bar = _progress.make_bar(progress, total, f"{len(shards)} shards")
    state = None
    try:
        _follow(scene, shards, options, deadline, bar, total, jr)
        state = "succeeded"
    except KeyboardInterrupt:
        if jr is not None:  # (run() says so: the jobs keep running)
            raise
        import sys
        ids = ", ".join(sh.job.id for sh in shards)
        for sh in shards:
            try:
                sh.job.cancel()
            except (ConnectionFailed, RaysweepError):
                pass
        print(f"raysweep: interrupted: cancelled jobs {ids}", file=sys.stderr)
        raise
    finally:
        if bar is not None:
            bar.close(state)
    from . import _data
    if not _data.have_xarray():  # the films, as sweep() gives them without xarray
        films = {}
        for sh in shards:
            films.update(sh.job.films())
        return films
    for sh in shards:
        while sh.dataset is None:
            try:
                sh.dataset = sh.job.dataset()
            except (ConnectionFailed, RaysweepError) as e:  # (its replica lost since the job ended)
                if not _lost(e):
                    raise
                _start(scene, sh, options, why=e, jr=jr)
                _follow(scene, [sh], options, deadline, None, 0, jr)
    return _join(shards, contexts)


def _follow(scene, shards, options, deadline, bar, total, jr=None):
    """Poll the shards' jobs until each has ended; submit a shard again under another key when
    its job was lost with its replica."""
    left = list(shards)
    while left:
        for sh in list(left):
            try:
                st = sh.job.refresh()
            except (ConnectionFailed, RaysweepError) as e:
                if not _lost(e):
                    raise
                _start(scene, sh, options, why=e, jr=jr)
                continue
            if st.get("state") in ("succeeded", "failed", "cancelled"):
                if st["state"] != "succeeded":
                    raise sh.job._failure()
                left.remove(sh)
        if bar is not None:
            bar.update(sum(sh.job.status.get("renders_done") or 0 for sh in shards), total)
        if left:
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError(f"spread: {len(left)} of {len(shards)} shards still running after the "
                                   "timeout (their jobs keep running" +
                                   (f"; the same sweep with journal={jr.path!r} follows them)" if jr else ")"))
            time.sleep(0.1)


def _join(shards, contexts):
    """The shards' datasets as the unsharded sweep's."""
    import numpy as np
    import xarray as xr
    parts = [_as_contexts(sh.dataset) for sh in shards]
    if len(parts) == 1:
        ds = parts[0]
    else:
        ds = xr.concat(parts, dim="context", data_vars="minimal", coords="minimal", compat="equals",
                       combine_attrs="override")
    order = [c["id"] for c in contexts]
    ds = ds.sel(context=order)
    ds.attrs = dict(shards[0].dataset.attrs)
    ds.attrs["job"] = ", ".join(sh.job.id for sh in shards)
    missing = sum(int(sh.dataset.attrs.get("films_missing", 0)) for sh in shards)
    if missing:
        ds.attrs["films_missing"] = np.int64(missing)
    names = list(contexts[0].get("coords") or {})
    if names and _complete_grid(contexts, names):
        ds = _as_grid(ds, names)
    ds["context"].attrs = dict(shards[0].dataset["context"].attrs)
    return ds


def _as_contexts(ds):
    """A dataset laid out over its coords as one with a ``context`` dimension (ids along it)."""
    if "context" in ds.dims:
        return ds
    dims = list(ds["context"].dims)
    if len(dims) == 1:  # (one coord: its index swapped for the ids')
        out = ds.rename({"context": "_id"}).swap_dims({dims[0]: "_id"}).rename({"_id": "context"})
        return out.transpose("context", ...)
    ids = ds["context"].stack(_c=dims).values
    out = ds.drop_vars("context").stack(_c=dims).reset_index("_c")
    out = out.assign_coords(context=("_c", ids)).swap_dims({"_c": "context"})
    return out.transpose("context", ...)


def _complete_grid(contexts, names):
    seen, values = set(), [set() for _ in names]
    for c in contexts:
        co = c.get("coords") or {}
        if list(co) != names:
            return False
        combo = tuple(co[n] for n in names)
        if combo in seen:
            return False
        seen.add(combo)
        for v, x in zip(values, combo):
            v.add(x)
    total = 1
    for v in values:
        total *= len(v)
    return total == len(contexts)


def _as_grid(ds, names):
    """A ``context``-dimension dataset over a complete grid laid out over its coords, values sorted."""
    ds = ds.assign_coords(_id=("context", ds["context"].values))
    ds = ds.drop_vars("context").rename({"context": "_c"}) if "context" in ds.coords else ds
    if len(names) == 1:  # (one coord: an index of its own, not a MultiIndex to unstack)
        ds = ds.swap_dims({"_c": names[0]}).sortby(names[0])
    else:  # (a complete grid: unstack fills nothing, and 0 spares the integers a cast of NaN)
        ds = ds.set_index(_c=names).unstack("_c", fill_value=0)
    ds = ds.rename({"_id": "context"})
    return ds.transpose(*names, ...)
