"""Progress of long work, declared once: a bar with its rate and ETA on a terminal, plain
lines in a log.

A bar redraws itself with carriage returns, which fill a log (stderr redirected to a
file, a CI job) with one long line of every redraw.  Off a terminal the same progress
is a plain line at most every :data:`LINE_SECONDS` and one at the end; a transient bar
(``leave=False``: a render's, under a run's own bar) says nothing there.
"""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

LINE_SECONDS = 10.0  # the least time between two lines of progress in a log


def progress_bar(total: float | None = None, *, desc: str = "", unit: str = "it",
             enabled: bool = True, leave: bool = True, stream: TextIO | None = None,
             **bar: Any) -> Any:
    """A progress bar for ``total`` units of work, used as tqdm's (``update``, ``n``,
    ``total``, ``close``, a context manager): tqdm's own on a terminal, else
    :class:`PlainLines` (or nothing, for a transient bar); none where not ``enabled``.
    ``bar``: tqdm's further options (its ``bar_format``)."""
    from tqdm import tqdm

    stream = stream or sys.stderr
    terminal = hasattr(stream, "isatty") and stream.isatty()
    if enabled and not terminal:
        return PlainLines(total, desc, unit, stream, silent=not leave)
    return tqdm(total=total, desc=desc, unit=unit, disable=not enabled, leave=leave,
                file=stream, **bar)


class PlainLines:
    """Progress as plain lines: ``desc: n/total unit, rate, ETA`` at most every
    :data:`LINE_SECONDS`, and once when it closes."""

    def __init__(self, total: float | None, desc: str, unit: str, stream: TextIO,
                 silent: bool = False):
        self.total, self.desc, self.unit, self.stream, self.silent = total, desc, unit, \
            stream, silent
        self.n = 0.0
        self.start = self.last = time.monotonic()
        self.closed = False

    def update(self, k: float = 1) -> None:
        """``k`` more units done."""
        self.n += k
        now = time.monotonic()
        if now - self.last >= LINE_SECONDS:
            self.last = now
            self._line(now)

    def close(self) -> None:
        """The last line (once)."""
        if not self.closed:
            self.closed = True
            self._line(time.monotonic(), done=True)

    def __enter__(self) -> PlainLines:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def _line(self, now: float, done: bool = False) -> None:
        if self.silent:
            return
        elapsed = now - self.start
        rate = self.n / elapsed if elapsed > 0 else 0.0
        of = f"/{self.total:g}" if self.total else ""
        text = f"{self.desc}: {self.n:g}{of} {self.unit}, {_duration(elapsed)}"
        if rate > 0:
            text += f", {rate:.3g} {self.unit}/s"
            if self.total and not done and self.n < self.total:
                text += f", ETA {_duration((self.total - self.n) / rate)}"
        print(text, file=self.stream, flush=True)


def _duration(seconds: float) -> str:
    """``42 s``, ``3 min 05 s``, ``1 h 02 min``."""
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"
