"""The exception classes that reach the user, and the exit status of each.

Bad input (a file, a key or an option the user can fix) exits with status 2;
a run that failed (nothing usable in a frame, a backend that does not work here,
measurements the solver cannot solve) exits with status 1.  The CLI maps classes to
statuses with :func:`exit_status`; nothing is told apart by name.
"""

from __future__ import annotations

import errno
import sys
from collections.abc import Callable
from typing import Any, TextIO

from solver.errors import BadParameter, InputError, SolverError

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1

__all__ = ["InputError", "SolverError", "SceneError", "BadParameter", "BadArgument",
           "OutputError", "RunFailed", "DiskError", "DISK_CAUSES", "write_error",
           "DetectionError", "BackendError", "EXIT_BAD_INPUT", "EXIT_FAILED", "exit_status",
           "one_line_warning", "Failures"]


class SceneError(InputError):
    """A bad scene or dataset-spec file.  ``others``: the further failures found in the
    same file (independent of this one; ``mirrorsim check`` lists them all)."""

    others: tuple[SceneError, ...] = ()


class Failures:
    """The failures found so far in one scene: each independent check is attempted, and
    the first failure is raised with the others attached (``SceneError.others``).  The
    scene reader and the composer (:mod:`mirrorsim.truth.compose`) share one."""

    def __init__(self, lenient: bool = False):
        self.found: list[SceneError] = []
        # lenient: only a block that cannot be read stops the scene being built (plot)
        self.lenient = lenient

    def attempt(self, fn: Callable, *args, default: Any = None, **kwargs) -> Any:
        """``fn(*args, **kwargs)``, or ``default`` with its SceneError recorded."""
        try:
            return fn(*args, **kwargs)
        except SceneError as exc:
            self.found.append(exc)
            return default

    def raise_any(self, hint: str = "", structural: bool = False) -> None:
        """Raise the first failure found, the others attached, with ``hint`` added to its
        line (a value in the wrong units is blamed on another key); when lenient, only
        ``structural`` failures (a block not read) are raised."""
        if not self.found:
            return
        first = self.found[0]
        if hint and hint not in first.message:
            first = self.found[0] = SceneError(first.file, first.key,
                                               f"{first.message} ({hint})")
        if self.lenient and not structural:
            return
        first.others = tuple(self.found[1:])
        raise first


class BadArgument(InputError):
    """A command-line option out of range: ``BadArgument("--workers", "0 must be ≥ 1")``
    (raised by :mod:`mirrorsim.cli` only)."""

    def __init__(self, option: str, message: str):
        super().__init__(option, "", message)


class OutputError(InputError):
    """An output path that cannot be written (exit 2): ``OutputError(path, message)``."""

    def __init__(self, path, message: str):
        super().__init__(path, "", message)


class RunFailed(RuntimeError):
    """The run itself failed (exit status 1); the message says why."""


class DiskError(RunFailed):
    """A write failed for a cause outside the input (exit status 1): a full disk, a
    file-size limit, a quota, an I/O error.  The input was fine; the run was not."""


# the causes of a failed write that are the machine's, not the input's, in words
DISK_CAUSES = {errno.ENOSPC: "disk full", errno.EFBIG: "file size limit reached",
               errno.EDQUOT: "disk quota exceeded", errno.EIO: "I/O error"}


def write_error(path: object, exc: OSError, what: str) -> InputError | DiskError:
    """The error to raise for a write of ``path`` that failed with ``exc``:
    :class:`DiskError` (exit 1) where the machine is at fault, naming the cause, else
    :class:`OutputError` (exit 2: a path the user can change).  ``what``: the message's
    start, e.g. ``"--out: cannot write"``."""
    if exc.errno in DISK_CAUSES:
        return DiskError(f"{path}: {what}: {DISK_CAUSES[exc.errno]} "
                         f"({exc.strerror or exc})")
    return OutputError(path, f"{what}: {exc.strerror or exc}")


class DetectionError(RunFailed):
    """Nothing usable was found in a frame (the message says what)."""


class BackendError(RunFailed):
    """The requested Mitsuba variant does not work on this machine."""


def exit_status(exc: BaseException) -> int | None:
    """The exit status for an exception the user should see as one line, else None."""
    if isinstance(exc, InputError):
        return EXIT_BAD_INPUT
    if isinstance(exc, RunFailed | SolverError):
        return EXIT_FAILED
    return None


def one_line_warning(message: Warning | str, category: type[Warning],  # noqa: ARG001
                     filename: str, lineno: int, file: TextIO | None = None,  # noqa: ARG001
                     line: str | None = None) -> None:  # noqa: ARG001
    """``warnings.showwarning`` for the command line (and its worker processes): one
    ``warning:`` line on stderr, without the source line."""
    print(f"warning: {message}", file=sys.stderr)
