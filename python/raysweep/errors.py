"""Exceptions raised by the raysweep client.

Every error the daemon answers is an RFC 9457 problem (``application/problem+json``,
docs/daemon.md): :class:`RaysweepError` carries its members as attributes
(``status``, ``code``, ``title``, ``detail``, ``pointer``, ``key``,
``candidates``) and prints them on one line, with "did you mean" for an
unknown parameter key.
"""

import difflib

__all__ = [
    "RaysweepError",
    "UnknownKeyError",
    "ConnectionFailed",
    "JobFailed",
    "SweepWarning",
    "did_you_mean",
]


def did_you_mean(key, known, n=3):
    """The up to ``n`` keys of ``known`` closest to ``key`` (difflib's ratio, best first)."""
    return difflib.get_close_matches(str(key), list(known), n=n, cutoff=0.5)


class RaysweepError(Exception):
    """An error from the daemon (a problem+json answer) or from the client itself.

    Attributes (``None`` when the problem has no such member):

    - ``status``: the HTTP status (422, 404, ...), ``None`` for a local error;
    - ``code``: the machine code, ``RSW_ERR_...`` or the HTTP status name;
    - ``title``: the problem's short summary;
    - ``detail``: the explanation of this occurrence;
    - ``pointer``: the JSON pointer (or ``file:line`` of an XML scene) of the bad input;
    - ``key``: the parameter key the error is about;
    - ``candidates``: the closest known keys to an unknown ``key`` (a list);
    - ``method``, ``path``: the request that failed;
    - ``problem``: the whole problem object as a dict.
    """

    def __init__(self, detail, *, status=None, code=None, title=None, pointer=None, key=None,
                 candidates=None, method=None, path=None, problem=None):
        self.status = status
        self.code = code
        self.title = title
        self.detail = detail
        self.pointer = pointer
        self.key = key
        self.candidates = list(candidates or [])
        self.method = method
        self.path = path
        self.problem = dict(problem or {})
        super().__init__(self._message())

    @classmethod
    def from_problem(cls, problem, status, method=None, path=None):
        """The exception for a decoded problem+json body (a dict) answered with ``status``."""
        if not isinstance(problem, dict):
            problem = {}
        kind = UnknownKeyError if problem.get("code") == "RSW_ERR_UNKNOWN_NAME" and problem.get("key") else cls
        return kind(problem.get("detail") or problem.get("title") or f"HTTP {status}",
                    status=problem.get("status", status), code=problem.get("code"),
                    title=problem.get("title"), pointer=problem.get("pointer"), key=problem.get("key"),
                    candidates=problem.get("candidates"), method=method, path=path, problem=problem)

    def _message(self):
        """``detail (at pointer); did you mean ...? [422 RSW_ERR_...: title]``."""
        detail = self.detail or ""
        msg = detail
        if self.pointer and self.pointer not in detail:
            msg += f" (at {self.pointer})"
        if self.candidates and "closest" not in detail and "did you mean" not in detail:
            msg += "; did you mean " + ", ".join(repr(c) for c in self.candidates) + "?"
        tail = " ".join(str(x) for x in (self.status, self.code) if x)
        if self.title and self.title not in detail:
            tail = f"{tail}: {self.title}" if tail else self.title
        return f"{msg} [{tail}]" if tail else msg

    def with_candidates(self, candidates):
        """This error with ``candidates`` (computed by the client) added to its message."""
        self.candidates = list(candidates)
        self.args = (self._message(),)
        return self

    def __str__(self):
        return self.args[0] if self.args else ""


class UnknownKeyError(RaysweepError, KeyError):
    """A parameter key that names nothing in the scene; ``candidates`` holds the closest keys.

    Also a :class:`KeyError`, so ``except KeyError`` catches it as for a dict.
    """

    def __str__(self):  # KeyError would print the repr of the message
        return RaysweepError.__str__(self)


class ConnectionFailed(RaysweepError, ConnectionError):
    """The daemon could not be reached (refused, timed out, the connection dropped); ``refused``
    is true when nothing listened at its address (after the retries)."""

    refused = False


class JobFailed(RaysweepError):
    """A job ended ``failed`` or ``cancelled``; ``job`` is the job, ``state`` its end state,
    ``failures`` its failed renders as ``(context, sensor, error)`` (the message quotes the first)."""

    def __init__(self, detail, job=None, state=None, failures=None, **kw):
        self.job = job
        self.state = state
        self.failures = list(failures or [])
        super().__init__(detail, **kw)


class SweepWarning(UserWarning):
    """The daemon's warning about a job it accepted: its contexts differ in a coordinate, or in
    the wavelength, that changes nothing they render (``coordinate_unused``,
    ``wavelength_unused``; docs/experiments.md#templates). ``code``, ``coordinate`` and
    ``job`` (the job's id) as the daemon gives them. Raised through :mod:`warnings` at
    submission, so it shows in a notebook or a script like any warning (``warnings.simplefilter``
    turns it into an error or silences it)."""

    def __init__(self, message, code=None, coordinate=None, job=None):
        super().__init__(message)
        self.code = code
        self.coordinate = coordinate
        self.job = job
