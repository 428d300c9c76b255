"""Progress bars for jobs: tqdm in notebooks (when installed), a text bar on a terminal, else none."""

import sys
import time


def _in_notebook():
    """Whether this runs in a Jupyter kernel (IPython's ZMQ shell)."""
    ipython = sys.modules.get("IPython")
    if ipython is None:
        return False
    try:
        shell = ipython.get_ipython()
    except AttributeError:
        return False
    return shell is not None and type(shell).__name__ == "ZMQInteractiveShell"


def _tqdm_class(notebook):
    try:
        if notebook:
            try:
                import ipywidgets  # noqa: F401  (tqdm.notebook's widget)
                from tqdm.notebook import tqdm
                return tqdm
            except ImportError:
                pass
        from tqdm import tqdm
        return tqdm
    except ImportError:
        return None


def make_bar(progress, total, desc, stream=None):
    """A bar for ``total`` renders, or ``None``.

    ``progress``: ``True`` (always), ``False`` (never) or ``None`` (automatic:
    in a notebook, tqdm when installed, else the text bar; on a terminal
    (stderr a tty), tqdm when installed, else the text bar; otherwise none).
    Also accepts a tqdm-like class, called as ``cls(total=, desc=, unit=)``.
    """
    stream = stream or sys.stderr
    if progress is False:
        return None
    if callable(progress) and progress is not True:
        return _Tqdm(progress(total=total, desc=desc, unit="render"))
    notebook = _in_notebook()
    tty = bool(getattr(stream, "isatty", lambda: False)())
    if progress is None and not (notebook or tty):
        return None
    cls = _tqdm_class(notebook)
    if cls is not None:
        return _Tqdm(cls(total=total, desc=desc, unit="render", file=None if notebook else stream))
    return TextBar(total, desc, stream, live=tty or notebook)


class _Tqdm:
    """Adapts a tqdm bar to :class:`TextBar`'s interface."""

    def __init__(self, bar):
        self.bar = bar

    def update(self, done, total):
        if total and self.bar.total != total:
            self.bar.total = total
            self.bar.refresh()
        if done > self.bar.n:
            self.bar.update(done - self.bar.n)

    def close(self, state=None):
        if state is not None:
            self.bar.set_postfix_str(state, refresh=False)
        self.bar.close()


class TextBar:
    """``desc [#######.......] 12/40 3.1/s ETA 9s`` on one line, redrawn in place (``live``) or once at the end."""

    def __init__(self, total, desc, stream, live=True, width=30):
        self.total, self.desc, self.stream, self.live, self.width = total, desc, stream, live, width
        self.done = 0
        self.start = time.monotonic()
        self._last = 0.0
        if live:
            self._draw()

    def _line(self):
        total = max(self.total or 0, 1)
        filled = int(self.width * min(self.done, total) / total)
        elapsed = time.monotonic() - self.start
        rate = self.done / elapsed if elapsed > 0 else 0.0
        eta = f" ETA {((total - self.done) / rate):.0f}s" if rate > 0 and self.done < total else ""
        bar = "#" * filled + "." * (self.width - filled)
        return f"{self.desc} [{bar}] {self.done}/{self.total} {rate:.1f}/s{eta}"

    def _draw(self):
        self.stream.write("\r" + self._line() + "\033[K")
        self.stream.flush()

    def update(self, done, total):
        self.done, self.total = done, total or self.total
        now = time.monotonic()
        if self.live and (now - self._last > 0.1 or done >= (self.total or 0)):
            self._last = now
            self._draw()

    def close(self, state=None):
        end = f" {state}" if state else ""
        if self.live:
            self.stream.write("\r" + self._line() + end + "\033[K\n")
        else:
            self.stream.write(self._line() + end + "\n")
        self.stream.flush()
